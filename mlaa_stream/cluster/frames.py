"""Folders of images and numbered sequences on a Dask cluster (dask.distributed).

    from dask.distributed import Client
    from mlaa_stream.cluster.frames import filter_on_cluster
    with Client("tcp://scheduler:8786") as client:
        report = filter_on_cluster(client, "shot/%04d.exr", "clean/%04d.exr", preset="default")

The frames are split into chunks of consecutive frames. Each chunk is one task: a worker reads, filters
and writes its frames through the same pipeline as one machine (temporary name, check, rename), with its
own OpenCL device and one Filter per worker process. A task that fails is retried once; a worker that dies
has its chunks run again elsewhere (an output its first run completed is kept, not written twice); the
temporary file a killed worker left behind is removed at the end. Outputs equal the single-machine ones
bit for bit (the spatial filter reads nothing across frames). With the temporal stage (`temporal=`, a
TemporalSpec) each chunk first runs the frames before it through the filter and the stage, unwritten
(warm-up: mlaa_stream/cluster/temporal.py says how many and what equality that gives), and with its
`lookahead` N reads the N frames after its end too (unwritten), as one machine's stage reads them.
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from typing import Callable

from mlaa_stream.io.images import check_complete, image_shape, remove_quietly, stale_temp_files
from mlaa_stream.io.sequence import (FilterSet, FrameFile, Report, consecutive_ahead, frame_number, image_sink,
                                     image_source, is_linear)

CHUNK_FRAMES = 16  # frames per task: a few seconds of work for a 1080p frame, enough to hide scheduling


class ClusterJobError(RuntimeError):
    """A chunk failed on the cluster after its retry; the message names the chunk and its frames."""


@dataclass(frozen=True)
class Chunk:
    """Consecutive frames of one job, filtered by one task."""

    index: int
    files: tuple[FrameFile, ...]
    warmup: tuple[FrameFile, ...] = ()  # frames before it, the last ones run through the temporal stage unwritten
    starts_stream: bool = True  # `warmup` begins at the job's first frame
    ahead: tuple[FrameFile, ...] = ()   # frames after it, read for the temporal stage's look-ahead, unwritten

    @property
    def label(self) -> str:
        a, b = self.files[0], self.files[-1]
        if a.number is not None:
            return f"chunk {self.index} (frames {a.number}-{b.number})"
        return f"chunk {self.index} ({os.path.basename(a.src)} .. {os.path.basename(b.src)})"


@dataclass
class ChunkResult:
    index: int
    written: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # complete from an earlier run of this chunk
    failed: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)


def plan_chunks(files: list[FrameFile], chunk_frames: int = CHUNK_FRAMES, warmup: int = 0,
                ahead: int = 0) -> list[Chunk]:
    """Consecutive chunks of `chunk_frames`, each with up to `warmup` frames before it and `ahead` after it."""
    if chunk_frames < 1:
        raise ValueError(f"chunk_frames: expected >= 1, got {chunk_frames}")
    return [Chunk(k, tuple(files[i:i + chunk_frames]), tuple(files[max(0, i - warmup):i]), i <= warmup,
                  tuple(files[i + chunk_frames:i + chunk_frames + ahead]))
            for k, i in enumerate(range(0, len(files), chunk_frames))]


_worker_filters: dict[tuple, object] = {}
_worker_lock = threading.Lock()


def _worker_filter(kwargs: dict):
    """One Filter per worker process and option set, kept between tasks (kernels built once)."""
    from mlaa_stream.spatial.fast_filter import FastFilter
    from mlaa_stream.spatial.filter import Filter

    key = tuple(sorted(kwargs.items()))
    with _worker_lock:
        if key not in _worker_filters:  # the fast preset without host copies on CPU devices
            _worker_filters[key] = (FastFilter if kwargs.get("fast") else Filter)(bgr=False, **kwargs)
        return _worker_filters[key]


def filter_chunk(chunk: Chunk, filter_kwargs: dict, overwrite: bool, strict: bool,
                 like: tuple | None = None, temporal=None, jpeg_quality: int | None = None,
                 transfer: str = "auto") -> ChunkResult:
    """Run on a worker: read, filter and write the chunk's frames. Outputs a previous run of this chunk
    completed are kept (a rerun after a worker died). Raises (and the task is retried) where a sequence
    would stop on one machine. `temporal` (a TemporalSpec): a new stage runs over the chunk's warm-up
    frames and then all its frames (kept outputs too: the history must not skip them)."""
    from mlaa_stream.pipeline import PipelineError, run_pipeline

    result = ChunkResult(chunk.index)
    todo = []
    for ff in chunk.files:
        shape = None if overwrite or not os.path.exists(ff.dst) else image_shape(ff.src)
        if shape is not None and check_complete(ff.dst, *shape, decode=False) is None:
            result.skipped.append(ff.dst)
        else:
            todo.append(ff)
    encoded = _worker_filter(filter_kwargs)
    filt = FilterSet(encoded, lambda options: _worker_filter(dict(filter_kwargs, **options)), transfer)
    w = temporal.warmup if temporal is not None else 0
    while True:
        report = Report()
        warmup = chunk.warmup[max(0, len(chunk.warmup) - w):] if w else ()
        sink = image_sink(report, overwrite=True, strict=strict, jpeg_quality=jpeg_quality)
        stage = hook = None
        read = todo
        if temporal is not None:
            from mlaa_stream.cluster.temporal import WarmedStage
            stage = WarmedStage(temporal.stage(encoded), temporal.warmup, can_extend=w < len(chunk.warmup),
                                from_start=len(warmup) == len(chunk.warmup) and chunk.starts_stream)
            read = list(warmup) + list(chunk.files) + list(chunk.ahead)
            hook, source, sink = _with_temporal(stage, read, set(warmup), report, strict, like, set(todo), sink)
        else:
            source = image_source(todo, report, strict=strict, like=like)
        try:
            run_pipeline(source, filt, sink, temporal=hook)
            break
        except PipelineError as exc:
            from mlaa_stream.cluster.temporal import ShortWarmup
            if isinstance(exc.cause, ShortWarmup):  # held frames before the chunk: read further back
                w = min(len(chunk.warmup), w + max(exc.cause.missing, w))
                continue
            ff = exc.meta[0] if exc.meta else (read[exc.index] if 0 <= exc.index < len(read) else None)
            raise ClusterJobError(f"{chunk.label}: {ff.label if ff else f'frame {exc.index}'}: {exc.stage} failed: "
                                  f"{exc.cause}") from exc
        finally:
            if stage is not None:
                stage.close()
    if stage is not None and stage.short:
        report.warn(f"{chunk.label}: the {len(warmup)} frames before it hold {stage.changes} changes (held "
                    f"frames), {temporal.warmup} are needed: its first outputs may differ from one machine's")
    if warmup:  # an unreadable warm-up frame is its own chunk's failure
        report.failed = [m for m in report.failed if not any(ff.src in m for ff in warmup)]
    result.written, result.failed, result.warnings = report.written, report.failed, report.warnings
    return result


def _with_temporal(stage, files: list[FrameFile], warm: set, report: Report, strict: bool, like, write: set,
                   sink):
    """(temporal hook, source, sink) for a chunk read with its warm-up (`warm`): the stage (a WarmedStage)
    is called with the frame number (a folder: the file's position in name order), as on one machine
    (cli/filter_jobs.SequenceTemporal), and only the frames in `write` reach the sink."""
    read_order: dict[int, FrameFile] = {}
    read_linear: dict[int, bool] = {}   # position -> linear light (the stage's colour space), as on one machine

    def source():
        inner = image_source(files, report, strict=strict, like=like)
        try:
            for position, item in enumerate(inner):
                if not item.passthrough:   # a file copied unchanged never reaches the stage
                    read_order[position] = item.meta[0]
                    read_linear[position] = is_linear(item.meta[1])
                yield item
        finally:
            inner.close()

    def hook(frame_in, frame_out, index: int, future=()):
        ff = read_order.get(index)
        number = frame_number(read_order, index)
        ahead = consecutive_ahead(read_order, index, future)   # as on one machine
        read_order.pop(index, None)
        stage.stage.set_linear_input(read_linear.pop(index, False))
        return stage(frame_in, frame_out, number, ff in warm, future=ahead)
    hook.lookahead = getattr(stage, "lookahead", 0)

    def only_written(item) -> None:
        if item.meta[0] in write:
            sink(item)

    return hook, source(), only_written


def run_chunks(client, files: list[FrameFile], filter_kwargs: dict, *, overwrite: bool, strict: bool,
               chunk_frames: int = CHUNK_FRAMES, on_frames: Callable[[int], None] | None = None,
               say: Callable[[str], None] | None = None, temporal=None,
               done: frozenset[str] = frozenset(), jpeg_quality: int | None = None,
               caution: Callable[[str], None] | None = None, transfer: str = "auto") -> Report:
    """Filter `files` on the cluster behind `client`; returns what happened to each file. Progress:
    `on_frames(done)` after each chunk; failures are said through `say`, warnings through `caution` (else `say`).
    Raises ClusterJobError naming the chunk that failed twice.
    `temporal`: a TemporalSpec (mlaa_stream/cluster/temporal.py), or None for the spatial filter only.
    `transfer`: --transfer (io/sequence.py image_transfer's choice).
    `done`: outputs known complete (--resume with the temporal stage: `files` is then the whole job, so that the
    chunks are those of the first run, each with its warm-up and look-ahead frames; a chunk whose outputs are all
    done is not run, and the others write only what is missing, as a chunk rerun after its worker died does)."""
    from dask.distributed import as_completed

    say = say or (lambda msg: None)
    report = Report(say=say, caution=caution or say)
    from mlaa_stream.cluster.temporal import MAX_WARMUP_FACTOR
    chunks = plan_chunks(files, chunk_frames, MAX_WARMUP_FACTOR * temporal.warmup if temporal is not None else 0,
                         temporal.lookahead if temporal is not None else 0)
    chunks = [c for c in chunks if any(ff.dst not in done for ff in c.files)]
    like = None
    if strict and files:
        from mlaa_stream.io.images import ImageReadError, read_image
        try:
            first = read_image(files[0].src)   # the size and type every chunk's frames must have
        except ImageReadError as exc:   # a damaged first frame: the job's error, not a traceback (--cluster)
            raise ClusterJobError(f"{files[0].label}: read failed: {exc}") from exc
        like = ((first.pixels.shape, first.pixels.dtype), files[0])
    futures = {client.submit(filter_chunk, c, filter_kwargs, overwrite, strict, like, temporal, jpeg_quality,
                             transfer, retries=1, pure=False,
                             key=f"mlaa-chunk-{c.index}-{os.getpid()}-{id(files)}"): c for c in chunks}
    frames = 0
    failure: BaseException | None = None
    try:
        for fut in as_completed(futures):
            chunk = futures[fut]
            if fut.status != "finished":
                exc = fut.exception()
                # a ClusterJobError from filter_chunk names its chunk already: prefixing it again doubled it
                err = exc if isinstance(exc, ClusterJobError) else \
                    ClusterJobError(f"{chunk.label}: failed on the cluster: {exc}")
                if failure is None:
                    failure = err   # raised at the end, where the caller reports it: said here too, it came twice
                else:
                    say(str(err))   # every further failing chunk, once
                continue
            r = fut.result()
            report.written += r.written
            report.skipped += [dst for dst in r.skipped if dst not in done]   # complete from this job's own runs
            for msg in r.failed:
                report.fail(msg)
            for msg in r.warnings:
                report.note(msg)
            frames += sum(ff.dst not in done for ff in chunk.files)
            if on_frames is not None:
                on_frames(frames)
    finally:
        for fut in futures:
            fut.cancel()
        for folder in sorted({os.path.dirname(os.path.abspath(f.dst)) for f in files}):
            for path in stale_temp_files(folder):  # half-written by a worker that was killed
                remove_quietly(path)
    if failure is not None:
        raise failure
    return report


def filter_on_cluster(client, input_path: str, output: str, *, preset: str | None = None,
                      overwrite: bool = False, resume: bool = False, chunk_frames: int = CHUNK_FRAMES,
                      temporal=None, **filter_kwargs) -> Report:
    """The Python API: filter a folder or a printf frame pattern into `output` (a folder or a pattern) on
    the cluster behind `client` (a dask.distributed.Client you made). `resume` skips complete outputs;
    without it or `overwrite`, an existing output is an error. `temporal`: a TemporalSpec
    (mlaa_stream.cluster.temporal) turns the temporal stage on, with a warm-up per chunk."""
    from mlaa_stream.io.sequence import (expand_pattern, is_pattern, list_folder, output_over_input, plan_images)
    from mlaa_stream.spatial.filter import PRESETS
    from mlaa_stream.spatial.keep import keep_rects

    kwargs = dict(PRESETS.get(preset or "default", {}), **filter_kwargs)
    if "keep" in kwargs:  # KeepRects in a tuple: the workers key their filters by the options (_worker_filter)
        kwargs["keep"] = keep_rects(kwargs["keep"])
    strict = is_pattern(input_path)
    if strict:
        found, _missing = expand_pattern(input_path)
        numbers, srcs = [n for n, _ in found], [p for _, p in found]
    else:
        srcs, _others = list_folder(input_path)
        numbers = None
    if not srcs:
        raise ValueError(f"{input_path}: expected images, found none")
    out = output if is_pattern(output) else os.path.join(output, "")
    plan = plan_images(srcs, out, numbers)
    clash = output_over_input(plan)
    if clash is not None:   # overwrite=True replaces outputs, never an input
        raise ValueError(clash)
    for d in sorted({os.path.dirname(os.path.abspath(f.dst)) for f in plan}):
        os.makedirs(d, exist_ok=True)
    existing = [f for f in plan if os.path.exists(f.dst)]
    done: frozenset[str] = frozenset()
    if existing and resume:
        def complete(f: FrameFile) -> bool:
            # an input that no longer opens has no size to hold its output to: kept, as the command line keeps it
            # (ImageJob._keep_complete); `*image_shape(...)` of None was a TypeError
            shape = image_shape(f.src)
            return shape is None or check_complete(f.dst, *shape, decode=False) is None
        done = frozenset(f.dst for f in existing if complete(f))
        if temporal is None:  # the temporal stage reads the complete ones too (run_chunks' `done`)
            plan, done = [f for f in plan if f.dst not in done], frozenset()
    elif existing and not overwrite:
        raise FileExistsError(f"{existing[0].dst}: exists; pass overwrite=True or resume=True")
    return run_chunks(client, plan, kwargs, overwrite=overwrite, strict=strict, chunk_frames=chunk_frames,
                      temporal=temporal, done=done)
