"""Point-sampled moire in two-colour art, low-passed (issue 15: the perspective checkerboard).

A pattern finer than the pixel grid -- a checkerboard towards its horizon, a far grid of lines -- comes out of 1-spp
sampling as dashed lines one pixel thick that alternate row by row: each row is another phase of the pattern, and
the truth there is close to the mean of neighbouring rows (a grey haze with faint stripes), where MLAA reads stair
steps and FXAA only blurs a little. Where a two-colour window is dense with such dashed isolated lines, the last
pass of the default chain replaces the pixel with the input's 3 x 3 binomial ([1 2 1] / 4 along rows and columns), in
linear light.
kernels/moire.cl states the rule; `moire_reference` computes the same in numpy. Why these constants:
docs/spatial_tuning.md, "Moire in two-colour art".

Untouched by construction: any window with a third colour (photographs, renders, text and art through a lossy codec,
antialiased art), ruled lines and 1-px checker fills (lines without dash ends), sparse thin lines (under
MOIRE_LINES per window).
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.context import Context
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, defines_for, frame_format

MOIRE_RADIUS = 3   # the window: (2 r + 1)^2 pixels
MOIRE_LINES = 10   # isolated-line pixels of one kind in the window (of 49: ~20 %) for the low-pass
MOIRE_ENDS = 4     # ... with at least one dash end per MOIRE_ENDS of them (dashes of 8 px or less on average)
MOIRE_REGION = 60  # ... and of that kind in the 3 x 3 tiles around the pixel's (of 576 px: ~10 %; a line of 6-px text
                   # holds fewer)
MOIRE_SEGMENT = 64  # pixels of a row per work item of moire_lines (MOIRE_TILE rows)
MOIRE_TILE = 8     # pixels per side of moire_lowpass's tiles (a window lies inside the 3 x 3 tiles around its own)


class MoirePass:
    """kernels/moire.cl for one frame format; `enqueue` runs it over dst in place, reading src."""

    def __init__(self, context: Context, fmt: FrameFormat, linear: bool = True, linear_input: bool = False):
        self.fmt = fmt
        self.tiles = (-(-fmt.width // MOIRE_TILE), -(-fmt.height // MOIRE_TILE))
        defs = defines_for(fmt, LINEAR_INPUT=int(linear_input), BLEND_LINEAR=int(linear), MOIRE_RADIUS=MOIRE_RADIUS,
                           MOIRE_LINES=MOIRE_LINES, MOIRE_ENDS=MOIRE_ENDS, MOIRE_REGION=MOIRE_REGION,
                           MOIRE_TILE=MOIRE_TILE,
                           MOIRE_SEGMENT=MOIRE_SEGMENT)
        self._lines = context.kernel("moire", "moire_lines", defs)
        self._lowpass = context.kernel("moire", "moire_lowpass", defs)

    @staticmethod
    def scratch_bytes(fmt: FrameFormat) -> int:
        """Bytes of scratch memory `enqueue` needs: the line bits (a byte per pixel), then two bytes per tile."""
        return fmt.pixels + 2 * -(-fmt.width // MOIRE_TILE) * -(-fmt.height // MOIRE_TILE)

    def enqueue(self, queue, src, dst, edges, luts, scratch, wait_for: list, events: dict) -> cl.Event:
        """dst holds the earlier passes' output of src, `edges` detect_edges' output; `scratch` (scratch_bytes or
        more) is free for this pass (the filter lends the blend's feature shares). Returns the event after which
        dst holds the result."""
        if scratch.size < self.scratch_bytes(self.fmt):
            raise ValueError(f"moire: expected a scratch buffer of {self.scratch_bytes(self.fmt)} bytes, got "
                             f"{scratch.size}")
        W, H = np.int32(self.fmt.width), np.int32(self.fmt.height)
        tx, ty = np.int32(self.tiles[0]), np.int32(self.tiles[1])
        events["moire_lines"] = self._lines(queue, (-(-self.fmt.width // MOIRE_SEGMENT), self.tiles[1]), None, src,
                                            edges, scratch, W, H, tx, wait_for=wait_for)
        events["moire"] = self._lowpass(queue, self.tiles, None, src, scratch, luts, dst, W, H, tx, ty,
                                        wait_for=[events["moire_lines"]])
        return events["moire"]


# --- numpy reference ------------------------------------------------------------------------------
def _clamped(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """a shifted so that element (y, x) holds a[y + dy, x + dx], coordinates clamped to the array."""
    h, w = a.shape[:2]
    ys = np.clip(np.arange(h) + dy, 0, h - 1)
    xs = np.clip(np.arange(w) + dx, 0, w - 1)
    return a[ys][:, xs]


def _window_sum(m: np.ndarray, r: int) -> np.ndarray:
    """Sum of m over the (2 r + 1)^2 window around each element, inside the array only."""
    h, w = m.shape
    p = np.zeros((h + 2 * r, w + 2 * r), np.int32)
    p[r:r + h, r:r + w] = m
    c = p.cumsum(0).cumsum(1)
    c = np.pad(c, ((1, 0), (1, 0)))
    k = 2 * r + 1
    return c[k:k + h, k:k + w] - c[:h, k:k + w] - c[k:k + h, :w] + c[:h, :w]


def line_bits(colours: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(line_v, line_h) of kernels/moire.cl for an (H, W, C) array of the colour samples and detect_edges' (H, W)
    output: isolated row / column pixels in two-colour surroundings."""
    def same(a, b):
        return (a == b).all(-1)
    h, w = edges.shape
    bottom, right = (edges & 1) != 0, (edges & 2) != 0
    ys, xs = np.mgrid[0:h, 0:w]
    cand_v = (ys > 0) & (ys < h - 1) & _clamped(bottom, -1, 0) & bottom
    cand_h = (xs > 0) & (xs < w - 1) & _clamped(right, 0, -1) & right
    c = colours
    n, s = _clamped(c, -1, 0), _clamped(c, 1, 0)
    o, e = _clamped(c, 0, -1), _clamped(c, 0, 1)
    v = cand_v & same(n, s) & (same(o, c) | same(o, n)) & (same(e, c) | same(e, n))
    hz = cand_h & same(o, e) & (same(n, c) | same(n, o)) & (same(s, c) | same(s, o))
    return v, hz


def two_colours(colours: np.ndarray, r: int = MOIRE_RADIUS) -> np.ndarray:
    """True where the window around a pixel (inside the frame) holds at most two colours."""
    h, w = colours.shape[:2]
    other = np.full((h, w), -1, np.int64)        # flat index of the first pixel of another colour, scan order
    ok = np.ones((h, w), bool)
    flat = colours.reshape(h * w, -1)
    ys, xs = np.mgrid[0:h, 0:w]
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            yy, xx = ys + dy, xs + dx
            inside = (yy >= 0) & (yy < h) & (xx >= 0) & (xx < w)
            j = np.clip(yy, 0, h - 1) * w + np.clip(xx, 0, w - 1)
            differs = inside & ~(flat[j] == colours).all(-1)
            first = differs & (other < 0)
            later = differs & (other >= 0)
            ok &= ~(later & ~(flat[j] == flat[np.maximum(other, 0)]).all(-1))
            other = np.where(first, j, other)
    return ok


def _region_sum(m: np.ndarray) -> np.ndarray:
    """Per pixel: the sum of m over the 3 x 3 tiles of MOIRE_TILE^2 pixels around its tile (inside the frame)."""
    h, w = m.shape
    T = MOIRE_TILE
    ty, tx = -(-h // T), -(-w // T)
    p = np.zeros((ty * T, tx * T), np.int32)
    p[:h, :w] = m
    tiles = np.pad(p.reshape(ty, T, tx, T).sum(axis=(1, 3)), 1)
    s = sum(tiles[1 + dy:1 + dy + ty, 1 + dx:1 + dx + tx] for dy in (-1, 0, 1) for dx in (-1, 0, 1))
    return np.repeat(np.repeat(s, T, 0), T, 1)[:h, :w]


def moire_fires(colours: np.ndarray, edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the rule holds for lines across the rows (fire_v) and, elsewhere, across the columns (fire_h); the kernel
    low-passes where either does."""
    line_v, line_h = line_bits(colours, edges)
    tone = two_colours(colours)
    fires = []
    for bit, m in ((0, line_v), (1, line_h)):
        a = _clamped(m, 0, -1) if bit == 0 else _clamped(m, -1, 0)
        b = _clamped(m, 0, 1) if bit == 0 else _clamped(m, 1, 0)
        n = _window_sum(m.astype(np.int32), MOIRE_RADIUS)
        ends = _window_sum((m & ~(a & b)).astype(np.int32), MOIRE_RADIUS)
        fires.append(tone & (n >= MOIRE_LINES) & (MOIRE_ENDS * ends >= n) & (_region_sum(m) >= MOIRE_REGION))
    return fires[0], fires[1] & ~fires[0]


def moire_reference(src: np.ndarray, out: np.ndarray, edges: np.ndarray, *, linear: bool = True,
                    linear_input: bool = False, bgr: bool = False) -> np.ndarray:
    """kernels/moire.cl on `out` (the earlier passes' output of `src`, `edges` detect_edges' output (H, W) uint8,
    EDGE_BOTTOM 1 | EDGE_RIGHT 2), in float32 numpy with the kernel's order."""
    fmt = frame_format(src, bgr)
    f32 = np.float32
    h, w, ch = fmt.height, fmt.width, fmt.channels
    a = np.asarray(src).reshape(h, w, ch)
    res = np.array(out, copy=True).reshape(h, w, ch)
    planes = 1 if ch == 1 else 3
    colours = a[..., :planes]
    fire_v, fire_h = moire_fires(colours, np.asarray(edges).reshape(h, w))
    pmax = f32(1.0) if fmt.dtype == np.float32 else f32(np.iinfo(fmt.dtype).max)
    decode = linear and not linear_input
    luts = device_luts()
    v = colours.astype(f32) * (f32(1.0) / pmax)
    mix = lut_read(luts, v).astype(f32) if decode else v
    fire = fire_v | fire_h
    row = f32(0.25) * (_clamped(mix, 0, -1) + _clamped(mix, 0, 1)) + f32(0.5) * mix   # the kernel's order
    m = f32(0.25) * (_clamped(row, -1, 0) + _clamped(row, 1, 0)) + f32(0.5) * row
    if decode:
        m = lut_read(luts[2 * (LUT_SIZE + 1):], m).astype(f32)
    if decode and fmt.dtype == np.float32:   # the tables span [0, 1]: a value outside the 3 x 3 keeps the pixel
        inside = ((v >= 0) & (v <= 1)).all(-1)
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                fire = fire & _clamped(inside, dy, dx)
    if fmt.dtype == np.float32:
        q = m
    else:
        q = np.floor(np.clip(m * pmax + f32(0.5), f32(0), pmax))
    res[..., :planes] = np.where(fire[..., None], q.astype(fmt.dtype), res[..., :planes])
    return res.reshape(np.shape(out))
