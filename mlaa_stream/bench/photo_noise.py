"""Photographs with camera noise: does the filter leave them alone?

    python -m mlaa_stream.bench.photo_noise [--methods mlaa,mlaa:screen,fxaa] [--sigmas 3,6] [--seed 0]

A photograph has no jaggies to remove, so its truth is the frame itself and every change is damage. Noise makes
it look busy: many exact colours per window, and colour noise in dark areas passes the CIELAB edge threshold, so the
MLAA passes blend some of it -- what a 1-spp render's busy pixels look like to the render-region test
(docs/spatial_tuning.md, "Busy pixels within the grain"). Frames: matplotlib's portrait sample as shot (600x512),
two crops of it magnified 2x (bicubic: soft edges, smooth areas) and the whole upscaled to 1920x1080, each clean and
with seeded Gaussian noise of each --sigmas deviation in 8-bit levels, per channel ("colour") or one value for R, G
and B ("mono"). Per frame and method: the share of tiles the filter takes for render regions (methods with render
regions; '-' otherwise) and the RMS of the change (8-bit levels). A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse

import numpy as np

from mlaa_stream.bench.accuracy import METHODS, new_shot
from mlaa_stream.spatial.filter import Filter


def photographs() -> dict[str, np.ndarray]:
    """The portrait sample as shot, two 2x magnified crops and the whole at 1920x1080 (uint8 RGB)."""
    import cv2
    import matplotlib.image
    from matplotlib import cbook
    photo = np.ascontiguousarray(
        matplotlib.image.imread(cbook.get_sample_data("grace_hopper.jpg", asfileobj=False))[..., :3], np.uint8)
    return {"300x256 (2x crop)": cv2.resize(photo[:150, :128], None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC),
            "400x320 (2x crop)": cv2.resize(photo[:200, :160], None, fx=2, fy=2, interpolation=cv2.INTER_CUBIC),
            "600x512 (as shot)": photo,
            "1920x1080 (upscaled)": cv2.resize(photo, (1920, 1080), interpolation=cv2.INTER_CUBIC)}


def with_noise(frame: np.ndarray, sigma: float, colour: bool, seed: int) -> np.ndarray:
    """Seeded Gaussian noise of `sigma` levels, per channel (`colour`) or one value for R, G and B."""
    rng = np.random.default_rng(seed)
    n = rng.normal(0, sigma, frame.shape if colour else frame.shape[:2] + (1,))
    return np.clip(np.rint(frame + n), 0, 255).astype(np.uint8)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--methods", default="mlaa,mlaa:screen,fxaa")
    ap.add_argument("--sigmas", default="3,6", help="noise deviations in 8-bit levels (comma-separated)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    methods = args.methods.split(",")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise SystemExit(f"expected methods from {', '.join(METHODS)}, got {', '.join(unknown)}")
    try:
        sigmas = [float(v) for v in args.sigmas.split(",") if v]
    except ValueError:
        raise SystemExit(f"--sigmas: expected numbers, comma-separated, got {args.sigmas!r}") from None
    frames = {}
    for name, photo in photographs().items():
        frames[f"{name}, clean"] = photo
        for sigma in sigmas:
            for colour in (True, False):
                frames[f"{name}, {'colour' if colour else 'mono'} {sigma:g}"] = with_noise(photo, sigma, colour,
                                                                                           args.seed)
    print("frame".ljust(36) + "".join(f"{m} (regions % / change RMS)".rjust(34) for m in methods))
    cells = {name: [] for name in frames}
    for m in methods:
        proc = METHODS[m](args.device)
        keeps = isinstance(proc, Filter)   # its render regions are read back (Filter.last_regions)
        if keeps:
            proc.keep_regions = True
        for name, x in frames.items():
            new_shot(proc)  # every frame judged alone
            out = proc.process(x).astype(np.float64)
            rms = float(np.sqrt(np.mean((out - x) ** 2)))
            regions = proc.last_regions if keeps else None
            share = "-" if regions is None else f"{100 * float(np.mean(regions)):.0f}"
            cells[name].append(f"{share} / {rms:.2f}")
    for name, row in cells.items():
        print(name.ljust(36) + "".join(c.rjust(34) for c in row))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
