"""End-to-end streaming benchmark: `python -m mlaa_stream.bench.pipeline [--frames N] [--sizes ...]`.

For each size (default 1080p and 720p) it writes a synthetic aliased clip (H.264), then measures
in one run, as frames per second and as ratios:
  transcode    decode + encode through the same pipeline with an identity filter;
  filter       the Filter alone on frames already in memory (2 in flight, and serialized);
  end-to-end   decode + filter + encode (2 in flight, and serialized: submit then result at once);
  + temporal   with --temporal also decode + filter + the temporal stage as `--temporal` runs it (method auto,
               look-ahead 2) + encode, with the stage's share of the wall time (issue 16: >= 0.5x a
               transcode's frames per second).
Machines here are noisy: rows are measured in interleaved rounds and the median is shown; compare
the rows of one run, not runs with each other.
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from fractions import Fraction

import numpy as np

from mlaa_stream.pipeline import StageTimes
from mlaa_stream.io.video import VideoWriter, probe_video, read_video
from mlaa_stream.pipeline import filter_video

TEMPORAL_ROW = "end-to-end + temporal, 2 in flight"
TEMPORAL_SHARE = "temporal stage's share of the wall time"
SIZES = {"2160p": (3840, 2160), "1080p": (1920, 1080), "720p": (1280, 720), "480p": (854, 480)}


class _Identity:
    """A 'filter' that returns the frame: what the pipeline costs without the device."""

    class _Done:
        def __init__(self, frame):
            self.frame = frame

        def result(self):
            return self.frame

    def submit(self, frame):
        return self._Done(frame)


def synthetic_clip(path: str, width: int, height: int, frames: int) -> None:
    """An aliased scene (hard-edged rotated bars, 1 sample per pixel) panning a pixel per frame."""
    import av

    y, x = np.mgrid[0:height, 0:width + frames].astype(np.float32)
    bands = (np.floor((x * 0.3 + y * 0.9) / 40) % 2).astype(bool)
    base = np.where(bands[:, :, None], np.uint8([230, 180, 40]), np.uint8([30, 50, 120]))
    with av.open(path, "w") as out:
        s = out.add_stream("libx264", rate=30, options={"crf": "18", "preset": "ultrafast"})
        s.width, s.height, s.pix_fmt = width, height, "yuv420p"
        for i in range(frames):
            f = av.VideoFrame.from_ndarray(np.ascontiguousarray(base[:, i:i + width]), format="rgb24")
            f.pts, f.time_base = i, Fraction(1, 30)
            for p in s.encode(f):
                out.mux(p)
        for p in s.encode():
            out.mux(p)


def _fps(frames: int, seconds: float) -> float:
    return frames / seconds if seconds > 0 else float("inf")


def bench_size(name: str, width: int, height: int, frames: int, filt, folder: str,
               codec: str, preset: str, repeat: int = 3, temporal_filter=None) -> dict[str, float]:
    """All measurements for one frame size; returns the median fps of `repeat` rounds per row.
    `temporal_filter`: a Filter(keep_regions=True) for the rows with the temporal stage (None: no such rows);
    their stage's median share of the wall time is the row TEMPORAL_SHARE."""
    clip = os.path.join(folder, f"{name}.mp4")
    synthetic_clip(clip, width, height, frames)
    info = probe_video(clip)
    rows: dict[str, float] = {}

    decoded = [it.frame for it in read_video(info)]
    # warm-up: kernels for this frame format built, buffers allocated
    for f in decoded[:2]:
        filt.process(f)

    shares: list[float] = []

    def end_to_end(f, in_flight, temporal=None):
        out = os.path.join(folder, f"{name}_out.mp4")
        w = VideoWriter(out, info, codec=codec, preset=preset, overwrite=True)
        times = StageTimes()
        t0 = time.perf_counter()
        n = filter_video(info, w, f, in_flight=in_flight, temporal=temporal, times=times)
        wall = time.perf_counter() - t0
        if temporal is not None:
            shares.append(times.temporal / wall)
        return _fps(n, wall)

    def with_temporal():
        from mlaa_stream.temporal.methods import DEFAULT_LOOKAHEAD, DEFAULT_METHOD, make_stage
        stage = make_stage(DEFAULT_METHOD, temporal_filter.context, bgr=False, regions_from=temporal_filter,
                           lookahead=DEFAULT_LOOKAHEAD)
        try:
            return end_to_end(temporal_filter, 2, stage)
        finally:
            stage.close()

    def filter_alone(in_flight):
        t0 = time.perf_counter()
        pending = []
        for f in decoded:
            pending.append(filt.submit(f))
            if len(pending) >= in_flight:
                pending.pop(0).result()
        for p in pending:
            p.result()
        return _fps(len(decoded), time.perf_counter() - t0)

    runs = {
        "decode only": lambda: _fps(len(decoded), _time_decode(info)),
        "transcode (decode+encode)": lambda: end_to_end(_Identity(), 2),
        "filter alone, 2 in flight": lambda: filter_alone(2),
        "filter alone, serialized": lambda: filter_alone(1),
        "end-to-end, 2 in flight": lambda: end_to_end(filt, 2),
        "end-to-end, serialized": lambda: end_to_end(filt, 1),
    }
    if temporal_filter is not None:
        for f in decoded[:2]:
            temporal_filter.process(f)
        runs[TEMPORAL_ROW] = with_temporal
    samples: dict[str, list[float]] = {k: [] for k in runs}
    for _ in range(repeat):  # rounds interleave the rows, so load changes hit them all alike
        for label, fn in runs.items():
            samples[label].append(fn())
    rows.update({k: float(np.median(v)) for k, v in samples.items()})
    if shares:
        rows[TEMPORAL_SHARE] = float(np.median(shares))
    return rows


def _time_decode(info) -> float:
    t0 = time.perf_counter()
    for _ in read_video(info):
        pass
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=30, help="frames per clip (default 30)")
    ap.add_argument("--sizes", default="1080p,720p", help=f"comma list of {', '.join(SIZES)}")
    ap.add_argument("--device", default=None, help="OpenCL device (index or name part)")
    ap.add_argument("--repeat", type=int, default=3, help="rounds per row; the median is shown")
    ap.add_argument("--codec", default="libx264")
    ap.add_argument("--encoder-preset", default="veryfast")
    ap.add_argument("--temporal", action="store_true",
                    help="also end to end with the temporal stage as --temporal runs it (method auto, look-ahead 2)")
    args = ap.parse_args(argv)

    from contextlib import nullcontext

    from mlaa_stream.spatial.filter import Filter

    with Filter(args.device) as filt, tempfile.TemporaryDirectory(prefix="mlaa-bench-") as folder, \
            (Filter(args.device, bgr=False, keep_regions=True) if args.temporal else nullcontext()) as tfilt:
        device = filt.device_name
        print(f"device: {device}" + ("  (STAND-IN filter: returns a copy)" if device == "stand-in" else ""))
        print(f"encoder: {args.codec} preset {args.encoder_preset}, {args.frames} frames per clip, "
              f"median of {args.repeat} interleaved rounds, {os.cpu_count()} CPUs visible")
        for name in args.sizes.split(","):
            w, h = SIZES[name.strip()]
            rows = bench_size(name.strip(), w, h, args.frames, filt, folder, args.codec,
                              args.encoder_preset, args.repeat, temporal_filter=tfilt)
            share = rows.pop(TEMPORAL_SHARE, None)
            e2e = rows["end-to-end, 2 in flight"]
            print(f"\n{name} ({w}x{h})")
            for label, fps in rows.items():
                print(f"  {label:<34} {fps:8.2f} fps  {1000 / fps:8.1f} ms/frame  "
                      f"x{fps / e2e:5.2f} of end-to-end")
            if share is not None:
                print(f"  with the temporal stage: x{rows[TEMPORAL_ROW] / rows['transcode (decode+encode)']:.2f} of "
                      f"a transcode's fps; the stage takes {100 * share:.0f} % of the wall time")
            print(f"  overlap gain (2 in flight / serialized): end-to-end "
                  f"x{e2e / rows['end-to-end, serialized']:.2f}, filter alone "
                  f"x{rows['filter alone, 2 in flight'] / rows['filter alone, serialized']:.2f}")


if __name__ == "__main__":
    main()
