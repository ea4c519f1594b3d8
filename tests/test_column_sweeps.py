"""The column sweeps GPUs take (Context.column_sweeps: vline_distances_columns, fast_vshapes_columns), run here on
whatever device the tests use: the same line distances and L shapes as their references and as the strip sweeps
CPUs take, and the same frames out. Exact: they are integers."""
from __future__ import annotations

import numpy as np
import pyopencl as cl
import pytest

from mlaa_stream.device.context import Context
from mlaa_stream.spatial import fast as F
from mlaa_stream.spatial.fast import FAST_VCHUNK
from mlaa_stream.spatial.filter import VCHUNK, Filter
from mlaa_stream.spatial.reference import distances_reference
from mlaa_stream.yardstick.scenes import timing_frame


@pytest.fixture(scope="module")
def contexts():
    """(strip sweeps, column sweeps) on the tests' device."""
    strips, columns = Context(), Context()
    strips.column_sweeps, columns.column_sweeps = False, True
    return strips, columns


def columns_frame(seed: int, h: int, w: int) -> np.ndarray:
    """Vertical bars of random colours and heights (lines far longer than a chunk), cut by horizontal bars whose
    edges fall on the chunks' first and last rows, over random blocks: every way a line meets a chunk border."""
    rng = np.random.default_rng(seed)
    img = np.empty((h, w, 3), np.uint8)
    img[:] = rng.integers(0, 256, 3)
    for _ in range(8):
        y0, x0 = rng.integers(0, h - 4), rng.integers(0, w - 4)
        img[y0:y0 + rng.integers(2, 12), x0:x0 + rng.integers(2, 12)] = rng.integers(0, 256, 3)
    for _ in range(w // 6):
        x, y0 = rng.integers(0, w - 2), rng.integers(0, h // 2)
        img[y0:rng.integers(y0 + 1, h + 1), x:x + rng.integers(1, 4)] = rng.integers(0, 256, 3)
    for chunk in (VCHUNK, FAST_VCHUNK):
        for y in range(chunk, h, chunk):   # bars over rows y - 1 / y: bottom edges across the chunk borders
            if rng.random() < 0.6:
                x0 = rng.integers(0, w - 8)
                img[y - int(rng.integers(0, 2)):y + int(rng.integers(1, 3)), x0:x0 + rng.integers(2, 30)] = \
                    rng.integers(0, 256, 3)
    return img


FRAMES = [(1, 200, 90), (2, 131, 77), (3, 33, 40), (4, 97, 129)]   # heights on, off and just past a chunk


@pytest.mark.parametrize("seed,h,w", FRAMES)
def test_line_distances_match_the_reference_and_the_strips(contexts, seed, h, w):
    frame = columns_frame(seed, h, w)
    strips, columns = (Filter(context=c, fallback="off").intermediates(frame) for c in contexts)
    e = columns["edges"]
    right = (e & 2) > 0
    assert right.sum() > 200 and (strips["edges"] == e).all()
    _, vd = distances_reference(e)
    assert (vd[right].sum(-1) + 1).max() > min(1.5 * VCHUNK, h / 2)   # lines through chunk borders
    np.testing.assert_array_equal(columns["vdist"][right], vd[right])
    np.testing.assert_array_equal(columns["vdist"][right], strips["vdist"][right])
    np.testing.assert_array_equal(columns["out"], strips["out"])


def fast_shapes(context: Context, frame: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    f = Filter(context=context, fast=True)
    out = f.process(frame)
    e = np.empty(frame.shape[:2], np.uint8)
    vs = np.empty(frame.shape[:2] + (2,), np.uint8)
    cl.enqueue_copy(f.queue, e, f._fast.edges, is_blocking=True)
    cl.enqueue_copy(f.queue, vs, f._fast.vshapes, is_blocking=True)
    return e, vs, out


@pytest.mark.parametrize("seed,h,w", FRAMES)
def test_fast_shapes_match_the_reference_and_the_strips(contexts, seed, h, w):
    frame = columns_frame(seed, h, w)
    (e0, vs0, out0), (e, vs, out) = (fast_shapes(c, frame) for c in contexts)
    ref = F.fast_lshapes_reference(F.fast_edges_reference(frame))
    right = (e & F.E_RIGHT) > 0
    assert right.sum() > 200 and (e0 == e).all()
    if h > 3 * FAST_VCHUNK:   # runs past the bound through chunk borders: their middles unknown
        assert (ref[..., 2:][right] & 31 == F.FAST_MAX_LEN - 1).any()
    np.testing.assert_array_equal(vs[right], ref[..., 2:][right])
    np.testing.assert_array_equal(vs[right], vs0[right])
    np.testing.assert_array_equal(out, out0)


@pytest.mark.parametrize("fast", [False, True])
def test_the_timing_frame_comes_out_the_same(contexts, fast):
    """The yardstick's mixed 1080p frame: UI boxes, text, long edges, a checkerboard, a photograph, wires."""
    frame = timing_frame()
    outs = [Filter(context=c, fast=fast).process(frame) for c in contexts]
    assert (outs[0] != frame).any(-1).mean() > 0.02
    np.testing.assert_array_equal(outs[1], outs[0])
