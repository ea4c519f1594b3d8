"""The refine table: a second footprint table (spatial/footprint.py) that takes the first one's output as its window.

Why: the footprint table is a linear filter of the 1-spp input per structure class, and that family is at its
ceiling (docs/spatial_tuning.md, "The footprint table": fitted to the held-out views themselves it reaches 74 %);
a small per-pixel network gains 1-2 points but costs ~100x the arithmetic ("A nonlinear per-pixel model"). Two
linear stages with a clamp between them are a cheap nonlinear filter with a wider reach (9x9): the second stage
sees the first one's colours, classed by the structure of that output, and corrects what the first leaves
(docs/spatial_tuning.md, "The refine table").

Per pixel of a render region, in mix space (linear light by default), with `mid` the colour after the MLAA passes,
the FXAA fallback and the footprint table, and `in` the input, for each colour channel c:

    out_c = clamp(mid_c + sum_k R[b, k] * (mid_c(p + o_k) - mid_c)
                        + sum_j R[b, 25 + j] * (in_c(p + i_j) - mid_c), lo_c, hi_c)

- o_k: the 25 offsets of the 5x5 window, i_j the 9 of the 3x3 window, row by row (reads clamped at the frame's
  edges); [lo_c, hi_c]: the range of mid's 3x3 window;
- bucket b: footprint_buckets of mid (its structure tensor) and whether mid differs from the input, with the
  strength levels scaled by the square root of the first table's Weber unit (weber_squared=False): measured between
  absolute levels and the first table's (docs/spatial_tuning.md, "Dim renders");
- only pixels with strong local contrast in the input (any channel's range over its 3x3 window at least
  REFINE_GATE of full scale, in stored values) and, as for the first table, not a pixel the chain changed on a
  straight edge run (fallback.py REGION_KEEP_RUN): elsewhere the second stage moved flat shading for little gain
  and raised the damage away from edges.

The table (BUCKETS x REFINE_WEIGHTS float32) ships as mlaa_stream/data/footprint_refine.npy; `python -m
mlaa_stream.bench.footprint_fit --refine` fits it on the first table's training views. Kernel: kernels/fallback.cl
refine_tile.
"""
from __future__ import annotations

import numpy as np

from mlaa_stream.spatial.footprint import (BUCKETS, TABLE_RADIUS, TAPS, _shifted, checked_table, footprint_buckets,
                                           range3, resolved, shipped_table, solve_buckets, table_sum)

INPUT_TAPS = 9                         # the input's 3x3 window
REFINE_WEIGHTS = TAPS + INPUT_TAPS     # 25 taps of mid's 5x5 window, then the input's 3x3
REFINE_GATE = 0.3                      # the input's 3x3 range (stored values, of full scale) a pixel needs
REFINE_FILE = "footprint_refine.npy"


def as_refine_table(table: np.ndarray) -> np.ndarray:
    """`table` checked: a (BUCKETS, REFINE_WEIGHTS) array of finite numbers, as float32."""
    return checked_table(table, REFINE_WEIGHTS, "refine table")


def load_refine_table() -> np.ndarray:
    """The shipped refine table, (BUCKETS, REFINE_WEIGHTS) float32."""
    return as_refine_table(shipped_table(REFINE_FILE))


def refine_table_of(spec: np.ndarray | str | None) -> np.ndarray | None:
    """Filter's `refine_table` / fallback_reference's `refine` resolved: "default" the shipped table, None none, an
    array checked by as_refine_table."""
    return resolved(spec, "refine_table", load_refine_table, as_refine_table)


def refine_features(inp: np.ndarray, mid: np.ndarray) -> np.ndarray:
    """(h, w, 3, REFINE_WEIGHTS) float32: mid's 25 window taps minus its centre, then the input's 9 minus mid's
    centre."""
    r = TABLE_RADIUS
    cols = [_shifted(mid, dy, dx) - mid for dy in range(-r, r + 1) for dx in range(-r, r + 1)]
    cols += [_shifted(inp, dy, dx) - mid for dy in (-1, 0, 1) for dx in (-1, 0, 1)]
    return np.stack(cols, -1).astype(np.float32)


def gate(stored: np.ndarray, pixel_max: float) -> np.ndarray:
    """(h, w) bool: any colour channel of `stored` ((h, w, ch) as the frame stores it) spans REFINE_GATE of full
    scale or more over the pixel's 3x3 window (integer frames: ceil(REFINE_GATE * max) levels, as the kernel
    compares)."""
    a = np.asarray(stored)
    ch = a.shape[-1] if a.ndim == 3 else 1
    lo, hi = range3(a.reshape(a.shape[:2] + (ch,))[..., :min(ch, 3)])
    if np.issubdtype(a.dtype, np.integer):
        return np.any(hi.astype(np.int64) - lo >= int(np.ceil(REFINE_GATE * pixel_max)), -1)
    f32 = np.float32
    return np.any((hi.astype(f32) - lo.astype(f32)) * (f32(1.0) / f32(pixel_max)) >= f32(REFINE_GATE), -1)


def refine_reference(inp: np.ndarray, mid: np.ndarray, changed: np.ndarray, table: np.ndarray) -> np.ndarray:
    """What refine_tile makes of every pixel: the new colour (h, w, 3) float32 in mix space; `inp`, `mid` mix-space
    RGB, `changed` (h, w) bool: mid differs from the input."""
    f32 = np.float32
    feats = refine_features(inp, mid)
    pred = table_sum(mid, feats, table[footprint_buckets(mid, changed, weber_squared=False)])
    lo, hi = range3(mid)
    return np.clip(pred, lo, hi).astype(f32)


def fit_refine(samples, ridge: float = 1e-4, min_samples: int = 200) -> np.ndarray:
    """Least-squares refine table from `samples`: an iterable of (inp, mid, changed, truth, mask) -- mix-space
    input, first-stage output and truth (h, w, 3) float32, `changed` (mid differs from the input) and `mask` (the
    pixels to fit) (h, w) bool. A bucket with too few samples keeps mid's colour (all weights 0)."""
    def rows():
        for inp, mid, changed, truth, mask in samples:
            yield (refine_features(inp, mid)[mask], (truth - mid)[mask],
                   footprint_buckets(mid, changed, weber_squared=False)[mask])
    return solve_buckets(rows(), REFINE_WEIGHTS, np.zeros((BUCKETS, REFINE_WEIGHTS), np.float32), ridge,
                         min_samples)
