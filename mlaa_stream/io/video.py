"""Video through PyAV: decode to RGB frames and encode them back, keeping what the source had.

Kept: frame rate and timestamps (time base and pts are copied), resolution and pixel aspect ratio, bit
depth (a source with more than 8 bits per sample decodes to rgb48le/uint16 and is encoded to a >8-bit
pixel format where the codec has one), alpha where the codec can store it, colour tags (matrix, range,
primaries, transfer), HDR10 static metadata (mastering display, content light level: with libx265) and every audio
stream (copied packet by packet, not re-encoded). Interlaced sources are made progressive on decode where asked
(read_video's `deinterlace`: io/deinterlace.py), before the frames become RGB.
OpenCV's VideoCapture/VideoWriter serve only as a fallback (8-bit, no audio, mp4v).

The output is encoded under a temporary name in its directory and renamed when complete.
"""
from __future__ import annotations

import io
import math
import os
import struct
import sys
from dataclasses import dataclass
from fractions import Fraction
from typing import Callable, Iterator

import numpy as np

from mlaa_stream.io.deinterlace import FLAGGED
from mlaa_stream.io.images import publish, remove_quietly, temp_path_for
from mlaa_stream.io.item import Item

try:
    import av
except ImportError as _exc:  # pragma: no cover - av is a dependency; OpenCV is the fallback
    av = None
    _AV_ERROR: Exception | None = _exc
else:
    _AV_ERROR = None

VIDEO_EXTENSIONS = frozenset({
    ".mp4", ".m4v", ".mov", ".mkv", ".webm", ".avi", ".mxf", ".ts", ".mts", ".m2ts", ".mpg",
    ".mpeg", ".y4m", ".nut", ".flv", ".wmv", ".ogv", ".3gp",
})

DEFAULT_CODEC = "libx264"
DEFAULT_CRF = 18
DEFAULT_ENCODER_PRESET = "veryfast"

# Codecs people use for lossless intermediates: they get an RGB pixel format when they have one.
LOSSLESS_RGB_CODECS = frozenset({"ffv1", "libx264rgb", "png", "qtrle", "utvideo", "huffyuv", "ffvhuff"})
# Encoders whose time base must be 1/fps-like (MPEG-4 part 2 limits the denominator to 16 bits).
_FPS_TIME_BASE_CODECS = frozenset({"mpeg4", "mpeg2video", "mpeg1video", "h263", "msmpeg4v2"})
# Containers that store one index entry per tick of the time base (AVI): a finer time base than the frame
# rate declares that rate (an MP4 source's 1/12288 -> 600 fps) and fills the gaps with empty frames.
_FPS_TIME_BASE_FORMATS = frozenset({"avi"})
# Encoders that store the pixel aspect ratio in their bitstream (H.264/HEVC VUI, MPEG-4 Part 2's VOL): kept in any
# container.
_SAR_IN_BITSTREAM = frozenset({"libx264", "libx264rgb", "libx265", "mpeg4"})
# Containers that store a display rotation (a display matrix), measured with PyAV 18 / FFmpeg 8: not AVI, MPEG-TS,
# NUT, y4m, MXF, FLV, ASF, MPEG-PS.
_ROTATION_FORMATS = frozenset({"mp4", "mov", "ipod", "3gp", "3g2", "ismv", "matroska", "webm"})
# Containers that store it from the stream, which PyAV cannot set (MP4/MOV take the codec's parameters): with any
# other encoder it is lost -- y4m's A tag written 0:0, measured with PyAV 18 / FFmpeg 8 for each of these.
_SAR_FROM_STREAM_FORMATS = frozenset({"matroska", "webm", "yuv4mpegpipe", "nut", "avi"})
# FFmpeg's AVFieldOrder (PyAV gives the number; older versions a name): the field shown first, where interlaced
_TOP, _BOTTOM = "top field first", "bottom field first"
_FIELD_FIRST = {2: _TOP, 3: _BOTTOM, 4: _BOTTOM, 5: _TOP, "tt": _TOP, "bb": _BOTTOM, "tb": _BOTTOM, "bt": _TOP}
_UNSPECIFIED = {"colorspace": 2, "color_primaries": 2, "color_trc": 2, "color_range": 0}


def _sws_flags():
    """swscale flags for YUV <-> RGB: accurate rounding and full chroma interpolation. With the
    defaults a decode + encode round trip darkens luma by ~1 level (measured on the demo clip);
    with these luma comes back within 0.04 levels on average."""
    from av.video.reformatter import Interpolation as I

    return I.BICUBIC | I.ACCURATE_RND | I.FULL_CHR_H_INT | I.FULL_CHR_H_INP


class VideoError(Exception):
    """A video could not be read or written; the message names the file (and the frame)."""


class VideoReadError(VideoError):
    """Decoding stopped early; `frames_read` frames (0..frames_read-1) were delivered before it."""

    def __init__(self, message: str, frames_read: int = 0):
        super().__init__(message)
        self.frames_read = frames_read


@dataclass(frozen=True)
class VideoInfo:
    """What we keep from a source video."""

    path: str
    width: int
    height: int
    fps: Fraction | None
    time_base: Fraction | None
    frames: int | None  # as the container declares it, or from its duration; None if unknown
    pix_fmt: str
    bits: int
    has_alpha: bool
    codec: str
    colour: dict  # colorspace, color_range, color_primaries, color_trc as FFmpeg's enum values
    audio_streams: int
    frames_declared: bool = True  # `frames` is the container's own count, not duration x rate
    duration: float | None = None  # seconds, the stream's (or the container's) when known
    rotation: int = 0  # degrees of the display matrix (phones film sideways and say so there)
    subtitle_streams: int = 0
    other_streams: tuple[str, ...] = ()  # streams not copied as audio or subtitle: data, attachments, more video
    sar: Fraction | None = None  # sample (pixel) aspect ratio of an anamorphic source; None: square or unknown
    # "top field first" / "bottom field first" (shown first), "frames flagged interlaced" (the stream says neither, its
    # first frame does); None: progressive, unknown
    interlaced: str | None = None
    hdr10: tuple[str, ...] = ()  # HDR10 static metadata on the first frame, as x265 parameters (_hdr10_params)
    alpha_unread: bool = False  # the stream says it has alpha that the decoder does not give (WebM VP9's side stream)
    # seconds of the container's first timestamp (MPEG-TS captures, cut segments: often far from 0; negative ones --
    # an edit list's priming -- count as 0): --start/--end count from it, as FFmpeg's -ss does
    start_time: float = 0.0
    profile: str | None = None  # the codec's profile as FFmpeg names it ("DNXHR SQ", "High 10"); None: unknown

    @property
    def sample_format(self) -> str:
        """The RGB layout frames are decoded to: 8-bit or 16-bit, with alpha when the source has it."""
        if self.bits > 8:
            return "rgba64le" if self.has_alpha else "rgb48le"
        return "rgba" if self.has_alpha else "rgb24"


@dataclass(frozen=True)
class FrameTime:
    """A decoded frame's timestamp in its stream's time base (pts None when the container has none)."""

    pts: int | None
    time_base: Fraction | None


def is_video_path(path: str) -> bool:
    return os.path.splitext(path)[1].lower() in VIDEO_EXTENSIONS


def is_special_file(path: str) -> bool:
    """Whether `path` exists as something other than a regular file or a folder: a device (/dev/null), a named pipe,
    a socket -- written into as it is, never replaced."""
    import stat

    try:
        mode = os.stat(path).st_mode
    except OSError:
        return False
    return not (stat.S_ISREG(mode) or stat.S_ISDIR(mode))


def _require_av() -> None:
    if av is None:
        raise VideoError(f"PyAV cannot be imported ({_AV_ERROR}); use --video-backend opencv "
                         f"or 'pip install av'")


def _format_bits_alpha(name: str) -> tuple[int, bool]:
    fmt = av.VideoFormat(name)
    comps = fmt.components
    bits = max((c.bits for c in comps), default=8)
    return bits, any(c.is_alpha for c in comps)


def probe_video(path: str) -> VideoInfo:
    """Open `path` and describe its first video stream; VideoError if it is not a readable video."""
    _require_av()
    if os.path.isfile(path) and os.path.getsize(path) == 0:
        raise VideoError(f"{path}: expected a video, got an empty file")
    try:
        container = av.open(path)
    except (av.error.FFmpegError, OSError) as exc:
        raise VideoError(f"{path}: expected a video FFmpeg can read, got: {exc}") from exc
    try:
        return _describe(container, path, *_first_frame_facts(path))
    finally:
        container.close()


PIPE = "-"  # INPUT or OUTPUT: standard input / output
# -f names people use -> FFmpeg's muxer/demuxer names
FORMAT_ALIASES = {"y4m": "yuv4mpegpipe", "mkv": "matroska", "ts": "mpegts"}
# Extensions whose container holds raw pictures: encoded with rawvideo, not a compressed codec.
_RAW_FORMATS = {"yuv4mpegpipe": ("yuv420p", "yuv422p", "yuv444p", "gray", "yuv420p10le", "yuv422p10le",
                                 "yuv444p10le", "yuv420p12le", "yuv444p12le", "yuv420p16le", "yuv444p16le")}


def container_format_for(name: str | None, path: str) -> str | None:
    """The FFmpeg muxer for `-f NAME`, or for the output's extension where FFmpeg would not guess it
    (.y4m); None: FFmpeg picks by the file name."""
    if name:
        return FORMAT_ALIASES.get(name.lower(), name.lower())
    if os.path.splitext(path)[1].lower() == ".y4m":
        return "yuv4mpegpipe"
    return None


def _raw_pix_fmt(fmt: str, info: "VideoInfo") -> str:
    """The raw container's pixel format closest to the source: its own where allowed, else 4:4:4 at the
    source's depth (RGB frames lose no chroma)."""
    allowed = _RAW_FORMATS[fmt]
    if info.pix_fmt in allowed:
        return info.pix_fmt
    bits = info.bits
    return "yuv444p" if bits <= 8 else ("yuv444p10le" if bits <= 10 else
                                        "yuv444p12le" if bits <= 12 else "yuv444p16le")


def open_pipe(fmt: str | None = None, stream=None) -> tuple[VideoInfo, object]:
    """Open standard input (or `stream`) as a video container (y4m, NUT, Matroska, MPEG-TS: formats that
    need no seeking) and describe it; the container is returned for read_video, as a pipe opens once."""
    _require_av()
    src = _CountedInput(stream if stream is not None else sys.stdin.buffer)
    try:
        container = av.open(src, format=container_format_for(fmt, "") if fmt else None)
    except (av.error.FFmpegError, OSError, ValueError) as exc:
        raise VideoError(f"standard input: expected a video stream (y4m, NUT, MKV, MPEG-TS), got: {exc}") from exc
    try:
        return _describe(container, PIPE, 0), container
    except BaseException:
        container.close()
        raise


class _CountedInput:
    """A pipe as PyAV reads it, counting the bytes read: FFmpeg's y4m reader ends at the last whole frame of a stream
    cut short without an error, and a pipe cannot be measured afterwards as a file is (_y4m_leftover). Only read():
    without seek and tell PyAV takes it as unseekable, as it took standard input itself."""

    def __init__(self, raw):
        self._raw = raw
        self.consumed = 0  # bytes read so far
        self.ended = False  # an empty read: the writer closed its end

    def read(self, size: int = -1) -> bytes:
        data = self._raw.read(size)
        self.consumed += len(data)
        self.ended = self.ended or not data
        return data


def _describe(container, path: str, rotation: int, hdr10: tuple[str, ...] = (), flagged: bool = False) -> VideoInfo:
    """What we keep from the first video stream of an open container; `flagged`: its first frame says it is
    interlaced."""
    if not container.streams.video:
        raise VideoError(f"{path}: expected a video stream, found none")
    s = container.streams.video[0]
    cc = s.codec_context
    if not cc.width or not cc.height or cc.format is None:
        raise VideoError(f"{path}: expected a video stream with a size and pixel format, got "
                         f"{cc.width}x{cc.height} {cc.format}")
    pix = cc.format.name
    bits, alpha = _format_bits_alpha(pix)
    fps = s.average_rate or s.guessed_rate or None
    frames = s.frames or None
    declared = frames is not None
    duration = (float(s.duration * s.time_base) if s.duration and s.time_base else
                container.duration / 1e6 if container.duration else None)
    if frames is None and fps and duration:
        frames = int(round(duration * fps))  # an estimate (progress bar): wrong for variable rates
    colour = {k: int(getattr(cc, k) or 0) for k in _UNSPECIFIED}
    sar = s.sample_aspect_ratio or cc.sample_aspect_ratio  # the container's (MP4 pasp, MKV) or the bitstream's
    others = tuple(f"{st.type} stream {st.index}" for st in container.streams  # a second video stream too
                   if st.type not in ("video", "audio", "subtitle") or (st.type == "video" and st is not s))
    return VideoInfo(path=path, width=cc.width, height=cc.height,
                     fps=Fraction(fps) if fps else None,
                     time_base=Fraction(s.time_base) if s.time_base else None,
                     frames=frames, pix_fmt=pix, bits=bits, has_alpha=alpha, codec=cc.name,
                     colour=colour, audio_streams=len(container.streams.audio),
                     frames_declared=declared, duration=duration, rotation=rotation,
                     subtitle_streams=len(container.streams.subtitles), other_streams=others,
                     sar=Fraction(sar) if sar and sar != 1 else None,
                     interlaced=_FIELD_FIRST.get(getattr(cc, "field_order", None)) or (FLAGGED if flagged else None),
                     hdr10=hdr10, start_time=max(0.0, (container.start_time or 0) / 1e6),
                     profile=cc.profile if isinstance(cc.profile, str) else None,
                     alpha_unread=not alpha and str(_tag(s.metadata, "alpha_mode")) == "1")


def _tag(tags, name: str):
    """A tag by name, in any case (Matroska's are upper case as read back), or None."""
    return next((v for k, v in dict(tags or {}).items() if k.lower() == name), None)


def _first_frame_facts(path: str) -> tuple[int, tuple[str, ...], bool]:
    """From the first frame: the display rotation in degrees (0, 90, 180, -90; its display matrix), its HDR10
    static metadata as x265 parameters (_hdr10_params) and whether it is flagged interlaced."""
    try:
        with av.open(path) as c:
            if not c.streams.video:
                return 0, (), False  # no video stream: _describe says so
            for frame in c.decode(video=0):
                return int(round(frame.rotation or 0)), _hdr10_params(frame), bool(frame.interlaced_frame)
    except (av.error.FFmpegError, OSError, EOFError, AttributeError):
        pass
    return 0, (), False


def _hdr10_params(frame) -> tuple[str, ...]:
    """x265's parameters for a decoded frame's HDR10 static metadata: the mastering display (SMPTE ST 2086: FFmpeg's
    AVMasteringDisplayMetadata, primaries R, G, B and the white point as rationals, then the least and most
    luminance) as master-display=G(x,y)B(x,y)R(x,y)WP(x,y)L(max,min) in x265's units (1/50000, 1/10000 cd/m2), and
    the content light level (CTA-861.3: MaxCLL, MaxFALL) as max-cll; () where the frame carries neither. Frames are
    rebuilt from arrays, so what the source's frames carried is passed to the encoder here."""
    out = []
    for sd in getattr(frame, "side_data", ()):
        kind, raw = getattr(sd.type, "name", str(sd.type)), bytes(sd)
        if kind == "MASTERING_DISPLAY_METADATA" and len(raw) >= 88:
            v = struct.unpack_from("<22i", raw)
            if not (v[20] and v[21]) or 0 in v[1:20:2]:   # primaries and luminance both given, no zero denominator
                continue
            q = [Fraction(v[2 * i], v[2 * i + 1]) for i in range(10)]

            def xy(i: int) -> str:
                return f"({round(q[i] * 50000)},{round(q[i + 1] * 50000)})"
            out.append(f"master-display=G{xy(2)}B{xy(4)}R{xy(0)}WP{xy(6)}"
                       f"L({round(q[9] * 10000)},{round(q[8] * 10000)})")
        elif kind == "CONTENT_LIGHT_LEVEL" and len(raw) >= 8:
            out.append("max-cll={},{}".format(*struct.unpack_from("<2I", raw)))
    return tuple(out)


# The encoder that keeps a source's codec family when no --codec is given (None: DEFAULT_CODEC); by FFmpeg's name of
# the family (AV1 decodes with libdav1d, whose name is no family's), several where builds have one or the other
# (PyAV's wheels have SVT-AV1, not libaom).
CODEC_FAMILY = {"hevc": "libx265", "prores": "prores_ks", "ffv1": "ffv1", "vp9": "libvpx-vp9",
                "av1": ("libaom-av1", "libsvtav1"), "dnxhd": "dnxhd", "mjpeg": "mjpeg", "png": "png",
                "utvideo": "utvideo", "qtrle": "qtrle"}   # QuickTime Animation: lossless, with alpha (argb)
# Container and stream tags that describe the file written, not the content: not copied.
_NOT_COPIED_TAGS = {"encoder", "major_brand", "minor_version", "compatible_brands", "duration",
                    "number_of_frames", "number_of_bytes", "_statistics_tags", "_statistics_writing_app",
                    "_statistics_writing_date_utc", "bps", "handler_name", "vendor_id"}


def codec_for(info: VideoInfo) -> str:
    """The encoder for `info` when none is asked for: the source's family (HEVC stays HEVC, ProRes stays
    ProRes) where FFmpeg has an encoder for it, else DEFAULT_CODEC."""
    try:
        family = av.Codec(info.codec, "r").canonical_name   # the decoder's family: libdav1d -> av1
    except Exception:  # noqa: BLE001 - no such decoder here (OpenCV's "opencv"): the name as it is
        family = info.codec
    names = CODEC_FAMILY.get(family, ())
    names = (names,) if isinstance(names, str) else names
    return next((name for name in names if name in av.codecs_available), DEFAULT_CODEC)


def _container_holds(format_name: str, codec: str) -> bool:
    """False where FFmpeg knows the muxer cannot store the codec (H.264 in WebM); True where it can or does not
    say (MPEG-TS answers no query)."""
    with av.open(io.BytesIO(), "w", format=format_name) as probe:
        try:
            probe.add_stream(codec)
        except ValueError:
            return False
    return True


def _copy_tags(src: dict, dst) -> None:
    for key, value in src.items():
        if key.lower() not in _NOT_COPIED_TAGS and not key.upper().startswith("DURATION"):
            dst[key] = value


# Seconds a copied packet may lie before the output's start and still be kept (at 0): rounding, not content.
_START_SLACK = 0.001
# FFmpeg's default channel layout for a channel count (av_channel_layout_default): what a layout of unspecified order
# is encoded as with --audio aac
_DEFAULT_LAYOUTS = {1: "mono", 2: "stereo", 3: "2.1", 4: "4.0", 5: "5.0", 6: "5.1", 7: "6.1", 8: "7.1"}
# Output formats whose muxer stores attachment streams (fonts for subtitles, cover art) in its header.
_ATTACHMENT_FORMATS = ("matroska",)


def copy_chapters_and_attachments(src, out, offset: float = 0.0,
                                  end: float | None = None) -> tuple[set[str], list[str]]:
    """Copy the chapters and attachment streams of the open input `src` into the output `out` (before its
    header is written). Chapters are shifted by -`offset` seconds (a trimmed start) and cut at `end`
    (output seconds); those outside are left out. Attachments (MKV fonts, cover art) only where the
    output's format stores them (Matroska). Returns (the attachment streams dealt with, kept or named in
    a warning, as VideoInfo.other_streams names them; warnings naming what was not kept)."""
    warnings: list[str] = []
    chapters = []
    if not hasattr(src, "chapters") or not hasattr(out, "set_chapters"):  # an older PyAV (18 has both)
        warnings.append(f"chapters, if any, not kept: PyAV {av.__version__} cannot copy them")
    for ch in src.chapters() if hasattr(src, "chapters") and hasattr(out, "set_chapters") else ():
        tb = Fraction(ch["time_base"])
        start, stop = ch["start"] * tb - Fraction(offset), ch["end"] * tb - Fraction(offset)
        if stop <= 0 or (end is not None and start >= end):
            continue
        if end is not None:
            stop = min(stop, Fraction(end))
        chapters.append({**ch, "start": int(round(max(start, 0) / tb)), "end": int(round(stop / tb))})
    if chapters:
        try:
            out.set_chapters(chapters)
        except Exception as exc:  # noqa: BLE001 - a muxer or PyAV without chapters: say so, go on
            warnings.append(f"{len(chapters)} chapters not kept ({exc})")
    kept: set[str] = set()
    attachments = [st for st in src.streams if st.type == "attachment"]
    named = {f"attachment stream {st.index}" for st in attachments}
    if attachments and not any(f in out.format.name.split(",") for f in _ATTACHMENT_FORMATS):
        n = len(attachments)
        warnings.append(f"{n} attachment{'s' if n > 1 else ''} ({', '.join(str(a.name) for a in attachments)}) "
                        f"not kept: {out.format.name} cannot hold them (MKV does)")
        attachments = []
    for st in attachments:
        try:
            out.add_attachment(st.name, st.mimetype, bytes(st.data))
        except Exception as exc:  # noqa: BLE001 - e.g. a PyAV without add_attachment (before 14)
            warnings.append(f"attachment {st.name} not kept ({exc})")
    return named, warnings


def parse_time(text: str, fps: Fraction | None) -> float:
    """A time in seconds from '12.5', '1:02.5', '0:01:02.5' or a frame number '300f' (at `fps`)."""
    t = (text or "").strip()
    try:
        if t.endswith("f"):
            frame = int(t[:-1])
            if frame < 0:
                raise ValueError
            return frame / float(fps or 25)
        parts = [float(p) for p in t.split(":")]
        if not parts or len(parts) > 3 or any(not math.isfinite(p) or p < 0 for p in parts):
            raise ValueError
        return sum(p * 60 ** k for k, p in enumerate(reversed(parts)))
    except ValueError:
        raise ValueError(f"expected a time like 12.5, 1:02.5 or 0:01:02.5, or a frame like 300f, "
                         f"got {text!r}") from None


def read_video(info: VideoInfo, *, check_length: bool = True, start: float | None = None,
               end: float | None = None, container=None, require_frames: bool = False, deinterlace: str = "off",
               on_deinterlace: Callable[[str, str], None] | None = None) -> Iterator[Item]:
    """Decode every frame of `info.path` (between `start` and `end` seconds where given) to
    `info.sample_format`; Item.meta is a FrameTime.

    `deinterlace` (auto / on / off; mlaa_stream/io/deinterlace.py): interlaced frames made progressive before they
    become RGB, one per frame at its timestamp; auto where the stream's field order or its first frame says it is
    interlaced. `on_deinterlace(filter, reason)` is called once when that starts.

    Raises VideoReadError naming the frame where decoding stopped, also when the stream ends well
    before the length its container declares (a truncated file that decodes without an error), and with
    `require_frames` when a trim holds no frame (a user's --start/--end: nothing worth writing; a cluster's
    last segment may be empty).
    """
    _require_av()
    path = info.path if info.path != PIPE else "standard input"
    if container is None:  # `container`: already open (a pipe, from open_pipe); closed here at the end
        try:
            container = av.open(info.path)
        except (av.error.FFmpegError, OSError) as exc:
            raise VideoReadError(f"{path}: cannot open: {exc}", 0) from exc
    n, last_time = 0, None
    data_end = [None]  # the stream offset where the last packet's data ends (y4m on a pipe: _y4m_pipe_leftover)
    half = 0.5 / float(info.fps or 25)  # a frame counts as inside [start, end) by its timestamp
    try:
        stream = container.streams.video[0]
        stream.thread_type = "AUTO"
        sws = _sws_flags()
        from_start = [True]   # the frames come from the stream's beginning (no seek), as they do without `start`
        if start and info.path != PIPE:  # to the keyframe before `start`; the frames before it are decoded and dropped
            frames = _decoded_from(container, stream, start, half, data_end, from_start, info.path)
        else:  # a pipe cannot seek ('Operation not permitted', or nothing read): its frames before `start` are dropped
            frames = _decoded(container, stream, data_end)
        if deinterlace != "off":  # before the trim: the frames before `start` are the first one's field neighbours
            frames = _deinterlaced(frames, info, deinterlace, on_deinterlace)
        decoded = 0   # frames decoded so far, those before `start` too
        try:
            for frame in frames:
                ft = float(frame.pts * frame.time_base) if frame.pts is not None and frame.time_base else None
                if ft is None and from_start[0] and (start or end is not None):
                    # no timestamps (a raw H.264 / HEVC stream, a Raspberry Pi's .h264): its place at the nominal
                    # rate, as the writer times it; a trim kept every frame
                    ft = decoded / float(info.fps or 25)
                decoded += 1
                if start and ft is not None and ft < start - half:
                    continue
                if end is not None and ft is not None and ft >= end - half:
                    if not n and require_frames:
                        raise _nothing_between(path, start, end, info)
                    return
                if (frame.width, frame.height) != (info.width, info.height):
                    raise VideoReadError(
                        f"{path}: frame {n}: expected {info.width}x{info.height}, got "
                        f"{frame.width}x{frame.height} (size changes mid-stream are not "
                        f"supported)", n)
                rng = frame.color_range or None
                rgb = frame.reformat(format=info.sample_format, src_color_range=rng,
                                     interpolation=sws)
                if frame.pts is not None and frame.time_base:
                    last_time = float(frame.pts * frame.time_base)
                yield Item(rgb.to_ndarray(), FrameTime(frame.pts, frame.time_base))
                n += 1
        except (av.error.FFmpegError, EOFError) as exc:
            raise VideoReadError(f"{path}: decoding stopped at frame {n}: {exc}", n) from exc
        if not n and require_frames and (start or end is not None):
            raise _nothing_between(path, start, end, info)
        if check_length and not start and end is None:
            _check_length(info, n, last_time, _y4m_pipe_leftover(container, data_end[0]))
    finally:
        container.close()


def _decoded(container, stream, data_end: list) -> Iterator:
    """The stream's frames as decoded; data_end[0]: where the last packet's data ends in the stream."""
    for packet in container.demux(stream):
        if packet.size and packet.pos is not None and packet.pos >= 0:
            data_end[0] = packet.pos + packet.size
        yield from packet.decode()


def _decoded_from(container, stream, start: float, half: float, data_end: list, from_start: list,
                  path: str) -> Iterator:
    """The stream's frames as decoded from the keyframe before `start` (seconds; `half`: half a frame). A seek can land
    past it -- MPEG-TS lands on the packet at the time asked, keyframe or not, and nothing decodes until the next
    keyframe: a trim lost the frames up to it, or all of them --: then again from further back (1, 4, 16 ... s before
    `start`), in the end from the beginning, until the first frame decoded comes before `start`. A stream FFmpeg cannot
    seek (raw H.264 / HEVC, without timestamps: 'Operation not permitted') is read from its beginning.
    `from_start[0]`: set False where the frames come from a seek, not the beginning. `path`: the file, opened again."""
    back = 0.0
    while True:
        target = start - back
        try:
            if target > 0:
                container.seek(int(target / stream.time_base), stream=stream, backward=True, any_frame=False)
            else:
                container.seek(0)   # the beginning (MPEG-TS's seek to its stream's first time lands past it)
        except av.error.FFmpegError:
            if back:
                raise
            # the failed seek read the stream to its end looking for timestamps: from the beginning of a new opening
            with av.open(path) as fresh:
                again = fresh.streams.video[0]
                again.thread_type = "AUTO"
                yield from _decoded(fresh, again, data_end)
            return
        from_start[0] = target <= 0
        frames = _decoded(container, stream, data_end)
        first = next(frames, None)
        ft = float(first.pts * first.time_base) if first is not None and first.pts is not None and first.time_base \
            else None
        if target <= 0 or (first is not None and (ft is None or ft < start - half)):
            if first is not None:
                yield first
            yield from frames
            return
        back = back * 4 if back else 1.0


def _deinterlaced(frames: Iterator, info: VideoInfo, mode: str, on_deinterlace) -> Iterator:
    """`frames` made progressive where `mode` (deinterlace.reason) says so, else as they are. A decoding error is
    raised after the frames held by the deinterlacer (one) are given, as without it; a frame of another size goes
    through as it is, for read_video to refuse."""
    from mlaa_stream.io.deinterlace import Deinterlacer, reason

    first = next(frames, None)
    why = None if first is None else reason(mode, info.interlaced, bool(first.interlaced_frame))
    if why is None:  # progressive: the decoder's frames themselves
        if first is not None:
            yield first
            yield from frames
        return
    # auto on frames that say which are interlaced: those only (a progressive stretch of a broadcast stays sharp)
    deint = Deinterlacer(info.interlaced, only_flagged=mode == "auto" and bool(first.interlaced_frame))
    if on_deinterlace is not None:
        on_deinterlace(deint.name, why)
    frame = first
    while frame is not None:
        if (frame.width, frame.height) != (info.width, info.height):
            yield from deint.flush()
            yield frame
            return
        yield from deint.push(frame, info.time_base)
        try:
            frame = next(frames, None)
        except (av.error.FFmpegError, EOFError):
            yield from deint.flush()
            raise
    yield from deint.flush()


def _nothing_between(path: str, start: float | None, end: float | None, info: VideoInfo) -> VideoReadError:
    """The error for a trim (--start/--end) that holds no frame: nothing is worth writing. The times are said from
    the video's first timestamp (info.start_time), as the user gave them."""
    t0 = info.start_time
    length = f" (the video is {info.duration:.3f} s long)" if info.duration else ""
    return VideoReadError(f"{path}: no frame between {max(0.0, (start or t0) - t0):g} s and "
                          f"{'the end' if end is None else f'{end - t0:g} s'}{length}", 0)


_Y4M_MAGIC = b"YUV4MPEG2 "
_Y4M_FRAME = b"FRAME\n"


def _y4m_leftover(path: str, n: int, info: VideoInfo) -> int:
    """Bytes after the n-th whole frame of a y4m file (0 where it ends there, or where the file is no y4m whose frames
    carry no parameters): FFmpeg's reader ends at the last whole frame of a file cut short without an error."""
    try:
        with open(path, "rb") as fh:
            header = fh.readline(4096)
            if not header.startswith(_Y4M_MAGIC) or not header.endswith(b"\n"):
                return 0
            fmt = av.VideoFormat(info.pix_fmt, info.width, info.height)   # y4m's formats are planar
            record = len(_Y4M_FRAME) + sum(c.width * c.height * ((c.bits + 7) // 8) for c in fmt.components)
            fh.seek(len(header) + (n - 1) * record)
            if fh.read(len(_Y4M_FRAME)) != _Y4M_FRAME:   # frame parameters, another layout: not judged here
                return 0
            size = os.fstat(fh.fileno()).st_size
    except (OSError, ValueError):
        return 0
    return max(0, size - len(header) - n * record)


def _y4m_pipe_leftover(container, data_end: int | None) -> int:
    """Bytes of a y4m stream on a pipe (open_pipe) after its last whole frame: 0 where it ends there, or where it is
    no y4m, was not read to its end or is not a pipe. The demuxer's packets say where their data lies in the stream
    (frame parameters and all), _CountedInput how many bytes the pipe held."""
    src = getattr(container, "file", None)
    src = src if isinstance(src, _CountedInput) else getattr(src, "file", None)  # PyAV 18: its wrapper, PyIOFile
    if not isinstance(src, _CountedInput) or not src.ended or data_end is None \
            or "yuv4mpegpipe" not in container.format.name.split(","):
        return 0
    return max(0, src.consumed - data_end)


def _check_length(info: VideoInfo, n: int, last_time: float | None, pipe_leftover: int = 0) -> None:
    """VideoReadError when a stream that decoded without an error still ended early: fewer frames
    than the container declares, or (no declared count: MKV, WebM, variable frame rates) its last
    frame well before the declared duration, or a y4m file or pipe (`pipe_leftover`: _y4m_pipe_leftover) holds
    bytes of a frame after its last whole one. Durations are not frame counts when the rate varies."""
    if not n:  # a y4m header and no FRAME (vspipe failing before its first frame): no video to write
        raise VideoReadError(f"{'standard input' if info.path == PIPE else info.path}: expected video frames, "
                             f"the stream holds none", 0)
    left = _y4m_leftover(info.path, n, info) if info.path != PIPE else 0
    if left:
        raise VideoReadError(f"{info.path}: the stream ended at frame {n}, {left} bytes of a frame after it (truncated "
                             f"file?)", n)
    if pipe_leftover:  # the program writing the pipe stopped mid-frame (killed, out of disk, a crash)
        raise VideoReadError(f"standard input: the stream ended at frame {n}, {pipe_leftover} bytes of a frame after "
                             f"it (truncated stream: did the program writing it stop early?)", n)
    expected = info.frames
    if info.frames_declared and expected and n + max(2, expected // 50) < expected:
        raise VideoReadError(f"{info.path}: the stream ended at frame {n}, expected {expected} "
                             f"frames (truncated file?)", n)
    if not info.frames_declared and info.duration and last_time is not None:
        slack = max(0.05 * info.duration, 3.0 / float(info.fps or 25))  # 3 frames at the mean rate
        if last_time + slack < info.duration:
            raise VideoReadError(f"{info.path}: the stream ended at frame {n} ({last_time:.2f} s), "
                                 f"expected {info.duration:.2f} s (truncated file?)", n)


# Encoders that list alpha formats they cannot open: libvpx-vp9 encodes alpha only as a second 4:2:0 VP9 stream
# (WebM's alpha_mode 1), at any frame size, odd ones too; with yuva422p, yuva444p or gbrap avcodec_open2 fails (EINVAL,
# measured with FFmpeg 8.1: an RGBA source into WebM failed to start encoding).
_ALPHA_FORMATS_OPENED = {"libvpx-vp9": ("yuva420p",)}


def choose_pix_fmt(codec: str, src_pix_fmt: str, width: int, height: int) -> str | None:
    """The codec's pixel format closest to the source: same bits (or more), alpha kept if possible,
    chroma subsampling only where the size allows it; RGB first for lossless intermediates."""
    _require_av()
    formats = [f.name for f in (av.Codec(codec, "w").video_formats or ())]
    opened = _ALPHA_FORMATS_OPENED.get(codec)
    if opened is not None:  # the alpha formats the encoder lists but refuses
        formats = [n for n in formats if n in opened or not _format_bits_alpha(n)[1]]
    if not formats:
        return None
    sbits, salpha = _format_bits_alpha(src_pix_fmt)
    src = av.VideoFormat(src_pix_fmt)
    # subsampled or not by the format, not the size: a 1-pixel-wide frame's chroma is 1 wide in every format
    src_sub = src.chroma_width(2) < 2 or src.chroma_height(2) < 2
    lossless = codec in LOSSLESS_RGB_CODECS

    def colours(fmt) -> int:
        """Colour planes (alpha aside): 1 for grey; a palette's one plane of indices stands for colours."""
        return 3 if fmt.name.startswith("pal") else sum(1 for c in fmt.components if not c.is_alpha)

    def key(name: str) -> tuple:
        f = av.VideoFormat(name)
        bits, alpha = _format_bits_alpha(name)
        sub_w = f.chroma_width(2) < 2
        sub_h = f.chroma_height(2) < 2
        fits = (not sub_w or width % 2 == 0) and (not sub_h or height % 2 == 0)
        fits = fits or (salpha and name in (opened or ()))   # libvpx-vp9's yuva420p: any size
        # never a palette, which swscale cannot write (APNG's and GIF's first formats like YUV's, not RGB: every
        # frame failed, ENOTSUP), and a colour source never to grey (the colour dropped) where the codec has colour
        return (name.startswith("pal"), not fits, salpha and not alpha, colours(f) < colours(src), bits < sbits,
                name.startswith(("nv", "yuvj", "bayer")),
                lossless and not f.is_rgb, name != src_pix_fmt,
                f.is_rgb != src.is_rgb, (sub_w or sub_h) != src_sub, abs(bits - sbits), alpha != salpha,
                formats.index(name))

    return min(formats, key=key)


def encoder_options(codec: str, crf: int | None, preset: str | None) -> dict[str, str]:
    """Rate-control options the codec understands (crf/preset for x264/x265, crf for VP9/AV1)."""
    opts: dict[str, str] = {}
    if codec in ("libx264", "libx264rgb", "libx265"):
        if crf is not None:
            opts["crf"] = str(crf)
        if preset:
            opts["preset"] = preset
        if codec == "libx265":
            opts["x265-params"] = "log-level=error"
    elif codec in ("libvpx-vp9", "libaom-av1", "libsvtav1"):
        if crf is not None:
            opts["crf"] = str(crf)
        if codec == "libvpx-vp9":
            opts["b"] = "0"
    return opts


# DNxHD's encoder opens only with a profile (DNxHR, frames from 256x120) or, as DNxHD, a bit rate naming one of its
# fixed formats; without either avcodec_open2 fails (EINVAL): a DNxHR source or --codec dnxhd was never written.
_DNXHR_FOR_FORMAT = {"yuv422p": "dnxhr_hq", "yuv422p10le": "dnxhr_hqx", "yuv444p10le": "dnxhr_444",
                     "gbrp10le": "dnxhr_444"}


def _dnxhd_options(info: VideoInfo, pix_fmt: str) -> dict[str, str]:
    """The dnxhd encoder's profile: a DNxHR source's own at its pixel format, else the DNxHR profile of the pixel
    format (HQ for 8-bit 4:2:2, HQX for 10-bit, 444). A DNxHD source's bit rate as the container measures it names no
    format of the encoder's table (121241600 for its 120 Mb/s): it is written as DNxHR."""
    profile = (info.profile or "").lower().replace(" ", "_")
    if pix_fmt == info.pix_fmt and profile.startswith("dnxhr_"):
        return {"profile": profile}
    return {"profile": _DNXHR_FOR_FORMAT.get(pix_fmt, "dnxhr_hq")}


class VideoWriter:
    """Encode RGB(A) frames like `info`'s source, copying its audio; `commit()` renames into place."""

    def __init__(self, path: str, info: VideoInfo, *, codec: str | None = DEFAULT_CODEC,
                 crf: int | None = DEFAULT_CRF, preset: str | None = DEFAULT_ENCODER_PRESET,
                 pix_fmt: str | None = None, copy_audio: bool = True, overwrite: bool = False,
                 audio: str | None = None, container_format: str | None = None, offset: float = 0.0,
                 end: float | None = None, extra_options: dict[str, str] | None = None,
                 copy_extras: bool = True):
        """`codec` None: the source's family (codec_for). `audio`: "copy" (default, with the subtitle
        streams and every tag), "aac" (audio re-encoded, subtitles copied) or "none"; `copy_audio=False`
        is "none". `copy_extras`: the chapters and attachments too (False: a cluster's segment files)."""
        _require_av()
        container_format = container_format or container_format_for(None, path)
        if path == PIPE and not container_format:
            raise VideoError("standard output: expected a container format (-f y4m, nut, matroska or mpegts)")
        raw = container_format in _RAW_FORMATS
        # the source's family may not go in the output's container: _open then takes the container's own
        self._codec_chosen = None if codec else (crf, preset, pix_fmt, extra_options)
        codec = codec or ("rawvideo" if raw or (path == PIPE and container_format == "nut") else codec_for(info))
        if raw and not pix_fmt:
            pix_fmt = _raw_pix_fmt(container_format, info)
        audio = audio or ("copy" if copy_audio else "none")
        held = [k for k, n in (("audio", info.audio_streams), ("subtitle", info.subtitle_streams)) if n]
        dropped = []  # the writer's first warnings
        if (raw or info.path == PIPE) and audio != "none" and held:
            # a pipe's audio was dropped without a word (an MKV or TS with audio on standard input)
            why = ("standard input is read once, for its video (give the file as INPUT to keep them)"
                   if info.path == PIPE else f"{container_format} holds video only")
            dropped.append(f"{path}: {' and '.join(held)} streams not kept: {why}")
        if info.path == PIPE or raw:
            audio = "none"  # a pipe is read once (its audio is not there to copy); y4m holds video only
        if audio not in ("copy", "aac", "none"):
            raise VideoError(f"{path}: expected --audio copy, aac or none, got {audio!r}")
        self.audio = audio
        self.container_format = container_format
        self.offset = float(offset)  # seconds of the source before the first frame (--start): cut
        self.audio_end = None if end is None else float(end) - self.offset  # --end, in output seconds
        if codec not in av.codecs_available:
            raise VideoError(f"{path}: expected an encoder FFmpeg has (libx264, libx265, ffv1, "
                             f"libx264rgb, prores_ks ...), got {codec!r}")
        try:
            av.Codec(codec, "w")
        except Exception as exc:  # a decoder-only name
            raise VideoError(f"{path}: {codec!r} is not an encoder: {exc}") from exc
        self.path, self.info, self.overwrite = path, info, overwrite
        self.codec = codec
        self.pix_fmt = pix_fmt or choose_pix_fmt(codec, info.pix_fmt, info.width, info.height) or "yuv420p"
        self.frames_written = 0
        self.last_time: float | None = None  # seconds, end of the last frame written
        self._last_pts: int | None = None  # the last frame's, in the stream's time base: each next one is later
        self._retimed = 0  # frames whose source timestamp was not after the one before
        self._last_t: Fraction | None = None  # the last frame's time as the source gave it (seconds)
        self.warnings: list[str] = dropped
        # standard output, and a device or named pipe (/dev/null, a FIFO a player reads): written as it comes; renamed
        # into place, a temporary file replaced the device node itself (as root, /dev/null became a regular file)
        self._tmp = None if path == PIPE or is_special_file(path) else temp_path_for(path)
        self._options = {**encoder_options(codec, crf, preset), **(extra_options or {})}
        if codec == "dnxhd":
            self._options = {**_dnxhd_options(info, self.pix_fmt), **self._options}
        self._audio_in = None
        self._audio_packets: Iterator | None = None
        self._audio_map: dict = {}
        self._lookahead = None
        self._closed = False
        self._decoders: dict = {}  # source audio stream index -> output stream, when re-encoding
        self._copy_extras_too = copy_extras
        kinds = ("audio", "subtitle") if audio != "none" else ()
        try:
            self._open(tuple(k for k in kinds if (info.audio_streams if k == "audio" else info.subtitle_streams)))
        except VideoError:
            if self._tmp is not None:   # standard output has none: unlink(None) hid the error under a TypeError
                remove_quietly(self._tmp)
            raise
        except Exception as exc:
            self._close_quietly()
            try:
                fmt = av.VideoFormat(self.pix_fmt)
                odd = (fmt.chroma_width(2) < 2 and info.width % 2) or (fmt.chroma_height(2) < 2 and info.height % 2)
            except ValueError:   # no such pixel format: the error says so
                odd = False
            # x264's "Generic error in an external library" for --pix-fmt yuv420p at 161x91 named no cause
            hint = (f" ({self.pix_fmt} halves the chroma, which {info.width}x{info.height} cannot: a 4:4:4 format, "
                    f"or leave --pix-fmt out)" if odd else "")
            raise VideoError(f"{path}: cannot start encoding with {self.codec} ({self.pix_fmt}): {exc}{hint}") from exc

    # -- setup ---------------------------------------------------------------------------------
    def _open(self, keep: tuple[str, ...]) -> None:
        """Open the output with the video stream and the source's streams of the kinds in `keep`
        ("audio", "subtitle"); where the container cannot hold them, try again with fewer, and say so."""
        info = self.info
        try:
            target = self._tmp if self._tmp is not None else sys.stdout.buffer if self.path == PIPE else self.path
            # y4m's muxer takes more than 8 bits per sample only as a non-standard extension
            options = {"strict": "-1"} if self.container_format in _RAW_FORMATS and info.bits > 8 else None
            self._out = av.open(target, "w", format=self.container_format, options=options)
        except (av.error.FFmpegError, OSError, ValueError) as exc:
            raise VideoError(f"{self.path}: cannot create the output: {exc}") from exc
        rate = info.fps or Fraction(25)
        if self._codec_chosen is not None and not _container_holds(self._out.format.name, self.codec):
            self._take_containers_codec()
        self._keep_hdr10()
        crf = self._options.get("crf")
        if self.codec in ("libx264", "libx264rgb", "libx265") and crf is not None and float(crf) > 51:
            # --crf goes to 63 for VP9 and AV1; x264 took more as 51 without a word, x265 refused to start
            # ('Invalid data found when processing input')
            self.warnings.append(f"{self.path}: --crf {crf}: {self.codec} takes 0 to 51 (VP9 and AV1 up to 63); "
                                 f"encoded at 51")
            self._options["crf"] = "51"
        if self.codec == "libsvtav1":   # SVT-AV1 logs its whole configuration on stderr; errors only (SVT_LOG=1)
            os.environ.setdefault("SVT_LOG", "1")
        stream = self._out.add_stream(self.codec, rate=rate, options=dict(self._options))
        if info.rotation:
            stream.set_display_rotation(info.rotation)
            if not any(f in _ROTATION_FORMATS for f in self._out.format.name.split(",")):
                # AVI, MPEG-TS, NUT, y4m ... have no display matrix: a phone's clip played on its side without a word
                self.warnings.append(f"{self.path}: display rotation of {info.path} ({info.rotation} degrees) not "
                                     f"kept: {self._out.format.name} does not store it (MP4, MOV, MKV and WebM do); it "
                                     f"plays as stored")
        self._copy_metadata(stream)
        stream.width, stream.height = info.width, info.height
        stream.pix_fmt = self.pix_fmt
        if info.sar:  # anamorphic: shown at width x sar (DV, DVD, HDV); square pixels otherwise
            stream.codec_context.sample_aspect_ratio = info.sar
            if self._out.format.name in _SAR_FROM_STREAM_FORMATS and self.codec not in _SAR_IN_BITSTREAM:
                self.warnings.append(f"{self.path}: pixel aspect ratio {info.sar} of {info.path} not kept: "
                                     f"{self.codec} in {self._out.format.name} does not store it (MP4/MOV do with "
                                     f"any codec, MKV and NUT with libx264 / libx265)")
        if self.codec in _FPS_TIME_BASE_CODECS or info.time_base is None or \
                self.container_format in _RAW_FORMATS or \
                self._out.format.name in _FPS_TIME_BASE_FORMATS:  # y4m reads its frame rate from the time base
            self._time_base = Fraction(1, 1) / rate
        else:
            self._time_base = info.time_base
        stream.time_base = self._time_base
        stream.codec_context.time_base = self._time_base
        out_fmt = av.VideoFormat(self.pix_fmt)
        self._yuv = not out_fmt.is_rgb and not self.pix_fmt.startswith("gray")
        for key, unspecified in _UNSPECIFIED.items():
            value = info.colour.get(key, unspecified)
            # the matrix only onto YUV planes, and never an RGB source's "RGB" (0): players showed the YUV
            # planes as G, B, R (an RGB H.264 / PNG source through libx264: colours off by ~50 levels; VP9 refused)
            if key == "colorspace" and (not self._yuv or value == 0):
                continue
            if value != unspecified:
                setattr(stream.codec_context, key, value)
        if self._yuv and info.colour.get("color_range", 0) == 0:
            stream.codec_context.color_range = 1  # tag what swscale writes: limited (MPEG) range
        self._stream = stream
        self._sws = _sws_flags()
        out_bits = _format_bits_alpha(self.pix_fmt)[0]
        if out_bits < info.bits:
            self.warnings.append(f"{self.path}: {info.bits}-bit source written as {out_bits}-bit "
                                 f"{self.pix_fmt} ({self.codec} has no deeper format)")
        if info.has_alpha and not _format_bits_alpha(self.pix_fmt)[1]:
            self.warnings.append(f"{self.path}: {self.codec} ({self.pix_fmt}) has no alpha; alpha dropped")
        kept = self._copy_extras()
        if keep:
            try:
                self._start_audio(keep)
                self._out.start_encoding()
            except Exception as exc:  # e.g. SRT subtitles in MP4, or AAC in WebM
                dropped = keep[-1]
                # re-encoding helps only where the container holds AAC and it was not asked already (GIF, APNG, WebP)
                hint = (" (--audio aac re-encodes the audio)" if self.audio == "copy" and
                        _container_holds(self._out.format.name, "aac") else "") if dropped == "audio" \
                    else " (MKV holds them)"
                self.warnings.append(f"{self.path}: {dropped} streams not kept: {self._out.format.name} "
                                     f"cannot hold them ({exc}){hint}")
                self._close_quietly()
                self._audio_map, self._decoders = {}, {}
                self._open(keep[:-1])
                return
        else:
            self._out.start_encoding()
        for what in self.info.other_streams:
            if what not in kept:  # data streams, or attachments of a source this could not open
                self.warnings.append(f"{self.path}: {what} of {self.info.path} not kept")

    def _keep_hdr10(self) -> None:
        """The source's HDR10 static metadata (VideoInfo.hdr10) into libx265's parameters (its SEI); named where the
        encoder cannot write it (the colour tags are kept apart, by every encoder)."""
        if not self.info.hdr10:
            return
        if self.codec == "libx265":
            params = [p for p in self._options.get("x265-params", "").split(":") if p]
            self._options["x265-params"] = ":".join(params + list(self.info.hdr10))
        else:
            self.warnings.append(f"{self.path}: the HDR10 mastering display / light level metadata of {self.info.path} "
                                 f"not kept: only libx265 writes it here (--codec libx265)")

    def _take_containers_codec(self) -> None:
        """No --codec and the source's family cannot go in the output's container (H.264 in WebM, ProRes in
        MP4): the container's own encoder (WebM: VP9), said in a warning."""
        crf, preset, pix_fmt, extra = self._codec_chosen
        default = av.Codec(self._out.default_video_codec, "w").name
        self.warnings.append(f"{self.path}: {self._out.format.name} cannot hold {self.codec}; encoded with "
                             f"{default} (--codec picks another)")
        self.codec = default
        self.pix_fmt = pix_fmt or choose_pix_fmt(default, self.info.pix_fmt, self.info.width,
                                                 self.info.height) or "yuv420p"
        self._options = {**encoder_options(default, crf, preset), **(extra or {})}
        self._codec_chosen = None

    def _copy_extras(self) -> set[str]:
        """The source's chapters and attachments (copy_chapters_and_attachments); returns the streams
        dealt with, as info.other_streams names them."""
        if not self._copy_extras_too:
            return set(self.info.other_streams)  # the caller copies them (the cluster's join)
        if self.info.path == PIPE:
            return set()  # read once: nothing to copy them from
        try:
            with av.open(self.info.path) as src:
                kept, warnings = copy_chapters_and_attachments(src, self._out, self.offset, self.audio_end)
        except (av.error.FFmpegError, OSError):
            return set()  # a source that is not a video file (frames encoded into one)
        self.warnings += [f"{self.path}: {w}" for w in warnings]
        return kept

    def _copy_metadata(self, video_stream) -> None:
        """The container's tags (title, dates, ...) and the video stream's (language, title)."""
        if self.info.path == PIPE:
            return
        try:
            with av.open(self.info.path) as src:
                _copy_tags(src.metadata, self._out.metadata)
                _copy_tags(src.streams.video[0].metadata, video_stream.metadata)
        except (av.error.FFmpegError, OSError, IndexError):
            pass  # a source that is not a video file (frames encoded into one): nothing to copy

    def _start_audio(self, keep: tuple[str, ...]) -> None:
        """The source's audio and subtitle streams (those of the kinds in `keep`), copied (or audio
        re-encoded with --audio aac), with their tags (language, title) and disposition."""
        self._audio_in = av.open(self.info.path)
        ins = [s for s in self._audio_in.streams if s.type in keep]
        for s in ins:
            if s.type == "audio" and self.audio == "aac":
                out = self._out.add_stream("aac", rate=s.codec_context.sample_rate or 48000)
                layout = s.codec_context.layout
                # a layout of unspecified order ("1 channels": PCM in MKV, WAV), which the AAC encoder refuses
                # (avcodec_open2: Invalid argument, the audio dropped): the default layout of its channel count
                unordered = layout.name.endswith(" channels")
                out.layout = _DEFAULT_LAYOUTS.get(len(layout.channels), layout) if unordered else layout
                self._decoders[s.index] = out
            else:
                out = self._out.add_stream_from_template(s)
            _copy_tags(s.metadata, out.metadata)
            out.disposition = s.disposition
            self._audio_map[s.index] = out
        self._audio_packets = iter(self._audio_in.demux(*ins))

    # -- writing -------------------------------------------------------------------------------
    def write(self, frame: np.ndarray, when: FrameTime | None = None) -> None:
        """Encode one RGB(A) frame (uint8 or uint16, as decoded) at the source frame's timestamp."""
        vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format=self._array_format(frame))
        tb = self._time_base
        if when is not None and when.pts is not None and when.time_base:
            t = when.pts * Fraction(when.time_base) - Fraction(self.offset).limit_denominator(1_000_000)
            if self.offset and t < 0 and not self.frames_written:
                # --start between two frames: read_video keeps the frame nearest to it, up to half a frame before.
                # The output starts at that frame, audio too: at a negative time MP4's edit list hid it (one frame
                # fewer than written), MKV's muxer moved it to 0 and every later frame with it
                self.offset += float(t)
                if self.audio_end is not None:
                    self.audio_end -= float(t)
                t = Fraction(0)
        else:
            t = self.frames_written / (self.info.fps or Fraction(25))
        pts = int(round(t / tb))
        source_t, previous_t, self._last_t = t, self._last_t, t
        if self._last_pts is not None and pts <= self._last_pts:
            # a damaged timestamp (a corrupt block's, or one far ahead before it): the muxer refuses a frame
            # that is not after the one before; it goes one frame after that one instead
            t = (self._last_pts + 1) * tb + (1 / (self.info.fps or Fraction(25)) - tb)
            pts = int(round(t / tb))
            if not self._retimed:
                # a variable frame rate into a container of one rate (AVI, y4m: a time base of one frame): frames
                # closer than a frame apart share a tick, and were called damaged
                why = ("timestamp not after the previous frame's (damaged input?)"
                       if previous_t is None or source_t <= previous_t else
                       f"less than a frame after the previous one (a variable frame rate), and "
                       f"{self._out.format.name} here holds one frame per 1/{1 / tb} s")
                self.warnings.append(f"{self.path}: frame {self.frames_written} (and any later like it): {why}: "
                                     f"written one frame after it, later than in the source")
            self._retimed += 1
        vf.pts = self._last_pts = pts
        vf.time_base = tb
        if self._yuv:
            vf = vf.reformat(format=self.pix_fmt, dst_colorspace=self._colorspace(),
                             dst_color_range=self._stream.codec_context.color_range or 1,
                             interpolation=self._sws)
        for packet in self._stream.encode(vf):
            self._out.mux(packet)
        self.frames_written += 1
        self.last_time = float(t + 1 / (self.info.fps or Fraction(25)))
        if self._audio_packets is not None:
            self._copy_audio(until=self.last_time)

    def _array_format(self, frame: np.ndarray) -> str:
        c = frame.shape[2] if frame.ndim == 3 else 1
        if frame.dtype == np.uint16:
            return "rgba64le" if c == 4 else "rgb48le"
        if frame.dtype == np.uint8:
            return "rgba" if c == 4 else "rgb24"
        raise VideoError(f"{self.path}: frame {self.frames_written}: expected uint8 or uint16 "
                         f"RGB(A), got {frame.dtype} with {c} channels")

    def _colorspace(self):
        cs = self.info.colour.get("colorspace", 2)
        return None if cs in (0, 2) else cs

    def _copy_audio(self, until: float | None) -> None:
        """Mux audio packets up to `until` seconds (all when None), interleaved with the video."""
        while True:
            pkt = self._lookahead
            if pkt is None:
                try:
                    pkt = next(self._audio_packets)
                except (StopIteration, av.error.FFmpegError, EOFError):
                    self._audio_packets = None
                    return
            if pkt.dts is None:  # the demuxer's end-of-stream marker
                self._lookahead = None
                continue
            t = (float(pkt.pts * pkt.time_base) if pkt.pts is not None else float(pkt.dts * pkt.time_base)) \
                - self.offset
            if until is not None and t >= until:
                self._lookahead = pkt
                return
            self._lookahead = None
            if self.offset:
                # before --start (or the container's first timestamp); the offset is a float and the container's
                # start time whole microseconds: a packet at the very start came out a hair before it, and was lost
                if t < -_START_SLACK:
                    continue
                shift = int(round(self.offset / pkt.time_base))
                pkt.pts = None if pkt.pts is None else max(0, pkt.pts - shift)
                pkt.dts = None if pkt.dts is None else max(0, pkt.dts - shift)
            index = pkt.stream.index
            if index in self._decoders:  # --audio aac: decode, re-encode
                for frame in pkt.decode():
                    frame.pts = None
                    for out in self._decoders[index].encode(frame):
                        self._out.mux(out)
                continue
            pkt.stream = self._audio_map[index]
            self._out.mux(pkt)

    # -- finishing -----------------------------------------------------------------------------
    def commit(self, *, audio_until: float | None = None) -> None:
        """Flush the encoder, copy the remaining audio (up to `audio_until` s), close, rename."""
        try:
            for packet in self._stream.encode():
                self._out.mux(packet)
            if self._audio_packets is not None:
                self._copy_audio(until=audio_until if audio_until is not None else self.audio_end)
            for stream in self._decoders.values():  # flush the audio encoders
                for packet in stream.encode(None):
                    self._out.mux(packet)
            self._out.close()
            self._closed = True
            if self._audio_in is not None:
                self._audio_in.close()
            if self._tmp is not None:
                publish(self._tmp, self.path, self.overwrite)
        except av.error.FFmpegError as exc:  # the encoder's or muxer's last packets
            self.abort()
            raise VideoError(f"{self.path}: cannot finish writing ({exc}); not written") from exc
        except BaseException:
            self.abort()
            raise

    def abort(self) -> None:
        """Close without keeping anything: the temporary file is removed."""
        self._close_quietly()
        if self._tmp is not None:
            remove_quietly(self._tmp)

    def _close_quietly(self) -> None:
        for obj in (getattr(self, "_out", None), self._audio_in):
            if obj is None:
                continue
            try:
                obj.close()
            except Exception:  # noqa: BLE001 - closing a half-written output after the real error
                pass
        self._audio_in = None
        self._audio_packets = None
        self._lookahead = None


# -- OpenCV fallback ----------------------------------------------------------------------------
def probe_video_cv(path: str) -> VideoInfo:
    """Describe a video through OpenCV (8-bit, no audio): the fallback when PyAV is missing."""
    import cv2

    cap = cv2.VideoCapture(path)
    try:
        if not cap.isOpened():
            raise VideoError(f"{path}: expected a video OpenCV can read, got none")
        w, h = int(cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        fps = cap.get(cv2.CAP_PROP_FPS) or 25.0
        n = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) or None
        if w < 1 or h < 1:
            raise VideoError(f"{path}: expected a video with a size, got {w}x{h}")
        return VideoInfo(path=path, width=w, height=h, fps=Fraction(fps).limit_denominator(1001),
                         time_base=None, frames=n, pix_fmt="bgr24", bits=8, has_alpha=False,
                         codec="opencv", colour=dict(_UNSPECIFIED), audio_streams=0)
    finally:
        cap.release()


def read_video_cv(info: VideoInfo) -> Iterator[Item]:
    """Frames through cv2.VideoCapture, converted to RGB uint8 like `read_video`."""
    import cv2

    cap = cv2.VideoCapture(info.path)
    n, last_s = 0, None
    try:
        while True:
            ok, bgr = cap.read()
            if not ok:
                break
            last_s = cap.get(cv2.CAP_PROP_POS_MSEC) / 1000.0   # the frame just read
            yield Item(np.ascontiguousarray(bgr[:, :, ::-1]), None)
            n += 1
        # OpenCV's count of an MKV / WebM is its duration x the mean rate: a variable rate has fewer frames, so a
        # short count is a truncation only where the last frame also comes well before that duration (as read_video)
        fps = float(info.fps or 25)
        expected_s = (info.frames or 0) / fps
        if info.frames and n + max(2, info.frames // 50) < info.frames and \
                (not last_s or last_s + max(0.05 * expected_s, 3.0 / fps) < expected_s):
            raise VideoReadError(f"{info.path}: the stream ended at frame {n}, expected about "
                                 f"{info.frames} frames (truncated file?)", n)
    finally:
        cap.release()


class CvVideoWriter:
    """cv2.VideoWriter with the VideoWriter interface: mp4v, 8-bit, no audio; temp name + rename."""

    def __init__(self, path: str, info: VideoInfo, *, fourcc: str = "mp4v", overwrite: bool = False):
        import cv2

        self.path, self.info, self.overwrite = path, info, overwrite
        self.frames_written = 0
        self.last_time: float | None = None
        self.warnings: list[str] = []
        self._tmp = temp_path_for(path)
        self._cv2 = cv2
        self._w = cv2.VideoWriter(self._tmp, cv2.VideoWriter_fourcc(*fourcc), float(info.fps or 25),
                                  (info.width, info.height))
        if not self._w.isOpened():
            remove_quietly(self._tmp)
            raise VideoError(f"{path}: OpenCV cannot write {fourcc} here")
        if info.audio_streams:
            self.warnings.append(f"{path}: the OpenCV fallback does not copy audio")

    def write(self, frame: np.ndarray, when: FrameTime | None = None) -> None:
        if frame.dtype != np.uint8:
            frame = (frame >> 8).astype(np.uint8) if frame.dtype == np.uint16 else frame
        self._w.write(np.ascontiguousarray(frame[:, :, 2::-1]))
        self.frames_written += 1

    def commit(self, *, audio_until: float | None = None) -> None:
        self._w.release()
        try:
            publish(self._tmp, self.path, self.overwrite)
        except BaseException:
            remove_quietly(self._tmp)
            raise

    def abort(self) -> None:
        self._w.release()
        remove_quietly(self._tmp)
