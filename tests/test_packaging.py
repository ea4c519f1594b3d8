"""The wheel carries every kernel and the footprint table, and installs no top-level `cli` package (DESIGN.md,
Layout)."""
from __future__ import annotations

import subprocess
import sys
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_wheel_contains_every_kernel_and_no_top_level_cli(tmp_path):
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-q", "-w", str(tmp_path), str(ROOT)],
                   check=True, capture_output=True)
    wheel = next(tmp_path.glob("mlaa_stream-*.whl"))
    names = zipfile.ZipFile(wheel).namelist()
    kernels = sorted(p.name for p in (ROOT / "kernels").glob("*.cl"))
    assert kernels, "no kernels in the source tree"
    for k in kernels:
        assert f"mlaa_stream/kernels/{k}" in names, f"{k} missing from the wheel"
    assert "mlaa_stream/cli/main.py" in names
    assert "mlaa_stream/data/footprint_table.npy" in names  # the footprint table (spatial/footprint.py)
    tops = {n.split("/")[0] for n in names}
    assert "cli" not in tops and "kernels" not in tops, f"top-level entries: {sorted(tops)}"


def test_kernels_load_through_importlib_resources():
    from mlaa_stream.device.context import kernel_source
    assert "__kernel void detect_edges" in kernel_source("edges")
