"""mlaa-stream: morphological antialiasing for video and frame sequences, as OpenCL kernels."""
from pathlib import Path as _Path

# In a source checkout (cwd on sys.path shadows the installed package), `cli/` and `kernels/` sit
# beside this folder; pyproject.toml maps them to mlaa_stream.cli / mlaa_stream.kernels when installed.
_root = _Path(__file__).resolve().parent.parent
if (_root / "pyproject.toml").is_file() and (_root / "kernels" / "common.cl").is_file():
    __path__.append(str(_root))  # noqa: F821 - the package's own __path__

from mlaa_stream.device.context import DeviceError, KernelBuildError, list_devices  # noqa: E402
from mlaa_stream.spatial.filter import PRESETS, Filter  # noqa: E402
from mlaa_stream.antialiaser import Antialiaser  # noqa: E402

__all__ = ["Antialiaser", "DeviceError", "Filter", "KernelBuildError", "PRESETS", "list_devices"]
__version__ = "0.1.0"
