"""mlaa-stream: morphological antialiasing for video and frame sequences, as OpenCL kernels."""
from .device import DeviceError, KernelBuildError, list_devices

__all__ = ["DeviceError", "KernelBuildError", "list_devices"]
__version__ = "0.1.0"
