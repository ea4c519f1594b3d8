"""The fast path (preset `fast`): seed 004's three-pass MLAA with a bounded edge length (kernels/fast.cl),
and its plain numpy reference, pass by pass.

    edges  = fast_edges_reference(frame)           # (H, W) uint8: top / right / bottom / left bits
    shapes = fast_lshapes_reference(edges)         # (H, W, 4) uint8: four L shapes per pixel
    out    = fast_blend_reference(frame, edges, shapes)

Trades against the default preset (measured in docs/fast.md): a weighted RGB difference instead of CIELAB,
no guards (already antialiased content, grain), no diagonal or sub-pixel handling, no bridging, and lines
longer than FAST_MAX_LEN pixels left as they are.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.device.context import linear_levels
from mlaa_stream.spatial.filter import SUBPIXEL, SUBPIXEL_BG, SUBPIXEL_END  # the default preset's sub-pixel rule

FAST_THRESHOLD = 0.06  # weighted RGB difference (Rec. 709 weights), fraction of full scale (seed 004)
FAST_MAX_LEN = 31  # longest line an L shape follows, in pixels (5 bits of its byte)
FAST_ROWS = 8  # rows per work item of the edge pass (each row's bottom edges are the next one's top edges)
FAST_COLS = 64  # columns of a block (kernels/fast.cl: the shape sweeps' 64-bit masks)
FAST_VCHUNK = 32  # rows per work item of fast_vshapes_columns (GPUs)
E_TOP, E_RIGHT, E_BOTTOM, E_LEFT = 1, 2, 4, 8
SIDE_A, SIDE_B, LONG = 1, 2, 128
LUMA_WEIGHTS = np.array([0.2126, 0.7152, 0.0722])


def fast_defines(threshold: float = FAST_THRESHOLD, max_len: int = FAST_MAX_LEN) -> dict[str, object]:
    if not 2 <= int(max_len) <= 31:
        raise ValueError(f"max_len: expected 2..31 pixels (5 bits per L shape), got {max_len}")
    return {"FAST_THRESHOLD": float(threshold), "FAST_MAX_LEN": int(max_len), "FAST_ROWS": FAST_ROWS,
            "FAST_VCHUNK": FAST_VCHUNK}


def _rgb(frame: np.ndarray) -> np.ndarray:
    """(H, W, 3) float64 in [0, 1] as the kernels read it (grey repeated)."""
    f = frame.astype(np.float64)
    if frame.dtype.kind in "ui":
        f /= np.iinfo(frame.dtype).max
    if f.ndim == 2:
        f = f[..., None]
    if f.shape[2] == 1:
        f = np.repeat(f, 3, axis=2)
    return f[..., :3]


INT_WEIGHTS = np.array([54, 183, 19])  # LUMA_WEIGHTS in 256ths: integer frames compare stored levels exactly


def fast_edges_reference(frame: np.ndarray, threshold: float = FAST_THRESHOLD) -> np.ndarray:
    """Pass 1: each pixel's edges to its four neighbours, each edge stored in both pixels."""
    if frame.dtype.kind in "ui":
        top = np.iinfo(frame.dtype).max
        lv = frame.astype(np.int64)
        lv = lv[..., None] if lv.ndim == 2 else lv
        lv = np.repeat(lv, 3, axis=2) if lv.shape[2] == 1 else lv[..., :3]
        limit = int(np.float32(threshold) * np.float32(top) * np.float32(256))
        dx = (np.abs(lv[:, 1:] - lv[:, :-1]) * INT_WEIGHTS).sum(-1) > limit
        dy = (np.abs(lv[1:] - lv[:-1]) * INT_WEIGHTS).sum(-1) > limit
    else:
        rgb = _rgb(frame).astype(np.float32)
        w = LUMA_WEIGHTS.astype(np.float32)
        dx = (np.abs(rgb[:, 1:] - rgb[:, :-1]) * w).sum(-1) > np.float32(threshold)
        dy = (np.abs(rgb[1:] - rgb[:-1]) * w).sum(-1) > np.float32(threshold)
    e = np.zeros(frame.shape[:2], np.uint8)
    e[:, :-1] |= np.where(dx, E_RIGHT, 0).astype(np.uint8)
    e[:, 1:] |= np.where(dx, E_LEFT, 0).astype(np.uint8)
    e[:-1] |= np.where(dy, E_BOTTOM, 0).astype(np.uint8)
    e[1:] |= np.where(dy, E_TOP, 0).astype(np.uint8)
    return e


def _crossing(has, xc: int, y: int) -> int:
    """Bits 5-7 of a shape byte: the crossing at a line's end across the right edge of column xc (rows y,
    y + 1) of a line of bottom edges in row y."""
    a, b = has(xc, y, E_RIGHT), has(xc, y + 1, E_RIGHT)
    side = (SIDE_A if a else 0) | (SIDE_B if b else 0)
    long_ = (side == SIDE_A and has(xc, y - 1, E_RIGHT) and has(xc, y - 2, E_RIGHT)) or \
            (side == SIDE_B and has(xc, y + 2, E_RIGHT) and has(xc, y + 3, E_RIGHT))
    return side << 5 | (LONG if long_ else 0)


def _row_shapes(edges: np.ndarray, max_len: int) -> np.ndarray:
    """(left, right) shapes along the bottom edges of every row: each run of bottom edges (split where a
    right edge crosses between two of its pixels, in either row) and the crossings at its two ends."""
    h, w = edges.shape
    out = np.zeros((h, w, 2), np.uint8)

    def has(x: int, y: int, bit: int) -> bool:
        return 0 <= x < w and 0 <= y < h and bool(edges[y, x] & bit)

    def byte(d: int, cross: int) -> int:
        return d | cross if d <= max_len - 1 else max_len - 1  # beyond the bound: the end is not known

    for y in range(h):
        x = 0
        while x < w:
            if not edges[y, x] & E_BOTTOM:
                x += 1
                continue
            xe = x
            while xe + 1 < w and edges[y, xe + 1] & E_BOTTOM and not has(xe, y, E_RIGHT) and not has(xe, y + 1, E_RIGHT):
                xe += 1
            c0, c1 = _crossing(has, x - 1, y), _crossing(has, xe, y)
            for t in range(x, xe + 1):
                out[y, t] = (byte(t - x, c0), byte(xe - t, c1))
            x = xe + 1
    return out


def _transpose_edges(edges: np.ndarray) -> np.ndarray:
    """The edge buffer of the transposed frame: right edges become bottom edges and the other way round."""
    t = np.zeros_like(edges.T)
    for a, b in ((E_TOP, E_LEFT), (E_LEFT, E_TOP), (E_BOTTOM, E_RIGHT), (E_RIGHT, E_BOTTOM)):
        t |= np.where(edges.T & a, b, 0).astype(np.uint8)
    return t


def fast_lshapes_reference(edges: np.ndarray, max_len: int = FAST_MAX_LEN) -> np.ndarray:
    """Pass 2: four L shapes per pixel (left and right along its bottom edge, up and down along its right
    edge, the latter as the rows of the transposed frame); 0 where the pixel has no such edge."""
    out = np.zeros((*edges.shape, 4), np.uint8)
    out[..., :2] = _row_shapes(edges, max_len)
    out[..., 2:] = _row_shapes(_transpose_edges(edges), max_len).transpose(1, 0, 2)
    out[..., :2] *= (edges & E_BOTTOM > 0)[..., None]
    out[..., 2:] *= (edges & E_RIGHT > 0)[..., None]
    return out


def trapezoid(p: int, length: int) -> float:
    """Seed 000 eq. (2) in float32 (kernels/fast.cl reads it from trapezoid_table)."""
    if 2 * p + 2 <= length:
        return float(np.float32(0.5) * (np.float32(1) - np.float32(2 * p + 1) / np.float32(length)))
    if 2 * p + 1 == length:
        return float(np.float32(1) / (np.float32(8) * np.float32(length)))
    return 0.0


def trapezoid_table() -> np.ndarray:
    """(64 * 32,) float32: trapezoid(p, length) at [length * 32 + p], every p < 32 and length < 64 a pair of
    shape bytes can give (kernels/fast.cl reads the areas from it)."""
    return np.array([[trapezoid(p, n) if n else 0.0 for p in range(32)] for n in range(64)], np.float32).ravel()


def line_areas(s0: int, s1: int) -> tuple[float, float]:
    """(side A, side B) areas of a line from its two shapes; none for U shapes and long (corner) ends."""
    d0, d1 = s0 & 31, s1 & 31
    a0, a1 = (s0 >> 5) & 3, (s1 >> 5) & 3
    a0, a1 = (0 if a0 == 3 else a0), (0 if a1 == 3 else a1)
    if (a0 == 0 and a1 == 0) or a0 == a1:
        return 0.0, 0.0
    length = d0 + d1 + 1
    ta = tb = 0.0
    for a, s, d in ((a0, s0, d0), (a1, s1, d1)):
        if a and not s & LONG:
            t = trapezoid(d, length)
            ta, tb = (ta + t, tb) if a == SIDE_A else (ta, tb + t)
    return ta, tb


def fast_weights_reference(edges: np.ndarray, shapes: np.ndarray) -> np.ndarray:
    """(top, bottom, left, right) areas each pixel takes from its neighbours."""
    h, w = edges.shape
    out = np.zeros((h, w, 4))
    for y, x in zip(*np.nonzero(edges)):
        e = edges[y, x]
        if e & E_BOTTOM:
            out[y, x, 1] = line_areas(*shapes[y, x, :2])[0]
        if e & E_TOP:
            out[y, x, 0] = line_areas(*shapes[y - 1, x, :2])[1]
        if e & E_RIGHT:
            out[y, x, 3] = line_areas(*shapes[y, x, 2:])[0]
        if e & E_LEFT:
            out[y, x, 2] = line_areas(*shapes[y, x - 1, 2:])[1]
    return out


def _sides(edges: np.ndarray) -> np.ndarray:
    return sum((edges >> k) & 1 for k in range(4)).astype(np.int64)


def fast_subpixel_reference(mix: np.ndarray, edges: np.ndarray, out: np.ndarray, subpixel: float = SUBPIXEL,
                            subpixel_end: float = SUBPIXEL_END, subpixel_bg: float = SUBPIXEL_BG) -> np.ndarray:
    """The sub-pixel rule (kernels/fast.cl `subpixel`, blend.cl's with isolation in place of the grain guard):
    isolated pixels with edges on 3-4 sides that are a luma extremum on one background move from `out` towards
    their 3x3 mean (in the mixing space `mix`). Returns the mask of pixels moved; `out` is updated in place."""
    h, w = edges.shape
    sides = _sides(edges)
    moved = np.zeros((h, w), bool)
    if subpixel <= 0:
        return moved
    pad = np.pad(mix, ((1, 1), (1, 1), (0, 0)), mode="edge")
    luma = mix @ LUMA_WEIGHTS
    for y, x in zip(*np.nonzero(sides >= 3)):
        across = [(y + dy, x + dx) for bit, dy, dx in ((E_TOP, -1, 0), (E_RIGHT, 0, 1), (E_BOTTOM, 1, 0),
                                                       (E_LEFT, 0, -1)) if edges[y, x] & bit]
        if any(sides[p] >= 3 for p in across):  # a cluster of features: noise, fine texture
            continue
        yc, yn = luma[y, x], np.array([luma[p] for p in across])
        lo, hi = (yn < yc).any(), (yn > yc).any()
        contrast = yn.min() - yc if hi else yc - yn.max()
        if (lo and hi) or yn.max() - yn.min() > subpixel_bg * contrast:
            continue
        box = pad[y:y + 3, x:x + 3].reshape(9, -1).sum(0) / 9
        out[y, x] += (subpixel if sides[y, x] == 4 else subpixel_end) * (box - out[y, x])
        moved[y, x] = True
    return moved


def fast_blend_reference(frame: np.ndarray, edges: np.ndarray, shapes: np.ndarray, linear: bool = True,
                         linear_input: bool = False, subpixel: float = SUBPIXEL) -> np.ndarray:
    """Pass 3: c + sum_k w_k^2 (n_k - c) / sum_k w_k over the four neighbours, in linear light (blend.cl's
    rule), then the sub-pixel rule (`subpixel` 0: off); alpha and other channels as they were."""
    wts = fast_weights_reference(edges, shapes)
    rgb = _rgb(frame)
    mix = srgb_to_linear(rgb) if linear and not linear_input else rgb
    pad = np.pad(mix, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = edges.shape
    neighbours = [pad[:-2, 1:-1], pad[2:, 1:-1], pad[1:-1, :-2], pad[1:-1, 2:]]
    total = wts.sum(-1)
    acc = sum(wts[..., k:k + 1] ** 2 * (neighbours[k] - mix) for k in range(4))
    out = np.where(total[..., None] > 0, mix + acc / np.maximum(total, 1e-30)[..., None], mix)
    moved = fast_subpixel_reference(mix, edges, out, subpixel, SUBPIXEL_END * subpixel / SUBPIXEL)
    out = linear_to_srgb(out) if linear and not linear_input else out
    result = frame.copy()
    changed = (total > 0) | moved
    if frame.dtype.kind in "ui":
        top = np.iinfo(frame.dtype).max
        vals = np.clip(np.floor(out * top + 0.5), 0, top).astype(frame.dtype)
    else:
        vals = out.astype(frame.dtype)
    if frame.ndim == 2 or frame.shape[2] == 1:
        view = result if frame.ndim == 2 else result[..., 0]
        view[changed] = vals[..., 0][changed]
    else:
        result[..., :3][changed] = vals[changed]
    return result


def fast_reference(frame: np.ndarray, threshold: float = FAST_THRESHOLD, max_len: int = FAST_MAX_LEN,
                   linear: bool = True, linear_input: bool = False, subpixel: float = SUBPIXEL) -> np.ndarray:
    """The whole fast path, pass after pass."""
    edges = fast_edges_reference(frame, threshold)
    return fast_blend_reference(frame, edges, fast_lshapes_reference(edges, max_len), linear, linear_input,
                                subpixel)


class FastPasses:
    """The three kernels of kernels/fast.cl and their buffers for one frame format. The edge pass also
    copies src into dst, and the blend writes only the pixels it changes."""

    def __init__(self, context, fmt, base_defines: dict[str, object], luts, threshold: float = FAST_THRESHOLD,
                 max_len: int = FAST_MAX_LEN):
        defs = {**base_defines, **fast_defines(threshold, max_len)}
        self.fmt = fmt
        self.edges = context.buffer(fmt.pixels)
        self.hshapes = context.buffer(2 * fmt.pixels)
        self.vshapes = context.buffer(2 * fmt.pixels)
        self.blocks = context.buffer(-(-fmt.width // FAST_COLS) * -(-fmt.height // FAST_ROWS))  # a byte per block
        self._k_edges = context.kernel("fast", "fast_edges", defs)
        # the edge pass in work groups of one work item on a CPU: with 8 (CPU_LOCAL) it is slower (docs/fast.md)
        self._edges_local = (1, 1) if context.device.type & cl.device_type.CPU else None
        self._k_hshapes = context.kernel("fast", "fast_hshapes", defs)
        self._column_sweeps = context.column_sweeps   # fast_vshapes_columns: a work item per column and chunk
        self._k_vshapes = context.kernel("fast", "fast_vshapes_columns" if self._column_sweeps else "fast_vshapes",
                                         defs)
        self._k_blend = context.kernel("fast", "fast_blend", defs)
        self._lin = linear_levels(context, "fast", defs, fmt, luts)  # integer frames: one load per level
        self._trap = cl.Buffer(context.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR,
                               hostbuf=trapezoid_table())

    def device_bytes(self) -> int:
        return self.edges.size + self.hshapes.size + self.vshapes.size + self.blocks.size

    def enqueue(self, queue, src, dst, luts, wait_for: list, segment: int | None = None,
                events: dict | None = None):
        """The passes of one frame after `wait_for`; returns the last event. `segment` (the default passes'
        work size) is not used: these passes work in blocks of FAST_COLS x FAST_ROWS pixels."""
        ev = {} if events is None else events
        w, h = self.fmt.width, self.fmt.height
        W, H = np.int32(w), np.int32(h)
        bx = -(-w // FAST_COLS)
        ev["fast_edges"] = self._k_edges(queue, (bx, -(-h // FAST_ROWS)), self._edges_local, src, self.edges, dst,
                                         self.blocks, W, H, wait_for=wait_for)
        ev["fast_hshapes"] = self._k_hshapes(queue, (h,), None, self.edges, self.blocks, self.hshapes, W, H,
                                             wait_for=[ev["fast_edges"]])
        if self._column_sweeps:
            ev["fast_vshapes"] = self._k_vshapes(queue, (w, -(-h // FAST_VCHUNK)), None, self.edges, self.vshapes,
                                                 W, H, wait_for=[ev["fast_edges"]])
        else:
            ev["fast_vshapes"] = self._k_vshapes(queue, (bx,), None, self.edges, self.blocks, self.vshapes, W, H,
                                                 wait_for=[ev["fast_edges"]])
        ev["fast_blend"] = self._k_blend(queue, (bx, h), None, src, self.edges, self.blocks, self.hshapes,
                                         self.vshapes, luts, self._lin, self._trap, dst, W, H,
                                         wait_for=[ev["fast_hshapes"], ev["fast_vshapes"]])
        return ev["fast_blend"]
