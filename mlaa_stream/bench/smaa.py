"""SMAA 1x (ultra preset) in vectorised numpy: a peer method for the bench, not part of the filter.

    smaa = SMAA()
    out = smaa.process(frame)           # same shape and dtype; the bench's Processor interface

Jimenez, Echevarria, Sousa, Gutierrez 2012, "SMAA: Enhanced Subpixel Morphological Antialiasing"
(Eurographics), section 3 (the MLAA pipeline it builds on: edges, pattern search, areas, blending) and
section 4 (local contrast adaptation, crossing edges, sharp geometric features / corner rounding); the
project's seed document /work/shared/seeds/002_597776cfc414eb03.txt (EBAA, an SMAA-class method) describes
the same three passes ("edge detection", "pattern detection", "blending weights" with the area
pre-calculation). Written from the paper and from reading the reference shader's structure, not copied.

What is implemented, with the ULTRA preset's settings:

1. edge detection on luma of the gamma-encoded colour (threshold 0.05) with local contrast adaptation
   (factor 2.0): an edge is kept only where its contrast is at least half the largest contrast around it;
2. blending weights for orthogonal (horizontal and vertical) patterns: for each edge, the distances to both
   ends of its line (at most 2 x 32 search steps = 64 pixels each way) and the crossing edges at each end,
   then the area under the revectorised line through the half-pixel points at the ends (the area table,
   computed here from the geometry, exactly, at import -- see `area_table`); corner rounding 25 %;
3. neighbourhood blending in linear light (sRGB decoded, blended, encoded: "SMAA 1x ultra (linear blend)").

Diagonal patterns (SMAA's diagonal search, 16 steps, and AreaTex's diagonal lines) are an option,
SMAA(diagonals=True), off by default and not what the bench's "smaa" runs: see `_diagonal_weights` for what
they do and the note there for why they are off. Without them, 1:1-ish slopes are handled as the orthogonal
patterns of their short steps, as MLAA does. Not implemented: predication, temporal reprojection, S2x/T2x/4x.
The orthogonal area table holds the exact coverage for integer distances, where the shader reads
a 16x16-per-pattern texture with sqrt-compressed distances and bilinear filtering (the same values at
squared distances, interpolated between).

Speed: this is numpy on the host CPU, not OpenCL -- the bench's ms column for "smaa" measures this
reference implementation, not what SMAA costs as a GPU shader.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear

# The ULTRA preset (SMAA.hlsl's SMAA_PRESET_ULTRA).
THRESHOLD = 0.05                 # luma edge threshold
CONTRAST_ADAPTATION = 2.0        # local contrast adaptation factor
MAX_SEARCH_STEPS = 32            # orthogonal search: 2 pixels per step, so lines up to 64 pixels each way
MAX_SEARCH_STEPS_DIAG = 16       # the preset's diagonal search (not implemented, see the module docstring)
CORNER_ROUNDING = 25             # percent
MAX_DISTANCE = 2 * MAX_SEARCH_STEPS

_LUMA = np.array([0.2126, 0.7152, 0.0722], np.float32)   # Rec. 709 weights, as SMAA's luma edge detection
# Crossing-edge codes at one end of a line: none, in the pixel's own row ("down" for a horizontal edge at the
# pixel's top), in the neighbour's row ("up"), both.
NONE, DOWN, UP, BOTH = 0, 1, 2, 3
_HEIGHT = {DOWN: -0.5, UP: 0.5}  # where the revectorised line starts: the middle of the crossing edge



# --- the area table (paper section 3, "area pre-calculation"; SMAA's AreaTex, orthogonal part) ----------------
def _segment_area(x0, y0, x1, y1, a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(negative, positive) area between y = 0 and the segment (x0, y0)-(x1, y1) over x in [a, b], clipped to
    the segment; every argument an array or a number (broadcast). Exact: the segment is linear, so it is split
    at its zero into two triangles where it changes sign within [a, b], else one trapezoid."""
    x0, y0, x1, y1, a, b = np.broadcast_arrays(*(np.asarray(v, np.float64) for v in (x0, y0, x1, y1, a, b)))
    lo, hi = np.maximum(a, x0), np.minimum(b, x1)
    width = np.maximum(hi - lo, 0.0)
    slope = (y1 - y0) / (x1 - x0)
    f_lo, f_hi = y0 + slope * (lo - x0), y0 + slope * (hi - x0)
    same = (f_lo * f_hi) >= 0.0
    trap = 0.5 * (f_lo + f_hi) * width
    t0 = np.where(same, lo, lo + width * f_lo / np.where(same, 1.0, f_lo - f_hi))   # the zero, when crossed
    tri_lo, tri_hi = 0.5 * f_lo * (t0 - lo), 0.5 * f_hi * (hi - t0)
    pos = np.where(same, np.maximum(trap, 0.0), np.maximum(tri_lo, 0.0) + np.maximum(tri_hi, 0.0))
    neg = np.where(same, np.maximum(-trap, 0.0), np.maximum(-tri_lo, 0.0) + np.maximum(-tri_hi, 0.0))
    return neg, pos


@lru_cache(maxsize=None)
def area_table(max_distance: int = MAX_DISTANCE) -> np.ndarray:
    """Blending areas of the orthogonal patterns: table[e1, e2, left, right] = (own, other), float32.

    A horizontal edge line at the top of a pixel row runs `left` pixels left and `right` pixels right of the
    pixel (its length d = left + right + 1, the pixel spans [left, left + 1]); e1, e2 are the crossing edges
    at its left and right ends (NONE, DOWN: in the pixel's own row, UP: in the row above, BOTH). The line is
    revectorised through the middle of each crossing edge (height -0.5 for DOWN, +0.5 for UP; the paper's
    fig. 3 and MLAA's L, Z and U shapes): Z (crossings on opposite sides): one straight segment end to end;
    U (same side): two segments meeting the edge at d/2; L (one crossing end): the half at that end only, and
    only for the pixels of that half (nearer the crossing end) -- so a line without crossing edges, a straight
    step, stays untouched. An end with BOTH crossings counts as the opposite of the other end (a Z either
    way), or as nothing when the other end has none or both (SMAA's AreaTex patterns 5, 7, 10, 11, 13-15).
    `own` (negative side): the share of the row above that the pixel takes; `other` (positive side): the
    share of this pixel that the pixel above takes. Vertical lines use the same table, transposed.
    """
    n = max_distance + 1
    left, right = np.meshgrid(np.arange(n, dtype=np.float64), np.arange(n, dtype=np.float64), indexing="ij")
    d = left + right + 1.0
    a, b = left, left + 1.0
    out = np.zeros((4, 4, n, n, 2), np.float64)
    for e1 in range(4):
        for e2 in range(4):
            c1, c2 = e1, e2
            if c1 == BOTH and c2 in (DOWN, UP):
                c1 = UP if c2 == DOWN else DOWN
            elif c2 == BOTH and c1 in (DOWN, UP):
                c2 = UP if c1 == DOWN else DOWN
            if BOTH in (c1, c2) or c1 == c2 == NONE:
                continue                                      # no crossing edge that makes a step: no blending
            if c1 != NONE and c2 != NONE and c1 != c2:        # Z: one segment between the two half-pixel points
                neg, pos = _segment_area(0.0, _HEIGHT[c1], d, _HEIGHT[c2], a, b)
            else:
                neg, pos = np.zeros_like(d), np.zeros_like(d)
                if c1 != NONE:                                # the left half: left end to (d/2, 0)
                    n1, p1 = _segment_area(0.0, _HEIGHT[c1], d / 2.0, 0.0, a, b)
                    keep = (left <= right) | (c2 != NONE)     # an L blends only the half at its crossing end
                    neg, pos = neg + np.where(keep, n1, 0.0), pos + np.where(keep, p1, 0.0)
                if c2 != NONE:                                # the right half: (d/2, 0) to the right end
                    n2, p2 = _segment_area(d / 2.0, 0.0, d, _HEIGHT[c2], a, b)
                    keep = (left >= right) | (c1 != NONE)
                    neg, pos = neg + np.where(keep, n2, 0.0), pos + np.where(keep, p2, 0.0)
            out[e1, e2, ..., 0], out[e1, e2, ..., 1] = neg, pos
    return out.astype(np.float32)


# --- pass 1: edges (paper section 4.1, luma edges with local contrast adaptation) --------------------------------
def detect_edges(luma: np.ndarray, threshold: float = THRESHOLD,
                 adaptation: float = CONTRAST_ADAPTATION) -> tuple[np.ndarray, np.ndarray]:
    """(left, top): bool (h, w) arrays, an edge between the pixel and its left / top neighbour.

    An edge is where the luma step is at least `threshold`, kept only when that step is at least 1/adaptation
    of the largest step around it (the four steps of the pixel and the one beyond its left / top neighbour),
    so a weaker edge beside a much stronger one is not antialiased (the paper's eq. 1). Outside the frame the
    border pixels repeat (a texture's clamp), so there are no edges along the frame's border."""
    L = np.pad(luma.astype(np.float32), 2, mode="edge")
    c = L[2:-2, 2:-2]
    d_left, d_top = np.abs(c - L[2:-2, 1:-3]), np.abs(c - L[1:-3, 2:-2])
    d_right, d_bottom = np.abs(c - L[2:-2, 3:-1]), np.abs(c - L[3:-1, 2:-2])
    d_leftleft = np.abs(L[2:-2, 1:-3] - L[2:-2, :-4])
    d_toptop = np.abs(L[1:-3, 2:-2] - L[:-4, 2:-2])
    biggest = np.maximum(np.maximum(np.maximum(d_left, d_right), d_leftleft),
                         np.maximum(np.maximum(d_top, d_bottom), d_toptop))
    a = np.float32(adaptation)
    left = (d_left >= threshold) & (a * d_left >= biggest)
    top = (d_top >= threshold) & (a * d_top >= biggest)
    return left, top


# --- pass 2: blending weights (paper sections 3 and 4.2-4.3) ---------------------------------------------------
def _line_weights(along: np.ndarray, across: np.ndarray, rounding: float, max_distance: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """(own, other) weights of the edges at the top of each pixel, `along` (h, w) bool, with `across` (h, w)
    bool the edges at the left of each pixel (the crossing edges). Returns two float32 (h, w) arrays: `own`,
    the share of the pixel above that the pixel takes; `other`, the share of the pixel the one above takes.

    Each edge's line extends left and right while the neighbour also has an edge at its top and no crossing
    edge (in the pixel's row or the row above) separates them (the shader's searches, SMAA 4.2), at most
    max_distance pixels each way. The crossing edges at the line's ends pick the pattern in area_table; corner
    rounding (SMAA 4.3) then keeps only `rounding` of the blending where a crossing edge goes on past the
    line's own two rows -- a real corner of a shape, not a step of a slanted edge."""
    h, w = along.shape
    zeros_row = np.zeros((1, w), bool)
    zeros_col = np.zeros((h, 1), bool)
    across_up = np.vstack([zeros_row, across[:-1]])        # crossing edges in the row above
    crossing = across | across_up
    # cont[y, x]: the line at the top of pixel x goes on into pixel x - 1.
    cont = np.hstack([zeros_col, along[:, :-1] & ~crossing[:, 1:]]) & along
    xs = np.arange(w, dtype=np.int32)
    starts = np.where(along & ~cont, xs, -1)
    first = np.maximum.accumulate(starts, axis=1)           # the line's left end, for every pixel of the line
    cont_right = np.hstack([cont[:, 1:], zeros_col])        # the line goes on into pixel x + 1
    ends = np.where(along & ~cont_right, xs, w)
    last = np.minimum.accumulate(ends[:, ::-1], axis=1)[:, ::-1]

    own, other = np.zeros((h, w), np.float32), np.zeros((h, w), np.float32)
    ys, xe = np.nonzero(along)
    if ys.size == 0:
        return own, other
    left = np.minimum(xe - first[ys, xe], max_distance)
    right = np.minimum(last[ys, xe] - xe, max_distance)
    x_left, x_right = xe - left, xe + right                 # the ends (or as far as the search went)
    # The crossing edges at each end: at the left of the left end, at the left of the pixel past the right end.
    pad_across = np.pad(across, ((2, 2), (0, 1)))            # zeros outside the frame: no edge there
    yp = ys + 2

    def cross(rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        return pad_across[rows, cols]

    e1 = cross(yp, x_left) * DOWN + cross(yp - 1, x_left) * UP
    e2 = cross(yp, x_right + 1) * DOWN + cross(yp - 1, x_right + 1) * UP
    table = area_table(max_distance)
    wts = table[e1, e2, left, right]                          # (n, 2)
    if rounding < 1.0:
        near_left, near_right = left <= right, right <= left
        share = (1.0 - rounding) / (near_left.astype(np.float32) + near_right)
        r_left, r_right = share * near_left, share * near_right
        # Does the crossing edge at either end go on below the pixel (row y + 1) or above the row above (y - 2)?
        f_own = 1.0 - r_left * cross(yp + 1, x_left) - r_right * cross(yp + 1, x_right + 1)
        f_other = 1.0 - r_left * cross(yp - 2, x_left) - r_right * cross(yp - 2, x_right + 1)
        wts = wts * np.clip(np.stack([f_own, f_other], -1), 0.0, 1.0).astype(np.float32)
    own[ys, xe], other[ys, xe] = wts[:, 0], wts[:, 1]
    return own, other


# --- diagonal patterns (paper section 4.2, "diagonal patterns"; SMAA's diagonal search and AreaTex diagonal part)
# A diagonal line is a run of pixels along a 45-degree direction that each have two edges: the top and the left
# edge for "/" lines (rising to the right), the top and the right edge for "\\" lines. Its area is computed in a
# frame where the line runs from its first pixel, the square (1, 0), along (+1, +1), y up: the current pixel is
# the square (1 + left, left) and its neighbour across the top edge the square (1 + left, 1 + left) ("/" lines;
# "\\" lines are the mirror image, so the two shares swap). The crossing edges at each end (0 none, 1 the
# vertical one, 2 the horizontal one, 3 both) say where the line starts and ends; where an end is not known
# (no crossing edge) the area is the mean over the two 45-degree lines it could be (the line through the
# steps' outer corners and the one through their inner corners), which is also what a long line's middle gets.
# Each entry: lines (x1, y1, x2, y2), the line from (x1, y1) to (x2 + d, y2 + d), d the line's length in pixels.
_DIAG_LINES: dict[tuple[int, int], tuple[tuple[int, int, int, int], ...]] = {
    (0, 0): ((1, 1, 1, 1), (1, 0, 1, 0)), (1, 0): ((1, 0, 0, 0), (1, 0, 1, 0)),
    (0, 2): ((0, 0, 1, 0), (1, 0, 1, 0)), (1, 2): ((1, 0, 1, 0),),
    (2, 0): ((1, 1, 0, 0), (1, 1, 1, 0)), (3, 0): ((1, 1, 0, 0), (1, 0, 1, 0)),
    (2, 2): ((1, 1, 1, 0),), (3, 2): ((1, 1, 1, 0), (1, 0, 1, 0)),
    (0, 1): ((0, 0, 1, 1), (1, 0, 1, 1)), (1, 1): ((1, 0, 1, 1),),
    (0, 3): ((0, 0, 1, 1), (1, 0, 1, 0)), (1, 3): ((1, 0, 1, 1), (1, 0, 1, 0)),
    (2, 1): ((1, 1, 1, 1),), (3, 1): ((1, 1, 1, 1), (1, 0, 1, 1)),
    (2, 3): ((1, 1, 1, 1), (1, 1, 1, 0)), (3, 3): ((1, 1, 1, 1), (1, 0, 1, 0)),
}
DIAG_SIZE = 20   # distances 0..19 each way (the search reaches 16)


def _below(x1: float, y1: float, x2: np.ndarray, y2: np.ndarray, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """Share of the unit square at (sx, sy) below the (infinite) line through (x1, y1) and (x2, y2), x2 > x1:
    the height under the line clipped to [0, 1] (u = line - sy), integrated exactly over the square's width
    with the antiderivative F of clip(u, 0, 1) (0 below 0, u^2 / 2 up to 1, u - 1/2 above)."""
    slope = (y2 - y1) / (x2 - x1)

    def F(u: np.ndarray) -> np.ndarray:
        return np.where(u <= 0.0, 0.0, np.where(u >= 1.0, u - 0.5, 0.5 * u * u))

    u0 = y1 + slope * (sx - x1) - sy
    return (F(u0 + slope) - F(u0)) / slope


@lru_cache(maxsize=None)
def diag_area_table() -> np.ndarray:
    """Blending areas of the diagonal patterns: table[c1, c2, left, right] = (current, across), float32: the
    share of the current pixel on the far side of the line (the square (1 + left, left), above the line) and
    of its neighbour across the top edge (the square (1 + left, 1 + left), below it), mean over the pattern's
    candidate lines (see _DIAG_LINES). Shares under 1/255 are 0, as in SMAA's 8-bit texture, so that a pattern
    that hardly touches the pixel does not count as a diagonal (which would skip the orthogonal patterns)."""
    left, right = np.meshgrid(np.arange(DIAG_SIZE, dtype=np.float64), np.arange(DIAG_SIZE, dtype=np.float64),
                              indexing="ij")
    d = np.maximum(left + right + 1.0, 4.0)   # lines of 4+ pixels only: shorter ones are not diagonals
    out = np.zeros((4, 4, DIAG_SIZE, DIAG_SIZE, 2))
    for (c1, c2), lines in _DIAG_LINES.items():
        for x1, y1, x2, y2 in lines:
            args = (float(x1), float(y1), x2 + d, y2 + d)
            out[c1, c2, ..., 0] += 1.0 - _below(*args, 1.0 + left, left)
            out[c1, c2, ..., 1] += _below(*args, 1.0 + left, 1.0 + left)
        out[c1, c2] /= len(lines)
    out[out < 1.0 / 255.0] = 0.0
    return out.astype(np.float32)


def _diagonal_weights(left: np.ndarray, top: np.ndarray, max_steps: int = MAX_SEARCH_STEPS_DIAG
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(r, g, found): the weights of diagonal lines through pixels with a top edge, and where one was found
    (those pixels then skip the orthogonal patterns, horizontal and vertical, as in SMAA).

    For a "/" line the search runs from the pixel down-left (only when the pixel also has a left edge) and
    up-right over pixels with both edges, at most max_steps each way; down-left, one more pixel with a top
    edge only ends the line. For a "\\" line likewise up-left and (when the pixel has a right edge) down-right
    over pixels with top and right edges, one more with a top edge ending it down-right. Lines of 4+ pixels
    count. An end's crossing edges are read beside it (see diag_area_table), none where the search ran out.

    Why off by default: on `mlaa-stream bench --methods smaa` they cost 1.4 points over all categories (61.1 ->
    59.7 %): diagonals 84.2 -> 73.6 % (the 45-degree rotated rectangles: their sides end in the corners'
    crossing edges, and the line so chosen runs through the steps' inner corners, half a pixel off the truth at
    that phase), cut 88.3 -> 83.7 %, rendered 49.1 -> 49.3 %, the rest within 0.5. The search, the crossing
    edges and the lines follow the reference shader and AreaTex as read; with no reference SMAA output to
    compare against, it is not established whether that loss is SMAA's or a misreading here."""
    h, w = top.shape
    pad = max_steps + 2
    L, T = np.pad(left, pad), np.pad(top, pad)
    R = np.zeros_like(L)
    R[:, :-1] = L[:, 1:]                                 # an edge at the pixel's right
    r_out, g_out = np.zeros((h, w), np.float32), np.zeros((h, w), np.float32)
    ys, xs = np.nonzero(top)
    if ys.size == 0:
        return r_out, g_out, np.zeros((h, w), bool)
    yp, xp = ys + pad, xs + pad
    table = diag_area_table()

    def search(run: np.ndarray, dy: int, dx: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Pixels of `run` in a row from the pixel along (dx, dy): (distance, ran out, last pixel's top edge)."""
        n = np.zeros(ys.size, np.int64)
        alive = np.ones(ys.size, bool)
        for k in range(1, max_steps + 1):
            alive &= run[yp + k * dy, xp + k * dx]
            n += alive
        z = np.minimum(n, max_steps - 1)
        last_top = T[yp + (z + 1) * dy, xp + (z + 1) * dx]
        return z, n >= max_steps, last_top

    # "/" lines: pixels with top and left edges, down-left and up-right.
    run1 = L & T
    has_left = L[yp, xp]
    z, out_l, last_top = search(run1, 1, -1)
    d_l = np.where(has_left, z + last_top, 0)
    out_l &= has_left
    d_r, out_r, _ = search(run1, -1, 1)
    e1y, e1x, e2y, e2x = yp + d_l, xp - d_l, yp - d_r, xp + d_r        # the down-left and up-right ends
    c1 = np.where(out_l, 0, 2 * T[e1y, e1x - 1] + L[e1y, e1x])
    c2 = np.where(out_r, 0, 2 * T[e2y, e2x + 1] + L[e2y - 1, e2x + 1])
    ok = (d_l + d_r) > 2
    w1 = table[c1, c2, np.minimum(d_l, DIAG_SIZE - 1), np.minimum(d_r, DIAG_SIZE - 1)] * ok[:, None]

    # "\\" lines: pixels with top and right edges, up-left and down-right; the mirror image, shares swapped.
    run2 = T & R
    d_l, out_l, _ = search(run2, -1, -1)
    has_right = R[yp, xp]
    z, out_r, last_top = search(run2, 1, 1)
    d_r = np.where(has_right, z + last_top, 0)
    out_r &= has_right
    e1y, e1x, e2y, e2x = yp - d_l, xp - d_l, yp + d_r, xp + d_r        # the up-left and down-right ends
    c1 = np.where(out_l, 0, 2 * T[e1y, e1x - 1] + L[e1y - 1, e1x])
    c2 = np.where(out_r, 0, 2 * T[e2y, e2x + 1] + L[e2y, e2x + 1])
    ok = (d_l + d_r) > 2
    w2 = table[c1, c2, np.minimum(d_l, DIAG_SIZE - 1), np.minimum(d_r, DIAG_SIZE - 1)] * ok[:, None]

    r_out[ys, xs] = w1[:, 0] + w2[:, 1]
    g_out[ys, xs] = w1[:, 1] + w2[:, 0]
    return r_out, g_out, (r_out + g_out) > 0


def blending_weights(left: np.ndarray, top: np.ndarray, corner_rounding: float = CORNER_ROUNDING,
                     max_distance: int = MAX_DISTANCE, diagonals: bool = False) -> np.ndarray:
    """SMAA's blend texture, (h, w, 4) float32: r, g for the edge at the pixel's top (r: the pixel takes from
    the one above, g: the one above takes from the pixel), b, a for the edge at its left (b: the pixel takes
    from its left neighbour, a: the left neighbour takes from the pixel). A pixel on a diagonal line takes the
    diagonal's r, g and no orthogonal weights (SMAA gives diagonals priority)."""
    rounding = corner_rounding / 100.0
    r, g = _line_weights(top, left, rounding, max_distance)
    bt, at = _line_weights(left.T, top.T, rounding, max_distance)   # vertical lines: the same, transposed
    b, a = bt.T, at.T
    if diagonals:
        dr, dg, found = _diagonal_weights(left, top)
        r, g = np.where(found, dr, r), np.where(found, dg, g)
        b, a = np.where(found, 0.0, b), np.where(found, 0.0, a)
    return np.stack([r, g, b, a], -1).astype(np.float32)


# --- pass 3: neighbourhood blending (paper section 3, "blending") ---------------------------------------------
def blend_neighbours(lin: np.ndarray, weights: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(mask, colours): the pixels that blend and their new colour (n, c), from linear-light `lin` (h, w, c).

    Each pixel reads four weights: from its right neighbour's a and its bottom neighbour's g (the edges on its
    right and bottom sides) and its own b and r (left and top); it blends along the direction (horizontal or
    vertical) with the larger weight only, each side mixed by its weight, the two sides averaged by weight."""
    h, w = weights.shape[:2]
    a_right = np.zeros((h, w), np.float32)
    a_right[:, :-1] = weights[:, 1:, 3]
    a_bottom = np.zeros((h, w), np.float32)
    a_bottom[:-1] = weights[1:, :, 1]
    a_left, a_top = weights[..., 2], weights[..., 0]
    mask = (a_right + a_bottom + a_left + a_top) >= 1e-5
    ys, xs = np.nonzero(mask)
    ar, ab, al, at = a_right[ys, xs], a_bottom[ys, xs], a_left[ys, xs], a_top[ys, xs]
    horizontal = np.maximum(ar, al) > np.maximum(ab, at)
    w1, w2 = np.where(horizontal, ar, ab), np.where(horizontal, al, at)   # right / bottom, left / top
    y1, x1 = np.where(horizontal, ys, np.minimum(ys + 1, h - 1)), np.where(horizontal, np.minimum(xs + 1, w - 1), xs)
    y2, x2 = np.where(horizontal, ys, np.maximum(ys - 1, 0)), np.where(horizontal, np.maximum(xs - 1, 0), xs)
    c = lin[ys, xs]
    total = w1 + w2
    c1 = c + (lin[y1, x1] - c) * w1[:, None]
    c2 = c + (lin[y2, x2] - c) * w2[:, None]
    out = (c1 * w1[:, None] + c2 * w2[:, None]) / total[:, None]
    return mask, out


# --- the method ---------------------------------------------------------------------------------------------
_SCALE = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0, np.dtype(np.float32): 1.0,
          np.dtype(np.float64): 1.0}


@lru_cache(maxsize=None)
def _decode_lut(levels: int) -> np.ndarray:
    """sRGB -> linear for every integer code of an 8- or 16-bit frame."""
    return srgb_to_linear(np.arange(levels + 1) / levels).astype(np.float32)


class SMAA:
    """SMAA 1x, ULTRA preset, orthogonal patterns with corner rounding (diagonal ones with diagonals=True),
    blended in linear light -- numpy on the host CPU, so the bench's ms column for it measures this reference,
    not a GPU shader (see the module docstring for what is and is not implemented).

    `process(frame)`: uint8 / uint16 / float32 grey or RGB, (h, w) or (h, w, c) with c 1-4 (2: grey and alpha,
    4: RGBA); alpha passes through unchanged; the same shape and dtype back. Values are taken as sRGB-encoded
    in [0, 1] (float frames: outside it, blended pixels are clamped to it; unblended pixels come back bit for
    bit). `device` is accepted for the bench's factories and ignored."""

    def __init__(self, device: object = None, *, threshold: float = THRESHOLD,
                 adaptation: float = CONTRAST_ADAPTATION, corner_rounding: float = CORNER_ROUNDING,
                 max_search_steps: int = MAX_SEARCH_STEPS, diagonals: bool = False, bgr: bool = False):
        if not 0.0 < threshold <= 1.0:
            raise ValueError(f"threshold: expected a number in (0, 1], got {threshold!r}")
        if not 0.0 <= corner_rounding <= 100.0:
            raise ValueError(f"corner_rounding: expected a percentage in [0, 100], got {corner_rounding!r}")
        if int(max_search_steps) < 1:
            raise ValueError(f"max_search_steps: expected a positive integer, got {max_search_steps!r}")
        self.threshold, self.adaptation = float(threshold), float(adaptation)
        self.corner_rounding, self.max_distance = float(corner_rounding), 2 * int(max_search_steps)
        self.diagonals, self.bgr = bool(diagonals), bgr
        area_table(self.max_distance)                 # build the tables now, not inside the first timed frame
        diag_area_table()

    @property
    def device_name(self) -> str:
        return "numpy (SMAA 1x ultra)"

    def process(self, frame: np.ndarray) -> np.ndarray:
        """Antialias one frame; the same shape and dtype back."""
        frame = np.asarray(frame)
        if frame.dtype not in _SCALE:
            raise ValueError(f"expected a uint8, uint16 or float32 frame, got {frame.dtype}")
        if frame.ndim not in (2, 3) or (frame.ndim == 3 and not 1 <= frame.shape[2] <= 4):
            raise ValueError(f"expected an (h, w) or (h, w, 1-4) frame, got shape {frame.shape}")
        img = frame.reshape(frame.shape[0], frame.shape[1], -1)
        colour = img[..., :1] if img.shape[2] <= 2 else img[..., :3]   # alpha (channel 2 or 4) stays as it is
        scale = _SCALE[frame.dtype]
        if colour.shape[2] == 1:
            luma = colour[..., 0].astype(np.float32) / np.float32(scale)
        else:
            rgb = colour[..., ::-1] if self.bgr else colour
            luma = (rgb.astype(np.float32) / np.float32(scale)) @ _LUMA
        left, top = detect_edges(luma, self.threshold, self.adaptation)
        weights = blending_weights(left, top, self.corner_rounding, self.max_distance, self.diagonals)
        if frame.dtype.kind == "u":
            lin = _decode_lut(int(scale))[colour]
        else:
            lin = srgb_to_linear(colour).astype(np.float32)
        mask, blended = blend_neighbours(lin, weights)
        out = img.copy()
        if blended.size:
            enc = linear_to_srgb(blended)
            if frame.dtype.kind == "u":
                enc = np.clip(np.rint(enc * scale), 0, scale)
            out[mask, :colour.shape[2]] = enc.astype(frame.dtype)
        return out.reshape(frame.shape)

    def close(self) -> None:
        pass

    def __enter__(self) -> "SMAA":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
