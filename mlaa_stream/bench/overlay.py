"""Benchmark GRLAA overlays against cv2.polylines(LINE_AA) and a supersampled truth.

Run `python -m mlaa_stream.bench.overlay` (`--quick` for a smaller run); writes docs/grlaa_bench.md.
Truth: the same lines point-sampled 8x8 per pixel without antialiasing (8x larger), box-downsampled
in linear light. Errors are in 8-bit sRGB levels over the pixels near the lines.
"""
from __future__ import annotations

import argparse
import datetime
import math
import os
import platform
import statistics
import sys
import time

import numpy as np

from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.overlay.grlaa import OverlayRenderer

BG = (40, 60, 50)            # background, sRGB 8-bit (RGB)
FG = (255, 236, 160)         # line colour, sRGB 8-bit (RGB)
SUPERSAMPLE = 8


# ----------------------------------------------------------------------------------- truth

def _dist_to_polyline(sx: np.ndarray, sy: np.ndarray, pts: np.ndarray) -> np.ndarray:
    d = np.full(np.broadcast_shapes(sx.shape, sy.shape), np.inf)
    segs = [(pts[i], pts[i + 1]) for i in range(len(pts) - 1)] or [(pts[0], pts[0])]
    for a, b in segs:
        dx, dy = b - a
        l2 = dx * dx + dy * dy
        t = np.clip(((sx - a[0]) * dx + (sy - a[1]) * dy) / l2, 0, 1) if l2 > 0 else 0.0
        np.minimum(d, np.hypot(sx - a[0] - t * dx, sy - a[1] - t * dy), out=d)
    return d


def truth_coverage(lines: list[np.ndarray], widths: list[float], height: int, width: int,
                   ss: int = SUPERSAMPLE) -> list[tuple[slice, slice, np.ndarray]]:
    """Per line: (rows, cols, coverage) = share of ss x ss point samples inside the stroke (round
    caps and joins), i.e. the line drawn ss times larger without antialiasing, box-downsampled."""
    out = []
    off = (np.arange(ss) + 0.5) / ss - 0.5
    for pts, w in zip(lines, widths):
        r = 0.5 * w
        x0 = max(int(math.floor(pts[:, 0].min() - r - 1)), 0)
        x1 = min(int(math.ceil(pts[:, 0].max() + r + 1)) + 1, width)
        y0 = max(int(math.floor(pts[:, 1].min() - r - 1)), 0)
        y1 = min(int(math.ceil(pts[:, 1].max() + r + 1)) + 1, height)
        if x0 >= x1 or y0 >= y1:
            out.append((slice(0, 0), slice(0, 0), np.zeros((0, 0))))
            continue
        sy = (np.arange(y0, y1)[:, None] + off[None, :]).reshape(-1)
        sx = (np.arange(x0, x1)[:, None] + off[None, :]).reshape(-1)
        inside = _dist_to_polyline(sx[None, :], sy[:, None], pts) <= r
        cov = inside.reshape(y1 - y0, ss, x1 - x0, ss).mean(axis=(1, 3))
        out.append((slice(y0, y1), slice(x0, x1), cov))
    return out


def truth_image(lines: list[np.ndarray], widths: list[float], height: int, width: int,
                bg=BG, fg=FG, ss: int = SUPERSAMPLE) -> np.ndarray:
    """sRGB float image (RGB, 0..1) of opaque `fg` lines over `bg`, composited in linear light."""
    bg_lin, fg_lin = srgb_to_linear(np.array(bg) / 255.0), srgb_to_linear(np.array(fg) / 255.0)
    lin = np.empty((height, width, 3))
    lin[:] = bg_lin
    for rows, cols, cov in truth_coverage(lines, widths, height, width, ss):
        c = cov[..., None]
        lin[rows, cols] = c * fg_lin + (1 - c) * lin[rows, cols]
    return linear_to_srgb(lin)


# ------------------------------------------------------------------------------- renderers

def draw_grlaa(renderer: OverlayRenderer, lines, widths, height, width, bg=BG, fg=FG) -> np.ndarray:
    frame = np.empty((height, width, 3), np.uint8)
    frame[:] = bg
    return renderer.draw(frame, lines, width=widths, color=fg, bgr=False)


def draw_cv2(lines, widths, height, width, bg=BG, fg=FG, delta: int = 0) -> np.ndarray:
    """cv2.polylines with LINE_AA, sub-pixel coordinates (shift=4), thickness round(w) + delta."""
    import cv2
    frame = np.empty((height, width, 3), np.uint8)
    frame[:] = bg
    for pts, w in zip(lines, widths):
        p = np.round(np.asarray(pts) * 16).astype(np.int32)
        cv2.polylines(frame, [p], False, fg, max(int(round(w)) + delta, 1), cv2.LINE_AA, 4)
    return frame


def _errors(img: np.ndarray, truth: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    d = (img.astype(np.float64) / 255.0 - truth)[mask] * 255.0
    return float(np.abs(d).mean()), float(np.sqrt((d * d).mean()))


def _mask(truth: np.ndarray, *imgs: np.ndarray, bg=BG) -> np.ndarray:
    """Pixels over the lines: any method or the truth differs from the background."""
    m = np.abs(truth * 255.0 - np.array(bg)).max(-1) > 0.25
    for im in imgs:
        m |= (im != np.array(bg, np.uint8)).any(-1)
    return m


def random_lines(rng: np.random.Generator, n: int, height: int, width: int, margin: float,
                 vertices=(2, 5), length=(40.0, 140.0)) -> list[np.ndarray]:
    """Polylines at random angles, inside the canvas less `margin`."""
    lines = []
    for _ in range(n):
        k = int(rng.integers(vertices[0], vertices[1] + 1))
        p = [rng.uniform([margin, margin], [width - margin, height - margin])]
        for _ in range(k - 1):
            a, ln = rng.uniform(0, 2 * np.pi), rng.uniform(*length) / (k - 1)
            q = p[-1] + ln * np.array([math.cos(a), math.sin(a)])
            p.append(np.clip(q, margin, [width - margin, height - margin]))
        lines.append(np.array(p))
    return lines


# ------------------------------------------------------------------------------- sections

def accuracy_by_width(renderer, widths, seed=1, n=10, size=(200, 280)) -> list[dict]:
    h, w = size
    rows = []
    for wd in widths:
        rng = np.random.default_rng(seed + int(wd * 10))
        lines = random_lines(rng, n, h, w, margin=wd / 2 + 2)
        ws = [float(wd)] * n
        truth = truth_image(lines, ws, h, w)
        ours, cv = draw_grlaa(renderer, lines, ws, h, w), draw_cv2(lines, ws, h, w)
        # cv2's AA fringe lies outside the nominal width: also try thinner and thicker strokes
        others = {dl: draw_cv2(lines, ws, h, w, delta=dl) for dl in (-2, -1, 1) if wd + dl >= 1}
        m = _mask(truth, ours, cv, *others.values())
        tried = [(0, _errors(cv, truth, m))] + [(dl, _errors(im, truth, m)) for dl, im in others.items()]
        best = min(tried, key=lambda t: t[1][0])
        rows.append({"width": wd, "pixels": int(m.sum()), "ours": _errors(ours, truth, m),
                     "cv2": _errors(cv, truth, m), "cv2_best": best[1], "cv2_best_t": int(wd) + best[0]})
    return rows


def accuracy_by_angle(renderer, width=3.0, step=5, size=(200, 200)) -> list[dict]:
    h, w = size
    rows = []
    for deg in range(0, 91, step):
        a = math.radians(deg)
        c = np.array([w / 2 + 0.37, h / 2 + 0.21])  # off the pixel grid
        d = 80 * np.array([math.cos(a), math.sin(a)])
        lines = [np.array([c - d, c + d])]
        truth = truth_image(lines, [width], h, w)
        ours, cv = draw_grlaa(renderer, lines, [width], h, w), draw_cv2(lines, [width], h, w)
        m = _mask(truth, ours, cv)
        rows.append({"angle": deg, "ours": _errors(ours, truth, m), "cv2": _errors(cv, truth, m)})
    return rows


def accuracy_by_scale(renderer, scales=(0.5, 1, 2, 4, 8), seed=7, base=(48, 64)) -> list[dict]:
    """One scene drawn at several scales (coordinates and widths scaled). Scale independence: the
    error summed over the image per pixel of edge length stays constant."""
    rng = np.random.default_rng(seed)
    bh, bw = base
    lines0 = random_lines(rng, 4, bh, bw, margin=5, vertices=(3, 4), length=(20, 40))
    widths0 = [2.0, 3.0, 4.0, 6.0]
    rows = []
    for s in scales:
        h, w = int(bh * s), int(bw * s)
        lines = [(p + 0.5) * s - 0.5 for p in lines0]  # pixel centres sit at integers
        ws = [x * s for x in widths0]
        truth = truth_image(lines, ws, h, w)
        ours, cv = draw_grlaa(renderer, lines, ws, h, w), draw_cv2(lines, ws, h, w)
        m = _mask(truth, ours, cv)
        # edge length: both sides of every stroke plus its caps (round: 2 pi r per line)
        edge = sum(2 * np.hypot(*np.diff(p, axis=0).T).sum() + math.pi * wd for p, wd in zip(lines, ws))
        row = {"scale": s, "size": f"{w}x{h}", "pixels": int(m.sum()), "edge": edge}
        for name, im in (("ours", ours), ("cv2", cv)):
            d = np.abs(im.astype(np.float64) / 255.0 - truth) * 255.0
            row[name] = (float(d[m].mean()), float(d.sum() / 3 / edge))
        rows.append(row)
    return rows


def speed(renderer, widths=(1, 3, 8), runs=25, warmup=3, outline=False) -> list[dict]:
    """100 polylines of 50 segments on a 1920x1080 BGR uint8 frame: ms per frame, drawn in place."""
    import cv2
    rng = np.random.default_rng(0)
    h, w = 1080, 1920
    lines = [np.cumsum(rng.normal(0, 15, (51, 2)), 0) + rng.uniform([0, 0], [w, h]) for _ in range(100)]
    pts16 = [np.round(p * 16).astype(np.int32) for p in lines]
    base = np.empty((h, w, 3), np.uint8)
    base[:] = BG[::-1]
    rows = []
    for wd in widths:
        ow = 1.0 if outline else 0.0
        t_ours, t_cv = [], []
        for i in range(warmup + runs):
            fa, fb = base.copy(), base.copy()
            t0 = time.perf_counter()
            renderer.draw(fa, lines, width=wd, color=FG[::-1], outline_width=ow, inplace=True)
            t1 = time.perf_counter()
            cv2.polylines(fb, pts16, False, FG[::-1], int(wd), cv2.LINE_AA, 4)
            t2 = time.perf_counter()
            if i >= warmup:
                t_ours.append(t1 - t0)
                t_cv.append(t2 - t1)
        rows.append({"width": wd, "outline": ow, "ours": statistics.median(t_ours) * 1e3,
                     "ours_min": min(t_ours) * 1e3, "cv2": statistics.median(t_cv) * 1e3,
                     "cv2_min": min(t_cv) * 1e3})
    return rows


# --------------------------------------------------------------------------------- report

def _report(cmd, device, width_rows, angle_rows, scale_rows, speed_rows, elapsed) -> str:
    now = datetime.datetime.now().strftime("%Y-%m-%d %H:%M")
    load = " / ".join(f"{v:.1f}" for v in os.getloadavg()) + " over 1 / 5 / 15 min at the end"
    import cv2
    L = [
        "# GRLAA overlay benchmark",
        "",
        f"Command: `{cmd}`  ",
        f"Device: {device}  ",
        f"Host: {platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, "
        f"Python {platform.python_version()}, OpenCV {cv2.__version__}  ",
        f"Date: {now} (run took {elapsed:.0f} s)",
        "",
        "Truth: the same lines point-sampled 8x8 per pixel with no antialiasing (drawn 8x larger), "
        "box-downsampled in linear light, round caps and joins. Error: |method - truth| in 8-bit "
        "sRGB levels, averaged over the pixels where the truth or either method differs from the "
        f"background. Lines sRGB {FG} over {BG}. cv2: `cv2.polylines(..., thickness=round(w), "
        "cv2.LINE_AA, shift=4)`; ours: `OverlayRenderer.draw` (strength 1, round caps).",
        "",
        "## Error by width (random polylines, all angles)",
        "",
        "cv2's LINE_AA fringe lies outside the nominal thickness (a thickness-3 line is about 5 px "
        "across), so the table also gives cv2 at its best thickness among w-2 .. w+1 (the truth "
        "stays at width w).",
        "",
        "| width px | pixels | GRLAA mean | cv2 mean | cv2 best mean (thickness) | GRLAA RMSE | "
        "cv2 RMSE | GRLAA / cv2 best |",
        "| ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |",
    ]
    for r in width_rows:
        L.append(f"| {r['width']:g} | {r['pixels']} | {r['ours'][0]:.2f} | {r['cv2'][0]:.2f} | "
                 f"{r['cv2_best'][0]:.2f} ({r['cv2_best_t']}) | {r['ours'][1]:.2f} | "
                 f"{r['cv2'][1]:.2f} | {r['ours'][0] / r['cv2_best'][0]:.2f} |")
    wins = sum(r["ours"][0] < r["cv2_best"][0] for r in width_rows)
    L += ["", f"GRLAA has the lower mean error than cv2 at its best thickness at {wins} of "
          f"{len(width_rows)} widths.", "",
          "## Error by angle (one straight line, width 3 px, off the pixel grid)", "",
          "| angle deg | GRLAA mean | cv2 mean |", "| ---: | ---: | ---: |"]
    for r in angle_rows:
        L.append(f"| {r['angle']} | {r['ours'][0]:.2f} | {r['cv2'][0]:.2f} |")
    L += ["", "## Error against scale (one scene: coordinates and widths times the scale)", "",
          "Per edge length = the error summed over the image (levels, mean of RGB) divided by "
          "the length of the strokes' outlines in pixels: constant means the edge quality does "
          "not depend on scale (seed 001's claim). Per pixel falls with scale because wide "
          "strokes have more interior.", "",
          "| scale | image | GRLAA per edge px | cv2 per edge px | GRLAA per pixel | cv2 per pixel |",
          "| ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in scale_rows:
        L.append(f"| {r['scale']:g} | {r['size']} | {r['ours'][1]:.2f} | {r['cv2'][1]:.2f} | "
                 f"{r['ours'][0]:.2f} | {r['cv2'][0]:.2f} |")
    L += ["", "## Speed (1920x1080 BGR uint8, 100 polylines x 50 segments, drawn in place)", "",
          "Median of the timed runs after warm-up (min in brackets), ours and cv2 interleaved in "
          "one loop; ours includes the host's per-line tables, the device's segment tables and "
          "binning, the drawing kernel, and the frame's upload and download where the device "
          "does not share host memory (on a CPU device the kernel draws into the numpy frame). "
          f"On a host shared with other work (load average {load}) the medians move by tens of "
          "percent between runs; the minima are steadier.", "",
          "| width px | outline px | GRLAA ms | cv2 ms | GRLAA / cv2 (medians) | GRLAA / cv2 (minima) |",
          "| ---: | ---: | ---: | ---: | ---: | ---: |"]
    for r in speed_rows:
        L.append(f"| {r['width']:g} | {r['outline']:g} | {r['ours']:.1f} ({r['ours_min']:.1f}) | "
                 f"{r['cv2']:.1f} ({r['cv2_min']:.1f}) | {r['ours'] / r['cv2']:.2f} | "
                 f"{r['ours_min'] / r['cv2_min']:.2f} |")
    fast = sum(r["ours"] <= r["cv2"] for r in speed_rows)
    L += ["", f"GRLAA is at least as fast as cv2 in {fast} of {len(speed_rows)} cases (medians)."]
    return "\n".join(L) + "\n"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--device", default=None, help="OpenCL device index or name part")
    ap.add_argument("--quick", action="store_true", help="fewer widths, angles, scales and runs")
    ap.add_argument("--runs", type=int, default=25, help="timed runs per speed case (>= 20)")
    ap.add_argument("-o", "--output", default=os.path.join("docs", "grlaa_bench.md"))
    args = ap.parse_args(argv)
    t0 = time.time()
    renderer = OverlayRenderer(args.device)
    widths = [1, 3, 8, 24] if args.quick else [1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 40]
    width_rows = accuracy_by_width(renderer, widths)
    angle_rows = accuracy_by_angle(renderer, step=30 if args.quick else 5)
    scale_rows = accuracy_by_scale(renderer, scales=(0.5, 1, 2) if args.quick else (0.5, 1, 2, 4, 8))
    speed_rows = speed(renderer, runs=5 if args.quick else max(args.runs, 20))
    if not args.quick:
        speed_rows += speed(renderer, widths=(8,), runs=max(args.runs, 20), outline=True)
    cmd = "python -m mlaa_stream.bench.overlay" + (" " + " ".join(argv or sys.argv[1:])).rstrip()
    text = _report(cmd, renderer.device_name, width_rows, angle_rows, scale_rows, speed_rows,
                   time.time() - t0)
    os.makedirs(os.path.dirname(args.output) or ".", exist_ok=True)
    tmp = args.output + ".tmp"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, args.output)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
