"""How far a chunk's temporal output is from one machine's after W warm-up frames (issue 18).

    python -m mlaa_stream.bench.warmup [--frames 48] [--size 160x96] [--chunk 16] [--warmup 0,4,8,16]
        [--ring K] [--hold AT:N]

For each temporal method and bench scene (mlaa_stream/bench/temporal.py: pan, rotation, mover, cut), one
stage runs over every frame (the single machine); then, for each chunk start s (every --chunk frames)
and each W, a new stage runs over frames s-W .. s+chunk-1 as a cluster worker does
(mlaa_stream/cluster/temporal.py) and its outputs of s .. s+chunk-1 are compared with the single
machine's: the largest difference in 8-bit levels over all chunks and the share of samples that differ.
--ring sets TSS's K; --hold AT:N repeats frame AT N more times (a held frame: the scene pauses), the
sequence cut back to --frames.
No Dask: the stage is the same object the workers build (TemporalSpec.stage).
"""
from __future__ import annotations

import argparse

import numpy as np

from mlaa_stream.bench.temporal import SCENES
from mlaa_stream.cluster.temporal import TemporalSpec


def outputs(spec: TemporalSpec, filt, inputs: np.ndarray, spatial: list[tuple], first: int,
            last: int) -> list[np.ndarray]:
    """The stage's outputs for frames first .. last-1 (a new stage, as a worker's); `spatial`: per frame
    the filter's output and its render regions."""
    stage = spec.stage(filt)
    try:
        return [np.array(stage(inputs[t], spatial[t][0], t, regions=spatial[t][1])) for t in range(first, last)]
    finally:
        stage.close()


def measure(spec: TemporalSpec, filt, inputs: np.ndarray, chunk: int, warmups: list[int]) -> dict[int, tuple]:
    """{W: (max |difference| in levels, share of samples that differ)} over every chunk after the first."""
    n = len(inputs)
    spatial = [(filt.process(f), filt.last_regions) for f in inputs]
    single = outputs(spec, filt, inputs, spatial, 0, n)
    res = {}
    for w in warmups:
        worst, differ, total = 0, 0, 0
        for s in range(chunk, n, chunk):
            e = min(n, s + chunk)
            got = outputs(spec, filt, inputs, spatial, max(0, s - w), e)[-(e - s):]
            for a, b in zip(got, single[s:e]):
                d = np.abs(a.astype(np.int16) - b.astype(np.int16))
                worst, differ, total = max(worst, int(d.max())), differ + int((d > 0).sum()), total + d.size
        res[w] = (worst, differ / max(total, 1))
    return res


def main(argv: list[str] | None = None) -> None:
    from mlaa_stream.spatial.filter import Filter

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=48)
    ap.add_argument("--size", default="160x96")
    ap.add_argument("--chunk", type=int, default=16)
    ap.add_argument("--warmup", default="0,4,8,16")
    ap.add_argument("--methods", default="tss,blend,tss+blend")
    ap.add_argument("--scenes", default="pan,rotation,mover,cut")
    ap.add_argument("--ring", type=int, default=None, help="TSS's K (default: tss.DEFAULT_FRAMES)")
    ap.add_argument("--hold", default=None, metavar="AT:N", help="repeat frame AT N more times")
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    warmups = [int(v) for v in a.warmup.split(",")]
    filt = Filter(bgr=False, keep_regions=True)
    print(f"device: {filt.device_name}; {a.frames} frames of {w}x{h}, chunks of {a.chunk}, ring K = "
          f"{TemporalSpec('tss', a.ring).ring}" + (f", frame {a.hold.split(':')[0]} held {a.hold.split(':')[1]} more times"
                                                    if a.hold else ""))
    print("| method | scene | " + " | ".join(f"W={v}: max / share" for v in warmups) + " |")
    print("| --- | --- | " + " | ".join("---" for _ in warmups) + " |")
    for name in a.scenes.split(","):
        inputs = SCENES[name](a.frames, w, h).inputs
        if a.hold:
            at, n = (int(v) for v in a.hold.split(":"))
            inputs = np.concatenate([inputs[:at + 1], np.repeat(inputs[at:at + 1], n, 0), inputs[at + 1:]])[:a.frames]
        for method in a.methods.split(","):
            res = measure(TemporalSpec(method, a.ring), filt, inputs, a.chunk, warmups)
            print(f"| {method} | {name} | " + " | ".join(f"{res[v][0]} / {res[v][1]:.2%}" for v in warmups) + " |",
                  flush=True)


if __name__ == "__main__":
    main()
