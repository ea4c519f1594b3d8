"""Image folders and numbered frame sequences: which files, in which order, where each output goes,
and the pipeline's source and sink for them (through OpenImageIO, see image_io).

A folder holds independent images: a file that cannot be read or written is reported and the
others go on. A printf pattern (`shot/%04d.exr`, with `--frames A-B` or every number found) is one
sequence: its frames must agree in size, channels and sample type, and the first bad frame stops it.
Outputs are written under temporary names and renamed, so with `resume` an existing output is a
complete one and is skipped.
"""
from __future__ import annotations

import errno
import os
import re
from dataclasses import dataclass, field
from typing import Callable, Iterator

from mlaa_stream.io.images import (Image, ImageReadError, ImageWriteError, is_image_path, is_premultiplied,
                                   is_temp_path, read_image, split_for_filter, unpremultiplies, without_colour,
                                   write_image)
from mlaa_stream.device.transfer import FFMPEG_TRC, TRANSFERS
from mlaa_stream.io.item import Item

_PRINTF = re.compile(r"%(0?)(\d*)d")
_FATAL_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EROFS}
# the first number of frames written through a pattern from unnumbered inputs (a video, a folder, one image):
# 1, as FFmpeg's image2 muxer numbers them
FIRST_FRAME_NUMBER = 1


@dataclass(frozen=True)
class FrameFile:
    """One input file and its output; `number` is the frame number for patterns, else None; `position` the file's
    place in a folder's name order (the temporal stage's frame number there), else None."""

    src: str
    dst: str
    number: int | None = None
    position: int | None = None

    @property
    def sequence_number(self) -> int | None:
        """The frame's number in its sequence: `number`, else `position`."""
        return self.number if self.number is not None else self.position

    @property
    def label(self) -> str:
        return self.src if self.number is None else f"frame {self.number} ({self.src})"


@dataclass
class Report:
    """What happened to each file: messages are also passed to `say` as they happen."""

    say: Callable[[str], None] = lambda msg: None
    inform: Callable[[str], None] = lambda msg: None  # details (the CLI's -v)
    caution: Callable[[str], None] = lambda msg: None  # about the whole run (the CLI's warning), once each
    written: list[str] = field(default_factory=list)
    skipped: list[str] = field(default_factory=list)  # resume: outputs already complete
    copied: list[str] = field(default_factory=list)  # written unfiltered: no colour channels (also in `written`)
    failed: list[str] = field(default_factory=list)  # messages naming the file
    warnings: list[str] = field(default_factory=list)
    cautioned: set[str] = field(default_factory=set)

    def caution_once(self, msg: str) -> None:
        """Say `msg` through `caution` the first time only (it holds for every frame of the run)."""
        if msg not in self.cautioned:
            self.cautioned.add(msg)
            self.caution(msg)

    def fail(self, msg: str) -> None:
        self.failed.append(msg)
        self.say(msg)

    def warn(self, msg: str) -> None:
        self.warnings.append(msg)
        self.say(msg)

    def note(self, msg: str) -> None:
        """A warning about one file that is no failure: kept in `warnings`, said through `caution`."""
        self.warnings.append(msg)
        self.caution(msg)


# Colour-space names (lower case) of log encodings, which a linear keyword ("aces") must not make linear: ACEScc and
# ACEScct ("ACEScct", "acescct_ap1", "ACES - ACEScct"), and log curves (LogC, ADX "Log film scan", "Cineon log")
_LOG_MARKS = ("acescc", "log")


def is_linear_colour_space(name: str) -> bool | None:
    """Whether an oiio:ColorSpace tag names linear light (linear, scene_linear, ACES2065-1, ACEScg, raw data):
    True / False, None where there is no tag. ACEScc and ACEScct are log encodings, not linear light."""
    cs = name.lower()
    if not cs:
        return None
    if any(k in cs for k in _LOG_MARKS):
        return False
    return any(k in cs for k in ("lin", "aces", "scene_linear", "raw"))


def is_linear(image: Image) -> bool:
    """True when the pixels are linear light: a colour space tagged linear/ACES (not ACEScc/ACEScct, which are
    log), or untagged float."""
    tagged = is_linear_colour_space(image.spec.get_string_attribute("oiio:ColorSpace", ""))
    return image.pixels.dtype.kind == "f" if tagged is None else tagged


def image_transfer(image: Image, choice: str = "auto") -> str | None:
    """The HDR transfer an integer image's samples code light with ("pq", "hlg"; device/transfer.py): `choice` where
    it names one ("sdr": none), else ("auto") its CICP (PNG's cICP, AVIF / HEIF / JPEG XL's colour description:
    H.273's codes, FFmpeg's too) or an OpenColorIO-style colour space name (pq_rec2020_display,
    hlg_rec2020_display); None for anything else and for float images (linear light or display-encoded)."""
    if image.pixels.dtype.kind not in "ui" or choice == "sdr":
        return None
    if choice != "auto":
        return choice
    cicp = image.spec.getattribute("CICP")
    if cicp is not None and len(cicp) >= 2:
        return FFMPEG_TRC.get(int(cicp[1]))
    name = image.spec.get_string_attribute("oiio:ColorSpace", "").lower()
    return next((t for t in TRANSFERS if name.startswith(f"{t}_") or f"_{t}_" in name), None)


class FilterSet:
    """The filter for display-encoded images and, made on first need by `make(options)` with the filter's options
    for them, one for linear-light images (`linear_input=True`: EXRs and sRGB PNGs can share a folder) and one per
    HDR transfer (`transfer=`: PQ / HLG PNGs, image_transfer with `transfer` as its choice)."""

    def __init__(self, encoded, make: Callable[[dict], object], transfer: str = "auto"):
        self.encoded, self._make, self.transfer = encoded, make, transfer
        self.variants: dict[tuple, object] = {}

    def for_item(self, item: Item):
        image = item.meta[1]
        transfer = image_transfer(image, self.transfer)
        key = ("transfer", transfer) if transfer else ("linear_input", True) if is_linear(image) else None
        if key is None:
            return self.encoded
        if key not in self.variants:
            made = self.variants[key] = self._make(dict([key]))
            if hasattr(made, "regions_owner"):  # a temporal stage reads the encoded filter's last_regions
                made.regions_owner = self.encoded
        return self.variants[key]

    def close(self) -> None:
        for made in self.variants.values():
            if made is not self.encoded:
                made.close()


class SequenceError(ValueError):
    """A frame does not fit the sequence (size, channels, sample type); names the frame."""


def is_pattern(path: str) -> bool:
    """True when the file name holds a printf frame number like %04d."""
    return bool(_PRINTF.search(os.path.basename(path)))


_HASHES = re.compile(r"#{2,}")


def printf_pattern(path: str) -> str:
    """A pattern written with hashes, as Nuke and RV write them ("shot.####.exr": one # a digit, from ##), as the
    printf pattern it means ("shot.%04d.exr"); other paths, and a file or folder that exists under that very name,
    as they are. Only the file name's first run counts, as for %04d."""
    folder, base = os.path.split(path)
    m = _HASHES.search(base)
    if m is None or _PRINTF.search(base) or os.path.exists(path):
        return path
    return os.path.join(folder, f"{base[:m.start()]}%0{len(m.group())}d{base[m.end():]}")


def frame_path(pattern: str, number: int) -> str:
    """The file name of frame `number`: the first %d / %0Nd of the file name replaced."""
    folder, base = os.path.split(pattern)
    m = _PRINTF.search(base)
    if m is None:
        raise ValueError(f"expected a frame pattern like shot/%04d.exr, got {pattern!r}")
    digits = f"{number:0{m.group(2)}d}" if m.group(1) == "0" and m.group(2) else str(number)
    return os.path.join(folder, base[:m.start()] + digits + base[m.end():])


def parse_frames(text: str) -> tuple[int, int]:
    """'A-B' (or a single 'A') -> (A, B) with A <= B."""
    m = re.fullmatch(r"\s*(\d+)\s*(?:[-:]\s*(\d+)\s*)?", text or "")
    if not m:
        raise ValueError(f"expected --frames A-B with whole numbers (e.g. 1001-1100), got {text!r}")
    a = int(m.group(1))
    b = int(m.group(2)) if m.group(2) is not None else a
    if b < a:
        raise ValueError(f"expected --frames A-B with A <= B, got {text!r}")
    return a, b


def _pattern_regex(basename: str) -> re.Pattern:
    m = _PRINTF.search(basename)
    width = int(m.group(2)) if m.group(2) else 1
    # only the names frame_path gives: %04d is 4 digits, or more without a leading zero (0012, 12345, not 00012), %d
    # has none (9, not 09: a second file of frame 9 was taken or not by the folder's listing order, unlike --frames)
    digits = rf"(\d{{{width}}}|[1-9]\d{{{width},}})" if m.group(1) == "0" else r"(0|[1-9]\d*)"
    return re.compile(re.escape(basename[:m.start()]) + digits + re.escape(basename[m.end():]) + r"\Z")


def format_spans(spans: list[tuple[int, int]]) -> str:
    """[(3, 5), (9, 9)] -> '3-5, 9'."""
    return ", ".join(str(a) if a == b else f"{a}-{b}" for a, b in spans)


def _gaps(numbers: list[int], first: int, last: int) -> list[tuple[int, int]]:
    """The spans of first..last that `numbers` (sorted, within it) leave out."""
    gaps, at = [], first
    for n in numbers:
        if n > at:
            gaps.append((at, n - 1))
        at = n + 1
    if at <= last:
        gaps.append((at, last))
    return gaps


def expand_pattern(pattern: str, frames: tuple[int, int] | None = None
                   ) -> tuple[list[tuple[int, str]], list[tuple[int, int]]]:
    """The existing frames of a printf pattern, in order, and the missing numbers as spans (first, last).

    With `frames` the numbers A..B are expected; without, every number found in the folder, and
    the gaps between the first and last. The folder is listed once either way: testing each number of a range for a
    file took 17 s for --frames 1-2000000, and a typo's 1-100000000 minutes and gigabytes of missing numbers.
    """
    folder, base = os.path.split(pattern)
    folder = folder or "."
    rx = _pattern_regex(base)
    numbers: dict[int, str] = {}
    try:
        names = os.listdir(folder)
    except OSError:
        names = []
    for name in names:
        m = rx.match(name)
        if m and not is_temp_path(name):
            numbers.setdefault(int(m.group(1)), os.path.join(folder, name) if folder != "." else name)
    if frames is not None:
        # the names frame_path gives (the pattern's own), files only, as a test of each number's path would find
        found = [(n, frame_path(pattern, n)) for n in sorted(numbers) if frames[0] <= n <= frames[1]]
        found = [(n, path) for n, path in found if os.path.isfile(path)]
        return found, _gaps([n for n, _ in found], frames[0], frames[1])
    found = sorted(numbers.items())
    if not found:
        return [], []
    return found, _gaps([n for n, _ in found], found[0][0], found[-1][0])


def list_folder(folder: str) -> tuple[list[str], list[str]]:
    """Image files of `folder` in name order, and the other files (not images by extension).

    Hidden files, our own temporary files and sub-folders are left out; a link to a file that is gone is listed
    (its read fails naming it) rather than dropped without a word.
    """
    images, others = [], []
    for name in sorted(os.listdir(folder)):
        path = os.path.join(folder, name)
        broken_link = os.path.islink(path) and not os.path.exists(path)
        if name.startswith(".") or is_temp_path(name) or not (os.path.isfile(path) or broken_link):
            continue
        (images if is_image_path(name) else others).append(path)
    return images, others


def output_path(src: str, output: str, number: int | None = None) -> str:
    """Where the output of `src` goes: `output` as a printf pattern, a folder, or the file itself."""
    if number is not None and is_pattern(output):
        return frame_path(output, number)
    if os.path.isdir(output) or output.endswith(("/", os.sep)):
        return os.path.join(output, os.path.basename(src))
    return output


def same_file(a: str, b: str) -> bool:
    """True when the paths name the same file (also through links), existing or not."""
    if os.path.realpath(a) == os.path.realpath(b):
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def output_over_input(plan: list[FrameFile]) -> str | None:
    """A message naming the first output that is an input of the plan -- its own, or another frame's (a folder
    numbered into a pattern in its own folder: 0003.png's output is 0002.png) -- else None. Checked before
    anything is written: --overwrite replaces outputs, never an input."""
    def key(path: str) -> tuple:
        try:
            st = os.stat(path)
            return st.st_dev, st.st_ino   # hard links and links to links name the same file
        except OSError:
            return (os.path.realpath(path),)
    inputs = {key(ff.src): ff for ff in plan}
    for ff in plan:
        other = inputs.get(key(ff.dst))
        if other is None:
            other = inputs.get((os.path.realpath(ff.dst),))   # an input that is gone (a broken link) by its name
        if other is ff or (other is None and same_file(ff.src, ff.dst)):
            return f"{ff.dst}: output is the input {ff.src}; choose another output"
        if other is not None:
            return f"{ff.dst}: the output of {ff.src} would replace the input {other.src}; choose another output"
    return None


def image_source(files: list[FrameFile], report: Report, *, strict: bool,
                 like: tuple | None = None, optional: frozenset[int] = frozenset()) -> Iterator[Item]:
    """Read each file; Item.meta = (FrameFile, Image, merge). Folder mode (not strict) reports a bad
    file and goes on; strict (a sequence) raises at the first unreadable or mismatched frame. `like`:
    ((shape, dtype), FrameFile) every frame must match (a chunk of a longer sequence: its first frame).
    `optional`: ids of files read only for the temporal stage, their outputs done (--resume's look-ahead and
    warm-up frames): one that cannot be read is left out with a warning (report.note), in either mode, and none is
    held to the sequence's size.
    A file without colour channels (images.without_colour: an EXR of depth, normals, motion vectors) is a
    passthrough Item, all its channels as read: image_sink writes it unchanged, never filtered."""
    first: tuple | None = like
    for ff in files:
        try:
            image = read_image(ff.src)
            copy = without_colour(image)
            frame, merge = (image.pixels, _unchanged) if copy else split_for_filter(image)
        except ImageReadError as exc:
            if id(ff) in optional:   # its output is done: no failure of this run (the stage resets at the gap)
                why = str(exc).removeprefix(f"{ff.src}: ")
                report.note(f"{ff.src}: left out of the temporal stage, which read it only (its output is done): {why}")
                continue
            if strict:
                raise
            report.fail(str(exc))
            continue
        for note in image.conversions:
            report.inform(f"{ff.src}: {note}")
        for note in image.lossy:   # the same for every frame of a sequence: said once
            report.caution_once(note)
        if strict and id(ff) not in optional:
            shape = (image.pixels.shape, image.pixels.dtype)
            if first is None:
                first = (shape, ff)
            elif shape != first[0]:
                (s0, d0), (s1, d1) = first[0], shape
                raise SequenceError(
                    f"{ff.label}: expected {s0[1]}x{s0[0]} with {s0[2]} channels of {d0} like "
                    f"{first[1].src}, got {s1[1]}x{s1[0]} with {s1[2]} channels of {d1}{_data_window(image)}")
        yield Item(frame, (ff, image, merge), passthrough=bool(copy), premultiplied=is_premultiplied(image.spec))


def _unchanged(pixels):
    """A passthrough item's merge: its pixels are the whole image already."""
    return pixels


def _data_window(image: Image) -> str:
    """Where an EXR's pixels (its data window, what is filtered) are not its whole display window: said, since a
    viewer shows the display window's size (renders cropped to their bounding box change size frame by frame)."""
    spec = image.spec
    if (spec.x, spec.y, spec.width, spec.height) == (spec.full_x, spec.full_y, spec.full_width, spec.full_height):
        return ""
    return (f" (its data window, {spec.width}x{spec.height} at {spec.x},{spec.y} of a {spec.full_width}x"
            f"{spec.full_height} display window; a sequence keeps one data window size)")


def image_sink(report: Report, *, overwrite: bool, strict: bool,
               jpeg_quality: int | None = None) -> Callable[[Item], None]:
    """Write each filtered frame back in its source's format and metadata, atomically; linear-light frames
    written to an integer format are encoded to sRGB and premultiplied alpha written to a format of straight alpha
    is divided out (write_image), each said once through report.caution. JPEG outputs get `jpeg_quality` (1-100,
    --jpeg-quality), else their JPEG source's quality, else write_image's default. A passthrough item (no colour) is
    written as read, its channels, types and header as the input's (never sRGB-encoded: its data is not light),
    said through report.note.

    A full disk (or a read-only file system) always stops the run; other write failures stop a
    sequence (strict) but only skip the file in a folder.
    """
    def sink(item: Item) -> None:
        ff, image, merge = item.meta
        try:
            encoded = write_image(ff.dst, merge(item.frame), image.spec, overwrite=overwrite,
                                  linear=is_linear(image) and not item.passthrough,
                                  quality=jpeg_quality or image.quality)
        except ImageWriteError as exc:
            if strict:
                raise
            report.fail(str(exc))
            return
        except OSError as exc:
            if strict or exc.errno in _FATAL_ERRNOS:
                raise
            report.fail(f"{ff.dst}: cannot write: {exc.strerror or exc}")
            return
        report.written.append(ff.dst)
        if item.passthrough:
            report.copied.append(ff.dst)
            report.note(f"{ff.src}: {without_colour(image)}: copied unchanged")
        src_ext, ext = os.path.splitext(ff.src)[1].lower(), os.path.splitext(ff.dst)[1].lower() or ff.dst
        if unpremultiplies(ff.dst, image.spec):   # EXR's associated alpha into PNG's straight alpha
            report.caution_once(f"premultiplied alpha of {src_ext or 'the input'} frames is divided out for {ext}, a "
                                f"format of straight alpha (EXR and TIFF keep it premultiplied)")
        if encoded:  # linear light in a format of display values (PNG, JPEG, 8/16-bit TIFF)
            report.caution_once(f"linear-light frames ({src_ext or 'float'}) are encoded to sRGB for {ext}, a format "
                                f"of display values (EXR and float TIFF keep them linear)")

    return sink


def frame_number(read_order: dict, position: int) -> int:
    """The frame number a temporal stage gets for the frame at `position` of a run (read_order: position ->
    FrameFile as read): the file's sequence number (a folder: its position in name order), else the position."""
    ff = read_order.get(position)
    return position if ff is None or ff.sequence_number is None else ff.sequence_number


def consecutive_ahead(read_order: dict, position: int, future) -> list:
    """The look-ahead frames (those read after `position`) up to a gap in the numbering, where the temporal
    stage resets: the window ends before it."""
    number = frame_number(read_order, position)
    n = 0
    while n < len(future) and frame_number(read_order, position + 1 + n) == number + 1 + n:
        n += 1
    return list(future)[:n]


def plan_images(src_paths: list[str], output: str, numbers: list[int | None] | None = None) -> list[FrameFile]:
    """Pair each input with its output path; without numbers (a folder) each file gets its position in the list,
    and where `output` is a frame pattern, numbers in list order from FIRST_FRAME_NUMBER (the names to write)."""
    if numbers is None and is_pattern(output):
        numbers = list(range(FIRST_FRAME_NUMBER, FIRST_FRAME_NUMBER + len(src_paths)))
    if numbers is None:
        return [FrameFile(src, output_path(src, output, None), None, k) for k, src in enumerate(src_paths)]
    return [FrameFile(src, output_path(src, output, n), n) for src, n in zip(src_paths, numbers)]

