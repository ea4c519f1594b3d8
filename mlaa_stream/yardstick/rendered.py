"""A "rendered" yardstick category: procedural 3D scenes drawn by a real rasterizer.

The other scenes (mlaa_stream.yardstick.scenes) are 2D polygons filled by a numpy scanline. These are 3D
worlds rendered with OpenGL (moderngl on a headless EGL context; Mesa llvmpipe on a CPU), so the
aliasing is what a game engine produces: perspective edges, textures with mipmaps and trilinear
filtering, Lambert + Blinn-Phong lighting, sub-pixel cables and balusters, alpha-tested fences and
foliage, specular highlights.

Each frame is drawn twice from the same camera:
- input: one pass at the pixel centres into an 8-bit target, the shader encoding sRGB (what a
  game writes to its swapchain);
- truth: 8x8 passes with the projection jittered by ((i + 0.5) / 8 - 0.5) pixel, each written as
  linear light to a float32 target and averaged, then encoded to 8-bit sRGB (the scenes' encode8).
Texture LOD is the same in every pass (jitter moves the image, not the derivatives), so the truth is
the input's own shading, supersampled: a filter is scored on edges, not on texture sharpness.

    scenes = generate_rendered(small=True)       # list[mlaa_stream.yardstick.scenes.Scene], category "rendered"
    ok, why = egl_available()

Rendered scenes are cached as compressed .npz files (see cache_path); a second call loads them.
"""
from __future__ import annotations

import hashlib
import json
import math
import os
import time
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from mlaa_stream.yardstick.photo_textures import with_textures
from mlaa_stream.yardstick.scenes import TRUTH_SPP, Scene, SceneUnavailable, edge_mask, encode8, srgb8_to_linear
from mlaa_stream.yardstick.town import town_world  # a second world, for held-out views only
from mlaa_stream.yardstick.world import (Lighting, Material, Mesh, World, beam, box, cable, combine, cylinder, fbm,
                                      hexahedron, linear_tint, merge, quad, rgba, sag, sphere, tex_metal, tex_white,
                                      torus, value_noise)

VERSION = 1  # bump when geometry, shading or cameras change: it keys the cache
CATEGORY = "rendered"
SCENE_NAMES = ("rendered_atrium", "rendered_stress", "rendered_pan", "rendered_dolly", "rendered_orbit")
SIZES = {True: (320, 180), False: (640, 360)}  # small -> (width, height)
SHOT_FRAMES = 8  # frames of each animated shot
PAN_PX_PER_FRAME = 0.3  # image motion of the pan at the image centre
FLAT_COLOUR = (200, 48, 40)  # sRGB8 of the unlit banner: its truth must equal it exactly
GL_SRGB8_ALPHA8 = 0x8C43  # textures store sRGB codes; the sampler decodes to linear before filtering
NEAR, FAR = 0.2, 2500.0


# --- the EGL context ------------------------------------------------------------------------------
EGL_HINT = ("needs moderngl (pip install moderngl) and an EGL driver: Debian's libegl1 + libegl-mesa0 "
            "(the Mesa EGL vendor, which exposes llvmpipe as a device) and libgl1-mesa-dri (swrast)")


@lru_cache(maxsize=1)
def _context():
    """One headless OpenGL 3.3+ context per process (EGL device platform; llvmpipe without a GPU)."""
    import moderngl
    return moderngl.create_context(standalone=True, backend="egl", require=330)


def egl_available() -> tuple[bool, str]:
    """(True, renderer name) when a headless EGL context can be made, else (False, why)."""
    try:
        import moderngl  # noqa: F401
    except ImportError as exc:
        return False, f"moderngl is not installed ({exc}); {EGL_HINT}"
    try:
        ctx = _context()
    except Exception as exc:  # glcontext raises plain Exceptions naming the failing EGL call
        _context.cache_clear()
        return False, f"no EGL context: {type(exc).__name__}: {exc}; {EGL_HINT}"
    return True, f"{ctx.info['GL_RENDERER']} ({ctx.info['GL_VERSION']})"


# --- the plaza's textures (sRGB8 RGBA) and mip chains built in linear light ----------------------------
def tex_bricks(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """Running-bond bricks: 8 bricks x 32 courses, 3 px mortar, per-brick colour and grain."""
    y, x = np.mgrid[0:size, 0:size]
    row = y // (size // 32)
    bx = (x + (row % 2) * (size // 16)) % size  # every other course offset by half a brick
    col = bx // (size // 8)
    mortar = ((y % (size // 32)) < 3) | ((bx % (size // 8)) < 3)
    tone = rng.uniform(0.75, 1.1, (32, 8))[row, col]
    grain = fbm(size, 16, 4, rng)
    brick = np.stack([0.62, 0.30, 0.22]) * (tone * (0.8 + 0.35 * grain))[..., None]
    rgb = np.where(mortar[..., None], (0.72 + 0.1 * grain[..., None]) * np.array([0.9, 0.88, 0.82]), brick)
    return rgba(rgb)


def tex_tiles(rng: np.random.Generator, size: int = 512) -> np.ndarray:
    """4x4 square floor tiles, a checker of two stones with grain, 4 px dark grout."""
    y, x = np.mgrid[0:size, 0:size]
    t = size // 4
    tx, ty = x // t, y // t
    grout = ((x % t) < 4) | ((y % t) < 4)
    grain = fbm(size, 8, 5, rng)
    light, dark = np.array([0.80, 0.76, 0.68]), np.array([0.56, 0.53, 0.50])
    base = np.where(((tx + ty) % 2 == 0)[..., None], light, dark)
    tone = rng.uniform(0.9, 1.05, (4, 4))[ty, tx]
    rgb = base * (tone * (0.85 + 0.25 * grain))[..., None]
    return rgba(np.where(grout[..., None], 0.22, rgb))


def tex_stone(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Beige-grey stone: fractal noise with darker veins."""
    n = fbm(size, 4, 6, rng)
    veins = np.abs(np.sin(12 * fbm(size, 2, 4, rng)))
    v = 0.65 + 0.25 * n - 0.15 * (veins < 0.12)
    return rgba(v[..., None] * np.array([0.95, 0.9, 0.82]))


def tex_wood(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Wood grain running along x: rings perturbed by noise."""
    y = np.arange(size)[:, None] / size
    n = fbm(size, 4, 4, rng)
    rings = 0.5 + 0.5 * np.sin(2 * np.pi * (6 * y + 1.5 * n))
    v = 0.55 + 0.3 * rings
    return rgba(v[..., None] * np.array([0.62, 0.42, 0.25]))


def tex_grass(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Green-brown ground: two noise scales mixing grass and earth."""
    big, fine = fbm(size, 4, 3, rng), value_noise(size, 128, rng)
    green, earth = np.array([0.30, 0.42, 0.16]), np.array([0.42, 0.36, 0.24])
    rgb = green * (1 - big[..., None]) + earth * big[..., None]
    return rgba(rgb * (0.8 + 0.35 * fine)[..., None])


def tex_chainlink(rng: np.random.Generator, size: int = 256, diamonds: int = 5,
                  wire_px: float = 5.0) -> np.ndarray:
    """Chain-link mesh: wires along both diagonals, alpha 1 on the wire (antialiased), 0 between."""
    y, x = np.mgrid[0:size, 0:size] + 0.5
    p = size / diamonds
    u, v = (x + y) % p, (x - y) % p
    d = np.minimum(np.minimum(u, p - u), np.minimum(v, p - v)) / math.sqrt(2)  # px to the nearest wire
    alpha = np.clip(wire_px / 2 + 0.5 - d, 0, 1)
    shade = 0.62 + 0.25 * np.clip(1 - d / (wire_px / 2), 0, 1)  # round wire: lighter along its middle
    return rgba(shade[..., None] * np.array([0.95, 0.97, 1.0]), alpha)


def tex_leaves(rng: np.random.Generator, size: int = 256, leaves: int = 90) -> np.ndarray:
    """A leaf card: a twig and filled ellipse leaves in greens on transparent black."""
    import cv2
    img = np.zeros((size, size, 4), np.uint8)
    cv2.line(img, (size // 2, size - 4), (size // 2 + 10, 20), (90, 60, 35, 255), 3, cv2.LINE_AA)
    for _ in range(leaves):
        c = (int(rng.uniform(0.12, 0.88) * size), int(rng.uniform(0.08, 0.92) * size))
        axes = (int(rng.uniform(0.06, 0.10) * size), int(rng.uniform(0.025, 0.04) * size))
        g = rng.uniform(0.6, 1.0)
        colour = (int(60 * g), int(140 * g), int(45 * g), 255)
        cv2.ellipse(img, c, axes, float(rng.uniform(0, 180)), 0, 360, colour, -1, cv2.LINE_AA)
    return img


def tex_sign(rng: np.random.Generator, width: int = 512, height: int = 128) -> np.ndarray:
    """A station sign: white border and text (cv2.putText, antialiased) on dark blue."""
    import cv2
    img = np.zeros((height, width, 4), np.uint8)
    img[:] = (22, 52, 112, 255)
    cv2.rectangle(img, (6, 6), (width - 7, height - 7), (240, 240, 240, 255), 5, cv2.LINE_AA)
    cv2.putText(img, "PLATFORM 3", (28, 62), cv2.FONT_HERSHEY_DUPLEX, 1.5, (245, 245, 245, 255), 3,
                cv2.LINE_AA)
    cv2.putText(img, "MLAA STREAM -> CITY", (30, 104), cv2.FONT_HERSHEY_SIMPLEX, 1.0,
                (250, 210, 60, 255), 2, cv2.LINE_AA)
    return img


# name -> (texture maker, alpha-tested); seeds are fixed per name so every run draws the same texels
TEXTURES = {
    "bricks": (tex_bricks, False), "tiles": (tex_tiles, False), "stone": (tex_stone, False),
    "wood": (tex_wood, False), "grass": (tex_grass, False), "metal": (tex_metal, False),
    "white": (tex_white, False), "chainlink": (tex_chainlink, True), "leaves": (tex_leaves, True),
    "sign": (tex_sign, False),
}


def _down2(a: np.ndarray, w: np.ndarray | None = None) -> np.ndarray:
    """2x2 box average (a dimension of 1 stays 1); with weights w, the w-weighted average."""
    h, wd = a.shape[:2]
    sy, sx = (2 if h > 1 else 1), (2 if wd > 1 else 1)
    shape = (h // sy, sy, wd // sx, sx) + a.shape[2:]
    if w is None:
        return a.reshape(shape).mean(axis=(1, 3))
    ws = w.reshape(shape[:4])
    num = (a * w[..., None]).reshape(shape).sum(axis=(1, 3))
    den = ws.sum(axis=(1, 3))[..., None]
    plain = a.reshape(shape).mean(axis=(1, 3))
    return np.where(den > 0, num / np.maximum(den, 1e-12), plain)


ALPHA_MIP_MIN = 16  # alpha-tested chains stop at 16 texels: smaller levels are near-uniform alpha


def mip_chain(rgba: np.ndarray, alpha_tested: bool) -> list[np.ndarray]:
    """The mip levels, averaged in linear light and re-encoded to sRGB8: down to 1x1, or for
    alpha-tested textures down to ALPHA_MIP_MIN texels (the sampler's max level).

    Alpha-tested textures average colour weighted by alpha (no dark fringes from the transparent
    texels) and rescale each level's alpha so that the share of texels passing the 0.5 test stays
    the base level's (coverage-preserving mipmaps, as engines do). Levels below ALPHA_MIP_MIN are
    left out: their alpha is nearly uniform and the test would turn a distant fence into a solid
    wall or nothing; instead it stays undersampled, sparkling at 1 spp as in games."""
    lin = srgb8_to_linear(rgba[..., :3]).astype(np.float64)
    alpha = rgba[..., 3].astype(np.float64) / 255.0
    coverage = float(np.mean(alpha >= 0.5))
    levels = [rgba]
    raw_alpha = alpha
    smallest = ALPHA_MIP_MIN if alpha_tested else 1
    while min(lin.shape[:2]) > smallest or (smallest == 1 and max(lin.shape[:2]) > 1):
        lin = _down2(lin, raw_alpha if alpha_tested else None)
        raw_alpha = _down2(raw_alpha)
        a = raw_alpha
        if alpha_tested and 0 < coverage < 1:
            q = float(np.quantile(a, 1 - coverage))  # the alpha the 0.5 test should cut at
            a = np.clip(a * (0.5 / max(q, 1e-6)), 0, 1)
        levels.append(np.dstack([encode8(lin), np.round(a * 255).astype(np.uint8)]))
    return levels


# --- materials and the world ----------------------------------------------------------------------
MATERIALS = {
    "grass": Material("grass", (4.0, 4.0), specular=0.02, shininess=8),
    "tiles": Material("tiles", (2.0, 2.0), specular=0.25, shininess=48),
    "stone": Material("stone", (2.0, 2.0), specular=0.05, shininess=16),
    "marble": Material("stone", (1.5, 1.5), tint=(1.25, 1.22, 1.18), specular=0.35, shininess=80),
    "bricks": Material("bricks", (2.0, 2.0), specular=0.03),
    "wood": Material("wood", (1.0, 0.5), specular=0.05),
    "rail": Material("metal", (1.0, 1.0), tint=(0.06, 0.16, 0.08), specular=0.6, shininess=60),
    "steel": Material("metal", (1.0, 1.0), tint=(0.45, 0.46, 0.48), specular=0.5, shininess=40),
    "cable": Material("metal", (1.0, 1.0), tint=(0.02, 0.02, 0.02), specular=0.4, shininess=30),
    "chainlink": Material("chainlink", (0.3, 0.3), specular=0.3, shininess=30, alpha_test=True, two_sided=True),
    "leaves": Material("leaves", (1.4, 1.4), specular=0.05, alpha_test=True, two_sided=True),
    "sign": Material("sign", (3.2, 0.8), specular=0.1, shininess=30),
    "banner": Material("white", (1.0, 1.0), tint=linear_tint(FLAT_COLOUR), emissive=True),
    "red_gloss": Material("white", tint=(0.55, 0.02, 0.02), specular=1.0, shininess=300),
    "blue_gloss": Material("white", tint=(0.02, 0.06, 0.45), specular=1.0, shininess=500),
    "chrome": Material("white", tint=(0.5, 0.5, 0.52), specular=1.5, shininess=800),
    "gold": Material("white", tint=(0.6, 0.38, 0.08), specular=1.0, shininess=120),
}


# The plaza's draw order (World.draw_order); the sky is drawn at the very end where nothing was drawn
# (the pass is fragment-bound).
DRAW_ORDER = ("red_gloss", "blue_gloss", "chrome", "gold", "sign", "banner", "marble", "stone", "bricks",
              "wood", "steel", "rail", "cable", "tiles", "grass", "leaves", "chainlink")


def _ground() -> dict[str, list[Mesh]]:
    """A 4 km ground to the horizon and a tiled plaza in front of the colonnade."""
    return {"grass": [quad((0, 0, -800), (2000, 0, 0), (0, 0, 2000))],
            "tiles": [quad((-0.5, 0.01, -22), (7.5, 0, 0), (0, 0, 30))]}


def _colonnade() -> dict[str, list[Mesh]]:
    """A raised arcade along -z: platform, columns with bases and capitals, round arches of
    voussoirs, an entablature, a back wall, a roof slab, and five stairs down to the plaza."""
    out: dict[str, list[Mesh]] = {"stone": [], "marble": [], "bricks": []}
    x, z0, z1, pitch = -6.0, -4.0, -44.0, 4.0
    out["stone"].append(box((-10.5, 0, -46), (-4.5, 0.9, -2)))
    top = 4.85  # capitals' top: the arches spring from here
    zs = np.arange(z0, z1 - 0.1, -pitch)
    for z in zs:
        out["stone"].append(box((x - 0.45, 0.9, z - 0.45), (x + 0.45, 1.15, z + 0.45)))
        out["marble"].append(cylinder((x, 1.15, z), (x, 4.6, z), 0.3, seg=16, caps=False))
        out["stone"].append(box((x - 0.4, 4.6, z - 0.4), (x + 0.4, top, z + 0.4)))
    r_in, r_out, half = pitch / 2 - 0.4, pitch / 2 + 0.05, 0.35
    for za, zb in zip(zs[:-1], zs[1:]):
        zc = (za + zb) / 2
        th = np.linspace(0, np.pi, 10)
        for t0, t1 in zip(th[:-1], th[1:]):  # one voussoir: an annulus sector, extruded along x
            c = np.empty((2, 2, 2, 3))
            for ix, xx in enumerate((x - half, x + half)):
                for iy, rr in enumerate((r_in, r_out)):
                    for iz, tt in enumerate((t0, t1)):
                        c[ix, iy, iz] = (xx, top + rr * np.sin(tt), zc + rr * np.cos(tt))
            out["bricks"].append(hexahedron(c))
    roof_y = top + r_out
    out["stone"].append(box((x - 0.45, roof_y, z1 - 0.6), (x + 0.45, roof_y + 0.7, z0 + 0.6)))
    out["bricks"].append(box((-10.5, 0.9, z1 - 0.6), (-10.0, roof_y + 0.7, z0 + 0.6)))
    out["stone"].append(box((-10.6, roof_y + 0.7, z1 - 0.8), (x + 0.6, roof_y + 0.95, z0 + 0.8)))
    for k in range(5):  # the lowest step reaches furthest towards the plaza
        out["stone"].append(box((-4.5, 0.18 * k, -45), (-4.5 + 0.35 * (5 - k), 0.18 * (k + 1), -3)))
    return out


def _railing() -> dict[str, list[Mesh]]:
    """A railing to the horizon: two rails and a baluster every 0.4 m for 200 m."""
    x, z0, z1 = 6.5, 4.0, -200.0
    parts = [beam((x, 1.0, z0), (x, 1.0, z1), 0.07, 0.06), beam((x, 0.15, z0), (x, 0.15, z1), 0.05, 0.05)]
    parts += [beam((x, 0.15, z), (x, 1.0, z), 0.035, 0.035) for z in np.arange(z0, z1, -0.4)]
    return {"rail": parts}


def _power_line() -> dict[str, list[Mesh]]:
    """Wooden poles every 25 m along the road to 400 m, cross-arms, three sagging cables."""
    out: dict[str, list[Mesh]] = {"wood": [], "steel": [], "cable": []}
    x, h = 11.0, 9.0
    zs = np.arange(2.0, -400.0, -25.0)
    arms = (-0.9, 0.0, 0.9)
    for z in zs:
        out["wood"].append(cylinder((x, 0, z), (x, h, z), 0.13, seg=8))
        out["wood"].append(beam((x - 1.1, h - 0.6, z), (x + 1.1, h - 0.6, z), 0.12, 0.12))
        out["steel"] += [box((x + a - 0.04, h - 0.54, z - 0.04), (x + a + 0.04, h - 0.4, z + 0.04)) for a in arms]
    for a in arms:
        for za, zb in zip(zs[:-1], zs[1:]):
            out["cable"] += cable(sag((x + a, h - 0.4, za), (x + a, h - 0.4, zb), 0.5, 8), 0.015)
    return out


def _fence() -> dict[str, list[Mesh]]:
    """A 2.2 m chain-link fence along x = 8.6 with posts every 3 m and a top pipe."""
    x, z0, z1, h = 8.6, -3.0, -72.0, 2.2
    zs = np.arange(z0, z1 - 0.1, -3.0)
    out = {"chainlink": [quad((x, h / 2, (z0 + z1) / 2), (0, 0, (z0 - z1) / 2), (0, h / 2, 0))],
           "steel": [cylinder((x, 0, z), (x, h + 0.05, z), 0.035, seg=6) for z in zs]}
    out["steel"].append(cylinder((x, h, z0), (x, h, z1), 0.025, seg=6))
    return out


def _tree(rng: np.random.Generator, base) -> dict[str, list[Mesh]]:
    """A trunk and a crown of 48 randomly oriented alpha-tested leaf cards."""
    bx, bz = base
    out = {"wood": [cylinder((bx, 0, bz), (bx, 3.8, bz), 0.2, seg=6)], "leaves": []}
    centre = np.array([bx, 5.0, bz])
    for _ in range(48):
        p = centre + rng.normal(0, 1, 3) * (1.3, 0.9, 1.3)
        n = rng.normal(0, 1, 3)
        n /= np.linalg.norm(n)
        u = np.cross(n, [0, 1, 0] if abs(n[1]) < 0.9 else [1, 0, 0])
        u /= np.linalg.norm(u)
        out["leaves"].append(quad(p, u * 0.7, np.cross(n, u) * 0.7))
    return out


def _trees() -> dict[str, list[Mesh]]:
    rng = np.random.default_rng(7)
    bases = [(-13.5, -8), (-14, -22), (-13, -37), (15, -12), (19, -25), (14, -40), (22, -55), (16, -70),
             (28, -34)]
    return combine(_tree(rng, b) for b in bases)


def _ornaments() -> dict[str, list[Mesh]]:
    """Plinths with glossy spheres and a standing torus; a lit sign; the flat unlit banner."""
    out: dict[str, list[Mesh]] = {"stone": [], "wood": [], "steel": []}
    items = [((0.0, -5.0), "red_gloss"), ((2.4, -7.0), "chrome"), ((-1.8, -9.0), "blue_gloss")]
    for (px, pz), mat in items:
        out["stone"].append(box((px - 0.4, 0, pz - 0.4), (px + 0.4, 1.0, pz + 0.4)))
        out.setdefault(mat, []).append(sphere((px, 1.45, pz), 0.45))
    out["stone"].append(box((3.8, 0, -3.6), (4.6, 0.8, -2.8)))
    out["gold"] = [torus((4.2, 1.45, -3.2), 0.5, 0.14, axis=(0.6, 0.0, 0.8))]
    # the sign: turned 20 degrees so its text and border run at a slant
    a = math.radians(20)
    u, v = np.array([math.cos(a), 0, -math.sin(a)]) * 1.6, np.array([0, 0.4, 0])
    centre = np.array([-1.2, 2.6, -13.0])
    out["sign"] = [quad(centre, u, v)]
    out["wood"] += [cylinder(centre + s * u * 0.8 - [0, 2.6, 0], centre + s * u * 0.8 - [0, 0.4, 0], 0.06, seg=8)
                    for s in (-1, 1)]
    out["banner"] = [quad((3.0, 2.8, -16.0), (1.5, 0, 0), (0, 1.0, 0))]
    out["steel"] += [cylinder((x, 0, -16.05), (x, 3.8, -16.05), 0.05, seg=8) for x in (1.45, 4.55)]
    return out


def _pylon(x: float, z: float, h: float = 36.0) -> list[Mesh]:
    """A lattice transmission tower: four tapering legs, a ring and X-bracing per 4.5 m panel,
    and cross-arms near the top."""
    def corner(y: float, sx: int, sz: int) -> np.ndarray:
        half = 4.0 + (1.2 - 4.0) * y / h
        return np.array([x + sx * half, y, z + sz * half])

    cs = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    w = 0.35
    parts = [beam(corner(0, *c), corner(h, *c), w, w) for c in cs]
    ys = np.linspace(0, h, 9)
    for y0, y1 in zip(ys[:-1], ys[1:]):
        for c, d in zip(cs, cs[1:] + cs[:1]):
            parts.append(beam(corner(y1, *c), corner(y1, *d), w * 0.6, w * 0.6))
            parts.append(beam(corner(y0, *c), corner(y1, *d), w * 0.5, w * 0.5))
            parts.append(beam(corner(y0, *d), corner(y1, *c), w * 0.5, w * 0.5))
    for y in (h - 8, h - 2):
        parts.append(beam((x - 12, y, z), (x + 12, y, z), 0.6, 0.8))
    return parts


def _pylons() -> dict[str, list[Mesh]]:
    """Five pylons across the view 300 m away, with four sagging cables between them."""
    xs, z, h = np.arange(-200.0, 201.0, 100.0), -320.0, 36.0
    out = {"steel": [m for x in xs for m in _pylon(x, z, h)], "cable": []}
    for dx, y in ((-11.5, h - 8), (11.5, h - 8), (-11.5, h - 2), (11.5, h - 2)):
        for xa, xb in zip(xs[:-1], xs[1:]):
            out["cable"] += cable(sag((xa + dx, y, z), (xb + dx, y, z), 5.0, 12), 0.05)
    return out


PLAZA_LIGHT = Lighting(sun_dir=(-0.45, 0.75, 0.48), sun=(2.0, 1.85, 1.6), sky_zenith=(0.18, 0.32, 0.62),
                       sky_horizon=(0.62, 0.72, 0.85), ambient_sky=(0.16, 0.19, 0.26),
                       ambient_ground=(0.07, 0.06, 0.05),
                       fog_density=0.0035)  # distant pylons fade into the horizon colour
WORLDS = ("plaza", "town")  # plaza: the bench's scenes and the held-out views; town: yardstick/town.py


@lru_cache(maxsize=2)
def build_world(name: str = "plaza") -> World:
    """The named world, the same for every scene drawn in it."""
    if name == "town":
        return town_world()
    if name != "plaza":
        raise ValueError(f"expected a world from {', '.join(WORLDS)}, got {name!r}")
    groups = combine([_ground(), _colonnade(), _railing(), _power_line(), _fence(), _trees(),
                       _ornaments(), _pylons()])
    return World({k: merge(v) for k, v in groups.items() if v}, MATERIALS, TEXTURES, DRAW_ORDER, PLAZA_LIGHT)


# --- cameras --------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Camera:
    eye: tuple
    target: tuple
    vfov: float = 50.0  # vertical field of view, degrees

    def view(self) -> np.ndarray:
        e, t = np.asarray(self.eye, float), np.asarray(self.target, float)
        f = (t - e) / np.linalg.norm(t - e)
        s = np.cross(f, [0, 1, 0])
        s /= np.linalg.norm(s)
        u = np.cross(s, f)
        m = np.eye(4)
        m[0, :3], m[1, :3], m[2, :3] = s, u, -f
        m[:3, 3] = -m[:3, :3] @ e
        return m

    def projection(self, aspect: float) -> np.ndarray:
        f = 1.0 / math.tan(math.radians(self.vfov) / 2)
        m = np.zeros((4, 4))
        m[0, 0], m[1, 1] = f / aspect, f
        m[2, 2], m[2, 3] = (FAR + NEAR) / (NEAR - FAR), 2 * FAR * NEAR / (NEAR - FAR)
        m[3, 2] = -1.0
        return m

    def view_projection(self, width: int, height: int, dx: float = 0.0, dy: float = 0.0) -> np.ndarray:
        """Projection x view, the image shifted by (dx, dy) pixels (a translation in NDC, applied
        after the perspective divide: the jitter of the supersampled truth)."""
        jitter = np.eye(4)
        jitter[0, 3], jitter[1, 3] = 2 * dx / width, 2 * dy / height
        return jitter @ self.projection(width / height) @ self.view()


def _yawed(eye, target, angle: float) -> tuple:
    """target turned around the eye's vertical axis by angle (radians, positive to the right)."""
    e, t = np.asarray(eye, float), np.asarray(target, float)
    d = t - e
    c, s = math.cos(angle), math.sin(angle)
    return tuple(e + [c * d[0] - s * d[2], d[1], s * d[0] + c * d[2]])


def shot(name: str, width: int, height: int) -> list[Camera]:
    """The cameras of a scene, one per frame."""
    n = SHOT_FRAMES
    if name == "rendered_atrium":
        return [Camera((2.0, 1.7, 9.0), (-2.5, 2.4, -20.0), 55.0)]
    if name == "rendered_stress":  # down the road: railing, fence, cables and pylons converge
        return [Camera((5.6, 1.7, -18.0), (7.9, 2.7, -140.0), 30.0)]
    if name == "rendered_pan":  # a yaw pan, PAN_PX_PER_FRAME at the image centre whatever the size
        cam = Camera((0.5, 1.65, 6.0), (-4.0, 2.6, -18.0), 50.0)
        step = PAN_PX_PER_FRAME * 2 * math.tan(math.radians(cam.vfov) / 2) / height
        return [Camera(cam.eye, _yawed(cam.eye, cam.target, k * step), cam.vfov) for k in range(n)]
    if name == "rendered_dolly":  # forward 5 cm per frame towards the plinths
        return [Camera((1.2, 1.6, 5.0 - 0.05 * k), (1.0, 1.5, -8.0 - 0.05 * k), 50.0) for k in range(n)]
    if name == "rendered_orbit":  # 0.25 degree per frame around the spheres, 6.5 m out
        centre = np.array([0.6, 1.3, -7.0])
        cams = []
        for k in range(n):
            a = math.radians(28.0 + 0.25 * k)
            eye = centre + [6.5 * math.sin(a), 1.2, 6.5 * math.cos(a)]
            cams.append(Camera(tuple(eye), tuple(centre), 48.0))
        return cams
    raise ValueError(f"expected a scene name from {', '.join(SCENE_NAMES)}, got {name!r}")


NOTES = {
    "rendered_atrium": "arcade, stairs, glossy spheres, torus, sign, banner, railing and poles to the horizon",
    "rendered_stress": "long lens down the road: balusters, chain-link, cables and pylons going sub-pixel",
    "rendered_pan": f"yaw pan {PAN_PX_PER_FRAME} px/frame over the arcade, sign and trees",
    "rendered_dolly": "dolly forward 5 cm/frame towards the glossy spheres",
    "rendered_orbit": "orbit 0.25 deg/frame around the spheres and torus",
}


# --- the renderer ---------------------------------------------------------------------------------
VERTEX_SHADER = """
#version 330
uniform mat4 u_vp;
in vec3 in_pos;
in vec3 in_nrm;
in vec2 in_uv;
out vec3 v_pos;
out vec3 v_nrm;
out vec2 v_uv;
void main() {
    v_pos = in_pos;  // meshes are in world space: no model matrix
    v_nrm = in_nrm;
    v_uv = in_uv;
    gl_Position = u_vp * vec4(in_pos, 1.0);
}
"""

# Shading in linear light; clamped to [0, 1] (the display range) before either output, so the
# truth averages exactly the values the 1-spp input encodes -- but for the HDR renders' linear output
# (Renderer(hdr=True)), which keeps highlights over 1 as a scene-referred EXR holds them.
COMMON_GLSL = """
uniform bool u_encode;  // true: sRGB-encode for the 8-bit input target; false: linear for the truth
uniform bool u_hdr;     // linear output unclamped above (highlights over 1)
vec3 encode_srgb(vec3 c) {
    return mix(c * 12.92, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(vec3(0.0031308), c));
}
vec4 finish(vec3 c) {
    c = (u_hdr && !u_encode) ? max(c, 0.0) : clamp(c, 0.0, 1.0);
    return vec4(u_encode ? encode_srgb(c) : c, 1.0);
}
"""

FRAGMENT_SHADER = """
#version 330
uniform sampler2D u_tex;
uniform vec2 u_tile;
uniform vec3 u_tint;
uniform float u_spec;
uniform float u_shininess;
uniform bool u_alpha_test;
uniform bool u_two_sided;
uniform bool u_emissive;
uniform vec3 u_eye;
uniform vec3 u_sun_dir;
uniform vec3 u_sun;
uniform vec3 u_amb_sky;
uniform vec3 u_amb_ground;
uniform vec3 u_fog;
uniform float u_fog_density;
in vec3 v_pos;
in vec3 v_nrm;
in vec2 v_uv;
out vec4 f_colour;
""" + COMMON_GLSL + """
void main() {
    vec4 t = texture(u_tex, v_uv / u_tile);  // trilinear; sRGB texels decoded before filtering
    if (u_alpha_test && t.a < 0.5) discard;
    vec3 albedo = t.rgb * u_tint;
    if (u_emissive) { f_colour = finish(albedo); return; }
    vec3 n = normalize(v_nrm);
    vec3 to_eye = u_eye - v_pos;
    vec3 v = normalize(to_eye);
    if (u_two_sided && dot(n, v) < 0.0) n = -n;
    float ndl = max(dot(n, u_sun_dir), 0.0);
    vec3 h = normalize(u_sun_dir + v);
    // energy-normalised Blinn-Phong lobe: small bright highlights at high shininess
    float spec = ndl > 0.0 ? pow(max(dot(n, h), 0.0), u_shininess) * (u_shininess + 8.0) / 25.13 : 0.0;
    vec3 ambient = mix(u_amb_ground, u_amb_sky, 0.5 + 0.5 * n.y);
    vec3 c = albedo * (ambient + u_sun * ndl) + u_spec * spec * u_sun;
    float fog = exp(-u_fog_density * length(to_eye));
    f_colour = finish(mix(u_fog, c, fog));
}
"""

SKY_VERTEX = """
#version 330
void main() {  // one triangle covering the screen, at the far plane
    vec2 p = vec2((gl_VertexID << 1) & 2, gl_VertexID & 2) * 2.0 - 1.0;
    gl_Position = vec4(p, 1.0, 1.0);
}
"""

SKY_FRAGMENT = """
#version 330
uniform mat4 u_inv_vp;  // inverse of the (jittered) view-projection: each sample's own ray
uniform vec2 u_size;
uniform vec3 u_eye;
uniform vec3 u_zenith;
uniform vec3 u_horizon;
out vec4 f_colour;
""" + COMMON_GLSL + """
void main() {
    vec4 p = u_inv_vp * vec4(gl_FragCoord.xy / u_size * 2.0 - 1.0, 1.0, 1.0);
    vec3 d = normalize(p.xyz / p.w - u_eye);
    float t = pow(clamp(d.y, 0.0, 1.0), 0.6);
    f_colour = finish(mix(u_horizon, u_zenith, t));
}
"""


def _mat_bytes(m: np.ndarray) -> bytes:
    return np.ascontiguousarray(m.T, dtype=np.float32).tobytes()  # GLSL reads column-major


class Renderer:
    """The world on one GL context at one size: textures, meshes, an 8-bit target for the input
    and a float32 target for the truth passes (sharing one depth buffer)."""

    def __init__(self, ctx, width: int, height: int, world: str = "plaza", textures: str = "procedural",
                 texture_repeat: float = 1.0, hdr: bool = False, sky_gain: float = 1.0):
        """`textures`: the world's own procedural textures, or a set of photographs (yardstick/photo_textures.py),
        repeated `texture_repeat` times as often across their surfaces. `hdr`: the linear outputs (truth_linear,
        input_linear) keep values over 1 (specular highlights); `sky_gain`: the sky's radiance times this."""
        self.hdr, self.sky_gain = bool(hdr), float(sky_gain)
        import moderngl
        self.mgl = moderngl
        self.ctx, self.width, self.height = ctx, width, height
        self.world = with_textures(build_world(world), textures, texture_repeat)
        self.prog = ctx.program(vertex_shader=VERTEX_SHADER, fragment_shader=FRAGMENT_SHADER)
        self.sky = ctx.program(vertex_shader=SKY_VERTEX, fragment_shader=SKY_FRAGMENT)
        self.sky_vao = ctx.vertex_array(self.sky, [])
        self.textures = {name: self._texture(name) for name in self.world.textures}
        self.draws = []  # (material, vertex array, buffers) in the world's draw order
        order = self.world.draw_order
        for name in sorted(self.world.meshes, key=order.index):
            mesh = self.world.meshes[name]
            data = np.hstack([mesh.pos, mesh.nrm, mesh.uv]).astype(np.float32)
            vbo, ibo = ctx.buffer(data.tobytes()), ctx.buffer(mesh.idx.astype(np.uint32).tobytes())
            vao = ctx.vertex_array(self.prog, [(vbo, "3f 3f 2f", "in_pos", "in_nrm", "in_uv")],
                                   index_buffer=ibo, index_element_size=4)
            self.draws.append((self.world.materials[name], vao, (vbo, ibo)))
        depth = ctx.depth_renderbuffer((width, height))
        self.fbo8 = ctx.framebuffer([ctx.renderbuffer((width, height), 4)], depth)
        self.fbo32 = ctx.framebuffer([ctx.renderbuffer((width, height), 4, dtype="f4")], depth)
        self.msaa_fbos = {}  # samples -> multisample target (msaa_frame), made when first asked for
        self._set_lights()

    def _texture(self, name: str):
        """Upload a procedural texture with its own mip chain (sRGB8, trilinear, repeating)."""
        make, alpha_tested = self.world.textures[name]
        seed = int(hashlib.sha256(name.encode()).hexdigest()[:8], 16)
        levels = mip_chain(make(np.random.default_rng(seed)), alpha_tested)
        # numpy row 0 is the image's top; GL's first row is v = 0, the bottom: flip on upload
        h, w = levels[0].shape[:2]
        tex = self.ctx.texture((w, h), 4, np.flipud(levels[0]).tobytes(), internal_format=GL_SRGB8_ALPHA8)
        tex.build_mipmaps(0, len(levels) - 1)  # allocates the chain; each level is then replaced by ours
        for k, lev in enumerate(levels[1:], start=1):
            tex.write(np.ascontiguousarray(np.flipud(lev)).tobytes(), level=k)
        tex.filter = (self.mgl.LINEAR_MIPMAP_LINEAR, self.mgl.LINEAR)  # trilinear
        tex.repeat_x = tex.repeat_y = True
        return tex

    def _set_lights(self) -> None:
        light = self.world.light
        sun = np.asarray(light.sun_dir, float)
        p = self.prog
        p["u_sun_dir"].value = tuple(sun / np.linalg.norm(sun))
        p["u_sun"].value, p["u_fog"].value = light.sun, light.sky_horizon
        p["u_fog_density"].value = light.fog_density
        p["u_amb_sky"].value, p["u_amb_ground"].value = light.ambient_sky, light.ambient_ground
        self.sky["u_zenith"].value = tuple(self.sky_gain * np.asarray(light.sky_zenith, float))
        self.sky["u_horizon"].value = tuple(self.sky_gain * np.asarray(light.sky_horizon, float))
        self.sky["u_size"].value = (float(self.width), float(self.height))

    def draw(self, cam: Camera, dx: float, dy: float, encode: bool) -> None:
        """One pass of the whole world into the bound target, the image shifted by (dx, dy) px."""
        mgl = self.mgl
        vp = cam.view_projection(self.width, self.height, dx, dy)
        self.ctx.disable(mgl.CULL_FACE)  # no face culling: cards and fences are seen from both sides
        self.ctx.enable(mgl.DEPTH_TEST)
        self.ctx.depth_func = "<="  # the sky sits at depth 1.0, the cleared value: drawn where nothing is
        p = self.prog
        p["u_vp"].write(_mat_bytes(vp))
        p["u_eye"].value = tuple(map(float, cam.eye))
        p["u_encode"].value, p["u_hdr"].value = encode, self.hdr
        for mat, vao, _ in self.draws:
            self.textures[mat.texture].use(0)
            p["u_tex"].value = 0
            p["u_tile"].value, p["u_tint"].value = mat.tile, mat.tint
            p["u_spec"].value, p["u_shininess"].value = mat.specular, mat.shininess
            p["u_alpha_test"].value, p["u_two_sided"].value = mat.alpha_test, mat.two_sided
            p["u_emissive"].value = mat.emissive
            vao.render()
        self.sky["u_inv_vp"].write(_mat_bytes(np.linalg.inv(vp)))
        self.sky["u_eye"].value = tuple(map(float, cam.eye))
        self.sky["u_encode"].value, self.sky["u_hdr"].value = encode, self.hdr
        self.sky_vao.render(mgl.TRIANGLES, vertices=3)

    def input_frame(self, cam: Camera) -> np.ndarray:
        """One sample per pixel at the pixel centres, sRGB-encoded by the shader: (H, W, 3) uint8."""
        self.fbo8.use()
        self.fbo8.clear(0, 0, 0, 1, depth=1.0)
        self.draw(cam, 0.0, 0.0, encode=True)
        img = np.frombuffer(self.fbo8.read(components=3), np.uint8).reshape(self.height, self.width, 3)
        return np.flipud(img).copy()

    def depth_frame(self, cam: Camera) -> np.ndarray:
        """The window depth in [0, 1] of the 1-spp pass (what each pixel centre's sample hit; the sky is 1):
        (H, W) float32, row 0 the image's top. For exact motion (reprojection)."""
        self.input_frame(cam)
        depth = np.frombuffer(self.fbo8.read(components=1, attachment=-1, dtype="f4"), np.float32)
        return np.flipud(depth.reshape(self.height, self.width)).copy()

    def input_linear(self, cam: Camera) -> np.ndarray:
        """One sample per pixel at the pixel centres in linear light, as a renderer writes an EXR: (H, W, 3)
        float32 (over 1 in highlights with hdr=True)."""
        self.fbo32.use()
        return np.flipud(self._linear_pass(cam, 0.0, 0.0)).copy()

    def truth_linear(self, cam: Camera, spp: int = TRUTH_SPP) -> np.ndarray:
        """The mean of spp x spp jittered passes in linear light: (H, W, 3) float64."""
        return self.truth_mapped(cam, [lambda light: light], spp)[0]

    def truth_mapped(self, cam: Camera, maps: list[Callable[[np.ndarray], np.ndarray]],
                     spp: int = TRUTH_SPP) -> list[np.ndarray]:
        """For each function of `maps` (linear light -> display light, e.g. a tone curve), the mean of spp x spp
        jittered passes each mapped on its own, as a renderer that tone-maps every sample before the resolve shows
        them: (H, W, 3) float64 per map, row 0 the top. With hdr=True the passes keep highlights over 1."""
        self.fbo32.use()
        accs = [np.zeros((self.height, self.width, 3), np.float64) for _ in maps]
        offsets = (np.arange(spp) + 0.5) / spp - 0.5
        for dy in offsets:
            for dx in offsets:
                sample = self._linear_pass(cam, dx, dy).astype(np.float64)
                for acc, f in zip(accs, maps):
                    acc += f(sample)
        return [np.flipud(acc / (spp * spp)).copy() for acc in accs]

    def coverage_frames(self, cam: Camera, spp: int = TRUTH_SPP) -> tuple[np.ndarray, ...]:
        """The world with its sky as transparency, as a renderer writes an element over nothing: the 1-spp linear
        colour and coverage (1 where a pixel centre hit geometry, 0 on the sky) and the spp x spp jittered means of
        the premultiplied colour and of the coverage. (H, W, 3), (H, W), (H, W, 3), (H, W) float64, row 0 the top."""
        self.fbo32.use()

        def one(dx: float, dy: float) -> tuple[np.ndarray, np.ndarray]:
            rgb = self._linear_pass(cam, dx, dy).astype(np.float64)
            depth = np.frombuffer(self.fbo32.read(components=1, attachment=-1, dtype="f4"), np.float32)
            return rgb, (depth.reshape(self.height, self.width) < 1.0).astype(np.float64)  # the sky sits at 1

        colour, cover = one(0.0, 0.0)
        acc, acc_cover = np.zeros_like(colour), np.zeros_like(cover)
        offsets = (np.arange(spp) + 0.5) / spp - 0.5
        for dy in offsets:
            for dx in offsets:
                c, a = one(dx, dy)
                acc += c * a[..., None]
                acc_cover += a
        n = spp * spp
        return tuple(np.flipud(v).copy() for v in (colour, cover, acc / n, acc_cover / n))

    def _linear_pass(self, cam: Camera, dx: float, dy: float) -> np.ndarray:
        """One linear pass into the bound float target, the image shifted by (dx, dy) px: _linear_rows."""
        self.fbo32.clear(0, 0, 0, 1, depth=1.0)
        self.draw(cam, dx, dy, encode=False)
        return self._linear_rows()

    def _linear_rows(self) -> np.ndarray:
        """The float target's RGB as GL stores it, bottom row first: (H, W, 3) float32."""
        return np.frombuffer(self.fbo32.read(components=3, dtype="f4"), np.float32).reshape(self.height, self.width, 3)

    def truth_frame(self, cam: Camera, spp: int = TRUTH_SPP) -> np.ndarray:
        """The supersampled truth encoded like the other scenes' (encode8): (H, W, 3) uint8."""
        return encode8(self.truth_linear(cam, spp))

    def msaa_frame(self, cam: Camera, samples: int = 4) -> np.ndarray:
        """The world as a game with MSAA draws it: coverage and depth from `samples` samples per pixel, each
        fragment shaded once, resolved (the samples' mean) in linear light and encoded like the truth: (H, W, 3)
        uint8. Raises ValueError when the GL driver offers no such sample count (llvmpipe: 4, not 8)."""
        if samples not in self.msaa_fbos:
            size = (self.width, self.height)
            try:
                colour = self.ctx.renderbuffer(size, 4, samples=samples, dtype="f4")
            except self.mgl.Error as e:
                raise ValueError(f"this GL driver draws no MSAA with {samples} samples: {e}") from None
            depth = self.ctx.depth_renderbuffer(size, samples=samples)
            self.msaa_fbos[samples] = self.ctx.framebuffer([colour], depth)
        fbo = self.msaa_fbos[samples]
        fbo.use()
        fbo.clear(0, 0, 0, 1, depth=1.0)
        self.draw(cam, 0.0, 0.0, encode=False)
        self.ctx.copy_framebuffer(self.fbo32, fbo)  # the resolve: the mean of each pixel's samples
        return encode8(np.flipud(self._linear_rows()).astype(np.float64))

    def release(self) -> None:
        for _, vao, bufs in self.draws:
            vao.release()
            for b in bufs:
                b.release()
        for t in self.textures.values():
            t.release()
        for obj in (self.sky_vao, self.prog, self.sky, self.fbo8, self.fbo32):
            obj.release()
        for fbo in self.msaa_fbos.values():
            fbo.release()


def reprojection(cam_from: Camera, cam_to: Camera, depth: np.ndarray) -> np.ndarray:
    """Exact motion of a still world: where the point each pixel centre of cam_from's frame hit (window depth
    `depth`, Renderer.depth_frame) lies in cam_to's frame. Returns (H, W, 2) float32 offsets (x, y) in pixels,
    position in cam_to's frame = pixel index + offset (the maps of mlaa_stream.temporal.motion_ring). The sky (depth 1)
    is taken at the far plane. Occlusion is not tested: a point hidden in cam_to's frame still gets its
    position (the temporal stages' colour box is what rejects such samples)."""
    h, w = depth.shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    ndc = np.stack([2 * (xs + 0.5) / w - 1, 1 - 2 * (ys + 0.5) / h, 2 * depth.astype(np.float64) - 1,
                    np.ones_like(xs)], -1)
    world = ndc @ np.linalg.inv(cam_from.view_projection(w, h)).T
    clip = world @ cam_to.view_projection(w, h).T   # the homogeneous w cancels in the divide below
    px = (clip[..., 0] / clip[..., 3] + 1) / 2 * w - 0.5
    py = (1 - clip[..., 1] / clip[..., 3]) / 2 * h - 0.5
    return np.stack([px - xs, py - ys], -1).astype(np.float32)


def depth_frames(cams: list[Camera], width: int, height: int, renderer: Renderer | None = None,
                 world: str = "plaza") -> np.ndarray:
    """Each camera's window depth (Renderer.depth_frame) in `world` (or `renderer`'s): (T, H, W) float32 (not
    cached: ~0.3 s a frame)."""
    own = renderer is None
    r = Renderer(_context(), width, height, world) if own else renderer
    try:
        return np.stack([r.depth_frame(c) for c in cams])
    finally:
        if own:
            r.release()


def render_scene(name: str, small: bool = False, renderer: Renderer | None = None) -> Scene:
    """Render one scene (no cache): every frame's input and 8x8 truth."""
    width, height = SIZES[bool(small)]
    own = renderer is None
    r = Renderer(_context(), width, height) if own else renderer
    try:
        cams = shot(name, width, height)
        inputs = np.stack([r.input_frame(c) for c in cams])
        truths = np.stack([r.truth_frame(c) for c in cams])
    finally:
        if own:
            r.release()
    return Scene(name, CATEGORY, inputs, truths, edge_mask(inputs, truths), notes=NOTES[name])


# --- cache and the public entry point -------------------------------------------------------------
def default_cache_dir() -> Path:
    """$MLAA_STREAM_CACHE/rendered when set, else ~/.cache/mlaa-stream/rendered."""
    root = os.environ.get("MLAA_STREAM_CACHE")
    return (Path(root) if root else Path.home() / ".cache" / "mlaa-stream") / "rendered"


def cache_path(cache_dir: Path, name: str, small: bool) -> Path:
    """The .npz of one scene, keyed by a hash of (name, size, VERSION)."""
    width, height = SIZES[bool(small)]
    key = json.dumps([name, width, height, VERSION]).encode()
    return Path(cache_dir) / f"{name}_{width}x{height}_{hashlib.sha256(key).hexdigest()[:16]}.npz"


def _load(path: Path, name: str) -> Scene | None:
    try:
        with np.load(path) as z:
            inputs, truths = z["inputs"], z["truths"]
    except (OSError, KeyError, ValueError):  # absent or half-written: render again
        return None
    return Scene(name, CATEGORY, inputs, truths, edge_mask(inputs, truths), notes=NOTES[name])


def _save(path: Path, scene: Scene) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
    np.savez_compressed(tmp, inputs=scene.inputs, truths=scene.truths)
    os.replace(tmp, path)  # atomic: a reader never sees half a file


@dataclass
class RenderLog:
    """Seconds spent per scene (0 when loaded from the cache)."""

    seconds: dict[str, float] = field(default_factory=dict)
    cached: dict[str, bool] = field(default_factory=dict)


LAST_RUN = RenderLog()  # timings of the latest generate_rendered call


def generate_rendered(small: bool = False, names: list[str] | None = None,
                      cache_dir: Path | None = None, *, use_cache: bool = True) -> list[Scene]:
    """The rendered scenes (or the named ones), from the cache when there, else rendered and cached.

    Raises SceneUnavailable (a RuntimeError) when a scene must be rendered and no EGL context can be made."""
    names = list(SCENE_NAMES) if names is None else list(names)
    unknown = [n for n in names if n not in SCENE_NAMES]
    if unknown:
        raise ValueError(f"expected scene names from {', '.join(SCENE_NAMES)}, got {', '.join(unknown)}")
    cache_dir = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    LAST_RUN.seconds.clear()
    LAST_RUN.cached.clear()
    out: list[Scene] = []
    renderer = None
    try:
        for name in names:
            t0 = time.perf_counter()
            path = cache_path(cache_dir, name, small)
            scene = _load(path, name) if use_cache else None
            LAST_RUN.cached[name] = scene is not None
            if scene is None:
                if renderer is None:
                    ok, why = egl_available()
                    if not ok:
                        raise SceneUnavailable(f"rendered scenes need a headless OpenGL context to render "
                                               f"{name} (not in the cache {cache_dir}): {why}")
                    renderer = Renderer(_context(), *SIZES[bool(small)])
                scene = render_scene(name, small, renderer)
                if use_cache:
                    _save(path, scene)
            LAST_RUN.seconds[name] = time.perf_counter() - t0
            out.append(scene)
    finally:
        if renderer is not None:
            renderer.release()
    return out


if __name__ == "__main__":  # python rendered.py [--small] [--no-cache] [--png DIR]
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--small", action="store_true")
    ap.add_argument("--no-cache", action="store_true")
    ap.add_argument("--png", type=Path, help="write each scene's first input and truth as PNG here")
    ap.add_argument("names", nargs="*")
    args = ap.parse_args()
    print("EGL:", egl_available()[1])
    t_all = time.perf_counter()
    scenes = generate_rendered(args.small, args.names or None, use_cache=not args.no_cache)
    for s in scenes:
        edges = float(s.edges.mean())
        print(f"{s.name:18s} {s.size[0]}x{s.size[1]}x{s.frames}  {LAST_RUN.seconds[s.name]:6.1f} s"
              f"{' (cache)' if LAST_RUN.cached[s.name] else ''}  edge pixels {100 * edges:.1f} %")
        if args.png:
            import cv2
            args.png.mkdir(parents=True, exist_ok=True)
            for k in sorted({0, s.frames - 1}):
                for kind, arr in (("in", s.inputs[k]), ("truth", s.truths[k])):
                    cv2.imwrite(str(args.png / f"{s.name}_{k}_{kind}.png"), arr[..., ::-1])
    print(f"total {time.perf_counter() - t_all:.1f} s")
