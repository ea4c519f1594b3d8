"""What a rendered world is made of (yardstick/rendered.py draws them; the plaza there, the town in town.py): meshes in
world space and their primitives, procedural texture helpers, materials, light, and the World that holds them."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from mlaa_stream.yardstick.scenes import srgb8_to_linear


# --- texture helpers: procedural, sRGB8 RGBA ------------------------------------------------------
def value_noise(size: int, cells: int, rng: np.random.Generator) -> np.ndarray:
    """Tileable value noise in [0, 1]: a cells x cells random grid, smoothstep-interpolated."""
    g = rng.random((cells, cells))
    x = np.arange(size) * cells / size
    i = np.floor(x).astype(int)
    f = x - i
    f = f * f * (3 - 2 * f)
    i1 = (i + 1) % cells
    rows = g[:, i] * (1 - f) + g[:, i1] * f  # (cells, size): interpolated along x
    return rows[i] * (1 - f)[:, None] + rows[i1] * f[:, None]


def fbm(size: int, cells: int, octaves: int, rng: np.random.Generator) -> np.ndarray:
    """Fractal sum of value noise octaves, normalised to [0, 1]."""
    out = sum(0.5 ** o * value_noise(size, cells * 2 ** o, rng) for o in range(octaves))
    return (out - out.min()) / max(out.max() - out.min(), 1e-9)


def rgba(rgb: np.ndarray, alpha: np.ndarray | None = None) -> np.ndarray:
    """float sRGB in [0, 1] (H, W, 3) (+ alpha) -> uint8 RGBA."""
    a = np.ones(rgb.shape[:2]) if alpha is None else alpha
    return np.round(np.clip(np.dstack([rgb, a]), 0, 1) * 255).astype(np.uint8)


def tex_metal(rng: np.random.Generator, size: int = 64) -> np.ndarray:
    """Near-white brushed metal; materials tint it."""
    v = 0.85 + 0.1 * value_noise(size, 32, rng)
    return rgba(np.repeat(v[..., None], 3, axis=-1))


def tex_white(rng: np.random.Generator, size: int = 4) -> np.ndarray:
    """Plain white: the colour comes from the material's tint (exactly, 255 decodes to 1.0)."""
    return np.full((size, size, 4), 255, np.uint8)


# --- meshes ---------------------------------------------------------------------------------------
@dataclass
class Mesh:
    """Indexed triangles in world space: positions and normals (N, 3), uv in metres (N, 2)."""

    pos: np.ndarray
    nrm: np.ndarray
    uv: np.ndarray
    idx: np.ndarray

    @property
    def triangles(self) -> int:
        return len(self.idx) // 3


def merge(meshes: list[Mesh]) -> Mesh:
    offsets = np.cumsum([0] + [len(m.pos) for m in meshes[:-1]])
    return Mesh(np.concatenate([m.pos for m in meshes]), np.concatenate([m.nrm for m in meshes]),
                np.concatenate([m.uv for m in meshes]),
                np.concatenate([m.idx + o for m, o in zip(meshes, offsets)]).astype(np.uint32))


def transform(mesh: Mesh, m: np.ndarray) -> Mesh:
    """Apply a 4x4 affine matrix (normals by the inverse transpose)."""
    pos = mesh.pos @ m[:3, :3].T + m[:3, 3]
    nrm = mesh.nrm @ np.linalg.inv(m[:3, :3])
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    return Mesh(pos, nrm, mesh.uv, mesh.idx)


def segment_frame(p0, p1) -> np.ndarray:
    """4x4 matrix taking local z to the segment p0 -> p1 (local origin at p0), unit scale."""
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    z = (p1 - p0) / np.linalg.norm(p1 - p0)
    ref = np.array([0.0, 1.0, 0.0]) if abs(z[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, z)
    x /= np.linalg.norm(x)
    m = np.eye(4)
    m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = x, np.cross(z, x), z, p0
    return m


def hexahedron(c: np.ndarray) -> Mesh:
    """Six flat-shaded quads from 8 corners c[(ix, iy, iz)] given as an (2, 2, 2, 3) array; uv is
    each face's own corner-to-corner lengths in metres."""
    faces = [((0, 0, 0), (0, 1, 0), (0, 1, 1), (0, 0, 1)), ((1, 0, 0), (1, 0, 1), (1, 1, 1), (1, 1, 0)),
             ((0, 0, 0), (0, 0, 1), (1, 0, 1), (1, 0, 0)), ((0, 1, 0), (1, 1, 0), (1, 1, 1), (0, 1, 1)),
             ((0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)), ((0, 0, 1), (0, 1, 1), (1, 1, 1), (1, 0, 1))]
    centre = c.reshape(-1, 3).mean(axis=0)
    pos, nrm, uv, idx = [], [], [], []
    for k, f in enumerate(faces):
        q = np.array([c[i] for i in f])
        n = np.cross(q[1] - q[0], q[3] - q[0])
        n /= max(np.linalg.norm(n), 1e-12)
        if np.dot(n, q.mean(axis=0) - centre) < 0:  # point outwards whatever the corner order
            n = -n
        du, dv = np.linalg.norm(q[3] - q[0]), np.linalg.norm(q[1] - q[0])
        pos.append(q)
        nrm.append(np.repeat(n[None], 4, axis=0))
        uv.append(np.array([[0, 0], [0, dv], [du, dv], [du, 0]]))
        idx += [4 * k + j for j in (0, 1, 2, 0, 2, 3)]
    return Mesh(np.concatenate(pos), np.concatenate(nrm), np.concatenate(uv), np.array(idx, np.uint32))


def box(lo, hi) -> Mesh:
    """Axis-aligned box from corner lo to corner hi."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    g = np.stack(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij"), -1)
    return hexahedron(lo + g * (hi - lo))


def beam(p0, p1, w: float, h: float) -> Mesh:
    """A square-section bar of w x h from p0 to p1 (railings, lattice members, cross-arms)."""
    length = float(np.linalg.norm(np.asarray(p1, float) - np.asarray(p0, float)))
    return transform(box((-w / 2, -h / 2, 0), (w / 2, h / 2, length)), segment_frame(p0, p1))


def cylinder(p0, p1, r: float, seg: int = 12, caps: bool = True) -> Mesh:
    """A smooth-shaded cylinder from p0 to p1; uv = (arc length, length) in metres."""
    length = float(np.linalg.norm(np.asarray(p1, float) - np.asarray(p0, float)))
    t = np.linspace(0, 2 * np.pi, seg + 1)
    ring = np.stack([np.cos(t), np.sin(t), np.zeros_like(t)], -1)
    pos = np.concatenate([ring * r, ring * r + [0, 0, length]])
    nrm = np.concatenate([ring, ring])
    uv = np.concatenate([np.stack([t * r, np.zeros_like(t)], -1), np.stack([t * r, np.full_like(t, length)], -1)])
    n = seg + 1
    idx = [[i, i + 1, n + i + 1, i, n + i + 1, n + i] for i in range(seg)]
    parts = [Mesh(pos, nrm, uv, np.array(idx, np.uint32).ravel())]
    if caps:
        for z, s in ((0.0, -1.0), (length, 1.0)):
            cp = np.concatenate([[[0, 0, z]], ring[:-1] * r + [0, 0, z]])
            cn = np.repeat([[0, 0, s]], seg + 1, axis=0)
            ci = np.array([[0, 1 + i, 1 + (i + 1) % seg] for i in range(seg)], np.uint32).ravel()
            parts.append(Mesh(cp, cn, cp[:, :2].copy(), ci))
    return transform(merge(parts), segment_frame(p0, p1))


def sphere(c, r: float, nu: int = 32, nv: int = 16) -> Mesh:
    u = np.linspace(0, 2 * np.pi, nu + 1)
    v = np.linspace(0, np.pi, nv + 1)
    uu, vv = np.meshgrid(u, v)
    n = np.stack([np.sin(vv) * np.cos(uu), np.cos(vv), np.sin(vv) * np.sin(uu)], -1).reshape(-1, 3)
    uv = np.stack([uu * r, vv * r], -1).reshape(-1, 2)
    return Mesh(np.asarray(c, float) + r * n, n, uv, grid_indices(nu, nv))


def torus(c, big_r: float, r: float, axis=(0, 0, 1), nu: int = 40, nv: int = 14) -> Mesh:
    """A torus around `axis` through c: ring radius big_r, tube radius r."""
    u = np.linspace(0, 2 * np.pi, nu + 1)
    v = np.linspace(0, 2 * np.pi, nv + 1)
    uu, vv = np.meshgrid(u, v)
    ring = np.stack([np.cos(uu), np.sin(uu), np.zeros_like(uu)], -1)
    n = ring * np.cos(vv)[..., None] + np.array([0, 0, 1.0]) * np.sin(vv)[..., None]
    pos = big_r * ring + r * n
    uv = np.stack([uu * big_r, vv * r], -1)
    local = Mesh(pos.reshape(-1, 3), n.reshape(-1, 3), uv.reshape(-1, 2), grid_indices(nu, nv))
    c = np.asarray(c, float)
    return transform(local, segment_frame(c, c + np.asarray(axis, float)))


def grid_indices(nu: int, nv: int) -> np.ndarray:
    """Two triangles per cell of an (nv + 1) x (nu + 1) vertex grid."""
    j, i = np.mgrid[0:nv, 0:nu]
    a = (j * (nu + 1) + i).ravel()
    return np.stack([a, a + 1, a + nu + 2, a, a + nu + 2, a + nu + 1], -1).ravel().astype(np.uint32)


def quad(centre, u_half, v_half) -> Mesh:
    """A flat quad centre +- u_half +- v_half; uv in metres from its (-u, -v) corner."""
    c, u, v = (np.asarray(a, float) for a in (centre, u_half, v_half))
    pos = np.array([c - u - v, c + u - v, c + u + v, c - u + v])
    n = np.cross(u, v)
    n /= np.linalg.norm(n)
    lu, lv = 2 * np.linalg.norm(u), 2 * np.linalg.norm(v)
    uv = np.array([[0, 0], [lu, 0], [lu, lv], [0, lv]])
    return Mesh(pos, np.repeat(n[None], 4, axis=0), uv, np.array([0, 1, 2, 0, 2, 3], np.uint32))


def linear_tint(srgb8) -> tuple:
    """sRGB8 triple -> linear tint (exact decode: a white texture times it gives that colour)."""
    return tuple(float(x) for x in srgb8_to_linear(np.asarray(srgb8, np.uint8)))


@dataclass(frozen=True)
class Material:
    texture: str
    tile: tuple = (2.0, 2.0)  # metres per texture repeat along u and v
    tint: tuple = (1.0, 1.0, 1.0)  # linear multiplier of the texture colour
    specular: float = 0.04  # Blinn-Phong weight (energy-normalised lobe)
    shininess: float = 16.0
    alpha_test: bool = False  # discard where texture alpha < 0.5
    two_sided: bool = False  # light the back face with the flipped normal (cards, fences)
    emissive: bool = False  # unlit and unfogged: outputs texture * tint


def sag(p0, p1, depth: float, n: int) -> np.ndarray:
    """n + 1 points of a hanging cable from p0 to p1 (a parabola: close to a catenary at small sag)."""
    s = np.linspace(0, 1, n + 1)[:, None]
    pts = np.asarray(p0, float) * (1 - s) + np.asarray(p1, float) * s
    pts[:, 1] -= 4 * depth * s[:, 0] * (1 - s[:, 0])
    return pts


def cable(points: np.ndarray, r: float) -> list[Mesh]:
    """A cable as thin 4-sided cylinders along a polyline (sub-pixel beyond a few metres)."""
    return [cylinder(a, b, r, seg=4, caps=False) for a, b in zip(points[:-1], points[1:])]


def combine(groups) -> dict[str, list[Mesh]]:
    out: dict[str, list[Mesh]] = {}
    for g in groups:
        for k, v in g.items():
            out.setdefault(k, []).extend(v)
    return out


@dataclass(frozen=True)
class Lighting:
    """A world's sun, sky and fog (all linear light)."""

    sun_dir: tuple  # towards the sun (normalised in the shader setup)
    sun: tuple  # radiance of the sun
    sky_zenith: tuple
    sky_horizon: tuple  # also the fog's colour
    ambient_sky: tuple  # hemisphere light from above ...
    ambient_ground: tuple  # ... and from below
    fog_density: float  # per metre


@dataclass(frozen=True)
class World:
    """What a Renderer draws: material name -> one merged mesh, the materials, the textures they read (name ->
    (maker, alpha-tested)), the draw order (small and near things first, alpha-tested cards last: llvmpipe's
    early depth test then skips shading the occluded parts of big surfaces) and the light."""

    meshes: dict
    materials: dict
    textures: dict
    draw_order: tuple
    light: Lighting


