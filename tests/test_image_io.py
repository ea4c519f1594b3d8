"""Still images through OpenImageIO: bit depth, channels, alpha and metadata survive a round trip;
bad files are refused naming the file; writes are atomic (temporary name, then rename)."""
from __future__ import annotations

import errno
import os

import numpy as np
import OpenImageIO as oiio
import pytest

from mlaa_stream.io import images as image_io
from mlaa_stream.io.images import (ImageReadError, ImageWriteError, filtered_channels, publish,
                                  read_image, split_for_filter, write_image)

DEMO = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "images")


def write_raw(path, arr, fmt, attrs=None):
    spec = oiio.ImageSpec(arr.shape[1], arr.shape[0], arr.shape[2], fmt)
    for k, v in (attrs or {}).items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(arr) and out.close(), oiio.geterror()


def leftovers(folder) -> list[str]:
    return [n for n in os.listdir(folder) if image_io.is_temp_path(n)]


@pytest.mark.parametrize("name,dtype,channels", [
    ("rgb8.png", np.uint8, 3), ("rgba16.png", np.uint16, 4), ("linear_half.exr", np.float16, 4),
    ("float32.tif", np.float32, 3), ("grey.png", np.uint8, 1), ("palette.png", np.uint8, 3),
    ("odd_37x23.jpg", np.uint8, 3)])
def test_demo_images_read_in_their_own_sample_type(name, dtype, channels):
    im = read_image(os.path.join(DEMO, name))
    assert im.pixels.dtype == dtype and im.pixels.shape[2] == channels
    assert im.pixels.min() != im.pixels.max()


@pytest.mark.parametrize("fmt,dtype,ext,channels", [
    ("uint8", np.uint8, ".png", 3), ("uint16", np.uint16, ".png", 4), ("uint16", np.uint16, ".tif", 4),
    ("half", np.float16, ".exr", 4), ("float", np.float32, ".exr", 3), ("uint8", np.uint8, ".png", 1),
    ("uint8", np.uint8, ".png", 2), ("uint16", np.uint16, ".tif", 1)])
def test_round_trip_is_bit_exact_with_metadata(tmp_path, fmt, dtype, ext, channels):
    rng = np.random.default_rng(5)
    if np.dtype(dtype).kind == "f":
        arr = rng.random((7, 9, channels)).astype(dtype)
    else:
        arr = rng.integers(0, np.iinfo(dtype).max, (7, 9, channels), dtype=dtype)
    attrs = {"oiio:ColorSpace": "lin_rec709" if ext == ".exr" else "sRGB", "Artist": "mlaa test"}
    if channels in (2, 4):
        attrs["oiio:UnassociatedAlpha"] = 1
    src = tmp_path / f"in{ext}"
    write_raw(src, arr, fmt, attrs)
    im = read_image(str(src))
    np.testing.assert_array_equal(im.pixels, arr)  # unassociated alpha read as stored
    dst = tmp_path / f"out{ext}"
    write_image(str(dst), im.pixels, im.spec)
    back = read_image(str(dst))
    assert back.pixels.dtype == dtype
    np.testing.assert_array_equal(back.pixels, arr)
    assert back.spec.get_string_attribute("Artist") == "mlaa test"
    assert back.spec.get_string_attribute("oiio:ColorSpace") == im.spec.get_string_attribute("oiio:ColorSpace")
    assert back.channel_names == im.channel_names
    assert leftovers(tmp_path) == []


def test_sample_types_the_filter_lacks_come_back_in_the_files_type(tmp_path):
    arr = np.random.default_rng(2).integers(-30000, 30000, (5, 6, 3), dtype=np.int16)
    src = tmp_path / "int16.tif"
    write_raw(src, arr, "int16")
    im = read_image(str(src))
    assert im.pixels.dtype == np.float32
    write_image(str(tmp_path / "out.tif"), im.pixels, im.spec)
    inp = oiio.ImageInput.open(str(tmp_path / "out.tif"))
    assert str(inp.spec().format) == "int16"
    np.testing.assert_array_equal(inp.read_image(0, 0, 0, 3, "int16"), arr)
    inp.close()


def test_palette_png_reads_as_the_colours_it_shows():
    from PIL import Image

    path = os.path.join(DEMO, "palette.png")
    expected = np.asarray(Image.open(path).convert("RGB"))
    np.testing.assert_array_equal(read_image(path).pixels, expected)


@pytest.mark.parametrize("content,message", [
    (b"", "expected an image, got an empty file"),
    (b"hello, not a picture", "expected an image OpenImageIO can read"),
    (b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\x00\x00", "expected an image OpenImageIO can read")])
def test_unreadable_files_are_refused_naming_the_file(tmp_path, content, message):
    path = tmp_path / "bad.png"
    path.write_bytes(content)
    with pytest.raises(ImageReadError, match=message) as ei:
        read_image(str(path))
    assert str(path) in str(ei.value)


def test_a_missing_file_is_refused_naming_it(tmp_path):
    with pytest.raises(ImageReadError, match="nope.png: cannot read"):
        read_image(str(tmp_path / "nope.png"))


@pytest.mark.parametrize("n,alpha,expected", [(1, -1, 1), (2, 1, 1), (3, -1, 3), (4, 3, 4),
                                              (5, 3, 4), (5, -1, 3), (6, 4, 3)])
def test_filtered_channels(n, alpha, expected):
    assert filtered_channels(n, alpha) == expected


def test_split_for_filter_keeps_extra_channels_untouched(tmp_path):
    rng = np.random.default_rng(9)
    arr = rng.random((4, 5, 5)).astype(np.float32)  # R G B A Z
    spec = oiio.ImageSpec(5, 4, 5, "float")
    spec.channelnames = ("R", "G", "B", "A", "Z")
    spec.alpha_channel = 3
    frame, merge = split_for_filter(image_io.Image(arr, spec, "x.exr"))
    assert frame.shape == (4, 5, 4)
    out = merge(frame * 0.5)
    np.testing.assert_array_equal(out[:, :, 4], arr[:, :, 4])
    np.testing.assert_array_equal(out[:, :, :4], arr[:, :, :4] * 0.5)
    grey_alpha = rng.integers(0, 255, (4, 5, 2), dtype=np.uint8)
    frame, merge = split_for_filter(image_io.Image(grey_alpha, oiio.ImageSpec(5, 4, 2, "uint8"), "g.png"))
    assert frame.shape == (4, 5, 1)
    np.testing.assert_array_equal(merge(frame)[:, :, 1], grey_alpha[:, :, 1])


@pytest.mark.parametrize("names,colour", [
    # Blender's multilayer EXR with an AO pass: OpenImageIO lists AO (sorted first) before Combined
    (("ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B", "ViewLayer.Combined.A",
      "ViewLayer.AO.R", "ViewLayer.AO.G", "ViewLayer.AO.B", "ViewLayer.Depth.Z"),
     ("ViewLayer.Combined.R", "ViewLayer.Combined.G", "ViewLayer.Combined.B", "ViewLayer.Combined.A")),
    # a plain Z sorts before a lower-case layer
    (("diffuse.R", "diffuse.G", "diffuse.B", "Z"), ("diffuse.R", "diffuse.G", "diffuse.B")),
    # RGB + Z without alpha: the depth is not the filter's fourth channel
    (("R", "G", "B", "Z"), ("R", "G", "B")),
])
def test_the_colour_channels_of_an_exr_are_found_by_name(tmp_path, names, colour):
    rng = np.random.default_rng(12)
    arr = rng.random((4, 5, len(names))).astype(np.float32)
    spec = oiio.ImageSpec(5, 4, len(names), "float")
    spec.channelnames = names
    path = str(tmp_path / "layers.exr")
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_image(arr) and out.close(), oiio.geterror()
    image = read_image(path)
    read_names = image.channel_names
    frame, merge = split_for_filter(image)
    want = [read_names.index(n) for n in colour]
    np.testing.assert_array_equal(frame, image.pixels[:, :, want])
    merged = merge(frame + 1)
    others = [k for k in range(len(names)) if k not in want]
    np.testing.assert_array_equal(merged[:, :, want], image.pixels[:, :, want] + 1)
    np.testing.assert_array_equal(merged[:, :, others], image.pixels[:, :, others])


def test_a_full_disk_leaves_neither_a_final_nor_a_temporary_file(tmp_path, monkeypatch):
    def full_disk(tmp, pixels, spec, final):
        with open(tmp, "wb") as fh:  # half a file on disk, then the disk is full
            fh.write(b"\x89PNG partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), final)

    monkeypatch.setattr(image_io, "_write_file", full_disk)
    with pytest.raises(OSError) as ei:
        write_image(str(tmp_path / "out.png"), np.zeros((2, 2, 3), np.uint8) + 7)
    assert ei.value.errno == errno.ENOSPC
    assert os.listdir(tmp_path) == []


def test_oiio_reporting_no_space_becomes_enospc(tmp_path, monkeypatch):
    class Out:
        def open(self, *a):
            return True

        def write_image(self, *a):
            return False

        def close(self):
            return True

        def geterror(self):
            return f"write failed: {os.strerror(errno.ENOSPC)}"

    monkeypatch.setattr(image_io.oiio.ImageOutput, "create", staticmethod(lambda p: Out()))
    with pytest.raises(OSError) as ei:
        write_image(str(tmp_path / "o.png"), np.ones((2, 2, 3), np.uint8))
    assert ei.value.errno == errno.ENOSPC and ei.value.filename == str(tmp_path / "o.png")


def test_publish_never_replaces_without_overwrite(tmp_path):
    final, tmp = tmp_path / "a.png", tmp_path / ".a.mlaa-tmp1-0.png"
    final.write_bytes(b"old")
    tmp.write_bytes(b"new")
    with pytest.raises(ImageWriteError, match="exists; use --overwrite"):
        publish(str(tmp), str(final), overwrite=False)
    assert final.read_bytes() == b"old" and not tmp.exists()
    tmp.write_bytes(b"new")
    publish(str(tmp), str(final), overwrite=True)
    assert final.read_bytes() == b"new" and not tmp.exists()


def test_unknown_output_extension_is_a_write_error_naming_the_file(tmp_path):
    with pytest.raises(ImageWriteError, match="out.nope: no OpenImageIO writer"):
        write_image(str(tmp_path / "out.nope"), np.ones((2, 2, 3), np.uint8))
    assert os.listdir(tmp_path) == []


def test_linear_exr_written_to_png_is_encoded_to_srgb_and_to_exr_or_float_tiff_kept_linear(tmp_path):
    from mlaa_stream.io.sequence import is_linear

    arr = np.zeros((3, 4, 4), np.float16)
    arr[..., :3], arr[..., 3] = 0.2, 0.5   # linear grey 0.2, alpha 0.5
    write_raw(tmp_path / "in.exr", arr, "half", {"oiio:ColorSpace": "lin_rec709"})
    im = read_image(str(tmp_path / "in.exr"))
    assert is_linear(im)
    lin = float(np.float16(0.2))
    want = round((1.055 * lin ** (1 / 2.4) - 0.055) * 255)   # IEC 61966-2-1 encode: 124
    assert want == 124
    assert write_image(str(tmp_path / "out.png"), im.pixels, im.spec, linear=True) is True
    png = read_image(str(tmp_path / "out.png"))
    assert png.pixels.dtype == np.uint8
    assert (png.pixels[..., :3] == want).all() and (png.pixels[..., 3] == 128).all()   # alpha is not light
    assert "srgb" in png.spec.get_string_attribute("oiio:ColorSpace").lower()
    for ext in (".exr", ".tif"):   # float formats: linear values as they are
        assert write_image(str(tmp_path / f"out{ext}"), im.pixels, im.spec, linear=True) is False
        back = read_image(str(tmp_path / f"out{ext}"))
        np.testing.assert_array_equal(back.pixels.astype(np.float16), arr)
    assert leftovers(tmp_path) == []
