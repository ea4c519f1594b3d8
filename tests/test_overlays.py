"""Text over a render leaves the render regions (kernels/overlays.cl against spatial/overlays.py, and known answers)."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from mlaa_stream.spatial import overlays as O
from mlaa_stream.spatial.fallback import FALLBACK_TILE, SEGMENT, fallback_defines
from mlaa_stream.device.formats import frame_format, levels8
from mlaa_stream.yardstick.scenes import coverage, text_polygons

T = FALLBACK_TILE


def point_sampled_render(h: int, w: int, seed: int) -> np.ndarray:
    """A stand-in for a 1-spp render: shaded value noise under hard-edged polygons of random colours."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] + 0.5
    base = rng.uniform(40, 200, 3)
    shade = 0.75 + 0.25 * np.sin(x / rng.uniform(5, 11)) * np.cos(y / rng.uniform(4, 9))
    img = base * shade[..., None] + rng.normal(0, 6, (h, w, 3))
    for _ in range(8):
        a, b, c = rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.4, 0.4)
        img[a * (x - w / 2) + b * (y - h / 2) > c * w] = rng.uniform(10, 245, 3) * shade[..., None][
            a * (x - w / 2) + b * (y - h / 2) > c * w]
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def with_subtitle(frame: np.ndarray, outline: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """White antialiased text (8x8 coverage, blended in sRGB) near the bottom, optionally on a black band; and the
    mask of the rows it covers."""
    h, w = frame.shape[:2]
    cov = coverage(text_polygons("Quiet night 1984", 6, h - 10, 18), 8, 0, h, 0, w).reshape(h, 8, w, 8).mean((1, 3))
    out = frame.astype(np.float64)
    if outline:
        ring = np.zeros_like(cov)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                ring = np.maximum(ring, np.roll(np.roll(cov, dy, 0), dx, 1))
        out *= 1 - ring[..., None]
    out = out * (1 - cov[..., None]) + 255 * cov[..., None]
    return np.round(out).astype(np.uint8), cov > 0.02


def run_kernels(device, frame: np.ndarray, bgr: bool = False, render: np.ndarray | None = None):
    """overlay_counts and overlay_tiles on `frame` with every tile a render region (or `render`): the counts
    (tiles_y, tiles_x, 2) and the flags left."""
    fmt = frame_format(frame, bgr)
    defs = {**fallback_defines(fmt, True, False), **O.overlay_defines()}
    tx, ty = -(-fmt.width // T), -(-fmt.height // T)
    flags = np.ones((ty, tx), np.uint8) if render is None else render.astype(np.uint8)
    mf = cl.mem_flags
    src = cl.Buffer(device.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(frame))
    reg = cl.Buffer(device.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=flags)
    counts = cl.Buffer(device.ctx, mf.READ_WRITE, 2 * tx * ty)
    seeds = cl.Buffer(device.ctx, mf.READ_WRITE, tx * ty)
    k_counts = device.kernel("overlays", "overlay_counts", defs)
    k_seeds = device.kernel("overlays", "overlay_seeds", defs)
    k_tiles = device.kernel("overlays", "overlay_tiles", defs)
    W, H, TX, TY = (np.int32(v) for v in (fmt.width, fmt.height, tx, ty))
    k_counts(device.queue, (-(-fmt.width // SEGMENT), ty), None, src, reg, counts, W, H, TX, TY)
    k_seeds(device.queue, (ty,), None, counts, seeds, TX, TY)
    k_tiles(device.queue, (ty,), None, counts, seeds, reg, TX, TY)
    c = np.empty(2 * tx * ty, np.uint8)
    cl.enqueue_copy(device.queue, c, counts)
    cl.enqueue_copy(device.queue, flags, reg)
    return c.reshape(ty, tx, 2), flags.astype(bool)


def codec_noise(frame: np.ndarray, seed: int) -> np.ndarray:
    """+-3 levels of seeded noise: no colour stays exactly flat, as after a video codec."""
    noise = np.random.default_rng(seed).integers(-3, 4, frame.shape)
    return np.clip(frame.astype(np.int64) + noise, 0, 255).astype(np.uint8)


@pytest.mark.parametrize("kind", ["uint8", "uint16", "float32", "bgr", "grey", "rgba", "noisy"])
def test_kernel_matches_the_reference(device, kind):
    """Seeded renders with and without subtitles at sizes that are not multiples of the tile, every sample type."""
    for seed, (h, w) in ((1, (61, 83)), (2, (48, 96))):
        frame, _ = with_subtitle(point_sampled_render(h, w, seed), outline=seed == 2)
        bgr = kind == "bgr"
        if kind == "uint16":
            frame = frame.astype(np.uint16) * 257 + np.random.default_rng(seed).integers(0, 100, frame.shape,
                                                                                      dtype=np.uint16)
        elif kind == "float32":
            frame = frame.astype(np.float32) / 255 + np.float32(0.3 / 255)
        elif kind == "grey":
            frame = np.ascontiguousarray(frame[..., 1])
        elif kind == "rgba":
            frame = np.concatenate([frame, np.full((h, w, 1), 200, np.uint8)], -1)
        elif kind == "noisy":
            frame = codec_noise(frame, seed)
        counts, flags = run_kernels(device, frame, bgr=bgr)
        nb, nm = O.overlay_counts(levels8(frame, bgr))
        np.testing.assert_array_equal(counts[..., 0], nb)
        np.testing.assert_array_equal(counts[..., 1], nm)
        np.testing.assert_array_equal(flags, ~O.overlay_tiles(frame, bgr))
        assert nm.sum() > 0


@pytest.mark.parametrize("outline, noisy", [(False, False), (True, False), (True, True)])
def test_subtitles_over_a_render_are_found_and_the_render_is_not(device, outline, noisy):
    """Known answer: the tiles under white (or outlined) antialiased text are overlay, with a codec's noise too; a
    render without text has none; tiles more than three tiles from every region are not even counted."""
    plain = point_sampled_render(64, 160, 7)
    frame, text = with_subtitle(plain, outline)
    if noisy:
        plain, frame = codec_noise(plain, 3), codec_noise(frame, 3)
    _, flags = run_kernels(device, plain)
    assert flags.all()
    _, flags = run_kernels(device, frame)
    text_tiles = text.reshape(8, T, 20, T).any((1, 3))
    assert (~flags[text_tiles]).mean() > (0.5 if noisy else 0.6 if outline else 0.9)
    assert flags[:4].all()  # the rows above the text stay regions
    render = np.zeros((8, 20), bool)
    render[0, 0] = True
    counts, _ = run_kernels(device, frame, render=render)
    assert not counts[4:].any() and not counts[:, 4:].any()


def test_the_filter_keeps_subtitles_over_a_render_out_of_its_regions(device):
    """End to end on a real render (needs EGL or the scene cache): with white subtitles composited over the bench's
    rendered atrium, the text's tiles are no render regions and the filter leaves the text nearly as it is."""
    from mlaa_stream.yardstick.rendered import egl_available
    from mlaa_stream.yardstick.scenes import SceneUnavailable, generate_scenes
    from mlaa_stream.spatial.filter import Filter
    try:
        atrium = [s for s in generate_scenes(names=["rendered"]) if s.name == "rendered_atrium"][0]
    except SceneUnavailable as exc:
        pytest.skip(f"rendered scenes need EGL or their cache: {exc} ({egl_available()[1]})")
    base = atrium.inputs[0]
    frame, text = with_subtitle(base)
    with Filter(context=device, keep_regions=True) as f:
        out = f.process(frame)
        regions = f.last_regions.astype(bool)
        plain = f.process(base)
        assert f.last_regions.mean() > 0.5  # a render: most tiles are regions
    h, w = text.shape
    text_tiles = np.zeros_like(regions)
    text_tiles[:h // T, :w // T] = text[:h // T * T, :w // T * T].reshape(h // T, T, w // T, T).any((1, 3))
    assert regions[text_tiles].mean() < 0.1
    change = np.sqrt(((out.astype(float) - frame)[text] ** 2).mean())  # 22 levels RMSE before the rule
    assert change < 5, change
    np.testing.assert_array_equal(out[:h - 72], plain[:h - 72])  # far from the text: as without it
