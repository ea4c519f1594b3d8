"""GPU OpenCL drivers that are on the machine but that the OpenCL loader cannot see.

pyopencl's loader (ocl-icd) finds drivers through ICD files: one line each, the driver library's path or name, in
`/etc/OpenCL/vendors/*.icd` or where `$OCL_ICD_VENDORS` points (a folder of them, or one file). GPU containers
often carry the vendor's library (mounted with the driver) but no ICD file for it, and the filter then runs on the
CPU without a word. Seen on an NVIDIA H200 machine: `/usr/local/nvidia/lib64/libnvidia-opencl.so` present, only
`pocl.icd` in `/etc/OpenCL/vendors` (docs/portability.md). `mlaa-stream devices` names such a library and the ICD
file that would register it.
"""
from __future__ import annotations

import glob
import os
import sys
from dataclasses import dataclass

# Vendor OpenCL drivers for GPUs: (vendor, library file name as the ICD file names it, ICD file name).
GPU_DRIVERS = (("NVIDIA", "libnvidia-opencl.so.1", "nvidia.icd"),
               ("AMD ROCm", "libamdocl64.so", "amdocl64.icd"),
               ("Intel", "libigdrcl.so", "intel.icd"))
# Where such libraries are installed or mounted (besides $LD_LIBRARY_PATH's folders).
LIBRARY_DIRS = ("/usr/lib/x86_64-linux-gnu", "/usr/lib/aarch64-linux-gnu", "/usr/lib64", "/usr/lib",
                "/usr/local/lib", "/usr/local/nvidia/lib64", "/usr/local/nvidia/lib", "/opt/rocm/lib",
                "/opt/rocm/opencl/lib")
VENDORS_DIR = "/etc/OpenCL/vendors"
VENDORS_ENV = "OCL_ICD_VENDORS"


@dataclass(frozen=True)
class UnregisteredDriver:
    vendor: str
    library: str     # its path on this machine
    icd_name: str    # the ICD file that would register it

    def hint(self) -> str:
        return (f"{self.vendor}'s OpenCL driver is at {self.library} but no ICD file names it, so OpenCL cannot "
                f"see the GPU: register it with 'echo {self.library} > {VENDORS_DIR}/{self.icd_name}' (or put "
                f"that file in a folder of your own and set ${VENDORS_ENV} to the folder)")


def registered_libraries(environ: dict[str, str] | None = None) -> set[str]:
    """The file names of the libraries that the loader's ICD files name."""
    env = os.environ if environ is None else environ
    where = env.get(VENDORS_ENV) or VENDORS_DIR
    files = [where] if os.path.isfile(where) else sorted(glob.glob(os.path.join(where, "*.icd")))
    names = set()
    for path in files:
        try:
            with open(path, encoding="utf-8", errors="replace") as f:
                names.update(os.path.basename(line.strip()) for line in f if line.strip())
        except OSError:
            continue
    return names


def unregistered_gpu_drivers(library_dirs: tuple[str, ...] | None = None,
                             environ: dict[str, str] | None = None) -> list[UnregisteredDriver]:
    """GPU vendors' OpenCL libraries present in `library_dirs` (default LIBRARY_DIRS) and $LD_LIBRARY_PATH's
    folders that no ICD file names."""
    env = os.environ if environ is None else environ
    dirs = [d for d in env.get("LD_LIBRARY_PATH", "").split(os.pathsep) if d] + list(
        LIBRARY_DIRS if library_dirs is None else library_dirs)
    known = registered_libraries(env)
    found = []
    for vendor, lib, icd in GPU_DRIVERS:
        stem = lib.split(".so")[0] + ".so"
        if any(name.startswith(stem) for name in known):
            continue
        for d in dict.fromkeys(dirs):
            hits = sorted(glob.glob(os.path.join(d, stem + "*")))
            if hits:
                exact = os.path.join(d, lib)
                found.append(UnregisteredDriver(vendor, exact if exact in hits else hits[0], icd))
                break
    return found


def unregistered_pip_runtimes(prefix: str | None = None, environ: dict[str, str] | None = None) -> list[str]:
    """How to register a CPU runtime that pip installed into this environment but could not give an ICD file:
    Intel's (PyPI `intel-opencl-rt` with `intel-cmplr-lib-rt`, a proprietary licence), which builds where PyPI's PoCL
    cannot (docs/portability.md, "Default device"). Empty where there is none or an ICD file names it."""
    prefix = sys.prefix if prefix is None else prefix
    lib = os.path.join(prefix, "lib", "libintelocl.so")
    if not os.path.exists(lib) or os.path.basename(lib) in registered_libraries(environ):
        return []
    return [f"Intel's CPU OpenCL runtime is installed here ({lib}) but no ICD file names it: register it with "
            f"'echo {lib} > {VENDORS_DIR}/intel-cpu.icd' (or in a folder of your own that ${VENDORS_ENV} names) and "
            f"run with LD_LIBRARY_PATH={os.path.dirname(lib)}"]
