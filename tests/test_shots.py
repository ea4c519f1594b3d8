"""The render verdict held over a shot (spatial/shots.py, kernels/fallback.cl render_frame's hold)."""
import numpy as np
import pytest

from mlaa_stream.spatial.fallback import FALLBACK_TILE, RENDER_RADIUS, fallback_reference, render_regions_of
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.spatial.shots import (CUT_HIST, HELD_SUPERSAMPLED_RUN, ShotTracker, histogram_distance,
                                      thumbnail)
from tests.test_fallback import _as, cables_on_sky, flat_art, ramps_beside_render, shaded_polygons


def frames(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A render frame (renders over most of its edge tiles, cables on a sky beside them: regions only through the
    frame's verdict) and a frame of the same shot under RENDER_FRAME_PCT (one render, the cables twice), with
    close histograms."""
    gap = np.full((144, (RENDER_RADIUS + 2) * FALLBACK_TILE, 3), 200, np.uint8)
    render = [shaded_polygons(seed, 144, 192), shaded_polygons(seed + 10, 144, 192)]
    sky = cables_on_sky(seed, 144, 192)
    return np.concatenate([*render, gap, sky], 1), np.concatenate([render[0], gap, sky, sky], 1)


def tiles_to_pixels(flags: np.ndarray, h: int, w: int) -> np.ndarray:
    return np.repeat(np.repeat(flags > 0, FALLBACK_TILE, 0), FALLBACK_TILE, 1)[:h, :w]


def test_thumbnail_and_histogram_distance_known_answers():
    """A thumbnail takes one pixel in 8 each way of the green channel (grey frames: their one), codes scaled to 0..255
    (uint16 and floats clipped to [0, 1]); the distance is 0 for the same histogram and 1 for disjoint ones."""
    rng = np.random.default_rng(3)
    a = rng.integers(0, 256, (64, 96, 3), dtype=np.uint8)
    t = thumbnail(a)
    assert t.shape == (8, 12) and t.dtype == np.uint8
    np.testing.assert_array_equal(t, a[::8, ::8, 1])
    np.testing.assert_array_equal(thumbnail(a[..., ::-1]), t)  # BGR: the same middle channel
    np.testing.assert_array_equal(thumbnail(a[..., 1]), t)
    np.testing.assert_array_equal(thumbnail(a.astype(np.uint16) * 257), t)
    np.testing.assert_allclose(thumbnail(a.astype(np.float32) / 255).astype(int), t, atol=1)
    np.testing.assert_array_equal(thumbnail(np.dstack([a, a[..., :1]])), t)  # alpha is no colour
    assert thumbnail(np.full((16, 16), 2.0, np.float32)).max() == 255
    assert histogram_distance(t, t) == 0.0
    assert histogram_distance(np.zeros((8, 8), np.uint8), np.full((8, 8), 200, np.uint8)) == 1.0


def test_shot_tracker_cuts():
    """The first frame, a frame after reset() and a frame whose histogram moved by over CUT_HIST start shots; the
    same scene a little changed, or with another shape (a new stream), does or does not as it should."""
    render, other = frames()
    dark = (render // 4).astype(np.uint8)
    assert histogram_distance(thumbnail(render), thumbnail(other)) <= CUT_HIST
    assert histogram_distance(thumbnail(render), thumbnail(dark)) > CUT_HIST
    shots = ShotTracker()
    assert shots.cut(render)
    assert not shots.cut(other)
    assert not shots.cut(render)
    assert shots.cut(dark)
    shots.reset()
    assert shots.cut(dark)
    assert shots.cut(dark[:64])


@pytest.mark.parametrize("dtype,channels", [(np.uint8, 3), (np.uint16, 3), (np.float32, 4)])
def test_a_frame_of_a_render_shot_is_held_a_render(dtype, channels):
    """Known answer: the second frame alone is no render (its cables are no regions); after the render frame of its
    shot it is one, its cables regions, and its output the reference's with `held` (exact); after new_shot(), with
    hold_render=False, or after a cut, it is judged alone again."""
    render, other = (_as(f, dtype, channels) for f in frames())
    h, w = other.shape[:2]
    cables = np.s_[:, -384:]
    with Filter(fallback="off") as g:
        passes = g.intermediates(other)
    alone = render_regions_of(other, passes["out"], passes["edges"])
    assert not alone[cables].any()
    ref = {held: fallback_reference(other, passes["out"], passes["edges"], passes["hdist"], passes["vdist"],
                                    held=held) for held in (False, True)}
    assert not np.array_equal(ref[False], ref[True])

    def check(got: np.ndarray, held: bool) -> None:
        if dtype == np.float32:
            np.testing.assert_allclose(got, ref[held], rtol=0, atol=1e-6)
        else:
            np.testing.assert_array_equal(got, ref[held])

    with Filter(keep_regions=True) as f:
        f.process(render)
        check(f.process(other), True)
        assert tiles_to_pixels(f.last_regions, h, w)[cables].mean() > 0.95
        check(f.process(other), True)  # held frames hold on
        f.new_shot()
        check(f.process(other), False)
        assert not tiles_to_pixels(f.last_regions, h, w)[cables].any()
        check(f.process(other), False)  # nothing was held since the new shot
        f.process(render)
        f.process(_as(flat_art(1, h, w) // 5, dtype, channels))  # a cut: another histogram
        check(f.process(other), False)
    with Filter(hold_render=False) as f:
        f.process(render)
        check(f.process(other), False)


def test_the_hold_ends_after_render_hold_frames(monkeypatch):
    """Known answer: a render held for RENDER_HOLD_FRAMES frames is no longer held on the frame after them (the
    kernel's count, here built with 2), and a frame that is a render by its own share renews the hold."""
    import mlaa_stream.spatial.fallback as F
    monkeypatch.setattr(F, "RENDER_HOLD_FRAMES", 2)
    render, other = frames(1)
    cables = np.s_[:, -384:]
    h, w = other.shape[:2]
    held = []
    with Filter(keep_regions=True) as f:
        for frame in (render, other, other, other, render, other):
            f.process(frame)
            if frame is other:
                held.append(bool(tiles_to_pixels(f.last_regions, h, w)[cables].mean() > 0.95))
    assert held == [True, True, False, True]


def test_frames_that_look_supersampled_are_held_for_a_short_run_only():
    """Known answer (HELD_SUPERSAMPLED_RUN): a frame judged supersampled (ramps beside a render, tests/test_fallback.py,
    and cables on a sky that only a render verdict makes regions) in a shot held as a render is held -- its cables
    regions, its output the reference's with `held_supersampled` -- while it is one of at most HELD_SUPERSAMPLED_RUN
    such frames in a row, as a codec's B-frames are; the next one in the run is judged supersampled (the reference
    without the hold), and so is the same frame after new_shot()."""
    render, _ = frames()
    ramps = ramps_beside_render(0)
    gap = np.full((144, (RENDER_RADIUS + 2) * FALLBACK_TILE, 3), 200, np.uint8)
    ss = np.concatenate([ramps, ramps[:, 192:], gap, cables_on_sky(0, 144, 96)], 1)
    h, w = ss.shape[:2]
    tracker = ShotTracker()
    assert [tracker.cut(f) for f in (render, ss)] == [True, False]
    with Filter(fallback="off") as g:
        p = g.intermediates(ss)
    args = (ss, p["out"], p["edges"], p["hdist"], p["vdist"])
    alone = fallback_reference(*args)
    np.testing.assert_array_equal(fallback_reference(*args, held=True), alone)  # looks supersampled: not held
    held = fallback_reference(*args, held=True, held_supersampled=True)
    assert not np.array_equal(held, alone)
    assert not render_regions_of(ss, p["out"], p["edges"])[:, -96:].any()
    with Filter(keep_regions=True) as f:
        f.process(render)
        for _ in range(HELD_SUPERSAMPLED_RUN):
            np.testing.assert_array_equal(f.process(ss), held)
            assert tiles_to_pixels(f.last_regions, h, w)[:, -96:].mean() > 0.95
        np.testing.assert_array_equal(f.process(ss), alone)
        f.process(render)  # a frame that does not look supersampled ends the run
        np.testing.assert_array_equal(f.process(ss), held)
        f.new_shot()
        np.testing.assert_array_equal(f.process(ss), alone)


def test_the_antialiaser_holds_and_starts_shots():
    """The Antialiaser's filter holds a render verdict over its calls (the second frame after the render frame as the
    Filter's), new_shot() and hold_render=False judge it alone, and the fast preset (no render regions) takes both."""
    from mlaa_stream.antialiaser import Antialiaser
    render, other = frames()
    with Filter(bgr=True) as f:
        f.process(render)
        held = f.process(other)
    with Filter(bgr=True, hold_render=False) as f:
        alone = f.process(other)
    assert not np.array_equal(held, alone)
    with Antialiaser() as aa:
        aa(render)
        np.testing.assert_array_equal(aa(other), held)
        aa.new_shot()
        np.testing.assert_array_equal(aa(other), alone)
    with Antialiaser(hold_render=False) as aa:
        aa(render)
        np.testing.assert_array_equal(aa(other), alone)
    with Antialiaser(preset="fast", hold_render=True) as aa:
        aa(render)
        aa.new_shot()
        assert aa(other).shape == other.shape
