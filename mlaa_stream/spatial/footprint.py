"""The footprint table: in render regions, each pixel's colour becomes an estimate of the average over its square
footprint -- the truth of a 1-spp render, whose pixels are point samples -- from its 5x5 window of samples and
the colour the chain gave it.

Why: a 1-spp frame is sharper than its truth wherever the MLAA passes find no edge to blend (texture, shading,
short and curved edges, thin features). A fixed 3x3 tent (what this replaced) removes part of that; a linear
filter per local structure class removes more, because the right filter across a texture edge is not the one
along it or on flat shading (the RAISR idea: Romano, Isidoro, Milanfar, "RAISR: Rapid and Accurate Image
Super Resolution", IEEE TCI 2017 -- buckets by the structure tensor's angle, strength and coherence, one
least-squares filter per bucket). docs/spatial_tuning.md, "The footprint table", has the measurements.

Per pixel, in mix space (linear light by default), for each colour channel c:

    out_c = clamp(in_c + sum_k T[b, k] * (in_c(p + o_k) - in_c) + T[b, 25] * (chain_c - in_c), lo_c, hi_c)

- o_k: the 25 offsets of the 5x5 window, row by row (clamped at the frame's edges); chain: the colour after the
  MLAA passes and the FXAA fallback; [lo_c, hi_c]: the range of the 3x3 input window and the chain's colour (no
  overshoot: no halo around edges);
- bucket b from the structure tensor of linear luma (central differences, averaged over the 5x5 window):
  ANGLES orientations of the dominant gradient, STRENGTHS bands of its eigenvalue relative to the window's mean
  luma m, sqrt(l1) / s with s = (m + STRENGTH_FLOOR) / STRENGTH_REF (Weber's contrast: the same structure lands in
  the same band in a dim render as in a bright one; the refine table's bands use sqrt(s), spatial/refine.py),
  COHERENCES bands of (sqrt(l1) - sqrt(l2)) / (sqrt(l1) + sqrt(l2)), and whether the chain changed the pixel. The
  bands are tested without square roots (the kernel and this reference then agree on every bucket);
- a pixel whose 5x5 window is one colour and which the chain left keeps its colour, and so does a pixel that the
  chain changed on a straight edge run of REGION_KEEP_RUN pixels or more (fallback.py: the MLAA passes' verdict
  on a straight edge stands).

The table (BUCKETS x WEIGHTS float32) ships as mlaa_stream/data/footprint_table.npy; `python -m
mlaa_stream.bench.footprint_fit` renders its training views (none of them a bench scene or a held-out view) and
fits it again. Kernel: kernels/fallback.cl footprint_tile.
"""
from __future__ import annotations

from importlib import resources

import numpy as np

TABLE_RADIUS = 2                      # the 5x5 window
TAPS = (2 * TABLE_RADIUS + 1) ** 2    # 25 input taps ...
WEIGHTS = TAPS + 1                    # ... and the chain's colour
CHAIN_WEIGHT = TAPS                   # index of the chain's colour's weight
CENTRE_TAP = TAPS // 2                # its feature is always 0, so its weight has no effect
ANGLES, STRENGTHS, COHERENCES = 8, 3, 3
BUCKETS = ANGLES * STRENGTHS * COHERENCES * 2
STRENGTH_LEVELS = (0.02, 0.08)       # sqrt(l1) / s in linear luma per pixel: flat shading / texture / edges
STRENGTH_REF = 0.2                   # s = (m + STRENGTH_FLOOR) / STRENGTH_REF: the levels hold as they are at m = 0.19
STRENGTH_FLOOR = 0.01                # linear luma added to the window's mean m (near black: quantisation, not contrast)
COHERENCE_LEVELS = (0.3, 0.6)        # isotropic (corners, dots) / mixed / one direction (edges, lines)
LUMA = (0.2126, 0.7152, 0.0722)      # Rec. 709 weights on linear RGB
TABLE_FILE = "footprint_table.npy"


def as_table(table: np.ndarray) -> np.ndarray:
    """`table` checked: a (BUCKETS, WEIGHTS) array of finite numbers, as float32."""
    return checked_table(table, WEIGHTS, "footprint table")


def checked_table(table: np.ndarray, weights: int, what: str) -> np.ndarray:
    """`table` checked: a (BUCKETS, weights) array of finite numbers, as float32; `what` names it in the error."""
    t = np.asarray(table)
    if t.shape != (BUCKETS, weights) or not np.all(np.isfinite(t)):
        raise ValueError(f"{what}: expected a ({BUCKETS}, {weights}) array of finite numbers, got shape {t.shape}")
    return np.ascontiguousarray(t, np.float32)


def shipped_table(file: str) -> np.ndarray:
    """A table file of the package's data folder, as stored."""
    with resources.files("mlaa_stream").joinpath("data", file).open("rb") as f:
        return np.load(f)


def load_table() -> np.ndarray:
    """The shipped table, (BUCKETS, WEIGHTS) float32."""
    return as_table(shipped_table(TABLE_FILE))


def table_of(spec: np.ndarray | str | None) -> np.ndarray | None:
    """A table argument (Filter's `footprint_table`, fallback_reference's `table`) resolved: "default" the shipped
    table, None none, an array checked by as_table."""
    return resolved(spec, "footprint_table", load_table, as_table)


def resolved(spec, name: str, load, check):
    """A table argument resolved: "default" -> load(), None -> None, an array -> check(array)."""
    if isinstance(spec, str):
        if spec != "default":
            raise ValueError(f"{name}: expected 'default', None or an array, got {spec!r}")
        return load()
    return None if spec is None else check(spec)


def identity_table() -> np.ndarray:
    """A table that keeps the chain's colour everywhere (the pass without the footprint table)."""
    t = np.zeros((BUCKETS, WEIGHTS), np.float32)
    t[:, CHAIN_WEIGHT] = 1.0
    return t


def _shifted(a: np.ndarray, dy: int, dx: int) -> np.ndarray:
    """a[y + dy, x + dx], clamped at the frame's edges."""
    h, w = a.shape[:2]
    return a[np.clip(np.arange(h) + dy, 0, h - 1)][:, np.clip(np.arange(w) + dx, 0, w - 1)]


def range3(a: np.ndarray, also: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel and channel, the (min, max) of `a` over the 3x3 window (reads clamped at the frame's edges) and of
    `also` at the pixel itself when given."""
    lo, hi = (a, a) if also is None else (also, also)
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            s = _shifted(a, dy, dx)
            lo, hi = np.minimum(lo, s), np.maximum(hi, s)
    return lo, hi


def footprint_buckets(lin: np.ndarray, changed: np.ndarray, weber_squared: bool = True) -> np.ndarray:
    """Bucket per pixel, (h, w) int32, of `lin` ((h, w, 3) float32 RGB in mix space) and `changed` ((h, w) bool:
    the chain changed the pixel). The strength levels scale with s (`weber_squared`: l1 is compared against
    t^2 s^2, the footprint table's Weber contrast) or with sqrt(s) (t^2 s: the refine table's)."""
    f32 = np.float32
    y = (lin[..., 0] * f32(LUMA[0]) + lin[..., 1] * f32(LUMA[1]) + lin[..., 2] * f32(LUMA[2])).astype(f32)
    sxx = np.zeros_like(y)
    syy, sxy, sy = sxx.copy(), sxx.copy(), sxx.copy()
    r = TABLE_RADIUS
    for dx in range(-r, r + 1):  # per column of the window, then across (the kernel's order of summation)
        cxx, cyy, cxy, cy = np.zeros_like(y), np.zeros_like(y), np.zeros_like(y), np.zeros_like(y)
        for dy in range(-r, r + 1):  # central differences at each tap, every read clamped at the frame's edge
            a = (_shifted(y, dy, dx + 1) - _shifted(y, dy, dx - 1)) * f32(0.5)
            b = (_shifted(y, dy + 1, dx) - _shifted(y, dy - 1, dx)) * f32(0.5)
            cxx += a * a
            cyy += b * b
            cxy += a * b
            cy += _shifted(y, dy, dx)
        sxx += cxx
        syy += cyy
        sxy += cxy
        sy += cy
    n = f32(1.0 / TAPS)
    sxx, syy, sxy = sxx * n, syy * n, sxy * n
    scale = (sy * n + f32(STRENGTH_FLOOR)) * f32(1.0 / STRENGTH_REF)
    scale2 = scale * scale if weber_squared else scale  # the strength levels' unit, squared
    u, v = sxx - syy, f32(2) * sxy         # the doubled angle's vector: (l1 - l2) (cos 2t, sin 2t)
    tr, det2 = sxx + syy, u * u + v * v    # l1 + l2 and (l1 - l2)^2
    au, av = np.abs(u), np.abs(v)
    # octant of the doubled angle in [0, 2 pi): the orientation in [0, pi) in ANGLES bins of pi / 8
    octant = np.where(v >= 0, np.where(u > 0, np.where(av < au, 0, 1), np.where(av > au, 2, 3)),
                      np.where(u < 0, np.where(av < au, 4, 5), np.where(av > au, 6, 7)))

    # the bands, tested without square roots (the kernel's arithmetic): how many of the levels t each reaches
    def strength(t: np.float32) -> np.ndarray:  # l1 = (tr + sqrt(det2)) / 2 >= t^2 scale^2
        need = f32(2) * t * t * scale2 - tr
        return (need <= 0) | (det2 >= need * need)

    def coherence(t: np.float32) -> np.ndarray:  # (sqrt l1 - sqrt l2) >= t (sqrt l1 + sqrt l2)
        k = tr * (f32(2) * t / (f32(1) + t * t))  # <=> sqrt(det2) >= tr 2t / (1 + t^2)
        return det2 >= k * k

    s = sum(strength(f32(t)).astype(np.int32) for t in STRENGTH_LEVELS)
    c = sum(coherence(f32(t)).astype(np.int32) for t in COHERENCE_LEVELS)
    return (((octant * STRENGTHS + s) * COHERENCES + c) * 2 + changed).astype(np.int32)


def footprint_features(lin: np.ndarray, chain: np.ndarray) -> np.ndarray:
    """(h, w, 3, WEIGHTS) float32: the 25 window taps minus the centre, then the chain's colour minus the centre."""
    r = TABLE_RADIUS
    cols = [_shifted(lin, dy, dx) - lin for dy in range(-r, r + 1) for dx in range(-r, r + 1)]
    cols.append(chain - lin)
    return np.stack(cols, -1).astype(np.float32)


def table_sum(base: np.ndarray, feats: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """base + sum_k feats[..., k] * weights[..., k] per channel, in the kernels' order of summation (k ascending):
    `base` (h, w, 3), `feats` (h, w, 3, n), `weights` (h, w, n) -- each pixel's table row."""
    pred = base.copy()
    for k in range(feats.shape[-1]):
        pred += feats[..., k] * weights[:, :, None, k]
    return pred


def footprint_reference(lin: np.ndarray, chain: np.ndarray, changed: np.ndarray, table: np.ndarray
                        ) -> tuple[np.ndarray, np.ndarray]:
    """What footprint_tile makes of every pixel: (new colour (h, w, 3) float32 in mix space, kept (h, w) bool:
    one-colour windows the chain left, which keep their stored value)."""
    f32 = np.float32
    feats = footprint_features(lin, chain)
    pred = table_sum(lin, feats, table[footprint_buckets(lin, changed)])
    lo, hi = range3(lin, chain)
    flat = np.ones(changed.shape, bool)
    r = TABLE_RADIUS
    for dy in range(-r, r + 1):
        for dx in range(-r, r + 1):
            flat &= np.all(_shifted(lin, dy, dx) == lin, -1)
    return np.clip(pred, lo, hi).astype(f32), flat & ~changed


def fit_table(samples, ridge: float = 1e-4, min_samples: int = 200) -> np.ndarray:
    """Least-squares table from `samples`: an iterable of (lin, chain, changed, truth, mask) -- mix-space input,
    chain and truth (h, w, 3) float32, `changed` and `mask` (the pixels to fit, render regions) (h, w) bool. A
    bucket with fewer than `min_samples` channel samples keeps the chain's colour; `ridge` (relative to the
    bucket's mean feature energy) keeps rare buckets' filters tame."""
    def rows():
        for lin, chain, changed, truth, mask in samples:
            yield footprint_features(lin, chain)[mask], (truth - lin)[mask], footprint_buckets(lin, changed)[mask]
    return solve_buckets(rows(), WEIGHTS, identity_table(), ridge, min_samples)


def solve_buckets(rows, weights: int, fallback: np.ndarray, ridge: float = 1e-4, min_samples: int = 200
                  ) -> np.ndarray:
    """One ridge least-squares filter per bucket: `rows` yields (features (n, 3, weights), targets (n, 3),
    buckets (n,)) per frame, every colour channel a sample; a bucket with fewer than `min_samples` channel samples
    keeps its row of `fallback` (BUCKETS, weights)."""
    a = np.zeros((BUCKETS, weights, weights))
    v = np.zeros((BUCKETS, weights))
    count = np.zeros(BUCKETS, np.int64)
    for feats, target, buckets in rows:
        x = feats.reshape(-1, weights).astype(np.float64)
        y = target.reshape(-1).astype(np.float64)
        b = np.repeat(buckets, feats.shape[1])
        order = np.argsort(b, kind="stable")
        starts = np.searchsorted(b[order], np.arange(BUCKETS + 1))
        for q in range(BUCKETS):
            s = order[starts[q]:starts[q + 1]]
            if len(s):
                a[q] += x[s].T @ x[s]
                v[q] += x[s].T @ y[s]
                count[q] += len(s)
    table = np.array(fallback, np.float32)
    for q in range(BUCKETS):
        if count[q] >= min_samples:
            reg = ridge * np.trace(a[q]) / weights + 1e-12
            table[q] = np.linalg.solve(a[q] + reg * np.eye(weights), v[q])
    return table
