"""--start/--end trim a video written out as numbered images too: they used to be ignored there, and every
frame of the video was written."""
from __future__ import annotations

import os

import av
import numpy as np
from click.testing import CliRunner

from mlaa_stream.cli.main import main
from mlaa_stream.io.images import read_image

CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")  # 10 frames at 24 fps


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


def test_start_and_end_pick_the_frames_written_as_images(tmp_path):
    r = run(CLIP, "-o", tmp_path / "img" / "f_%04d.png", "--start", "3f", "--end", "6f")
    assert r.exit_code == 0, stderr(r)
    assert sorted(os.listdir(tmp_path / "img")) == ["f_0001.png", "f_0002.png", "f_0003.png"]
    with av.open(CLIP) as c:
        source = [f.to_ndarray(format="rgb24").astype(int) for f in c.decode(video=0)]
    for k in range(3):  # the filtered image is nearest to its own source frame, 3 + k
        img = read_image(str(tmp_path / "img" / f"f_{k + 1:04d}.png")).pixels.astype(int)
        assert int(np.argmin([np.abs(img - s).mean() for s in source])) == 3 + k


def test_a_backwards_trim_to_images_is_a_usage_error(tmp_path):
    r = run(CLIP, "-o", tmp_path / "img" / "f_%04d.png", "--start", "6f", "--end", "3f")
    assert r.exit_code == 2 and "must come after --start" in stderr(r)
    assert not os.listdir(tmp_path / "img")
