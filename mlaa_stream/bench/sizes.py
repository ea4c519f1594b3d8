"""How long the first frame of a new size takes, after the first size's kernel builds (issue 17: kernel
builds per frame size). Run it in a fresh process: PoCL caches compiled kernels on disk, so pass --fresh to
start from random sizes this machine has not seen.

    python -m mlaa_stream.bench.sizes [--sizes 12] [--preset default] [--seed N]
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from mlaa_stream.spatial.filter import PRESETS, Filter


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(prog="python -m mlaa_stream.bench.sizes", description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", type=int, default=12, help="new frame sizes after the first")
    ap.add_argument("--preset", default="default", choices=sorted(PRESETS))
    ap.add_argument("--seed", type=int, default=None, help="random sizes (default: from the clock: unseen)")
    args = ap.parse_args(argv)
    rng = np.random.default_rng(args.seed if args.seed is not None else time.time_ns())
    f = Filter(preset=args.preset)
    first = (rng.random((200, 300, 3)) * 255).astype(np.uint8)
    t0 = time.perf_counter()
    f.process(first)
    build = time.perf_counter() - t0
    times, pixels = [], 0
    for h, w in rng.integers(40, 720, (args.sizes, 2)):
        frame = (rng.random((int(h), int(w), 3)) * 255).astype(np.uint8)
        t0 = time.perf_counter()
        f.process(frame)
        times.append(time.perf_counter() - t0)
        pixels += int(h) * int(w)
    print(f"device: {f.device_name}; preset {args.preset}")
    print(f"first size (kernel builds, or PoCL's disk cache): {1000 * build:.0f} ms")
    print(f"first frame of each of {args.sizes} new sizes: median {1000 * np.median(times):.0f} ms, "
          f"max {1000 * max(times):.0f} ms; mixed-size throughput {args.sizes / sum(times):.1f} frames/s "
          f"({pixels / sum(times) / 1e6:.1f} Mpx/s)")


if __name__ == "__main__":
    main()
