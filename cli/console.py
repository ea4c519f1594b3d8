"""What `mlaa-stream` says and how it ends: messages on stderr, exit codes, the stop signals and the two
refusals (Usage: nothing done, exit 2; Failed: an input cannot be processed, exit 1)."""
from __future__ import annotations

import errno
import os
import signal
import sys
from contextlib import contextmanager
from typing import Iterator

import click

EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_NO_DEVICE, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
# The reader of standard output went away (`-o - | head`): the status a shell reports for a process SIGPIPE ended,
# as for Unix tools (Python ignores SIGPIPE, so the write fails with EPIPE instead of ending the process)
EXIT_BROKEN_PIPE = 128 + getattr(signal, "SIGPIPE", 13)


class Console:
    """Messages on stderr, prefixed; warnings and details follow -q / -v."""

    def __init__(self, verbose: int, quiet: bool):
        self.verbose, self.quiet = verbose, quiet

    def error(self, msg: str) -> None:
        click.echo(f"mlaa-stream: error: {msg}", err=True)

    def warn(self, msg: str) -> None:
        if not self.quiet:
            click.echo(f"mlaa-stream: warning: {msg}", err=True)

    def info(self, msg: str) -> None:
        if self.verbose and not self.quiet:
            click.echo(f"mlaa-stream: {msg}", err=True)

    def note(self, msg: str) -> None:
        """Something done to the input that the user should know of (not a fault): shown unless -q."""
        if not self.quiet:
            click.echo(f"mlaa-stream: {msg}", err=True)


def is_broken_pipe(exc: BaseException | None) -> bool:
    """True when `exc` is, or was caused by, a write to a pipe whose reader has gone (EPIPE): Python's
    BrokenPipeError, PyAV's (an FFmpegError that is one too), or either inside a PipelineError or VideoError."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno == errno.EPIPE:
            return True
        exc = getattr(exc, "cause", None) or exc.__cause__ or exc.__context__   # PipelineError keeps it in .cause
    return False


def stdout_gone() -> int:
    """Standard output's reader went away: nothing more can reach it, and Python's last flush of it at exit would
    print 'Exception ignored ... BrokenPipeError'; it is pointed at /dev/null instead. Returns EXIT_BROKEN_PIPE."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, sys.stdout.fileno())
        finally:
            os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no file descriptor (a test runner's stdout): nothing to flush
        pass
    return EXIT_BROKEN_PIPE


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP arrived: unwinds every stage as Ctrl-C does (outputs in progress removed)."""

    def __init__(self, signum: int):
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextmanager
def stop_signals_as_interrupts() -> Iterator[None]:
    """SIGTERM (timeout, systemd, docker, render-farm managers) and SIGHUP raise Terminated in the main
    thread for as long as the command runs; the previous handlers come back afterwards."""
    wanted = [getattr(signal, n) for n in ("SIGTERM", "SIGHUP") if hasattr(signal, n)]
    previous = {}

    def handler(signum, frame):
        raise Terminated(signum)

    try:
        for sig in wanted:
            previous[sig] = signal.signal(sig, handler)
    except ValueError:  # not the main thread (e.g. called from a worker): signals stay as they are
        pass
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)


class Usage(Exception):
    """Refused before doing anything (exit 2)."""


class Failed(Exception):
    """The input cannot be processed at all (exit 1)."""
