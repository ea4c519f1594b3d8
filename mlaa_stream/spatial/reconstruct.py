"""Topological reconstruction of sub-pixel features (seed 000 §4), plus two rules beyond the paper.

A pixel A whose 3x3 ring splits into "X" (colour differs from A by more than a CIELAB ΔE threshold)
and "X-bar" is replaced by the mean colour of X where X is a broken thin shape that A reconnects
(connexity numbers, seed 000 eq. 4). See docs/reconstruct.md for the rules and the measurements.
"""
from __future__ import annotations

import functools

import numpy as np

from mlaa_stream.device.colour import device_luts, lut_read, rgb_to_lab as _lab_exact
from mlaa_stream.device.context import Context, check_pass_buffers, default_context, linear_levels
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, defines_for, frame_format

try:
    import pyopencl as cl
except ImportError:  # pragma: no cover - device.py reports broken installs
    cl = None

DEFAULT_THRESHOLD = 10.0  # CIELAB ΔE76: "differs from A" (seed 000 §4.3)

# The ring N8*(A) in clockwise order; bit k of a neighbourhood mask is RING[k] = (dx, dy).
RING: tuple[tuple[int, int], ...] = ((-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0))


# ----------------------------------------------------------------------------------------------
# Tables over the 256 neighbourhood masks
# ----------------------------------------------------------------------------------------------

def _components(mask: int) -> list[list[int]]:
    """The 8-connected components of N8*(A) ∩ X (X given as a ring mask), as lists of ring indices."""
    left = [k for k in range(8) if mask >> k & 1]
    comps = []
    while left:
        stack = [left.pop(0)]
        comp = list(stack)
        while stack:
            k = stack.pop()
            for j in list(left):
                if max(abs(RING[k][0] - RING[j][0]), abs(RING[k][1] - RING[j][1])) == 1:
                    left.remove(j)
                    comp.append(j)
                    stack.append(j)
        comps.append(sorted(comp))
    return comps


@functools.lru_cache(maxsize=None)
def _connexity() -> np.ndarray:
    return np.array([len(_components(m)) for m in range(256)], dtype=np.uint8)


def connexity_table() -> np.ndarray:
    """T8(A, X) for every ring mask X (seed 000 eq. 4): 8-components of N8*(A) ∩ X, all 8-adjacent to A."""
    return _connexity().copy()


@functools.lru_cache(maxsize=None)
def _gap() -> np.ndarray:
    table = np.zeros(256, dtype=np.uint8)
    t8 = _connexity()
    for m in range(256):
        comps = _components(m)
        if len(comps) != 2 or max(len(c) for c in comps) > 2:
            continue  # not two thin pieces
        # the pieces lie on opposite sides of A: some pair of pixels at least 135 degrees apart
        if max(min((i - j) % 8, (j - i) % 8) for i in comps[0] for j in comps[1]) < 3:
            continue
        bar = _components(255 ^ m)
        if t8[255 ^ m] == 1 or (len(bar) == 2 and min(len(c) for c in bar) >= 2):
            table[m] = 1
    return table


def gap_table() -> np.ndarray:
    """1 for the ring masks X where A reconnects a broken thin shape: T8(A,X)=2 with both pieces at most
    2 ring pixels and on opposite sides of A, and T8(A,X-bar)=1 (seed 000 §4.2) -- or T8(A,X-bar)=2 with
    both background pieces at least 2 pixels, the horizontal/vertical gap the paper's rule misses."""
    return _gap().copy()


# ----------------------------------------------------------------------------------------------
# The cheap RGB test: a max-channel difference below which ΔE cannot exceed the threshold
# ----------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def _lab_lipschitz(linear_input: bool) -> float:
    """sup over the RGB cube of |J_Lab(rgb) s| for |s|_inf <= 1: ΔE(a, b) <= this * max|a - b|."""
    n = 49
    v = np.linspace(0.0, 1.0, n)
    rgb = np.stack(np.meshgrid(v, v, v, indexing="ij"), -1).reshape(-1, 3)
    h = 1e-4
    best = 0.0
    lab0 = _lab_of(rgb, linear_input)
    jac = []
    for c in range(3):  # one-sided finite differences, stepping inward at the top face
        step = np.zeros(3)
        step[c] = h
        sign = np.where(rgb[:, c:c + 1] > 1 - h, -1.0, 1.0)
        jac.append((_lab_of(rgb + sign * step, linear_input) - lab0) * sign / h)
    for s in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T:
        d = jac[0] * s[0] + jac[1] * s[1] + jac[2] * s[2]
        best = max(best, float(np.sqrt((d * d).sum(1)).max()))
    # the grid can miss the peak between samples and the tables interpolate: a 25% margin
    return 1.25 * best


def _lab_of(rgb: np.ndarray, linear_input: bool) -> np.ndarray:
    from mlaa_stream.device.colour import linear_to_srgb
    return _lab_exact(linear_to_srgb(rgb) if linear_input else rgb)


def cheap_bound(threshold: float, linear_input: bool = False) -> float:
    """Largest max-channel difference (normalised) that provably keeps ΔE76 at or below `threshold`."""
    return float(threshold) / _lab_lipschitz(bool(linear_input))


# ----------------------------------------------------------------------------------------------
# The plain numpy reference
# ----------------------------------------------------------------------------------------------

def _load_rgba(frame: np.ndarray, fmt: FrameFormat) -> np.ndarray:
    """What common.cl's load_px returns, for every pixel: float32 (H, W, 4) normalised RGBA."""
    pmax = np.float32({np.uint8: 255.0, np.uint16: 65535.0}.get(fmt.dtype.type, 1.0))
    a = np.asarray(frame).astype(np.float32).reshape(fmt.height, fmt.width, fmt.channels) * (np.float32(1) / pmax)
    out = np.ones((fmt.height, fmt.width, 4), np.float32)
    if fmt.channels == 1:
        out[..., :3] = a[..., :1]
    else:
        out[..., :3] = a[..., 2::-1] if fmt.bgr else a[..., :3]
        if fmt.channels == 4:
            out[..., 3] = a[..., 3]
    return out


def _lab_f32(rgb: np.ndarray, luts: np.ndarray, linear_input: bool) -> np.ndarray:
    """common.cl's rgb_to_lab in float32, table for table (the reference must agree on the masks)."""
    n = LUT_SIZE + 1
    if linear_input:
        enc = luts[2 * n:]
        rgb = np.stack([lut_read(enc, rgb[..., c]) for c in range(3)], -1)
    r, g, b = (lut_read(luts[:n], rgb[..., c]) for c in range(3))
    f32 = np.float32
    X = (f32(0.4124564) * r + f32(0.3575761) * g + f32(0.1804375) * b) * (f32(1) / f32(0.95047))
    Y = f32(0.2126729) * r + f32(0.7151522) * g + f32(0.0721750) * b
    Z = (f32(0.0193339) * r + f32(0.1191920) * g + f32(0.9503041) * b) * (f32(1) / f32(1.08883))
    ft = luts[n:2 * n]
    fx, fy, fz = lut_read(ft, X), lut_read(ft, Y), lut_read(ft, Z)
    return np.stack([f32(116) * fy - f32(16), f32(500) * (fx - fy), f32(200) * (fy - fz)], -1).astype(np.float32)


def _d2(a: np.ndarray, b: np.ndarray) -> float:
    d = a - b
    return float(d @ d)


def _consistent(labs: list[np.ndarray], t2: float) -> bool:
    """All colours of a shape within the threshold of their mean: the shape has one colour (seed 000 §4.2)."""
    m = np.mean(labs, axis=0)
    return all(_d2(v, m) <= t2 for v in labs)


OUTER: tuple[tuple[int, int], ...] = tuple((dx, dy) for dy in range(-2, 3) for dx in range(-2, 3)
                                          if max(abs(dx), abs(dy)) == 2)  # the 16 pixels at distance 2
MAX_OFFSET = 1.01  # px between the lines through the two pieces (1, plus room for float rounding)
MIN_AIM = 0.7  # cosine between a piece's direction and the way to A: within about 45 degrees
MAX_LINE_PIXELS = 8  # line-coloured pixels a 5x5 window around a gap may hold (a thin line holds 4-6)


def _thin_gap(lab, x, y, mask, c, t2, relaxed):
    """The 5x5 checks that the paper's 3x3 rule lacks (docs/reconstruct.md): every pixel of the window
    is line-coloured (within the threshold of c) or background (within the threshold of A; with
    `relaxed`, nearer to A than to c), at most MAX_LINE_PIXELS are line-coloured, and each piece of
    `mask` continues outward into the window's outer ring (a line end, not a dot or a blob)."""
    h, w = lab.shape[:2]
    a = lab[y, x]
    line = 0
    outer = []
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            px, py = x + dx, y + dy
            if (dx, dy) == (0, 0) or not (0 <= px < w and 0 <= py < h):
                continue
            dc, da = _d2(lab[py, px], c), _d2(lab[py, px], a)
            if dc <= t2:
                line += 1
                if max(abs(dx), abs(dy)) == 2:
                    outer.append((dx, dy))
            elif (da >= dc or da > 4 * t2) if relaxed else (da > t2):
                return False
    if line > MAX_LINE_PIXELS:
        return False
    pieces = []
    for comp in _components(mask):
        # the piece's direction: from its outer-ring line pixels to its ring pixels; A must lie ahead
        touch = [(ox, oy) for ox, oy in outer if any(max(abs(ox - RING[k][0]), abs(oy - RING[k][1])) == 1
                                                    for k in comp)]
        if not touch:
            return False
        px = sum(RING[k][0] for k in comp) / len(comp)
        py = sum(RING[k][1] for k in comp) / len(comp)
        vx = px - sum(o[0] for o in touch) / len(touch)
        vy = py - sum(o[1] for o in touch) / len(touch)
        vn = np.hypot(vx, vy)
        if vn == 0 or -(px * vx + py * vy) < MIN_AIM * np.hypot(px, py) * vn:
            return False
        pieces.append((px, py, vx / vn, vy / vn))
    # one line, not two parallel strokes: the pieces' lines (mean direction) at most 1 px apart
    (p1x, p1y, u1x, u1y), (p2x, p2y, u2x, u2y) = pieces
    ux, uy = u1x - u2x, u1y - u2y
    un = np.hypot(ux, uy)
    return un > 0 and abs((p2x - p1x) * uy - (p2y - p1y) * ux) <= MAX_OFFSET * un


def _decide(lab, rgba, x, y, t2, extended):
    """The reconstructed RGB of pixel (x, y), or None. Mirrors kernels/reconstruct.cl rule for rule."""
    h, w = lab.shape[:2]
    gap = _gap()
    a = lab[y, x]
    ring = [(x + dx, y + dy) for dx, dy in RING]
    valid = [0 <= px < w and 0 <= py < h for px, py in ring]
    n = [lab[py, px] if ok else a for (px, py), ok in zip(ring, valid)]
    dA = [_d2(v, a) for v in n]
    X = sum(1 << k for k in range(8) if valid[k] and dA[k] > t2)
    if X == 0:
        return None

    def mean_rgb(mask):
        return np.mean([rgba[ring[k][1], ring[k][0], :3] for k in range(8) if mask >> k & 1], axis=0)

    def shape(mask):
        """The shape's mean Lab if `mask` is a one-coloured broken thin shape, else None."""
        if not gap[mask]:
            return None
        labs = [n[k] for k in range(8) if mask >> k & 1]
        return np.mean(labs, axis=0) if _consistent(labs, t2) else None

    # seed 000 §4.2: T8(A, X) = 2, T8(A, X-bar) = 1 (gap_table), X of one colour; plus the 5x5 checks
    c = shape(X)
    if c is not None and _thin_gap(lab, x, y, X, c, t2, False):
        return mean_rgb(X)
    if not extended:
        return None
    # beyond the paper, (1): X relative to a line colour n[k] -- the neighbours nearer to it than to A
    for k in range(8):
        if not X >> k & 1:
            continue
        xk = sum(1 << j for j in range(8) if X >> j & 1 and _d2(n[j], n[k]) < dA[j])
        c = shape(xk)
        if xk != X and c is not None and _d2(c, a) > 9 * t2 and _thin_gap(lab, x, y, xk, c, t2, True):
            return mean_rgb(xk)
    # beyond the paper, (2): a gap of two pixels, A and B, in a straight line: q2 q1 A B q3 q4
    for k in range(8):
        if not X >> k & 1:
            continue
        dx, dy = RING[k]
        pts = [(x + dx, y + dy), (x + 2 * dx, y + 2 * dy), (x - 2 * dx, y - 2 * dy), (x - 3 * dx, y - 3 * dy)]
        bx, by = x - dx, y - dy
        if not all(0 <= px < w and 0 <= py < h for px, py in pts + [(bx, by)]):
            continue
        line = [lab[py, px] for px, py in pts]
        if not _consistent(line, t2):
            continue
        c = np.mean(line, axis=0)
        b = lab[by, bx]
        if not (_d2(a, b) <= t2 and _d2(a, c) > 9 * t2 and _d2(b, c) > 9 * t2):
            continue  # A and B: one background colour, the line's at least 3 thresholds away
        # thin, on a plain background: every other pixel around A or B is background, none line-coloured
        others = set()
        for cx, cy in ((x, y), (bx, by)):
            for ex, ey in RING:
                others.add((cx + ex, cy + ey))
        others -= {(x, y), (bx, by), pts[0], pts[2]}
        if all(_d2(lab[py, px], c) > t2 and min(_d2(lab[py, px], a), _d2(lab[py, px], b)) <= t2
               for px, py in others if 0 <= px < w and 0 <= py < h):
            return np.mean([rgba[py, px, :3] for px, py in pts], axis=0)
    return None


def _store(rgb: np.ndarray, fmt: FrameFormat, dtype: np.dtype) -> np.ndarray:
    """store_px for one pixel's RGB: the stored channel values (alpha left to the caller)."""
    if fmt.channels == 1:
        v = rgb[:1]
    else:
        v = rgb[::-1] if fmt.bgr else rgb
    if np.dtype(dtype).kind == "f":
        return v.astype(dtype)
    pmax = np.iinfo(dtype).max
    return np.clip(np.rint(v.astype(np.float64) * pmax), 0, pmax).astype(dtype)


def reconstruct_reference(frame: np.ndarray, *, threshold: float = DEFAULT_THRESHOLD, extended: bool = True,
                          bgr: bool = False, linear_input: bool = False) -> np.ndarray:
    """Plain numpy version of the pass (slow, obvious): the kernel is tested against it."""
    fmt = frame_format(frame, bgr)
    rgba = _load_rgba(np.asarray(frame, dtype=np.float32) if frame.dtype == np.float16 else frame, fmt)
    lab = _lab_f32(rgba[..., :3], device_luts(), linear_input)
    out = np.array(frame, copy=True)
    view = out.reshape(fmt.height, fmt.width, fmt.channels)
    t2 = float(np.float32(threshold) * np.float32(threshold))
    # only pixels with a differing neighbour can change (the kernel's early exit is an optimisation)
    pad = np.pad(lab, ((1, 1), (1, 1), (0, 0)), mode="edge")
    near = np.zeros(lab.shape[:2], bool)
    for dx, dy in RING:
        d = pad[1 + dy:1 + dy + fmt.height, 1 + dx:1 + dx + fmt.width] - lab
        near |= (d * d).sum(-1) > t2
    for y, x in zip(*np.nonzero(near)):
        rgb = _decide(lab, rgba, x, y, t2, extended)
        if rgb is not None:
            view[y, x, :3 if fmt.channels >= 3 else 1] = _store(rgb, fmt, out.dtype)
    return out


# ----------------------------------------------------------------------------------------------
# The OpenCL pass
# ----------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=None)
def _device_table() -> np.ndarray:
    """kernels/reconstruct.cl's table: bit 0 = gap_table, bit 1 = a sub-mask is a gap, bits 8..15 = the first
    8-component of X."""
    gap = _gap()
    possible = gap.astype(bool).copy()
    for m in range(256):  # increasing order: every sub-mask is settled before its supersets
        possible[m] |= any(possible[m & ~(1 << k)] for k in range(8) if m >> k & 1)
    table = np.zeros(256, dtype=np.uint32)
    for m in range(256):
        comps = _components(m)
        first = sum(1 << k for k in comps[0]) if comps else 0
        table[m] = int(gap[m]) | int(possible[m]) << 1 | first << 8
    return table


SEGMENT = 64  # pixels of a row per work item (kernels/common.cl), as in the core filter's passes
STRIP = 16  # rows per work item: each keeps the CIELAB of its last rows for the next


def cheap_levels(threshold: float, pixel_max: float, linear_input: bool = False) -> tuple[int, int]:
    """For integer frames: the smallest max-channel differences, in stored levels, at which ΔE76 may exceed
    `threshold` and 2 * `threshold` (cheap_bound: ΔE <= Lipschitz * difference)."""
    bound = cheap_bound(threshold, linear_input) * float(pixel_max)
    return int(np.floor(bound)) + 1, int(np.floor(2.0 * bound)) + 1


class Reconstructor:
    """The reconstruction pass for one frame format: program built, tables and scratch allocated once, then
    `enqueue` per frame (src -> dst, laid out like the frame). One kernel (kernels/reconstruct.cl): RGB bounds
    first, CIELAB a lane per pixel where a rule may fire, the rules where the exact ring masks allow."""

    def __init__(self, context: Context, fmt: FrameFormat, *, threshold: float = DEFAULT_THRESHOLD,
                 extended: bool = True, linear_input: bool = False):
        if not threshold > 0:
            raise ValueError(f"reconstruct: expected a ΔE threshold > 0, got {threshold}")
        self.context, self.fmt = context, fmt
        self.threshold, self.extended = float(threshold), bool(extended)
        integer = fmt.dtype.kind != "f"
        pmax = float(np.iinfo(fmt.dtype).max) if integer else 1.0
        near, far = cheap_levels(threshold, pmax, linear_input) if integer else (0, 0)
        defines = defines_for(fmt, CHEAP_BOUND=cheap_bound(threshold, linear_input), CHEAP_LEVELS=near,
                              FAR_LEVELS=far, EXTENDED=int(extended), LINEAR_INPUT=int(linear_input),
                              MAX_LINE_PIXELS=MAX_LINE_PIXELS, MIN_AIM=float(MIN_AIM),
                              MAX_OFFSET=float(MAX_OFFSET), SEGMENT=SEGMENT, STRIP=STRIP)
        self.defines = defines  # the build defines (tests build reconstruct_lab_check with them)
        self._kernel = context.kernel("reconstruct", "reconstruct", defines)
        mf = cl.mem_flags
        self._table = cl.Buffer(context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=_device_table())
        self._t2 = np.float32(np.float32(threshold) * np.float32(threshold))
        # a work item per SEGMENT pixels of STRIP rows, each with CIELAB scratch for 3 rows of its segment
        self._global = (-(-fmt.width // SEGMENT), -(-fmt.height // STRIP))
        self._scratch = context.buffer(4 * 3 * 3 * (SEGMENT + 8) * self._global[0] * self._global[1])
        # CPU devices: a work group per row of work items (left to PoCL, this small grid became one group, one
        # thread); other devices choose their own
        cpu = context.device.type & cl.device_type.CPU
        self._local = (self._global[0], 1) if cpu else None
        # integer frames: sRGB->linear per stored level, filled once on the device with common.cl's lut_read
        luts = cl.Buffer(context.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=device_luts())
        self._lin = linear_levels(context, "reconstruct", defines, fmt, luts)
        self._last = None  # this pass's previous frame: its scratch is reused

    def enqueue(self, queue: "cl.CommandQueue", src: "cl.Buffer", dst: "cl.Buffer", luts: "cl.Buffer",
                wait_for: list | None = None) -> "cl.Event":
        """Enqueue the pass on `queue`: dst = src except reconstructed pixels; returns the kernel's event."""
        check_pass_buffers("reconstruct", self.fmt, src, dst)
        W, H = np.int32(self.fmt.width), np.int32(self.fmt.height)
        after = list(wait_for or []) + ([self._last] if self._last is not None else [])
        # dst = src first (a device copy, ~0.3 ms at 1080p); the kernel then writes changed pixels only
        copied = cl.enqueue_copy(queue, dst, src, byte_count=self.fmt.nbytes, wait_for=after)
        self._last = self._kernel(queue, self._global, self._local, src, dst, luts, self._lin, self._scratch,
                                  self._table, W, H, self._t2, wait_for=[copied])
        return self._last


def reconstruct(frame: np.ndarray, *, threshold: float = DEFAULT_THRESHOLD, extended: bool = True,
                device=None, bgr: bool = False, linear_input: bool = False) -> np.ndarray:
    """Run the pass on one frame (upload, kernel, download); same shape and dtype as `frame`."""
    fmt = frame_format(frame, bgr)
    ctx = default_context(device)
    host = np.ascontiguousarray(frame, dtype=fmt.dtype)
    mf = cl.mem_flags
    src = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=host)
    dst = ctx.buffer(fmt.nbytes)
    luts = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=device_luts())
    rec = Reconstructor(ctx, fmt, threshold=threshold, extended=extended, linear_input=linear_input)
    out = np.empty_like(host)
    rec.enqueue(ctx.queue, src, dst, luts)
    cl.enqueue_copy(ctx.queue, out, dst)
    return out.astype(frame.dtype, copy=False).reshape(frame.shape)
