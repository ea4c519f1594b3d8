"""Held-out rendered shots through H.264: the render verdict held over a shot against each frame judged alone.

    python -m mlaa_stream.bench.codec_shots [--sizes 960x540] [--frames 12] [--crf 0,18,23,28]
                                            [--worlds plaza,town] [--shots far_tele_pan,...] [--verdicts]
                                            [--methods alone,held,fxaa,mlaa:rendered]

A video codec spends its bits unevenly: a compressed render's keyframe keeps the busy texture that makes the frame
a render (spatial/fallback.py RENDER_FRAME_PCT), its P- and B-frames may fall under it, and then the verdict flips
from frame to frame. Each held-out shot (bench/rendered_views.py view_cameras: a pan and a dolly per view) is
rendered like the bench's (1 spp; truth 8x8 samples in linear light), sent through libx264 (veryfast, as
codec_check; crf 0: uncompressed), and filtered by the default with `hold_render` off ("alone") and on ("held",
spatial/shots.py), and by any other method of `mlaa-stream bench` named in `--methods` (a fresh one per shot).
Per shot and CRF (`--verdicts`: first the frames judged a render by their own share, R, or not, .): error
removed % (the mean over frames, the codec's frame counted as the input) / temporal error relative to the input's /
damage away from edges (levels, mean over frames), for each method. Needs EGL (`pip install 'mlaa-stream[bench]'`).
A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse

import numpy as np

from mlaa_stream.bench.accuracy import METHODS, close_processor, run_frames
from mlaa_stream.bench.codec_check import through_h264
from mlaa_stream.bench.rendered_views import WORLD_VIEWS, view_cameras
from mlaa_stream.spatial.fallback import render_regions_of
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.rendered import Renderer, _context, egl_available


SETTINGS = {"alone": False, "held": True}   # --methods: the default with hold_render off / on


def shot_frames(world: str, width: int, height: int, frames: int, names: list[str] | None):
    """(shot name, inputs, truths) of `world`'s held-out shots (all, or those in `names`)."""
    renderer = Renderer(_context(), width, height, world)
    try:
        for name, cams in view_cameras(width, height, frames, world).items():
            if names is None or name in names:
                yield (name, np.stack([renderer.input_frame(c) for c in cams]),
                       np.stack([renderer.truth_frame(c) for c in cams]))
    finally:
        renderer.release()


def own_verdict(passes_filter: Filter, frame: np.ndarray) -> str:
    """'R' where `frame` judged alone is a render (holding the verdict would change none of its regions), '.' where
    not; `passes_filter`: a Filter with the fallback off (the MLAA passes' output for the reference)."""
    passes = passes_filter.intermediates(frame)
    alone = render_regions_of(frame, passes["out"], passes["edges"])
    return "R" if np.array_equal(alone, render_regions_of(frame, passes["out"], passes["edges"], held=True)) else "."


def scores(outs: np.ndarray, inputs: np.ndarray, truths: np.ndarray) -> tuple[float, float, float]:
    """Error removed (mean over frames), temporal error, damage away from edges (mean over frames)."""
    removed = float(np.mean([M.error_removed(o, i, t) for o, i, t in zip(outs, inputs, truths)]))
    dmg = float(np.mean([M.damage(o, i, t) for o, i, t in zip(outs, inputs, truths)]))
    return removed, M.temporal_error(outs, inputs, truths), dmg


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="960x540", help="WxH,... (even sizes: the codec's 4:2:0)")
    ap.add_argument("--frames", type=int, default=12, help="frames per shot (default %(default)s)")
    ap.add_argument("--crf", default="0,18,23,28", help="libx264 CRFs, comma-separated; 0: uncompressed")
    ap.add_argument("--worlds", default="plaza,town", help=f"of {', '.join(WORLD_VIEWS)}, comma-separated")
    ap.add_argument("--shots", default="", help="shot names (VIEW_pan, VIEW_dolly), comma-separated; default all")
    ap.add_argument("--verdicts", action="store_true",
                    help="also print each frame's own verdict (R: a render by its own share; the numpy reference, "
                         "~1 s a frame at 960x540)")
    ap.add_argument("--methods", default="alone,held",
                    help="comma-separated: alone (the default judging each frame by itself), held (the default), or "
                         f"methods of the bench ({', '.join(m for m in METHODS if m != 'mlaa')})")
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    methods = [m for m in args.methods.split(",") if m]
    unknown = [m for m in methods if m not in SETTINGS and m not in METHODS]
    if not methods or unknown:
        raise SystemExit(f"--methods: expected alone, held or methods of the bench, got {args.methods!r}")
    ok, why = egl_available()
    if not ok:
        raise SystemExit(f"rendered shots need a headless OpenGL context: {why}")
    worlds = [w for w in args.worlds.split(",") if w]
    if not worlds or any(w not in WORLD_VIEWS for w in worlds):
        raise SystemExit(f"--worlds: expected names from {', '.join(WORLD_VIEWS)}, got {args.worlds!r}")
    try:
        crfs = [int(c) for c in args.crf.split(",") if c]
        sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    except ValueError:
        raise SystemExit("--crf / --sizes: expected integers, comma-separated (sizes as WxH)") from None
    if args.frames < 2:
        raise SystemExit("--frames: at least 2 (temporal error compares frames)")
    names = [s for s in args.shots.split(",") if s] or None
    verdicts = f"{'own verdicts':{args.frames}s}" if args.verdicts else ""
    print(f"{'shot':34s} {'crf':>4s}  {verdicts}" + "".join(f"  {m:>20s}" for m in methods))
    means: dict[tuple[int, str], list] = {}
    passes_filter = Filter(device=args.device, fallback="off")
    for world in worlds:
        for width, height in sizes:
            for name, inputs, truths in shot_frames(world, width, height, args.frames, names):
                for crf in crfs:
                    coded = through_h264(inputs, crf) if crf else inputs
                    row = f"{world + ':' + name + f'_{width}':34s} {crf:4d}  "
                    if args.verdicts:
                        row += f"{''.join(own_verdict(passes_filter, f) for f in coded):{args.frames}s}"
                    for m in methods:
                        proc = (Filter(device=args.device, hold_render=SETTINGS[m]) if m in SETTINGS
                                else METHODS[m](args.device))
                        try:
                            outs = run_frames(proc, coded)
                        finally:
                            close_processor(proc)
                        s = scores(outs, coded, truths)
                        means.setdefault((crf, m), []).append(s)
                        row += f"  {100 * s[0]:6.1f} / {s[1]:.3f} / {s[2]:.2f}"
                    print(row, flush=True)
    passes_filter.close()
    for crf in crfs:
        cells = [f"{m} {100 * v[0]:.1f} % / {v[1]:.3f} / {v[2]:.2f}"
                 for m, v in ((m, np.mean(means[crf, m], axis=0)) for m in methods)]
        print(f"mean, crf {crf:2d} ({len(means[crf, methods[0]])} shots): " + ", ".join(cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
