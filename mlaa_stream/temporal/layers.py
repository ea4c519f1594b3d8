"""Moving layers: the TSS motion model for frames where one translation does not explain the scene (issue 16:
"static / one global translation or affine / per moving layer / dense DIS flow, chosen per frame").

A frame that choose_model classes dense (a turning object over a still background, a mover) is explained as a
background translation plus a few layers, each moving by one map (the issue's experiment: ECC-fitted Euclidean
layers found by frame differencing, background within 2 px of a silhouette moved with the layer):

  1. background: choose_model's translation, or none where no motion leaves no larger residual sum
     (`background_of`); tss.MotionRing also takes a slow global frame for a still background where the ring's
     baseline shows it (`still_background`: an object turning over it pulls one translation to ~0.2 px per frame);
  2. regions: the flow-size texels the background's motion leaves over LAYER_LEVEL (blurred grey, blobs that
     survive a 3x3 erosion, as choose_model's outliers), merged within LAYER_MERGE texels, connected regions of
     LAYER_MIN_AREA texels or more; where their convex hull covers more than LAYER_MAX_SHARE of the frame the camera
     moved (a dolly, an orbit: parallax), which layers do not model: no layers;
  3. one layer for the hull of all regions first (a turning object changes along its rim in pieces, each a straight
     edge that fixes only the motion across it), each region's hull on its own only where that fails; its map from
     the current frame to the previous one: the first of affine, similarity and Euclidean that its points fix
     (`LayerPoints.conditioning`), started from the median DIS flow of the points that moved, refined by
     inverse-compositional Gauss-Newton (Baker and Matthews) at the current frame's largest gradients that the
     background leaves off by over LAYER_STILL; kept where it leaves under LAYER_FIT_SHARE of the background's
     median residual there;
  4. labels: inside a layer's hull a texel moves with the layer unless the background explains it better
     (3x3 mean residuals); layer texels are grown by LAYER_GROW texels into the background (motion-vector
     dilation: the background next to a silhouette moves with it); changed texels nothing explains take no
     samples; layers under LAYER_MIN_SHARE of the frame are not worth a field per ring frame: no layers;
  5. ring (`layer_fields`; frames ahead: `ahead_fields`): each ring frame's map becomes a field (full-size px at
     flow size, as the dense path's): its own background translation everywhere, each layer's map on that layer's
     texels. A ring frame's map for a layer starts from its previous field composed with this frame's layer map
     (fitted at the layer's points) and is refined *directly* against that ring frame (chaining alone drifts).

MotionRing then checks every field per region (_alignment) and the colour box rejects the rest; TSSStage resolves
the layers' rectangle with the general kernel (FULL_CELLS_FIELDS) and the rest with the background's translations.
docs/temporal.md, "Moving layers".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from mlaa_stream.temporal.stage import GLOBAL_MIN_SHIFT, Decision, Pyramid

LAYER_LEVEL = 10.0       # grey levels: a texel the background's motion leaves this far off has moved by itself
LAYER_MERGE = 4          # texels: changed blobs this close are one layer
LAYER_MIN_AREA = 24      # texels: smaller regions are not layers (they take no samples)
LAYER_MIN_SHARE = 0.01   # layers taking less of the frame are not worth their cost (a field, steps and a check per
                         # ring frame: ~6 ms at 1080p): the ring restarts as without layers
LAYER_MAX = 4            # layers per frame (the largest)
LAYER_MAX_SHARE = 0.5    # the changed regions' convex hull over this share of the frame: the camera moved (parallax)
LAYER_POINTS = 4096      # a layer's Gauss-Newton points (its largest gradients)
LAYER_ROBUST = 8.0       # grey levels: robust scale of a layer's steps (its region holds uncovered background too)
LAYER_STEPS = 5          # steps for the newest ring frame's map
LAYER_REFINE_STEPS = 2   # ... and for each older ring frame's, from the composed map
LAYER_FIT_SHARE = 0.85   # a layer's map must leave under this share of the background's median |residual| at its points
LAYER_FIT_LEVEL = 4.0    # a ring frame's map refined from the composed one: median |residual| over this, not found
LAYER_CONDITION = 0.05   # LayerPoints.conditioning under this: the points do not fix an affine map (one edge)
LAYER_MARGIN = 1.0       # grey levels: a texel of a layer's region stays with the background where its residual is
                         # lower by this
LAYER_STILL = 2.0        # grey levels: a region's texel the background's motion explains this well is no point of the
                         # layer's fit (still texture next to a mover fits it to no motion, or to the texture's period)
STILL_SHIFT = 1.0        # px: a global frame moving less than this is tested for a still background
                         # (tss.MotionRing._still_background) ...
STILL_AGE = 3            # ... over a ring of at least this many frames, where no motion leaves a sum of residuals
STILL_MARGIN = 1.0       # ... no larger than the moving background's (still_background) ...
STILL_SHARE = 0.5        # ... and this share of the textured texels unchanged
STILL_TEXTURE = 4.0      # grey levels per texel: textured (blurred gradient magnitude)
LAYER_MISFIT = 0.05     # share of a layer's texels its map may leave over LAYER_LEVEL (a right map: under 1 %; a map
                        # locked to the period of stripes a box moves over: 10-13 %)
LAYER_GROW = 1           # texels (flow size): layer labels grown into the background


def sample_bilinear(img: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """img at positions (x, y), exact bilinear interpolation, positions clamped to the frame."""
    h, w = img.shape
    # in place on this function's own temporaries (a step samples 16k points, ~25 times per 1080p frame); the
    # fractions in float64 whatever the positions' type, as x - x0 gives them
    x = np.clip(x, 0, w - 1).astype(np.float64, copy=False)
    y = np.clip(y, 0, h - 1).astype(np.float64, copy=False)
    x0 = x.astype(np.intp)
    np.minimum(x0, max(w - 2, 0), out=x0)
    i = y.astype(np.intp)
    np.minimum(i, max(h - 2, 0), out=i)
    y -= i   # ay
    x -= x0  # ax
    i *= w
    i += x0
    flat = img.ravel()
    dx, dy = (1 if w > 1 else 0), (w if h > 1 else 0)
    p00 = flat.take(i)
    i += dx
    p01 = flat.take(i)
    i += dy
    p11 = flat.take(i)
    i -= dx
    p10 = flat.take(i)
    p01 -= p00
    top = x * p01
    top += p00      # p00 + ax (p01 - p00)
    p11 -= p10
    out = x * p11
    out += p10
    out -= top
    out *= y
    out += top      # top + ay (p10 + ax (p11 - p10) - top)
    return out


def _steepest(u: np.ndarray, v: np.ndarray, gu: np.ndarray, gv: np.ndarray, dof: int) -> np.ndarray:
    """The steepest-descent images of a map's parameters at points (u, v) of gradients (gu, gv): dof 3 (Euclidean:
    rotation, shift), 4 (similarity: scale, rotation, shift), 6 (affine) or 8 (homography)."""
    if dof == 3:
        return np.stack([gv * u - gu * v, gu, gv], -1)
    if dof == 4:
        return np.stack([gu * u + gv * v, gv * u - gu * v, gu, gv], -1)
    cols = [gu * u, gu * v, gu, gv * u, gv * v, gv]
    if dof == 8:
        cols += [-(gu * u + gv * v) * u, -(gu * u + gv * v) * v]
    return np.stack(cols, -1)


def _step_map(p: np.ndarray, dof: int) -> np.ndarray:
    """The 3x3 map of a parameter step (the parameters of _steepest)."""
    if dof == 3:
        c, s = math.cos(p[0]), math.sin(p[0])
        return np.array([[c, -s, p[1]], [s, c, p[2]], [0.0, 0.0, 1.0]])
    if dof == 4:
        return np.array([[1 + p[0], -p[1], p[2]], [p[1], 1 + p[0], p[3]], [0.0, 0.0, 1.0]])
    q = np.zeros(8)
    q[:dof] = p
    return np.array([[1 + q[0], q[1], q[2]], [q[3], 1 + q[4], q[5]], [q[6], q[7], 1.0]])


class CompositionalPoints:
    """What inverse_compositional's steps at fixed points reuse from call to call: the steepest-descent matrix, the
    points' homogeneous coordinates and the coordinates' normalisation (they depend on the points and dof alone)."""

    def __init__(self, xs: np.ndarray, ys: np.ndarray, gx: np.ndarray, gy: np.ndarray, shape: tuple[int, int],
                 dof: int):
        h, w = shape
        cx, cy, sc = (w - 1) / 2.0, (h - 1) / 2.0, max(w, h) / 2.0
        self.sd = _steepest((xs - cx) / sc, (ys - cy) / sc, gx * sc, gy * sc, dof)
        self.norm = np.array([[1 / sc, 0, -cx / sc], [0, 1 / sc, -cy / sc], [0, 0, 1.0]])
        self.denorm = np.linalg.inv(self.norm)
        self.pts = np.stack([xs, ys, np.ones_like(xs)], -1)


def inverse_compositional(ring_b: np.ndarray, m: np.ndarray, steps: int, xs: np.ndarray, ys: np.ndarray,
                          c: np.ndarray, gx: np.ndarray, gy: np.ndarray, shape: tuple[int, int], dof: int,
                          robust: float, prepared: CompositionalPoints | None = None) -> np.ndarray:
    """`steps` inverse-compositional Gauss-Newton steps (Baker and Matthews) of the map m (3x3, flow px) with
    cur(x) ~ ring(m x) at points (xs, ys) of values c and gradients (gx, gy) of the current frame; dof 8
    (homography), 6 (affine), 4 (similarity) or 3 (Euclidean); residuals weighted 1 / (1 + (r / robust)^2);
    coordinates centred and scaled to [-1, 1] for the parameters' conditioning. `prepared`: the same points'
    CompositionalPoints (of this dof) when the caller keeps them, else made here."""
    p = CompositionalPoints(xs, ys, gx, gy, shape, dof) if prepared is None else prepared
    sd, norm, denorm, pts = p.sd, p.norm, p.denorm, p.pts
    m = np.array(m, np.float64)
    for _ in range(steps):
        q = pts @ m.T
        r = sample_bilinear(ring_b, q[:, 0] / q[:, 2], q[:, 1] / q[:, 2])
        r -= c
        wr = r * r   # 1 / (1 + (r / robust)^2), in place
        wr *= 1.0 / (robust * robust)
        wr += 1.0
        np.divide(1.0, wr, out=wr)
        # sd * wr[:, None] as one flat product (a broadcast over rows of dof values is slower), then matrix
        # products: faster here than einsum and add.reduce
        hess = (sd.ravel() * np.repeat(wr, sd.shape[1])).reshape(sd.shape).T @ sd
        b = (wr * r) @ sd
        try:
            dp = np.linalg.solve(hess, b)
        except np.linalg.LinAlgError:
            break
        m = m @ (denorm @ np.linalg.inv(_step_map(dp, dof)) @ norm)
        m /= m[2, 2]
    return m


class LayerPoints:
    """One layer's Gauss-Newton points: the current frame's largest gradients inside its region (flow size)."""

    def __init__(self, cur_b: np.ndarray, region: np.ndarray, gx: np.ndarray, gy: np.ndarray,
                 energy: np.ndarray | None = None):
        """`energy`: gx^2 + gy^2 when the caller has it (one per frame for every layer)."""
        self.shape = cur_b.shape
        x, y, w, h = cv2.boundingRect(region.astype(np.uint8))   # the region's texels only (one small region of
        box = (slice(y, y + h), slice(x, x + w))                  # a large frame)
        e = (gx[box] * gx[box] + gy[box] * gy[box]) if energy is None else energy[box]
        ys, xs = np.nonzero(region[box] & (e > 1e-3))
        if ys.size > LAYER_POINTS:
            top = np.argpartition(-e[ys, xs], LAYER_POINTS - 1)[:LAYER_POINTS]
            ys, xs = ys[top], xs[top]
        ys, xs = ys + y, xs + x
        self.iy, self.ix = ys, xs
        self.xs, self.ys = xs.astype(np.float64), ys.astype(np.float64)
        self.c = cur_b[ys, xs].astype(np.float64)
        self.gx, self.gy = gx[ys, xs].astype(np.float64), gy[ys, xs].astype(np.float64)

    def conditioning(self, dof: int = 6) -> float:
        """The smallest over the largest eigenvalue of the Gauss-Newton matrix of a map with `dof` parameters
        (6 affine, 4 similarity, 3 Euclidean; coordinates scaled to [-1, 1] over the layer's points): near 0 where
        the points do not fix them all (one straight edge fixes only the motion across it)."""
        if self.count < dof:
            return 0.0
        cx, cy = self.xs.mean(), self.ys.mean()
        sc = max(np.ptp(self.xs), np.ptp(self.ys), 1.0) / 2.0
        sd = _steepest((self.xs - cx) / sc, (self.ys - cy) / sc, self.gx, self.gy, dof)
        ev = np.linalg.eigvalsh(sd.T @ sd)
        return float(ev[0] / ev[-1]) if ev[-1] > 0 else 0.0

    @property
    def count(self) -> int:
        return int(self.xs.size)

    def refine(self, ring_b: np.ndarray, m: np.ndarray, steps: int, dof: int = 6) -> tuple[np.ndarray, float]:
        """The map m (flow px, current -> ring frame; dof 6 affine, 4 similarity, 3 Euclidean) after `steps`
        steps, and its median |residual|."""
        m = inverse_compositional(ring_b, m, steps, self.xs, self.ys, self.c, self.gx, self.gy, self.shape, dof,
                                  LAYER_ROBUST)
        q = np.stack([self.xs, self.ys, np.ones_like(self.xs)], -1) @ m.T
        r = sample_bilinear(ring_b, q[:, 0] / q[:, 2], q[:, 1] / q[:, 2]) - self.c
        return m, float(np.median(np.abs(r))) if r.size else math.inf

    def fit_to(self, fld: np.ndarray, fs: int, m: np.ndarray, dof: int = 6) -> np.ndarray | None:
        """The map (flow px; dof 6 affine, 4 similarity, 3 Euclidean) that best fits, at the points, positions m(x)
        moved on by the field `fld` (full-size px at flow size, read at m(x)): the composition of m with a ring
        frame's previous map. None where too few of those positions have a finite field."""
        q = np.stack([self.xs, self.ys, np.ones_like(self.xs)], -1) @ m.T
        qx, qy = q[:, 0] / q[:, 2], q[:, 1] / q[:, 2]
        off = np.stack([sample_bilinear(fld[..., k], qx, qy) for k in (0, 1)], -1) / fs
        ok = np.isfinite(off).all(-1)
        k = int(np.count_nonzero(ok))
        if k < 6:
            return None
        x, y, one, zero = self.xs[ok], self.ys[ok], np.ones(k), np.zeros(k)
        tx, ty = qx[ok] + off[ok, 0], qy[ok] + off[ok, 1]
        if dof in (3, 4):   # x' = a x - b y + c, y' = b x + a y + d (Euclidean: a, b scaled to a rotation)
            a = np.concatenate([np.stack([x, -y, one, zero], -1), np.stack([y, x, zero, one], -1)])
            (p, r, c, d), *_ = np.linalg.lstsq(a, np.concatenate([tx, ty]), rcond=None)
            if dof == 3:
                k = math.hypot(p, r) or 1.0
                mx, my = x.mean(), y.mean()   # keep the points' mean where the fit puts it
                p, r = p / k, r / k
                c, d = tx.mean() - (p * mx - r * my), ty.mean() - (r * mx + p * my)
            return np.array([[p, -r, c], [r, p, d], [0.0, 0.0, 1.0]])
        sol, *_ = np.linalg.lstsq(np.stack([x, y, one], -1), np.stack([tx, ty], -1), rcond=None)
        return np.vstack([sol.T, [0.0, 0.0, 1.0]])


@dataclass
class Layer:
    """One moving layer of the current frame: its texels (flow size), points and map to the previous frame."""

    texels: np.ndarray        # bool (fh, fw): texels that move with it (labels, grown)
    points: LayerPoints
    affine: np.ndarray        # 3x3 flow px, current -> previous frame
    dof: int = 6              # the map's parameters: 6 affine, 4 similarity, 3 Euclidean (what the points fix)
    core: np.ndarray | None = None   # bool (fh, fw): its texels before the labels grew (where it is; None: texels)

    def __post_init__(self) -> None:
        ys, xs = np.nonzero(self.texels)
        self.box = (slice(int(ys.min()), int(ys.max()) + 1), slice(int(xs.min()), int(xs.max()) + 1)) if ys.size \
            else (slice(0, 0), slice(0, 0))
        self.inside = self.texels[self.box]   # the texels inside the bounding box


def translation_map(d: tuple[float, float]) -> np.ndarray:
    """The 3x3 map of a translation by d (in the map's own px)."""
    return np.array([[1.0, 0.0, d[0]], [0.0, 1.0, d[1]], [0.0, 0.0, 1.0]])


def _box_residual(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return cv2.blur(np.abs(a - b), (3, 3))


def _warp(img: np.ndarray, m: np.ndarray) -> np.ndarray:
    h, w = img.shape
    return cv2.warpAffine(img, m[:2].astype(np.float64), (w, h), flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                          borderMode=cv2.BORDER_REPLICATE)


def _changed(prev_b: np.ndarray, cur_b: np.ndarray, m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(prev warped by m, blobs of residual over LAYER_LEVEL that survive a 3x3 erosion) at flow size."""
    warped = _warp(prev_b, m)
    blobs = cv2.erode((np.abs(warped - cur_b) > LAYER_LEVEL).astype(np.uint8), np.ones((3, 3), np.uint8))
    return warped, blobs


def _hull(mask: np.ndarray) -> np.ndarray:
    """The filled convex hull of a mask's texels (a turning object's changed texels are its rim: the hull
    holds the rest of it)."""
    m = mask.astype(np.uint8)
    out = np.zeros(mask.shape, np.uint8)
    pts = cv2.findNonZero(m)
    if pts is not None:
        cv2.fillConvexPoly(out, cv2.convexHull(pts), 1)
    return (out | m).astype(bool)


def residual_sum(prev: Pyramid, cur: Pyramid, d: tuple[float, float]) -> float:
    """Sum of |cur - prev moved by d (full-size px)| over the blurred flow-size grey."""
    return float(_residual(prev, cur, d).sum())


def _moved(prev: Pyramid, cur: Pyramid, d: tuple[float, float]) -> np.ndarray:
    fs = cur.flow_scale
    return _warp(prev.blurred("flow"), translation_map((d[0] / fs, d[1] / fs)))


def _residual(prev: Pyramid, cur: Pyramid, d: tuple[float, float]) -> np.ndarray:
    """|prev moved by d - cur| on the blurred flow-size grey (in place on the warp: no frame-size temporaries)."""
    r = _moved(prev, cur, d)
    np.subtract(r, cur.blurred("flow"), out=r)
    return np.abs(r, out=r)


def still_background(far: Pyramid, cur: Pyramid, moved: tuple[float, float]) -> bool:
    """Is the background still between ring frame `far` and `cur`, rather than moved by `moved` (full-size px)?
    Both: no motion leaves no larger sum of residuals (STILL_MARGIN), and at least STILL_SHARE of the current
    frame's textured texels (blurred gradient over STILL_TEXTURE levels per texel) match unmoved within one level
    (a still background is the same texels; a moving object over it changes its own). Each alone is fooled: a slow
    vector pan's 1-spp frames keep most near-horizontal edges unchanged for frames (share 0.54-0.67 at ages 3-5),
    and a large textured object turning leaves a residual sum near the moving background's (ratio 0.94-0.96)."""
    still = _residual(far, cur, (0.0, 0.0))
    if float(still.sum()) > STILL_MARGIN * float(_residual(far, cur, moved).sum()):
        return False
    if "still_texture" not in cur._blur:
        gx, gy = cur.gradients("flow")[:2]   # the Sobel gradients of the blurred flow-size grey
        cur._blur["still_texture"] = cv2.magnitude(gx, gy) > STILL_TEXTURE
    tex = cur._blur["still_texture"]
    textured = np.count_nonzero(tex)
    return bool(textured) and np.count_nonzero((still < 1.0) & tex) >= STILL_SHARE * textured


def background_of(dec: Decision, prev: Pyramid, cur: Pyramid) -> tuple[float, float]:
    """The background's translation (full-size px): choose_model's, or none where no motion leaves no larger a sum
    of residuals (a mover pulled the frame's robust estimate off a still background: the background's texels are
    then explained exactly by no motion, while a moving background adds its displacement everywhere)."""
    d = dec.translation
    if dec.measures.get("still_background"):
        return (0.0, 0.0)
    if math.hypot(*d) < GLOBAL_MIN_SHIFT or residual_sum(prev, cur, (0.0, 0.0)) <= residual_sum(prev, cur, d):
        return (0.0, 0.0)
    return (float(d[0]), float(d[1]))


def _fit(pts: LayerPoints, prev_b: np.ndarray, fl: np.ndarray,
         bg_f: tuple[float, float]) -> tuple[np.ndarray, int] | None:
    """A layer's map to the previous frame (flow px) and its parameter count: the first of affine, similarity and
    Euclidean that the points fix (LAYER_CONDITION: a turning square whose rim moves by more than LAYER_STILL only
    near its corners fixes no affine map; a wheel's radial spokes fix no scale), else none. From the median DIS flow
    of its points that moved against the background (else from the background's translation), LAYER_STEPS
    Gauss-Newton steps. None also where the map does not explain the points: the median |residual| stays over
    LAYER_FIT_SHARE of the background's there (1-spp aliasing leaves a few levels at the edges of a right map)."""
    if pts.count < 16:
        return None
    dof = next((d for d in (6, 4, 3) if pts.conditioning(d) >= LAYER_CONDITION), None)
    if dof is None:
        return None
    f = fl[pts.iy, pts.ix]
    moved = np.hypot(f[:, 0] - bg_f[0], f[:, 1] - bg_f[1]) > 0.5
    start = np.median(f[moved], axis=0) if np.count_nonzero(moved) >= 16 else np.array(bg_f)
    m, level = pts.refine(prev_b, translation_map((float(start[0]), float(start[1]))), LAYER_STEPS, dof)
    _, level_bg = pts.refine(prev_b, translation_map(bg_f), 0)
    return (m, dof) if level <= LAYER_FIT_SHARE * level_bg else None


def find_layers(prev: Pyramid, cur: Pyramid, bg: tuple[float, float], flow) -> tuple[list[Layer], np.ndarray] | None:
    """The moving layers of `cur` relative to `prev` with the background moving by `bg` (full-size px):
    (layers, texels of regions no layer explains), or None where layers do not explain the frame (nothing
    moved by itself, or most of the frame did). All changed regions are tried as one layer first (a turning
    object changes along its rim, in several pieces), then each on its own. `flow(a, b, start)`: DIS flow
    cur -> prev (the start of each fit)."""
    fs = cur.flow_scale
    cur_b, prev_b = cur.blurred("flow"), prev.blurred("flow")
    fh, fw = cur_b.shape
    bg_f = (bg[0] / fs, bg[1] / fs)
    warped_bg, blobs = _changed(prev_b, cur_b, translation_map(bg_f))
    if not blobs.any():
        return None
    merged = cv2.dilate(blobs, np.ones((2 * LAYER_MERGE + 1,) * 2, np.uint8))
    n, lab, stats, _ = cv2.connectedComponentsWithStats(merged, connectivity=8)
    comps = sorted((k for k in range(1, n) if stats[k, cv2.CC_STAT_AREA] >= LAYER_MIN_AREA),
                   key=lambda k: -stats[k, cv2.CC_STAT_AREA])
    if not comps:
        return None
    union = _hull(np.isin(lab, comps))
    if np.count_nonzero(union) > LAYER_MAX_SHARE * union.size:
        return None   # changes all over the frame: the camera moved (a dolly, an orbit), with parallax
    unexplained = merged > 0
    gx = cv2.Sobel(cur_b, cv2.CV_32F, 1, 0, ksize=3, scale=0.125)
    gy = cv2.Sobel(cur_b, cv2.CV_32F, 0, 1, ksize=3, scale=0.125)
    energy = gx * gx + gy * gy
    fl = flow(cur.flow, prev.flow, bg_f)
    # a layer's points: texels of its region's hull that the background's motion leaves off by over LAYER_STILL
    # (a turning object's rim moves by little near its centre: under LAYER_LEVEL, still a point)
    moved = np.abs(warped_bg - cur_b) > LAYER_STILL
    joint = _fit(LayerPoints(cur_b, union & moved, gx, gy, energy), prev_b, fl, bg_f)
    fits = [(union, joint)]
    if joint is None and len(comps) > 1:
        hulls = [_hull(lab == k) for k in comps[:LAYER_MAX]]
        fits = [(r, _fit(LayerPoints(cur_b, r & moved, gx, gy, energy), prev_b, fl, bg_f)) for r in hulls]
    best = _box_residual(warped_bg, cur_b)
    labels = np.zeros((fh, fw), np.int32)
    fitted: list[tuple[LayerPoints, np.ndarray, int]] = []
    residuals = []
    for region, fit in fits:
        if fit is None:
            continue
        m, dof = fit
        r = _box_residual(_warp(prev_b, m), cur_b)
        take = region & (r <= best + LAYER_MARGIN)
        labels[take] = len(fitted) + 1
        best = np.where(take, np.minimum(r, best), best)
        fitted.append((LayerPoints(cur_b, region & moved, gx, gy, energy), m, dof))
        residuals.append(r)
    if not fitted or np.count_nonzero(labels) < LAYER_MIN_SHARE * labels.size:
        return None   # no layers, or too small to pay for a field per ring frame: the ring restarts
    core = labels
    if LAYER_GROW > 0:
        grown = cv2.dilate(labels.astype(np.uint8), np.ones((2 * LAYER_GROW + 1,) * 2, np.uint8))
        labels = np.where(labels == 0, grown, labels)
    texels = [labels == k + 1 for k in range(len(fitted))]
    for mine, r in zip(texels, residuals):
        if np.count_nonzero(mine & (r > LAYER_LEVEL)) > LAYER_MISFIT * np.count_nonzero(mine):
            return None   # a map that fits the texture around a mover but not the mover (stripes' period)
    layers = [Layer(mine, pts, m, dof, core == k + 1) for k, (mine, (pts, m, dof)) in enumerate(zip(texels, fitted))]
    # changed texels no layer takes and the background does not explain either: no samples there
    return layers, unexplained & (labels == 0) & (_box_residual(warped_bg, cur_b) > LAYER_LEVEL)


def _field(shape: tuple[int, int], bg: tuple[float, float], unexplained: np.ndarray, layers: list[Layer],
           maps: list[np.ndarray | None], fs: int) -> np.ndarray:
    """A ring frame's field (full-size px at flow size): `bg` everywhere, NaN on unexplained texels (`unexplained`:
    their flat indices), each layer's map on its texels (NaN where its map was not found: None); the layers are
    written over their bounding boxes. Background texels that the ring frame shows covered by a layer (where the
    layer was then: behind a mover, the background it uncovered since) are NaN too: no ghost of the mover."""
    out = np.empty(shape + (2,), np.float32)
    out.view(np.complex64).fill(complex(bg[0], bg[1]))   # (x, y) pairs in one pass (broadcasting a pair: ~10x slower)
    out.reshape(-1, 2)[unexplained] = np.nan
    covered = _covered(shape, bg, layers, maps, fs)
    if covered is not None:
        out[covered] = np.nan
    for layer, a in zip(layers, maps):
        ys, xs = layer.box
        view = out[ys, xs]
        if a is None:
            view[layer.inside] = np.nan
            continue
        x = np.arange(xs.start, xs.stop, dtype=np.float32)[None, :]
        y = np.arange(ys.start, ys.stop, dtype=np.float32)[:, None]
        for k in (0, 1):
            off = (np.float32(a[k, 0] - (k == 0)) * x + np.float32(a[k, 1] - (k == 1)) * y + np.float32(a[k, 2])) * fs
            np.copyto(view[..., k], off.astype(np.float32), where=layer.inside)
    return out


def _covered(shape: tuple[int, int], bg: tuple[float, float], layers: list[Layer], maps: list[np.ndarray | None],
             fs: int) -> np.ndarray | None:
    """Texels of the current frame's background whose position in a ring frame (moved on by `bg`) lay on a layer
    there: the layer's texels carried by its map into that frame (texel x of the background reads the ring frame
    at T x; it was the layer's where map^-1 T x is one of the layer's core texels now: before the labels grew, whose
    margin is background that would lose its samples; docs/temporal.md). None where nothing is."""
    h, w = shape
    to_ring = translation_map((bg[0] / fs, bg[1] / fs))
    covered = None
    for layer, a in zip(layers, maps):
        if a is None or abs(np.linalg.det(a[:2, :2])) < 1e-6:   # no map, or one that folds the layer flat
            continue
        back = np.linalg.inv(a) @ to_ring   # current background texel -> where the layer's texel now is
        where = layer.texels if layer.core is None else layer.core
        hit = cv2.warpAffine(where.view(np.uint8), back[:2].astype(np.float64), (w, h),
                             flags=cv2.INTER_NEAREST | cv2.WARP_INVERSE_MAP, borderMode=cv2.BORDER_CONSTANT) > 0
        covered = hit if covered is None else covered | hit
    if covered is None:
        return None
    for layer in layers:
        covered &= ~layer.texels
    return covered if covered.any() else None


def layers_box(layers: list[Layer]) -> tuple[slice, slice]:
    """The bounding box of the layers' texels: where a field of theirs departs from the background's translation
    (NaN texels aside)."""
    ys = [layer.box[0] for layer in layers]
    xs = [layer.box[1] for layer in layers]
    return (slice(min(s.start for s in ys), max(s.stop for s in ys)),
            slice(min(s.start for s in xs), max(s.stop for s in xs)))


def _refined(layer: Layer, ring_b: np.ndarray, start: np.ndarray | None) -> np.ndarray | None:
    """A layer's map into another frame from `start`, LAYER_REFINE_STEPS direct steps; None where it leaves a
    median |residual| over LAYER_FIT_LEVEL at the layer's points (or there was no start)."""
    if start is None:
        return None
    a, level = layer.points.refine(ring_b, start, LAYER_REFINE_STEPS, layer.dof)
    return a if level <= LAYER_FIT_LEVEL else None


def layer_fields(entries: list, layers: list[Layer], unexplained: np.ndarray, bg: tuple[float, float],
                 fs: int) -> None:
    """Each ring entry's map becomes a field: its background translation (`entry.bg`, moved on by `bg`)
    everywhere, NaN on unexplained texels, each layer's map (composed, then refined directly) on the layer's
    texels. entries: oldest first, the previous frame last (its map was the identity)."""
    shape, nan, box = unexplained.shape, np.flatnonzero(unexplained), layers_box(layers)
    for j, e in enumerate(entries):
        old_bg = e.bg if e.field is not None or e.shift is None else e.shift
        prev_map = e.field if e.field is not None else np.broadcast_to(np.float32(old_bg), shape + (2,))
        e.bg = (old_bg[0] + bg[0], old_bg[1] + bg[1])
        if j == len(entries) - 1:
            maps = [layer.affine for layer in layers]
        else:
            ring_b = e.pyr.blurred("flow")
            maps = [_refined(layer, ring_b, layer.points.fit_to(prev_map, fs, layer.affine, layer.dof))
                    for layer in layers]
        e.field, e.shift, e.projective, e.field_box = _field(shape, e.bg, nan, layers, maps, fs), None, False, box


def ahead_fields(pyr: Pyramid, index: int, future: list, layers: list[Layer], unexplained: np.ndarray,
                 entry, still: bool = False, forward: bool = False) -> list:
    """Look-ahead ring entries of a layers frame (`future`: Ahead records of frames index + 1, ...): each one's
    background translation chained from the frame-to-frame decisions (background_of; none where the current
    frame's background was found `still`), each layer's map started from the previous frame's continued by the
    layer's own step (a steady motion: current -> next is the inverse of current -> previous) and refined directly.
    The window ends before a frame that is not the next one or was a cut. entry(index, pyr, field, bg, box): a ring
    entry. `forward`: the layers' maps are to the next frame (a shot's first frame: find_layers run against the
    frame after it), so they are the step themselves."""
    fs = pyr.flow_scale
    out = []
    bg = (0.0, 0.0)
    step = [layer.affine if forward else np.linalg.inv(layer.affine) for layer in layers]
    maps: list[np.ndarray | None] = [np.eye(3) for _ in layers]
    prev, nan, box = pyr, np.flatnonzero(unexplained), layers_box(layers)
    for k, a in enumerate(future):
        if a.index != index + 1 + k or a.decision.model == "reset" or a.pyr.flow.shape != pyr.flow.shape:
            break
        d = (0.0, 0.0) if still or a.decision.model == "static" else background_of(a.decision, prev, a.pyr)
        bg = (bg[0] - d[0], bg[1] - d[1])
        ring_b = a.pyr.blurred("flow")
        maps = [_refined(layer, ring_b, None if m is None else m @ s) for layer, m, s in zip(layers, maps, step)]
        out.append(entry(a.index, a.pyr, _field(unexplained.shape, bg, nan, layers, maps, fs), bg, box))
        prev = a.pyr
    return out


def layers_decision(dec: Decision, layers: list[Layer]) -> Decision:
    """The frame's record: model "layers", with how many."""
    return Decision("layers", dec.translation, {**dec.measures, "layers": len(layers)})
