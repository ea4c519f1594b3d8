"""OpenCL device selection and a program cache: one build per (device, source, defines)."""
from __future__ import annotations

import os
import re
import threading
import warnings
from dataclasses import dataclass
from importlib import resources

import numpy as np

from mlaa_stream.device.buildcheck import check_build_in_child, needs_child_build

try:  # pyopencl is a hard dependency, but say how to fix a broken install in one sentence.
    import pyopencl as cl
except ImportError as exc:  # pragma: no cover - only on broken installs
    cl = None
    _IMPORT_ERROR: Exception | None = exc
else:
    _IMPORT_ERROR = None

DEVICE_ENV = "MLAA_STREAM_DEVICE"
# Extra OpenCL build options for debugging tools, e.g. "-cl-opt-disable" under Oclgrind (docs/portability.md).
CL_OPTIONS_ENV = "MLAA_STREAM_CL_OPTIONS"


def pin_pocl_workers(environ=os.environ) -> bool:
    """Ask PoCL's CPU driver to pin its worker thread i to CPU i (POCL_AFFINITY=1), unless the
    user set POCL_AFFINITY or this process may not run on every CPU (taskset, cpusets: pinning
    would leave the set, or fail). PoCL reads it when the platform is first queried, so this runs
    at import, before any query. True if it was set here.

    Why: when the host thread has been busy between kernels (a capture loop decoding a frame,
    cv2 drawing), the Linux scheduler wakes both unpinned workers on the one idle core, and a
    short kernel then runs on one core for its whole length. Measured here (2 cores,
    docs/grlaa_bench.md): a 2.4 ms overlay draw took 4.5 ms in 2 of 3 frames after 2 ms of host
    work, and 2.6 ms pinned; pipeline_bench 1080p end to end 1-3 % faster pinned."""
    if "POCL_AFFINITY" in environ or not hasattr(os, "sched_getaffinity"):
        return False
    try:
        allowed = os.sched_getaffinity(0)
    except OSError:
        return False
    if allowed != set(range(os.cpu_count() or 0)):
        return False
    environ["POCL_AFFINITY"] = "1"
    return True


pin_pocl_workers()

NO_PLATFORM_HINT = (
    "no OpenCL platform found: install the CPU runtime with "
    "'pip install pocl-binary-distribution' (or a GPU vendor's OpenCL driver)"
)
# The OpenCL loader (ocl-icd) looks for drivers only where this names when it is set, not in /etc/OpenCL/vendors:
# set wrong (OCL_ICD_VENDORS=/nonexistent) it lists no platform at all, with every runtime installed.
LOADER_VENDORS_ENV = "OCL_ICD_VENDORS"


def no_platform_message(environ=os.environ) -> str:
    """NO_PLATFORM_HINT, or where $OCL_ICD_VENDORS is set, that first: then the likelier cause."""
    where = environ.get(LOADER_VENDORS_ENV)
    if where is None:
        return NO_PLATFORM_HINT
    return (f"no OpenCL platform found where {LOADER_VENDORS_ENV}={where!r} points (the OpenCL loader then looks "
            f"for drivers only there): unset it to use those registered in /etc/OpenCL/vendors, or "
            + NO_PLATFORM_HINT.split(": ", 1)[1])


class DeviceError(RuntimeError):
    """No usable OpenCL device, or the one asked for does not exist."""


class KernelBuildError(RuntimeError):
    """An OpenCL program failed to build; names the file, the defines and the compiler log."""


@dataclass(frozen=True)
class DeviceInfo:
    index: int
    platform: str
    name: str
    kind: str  # "GPU", "CPU", "ACCELERATOR", ...
    compute_units: int
    global_mem_mb: int

    def label(self) -> str:
        return f"{self.name} ({self.kind}, {self.platform})"


def _kind(dev) -> str:
    t = dev.type
    if t & cl.device_type.GPU:
        return "GPU"
    if t & cl.device_type.CPU:
        return "CPU"
    if t & cl.device_type.ACCELERATOR:
        return "ACCELERATOR"
    return "OTHER"


def _all_devices() -> list:
    if cl is None:
        raise DeviceError(f"pyopencl cannot be imported ({_IMPORT_ERROR}); {NO_PLATFORM_HINT}")
    try:
        platforms = cl.get_platforms()
    except cl.Error as exc:  # PLATFORM_NOT_FOUND_KHR and friends
        raise DeviceError(no_platform_message()) from exc
    devices = []
    for p in platforms:
        try:
            devices.extend(p.get_devices())
        except cl.Error:  # a platform with no devices: skip it, others may serve
            continue
    if not devices:
        raise DeviceError(no_platform_message())
    return devices


def list_devices() -> list[DeviceInfo]:
    """All OpenCL devices, in the order `--device N` numbers them."""
    return [
        DeviceInfo(i, d.platform.name.strip(), d.name.strip(), _kind(d), d.max_compute_units,
                   d.global_mem_size // (1 << 20))
        for i, d in enumerate(_all_devices())
    ]


# Devices that report themselves as GPUs but are not hardware (debugging tools): never the default.
SIMULATORS = ("oclgrind",)
# CPU runtimes in order of preference when there is no GPU: PoCL is the one the kernels are tuned for
# (their inline loads, builtins and work-group shapes were measured on it); others after it, in listing order.
CPU_PREFERENCE = ("portable computing language",)
# A CPU runtime compiles for the CPU it runs on and its LLVM must know that CPU: PoCL from PyPI (PoCL 3.0, LLVM 14)
# fails every build on CPUs newer than LLVM 14 ("unknown target CPU 'generic'", measured on an AMD EPYC of family
# 26, Zen 5). Before a device is picked by default (a GPU too: a driver can be installed and broken) it builds this
# one-line kernel.
PROBE_SOURCE = "__kernel void probe(__global int *p) { p[get_global_id(0)] += 1; }"
NO_CPU_COMPILER_HINT = (
    "install your distribution's PoCL, whose LLVM is newer (Debian/Ubuntu: 'apt-get install pocl-opencl-icd'; "
    "Fedora: 'dnf install pocl'), or Mesa's rusticl ('apt-get install mesa-opencl-icd', then "
    "RUSTICL_ENABLE=llvmpipe), or with pip alone Intel's CPU runtime ('pip install intel-opencl-rt "
    "intel-cmplr-lib-rt', a proprietary licence; `mlaa-stream devices` then says how to register it): mlaa-stream "
    "picks the first CPU runtime that builds (docs/portability.md)")
_probed: dict[tuple[str, str, str], str | None] = {}


def compile_problem(dev) -> str | None:
    """None when `dev`'s compiler builds PROBE_SOURCE; otherwise the compiler's complaint, in one line.
    Asked once per device and process."""
    key = (dev.platform.name, dev.platform.version, dev.name)
    if key not in _probed:
        options = ["-cl-std=CL1.2"]
        if needs_child_build(dev):  # a driver that may end the process on a failed build
            problem = check_build_in_child(dev, PROBE_SOURCE, options)
        else:
            try:
                cl.Program(cl.Context([dev]), PROBE_SOURCE).build(options=options)
                problem = None
            except cl.Error as exc:
                problem = str(exc)
        if problem is not None:  # the compiler's own line ("error: ..."), else the driver's message
            lines = [ln.strip() for ln in problem.splitlines() if ln.strip()]
            problem = next((ln for ln in lines if "error" in ln.lower() and "clBuildProgram" not in ln),
                           lines[-1] if lines else "the build failed")
        _probed[key] = problem
    return _probed[key]


def _runtime(dev) -> str:
    """The platform and its compiler, short: "Portable Computing Language: PoCL 3.0-rc2, LLVM 14.0.6"."""
    found = re.findall(r"(?:PoCL|LLVM|Mesa) [^\s,]+", getattr(dev.platform, "version", ""))
    return dev.platform.name.strip() + (": " + ", ".join(found) if found else "")


def _is_simulator(dev) -> bool:
    text = f"{dev.platform.name} {dev.name}".lower()
    return any(s in text for s in SIMULATORS)


def default_choice(devices: list, problem=compile_problem) -> tuple[object, str]:
    """The device used when none is asked for, and why: the first GPU that is not a simulator and whose compiler
    builds (`problem(device)` is None: a GPU driver that is installed but broken is passed over), else the first
    CPU runtime that builds (PoCL first), else the first device. Raises DeviceError when there are GPUs or CPU
    runtimes and none of them builds."""
    skipped: list[str] = []

    def chosen(d, why: str) -> tuple[object, str]:
        return d, why + "".join(f"; skipped {s}" for s in skipped)

    def builds(d) -> bool:
        complaint = problem(d)
        if complaint is not None:
            skipped.append(f"{d.name.strip()} ({_runtime(d)}): {complaint}")
        return complaint is None

    gpus = [d for d in devices if _kind(d) == "GPU" and not _is_simulator(d)]
    for d in gpus:
        if builds(d):
            return chosen(d, "a GPU")
    no_gpu = "no GPU that builds" if gpus else "no GPU"
    cpus = [d for d in devices if _kind(d) == "CPU"]
    preferred = [d for name in CPU_PREFERENCE for d in cpus if name in d.platform.name.lower()]
    for d in preferred + [d for d in cpus if d not in preferred]:
        if builds(d):
            return chosen(d, f"{no_gpu}; PoCL is the CPU runtime the kernels are tuned for" if d in preferred
                          else f"{no_gpu}; the first CPU runtime that builds")
    if skipped:
        raise DeviceError("no device here builds kernels (" + "; ".join(skipped) + ")"
                          + (": " + NO_CPU_COMPILER_HINT if cpus else ""))
    return devices[0], "no GPU or CPU device; the first device (a simulator or accelerator)"


def _identity(dev) -> tuple:
    """What a device says of itself and its runtime: equal for one driver registered twice (two ICD files)."""
    return (dev.platform.name, dev.platform.version, dev.name, dev.version, dev.driver_version, dev.vendor_id,
            dev.global_mem_size, dev.max_compute_units)


def same_device(a, b) -> bool:
    """True when two listed devices are one: the same OpenCL device listed twice, or one driver registered twice (its
    devices then come under two platforms that say the same of themselves). Two GPUs of one model on one platform
    are two devices, whatever their names."""
    if a.int_ptr == b.int_ptr:
        return True
    return a.platform.int_ptr != b.platform.int_ptr and _identity(a) == _identity(b)


def select_device(spec: str | int | None = None):
    """Pick a device: `spec` (index or name substring), else $MLAA_STREAM_DEVICE, else
    `default_choice` (a real GPU, else PoCL's CPU device, else the first). "gpu" / "cpu" pick the device of that
    kind that `default_choice` would pick among them. A name that matches several devices (that are not one listed
    twice, same_device) is a DeviceError listing them: the first of them is not necessarily the one meant (two GPUs
    of a kind, two CPU runtimes)."""
    devices = _all_devices()
    source = ""  # where the spec came from, in errors: a user who typed no --device must learn it was the variable
    if spec is None or str(spec).strip() == "":
        # blank (a variable set to spaces) is unset, as empty is: stripped to '', it matched every device's name
        spec = os.environ.get(DEVICE_ENV, "").strip() or None
        source = f"${DEVICE_ENV}: " if spec is not None else ""
    if spec is None:
        return default_choice(devices)[0]
    s = str(spec).strip()
    if s.isdigit():
        i = int(s)
        if i >= len(devices):
            raise DeviceError(f"{source}expected a device index below {len(devices)}, got {i} "
                              f"(see 'mlaa-stream devices')")
        return devices[i]
    of_kind = [d for d in devices if s.upper() in ("GPU", "CPU") and _kind(d) == s.upper()]
    if of_kind:   # a kind word: that kind's device the default would pick (two CPU runtimes are no error here)
        return default_choice(of_kind, problem=compile_problem)[0]
    matches = [(i, d) for i, d in enumerate(devices) if s.lower() in f"{d.platform.name} {d.name}".lower()
               or s.upper() == _kind(d)]
    if not matches:
        names = ", ".join(d.name.strip() for d in devices)
        if s.upper() in ("GPU", "CPU"):  # a kind word, not a name part: say that no device is of that kind
            raise DeviceError(f"{source}no OpenCL device is a {s.upper()} ({s!r} picks one of that kind); "
                              f"available: {names}")
        raise DeviceError(f"{source}no OpenCL device matches {s!r}; available: {names}")
    distinct = [(i, d) for k, (i, d) in enumerate(matches) if not any(same_device(d, e) for _, e in matches[:k])]
    if len(distinct) > 1:
        listed = "; ".join(f"{i}: {d.name.strip()} ({_kind(d)}, {_runtime(d)})" for i, d in distinct)
        pick = f"{DEVICE_ENV}={distinct[0][0]}" if source else f"--device {distinct[0][0]}"
        raise DeviceError(f"{source}{s!r} matches {len(distinct)} OpenCL devices ({listed}); pick one by its index, "
                          f"e.g. {pick}, or by more of its name ('mlaa-stream devices' lists them)")
    return matches[0][1]


# Programs built from more than one file, in this order (after common.cl): the long passes are split
# into readable parts; the compiler sees the same text as one file would give it.
PROGRAM_PARTS = {"bridge": ("bridge_links", "bridge"), "reconstruct": ("reconstruct_rules", "reconstruct"),
                 "fallback": ("fxaa", "noise", "fallback")}


def kernel_source(name: str) -> str:
    """The text of kernels/<name>.cl as shipped inside the package."""
    return resources.files("mlaa_stream.kernels").joinpath(f"{name}.cl").read_text()


def format_defines(defines: dict[str, object]) -> list[str]:
    """The one place where defines become compiler options."""
    opts = []
    for key in sorted(defines):
        val = defines[key]
        if isinstance(val, bool):
            val = int(val)
        if isinstance(val, float):
            val = repr(float(val)) + "f"
        opts.append(f"-D{key}={val}")
    return opts


class Context:
    """One OpenCL context + queue on one device, with programs built once per (source, defines)."""

    def __init__(self, device: str | int | None = None):
        self.device = device if (cl is not None and isinstance(device, cl.Device)) else select_device(device)
        self.ctx = cl.Context([self.device])
        self.queue = cl.CommandQueue(self.ctx)
        self._programs: dict[tuple, object] = {}
        self._kernels: dict[tuple, object] = {}
        self._lock = threading.Lock()
        self.poison: int | None = None  # a byte pattern for new buffers (see `buffer`)
        # The sweeps along columns (line distances, the fast preset's right-edge shapes): a work item per column and
        # chunk of rows on GPUs (thousands of threads, neighbours read neighbouring bytes), a work item per strip
        # of 64 columns walking every row on CPUs (a few long sequential loops; docs/portability.md, "On an NVIDIA GPU")
        self.column_sweeps = not (self.device.type & cl.device_type.CPU)

    @property
    def name(self) -> str:
        return f"{self.device.name.strip()} ({_kind(self.device)}, {self.device.platform.name.strip()})"

    def program(self, name: str, defines: dict[str, object] | None = None):
        opts = format_defines(defines or {})
        key = (name, tuple(opts))
        with self._lock:
            prg = self._programs.get(key)
            if prg is None:
                # common.cl (pixel formats, colour tables) is prepended to every kernel file.
                src = kernel_source("common") + "".join(
                    "\n#line 1\n" + kernel_source(part) for part in PROGRAM_PARTS.get(name, (name,)))
                options = ["-cl-std=CL1.2", *opts, *os.environ.get(CL_OPTIONS_ENV, "").split()]
                files = " + ".join(f"kernels/{p}.cl" for p in PROGRAM_PARTS.get(name, (name,)))
                if needs_child_build(self.device):  # a driver that may end the process on a failed build
                    problem = check_build_in_child(self.device, src, options)
                    if problem is not None:
                        raise KernelBuildError(f"{files} failed to build on {self.name} with defines "
                                               f"{' '.join(opts) or '(none)'}:\n{problem}")
                try:
                    with warnings.catch_warnings():
                        # a compiler's remarks on our tested kernels (clang 15's "logical '&&' with constant
                        # operand" where a define makes an operand constant) are nothing a user can act on;
                        # PYOPENCL_COMPILER_OUTPUT=1 shows them
                        if not os.environ.get("PYOPENCL_COMPILER_OUTPUT"):
                            warnings.simplefilter("ignore", cl.CompilerWarning)
                        prg = cl.Program(self.ctx, src).build(options=options)
                except cl.Error as exc:
                    raise KernelBuildError(
                        f"{files} failed to build on {self.name} with defines "
                        f"{' '.join(opts) or '(none)'}:\n{exc}") from exc
                self._programs[key] = prg
            return prg

    def kernel(self, name: str, function: str, defines: dict[str, object] | None = None) -> "SizedKernel":
        """A kernel object, fetched once per (file, defines, function) and reused."""
        key = (name, tuple(format_defines(defines or {})), function)
        k = self._kernels.get(key)
        if k is None:
            k = SizedKernel(cl.Kernel(self.program(name, defines), function),
                            bool(self.device.type & cl.device_type.CPU))
            self._kernels[key] = k
        return k

    def buffer(self, nbytes: int, flags=None):
        """A device buffer; filled with the byte `self.poison` when that is set (tests: no kernel may read
        a byte it did not write first, so outputs must not depend on the pattern)."""
        buf = cl.Buffer(self.ctx, flags or cl.mem_flags.READ_WRITE, size=max(int(nbytes), 1))
        if self.poison is not None:
            cl.enqueue_fill_buffer(self.queue, buf, np.uint8(self.poison), 0, buf.size).wait()
        return buf


# PoCL compiles a kernel once per work-group size; left to choose, it derives one from the global size, so
# every new frame size cost a build of seconds (a folder of mixed sizes, a resized capture window). On CPU
# devices a launch without a work-group size gets this fixed one and its global size is rounded up to a
# multiple of it (every kernel returns early past the frame's last row and column).
CPU_LOCAL = {1: (8,), 2: (1, 8), 3: (1, 1, 8)}


def launch_size(global_size: tuple[int, ...], cpu: bool) -> tuple[tuple[int, ...], tuple[int, ...] | None]:
    """(global, local) for a launch without a local size: fixed and padded on CPU devices, as given on GPUs."""
    if not cpu:
        return tuple(global_size), None
    local = CPU_LOCAL[len(global_size)]
    return tuple(-(-int(g) // l) * l for g, l in zip(global_size, local)), local


class SizedKernel:
    """A pyopencl kernel whose launches without a local size get `launch_size`'s (see CPU_LOCAL).

    One object serves every filter and stage on its context (Context.kernel), and a launch sets the kernel's
    arguments and then enqueues it: two threads launching at once (two Antialiasers, one per thread) could
    enqueue one with the other's buffers. The lock makes each launch's set-and-enqueue one step."""

    def __init__(self, kernel, cpu: bool):
        self.kernel, self.cpu = kernel, cpu
        self._lock = threading.Lock()

    def __call__(self, queue, global_size, local_size, *args, **kwargs):
        if local_size is None:
            global_size, local_size = launch_size(global_size, self.cpu)
        with self._lock:
            return self.kernel(queue, global_size, local_size, *args, **kwargs)

    def __getattr__(self, name: str):
        return getattr(self.kernel, name)


def check_pass_buffers(what: str, fmt, src, dst) -> None:
    """A src -> dst pass needs two distinct buffers, each holding at least one frame of `fmt`."""
    if src is dst or src.int_ptr == dst.int_ptr:
        raise ValueError(f"{what}: expected dst to be a different buffer from src, got the same one")
    for name, buf in (("src", src), ("dst", dst)):
        if buf.size < fmt.nbytes:
            raise ValueError(f"{what}: expected {name} of at least {fmt.nbytes} bytes for a {fmt.width}x"
                             f"{fmt.height}x{fmt.channels} frame, got {buf.size}")


def linear_levels(context: Context, program: str, defines: dict[str, object], fmt, luts) -> "cl.Buffer":
    """Integer frames: a device buffer of PIXEL_MAX + 1 floats, entry v = the linear value common.cl's
    tables give for the stored level v (its `linear_levels` kernel, run once on the device from the
    `program` built with `defines`, so the numbers are the kernels' own). Float frames: one unused float."""
    if fmt.dtype.kind == "f":
        return context.buffer(4)
    levels = int(np.iinfo(fmt.dtype).max) + 1
    lin = context.buffer(4 * levels)
    context.kernel(program, "linear_levels", defines)(context.queue, (levels,), None, luts, lin).wait()
    return lin


_contexts: dict[str, Context] = {}
_contexts_lock = threading.Lock()


def default_context(device: str | int | None = None) -> Context:
    """A process-wide context per device choice, created on first use and shared (programs too)."""
    key = "" if device is None else str(device)
    with _contexts_lock:
        ctx = _contexts.get(key)
        if ctx is None:
            ctx = _contexts[key] = Context(device)
        return ctx


def i32(v) -> np.int32:
    return np.int32(v)


def f32(v) -> np.float32:
    return np.float32(v)
