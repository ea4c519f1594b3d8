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


def write_anamorphic(path: str, sar: Fraction, frames: int = 3) -> None:
    """64x48 stored, shown 4:3 wider (DV, DVD and HDV store 720 or 1440 columns for a wider picture)."""
    with av.open(path, "w") as out:
        s = out.add_stream("libx264", rate=24)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        s.codec_context.sample_aspect_ratio = sar
        for i in range(frames):
            f = av.VideoFrame.from_ndarray(np.full((48, 64, 3), 40 * i, np.uint8), format="rgb24")
            f.pts = i
            for p in s.encode(f):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


@pytest.mark.parametrize("ext,codec", [("mp4", None), ("mkv", None), ("mov", "prores_ks")])
def test_an_anamorphic_video_keeps_its_pixel_aspect_ratio(tmp_path, ext, codec):
    src = str(tmp_path / "dv.mp4")
    write_anamorphic(src, Fraction(4, 3))
    assert probe_video(src).sar == Fraction(4, 3)
    out = tmp_path / f"out.{ext}"
    r = run(src, "-o", out, *(("--codec", codec) if codec else ()))
    assert r.exit_code == 0, r.output
    assert probe_video(str(out)).sar == Fraction(4, 3)  # was square: the picture shown 3/4 as wide


def test_a_pixel_aspect_ratio_matroska_cannot_take_is_named(tmp_path):
    src = str(tmp_path / "dv.mp4")
    write_anamorphic(src, Fraction(4, 3))
    r = run(src, "-o", tmp_path / "out.mkv", "--codec", "ffv1")
    assert r.exit_code == 0, r.output
    assert "pixel aspect ratio 4/3 of" in r.output and "not kept" in r.output
