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
bit for bit (the spatial filter reads nothing across frames).
"""
from __future__ import annotations

import os
import threading
from dataclasses import dataclass, field
from typing import Callable

from mlaa_stream.io.images import check_complete, image_shape, remove_quietly, stale_temp_files
from mlaa_stream.io.sequence import FilterSet, FrameFile, Report, image_sink, image_source

CHUNK_FRAMES = 16  # frames per task: a few seconds of work for a 1080p frame, enough to hide scheduling


class ClusterJobError(RuntimeError):
    """A chunk failed on the cluster after its retry; the message names the chunk and its frames."""


@dataclass(frozen=True)
class Chunk:
    """Consecutive frames of one job, filtered by one task."""

    index: int
    files: tuple[FrameFile, ...]

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


def plan_chunks(files: list[FrameFile], chunk_frames: int = CHUNK_FRAMES) -> list[Chunk]:
    if chunk_frames < 1:
        raise ValueError(f"chunk_frames: expected >= 1, got {chunk_frames}")
    return [Chunk(k, tuple(files[i:i + chunk_frames])) for k, i in enumerate(range(0, len(files), chunk_frames))]


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
                 like: tuple | None = None) -> ChunkResult:
    """Run on a worker: read, filter and write the chunk's frames. Outputs a previous run of this chunk
    completed are kept (a rerun after a worker died). Raises (and the task is retried) where a sequence
    would stop on one machine."""
    from mlaa_stream.pipeline import PipelineError, run_pipeline

    result = ChunkResult(chunk.index)
    todo = []
    for ff in chunk.files:
        shape = None if overwrite or not os.path.exists(ff.dst) else image_shape(ff.src)
        if shape is not None and check_complete(ff.dst, *shape, decode=False) is None:
            result.skipped.append(ff.dst)
        else:
            todo.append(ff)
    report = Report()
    linear_kwargs = dict(filter_kwargs, linear_input=True)
    filt = FilterSet(_worker_filter(filter_kwargs), lambda: _worker_filter(linear_kwargs))
    try:
        run_pipeline(image_source(todo, report, strict=strict, like=like), filt,
                     image_sink(report, overwrite=True, strict=strict))
    except PipelineError as exc:
        ff = exc.meta[0] if exc.meta else (todo[exc.index] if 0 <= exc.index < len(todo) else None)
        raise ClusterJobError(f"{chunk.label}: {ff.label if ff else f'frame {exc.index}'}: {exc.stage} failed: "
                              f"{exc.cause}") from exc
    result.written, result.failed, result.warnings = report.written, report.failed, report.warnings
    return result


def run_chunks(client, files: list[FrameFile], filter_kwargs: dict, *, overwrite: bool, strict: bool,
               chunk_frames: int = CHUNK_FRAMES, on_frames: Callable[[int], None] | None = None,
               say: Callable[[str], None] | None = None) -> Report:
    """Filter `files` on the cluster behind `client`; returns what happened to each file. Progress:
    `on_frames(done)` after each chunk. Raises ClusterJobError naming the chunk that failed twice."""
    from dask.distributed import as_completed

    say = say or (lambda msg: None)
    report = Report(say=say)
    chunks = plan_chunks(files, chunk_frames)
    like = None
    if strict and files:
        from mlaa_stream.io.images import read_image
        first = read_image(files[0].src)
        like = ((first.pixels.shape, first.pixels.dtype), files[0])
    futures = {client.submit(filter_chunk, c, filter_kwargs, overwrite, strict, like, retries=1, pure=False,
                             key=f"mlaa-chunk-{c.index}-{os.getpid()}-{id(files)}"): c for c in chunks}
    done = 0
    failure: BaseException | None = None
    try:
        for fut in as_completed(futures):
            chunk = futures[fut]
            if fut.status != "finished":
                exc = fut.exception()
                failure = failure or (exc if isinstance(exc, ClusterJobError) else
                                      ClusterJobError(f"{chunk.label}: failed on the cluster: {exc}"))
                say(str(failure if failure is exc else ClusterJobError(f"{chunk.label}: {exc}")))
                continue
            r = fut.result()
            report.written += r.written
            report.skipped += r.skipped
            for msg in r.failed:
                report.fail(msg)
            for msg in r.warnings:
                report.warn(msg)
            done += len(chunk.files)
            if on_frames is not None:
                on_frames(done)
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
                      **filter_kwargs) -> Report:
    """The Python API: filter a folder or a printf frame pattern into `output` (a folder or a pattern) on
    the cluster behind `client` (a dask.distributed.Client you made). `resume` skips complete outputs;
    without it or `overwrite`, an existing output is an error."""
    from mlaa_stream.io.sequence import (expand_pattern, is_pattern, list_folder, plan_images)
    from mlaa_stream.spatial.filter import PRESETS

    kwargs = dict(PRESETS.get(preset or "default", {}), **filter_kwargs)
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
    for d in sorted({os.path.dirname(os.path.abspath(f.dst)) for f in plan}):
        os.makedirs(d, exist_ok=True)
    existing = [f for f in plan if os.path.exists(f.dst)]
    if existing and resume:
        plan = [f for f in plan if f not in existing or check_complete(f.dst, *image_shape(f.src), decode=False)]
    elif existing and not overwrite:
        raise FileExistsError(f"{existing[0].dst}: exists; pass overwrite=True or resume=True")
    return run_chunks(client, plan, kwargs, overwrite=overwrite, strict=strict, chunk_frames=chunk_frames)
