"""`mlaa-stream INPUT -o OUTPUT`: filter an image, a folder of images, a frame sequence or a video."""
from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass

import click

from mlaa_stream.cli.console import (EXIT_BROKEN_PIPE, EXIT_FAILED, EXIT_INTERRUPTED, EXIT_NO_DEVICE, EXIT_OK,
                                     EXIT_USAGE, Console, Failed, Terminated, Usage, is_broken_pipe, stdout_gone,
                                     stop_signals_as_interrupts)
from mlaa_stream.cli.filter_jobs import ImageJob, SequenceTemporal, VideoJob, check_writable
from mlaa_stream.cli.options import configure_logging, device_option, verbosity_options
from mlaa_stream.cli.stats_spool import StatsSpool
from mlaa_stream.device.transfer import TRANSFER_CHOICES, TRANSFER_NAMES
from mlaa_stream.spatial.fast_filter import FastFilter
from mlaa_stream.spatial.filter import DEFAULT_THRESHOLDS, PRESET_USES, PRESETS
from mlaa_stream.temporal.methods import RING_FRAMES


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
Video goes through PyAV (FFmpeg): frame rate, timestamps (from the first one: an MPEG-TS capture's
clock offset is dropped, as FFmpeg does), resolution, pixel aspect ratio, colour
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
    # clear the failed probe's error: left pending, OpenImageIO printed it at exit ("... exited with a pending error
    # message ... could not find a format reader for ...") after a video without a known extension was filtered
    oiio.geterror()
    return "video"  # probe_video says so if it is not one either


def _warn_unused_options(ctx: click.Context, con: Console, kind: str, job: type, runner: object = None) -> None:
    """Options given on the command line (not defaults) that this job has no use for: a warning each, not an
    error (--rate with a video input, the encoder's, container's and audio options with images out, --audio
    copy/aac and --deinterlace with images in, --crf and --encoder-preset with an encoder that has no such setting:
    `runner`'s writer says which encoder it took)."""
    from mlaa_stream.cli.convert_jobs import SequenceToVideoJob, VideoToImagesJob

    def given(name: str) -> bool:
        return ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE

    if given("rate") and job is not SequenceToVideoJob:
        why = "a video keeps its own frame rate" if job is VideoJob else "images have no frame rate"
        con.warn(f"--rate has no effect here: it sets the frame rate of a video made from images; {why}")
    if given("deinterlace") and kind != "video":
        con.warn("--deinterlace has no effect here: it sets what happens to an interlaced video's fields, and the "
                 "input is images")
    if given("jpeg_quality") and job in (VideoJob, SequenceToVideoJob):
        con.warn("--jpeg-quality has no effect here: it sets the quality of JPEG images written, and the output is "
                 "a video (--crf sets its encoder's)")
    if given("audio") and job is SequenceToVideoJob and ctx.params.get("audio") != "none":
        con.warn(f"--audio {ctx.params['audio']} has no effect here: it sets what happens to a video's audio "
                 f"tracks, and images have none (the video is made without audio)")
    writer = getattr(runner, "writer", None)
    if writer is not None and (given("crf") or given("encoder_preset")):
        # ProRes, FFV1, DNxHD ... take neither (the OpenCV fallback's mp4v neither): they were dropped without a word
        from mlaa_stream.io.video import encoder_options
        codec = getattr(writer, "codec", "mp4v (the OpenCV fallback)")
        takes = encoder_options(codec, 0, "preset")
        flags = (("crf", "--crf", "crf"), ("encoder_preset", "--encoder-preset", "preset"))
        unused = [flag for name, flag, key in flags if given(name) and key not in takes]
        if unused:
            con.warn(f"{', '.join(unused)} {'has' if len(unused) == 1 else 'have'} no effect with {codec}: "
                     f"{'it sets' if len(unused) == 1 else 'they set'} x264 / x265 "
                     f"{'(and VP9 / AV1) ' if '--crf' in unused else ''}encoding")
    if job is ImageJob or job is VideoToImagesJob:   # images out: no video encoder, container or audio
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
    return VideoJob if kind == "video" else ImageJob


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
                   "FFV1 -> ffv1, AV1 -> libaom-av1 or libsvtav1, DNxHR -> dnxhd; others libx264; the container's "
                   "own where it cannot hold that one: WebM -> VP9).")
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
        code = stdout_gone()
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
                check_writable(folder)
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
        _warn_unused_options(ctx, con, kind, job, runner)
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
            stage = SequenceTemporal(stage, runner, con)
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


