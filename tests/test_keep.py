"""Keep rectangles (spatial/keep.py): parts of every frame that come out exactly as they went in -- subtitles or a
HUD over a render, which the render regions' tables would soften."""
from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.spatial.keep import KeepRect, keep_rects, parse_keep, restore_kept


def aliased_frame(h: int = 48, w: int = 64, seed: int = 5) -> np.ndarray:
    """Seeded random half-planes at 1 spp: staircases everywhere that the filter changes."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w] + 0.5
    frame = np.empty((h, w, 3), np.uint8)
    frame[:] = rng.integers(20, 236, 3)
    for _ in range(6):
        a, b, c = rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(-0.5, 0.5)
        frame[a * (x - w / 2) + b * (y - h / 2) > c * w] = rng.integers(20, 236, 3)
    return frame


def test_rectangles_in_pixels_and_percentages_clipped_to_the_frame():
    assert parse_keep("10,20,30,40").slices(100, 200) == (slice(20, 60), slice(10, 40))
    assert parse_keep("0, 85%, 100%, 15%").slices(200, 100) == (slice(170, 200), slice(0, 100))
    assert parse_keep("90,90,50,50").slices(100, 100) == (slice(90, 100), slice(90, 100))
    assert parse_keep("300,0,5,5").slices(100, 100)[1] == slice(100, 100)  # outside: empty
    assert keep_rects("1,2,3,4") == (KeepRect(1, 2, 3, 4),)
    assert keep_rects(None) == ()


@pytest.mark.parametrize("text, message", [("1,2,3", "expected X,Y,W,H"), ("a,1,1,1", "X of .* is not a number"),
                                           ("0,0,0,5", "W of .* must be positive"), ("-1,0,5,5", "X of .* >= 0"),
                                           ("1.5,0,5,5", "whole pixels"), ("0,0,nan%,5", "W of")])
def test_a_bad_rectangle_is_refused_by_what_is_wrong(text, message):
    with pytest.raises(ValueError, match=message):
        parse_keep(text)


@pytest.mark.parametrize("preset", [None, "fast"])
def test_the_filter_leaves_the_rectangle_as_it_was_and_the_rest_as_without(device, preset):
    from mlaa_stream.spatial.fast_filter import FastFilter
    from mlaa_stream.spatial.filter import Filter
    frame = aliased_frame()
    make = FastFilter if preset == "fast" else Filter
    with make(context=device) as plain, make(context=device, keep=["8,6,20,10", "0,75%,100%,25%"]) as kept:
        a, b = plain.process(frame), kept.process(frame)
        pending = kept.submit(frame)
        c = pending.result()
    inside = np.zeros(frame.shape[:2], bool)
    inside[6:16, 8:28] = True
    inside[36:] = True
    assert np.any(a[inside] != frame[inside])  # the filter would change them
    np.testing.assert_array_equal(b[inside], frame[inside])
    np.testing.assert_array_equal(b[~inside], a[~inside])
    np.testing.assert_array_equal(c, b)


def test_the_rectangle_survives_the_temporal_stage():
    """Antialiaser(temporal=True): the temporal stage mixes frames; the rectangle is put back after it, in calls
    and in streams."""
    from mlaa_stream import Antialiaser
    from mlaa_stream.bench.temporal import scene_pan
    frames = [np.ascontiguousarray(f[..., ::-1]) for f in scene_pan(5, 160, 96).inputs]
    rows, cols = slice(60, 96), slice(0, 160)
    with Antialiaser(temporal=True, temporal_frames=3, keep="0,60,100%,36") as aa:
        outs = [aa(f) for f in frames]
        streamed = list(aa.stream(frames))
    with Antialiaser(temporal=True, temporal_frames=3) as aa:
        plain = [aa(f) for f in frames]
    assert any(np.any(p[rows, cols] != f[rows, cols]) for p, f in zip(plain, frames))
    for o, s, f in zip(outs, streamed, frames):
        np.testing.assert_array_equal(o[rows, cols], f[rows, cols])
        np.testing.assert_array_equal(s[rows, cols], f[rows, cols])


def test_restore_copies_a_read_only_output():
    frame = np.arange(24, dtype=np.uint8).reshape(2, 4, 3)
    out = np.zeros_like(frame)
    out.flags.writeable = False
    got = restore_kept(frame, out, keep_rects("1,0,2,1"))
    np.testing.assert_array_equal(got[0, 1:3], frame[0, 1:3])
    assert not got[1].any() and not out.any()


def test_command_line_keep_option(tmp_path):
    from mlaa_stream.cli.main import main
    from mlaa_stream.io.images import read_image, write_image
    frame = aliased_frame(seed=9)
    src, dst = tmp_path / "in.png", tmp_path / "out.png"
    write_image(str(src), frame)
    result = CliRunner().invoke(main, ["filter", str(src), "-o", str(dst), "--keep", "0,50%,100%,50%", "-q"])
    assert result.exit_code == 0, result.output
    out = read_image(str(dst)).pixels
    np.testing.assert_array_equal(out[24:], frame[24:])
    assert np.any(out[:24] != frame[:24])
    bad = CliRunner().invoke(main, ["filter", str(src), "-o", str(tmp_path / "b.png"), "--keep", "0,0,0,5"])
    assert bad.exit_code == 2 and "--keep: W of '0,0,0,5' must be positive" in bad.output
    assert not (tmp_path / "b.png").exists()


def test_a_rectangle_outside_the_frame_is_said_once(caplog):
    """A typo ('0,1800,...' on a 720-line video) would protect nothing: a warning names it, once per frame size."""
    from mlaa_stream.spatial.keep import kept_patches
    frame = np.zeros((48, 64, 3), np.uint8)
    with caplog.at_level("WARNING", logger="mlaa_stream.spatial.keep"):
        for _ in range(3):
            assert kept_patches(frame, keep_rects(["0,100,64,10", "0,50%,100%,10%"]))[0][1].size == 0
    said = [r.getMessage() for r in caplog.records]
    assert said == ["keep rectangle 0,100,64,10 lies outside the 64x48 frame: it keeps nothing there"]


@pytest.mark.parametrize("text, name", [("1e400,0,5,5", "X"), ("0,0,1e400%,5", "W"), ("0,0,5,-inf", "H")])
def test_an_infinite_value_is_refused_by_name_not_a_traceback(text, name):
    """'1e400' parses as infinity; int() of it raised OverflowError before the finiteness check."""
    with pytest.raises(ValueError, match=f"keep: {name} of "):
        parse_keep(text)


@pytest.mark.parametrize("keep", [[(0, 0, 10, 10)], (0, 0, 10, 10), [[1, 2, 3, 4]]])
def test_a_rectangle_of_another_type_is_refused_by_its_type(keep):
    """keep=[(0, 0, 10, 10)] was turned into text and refused as "X of (0, 0, 10, 10) is not a number: '(0'"."""
    with pytest.raises(ValueError, match=r"keep: expected KeepRect\(x, y, w, h\) or an 'X,Y,W,H' string .* got "):
        keep_rects(keep)
