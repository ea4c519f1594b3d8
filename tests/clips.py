"""Small synthetic clips for the video tests."""
from __future__ import annotations

import av
import numpy as np


def mux_moving_edge(container, stream, frames: int, start: int, level: int = 200) -> None:
    """Encode `frames` frames of a vertical edge (black | `level`) moving one pixel per frame from column `start` into
    `stream` (its width and height set), muxed into `container`, then flush the encoder."""
    for i in range(frames):
        img = np.zeros((stream.height, stream.width, 3), np.uint8)
        img[:, start + i:] = level
        for p in stream.encode(av.VideoFrame.from_ndarray(img, format="rgb24")):
            container.mux(p)
    for p in stream.encode():
        container.mux(p)
