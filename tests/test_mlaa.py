"""The MLAA passes against their numpy references and against cases with known answers.

Tolerances: edge masks agree exactly except where ΔE lies within 0.1 of the threshold (the kernel
reads colour tables with linear interpolation, the reference uses the exact formulas); distances
exactly; weights within 1e-4 (16-bit storage); 8-bit output within 1 level, >= 99% of pixels exact.
The whole-filter comparisons run without the FXAA fallback (Filter(fallback="off")): mlaa_reference is
the MLAA passes; tests/test_fallback.py checks the fallback on top of them.
"""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.device.colour import rgb_to_lab
from mlaa_stream.spatial.filter import EDGE_ROWS, SHORT_CORNER, Filter, area_table, trapezoid_area
from mlaa_stream.spatial.reference import (distances_reference, edges_reference, mlaa_reference,
                                   normalised_rgb, weights_reference)


@pytest.fixture(scope="module")
def filt():
    with Filter() as f:
        yield f


def blocky(seed: int, h: int = 48, w: int = 64, dtype=np.uint8, channels: int = 3) -> np.ndarray:
    """Random rectangles and staircases of random colours over a random background."""
    rng = np.random.default_rng(seed)
    img = np.empty((h, w, channels))
    img[:] = rng.random(channels)
    for _ in range(12):
        y0, x0 = rng.integers(0, h - 2), rng.integers(0, w - 2)
        y1, x1 = rng.integers(y0 + 1, h + 1), rng.integers(x0 + 1, w + 1)
        img[y0:y1, x0:x1] = rng.random(channels)
    yy, xx = np.mgrid[0:h, 0:w]
    for _ in range(3):  # half-planes at random angles: staircases of every slope
        a = rng.uniform(0, 2 * np.pi)
        mask = np.cos(a) * (xx - w / 2) + np.sin(a) * (yy - h / 2) > rng.uniform(-10, 10)
        img[mask] = rng.random(channels)
    if channels == 4:
        img[..., 3] = rng.random((h, w))
    return to_dtype(img, dtype)


def to_dtype(img: np.ndarray, dtype) -> np.ndarray:
    if dtype == np.uint8:
        return np.rint(img * 255).astype(np.uint8)
    if dtype == np.uint16:
        return np.rint(img * 65535).astype(np.uint16)
    return img.astype(dtype)


def near_threshold(frame: np.ndarray, threshold: float, bgr: bool = False) -> np.ndarray:
    """Edge bits whose ΔE lies within 0.1 of the threshold: the only place kernel and reference may differ."""
    rgb, _ = normalised_rgb(frame, bgr)
    lab = rgb_to_lab(rgb)
    amb = np.zeros(frame.shape[:2], np.uint8)
    amb[:-1] |= np.uint8(1) * (np.abs(np.linalg.norm(lab[:-1] - lab[1:], axis=-1) - threshold) < 0.1)
    amb[:, :-1] |= np.uint8(2) * (np.abs(np.linalg.norm(lab[:, :-1] - lab[:, 1:], axis=-1) - threshold) < 0.1)
    return amb


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_edges_match_reference(filt, seed):
    img = blocky(seed)
    got = filt.intermediates(img)["edges"]
    want = edges_reference(img, filt.options.threshold)
    differ = (got ^ want) & ~near_threshold(img, filt.options.threshold)
    assert not differ.any(), f"{differ.astype(bool).sum()} edge bits differ"
    assert want.astype(bool).mean() > 0.01  # the image really has edges


def antialiased_scene(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """(1-spp render, 8x8-supersampled render) of random polygons and a thin bar."""
    from mlaa_stream.yardstick import scenes as S

    rng = np.random.default_rng(seed)
    layers = [S.Layer(None, tuple(rng.integers(0, 256, 3)))]
    for _ in range(6):
        layers.append(S.Layer((S.rotated_rect(*rng.uniform(10, 70, 2), *rng.uniform(6, 40, 2),
                                              rng.uniform(0, 180)),), tuple(rng.integers(0, 256, 3))))
    layers.append(S.Layer((S.rotated_rect(40.2, 30.1, 70, 1.2, rng.uniform(0, 180)),), (20, 20, 20)))
    return S.render_pair(layers, 80, 60)


@pytest.mark.parametrize("seed", [11, 12])
def test_edges_match_reference_on_antialiased_input(filt, seed):
    """The already-antialiased guard (colour between p and q beside the step), kernel vs reference."""
    _, aa = antialiased_scene(seed)
    got = filt.intermediates(aa)["edges"]
    want = edges_reference(aa, filt.options.threshold)
    differ = (got ^ want) & ~near_threshold(aa, filt.options.threshold)
    assert not differ.any(), f"{differ.astype(bool).sum()} edge bits differ"
    loose = edges_reference(aa, filt.options.threshold, aa_guard=False)
    assert (loose & ~want).any()   # the guard did reject edges here


@pytest.mark.parametrize("seed,sigma,dtype", [(24, 6, np.uint8), (22, 20, np.uint8), (23, 12, np.uint16)])
def test_edges_match_reference_on_noisy_input(filt, seed, sigma, dtype):
    """Camera noise over blocky content: nearly every group takes the lane path (CIELAB and the
    antialiased guard decided 8 lanes at a time on the stored levels, kernels/edges.cl VANTIALIASED,
    the float path only where the rounding could matter); edges as the reference's. (Seed 21 at sigma 6
    holds an exact tie, t = AA_LO in `between`, which the float32 kernel -- before and after the lane
    path -- and the float64 reference round apart: a known reference limit, not tested here.)"""
    rng = np.random.default_rng(seed)
    img = blocky(seed, dtype=np.float64) + rng.normal(0, sigma / 255, (48, 64, 3))
    img = to_dtype(np.clip(img, 0, 1), dtype)
    got = filt.intermediates(img)["edges"]
    want = edges_reference(img, filt.options.threshold)
    differ = (got ^ want) & ~near_threshold(img, filt.options.threshold)
    assert not differ.any(), f"{differ.astype(bool).sum()} edge bits differ"
    loose = edges_reference(img, filt.options.threshold, aa_guard=False)
    assert want.astype(bool).mean() > 0.05 and (loose & ~want).any()   # edges found, and some guarded


@pytest.mark.parametrize("h,w,dtype", [(45, 70, np.uint8), (46, 129, np.uint8), (47, 200, np.uint16),
                                       (9, 65, np.uint8), (3, 17, np.uint8), (2, 70, np.uint8),
                                       (1, 130, np.uint8), (130, 1, np.uint8)])
def test_edges_match_reference_when_height_is_not_a_multiple_of_edge_rows(filt, h, w, dtype):
    """detect_edges' work items own EDGE_ROWS rows (kernels/edges.cl keeps a row's samples and CIELAB for
    the row below): the frame's last, shorter block of rows, segments cut short by the width, single rows
    and columns; runs of four close colours with noise, so consecutive rows take the lane path and the
    ramp test sees the row above (breaking the kept row y - 1, its CIELAB or row y's right samples fails
    here). (Seeds + 0 and + 1 hold exact ties, t = 1 - AA_LO in `between`, at 46 x 129: the known
    reference limit.)"""
    assert h % EDGE_ROWS
    rng = np.random.default_rng(h * 1000 + w + 2)
    pal = rng.random((1, 3)) * 0.6 + rng.random((4, 3)) * 0.2
    blocks = np.repeat(rng.integers(0, 4, (h, -(-w // 5))), 5, axis=1)[:, :w]   # runs of 5 px, a row each
    img = to_dtype(np.clip(pal[blocks] + rng.normal(0, 3 / 255, (h, w, 3)), 0, 1), dtype)
    got = filt.intermediates(img)["edges"]
    want = edges_reference(img, filt.options.threshold)
    differ = (got ^ want) & ~near_threshold(img, filt.options.threshold)
    assert not differ.any(), f"{differ.astype(bool).sum()} edge bits differ"
    assert want.astype(bool).mean() > 0.02   # the image really has edges


@pytest.mark.parametrize("angle", [10, 30, 45, 60, 80])
def test_antialiased_polygon_edges_are_left_alone(filt, angle):
    """A polygon already antialiased (8x8 samples per pixel) comes out untouched; its 1-spp render
    is still filtered."""
    from mlaa_stream.yardstick import scenes as S

    layers = [S.Layer(None, (230, 225, 210)), S.Layer((S.rotated_rect(40.3, 30.2, 50, 30, angle),), (40, 60, 120))]
    one_spp, aa = S.render_pair(layers, 80, 60)
    np.testing.assert_array_equal(filt.process(aa), aa)
    assert (filt.process(one_spp) != one_spp).any(-1).sum() > 100


@pytest.mark.parametrize("metric,threshold", [("luma", 0.06), ("rgb", 0.06)])
def test_other_metrics_match_reference(metric, threshold):
    img = blocky(7)
    with Filter(metric=metric, threshold=threshold) as f:
        got = f.intermediates(img)["edges"]
    want = edges_reference(img, threshold, metric)
    assert (got == want).mean() > 0.999


@pytest.mark.parametrize("seed", [4, 5])
def test_distances_and_weights_match_reference(filt, seed):
    img = blocky(seed)
    r = filt.intermediates(img)
    e = r["edges"]
    hd, vd = distances_reference(e)
    b, rt = (e & 1) > 0, (e & 2) > 0
    np.testing.assert_array_equal(r["hdist"][b], hd[b])
    np.testing.assert_array_equal(r["vdist"][rt], vd[rt])
    want = weights_reference(e, hd, vd, frame=img)
    got = r["weights"] / 65535.0
    valid = np.zeros_like(want, dtype=bool)  # slots the kernel writes: next to an existing edge
    valid[1:, :, 0] = b[:-1]
    valid[:, :, 1] = b
    valid[:, 1:, 2] = rt[:, :-1]
    valid[:, :, 3] = rt
    np.testing.assert_allclose(got[valid], want[valid], atol=1e-4)
    assert (want > 0).sum() > 20


@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, False), (np.uint8, 3, True),
                                                 (np.uint16, 3, False), (np.float32, 3, False),
                                                 (np.uint8, 4, False), (np.uint8, 1, False)])
def test_filter_matches_reference(dtype, channels, bgr):
    img = blocky(11, dtype=dtype, channels=channels)
    if channels == 1:
        img = img[..., 0]
    with Filter(bgr=bgr, fallback="off", alpha="keep") as f:  # the kernels' alpha kept (tests/test_alpha.py)
        got = f.process(img)
    want = mlaa_reference(img, bgr=bgr)
    assert got.shape == img.shape and got.dtype == img.dtype
    scale = {np.uint8: 1.0, np.uint16: 1 / 257.0, np.float32: 255.0}[dtype]
    diff = np.abs(got.astype(np.float64) - want.astype(np.float64)) * scale
    assert diff.max() <= 1.0 + 1e-6, f"max difference {diff.max():.3f} levels"
    changed = (want != img).any(axis=-1) if img.ndim == 3 else want != img
    assert changed.mean() > 0.02  # the filter really did something
    if dtype == np.uint8:
        assert (diff == 0).mean() >= 0.99
    if channels == 4:
        np.testing.assert_array_equal(got[..., 3], img[..., 3])  # alpha passes through


def test_float16_and_float64_keep_dtype(filt):
    img = blocky(12, dtype=np.float32)
    for dt in (np.float16, np.float64):
        out = filt.process(img.astype(dt))
        assert out.dtype == dt and out.shape == img.shape


def test_constant_image_is_unchanged(filt):
    img = np.empty((37, 53, 3), np.uint8)
    img[:] = (200, 31, 77)
    np.testing.assert_array_equal(filt.process(img), img)


def test_axis_aligned_rectangles_are_unchanged(filt):
    rng = np.random.default_rng(3)
    img = np.full((60, 80, 3), (20, 90, 160), np.uint8)
    for y0, x0, y1, x1 in [(5, 5, 20, 30), (25, 40, 55, 75), (10, 50, 14, 52), (40, 3, 58, 20)]:
        img[y0:y1, x0:x1] = rng.integers(0, 256, 3)
    np.testing.assert_array_equal(filt.process(img), img)


@pytest.mark.parametrize("L", [4, 7, 16])
def test_staircase_weights_follow_eq2(filt, L):
    """A step edge of slope 1/L: each pixel next to the line gets A = 1/2 (1 - (2p+1)/L) (seed 000 eq. 2)."""
    h, w = 24, 8 * L
    img = np.full((h, w, 3), 30, np.uint8)
    for x in range(w):
        img[6 + x // L:, x] = 220  # rows below the line are light; the line drops one row every L px
    r = filt.intermediates(img)
    wts = r["weights"] / 65535.0
    for k in range(2, 6):  # steps away from the image borders
        x0, y_line = k * L, 5 + k  # segment k: the line between rows y_line, y_line+1 over [x0, x0+L)
        for p in range(L // 2):
            want = trapezoid_area(p, L)
            # left end: the crossing edge goes up, so the upper row takes from below ...
            assert wts[y_line, x0 + p, 1] == pytest.approx(want, abs=1e-4)
            # ... right end: it goes down, so the lower row takes from above
            assert wts[y_line + 1, x0 + L - 1 - p, 0] == pytest.approx(want, abs=1e-4)
        assert wts[y_line, x0 + L - 1, 1] == 0.0 and wts[y_line + 1, x0, 0] == 0.0


@pytest.mark.parametrize("step, factor", [(1, 1.0), (2, SHORT_CORNER), (3, 0.0), (5, 0.0)])
def test_step_height_decides_jaggy_or_corner(filt, step, factor):
    """A horizontal border that steps up by `step` rows: a 1-px step is a jaggy (eq. 2's full area),
    a 3+ px step a corner (sharp at rounding 0), a 2-px step in between (SHORT_CORNER x area)."""
    L, h = 12, 24
    img = np.full((h, 2 * L, 3), 30, np.uint8)
    img[12:, :L] = 220
    img[12 - step:, L:] = 220
    wts = filt.intermediates(img)["weights"] / 65535.0
    # the line between rows 11 and 12 over x = 0 .. L-1 ends at x = L-1 in a crossing edge going
    # up `step` pixels: the pixels above the line take from below, counted from that end
    for p in range(L // 2):
        want = factor * trapezoid_area(p, L)
        assert wts[11, L - 1 - p, 1] == pytest.approx(want, abs=1e-4)
    assert np.all(wts[12, :L, 0] == 0.0)


def test_steep_staircase_blends_along_its_long_runs_only(filt):
    """Slope 2 (runs of 2 rows, 1 column): the 1-px horizontal lines between 2-px crossing edges
    are not blended; the vertical lines of length 2 are (eq. 2 with L = 2: 1/4 at each end)."""
    h, w = 40, 16
    img = np.full((h, w, 3), 30, np.uint8)
    for x in range(w):
        img[2 * x + 4:, x] = 220
    wts = filt.intermediates(img)["weights"] / 65535.0
    for x in range(3, 12):
        assert wts[2 * x + 3, x, 1] == 0.0 and wts[2 * x + 4, x, 0] == 0.0   # horizontal steps
    # vertical line between columns x and x+1 over rows 2x+4, 2x+5 (left pixels light): its top end
    # crosses on the left, its bottom end on the right (a Z): eq. (2) with L = 2 gives 1/4 at each
    for x in range(3, 12):
        assert wts[2 * x + 4, x, 3] == pytest.approx(trapezoid_area(0, 2), abs=1e-4)
        assert wts[2 * x + 5, x + 1, 2] == pytest.approx(trapezoid_area(0, 2), abs=1e-4)
        assert wts[2 * x + 4, x + 1, 2] == 0.0 and wts[2 * x + 5, x, 3] == 0.0


def test_long_edge_is_blended_along_its_whole_length(filt):
    """Steps of 600 px: distances are not capped at 255 (the seed's limit)."""
    L = 600
    img = np.full((8, 3 * L, 3), 25, np.uint8)
    for x in range(3 * L):
        img[2 + x // L:, x] = 230
    r = filt.intermediates(img)
    hd = r["hdist"]
    assert hd[2, L + 450, 0] == 450 and hd[2, L + 450, 1] == L - 1 - 450
    wts = r["weights"] / 65535.0
    # the upper row near the left end of the middle segment: p = 0 .. 299 all get eq. (2)'s area
    p = np.arange(L // 2)
    got = wts[2, L + p, 1]
    want = np.array([trapezoid_area(int(q), L) for q in p])
    np.testing.assert_allclose(got, want, atol=1e-4)
    assert got[298] > 0 and got[299] > 0


@pytest.mark.parametrize("op", ["fliplr", "flipud", "transpose"])
def test_flips_and_transposes_commute(filt, op):
    img = blocky(21)
    f = {"fliplr": lambda a: a[:, ::-1], "flipud": lambda a: a[::-1],
         "transpose": lambda a: a.transpose(1, 0, 2)}[op]
    a = f(filt.process(img)).astype(int)
    b = filt.process(np.ascontiguousarray(f(img))).astype(int)
    assert np.abs(a - b).max() <= 1
    assert (a == b).mean() >= 0.999


def test_area_table_matches_formula():
    t = area_table(32)
    for L in range(1, 33):
        for p in range(L):
            assert t[L, p] == pytest.approx(trapezoid_area(p, L))
    assert trapezoid_area(0, 1) == pytest.approx(1 / 8)          # middle pixel of an odd line
    assert trapezoid_area(1, 4) == pytest.approx(0.5 * (1 - 3 / 4))


def test_buffers_allocated_once_per_frame_size(filt):
    img = blocky(30)
    filt.process(img)
    bufs = filt._buffers
    for _ in range(3):
        filt.process(img)
    assert filt._buffers is bufs
    filt.process(blocky(31, h=20, w=30))
    assert filt._buffers is not bufs
    # 8-bit RGB: 2 x 2 frame slots (12), edges (1), distances (8), weights (8), moved-feature flags (1) and
    # their shares (16, float4), bridging (17: found bits 1, links 8, their claims 4, the claim pass's
    # verdicts 4), the fallback's per-tile counts, region sums and flags (49/64), the refine table's copy of the
    # frame (3), the noise mask's quiet flags (1)
    # (+ per-row-segment and per-tile-column buffers and the noise census' 256 bytes per band of 8 rows: a little more on
    # small frames; this 30 x 20 one: 69.57)
    assert filt.device_bytes_per_pixel() <= 69.65


def test_submit_overlaps_and_keeps_order(filt):
    frames = [blocky(40 + k) for k in range(5)]
    want = [filt.process(f) for f in frames]
    pending = [filt.submit(f) for f in frames[:2]]
    got = []
    for f in frames[2:]:
        pending.append(filt.submit(f))
        got.append(pending.pop(0).result())
    got += [p.result() for p in pending]
    for g, w in zip(got, want):
        np.testing.assert_array_equal(g, w)


@pytest.mark.parametrize("kind", ["default", "fast", "float with NaN", "show regions", "keep"])
def test_each_result_call_returns_an_array_of_its_own(kind):
    """PendingFrame.result() called twice gave two views of one download buffer: a caller who drew on the first
    (cv2.putText) saw it in the second. Each call now returns an array of its own (the first the download itself,
    no copy: FastFilter's frames would pay one; later ones a copy)."""
    from mlaa_stream.spatial.fast_filter import FastFilter
    frame = blocky(9, dtype=np.float32 if kind == "float with NaN" else np.uint8)
    if kind == "float with NaN":
        frame[3, 5] = np.nan
    opts = {"show regions": dict(show="regions"), "keep": dict(keep="0,0,8,8")}.get(kind, {})
    with (FastFilter() if kind == "fast" else Filter(**opts)) as f:
        want = f.process(frame)
        pending = f.submit(frame)
        first = pending.result()
        second = pending.result()
        assert not np.shares_memory(first, second)
        np.testing.assert_array_equal(first, want)
        np.testing.assert_array_equal(second, want)
        first[...] = 0
        np.testing.assert_array_equal(second, want)
        third = pending.result()
        assert not np.shares_memory(third, first) and not np.shares_memory(third, second)


@pytest.mark.parametrize("bad,msg", [(np.zeros((4, 4, 2), np.uint8), "expected shape"),
                                     (np.zeros((4, 4, 3), np.int32), "expected uint8"),
                                     (np.zeros((0, 4, 3), np.uint8), "at least 1x1")])
def test_bad_frames_are_refused_before_any_kernel(filt, bad, msg):
    with pytest.raises((ValueError, TypeError), match=msg):
        filt.process(bad)


@pytest.mark.parametrize("shape", [(1, 1, 3), (1, 9, 3), (9, 1, 3), (2, 2, 3)])
def test_tiny_frames(filt, shape):
    img = np.random.default_rng(5).integers(0, 256, shape).astype(np.uint8)
    out = filt.process(img)
    np.testing.assert_array_equal(out, mlaa_reference(img))


def test_linear_float_frames_match_reference():
    """Float frames in linear light (EXR): edges compared after encoding, mixing done as they are."""
    img = blocky(13, dtype=np.float32) ** 2.2 * 1.5  # linear values, some above 1 (HDR)
    with Filter(linear_input=True) as f:
        got = f.process(img)
    want = mlaa_reference(img, linear_input=True)
    np.testing.assert_allclose(got, want, atol=2e-3)
    assert (np.abs(want - img) > 1e-4).mean() > 0.01


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_linear_integer_frames_match_reference(dtype):
    """Integer frames in linear light (16-bit linear TIFF): CIELAB from the per-level table, which encodes
    each level first (common.cl linear_levels), must give the reference's edges and output."""
    img = blocky(17, dtype=dtype)
    with Filter(linear_input=True, fallback="off") as f:
        got = f.process(img)
    want = mlaa_reference(img, linear_input=True)
    d = np.abs(got.astype(np.int64) - want.astype(np.int64))
    assert d.max() <= 1 and (d == 0).mean() > 0.999
    assert (want != img).any(axis=-1).mean() > 0.01


def test_display_space_blending_matches_reference():
    img = blocky(14)
    with Filter(linear=False) as f:
        got = f.process(img)
    want = mlaa_reference(img, linear=False)
    assert np.abs(got.astype(int) - want).max() <= 1


def test_cheap_rgb_bound_never_hides_a_lab_edge():
    """The early exit of edges.cl: ΔE76 <= LAB_LIPSCHITZ * max channel difference, on random pairs."""
    from mlaa_stream.spatial.filter import LAB_LIPSCHITZ
    rng = np.random.default_rng(8)
    a = rng.random((200000, 3))
    b = np.clip(a + (rng.random((200000, 3)) - 0.5) * rng.choice([0.002, 0.02, 0.1], (200000, 1)), 0, 1)
    de = np.linalg.norm(rgb_to_lab(a) - rgb_to_lab(b), axis=-1)
    assert (de <= LAB_LIPSCHITZ * np.abs(a - b).max(-1) + 1e-9).all()


# ---- grain guard (kernels/blend.cl in_grain, reference.grain_mask) ----------------------------------------

def grainy(seed: int, dtype=np.uint8, channels: int = 3) -> np.ndarray:
    """blocky() with a 20x24 patch of per-pixel grain (mid grey +-40 levels per channel) across its edges."""
    img = blocky(seed, channels=channels).astype(np.int64)
    rng = np.random.default_rng(seed)
    img[14:34, 20:44, :3] = 128 + rng.integers(-40, 41, (20, 24, min(channels, 3)))
    img = img.astype(np.uint8)
    if dtype == np.uint16:
        return img.astype(np.uint16) * 257
    if dtype == np.float32:
        return img.astype(np.float32) / 255.0
    return img


def test_grain_mask_known_answers():
    from mlaa_stream.spatial.reference import grain_mask
    rng = np.random.default_rng(3)
    flat = np.full((20, 24, 3), 90, np.uint8)
    assert not grain_mask(flat).any()
    checker = ((np.indices((20, 24)).sum(0) % 2) * 255).astype(np.uint8)   # 4 neighbours differ, 4 do not
    assert not grain_mask(checker).any()
    line = flat.copy()
    line[10, :] = 250                                                      # a 1-px line: 3 neighbours at most
    assert not grain_mask(line).any()
    noise = (128 + rng.integers(-60, 61, (20, 24, 3))).astype(np.uint8)     # grain: almost every pixel
    assert grain_mask(noise).mean() > 0.95
    # GRAIN_STEP - 1 levels do not count, GRAIN_STEP do: a checker of +-(GRAIN_STEP - 1) / 2 around grey is not grain
    from mlaa_stream.spatial.filter import GRAIN_STEP
    soft = (np.indices((20, 24)).sum(0) % 2 * (GRAIN_STEP - 1) + 100).astype(np.uint8)
    rnd = rng.integers(0, 2, (20, 24)).astype(np.uint8)
    assert not grain_mask(soft).any()
    assert grain_mask(rnd * GRAIN_STEP + 100).sum() > grain_mask(rnd * (GRAIN_STEP - 1) + 100).sum() == 0


def test_grain_is_left_untouched():
    """Per-pixel grain over a whole frame: the filter returns it unchanged; without the guard it would not."""
    img = (128 + np.random.default_rng(8).integers(-40, 41, (48, 64, 3))).astype(np.uint8)
    with Filter(bridge=False) as f:
        np.testing.assert_array_equal(f.process(img), img)
    with Filter(bridge=False, grain_guard=False) as f:
        assert (f.process(img) != img).any(-1).mean() > 0.02


@pytest.mark.parametrize("dtype,channels", [(np.uint8, 3), (np.uint16, 3), (np.float32, 3), (np.uint8, 1),
                                            (np.uint8, 4)])
def test_grain_guard_matches_reference(dtype, channels):
    """A render with a grain patch: kernel against mlaa_reference (<= 1 level, as the other formats); the guard
    keeps the patch and the reference without it would have changed pixels there."""
    from mlaa_stream.spatial.reference import grain_mask
    img = grainy(21, dtype, channels)
    if channels == 1:
        img = img[..., 0]
    with Filter(bridge=False, fallback="off", alpha="keep") as f:
        got = f.process(img)
    want = mlaa_reference(img)
    scale = {np.uint8: 1.0, np.uint16: 1 / 257.0, np.float32: 255.0}[dtype]
    assert np.abs(got.astype(np.float64) - want.astype(np.float64)).max() * scale <= 1.0 + 1e-6
    keep = grain_mask(img)
    assert keep.sum() > 100
    np.testing.assert_array_equal(got[keep], img[keep])
    unguarded = mlaa_reference(img, grain_guard=False)
    assert (unguarded[keep] != img[keep]).any()
    assert (got != img).any()   # the blocks' edges outside the patch are still antialiased


# ---- square ends of 2-px strokes (kernels/weights.cl stroke_end_h / stroke_end_v) ---------------------------

def _glyph_l(transpose: bool = False) -> np.ndarray:
    """An 'L' turned over: a 2-px stem 16 px tall hanging from a 2-px bar, pixel-aligned (hinted text)."""
    img = np.full((24, 20, 3), 240, np.uint8)
    img[2:4, 6:16] = 30     # the bar
    img[2:18, 6:8] = 30     # the stem, its square end at row 17
    return np.ascontiguousarray(img.transpose(1, 0, 2)) if transpose else img


@pytest.mark.parametrize("transpose", [False, True])
def test_square_end_of_a_2px_stroke_stays_sharp(transpose, monkeypatch):
    import mlaa_stream.spatial.filter as mlaa_module
    img = _glyph_l(transpose)
    with Filter(bridge=False) as f:
        got = f.intermediates(img)
    want = weights_reference(*_edges_and_distances(img), frame=img)
    _assert_weights_match(got, want)
    # the stem's border along its last rows: nothing taken across it (before the rule, the Z from the bar's
    # corner to the square end blended the stem's last 8 rows)
    stem = (slice(10, 18), 7) if not transpose else (7, slice(10, 18))
    assert not want[stem].any()
    np.testing.assert_array_equal(got["out"], img)
    monkeypatch.setattr(mlaa_module, "STROKE_END_MIN_L", 10 ** 6)
    assert weights_reference(*_edges_and_distances(img), frame=img)[stem].any()


def test_a_2px_step_of_a_filled_shape_is_still_blended():
    """The same 2-px crossing where the border goes on the other way (a staircase step) is a jaggy."""
    img = np.full((24, 20, 3), 240, np.uint8)
    img[:12, 6:] = 30
    img[12:, 8:] = 30
    with Filter(bridge=False) as f:
        got = f.intermediates(img)
    want = weights_reference(*_edges_and_distances(img), frame=img)
    _assert_weights_match(got, want)
    assert want[:12, 5:7].any() and (got["out"] != img).any()


# ---- 1-px strokes (kernels/weights.cl STEM_MIN_L, STEM_K) -----------------------------------------------

def _stem(transpose: bool = False, bump: bool = False) -> np.ndarray:
    """A 1-px stem 12 px tall at column 9, rows 4..15 (small text's 'l'); with `bump`, the same column sits on
    a filled block below instead (a 1-px plateau of a shape: the bump of a curve, not a stroke)."""
    img = np.full((24, 20, 3), 240, np.uint8)
    img[4:16, 9] = 30
    if bump:
        img[4:16, 9] = 240
        img[8, 4:16] = 30      # the plateau: 12 px wide, 1 px high
        img[9:20, 1:19] = 30   # the block under it
    return np.ascontiguousarray(img.transpose(1, 0, 2)) if transpose else img


@pytest.mark.parametrize("transpose", [False, True])
def test_long_1px_stem_is_not_tapered_as_a_bump(transpose, monkeypatch):
    """Known answer: each side of a 1-px stem of length L = 12 is a U shape whose 1-px crossings are the stem's
    ends; the stem pixel at distances (d0, d1) from them takes STEM_K * (A(d0, L) + A(d1, L)) of its neighbour
    (seed 000 eq. 2), the neighbour nothing. Without the rule (STEM_MIN_L huge) the full areas."""
    import mlaa_stream.spatial.filter as mlaa_module
    img = _stem(transpose)
    with Filter(bridge=False, subpixel=0.0) as f:
        got = f.intermediates(img)
    want = weights_reference(*_edges_and_distances(img), frame=img)
    _assert_weights_match(got, want)
    k = mlaa_module.STEM_K
    area = np.array([trapezoid_area(d, 12) + trapezoid_area(11 - d, 12) for d in range(12)])
    w = want if not transpose else want.transpose(1, 0, 2)[..., [2, 3, 0, 1]]
    np.testing.assert_allclose(w[4:16, 9, 2], k * area, atol=1e-12)   # the stem takes from its left ...
    np.testing.assert_allclose(w[4:16, 9, 3], k * area, atol=1e-12)   # ... and right neighbour
    assert not w[4:16, 8, 3].any() and not w[4:16, 10, 2].any()       # they take nothing from it
    monkeypatch.setattr(mlaa_module, "STEM_MIN_L", 10 ** 6)
    w = weights_reference(*_edges_and_distances(img), frame=img)
    w = w if not transpose else w.transpose(1, 0, 2)[..., [2, 3, 0, 1]]
    np.testing.assert_allclose(w[4:16, 9, 2], area, atol=1e-12)
    with Filter(bridge=False, subpixel=0.0) as f:
        _assert_weights_match(f.intermediates(img), w if not transpose else w.transpose(1, 0, 2)[..., [2, 3, 0, 1]])


@pytest.mark.parametrize("transpose", [False, True])
def test_1px_bump_of_a_filled_shape_is_still_blended_in_full(transpose):
    """The same U shape on a plateau whose far side is the shape itself (no edge there): a curve's bump."""
    img = _stem(transpose, bump=True)
    with Filter(bridge=False, subpixel=0.0) as f:
        got = f.intermediates(img)
    want = weights_reference(*_edges_and_distances(img), frame=img)
    _assert_weights_match(got, want)
    w = want if not transpose else want.transpose(1, 0, 2)[..., [2, 3, 0, 1]]
    area = np.array([trapezoid_area(d, 12) + trapezoid_area(11 - d, 12) for d in range(12)])
    np.testing.assert_allclose(w[8, 4:16, 0], area, atol=1e-12)   # the plateau takes from above, unscaled


def _assert_weights_match(got: dict, want: np.ndarray) -> None:
    """The kernel's weights equal the reference's in the slots it writes (next to an edge)."""
    b, rt = (got["edges"] & 1) > 0, (got["edges"] & 2) > 0
    valid = np.zeros_like(want, dtype=bool)
    valid[1:, :, 0] = b[:-1]
    valid[:, :, 1] = b
    valid[:, 1:, 2] = rt[:, :-1]
    valid[:, :, 3] = rt
    np.testing.assert_allclose(got["weights"][valid] / 65535.0, want[valid], atol=1e-4)


def _edges_and_distances(img: np.ndarray):
    e = edges_reference(img)
    hd, vd = distances_reference(e)
    return e, hd, vd


def test_antialiased_guard_ignores_texture_beside_a_1spp_edge(filt):
    """The antialiased guard's narrow window (kernels/edges.cl `antialiased`, AA_NEAR and AA_OFF): a
    1-spp edge between grey 90 (above) and grey 200 (below) whose upper side holds texture -- a pixel
    a fifth of the way towards the other side (x = 5, float path; x = 12, lane path), or a colour
    half-way in value but far off the grey segment (x = 28) -- keeps the edge beside it; a coverage
    mix half-way on the segment (x = 20: already antialiased) still turns it off."""
    img = np.full((16, 40, 3), 90, np.uint8)
    img[8:] = 200
    img[7, 5] = img[7, 12] = 112          # t = 0.2 < AA_NEAR: texture, not coverage
    img[7, 20] = 145                      # t = 0.5 on the segment: a coverage ramp
    img[7, 28] = (180, 100, 145)          # t = 0.47, off the segment by 0.3 of the step (> AA_OFF)
    got = filt.intermediates(img)["edges"]
    want = edges_reference(img, filt.options.threshold)
    np.testing.assert_array_equal(got, want)
    for x in (4, 6, 11, 13, 27, 29):
        assert got[7, x] & 1, f"edge beside texture at x = {x} lost"
    for x in (19, 21):
        assert not got[7, x] & 1, f"edge beside a coverage mix at x = {x} kept"


@pytest.mark.parametrize("value", [230, 20])
def test_subpixel_dot_moves_towards_its_surroundings(value):
    """A lone 1-spp dot (edges on four sides; a cable or fence wire far away), bright or dark, on grey 120:
    blend.cl's SUBPIXEL rule moves it half-way (in linear light) to the mean of its 3x3 window, as the
    reference does; with subpixel=0 it stays as MLAA leaves it. A pixel with edges on three sides that lies
    between its neighbours (a coverage step of antialiased content) is not a feature and is left alone, nor is
    speckle whose neighbours share no background (a photograph's or a texture's own detail: SUBPIXEL_BG)."""
    from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
    img = np.full((12, 24, 3), 120, np.uint8)
    img[5, 10] = value
    img[:, 18] = 240                            # a light stripe, and beside it a 1-px green line whose
    img[2:9, 17] = (40, 160, 40)                # ends (2, 17) and (8, 17) lie between 120 and 240 in luma
    img[5, 4], img[4, 4], img[6, 4], img[7, 4] = 250, (30, 30, 200), 225, 250   # speckle: a light pixel
    img[5, 3], img[5, 5] = (200, 40, 40), (40, 160, 40)                         # (5, 4) on no one background
    with Filter(bridge=False) as f:
        out = f.process(img)
    with Filter(bridge=False, subpixel=0.0) as f:
        plain = f.process(img)
    np.testing.assert_array_equal(out, mlaa_reference(img))
    lin_c, lin_bg = srgb_to_linear(value / 255.0), srgb_to_linear(120 / 255.0)
    plain_c = srgb_to_linear(plain[5, 10, 0] / 255.0)
    want = linear_to_srgb(plain_c + 0.5 * ((lin_c + 8 * lin_bg) / 9 - plain_c)) * 255
    assert abs(int(out[5, 10, 0]) - want) <= 1
    assert abs(int(out[5, 10, 0]) - 120) < abs(int(plain[5, 10, 0]) - 120)
    np.testing.assert_array_equal(out[:, 15:20], plain[:, 15:20])
    np.testing.assert_array_equal(out[:, :7], plain[:, :7])
    assert (out[5, 4] == 250).all()


@pytest.mark.parametrize("value", [20, 235])
def test_subpixel_move_is_shared_by_the_neighbours_across_its_edges(value):
    """Known answer (blend.cl SUBPIXEL_SHARE): the ink a lone dot loses (or gains) goes to the four neighbours
    across its edges, a quarter each, in linear light -- a thin feature keeps its weight instead of fading.
    With b the dot's colour after the line blends (subpixel=0), the dot moves by delta = SUBPIXEL (box - b);
    each neighbour moves by -SUBPIXEL_SHARE delta / 4 from where the line blends left it, so the five moves
    sum to 0 up to rounding; kernel and reference agree exactly."""
    from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
    from mlaa_stream.spatial.filter import SUBPIXEL, SUBPIXEL_SHARE
    img = np.full((12, 16, 3), 120, np.uint8)
    img[5, 7] = value
    with Filter(bridge=False) as f:
        out = f.process(img)
    with Filter(bridge=False, subpixel=0.0) as f:
        plain = f.process(img)
    np.testing.assert_array_equal(out, mlaa_reference(img))
    lin = lambda v: srgb_to_linear(np.asarray(v, np.float64) / 255.0)
    b = lin(plain[5, 7, 0])
    delta = SUBPIXEL * ((lin(value) + 8 * lin(120)) / 9 - b)
    assert abs(int(out[5, 7, 0]) - linear_to_srgb(b + delta) * 255) <= 1
    sides = ((4, 7), (6, 7), (5, 6), (5, 8))
    for y, x in sides:
        want = linear_to_srgb(lin(plain[y, x, 0]) - SUBPIXEL_SHARE * delta / 4) * 255
        assert abs(int(out[y, x, 0]) - want) <= 1, (y, x, out[y, x, 0], want)
    moves = [lin(out[y, x, 0]) - lin(plain[y, x, 0]) for y, x in [(5, 7), *sides]]
    assert abs(sum(moves)) < abs(delta) * 0.05 + 5 * 0.5 / 255   # ink kept, up to rounding
    assert out[4, 6, 0] == plain[4, 6, 0] and out[6, 8, 0] == plain[6, 8, 0]  # diagonals share no edge
