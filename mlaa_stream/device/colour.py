"""Colour conversions in numpy (the references) and the lookup tables the kernels use."""
from __future__ import annotations

import numpy as np

from mlaa_stream.device.formats import LUT_SIZE

# sRGB -> XYZ (D65), rows X, Y, Z; white point for CIELAB.
_RGB_TO_XYZ = np.array([[0.4124564, 0.3575761, 0.1804375],
                        [0.2126729, 0.7151522, 0.0721750],
                        [0.0193339, 0.1191920, 0.9503041]])
_WHITE = np.array([0.95047, 1.0, 1.08883])
LUMA = np.array([0.2126, 0.7152, 0.0722])  # Rec. 709 weights


def srgb_to_linear(v: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 decode, for values in [0, 1] (values outside are clamped)."""
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(v: np.ndarray) -> np.ndarray:
    v = np.clip(np.asarray(v, dtype=np.float64), 0.0, 1.0)
    return np.where(v <= 0.0031308, v * 12.92, 1.055 * v ** (1 / 2.4) - 0.055)


def lab_f(t: np.ndarray) -> np.ndarray:
    """CIELAB's f(t): cube root above (6/29)^3, the linear toe below."""
    t = np.asarray(t, dtype=np.float64)
    d = 6.0 / 29.0
    return np.where(t > d ** 3, np.cbrt(np.maximum(t, 0)), t / (3 * d * d) + 4.0 / 29.0)


def rgb_to_lab(rgb: np.ndarray) -> np.ndarray:
    """CIELAB of sRGB values in [0, 1], shape (..., 3)."""
    lin = srgb_to_linear(rgb)
    xyz = lin @ _RGB_TO_XYZ.T / _WHITE
    f = lab_f(np.clip(xyz, 0.0, 1.0))
    return np.stack([116 * f[..., 1] - 16, 500 * (f[..., 0] - f[..., 1]), 200 * (f[..., 1] - f[..., 2])], -1)


def device_luts() -> np.ndarray:
    """The tables of kernels/common.cl, LUT_SIZE+1 samples each over [0, 1]:
    sRGB->linear, CIELAB f(t), linear->sRGB."""
    x = np.linspace(0.0, 1.0, LUT_SIZE + 1)
    return np.concatenate([srgb_to_linear(x), lab_f(x), linear_to_srgb(x)]).astype(np.float32)


def lut_read(lut: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Exactly what common.cl's lut_read computes (linear interpolation), for the references."""
    t = np.clip(x, 0.0, 1.0).astype(np.float32) * np.float32(LUT_SIZE)
    i = np.minimum(t.astype(np.int32), LUT_SIZE - 1)
    f = t - i
    return lut[i] + f * (lut[i + 1] - lut[i])
