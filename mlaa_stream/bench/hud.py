"""Text over a render: subtitles and HUD boxes composited over rendered frames -- does the filter leave them alone?

    python -m mlaa_stream.bench.hud [--methods none,fxaa,mlaa,mlaa:screen,mlaa+keep] [--sizes 640x360] [--crf 18,23]

Game captures and rendered video carry text the renderer did not draw: subtitles, a HUD, a slate. It is
antialiased already (or pixel-aligned UI), so a filter should leave it as it is, while it antialiases the render
around it. Bases: the bench's rendered atrium and stress scenes (frame 0) and the held-out views
(bench/rendered_views.py) at each size. Overlays, each composited into input and truth alike:
`subs` -- two lines of white DejaVu Sans (16 and 20 px) near the bottom, antialiased (8x8 coverage) and blended in
sRGB as subtitle renderers do; `subs_outline` -- the same with a black outline 1.5 px wide; `ui_aa` / `ui_aliased`
-- two crops of the text_ui scene's boxes (its 8x8 truth, or its 1-spp input with its own truth) at the top left
and the right. Per frame and method: RMSE against the truth
inside the overlay (8-bit levels; its pixels and one around, for the subtitles) and error removed outside it (%).
`mlaa+keep` is the default filter with the overlays' bounding boxes given as keep rectangles (spatial/keep.py), as a
user who knows where they are would. `--crf 18,23`: also each composite through H.264 (the codec's error counted as
the input's). Needs EGL (the rendered scenes). A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse

import numpy as np

from mlaa_stream.bench.accuracy import METHODS, new_shot
from mlaa_stream.spatial.keep import keep_rects, restore_kept
from mlaa_stream.yardstick.scenes import coverage, generate_scenes, text_polygons

OVERLAYS = ("subs", "subs_outline", "ui_aa", "ui_aliased")
UI_CROPS = ((4, 4, 60, 200), (110, 4, 60, 180))  # (row, column, height, width) of the text_ui scene's frame


def _grow(mask: np.ndarray) -> np.ndarray:
    """mask and its 8 neighbours."""
    h, w = mask.shape
    p = np.pad(mask, 1)
    return np.any([p[dy:dy + h, dx:dx + w] for dy in range(3) for dx in range(3)], 0)


def subtitle_coverage(height: int, width: int, outline: float = 0.0) -> np.ndarray:
    """Coverage (0..1, height x width) of two subtitle lines near the bottom, from 8x8 samples per pixel; with
    `outline` > 0 the glyphs grown by that many pixels (a subtitle's outline: the samples within that distance)."""
    lines = (("The quick brown fox jumps", 0.12 * width, height - 24, 20),
             ("over the lazy dog 0123", 0.2 * width, height - 52, 16))
    samples = np.zeros((height * 8, width * 8), bool)
    for text, x, y, size in lines:
        samples |= coverage(text_polygons(text, x, y, size), 8, 0, height, 0, width)
    r = int(round(outline * 8))
    if r:
        grown = samples.copy()
        for dy in range(-r, r + 1):
            dx = int((r * r - dy * dy) ** 0.5)
            row = np.roll(samples, dy, 0)
            for sx in range(-dx, dx + 1):
                grown |= np.roll(row, sx, 1)
        samples = grown
    return samples.reshape(height, 8, width, 8).mean((1, 3))


def composite(base: tuple[np.ndarray, np.ndarray], overlay: str,
              ui: dict[str, tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[str]]:
    """(input, truth, overlay mask, keep rectangles 'X,Y,W,H') of `overlay` over the rendered frame `base`."""
    inp, truth = base[0].copy(), base[1].copy()
    h, w = inp.shape[:2]
    mask = np.zeros((h, w), bool)
    if overlay in ("subs", "subs_outline"):
        cov = subtitle_coverage(h, w)[..., None]
        ring = subtitle_coverage(h, w, 1.5)[..., None] if overlay == "subs_outline" else np.zeros_like(cov)
        inp, truth = ((np.round((a * (1 - ring)) * (1 - cov) + 255 * cov)).astype(np.uint8) for a in (inp, truth))
        mask = _grow(np.maximum(cov, ring)[..., 0] > 0.02)
    else:
        src_in, src_truth = ui["text_ui_aa" if overlay == "ui_aa" else "text_ui"]
        for (sy, sx, ph, pw), (dy, dx) in zip(UI_CROPS, ((8, 8), (150, w - 190))):
            inp[dy:dy + ph, dx:dx + pw] = src_in[sy:sy + ph, sx:sx + pw]
            truth[dy:dy + ph, dx:dx + pw] = src_truth[sy:sy + ph, sx:sx + pw]
            mask[dy:dy + ph, dx:dx + pw] = True
    rects = []
    for rows, cols in _boxes(mask):
        rects.append(f"{cols.start},{rows.start},{cols.stop - cols.start},{rows.stop - rows.start}")
    return inp, truth, mask, rects


def _boxes(mask: np.ndarray) -> list[tuple[slice, slice]]:
    """Bounding boxes of the mask's bands of rows (the subtitle lines are one band, the UI crops two)."""
    rows = np.flatnonzero(mask.any(1))
    if not len(rows):
        return []
    bands = np.split(rows, np.flatnonzero(np.diff(rows) > 1) + 1)
    out = []
    for band in bands:
        cols = np.flatnonzero(mask[band[0]:band[-1] + 1].any(0))
        groups = np.split(cols, np.flatnonzero(np.diff(cols) > 1) + 1)
        for g in groups:
            out.append((slice(band[0], band[-1] + 1), slice(g[0], g[-1] + 1)))
    return out


def scores(out: np.ndarray, inp: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """(RMSE against the truth inside the mask, in levels; error removed outside it, %)."""
    d_out = out.astype(np.float64) - truth
    d_in = inp.astype(np.float64) - truth
    inside = float(np.sqrt((d_out[mask] ** 2).mean()))
    rest = 100.0 * (1.0 - (d_out[~mask] ** 2).mean() / max((d_in[~mask] ** 2).mean(), 1e-12))
    return inside, rest


def bases(sizes: list[tuple[int, int]]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """The rendered frames overlays go on: the bench's atrium and stress scenes, the held-out views."""
    from mlaa_stream.bench.rendered_views import render_views
    out = {}
    for sc in generate_scenes(names=["rendered"]):
        if sc.name in ("rendered_atrium", "rendered_stress"):
            out[sc.name] = (sc.inputs[0], sc.truths[0])
    out.update(render_views(sizes))
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--methods", default="none,fxaa,mlaa,mlaa:screen,mlaa+keep")
    ap.add_argument("--sizes", default="640x360")
    ap.add_argument("--crf", default="",
                    help="also every frame through H.264 at these CRFs (comma-separated; as rendered video with "
                         "burned-in subtitles reaches the filter; FRAME|OVERLAY|crfN), scored against the clean truth")
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    from mlaa_stream.bench.rendered_views import _int_list
    from mlaa_stream.yardstick.rendered import egl_available
    ok, why = egl_available()
    if not ok:
        raise SystemExit(f"rendered frames need a headless OpenGL context: {why}")
    methods = args.methods.split(",")
    unknown = [m for m in methods if m not in METHODS and m != "mlaa+keep"]
    if unknown:
        raise SystemExit(f"expected methods from {', '.join([*METHODS, 'mlaa+keep'])}, got {', '.join(unknown)}")
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    ui = {sc.name: (sc.inputs[0], sc.truths[0]) for sc in generate_scenes(names=["text_ui", "antialiased"])}
    frames = {f"{name}|{ov}": composite(base, ov, ui) for name, base in bases(sizes).items() for ov in OVERLAYS}
    crfs = _int_list("--crf", args.crf, 0)
    if crfs:
        from mlaa_stream.bench.codec_check import through_h264
        for key, (inp, truth, mask, rects) in list(frames.items()):
            for crf in crfs:
                frames[f"{key}|crf{crf}"] = (through_h264(np.stack([inp, inp]), crf)[0], truth, mask, rects)
    # mlaa+keep: the default filter's output with the input put back in the rectangles, as Filter(keep=...) does
    procs = {m: METHODS["mlaa" if m == "mlaa+keep" else m](args.device) for m in methods}
    print("RMSE inside the overlay (levels) / error removed outside it (%)")
    print("frame|overlay".ljust(34) + "".join(m.rjust(16) for m in methods))
    totals: dict[tuple[str, str], list[tuple[float, float]]] = {}
    for key, (inp, truth, mask, rects) in frames.items():
        row = key.ljust(34)
        for m in methods:
            new_shot(procs[m])  # every frame judged alone
            out = procs[m].process(inp)
            if m == "mlaa+keep":
                out = restore_kept(inp, out, keep_rects(rects))
            inside, rest = scores(out, inp, truth, mask)
            totals.setdefault(("|".join(key.split("|")[1:]), m), []).append((inside, rest))
            row += f"{inside:7.2f} / {rest:5.1f}".rjust(16)
        print(row, flush=True)
    for ov in [*OVERLAYS, *(f"{o}|crf{c}" for o in OVERLAYS for c in crfs)]:
        cells = [totals[(ov, m)] for m in methods]
        print(f"mean {ov}".ljust(34) + "".join(f"{np.mean([a for a, _ in c]):7.2f} / {np.mean([b for _, b in c]):5.1f}"
                                               .rjust(16) for c in cells))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
