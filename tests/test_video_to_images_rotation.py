"""A video with a display rotation (phones film sideways and say so in the display matrix) written out as
images: the images are as stored, so the rotation they lose is reported instead of dropped silently."""
from __future__ import annotations

import av
import numpy as np
from click.testing import CliRunner

from mlaa_stream.cli.main import main


def rotated_clip(path, degrees: int) -> None:
    with av.open(str(path), "w") as c:
        s = c.add_stream("libx264", rate=24)
        s.width, s.height, s.pix_fmt = 64, 48, "yuv420p"
        if degrees:
            s.set_display_rotation(degrees)
        for k in range(2):
            img = np.zeros((48, 64, 3), np.uint8)
            img[10:30, 5 + k:40] = 255
            for p in s.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
                c.mux(p)
        for p in s.encode(None):
            c.mux(p)


def stderr(r) -> str:
    return r.stderr if hasattr(r, "stderr") else r.output


def test_a_rotation_lost_on_images_is_reported(tmp_path):
    rotated_clip(tmp_path / "r.mp4", 90)
    r = CliRunner().invoke(main, [str(tmp_path / "r.mp4"), "-o", str(tmp_path / "img" / "%02d.png")])
    assert r.exit_code == 0, stderr(r)
    assert "displayed rotated by 90 degrees" in stderr(r)


def test_an_unrotated_video_says_nothing_of_rotation(tmp_path):
    rotated_clip(tmp_path / "r.mp4", 0)
    r = CliRunner().invoke(main, [str(tmp_path / "r.mp4"), "-o", str(tmp_path / "img" / "%02d.png")])
    assert r.exit_code == 0 and "displayed rotated" not in stderr(r)


def test_keep_on_a_rotated_video_says_the_rectangles_are_in_stored_frames(tmp_path):
    """--keep is applied to the frames as stored; on a video displayed rotated, a rectangle measured on the turned
    picture kept another place without a word."""
    rotated_clip(tmp_path / "r.mp4", 90)
    r = CliRunner().invoke(main, [str(tmp_path / "r.mp4"), "-o", str(tmp_path / "o.mp4"), "--keep", "0,0,50%,50%"])
    assert r.exit_code == 0, stderr(r)
    assert "--keep: " in stderr(r) and "rotated by 90 degrees" in stderr(r) and "as stored (64x48" in stderr(r)
    rotated_clip(tmp_path / "u.mp4", 0)
    r = CliRunner().invoke(main, [str(tmp_path / "u.mp4"), "-o", str(tmp_path / "p.mp4"), "--keep", "0,0,50%,50%"])
    assert r.exit_code == 0 and "--keep: " not in stderr(r)
