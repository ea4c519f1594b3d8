"""Scene generator: the rasteriser against matplotlib's point-in-polygon, known coverages, the
properties each category promises, and the `scenes` command."""
from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from matplotlib.path import Path

from mlaa_stream.yardstick import scenes as S
from mlaa_stream.cli.main import main
from mlaa_stream.device.colour import linear_to_srgb


@pytest.fixture(scope="module")
def small():
    return {s.name: s for s in S.generate_scenes(small=True, seed=0)}


def _star(rng, cx, cy, n, r0, r1):
    t = np.sort(rng.uniform(0, 2 * np.pi, n))
    r = rng.uniform(r0, r1, n)
    return np.stack([cx + r * np.cos(t), cy + r * np.sin(t)], -1)


@pytest.mark.parametrize("spp", [1, 3, 8])
def test_coverage_matches_matplotlib_contains_points(spp):
    rng = np.random.default_rng(7)
    polys = [_star(rng, 20.3, 15.7, 9, 4, 14), _star(rng, 31.1, 20.2, 7, 2, 9)]
    w, h, row0, col0 = 40, 24, 3, 2
    mask = S.coverage(polys, spp, row0, h - row0, col0, w - col0)
    ys = row0 + (np.arange((h - row0) * spp) + 0.5) / spp
    xs = col0 + (np.arange((w - col0) * spp) + 0.5) / spp
    X, Y = np.meshgrid(xs, ys)
    pts = np.stack([X.ravel(), Y.ravel()], -1)
    # Nonzero winding: inside either star (each star is simple, so winding is 0 or +-1 per star).
    ref = np.zeros(len(pts), bool)
    for p in polys:
        ref |= Path(p).contains_points(pts)
    ref = ref.reshape(mask.shape)
    assert mask.sum() > 100
    assert (mask != ref).sum() == 0


def test_coverage_holes_by_opposite_winding():
    outer = S.rect(2, 2, 18, 18)
    inner = S.rect(6, 6, 14, 14)[::-1]  # reversed: winding -1 cancels the outer +1
    m = S.coverage([outer, inner], 1, 0, 20, 0, 20)
    assert m[3, 3] and m[4, 17] and not m[10, 10] and not m[0, 0]
    assert m.sum() == 16 * 16 - 8 * 8


def test_truth_is_linear_light_average_known_answer():
    # White where x < 10.25 on black: pixel 10 is a quarter covered. Its truth is the sRGB
    # encoding of linear 0.25 (not 25 % of 255); at 1 spp its centre (10.5) is black.
    layers = [S.Layer(None, (0, 0, 0)), S.Layer((S.rect(-1, -1, 10.25, 9),), (255, 255, 255))]
    inp, truth = S.render_pair(layers, 16, 8)
    expect = int(np.round(linear_to_srgb(0.25) * 255))
    assert expect == 137
    assert (truth[:, 10] == expect).all() and (inp[:, 10] == 0).all()
    assert (truth[:, :10] == 255).all() and (inp[:, :10] == 255).all()
    assert (truth[:, 11:] == 0).all() and (inp[:, 11:] == 0).all()


def test_half_covered_diagonal_pixels():
    # The triangle below y = x: of a diagonal pixel's 8x8 samples, 28 lie strictly below the line
    # and 8 on it, which the half-open rule (x >= crossing is right of the edge) leaves outside.
    layers = [S.Layer(None, (0, 0, 0)), S.Layer((np.array([[0, 0], [12, 12], [0, 12]], float),), (255, 255, 255))]
    lin = S.render(layers, 12, 12, 8)
    diag = lin[np.arange(12), np.arange(12), 0]
    assert np.allclose(diag, 28 / 64, atol=1e-6)
    assert np.allclose(lin[5, 2], 1.0) and np.allclose(lin[2, 5], 0.0)


def test_generation_is_deterministic_and_seeded():
    a = S.generate_scenes(small=True, seed=3, names=["wires", "noise"])
    b = S.generate_scenes(small=True, seed=3, names=["wires", "noise"])
    c = S.generate_scenes(small=True, seed=4, names=["wires", "noise"])
    for x, y in zip(a, b):
        assert np.array_equal(x.inputs, y.inputs) and np.array_equal(x.truths, y.truths)
    assert not np.array_equal(a[0].truths, c[0].truths)


def test_every_category_and_shapes(small):
    assert {s.category for s in small.values()} == set(S.CATEGORIES)
    for s in small.values():
        t, h, w = s.inputs.shape[:3]
        assert s.inputs.dtype == np.uint8 and s.truths.dtype == np.uint8
        assert s.inputs.shape == s.truths.shape == (t, h, w, 3)
        assert s.edges.shape == (t, h, w) and s.edges.dtype == bool
        assert np.array_equal(s.edges, S.edge_mask(s.inputs, s.truths))
        # every scene has some aliasing to remove, but the already-antialiased ones (input = truth)
        assert s.edges.any() != (s.category == "antialiased"), s.name
        assert s.inputs.std() > 5, s.name  # never a blank frame
    for name in ("rotation", "pan", "mover", "cut"):
        assert small[name].frames >= 4 and small[name].animated


def test_antialiased_scenes_are_their_own_truth(small):
    aa = [s for s in small.values() if s.category == "antialiased"]
    assert {s.name for s in aa} >= {"text_ui_aa", "wires_aa", "diagonals_aa"}
    for s in aa:
        assert np.array_equal(s.inputs, s.truths)
        # antialiased: intermediate levels between the two colours of an edge are everywhere
        assert len(np.unique(s.inputs.reshape(-1, 3), axis=0)) > 50, s.name


def test_photo_truth_equals_input_inside_the_photo(small):
    s = small["photo"]
    y0 = x0 = 16
    inp, truth = s.inputs[0, y0:y0 + 80, x0:x0 + 96], s.truths[0, y0:y0 + 80, x0:x0 + 96]
    assert np.array_equal(inp, truth)
    assert inp.std() > 20  # it is a photograph, not a flat patch
    assert not s.edges[0, y0:y0 + 80, x0:x0 + 96].any()


def test_long_edge_steps_are_longer_than_255(small):
    s = small["long_edges_h"]
    strip = s.inputs[0, :24, :, 1].astype(int)  # first strip: one rising edge of slope 1/280
    boundary = (np.abs(np.diff(strip, axis=0)) > 20).argmax(axis=0)  # edge row per column
    steps = np.flatnonzero(np.diff(boundary))
    runs = np.diff(steps)
    assert len(steps) >= 1
    assert (runs > 255).all() if len(runs) else steps[0] > 255 or 600 - steps[-1] > 255


def test_stroke_area_is_width_times_length():
    for w in (0.3, 0.75, 1.5):
        p = S.stroke(np.array([[1.0, 2.0], [41.0, 12.0]]), w)
        x, y = p[:, 0], p[:, 1]
        area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
        assert area == pytest.approx(w * np.hypot(40, 10), rel=1e-9)


def test_thin_wires_break_at_one_sample_per_pixel(small):
    from mlaa_stream.yardstick.metrics import broken_wires

    s = small["wires"]
    assert s.wires.mean() > 0.02 and s.backgrounds is not None
    assert broken_wires(s.inputs, s.truths, s.backgrounds, s.wires) > 0.3
    assert broken_wires(s.truths, s.truths, s.backgrounds, s.wires) == 0.0


def test_text_input_and_truth_share_geometry(small):
    s = small["text_ui"]
    ink_in = (255 - s.inputs[0].astype(float)).sum()
    ink_truth = (255 - s.truths[0].astype(float)).sum()
    assert ink_in == pytest.approx(ink_truth, rel=0.1)
    polys = S.text_polygons("Hg", 0, 20, 20)
    assert len(polys) >= 3 and max(len(p) for p in polys) > 30  # curves flattened, 'g' has a hole
    assert s.sharp is not None and s.sharp.any()
    # UI borders are pixel-aligned: input equals truth there except where a glyph touches them.
    d = np.abs(s.inputs.astype(int) - s.truths).max(-1)[s.sharp]
    assert (d <= 1).mean() > 0.99


def test_checkerboard_aliases_towards_horizon(small):
    s = small["checkerboard"]
    h = s.size[1]
    top, bottom = s.edges[0, : h // 2].mean(), s.edges[0, h // 2:].mean()
    assert top > bottom  # moire near the horizon


def test_timing_frame_is_deterministic():
    a = S.timing_frame(480, 270)
    assert a.shape == (270, 480, 3) and a.dtype == np.uint8 and a.std() > 20
    assert np.array_equal(a, S.timing_frame(480, 270))
    assert not np.array_equal(a, S.timing_frame(480, 270, shift=0.5))


def test_unknown_scene_name_is_refused():
    with pytest.raises(ValueError, match="expected scene names"):
        S.generate_scenes(names=["nope"])


def test_scenes_command_writes_and_refuses_to_overwrite(tmp_path):
    import OpenImageIO as oiio

    out = tmp_path / "scenes"
    r = CliRunner().invoke(main, ["scenes", str(out), "--small", "--only", "diagonals,rotation"])
    assert r.exit_code == 0, r.output
    index = json.loads((out / "scenes.json").read_text())
    assert [s["name"] for s in index["scenes"]] == ["diagonals", "rotation"]
    assert (out / "rotation_03_truth.png").exists() and (out / "rotation_00_wires.png").exists()
    img = oiio.ImageInput.open(str(out / "diagonals_00_input.png"))
    pixels = img.read_image(format="uint8")
    img.close()
    ref = S.generate_scenes(small=True, names=["diagonals"])[0].inputs[0]
    assert np.array_equal(pixels, ref)
    r = CliRunner().invoke(main, ["scenes", str(out), "--small", "--only", "diagonals"])
    assert r.exit_code == 2 and "--overwrite" in r.output
    r = CliRunner().invoke(main, ["scenes", str(out), "--small", "--only", "diagonals", "--overwrite"])
    assert r.exit_code == 0, r.output
    r = CliRunner().invoke(main, ["scenes", str(out), "--only", "bogus"])
    assert r.exit_code == 2 and "expected scene names" in r.output


def test_scenes_help_lists_every_group_it_accepts():
    # --only named "scene groups" without saying which: the names came only with an error
    r = CliRunner().invoke(main, ["scenes", "--help"])
    assert r.exit_code == 0, r.output
    listed = " ".join(r.output.split("--only")[1].split("--overwrite")[0].split())
    assert listed.endswith(f"(default: all): {', '.join(S.SCENES)}.")


@pytest.mark.parametrize("args, message", [(["--only", ","], "--only: expected comma-separated names"),
                                           (["--seed", "-1"], "'--seed': -1 is not in the range x>=0")])
def test_scenes_options_that_name_nothing_or_a_bad_seed_are_refused(tmp_path, args, message):
    """--only ',' wrote nothing and exited 0; --seed -1 failed with numpy's message, not naming the option."""
    r = CliRunner().invoke(main, ["scenes", str(tmp_path / "s"), "--small", *args])
    assert r.exit_code == 2 and message in r.output
    assert not (tmp_path / "s").exists()


def test_a_scene_named_twice_is_written_once(tmp_path):
    r = CliRunner().invoke(main, ["scenes", str(tmp_path), "--small", "--only", "diagonals, diagonals"])
    assert r.exit_code == 0, r.output
    index = json.loads((tmp_path / "scenes.json").read_text())["scenes"]
    assert [s["name"] for s in index].count("diagonals") == 1 and len(index) == 1


@pytest.mark.parametrize("args, message", [(["--methods", " , "], "--methods: expected comma-separated names"),
                                           (["--scenes", ","], "--scenes: expected comma-separated names"),
                                           (["--seed", "-2"], "'--seed': -2 is not in the range x>=0")])
def test_bench_options_that_name_nothing_or_a_bad_seed_are_refused(tmp_path, args, message):
    r = CliRunner().invoke(main, ["bench", "--quick", "--out", str(tmp_path / "b"), *args])
    assert r.exit_code == 2 and message in r.output
    assert not (tmp_path / "b").exists()


def test_an_output_folder_that_cannot_be_made_is_named_not_a_traceback(tmp_path):
    """A file where the folder should go ended scenes in a NotADirectoryError traceback, and bench likewise, but
    only after measuring every method."""
    (tmp_path / "f").write_text("")
    r = CliRunner().invoke(main, ["scenes", str(tmp_path / "f" / "s"), "--small", "--only", "diagonals"])
    assert r.exit_code == 1 and f"{tmp_path / 'f' / 's'}: cannot create the folder (Not a directory)" in r.output
    r = CliRunner().invoke(main, ["bench", "--quick", "--methods", "none", "--scenes", "diagonals", "--frames", "1",
                                  "--out", str(tmp_path / "f" / "b")])
    assert r.exit_code == 2 and "--out: " in r.output and "cannot create the folder (Not a directory)" in r.output


@pytest.mark.parametrize("in_the_way", ["scenes.json", "diagonals_00_input.png"])
def test_scenes_command_names_an_output_it_cannot_write(tmp_path, in_the_way):
    """A folder where scenes.json goes ended in a traceback (IsADirectoryError); one where an image goes said
    'cannot write ()'. Both exit 1 naming the file and why."""
    out = tmp_path / "scenes"
    (out / in_the_way).mkdir(parents=True)
    r = CliRunner().invoke(main, ["scenes", str(out), "--small", "--only", "diagonals", "--overwrite"])
    assert r.exit_code == 1, r.output
    assert f"{out / in_the_way}: cannot write (" in r.output and "cannot write ()" not in r.output
    assert r.exception is None or isinstance(r.exception, SystemExit)
