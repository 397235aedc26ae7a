"""Shared fixtures of the ensemble tests: a LocalCluster, and a real cluster of separate processes (a
``dask scheduler`` and two ``dask worker`` processes on 127.0.0.1), both shared by the whole folder and
closed at its end; the serial in-process reference runs the members are compared with."""
from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "models"
START_SECONDS = 90  # bound on starting the process cluster (it normally takes a few seconds)


@pytest.fixture(scope="session")
def local_client():
    """A LocalCluster with 2 single-threaded worker processes, as the default engine makes."""
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0")
    client = Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="session")
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


@pytest.fixture(scope="session")
def process_client(process_cluster):
    from distributed import Client

    client = Client(process_cluster, timeout=30)
    yield client
    client.close()


def _span(text: str) -> slice:
    """'3' or '1..10' (1-based, inclusive) -> a 0-based slice."""
    first, _, last = text.partition("..")
    return slice(int(first) - 1, int(last or first))


def serial_run(scene, setting: dict, t_end: float, n_out: int, method="rattle", dt=1e-3, rtol=None,
               project_initial=None):
    """The member run serially in this process through the library's public API only (its own reading of
    the parameter names, not the ensemble module's): ``ln.simulate`` on the scene with the member's values."""
    mass, length, gravity = np.array(scene.mass), np.array(scene.length), np.array(scene.gravity)
    U0 = np.array(scene.U0)
    forces = np.zeros((scene.K, 3))
    data = scene.to_dict()
    for name, value in setting.items():
        family, index = re.fullmatch(r"(\w+)(?:\[(.*)\])?", name).groups()
        slots = tuple(_span(s) for s in index.split(",")) if index else ()
        target = {"M": mass, "R": length, "g": gravity, "F": forces, "U0": U0}.get(family)
        if target is not None:
            target[slots] = value
        elif family == "stiffness":
            for spring in data["springs"][slots[0]]:
                spring["stiffness"] = value
        else:
            raise AssertionError(f"serial_run does not know {name}")
    changed = ln.Scene.from_dict(data).with_parameters(mass=mass, length=length, gravity=gravity).with_state(U0=U0)
    return ln.simulate(changed, t_end, method=method, dt=dt, rtol=rtol, n_out=n_out,
                       forces=forces if any(n.startswith("F[") for n in setting) else None,
                       project_initial=project_initial)


def assert_member_equals(ds, member: int, reference, atol=1e-12) -> None:
    """X, U, T of one member against a serial run, to round-off."""
    np.testing.assert_allclose(ds["X"].values[member], reference.X, rtol=0, atol=atol)
    np.testing.assert_allclose(ds["U"].values[member], reference.U, rtol=0, atol=atol * 100)
    np.testing.assert_allclose(ds["T"].values[member], reference.T, rtol=1e-10, atol=atol * 100)
    assert ds["max_tension"].values[member] == pytest.approx(reference.T.max(), rel=1e-10)
    tip = int(ds.attrs["tip_mass"]) - 1
    np.testing.assert_allclose(ds["tip_final"].values[member], reference.X[-1, tip], rtol=0, atol=atol)
