"""The spatial MLAA filter (seed 000 §3) -- TEMPORARY STAND-IN: returns a copy of the frame.

Interface (stable, the real implementation replaces the body):
    f = Filter(device=None, threshold=None, metric="lab", linear=True, reconstruct=False, bgr=False)
    out = f.process(frame)            # same shape and dtype as frame
    pending = f.submit(frame); out = pending.result()   # non-blocking upload/kernels/download
    f.close()  /  with Filter() as f: ...
"""
from __future__ import annotations

import numpy as np


class PendingFrame:
    def __init__(self, out: np.ndarray):
        self._out = out

    def result(self) -> np.ndarray:
        return self._out


class Filter:
    def __init__(self, device=None, *, threshold=None, metric="lab", linear=True,
                 reconstruct=False, bgr=False):
        self.device_name = "stand-in"

    def submit(self, frame: np.ndarray) -> PendingFrame:
        return PendingFrame(np.array(frame, copy=True))

    def process(self, frame: np.ndarray) -> np.ndarray:
        return self.submit(frame).result()

    def close(self) -> None:
        pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()
