"""Progress on stderr while frames are written: frames done, frames per second, time left.

Shown only when the stream is a terminal (a log file gets no carriage-return noise); `quiet`
silences it. Updates are throttled so a fast pipeline does not spend its time printing.
"""
from __future__ import annotations

import sys
import threading
import time
from typing import TextIO


def _clock(seconds: float) -> str:
    seconds = int(round(seconds))
    h, rem = divmod(seconds, 3600)
    m, s = divmod(rem, 60)
    return f"{h}:{m:02d}:{s:02d}" if h else f"{m}:{s:02d}"


class Progress:
    """`update(done)` from any thread; `close()` ends the line. Prints nothing when disabled."""

    def __init__(self, total: int | None, *, label: str = "", stream: TextIO | None = None,
                 enabled: bool | None = None, interval: float = 0.25, machine: TextIO | None = None):
        """`machine`: also write key=value blocks there (--progress FILE|-), each ended by a `progress=`
        line as ffmpeg's -progress does: frame, total_frames, fps, elapsed_s, left_s; at most one a second
        and a last one (progress=end) on close."""
        self.machine = machine
        self._machine_last = 0.0
        self.stream = stream if stream is not None else sys.stderr
        if enabled is None:
            isatty = getattr(self.stream, "isatty", None)
            enabled = bool(isatty and isatty())
        self.enabled = enabled
        self.total = total if total and total > 0 else None
        self.label = label
        self.interval = interval
        self.started = time.perf_counter()
        self._last = 0.0
        self._done = 0
        self._width = 0
        self._lock = threading.Lock()

    def line(self, done: int, now: float | None = None) -> str:
        """The text shown for `done` frames: 'label  12/300 frames  24.3 fps  0:11 left'."""
        elapsed = (now if now is not None else time.perf_counter()) - self.started
        fps = done / elapsed if elapsed > 0 else 0.0
        count = f"{done}/{self.total}" if self.total else f"{done}"
        text = f"{self.label}  {count} frames  {fps:.1f} fps"
        if self.total and fps > 0 and done < self.total:
            text += f"  {_clock((self.total - done) / fps)} left"
        elif self.total is None or done >= self.total:
            text += f"  {_clock(elapsed)}"
        return text.strip()

    def machine_block(self, done: int, end: bool, now: float | None = None) -> str:
        """One key=value block for `done` frames."""
        elapsed = (now if now is not None else time.perf_counter()) - self.started
        fps = done / elapsed if elapsed > 0 else 0.0
        left = (self.total - done) / fps if self.total and fps > 0 else None
        lines = [f"frame={done}", f"total_frames={self.total if self.total else 'N/A'}", f"fps={fps:.2f}",
                 f"elapsed_s={elapsed:.2f}", f"left_s={'N/A' if left is None else f'{max(left, 0.0):.1f}'}",
                 f"progress={'end' if end else 'continue'}"]
        return "\n".join(lines) + "\n"

    def _write_machine(self, done: int, end: bool) -> None:
        now = time.perf_counter()
        if self.machine is None or (not end and now - self._machine_last < 1.0):
            return
        self._machine_last = now
        try:
            self.machine.write(self.machine_block(done, end, now))
            self.machine.flush()
        except (OSError, ValueError):  # a closed pipe must not stop the filter
            self.machine = None

    def update(self, done: int) -> None:
        self._done = done
        self._write_machine(done, end=False)
        if not self.enabled:
            return
        now = time.perf_counter()
        if now - self._last < self.interval and not (self.total and done >= self.total):
            return
        with self._lock:
            self._last = now
            text = self.line(done, now)
            pad = max(0, self._width - len(text))
            self._width = len(text)
            self.stream.write("\r" + text + " " * pad)
            self.stream.flush()

    def clear(self) -> None:
        """Blank the progress line so that a message printed next starts at the line's start."""
        if not self.enabled or not self._width:
            return
        with self._lock:
            self.stream.write("\r" + " " * self._width + "\r")
            self.stream.flush()
            self._width = 0
            self._last = 0.0

    def close(self) -> None:
        """Print the final state and end the line."""
        self._write_machine(self._done, end=True)
        if not self.enabled:
            return
        with self._lock:
            self.stream.write("\r" + self.line(self._done) + " " * 4 + "\n")
            self.stream.flush()
            self._width = 0
