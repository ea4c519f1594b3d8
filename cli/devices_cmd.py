"""`mlaa-stream devices`: list the OpenCL devices and which one is picked by default."""
from __future__ import annotations

import os
import sys

import click

from mlaa_stream.device.context import (DEVICE_ENV, DeviceError, _all_devices, default_choice, list_devices,
                                        select_device)
from mlaa_stream.device.drivers import unregistered_gpu_drivers, unregistered_pip_runtimes


@click.command("devices", epilog="Exit codes: 0 listed; 3 no OpenCL device (the message says why and what to install).")
def devices_command() -> None:
    """List OpenCL devices; the one marked * is used by default."""
    try:
        infos = list_devices()
        chosen = select_device(None)
        env = os.environ.get(DEVICE_ENV)
        why = f"${DEVICE_ENV}={env}" if env else default_choice(_all_devices())[1]
    except DeviceError as exc:
        click.echo(f"mlaa-stream: {exc}", err=True)
        for driver in unregistered_gpu_drivers():
            click.echo(f"mlaa-stream: {driver.hint()}", err=True)
        for hint in unregistered_pip_runtimes():
            click.echo(f"mlaa-stream: {hint}", err=True)
        sys.exit(3)
    for info in infos:
        mark = "*" if (info.name, info.platform) == (chosen.name.strip(), chosen.platform.name.strip()) else " "
        click.echo(f"{mark} {info.index}: {info.name}  [{info.kind}, {info.platform}, "
                   f"{info.compute_units} compute units, {info.global_mem_mb} MiB]")
    click.echo(f"* picked by default: {why} (--device N or ${DEVICE_ENV} picks another)")
    if not any(info.kind == "GPU" for info in infos):
        for driver in unregistered_gpu_drivers():
            click.echo(f"note: {driver.hint()}")
