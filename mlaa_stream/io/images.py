"""Still images through OpenImageIO: read and write keeping bit depth, channels, alpha and metadata.

Every output is written under a temporary name in its destination directory, checked (it opens,
has the expected size and decodes to the end; PNG and JPEG also end with their terminating marker,
because their writers report no error when the disk fills up) and only then renamed, so a final name
never holds a half-written file (also on Ctrl-C, SIGTERM or a full disk).
"""
from __future__ import annotations

import errno
import itertools
import os
import re
import shutil
import struct
import tempfile
from dataclasses import dataclass
from functools import lru_cache
from typing import Callable

import numpy as np
import OpenImageIO as oiio

# Sample types the filter takes as they are.
_NATIVE = {"uint8": np.uint8, "uint16": np.uint16, "half": np.float16, "float": np.float32}
# Sample types read as they are too (a double or 8/16/32-bit integer TIFF) but filtered as float32 (integers scaled
# to [-1, 1] as OpenImageIO converts them): split_for_filter puts back only the samples the filter changed, so the
# others come back bit for bit (float32 holds neither a double nor an integer over 2^24). Any other type, and a file
# whose channels have several types (an EXR's half colour and uint ids), is read as float32.
_WIDE = {"double": np.float64, "int8": np.int8, "int16": np.int16, "uint": np.uint32, "int": np.int32}

# Formats whose alpha is associated (colour premultiplied by alpha): EXR always, TIFF where its file says so (read
# with oiio:UnassociatedAlpha unset). Every other format (PNG, TGA, WebP, BMP ...) stores straight alpha.
_PREMULTIPLIED_FORMATS = ("openexr", "tiff")

_TMP_MARK = ".mlaa-tmp"
_tmp_counter = itertools.count()


class ImageReadError(Exception):
    """An input image could not be read; the message names the file."""


class ImageWriteError(Exception):
    """An output image could not be written; the message names the file."""


@dataclass
class Image:
    """Pixels as (H, W, C) in the file's sample type (or float32), and the file's spec for writing back."""

    pixels: np.ndarray
    spec: oiio.ImageSpec
    path: str
    conversions: tuple[str, ...] = ()  # colour-model changes made on reading (CMYK, palette), to report
    quality: int | None = None  # a JPEG's quality, estimated from its quantisation table (jpeg_quality): kept
    lossy: tuple[str, ...] = ()  # what writing back cannot keep bit for bit (inexact_channels), to warn about
    format_name: str = ""  # OpenImageIO's name of the file's format ("openexr"): whether its channel names say much

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(self.spec.channelnames)


@lru_cache(maxsize=None)
def _format_extensions() -> dict[str, frozenset[str]]:
    """OpenImageIO's format names -> their file extensions (lower case, with the dot)."""
    formats = {}
    for entry in oiio.get_string_attribute("extension_list").split(";"):
        name, _, names = entry.partition(":")
        formats[name] = frozenset("." + n.lower() for n in names.split(",") if n)
    return formats


def image_extensions() -> frozenset[str]:
    """File extensions OpenImageIO can read (lower case, with the dot)."""
    exts = set().union(*_format_extensions().values())
    exts.discard(".null")
    exts.discard(".nul")
    exts.discard(".term")
    return frozenset(exts)


def is_image_path(path: str) -> bool:
    """True when the extension is one OpenImageIO reads (the file itself is not opened)."""
    return os.path.splitext(path)[1].lower() in image_extensions()


def has_writer(path: str) -> bool:
    """True when OpenImageIO has a writer for `path`'s extension (nothing is opened or created)."""
    out = oiio.ImageOutput.create(path)
    if out is None:
        oiio.geterror()  # clear it
        return False
    return True


def is_temp_path(path: str) -> bool:
    """True for our own temporary output names (skipped when listing a folder)."""
    return _TMP_MARK in os.path.basename(path)


def read_image(path: str) -> Image:
    """Read subimage 0 of `path` as stored: uint8/uint16/half/float and the _WIDE types kept, others as float32."""
    config = oiio.ImageSpec()
    # Unassociated alpha (PNG, TIFF) is returned as stored instead of premultiplied, so it round-trips.
    config.attribute("oiio:UnassociatedAlpha", 1)
    try:
        size = os.path.getsize(path)
    except OSError as exc:
        if os.path.islink(path):  # a frame linked from a cache or another shot that is gone
            raise ImageReadError(f"{path}: cannot read: a link to {os.readlink(path)}, which does not exist") from exc
        raise ImageReadError(f"{path}: cannot read ({exc.strerror})") from exc
    if size == 0:
        raise ImageReadError(f"{path}: expected an image, got an empty file")
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise ImageReadError(f"{path}: expected an image OpenImageIO can read, got: "
                             f"{oiio.geterror() or 'unknown format'}")
    try:
        spec = inp.spec()
        if spec.width < 1 or spec.height < 1 or spec.nchannels < 1:
            raise ImageReadError(f"{path}: expected at least 1x1 pixels and one channel, "
                                 f"got {spec.width}x{spec.height} with {spec.nchannels} channels")
        if spec.depth > 1:
            raise ImageReadError(f"{path}: expected a 2D image, got a volume of depth {spec.depth}")
        if inp.seek_subimage(1, 0):  # only the first would be filtered and written: refuse, lose nothing
            count = 2
            while count < 10_000 and inp.seek_subimage(count, 0):
                count += 1
            if inp.format_name() == "openexr":
                # the parts of one frame (beauty, depth, AOVs), not frames: FFmpeg's advice does not apply
                parts = []
                for k in range(min(count, 8)):
                    inp.seek_subimage(k, 0)
                    parts.append(inp.spec().get_string_attribute("name", "") or f"part {k}")
                more = ", ..." if count > len(parts) else ""
                raise ImageReadError(f"{path}: expected a single-part EXR, got a multi-part file with {count} parts "
                                     f"({', '.join(parts)}{more}); write the part to filter as its own file first "
                                     f"(e.g. oiiotool {os.path.basename(path)} --subimage {parts[0]!r} -o part.exr)")
            raise ImageReadError(f"{path}: expected a single image, got {count} (an animated or multi-page "
                                 f"file); filter it as a video or split it into frames first "
                                 f"(e.g. ffmpeg -i {os.path.basename(path)} frames/%04d.png)")
        inp.geterror()  # clear the probe's 'could not seek to subimage 1': a failed read must report its own error
        # reopened after the probe: a failed seek leaves some readers unable to decode subimage 0 (WebP's:
        # "Couldn't decode subimage 0", even after seeking back), so every WebP was refused as unreadable
        inp.close()
        inp = oiio.ImageInput.open(path, config)
        if inp is None:
            raise ImageReadError(f"{path}: expected an image OpenImageIO can read, got: "
                                 f"{oiio.geterror() or 'unknown format'}")
        spec = inp.spec()   # the reopened input's: the first one's is gone with it
        conversions = _conversions(path, spec)
        fmt = str(spec.format)
        read_fmt = fmt if fmt in _NATIVE or (fmt in _WIDE and not spec.channelformats) else "float"
        pixels = inp.read_image(0, 0, 0, spec.nchannels, read_fmt)
        # a truncated JPEG decodes with its missing rows grey and only an error ("Premature end of JPEG file")
        err = inp.geterror() if pixels is None or inp.has_error else ""
        if pixels is None or err:
            raise ImageReadError(f"{path}: reading pixels failed: {err or 'unknown error'}")
        spec = oiio.ImageSpec(spec)  # a copy that outlives the ImageInput
        if spec.alpha_channel >= 0 and inp.format_name() not in _PREMULTIPLIED_FORMATS:
            spec.attribute("oiio:UnassociatedAlpha", 1)  # straight alpha, also where the reader does not say so (BMP)
        format_name = inp.format_name()
        quality = jpeg_quality(path) if format_name == "jpeg" else None
        lossy = inexact_channels(inp, spec) if read_fmt == "float" else ()
    finally:
        inp.close()
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return Image(pixels=pixels, spec=spec, path=path, conversions=conversions, quality=quality, lossy=lossy,
                 format_name=format_name)


def inexact_channels(inp: oiio.ImageInput, spec: oiio.ImageSpec) -> tuple[str, ...]:
    """A warning naming the 32-bit integer channels of an open image (an EXR's UINT object-id pass) that hold values
    float32 cannot (over 2^24), or (): OpenImageIO reads them into, and writes them from, one sample type for every
    channel, float32 here, so such ids -- hashes -- come back rounded though no filter touched them."""
    formats = spec.channelformats or (spec.format,) * spec.nchannels
    names = tuple(spec.channelnames)
    wide = []
    for c, fmt in enumerate(formats):
        if str(fmt) in ("uint", "int"):
            native = inp.read_image(0, 0, c, c + 1, str(fmt))
            if native is not None and np.abs(np.asarray(native, np.int64)).max(initial=0) > 1 << 24:
                wide.append(names[c] if c < len(names) else f"channel {c}")
    if not wide:
        return ()
    return (f"{', '.join(wide)}: 32-bit integer channel{'s' if len(wide) > 1 else ''} with values over 2^24 "
            f"(ids); OpenImageIO reads and writes {'them' if len(wide) > 1 else 'it'} through float32, so "
            f"{'they come' if len(wide) > 1 else 'it comes'} back rounded to 24 significant bits, not bit for bit",)


# JPEG outputs whose source had no quality to keep (not a JPEG): OpenImageIO's own default (measured: its
# quantisation tables are libjpeg's at 98), what they were written at before.
DEFAULT_JPEG_QUALITY = 98
_JPEG_EXTENSIONS = frozenset({".jpg", ".jpeg", ".jpe", ".jfif"})
# libjpeg's (IJG's) base luminance quantisation table (ITU T.81 Annex K), in natural order, and the zigzag order
# a DQT segment stores tables in (position k of the segment holds entry _ZIGZAG[k])
_IJG_LUMINANCE = (16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56,
                  14, 17, 22, 29, 51, 87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92,
                  49, 64, 78, 87, 103, 121, 120, 101, 72, 92, 95, 98, 112, 100, 103, 99)
_ZIGZAG = (0, 1, 8, 16, 9, 2, 3, 10, 17, 24, 32, 25, 18, 11, 4, 5, 12, 19, 26, 33, 40, 48, 41, 34, 27, 20, 13, 6, 7, 14,
           21, 28, 35, 42, 49, 56, 57, 50, 43, 36, 29, 22, 15, 23, 30, 37, 44, 51, 58, 59, 52, 45, 38, 31, 39, 46, 53,
           60, 61, 54, 47, 55, 62, 63)


def _ijg_table(quality: int) -> tuple[int, ...]:
    """The luminance table libjpeg's jpeg_set_quality(quality, force_baseline=TRUE) writes, in zigzag order."""
    scale = 5000 // quality if quality < 50 else 200 - 2 * quality
    return tuple(min(max((_IJG_LUMINANCE[n] * scale + 50) // 100, 1), 255) for n in _ZIGZAG)


def _luminance_table(path: str) -> tuple[int, ...] | None:
    """A JPEG's quantisation table 0 (luma's, in zigzag order) from its DQT segment, or None (no JPEG, no table)."""
    try:
        with open(path, "rb") as fh:
            if fh.read(2) != b"\xff\xd8":
                return None
            while True:
                if fh.read(1) != b"\xff":
                    return None   # segments follow each other: anything else is a damaged file
                marker = fh.read(1)
                while marker == b"\xff":  # fill bytes
                    marker = fh.read(1)
                if not marker or marker in (b"\xda", b"\xd9"):  # the scan (or the end) before any table 0
                    return None
                if 0xd0 <= marker[0] <= 0xd7 or marker == b"\x01":  # markers without a length
                    continue
                head = fh.read(2)
                if len(head) < 2:
                    return None
                data = fh.read(struct.unpack(">H", head)[0] - 2)
                if marker != b"\xdb":
                    continue
                i = 0
                while i < len(data):  # a DQT segment may hold several tables: Pq (precision) Tq (id), 64 values
                    wide, table = data[i] >> 4, data[i] & 15
                    size = 128 if wide else 64
                    values = data[i + 1:i + 1 + size]
                    if len(values) < size:
                        return None
                    if table == 0:
                        return tuple(struct.unpack(">64H", values)) if wide else tuple(values)
                    i += 1 + size
    except OSError:
        return None


def jpeg_quality(path: str) -> int | None:
    """The quality (1-100) a JPEG was saved at, estimated from its luma quantisation table: the libjpeg quality
    whose table is nearest (sum of absolute differences; exact for libjpeg's own -- OpenImageIO, Pillow, ImageMagick,
    GIMP, ffmpeg -- other encoders' tables, a camera's, get the nearest). None where the file has no table."""
    table = _luminance_table(path)
    if table is None:
        return None
    return min(range(1, 101), key=lambda q: sum(abs(a - b) for a, b in zip(_ijg_table(q), table)))


def _conversions(path: str, spec: oiio.ImageSpec) -> tuple[str, ...]:
    """The colour-model conversions OpenImageIO makes on reading, which the output keeps."""
    notes = []
    model = spec.get_string_attribute("jpeg:ColorSpace", "")
    if model.upper() in ("CMYK", "YCCK"):
        notes.append(f"{model} converted to RGB (written back as RGB)")
    bits = spec.get_int_attribute("oiio:BitsPerSample", 0)
    if 0 < bits < 8:
        notes.append(f"{bits}-bit samples written back as 8-bit (the blended edges need the levels between)")
    if os.path.splitext(path)[1].lower() == ".png":
        with open(path, "rb") as fh:
            header = fh.read(26)
        if len(header) == 26 and header[25] == 3:  # IHDR colour type 3: indexed colour
            notes.append("palette colours expanded to RGB (written back as RGB)")
    return tuple(notes)


def filtered_channels(nchannels: int, alpha_channel: int = -1) -> int:
    """How many leading channels go through the filter; the rest pass through unchanged.

    1, 3, 4: all (the filter itself keeps a 4th channel, alpha, unchanged); 2 (grey + alpha): the
    grey one; more than 4 (e.g. RGBA + Z in an EXR): RGBA when alpha is the 4th channel, else RGB.
    """
    if nchannels == 2:
        return 1
    if nchannels <= 4:
        return nchannels
    return 4 if alpha_channel == 3 else 3


# Names of layers that hold the rendered image itself, preferred among several RGB layers of an EXR
# (Blender's "ViewLayer.Combined", Arnold/RenderMan/Houdini's "beauty"/"rgba"/"C").
_BEAUTY_LAYERS = ("combined", "beauty", "rgba", "c")


def cryptomatte_channels(names: tuple[str, ...], spec: oiio.ImageSpec | None = None) -> frozenset[int]:
    """The channels of `names` that hold cryptomatte ids and coverages (float ids that any blend corrupts).

    Cryptomatte stores each type as layers "<name>00", "<name>01" ... (R, B: ids; G, A: coverage) and names
    them in the header ("cryptomatte/<key>/name": "CryptoObject", Blender's "ViewLayer.CryptoObject"); Arnold
    adds a preview layer "<name>" itself. Those layers, and any layer whose last part starts with "crypto" (a
    file whose header was dropped on the way), are data, never colour.
    """
    types = set()
    if spec is not None:
        for attr in spec.extra_attribs:
            if re.fullmatch(r"cryptomatte/[^/]+/name", attr.name) and isinstance(attr.value, str) and attr.value:
                types.add(attr.value)
    found = set()
    for k, name in enumerate(names):
        layer, dot, _ = name.rpartition(".")
        if not dot:
            continue
        if layer.rpartition(".")[2].lower().startswith("crypto") or any(
                layer == t or re.fullmatch(re.escape(t) + r"\d+", layer) for t in types):
            found.add(k)
    return frozenset(found)


def filter_channel_indices(names: tuple[str, ...], alpha_channel: int = -1,
                           data: frozenset[int] = frozenset()) -> tuple[int, ...]:
    """The channels that go through the filter, in the order it takes them (R, G, B[, A] or one grey).

    By name where the names say which channels are colour (colour_by_name), else by position (filtered_channels).
    `data`: channels that are never filtered (cryptomatte_channels: ids); () where no other channel is left.
    """
    named = colour_by_name(names, alpha_channel, data)
    if named:
        return named
    # by position among the channels that may be filtered (OpenImageIO may have taken a cryptomatte A for alpha)
    rest = [k for k in range(len(names)) if k not in data]
    alpha = rest.index(alpha_channel) if alpha_channel in rest else -1
    return tuple(rest[:filtered_channels(len(rest), alpha)]) if rest else ()


def colour_by_name(names: tuple[str, ...], alpha_channel: int = -1,
                   data: frozenset[int] = frozenset()) -> tuple[int, ...]:
    """The colour channels the names say, in the filter's order, or () where they say none: plain R, G, B (+ A),
    else plain Y, else the R, G, B (+ A) of one layer of a multi-layer EXR ("ViewLayer.Combined.R" ...): the layer of
    the alpha channel, else a beauty layer by name, else the first. OpenImageIO lists an EXR's channels by layer
    name, so a pass that sorts first (Blender's "AO" before "Combined", a plain "Z" before "diffuse.R") would
    otherwise be filtered in the beauty's place. `data` (cryptomatte_channels) are never colour.
    """
    where = {name: k for k, name in enumerate(names) if k not in data}
    if all(c in where for c in "RGB"):
        return tuple(where[c] for c in "RGBA" if c in where)
    if "Y" in where:
        return (where["Y"],)
    layers: dict[str, dict[str, int]] = {}
    for k, name in enumerate(names):
        layer, dot, last = name.rpartition(".")
        if dot and last in ("R", "G", "B", "A") and k not in data:
            layers.setdefault(layer, {})[last] = k
    rgb = [(layer, chans) for layer, chans in layers.items() if all(c in chans for c in "RGB")]
    if not rgb:
        return ()

    def rank(entry: tuple[str, dict[str, int]]) -> int:
        layer, chans = entry
        if alpha_channel >= 0 and chans.get("A") == alpha_channel:
            return 0
        return 1 if layer.rpartition(".")[2].lower() in _BEAUTY_LAYERS else 2
    _, chans = min(rgb, key=rank)  # min keeps the first of equal rank: channel order
    return tuple(chans[c] for c in "RGBA" if c in chans)


# Formats whose files name their channels (an EXR's "Z", "N.x", "motion.u"); other formats' names are OpenImageIO's
# defaults by position (a 2-channel TIFF's "R", "G" is grey and alpha), which say nothing of what a channel holds.
NAMED_CHANNEL_FORMATS = ("openexr",)


def without_colour(image: Image) -> str | None:
    """Why `image` holds nothing to filter -- "no colour channels (Z)", "only cryptomatte channels (...)" -- or
    None where it has colour: a file that names its channels (an EXR) and names no colour (colour_by_name) holds data
    -- depth, normals, positions, motion vectors, ids --, which a blend corrupts (a depth between two surfaces is
    neither's). Render pipelines write such passes as files of their own beside the beauty."""
    return no_colour_reason(image.format_name, image.spec, image.pixels.shape[2])


def no_colour_reason(format_name: str, spec: oiio.ImageSpec, channels: int) -> str | None:
    """without_colour's verdict from a file's format name, spec and number of channels read (the compare command
    reads pixels itself)."""
    names = tuple(spec.channelnames)
    if format_name not in NAMED_CHANNEL_FORMATS or len(names) != channels:
        return None
    data = cryptomatte_channels(names, spec)
    if colour_by_name(names, spec.alpha_channel, data):
        return None
    shown = ", ".join(names[:6]) + (f" and {len(names) - 6} more" if len(names) > 6 else "")
    return f"{'only cryptomatte' if len(data) == len(names) else 'no colour'} channels ({shown})"


def split_for_filter(image: Image) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The frame the filter sees and a function that puts its result back among the other channels.

    Cryptomatte channels (ids) are never in the frame; an image without colour channels (without_colour) is refused
    (ImageReadError): image_source passes such a file through unfiltered instead. Samples of a _WIDE type (double,
    8/16/32-bit integers) go to the filter as float32, and only those it changed come back from it (in the file's
    type): the others are put back as read, bit for bit.
    """
    frame, merge = _split_channels(image)
    if frame.dtype.type not in _WIDE.values():
        return frame, merge
    sent = _as_float32(frame)
    return sent, lambda out: merge(_changed_only(out, sent, frame))


def _as_float32(samples: np.ndarray) -> np.ndarray:
    """Samples of a _WIDE type as float32, integers scaled by their type's maximum (as OpenImageIO converts them)."""
    if samples.dtype.kind == "f":
        with np.errstate(over="ignore"):   # beyond float32: inf, which the filter leaves; put back as read
            return samples.astype(np.float32)
    return (samples / float(np.iinfo(samples.dtype).max)).astype(np.float32)


def _changed_only(out: np.ndarray, sent: np.ndarray, native: np.ndarray) -> np.ndarray:
    """`native` with the samples the filter changed (its float32 `out` differs from `sent`, what it was given, bit
    for bit: a NaN it kept counts as kept) replaced by `out` in native's type (integers rounded, clipped)."""
    out = np.asarray(out, np.float32).reshape(sent.shape)
    changed = out.view(np.uint32) != sent.view(np.uint32)
    result = native.copy()
    if native.dtype.kind == "f":
        result[changed] = out[changed]
    else:
        info = np.iinfo(native.dtype)
        result[changed] = np.clip(np.rint(out[changed].astype(np.float64) * info.max), info.min, info.max)
    return result


def _split_channels(image: Image) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """split_for_filter's channels: the frame in the image's own sample type, and the function putting it back."""
    pixels = image.pixels
    nchannels = pixels.shape[2]
    names = tuple(image.spec.channelnames)
    if len(names) != nchannels:  # a spec that does not describe these pixels: by position
        names = ("",) * nchannels
    reason = without_colour(image)
    data = cryptomatte_channels(names, image.spec)
    idx = filter_channel_indices(names, image.spec.alpha_channel, data)
    if reason is not None or not idx:  # blending data (depth, ids) would corrupt it: refuse, write nothing
        reason = reason or f"only cryptomatte channels ({', '.join(names[k] for k in sorted(data))})"
        raise ImageReadError(f"{image.path}: expected colour channels to filter, got {reason}; data must not be "
                             f"blended")
    alpha = image.spec.alpha_channel
    if len(idx) == 1 and 0 <= alpha < nchannels and alpha not in data and alpha != idx[0]:
        # grey + alpha: the filter takes RGBA (the grey three times, R = G = B stays so) to filter the alpha as
        # coverage with it (spatial/alpha.py); its R and A come back
        grey = idx[0]

        def merge_grey(out: np.ndarray) -> np.ndarray:
            full = pixels.copy()
            full[:, :, grey], full[:, :, alpha] = out[:, :, 0], out[:, :, 3]
            return full

        return np.ascontiguousarray(pixels[:, :, [grey, grey, grey, alpha]]), merge_grey
    if idx == tuple(range(nchannels)):
        return pixels, lambda out: out
    if idx == tuple(range(len(idx))):  # the leading channels: a cheaper split and concatenation
        rest = pixels[:, :, len(idx):]
        return np.ascontiguousarray(pixels[:, :, :len(idx)]), lambda out: np.concatenate(
            [out.reshape(out.shape[0], out.shape[1], -1), rest], axis=2)
    chosen = list(idx)

    def merge(out: np.ndarray) -> np.ndarray:
        full = pixels.copy()
        full[:, :, chosen] = out.reshape(out.shape[0], out.shape[1], -1)
        return full

    return np.ascontiguousarray(pixels[:, :, chosen]), merge


_TMP_NAME = re.compile(r"\A\..*" + re.escape(_TMP_MARK) + r"(\d+)-\d+(\.[^.]*)?\Z")
# The last bytes of a complete file, for formats whose writers do not report a failed write.
_TRAILERS = {".png": b"IEND\xaeB`\x82", ".jpg": b"\xff\xd9", ".jpeg": b"\xff\xd9", ".jpe": b"\xff\xd9"}
_LOW_SPACE = 1 << 20  # free bytes below which an incomplete write is reported as a full disk
# libjpeg ends the process when a write fails ("Output file write error --- out of disk space?"), so a
# JPEG is written only where its largest possible size fits: 2 bytes per sample (quality 100 on noise
# measured ~1.2) plus room for metadata.
_EXITS_ON_WRITE_ERROR = frozenset({".jpg", ".jpeg", ".jpe", ".jfif"})


def stale_temp_files(folder: str) -> list[str]:
    """Our temporary files in `folder` left by processes that are gone (killed, power cut)."""
    stale = []
    try:
        names = os.listdir(folder)
    except OSError:
        return []
    for name in names:
        m = _TMP_NAME.match(name)
        if m and not _process_alive(int(m.group(1))):
            stale.append(os.path.join(folder, name))
    return sorted(stale)


def _process_alive(pid: int) -> bool:
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's live process
    return True


def image_shape(path: str) -> tuple[int, int, int] | None:
    """(width, height, channels) from the file's header, or None when it does not open."""
    inp = oiio.ImageInput.open(path)
    if inp is None:
        oiio.geterror()  # clear it
        return None
    try:
        spec = inp.spec()
        return spec.width, spec.height, spec.nchannels
    finally:
        inp.close()


def check_complete(path: str, width: int | None = None, height: int | None = None,
                   nchannels: int | None = None, *, decode: bool = True) -> str | None:
    """Why `path` is not a complete image (of the expected size, when given), or None when it is:
    it opens, has that size, for PNG and JPEG ends with its trailer and, with `decode`, decodes to
    the end without an error (without, for --resume over many files: the header, and for formats without a trailer
    -- EXR, TIFF -- the chunks of the first and last rows, which a file cut short lacks)."""
    try:
        size = os.path.getsize(path)
    except OSError as exc:
        return f"cannot read ({exc.strerror})"
    if size == 0:
        return "empty file"
    trailer = _TRAILERS.get(os.path.splitext(path)[1].lower())
    if trailer is not None:
        with open(path, "rb") as fh:
            fh.seek(max(0, size - len(trailer)))
            if fh.read() != trailer:
                return "truncated (no end marker)"
    inp = oiio.ImageInput.open(path)
    if inp is None:
        return f"does not open ({oiio.geterror() or 'unknown format'})"
    try:
        spec = inp.spec()
        got = (spec.width, spec.height, spec.nchannels)
        want = (width or spec.width, height or spec.height, nchannels or spec.nchannels)
        if got != want:
            return f"expected {want[0]}x{want[1]} with {want[2]} channels, got {got[0]}x{got[1]} with {got[2]}"
        if not decode:
            return None if trailer is not None else _ends_decode(inp, spec)
        pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
        err = inp.geterror()
        if pixels is None or err:
            return f"does not decode to the end ({err or 'unknown error'})"
    finally:
        inp.close()
    return None


def _ends_decode(inp: oiio.ImageInput, spec: oiio.ImageSpec) -> str | None:
    """Why the first or last rows of an open image (a texture's: and its last MIP level) do not decode, or None: the
    chunks a file cut short (a copy interrupted, a writer killed) lacks, whichever order it stores its rows in; whole
    tile rows for a tiled file."""
    top, bottom = spec.y, spec.y + spec.height
    step = spec.tile_height if spec.tile_width else 1
    for y in (top, top + (spec.height - 1) // step * step):
        end = min(y + step, bottom)
        if spec.tile_width:
            rows = inp.read_tiles(0, 0, spec.x, spec.x + spec.width, y, end, spec.z, spec.z + max(spec.depth, 1),
                                  0, spec.nchannels, "float")
        else:
            rows = inp.read_scanlines(0, 0, y, end, spec.z, 0, spec.nchannels, "float")
        if rows is None or inp.has_error:
            return f"does not decode to the end ({inp.geterror() or 'unknown error'})"
    last = spec.get_int_attribute("oiio:miplevels", 1) - 1   # a texture's levels follow level 0: its smallest
    if last > 0 and (inp.read_image(0, last, 0, spec.nchannels, "float") is None or inp.has_error):
        return f"does not decode to the end ({inp.geterror() or 'unknown error'})"
    return None


def temp_path_for(final: str) -> str:
    """A hidden temporary name beside `final`, keeping its extension (writers pick the format by it)."""
    folder, base = os.path.split(os.path.abspath(final))
    stem, ext = os.path.splitext(base)
    return os.path.join(folder, f".{stem}{_TMP_MARK}{os.getpid()}-{next(_tmp_counter)}{ext}")


def publish(tmp: str, final: str, overwrite: bool) -> None:
    """Move a completely written `tmp` to `final`; without `overwrite` an existing `final` is kept."""
    if overwrite:
        os.replace(tmp, final)
        return
    try:
        os.link(tmp, final)  # atomic no-clobber: fails with EEXIST if someone created `final`
    except FileExistsError:
        remove_quietly(tmp)
        raise ImageWriteError(f"{final}: exists; use --overwrite to replace it") from None
    except OSError:  # a file system without hard links: check, then rename
        if os.path.exists(final):
            remove_quietly(tmp)
            raise ImageWriteError(f"{final}: exists; use --overwrite to replace it") from None
        os.replace(tmp, final)
    else:
        os.unlink(tmp)


def remove_quietly(path: str) -> None:
    """Remove a temporary file if it is there; a failure to remove it must not hide the real error."""
    try:
        os.unlink(path)
    except (FileNotFoundError, NotADirectoryError):  # not there (a file where its folder should be: never made)
        pass
    except OSError as exc:  # pragma: no cover - e.g. the directory became read-only meanwhile
        import warnings
        warnings.warn(f"could not remove temporary file {path}: {exc}", stacklevel=2)


def output_spec(spec: oiio.ImageSpec, pixels: np.ndarray) -> oiio.ImageSpec:
    """The input's spec (metadata included) for writing `pixels` back; its alpha stays as it says (is_premultiplied)."""
    out = oiio.ImageSpec(spec)
    h, w = pixels.shape[:2]
    c = 1 if pixels.ndim == 2 else pixels.shape[2]
    if (out.width, out.height, out.nchannels) != (w, h, c):
        raise ValueError(f"expected pixels of {out.width}x{out.height}x{out.nchannels}, "
                         f"got {w}x{h}x{c}")
    compression, level = out.get_string_attribute("compression", ""), out.getattribute("openexr:dwaCompressionLevel")
    if compression in ("dwaa", "dwab") and isinstance(level, (int, float)):
        # OpenEXR's reader gives a DWA file's level apart from "compression", and its writer takes it only inside it
        # ("dwaa:200"): else every frame would be written at the default 45, a different size and loss than the input's
        out.attribute("compression", f"{compression}:{level:g}")
    if 0 < out.get_int_attribute("oiio:BitsPerSample", 0) < 8:
        # a 1/2/4-bit file (line art, a fax scan): TIFF's writer would pack the filtered levels back into 2/4/16
        out.erase_attribute("oiio:BitsPerSample")
    return out


def is_premultiplied(spec: oiio.ImageSpec) -> bool:
    """True when the spec's alpha is associated (colour premultiplied by it): OpenImageIO's convention for a spec
    with an alpha channel not marked oiio:UnassociatedAlpha; read_image marks every straight-alpha file."""
    return spec.alpha_channel >= 0 and not spec.get_int_attribute("oiio:UnassociatedAlpha", 0)


def unpremultiplies(path: str, spec: oiio.ImageSpec) -> bool:
    """True when write_image divides the colour of `spec`'s pixels by alpha for `path`: premultiplied alpha (EXR, a
    TIFF tagged so) into a format of straight alpha (PNG, TGA ...); EXR and TIFF keep it premultiplied."""
    ext = os.path.splitext(path)[1].lower()
    keeps = any(ext in _format_extensions().get(name, ()) for name in _PREMULTIPLIED_FORMATS)
    return is_premultiplied(spec) and not keeps


def unpremultiplied(pixels: np.ndarray, spec: oiio.ImageSpec) -> tuple[np.ndarray, oiio.ImageSpec]:
    """Straight-alpha pixels from premultiplied ones: colour divided by alpha (float32; integers rounded back to
    their type), alpha and depth as they are; where alpha is 0 (or less) the colour stays (nothing to recover).
    The spec is marked unassociated."""
    alpha = spec.alpha_channel
    colour = [c for c in range(pixels.shape[2]) if c not in (alpha, spec.z_channel)]
    top = 1.0 if pixels.dtype.kind == "f" else float(np.iinfo(pixels.dtype).max)
    a = pixels[:, :, alpha:alpha + 1].astype(np.float64) / top
    scale = np.divide(1.0, a, out=np.ones_like(a), where=a > 0)
    straight = pixels[:, :, colour] * scale
    if pixels.dtype.kind == "f":
        out = pixels.astype(np.float32)  # float16 would overflow where alpha is tiny
    else:
        out, straight = pixels.copy(), np.clip(np.rint(straight), 0, top)
    out[:, :, colour] = straight
    spec = oiio.ImageSpec(spec)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    return out, spec


@lru_cache(maxsize=None)
def stored_format(ext: str, fmt: str, nchannels: int = 3) -> str:
    """The sample type OpenImageIO's writer for `ext` stores when asked for `fmt` (PNG: 'uint8' for 'half';
    TIFF keeps floats), found by opening a 1x1 image of `nchannels` in a scratch folder: writers decide this in open(),
    after which the header (PNG's gAMA/sRGB chunk) is written and the colour-space tag can no longer change."""
    with tempfile.TemporaryDirectory(prefix="mlaa-probe") as folder:
        probe = os.path.join(folder, "probe" + ext)
        out = oiio.ImageOutput.create(probe)
        if out is None:
            oiio.geterror()  # clear it: the real write reports the missing writer, naming the file
            return fmt
        try:
            if not out.open(probe, oiio.ImageSpec(1, 1, nchannels, fmt)):
                out.geterror()
                return fmt
            stored = str(out.spec().format)
            out.write_image(np.zeros((1, 1, nchannels), np.float32))  # closing without pixels makes libpng complain
        finally:
            out.close()
    return stored


def is_display_encoded(path: str, spec: oiio.ImageSpec) -> bool:
    """True when `path`'s format stores the spec's samples as integers (PNG, JPEG, 8/16-bit TIFF): display
    values, which linear light must be encoded for (floats: EXR, float TIFF, stay linear)."""
    stored = stored_format(os.path.splitext(path)[1].lower(), str(spec.format), spec.nchannels)
    return stored not in ("half", "float", "double")


def srgb_encoded(pixels: np.ndarray, spec: oiio.ImageSpec) -> tuple[np.ndarray, oiio.ImageSpec]:
    """Linear-light float `pixels` encoded to sRGB (clipped to [0, 1] first) for an integer format, and the
    spec tagged sRGB; alpha and depth channels stay as they are (they are not light)."""
    from mlaa_stream.device.colour import linear_to_srgb

    out = pixels.astype(np.float32)
    keep = {spec.alpha_channel, spec.z_channel}
    colour = [c for c in range(pixels.shape[2]) if c not in keep]
    out[:, :, colour] = linear_to_srgb(out[:, :, colour])
    spec = oiio.ImageSpec(spec)
    spec.attribute("oiio:ColorSpace", "sRGB")
    return out, spec


def write_image(path: str, pixels: np.ndarray, spec: oiio.ImageSpec | None = None, *,
                overwrite: bool = False, linear: bool = False, quality: int | None = None,
                cicp: tuple[int, int, int, int] | None = None) -> bool:
    """Write `pixels` to `path` atomically (temporary name, then rename), in the spec's sample type.

    Without a spec the sample type is the array's and alpha is straight (as decoded video has it). Premultiplied
    alpha (is_premultiplied: EXR) is divided out for a format of straight alpha (unpremultiplies: PNG). `linear`:
    float pixels are linear light (is_linear); where the format stores integers they are encoded to sRGB
    (srgb_encoded), else written as they are. True when they were encoded. `quality`: a JPEG output's, 1-100 (the
    source JPEG's, Image.quality, or --jpeg-quality); None: DEFAULT_JPEG_QUALITY. `cicp`: the colour description
    (primaries, transfer, matrix, range; H.273) to write, for HDR frames from a video. A full disk raises
    OSError(ENOSPC); any other failure raises ImageWriteError naming the file.
    """
    pixels = np.ascontiguousarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    if spec is None:
        fmt = {np.dtype(v): k for k, v in _NATIVE.items()}.get(pixels.dtype)
        if fmt is None:
            raise ImageWriteError(f"{path}: expected uint8, uint16, float16 or float32 pixels, "
                                  f"got {pixels.dtype}")
        spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], fmt)
        spec.attribute("oiio:UnassociatedAlpha", 1)
    if cicp is not None:
        spec.attribute("CICP", "int[4]", tuple(int(v) for v in cicp))
    spec = output_spec(spec, pixels)
    if unpremultiplies(path, spec):
        pixels, spec = unpremultiplied(pixels, spec)
    encode = linear and pixels.dtype.kind == "f" and is_display_encoded(path, spec)
    if encode:
        pixels, spec = srgb_encoded(pixels, spec)
    if os.path.splitext(path)[1].lower() in _JPEG_EXTENSIONS:
        # OpenImageIO's writer takes the quality from "Compression" (jpeg:N); a JPEG source's spec carries none
        spec.attribute("Compression", f"jpeg:{min(max(int(quality or DEFAULT_JPEG_QUALITY), 1), 100)}")
    tmp = temp_path_for(path)
    try:
        _write_file(tmp, pixels, spec, path)
        publish(tmp, path, overwrite)
    except BaseException:
        remove_quietly(tmp)
        raise
    return encode


def _write_file(tmp: str, pixels: np.ndarray, spec: oiio.ImageSpec, final: str) -> None:
    if os.path.splitext(tmp)[1].lower() in _EXITS_ON_WRITE_ERROR:
        need = 2 * spec.width * spec.height * spec.nchannels + (1 << 20)
        free = _free_bytes(tmp)
        if free < need:
            raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)}: a JPEG of this size needs up to "
                          f"{need / 1e6:.1f} MB, {free / 1e6:.1f} MB free", final)
    out = oiio.ImageOutput.create(tmp)
    if out is None:
        raise ImageWriteError(f"{final}: no OpenImageIO writer for this extension "
                              f"({oiio.geterror() or 'unknown format'})")
    if spec.tile_width and not out.supports("tiles"):
        # a tiled input (a render's tiled EXR, a tiled TIFF) into a format of scanlines (PNG, JPEG ...): written as
        # scanlines, else its writer refuses the tile sizes the input's spec carries ("does not support tiled images")
        spec = oiio.ImageSpec(spec)
        spec.tile_width = spec.tile_height = 0
        spec.tile_depth = 1
    ok = out.open(tmp, spec) and out.write_image(pixels) and _write_mip_levels(out, tmp, spec, pixels)
    err = "" if ok else out.geterror()
    ok = out.close() and ok
    err = err or ("" if ok else out.geterror())
    format_name = out.format_name() if ok else ""   # named only where the write went through
    del out   # OpenEXR's writer ends a MIP-mapped file when the ImageOutput goes, not on close(): before the check
    if ok:
        written = image_shape(tmp)
        if written is not None and written[:2] == (spec.width, spec.height) and written[2] != spec.nchannels:
            # JPEG drops alpha and GIF adds it without an error: a format limit, not a failed write
            ok, err = False, (f"{format_name} does not support {spec.nchannels}-channel images "
                              f"(it wrote {written[2]}); PNG, TIFF and EXR keep them")
        else:
            problem = check_complete(tmp, spec.width, spec.height, spec.nchannels)
            if problem is not None:
                ok, err = False, f"the written file is incomplete: {problem}"
    if not ok:
        err = err or oiio.geterror() or "unknown error"
        if (os.strerror(errno.ENOSPC) in err or os.strerror(errno.EDQUOT) in err
                or _free_bytes(tmp) < _LOW_SPACE):
            raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)}: {err}", final)
        raise ImageWriteError(f"{final}: writing failed: {err}")


def _write_mip_levels(out: oiio.ImageOutput, tmp: str, spec: oiio.ImageSpec, pixels: np.ndarray) -> bool:
    """A texture's MIP levels (an input read with several, as maketx writes .tx and .exr), remade from the filtered
    level 0 down to 1x1, each its box-filtered average: an EXR opened as a texture is incomplete -- empty -- without
    them, and a TIFF tagged a texture would lose them. True where nothing failed; a format without levels (PNG) gets
    level 0 alone."""
    if spec.get_int_attribute("oiio:miplevels", 1) < 2 or not spec.get_string_attribute("textureformat"):
        return True
    mode = "AppendMIPLevel" if out.supports("mipmap") else "AppendSubimage" if out.supports("multiimage") else None
    if mode is None:
        return True
    buf = oiio.ImageBuf(oiio.ImageSpec(spec.width, spec.height, spec.nchannels, oiio.FLOAT))
    buf.set_pixels(oiio.ROI.All, pixels.astype(np.float32) / (1.0 if pixels.dtype.kind == "f"
                                                              else float(np.iinfo(pixels.dtype).max)))
    round_up = spec.get_int_attribute("openexr:roundingmode", 0) == 1   # OpenEXR's ROUND_UP level sizes
    w, h = spec.width, spec.height
    while w > 1 or h > 1:
        w, h = max(1, (w + round_up) // 2), max(1, (h + round_up) // 2)
        level = oiio.ImageSpec(spec)
        level.x = level.y = level.full_x = level.full_y = 0
        level.width, level.height, level.full_width, level.full_height = w, h, w, h
        small = oiio.ImageBufAlgo.resize(buf, filtername="box", roi=oiio.ROI(0, w, 0, h, 0, 1, 0, spec.nchannels))
        if not (out.open(tmp, level, mode) and out.write_image(small.get_pixels(oiio.FLOAT))):
            return False
    return True


def _free_bytes(path: str) -> int:
    try:
        return shutil.disk_usage(os.path.dirname(os.path.abspath(path))).free
    except OSError:
        return 1 << 62
