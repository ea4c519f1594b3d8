"""VapourSynth integration (issue 17 item 6): filter a `vapoursynth.VideoNode` through the spatial Filter.

    import vapoursynth as vs
    from mlaa_stream.io.vsnode import filter_node
    clip = core.lsmas.LWLibavSource("in.mkv").resize.Bicubic(format=vs.RGB24, matrix_in_s="709")
    clip = filter_node(clip, preset="default")
    clip.set_output()

RGB24, RGB48 and RGBS clips (one plane per channel, 8/16-bit integer or 32-bit float); anything else is
refused naming the format (convert with `resize` first). Each frame is interleaved, filtered and split
back into planes in a `std.ModifyFrame` callback; VapourSynth may ask for frames from several threads,
so the device is used by one at a time. `vapoursynth` itself comes from its own installer (the PyPI
wheel needs the system library and Python >= 3.12); nothing here imports it before it is called.
"""
from __future__ import annotations

import threading
from typing import Any

import numpy as np

# VapourSynth format names this accepts, and the sample type each has
FORMATS = {"RGB24": np.uint8, "RGB48": np.uint16, "RGBS": np.float32}


def interleave(planes: list[np.ndarray]) -> np.ndarray:
    """(H, W, 3) from three (H, W) planes (R, G, B), as the Filter takes frames."""
    return np.ascontiguousarray(np.stack(planes, axis=-1))


def filter_planes(filt, lock: threading.Lock, frame: Any) -> Any:
    """A copy of the VapourSynth frame `frame` (planes R, G, B readable as arrays) with the filter's output."""
    out = frame.copy()
    src = [np.asarray(frame[p]) for p in range(3)]
    with lock:
        result = filt.process(interleave(src))
    for p in range(3):
        np.copyto(np.asarray(out[p]), result[..., p])
    return out


def filter_node(node: Any, *, device: str | int | None = None, preset: str | None = None,
                **filter_kwargs) -> Any:
    """`node` (a vapoursynth.VideoNode in RGB24, RGB48 or RGBS) antialiased frame by frame by the Filter.
    Raises ValueError naming the format for anything else."""
    from mlaa_stream.spatial.filter import Filter

    name = getattr(node.format, "name", None)
    if name not in FORMATS:
        raise ValueError(f"expected an RGB24, RGB48 or RGBS clip, got {name or 'a clip of varying format'} "
                         f"(convert with core.resize first)")
    filt = Filter(device, bgr=False, preset=preset, **filter_kwargs)
    lock = threading.Lock()
    return node.std.ModifyFrame(clips=node, selector=lambda n, f: filter_planes(filt, lock, f))
