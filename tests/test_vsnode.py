"""VapourSynth integration (issue 17 item 6): mlaa_stream.io.vsnode filters a VideoNode frame by frame.

The frame plumbing runs always, on stand-in frames with VapourSynth's interface (copy(), planes as
arrays); the clip test needs `vapoursynth` itself, which PyPI ships only for Python >= 3.12 and which
needs the VapourSynth system library: it skips elsewhere, saying so."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from mlaa_stream.io.vsnode import filter_node, filter_planes, interleave
from mlaa_stream.spatial.filter import Filter


class FakeFrame:
    """A VapourSynth frame's interface as filter_planes uses it: frame[plane] -> writable array, copy()."""

    def __init__(self, planes: list[np.ndarray]):
        self.planes = planes

    def __getitem__(self, p: int) -> np.ndarray:
        return self.planes[p]

    def copy(self) -> "FakeFrame":
        return FakeFrame([p.copy() for p in self.planes])


def aliased(dtype, h: int = 24, w: int = 40) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    hi = {np.uint8: 255, np.uint16: 65535, np.float32: 1.0}[dtype]
    rng = np.random.default_rng(17)
    inside = (2 * y > x + 3)[..., None]
    img = np.where(inside, [0.1, 0.2, 0.8], [0.9, 0.85, 0.7]) + rng.uniform(-0.01, 0.01, (h, w, 3))
    return (img * hi).astype(dtype)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16, np.float32])
def test_planes_in_planes_out_equal_the_filter_on_the_interleaved_frame(dtype):
    img = aliased(dtype)
    frame = FakeFrame([np.ascontiguousarray(img[..., c]) for c in range(3)])
    assert np.array_equal(interleave(frame.planes), img)
    with Filter(bgr=False) as filt:
        out = filter_planes(filt, threading.Lock(), frame)
        want = filt.process(img)
    assert not np.array_equal(want, img)  # the edge is antialiased
    for c in range(3):
        assert out[c].dtype == np.dtype(dtype) and np.array_equal(out[c], want[..., c])
        assert np.array_equal(frame[c], img[..., c])  # the source frame is untouched


def test_a_clip_through_vapoursynth():
    vs = pytest.importorskip("vapoursynth", reason="vapoursynth is not installed: PyPI has it for Python >= "
                             "3.12 only and it needs the VapourSynth system library (not on this machine)")
    core = vs.core
    img = aliased(np.uint8)
    clip = core.std.BlankClip(width=img.shape[1], height=img.shape[0], format=vs.RGB24, length=2)

    def paint(n, f):
        fout = f.copy()
        for c in range(3):
            np.copyto(np.asarray(fout[c]), img[..., c])
        return fout
    clip = core.std.ModifyFrame(clips=clip, selector=paint)
    out = filter_node(clip)
    with Filter(bgr=False) as filt:
        want = filt.process(img)
    got = out.get_frame(1)
    assert np.array_equal(interleave([np.asarray(got[c]) for c in range(3)]), want)
    with pytest.raises(ValueError, match="expected an RGB24, RGB48 or RGBS clip, got YUV420P8"):
        filter_node(core.std.BlankClip(format=vs.YUV420P8))
