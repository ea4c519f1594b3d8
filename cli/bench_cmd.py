"""`mlaa-stream bench`: every method and preset over the scenes; writes a results folder (--out).

Exit codes: 0 done (methods that failed are listed in the outputs); 1 every method failed;
2 usage error; 3 no OpenCL device.
"""
from __future__ import annotations

import os
import shlex
import sys
import tempfile

import click

from mlaa_stream.device.context import DeviceError
from mlaa_stream.cli.options import comma_names, device_option, require_bench_extras


@click.command("bench", epilog="Exit codes: 0 done (methods that failed are listed in the outputs); "
               "1 every method failed; "
               "2 usage error; 3 no OpenCL device.")
@click.option("--quick", is_flag=True, help="CI-sized: small scenes, 5 timed frames, no FLIP (< 1 minute).")
@click.option("--out", "out_dir", default=None, type=click.Path(file_okay=False),
              help="Folder for results.csv, README.md and speed_vs_accuracy.png (replaced on each run); "
                   "default: mlaa-stream-bench in the temporary folder. The project's figures: --out docs/bench.")
@click.option("--methods", default=None, metavar="A,B",
              help="Comma-separated subset of methods (default: all; see --list).")
@click.option("--frames", type=click.IntRange(1, 10000), default=None,
              help="Timed 1080p frames per method (default 20, quick 5).")
@click.option("--flip/--no-flip", default=None, help="Score FLIP (default: on for full runs when installed).")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Scene seed.")
@click.option("--scenes", "scene_names", default=None, metavar="A,B",
              help="Comma-separated scene groups (default: all; see 'mlaa-stream scenes --help').")
@click.option("--list", "list_methods", is_flag=True, help="List the methods and exit.")
@device_option
def bench_command(quick, out_dir, methods, frames, flip, seed, scene_names, list_methods, device) -> None:
    """Measure speed against accuracy for every method on the generated scenes."""
    require_bench_extras()
    from mlaa_stream.bench import accuracy as B

    if list_methods:
        for name in [*B.METHODS, B.TRUTH]:
            click.echo(name)
        return
    if out_dir is None:
        out_dir = os.path.join(tempfile.gettempdir(), "mlaa-stream-bench")
    names, groups = comma_names("--methods", methods), comma_names("--scenes", scene_names)
    try:  # now, not after the whole run: bench.write_outputs made it only once every method had been measured
        os.makedirs(out_dir, exist_ok=True)
    except OSError as exc:
        raise click.BadParameter(f"{out_dir}: cannot create the folder ({exc.strerror})", param_hint="--out") from exc
    for name in B.OUTPUT_NAMES:  # now, not as a traceback once every method has been measured
        if os.path.isdir(os.path.join(out_dir, name)):
            raise click.BadParameter(f"{os.path.join(out_dir, name)}: a folder is in the way of the results",
                                     param_hint="--out")
    command = "mlaa-stream " + " ".join(shlex.quote(a) for a in ["bench", *sys.argv[2:]]) \
        if len(sys.argv) > 1 and sys.argv[1] == "bench" else "mlaa-stream bench" + (" --quick" if quick else "")
    try:
        res = B.bench(out_dir, quick=quick, device=device, method_names=names, frames=frames, flip=flip,
                      seed=seed, scene_names=groups, log=lambda m: click.echo(m, err=True), command=command)
    except DeviceError as exc:
        click.echo(f"mlaa-stream: {exc}", err=True)
        sys.exit(3)
    except OSError as exc:  # writing the results (a full disk): said, not a traceback
        click.echo(f"mlaa-stream: error: {exc.filename or out_dir}: cannot write the results "
                   f"({exc.strerror or exc})", err=True)
        sys.exit(1)
    except ValueError as exc:
        raise click.UsageError(str(exc)) from exc
    click.echo(f"mlaa-stream: results in {out_dir}", err=True)
    summ = B.summary(res)
    click.echo(f"device: {res.device}")
    click.echo(f"{'method':<18}{'ms/1080p':>10}{'err removed':>13}{'edge err':>10}{'damage':>8}"
               f"{'wires':>8}{'temporal':>10}{'flicker':>9}")
    for m, v in summ.items():
        click.echo(f"{m:<18}{B._num(v['ms'], 1):>10}{B._pct(v['error_removed']):>13}"
                   f"{B._pct(v['edge_error_removed']):>10}{B._num(v['damage']):>8}"
                   f"{B._pct(v['broken_wires']):>8}{B._num(v['temporal_error']):>10}{B._num(v['flicker']):>9}")
    for m, e in res.failures.items():
        click.echo(f"{m}: FAILED {e}", err=True)
    click.echo(f"wrote {out_dir}/results.csv, README.md, speed_vs_accuracy.png", err=True)
    if res.failures and len(res.failures) == len([m for m in res.methods if m != B.TRUTH]):
        sys.exit(1)
