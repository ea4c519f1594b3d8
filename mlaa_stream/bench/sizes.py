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
    from mlaa_stream.yardstick.scenes import timing_frame

    content = timing_frame()  # crops of the mixed timing frame: realistic content at every size
    f = Filter(preset=args.preset)
    t0 = time.perf_counter()
    f.process(np.ascontiguousarray(content[:200, :300]))
    build = time.perf_counter() - t0
    first, again = [], []
    for h, w in rng.integers(40, 720, (args.sizes, 2)):
        y, x = int(rng.integers(0, 1080 - h)), int(rng.integers(0, 1920 - w))
        frame = np.ascontiguousarray(content[y:y + h, x:x + w])
        t0 = time.perf_counter()
        f.process(frame)
        t1 = time.perf_counter()
        f.process(frame)  # the same size again: the frame's own cost, without anything size-specific
        first.append(t1 - t0)
        again.append(time.perf_counter() - t1)
    extra = np.array(first) - np.array(again)
    print(f"device: {f.device_name}; preset {args.preset}")
    print(f"first size (kernel builds, or PoCL's disk cache): {1000 * build:.0f} ms")
    print(f"{args.sizes} new sizes (crops of the mixed frame, 40-720 px a side): first frame median "
          f"{1000 * np.median(first):.1f} ms; the same frame again {1000 * np.median(again):.1f} ms; what a new "
          f"size adds: median {1000 * np.median(extra):.1f} ms, max {1000 * extra.max():.1f} ms")


if __name__ == "__main__":
    main()
