"""The default filter's speed in several checkouts, interleaved: `python -m mlaa_stream.bench.checkouts A B ...`.

Each checkout (a git worktree, e.g. `git worktree add /tmp/old <commit>`) runs in its own process with its own
`mlaa_stream` on the path and times `Filter().process` on 1920x1080 frames: the yardstick's mixed timing frame, a
photograph, and a 1-spp render (the rendered atrium still tiled 3x3, where the rendered scenes are available).
`--stage tss`: the temporal supersampling stage instead (TSSStage, K = 16, causal) on three 1080p shots (the frames
as their own spatial output): mlaa_stream.bench.temporal's timing pan (one translation per ring frame:
tss_resolve_shift) and turning layer (moving layers: tss_resolve over the layers' box), and the timing frame zooming
0.3 % per frame with dense_samples (`--dense-motion`: every timed frame resolved through tracked tiles, tss_resolve
over the frame); per shot its host motion (stats "flow_ms"), its resolve ("resolve_ms")
and the whole call, median over the frames after the K warm-up frames.
Rounds alternate the checkouts (A, B, A, B, ...), so a busy machine slows all of them alike; the report is the
median over rounds of each checkout's median ms per frame, and its ratio to the first checkout's. A benchmark,
never a unit test.
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

# Run inside each checkout: prints {"frame name": median ms} as JSON on its last line. Self-contained (it builds
# the frames as bench/mlaa_profile.py does): an older checkout has only Filter and timing_frame to offer.
_TIMER = r"""
import json, sys, time
import numpy as np
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.yardstick.scenes import timing_frame
import cv2, matplotlib.image
from matplotlib import cbook
runs = int(sys.argv[1])
img = matplotlib.image.imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[..., :3]
frames = {"mixed": timing_frame(),
          "photo": np.ascontiguousarray(cv2.resize(np.ascontiguousarray(img), (1920, 1080),
                                                   interpolation=cv2.INTER_CUBIC))}
try:
    from mlaa_stream.yardstick.scenes import generate_scenes
    atrium = [s for s in generate_scenes(names=["rendered"]) if s.name == "rendered_atrium"][0]
    frames["rendered"] = np.ascontiguousarray(np.tile(atrium.inputs[0], (3, 3, 1)))
except Exception:
    pass
f = Filter()
out = {}
for name, fr in frames.items():
    for _ in range(3):
        f.process(fr)
    ts = []
    for _ in range(runs):
        t = time.perf_counter()
        f.process(fr)
        ts.append(time.perf_counter() - t)
    out[name] = 1000 * float(np.median(ts))
print(json.dumps(out))
"""

# --stage tss: the same contract, for the temporal supersampling stage on three 1080p shots
_TSS_TIMER = r"""
import json, sys, time
import cv2
import numpy as np
from mlaa_stream.bench.temporal import _pan_frames, _turning_frames
from mlaa_stream.temporal.tss import TSSStage
from mlaa_stream.yardstick.scenes import timing_frame
runs, k = int(sys.argv[1]), 16
base = timing_frame(1936, 1096)
zoom = [cv2.warpAffine(base, cv2.getRotationMatrix2D((968.3, 548.2), 0.0, 1.0 + 0.003 * t), (1936, 1096),
                       flags=cv2.INTER_LINEAR)[8:1088, 8:1928] for t in range(k + runs)]
out = {}
for shot, frames, dense in (("pan", _pan_frames(k + runs, base), False),
                            ("turning", _turning_frames(k + runs, base), False), ("dolly", zoom, True)):
    with TSSStage(None, frames=k, bgr=False, dense_samples=dense) as st:
        ts = []
        for i, f in enumerate(frames):
            t = time.perf_counter()
            st(f, f, i)
            ts.append(time.perf_counter() - t)
        rows = st.stats[k:]
        out.update({f"{shot} motion": float(np.median([r["flow_ms"] for r in rows])),
                    f"{shot} resolve": float(np.median([r["resolve_ms"] for r in rows])),
                    f"{shot} stage": 1000 * float(np.median(ts[k:]))})
print(json.dumps(out))
"""
TIMERS = {"filter": _TIMER, "tss": _TSS_TIMER}


def time_checkout(root: Path, runs: int, stage: str = "filter") -> dict[str, float]:
    """Median ms per frame of each timing frame (`stage` "filter") or of the TSS stage's parts ("tss") in checkout
    `root` (a fresh process)."""
    env = {**os.environ, "PYTHONPATH": str(root)}
    done = subprocess.run([sys.executable, "-c", TIMERS[stage], str(runs)], cwd=root, env=env, capture_output=True,
                          text=True, check=True)
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("checkouts", nargs="+", type=Path, help="checkout roots; ratios are to the first")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--runs", type=int, default=15, help="frames timed per frame kind and round")
    ap.add_argument("--stage", choices=sorted(TIMERS), default="filter",
                    help="filter: the default spatial filter; tss: the temporal supersampling stage on 1080p "
                         "shots (a pan, a turning layer, a dolly with dense motion)")
    args = ap.parse_args(argv)
    roots = [p.resolve() for p in args.checkouts]
    results: dict[Path, list[dict[str, float]]] = {r: [] for r in roots}
    for k in range(args.rounds):
        for r in roots:
            results[r].append(time_checkout(r, args.runs, args.stage))
            print(f"round {k + 1}: {r}: " + ", ".join(f"{n} {v:.1f} ms" for n, v in results[r][-1].items()),
                  flush=True)
    names = [n for n in results[roots[0]][0] if all(n in res[0] for res in results.values())]
    med = {r: {n: float(np.median([res[n] for res in results[r]])) for n in names} for r in roots}
    print("\n| checkout | " + " | ".join(f"{n} ms (x first)" for n in names) + " |")
    print("|---" * (len(names) + 1) + "|")
    for r in roots:
        print(f"| {r} | " + " | ".join(f"{med[r][n]:.1f} ({med[r][n] / med[roots[0]][n]:.2f}x)" for n in names)
              + " |")


if __name__ == "__main__":
    main()
