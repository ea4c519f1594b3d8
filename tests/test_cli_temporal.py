"""The temporal options of the filter command: --temporal on video, folders and sequences, --stats,
resets at gaps in the numbering, single images spatial only."""
from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main

DEMO = Path(__file__).resolve().parent.parent / "fixtures" / "demo"


def test_video_gets_the_temporal_stage_and_stats(tmp_path):
    out, stats = tmp_path / "out.mp4", tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(out), "--temporal",
                                    "--stats", str(stats), "-q"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(stats.open()))
    assert len(rows) == 10 and rows[0]["model"] == "reset"
    assert {r["model"] for r in rows[1:]} <= {"static", "global", "layers", "dense", "reset"}
    assert {"ring", "model", "flow_ms", "resolve_ms"} <= set(rows[0])


@pytest.mark.parametrize("method", ["auto", "blend", "tss+blend"])
def test_blend_methods(tmp_path, method):
    out, stats = tmp_path / "out.mp4", tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(out), "--temporal",
                                    "--temporal-method", method, "--stats", str(stats), "-q"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(stats.open()))
    assert len(rows) == 10 and "history_weight_mean" in rows[0]
    assert ("ring" in rows[0]) == (method != "blend")
    assert ("gate_share" in rows[1]) == (method == "auto")  # auto: the blend only on moving render pixels


def test_temporal_is_off_by_default_and_stats_imply_it(tmp_path):
    out = tmp_path / "out.mp4"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(out), "-v"])
    assert res.exit_code == 0, res.output
    assert out.exists() and "temporal models" not in res.output
    stats = tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "b.mp4"),
                                    "--stats", str(stats), "-q"])
    assert res.exit_code == 0 and stats.exists()
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "c.mp4"),
                                    "--no-temporal", "--stats", str(tmp_path / "none.csv"), "-q"])
    assert res.exit_code == 0 and not (tmp_path / "none.csv").exists()


def _pan_frames(n: int) -> list[np.ndarray]:
    from mlaa_stream.bench.temporal import scene_pan
    return list(scene_pan(n, 160, 90).inputs)


def test_temporal_on_a_folder(tmp_path):
    from mlaa_stream.io.images import write_image
    src = tmp_path / "in"
    src.mkdir()
    frames = _pan_frames(5)
    for i, f in enumerate(frames):
        write_image(str(src / f"f{i:02d}.png"), f)
    stats = tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(src), "-o", str(tmp_path / "out"), "--temporal",
                                    "--temporal-frames", "4", "--stats", str(stats), "-v"])
    assert res.exit_code == 0, res.output
    assert len(list((tmp_path / "out").glob("*.png"))) == 5
    rows = list(csv.DictReader(stats.open()))
    assert [r["index"] for r in rows] == ["0", "1", "2", "3", "4"]
    assert rows[0]["model"] == "reset" and "reset" not in [r["model"] for r in rows[1:]]
    assert max(int(r["ring"]) for r in rows) <= 4


def test_sequence_gap_resets_and_says_so(tmp_path):
    from mlaa_stream.io.images import write_image
    frames = _pan_frames(5)
    for n, f in zip((1, 2, 3, 5, 6), frames):
        write_image(str(tmp_path / f"s.{n:04d}.png"), f)
    stats = tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(tmp_path / "s.%04d.png"), "-o", str(tmp_path / "o" / "s.%04d.png"),
                                    "--temporal", "--stats", str(stats), "-v"])
    assert res.exit_code == 0, res.output
    assert "temporal history reset (gap in the numbering after 3)" in res.output
    rows = list(csv.DictReader(stats.open()))
    assert [r["index"] for r in rows] == ["1", "2", "3", "5", "6"]
    assert [r["model"] for r in rows][3] == "reset"


def test_single_image_is_spatial_only(tmp_path):
    from mlaa_stream.io.images import write_image
    write_image(str(tmp_path / "a.png"), _pan_frames(1)[0])
    res = CliRunner().invoke(main, [str(tmp_path / "a.png"), "-o", str(tmp_path / "b.png"), "--temporal", "-v"])
    assert res.exit_code == 0, res.output
    assert "spatial antialiasing only" in res.output and (tmp_path / "b.png").exists()



def test_single_image_warns_that_stats_and_history_are_not_made(tmp_path):
    # --stats would write no file and --show history give no view: a warning without -v, not a silent no-op
    from mlaa_stream.io.images import write_image
    write_image(str(tmp_path / "a.png"), _pan_frames(1)[0])
    res = CliRunner().invoke(main, [str(tmp_path / "a.png"), "-o", str(tmp_path / "b.png"),
                                    "--stats", str(tmp_path / "s.csv"), "--show", "history"])
    assert res.exit_code == 0, res.output
    assert "warning: --stats, --show history have no effect here: a single image" in res.output
    assert (tmp_path / "b.png").exists() and not (tmp_path / "s.csv").exists()


def test_temporal_settings_that_do_nothing_are_named(tmp_path):
    # --temporal-method and the like do not turn the stage on: given without it they did nothing, silently
    folder = tmp_path / "in"
    folder.mkdir()
    from mlaa_stream.io.images import write_image
    for k, f in enumerate(_pan_frames(3)):
        write_image(str(folder / f"f{k}.png"), f)
    res = CliRunner().invoke(main, [str(folder), "-o", str(tmp_path / "a"), "--temporal-method", "tss",
                                    "--temporal-frames", "4"])
    assert res.exit_code == 0, res.output
    assert "--temporal-frames, --temporal-method have no effect here: the temporal stage is off" in res.output
    res = CliRunner().invoke(main, [str(folder), "-o", str(tmp_path / "b"), "--temporal", "--temporal-method",
                                    "blend", "--temporal-frames", "4"])
    assert res.exit_code == 0, res.output
    assert "--temporal-frames has no effect with --temporal-method blend" in res.output
    res = CliRunner().invoke(main, [str(folder), "-o", str(tmp_path / "c"), "--temporal", "--temporal-frames", "4"])
    assert res.exit_code == 0 and "no effect" not in res.output, res.output


def test_no_temporal_names_the_options_it_overrides(tmp_path):
    # --no-temporal outranks --stats, --show history, --lookahead and --dense-motion, which otherwise imply the stage:
    # no CSV, no view, spatial frames -- said in a warning, not dropped without a word
    folder = tmp_path / "in"
    folder.mkdir()
    from mlaa_stream.io.images import write_image
    for k, f in enumerate(_pan_frames(2)):
        write_image(str(folder / f"f{k}.png"), f)
    stats = tmp_path / "s.csv"
    res = CliRunner().invoke(main, [str(folder), "-o", str(tmp_path / "a"), "--no-temporal", "--stats", str(stats),
                                    "--show", "history", "--lookahead", "3", "--dense-motion"])
    assert res.exit_code == 0, res.output
    assert ("--stats, --show history, --lookahead, --dense-motion have no effect here: the temporal stage is off "
            "(--no-temporal turns it off)") in res.output
    assert not stats.exists()
    res = CliRunner().invoke(main, [str(folder), "-o", str(tmp_path / "b"), "--lookahead", "0"])
    assert res.exit_code == 0 and "--lookahead has no effect here: the temporal stage is off" in res.output
    res = CliRunner().invoke(main, [str(folder), "-o", str(tmp_path / "c"), "--no-temporal"])
    assert res.exit_code == 0 and "no effect" not in res.output, res.output


def _resume_after_losing(tmp_path, args: list[str], lost: list[Path], indices: list[str], warmed: int = 4) -> dict:
    """Run `args` whole, remove the outputs `lost`, run again with --resume: the stage must warm up on the `warmed`
    frames before them, and the written frames (stats `indices`) get the models and rings of the whole run (without
    the warm-up the first one is a reset with a ring of 1), --stats listing only them. Returns the lost outputs'
    pixels from the whole run."""
    from mlaa_stream.io.images import read_image
    full, stats = tmp_path / "full.csv", tmp_path / "stats.csv"
    res = CliRunner().invoke(main, args + ["--stats", str(full)])
    assert res.exit_code == 0, res.output
    whole = {p: read_image(str(p)).pixels for p in lost}
    for p in lost:
        p.unlink()
    res = CliRunner().invoke(main, args + ["--resume", "--stats", str(stats), "-v"])
    assert res.exit_code == 0, res.output
    assert f"temporal history warmed up from {warmed} frames before" in res.output, res.output
    rows = list(csv.DictReader(stats.open()))
    assert [r["index"] for r in rows] == indices
    expected = [r for r in csv.DictReader(full.open()) if r["index"] in indices]
    assert [(r["model"], r["ring"]) for r in rows] == [(r["model"], r["ring"]) for r in expected]
    assert rows[0]["model"] != "reset"
    return whole


def test_sequence_resume_warms_up_the_temporal_stage(tmp_path):
    """--resume (issue 16) on a numbered sequence: the frames numbered before the first one to write."""
    from mlaa_stream.io.images import write_image
    for n, f in enumerate(_pan_frames(7), start=1):
        write_image(str(tmp_path / f"s.{n:04d}.png"), f)
    out = tmp_path / "o"
    args = [str(tmp_path / "s.%04d.png"), "-o", str(out / "s.%04d.png"), "--temporal", "--temporal-frames", "4"]
    # method auto (TSS, then the blend): BLEND_WARMUP frames, more than the ring's 4 -- here all 5 before frame 6
    _resume_after_losing(tmp_path, args, [out / f"s.{n:04d}.png" for n in (6, 7)], ["6", "7"], warmed=5)


def test_folder_resume_warms_up_the_temporal_stage(tmp_path):
    """A folder's files in name order (their positions are the frame numbers): the written frames come out bit
    for bit as in the whole run."""
    from mlaa_stream.io.images import read_image, write_image
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    for i, f in enumerate(_pan_frames(7)):
        write_image(str(src / f"shot_{chr(ord('a') + i)}.png"), f)
    args = [str(src), "-o", str(out), "--temporal", "--temporal-frames", "4"]
    whole = _resume_after_losing(tmp_path, args, [out / f"shot_{n}.png" for n in "fg"], ["5", "6"], warmed=5)
    for p, pixels in whole.items():
        np.testing.assert_array_equal(read_image(str(p)).pixels, pixels)


def _wide_pan(n: int) -> list[np.ndarray]:
    """A pan wide enough for one global translation per frame (160 x 90 is measured as dense motion)."""
    from mlaa_stream.bench.temporal import scene_pan
    return list(scene_pan(n, 240, 136).inputs)


def test_lookahead_on_a_sequence_stops_at_gaps(tmp_path):
    """--lookahead 2 (issue 16; the command line's default) on a numbered sequence with a gap after 3: frames 1-3
    read 2, 1, 0 frames ahead (the window ends at the gap, where the stage resets), 5-7 again 2, 1, 0; the outputs
    differ from the causal run's (--lookahead 0) on the frames that read ahead."""
    from mlaa_stream.io.images import read_image, write_image
    for n, f in zip((1, 2, 3, 5, 6, 7), _wide_pan(6)):
        write_image(str(tmp_path / f"s.{n:04d}.png"), f)
    runs = {}
    for la in ("0", "2", "default"):
        stats = tmp_path / f"stats{la}.csv"
        res = CliRunner().invoke(main, [str(tmp_path / "s.%04d.png"), "-o", str(tmp_path / la / "s.%04d.png"),
                                        "--temporal-method", "tss", "--stats", str(stats), "-q"]
                                 + ([] if la == "default" else ["--lookahead", la]))
        assert res.exit_code == 0, res.output
        runs[la] = list(csv.DictReader(stats.open()))
    assert [r["lookahead"] for r in runs["default"]] == [r["lookahead"] for r in runs["2"]]   # the default is 2
    assert [r["index"] for r in runs["2"]] == ["1", "2", "3", "5", "6", "7"]
    assert [r["lookahead"] for r in runs["2"]] == ["2", "1", "0", "2", "1", "0"]
    assert {r["lookahead"] for r in runs["0"]} == {"0"}
    changed = [not np.array_equal(read_image(str(tmp_path / "0" / f"s.{n:04d}.png")).pixels,
                                  read_image(str(tmp_path / "2" / f"s.{n:04d}.png")).pixels) for n in (1, 2, 5, 6)]
    assert all(changed)


def test_lookahead_folder_resume_is_bit_for_bit(tmp_path):
    """--resume with --lookahead: the written frames come out as in the whole run (the warm-up frames read their
    frames ahead too, as in the whole run: test_lookahead_resume_of_a_render_is_bit_for_bit)."""
    from mlaa_stream.io.images import read_image, write_image
    src, out = tmp_path / "in", tmp_path / "out"
    src.mkdir()
    for i, f in enumerate(_wide_pan(7)):
        write_image(str(src / f"shot_{chr(ord('a') + i)}.png"), f)
    args = [str(src), "-o", str(out), "--lookahead", "2", "--temporal-frames", "4"]
    whole = _resume_after_losing(tmp_path, args, [out / f"shot_{n}.png" for n in "ef"], ["4", "5"])
    for p, pixels in whole.items():
        np.testing.assert_array_equal(read_image(str(p)).pixels, pixels)


def test_lookahead_resume_of_a_render_is_bit_for_bit(tmp_path):
    """--temporal (auto: TSS, then the blend on moving render pixels) with its default look-ahead on a rendered pan,
    resumed after frame 3: the warm-up frames get the frames after them as the whole run handed them in (the stage
    keeps what it measured of them), else every written frame differed from the whole run's (the first by 7
    levels)."""
    from mlaa_stream.io.images import read_image, write_image
    from mlaa_stream.yardstick.rendered import egl_available, generate_rendered
    from mlaa_stream.yardstick.scenes import SceneUnavailable
    try:
        pan = generate_rendered(small=True, names=["rendered_pan"])[0]
    except SceneUnavailable as exc:
        pytest.skip(f"rendered scenes need EGL or their cache: {exc} ({egl_available()[1]})")
    frames = list(pan.inputs)
    for n, f in enumerate(frames, start=1):
        write_image(str(tmp_path / f"p.{n:04d}.png"), f)
    out = tmp_path / "o"
    args = [str(tmp_path / "p.%04d.png"), "-o", str(out / "p.%04d.png"), "--temporal", "-q"]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    whole = {n: read_image(str(out / f"p.{n:04d}.png")).pixels for n in range(4, len(frames) + 1)}
    for n in whole:
        (out / f"p.{n:04d}.png").unlink()
    res = CliRunner().invoke(main, args + ["--resume"])
    assert res.exit_code == 0, res.output
    for n, pixels in whole.items():
        np.testing.assert_array_equal(read_image(str(out / f"p.{n:04d}.png")).pixels, pixels, err_msg=f"frame {n}")


@pytest.mark.parametrize("lookahead", ["0", "2"])
def test_resume_warms_up_after_every_hole_of_skipped_outputs(tmp_path, lookahead):
    """--resume where outputs in the middle exist (a cluster's chunks done out of order, an earlier --frames run):
    the frames after such a hole get the skipped frames before them through the stage as the first one does, else
    the stage reset there ("gap in the numbering", though no input is missing) and they came out unlike the whole
    run's; --stats lists the written frames only."""
    from mlaa_stream.io.images import read_image, write_image
    frames = _wide_pan(9)
    for n, f in enumerate(frames, start=1):
        write_image(str(tmp_path / f"s.{n:04d}.png"), f)
    out, stats = tmp_path / "o", tmp_path / "stats.csv"
    args = [str(tmp_path / "s.%04d.png"), "-o", str(out / "s.%04d.png"), "--temporal", "--temporal-method", "tss",
            "--temporal-frames", "4", "--lookahead", lookahead]
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    lost = (3, 8, 9)   # frames 4-7 stay: a hole longer than the look-ahead before 8
    whole = {n: read_image(str(out / f"s.{n:04d}.png")).pixels for n in lost}
    for n in lost:
        (out / f"s.{n:04d}.png").unlink()
    res = CliRunner().invoke(main, args + ["--resume", "--stats", str(stats), "-v"])
    assert res.exit_code == 0, res.output
    assert "temporal history reset" not in res.output
    assert [r["index"] for r in csv.DictReader(stats.open())] == [str(n) for n in lost]
    for n, pixels in whole.items():
        np.testing.assert_array_equal(read_image(str(out / f"s.{n:04d}.png")).pixels, pixels, err_msg=f"frame {n}")


def test_a_warm_up_frame_that_cannot_be_read_is_a_warning_not_a_failure(tmp_path):
    """--resume --temporal where the input of a frame done (a warm-up frame) is damaged since: a sequence ended in an
    ImageReadError traceback, a folder counted it as failed (exit 1) though every output was there; now a warning,
    the history starting after it, and the frames to write written."""
    from mlaa_stream.io.images import write_image
    src = tmp_path / "in"
    src.mkdir()
    for n, f in enumerate(_pan_frames(6), start=1):
        write_image(str(src / f"s.{n:04d}.png"), f)
    runs = {"seq": (src / "s.%04d.png", tmp_path / "seq" / "s.%04d.png"), "folder": (src, tmp_path / "folder")}
    for inp, target in runs.values():
        res = CliRunner().invoke(main, [str(inp), "-o", str(target), "--temporal", "-q"])
        assert res.exit_code == 0, res.output
    whole = (src / "s.0002.png").read_bytes()
    (src / "s.0002.png").write_bytes(whole[:len(whole) // 3])
    for what, (inp, target) in runs.items():
        out = tmp_path / what
        for n in (4, 5, 6):
            (out / f"s.{n:04d}.png").unlink()
        res = CliRunner().invoke(main, [str(inp), "-o", str(target), "--temporal", "--resume"])
        assert res.exit_code == 0, res.output
        assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
        assert "s.0002.png: not read for the temporal warm-up" in res.output
        assert sorted(os.listdir(out)) == [f"s.{n:04d}.png" for n in range(1, 7)]


@pytest.mark.parametrize("what", ["seq", "folder"])
def test_a_frame_read_only_for_the_stage_that_cannot_be_read_is_a_warning(tmp_path, what):
    """--resume --temporal with a hole: the skipped frames after one to write (look-ahead) and before the next one
    (its warm-up) are read, not written. One whose input is damaged since stopped a sequence there ("stopped: 1 of 3
    outputs written") and failed a folder (exit 1), though its output is done; now a warning, the rest written."""
    from mlaa_stream.io.images import write_image
    src = tmp_path / "in"
    src.mkdir()
    for n, f in enumerate(_pan_frames(8), start=1):
        write_image(str(src / f"s.{n:04d}.png"), f)
    inp, out = (src / "s.%04d.png", tmp_path / "o" / "s.%04d.png") if what == "seq" else (src, tmp_path / "o")
    res = CliRunner().invoke(main, [str(inp), "-o", str(out), "--temporal", "-q"])
    assert res.exit_code == 0, res.output
    for n in (4, 7, 8):
        (tmp_path / "o" / f"s.{n:04d}.png").unlink()
    whole = (src / "s.0005.png").read_bytes()
    (src / "s.0005.png").write_bytes(whole[:len(whole) // 3])
    res = CliRunner().invoke(main, [str(inp), "-o", str(out), "--temporal", "--resume"])
    assert res.exit_code == 0, res.output
    assert "s.0005.png: left out of the temporal stage" in res.output
    assert sorted(os.listdir(tmp_path / "o")) == [f"s.{n:04d}.png" for n in range(1, 9)]


def test_lookahead_on_video_and_refusals(tmp_path):
    """--lookahead implies --temporal; a video gets it (stats per frame); the blend alone refuses it with a message
    naming the option."""
    stats = tmp_path / "stats.csv"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "a.mp4"), "--lookahead", "3",
                                    "--stats", str(stats), "-q"])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(stats.open()))
    assert len(rows) == 10 and rows[-1]["lookahead"] == "0"
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "b.mp4"), "--lookahead", "2",
                                    "--temporal-method", "blend"])
    assert res.exit_code != 0 and "--lookahead needs a --temporal-method with TSS" in res.output
    res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / "c.mp4"), "--temporal",
                                    "--temporal-method", "blend", "-q"])   # its default: none, no complaint
    assert res.exit_code == 0, res.output


def test_dense_motion_on_a_dolly_sequence(tmp_path, zoom_frames):
    """--dense-motion (implies --temporal): a dolly's frames as a numbered sequence, one camera motion per frame
    (--temporal-mode global), get tracked tiles where the translation fails (stats "tracked") and come out different
    from the run without the option, which keeps translations; the blend alone refuses the option."""
    from mlaa_stream.io.images import read_image, write_image
    frames, _, _ = zoom_frames(1.01, w=320, h=240)
    for n, f in enumerate(frames):
        write_image(str(tmp_path / f"d.{n:04d}.png"), np.repeat(f[..., None], 3, -1))
    runs = {}
    for name, extra in (("dense", ["--dense-motion"]), ("plain", ["--temporal"])):
        stats = tmp_path / f"{name}.csv"
        res = CliRunner().invoke(main, [str(tmp_path / "d.%04d.png"), "-o", str(tmp_path / name / "d.%04d.png"),
                                        "--temporal-method", "tss", "--temporal-mode", "global", "--stats",
                                        str(stats), "-q"] + extra)
        assert res.exit_code == 0, res.output
        runs[name] = [r.get("tracked") == "True" for r in csv.DictReader(stats.open())]
    assert all(runs["dense"][2:]) and not any(runs["plain"])
    assert not np.array_equal(read_image(str(tmp_path / "dense" / "d.0005.png")).pixels,
                              read_image(str(tmp_path / "plain" / "d.0005.png")).pixels)
    res = CliRunner().invoke(main, [str(tmp_path / "d.%04d.png"), "-o", str(tmp_path / "b" / "d.%04d.png"),
                                    "--dense-motion", "--temporal-method", "blend"])
    assert res.exit_code != 0 and "--dense-motion needs a --temporal-method with TSS" in res.output


def test_temporal_on_linear_hdr_exr_frames(tmp_path):
    """A folder of half-float EXRs in linear light with highlights over 1 (a render pipeline's frames): TSS
    resolves them in linear light, keeps the highlights and moves closer to the supersampled truth; the outputs
    are the API stage's (TSSStage(linear_input=True) after Filter(linear_input=True)). Before, --temporal wrote
    NaN and values near 65000 (half frames read as float32) and clipped highlights to 1."""
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.io.images import read_image, write_image
    from mlaa_stream.spatial.filter import Filter
    from mlaa_stream.temporal.tss import TSSStage

    sc = scene_pan(8, 160, 90)

    def linear_hdr(u8):   # sRGB-decoded, then 3x: the bright half of the frame goes over 1
        c = np.asarray(u8, np.float64) / 255.0
        return (3.0 * np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)).astype(np.float16)
    frames = [linear_hdr(f) for f in sc.inputs]
    src = tmp_path / "in"
    src.mkdir()
    for i, f in enumerate(frames):
        write_image(str(src / f"f{i:02d}.exr"), f)
    for name, extra in (("tss", ["--temporal", "--temporal-method", "tss"]), ("sp", [])):
        res = CliRunner().invoke(main, [str(src), "-o", str(tmp_path / name), "-q"] + extra)
        assert res.exit_code == 0, res.output
    read = lambda name, i: read_image(str(tmp_path / name / f"f{i:02d}.exr")).pixels
    outs = [read("tss", i) for i in range(8)]
    spatial = [read("sp", i) for i in range(8)]
    assert all(o.dtype == np.float16 and np.isfinite(o).all() for o in outs)
    assert max(float(o.max()) for o in outs) == max(float(f.max()) for f in frames) > 2.0
    changed = [(o != s).any(-1) for o, s in zip(outs, spatial)]
    assert np.mean([c.mean() for c in changed[3:]]) > 0.01
    assert any((c & (o > 1).any(-1)).any() for c, o in zip(changed, outs))   # resolved above 1, not clipped
    truth = [linear_hdr(t).astype(np.float64) for t in sc.truths]
    err = lambda xs: sum(float(((x.astype(np.float64) - t) ** 2).sum()) for x, t in zip(xs[3:], truth[3:]))
    assert err(outs) < 0.9 * err(spatial)
    stage = TSSStage(bgr=False, lookahead=2, linear_input=True)   # the command line's default look-ahead
    with Filter(None, bgr=False, linear_input=True) as f:
        want = [stage(x, f.process(x), i, future=frames[i + 1:i + 3]) for i, x in enumerate(frames)]
    assert all(np.array_equal(a, b) for a, b in zip(outs, want))


def test_temporal_on_exr_frames_with_nan_and_inf(tmp_path):
    """NaN and inf pixels in linear-light EXRs (a renderer's fireflies) pass the temporal stage as the spatial
    filter passes them (the motion's grey read them as an index out of range and stopped the run)."""
    from mlaa_stream.io.images import read_image, write_image
    frames = [(np.asarray(f, np.float32) / 255.0) ** 2.2 for f in _pan_frames(5)]
    src = tmp_path / "in"
    src.mkdir()
    for i, f in enumerate(frames):
        f = f.copy()
        f[40:42, 50:52] = np.nan
        f[10, 10] = np.inf
        write_image(str(src / f"f{i:02d}.exr"), f)
    for name, extra in (("t", ["--temporal"]), ("sp", [])):
        res = CliRunner().invoke(main, [str(src), "-o", str(tmp_path / name), "-q"] + extra)
        assert res.exit_code == 0, res.output
    for i in range(5):
        out, sp = (read_image(str(tmp_path / d / f"f{i:02d}.exr")).pixels for d in ("t", "sp"))
        assert np.array_equal(np.isnan(out), np.isnan(sp)) and np.isnan(out).any()
        assert np.array_equal(np.isinf(out), np.isinf(sp))


@pytest.mark.parametrize("method", ["tss+blend", "blend"])
def test_every_stats_column_is_documented(tmp_path, method):
    """--stats wrote some twenty columns that no page explained (--help said "motion model used, ms"): each one
    is now in docs/temporal.md's "--stats FILE" table, and the help points there."""
    from mlaa_stream.io.images import write_image
    src = tmp_path / "in"
    src.mkdir()
    for i, f in enumerate(_pan_frames(4)):
        write_image(str(src / f"f{i}.png"), f)
    write_image(str(src / "f4.png"), _pan_frames(4)[3])   # a repeated frame: the "repeat" column
    stats = tmp_path / "s.csv"
    res = CliRunner().invoke(main, [str(src), "-o", str(tmp_path / "out"), "--temporal-method", method,
                                    "--stats", str(stats), "-q"])
    assert res.exit_code == 0, res.output
    columns = set(next(csv.reader(stats.open())))
    doc = (Path(__file__).resolve().parent.parent / "docs" / "temporal.md").read_text()
    section = doc.split("## `--stats FILE`", 1)[1].split("\n## ", 1)[0]
    named = {c for line in section.splitlines() if line.startswith("| `") for c in
             line.split("|")[1].replace("`", "").replace(" ", "").split(",")}
    assert columns and columns <= named, sorted(columns - named)
    help_text = CliRunner().invoke(main, ["filter", "--help"], terminal_width=200).output
    assert 'docs/temporal.md, "--stats FILE"' in help_text


@pytest.mark.parametrize("method", ["auto", "tss", "blend"])
def test_stats_rows_spooled_to_disk_come_back_whole(tmp_path, monkeypatch, method):
    """--stats over a run whose rows move to the spool every 2 frames (cli/stats_spool.py; a long video's rows no
    longer stay in memory) is the same CSV as a run that keeps them all, but for the timings; and the stage never
    holds more than SPOOL_EVERY + KEEP rows."""
    from mlaa_stream.cli import stats_spool

    def run(name: str) -> list[dict]:
        stats = tmp_path / f"{name}.csv"
        res = CliRunner().invoke(main, [str(DEMO / "clip.mp4"), "-o", str(tmp_path / f"{name}.mp4"), "--temporal",
                                        "--temporal-method", method, "--stats", str(stats), "-q"])
        assert res.exit_code == 0, res.output
        return [{k: v for k, v in row.items() if not k.endswith("_ms")} for row in csv.DictReader(stats.open())]

    whole = run("whole")
    held = []
    drain = stats_spool.StatsSpool.drain

    def watched(self, keep=None):
        drain(self, keep)
        held.append(len(self.stage.stats))

    monkeypatch.setattr(stats_spool, "SPOOL_EVERY", 2)
    monkeypatch.setattr(stats_spool, "KEEP", 1)
    monkeypatch.setattr(stats_spool.StatsSpool, "drain", watched)
    assert run("spooled") == whole and len(whole) == 10
    assert max(held) <= 3 and held[-1] < len(whole)


@pytest.mark.parametrize("frames", [0, 1, 2, 3, 63, 64, 65, 1000])
def test_temporal_frames_takes_what_the_api_takes(tmp_path, frames):
    """--temporal-frames refuses exactly the values the API's check refuses (RING_FRAMES), naming the option."""
    from mlaa_stream.temporal.methods import check_frames
    try:
        check_frames(frames)
        api_refuses = False
    except ValueError:
        api_refuses = True
    res = CliRunner().invoke(main, [str(tmp_path / "missing.png"), "-o", str(tmp_path / "b.png"), "--temporal",
                                    "--temporal-frames", str(frames)])
    assert res.exit_code == 2, res.output   # a usage error either way: the option's, else the missing input's
    assert ("Invalid value for '--temporal-frames'" in res.output) == api_refuses, res.output


def test_temporal_frames_range_is_the_apis_constant(tmp_path):
    """The command line's range is RING_FRAMES itself, not a copy of its values: with the constant changed before the
    CLI is imported (a fresh interpreter), the CLI follows it."""
    import subprocess
    import sys
    code = ("import mlaa_stream.temporal.methods as m; m.RING_FRAMES = (3, 9)\n"
            "from click.testing import CliRunner\n"
            "from mlaa_stream.cli.main import main\n"
            "for k in ('2', '9', '10'):\n"
            "    r = CliRunner().invoke(main, ['missing.png', '-o', 'b.png', '--temporal', '--temporal-frames', k])\n"
            "    print(k, \"Invalid value for '--temporal-frames'\" in r.output)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         cwd=tmp_path).stdout
    assert out.split() == ["2", "True", "9", "False", "10", "True"], out


def test_blend_resume_warms_up_as_a_cluster_chunk_does(tmp_path):
    """--resume with the blend (a recursive history, never exactly identical after a warm-up): BLEND_WARMUP frames
    before the first one to write, as each cluster chunk reads (cluster/temporal.py); with 3, the resumed frames of
    this pan were up to 10 levels off the whole run's on 3 % of their pixels, now at most 1 level."""
    from mlaa_stream.cluster.temporal import BLEND_WARMUP
    from mlaa_stream.io.images import read_image, write_image
    for n, f in enumerate(_pan_frames(12), start=1):
        write_image(str(tmp_path / f"s.{n:04d}.png"), f)
    out = tmp_path / "o"
    args = [str(tmp_path / "s.%04d.png"), "-o", str(out / "s.%04d.png"), "--temporal", "--temporal-method", "blend"]
    assert CliRunner().invoke(main, args).exit_code == 0
    whole = {n: read_image(str(out / f"s.{n:04d}.png")).pixels for n in (11, 12)}
    for n in whole:
        (out / f"s.{n:04d}.png").unlink()
    res = CliRunner().invoke(main, args + ["--resume", "-v"])
    assert res.exit_code == 0, res.output
    assert f"temporal history warmed up from {BLEND_WARMUP} frames before frame 11" in res.output, res.output
    for n, pixels in whole.items():
        assert np.abs(read_image(str(out / f"s.{n:04d}.png")).pixels.astype(int) - pixels).max() <= 1
