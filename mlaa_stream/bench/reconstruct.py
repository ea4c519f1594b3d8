"""Benchmark of the topological reconstruction pass (seed 000 §4): `python -m mlaa_stream.bench.reconstruct`.

Accuracy on the yardstick scenes (wires, text_ui, photo) and ms per 1920x1080 frame of the pass alone and of
the core filter, interleaved; docs/reconstruct.md quotes it. Timings never go in unit tests.
"""
from __future__ import annotations

import time

import numpy as np
import pyopencl as cl

from mlaa_stream.device.colour import device_luts
from mlaa_stream.device.context import Context, default_context
from mlaa_stream.device.formats import frame_format
from mlaa_stream.spatial.reconstruct import Reconstructor, reconstruct


def centre_line(truth: np.ndarray, background: np.ndarray, wires: np.ndarray) -> np.ndarray:
    """Wire pixels on the wire's centre line: a local maximum of the truth's contrast across x or y."""
    from mlaa_stream.yardstick.metrics import contrast
    c = np.pad(contrast(truth, background), 1)
    mid = c[1:-1, 1:-1]
    across_x = (mid >= c[1:-1, :-2]) & (mid >= c[1:-1, 2:])
    across_y = (mid >= c[:-2, 1:-1]) & (mid >= c[2:, 1:-1])
    return wires & (across_x | across_y)


def bench_reconstruct(device=None, runs: int = 20, small: bool = False, split: bool = False) -> dict:
    """Accuracy on the yardstick scenes (wires, text_ui, photo); ms per 1920x1080 frame of the pass alone and
    of the core filter, on the frames of timing_frames(); with `split`, also the timing of the pass's parts
    and how many pixels each kind of RGB bound would send on to CIELAB (gate_stats)."""
    from mlaa_stream.yardstick.metrics import broken_wires, damage
    from mlaa_stream.yardstick.scenes import generate_scenes

    report: dict = {}
    for scene in generate_scenes(small=small, names=["wires", "text_ui", "photo"]):
        inp, truth = scene.inputs[0], scene.truths[0]
        row: dict = {}
        outs = {"input": inp}
        for ext in (False, True):
            outs["paper+5x5" if not ext else "extended"] = reconstruct(inp, extended=ext, device=device)
        from mlaa_stream.spatial.filter import Filter
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
        report[f"ms_1080p_{name}"] = _time_frame(ctx, frame, luts, runs, device, split)
        if split:
            report[f"gate_stats_{name}"] = gate_stats(frame)
    return report


def gate_stats(frame: np.ndarray, threshold: float = 10.0) -> dict[str, float]:
    """Share of an 8-bit RGB frame's pixels (and of its 8-pixel groups) where a rule may fire -- two ring
    neighbours at ring distance >= 3 over the threshold, the kernel's table bit 1 -- by each way of bounding
    ΔE76 from RGB: the kernel's rigorous bound (global Lipschitz constant x max-channel difference); the
    same with the Lipschitz constant at A's own colour (no margin: what any direction-free bound can reach
    at best); the linearisation J(A) (rgb_b - rgb_a) (no margin: what a direction-aware bound can reach at
    best); and exact CIELAB. Also the share where the exact mask is a gap (the rules run)."""
    from mlaa_stream.device.colour import rgb_to_lab
    from mlaa_stream.spatial.reconstruct import _device_table, cheap_levels
    table = _device_table()
    may = (table & 2).astype(bool)
    h, w = frame.shape[:2]
    rgb = frame[..., :3].astype(np.float64) / 255.0
    lab = rgb_to_lab(rgb)
    step = 1.0 / 255.0
    jac = [(rgb_to_lab(np.clip(rgb + np.eye(3)[c] * step, 0.0, 1.0)) - lab) / step for c in range(3)]
    k_local = np.zeros((h, w))
    for sgn in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T:
        d = jac[0] * sgn[0] + jac[1] * sgn[1] + jac[2] * sgn[2]
        k_local = np.maximum(k_local, np.sqrt((d * d).sum(-1)))
    near = cheap_levels(threshold, 255.0)[0]
    pad_i = np.pad(frame[..., :3].astype(np.int32), ((1, 1), (1, 1), (0, 0)), mode="edge")
    pad_l = np.pad(lab, ((1, 1), (1, 1), (0, 0)), mode="edge")
    masks = {k: np.zeros((h, w), np.int32) for k in ("rgb_gate", "local_lipschitz", "linearised", "exact")}
    ring = [(-1, -1), (0, -1), (1, -1), (1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0)]
    for k, (dx, dy) in enumerate(ring):
        diff = pad_i[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] - pad_i[1:-1, 1:-1]
        m = np.abs(diff).max(-1)
        lin = sum(jac[c] * (diff[..., c:c + 1] / 255.0) for c in range(3))
        dl = pad_l[1 + dy:1 + dy + h, 1 + dx:1 + dx + w] - lab
        for name, over in (("rgb_gate", m >= near), ("local_lipschitz", m / 255.0 * k_local > threshold),
                           ("linearised", (lin * lin).sum(-1) > threshold ** 2),
                           ("exact", (dl * dl).sum(-1) > threshold ** 2)):
            masks[name] |= over.astype(np.int32) << k
    out: dict[str, float] = {}
    w8 = w // 8 * 8
    for name, mask in masks.items():
        px = may[mask]
        out[f"{name}_pixels"] = round(float(px.mean()), 4)
        out[f"{name}_groups"] = round(float(px[:, :w8].reshape(h, -1, 8).any(-1).mean()), 4)
    out["exact_gap_pixels"] = round(float((table[masks["exact"]] & 1).astype(bool).mean()), 4)
    return out


def timing_frames() -> dict[str, np.ndarray]:
    """1920x1080 uint8 RGB frames for the speed measurement: the mixed timing frame, a photograph
    (matplotlib's grace_hopper sample, resized) and a mostly flat render (the wires scene on a plain canvas)."""
    import cv2
    from mlaa_stream.yardstick.scenes import generate_scenes, timing_frame
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


def _time_frame(ctx: Context, frame: np.ndarray, luts: "cl.Buffer", runs: int, device,
                split: bool = False) -> dict[str, float]:
    """Median ms of the pass (device copy + kernel) for both rule sets, and of the core filter
    (Filter().process: upload, kernels, download) on the same frame, after 3 warm-up runs each; and their ratios.
    With `split`, the extended pass stopped after the RGB gate and before the rules (STOP_AFTER 1, 2), all
    interleaved in one loop."""
    from mlaa_stream.spatial.filter import Filter
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

    if split:
        steps = {}
        for stop, name in ((1, "gate_only"), (2, "gate_cielab"), (0, "extended")):
            rec = Reconstructor(ctx, fmt, extended=True)
            if stop:
                rec._kernel = ctx.kernel("reconstruct", "reconstruct", {**rec.defines, "STOP_AFTER": stop})
            steps[name] = lambda rec=rec: rec.enqueue(ctx.queue, src, dst, luts).wait()
        with Filter(device) as f:
            steps["core_filter"] = lambda: f.process(frame)
            times: dict[str, list[float]] = {k: [] for k in steps}
            for it in range(runs + 3):
                for k, step in steps.items():
                    t0 = time.perf_counter()
                    step()
                    if it >= 3:
                        times[k].append((time.perf_counter() - t0) * 1e3)
        core = float(np.median(times["core_filter"]))
        for k, v in times.items():
            out[k] = round(float(np.median(v)), 2)
            out[f"{k}_vs_core"] = round(float(np.median(v)) / core, 2)
        return out
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
    p.add_argument("--split", action="store_true",
                   help="time the pass's parts (RGB gate, + CIELAB, + rules) and count what each RGB bound lets through")
    args = p.parse_args()
    print(json.dumps(bench_reconstruct(args.device, args.runs, args.small, args.split), indent=1))


if __name__ == "__main__":
    main()
