"""GRLAA overlays (kernels/grlaa.cl) against the numpy reference, known answers and a supersampled truth.

Tolerances (kernel vs reference, same float32 tables; the kernel computes in float32, the
reference in float64): uint8 within 1 level on <= 0.1% of samples; uint16 within 8 codes on <= 2%;
float32 within 1e-4; float16 within 1e-3 (one ulp near 1). Known answers: axis-aligned coverage is
exact (linear ramp), so edge rows match the analytic value within 1e-3 (LUT encode) and fully
covered rows are bit-exact; tilted half-planes match the exact pixel-square area within 5e-5
(float32 arithmetic at coordinates of a few hundred pixels).
"""
from __future__ import annotations

import json
import math
import os
import re
import warnings

import numpy as np
import pyopencl as cl
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.device.context import DeviceError
from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.overlay.grlaa import (OverlayRenderer, _segment_cover, as_lines,
                                 draw_polylines, enc8_read, enc8_table, footprint_cdf,
                                 line_tables, load_overlay, make_styles, segment_tables,
                                 parse_color, parse_overlay, reference_draw_polylines)


@pytest.fixture(scope="module")
def renderer():
    try:
        return OverlayRenderer()
    except DeviceError as exc:  # PoCL comes with the package: a missing device is a broken install
        pytest.fail(f"no OpenCL device (expected PoCL from `pip install .`): {exc}")


def random_scene(seed: int, h: int = 72, w: int = 96, n: int = 10):
    """Random polylines (1..8 points, some off-frame) and random styles of every kind."""
    rng = np.random.default_rng(seed)
    lines = [rng.uniform([-8, -8], [w + 8, h + 8], (int(rng.integers(1, 9)), 2)) for _ in range(n)]
    kw = dict(
        width=rng.uniform(0.3, 24, n).tolist(),
        color=[tuple(rng.integers(0, 256, 3).tolist()) for _ in range(n)],
        outline=[tuple(rng.integers(0, 256, 3).tolist()) for _ in range(n)],
        outline_width=(rng.uniform(0, 4, n) * (rng.random(n) < 0.6)).tolist(),
        opacity=np.where(rng.random(n) < 0.5, 1.0, rng.uniform(0.2, 1, n)).tolist(),
        cap=[("round", "butt", "square")[i] for i in rng.integers(0, 3, n)])
    return rng, lines, kw


CASES = [  # dtype, shape, bgr, max abs diff, max share of differing samples
    (np.uint8, (72, 96, 3), True, 1, 1e-3),
    (np.uint8, (71, 93, 4), False, 1, 1e-3),  # widths not a multiple of 8: partial chunks
    (np.uint8, (70, 91), True, 1, 1e-3),
    (np.uint16, (72, 96, 4), False, 8, 2e-2),
    (np.float32, (72, 96), True, 1e-4, 1.0),
    (np.float16, (72, 96, 3), False, 1e-3, 1.0),
    (np.float32, (72, 96, 4), True, 1e-4, 1.0),
]


@pytest.mark.parametrize("dtype,shape,bgr,tol,share", CASES)
@pytest.mark.parametrize("seed", [0, 1])
def test_kernel_matches_reference(renderer, dtype, shape, bgr, tol, share, seed):
    rng, lines, kw = random_scene(seed)
    if np.issubdtype(dtype, np.integer):
        frame = rng.integers(0, np.iinfo(dtype).max + 1, shape).astype(dtype)
    else:
        frame = rng.random(shape).astype(dtype)
    out = renderer.draw(frame, lines, bgr=bgr, **kw)
    ref = reference_draw_polylines(frame, lines, bgr=bgr, **kw)
    assert out.dtype == frame.dtype and out.shape == frame.shape
    d = np.abs(out.astype(np.float64) - ref.astype(np.float64))
    assert d.max() <= tol
    assert (d > 0).mean() <= share
    assert (out != frame).mean() > 0.3  # the scene draws over much of the frame


def test_enc8_table_known_answers():
    """uint8 encode table: every byte's decoded value encodes back to the byte; against the exact
    sRGB curve rounded half up, off by at most 1 level on <= 0.2% of random linear values."""
    table = enc8_table()
    dec = lut_read(device_luts(), np.arange(256) / 255.0).astype(np.float32)
    assert np.array_equal(enc8_read(table, dec.astype(np.float64)), np.arange(256))
    x = np.random.default_rng(0).random(100000)
    d = np.abs(enc8_read(table, x).astype(int) - np.floor(linear_to_srgb(x) * 255 + 0.5))
    assert d.max() <= 1 and (d > 0).mean() <= 2e-3


@pytest.mark.parametrize("shape", [(40, 61, 3), (40, 61, 4), (40, 61)])
def test_uint8_zero_opacity_keeps_every_byte(renderer, shape):
    """Known answer: lines of opacity 0 cover pixels that are decoded, composited under nothing
    and encoded again (uint8 write-back): every byte comes back as it was."""
    frame = np.random.default_rng(5).integers(0, 256, shape).astype(np.uint8)
    if len(shape) == 3 and shape[2] == 4:
        frame[..., 3] = 255  # opaque (where alpha is 0 the colour is undefined and becomes 0)
    lines = [np.array([[-3.0, 2.0], [30.0, 37.5], [64.0, 5.0]]), np.array([[5.0, 20.0], [56.0, 21.0]])]
    out = renderer.draw(frame, lines, width=[1.0, 9.0], opacity=0.0)
    assert np.array_equal(out, frame)


def test_pixels_beyond_reach_are_untouched(renderer):
    rng = np.random.default_rng(3)
    frame = rng.integers(0, 256, (64, 80, 3)).astype(np.uint8)
    line = np.array([[10.0, 20.0], [70.0, 40.0]])
    out = renderer.draw(frame, [line], width=5, color=(0, 0, 255))
    yy, xx = np.mgrid[0:64, 0:80]
    t = np.clip(((xx - 10) * 60 + (yy - 20) * 20) / (60 ** 2 + 20 ** 2), 0, 1)
    dist = np.hypot(xx - 10 - 60 * t, yy - 20 - 20 * t)
    far = dist > 2.5 + math.sqrt(0.5) + 1e-3
    assert np.array_equal(out[far], frame[far])
    assert (out[dist < 2.5 - math.sqrt(0.5)] == (0, 0, 255)).all()  # BGR tuple, as cv2


# ------------------------------------------------------------------------- known answers

BG8, FILL8, OUT8 = (90, 90, 90), (250, 200, 40), (10, 20, 160)


def _expected(cov: float, fg=FILL8, bg=BG8) -> np.ndarray:
    lin = cov * srgb_to_linear(np.array(fg) / 255) + (1 - cov) * srgb_to_linear(np.array(bg) / 255)
    return linear_to_srgb(lin)


@pytest.mark.parametrize("impl", ["kernel", "reference"])
def test_horizontal_road_width_4(renderer, impl):
    """Centre y = 10.3, width 4: edges at 8.3 and 12.3, so rows 9..11 are inside, row 8 is covered
    0.2, row 12 0.8, rows 7 and 13 are untouched (away from the caps)."""
    frame = np.empty((24, 64, 3), np.float32)
    frame[:] = np.array(BG8) / 255
    line = np.array([[-20.0, 10.3], [90.0, 10.3]])
    kw = dict(width=4.0, color="#%02x%02x%02x" % FILL8, bgr=False)
    out = renderer.draw(frame, [line], **kw) if impl == "kernel" else \
        reference_draw_polylines(frame, [line], **kw)
    mid = out[:, 8:56]
    assert np.array_equal(mid[9:12], np.broadcast_to(np.float32(np.array(FILL8) / 255), mid[9:12].shape))
    assert np.array_equal(mid[:8], frame[:8, 8:56]) and np.array_equal(mid[13:], frame[13:, 8:56])
    np.testing.assert_allclose(mid[8], np.broadcast_to(_expected(0.2), mid[8].shape), atol=1e-3)
    np.testing.assert_allclose(mid[12], np.broadcast_to(_expected(0.8), mid[12].shape), atol=1e-3)


@pytest.mark.parametrize("impl", ["kernel", "reference"])
def test_outline_band(renderer, impl):
    """Width 8, outline 2 at y = 20: outline over [16, 18] and [22, 24], fill over [18, 22]."""
    frame = np.empty((40, 64, 3), np.uint8)
    frame[:] = BG8
    line = np.array([[-20.0, 20.0], [90.0, 20.0]])
    kw = dict(width=8.0, color=FILL8, outline=OUT8, outline_width=2.0, bgr=False)
    out = renderer.draw(frame, [line], **kw) if impl == "kernel" else \
        reference_draw_polylines(frame, [line], **kw)
    mid = out[:, 8:56].astype(int)
    assert (mid[17] == OUT8).all() and (mid[23] == OUT8).all()
    assert (mid[19:22] == FILL8).all()
    assert np.array_equal(mid[:15], frame[:15, 8:56]) and np.array_equal(mid[26:], frame[26:, 8:56])
    # row 18 straddles the outline/fill border: half of each, mixed in linear light
    half = linear_to_srgb(0.5 * srgb_to_linear(np.array(FILL8) / 255)
                          + 0.5 * srgb_to_linear(np.array(OUT8) / 255)) * 255
    assert np.abs(mid[18] - half).max() <= 1
    assert np.abs(mid[16] - _expected(0.5, OUT8) * 255).max() <= 1  # outer edge: half covered


def _square_area_below(nx: float, ny: float, c: float, px: float, py: float) -> float:
    """Exact area of the pixel square around (px, py) where nx*x + ny*y <= c (polygon clipping)."""
    poly = [(px - .5, py - .5), (px + .5, py - .5), (px + .5, py + .5), (px - .5, py + .5)]
    out = []
    for i in range(4):
        a, b = poly[i], poly[(i + 1) % 4]
        fa, fb = nx * a[0] + ny * a[1] - c, nx * b[0] + ny * b[1] - c
        if fa <= 0:
            out.append(a)
        if (fa < 0) != (fb < 0) and fa != fb:
            t = fa / (fa - fb)
            out.append((a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])))
    if len(out) < 3:
        return 0.0
    nxt = out[1:] + out[:1]
    return 0.5 * abs(sum(a[0] * b[1] - b[0] * a[1] for a, b in zip(out, nxt)))


@pytest.mark.parametrize("angle", [0.0, 17.0, 30.0, 45.0, 71.0])
def test_tilted_edge_is_exact_box_coverage(renderer, angle):
    """A 200-px road at an angle, linear float frame, black under white: each pixel's value is its
    coverage, which must equal the exact area of the pixel square on the road's side of the edge."""
    a = math.radians(angle)
    t = np.array([math.cos(a), math.sin(a)])
    n = np.array([-t[1], t[0]])
    m = np.array([32.2, 32.7])  # the edge passes here; the road's other edge is 200 px away
    c = m - 100 * n
    line = np.array([c - 400 * t, c + 400 * t])
    frame = np.zeros((64, 64, 3), np.float32)
    r2 = OverlayRenderer(linear=True)
    out = r2.draw(frame, [line], width=200.0, color="#ffffff", bgr=False)[..., 0]
    edge = n @ m  # the road is n.x <= edge inside the frame
    exact = np.array([[_square_area_below(n[0], n[1], edge, x, y) for x in range(64)] for y in range(64)])
    np.testing.assert_allclose(out, exact, atol=5e-5)  # float32 at coordinates ~400 px
    assert ((exact > 0) & (exact < 1)).sum() > 40  # the edge crosses the frame


def test_footprint_cdf_is_the_box_coverage():
    """Reference of the kernel's ramp: a = b = 1/sqrt(2) is a 45-degree edge; b = 0 the seed's ramp."""
    s = np.linspace(-1, 1, 41)
    np.testing.assert_allclose(footprint_cdf(s, 1.0, 0.0), np.clip(s + 0.5, 0, 1))
    k = math.sqrt(0.5)
    exact = [_square_area_below(k, k, v, 0.0, 0.0) for v in s]
    np.testing.assert_allclose(footprint_cdf(s, k, k), exact, atol=1e-12)


def test_error_against_supersampled_truth_is_small(renderer):
    """Random polylines of widths 1..12 against 8x8 point samples resolved in linear light."""
    from mlaa_stream.bench.overlay import draw_grlaa, random_lines, truth_image
    rng = np.random.default_rng(11)
    h, w = 90, 120
    lines = random_lines(rng, 8, h, w, margin=8)
    widths = [1.0, 1.5, 2.0, 3.0, 4.0, 6.0, 9.0, 12.0]
    truth = truth_image(lines, widths, h, w)
    ours = draw_grlaa(renderer, lines, widths, h, w).astype(np.float64) / 255
    bg = truth[0, 0]
    near = (np.abs(truth - bg).max(-1) > 0.5 / 255) | (np.abs(ours - bg).max(-1) > 0.5 / 255)
    err = np.abs(ours - truth).max(-1)[near] * 255
    assert near.sum() > 2000
    # 8-bit levels; measured 0.89 and 10.3. The largest errors sit where a polyline crosses
    # itself (its segments merge by max, the truth by union). cv2 LINE_AA: docs/grlaa_bench.md.
    assert err.mean() < 1.2
    assert np.quantile(err, 0.99) < 14


# ------------------------------------------------------------------------------- API

def test_inplace_and_copy(renderer):
    frame = np.full((20, 30, 3), 7, np.uint8)
    line = np.array([[2.0, 10.0], [28.0, 10.0]])
    out = renderer.draw(frame, [line], width=3)
    assert out is not frame and (frame == 7).all() and (out != 7).any()
    same = renderer.draw(frame, [line], width=3, inplace=True)
    assert same is frame and np.array_equal(frame, out)
    ro = np.full((20, 30, 3), 7, np.uint8)
    ro.flags.writeable = False
    with pytest.raises(ValueError, match="expected a writeable array"):
        renderer.draw(ro, [line], inplace=True)


def test_buffers_kept_between_frames(renderer):
    r = OverlayRenderer(zero_copy=False)
    f = np.zeros((30, 40, 3), np.uint8)
    r.draw(f, [np.array([[1.0, 1.0], [30.0, 20.0]])])
    buf, kern = r._frame_buf, r._kernel
    r.draw(f, [np.array([[5.0, 1.0], [35.0, 25.0]])], width=4)
    assert buf is not None and r._frame_buf is buf and r._kernel is kern


@pytest.mark.parametrize("zero_copy", [True, False])
def test_kept_tables_and_arguments_follow_every_change(zero_copy):
    """A renderer keeps the last style's tables, the lines' tables and the kernels' arguments
    between frames; every change of style, point counts, frame size or format is drawn as a new
    renderer draws it, including with a second renderer drawing on the same device in between."""
    rng = np.random.default_rng(11)
    r, other = OverlayRenderer(zero_copy=zero_copy), OverlayRenderer(zero_copy=zero_copy)
    lines_a = [rng.uniform(-4, 70, (k, 2)) for k in (2, 5, 9)]
    lines_b = [rng.uniform(-4, 70, (k, 2)) for k in (2, 5, 9)]   # same point counts as lines_a
    lines_c = [rng.uniform(-4, 70, (k, 2)) for k in (3, 1, 7, 4)]
    calls = [
        ((72, 96, 3), lines_a, dict(width=1.0, color=(250, 200, 10))),
        ((72, 96, 3), lines_b, dict(width=1.0, color=(250, 200, 10))),
        ((72, 96, 3), lines_b, dict(width=6.0, color=(250, 200, 10), outline_width=1.5)),
        ((72, 96, 3), lines_c, dict(width=6.0, color=(250, 200, 10), outline_width=1.5)),
        ((72, 96, 3), lines_c, dict(width=[1.0, 3.0, 9.0, 2.0], color="#20f0a0")),
        ((72, 96, 3), lines_a, dict(width=1.0, color=(250, 200, 10))),
        ((50, 61), lines_a, dict(width=2.5, cap="square")),
        ((72, 96, 3), lines_a, dict(width=1.0, color=(250, 200, 10))),
    ]
    for i, (shape, lines, kw) in enumerate(calls):
        frame = rng.integers(0, 256, shape).astype(np.uint8)
        other.draw(frame, lines_c, width=3.0)  # the same device's kernels, other arguments
        got = r.draw(frame, lines, **kw)
        want = OverlayRenderer(zero_copy=zero_copy).draw(frame, lines, **kw)
        assert np.array_equal(got, want), f"call {i}"


def test_checked_lines_fast_and_general_paths_agree():
    """Lists of float64 (N, 2) arrays are checked through their concatenation; anything else
    goes through the per-line path; both give the same lines and name the same bad line."""
    rng = np.random.default_rng(3)
    lines = [rng.uniform(0, 50, (k, 2)) for k in (1, 4, 2)]
    fast = as_lines(lines)
    assert fast is lines or all(a is b for a, b in zip(fast, lines))
    general = as_lines([a.tolist() for a in lines])
    assert all(np.array_equal(a, b) for a, b in zip(fast, general))
    bad = [a.copy() for a in lines]
    bad[2][1, 0] = np.inf
    with pytest.raises(ValueError, match="line 2: expected finite"):
        as_lines(bad)
    with pytest.raises(ValueError, match=r"line 1: expected points of shape \(N, 2\), got \(0, 2\)"):
        as_lines([lines[0], np.zeros((0, 2))])
    with pytest.raises(ValueError, match=r"line 1: expected points of shape"):
        as_lines([lines[0], np.zeros((3, 1))])


@pytest.mark.parametrize("dtype,shape", [(np.uint8, (72, 96, 3)), (np.float32, (72, 96, 4)),
                                         (np.float16, (72, 96))])
def test_zero_copy_and_device_buffer_paths_agree(renderer, dtype, shape):
    """Drawing straight into the numpy frame and through a device buffer give the same bits."""
    rng, lines, kw = random_scene(3)
    frame = (rng.random(shape) * (255 if dtype == np.uint8 else 1)).astype(dtype)
    outs = []
    for zc in (True, False):
        r = OverlayRenderer(zero_copy=zc)
        copy = r.draw(frame, lines, **kw)
        f = frame.copy()
        assert r.draw(f, lines, inplace=True, **kw) is f
        assert np.array_equal(copy, f) and copy.dtype == frame.dtype
        outs.append(copy)
    assert np.array_equal(outs[0], outs[1])
    assert (outs[0] != frame).mean() > 0.3


@pytest.mark.parametrize("offset", [0, 1, 3, 100])
def test_drawing_in_place_into_unaligned_frames(offset):
    """Zero-copy drawing reads no map back on PoCL (the kernel writes the array itself): frames at
    any byte offset, in place and into copies, equal the device-buffer path's, over two frames."""
    rng, lines, kw = random_scene(6, n=14)
    h, w = 72, 96
    store = np.zeros(h * w * 3 + offset, np.uint8)
    frame = store[offset:].reshape(h, w, 3)
    frame[...] = rng.integers(0, 256, (h, w, 3))
    direct, buffered = OverlayRenderer(zero_copy=True), OverlayRenderer(zero_copy=False)
    for lines_now in (lines, [ln[::-1] + 1.5 for ln in lines]):
        want = buffered.draw(frame, lines_now, **kw)
        assert np.array_equal(direct.draw(frame, lines_now, **kw), want)
        f = frame.copy() if offset == 0 else frame
        before = f.copy()
        assert direct.draw(f, lines_now, inplace=True, **kw) is f
        assert np.array_equal(f, want) and (f != before).mean() > 0.1
        frame[...] = before


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_thin_and_outlined_strokes_match_reference(renderer, seed):
    """The kernel's 8-pixel lanes (kernels/grlaa.cl round_cover8): thin strokes (both edges' terms),
    strokes just above and below the footprint's half diagonal (the second edge's term skipped or
    not), outlines, opacities, at random angles, on a float32 frame whose width (45) is not a
    multiple of 8 or of the tile, so lanes and tiles cross the frame's right edge. Tolerance 1e-4
    (float32 kernel vs float64 reference, same tables)."""
    rng = np.random.default_rng(100 + seed)
    h, w, n = 40, 45, 14
    lines = [rng.uniform([-3, -3], [w + 3, h + 3], (int(rng.integers(2, 6)), 2)) for _ in range(n)]
    widths = rng.choice([0.3, 0.8, 1.0, 1.41, 1.42, 1.5, 2.0, 3.0], n)
    kw = dict(width=widths.tolist(), color=[tuple(rng.integers(0, 256, 3).tolist()) for _ in range(n)],
              outline=[tuple(rng.integers(0, 256, 3).tolist()) for _ in range(n)],
              outline_width=(widths * rng.choice([0.0, 0.2, 0.4], n)).tolist(),
              opacity=np.where(rng.random(n) < 0.5, 1.0, rng.uniform(0.3, 1, n)).tolist())
    frame = rng.random((h, w, 3)).astype(np.float32)
    out = renderer.draw(frame, lines, **kw)
    ref = reference_draw_polylines(frame, lines, **kw)
    assert np.abs(out.astype(np.float64) - ref).max() <= 1e-4
    assert (out != frame).any(axis=2)[:, -1].any()  # lines reach the last column


@pytest.mark.parametrize("shape,bgr", [((75, 101, 3), True), ((75, 101, 4), False), ((75, 101), True)])
def test_every_tile_size_draws_the_same(shape, bgr):
    """uint8 frames (the listed write-back of kernels/grlaa.cl: q in a byte up to 16 x 16 tiles, in
    a ushort for 32 x 32): tiles of 8, 16 and 32 draw the same bytes, within 1 level of the
    reference on <= 0.1% of samples, on a frame whose width is no multiple of 8, with strokes wide
    enough to cover whole tiles (every pixel of a 32 x 32 tile listed)."""
    rng, lines, kw = random_scene(5, h=shape[0], w=shape[1], n=12)
    kw["width"][:2] = [70.0, 45.0]
    frame = rng.integers(0, 256, shape).astype(np.uint8)
    outs = [OverlayRenderer(tile=t).draw(frame, lines, bgr=bgr, **kw) for t in (8, 16, 32)]
    assert np.array_equal(outs[0], outs[1]) and np.array_equal(outs[1], outs[2])
    ref = reference_draw_polylines(frame, lines, bgr=bgr, **kw)
    d = np.abs(outs[1].astype(np.int16) - ref.astype(np.int16))
    assert d.max() <= 1 and (d > 0).mean() <= 1e-3
    assert (outs[1] != frame).mean() > 0.5


def test_style_arguments_kept_only_while_equal(renderer):
    """draw keeps the styles built for its last (hashable) style arguments; other arguments,
    or unhashable ones (lists, arrays), build them anew."""
    r = OverlayRenderer()
    f = np.zeros((20, 30, 3), np.uint8)
    lines = [np.array([[2.0, 3.0], [25.0, 15.0]])]
    a = r.draw(f, lines, width=2, color=(10, 200, 30))
    styles = r._styles_cache[1]
    b = r.draw(f, lines, width=2, color=(10, 200, 30))
    assert r._styles_cache[1] is styles and np.array_equal(a, b)
    c = r.draw(f, lines, width=2, color=(10, 200, 31))
    styles_c = r._styles_cache[1]
    assert styles_c is not styles and not np.array_equal(a, c)
    d = r.draw(f, lines, width=[2.0], color=np.array([10, 200, 30]))
    assert np.array_equal(a, d) and r._styles_cache[1] is styles_c


def test_one_pixel_line_known_answer(renderer):
    """A horizontal 1-px line centred at y = 10.25 covers row 10 by 0.75 and row 11 by 0.25 (the
    linear ramp, exact for an axis-aligned edge); a vertical one likewise per column; the join of
    the two (an L) is drawn once (max), not blended twice."""
    frame = np.zeros((24, 30), np.float32)
    r2 = OverlayRenderer(linear=True)
    line = np.array([[3.0, 10.25], [20.0, 10.25], [20.0, 2.0]])
    out = r2.draw(frame, [line], width=1.0, color="#ffffff", bgr=False)
    np.testing.assert_allclose(out[10, 5:19], 0.75, atol=1e-6)
    np.testing.assert_allclose(out[11, 5:19], 0.25, atol=1e-6)
    assert (out[12:] == 0).all() and (out[:9, :19] == 0).all()
    np.testing.assert_allclose(out[3:9, 20], 1.0, atol=1e-6)  # vertical leg: column 20 fully
    assert (out[3:9, 19] == 0).all() and (out[3:9, 21] == 0).all()
    assert out.max() <= 1.0  # the corner is not covered twice


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_binning_lists_every_touched_tile(seed):
    """Device binning: every pixel a segment covers (numpy reference) lies in a tile that lists
    the segment, and each segment is listed once per tile."""
    rng, lines, kw = random_scene(seed, h=90, w=120, n=12)
    pts = as_lines(lines)
    styles = make_styles(len(pts), kw["width"], kw["color"], kw["outline"], kw["outline_width"],
                         kw["opacity"], kw["cap"])
    tables = segment_tables(pts, styles, 3, clip=(120, 90))
    frame = np.zeros((90, 120, 3), np.uint8)
    for tile in (8, 16, 32):
        entries, tiles = OverlayRenderer(tile=tile).bin(tables, frame)
        assert len(set(map(tuple, tiles[:, :2].tolist()))) == len(tiles)
        listed = set(zip(np.repeat(tiles[:, 0] + 1000 * tiles[:, 1], tiles[:, 3]).tolist(),
                         entries.tolist()))
        # drawing order within each tile
        for t in tiles:
            e = entries[t[2]:t[2] + t[3]]
            assert (np.diff(e) > 0).all()
        py, px = np.mgrid[0:90, 0:120].astype(np.float64)
        for s in range(len(tables.ends)):
            k = int(tables.meta[s]) >> 3
            co, _ = _segment_cover(px, py, tables.ends[s], int(tables.meta[s]),
                                   float(tables.polys[k, 0, 0]), float(tables.polys[k, 0, 1]), 1.0)
            ys, xs = np.nonzero(co > 0)
            need = set((xs // tile + 1000 * (ys // tile)).tolist())
            assert all((t, s) in listed for t in need), (tile, s)


def test_noncontiguous_and_float16_frames(renderer):
    rng = np.random.default_rng(5)
    base = rng.random((40, 50, 3)).astype(np.float16)
    view = base[:, ::-1]  # not C-contiguous
    line = [np.array([[3.0, 3.0], [45.0, 30.0], [10.0, 35.0]])]
    out = renderer.draw(view, line, width=3, outline_width=1)
    ref = reference_draw_polylines(np.ascontiguousarray(view), line, width=3, outline_width=1)
    assert out.dtype == np.float16
    assert np.abs(out.astype(np.float64) - ref.astype(np.float64)).max() <= 1e-3


def test_lines_off_frame_and_empty(renderer):
    frame = np.random.default_rng(2).integers(0, 256, (16, 16, 3)).astype(np.uint8)
    assert np.array_equal(renderer.draw(frame, [np.array([[-50.0, -50.0], [-20.0, -30.0]])]), frame)
    assert np.array_equal(renderer.draw(frame, []), frame)


def test_huge_coordinates_are_clipped_exactly(renderer):
    frame = np.full((40, 60, 3), 50, np.uint8)
    lines = [np.array([[-1e7, -0.5e7], [1e7, 0.5e7 + 10]]), np.array([[-100.0, 30.0], [1e5, 30.3]])]
    out = renderer.draw(frame, lines, width=3, cap="butt")
    ref = reference_draw_polylines(frame, lines, width=3, cap="butt")
    assert np.abs(out.astype(int) - ref.astype(int)).max() <= 1 and (out != frame).any()


@pytest.mark.parametrize("far", [1e17, 1e18, 1e20, 1e300, 1.7e308])
def test_lines_from_astronomically_far_are_cut_to_the_frame_exactly(renderer, far):
    # the cut end was o + t * d in float64, off by ulp(|o|): a line from x = -1e18 to x = 30 drew 3 pixels, one
    # from -1e17 ended at 32; lines between two far ends (a line drawn "to infinity") drew 4 pixels
    frame = np.full((40, 60, 3), 30, np.uint8)
    for far_line, near_line, kw in (
            ([[-far, 20.0], [30.0, 20.0]], [[-100.0, 20.0], [30.0, 20.0]], dict(width=3, cap="butt")),
            ([[-far, -far], [far, far]], [[-100.0, -100.0], [100.0, 100.0]], dict(width=3)),
            ([[-far, 7.0], [far, 7.0], [far, 9.0]], [[-100.0, 7.0], [100.0, 7.0]], dict(width=2))):
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # no float64 overflow on the way either
            out = renderer.draw(frame, [np.array(far_line)], **kw)
        assert np.array_equal(out, renderer.draw(frame, [np.array(near_line)], **kw)), far_line


@pytest.mark.parametrize("seed", [0, 1])
def test_device_segment_tables_match_numpy(renderer, seed):
    """kernels/grlaa.cl grlaa_segments (float32, points within DEVICE_CLIP_MARGIN of the frame)
    against the float64 segment_tables, clipping included: same segments, flags and styles;
    positions within 2e-4 px (float32 at a few thousand px), tangents within 1e-5; the segments
    the numpy clipping drops get reach -1 (not binned)."""
    rng = np.random.default_rng(seed)
    h, w = 60, 80
    lines = [rng.uniform([-3000, -3000], [w + 3000, h + 3000], (int(rng.integers(1, 7)), 2))
             for _ in range(40)]
    lines += [np.array([[-5.0, 30.5], [40.0, 31.0], [400.0, 20.0]]), np.array([[30.0, 20.0]])]
    styles = make_styles(len(lines), rng.uniform(0.5, 12, len(lines)).tolist(),
                         cap=[("round", "butt", "square")[i] for i in rng.integers(0, 3, len(lines))])
    frame = np.zeros((h, w, 3), np.uint8)
    r = OverlayRenderer()
    r.draw(frame, lines[:1])  # set up for this frame size
    lt = line_tables(styles, 3)
    segs_b, meta_b, n = r._segments(as_lines(lines), styles, lt, r._fmt)
    segs, meta = np.empty((n, 8), np.float32), np.empty(n, np.int32)
    q = r._ctx.queue
    cl.enqueue_copy(q, segs, segs_b)
    cl.enqueue_copy(q, meta, meta_b, is_blocking=True)
    cl.enqueue_copy(q, r._counts, np.zeros(int(np.prod(r._tiles_xy)), np.int32), is_blocking=True)
    r._inputs.clear()
    full = segment_tables(as_lines(lines), styles, 3)               # every segment, not clipped
    cut = segment_tables(as_lines(lines), styles, 3, clip=(w, h))   # the ones kept, clipped
    assert n == len(full.segs)
    np.testing.assert_array_equal(meta, full.meta)
    kept = segs[:, 7] >= 0
    assert kept.sum() == len(cut.segs)
    np.testing.assert_array_equal(meta[kept], cut.meta)
    d, e = segs[kept], cut.segs
    np.testing.assert_allclose(d[:, [5, 6, 7]], e[:, [5, 6, 7]], rtol=1e-6)
    np.testing.assert_allclose(d[:, [2, 3]], e[:, [2, 3]], atol=1e-5)
    # start and end points (a + length * t) within 2e-4 px
    pd, pe = d[:, :2].astype(np.float64), e[:, :2].astype(np.float64)
    ed, ee = pd + d[:, 4:5] * d[:, 2:4], pe + e[:, 4:5] * e[:, 2:4]
    assert np.abs(pd - pe).max() <= 2e-4 and np.abs(ed - ee).max() <= 2e-4
    out = r.draw(frame, lines, width=styles[0].width)  # and the drawing: kernel vs reference
    ref = reference_draw_polylines(frame, lines, width=styles[0].width)
    assert np.abs(out.astype(int) - ref.astype(int)).max() <= 1


def test_tile_overflow_bins_again_with_more_room():
    """A tile listing more segments than its room: nothing is drawn, the room doubles and the
    frame is drawn again; the result is the same as with room to spare."""
    rng, lines, kw = random_scene(4, n=30)
    frame = rng.integers(0, 256, (72, 96, 3)).astype(np.uint8)
    r = OverlayRenderer()
    want = r.draw(frame, lines, **kw)
    r._cap = 1  # (the buffer is larger than needed: only the room per tile shrinks)
    got = r.draw(frame, lines, **kw)
    assert r._cap > 1 and np.array_equal(got, want)
    ref = reference_draw_polylines(frame, lines, **kw)
    assert np.abs(got.astype(int) - ref.astype(int)).max() <= 1


@pytest.mark.parametrize("zero_copy", [True, False])
def test_a_failed_frame_leaves_the_renderer_usable(monkeypatch, zero_copy):
    """An error after the frame's segments were binned (here, interrupting the draw): the
    binning's counters are cleared, and the next frame is drawn as by a fresh renderer."""
    rng, lines, kw = random_scene(5, n=12)
    frame = rng.integers(0, 256, (72, 96, 3)).astype(np.uint8)
    want = OverlayRenderer(zero_copy=zero_copy).draw(frame, lines, **kw)
    r = OverlayRenderer(zero_copy=zero_copy)

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(r, "_draw_binned", interrupted)
    with pytest.raises(KeyboardInterrupt):
        r.draw(frame, lines, **kw)
    monkeypatch.undo()
    assert np.array_equal(r.draw(frame, lines, **kw), want)


@pytest.mark.parametrize("bad,match", [
    (dict(lines=[np.array([[0.0, np.nan], [3.0, 4.0]])]), "line 0: expected finite coordinates"),
    (dict(width=0.0), "expected width > 0"),
    (dict(color="#12345"), "expected '#rrggbb'"),
    (dict(color=(300, 0, 0)), "expected 3 numbers 0..255"),
    (dict(cap="arrow"), "expected cap one of"),
    (dict(opacity=1.5), "expected opacity in"),
    (dict(width=[1.0, 2.0]), "expected one value or 1"),
])
def test_bad_arguments(renderer, bad, match):
    kw = dict(lines=[np.array([[0.0, 0.0], [3.0, 4.0]])])
    kw.update(bad)
    with pytest.raises(ValueError, match=match):
        renderer.draw(np.zeros((8, 8, 3), np.uint8), **kw)


def test_bad_frame(renderer):
    with pytest.raises(ValueError, match=r"expected shape \(H, W\) or \(H, W, 1\|3\|4\)"):
        draw_polylines(np.zeros((8, 8, 2), np.uint8), [np.array([[0.0, 0.0], [1.0, 1.0]])])


def test_parse_color():
    assert parse_color("#ff8000") == (1.0, 128 / 255, 0.0)
    assert parse_color([0, 255, 51]) == (0.0, 1.0, 0.2)


def test_a_colour_on_a_zero_to_one_scale_is_refused_not_drawn_near_black():
    # [1.0, 0.5, 0] on the 0..255 scale is under one level per channel: the line came out black without a word
    with pytest.raises(ValueError, match=r"route: color: expected 3 numbers 0..255, got .*multiply it by 255"):
        parse_color([1.0, 0.5, 0.0], "route: color")
    assert parse_color([1, 0, 1]) == (1 / 255, 0.0, 1 / 255)   # whole levels stay levels
    assert parse_color([0.0, 0.0, 0.0]) == (0.0, 0.0, 0.0)


@pytest.mark.parametrize("bad", ["#-1-1-1", "+f+f+f", "# 1 1 1", "#\uff11\uff11\uff11"])
def test_parse_color_takes_hex_digits_only(bad):
    # int(s, 16) took a sign and spaces: '#-1-1-1' was -1/255 per channel (below black), drawn as black
    with pytest.raises(ValueError, match="expected '#rrggbb'"):
        parse_color(bad)


def test_colours_as_one_number_and_per_line_lists_of_mixed_forms(renderer):
    # a number (cv2's grey colour) raised TypeError ('int' object is not iterable), and a per-line list mixing
    # a string and a tuple numpy's "inhomogeneous shape" ValueError
    frame = np.zeros((16, 24, 3), np.uint8)
    line = np.array([[2.0, 8.0], [21.0, 8.0]])
    assert parse_color(128) == parse_color((128,)) == parse_color(np.array(128)) == (128 / 255,) * 3
    assert (renderer.draw(frame, [line], width=3, color=128)[8, 10] == 128).all()
    out = renderer.draw(frame, [line, line + [0, 5]], width=3, color=["#ff0000", (0, 255, 0)], bgr=True)
    assert tuple(out[8, 10]) == (0, 0, 255) and tuple(out[13, 10]) == (0, 255, 0)


# ------------------------------------------------------------------------- overlay files

def _write(tmp_path, doc, name="ov.geojson"):
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return str(p)


def test_load_overlay_fixed_and_per_frame(renderer, tmp_path):
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "LineString", "coordinates": [[2, 5], [28, 5]]},
         "properties": {"width": 3, "color": "#ff0000"}},
        {"type": "Feature", "geometry": None,
         "properties": {"width": 2, "color": [0, 0, 255],
                        "frames": {"1": [[2, 15], [28, 15]],
                                   "2": [[[2, 12], [10, 12]], [[20, 18], [28, 18]]]}}},
        {"type": "Feature", "properties": {"first_frame": 2, "color": "#00ff00"},
         "geometry": {"type": "MultiLineString", "coordinates": [[[15, 0], [15, 19]]]}},
    ]}
    draw = load_overlay(_write(tmp_path, doc), bgr=True)
    f = np.zeros((20, 30, 3), np.uint8)
    o0, o1, o2 = draw(f, 0), draw(f, 1), draw(f, 2)
    assert (o0[5, 10] == (0, 0, 255)).all()           # file colours are RGB; frames BGR
    assert (o0[15] == 0).all() and (o1[15, 10] == (255, 0, 0)).all()
    assert (o2[12, 5] == (255, 0, 0)).all() and (o2[18, 25] == (255, 0, 0)).all()
    assert (o0[10, 15] == 0).all() and (o2[10, 15] == (0, 255, 0)).all()
    assert (f == 0).all()  # not drawn in place by default


@pytest.mark.parametrize("doc,match", [
    ({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {},
      "geometry": {"type": "Circle", "coordinates": [1, 2]}}]}, "feature 0: expected a GeoJSON geometry"),
    ({"type": "FeatureCollection", "features": [{"type": "Feature", "properties": {"width": -1},
      "geometry": {"type": "LineString", "coordinates": [[1, 2], [3, 4]]}}]},
     "feature 0: expected width > 0"),
    ({"type": "Feature", "geometry": None, "properties": {"frames": {"x": [[1, 2]]}}},
     "expected frame indices >= 0"),
    ({"type": "Feature", "geometry": None, "properties": {}}, "expected a geometry or 'frames'"),
    ({"features": []}, "expected a GeoJSON object with a 'type'"),
])
def test_overlay_file_errors_name_file_and_feature(tmp_path, doc, match):
    path = _write(tmp_path, doc)
    with pytest.raises(ValueError, match=match) as info:
        load_overlay(path)
    assert path in str(info.value)


def test_overlay_file_not_json(tmp_path):
    p = tmp_path / "bad.json"
    p.write_text("{ nope")
    with pytest.raises(ValueError, match=r"bad.json: expected JSON, got an error at line 1"):
        load_overlay(str(p))


@pytest.mark.parametrize("encoding", ["utf-8-sig", "utf-16"])
def test_overlay_files_with_a_byte_order_mark_are_read(tmp_path, encoding):
    # a Windows editor's UTF-8 BOM was refused ("Unexpected UTF-8 BOM"), UTF-16 failed with the codec's message alone
    doc = {"type": "LineString", "coordinates": [[1, 2], [30, 20]]}
    p = tmp_path / "route.geojson"
    p.write_bytes(json.dumps(doc).encode(encoding))
    assert np.array_equal(load_overlay(str(p)).features[0].lines_at(0)[0], [[1, 2], [30, 20]])


def test_an_overlay_file_that_is_not_text_is_named(tmp_path):
    p = tmp_path / "route.geojson"
    p.write_bytes(b'{"type": "LineString", "coordinates": [[1, 2], [3, 4]], "name": "\xff"}')
    with pytest.raises(ValueError, match=r"route.geojson: expected JSON text \(UTF-8\), got bytes that are not text"):
        load_overlay(str(p))


@pytest.mark.parametrize("field,value,shown", [
    ("width", 1e40, "1e+40"), ("width", math.inf, "inf"), ("width", math.nan, "nan"), ("width", -2.0, "-2"),
    ("width", 65536.5, "65536.5"), ("outline_width", 1e40, "1e+40"), ("outline_width", -1.0, "-1")])
def test_absurd_widths_are_refused_naming_file_feature_and_value(tmp_path, field, value, shown):
    # a width of 1e40 passed the check (finite, > 0) and drew nothing: float32 made it infinite on the device
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main

    line = {"type": "LineString", "coordinates": [[1, 2], [30, 20]]}
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": line},
        {"type": "Feature", "properties": {field: value}, "geometry": line}]}
    path = _write(tmp_path, doc)
    with pytest.raises(ValueError, match=rf"expected {field} .*<= 65536 pixels, got {re.escape(shown)}\Z") as info:
        load_overlay(path)
    assert f"{path}: feature 1: expected {field} " in str(info.value)
    with pytest.raises(ValueError, match=rf"line 0: expected {field} .*got {re.escape(shown)}\Z"):
        draw_polylines(np.zeros((8, 8, 3), np.uint8), [np.array([[0.0, 0.0], [3.0, 4.0]])], **{field: value})
    out = tmp_path / "out"
    r = CliRunner().invoke(main, [os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "images"),
                                  "-o", str(out), "--overlay", path])
    assert r.exit_code == 2, r.output   # a usage error, as other bad --overlay files: nothing done
    assert f"--overlay {path}" in r.output and f"feature 1: expected {field} " in r.output and shown in r.output
    assert not out.exists()


def test_the_widest_stroke_allowed_is_drawn(renderer):
    from mlaa_stream.overlay.grlaa import MAX_WIDTH

    out = renderer.draw(np.zeros((8, 8, 3), np.uint8), [np.array([[0.0, 0.0], [3.0, 4.0]])], width=MAX_WIDTH)
    assert (out == 255).all()


def test_parse_bare_geometry():
    feats = parse_overlay({"type": "LineString", "coordinates": [[0, 0], [1, 1], [2, 0]]})
    assert len(feats) == 1 and feats[0].lines_at(5)[0].shape == (3, 2)


@pytest.mark.parametrize("geom", [
    {"type": "LineString", "coordinates": [[0, 0], [4, 2, 7.5], [9, 3]]},
    {"type": "MultiLineString", "coordinates": [[[0, 0], [4, 2, 7.5], [9, 3]], [[1, 1], [2, 2]]]},
])
def test_a_third_coordinate_on_some_positions_only_is_ignored(geom):
    # a position may carry an altitude (docs/grlaa.md: "a third coordinate is ignored"); on some points only, numpy
    # refused the ragged list: the LineString failed with numpy's own message (no file, no feature), the
    # MultiLineString with "expected coordinates"
    feats = parse_overlay({"type": "Feature", "properties": {}, "geometry": geom}, "route.geojson")
    assert np.array_equal(feats[0].lines_at(0)[0], [[0, 0], [4, 2], [9, 3]])
    frames = parse_overlay({"type": "Feature", "geometry": None, "properties": {"frames": {"3": geom["coordinates"]}}})
    assert np.array_equal(frames[0].lines_at(3)[0], [[0, 0], [4, 2], [9, 3]])
    bad = {"type": "LineString", "coordinates": [[0, 0], [4]]}
    with pytest.raises(ValueError, match=r"route.geojson: feature 0: line 0: expected positions .*fewer than 2"):
        parse_overlay({"type": "Feature", "properties": {}, "geometry": bad}, "route.geojson")


def test_geometries_other_than_lines_among_them():
    # a GeoJSON export mixes geometry types: one Point refused the whole file ("expected a LineString ... 'Point'");
    # points and empty geometries draw nothing, a polygon its rings as closed lines, a collection its members
    ring = [[0, 0], [4, 0], [4, 3], [0, 0]]
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {}, "geometry": {"type": "Point", "coordinates": [1, 2]}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "MultiPoint", "coordinates": [[1, 2], [3, 4]]}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "LineString", "coordinates": []}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [ring, ring[::-1]]}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "MultiPolygon", "coordinates": [[ring], []]}},
        {"type": "Feature", "properties": {}, "geometry": {"type": "GeometryCollection", "geometries": [
            {"type": "Point", "coordinates": [0, 0]}, {"type": "LineString", "coordinates": [[5, 5], [9, 9]]}]}},
    ]}
    feats = parse_overlay(doc, "mixed.geojson")
    assert [len(f.lines_at(0)) for f in feats] == [0, 0, 0, 2, 1, 1]
    assert np.array_equal(feats[3].lines_at(0)[1], np.array(ring[::-1], float))
    assert np.array_equal(feats[5].lines_at(0)[0], [[5, 5], [9, 9]])
    with pytest.raises(ValueError, match=r"mixed.geojson: feature 0: geometry 0: expected a GeoJSON geometry"):
        parse_overlay({"type": "Feature", "properties": {}, "geometry": {"type": "GeometryCollection",
                                                                         "geometries": [{"type": "Sphere"}]}},
                      "mixed.geojson")


# ---------------------------------------------------------------------------------- CLI

def _png(path, pixels):
    import OpenImageIO as oiio
    out = oiio.ImageOutput.create(path)
    fmt = "uint16" if pixels.dtype == np.uint16 else "uint8"
    assert out.open(path, oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt))
    assert out.write_image(pixels)
    out.close()


def test_cli_overlay(renderer, tmp_path):
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main
    src = str(tmp_path / "in.png")
    _png(src, np.full((30, 40, 3), 20000, np.uint16))
    lines = _write(tmp_path, {"type": "Feature", "properties": {"width": 4, "color": "#ffffff"},
                              "geometry": {"type": "LineString", "coordinates": [[3, 15], [37, 15]]}})
    dst = str(tmp_path / "out.png")
    run = CliRunner().invoke
    r = run(main, ["overlay", src, "-o", dst, "--lines", lines])
    assert r.exit_code == 0, r.output
    from mlaa_stream.io.images import read_image
    img = read_image(dst).pixels
    assert img.dtype == np.uint16 and (img[15, 20] == 65535).all() and (img[2, 2] == 20000).all()
    r = run(main, ["overlay", src, "-o", dst, "--lines", lines])
    assert r.exit_code == 2 and "exists; use --overwrite" in r.output
    assert run(main, ["overlay", src, "-o", dst, "--lines", lines, "--overwrite"]).exit_code == 0
    r = run(main, ["overlay", src, "-o", src, "--lines", lines, "--overwrite"])
    assert r.exit_code == 2 and "is the input" in r.output
    bad = tmp_path / "bad.json"
    bad.write_text("[]")
    r = run(main, ["overlay", src, "-o", str(tmp_path / "o2.png"), "--lines", str(bad)])
    assert r.exit_code == 1 and "bad.json" in r.output
    assert not os.path.exists(tmp_path / "o2.png")
    assert not [p for p in os.listdir(tmp_path) if "tmp" in p]



@pytest.mark.parametrize("where", ["nodir", "afile"])
def test_cli_overlay_into_a_missing_output_folder_names_the_folder(tmp_path, where):
    # OpenImageIO's error named the hidden temporary file, and under a file a Python warning (with its source line)
    # said the temporary file could not be removed
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main
    src = str(tmp_path / "in.png")
    _png(src, np.full((30, 40, 3), 200, np.uint8))
    (tmp_path / "afile").write_text("x")
    lines = _write(tmp_path, {"type": "LineString", "coordinates": [[3, 15], [37, 15]]})
    r = CliRunner().invoke(main, ["overlay", src, "-o", str(tmp_path / where / "out.png"), "--lines", lines])
    assert r.exit_code == 1, r.output
    assert f"{tmp_path / where}: the output folder does not exist" in r.output
    assert "tmp" not in r.output.replace(str(tmp_path), "") and "Warning" not in r.output


@pytest.mark.parametrize("which", [0, 1, 2])
def test_cli_overlay_refuses_standard_input_and_output(tmp_path, monkeypatch, which):
    # '-' was taken for a file name: "expected an image file, got nothing", "cannot read (No such file or
    # directory)" or, for -o, "no OpenImageIO writer for this extension"
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main
    monkeypatch.chdir(tmp_path)
    _png("in.png", np.full((30, 40, 3), 200, np.uint8))
    _write(tmp_path, {"type": "LineString", "coordinates": [[3, 15], [37, 15]]}, "l.json")
    args = ["in.png", "out.png", "l.json"]
    args[which] = "-"
    r = CliRunner().invoke(main, ["overlay", args[0], "-o", args[1], "--lines", args[2]])
    assert r.exit_code == 2, r.output
    assert f"{('IN_IMAGE', '-o', '--lines')[which]} -: standard input and output are not read or written" in r.output
    assert sorted(os.listdir(tmp_path)) == ["in.png", "l.json"]


def test_cli_overlay_refuses_an_exr_without_colour(tmp_path):
    """Lines drawn into a depth pass would be depths of nothing: refused, naming the channels (a traceback before)."""
    import OpenImageIO as oiio
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main
    src, dst = str(tmp_path / "depth.exr"), str(tmp_path / "out.exr")
    spec = oiio.ImageSpec(40, 30, 1, "float")
    spec.channelnames = ("Z",)
    out = oiio.ImageOutput.create(src)
    assert out.open(src, spec) and out.write_image(np.full((30, 40, 1), 7.5, np.float32)) and out.close()
    lines = _write(tmp_path, {"type": "Feature", "properties": {"width": 4, "color": "#ffffff"},
                              "geometry": {"type": "LineString", "coordinates": [[3, 15], [37, 15]]}})
    r = CliRunner().invoke(main, ["overlay", src, "-o", dst, "--lines", lines])
    assert r.exit_code == 1 and "expected colour channels to filter, got no colour channels (Z)" in r.output, r.output
    assert "Traceback" not in r.output and not os.path.exists(dst)

@pytest.mark.parametrize("zero_copy", [True, False])
def test_lines_wholly_far_off_the_frame_leave_it_unchanged(zero_copy):
    """Points over DEVICE_CLIP_MARGIN px off the frame are cut on the host; when every segment is cut away the
    tables are empty, which once made a zero-size OpenCL buffer (INVALID_BUFFER_SIZE) instead of drawing nothing."""
    rng = np.random.default_rng(3)
    frame = rng.integers(0, 256, (48, 64, 3)).astype(np.uint8)
    far = [np.array([[-500.0, -500.0], [1e6, 3000.0]]), np.array([[-9000.0, 10.0], [-8000.0, 40.0]])]
    r = OverlayRenderer(zero_copy=zero_copy)
    assert np.array_equal(r.draw(frame, far, width=3.0), frame)
    # the same renderer then draws a line on the frame as a new one does
    near = far + [np.array([[5.0, 5.0], [50.0, 40.0]])]
    assert np.array_equal(r.draw(frame, near, width=3.0),
                          OverlayRenderer(zero_copy=zero_copy).draw(frame, near, width=3.0))


def test_cli_filter_overlay_draws_linear_light_into_exrs(tmp_path):
    """`mlaa-stream shot.exr -o out.exr --overlay lines` drew the file's sRGB colours as they are into linear light
    (#3080ff's red 0.19 instead of 0.03: washed out), where `mlaa-stream overlay` composites EXRs as linear light.
    Each frame of a folder is drawn as it is: linear for the EXR, sRGB codes for the PNG."""
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main
    from mlaa_stream.io.images import read_image, write_image
    src = tmp_path / "shots"
    src.mkdir()
    write_image(str(src / "a.exr"), np.full((30, 40, 3), 0.2, np.float16))
    _png(str(src / "b.png"), np.full((30, 40, 3), 90, np.uint8))
    lines = _write(tmp_path, {"type": "Feature", "properties": {"width": 8, "color": "#3080ff"},
                              "geometry": {"type": "LineString", "coordinates": [[2, 15], [37, 15]]}})
    colour = np.array([0x30, 0x80, 0xFF]) / 255
    for args in ([str(src / "a.exr"), "-o", str(tmp_path / "one.exr")], [str(src), "-o", str(tmp_path / "out")],
                 [str(src), "-o", str(tmp_path / "out_t"), "--temporal"]):
        r = CliRunner().invoke(main, [*args, "--overlay", lines, "-q"])
        assert r.exit_code == 0, r.output
    for exr in (tmp_path / "one.exr", tmp_path / "out" / "a.exr", tmp_path / "out_t" / "a.exr"):
        np.testing.assert_allclose(read_image(str(exr)).pixels[15, 20, :3].astype(float), srgb_to_linear(colour),
                                   atol=2e-3)
    assert tuple(read_image(str(tmp_path / "out" / "b.png")).pixels[15, 20]) == (0x30, 0x80, 0xFF)


def _premultiplied_exr(path, shape=(30, 40)):
    import OpenImageIO as oiio
    spec = oiio.ImageSpec(shape[1], shape[0], 4, "half")
    spec.channelnames, spec.alpha_channel = ("R", "G", "B", "A"), 3
    px = np.zeros((*shape, 4), np.float32)
    px[..., :3], px[..., 3] = 0.1, 0.5   # straight 0.2 at alpha 0.5
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_image(px) and out.close()


def test_overlays_over_premultiplied_alpha_composite_as_premultiplied(renderer, tmp_path):
    """An EXR's RGBA is premultiplied; the renderer composites over straight alpha, and took the premultiplied
    colour for straight: white at opacity 0.5 over 0.1 at alpha 0.5 gave 0.70 (written premultiplied) where
    0.5 + 0.5 * 0.1 = 0.55 is right, in `mlaa-stream overlay` and in the filter's --overlay alike."""
    from click.testing import CliRunner
    from mlaa_stream.cli.main import main
    from mlaa_stream.io.images import read_image
    from mlaa_stream.overlay.grlaa import LineStyle
    src = str(tmp_path / "pm.exr")
    _premultiplied_exr(src)
    lines = _write(tmp_path, {"type": "Feature", "properties": {"width": 8, "color": "#ffffff", "opacity": 0.5},
                              "geometry": {"type": "LineString", "coordinates": [[2, 15], [37, 15]]}})
    for args in (["overlay", src, "-o", str(tmp_path / "a.exr"), "--lines", lines],
                 [src, "-o", str(tmp_path / "b.exr"), "--overlay", lines, "-q"]):
        r = CliRunner().invoke(main, args)
        assert r.exit_code == 0, r.output
    for name in ("a.exr", "b.exr"):
        px = read_image(str(tmp_path / name)).pixels.astype(np.float32)
        np.testing.assert_allclose(px[15, 20], [0.55, 0.55, 0.55, 0.75], atol=1e-3)
        np.testing.assert_array_equal(px[:5], read_image(src).pixels[:5].astype(np.float32))   # untouched
    # the API: 16-bit premultiplied samples, untouched ones bit for bit
    frame = np.zeros((16, 24, 4), np.uint16)
    frame[..., :3], frame[..., 3] = 9000, 30000
    frame[3, 3] = (7, 8, 9, 10)   # a dark, nearly transparent sample: its division must not come back changed
    out = renderer.draw_styled(frame, [np.array([[2.0, 10.0], [21.0, 10.0]])], [LineStyle(4.0, opacity=0.5)],
                               premultiplied=True)
    assert np.array_equal(out[:6], frame[:6])
    # as the same pixels drawn straight (9000 / 30000 of full scale) and premultiplied after
    straight = frame.copy()
    straight[..., :3] = round(65535 * 9000 / 30000)
    ref = renderer.draw_styled(straight, [np.array([[2.0, 10.0], [21.0, 10.0]])], [LineStyle(4.0, opacity=0.5)])
    ref = ref.astype(np.float64)
    ref[..., :3] *= ref[..., 3:] / 65535
    assert np.abs(out[6:].astype(np.float64) - ref[6:]).max() <= 3 and out[10, 12, 3] > 40000
    frame.flags.writeable = False
    with pytest.raises(ValueError, match="expected a writeable array for inplace drawing"):
        renderer.draw_styled(frame, [np.array([[2.0, 10.0], [21.0, 10.0]])], [LineStyle(4.0)], inplace=True,
                             premultiplied=True)
