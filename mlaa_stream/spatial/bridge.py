"""Bridging the dash chains of sub-pixel wires (beyond seed 000 §4; docs/reconstruct.md, "Bridging").

A wire thinner than a pixel at a shallow angle is sampled at 1 spp as dashes: a 1-px-tall run of ink in
row r, a gap of background in rows r and r+d, the next run in row r+d. This pass finds such links and
redraws the columns they span, in rows r and r+d, with the coverage a straight band of the estimated
width passing from the middle of one dash to the middle of the next would give. Steep wires are the
transpose, wires near 45 degrees the same on the two diagonal lattices. A wire that crosses the frame's edge
keeps its first and last gap: a dash cut by the edge counts as long as the next one, and a chain that starts
or ends within a gap of the edge draws its band on to it. The end of another wire of the same ink two rows from a
dash (beside it, away from the gap) does not refuse a link of long dashes, nor does another wire of the same ink
crossing the gap (the gap runs past it; it keeps its pixels). Detection reads the input; the
drawing writes another frame (the MLAA output: `Filter(bridge=True)`, the default).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from mlaa_stream.device.colour import device_luts, lut_read
from mlaa_stream.device.context import Context, check_pass_buffers, default_context, launch_size
from mlaa_stream.device.formats import LUT_SIZE, FrameFormat, defines_for, frame_format

try:
    import pyopencl as cl
except ImportError:  # pragma: no cover - device.py reports broken installs
    cl = None

MAX_GAP = 24  # longest gap bridged, in pixels
MAX_RUN = 32  # longest dash, in pixels
INK_MIN = 0.1  # a dash differs from the background by at least this (max channel, normalised)
BG_TOL = 0.02  # "background": within this of the background colour next to the dash end (max channel)
INK_TOL = 0.1  # "the same ink": within this of the colour at the dash end (max channel)
GAP_PER_RUN = 3  # gap <= GAP_PER_RUN * mean dash + GAP_SLACK: wires at least 1/4 px wide, not specks far apart
GAP_SLACK = 2
MIN_DASHES = 3  # a link is drawn only inside a chain of at least this many dashes (2 or 3)
MAX_SKIP = 3  # a chain cut by a crossing is bridged to one that goes on at most this many lattice rows later
POKE_RUN = 2  # another wire's end of the link's ink beside a dash, two rows from it: at most this long (0: off)
POKE_DASH = 3  # ... and only for links whose dashes are both at least this long
XING_RUN = 3  # another wire of the link's ink crossing the gap: at most this many steps along each row (0: off)
XING_DASH = 4  # ... and only for links whose dashes are both at least this long
MESH_DASH = 2  # links of dots this long or shorter need rows -2d and 3d free of the ink: not a mesh (0: off)


@dataclass(frozen=True)
class BridgeOptions:
    """The pass's thresholds (module constants above) and the blending space (as the Filter's)."""

    max_gap: int = MAX_GAP
    max_run: int = MAX_RUN
    ink_min: float = INK_MIN
    bg_tol: float = BG_TOL
    ink_tol: float = INK_TOL
    gap_per_run: int = GAP_PER_RUN
    gap_slack: int = GAP_SLACK
    min_dashes: int = MIN_DASHES
    max_skip: int = MAX_SKIP
    poke_run: int = POKE_RUN
    poke_dash: int = POKE_DASH
    xing_run: int = XING_RUN
    xing_dash: int = XING_DASH
    mesh_dash: int = MESH_DASH
    linear: bool = True
    linear_input: bool = False

    def defines(self) -> dict[str, object]:
        return {"MAX_GAP": int(self.max_gap), "MAX_RUN": int(self.max_run), "INK_MIN": float(self.ink_min),
                "BG_TOL": float(self.bg_tol), "INK_TOL": float(self.ink_tol),
                "GAP_PER_RUN": int(self.gap_per_run), "GAP_SLACK": int(self.gap_slack),
                "MIN_DASHES": int(self.min_dashes), "MAX_SKIP": int(self.max_skip), "POKE_RUN": int(self.poke_run),
                "POKE_DASH": int(self.poke_dash), "XING_RUN": int(self.xing_run),
                "XING_DASH": int(self.xing_dash), "MESH_DASH": int(self.mesh_dash), "BLEND_LINEAR": int(self.linear),
                "LINEAR_INPUT": int(self.linear_input)}


# Scan orientations, in the order the passes run: (a, b) = one step along a "row" and one step across it.
# Rows and columns see shallow and steep wires; the two diagonal lattices (a unimodular shear of the pixel
# grid, so every rule holds unchanged in (i, j) coordinates) see wires near 45 degrees.
ORIENTATIONS: tuple[tuple[tuple[int, int], tuple[int, int]], ...] = (
    ((1, 0), (0, 1)), ((0, 1), (1, 0)), ((1, 1), (1, 0)), ((1, -1), (1, 0)))


@dataclass(frozen=True)
class Link:
    """In lattice steps from the end (x, y) of dash 1: dash 1 = i in a..0 at j = 0, the gap, dash 2 =
    i in s..b at j = d."""

    x: int
    y: int
    d: int
    a: int
    s: int
    b: int


# ----------------------------------------------------------------------------------------------
# The plain numpy reference
# ----------------------------------------------------------------------------------------------

def _diff(p: np.ndarray, q: np.ndarray) -> np.float32:
    return np.float32(np.abs(p - q).max())


def _on_mix_line(p: np.ndarray, ink: np.ndarray, bgc: np.ndarray) -> np.ndarray:
    """The mix bgc + t (ink - bgc), t in [0, 1], nearest to p (float32, in the kernel's order of operations)."""
    e, q = ink - bgc, p - bgc
    t = (q[0] * e[0] + q[1] * e[1] + q[2] * e[2]) / (e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    t = min(max(t, np.float32(0)), np.float32(1))
    return bgc + t * e


class _Scan:
    """The frame seen in one orientation: pixel (i, j) steps from (x, y) is (x + i a + j b)."""

    def __init__(self, rgb: np.ndarray, ab, o: BridgeOptions):
        self.rgb, self.o = rgb, o
        # the kernel's thresholds are float literals: compare in float32 as it does
        self.ink_min, self.bg_tol, self.ink_tol = (np.float32(v) for v in (o.ink_min, o.bg_tol, o.ink_tol))
        (self.ax, self.ay), (self.bx, self.by) = ab
        self.h, self.w = rgb.shape[:2]

    def at(self, x: int, y: int, i: int, j: int) -> tuple[int, int]:
        return x + i * self.ax + j * self.bx, y + i * self.ay + j * self.by

    def px(self, x: int, y: int, i: int, j: int) -> np.ndarray | None:
        px, py = self.at(x, y, i, j)
        return self.rgb[py, px] if 0 <= px < self.w and 0 <= py < self.h else None

    def cls(self, x: int, y: int, i: int, j: int, ink: np.ndarray, bgc: np.ndarray) -> int:
        """Lattice pixel (i, j) as 1 background, 2 ink, 3 another colour (another wire), 0 a mix of the two
        (antialiased ink: it refuses a link as the ink does) or outside the frame."""
        p = self.px(x, y, i, j)
        if p is None:
            return 0
        if _diff(p, bgc) <= self.bg_tol:
            return 1
        if _diff(p, ink) <= self.ink_tol:
            return 2
        return 0 if _diff(p, _on_mix_line(p, ink, bgc)) <= self.ink_tol else 3

    def inside(self, x: int, y: int, i: int, j: int) -> bool:
        px, py = self.at(x, y, i, j)
        return 0 <= px < self.w and 0 <= py < self.h

    def link(self, x: int, y: int) -> Link | None:
        """The link whose dash 1 ends at (x, y), or None. Lattice rows -d .. 2d over the two dashes and the gap
        hold only the two dashes (one ink colour), background (one colour), pixels of other colours (wires
        crossing this one) and, when a dash is cut by the frame, pixels outside it; exactly one direction d
        qualifies. A dash may run under another colour, and may start or end under it (occluded): it then runs
        from its first to its last pixel of the ink, and the window covers the occluding pixels too. One dash may
        be cut by the frame's edge (its ink reaches the edge): `cut_lengths` gives the lengths the link is judged
        and drawn with. Beside a dash, two rows from it (row 2d beside dash 1, row -d beside dash 2, but not over
        the dash's step next to the gap), the end of another wire of the same ink (`poke`) counts as clear when
        both dashes are at least POKE_DASH long. Over steps 2 .. s - 2 of the gap, another wire of the same ink
        crossing the rows (`xing`) counts as clear when both dashes are at least XING_DASH long, and the gap in row d
        runs past a run of it that could not start dash 2 (the ink beside it in row 0 or 2d would refuse that
        link: so no link found before is lost). Dots (both dashes MESH_DASH px or shorter) need rows -2d and 3d
        over steps a - 1 .. b + 1 free of the ink and its mixes: else they are a mesh's samples (a fence)."""
        o = self.o
        ink, bgc = self.px(x, y, 0, 0), self.px(x, y, 1, 0)
        if ink is None or bgc is None or _diff(ink, bgc) < self.ink_min:
            return None

        def c(i: int, j: int) -> int:
            return self.cls(x, y, i, j, ink, bgc)

        def clear(i: int, j: int) -> bool:  # background, another wire's colour, or outside the frame
            return c(i, j) in (1, 3) or not self.inside(x, y, i, j)

        def window(a0: int, b0: int, d: int) -> list[tuple[int, int]]:  # rows -d .. 2d but the two dashes
            return [(i, 0) for i in range(1, b0 + 1)] + [(i, d) for i in range(a0, 1)] + \
                [(i, j) for i in range(a0, b0 + 1) for j in (-d, 2 * d)]

        a0 = None  # dash 1: ink (or another colour) back from (0, 0) to a0; background (or the frame's edge) before
        for k in range(1, o.max_run + 1):
            if not self.inside(x, y, -k, 0):  # cut by the frame: its ink must reach the edge
                if c(1 - k, 0) != 2:
                    return None
                a0 = 1 - k
                break
            ck = c(-k, 0)
            if ck == 1:
                a0 = 1 - k
                break
            if ck == 0:
                return None
        if a0 is None:
            return None
        a = min(i for i in range(a0, 1) if c(i, 0) == 2)  # its first pixel of the ink
        found = []
        for d in (1, -1):
            s = None  # the gap in row d (past another wire of the ink crossing it), then dash 2 from s
            xs = []  # steps of the crossing pixels in it
            k = 0
            while k < o.max_gap + 1:
                k += 1
                if not self.inside(x, y, k, d):
                    break
                if clear(k, d):
                    continue
                run = self.thin(x, y, k, d, ink, bgc) if k >= 2 else None
                if run is not None and self.xing(x, y, k, d, ink, bgc) and \
                        any(c(i, j) == 2 for i in range(k - 1, run[1] + 1) for j in (0, 2 * d)):
                    # a crossing that cannot start dash 2 (the ink beside it in row 0 or 2d would refuse that link)
                    xs.append(run[1])
                    k = run[1]
                    continue
                if k >= 2 and c(k, d) == 2:
                    s = k
                break
            if s is None:
                continue
            b0 = None  # dash 2: ink (or another colour) from s to b0, background (or the frame's edge) after it
            for k in range(s + 1, s + o.max_run + 1):
                if not self.inside(x, y, k, d):
                    if c(k - 1, d) == 2:
                        b0 = k - 1
                    break
                ck = c(k, d)
                if ck == 1:
                    b0 = k - 1
                    break
                if ck == 0:
                    break
            if b0 is None:
                continue
            b = max(i for i in range(s, b0 + 1) if c(i, d) == 2)  # its last pixel of the ink
            ln = Link(x, y, d, a, s, b)
            cut = self.cut_lengths(ln)
            if cut is None:
                continue  # both dashes cut by the frame
            n1, n2 = cut
            if 2 * (s - 1) > o.gap_per_run * (n1 + n2) + 2 * o.gap_slack:
                continue  # gap <= GAP_PER_RUN * mean dash + GAP_SLACK
            win = window(a0, b0, d)
            used = set()  # which allowance the window needed: "poke", "xing"

            def ok(i: int, j: int) -> bool:  # clear; another wire's end beside a dash, two rows from it; a crossing
                if clear(i, j):
                    return True
                if (j == 2 * d and i < 0 and self.poke(x, y, i, j, d, ink, bgc)) or \
                        (j == -d and i > s and self.poke(x, y, i, j, -d, ink, bgc)):
                    used.add("poke")
                    return True
                if 2 <= i <= s - 2 and self.xing(x, y, i, j, ink, bgc):
                    used.add("xing")
                    return True
                return False
            if xs:
                used.add("xing")
            # the window may reach outside the frame only beside a dash the frame cuts; crossings lie in steps
            # 2 .. s - 2 of the gap; each allowance only for links of long dashes
            if all(ok(i, j) for i, j in win) and (not xs or max(xs) <= s - 2) and \
                    (any(self.cuts(ln)) or all(self.inside(x, y, i, j) for i, j in win)) and \
                    ("poke" not in used or min(n1, n2) >= o.poke_dash) and \
                    ("xing" not in used or min(n1, n2) >= o.xing_dash) and \
                    not (max(n1, n2) <= o.mesh_dash and any(
                        self.inside(x, y, i, j) and c(i, j) in (0, 2)
                        for i in range(a - 1, b + 2) for j in (-2 * d, 3 * d))):
                # (the last: dots with more of the ink one row further out are a mesh's samples: a fence far away)
                found.append(ln)
        return found[0] if len(found) == 1 else None

    def thin(self, x: int, y: int, i: int, j: int, ink: np.ndarray, bgc: np.ndarray) -> tuple[int, int] | None:
        """The run of the ink along lattice row j through (i, j), (lo, hi), when it is at most XING_RUN steps long;
        else None (not the ink, or a longer run: a dash or a shape, not a wire crossing the row)."""
        def ink_at(ii: int) -> bool:
            return self.cls(x, y, ii, j, ink, bgc) == 2

        if not ink_at(i):
            return None
        lo = hi = i
        while lo > i - self.o.xing_run and ink_at(lo - 1):
            lo -= 1
        while hi < i + self.o.xing_run and ink_at(hi + 1):
            hi += 1
        return (lo, hi) if hi - lo + 1 <= self.o.xing_run else None

    def xing(self, x: int, y: int, i: int, j: int, ink: np.ndarray, bgc: np.ndarray) -> bool:
        """Is lattice pixel (i, j) part of another wire of the link's ink crossing its lattice rows: a thin run
        (`thin`) with a thin run of the ink on either side across the rows, in row j -+ 1 within a step of its
        ends or in row j -+ 2 within two (a steep wire, or the dashes of one under a pixel wide)?"""
        run = self.thin(x, y, i, j, ink, bgc)
        if run is None:
            return False
        lo, hi = run
        return all(any(self.thin(x, y, ii, j + t * r, ink, bgc) is not None
                       for r in (1, 2) for ii in range(lo - r, hi + r + 1)) for t in (-1, 1))

    def poke(self, x: int, y: int, i: int, j: int, out: int, ink: np.ndarray, bgc: np.ndarray) -> bool:
        """Is lattice pixel (i, j) the end of another wire of the link's ink reaching into row j from beyond it: the
        ink, in a run of at most POKE_RUN steps along row j, with the ink at step i - 1, i or i + 1 of row j + out?"""
        def ink_at(ii: int, jj: int) -> bool:
            return self.cls(x, y, ii, jj, ink, bgc) == 2

        if not ink_at(i, j) or not (ink_at(i - 1, j + out) or ink_at(i, j + out) or ink_at(i + 1, j + out)):
            return False
        lo = hi = i
        while lo > i - self.o.poke_run and ink_at(lo - 1, j):
            lo -= 1
        while hi < i + self.o.poke_run and ink_at(hi + 1, j):
            hi += 1
        return hi - lo + 1 <= self.o.poke_run

    def cuts(self, ln: Link) -> tuple[bool, bool]:
        """Is dash 1 / dash 2 of `ln` cut by the frame's edge (the step before its first / after its last
        pixel of the ink lies outside the frame)?"""
        return (not self.inside(ln.x, ln.y, ln.a - 1, 0), not self.inside(ln.x, ln.y, ln.b + 1, ln.d))

    def cut_lengths(self, ln: Link) -> tuple[int, int] | None:
        """The dash lengths (n1, n2) `ln` is judged and drawn with: a dash cut by the frame's edge is taken as
        long as the other dash when its visible part is shorter (a straight wire's dashes differ by at most one
        pixel); None when both are cut."""
        n1, n2 = 1 - ln.a, ln.b - ln.s + 1
        c1, c2 = self.cuts(ln)
        if c1 and c2:
            return None
        return (max(n1, n2) if c1 else n1), (max(n1, n2) if c2 else n2)

    def incoming(self, ln: Link) -> Link | None:
        """The link of the same direction that ends at dash 1 of `ln` (a dash before it, one lattice row back, past
        background, other colours and, before a dash 1 of XING_DASH or more, a wire of the same ink crossing the
        gap), or None. A straight wire's chain steps one way: dots that zig-zag are a mesh's samples (a fence)."""
        o, P = self.o, self.px
        ink, bgc = P(ln.x, ln.y, 0, 0), P(ln.x, ln.y, 1, 0)
        for j in (-ln.d,):
            for k in range(1, o.max_gap + 2):
                c = self.cls(ln.x, ln.y, ln.a - k, j, ink, bgc)
                if c in (1, 3):  # background, or a wire of another colour crossing the gap
                    continue
                if c == 0:
                    break
                ex, ey = self.at(ln.x, ln.y, ln.a - k, j)
                prev = self.link(ex, ey)
                if prev is not None and j + prev.d == 0 and prev.s == k:
                    return prev
                if 1 - ln.a >= o.xing_dash and self.xing(ln.x, ln.y, ln.a - k, j, ink, bgc):
                    continue  # a wire of the same ink crossing the gap, before a long dash 1
                break
        return None

    def outgoing(self, ln: Link) -> bool:
        """Does a link of the same direction start at the end of dash 2 of `ln`?"""
        nxt = self.link(*self.at(ln.x, ln.y, ln.b, ln.d))
        return nxt is not None and nxt.d == ln.d

    def touches(self, ln: Link) -> bool:
        """Does the line go on without a gap: a dash of the same ink touching dash 1 diagonally one row
        before it, or dash 2 one row after it (ink with background beyond it across the line, and beyond
        the dash it touches: the line does not turn back, as the tip of a '<' does)?"""
        P, d = self.px, ln.d
        ink, bgc = P(ln.x, ln.y, 0, 0), P(ln.x, ln.y, 1, 0)
        for i, j, back, beyond in ((ln.a - 1, -d, ln.a, -2 * d), (ln.b + 1, 2 * d, ln.b, 3 * d)):
            t, u, v = P(ln.x, ln.y, i, j), P(ln.x, ln.y, i, beyond), P(ln.x, ln.y, back, beyond)
            if t is not None and u is not None and v is not None and _diff(t, ink) <= self.ink_tol \
                    and _diff(u, bgc) <= self.bg_tol and _diff(v, bgc) <= self.bg_tol:
                return True
        return False

    def _step_diff(self, dx: int, dy: int) -> np.ndarray:
        """Max-channel difference of each pixel from the one (dx, dy) away; -1 where that is outside."""
        h, w = self.h, self.w
        res = np.full((h, w), -1.0, np.float32)
        ys, xs = slice(max(0, -dy), h - max(0, dy)), slice(max(0, -dx), w - max(0, dx))
        yt, xt = slice(max(0, dy), h - max(0, -dy)), slice(max(0, dx), w - max(0, -dx))
        res[ys, xs] = np.abs(self.rgb[ys, xs] - self.rgb[yt, xt]).max(-1)
        return res

    def to_edge(self, ln: Link, i0: int, di: int, j0: int, j1: int) -> int:
        """How many steps i0, i0 + di, ... of lattice row j0 lie in the frame before its edge, when that is at
        most the link's gap g = s - 1 and they are all background, and so are those of row j1 inside the frame;
        else 0. A chain that starts (ends) that close to the edge has its previous (next) dash, g steps on in row
        j1, outside the frame."""
        ink, bgc = self.px(ln.x, ln.y, 0, 0), self.px(ln.x, ln.y, 1, 0)
        for k in range(ln.s):
            i = i0 + k * di
            if not self.inside(ln.x, ln.y, i, j0):
                return k
            if k == ln.s - 1 or self.cls(ln.x, ln.y, i, j0, ink, bgc) != 1 or \
                    (self.inside(ln.x, ln.y, i, j1) and self.cls(ln.x, ln.y, i, j1, ink, bgc) != 1):
                return 0
        return 0

    def links(self) -> list[tuple[Link, int, int, int, int, tuple[int, int, Link] | None]]:
        """Every drawn link with the steps it owns along the lattice row, [c0, c1), the steps e0 before c0 and
        e1 after c1 it extends the band over to the frame's edge (the first or last link of a chain of three
        links or more, `to_edge`), and where a chain it ends goes on (`resumes`). A link with a dash cut by the
        frame is drawn only where the chain goes on from its other dash."""
        o = self.o
        res = []
        # candidates: a dash end differs from the pixel after it and from the one beside it (or that one lies
        # outside the frame)
        beside = self._step_diff(self.bx, self.by)
        cand = (self._step_diff(self.ax, self.ay) >= self.ink_min) & ((beside >= self.ink_min) | (beside < 0))
        for y, x in zip(*np.nonzero(cand)):
            ln = self.link(int(x), int(y))
            if ln is None:
                continue
            prev = self.incoming(ln)
            inc, out = prev is not None, self.outgoing(ln)
            cut1, cut2 = self.cuts(ln)
            if cut1 or cut2:
                if not (out if cut1 else inc):
                    continue  # a dash cut by the frame: the chain must go on from the other dash
            elif o.min_dashes >= 3 and not (inc or out or self.touches(ln)):
                continue
            c0 = math.ceil(ln.a / 2) if inc else ln.a  # the dash middles a/2 and (s + b)/2, rounded up
            c1 = math.ceil((ln.s + ln.b) / 2) if out else ln.b + 1
            # a chain of three links or more that starts (ends) within a gap of the frame's edge: the band goes on
            # to the edge in rows 0 and -d (d and 2d)
            e0 = e1 = 0
            if out and not inc and not cut1 and self.outgoing(self.link(*self.at(ln.x, ln.y, ln.b, ln.d))):
                e0 = self.to_edge(ln, ln.a - 1, -1, 0, -ln.d)
            if inc and not out and not cut2 and self.incoming(prev) is not None:
                e1 = self.to_edge(ln, ln.b + 1, 1, ln.d, 2 * ln.d)
            res.append((ln, c0, c1, e0, e1, self.resumes(ln) if inc and not out and not cut2 else None))
        return res

    def resumes(self, ln: Link) -> tuple[int, int, Link] | None:
        """Where a chain cut by a crossing goes on: `ln` ends a chain of two links or more; the first link S,
        m = 1..MAX_SKIP lattice rows beyond its dash 2, of the same direction and ink, no dash cut by the
        frame, that starts a chain of two links or more with the same period (twice the distance of the dash
        middles, P2 = s + b - a) and whose dash 1's middle lies m periods after the middle of dash 2 of `ln`
        (both within max(12, P2) / 4 half steps): (m, the step of S's dash 1 end, S), or None."""
        P, d = self.px, ln.d
        ink, bgc = P(ln.x, ln.y, 0, 0), P(ln.x, ln.y, 1, 0)
        p2 = ln.s + ln.b - ln.a
        q = max(12, p2)
        for m in range(1, self.o.max_skip + 1):
            c = ln.s + ln.b + m * p2  # twice the middle of dash 1 of S expected
            for i in range((4 * c - q) // 8, (4 * c + q + 4 * self.o.max_run) // 8 + 1):
                if i <= ln.b or self.cls(ln.x, ln.y, i, (m + 1) * d, ink, bgc) != 2 \
                        or self.cls(ln.x, ln.y, i + 1, (m + 1) * d, ink, bgc) != 1:
                    continue
                sx, sy = self.at(ln.x, ln.y, i, (m + 1) * d)
                s = self.link(sx, sy)
                if s is None or s.d != d or 4 * abs(2 * i + s.a - c) > q or 4 * abs(s.s + s.b - s.a - p2) > q \
                        or any(self.cuts(s)) or not self.outgoing(s):
                    continue
                return m, i, s
        return None


def _coverage(delta: np.float32, half: np.float32, diagonal: bool) -> np.float32:
    """Coverage of a pixel by a band of half thickness `half` (in lattice rows) whose centre lies `delta`
    rows from the pixel's: rows and columns, the overlap of two intervals (the pixel spans one row);
    diagonal lattices, the integral of the pixel's triangular footprint across the rows (support +-1)."""
    f32 = np.float32
    lo, hi = delta - half, delta + half
    if not diagonal:
        top, bot = min(hi, f32(0.5)), max(lo, f32(-0.5))
        return f32(top - bot) if top > bot else f32(0)
    return _tri_cdf(hi) - _tri_cdf(lo)


def _tri_cdf(t: np.float32) -> np.float32:
    f32 = np.float32
    if t <= f32(-1):
        return f32(0)
    if t <= f32(0):
        return f32(0.5) * (t + f32(1)) * (t + f32(1))
    if t < f32(1):
        return f32(1) - f32(0.5) * (f32(1) - t) * (f32(1) - t)
    return f32(1)


def _draw(scan: _Scan, lin: np.ndarray, diagonal: bool) -> dict[tuple[int, int], tuple[int, np.ndarray]]:
    """Find the links of one orientation and the pixels they write: {(x, y): (claim, RGB in the mixing
    space)}; a link that ends a chain cut by a crossing also writes the band across the cut (`resumes`), over
    background pixels. A pixel of another colour than the link's background and ink (a crossing wire), or of the ink
    over the gap (a wire of the same ink crossing it), is never written;
    a pixel two links would write goes to the lower claim (index of the pixel where dash 1 ends), as the
    kernel's atomic_min settles it."""
    f32 = np.float32
    res: dict[tuple[int, int], tuple[int, np.ndarray]] = {}
    for ln, c0, c1, e0, e1, on in scan.links():
        cid = ln.y * scan.w + ln.x
        (n1, n2), g = scan.cut_lengths(ln), ln.s - 1  # a dash cut by the frame: as long as the other one
        m1, m2 = f32(1 - n1) * f32(0.5), f32(2 * ln.s + n2 - 1) * f32(0.5)  # dash middles (dash 1 ends at 0)
        n = f32(n1 + n2) * f32(0.5)
        half = f32(0.5) * n / (n + f32(g))  # the band's half thickness: W = n / (n + g) rows
        bx, by = scan.at(ln.x, ln.y, 1, 0)
        sx, sy = scan.at(ln.x, ln.y, ln.s, ln.d)
        bgc = lin[by, bx]
        ink = (lin[ln.y, ln.x] + lin[sy, sx]) * f32(0.5)
        raw_ink, raw_bgc = scan.rgb[ln.y, ln.x], scan.rgb[by, bx]
        for i in range(c0 - e0, c1 + e1):
            u = (f32(i) - m1) / (m2 - m1)  # the band's centre, in rows from row 0 toward row d
            j0 = -ln.d if i < c0 else (ln.d if i >= c1 else 0)  # the two rows the band crosses at step i
            for j, delta in ((j0, u - f32(j0 * ln.d)), (j0 + ln.d, u - f32(j0 * ln.d + 1))):
                if not scan.inside(ln.x, ln.y, i, j):
                    continue
                k = scan.cls(ln.x, ln.y, i, j, raw_ink, raw_bgc)
                if k == 3 or (k == 2 and 0 < i < ln.s):  # another wire's pixel, or one of the ink crossing the gap
                    continue
                px, py = scan.at(ln.x, ln.y, i, j)
                if (px, py) not in res or cid < res[(px, py)][0]:
                    res[(px, py)] = (cid, bgc + _coverage(delta, half, diagonal) * (ink - bgc))
        if on is None:
            continue
        # the cut: the band from the middle of dash 2 (row d) to the middle of dash 1 of S (row (m + 1) d),
        # over the background pixels of rows d .. (m + 1) d between the two dashes
        m, i_s, sl = on
        ms = f32(i_s) + f32(sl.a) * f32(0.5)
        for i in range(ln.b + 1, i_s + sl.a):
            v = f32(m) * (f32(i) - m2) / (ms - m2)  # the band's centre, rows beyond row d
            for r in range(m + 1):
                j = (r + 1) * ln.d
                cov = _coverage(v - f32(r), half, diagonal)
                if cov <= f32(0) or scan.cls(ln.x, ln.y, i, j, raw_ink, raw_bgc) != 1:
                    continue
                px, py = scan.at(ln.x, ln.y, i, j)
                if (px, py) not in res or cid < res[(px, py)][0]:
                    res[(px, py)] = (cid, bgc + cov * (ink - bgc))
    return res


def _to_mix(rgb: np.ndarray, o: BridgeOptions) -> np.ndarray:
    if o.linear and not o.linear_input:
        luts = device_luts()
        return np.stack([lut_read(luts, rgb[..., c]) for c in range(3)], -1).astype(np.float32)
    return rgb


def _from_mix(v: np.ndarray, o: BridgeOptions) -> np.ndarray:
    if o.linear and not o.linear_input:
        enc = device_luts()[2 * (LUT_SIZE + 1):]
        return np.stack([lut_read(enc, v[..., c]) for c in range(3)], -1).astype(np.float32)
    return v


def _load_rgb(frame: np.ndarray, fmt: FrameFormat) -> np.ndarray:
    """common.cl's load_px, RGB only: float32 (H, W, 3) normalised."""
    pmax = np.float32({np.uint8: 255.0, np.uint16: 65535.0}.get(fmt.dtype.type, 1.0))
    a = np.asarray(frame).astype(np.float32).reshape(fmt.height, fmt.width, fmt.channels) * (np.float32(1) / pmax)
    if fmt.channels == 1:
        return np.repeat(a[..., :1], 3, -1)
    return np.ascontiguousarray(a[..., 2::-1] if fmt.bgr else a[..., :3])


def _store(v: np.ndarray, fmt: FrameFormat) -> np.ndarray:
    """common.cl's store_px / to_pixel for RGB values (H, W, 3): round half up, clamped."""
    if fmt.channels == 1:
        v = v[..., :1]
    elif fmt.bgr:
        v = v[..., ::-1]
    if fmt.dtype.kind == "f":
        return v.astype(fmt.dtype)
    pmax = np.float32(np.iinfo(fmt.dtype).max)
    t = np.clip(v.astype(np.float32) * pmax + np.float32(0.5), 0, pmax)
    return t.astype(fmt.dtype)


def bridge_reference(src: np.ndarray, dst: np.ndarray | None = None, *, bgr: bool = False,
                     options: BridgeOptions | None = None) -> np.ndarray:
    """Plain numpy version of the pass (slow, obvious): links found in `src`, drawn into a copy of `dst`
    (default: `src`), one orientation after the other in ORIENTATIONS' order, as kernels/bridge.cl runs them."""
    o = options or BridgeOptions()
    fmt = frame_format(src, bgr)
    base = src if dst is None else dst
    if frame_format(base, bgr) != fmt:
        raise ValueError(f"bridge: expected dst like src {fmt}, got {frame_format(base, bgr)}")
    rgb = _load_rgb(src, fmt)
    lin = _to_mix(rgb, o)
    out = np.array(base, copy=True)
    view = out.reshape(fmt.height, fmt.width, fmt.channels)
    for ab in ORIENTATIONS:
        pix = _draw(_Scan(rgb, ab, o), lin, ab[0][0] != 0 and ab[0][1] != 0)
        if pix:
            ys, xs = np.array([p[1] for p in pix]), np.array([p[0] for p in pix])
            vals = _store(_from_mix(np.stack([v for _, v in pix.values()])[None], o), fmt)[0]
            view[ys, xs, :vals.shape[-1]] = vals
    return out


# ----------------------------------------------------------------------------------------------
# The OpenCL pass
# ----------------------------------------------------------------------------------------------

SEGMENT = 64  # pixels of a row per work item (kernels/common.cl), as in the core filter's passes


class Bridger:
    """The bridging pass for one frame format: kernels built and work buffers allocated once, then `enqueue`
    per frame. Links are found in src and drawn into dst (a different buffer laid out like the frame, e.g.
    the MLAA output)."""

    def __init__(self, context: Context, fmt: FrameFormat, options: BridgeOptions | None = None):
        o = options or BridgeOptions()
        if not (1 <= o.max_gap <= 30 and 1 <= o.max_run <= 32):  # kernels/bridge.cl packs links in 16 bits
            raise ValueError(f"bridge: expected max_gap in 1..30 and max_run in 1..32, got {o.max_gap} "
                             f"and {o.max_run}")
        if o.min_dashes not in (2, 3):
            raise ValueError(f"bridge: expected min_dashes 2 or 3, got {o.min_dashes}")
        if not 0 <= o.max_skip <= 3:
            raise ValueError(f"bridge: expected max_skip in 0..3, got {o.max_skip}")
        self.fmt, self.options = fmt, o
        defines = defines_for(fmt, SEGMENT=SEGMENT, **o.defines())
        self._find = context.kernel("bridge", "bridge_find", defines)
        self._claim = context.kernel("bridge", "bridge_claim", defines)
        self._draw = context.kernel("bridge", "bridge_draw", defines)
        # per pixel: 1 byte, bit o = "a link of orientation o ends here", 4 packed links (2 bytes each), the
        # claim of the link that draws it (all ones when none: filled once, each draw pass resets what it used),
        # and the claim pass's verdict on the link ending here (read by the draw pass of the same orientation)
        self._found = context.buffer(fmt.pixels)
        self._links = context.buffer(8 * fmt.pixels)
        self._claims = context.buffer(4 * fmt.pixels)
        self._verdicts = context.buffer(4 * fmt.pixels)
        cl.enqueue_fill_buffer(context.queue, self._claims, np.uint32(0xFFFFFFFF), 0, 4 * fmt.pixels).wait()
        self._global = (-(-fmt.width // SEGMENT), fmt.height)
        # per work item (the launch's padded grid): the orientations found
        padded, _ = launch_size(self._global, bool(context.device.type & cl.device_type.CPU))
        self._segments = context.buffer(padded[0] * padded[1])
        self._last = None  # this pass's previous frame: its work buffers are reused

    def device_bytes(self) -> int:
        return self._found.size + self._links.size + self._claims.size + self._verdicts.size + self._segments.size

    def enqueue(self, queue: "cl.CommandQueue", src: "cl.Buffer", dst: "cl.Buffer", luts: "cl.Buffer",
                wait_for: list | None = None, events: dict | None = None) -> "cl.Event":
        """Enqueue the find pass (all orientations), then the claim and draw passes per orientation in order;
        returns the last event. `events`, when given, receives each kernel's event (bridge_find, bridge_claim0..3,
        bridge_draw0..3)."""
        check_pass_buffers("bridge", self.fmt, src, dst)
        W, H = np.int32(self.fmt.width), np.int32(self.fmt.height)
        ev = list(wait_for or []) + ([self._last] if self._last is not None else [])
        rec = {} if events is None else events
        rec["bridge_find"] = self._find(queue, self._global, None, src, self._found, self._links, self._segments,
                                        W, H, wait_for=ev)
        ev = [rec["bridge_find"]]
        for o in range(len(ORIENTATIONS)):  # in order: a later orientation's pixels overwrite an earlier's
            rec[f"bridge_claim{o}"] = self._claim(queue, self._global, None, src, self._found, self._links,
                                                  self._segments, self._claims, self._verdicts, W, H, np.int32(o),
                                                  wait_for=ev)
            rec[f"bridge_draw{o}"] = self._draw(queue, self._global, None, src, dst, luts, self._found, self._links,
                                                self._segments, self._claims, self._verdicts, W, H, np.int32(o),
                                                wait_for=[rec[f"bridge_claim{o}"]])
            ev = [rec[f"bridge_draw{o}"]]
        self._last = ev[0]
        return self._last


def bridge(src: np.ndarray, dst: np.ndarray | None = None, *, device=None, bgr: bool = False,
           options: BridgeOptions | None = None) -> np.ndarray:
    """Run the pass on one frame (upload, kernels, download): links found in `src`, drawn into a copy of
    `dst` (default: `src`); same shape and dtype as `src`."""
    fmt = frame_format(src, bgr)
    base = src if dst is None else dst
    if frame_format(base, bgr) != fmt or np.shape(base) != np.shape(src):
        raise ValueError(f"bridge: expected dst like src {np.shape(src)} {src.dtype}, "
                         f"got {np.shape(base)} {base.dtype}")
    ctx = default_context(device)
    mf = cl.mem_flags
    d_src = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(src, dtype=fmt.dtype))
    out = np.ascontiguousarray(base, dtype=fmt.dtype).copy()
    d_dst = cl.Buffer(ctx.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=out)
    luts = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=device_luts())
    Bridger(ctx, fmt, options).enqueue(ctx.queue, d_src, d_dst, luts)
    cl.enqueue_copy(ctx.queue, out, d_dst)
    return out.astype(src.dtype, copy=False).reshape(src.shape)
