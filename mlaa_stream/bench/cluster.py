"""Frames per second of one temporal job: the plain pipeline against `--cluster local:1` and `local:2`.

    python -m mlaa_stream.bench.cluster [--frames 64] [--size 320x180] [--chunks 16,64] [--rounds 3]

A sub-pixel pan (mlaa_stream/bench/temporal.py) is written as a PNG sequence to a temporary folder; each
configuration runs the command line in a new process (`mlaa-stream IN -o OUT --temporal ...`), in
interleaved rounds (plain, local:1, local:2, ... then again), and the median wall time of the rounds is
reported as frames per second of the whole job: process start, cluster start, kernel builds and each
chunk's warm-up frames included (the warm-up is what temporal adds on a cluster).
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

CLI = "from mlaa_stream.cli.main import main; main()"


def write_sequence(folder: str, frames: int, w: int, h: int) -> str:
    from mlaa_stream.bench.temporal import scene_pan
    from mlaa_stream.io.images import write_image

    os.makedirs(folder, exist_ok=True)
    for k, img in enumerate(scene_pan(frames, w, h).inputs):
        write_image(os.path.join(folder, f"p.{k:04d}.png"), img)
    return os.path.join(folder, "p.%04d.png")


def run_once(pattern: str, out: str, extra: list[str]) -> float:
    cmd = [sys.executable, "-c", CLI, pattern, "-o", os.path.join(out, "c.%04d.png"), "--overwrite", "-q",
           "--temporal", *extra]
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True)
    return time.perf_counter() - t0


def main(argv: list[str] | None = None) -> None:
    from mlaa_stream.cluster.temporal import TemporalSpec
    from mlaa_stream.device.context import default_context

    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=64)
    ap.add_argument("--size", default="320x180")
    ap.add_argument("--chunks", default="16,64", help="--chunk-frames values for the cluster runs")
    ap.add_argument("--workers", default="1,2")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--method", default="tss", choices=["tss", "blend", "tss+blend"])
    a = ap.parse_args(argv)
    w, h = (int(v) for v in a.size.split("x"))
    configs = [("plain", [])]
    for c in (int(v) for v in a.chunks.split(",")):
        for n in (int(v) for v in a.workers.split(",")):
            configs.append((f"local:{n} chunk {c}", ["--cluster", f"local:{n}", "--chunk-frames", str(c)]))
    warm = TemporalSpec(a.method).warmup
    with tempfile.TemporaryDirectory(prefix="mlaa-bench-cluster-") as tmp:
        pattern = write_sequence(os.path.join(tmp, "in"), a.frames, w, h)
        times: dict[str, list[float]] = {name: [] for name, _ in configs}
        for _ in range(a.rounds):
            for name, extra in configs:
                times[name].append(run_once(pattern, os.path.join(tmp, "out"),
                                            ["--temporal-method", a.method, *extra]))
    print(f"device: {default_context(None).name}; {a.frames} frames of {w}x{h}, --temporal-method {a.method} "
          f"(warm-up {warm} frames per chunk after the first), median of {a.rounds} interleaved rounds, "
          f"load average {os.getloadavg()[0]:.1f}")
    print("| run | wall s | fps | frames filtered |")
    print("| --- | --- | --- | --- |")
    for name, extra in configs:
        t = statistics.median(times[name])
        chunk = int(extra[-1]) if extra else 0
        starts = range(chunk, a.frames, chunk) if chunk else ()
        filtered = a.frames + sum(min(warm, s) for s in starts)
        print(f"| {name} | {t:.2f} | {a.frames / t:.1f} | {filtered} |")


if __name__ == "__main__":
    main()
