"""The refine table (mlaa_stream/spatial/refine.py, kernels/fallback.cl refine_tile): the gate, the reference and the
fit against cases with a known answer, and the kernel with known tables. The kernel against fallback_reference bit
for bit, in every format, is tests/test_fallback.py test_kernel_matches_reference (the shipped tables)."""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.fallback import fallback_reference, long_runs
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.spatial.footprint import BUCKETS, TAPS, footprint_buckets
from mlaa_stream.spatial.refine import (REFINE_GATE, REFINE_WEIGHTS, as_refine_table, fit_refine, gate,
                                        load_refine_table, refine_features, refine_reference)

from test_fallback import regions_of, render_beside_art, shaded_polygons

INPUT_CENTRE = TAPS + 4  # the weight of the input's own colour (the 3x3 window's centre)


def input_table() -> np.ndarray:
    """Every bucket: the input's own colour (mid's colour minus itself plus the input minus mid)."""
    t = np.zeros((BUCKETS, REFINE_WEIGHTS), np.float32)
    t[:, INPUT_CENTRE] = 1.0
    return t


@pytest.mark.parametrize("dtype,pmax", [(np.uint8, 255), (np.uint16, 65535), (np.float32, 1.0)])
def test_gate_threshold(dtype, pmax):
    """A step of REFINE_GATE of full scale opens the gate on both sides of it (and only there); one level less (a
    hundredth of the gate for float frames) does not."""
    need = np.ceil(REFINE_GATE * pmax) if dtype != np.float32 else REFINE_GATE
    less = need - 1 if dtype != np.float32 else REFINE_GATE * 0.99
    for step, opens in ((need, True), (less, False)):
        img = np.full((6, 8, 3), 0.1 * pmax, np.float64)
        img[:, 4:, 1] += step
        got = gate(img.astype(dtype), pmax)
        assert got[:, 3:5].all() == opens and not got[:, :3].any() and not got[:, 5:].any()


def test_reference_known_tables():
    """Zero weights keep mid's colour; the input-centre table gives the input clamped to mid's 3x3 range."""
    rng = np.random.default_rng(3)
    inp = rng.uniform(0.05, 0.95, (12, 14, 3)).astype(np.float32)
    mid = (0.5 * inp + 0.25).astype(np.float32)
    changed = rng.random((12, 14)) < 0.5
    zero = refine_reference(inp, mid, changed, np.zeros((BUCKETS, REFINE_WEIGHTS), np.float32))
    np.testing.assert_array_equal(zero, mid)
    got = refine_reference(inp, mid, changed, input_table())
    pad = np.pad(mid, ((1, 1), (1, 1), (0, 0)), mode="edge")
    wins = np.stack([pad[dy:dy + 12, dx:dx + 14] for dy in range(3) for dx in range(3)])
    np.testing.assert_allclose(got, np.clip(inp, wins.min(0), wins.max(0)), rtol=0, atol=1e-6)
    assert np.any(got != mid) and np.any(got != inp)


def test_fit_recovers_a_known_filter():
    """Targets made by a known per-bucket filter of mid's window and the input's are fitted back."""
    rng = np.random.default_rng(7)
    truth_table = (rng.normal(0, 0.05, (BUCKETS, REFINE_WEIGHTS))).astype(np.float32)
    truth_table[:, TAPS // 2] = 0  # mid's centre tap: its feature is always 0, its weight has no effect
    frames = []
    for _ in range(6):
        inp = rng.uniform(0, 1, (40, 48, 3)).astype(np.float32)
        mid = (0.7 * inp + 0.3 * rng.uniform(0, 1, (40, 48, 3))).astype(np.float32)
        changed = rng.random((40, 48)) < 0.5
        feats = refine_features(inp, mid)
        w = truth_table[footprint_buckets(mid, changed, weber_squared=False)]
        truth = mid + np.einsum("hwcf,hwf->hwc", feats, w)
        frames.append((inp, mid, changed, truth, np.ones((40, 48), bool)))
    table = fit_refine(frames, ridge=1e-9, min_samples=50)
    counts = np.bincount(np.concatenate([footprint_buckets(m, c, weber_squared=False).ravel()
                                         for _, m, c, _, _ in frames]), minlength=BUCKETS)
    seen = np.flatnonzero(counts >= 200)  # pixels (3 channel samples each): enough for 34 weights
    assert len(seen) > 10
    np.testing.assert_allclose(table[seen], truth_table[seen], atol=2e-3)


def test_table_checked_and_shipped():
    t = load_refine_table()
    assert t.shape == (BUCKETS, REFINE_WEIGHTS) and t.dtype == np.float32 and np.all(np.isfinite(t))
    assert np.any(t != 0)
    with pytest.raises(ValueError, match="refine table"):
        as_refine_table(np.zeros((BUCKETS, REFINE_WEIGHTS - 1)))
    with pytest.raises(ValueError, match="refine_table"):
        Filter(refine_table="learned")


def test_kernel_with_known_tables():
    """Through the device: zero weights give the output without a refine table; the input-centre table puts every
    gated render-region pixel (not on a straight run the chain changed) at its input colour clamped to the first
    stage's 3x3 range (within one level of rounding) and leaves every other pixel as the first stage made it."""
    frame = shaded_polygons(5, 96, 128)
    regions = regions_of(frame)
    assert regions.mean() > 0.9
    with Filter(refine_table=None) as n, Filter(refine_table=np.zeros((BUCKETS, REFINE_WEIGHTS))) as z, \
            Filter(refine_table=input_table()) as t:
        mid, zero, got = n.process(frame), z.process(frame), t.process(frame)
    assert np.abs(zero.astype(int) - mid).max() <= 1  # decode / encode round trip of the kept colour
    with Filter(fallback="off") as m:
        passes = m.intermediates(frame)
    runs = long_runs(passes["edges"], passes["hdist"], passes["vdist"]) & np.any(mid != frame, -1)
    take = regions & ~runs & gate(frame, 255.0)
    assert 0.05 < take.mean() < 0.9
    pad = np.pad(mid, ((1, 1), (1, 1), (0, 0)), mode="edge")
    wins = np.stack([pad[dy:dy + 96, dx:dx + 128] for dy in range(3) for dx in range(3)]).astype(int)
    lin = lambda a: srgb_to_linear(a / 255.0)
    want = 255 * linear_to_srgb(np.clip(lin(frame.astype(float)), lin(wins.min(0)), lin(wins.max(0))))
    assert np.all(np.abs(got - want).max(-1)[take] <= 1.0)
    np.testing.assert_array_equal(got[~take], mid[~take])


def test_shipped_table_moves_the_bench_case():
    """fallback_reference with and without the shipped refine table differ on the kernel test's frame (so that test
    covers the refine kernel), only inside render regions."""
    frame = render_beside_art(12)
    with Filter(fallback="off") as g:
        p = g.intermediates(frame)
    with_r = fallback_reference(frame, p["out"], p["edges"], p["hdist"], p["vdist"])
    without = fallback_reference(frame, p["out"], p["edges"], p["hdist"], p["vdist"], refine=None)
    moved = np.any(with_r != without, -1)
    assert moved.sum() > 20 and not moved[~regions_of(frame)].any()
