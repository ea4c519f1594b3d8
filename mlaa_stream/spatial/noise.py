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

import cv2
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
    """(h, w) int32 Rec. 709 luma in 256ths of 8-bit levels (kernels/noise.cl luma256)."""
    a = np.asarray(frame)
    if a.dtype == np.uint8 and a.ndim == 3 and a.shape[2] >= 3:  # the common case, in float32 (exact: < 2^24)
        w = LUMA256[::-1] if bgr else LUMA256
        return (a[..., :3].astype(np.float32) @ w.astype(np.float32)).astype(np.int32)
    return (levels8(frame, bgr) @ LUMA256).astype(np.int32)


def noise_census(lum: np.ndarray) -> np.ndarray:
    """Per band of TILE rows, the histogram (bands, NOISE_BINS) of |Laplacian| of `lum` in whole levels over the
    sampled pixels: rows 1 and 1 + NOISE_ROW_STEP of each band, odd columns, none on the frame's border."""
    h, w = lum.shape
    bands = -(-h // TILE)
    hist = np.zeros((bands, NOISE_BINS), np.int64)
    ys = np.array([b * TILE + r for b in range(bands) for r in range(1, TILE, NOISE_ROW_STEP)], np.int64)
    ys = ys[ys < h - 1]
    if w < 3 or not len(ys):
        return hist
    lum = lum.astype(np.int64)
    d2 = lum[ys - 1] - 2 * lum[ys] + lum[ys + 1]              # each sampled row's column second differences
    lap = np.abs(d2[:, :-2] - 2 * d2[:, 1:-1] + d2[:, 2:])[:, 0::2] >> 8  # odd columns x = 1, 3, ...
    bins = np.minimum(lap, NOISE_BINS - 1) + (ys // TILE)[:, None] * NOISE_BINS
    hist.ravel()[:] = np.bincount(bins.ravel(), minlength=bands * NOISE_BINS)
    return hist


def level_of(lum: np.ndarray) -> int:
    """The noise level of luma `lum` (kernels/noise.cl noise_level): the lower median bin of the census, 0 if
    nothing was sampled."""
    total = noise_census(lum).sum(0)
    n = int(total.sum())
    return int(np.searchsorted(np.cumsum(total) * 2, n)) if n else 0


def noise_level(frame: np.ndarray, bgr: bool = False) -> int:
    """The frame's noise level in whole levels (level_of its luma256)."""
    return level_of(luma256(frame, bgr))


def quiet_pixels(frame: np.ndarray, bgr: bool = False, level: int | None = None) -> np.ndarray:
    """(h, w) bool: pixels whose 3x3 window of luma (clamped to the frame) spans under NOISE_SPAN x the frame's
    noise level (kernels/noise.cl noise_quiet; `level`: noise_level's, computed when None)."""
    lum = luma256(frame, bgr)
    level = level_of(lum) if level is None else level
    if level <= 0:
        return np.zeros(lum.shape, bool)
    k = np.ones((3, 3), np.uint8)
    f = lum.astype(np.float32)  # exact: luma in 256ths stays under 2^24
    span = cv2.dilate(f, k, borderType=cv2.BORDER_REPLICATE) - cv2.erode(f, k, borderType=cv2.BORDER_REPLICATE)
    return span * NOISE_SPAN.denominator < NOISE_SPAN.numerator * 256 * level
