"""Metrics on hand-made cases with known values, the bench's outputs, and the `compare` command."""
from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.bench import accuracy as B
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick import scenes as S
from mlaa_stream.cli.main import main


def _pair(seed=0, shape=(20, 30, 3)):
    rng = np.random.default_rng(seed)
    truth = rng.integers(20, 216, shape).astype(np.uint8)
    inp = truth.copy()
    inp[5:9, 4:20] += 12  # an "aliased" band: 12 levels off in every channel
    return inp, truth


def test_levels_of_each_sample_type():
    assert M.levels(np.array([255], np.uint8))[0] == 255
    assert M.levels(np.array([65535], np.uint16))[0] == pytest.approx(255)
    assert M.levels(np.array([0.5], np.float32))[0] == pytest.approx(127.5)
    with pytest.raises(TypeError, match="expected uint8"):
        M.levels(np.array([1], np.int32))


def test_mse_and_error_removed_known_values():
    inp, truth = _pair()
    band = np.zeros(truth.shape[:2], bool)
    band[5:9, 4:20] = True
    assert M.mse(inp, truth) == pytest.approx(144 * band.mean())
    assert M.mse(inp, truth, band) == pytest.approx(144)
    half = truth.copy()
    half[5:9, 4:20] += 6  # half the error left -> a quarter of the squared error
    assert M.error_removed(half, inp, truth) == pytest.approx(0.75)
    assert M.error_removed(truth, inp, truth) == 1.0
    assert M.error_removed(inp, inp, truth) == 0.0
    worse = inp.copy()
    worse[5:9, 4:20] += 12
    assert M.error_removed(worse, inp, truth) == pytest.approx(-3.0)
    assert math.isnan(M.error_removed(truth, truth, truth))
    with pytest.raises(ValueError, match="expected equal shapes"):
        M.mse(inp, truth[:5])


def test_damage_counts_only_pixels_away_from_edges():
    inp, truth = _pair(1)
    edges = ~M.near_mask(inp, truth, 3.0)
    assert edges.sum() == 4 * 16
    out = truth.copy()
    out[4, 10] = out[4, 10] + 50  # next to the band: not counted as damage
    assert M.damage(out, inp, truth, edges) == 0.0
    out[15, 25] = out[15, 25] + 10  # far away: counted
    n = M.damage_mask(inp, truth, edges).sum()
    assert n == 20 * 30 - 6 * 18
    assert M.damage(out, inp, truth, edges) == pytest.approx(math.sqrt(100 / n))


def test_dilate_matches_a_direct_loop():
    rng = np.random.default_rng(3)
    m = rng.random((2, 9, 11)) > 0.9
    ref = np.zeros_like(m)
    for t, y, x in zip(*np.nonzero(m)):
        ref[t, max(0, y - 1):y + 2, max(0, x - 1):x + 2] = True
    assert np.array_equal(M.dilate(m, 1), ref)


def test_broken_wires_known_share():
    bg = np.full((4, 10, 3), 200, np.uint8)
    truth = bg.copy()
    truth[1, :] = 140  # a wire with contrast 60
    wires = np.zeros((4, 10), bool)
    wires[1, :] = True
    out = truth.copy()
    out[1, :3] = 185  # contrast 15 < 20: broken
    out[1, 3:5] = 179  # contrast 21 >= 20: kept
    assert M.broken_wires(out, truth, bg, wires) == pytest.approx(0.3)
    assert M.broken_wires(truth, truth, bg, wires) == 0.0
    assert math.isnan(M.broken_wires(out, truth, bg, np.zeros_like(wires)))


def test_temporal_error_and_flicker_known_values():
    rng = np.random.default_rng(5)
    truth = rng.integers(50, 200, (4, 6, 8, 3)).astype(np.uint8)
    inp = truth.copy()
    inp[1::2] += 10  # flickers: every other frame 10 levels off
    assert M.temporal_error(truth, inp, truth) == 0.0
    assert M.temporal_error(inp, inp, truth) == 1.0
    half = truth.copy()
    half[1::2] += 5
    assert M.temporal_error(half, inp, truth) == pytest.approx(0.5)
    assert M.flicker_ratio(truth, truth) == 1.0
    frozen = np.repeat(truth[:1], 4, axis=0)  # smears all motion away
    assert M.flicker_ratio(frozen, truth) == 0.0
    assert M.flicker_ratio(inp, truth) > 1.0
    assert math.isnan(M.temporal_error(truth[:1], inp[:1], truth[:1]))


def test_flip_optional():
    inp, truth = _pair(2, (40, 40, 3))
    if not M.flip_available():  # the optional extra is absent: the metric says so with NaN
        assert math.isnan(M.flip(inp, truth))
        return
    assert M.flip(truth, truth) == pytest.approx(0.0, abs=1e-6)
    assert M.flip(inp, truth) > 0.0



def test_flip_of_a_sequence_is_the_mean_over_its_frames():
    """Known answer: a shot whose first frame is the truth and whose second is the aliased input scores half the
    input's FLIP (the first frame alone would say 0: a temporal stage returns it as the spatial filter does)."""
    if not M.flip_available():
        pytest.skip("flip-evaluator is not installed (pip install 'mlaa-stream[flip]')")
    inp, truth = _pair(2, (40, 40, 3))
    outs = np.stack([truth, inp])
    got = M.score(outs, np.stack([inp, inp]), np.stack([truth, truth]), with_flip=True)["flip"]
    assert got == pytest.approx(M.flip(inp, truth) / 2, rel=1e-6)

def test_score_of_input_and_truth_on_a_scene():
    s = S.generate_scenes(small=True, names=["rotation"])[0]
    none = M.score(s.inputs, s.inputs, s.truths, s.edges, s.wires, s.backgrounds)
    perfect = M.score(s.truths, s.inputs, s.truths, s.edges, s.wires, s.backgrounds)
    assert none["error_removed"] == 0.0 and none["temporal_error"] == 1.0 and none["damage"] == 0.0
    assert perfect["error_removed"] == 1.0 and perfect["temporal_error"] == 0.0
    assert perfect["flicker"] == 1.0 and perfect["broken_wires"] == 0.0
    assert none["broken_wires"] > 0.1


def test_registry_holds_baselines_and_every_preset():
    from mlaa_stream.spatial.filter import PRESETS

    assert {"none", "fxaa", "mlaa"} <= set(B.METHODS)
    for name, kw in PRESETS.items():
        assert (f"mlaa:{name}" in B.METHODS) == bool(kw)


def test_bench_outputs(tmp_path):
    scenes = S.generate_scenes(small=True, names=["diagonals", "photo", "pan"])
    res = B.run_bench(scenes, ["none", "fxaa"], timed_frames=2, warmup=1, command="test")
    assert set(res.timings) == {"none", "fxaa"} and not res.failures
    assert all(t.median_ms > 0 for t in res.timings.values())
    paths = B.write_outputs(res, tmp_path, scenes)
    rows = list(csv.DictReader(open(paths[0])))
    assert {r["method"] for r in rows} == {"none", "fxaa", "truth"} and len(rows) == 9
    by = {(r["method"], r["scene"]): r for r in rows}
    assert float(by["none", "diagonals"]["error_removed"]) == 0.0
    assert float(by["truth", "pan"]["temporal_error"]) == 0.0
    text = paths[1].read_text()
    assert "## diagonals" in text and "## pan" in text and res.device in text and "test" in text
    assert paths[2].stat().st_size > 10_000


def test_bench_temporal_method_reads_frames_ahead():
    """The bench's mlaa+temporal is what --temporal runs: TSS reading DEFAULT_LOOKAHEAD frames ahead (the same
    frames as a stage driven by hand with them), and the shot's frames in order through a fresh stage."""
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.temporal.methods import DEFAULT_LOOKAHEAD
    from mlaa_stream.temporal.tss import TSSStage
    sc = scene_pan(5, 240, 136)
    proc = B.METHODS["mlaa+temporal:tss"](None)
    try:
        outs = B.run_scene(proc, sc)
        assert [r["lookahead"] for r in proc.stage.stats] == [2, 2, 2, 1, 0] and DEFAULT_LOOKAHEAD == 2
        with TSSStage(bgr=False, lookahead=2, context=proc.filter.context) as stage:
            expected = [stage(f, proc.filter.process(f), i, future=sc.inputs[i + 1:i + 3])
                        for i, f in enumerate(sc.inputs)]
        assert all(np.array_equal(a, b) for a, b in zip(outs, expected))
    finally:
        proc.close()


def test_bench_records_a_failing_method(monkeypatch):
    def broken(device):
        raise RuntimeError("kernel exploded")

    monkeypatch.setitem(B.METHODS, "broken", broken)
    scenes = S.generate_scenes(small=True, names=["diagonals"])
    res = B.run_bench(scenes, ["none", "broken"], timed_frames=0)
    assert "kernel exploded" in res.failures["broken"]
    assert {r["method"] for r in res.rows} == {"none", "truth"}


def test_bench_command_small(tmp_path):
    out = tmp_path / "bench"
    r = CliRunner().invoke(main, ["bench", "--quick", "--methods", "none", "--scenes", "diagonals",
                                  "--frames", "1", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert "none" in r.output and (out / "README.md").exists() and (out / "speed_vs_accuracy.png").exists()
    r = CliRunner().invoke(main, ["bench", "--methods", "nope", "--out", str(out)])
    assert r.exit_code == 2 and "expected methods" in r.output
    r = CliRunner().invoke(main, ["bench", "--list"])
    assert r.exit_code == 0 and "fxaa" in r.output.split()


def _write(path, img):
    from mlaa_stream.cli.scenes_cmd import write_png
    write_png(path, img)


def test_compare_command(tmp_path):
    inp, truth = _pair(4, (32, 48, 3))
    half = truth.copy()
    half[5:9, 4:20] += 6
    for name, img in (("in.png", inp), ("truth.png", truth), ("half.png", half)):
        _write(tmp_path / name, img)
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "half.png"), str(tmp_path / "truth.png"),
                                  "--input", str(tmp_path / "in.png"), "--no-flip"])
    assert r.exit_code == 0, r.output
    assert "error removed:      75.0 %" in r.output and "64 edge pixels" in r.output
    _write(tmp_path / "small.png", truth[:10])
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "small.png"), str(tmp_path / "truth.png")])
    assert r.exit_code == 1 and "expected 48x32" in r.output
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "missing.png"), str(tmp_path / "truth.png")])
    assert r.exit_code == 1 and "missing.png" in r.output


def test_compare_scores_linear_light_against_display_values_encoded_alike(tmp_path):
    # an EXR and the same picture as an sRGB PNG scored ~38 levels apart: linear light read as display values
    from mlaa_stream.device.colour import linear_to_srgb
    from mlaa_stream.io.images import write_image
    rng = np.random.default_rng(3)
    lin = (rng.random((16, 24, 3)) * 0.8 + 0.05).astype(np.float32)
    write_image(str(tmp_path / "a.exr"), lin.astype(np.float16))
    _write(tmp_path / "a.png", np.rint(linear_to_srgb(lin.astype(np.float16)) * 255).astype(np.uint8))
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "a.png"), str(tmp_path / "a.exr"), "--no-flip"])
    assert r.exit_code == 0, r.output
    assert "a.exr: linear light, compared sRGB-encoded" in r.output
    rmse = float(r.output.split("RMSE vs truth (8-bit levels): out ")[1].split()[0])
    assert rmse < 0.6, r.output
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "a.exr"), str(tmp_path / "a.exr"), "--no-flip"])
    assert r.exit_code == 0 and "linear light" not in r.output and "out 0.000" in r.output, r.output


def test_compare_scores_a_multi_layer_exr_by_its_beauty(tmp_path):
    """Blender's multilayer EXR lists an AO pass (sorted first) before Combined: compare scored the AO pass. It
    scores the channels the filter takes (mlaa_stream.io.images.filter_channel_indices)."""
    import OpenImageIO as oiio
    from mlaa_stream.device.colour import linear_to_srgb
    rng = np.random.default_rng(5)
    beauty = rng.random((8, 12, 3)).astype(np.float32)
    names = ("View.Combined.R", "View.Combined.G", "View.Combined.B", "View.AO.R", "View.AO.G", "View.AO.B")
    spec = oiio.ImageSpec(12, 8, 6, "float")
    spec.channelnames = names
    path = str(tmp_path / "layers.exr")
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_image(np.concatenate([beauty, np.full_like(beauty, 0.5)], 2))
    out.close()
    _write(tmp_path / "b.png", np.rint(linear_to_srgb(beauty) * 255).astype(np.uint8))
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "b.png"), path, "--no-flip"])
    assert r.exit_code == 0, r.output
    rmse = float(r.output.split("RMSE vs truth (8-bit levels): out ")[1].split()[0])
    assert rmse < 0.6, r.output


@pytest.mark.parametrize("names", [("Z",), ("N.x", "N.y", "N.z")])
def test_compare_refuses_an_exr_without_colour(tmp_path, names):
    """A depth or normals pass (which the filter copies unchanged) was scored as colour: its channels taken by
    position, an RMSE of depths against colours with exit 0. Refused, naming its channels, as the filter does."""
    import OpenImageIO as oiio
    spec = oiio.ImageSpec(12, 8, len(names), "float")
    spec.channelnames = names
    path = str(tmp_path / "pass.exr")
    out = oiio.ImageOutput.create(path)
    assert out.open(path, spec) and out.write_image(np.full((8, 12, len(names)), 0.5, np.float32))
    out.close()
    _write(tmp_path / "b.png", np.full((8, 12, 3), 128, np.uint8))
    for args in ([path, str(tmp_path / "b.png")], [str(tmp_path / "b.png"), path]):
        r = CliRunner().invoke(main, ["compare", *args, "--no-flip"])
        assert r.exit_code == 1, r.output
        assert f"pass.exr: expected colour channels, got no colour channels ({', '.join(names)})" in r.output
        assert "RMSE" not in r.output


def test_bench_results_it_cannot_write_are_named(tmp_path, monkeypatch):
    """A folder in the way of results.csv (README.md, the chart) ended the run, once every method had been measured,
    in a traceback (IsADirectoryError): refused before the run now, a usage error; a failed write (a full disk) is
    named, exit 1."""
    import errno

    out = tmp_path / "bench"
    (out / "results.csv").mkdir(parents=True)
    args = ["bench", "--quick", "--methods", "none", "--scenes", "wires", "--no-flip", "--out", str(out)]
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 2 and f"{out / 'results.csv'}: a folder is in the way" in r.output, r.output
    (out / "results.csv").rmdir()

    def full(res, path):
        raise OSError(errno.ENOSPC, "No space left on device", str(path))
    monkeypatch.setattr(B, "write_csv", full)
    r = CliRunner().invoke(main, args)
    assert r.exit_code == 1, r.output
    assert f"{out / 'results.csv'}: cannot write the results (No space left on device)" in r.output
    assert isinstance(r.exception, SystemExit)


def test_compare_leaves_non_finite_pixels_out_and_says_so(tmp_path):
    """One NaN sample (a render's, which the filter passes through) made every score 'n/a', an infinite one the RMSE
    'inf', without a word. Such pixels are left out of the scores, with a note naming the file and how many."""
    from mlaa_stream.io.images import write_image
    rng = np.random.default_rng(7)
    truth = rng.random((16, 24, 3)).astype(np.float32)
    out = truth.copy()
    out[2:4, 2:10] += 0.1   # an error that must still be scored
    out[8, 8, 1], out[9, 9, 0] = np.nan, np.inf
    write_image(str(tmp_path / "t.exr"), truth)
    write_image(str(tmp_path / "o.exr"), out)
    r = CliRunner().invoke(main, ["compare", str(tmp_path / "o.exr"), str(tmp_path / "t.exr"), "--no-flip"])
    assert r.exit_code == 0, r.output
    assert "2 pixels with NaN or infinite samples (in " in r.output and "o.exr) left out of the scores" in r.output
    rmse = float(r.output.split("RMSE vs truth (8-bit levels): out ")[1].split()[0])
    assert math.isfinite(rmse) and rmse > 1
