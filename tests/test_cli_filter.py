"""`mlaa-stream INPUT -o OUTPUT` through click's CliRunner: exit codes and messages for images,
folders, sequences and videos, for good input and for every kind of bad input."""
from __future__ import annotations

import errno
import os
import re
import shutil
import struct
import subprocess
import sys
from pathlib import Path
import types
import zlib

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.io import images as image_io
from mlaa_stream.cli.main import main
from mlaa_stream.io.images import read_image
from demo_maker import ROOT, make_demo

DEMO = os.path.join(ROOT, "fixtures", "demo")


def run(*args: str):
    result = CliRunner().invoke(main, [str(a) for a in args])
    assert "Traceback" not in result.output, result.output
    assert not isinstance(result.exception, Exception) or isinstance(result.exception, SystemExit), \
        repr(result.exception)
    return result


def stderr(result) -> str:
    return result.stderr if hasattr(result, "stderr") else result.output


def temp_files(folder) -> list[str]:
    return [os.path.join(d, n) for d, _, fs in os.walk(folder) for n in fs if image_io.is_temp_path(n)]


def write_png(path, arr):
    make_demo.write_oiio(str(path), arr, "uint8" if arr.dtype == np.uint8 else "uint16")


def staircase(h=24, w=32, slope=3.0, dtype=np.uint8):
    """An aliased half-plane: a staircase edge the filter must change."""
    y, x = np.mgrid[0:h, 0:w]
    hi = np.iinfo(dtype).max if np.dtype(dtype).kind == "u" else 1.0
    img = np.where((y > x / slope + h / 4)[:, :, None], np.array([0.9, 0.8, 0.1]) * hi,
                   np.array([0.1, 0.2, 0.6]) * hi)
    return img.astype(dtype)


def png_with_size(path, w, h):
    """A syntactically valid PNG header claiming w x h pixels (0 is invalid in PNG)."""
    def chunk(kind, data):
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))
    raw = zlib.compress(b"")
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0))
                     + chunk(b"IDAT", raw) + chunk(b"IEND", b""))


# -- images and folders -------------------------------------------------------------------------
def test_demo_folder_keeps_formats_depth_alpha_and_metadata(tmp_path):
    out = tmp_path / "clean"
    r = run(os.path.join(DEMO, "images"), "-o", out)
    assert r.exit_code == 0, stderr(r)
    names = sorted(os.listdir(os.path.join(DEMO, "images")))
    assert sorted(os.listdir(out)) == names
    changed = 0
    for name in names:
        a, b = read_image(os.path.join(DEMO, "images", name)), read_image(str(out / name))
        assert b.pixels.dtype == a.pixels.dtype and b.pixels.shape == a.pixels.shape, name
        assert b.spec.get_string_attribute("oiio:ColorSpace") == a.spec.get_string_attribute("oiio:ColorSpace")
        if a.pixels.shape[2] == 4:
            np.testing.assert_array_equal(b.pixels[:, :, 3], a.pixels[:, :, 3])  # alpha untouched
        changed += not np.array_equal(a.pixels, b.pixels)
    assert changed >= 6  # the jpeg is re-encoded anyway; the rest change only by filtering
    assert temp_files(tmp_path) == []


def test_single_image_refuses_to_overwrite_then_overwrites(tmp_path):
    src = tmp_path / "in.png"
    write_png(src, staircase())
    dst = tmp_path / "out.png"
    assert run(src, "-o", dst).exit_code == 0
    first = dst.read_bytes()
    r = run(src, "-o", dst)
    assert r.exit_code == 2 and f"{dst}: exists" in stderr(r) and "--overwrite" in stderr(r)
    assert dst.read_bytes() == first
    r = run(src, "-o", dst, "--overwrite", "--metric", "luma")
    assert r.exit_code == 0, stderr(r)
    assert not np.array_equal(read_image(str(dst)).pixels, staircase())


def test_output_into_an_existing_folder_keeps_the_name(tmp_path):
    src = tmp_path / "in.png"
    write_png(src, staircase())
    (tmp_path / "o").mkdir()
    assert run(src, "-o", tmp_path / "o").exit_code == 0
    assert os.listdir(tmp_path / "o") == ["in.png"]


@pytest.mark.parametrize("how", ["same", "dot", "symlink", "hardlink"])
def test_output_that_is_the_input_is_refused(tmp_path, how):
    src = tmp_path / "in.png"
    write_png(src, staircase())
    before = src.read_bytes()
    if how == "same":
        out = src
    elif how == "dot":
        out = tmp_path / "." / "in.png"
    elif how == "symlink":
        out = tmp_path / "link.png"
        out.symlink_to(src)
    else:
        out = tmp_path / "hard.png"
        os.link(src, out)
    r = run(src, "-o", out, "--overwrite")
    assert r.exit_code == 2 and "is the input" in stderr(r)
    assert src.read_bytes() == before


def test_a_folder_numbered_into_a_pattern_in_itself_never_replaces_an_input(tmp_path):
    """in/ with 0002.png, 0003.png, a.png -o 'in/%04d.png' -y: 0003.png's output is 0002.png, 0002.png's is
    0001.png -- --overwrite replaced two inputs ('never an input'). Refused before anything is written, by the
    command line and by the cluster's Python API."""
    from mlaa_stream.cluster.frames import filter_on_cluster
    for name in ("0002.png", "0003.png", "a.png"):
        write_png(tmp_path / name, staircase())
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    r = run(tmp_path, "-o", tmp_path / "%04d.png", "--overwrite")
    two, three = tmp_path / "0002.png", tmp_path / "0003.png"
    msg = f"{two}: the output of {three} would replace the input {two}"
    assert r.exit_code == 2 and msg in stderr(r)
    with pytest.raises(ValueError, match="would replace the input"):
        filter_on_cluster(None, str(tmp_path), str(tmp_path / "%04d.png"), overwrite=True)  # before any client use
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_a_folder_into_itself_is_refused(tmp_path):
    write_png(tmp_path / "a.png", staircase())
    r = run(tmp_path, "-o", tmp_path, "--overwrite")
    assert r.exit_code == 2 and "is the input folder" in stderr(r)


def test_nonexistent_input(tmp_path):
    r = run(tmp_path / "nope.png", "-o", tmp_path / "o.png")
    assert r.exit_code == 2 and "nope.png: no such file or directory" in stderr(r)


def test_bad_files_in_a_folder_are_named_and_the_others_processed(tmp_path):
    src = tmp_path / "in"
    src.mkdir()
    write_png(src / "a_good.png", staircase())
    (src / "b_empty.png").write_bytes(b"")
    (src / "c_text.png").write_text("not an image")
    png_with_size(src / "d_zero_wide.png", 0, 5)
    write_png(src / "e_one_wide.png", staircase(w=1))
    write_png(src / "f_one_pixel.png", staircase(h=1, w=1))
    write_png(src / "g_odd.png", staircase(h=7, w=13))
    write_png(src / "h_sixteen.png", staircase(dtype=np.uint16))
    Image = pytest.importorskip("PIL.Image")
    Image.fromarray(staircase()).quantize(colors=4).save(src / "i_palette.png")
    rgba = np.concatenate([staircase(), np.full((24, 32, 1), 77, np.uint8)], axis=2)
    make_demo.write_oiio(str(src / "j_alpha.png"), rgba, "uint8", {"oiio:UnassociatedAlpha": 1})
    (src / "notes.txt").write_text("a text file among the images")
    out = tmp_path / "out"
    r = run(src, "-o", out)
    err = stderr(r)
    assert r.exit_code == 1
    for bad in ("b_empty.png", "c_text.png", "d_zero_wide.png"):
        assert str(src / bad) in err
        assert not (out / bad).exists()
    assert "empty file" in err
    assert "notes.txt: skipped (not an image file" in err
    assert "3 failed, 7 written" in err
    good = ["a_good.png", "e_one_wide.png", "f_one_pixel.png", "g_odd.png", "h_sixteen.png",
            "i_palette.png", "j_alpha.png"]
    assert sorted(os.listdir(out)) == good
    assert read_image(str(out / "h_sixteen.png")).pixels.dtype == np.uint16
    assert read_image(str(out / "e_one_wide.png")).pixels.shape == (24, 1, 3)
    np.testing.assert_array_equal(read_image(str(out / "j_alpha.png")).pixels[:, :, 3], 77)
    assert temp_files(tmp_path) == []


def test_a_broken_link_in_a_folder_is_named_not_dropped(tmp_path):
    """A folder of frames linked from a cache with one link gone lost that frame without a word (exit 0)."""
    src = tmp_path / "in 1"
    src.mkdir()
    write_png(tmp_path / "cached.png", staircase())
    os.symlink(tmp_path / "cached.png", src / "a_linked.png")
    os.symlink(tmp_path / "gone.png", src / "b_broken.png")
    out = tmp_path / "out"
    r = run(src, "-o", out)
    err = stderr(r)
    assert r.exit_code == 1
    assert f"{src / 'b_broken.png'}: cannot read: a link to {tmp_path / 'gone.png'}, which does not exist" in err
    assert "1 failed, 1 written" in err
    assert sorted(os.listdir(out)) == ["a_linked.png"]


def test_a_non_image_file_given_directly_is_refused(tmp_path):
    bad = tmp_path / "photo.png"
    bad.write_text("hello")
    r = run(bad, "-o", tmp_path / "o.png")
    assert r.exit_code == 1 and f"{bad}: expected an image" in stderr(r)
    assert not (tmp_path / "o.png").exists()


def test_unwritable_output_folder(tmp_path):
    src = tmp_path / "in.png"
    write_png(src, staircase())
    locked = tmp_path / "locked"
    locked.mkdir()
    immutable = False
    if os.geteuid() == 0:  # root ignores permission bits; the immutable attribute still holds
        immutable = shutil.which("chattr") is not None and \
            subprocess.run(["chattr", "+i", str(locked)], capture_output=True).returncode == 0
        if not immutable:  # no chattr here: /proc is a folder that not even root can create files in
            locked = Path("/proc")
            if not locked.is_dir():
                pytest.skip("cannot make a folder unwritable for root here")
    else:
        locked.chmod(0o555)
    try:
        r = run(src, "-o", locked / "o.png")
        assert r.exit_code == 1 and f"{locked}: cannot write in this folder" in stderr(r)
        r = run(tmp_path / "in.png", "-o", locked / "o.png", "--overwrite")
        assert r.exit_code == 1
        folder = tmp_path / "folder"
        folder.mkdir()
        shutil.copy(src, folder / "a.png")
        r = run(folder, "-o", locked / "sub")  # a folder output must be created: it cannot be
        assert r.exit_code == 1 and f"{locked / 'sub'}: cannot create the output folder" in stderr(r)
    finally:
        if immutable:
            subprocess.run(["chattr", "-i", str(locked)])
        elif os.geteuid() != 0:
            locked.chmod(0o755)
    assert os.listdir(locked) == []


def test_a_full_disk_stops_the_run_and_leaves_no_partial_file(tmp_path, monkeypatch):
    src = tmp_path / "in"
    src.mkdir()
    for i in range(5):
        write_png(src / f"f{i}.png", staircase(slope=2 + i))
    calls = []

    def full_after_two(tmp, pixels, spec, final):
        calls.append(final)
        if len(calls) > 2:
            with open(tmp, "wb") as fh:
                fh.write(b"partial")
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), final)
        return real(tmp, pixels, spec, final)

    real = image_io._write_file
    monkeypatch.setattr(image_io, "_write_file", full_after_two)
    r = run(src, "-o", tmp_path / "out")
    assert r.exit_code == 1
    assert "No space left on device" in stderr(r) and "f2.png" in stderr(r)
    assert "stopped: 2 of 5 outputs written" in stderr(r)
    assert sorted(os.listdir(tmp_path / "out")) == ["f0.png", "f1.png"]
    assert len(calls) == 3  # stopped at the first full-disk error
    assert temp_files(tmp_path) == []


def test_ctrl_c_keeps_complete_files_and_no_temporary_one(tmp_path, monkeypatch, send_signal):
    src = tmp_path / "in"
    src.mkdir()
    for i in range(12):
        write_png(src / f"f{i:02d}.png", staircase(slope=2 + i))
    real = image_io._write_file
    seen = []

    def interrupt_at_third(tmp, pixels, spec, final):
        seen.append(final)
        if len(seen) == 3:
            send_signal()  # Ctrl-C arrives while file 3 is being written
        return real(tmp, pixels, spec, final)

    monkeypatch.setattr(image_io, "_write_file", interrupt_at_third)
    r = run(src, "-o", tmp_path / "out")
    assert r.exit_code == 130 and "interrupted" in stderr(r)
    written = sorted(os.listdir(tmp_path / "out"))
    assert 2 <= len(written) < 12
    for name in written:  # every file under a final name is complete
        assert read_image(str(tmp_path / "out" / name)).pixels.shape == (24, 32, 3)
    assert temp_files(tmp_path) == []


# -- sequences ---------------------------------------------------------------------------------
def make_sequence(folder, numbers, size=(24, 32), ext="png"):
    folder.mkdir(exist_ok=True)
    for n in numbers:
        write_png(folder / f"shot.{n:04d}.{ext}", staircase(*size, slope=2 + n % 5))


def test_sequence_with_a_frame_range_and_an_output_pattern(tmp_path):
    make_sequence(tmp_path / "seq", range(1001, 1006))
    r = run(tmp_path / "seq" / "shot.%04d.png", "--frames", "1002-1004", "-o", tmp_path / "o" / "c_%04d.png")
    assert r.exit_code == 0, stderr(r)
    assert sorted(os.listdir(tmp_path / "o")) == ["c_1002.png", "c_1003.png", "c_1004.png"]


def test_a_folder_or_one_image_to_an_output_pattern_is_numbered_in_name_order_from_1(tmp_path):
    (tmp_path / "in").mkdir()
    for k, name in enumerate(("b.png", "a.png", "c.png")):   # name order, not the order written
        write_png(tmp_path / "in" / name, staircase(slope=2 + k))
    out = tmp_path / "o" / "%04d.png"
    r = run(tmp_path / "in", "-o", out)
    assert r.exit_code == 0, stderr(r)
    assert sorted(os.listdir(tmp_path / "o")) == ["0001.png", "0002.png", "0003.png"]   # never a literal %04d
    for n, name in ((1, "a.png"), (3, "c.png")):
        alone = tmp_path / f"alone_{n}.png"
        assert run(tmp_path / "in" / name, "-o", alone).exit_code == 0
        np.testing.assert_array_equal(read_image(str(tmp_path / "o" / f"{n:04d}.png")).pixels,
                                      read_image(str(alone)).pixels)
    r = run(tmp_path / "in", "-o", out)
    assert r.exit_code == 2 and "0001.png: exists (and 2 more)" in stderr(r)
    (tmp_path / "o" / "0002.png").unlink()
    r = run(tmp_path / "in", "-o", out, "--resume", "-v")
    assert r.exit_code == 0 and "--resume: 2 outputs exist and are skipped" in stderr(r)
    assert sorted(os.listdir(tmp_path / "o")) == ["0001.png", "0002.png", "0003.png"]
    assert run(tmp_path / "in", "-o", out, "--overwrite").exit_code == 0
    r = run(tmp_path / "in" / "b.png", "-o", tmp_path / "one" / "f_%03d.png")   # one image: frame 1
    assert r.exit_code == 0, stderr(r)
    assert os.listdir(tmp_path / "one") == ["f_001.png"]



@pytest.mark.parametrize("name", ["%04d.xyz", "%04d"])
def test_an_output_pattern_without_a_writer_is_refused_before_any_frame_is_filtered(tmp_path, name):
    # every frame was filtered, then its write failed ("no OpenImageIO writer"), one error per frame, exit 1
    make_sequence(tmp_path / "seq", range(1, 4))
    for src in (tmp_path / "seq", tmp_path / "seq" / "shot.%04d.png"):
        r = run(src, "-o", tmp_path / "o" / name)
        assert r.exit_code == 2, stderr(r)
        assert stderr(r).count("error:") == 1 and "OpenImageIO has no writer for" in stderr(r), stderr(r)
        assert not (tmp_path / "o").exists()


def test_a_folder_or_sequence_to_one_image_name_is_refused_naming_a_pattern(tmp_path):
    make_sequence(tmp_path / "seq", (1, 2))
    for src in (tmp_path / "seq", tmp_path / "seq" / "shot.%04d.png"):
        r = run(src, "-o", tmp_path / "out.png")
        assert r.exit_code == 2 and f"{tmp_path / 'out'}/%04d.png" in stderr(r), stderr(r)
        assert not (tmp_path / "out.png").exists()
    r = run(tmp_path / "seq", "-o", f"{tmp_path / 'dir.png'}/")   # a folder named so, asked for
    assert r.exit_code == 0 and sorted(os.listdir(tmp_path / "dir.png")) == ["shot.0001.png", "shot.0002.png"]


def test_a_pattern_finds_the_names_it_writes_as_frames_does_not_a_second_padding(tmp_path):
    from mlaa_stream.io.sequence import expand_pattern

    folder = tmp_path / "seq"
    folder.mkdir()
    for name in ("f1.png", "f01.png", "f2.png", "f10.png", "g0012.png", "g12345.png", "g00013.png"):
        (folder / name).write_bytes(b"")
    # f01.png is another file of frame 1: which one was taken followed the folder's listing order
    for frames in (None, (1, 10)):
        assert expand_pattern(str(folder / "f%d.png"), frames)[0] == [
            (1, str(folder / "f1.png")), (2, str(folder / "f2.png")), (10, str(folder / "f10.png"))]
    assert expand_pattern(str(folder / "g%04d.png"))[0] == [(12, str(folder / "g0012.png")),
                                                            (12345, str(folder / "g12345.png"))]


def test_frames_are_found_by_listing_the_folder_once_and_gaps_come_as_spans(tmp_path):
    # --frames A-B tested a path per number: 1-2000000 took 17 s, a typo's 1-100000000 minutes and a list of every
    # missing number (gigabytes); the folder is listed once and the missing numbers come back as spans
    from mlaa_stream.io.sequence import expand_pattern, format_spans

    folder = tmp_path / "seq"
    folder.mkdir()
    for n in (3, 4, 9):
        (folder / f"s.{n:04d}.png").write_bytes(b"")
    found = [(3, str(folder / "s.0003.png")), (4, str(folder / "s.0004.png")), (9, str(folder / "s.0009.png"))]
    assert expand_pattern(str(folder / "s.%04d.png")) == (found, [(5, 8)])
    (folder / "s.0005.png").mkdir()   # with --frames, a folder of a frame's name is no frame, as before
    # (old code: 3 million file tests and a list of every missing number; 10 ** 12 would not end)
    assert expand_pattern(str(folder / "s.%04d.png"), (1, 3_000_000)) == (found, [(1, 2), (5, 8), (10, 3_000_000)])
    assert format_spans([(1, 2), (5, 8), (10, 10 ** 12)]) == "1-2, 5-8, 10-1000000000000"
    r = run(folder / "s.%04d.png", "--frames", "1-3000000", "-o", tmp_path / "out" / "o.%04d.png")
    assert r.exit_code == 1 and "missing frames 1-2, 5-8, 10-3000000" in r.output, r.output


def test_sequence_gaps_are_reported(tmp_path):
    make_sequence(tmp_path / "seq", [1, 2, 5, 6, 9])
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", tmp_path / "o")
    assert r.exit_code == 0
    assert "missing frames 3-4, 7-8" in stderr(r)
    assert len(os.listdir(tmp_path / "o")) == 5
    r = run(tmp_path / "seq" / "shot.%04d.png", "--frames", "1-6", "-o", tmp_path / "o2")
    assert r.exit_code == 1 and "missing frames 3-4" in stderr(r)
    assert sorted(os.listdir(tmp_path / "o2")) == ["shot.0001.png", "shot.0002.png",
                                                   "shot.0005.png", "shot.0006.png"]


def test_sequence_resume_skips_complete_outputs(tmp_path):
    make_sequence(tmp_path / "seq", range(1, 7))
    out = tmp_path / "o"
    out.mkdir()
    write_png(out / "shot.0002.png", staircase())  # "already done" marker content
    marker = (out / "shot.0002.png").read_bytes()
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", out)
    assert r.exit_code == 2 and "--resume" in stderr(r)
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", out, "--resume", "-v")
    assert r.exit_code == 0, stderr(r)
    assert "1 outputs exist and are skipped" in stderr(r)
    assert (out / "shot.0002.png").read_bytes() == marker
    assert len(os.listdir(out)) == 6
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", out, "--resume", "--overwrite")
    assert r.exit_code == 2 and "contradict" in stderr(r)


def test_a_linear_exr_sequence_to_png_is_srgb_encoded_once_said_and_to_exr_unchanged(tmp_path):
    (tmp_path / "ex").mkdir()
    flat = np.full((12, 16, 3), 0.2, np.float16)   # no edges: the filter leaves it as it is
    for n in (1, 2):
        make_demo.write_oiio(str(tmp_path / "ex" / f"{n:04d}.exr"), flat, "half", {"oiio:ColorSpace": "lin_rec709"})
    r = run(tmp_path / "ex" / "%04d.exr", "-o", tmp_path / "o" / "%04d.png")
    assert r.exit_code == 0, stderr(r)
    want = round((1.055 * float(np.float16(0.2)) ** (1 / 2.4) - 0.055) * 255)   # sRGB of linear 0.2: 124
    for n in (1, 2):
        png = read_image(str(tmp_path / "o" / f"{n:04d}.png"))
        assert png.pixels.dtype == np.uint8 and (png.pixels == want).all()
    assert stderr(r).count("encoded to sRGB for .png") == 1
    r = run(tmp_path / "ex" / "%04d.exr", "-o", tmp_path / "e" / "%04d.exr")
    assert r.exit_code == 0 and "sRGB" not in stderr(r)
    np.testing.assert_array_equal(read_image(str(tmp_path / "e" / "0001.exr")).pixels, flat)


@pytest.mark.parametrize("change", ["size", "channels", "depth"])
def test_a_sequence_whose_frames_change_stops_naming_the_frame(tmp_path, change):
    make_sequence(tmp_path / "seq", range(1, 4))
    bad = tmp_path / "seq" / "shot.0004.png"
    if change == "size":
        write_png(bad, staircase(20, 32))
    elif change == "channels":
        make_demo.write_oiio(str(bad), np.concatenate([staircase(), staircase()[:, :, :1]], 2), "uint8")
    else:
        write_png(bad, staircase(dtype=np.uint16))
    make_sequence(tmp_path / "seq", range(5, 7))
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", tmp_path / "o")
    assert r.exit_code == 1
    assert f"frame 4 ({bad})" in stderr(r) and "expected 32x24 with 3 channels of uint8" in stderr(r)
    assert sorted(os.listdir(tmp_path / "o")) == ["shot.0001.png", "shot.0002.png", "shot.0003.png"]


def test_an_exr_sequence_whose_data_window_changes_says_so(tmp_path):
    """Renders cropped to their bounding box change data window frame by frame while a viewer shows one display
    size: 'expected 16x12, got 10x8' named no data window."""
    import OpenImageIO as oiio
    (tmp_path / "seq").mkdir()
    for n, (x, y, w, h) in enumerate([(0, 0, 16, 12), (3, 2, 10, 8)], start=1):
        spec = oiio.ImageSpec(w, h, 3, "half")
        spec.x, spec.y, spec.full_width, spec.full_height = x, y, 16, 12
        path = str(tmp_path / "seq" / f"r.{n:04d}.exr")
        out = oiio.ImageOutput.create(path)
        assert out.open(path, spec) and out.write_image(np.full((h, w, 3), 0.5, np.float32)), oiio.geterror()
        out.close()
    r = run(tmp_path / "seq" / "r.%04d.exr", "-o", tmp_path / "o" / "r.%04d.exr")
    assert r.exit_code == 1
    assert ("expected 16x12 with 3 channels of float16 like" in stderr(r) and "got 10x8 with 3 channels of float16 "
            "(its data window, 10x8 at 3,2 of a 16x12 display window" in stderr(r)), stderr(r)


def test_frames_option_needs_a_pattern_and_a_range(tmp_path):
    write_png(tmp_path / "a.png", staircase())
    r = run(tmp_path / "a.png", "--frames", "1-3", "-o", tmp_path / "o.png")
    assert r.exit_code == 2 and "--frames needs a frame pattern" in stderr(r)
    make_sequence(tmp_path / "seq", [1])
    r = run(tmp_path / "seq" / "shot.%04d.png", "--frames", "9-3", "-o", tmp_path / "o")
    assert r.exit_code == 2 and "A <= B" in stderr(r)
    r = run(tmp_path / "seq" / "nothing.%04d.png", "-o", tmp_path / "o")
    assert r.exit_code == 2 and "no files match this frame pattern" in stderr(r)


# -- video -------------------------------------------------------------------------------------
def test_video_keeps_rate_frames_and_audio(tmp_path):
    out = tmp_path / "out.mp4"
    r = run(os.path.join(DEMO, "clip.mp4"), "-o", out, "-v")
    assert r.exit_code == 0, stderr(r)
    assert "device:" in stderr(r) and "device wait" in stderr(r)  # -v: per-stage timings
    with av.open(str(out)) as c:
        assert c.streams.video[0].average_rate == 24 and len(c.streams.audio) == 1
        assert sum(1 for _ in c.decode(video=0)) == 10
    assert os.listdir(tmp_path) == ["out.mp4"]


def test_ten_bit_video_stays_ten_bit_and_lossless_codec_works(tmp_path):
    src = tmp_path / "ten.mkv"
    make_demo.write_clip(str(src), frames=4, pix_fmt="yuv420p10le", audio=False)
    r = run(src, "-o", tmp_path / "out.mkv", "-q")
    assert r.exit_code == 0 and stderr(r) == ""
    with av.open(str(tmp_path / "out.mkv")) as c:
        assert c.streams.video[0].codec_context.pix_fmt == "yuv420p10le"
    r = run(src, "-o", tmp_path / "mid.mkv", "--codec", "ffv1")
    assert r.exit_code == 0
    with av.open(str(tmp_path / "mid.mkv")) as c:
        assert c.streams.video[0].codec_context.name == "ffv1"
        assert c.streams.video[0].codec_context.pix_fmt.startswith("gbrp1")


def test_truncated_video_keeps_a_valid_shorter_file_and_says_where_it_stopped(tmp_path):
    full = tmp_path / "full.mp4"
    make_demo.write_clip(str(full), frames=30)
    data = full.read_bytes()
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(data[: len(data) * 2 // 3])
    out = tmp_path / "out.mp4"
    r = run(cut, "-o", out)
    assert r.exit_code == 1
    err = stderr(r)
    # either the decoder fails on the cut packet, or the stream ends early for its declared length
    m = re.search(re.escape(str(cut)) + r": (?:decoding stopped|the stream ended) at frame (\d+)", err)
    assert m, err
    stopped = int(m.group(1))
    assert 0 < stopped < 30
    assert f"kept as a valid shorter video with the {stopped} frames" in err
    with av.open(str(out)) as c:
        assert sum(1 for _ in c.decode(video=0)) == stopped
    assert temp_files(tmp_path) == []


def test_not_a_video(tmp_path):
    bad = tmp_path / "movie.mp4"
    bad.write_text("definitely not a video")
    r = run(bad, "-o", tmp_path / "o.mp4")
    assert r.exit_code == 1 and f"{bad}: expected a video" in stderr(r)
    assert sorted(os.listdir(tmp_path)) == ["movie.mp4"]


def test_video_output_rules(tmp_path):
    clip = tmp_path / "c.mp4"
    shutil.copy(os.path.join(DEMO, "clip.mp4"), clip)
    r = run(clip, "-o", clip, "--overwrite")
    assert r.exit_code == 2 and "is the input" in stderr(r)
    (tmp_path / "o.mp4").write_bytes(b"keep me")
    r = run(clip, "-o", tmp_path / "o.mp4")
    assert r.exit_code == 2 and "exists; use --overwrite" in stderr(r)
    assert (tmp_path / "o.mp4").read_bytes() == b"keep me"
    r = run(clip, "-o", tmp_path / "o.mp4", "--codec", "nonesuch", "--overwrite")
    assert r.exit_code == 1 and "expected an encoder" in stderr(r)
    assert (tmp_path / "o.mp4").read_bytes() == b"keep me"


def test_video_ctrl_c_removes_the_output(tmp_path, monkeypatch, send_signal):
    from mlaa_stream.io import video as video_io

    real = video_io.VideoWriter.write

    def write(self, frame, when=None):
        if self.frames_written == 3:
            send_signal()
        return real(self, frame, when)

    monkeypatch.setattr(video_io.VideoWriter, "write", write)
    r = run(os.path.join(DEMO, "clip.mp4"), "-o", tmp_path / "o.mp4")
    assert r.exit_code == 130 and "interrupted" in stderr(r)
    assert os.listdir(tmp_path) == []


def test_video_full_disk_removes_the_output(tmp_path, monkeypatch):
    from mlaa_stream.io import video as video_io

    def write(self, frame, when=None):
        if self.frames_written == 4:
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        self.frames_written += 1

    monkeypatch.setattr(video_io.VideoWriter, "write", write)
    r = run(os.path.join(DEMO, "clip.mp4"), "-o", tmp_path / "o.mp4")
    assert r.exit_code == 1
    assert "write failed at frame 4" in stderr(r) and "No space left" in stderr(r)
    assert os.listdir(tmp_path) == []


def test_opencv_backend(tmp_path):
    r = run(os.path.join(DEMO, "clip.mp4"), "-o", tmp_path / "o.mp4", "--video-backend", "opencv")
    assert r.exit_code == 0, stderr(r)
    with av.open(str(tmp_path / "o.mp4")) as c:
        assert sum(1 for _ in c.decode(video=0)) == 10


# -- options -----------------------------------------------------------------------------------
def test_overlay_option_calls_load_overlay_lazily(tmp_path, monkeypatch):
    calls = []

    def load_overlay(path, bgr=True, device=None):
        assert bgr is False  # the CLI's frames are RGB
        calls.append(("load", path))

        def hook(frame, index):
            calls.append(("draw", index))
            out = frame.copy()
            out[0, 0] = 255
            return out
        return hook

    monkeypatch.setitem(sys.modules, "mlaa_stream.overlay.grlaa",
                        types.SimpleNamespace(load_overlay=load_overlay))
    geo = tmp_path / "roads.geojson"
    geo.write_text("{}")
    r = run(os.path.join(DEMO, "clip.mp4"), "-o", tmp_path / "o.mkv", "--overlay", geo,
            "--codec", "ffv1")
    assert r.exit_code == 0, stderr(r)
    assert calls[0] == ("load", str(geo)) and [c[1] for c in calls[1:]] == list(range(10))



def test_overlay_frames_of_a_folder_keep_their_index_through_resume_and_a_bad_file(tmp_path, monkeypatch):
    # the hook's index is the file's place in the folder: --resume (writing only f3) and an unreadable f1 used
    # to restart the count at the first file read, drawing another frame's lines
    calls = []

    def load_overlay(path, bgr=True, device=None):
        def hook(frame, index):
            calls.append(index)
            return frame
        return hook

    monkeypatch.setitem(sys.modules, "mlaa_stream.overlay.grlaa",
                        types.SimpleNamespace(load_overlay=load_overlay))
    geo = tmp_path / "roads.geojson"
    geo.write_text("{}")
    (tmp_path / "in").mkdir()
    for k in range(4):
        write_png(tmp_path / "in" / f"f{k}.png", staircase())
    assert run(tmp_path / "in", "-o", tmp_path / "o", "--overlay", geo).exit_code == 0
    assert calls == [0, 1, 2, 3]
    calls.clear()
    (tmp_path / "o" / "f3.png").unlink()
    r = run(tmp_path / "in", "-o", tmp_path / "o", "--overlay", geo, "--resume")
    assert r.exit_code == 0, stderr(r)
    assert calls == [3]
    calls.clear()
    (tmp_path / "in" / "f1.png").write_bytes(b"not a png")
    r = run(tmp_path / "in", "-o", tmp_path / "o2", "--overlay", geo)
    assert r.exit_code == 1 and calls == [0, 2, 3], stderr(r)

def test_overlay_with_the_real_overlay_module_draws_in_rgb(tmp_path):
    pytest.importorskip("mlaa_stream.overlay.grlaa")
    geo = tmp_path / "road.geojson"
    geo.write_text('{"type": "Feature", "geometry": {"type": "LineString", '
                   '"coordinates": [[2, 12], [30, 12]]}, "properties": {"width": 5, "color": "#ff0000"}}')
    src = tmp_path / "in.png"
    write_png(src, staircase())
    r = run(src, "-o", tmp_path / "o.png", "--overlay", geo)
    assert r.exit_code == 0, stderr(r)
    np.testing.assert_array_equal(read_image(str(tmp_path / "o.png")).pixels[12, 16], [255, 0, 0])
    r = run(src, "-o", tmp_path / "o2.png", "--overlay", tmp_path / "missing.json")
    assert r.exit_code == 2 and "missing.json" in stderr(r)


def test_bad_options_are_usage_errors(tmp_path):
    src = os.path.join(DEMO, "images", "rgb8.png")
    r = run(src, "-o", tmp_path / "o.png", "--metric", "hsv")
    assert r.exit_code == 2 and "hsv" in stderr(r)
    r = run(src, "-o", tmp_path / "o.png", "--preset", "nonesuch")
    assert r.exit_code == 2
    r = run(src, "-o", tmp_path / "o.png", "--threshold", "0")
    assert r.exit_code == 2


def test_preset_and_options(tmp_path):
    from mlaa_stream.spatial.filter import PRESETS

    src = tmp_path / "in.png"
    write_png(src, staircase())
    for name in sorted(PRESETS):
        r = run(src, "-o", tmp_path / f"{name}.png", "--preset", name, "--display-space", "--no-reconstruct")
        assert r.exit_code == 0, (name, stderr(r))


def test_bridge_switch_matches_the_filter(tmp_path):
    """--no-bridge leaves the dashes of a sub-pixel wire apart, as Filter(bridge=False); the default
    bridges them, as Filter()."""
    import cv2

    from mlaa_stream.yardstick import scenes as S
    from mlaa_stream.spatial.filter import Filter

    wire = S.stroke(np.array([[4.0, 10.3], [120.0, 22.1]]), 0.5)
    img = S.encode8(S.render([S.Layer(None, (228, 226, 218)), S.Layer((wire,), (24, 24, 32))], 128, 32, 1))
    src = tmp_path / "wire.png"
    cv2.imwrite(str(src), img[..., ::-1])
    for flag, bridge in (("--bridge", True), ("--no-bridge", False)):
        r = run(src, "-o", tmp_path / f"{flag}.png", flag)
        assert r.exit_code == 0, stderr(r)
        got = cv2.imread(str(tmp_path / f"{flag}.png"))[..., ::-1]
        with Filter(bridge=bridge) as f:
            np.testing.assert_array_equal(got, f.process(img))
    a, b = (cv2.imread(str(tmp_path / f"{n}.png")) for n in ("--bridge", "--no-bridge"))
    assert np.any(a != b)   # the wire's gaps were drawn


def test_help_explains_with_examples():
    r = run("filter", "--help")
    assert r.exit_code == 0
    for text in ("Examples:", "--overwrite", "--resume", "--frames", "--codec", "veryfast",
                 "Exit codes", "130 interrupted", "valid shorter", "--overlay", "%04d"):
        assert text in r.output, text


def test_every_preset_says_what_it_is_for():
    """--help names each preset's use (PRESET_USES), and no preset is without one."""
    from mlaa_stream.spatial.filter import PRESET_USES, PRESETS
    assert set(PRESET_USES) == set(PRESETS)


def test_show_regions_dims_what_is_not_a_render(tmp_path):
    """--show regions: the output where the frame is a render region, dimmed elsewhere; a flat-colour staircase
    has no region, so all of it is dimmed (to SHOW_DIM of the normal output's colour, within a level)."""
    from mlaa_stream.spatial.fallback import SHOW_DIM
    src, plain, shown = tmp_path / "in.png", tmp_path / "plain.png", tmp_path / "shown.png"
    write_png(src, staircase(48, 64))
    assert run(src, "-o", plain).exit_code == 0
    assert run(src, "-o", shown, "--show", "regions").exit_code == 0
    a, b = read_image(str(plain)).pixels.astype(float), read_image(str(shown)).pixels.astype(float)
    assert np.abs(b - a * SHOW_DIM).max() <= 1.0
    result = run(src, "-o", tmp_path / "fast.png", "--show", "regions", "--preset", "fast")
    assert result.exit_code == 2 and "--show regions" in stderr(result)


def test_a_gpu_driver_the_loader_cannot_see_is_named_when_the_filter_runs_on_the_cpu(tmp_path, monkeypatch):
    """A GPU container without the driver's ICD file: the frames come out (on the CPU) and a warning says how to
    register the GPU; none when a device is asked for."""
    from mlaa_stream.device import drivers
    libs = tmp_path / "lib64"
    libs.mkdir()
    (libs / "libnvidia-opencl.so.1").write_bytes(b"\x7fELF")
    (tmp_path / "vendors").mkdir()
    monkeypatch.setattr(drivers, "LIBRARY_DIRS", (str(libs),))
    monkeypatch.setenv(drivers.VENDORS_ENV, str(tmp_path / "vendors"))
    monkeypatch.delenv("MLAA_STREAM_DEVICE", raising=False)
    src = tmp_path / "in.png"
    write_png(src, staircase())
    r = run(src, "-o", tmp_path / "out.png")
    assert r.exit_code == 0, stderr(r)
    on_cpu = "CPU" in CliRunner().invoke(main, ["devices"]).output.splitlines()[0]
    assert ("warning: running on the CPU: NVIDIA's OpenCL driver is at" in stderr(r)) == on_cpu
    r = run(src, "-o", tmp_path / "out2.png", "--device", "0")
    assert r.exit_code == 0 and "running on the CPU" not in stderr(r)


def test_every_command_help_states_its_exit_codes():
    """devices, compare, scenes and bench said their exit codes only in their source's docstring."""
    from mlaa_stream.cli.main import main as cli_main
    for name in ("filter", "devices", "compare", "overlay", "scenes", "bench"):
        res = CliRunner().invoke(cli_main, [name, "--help"])
        assert res.exit_code == 0 and "Exit codes: 0 " in res.output, name


@pytest.mark.parametrize("args, warned", [(["--preset", "luma", "--threshold", "8"], True),
                                          (["--metric", "rgb", "--threshold", "1"], True),
                                          (["--metric", "luma", "--threshold", "0.5"], False),
                                          (["--threshold", "8"], False)])
def test_a_lab_sized_threshold_with_luma_or_rgb_is_warned(tmp_path, args, warned):
    """--threshold is ΔE for lab but a fraction of full scale for luma/rgb: 8 with luma found no edge and wrote the
    input back unchanged without a word."""
    write_png(tmp_path / "in.png", staircase())
    r = run(tmp_path / "in.png", "-o", tmp_path / "out.png", *args)
    assert r.exit_code == 0, stderr(r)
    assert ("no edges are found" in stderr(r)) == warned
    if warned:
        assert f"--threshold {args[-1]} with --metric " in stderr(r)


def test_python_dash_m_runs_the_command():
    # `python -m mlaa_stream.cli.main ...` did nothing and exited 0: the module had no __main__ entry
    r = subprocess.run([sys.executable, "-m", "mlaa_stream.cli.main", "--version"], capture_output=True, text=True,
                       timeout=120)
    assert r.returncode == 0 and "version" in r.stdout, (r.stdout, r.stderr)
