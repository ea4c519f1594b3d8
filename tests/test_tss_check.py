"""mlaa_stream.bench.tss_check's motion helpers (the benchmark itself is run by hand, never as a unit test)."""
from __future__ import annotations

import cv2
import numpy as np

from mlaa_stream.bench.tss_check import homography_maps


def test_homography_maps_recover_a_known_projective_motion():
    """Frames of a smooth random texture seen through known homographies A_t (frame t at x shows the texture at
    A_t x): the map from frame t to frame u is A_u^-1 A_t, and homography_maps finds it from the 8-bit frames
    within a median 0.04 px and at most 0.15 px (the corners, where the projective terms act) away from the
    borders (ECC on grey blurred by 1 px; seeded texture); a single translation would be off by over 0.3 px."""
    rng = np.random.default_rng(7)
    h, w = 150, 200
    texture = cv2.resize(rng.uniform(0, 255, (40, 52, 3)).astype(np.float32), (w + 80, h + 80),
                         interpolation=cv2.INTER_CUBIC)

    def a(t):
        return np.array([[1.0 + 0.002 * t, 0.001 * t, 40.0 + 0.45 * t],
                         [-0.001 * t, 1.0, 40.0 + 0.12 * t],
                         [2e-5 * t, 0.0, 1.0]])

    frames = np.stack([np.clip(cv2.warpPerspective(texture, a(t), (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP),
                               0, 255).astype(np.uint8) for t in range(4)])
    maps = homography_maps(frames)
    assert sorted(maps) == [(1, 0), (2, 0), (2, 1), (3, 0), (3, 1), (3, 2)]
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float64)
    for (t, u), found in maps.items():
        m = np.linalg.inv(a(u)) @ a(t)
        p = np.stack([xs, ys, np.ones_like(xs)], -1) @ m.T
        true = np.stack([p[..., 0] / p[..., 2] - xs, p[..., 1] / p[..., 2] - ys], -1)
        err = np.hypot(*(found - true).transpose(2, 0, 1))[10:-10, 10:-10]
        assert found.shape == (h, w, 2) and found.dtype == np.float32
        assert np.median(err) < 0.04 and err.max() < 0.15, ((t, u), float(np.median(err)), float(err.max()))
        # one translation could not do it: the true map varies over the frame by far more
        spread = np.hypot(*(true - true.reshape(-1, 2).mean(0)).transpose(2, 0, 1))[10:-10, 10:-10]
        if t - u >= 2:
            assert spread.max() > 0.3, ((t, u), float(spread.max()))
        assert np.abs(true).max() > 0.4   # the frames do move


def test_linear_light_frames_for_the_hdr_rows():
    """--hdr's frames: 8-bit sRGB decoded by IEC 61966-2-1 and scaled (0 -> 0, 255 -> scale, 188 -> ~0.5 scale,
    a code on the linear toe -> code / 12.92 / 255 scale), float32."""
    from mlaa_stream.bench.tss_check import linear_light
    out = linear_light(np.array([[0, 255, 188, 10]], np.uint8), 4.0)
    assert out.dtype == np.float32
    assert out[0, 0] == 0.0 and abs(out[0, 1] - 4.0) < 1e-6
    assert abs(out[0, 2] - 4.0 * 0.5029) < 1e-3 and abs(out[0, 3] - 4.0 * 10 / 255 / 12.92) < 1e-6


def test_dense_samples_is_a_tss_option():
    """make_stage passes dense_samples to TSS (alone or before the blend) and refuses it for the blend alone."""
    import pytest
    from mlaa_stream.device.context import default_context
    from mlaa_stream.temporal.methods import make_stage
    ctx = default_context(None)
    assert make_stage("tss", ctx, bgr=False, dense_samples=True).motion.dense_samples
    assert make_stage("auto", ctx, bgr=False, dense_samples=True).tss.motion.dense_samples
    assert not make_stage("tss", ctx, bgr=False).motion.dense_samples
    with pytest.raises(ValueError, match="dense_samples"):
        make_stage("blend", ctx, bgr=False, dense_samples=True)
