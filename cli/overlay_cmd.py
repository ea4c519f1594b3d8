"""`mlaa-stream overlay IN -o OUT --lines FILE`: draw GRLAA roads/routes (seed 001) on a still image.

Exit codes: 0 done; 1 the image or lines file could not be read or written; 2 usage error (nothing
done: bad option, output exists without --overwrite, output is the input); 3 no OpenCL device.
"""
from __future__ import annotations

import os
import sys

import click

from mlaa_stream.cli.options import device_option, verbosity_options

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NO_DEVICE = 0, 1, 2, 3

EPILOG = """\b
Examples:
  mlaa-stream overlay map.png -o route.png --lines route.geojson
  mlaa-stream overlay shot.exr -o shot_lanes.exr --lines lanes.json --frame 120

\b
The lines file is GeoJSON (LineString / MultiLineString features in pixel coordinates) with
properties width, color, outline, outline_width, opacity, cap; per-frame coordinates go in a
"frames" property (see docs/grlaa.md); --frame picks which frame's lines are drawn. Bit depth,
channels, alpha and metadata of the image are kept; images tagged linear (EXR) are composited as
linear light, others as sRGB-encoded. The output is written under a temporary name and renamed.

\b
Exit codes: 0 done; 1 the image or lines file could not be read or written; 2 usage error
(output exists without --overwrite, output is the input); 3 no OpenCL device.
"""


def _err(msg: str) -> None:
    click.echo(f"mlaa-stream: error: {msg}", err=True)


@click.command("overlay", epilog=EPILOG)
@click.argument("input_path", metavar="IN_IMAGE")
@click.option("-o", "--output", required=True, help="Output image (format from the extension).")
@click.option("--lines", "lines_path", required=True, metavar="FILE",
              help="Overlay file: GeoJSON/JSON lines in pixel coordinates (docs/grlaa.md).")
@click.option("--frame", default=0, show_default=True, type=click.IntRange(min=0),
              help="Frame index whose lines are drawn (files with per-frame coordinates).")
@click.option("--strength", default=1.0, show_default=True, type=click.FloatRange(min=0.05, max=8.0),
              help="Antialiasing ramp in pixels (seed 001's ANTIALIAS_STRENGTH; 1 = box-filter coverage).")
@click.option("--overwrite", is_flag=True, help="Replace the output if it exists (never the input).")
@device_option
@verbosity_options
def overlay_command(input_path: str, output: str, lines_path: str, frame: int, strength: float,
                    overwrite: bool, device: str | None, verbose: int, quiet: bool) -> None:
    """Draw antialiased polylines from a lines file onto one image."""
    sys.exit(_run(input_path, output, lines_path, frame, strength, overwrite, device, verbose, quiet))


def _run(input_path: str, output: str, lines_path: str, frame: int, strength: float,
         overwrite: bool, device: str | None, verbose: int, quiet: bool) -> int:
    for path, what in ((input_path, "IN_IMAGE"), (output, "-o"), (lines_path, "--lines")):
        if path == "-":  # else "got nothing", "cannot read (No such file)" or "no writer for this extension"
            _err(f"{what} -: standard input and output are not read or written here; give a file "
                 f"(the filter command's --overlay draws on a video through pipes)")
            return EXIT_USAGE
    if not os.path.isfile(input_path):
        got = "a folder" if os.path.isdir(input_path) else "nothing"
        _err(f"{input_path}: expected an image file, got {got}")
        return EXIT_USAGE
    if os.path.abspath(output) == os.path.abspath(input_path):
        _err(f"{output}: is the input; choose another output name")
        return EXIT_USAGE
    if os.path.isdir(output):
        _err(f"{output}: expected an image file name, got a folder")
        return EXIT_USAGE
    if os.path.exists(output) and not overwrite:
        _err(f"{output}: exists; use --overwrite to replace it")
        return EXIT_USAGE
    folder = os.path.dirname(os.path.abspath(output))
    if not os.path.isdir(folder):  # as the filter command says it (OpenImageIO's error named the temporary file)
        _err(f"{folder}: the output folder does not exist")
        return EXIT_FAILED

    from mlaa_stream.device.context import DeviceError, KernelBuildError
    from mlaa_stream.io.images import (ImageReadError, ImageWriteError, is_premultiplied, read_image,
                                       split_for_filter, unpremultiplies, write_image)
    from mlaa_stream.overlay.grlaa import OverlayRenderer, read_overlay
    from mlaa_stream.io.sequence import is_linear

    try:
        features = read_overlay(lines_path)
    except ValueError as exc:
        _err(str(exc))
        return EXIT_FAILED
    try:
        image = read_image(input_path)
    except ImageReadError as exc:
        _err(str(exc))
        return EXIT_FAILED
    lines, styles = [], []
    for f in features:
        for ln in f.lines_at(frame):
            lines.append(ln)
            styles.append(f.style)
    if not quiet and not lines:
        click.echo(f"mlaa-stream: warning: {lines_path}: no lines at frame {frame}; "
                   "the image is written unchanged", err=True)
    try:
        pixels, put_back = split_for_filter(image)   # an EXR of depth or ids only: refused, naming its channels
    except ImageReadError as exc:
        _err(str(exc))
        return EXIT_FAILED
    try:
        renderer = OverlayRenderer(device, strength, linear=is_linear(image))
        if verbose:
            click.echo(f"mlaa-stream: {len(lines)} lines on {renderer.device_name}", err=True)
        # an EXR's RGBA (a TIFF's tagged so) is premultiplied: the renderer composites over straight alpha
        out = renderer.draw_styled(pixels, lines, styles, bgr=False, what=input_path,
                                   premultiplied=is_premultiplied(image.spec))
    except DeviceError as exc:
        _err(str(exc))
        return EXIT_NO_DEVICE
    except KernelBuildError as exc:
        _err(str(exc))
        return EXIT_FAILED
    try:
        encoded = write_image(output, put_back(out), image.spec, overwrite=overwrite, linear=is_linear(image),
                              quality=image.quality)  # a JPEG source's quality kept
    except ImageWriteError as exc:
        _err(str(exc))
        return EXIT_USAGE if "exists" in str(exc) else EXIT_FAILED
    except OSError as exc:
        _err(f"{output}: {exc.strerror or exc}")
        return EXIT_FAILED
    if unpremultiplies(output, image.spec) and not quiet:  # as the filter command says
        click.echo(f"mlaa-stream: warning: {input_path}: premultiplied alpha divided out for {output}, a format of "
                   f"straight alpha (EXR and TIFF keep it premultiplied)", err=True)
    if encoded and not quiet:  # linear light in a format of display values, as the filter command says
        click.echo(f"mlaa-stream: warning: {input_path}: linear light encoded to sRGB for {output} (EXR and "
                   f"float TIFF keep it linear)", err=True)
    if verbose:
        click.echo(f"mlaa-stream: wrote {output}", err=True)
    return EXIT_OK
