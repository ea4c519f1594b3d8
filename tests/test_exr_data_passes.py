"""EXRs of data passes (depth, normals, positions, motion vectors) through `mlaa-stream`: a file without colour
channels is copied unchanged (a blended depth or normal at a silhouette is a value of neither surface), every channel,
name, sample type and header attribute bit for bit; a file with colour has its colour filtered and the rest kept."""
from __future__ import annotations

import csv
import os

import numpy as np
import OpenImageIO as oiio
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from test_exr_aovs import staircase


def run(*args) -> object:
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert "Traceback" not in result.output, result.output
    return result


def data_pass(mask: np.ndarray, n: int) -> np.ndarray:
    """`n` channels that step across the staircase's edge (what the filter would blend), with low bits half and
    float32 both keep."""
    rng = np.random.default_rng(n)
    near, far = rng.uniform(-3, 3, n), rng.uniform(5, 50, n)
    return np.where(mask[:, :, None], near, far).astype(np.float32) + rng.random(mask.shape + (n,), np.float32)


def write_exr(path, pixels: np.ndarray, names: tuple[str, ...], formats: tuple[str, ...]) -> None:
    """An EXR as a renderer writes one: per-channel sample types, zip compression, a data window inside a larger
    display window, and attributes of its own."""
    h, w, c = pixels.shape
    spec = oiio.ImageSpec(w, h, c, "float")
    spec.channelnames = names
    spec.channelformats = tuple(oiio.TypeDesc(f) for f in formats)
    spec.x, spec.y, spec.full_x, spec.full_y, spec.full_width, spec.full_height = 3, 2, 0, 0, w + 8, h + 4
    spec.attribute("compression", "zip")
    spec.attribute("renderer", "mlaa-test 1.0")
    spec.attribute("camera/fov", 42.5)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels) and out.close(), oiio.geterror()


def channels(path) -> tuple[oiio.ImageSpec, list[tuple[str, str, bytes]]]:
    """The spec and, per channel, its name, sample type and raw samples as stored."""
    inp = oiio.ImageInput.open(str(path))
    spec = oiio.ImageSpec(inp.spec())
    formats = spec.channelformats or (spec.format,) * spec.nchannels
    got = [(name, str(fmt), np.asarray(inp.read_image(0, 0, c, c + 1, str(fmt))).tobytes())
           for c, (name, fmt) in enumerate(zip(spec.channelnames, formats))]
    inp.close()
    return spec, got


def assert_copied(src, dst) -> None:
    """`dst` holds `src`'s channels (names, types, samples) bit for bit, and its header as the EXR write keeps it."""
    want_spec, want = channels(src)
    got_spec, got = channels(dst)
    assert [(n, f) for n, f, _ in got] == [(n, f) for n, f, _ in want]
    for (name, _, g), (_, _, w) in zip(got, want):
        assert g == w, f"{name} changed"
    for attr in ("compression", "renderer"):
        assert got_spec.get_string_attribute(attr) == want_spec.get_string_attribute(attr)
    assert got_spec.getattribute("camera/fov") == want_spec.getattribute("camera/fov")
    window = ("x", "y", "width", "height", "full_x", "full_y", "full_width", "full_height")
    assert [getattr(got_spec, k) for k in window] == [getattr(want_spec, k) for k in window]


@pytest.mark.parametrize("names, formats", [
    (("Z",), ("float",)),
    (("depth.Z",), ("half",)),
    (("N.x", "N.y", "N.z"), ("half",) * 3),
    (("normal.X", "normal.Y", "normal.Z"), ("float",) * 3),
    (("P.x", "P.y", "P.z", "Z"), ("float", "float", "float", "half")),
    (("motion.x", "motion.y"), ("half", "half")),
    (("forward.u", "forward.v"), ("float", "float")),
])
def test_an_exr_without_colour_is_copied_unchanged(tmp_path, names, formats):
    _, mask = staircase()
    src, dst = tmp_path / "pass.exr", tmp_path / "out.exr"
    write_exr(src, data_pass(mask, len(names)), names, formats)
    result = run(src, "-o", dst)
    assert result.exit_code == 0, result.output
    stored = [name for name, _, _ in channels(src)[1]]   # in OpenImageIO's order (Z first)
    assert sorted(stored) == sorted(names)
    line = f"mlaa-stream: warning: {src}: no colour channels ({', '.join(stored)}): copied unchanged"
    assert result.output.count("copied unchanged") == 1 and line in result.output, result.output
    assert_copied(src, dst)


def test_a_folder_of_beauty_and_data_passes_filters_the_beauty_and_copies_the_passes(tmp_path):
    rgb, mask = staircase()
    (tmp_path / "in").mkdir()
    write_exr(tmp_path / "in" / "beauty.exr", rgb, ("R", "G", "B"), ("half",) * 3)
    write_exr(tmp_path / "in" / "depth.exr", data_pass(mask, 1), ("Z",), ("float",))
    write_exr(tmp_path / "in" / "normals.exr", data_pass(mask, 3), ("N.x", "N.y", "N.z"), ("half",) * 3)
    result = run(tmp_path / "in", "-o", tmp_path / "out", "-v")
    assert result.exit_code == 0, result.output
    assert "3 written (2 copied unchanged: no colour), 0 skipped" in result.output
    assert result.output.count("copied unchanged") == 3   # one line a file, and the summary
    for name in ("depth.exr", "normals.exr"):
        assert_copied(tmp_path / "in" / name, tmp_path / "out" / name)
    _, beauty_in = channels(tmp_path / "in" / "beauty.exr")
    _, beauty_out = channels(tmp_path / "out" / "beauty.exr")
    assert beauty_in != beauty_out   # the colour file was filtered


def test_with_the_temporal_stage_the_passes_are_copied_and_have_no_stats_rows(tmp_path):
    rgb, mask = staircase()
    (tmp_path / "in").mkdir()
    for n in (1, 2):
        write_exr(tmp_path / "in" / f"a_beauty.{n}.exr", rgb, ("R", "G", "B"), ("half",) * 3)
        write_exr(tmp_path / "in" / f"b_depth.{n}.exr", data_pass(mask, 1), ("depth.Z",), ("float",))
    stats = tmp_path / "stats.csv"
    result = run(tmp_path / "in", "-o", tmp_path / "out", "--temporal", "--stats", stats)
    assert result.exit_code == 0, result.output
    for n in (1, 2):
        assert_copied(tmp_path / "in" / f"b_depth.{n}.exr", tmp_path / "out" / f"b_depth.{n}.exr")
    with open(stats, newline="") as fh:
        assert [int(row["index"]) for row in csv.DictReader(fh)] == [0, 1]   # the two beauty frames only


def test_a_sequence_of_depth_passes_is_copied_frame_by_frame(tmp_path):
    _, mask = staircase()
    (tmp_path / "shot").mkdir()
    for n in (1001, 1002, 1003):
        write_exr(tmp_path / "shot" / f"depth.{n}.exr", data_pass(mask, 1) + (n - 1001) / 4, ("Z",), ("float",))
    result = run(tmp_path / "shot" / "depth.%04d.exr", "-o", tmp_path / "clean" / "depth.%04d.exr")
    assert result.exit_code == 0, result.output
    for n in (1001, 1002, 1003):
        assert_copied(tmp_path / "shot" / f"depth.{n}.exr", tmp_path / "clean" / f"depth.{n}.exr")


@pytest.mark.parametrize("names, formats, colour", [
    (("R", "G", "B", "A", "Z", "N.x", "N.y", "N.z"), ("half",) * 4 + ("float",) + ("half",) * 3, ("R", "G", "B")),
    (("beauty.R", "beauty.G", "beauty.B", "depth.Z", "motion.x", "motion.y", "P.x", "P.y", "P.z"),
     ("float",) * 9, ("beauty.R", "beauty.G", "beauty.B")),
])
def test_a_multi_layer_exr_with_colour_has_it_filtered_and_its_passes_kept(tmp_path, names, formats, colour):
    rgb, mask = staircase()
    passes = data_pass(mask, len(names) - len(colour))
    alpha = ("A",) if "A" in names else ()
    pixels = np.concatenate([rgb, np.ones(mask.shape + (len(alpha),), np.float32), passes[:, :, len(alpha):]], 2)
    src, dst = tmp_path / "layers.exr", tmp_path / "out.exr"
    write_exr(src, pixels, names, formats)
    result = run(src, "-o", dst)
    assert result.exit_code == 0 and "copied unchanged" not in result.output, result.output
    _, want = channels(src)
    _, got = channels(dst)
    assert [(n, f) for n, f, _ in got] == [(n, f) for n, f, _ in want]
    for (name, _, g), (_, _, w) in zip(got, want):
        if name in colour:
            assert g != w, f"{name}: not filtered"
        else:
            assert g == w, f"{name} changed"


def test_a_tiff_whose_default_channel_names_say_nothing_is_still_filtered(tmp_path):
    """Only a format that names its channels (EXR) says a file has no colour: a 2-channel TIFF's "R", "G" are
    OpenImageIO's names by position (grey and an untagged alpha), filtered as before."""
    rgb, _ = staircase()
    grey = np.rint(np.stack([rgb[:, :, 0], np.ones_like(rgb[:, :, 0])], 2) * 65535).astype(np.uint16)
    src, dst = tmp_path / "ga.tif", tmp_path / "out.tif"
    out = oiio.ImageOutput.create(str(src))
    assert out.open(str(src), oiio.ImageSpec(grey.shape[1], grey.shape[0], 2, "uint16")) and out.write_image(grey) \
        and out.close()
    result = run(src, "-o", dst)
    assert result.exit_code == 0 and "copied unchanged" not in result.output, result.output
    inp = oiio.ImageInput.open(str(dst))
    got = np.asarray(inp.read_image(0, 0, 0, 2, "uint16"))
    inp.close()
    assert not np.array_equal(got[:, :, 0], grey[:, :, 0]) and np.array_equal(got[:, :, 1], grey[:, :, 1])
    assert os.path.getsize(dst) > 0
