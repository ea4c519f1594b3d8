"""Grain over a render is no aliasing: quiet pixels leave the render regions (kernels/noise.cl).

Film grain, sensor noise or a path tracer's residual noise lies over the point samples of a render. The render
regions' FXAA and footprint / refine tables (spatial/fallback.py) move every region pixel toward what a box filter
over point samples would give, and so smooth the grain, which the truth keeps: with grain of 8 levels over the
bench's renders the default removed less error than FXAA (docs/spatial_tuning.md, "Grain over a render"). The frame's
noise level is the median |Laplacian| of its luma over a sample of its pixels; a region pixel whose 3x3 window of
luma spans under NOISE_SPAN times it is quiet and keeps the MLAA passes' colour. A clean render's level is 0, so
nothing changes there. The kernel's comment gives the rule; this module holds its constants and its numpy
reference, which tests/test_noise.py holds the kernel to.
"""
from __future__ import annotations

from fractions import Fraction

import numpy as np

from mlaa_stream.device.formats import LUMA256, levels8

NOISE_SPAN = Fraction(3, 2)  # quiet: the 3x3 luma span under 3/2 the median |Laplacian| (~6 deviations of white noise)
NOISE_BINS = 64              # the census' bins: |Laplacian| in whole levels, the last for 63 and more
NOISE_ROW_STEP = 4           # rows 1 and 5 of each band of 8 (FALLBACK_TILE), every other column
TILE = 8                     # fallback.py FALLBACK_TILE


def noise_defines() -> dict:
    """The constants as kernels/noise.cl's defines."""
    return {"NOISE_SPAN_NUM": NOISE_SPAN.numerator, "NOISE_SPAN_DEN": NOISE_SPAN.denominator}


def luma256(frame: np.ndarray, bgr: bool = False) -> np.ndarray:
    """(h, w) int64 Rec. 709 luma in 256ths of 8-bit levels (kernels/noise.cl luma256)."""
    return levels8(frame, bgr) @ LUMA256


def noise_census(lum: np.ndarray) -> np.ndarray:
    """Per band of TILE rows, the histogram (bands, NOISE_BINS) of |Laplacian| of `lum` in whole levels over the
    sampled pixels: rows 1 and 1 + NOISE_ROW_STEP of each band, odd columns, none on the frame's border."""
    h, w = lum.shape
    bands = -(-h // TILE)
    hist = np.zeros((bands, NOISE_BINS), np.int64)
    if w < 3:
        return hist
    d2 = lum[:-2] - 2 * lum[1:-1] + lum[2:]            # row y's column second differences are d2[y - 1]
    lap = np.abs(d2[:, :-2] - 2 * d2[:, 1:-1] + d2[:, 2:]) >> 8  # lap[y - 1, x - 1]
    for band in range(bands):
        for r in range(1, TILE, NOISE_ROW_STEP):
            y = band * TILE + r
            if y >= h - 1:
                break
            hist[band] += np.bincount(np.minimum(lap[y - 1, 0::2], NOISE_BINS - 1), minlength=NOISE_BINS)
    return hist


def noise_level(frame: np.ndarray, bgr: bool = False) -> int:
    """The frame's noise level (kernels/noise.cl noise_level): the lower median bin of the census, 0 if empty."""
    total = noise_census(luma256(frame, bgr)).sum(0)
    n = int(total.sum())
    return int(np.searchsorted(np.cumsum(total) * 2, n)) if n else 0


def quiet_pixels(frame: np.ndarray, bgr: bool = False, level: int | None = None) -> np.ndarray:
    """(h, w) bool: pixels whose 3x3 window of luma (clamped to the frame) spans under NOISE_SPAN x the frame's
    noise level (kernels/noise.cl noise_quiet; `level`: noise_level's, computed when None)."""
    lum = luma256(frame, bgr)
    level = noise_level(frame, bgr) if level is None else level
    if level <= 0:
        return np.zeros(lum.shape, bool)
    h, w = lum.shape
    p = np.pad(lum, 1, mode="edge")
    win = np.stack([p[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)])
    span = win.max(0) - win.min(0)
    return span * NOISE_SPAN.denominator < NOISE_SPAN.numerator * 256 * level
