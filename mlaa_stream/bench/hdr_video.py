"""Renders coded as HDR video: `python -m mlaa_stream.bench.hdr_video [--sizes 960x540] [--transfers pq,hlg]
[--world plaza,town] [--sky 1] [--timing]`.

An HDR10 (PQ) or HLG video of a render holds 10-bit codes of light by a curve that is not sRGB's. Every held-out view
(bench/rendered_views.py) of each world is rendered in linear light with its highlights unclamped (1 spp at pixel
centres; truth the 8x8 jittered mean in linear light), BT.2408's reference white put at linear 1, and coded with each
transfer to 16-bit codes as a 10-bit video decodes to (device/transfer.py). The default filter runs on the codes as
they are -- taken as sRGB-coded, as it did before the transfer was read from the video -- and with
`transfer=` (the codes decoded to linear light, filtered, coded back). Scores are taken on the codes, the space the
curves were designed to make even for the eye: error removed % / damage away from edges (levels of 8 bits).
`--timing`: ms per 1920x1080 frame (the atrium tiled 3x3 as PQ codes), both ways. `--temporal`: the held-out shots
(each view as a pan and a dolly, `--frames` frames at the first size) coded as PQ, through the spatial filter with
the transfer, then each temporal method (causal) with the stage's transfer off (the codes) and on (light); error
removed % / damage of all frames.
Needs EGL, as the rendered scenes do. A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from mlaa_stream.bench.rendered_views import held_out_views, render_args, view_cameras
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.temporal.methods import make_stage, needs_regions
from mlaa_stream.device.transfer import TRANSFERS, encode
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.rendered import Renderer, _context, shot

def coded(linear: np.ndarray, transfer: str) -> np.ndarray:
    """Linear light (reference white 1) -> 16-bit codes of `transfer`, computed in float64 (exact codes)."""
    signal = encode(np.asarray(linear, np.float64), transfer)
    return np.clip(np.rint(np.asarray(signal, np.float64) * 65535.0), 0, 65535).astype(np.uint16)


def run(sizes: list[tuple[int, int]], transfers: list[str], worlds: list[str], sky: float = 1.0,
        device: str | None = None, log=print) -> dict[tuple[str, str], list[tuple[float, float]]]:
    """{(transfer, "codes" | "transfer"): [(error removed %, damage) per view]}, printing a row per view."""
    res: dict[tuple[str, str], list[tuple[float, float]]] = {}
    filters = {"codes": Filter(device), **{t: Filter(device, transfer=t) for t in transfers}}
    try:
        log("error removed % / damage: the codes filtered as sRGB-coded | with transfer=")
        for world, name, width, renderer, cam in held_out_views(sizes, worlds, hdr=True, sky_gain=sky):
            lin, truth_lin = renderer.input_linear(cam), renderer.truth_linear(cam)
            cells = []
            for t in transfers:
                inp, truth = coded(lin, t), coded(truth_lin, t)
                for how, filt in (("codes", filters["codes"]), ("transfer", filters[t])):
                    filt.new_shot()  # every view judged alone
                    out = filt.process(inp)
                    score = (100 * M.error_removed(out, inp, truth), M.damage(out, inp, truth))
                    res.setdefault((t, how), []).append(score)
                    cells.append(score)
            row = "  ".join(f"{t} {a[0]:5.1f} / {a[1]:.2f} | {b[0]:5.1f} / {b[1]:.2f}"
                            for t, a, b in zip(transfers, cells[0::2], cells[1::2]))
            log(f"  {world} {name}_{width}: {row}")
        for t in transfers:
            a, b = res[(t, "codes")], res[(t, "transfer")]
            better = sum(y[0] > x[0] for x, y in zip(a, b))
            log(f"  mean {t}: {np.mean([s[0] for s in a]):.1f} / {np.mean([s[1] for s in a]):.2f} | "
                f"{np.mean([s[0] for s in b]):.1f} / {np.mean([s[1] for s in b]):.2f} "
                f"(more error removed on {better} of {len(a)} views)")
    finally:
        for f in filters.values():
            f.close()
    return res


def run_temporal(size: tuple[int, int], worlds: list[str], methods: list[str], frames: int = 8,
                 device: str | None = None, log=print) -> dict[str, list[tuple[float, float]]]:
    """{"spatial" | "<method> codes" | "<method> light": [(error removed %, damage) per shot]} on the held-out shots
    coded as PQ, printing a row per shot."""
    width, height = size
    res: dict[str, list[tuple[float, float]]] = {}
    with Filter(device, transfer="pq", keep_regions=True) as filt:
        for world in worlds:
            renderer = Renderer(_context(), width, height, world, hdr=True)
            try:
                for shot_name, cameras in view_cameras(width, height, frames, world).items():
                    inp = np.stack([coded(renderer.input_linear(c), "pq") for c in cameras])
                    truth = np.stack([coded(renderer.truth_linear(c), "pq") for c in cameras])
                    filt.new_shot()  # each shot its own
                    row = {"spatial": np.stack([filt.process(f) for f in inp])}
                    for method in methods:
                        for how, transfer in (("codes", None), ("light", "pq")):
                            stage = make_stage(method, filt.context, bgr=False, transfer=transfer,
                                               regions_from=filt if needs_regions(method) else None)
                            filt.new_shot()
                            try:   # the spatial frame filtered just before the call: its render regions are read
                                row[f"{method} {how}"] = np.stack([stage(f, filt.process(f), i)
                                                                   for i, f in enumerate(inp)])
                            finally:
                                stage.close()
                    cells = []
                    for key, out in row.items():
                        score = (100 * M.error_removed(out, inp, truth), M.damage(out, inp, truth))
                        res.setdefault(key, []).append(score)
                        cells.append(f"{key} {score[0]:.1f} / {score[1]:.2f}")
                    log(f"  {world} {shot_name}: " + "  ".join(cells))
            finally:
                renderer.release()
    log("  mean: " + "  ".join(f"{k} {np.mean([s[0] for s in v]):.2f} / {np.mean([s[1] for s in v]):.3f}"
                                for k, v in res.items()))
    return res


def timing(device: str | None = None, log=print) -> dict[str, float]:
    """ms per 1920x1080 frame of PQ codes (the bench's atrium view rendered in linear light at 640x360, tiled 3x3),
    both ways."""
    renderer = Renderer(_context(), 640, 360, hdr=True)
    try:
        linear = renderer.input_linear(shot("rendered_atrium", 640, 360)[0])
    finally:
        renderer.release()
    codes = np.ascontiguousarray(np.tile(coded(linear, "pq"), (3, 3, 1)))
    out = {}
    for name, kwargs in (("codes as sRGB", {}), ("transfer=pq", {"transfer": "pq"})):
        with Filter(device, **kwargs) as f:
            times = []
            for k in range(10):
                t = time.perf_counter()
                f.process(codes)
                if k >= 2:
                    times.append(1e3 * (time.perf_counter() - t))
            out[name] = float(np.median(times))
            log(f"{name}: {out[name]:.1f} ms per 1920x1080 frame ({f.device_name})")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mlaa_stream.bench.hdr_video", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="960x540", help="frame sizes WxH, comma-separated (default 960x540)")
    ap.add_argument("--transfers", default=",".join(TRANSFERS), help="pq, hlg or both (default pq,hlg)")
    ap.add_argument("--world", default="plaza,town", help="worlds, comma-separated (default plaza,town)")
    ap.add_argument("--sky", type=float, default=1.0, help="the sky's radiance gain (default 1)")
    ap.add_argument("--timing", action="store_true", help="also ms per 1920x1080 frame")
    ap.add_argument("--temporal", default="", metavar="METHODS",
                    help="also the held-out shots through these temporal methods, comma-separated (e.g. tss,auto)")
    ap.add_argument("--frames", type=int, default=8, help="frames per --temporal shot (default 8)")
    ap.add_argument("--device", default=None, help="OpenCL device (as --device of mlaa-stream)")
    args = ap.parse_args(argv)
    transfers = [t for t in args.transfers.split(",") if t]
    unknown = [t for t in transfers if t not in TRANSFERS]
    if unknown or not transfers:
        raise SystemExit(f"--transfers: expected names from {', '.join(TRANSFERS)}, got {args.transfers}")
    sizes, worlds = render_args(args.sizes, args.world)
    run(sizes, transfers, worlds, args.sky, args.device)
    if args.temporal:
        run_temporal(sizes[0], worlds, [m for m in args.temporal.split(",") if m], args.frames, args.device)
    if args.timing:
        timing(args.device)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
