"""The moire pass (kernels/moire.cl, mlaa_stream/spatial/moire.py) against its numpy reference and against cases
with a known answer: point-sampled moire in two-colour art is low-passed across its lines; ruled lines, 1-px
checker fills, photographs and sparse thin lines are left as they are."""
from __future__ import annotations

import numpy as np
import pytest

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.spatial.moire import MOIRE_LINES, line_bits, moire_fires, moire_reference
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.scenes import checker_texture, build_scene, Layer, generate_scenes

A, B = (236, 236, 236), (28, 28, 36)


@pytest.fixture(scope="module")
def checker() -> np.ndarray:
    """A perspective checkerboard at 1 spp (the bench scene's texture, 200 x 120 px): moire towards its
    horizon, clean stair steps near the camera, a haze of a third colour above the horizon."""
    tex = checker_texture(200, 120 * 0.25, square=0.5, degrees=25.0)
    return build_scene("c", "checkerboard", [[Layer(None, tex)]], 200, 120).inputs[0]


def _formats(frame: np.ndarray):
    """The frame in each pixel format the filter takes: (frame, bgr, linear_input)."""
    rgb16 = frame.astype(np.uint16) * 257
    lin = srgb_to_linear(frame.astype(np.float32) / 255).astype(np.float32)
    bgra = np.dstack([frame[..., ::-1], np.full(frame.shape[:2], 200, np.uint8)])
    hdr = (frame.astype(np.float32) / 255)
    hdr[:6] *= 1.5   # display-encoded float over 1 in the top rows: those pixels keep the passes' output
    return [(frame, False, False), (bgra, True, False), (rgb16, False, False), (lin, False, True),
            (hdr, False, False), (frame.mean(-1).astype(np.uint8), False, False)]


@pytest.mark.parametrize("k", range(6), ids=["rgb8", "bgra8", "rgb16", "linear-float", "display-float", "grey8"])
def test_kernel_matches_reference(checker, k):
    """The pass on the filter's output: bit-identical to moire_reference in every pixel format, and it works:
    hundreds of pixels change, every one of them in a two-colour window."""
    frame, bgr, linear_input = _formats(checker)[k]
    with Filter(bgr=bgr, linear_input=linear_input, moire=False) as f0:
        before = f0.process(frame)
        edges = f0.intermediates(frame)["edges"]
    with Filter(bgr=bgr, linear_input=linear_input) as f1:
        after = f1.process(frame)
    ref = moire_reference(frame, before, edges, linear_input=linear_input, bgr=bgr)
    assert np.array_equal(after, ref)
    changed = (after != before).reshape(after.shape[0], after.shape[1], -1).any(-1)
    assert changed.sum() > 300
    if frame.ndim == 3 and frame.shape[2] == 4:
        assert np.array_equal(after[..., 3], frame[..., 3])   # alpha stays


def test_known_answer_dashes_alternating_row_by_row_become_their_mean():
    """Blocks of 4 columns that alternate colour row by row between solid blocks (dashes of isolated row pixels
    with an end on each side, as a pattern finer than the rows gives): inside, every pixel becomes the 3 x 3
    binomial ([1 2 1] x [1 2 1] / 16) of the input in linear light -- a block's inner columns exactly the mean of
    the two colours, its border columns and their solid neighbours a quarter or so of the way -- within one level
    (the tables); the frame's border rows keep the passes' output."""
    h, w = 40, 48
    yy, xx = np.mgrid[0:h, 0:w]
    alternating = (xx // 4) % 2 == 0
    frame = np.where((alternating & (yy % 2 == 0))[..., None], B, A).astype(np.uint8)
    fire_v, fire_h = moire_fires(frame, Filter(moire=False).intermediates(frame)["edges"])
    assert fire_v[4:-4, 4:-4].all() and not fire_h.any()
    out = Filter().process(frame).astype(np.float64)
    lin = srgb_to_linear(frame / 255.0)
    kernel = np.outer([1, 2, 1], [1, 2, 1]) / 16.0
    want = sum(kernel[dy + 1, dx + 1] * np.roll(lin, (-dy, -dx), (0, 1)) for dy in (-1, 0, 1) for dx in (-1, 0, 1))
    want = linear_to_srgb(want) * 255
    inner = np.zeros((h, w), bool)
    inner[4:-4, 4:-4] = True
    assert np.abs(out[inner] - want[inner]).max() <= 1.0
    mean = linear_to_srgb((srgb_to_linear(np.float64(A) / 255) + srgb_to_linear(np.float64(B) / 255)) / 2) * 255
    middle = inner & alternating & (xx % 4 > 0) & (xx % 4 < 3)
    assert middle.sum() > 100 and np.abs(out[middle] - mean).max() <= 1.0


@pytest.mark.parametrize("pattern", ["ruled_1px", "ruled_every_3", "checker_1px", "sparse_dashes", "third_colour"])
def test_exact_art_is_left_alone(pattern):
    """Two-colour art the rule must not take for moire: full-length ruled lines (no dash ends), a 1-px checker
    fill (its line pixels run through every window without an end), dashes too sparse (under MOIRE_LINES per
    window), and moire-like rows with a third colour in every window. The pass changes no pixel."""
    h, w = 40, 48
    yy, xx = np.mgrid[0:h, 0:w]
    rng = np.random.default_rng(3)
    mask = {"ruled_1px": yy % 2 == 0, "ruled_every_3": yy % 3 == 0, "checker_1px": (xx + yy) % 2 == 0,
            "sparse_dashes": (yy % 8 == 0) & ((xx // 3) % 2 == 0),
            "third_colour": ((xx // 3) + yy) % 2 == 0}[pattern]
    frame = np.where(mask[..., None], A, B).astype(np.uint8)
    if pattern == "third_colour":   # a third colour in every 7 x 7 window
        frame[(yy % 5 == 2) & (xx % 5 == 2)] = (200, 40, 40)
    assert np.array_equal(Filter().process(frame), Filter(moire=False).process(frame))
    if pattern == "sparse_dashes":
        line_v, _ = line_bits(frame, Filter(moire=False).intermediates(frame)["edges"])
        assert line_v.sum() > 0 and line_v[:7].sum() < MOIRE_LINES


def test_photographs_and_antialiased_art_are_left_alone():
    """Many colours in every window: the bench's photograph, its antialiased text and wires change nowhere."""
    scenes = {s.name: s for s in generate_scenes(small=True, names=["photo", "antialiased"])}
    for name in ("photo", "text_ui_aa", "wires_aa"):
        frame = scenes[name].inputs[0]
        assert np.array_equal(Filter().process(frame), Filter(moire=False).process(frame)), name


def test_the_checkerboard_gains_and_text_holds():
    """The bench's perspective checkerboard (its small version): error removed up by over 4 points; small aliased
    text and the wires within half a point."""
    scenes = {s.name: s for s in generate_scenes(small=True, names=["checkerboard", "text_ui", "wires"])}

    def removed(scene, **kw):
        return M.error_removed(Filter(**kw).process(scene.inputs[0]), scene.inputs[0], scene.truths[0])
    assert removed(scenes["checkerboard"]) > removed(scenes["checkerboard"], moire=False) + 0.04
    for name in ("text_ui", "wires"):
        assert abs(removed(scenes[name]) - removed(scenes[name], moire=False)) < 0.005, name
