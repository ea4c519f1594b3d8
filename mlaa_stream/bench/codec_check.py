"""Render regions through a video codec or JPEG: bench scenes encoded as a user's video or images would be.

    python -m mlaa_stream.bench.codec_check [--scenes rendered_pan,rendered_orbit,text_ui,checkerboard,pan] [--crf 18,23]
                                            [--jpeg 60,75] [--tile 1920x1080]

Each scene's frames (a still repeated 4 times) go through libx264 (PyAV, yuv420p, preset veryfast) at each CRF
and back, and each still through JPEG (OpenCV, 4:2:0) at each `--jpeg` quality; then the default filter and preset
`screen` (the same without render regions) run on the decoded frames. `--tile WxH` first repeats each frame (and
its truth) to that size, as a screen of such content would be, before the codec sees it. Printed per scene and
codec setting: the share of the first two frames' pixels in render regions, and error removed % of both against
the scene's truth (the codec's own error counts as the input's, so the figures fall with the CRF). Rendered video
should keep its regions; text and UI should have none. A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse
import io

import av
import numpy as np

from mlaa_stream.spatial.fallback import render_regions_of
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.scenes import generate_scenes, through_jpeg


def through_h264(frames: np.ndarray, crf: int) -> np.ndarray:
    """(T, H, W, 3) uint8 RGB (even H, W) -> the same frames after libx264 at `crf` and back."""
    buf = io.BytesIO()
    with av.open(buf, "w", format="mp4") as container:
        stream = container.add_stream("libx264", rate=24)
        stream.width, stream.height, stream.pix_fmt = frames.shape[2], frames.shape[1], "yuv420p"
        stream.options = {"crf": str(crf), "preset": "veryfast"}
        for frame in frames:
            for packet in stream.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(frame), format="rgb24")):
                container.mux(packet)
        for packet in stream.encode():
            container.mux(packet)
    buf.seek(0)
    with av.open(buf) as container:
        return np.stack([f.to_ndarray(format="rgb24") for f in container.decode(video=0)])


def tiled(frames: np.ndarray, width: int, height: int) -> np.ndarray:
    """(T, h, w, C) frames repeated across and down to (T, height, width, C)."""
    reps = (1, -(-height // frames.shape[1]), -(-width // frames.shape[2])) + (1,) * (frames.ndim - 3)
    return np.ascontiguousarray(np.tile(frames, reps)[:, :height, :width])


def region_share(filt: Filter, frame: np.ndarray) -> float:
    """The share of `frame`'s pixels in render regions (`filt`: the fallback off, for the MLAA passes' output)."""
    passes = filt.intermediates(frame)
    return float(render_regions_of(frame, passes["out"], passes["edges"]).mean())


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="rendered_pan,rendered_orbit,text_ui,checkerboard,pan")
    ap.add_argument("--crf", default="18,23", help="libx264 CRFs, comma-separated ('' for none)")
    ap.add_argument("--jpeg", default="", help="JPEG qualities, comma-separated (default none)")
    ap.add_argument("--tile", default="", metavar="WxH", help="repeat each frame to this size first (even)")
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    try:
        codecs = ([("crf", int(c)) for c in args.crf.split(",") if c]
                  + [("jpeg q", int(q)) for q in args.jpeg.split(",") if q])
        size = tuple(int(v) for v in args.tile.split("x")) if args.tile else None
    except ValueError:
        raise SystemExit("--crf / --jpeg / --tile: expected integers (the size as WxH)") from None
    if not codecs or (size is not None and (len(size) != 2 or min(size) < 2)):
        raise SystemExit("expected at least one --crf or --jpeg setting, and --tile as WxH")
    wanted = args.scenes.split(",")
    groups = sorted({"rendered" if n.startswith("rendered") else n for n in wanted})
    scenes = {s.name: s for s in generate_scenes(names=groups)}
    missing = [n for n in wanted if n not in scenes]
    if missing:
        raise SystemExit(f"unknown scenes: {', '.join(missing)}")
    default, screen = Filter(device=args.device), Filter(device=args.device, preset="screen")
    off = Filter(device=args.device, fallback="off")
    print("scene".ljust(16) + "codec".rjust(9) + "regions".rjust(9) + "default".rjust(9) + "screen".rjust(9))
    for name in wanted:
        s = scenes[name]
        inputs, truths = np.asarray(s.inputs), np.asarray(s.truths)
        if len(inputs) == 1:
            inputs, truths = np.repeat(inputs, 4, 0), np.repeat(truths, 4, 0)
        if size is not None:
            inputs, truths = tiled(inputs, *size), tiled(truths, *size)
        h, w = inputs.shape[1] // 2 * 2, inputs.shape[2] // 2 * 2  # yuv420p needs even sizes
        inputs, truths = inputs[:, :h, :w], truths[:, :h, :w]
        for kind, level in codecs:
            coded = through_h264(inputs, level) if kind == "crf" else through_jpeg(inputs, level)
            share = np.mean([region_share(off, f) for f in coded[:2]])
            default.new_shot()  # each clip its own shot (the render verdict is held over one: spatial/shots.py)
            scores = [M.error_removed(np.stack([f.process(x) for x in coded]), coded, truths)
                      for f in (default, screen)]
            print(name.ljust(16) + f"{kind} {level}".rjust(9) + f"{share * 100:8.0f}%"
                  + "".join(f"{v * 100:8.1f}%" for v in scores))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
