"""Per-pass timings of the spatial filter on 1920x1080 frames: `python -m mlaa_stream.bench.mlaa_profile`.

Five frames (seven with the rendered ones): the yardstick's mixed timing frame (edges, UI text, checkerboard, photo,
wires); a photograph three ways -- upscaled to fill the frame (smooth), tiled at 1:1 (every pixel differs from
its neighbours: a detailed shot) and upscaled with camera noise (Gaussian, sigma 2 levels: what video
from a camera looks like to edge detection) --; a flat frame (the floor); and, where the
rendered scenes can be drawn or are cached, a 1-spp render (the atrium still tiled 3x3), also with film grain
(Gaussian, 4 levels, one value for R, G and B: its render regions' quiet pixels, kernels/noise.cl). For each: the
median of >= 20 frames after warm-up of `Filter.process` (host to host), and each pass's device time on a
profiling queue. Writes
docs/performance.md. A benchmark, never a unit test; machines here are noisy.
"""
from __future__ import annotations

import argparse
import datetime
import time
from pathlib import Path

import numpy as np

from mlaa_stream.spatial.filter import Filter

ROOT = Path(__file__).resolve().parents[2]  # the checkout: mlaa_stream/bench/ is two levels down


def frames() -> dict[str, np.ndarray]:
    import cv2
    import matplotlib.image
    from matplotlib import cbook

    from mlaa_stream.yardstick.scenes import timing_frame
    original = np.ascontiguousarray(
        matplotlib.image.imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[..., :3])
    photo = cv2.resize(original, (1920, 1080), interpolation=cv2.INTER_CUBIC)
    rng = np.random.default_rng(0)
    noisy = np.clip(photo.astype(np.int16) + rng.normal(0, 2, photo.shape).round().astype(np.int16), 0, 255)
    out = {"mixed (yardstick timing frame)": timing_frame(),
            "photograph": np.ascontiguousarray(photo, dtype=np.uint8),
            "photograph, detailed (tiled 1:1)": np.ascontiguousarray(np.tile(original, (3, 4, 1))[:1080, :1920]),
            "photograph + camera noise": noisy.astype(np.uint8),
            "flat": np.full((1080, 1920, 3), 90, np.uint8)}
    try:  # a 1-spp render (the yardstick's rendered atrium still, 640x360, tiled 3x3): needs EGL or the cache
        from mlaa_stream.yardstick.scenes import SceneUnavailable, generate_scenes
        atrium = next(s for s in generate_scenes(names=["rendered"]) if s.name == "rendered_atrium")
        render = np.ascontiguousarray(np.tile(atrium.inputs[0], (3, 3, 1)))
        out["rendered (atrium still, tiled 3x3)"] = render
        grain = rng.normal(0, 4, render.shape[:2] + (1,)).round().astype(np.int16)
        out["rendered + film grain (4 levels)"] = np.clip(render.astype(np.int16) + grain, 0, 255).astype(np.uint8)
    except (SceneUnavailable, ImportError, StopIteration):
        pass
    return out


def measure(f: Filter, frame: np.ndarray, runs: int) -> tuple[float, dict[str, float]]:
    for _ in range(3):
        f.process(frame)
    times = []
    for _ in range(runs):
        t = time.perf_counter()
        f.process(frame)
        times.append((time.perf_counter() - t) * 1e3)
    return float(np.median(times)), f.profile(frame, runs=runs)


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=20)
    ap.add_argument("--preset", default="default")
    ap.add_argument("--out", default=str(ROOT / "docs" / "performance.md"))
    args = ap.parse_args(argv)
    from mlaa_stream.spatial.filter import PRESETS
    lines = []
    with Filter(**PRESETS[args.preset]) as f:
        for name, frame in frames().items():
            total, passes = measure(f, frame, args.runs)
            kernel_sum = sum(passes.values())
            shares = ", ".join(f"{k} {v:.1f} ms ({100 * v / kernel_sum:.0f} %)" for k, v in passes.items())
            lines.append(f"| {name} | {total:.1f} | {kernel_sum:.1f} | {shares} |")
            print(f"{name}: process {total:.1f} ms; passes {shares}")
        device, bpp = f.device_name, f.device_bytes_per_pixel()
    text = "\n".join([
        "# Spatial filter: time per 1920x1080 frame",
        "",
        f"- command: `python -m mlaa_stream.bench.mlaa_profile --runs {args.runs} --preset {args.preset}`",
        f"- date: {datetime.datetime.now():%Y-%m-%d %H:%M}",
        f"- device: {device}",
        f"- device memory: {bpp:.1f} bytes per pixel (8-bit RGB), allocated once per frame format",
        f"- median of {args.runs} frames after 3 warm-up frames; `process` is host to host (upload, passes,"
        " download); pass times are device times on a serialised profiling queue",
        "",
        "| frame | process (ms) | sum of passes (ms) | passes (share) |",
        "| --- | --- | --- | --- |",
        *lines, ""])
    Path(args.out).write_text(text)
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
