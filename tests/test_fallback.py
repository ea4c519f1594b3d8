"""The FXAA fallback pass (kernels/fallback.cl, mlaa_stream/spatial/fallback.py) against its numpy reference
and against cases with a known answer."""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.fallback import FALLBACK_MIX, FALLBACK_TILE, FALLBACK_WEIGHT, fallback_reference
from mlaa_stream.spatial.fxaa import fxaa_mix_reference
from mlaa_stream.spatial.filter import Filter


def textured_aliased(seed: int, h: int = 72, w: int = 96) -> np.ndarray:
    """A smooth random texture (lit surfaces) crossed by hard-edged 1-spp polygons with textured fills:
    the MLAA passes change many pixels, so the fallback's gates open."""
    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:h, 0:w].astype(np.float64)
    img = np.zeros((h, w, 3))
    for c in range(3):
        coarse = rng.uniform(0.1, 0.9, (h // 3 + 2, w // 3 + 2))  # texels of 3 px: short texture edges
        img[..., c] = np.kron(coarse, np.ones((3, 3)))[:h, :w]
        img[..., c] += 0.08 * np.sin(xx * rng.uniform(0.3, 1.2) + yy * rng.uniform(0.2, 0.9) + c)
    for _ in range(6):  # half-planes and wedges sampled at pixel centres: jaggies
        a, b = rng.uniform(-1, 1, 2)
        d = rng.uniform(0.2, 0.8) * (abs(a) * w + abs(b) * h)
        inside = a * (xx + 0.5) + b * (yy + 0.5) > d - (abs(a) * w + abs(b) * h) / 2
        tint = rng.uniform(0, 1, 3)
        img[inside] = 0.6 * tint + 0.4 * img[inside] * rng.uniform(0.5, 1.0)
    return np.clip(np.rint(img * 255), 0, 255).astype(np.uint8)


def _as(img8: np.ndarray, dtype, channels: int) -> np.ndarray:
    x = img8 if channels == 3 else (img8[..., :1] if channels == 1 else
                                    np.concatenate([img8, np.full(img8.shape[:2] + (1,), 200, np.uint8)], -1))
    if channels == 1:
        x = x[..., 0]
    if dtype == np.uint16:
        return x.astype(np.uint16) * 257
    if dtype == np.float32:
        return x.astype(np.float32) / 255.0
    return x.copy()


@pytest.mark.parametrize("mode", ["auto", "everywhere"])
@pytest.mark.parametrize("dtype,channels,bgr", [(np.uint8, 3, False), (np.uint8, 3, True), (np.uint8, 4, False),
                                                (np.uint8, 1, False), (np.uint16, 3, False), (np.float32, 3, False)])
def test_kernel_matches_reference(mode, dtype, channels, bgr):
    """Exact: the pass is FXAA's kernel code (bit-identical to fxaa_reference, test_fxaa) behind integer
    gates, so the output must equal fallback_reference of the MLAA passes' output to the last bit
    (float32: within 1e-6 of full scale)."""
    frame = _as(textured_aliased(12), dtype, channels)
    with Filter(bgr=bgr, fallback=mode) as f, Filter(bgr=bgr, fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    mlaa = passes["out"]
    want = fallback_reference(frame, mlaa, passes["edges"], bgr=bgr, everywhere=mode == "everywhere")
    changed = np.any(np.atleast_3d(got) != np.atleast_3d(mlaa), -1)
    if channels > 1 or mode == "everywhere":  # (grey: channel 0 alone gives MLAA too few jaggies to open the gates)
        assert changed.sum() > 20, "the case must exercise the pass"
    if dtype == np.float32:
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-6)
    else:
        np.testing.assert_array_equal(got, want)


def test_only_edge_pixels_change_and_mlaa_blends_move_half_way():
    """Known answer: the pass changes only pixels that border an MLAA edge; a pixel the MLAA passes left takes
    FALLBACK_WEIGHT of FXAA's colour from the source's, one they changed FALLBACK_MIX of the way from theirs,
    in linear light (both within one level of rounding of the formula applied to FXAA 3.11's colour)."""
    frame = textured_aliased(12)
    with Filter() as f, Filter(fallback="off") as g:
        got, passes = f.process(frame), g.intermediates(frame)
    mlaa, e = passes["out"], passes["edges"]
    borders = e != 0
    borders[1:] |= (e[:-1] & 1) > 0
    borders[:, 1:] |= (e[:, :-1] & 2) > 0
    by_mlaa = np.any(mlaa != frame, -1)
    by_fallback = np.any(got != mlaa, -1)
    assert (by_fallback & by_mlaa).sum() > 20 and (by_fallback & ~by_mlaa).sum() > 20
    assert not np.any(by_fallback & ~borders)
    _, fx = fxaa_mix_reference(frame)  # linear RGB
    for share, start, where in ((FALLBACK_WEIGHT, frame, ~by_mlaa), (FALLBACK_MIX, mlaa, by_mlaa)):
        m = srgb_to_linear(start.astype(np.float64) / 255)
        want = 255 * linear_to_srgb(m + share * (fx - m))
        sel = by_fallback & where
        assert np.abs(got[sel] - want[sel]).max() <= 1.0


def test_flat_colour_art_is_left_to_mlaa():
    """Known answer: two-colour aliased shapes (text, UI, vector art) have at most 3 colours in any 3x3
    window, so the gated fallback changes nothing there, however many jaggies MLAA blends."""
    rng = np.random.default_rng(11)
    h, w = 64, 96
    yy, xx = np.mgrid[0:h, 0:w] + 0.5
    img = np.full((h, w, 3), (235, 235, 230), np.uint8)
    for _ in range(5):
        cx, cy, r = rng.uniform(10, 86), rng.uniform(10, 54), rng.uniform(5, 14)
        img[(xx - cx) ** 2 + (yy - cy) ** 2 < r * r] = (30, 40, 120)
    with Filter() as f, Filter(fallback="off") as g:
        got, mlaa = f.process(img), g.process(img)
    assert np.any(mlaa != img)
    np.testing.assert_array_equal(got, mlaa)


def test_without_aliasing_evidence_nothing_changes():
    """Known answer: a smooth textured frame with no hard edges gives MLAA nothing to blend, so no tile has
    evidence and the gated fallback leaves the frame exactly as it was (photographs stay untouched)."""
    rng = np.random.default_rng(5)
    h, w = 48, 64
    base = rng.uniform(40, 210, (h // 8 + 2, w // 8 + 2, 3))
    yy, xx = np.mgrid[0:h, 0:w] / 8.0
    y0, x0 = np.floor(yy).astype(int), np.floor(xx).astype(int)
    ty, tx = (yy - y0)[..., None], (xx - x0)[..., None]
    img = (base[y0, x0] * (1 - ty) * (1 - tx) + base[y0 + 1, x0] * ty * (1 - tx)
           + base[y0, x0 + 1] * (1 - ty) * tx + base[y0 + 1, x0 + 1] * ty * tx)
    img = np.clip(np.rint(img + rng.normal(0, 1.5, img.shape)), 0, 255).astype(np.uint8)
    with Filter() as f:
        got = f.process(img)
    np.testing.assert_array_equal(got, img)


def test_everywhere_reaches_beyond_the_gates():
    """fallback="everywhere" (the `rendered` preset) touches a superset of what "auto" touches."""
    frame = textured_aliased(7, 96, 128)
    with Filter(fallback="off") as g, Filter() as a, Filter(preset="rendered") as e:
        mlaa, auto, every = g.process(frame), a.process(frame), e.process(frame)
    by_auto, by_every = np.any(auto != mlaa, -1), np.any(every != mlaa, -1)
    assert by_every.sum() > by_auto.sum() > 0
    np.testing.assert_array_equal(every[by_auto], auto[by_auto])


def test_option_checked():
    with pytest.raises(ValueError, match="fallback"):
        Filter(fallback="sometimes")
    assert Filter(fallback=False).fallback == "off" and Filter(fallback=True).fallback == "auto"
    assert Filter(preset="fast").fallback == "off"
    assert FALLBACK_TILE == 8
