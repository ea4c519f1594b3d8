"""Device selection, the program cache and the messages users see when OpenCL is missing or broken."""
from __future__ import annotations

import os

import pyopencl as cl
import numpy as np
import pytest
from click.testing import CliRunner

from mlaa_stream.device import context as dev
from mlaa_stream.cli.main import main


def test_devices_command_lists_the_default_device():
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 0, res.output
    assert "* 0:" in res.output or "*" in res.output.splitlines()[0]


def test_environment_variable_and_option_pick_the_device(monkeypatch):
    first = dev.list_devices()[0]
    monkeypatch.setenv(dev.DEVICE_ENV, "0")
    assert dev.select_device(None).name.strip() == first.name
    # the whole name (a part of it may match several devices: an error, test_a_device_name_matching_several_...)
    if sum(first.name.lower() in f"{d.platform} {d.name}".lower() for d in dev.list_devices()) == 1:
        assert dev.select_device(first.name).name.strip() == first.name


@pytest.mark.parametrize("spec,msg", [("99", "expected a device index below"),
                                      ("no-such-device-xyz", "no OpenCL device matches")])
def test_unknown_device_is_a_clear_error(spec, msg):
    with pytest.raises(dev.DeviceError, match=msg):
        dev.select_device(spec)


def test_no_platform_gives_one_sentence_not_a_traceback(monkeypatch):
    def boom():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")
    monkeypatch.setattr(dev.cl, "get_platforms", boom)
    with pytest.raises(dev.DeviceError, match="pip install pocl-binary-distribution"):
        dev.list_devices()
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 3
    assert "no OpenCL platform found" in res.output
    assert "Traceback" not in res.output


def test_programs_are_built_once_per_source_and_defines(monkeypatch):
    ctx = dev.Context(None)
    calls = []
    real = dev.kernel_source
    monkeypatch.setattr(dev, "kernel_source", lambda name: calls.append(name) or real(name))
    defs = {"PIXEL_T": "uchar", "CHANNELS": 3, "PIXEL_MAX": 255.0, "SEGMENT": 64}
    p1 = ctx.program("distances", defs)
    p2 = ctx.program("distances", dict(defs))
    assert p1 is p2 and calls.count("distances") == 1
    ctx.program("distances", {**defs, "CHANNELS": 4})
    assert calls.count("distances") == 2
    assert ctx.kernel("distances", "hline_distances", defs) is ctx.kernel("distances", "hline_distances", defs)


def test_build_error_names_file_defines_and_log(monkeypatch):
    ctx = dev.Context(None)
    real = dev.kernel_source
    monkeypatch.setattr(dev, "kernel_source",
                        lambda name: "__kernel void broken(void) { undeclared_thing(); }" if name == "edges"
                        else real(name))
    with pytest.raises(dev.KernelBuildError) as err:
        ctx.program("edges", {"METRIC": 0})
    text = str(err.value)
    assert "kernels/edges.cl" in text and "-DMETRIC=0" in text and "undeclared_thing" in text


def test_pocl_workers_are_pinned_only_where_the_process_may_use_every_cpu(monkeypatch):
    from mlaa_stream.device import context as device
    n = 4
    monkeypatch.setattr(device.os, "cpu_count", lambda: n)
    monkeypatch.setattr(device.os, "sched_getaffinity", lambda pid: set(range(n)), raising=False)
    env: dict[str, str] = {}
    assert device.pin_pocl_workers(env) and env == {"POCL_AFFINITY": "1"}
    env = {"POCL_AFFINITY": "0"}  # the user's choice stands
    assert not device.pin_pocl_workers(env) and env == {"POCL_AFFINITY": "0"}
    # taskset / cpusets: pinning worker i to CPU i would leave the allowed set
    monkeypatch.setattr(device.os, "sched_getaffinity", lambda pid: {1, 2}, raising=False)
    env = {}
    assert not device.pin_pocl_workers(env) and env == {}


def test_cpu_launches_get_a_fixed_work_group_and_a_padded_grid():
    """PoCL builds a kernel per work-group size: a fixed one means no build per frame size (issue 17)."""
    assert dev.launch_size((30, 1079), cpu=True) == ((30, 1080), (1, 8))
    assert dev.launch_size((1079,), cpu=True) == ((1080,), (8,))
    assert dev.launch_size((30, 1079), cpu=False) == ((30, 1079), None)


@pytest.mark.parametrize("shape", [(13, 17), (9, 70), (41, 3), (1, 1)])
def test_frames_of_sizes_off_the_work_group_grid_match_the_reference(shape):
    from mlaa_stream.spatial.filter import Filter
    from mlaa_stream.spatial.reference import mlaa_reference

    rng = np.random.default_rng(sum(shape))
    frame = np.kron(rng.integers(0, 256, (shape[0] // 3 + 1, shape[1] // 3 + 1, 3)), np.ones((3, 3, 1)))
    frame = frame[:shape[0], :shape[1]].astype(np.uint8)
    out = Filter(bridge=False).process(frame)
    ref = mlaa_reference(frame)
    assert np.abs(out.astype(int) - ref.astype(int)).max() <= 1


def test_a_gpu_driver_without_an_icd_file_is_named_with_the_fix(tmp_path, monkeypatch):
    """As on a GPU container: the vendor's library mounted, only PoCL registered (docs/portability.md)."""
    from mlaa_stream.device import drivers
    libs, vendors = tmp_path / "nvidia" / "lib64", tmp_path / "vendors"
    libs.mkdir(parents=True)
    vendors.mkdir()
    (libs / "libnvidia-opencl.so.1").write_bytes(b"\x7fELF")
    (libs / "libnvidia-opencl.so.580.159.04").write_bytes(b"\x7fELF")
    (vendors / "pocl.icd").write_text("libpocl.so.2\n")
    env = {drivers.VENDORS_ENV: str(vendors)}
    found = drivers.unregistered_gpu_drivers((str(tmp_path / "empty"), str(libs)), env)
    assert [(d.vendor, d.library, d.icd_name) for d in found] == [
        ("NVIDIA", str(libs / "libnvidia-opencl.so.1"), "nvidia.icd")]
    assert f"echo {libs / 'libnvidia-opencl.so.1'} > /etc/OpenCL/vendors/nvidia.icd" in found[0].hint()
    # the command says it where it lists no GPU
    monkeypatch.setattr(drivers, "LIBRARY_DIRS", (str(libs),))
    monkeypatch.setenv(drivers.VENDORS_ENV, str(vendors))
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 0 and ("note: NVIDIA's OpenCL driver is at" in res.output) == (" [GPU," not in res.output)
    # registered (by a path or by the bare name, in the folder or as the one file $OCL_ICD_VENDORS names): silent
    (vendors / "nvidia.icd").write_text(f"{libs / 'libnvidia-opencl.so.1'}\n")
    assert drivers.unregistered_gpu_drivers((str(libs),), env) == []
    one = tmp_path / "only.icd"
    one.write_text("libnvidia-opencl.so.1\n")
    assert drivers.unregistered_gpu_drivers((str(libs),), {drivers.VENDORS_ENV: str(one)}) == []


def test_a_pip_installed_intel_cpu_runtime_without_an_icd_file_is_named_with_the_fix(tmp_path):
    """pip cannot write an ICD file: where Intel's CPU runtime sits in the environment unregistered, the hint says
    how to register it (with the library path its own libraries need)."""
    from mlaa_stream.device import drivers
    (tmp_path / "lib").mkdir()
    (tmp_path / "lib" / "libintelocl.so").write_bytes(b"\x7fELF")
    vendors = tmp_path / "vendors"
    vendors.mkdir()
    (vendors / "pocl.icd").write_text("libpocl.so.2\n")
    env = {drivers.VENDORS_ENV: str(vendors)}
    (hint,) = drivers.unregistered_pip_runtimes(str(tmp_path), env)
    lib = tmp_path / "lib" / "libintelocl.so"
    assert f"echo {lib} > /etc/OpenCL/vendors/intel-cpu.icd" in hint and f"LD_LIBRARY_PATH={tmp_path / 'lib'}" in hint
    (vendors / "intel.icd").write_text(f"{lib}\n")
    assert drivers.unregistered_pip_runtimes(str(tmp_path), env) == []
    assert drivers.unregistered_pip_runtimes(str(tmp_path / "none"), env) == []


def test_a_device_variable_that_names_nothing_is_named_and_devices_still_lists(monkeypatch):
    """MLAA_STREAM_DEVICE=garbage: the error says the variable chose it (the user typed no --device), and
    `mlaa-stream devices`, where one goes to find a valid name, lists the devices before saying so (exit 3)."""
    monkeypatch.setenv(dev.DEVICE_ENV, "no-such-device-xyz")
    with pytest.raises(dev.DeviceError, match=r"^\$MLAA_STREAM_DEVICE: no OpenCL device matches"):
        dev.select_device(None)
    monkeypatch.setenv(dev.DEVICE_ENV, "99")
    with pytest.raises(dev.DeviceError, match=r"^\$MLAA_STREAM_DEVICE: expected a device index below"):
        dev.select_device(None)
    with pytest.raises(dev.DeviceError, match=r"^expected a device index below"):  # --device 99: no variable named
        dev.select_device("99")
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 3
    assert "0: " + dev.list_devices()[0].name in res.output and "$MLAA_STREAM_DEVICE: expected" in res.output
    assert "* " not in res.output


def test_devices_marks_the_chosen_device_not_every_device_of_its_name(monkeypatch):
    """Two devices of one name (two GPUs of a kind, one runtime registered twice): only the chosen one gets *."""
    class Twin:  # another device that reports the same name, platform and kind
        def __init__(self, device):
            self._device = device

        def __getattr__(self, name):
            return getattr(self._device, name)

    first = dev._all_devices()[0]
    monkeypatch.setattr(dev, "_all_devices", lambda devices=[first, Twin(first)]: devices)
    monkeypatch.setattr("mlaa_stream.cli.devices_cmd._all_devices", dev._all_devices)
    monkeypatch.setenv(dev.DEVICE_ENV, "1")
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 0, res.output
    assert [ln[:3] for ln in res.output.splitlines()[:2]] == ["  0", "* 1"]


def test_no_platform_with_the_loader_variable_set_names_the_variable(monkeypatch):
    """OCL_ICD_VENDORS=/nonexistent: the loader finds no platform with PoCL installed; 'install PoCL' alone
    would mislead, so the message names the variable first."""
    def boom():
        raise cl.LogicError("clGetPlatformIDs failed: PLATFORM_NOT_FOUND_KHR")
    monkeypatch.setattr(dev.cl, "get_platforms", boom)
    monkeypatch.setenv("OCL_ICD_VENDORS", "/nonexistent")
    with pytest.raises(dev.DeviceError, match="where OCL_ICD_VENDORS='/nonexistent' points .* unset it"):
        dev.list_devices()
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 3 and "OCL_ICD_VENDORS='/nonexistent'" in res.output
    monkeypatch.delenv("OCL_ICD_VENDORS")
    assert dev.no_platform_message() == dev.NO_PLATFORM_HINT


class StubPlatform:
    def __init__(self, name: str, version: str, ptr: int):
        self.name, self.version, self.int_ptr = name, version, ptr


class StubDevice:
    """An OpenCL device as select_device and `mlaa-stream devices` read it, where the machine has no second one."""

    def __init__(self, name: str, platform: StubPlatform, ptr: int, kind=cl.device_type.GPU):
        self.name, self.platform, self.int_ptr, self.type = name, platform, ptr, kind
        self.version, self.driver_version, self.vendor_id = "OpenCL 3.0 CUDA", "570.86", 0x10DE
        self.global_mem_size, self.max_compute_units = 141 << 30, 132


def test_a_device_name_matching_several_devices_is_an_error_naming_them(monkeypatch, tmp_path):
    """`--device H200` on a machine with two H200s (or `--device pocl` with two PoCLs) took the first without a word.
    Now it is an error listing the matches with their indices and saying how to pick one; the same device listed
    twice (one driver registered by two ICD files) is still taken."""
    nvidia = StubPlatform("NVIDIA CUDA", "OpenCL 3.0 CUDA 12.8", 1)
    gpus = [StubDevice("NVIDIA H200", nvidia, 10), StubDevice("NVIDIA H200", nvidia, 11)]
    monkeypatch.setattr(dev, "_all_devices", lambda: gpus)
    monkeypatch.delenv(dev.DEVICE_ENV, raising=False)
    with pytest.raises(dev.DeviceError, match=r"^'H200' matches 2 OpenCL devices \(0: NVIDIA H200 \(GPU, NVIDIA "
                                              r"CUDA\); 1: NVIDIA H200 \(GPU, NVIDIA CUDA\)\); pick one by its "
                                              r"index, e\.g\. --device 0"):
        dev.select_device("H200")
    monkeypatch.setattr(dev, "compile_problem", lambda d: None if d is gpus[1] else "fails to build")
    assert dev.select_device("gpu") is gpus[1]   # a kind word: the one of that kind the default would pick
    monkeypatch.setattr(dev, "compile_problem", lambda d: None)
    assert dev.select_device("1") is gpus[1]
    monkeypatch.setenv(dev.DEVICE_ENV, "nvidia")
    with pytest.raises(dev.DeviceError, match=r"^\$MLAA_STREAM_DEVICE: 'nvidia' matches 2 .* MLAA_STREAM_DEVICE=0"):
        dev.select_device(None)
    monkeypatch.setattr("mlaa_stream.cli.devices_cmd._all_devices", dev._all_devices)
    res = CliRunner().invoke(main, ["devices"])   # still lists them, then says why none is marked
    assert res.exit_code == 3 and "'nvidia' matches 2 OpenCL devices" in res.output
    assert res.output.splitlines()[:2] == ["  0: NVIDIA H200  [GPU, NVIDIA CUDA, 132 compute units, 144384 MiB]",
                                           "  1: NVIDIA H200  [GPU, NVIDIA CUDA, 132 compute units, 144384 MiB]"]
    png = os.path.join(os.path.dirname(__file__), "..", "fixtures", "demo", "images", "rgb8.png")
    res = CliRunner().invoke(main, [png, "-o", str(tmp_path / "out.png"), "--device", "H200"])
    assert res.exit_code == 3 and "'H200' matches 2 OpenCL devices" in res.output, res.output
    # one driver registered twice: its device under two platforms that say the same of themselves
    twice = [gpus[0], StubDevice("NVIDIA H200", StubPlatform("NVIDIA CUDA", "OpenCL 3.0 CUDA 12.8", 2), 20)]
    monkeypatch.setattr(dev, "_all_devices", lambda: twice)
    monkeypatch.delenv(dev.DEVICE_ENV)
    assert dev.select_device("H200") is twice[0]
    # the same device object listed twice
    monkeypatch.setattr(dev, "_all_devices", lambda: [gpus[0], gpus[0]])
    assert dev.select_device("H200") is gpus[0]
    # two runtimes on one CPU are two devices (one may build where the other cannot)
    pocl = [StubDevice("pthread-AMD EPYC", StubPlatform("Portable Computing Language", v, p), p * 10,
                       cl.device_type.CPU) for v, p in (("OpenCL 3.0 PoCL 3.1", 3), ("OpenCL 3.0 PoCL 3.0", 4))]
    monkeypatch.setattr(dev, "_all_devices", lambda: pocl)
    with pytest.raises(dev.DeviceError, match="'EPYC' matches 2"):
        dev.select_device("EPYC")


def test_a_blank_device_variable_is_unset_and_a_missing_kind_is_named(monkeypatch):
    """$MLAA_STREAM_DEVICE set to spaces was stripped to '' and matched every device's name ("'' matches 2 OpenCL
    devices" where two are listed); `gpu` on a machine without one said "no OpenCL device matches 'gpu'", as if
    it were a name part."""
    cpus = [StubDevice(f"pthread-CPU{k}", StubPlatform("Portable Computing Language", "OpenCL 3.0 PoCL 3.1", k),
                       k * 10, cl.device_type.CPU) for k in (1, 2)]
    monkeypatch.setattr(dev, "_all_devices", lambda: cpus)
    for d in cpus:  # default_choice's probe: both build (its default argument is the function itself)
        monkeypatch.setitem(dev._probed, (d.platform.name, d.platform.version, d.name), None)
    monkeypatch.setenv(dev.DEVICE_ENV, "  ")
    assert dev.select_device(None) is dev.select_device(" ") is dev.default_choice(cpus)[0]
    monkeypatch.setattr("mlaa_stream.cli.devices_cmd._all_devices", dev._all_devices)
    res = CliRunner().invoke(main, ["devices"])
    assert res.exit_code == 0 and "matches" not in res.output and "$MLAA_STREAM_DEVICE=" not in res.output, res.output
    monkeypatch.delenv(dev.DEVICE_ENV)
    with pytest.raises(dev.DeviceError, match=r"^no OpenCL device is a GPU \('gpu' picks one of that kind\)"):
        dev.select_device("gpu")
