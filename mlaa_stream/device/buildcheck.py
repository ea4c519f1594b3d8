"""Kernel builds that may end the process, tried in a child process first.

Some OpenCL drivers do not return an error when their compiler fails late: Mesa's rusticl ends the whole
process (exit status 8) when its LLVM-to-SPIR-V step rejects an intrinsic. On such devices every program
is first built in a child process; a failure there becomes a KernelBuildError naming the file, the
defines and the log, and a success is remembered on disk (per driver, device, source and options), so
each program is tried once per machine. PoCL reports every failure as an error: it is built directly.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

# Platforms whose failed builds come back as errors (measured: PoCL 3.x/6.x CPU devices).
BUILDS_SAFELY = ("portable computing language",)

_CHILD = r"""
import sys
import pyopencl as cl
platform, device, options = sys.argv[1], sys.argv[2], sys.argv[3:]
src = sys.stdin.read()
dev = [d for p in cl.get_platforms() if p.name == platform for d in p.get_devices() if d.name == device][0]
try:
    cl.Program(cl.Context([dev]), src).build(options=options)
except cl.Error as exc:
    sys.stderr.write(str(exc))
    sys.exit(1)
"""


def needs_child_build(device) -> bool:
    """True for devices whose compiler may end the process instead of reporting an error."""
    return not any(name in device.platform.name.lower() for name in BUILDS_SAFELY)


def _cache_dir() -> Path:
    root = os.environ.get("MLAA_STREAM_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "mlaa-stream")
    return Path(root) / "buildcheck"


def _key(device, src: str, options: list[str]) -> str:
    text = "\0".join([device.platform.name, device.platform.version, device.name, device.driver_version,
                      *options, src])
    return hashlib.sha256(text.encode()).hexdigest()


def check_build_in_child(device, src: str, options: list[str]) -> str | None:
    """Build `src` for `device` in a child process (once; remembered on disk). None when it builds;
    otherwise what went wrong, with the compiler's log or how the child ended."""
    marker = _cache_dir() / _key(device, src, options)
    if marker.exists():
        return None
    r = subprocess.run([sys.executable, "-c", _CHILD, device.platform.name, device.name, *options],
                       input=src, capture_output=True, text=True)
    if r.returncode == 0:
        try:
            marker.parent.mkdir(parents=True, exist_ok=True)
            marker.write_text("built\n")
        except OSError:
            pass  # a read-only home: tried again next time, nothing worse
        return None
    log = (r.stderr or r.stdout).strip()[-4000:]
    if r.returncode == 1:
        return log
    how = f"signal {-r.returncode}" if r.returncode < 0 else f"exit status {r.returncode}"
    return f"the driver's compiler ended the build process ({how}):\n{log}"
