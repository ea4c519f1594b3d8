"""Linear-light float frames are filtered at the power of two of exposure that puts their key near 1
(spatial/exposure.py): the output no longer depends on the exposure a renderer wrote, exactly."""
import numpy as np
import pytest

from mlaa_stream.spatial.exposure import KEY_PERCENTILE, exposure_scale
from mlaa_stream.spatial.filter import Filter


def aliased_linear_scene(h: int = 48, w: int = 64, seed: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """1-spp samples at pixel centres of a rotated bright square, a dark wedge and a thin bright line over a
    seeded mid-grey texture, in linear light (0.02-0.9), with its 8x8 supersampled truth: (input, truth)."""
    rng = np.random.default_rng(seed)
    tex = 0.18 + 0.04 * rng.random((h, w, 1)).astype(np.float32)

    def shade(y, x):
        c = np.broadcast_to(tex[np.clip(y.astype(int), 0, h - 1), np.clip(x.astype(int), 0, w - 1)],
                            y.shape + (3,)).copy()
        u, v = (x - 20) * 0.92 + (y - 22) * 0.39, -(x - 20) * 0.39 + (y - 22) * 0.92
        c[(np.abs(u) < 11) & (np.abs(v) < 11)] = (0.9, 0.7, 0.3)
        c[(y > 0.35 * (x - 36) + 26) & (x > 36)] = (0.02, 0.03, 0.05)
        c[np.abs(y - (0.12 * x + 4)) < 0.35] = (0.85, 0.85, 0.9)
        return c

    y, x = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    inp = shade(y, x).astype(np.float32)
    o = (np.arange(8) + 0.5) / 8 - 0.5
    truth = np.mean([shade(y + dy, x + dx) for dy in o for dx in o], axis=0)
    return inp, truth.astype(np.float32)


def test_exposure_scale_known_answers():
    """The key (KEY_PERCENTILE-th percentile of max(R, G, B)) goes to the power of two nearest 1 in stops; alpha
    does not count; a black frame keeps its scale; a huge sample caps the brightening."""
    assert KEY_PERCENTILE == 90
    frame = np.full((20, 20, 3), 0.25, np.float32)
    assert exposure_scale(frame) == 4.0
    assert exposure_scale(frame * 12) == 0.25          # key 3: 1.58 stops over -> 2 stops down
    assert exposure_scale(frame * 3.5) == 1.0          # key 0.875: within half a stop of 1
    assert exposure_scale(np.zeros((8, 8, 3), np.float32)) == 1.0
    rgba = np.concatenate([np.full((8, 8, 3), 0.01, np.float32), np.ones((8, 8, 1), np.float32)], -1)
    assert exposure_scale(rgba) == 128.0               # log2(100) = 6.64 stops: alpha's 1 is no light
    assert exposure_scale(np.full((8, 8), 2.0 ** -30, np.float32)) == 2.0 ** 24   # at most 24 stops
    huge = np.full((8, 8, 3), 1e-3, np.float32)
    huge[0, 0] = 1e14
    assert 1e14 * exposure_scale(huge) <= 1e15 and exposure_scale(huge) > 1.0
    huge[0, 0], huge[1, 1] = np.inf, np.nan                            # passed through unscaled: no limit
    assert exposure_scale(huge) == 1024.0
    big = np.full((1024, 1024, 3), 0.5, np.float32)    # read on every 4th row and column: rows between not read
    big[1::4] = 8.0
    assert exposure_scale(big) == 2.0


@pytest.mark.parametrize("stops", [-9, -4, 3, 6])
def test_output_does_not_depend_on_the_frames_exposure(stops):
    """The same linear frame at 2^stops gives 2^stops times the output, bit for bit (float32); without
    auto_exposure the filter's work changes with the exposure (at 2^-9 and 2^6 it leaves most edges)."""
    inp, _ = aliased_linear_scene()
    s = np.float32(2.0 ** stops)
    with Filter(linear_input=True) as auto, Filter(linear_input=True, auto_exposure=False) as plain:
        base = auto.process(inp)
        assert np.array_equal(auto.process(inp * s), base * s)
        changed = np.any(base != inp, axis=-1).sum()
        assert changed > 100
        if abs(stops) >= 6:
            changed_plain = np.any(plain.process(inp * s) != inp * s, axis=-1).sum()
            assert changed_plain < 0.5 * changed, (changed_plain, changed)


def test_a_dark_render_is_antialiased_as_the_bright_one():
    """Known answer against the 8x8 truth: at 2^-8 or 16 times its exposure the scene loses none of the error
    removed (without auto_exposure the filter leaves it all: 0.57 -> 0.0 / 0.006 here)."""
    inp, truth = aliased_linear_scene()

    def removed(out):
        return 1 - np.mean((out - truth) ** 2) / np.mean((inp - truth) ** 2)

    with Filter(linear_input=True) as auto, Filter(linear_input=True, auto_exposure=False) as plain:
        bright = removed(auto.process(inp))
        assert bright > 0.3
        for e in (np.float32(2.0 ** -8), np.float32(16)):
            assert removed(auto.process(inp * e) / e) == pytest.approx(bright, abs=1e-6)
            assert removed(plain.process(inp * e) / e) < 0.1


@pytest.mark.parametrize("dtype", [np.float16, np.float32])
def test_pixels_left_alone_come_back_bit_for_bit_with_their_alpha(dtype):
    """A smooth dark frame (nothing to antialias) brightened for filtering comes back exactly, alpha untouched;
    a non-finite sample too."""
    y, x = np.mgrid[0:32, 0:40].astype(np.float32)
    rng = np.random.default_rng(3)
    colour = (0.002 + 0.0004 * (x[..., None] + y[..., None] * np.float32([1, 0.5, 0.25])) / 40)
    frame = np.concatenate([colour, rng.random((32, 40, 1), dtype=np.float32)], -1).astype(dtype)
    frame[5, 7, 1] = np.nan
    assert exposure_scale(np.nan_to_num(frame).astype(np.float32)) > 64
    with Filter(linear_input=True) as auto:
        out = auto.process(frame)
    assert out.dtype == frame.dtype
    np.testing.assert_array_equal(out, frame)


def test_frames_that_are_not_linear_light_are_never_scaled():
    """Integer frames and display-encoded float frames are filtered as they are: auto_exposure changes nothing."""
    inp, _ = aliased_linear_scene()
    dark_float = inp * np.float32(0.05)
    dark_u16 = np.round(dark_float * 65535).astype(np.uint16)
    with Filter(linear_input=True) as auto, Filter(linear_input=True, auto_exposure=False) as plain:
        assert np.array_equal(auto.process(dark_u16), plain.process(dark_u16))
    with Filter() as auto, Filter(auto_exposure=False) as plain:
        assert np.array_equal(auto.process(dark_float), plain.process(dark_float))


def test_held_exposure_keeps_its_scale_within_a_stop_and_changes_past_it():
    """A sequence's key wobbling around a half-stop boundary keeps one scale; a jump of 2+ stops changes it."""
    from mlaa_stream.spatial.exposure import HeldExposure
    held = HeldExposure()
    frame = np.full((8, 8, 3), 1.0, np.float32)
    assert held.update(frame * 0.72) is False and held.scale == 1.0      # the first frame: no change to report
    for k in (0.70, 0.68, 0.4, 1.9, 0.72):                               # own scales 2, 2, 2, 0.5, 1: held
        assert held.update(frame * k) is False and held.scale == 1.0
    assert held.update(frame * 0.2) is True and held.scale == 4.0        # 2 stops: taken, the ring restarts
    assert held.update(frame * 0.3) is False and held.scale == 4.0


def test_temporal_supersampling_of_linear_frames_does_not_depend_on_their_exposure():
    """TSS on a sub-pixel pan in linear light: at 2^-6 and 2^5 of its exposure the outputs are that exposure times
    the outputs at 1, bit for bit, and TSS takes samples there (it differs from the spatial output); without
    auto_exposure the dark pan's resolve is another (its motion measured on a near-black grey)."""
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.temporal.tss import TSSStage
    from mlaa_stream.yardstick.scenes import srgb8_to_linear
    pan = [srgb8_to_linear(f).astype(np.float32) for f in scene_pan(6, 160, 96).inputs]

    def run(scale: float, auto: bool) -> tuple[np.ndarray, np.ndarray]:
        s = np.float32(scale)
        with Filter(None, bgr=False, linear_input=True) as filt, \
                TSSStage(context=filt.context, bgr=False, linear_input=True, auto_exposure=auto) as stage:
            spatial = [filt.process(f * s) for f in pan]
            outs = [stage(f * s, sp, i) for i, (f, sp) in enumerate(zip(pan, spatial))]
        return np.stack(outs), np.stack(spatial)

    base, spatial = run(1.0, True)
    assert np.any(base[2:] != spatial[2:], axis=-1).sum() > 200
    for stops in (-6, 5):
        s = np.float32(2.0 ** stops)
        outs, _ = run(float(s), True)
        np.testing.assert_array_equal(outs, base * s)
    plain, _ = run(2.0 ** -6, False)
    assert not np.array_equal(plain, base * np.float32(2.0 ** -6))


@pytest.mark.parametrize("method", ["tss+blend", "blend"])
def test_the_blend_sees_linear_frames_at_one_exposure(method):
    """Methods tss+blend (the blend everywhere after TSS) and blend on linear frames: at 2^-5 of the exposure the
    outputs are 2^-5 times the outputs at 1, bit for bit (the blend's history held at TSS's scale, or its own)."""
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.temporal.methods import make_stage
    from mlaa_stream.yardstick.scenes import srgb8_to_linear
    pan = [srgb8_to_linear(f).astype(np.float32) for f in scene_pan(5, 160, 96).inputs]

    def run(scale: float) -> np.ndarray:
        s = np.float32(scale)
        with Filter(None, bgr=False, linear_input=True) as filt, \
                make_stage(method, filt.context, bgr=False, linear_input=True) as stage:
            return np.stack([stage(f * s, filt.process(f * s), i) for i, f in enumerate(pan)])

    base = run(1.0)
    assert stage_changed(base, pan) and np.isfinite(base).all()
    np.testing.assert_array_equal(run(2.0 ** -5), base * np.float32(2.0 ** -5))


def stage_changed(outs: np.ndarray, inputs: list[np.ndarray]) -> bool:
    return bool(np.any(outs[1:] != np.stack(inputs)[1:]))


def test_exposure_bench_scores_hdr_renders_alike_at_every_exposure():
    """`python -m mlaa_stream.bench.exposure` at a small size, one world, two exposures four stops apart: with
    auto_exposure every view scores the same at both, and the renders hold highlights over 1."""
    from mlaa_stream.yardstick import rendered as R
    ok, why = R.egl_available()
    if not ok:
        pytest.skip(why)
    from mlaa_stream.bench.exposure import run
    from mlaa_stream.bench.rendered_views import VIEWS
    lines: list[str] = []
    res = run([(192, 108)], [1.0], [1.0, 16.0], ["plaza"], log=lines.append)
    assert res[(1.0, 1.0, True)] == res[(1.0, 16.0, True)]
    assert res[(1.0, 1.0, False)] != res[(1.0, 16.0, False)]
    assert len(res[(1.0, 1.0, True)]) == 4 and any("mean" in line for line in lines)
    renderer = R.Renderer(R._context(), 64, 36, "plaza", hdr=True)
    try:
        assert renderer.input_linear(R.Camera(*VIEWS["side_road"])).max() > 1.0
    finally:
        renderer.release()
