"""Linear-light renders at any exposure: `python -m mlaa_stream.bench.exposure [--sizes 960x540] [--sky 1,4]
[--exposures 0.0625,0.25,1,4,16] [--world plaza,town]`.

A render pipeline hands the filter scene-referred EXRs: linear light, highlights over 1, an exposure of the
renderer's choosing. Every held-out view (bench/rendered_views.py) of each world is rendered so -- 1 spp at pixel
centres in linear float, specular highlights unclamped, the sky's radiance times each `--sky` gain; truth the 8x8
jittered mean -- and multiplied by each exposure. The filter (default preset, linear_input=True) runs with and
without `auto_exposure` (spatial/exposure.py); each output is divided by its exposure and scored against the truth
as a viewer sees both: clipped to display white and sRGB-encoded (error removed % / damage away from edges, levels).
A filter whose work does not depend on the exposure prints one figure per view across a row.
Needs EGL, as the rendered scenes do. A benchmark, never a unit test.
"""
from __future__ import annotations

import argparse

import numpy as np

from mlaa_stream.bench.rendered_views import held_out_views, render_args
from mlaa_stream.spatial.filter import Filter
from mlaa_stream.yardstick import metrics as M
from mlaa_stream.yardstick.scenes import encode8


def _floats(text: str) -> list[float]:
    return [float(v) for v in text.split(",") if v]


def run(sizes: list[tuple[int, int]], skies: list[float], exposures: list[float], worlds: list[str],
        device: str | None = None, log=print) -> dict[tuple, list[tuple[float, float]]]:
    """{(sky, exposure, auto_exposure): [(error removed, damage) per view]}, printing a row per view."""
    res: dict[tuple, list[tuple[float, float]]] = {}
    with Filter(device, linear_input=True, auto_exposure=False) as plain, Filter(device, linear_input=True) as auto:
        for sky in skies:
            log(f"sky x{sky:g}: error removed % / damage, auto_exposure off | on, at exposure "
                + ", ".join(f"x{e:g}" for e in exposures))
            for _world, name, width, renderer, cam in held_out_views(sizes, worlds, hdr=True, sky_gain=sky):
                lin = renderer.input_linear(cam)
                seen = encode8(np.clip(lin, 0, 1))
                truth = encode8(np.clip(renderer.truth_linear(cam), 0, 1))
                cells = []
                for e in exposures:
                    for on, filt in ((False, plain), (True, auto)):
                        filt.new_shot()  # every view and exposure judged alone
                        out = encode8(np.clip(filt.process(lin * np.float32(e)) / np.float32(e), 0, 1))
                        score = (100 * M.error_removed(out, seen, truth), M.damage(out, seen, truth))
                        res.setdefault((sky, e, on), []).append(score)
                        cells.append(score)
                row = "  ".join(f"{a[0]:5.1f} / {a[1]:.2f} | {b[0]:5.1f} / {b[1]:.2f}"
                                for a, b in zip(cells[0::2], cells[1::2]))
                log(f"  {name}_{width}: {row}")
            row = "  ".join(f"x{e:g} {np.mean([s[0] for s in res[(sky, e, False)]]):.1f} / "
                            f"{np.mean([s[1] for s in res[(sky, e, False)]]):.2f} | "
                            f"{np.mean([s[0] for s in res[(sky, e, True)]]):.1f} / "
                            f"{np.mean([s[1] for s in res[(sky, e, True)]]):.2f}" for e in exposures)
            log(f"  mean: {row}")
    return res


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m mlaa_stream.bench.exposure", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="960x540", help="frame sizes WxH, comma-separated (default 960x540)")
    ap.add_argument("--sky", default="1,4", help="the sky's radiance gains, comma-separated (default 1,4)")
    ap.add_argument("--exposures", default="0.0625,0.25,1,4,16",
                    help="exposures the linear frames are multiplied by (default 0.0625,0.25,1,4,16)")
    ap.add_argument("--world", default="plaza,town", help="worlds, comma-separated (default plaza,town)")
    ap.add_argument("--device", default=None, help="OpenCL device (as --device of mlaa-stream)")
    args = ap.parse_args(argv)
    sizes, worlds = render_args(args.sizes, args.world)
    run(sizes, _floats(args.sky), _floats(args.exposures), worlds, args.device)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
