"""The unit every stage passes on: one frame, its position in the stream and its source's metadata."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class Item:
    """One frame on its way through the pipeline; `meta` is the source's (file name, pts, spec...). `passthrough`: a
    frame with nothing to filter (an EXR of depth or normals): it reaches the sink as read, in its place, through
    neither the filter, the temporal stage nor the post hooks. `premultiplied`: its colour is premultiplied by its
    alpha (EXR), for the filter's alpha as coverage (spatial/alpha.py)."""

    frame: np.ndarray
    meta: Any = None
    index: int = -1
    passthrough: bool = False
    premultiplied: bool = False
