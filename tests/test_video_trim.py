"""A trim that holds no frame (--start at or past the end, --end 0) is an error and writes nothing, instead of
an empty, unplayable video with exit code 0; --start/--end refuse NaN, infinity and negative frame numbers
(NaN used to end in a traceback)."""
from __future__ import annotations

import os

import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.video import parse_time

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")  # 10 frames at 24 fps


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


@pytest.mark.parametrize("trim", [("--start", "10"), ("--start", "10f"), ("--end", "0")])
def test_a_trim_without_frames_fails_and_writes_nothing(tmp_path, trim):
    out = tmp_path / "t.mp4"
    r = run(CLIP, "-o", out, *trim)
    assert r.exit_code == 1, stderr(r)
    assert "no frame between" in stderr(r) and "not written" in stderr(r)
    assert os.listdir(tmp_path) == []


def test_a_trim_without_frames_keeps_the_output_it_would_overwrite(tmp_path):
    out = tmp_path / "t.mp4"
    out.write_bytes(b"earlier output")
    r = run(CLIP, "-o", out, "-y", "--start", "9:00")
    assert r.exit_code == 1 and out.read_bytes() == b"earlier output"


@pytest.mark.parametrize("bad", ["nan", "infinity", "1e400", "-5f", "1:nan"])
def test_parse_time_refuses_non_finite_times_and_negative_frames(bad):
    with pytest.raises(ValueError, match="expected a time"):
        parse_time(bad, None)


def test_a_nan_start_is_a_usage_error(tmp_path):
    r = run(CLIP, "-o", tmp_path / "t.mp4", "--start", "nan")
    assert r.exit_code == 2 and "expected a time" in stderr(r)
