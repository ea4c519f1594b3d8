"""The Dask client for `--cluster`: `local:N` starts a LocalCluster of N worker processes on this machine
(tests, one big machine); anything else is a scheduler address (tcp://host:8786) of a running cluster."""
from __future__ import annotations

import logging
import re
from contextlib import contextmanager
from typing import Iterator


class ClusterAddressError(ValueError):
    """--cluster is neither local:N nor a scheduler address."""


def parse_address(address: str) -> tuple[str, int | str]:
    """("local", N) or ("remote", address); ClusterAddressError for anything else or without Dask."""
    try:
        import distributed  # noqa: F401
    except ImportError as exc:
        raise ClusterAddressError(f"--cluster needs Dask: pip install 'mlaa-stream[cluster]' ({exc})") from exc
    m = re.fullmatch(r"local(?::(\d+))?", address.strip())
    if m:
        n = int(m.group(1) or 2)
        if n < 1:
            raise ClusterAddressError(f"--cluster local:N: expected N >= 1, got {n}")
        return "local", n
    if "://" not in address and not re.fullmatch(r"[\w.-]+:\d+", address):
        raise ClusterAddressError(f"--cluster: expected local:N or a scheduler address like tcp://host:8786, "
                                  f"got {address!r}")
    return "remote", address


@contextmanager
def connect(address: str) -> Iterator[object]:
    """A dask.distributed.Client for `address`, closed (with its LocalCluster) on exit."""
    from dask.distributed import Client, LocalCluster

    kind, where = parse_address(address)
    if kind == "local":
        n = int(where)
        # one thread per worker: each worker's OpenCL device already uses the machine's cores. Workers log only
        # what is critical: a failing chunk is reported by the job (naming its chunk and frame), and the workers'
        # "Compute Failed" records with their tracebacks (ERROR) repeated it on this terminal, once per try
        cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                               silence_logs=logging.CRITICAL)
        client = Client(cluster)
        try:
            yield client
        finally:
            client.close()
            cluster.close()
        return
    client = Client(address, timeout="30s")
    try:
        yield client
    finally:
        client.close()
