"""Renders over transparency: `python -m mlaa_stream.bench.alpha [--sizes 640x360] [--world plaza,town]
[--timing]`.

A render pipeline writes elements over nothing (RGBA PNG with straight alpha, EXR with premultiplied alpha) to
composite them later. Every held-out view (bench/rendered_views.py) of each world is rendered with its sky as
transparency -- 1 spp at pixel centres: binary coverage; truth: the 8x8 jittered means of premultiplied colour and
coverage -- handed to the filter as an 8-bit straight-alpha frame (transparent pixels black, as renderers write
them) and as a premultiplied linear float frame, with alpha="keep" (the colour filtered alone, as before) and
alpha="coverage" (spatial/alpha.py). Scored: the error removed % of the composite over three plates (linear 0.2
grey, a soft texture, 0.8 grey; sRGB-encoded levels, as the bench scores) and of the alpha against the truth's
coverage. `--timing`: ms per 1920x1080 frame (the atrium view tiled 3x3), median of 8 after 2: RGB, RGBA PNG-style and
premultiplied float EXR-style frames, alpha as coverage and kept.
Needs EGL, as the rendered scenes do. A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

from mlaa_stream.bench.rendered_views import held_out_views, render_args
from mlaa_stream.device.colour import srgb_to_linear
from mlaa_stream.spatial.filter import ALPHA_MODES, Filter
from mlaa_stream.yardstick.rendered import Renderer, _context, shot
from mlaa_stream.yardstick.scenes import encode8

PLATES = ("grey 0.2", "texture", "grey 0.8")


def plates(h: int, w: int) -> list[np.ndarray]:
    yy, xx = np.mgrid[0:h, 0:w]
    texture = 0.25 + 0.2 * (np.sin(xx / 7.0) * np.cos(yy / 11.0))[..., None] * np.array([1.0, 0.8, 0.6])
    return [np.full((h, w, 3), 0.2), texture, np.full((h, w, 3), 0.8)]


def premultiplied_of(frame: np.ndarray, premultiplied: bool) -> tuple[np.ndarray, np.ndarray]:
    """(premultiplied linear colour, coverage) of an 8-bit straight or a float premultiplied RGBA frame."""
    if frame.dtype == np.uint8:
        a = frame[..., 3] / 255.0
        return srgb_to_linear(frame[..., :3] / 255.0) * a[..., None], a
    colour, a = frame[..., :3].astype(np.float64), frame[..., 3].astype(np.float64)
    return (colour if premultiplied else colour * a[..., None]), a


def scores(out: np.ndarray, inp: np.ndarray, truth: tuple[np.ndarray, np.ndarray], premultiplied: bool) -> list[float]:
    """Error removed % of the composite over each plate, then of the alpha."""
    (p_out, a_out), (p_in, a_in) = premultiplied_of(out, premultiplied), premultiplied_of(inp, premultiplied)
    p_t, a_t = truth
    res = []
    for plate in plates(*a_t.shape):
        over = lambda p, a: encode8(np.clip(p + (1 - a[..., None]) * plate, 0, 1)).astype(np.float64)  # noqa: E731
        t = over(p_t, a_t)
        res.append(100 * (1 - np.mean((over(p_out, a_out) - t) ** 2) / np.mean((over(p_in, a_in) - t) ** 2)))
    res.append(100 * (1 - np.mean((a_out - a_t) ** 2) / np.mean((a_in - a_t) ** 2)))
    return res


def frames_of(colour: np.ndarray, cover: np.ndarray) -> dict[str, np.ndarray]:
    """The render as an 8-bit straight-alpha frame (PNG) and as a premultiplied float32 frame (EXR)."""
    png = np.dstack([np.where(cover[..., None] > 0, encode8(colour), 0), np.rint(cover * 255)]).astype(np.uint8)
    exr = np.dstack([colour * cover[..., None], cover]).astype(np.float32)
    return {"png": png, "exr": exr}


def run(sizes: list[tuple[int, int]], worlds: list[str], device: str | None = None, log=print) -> dict:
    """{(format, alpha mode): [scores per view]}, printing a row per view."""
    res: dict[tuple[str, str], list[list[float]]] = {}
    filters = {(fmt, mode): Filter(device, alpha=mode, linear_input=fmt == "exr")
               for fmt in ("png", "exr") for mode in ALPHA_MODES}
    log("error removed %: composite over " + ", ".join(PLATES) + "; alpha -- alpha=" + " | ".join(ALPHA_MODES))
    try:
        for world, name, width, renderer, cam in held_out_views(sizes, worlds):
            colour, cover, truth_p, truth_a = renderer.coverage_frames(cam)
            for fmt, frame in frames_of(colour, cover).items():
                cells = []
                for mode in ALPHA_MODES:
                    filters[(fmt, mode)].new_shot()  # every view judged alone
                    out = filters[(fmt, mode)].process(frame, premultiplied=fmt == "exr")
                    s = scores(out, frame, (truth_p, truth_a), fmt == "exr")
                    res.setdefault((fmt, mode), []).append(s)
                    cells.append(" / ".join(f"{v:5.1f}" for v in s))
                log(f"  {world} {name}_{width} {fmt}: " + " | ".join(cells))
    finally:
        for f in filters.values():
            f.close()
    for (fmt, mode), rows in res.items():
        log(f"mean {fmt} alpha={mode}: " + " / ".join(f"{v:.1f}" for v in np.mean(rows, axis=0)))
    return res


def timing(device: str | None = None, log=print) -> dict[str, float]:
    """ms per 1920x1080 frame: the atrium view (its sky transparent) tiled 3x3, as RGB, as RGBA both ways and as a
    premultiplied float EXR frame both ways."""
    renderer = Renderer(_context(), 640, 360)
    try:
        colour, cover, _, _ = renderer.coverage_frames(shot("rendered_atrium", 640, 360)[0], spp=1)
    finally:
        renderer.release()
    frames = frames_of(colour, cover)
    png = np.ascontiguousarray(np.tile(frames["png"], (3, 3, 1)))
    exr = np.ascontiguousarray(np.tile(frames["exr"], (3, 3, 1)))
    cases = {"RGB (sky black)": (ALPHA_MODES[0], np.ascontiguousarray(png[..., :3]), False)}
    cases.update({f"RGBA alpha={m}": (m, png, False) for m in ALPHA_MODES})
    cases.update({f"EXR RGBA (premultiplied float) alpha={m}": ("exr " + m, exr, True) for m in ALPHA_MODES})
    out = {}
    filters = {m: Filter(device, alpha=m) for m in ALPHA_MODES}
    filters.update({"exr " + m: Filter(device, alpha=m, linear_input=True) for m in ALPHA_MODES})
    try:
        for name, (mode, frame, premultiplied) in cases.items():
            f = filters[mode]
            times = []
            for k in range(10):
                t = time.perf_counter()
                f.process(frame, premultiplied=premultiplied)
                if k >= 2:
                    times.append(1e3 * (time.perf_counter() - t))
            out[name] = float(np.median(times))
            log(f"{name}: {out[name]:.1f} ms per 1920x1080 frame ({f.device_name})")
    finally:
        for f in filters.values():
            f.close()
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mlaa_stream.bench.alpha", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="640x360", help="frame sizes WxH, comma-separated (default 640x360)")
    ap.add_argument("--world", default="plaza,town", help="worlds, comma-separated (default plaza,town)")
    ap.add_argument("--timing", action="store_true", help="also ms per 1920x1080 RGBA frame")
    ap.add_argument("--device", default=None, help="OpenCL device (as --device of mlaa-stream)")
    args = ap.parse_args(argv)
    sizes, worlds = render_args(args.sizes, args.world)
    run(sizes, worlds, args.device)
    if args.timing:
        timing(args.device)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
