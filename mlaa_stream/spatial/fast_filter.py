"""FastFilter: the `fast` preset (spatial/fast.py) without host copies where the device runs kernels on host
memory (PoCL's CPU driver).

Filter.submit copies a frame into a staging array, uploads it, and downloads the result: three copies of
the frame per call, about 2 ms of a 1080p frame here, which is most of what the fast passes cost on a frame
with few edges (docs/fast.md). Here the kernels read the frame and write a new array directly (buffers over
host memory, USE_HOST_PTR): fast_edges copies the frame into it and fast_blend writes the pixels it changes.
`process` reads the caller's array itself; `submit` (the caller may reuse its array at once) one copy of it.
Frames this cannot take (float frames, whose non-finite samples are replaced on the way
in; arrays that are not C-contiguous in the device's sample type; other devices) go through Filter.submit.

    with FastFilter() as f:                  # Filter(preset="fast") options
        out = f.process(frame)
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from mlaa_stream.device.formats import frame_format
from mlaa_stream.spatial.filter import Filter, PendingFrame
from mlaa_stream.spatial.keep import kept_patches


class FastFilter(Filter):
    """`Filter(preset="fast")` (keywords as Filter's), with zero-copy frames on PoCL's CPU device."""

    def __init__(self, device: str | int | None = None, **kwargs):
        super().__init__(device, **{**kwargs, "fast": True, "preset": None})
        dev = self.context.device
        # PoCL's CPU driver runs kernels on a USE_HOST_PTR array itself: once the last kernel's event is
        # complete the array holds the result (other runtimes may keep a device copy: they would need a map).
        self.direct = bool(dev.type & cl.device_type.CPU) and dev.host_unified_memory and \
            "Portable Computing Language" in dev.platform.name
        self._held: list = []  # (event, arrays and buffers the kernels use until it completes)

    def _direct_ok(self, frame: np.ndarray) -> bool:
        fmt = frame_format(frame, self.bgr)
        return (self.direct and frame.dtype.kind in "ui" and frame.dtype == fmt.dtype and frame.flags.c_contiguous
                and not self._wants_alpha(frame))

    def process(self, frame: np.ndarray, premultiplied: bool = False) -> np.ndarray:
        """Filter one frame: the kernels read `frame` itself (nothing else runs on it until this returns)."""
        return (self._enqueue_direct(frame).result() if self._direct_ok(frame) else
                super().process(frame, premultiplied))

    def submit(self, frame: np.ndarray, premultiplied: bool = False) -> PendingFrame:
        """As Filter.submit: the caller may change `frame` as soon as this returns, so the kernels read a copy
        (one copy instead of Filter's staging copy, upload and download)."""
        return (self._enqueue_direct(frame.copy()) if self._direct_ok(frame) else
                super().submit(frame, premultiplied))

    def _enqueue_direct(self, frame: np.ndarray) -> PendingFrame:
        """Enqueue the passes on `frame` and a new output array, both wrapped as device buffers."""
        mf = cl.mem_flags
        with self._lock:
            self._prepare(self._format(frame))
            out = np.empty_like(frame)
            src = cl.Buffer(self.context.ctx, mf.READ_ONLY | mf.USE_HOST_PTR, hostbuf=frame)
            dst = cl.Buffer(self.context.ctx, mf.WRITE_ONLY | mf.USE_HOST_PTR, hostbuf=out)
            # after the previous frame: the passes' own buffers (edges, shapes) are shared by all frames
            after = [self._last_event] if self._last_event is not None else []
            done = self._fast.enqueue(self.queue, src, dst, self._luts, after)
            self._last_event = done
            # the caller may drop the PendingFrame: the arrays stay referenced until the kernels are done
            complete = cl.command_execution_status.COMPLETE
            self._held = [(e, k) for e, k in self._held if e.command_execution_status != complete]
            self._held.append((done, (frame, out, src, dst)))
            self.queue.flush()
        return PendingFrame(out, done, frame.dtype, frame.shape, keep=(frame, src, dst),
                            patches=kept_patches(frame, self.keep))

    def close(self) -> None:
        try:
            super().close()
        finally:
            self._held = []
