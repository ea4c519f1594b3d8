"""kernels/temporal.cl against temporal_reference (seeded random frames, histories and flows, every
mode pair and pixel format; a case with a known answer), and TemporalStage on small sequences:
static shots converge, a sub-pixel pan uses the global model, a fast mover leaves no ghost, a cut
resets, "off" and strength 0 pass the spatial frame through.

Tolerance (kernel vs reference): integer frames within 1 level and identical on >= 99.9 % of
samples, float frames within 1e-5; history within 1e-3 (half-float rounding after float32 sums
in a different association); weights within 1 of 255. Both do the same float32 operations in the
same order with FP_CONTRACT off; the lookup-table reads of common.cl may be fused on the device.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from mlaa_stream.yardstick import scenes as S
from mlaa_stream.device.colour import device_luts, linear_to_srgb, srgb_to_linear
from mlaa_stream.device.context import default_context
from mlaa_stream.device.formats import frame_format
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.temporal.stage import (CUR_AFFINE, CUR_DENSE, CUR_RESET, PREV_AFFINE, PREV_DENSE, PREV_NONE,
                                  CHANGED_LEVELS, MOVED_LEVELS, SEGMENT, TemporalStage, decode_table, flat_3x3,
                                  BLOB_MARGIN, flat_levels, kernel_defines, make_params, moving_in_regions,
                                  temporal_reference, unexplained_blobs)
from mlaa_stream.bench.temporal import _pan_layers


# --- kernel vs reference ------------------------------------------------------------------------------
def run_kernel(cur, hist, params, cur_mode, prev_mode, flow_b, flow_f, flow_prev, bgr=False, gate=None):
    ctx = default_context()
    fmt = frame_format(cur, bgr)
    k = ctx.kernel("temporal", "temporal_blend", kernel_defines(fmt))
    q = ctx.queue
    mf = cl.mem_flags

    def buf(a):
        return cl.Buffer(ctx.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(a))

    host = np.ascontiguousarray(cur, dtype=fmt.dtype)
    h, w = fmt.height, fmt.width
    fh, fw = flow_b.shape[:2]
    dst, hist_out, conf = ctx.buffer(host.nbytes), ctx.buffer(hist.nbytes), ctx.buffer(h * w)
    k(q, (-(-w // SEGMENT), h), None, buf(host), buf(hist), hist_out, dst, conf, buf(flow_b), buf(flow_f),
      buf(flow_prev), buf(params), buf(device_luts()), buf(decode_table(fmt)), np.int32(w), np.int32(h), np.int32(fw), np.int32(fh),
      np.int32(fw), np.int32(fh), np.int32(cur_mode), np.int32(prev_mode),
      buf(np.zeros((h, w), np.uint8) if gate is None else gate.astype(np.uint8)), np.int32(gate is not None))
    out, ho, co = np.empty_like(host), np.empty_like(hist), np.empty((h, w), np.uint8)
    cl.enqueue_copy(q, out, dst)
    cl.enqueue_copy(q, ho, hist_out)
    cl.enqueue_copy(q, co, conf)
    q.finish()
    return out.astype(np.asarray(cur).dtype), ho, co


def assert_close(out, ref, hist, rhist, conf, rconf):
    assert out.shape == ref.shape and out.dtype == ref.dtype
    if np.issubdtype(out.dtype, np.floating):
        np.testing.assert_allclose(out.astype(np.float32), ref.astype(np.float32), atol=1e-5, rtol=0)
    else:
        d = np.abs(out.astype(np.int64) - ref.astype(np.int64))
        assert d.max() <= 1, f"max difference {d.max()} levels"
        assert (d == 0).mean() >= 0.999, f"only {(d == 0).mean():.5f} of samples identical"
    np.testing.assert_allclose(hist.astype(np.float32), rhist.astype(np.float32), atol=1e-3, rtol=0)
    assert np.abs(conf.astype(int) - rconf.astype(int)).max() <= 1


def random_case(seed, h, w, channels, dtype, flow_scale=1):
    rng = np.random.default_rng(seed)
    hi = {np.uint8: 256, np.uint16: 65536}.get(dtype)
    shape = (h, w) if channels == 1 else (h, w, channels)
    cur = rng.integers(0, hi, shape).astype(dtype) if hi else rng.random(shape).astype(dtype)
    hist = rng.random((h, w, 4)).astype(np.float16)
    fh, fw = -(-h // flow_scale), -(-w // flow_scale)
    flow_b = (rng.standard_normal((fh, fw, 2)) * 1.5).astype(np.float32)
    flow_f = (-flow_b + rng.standard_normal((fh, fw, 2)) * 0.4).astype(np.float32)
    flow_p = (flow_b + rng.standard_normal((fh, fw, 2)) * 0.4).astype(np.float32)
    params = make_params((1.01, 0.02, 1.3, -0.01, 0.99, -0.7), (1.0, 0.0, 0.5, 0.0, 1.0, 0.2),
                         flow_scale, flow_scale, 0.5, 0.5, 1.25, True)
    return cur, hist, params, flow_b, flow_f, flow_p


MODE_PAIRS = [(CUR_RESET, PREV_NONE), (CUR_AFFINE, PREV_NONE), (CUR_AFFINE, PREV_AFFINE),
              (CUR_AFFINE, PREV_DENSE), (CUR_DENSE, PREV_NONE), (CUR_DENSE, PREV_AFFINE),
              (CUR_DENSE, PREV_DENSE)]


@pytest.mark.parametrize("cur_mode,prev_mode", MODE_PAIRS)
def test_kernel_matches_reference_modes(cur_mode, prev_mode):
    cur, hist, params, fb, ff, fp = random_case(cur_mode * 3 + prev_mode, 37, 83, 3, np.uint8)
    got = run_kernel(cur, hist, params, cur_mode, prev_mode, fb, ff, fp, bgr=True)
    ref = temporal_reference(cur, hist, params, cur_mode, prev_mode, fb, ff, fp, bgr=True)
    if cur_mode != CUR_RESET:
        assert 0.05 < (ref[2] > 0).mean() < 1.0  # some history used, some rejected: both paths run
    assert_close(got[0], ref[0], got[1], ref[1], got[2], ref[2])


@pytest.mark.parametrize("channels,dtype,flow_scale", [(4, np.uint16, 1), (1, np.float32, 2), (3, np.uint8, 2)])
def test_kernel_matches_reference_formats(channels, dtype, flow_scale):
    cur, hist, params, fb, ff, fp = random_case(7, 29, 70, channels, dtype, flow_scale)
    got = run_kernel(cur, hist, params, CUR_DENSE, PREV_DENSE, fb, ff, fp)
    ref = temporal_reference(cur, hist, params, CUR_DENSE, PREV_DENSE, fb, ff, fp)
    assert_close(got[0], ref[0], got[1], ref[1], got[2], ref[2])
    if channels == 4:
        assert np.array_equal(got[0][..., 3], cur[..., 3])  # alpha is the current frame's


@pytest.mark.parametrize("shift", [(0.0, 0.0), (2.0, -1.0)])
def test_kernel_matches_reference_on_texels(shift):
    """Static and whole-pixel motion: every history position is a texel (the kernel's one-tap path)."""
    cur, hist, _, fb, ff, fp = random_case(5, 31, 66, 3, np.uint8)
    m = (1, 0, shift[0], 0, 1, shift[1])
    params = make_params(m, m, 1, 1, 0.5, 0.5, 1.25, False)
    got = run_kernel(cur, hist, params, CUR_AFFINE, PREV_AFFINE, fb, ff, fp, bgr=True)
    ref = temporal_reference(cur, hist, params, CUR_AFFINE, PREV_AFFINE, fb, ff, fp, bgr=True)
    assert 0.05 < (ref[2] > 0).mean() < 1.0
    assert_close(got[0], ref[0], got[1], ref[1], got[2], ref[2])


@pytest.mark.parametrize("cur_mode,channels,dtype", [(CUR_AFFINE, 3, np.uint8), (CUR_DENSE, 4, np.uint16),
                                                     (CUR_DENSE, 1, np.float32)])
def test_kernel_matches_reference_with_a_gate(cur_mode, channels, dtype):
    """where="render": no history where the gate is 0 (the spatial pixel bit for bit, weight 0), the same
    blend as without a gate elsewhere."""
    cur, hist, params, fb, ff, fp = random_case(11, 33, 75, channels, dtype)
    gate = (np.random.default_rng(12).random((33, 75)) < 0.5).astype(np.uint8)
    got = run_kernel(cur, hist, params, cur_mode, PREV_AFFINE, fb, ff, fp, gate=gate)
    ref = temporal_reference(cur, hist, params, cur_mode, PREV_AFFINE, fb, ff, fp, gate=gate)
    free = temporal_reference(cur, hist, params, cur_mode, PREV_AFFINE, fb, ff, fp)
    assert_close(got[0], ref[0], got[1], ref[1], got[2], ref[2])
    assert np.all(got[2][gate == 0] == 0) and (got[2][gate == 1] > 0).mean() > 0.05
    assert np.array_equal(got[0].reshape(33, 75, -1)[gate == 0], np.asarray(cur).reshape(33, 75, -1)[gate == 0])
    np.testing.assert_array_equal(ref[2][gate == 1], free[2][gate == 1])


def test_moving_in_regions_known_answer():
    """The gate: pixels of render-region tiles where the input moved by MOVED_LEVELS (dilated by one pixel)
    and the blended frame differs from the input by CHANGED_LEVELS."""
    h, w = 24, 32
    prev = np.full((h, w, 3), 100, np.uint8)
    cur = prev.copy()
    cur[5, 5, 1] = 100 + MOVED_LEVELS          # moved, in a region tile (row 0, column 0)
    cur[5, 20, 0] = 100 + MOVED_LEVELS - 1     # one level short
    cur[18, 4, 2] = 100 - MOVED_LEVELS         # moved, outside every region
    regions = np.zeros((3, 4), np.uint8)
    regions[0, 0] = regions[0, 2] = 1
    filtered = cur.copy()
    gate = moving_in_regions(cur, prev, regions)
    expect = np.zeros((h, w), np.uint8)
    expect[4:7, 4:7] = 1
    np.testing.assert_array_equal(gate, expect)
    filtered[4:7, 4:7] = cur[4:7, 4:7] + np.uint8(CHANGED_LEVELS)
    filtered[5, 6] = cur[5, 6] + np.uint8(CHANGED_LEVELS - 1)   # the filter barely touched it
    expect[5, 6] = 0
    np.testing.assert_array_equal(moving_in_regions(cur, prev, regions, filtered), expect)
    # 16-bit and float frames: the same levels in their units
    np.testing.assert_array_equal(moving_in_regions(cur.astype(np.uint16) * 257, prev.astype(np.uint16) * 257,
                                                    regions), gate)
    np.testing.assert_array_equal(moving_in_regions(cur / np.float32(255), prev / np.float32(255), regions), gate)
    assert moving_in_regions(cur, None, regions) is None and moving_in_regions(cur, prev, None) is None
    none = moving_in_regions(cur, prev, np.zeros_like(regions))   # no region tile: an empty gate, early
    assert none.shape == (h, w) and none.dtype == np.uint8 and not none.any()


def test_unexplained_blobs_known_answer():
    """A square that moved 20 px where the motion says 0 is a blob (grown by BLOB_MARGIN); a straight edge
    whose staircase moved by one pixel (a 1-px line of change) is not; with the square's motion only the
    background it uncovered is left."""
    h, w = 96, 128
    prev = np.full((h, w, 3), 60, np.uint8)
    cur = prev.copy()
    prev[30:50, 20:40] = 200
    cur[30:50, 40:60] = 200
    cur[80:, :], prev[81:, :] = 180, 180            # an edge one row lower in the previous frame
    blobs = unexplained_blobs(cur, prev, None, 1, (0.0, 0.0))
    grown = np.zeros((h, w), bool)
    grown[30 + 1 - BLOB_MARGIN:50 - 1 + BLOB_MARGIN, 20 + 1 - BLOB_MARGIN:60 - 1 + BLOB_MARGIN] = True
    np.testing.assert_array_equal(blobs > 0, grown)
    assert not blobs[80:].any() and not blobs[:, 60 + BLOB_MARGIN:].any()
    # the square's own motion as a dense flow (current -> previous: -20 px in x) explains it
    flow = np.zeros((h, w, 2), np.float32)
    flow[30:50, 40:60, 0] = -20.0
    flow[30:50, 20:40, 0] = 0.0
    explained = unexplained_blobs(cur, prev, flow, 1, (0.0, 0.0))
    assert blobs[30:50, 55:60].all() and not explained[30:50, 55:60].any()
    assert explained[30:50, 20:40].all()             # the background the square uncovered stays out


def test_unexplained_blobs_take_half_float_frames():
    """A half EXR's frames (the default method's gate on a render): OpenCV's remap and warpAffine have no half
    floats, and the second frame of every half EXR render ended the run with "ifunc != 0 in function 'remap'"; the
    answer is the float32 frames' own."""
    h, w = 48, 64
    prev = np.full((h, w, 3), 0.25, np.float32)
    cur = prev.copy()
    prev[10:20, 8:18] = 0.8
    cur[10:20, 20:30] = 0.8
    flow = np.zeros((h, w, 2), np.float32)
    flow[10:20, 20:30, 0] = -12.0
    for f, t in ((flow, (0.0, 0.0)), (None, (1.5, -0.5))):
        want = unexplained_blobs(cur, prev, f, 1, t)
        got = unexplained_blobs(cur.astype(np.float16), prev.astype(np.float16), f, 1, t)
        np.testing.assert_array_equal(got, want)
        assert want.any()


@pytest.mark.parametrize("mode", ["dense", "global"])
def test_non_finite_samples_do_not_spread_where_the_render_gate_blends(device, mode):
    """where="render" (the default method's blend) on a linear frame with a NaN row and an inf run: the kernel's
    3x3 clamp read them as its neighbours' bounds and wrote NaN beside them on gated pixels (README "Non-finite
    samples": they pass through and never spread); now replaced before the kernel as the spatial filter does."""
    import cv2
    from mlaa_stream.spatial.fallback import FALLBACK_TILE
    from mlaa_stream.temporal.stage import TemporalStage

    h, w = 64, 96
    base = np.random.default_rng(1).random((h // 4, w // 2, 3)).astype(np.float32)
    base = cv2.resize(base, (w * 2, h), interpolation=cv2.INTER_NEAREST)
    frames = [np.ascontiguousarray(base[:, 3 * k:3 * k + w]) for k in range(4)]   # blocks panning 3 px a frame
    frames[3] = frames[3].copy()
    frames[3][20:22, :, 0] = np.nan
    frames[3][40, 10:30, 1] = np.inf
    regions = np.ones((-(-h // FALLBACK_TILE), -(-w // FALLBACK_TILE)), np.uint8)   # all render
    stage = TemporalStage(context=device, bgr=False, where="render", fb_check=False, mode=mode, linear_input=True)
    for i, f in enumerate(frames):
        bad = ~np.isfinite(f)
        filtered = cv2.GaussianBlur(np.nan_to_num(f), (3, 3), 0.8)   # edges the filter changed: the gate's
        filtered[bad] = f[bad]
        out = stage(f, filtered, i, regions=regions)
        assert stage.stats[-1]["model"] == ("reset" if i == 0 else mode)
        assert np.isfinite(out[~bad]).all(), f"frame {i}: {np.count_nonzero(~np.isfinite(out[~bad]))} samples"
        np.testing.assert_array_equal(out[bad], f[bad])
    assert stage.stats[-1]["gate_share"] > 0


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_decode_table_is_the_interpolated_table_read(dtype):
    """The kernel's per-code decode table holds what lut_read gives for v / PIXEL_MAX (within 1 float32
    ulp of colour.lut_read, which widens to float64; the kernel output matches the reference, above);
    known answers: 0 -> 0, max -> 1, monotone, within the table's interpolation error (2e-4) of the
    exact sRGB decode."""
    from mlaa_stream.device.colour import lut_read
    fmt = frame_format(np.zeros((4, 4, 3), dtype), False)
    table = decode_table(fmt)
    pmax = np.iinfo(dtype).max
    assert table.shape == (pmax + 1,) and table.dtype == np.float32
    codes = np.arange(pmax + 1, dtype=np.float32) * (np.float32(1.0) / np.float32(pmax))
    np.testing.assert_allclose(table, lut_read(device_luts(), codes), atol=6e-8, rtol=0)
    assert table[0] == 0.0 and abs(table[-1] - 1.0) < 1e-6 and np.all(np.diff(table) >= 0)
    np.testing.assert_allclose(table, srgb_to_linear(codes.astype(np.float64)), atol=2e-4, rtol=0)
    assert decode_table(frame_format(np.zeros((4, 4), np.float32), False)).shape == (1,)


def test_kernel_known_answer_checkerboard():
    """Checkerboard of two greys; history a flat grey between them (inside every 3x3 box, so not
    clipped); static model, w = strength: out = encode(lin(c) + 0.5 (m - lin(c)))."""
    h, w = 12, 70
    a, b = 60, 200
    cur = np.where((np.indices((h, w)).sum(0) % 2) == 0, a, b).astype(np.uint8)
    m = 0.3
    hist = np.full((h, w, 4), m, np.float16)
    hist[..., 3] = 1
    params = make_params((1, 0, 0, 0, 1, 0), (1, 0, 0, 0, 1, 0), 1, 1, 0.5, 0.5, 1.25, False)
    zero = np.zeros((h, w, 2), np.float32)
    out, _, conf = run_kernel(cur, hist, params, CUR_AFFINE, PREV_AFFINE, zero, zero, zero)
    lin = srgb_to_linear(cur / 255.0)
    expect = np.round(linear_to_srgb(lin + 0.5 * (float(np.float16(m)) - lin)) * 255)
    assert np.abs(out.astype(int) - expect).max() <= 1
    assert (conf == 128).all()  # 0.5 * 255 + 0.5


def flat_case(seed, h, w, channels, dtype):
    """Blocks of random colours (flat interiors, group-wide and narrower, touching the frame's edges)
    over a noisy band; a random history and a small affine motion, so history is used elsewhere."""
    rng = np.random.default_rng(seed)
    hi = {np.uint8: 256, np.uint16: 65536}.get(dtype)
    shape = (h, w) if channels == 1 else (h, w, channels)
    big = rng.integers(0, hi, shape) if hi else rng.random(shape)
    cur = np.empty(shape, dtype)
    x = 0
    while x < w:
        bw = int(rng.integers(2, 15))
        cur[:, x:x + bw] = big[0:1, x:x + 1]
        x += bw
    cur[h // 2:, : w // 3] = big[h // 2:, : w // 3]             # noise: nothing flat there
    cur[: h // 3, w // 2:] = big[0, w // 2]                    # a wide flat block at the top edge
    # a near-flat block: one colour with +-1 level of noise (codec noise); +-1/255 for floats
    nb = cur[h // 3: h // 2, w // 2:]
    step = 1.0 / 255.0 if not hi else (257 if hi == 65536 else 1)
    base = np.clip(big[h // 3, w // 2], 3 * step, (hi - 1 if hi else 1.0) - 3 * step)
    nb[...] = base + rng.integers(-1, 2, nb.shape) * step
    hist = rng.random((h, w, 4)).astype(np.float16)
    zero = np.zeros((h, w, 2), np.float32)
    params = make_params((1, 0, 0.3, 0, 1, -0.2), (1, 0, 0.3, 0, 1, -0.2), 1, 1, 0.5, 0.5, 1.25, False)
    return cur, hist, params, zero


@pytest.mark.parametrize("channels,dtype", [(3, np.uint8), (4, np.uint16), (1, np.float32)])
def test_flat_neighbourhood_passes_through(channels, dtype):
    """The flat rule: where all 9 samples of the 3x3 neighbourhood (edges replicated) are within
    flat_levels (2 levels of 8 bits) of the centre's,
    the pixel is copied exactly, its history is the pixel in linear light and its weight is 0 --
    whatever the history says; the kernel still matches the reference everywhere."""
    h, w = 23, 75
    cur, hist, params, zero = flat_case(11 + channels, h, w, channels, dtype)
    got = run_kernel(cur, hist, params, CUR_AFFINE, PREV_AFFINE, zero, zero, zero, bgr=channels == 3)
    ref = temporal_reference(cur, hist, params, CUR_AFFINE, PREV_AFFINE, zero, zero, zero, bgr=channels == 3)
    assert_close(got[0], ref[0], got[1], ref[1], got[2], ref[2])
    px = cur.reshape(h, w, -1)
    flat = np.zeros((h, w), bool)
    lev = flat_levels(dtype)
    for y in range(h):   # plain loops: an independent statement of "(near-)flat"
        for x in range(w):
            ys, xs = [max(y - 1, 0), y, min(y + 1, h - 1)], [max(x - 1, 0), x, min(x + 1, w - 1)]
            flat[y, x] = all(np.abs(px[yy, xx].astype(float) - px[y, x]).max() <= lev for yy in ys for xx in xs)
    assert 0.3 < flat.mean() < 0.9
    assert np.array_equal(flat, flat_3x3(cur, lev))
    assert (flat & ~flat_3x3(cur)).sum() > 20   # near-flat pixels that are not exactly flat are tested
    out = got[0].reshape(h, w, -1)
    assert np.array_equal(out[flat], px[flat])
    assert (got[2][flat] == 0).all()
    assert (got[2][~flat] > 0).mean() > 0.3            # elsewhere history is used
    _, rhist, _ = temporal_reference(cur, hist, params, CUR_RESET, PREV_NONE, zero, zero, zero,
                                     bgr=channels == 3)
    assert np.array_equal(got[1][flat], rhist[flat])     # the history as on a reset


# --- the stage on sequences ---------------------------------------------------------------------------
@pytest.fixture(scope="module")
def spatial():
    with Filter(bgr=False) as f:
        yield f


def blocks(rng, h, w, block=6):
    small = rng.integers(30, 226, (h // block + 1, w // block + 1, 3)).astype(np.uint8)
    return np.kron(small, np.ones((block, block, 1), np.uint8))[:h, :w]


def run(stage, frames, spatial):
    sp = [spatial.process(f) for f in frames]
    return [stage(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))], sp


def test_static_noisy_sequence_converges(spatial):
    rng = np.random.default_rng(3)
    base = blocks(rng, 64, 96).astype(np.int16)
    frames = [np.clip(base + rng.normal(0, 2.0, base.shape), 0, 255).astype(np.uint8) for _ in range(8)]
    with TemporalStage(bgr=False) as st:
        outs, sp = run(st, frames, spatial)
        models = [r["model"] for r in st.stats]
    assert models[0] == "reset" and set(models[1:]) == {"static"}
    jitter_in = np.mean([np.abs(sp[t].astype(float) - sp[t - 1]).mean() for t in range(4, 8)])
    jitter_out = np.mean([np.abs(outs[t].astype(float) - outs[t - 1]).mean() for t in range(4, 8)])
    assert jitter_out < 0.75 * jitter_in, (jitter_out, jitter_in)
    assert np.abs(outs[-1].astype(float) - base).mean() < np.abs(sp[-1].astype(float) - base).mean()


def test_repeated_frame_returns_previous_output(spatial):
    """A frame identical to the previous input gets the previous output back (no flow, no kernel);
    one changed pixel is enough to run the stage again."""
    w, h = 160, 96
    frames = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 1)) for t in range(3)]
    changed = frames[2].copy()
    changed[40, 50] = 255 - changed[40, 50]
    frames += [frames[2].copy(), frames[2].copy(), changed]
    with TemporalStage(bgr=False) as st:
        outs, _ = run(st, frames, spatial)
        stats = st.stats
    assert [r.get("repeat", False) for r in stats] == [False, False, False, True, True, False]
    assert stats[3]["model"] == "static" and stats[3]["blend_ms"] == 0.0
    np.testing.assert_array_equal(outs[3], outs[2])
    np.testing.assert_array_equal(outs[4], outs[2])
    assert outs[3] is not outs[2] and outs[3].dtype == frames[0].dtype
    assert stats[5]["model"] != "reset" and np.any(outs[5] != outs[2])


def test_subpixel_pan_uses_global_model(spatial):
    w, h = 320, 180
    frames = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 1)) for t in range(5)]
    with TemporalStage(bgr=False) as st:
        _, sp = run(st, frames, spatial)
        stats = st.stats
    assert [r["model"] for r in stats] == ["reset"] + ["global"] * 4
    tr = np.array([r["translation"] for r in stats[1:]])  # current -> previous: (-0.35, -0.15)
    # aliasing of 1-spp edges biases single frames by up to ~0.25 px; the mean is close
    assert np.abs(tr - (-0.35, -0.15)).max() < 0.3 and np.abs(tr.mean(0) - (-0.35, -0.15)).max() < 0.1, tr
    # history is used (mean weight > 0.2) wherever the flat rule does not pass the pixel through
    busy = [1.0 - flat_3x3(f).mean() for f in sp[1:]]
    assert all(r["history_weight_mean"] > 0.2 * b for r, b in zip(stats[1:], busy)), (stats, busy)


def test_fast_mover_leaves_no_ghost(spatial):
    w, h = 160, 96
    stripes = tuple(S.rotated_rect(x, h / 2, 5.0, h * 1.5, 8.0) for x in np.arange(-20, w + 20, 14.0))

    def frame(x):
        box = () if x is None else (S.rect(x, 30, x + 30, 66),)
        layers = [S.Layer(None, (210, 220, 200)), S.Layer(stripes, (90, 110, 80))]
        return S.encode8(S.render(layers + ([S.Layer(box, (200, 40, 30))] if box else []), w, h, 1))

    xs = [10.3 + 22 * t for t in range(6)]
    frames = [frame(x) for x in xs]
    background = frame(None)
    with TemporalStage(bgr=False) as st:
        outs, sp = run(st, frames, spatial)
        assert "dense" in [r["model"] for r in st.stats]
    bg_sp = spatial.process(background)
    for t in range(2, 6):
        left = np.zeros((h, w), bool)  # where the box was at t-1 and is not at t (2-px margin)
        left[32:64, int(xs[t - 1]) + 2:int(xs[t]) - 2] = True
        d = np.abs(outs[t].astype(int) - bg_sp.astype(int)).max(-1)[left]
        # a ghost would differ by ~180 levels (the box's green against the background's); allow a
        # faint trace: no pixel over 32 levels, 2 levels on average
        assert d.max() <= 32 and d.mean() <= 2, (t, d.mean(), d.max())


def test_still_background_next_to_a_mover_keeps_its_place(spatial):
    """Slanted stripes above and below a box moving 9 px per frame: their input never changes, so
    their motion is zero (DIS alone spreads the box's motion over them) and, as their spatial
    output never changes either, the output there is the spatial frame's exactly."""
    w, h = 160, 112
    stripes = tuple(S.rotated_rect(x, y, 60.0, 3.0, 8.0) for x in np.arange(10, w, 40.0) for y in (12, 24, 88, 100))

    def frame(x):
        layers = [S.Layer(None, (210, 220, 200)), S.Layer(stripes, (90, 110, 80)),
                  S.Layer((S.rect(x, 44, x + 30, 68),), (200, 40, 30))]
        return S.encode8(S.render(layers, w, h, 1))

    frames = [frame(10.3 + 9 * t) for t in range(6)]
    with TemporalStage(bgr=False, mode="dense") as st:
        outs, sp = run(st, frames, spatial)
    still = np.ones((h, w), bool)
    still[36:76] = False   # the box's rows with a margin
    for t in range(1, 6):
        np.testing.assert_array_equal(sp[t][still], sp[0][still])   # the premise
        d = np.abs(outs[t].astype(int) - sp[t].astype(int)).max(-1)[still]
        assert d.max() == 0, (t, d.max(), d.mean())


def test_hard_cut_resets(spatial):
    rng = np.random.default_rng(5)
    a, b = blocks(rng, 48, 80), np.full((48, 80, 3), 20, np.uint8)
    b[10:40, 20:60] = (240, 200, 60)
    frames = [a, a, a, b, b]
    with TemporalStage(bgr=False) as st:
        outs, sp = run(st, frames, spatial)
        assert [r["model"] for r in st.stats][3] == "reset" and st.stats[3]["cut"]
    assert np.array_equal(outs[3], sp[3])


@pytest.mark.parametrize("kwargs", [{"mode": "off"}, {"strength_k": 0.0}])
def test_off_returns_spatial_frame(spatial, kwargs):
    rng = np.random.default_rng(9)
    frames = [blocks(rng, 32, 40) for _ in range(3)]
    with TemporalStage(bgr=False, **kwargs) as st:
        outs, sp = run(st, frames, spatial)
    assert all(o is s for o, s in zip(outs, sp))


def test_index_jump_resets_and_history_view(spatial):
    rng = np.random.default_rng(2)
    f = blocks(rng, 32, 48)
    s = spatial.process(f)
    with TemporalStage(bgr=False, show="history") as st:
        st(f, s, 0)
        v = st(f, s, 1)
        st(f, s, 5)
        assert [r["model"] for r in st.stats] == ["reset", "static", "reset"]
    assert v.shape == f.shape and v.dtype == f.dtype


def test_errors_name_the_frame():
    with TemporalStage(bgr=False) as st:
        with pytest.raises(ValueError, match="frame 4.*expected"):
            st(np.zeros((10, 12, 3), np.uint8), np.zeros((10, 13, 3), np.uint8), 4)
    with pytest.raises(ValueError, match="mode: expected"):
        TemporalStage(mode="fancy")


def test_render_gate_blends_only_moving_pixels_of_regions(spatial):
    """where="render": history only where moving_in_regions says so; without regions the spatial frames come
    back bit for bit (the rotation and the flat-colour scenes get no render regions)."""
    w, h = 160, 96
    frames = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 1)) for t in range(4)]
    sp = [spatial.process(f) for f in frames]
    regions = np.zeros((h // 8, w // 8), np.uint8)
    regions[:, : w // 16] = 1                        # the left half is a "render region"
    with TemporalStage(bgr=False, where="render") as st:
        outs = [st(f, s, i, regions=regions) for i, (f, s) in enumerate(zip(frames, sp))]
    changed_any = False
    for t in range(1, 4):
        gate = moving_in_regions(frames[t], frames[t - 1], regions, sp[t])
        changed = np.any(outs[t] != sp[t], axis=-1)
        assert not np.any(changed & (gate == 0)), t
        changed_any |= bool(changed.any())
    assert changed_any and not np.any(np.any(outs[3] != sp[3], axis=-1)[:, w // 2:])
    with TemporalStage(bgr=False, where="render") as st:
        bare = [st(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
    assert all(np.array_equal(a, b) for a, b in zip(bare, sp))
    with pytest.raises(ValueError, match="where"):
        TemporalStage(bgr=False, where="edges")


def test_auto_method_reads_the_filters_regions(spatial):
    """make_stage("auto"): TSS, then the blend on moving pixels of the regions its `regions_from` holds at each
    call (Filter.last_regions); without regions it returns exactly what TSS alone returns."""
    from types import SimpleNamespace
    from mlaa_stream.temporal.methods import make_stage
    w, h = 160, 96
    frames = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 1)) for t in range(4)]
    sp = [spatial.process(f) for f in frames]
    holder = SimpleNamespace(last_regions=None)
    tss = make_stage("tss", spatial.context, bgr=False)
    bare = make_stage("auto", spatial.context, bgr=False, regions_from=holder)
    alone = [tss(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
    assert all(np.array_equal(a, b) for a, b in zip(alone, [bare(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]))
    holder.last_regions = np.ones((h // 8, w // 8), np.uint8)
    auto = make_stage("auto", spatial.context, bgr=False, regions_from=holder)
    outs = [auto(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
    assert any(np.any(a != b) for a, b in zip(outs[1:], alone[1:]))
    assert [r["gate_share"] > 0 for r in auto.blend.stats] == [False, True, True, True]
    for st in (tss, bare, auto):
        st.close()
    with pytest.raises(ValueError, match="temporal method"):
        make_stage("smooth", spatial.context, bgr=False)


def test_known_motion_replaces_the_flow(spatial):
    """TemporalStage(motion=...): on dense frames the field it gives for the frame is the flow (DIS is not run);
    None falls back to DIS. The exact motion of a sub-pixel pan brings the output closer to its supersampled truth
    than a field 2 px off does; make_stage refuses motion for the tss method (it estimates its own)."""
    from mlaa_stream.temporal.methods import make_stage
    w, h = 160, 96
    frames = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 1)) for t in range(5)]
    truths = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 8)) for t in range(5)]
    sp = [spatial.process(f) for f in frames]
    calls = []

    def field(d):
        def motion(index):
            calls.append(index)
            return np.full((h, w, 2), d, np.float32)
        return motion

    def no_dis(*_):
        raise AssertionError("DIS ran although the motion was given")

    errors = {}
    for name, d in (("exact", (-0.35, -0.15)), ("off", (1.65, -0.15))):
        calls.clear()
        with TemporalStage(bgr=False, mode="dense", motion=field(d)) as st:
            st._flow = no_dis
            outs = [st(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
        assert calls == [1, 2, 3, 4] and [r["model"] for r in st.stats] == ["reset"] + ["dense"] * 4
        errors[name] = float(np.mean([(o.astype(float) - t) ** 2 for o, t in zip(outs[1:], truths[1:])]))
    assert errors["exact"] < 0.8 * errors["off"], errors
    with TemporalStage(bgr=False, mode="dense", motion=lambda index: None) as st:
        fallback = [st(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
    with TemporalStage(bgr=False, mode="dense") as st:
        plain = [st(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
    assert all(np.array_equal(a, b) for a, b in zip(fallback, plain))
    with pytest.raises(ValueError, match="motion"):
        make_stage("tss", spatial.context, bgr=False, motion=field((0.0, 0.0)))


def test_blend_reuses_what_tss_measured(spatial, monkeypatch):
    """TSSThenBlend hands TSS's pyramid and motion decision to the blend (no second choose_model on the same frame
    pair); the output is bit for bit what the blend gives when it measures the frames itself."""
    from types import SimpleNamespace
    from mlaa_stream.temporal import stage as stage_module
    from mlaa_stream.temporal.methods import make_stage
    w, h = 160, 96
    frames = [S.encode8(S.render(_pan_layers(w, h, 0.35 * t, 0.15 * t), w, h, 1)) for t in range(5)]
    sp = [spatial.process(f) for f in frames]
    holder = SimpleNamespace(last_regions=np.ones((h // 8, w // 8), np.uint8))
    outs = {}
    real = stage_module.choose_model
    for kind in ("shared", "own"):
        calls = []
        monkeypatch.setattr(stage_module, "choose_model", lambda *a, **k: calls.append(1) or real(*a, **k))
        st = make_stage("auto", spatial.context, bgr=False, regions_from=holder)
        if kind == "own":
            st._measured = lambda: None
        outs[kind] = [st(f, s, i) for i, (f, s) in enumerate(zip(frames, sp))]
        models = [r["blend_model"] for r in st.stats]
        st.close()
        blend_calls = len(calls)
        assert models == ["reset"] + ["dense"] * 4, models
        assert blend_calls == (0 if kind == "shared" else 4), (kind, blend_calls)
    assert all(np.array_equal(a, b) for a, b in zip(outs["shared"], outs["own"]))
    assert any(np.any(o != s) for o, s in zip(outs["shared"][1:], sp[1:]))
