"""A y4m output holds video only: the source's audio is left out with a warning, no longer silently."""
from __future__ import annotations

import os

from click.testing import CliRunner

from mlaa_stream.cli.main import main

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")  # with an audio track


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


def test_audio_left_out_of_y4m_is_reported(tmp_path):
    r = run(CLIP, "-o", tmp_path / "o.y4m")
    assert r.exit_code == 0, stderr(r)
    assert "audio streams not kept: yuv4mpegpipe holds video only" in stderr(r)
    assert (tmp_path / "o.y4m").read_bytes().startswith(b"YUV4MPEG2")


def test_audio_none_to_y4m_says_nothing(tmp_path):
    r = run(CLIP, "-o", tmp_path / "o.y4m", "--audio", "none")
    assert r.exit_code == 0 and "not kept" not in stderr(r)
