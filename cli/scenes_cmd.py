"""`mlaa-stream scenes OUT_DIR`: write the benchmark scenes as PNG (input, truth, masks) + index.

Exit codes: 0 written; 1 a file could not be written; 2 usage error (also: files exist and
--overwrite was not given).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import click

from mlaa_stream.cli.options import CommandError, comma_names, require_bench_extras
from mlaa_stream.yardstick.scenes import SCENES  # the groups for --help (this module needs numpy only)
import numpy as np


def write_png(path: Path, img: np.ndarray) -> None:
    """Write an 8-bit image with OpenImageIO; raises OSError naming the file."""
    import OpenImageIO as oiio

    a = np.ascontiguousarray(img)
    if a.ndim == 2:
        a = a[..., None]
    spec = oiio.ImageSpec(a.shape[1], a.shape[0], a.shape[2], oiio.UINT8)
    out = oiio.ImageOutput.create(str(path))
    if out is None or not out.open(str(path), spec):
        # OpenImageIO says nothing for a folder in the way ("cannot write ()")
        why = (out.geterror() if out is not None else "") or oiio.geterror() or \
            ("a folder is in the way" if os.path.isdir(path) else "cannot create the file")
        raise OSError(f"{path}: cannot write ({why})")
    try:
        if not out.write_image(a):
            raise OSError(f"{path}: cannot write ({out.geterror()})")
    finally:
        out.close()


def scene_files(scene) -> dict[str, np.ndarray]:
    """File name -> image for every frame of a scene."""
    files = {}
    for t in range(scene.frames):
        stem = f"{scene.name}_{t:02d}"
        files[f"{stem}_input.png"] = scene.inputs[t]
        files[f"{stem}_truth.png"] = scene.truths[t]
        files[f"{stem}_edges.png"] = scene.edges[t].astype(np.uint8) * 255
        if scene.wires is not None:
            files[f"{stem}_wires.png"] = scene.wires[t].astype(np.uint8) * 255
        if scene.sharp is not None:
            files[f"{stem}_sharp.png"] = scene.sharp[t].astype(np.uint8) * 255
    return files


@click.command("scenes", epilog="Exit codes: 0 written; 1 a file could not be written; "
               "2 usage error (also: files exist and "
               "--overwrite was not given).")
@click.argument("out_dir", type=click.Path(file_okay=False))
@click.option("--small", is_flag=True, help="The small variants used by the tests and bench --quick.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Random seed (same seed, same pixels).")
@click.option("--only", default=None, metavar="A,B",
              help=f"Comma-separated scene groups (default: all): {', '.join(SCENES)}.")
@click.option("--overwrite", is_flag=True, help="Replace files that already exist.")
def scenes_command(out_dir, small, seed, only, overwrite) -> None:
    """Render the test scenes (1-spp input and 8x8-spp truth) into OUT_DIR as PNG files."""
    require_bench_extras()
    from mlaa_stream.yardstick.scenes import SceneUnavailable, generate_scenes

    names = comma_names("--only", only)
    try:
        scenes = generate_scenes(small=small, seed=seed, names=names,
                                 warn=lambda msg: click.echo(f"mlaa-stream: warning: {msg}", err=True))
    except ValueError as exc:
        raise click.UsageError(str(exc)) from exc
    except SceneUnavailable as exc:
        raise CommandError(str(exc)) from exc
    out = Path(out_dir)
    plan = {name: img for s in scenes for name, img in scene_files(s).items()}
    plan_names = [*plan, "scenes.json"]
    existing = [n for n in plan_names if (out / n).exists()]
    if existing and not overwrite:
        raise click.UsageError(f"{out / existing[0]} exists ({len(existing)} files would be replaced); "
                               "pass --overwrite to replace them")
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:  # a file in the way, a folder that cannot be made: said, not a traceback
        click.echo(f"mlaa-stream: error: {out}: cannot create the folder ({exc.strerror})", err=True)
        raise SystemExit(1) from exc
    try:
        for name, img in plan.items():
            write_png(out / name, img)
    except OSError as exc:
        click.echo(f"mlaa-stream: {exc}", err=True)
        raise SystemExit(1) from exc
    index = [{"name": s.name, "category": s.category, "width": s.size[0], "height": s.size[1],
              "frames": s.frames, "notes": s.notes, "edge_pixels": int(s.edges.sum()),
              "wire_pixels": None if s.wires is None else int(s.wires.sum())} for s in scenes]
    try:
        (out / "scenes.json").write_text(json.dumps({"seed": seed, "small": small, "scenes": index}, indent=1))
    except OSError as exc:  # a folder in the way, a full disk: said, exit 1, not a traceback
        click.echo(f"mlaa-stream: {out / 'scenes.json'}: cannot write ({exc.strerror or exc})", err=True)
        raise SystemExit(1) from exc
    click.echo(f"wrote {len(plan)} images of {len(scenes)} scenes to {out}", err=True)
