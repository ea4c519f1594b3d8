"""A video on standard input written out as numbered images: the job used to probe a file named '-' and fail
with "-: expected a video FFmpeg can read, got: No such file or directory"."""
from __future__ import annotations

import os
import subprocess
import sys

CLI = [sys.executable, "-c", "from mlaa_stream.cli.main import main; main()"]
DEMO_CLIP = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "clip.mp4")  # 10 frames


def test_standard_input_becomes_numbered_images(tmp_path):
    with open(DEMO_CLIP, "rb") as clip:
        r = subprocess.run([*CLI, "-", "-o", str(tmp_path / "img" / "f_%02d.png")], stdin=clip,
                           capture_output=True, timeout=300)
    assert r.returncode == 0, r.stderr.decode()
    assert sorted(os.listdir(tmp_path / "img")) == [f"f_{n:02d}.png" for n in range(1, 11)]
