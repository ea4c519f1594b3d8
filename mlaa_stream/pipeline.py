"""The streaming pipeline: reader thread -> device stage -> temporal hook -> post hooks -> writer thread.

Bounded queues carry items (frame + index + the source's metadata) and end with a sentinel. The
device stage keeps up to `in_flight` frames submitted to the filter, so the upload of frame N+1
and the download of frame N-1 overlap the kernels of frame N; frames come out in order. An item marked
`passthrough` (nothing to filter) comes out in its place as it went in: no filter, temporal stage or post hooks.

Errors: a failure while reading, filtering or in a hook stops the reader at once; the frames before
the failing one still go through and are written, then `PipelineError` names the stage and the
frame index. A failure in the writer stops everything at once. KeyboardInterrupt stops all stages
and propagates. In every case all threads are joined before the call returns (the model is
imageio-ffmpeg's `read_frames`: a generator whose `finally` always stops its reader).
"""
from __future__ import annotations

import itertools
import queue
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator, Protocol, Sequence

import numpy as np

from mlaa_stream.io.item import Item
from mlaa_stream.spatial.alpha import spatial_at_rims
from mlaa_stream.spatial.keep import restore_kept

Temporal = Callable[[np.ndarray, np.ndarray, int], np.ndarray]
PostHook = Callable[[np.ndarray, int], np.ndarray]

_POLL_S = 0.05  # how often a blocked stage looks at the stop event


class _Sentinel:
    def __repr__(self) -> str:
        return "<end of stream>"


END = _Sentinel()


class PendingResult(Protocol):
    def result(self) -> np.ndarray: ...


class _Unfiltered:
    """The 'result' of a passthrough item: its frame as read."""

    def __init__(self, frame: np.ndarray):
        self.frame = frame

    def result(self) -> np.ndarray:
        return self.frame


class FrameFilter(Protocol):
    """What the device stage needs: `mlaa_stream.spatial.filter.Filter` has it. An object with
    `for_item(item) -> FrameFilter` instead picks a filter per frame (e.g. by colour encoding)."""

    def submit(self, frame: np.ndarray) -> PendingResult: ...


class PipelineError(RuntimeError):
    """A stage failed; `stage` is read, filter, temporal, post or write, `index` the frame's position
    in the stream and `meta` that frame's Item.meta (None when the frame was never read)."""

    def __init__(self, stage: str, index: int, cause: BaseException, meta: Any = None):
        self.stage, self.index, self.cause, self.meta = stage, index, cause, meta
        super().__init__(f"{stage} failed at frame {index}: {cause}")


@dataclass
class StageTimes:
    """Seconds spent in each stage (each field is written by one thread only), and frames counted."""

    read: float = 0.0
    submit: float = 0.0
    wait: float = 0.0  # blocked in .result(): the device work not hidden behind other stages
    temporal: float = 0.0
    post: float = 0.0
    write: float = 0.0
    frames: int = 0
    started: float = field(default_factory=time.perf_counter)

    def report(self) -> str:
        """One line per stage: total seconds and ms per frame."""
        n = max(self.frames, 1)
        wall = time.perf_counter() - self.started
        rows = [("read", self.read), ("submit", self.submit), ("device wait", self.wait),
                ("temporal", self.temporal), ("post hooks", self.post), ("write", self.write)]
        lines = [f"{name:>12}: {sec:7.2f} s  {1000 * sec / n:8.2f} ms/frame" for name, sec in rows]
        lines.append(f"{'wall':>12}: {wall:7.2f} s  {self.frames / wall if wall > 0 else 0:8.2f} fps "
                     f"({self.frames} frames)")
        return "\n".join(lines)


@dataclass
class _Failure:
    stage: str
    index: int
    exc: BaseException
    meta: Any = None


def _put(q: queue.Queue, obj: object, stop: threading.Event) -> bool:
    """Put into a bounded queue unless the pipeline is stopping; False when it was not put."""
    while not stop.is_set():
        try:
            q.put(obj, timeout=_POLL_S)
            return True
        except queue.Full:
            continue
    return False


def _get(q: queue.Queue, stop: threading.Event, producer: threading.Thread) -> object:
    """Take from a queue; END when the pipeline stops or the producer is gone."""
    while True:
        try:
            return q.get(timeout=_POLL_S)
        except queue.Empty:
            if stop.is_set() or not producer.is_alive():
                try:
                    return q.get_nowait()
                except queue.Empty:
                    return END


def _drain(q: queue.Queue) -> None:
    while True:
        try:
            q.get_nowait()
        except queue.Empty:
            return


class _Reader(threading.Thread):
    """Pulls frames from the source iterable (in this thread) into a bounded queue. `depth`: how many of the
    source's arrays the pipeline may still hold when the next one is read (queued, in flight, read ahead)."""

    def __init__(self, source: Iterable, q: queue.Queue, stop: threading.Event, times: StageTimes, depth: int = 1):
        super().__init__(name="mlaa-stream-reader", daemon=True)
        self.source, self.q, self.stop, self.times = source, q, stop, times
        self.depth = max(1, depth)

    def run(self) -> None:
        index = 0
        it = None
        recent: deque = deque(maxlen=self.depth)  # the source's last arrays, as it gave them
        try:
            it = iter(self.source)
            while not self.stop.is_set():
                t0 = time.perf_counter()
                try:
                    obj = next(it)
                except StopIteration:
                    break
                if isinstance(obj, np.ndarray):
                    # a source that reads every frame into one buffer (`ok, buf = cap.read(buf)` in a generator),
                    # or cycles through a pool of them (double buffering, a camera's ring), would overwrite the
                    # frames queued here before they are filtered: the first `depth` frames (a pool may come round
                    # while they are held) and each one in the memory of one of the last `depth` are copied
                    reused = index < self.depth or any(np.may_share_memory(obj, r) for r in recent)
                    recent.append(obj)
                    obj = obj.copy() if reused else obj
                self.times.read += time.perf_counter() - t0
                item = obj if isinstance(obj, Item) else Item(frame=obj)
                item.index = index
                if not _put(self.q, item, self.stop):
                    break
                index += 1
        except Exception as exc:
            _put(self.q, _Failure("read", index, exc), self.stop)
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                try:
                    close()  # a generator source runs its own `finally` (closes files) in this thread
                except Exception as exc:
                    _put(self.q, _Failure("read", index, exc), self.stop)
            _put(self.q, END, self.stop)


def stream_items(source: Iterable, filt: FrameFilter, *, in_flight: int = 2, queue_size: int = 4,
                 temporal: Temporal | None = None, post_hooks: Sequence[PostHook] = (),
                 times: StageTimes | None = None) -> Iterator[Item]:
    """Filter the frames of `source` (ndarrays or Items) in a reader thread + this thread, in order.

    `in_flight` frames are submitted before the oldest one's result is taken (1 = serialized).
    A temporal stage with a `lookahead` attribute N > 0 is called as `temporal(frame_in, frame_filtered,
    index, future=[raw frames index + 1 .. index + N])` (fewer at the end of the stream, and none from a passthrough
    item on: not of the sequence): a frame waits, filtered, until the N frames after it are read.
    Raises PipelineError after yielding every frame before the failing one. Frames are read ahead of the
    filter: an array in the memory of one of the source's recent ones (a reused buffer or a pool of them) is
    copied first, and so are the first frames, which such a pool may overwrite before it comes round.
    """
    if in_flight < 1:
        raise ValueError(f"expected in_flight >= 1, got {in_flight}")
    times = times if times is not None else StageTimes()
    stop = threading.Event()
    q: queue.Queue = queue.Queue(maxsize=max(1, queue_size))
    pending: deque = deque()   # (item, pending result): submitted to the filter
    ready: deque = deque()     # (item, filtered frame, pending result): collected, waiting for the frames after
    # it (look-ahead)
    ahead = max(0, int(getattr(temporal, "lookahead", 0) or 0)) if temporal is not None else 0
    # the source's arrays held while the next is read: queued, the reader's and the one being submitted, in
    # flight, read ahead, and the one being finished
    reader = _Reader(source, q, stop, times, depth=q.maxsize + in_flight + ahead + 3)
    # a temporal stage mixes frames: the filter's keep rectangles (spatial/keep.py) are restored after it too
    kept = getattr(getattr(filt, "encoded", filt), "keep", ()) if temporal is not None else ()
    upstream: _Failure | None = None  # read or submit failure: frames before it still come out
    lost: _Failure | None = None  # a submitted frame's result failed: frames before it still come out
    failure: _Failure | None = None  # failure while finishing a frame: nothing after it comes out
    reader.start()
    try:
        while True:
            obj = _get(q, stop, reader)
            if obj is END:
                break
            if isinstance(obj, _Failure):
                upstream = obj
                break
            t0 = time.perf_counter()
            try:
                if obj.passthrough:
                    pending.append((obj, _Unfiltered(obj.frame)))
                else:
                    f = filt.for_item(obj) if hasattr(filt, "for_item") else filt
                    pending.append((obj, f.submit(obj.frame, premultiplied=True) if obj.premultiplied else
                                       f.submit(obj.frame)))
            except Exception as exc:
                upstream = _Failure("filter", obj.index, exc, obj.meta)
                break
            times.submit += time.perf_counter() - t0
            while len(pending) >= in_flight and failure is None and lost is None:
                lost = _collect(pending.popleft(), ready, times)
                while ready and failure is None and lost is None and len(ready) - 1 + len(pending) >= ahead:
                    item, failure = _finish(ready, pending, ahead, temporal, post_hooks, times, kept)
                    if failure is None:
                        yield item
            if failure is not None or lost is not None:
                break
        stop.set()  # no more input is needed: let the reader go while the last frames finish
        while pending and failure is None and lost is None:
            lost = _collect(pending.popleft(), ready, times)
        if lost is not None:
            _settle(pending)   # frames after one the filter failed on: neither written nor read ahead
        while ready and failure is None:   # the frames before a read or filter failure still come out
            item, failure = _finish(ready, pending, ahead, temporal, post_hooks, times, kept)
            if failure is None:
                yield item
        failure = failure or lost or upstream
        if failure is not None:
            raise PipelineError(failure.stage, failure.index, failure.exc, failure.meta) from failure.exc
    finally:
        stop.set()
        _drain(q)
        reader.join()
        _settle(pending)


def _settle(pending: deque) -> None:
    """Frames submitted but never collected: let the device finish with them, their errors dropped."""
    while pending:
        _item, result = pending.popleft()
        try:
            result.result()
        except Exception:  # noqa: BLE001 - already unwinding from the error that matters
            pass


def _collect(entry: tuple, ready: deque, times: StageTimes) -> _Failure | None:
    """Wait for a submitted frame's filtered result and queue it for the temporal stage and the hooks."""
    item, pending = entry
    try:
        t0 = time.perf_counter()
        out = pending.result()
        times.wait += time.perf_counter() - t0
    except Exception as exc:
        return _Failure("filter", item.index, exc, item.meta)
    ready.append((item, out, pending))
    return None


def _finish(ready: deque, pending: deque, ahead: int, temporal: Temporal | None, post_hooks: Sequence[PostHook],
            times: StageTimes, kept: Sequence = ()) -> tuple[Item, _Failure | None]:
    """Run the temporal stage (with the raw frames of the next `ahead` items read; then the input put back in
    the `kept` rectangles) and the post hooks on the oldest collected frame."""
    item, out, result = ready.popleft()
    if item.passthrough:
        return item, None
    stage = "temporal"
    try:
        t1 = time.perf_counter()
        if temporal is not None and hasattr(result, "publish_regions"):
            # the frames after it were collected since: the filter's last_regions (a stage with where="render"
            # reads them) are theirs until this frame's are put back
            result.publish_regions()
        spatial = out
        if temporal is not None and ahead:
            later = [it for it, _, _ in ready] + [it for it, _ in pending]
            later = [it.frame for it in itertools.takewhile(lambda it: not it.passthrough, later[:ahead])]
            out = temporal(item.frame, out, item.index, future=later)
            t2 = time.perf_counter()
            times.temporal += t2 - t1
            t1 = t2
        elif temporal is not None:
            out = temporal(item.frame, out, item.index)
            t2 = time.perf_counter()
            times.temporal += t2 - t1
            t1 = t2
        if temporal is not None:
            out = spatial_at_rims(spatial, out)
        if kept:
            out = restore_kept(item.frame, out, kept)
        stage = "post"
        for hook in post_hooks:
            out = hook(out, item.index)
        times.post += time.perf_counter() - t1
    except Exception as exc:
        return item, _Failure(stage, item.index, exc, item.meta)
    return Item(frame=out, meta=item.meta, index=item.index, premultiplied=item.premultiplied), None


class _Writer(threading.Thread):
    """Hands each filtered item to the sink, in order, in its own thread."""

    def __init__(self, q: queue.Queue, sink: Callable[[Item], None], stop: threading.Event,
                 times: StageTimes, on_frame: Callable[[int], None] | None):
        super().__init__(name="mlaa-stream-writer", daemon=True)
        self.q, self.sink, self.stop, self.times, self.on_frame = q, sink, stop, times, on_frame
        self.failure: _Failure | None = None
        self.done = 0

    def run(self) -> None:
        obj = None
        try:
            while True:
                obj = self.q.get()
                if obj is END:
                    return
                t0 = time.perf_counter()
                self.sink(obj)
                self.times.write += time.perf_counter() - t0
                self.done += 1
                self.times.frames = self.done
                if self.on_frame is not None:
                    self.on_frame(self.done)
                if self.stop.is_set():
                    return
        except Exception as exc:
            self.failure = _Failure("write", obj.index, exc, obj.meta)
            self.stop.set()


def run_pipeline(source: Iterable, filt: FrameFilter, sink: Callable[[Item], None], *,
                 in_flight: int = 2, queue_size: int = 4, temporal: Temporal | None = None,
                 post_hooks: Sequence[PostHook] = (), times: StageTimes | None = None,
                 on_frame: Callable[[int], None] | None = None) -> int:
    """Read, filter and write every frame; returns the number written.

    `sink(item)` runs in the writer thread, in frame order. Raises PipelineError (after writing the
    frames before a read/filter/hook failure) or KeyboardInterrupt; no thread is left running.
    """
    times = times if times is not None else StageTimes()
    stop = threading.Event()
    out_q: queue.Queue = queue.Queue(maxsize=max(1, queue_size))
    writer = _Writer(out_q, sink, stop, times, on_frame)
    upstream: PipelineError | None = None
    gen = stream_items(source, filt, in_flight=in_flight, queue_size=queue_size,
                       temporal=temporal, post_hooks=post_hooks, times=times)
    writer.start()
    try:
        try:
            for item in gen:
                if not _put(out_q, item, stop):
                    break  # the writer failed
        except PipelineError as exc:
            upstream = exc  # the frames before it are queued: let the writer finish them
        gen.close()
        _put(out_q, END, stop)  # not put only when the writer has failed and is leaving anyway
        while writer.is_alive():
            writer.join(timeout=_POLL_S)  # a timed join keeps Ctrl-C deliverable
    finally:
        gen.close()
        if writer.is_alive():  # unwinding from KeyboardInterrupt or an unexpected error
            stop.set()
            _drain(out_q)
            out_q.put(END)
            writer.join()
    if writer.failure is not None:
        f = writer.failure
        raise PipelineError(f.stage, f.index, f.exc, f.meta) from f.exc
    if upstream is not None:
        raise upstream
    return writer.done


def filter_video(info: "VideoInfo", writer: "VideoWriter | CvVideoWriter", filt, *, source=None,
                 temporal=None, post_hooks=(), in_flight: int = 2, times=None, on_frame=None) -> int:
    """Decode `info`, filter every frame and encode it with `writer`; returns the frames written.

    A decoding error or a truncated input keeps the frames before it: the output is finished as a
    valid, shorter file (audio cut at its last frame), renamed into place, and the PipelineError
    is raised so the caller reports where the input stopped. Any other error, or Ctrl-C, removes
    the output. `source` replaces the decoder (the OpenCV fallback passes read_video_cv(info)).
    """
    from mlaa_stream.io.video import VideoReadError, read_video

    source = read_video(info) if source is None else source
    try:
        n = run_pipeline(source, filt, lambda item: writer.write(item.frame, item.meta),
                         in_flight=in_flight, temporal=temporal, post_hooks=post_hooks,
                         times=times, on_frame=on_frame)
    except PipelineError as exc:
        if exc.stage == "read" and isinstance(exc.cause, VideoReadError) and writer.frames_written:
            writer.commit(audio_until=writer.last_time)
        else:
            writer.abort()
        raise
    except BaseException:
        writer.abort()
        raise
    writer.commit()
    return n
