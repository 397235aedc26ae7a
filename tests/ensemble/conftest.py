"""Shared fixtures of the ensemble tests: a LocalCluster, one whose worker is a thread of this process, and a real
cluster of separate processes (a ``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1), each shared by
this folder's tests and closed when they are done. Helpers (the serial reference runs) are in ensemble_support.py."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time

import pytest

START_SECONDS = 90  # bound on starting the process cluster (it normally takes a few seconds)


@pytest.fixture(scope="package")
def local_client():
    """A LocalCluster with 2 single-threaded worker processes, as the default engine makes."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0")
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="package")
def threads_client():
    """A LocalCluster whose single worker is a thread of this process: what a test changes in the ensemble's
    modules here, the worker sees."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=False, dashboard_address="127.0.0.1:0")
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="package")
def process_cluster(tmp_path_factory):
    """A scheduler and 2 workers (each under its nanny, which restarts a killed worker), started as separate
    processes exactly as a user would start them; yields the scheduler's address. Each process leads its own
    process group, so cleanup ends it and its children by that id."""
    folder = tmp_path_factory.mktemp("dask_cluster")
    scheduler_file = folder / "scheduler.json"
    common = dict(cwd=str(folder), start_new_session=True, stdout=subprocess.DEVNULL)
    processes = [subprocess.Popen(
        [sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0",
         "--no-dashboard", "--dashboard-address", "127.0.0.1:0",  # its HTTP server stays on the loopback too
         "--scheduler-file", str(scheduler_file)],
        stderr=open(folder / "scheduler.log", "w"), **common)]
    try:
        deadline = time.monotonic() + START_SECONDS
        while not scheduler_file.exists() or not scheduler_file.read_text().strip():
            if time.monotonic() > deadline or processes[0].poll() is not None:
                raise RuntimeError(f"dask scheduler did not start: {(folder / 'scheduler.log').read_text()[-2000:]}")
            time.sleep(0.2)
        time.sleep(0.2)  # the file is written in one go, but let the scheduler finish its start
        address = json.loads(scheduler_file.read_text())["address"]
        assert address.startswith("tcp://127.0.0.1:")
        for n in range(2):
            processes.append(subprocess.Popen(
                [sys.executable, "-m", "distributed.cli.dask_worker", address, "--nthreads", "1",
                 "--host", "127.0.0.1", "--no-dashboard", "--name", f"worker-{n}", "--death-timeout", "60"],
                stderr=open(folder / f"worker-{n}.log", "w"), **common))
        from distributed import Client

        with Client(address, timeout=30) as client:
            client.wait_for_workers(2, timeout=START_SECONDS)
        yield address
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                os.killpg(process.pid, signal.SIGTERM)
        for process in processes:
            try:
                process.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(process.pid, signal.SIGKILL)
                process.wait(timeout=10)


@pytest.fixture(scope="package")
def process_client(process_cluster):
    from distributed import Client

    client = Client(process_cluster, timeout=30)
    yield client
    client.close()
