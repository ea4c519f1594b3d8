"""Plain numpy references of the MLAA passes (slow, obvious) that the OpenCL kernels are tested against.

Each function mirrors one kernel file: edges.cl, distances.cl, weights.cl, blend.cl.
"""
from __future__ import annotations

import numpy as np

from mlaa_stream.device.colour import LUMA, linear_to_srgb, rgb_to_lab, srgb_to_linear
from mlaa_stream.spatial.filter import (AA_LO, AA_NEAR, AA_OFF, DEFAULT_THRESHOLDS, SHORT_CORNER, SUBPIXEL,
                                        SUBPIXEL_BG, SUBPIXEL_END, SUBPIXEL_SHARE, ramp_fraction, trapezoid_area)

BOTTOM, RIGHT = 1, 2
BOTH = 2  # an end crossed on both sides


def normalised_rgb(frame: np.ndarray, bgr: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
    """(H, W, 3) float64 colour in [0, 1] (grey repeated) and the alpha channel, if any."""
    f = frame.astype(np.float64)
    if frame.dtype == np.uint8:
        f /= 255.0
    elif frame.dtype == np.uint16:
        f /= 65535.0
    if f.ndim == 2:
        f = f[..., None]
    alpha = f[..., 3] if f.shape[2] == 4 else None
    rgb = np.repeat(f, 3, axis=2) if f.shape[2] == 1 else f[..., :3]
    if bgr and f.shape[2] >= 3:
        rgb = rgb[..., ::-1]
    return rgb, alpha


def edges_reference(frame: np.ndarray, threshold: float | None = None, metric: str = "lab",
                    bgr: bool = False, linear_input: bool = False, ramp: float = 0.35,
                    aa_guard: bool = True) -> np.ndarray:
    """Bit 0: colour differs from the pixel below; bit 1: from the pixel to the right.
    Ramps (the colour keeps moving the same way one pixel further out, by more than `ramp` times
    the step, on the channel of the largest step) are not edges."""
    thr = DEFAULT_THRESHOLDS[metric] if threshold is None else threshold
    rgb, _ = normalised_rgb(frame, bgr)
    if linear_input:
        rgb = linear_to_srgb(rgb)

    def differ(a: np.ndarray, b: np.ndarray) -> np.ndarray:
        if metric == "lab":
            return np.linalg.norm(rgb_to_lab(a) - rgb_to_lab(b), axis=-1) > thr
        if metric == "luma":
            return np.abs((a - b) @ LUMA) > thr
        return np.abs(a - b) @ LUMA > thr

    # Integer frames: the ramp test runs exactly on the stored samples, with `ramp` as a fraction
    # (as kernels/edges.cl does); float frames compare in floats.
    exact = np.issubdtype(frame.dtype, np.integer) and not linear_input
    num, den = ramp_fraction(ramp)
    samples = rgb
    if exact:
        f = frame.astype(np.int64)
        f = f[..., None] if f.ndim == 2 else f
        samples = np.repeat(f, 3, axis=2) if f.shape[2] == 1 else f[..., :3]
        if bgr and f.shape[2] >= 3:
            samples = samples[..., ::-1]

    def ramp_along(c: np.ndarray) -> np.ndarray:
        """For steps c[k] -> c[k+1] along axis 0: is it part of a ramp?"""
        p, q = c[:-1], c[1:]
        d = q - p
        k = np.argmax(np.abs(d), axis=-1)[..., None]
        d1 = np.take_along_axis(d, k, -1)[..., 0]
        before = np.concatenate([p[:1], c[:-2]])   # the pixel before p (p itself at the border)
        after = np.concatenate([c[2:], q[-1:]])    # the pixel after q (q itself at the border)
        d0 = np.take_along_axis(p - before, k, -1)[..., 0]
        d2 = np.take_along_axis(after - q, k, -1)[..., 0]
        if exact:
            lim = num * np.abs(d1)
            return (((d0 * d1 > 0) & (np.abs(d0) * den > lim)) |
                    ((d2 * d1 > 0) & (np.abs(d2) * den > lim)))
        lim = ramp * np.abs(d1)
        return ((d0 * d1 > 0) & (np.abs(d0) > lim)) | ((d2 * d1 > 0) & (np.abs(d2) > lim))

    def between(m: np.ndarray, p: np.ndarray, d: np.ndarray, dd: np.ndarray,
                lo: float = AA_LO, hi: float = 1.0 - AA_LO) -> np.ndarray:
        v = m - p
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (v * d).sum(-1) / dd
        r = v - t[..., None] * d
        return (t > lo) & (t < hi) & ((r * r).sum(-1) <= AA_OFF * AA_OFF * dd) & (dd > 0)

    def antialiased_along(c: np.ndarray) -> np.ndarray:
        """For steps c[k] -> c[k+1] along axis 0: does a neighbour along the step (axis 1) of
        either pixel hold a colour between the two (beside p: more than AA_NEAR of the way from p;
        beside q: more than AA_NEAR from q), or is either pixel between its neighbours across the
        step (an already antialiased edge)?"""
        p, q = c[:-1], c[1:]
        d = q - p
        dd = (d * d).sum(-1)
        out = np.zeros(dd.shape, bool)
        # across: p between the pixel before it and q, or q between p and the pixel after it
        # (at the frame's border the pixel itself, which is never between)
        before = np.concatenate([p[:1], c[:-2]])
        after = np.concatenate([c[2:], q[-1:]])
        db, da = q - before, after - p
        out |= between(p, before, db, (db * db).sum(-1))
        out |= between(q, p, da, (da * da).sum(-1))
        for sl_m, sl_o in ((np.s_[:, :-1], np.s_[:, 1:]), (np.s_[:, 1:], np.s_[:, :-1])):
            # neighbours at axis-1 offset -1 (for columns 1..) and +1 (for columns ..-2)
            out[sl_o] |= between(p[sl_m], p[sl_o], d[sl_o], dd[sl_o], AA_NEAR, 1.0 - AA_LO)
            out[sl_o] |= between(q[sl_m], p[sl_o], d[sl_o], dd[sl_o], AA_LO, 1.0 - AA_NEAR)
        return out

    e = np.zeros(rgb.shape[:2], np.uint8)
    bottom = differ(rgb[:-1], rgb[1:])
    right = differ(rgb[:, :-1], rgb[:, 1:])
    if ramp > 0:
        bottom &= ~ramp_along(samples)
        right &= ~ramp_along(samples.transpose(1, 0, 2)).T
    if aa_guard:
        bottom &= ~antialiased_along(rgb)
        right &= ~antialiased_along(rgb.transpose(1, 0, 2)).transpose(1, 0)
    e[:-1] |= BOTTOM * bottom.astype(np.uint8)
    e[:, :-1] |= RIGHT * right.astype(np.uint8)
    return e


def _runs(on: np.ndarray, crossed: np.ndarray) -> np.ndarray:
    """For a 1-D line: (distance to run start, distance to run end) where `on`; runs split where
    `crossed[k]` (an edge crosses between k-1 and k)."""
    n = len(on)
    d = np.zeros((n, 2), np.int64)
    k = 0
    while k < n:
        if not on[k]:
            k += 1
            continue
        start = k
        k += 1
        while k < n and on[k] and not crossed[k]:
            k += 1
        for j in range(start, k):
            d[j] = (j - start, k - 1 - j)
    return d


def distances_reference(edges: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """hdist (left, right) along bottom edges and vdist (up, down) along right edges; 0 elsewhere."""
    h, w = edges.shape
    hdist = np.zeros((h, w, 2), np.int64)
    vdist = np.zeros((h, w, 2), np.int64)
    b, r = (edges & BOTTOM) > 0, (edges & RIGHT) > 0
    for y in range(h - 1):
        crossed = np.zeros(w, bool)
        crossed[1:] = r[y, :-1] | r[y + 1, :-1]
        hdist[y] = _runs(b[y], crossed)
    for x in range(w - 1):
        crossed = np.zeros(h, bool)
        crossed[1:] = b[:-1, x] | b[:-1, x + 1]
        vdist[:, x] = _runs(r[:, x], crossed)
    return hdist, vdist


def weights_reference(edges: np.ndarray, hdist: np.ndarray, vdist: np.ndarray,
                      rounding: float = 0.0, blend_u: bool = True,
                      frame: np.ndarray | None = None, short_corner: float = SHORT_CORNER) -> np.ndarray:
    """(top, bottom, left, right) fractions each pixel takes from its neighbours (seed 000 eq. 2).
    With `frame`, a crossing edge counts only if the pixel beyond it has the other side's colour. A 2-px
    crossing at the end of a line of STROKE_END_MIN_L+ pixels whose far end turns back along the line for
    three pixels is a 2-px stroke's square end: a corner, like a 3-px crossing. A U shape of STEM_MIN_L+ pixels
    whose bump is a 1-px line (an edge on its far side at both ends) is a 1-px stroke: areas times STEM_K."""
    from mlaa_stream.spatial.filter import STEM_K, STEM_MIN_L, STROKE_END_MIN_L
    h, w = edges.shape
    out = np.zeros((h, w, 4))
    rgb = None if frame is None else normalised_rgb(frame)[0]

    def turns(beyond: tuple[int, int], towards: tuple[int, int], away: tuple[int, int]) -> bool:
        """Is the pixel at `beyond` (y, x) closer in colour to `towards` than to `away`?"""
        if rgb is None:
            return True
        p = rgb[beyond]
        return float(((p - rgb[towards]) ** 2).sum()) < float(((p - rgb[away]) ** 2).sum())

    def has(x: int, y: int, bit: int) -> bool:
        return 0 <= x < w and 0 <= y < h and bool(edges[y, x] & bit)

    def run(x: int, y: int, bit: int, dx: int, dy: int) -> int:
        """How far a crossing edge continues past its first pixel: 0, 1 or 2 (= 2 or more)."""
        return 0 if not has(x, y, bit) else 1 + int(has(x + dx, y + dy, bit))

    def crossing(a: bool, b: bool, a2: int, b2: int) -> tuple[int, int]:
        """(side: +1 a, -1 b, 0 none, BOTH; corner code: 0 crossing edge 1 px, 1 two, 2 three+)."""
        long_edge = max(a2 if a else 0, b2 if b else 0)
        return (BOTH if a and b else 1 if a else -1 if b else 0), long_edge

    def areas(d0: int, d1: int, s0: int, long0: int, s1: int, long1: int, stem: bool = False) -> tuple[float, float]:
        ta = tb = 0.0
        if s0 == BOTH and s1 != BOTH:  # a thin line crossing: continue opposite to the other end (Z)
            s0 = -s1
        if s1 == BOTH and s0 != BOTH:
            s1 = -s0
        s0, s1 = (0 if s0 == BOTH else s0), (0 if s1 == BOTH else s1)
        if s0 == 0 and s1 == 0:
            return ta, tb
        if s0 == s1 and (not blend_u or long0 or long1):  # U shape: a bump, or the side of a box
            return ta, tb
        scale = STEM_K if s0 == s1 and stem else 1.0  # a U on a 1-px stroke: its ends are square
        length = d0 + d1 + 1
        for s, long_edge, d in ((s0, long0, d0), (s1, long1, d1)):
            if s:
                # 3+ px crossing: a corner (rounding); 2 px: short_corner, none on a 1-px line
                k = (rounding if long_edge == 2 else
                     (0.0 if length == 1 else short_corner) if long_edge == 1 else 1.0)
                a = scale * k * trapezoid_area(d, length)
                if s > 0:
                    ta += a
                else:
                    tb += a
        return ta, tb

    for y in range(h):
        for x in range(w):
            if edges[y, x] & BOTTOM:
                dl, dr = hdist[y, x]
                x0, x1 = x - dl, x + dr
                a0 = has(x0 - 1, y, RIGHT) and turns((y, x0 - 1), (y + 1, x0), (y, x0))
                b0 = has(x0 - 1, y + 1, RIGHT) and turns((y + 1, x0 - 1), (y, x0), (y + 1, x0))
                a1 = has(x1, y, RIGHT) and turns((y, x1 + 1), (y + 1, x1), (y, x1))
                b1 = has(x1, y + 1, RIGHT) and turns((y + 1, x1 + 1), (y, x1), (y + 1, x1))
                s0, k0 = crossing(a0, b0, run(x0 - 1, y - 1, RIGHT, 0, -1), run(x0 - 1, y + 2, RIGHT, 0, 1))
                s1, k1 = crossing(a1, b1, run(x1, y - 1, RIGHT, 0, -1), run(x1, y + 2, RIGHT, 0, 1))
                if dl + dr + 1 >= STROKE_END_MIN_L:  # a 2-px stroke's square end: a corner
                    if s0 in (1, -1) and k0 == 1 and all(has(x0 + t, y - 2 * s0, BOTTOM) for t in range(3)):
                        k0 = 2
                    if s1 in (1, -1) and k1 == 1 and all(has(x1 - t, y - 2 * s1, BOTTOM) for t in range(3)):
                        k1 = 2
                # a U of STEM_MIN_L+ px whose bump row is bordered on its far side at both ends: a 1-px stroke
                row = y - 1 if s0 == 1 else y + 1
                stem = (s0 == s1 and s0 in (1, -1) and dl + dr + 1 >= STEM_MIN_L and
                        has(x0, row, BOTTOM) and has(x1, row, BOTTOM))
                up, down = areas(dl, dr, s0, k0, s1, k1, stem)
                out[y, x, 1] = up
                out[y + 1, x, 0] = down
            if edges[y, x] & RIGHT:
                du, dd = vdist[y, x]
                y0, y1 = y - du, y + dd
                a0 = has(x, y0 - 1, BOTTOM) and turns((y0 - 1, x), (y0, x + 1), (y0, x))
                b0 = has(x + 1, y0 - 1, BOTTOM) and turns((y0 - 1, x + 1), (y0, x), (y0, x + 1))
                a1 = has(x, y1, BOTTOM) and turns((y1 + 1, x), (y1, x + 1), (y1, x))
                b1 = has(x + 1, y1, BOTTOM) and turns((y1 + 1, x + 1), (y1, x), (y1, x + 1))
                s0, k0 = crossing(a0, b0, run(x - 1, y0 - 1, BOTTOM, -1, 0), run(x + 2, y0 - 1, BOTTOM, 1, 0))
                s1, k1 = crossing(a1, b1, run(x - 1, y1, BOTTOM, -1, 0), run(x + 2, y1, BOTTOM, 1, 0))
                if du + dd + 1 >= STROKE_END_MIN_L:
                    if s0 in (1, -1) and k0 == 1 and all(has(x - 2 * s0, y0 + t, RIGHT) for t in range(3)):
                        k0 = 2
                    if s1 in (1, -1) and k1 == 1 and all(has(x - 2 * s1, y1 - t, RIGHT) for t in range(3)):
                        k1 = 2
                col = x - 1 if s0 == 1 else x + 1
                stem = (s0 == s1 and s0 in (1, -1) and du + dd + 1 >= STEM_MIN_L and
                        has(col, y0, RIGHT) and has(col, y1, RIGHT))
                left, right = areas(du, dd, s0, k0, s1, k1, stem)
                out[y, x, 3] = left
                out[y, x + 1, 2] = right
    return out


def grain_mask(frame: np.ndarray) -> np.ndarray:
    """kernels/blend.cl's in_grain for every pixel: its 3x3 window (clamped at the frame's edge) holds only
    pixels that differ from at least GRAIN_MIN of their 8 neighbours (clamped), by GRAIN_STEP / 255 of full
    scale or more in some colour channel (stored values; integer frames in whole levels)."""
    from mlaa_stream.spatial.filter import GRAIN_MIN, GRAIN_STEP
    f = frame if frame.ndim == 3 else frame[..., None]
    f = f[..., :3] if f.shape[2] >= 3 else f[..., :1]
    if f.dtype.kind in "ui":
        x = f.astype(np.int64)
        lim = -(-GRAIN_STEP * int(np.iinfo(f.dtype).max) // 255)
    else:
        x = f.astype(np.float32)
        lim = np.float32(GRAIN_STEP) / np.float32(255.0)
    h, w = x.shape[:2]
    pad = np.pad(x, ((1, 1), (1, 1), (0, 0)), mode="edge")
    count = np.zeros((h, w), np.int32)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            if dx or dy:
                count += (np.abs(pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] - x) >= lim).any(-1)
    busy = np.pad(count >= GRAIN_MIN, 1, mode="edge")
    out = np.ones((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            out &= busy[dy:dy + h, dx:dx + w]
    return out


def blend_reference(frame: np.ndarray, weights: np.ndarray, linear: bool = True,
                    linear_input: bool = False, bgr: bool = False, grain_guard: bool = True,
                    edges: np.ndarray | None = None, subpixel: float = SUBPIXEL) -> np.ndarray:
    """out = c + sum w_k^2 (n_k - c) / sum w_k over the four neighbours (seed 000 §3.5); with `edges`, a
    pixel bordered by edges on three or four sides, lighter (or darker) than every neighbour across them,
    which spread by at most SUBPIXEL_BG times its contrast to them (a sub-pixel feature on one background),
    then moves `subpixel` (four sides; three: `subpixel` * SUBPIXEL_END / SUBPIXEL) of the way to the mean
    of its 3x3 window (clamped), and each neighbour across those edges moves by -SUBPIXEL_SHARE / sides of
    that; pixels in grain (grain_mask) keep their colour."""
    rgb, alpha = normalised_rgb(frame, False)  # channel order does not matter for mixing
    decode = linear and not linear_input
    m = srgb_to_linear(rgb) if decode else rgb
    pad = np.pad(m, ((1, 1), (1, 1), (0, 0)), mode="edge")
    neighbours = [pad[:-2, 1:-1], pad[2:, 1:-1], pad[1:-1, :-2], pad[1:-1, 2:]]  # top, bottom, left, right
    acc = sum(weights[..., k, None] ** 2 * (neighbours[k] - m) for k in range(4))
    total = weights.sum(-1)[..., None]
    out = m + np.divide(acc, total, out=np.zeros_like(m), where=total > 0)
    if edges is not None and subpixel > 0:
        b, r = (edges & BOTTOM) > 0, (edges & RIGHT) > 0
        sides = b.astype(np.int64) + r
        sides[1:] += b[:-1]
        sides[:, 1:] += r[:, :-1]
        h, w = edges.shape
        box = sum(pad[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)) / 9.0
        # a local extremum in luma (Rec. 709, mix space) against every neighbour across its edges
        y = (m * np.array([0.2126, 0.7152, 0.0722])).sum(-1)
        ypad = np.pad(y, 1, mode="edge")
        lower = np.zeros((h, w), bool)
        higher = np.zeros((h, w), bool)
        ymin, ymax = np.full((h, w), np.inf), np.full((h, w), -np.inf)
        across = ((np.pad(b, ((1, 0), (0, 0)))[:-1], ypad[:-2, 1:-1]), (b, ypad[2:, 1:-1]),
                  (np.pad(r, ((0, 0), (1, 0)))[:, :-1], ypad[1:-1, :-2]), (r, ypad[1:-1, 2:]))
        for has, yn in across:
            lower |= has & (yn < y)
            higher |= has & (yn > y)
            ymin = np.where(has, np.minimum(ymin, yn), ymin)
            ymax = np.where(has, np.maximum(ymax, yn), ymax)
        # ... on one background: those neighbours spread by at most SUBPIXEL_BG times its contrast to them
        with np.errstate(invalid="ignore"):
            contrast = np.where(higher, ymin - y, y - ymax)
            background = ~(ymax - ymin > SUBPIXEL_BG * contrast)
        dot = (sides >= 3) & ~(lower & higher) & background
        amount = np.where(sides >= 4, subpixel, subpixel * SUBPIXEL_END / SUBPIXEL)[..., None]
        delta = np.where(dot[..., None], amount * (box - out), 0.0)
        # ... and the neighbours across its edges take SUBPIXEL_SHARE of that move, negated, split among them
        # (a feature in grain does not move, so it gives nothing)
        moved = dot & ~grain_mask(frame) if grain_guard else dot
        give = np.where(moved[..., None], -SUBPIXEL_SHARE * delta / np.maximum(sides, 1)[..., None], 0.0)
        share = np.zeros_like(out)
        share[1:] += np.where(b[:-1, :, None], give[:-1], 0.0)     # the feature above, across its bottom edge
        share[:-1] += np.where(b[:-1, :, None], give[1:], 0.0)     # the feature below, across this pixel's bottom
        share[:, 1:] += np.where(r[:, :-1, None], give[:, :-1], 0.0)  # the feature to the left
        share[:, :-1] += np.where(r[:, :-1, None], give[:, 1:], 0.0)  # the feature to the right
        out = out + delta + share
    out = linear_to_srgb(out) if decode else out
    res = _to_dtype(out, alpha, frame)
    if grain_guard:
        keep = grain_mask(frame)
        res[keep] = frame[keep]
    return res


def _to_dtype(rgb: np.ndarray, alpha: np.ndarray | None, like: np.ndarray) -> np.ndarray:
    chans = 1 if like.ndim == 2 else like.shape[2]
    if chans == 1:
        res = rgb[..., :1]
    else:
        res = rgb if alpha is None else np.concatenate([rgb, alpha[..., None]], -1)
    if like.dtype == np.uint8:
        res = np.clip(np.rint(res * 255), 0, 255).astype(np.uint8)
    elif like.dtype == np.uint16:
        res = np.clip(np.rint(res * 65535), 0, 65535).astype(np.uint16)
    else:
        res = res.astype(like.dtype)
    return res.reshape(like.shape)


def mlaa_reference(frame: np.ndarray, threshold: float | None = None, metric: str = "lab",
                   linear: bool = True, bgr: bool = False, linear_input: bool = False,
                   rounding: float = 0.0, blend_u: bool = True, ramp: float = 0.35,
                   short_corner: float = SHORT_CORNER, aa_guard: bool = True,
                   grain_guard: bool = True, subpixel: float = SUBPIXEL) -> np.ndarray:
    """The whole spatial filter, pass after pass (without the bridging pass: mlaa_stream.spatial.bridge.bridge_reference)."""
    e = edges_reference(frame, threshold, metric, bgr, linear_input, ramp, aa_guard)
    hd, vd = distances_reference(e)
    wts = weights_reference(e, hd, vd, rounding, blend_u, frame, short_corner)
    return blend_reference(frame, wts, linear, linear_input, bgr, grain_guard, e, subpixel)
