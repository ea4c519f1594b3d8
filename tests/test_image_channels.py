"""An image format that cannot hold the frame's channels is named as such: JPEG drops an alpha channel and
GIF adds one without an error, which used to be reported as "the written file is incomplete"."""
from __future__ import annotations

import os

import numpy as np
import pytest

from mlaa_stream.io.images import ImageWriteError, write_image


@pytest.mark.parametrize("name, channels", [("o.jpg", 4), ("o.jpg", 2), ("o.gif", 3)])
def test_a_format_without_those_channels_is_named_and_nothing_is_left(tmp_path, name, channels):
    with pytest.raises(ImageWriteError, match=f"does not support {channels}-channel images") as err:
        write_image(str(tmp_path / name), np.zeros((8, 8, channels), np.uint8))
    assert "incomplete" not in str(err.value) and name in str(err.value)
    assert os.listdir(tmp_path) == []


def test_formats_that_hold_the_channels_are_still_written(tmp_path):
    write_image(str(tmp_path / "o.jpg"), np.zeros((8, 8, 3), np.uint8))
    write_image(str(tmp_path / "o.png"), np.zeros((8, 8, 4), np.uint8))
    assert sorted(os.listdir(tmp_path)) == ["o.jpg", "o.png"]
