"""--progress and --stats files in a folder that does not exist are refused before any work, with one error
line: --progress used to end in a traceback, --stats in one after the whole video was written. Images are
refused on standard output (-o -) instead of going to a folder named "-"."""
from __future__ import annotations

import os

import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.images import write_image

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



@pytest.mark.parametrize("option", [["--progress"], ["--temporal", "--stats"]])
def test_a_report_file_named_as_an_image_or_video_is_refused(tmp_path, option):
    # --stats on an input frame wrote the CSV over it (the frame lost); on an output, over that output
    folder = tmp_path / "in"
    folder.mkdir()
    for k in range(2):
        write_image(str(folder / f"f{k}.png"), np.full((12, 16, 3), 40 * k, np.uint8))
    before = (folder / "f0.png").read_bytes()
    for target in (folder / "f0.png", tmp_path / "out" / "f1.png", tmp_path / "o.mkv"):
        r = run(folder, "-o", tmp_path / "out", *option, target)
        assert r.exit_code == 2, stderr(r)
        assert f"{option[-1]} {target}: names an image or video" in stderr(r)
    assert (folder / "f0.png").read_bytes() == before and not (tmp_path / "out").exists()

def test_a_progress_file_that_is_a_folder_is_refused(tmp_path):
    r = run(CLIP, "-o", tmp_path / "o.mp4", "--progress", tmp_path)
    assert r.exit_code == 1 and "is a folder" in stderr(r)
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize("source", ["folder", "image"])
def test_images_to_standard_output_are_refused(tmp_path, monkeypatch, source):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "in").mkdir()
    write_image(str(tmp_path / "in" / "a.png"), np.zeros((8, 8, 3), np.uint8))
    r = run(tmp_path / "in" if source == "folder" else tmp_path / "in" / "a.png", "-o", "-")
    assert r.exit_code == 2 and "standard output" in stderr(r)
    assert sorted(os.listdir(tmp_path)) == ["in"]  # no folder or file named '-'
