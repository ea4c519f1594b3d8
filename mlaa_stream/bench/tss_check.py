"""Is temporal supersampling never worse than spatial only? (issue 16's on-by-default condition)

    python -m mlaa_stream.bench.tss_check [--scenes rotation,pan,mover,cut,rendered] [--method auto]
        [--views] [--exact-motion] [--lookahead 0,2] [--tss-set NAME=VALUE ...]

Runs the bench's animated scenes (mlaa_stream.yardstick.scenes, the same frames `mlaa-stream bench` scores)
(with the rendered group, also `rendered_mover`: a fast mover over a rendered still, built here) through the
spatial filter alone and through the filter + a temporal stage (--method, one of
mlaa_stream.temporal.methods.METHODS; default "auto", what --temporal runs), and prints per scene: error removed,
damage away from edges (levels), temporal error, flicker energy, FLIP as the mean over **all** frames (the
bench's FLIP column scores frame 0 only, which a temporal stage returns unchanged), the share of pixels
whose output differs from the spatial output, the share that took samples (stats "samples_share": at
least MIN_CELLS filled cells; mean over frames), and the motion model of each frame (r reset, s static,
g global, p global with projective maps, t global with tracked tiles (dense_samples), l moving layers, d dense;
TSS's models where the method has TSS). A scene is "worse" when the stage loses in error removed, damage or
all-frame FLIP.
--views adds held-out rendered shots (mlaa_stream.bench.rendered_views.view_shots: a pan and a dolly from each
held-out view at 640x360, rendered here: a few minutes), shots no constant was measured on; `--world town`: the
second world's (yardstick/town.py) instead of the plaza's; `--view-frames N`: N frames per shot (default 8).
--lookahead N[,N...]: the method with TSS reading N frames after the current one too (a row per N, named
"<method>+N" for N > 0; what `--lookahead N` runs; default DEFAULT_LOOKAHEAD, what `--temporal` reads); each
row is checked against spatial only.
--tss-set sets a constant of temporal supersampling for the run (mlaa_stream.temporal.tss.set_constant) (e.g. BAND_TOL=1e9).
--exact-motion adds two oracle rows to each of the bench's rendered shots (and the held-out shots with --views), with
the renderer's exact motion (mlaa_stream.yardstick.rendered.reprojection, from each frame's depth; needs EGL):
"tss:exact", the TSS resolve (tss_frame_reference, the kernel's twin) with every ring frame's exact per-pixel map,
"tss:homography", the same resolve with one projective map per frame pair estimated from the frames (ECC,
homography_maps: slow, a measurement of the model, not of a fast estimator), and "<method>:exact", the method
with the blend's dense flow replaced by the exact one (TSS as usual). How much better motion could buy.
--dense-samples: the rows run TSS with dense_samples (per-tile tracked motion on dense frames; named
"<method>+N:dense"). The "ms" column: the stage's wall time per frame, mean over the frames after the first.
--stripes SPEED[,SPEED...]: also the end-to-end benchmark's bars (one edge direction: the motion along them is not
measured) panning SPEED px per frame, 480x270, 12 frames (bench/temporal.py scene_stripes).
--hdr SCALE[,SCALE...]: rows for linear-light HDR frames (what an EXR sequence gives): the bench's pan (or the
animated scene --hdr-scene names, e.g. rendered_pan), its input and truth sRGB-decoded and multiplied by SCALE,
float32, the filter and the stage with linear_input; error removed in linear light (the temporal measures as for the
other rows, FLIP and damage not scored).
"""
from __future__ import annotations

import argparse
import dataclasses
import time

import numpy as np

from mlaa_stream.bench.temporal import scene_stripes
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.temporal.methods import DEFAULT_LOOKAHEAD, METHODS, make_stage, needs_regions
from mlaa_stream.temporal.motion_ring import DEFAULT_FRAMES
from mlaa_stream.temporal.resolve import tss_frame_reference
from mlaa_stream.temporal.tss import set_constant
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.scenes import SCENES, Scene, edge_mask, generate_scenes


EXACT_SHOTS = ("rendered_pan", "rendered_dolly", "rendered_orbit")   # --exact-motion: the bench's shots (and --views')
MOVER_STEP = (23, 3)  # px per frame: faster than DIS's FAST preset follows on a small textured patch


def rendered_mover(scenes: list[Scene]) -> Scene | None:
    """A fast mover over a render: an 80x100 patch of rendered_stress (input and truth) moving MOVER_STEP px per
    frame over the still rendered_atrium, 8 frames; None without both stills. The moving-layer case where the
    blend ghosts (the background a mover uncovers takes the mover's colour from the history)."""
    stills = {s.name: s for s in scenes}
    if "rendered_atrium" not in stills or "rendered_stress" not in stills:
        return None
    back, patch = stills["rendered_atrium"], stills["rendered_stress"]
    src_in, src_truth = patch.inputs[0][150:230, 300:400], patch.truths[0][150:230, 300:400]
    inputs, truths = [], []
    for t in range(8):
        x0, y0 = 40 + MOVER_STEP[0] * t, 120 + MOVER_STEP[1] * t
        a, b = back.inputs[0].copy(), back.truths[0].copy()
        a[y0:y0 + 80, x0:x0 + 100], b[y0:y0 + 80, x0:x0 + 100] = src_in, src_truth
        inputs.append(a)
        truths.append(b)
    inputs, truths = np.stack(inputs), np.stack(truths)
    return Scene("rendered_mover", "rendered", inputs, truths, np.stack([edge_mask(a, b) for a, b in zip(inputs, truths)]))


def scene_scores(outs: np.ndarray, scene, with_flip: bool) -> dict[str, float]:
    r = M.score(outs, scene.inputs, scene.truths, scene.edges, scene.wires, scene.backgrounds)
    r["flip_all"] = (float(np.mean([M.flip(outs[t], scene.truths[t]) for t in range(len(outs))]))
                     if with_flip else float("nan"))
    return r


def shot_cameras(name: str, width: int, height: int, frames: int, world: str = "plaza") -> list | None:
    """The cameras of a rendered shot of this check (the bench's EXACT_SHOTS, the held-out view shots of `world`),
    else None."""
    from mlaa_stream.bench.rendered_views import view_cameras
    from mlaa_stream.yardstick import rendered as R
    if name in EXACT_SHOTS:
        return R.shot(name, width, height)
    return view_cameras(width, height, frames, world).get(name)


def exact_maps(cams: list, width: int, height: int, world: str = "plaza") -> dict[tuple[int, int], np.ndarray]:
    """A shot's exact motion: maps[t, u] = frame t's (H, W, 2) offsets into frame u, for u < t."""
    from mlaa_stream.yardstick import rendered as R
    depths = R.depth_frames(cams, width, height, world=world)
    return {(t, u): R.reprojection(cams[t], cams[u], depths[t]) for t in range(len(cams)) for u in range(t)}


def homography_maps(inputs: np.ndarray) -> dict[tuple[int, int], np.ndarray]:
    """One projective map per frame pair, estimated from the 1-spp frames alone: cv2.findTransformECC
    (MOTION_HOMOGRAPHY) of frame t's grey against frame u's, both blurred by 1 px, directly for every pair
    (started from the estimate of the pair (t - 1, u)); maps[t, u] as exact_maps gives them. A camera that
    turns about its eye (the pans) moves the image by exactly such a map."""
    import cv2
    grey = [cv2.GaussianBlur(cv2.cvtColor(f, cv2.COLOR_RGB2GRAY).astype(np.float32), (0, 0), 1.0) for f in inputs]
    h, w = grey[0].shape
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32)
    found, maps = {}, {}
    for t in range(len(grey)):
        for u in range(t):
            start = found.get((t - 1, u), np.eye(3, dtype=np.float32))
            try:
                _, found[t, u] = cv2.findTransformECC(grey[t], grey[u], start.copy(), cv2.MOTION_HOMOGRAPHY,
                                                      (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 60, 1e-5),
                                                      None, 1)
            except cv2.error:   # no convergence: keep the start
                found[t, u] = start
            p = np.stack([xs, ys, np.ones_like(xs)], -1) @ found[t, u].T
            maps[t, u] = np.stack([p[..., 0] / p[..., 2] - xs, p[..., 1] / p[..., 2] - ys], -1).astype(np.float32)
    return maps


def with_grain(scene: Scene, sigma: float, seed: int = 1) -> Scene:
    """`scene` with seeded Gaussian grain of `sigma` levels, new every frame (one value for R, G and B), added to
    input and truth alike, as grain added after rendering; edges kept from the clean scene."""
    n = np.random.default_rng(seed).normal(0.0, sigma, scene.inputs.shape[:3] + (1,))
    inputs, truths = (np.clip(np.round(a + n), 0, 255).astype(np.uint8) for a in (scene.inputs, scene.truths))
    return dataclasses.replace(scene, name=f"{scene.name}_grain{sigma:g}", inputs=inputs, truths=truths)


def exact_tss(scene: Scene, spatial: np.ndarray, maps: dict) -> np.ndarray:
    """TSS's resolve with exact maps: each frame from its last DEFAULT_FRAMES - 1 inputs and itself."""
    outs = []
    for t, (f, sp) in enumerate(zip(scene.inputs, spatial)):
        ring = [(scene.inputs[u], maps[t, u], None) for u in range(max(0, t - DEFAULT_FRAMES + 1), t)]
        outs.append(tss_frame_reference(sp, f, ring + [(f, (0.0, 0.0), None)], bgr=False)[0])
    return np.stack(outs)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenes", default="rotation,pan,mover,cut,rendered")
    ap.add_argument("--device", default=None)
    ap.add_argument("--method", default="auto", choices=METHODS)
    ap.add_argument("--views", action="store_true", help="also held-out rendered shots (needs EGL)")
    ap.add_argument("--world", default="plaza", choices=("plaza", "town"),
                    help="the world of the --views shots (default %(default)s)")
    ap.add_argument("--view-frames", type=int, default=8, metavar="N",
                    help="frames per --views shot (default %(default)s; more: longer rings, a few minutes more)")
    ap.add_argument("--tss-set", action="append", default=[], metavar="NAME=VALUE")
    ap.add_argument("--lookahead", default=str(DEFAULT_LOOKAHEAD), metavar="N[,N...]",
                    help="frames after the current one TSS also reads; a row per value (default: what --temporal "
                         f"reads, {DEFAULT_LOOKAHEAD})")
    ap.add_argument("--exact-motion", action="store_true",
                    help="oracle rows with the renderer's exact motion on the rendered shots (needs EGL)")
    ap.add_argument("--dense-samples", action="store_true",
                    help="TSS tracks per-tile motion on dense frames (dense_samples; slow)")
    ap.add_argument("--grain", default="", metavar="SIGMA[,SIGMA...]",
                    help="also every scene with film grain of these deviations in 8-bit levels: seeded Gaussian, new "
                         "every frame, one value for R, G and B, added to input and truth alike (NAME_grainN)")
    ap.add_argument("--stripes", default="", metavar="SPEED[,SPEED...]",
                    help="also the end-to-end benchmark's bars (one edge direction) panning SPEED px per frame "
                         "(stripes_SPEED: 480x270, 12 frames)")
    ap.add_argument("--hdr", default="", metavar="SCALE[,SCALE...]",
                    help="also the pan as linear-light HDR frames times each SCALE (linear_input)")
    ap.add_argument("--hdr-scene", default="pan", metavar="NAME",
                    help="the animated bench scene of the --hdr rows (default pan; e.g. rendered_pan, whose render "
                         "regions the blend of method auto acts in)")
    args = ap.parse_args(argv)
    lookaheads = [0] if args.method == "blend" else [int(v) for v in args.lookahead.split(",")]   # blend: the past
    for item in args.tss_set:
        set_constant(*item.split("=", 1))
    with_flip = M.flip_available()
    every = generate_scenes(names=args.scenes.split(","))
    scenes = [s for s in every if s.animated] + [m for m in [rendered_mover(every)] if m is not None]
    if args.views:
        from mlaa_stream.bench.rendered_views import view_shots
        scenes += view_shots(640, 360, args.view_frames, world=args.world)
    scenes += [with_grain(s, float(g)) for g in args.grain.split(",") if g for s in scenes]
    scenes += [scene_stripes(12, 480, 270, float(v)) for v in args.stripes.split(",") if v]
    worse = []
    with Filter(args.device, bgr=False, keep_regions=needs_regions(args.method)) as filt:
        print(f"device: {filt.device_name}; FLIP {'over all frames' if with_flip else 'not installed'}")
        print(f"{'scene':16s} {'method':8s} {'err.rem':>8s} {'damage':>8s} {'temp.err':>9s} {'flicker':>8s} "
              f"{'FLIP all':>9s} {'changed':>8s} {'sampled':>8s} {'ms':>6s}  models")
        for s in scenes:
            spatial, regions = [], []
            filt.new_shot()  # each scene its own shot
            for f in s.inputs:
                spatial.append(filt.process(f))
                regions.append(filt.last_regions)
            spatial = np.stack(spatial)
            a = scene_scores(spatial, s, with_flip)
            rows = [("mlaa", a, "")]
            for n in lookaheads:
                stage = make_stage(args.method, filt.context, bgr=False, lookahead=n, dense_samples=args.dense_samples)
                outs, ms = run_stage(stage, s.inputs, spatial, regions, n)
                stats = stage.stats
                b = scene_scores(outs, s, with_flip)
                changed = float(np.mean(np.any((outs != spatial).reshape(outs.shape[:3] + (-1,)), -1)))
                models = "".join("p" if r.get("projective") else "t" if r.get("tracked") else r["model"][0]
                                 for r in stats)
                sampled = float(np.mean([r.get("samples_share", float("nan")) for r in stats]))
                name = args.method + (f"+{n}" if n else "") + (":dense" if args.dense_samples else "")
                rows.append((name, b, f"{changed:8.3f} {sampled:8.3f} {ms:6.0f}  {models}"))
                if (b["error_removed"] < a["error_removed"] or b["damage"] > a["damage"]
                        or (with_flip and b["flip_all"] > a["flip_all"])):
                    worse.append(f"{s.name} ({name})")
            cams = (shot_cameras(s.name, s.inputs.shape[2], s.inputs.shape[1], len(s.inputs), args.world)
                    if args.exact_motion else None)
            if cams is not None:
                maps = exact_maps(cams, s.inputs.shape[2], s.inputs.shape[1],
                                  "plaza" if s.name in EXACT_SHOTS else args.world)
                rows.append(("tss:exact", scene_scores(exact_tss(s, spatial, maps), s, with_flip), ""))
                homographies = homography_maps(s.inputs)
                rows.append(("tss:homography", scene_scores(exact_tss(s, spatial, homographies), s, with_flip), ""))
                if args.method != "tss":
                    known = make_stage(args.method, filt.context, bgr=False,
                                       motion=lambda t, m=maps: m[t, t - 1] if t > 0 else None)
                    outs = np.stack([known(f, sp, i, regions=r)
                                     for i, (f, sp, r) in enumerate(zip(s.inputs, spatial, regions))])
                    known.close()
                    rows.append((f"{args.method}:exact", scene_scores(outs, s, with_flip), ""))
            for name, r, extra in rows:
                print(f"{s.name:16s} {name:8s} {r['error_removed']:8.3f} {r['damage']:8.4f} "
                      f"{r['temporal_error']:9.3f} {r['flicker']:8.3f} {r['flip_all']:9.5f} {extra}", flush=True)
    for scale in [float(v) for v in args.hdr.split(",") if v]:
        worse += hdr_rows(args, scale, lookaheads)
    print("worse than spatial only:", ", ".join(worse) if worse else "none")
    return 0


def linear_light(frames: np.ndarray, scale: float) -> np.ndarray:
    """8-bit sRGB frames as float32 linear light times `scale` (IEC 61966-2-1)."""
    c = frames.astype(np.float64) / 255.0
    return (scale * np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)).astype(np.float32)


def hdr_rows(args, scale: float, lookaheads: list[int]) -> list[str]:
    """--hdr: the scene --hdr-scene (the pan) as linear-light frames times `scale`, spatial only against the method
    (linear_input)."""
    group = args.hdr_scene if args.hdr_scene in SCENES else args.hdr_scene.split("_")[0]   # rendered_pan: rendered
    found = [s for s in generate_scenes(names=[group]) if s.animated and s.name == args.hdr_scene] \
        if group in SCENES else []
    if not found:
        raise SystemExit(f"--hdr-scene: expected an animated bench scene such as pan or rendered_pan, "
                         f"got {args.hdr_scene!r}")
    pan = found[0]
    inputs, truths = linear_light(pan.inputs, scale), linear_light(pan.truths, scale)
    name, worse = f"{pan.name} x{scale:g} lin", []
    with Filter(args.device, bgr=False, linear_input=True, keep_regions=needs_regions(args.method)) as filt:
        spatial, regions = [], []
        for f in inputs:
            spatial.append(filt.process(f))
            regions.append(filt.last_regions)
        spatial = np.stack(spatial)
        a = M.error_removed(spatial, inputs, truths)
        print(f"{name:16s} {'mlaa':8s} {a:8.3f} {'-':>8s} {M.temporal_error(spatial, inputs, truths):9.3f} "
              f"{M.flicker_ratio(spatial, truths):8.3f} {'-':>9s}", flush=True)
        for n in lookaheads:
            stage = make_stage(args.method, filt.context, bgr=False, lookahead=n, linear_input=True,
                               dense_samples=args.dense_samples)
            outs, ms = run_stage(stage, inputs, spatial, regions, n)
            b = M.error_removed(outs, inputs, truths)
            row = args.method + (f"+{n}" if n else "") + (":dense" if args.dense_samples else "")
            finite = bool(np.isfinite(outs).all())
            print(f"{name:16s} {row:8s} {b:8.3f} {'-':>8s} {M.temporal_error(outs, inputs, truths):9.3f} "
                  f"{M.flicker_ratio(outs, truths):8.3f} {'-':>9s} finite {finite}, max {float(outs.max()):.2f} "
                  f"(input {float(inputs.max()):.2f}), {ms:.0f} ms", flush=True)
            if b < a or not finite:
                worse.append(f"{name} ({row})")
    return worse


def run_stage(stage, inputs: np.ndarray, spatial: np.ndarray, regions: list, n: int) -> tuple[np.ndarray, float]:
    """The stage over a scene (reading n frames ahead): its outputs and wall ms per frame (mean over the frames after
    the first, which builds the kernels); closes it."""
    outs, times = [], []
    for i, (f, sp, r) in enumerate(zip(inputs, spatial, regions)):
        t0 = time.perf_counter()
        outs.append(stage(f, sp, i, regions=r, **({"future": inputs[i + 1:i + 1 + n]} if n else {})))
        times.append((time.perf_counter() - t0) * 1e3)
    stage.close()
    return np.stack(outs), float(np.mean(times[1:] or times))


if __name__ == "__main__":
    raise SystemExit(main())
