"""The FXAA fallback pass (kernels/fallback.cl, mlaa_stream/spatial/fallback.py) against its numpy reference
and against cases with a known answer."""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.fallback import (FALLBACK_MIX, FALLBACK_TILE, FALLBACK_WEIGHT, RENDER_RADIUS,
                                          SUPERSAMPLED_HARD_PCT, SUPERSAMPLED_MIN, SUPERSAMPLED_PCT, _frame_masks,
                                          fallback_reference, ramp_counts, region_pixels, render_regions_of,
                                          step_counts, supersampled)
from mlaa_stream.spatial.fxaa import fxaa_mix_reference, luma_reference
from mlaa_stream.spatial.filter import Filter


def textured_aliased(seed: int, h: int = 72, w: int = 96) -> np.ndarray:
    """A smooth random texture (lit surfaces) crossed by hard-edged 1-spp polygons with textured fills:
    the MLAA passes change many pixels, so the fallback's gates open."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.zeros((h, w, 3))
    for c in range(3):
        coarse = rng.uniform(0.1, 0.9, (h // 3 + 2, w // 3 + 2))  # texels of 3 px: short texture edges
        img[..., c] = np.kron(coarse, np.ones((3, 3)))[:h, :w]
        img[..., c] += 0.08 * np.sin(xx * rng.uniform(0.3, 1.2) + yy * rng.uniform(0.2, 0.9) + c)
    for _ in range(6):  # half-planes and wedges sampled at pixel centres: jaggies
        a, b = rng.uniform(-1, 1, 2)
        d = rng.uniform(0.2, 0.8) * (abs(a) * w + abs(b) * h)
        inside = a * (xx + 0.5) + b * (yy + 0.5) > d - (abs(a) * w + abs(b) * h) / 2
        tint = rng.uniform(0, 1, 3)
        img[inside] = 0.6 * tint + 0.4 * img[inside] * rng.uniform(0.5, 1.0)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def shaded_polygons(seed: int, h: int = 72, w: int = 96, cell: int = 4, samples: int = 1) -> np.ndarray:
    """Render-like: smoothly shaded texture (bilinear over random texels of `cell` px) under hard-edged shaded
    polygons sampled at pixel centres -- a 1-spp render's lit, textured surfaces and silhouettes; `samples` > 1:
    the same scene supersampled, the mean of samples x samples points per pixel (an ordered grid) in linear light."""
    rng = np.random.default_rng(seed)

    def texels(lo: float, hi: float) -> np.ndarray:
        return rng.uniform(lo, hi, (h // cell + 2, w // cell + 2))

    def smooth(g: np.ndarray, yy: np.ndarray, xx: np.ndarray) -> np.ndarray:
        y, x = np.clip(yy / cell, 0, h // cell + 0.999), np.clip(xx / cell, 0, w // cell + 0.999)
        y0, x0 = np.floor(y).astype(int), np.floor(x).astype(int)
        ty, tx = y - y0, x - x0
        return (g[y0, x0] * (1 - ty) * (1 - tx) + g[y0 + 1, x0] * ty * (1 - tx)
                + g[y0, x0 + 1] * (1 - ty) * tx + g[y0 + 1, x0 + 1] * ty * tx)

    ground = [texels(0.2, 0.8) for _ in range(3)]
    polygons = []
    for _ in range(10):
        a, b = rng.uniform(-1, 1, 2)
        cx, cy = rng.uniform(0, w), rng.uniform(0, h)
        polygons.append((a, b, cx, cy, rng.uniform(20, 60), texels(0.5, 1.0), rng.uniform(0.1, 1, 3)))
    linear = np.zeros((h, w, 3))
    offsets = (np.arange(samples) + 0.5) / samples
    for oy in offsets:
        for ox in offsets:
            yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + [[[oy - 0.5]], [[ox - 0.5]]]  # texels at pixel corners
            img = np.stack([smooth(g, yy, xx) for g in ground], -1)
            for a, b, cx, cy, radius, shade_texels, tint in polygons:
                inside = a * (xx + 0.5 - cx) + b * (yy + 0.5 - cy) > 0
                inside &= (xx - cx) ** 2 + (yy - cy) ** 2 < radius ** 2
                shade = smooth(shade_texels, yy, xx)[..., None] * tint
                img[inside] = shade[inside]
            linear += srgb_to_linear(img) if samples > 1 else img
    img = linear_to_srgb(linear / samples ** 2) if samples > 1 else linear
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def flat_art(seed: int, h: int, w: int) -> np.ndarray:
    """Two-colour aliased discs on a flat ground (text, UI, vector art)."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    img = np.full((h, w, 3), (235, 235, 230), np.uint8)
    for _ in range(max(1, h * w // 1200)):
        cx, cy, r = rng.uniform(8, w - 8), rng.uniform(8, h - 8), rng.uniform(5, 14)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] = (30, 40, 120)
    return img


def cables_on_sky(seed: int, h: int, w: int) -> np.ndarray:
    """Sub-pixel dark cables (0.5-0.9 px, sagging, sampled at pixel centres: dashed) across a smooth sky: thin
    features on a flat background, two-toned tiles in a render."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5
    img = np.stack([0.45 + 0.25 * yy / h + 0.05 * xx / w, 0.6 + 0.2 * yy / h, 0.9 - 0.05 * xx / w], -1)
    for _ in range(max(2, h // 16)):
        y0, slope = rng.uniform(4, h - 4), rng.uniform(-0.15, 0.15)
        width, sag = rng.uniform(0.5, 0.9), rng.uniform(0, 8)
        centre = y0 + slope * (xx - w / 2) + sag * ((xx - w / 2) / (w / 2)) ** 2
        img[np.abs(yy - centre) < width / 2] = (0.12, 0.12, 0.14)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def render_beside_art(seed: int) -> np.ndarray:
    """A render-like half (shaded_polygons) beside flat-colour art farther than RENDER_RADIUS tiles: the frame
    has render regions and tiles that are not."""
    gap = (RENDER_RADIUS + 2) * FALLBACK_TILE
    return np.concatenate([shaded_polygons(seed), flat_art(seed, 72, gap + 32)], 1)


def regions_of(frame: np.ndarray) -> np.ndarray:
    """The render regions that fallback_reference finds in `frame`."""
    with Filter(fallback="off") as g:
        passes = g.intermediates(frame)
    return render_regions_of(frame, passes["out"], passes["edges"])


def _as(img8: np.ndarray, dtype, channels: int) -> np.ndarray:
    x = img8 if channels == 3 else (img8[..., :1] if channels == 1 else
                                    np.concatenate([img8, np.full(img8.shape[:2] + (1,), 200, np.uint8)], -1))
    if channels == 1:
        x = x[..., 0]
    if dtype == np.uint16:
        return x.astype(np.uint16) * 257
    if dtype == np.float32:
        return x.astype(np.float32) / 255.0
    return x.copy()


@pytest.mark.parametrize("mode", ["auto", "edges", "everywhere"])
@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, False), (np.uint8, 3, True), (np.uint8, 4, False),
                                                (np.uint8, 1, False), (np.uint16, 3, False), (np.float32, 3, False)])
def test_kernel_matches_reference(mode, dtype, channels, bgr):
    """Exact: the pass is FXAA's kernel code (bit-identical to fxaa_reference, test_fxaa) behind integer
    gates, so the output must equal fallback_reference of the MLAA passes' output to the last bit
    (float32: within 1e-5 of full scale, test_fxaa's tolerance: OpenCL lets a device round divisions and square
    roots within a few ulps; an NVIDIA H200 gave 1.5e-6 on one value of this case)."""
    frame8 = render_beside_art(12)
    if mode == "auto" and channels == 3:  # the case must have render regions and tiles outside them
        regions = regions_of(frame8)
        assert regions[:, :64].all() and not regions[:, -32:].any()
    frame = _as(frame8, dtype, channels)
    with Filter(bgr=bgr, fallback=mode) as f, Filter(bgr=bgr, fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    mlaa = passes["out"]
    want = fallback_reference(frame, mlaa, passes["edges"], passes["hdist"], passes["vdist"], bgr=bgr,
                              everywhere=mode == "everywhere", regions=mode != "edges")
    changed = np.any(np.atleast_3d(got) != np.atleast_3d(mlaa), -1)
    if channels > 1 or mode == "everywhere":  # (grey: channel 0 alone gives MLAA too few jaggies to open the gates)
        assert changed.sum() > 20, "the case must exercise the pass"
    if dtype == np.float32:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-5)
    else:
        np.testing.assert_array_equal(got, want)


@pytest.mark.parametrize("mode", ["auto", "everywhere"])
def test_kernel_matches_reference_on_partial_tiles(mode):
    """Exact on a frame whose width and height are not multiples of FALLBACK_TILE: the last tiles of each row and
    column hold fewer pixels (footprint_tile computes their missing lanes from clamped reads and stores nothing
    there)."""
    frame = np.ascontiguousarray(render_beside_art(12)[:69, ::-1][:, 3:])  # 197 wide, the render on the right
    with Filter(fallback=mode) as f, Filter(fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    want = fallback_reference(frame, passes["out"], passes["edges"], passes["hdist"], passes["vdist"],
                              everywhere=mode == "everywhere")
    assert np.any(got[:, -5:] != passes["out"][:, -5:]), "the last, partial tile column must take the pass"
    np.testing.assert_array_equal(got, want)


def test_only_edge_pixels_change_outside_render_regions_and_the_formulas_hold():
    """Known answer: without the footprint table the pass changes only pixels that border an MLAA edge; a pixel
    the MLAA passes left takes FALLBACK_WEIGHT of FXAA's colour from the source's, one they changed FALLBACK_MIX
    of the way from theirs (linear light, within one level of rounding of the formula). The table then changes
    pixels inside render regions only (tests/test_footprint.py has its formula)."""
    frame = render_beside_art(12)
    with Filter(footprint_table=None) as f, Filter(fallback="off") as g, Filter() as d:
        got, passes, default = f.process(frame), g.intermediates(frame), d.process(frame)
    mlaa, e = passes["out"], passes["edges"]
    borders = e != 0
    borders[1:] |= (e[:-1] & 1) > 0
    borders[:, 1:] |= (e[:, :-1] & 2) > 0
    regions = regions_of(frame)
    by_mlaa = np.any(mlaa != frame, -1)
    by_fallback = np.any(got != mlaa, -1)
    assert (by_fallback & by_mlaa).sum() > 20 and (by_fallback & ~by_mlaa).sum() > 20
    assert not np.any(by_fallback & ~borders)
    _, fx = fxaa_mix_reference(frame)  # linear RGB
    lin = srgb_to_linear(frame.astype(np.float64) / 255)
    m = srgb_to_linear(mlaa.astype(np.float64) / 255)
    mixed = 255 * linear_to_srgb(m + FALLBACK_MIX * (fx - m))
    left = 255 * linear_to_srgb(lin + FALLBACK_WEIGHT * (fx - lin))

    def within_a_level(want: np.ndarray) -> np.ndarray:
        return np.abs(got - want).max(-1) <= 1.0

    assert within_a_level(mixed)[by_fallback & by_mlaa].all()
    assert within_a_level(left)[by_fallback & ~by_mlaa].all()
    by_table = np.any(default != got, -1)
    assert by_table[regions].mean() > 0.3 and not by_table[~regions].any()


def test_edges_mode_has_no_render_regions():
    """fallback="edges" (preset `screen`) is "auto" without render regions: on a render-like frame it changes
    only edge-bordering pixels, and every pixel it changes "auto" changes the same way outside the footprint."""
    frame = shaded_polygons(3, 144, 192)
    with Filter(fallback="off") as g, Filter() as a, Filter(preset="screen") as s:
        passes, auto, edges = g.intermediates(frame), a.process(frame), s.process(frame)
    mlaa, e = passes["out"], passes["edges"]
    borders = e != 0
    borders[1:] |= (e[:-1] & 1) > 0
    borders[:, 1:] |= (e[:, :-1] & 2) > 0
    by_edges = np.any(edges != mlaa, -1)
    assert by_edges.sum() > 20 and not np.any(by_edges & ~borders)
    assert np.any(auto != mlaa, -1)[~borders].sum() > 500


def test_two_toned_content_is_no_render_region():
    """Known answer: the yardstick's aliased text and checkerboard through JPEG (ringing gives their edge windows
    four or more colours, so their busy counts are high) stay out of render regions -- their busy tiles are
    two-toned -- while render-like frames are regions nearly everywhere."""
    from mlaa_stream.yardstick.scenes import SCENES
    for scene in SCENES["compressed"](np.random.default_rng(0), True):
        assert not regions_of(scene.inputs[0]).any(), scene.name
    for seed in range(3):
        assert regions_of(shaded_polygons(seed, 144, 192)).mean() > 0.9


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_a_render_frame_takes_every_busy_neighbourhood(seed):
    """Known answer (RENDER_FRAME_PCT): cables on a sky pass the busy tests but are two-toned, so alone, or beside a
    render that holds under RENDER_FRAME_PCT % of the frame's edge tiles, they are no render region; beside a render
    that holds most of the frame's edge tiles the frame is a render and they are regions (flat-colour art beside a
    render stays out: test_kernel_matches_reference). The kernel's flags equal the reference's in all three
    frames."""
    sky = cables_on_sky(seed, 144, 192)
    gap = np.full((144, (RENDER_RADIUS + 2) * FALLBACK_TILE, 3), 200, np.uint8)
    render = [shaded_polygons(seed, 144, 192), shaded_polygons(seed + 10, 144, 192)]
    mostly_render = np.concatenate([*render, gap, sky], 1)
    mostly_sky = np.concatenate([render[0], gap, sky, sky], 1)
    assert not regions_of(sky).any()
    assert regions_of(mostly_render)[:, -192:].mean() > 0.95
    assert not regions_of(mostly_sky)[:, -384:].any()
    assert regions_of(mostly_sky)[:, :192].mean() > 0.5  # the render part keeps its own regions
    with Filter(keep_regions=True) as f:
        for frame in (sky, mostly_render, mostly_sky):
            f.new_shot()  # three frames judged alone (a shot holds its render verdict: tests/test_shots.py)
            f.process(frame)
            h, w = frame.shape[:2]
            tiles = np.repeat(np.repeat(f.last_regions > 0, FALLBACK_TILE, 0), FALLBACK_TILE, 1)[:h, :w]
            np.testing.assert_array_equal(tiles, regions_of(frame))


@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, True), (np.uint8, 4, False), (np.uint16, 3, False),
                                                (np.float32, 3, False)])
def test_kernel_matches_reference_in_a_render_frame(dtype, channels, bgr):
    """Exact, as test_kernel_matches_reference, on a frame that render_frame judges a render (a render beside cables
    on a sky, which become regions only through it), in every stored format."""
    gap = np.full((144, (RENDER_RADIUS + 2) * FALLBACK_TILE, 3), 200, np.uint8)
    frame8 = np.concatenate([shaded_polygons(0, 144, 192), shaded_polygons(10, 144, 192), gap,
                             cables_on_sky(0, 144, 192)], 1)
    frame = _as(frame8[..., ::-1] if bgr else frame8, dtype, channels)
    with Filter(bgr=bgr) as f, Filter(bgr=bgr, fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    assert render_regions_of(frame, passes["out"], passes["edges"], bgr=bgr)[:, -192:].mean() > 0.95
    want = fallback_reference(frame, passes["out"], passes["edges"], passes["hdist"], passes["vdist"], bgr=bgr)
    if dtype == np.float32:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    else:
        np.testing.assert_array_equal(got, want)


def test_ramp_counts_known_answer():
    """Known answer (SUPERSAMPLED_*): per row of the sampled tile (0, 0) a hard step, a two-step ramp and a 1-px line
    (its steps go back: no ramp); a ramp in tile (0, 1) (odd tile column: not sampled), one in tile (0, 4) (no
    edge-bordering pixel) and tile row 1's (odd) are not counted; luma over 1 counts as 1."""
    row = np.full(48, 1.0, np.float32)
    row[:3] = (0.1, 0.5, 0.5)  # 0 -> 1: +0.4, hard (the steps before and after are 0)
    row[3] = 0.75              # 2 -> 3 and 3 -> 4: +0.25 each, both ramps
    row[6] = 0.3               # 5 -> 6 -0.7, 6 -> 7 +0.7: a line, no ramp
    row[10:13] = (0.6, 0.2, 0.6)
    row[34:37] = (0.6, 0.2, 0.6)
    luma = np.repeat(row[None], 16, 0)
    borders = np.zeros((16, 48), bool)
    borders[:, :16] = True
    assert ramp_counts(borders, luma) == (8 * 5, 8 * 2)
    # luma is clipped to display white (HDR frames): four times brighter, only the step from 0.4 to white is left
    assert ramp_counts(borders, luma * 4) == (8, 0)


def test_clean_transitions_known_answer():
    """Known answer (RAMP_FLANK, stair ends): in the sampled tile (0, 0) a hard step between plateaus that moves one
    pixel right between rows 3 and 4 -- only the two rows where it shifts and the one vertical step of the stair are
    stair ends, the runs between go on beside themselves; in tile (0, 2) one pixel halfway between two plateaus (a
    clean ramp, stairs or not); in tile (0, 4) a ramp over four pixels (its steps continue, not clean, none strong);
    tile row 1 (odd) is not counted."""
    row = np.full(48, 0.2, np.float32)
    row[20], row[21:32] = 0.5, 0.8           # x = 19 -> 21: +0.3, +0.3 between flat runs
    row[36:40], row[40:] = (0.35, 0.5, 0.65, 0.8), 0.8
    luma = np.repeat(row[None], 16, 0)
    luma[:4, 4:16] = 0.8                     # rows 0-3: +0.6 from x = 3 to 4 ...
    luma[4:, 5:16] = 0.8                     # ... rows 4-15: from x = 4 to 5
    borders = np.ones((16, 48), bool)
    strong, ramps, clean, clean_ramps = step_counts(borders, luma)
    assert (int(clean.sum()), int(clean_ramps.sum())) == (2 + 1 + 8, 8)
    assert clean[3, 3] == clean[4, 4] == clean[3, 4] == 1 and clean[:8, 19].all()  # (3, 4): the step below it
    assert not clean[8:].any() and not clean[:, 32:].any()
    assert (int(strong.sum()), int(ramps.sum())) == (8 + 1 + 16, 16)      # every row's step, the stair, the ramps


def ramps_beside_render(seed: int) -> np.ndarray:
    """A render (shaded_polygons) beside sine bars 3 px apart (steps of 0.2-0.4 full scale, each continued by the
    next) crossed by black 1-px lines every 32 rows (edges: the bars' tiles are counted): more than SUPERSAMPLED_PCT
    % of the frame's strong steps are ramps, under SUPERSAMPLED_HARD_PCT % hard stair ends."""
    xx = np.arange(144)[None, :, None]
    bars = np.broadcast_to(np.rint(127.5 + 120 * np.sin(xx * 2 * np.pi / 9 + seed)), (144, 144, 3)).astype(np.uint8)
    bars = bars.copy()
    bars[16::32] = 0
    return np.concatenate([shaded_polygons(seed, 144, 192), bars], 1)


@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, False), (np.uint8, 4, True), (np.uint16, 3, False),
                                                (np.float32, 3, False)])
def test_a_supersampled_frame_takes_no_fxaa_and_regions_stay_local(dtype, channels, bgr):
    """Known answer: a frame most of whose strong steps are ramps is judged supersampled, and no pixel outside
    render regions takes FXAA: there the output is the MLAA passes'. Render regions are judged locally
    (RENDER_RAMP_PCT): the render's tiles within RENDER_RADIUS tiles of the bars, whose clean transitions are all
    ramps, are none; its tiles farther away, hard steps only, stay regions. The kernel equals the reference in every
    stored format."""
    frame8 = ramps_beside_render(0)
    frame = _as(frame8[..., ::-1] if bgr else frame8, dtype, channels)
    with Filter(bgr=bgr, keep_regions=True) as f, Filter(bgr=bgr, fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
        tiles = f.last_regions.astype(bool)
    _, _, _, borders, _, rgb = _frame_masks(frame, passes["out"], passes["edges"], bgr)
    strong, ramps = ramp_counts(borders, luma_reference(rgb, False))
    assert ramps * 100 >= SUPERSAMPLED_PCT * strong
    assert supersampled(borders, luma_reference(rgb, False))
    render_tiles = 192 // FALLBACK_TILE
    assert tiles[:, :render_tiles - RENDER_RADIUS].all()
    assert not tiles[:, render_tiles - RENDER_RADIUS:].any()
    regions = render_regions_of(frame, passes["out"], passes["edges"], bgr=bgr)
    np.testing.assert_array_equal(regions, region_pixels(tiles, *regions.shape))
    want = fallback_reference(frame, passes["out"], passes["edges"], passes["hdist"], passes["vdist"], bgr=bgr)
    outside = ~regions
    if dtype == np.float32:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
        np.testing.assert_allclose(got[outside], passes["out"][outside], rtol=0, atol=1e-6)
    else:
        np.testing.assert_array_equal(got, want)
        np.testing.assert_array_equal(got[outside], passes["out"][outside])


@pytest.mark.parametrize("dtype,channels", [(np.uint8, 3), (np.uint16, 3), (np.float32, 3)])
def test_hard_stair_ends_keep_a_frame_with_smooth_texture_a_render(dtype, channels):
    """Known answer (SUPERSAMPLED_HARD_PCT): the render beside sine bars without crossing lines -- most of its
    counted strong steps are ramps (a magnified photographic texture's look), yet at least SUPERSAMPLED_HARD_PCT % of
    them are hard stair ends (1-spp geometry; supersampled frames measured 1-9 %) -- is no supersampled frame: the
    render's tiles beside the bars stay render regions, and the kernel equals the reference."""
    xx = np.arange(144)[None, :, None]
    bars = np.broadcast_to(np.rint(127.5 + 120 * np.sin(xx * 2 * np.pi / 9)), (144, 144, 3)).astype(np.uint8)
    frame = _as(np.concatenate([shaded_polygons(0, 144, 192), bars], 1), dtype, channels)
    with Filter(keep_regions=True) as f, Filter(fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
        tiles = f.last_regions.astype(bool)
    _, _, _, borders, _, rgb = _frame_masks(frame, passes["out"], passes["edges"], False)
    luma = luma_reference(rgb, False)
    strong, ramps, clean, clean_ramps = (int(a.sum()) for a in step_counts(borders, luma))
    assert strong >= 100 and ramps * 100 >= SUPERSAMPLED_PCT * strong
    assert (clean - clean_ramps) * 100 >= SUPERSAMPLED_HARD_PCT * strong
    assert not supersampled(borders, luma)
    render_tiles = 192 // FALLBACK_TILE
    assert tiles[:, :render_tiles].mean() > 0.9
    want = fallback_reference(frame, passes["out"], passes["edges"], passes["hdist"], passes["vdist"])
    if dtype == np.float32:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    else:
        np.testing.assert_array_equal(got, want)


def noisy_photograph(seed: int, rows: int, cols: int) -> np.ndarray:
    """A photograph (matplotlib's portrait sample, rows x cols from its top left) magnified 2x (bicubic: soft edges,
    smooth areas) with colour noise of 3 levels per channel."""
    import cv2
    import matplotlib.cbook
    import matplotlib.image
    photo = matplotlib.image.imread(matplotlib.cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[..., :3]
    big = cv2.resize(np.ascontiguousarray(photo[:rows, :cols]), None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC)
    noise = np.random.default_rng(seed).normal(0, 3, big.shape)
    return np.clip(np.rint(big + noise), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("rows,cols", [(200, 160), (150, 128)])
def test_a_noisy_photograph_has_no_render_region(rows, cols):
    """Known answer (busy pixels within the grain: noise.cl pixel_quiet, fallback.cl grain_verdict): a magnified
    photograph with colour noise -- judged supersampled at 400 x 320, not at 300 x 256; no 1-spp geometry in either --
    has pixels the MLAA passes blend (dark colour noise passes the CIELAB edge threshold) in windows of 4+ exact
    colours, which counted as a render's busy pixels: most of its tiles became render regions, whose tables moved it
    by over a level RMS. Their windows lie within the frame's grain: they count no more, no tile is a region and the
    output stays within half a level of the input (RMS). The kernel's regions equal the reference's."""
    from mlaa_stream.spatial.fallback import _busy_pixels, overlay_tiles, render_regions
    frame = noisy_photograph(0, rows, cols)
    with Filter(keep_regions=True) as f, Filter(fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
        tiles = f.last_regions.astype(bool)
    regions = render_regions_of(frame, passes["out"], passes["edges"])
    assert not tiles.any() and not regions.any()
    assert np.sqrt(np.mean((got.astype(float) - frame) ** 2)) < 0.5
    _, _, _, borders, changed, rgb = _frame_masks(frame, passes["out"], passes["edges"], False)
    luma = luma_reference(rgb, False)
    counted = _busy_pixels(changed, borders, rgb, np.zeros(borders.shape, bool), luma)  # the rule before: no grain test
    assert render_regions(counted, borders, luma, overlay_tiles(frame)).mean() > 0.5


@pytest.mark.parametrize("rows,periods", [(96, 12), (32, 6)])
def test_clean_ramps_alone_make_a_frame_supersampled(rows, periods):
    """Known answer (SUPERSAMPLED_CLEAN_PCT): bars whose every edge is one pixel halfway between two plateaus (steps
    of 0.15, none strong) crossed by 1-px lines every 16 rows (strong steps, none a ramp: the MLAA passes' edges) --
    a frame whose strong steps are under SUPERSAMPLED_PCT % ramps -- is judged supersampled by its clean transitions,
    all ramps: no pixel outside render regions takes FXAA, and the kernel equals the reference. The 32 x 48 frame
    counts 84 clean transitions: at least SUPERSAMPLED_MIN, under the 100 once asked."""
    levels = np.array([0.2, 0.2, 0.2, 0.35, 0.5, 0.5, 0.5, 0.35])
    luma8 = np.repeat(np.tile(levels, periods)[None], rows, 0)
    luma8[7::16] = 0.9
    frame = np.rint(255 * luma8)[..., None].repeat(3, 2).astype(np.uint8)
    with Filter(keep_regions=True) as f, Filter(fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    _, _, _, borders, _, rgb = _frame_masks(frame, passes["out"], passes["edges"], False)
    luma = luma_reference(rgb, False)
    strong, ramps, clean, clean_ramps = (int(a.sum()) for a in step_counts(borders, luma))
    assert strong >= SUPERSAMPLED_MIN and ramps * 100 < SUPERSAMPLED_PCT * strong
    assert clean >= SUPERSAMPLED_MIN and clean_ramps == clean
    assert supersampled(borders, luma)
    want = fallback_reference(frame, passes["out"], passes["edges"], passes["hdist"], passes["vdist"])
    np.testing.assert_array_equal(got, want)
    outside = ~render_regions_of(frame, passes["out"], passes["edges"])
    np.testing.assert_array_equal(got[outside], passes["out"][outside])


@pytest.mark.parametrize("seed,small", [(0, True), (1, True), (2, True), (2, False)])
def test_antialiased_content_is_no_render_region(seed, small):
    """Known answer: the yardstick's already antialiased text, wires and diagonals (8x8 samples per pixel) are no
    render regions at any seed (low-contrast tiles do not count as evidence; a region needs RENDER_MIN busy
    pixels: seed 2's full-size wires have a few dozen)."""
    from mlaa_stream.yardstick.scenes import generate_scenes
    for scene in generate_scenes(small=small, seed=seed, names=["antialiased"]):
        assert not regions_of(scene.inputs[0]).any(), scene.name


def test_footprint_leaves_one_colour_windows():
    """Known answer: in a render region, a pixel whose 5x5 window is one colour and which the chain left keeps
    it (the footprint table does not round-trip it through linear light)."""
    frame = shaded_polygons(9, 144, 192)
    frame[40:60, 40:80] = (90, 140, 60)  # a flat patch inside the render region
    with Filter() as f:
        got = f.process(frame)
    assert regions_of(frame)[45:55, 45:75].all()
    np.testing.assert_array_equal(got[42:58, 42:78], frame[42:58, 42:78])


def test_pixel_aligned_rule_in_a_busy_region_stays_sharp():
    """Known answer: a 1-px rule on noisy ground between busy rendered-like texture is a straight MLAA edge run
    (FALLBACK_KEEP_RUN or longer): the gated fallback leaves its pixels as MLAA left them (within 2 levels),
    where "everywhere" (no such test) smears it (by more than 20 levels somewhere)."""
    rng = np.random.default_rng(3)
    frame = textured_aliased(7, 144, 192).astype(np.int16)
    frame[68:76] = 225                      # a flat band (a UI strip) across the busy frame ...
    frame[72, 8:184] = 40                   # ... carrying a dark pixel-aligned rule, 176 px long
    frame = np.clip(frame + rng.normal(0, 1.0, frame.shape).round(), 0, 255).astype(np.uint8)  # light noise
    with Filter() as f, Filter(fallback="off") as g, Filter(fallback="everywhere") as e:
        got, mlaa, every = f.process(frame), g.process(frame), e.process(frame)
    rule = (slice(72, 73), slice(24, 168))  # away from the rule's ends
    assert np.abs(every[rule].astype(int) - mlaa[rule]).max() > 20
    assert np.abs(got[rule].astype(int) - mlaa[rule]).max() <= 2


def test_flat_colour_art_is_left_to_mlaa():
    """Known answer: two-colour aliased shapes (text, UI, vector art) have at most 3 colours in any 3x3
    window, so the gated fallback changes nothing there, however many jaggies MLAA blends."""
    rng = np.random.default_rng(11)
    h, w = 64, 96
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    img = np.full((h, w, 3), (235, 235, 230), np.uint8)
    for _ in range(5):
        cx, cy, r = rng.uniform(10, 86), rng.uniform(10, 54), rng.uniform(5, 14)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] = (30, 40, 120)
    with Filter() as f, Filter(fallback="off") as g:
        got, mlaa = f.process(img), g.process(img)
    assert np.any(mlaa != img)
    np.testing.assert_array_equal(got, mlaa)


def test_without_aliasing_evidence_nothing_changes():
    """Known answer: a smooth textured frame with no hard edges gives MLAA nothing to blend, so no tile has
    evidence and the gated fallback leaves the frame exactly as it was (photographs stay untouched)."""
    rng = np.random.default_rng(5)
    h, w = 48, 64
    base = rng.uniform(40, 210, (h // 8 + 2, w // 8 + 2, 3))
    yy, xx = np.mgrid[0:h, 0:w] / 8.0
    y0, x0 = np.floor(yy).astype(int), np.floor(xx).astype(int)
    ty, tx = (yy - y0)[..., None], (xx - x0)[..., None]
    img = (base[y0, x0] * (1 - ty) * (1 - tx) + base[y0 + 1, x0] * ty * (1 - tx)
           + base[y0, x0 + 1] * (1 - ty) * tx + base[y0 + 1, x0 + 1] * ty * tx)
    img = np.clip(np.rint(img + rng.normal(0, 1.5, img.shape)), 0, 255).astype(np.uint8)
    with Filter() as f:
        got = f.process(img)
    np.testing.assert_array_equal(got, img)


def test_everywhere_reaches_beyond_the_gates():
    """fallback="everywhere" (the `rendered` preset): its FXAA touches a superset of what "auto"'s touches, the
    same way (without the footprint table, whose input then differs); with the table, more pixels change too."""
    frame = textured_aliased(7, 96, 128)
    with Filter(fallback="off") as g, Filter(footprint_table=None) as a, \
            Filter(preset="rendered", footprint_table=None) as e, Filter() as at, Filter(preset="rendered") as et:
        mlaa, auto, every, auto_t, every_t = (g.process(frame), a.process(frame), e.process(frame),
                                              at.process(frame), et.process(frame))
    by_auto, by_every = np.any(auto != mlaa, -1), np.any(every != mlaa, -1)
    assert by_every.sum() > by_auto.sum() > 0
    np.testing.assert_array_equal(every[by_auto], auto[by_auto])
    assert np.any(every_t != mlaa, -1).sum() >= np.any(auto_t != mlaa, -1).sum()


def test_option_checked():
    with pytest.raises(ValueError, match="fallback"):
        Filter(fallback="sometimes")
    assert Filter(fallback=False).fallback == "off" and Filter(fallback=True).fallback == "auto"
    assert Filter(preset="fast").fallback == "off" and Filter(preset="screen").fallback == "edges"
    assert FALLBACK_TILE == 8


def test_codec_check_runs(capsys):
    """python -m mlaa_stream.bench.codec_check on one scene: encoded and decoded through H.264 (close to, not
    equal to, the input) and scored."""
    from mlaa_stream.bench import codec_check
    frames = np.repeat(shaded_polygons(1, 64, 96)[None], 2, 0)
    coded = codec_check.through_h264(frames, 18)
    assert coded.shape == frames.shape and np.any(coded != frames)
    assert np.abs(coded.astype(int) - frames).mean() < 16  # yuv420p halves the chroma of a busy texture
    assert codec_check.main(["--scenes", "text_ui", "--crf", "28"]) == 0
    assert "text_ui" in capsys.readouterr().out
    jpeg = codec_check.through_jpeg(frames, 75)
    assert jpeg.shape == frames.shape and np.any(jpeg != frames) and np.abs(jpeg.astype(int) - frames).mean() < 16
    big = codec_check.tiled(frames, 200, 150)   # 96 x 64 repeated: whole copies, then the cut ones
    assert big.shape == (2, 150, 200, 3) and np.array_equal(big[:, 64:128, 96:192], frames)
    assert codec_check.main(["--scenes", "text_ui", "--crf", "", "--jpeg", "60", "--tile", "512x448"]) == 0
    out = capsys.readouterr().out
    assert "jpeg q 60" in out and "crf" not in out.split("\n", 1)[1]
    with pytest.raises(SystemExit):
        codec_check.main(["--scenes", "text_ui", "--crf", "", "--jpeg", ""])


def test_show_regions_view():
    """Known answer: Filter(show="regions") returns the normal output inside render regions and SHOW_DIM of
    it (rounded) outside; "everywhere" is all region, "off" none; the option is checked."""
    from mlaa_stream.spatial.fallback import SHOW_DIM
    frame = render_beside_art(3)
    regions = regions_of(frame)
    assert 0 < regions.mean() < 1
    for mode, inside in (("auto", regions), ("everywhere", np.ones_like(regions)),
                         ("off", np.zeros_like(regions))):
        with Filter(fallback=mode) as f, Filter(fallback=mode, show="regions") as g:
            plain, shown = f.process(frame), g.process(frame)
        np.testing.assert_array_equal(shown[inside], plain[inside])
        dimmed = np.rint(plain[~inside].astype(np.float32) * np.float32(SHOW_DIM))
        np.testing.assert_array_equal(shown[~inside], dimmed.astype(np.uint8))
    with pytest.raises(ValueError, match="show"):
        Filter(show="history")


def test_keep_regions_hands_each_frame_its_flags():
    """Filter(keep_regions=True): every collected frame sets PendingFrame.regions and the filter's last_regions
    to its own tile flags (the temporal stage's where="render" reads them), also with two frames in flight;
    the output is the plain filter's."""
    from mlaa_stream.spatial.fallback import FALLBACK_TILE
    render, art = render_beside_art(3), render_beside_art(3)
    art[...] = art[:1, :1]          # one flat colour: no region
    with Filter() as f, Filter(keep_regions=True) as g:
        assert g.last_regions is None
        first, second = g.submit(render), g.submit(art)
        out = first.result()
        np.testing.assert_array_equal(out, f.process(render))
        tiles = np.repeat(np.repeat(first.regions > 0, FALLBACK_TILE, 0), FALLBACK_TILE, 1)[:render.shape[0],
                                                                                           :render.shape[1]]
        np.testing.assert_array_equal(tiles, regions_of(render))
        assert g.last_regions is first.regions
        second.result()
        assert g.last_regions is second.regions and not second.regions.any()
    with Filter(fallback="off", keep_regions=True) as h:
        h.process(render)
        assert h.last_regions is None
