"""`mlaa-stream devices`: list the OpenCL devices and which one is picked by default."""
from __future__ import annotations

import os
import sys

import click

from mlaa_stream.device.context import (DEVICE_ENV, DeviceError, _all_devices, default_choice, list_devices,
                                        select_device)
from mlaa_stream.device.drivers import unregistered_gpu_drivers, unregistered_pip_runtimes


@click.command("devices", epilog="Exit codes: 0 listed; 3 no OpenCL device (the message says why and what to install), "
                                  f"or ${DEVICE_ENV} names none (the devices are still listed).")
def devices_command() -> None:
    """List OpenCL devices; the one marked * is used by default."""
    try:
        devices = _all_devices()
        infos = list_devices()
    except DeviceError as exc:
        click.echo(f"mlaa-stream: {exc}", err=True)
        for driver in unregistered_gpu_drivers():
            click.echo(f"mlaa-stream: {driver.hint()}", err=True)
        for hint in unregistered_pip_runtimes():
            click.echo(f"mlaa-stream: {hint}", err=True)
        sys.exit(3)
    env = os.environ.get(DEVICE_ENV, "").strip()  # blank is unset, as select_device takes it
    try:
        chosen = select_device(None)
        why = f"${DEVICE_ENV}={env}" if env else default_choice(devices)[1]
    except DeviceError as exc:  # $MLAA_STREAM_DEVICE names no device: the list is what the user needs to fix it
        chosen, why = None, str(exc)
    for info, dev in zip(infos, devices):
        mark = "*" if dev == chosen else " "  # the device itself: two of one name (two GPUs of a kind) are two
        click.echo(f"{mark} {info.index}: {info.name}  [{info.kind}, {info.platform}, "
                   f"{info.compute_units} compute units, {info.global_mem_mb} MiB]")
    if chosen is None:
        click.echo(f"mlaa-stream: {why}", err=True)
    else:
        click.echo(f"* picked by default: {why} (--device N or ${DEVICE_ENV} picks another)")
    if not any(info.kind == "GPU" for info in infos):
        for driver in unregistered_gpu_drivers():
            click.echo(f"note: {driver.hint()}")
    if chosen is None:
        sys.exit(3)
