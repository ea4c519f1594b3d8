"""Held-out rendered views: the rendered world (yardstick/rendered.py) seen from cameras that no bench scene uses.

    python -m mlaa_stream.bench.rendered_views [--methods none,fxaa,mlaa,mlaa:screen,mlaa:rendered]
                                               [--sizes 640x360,960x540] [--samples 1,2,3]
                                               [--world plaza|town] [--textures procedural|photo|relief]
                                               [--texture-repeat 4] [--msaa 4] [--crf 18,23] [--exposures 0.5,0.3]
                                               [--tonemaps aces,reinhard] [--verdicts]

The bench's rendered scenes are what the spatial filter's rendered-content rules were measured on; these views
are not, so a rule that only fits those five scenes shows here. Each view is rendered like the bench's (1 spp at
pixel centres; truth: 8x8 jittered samples averaged in linear light), at each size, and every method of the
bench (mlaa_stream.bench.accuracy.METHODS) prints error removed % / damage away from edges (levels) / FLIP per
view, with the mean error removed. `--samples 2,3`: also inputs already supersampled (2x2, 3x3 samples per pixel on
an ordered grid, as renderers with supersampling make them; view_WIDTH_NxN): a filter should leave them about as
they are. `--textures photo|relief`: the worlds' walls, roofs and floors textured with photographs (as real scenes
are; yardstick/photo_textures.py; `--texture-repeat 4`: four times finer). `--msaa 4`: also inputs drawn with MSAA
(view_WIDTH_msaa4: edges from 4 coverage samples, shading once per pixel, as games with multisampling draw them).
`--crf 18,23`: also each 1-spp view through H.264 (view_WIDTH_crfN), as rendered video reaches the filter.
`--exposures 0.5,0.3`: also each 1-spp view and its truth with the linear light times these factors (view_WIDTH_expF:
a dim render -- dusk, an interior -- as the renderer would encode it). `--tonemaps aces,reinhard`: also each view
rendered with its highlights kept (over 1) and a game's tone curve applied to every sample, the 1-spp input's and
each of the truth's 8x8 before their mean (view_WIDTH_tmNAME: a game's frame, as a renderer with supersampling
would resolve it).
Needs what the rendered scenes need (EGL; `pip install 'mlaa-stream[bench]'`; `'mlaa-stream[flip]'` for FLIP).
A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse
import math
from typing import Iterator

import numpy as np

from mlaa_stream.bench.accuracy import METHODS, new_shot
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.photo_textures import TEXTURE_SETS
from mlaa_stream.yardstick.rendered import Camera, Renderer, _context, _yawed, egl_available
from mlaa_stream.yardstick.scenes import Scene, edge_mask, encode8

# name -> (eye, target, vertical field of view in degrees): views the bench's shots (rendered.shot) do not use
VIEWS: dict[str, tuple[tuple, tuple, float]] = {
    "low_arches": ((-4.0, 0.5, -2.0), (2.0, 4.0, -10.0), 60.0),  # up at the colonnade from the stairs' side
    "high_down": ((-2.0, 6.0, 10.0), (0.0, 0.0, -10.0), 55.0),  # over the whole arcade, looking down
    "side_road": ((8.0, 2.5, -5.0), (0.0, 1.5, -15.0), 45.0),  # across the spheres to the fence and cables
    "far_tele": ((3.0, 1.2, -30.0), (-5.0, 3.0, -60.0), 25.0),  # long lens towards the pylons
}
# the second world (yardstick/town.py): nothing of the filter was measured or fitted on it
TOWN_VIEWS: dict[str, tuple[tuple, tuple, float]] = {
    "street_down": ((0.3, 1.7, 6.0), (0.0, 3.2, -60.0), 55.0),  # down the street: facades, wires, bollards
    "facade_oblique": ((-3.0, 1.6, -12.0), (9.0, 5.0, -38.0), 50.0),  # along the right facades: windows, balconies
    "balcony_high": ((-5.0, 9.5, -20.0), (6.0, 3.0, -42.0), 50.0),  # from a balcony: roofs, lamps, the fountain
    "bikes_close": ((1.5, 1.3, -3.0), (4.7, 0.5, -9.0), 40.0),  # bicycles with sub-pixel spokes, cobbles
    "tele_wires": ((0.5, 2.0, 0.0), (1.0, 7.5, -140.0), 18.0),  # long lens: tram wires, lamps, the tower
}
WORLD_VIEWS = {"plaza": VIEWS, "town": TOWN_VIEWS}


def aces_filmic(x: np.ndarray) -> np.ndarray:
    """Narkowicz's fit of the ACES filmic reference curve (linear scene light -> linear display light, 0..1)."""
    return np.clip(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0)


def reinhard(x: np.ndarray) -> np.ndarray:
    """Reinhard's curve x / (1 + x) after an exposure of 1.5 (scene white 1 -> 0.6 of display white)."""
    return 1.5 * x / (1.0 + 1.5 * x)


# --tonemaps: tone curves a game applies to its HDR light before display, per sample
TONEMAPS = {"aces": aces_filmic, "reinhard": reinhard}


def render_args(sizes: str, worlds: str) -> tuple[list[tuple[int, int]], list[str]]:
    """A render benchmark's --sizes ('WxH,WxH') and --world ('plaza,town') parsed, after checking that EGL is there
    (SystemExit naming what is wrong)."""
    ok, why = egl_available()
    if not ok:
        raise SystemExit(f"needs a headless OpenGL (EGL) context for the renders ({why}); see README")
    names = [w for w in worlds.split(",") if w]
    unknown = [w for w in names if w not in WORLD_VIEWS]
    if unknown:
        raise SystemExit(f"--world: expected names from {', '.join(WORLD_VIEWS)}, got {', '.join(unknown)}")
    return [tuple(int(v) for v in s.split("x")) for s in sizes.split(",") if s], names


def held_out_views(sizes: list[tuple[int, int]], worlds: list[str],
                   **renderer_options) -> Iterator[tuple[str, str, int, Renderer, Camera]]:
    """Every held-out view of each world at each size, as (world, view name, width, renderer, camera): the
    renderer (Renderer(..., **renderer_options): hdr, sky_gain) is made per size and world and released after its
    views."""
    for width, height in sizes:
        for world in worlds:
            renderer = Renderer(_context(), width, height, world, **renderer_options)
            try:
                for name, view in WORLD_VIEWS[world].items():
                    yield world, name, width, renderer, Camera(*view)
            finally:
                renderer.release()


def render_views(sizes: list[tuple[int, int]], samples: tuple[int, ...] = (1,), world: str = "plaza",
                 textures: str = "procedural", texture_repeat: float = 1.0, msaa: tuple[int, ...] = (),
                 exposures: tuple[float, ...] = (), tonemaps: tuple[str, ...] = ()
                 ) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """{view_WIDTH: (input, truth)} for every view of `world` (its surfaces textured by the set `textures`, repeated
    `texture_repeat` times as often) at every size; for every n > 1 of `samples` also {view_WIDTH_NxN: (input
    supersampled with n x n samples per pixel, truth)}; for every n of `msaa` {view_WIDTH_msaaN: (input drawn with
    n-sample MSAA, truth)}; for every factor e of `exposures` {view_WIDTH_expE: (the 1-spp input, truth), both with
    their linear light times e, clipped at 1, encoded as the truth is}; for every name of `tonemaps` (TONEMAPS)
    {view_WIDTH_tmNAME: (the 1-spp light, highlights kept, through the curve; the truth's samples each through it,
    then their mean), both encoded as the truth is}."""
    frames = {}
    for width, height in sizes:
        renderer = Renderer(_context(), width, height, world, textures, texture_repeat)
        try:
            for name, (eye, target, fov) in WORLD_VIEWS[world].items():
                cam = Camera(eye, target, fov)
                truth_linear = renderer.truth_linear(cam)
                truth = encode8(truth_linear)
                for n in samples:
                    key = f"{name}_{width}" if n == 1 else f"{name}_{width}_{n}x{n}"
                    frames[key] = (renderer.input_frame(cam) if n == 1 else renderer.truth_frame(cam, n), truth)
                for n in msaa:
                    frames[f"{name}_{width}_msaa{n}"] = (renderer.msaa_frame(cam, n), truth)
                if exposures:
                    inp_linear = renderer.input_linear(cam)
                    for e in exposures:
                        frames[f"{name}_{width}_exp{e:g}"] = tuple(encode8(np.clip(a * e, 0.0, 1.0))
                                                                   for a in (inp_linear, truth_linear))
        finally:
            renderer.release()
        if tonemaps:
            frames.update(_tonemapped_views(width, height, world, textures, texture_repeat, tonemaps))
    return frames


def _tonemapped_views(width: int, height: int, world: str, textures: str, texture_repeat: float,
                      tonemaps: tuple[str, ...]) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """render_views' view_WIDTH_tmNAME frames: the world rendered with highlights kept (Renderer(hdr=True))."""
    frames = {}
    curves = [TONEMAPS[t] for t in tonemaps]
    renderer = Renderer(_context(), width, height, world, textures, texture_repeat, hdr=True)
    try:
        for name, (eye, target, fov) in WORLD_VIEWS[world].items():
            cam = Camera(eye, target, fov)
            inp_linear = renderer.input_linear(cam).astype(np.float64)
            for t, curve, truth in zip(tonemaps, curves, renderer.truth_mapped(cam, curves)):
                frames[f"{name}_{width}_tm{t}"] = (encode8(curve(inp_linear)), encode8(truth))
    finally:
        renderer.release()
    return frames


VIEW_PAN_PX = 0.45     # the held-out pans' image motion per frame at the centre (the bench's pan: 0.3)
VIEW_DOLLY_M = 0.04    # the held-out dollies' step along the view direction per frame, metres (the bench's: 0.05)


def with_grain(inp: np.ndarray, truth: np.ndarray, sigma: float, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """(input, truth) with the same seeded Gaussian grain of `sigma` levels (one value for R, G and B) added to both,
    as grain added after rendering (both 8-bit frames, rounded)."""
    n = np.random.default_rng(seed).normal(0.0, sigma, inp.shape[:2] + (1,))
    return tuple(np.clip(np.round(a + n), 0, 255).astype(np.uint8) for a in (inp, truth))


def view_cameras(width: int, height: int, frames: int = 8, world: str = "plaza") -> dict[str, list[Camera]]:
    """The held-out shots' cameras, one per frame: from every view of `world` a yaw pan of VIEW_PAN_PX px per frame
    ("<view>_pan") and a dolly of VIEW_DOLLY_M per frame ("<view>_dolly")."""
    shots = {}
    for name, (eye, target, fov) in WORLD_VIEWS[world].items():
        e, t = np.asarray(eye, float), np.asarray(target, float)
        step = VIEW_PAN_PX * 2 * math.tan(math.radians(fov) / 2) / height
        forward = (t - e) / np.linalg.norm(t - e) * VIEW_DOLLY_M
        shots[f"{name}_pan"] = [Camera(eye, _yawed(eye, target, k * step), fov) for k in range(frames)]
        shots[f"{name}_dolly"] = [Camera(tuple(e + k * forward), tuple(t + k * forward), fov) for k in range(frames)]
    return shots


def view_shots(width: int, height: int, frames: int = 8, world: str = "plaza") -> list[Scene]:
    """Animated held-out shots for the temporal stage (mlaa_stream.bench.tss_check --views): view_cameras' shots,
    input and truth as the bench's shots."""
    shots = []
    renderer = Renderer(_context(), width, height, world)
    try:
        for name, cams in view_cameras(width, height, frames, world).items():
            inputs = np.stack([renderer.input_frame(c) for c in cams])
            truths = np.stack([renderer.truth_frame(c) for c in cams])
            edges = np.stack([edge_mask(a, b) for a, b in zip(inputs, truths)])
            shots.append(Scene(name, "rendered", inputs, truths, edges))
    finally:
        renderer.release()
    return shots


def _int_list(option: str, text: str, minimum: int) -> tuple[int, ...]:
    """A comma-separated option's integers (none for ''), each at least `minimum`, or exit naming the option."""
    try:
        values = tuple(int(v) for v in text.split(",")) if text else ()
    except ValueError:
        values = (minimum - 1,)
    if values and min(values) < minimum:
        raise SystemExit(f"{option}: expected integers of {minimum} or more, comma-separated, got {text!r}")
    return values


def print_verdicts(frames: dict[str, tuple[np.ndarray, np.ndarray]], device: str | None = None) -> None:
    """Per view the fallback's frame evidence (spatial/fallback.py step_counts): ramps among strong steps, ramps
    among clean transitions, hard stair ends among strong steps, and the verdicts drawn from them."""
    from mlaa_stream.spatial.fallback import _frame_masks, _supersampled_by, one_spp_geometry, step_counts
    from mlaa_stream.spatial.filter import Filter
    from mlaa_stream.spatial.fxaa import luma_reference
    print("view".ljust(24) + "ramps %".rjust(9) + "clean ramps %".rjust(15) + "hard stair ends %".rjust(19)
          + "  verdict")
    with Filter(fallback="off", device=device) as passes_only:
        for view, (inp, _) in frames.items():
            passes = passes_only.intermediates(inp)
            _, _, _, borders, _, rgb = _frame_masks(inp, passes["out"], passes["edges"], False)
            counts = step_counts(borders, luma_reference(rgb, False))
            strong, ramps, clean, clean_ramps = (int(a.sum()) for a in counts)
            verdict = ("supersampled" if _supersampled_by(counts)
                       else "1-spp geometry" if one_spp_geometry(strong, clean, clean_ramps) else "-")
            print(view.ljust(24) + f"{100 * ramps / max(strong, 1):9.1f}{100 * clean_ramps / max(clean, 1):15.1f}"
                  f"{100 * (clean - clean_ramps) / max(strong, 1):19.1f}  {verdict}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--methods", default="none,fxaa,mlaa,mlaa:screen,mlaa:rendered")
    ap.add_argument("--sizes", default="640x360,960x540")
    ap.add_argument("--samples", default="1",
                    help="samples per pixel of the inputs, per axis, comma-separated (1: the 1-spp views)")
    ap.add_argument("--world", default="plaza", choices=sorted(WORLD_VIEWS),
                    help="plaza: the world of the bench's rendered scenes (other cameras); town: a second world "
                         "(yardstick/town.py) with its own textures, geometry and light")
    ap.add_argument("--textures", default="procedural", choices=TEXTURE_SETS,
                    help="the world's procedural textures, or photographs on its walls, roofs and floors "
                         "(yardstick/photo_textures.py: 'photo' crops of a portrait, 'relief' a hill-shaded "
                         "elevation model and a product photograph)")
    ap.add_argument("--texture-repeat", type=float, default=1.0,
                    help="with --textures photo|relief: the photographs repeat this many times as often across "
                         "their surfaces (4: finer texels, minified through the mipmaps as on far walls)")
    ap.add_argument("--msaa", default="",
                    help="also inputs drawn with MSAA, this many samples per pixel (comma-separated; as games draw "
                         "them: coverage per sample, shading once per pixel; view_WIDTH_msaaN)")
    ap.add_argument("--crf", default="",
                    help="also every 1-spp view through H.264 at these CRFs (comma-separated; libx264 through PyAV, "
                         "as mlaa_stream.bench.codec_check; view_WIDTH_crfN), scored against the clean truth")
    ap.add_argument("--grain", default="",
                    help="also every 1-spp view with film grain of these deviations in 8-bit levels (comma-separated;"
                         " seeded Gaussian, one value for R, G and B, added to input and truth alike, as grain added "
                         "after rendering; view_WIDTH_grainN)")
    ap.add_argument("--exposures", default="",
                    help="also every 1-spp view and its truth with the linear light times these factors "
                         "(comma-separated, e.g. 0.5,0.3: dim renders; view_WIDTH_expF)")
    ap.add_argument("--tonemaps", default="",
                    help="also every view rendered with its highlights kept and a tone curve applied to each "
                         f"sample (comma-separated, of {', '.join(TONEMAPS)}: a game's frame; view_WIDTH_tmNAME)")
    ap.add_argument("--verdicts", action="store_true",
                    help="also print each view's frame evidence: ramps and hard stair ends among its steps, and "
                         "whether it is judged supersampled or 1-spp geometry (docs/spatial_tuning.md)")
    ap.add_argument("--device", default=None)
    args = ap.parse_args(argv)
    ok, why = egl_available()
    if not ok:
        raise SystemExit(f"rendered views need a headless OpenGL context: {why}")
    methods = args.methods.split(",")
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise SystemExit(f"expected methods from {', '.join(METHODS)}, got {', '.join(unknown)}")
    sizes = [tuple(int(v) for v in s.split("x")) for s in args.sizes.split(",")]
    samples = _int_list("--samples", args.samples, 1)
    if not samples:
        raise SystemExit("--samples: expected positive integers, comma-separated, got ''")
    msaa, crfs = _int_list("--msaa", args.msaa, 2), _int_list("--crf", args.crf, 0)
    grains = _int_list("--grain", args.grain, 1)
    try:
        exposures = tuple(float(e) for e in args.exposures.split(",") if e)
    except ValueError:
        exposures = (0.0,)
    if any(not (0.0 < e < 100.0) for e in exposures):
        raise SystemExit(f"--exposures: expected factors over 0, comma-separated, got {args.exposures!r}")
    tonemaps = tuple(t for t in args.tonemaps.split(",") if t)
    unknown = [t for t in tonemaps if t not in TONEMAPS]
    if unknown:
        raise SystemExit(f"--tonemaps: expected names from {', '.join(TONEMAPS)}, got {', '.join(unknown)}")
    try:
        frames = render_views(sizes, samples, args.world, args.textures, args.texture_repeat, msaa, exposures,
                              tonemaps)
    except ValueError as e:
        raise SystemExit(f"--msaa: {e}") from None
    if crfs:
        from mlaa_stream.bench.codec_check import through_h264
        for view, (inp, truth) in list(frames.items()):
            if view.rsplit("_", 1)[-1].isdigit():  # a 1-spp view
                for crf in crfs:
                    frames[f"{view}_crf{crf}"] = (through_h264(np.stack([inp, inp]), crf)[0], truth)
    for view, (inp, truth) in list(frames.items()):
        if view.rsplit("_", 1)[-1].isdigit():
            for sigma in grains:
                frames[f"{view}_grain{sigma}"] = with_grain(inp, truth, sigma)
    with_flip = M.flip_available()  # an optional part ([bench])

    def group(view: str) -> str:  # the mean's row: "mean" for 1-spp views, "mean NxN" / "mean msaaN" / "mean crfN"
        last = view.rsplit("_", 1)[-1]
        return f"mean {last}" if "x" in last or last.startswith(("msaa", "crf", "grain", "exp", "tm")) else "mean"

    print("view".ljust(20) + "".join(m.rjust(24) for m in methods))
    removed = {(m, group(v)): [] for m in methods for v in frames}
    cells = {view: [] for view in frames}
    for m in methods:
        proc = METHODS[m](args.device)
        for view, (inp, truth) in frames.items():
            new_shot(proc)  # every view judged alone
            out = proc.process(inp)
            sc = M.score(out, inp, truth, edge_mask(inp, truth), with_flip=with_flip)
            removed[m, group(view)].append(sc["error_removed"])
            cells[view].append(f"{sc['error_removed'] * 100:5.1f} / {sc['damage']:.2f}"
                               + (f" / {sc['flip']:.4f}" if with_flip else ""))
    for view, row in cells.items():
        print(view.ljust(20) + "".join(c.rjust(24) for c in row))
    for g in dict.fromkeys(group(v) for v in frames):
        print(g.ljust(20) + "".join(f"{np.mean(removed[m, g]) * 100:5.1f}".rjust(24) for m in methods))
    if args.verdicts:
        print_verdicts(frames, args.device)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
