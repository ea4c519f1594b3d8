"""Benchmark of the bridging pass: `python -m mlaa_stream.bench.bridge`.

Per yardstick scene Filter(bridge=False) against Filter() (error removed, damage, broken wire pixels, pixels
changed), then ms per 1920x1080 frame, interleaved; docs/reconstruct.md quotes it.
"""
from __future__ import annotations

import numpy as np
import pyopencl as cl

from mlaa_stream.spatial.bridge import Bridger
from mlaa_stream.device.colour import device_luts
from mlaa_stream.device.context import default_context
from mlaa_stream.device.formats import frame_format


def _detailed_photo() -> np.ndarray:
    """matplotlib's grace_hopper sample tiled 1:1 to 1920x1080 (no resampling: every detail kept)."""
    import matplotlib.cbook as cbook
    import matplotlib.image

    img = matplotlib.image.imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[..., :3]
    return np.ascontiguousarray(np.tile(img, (3, 4, 1))[:1080, :1920])


def bench_bridge(device=None, runs: int = 25) -> dict:
    """Per yardstick scene: error removed, damage, broken wire pixels (all and centre line) and pixels changed,
    Filter(bridge=False) against Filter(); then median ms per 1920x1080 frame of the core filter, the filter
    with bridging, and the pass alone (device buffers), interleaved, after 3 warm-up runs."""
    import time

    from mlaa_stream.bench.accuracy import score_scene
    from mlaa_stream.yardstick.metrics import broken_wires
    from mlaa_stream.spatial.filter import Filter
    from mlaa_stream.bench.reconstruct import centre_line, timing_frames
    from mlaa_stream.yardstick.scenes import generate_scenes, timing_frame

    report: dict = {"device": default_context(device).name, "scenes": {}}
    with Filter(device, bridge=False) as core, Filter(device) as bridged:
        for s in generate_scenes():
            row = {}
            outs = {}
            for name, f in (("core", core), ("core+bridge", bridged)):
                f.new_shot()  # each scene its own shot
                outs[name] = out = np.stack([f.process(x) for x in s.inputs])
                r = {k: score_scene(out, s, False)[k] for k in ("error_removed", "damage", "broken_wires")}
                if s.wires is not None:
                    r["broken_centre"] = float(np.mean([broken_wires(o, t, g, centre_line(t, g, w)) for o, t, g, w
                                                        in zip(out, s.truths, s.backgrounds, s.wires)]))
                row[name] = r
            row["changed"] = int((outs["core"] != outs["core+bridge"]).any(-1).sum())
            report["scenes"][s.name] = row
        wires = generate_scenes(names=["wires"])[0].inputs[0]
        frames = {"timing": timing_frame(), "photo": timing_frames().get("photo"),
                  "wires_tiled": np.ascontiguousarray(np.tile(wires, (5, 5, 1))[:1080, :1920]),
                  "detailed_photo": _detailed_photo()}
        ctx = default_context(device)
        mf = cl.mem_flags
        luts = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=device_luts())
        for name, fr in frames.items():
            if fr is None:
                continue
            src = cl.Buffer(ctx.ctx, mf.READ_ONLY | mf.COPY_HOST_PTR, hostbuf=fr)
            dst = cl.Buffer(ctx.ctx, mf.READ_WRITE | mf.COPY_HOST_PTR, hostbuf=fr)
            pas = Bridger(ctx, frame_format(fr))
            steps = {"core": lambda: core.process(fr), "core+bridge": lambda: bridged.process(fr),
                     "pass": lambda: pas.enqueue(ctx.queue, src, dst, luts).wait()}
            times: dict[str, list[float]] = {k: [] for k in steps}
            for k in range(runs + 3):
                for key, step in steps.items():
                    t0 = time.perf_counter()
                    step()
                    if k >= 3:
                        times[key].append((time.perf_counter() - t0) * 1e3)
            report[f"ms_1080p_{name}"] = {k: round(float(np.median(v)), 2) for k, v in times.items()}
    return report


def main() -> None:
    import argparse
    ap = argparse.ArgumentParser(description=bench_bridge.__doc__)
    ap.add_argument("--device", default=None)
    ap.add_argument("--runs", type=int, default=25)
    args = ap.parse_args()
    rep = bench_bridge(args.device, args.runs)
    print(f"device: {rep['device']}")
    print("| scene | error removed (core / +bridge) | damage | broken | broken (centre line) | px changed |")
    print("| --- | --- | --- | --- | --- | --- |")
    for name, row in rep["scenes"].items():
        a, b = row["core"], row["core+bridge"]
        broken = (f"{100 * a['broken_wires']:.1f}% / {100 * b['broken_wires']:.1f}%"
                  if a["broken_wires"] == a["broken_wires"] else "")
        centre = f"{100 * a['broken_centre']:.1f}% / {100 * b['broken_centre']:.1f}%" if "broken_centre" in a else ""
        print(f"| {name} | {100 * a['error_removed']:.1f}% / {100 * b['error_removed']:.1f}% | "
              f"{a['damage']:.2f} / {b['damage']:.2f} | {broken} | {centre} | {row['changed']} |")
    for key, val in rep.items():
        if key.startswith("ms_"):
            print(f"{key}: core {val['core']} ms, core+bridge {val['core+bridge']} ms, pass {val['pass']} ms "
                  f"({100 * val['pass'] / val['core']:.0f}% of the core)")


if __name__ == "__main__":
    main()
