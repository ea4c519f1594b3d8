"""Temporal supersampling (issue 16): kernels/tss.cl against tss_frame_reference, and known answers on
scenes with supersampled truth (static shot, sub-pixel pan, hard cut, fast mover)."""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.bench.temporal import scene_cut, scene_mover, scene_pan
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.temporal.resolve import tss_frame_reference
from mlaa_stream.temporal.tss import TSSStage
from mlaa_stream.yardstick import metrics as M


@pytest.fixture(scope="module")
def stage_parts():
    from mlaa_stream.device.context import default_context
    return default_context(None)


def _random_ring(rng, h, w, channels, dtype, k, dense, fs=1):
    def frame():
        shape = (h, w) if channels == 1 else (h, w, channels)
        if dtype == np.float32:
            return rng.random(shape, np.float32)
        hi = 255 if dtype == np.uint8 else 65535
        # blocks with noise: boxes that admit samples, edges that reject some
        base = rng.integers(0, hi + 1, (h // 4 + 1, w // 4 + 1) + shape[2:]).repeat(4, 0).repeat(4, 1)[:h, :w]
        return np.clip(base + rng.integers(-hi // 20, hi // 20, shape), 0, hi).astype(dtype)
    fh, fw = -(-h // fs), -(-w // fs)
    ring = []
    for j in range(k - 1):
        f = frame()
        if dense and j % 2:
            fld = rng.normal(0, 1.5, (fh, fw, 2)).astype(np.float32)
            fld[rng.random((fh, fw)) < 0.05] = np.nan
            ring.append((f, fld, (rng.random((fh, fw)) > 0.1).astype(np.uint8)))
        else:
            ring.append((f, (float(rng.normal(0, 2)), float(rng.normal(0, 2))), None))
    cur = frame()
    ring.append((cur, (0.0, 0.0), None))
    return cur, frame(), ring


def _run_kernel(stage, cur, spatial, ring, bgr, fs):
    """Drive the device path of TSSStage with a hand-made ring (maps and valid masks as given)."""
    from mlaa_stream.temporal.motion_ring import FrameMotion, RingEntry
    from mlaa_stream.temporal.stage import Decision, Pyramid
    import pyopencl as cl
    h, w = cur.shape[:2]
    pyr = Pyramid(np.zeros((-(-h // fs), -(-w // fs)), np.uint8), np.zeros((1, 1), np.uint8), fs, 1)
    bufs = stage._prepare(cur, pyr)
    entries = []
    for j, (f, m, ok) in enumerate(ring):
        e = RingEntry(j, None, pyr, shift=None if isinstance(m, np.ndarray) else m,
                      field=m if isinstance(m, np.ndarray) else None, slot=j, valid=ok)
        if j < len(ring) - 1:
            stage._ingest(f, pyr, j, j)
        entries.append(e)
    out, cells = stage._resolve(cur, spatial, pyr, FrameMotion(Decision("global"), entries), [])
    return out, cells.copy()


@pytest.mark.parametrize("channels,dtype,bgr,dense,fs,k", [
    (3, np.uint8, False, False, 1, 7), (3, np.uint8, False, False, 1, 20), (4, np.uint8, True, False, 2, 7),
    (4, np.uint16, False, False, 1, 7), (1, np.float32, False, False, 2, 7), (1, np.uint8, False, False, 2, 12),
    (3, np.uint8, True, True, 1, 7), (4, np.uint16, False, True, 2, 7),
    (1, np.float32, False, True, 2, 7), (3, np.uint8, False, True, 2, 7)])
def test_kernel_matches_reference(stage_parts, channels, dtype, bgr, dense, fs, k):
    """tss_resolve (dense maps, FULL_CELLS_FIELDS) and tss_resolve_shift (the default translation path; 53 px wide: three
    full 16-pixel groups and a partial one; K = 20 puts several frames in some cells) against the
    reference: bit-identical."""
    rng = np.random.default_rng(channels * 7 + fs + k)
    h, w = 37, 53
    cur, spatial, ring = _random_ring(rng, h, w, channels, dtype, k, dense, fs)
    if not dense:   # translation maps with valid masks on some frames (the per-tile check's output)
        fh, fw = -(-h // fs), -(-w // fs)
        ring = [(f, m, (rng.random((fh, fw)) > 0.2).astype(np.uint8) if j % 3 == 1 else None)
                for j, (f, m, _) in enumerate(ring)]
    stage = TSSStage(frames=k + 1, bgr=bgr, context=stage_parts, dense_samples=dense)
    out, cells = _run_kernel(stage, cur, spatial, ring, bgr, fs)
    from mlaa_stream.temporal.resolve import GRID, EPS, MIN_CELLS
    ref, rcells = tss_frame_reference(spatial, cur, ring, bgr, fs, GRID, EPS, MIN_CELLS,
                                      stage.field_full_cells if dense else stage.full_cells)
    assert np.array_equal(cells, rcells) and cells.max() >= 2
    assert np.array_equal(out, ref)
    assert np.array_equal(out[cells < 2], spatial[cells < 2])


@pytest.mark.parametrize("grid", [3, 8])
def test_kernel_matches_reference_at_other_grids(stage_parts, grid):
    """Both resolves at footprints of 3x3 and 8x8 cells (tss_resolve keeps one bit per cell in a 64-bit word:
    8x8 fills its top bit) against the reference: bit-identical; a grid over 8 is refused."""
    from mlaa_stream.temporal.resolve import EPS, MIN_CELLS
    rng = np.random.default_rng(40 + grid)
    h, w, fs, k = 37, 53, 2, 24
    for dense in (True, False):
        cur, spatial, ring = _random_ring(rng, h, w, 3, np.uint8, k, dense, fs)
        if dense:   # small motion: most samples pass the colour box and spread over the footprint's cells
            ring = [(f, m * np.float32(0.3), ok) if isinstance(m, np.ndarray) else (f, m, ok) for f, m, ok in ring]
        stage = TSSStage(frames=k + 1, bgr=False, context=stage_parts, dense_samples=dense, grid=grid)
        out, cells = _run_kernel(stage, cur, spatial, ring, False, fs)
        ref, rcells = tss_frame_reference(spatial, cur, ring, False, fs, grid, EPS, MIN_CELLS,
                                          stage.field_full_cells if dense else stage.full_cells)
        assert np.array_equal(cells, rcells) and cells.max() >= 4
        assert np.array_equal(out, ref)
    with pytest.raises(ValueError, match="grid: expected 1 to 8"):
        TSSStage(frames=4, context=stage_parts, grid=9)


@pytest.mark.parametrize("linear,dense", [(True, False), (True, True), (False, False), (False, True)])
def test_kernel_matches_reference_on_hdr_float_frames(stage_parts, linear, dense):
    """Float frames above 1 (HDR renders; linear light: the ring spans [0, LINEAR_RANGE]): bit-identical to the
    reference, and every pixel whose 3x3 input box or spatial pixel is over the ring's range keeps the spatial
    pixel bit for bit (a sample over range is never averaged: before, such values came out clipped or as NaN)."""
    import cv2
    from mlaa_stream.temporal.resolve import EPS, GRID, LINEAR_RANGE, MIN_CELLS
    rng = np.random.default_rng(11 + 2 * linear + dense)
    h, w, fs, k = 37, 53, 2 if dense else 1, 9
    cur, spatial, ring = _random_ring(rng, h, w, 3, np.float32, k, dense, fs)

    def hdr(f):   # 4x4 blocks at 1x, 3x (over 1, within the linear range) and over the linear range
        gain = rng.choice([1.0, 3.0, 1.25 * LINEAR_RANGE], (h // 4 + 1, w // 4 + 1), p=[0.7, 0.15, 0.15])
        return (f * gain.repeat(4, 0).repeat(4, 1)[:h, :w, None]).astype(np.float32)
    ring = [(hdr(f), m, ok) for f, m, ok in ring[:-1]]
    cur = hdr(cur)
    ring.append((cur, (0.0, 0.0), None))
    spatial = hdr(spatial)
    stage = TSSStage(frames=k + 1, bgr=False, context=stage_parts, dense_samples=dense, linear_input=linear)
    out, cells = _run_kernel(stage, cur, spatial, ring, False, fs)
    ref, rcells = tss_frame_reference(spatial, cur, ring, False, fs, GRID, EPS, MIN_CELLS,
                                      stage.field_full_cells if dense else stage.full_cells, linear)
    assert np.array_equal(cells, rcells) and cells.max() >= 2
    assert np.array_equal(out, ref) and np.isfinite(out).all()
    top = LINEAR_RANGE if linear else 1.0
    over = cv2.dilate((cur > top).any(-1).astype(np.uint8), np.ones((3, 3), np.uint8),
                      borderType=cv2.BORDER_REPLICATE).astype(bool) | (spatial > top).any(-1)
    assert over.mean() > 0.2
    assert np.array_equal(out[over], spatial[over])
    changed = (out != spatial).any(-1)
    assert changed[~over].mean() > 0.05
    if linear:   # values over 1 within the range are resolved, not clipped
        assert (changed & (out > 1.0).any(-1)).any()


def test_half_float_frames_are_resolved_as_float32(stage_parts):
    """float16 frames (half EXR) give the float32 run's output in float16 (they were read as float32 bytes)."""
    sc = scene_pan(6, 96, 64)
    lin = [(np.asarray(f, np.float32) / 255.0) ** 2.2 for f in sc.inputs]
    outs = {}
    for dtype in (np.float32, np.float16):
        stage = TSSStage(frames=6, bgr=False, context=stage_parts, linear_input=True)
        outs[dtype] = [stage(f.astype(dtype), f.astype(dtype), i) for i, f in enumerate(lin)]
    assert all(o.dtype == np.float16 for o in outs[np.float16])
    half_in = [f.astype(np.float16).astype(np.float32) for f in lin]
    stage = TSSStage(frames=6, bgr=False, context=stage_parts, linear_input=True)
    want = [stage(f, f, i).astype(np.float16) for i, f in enumerate(half_in)]
    assert any(not np.array_equal(o, f.astype(np.float16)) for o, f in zip(outs[np.float16], lin))   # TSS acted
    assert all(np.array_equal(a, b) for a, b in zip(outs[np.float16], want))


@pytest.fixture(scope="module")
def filt():
    with Filter(None, bgr=False) as f:
        yield f


def _run(stage, scene, spatial):
    return np.stack([stage(f, s, i) for i, (f, s) in enumerate(zip(scene.inputs, spatial))])


def test_static_scene_returns_the_spatial_output(filt):
    sc = scene_pan(1, 120, 68)
    noisy = []
    rng = np.random.default_rng(1)
    for _ in range(6):   # a still shot through a codec: +-1 level on a few samples
        f = sc.inputs[0].astype(np.int16) + (rng.random(sc.inputs[0].shape) < 0.01)
        noisy.append(np.clip(f, 0, 255).astype(np.uint8))
    stage = TSSStage(bgr=False)
    for i, f in enumerate(noisy):
        sp = filt.process(f)
        out = stage(f, sp, i)
        assert np.array_equal(out, sp)
    assert {r["model"] for r in stage.stats[1:]} == {"static"}



def test_history_view_on_repeated_frames_and_with_auto(filt):
    """--show history: a repeated frame (a still shot) shows the view of the frame it repeats, not the image; "auto"
    shows TSS's samples per pixel (its blend, only in render regions, would show rejection everywhere else)."""
    from mlaa_stream.temporal.methods import make_stage
    still = scene_pan(1, 120, 68).inputs[0]
    sp = filt.process(still)
    with TSSStage(bgr=False, show="history") as stage:
        views = [stage(still, sp, i) for i in range(3)]
    assert [r["model"] for r in stage.stats] == ["reset", "static", "static"]
    assert not np.array_equal(views[0], sp)
    assert all(np.array_equal(v, views[0]) for v in views[1:])
    sc = scene_pan(5, 160, 96)
    spatial = [filt.process(f) for f in sc.inputs]
    with TSSStage(context=filt.context, bgr=False, show="history") as tss, \
            make_stage("auto", filt.context, bgr=False, show="history") as auto:
        for i, (f, s) in enumerate(zip(sc.inputs, spatial)):
            np.testing.assert_array_equal(auto(f, s, i), tss(f, s, i))
    assert any(r["samples_share"] > 0 for r in tss.stats)


def test_a_ring_larger_than_the_device_allows_is_named(filt):
    # Antialiaser(temporal_frames=...) has no upper bound: a ring past the device's largest buffer was OpenCL's
    # INVALID_BUFFER_SIZE at frame 0, naming neither the frames nor the size
    f = np.zeros((512, 512, 3), np.uint8)   # 1.5 TiB of ring: past any device's largest buffer
    with TSSStage(context=filt.context, bgr=False, frames=10**6, lookahead=2) as stage:
        with pytest.raises(ValueError, match=r"a ring of 1000002 frames \(K and the look-ahead\) of 512x512 takes .* "
                                             r"more than the device allows"):
            stage(f, f, 0)

def test_subpixel_pan_converges_toward_the_truth(filt):
    sc = scene_pan(12, 320, 180)
    spatial = [filt.process(f) for f in sc.inputs]
    stage = TSSStage(bgr=False, frames=12)
    outs = _run(stage, sc, spatial)
    assert sum(r["model"] == "global" for r in stage.stats[1:]) >= 8
    late = slice(8, 12)
    tss = M.error_removed(outs[late], sc.inputs[late], sc.truths[late])
    sp = M.error_removed(np.stack(spatial)[late], sc.inputs[late], sc.truths[late])
    assert tss > sp + 0.1, (tss, sp)
    assert stage.stats[-1]["cells_mean"] > 4


def test_grain_keeps_the_spatial_pixel_where_the_window_is_quiet(filt):
    """Grain new every frame (part of the truth) over a sub-pixel pan: where the input's window spans no more than
    the grain (spatial/noise.py quiet_pixels) the spatial pixel stands; edges still take samples, and against the
    truth with its grain the stage removes more error than the spatial filter and keeps the grain's frame-to-frame
    change (the ring's samples would average it away: temporal error 1.7x the spatial output's without the rule, 0.8x
    with it)."""
    from mlaa_stream.spatial.noise import noise_level, quiet_pixels
    sc = scene_pan(12, 320, 180)
    rng = np.random.default_rng(3)
    grain = rng.normal(0, 4, sc.inputs.shape[:3] + (1,))
    inputs, truths = (np.clip(np.round(a + grain), 0, 255).astype(np.uint8) for a in (sc.inputs, sc.truths))
    spatial = [filt.process(f) for f in inputs]
    stage = TSSStage(bgr=False, frames=12)
    outs = np.stack([stage(f, s, i) for i, (f, s) in enumerate(zip(inputs, spatial))])
    assert noise_level(inputs[5]) >= 12 and all(r["noise_level"] >= 12 for r in stage.stats)
    for t in (4, 11):
        quiet = quiet_pixels(inputs[t])
        assert 0.5 < quiet.mean() < 0.99
        np.testing.assert_array_equal(outs[t][quiet], spatial[t][quiet])
        assert np.any(outs[t][~quiet] != spatial[t][~quiet])
    late = slice(6, 12)
    assert M.error_removed(outs[late], inputs[late], truths[late]) > M.error_removed(
        np.stack(spatial)[late], inputs[late], truths[late])
    assert M.temporal_error(outs, inputs, truths) < 0.9 * M.temporal_error(np.stack(spatial), inputs, truths)


def test_cut_resets_and_returns_the_spatial_frame(filt):
    sc = scene_cut(10, 160, 90)
    spatial = [filt.process(f) for f in sc.inputs]
    stage = TSSStage(bgr=False)
    outs = _run(stage, sc, spatial)
    models = [r["model"] for r in stage.stats]
    assert models[0] == "reset" and models[5] == "reset" and "reset" not in models[6:]
    assert np.array_equal(outs[5], spatial[5])
    assert stage.stats[5]["ring"] == 1


def test_fast_mover_leaves_no_ghost(filt):
    sc = scene_mover(8, 160, 90)
    spatial = np.stack([filt.process(f) for f in sc.inputs])
    stage = TSSStage(bgr=False)
    outs = _run(stage, sc, spatial)
    truth = sc.truths.astype(np.float32)
    err_t = np.abs(outs.astype(np.float32) - truth).max(-1)
    err_s = np.abs(spatial.astype(np.float32) - truth).max(-1)
    # no pixel of a trail: nowhere much further from the truth than the spatial output
    assert (err_t - err_s).max() < 40
    assert M.error_removed(outs, sc.inputs, sc.truths) >= M.error_removed(spatial, sc.inputs, sc.truths) - 0.005


def test_index_jump_and_size_change_reset(filt):
    sc = scene_pan(4, 96, 54)
    stage = TSSStage(bgr=False)
    for i in (0, 1, 5):
        stage(sc.inputs[min(i, 3)], filt.process(sc.inputs[min(i, 3)]), i)
    models = [r["model"] for r in stage.stats]
    assert models[0] == "reset" and models[1] != "reset" and models[2] == "reset"
    small = np.ascontiguousarray(sc.inputs[0][:40, :60])
    stage(small, filt.process(small), 6)
    assert stage.stats[-1]["model"] == "reset"


def test_sample_type_change_starts_a_new_ring(filt):
    # the same pan as uint8, then as uint16: a new type is a new ring (it used to be taken for a repeated
    # frame, returning the previous uint8 output, or to fail with a KeyError on the ring's slots)
    sc = scene_pan(6, 96, 54)
    stage = TSSStage(bgr=False)
    for i, f in enumerate(sc.inputs[:3]):
        stage(f, filt.process(f), i)
    wide = [f.astype(np.uint16) * np.uint16(257) for f in sc.inputs[2:]]
    for i, f in enumerate(wide, start=3):
        sp = filt.process(f)
        out = stage(f, sp, i)
        assert out.dtype == np.uint16 and out.shape == f.shape
        if i == 3:
            assert stage.stats[-1]["model"] == "reset" and np.array_equal(out, sp)


def test_numpy_backend_is_the_reference(filt):
    sc = scene_pan(5, 96, 54)
    spatial = [filt.process(f) for f in sc.inputs]
    a, b = TSSStage(bgr=False), TSSStage(bgr=False, backend="numpy")
    for i, (f, s) in enumerate(zip(sc.inputs, spatial)):
        assert np.array_equal(a(f, s, i), b(f, s, i))


def _run_ahead(stage, scene, spatial, n):
    """The scene through a stage reading n frames ahead (fewer at the end), as the pipeline hands them in."""
    return np.stack([stage(f, s, i, future=scene.inputs[i + 1:i + 1 + n])
                     for i, (f, s) in enumerate(zip(scene.inputs, spatial))])


def test_lookahead_numpy_backend_is_the_reference(filt):
    """Look-ahead frames through the device (slots of their own, ingested once) and the numpy reference: bit
    for bit, the end of the shot (fewer frames ahead) included."""
    sc = scene_pan(6, 240, 136)
    spatial = [filt.process(f) for f in sc.inputs]
    a, b = TSSStage(bgr=False, frames=4, lookahead=2), TSSStage(bgr=False, frames=4, lookahead=2, backend="numpy")
    outs_a, outs_b = _run_ahead(a, sc, spatial, 2), _run_ahead(b, sc, spatial, 2)
    assert np.array_equal(outs_a, outs_b)
    assert [r["lookahead"] for r in a.stats] == [2, 2, 2, 2, 1, 0]


def test_lookahead_fills_the_first_frame(filt):
    """Without look-ahead the first frame of a pan has no other samples and is the spatial output bit for bit;
    with two frames ahead its pixels take samples and it is closer to the truth. Over the shot the look-ahead
    run removes more error."""
    sc = scene_pan(8, 320, 180)
    spatial = [filt.process(f) for f in sc.inputs]
    causal = _run(TSSStage(bgr=False, frames=8), sc, spatial)
    stage = TSSStage(bgr=False, frames=8, lookahead=2)
    ahead = _run_ahead(stage, sc, spatial, 2)
    assert np.array_equal(causal[0], spatial[0])
    assert stage.stats[0]["model"] == "reset" and stage.stats[0]["samples_share"] > 0.05
    first = M.error_removed(ahead[:1], sc.inputs[:1], sc.truths[:1])
    assert first > M.error_removed(causal[:1], sc.inputs[:1], sc.truths[:1]) + 0.05
    assert M.error_removed(ahead, sc.inputs, sc.truths) > M.error_removed(causal, sc.inputs, sc.truths)


def test_lookahead_stops_at_a_cut(filt):
    """No sample from after a cut before it: the frames just before the cut read no frame past it, and their
    outputs are those of a stage that never saw the second shot."""
    sc = scene_cut(10, 160, 90)
    spatial = [filt.process(f) for f in sc.inputs]
    stage = TSSStage(bgr=False, lookahead=3)
    outs = _run_ahead(stage, sc, spatial, 3)
    assert [r["lookahead"] for r in stage.stats[2:5]] == [2, 1, 0]
    first_shot = TSSStage(bgr=False, lookahead=3)
    alone = np.stack([first_shot(f, s, i, future=sc.inputs[i + 1:5]) for i, (f, s) in
                      enumerate(zip(sc.inputs[:5], spatial[:5]))])
    assert np.array_equal(outs[:5], alone)


def _two_edges(y_top: float, y_bottom: float, w: int = 240, h: int = 144) -> np.ndarray:
    """Grey float32 frame (blurred as the refiner reads it): two long horizontal edges of equal contrast
    at y_top and y_bottom (sub-pixel positions, by area coverage of the row they cross), plus static
    vertical edges every 32 px (added, so the gradients stay separable) that fix the horizontal motion."""
    import cv2
    ys = np.arange(h, dtype=np.float64)[:, None] + 0.5
    xs = np.arange(w, dtype=np.float64)[None, :]
    img = 40.0 + 100.0 * np.clip(ys - y_top, 0, 1) - 100.0 * np.clip(ys - y_bottom, 0, 1)
    img = img + 60.0 * ((xs // 32) % 2)
    return cv2.GaussianBlur(np.broadcast_to(img, (h, w)).astype(np.float32), (0, 0), 1.0)


def test_band_check_masks_a_second_motion_along_long_edges():
    """Known answer (_Refiner._band_deviations): the upper edge moved 0.6 px between the ring frame and the
    current one, the lower edge did not (a static border over a pan). The frame's translation splits the
    difference, so each edge's row band is ~0.3 px off it: both bands (rows 32-63 and 64-95 with
    BAND = 32) lose that frame's samples, every other row keeps them, and no column band is masked
    (the vertical edges did not move). With both edges moved alike nothing is masked. The 48-px tile
    check cannot see this: the tiles on the horizontal edges hold one edge direction only. (240 x 144:
    whole 48-px tiles, so no partial tile row copies a band's mask.)"""
    from mlaa_stream.temporal import motion_ring as T
    assert T.BAND == 32
    ring = _two_edges(40.0, 80.0)
    d, valid = T._Refiner(_two_edges(40.6, 80.0)).step(ring, (0.0, 0.0))
    assert -0.45 < d[1] < -0.15 and abs(d[0]) < 0.02, d     # cur(x) ~ ring(x + d): the moved edge says -0.6
    assert valid is not None
    assert set(np.flatnonzero(valid.min(1) == 0)) == set(range(32, 96))
    assert valid[:32].all() and valid[96:].all()
    d2, valid = T._Refiner(_two_edges(40.6, 80.6)).step(ring, (0.0, 0.0))
    assert valid is None and abs(d2[1] + 0.6) < 0.15, d2


def test_still_bands_leave_the_estimate_and_lose_their_samples():
    """Known answer (_Refiner._band_weights): the upper edge moved 0.6 px, the lower one is still (a
    static border over a pan). The first step averages the two (about -0.3); the still band (own motion
    0 while the frame's is over 2 STATIC_TOL) then counts for nothing, so the translation converges to
    the moving edge's -0.6 px, and the last step's band check masks the still band's rows (64-95: 0.6 px
    off the frame) and keeps the moving one's (the tile check masks its 48-px tiles, rows 48-95, too)."""
    from mlaa_stream.temporal import motion_ring as T
    assert T.BAND == 32 and T.STATIC_TOL > 0
    ring = _two_edges(40.0, 80.0)
    ref = T._Refiner(_two_edges(40.6, 80.0))
    d, weights, valid = (0.0, 0.0), None, None
    for k in range(3):
        d, valid = ref.step(ring, d, check=k == 2, weights=weights)
        weights = ref.band_weights
    assert abs(d[1] + 0.6) < 0.1 and abs(d[0]) < 0.02, d
    assert valid is not None
    assert not valid[64:96].any()           # the still band (and the 48-px tiles holding it: rows 48-95)
    assert valid[:48].all() and valid[96:].all()   # the moving edge's rows keep their samples


@pytest.mark.parametrize("dtype,level", [(np.uint8, 1), (np.uint16, 257)])
def test_dead_zone_keeps_the_spatial_pixel(stage_parts, dtype, level):
    """Known answer: an input of columns alternating 100 and 101 levels (not flat, so the ring is read),
    seen at 12 distinct sub-pixel phases, resolves every inner pixel to 100 or 101 levels. A spatial output
    of 101 is then within one 8-bit level everywhere and is kept bit for bit (the dead zone); one of 105 is
    replaced by the resolve (kernel and reference alike)."""
    h, w = 24, 40
    cols = (100 + np.arange(w) % 2) * level
    cur = np.repeat(np.repeat(cols[None, :, None], h, 0), 3, 2).astype(dtype)
    ring = [(cur, (0.25 * (j % 4) + 0.1, 0.25 * (j // 4) + 0.1), None) for j in range(11)]
    ring.append((cur, (0.0, 0.0), None))
    inner = (slice(2, -2), slice(2, -2))     # the last row and column lose the far phases' samples
    for value in (101, 105):
        spatial = np.full((h, w, 3), value * level, dtype)
        ref, cells = tss_frame_reference(spatial, cur, ring, False)
        assert cells[inner].min() >= 9
        if value == 101:
            assert np.array_equal(ref[inner], spatial[inner])
        else:
            tol = 0 if level == 1 else 2             # uint16: the 16-bit linear ring's rounding
            r = ref[inner].astype(int)
            assert ((r >= 100 * level - tol) & (r <= 101 * level + tol)).all(), np.unique(r)
        stage = TSSStage(frames=len(ring) + 1, bgr=False, context=stage_parts)
        out, _ = _run_kernel(stage, cur, spatial, ring, False, 1)
        assert np.array_equal(out, ref)


def test_flat_neighbourhood_keeps_the_spatial_pixel(stage_parts):
    """Known answer: where the current frame's 3x3 is flat (here: everywhere) no sample is read and the
    spatial pixel stands, even if the ring disagrees by less than the colour box's widening."""
    h, w = 20, 37
    cur = np.full((h, w, 3), 100, np.uint8)
    other = np.full((h, w, 3), 103, np.uint8)
    ring = [(other, (0.25 * (j % 4) + 0.1, 0.25 * (j // 4) + 0.1), None) for j in range(11)]
    ring.append((cur, (0.0, 0.0), None))
    spatial = np.full((h, w, 3), 99, np.uint8)
    ref, cells = tss_frame_reference(spatial, cur, ring, False)
    assert np.array_equal(ref, spatial) and not cells.any()
    stage = TSSStage(frames=len(ring) + 1, bgr=False, context=stage_parts)
    out, kcells = _run_kernel(stage, cur, spatial, ring, False, 1)
    assert np.array_equal(out, spatial) and not kcells.any()
    # one pixel of 101 in the middle: its 3x3 and its neighbours' are no longer flat and they resolve
    cur2 = cur.copy()
    cur2[10, 18] = 101
    ref2, cells2 = tss_frame_reference(spatial, cur2, ring[:-1] + [(cur2, (0.0, 0.0), None)], False)
    assert (cells2[9:12, 17:20] >= 9).all() and cells2.sum() == cells2[9:12, 17:20].sum()
    out2, _ = _run_kernel(stage, cur2, spatial, ring[:-1] + [(cur2, (0.0, 0.0), None)], False, 1)
    assert np.array_equal(out2, ref2) and not np.array_equal(out2[9:12, 17:20], spatial[9:12, 17:20])


def _projective_frames(n, h=144, w=240, perspective=5e-6, seed=5):
    """Frames of a smooth seeded random texture seen through homographies A_t (frame t at x shows the texture at
    A_t x): a turning camera's 0.45 px per frame with the image's edges moving faster (perspective)."""
    import cv2
    rng = np.random.default_rng(seed)
    texture = cv2.resize(rng.uniform(0, 255, (36, 60)).astype(np.float32), (w + 80, h + 80),
                         interpolation=cv2.INTER_CUBIC)

    def a(t):
        return np.array([[1.0, 0.0, 40.0 + 0.45 * t], [0.0, 1.0, 40.0], [perspective * t, 0.0, 1.0]])

    frames = [np.clip(cv2.warpPerspective(texture, a(t), (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP),
                      0, 255) for t in range(n)]
    return frames, a


def test_homography_steps_recover_a_projective_map():
    """Known answer (_Refiner.homography): from the translation that fits best, inverse-compositional steps at the
    refiner's points find the map from frame 3 to frame 0 (A_0^-1 A_3) within 0.05 px over the frame, where the
    translation alone is off by over 0.3 px at the sides."""
    import cv2
    from mlaa_stream.temporal import motion_ring as T
    frames, a = _projective_frames(4, perspective=2e-5)
    cur, ring = (cv2.GaussianBlur(f.astype(np.float32), (0, 0), 1.0) for f in (frames[3], frames[0]))
    ref = T._Refiner(cur)
    d = (0.0, 0.0)
    for _ in range(4):
        d, _ = ref.step(ring, d, check=False)
    m = ref.homography(ring, T._translation(d, 1), 5)
    true = np.linalg.inv(a(0)) @ a(3)
    ys, xs = np.mgrid[8:136, 8:232].astype(np.float64)

    def field(mat):
        p = np.stack([xs, ys, np.ones_like(xs)], -1) @ mat.T
        return np.stack([p[..., 0] / p[..., 2] - xs, p[..., 1] / p[..., 2] - ys], -1)

    assert np.abs(field(m) - field(true)).max() < 0.05, np.abs(field(m) - field(true)).max()
    assert np.abs(field(T._translation(d, 1)) - field(true)).max() > 0.3


def test_projective_maps_only_where_a_translation_does_not_fit(filt):
    """MotionRing._projective: a turning camera's frames (the image's sides move faster than its centre) take
    projective maps from the third frame on (the translation departs by PROJECTIVE_MIN px at a corner), whose
    per-tile translations follow the true motion within 0.1 px; the kernel (per-tile tables of
    tss_resolve_shift) returns what the numpy reference does, bit for bit; a pure translation keeps one table."""
    from mlaa_stream.temporal import resolve as T
    for perspective, projective in ((5e-6, True), (0.0, False)):
        frames, a = _projective_frames(6, perspective=perspective)
        frames = [np.repeat(f[..., None], 3, -1).astype(np.uint8) for f in frames]
        h, w = frames[0].shape[:2]
        outs = {}
        for backend in ("device", "numpy"):
            st = TSSStage(context=filt.context, bgr=False, frames=8, backend=backend)
            outs[backend] = [st(f, filt.process(f), i) for i, f in enumerate(frames)]
            entries = st.motion.entries[:-1]
            assert [r["model"] for r in st.stats] == ["reset"] + ["global"] * 5
            assert all(e.projective for e in entries) == projective
            assert not any(e.projective for e in entries) == (not projective)
            st.close()
        assert all(np.array_equal(x, y) for x, y in zip(outs["device"], outs["numpy"]))
        assert any(np.any(o != filt.process(f)) for o, f in zip(outs["device"][2:], frames[2:]))
        if projective:
            got = T.tile_shifts(entries[0].homography, w, h, 1).shifts      # frame 0, seen from frame 5
            ty, tx = got.shape[:2]
            cy = np.minimum(np.arange(ty) * T.TILE_ROWS + (T.TILE_ROWS - 1) / 2.0, h - 1)
            cx = np.minimum(np.arange(tx) * T.LANES + (T.LANES - 1) / 2.0, w - 1)
            gx, gy = np.meshgrid(cx, cy)
            p = np.stack([gx, gy, np.ones_like(gx)], -1) @ (np.linalg.inv(a(0)) @ a(5)).T
            want = np.stack([p[..., 0] / p[..., 2] - gx, p[..., 1] / p[..., 2] - gy], -1)
            assert np.abs(got - want).max() < 0.1, np.abs(got - want).max()


@pytest.mark.parametrize("channels,dtype", [(1, np.uint8), (4, np.uint8), (3, np.uint16), (3, np.float32)])
def test_projective_kernel_matches_reference_in_every_format(filt, channels, dtype):
    """The per-tile tables of tss_resolve_shift against tss_reference's TileShifts on a turning camera's frames in
    grey, BGRA, 16-bit and float formats: bit for bit, and projective maps in use."""
    frames, _ = _projective_frames(5, perspective=5e-6)
    scale = {np.uint8: 1.0, np.uint16: 257.0, np.float32: 1.0 / 255.0}[dtype]
    shaped = []
    for f in frames:
        v = (f * scale).astype(dtype) if dtype != np.float32 else (np.round(f) * scale).astype(dtype)
        if channels == 1:
            shaped.append(v)
        else:
            alpha = np.full(v.shape, 255 * scale, dtype)
            shaped.append(np.stack([v, v * 0 + v, v] + ([alpha] if channels == 4 else []), -1).astype(dtype))
    outs = {}
    with Filter(bgr=channels == 4) as spatial:
        for backend in ("device", "numpy"):
            st = TSSStage(context=spatial.context, bgr=channels == 4, frames=6, backend=backend)
            outs[backend] = [st(f, spatial.process(f), i) for i, f in enumerate(shaped)]
            assert any(r.get("projective") for r in st.stats), backend
            st.close()
    for a, b in zip(outs["device"], outs["numpy"]):
        assert a.dtype == b.dtype and np.array_equal(a, b)


def test_band_growth_keeps_aliasing_and_drops_a_second_motion():
    """Known answers for the band check's age rule (BAND_GROWTH): three bands checked in ring frames of ages 1, 4, 7
    and 10. Band 0 deviates by 0.4 px at every age (a bias of 1-spp aliasing along its edges: kept), band 1 by
    0.12 px per frame of age (a second motion: off where its deviation is over BAND_TOL, from age 4), band 2 by
    1.0 px (over BAND_FAR: off at any age); a band without texture is never off."""
    from mlaa_stream.temporal.motion_ring import BAND_FAR, BAND_GROWTH, BAND_TOL, _band_slopes, _bands_growing
    assert BAND_GROWTH > 0 and BAND_FAR < 1.0
    ages = (1, 4, 7, 10)
    textured = np.array([True, True, True, False])
    checks = []
    for a in ages:
        dev = np.array([0.4, 0.12 * a, 1.0, 5.0])
        checks.append((None, a, (None, dev, textured, dev, textured)))
    slopes = _band_slopes(checks)
    np.testing.assert_allclose(slopes[0][:3], [0.0, 0.12, 0.0], atol=1e-12)
    for a in ages:
        rows, cols = _bands_growing(slopes, a, *checks[ages.index(a)][2][1:])
        expect = [False, 0.12 * a > BAND_TOL, True, False]
        assert list(rows) == expect and list(cols) == expect, (a, rows)


@pytest.mark.parametrize("flow_scale", [1, 2, 3, 4, 8])
def test_vrows_repeat_each_mask_column_flow_scale_times(flow_scale):
    """The resolve's per-pixel mask rows: each flow texel's byte repeated flow_scale times along the row, cut to
    the frame's width (the wide-integer form against np.repeat, seeded masks, widths that cut a texel)."""
    from mlaa_stream.temporal.tss import vrows_of
    rng = np.random.default_rng(flow_scale)
    valid = (rng.random((23, 37)) > 0.4).astype(np.uint8)
    width = 37 * flow_scale - (flow_scale > 1)
    rows = vrows_of(valid, flow_scale, width)
    assert rows.dtype == np.uint8 and rows.flags.c_contiguous
    assert np.array_equal(rows, np.repeat(valid, flow_scale, 1)[:, :width])
    assert np.array_equal(vrows_of(valid.astype(bool), flow_scale, width), rows)


def _zoom_field_errors(entries, t: int, z: float, centre) -> np.ndarray:
    """Each ring frame's field against the exact zoom map, px (texels it keeps), after asserting it keeps most."""
    h, w = entries[0].pyr.flow.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    errs = []
    for e in entries[:-1]:
        k = z ** (e.index - t) - 1.0
        exact = np.stack([k * (xs - centre[0]), k * (ys - centre[1])], -1)
        ok = np.isfinite(e.field[..., 0])
        assert ok.mean() > 0.5
        errs.append(np.abs(e.field[ok] - exact[ok]).max(-1))
    return np.concatenate(errs)


def test_dense_samples_track_a_zoom_tile_by_tile(stage_parts, zoom_frames):
    """dense_samples: a textured plane zooming 1 % per frame about the centre (a dolly; dense to the motion models)
    keeps its ring, each ring frame's field the exact zoom map within 0.2 px at 95 % of the texels it keeps (median
    under 0.06; the tile centres' grid misplaced by a few px or clamped at the borders gave 0.2-0.5), and the
    output is closer to the box-filtered truth than the spatial output; without the option the ring restarts every
    frame and the spatial output stands."""
    z = 1.01
    frames, truths, centre = zoom_frames(z)
    outs = {}
    for dense in (False, True):
        st = TSSStage(frames=6, bgr=False, context=stage_parts, mode="dense", dense_samples=dense)
        st.motion.layers = False   # the plane as a whole: no moving layers
        outs[dense] = []
        for t, f in enumerate(frames):
            outs[dense].append(st(f, f, t))
            if dense and t == len(frames) - 1:
                errs = _zoom_field_errors(st.motion.entries, t, z, centre)
                assert np.percentile(errs, 95) < 0.2 and np.median(errs) < 0.06
        st.close()
    assert all(np.array_equal(o, f) for o, f in zip(outs[False], frames))
    err = lambda xs: sum(float(((x.astype(float) - y) ** 2).sum()) for x, y in zip(xs[2:], truths[2:]))
    assert err(outs[True]) < 0.97 * err(frames)   # 0.955 measured: the texture is smooth but for its lines


def test_dense_samples_track_a_dolly_the_translation_fails(stage_parts, zoom_frames):
    """dense_samples on global frames: where one translation fails the tile check over most of the frame (the zoom
    above, decided global), the ring's maps become tracked tiles (stats "tracked"), within 0.2 px of the exact
    zoom at 95 % of the texels kept, and the output is closer to the truth than with the translations; without the
    option, and on a pure translation with it, the maps stay translations."""
    z = 1.01
    frames, truths, centre = zoom_frames(z, w=320, h=240)   # 30 tiles of the check (PARALLAX_TILES)
    outs = {}
    for dense in (False, True):
        st = TSSStage(frames=6, bgr=False, context=stage_parts, mode="global", dense_samples=dense)
        outs[dense] = [st(f, f, t) for t, f in enumerate(frames)]
        tracked = [bool(r.get("tracked")) for r in st.stats]
        if dense:
            assert all(tracked[2:]), tracked   # the newest ring frame's tiles fail from the second frame on
            errs = _zoom_field_errors(st.motion.entries, len(frames) - 1, z, centre)
            assert np.percentile(errs, 95) < 0.2 and np.median(errs) < 0.06
        else:
            assert not any(tracked) and all(e.translated for e in st.motion.entries)
        st.close()
    err = lambda xs: sum(float(((x.astype(float) - y) ** 2).sum()) for x, y in zip(xs[2:], truths[2:]))
    assert err(outs[True]) < 0.985 * err(outs[False])   # 0.976 measured (the translations: 1.001 of the input's)
    # a pure translation (the same plane panned 0.3 / 0.2 px per frame) keeps one translation per ring frame
    import cv2
    tex = zoom_frames(1.0, 1, w=320, h=240)[1][0]   # any smooth texture with lines
    pan = [cv2.warpAffine(tex, np.float32([[1, 0, 0.3 * t], [0, 1, 0.2 * t]]), tex.shape[1::-1],
                          borderMode=cv2.BORDER_REFLECT) for t in range(6)]
    st = TSSStage(frames=6, bgr=False, context=stage_parts, mode="global", dense_samples=True)
    for t, f in enumerate(pan):
        st(f, f, t)
    assert not any(r.get("tracked") for r in st.stats) and all(e.translated for e in st.motion.entries)
    st.close()


def test_tracked_frames_keep_only_the_newest_ring_frames(stage_parts, zoom_frames):
    """dense_samples: on a tracked frame, ring frames over TRACKED_AGE frames old leave the ring (a dolly's field
    departs from a tile's translation with age); a K = 16 ring on a 10-frame dolly holds TRACKED_AGE past frames
    and the current one, the newest TRACKED_AGE frames in order."""
    from mlaa_stream.temporal.motion_ring import TRACKED_AGE
    frames, _, _ = zoom_frames(1.01, n=TRACKED_AGE + 3, w=320, h=240)
    st = TSSStage(frames=16, bgr=False, context=stage_parts, mode="global", dense_samples=True)
    for t, f in enumerate(frames):
        st(f, f, t)
    assert st.stats[-1].get("tracked")
    assert [e.index for e in st.motion.entries] == list(range(len(frames) - TRACKED_AGE - 1, len(frames)))
    st.close()


def test_trajectory_fit_drops_the_common_offset():
    """Known answers for MotionRing._fit_trajectory: translations c + v age + w age^2 + alternating noise (a 1-spp
    frame's quantised edges) become the least-squares polynomial without its offset c; a shaking camera (residual
    over TRAJECTORY_TOL) and a ring holding a dense field keep their estimates; look-ahead frames join the fit
    from the ring's measured estimates."""
    from mlaa_stream.temporal.motion_ring import TRAJECTORY_DEGREE, TRAJECTORY_TOL, MotionRing, RingEntry
    rng = np.random.default_rng(3)
    index, ages = 20, np.arange(15, 0, -1)
    motion = np.outer(ages, [-0.35, -0.15]) + np.outer(ages ** 2, [0.004, -0.002])
    shifts = np.array([0.07, -0.05]) + motion + rng.choice([-0.04, 0.04], (len(ages), 2))
    ring = MotionRing(frames=16)
    ring.entries = [RingEntry(index - int(a), None, None, shift=tuple(s)) for a, s in zip(ages, shifts)]
    ring._fit_trajectory(index)
    want = np.stack([np.polyval(np.polyfit(ages, shifts[:, k], TRAJECTORY_DEGREE), ages)
                     - np.polyfit(ages, shifts[:, k], TRAJECTORY_DEGREE)[-1] for k in range(2)], 1)
    got = np.array([e.shift for e in ring.entries])
    np.testing.assert_allclose(got, want, atol=1e-9)
    assert np.abs(got - motion).max() < 0.08 < np.abs(shifts - motion).max()   # closer than the estimates
    assert [e.estimate for e in ring.entries] == [tuple(s) for s in shifts]

    # look-ahead frames (negative ages) join the same fit, from the ring's measured estimates
    ahead = [RingEntry(index + k, None, None, shift=(0.35 * k + 0.01, 0.15 * k - 0.02)) for k in (1, 2)]
    ring._fit_trajectory(index, ahead)
    every = np.concatenate([ages, [-1, -2]])
    measured = np.concatenate([shifts, [e.estimate for e in ahead]])
    coefs = [np.polyfit(every, measured[:, k], TRAJECTORY_DEGREE) for k in range(2)]
    want = np.stack([np.polyval(c, every) - c[-1] for c in coefs], 1)
    np.testing.assert_allclose(np.array([e.shift for e in ring.entries + ahead]), want, atol=1e-9)

    shaking = motion + rng.choice([-0.3, 0.3], (len(ages), 2))   # residual ~0.3 px
    ring.entries = [RingEntry(index - int(a), None, None, shift=tuple(s)) for a, s in zip(ages, shaking)]
    ring._fit_trajectory(index)
    assert np.array_equal(np.array([e.shift for e in ring.entries]), shaking)
    assert all(e.estimate is None for e in ring.entries) and TRAJECTORY_TOL < 0.3

    ring.entries = [RingEntry(index - int(a), None, None, shift=tuple(s)) for a, s in zip(ages, shifts)]
    ring.entries[3].shift = None   # a dense field: the ring is not one translation per frame
    ring._fit_trajectory(index)
    assert ring.entries[0].shift == tuple(shifts[0])


def test_trajectory_fit_brings_a_flat_colour_pan_closer_to_its_motion(filt, monkeypatch):
    """The bench's vector pan (0.35, 0.15) px per frame: long horizontal edges make each direct estimate jump with
    their quantised rows; the ring's fitted line is closer to the exact motion than the estimates alone."""
    import mlaa_stream.temporal.motion_ring as motion_ring
    sc = scene_pan(16, 480, 270)
    spatial = [filt.process(f) for f in sc.inputs]

    def ring_error(tol: float) -> float:
        monkeypatch.setattr(motion_ring, "TRAJECTORY_TOL", tol)
        stage = TSSStage(bgr=False, frames=16)
        _run(stage, sc, spatial)
        ring = stage.motion
        last = len(sc.inputs) - 1
        err = [np.subtract(e.shift, (-0.35 * (last - e.index), -0.15 * (last - e.index))) for e in ring.entries]
        return float(np.sqrt((np.array(err) ** 2).mean()))

    fitted, raw = ring_error(0.1), ring_error(0.0)
    assert fitted < 0.035 and fitted < 0.7 * raw, (fitted, raw)   # measured 0.025 against 0.053


@pytest.mark.parametrize("speed", [1.0, 0.6])
def test_stripes_of_one_direction_keep_the_spatial_output(filt, speed):
    """Bars of one slope panning (the end-to-end benchmark's clip): the motion along them cannot be measured, the
    samples TSS placed by its guess lined up in each footprint and pulled MLAA's blend back to the aliased steps
    (error removed 0.921 -> 0.857 at 1 px per frame, 0.929 -> 0.901 at 0.6). Now such frames keep the spatial output
    (APERTURE_RATIO: their points' structure tensor has eigenvalues ~400x apart; the bench pan's 9x)."""
    from mlaa_stream.bench.temporal import scene_stripes
    sc = scene_stripes(6, 240, 135, speed)
    spatial = [filt.process(f) for f in sc.inputs]
    with TSSStage(context=filt.context, bgr=False, lookahead=2) as stage:
        outs = [stage(f, s, i, future=list(sc.inputs[i + 1:i + 3])) for i, (f, s) in enumerate(zip(sc.inputs, spatial))]
    assert all(np.array_equal(o, s) for o, s in zip(outs, spatial))
    assert sum("aperture" in r for r in stage.stats) >= 4
    assert all(r["aperture"] < 0.01 for r in stage.stats if "aperture" in r)
    pan = scene_pan(4, 160, 96)   # many edge directions: samples taken as before
    sp = [filt.process(f) for f in pan.inputs]
    with TSSStage(context=filt.context, bgr=False) as stage:
        outs = _run(stage, pan, sp)
    assert not any("aperture" in r for r in stage.stats) and not np.array_equal(outs[-1], sp[-1])


def test_set_constant_reaches_every_module_that_holds_the_constant():
    """The benches' --tss-set (tss.set_constant): FULL_CELLS lives in resolve.py and the stage holds a copy; both
    take the value (read as the constant's type), so the stage's kernel defines and the numpy reference agree.
    A name that is no constant of the three modules is refused."""
    from mlaa_stream.device.formats import frame_format
    from mlaa_stream.temporal import motion_ring, resolve, tss
    saved = {n: getattr(m, n) for m, n in ((resolve, "FULL_CELLS"), (tss, "FULL_CELLS"),
                                           (motion_ring, "TRAJECTORY_AHEAD"), (motion_ring, "BAND_TOL"))}
    try:
        tss.set_constant("FULL_CELLS", "12")
        assert resolve.FULL_CELLS == 12 and tss.FULL_CELLS == 12 and type(tss.FULL_CELLS) is int
        assert tss.kernel_defines(frame_format(np.zeros((4, 4, 3), np.uint8), False))["FULL_CELLS"] == 12
        tss.set_constant("TRAJECTORY_AHEAD", "false")
        assert motion_ring.TRAJECTORY_AHEAD is False
        tss.set_constant("BAND_TOL", "1e9")
        assert motion_ring.BAND_TOL == 1e9
        for bad in ("NO_SUCH_CONSTANT", "set_constant", "np"):
            with pytest.raises(KeyError):
                tss.set_constant(bad, "1")
    finally:
        resolve.FULL_CELLS = tss.FULL_CELLS = saved["FULL_CELLS"]
        motion_ring.TRAJECTORY_AHEAD, motion_ring.BAND_TOL = saved["TRAJECTORY_AHEAD"], saved["BAND_TOL"]
