"""Accuracy and temporal metrics against a supersampled truth (DESIGN.md, "Measuring"); numpy only.

Images are (..., H, W, C) arrays: uint8, uint16 or float (0..1). Every metric works in 8-bit
levels so numbers compare across bit depths. Sequences stack frames on the first axis.
"""
from __future__ import annotations

import math

import numpy as np

NEAR_LEVELS = 1.0  # "input ~= truth": no channel differs by more than this many 8-bit levels
BROKEN_FRACTION = 1.0 / 3.0  # a wire pixel is broken when its contrast falls under this share of the truth's
FLIP_MAX_PIXELS = 256 * 256  # FLIP costs seconds per megapixel: score at most this many (a centre crop)


def levels(img: np.ndarray) -> np.ndarray:
    """The image as float64 in 8-bit levels (0..255), whatever its sample type."""
    a = np.asarray(img)
    if a.dtype == np.uint8:
        return a.astype(np.float64)
    if a.dtype == np.uint16:
        return a.astype(np.float64) * (255.0 / 65535.0)
    if np.issubdtype(a.dtype, np.floating):
        return a.astype(np.float64) * 255.0
    raise TypeError(f"expected uint8, uint16 or float samples, got {a.dtype}")


def _check(a: np.ndarray, b: np.ndarray, what: str = "images") -> None:
    if np.shape(a) != np.shape(b):
        raise ValueError(f"{what}: expected equal shapes, got {np.shape(a)} and {np.shape(b)}")


def mse(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean squared error in 8-bit levels over all channels, optionally over mask (..., H, W)."""
    _check(a, b)
    d2 = ((levels(a) - levels(b)) ** 2).mean(axis=-1)
    if mask is not None:
        d2 = d2[np.broadcast_to(mask, d2.shape)]
    return float(d2.mean()) if d2.size else math.nan


def error_removed(out: np.ndarray, inp: np.ndarray, truth: np.ndarray,
                  mask: np.ndarray | None = None) -> float:
    """1 - MSE(out, truth) / MSE(in, truth): 1 = all aliasing error gone, 0 = none, < 0 = worse."""
    base = mse(inp, truth, mask)
    if not base > 0:
        return math.nan
    return 1.0 - mse(out, truth, mask) / base


def near_mask(inp: np.ndarray, truth: np.ndarray, tol: float = NEAR_LEVELS) -> np.ndarray:
    """Pixels where the input already equals the truth (within tol levels in every channel)."""
    return np.abs(levels(inp) - levels(truth)).max(axis=-1) <= tol


def dilate(mask: np.ndarray, radius: int = 1) -> np.ndarray:
    """Binary dilation by a (2r+1)^2 square over the last two axes."""
    m = np.asarray(mask, bool)
    out = m.copy()
    h, w = m.shape[-2:]
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            if dy == 0 and dx == 0:
                continue
            src = m[..., max(0, -dy):h - max(0, dy), max(0, -dx):w - max(0, dx)]
            out[..., max(0, dy):h - max(0, -dy), max(0, dx):w - max(0, -dx)] |= src
    return out


def damage_mask(inp: np.ndarray, truth: np.ndarray, edges: np.ndarray | None = None) -> np.ndarray:
    """Where a perfect filter changes nothing: input ~= truth, and not next to an edge pixel."""
    near = near_mask(inp, truth)
    if edges is None:
        edges = ~near
    return near & ~dilate(edges, 1)


def damage(out: np.ndarray, inp: np.ndarray, truth: np.ndarray,
           edges: np.ndarray | None = None) -> float:
    """RMSE in 8-bit levels against the truth, over pixels away from edges (damage_mask)."""
    return math.sqrt(mse(out, truth, damage_mask(inp, truth, edges)))


def contrast(img: np.ndarray, background: np.ndarray) -> np.ndarray:
    """Largest channel difference from the background, in 8-bit levels, per pixel."""
    _check(img, background)
    return np.abs(levels(img) - levels(background)).max(axis=-1)


def broken_wires(out: np.ndarray, truth: np.ndarray, background: np.ndarray,
                 wires: np.ndarray) -> float:
    """Share of wire pixels whose contrast against the background fell under a third of the truth's."""
    w = np.asarray(wires, bool)
    if not w.any():
        return math.nan
    c_out, c_truth = contrast(out, background)[w], contrast(truth, background)[w]
    return float(np.mean(c_out < BROKEN_FRACTION * c_truth))


def temporal_error(outs: np.ndarray, inps: np.ndarray, truths: np.ndarray) -> float:
    """mean |(out_t - out_t-1) - (truth_t - truth_t-1)| relative to the input's: < 1 is steadier."""
    _check(outs, truths, "sequences")
    _check(inps, truths, "sequences")
    if len(truths) < 2:
        return math.nan
    dt = np.diff(levels(truths), axis=0)
    base = np.abs(np.diff(levels(inps), axis=0) - dt).mean()
    if not base > 0:
        return math.nan
    return float(np.abs(np.diff(levels(outs), axis=0) - dt).mean() / base)


def flicker_ratio(outs: np.ndarray, truths: np.ndarray) -> float:
    """sum (out_t - out_t-1)^2 / sum (truth_t - truth_t-1)^2: 1 ideal, above flickers, below smears."""
    _check(outs, truths, "sequences")
    if len(truths) < 2:
        return math.nan
    den = (np.diff(levels(truths), axis=0) ** 2).sum()
    if not den > 0:
        return math.nan
    return float((np.diff(levels(outs), axis=0) ** 2).sum() / den)


def flip_available() -> bool:
    try:
        import flip_evaluator  # noqa: F401
    except ImportError:
        return False
    return True


def _centre_crop(img: np.ndarray, max_pixels: int) -> np.ndarray:
    h, w = img.shape[:2]
    if h * w <= max_pixels:
        return img
    side = int(math.sqrt(max_pixels))
    ch, cw = min(h, side), min(w, max_pixels // min(h, side))
    y0, x0 = (h - ch) // 2, (w - cw) // 2
    return img[y0:y0 + ch, x0:x0 + cw]


def flip(out: np.ndarray, truth: np.ndarray, max_pixels: int = FLIP_MAX_PIXELS) -> float:
    """Mean NVIDIA FLIP (LDR) of one frame against the truth, on a centre crop of at most
    max_pixels; NaN when flip-evaluator is not installed (pip install flip-evaluator)."""
    _check(out, truth)
    try:
        import flip_evaluator
    except ImportError:
        return math.nan
    rgb = [np.ascontiguousarray(_centre_crop(np.clip(levels(x) / 255.0, 0, 1), max_pixels)
                                [..., :3], dtype=np.float32) for x in (truth, out)]
    if rgb[0].ndim == 2 or rgb[0].shape[-1] == 1:
        rgb = [np.repeat(x.reshape(*x.shape[:2], 1), 3, axis=-1) for x in rgb]
    _, mean, _ = flip_evaluator.evaluate(rgb[0], rgb[1], "LDR", applyMagma=False)
    return float(mean)


def score(outs: np.ndarray, inps: np.ndarray, truths: np.ndarray, edges: np.ndarray | None = None,
          wires: np.ndarray | None = None, backgrounds: np.ndarray | None = None,
          with_flip: bool = False) -> dict[str, float]:
    """Every metric for one sequence (T, H, W, C) or frame (H, W, C); NaN where one does not apply.
    FLIP is the mean over the frames (each a centre crop: it costs seconds per megapixel): a temporal stage
    returns the first frame of a shot as the spatial filter does, so the first frame alone cannot tell them apart."""
    _check(outs, truths)
    _check(inps, truths)
    if edges is None:
        edges = ~near_mask(inps, truths, 3.0)
    seq = np.ndim(truths) == 4 and len(truths) > 1
    first = (lambda a: a[0]) if np.ndim(truths) == 4 else (lambda a: a)
    res = {
        "error_removed": error_removed(outs, inps, truths),
        "edge_error_removed": error_removed(outs, inps, truths, edges),
        "damage": damage(outs, inps, truths, edges),
        "rmse": math.sqrt(mse(outs, truths)),
        "broken_wires": (broken_wires(outs, truths, backgrounds, wires)
                         if wires is not None and backgrounds is not None else math.nan),
        "flip": (float(np.mean([flip(o, t) for o, t in zip(outs, truths)])) if seq else
                 flip(first(outs), first(truths))) if with_flip else math.nan,
        "temporal_error": temporal_error(outs, inps, truths) if seq else math.nan,
        "flicker": flicker_ratio(outs, truths) if seq else math.nan,
    }
    return res
