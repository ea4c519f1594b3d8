"""Shared fixtures. The package installs PoCL from PyPI, so an OpenCL device is always expected here:
without one the kernel tests fail loudly instead of skipping (a skip would hide a broken install)."""
from __future__ import annotations

import pytest

from mlaa_stream.device import Context, DeviceError, default_context


@pytest.fixture(scope="module")
def device() -> Context:
    """The OpenCL device kernel tests run on; host-only tests do not ask for it."""
    try:
        return default_context(None)
    except DeviceError as exc:
        pytest.fail(f"no OpenCL device (expected PoCL from `pip install .`): {exc}")
