"""Which frames of a stream belong to one shot: the render verdict is held over a shot (kernels/fallback.cl
render_frame).

A video codec spends its bits unevenly: a compressed render's keyframe keeps the busy texture that judges it a
render (RENDER_FRAME_PCT), the P- and B-frames after it are smoothed under that share, and the verdict flips from
frame to frame (docs/spatial_tuning.md, "RENDER_HOLD_FRAMES"). A frame judged a render by its own share holds the
verdict for the RENDER_HOLD_FRAMES frames after it, until a cut: a histogram of its green channel that moved by more
than CUT_HIST (half the L1 distance, as the temporal stage's cut test on grey) from the previous frame's.
"""
from __future__ import annotations

import cv2
import numpy as np

# x264's default keyframe interval: a render judged at its keyframe is held to the next one
RENDER_HOLD_FRAMES = 250
# A held frame that looks supersampled stays held if it is one of at most this many such frames in a row: a codec's
# blur makes its B-frames look supersampled (x264's default: up to 3 B-frames between reference frames); a shot that
# turns supersampled for longer is judged supersampled (docs/spatial_tuning.md, "RENDER_HOLD_FRAMES").
HELD_SUPERSAMPLED_RUN = 3
CUT_HIST = 0.45  # a cut: histograms this far apart (half their L1 distance; also temporal/stage.py's cut test)
THUMB_STEP = 8  # the histogram's thumbnail: one pixel in THUMB_STEP x THUMB_STEP


def histogram_distance(a: np.ndarray, b: np.ndarray, bins: int = 32) -> float:
    """Half the L1 distance of the normalised grey histograms of two uint8 images: 0 same, 1 disjoint."""
    ha = cv2.calcHist([a], [0], None, [bins], [0, 256]).ravel()
    hb = cv2.calcHist([b], [0], None, [bins], [0, 256]).ravel()
    return float(0.5 * np.abs(ha / max(ha.sum(), 1) - hb / max(hb.sum(), 1)).sum())


def thumbnail(frame: np.ndarray) -> np.ndarray:
    """A uint8 thumbnail of `frame` (H, W[, C]; integer codes or float in [0, 1], clipped): one pixel in THUMB_STEP
    each way, of its green channel (the middle one in RGB and BGR alike, most of luma; a grey frame's only one)."""
    a = np.asarray(frame)[::THUMB_STEP, ::THUMB_STEP]
    if a.ndim == 3:
        a = a[..., min(1, a.shape[-1] - 1)]
    if a.dtype == np.uint8:
        return np.ascontiguousarray(a)
    scale = 255.0 / np.iinfo(a.dtype).max if a.dtype.kind in "ui" else 255.0
    return np.clip(np.nan_to_num(a.astype(np.float32) * scale), 0, 255).astype(np.uint8)


class ShotTracker:
    """Cuts in a stream of frames, for the held render verdict: `cut(frame)` is True for the first frame and after
    reset(), and where the frame's histogram moved by more than CUT_HIST from the previous frame's."""

    def __init__(self) -> None:
        self._last: np.ndarray | None = None

    def reset(self) -> None:
        """The next frame starts a shot (nothing before it is held)."""
        self._last = None

    def cut(self, frame: np.ndarray) -> bool:
        thumb = thumbnail(frame)
        last, self._last = self._last, thumb
        return last is None or last.shape != thumb.shape or histogram_distance(last, thumb) > CUT_HIST
