"""Photographic textures for the rendered worlds: the opaque procedural textures (bricks, plaster, cobbles, ...)
replaced by photographs, as in real scenes (Sponza's walls and floors are photographs). Magnified photographs make
smooth ramps between plateaus inside surfaces, which a 1-spp render's procedural textures hardly have: they test
that the filter still finds a render's jaggies there (fallback.py, RENDER_RAMP_PCT).

Two sets, from matplotlib's sample data (no download): "photo", crops of grace_hopper.jpg tinted per texture;
"relief", the Jacksboro fault elevation model hill-shaded, and a product photograph (Minduka_Present_Blue_Pack.png).
Signs, window panes, white and metal surfaces and alpha-tested cut-outs keep their procedural textures."""
from __future__ import annotations

from dataclasses import replace
from typing import Callable

import numpy as np

from mlaa_stream.yardstick.world import World

TEXTURE_SETS = ("procedural", "photo", "relief")
SIZE = 512  # texels per side, as the procedural bricks and tiles
KEPT = ("white", "metal")  # flat materials: a photograph would not stand for them
# (left, top, width, height) crops of grace_hopper.jpg (512 x 600) and a tint each, used in turn
PHOTO_CROPS = [(0, 0, 256, 256), (256, 0, 256, 256), (0, 300, 256, 256), (200, 200, 300, 300), (100, 350, 250, 250)]
PHOTO_TINTS = [(1.0, 0.85, 0.75), (0.9, 0.9, 0.9), (0.8, 0.9, 0.8), (1.0, 1.0, 1.0), (0.9, 0.8, 0.7)]
# (top, left) of 200 x 200 windows of the elevation model's hill shade, and a tint each
RELIEF_WINDOWS = [((0, 0), (1.0, 0.9, 0.8)), ((100, 150), (0.8, 0.85, 0.7)), ((140, 200), (0.9, 0.9, 0.95))]


def _sample(name: str) -> str:
    from matplotlib import cbook
    return cbook.get_sample_data(name, asfileobj=False)


def _rgba(rgb8: np.ndarray) -> np.ndarray:
    return np.dstack([rgb8, np.full(rgb8.shape[:2], 255, np.uint8)])


def _photo(crop: tuple, tint: tuple) -> Callable:
    def make(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
        import cv2
        import matplotlib.image
        img = matplotlib.image.imread(_sample("grace_hopper.jpg"))[..., :3]
        left, top, w, h = crop
        a = cv2.resize(np.ascontiguousarray(img[top:top + h, left:left + w]), (size, size),
                       interpolation=cv2.INTER_AREA)
        return _rgba(np.clip(a * np.asarray(tint), 0, 255).astype(np.uint8))
    return make


def _relief(top_left: tuple, tint: tuple) -> Callable:
    def make(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
        import cv2
        dem = np.load(_sample("jacksboro_fault_dem.npz"))["elevation"].astype(np.float64)
        gy, gx = np.gradient(dem)
        shade = np.clip(0.6 + 0.08 * (gx - gy), 0, 1)  # lit from the north-west
        y, x = top_left
        a = cv2.resize(shade[y:y + 200, x:x + 200], (size, size), interpolation=cv2.INTER_CUBIC)
        return _rgba(np.clip(a[..., None] * np.asarray(tint) * 255, 0, 255).astype(np.uint8))
    return make


def _product(rng: np.random.Generator, size: int = SIZE) -> np.ndarray:
    import cv2
    import matplotlib.image
    img = matplotlib.image.imread(_sample("Minduka_Present_Blue_Pack.png"))[..., :3]  # float in [0, 1]
    return _rgba(cv2.resize((img * 255).astype(np.uint8), (size, size), interpolation=cv2.INTER_CUBIC))


def _makers(kind: str) -> list[Callable]:
    if kind == "photo":
        return [_photo(c, t) for c, t in zip(PHOTO_CROPS, PHOTO_TINTS)]
    relief = [_relief(tl, t) for tl, t in RELIEF_WINDOWS]
    return [relief[0], _product, relief[1], relief[2]]


def with_textures(world: World, kind: str, repeat: float = 1.0) -> World:
    """`world` with its opaque textures (but for signs, windows, white and metal) replaced by the set `kind` (one of
    TEXTURE_SETS; "procedural" returns the world unchanged), in the order of the world's texture table. `repeat`:
    the replaced textures repeat that many times as often across their surfaces (> 1: finer texels, minified
    through the mipmaps as far walls in real scenes are)."""
    if kind not in TEXTURE_SETS:
        raise ValueError(f"expected a texture set from {', '.join(TEXTURE_SETS)}, got {kind!r}")
    if not repeat > 0:
        raise ValueError(f"expected a positive texture repeat, got {repeat!r}")
    if kind == "procedural":
        return world
    makers, textures, k = _makers(kind), dict(world.textures), 0
    for name, (make, alpha_tested) in world.textures.items():
        if alpha_tested or name in KEPT or "sign" in name or "window" in name:
            continue
        textures[name] = (makers[k % len(makers)], False)
        k += 1
    if repeat == 1.0:
        return replace(world, textures=textures)
    replaced = {name for name in textures if textures[name] is not world.textures[name]}
    materials = {name: replace(m, tile=(m.tile[0] / repeat, m.tile[1] / repeat)) if m.texture in replaced else m
                 for name, m in world.materials.items()}
    return replace(world, textures=textures, materials=materials)
