"""Grain over a render (kernels/noise.cl, spatial/noise.py): the census and level kernels against the reference,
known answers for the level, and the fallback pass with quiet pixels against fallback_reference."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from mlaa_stream.device.formats import frame_format
from mlaa_stream.spatial import noise as N
from mlaa_stream.spatial.fallback import (FALLBACK_TILE, SEGMENT, fallback_defines, fallback_reference,
                                         render_regions_of)
from mlaa_stream.spatial.filter import Filter

from test_fallback import _as, cables_on_sky, shaded_polygons


def with_grain(frame8: np.ndarray, sigma: float, seed: int, mono: bool = True) -> np.ndarray:
    """Seeded Gaussian grain of `sigma` levels added after the render (one value for R, G, B when `mono`)."""
    rng = np.random.default_rng(seed)
    n = rng.normal(0, sigma, frame8.shape[:2] + ((1,) if mono else (frame8.shape[2],)))
    return np.clip(np.round(frame8 + n), 0, 255).astype(np.uint8)


def render_frame8(seed: int) -> np.ndarray:
    """A frame render_frame judges a render (test_fallback's render beside cables on a sky), 144 x 424."""
    gap = np.full((144, 40, 3), 200, np.uint8)
    return np.concatenate([shaded_polygons(seed, 144, 192), gap, cables_on_sky(seed, 144, 192)], 1)


def run_census(device, frame: np.ndarray, bgr: bool = False) -> tuple[np.ndarray, int, np.ndarray]:
    """noise_census, noise_level and noise_mask on `frame`: the bands' histograms, the level and the quiet flags
    (h, w) bool (all False where the level is 0: the mask is not written then)."""
    fmt = frame_format(frame, bgr)
    defs = fallback_defines(fmt, True, False)
    bands = -(-fmt.height // FALLBACK_TILE)
    mf = cl.mem_flags
    src = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(frame))
    hist = cl.Buffer(device.ctx, mf.READ_WRITE, 4 * N.NOISE_BINS * bands)
    level = cl.Buffer(device.ctx, mf.READ_WRITE, 4)
    flags = np.zeros((fmt.height, fmt.width), np.uint8)
    quiet = cl.Buffer(device.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=flags)
    W, H = np.int32(fmt.width), np.int32(fmt.height)
    device.kernel("fallback", "noise_census", defs)(device.queue, (bands,), None, src, hist, W, H)
    device.kernel("fallback", "noise_level", defs)(device.queue, (1,), None, hist, level, np.int32(bands))
    render = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR,  # every tile a region: the whole mask
                       hostbuf=np.ones(bands * -(-fmt.width // FALLBACK_TILE), np.uint8))
    device.kernel("fallback", "noise_mask", defs)(device.queue, (-(-fmt.width // SEGMENT), fmt.height), None, src,
                                                  level, render, quiet, W, H, np.int32(-(-fmt.width // FALLBACK_TILE)))
    h, lv = np.empty((bands, N.NOISE_BINS), np.int32), np.empty(1, np.int32)
    cl.enqueue_copy(device.queue, h, hist)
    cl.enqueue_copy(device.queue, lv, level)
    cl.enqueue_copy(device.queue, flags, quiet)
    return h, int(lv[0]), flags.astype(bool)


@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, False), (np.uint8, 3, True), (np.uint8, 4, False),
                                                (np.uint8, 1, False), (np.uint16, 3, False), (np.float32, 3, False)])
def test_census_and_level_match_the_reference(device, dtype, channels, bgr):
    """Exact (integers on 8-bit levels), at sizes that are not multiples of the band or of SEGMENT, clean and with
    grain: the histograms, the level and the quiet mask."""
    for seed, (h, w), sigma in ((1, (61, 83), 5.0), (2, (48, 97), 0.0), (3, (3, 2), 9.0), (4, (20, 150), 6.0)):
        frame8 = with_grain(shaded_polygons(seed, max(h, 8), max(w, 8))[:h, :w], sigma, seed, mono=seed != 3)
        frame = _as(frame8[..., ::-1] if bgr else frame8, dtype, channels)
        hist, level, quiet = run_census(device, frame, bgr)
        np.testing.assert_array_equal(hist, N.noise_census(N.luma256(frame, bgr)))
        assert level == N.noise_level(frame, bgr)
        np.testing.assert_array_equal(quiet, N.quiet_pixels(frame, bgr))
        if h > 8 and sigma:
            assert level > 0 and 0.1 < quiet.mean() < 1


@pytest.mark.parametrize("sigma", [2.0, 4.0, 8.0])
def test_level_of_white_noise(sigma):
    """Known answer: grain of deviation s on mid grey: |Laplacian| ~ |N(0, 6 s)|, median 6 s 0.6745 (floor);
    a clean render or a smooth ramp has level 0."""
    flat = np.full((256, 256, 3), 128, np.uint8)
    want = 6 * sigma * 0.6745
    assert abs(N.noise_level(with_grain(flat, sigma, 0)) - want) <= 1.0
    ramp = np.broadcast_to(np.linspace(20, 230, 256)[None, :, None], (256, 256, 3)).round().astype(np.uint8)
    assert N.noise_level(ramp) == 0
    assert N.noise_level(render_frame8(4)) == 0


def test_quiet_pixels_known_answer():
    """A 3x3 window spanning under 3/2 of the level is quiet; the grain alone is, its edges are not."""
    frame = np.full((32, 32, 3), 100, np.uint8)
    frame[:, 16:] = 200  # a step of 100 levels
    level = 10
    quiet = N.quiet_pixels(frame, level=level)
    assert quiet[:, :15].all() and quiet[:, 17:].all() and not quiet[:, 15:17].any()
    assert not N.quiet_pixels(frame, level=0).any()
    step = np.full((8, 8, 3), 100, np.uint8)
    step[4:] = 114  # luma span 14 levels (x 256): quiet under level 10 (span < 15), not under 9 (span >= 13.5)
    assert N.quiet_pixels(step, level=10)[3].all() and not N.quiet_pixels(step, level=9)[3].any()


@pytest.mark.parametrize("mode", ["auto", "everywhere"])
@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, False), (np.uint8, 3, True), (np.uint8, 4, False),
                                                (np.uint16, 3, False), (np.float32, 3, False)])
def test_the_pass_with_grain_matches_the_reference(mode, dtype, channels, bgr):
    """Exact, as test_fallback's kernel tests, on a render with grain: quiet pixels leave the render regions, and
    that changes the output (the reference with no quiet pixel differs)."""
    frame8 = with_grain(render_frame8(0), 4.0, 5)
    frame = _as(frame8[..., ::-1] if bgr else frame8, dtype, channels)
    with Filter(bgr=bgr, fallback=mode) as f, Filter(bgr=bgr, fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    args = (frame, passes["out"], passes["edges"], passes["hdist"], passes["vdist"])
    want = fallback_reference(*args, bgr=bgr, everywhere=mode == "everywhere")
    if mode == "auto":
        assert render_regions_of(frame, passes["out"], passes["edges"], bgr=bgr).mean() > 0.5
    quiet = N.quiet_pixels(frame, bgr)
    assert 0.2 < quiet.mean() < 0.98
    if dtype == np.float32:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    else:
        np.testing.assert_array_equal(got, want)
    saved = N.quiet_pixels
    try:
        import mlaa_stream.spatial.fallback as F
        F.quiet_pixels = lambda f, bgr=False, level=None: np.zeros(f.shape[:2], bool)
        ungated = fallback_reference(*args, bgr=bgr, everywhere=mode == "everywhere")
    finally:
        F.quiet_pixels = saved
    assert np.any(ungated != want)


def test_grain_is_kept_over_a_render():
    """Known answer: on a render with grain, the region pixels whose windows hold nothing but grain keep the
    MLAA passes' colour (without the gate the regions' passes moved 90 % of them, by 2.8 levels on average)."""
    frame = with_grain(render_frame8(1), 6.0, 2)
    with Filter() as f, Filter(fallback="off") as g:
        got, chain = f.process(frame), g.process(frame)
    quiet = N.quiet_pixels(frame)
    assert quiet.mean() > 0.5
    moved = np.abs(got.astype(int) - chain).max(-1)
    assert (moved[quiet] > 0).mean() < 0.05, "quiet pixels must keep the chain's colour (but FXAA's busy tiles)"
    assert moved[~quiet].max() > 0


@pytest.mark.parametrize("sigma,mono", [(4.0, True), (8.0, True), (4.0, False)])
def test_a_grainy_render_keeps_its_busy_pixels_within_the_grain(sigma, mono):
    """Known answer (fallback.cl grain_verdict): a render with grain shows 1-spp geometry (hard stair ends), so its
    busy pixels within the grain still count: its render regions are those of the rule without the grain test, and
    the kernel's equal the reference's. (A noisy photograph, with no stair ends, loses them: test_fallback.)"""
    from mlaa_stream.spatial.fallback import (_busy_pixels, _frame_masks, one_spp_geometry, overlay_tiles,
                                              region_pixels, render_regions, step_counts)
    from mlaa_stream.spatial.fxaa import luma_reference
    frame = with_grain(render_frame8(2), sigma, 3, mono)
    with Filter(keep_regions=True) as f, Filter(fallback="off") as g:
        f.process(frame)
        tiles, passes = f.last_regions, g.intermediates(frame)
    _, _, _, borders, changed, rgb = _frame_masks(frame, passes["out"], passes["edges"], False)
    luma = luma_reference(rgb, False)
    strong, _, clean, clean_ramps = (int(a.sum()) for a in step_counts(borders, luma))
    assert one_spp_geometry(strong, clean, clean_ramps)
    quiet = N.quiet_pixels(frame)
    busy = _busy_pixels(changed, borders, rgb, quiet, luma)
    assert (busy & quiet).any()
    ungated = render_regions(_busy_pixels(changed, borders, rgb, np.zeros_like(quiet), luma), borders, luma,
                             overlay_tiles(frame))
    np.testing.assert_array_equal(render_regions(busy, borders, luma, overlay_tiles(frame)), ungated)
    np.testing.assert_array_equal(region_pixels(tiles, *quiet.shape), ungated)
    assert ungated.mean() > 0.5


def test_photo_noise_bench_runs(capsys):
    """python -m mlaa_stream.bench.photo_noise: every photograph clean and with noise scored, and with colour noise
    of 3 levels the default finds no render region in any of them (before grain_verdict: 11-100 % of the tiles)."""
    from mlaa_stream.bench import photo_noise
    assert photo_noise.main(["--methods", "mlaa,none", "--sigmas", "3"]) == 0
    rows = [line for line in capsys.readouterr().out.splitlines() if "colour 3" in line]
    assert len(rows) == len(photo_noise.photographs())
    assert all(line.split()[-6] == "0" and line.split()[-3] == "-" for line in rows), rows
