"""Rectangles of the frame that come out exactly as they went in: burned-in subtitles, a game's HUD, a slate.

In a frame the filter judges a 1-spp 3D render, every busy neighbourhood is a render region (spatial/fallback.py),
and antialiased text drawn over the render lies inside one: the FXAA fallback and the footprint and refine tables
blur it (docs/spatial_tuning.md, "Text and HUDs over a render": white subtitles over the bench's renders move by
22-26 levels RMSE). No local test measured there tells such text from the render's own thin features without
costing the render, but where the overlays sit is known to whoever made the frames: `--keep X,Y,W,H` (the
command line) or `keep=[...]` (Filter, Antialiaser) names them, in pixels or in % of the frame's width / height.

    Filter(keep=["0,85%,100%,15%"])   # the bottom 15 % of every frame (subtitles) left as it is
"""
from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Iterable, Sequence

import numpy as np

_log = logging.getLogger(__name__)
_warned: set = set()  # (rectangle, frame size) pairs already said to lie outside the frame


@dataclass(frozen=True)
class KeepRect:
    """x, y, width, height: pixels, or fractions of the frame's width / height where `relative` says so."""
    x: float
    y: float
    w: float
    h: float
    relative: tuple[bool, bool, bool, bool] = (False, False, False, False)

    def slices(self, height: int, width: int) -> tuple[slice, slice]:
        """(rows, columns) of the rectangle in a height x width frame, clipped to it (possibly empty)."""
        def px(value: float, rel: bool, size: int) -> int:
            return int(round(value * size)) if rel else int(value)
        x0, y0 = px(self.x, self.relative[0], width), px(self.y, self.relative[1], height)
        x1, y1 = x0 + px(self.w, self.relative[2], width), y0 + px(self.h, self.relative[3], height)
        return slice(min(y0, height), min(y1, height)), slice(min(x0, width), min(x1, width))


def parse_keep(text: str) -> KeepRect:
    """'X,Y,W,H' in pixels, each value optionally a percentage of the frame's width (X, W) or height (Y, H), e.g.
    '0,85%,100%,15%'. Raises ValueError naming what is wrong."""
    parts = [p.strip() for p in str(text).split(",")]
    if len(parts) != 4:
        raise ValueError(f"keep: expected X,Y,W,H (pixels or %), got {text!r}")
    values, relative = [], []
    for name, part in zip("XYWH", parts):
        rel = part.endswith("%")
        try:
            v = float(part[:-1]) / 100.0 if rel else float(part)
        except ValueError:
            raise ValueError(f"keep: {name} of {text!r} is not a number: {part!r}") from None
        # finite first: int() of an infinity ('1e400' parses as one) raises OverflowError, not a message
        if not (v >= 0 and np.isfinite(v)) or (name in "WH" and v == 0):
            raise ValueError(f"keep: {name} of {text!r} must be {'positive' if name in 'WH' else '>= 0'}, "
                             f"got {part!r}")
        if not rel and v != int(v):
            raise ValueError(f"keep: {name} of {text!r} must be whole pixels or a percentage, got {part!r}")
        values.append(v)
        relative.append(rel)
    return KeepRect(*values, relative=tuple(relative))


def keep_rects(keep: Iterable[KeepRect | str] | str | None) -> tuple[KeepRect, ...]:
    """The rectangles of a `keep` option: KeepRects, 'X,Y,W,H' strings, or one string."""
    if keep is None:
        return ()
    if isinstance(keep, (str, KeepRect)):
        keep = [keep]
    return tuple(_keep_rect(k) for k in keep)


def _keep_rect(k: object) -> KeepRect:
    """One item of a `keep` option. Anything but a KeepRect or a string is refused by type: a tuple of numbers was
    turned into its text and refused as: X of (0, 0, 10, 10) is not a number: '(0'."""
    if isinstance(k, KeepRect):
        return k
    if isinstance(k, str):
        return parse_keep(k)
    raise ValueError(f"keep: expected KeepRect(x, y, w, h) or an 'X,Y,W,H' string (pixels or %) for each "
                     f"rectangle, got {type(k).__name__} {k!r}")


def kept_patches(frame: np.ndarray, rects: Sequence[KeepRect]) -> list[tuple[tuple[slice, slice], np.ndarray]]:
    """Copies of `frame` inside each rectangle, to paste back into the output (restore_patches)."""
    h, w = frame.shape[:2]
    out = []
    for r in rects:
        sl = r.slices(h, w)
        if (sl[0].start >= sl[0].stop or sl[1].start >= sl[1].stop) and (r, h, w) not in _warned:
            _warned.add((r, h, w))  # a typo would otherwise protect nothing without a word, once per size
            _log.warning("keep rectangle %s lies outside the %dx%d frame: it keeps nothing there", _text(r), w, h)
        out.append((sl, frame[sl].copy()))
    return out


def _text(r: KeepRect) -> str:
    """The rectangle as it was written: X,Y,W,H with % where relative."""
    return ",".join(f"{v * 100:g}%" if rel else f"{v:g}" for v, rel in zip((r.x, r.y, r.w, r.h), r.relative))


def restore_patches(out: np.ndarray, patches: Sequence[tuple[tuple[slice, slice], np.ndarray]]) -> np.ndarray:
    """`out` with each patch pasted back where it came from (a copy when `out` is read-only)."""
    if not patches:
        return out
    if not out.flags.writeable:
        out = out.copy()
    for sl, patch in patches:
        out[sl] = patch
    return out


def restore_kept(frame: np.ndarray, out: np.ndarray, rects: Sequence[KeepRect]) -> np.ndarray:
    """`out` with `frame`'s pixels inside each rectangle (after a temporal stage, which mixes frames)."""
    return restore_patches(out, kept_patches(frame, rects)) if rects else out
