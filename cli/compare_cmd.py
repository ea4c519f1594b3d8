"""`mlaa-stream compare OUT TRUTH [--input IN]`: the benchmark's numbers for your own images.

Exit codes: 0 compared; 1 an image could not be read or sizes differ; 2 usage error.
"""
from __future__ import annotations

import math
import os

import click
import numpy as np

from mlaa_stream.cli.options import CommandError


def read_image(path: str) -> np.ndarray:
    """An image as float32 (H, W, 3), 0..1 for integer files; alpha dropped, grey repeated."""
    return read_image_encoding(path)[0]


def read_image_encoding(path: str) -> tuple[np.ndarray, bool]:
    """read_image's pixels and whether they are linear light (as mlaa_stream.io.sequence.is_linear: a colour
    space tagged linear/ACES -- not ACEScc/ACEScct --, or untagged float such as EXR)."""
    import OpenImageIO as oiio

    from mlaa_stream.io.images import cryptomatte_channels, filter_channel_indices, no_colour_reason
    from mlaa_stream.io.sequence import is_linear_colour_space

    if os.path.isdir(path):  # OpenImageIO would answer that it has no reader for the format named like the folder
        raise CommandError(f"{path}: expected an image file, got a folder (compare scores one image at a time)")
    config = oiio.ImageSpec()
    # straight alpha (PNG, TIFF) read as stored, as the filter reads and writes it: OpenImageIO would otherwise
    # premultiply the colour, and an RGBA output scored against an RGB truth would count alpha as colour error
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(path, config)
    if inp is None:
        raise CommandError(f"{path}: cannot open ({oiio.geterror()})")
    try:
        spec = inp.spec()
        format_name = inp.format_name()
        cs = spec.get_string_attribute("oiio:ColorSpace", "").lower()
        floating = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
        tagged = is_linear_colour_space(cs)
        linear = floating if tagged is None else tagged
        arr = inp.read_image(format="float")
        if arr is None:
            raise CommandError(f"{path}: cannot read pixels ({inp.geterror()})")
    finally:
        inp.close()
    arr = np.asarray(arr, np.float32)
    if arr.ndim == 2:
        arr = arr[..., None]
    # the colour channels the filter takes, by name: a multi-layer EXR's beauty, not a pass that sorts first
    names = tuple(spec.channelnames) if len(spec.channelnames) == arr.shape[2] else ("",) * arr.shape[2]
    # an EXR of depth, normals or motion vectors (the filter copies it unchanged): its channels taken by position for
    # colour gave an RMSE of a depth against colours
    why = no_colour_reason(format_name, spec, arr.shape[2]) if len(set(names)) == len(names) and "" not in names \
        else None
    if why is not None:
        raise CommandError(f"{path}: expected colour channels, got {why}")
    colour = list(filter_channel_indices(names, spec.alpha_channel, cryptomatte_channels(names, spec)))
    if not colour:
        raise CommandError(f"{path}: expected colour channels, got only cryptomatte channels")
    arr = arr[..., colour[:3]] if len(colour) >= 3 else np.repeat(arr[..., colour[:1]], 3, axis=2)
    return np.ascontiguousarray(arr), linear


def compare_numbers(out: np.ndarray, truth: np.ndarray, inp: np.ndarray | None,
                    with_flip: bool) -> dict[str, float]:
    """The numbers `compare` prints; those that need the input are NaN without it."""
    from mlaa_stream.yardstick import metrics as M

    res = {"rmse": math.sqrt(M.mse(out, truth)), "flip": M.flip(out, truth) if with_flip else math.nan}
    if inp is not None:
        edges = ~M.near_mask(inp, truth, 3.0)
        res.update(rmse_input=math.sqrt(M.mse(inp, truth)),
                   error_removed=M.error_removed(out, inp, truth),
                   edge_error_removed=M.error_removed(out, inp, truth, edges),
                   edge_pixels=float(edges.sum()),
                   damage=M.damage(out, inp, truth, edges),
                   flip_input=M.flip(inp, truth) if with_flip else math.nan)
    return res


def _f(v: float, fmt: str) -> str:
    return "n/a" if v is None or math.isnan(v) else format(v, fmt)


@click.command("compare", epilog="Exit codes: 0 compared; 1 an image could not be read or sizes differ; 2 usage error.")
@click.argument("out_path", metavar="OUT")
@click.argument("truth_path", metavar="TRUTH")
@click.option("--input", "input_path", default=None, metavar="IN",
              help="The aliased input, for error removed, edge error removed and damage.")
@click.option("--flip/--no-flip", default=True, show_default=True,
              help="Also score NVIDIA FLIP (needs 'pip install flip-evaluator'; centre crop <= 256x256).")
def compare_command(out_path, truth_path, input_path, flip) -> None:
    """Score a filtered image OUT against a reference TRUTH (and the input IN).

    A linear-light image (EXR, untagged float) among display-encoded ones is compared sRGB-encoded. Pixels
    with NaN or infinite samples are left out of the scores (a note says how many).
    """
    from mlaa_stream.yardstick import metrics as M

    images = [read_image_encoding(p) if p else (None, False) for p in (out_path, truth_path, input_path)]
    named = [(p, img, lin) for p, (img, lin) in zip((out_path, truth_path, input_path), images) if p]
    if len({lin for _, _, lin in named}) > 1:
        # linear light (EXR) against display values (PNG): the same picture scores tens of levels apart; compare
        # both as display values, as the filter writes linear light to PNG (clipped to 0-1, sRGB-encoded)
        from mlaa_stream.device.colour import linear_to_srgb
        images = [(None if img is None else linear_to_srgb(img).astype(np.float32) if lin else img, lin)
                  for img, lin in images]
        click.echo("mlaa-stream: note: " + ", ".join(p for p, _, lin in named if lin)
                   + ": linear light, compared sRGB-encoded (clipped to 0-1) against display-encoded images",
                   err=True)
    out, truth, inp = (img for img, _ in images)
    for name, img in ((out_path, out), (input_path, inp)):
        if img is not None and img.shape != truth.shape:
            raise CommandError(f"{name}: expected {truth.shape[1]}x{truth.shape[0]} like "
                                       f"{truth_path}, got {img.shape[1]}x{img.shape[0]}")
    # NaN / infinite samples (a render's, which the filter passes through unchanged) made every score n/a (or inf)
    # without a word: their pixels are left out of the scores, said with how many
    present = [(p, img) for p, img in ((out_path, out), (truth_path, truth), (input_path, inp)) if img is not None]
    bad = np.zeros(truth.shape[:2], bool)
    holders = []
    for p, img in present:
        nonfinite = ~np.isfinite(img).all(axis=2)
        if nonfinite.any():
            bad |= nonfinite
            holders.append(p)
    if bad.any():
        for _, img in present:
            img[bad] = 0.0   # the same value in every image: no error there, in no score
        click.echo(f"mlaa-stream: note: {int(bad.sum())} pixels with NaN or infinite samples (in "
                   f"{', '.join(holders)}) left out of the scores", err=True)
    with_flip = flip and M.flip_available()
    r = compare_numbers(out, truth, inp, with_flip)
    click.echo(f"RMSE vs truth (8-bit levels): out {_f(r['rmse'], '.3f')}"
               + (f", input {_f(r['rmse_input'], '.3f')}" if inp is not None else ""))
    if inp is not None:
        click.echo(f"error removed:      {_f(100 * r['error_removed'], '.1f')} %")
        click.echo(f"edge error removed: {_f(100 * r['edge_error_removed'], '.1f')} % "
                   f"({int(r['edge_pixels'])} edge pixels)")
        click.echo(f"damage away from edges (RMSE, levels): {_f(r['damage'], '.3f')}")
    if with_flip:
        click.echo(f"FLIP: out {_f(r['flip'], '.4f')}"
                   + (f", input {_f(r['flip_input'], '.4f')}" if inp is not None else ""))
    elif flip:
        click.echo("FLIP: n/a (pip install flip-evaluator)")
