"""Video inputs a serious user brings: no video stream at all, sizes of one pixel, anamorphic pixels,
several video streams, damaged timestamps, containers the source's codec cannot go in."""
from __future__ import annotations

import importlib.util
import os
from fractions import Fraction

import av
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.video import VideoError, choose_pix_fmt, probe_video

ROOT = os.path.join(os.path.dirname(__file__), "..")
_spec = importlib.util.spec_from_file_location("make_demo", os.path.join(ROOT, "fixtures", "make_demo.py"))
make_demo = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(make_demo)


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def write_audio_only(path: str) -> None:
    with av.open(path, "w") as out:
        a = out.add_stream("aac", rate=48000, layout="mono")
        for i in range(8):
            fr = av.AudioFrame.from_ndarray(np.zeros((1, 1024), np.float32), format="fltp", layout="mono")
            fr.sample_rate, fr.pts = 48000, i * 1024
            for p in a.encode(fr):
                out.mux(p)
        for p in a.encode():
            out.mux(p)


def test_an_audio_only_file_is_refused_naming_it(tmp_path):
    src = str(tmp_path / "song.mp4")
    write_audio_only(src)
    with pytest.raises(VideoError, match="song.mp4: expected a video stream, found none"):
        probe_video(src)
    r = run(src, "-o", tmp_path / "out.mp4")
    assert r.exit_code == 1 and isinstance(r.exception, SystemExit), r.output  # no traceback
    assert "expected a video stream, found none" in r.output
    assert os.listdir(tmp_path) == ["song.mp4"]


@pytest.mark.parametrize("w,h", [(1, 17), (16, 1)])
def test_a_one_pixel_wide_or_tall_video_is_encoded(tmp_path, w, h):
    # A 1-pixel dimension has chroma as wide as the frame in every format: 4:2:x looked unsubsampled there
    # and libx264 refused yuv422p / yuv420p ('Generic error in an external library').
    assert choose_pix_fmt("libx264", "rgb24", 1, 17) == "yuv444p"
    assert choose_pix_fmt("libx264", "yuv420p", 16, 1) != "yuv420p"
    assert choose_pix_fmt("libx264", "yuv420p", 64, 48) == "yuv420p"
    src = str(tmp_path / "thin.nut")
    make_demo.write_clip(src, frames=3, w=w, h=h, codec="rawvideo", pix_fmt="rgb24", audio=False)
    out = tmp_path / "thin.mp4"
    r = run(src, "-o", out, "-q")
    assert r.exit_code == 0, r.output
    info = probe_video(str(out))
    assert (info.width, info.height) == (w, h) and info.frames == 3
