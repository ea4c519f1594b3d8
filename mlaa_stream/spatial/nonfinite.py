"""Non-finite samples (NaN, ±Inf) in float frames: kept out of the kernels, put back in the output.

What they become (README "Non-finite samples"): a NaN or infinite sample passes through unchanged and
never counts as an edge or spreads to its neighbours. Finite samples beyond ±SAMPLE_LIMIT are treated
the same way: no image holds such light levels, and blending them (differences, squared weights summed
over four neighbours) could overflow float32 into ±Inf. Before upload each one is replaced by the
nearest finite sample of the same channel along its row (left first, then right; 0 in a row with
none), so its neighbours are filtered as if the pixel continued the row; after download the original
non-finite sample is written back in place.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SAMPLE_LIMIT = 1e15  # |v| above this is out of range; its square and sums of four stay finite in float32


@dataclass
class NonFinite:
    """Where a frame had non-finite samples, and their values, to restore after filtering."""

    where: np.ndarray  # bool, the frame's shape
    values: np.ndarray  # the non-finite samples, in `where`'s order

    def restore(self, out: np.ndarray) -> np.ndarray:
        """Write the original non-finite samples back into `out` (same shape as the frame)."""
        out = out.astype(self.values.dtype, copy=False) if out.dtype.kind == "f" else out
        out[self.where] = self.values.astype(out.dtype, copy=False)
        return out


def replace_non_finite(frame: np.ndarray, original: np.ndarray | None = None) -> NonFinite | None:
    """Replace the non-finite and out-of-range samples of a float `frame` in place (see the module's
    note); None when there are none (the usual case: one vectorised test per frame). `original`: the
    caller's frame that `frame` is a narrower copy of (float64 into float32, where 1e300 became inf): the
    values to restore are taken from it, so a finite sample comes back finite and exact."""
    if frame.dtype.kind != "f":
        return None
    with np.errstate(invalid="ignore"):
        finite = np.abs(frame) <= SAMPLE_LIMIT  # False for NaN and ±Inf too
    if finite.all():
        return None
    bad = ~finite
    source = frame if original is None or original.shape != frame.shape else original
    restore = NonFinite(bad.copy(), source[bad].copy())
    rows = frame.reshape(frame.shape[0], frame.shape[1], -1)  # (H, W, C) view
    good = finite.reshape(rows.shape)
    w = rows.shape[1]
    col = np.arange(w)[None, :, None]
    left = np.maximum.accumulate(np.where(good, col, -1), axis=1)  # nearest finite at or left of x
    right = np.flip(np.minimum.accumulate(np.flip(np.where(good, col, w), axis=1), axis=1), axis=1)
    src = np.where(left >= 0, left, right)
    fill = np.take_along_axis(rows, np.clip(src, 0, w - 1), axis=1)
    fill = np.where(src < w, fill, 0)  # a row of one channel with no finite sample at all
    rows[...] = np.where(good, rows, fill)
    return restore


def restore_out_of_range(frame_in: np.ndarray, out: np.ndarray) -> np.ndarray:
    """`out` with the non-finite and out-of-range samples of a float `frame_in` put back as they were.

    For stages after the spatial filter that mix frames (the temporal stage): they read such samples as
    black, white or over range and would write history over them, where the module's rule says they pass
    through unchanged. Integer frames, and outputs of another shape (a debug view), are returned as they are.
    """
    fin = np.asarray(frame_in)
    if fin.dtype.kind != "f" or out.dtype.kind != "f" or out.shape != fin.shape:
        return out
    with np.errstate(invalid="ignore"):
        bad = ~(np.abs(fin) <= np.float64(SAMPLE_LIMIT))   # float64: 1e15 overflows a half frame's type
    if not bad.any():
        return out
    out = out if out.flags.writeable else out.copy()
    out[bad] = fin[bad]
    return out
