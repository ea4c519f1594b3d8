"""Options shared by several commands, defined once."""
from __future__ import annotations

import logging
import os

import click

device_option = click.option(
    "--device", "device", default=None, metavar="N|NAME",
    help="OpenCL device: index or name part from 'mlaa-stream devices' (a part that names several devices is an "
         "error listing them: give the index), or gpu / cpu: the one of that kind the default would pick "
         "(default: $MLAA_STREAM_DEVICE, else a GPU, else the CPU).")


def verbosity_options(f):
    f = click.option("-v", "--verbose", count=True, help="More detail on stderr (repeatable).")(f)
    f = click.option("-q", "--quiet", is_flag=True, help="Only errors on stderr.")(f)
    return f


def configure_logging(verbose: int, quiet: bool) -> None:
    level = logging.ERROR if quiet else (logging.DEBUG if verbose > 1 else
                                         logging.INFO if verbose else logging.WARNING)
    logging.basicConfig(level=level, format="mlaa-stream: %(message)s")
    # Dask's scheduler and workers (--cluster) log every connection at INFO: only with -vv. Importing
    # distributed sets its loggers from Dask's config (INFO), so the level goes in there too (the
    # environment also reaches the worker processes); distributed is imported only by --cluster.
    dask_level = "debug" if verbose > 1 else "error" if quiet else "warning"
    os.environ.setdefault("DASK_LOGGING__DISTRIBUTED", dask_level)  # a user's own setting wins
    logging.getLogger("distributed").setLevel(dask_level.upper())


class CommandError(click.ClickException):
    """A failure every command reports the same way: `mlaa-stream: error: ...` on stderr, exit 1."""

    def show(self, file=None) -> None:
        click.echo(f"mlaa-stream: error: {self.format_message()}", err=True, file=file)


def require_bench_extras() -> None:
    """The yardstick and the chart need matplotlib (text outlines, the sample photograph, the chart)."""
    try:
        import matplotlib  # noqa: F401
    except ImportError as exc:
        raise CommandError("this command needs the benchmark extras: pip install 'mlaa-stream[bench]' "
                           f"({exc})") from exc


def comma_names(option: str, text: str | None) -> list[str] | None:
    """The names of a comma-separated option (--only A,B): None when not given; each name once, in the order given
    (a name repeated would run or write its scene twice). Raises click.BadParameter when it names nothing (',' or
    ''), which would otherwise run nothing and exit 0."""
    if text is None:
        return None
    names = list(dict.fromkeys(n.strip() for n in text.split(",") if n.strip()))
    if not names:
        raise click.BadParameter(f"expected comma-separated names, got {text!r}", param_hint=option)
    return names
