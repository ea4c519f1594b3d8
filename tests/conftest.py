"""Shared fixtures. The package installs PoCL from PyPI, so an OpenCL device is always expected here:
without one the kernel tests fail loudly instead of skipping (a skip would hide a broken install)."""
from __future__ import annotations

import os
import signal

import numpy as np
import pytest

from mlaa_stream.device.context import Context, DeviceError, default_context


@pytest.fixture(scope="module")
def device() -> Context:
    """The OpenCL device kernel tests run on; host-only tests do not ask for it."""
    try:
        return default_context(None)
    except DeviceError as exc:
        pytest.fail(f"no OpenCL device (expected PoCL from `pip install .`): {exc}")


@pytest.fixture(scope="module")
def client():
    """A Dask LocalCluster of 2 worker processes (one thread each) and its client, per test module."""
    distributed = pytest.importorskip("distributed", reason="Dask is in the [cluster] and [test] extras")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0")
    c = distributed.Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture
def send_signal():
    """`send_signal(sig)` delivers a real signal to this process, as a terminal's Ctrl-C or `kill` would.

    SIGINT gets Python's default handler (KeyboardInterrupt) for the test, so it arrives whether or not
    the suite was started with SIGINT ignored (`cmd &` in a non-interactive shell)."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield lambda sig=signal.SIGINT: os.kill(os.getpid(), sig)
    finally:
        signal.signal(signal.SIGINT, previous)


# Lines the suite wants in the CI log even with -q (e.g. the kernel tests' result on a second OpenCL
# implementation, tests/test_portability.py).
SUMMARY_LINES: list[str] = []


def pytest_terminal_summary(terminalreporter) -> None:
    for line in SUMMARY_LINES:
        terminalreporter.write_line(line)


@pytest.fixture
def zoom_frames():
    """_zoom: a dolly's frames (tests of the temporal stage's dense motion)."""
    return _zoom


def _zoom(z: float, n: int = 6, seed: int = 8, w: int = 160, h: int = 120):
    """A textured plane zooming by z per frame about the centre (a dolly), w x h: 1-spp frames (point samples at
    pixel centres), box-filtered truths and the zoom's centre in pixels."""
    import cv2
    rng = np.random.default_rng(seed)
    up = 4
    tex = cv2.GaussianBlur(rng.random((h * up, w * up)).astype(np.float32), (0, 0), 5)
    tex = np.clip((tex - tex.mean()) / tex.std() * 60 + 128, 0, 255).astype(np.float32)
    tex[::97] = 240.0   # thin bright lines: aliasing to resolve
    cxh, cyh = (w * up - 1) / 2, (h * up - 1) / 2
    frames, truths = [], []
    for t in range(n):
        s = z ** t
        hi = cv2.warpAffine(tex, np.float32([[s, 0, (1 - s) * cxh], [0, s, (1 - s) * cyh]]), (w * up, h * up),
                            flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
        frames.append(np.round(hi[up // 2::up, up // 2::up]).astype(np.uint8))
        truths.append(np.round(cv2.resize(hi, (w, h), interpolation=cv2.INTER_AREA)).astype(np.uint8))
    return frames, truths, ((cxh - up // 2) / up, (cyh - up // 2) / up)
