"""Fit the footprint table (mlaa_stream/spatial/footprint.py), or the refine table after it (--refine,
mlaa_stream/spatial/refine.py), on rendered training views and write it.

    python -m mlaa_stream.bench.footprint_fit [--refine] [--out FILE] [--sizes 640x360,960x540]

The training views are cameras in the rendered world (yardstick/rendered.py) that neither a bench scene nor a
held-out view (bench/rendered_views.py) uses, so both stay out of sample. Each view is rendered like the bench's
(1 spp at pixel centres; truth: 8x8 jittered samples averaged in linear light) at each size, run through the
default Filter without the table, and every pixel the table takes (fallback.table_pixels), in all eight flips
and transposes of the frame, is a sample of the least-squares fit. --refine: the default Filter with the shipped
footprint table and no refine table gives each view's first stage; its pixels are the table's with strong
local contrast (refine.gate). Needs EGL
(`pip install 'mlaa-stream[bench]'`); 2-3 minutes here.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from mlaa_stream.device.formats import frame_format
from mlaa_stream.spatial.fallback import long_runs, region_pixels, table_pixels, to_mix_space
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.spatial.footprint import TABLE_FILE, fit_table
from mlaa_stream.spatial.refine import REFINE_FILE, fit_refine, gate
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.rendered import Camera, Renderer, _context, egl_available

# name -> (eye, target, vertical field of view in degrees)
TRAIN_VIEWS: dict[str, tuple[tuple, tuple, float]] = {
    "west": ((-6.0, 1.8, 4.0), (0.0, 2.0, -12.0), 50.0),          # along the arcade, stairs and spheres
    "east_high": ((6.0, 3.0, 2.0), (-2.0, 1.0, -14.0), 40.0),     # over the torus to the arches
    "low_road": ((0.0, 1.0, -6.0), (6.0, 2.0, -30.0), 60.0),      # down the road past the sign
    "mid": ((-3.0, 4.0, -12.0), (4.0, 0.5, -25.0), 45.0),         # the flag, fence and cables from above
    "far": ((10.0, 1.7, -25.0), (-2.0, 2.0, -40.0), 35.0),        # through the chain-link fence
    "top": ((0.0, 8.0, -5.0), (0.0, 0.0, -20.0), 65.0),           # down on the colonnade's roofline
}
# the second world's training views (yardstick/town.py; its held-out views are rendered_views.TOWN_VIEWS)
TOWN_TRAIN_VIEWS: dict[str, tuple[tuple, tuple, float]] = {
    "back_left": ((-4.5, 1.7, -30.0), (-2.0, 2.5, -5.0), 50.0),   # back along the left pavement
    "across": ((4.5, 1.6, -50.0), (-6.0, 4.0, -55.0), 55.0),       # across the street at the left facades
    "bikes_high": ((0.0, 4.0, -2.0), (5.0, 0.0, -12.0), 45.0),     # down on the bicycles and the kerb
    "tower_tele": ((-2.0, 1.5, -80.0), (3.0, 20.0, -260.0), 20.0),  # long lens up the street to the tower
}
WORLD_TRAIN_VIEWS = {"plaza": TRAIN_VIEWS, "town": TOWN_TRAIN_VIEWS}
DEFAULT_SIZES = "640x360,960x540"


def dihedral(a: np.ndarray, k: int) -> np.ndarray:
    """One of the eight flips and transposes of a frame (k in 0..7), on its first two axes."""
    if k & 4:
        a = np.swapaxes(a, 0, 1)
    if k & 1:
        a = a[::-1]
    if k & 2:
        a = a[:, ::-1]
    return np.ascontiguousarray(a)


def training_frames(sizes: list[tuple[int, int]], refine: bool = False,
                    worlds: tuple[str, ...] = ("plaza",)) -> list[tuple[np.ndarray, ...]]:
    """(input, truth, chain without the table, mask of the pixels the table takes) per training view and size;
    `refine`: (input, truth, chain with the table and without the refine table, mask of the pixels the refine
    table takes)."""
    frames = []
    first = {"refine_table": None} if refine else {"footprint_table": None}
    with Filter(keep_regions=True, **first) as chain, Filter(fallback="off") as mlaa:
        for world, (width, height) in [(w, s) for w in worlds for s in sizes]:
            renderer = Renderer(_context(), width, height, world)
            try:
                for eye, target, fov in WORLD_TRAIN_VIEWS[world].values():
                    cam = Camera(eye, target, fov)
                    inp, truth = renderer.input_frame(cam), renderer.truth_frame(cam)
                    chain.new_shot()  # every training view judged alone
                    out = chain.process(inp)
                    passes = mlaa.intermediates(inp)
                    runs = long_runs(passes["edges"], passes["hdist"], passes["vdist"])
                    mask = table_pixels(region_pixels(chain.last_regions, height, width), runs,
                                        np.any(out != inp, -1))
                    if refine:
                        mask &= gate(inp, 255.0)
                    frames.append((inp, truth, out, mask))
            finally:
                renderer.release()
    return frames


def samples(frames):
    """fit_table's (and fit_refine's) samples: every training frame in its eight orientations, in mix space (linear
    light)."""
    for inp, truth, out, mask in frames:
        fmt = frame_format(inp)
        for k in range(8):
            i, t, o, m = (dihedral(a, k) for a in (inp, truth, out, mask))
            yield (to_mix_space(i, fmt, True), to_mix_space(o, fmt, True), np.any(o != i, -1),
                   to_mix_space(t, fmt, True), m)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mlaa_stream.bench.footprint_fit", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--refine", action="store_true", help="fit the refine table (after the shipped footprint table)")
    ap.add_argument("--out", default=None, help="where to write the table (default: the package's)")
    ap.add_argument("--sizes", default=DEFAULT_SIZES, help="WxH,... (default %(default)s)")
    ap.add_argument("--worlds", default="plaza", help="the rendered worlds whose training views are fitted, "
                    f"comma-separated, of {', '.join(WORLD_TRAIN_VIEWS)} (default %(default)s)")
    args = ap.parse_args(argv)
    worlds = tuple(args.worlds.split(","))
    if not worlds or any(w not in WORLD_TRAIN_VIEWS for w in worlds):
        ap.error(f"--worlds: expected names from {', '.join(WORLD_TRAIN_VIEWS)}, got {args.worlds!r}")
    ok, why = egl_available()
    if not ok:
        ap.error(f"the training views need a headless OpenGL context: {why}")
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    out = args.out or str(Path(__file__).resolve().parents[1] / "data" / (REFINE_FILE if args.refine else TABLE_FILE))
    frames = training_frames(sizes, args.refine, worlds)
    table = fit_refine(samples(frames)) if args.refine else fit_table(samples(frames))
    np.save(out, table)
    print(f"wrote {out}: {table.shape[0]} buckets x {table.shape[1]} weights")
    check = {"refine_table": table} if args.refine else {"footprint_table": table, "refine_table": None}
    with Filter(**check) as f:  # in-sample check: the held-out views are rendered_views' job
        names = [f"{n}_{w}" for world in worlds for w, _ in sizes for n in WORLD_TRAIN_VIEWS[world]]
        for (inp, truth, first, _), name in zip(frames, names):
            f.new_shot()
            print(f"{name:16s} error removed without the table {M.error_removed(first, inp, truth):.3f}, "
                  f"with it {M.error_removed(f.process(inp), inp, truth):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
