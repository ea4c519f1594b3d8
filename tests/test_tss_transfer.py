"""The temporal stages on HDR video's codes (device/transfer.py): TSS averages the light PQ / HLG codes stand for, as
the spatial Filter(transfer=...) mixes it; the blend keeps blending the codes; without a transfer every output is as
before (tests/test_tss.py, tests/test_temporal.py)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from mlaa_stream.device.formats import frame_format, with_transfer
from mlaa_stream.device.transfer import pq_to_linear
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.temporal.methods import make_stage
from mlaa_stream.temporal.stage import decode_table
from mlaa_stream.temporal.resolve import (EPS, GRID, LINEAR_RANGE, MIN_CELLS, ONE, OVER, encode_table, level_table,
                                          tss_frame_reference)
from mlaa_stream.temporal.tss import TSSStage
from mlaa_stream.yardstick import metrics as M
from test_transfer import coded
from test_tss import _random_ring, _run_kernel


@pytest.fixture(scope="module")
def stage_parts():
    from mlaa_stream.device.context import default_context
    return default_context(None)


@pytest.mark.parametrize("dense", [False, True])
def test_tss_kernel_matches_reference_on_pq_codes(stage_parts, dense):
    """16-bit PQ codes (light up to 49 x reference white): both resolves bit-identical to the reference; the ring
    holds the codes' light over [0, LINEAR_RANGE], so a pixel whose 3x3 input box or spatial pixel codes more light
    (PQ over 3250 cd/m2) keeps the spatial pixel bit for bit, and the rest are mixed and coded back by the transfer."""
    rng = np.random.default_rng(36 + dense)
    h, w, fs, k = 37, 53, 2 if dense else 1, 9
    cur, spatial, ring = _random_ring(rng, h, w, 3, np.uint16, k, dense, fs)
    stage = TSSStage(frames=k + 1, bgr=False, context=stage_parts, dense_samples=dense, transfer="pq")
    out, cells = _run_kernel(stage, cur, spatial, ring, False, fs)
    ref, rcells = tss_frame_reference(spatial, cur, ring, False, fs, GRID, EPS, MIN_CELLS,
                                      stage.field_full_cells if dense else stage.full_cells, transfer="pq")
    assert np.array_equal(cells, rcells) and cells.max() >= 2
    assert np.array_equal(out, ref)
    top = pq_to_linear(np.arange(65536) / 65535) > LINEAR_RANGE   # codes over the ring's range
    over = cv2.dilate(top[cur].any(-1).astype(np.uint8), np.ones((3, 3), np.uint8),
                      borderType=cv2.BORDER_REPLICATE).astype(bool) | top[spatial].any(-1)
    assert 0.2 < over.mean() < 0.9
    assert np.array_equal(out[over], spatial[over])
    assert (out != spatial).any(-1)[~over].mean() > 0.05
    # the sRGB tables' resolve of the same codes is another one
    plain, _ = tss_frame_reference(spatial, cur, ring, False, fs, GRID, EPS, MIN_CELLS,
                                   stage.field_full_cells if dense else stage.full_cells)
    assert not np.array_equal(plain, ref)


def test_tss_tables_hold_the_light_of_the_codes():
    """ltab: a PQ code's light / LINEAR_RANGE in 16 bits (OVER above the range, in-range ones below it); etab codes
    that light back: a code through both comes back within one 8-bit level (257 codes) from 0.2 cd/m2 up and within
    100 codes from 1 cd/m2 up; below 0.2 cd/m2 the ring's step (0.05 cd/m2) is coarser than that, and there the
    resolve keeps the spatial pixel where it lands within one step of it (tss.cl tss_store)."""
    fmt = with_transfer(frame_format(np.zeros((2, 2, 3), np.uint16), False), "pq")
    assert frame_format(np.zeros((2, 2, 3), np.float32), False) == with_transfer(
        frame_format(np.zeros((2, 2, 3), np.float32), False), "pq")   # float frames hold no codes of a transfer
    ltab, etab = level_table(fmt), encode_table(fmt)
    light = decode_table(fmt)   # the decode table the TSS ring reads: the transfer's
    assert np.array_equal(ltab == OVER, light > LINEAR_RANGE) and ONE - 16 < ltab[light <= LINEAR_RANGE].max() < ONE
    back = np.abs(etab[ltab].astype(np.int64) - np.arange(65536))
    inside = light <= LINEAR_RANGE
    assert back[inside & (light * 203 >= 0.2)].max() <= 257 and back[inside & (light * 203 >= 1)].max() <= 100
    assert back[inside].max() > 257
    assert np.all(np.diff(ltab[inside].astype(np.int64)) >= 0) and np.all(np.diff(etab.astype(np.int64)) >= 0)


def test_dark_codes_within_a_ring_step_keep_the_spatial_pixel(stage_parts):
    """Near black (PQ under 0.2 cd/m2) a resolve that lands within one ring step of the spatial pixel's light keeps
    the spatial pixel's codes (the ring's rounding alone would move them by up to 2000 codes): the device as the
    reference."""
    h, w = 16, 37
    rng = np.random.default_rng(3)
    cur = rng.integers(1500, 3000, (h, w, 3)).astype(np.uint16)       # 0.01-0.05 cd/m2: one or two ring steps
    ring = [(np.roll(cur, s, (0, 1)), (0.25 * s, 0.5 * s), None) for s in (1, 2, 3)] + [(cur, (0.0, 0.0), None)]
    ref, rcells = tss_frame_reference(cur, cur, ring, False, transfer="pq")
    assert rcells.mean() >= MIN_CELLS and np.array_equal(ref, cur)
    stage = TSSStage(frames=len(ring), bgr=False, context=stage_parts, transfer="pq")
    out, cells = _run_kernel(stage, cur, cur, ring, False, 1)
    assert np.array_equal(cells, rcells) and np.array_equal(out, cur)


def _lamp_pan(n: int, h: int, w: int, samples: int, speed: tuple[float, float] = (0.3, 0.11)) -> np.ndarray:
    """(n, h, w, 3) linear light: a bright (1000 cd/m2) region on a dark (1 cd/m2) ground, bounded by two half-planes'
    edges (slopes 0.35 and -3: one edge direction alone leaves the motion along it unknown, and TSS keeps the spatial
    output there) panning `speed` px per frame; the box mean of samples x samples point samples per pixel."""
    out = []
    for t in range(n):
        y, x = (np.mgrid[0:h * samples, 0:w * samples] + 0.5) / samples
        x, y = x - speed[0] * t, y - speed[1] * t
        lit = (y > 0.35 * x + 9.3) & (x > 20.2 - y / 3.0)
        img = np.where(lit, 1000.0 / 203, 1.0 / 203).reshape(h, samples, w, samples).mean(axis=(1, 3))
        out.append(np.repeat(img[..., None], 3, axis=2))
    return np.stack(out)


def test_tss_pan_of_a_lamp_edge_converges_to_the_light():
    """A sub-pixel pan (0.3 px per frame, 8 frames) of a lamp's edges on a dark ground as 1-spp PQ codes, against an
    8x8 box truth in light scored on the codes: TSS with the transfer (after Filter(transfer="pq")) takes samples and
    ends with less error than the same stage mixing the codes as sRGB, whose rims are too dark."""
    n, h, w = 8, 64, 96
    inputs, truths = coded(_lamp_pan(n, h, w, 1), "pq"), coded(_lamp_pan(n, h, w, 8), "pq")
    with Filter(transfer="pq", bgr=False) as filt:
        spatial = [filt.process(f) for f in inputs]
        outs = {}
        for transfer in ("pq", None):
            with make_stage("tss", filt.context, bgr=False, frames=n, transfer=transfer) as stage:
                outs[transfer] = np.stack([stage(f, s, i) for i, (f, s) in enumerate(zip(inputs, spatial))])
                assert sum(r["model"] == "global" for r in stage.stats[1:]) >= 5
    late = slice(4, n)
    err = {t: M.mse(o[late], truths[late]) for t, o in outs.items()}
    sp = M.mse(np.stack(spatial)[late], truths[late])
    changed = (outs["pq"][late] != np.stack(spatial)[late]).any(-1).mean()
    assert changed > 0.01, changed
    assert err["pq"] < err[None] and err["pq"] < sp, (err, sp)


def test_every_way_of_making_a_stage_takes_the_transfer():
    """make_stage's methods, TemporalSpec.stage (the command line, the cluster: from the Filter's transfer) and the
    Antialiaser hand the transfer to every TSS stage they make; a transfer with linear input is refused."""
    from mlaa_stream import Antialiaser
    from mlaa_stream.cluster.temporal import TemporalSpec
    with Filter(transfer="hlg", bgr=False) as filt:
        for method in ("auto", "tss", "tss+blend"):   # the blend keeps blending the codes: it has no transfer
            stage = TemporalSpec(method).stage(filt)
            assert (stage if method == "tss" else stage.tss).transfer == "hlg", method
            assert not hasattr(getattr(stage, "blend", None), "transfer")
            stage.close()
        with make_stage("tss", filt.context, bgr=False) as plain:
            assert plain.transfer is None
    with Antialiaser(transfer="pq", temporal="tss") as aa:
        assert aa.temporal.transfer == "pq"
    with pytest.raises(ValueError, match="transfer and linear_input exclude each other"):
        TSSStage(transfer="pq", linear_input=True, backend="numpy")
