"""Still images through OpenImageIO: read and write keeping bit depth, channels, alpha and metadata.

Every output is written under a temporary name in its destination directory and renamed when
complete, so a final name never holds a half-written file (also on Ctrl-C or a full disk).
"""
from __future__ import annotations

import errno
import itertools
import os
from dataclasses import dataclass
from typing import Callable

import numpy as np
import OpenImageIO as oiio

# Sample types the filter takes as they are; any other (int8/16, uint32, double) is read as float32
# and converted back to the file's own type when written.
_NATIVE = {"uint8": np.uint8, "uint16": np.uint16, "half": np.float16, "float": np.float32}

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

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(self.spec.channelnames)


def image_extensions() -> frozenset[str]:
    """File extensions OpenImageIO can read (lower case, with the dot)."""
    exts = set()
    for entry in oiio.get_string_attribute("extension_list").split(";"):
        _, _, names = entry.partition(":")
        exts.update("." + n.lower() for n in names.split(",") if n)
    exts.discard(".null")
    exts.discard(".nul")
    exts.discard(".term")
    return frozenset(exts)


def is_image_path(path: str) -> bool:
    """True when the extension is one OpenImageIO reads (the file itself is not opened)."""
    return os.path.splitext(path)[1].lower() in image_extensions()


def is_temp_path(path: str) -> bool:
    """True for our own temporary output names (skipped when listing a folder)."""
    return _TMP_MARK in os.path.basename(path)


def read_image(path: str) -> Image:
    """Read subimage 0 of `path` as stored: uint8/uint16/half/float kept, other types as float32."""
    config = oiio.ImageSpec()
    # Unassociated alpha (PNG, TIFF) is returned as stored instead of premultiplied, so it round-trips.
    config.attribute("oiio:UnassociatedAlpha", 1)
    try:
        size = os.path.getsize(path)
    except OSError as exc:
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
        fmt = str(spec.format)
        read_fmt = fmt if fmt in _NATIVE else "float"
        pixels = inp.read_image(0, 0, 0, spec.nchannels, read_fmt)
        if pixels is None:
            raise ImageReadError(f"{path}: reading pixels failed: {inp.geterror() or 'unknown error'}")
        spec = oiio.ImageSpec(spec)  # a copy that outlives the ImageInput
    finally:
        inp.close()
    pixels = np.asarray(pixels)
    if pixels.ndim == 2:
        pixels = pixels[:, :, None]
    return Image(pixels=pixels, spec=spec, path=path)


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


def split_for_filter(image: Image) -> tuple[np.ndarray, Callable[[np.ndarray], np.ndarray]]:
    """The frame the filter sees and a function that puts its result back among the other channels."""
    pixels = image.pixels
    n = filtered_channels(pixels.shape[2], image.spec.alpha_channel)
    if n == pixels.shape[2]:
        return pixels, lambda out: out
    rest = pixels[:, :, n:]
    return np.ascontiguousarray(pixels[:, :, :n]), lambda out: np.concatenate(
        [out.reshape(out.shape[0], out.shape[1], -1), rest], axis=2)


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
    except FileNotFoundError:
        pass
    except OSError as exc:  # pragma: no cover - e.g. the directory became read-only meanwhile
        import warnings
        warnings.warn(f"could not remove temporary file {path}: {exc}", stacklevel=2)


def output_spec(spec: oiio.ImageSpec, pixels: np.ndarray) -> oiio.ImageSpec:
    """The input's spec (metadata included) for writing `pixels` back; alpha stays unassociated."""
    out = oiio.ImageSpec(spec)
    h, w = pixels.shape[:2]
    c = 1 if pixels.ndim == 2 else pixels.shape[2]
    if (out.width, out.height, out.nchannels) != (w, h, c):
        raise ValueError(f"expected pixels of {out.width}x{out.height}x{out.nchannels}, "
                         f"got {w}x{h}x{c}")
    if out.alpha_channel >= 0:
        out.attribute("oiio:UnassociatedAlpha", 1)
    return out


def write_image(path: str, pixels: np.ndarray, spec: oiio.ImageSpec | None = None, *,
                overwrite: bool = False) -> None:
    """Write `pixels` to `path` atomically (temporary name, then rename), in the spec's sample type.

    Without a spec the sample type is the array's. A full disk raises OSError(ENOSPC); any other
    failure raises ImageWriteError naming the file.
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
    spec = output_spec(spec, pixels)
    tmp = temp_path_for(path)
    try:
        _write_file(tmp, pixels, spec, path)
        publish(tmp, path, overwrite)
    except BaseException:
        remove_quietly(tmp)
        raise


def _write_file(tmp: str, pixels: np.ndarray, spec: oiio.ImageSpec, final: str) -> None:
    out = oiio.ImageOutput.create(tmp)
    if out is None:
        raise ImageWriteError(f"{final}: no OpenImageIO writer for this extension "
                              f"({oiio.geterror() or 'unknown format'})")
    ok = out.open(tmp, spec) and out.write_image(pixels)
    err = "" if ok else out.geterror()
    ok = out.close() and ok
    if not ok:
        err = err or out.geterror() or oiio.geterror() or "unknown error"
        if os.strerror(errno.ENOSPC) in err or os.strerror(errno.EDQUOT) in err:
            raise OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)}: {err}", final)
        raise ImageWriteError(f"{final}: writing failed: {err}")
