"""A second rendered world, "town": a street of houses in evening light, for held-out views only.

The plaza (yardstick/rendered.py) is where the bench's rendered scenes, the held-out views and the footprint
tables' training views are all drawn, so a rule could fit its textures, materials and light without failing
any of them. The town shares only the renderer and the primitives: its own textures (plaster, windows with
mullions, roof tiles, cobbles, striped awnings, a square grate, ivy), materials, geometry (facades with window
grids and balconies, tram wires across the street, bicycles with sub-pixel spokes, lamp posts, bollards, a
distant church tower) and a low warm sun. No bench scene and no training view uses it
(mlaa_stream.bench.rendered_views --world town).
"""
from __future__ import annotations

import math

import numpy as np

from mlaa_stream.yardstick.world import (Lighting, Material, Mesh, World, beam, box, cable, combine, cylinder, fbm,
                                      linear_tint, merge, quad, rgba, sag, sphere, tex_metal, tex_white, torus,
                                      value_noise)


# --- textures -------------------------------------------------------------------------------------
def tex_plaster(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Light plaster with blotches and fine grain; materials tint it per house."""
    blot, fine = fbm(size, 3, 5, rng), value_noise(size, 96, rng)
    v = 0.78 + 0.14 * blot + 0.06 * fine
    return rgba(v[..., None] * np.array([0.97, 0.94, 0.88]))


def tex_window(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """A window (one quad per window): a white frame, a cross of mullions, dark glass with a sky reflection."""
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size
    frame = (x < 0.08) | (x > 0.92) | (y < 0.06) | (y > 0.94) | (np.abs(x - 0.5) < 0.03) | (np.abs(y - 0.42) < 0.025)
    glass = np.stack([0.10 + 0.25 * (1 - y), 0.13 + 0.28 * (1 - y), 0.18 + 0.32 * (1 - y)], -1)
    glass *= (0.85 + 0.3 * value_noise(size, 4, rng))[..., None]
    return rgba(np.where(frame[..., None], np.array([0.92, 0.91, 0.88]), glass))


def tex_roof(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Red clay roof tiles: 8 rows of 8 rounded tiles, each row shadowed under the one above."""
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size
    row = np.floor(y * 8).astype(int)
    fy = y * 8 - row
    fx = (x * 8 + 0.5 * (row % 2)) % 1.0
    bulge = np.sqrt(np.clip(1 - (2 * fx - 1) ** 2, 0, 1))
    tone = rng.uniform(0.8, 1.1, (8, 9))[row, np.floor(x * 8 + 0.5 * (row % 2)).astype(int) % 9]
    v = tone * (0.45 + 0.45 * bulge) * (0.55 + 0.45 * np.clip(fy / 0.3, 0, 1))
    return rgba(v[..., None] * np.array([0.78, 0.36, 0.24]))


def tex_cobbles(rng: np.random.Generator, size: int = 256) -> np.ndarray:
    """Grey cobbles: a jittered grid of 8 x 8 rounded stones with dark joints."""
    y, x = (np.mgrid[0:size, 0:size] + 0.5) / size * 8
    cy, cx = np.floor(y).astype(int), np.floor(x).astype(int)
    jit = rng.uniform(-0.12, 0.12, (8, 8, 2))
    dy = y - cy - 0.5 - jit[cy, cx, 0]
    dx = x - cx - 0.5 - jit[cy, cx, 1]
    d = np.maximum(np.abs(dx), np.abs(dy))
    stone = np.clip((0.5 - d) / 0.12, 0, 1)
    tone = rng.uniform(0.75, 1.05, (8, 8))[cy, cx] * (0.85 + 0.25 * fbm(size, 8, 3, rng))
    v = 0.12 + stone * tone * 0.5
    return rgba(v[..., None] * np.array([0.95, 0.95, 1.0]))


def tex_awning(rng: np.random.Generator, size: int = 128) -> np.ndarray:
    """Striped awning fabric: 8 red and cream stripes along u."""
    x = (np.arange(size) + 0.5) / size
    stripe = (np.floor(x * 8) % 2 == 0)[None, :].repeat(size, 0)
    weave = 0.92 + 0.08 * value_noise(size, 64, rng)
    rgb = np.where(stripe[..., None], np.array([0.70, 0.10, 0.10]), np.array([0.93, 0.88, 0.76]))
    return rgba(rgb * weave[..., None])


def tex_grate(rng: np.random.Generator, size: int = 128, bars: int = 4, bar_px: float = 6.0) -> np.ndarray:
    """A square steel grate: bars along both axes, alpha 1 on the bars, 0 between."""
    y, x = np.mgrid[0:size, 0:size] + 0.5
    p = size / bars
    d = np.minimum(np.minimum(x % p, p - x % p), np.minimum(y % p, p - y % p))
    alpha = np.clip(bar_px / 2 + 0.5 - d, 0, 1)
    return rgba(np.full((size, size, 3), 0.8), alpha)


def tex_ivy(rng: np.random.Generator, size: int = 256, leaves: int = 160) -> np.ndarray:
    """An ivy card: many small dark-green pointed leaves on transparent black."""
    import cv2
    img = np.zeros((size, size, 4), np.uint8)
    for _ in range(leaves):
        c = np.array([rng.uniform(0.06, 0.94), rng.uniform(0.06, 0.94)]) * size
        a = rng.uniform(0, 2 * math.pi)
        r = rng.uniform(0.03, 0.06) * size
        pts = [c + r * np.array([math.cos(a + t), math.sin(a + t)]) * s for t, s in
               ((0, 1.6), (2.2, 0.9), (math.pi, 0.5), (-2.2, 0.9))]
        g = rng.uniform(0.5, 1.0)
        cv2.fillPoly(img, [np.round(np.array(pts)).astype(np.int32)], (int(40 * g), int(95 * g), int(35 * g), 255),
                     cv2.LINE_AA)
    return img


def tex_shopsign(rng: np.random.Generator, width: int = 512, height: int = 128) -> np.ndarray:
    """A shop sign: dark serif lettering on cream with a thin dark border."""
    import cv2
    img = np.zeros((height, width, 4), np.uint8)
    img[:] = (236, 226, 196, 255)
    cv2.rectangle(img, (4, 4), (width - 5, height - 5), (40, 30, 25, 255), 3, cv2.LINE_AA)
    cv2.putText(img, "BAKERY & CAFE", (24, 80), cv2.FONT_HERSHEY_COMPLEX, 1.6, (45, 30, 20, 255), 3, cv2.LINE_AA)
    return img


TEXTURES = {
    "plaster": (tex_plaster, False), "window": (tex_window, False), "roof": (tex_roof, False),
    "cobbles": (tex_cobbles, False), "awning": (tex_awning, False), "grate": (tex_grate, True),
    "ivy": (tex_ivy, True), "shopsign": (tex_shopsign, False), "metal": (tex_metal, False),
    "white": (tex_white, False),
}

MATERIALS = {
    "plaster_ochre": Material("plaster", (2.5, 2.5), tint=(1.0, 0.78, 0.48), specular=0.02),
    "plaster_rose": Material("plaster", (2.5, 2.5), tint=(0.95, 0.62, 0.58), specular=0.02),
    "plaster_grey": Material("plaster", (2.5, 2.5), tint=(0.72, 0.75, 0.78), specular=0.02),
    "window": Material("window", (1.0, 1.6), specular=0.8, shininess=200),
    "roof": Material("roof", (1.6, 1.6), specular=0.05),
    "cobbles": Material("cobbles", (2.0, 2.0), specular=0.15, shininess=24),
    "kerb": Material("plaster", (1.0, 1.0), tint=(0.55, 0.55, 0.56), specular=0.05),
    "awning": Material("awning", (2.4, 1.0), specular=0.03, two_sided=True),
    "grate": Material("grate", (0.6, 0.6), tint=(0.15, 0.15, 0.16), specular=0.4, shininess=40, alpha_test=True,
                      two_sided=True),
    "ivy": Material("ivy", (1.2, 1.2), specular=0.08, shininess=20, alpha_test=True, two_sided=True),
    "shopsign": Material("shopsign", (2.4, 0.45), specular=0.05),
    "iron": Material("metal", (1.0, 1.0), tint=(0.05, 0.05, 0.06), specular=0.5, shininess=50),
    "wire": Material("metal", (1.0, 1.0), tint=(0.03, 0.03, 0.03), specular=0.3, shininess=30),
    "bike_red": Material("white", tint=(0.5, 0.04, 0.03), specular=0.9, shininess=120),
    "lamp": Material("white", tint=linear_tint((255, 236, 190)), emissive=True),
    "brass": Material("white", tint=(0.55, 0.40, 0.12), specular=1.2, shininess=150),
}

DRAW_ORDER = ("lamp", "brass", "bike_red", "shopsign", "window", "awning", "iron", "wire", "kerb", "plaster_ochre",
              "plaster_rose", "plaster_grey", "roof", "cobbles", "ivy", "grate")

LIGHT = Lighting(sun_dir=(0.75, 0.32, -0.35), sun=(2.4, 1.7, 1.05), sky_zenith=(0.22, 0.30, 0.55),
                 sky_horizon=(0.85, 0.62, 0.45), ambient_sky=(0.12, 0.13, 0.20), ambient_ground=(0.09, 0.06, 0.04),
                 fog_density=0.006)

STREET_X = 6.0        # the facades stand at x = +-STREET_X (street and pavements between)
PLASTERS = ("plaster_ochre", "plaster_rose", "plaster_grey")


# --- geometry -------------------------------------------------------------------------------------
def _ground() -> dict[str, list[Mesh]]:
    """Cobbled street, raised pavements with kerbs, a plain ground beyond."""
    out = {"cobbles": [quad((0, 0, -120), (STREET_X, 0, 0), (0, 0, 140))], "kerb": []}
    for s in (-1, 1):
        out["kerb"].append(box((min(s * 4.0, s * STREET_X), 0, -260), (max(s * 4.0, s * STREET_X), 0.15, 20)))
    return out


def _house(side: int, z0: float, length: float, floors: int, plaster: str, rng: np.random.Generator,
           shop: bool) -> dict[str, list[Mesh]]:
    """One house on side -1 (left) or +1 (right) from z0 back to z0 - length: a plaster block, a grid of windows
    (3 m floors, 2.6 m apart), balconies with iron railings on some, a tiled roof slope, a shop front with an
    awning and a sign on the ground floor where `shop`."""
    x_face = side * STREET_X
    depth, height = 9.0, 3.0 * floors + 0.6
    out: dict[str, list[Mesh]] = {plaster: [], "window": [], "roof": [], "iron": []}
    out[plaster].append(box((min(x_face, x_face + side * depth), 0, z0 - length),
                            (max(x_face, x_face + side * depth), height, z0)))
    # the roof: one slope up from the facade's top to the ridge 3.5 m higher and 4.5 m back
    ridge = np.array([x_face + side * 4.5, height + 3.5, 0.0])
    eave = np.array([x_face - side * 0.4, height - 0.2, 0.0])
    zc = z0 - length / 2
    mid = (ridge + eave) / 2
    out["roof"].append(quad((mid[0], mid[1], zc), (ridge - eave) / 2, (0, 0, length / 2 + 0.3)))
    n_win = max(int((length - 1.0) // 2.6), 1)
    zs = z0 - length / 2 + (np.arange(n_win) - (n_win - 1) / 2) * 2.6
    x_win = x_face - side * 0.02
    for f in range(floors):
        y = 3.0 * f + 1.0
        for z in zs:
            if f == 0 and shop:
                continue
            out["window"].append(quad((x_win, y + 0.8, z), (0, 0, 0.55), (0, 0.8, 0)))
        if f >= 1 and rng.random() < 0.5:  # a balcony: slab, top rail and balusters every 0.12 m
            za, zb = zs[0] - 0.9, zs[-1] + 0.9
            xo = x_face - side * 0.9
            out.setdefault("kerb", []).append(box((min(x_face, xo), y - 0.15, za), (max(x_face, xo), y, zb)))
            out["iron"].append(beam((xo, y + 1.0, za), (xo, y + 1.0, zb), 0.04, 0.04))
            for zz in np.arange(za, zb + 1e-6, 0.12):
                out["iron"].append(beam((xo, y, zz), (xo, y + 1.0, zz), 0.018, 0.018))
    if shop:
        zc0 = z0 - length / 2
        out["window"].append(quad((x_win, 1.5, zc0), (0, 0, min(length / 2 - 0.8, 2.6)), (0, 1.1, 0)))
        # the awning slopes down from the facade over the pavement
        top, low = np.array([x_face, 3.1, zc0]), np.array([x_face - side * 1.6, 2.5, zc0])
        out["awning"] = [quad((top + low) / 2, (0, 0, min(length / 2 - 0.5, 3.0)), (top - low) / 2)]
        out["shopsign"] = [quad((x_win - side * 0.01, 3.45, zc0), (0, 0, 1.6), (0, 0.3, 0))]
    return out


def _houses() -> dict[str, list[Mesh]]:
    rng = np.random.default_rng(11)
    groups = []
    for side in (-1, 1):
        z = 8.0
        while z > -170.0:
            length = float(rng.uniform(7.0, 13.0))
            groups.append(_house(side, z, length, int(rng.integers(2, 5)), PLASTERS[int(rng.integers(3))], rng,
                                 shop=bool(rng.random() < 0.35)))
            z -= length
    return combine(groups)


def _tram_wires() -> dict[str, list[Mesh]]:
    """Two contact wires along the street 6 m up, held by span wires from the facades every 25 m."""
    out: dict[str, list[Mesh]] = {"wire": []}
    zs = np.arange(5.0, -180.0, -25.0)
    for x in (-1.4, 1.4):
        for za, zb in zip(zs[:-1], zs[1:]):
            out["wire"] += cable(sag((x, 6.0, za), (x, 6.0, zb), 0.15, 6), 0.012)
    for z in zs:
        out["wire"] += cable(sag((-STREET_X, 7.0, z), (STREET_X, 7.0, z), 0.6, 8), 0.01)
    return out


def _bicycle(x: float, z: float, facing: float) -> dict[str, list[Mesh]]:
    """A bicycle standing along `facing` (radians about the vertical): two wheels with 16 sub-pixel spokes each, a
    tube frame, handlebars."""
    d = np.array([math.sin(facing), 0.0, math.cos(facing)])
    base = np.array([x, 0.0, z])
    r = 0.34
    back, front = base - d * 0.52 + [0, r, 0], base + d * 0.52 + [0, r, 0]
    side = np.cross(d, [0, 1, 0])
    out: dict[str, list[Mesh]] = {"iron": [], "bike_red": []}
    for c in (back, front):
        out["iron"].append(torus(c, r, 0.018, axis=tuple(side), nu=36, nv=6))
        for k in range(16):
            a = 2 * math.pi * k / 16
            rim = c + r * (math.cos(a) * d + math.sin(a) * np.array([0, 1.0, 0]))
            out["iron"].append(cylinder(c, rim, 0.0035, seg=4, caps=False))
    seat, bar, crank = base + [0, 0.95, 0] - d * 0.18, base + [0, 1.0, 0] + d * 0.42, base + [0, r, 0]
    for a, b in ((back, crank), (crank, seat), (seat, bar), (crank, bar), (back, seat), (bar, front)):
        out["bike_red"].append(cylinder(a, b, 0.02, seg=6, caps=False))
    out["iron"].append(cylinder(bar - side * 0.28, bar + side * 0.28, 0.012, seg=6))
    return out


def _street_furniture() -> dict[str, list[Mesh]]:
    """Lamp posts every 18 m on both pavements, bollards along the left kerb, bicycles, planters with ivy, a
    grate gate and a fountain."""
    groups = []
    for z in np.arange(2.0, -160.0, -18.0):
        for s in (-1, 1):
            x = s * 4.5
            groups.append({"iron": [cylinder((x, 0.15, z), (x, 4.6, z), 0.06, seg=10),
                                    beam((x, 4.6, z), (x - s * 0.6, 4.6, z), 0.05, 0.05)],
                           "lamp": [sphere((x - s * 0.6, 4.4, z), 0.16, nu=16, nv=8)]})
    groups.append({"brass": [sphere((-4.25, 0.95, z), 0.09, nu=12, nv=6) for z in np.arange(0.0, -60.0, -2.0)],
                   "iron": [cylinder((-4.25, 0.15, z), (-4.25, 0.9, z), 0.07, seg=10) for z in
                            np.arange(0.0, -60.0, -2.0)]})
    for k, z in enumerate(np.arange(-6.0, -11.0, -0.7)):
        groups.append(_bicycle(4.7, z, math.radians(90 + 6 * k)))
    rng = np.random.default_rng(5)
    for z in (-14.0, -30.0, -46.0):
        cards = []
        for _ in range(26):  # a bush of ivy cards on a planter
            p = np.array([-4.9, 1.4, z]) + rng.normal(0, 1, 3) * (0.35, 0.3, 0.55)
            n = rng.normal(0, 1, 3)
            n /= np.linalg.norm(n)
            u = np.cross(n, [0, 1, 0] if abs(n[1]) < 0.9 else [1, 0, 0])
            u /= np.linalg.norm(u)
            cards.append(quad(p, u * 0.45, np.cross(n, u) * 0.45))
        groups.append({"ivy": cards, "kerb": [box((-5.5, 0.15, z - 0.9), (-4.3, 0.9, z + 0.9))]})
    # an alley gate on the right between two houses' fronts, and ivy climbing a left facade
    groups.append({"grate": [quad((STREET_X - 0.05, 1.4, -24.0), (0, 0, 1.2), (0, 1.25, 0))]})
    groups.append({"ivy": [quad((-STREET_X + 0.03, 2.5 + 0.9 * k, -35.0 - 0.6 * k), (0, 0, 1.2), (0, 1.0, 0))
                           for k in range(6)]})
    # a fountain in a widening at the street's end
    groups.append({"brass": [torus((0.0, 0.5, -70.0), 2.0, 0.12, axis=(0, 1, 0)),
                             cylinder((0.0, 0.0, -70.0), (0.0, 2.2, -70.0), 0.14, seg=16),
                             sphere((0.0, 2.35, -70.0), 0.22)],
                   "kerb": [cylinder((0.0, 0.0, -70.0), (0.0, 0.45, -70.0), 2.0, seg=48)]})
    return combine(groups)


def _tower() -> dict[str, list[Mesh]]:
    """A church tower at the street's end, 260 m away: a shaft, a pyramid roof of four slopes and a thin cross."""
    x, z, w, h = 3.0, -260.0, 6.0, 42.0
    out = {"plaster_grey": [box((x - w / 2, 0, z - w / 2), (x + w / 2, h, z + w / 2))], "roof": [], "iron": []}
    apex = np.array([x, h + 14.0, z])
    corners = [np.array([x + sx * w / 2, h, z + sz * w / 2]) for sx, sz in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    for a, b in zip(corners, corners[1:] + corners[:1]):  # each slope a triangle (a quad with two corners at the apex)
        n = np.cross(b - a, apex - a)
        n /= np.linalg.norm(n)
        if np.dot(n, (a + b) / 2 - [x, h, z]) < 0:
            n = -n
        out["roof"].append(Mesh(np.array([a, b, apex, apex]), np.repeat(n[None], 4, 0),
                                np.array([[0, 0], [w, 0], [w / 2, 14.0], [w / 2, 14.0]]),
                                np.array([0, 1, 2, 0, 2, 3], np.uint32)))
    out["iron"] += [beam(apex, apex + [0, 4.0, 0], 0.15, 0.15), beam(apex + [-1.2, 2.8, 0], apex + [1.2, 2.8, 0],
                                                                     0.15, 0.15)]
    return out


def town_world() -> World:
    groups = combine([_ground(), _houses(), _tram_wires(), _street_furniture(), _tower()])
    return World({k: merge(v) for k, v in groups.items() if v}, MATERIALS, TEXTURES, DRAW_ORDER, LIGHT)
