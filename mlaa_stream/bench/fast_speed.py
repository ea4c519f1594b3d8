"""The fast preset's time against the default preset's, per 1920x1080 frame:
`python -m mlaa_stream.bench.fast_speed`.

Frames: the yardstick's mixed timing frame; a rendered frame (the first frame of rendered_atrium, 640x360,
tiled 3x3; left out when the rendered cache is missing and no EGL context can draw it); a frame with few
edges (a smooth photograph, 2x upscaled, with a dozen aliased discs and bars: under 3 % of its pixels
have a fast-preset edge); and a flat frame. For each frame three filters' `process` (host to host) run
interleaved in one process (wall time, and the process's CPU time, less disturbed by other processes' load)
-- FastFilter (the fast preset without host copies: Antialiaser(preset="fast")),
Filter(preset="fast") (staging copy, upload, download) and Filter(preset="default") -- and the median of
`--runs` frames after warm-up is taken; then the fast passes are timed on a serialised profiling queue
(`Filter.profile`, the copying path: upload and download included).
A benchmark, never a unit test; machines here are noisy: compare the ratios.
"""
from __future__ import annotations

import argparse
import os
import resource
import time

import numpy as np

from mlaa_stream.spatial.filter import Filter

W, H = 1920, 1080


def few_edges_frame() -> np.ndarray:
    """A smooth photograph with a dozen aliased shapes: edges at a few per cent of the pixels."""
    import cv2
    import matplotlib.image
    from matplotlib import cbook

    photo = matplotlib.image.imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[..., :3]
    frame = cv2.GaussianBlur(cv2.resize(np.ascontiguousarray(photo), (W, H), interpolation=cv2.INTER_CUBIC),
                             (0, 0), 4)
    yy, xx = np.mgrid[:H, :W]
    rng = np.random.default_rng(0)
    for k in range(12):
        cx, cy, r = rng.integers(100, W - 100), rng.integers(100, H - 100), rng.integers(20, 80)
        colour = rng.integers(0, 256, 3)
        if k % 2:
            frame[(xx - cx) ** 2 + (yy - cy) ** 2 <= r * r] = colour
        else:  # a bar at a shallow slope
            frame[(np.abs((yy - cy) - 0.2 * (xx - cx)) < r / 8) & (np.abs(xx - cx) < 3 * r)] = colour
    return np.ascontiguousarray(frame, dtype=np.uint8)


def rendered_frame() -> np.ndarray | None:
    try:
        from mlaa_stream.yardstick.rendered import generate_rendered
        scene = generate_rendered(small=False, names=["rendered_atrium"])[0]
    except Exception as exc:  # no cache and no EGL context
        print(f"rendered frame left out: {exc}")
        return None
    tile = scene.inputs[0][..., :3]
    return np.ascontiguousarray(np.tile(tile, (H // tile.shape[0] + 1, W // tile.shape[1] + 1, 1))[:H, :W])


def frames() -> dict[str, np.ndarray]:
    from mlaa_stream.yardstick.scenes import timing_frame
    out = {"mixed (yardstick timing frame)": timing_frame()}
    rendered = rendered_frame()
    if rendered is not None:
        out["rendered (atrium, tiled 3x3)"] = rendered
    out["few edges (smooth photo + 12 shapes)"] = few_edges_frame()
    out["flat"] = np.full((H, W, 3), 90, np.uint8)
    return out


def _cpu_s() -> float:
    r = resource.getrusage(resource.RUSAGE_SELF)  # this process and its threads (PoCL's workers)
    return r.ru_utime + r.ru_stime


def interleaved(filters: list[Filter], frame: np.ndarray, runs: int, warmup: int = 3
                ) -> tuple[list[float], list[float]]:
    """Median `process` milliseconds of each filter, run in turn frame after frame: wall time, and CPU time
    of the process (all threads), which other processes' load disturbs less."""
    wall: list[list[float]] = [[] for _ in filters]
    cpu: list[list[float]] = [[] for _ in filters]
    for k in range(warmup + runs):
        for f, tw, tc in zip(filters, wall, cpu):
            t0, c0 = time.perf_counter(), _cpu_s()
            f.process(frame)
            if k >= warmup:
                tw.append((time.perf_counter() - t0) * 1e3)
                tc.append((_cpu_s() - c0) * 1e3)
    return [float(np.median(t)) for t in wall], [float(np.median(t)) for t in cpu]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=30)
    args = ap.parse_args(argv)
    from mlaa_stream.spatial.fast import fast_edges_reference
    from mlaa_stream.spatial.fast_filter import FastFilter
    direct, fast, default = FastFilter(), Filter(preset="fast"), Filter(preset="default")
    try:
        print(f"device: {fast.device_name}; median of {args.runs} frames after 3 warm-up, interleaved; "
              f"load average {os.getloadavg()[0]:.1f} at the start")
        print("| frame | edge pixels (fast) | FastFilter (ms) | Filter fast (ms) | default (ms) | FastFilter / default "
              "| Filter fast / default | CPU ms: FastFilter, default (ratio) | fast passes, device ms |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for name, frame in frames().items():
            share = float((fast_edges_reference(frame) > 0).mean())
            (tz, tf, td), (cz, _, cd) = interleaved([direct, fast, default], frame, args.runs)
            passes = fast.profile(frame, runs=args.runs)
            shares = ", ".join(f"{k} {v:.2f}" for k, v in passes.items())
            print(f"| {name} | {100 * share:.1f} % | {tz:.1f} | {tf:.1f} | {td:.1f} | **{tz / td:.2f}x** "
                  f"| {tf / td:.2f}x | {cz:.1f}, {cd:.1f} ({cz / cd:.2f}x) | {shares} |", flush=True)
        print(f"load average {os.getloadavg()[0]:.1f} at the end")
    finally:
        for f in (direct, fast, default):
            f.close()


if __name__ == "__main__":
    main()
