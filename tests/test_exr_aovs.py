"""Render-pipeline EXRs through `mlaa-stream`: AOV and cryptomatte channels, colour-space tags, compression
settings. What is not colour must come out bit for bit, and what a pipeline reads from the header must stay."""
from __future__ import annotations

import os

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.images import ImageReadError, read_image, split_for_filter


def run(*args: str):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert "Traceback" not in result.output, result.output
    return result


def staircase(h: int = 24, w: int = 32) -> tuple[np.ndarray, np.ndarray]:
    """An aliased half-plane (RGB float) and its mask: a staircase edge the filter changes."""
    y, x = np.mgrid[0:h, 0:w]
    mask = y > x / 3.0 + h / 4
    rgb = np.where(mask[:, :, None], np.float32([0.9, 0.8, 0.1]), np.float32([0.1, 0.2, 0.6]))
    return rgb.astype(np.float32), mask


def crypto_ids(mask: np.ndarray) -> np.ndarray:
    """Cryptomatte-like ids: float32 bit patterns of hashes, in the range colour takes (0.29, 0.57)."""
    a, b = np.uint32(0x3F123457).view(np.float32), np.uint32(0x3E987655).view(np.float32)
    return np.where(mask, a, b).astype(np.float32)


def write_exr(path, pixels: np.ndarray, names: tuple[str, ...], **attrs) -> None:
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], "float")
    spec.channelnames = names
    for key, value in attrs.items():
        spec.attribute(key, value)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close(), oiio.geterror()


def read_all(path) -> tuple[tuple[str, ...], np.ndarray]:
    inp = oiio.ImageInput.open(str(path))
    spec = inp.spec()
    pixels = inp.read_image(0, 0, 0, spec.nchannels, "float")
    inp.close()
    return tuple(spec.channelnames), np.asarray(pixels)


@pytest.mark.parametrize("crypto, attrs", [
    ("CryptoObject00", {}),   # sorts before "diffuse", and OpenImageIO takes its A for the image's alpha
    ("ViewLayer.CryptoMaterial00", {}),   # Blender's naming
    ("matte_ids00", {"cryptomatte/a1b2c3d/name": "matte_ids"}),   # a type named otherwise: by its header
])
def test_cryptomatte_layers_are_never_filtered_as_the_colour(tmp_path, crypto, attrs):
    rgb, mask = staircase()
    ids = crypto_ids(mask)
    names = (f"{crypto}.R", f"{crypto}.G", f"{crypto}.B", f"{crypto}.A", "diffuse.R", "diffuse.G", "diffuse.B")
    pixels = np.concatenate([np.stack([ids, np.full_like(ids, 0.6), ids[:, ::-1], np.full_like(ids, 0.4)], 2), rgb],
                            axis=2)
    src = tmp_path / "aov.exr"
    write_exr(src, pixels, names, **attrs)
    image = read_image(str(src))
    frame, _ = split_for_filter(image)
    diffuse = [image.channel_names.index(n) for n in ("diffuse.R", "diffuse.G", "diffuse.B")]
    np.testing.assert_array_equal(frame, image.pixels[:, :, diffuse])

    dst = tmp_path / "out.exr"
    result = run(src, "-o", dst)
    assert result.exit_code == 0, result.output
    got_names, got = read_all(dst)
    want_names, want = read_all(src)
    assert got_names == want_names
    for k, name in enumerate(want_names):
        if name.startswith(crypto):   # ids and coverage bit for bit
            np.testing.assert_array_equal(got[:, :, k].view(np.uint32), want[:, :, k].view(np.uint32), err_msg=name)
    assert not np.array_equal(got[:, :, diffuse], want[:, :, diffuse])   # the colour layer was filtered


def test_an_exr_of_cryptomatte_channels_only_is_copied_unchanged(tmp_path):
    """Refused before (nothing to filter, and the run failed); now copied as every file without colour is
    (tests/test_exr_data_passes.py): render pipelines write cryptomatte as a file of its own beside the beauty."""
    _, mask = staircase()
    ids = crypto_ids(mask)
    names = ("CryptoAsset00.R", "CryptoAsset00.G", "CryptoAsset00.B", "CryptoAsset00.A")
    src = tmp_path / "crypto.exr"
    write_exr(src, np.stack([ids, ids * 0 + 1, ids[::-1], ids * 0], 2), names)
    with pytest.raises(ImageReadError, match="only cryptomatte channels"):
        split_for_filter(read_image(str(src)))   # what takes a frame to filter (the overlay command) refuses it
    result = run(src, "-o", tmp_path / "out.exr")
    assert result.exit_code == 0, result.output
    assert f"{src}: only cryptomatte channels ({', '.join(names)}): copied unchanged" in result.output
    got_names, got = read_all(tmp_path / "out.exr")
    want_names, want = read_all(src)
    assert got_names == want_names and np.array_equal(got.view(np.uint32), want.view(np.uint32))


@pytest.mark.parametrize("space, linear", [("ACEScct", False), ("acescct_ap1", False), ("ACES - ACEScc", False),
                                           ("ACEScg", True), ("lin_ap1_scene", True), ("ACES2065-1", True)])
def test_aces_log_encodings_are_not_taken_for_linear_light(tmp_path, space, linear):
    from mlaa_stream.io.sequence import is_linear

    rgb, _ = staircase()
    src = tmp_path / "graded.exr"
    write_exr(src, rgb, ("R", "G", "B"), **{"oiio:ColorSpace": space})
    assert is_linear(read_image(str(src))) is linear
    # written to PNG: linear light is encoded to sRGB; ACEScct's log values are written as they are
    result = run(src, "-o", tmp_path / "out.png")
    assert result.exit_code == 0, result.output
    assert ("encoded to sRGB" in result.output) is linear
    inp = oiio.ImageInput.open(str(tmp_path / "out.png"))
    corner = np.asarray(inp.read_image(0, 0, 0, 3, "float"))[0, 0]   # far from the edge: unfiltered
    inp.close()
    if not linear:
        np.testing.assert_allclose(corner, rgb[0, 0], atol=0.5 / 255)


@pytest.mark.parametrize("compression, level", [("dwaa", 200.0), ("dwab", 300.0), ("dwaa", 15.0)])
def test_an_exr_keeps_its_dwa_compression_level(tmp_path, compression, level):
    rgb, _ = staircase()
    src = tmp_path / "dwa.exr"
    write_exr(src, rgb, ("R", "G", "B"), compression=f"{compression}:{level:g}")
    result = run(src, "-o", tmp_path / "out.exr")
    assert result.exit_code == 0, result.output
    spec = oiio.ImageInput.open(str(tmp_path / "out.exr")).spec()
    assert spec.get_string_attribute("compression") == compression
    assert spec.getattribute("openexr:dwaCompressionLevel") == level


def test_a_hash_pattern_is_a_frame_pattern_in_and_out(tmp_path):
    from mlaa_stream.io.sequence import printf_pattern

    rgb, _ = staircase()
    (tmp_path / "shot").mkdir()
    for n in (1001, 1002):
        write_exr(tmp_path / "shot" / f"shot.{n}.exr", rgb, ("R", "G", "B"))
    result = run(tmp_path / "shot" / "shot.####.exr", "-o", tmp_path / "clean" / "shot_####.exr")
    assert result.exit_code == 0, result.output
    assert sorted(os.listdir(tmp_path / "clean")) == ["shot_1001.exr", "shot_1002.exr"]
    assert printf_pattern("a/b.######.dpx") == "a/b.%06d.dpx"
    assert printf_pattern("take#1.png") == "take#1.png" and printf_pattern("x.%04d.exr") == "x.%04d.exr"
    literal = tmp_path / "odd##name.exr"   # a file named so is that file
    write_exr(literal, rgb, ("R", "G", "B"))
    assert printf_pattern(str(literal)) == str(literal)


@pytest.mark.parametrize("big", [True, False])
def test_a_32_bit_integer_id_channel_that_cannot_come_back_exactly_is_named(tmp_path, big):
    rgb, mask = staircase()
    ids = np.where(mask, 0xDEADBEEF if big else 1000, 123456789 if big else 7).astype(np.uint32)
    spec = oiio.ImageSpec(rgb.shape[1], rgb.shape[0], 4, "float")
    spec.channelnames = ("R", "G", "B", "objectId")
    spec.channelformats = (oiio.TypeDesc("half"),) * 3 + (oiio.TypeDesc("uint"),)
    pixels = np.zeros(rgb.shape[:2] + (4,), np.uint32)   # one buffer type for all: uint32 keeps the ids exact
    pixels[:, :, :3] = np.rint(rgb * 4294967295.0).astype(np.uint32)
    pixels[:, :, 3] = ids
    src = tmp_path / "ids.exr"
    out = oiio.ImageOutput.create(str(src))
    assert out.open(str(src), spec) and out.write_image(pixels) and out.close(), oiio.geterror()
    result = run(src, "-o", tmp_path / "out.exr")
    assert result.exit_code == 0, result.output
    assert ("objectId: 32-bit integer channel with values over 2^24" in result.output) is big
    if not big:   # ids float32 holds come back bit for bit
        inp = oiio.ImageInput.open(str(tmp_path / "out.exr"))
        np.testing.assert_array_equal(np.asarray(inp.read_image(0, 0, 3, 4, "uint")).reshape(ids.shape), ids)
        inp.close()
