"""--progress and --stats files in a folder that does not exist are refused before any work, with one error
line: --progress used to end in a traceback, --stats in one after the whole video was written."""
from __future__ import annotations

import os

import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


@pytest.mark.parametrize("option", [["--progress"], ["--temporal", "--stats"]])
def test_a_report_file_in_a_missing_folder_is_refused_before_the_run(tmp_path, option):
    r = run(CLIP, "-o", tmp_path / "o.mp4", *option, tmp_path / "missing" / "report.txt")
    assert r.exit_code == 1, stderr(r)
    assert f"{option[-1]} " in stderr(r) and "does not exist" in stderr(r)
    assert r.exception is None or isinstance(r.exception, SystemExit)  # no traceback
    assert os.listdir(tmp_path) == []


def test_a_progress_file_that_is_a_folder_is_refused(tmp_path):
    r = run(CLIP, "-o", tmp_path / "o.mp4", "--progress", tmp_path)
    assert r.exit_code == 1 and "is a folder" in stderr(r)
    assert os.listdir(tmp_path) == []
