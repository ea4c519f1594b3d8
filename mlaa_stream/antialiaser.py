"""`Antialiaser`: the filter for OpenCV capture loops, on BGR numpy frames.

    with mlaa_stream.Antialiaser() as aa:
        out = aa(frame)                       # one frame at a time, state kept between calls
        for out in aa.stream(cv2.VideoCapture("in.mp4")):   # or any iterable of frames
            ...                               # decoding, filtering and your loop overlap

Both paths run the same stages as the command line (filter, temporal hook, post hooks); `stream`
also overlaps decoding (a reader thread) and device transfers (frames in flight) with your loop.
"""
from __future__ import annotations

import threading
from numbers import Integral
from typing import Any, Iterable, Iterator, Sequence

import numpy as np

from mlaa_stream.spatial.alpha import spatial_at_rims
from mlaa_stream.spatial.filter import PRESETS, Filter
from mlaa_stream.spatial.fast_filter import FastFilter
from mlaa_stream.spatial.keep import KeepRect, keep_rects, restore_kept
from mlaa_stream.pipeline import PipelineError, PostHook, Temporal, stream_items
from mlaa_stream.temporal.methods import METHODS, check_frames, make_stage, needs_regions, stats_lists

# Rows of the temporal stage's per-frame `stats` kept (the last ones): the stages append one a frame, for the
# command line's --stats CSV of a file, and a live capture loop runs for hours (about 2.5 KB a frame).
STATS_KEPT = 1000


def _capture_frames(cap: Any) -> Iterator[np.ndarray]:
    """Frames of a cv2.VideoCapture until it has no more (the capture is not released here)."""
    while True:
        ok, frame = cap.read()
        if not ok or frame is None:
            return
        yield frame


def _whole(value: object, least: int) -> bool:
    """Whether `value` is an integer (a numpy one too; not a bool) of at least `least`."""
    return isinstance(value, Integral) and not isinstance(value, bool) and value >= least


def _trim_stats(stage: Any) -> None:
    """Keep the last STATS_KEPT rows of a temporal stage's per-frame stats (TSSThenBlend: of both its stages)."""
    for rows in stats_lists(stage):
        if len(rows) > STATS_KEPT:
            del rows[:-STATS_KEPT]


class Antialiaser:
    """Antialias BGR(A) or grey frames (uint8 as OpenCV delivers them; uint16/float also work).

    `device`: an index or a name substring as `mlaa-stream devices` lists them (None: $MLAA_STREAM_DEVICE, else a
    GPU, else PoCL's CPU device). Other options are the Filter's (`preset` first, explicit keywords override it).
    Frames of one object are one sequence (the frame index, the temporal history): threads may share it (each frame
    gets the next index, streams' frames too; with a temporal stage the calls take turns and another thread's frames
    during a stream are refused), but a thread with a sequence of its own makes its own. `temporal=True` (or
    "auto") adds temporal supersampling (mlaa_stream.temporal.tss.TSSStage: the input's samples of the last
    `temporal_frames` frames (default 16, 2 to 64; a TSS setting, refused without TSS) accumulated along the motion;
    its ring is kept between calls) and the reprojection blend on moving edges of render regions;
    "tss", "blend" and "tss+blend" are the other methods of mlaa_stream.temporal.methods; or pass any
    `(frame_in, frame_filtered, index) -> frame` stage.
    `lookahead=N` (files, not live capture): in `stream`, temporal supersampling also reads the N frames after
    each one (each output then waits for N more frames to be read); `aa(frame)` reads the past only.
    `post_hooks` is a list of `(frame, index) -> frame` callables (overlays), applied after it.
    `dense_motion=True`: temporal supersampling tracks motion tile by tile where one camera motion does not
    explain a frame (dollies, orbits; TSSStage's dense_samples: more error removed there, several times slower).
    The stage made here is `temporal`; its `stats` holds one row per frame, the last STATS_KEPT (1000) frames'.
    `linear_input=True`: the frames hold linear light (EXR renders, float, highlights may exceed 1): the filter
    and the temporal stage take them as they are instead of sRGB-decoding them.
    `keep`: rectangles every output frame takes unchanged from its input (subtitles, a HUD over a render:
    spatial/keep.py), as KeepRect or 'X,Y,W,H' strings in pixels or % of the frame.
    `alpha`: "coverage" antialiases the alpha of BGRA frames whose alpha varies (straight alpha, as OpenCV reads
    PNGs) with their colour (spatial/alpha.py); "keep" leaves it as it is.
    `transfer="pq"` / `"hlg"`: the frames are 8/16-bit codes of HDR video (HDR10's SMPTE ST 2084, HLG): the filter
    works in the linear light they code and codes its output back (device/transfer.py); so does temporal
    supersampling, while the blend keeps blending the codes.
    `hold_render`: the frames form shots (spatial/shots.py): a frame judged a render holds that verdict for the
    frames after it until a cut, as a video codec's P- and B-frames need; `new_shot()` starts a shot by hand (frames
    that are not one sequence); False judges every frame alone.
    """

    def __init__(self, device: str | int | None = None, *, preset: str | None = None,
                 threshold: float | None = None, metric: str | None = None, linear: bool | None = None,
                 reconstruct: bool | None = None, temporal: Temporal | bool | str | None = None,
                 temporal_frames: int | None = None, post_hooks: Sequence[PostHook] | None = (), in_flight: int = 2,
                 lookahead: int = 0, linear_input: bool = False, dense_motion: bool = False,
                 keep: Sequence[KeepRect | str] | str | None = None, alpha: str = "coverage",
                 transfer: str | None = None, hold_render: bool = True):
        if preset is not None and preset not in PRESETS:
            raise ValueError(f"expected a preset among {', '.join(sorted(PRESETS))}, got {preset!r}")
        kwargs = dict(PRESETS.get(preset or "default", {}))
        for key, value in (("threshold", threshold), ("metric", metric), ("linear", linear),
                           ("reconstruct", reconstruct)):
            if value is not None:
                kwargs[key] = value
        if linear_input:
            kwargs["linear_input"] = True
        if keep is not None:
            kwargs["keep"] = keep_rects(keep)
        kwargs["alpha"] = alpha
        if transfer is not None:
            kwargs["transfer"] = transfer
        method = "auto" if temporal is True else temporal
        # a stage that is no method's name nor callable (temporal=1), hooks that are not callables and in_flight
        # < 1 failed only at the first frame ("'int' object is not callable") or the first stream: named here
        if (isinstance(method, str) and method not in METHODS) or not (
                method is None or method is False or isinstance(method, str) or callable(method)):
            raise ValueError(f"temporal: expected True, {', '.join(map(repr, METHODS))} or a callable, "
                             f"got {temporal!r}")
        # None: no hooks, as for `temporal` (it failed as "'NoneType' object is not iterable")
        hooks = [] if callable(post_hooks) or post_hooks is None else list(post_hooks)   # a generator is read once
        if callable(post_hooks) or not all(callable(h) for h in hooks):
            raise TypeError(f"post_hooks: expected a list of (frame, index) -> frame callables, got {post_hooks!r}")
        # whole numbers of frames: 2.5 in flight was taken, and a look-ahead of 1.5 or "2" became int() of it
        if not _whole(in_flight, 1):
            raise ValueError(f"in_flight: expected 1 or more frames on the device at once (an integer), "
                             f"got {in_flight!r}")
        if not _whole(lookahead, 0):
            raise ValueError(f"lookahead: expected 0 or more frames (an integer), got {lookahead!r}")
        if method == "blend" and temporal_frames is not None:   # make_stage leaves it to the CLI's warning
            raise ValueError("temporal_frames: the ring of temporal supersampling, which the blend method does not "
                             "use; use a method with TSS")
        if isinstance(method, str) and method != "blend" and temporal_frames is not None:
            check_frames(temporal_frames)   # before the filter is made: a ring of one frame holds no history
        if isinstance(method, str) and needs_regions(method) and not kwargs.get("fast"):
            kwargs["keep_regions"] = True  # the stage reads the filter's render regions
        if not kwargs.get("fast"):  # the fast preset has no render regions to hold
            kwargs["hold_render"] = hold_render
        # the fast preset without host copies on CPU devices (spatial/fast_filter.py)
        self._filter = (FastFilter if kwargs.get("fast") else Filter)(device, bgr=True, **kwargs)
        self.device_name: str = self._filter.device_name
        if isinstance(method, str):
            temporal = make_stage(method, self._filter.context, bgr=True, frames=temporal_frames,
                                  regions_from=self._filter, lookahead=lookahead, linear_input=linear_input,
                                  dense_samples=dense_motion, transfer=transfer)
        elif lookahead or dense_motion or temporal_frames is not None:
            raise ValueError("lookahead, dense_motion, temporal_frames: need temporal=True or one of the temporal "
                             "methods with TSS")
        self.temporal = temporal or None
        self._own_stage = isinstance(method, str)   # its stats are trimmed (_trim_stats); a callable's are the caller's
        self.post_hooks = hooks
        self.in_flight = int(in_flight)
        self.index = 0  # frames processed so far, across calls and streams
        self._closed = False
        # index claims, and with a temporal stage each call's filter + stage step: threads sharing this object
        # each got the same index (the stage restarted its ring at the repeat, its stats had rows twice)
        self._lock = threading.Lock()
        # the streams of a temporal stage begun and not ended -> the thread that drives each (last resumed it)
        self._streams: dict[object, int] = {}

    def new_shot(self) -> None:
        """The next frame starts a shot: the filter holds no render verdict from the frames before it."""
        new_shot = getattr(self._filter, "new_shot", None)
        if new_shot is not None:
            new_shot()

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        """Antialias one frame (blocking); returns a new array of the same shape and dtype.

        Threads may share one object: each frame gets the next index. With a temporal stage the calls take
        turns (the stage is one sequence, and "auto" reads the render regions of the frame just filtered);
        a call while another thread's `stream` of it runs is refused."""
        self._check_open()
        if self.temporal is None:
            out = self._filter.process(frame)   # concurrent calls overlap here (the filter has its own locks)
            with self._lock:
                index, self.index = self.index, self.index + 1
        else:
            with self._lock:
                self._check_idle()
                out = self._filter.process(frame)
                index = self.index
                out = restore_kept(frame, spatial_at_rims(out, self.temporal(frame, out, index)), self._filter.keep)
                if self._own_stage:
                    _trim_stats(self.temporal)
                self.index = index + 1   # the stage took it: a failing hook below must not hand it the index again
        for hook in self.post_hooks:
            out = hook(out, index)
        return out

    def stream(self, source: Any | Iterable[np.ndarray]) -> Iterator[np.ndarray]:
        """Yield the antialiased frames of a cv2.VideoCapture (read until it ends) or an iterable (an array of
        frames along its first axis too; one frame is refused: aa(frame) filters it).

        Decoding runs in a reader thread and frames overlap on the device; leaving the loop early
        (break) stops the reader. Each frame takes the next `index` (across calls and streams, the number the post
        hooks and the temporal stage get) when it reaches them: without a temporal stage, streams in several threads
        may share this object, each frame's index unique and each stream's increasing (not consecutive where others
        take some meanwhile). Errors are raised as PipelineError naming that index.
        """
        self._check_open()
        capture = hasattr(source, "read") and hasattr(source, "isOpened")
        if capture and not source.isOpened():
            # a capture that could not open its file or camera reads nothing: say so instead of ending at once
            raise ValueError("the capture is not open (cv2.VideoCapture could not open its file or camera)")
        if isinstance(source, np.ndarray) and (source.ndim < 3 or (source.ndim == 3 and source.shape[2] in (1, 3, 4))):
            # iterating one frame gives its rows: each came out as a frame of one row's pixels, without an error
            raise ValueError(f"stream: expected frames (a capture, an iterable, or an array of frames along its first "
                             f"axis), got one {source.shape} array; aa(frame) filters one frame (a stack of grey "
                             f"frames this narrow: pass list(stack))")
        frames = _capture_frames(source) if capture else source
        token = object()
        if self.temporal is not None:
            with self._lock:   # after a call in another thread: its frame comes before this stream's
                self._check_idle()
                self._streams[token] = threading.get_ident()
        inner = self._stream(frames)
        try:
            for out in inner:
                yield out
                if token in self._streams:   # the loop may go on in another thread: it drives the stream now
                    self._streams[token] = threading.get_ident()
        finally:
            inner.close()   # stops the reader thread now, whatever ends the loop
            self._streams.pop(token, None)

    def _stream(self, frames: Any) -> Iterator[np.ndarray]:
        claimed: dict[int, int] = {}   # position in this stream -> the index its frame took

        def index_of(position: int) -> int:
            """The frame's index, taken (the next one of this object) the first time its stage, hooks or the loop
            need it: streams running at once, and calls, each get their own, and a stream's frames come in order."""
            with self._lock:
                if position not in claimed:
                    claimed[position], self.index = self.index, self.index + 1
                return claimed[position]

        temporal = None
        if self.temporal is not None:
            user_temporal, own = self.temporal, self._own_stage

            def temporal(a, b, i, **future):
                out = user_temporal(a, b, index_of(i), **future)
                if own:
                    _trim_stats(user_temporal)
                return out
            temporal.lookahead = getattr(user_temporal, "lookahead", 0)   # the pipeline reads it
        hooks = [(lambda h: (lambda f, i: h(f, index_of(i))))(h) for h in self.post_hooks]
        items = stream_items(frames, self._filter, in_flight=self.in_flight, temporal=temporal, post_hooks=hooks)
        try:
            for item in items:
                index_of(item.index)
                claimed.pop(item.index)
                yield item.frame
                # closed while the loop held a frame: stop here rather than refill the freed device buffers
                self._check_open()
        except PipelineError as exc:
            # the pipeline counts from this stream's first frame; name the frame as the hooks and the temporal
            # stage saw it, or (never given one: a read or filter failure) the index it would have taken
            with self._lock:
                index = claimed.get(exc.index, self.index)
            if index == exc.index:
                raise
            raise PipelineError(exc.stage, index, exc.cause, exc.meta) from exc.cause
        finally:
            items.close()   # stops the reader thread now, whatever ends the loop

    def _check_open(self) -> None:
        if self._closed:
            raise RuntimeError("this Antialiaser is closed")

    def _check_idle(self) -> None:
        """Refuse a temporal stage's frame from this thread while another thread's stream feeds it: the two
        sequences would mix in its history. (The thread that drives a stream may call between its frames, or after
        leaving the loop, as before: its own sequence.)"""
        me = threading.get_ident()
        if any(thread != me for thread in list(self._streams.values())):
            raise RuntimeError("a stream of this Antialiaser is running in another thread, and its temporal stage "
                               "takes one sequence of frames: finish or close that stream first (`frames.close()`), "
                               "or make another Antialiaser for this thread")

    def close(self) -> None:
        """Free the device buffers; the object cannot be used afterwards."""
        if not self._closed:
            self._closed = True
            self._filter.close()
            if hasattr(self.temporal, "close"):
                self.temporal.close()

    def __getstate__(self) -> None:
        # pickle named pyopencl's Device ("cannot pickle 'Device' object"): say what cannot travel and what to do
        raise TypeError("an Antialiaser holds OpenCL device state and cannot be pickled or copied; make one in each "
                        "process or thread that filters (Antialiaser(...) with the same options)")

    def __enter__(self) -> "Antialiaser":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
