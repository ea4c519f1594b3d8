"""The fast path (issue 19, seed 004): three passes with a bounded edge length, each against its numpy
reference (mlaa_stream/spatial/fast.py) and against cases with a known answer."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from mlaa_stream.spatial import fast as F
from mlaa_stream.spatial.filter import PRESETS, Filter


def staircase(h: int, w: int, step: int, dtype=np.uint8, channels: int = 3) -> np.ndarray:
    """A dark region below a line rising one pixel every `step` pixels, on a light ground."""
    y, x = np.mgrid[0:h, 0:w]
    top = np.iinfo(dtype).max if dtype != np.float32 else 1.0
    img = np.where((y > h // 2 - x // step)[..., None], 0.1 * top, 0.9 * top)
    img = np.repeat(img, channels, axis=2)
    if channels == 4:
        img[..., 3] = 0.5 * top
    return img.astype(dtype)


def random_blocks(seed: int, h: int = 37, w: int = 53, dtype=np.uint8) -> np.ndarray:
    rng = np.random.default_rng(seed)
    small = rng.integers(0, 256, (h // 4 + 1, w // 5 + 1, 3))
    img = np.kron(small, np.ones((4, 5, 1)))[:h, :w]
    img[rng.random((h, w)) < 0.05] = 255 - img[rng.random((h, w)) < 2][:1]
    return (img * (np.iinfo(dtype).max / 255)).astype(dtype) if dtype != np.float32 else (img / 255).astype(dtype)


def passes(frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The kernel's edge buffer and L-shape buffers for `frame`."""
    f = Filter(fast=True)
    f.process(frame)
    h, w = frame.shape[:2]
    fp = f._fast
    e = np.empty((h, w), np.uint8)
    hs = np.empty((h, w, 2), np.uint8)
    vs = np.empty((h, w, 2), np.uint8)
    for arr, buf in ((e, fp.edges), (hs, fp.hshapes), (vs, fp.vshapes)):
        cl.enqueue_copy(f.queue, arr, buf, is_blocking=True)
    return e, hs, vs


@pytest.mark.parametrize("seed,size", [(0, (37, 53)), (1, (37, 53)), (2, (70, 150)), (3, (70, 150))])
def test_edges_and_shapes_match_the_reference_exactly(seed, size):
    """(70, 150): lines across the vertical sweep's 64-column strips and a part strip."""
    frame = random_blocks(seed, *size)
    e, hs, vs = passes(frame)
    ref_e = F.fast_edges_reference(frame)
    assert np.array_equal(e, ref_e)
    ref_s = F.fast_lshapes_reference(ref_e)
    bottom, right = (ref_e & F.E_BOTTOM) > 0, (ref_e & F.E_RIGHT) > 0  # shapes are read only there
    assert np.array_equal(hs[bottom], ref_s[..., :2][bottom])
    assert np.array_equal(vs[right], ref_s[..., 2:][right])


def assert_shapes_exact(frame: np.ndarray) -> np.ndarray:
    e, hs, vs = passes(frame)
    ref_e = F.fast_edges_reference(frame)
    ref_s = F.fast_lshapes_reference(ref_e)
    bottom, right = (ref_e & F.E_BOTTOM) > 0, (ref_e & F.E_RIGHT) > 0
    assert np.array_equal(e, ref_e)
    assert np.array_equal(hs[bottom], ref_s[..., :2][bottom]) and np.array_equal(vs[right], ref_s[..., 2:][right])
    return ref_s


def test_lines_across_the_64_column_masks_end_where_the_reference_ends_them():
    """The shape sweeps take 64 columns at a time as bit masks. Right edges of column 63 (the last of the first
    64), cut by a bottom edge under column 64 only; bottom edges of row 9 from x = 10 to 150 (across two
    borders), cut by a right edge at x = 64 in the row below only, and a line beyond the bound."""
    frame = np.full((30, 200, 3), 40, np.uint8)
    frame[:, 64:] = (200, 200, 200)
    frame[15:, 64:] = (120, 30, 200)
    ref_s = assert_shapes_exact(frame)
    assert ref_s[14, 63, 3] & 31 == 0 and ref_s[15, 63, 2] & 31 == 0  # the line splits between rows 14 and 15
    frame = np.full((20, 200, 3), 40, np.uint8)
    frame[10:, 10:151] = (200, 200, 200)
    frame[10:, 65:151] = (30, 200, 90)
    ref_s = assert_shapes_exact(frame)
    assert ref_s[9, 64, 1] & 31 == 0 and ref_s[9, 65, 0] & 31 == 0  # the line splits between x = 64 and 65


def passes_of(f: Filter, frame: np.ndarray) -> np.ndarray:
    """The edge buffer the kernel left for `frame`."""
    f.process(frame)
    e = np.empty(frame.shape[:2], np.uint8)
    cl.enqueue_copy(f.queue, e, f._fast.edges, is_blocking=True)
    return e


@pytest.mark.parametrize("bgr", [False, True])
def test_edges_near_the_threshold_match_the_reference_across_segments(bgr):
    """8-bit RGB takes the 8-pixel vector path: differences straddling the limit (15 levels on one channel,
    mixes of channels), widths that are no multiple of 8 and rows of several work items (SEGMENT 64)."""
    rng = np.random.default_rng(11)
    for h, w in ((21, 150), (9, 129), (5, 9)):
        frame = (np.full((h, w, 3), 100) + rng.integers(0, 40, (h, w, 3)) * (rng.random((h, w, 1)) < 0.5)
                 ).astype(np.uint8)
        e = passes_of(Filter(fast=True, bgr=bgr), np.ascontiguousarray(frame[..., ::-1]) if bgr else frame)
        ref = F.fast_edges_reference(frame)
        assert 0.1 < (ref > 0).mean() < 0.9
        assert np.array_equal(e, ref)


@pytest.mark.parametrize("dtype,channels", [(np.uint8, 3), (np.uint8, 4), (np.uint16, 3), (np.float32, 3),
                                            (np.uint8, 1)])
def test_output_matches_the_reference(dtype, channels):
    frame = random_blocks(7, dtype=dtype)
    if channels == 1:
        frame = np.ascontiguousarray(frame[..., 1])
    elif channels == 4:
        frame = np.dstack([frame, frame[..., :1]])
    out = Filter(fast=True, alpha="keep").process(frame)  # the kernels keep alpha (tests/test_alpha.py)
    ref = F.fast_reference(frame)
    if dtype == np.float32:
        np.testing.assert_allclose(out, ref, atol=2e-4)  # the kernels' colour tables vs the exact curve
    else:
        diff = np.abs(out.astype(np.int64) - ref.astype(np.int64))
        assert diff.max() <= 1 and (diff == 0).mean() > 0.999  # tables vs formula: rounding ties only
    assert (out != frame).any()


def test_known_l_shapes_encode_exactly():
    e = np.zeros((8, 12), np.uint8)
    e[3, 2:9] |= F.E_BOTTOM  # a line of 7 bottom edges, row 3, x = 2..8
    e[4, 2:9] |= F.E_TOP
    e[3, 1] |= F.E_RIGHT  # left end: crossing in this row (side A), one pixel long
    e[3, 2] |= F.E_LEFT
    for y in (4, 5, 6):  # right end: crossing in the row below (side B), three pixels long: a corner
        e[y, 8] |= F.E_RIGHT
        e[y, 9] |= F.E_LEFT
    s = F.fast_lshapes_reference(e)
    assert s[3, 2, 0] == (0 | F.SIDE_A << 5) and s[3, 2, 1] == (6 | F.SIDE_B << 5 | F.LONG)
    assert s[3, 5, 0] == (3 | F.SIDE_A << 5) and s[3, 5, 1] == (3 | F.SIDE_B << 5 | F.LONG)
    assert F.line_areas(s[3, 2, 0], s[3, 2, 1]) == (pytest.approx(0.5 * (1 - 1 / 7)), 0.0)  # long end: no area
    ee, hs, _ = passes(np.where(np.isin(np.arange(12), range(2, 9))[None, :, None] & (np.arange(8) > 3)[:, None, None],
                                20, 230).astype(np.uint8).repeat(3, axis=2))
    assert hs[3, 2, 1] & 31 == 6


def test_a_line_longer_than_the_bound_is_left_alone_in_its_middle():
    frame = staircase(16, 200, step=100)  # steps 100 px long: beyond FAST_MAX_LEN
    out = Filter(fast=True).process(frame)
    changed_x = np.nonzero((out != frame).any(-1).any(0))[0]
    # only within the bound of each step's ends (x = 0, 100, 199)
    assert all(min(abs(x - 0), abs(x - 99), abs(x - 100), abs(x - 199)) < F.FAST_MAX_LEN for x in changed_x)
    assert 30 < 100 < 170 and not ((out != frame).any(-1)[:, 40:60]).any()


@pytest.mark.parametrize("step", [2, 3, 5, 8])
def test_a_staircase_shorter_than_the_bound_blends_as_the_default_preset(step):
    frame = staircase(48, 96, step)
    fast = Filter(fast=True).process(frame).astype(np.int64)
    default = Filter(bridge=False).process(frame).astype(np.int64)
    interior = (slice(4, -4), slice(4, -4))  # the frame's border: the default has more rules there
    diff = np.abs(fast - default)[interior]
    assert ((fast != frame) == (default != frame))[interior].all()  # the same pixels blended
    # Levels. Steps of 3+ px: float rounding of the same areas. Steps of 2 px: the default scales a 2-px
    # crossing by SHORT_CORNER (0.75) and does not blend the 1-px lines between them; the fast path's byte
    # has no room for that rule (9 levels on a 204-level step, 1 pixel in 2 along the edge).
    assert diff.max() <= (10 if step == 2 else 2), diff.max()
    assert diff.mean() <= (1.5 if step == 2 else 0.1)


@pytest.mark.parametrize("op", [np.fliplr, np.flipud, lambda a: a.transpose(1, 0, 2)])
def test_flips_and_transposes_commute(op):
    frame = np.ascontiguousarray(random_blocks(3, 40, 40))
    f = Filter(fast=True)
    a = f.process(np.ascontiguousarray(op(frame)))
    b = np.ascontiguousarray(op(f.process(frame)))
    assert np.array_equal(a, b)


def test_the_preset_by_name_everywhere():
    assert PRESETS["fast"] == {"fast": True}
    frame = staircase(24, 40, 3)
    assert np.array_equal(Filter(preset="fast").process(frame), Filter(fast=True).process(frame))
    with pytest.raises(ValueError, match="preset: expected one of"):
        Filter(preset="nope")
    from mlaa_stream import Antialiaser
    with Antialiaser(preset="fast") as aa:
        bgr = np.ascontiguousarray(frame[..., ::-1])
        assert np.array_equal(aa(bgr)[..., ::-1], Filter(fast=True).process(frame))


@pytest.mark.parametrize("dtype,channels", [(np.uint8, 3), (np.uint8, 4), (np.uint16, 3), (np.uint8, 1),
                                            (np.float32, 3)])
def test_the_zero_copy_filter_gives_the_filters_output(dtype, channels):
    """FastFilter (kernels on the caller's array and a new one, on PoCL's CPU driver; float frames through
    Filter.submit) against Filter(fast=True); also non-contiguous and read-only frames."""
    from mlaa_stream.spatial.fast_filter import FastFilter
    frame = random_blocks(5, 45, 77, dtype=dtype)
    frame = np.ascontiguousarray(frame[..., 1]) if channels == 1 else \
        np.dstack([frame, frame[..., :1]]) if channels == 4 else frame
    expected = Filter(fast=True).process(frame)
    with FastFilter() as f:
        assert np.array_equal(f.process(frame), expected)
        assert np.array_equal(f.process(np.asfortranarray(frame)), expected)
        ro = frame.copy()
        ro.flags.writeable = False
        assert np.array_equal(f.process(ro), expected)


def test_the_zero_copy_filter_keeps_frames_in_flight_apart():
    from mlaa_stream.spatial.fast_filter import FastFilter
    frames = [random_blocks(s, 40, 70) for s in range(4)] + [staircase(24, 90, 3)]
    expected = [Filter(fast=True).process(fr) for fr in frames]
    with FastFilter() as f:
        pending = [f.submit(fr) for fr in frames]  # all enqueued before any result is read
        assert all(np.array_equal(p.result(), e) for p, e in zip(pending, expected))
        assert f.direct == ("Portable Computing Language" in f.context.device.platform.name
                            and bool(f.context.device.type & cl.device_type.CPU))


def test_a_sparse_frame_skips_blocks_without_edges_and_matches_the_reference():
    """A few shapes on a flat ground: most 64 x 8 blocks hold no edge and every pass skips them (and the edge
    pass tests the flat rows 64 pixels at a time)."""
    rng = np.random.default_rng(21)
    frame = np.full((90, 330, 3), 70, np.uint8)
    yy, xx = np.mgrid[:90, :330]
    for _ in range(5):
        cx, cy, r = rng.integers(10, 320), rng.integers(5, 85), rng.integers(3, 12)
        frame[(xx - cx) ** 2 + 3 * (yy - cy) ** 2 <= r * r] = rng.integers(0, 256, 3)
    assert_shapes_exact(frame)
    # a boundary on a block's first row (8) between flat areas: the 64-pixel quiet test looks up there too
    flat = np.full((20, 200, 3), 60, np.uint8)
    flat[8:, 30:] = 190
    assert_shapes_exact(flat)
    out = Filter(fast=True, alpha="keep").process(frame)  # the kernels keep alpha (tests/test_alpha.py)
    ref = F.fast_reference(frame)
    diff = np.abs(out.astype(np.int64) - ref.astype(np.int64))
    assert diff.max() <= 1 and (diff == 0).mean() > 0.999 and (out != frame).any()


def dots_frame(seed: int = 4) -> np.ndarray:
    """Isolated 1-px dots and 1-px line ends (sub-pixel features) on a flat ground, and a patch of noise."""
    rng = np.random.default_rng(seed)
    frame = np.full((48, 96, 3), 150, np.uint8)
    for _ in range(30):
        y, x = rng.integers(1, 47), rng.integers(1, 60)
        frame[y, x] = rng.integers(0, 256, 3)
    frame[10, 62:70] = 20  # a 1-px line: its ends have edges on three sides
    frame[20:40, 70:90] = rng.integers(0, 256, (20, 20, 3))
    return frame


def test_an_isolated_dot_moves_towards_its_3x3_mean():
    from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
    from mlaa_stream.spatial.filter import SUBPIXEL
    frame = np.full((9, 9, 3), 200, np.uint8)
    frame[4, 4] = 30
    out = Filter(fast=True).process(frame)
    dot, ground = srgb_to_linear(30 / 255), srgb_to_linear(200 / 255)
    expected = linear_to_srgb(dot + SUBPIXEL * ((dot + 8 * ground) / 9 - dot)) * 255
    assert np.abs(out[4, 4].astype(float) - expected).max() <= 1, (out[4, 4], expected)
    assert np.array_equal(Filter(fast=True, subpixel=0).process(frame)[4, 4], frame[4, 4])


def test_a_cluster_of_features_is_left_alone():
    """A 1-px checkerboard: every pixel has four edges, so does every neighbour: noise, not a dot."""
    frame = np.full((16, 16, 3), 128, np.uint8)
    frame[4:12, 4:12] = np.where(((np.indices((8, 8)).sum(0)) % 2 == 0)[..., None], 20, 230)
    out = Filter(fast=True).process(frame)
    assert np.array_equal(out[5:11, 5:11], frame[5:11, 5:11])


@pytest.mark.parametrize("subpixel", [0.0, 0.5])
def test_sub_pixel_features_match_the_reference(subpixel):
    frame = dots_frame()
    out = Filter(fast=True, subpixel=subpixel).process(frame)
    ref = F.fast_reference(frame, subpixel=subpixel)
    moved = (F.fast_reference(frame, subpixel=0.5) != F.fast_reference(frame, subpixel=0.0)).any(-1)
    assert moved.sum() >= 20  # the dots and line ends, not the noise patch
    assert not moved[21:39, 71:89].any()
    diff = np.abs(out.astype(np.int64) - ref.astype(np.int64))
    assert diff.max() <= 1 and (diff == 0).mean() > 0.999


def test_the_zero_copy_filter_lets_the_caller_reuse_a_submitted_frame():
    """Filter.submit's contract: the caller may overwrite its array as soon as submit returns."""
    from mlaa_stream.spatial.fast_filter import FastFilter
    frame = random_blocks(8, 40, 70)
    expected = Filter(fast=True).process(frame)
    with FastFilter() as f:
        pending = f.submit(frame)
        frame[:] = 0
        assert np.array_equal(pending.result(), expected)
