"""GRLAA overlays (seed 001): antialiased polylines with an outline, drawn over numpy frames.

`draw_polylines` for one call, `OverlayRenderer` to keep the kernel and buffers between frames of a
capture loop, `load_overlay` for a JSON/GeoJSON file (format in docs/grlaa.md), and
`reference_draw_polylines`, the plain numpy reference of kernels/grlaa.cl.
Coordinates are pixels, x right, y down, pixel centres at integers (as cv2 with `shift`).
"""
from __future__ import annotations

import json
import math
import numbers
import os
import string
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable

import numpy as np

from mlaa_stream.device.colour import LUMA, device_luts, linear_to_srgb, lut_read, srgb_to_linear
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, defines_for, frame_format

CAPS = {"round": 0, "butt": 3, "square": 7}  # seg_meta flag bits of kernels/grlaa.cl
DEFAULT_TILE = 16
ENC8_SIZE = 65536  # kernels/grlaa.cl: uint8 encode table
BIN_LOCAL = 64     # work-group size of the binning kernel
BIN_CAP = 64       # initial room for entries per tile (grows when a tile lists more)
DEVICE_CLIP_MARGIN = 4096.0  # points this far off the frame: segment tables in float64 on the host
EXACT_CLIP_BEYOND = 2.0 ** 32  # segments with an end this far out are cut to the frame exactly (_clip_segments)
# The widest stroke (and outline) drawn: kernels/grlaa.cl computes distances to the stroke's edge in float32, whose
# spacing at 2^15 px (half this width) is 2^-8 px. Against the float64 reference an edge 65536 px wide is within 1
# level of 8-bit coverage (measured: 3 levels at 2^20, the edge lost at 2^23, and nothing at all drawn from ~4.3e9
# on, where the half width overflows the kernel's int tile bounds), and it is over 4x the widest frame in use (16K:
# 15360 px): a wider stroke covers the same pixels, so a wider value is a mistake (a unit, an exponent), refused
# rather than drawn as nothing.
MAX_WIDTH = 65536.0
_FOOTPRINT_HALF_DIAGONAL = math.sqrt(0.5)
_HEX_DIGITS = frozenset(string.hexdigits)  # ASCII only: int(..., 16) also takes other scripts' digits

# --------------------------------------------------------------------------------------- styles

def parse_color(value, what: str = "color") -> tuple[float, float, float]:
    """A colour as sRGB in [0, 1], in the order given: '#rrggbb' / '#rgb' (always RGB), 3 numbers 0..255, or one
    number 0..255 (or a 1-sequence): grey."""
    if isinstance(value, str):
        s = value.strip().lstrip("#")
        if len(s) == 3:
            s = "".join(ch * 2 for ch in s)
        # hex digits only: int(..., 16) alone took '#-1-1-1' (-1/255: a colour below black) and '+f+f+f'
        if len(s) != 6 or not all(ch in _HEX_DIGITS for ch in s):
            raise ValueError(f"{what}: expected '#rrggbb', got {value!r}")
        return tuple(int(s[i:i + 2], 16) / 255.0 for i in (0, 2, 4))  # type: ignore[return-value]
    try:
        # one number (a 0-d array too): grey, as a 1-sequence is (cv2 takes a scalar colour too)
        vals = [float(value)] if isinstance(value, numbers.Real) or np.ndim(value) == 0 else [float(v) for v in value]
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected '#rrggbb' or 3 numbers 0..255, got {value!r}") from None
    if len(vals) == 1:
        vals = vals * 3
    if len(vals) != 3 or not all(0.0 <= v <= 255.0 for v in vals):
        raise ValueError(f"{what}: expected 3 numbers 0..255, got {value!r}")
    if all(v <= 1.0 for v in vals) and any(v != int(v) for v in vals):
        # fractions of one level each: a colour written on a 0..1 scale ([1.0, 0.5, 0]), drawn near-black without a word
        raise ValueError(f"{what}: expected 3 numbers 0..255, got {value!r} (a 0..1 colour? multiply it by 255)")
    return tuple(v / 255.0 for v in vals)  # type: ignore[return-value]


@dataclass(frozen=True)
class LineStyle:
    """How one polyline is drawn; colours are sRGB in [0, 1], RGB order; lengths in pixels.

    `width` is the whole stroke, outline included: the outline is the band of `outline_width`
    along the inside of the stroke's edge (seed 001's OUTLINE_WIDTH, here in pixels).
    """

    width: float = 2.0
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    outline: tuple[float, float, float] = (0.0, 0.0, 0.0)
    outline_width: float = 0.0
    opacity: float = 1.0
    cap: str = "round"

    def check(self, what: str) -> None:
        if not (0 < self.width <= MAX_WIDTH):   # also NaN and infinity
            raise ValueError(f"{what}: expected width > 0 and <= {MAX_WIDTH:g} pixels, got {self.width:g}")
        if not (0 <= self.outline_width <= MAX_WIDTH):
            raise ValueError(f"{what}: expected outline_width >= 0 and <= {MAX_WIDTH:g} pixels, "
                             f"got {self.outline_width:g}")
        if not (0.0 <= self.opacity <= 1.0):
            raise ValueError(f"{what}: expected opacity in [0, 1], got {self.opacity}")
        if self.cap not in CAPS:
            raise ValueError(f"{what}: expected cap one of {sorted(CAPS)}, got {self.cap!r}")


def _is_one_color(v) -> bool:
    """Whether `v` is one colour (a string, a number, 1 or 3 numbers) rather than one per line. Per-line lists may
    mix forms (["#ff0000", (0, 0, 255)]), which np.ndim alone refused with numpy's own message."""
    if isinstance(v, (str, numbers.Real)):  # a number: grey (parse_color)
        return True
    if isinstance(v, np.ndarray):
        return v.ndim == 0 or (v.ndim == 1 and len(v) in (1, 3))
    try:
        items = list(v)
    except TypeError:
        return False
    return len(items) in (1, 3) and all(isinstance(x, numbers.Real) or (isinstance(x, np.ndarray) and x.ndim == 0)
                                        for x in items)


def _per_line(value, n: int, name: str, is_one: Callable[[object], bool]) -> list:
    if is_one(value):
        return [value] * n
    vals = list(value)
    if len(vals) != n:
        raise ValueError(f"{name}: expected one value or {n} (one per line), got {len(vals)}")
    return vals


def make_styles(n: int, width=2.0, color="#ffffff", outline="#000000", outline_width=0.0,
                opacity=1.0, cap="round", bgr: bool = True) -> list[LineStyle]:
    """Per-line styles from scalars or per-line sequences; tuple colours are in the frame's order
    (BGR when `bgr`, as cv2), '#rrggbb' strings are RGB."""
    def scalar(v):
        return np.ndim(v) == 0

    parsed: dict = {}

    def to_rgb(c, what):
        key = c if isinstance(c, str) else tuple(np.ravel(c).tolist())
        if key not in parsed:
            rgb = parse_color(c, what)
            parsed[key] = rgb[::-1] if (bgr and not isinstance(c, str)) else rgb
        return parsed[key]

    if scalar(width) and _is_one_color(color) and _is_one_color(outline) and scalar(outline_width) \
            and scalar(opacity) and isinstance(cap, str):  # one style for all lines: build it once
        st = LineStyle(float(width), to_rgb(color, "line 0: color"), to_rgb(outline, "line 0: outline"),
                       float(outline_width), float(opacity), cap)
        st.check("line 0")
        return [st] * n
    ws = _per_line(width, n, "width", scalar)
    cs = _per_line(color, n, "color", _is_one_color)
    os_ = _per_line(outline, n, "outline", _is_one_color)
    ows = _per_line(outline_width, n, "outline_width", scalar)
    ops = _per_line(opacity, n, "opacity", scalar)
    caps = _per_line(cap, n, "cap", lambda v: isinstance(v, str))
    styles, made = [], {}
    for i in range(n):
        st = LineStyle(float(ws[i]), to_rgb(cs[i], f"line {i}: color"),
                       to_rgb(os_[i], f"line {i}: outline"), float(ows[i]), float(ops[i]), str(caps[i]))
        if st not in made:  # equal styles are checked once
            st.check(f"line {i}")
            made[st] = st
        styles.append(made[st])
    return styles


def as_lines(lines) -> list[np.ndarray]:
    """Polylines as float64 (N, 2) arrays: one (N, 2) array, an (L, N, 2) array or a list of them."""
    return _checked_lines(lines)[0]


def _checked_lines(lines) -> tuple[list[np.ndarray], np.ndarray]:
    """as_lines, and all points one after the other (float64 (P, 2)). A list of float64 (N, 2)
    arrays (a capture loop's usual input) is checked at once, through that concatenation."""
    if isinstance(lines, np.ndarray) and lines.ndim == 2:
        lines = [lines]
    if type(lines) is list and lines and all(type(a) is np.ndarray and a.dtype == np.float64
                                             for a in lines):
        try:
            allp = np.concatenate(lines)
        except ValueError:  # mixed shapes: the general path names the line
            allp = None
        if allp is not None and allp.ndim == 2 and allp.shape[1] == 2 \
                and min(map(len, lines)) >= 1 and np.isfinite(allp).all():
            return lines, allp
    out = []
    for i, ln in enumerate(lines):
        a = np.asarray(ln, dtype=np.float64)
        if a.ndim == 3 and a.shape[1] == 1:  # cv2's (N, 1, 2) point arrays
            a = a[:, 0]
        if a.ndim != 2 or a.shape[1] < 2 or a.shape[0] < 1:
            raise ValueError(f"line {i}: expected points of shape (N, 2), got {a.shape}")
        out.append(a[:, :2])
    allp = np.concatenate(out) if out else np.zeros((0, 2))
    if not np.isfinite(allp).all():  # one test; then find the line
        i = next(i for i, a in enumerate(out) if not np.isfinite(a).all())
        raise ValueError(f"line {i}: expected finite coordinates, got NaN or infinity")
    return out, allp


def to_byte(v: np.ndarray) -> np.ndarray:
    """common.cl's to_pixel for uint8 in float32: clamp(v * 255 + 0.5) truncated (round half up)."""
    t = np.asarray(v, np.float32) * np.float32(255.0) + np.float32(0.5)
    return np.clip(t, 0, 255).astype(np.uint8)


def enc8_table() -> np.ndarray:
    """uint8 sRGB frames: linear light i / 65535 -> sRGB byte (the LUT encode of common.cl, then
    to_pixel); kernels/grlaa.cl reads it at rint(v * 65535), a step of 1.5e-5 in linear
    light, at most 0.05 of a level in sRGB (at black, where the curve is steepest)."""
    luts = device_luts()
    x = np.arange(ENC8_SIZE, dtype=np.float64) / (ENC8_SIZE - 1)
    return to_byte(lut_read(luts[2 * (LUT_SIZE + 1):], x))


def enc8_read(table: np.ndarray, v: np.ndarray) -> np.ndarray:
    """What kernels/grlaa.cl encodes uint8 with: the table at rint(v * 65535), v clamped to [0, 1]."""
    return table[np.rint(np.clip(v, 0.0, 1.0) * (ENC8_SIZE - 1)).astype(np.intp)]


# ------------------------------------------------------------------------------- segment tables

@dataclass
class SegmentTables:
    """What kernels/grlaa.cl reads: segments, their flags, and per-polyline parameters."""

    ends: np.ndarray   # (S, 4) float64 x0, y0, x1, y1 (binning and the numpy reference)
    segs: np.ndarray   # (S, 8) float32 x0, y0, tx, ty, length, r, r_inner, reach (the kernel)
    meta: np.ndarray   # (S,) int32 (polyline << 3) | cap flags
    reach: np.ndarray  # (S,) float64 farthest distance from the segment a pixel centre can be touched
    polys: np.ndarray  # (P, 5, 4) float32


@dataclass
class LineTables:
    """Per-polyline values: the kernel's polys table (one row per line), and r, r_inner, reach
    and cap flags (CAPS), one value only when all lines share one style (`uniform`)."""

    polys: np.ndarray  # (P, 5, 4) float32
    r: np.ndarray
    ri: np.ndarray
    reach: np.ndarray  # farthest distance from a segment at which a pixel centre can be touched
    caps: np.ndarray   # int32
    uniform: bool


def line_tables(styles: list[LineStyle], channels: int, linear_frame: bool = False,
                strength: float = 1.0) -> LineTables:
    """Per-polyline tables of kernels/grlaa.cl (colours in linear light and as stored)."""
    nl = len(styles)
    if nl == 0:
        e = np.zeros(0)
        return LineTables(np.zeros((0, 5, 4), np.float32), e, e, e, np.zeros(0, np.int32), False)
    # one style for all lines (make_styles' scalar case): computed once, per-line values scalars
    uniform = styles.count(styles[0]) == nl
    if uniform:
        styles = styles[:1]
    polys = np.zeros((len(styles), 5, 4), np.float32)
    r = 0.5 * np.array([st.width for st in styles])
    ri = np.maximum(r - np.array([st.outline_width for st in styles]), 0.0)
    fill = np.array([st.color for st in styles], np.float64)
    outl = np.array([st.outline for st in styles], np.float64)
    fill_lin, out_lin = srgb_to_linear(fill), srgb_to_linear(outl)
    if channels < 3:  # grey frames: the colours' luminance, in linear light
        fill_lin = np.repeat(fill_lin @ LUMA[:, None], 3, axis=1)
        out_lin = np.repeat(out_lin @ LUMA[:, None], 3, axis=1)
        fill, outl = linear_to_srgb(fill_lin), linear_to_srgb(out_lin)
    polys[:, 0, 0], polys[:, 0, 1] = r, ri
    polys[:, 0, 2] = [st.opacity for st in styles]
    polys[:, 1, :3], polys[:, 2, :3] = fill_lin, out_lin
    polys[:, 3, :3] = fill_lin if linear_frame else fill
    polys[:, 4, :3] = out_lin if linear_frame else outl
    caps = np.array([CAPS[st.cap] for st in styles], np.int32)
    # square caps reach r*sqrt(2) past the end point (the corners); + half the footprint diagonal
    reach = r * np.where(caps & 4, math.sqrt(2.0), 1.0) + (_FOOTPRINT_HALF_DIAGONAL * strength + 1e-3)
    if uniform:
        polys = np.repeat(polys, nl, axis=0)
    return LineTables(polys, r, ri, reach, caps, uniform)


def segment_tables(lines: list[np.ndarray], styles: list[LineStyle], channels: int,
                   linear_frame: bool = False, strength: float = 1.0,
                   clip: tuple[int, int] | None = None) -> SegmentTables:
    """Flatten polylines into the kernel's tables in float64 (the numpy reference's, and the
    kernel's when points lie far off the frame: kernels/grlaa.cl grlaa_segments does the same
    on the device otherwise).

    With clip=(width, height), segments are cut to the frame grown by their reach (what lies
    beyond touches no pixel) so float32 stays precise and far-off lines cost nothing."""
    nl = len(lines)
    lt = line_tables(styles, channels, linear_frame, strength)
    polys, r, ri, uniform, caps = lt.polys, lt.r, lt.ri, lt.uniform, lt.caps
    if nl == 0:
        return SegmentTables(np.zeros((0, 4)), np.zeros((0, 8), np.float32), np.zeros(0, np.int32),
                             np.zeros(0), polys)
    counts = np.fromiter(map(len, lines), np.intp, nl)
    nseg = np.maximum(counts - 1, 1)  # a single point is a zero-length segment (a dot)
    allp = np.concatenate(lines)
    line_of = np.repeat(np.arange(nl, dtype=np.int32), nseg)
    first = np.cumsum(nseg) - nseg
    last = first + nseg - 1
    # segment starts: every point but the last of each line of 2 or more points
    is_start = np.ones(len(allp), bool)
    is_start[(np.cumsum(counts) - 1)[counts > 1]] = False
    ia = np.flatnonzero(is_start)
    ib = ia + 1
    ib[first[counts == 1]] -= 1  # a dot ends where it starts
    # 1-D columns throughout (numpy is much slower on short 2-D rows)
    px, py = allp[:, 0], allp[:, 1]
    cols = [np.take(px, ia), np.take(py, ia), np.take(px, ib), np.take(py, ib)]
    meta = line_of << 3
    if caps.any():  # flat caps: flags on each line's first and last segment
        capl = np.broadcast_to(caps, (nl,))
        meta[first] |= np.where(capl > 0, 1 | (capl & 4), 0)
        meta[last] |= np.where(capl > 0, 2 | (capl & 4), 0)
    reach_l = lt.reach
    reach = np.full(len(ia), reach_l[0]) if uniform else np.take(reach_l, line_of)
    if clip is not None:
        keep, cols = _clip_segments(cols, reach, *clip)
        if keep is not None:
            meta, reach, line_of = meta[keep], reach[keep], line_of[keep]
    x0, y0, x1, y1 = cols
    dx, dy = x1 - x0, y1 - y0
    length = np.sqrt(dx * dx + dy * dy)
    n = len(x0)
    ends = np.empty((n, 4))
    segs = np.empty((n, 8), np.float32)
    for c, v in enumerate(cols):
        ends[:, c] = v
    segs[:, 0], segs[:, 1] = x0, y0
    with np.errstate(divide="ignore", invalid="ignore"):
        segs[:, 2] = np.where(length > 0, dx / length, 1.0)
        segs[:, 3] = np.where(length > 0, dy / length, 0.0)
    segs[:, 4], segs[:, 7] = length, reach
    segs[:, 5], segs[:, 6] = (r[0], ri[0]) if uniform else (np.take(r, line_of), np.take(ri, line_of))
    return SegmentTables(ends, segs, meta, reach, polys)


def _clip_segments(cols: list[np.ndarray], reach: np.ndarray, width: int, height: int):
    """Liang-Barsky: segments (columns x0, y0, x1, y1) cut to [-m, width-1+m] x [-m, height-1+m],
    m = reach + 1; returns (kept mask or None when all are kept, cut columns). A cut end lies over
    `reach` outside the frame, so its cap shows nowhere. Only segments with an end outside that box
    are cut."""
    m = reach + 1.0
    x0, y0, x1, y1 = cols
    out = np.flatnonzero((np.minimum(x0, x1) < -m) | (np.maximum(x0, x1) > width - 1 + m) |
                         (np.minimum(y0, y1) < -m) | (np.maximum(y0, y1) > height - 1 + m))
    if len(out) == 0:
        return None, cols
    m = m[out]
    ox, oy = x0[out], y0[out]
    with np.errstate(over="ignore", divide="ignore", invalid="ignore"):  # exact below where float64 overflows
        dx, dy = x1[out] - ox, y1[out] - oy
        t0, t1 = np.zeros(len(out)), np.ones(len(out))
        ok = np.ones(len(out), bool)
        for p, q in ((-dx, ox + m), (dx, width - 1 + m - ox), (-dy, oy + m), (dy, height - 1 + m - oy)):
            r = q / p
            ok &= ~((p == 0) & (q < 0))
            t0 = np.where(p < 0, np.maximum(t0, r), t0)
            t1 = np.where(p > 0, np.minimum(t1, r), t1)
        ok &= t0 <= t1
        cut_out = [ox + t0 * dx, oy + t0 * dy, ox + t1 * dx, oy + t1 * dy]
    # o + t * d cancels: a cut end lies near the frame, the ends it is cut from up to |o| away, so its error is
    # ulp(|o|) (a line from x = -1e18 to the frame started thousands of pixels late). Beyond EXACT_CLIP_BEYOND px
    # (error over 1e-6 px) such segments are cut in exact rational arithmetic instead.
    big = np.flatnonzero(np.maximum(np.maximum(np.abs(ox), np.abs(oy)),
                                    np.maximum(np.abs(x1[out]), np.abs(y1[out]))) > EXACT_CLIP_BEYOND)
    for i in big:
        o = out[i]
        got = _clip_exact(float(x0[o]), float(y0[o]), float(x1[o]), float(y1[o]), float(m[i]), width, height)
        ok[i] = got is not None
        if got is not None:
            for c, v in enumerate(got):
                cut_out[c][i] = v
    keep = np.ones(len(x0), bool)
    keep[out] = ok
    cut = []
    for v, c in zip((x0, y0, x1, y1), cut_out):
        v = v.copy()
        v[out] = c
        cut.append(v[keep])
    return keep, cut


def _clip_exact(x0: float, y0: float, x1: float, y1: float, m: float, width: int,
                height: int) -> tuple[float, float, float, float] | None:
    """_clip_segments' Liang-Barsky for one segment in exact rationals (its ends are exact binary fractions); the
    cut ends rounded to float64 once. None where the segment misses the box."""
    X0, Y0, X1, Y1, M = map(Fraction, (x0, y0, x1, y1, m))
    dx, dy = X1 - X0, Y1 - Y0
    t0, t1 = Fraction(0), Fraction(1)
    for p, q in ((-dx, X0 + M), (dx, width - 1 + M - X0), (-dy, Y0 + M), (dy, height - 1 + M - Y0)):
        if p == 0:
            if q < 0:
                return None
        elif p < 0:
            t0 = max(t0, q / p)
        else:
            t1 = min(t1, q / p)
    if t0 > t1:
        return None
    return float(X0 + t0 * dx), float(Y0 + t0 * dy), float(X0 + t1 * dx), float(Y0 + t1 * dy)


# ----------------------------------------------------------------------------- OpenCL renderer

class OverlayRenderer:
    """Draws GRLAA polylines on frames; keeps the program, kernel and buffers between frames.

    Not thread-safe: use one renderer per thread.
    """

    def __init__(self, device: str | int | None = None, strength: float = 1.0,
                 tile: int = DEFAULT_TILE, linear: bool = False, zero_copy: bool | None = None):
        """`strength` is seed 001's ANTIALIAS_STRENGTH in pixels (1 = exact box-filter coverage);
        `linear` says frames hold linear light instead of sRGB. `zero_copy`: the kernel draws
        straight into the numpy frame (wrapped, not copied); default: on devices that share host
        memory (CPU). Otherwise the frame goes through a device buffer kept per frame size."""
        from mlaa_stream.device.context import default_context
        import pyopencl as cl

        if not (math.isfinite(strength) and strength > 0):
            raise ValueError(f"strength: expected > 0 pixels, got {strength}")
        if tile not in (8, 16, 32):
            raise ValueError(f"tile: expected 8, 16 or 32, got {tile}")
        self._cl = cl
        self._ctx = default_context(device)
        # One work-item per tile. On a CPU device work-items of a group run one after another, so
        # groups of one are simplest; a GPU wants wider groups. Fixed per device: no recompiles.
        self._local = 1 if self._ctx.device.type & cl.device_type.CPU else 32
        is_cpu = bool(self._ctx.device.type & cl.device_type.CPU)
        self.zero_copy = bool(is_cpu and self._ctx.device.host_unified_memory) if zero_copy is None \
            else bool(zero_copy)
        # PoCL's CPU driver runs kernels on a USE_HOST_PTR array itself, so once a kernel's event
        # has completed the array holds what it wrote: no map of the frame and no read of the
        # overflow flag, each a command through the queue (together ~0.15 ms a frame, 7 % of a
        # 1-px draw). Other zero-copy runtimes may keep a copy: they map.
        self._direct = self.zero_copy and "Portable Computing Language" in \
            self._ctx.device.platform.name
        self.strength = float(strength)
        self.tile = int(tile)
        self.linear = bool(linear)
        luts = device_luts()
        self._luts = self._ctx.buffer(luts.nbytes, cl.mem_flags.READ_ONLY)
        cl.enqueue_copy(self._ctx.queue, self._luts, luts)
        # uint8 sRGB frames decode through a 256-entry table (the same LUT read, done once here)
        dec8 = lut_read(luts, np.arange(256) / 255.0).astype(np.float32)
        self._dec8 = self._ctx.buffer(dec8.nbytes, cl.mem_flags.READ_ONLY)
        cl.enqueue_copy(self._ctx.queue, self._dec8, dec8)
        enc8 = enc8_table()
        self._enc8 = self._ctx.buffer(enc8.nbytes, cl.mem_flags.READ_ONLY)
        cl.enqueue_copy(self._ctx.queue, self._enc8, enc8)
        self._fmt: FrameFormat | None = None
        self._frame_buf = None
        self._kernel = None
        self._bufs: dict[str, tuple[object, int]] = {}
        self._inputs: list[tuple[np.ndarray, object]] = []
        self._args: dict[str, list] = {}   # per kernel: the arguments set last (_set_args)
        # (key, LineTables, pcol buffer, polys buffer, pcol array the buffer may wrap)
        self._tables_cache: tuple | None = None
        # (key, line_i buffer, line_f buffer, segments, (line_i, line_f, LineTables) kept alive)
        self._lines_cache: tuple | None = None
        # ((number of lines, style arguments), styles): draw's last styles
        self._styles_cache: tuple | None = None

    @property
    def device_name(self) -> str:
        return self._ctx.name

    def _grow(self, name: str, host: np.ndarray):
        """A buffer of at least host.nbytes, reused across frames; grows by doubling only."""
        buf, cap = self._bufs.get(name, (None, 0))
        if host.nbytes > cap:
            cap = max(host.nbytes, 2 * cap, 4096)
            buf = self._ctx.buffer(cap, self._cl.mem_flags.READ_ONLY)
            self._bufs[name] = (buf, cap)
        if host.nbytes:
            self._cl.enqueue_copy(self._ctx.queue, buf, host, is_blocking=False)
        return buf

    def _setup(self, fmt: FrameFormat) -> None:
        if fmt == self._fmt:
            return
        cl = self._cl
        decode8 = int(fmt.dtype == np.uint8 and not self.linear)
        defines = defines_for(fmt, TILE=self.tile, LINEAR_FRAME=int(self.linear), DECODE8=decode8)
        # Kernel objects of this renderer's own (not the context's shared ones): _set_args keeps
        # the arguments set on them between frames and sets only those that changed.
        prg = self._ctx.program("grlaa", defines)
        self._kernel = cl.Kernel(prg, "grlaa_draw")
        self._frame_buf = None if self.zero_copy else self._ctx.buffer(fmt.nbytes)
        # binning on the device: per-tile counters (cleared by grlaa_draw), room for `cap`
        # entries per tile, and a flag set when a tile had more
        tx, ty = -(-fmt.width // self.tile), -(-fmt.height // self.tile)
        self._tiles_xy = (np.int32(tx), np.int32(ty))
        self._counts = self._ctx.buffer(4 * tx * ty)
        cl.enqueue_copy(self._ctx.queue, self._counts, np.zeros(tx * ty, np.int32))
        self._overflow_host = np.zeros(1, np.int32)
        if self._direct:  # the kernels set the host's flag itself
            self._overflow = cl.Buffer(self._ctx.ctx, cl.mem_flags.READ_WRITE |
                                       cl.mem_flags.USE_HOST_PTR, hostbuf=self._overflow_host)
        else:
            self._overflow = self._ctx.buffer(4)
            cl.enqueue_copy(self._ctx.queue, self._overflow, self._overflow_host)
        self._cap = BIN_CAP
        self._entries = self._ctx.buffer(4 * tx * ty * self._cap)
        self._k_bin = cl.Kernel(prg, "grlaa_bin")
        self._k_segments = cl.Kernel(prg, "grlaa_segments")
        self._args = {}
        self._tables_cache = self._lines_cache = None
        self._fmt = fmt

    def _set_args(self, name: str, kernel, *args) -> None:
        """kernel.set_arg for the arguments that differ from those set last (the same buffer
        object, or an equal number of the same type): a frame of a capture loop changes few,
        and pyopencl's set_args costs microseconds an argument."""
        last = self._args.get(name)
        for i, a in enumerate(args):
            if last is not None:
                b = last[i]
                if a is b or (isinstance(a, np.generic) and type(a) is type(b) and a == b):
                    continue
            kernel.set_arg(i, a)
        self._args[name] = list(args)

    def _kept_input(self, host: np.ndarray):
        """A kernel input kept across frames (cached tables): its own buffer, written once."""
        mf = self._cl.mem_flags
        if self.zero_copy:
            return self._cl.Buffer(self._ctx.ctx, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=host)
        buf = self._ctx.buffer(host.nbytes, mf.READ_ONLY)
        self._cl.enqueue_copy(self._ctx.queue, buf, host, is_blocking=False)
        return buf

    def _tables(self, styles: list[LineStyle], channels: int):
        """(LineTables, pcol buffer, polys buffer) for `styles`. Kept for one style shared by all
        lines (a capture loop draws the same style every frame), so then nothing is rebuilt."""
        n = len(styles)
        key = (styles[0], n, channels) if styles.count(styles[0]) == n else None
        if key is not None and self._tables_cache is not None and self._tables_cache[0] == key:
            return self._tables_cache[1:4]
        lt = line_tables(styles, channels, self.linear, self.strength)
        # uint8 frames: fully covered pixels take these bytes, (R << 16) | (G << 8) | B, at
        # 1 + 2 * polyline (fill) and 2 + 2 * polyline (outline)
        rgb = to_byte(lt.polys[:, 3:5, :3]).astype(np.uint32)
        pcol = np.zeros(1 + 2 * len(rgb), np.uint32)
        pcol[1:] = ((rgb[..., 0] << 16) | (rgb[..., 1] << 8) | rgb[..., 2]).ravel()
        if key is None:
            return lt, self._input("pcol", pcol), self._input("polys", lt.polys)
        # the host arrays stay referenced by the cache while their buffers may wrap them
        self._tables_cache = (key, lt, self._kept_input(pcol), self._kept_input(lt.polys), pcol)
        return self._tables_cache[1:4]

    def _input(self, name: str, host: np.ndarray):
        """A per-frame input for the kernels. On zero-copy (CPU) devices the host array itself,
        wrapped (no command in the queue: a write waits for PoCL's worker threads, which under
        load costs milliseconds); elsewhere a buffer kept between frames, written (_grow)."""
        if not self.zero_copy:
            return self._grow(name, host)
        host = np.ascontiguousarray(host)
        if host.size == 0:
            # OpenCL has no zero-size buffers (INVALID_BUFFER_SIZE): lines lying wholly far off the frame leave empty
            # segment tables; the kernels read none of a 0-segment table, so one zeroed element stands in for it
            host = np.zeros((1,) + host.shape[1:], host.dtype)
        buf = self._cl.Buffer(self._ctx.ctx, self._cl.mem_flags.READ_ONLY |
                              self._cl.mem_flags.USE_HOST_PTR, hostbuf=host)
        self._inputs.append((host, buf))  # both kept until the frame is drawn
        return buf

    def _writable(self, name: str, nbytes: int):
        """A device-written buffer of at least nbytes, reused across frames (grows by doubling)."""
        buf, cap = self._bufs.get(name, (None, 0))
        if nbytes > cap:
            cap = max(nbytes, 2 * cap, 4096)
            buf = self._ctx.buffer(cap)
            self._bufs[name] = (buf, cap)
        return buf

    def _segments(self, lines: list[np.ndarray], styles: list[LineStyle], lt: LineTables,
                  fmt: FrameFormat, allp: np.ndarray | None = None):
        """Enqueue the segment tables and their binning into tiles; returns (segs buffer, meta
        buffer, number of segments). kernels/grlaa.cl grlaa_segments builds and bins them from the
        points in float32; where a point lies more than DEVICE_CLIP_MARGIN px off the frame
        (grown to a square), the float64 segment_tables builds them (float32 would not cut such
        segments to the frame precisely) and grlaa_bin bins them. Nothing waits: grlaa_draw reads
        the counts, and draws nothing if a tile overflowed its room (_more_room). `allp`: the
        lines' points one after the other, when the caller has them."""
        cl, q = self._cl, self._ctx.queue
        nl = len(lines)
        tx, ty = self._tiles_xy
        binning = (tx, ty, np.int32(self._cap), self._counts, self._entries, self._overflow)
        if allp is None:
            allp = np.concatenate(lines) if nl > 1 else lines[0]
        m = DEVICE_CLIP_MARGIN  # (whole-array min and max: much faster than per column)
        if allp.min() < -m or allp.max() > max(fmt.width, fmt.height) + m:
            tables = segment_tables(lines, styles, fmt.channels, self.linear, self.strength,
                                    clip=(fmt.width, fmt.height))
            total = len(tables.segs)
            segs, meta = self._input("segs", tables.segs), self._input("meta", tables.meta)
            if total:
                self._set_args("bin", self._k_bin, segs, np.int32(total), *binning)
                cl.enqueue_nd_range_kernel(q, self._k_bin, (-(-total // BIN_LOCAL) * BIN_LOCAL,),
                                           (BIN_LOCAL,))
            return segs, meta, total
        counts = np.fromiter(map(len, lines), np.int32, nl)
        # The per-line tables are kept while the lines' point counts and styles stay the same.
        key = (counts.tobytes(), id(lt))
        if self._lines_cache is not None and self._lines_cache[0] == key:
            _, li_b, lf_b, total, _ = self._lines_cache
        else:
            nseg = np.maximum(counts - 1, 1)  # a single point is a zero-length segment (a dot)
            li = np.empty((nl, 4), np.int32)  # first point, first segment, points, cap flags
            li[:, 0] = np.cumsum(counts) - counts
            li[:, 1] = np.cumsum(nseg) - nseg
            li[:, 2] = counts
            li[:, 3] = lt.caps
            lf = np.zeros((nl, 4), np.float32)  # r, r_inner, reach
            lf[:, 0], lf[:, 1], lf[:, 2] = lt.r, lt.ri, lt.reach
            total = int(li[-1, 1] + nseg[-1])
            li_b, lf_b = self._kept_input(li), self._kept_input(lf)
            # lt stays referenced, so its id names it while the entry lives
            self._lines_cache = (key, li_b, lf_b, total, (li, lf, lt))
        segs = self._writable("segs_dev", 32 * total)
        meta = self._writable("meta_dev", 4 * total)
        k = self._k_segments
        self._set_args("segments", k, self._input("pts", allp.astype(np.float32)), li_b, lf_b,
                       np.int32(nl), np.int32(total), np.int32(fmt.width), np.int32(fmt.height),
                       segs, meta, *binning)
        cl.enqueue_nd_range_kernel(q, k, (-(-total // BIN_LOCAL) * BIN_LOCAL,), (BIN_LOCAL,))
        return segs, meta, total

    def _more_room(self) -> bool:
        """After a draw has completed and self._overflow_host was read: if a tile overflowed its
        room (nothing was drawn), clear the flag and double the room per tile; True if so."""
        if not self._overflow_host[0]:
            return False
        self._overflow_host[0] = 0
        if not self._direct:
            self._cl.enqueue_copy(self._ctx.queue, self._overflow, self._overflow_host)
        self._cap *= 2
        tx, ty = self._tiles_xy
        self._entries = self._ctx.buffer(4 * int(tx) * int(ty) * self._cap)
        return True

    def bin(self, tables: SegmentTables, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """kernels/grlaa.cl grlaa_bin on `tables` for frames like `frame`, read back (for tests):
        (entries int32, tiles (T, 4) int32 x, y, first, count) of the non-empty tiles, entries
        in drawing order per tile and packed (first = the tile's offset in entries)."""
        cl, q = self._cl, self._ctx.queue
        self._setup(frame_format(frame))
        tx, ty = (int(v) for v in self._tiles_xy)
        counts = np.zeros(tx * ty, np.int32)
        segs = self._grow("segs", tables.segs)
        while len(tables.segs):
            self._set_args("bin", self._k_bin, segs, np.int32(len(tables.segs)), *self._tiles_xy,
                           np.int32(self._cap), self._counts, self._entries, self._overflow)
            cl.enqueue_nd_range_kernel(q, self._k_bin, (-(-len(tables.segs) // BIN_LOCAL) * BIN_LOCAL,),
                                       (BIN_LOCAL,))
            cl.enqueue_copy(q, counts, self._counts, is_blocking=True)
            cl.enqueue_copy(q, self._counts, np.zeros_like(counts))  # as grlaa_draw leaves them
            if not self._direct:
                cl.enqueue_copy(q, self._overflow_host, self._overflow, is_blocking=True)
            else:
                q.finish()
            if not self._more_room():
                break
        room = np.empty(tx * ty * self._cap, np.int32)
        cl.enqueue_copy(q, room, self._entries, is_blocking=True)
        t = np.flatnonzero(counts)
        tiles = np.stack([t % tx, t // tx, np.cumsum(counts[t]) - counts[t], counts[t]], axis=1)
        entries = np.concatenate([np.sort(room[i * self._cap:i * self._cap + counts[i]]) for i in t]
                                 or [room[:0]])
        return entries, tiles.astype(np.int32)

    def draw(self, frame: np.ndarray, lines, width=2.0, color="#ffffff", outline="#000000",
             outline_width=0.0, opacity=1.0, cap="round", bgr: bool = True,
             inplace: bool = False, what: str = "frame") -> np.ndarray:
        """Draw `lines` over `frame`; returns a new frame of the same shape and dtype, or `frame`
        itself (drawn into) with `inplace`. Style arguments: one value or one per line."""
        pts, allp = _checked_lines(lines)
        styles = self._styles(len(pts), width, color, outline, outline_width, opacity, cap, bgr)
        return self._draw(frame, pts, allp, styles, bgr, inplace, what)

    def _styles(self, n: int, *args) -> list[LineStyle]:
        """make_styles(n, *args), kept for the last arguments when they are hashable (numbers,
        strings, tuples): a capture loop passes the same ones every frame."""
        key = (n, args)
        try:
            if self._styles_cache is not None and self._styles_cache[0] == key:
                return self._styles_cache[1]
            hash(key)
        except (TypeError, ValueError):  # lists, arrays: built every time
            return make_styles(n, *args)
        styles = make_styles(n, *args)
        self._styles_cache = (key, styles)
        return styles

    def draw_styled(self, frame: np.ndarray, lines: list[np.ndarray], styles: list[LineStyle],
                    bgr: bool = True, inplace: bool = False, what: str = "frame",
                    premultiplied: bool = False) -> np.ndarray:
        """`draw` with checked lines (as_lines) and one LineStyle per line. `premultiplied`: a 4-channel frame's
        colour is premultiplied by its alpha (an EXR's RGBA), not straight: see draw_premultiplied."""
        allp = np.concatenate(lines) if lines else np.zeros((0, 2))
        if premultiplied and frame.ndim == 3 and frame.shape[2] == 4 and lines:
            if inplace and not frame.flags.writeable:  # as _draw says it
                raise ValueError(f"{what}: expected a writeable array for inplace drawing, got a read-only one")
            out = draw_premultiplied(lambda f: self._draw(f, lines, allp, styles, bgr, False, what), frame)
            if inplace:
                frame[...] = out
                return frame
            return out
        return self._draw(frame, lines, allp, styles, bgr, inplace, what)

    def _draw(self, frame: np.ndarray, lines: list[np.ndarray], allp: np.ndarray,
              styles: list[LineStyle], bgr: bool, inplace: bool, what: str) -> np.ndarray:
        fmt = frame_format(frame, bgr=bgr, what=what)
        if inplace and not frame.flags.writeable:
            raise ValueError(f"{what}: expected a writeable array for inplace drawing, got a read-only one")
        if not lines:
            return frame if inplace else frame.copy()
        self._setup(fmt)
        lt, pcol_b, polys_b = self._tables(styles, fmt.channels)
        try:
            segs, meta, nseg = self._segments(lines, styles, lt, fmt, allp)
            if nseg == 0:
                return frame if inplace else frame.copy()
            dst = self._draw_binned(frame, fmt, inplace, lt, lines, styles, segs, meta, pcol_b,
                                    polys_b)
        except BaseException:  # the binning's counters must start the next frame at zero
            self._ctx.queue.finish()
            self._cl.enqueue_copy(self._ctx.queue, self._counts,
                                  np.zeros(int(np.prod(self._tiles_xy)), np.int32), is_blocking=True)
            raise
        finally:
            self._inputs.clear()
        if dst.dtype != frame.dtype:
            dst = dst.astype(frame.dtype)
        if inplace and dst is not frame:
            frame[...] = dst
            return frame
        return dst

    def _draw_binned(self, frame: np.ndarray, fmt: FrameFormat, inplace: bool, lt: LineTables,
                     lines: list[np.ndarray], styles: list[LineStyle], segs, meta, pcol_b,
                     polys_b) -> np.ndarray:
        """grlaa_draw over the frame once the segments are binned (draw_styled); returns the
        drawn array (the frame itself, or a copy in the frame's format)."""
        cl = self._cl
        q = self._ctx.queue
        mf = cl.mem_flags
        same = frame.dtype == fmt.dtype and frame.flags.c_contiguous
        if self.zero_copy:  # draw into the output array itself: no frame transfers
            dst = frame if (inplace and same) else np.array(frame, dtype=fmt.dtype, order="C")
            fbuf = cl.Buffer(self._ctx.ctx, mf.READ_WRITE | mf.USE_HOST_PTR, hostbuf=dst)
        else:
            src = frame if same else np.ascontiguousarray(frame, dtype=fmt.dtype)
            dst = frame if (inplace and same) else np.empty(src.shape, fmt.dtype)
            fbuf = self._frame_buf
            cl.enqueue_copy(q, fbuf, src, is_blocking=False)
        k = self._kernel
        # one work-item per tile of the frame (empty tiles return at once)
        n = -(-int(np.prod(self._tiles_xy)) // self._local) * self._local
        while True:
            self._set_args("draw", k, fbuf, self._luts, self._dec8, self._enc8, pcol_b, segs,
                           meta, self._entries, self._counts, self._overflow, polys_b,
                           np.int32(fmt.width), np.int32(fmt.height), np.float32(self.strength),
                           self._tiles_xy[0], np.int32(self._cap))
            drawn = cl.enqueue_nd_range_kernel(q, k, (n,), (self._local,))
            if self._direct:  # one wait per frame: the frame and the flag are the host's arrays
                drawn.wait()
            else:
                if self.zero_copy:  # mapping makes the host array current
                    view, _ = cl.enqueue_map_buffer(q, fbuf, cl.map_flags.READ, 0, dst.shape,
                                                    dst.dtype, is_blocking=False)
                # one wait per frame: the in-order queue has drawn (and mapped) when the flag arrives
                cl.enqueue_copy(q, self._overflow_host, self._overflow, is_blocking=True)
                if self.zero_copy:
                    view.base.release(q)  # unmapping a read mapping writes nothing back
            if not self._more_room():
                break
            segs, meta, _ = self._segments(lines, styles, lt, fmt)  # bin again, more room
        if self.zero_copy:
            fbuf.release()  # freed once the queued unmap has run
        else:
            cl.enqueue_copy(q, dst, fbuf, is_blocking=True)
        return dst

    __call__ = draw


def draw_premultiplied(draw_straight: Callable[[np.ndarray], np.ndarray], frame: np.ndarray) -> np.ndarray:
    """Draw over an (H, W, 4) frame whose colour is premultiplied by its alpha (EXR's RGBA, a TIFF tagged so):
    `draw_straight(f)` composites over straight alpha (kernels/grlaa.cl), which took the premultiplied colour for
    straight (a white line at opacity 0.5 over 0.1 premultiplied at alpha 0.5 gave 0.70, not 0.55). So the colour
    is divided by alpha (as float32, 0..1), drawn, and multiplied by the new alpha: only on the pixels the lines
    touched, every other sample stays bit for bit. Where alpha is 0 the colour stays as it is (nothing to divide)."""
    top = 1.0 if frame.dtype.kind == "f" else float(np.iinfo(frame.dtype).max)
    px = frame.astype(np.float32) / np.float32(top)
    alpha = px[..., 3:]
    straight = px.copy()
    straight[..., :3] = np.where(alpha > 0, px[..., :3] / np.where(alpha > 0, alpha, 1), px[..., :3])
    drawn = draw_straight(straight)
    touched = (drawn != straight).any(axis=2)
    prem = drawn[touched]
    prem[:, :3] *= prem[:, 3:]
    out = frame.copy()
    if frame.dtype.kind == "f":
        out[touched] = prem.astype(frame.dtype)
    else:
        out[touched] = np.clip(np.rint(prem * top), 0, top).astype(frame.dtype)
    return out


_renderers: dict[tuple, OverlayRenderer] = {}


def draw_polylines(frame: np.ndarray, lines, width=2.0, color="#ffffff", outline="#000000",
                   outline_width=0.0, opacity=1.0, cap="round", bgr: bool = True,
                   device: str | int | None = None, strength: float = 1.0,
                   inplace: bool = False) -> np.ndarray:
    """Draw antialiased polylines (GRLAA, seed 001) over a numpy frame; returns the drawn frame.

    Tuple colours are 0..255 in the frame's channel order (BGR when `bgr`, as cv2); '#rrggbb' is RGB.
    A renderer per (device, strength) is kept, so calling this per frame builds nothing twice.
    """
    key = (None if device is None else str(device), float(strength))
    r = _renderers.get(key)
    if r is None:
        r = _renderers[key] = OverlayRenderer(device, strength)
    return r.draw(frame, lines, width, color, outline, outline_width, opacity, cap, bgr, inplace)


# ------------------------------------------------------------------------------- overlay files

@dataclass
class OverlayFeature:
    """One feature of an overlay file: a style, fixed lines and/or lines per frame index."""

    style: LineStyle
    lines: list[np.ndarray] | None
    frames: dict[int, list[np.ndarray]]
    first_frame: int | None = None
    last_frame: int | None = None

    def lines_at(self, index: int) -> list[np.ndarray]:
        if index in self.frames:
            return self.frames[index]
        if self.lines is None:
            return []
        if (self.first_frame is not None and index < self.first_frame) or \
                (self.last_frame is not None and index > self.last_frame):
            return []
        return self.lines


def _geometry_lines(geom, where: str) -> list[np.ndarray] | None:
    if geom is None:
        return None
    if not isinstance(geom, dict) or "type" not in geom:
        raise ValueError(f"{where}: expected a GeoJSON geometry object, got {type(geom).__name__}")
    kind = geom["type"]
    coords = geom.get("coordinates")
    # GeoJSON exports mix geometry types: what has no line draws nothing (points; an empty geometry, which RFC 7946
    # allows), a polygon draws its rings as closed lines, a collection its members -- one such feature refused the
    # whole file ("expected a LineString ... got 'Point'")
    if kind in ("Point", "MultiPoint") or (kind in _LINE_KINDS and isinstance(coords, list) and not coords):
        return []
    if kind == "LineString":
        return _coords_lines(coords, where, multi=False)
    if kind == "MultiLineString":
        return _coords_lines(coords, where, multi=True)
    if kind == "Polygon":   # [ring, ...], each ring closed: its first position repeated last
        return _coords_lines(coords, where, multi=True)
    if kind == "MultiPolygon":   # [polygon, ...]
        if not isinstance(coords, list) or not all(isinstance(p, list) for p in coords):
            raise ValueError(f"{where}: expected MultiPolygon coordinates [[[[x, y], ...], ...], ...], "
                             f"got {coords!r:.60}")
        return [ring for j, poly in enumerate(coords) if poly
                for ring in _coords_lines(poly, f"{where}: polygon {j}", multi=True)]
    if kind == "GeometryCollection":
        members = geom.get("geometries")
        if not isinstance(members, list):
            raise ValueError(f"{where}: expected 'geometries' to be a list, got {type(members).__name__}")
        return [line for j, g in enumerate(members) for line in (_geometry_lines(g, f"{where}: geometry {j}") or [])]
    raise ValueError(f"{where}: expected a GeoJSON geometry (LineString, MultiLineString, Polygon, ...), got {kind!r}")


_LINE_KINDS = ("LineString", "MultiLineString", "Polygon", "MultiPolygon")


def _positions(line) -> np.ndarray | None:
    """One line's positions as float64 (N, k): at once where every position has as many numbers, else one by
    one, keeping x and y (GeoJSON lets a position carry a third number, which is ignored, on some points only);
    None where a position is not a list of 2 or more numbers."""
    try:
        return np.asarray(line, dtype=np.float64)
    except (TypeError, ValueError):  # positions of mixed lengths: numpy refuses the ragged list
        pass
    try:
        if isinstance(line, (str, bytes)) or any(isinstance(p, (str, bytes)) or len(p) < 2 for p in line):
            return None
        return np.array([[float(p[0]), float(p[1])] for p in line], dtype=np.float64)
    except (TypeError, ValueError):
        return None


def _coords_lines(coords, where: str, multi: bool | None = None) -> list[np.ndarray]:
    """LineString ([[x, y], ...]) or MultiLineString ([[[x, y], ...], ...]) coordinates."""
    try:
        a = [np.asarray(c, dtype=np.float64) if multi is False else _positions(c) for c in coords] \
            if coords is not None else None
    except (TypeError, ValueError):
        a = None
    if a is None or len(a) == 0 or any(p is None for p in a):
        raise ValueError(f"{where}: expected coordinates [[x, y], ...], got {coords!r:.60}")
    if multi is None:
        multi = a[0].ndim == 2
    parts = a if multi else [_positions(coords)]
    out = []
    for j, p in enumerate(parts):
        if p is None or p.ndim != 2 or p.shape[1] < 2 or len(p) < 1:
            raise ValueError(f"{where}: line {j}: expected positions [[x, y], ...], got "
                             f"{'a position of fewer than 2 numbers' if p is None else f'shape {p.shape}'}")
        if not np.isfinite(p[:, :2]).all():
            raise ValueError(f"{where}: line {j}: expected finite coordinates, got NaN or infinity")
        out.append(np.ascontiguousarray(p[:, :2]))
    return out


def _style_from(props: dict, where: str) -> LineStyle:
    d = LineStyle()
    try:
        st = LineStyle(
            width=float(props.get("width", d.width)),
            color=parse_color(props.get("color", "#ffffff"), f"{where}: color"),
            outline=parse_color(props.get("outline", "#000000"), f"{where}: outline"),
            outline_width=float(props.get("outline_width", d.outline_width)),
            opacity=float(props.get("opacity", d.opacity)),
            cap=str(props.get("cap", d.cap)))
    except (TypeError, ValueError) as exc:
        if str(exc).startswith(where):
            raise
        raise ValueError(f"{where}: expected numbers for width, outline_width and opacity ({exc})") from None
    st.check(where)
    return st


def _frame_range(props: dict, key: str, where: str) -> int | None:
    v = props.get(key)
    if v is None:
        return None
    if not isinstance(v, int) or isinstance(v, bool) or v < 0:
        raise ValueError(f"{where}: expected {key} to be a frame index >= 0, got {v!r}")
    return v


def parse_overlay(doc: dict, name: str = "overlay") -> list[OverlayFeature]:
    """Features of an overlay document (GeoJSON FeatureCollection, Feature or line geometry)."""
    if not isinstance(doc, dict) or "type" not in doc:
        raise ValueError(f"{name}: expected a GeoJSON object with a 'type', got {type(doc).__name__}")
    if doc["type"] == "FeatureCollection":
        feats = doc.get("features")
        if not isinstance(feats, list):
            raise ValueError(f"{name}: expected 'features' to be a list, got {type(feats).__name__}")
    elif doc["type"] == "Feature":
        feats = [doc]
    else:
        feats = [{"type": "Feature", "geometry": doc, "properties": {}}]
    out = []
    for i, f in enumerate(feats):
        where = f"{name}: feature {i}"
        if not isinstance(f, dict) or f.get("type") != "Feature":
            raise ValueError(f"{where}: expected a GeoJSON Feature, got {str(f)[:60]}")
        props = f.get("properties") or {}
        if not isinstance(props, dict):
            raise ValueError(f"{where}: expected 'properties' to be an object, got {type(props).__name__}")
        style = _style_from(props, where)
        lines = _geometry_lines(f.get("geometry"), where)
        frames: dict[int, list[np.ndarray]] = {}
        raw = props.get("frames") or {}
        if not isinstance(raw, dict):
            raise ValueError(f"{where}: expected 'frames' to map frame indices to coordinates, "
                             f"got {type(raw).__name__}")
        for key, coords in raw.items():
            try:
                idx = int(key)
                if idx < 0 or str(idx) != str(key).strip():
                    raise ValueError
            except ValueError:
                raise ValueError(f"{where}: expected frame indices >= 0 as keys of 'frames', "
                                 f"got {key!r}") from None
            frames[idx] = _coords_lines(coords, f"{where}: frame {idx}")
        if lines is None and not frames:
            raise ValueError(f"{where}: expected a geometry or 'frames', got neither")
        out.append(OverlayFeature(style, lines, frames, _frame_range(props, "first_frame", where),
                                  _frame_range(props, "last_frame", where)))
    return out


def read_overlay(path: str) -> list[OverlayFeature]:
    """Parse an overlay file (JSON/GeoJSON, docs/grlaa.md); errors name the file and feature."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except OSError as exc:
        raise ValueError(f"{path}: cannot read ({exc.strerror})") from exc
    try:
        # bytes: json detects UTF-8 with a byte order mark (Windows editors write one: "Unexpected UTF-8 BOM"
        # before) and UTF-16/32, as RFC 8259 lets a reader
        doc = json.loads(raw)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: expected JSON, got an error at line {exc.lineno} "
                         f"column {exc.colno}: {exc.msg}") from exc
    except UnicodeDecodeError as exc:  # named the codec, not the file
        raise ValueError(f"{path}: expected JSON text (UTF-8), got bytes that are not text ({exc.reason} at "
                         f"byte {exc.start})") from exc
    return parse_overlay(doc, os.fspath(path))


def load_overlay(path: str, bgr: bool = True, device: str | int | None = None,
                 strength: float = 1.0, linear: bool = False,
                 inplace: bool = False) -> Callable[..., np.ndarray]:
    """Read an overlay file once; returns draw(frame, index, linear=None) -> frame with that frame's lines drawn.

    `bgr` is the channel order of the frames it will get (file colours are always RGB). `linear`: the frames hold
    linear light (EXR) instead of sRGB codes; draw's own `linear` says it for one frame (a folder mixing EXR and
    PNG), and its `premultiplied` that a 4-channel frame's colour is premultiplied by its alpha (an EXR's RGBA):
    the command line passes both for each frame, as draw's `per_frame_format` attribute says it may.
    """
    features = read_overlay(path)
    renderers: dict[bool, OverlayRenderer] = {}   # one per kind of frame: the renderer's kernel is built for one

    def draw(frame: np.ndarray, index: int, linear: bool | None = None, premultiplied: bool = False) -> np.ndarray:
        lines, styles = [], []
        for f in features:
            for ln in f.lines_at(int(index)):
                lines.append(ln)
                styles.append(f.style)
        if not lines:
            return frame if inplace else frame.copy()
        lin = default_linear if linear is None else bool(linear)
        if lin not in renderers:
            renderers[lin] = OverlayRenderer(device, strength, linear=lin)
        return renderers[lin].draw_styled(frame, lines, styles, bgr=bgr, inplace=inplace, what=f"frame {index}",
                                          premultiplied=premultiplied)

    default_linear = bool(linear)
    draw.features = features  # type: ignore[attr-defined]
    draw.per_frame_format = True  # type: ignore[attr-defined]
    return draw


# ---------------------------------------------------------------------------- numpy reference

def footprint_cdf(s: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Coverage of the half-plane {u <= s} by a box pixel whose projected footprint on the
    normal is U(a) + U(b), a >= b (reference of kernels/grlaa.cl footprint_cdf)."""
    s, a, b = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (s, a, b)))
    x = s + 0.5 * (a + b)
    ab2 = np.where(a * b > 0, 2 * a * b, 1.0)
    y = a + b - x
    out = np.where(x < b, x * x / ab2,
                   np.where(x <= a, (x - 0.5 * b) / np.where(a > 0, a, 1.0), 1.0 - y * y / ab2))
    return np.where(x <= 0, 0.0, np.where(x >= a + b, 1.0, out))


def _segment_cover(px, py, seg, meta, r, ri, strength):
    """(outer, inner) coverage of one segment's stroke at pixel centres (px, py)."""
    ax, ay, bx, by = (float(v) for v in seg)
    dx, dy = bx - ax, by - ay
    ln = math.hypot(dx, dy)
    tx, ty = (dx / ln, dy / ln) if ln > 0 else (1.0, 0.0)
    apx, apy = px - ax, py - ay
    along = apx * tx + apy * ty
    round_ = ((ln <= 0) & (not meta & 3)) | ((along < 0) & (not meta & 1)) | \
        ((along > ln) & (not meta & 2))
    vx = np.where(along < 0, apx, px - bx)
    vy = np.where(along < 0, apy, py - by)
    vd = np.hypot(vx, vy)
    safe = round_ & (vd > 1e-6)
    nx = np.where(safe, vx / np.where(safe, vd, 1), -ty)
    ny = np.where(safe, vy / np.where(safe, vd, 1), tx)
    dist = np.where(round_, vd, np.abs(tx * apy - ty * apx))
    na, nb = np.abs(nx) * strength, np.abs(ny) * strength
    fa, fb = np.maximum(na, nb), np.minimum(na, nb)
    co = footprint_cdf(r - dist, fa, fb) - footprint_cdf(-r - dist, fa, fb)
    ci = (footprint_cdf(ri - dist, fa, fb) - footprint_cdf(-ri - dist, fa, fb)) if ri > 0 \
        else np.zeros_like(co)
    if meta & 3:
        ta, tb = max(abs(tx), abs(ty)) * strength, min(abs(tx), abs(ty)) * strength
        ext = r if meta & 4 else 0.0
        ext_i = ext - (r - ri)
        if meta & 1:
            co = co * footprint_cdf(along + ext, ta, tb)
            ci = ci * footprint_cdf(along + ext_i, ta, tb)
        if meta & 2:
            co = co * footprint_cdf(ln - along + ext, ta, tb)
            ci = ci * footprint_cdf(ln - along + ext_i, ta, tb)
    return co, ci


def polyline_coverage(tables: SegmentTables, k: int, height: int, width: int,
                      strength: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(outer, inner) coverage of polyline k over a height x width frame (max over its segments)."""
    a_out = np.zeros((height, width))
    a_in = np.zeros((height, width))
    r, ri = float(tables.polys[k, 0, 0]), float(tables.polys[k, 0, 1])
    for s in np.flatnonzero((tables.meta >> 3) == k):
        seg = tables.ends[s]
        pad = tables.reach[s]
        x0 = max(int(math.floor(min(seg[0], seg[2]) - pad)), 0)
        x1 = min(int(math.ceil(max(seg[0], seg[2]) + pad)) + 1, width)
        y0 = max(int(math.floor(min(seg[1], seg[3]) - pad)), 0)
        y1 = min(int(math.ceil(max(seg[1], seg[3]) + pad)) + 1, height)
        if x0 >= x1 or y0 >= y1:
            continue
        py, px = np.mgrid[y0:y1, x0:x1].astype(np.float64)
        co, ci = _segment_cover(px, py, seg, int(tables.meta[s]), r, ri, strength)
        np.maximum(a_out[y0:y1, x0:x1], co, out=a_out[y0:y1, x0:x1])
        np.maximum(a_in[y0:y1, x0:x1], ci, out=a_in[y0:y1, x0:x1])
    return a_out, a_in


def reference_draw_polylines(frame: np.ndarray, lines, width=2.0, color="#ffffff",
                             outline="#000000", outline_width=0.0, opacity=1.0, cap="round",
                             bgr: bool = True, strength: float = 1.0,
                             linear: bool = False) -> np.ndarray:
    """Plain numpy version of kernels/grlaa.cl (no tiles: every pixel tests every segment)."""
    fmt = frame_format(frame, bgr=bgr)
    pts = as_lines(lines)
    styles = make_styles(len(pts), width, color, outline, outline_width, opacity, cap, bgr)
    tables = segment_tables(pts, styles, fmt.channels, linear, strength)
    h, w, c = fmt.height, fmt.width, fmt.channels
    pmax = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(fmt.dtype, 1.0)
    px = np.asarray(frame, dtype=np.float64).reshape(h, w, c) / pmax
    rgb = px[..., :3] if c >= 3 else np.repeat(px[..., :1], 3, axis=2)
    if fmt.bgr:
        rgb = rgb[..., ::-1]
    alpha = px[..., 3].copy() if c == 4 else np.ones((h, w))
    luts = device_luts()
    enc = luts[2 * (LUT_SIZE + 1):]
    lin = rgb.copy() if linear else np.where(rgb > 1, ((rgb + 0.055) / 1.055) ** 2.4, lut_read(luts, rgb))
    touched = np.zeros((h, w), bool)
    exact = np.zeros((h, w), np.int64)
    for k in range(len(pts)):
        a_out, a_in = polyline_coverage(tables, k, h, w, strength)
        m = a_out > 0
        if not m.any():
            continue
        op = float(tables.polys[k, 0, 2])
        A = a_out * op
        col = op * (a_in[..., None] * tables.polys[k, 1, :3] +
                    (a_out - a_in)[..., None] * tables.polys[k, 2, :3])
        if c == 4:
            na = A + (1 - A) * alpha
            new = np.where(na[..., None] > 0, (col + ((1 - A) * alpha)[..., None] * lin)
                           / np.where(na > 0, na, 1)[..., None], 0.0)
            alpha = np.where(m, na, alpha)
        else:
            new = col + (1 - A)[..., None] * lin
        lin = np.where(m[..., None], new, lin)
        ex = np.where((A >= 1) & (a_in >= 1), 1 + 2 * k, np.where((A >= 1) & (a_in <= 0), 2 + 2 * k, 0))
        exact = np.where(m, ex, exact)
        touched |= m
    alpha = np.where(exact > 0, 1.0, alpha)
    byte = fmt.dtype == np.uint8 and not linear  # the kernel encodes these through enc8, to bytes
    if byte:
        out_rgb = enc8_read(enc8_table(), lin).astype(np.float64)
        alpha = to_byte(alpha).astype(np.float64)
    else:
        out_rgb = lin if linear else np.where(lin > 1, 1.055 * np.abs(lin) ** (1 / 2.4) - 0.055,
                                              lut_read(enc, lin))
    for k in range(len(pts)):
        for j, sel in ((0, exact == 1 + 2 * k), (1, exact == 2 + 2 * k)):
            col = tables.polys[k, 3 + j, :3]
            out_rgb[sel] = to_byte(col) if byte else col
    if fmt.bgr:
        out_rgb = out_rgb[..., ::-1]
    res = np.concatenate([out_rgb, alpha[..., None]], axis=2)[..., :c] if c >= 3 else out_rgb[..., :1]
    if pmax != 1.0 and not byte:
        res = np.clip(np.rint(res * pmax), 0, pmax)
    out = np.asarray(frame).reshape(h, w, c).copy()
    out[touched] = res[touched].astype(out.dtype)
    return out.reshape(np.shape(frame))
