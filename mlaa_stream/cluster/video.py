"""A video on a Dask cluster: the frames split into time ranges, each filtered and encoded by a worker into
a segment file, the segments joined in order without re-encoding, the audio and subtitle streams (and the
tags and rotation) copied once from the source.

    with Client(...) as client:
        frames = filter_video_on_cluster(client, "in.mkv", "out.mkv", codec="ffv1")

A range starts at any frame: its worker seeks to the keyframe before it and decodes up to it (read_video's
`start`), so ranges need no keyframe alignment; every frame falls in exactly one range (by its timestamp,
to half a frame). Segments are encoded without B-frames (x264/x265: `bf=0`), so that the joined stream's
decoding order stays monotonic across segment boundaries. Containers: whatever PyAV writes and can
remux (MKV, MP4, MOV, NUT); the codec must be one whose packets stand alone after a keyframe (all FFmpeg
video encoders used here). With the temporal stage (`temporal=`, a TemporalSpec) a worker starts its
decoding `warmup` frames before its range and runs them through the filter and the stage unwritten
(mlaa_stream/cluster/temporal.py).
"""
from __future__ import annotations

import heapq
import math
import os
from dataclasses import dataclass
from fractions import Fraction

from mlaa_stream.io.images import publish, remove_quietly, stale_temp_files, temp_path_for

SEGMENT_SECONDS = 2.0  # default time range per task


class ClusterVideoError(RuntimeError):
    """A segment failed on the cluster after its retry; the message names the segment and its frames."""


@dataclass(frozen=True)
class Segment:
    index: int
    start: float  # seconds, source time
    end: float | None  # None: to the end of the source
    path: str  # the segment file (a temporary name beside the output)

    def label(self, fps: Fraction | None) -> str:
        rate = float(fps or 25)
        first = int(round(self.start * rate))
        last = "end" if self.end is None else str(int(round(self.end * rate)) - 1)
        return f"segment {self.index} (frames {first}-{last})"


def plan_segments(duration: float, fps: Fraction | None, output: str,
                  seconds: float = SEGMENT_SECONDS) -> list[Segment]:
    """Time ranges of whole frames covering [0, duration): the last one runs to the end."""
    frame = 1.0 / float(fps or 25)
    per = max(1, int(round(seconds / frame)))  # frames per segment
    n = max(1, math.ceil(duration / (per * frame) - 1e-9))
    return [Segment(k, k * per * frame, None if k == n - 1 else (k + 1) * per * frame,
                    temp_path_for(os.path.splitext(output)[0] + f".seg{k:04d}.mkv")) for k in range(n)]


def encode_segment(source: str, segment: Segment, filter_kwargs: dict, codec: str | None, crf: int,
                   encoder_preset: str, pix_fmt: str | None, temporal=None, deinterlace: str = "off") -> int:
    """Run on a worker: decode the segment's frames, filter them, encode them into segment.path (video only,
    at the source's timestamps). Returns the frames written. `temporal` (a TemporalSpec): a new
    stage runs over the `temporal.warmup` frames before the segment (decoded, filtered, not written; more
    where frames are held: WarmedStage) and then over the segment's. `deinterlace`: read_video's (auto / on / off);
    the frames before the segment, decoded from its keyframe, are its first frame's field neighbours."""
    from mlaa_stream.cluster.frames import _worker_filter
    from mlaa_stream.cluster.temporal import MAX_WARMUP_FACTOR, ShortWarmup, WarmedStage
    from mlaa_stream.io.video import VideoWriter, probe_video
    from mlaa_stream.pipeline import PipelineError

    info = probe_video(source)
    filt = _worker_filter(filter_kwargs)
    frame = 1.0 / float(info.fps or 25)
    w = temporal.warmup if temporal is not None else 0
    while True:
        start = max(0.0, segment.start - w * frame)
        stage = None
        if temporal is not None:
            stage = WarmedStage(temporal.stage(filt), temporal.warmup, from_start=start < frame / 2,
                                can_extend=start >= frame / 2 and w < MAX_WARMUP_FACTOR * temporal.warmup)
        # the source's own timestamps (offset 0): shifted by segment.start, a variable-rate frame just before the
        # range's nominal start (it belongs here by half a frame) got a negative time, which the muxer moved to 0
        # and every later frame of the segment with it; join_segments copies them unshifted
        writer = VideoWriter(segment.path, info, codec=codec, crf=crf, preset=encoder_preset, pix_fmt=pix_fmt,
                             audio="none", overwrite=True, container_format="matroska",
                             extra_options={"bf": "0"}, copy_extras=False)
        try:
            n = _run_segment(info, segment, start if start >= frame / 2 else None, filt, writer, stage, deinterlace)
            writer.commit()
            return n
        except PipelineError as exc:
            writer.abort()
            if isinstance(exc.cause, ShortWarmup):  # held frames before the segment: decode from further back
                w += max(exc.cause.missing, w)
                continue
            raise
        except BaseException:
            writer.abort()
            raise
        finally:
            if stage is not None:
                stage.close()


def _run_segment(info, segment: Segment, start: float | None, filt, writer, stage, deinterlace: str = "off") -> int:
    """Decode from `start`, filter, run the temporal stage (if any) and write the frames of `segment`
    (those before it are its warm-up). Returns the frames written."""
    from mlaa_stream.io.video import read_video
    from mlaa_stream.pipeline import run_pipeline

    first = segment.start - 0.5 / float(info.fps or 25)  # a frame belongs to the range by its timestamp
    warm: dict[int, bool] = {}
    written = [0]

    def is_warm(item) -> bool:
        ft = item.meta
        return ft.pts is not None and bool(ft.time_base) and float(ft.pts * ft.time_base) < first

    frame = 1.0 / float(info.fps or 25)
    ahead = getattr(stage, "lookahead", 0) if stage is not None else 0
    last = None if segment.end is None else segment.end - 0.5 * frame   # frames from here on: look-ahead only

    def is_ahead(item) -> bool:
        ft = item.meta
        return last is not None and ft.pts is not None and bool(ft.time_base) and float(ft.pts * ft.time_base) >= last

    def source():
        # the stage's look-ahead reads the N frames after the segment too (not written)
        inner = read_video(info, start=start, end=segment.end if segment.end is None or not ahead
                           else segment.end + ahead * frame, deinterlace=deinterlace)
        try:
            for position, item in enumerate(inner):
                warm[position] = is_warm(item)
                yield item
        finally:
            inner.close()

    def hook(frame_in, frame_out, index: int, future=()):
        return stage(frame_in, frame_out, index, warm.pop(index, False), future=future)
    hook.lookahead = ahead

    def sink(item) -> None:
        if not is_warm(item) and not is_ahead(item):
            writer.write(item.frame, item.meta)
            written[0] += 1

    run_pipeline(source(), filt, sink, temporal=hook if stage is not None else None)
    return written[0]


def join_segments(segments: list[Segment], info, output: str, *, overwrite: bool, audio: bool = True) -> list[str]:
    """Concatenate the segments' video packets in order (at their source timestamps) into `output`,
    with the source's audio and subtitle streams (unless `audio` is False), tags, rotation, chapters and
    attachments; written under a temporary name. Returns warnings naming what was not kept."""
    import av

    from mlaa_stream.io.video import _copy_tags, copy_chapters_and_attachments

    tmp = temp_path_for(output)
    first = av.open(segments[0].path)
    src = av.open(info.path)
    try:
        out = av.open(tmp, "w")
        vin = first.streams.video[0]
        vout = out.add_stream_from_template(vin)
        if info.rotation:
            vout.set_display_rotation(info.rotation)
        copies = {}
        _copy_tags(src.metadata, out.metadata)
        _copy_tags(src.streams.video[0].metadata, vout.metadata)
        _kept, warnings = copy_chapters_and_attachments(src, out)
        if audio:
            for s in src.streams:
                if s.type in ("audio", "subtitle"):
                    o = out.add_stream_from_template(s)
                    _copy_tags(s.metadata, o.metadata)
                    copies[s.index] = o
        out.start_encoding()

        def video_packets():
            for seg in segments:
                with av.open(seg.path) as c:
                    for pkt in c.demux(c.streams.video[0]):   # in source time already (encode_segment)
                        if pkt.dts is None:
                            continue
                        yield float(pkt.dts * pkt.time_base), pkt

        def copied_packets():
            if not copies:
                return
            for pkt in src.demux(*[src.streams[i] for i in copies]):
                if pkt.dts is None:
                    continue
                yield float(pkt.dts * pkt.time_base), pkt

        for t, pkt in heapq.merge(video_packets(), copied_packets(), key=lambda tp: tp[0]):
            pkt.stream = vout if pkt.stream.type == "video" else copies[pkt.stream.index]
            out.mux(pkt)
        out.close()
        publish(tmp, output, overwrite)
    except BaseException:
        remove_quietly(tmp)
        raise
    finally:
        first.close()
        src.close()
    return [f"{output}: {w}" for w in warnings]


def filter_video_on_cluster(client, source: str, output: str, *, preset: str | None = None,
                            codec: str | None = None, crf: int = 18, encoder_preset: str = "veryfast",
                            pix_fmt: str | None = None, overwrite: bool = False, audio: bool = True,
                            segment_seconds: float = SEGMENT_SECONDS, on_frames=None, temporal=None,
                            warn=None, deinterlace: str = "off", **filter_kwargs) -> int:
    """Filter the video `source` into `output` on the cluster behind `client`; returns the frames written.
    `temporal`: a TemporalSpec (mlaa_stream.cluster.temporal) turns the temporal stage on, with a warm-up
    per segment. `warn(message)`: what of the source was not kept (chapters, attachments). `deinterlace`: auto / on /
    off, as read_video takes it (each worker decides for its segment as read_video does).
    Raises ClusterVideoError naming the segment that failed twice; nothing is left under the output's name
    or as a segment file on failure."""
    from dask.distributed import as_completed

    from mlaa_stream.io.video import probe_video
    from mlaa_stream.spatial.filter import PRESETS
    from mlaa_stream.spatial.keep import keep_rects

    if os.path.exists(output) and not overwrite:
        raise FileExistsError(f"{output}: exists; pass overwrite=True")
    info = probe_video(source)
    if not info.duration:
        raise ClusterVideoError(f"{source}: the container declares no duration: the video cannot be split")
    kwargs = dict(PRESETS.get(preset or "default", {}), **filter_kwargs)
    if "keep" in kwargs:  # KeepRects in a tuple: the workers key their filters by the options (frames._worker_filter)
        kwargs["keep"] = keep_rects(kwargs["keep"])
    segments = plan_segments(info.duration, info.fps, output, segment_seconds)
    futures = {client.submit(encode_segment, source, seg, kwargs, codec, crf, encoder_preset, pix_fmt, temporal,
                             deinterlace, retries=1, pure=False,
                             key=f"mlaa-seg-{seg.index}-{os.getpid()}-{id(segments)}"): seg
               for seg in segments}
    frames, failure, counts = 0, None, {}
    try:
        for fut in as_completed(futures):
            seg = futures[fut]
            if fut.status != "finished":
                failure = failure or ClusterVideoError(f"{source}: {seg.label(info.fps)} failed on the cluster: "
                                                       f"{fut.exception()}")
                continue
            counts[seg.index] = fut.result()
            frames += counts[seg.index]
            if on_frames is not None:
                on_frames(frames)
        if failure is not None:
            raise failure
        # a last range past the last frame (the container's duration counts the audio too) holds nothing
        for w in join_segments([s for s in segments if counts.get(s.index)], info, output, overwrite=overwrite,
                               audio=audio):
            (warn or (lambda msg: None))(w)
    finally:
        for fut in futures:
            fut.cancel()
        for seg in segments:
            remove_quietly(seg.path)
        for path in stale_temp_files(os.path.dirname(os.path.abspath(output))):
            remove_quietly(path)  # segments of workers that were killed
    return frames
