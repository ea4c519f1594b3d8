"""The footprint table (mlaa_stream/spatial/footprint.py, kernels/fallback.cl footprint_tile): buckets and fit
against cases with a known answer, and the kernel with known tables. The kernel against fallback_reference bit
for bit, in every format, is tests/test_fallback.py test_kernel_matches_reference."""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.fallback import FALLBACK_KEEP_RUN, long_runs
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.spatial.footprint import (BUCKETS, CENTRE_TAP, COHERENCES, STRENGTHS, TABLE_RADIUS, WEIGHTS,
                                           as_table, fit_table, footprint_buckets, footprint_reference,
                                           identity_table, load_table)

from test_fallback import regions_of, shaded_polygons


def parts(bucket: np.ndarray) -> tuple[np.ndarray, ...]:
    """(octant, strength band, coherence band, changed) of bucket ids."""
    changed = bucket % 2
    rest = bucket // 2
    return rest // (STRENGTHS * COHERENCES), (rest // COHERENCES) % STRENGTHS, rest % COHERENCES, changed


def ramp(angle_deg: float, slope: float, size: int = 16) -> np.ndarray:
    """Linear RGB (grey) rising by `slope` per pixel along direction `angle_deg`."""
    yy, xx = np.mgrid[0:size, 0:size].astype(np.float32)
    t = np.radians(angle_deg)
    y = 0.3 + slope * (np.cos(t) * xx + np.sin(t) * yy)
    return np.repeat(y[..., None], 3, -1).astype(np.float32)


def tent_table() -> np.ndarray:
    """Every bucket: the 3x3 tent average of the input (1 2 1 x 1 2 1 / 16) inside the 5x5 window."""
    n = 2 * TABLE_RADIUS + 1
    w = np.zeros((n, n), np.float32)
    w[TABLE_RADIUS - 1:TABLE_RADIUS + 2, TABLE_RADIUS - 1:TABLE_RADIUS + 2] = np.outer([1, 2, 1], [1, 2, 1]) / 16
    t = np.zeros((BUCKETS, WEIGHTS), np.float32)
    t[:, :n * n] = w.reshape(-1)
    return t


@pytest.mark.parametrize("angle", [10, 35, 55, 80, 100, 125, 145, 170])
def test_the_octant_is_the_gradients_orientation(angle):
    """Known answer: a linear ramp's gradient at `angle` degrees (x right, y down) falls in orientation bin
    angle // 22.5 (bins of pi / 8 over [0, pi)); interior pixels only (the clamped border flattens the ramp)."""
    lin = ramp(angle, 0.03)
    b = footprint_buckets(lin, np.zeros(lin.shape[:2], bool))[4:-4, 4:-4]
    assert np.all(parts(b)[0] == int(angle // 22.5))


@pytest.mark.parametrize("gain", [1.0, 0.2])
@pytest.mark.parametrize("slope,band", [(0.0, 0), (0.03, 0), (0.1, 1), (0.3, 2)])
def test_strength_bands(slope, band, gain):
    """Known answer: a ramp's sqrt(l1) is its slope and its 5x5 mean the centre's luma (0.5): slope / s, s = (0.5 +
    STRENGTH_FLOOR) / STRENGTH_REF, under 0.02, 0.02-0.08, over 0.08 are bands 0, 1, 2 -- and the same ramp five
    times darker (the same contrast, a dim render) falls in the same band."""
    lin = gain * (ramp(30, slope) - 0.3 + 0.5 - slope * (np.cos(np.radians(30)) + np.sin(np.radians(30))) * 8)
    assert abs(lin[8, 8, 0] - 0.5 * gain) < 1e-5
    b = footprint_buckets(lin.astype(np.float32), np.zeros(lin.shape[:2], bool))
    assert parts(b)[1][8, 8] == band


def test_coherence_bands_and_the_changed_flag():
    """Known answer: a ramp has one direction (l2 = 0: top band); a bowl (luma x^2 + y^2, centred on a pixel)
    has l1 = l2 at its centre (bottom band); the changed flag is the lowest bit."""
    lin = ramp(45, 0.05)
    changed = np.zeros(lin.shape[:2], bool)
    changed[8, 8] = True
    b = footprint_buckets(lin, changed)
    assert np.all(parts(b)[2][4:-4, 4:-4] == COHERENCES - 1)
    assert parts(b)[3][8, 8] == 1 and parts(b)[3].sum() == 1
    yy, xx = np.mgrid[-8:9, -8:9].astype(np.float32)
    bowl = np.repeat((0.2 + 0.004 * (xx * xx + yy * yy))[..., None], 3, -1).astype(np.float32)
    assert parts(footprint_buckets(bowl, np.zeros(bowl.shape[:2], bool)))[2][8, 8] == 0


def test_reference_formula_and_clamp():
    """Known answers: the identity table gives the chain's colour; the tent table gives the tent average (a mean
    of the 3x3 window, never clamped); a table that doubles the step to a neighbour is clamped to the 3x3
    window's range; one-colour windows the chain left are kept, with any table."""
    rng = np.random.default_rng(4)
    lin = rng.uniform(0.05, 0.9, (12, 14, 3)).astype(np.float32)
    chain = np.clip(lin + rng.normal(0, 0.05, lin.shape), 0, 1).astype(np.float32)
    changed = rng.uniform(size=lin.shape[:2]) < 0.3
    new, kept = footprint_reference(lin, chain, changed, identity_table())
    np.testing.assert_allclose(new, chain, rtol=0, atol=1e-6)
    assert not kept.any()
    new, _ = footprint_reference(lin, chain, changed, tent_table())
    pad = np.pad(lin.astype(np.float64), ((1, 1), (1, 1), (0, 0)), mode="edge")
    tent = sum((2 - dx * dx) * (2 - dy * dy) * pad[1 + dy:13 + dy, 1 + dx:15 + dx]
               for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 16
    np.testing.assert_allclose(new, tent, rtol=0, atol=1e-6)
    wild = np.zeros((BUCKETS, WEIGHTS), np.float32)
    wild[:, TABLE_RADIUS * (2 * TABLE_RADIUS + 1) + TABLE_RADIUS + 1] = 4.0  # 4x the step to the right neighbour
    new, _ = footprint_reference(lin, chain, changed, wild)
    lo = np.minimum(chain, np.min([np.roll(np.roll(np.pad(lin, ((1, 1), (1, 1), (0, 0)), mode="edge"), -dy, 0),
                                               -dx, 1)[1:13, 1:15] for dy in (-1, 0, 1) for dx in (-1, 0, 1)], 0))
    assert np.all(new >= lo - 1e-7) and np.any(new == lo)
    flat = np.full((9, 9, 3), 0.4, np.float32)
    new, kept = footprint_reference(flat, flat, np.zeros((9, 9), bool), wild)
    assert kept.all()


def test_fit_recovers_a_known_filter():
    """Known answer: when the truth is the tent average of the input, every bucket with enough samples fits the
    tent's weights (ridge 0: exact up to float rounding)."""
    rng = np.random.default_rng(9)
    samples = []
    for _ in range(3):
        lin = rng.uniform(0.0, 1.0, (40, 48, 3)).astype(np.float32)
        chain = np.clip(lin + rng.normal(0, 0.1, lin.shape), 0, 1).astype(np.float32)
        changed = rng.uniform(size=lin.shape[:2]) < 0.5
        truth, _ = footprint_reference(lin, chain, changed, tent_table())
        samples.append((lin, chain, changed, truth, np.ones(lin.shape[:2], bool)))
    table = fit_table(samples, ridge=0.0, min_samples=400)
    fitted = ~np.all(table == identity_table(), 1)
    assert fitted.sum() >= 10
    taps = np.arange(WEIGHTS) != CENTRE_TAP  # the centre tap's feature is always 0: its weight is free
    np.testing.assert_allclose(table[fitted][:, taps], tent_table()[fitted][:, taps], rtol=0, atol=2e-4)


def test_table_checked_and_shipped():
    t = load_table()
    assert t.shape == (BUCKETS, WEIGHTS) and t.dtype == np.float32 and np.all(np.isfinite(t))
    assert not np.array_equal(t, identity_table())
    with pytest.raises(ValueError, match="footprint table"):
        as_table(np.zeros((BUCKETS, WEIGHTS - 1)))
    bad = identity_table()
    bad[3, 4] = np.nan
    with pytest.raises(ValueError, match="footprint table"):
        Filter(footprint_table=bad)
    with pytest.raises(ValueError, match="footprint_table"):
        Filter(footprint_table="learned")


def test_kernel_with_known_tables():
    """Known answers through the device: with the identity table a render-like frame comes out as without a
    table; with the tent table every render-region pixel is the tent average of its 3x3 input window in linear
    light (within one level of rounding), but for pixels the chain changed on straight edge runs (REGION_KEEP_RUN
    px or longer: a shallow edge across a flat band), which keep the chain's colour."""
    frame = shaded_polygons(5, 96, 128)
    yy, xx = np.mgrid[0:96, 0:128] + 0.5
    band = (yy > 40) & (yy < 60)
    frame[band] = (200, 190, 170)
    frame[band & (yy > 46 + xx / 48)] = (60, 50, 40)  # runs of 48 px
    regions = regions_of(frame)
    assert regions.mean() > 0.9
    with Filter(footprint_table=None) as n, Filter(footprint_table=identity_table(), refine_table=None) as i, \
            Filter(footprint_table=tent_table(), refine_table=None) as t, Filter() as d:
        chain, ident, tent_out, default = n.process(frame), i.process(frame), t.process(frame), d.process(frame)
    assert np.abs(ident.astype(int) - chain).max() <= 1  # decode / encode round trip of the kept colour
    lin = srgb_to_linear(frame.astype(np.float64) / 255)
    pad = np.pad(lin, ((1, 1), (1, 1), (0, 0)), mode="edge")
    h, w = frame.shape[:2]
    tent = sum((2 - dx * dx) * (2 - dy * dy) * pad[1 + dy:1 + dy + h, 1 + dx:1 + dx + w]
               for dy in (-1, 0, 1) for dx in (-1, 0, 1)) / 16
    want = 255 * linear_to_srgb(tent)
    with Filter(fallback="off") as m:
        passes = m.intermediates(frame)
    kept = long_runs(passes["edges"], passes["hdist"], passes["vdist"]) & np.any(chain != frame, -1)
    assert 0 < kept[regions].mean() < 0.2
    shorter = long_runs(passes["edges"], passes["hdist"], passes["vdist"], FALLBACK_KEEP_RUN) & ~kept
    assert (shorter & regions & np.any(chain != frame, -1)).sum() > 20  # runs of 16-31 px take the table (below)
    np.testing.assert_array_equal(tent_out[kept], chain[kept])
    assert np.all(np.abs(tent_out - want).max(-1)[regions & ~kept] <= 1.0)
    assert np.array_equal(tent_out[~regions], chain[~regions])
    assert np.any(default != chain) and np.any(default != tent_out)
