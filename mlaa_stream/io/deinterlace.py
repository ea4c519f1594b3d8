"""Interlaced video made progressive before the filter: libavfilter's bwdif (yadif where this FFmpeg lacks it).

An interlaced frame holds two fields a field-time apart; on anything that moves, their rows alternate between two
positions (combing), which the antialiasing filter takes for jaggies and smears. The deinterlacer runs on the decoded
frames in their own pixel format (YUV, fields and chroma as coded), before they become RGB: one progressive frame per
frame (mode send_frame: same rate, same count), each given the timestamp of the frame it comes from.
"""
from __future__ import annotations

from collections import deque
from fractions import Fraction

MODES = ("auto", "on", "off")   # --deinterlace: the stream's word (auto), always, never
FILTERS = ("bwdif", "yadif")    # in order of preference: bwdif interpolates the missing rows better
FLAGGED = "frames flagged interlaced"   # the reason when the frames say so and the stream does not
FORCED = "--deinterlace on"              # ... when neither does


def filter_name() -> str:
    """The deinterlacer this PyAV's FFmpeg has: bwdif, else yadif (older builds, and ones made without bwdif)."""
    import av.filter

    return next((name for name in FILTERS if name in av.filter.filters_available), FILTERS[-1])


def reason(mode: str, field_order: str | None, frame_flagged: bool) -> str | None:
    """Why the frames are deinterlaced under `mode` (auto / on / off), or None where they are not: the stream's field
    order ("top field first" ...; VideoInfo.interlaced), FLAGGED (the first frame says it is interlaced), or FORCED
    where only the mode says so."""
    if mode not in MODES:
        raise ValueError(f"deinterlace: expected one of {', '.join(MODES)}, got {mode!r}")
    if mode == "off":
        return None
    why = field_order or (FLAGGED if frame_flagged else None)
    return why or (FORCED if mode == "on" else None)


class Deinterlacer:
    """bwdif (or yadif) in send_frame mode through an av.filter.Graph, made on the first frame pushed (its size and
    pixel format). `field_order` from the stream sets the parity (frames that do not say theirs are taken as top field
    first by FFmpeg otherwise); `only_flagged`: leave frames that are not flagged interlaced as they are (auto mode on
    a stream whose frames say which are: a progressive stretch of a broadcast stays sharp)."""

    def __init__(self, field_order: str | None = None, only_flagged: bool = False, name: str | None = None):
        self.name = name or filter_name()
        self._parity = {"top field first": "tff", "bottom field first": "bff"}.get(field_order or "", "auto")
        self._deint = "interlaced" if only_flagged else "all"
        self._graph = None
        self._times: deque = deque()   # (pts, time_base) of the frames pushed and not yet pulled, in order

    def _open(self, frame, time_base: Fraction) -> None:
        import av.filter

        graph = av.filter.Graph()
        src = graph.add_buffer(width=frame.width, height=frame.height, format=frame.format.name, time_base=time_base)
        deint = graph.add(self.name, f"mode=send_frame:parity={self._parity}:deint={self._deint}")
        sink = graph.add("buffersink")
        src.link_to(deint)
        deint.link_to(sink)
        graph.configure()   # formats the filter lacks (packed RGB, NV12) are converted by the scaler it inserts
        self._graph = graph

    def push(self, frame, time_base: Fraction | None = None) -> list:
        """Hand in one decoded frame; returns the progressive frames ready (the filter keeps one frame back: it reads
        the next frame's fields)."""
        if self._graph is None:
            self._open(frame, Fraction(frame.time_base or time_base or Fraction(1, 25)))
        self._times.append((frame.pts, frame.time_base))
        self._graph.push(frame)
        return self._pull()

    def flush(self) -> list:
        """The frames still held, at the end of the stream (or before an error is raised: none is lost)."""
        if self._graph is None:
            return []
        self._graph.push(None)
        return self._pull()

    def _pull(self) -> list:
        import av

        out = []
        while self._times:
            try:
                frame = self._graph.pull()
            except (av.error.BlockingIOError, av.error.EOFError, BlockingIOError, EOFError):
                break
            # the filter doubles the time base (a field's time); the source frame's own timestamp instead, exact
            frame.pts, time_base = self._times.popleft()
            if time_base is not None:
                frame.time_base = time_base
            out.append(frame)
        return out
