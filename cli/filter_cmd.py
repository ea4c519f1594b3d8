"""`mlaa-stream INPUT -o OUTPUT`: filter an image, a folder of images, a frame sequence or a video."""
from __future__ import annotations

import errno
import os
import signal
import sys
import tempfile
import time
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Iterator

import click

from mlaa_stream.spatial.filter import DEFAULT_THRESHOLDS, PRESET_USES, PRESETS
from mlaa_stream.spatial.fast_filter import FastFilter
from mlaa_stream.device.transfer import TRANSFER_CHOICES, TRANSFER_NAMES
from mlaa_stream.cli.options import configure_logging, device_option, verbosity_options
from mlaa_stream.cli.stats_spool import StatsSpool
from mlaa_stream.temporal.methods import RING_FRAMES

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NO_DEVICE, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
# The reader of standard output went away (`-o - | head`): the status a shell reports for a process SIGPIPE ended,
# as for Unix tools (Python ignores SIGPIPE, so the write fails with EPIPE instead of ending the process)
EXIT_BROKEN_PIPE = 128 + getattr(signal, "SIGPIPE", 13)

EPILOG = """\b
Examples:
  mlaa-stream shot.png -o clean.png                  one image (format from the name)
  mlaa-stream renders/ -o clean/                     every image of a folder, same names
  mlaa-stream 'shot/%04d.exr' --frames 1001-1100 -o clean/   a numbered sequence
  mlaa-stream 'shot/%04d.exr' -o 'clean/%04d.exr' --resume  go on after an interruption
  mlaa-stream in.mp4 -o out.mp4                      H.264, CRF 18, preset veryfast, audio copied
  mlaa-stream in.mov -o mid.mkv --codec ffv1         lossless intermediate (also: libx264rgb --crf 0)
  mlaa-stream in.mp4 -o out.mp4 --preset soft --metric luma --threshold 0.08
  mlaa-stream in.mp4 -o 'frames/%04d.png'            a video to images; 'shot/%04d.png' -o out.mp4 back
  mlaa-stream in.mkv --start 1:30 --end 2:00 -o clip.mkv   trim (seconds, h:m:s or frames like 300f)
  vspipe -c y4m script.vpy - | mlaa-stream - -o - -f y4m | ffmpeg -i - out.mkv   pipes

\b
Images and sequences go through OpenImageIO: bit depth (8/16-bit, half, float), channels, alpha
(passed through unchanged), metadata and a JPEG's quality are kept; palette PNGs come out as RGB(A). EXRs tagged
linear (and untagged float images) are taken as linear light, others as sRGB-encoded. Linear light is
judged at the power of two of exposure that puts its 90th percentile near white, whatever exposure or
units the renderer wrote (the output keeps the input's; TSS too). Linear light
written to a format of display values (PNG, JPEG) is encoded to sRGB, clipped to 0-1, and EXR's
premultiplied alpha written to a format of straight alpha (PNG) is divided out. An EXR without colour
channels (depth, normals, positions, motion vectors: no R, G, B or Y of its own or of a layer) is copied
unchanged, said in a warning; it counts as written, has no --stats row, and is no failure. In a folder,
files that are not images by their extension are skipped with a warning; a file that cannot be
read or written is reported and the others are still processed. A sequence (%04d pattern) must keep
one size, channel count and sample type; the first frame that differs stops it. Gaps in the
numbering are reported. Every output is written under a temporary name beside it, checked (it
reopens and decodes to the end) and renamed: --resume skips an existing output only when it is
complete and writes an incomplete one again; with --temporal on a sequence it first runs the frames
just before the first one to write through the temporal stage (its history, outputs not written).
NaN and infinite samples pass through unchanged.

\b
Video goes through PyAV (FFmpeg): frame rate, timestamps, resolution, pixel aspect ratio, colour
tags, HDR10 mastering display and light levels (with libx265) and audio are kept; a source with more
than 8 bits per sample stays 10/12/16-bit where the codec allows it. An interlaced source (its stream's
field order, or its frames, say so) is deinterlaced with bwdif (yadif where FFmpeg lacks it) before the
filter, one progressive frame per frame at the same timestamps, and said once (--deinterlace). If the
input is truncated or corrupt, the frames that decode are filtered and the output is kept as a
valid shorter file; the exit code is 1 and the message says at which frame decoding stopped.

\b
Exit codes: 0 all done; 1 some inputs failed (the others were processed); 2 usage error
(nothing done: bad option, missing input, output would overwrite); 3 no OpenCL device;
130 interrupted (Ctrl-C), 143 terminated (SIGTERM), 129 hung up (SIGHUP): outputs in progress
are removed, complete ones kept; --resume goes on from there. 141: standard output's reader
went away (-o - | head), stopped without a message, as Unix tools do.
"""


class Console:
    """Messages on stderr, prefixed; warnings and details follow -q / -v."""

    def __init__(self, verbose: int, quiet: bool):
        self.verbose, self.quiet = verbose, quiet

    def error(self, msg: str) -> None:
        click.echo(f"mlaa-stream: error: {msg}", err=True)

    def warn(self, msg: str) -> None:
        if not self.quiet:
            click.echo(f"mlaa-stream: warning: {msg}", err=True)

    def info(self, msg: str) -> None:
        if self.verbose and not self.quiet:
            click.echo(f"mlaa-stream: {msg}", err=True)

    def note(self, msg: str) -> None:
        """Something done to the input that the user should know of (not a fault): shown unless -q."""
        if not self.quiet:
            click.echo(f"mlaa-stream: {msg}", err=True)


def _warn_unseen_gpu(filt, device: str | None, con: Console) -> None:
    """The default device is a CPU while a GPU's OpenCL driver sits on the machine unregistered (a GPU container
    without its ICD file): say so once, with the fix (mlaa_stream/device/drivers.py)."""
    import pyopencl as cl

    from mlaa_stream.device.context import DEVICE_ENV
    from mlaa_stream.device.drivers import unregistered_gpu_drivers
    if device or os.environ.get(DEVICE_ENV) or not filt.context.device.type & cl.device_type.CPU:
        return
    for driver in unregistered_gpu_drivers():
        con.warn(f"running on the CPU: {driver.hint()}")


def deinterlace_note(con: Console, input_path: str):
    """What read_video's on_deinterlace calls, once, when it makes the input progressive: says so, and how not to."""
    from mlaa_stream.io.deinterlace import FORCED

    label = "standard input" if input_path == "-" else input_path

    def note(name: str, why: str) -> None:
        if why == FORCED:
            con.note(f"{label}: deinterlaced with {name} (--deinterlace on; the stream does not say it is interlaced)")
        else:
            con.note(f"{label}: interlaced ({why}): deinterlaced with {name}; --deinterlace off to keep the fields")
    return note


def is_broken_pipe(exc: BaseException | None) -> bool:
    """True when `exc` is, or was caused by, a write to a pipe whose reader has gone (EPIPE): Python's
    BrokenPipeError, PyAV's (an FFmpegError that is one too), or either inside a PipelineError or VideoError."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno == errno.EPIPE:
            return True
        exc = getattr(exc, "cause", None) or exc.__cause__ or exc.__context__   # PipelineError keeps it in .cause
    return False


def _stdout_gone() -> int:
    """Standard output's reader went away: nothing more can reach it, and Python's last flush of it at exit would
    print 'Exception ignored ... BrokenPipeError'; it is pointed at /dev/null instead. Returns EXIT_BROKEN_PIPE."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, sys.stdout.fileno())
        finally:
            os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no file descriptor (a test runner's stdout): nothing to flush
        pass
    return EXIT_BROKEN_PIPE


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP arrived: unwinds every stage as Ctrl-C does (outputs in progress removed)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextmanager
def stop_signals_as_interrupts() -> Iterator[None]:
    """SIGTERM (timeout, systemd, docker, render-farm managers) and SIGHUP raise Terminated in the main
    thread for as long as the command runs; the previous handlers come back afterwards."""
    wanted = [getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)]
    previous = {}

    def handler(signum, frame):
        raise Terminated(signum)

    try:
        for sig in wanted:
            previous[sig] = signal.signal(sig, handler)
    except ValueError:  # not the main thread (e.g. called from a worker): signals stay as they are
        pass
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


class Usage(Exception):
    """Refused before doing anything (exit 2)."""


class Failed(Exception):
    """The input cannot be processed at all (exit 1)."""


def _filter_kwargs(ctx: click.Context, preset: str | None, threshold, metric, display_space,
                   reconstruct, bridge=None) -> dict:
    """The preset's settings, overridden by options given on the command line."""
    kwargs = dict(PRESETS.get(preset or "default", {}))
    if threshold is not None:
        kwargs["threshold"] = threshold
    if metric is not None:
        kwargs["metric"] = metric
    if ctx.get_parameter_source("display_space") == click.core.ParameterSource.COMMANDLINE:
        kwargs["linear"] = not display_space
    if reconstruct is not None:
        kwargs["reconstruct"] = reconstruct
    if bridge is not None:
        kwargs["bridge"] = bridge
    return kwargs


def video_transfer(info, choice: str, opencv: bool = False) -> str | None:
    """The HDR transfer a video's codes are filtered through (device/transfer.py): --transfer's `choice`, or for
    "auto" the stream's colour tags (HDR10's PQ, HLG; OpenCV's decoder does not say what its frames code)."""
    from mlaa_stream.device.transfer import FFMPEG_TRC
    if choice == "auto":
        return None if opencv else FFMPEG_TRC.get(info.colour.get("color_trc"))
    return None if choice == "sdr" else choice


def _check_writable(folder: str) -> None:
    """Create and remove a file in `folder`: the only test that holds for root, ACLs, read-only mounts."""
    try:
        with tempfile.NamedTemporaryFile(dir=folder, prefix=".mlaa-tmp-probe"):
            pass
    except OSError as exc:
        raise OSError(exc.errno, f"{folder}: cannot write in this folder ({exc.strerror})") from exc


def video_trim(opts: dict, info) -> tuple[float | None, float | None]:
    """--start/--end of a video input in seconds (None: not given); refused when empty or backwards."""
    from mlaa_stream.io.video import parse_time

    try:
        start = parse_time(opts["start"], info.fps) if opts.get("start") is not None else None
        end = parse_time(opts["end"], info.fps) if opts.get("end") is not None else None
    except ValueError as exc:
        raise Usage(f"--start/--end: {exc}") from exc
    if start is not None and end is not None and end <= start:
        raise Usage(f"--end ({opts['end']}) must come after --start ({opts['start']})")
    if opts["video_backend"] == "opencv" and (start or end is not None):
        raise Usage("--start/--end need the pyav video backend")
    return start, end


def _load_post_hooks(overlay: str | None, device: str | None) -> list:
    """The --overlay hook: our frames are RGB (decoded video, OpenImageIO), not cv2's BGR."""
    if overlay is None:
        return []
    try:
        from mlaa_stream.overlay.grlaa import load_overlay
    except ImportError as exc:
        raise Usage(f"--overlay: this build has no overlay support ({exc})") from exc
    try:
        return [load_overlay(overlay, bgr=False, device=device)]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise Usage(f"--overlay {overlay}: expected JSON/GeoJSON polylines, got: {exc}") from exc


def _kind_of(path: str) -> str:
    """'pattern', 'folder', 'video' or 'image' by name; an unknown extension is tried as both."""
    from mlaa_stream.io.images import is_image_path
    from mlaa_stream.io.sequence import is_pattern
    from mlaa_stream.io.video import is_video_path

    if path == "-":
        return "video"  # standard input: a stream FFmpeg can read without seeking (y4m, NUT, MKV, TS)
    if is_pattern(path) and not os.path.exists(path):
        return "pattern"
    if not os.path.exists(path):
        raise Usage(f"{path}: no such file or directory")
    if os.path.isdir(path):
        return "folder"
    if is_video_path(path):
        return "video"
    if is_image_path(path):
        return "image"
    import OpenImageIO as oiio

    inp = oiio.ImageInput.open(path)
    if inp is not None:
        inp.close()
        return "image"
    return "video"  # probe_video says so if it is not one either


def _warn_unused_options(ctx: click.Context, con: Console, kind: str, job: type) -> None:
    """Options given on the command line (not defaults) that this job has no use for: a warning each, not an
    error (--rate with a video input, the encoder's, container's and audio options with images out, --audio
    copy/aac and --deinterlace with images in)."""
    from mlaa_stream.cli.convert_jobs import SequenceToVideoJob, VideoToImagesJob

    def given(name: str) -> bool:
        return ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE

    if given("rate") and job is not SequenceToVideoJob:
        why = "a video keeps its own frame rate" if job is _VideoJob else "images have no frame rate"
        con.warn(f"--rate has no effect here: it sets the frame rate of a video made from images; {why}")
    if given("deinterlace") and kind != "video":
        con.warn(f"--deinterlace has no effect here: it sets what happens to an interlaced video's fields, and the "
                 f"input is images")
    if given("jpeg_quality") and job in (_VideoJob, SequenceToVideoJob):
        con.warn("--jpeg-quality has no effect here: it sets the quality of JPEG images written, and the output is "
                 "a video (--crf sets its encoder's)")
    if given("audio") and job is SequenceToVideoJob and ctx.params.get("audio") != "none":
        con.warn(f"--audio {ctx.params['audio']} has no effect here: it sets what happens to a video's audio "
                 f"tracks, and images have none (the video is made without audio)")
    if job is _ImageJob or job is VideoToImagesJob:   # images out: no video encoder, container or audio
        encoder = (("codec", "--codec"), ("crf", "--crf"), ("encoder_preset", "--encoder-preset"),
                   ("pix_fmt", "--pix-fmt"))
        unused = [flag for name, flag in encoder if given(name)]
        sets = ["the video encoder"] if unused else []
        for name, flag, what in (("container", "-f/--format", "the video container"),
                                 ("audio", "--audio", "the video's audio tracks")):
            if given(name):
                unused.append(flag)
                sets.append(what)
        if unused:
            what = sets[0] if len(sets) == 1 else f"{', '.join(sets[:-1])} and {sets[-1]}"
            con.warn(f"{', '.join(unused)} {'has' if len(unused) == 1 else 'have'} no effect here: "
                     f"{'it sets' if len(unused) == 1 else 'they set'} {what}, and the output is images")


def _warn_unused_temporal_options(ctx: click.Context, con: Console, temporal: "TemporalOptions") -> None:
    """The temporal stage's settings given on the command line where they do nothing: a warning each run, as
    _warn_unused_options does (they do not turn the stage on; --lookahead, --dense-motion, --stats do)."""
    def given(name: str) -> bool:
        return ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE

    flags = (("temporal_frames", "--temporal-frames"), ("temporal_method", "--temporal-method"),
             ("temporal_mode", "--temporal-mode"), ("temporal_k", "--temporal-k"))
    if temporal.spec() is None:
        unused = [flag for name, flag in flags if given(name)]
        if temporal.enabled is False:
            # --no-temporal outranks the options that otherwise imply the stage: no CSV, no view, no frames read ahead
            implied = (("--stats", temporal.stats_path), ("--show history", temporal.show == "history"),
                       ("--lookahead", given("lookahead")), ("--dense-motion", temporal.dense_motion))
            unused += [flag for flag, on in implied if on]
        elif given("lookahead"):   # --lookahead 0 alone does not turn the stage on
            unused.append("--lookahead")
        if unused:
            off = "--no-temporal turns it off" if temporal.enabled is False else "--temporal turns it on"
            con.warn(f"{', '.join(unused)} {'has' if len(unused) == 1 else 'have'} no effect here: the temporal "
                     f"stage is off ({off})")
        return
    if temporal.method == "blend" and given("temporal_frames"):
        con.warn("--temporal-frames has no effect with --temporal-method blend: it sets the ring of temporal "
                 "supersampling, which the blend does not use")
    if temporal.method == "tss" and given("temporal_k"):
        con.warn("--temporal-k has no effect with --temporal-method tss: it sets the blend's velocity weight")


def _job_for(kind: str, output: str) -> type:
    """The job for an input kind and an output: same kind (video -> video, images -> images), or a
    conversion: a folder or pattern -> a video file (by its extension), a video -> a frame pattern."""
    from mlaa_stream.io.sequence import is_pattern
    from mlaa_stream.io.video import is_video_path

    if kind in ("folder", "pattern") and is_video_path(output) and not os.path.isdir(output):
        from mlaa_stream.cli.convert_jobs import SequenceToVideoJob
        return SequenceToVideoJob
    if kind == "video" and is_pattern(output):
        from mlaa_stream.cli.convert_jobs import VideoToImagesJob
        return VideoToImagesJob
    return _VideoJob if kind == "video" else _ImageJob


@click.command("filter", epilog=EPILOG, context_settings={"max_content_width": 100})
@click.argument("input_path", metavar="INPUT")
@click.option("-o", "--output", required=True, metavar="OUTPUT",
              help="Output file, folder (same names as the inputs) or frame pattern (clean/%04d.png: a sequence "
                   "keeps its numbers, a folder's images are numbered in name order from 1).")
@click.option("-y", "--overwrite", is_flag=True, help="Replace outputs that exist (never an input).")
@click.option("--resume", is_flag=True,
              help="Skip inputs whose output exists already (folders, sequences, a video written as images); "
                   "--temporal on a sequence warms up from the skipped frames just before the first one to "
                   "write; a video's skipped frames are still filtered with --temporal or --overlay, not written.")
@click.option("--frames", metavar="A-B", help="Frame numbers of a %04d pattern, e.g. 1001-1100 "
              "(default: every number found; gaps are reported).")
@click.option("--preset", type=click.Choice(sorted(PRESETS)), default=None,
              help="The antialiasing filter's named settings (the options below override them): "
                   + "; ".join(f"{name}: {use}" for name, use in PRESET_USES.items())
                   + ". The video encoder's speed is --encoder-preset.")
@click.option("--threshold", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Edge threshold: CIELAB ΔE for --metric lab (default 8), a fraction of full "
                   "scale for luma/rgb (default 0.06).")
@click.option("--metric", type=click.Choice(["lab", "luma", "rgb"]), default=None,
              help="Colour difference that finds edges (default: lab).")
@click.option("--display-space", "display_space", is_flag=True,
              help="Blend in display (sRGB-encoded) values instead of linear light.")
@click.option("--reconstruct/--no-reconstruct", default=None,
              help="Topological reconstruction of thin features before edge detection.")
@click.option("--bridge/--no-bridge", default=None,
              help="Reconnect the dashes of sub-pixel wires after blending (default: on).")
@click.option("--codec", default=None,
              help="Video encoder: libx264, libx265, ffv1 / libx264rgb (lossless intermediates), "
                   "prores_ks ... (default: the source's family, HEVC -> libx265, ProRes -> prores_ks, "
                   "FFV1 -> ffv1; others libx264; the container's own where it cannot hold that one: WebM -> VP9).")
@click.option("-f", "--format", "container", default=None, metavar="NAME",
              help="Output container (FFmpeg's name, or y4m / mkv / ts); needed with -o - (standard "
                   "output): y4m (raw, 8-16 bit), nut, matroska, mpegts. Default: from the file name.")
@click.option("--audio", type=click.Choice(["copy", "aac", "none"]), default="copy", show_default=True,
              help="Audio tracks: copied with the subtitle streams and every tag (language, title), "
                   "re-encoded to AAC (subtitles still copied), or left out.")
@click.option("--crf", type=click.IntRange(0, 63), default=18, show_default=True,
              help="Constant rate factor for x264/x265/VP9/AV1 (0 = lossless with libx264rgb).")
@click.option("--encoder-preset", default="veryfast", show_default=True,
              help="The video encoder's speed preset for x264/x265 (ultrafast ... veryslow); not the "
                   "filter's --preset.")
@click.option("--pix-fmt", default=None, help="Encoder pixel format (default: the closest to the source).")
@click.option("--jpeg-quality", type=click.IntRange(1, 100), default=None, metavar="1-100",
              help="Quality of JPEG outputs (images, frames of a video). Default: a JPEG source's own, estimated "
                   "from its quantisation table; 98 (OpenImageIO's) for other sources.")
@click.option("--start", "start", default=None, metavar="TIME",
              help="Video: begin here (seconds 12.5, 1:02.5, 0:01:02.5, or a frame 300f); the output "
                   "starts at 0, audio and subtitles cut to match.")
@click.option("--end", "end", default=None, metavar="TIME", help="Video: stop before this time or frame.")
@click.option("--rate", type=click.FloatRange(min=0, min_open=True), default=24.0, show_default=True,
              help="Frame rate of a video made from images (a folder or pattern with -o out.mp4).")
@click.option("--deinterlace", type=click.Choice(["auto", "on", "off"]), default="auto", show_default=True,
              help="Video: make interlaced frames progressive before the filter (bwdif, one frame per frame, same "
                   "rate and timestamps), else the combing of moving edges is taken for jaggies and smeared. auto: "
                   "where the stream's field order or its frames say it is interlaced; on: always; off: never (the "
                   "fields filtered as one frame).")
@click.option("--video-backend", type=click.Choice(["pyav", "opencv"]), default="pyav",
              show_default=True, help="opencv: the fallback (8-bit, mp4v, no audio).")
@click.option("--overlay", type=click.Path(dir_okay=False), default=None,
              help="Draw antialiased polylines from a JSON/GeoJSON file on every frame.")
@click.option("--cluster", default=None, metavar="ADDRESS",
              help="Run on a Dask cluster: a scheduler address (tcp://host:8786) or local:N (N worker "
                   "processes here). Videos, folders and frame patterns (with --temporal each chunk first "
                   "runs the frames before it, unwritten); each worker needs the package and an OpenCL "
                   "device (docs/cluster.md).")
@click.option("--chunk-frames", type=click.IntRange(min=1), default=16, show_default=True,
              help="Frames per cluster task (with --temporal: several times the warm-up, e.g. 64).")
@click.option("--progress", "progress_path", default=None, metavar="FILE|-",
              help="Also write machine-readable progress there (- is stdout): key=value lines (frame, "
                   "total_frames, fps, elapsed_s, left_s), each block ended by progress=continue|end.")
@click.option("--in-flight", type=click.IntRange(1, 3), default=2, show_default=True,
              help="Frames submitted to the device before the oldest is collected (1 = serialized).")
@click.option("--temporal/--no-temporal", default=None,
              help="Temporal supersampling for video, folders and frame sequences: the input's "
                   "samples of the last K frames accumulated along the motion (issue 16). Off by "
                   "default: not yet never-worse than spatial only (docs/temporal.md).")
@click.option("--temporal-frames", "temporal_frames", type=click.IntRange(*RING_FRAMES), default=None,
              help=f"K: input frames kept in the ring, {RING_FRAMES[0]} to {RING_FRAMES[1]} (default 16; more: "
                   f"steadier pans, more memory).")
@click.option("--temporal-method", type=click.Choice(["auto", "tss", "blend", "tss+blend"]), default="auto",
              show_default=True,
              help="auto: temporal supersampling, then the previous output reprojected and blended on "
                   "moving edges of render regions (1-spp 3D renders); tss: temporal supersampling "
                   "only; blend: the reprojection blend everywhere (seed 002); tss+blend: both "
                   "everywhere (docs/temporal.md).")
@click.option("--lookahead", type=click.IntRange(0, 8), default=None, metavar="N",
              help="Temporal supersampling also reads the N frames after each one (each output waits for N "
                   "more frames; implies --temporal). Default with the temporal stage: 2 (steadier and more "
                   "error removed on every shot where it takes samples, ~1.1x its time: docs/temporal.md, "
                   "\"Look-ahead\"); 0 reads the past only.")
@click.option("--dense-motion", is_flag=True, default=False,
              help="Temporal supersampling tracks motion tile by tile where one camera motion does not "
                   "explain a frame (a dolly, an orbit: near and far content move apart). More error "
                   "removed on such shots, and with --temporal-method tss less damage than without it; "
                   "slow: ~3x the stage's time on those frames (docs/temporal.md, \"Dollies through "
                   "tracked tiles\"). Implies --temporal.")
@click.option("--temporal-mode", type=click.Choice(["adaptive", "dense", "global", "static"]),
              default="adaptive", show_default=True,
              help="Motion model: adaptive picks per frame the cheapest that explains it "
                   "(static shot, one global motion, moving layers over a background, dense flow).")
@click.option("--temporal-k", type=click.FloatRange(min=0), default=None,
              help="Velocity-difference strength K of seed 002 in pixel units (larger rejects "
                   "history sooner; 0 keeps it regardless of speed).")
@click.option("--stats", "stats_path", type=click.Path(dir_okay=False), default=None,
              help="Write per-frame temporal statistics to this CSV (implies --temporal): one row per frame written, "
                   "its motion model (reset, static, global, layers, dense), samples taken, ms; columns in "
                   "docs/temporal.md, \"--stats FILE\".")
@click.option("--alpha", "alpha", type=click.Choice(["coverage", "keep"]), default="coverage", show_default=True,
              help="An RGBA frame's alpha: coverage antialiases a silhouette against transparency in the alpha too "
                   "(an element rendered over transparency: the colour of the rim stays the element's, no dark "
                   "fringe once composited); keep leaves the alpha as it is and filters the colour alone.")
@click.option("--transfer", "transfer", type=click.Choice(TRANSFER_CHOICES), default="auto", show_default=True,
              help="How integer samples code light: auto reads it from a video's colour tags and an image's cICP or "
                   "colour space (HDR10's PQ, HLG: mixed as the light they code); pq or hlg say so for files that "
                   "do not (a y4m, an untagged PNG); sdr takes every file as sRGB-coded.")
@click.option("--keep", "keep", multiple=True, metavar="X,Y,W,H",
              help="Leave this rectangle of every frame exactly as it is (burned-in subtitles, a HUD or a slate "
                   "over a render, which the filter would soften); pixels or % of the frame, e.g. "
                   "0,85%,100%,15% for the bottom 15 %. Repeat for several.")
@click.option("--show", type=click.Choice(["history", "regions"]), default=None,
              help="Debug view instead of the image: history = the temporal stage's samples per pixel "
                   "(implies --temporal; the blend's weights with --temporal-method blend or tss+blend); regions = "
                   "the output with everything outside render regions dimmed (where the filter treats the frame as "
                   "a 1-spp 3D render).")
@device_option
@verbosity_options
@click.pass_context
def filter_command(ctx: click.Context, input_path: str, output: str, overwrite: bool, resume: bool,
                   frames: str | None, preset: str | None, threshold: float | None,
                   metric: str | None, display_space: bool, reconstruct: bool | None,
                   bridge: bool | None, codec: str | None, container: str | None, audio: str,
                   crf: int, encoder_preset: str, pix_fmt: str | None, jpeg_quality: int | None,
                   start: str | None, end: str | None,
                   rate: float, deinterlace: str, video_backend: str,
                   overlay: str | None, cluster: str | None, chunk_frames: int, progress_path: str | None,
                   in_flight: int, temporal: bool | None,
                   temporal_frames: int | None, temporal_method: str, lookahead: int | None, dense_motion: bool,
                   temporal_mode: str,
                   temporal_k: float | None, stats_path: str | None, alpha: str, transfer: str, keep: tuple[str, ...],
                   show: str | None, device: str | None, verbose: int, quiet: bool) -> None:
    """Remove jaggies from an image, a folder of images, a frame sequence or a video.

    INPUT is an image, a folder (its images in name order), a printf frame pattern such as
    'shot/%04d.exr' (or 'shot/####.exr'), or a video. OUTPUT gets the same file names and formats.
    """
    configure_logging(verbose, quiet)
    con = Console(verbose, quiet)
    try:
        with stop_signals_as_interrupts():
            code = _filter(ctx, con, input_path, output, overwrite=overwrite, resume=resume,
                           frames=frames, preset=preset, threshold=threshold, metric=metric,
                           display_space=display_space, reconstruct=reconstruct, bridge=bridge,
                           codec=codec, container=container, audio=audio, crf=crf,
                           encoder_preset=encoder_preset, pix_fmt=pix_fmt, rate=rate, jpeg_quality=jpeg_quality,
                           video_backend=video_backend, deinterlace=deinterlace, start=start, end=end,
                           overlay=overlay, in_flight=in_flight, device=device, progress_path=progress_path,
                           cluster=cluster, chunk_frames=chunk_frames, keep=keep, alpha=alpha, transfer=transfer,
                           temporal=TemporalOptions(temporal, temporal_mode, temporal_k, stats_path, show,
                                                    temporal_frames, temporal_method, lookahead, dense_motion))
    except Terminated as exc:
        con.error(f"terminated by {exc}; complete outputs are kept, the one in progress was removed")
        code = 128 + exc.signum
    except KeyboardInterrupt:
        con.error("interrupted; complete outputs are kept, the one in progress was removed")
        code = EXIT_INTERRUPTED
    except BrokenPipeError:  # standard output's reader went away outside the video writer (--progress -): quietly
        code = EXIT_BROKEN_PIPE
    if code == EXIT_BROKEN_PIPE:
        code = _stdout_gone()
    sys.exit(code)


def _filter(ctx: click.Context, con: Console, input_path: str, output: str, *, overwrite: bool,
            resume: bool, frames: str | None, preset: str | None, threshold, metric, display_space,
            reconstruct, codec: str | None, crf: int, encoder_preset: str, pix_fmt: str | None,
            video_backend: str, overlay: str | None, in_flight: int, device: str | None, deinterlace: str = "auto",
            temporal: "TemporalOptions | None" = None, bridge: bool | None = None, rate: float = 24.0,
            audio: str = "copy", progress_path: str | None = None, start: str | None = None,
            end: str | None = None, container: str | None = None, cluster: str | None = None,
            chunk_frames: int = 16, keep: tuple[str, ...] = (), jpeg_quality: int | None = None,
            alpha: str = "coverage", transfer: str = "auto") -> int:
    """Check everything that can be checked without a device, then build the filter and run."""
    from mlaa_stream.io.sequence import printf_pattern

    # shot.####.exr (Nuke, RV) is shot.%04d.exr: else "no such file" for an input, "names one image" for an output
    input_path, output = printf_pattern(input_path), printf_pattern(output)
    temporal = temporal or TemporalOptions()
    show_regions = temporal.show == "regions"
    if overwrite and resume:
        con.error("--overwrite and --resume contradict each other: choose one")
        return EXIT_USAGE
    kwargs = _filter_kwargs(ctx, preset, threshold, metric, display_space, reconstruct, bridge)
    if alpha != "coverage":
        kwargs["alpha"] = alpha
    if threshold is not None and threshold >= 1 and kwargs.get("metric", "lab") in ("luma", "rgb"):
        # luma and rgb thresholds are fractions of full scale: no two colours of an image in 0-1 differ by 1 or more,
        # so a ΔE-sized value (8, --metric lab's default) finds no edge and writes the input back without a word
        con.warn(f"--threshold {threshold:g} with --metric {kwargs['metric']}: a fraction of full scale (default "
                 f"{DEFAULT_THRESHOLDS[kwargs['metric']]:g}); colours in 0-1 never differ that much, so no edges "
                 f"are found (a ΔE such as 8 is --metric lab's scale)")
    if keep:
        from mlaa_stream.spatial.keep import keep_rects
        try:
            kwargs["keep"] = keep_rects(keep)
        except ValueError as exc:
            con.error(f"--{exc}")
            return EXIT_USAGE
    if show_regions:  # the spatial filter's view: it does not imply the temporal stage
        temporal.show = None
        if kwargs.get("fast"):
            con.error("--show regions needs the default chain (the fast preset has no render regions)")
            return EXIT_USAGE
        kwargs["show"] = "regions"
    try:
        kind = _kind_of(input_path)
        if frames is not None and kind != "pattern":
            raise Usage(f"--frames needs a frame pattern like shot/%04d.exr, got {input_path} "
                        f"(for a video: --start/--end)")
        if cluster is not None and kind not in ("folder", "pattern", "video"):
            raise Usage("--cluster runs videos, folders and frame patterns; a single image runs here")
        if cluster is not None and kind == "video" and (input_path == "-" or output == "-" or start or end):
            raise Usage("--cluster needs a video file in and out (no pipes, --start or --end)")
        if cluster is not None and overlay is not None:
            raise Usage("--overlay is not available with --cluster")
        if cluster is not None:
            from mlaa_stream.cluster.connect import ClusterAddressError, parse_address
            try:
                parse_address(cluster)
            except ClusterAddressError as exc:
                raise Usage(str(exc)) from exc
        if output == "-" and kind != "video":  # else a folder named '-', or a file OpenImageIO cannot write
            raise Usage("-o - (standard output) takes a video read from a video file or standard input; "
                        "write images to a file, a folder or a frame pattern")
        if (start is not None or end is not None) and kind != "video":
            raise Usage("--start/--end trim a video; for a frame pattern use --frames A-B")
        post_hooks = _load_post_hooks(overlay, device)
        if not (temporal.wanted and kind == "image"):   # a single image with the stage asked for: said below
            _warn_unused_temporal_options(ctx, con, temporal)
        if temporal.wanted and kind == "image":
            # --stats and --show history ask for something the run will not make (no file, no view): warned
            unmade = [flag for flag, on in (("--stats", temporal.stats_path), ("--show history", temporal.show))
                      if on]
            if unmade:
                con.warn(f"{', '.join(unmade)} {'has' if len(unmade) == 1 else 'have'} no effect here: a single "
                         f"image gets spatial antialiasing only (temporal needs a sequence)")
            else:
                con.info("a single image: spatial antialiasing only (temporal needs a sequence)")
            temporal.enabled, temporal.show, temporal.stats_path, temporal.lookahead = False, None, None, None
            temporal.dense_motion = False
        for what, path in (("--progress", progress_path if progress_path != "-" else None),
                           ("--stats", temporal.stats_path)):
            if path:  # written during or after the run: a missing folder would end it in a traceback
                from mlaa_stream.io.images import is_image_path
                from mlaa_stream.io.sequence import same_file
                from mlaa_stream.io.video import is_video_path
                # a text file named as an image or a video is an input or output mistyped: it would be written over
                if is_image_path(path) or is_video_path(path) or (input_path != "-" and same_file(path, input_path)):
                    raise Usage(f"{what} {path}: names an image or video (the input, an output?), which it would "
                                f"replace with text; choose a .csv or .txt name")
                folder = os.path.dirname(os.path.abspath(path))
                if not os.path.isdir(folder):
                    raise Failed(f"{what} {path}: the folder {folder} does not exist")
                if os.path.isdir(path):
                    raise Failed(f"{what} {path}: is a folder; expected a file name")
                _check_writable(folder)
        if temporal.spec() is not None and not kwargs.get("fast"):
            from mlaa_stream.temporal.methods import needs_regions
            kwargs["keep_regions"] = needs_regions(temporal.method)  # the stage reads the filter's regions
        if cluster is not None and (temporal.show or temporal.stats_path or show_regions):
            raise Usage("--stats and --show are not available with --cluster (each worker has its own stage)")
        if temporal.lookahead and temporal.spec() is not None and temporal.method == "blend":
            raise Usage("--lookahead needs a --temporal-method with TSS (auto, tss, tss+blend): the blend "
                        "reads the past only")
        if temporal.dense_motion and temporal.spec() is not None and temporal.method == "blend":
            raise Usage("--dense-motion needs a --temporal-method with TSS (auto, tss, tss+blend): the blend "
                        "has its own dense flow")
        job = _job_for(kind, output)
        runner = job(input_path, output, kind, con, overwrite=overwrite, resume=resume,
                     frames=frames, codec=codec, container=container, audio=audio,
                     progress_path=progress_path, crf=crf, start=start, end=end, cluster=cluster,
                     chunk_frames=chunk_frames, temporal_spec=temporal.spec() if cluster else None,
                     lookahead=temporal.frames_ahead if temporal.spec() is not None else 0,
                     encoder_preset=encoder_preset, pix_fmt=pix_fmt, rate=rate, jpeg_quality=jpeg_quality,
                     video_backend=video_backend, deinterlace=deinterlace, filter_kwargs=kwargs, transfer=transfer)
        runner.prepare()
        _warn_unused_options(ctx, con, kind, job)
        transfer = getattr(runner, "transfer", None)
        if transfer is not None and kwargs.get("linear", True):  # --display-space: the codes' own mix, as asked
            kwargs["transfer"] = transfer   # the same dict the job holds: a cluster's workers get it too
            con.info(f"{'standard input' if input_path == '-' else input_path}: coded with {TRANSFER_NAMES[transfer]} "
                     f"(HDR): filtered in the linear light its codes stand for")
        info = getattr(runner, "info", None)
        if info is not None and getattr(info, "interlaced", None) and deinterlace == "off":
            # two fields a field-time apart in one frame: their combing on anything that moves looks like jaggies
            con.warn(f"{'standard input' if input_path == '-' else input_path} is interlaced ({info.interlaced}): "
                     f"with --deinterlace off it is filtered and written as progressive frames, and the combing of "
                     f"moving edges is taken for jaggies (--deinterlace auto makes it progressive first)")
        if info is not None and getattr(info, "alpha_unread", False):
            # WebM VP9 keeps alpha in a side stream that FFmpeg's own VP9 decoder does not read
            con.warn(f"{'standard input' if input_path == '-' else input_path}: its alpha (WebM VP9 alpha_mode) is not "
                     f"read by this FFmpeg's VP9 decoder: the output has none")
        if keep and info is not None and getattr(info, "rotation", 0):
            # a phone's video: players turn it, but the filter (and --keep) sees the frames as stored, so
            # rectangles measured on the turned picture would keep the wrong place without a word
            con.warn(f"--keep: {input_path} is displayed rotated by {info.rotation} degrees; the rectangles are "
                     f"taken in its frames as stored ({info.width}x{info.height}, before that rotation)")
    except Usage as exc:
        con.error(str(exc))
        return EXIT_USAGE
    except Failed as exc:
        if output == "-" and is_broken_pipe(exc):  # the reader went away before the first frame (-o - | true)
            return EXIT_BROKEN_PIPE
        con.error(str(exc))
        return EXIT_FAILED
    except OSError as exc:
        con.error(exc.strerror if exc.filename is None else f"{exc.filename}: {exc.strerror}")
        return EXIT_FAILED
    if runner.nothing_to_do():
        con.info("nothing to do: every output exists")
        return EXIT_FAILED if runner.failed_early else EXIT_OK

    from mlaa_stream.device.context import DeviceError, KernelBuildError
    from mlaa_stream.spatial.filter import Filter
    from mlaa_stream.pipeline import StageTimes

    try:
        try:
            filt = (FastFilter if kwargs.get("fast") else Filter)(device, bgr=False, **kwargs)  # fast: no host copies
        except DeviceError as exc:
            con.error(str(exc))
            return EXIT_NO_DEVICE
        except (ValueError, KernelBuildError) as exc:
            con.error(str(exc))
            return EXIT_USAGE if isinstance(exc, ValueError) else EXIT_FAILED
        con.info(f"device: {filt.device_name}")
        _warn_unseen_gpu(filt, device, con)
        times = StageTimes()
        stage = temporal.stage(filt) if kind != "image" and cluster is None else None  # workers: their own
        spool = stage = StatsSpool(stage) if stage is not None else None  # rows on disk as the run goes
        if stage is not None and kind != "video":
            stage = _SequenceTemporal(stage, runner, con)
        try:
            with filt:
                code = runner.run(filt, post_hooks, in_flight, times, stage)
        finally:
            if spool is not None:
                temporal.finish(spool, con, skip=runner.unwritten_indices())
    finally:
        runner.abort()  # no-op after a commit; removes a video in progress on errors and Ctrl-C
        runner.close_progress()
    on_workers = cluster is not None  # the stages ran on the cluster's workers: this process timed none of them
    if con.verbose and not con.quiet and not on_workers:
        click.echo(times.report(), err=True)
    elif not con.quiet and (not sys.stderr.isatty() or con.verbose) and code == EXIT_OK:
        # logs and pipes: one line, no bar; with -v on a cluster this line instead of a table of zeros
        wall = time.perf_counter() - times.started
        click.echo(f"mlaa-stream: {runner.written} frames in {wall:.1f} s "
                   f"({runner.written / wall if wall > 0 else 0:.1f} fps) -> {runner.output}", err=True)
    if runner.failed_early and code == EXIT_OK:
        code = EXIT_FAILED
    return code


@dataclass
class TemporalOptions:
    """The temporal stage's command-line settings (issues 6, 16); off unless --temporal (or --stats /
    --show history, which imply it)."""

    enabled: bool | None = None
    mode: str = "adaptive"
    k: float | None = None
    stats_path: str | None = None
    show: str | None = None
    frames: int | None = None
    method: str = "auto"
    lookahead: int | None = None   # --lookahead; None: DEFAULT_LOOKAHEAD with a method that has TSS
    dense_motion: bool = False     # --dense-motion: TSS's dense_samples

    @property
    def wanted(self) -> bool:
        return bool(self.enabled or self.show or self.stats_path or self.lookahead or self.dense_motion)

    def stage(self, filt):
        """The temporal stage sharing the filter's OpenCL context, or None when off."""
        spec = self.spec()
        return None if spec is None else spec.stage(filt, show=self.show)

    def spec(self):
        """The settings as a TemporalSpec (what the cluster's workers get), or None when off."""
        if self.enabled is False or (self.enabled is None and not self.wanted):
            return None  # off unless asked for; --show history, --stats, --lookahead and --dense-motion imply it
        from mlaa_stream.cluster.temporal import TemporalSpec
        return TemporalSpec(self.method, self.frames, self.mode, self.k, self.frames_ahead, self.dense_motion)

    @property
    def frames_ahead(self) -> int:
        """N for the stage: --lookahead, else DEFAULT_LOOKAHEAD (files: the output may wait), 0 for the blend."""
        from mlaa_stream.temporal.methods import DEFAULT_LOOKAHEAD
        if self.lookahead is not None:
            return self.lookahead
        return 0 if self.method == "blend" else DEFAULT_LOOKAHEAD

    def finish(self, stage: StatsSpool, con: "Console", skip: set = frozenset()) -> None:
        """Write --stats and say which motion models were used, then close the stage; `skip`: frame numbers read
        only as look-ahead frames (--resume), not written."""
        try:
            counts: dict[str, int] = {}
            keys: set[str] = set()  # the CSV's columns: every row's, known before its first row is written
            for row in stage.rows():
                if row.get("index") not in skip:
                    counts[row.get("model", "?")] = counts.get(row.get("model", "?"), 0) + 1
                    keys.update(row)
            if not counts:
                return
            con.info("temporal models: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))
            if self.stats_path:
                import csv
                with open(self.stats_path, "w", newline="") as fh:
                    w = csv.DictWriter(fh, fieldnames=sorted(keys))
                    w.writeheader()
                    w.writerows(row for row in stage.rows() if row.get("index") not in skip)
        finally:
            stage.close()


class _SequenceTemporal:
    """The temporal stage for folders and sequences: frames in name/number order; the stage is called
    with the frame number (a gap in the numbering is a jump: the history resets) and says when it
    resets for a gap or a change of size. Positions map to files through the runner's plan as read."""

    def __init__(self, stage, runner: "_ImageJob", con: Console):
        self.stage, self.runner, self.con = stage, runner, con
        self.lookahead = getattr(stage, "lookahead", 0)   # the pipeline hands in that many frames ahead
        self._prev: tuple | None = None   # (number, shape) of the previous frame

    def __call__(self, frame_in, frame_out, index: int, future=()):
        from mlaa_stream.io.sequence import consecutive_ahead, frame_number
        ff = self.runner.read_order.get(index)
        number = frame_number(self.runner.read_order, index)
        future = consecutive_ahead(self.runner.read_order, index, future)
        shape = (frame_in.shape, frame_in.dtype)
        if self._prev is not None:
            label = ff.label if ff is not None else f"frame {index}"
            if number != self._prev[0] + 1:
                self.con.info(f"{label}: temporal history reset (gap in the numbering after "
                              f"{self._prev[0]})")
            elif shape != self._prev[1]:
                self.con.info(f"{label}: temporal history reset (the frame size or type changed)")
        if self._use_linear(self.runner.read_linear.pop(index, False)) and self._prev is not None:
            self.con.info(f"{ff.label if ff is not None else f'frame {index}'}: temporal history reset (linear "
                          f"light and display-encoded frames take separate histories)")
        self._prev = (number, shape)
        self.runner.read_order.pop(index, None)
        return self.stage(frame_in, frame_out, number, future=future) if self.lookahead else \
            self.stage(frame_in, frame_out, number)

    def _use_linear(self, linear: bool) -> bool:
        """The stage's colour space for the next frame (linear light: EXR, untagged float); True when it changed."""
        use = getattr(self.stage, "set_linear_input", None)
        return bool(use(linear)) if use is not None else False

    def warm(self, frame_in, frame_out, ff, linear: bool = False) -> None:
        """A frame before the first one to write (--resume): through the stage, output discarded."""
        self._use_linear(linear)
        number = ff.sequence_number if ff.sequence_number is not None else (self._prev[0] + 1 if self._prev else 0)
        self._prev = (number, (frame_in.shape, frame_in.dtype))
        self.stage(frame_in, frame_out, number)


class _Job:
    def __init__(self, input_path: str, output: str, kind: str, con: Console, **opts):
        self.input, self.output, self.kind, self.con, self.opts = input_path, output, kind, con, opts
        self.written = 0
        self.failed_early = False

    def _progress(self, total: int | None):
        from mlaa_stream.io.progress import Progress

        path = self.opts.get("progress_path")
        if path and getattr(self, "_machine", None) is None:
            try:
                self._machine = sys.stdout if path == "-" else open(path, "w", buffering=1)
            except OSError as exc:
                raise Failed(f"{path}: cannot write progress ({exc.strerror})") from exc
        return Progress(total, label=os.path.basename(self.input.rstrip("/")) or self.input,
                        enabled=None if not self.con.quiet else False, machine=getattr(self, "_machine", None))

    def unwritten_indices(self) -> set:
        """The temporal stage's indices of frames it ran on but that are not written (--resume): left out of --stats."""
        return set()

    def close_progress(self) -> None:
        machine = getattr(self, "_machine", None)
        if machine is not None and machine is not sys.stdout:
            machine.close()


class _ImageJob(_Job):
    """An image, a folder of images or a numbered sequence."""

    def prepare(self) -> None:
        from mlaa_stream.io.images import is_image_path, remove_quietly, stale_temp_files
        from mlaa_stream.io.sequence import (Report, expand_pattern, format_ranges, is_pattern, list_folder,
                                output_over_input, parse_frames, plan_images, same_file)

        o, con = self.opts, self.con
        self.strict = self.kind == "pattern"
        self.report = Report(say=con.error, inform=con.info, caution=con.warn)
        numbers = None
        if self.kind == "image":
            srcs = [self.input]
        elif self.kind == "folder":
            srcs, others = list_folder(self.input)
            for path in others:
                con.warn(f"{path}: skipped (not an image file by its extension)")
            if same_file(self.input, self.output):
                raise Usage(f"{self.output}: is the input folder; choose another output folder")
            if not srcs:
                raise Failed(f"{self.input}: expected image files, found none")
        else:
            rng = None
            if o["frames"] is not None:
                try:
                    rng = parse_frames(o["frames"])
                except ValueError as exc:
                    raise Usage(str(exc)) from exc
            found, missing = expand_pattern(self.input, rng)
            if not found:
                raise Usage(f"{self.input}: no files match this frame pattern"
                            + (f" for frames {o['frames']}" if rng else ""))
            if missing:
                msg = f"{self.input}: missing frames {format_ranges(missing)}"
                if rng is not None:
                    self.report.fail(msg)  # frames asked for by --frames that are not there
                    self.failed_early = True
                else:
                    con.warn(msg + " (gap in the numbering)")
            numbers = [n for n, _ in found]
            srcs = [p for _, p in found]
        if self.kind != "image" and not is_pattern(self.output):
            if os.path.exists(self.output) and not os.path.isdir(self.output):
                raise Usage(f"{self.output}: expected a folder (or a %04d pattern) for "
                            f"{'a folder' if self.kind == 'folder' else 'a sequence'}, got a file")
            if not os.path.exists(self.output) and is_image_path(self.output):
                # out.png would become a folder named out.png: more likely one image was meant, which many are not
                stem, ext = os.path.splitext(self.output)
                many = "a folder" if self.kind == "folder" else "a sequence"
                raise Usage(f"{self.output}: names one image, and {many} has many; give a folder or a frame "
                            f"pattern such as {stem}/%04d{ext} (a folder named so: end it with /)")
            self.output = os.path.join(self.output, "")  # a folder, created below
        self.plan = plan_images(srcs, self.output, numbers)
        # each file's place in the whole plan: the post hooks' frame index (--overlay's frames), whatever
        # --resume skips, look-ahead reads add or an unreadable file of a folder leaves out
        self.positions = {id(ff): i for i, ff in enumerate(self.plan)}
        clash = output_over_input(self.plan)
        if clash is not None:
            raise Usage(clash)
        dst_dirs = sorted({os.path.dirname(os.path.abspath(ff.dst)) for ff in self.plan})
        if self.kind != "image" or is_pattern(self.output):   # a pattern's folder is made, as for a video's frames
            for d in dst_dirs:
                try:
                    os.makedirs(d, exist_ok=True)
                except OSError as exc:
                    raise OSError(exc.errno, f"cannot create the output folder ({exc.strerror})",
                                  d) from exc
        for d in dst_dirs:  # temporary files of a run that was killed (SIGKILL, power cut)
            for path in stale_temp_files(d):
                remove_quietly(path)
                con.info(f"{path}: removed (a temporary file left by an interrupted run)")
        existing = [ff for ff in self.plan if os.path.exists(ff.dst)]
        if existing and o["resume"]:
            existing = self._keep_complete(existing)
            self.report.skipped.extend(ff.dst for ff in existing)
            con.info(f"--resume: {len(existing)} outputs exist and are skipped")
            skipped = set(id(ff) for ff in existing)
            first = next((i for i, ff in enumerate(self.plan) if id(ff) not in skipped), None)
            # the temporal stage's warm-up: the skipped frames just before the first one to write,
            # consecutive in number or, in a folder, in name order (issue 16: --resume warms up from the K frames
            # before it)
            warm: list = []
            if first is not None:
                for ff in reversed(self.plan[:first]):
                    nxt = warm[0] if warm else self.plan[first]
                    if id(ff) not in skipped or ff.sequence_number is None or nxt.sequence_number is None \
                            or ff.sequence_number != nxt.sequence_number - 1:
                        break
                    warm.insert(0, ff)
            self.warm_up = warm
            whole, self.plan = self.plan, [ff for ff in self.plan if id(ff) not in skipped]
            self.whole_plan = whole   # --cluster --temporal: the chunks of the first run (_run_on_cluster)
            self._read_ahead_of(whole, skipped)
        elif existing and not o["overwrite"]:
            more = f" (and {len(existing) - 1} more)" if len(existing) > 1 else ""
            raise Usage(f"{existing[0].dst}: exists{more}; use --overwrite to replace "
                        f"or --resume to skip existing outputs")
        for d in dst_dirs:
            if not os.path.isdir(d):
                raise Failed(f"{d}: the output folder does not exist")
            _check_writable(d)

    def _read_ahead_of(self, whole: list, skipped: set) -> None:
        """--resume with --lookahead N: after each file to write, the (skipped) files that follow it, up to N and
        consecutive, are read too but not written (`read_ahead`), so that its output reads the frames ahead an
        uninterrupted run read."""
        n = self.opts.get("lookahead", 0)
        extra: list = []
        for i, ff in enumerate(whole):
            if id(ff) in skipped:
                continue
            for nxt, prev in zip(whole[i + 1:i + 1 + n], whole[i:i + n]):
                if id(nxt) not in skipped or prev.sequence_number is None or nxt.sequence_number is None \
                        or nxt.sequence_number != prev.sequence_number + 1:
                    break
                extra.append(nxt)
        ids = {id(ff) for ff in extra}
        self.read_ahead = ids
        self.read_ahead_numbers = {ff.sequence_number for ff in extra}
        self.read_plan = [ff for ff in whole if id(ff) not in skipped or id(ff) in ids]

    def _warm_up(self, filt, temporal) -> None:
        _warm_up_images(self, filt, temporal)

    def unwritten_indices(self) -> set:
        return getattr(self, "read_ahead_numbers", set())   # warm-up frames' rows are dropped by _warm_up_images

    def _keep_complete(self, existing: list) -> list:
        """--resume: the existing outputs that are complete (header of the input's size, PNG/JPEG end
        marker, EXR/TIFF first and last rows decode); an incomplete one (e.g. from a version that did not check
        writes, a copy cut short) is removed and redone."""
        from mlaa_stream.io.images import check_complete, image_shape

        complete = []
        for ff in existing:
            shape = image_shape(ff.src)
            why = check_complete(ff.dst, *shape, decode=False) if shape else None
            if why is None:
                complete.append(ff)
                continue
            self.con.warn(f"{ff.dst}: incomplete ({why}); it is written again")
            try:
                os.unlink(ff.dst)
            except OSError as exc:
                raise Failed(f"{ff.dst}: incomplete and cannot be removed ({exc.strerror})") from exc
        return complete

    def nothing_to_do(self) -> bool:
        return not self.plan

    def run(self, filt, post_hooks, in_flight, times, temporal=None) -> int:
        from mlaa_stream.spatial.filter import Filter
        from mlaa_stream.pipeline import PipelineError, run_pipeline
        from mlaa_stream.io.sequence import FilterSet, image_sink, image_source, is_linear

        encoded = filt

        def make_variant(options: dict):
            """Linear-light inputs (EXR, untagged float) are not sRGB-decoded before blending; HDR images (PQ / HLG
            PNGs) are decoded by their transfer (device/transfer.py)."""
            kwargs = dict(self.opts["filter_kwargs"], **options)
            what = ("linear-light" if "linear_input" in options else
                    f"HDR ({TRANSFER_NAMES.get(options.get('transfer'), options.get('transfer'))})")
            if "transfer" in options and not kwargs.get("linear", True):   # --display-space: the codes' own mix
                return encoded
            try:
                made = (FastFilter if kwargs.get("fast") else Filter)(context=encoded.context, bgr=False, **kwargs)
            except TypeError as exc:  # a Filter without the option: treat them as encoded
                self.con.warn(f"{what} inputs filtered as display-encoded ({exc})")
                return encoded
            if "transfer" in options:
                self.con.info(f"{what} images: filtered in the linear light their codes stand for")
            return made

        if self.opts.get("cluster"):
            return self._run_on_cluster()
        filt = FilterSet(encoded, make_variant, self.opts.get("transfer", "auto"))
        read_plan = getattr(self, "read_plan", self.plan) if temporal is not None else self.plan
        read_ahead = getattr(self, "read_ahead", set())
        progress = self._progress(len(read_plan))
        say = self.report.say
        self.report.say = lambda msg: (progress.clear(), say(msg))
        caution = self.report.caution
        self.report.caution = lambda msg: (progress.clear(), caution(msg))
        write = image_sink(self.report, overwrite=self.opts["overwrite"], strict=self.strict,
                           jpeg_quality=self.opts.get("jpeg_quality"))

        def sink(item) -> None:
            if id(item.meta[0]) not in read_ahead:   # a look-ahead frame of --resume: read, not written
                write(item)
        self.read_order: dict = {}
        self.read_linear: dict = {}   # position -> the frame is linear light (the temporal stage's colour space)
        positions = getattr(self, "positions", {})
        hook_index: dict = {}   # position read -> the file's place in the whole plan (self.positions)

        def source():
            """image_source, remembering which file each position is (for the temporal stage and the hooks)."""
            inner = image_source(read_plan, self.report, strict=self.strict)
            try:
                for position, item in enumerate(inner):
                    if not item.passthrough:   # a file copied unchanged: neither the stage's nor the hooks'
                        self.read_order[position] = item.meta[0]
                        self.read_linear[position] = is_linear(item.meta[1])
                        hook_index[position] = positions.get(id(item.meta[0]), position)
                    yield item
            finally:
                inner.close()
        post_hooks = [(lambda h: (lambda f, i: h(f, hook_index.get(i, i))))(h) for h in post_hooks]
        if temporal is not None and getattr(self, "warm_up", None):
            self._warm_up(filt, temporal)
        try:
            run_pipeline(source(), filt, sink, temporal=temporal,
                         in_flight=in_flight, post_hooks=post_hooks, times=times,
                         on_frame=progress.update)
            stopped = None
        except PipelineError as exc:
            stopped = exc
        finally:
            progress.close()
            filt.close()
            self.written = len(self.report.written)
        if stopped is not None:
            ff = stopped.meta[0] if stopped.meta else None
            cause = str(stopped.cause)
            named = ff is not None and (ff.src in cause or ff.dst in cause)
            if ff is None and self.strict and stopped.stage == "read":
                named = True  # a sequence's read errors name their file or frame themselves
            self.con.error(cause if named else f"{ff.label if ff else f'frame {stopped.index}'}: "
                           f"{stopped.stage} failed: {cause}")
            self.con.error(f"stopped: {self.written} of {len(self.plan)} outputs written")
            return EXIT_FAILED
        if self.report.failed:
            self.con.error(f"{len(self.report.failed)} failed, {self.written} written")
            return EXIT_FAILED
        copied = f" ({len(self.report.copied)} copied unchanged: no colour)" if self.report.copied else ""
        self.con.info(f"{self.written} written{copied}, {len(self.report.skipped)} skipped")
        return EXIT_OK

    def _run_on_cluster(self) -> int:
        """The same plan, filtered in chunks by the workers of a Dask cluster (mlaa_stream.cluster)."""
        from mlaa_stream.cluster.connect import ClusterAddressError, connect
        from mlaa_stream.cluster.frames import ClusterJobError, run_chunks

        progress = self._progress(len(self.plan))
        temporal = self.opts.get("temporal_spec")
        files, done = self.plan, frozenset()
        if temporal is not None and getattr(self, "whole_plan", None):
            # --resume: the whole job with the complete outputs marked done, so that each chunk still reads its
            # warm-up (and look-ahead) frames, as one machine warms up from the skipped frames before it
            files, done = self.whole_plan, frozenset(self.report.skipped)
        try:
            with connect(self.opts["cluster"]) as client:
                self.con.info(f"cluster: {len(client.scheduler_info()['workers'])} workers")
                report = run_chunks(client, files, self.opts["filter_kwargs"],
                                    overwrite=self.opts["overwrite"], strict=self.strict,
                                    chunk_frames=self.opts["chunk_frames"], on_frames=progress.update,
                                    temporal=temporal, done=done, jpeg_quality=self.opts.get("jpeg_quality"),
                                    transfer=self.opts.get("transfer", "auto"),
                                    say=lambda msg: (progress.clear(), self.con.error(msg)),
                                    caution=lambda msg: (progress.clear(), self.con.warn(msg)))
        except ClusterAddressError as exc:
            progress.close()
            raise Usage(str(exc)) from exc
        except (ClusterJobError, OSError) as exc:
            progress.close()
            self.con.error(str(exc))
            self.con.error("stopped: the outputs written are complete; --resume goes on from there")
            return EXIT_FAILED
        progress.close()
        self.written = len(report.written) + len(report.skipped)
        if report.failed:
            self.con.error(f"{len(report.failed)} failed, {self.written} written")
            return EXIT_FAILED
        self.con.info(f"{self.written} written, {len(self.report.skipped)} skipped")   # as one machine says it
        return EXIT_OK

    def abort(self) -> None:
        pass


def _ring_frames(stage) -> int:
    """How many frames before the first one to write the temporal stage wants (its ring; the blend: 3)."""
    inner = getattr(stage, "tss", stage)
    return int(getattr(inner, "frames", 3))


def _warm_up_images(job: "_ImageJob", filt, temporal: "_SequenceTemporal") -> None:
    """--resume with the temporal stage: the inputs of the last skipped frames before the first one to
    write go through the spatial filter and the stage (outputs discarded, not in --stats), so the
    first written frame has the history it would have had in an uninterrupted run."""
    from mlaa_stream.io.sequence import image_source, is_linear
    from mlaa_stream.temporal.methods import stats_lists
    warm = job.warm_up[-_ring_frames(temporal.stage):]
    stage = temporal.stage
    keep = [(rows, len(rows)) for rows in stats_lists(stage)]
    done = 0
    try:
        for item in image_source(warm, job.report, strict=job.strict):
            if item.passthrough:   # no colour: not of the stage's sequence
                continue
            f = filt.for_item(item) if hasattr(filt, "for_item") else filt
            temporal.warm(item.frame, f.process(item.frame), item.meta[0], is_linear(item.meta[1]))
            done += 1
    finally:
        for rows, n in keep:
            del rows[n:]
    if done:
        job.con.info(f"--resume: temporal history warmed up from {done} frames before "
                     f"{job.plan[0].label if job.plan else 'the end'}")


class _VideoJob(_Job):
    """A video file in, a video file out."""

    def prepare(self) -> None:
        from mlaa_stream.io.video import (PIPE, CvVideoWriter, VideoError, VideoWriter, container_format_for,
                                          open_pipe, probe_video, probe_video_cv)

        o = self.opts
        out = self.output
        if out != PIPE:
            self._check_output_file(out)
        elif o.get("progress_path") == PIPE:
            raise Usage("--progress - and -o - both want standard output; give --progress a file")
        if (self.input == PIPE or out == PIPE) and o["video_backend"] == "opencv":
            raise Usage("pipes (-) need the pyav video backend")
        if o.get("deinterlace") == "on" and o["video_backend"] == "opencv":
            raise Usage("--deinterlace on needs the pyav video backend (libavfilter's bwdif)")
        self.pipe_in = None
        try:
            if self.input == PIPE:  # read once: the open container goes on to read_video
                self.info, self.pipe_in = open_pipe()
            else:
                self.info = (probe_video_cv if o["video_backend"] == "opencv" else probe_video)(self.input)
        except VideoError as exc:
            raise Failed(str(exc)) from exc
        self.start, self.end = self._trim()
        self.transfer = video_transfer(self.info, o.get("transfer", "auto"), o["video_backend"] == "opencv")
        self.con.info(f"{self.input}: {self.info.width}x{self.info.height} {self.info.pix_fmt} "
                      f"{self.info.bits}-bit, {self.info.fps} fps, {self.info.frames or '?'} frames, "
                      f"{self.info.audio_streams} audio streams")
        try:
            if o["video_backend"] == "opencv":
                self.writer = CvVideoWriter(out, self.info, overwrite=o["overwrite"])
            else:
                self.writer = VideoWriter(out, self.info, codec=o["codec"], crf=o["crf"],
                                          preset=o["encoder_preset"], pix_fmt=o["pix_fmt"],
                                          overwrite=o["overwrite"], audio=o["audio"],
                                          offset=self.start or 0.0, end=self.end,
                                          container_format=container_format_for(o.get("container"), out))
        except VideoError as exc:
            raise Failed(str(exc)) from exc
        self.con.info(f"encoding {getattr(self.writer, 'codec', 'mp4v')} "
                      f"{getattr(self.writer, 'pix_fmt', 'bgr24')} to {out}")

    def _stdout_gone(self) -> int:
        """Standard output's reader went away: no error (head, a player closed), said only with -v."""
        self.con.info(f"standard output closed by its reader after {self.writer.frames_written} frames; stopped")
        return EXIT_BROKEN_PIPE

    def _check_output_file(self, out: str) -> None:
        """A video file out: not the input, not there already (without -y), in a writable folder;
        temporary files of killed runs there are removed."""
        from mlaa_stream.io.images import remove_quietly, stale_temp_files
        from mlaa_stream.io.sequence import same_file
        from mlaa_stream.io.video import PIPE

        o = self.opts
        if os.path.isdir(out) or out.endswith(("/", os.sep)):
            out = os.path.join(out, os.path.basename(self.input) if self.input != PIPE else "out.mkv")
        self.output = out
        if self.input != PIPE and same_file(self.input, out):
            raise Usage(f"{out}: output is the input; choose another output")
        if o["resume"]:
            self.con.warn("--resume applies to folders and sequences; a video is redone")
        if os.path.exists(out) and not o["overwrite"]:
            raise Usage(f"{out}: exists; use --overwrite to replace it")
        folder = os.path.dirname(os.path.abspath(out))
        if not os.path.isdir(folder):
            raise Failed(f"{folder}: the output folder does not exist")
        _check_writable(folder)
        for path in stale_temp_files(folder):  # left by a run that was killed
            remove_quietly(path)
            self.con.info(f"{path}: removed (a temporary file left by an interrupted run)")

    def _trim(self) -> tuple[float | None, float | None]:
        return video_trim(self.opts, self.info)

    def nothing_to_do(self) -> bool:
        return False

    def abort(self) -> None:
        writer = getattr(self, "writer", None)
        if writer is not None and not getattr(self, "_finished", False):
            writer.abort()

    def _run_on_cluster(self) -> int:
        """Segments of the video filtered and encoded by the workers, joined here (mlaa_stream.cluster.video)."""
        from mlaa_stream.cluster.connect import connect
        from mlaa_stream.cluster.video import ClusterVideoError, filter_video_on_cluster

        self.writer.abort()  # the workers encode; the join writes the output
        self._finished = True
        o = self.opts
        progress = self._progress(self.info.frames)
        from mlaa_stream.io.deinterlace import filter_name, reason
        why = reason(o.get("deinterlace", "off"), self.info.interlaced, False)   # the first frame's flag: probe_video
        if why is not None:   # each worker decides as read_video does; said here, once
            deinterlace_note(self.con, self.input)(filter_name(), why)
        try:
            with connect(o["cluster"]) as client:
                self.written = filter_video_on_cluster(
                    client, self.input, self.output, codec=o["codec"], crf=o["crf"],
                    encoder_preset=o["encoder_preset"], pix_fmt=o["pix_fmt"], overwrite=o["overwrite"],
                    audio=o["audio"] != "none", on_frames=progress.update,
                    segment_seconds=o["chunk_frames"] / float(self.info.fps or 25),
                    temporal=o.get("temporal_spec"), warn=self.con.warn, deinterlace=o.get("deinterlace", "off"),
                    **o["filter_kwargs"])
        except (ClusterVideoError, OSError) as exc:
            self.con.error(str(exc))
            self.con.error(f"{self.output}: not written")
            return EXIT_FAILED
        finally:
            progress.close()
        self.con.info(f"{self.output}: {self.written} frames")   # as one machine says it
        return EXIT_OK

    def run(self, filt, post_hooks, in_flight, times, temporal=None) -> int:
        from mlaa_stream.pipeline import PipelineError
        from mlaa_stream.io.video import VideoError, VideoReadError, read_video_cv

        if self.opts.get("cluster"):
            return self._run_on_cluster()
        from mlaa_stream.pipeline import filter_video

        from mlaa_stream.io.video import read_video

        if self.opts["video_backend"] == "opencv":
            source = read_video_cv(self.info)
        else:
            source = read_video(self.info, start=self.start, end=self.end, container=self.pipe_in,
                                require_frames=True, deinterlace=self.opts.get("deinterlace", "off"),
                                on_deinterlace=deinterlace_note(self.con, self.input))
        total = self.info.frames
        if total and self.info.fps and (self.start or self.end is not None):
            duration = (self.end if self.end is not None else total / float(self.info.fps)) - (self.start or 0)
            total = max(int(round(duration * float(self.info.fps))), 0)
        progress = self._progress(total)
        try:
            filter_video(self.info, self.writer, filt, source=source, post_hooks=post_hooks,
                         temporal=temporal,
                         in_flight=in_flight, times=times, on_frame=progress.update)
            stopped = None
            self._finished = True
        except PipelineError as exc:
            stopped = exc
            self._finished = True  # filter_video kept the shorter file or removed it
        except VideoError as exc:  # finishing the output failed: filter_video removed it
            self._finished = True
            if self.output == "-" and is_broken_pipe(exc):   # the reader went away before the stream's end
                return self._stdout_gone()
            self.con.error(str(exc))
            return EXIT_FAILED
        except BrokenPipeError:   # the muxer's last bytes (its trailer) to a reader that went away
            self._finished = True
            return self._stdout_gone()
        finally:
            progress.close()
            self.written = self.writer.frames_written
            for w in dict.fromkeys(self.writer.warnings):
                self.con.warn(w)
        if stopped is not None and self.output == "-" and is_broken_pipe(stopped):
            return self._stdout_gone()   # `-o - | head`: the reader has what it wanted; Unix tools stop quietly
        if stopped is None:
            self.con.info(f"{self.output}: {self.written} frames")
            return EXIT_OK
        if stopped.stage == "read" and isinstance(stopped.cause, VideoReadError):
            self.con.error(str(stopped.cause))
            if self.written:
                self.con.error(f"{self.output}: kept as a valid shorter video with the "
                               f"{self.written} frames before it")
            else:
                self.con.error(f"{self.output}: not written (no frame decoded)")
        else:
            self.con.error(f"{self.input}: {stopped}; {self.output} not written")
        return EXIT_FAILED
