"""TIFFs of sample types the filter does not take (double, 8/16/32-bit integers) through `mlaa-stream`: written back
in their own type, the pixels the filter did not change bit for bit (they went through float32, which holds neither
a double nor an integer over 2^24, and integers were taken for linear light and encoded to sRGB on writing)."""
from __future__ import annotations

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main

H, W = 24, 32


def staircase() -> tuple[np.ndarray, np.ndarray]:
    """An aliased half-plane (RGB in [0, 1], float64, with low bits float32 cannot hold) and its mask."""
    y, x = np.mgrid[0:H, 0:W]
    mask = y > x / 3.0 + H / 4
    rgb = np.where(mask[:, :, None], [0.9, 0.8, 0.1], [0.1, 0.2, 0.6])
    return rgb + np.random.default_rng(3).random(rgb.shape) * 1e-4, mask


def near_edge(mask: np.ndarray, reach: int = 2) -> np.ndarray:
    """Pixels within `reach` of a pixel on the other side of the mask's edge (the only ones the filter may change)."""
    padded = np.pad(mask, reach, mode="edge")
    near = np.zeros_like(mask)
    for dy in range(-reach, reach + 1):
        for dx in range(-reach, reach + 1):
            near |= padded[reach + dy:reach + dy + H, reach + dx:reach + dx + W] != mask
    return near


def in_type(rgb: np.ndarray, fmt: str) -> np.ndarray:
    if fmt == "double":
        return rgb
    dtype = {"uint": np.uint32, "int": np.int32, "int16": np.int16, "int8": np.int8}[fmt]
    return np.rint(rgb * np.iinfo(dtype).max).astype(dtype)


def write_tiff(path, pixels: np.ndarray, fmt: str) -> None:
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), oiio.ImageSpec(W, H, pixels.shape[2], fmt)) and out.write_image(pixels) \
        and out.close(), oiio.geterror()


def read_as_stored(path) -> tuple[str, np.ndarray]:
    inp = oiio.ImageInput.open(str(path))
    fmt = str(inp.spec().format)
    pixels = np.asarray(inp.read_image(0, 0, 0, inp.spec().nchannels, fmt))
    inp.close()
    return fmt, pixels


@pytest.mark.parametrize("fmt", ["double", "uint", "int", "int16", "int8"])
def test_a_tiff_of_another_sample_type_comes_back_in_it_untouched_pixels_bit_for_bit(tmp_path, fmt):
    rgb, mask = staircase()
    pixels = in_type(rgb, fmt)
    if fmt == "double":   # special values far from the edge: a NaN, and a number float32 has no room for
        pixels[0, 0, 0], pixels[0, 1, 1] = np.nan, 1e300
    src, dst = tmp_path / "in.tif", tmp_path / "out.tif"
    write_tiff(src, pixels, fmt)
    result = CliRunner().invoke(main, [str(src), "-o", str(dst)])
    assert result.exit_code == 0 and "Traceback" not in result.output, result.output
    assert "2^24" not in result.output
    got_fmt, got = read_as_stored(dst)
    _, want = read_as_stored(src)
    assert got_fmt == fmt and got.dtype == want.dtype
    edge = near_edge(mask)
    changed = (got.view(np.uint8).reshape(H, W, 3, -1) != want.view(np.uint8).reshape(H, W, 3, -1)).any(axis=(2, 3))
    assert changed.any() and not (changed & ~edge).any()   # the edge filtered, nothing else touched
    # the changed samples are blends of the two sides, scaled back to the type (not sRGB-encoded, nor clipped)
    blend = got[changed].astype(np.float64) / (1.0 if fmt == "double" else np.iinfo(got.dtype).max)
    assert blend.min() >= 0.099 and blend.max() <= 0.901


def test_a_video_is_not_made_from_32_bit_integer_frames(tmp_path):
    """They were read as float32 and refused as linear light; read as stored, they would reach the encoder."""
    rgb, _ = staircase()
    for n in (1, 2):
        write_tiff(tmp_path / f"{n:04d}.tif", in_type(rgb, "int"), "int")
    result = CliRunner().invoke(main, [str(tmp_path / "%04d.tif"), "-o", str(tmp_path / "out.mp4")])
    assert result.exit_code == 2 and "int32 samples cannot be encoded to video here" in result.output, result.output
