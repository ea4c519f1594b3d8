"""kernels/fxaa.cl against fxaa_reference (seeded random frames, scene frames, every pixel format)
and against hand-computed answers.

Tolerance: integer frames within 1 level everywhere and identical on >= 99.9 % of pixels (the
kernel and the reference do the same float32 operations in the same order; a float rounding at a
.5 boundary or a fused LUT multiply-add may move one level); float frames within 1e-5.
"""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.yardstick import scenes as S
from mlaa_stream.device.colour import linear_to_srgb
from mlaa_stream.spatial.fxaa import FXAA, QUALITY_STEPS, fxaa_reference


@pytest.fixture(scope="module")
def fxaa():
    with FXAA() as f:
        yield f


def assert_close(out, ref):
    assert out.shape == ref.shape and out.dtype == ref.dtype
    if np.issubdtype(out.dtype, np.floating):
        np.testing.assert_allclose(out.astype(np.float32), ref.astype(np.float32), atol=1e-5, rtol=0)
        return
    d = np.abs(out.astype(np.int64) - ref.astype(np.int64))
    assert d.max() <= 1, f"max difference {d.max()} levels"
    assert (d == 0).mean() >= 0.999, f"only {(d == 0).mean():.5f} of samples identical"


def blocky(rng, h, w, c=3, block=3, dtype=np.uint8, hi=256):
    """Random blocks (edges of every orientation, flat areas for the early exit)."""
    small = rng.integers(0, hi, (h // block + 1, w // block + 1, c)).astype(dtype)
    img = np.kron(small, np.ones((block, block, 1), dtype))[:h, :w]
    return img


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_random_blocks_match_reference(fxaa, seed):
    rng = np.random.default_rng(seed)
    img = blocky(rng, 47, 61)
    out = fxaa.process(img)
    ref = fxaa_reference(img)
    assert (ref != img).mean() > 0.3  # the test exercises the full path, not just early exits
    assert_close(out, ref)


def test_random_noise_matches_reference(fxaa):
    img = np.random.default_rng(11).integers(0, 256, (33, 40, 3), dtype=np.uint8)
    assert_close(fxaa.process(img), fxaa_reference(img))


@pytest.mark.parametrize("name", ["text_ui", "wires", "long_edges", "checkerboard"])
def test_scene_frames_match_reference(fxaa, name):
    img = S.generate_scenes(small=True, names=[name])[0].inputs[0]
    assert_close(fxaa.process(img), fxaa_reference(img))


@pytest.mark.parametrize("kw", [{"linear": False}, {"quality": 39}, {"quality": 10},
                                {"subpix": 0.0, "edge_threshold": 0.063, "edge_threshold_min": 0.0312}])
def test_options_match_reference(kw):
    img = blocky(np.random.default_rng(4), 40, 52)
    with FXAA(**kw) as f:
        assert_close(f.process(img), fxaa_reference(img, **kw))


@pytest.mark.parametrize("dtype,shape,kw", [
    (np.uint8, (30, 41), {}),
    (np.uint8, (30, 41, 1), {}),
    (np.uint8, (30, 41, 4), {}),
    (np.uint16, (30, 41, 3), {}),
    (np.float32, (30, 41, 3), {}),
    (np.float16, (30, 41, 3), {"linear_input": True}),
    (np.float32, (30, 41), {"linear": False}),
])
def test_pixel_formats_match_reference(dtype, shape, kw):
    rng = np.random.default_rng(9)
    c = shape[2] if len(shape) == 3 else 1
    if np.issubdtype(dtype, np.floating):
        img = blocky(rng, shape[0], shape[1], c, dtype=np.float32, hi=1000).astype(np.float32) / 999
        img = img.astype(dtype)
    else:
        img = blocky(rng, shape[0], shape[1], c, dtype=dtype, hi=np.iinfo(dtype).max + 1)
    img = img.reshape(shape)
    with FXAA(**kw) as f:
        out = f.process(img)
    assert_close(out, fxaa_reference(img, **kw))
    if c == 4:
        assert np.array_equal(out[..., 3], img[..., 3])  # alpha untouched


def test_bgr_is_rgb_reversed(fxaa):
    img = blocky(np.random.default_rng(8), 36, 36)
    with FXAA(bgr=True) as f:
        out_bgr = f.process(np.ascontiguousarray(img[..., ::-1]))
    assert np.array_equal(out_bgr[..., ::-1], fxaa.process(img))


def test_flat_frame_is_unchanged(fxaa):
    img = np.full((16, 24, 3), 77, np.uint8)
    img[:, :, 2] = 200
    assert np.array_equal(fxaa.process(img), img)


@pytest.mark.parametrize("transpose", [False, True])
def test_straight_pixel_aligned_edge_known_answer(fxaa, transpose):
    # Black x < 10, white x >= 10, edge runs the whole frame. By hand (FXAA 3.11 quality):
    # pixel 9: range 1, vertical span, lumaS := lumaE = 1, pairN false; subpixA = 2*(0+0+0+1)+(0+0+1+1)
    # = 4, subpixC = |4/12 - 0| / 1 = 1/3; the search never ends (luma 0.5 along the edge) so
    # dstN = dstP and pixelOffset = 0; subpixH = ((3 - 2/3) (1/9))^2 * 0.75 = 0.75 (7/27)^2.
    # The pixel then reads 0.0504 of the way towards its white neighbour, in linear light.
    # Pixel 10 mirrors it. Everything else exits early (no local contrast).
    img = np.zeros((24, 20, 3), np.uint8)
    img[:, 10:] = 255
    if transpose:
        img = np.ascontiguousarray(img.transpose(1, 0, 2))
    out = fxaa.process(img)
    if transpose:
        out = out.transpose(1, 0, 2)
    t = 0.75 * (7 / 27) ** 2
    dark = round(float(linear_to_srgb(t)) * 255)
    light = round(float(linear_to_srgb(1 - t)) * 255)
    assert dark == 63 and light == 249
    assert np.abs(out[:, 9].astype(int) - dark).max() <= 1
    assert np.abs(out[:, 10].astype(int) - light).max() <= 1
    assert (out[:, :9] == 0).all() and (out[:, 11:] == 255).all()


def test_quality_presets_are_the_shader_tables():
    assert QUALITY_STEPS[12] == (1.0, 1.5, 2.0, 4.0, 12.0)
    assert QUALITY_STEPS[39][:6] == (1.0, 1.0, 1.0, 1.0, 1.0, 1.5)


def test_errors_name_the_problem():
    with pytest.raises(ValueError, match="quality: expected one of"):
        FXAA(quality=7)
    with pytest.raises(ValueError, match="subpix: expected a number in"):
        fxaa_reference(np.zeros((4, 4, 3), np.uint8), subpix=2.0)
    with FXAA() as f:
        with pytest.raises(ValueError, match=r"expected shape \(H, W\)"):
            f.process(np.zeros((4, 4, 2), np.uint8))


def test_submit_overlaps_and_keeps_order(fxaa):
    rng = np.random.default_rng(12)
    frames = [blocky(rng, 32, 40) for _ in range(4)]
    pending = [fxaa.submit(f) for f in frames]
    for f, p in zip(frames, pending):
        assert np.array_equal(p.result(), fxaa.process(f))


def test_each_result_call_returns_an_array_of_its_own(fxaa):
    """result() twice gave two views of one download buffer (as the Filter's PendingFrame did)."""
    frame = blocky(np.random.default_rng(13), 32, 40)
    pending = fxaa.submit(frame)
    first, second = pending.result(), pending.result()
    assert not np.shares_memory(first, second) and np.array_equal(first, second)
    want = second.copy()
    first[...] = 0
    assert np.array_equal(second, want)
