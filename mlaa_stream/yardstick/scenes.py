"""Test scenes with supersampled truth: the yardstick every method is measured against.

Each scene is drawn twice from the same geometry: one sample per pixel at the pixel centre (the
aliased input) and 8x8 samples per pixel averaged in linear light (the truth). Geometry is filled
polygons (nonzero winding, tested at the sample positions by a vectorised scanline) and textures
evaluated at the sample positions, so a whole set renders in seconds with numpy alone.

    scenes = generate_scenes(small=True)        # list[Scene]
    frame = timing_frame()                      # a 1920x1080 input for speed measurements
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Callable, Union

import numpy as np

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear

TRUTH_SPP = 8  # samples per pixel side of the truth: 8x8 = 64 per pixel (the issue asks >= 8x8)
EDGE_LEVELS = 3  # an "edge pixel" differs from the truth by more than this, in 8-bit levels
WIRE_LEVELS = 12  # a "wire pixel" differs from the wire-less background by at least this in the truth
BAND_SAMPLES = 2_000_000  # samples rendered at once (bounds memory to ~40 MB whatever the scene size)

# A colour is an sRGB 8-bit triple, or a texture: f(x, y) -> linear RGB (..., 3) at sample positions.
Texture = Callable[[np.ndarray, np.ndarray], np.ndarray]
Colour = Union[tuple, Texture]


@dataclass(frozen=True)
class Layer:
    """Paint `colour` where the polygons cover (nonzero winding); polygons None paints everything."""

    polygons: tuple | None
    colour: Colour


@dataclass
class Scene:
    """One scene: T frames of input and truth (uint8 RGB) with the masks the metrics need."""

    name: str
    category: str
    inputs: np.ndarray  # (T, H, W, 3) uint8, one sample per pixel
    truths: np.ndarray  # (T, H, W, 3) uint8, 8x8 samples resolved in linear light
    edges: np.ndarray  # (T, H, W) bool: input differs from truth by more than EDGE_LEVELS
    wires: np.ndarray | None = None  # (T, H, W) bool: pixels of thin features
    backgrounds: np.ndarray | None = None  # (T, H, W, 3) truth without the thin features
    sharp: np.ndarray | None = None  # (T, H, W) bool: pixel-aligned details that must stay exact
    notes: str = ""

    @property
    def frames(self) -> int:
        return int(self.inputs.shape[0])

    @property
    def animated(self) -> bool:
        return self.frames > 1

    @property
    def size(self) -> tuple[int, int]:
        """(width, height)."""
        return int(self.inputs.shape[2]), int(self.inputs.shape[1])


# --- colours --------------------------------------------------------------------------------------
def _linear(c: tuple) -> np.ndarray:
    return srgb_to_linear(np.asarray(c, dtype=np.float64) / 255.0).astype(np.float32)


_SRGB8_TO_LINEAR = srgb_to_linear(np.arange(256) / 255.0).astype(np.float32)


def srgb8_to_linear(v: np.ndarray) -> np.ndarray:
    """Exact decode of 8-bit sRGB codes by table (textures store 8-bit colours)."""
    return _SRGB8_TO_LINEAR[np.asarray(v, dtype=np.uint8)]


def encode8(lin: np.ndarray) -> np.ndarray:
    """Linear light -> 8-bit sRGB codes, rounded."""
    return np.round(linear_to_srgb(lin) * 255.0).astype(np.uint8)


# --- the rasteriser -------------------------------------------------------------------------------
def coverage(polygons, spp: int, row0: int, rows: int, col0: int, cols: int) -> np.ndarray:
    """Nonzero-winding inside test at the sample grid of the pixel window rows x cols at
    (row0, col0).

    Samples sit at (col0 + (i + 0.5) / spp, row0 + (j + 0.5) / spp). Each polygon edge adds its
    winding direction (+1 down, -1 up) at the first sample right of its crossing with each sample
    row, half-open in y; a cumulative sum along the row gives every sample's winding number.
    Returns bool (rows * spp, cols * spp).
    """
    s, R, C = spp, rows * spp, cols * spp
    pts = [np.asarray(p, dtype=np.float64).reshape(-1, 2) for p in polygons]
    pts = [p for p in pts if len(p) >= 3]
    if not pts:
        return np.zeros((R, C), bool)
    a = np.concatenate(pts)
    b = np.concatenate([np.roll(p, -1, axis=0) for p in pts])
    keep = a[:, 1] != b[:, 1]
    a, b = a[keep], b[keep]
    ylo, yhi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    j0 = np.clip(np.ceil((ylo - row0) * s - 0.5), 0, R).astype(np.int64)
    j1 = np.clip(np.ceil((yhi - row0) * s - 0.5), 0, R).astype(np.int64)
    n = j1 - j0
    total = int(n.sum())
    if total == 0:
        return np.zeros((R, C), bool)
    e = np.repeat(np.arange(len(n)), n)
    first = np.cumsum(n) - n
    j = j0[e] + (np.arange(total) - first[e])
    y = row0 + (j + 0.5) / s
    ax, ay, bx, by = a[e, 0], a[e, 1], b[e, 0], b[e, 1]
    xc = ax + (y - ay) * (bx - ax) / (by - ay)
    i = np.clip(np.ceil((xc - col0) * s - 0.5), 0, C).astype(np.int64)
    d = np.where(by > ay, 1.0, -1.0)
    acc = np.bincount(j * (C + 1) + i, weights=d, minlength=R * (C + 1)).reshape(R, C + 1)
    return np.cumsum(acc[:, :C].astype(np.int16), axis=1, dtype=np.int16) != 0


def _bbox(polygons) -> tuple[float, float, float, float]:
    allp = np.concatenate([np.asarray(p, float).reshape(-1, 2) for p in polygons])
    return allp[:, 0].min(), allp[:, 1].min(), allp[:, 0].max(), allp[:, 1].max()


def render(layers: list[Layer], width: int, height: int, spp: int) -> np.ndarray:
    """Paint the layers in order at spp x spp samples per pixel; returns the per-pixel mean in
    linear light, float32 (height, width, 3). spp=1 samples the pixel centre only.

    Each sample keeps the index of the last layer covering it (one byte), which then looks up its
    flat colour or, for textures, is evaluated at the sample's position.
    """
    n_layers = len(layers)
    if n_layers > 254:
        raise ValueError(f"expected at most 254 layers, got {n_layers}")
    flat = np.zeros((n_layers + 1, 3), np.float32)  # row n_layers: nothing painted (black)
    for k, layer in enumerate(layers):
        if not callable(layer.colour):
            flat[k] = _linear(layer.colour)
    boxes = [None if la.polygons is None else _bbox(la.polygons) for la in layers]
    out = np.empty((height, width, 3), np.float32)
    band = max(1, BAND_SAMPLES // (width * spp * spp))
    xs = (np.arange(width * spp) + 0.5) / spp
    s2 = spp * spp
    for row0 in range(0, height, band):
        rows = min(band, height - row0)
        ys = row0 + (np.arange(rows * spp) + 0.5) / spp
        ids = np.full((rows * spp, width * spp), n_layers, np.uint8)
        for k, (layer, box) in enumerate(zip(layers, boxes)):
            if box is None:
                ids[...] = k
                continue
            r0 = max(row0, int(np.floor(box[1])))
            r1 = min(row0 + rows, int(np.ceil(box[3])) + 1)
            c0 = max(0, int(np.floor(box[0])))
            c1 = min(width, int(np.ceil(box[2])) + 1)
            if r1 <= r0 or c1 <= c0:
                continue
            mask = coverage(layer.polygons, spp, r0, r1 - r0, c0, c1 - c0)
            win = ids[(r0 - row0) * spp:(r1 - row0) * spp, c0 * spp:c1 * spp]
            win[mask] = k
        val = flat[ids]
        for k, layer in enumerate(layers):
            if callable(layer.colour):
                jj, ii = np.nonzero(ids == k)
                if len(jj):
                    val[jj, ii] = layer.colour(xs[ii], ys[jj])
        # mean over each pixel's spp x spp block: first down the sub-rows, then across.
        acc = val.reshape(rows, spp, width * spp * 3).sum(axis=1, dtype=np.float64)
        acc = acc.reshape(rows, width, spp, 3).sum(axis=2)
        out[row0:row0 + rows] = (acc / s2).reshape(rows, width, 3)
    return out


def render_pair(layers: list[Layer], width: int, height: int,
                spp: int = TRUTH_SPP) -> tuple[np.ndarray, np.ndarray]:
    """(input, truth) as uint8 sRGB: 1 sample at the pixel centre, and spp x spp in linear light."""
    return encode8(render(layers, width, height, 1)), encode8(render(layers, width, height, spp))


def edge_mask(inp: np.ndarray, truth: np.ndarray, levels: int = EDGE_LEVELS) -> np.ndarray:
    """Pixels where the input differs from the truth by more than `levels` in any channel."""
    return np.abs(inp.astype(np.int16) - truth.astype(np.int16)).max(axis=-1) > levels


# --- geometry helpers -----------------------------------------------------------------------------
def rect(x0: float, y0: float, x1: float, y1: float) -> np.ndarray:
    return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]], float)


def rotated_rect(cx: float, cy: float, w: float, h: float, degrees: float) -> np.ndarray:
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    local = np.array([[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]])
    return local @ np.array([[c, s], [-s, c]]) + [cx, cy]


def ellipse(cx: float, cy: float, rx: float, ry: float, n: int = 256) -> np.ndarray:
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.stack([cx + rx * np.cos(t), cy + ry * np.sin(t)], -1)


def stroke(points: np.ndarray, width: float) -> np.ndarray:
    """The outline polygon of a polyline drawn `width` wide (butt ends); fine for gentle curves."""
    p = np.asarray(points, float)
    d = np.gradient(p, axis=0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    nrm = np.stack([-d[:, 1], d[:, 0]], -1) * (width / 2)
    return np.concatenate([p + nrm, (p - nrm)[::-1]])


def translate(polys, dx: float, dy: float) -> tuple:
    return tuple(np.asarray(p, float) + [dx, dy] for p in polys)


@lru_cache(maxsize=None)
def _font():
    from pathlib import Path

    import matplotlib
    from matplotlib.font_manager import FontProperties
    # DejaVu Sans ships inside matplotlib: the same glyphs on every machine.
    return FontProperties(fname=str(Path(matplotlib.get_data_path()) / "fonts/ttf/DejaVuSans.ttf"))


def text_polygons(text: str, x: float, y: float, size: float) -> tuple:
    """Glyph outlines of `text` (DejaVu Sans, `size` px em) with the baseline starting at (x, y),
    Beziers flattened finely (8 segments each) so the 8x8 truth sees the real curve."""
    from matplotlib.path import Path
    from matplotlib.textpath import TextPath

    path = TextPath((0, 0), text, size=size, prop=_font())
    polys: list[list] = []
    for bez, code in path.iter_bezier():
        cp = bez.control_points
        if code == Path.MOVETO:
            polys.append([cp[0]])
        elif code == Path.LINETO or code == Path.CLOSEPOLY:
            polys[-1].append(cp[-1])
        else:
            polys[-1].extend(bez(np.linspace(0, 1, 9)[1:]))
    out = []
    for p in polys:
        a = np.asarray(p, float)
        if len(a) >= 3:
            out.append(np.stack([x + a[:, 0], y - a[:, 1]], -1))  # font y is up, image y is down
    return tuple(out)


# --- textures -------------------------------------------------------------------------------------
def photo_texture(x0: int, y0: int, crop: tuple[int, int, int, int]) -> tuple[Texture, np.ndarray]:
    """matplotlib's grace_hopper.jpg crop (left, top, width, height) placed with its top-left
    pixel at integer (x0, y0), nearest texel: every sample of a pixel sees the same texel, so the
    truth equals the input there. Returns (texture, rectangle polygon)."""
    import matplotlib.image
    from matplotlib import cbook

    img = matplotlib.image.imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))
    cl, ct, cw, ch = crop
    tex = srgb8_to_linear(np.ascontiguousarray(img[ct:ct + ch, cl:cl + cw, :3]))

    def texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        i = np.clip(np.floor(x - x0).astype(np.int64), 0, cw - 1)
        j = np.clip(np.floor(y - y0).astype(np.int64), 0, ch - 1)
        return tex[j, i]

    return texture, rect(x0, y0, x0 + cw, y0 + ch)


def checker_texture(width: int, horizon: float, square: float = 0.5,
                    degrees: float = 20.0, far: float = 80.0,
                    colours=((236, 236, 236), (28, 28, 36))) -> Texture:
    """A checkerboard ground plane seen in perspective (pinhole camera one unit above it, focal
    length = width px): fine towards the horizon, where point sampling makes moire. Beyond `far`
    the plane fades to its mean colour (haze), above the horizon the sky is that colour too."""
    c0, c1 = _linear(colours[0]), _linear(colours[1])
    haze = (c0 + c1) / 2
    ca, sa = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))

    def texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        dy = y - horizon
        z = np.minimum(width / np.maximum(dy, 1e-9), 2 * far)  # the sky is haze anyway
        u = (x - width / 2) * z / width
        uu, vv = u * ca - z * sa, u * sa + z * ca
        odd = ((np.floor(uu / square) + np.floor(vv / square)) % 2) == 1
        col = np.where(odd[..., None], c1, c0)
        return np.where((z < far)[..., None], col, haze).astype(np.float32)

    return texture


def noise_texture(rng: np.random.Generator, texel: float, degrees: float, split_x: float) -> Texture:
    """Left of split_x: value noise with texels smaller than a pixel, rotated (aliases at 1 spp);
    right: one random colour per pixel (input equals truth). Both confuse edge detectors."""
    table = rng.integers(0, 256, size=(512, 512, 3), dtype=np.uint8)
    grain = rng.integers(40, 216, size=(1024, 1024, 3), dtype=np.uint8)
    ca, sa = np.cos(np.radians(degrees)), np.sin(np.radians(degrees))

    def texture(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        u = np.floor((x * ca - y * sa) / texel).astype(np.int64) % 512
        v = np.floor((x * sa + y * ca) / texel).astype(np.int64) % 512
        sub = srgb8_to_linear(table[v, u])
        pix = srgb8_to_linear(grain[np.floor(y).astype(np.int64) % 1024, np.floor(x).astype(np.int64) % 1024])
        return np.where((x < split_x)[..., None], sub, pix)

    return texture


# --- scene assembly -------------------------------------------------------------------------------
def build_scene(name: str, category: str, frames: list[list[Layer]], width: int, height: int,
                thin: list[list[Layer]] | None = None, sharp: np.ndarray | None = None,
                notes: str = "") -> Scene:
    """Render each frame's layers (plus optional thin-feature layers on top) into a Scene."""
    ins, truths, bgs, wires = [], [], [], []
    for t, layers in enumerate(frames):
        top = thin[t] if thin else []
        i, tr = render_pair(layers + top, width, height)
        ins.append(i)
        truths.append(tr)
        if thin:
            bg = encode8(render(layers, width, height, TRUTH_SPP))
            bgs.append(bg)
            wires.append(np.abs(tr.astype(np.int16) - bg).max(axis=-1) >= WIRE_LEVELS)
    inputs, truth = np.stack(ins), np.stack(truths)
    sharp_t = None if sharp is None else np.broadcast_to(sharp, inputs.shape[:3]).copy()
    return Scene(name, category, inputs, truth, edge_mask(inputs, truth),
                 np.stack(wires) if thin else None, np.stack(bgs) if thin else None, sharp_t, notes)


PAIRS = [  # colour pairs for edges: high contrast, colour, and low-contrast ones
    ((24, 24, 28), (232, 232, 226)),
    ((200, 48, 40), (40, 150, 70)),
    ((118, 118, 118), (136, 136, 136)),
    ((60, 80, 190), (80, 100, 160)),
    ((250, 250, 250), (245, 225, 90)),
    ((30, 60, 40), (200, 210, 230)),
]


def _long_edge_layers(width: int, height: int, slopes, vertical: bool, dx: float = 0.0,
                      dy: float = 0.0) -> list[Layer]:
    """Horizontal strips, each with one edge of slope 1/L across it (steps L px long)."""
    n = len(slopes)
    h = height // n
    layers = []
    for k, L in enumerate(slopes):
        a, b = PAIRS[k % len(PAIRS)]
        y0 = k * h
        yc = y0 + h / 2 - (width / L) / 2 + 0.37 + dy
        top = [[-1, yc + (-1 - dx) / L], [width + 1, yc + (width + 1 - dx) / L]]
        if k % 2:  # falling edges too
            top = [[-1, yc + (width + 1 + dx) / L], [width + 1, yc + (-1 + dx) / L]]
        poly = np.array(top + [[width + 1, y0 + h], [-1, y0 + h]], float)
        layers += [Layer((rect(-1, y0, width + 1, y0 + h),), a), Layer((poly,), b)]
    if vertical:
        layers = [Layer(tuple(p[:, ::-1] for p in lay.polygons), lay.colour) for lay in layers]
    return layers


def scene_long_edges(rng: np.random.Generator, small: bool) -> list[Scene]:
    slopes = [260, 300, 400, 520] if not small else [280, 300]
    w, h = (1040, 192) if not small else (600, 48)
    out = [build_scene("long_edges_h", "long_edges", [_long_edge_layers(w, h, slopes, False)], w, h,
                       notes=f"near-horizontal edges, steps {min(slopes)}-{max(slopes)} px")]
    if not small:
        out.append(build_scene("long_edges_v", "long_edges",
                               [_long_edge_layers(w, h, slopes[::-1], True)], h, w,
                               notes=f"near-vertical edges, steps {min(slopes)}-{max(slopes)} px"))
    return out


def _diagonal_layers(cell: int, cols: int, angles, dx: float = 0.0, dy: float = 0.0) -> list[Layer]:
    layers = []
    for k, ang in enumerate(angles):
        a, b = PAIRS[k % len(PAIRS)]
        cx, cy = (k % cols) * cell, (k // cols) * cell
        layers.append(Layer((rect(cx, cy, cx + cell, cy + cell),), a))
        layers.append(Layer((rotated_rect(cx + cell / 2 + 0.31 + dx, cy + cell / 2 + 0.17 + dy,
                                          cell * 0.62, cell * 0.5, ang),), b))
    return layers


def scene_diagonals(rng: np.random.Generator, small: bool) -> list[Scene]:
    cell = 128 if not small else 64
    angles = [30, 45, 60, -30, -45, -60]
    if small:
        angles = angles[:3]
    cols = 3
    rows = (len(angles) + cols - 1) // cols
    return [build_scene("diagonals", "diagonals", [_diagonal_layers(cell, cols, angles)],
                        cols * cell, rows * cell, notes=f"30/45/60 degree polygons, {len(angles)} colour pairs")]


def scene_wires(rng: np.random.Generator, small: bool) -> list[Scene]:
    w, h = (384, 256) if not small else (160, 96)
    bg = [Layer(None, (228, 226, 218))]
    thin = []
    widths = [0.3, 0.5, 0.75, 1.0, 1.25, 1.5]
    angles = [2.0, 7.0, 18.0, 33.0, 48.0, 63.0, 80.0, 88.5]
    inks = [(24, 24, 32), (150, 30, 30), (30, 70, 150)]
    n_straight = 8 if not small else 4
    for k in range(n_straight):
        wd = widths[k % len(widths)]
        ang = np.radians(angles[k % len(angles)])
        cx, cy = rng.uniform(0.3, 0.7) * w, rng.uniform(0.3, 0.7) * h
        L = 0.45 * min(w, h) / max(abs(np.sin(ang)), 0.3) if ang > 0.05 else 0.45 * w
        d = np.array([np.cos(ang), np.sin(ang)]) * L
        pts = np.array([[cx, cy] - d, [cx, cy] + d])
        thin.append(Layer((stroke(pts, wd),), inks[k % len(inks)]))
    n_curved = 4 if not small else 2
    for k in range(n_curved):
        wd = widths[(k * 2 + 1) % len(widths)]
        t = np.linspace(0.05, 0.95, int(w * 2))
        amp, per = rng.uniform(0.08, 0.2) * h, rng.uniform(0.6, 1.4) * w
        x = t * w
        y = (k + 0.5) * h / n_curved + amp * np.sin(2 * np.pi * x / per + rng.uniform(0, 6))
        thin.append(Layer((stroke(np.stack([x, y], -1), wd),), inks[(k + 1) % len(inks)]))
    return [build_scene("wires", "wires", [bg], w, h, thin=[thin],
                        notes="straight and curved wires 0.3-1.5 px wide")]


TEXTS = ["The quick brown fox 0123", "Settings", "Cancel", "OK", "jumps over 4567",
         "lazy dogs & wires", "File Edit View", "Il1| mnw @%"]


def _ui_layers(w: int, h: int, rng: np.random.Generator, small: bool, dx: float = 0.0,
               dy: float = 0.0) -> tuple[list[Layer], np.ndarray]:
    """UI boxes with 1-px borders on integer pixels (sharp corners) and small text inside."""
    layers = [Layer(None, (238, 238, 234))]
    sharp = np.zeros((h, w), bool)
    sizes = [6, 7, 8, 9, 10, 12, 14, 16, 20] if not small else [7, 10, 14, 20]
    y = 4
    k = 0
    while k < len(sizes) and y + sizes[k] * 1.6 + 6 < h:
        s = sizes[k]
        bh = int(np.ceil(s * 1.5)) + 4
        bw = min(w - 8, int(s * 11) + 8)
        x0, y0 = 4 + (k % 2) * 6, y
        border, fill, ink = ((60, 60, 70), (250, 250, 250), (20, 20, 24)) if k % 3 else \
            ((20, 40, 120), (40, 70, 160), (250, 250, 250))
        layers.append(Layer((rect(x0, y0, x0 + bw, y0 + bh),), border))
        layers.append(Layer((rect(x0 + 1, y0 + 1, x0 + bw - 1, y0 + bh - 1),), fill))
        sharp[y0:y0 + bh, x0:x0 + bw] = True
        sharp[y0 + 1:y0 + bh - 1, x0 + 1:x0 + bw - 1] = False
        text = TEXTS[k % len(TEXTS)]
        base = y0 + 2 + s * 1.05 + rng.uniform(0, 1) + dy
        layers.append(Layer(text_polygons(text, x0 + 3 + rng.uniform(0, 1) + dx, base, s), ink))
        y += bh + 3
        k += 1
    return layers, sharp


def scene_text(rng: np.random.Generator, small: bool) -> list[Scene]:
    w, h = (256, 224) if not small else (160, 96)
    layers, sharp = _ui_layers(w, h, rng, small)
    return [build_scene("text_ui", "text_ui", [layers], w, h, sharp=sharp,
                        notes="DejaVu Sans 6-20 px in UI boxes with 1-px borders")]


def scene_photo(rng: np.random.Generator, small: bool) -> list[Scene]:
    w, h = (320, 288) if not small else (128, 112)
    cw, ch = (256, 224) if not small else (96, 80)
    ox = oy = 32 if not small else 16
    tex, box = photo_texture(ox, oy, (140, 120, cw, ch) if not small else (200, 150, cw, ch))
    layers = [Layer(None, (70, 90, 110)),
              Layer((rotated_rect(w * 0.5 + 0.3, h * 0.5 + 0.2, w * 1.1, h * 0.55, 33),), (180, 160, 120)),
              Layer((rect(ox - 3, oy - 3, ox + cw + 3, oy + ch + 3),), (250, 250, 250)),
              Layer((box,), tex)]
    return [build_scene("photo", "photo", [layers], w, h,
                        notes="grace_hopper.jpg crop, pixel-aligned: must come out untouched")]


def scene_checker(rng: np.random.Generator, small: bool) -> list[Scene]:
    w, h = (384, 256) if not small else (160, 112)
    tex = checker_texture(w, h * 0.22, square=0.5, degrees=20.0)
    return [build_scene("checkerboard", "checkerboard", [[Layer(None, tex)]], w, h,
                        notes="perspective checkerboard: moire near the horizon")]


def scene_noise(rng: np.random.Generator, small: bool) -> list[Scene]:
    w, h = (256, 192) if not small else (128, 64)
    tex = noise_texture(rng, texel=0.7, degrees=17.0, split_x=w / 2)
    return [build_scene("noise", "noise", [[Layer(None, tex)]], w, h,
                        notes="left: 0.7-px value noise (aliases); right: per-pixel grain (exact)")]


def scene_rotation(rng: np.random.Generator, small: bool) -> list[Scene]:
    n, size = (6, 192) if not small else (4, 96)
    frames, thin = [], []
    for t in range(n):
        ang = 10.0 + 0.8 * t
        c = size / 2 + 0.21
        frames.append([Layer(None, (235, 230, 220)),
                       Layer((rotated_rect(c, c, size * 0.55, size * 0.55, ang),), (40, 60, 120))])
        thin.append([Layer((rotated_rect(c, c, size * 0.85, 0.8, ang + 45),), (20, 20, 20))])
    return [build_scene("rotation", "rotation", frames, size, size, thin=thin,
                        notes="square and a 0.8-px bar turning 0.8 degrees per frame")]


def scene_pan(rng: np.random.Generator, small: bool) -> list[Scene]:
    n = 6 if not small else 4
    w, h = (600, 160) if not small else (320, 64)
    frames = []
    text = text_polygons("Sub-pixel pan 0123", 20.0, h - 12.0, 14 if not small else 10)
    for t in range(n):
        dx, dy = 0.35 * t, 0.15 * t
        layers = _long_edge_layers(w, h // 2, [290, 310], False, dx=dx, dy=dy)
        layers += [Layer((rect(-1, h // 2, w + 1, h + 1),), (240, 240, 236)),
                   Layer((np.array([[w * 0.6, h], [w * 0.6 + h / 2, h / 2 + 4], [w * 0.6 + h, h]]) + [dx, dy],),
                         (120, 40, 40)),
                   Layer(translate(text, dx, dy), (20, 20, 24))]
        frames.append(layers)
    return [build_scene("pan", "pan", frames, w, h, notes="long edges, a triangle and text panning "
                        "(0.35, 0.15) px per frame")]


def scene_mover(rng: np.random.Generator, small: bool) -> list[Scene]:
    n = 6 if not small else 4
    w, h = (256, 160) if not small else (128, 80)
    stripes = tuple(rotated_rect(x, h / 2, 5.0, h * 1.5, 8.0) for x in np.arange(-20, w + 20, 14.0))
    frames = []
    for t in range(n):
        x = 10.3 + (w * 0.12) * t
        frames.append([Layer(None, (210, 220, 200)), Layer(stripes, (90, 110, 80)),
                       Layer((rotated_rect(x + h * 0.15, h * 0.5 + 0.4, h * 0.3, h * 0.3, 22.0),), (200, 40, 30))])
    return [build_scene("mover", "mover", frames, w, h,
                        notes="a box moving 12% of the width per frame over slanted stripes (disocclusion)")]


def scene_cut(rng: np.random.Generator, small: bool) -> list[Scene]:
    n = 6 if not small else 4
    cell = 96 if not small else 48
    w, h = 3 * cell, 2 * cell
    frames = []
    for t in range(n):
        if t < n // 2:
            frames.append(_diagonal_layers(cell, 3, [30, 45, 60, -30, -45, -60], dx=0.25 * t))
        else:
            frames.append([Layer(None, (20, 30, 40)),
                           Layer((ellipse(w / 2 + 0.3 * t, h / 2, w * 0.35, h * 0.3),), (230, 200, 80)),
                           Layer((rotated_rect(w / 2, h / 2 + 0.25 * t, w * 0.5, 3.0, 12.0),), (20, 30, 40))])
    return [build_scene("cut", "cut", frames, w, h, notes=f"hard cut after frame {n // 2 - 1}")]


def scene_antialiased(rng: np.random.Generator, small: bool) -> list[Scene]:
    """Content that is already antialiased (rendered at 8x8 samples per pixel, as an antialiasing renderer,
    font rasteriser or downscale delivers it): UI text, thin wires, polygons. Input = truth, so a filter can
    only damage it: the category is scored on damage (RMSE of the change) alone."""
    out = []
    for make in (scene_text, scene_wires, scene_diagonals):
        for sc in make(rng, small):
            t = sc.truths
            out.append(Scene(f"{sc.name}_aa", "antialiased", t.copy(), t.copy(), np.zeros(t.shape[:3], bool),
                             None, None, None, f"{sc.notes}, already antialiased: must come out untouched"))
    return out


COMPRESSED_QUALITY = 85  # JPEG quality of the compressed group: a screen recording's or a web video's level


def through_jpeg(frames: np.ndarray, quality: int) -> np.ndarray:
    """(T, H, W, 3) uint8 RGB -> each frame after JPEG at `quality` (OpenCV's encoder, 4:2:0) and back."""
    import cv2

    return np.stack([cv2.imdecode(cv2.imencode(".jpg", f[..., ::-1], [cv2.IMWRITE_JPEG_QUALITY, int(quality)])[1],
                                  cv2.IMREAD_COLOR)[..., ::-1] for f in frames])


def scene_compressed(rng: np.random.Generator, small: bool) -> list[Scene]:
    """Aliased flat-colour art (the text_ui and checkerboard scenes) through a lossy codec (JPEG at
    COMPRESSED_QUALITY, cv2): screen recordings and video of UI. The codec's ringing gives flat-colour windows
    many colours, so tests for "busy, rendered-like content" must not take it for a render. Truth: the clean
    8x8-spp truth."""
    out = []
    for make in (scene_text, scene_checker):
        for sc in make(rng, small):
            ins = through_jpeg(sc.inputs, COMPRESSED_QUALITY)
            out.append(Scene(f"{sc.name}_jpeg", "compressed", ins, sc.truths, edge_mask(ins, sc.truths),
                             None, None, None, f"{sc.notes}, through JPEG q{COMPRESSED_QUALITY}"))
    return out


class SceneUnavailable(RuntimeError):
    """A scene group needs a part this machine lacks (the rendered group: an EGL context)."""


def scene_rendered(rng: np.random.Generator, small: bool) -> list[Scene]:
    """Frames of a real 3D rasterizer (yardstick/rendered.py): textured, lit, alpha-tested, thin geometry
    far away; stills and camera shots. Cached on disk after the first render: a machine without EGL reads the
    cache (SceneUnavailable only where a scene must be rendered)."""
    from mlaa_stream.yardstick.rendered import generate_rendered

    return generate_rendered(small=small)


SCENES: dict[str, Callable[[np.random.Generator, bool], list[Scene]]] = {
    "long_edges": scene_long_edges,
    "diagonals": scene_diagonals,
    "wires": scene_wires,
    "text_ui": scene_text,
    "photo": scene_photo,
    "antialiased": scene_antialiased,
    "checkerboard": scene_checker,
    "noise": scene_noise,
    "rotation": scene_rotation,
    "pan": scene_pan,
    "mover": scene_mover,
    "cut": scene_cut,
    "rendered": scene_rendered,
    "compressed": scene_compressed,  # last: a group's seed is its place in this dict
}
CATEGORIES = list(SCENES)


def generate_scenes(small: bool = False, seed: int = 0, names: list[str] | None = None,
                    warn: Callable[[str], None] | None = None) -> list[Scene]:
    """Render the scene set (or the named groups of it); same seed, same pixels. Without `names`, a
    group this machine cannot render (SceneUnavailable) is left out and `warn` says why; a group asked
    for by name raises instead."""
    asked = names is not None
    names = list(SCENES) if names is None else list(names)
    unknown = [n for n in names if n not in SCENES]
    if unknown:
        raise ValueError(f"expected scene names from {', '.join(SCENES)}, got {', '.join(unknown)}")
    out: list[Scene] = []
    for name in names:
        rng = np.random.default_rng([seed, list(SCENES).index(name)])
        try:
            out.extend(SCENES[name](rng, small))
        except SceneUnavailable as exc:
            if asked:
                raise
            (warn or (lambda msg: None))(f"{name}: left out: {exc}")
    return out


def timing_frame(width: int = 1920, height: int = 1080, seed: int = 0, shift: float = 0.0) -> np.ndarray:
    """A 1-spp input frame mixing every kind of content, for speed measurements: diagonals and long
    edges across the top half; UI text, a checkerboard, and a photo crossed by wires below.
    `shift` pans the geometry by a sub-pixel amount."""
    rng = np.random.default_rng(seed)
    w3, h2 = width // 3, height // 2
    layers = _diagonal_layers(width // 6, 6, [30, 45, 60, -30, -45, -60], dx=shift, dy=shift * 0.5)
    layers += [Layer(translate(la.polygons, 0, height // 6), la.colour)
               for la in _long_edge_layers(width, height // 3, [270, 330, 420, 500], False, dx=shift)]
    ui, _ = _ui_layers(w3, h2, rng, False, dx=shift)
    layers += [Layer((rect(0, h2, w3, height),), la.colour) if la.polygons is None else
               Layer(translate(la.polygons, 0, h2), la.colour) for la in ui]
    checker = checker_texture(w3, height * 0.55)
    layers.append(Layer((rect(w3, h2, 2 * w3, height),), lambda x, y: checker(x - w3, y)))
    layers.append(Layer((rect(2 * w3, h2, width, height),), (60, 70, 80)))
    photo, box = photo_texture(2 * w3 + 20, h2 + 20, (100, 100, min(400, w3 - 40), min(400, h2 - 40)))
    layers.append(Layer((box,), photo))
    for k in range(12):
        y = h2 + 8 + k * 4.7 + shift
        layers.append(Layer((stroke(np.array([[2 * w3 + 4, y], [width - 4, y + 30]]), 0.3 + 0.1 * k),),
                            (20, 20, 20)))
    return encode8(render(layers, width, height, 1))
