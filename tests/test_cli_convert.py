"""Frames <-> video and the command-line habits of issue 17: a folder or frame pattern encoded into a
video, a video written as numbered images, -y, the one-line summary when stderr is not a terminal, one
error format for every command, and the bench's results folder."""
from __future__ import annotations

import csv
import os

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.images import read_image, write_image

DEMO = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo")
CLIP = os.path.join(DEMO, "clip.mp4")


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


def staircases(folder, n: int, dtype=np.uint8, size=(36, 52)):
    folder.mkdir(exist_ok=True)
    y, x = np.mgrid[0:size[0], 0:size[1]]
    top = np.iinfo(dtype).max
    for k in range(n):
        img = np.where(((y * (2 + k % 3)) > x + k)[..., None], [top // 9, top // 7, top // 5], [top, top, top // 2])
        write_image(str(folder / f"shot.{1001 + k:04d}.png"), img.astype(dtype))


def video_frames(path) -> tuple[list[np.ndarray], float]:
    with av.open(str(path)) as c:
        s = c.streams.video[0]
        return [f.to_ndarray(format="rgb24") for f in c.decode(s)], float(s.average_rate)


def test_a_frame_pattern_becomes_a_video_at_the_given_rate(tmp_path):
    staircases(tmp_path / "seq", 6)
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", tmp_path / "out.mp4", "--rate", "30")
    assert r.exit_code == 0, stderr(r)
    frames, rate = video_frames(tmp_path / "out.mp4")
    assert len(frames) == 6 and frames[0].shape == (36, 52, 3) and rate == 30.0
    assert not (tmp_path / "out.mp4").is_dir()


def test_a_folder_becomes_a_lossless_video_equal_to_the_filtered_frames(tmp_path):
    staircases(tmp_path / "seq", 4)
    assert run(tmp_path / "seq", "-o", tmp_path / "out.mkv", "--codec", "libx264rgb", "--crf", "0").exit_code == 0
    assert run(tmp_path / "seq", "-o", tmp_path / "frames").exit_code == 0
    frames, rate = video_frames(tmp_path / "out.mkv")
    assert rate == 24.0  # the default --rate
    for k, name in enumerate(sorted(os.listdir(tmp_path / "frames"))):
        assert np.array_equal(frames[k], read_image(str(tmp_path / "frames" / name)).pixels)



def test_a_folder_becomes_a_video_with_the_temporal_stage(tmp_path):
    # the temporal stage reads the job's per-frame colour space: it stopped at the first frame with an
    # AttributeError ('SequenceToVideoJob' object has no attribute 'read_linear')
    staircases(tmp_path / "seq", 4)
    r = run(tmp_path / "seq", "-o", tmp_path / "out.mkv", "--codec", "libx264rgb", "--crf", "0", "--temporal",
            "--stats", tmp_path / "s.csv")
    assert r.exit_code == 0, stderr(r)
    assert len(video_frames(tmp_path / "out.mkv")[0]) == 4
    assert len((tmp_path / "s.csv").read_text().splitlines()) == 5

@pytest.mark.parametrize("source", ["folder", "pattern"])
def test_a_video_made_from_images_takes_the_format_option_and_names_audio_it_cannot_copy(tmp_path, source):
    # -f/--format and --audio were ignored without a word for a folder or pattern -> video: out.mp4 came out MP4
    staircases(tmp_path / "seq", 3)
    src = tmp_path / "seq" if source == "folder" else tmp_path / "seq" / "shot.%04d.png"
    r = run(src, "-o", tmp_path / "out.mp4", "-f", "nut", "--audio", "aac")
    assert r.exit_code == 0, stderr(r)
    with av.open(str(tmp_path / "out.mp4")) as c:
        assert c.format.name == "nut" and not c.streams.audio
    assert len(video_frames(tmp_path / "out.mp4")[0]) == 3
    assert stderr(r).count("--audio aac has no effect here") == 1 and "images have none" in stderr(r)
    assert "-f/--format" not in stderr(r)
    r = run(src, "-o", tmp_path / "out.y4m", "--audio", "none")   # honoured as asked: no audio, no warning
    assert r.exit_code == 0 and "no effect" not in stderr(r), stderr(r)
    with av.open(str(tmp_path / "out.y4m")) as c:
        assert c.format.name == "yuv4mpegpipe" and not c.streams.audio


def test_a_video_becomes_numbered_images_from_1(tmp_path):
    r = run(CLIP, "-o", tmp_path / "img" / "f_%04d.png")
    assert r.exit_code == 0, stderr(r)
    names = sorted(os.listdir(tmp_path / "img"))
    assert names == [f"f_{n:04d}.png" for n in range(1, 11)]
    assert read_image(str(tmp_path / "img" / names[0])).pixels.shape == (48, 64, 3)
    assert "audio is not written to images" in stderr(r)


def test_a_video_to_images_resumes_skipping_complete_outputs(tmp_path):
    img = tmp_path / "img"
    assert run(CLIP, "-o", img / "f_%04d.png").exit_code == 0
    first = {n: read_image(str(img / n)).pixels for n in os.listdir(img)}
    for n in range(6, 11):   # an interrupted run: frames 6-10 missing, 3 half written, 2 "done" differently
        (img / f"f_{n:04d}.png").unlink()
    (img / "f_0003.png").write_bytes((img / "f_0003.png").read_bytes()[:100])
    write_image(str(img / "f_0002.png"), np.zeros((48, 64, 3), np.uint8), overwrite=True)
    marker = (img / "f_0002.png").read_bytes()
    r = run(CLIP, "-o", img / "f_%04d.png")
    assert r.exit_code == 2 and "--overwrite to replace or --resume to skip" in stderr(r)
    r = run(CLIP, "-o", img / "f_%04d.png", "--resume", "-v")
    assert r.exit_code == 0, stderr(r)
    assert "f_0003.png: incomplete" in stderr(r) and "--resume: 4 outputs exist and are skipped" in stderr(r)
    assert (img / "f_0002.png").read_bytes() == marker   # complete: kept
    assert sorted(os.listdir(img)) == sorted(first)
    for n in [3] + list(range(6, 11)):   # written again, as the whole run wrote them
        np.testing.assert_array_equal(read_image(str(img / f"f_{n:04d}.png")).pixels, first[f"f_{n:04d}.png"])
    tem = tmp_path / "tem"   # with the temporal stage every frame is filtered (its history), the done ones not written
    assert run(CLIP, "-o", tem / "f_%04d.png", "--temporal").exit_code == 0
    whole = {n: read_image(str(tem / n)).pixels for n in os.listdir(tem)}
    for n in range(6, 11):
        (tem / f"f_{n:04d}.png").unlink()
    stats = tmp_path / "stats.csv"
    r = run(CLIP, "-o", tem / "f_%04d.png", "--temporal", "--resume", "--stats", stats)
    assert r.exit_code == 0, stderr(r)
    for name, pixels in whole.items():
        np.testing.assert_array_equal(read_image(str(tem / name)).pixels, pixels)
    # --stats: a row per frame written (f_0006 .. f_0010: the video's frames 5-9), not the done ones run through
    assert [row["index"] for row in csv.DictReader(stats.open())] == [str(i) for i in range(5, 10)]


def test_options_given_for_another_kind_of_output_are_named_once_as_having_no_effect(tmp_path):
    r = run(CLIP, "-o", tmp_path / "v.mp4", "--rate", "30")   # video -> video: its own rate
    assert r.exit_code == 0, stderr(r)
    assert stderr(r).count("--rate has no effect here") == 1 and "keeps its own frame rate" in stderr(r)
    assert video_frames(tmp_path / "v.mp4")[1] == 24.0
    r = run(CLIP, "-o", tmp_path / "img" / "f_%04d.png", "--rate", "30", "--crf", "20", "--pix-fmt", "yuv444p")
    assert r.exit_code == 0, stderr(r)
    assert "--rate has no effect here" in stderr(r) and "images have no frame rate" in stderr(r)
    assert stderr(r).count("--crf, --pix-fmt have no effect here: they set the video encoder") == 1
    staircases(tmp_path / "seq", 2)
    r = run(tmp_path / "seq", "-o", tmp_path / "o", "--codec", "ffv1")
    assert r.exit_code == 0 and "--codec has no effect here: it sets the video encoder" in stderr(r)
    r = run(tmp_path / "seq", "-o", tmp_path / "o.mp4", "--rate", "30", "--crf", "20")   # used: no warning
    assert r.exit_code == 0 and "no effect" not in stderr(r)
    r = run(CLIP, "-o", tmp_path / "img2" / "f_%04d.png")   # defaults are not "given"
    assert r.exit_code == 0 and "no effect" not in stderr(r)
    r = run(CLIP, "-o", tmp_path / "img3" / "f_%04d.png", "--crf", "20", "-f", "mkv", "--audio", "aac")
    assert r.exit_code == 0, stderr(r)
    assert stderr(r).count("no effect here") == 1
    assert ("--crf, -f/--format, --audio have no effect here: they set the video encoder, the video container "
            "and the video's audio tracks, and the output is images") in stderr(r)
    r = run(tmp_path / "seq", "-o", tmp_path / "o", "--audio", "none", "-y")   # a folder out too
    assert r.exit_code == 0 and "--audio has no effect here: it sets the video's audio tracks" in stderr(r)
    r = run(tmp_path / "seq", "-o", tmp_path / "o", "--format", "mp4", "-y")
    assert r.exit_code == 0 and "-f/--format has no effect here: it sets the video container" in stderr(r)


def test_float_frames_to_video_are_refused_and_existing_outputs_need_y(tmp_path):
    folder = tmp_path / "exr"
    folder.mkdir()
    write_image(str(folder / "a.0001.exr"), np.full((8, 8, 3), 0.5, np.float16))
    r = run(folder, "-o", tmp_path / "o.mp4")
    assert r.exit_code == 2 and "cannot be encoded to video" in stderr(r) and "PNG frames" in stderr(r)
    r = run(folder / "a.%04d.exr", "-o", tmp_path / "png" / "a.%04d.png")   # as suggested: PNG frames (sRGB)
    assert r.exit_code == 0 and "encoded to sRGB for .png" in stderr(r)
    assert run(tmp_path / "png", "-o", tmp_path / "p.mp4").exit_code == 0
    staircases(tmp_path / "seq", 3)
    (tmp_path / "o.mp4").write_bytes(b"keep")
    r = run(tmp_path / "seq", "-o", tmp_path / "o.mp4")
    assert r.exit_code == 2 and "--overwrite (-y)" in stderr(r)
    assert (tmp_path / "o.mp4").read_bytes() == b"keep"
    assert run(tmp_path / "seq", "-o", tmp_path / "o.mp4", "-y").exit_code == 0
    assert len(video_frames(tmp_path / "o.mp4")[0]) == 3


@pytest.mark.parametrize("cut", ["empty", "truncated"])
def test_an_unreadable_first_frame_to_video_is_an_error_naming_it_not_a_traceback(tmp_path, cut):
    # the first frame is read before the run (its type and channels set the video's): an empty or truncated one
    # ended the command in an ImageReadError traceback
    staircases(tmp_path / "seq", 3)
    whole = (tmp_path / "seq" / "shot.1001.png").read_bytes()
    (tmp_path / "seq" / "shot.1000.png").write_bytes(b"" if cut == "empty" else whole[:len(whole) // 2])
    for src in (tmp_path / "seq", tmp_path / "seq" / "shot.%04d.png"):
        r = run(src, "-o", tmp_path / "out.mp4")
        assert r.exit_code == 1, stderr(r)
        assert r.exception is None or isinstance(r.exception, SystemExit)
        assert "shot.1000.png" in stderr(r) and "Traceback" not in stderr(r)
        assert not (tmp_path / "out.mp4").exists()


def test_a_frame_that_stops_a_video_is_named_by_its_own_number(tmp_path):
    # a read error carries the file's place in the plan (2), which was given as its frame number: "frame 2: read
    # failed: frame 1003 (shot.1003.png): expected ..." named two frames
    staircases(tmp_path / "seq", 4)
    staircases(tmp_path / "other", 3, size=(20, 30))
    os.replace(tmp_path / "other" / "shot.1003.png", tmp_path / "seq" / "shot.1003.png")
    r = run(tmp_path / "seq" / "shot.%04d.png", "-o", tmp_path / "out.mp4")
    assert r.exit_code == 1
    errors = [line for line in stderr(r).splitlines() if "error:" in line]
    assert len(errors) == 1 and "frame 1003 (" in errors[0] and "frame 2" not in errors[0], errors
    r = run(tmp_path / "seq", "-o", tmp_path / "out.mp4")   # a folder: the file, no number
    errors = [line for line in stderr(r).splitlines() if "error:" in line]
    assert r.exit_code == 1 and len(errors) == 1 and "shot.1003.png" in errors[0] and "frame 2" not in errors[0]
    assert not (tmp_path / "out.mp4").exists()


def test_one_summary_line_when_stderr_is_not_a_terminal_and_none_with_q(tmp_path):
    staircases(tmp_path / "seq", 2)
    r = run(tmp_path / "seq", "-o", tmp_path / "out")
    assert r.exit_code == 0
    lines = [l for l in stderr(r).splitlines() if "frames in" in l]
    assert len(lines) == 1 and lines[0].startswith("mlaa-stream: 2 frames in") and "fps) ->" in lines[0]
    r = run(tmp_path / "seq", "-o", tmp_path / "out2", "-q")
    assert r.exit_code == 0 and "frames in" not in stderr(r)


def test_every_command_reports_errors_alike(tmp_path):
    r = run("compare", tmp_path / "missing.png", tmp_path / "missing2.png")
    assert r.exit_code == 1 and stderr(r).startswith("mlaa-stream: error: ") and "missing.png" in stderr(r)


def test_bench_writes_to_a_temporary_folder_unless_told(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    import tempfile
    monkeypatch.setattr(tempfile, "tempdir", None)
    r = run("bench", "--quick", "--methods", "none", "--scenes", "diagonals", "--frames", "1")
    assert r.exit_code == 0, stderr(r)
    assert (tmp_path / "tmp" / "mlaa-stream-bench" / "README.md").exists()
    assert not (tmp_path / "docs").exists()


def test_start_and_end_trim_a_video_and_its_audio(tmp_path):
    r = run(CLIP, "-o", tmp_path / "t.mp4", "--start", "0.125", "--end", "8f")
    assert r.exit_code == 0, stderr(r)
    with av.open(str(tmp_path / "t.mp4")) as c:
        times = [float(f.pts * f.time_base) for f in c.decode(video=0)]
    assert len(times) == 5 and times[0] == 0.0  # source frames 3..7, the output starts at 0
    with av.open(str(tmp_path / "t.mp4")) as c:
        audio = c.streams.audio[0]
        assert abs(float(audio.duration * audio.time_base) - 5 / 24) < 0.03
    r = run(CLIP, "-o", tmp_path / "u.mp4", "--start", "2", "--end", "1")
    assert r.exit_code == 2 and "must come after --start" in stderr(r)
    r = run(DEMO + "/images", "-o", tmp_path / "o", "--start", "1")
    assert r.exit_code == 2 and "--start/--end trim a video" in stderr(r)


def test_parse_time_forms():
    from mlaa_stream.io.video import parse_time
    from fractions import Fraction

    assert parse_time("12.5", None) == 12.5 and parse_time("1:02.5", None) == 62.5
    assert parse_time("1:00:01", None) == 3601.0 and parse_time("48f", Fraction(24)) == 2.0
    for bad in ("", "x", "1:2:3:4", "-3"):
        try:
            parse_time(bad, None)
        except ValueError as exc:
            assert "expected a time" in str(exc)
        else:
            raise AssertionError(bad)


def test_machine_readable_progress(tmp_path):
    r = run(CLIP, "-o", tmp_path / "o.mp4", "--progress", tmp_path / "p.txt", "-q")
    assert r.exit_code == 0, stderr(r)
    blocks, block = [], {}
    for line in (tmp_path / "p.txt").read_text().splitlines():
        key, _, value = line.partition("=")
        block[key] = value
        if key == "progress":
            blocks.append(block)
            block = {}
    assert blocks and block == {} and blocks[-1]["progress"] == "end"
    assert all(b["progress"] == "continue" for b in blocks[:-1])
    last = blocks[-1]
    assert last["frame"] == "10" and last["total_frames"] == "10" and float(last["fps"]) > 0


def _write_straight(path, pixels: np.ndarray) -> None:
    """An 8-bit image written as given (straight alpha: OpenImageIO does not divide the colour by alpha)."""
    import OpenImageIO as oiio
    spec = oiio.ImageSpec(pixels.shape[1], pixels.shape[0], pixels.shape[2], oiio.UINT8)
    spec.attribute("oiio:UnassociatedAlpha", 1)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(pixels)
    out.close()


def test_compare_scores_the_colour_of_an_rgba_png_as_stored(tmp_path):
    """The filter keeps a PNG's straight alpha and filters the colour as stored; compare read it premultiplied, so an
    RGBA output with the truth's very colours scored tens of levels of error against an RGB truth."""
    rgb = np.random.default_rng(4).integers(0, 256, (24, 32, 3), dtype=np.uint8)
    _write_straight(tmp_path / "out.png", np.concatenate([rgb, np.full((24, 32, 1), 128, np.uint8)], -1))
    _write_straight(tmp_path / "truth.png", rgb)
    r = run("compare", tmp_path / "out.png", tmp_path / "truth.png", "--no-flip")
    assert r.exit_code == 0, stderr(r)
    assert "RMSE vs truth (8-bit levels): out 0.000" in r.output


def test_compare_names_a_folder_given_for_an_image(tmp_path):
    _write_straight(tmp_path / "a.png", np.zeros((8, 8, 3), np.uint8))
    (tmp_path / "shots").mkdir()
    for args in (("shots", "a.png"), ("a.png", "a.png", "--input", "shots")):
        r = run("compare", *(tmp_path / a if not a.startswith("--") else a for a in args), "--no-flip")
        assert r.exit_code == 1 and f"{tmp_path / 'shots'}: expected an image file, got a folder" in stderr(r)
