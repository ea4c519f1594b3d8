"""Benchmark of the temporal stage: accuracy and steadiness on animated scenes, speed per 1080p frame.

    python -m mlaa_stream.bench.temporal [--frames 24] [--width 480] [--height 270] [--timed 12] [--rendered]

Writes docs/temporal_bench.md (command, device, date). Scenes are rendered here with the scene
module's rasteriser (1 sample per pixel input, 8x8 supersampled truth in linear light), longer than
the bench's own animated scenes so that a history can build up: slow rotation, sub-pixel pan, a
fast mover with disocclusion, a hard cut; --rendered adds the rendered shots of
mlaa_stream.yardstick.rendered (pan, dolly, orbit; cached). Metrics are mlaa_stream.yardstick.metrics'
(temporal error, flicker energy ratio, error removed, damage away from edges). Methods: spatial only
(Filter), + temporal supersampling (TSSStage) for several K, + the older reprojection blending
(TemporalStage, adaptive).
"""
from __future__ import annotations

import argparse
import datetime as _dt
import math
import statistics
import sys
import time
from pathlib import Path

import cv2
import numpy as np

from mlaa_stream.yardstick import metrics as M
from mlaa_stream.device.colour import linear_to_srgb, srgb_to_linear
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.yardstick.scenes import (Layer, Scene, build_scene, edge_mask, ellipse, rect, rotated_rect,
                                           text_polygons, timing_frame, translate)
from mlaa_stream.temporal.stage import TemporalStage
from mlaa_stream.temporal.tss import DEFAULT_FRAMES, TSSStage, TSSThenBlend

MODES = ["adaptive", "dense", "global", "static"]   # of the blend stage (--blend-modes)
TSS_FRAMES = (8, 16, 24)
DOCS = Path(__file__).resolve().parent.parent.parent / "docs" / "temporal_bench.md"


# --- scenes (T frames each) ---------------------------------------------------------------------------
def _pan_layers(w: int, h: int, dx: float, dy: float) -> list[Layer]:
    m = 40.0  # geometry extends past the frame so the pan never uncovers an empty border
    polys = [
        ((rect(-m, -m, w + m, h * 0.5),), (232, 232, 226)),
        ((np.array([[-m, h * 0.22], [w + m, h * 0.22 + (w + 2 * m) / 300.0], [w + m, h * 0.5],
                    [-m, h * 0.5]]),), (24, 24, 28)),
        ((np.array([[-m, h * 0.5], [w + m, h * 0.5], [w + m, h * 0.75 - (w + 2 * m) / 260.0],
                    [-m, h * 0.75]]),), (40, 150, 70)),
        ((rect(-m, h * 0.75, w + m, h + m),), (240, 240, 236)),
        ((rotated_rect(w * 0.2, h * 0.62, h * 0.3, h * 0.18, 30),), (200, 48, 40)),
        ((rotated_rect(w * 0.45, h * 0.62, h * 0.3, h * 0.18, -60),), (60, 80, 190)),
        ((np.array([[w * 0.65, h * 0.72], [w * 0.65 + h * 0.2, h * 0.52], [w * 0.65 + h * 0.4, h * 0.72]]),),
         (120, 40, 40)),
        (text_polygons("Sub-pixel pan 0123", w * 0.05, h * 0.95, max(10.0, h * 0.08)), (20, 20, 24)),
        ((rotated_rect(w * 0.5, h * 0.35, w * 1.2, 0.8, 4.0),), (30, 30, 30)),
    ]
    return [Layer(None, (128, 128, 128))] + [Layer(translate(p, dx, dy), c) for p, c in polys]


def scene_pan(n: int, w: int, h: int) -> Scene:
    frames = [_pan_layers(w, h, 0.35 * t, 0.15 * t) for t in range(n)]
    return build_scene("pan", "pan", frames, w, h, notes="whole frame pans (0.35, 0.15) px per frame")


def scene_stripes(n: int, w: int, h: int, speed: float) -> Scene:
    """The end-to-end benchmark's clip (bench/pipeline.py synthetic_clip: hard-edged bars at slope 1/3, 40 px apart
    across x 0.3 + y 0.9) panning `speed` px per frame to the left: 1 spp at pixel centres, truth 8x8 in linear light.
    One edge direction only: the motion along the bars cannot be measured (docs/temporal.md, "Stripes")."""
    cols = (np.uint8([230, 180, 40]), np.uint8([30, 50, 120]))
    lin = [srgb_to_linear(c.astype(np.float64) / 255.0) for c in cols]
    y, x = np.mgrid[0:h, 0:w].astype(np.float64) + 0.5

    def shot(t: float, ss: int) -> np.ndarray:
        offsets = (np.arange(ss) + 0.5) / ss - 0.5
        acc = np.zeros((h, w, 3))
        for dy in offsets:
            for dx in offsets:
                band = (np.floor(((x + dx + speed * t) * 0.3 + (y + dy) * 0.9) / 40) % 2).astype(bool)
                acc += np.where(band[..., None], lin[0], lin[1])
        return np.round(linear_to_srgb(acc / ss ** 2) * 255).astype(np.uint8)

    inputs = np.stack([shot(t, 1) for t in range(n)])
    truth = np.stack([shot(t, 8) for t in range(n)])
    return Scene(f"stripes_{speed:g}", "pan", inputs, truth, edge_mask(inputs, truth),
                 notes=f"bars at slope 1/3 panning {speed:g} px per frame")


def scene_rotation(n: int, w: int, h: int) -> Scene:
    frames = []
    for t in range(n):
        ang = 10.0 + 0.5 * t
        cx, cy = w / 2 + 0.21, h / 2 + 0.13
        frames.append([Layer(None, (235, 230, 220)),
                       Layer((rotated_rect(cx, cy, h * 0.6, h * 0.6, ang),), (40, 60, 120)),
                       Layer((rotated_rect(cx, cy, h * 0.9, 0.8, ang + 45),), (20, 20, 20))])
    return build_scene("rotation", "rotation", frames, w, h,
                       notes="square and a 0.8-px bar turning 0.5 degrees per frame")


def scene_mover(n: int, w: int, h: int) -> Scene:
    stripes = tuple(rotated_rect(x, h / 2, 5.0, h * 1.5, 8.0) for x in np.arange(-20, w + 20, 14.0))
    step = (w * 0.8) / max(n - 1, 1)
    frames = []
    for t in range(n):
        x = w * 0.05 + step * t + 0.3
        frames.append([Layer(None, (210, 220, 200)), Layer(stripes, (90, 110, 80)),
                       Layer((rotated_rect(x + h * 0.15, h * 0.5 + 0.4, h * 0.3, h * 0.3, 22.0),),
                             (200, 40, 30))])
    return build_scene("mover", "mover", frames, w, h,
                       notes=f"a box moving {step:.1f} px per frame over slanted stripes (disocclusion)")


def scene_cut(n: int, w: int, h: int) -> Scene:
    frames = []
    cut = n // 2
    for t in range(n):
        if t < cut:
            cell = h // 2
            layers = [Layer(None, (232, 232, 226))]
            for k, ang in enumerate([30, 45, 60, -30, -45, -60, 20, -20]):
                cx, cy = (k % 4) * w / 4 + w / 8, (k // 4) * cell + cell / 2
                layers.append(Layer((rotated_rect(cx + 0.25 * t, cy + 0.1 * t, cell * 0.7, cell * 0.45, ang),),
                                    (24 + 20 * k, 60, 150 - 10 * k)))
            frames.append(layers)
        else:
            frames.append([Layer(None, (20, 30, 40)),
                           Layer((ellipse(w / 2 + 0.3 * t, h / 2, w * 0.35, h * 0.3),), (230, 200, 80)),
                           Layer((rotated_rect(w / 2, h / 2 + 0.25 * t, w * 0.5, 3.0, 12.0),), (20, 30, 40))])
    return build_scene("cut", "cut", frames, w, h, notes=f"slow pan, hard cut after frame {cut - 1}")


SCENES = {"rotation": scene_rotation, "pan": scene_pan, "mover": scene_mover, "cut": scene_cut}


def exact_motion(name: str, w: int, h: int) -> np.ndarray | None:
    """The scene's true motion as a 2x3 map from a pixel of frame t to where it was in frame t-1
    (None where the motion is not one affine map: the mover, the cut)."""
    if name == "pan":
        return np.float32([[1, 0, -0.35], [0, 1, -0.15]])
    if name == "rotation":
        a = math.radians(-0.5)
        c, s = math.cos(a), math.sin(a)
        cx, cy = w / 2 + 0.21, h / 2 + 0.13
        return np.float32([[c, -s, cx - c * cx + s * cy], [s, c, cy - s * cx - c * cy]])
    return None


def reprojected_truth(truths: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """Frame t = the true frame t-1 warped by the exact motion (Catmull-Rom, linear light): the best
    history any reprojection can bring, so the floor of the stage's temporal error on this metric."""
    h, w = truths.shape[1:3]
    lin = srgb_to_linear(truths.astype(np.float32) / 255.0).astype(np.float32)
    outs = [truths[0]]
    for t in range(1, len(truths)):
        warped = cv2.warpAffine(lin[t - 1], motion, (w, h), flags=cv2.INTER_CUBIC | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_REPLICATE)
        outs.append(np.clip(linear_to_srgb(warped) * 255.0 + 0.5, 0, 255).astype(np.uint8))
    return np.stack(outs)


# --- runs -------------------------------------------------------------------------------------------
def run_sequence(scene: Scene, spatial: list[np.ndarray], mode: str | None,
                 device: str | None = None) -> tuple[np.ndarray, list[dict]]:
    """Scene frames through a temporal stage after the spatial outputs: mode None = spatial only,
    "tss K" = TSSStage(frames=K), otherwise TemporalStage(mode) (the blend)."""
    if mode is None:
        return np.stack(spatial), []
    if mode == "tss+blend":
        with TSSThenBlend(device, bgr=False) as stage:
            outs = [stage(f, s, i) for i, (f, s) in enumerate(zip(scene.inputs, spatial))]
            return np.stack(outs), stage.stats
    if mode.startswith("tss"):
        k, ahead = _tss_mode(mode)
        with TSSStage(device, frames=k, bgr=False, lookahead=ahead) as stage:
            outs = [stage(f, s, i, future=scene.inputs[i + 1:i + 1 + ahead]) for i, (f, s) in
                    enumerate(zip(scene.inputs, spatial))]
            return np.stack(outs), stage.stats
    with TemporalStage(device, mode=mode, bgr=False) as stage:
        outs = [stage(f, s, i) for i, (f, s) in enumerate(zip(scene.inputs, spatial))]
        return np.stack(outs), stage.stats


def score(outs: np.ndarray, scene: Scene) -> dict[str, float]:
    return {"temporal_error": M.temporal_error(outs, scene.inputs, scene.truths),
            "flicker": M.flicker_ratio(outs, scene.truths),
            "error_removed": M.error_removed(outs, scene.inputs, scene.truths),
            "damage": M.damage(outs, scene.inputs, scene.truths, scene.edges)}


def _pan_frames(n: int, base: np.ndarray, step=(0.35, 0.15)) -> list[np.ndarray]:
    """n frames of a 1080p pan: `base` shifted by t*step (bilinear), cropped to 1920x1080."""
    out = []
    for t in range(n):
        m = np.float32([[1, 0, -step[0] * t - 8], [0, 1, -step[1] * t - 8]])
        out.append(cv2.warpAffine(base, m, (1920, 1080), flags=cv2.INTER_LINEAR))
    return out


def _turning_frames(n: int, base: np.ndarray, deg: float = 0.5) -> list[np.ndarray]:
    """n frames of 1080p: a disc of `base` (radius 300 px) turning `deg` degrees per frame about its centre over the
    still rest of it (TSS: moving layers), cropped to 1920x1080."""
    still = base[8:1088, 8:1928]
    ys, xs = np.mgrid[0:1080, 0:1920]
    disc = (np.hypot(xs - 960.3, ys - 540.2) <= 300)[..., None]
    out = []
    for t in range(n):
        m = cv2.getRotationMatrix2D((960.3, 540.2), deg * t, 1.0)
        out.append(np.where(disc, cv2.warpAffine(still, m, (1920, 1080), flags=cv2.INTER_LINEAR), still))
    return out


def time_stage(frames: list[np.ndarray], spatial: list[np.ndarray], mode: str, warmup: int,
               device: str | None) -> tuple[float, dict[str, int], float, float]:
    """Median wall ms of the stage per frame after warm-up, the models used, median flow/blend ms."""
    if mode == "tss+blend":
        stage_cm = TSSThenBlend(device, bgr=False)
    elif mode.startswith("tss"):
        k, ahead = _tss_mode(mode)
        stage_cm = TSSStage(device, frames=k, bgr=False, lookahead=ahead)
    else:
        stage_cm = TemporalStage(device, mode=mode, bgr=False)
    with stage_cm as stage:
        times = []
        ahead = getattr(stage, "lookahead", 0)
        for i, (f, s) in enumerate(zip(frames, spatial)):
            t0 = time.perf_counter()
            stage(f, s, i, **({"future": frames[i + 1:i + 1 + ahead]} if ahead else {}))
            if warmup <= i < len(frames) - ahead:   # look-ahead: frames with all N frames ahead
                times.append((time.perf_counter() - t0) * 1e3)
        st = stage.stats[warmup:len(frames) - ahead]
        models: dict[str, int] = {}
        for r in st:
            models[r["model"]] = models.get(r["model"], 0) + 1
        return (statistics.median(times), models, statistics.median(r["flow_ms"] for r in st),
                statistics.median(r.get("blend_ms", r.get("resolve_ms", 0.0)) for r in st))


def _tss_key(mode: str) -> str:
    k, ahead = _tss_mode(mode)
    return f"+TSS K={k}" + (f", look-ahead {ahead}" if ahead else "")


def _tss_mode(mode: str) -> tuple[int, int]:
    """"tss K" or "tss K+N" (N frames of look-ahead): (K, N)."""
    k, _, ahead = mode.split()[1].partition("+")
    return int(k), int(ahead or 0)


def _set_tss_constants(pairs: list[str]) -> None:
    """--tss-set NAME=VALUE: the tuning runs of docs/temporal.md, by command."""
    from mlaa_stream.temporal.tss import set_constant
    names = ("FULL_CELLS", "FULL_CELLS_AHEAD", "REFINE_POINTS", "REFINE_STEPS", "NEWEST_STEPS", "REFINE_EVERY", "TILE_TOL",
             "BAND_TOL", "BAND_TEXTURE", "STATIC_TOL", "BAND_GROWTH", "BAND_FAR", "TRAJECTORY_MIN", "TRAJECTORY_TOL",
             "TRAJECTORY_DEGREE", "TRAJECTORY_AHEAD")
    for pair in pairs:
        name, _, value = pair.partition("=")
        if name not in names:
            raise SystemExit(f"--tss-set: expected one of {', '.join(names)}, got {name!r}")
        set_constant(name, value)


def _fmt(v: float, digits: int = 3) -> str:
    return "n/a" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.{digits}f}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mlaa_stream.bench.temporal", description=__doc__.split("\n")[0])
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--width", type=int, default=480)
    ap.add_argument("--height", type=int, default=270)
    ap.add_argument("--timed", type=int, default=12, help="timed 1080p frames after warm-up (0: skip speed)")
    ap.add_argument("--rendered", action="store_true", help="also the rendered pan, dolly and orbit shots")
    ap.add_argument("--tss-frames", default=",".join(map(str, TSS_FRAMES)), help="K values for TSS rows")
    ap.add_argument("--blend-modes", default="adaptive", help="modes of the older blend stage ('' for none)")
    ap.add_argument("--lookahead", default="2,4", help="look-ahead frames N for rows of TSS with K = 16 ('' for none)")
    ap.add_argument("--device", default=None)
    ap.add_argument("--scenes", default=",".join(SCENES))
    ap.add_argument("--out", default=str(DOCS))
    ap.add_argument("--tss-set", action="append", default=[], metavar="NAME=VALUE",
                    help="tuning: set a constant of temporal supersampling for this run (FULL_CELLS, BAND_TOL, "
                         "REFINE_POINTS, REFINE_STEPS, NEWEST_STEPS, REFINE_EVERY, TILE_TOL; repeatable)")
    args = ap.parse_args(argv)
    _set_tss_constants(args.tss_set)
    command = "python -m mlaa_stream.bench.temporal " + " ".join(argv if argv is not None else sys.argv[1:])
    lines: list[str] = []

    def log(msg: str) -> None:
        print(msg, flush=True)

    spatial_filter = Filter(args.device)
    device = spatial_filter.device_name
    results: dict[str, dict[str, dict]] = {}
    model_use: dict[str, dict[str, dict[str, int]]] = {}
    ahead_modes = [f"tss {DEFAULT_FRAMES}+{n}" for n in args.lookahead.split(",") if n]
    methods = [None] + [f"tss {k}" for k in args.tss_frames.split(",") if k] + ahead_modes + \
        [m for m in args.blend_modes.split(",") if m] + ["tss+blend"]
    scenes = []
    for name in args.scenes.split(","):
        t0 = time.perf_counter()
        scenes.append((name, SCENES[name](args.frames, args.width, args.height)))
        log(f"{name}: rendered {args.frames} frames {args.width}x{args.height} in {time.perf_counter() - t0:.1f} s")
    if args.rendered:
        from mlaa_stream.yardstick.scenes import generate_scenes
        for sc in generate_scenes(names=["rendered"]):
            if sc.animated:
                scenes.append((sc.name, sc))
    for name, scene in scenes:
        spatial_filter.new_shot()  # each scene its own shot
        spatial = [spatial_filter.process(f) for f in scene.inputs]
        results[name], model_use[name] = {}, {}
        for mode in methods:
            outs, stats = run_sequence(scene, spatial, mode, args.device)
            key = ("spatial only" if mode is None else f"+TSS K={DEFAULT_FRAMES} then blend" if mode == "tss+blend"
                   else _tss_key(mode) if mode.startswith("tss") else f"+blend {mode}")
            results[name][key] = score(outs, scene)
            counts: dict[str, int] = {}
            for r in stats:
                counts[r["model"]] = counts.get(r["model"], 0) + 1
            model_use[name][key] = counts
            s = results[name][key]
            log(f"  {key:22s} temporal error {_fmt(s['temporal_error'])}  flicker {_fmt(s['flicker'])}  "
                f"error removed {_fmt(s['error_removed'])}  damage {_fmt(s['damage'], 2)}  models {counts}")
        results[name]["input"] = score(scene.inputs, scene)
        # a reference point for the metric: the truth itself, slightly blurred
        blurred = np.stack([cv2.GaussianBlur(t, (0, 0), 0.5) for t in scene.truths])
        results[name]["truth blurred (sigma 0.5 px)"] = score(blurred, scene)
        motion = exact_motion(name, args.width, args.height)
        if motion is not None:
            results[name]["previous truth reprojected exactly"] = score(
                reprojected_truth(np.stack(scene.truths), motion), scene)

    speed = {}
    if args.timed > 0:
        n = args.timed + max([int(k) for k in args.tss_frames.split(",") if k] + [3, DEFAULT_FRAMES]) + max(
            [int(v) for v in args.lookahead.split(",") if v] + [0])
        base = timing_frame(1936, 1096)
        pan = _pan_frames(n, base)
        turning = _turning_frames(n, base)
        static = [base[8:1088, 8:1928].copy()] * n
        # a still shot through a codec: the same frame with +-1 level of noise on 2 % of its samples
        rng = np.random.default_rng(0)
        noisy = []
        for _ in range(n):
            f = static[0].astype(np.int16)
            f += (rng.random(f.shape) < 0.02) * rng.choice(np.array([-1, 1], np.int16), f.shape)
            noisy.append(np.clip(f, 0, 255).astype(np.uint8))
        pan_sp = [spatial_filter.process(f) for f in pan]
        static_sp = [spatial_filter.process(static[0])] * n
        noisy_sp = [spatial_filter.process(f) for f in noisy]
        turning_sp = [spatial_filter.process(f) for f in turning]
        for shot, frames, sp in (("pan", pan, pan_sp), ("turning layer", turning, turning_sp), ("static", static, static_sp),
                                 ("static, codec noise", noisy, noisy_sp)):
            for mode in [f"tss {k}" for k in args.tss_frames.split(",") if k] + ahead_modes + ["adaptive", "tss+blend"]:
                warm = _tss_mode(mode)[0] if mode.startswith("tss ") else DEFAULT_FRAMES if mode == "tss+blend" else 3
                speed[(shot, mode)] = time_stage(frames, sp, mode, warm, args.device)
                ms, models, fms, bms = speed[(shot, mode)]
                log(f"speed {shot} {mode}: {ms:.1f} ms per 1080p frame (flow+decision {fms:.1f}, "
                    f"upload+blend+download {bms:.1f}), models {models}")
    spatial_filter.close()

    date = _dt.datetime.now().strftime("%Y-%m-%d %H:%M")
    lines += ["# Temporal stage benchmark", "",
              f"- command: `{command.strip()}`", f"- device: {device}", f"- date: {date}",
              f"- scenes: {args.frames} frames of {args.width}x{args.height}, input 1 sample per pixel, "
              "truth 8x8 samples resolved in linear light (rendered by mlaa_stream.bench.temporal)"
              + ("; rendered_*: the rendered shots (mlaa_stream.yardstick.rendered, 8 frames of 640x360)"
                 if args.rendered else ""), "",
              "Temporal error = mean |(out_t - out_t-1) - (truth_t - truth_t-1)| / the same for the input "
              "(< 1 steadier than the input; goal <= 0.2 on rotation and pan). Flicker = sum (out_t - out_t-1)^2 / "
              "sum (truth_t - truth_t-1)^2 (1 ideal; goal 0.8-1.2). Error removed = 1 - MSE(out, truth) / "
              "MSE(in, truth) (goal: above spatial only everywhere). Damage = RMSE in 8-bit levels away from edges "
              "(lower is better). TSS = temporal supersampling (mlaa_stream.temporal.tss, the default "
              f"K = {DEFAULT_FRAMES}); blend = the older reprojection blending (mlaa_stream.temporal.stage).", ""]
    for name, rows in results.items():
        lines += [f"## {name}", "", "| method | temporal error | flicker energy | error removed | damage | models used |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for key, s in rows.items():
            used = model_use[name].get(key, {})
            lines.append(f"| {key} | {_fmt(s['temporal_error'])} | {_fmt(s['flicker'])} | "
                         f"{_fmt(s['error_removed'])} | {_fmt(s['damage'], 2)} | "
                         f"{', '.join(f'{k} {v}' for k, v in used.items()) or '-'} |")
        lines.append("")
    if speed:
        lines += ["## Speed (1920x1080, temporal stage only, wall clock)", "",
                  f"Median over {args.timed} frames after warm-up (K frames for TSS, 3 for the blend); the pan is "
                  "the timing frame shifted (0.35, 0.15) px per frame; the turning layer is a disc of it (radius 300 "
                  "px) turning 0.5 degrees per frame over the still rest (TSS: moving layers); the static shot "
                  "repeats one frame "
                  "(identical frames: the previous output is returned, no kernel); the codec-noise static shot "
                  "adds +-1 level to 2 % of the samples of each frame (TSS: every sample in one cell, no kernel; "
                  "blend: unwarped blend). Machine shared with other jobs: compare rows of one run.", "",
                  "| shot | method | ms / frame | motion ms (host) | upload + kernel + download ms | models |",
                  "| --- | --- | --- | --- | --- | --- |"]
        for (shot, mode), (ms, models, fms, bms) in speed.items():
            lines.append(f"| {shot} | {mode} | {ms:.1f} | {fms:.1f} | {bms:.1f} | "
                         f"{', '.join(f'{k} {v}' for k, v in models.items())} |")
        lines.append("")
    Path(args.out).write_text("\n".join(lines))
    log(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
