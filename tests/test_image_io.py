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
    assert im.pixels.dtype == np.int16   # read as stored; the filter gets float32 (tests/test_tiff_sample_types.py)
    write_image(str(tmp_path / "out.tif"), im.pixels, im.spec)
    inp = oiio.ImageInput.open(str(tmp_path / "out.tif"))
    assert str(inp.spec().format) == "int16"
    np.testing.assert_array_equal(inp.read_image(0, 0, 0, 3, "int16"), arr)
    inp.close()


def test_a_1_bit_tiff_comes_back_8_bit_keeping_the_filtered_levels(tmp_path):
    arr = (np.random.default_rng(6).random((8, 16, 1)) > 0.5).astype(np.uint8) * 255
    src = tmp_path / "lineart.tif"
    write_raw(src, arr, "uint8", {"oiio:BitsPerSample": 1})
    im = read_image(str(src))
    assert im.spec.get_int_attribute("oiio:BitsPerSample") == 1
    assert any("1-bit samples written back as 8-bit" in note for note in im.conversions)
    blended = im.pixels.copy()
    blended[0, :, 0] = np.arange(16) * 17   # levels between black and white, as at an antialiased edge
    write_image(str(tmp_path / "out.tif"), blended, im.spec)
    back = read_image(str(tmp_path / "out.tif"))
    np.testing.assert_array_equal(back.pixels, blended)   # was cut back to 0 / 255


@pytest.mark.parametrize("ext", [".exr", ".tif"])
def test_a_mip_mapped_texture_is_written_with_its_levels_remade_from_level_0(tmp_path, ext):
    arr = np.random.default_rng(7).random((24, 40, 3)).astype(np.float32)
    flat = oiio.ImageBuf(oiio.ImageSpec(40, 24, 3, oiio.FLOAT))
    flat.set_pixels(oiio.ROI.All, arr)
    src = str(tmp_path / f"tex{ext}")
    assert oiio.ImageBufAlgo.make_texture(oiio.MakeTxTexture, flat, src, oiio.ImageSpec()), oiio.geterror()
    im = read_image(src)
    dst = str(tmp_path / f"out{ext}")
    write_image(dst, im.pixels, im.spec)   # the EXR was refused: 'the written file is incomplete: empty file'
    inp = oiio.ImageInput.open(dst)
    sizes = []
    while inp.seek_subimage(0, len(sizes)):
        sizes.append((inp.spec().width, inp.spec().height))
    level1 = inp.read_image(0, 1, 0, 3, "float")
    inp.close()
    assert sizes == [(40, 24), (20, 12), (10, 6), (5, 3), (2, 1), (1, 1)]   # the TIFF kept level 0 alone
    np.testing.assert_array_equal(read_image(dst).pixels, im.pixels)
    np.testing.assert_allclose(level1, im.pixels.astype(np.float32).reshape(12, 2, 20, 2, 3).mean(axis=(1, 3)),
                               atol=2e-3 if ext == ".exr" else 3e-3)   # half floats, 8-bit
    assert leftovers(tmp_path) == []


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


def test_a_truncated_jpeg_is_refused_not_filtered_with_grey_rows(tmp_path):
    # libjpeg fills the missing rows with grey and OpenImageIO returns them, reporting only an error
    arr = np.random.default_rng(3).integers(0, 255, (64, 48, 3), dtype=np.uint8)
    whole = tmp_path / "whole.jpg"
    write_raw(whole, arr, "uint8")
    cut = tmp_path / "cut.jpg"
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size // 2])
    with pytest.raises(ImageReadError, match="cut.jpg: reading pixels failed: .*Premature end of JPEG"):
        read_image(str(cut))


def test_a_truncated_tiff_names_its_own_read_error_not_the_subimage_probe(tmp_path):
    arr = np.random.default_rng(4).integers(0, 255, (64, 48, 3), dtype=np.uint8)
    whole = tmp_path / "whole.tif"
    write_raw(whole, arr, "uint8", {"compression": "none"})
    cut = tmp_path / "cut.tif"
    cut.write_bytes(whole.read_bytes()[:whole.stat().st_size // 2])
    with pytest.raises(ImageReadError, match="cut.tif: reading pixels failed") as ei:
        read_image(str(cut))
    assert "subimage" not in str(ei.value)


def test_a_webp_is_read_not_refused_after_the_subimage_probe(tmp_path):
    # OpenImageIO's WebP reader cannot decode subimage 0 after a failed seek to subimage 1 (the multi-image probe):
    # every WebP was refused with "reading pixels failed: Couldn't decode subimage 0"
    if oiio.ImageOutput.create(str(tmp_path / "probe.webp")) is None:
        oiio.geterror()
        pytest.skip("this OpenImageIO has no WebP writer")
    arr = np.random.default_rng(6).integers(0, 255, (12, 17, 3), dtype=np.uint8)
    path = tmp_path / "frame.webp"
    write_raw(path, arr, "uint8", {"compression": "lossless"})
    inp = oiio.ImageInput.open(str(path))
    expected = inp.read_image(0, 0, 0, 3, "uint8")
    inp.close()
    im = read_image(str(path))
    assert im.pixels.shape == (12, 17, 3)
    np.testing.assert_array_equal(im.pixels, expected)


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


@pytest.mark.parametrize("src_ext,fmt,dst_ext", [(".exr", "half", ".png"), (".tif", "uint8", ".jpg"),
                                                (".tif", "uint16", ".png"), (".exr", "half", ".tif")])
def test_a_tiled_input_is_written_to_a_format_of_scanlines(tmp_path, src_ext, fmt, dst_ext):
    # a tiled EXR or TIFF's spec carries its tile sizes: PNG's and JPEG's writers refused them ("png does not support
    # tiled images"), so no tiled render could be written as PNG or JPEG frames; TIFF keeps the tiles
    arr = np.random.default_rng(7).random((20, 30, 3)).astype(np.float32)
    spec = oiio.ImageSpec(30, 20, 3, fmt)
    spec.tile_width = spec.tile_height = 16
    src = tmp_path / f"tiled{src_ext}"
    out = oiio.ImageOutput.create(str(src))
    assert out.open(str(src), spec) and out.write_image(arr) and out.close(), oiio.geterror()
    im = read_image(str(src))
    assert im.spec.tile_width == 16
    dst = tmp_path / f"out{dst_ext}"
    write_image(str(dst), im.pixels, im.spec)
    back = read_image(str(dst))
    assert back.pixels.shape == (20, 30, 3)
    assert back.spec.tile_width == (16 if dst_ext == ".tif" else 0)
    assert leftovers(tmp_path) == []


def test_unknown_output_extension_is_a_write_error_naming_the_file(tmp_path):
    with pytest.raises(ImageWriteError, match="out.nope: no OpenImageIO writer"):
        write_image(str(tmp_path / "out.nope"), np.ones((2, 2, 3), np.uint8))
    assert os.listdir(tmp_path) == []


def test_linear_exr_written_to_png_is_encoded_to_srgb_and_to_exr_or_float_tiff_kept_linear(tmp_path):
    from mlaa_stream.io.sequence import is_linear

    arr = np.zeros((3, 4, 4), np.float16)
    arr[..., :3], arr[..., 3] = 0.2, 0.5   # linear grey 0.2 premultiplied by alpha 0.5 (EXR's associated alpha)
    write_raw(tmp_path / "in.exr", arr, "half", {"oiio:ColorSpace": "lin_rec709"})
    im = read_image(str(tmp_path / "in.exr"))
    assert is_linear(im)
    lin = float(np.float16(0.2)) / 0.5   # PNG's straight alpha: the colour divided by alpha first
    want = round((1.055 * lin ** (1 / 2.4) - 0.055) * 255)   # IEC 61966-2-1 encode: 170
    assert want == 170
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


def srgb8(linear: np.ndarray) -> np.ndarray:
    """IEC 61966-2-1 encode of linear light clipped to [0, 1], as 8-bit levels (float, unrounded)."""
    v = np.clip(linear, 0.0, 1.0)
    return 255 * np.where(v <= 0.0031308, 12.92 * v, 1.055 * v ** (1 / 2.4) - 0.055)


def premultiplied_rgba(rng) -> tuple[np.ndarray, np.ndarray]:
    """(straight, premultiplied) float64 RGBA of 6x7 pixels: alpha 0.05-1, one column of alpha 0 (colour 0)."""
    straight = rng.random((6, 7, 4))
    straight[..., 3] = 0.05 + 0.95 * straight[..., 3]
    straight[:, 0] = 0.0
    pre = straight.copy()
    pre[..., :3] *= pre[..., 3:]
    return straight, pre


@pytest.mark.parametrize("ext,fmt", [(".exr", "half"), (".tif", "float")])
def test_premultiplied_alpha_is_divided_out_for_png_and_alpha_0_kept(tmp_path, ext, fmt):
    # EXR (and a float TIFF tagged associated) stores colour premultiplied by alpha, PNG straight colour: the PNG
    # got the premultiplied values, too dark wherever alpha < 1
    straight, pre = premultiplied_rgba(np.random.default_rng(11))
    stored = pre.astype(np.float16 if fmt == "half" else np.float32)
    write_raw(tmp_path / f"in{ext}", stored, fmt)   # no oiio:UnassociatedAlpha: associated, as EXR always is
    im = read_image(str(tmp_path / f"in{ext}"))
    assert image_io.is_premultiplied(im.spec) and image_io.unpremultiplies("o.png", im.spec)
    assert write_image(str(tmp_path / "out.png"), im.pixels, im.spec, linear=True) is True   # linear -> sRGB too
    png = read_image(str(tmp_path / "out.png")).pixels.astype(np.float64)
    s = stored.astype(np.float64)
    want = srgb8(s[..., :3] / np.where(s[..., 3:] > 0, s[..., 3:], 1.0))
    np.testing.assert_allclose(png[..., :3], want, atol=0.51)   # the rounding of 8 bits, no more
    np.testing.assert_allclose(png[..., 3], np.rint(s[..., 3] * 255), atol=0.51)   # alpha as it is
    assert (png[:, 0] == 0).all()   # alpha 0: nothing to divide, colour kept (no NaN)
    assert np.abs(png[..., :3] - srgb8(straight[..., :3])).max() < 1.5   # the straight colour, not the stored one
    assert np.abs(png[..., :3] - srgb8(pre[..., :3])).max() > 40


def test_premultiplied_16_bit_tiff_is_divided_out_for_png_in_its_own_levels(tmp_path):
    _, pre = premultiplied_rgba(np.random.default_rng(12))
    stored = np.rint(pre * 65535).astype(np.uint16)
    write_raw(tmp_path / "in.tif", stored, "uint16")   # tagged associated (no oiio:UnassociatedAlpha)
    im = read_image(str(tmp_path / "in.tif"))
    write_image(str(tmp_path / "out.png"), im.pixels, im.spec)
    png = read_image(str(tmp_path / "out.png")).pixels
    s = stored.astype(np.float64)
    want = np.clip(np.rint(s[..., :3] * 65535 / np.where(s[..., 3:] > 0, s[..., 3:], 65535)), 0, 65535)
    assert png.dtype == np.uint16
    np.testing.assert_array_equal(png[..., :3], want)
    np.testing.assert_array_equal(png[..., 3], stored[..., 3])


@pytest.mark.parametrize("src", [".exr", ".tif"])
def test_premultiplied_alpha_stays_premultiplied_and_bit_exact_in_exr_and_tiff(tmp_path, src):
    _, pre = premultiplied_rgba(np.random.default_rng(13))
    stored = pre.astype(np.float32)
    write_raw(tmp_path / f"in{src}", stored, "float")
    im = read_image(str(tmp_path / f"in{src}"))
    for ext in (".exr", ".tif"):
        assert not image_io.unpremultiplies(f"o{ext}", im.spec)
        write_image(str(tmp_path / f"out{ext}"), im.pixels, im.spec, linear=True)
        back = read_image(str(tmp_path / f"out{ext}"))
        np.testing.assert_array_equal(back.pixels, stored)
        assert image_io.is_premultiplied(back.spec)   # the TIFF is tagged associated, not straight
        again = tmp_path / f"again{ext}"
        write_image(str(again), back.pixels, back.spec)
        np.testing.assert_array_equal(read_image(str(again)).pixels, stored)


def test_straight_alpha_is_written_as_it_is(tmp_path):
    # PNG, TGA and BMP store straight alpha (BMP's reader does not say so): nothing divided, to any format
    rgba = np.random.default_rng(14).integers(0, 256, (5, 6, 4), dtype=np.uint8)
    for ext in (".png", ".tga", ".bmp"):
        write_raw(tmp_path / f"in{ext}", rgba, "uint8", {"oiio:UnassociatedAlpha": 1})
        im = read_image(str(tmp_path / f"in{ext}"))
        assert not image_io.is_premultiplied(im.spec)
        write_image(str(tmp_path / f"out{ext}.png"), im.pixels, im.spec)
        np.testing.assert_array_equal(read_image(str(tmp_path / f"out{ext}.png")).pixels, rgba)
    write_image(str(tmp_path / "frame.png"), rgba)   # no spec (a decoded video frame): straight
    np.testing.assert_array_equal(read_image(str(tmp_path / "frame.png")).pixels, rgba)


def test_the_filter_says_once_that_premultiplied_alpha_is_divided_out(tmp_path):
    from click.testing import CliRunner

    from mlaa_stream.cli.main import main

    frame = np.zeros((12, 16, 4), np.float16)
    frame[..., :3], frame[..., 3] = 0.1, 0.25   # flat (nothing for the filter): straight linear 0.4
    (tmp_path / "in").mkdir()
    for n in (1, 2):
        write_raw(tmp_path / "in" / f"a.{n:04d}.exr", frame, "half")
    r = CliRunner().invoke(main, [str(tmp_path / "in" / "a.%04d.exr"), "-o", str(tmp_path / "out" / "a.%04d.png")])
    assert r.exit_code == 0, r.output
    assert r.output.count("premultiplied alpha of .exr frames is divided out for .png") == 1
    png = read_image(str(tmp_path / "out" / "a.0002.png")).pixels
    assert (png[..., :3] == round(float(srgb8(np.float64(np.float16(0.1)) / np.float16(0.25))))).all()
    assert (png[..., 3] == 64).all()
    r = CliRunner().invoke(main, [str(tmp_path / "in"), "-o", str(tmp_path / "exr")])   # EXR out: nothing said
    assert r.exit_code == 0 and "premultiplied" not in r.output, r.output
    np.testing.assert_array_equal(read_image(str(tmp_path / "exr" / "a.0001.exr")).pixels, frame)


def test_jpeg_outputs_keep_their_source_quality(tmp_path):
    """A folder of JPEGs saved at 100 (4:4:4) and 75: their outputs were all written at OpenImageIO's default (98),
    losing detail of the first and inflating the second. Each output now gets its source's quality, estimated from
    its luma quantisation table (libjpeg's own tables: tolerance 0, the table matches exactly); a PNG source gets 98,
    and --jpeg-quality sets it for all, also for a video's frames."""
    from click.testing import CliRunner

    from mlaa_stream.cli.main import main
    from mlaa_stream.io.images import DEFAULT_JPEG_QUALITY, jpeg_quality

    y, x = np.mgrid[0:48, 0:64]
    img = np.where(((y * 2) > x)[..., None], [30, 40, 200], [230, 220, 200]).astype(np.uint8)
    (tmp_path / "in").mkdir()
    for q, sub in ((100, "4:4:4"), (75, "4:2:0"), (40, "4:2:0")):
        write_raw(tmp_path / "in" / f"q{q}.jpg", img, "uint8", {"Compression": f"jpeg:{q}", "jpeg:subsampling": sub})
        assert jpeg_quality(str(tmp_path / "in" / f"q{q}.jpg")) == q
    assert jpeg_quality(os.path.join(DEMO, "rgb8.png")) is None
    r = CliRunner().invoke(main, [str(tmp_path / "in"), "-o", str(tmp_path / "out")])
    assert r.exit_code == 0, r.output
    for q in (100, 75, 40):
        assert jpeg_quality(str(tmp_path / "out" / f"q{q}.jpg")) == q
    inp = oiio.ImageInput.open(str(tmp_path / "out" / "q100.jpg"))
    assert inp.spec().get_string_attribute("jpeg:subsampling") == "4:4:4"
    inp.close()
    r = CliRunner().invoke(main, [str(tmp_path / "in"), "-o", str(tmp_path / "q90"), "--jpeg-quality", "90"])
    assert r.exit_code == 0 and "no effect" not in r.output, r.output
    assert {jpeg_quality(str(tmp_path / "q90" / f"q{q}.jpg")) for q in (100, 75, 40)} == {90}
    r = CliRunner().invoke(main, [os.path.join(DEMO, "rgb8.png"), "-o", str(tmp_path / "from_png.jpg")])
    assert r.exit_code == 0 and jpeg_quality(str(tmp_path / "from_png.jpg")) == DEFAULT_JPEG_QUALITY, r.output
    clip = os.path.join(DEMO, "..", "clip.mp4")
    r = CliRunner().invoke(main, [clip, "-o", str(tmp_path / "frames" / "%04d.jpg"), "--jpeg-quality", "85"])
    assert r.exit_code == 0, r.output
    assert jpeg_quality(str(tmp_path / "frames" / "0001.jpg")) == 85
    r = CliRunner().invoke(main, [clip, "-o", str(tmp_path / "c.mp4"), "--jpeg-quality", "85"])
    assert r.exit_code == 0 and "--jpeg-quality has no effect here" in r.output, r.output
