"""Benchmark of the topological reconstruction pass (seed 000 §4): `python -m mlaa_stream.reconstruct_bench`.

Accuracy on the yardstick scenes (wires, text_ui, photo) and ms per 1920x1080 frame of the pass alone and of
the core filter, interleaved; docs/reconstruct.md quotes it. Timings never go in unit tests.
"""
from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from .colour import device_luts
from .device import Context, default_context
from .formats import frame_format
from .reconstruct import Reconstructor, reconstruct


def centre_line(truth: np.ndarray, background: np.ndarray, wires: np.ndarray) -> np.ndarray:
    """Wire pixels on the wire's centre line: a local maximum of the truth's contrast across x or y."""
    from .metrics import contrast
    c = np.pad(contrast(truth, background), 1)
    mid = c[1:-1, 1:-1]
    across_x = (mid >= c[1:-1, :-2]) & (mid >= c[1:-1, 2:])
    across_y = (mid >= c[:-2, 1:-1]) & (mid >= c[2:, 1:-1])
    return wires & (across_x | across_y)


def bench_reconstruct(device=None, runs: int = 20, small: bool = False) -> dict:
    """Accuracy on the yardstick scenes (wires, text_ui, photo); ms per 1920x1080 frame of the pass alone and
    of the core filter, on the frames of timing_frames()."""
    from .metrics import broken_wires, damage
    from .scenes import generate_scenes

    report: dict = {}
    for scene in generate_scenes(small=small, names=["wires", "text_ui", "photo"]):
        inp, truth = scene.inputs[0], scene.truths[0]
        row: dict = {}
        outs = {"input": inp}
        for ext in (False, True):
            outs["paper+5x5" if not ext else "extended"] = reconstruct(inp, extended=ext, device=device)
        from .mlaa import Filter
        for name, rec in (("core", False), ("core+reconstruct", True)):
            with Filter(device, reconstruct=rec) as f:
                outs[name] = f.process(inp)
        for name, out in outs.items():
            r = {"changed": int((out != inp).any(-1).sum()), "damage_rmse": damage(out, inp, truth, scene.edges[0])}
            if scene.wires is not None:
                bg, w = scene.backgrounds[0], scene.wires[0]
                r["broken"] = broken_wires(out, truth, bg, w)
                r["broken_centre"] = broken_wires(out, truth, bg, centre_line(truth, bg, w))
            row[name] = r
        report[scene.name] = row
    ctx = default_context(device)
    report["device"] = ctx.name
    luts = cl.Buffer(ctx.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=device_luts())
    for name, frame in timing_frames().items():
        report[f"ms_1080p_{name}"] = _time_frame(ctx, frame, luts, runs, device)
    return report


def timing_frames() -> dict[str, np.ndarray]:
    """1920x1080 uint8 RGB frames for the speed measurement: the mixed timing frame, a photograph
    (matplotlib's grace_hopper sample, resized) and a mostly flat render (the wires scene on a plain canvas)."""
    import cv2
    from .scenes import generate_scenes, timing_frame
    frames = {"timing": timing_frame()}
    try:
        from matplotlib import cbook
        with cbook.get_sample_data("grace_hopper.jpg") as f:
            photo = cv2.imdecode(np.frombuffer(f.read(), np.uint8), cv2.IMREAD_COLOR)[..., ::-1]
        frames["photo"] = np.ascontiguousarray(cv2.resize(photo, (1920, 1080), interpolation=cv2.INTER_LINEAR))
    except (ImportError, OSError, ValueError):  # pragma: no cover - matplotlib's sample data is optional
        pass
    wires = generate_scenes(names=["wires"])[0].inputs[0]
    flat = np.empty((1080, 1920, 3), np.uint8)
    flat[:] = wires[0, 0]
    flat[:wires.shape[0], :wires.shape[1]] = wires
    frames["flat"] = flat
    return frames


def _time_frame(ctx: Context, frame: np.ndarray, luts: "cl.Buffer", runs: int, device) -> dict[str, float]:
    """Median ms of the pass (device copy + kernel) for both rule sets, and of the core filter
    (Filter().process: upload, kernels, download) on the same frame, after 3 warm-up runs each; and their ratios."""
    from .mlaa import Filter
    fmt = frame_format(frame)
    src = cl.Buffer(ctx.ctx, cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR, hostbuf=np.ascontiguousarray(frame))
    dst = ctx.buffer(fmt.nbytes)
    out: dict[str, float] = {}

    def median_ms(step) -> float:
        for _ in range(3):
            step()
        times = []
        for _ in range(runs):
            t0 = time.perf_counter()
            step()
            times.append((time.perf_counter() - t0) * 1e3)
        return round(float(np.median(times)), 2)

    for ext in (False, True):
        rec = Reconstructor(ctx, fmt, extended=ext)
        out["extended" if ext else "paper"] = median_ms(lambda: rec.enqueue(ctx.queue, src, dst, luts).wait())
    with Filter(device) as f:
        out["core_filter"] = median_ms(lambda: f.process(frame))
    for rules in ("paper", "extended"):  # issue #5's budget: the pass at most half the core filter
        out[f"{rules}_vs_core"] = round(out[rules] / out["core_filter"], 2)
    return out


def main() -> None:
    import argparse
    import json
    p = argparse.ArgumentParser(description="Benchmark the reconstruction pass (docs/reconstruct.md).")
    p.add_argument("--device", default=None)
    p.add_argument("--runs", type=int, default=20)
    p.add_argument("--small", action="store_true")
    args = p.parse_args()
    print(json.dumps(bench_reconstruct(args.device, args.runs, args.small), indent=1))


if __name__ == "__main__":
    main()
