"""Exposure of linear-light float frames: the filter's tests look at a frame as if its white were 1.

The filter's perceptual tests (CIELAB edges against a fixed ΔE, the render-region statistics on luma clipped to
display white, the grain level) were tuned on display-referred frames, whose white is 1. A scene-referred render
(EXR, linear light) can sit stops away from that: a renderer writing physical units, a shot exposed dark to be
graded later, a sky several times brighter than white. On the held-out rendered views (docs/spatial_tuning.md,
"Exposure of linear-light frames") the same frame multiplied by 1/16 ... 16 lost up to 35 points of error removed
against its own best exposure (a telephoto view at x16: 78 -> 14 %). So a linear-light float frame is filtered
at the power of two that brings its key -- the KEY_PERCENTILE-th percentile of each pixel's largest colour
channel -- nearest to 1, and the output is multiplied back. A power of two keeps the round trip exact: a pixel the
filter leaves alone comes back bit for bit.
"""
from __future__ import annotations

import numpy as np

KEY_PERCENTILE = 90      # the key: this percentile of max(R, G, B) (docs/spatial_tuning.md, "Exposure of ...")
MAX_STOPS = 24           # at most 2^24 either way: beyond that a frame is black or holds no light to speak of
KEY_SAMPLES = 65536      # the key is read from a regular grid of about this many pixels (a stride per axis)
SCALED_LIMIT = 1e15      # no scaled sample may exceed this (nonfinite.SAMPLE_LIMIT: float32 sums stay finite)


def colour_view(frame: np.ndarray) -> np.ndarray:
    """The colour channels of an (H, W), (H, W, 1|3|4) frame: alpha (a fourth channel) is no light."""
    return frame[..., :3] if frame.ndim == 3 and frame.shape[2] == 4 else frame


def exposure_scale(frame: np.ndarray) -> float:
    """The power of two by which to multiply the colour of the linear-light float `frame` so that its key lands
    nearest to 1 on a logarithmic scale; 1.0 where the key is not positive (a black frame) or not finite."""
    colour = colour_view(frame)
    stride = max(1, int(np.sqrt(colour.shape[0] * colour.shape[1] / KEY_SAMPLES)))
    colour = colour[::stride, ::stride]
    if colour.ndim == 3:   # max over channels as pairwise maxima: numpy's reduction over a short axis is slow
        peak = colour[..., 0]
        for c in range(1, colour.shape[2]):
            peak = np.maximum(peak, colour[..., c])
    else:
        peak = colour
    peak = peak.ravel()
    k = min(peak.size - 1, int(peak.size * KEY_PERCENTILE / 100))
    key = float(np.partition(peak, k)[k])
    if not (key > 0.0 and np.isfinite(key)):   # black, or mostly NaN / inf (a caller that did not replace them)
        return 1.0
    stops = int(np.clip(np.round(-np.log2(key)), -MAX_STOPS, MAX_STOPS))
    if stops > 0:   # brightening: the frame's largest sample must stay in range (NaN, inf and samples already
        mag = np.abs(colour_view(frame))   # out of it pass through unchanged: spatial/nonfinite.py)
        largest = float(np.max(mag, where=mag <= SCALED_LIMIT, initial=0.0))
        while stops > 0 and largest * 2.0 ** stops > SCALED_LIMIT:
            stops -= 1
    return float(2.0 ** stops)


def scale_colour(frame: np.ndarray, scale: float) -> None:
    """Multiply the colour channels of the float `frame` by `scale` in place (a power of two: exact)."""
    if scale != 1.0:
        colour = colour_view(frame)
        np.multiply(colour, frame.dtype.type(scale), out=colour)


def exposed(frame: np.ndarray, scale: float) -> np.ndarray:
    """A copy of the float `frame` with its colour channels multiplied by `scale` (a power of two: exact)."""
    out = np.array(frame, copy=True)
    scale_colour(out, scale)
    return out


class HeldExposure:
    """The scale of a sequence whose frames share state (the temporal stage's ring): a frame's own scale
    (exposure_scale) replaces the held one only when the two differ by more than HOLD_STOPS stops (the frame's key
    then lies over 1.5 stops from 1 at the held scale), so a key near a half-stop boundary does not switch scales,
    and restart the ring, frame after frame."""

    HOLD_STOPS = 1

    def __init__(self) -> None:
        self.scale: float | None = None

    def update(self, frame: np.ndarray) -> bool:
        """Take `frame`'s own scale where it must change; True when it changed (what was held at the old scale is
        another exposure's)."""
        own = exposure_scale(frame)
        if self.scale is not None and abs(np.log2(own / self.scale)) <= self.HOLD_STOPS:
            return False
        changed = self.scale is not None
        self.scale = own
        return changed

    def scale_for(self, frame: np.ndarray, linear: bool) -> tuple[float, bool]:
        """The scale `frame` is worked at -- the held one for a linear-light float frame, else 1 -- and whether the
        held scale changed with it (the caller's history is then another exposure's)."""
        if not linear or np.asarray(frame).dtype.kind != "f":
            return 1.0, False
        changed = self.update(np.asarray(frame))
        return self.scale, changed
