"""Faults: a member whose values make an invalid scene, or whose run fails, is recorded with its error while
the others complete; a worker killed mid-study costs only the retries of its members."""
import logging
import os
import re
import signal

import h5py
import numpy as np

import linknet_core as ln
from linknet_core.ensemble import open_study, shards, summary

from .ensemble_support import MODELS, assert_member_equals, serial_run

T_END, N_OUT = 0.5, 26


def test_invalid_member_and_failed_run_are_recorded_the_others_complete(local_client, tmp_path):
    scene = ln.load_scene(MODELS / "chain_10.json")
    ds = ln.ensemble(scene, vary={"M[11]": [1.0, -1.0], "F[11,3]": [2.0, 1e200]}, t_end=T_END, n_out=N_OUT,
                     client=local_client, out=tmp_path / "faults.nc")
    status, error = list(ds["status"].values), list(ds["error"].values)
    assert status == ["ok", "failed", "failed", "failed"], error
    # member 1: a huge force, the run fails; members 2, 3: a negative mass, the scene is invalid
    assert "non-finite" in error[1] or "SolverError" in error[1], error[1]
    assert error[2].startswith("invalid scene:") and "mass" in error[2] and "positive" in error[2]
    assert error[3] == error[2]
    assert np.isnan(ds["X"].values[1:]).all() and np.isnan(ds["max_tension"].values[1:]).all()
    assert ds.attrs["failed"] == 3 and ds.attrs["complete"] == 1
    assert_member_equals(ds, 0, serial_run(scene, {"M[11]": 1.0, "F[11,3]": 2.0}, T_END, N_OUT))
    text = summary(ds)
    assert "members 2-3: invalid scene" in text and "member 1 (M[11]=1, F[11,3]=1e+200)" in text


def test_killed_worker_costs_only_its_members_retries(process_client, tmp_path, caplog):
    """SIGKILL one of the two `dask worker` processes after the third result: its members in flight run again
    on a worker that lives (its nanny starts a new one), every member still equals its serial run, results
    finished before the kill are kept, and the study names the retried members, those whose finished result
    was lost with the worker before the study fetched it included (Dask's client says it reschedules them). The
    shard folder holds one whole shard per member, each in the file once: no half shard of the killed task, no
    member twice."""
    scene = ln.load_scene(MODELS / "chain_10.json")
    dt, t_end = 1e-5, 0.6  # ~0.3 s per member: the kill lands while both workers run members
    pids = process_client.run(os.getpid)  # worker address -> process id
    killed = {}

    def kill_after_third_result(progress):
        if progress.done >= 3 and not killed:
            busy = [w for w, keys in process_client.processing().items() if keys and w in pids]
            if busy:  # else at the next result
                killed["address"] = busy[0]
                os.kill(pids[busy[0]], signal.SIGKILL)

    masses = np.linspace(0.5, 2.0, 12)
    out = tmp_path / "killed.nc"
    with caplog.at_level(logging.WARNING, logger="distributed.client"):
        ds = ln.ensemble(scene, vary={"M[11]": masses}, t_end=t_end, n_out=N_OUT, dt=dt, client=process_client,
                         members_per_task=1, progress=kill_after_third_result, out=out)
    assert killed, "the study ended before the kill"
    assert list(ds["status"].values) == ["ok"] * 12, list(ds["error"].values)
    retried = np.flatnonzero(ds["retried"].values)
    assert 1 <= retried.size <= 4  # at most the 2 tasks per worker thread in flight
    assert ds.attrs["retried"] == retried.size
    workers = ds["worker"].values
    assert killed["address"] not in set(workers[retried])  # reruns happened on living workers
    kept = [m for m in range(12) if workers[m] == killed["address"]]  # finished before the kill: not rerun
    assert not set(kept) & set(retried)
    # tasks (one member each) whose finished result died with the worker: run again, so retried
    lost = [int(first) for record in caplog.records if "rescheduling" in record.getMessage()
            for first in re.findall(r"linknet-ensemble-\w+-(\d+)-1", record.getMessage())]
    assert set(lost) <= set(retried), (lost, retried)
    for m in range(12):
        assert_member_equals(ds, m, serial_run(scene, {"M[11]": masses[m]}, t_end, N_OUT, dt=dt))
    with h5py.File(out, "r") as f:
        sources = sorted((m.vspace.get_select_bounds()[0][0], m.file_name) for m in f["X"].virtual_sources())
    assert [first for first, _ in sources] == list(range(12))  # one task per member, each mapped once
    names = sorted(p.name for p in (tmp_path / "killed.shards").iterdir())
    assert names == sorted([shards.MARKER, shards.LAYOUT] + [os.path.basename(source) for _, source in sources])
    process_client.wait_for_workers(2, timeout=60)  # the nanny restarted the killed worker


class _FlakyFuture:
    """A finished batch whose result fetch fails `failures` times (as a connection fault would)."""

    status, key = "finished", "linknet-ensemble-x-0-1"

    def __init__(self, failures):
        self.failures = failures

    def result(self, timeout):
        if self.failures:
            self.failures -= 1
            raise AssertionError("comm fault while fetching")
        return {"first": 0}


def test_a_failed_fetch_is_tried_again_then_the_batch_reruns():
    """A fault while fetching a finished batch's result is not the members' failure and does not leave the
    study waiting: the fetch is tried again, and after FETCH_ATTEMPTS the batch is marked to run again."""
    from linknet_core.ensemble.engine import FETCH_ATTEMPTS, _fetch, _FetchFailed

    assert _fetch(_FlakyFuture(FETCH_ATTEMPTS - 1)) == ({"first": 0}, None)
    result, failure = _fetch(_FlakyFuture(FETCH_ATTEMPTS))
    assert result is None and isinstance(failure, _FetchFailed) and "comm fault" in str(failure)


def test_the_studys_scheduler_drops_only_the_lost_result_error():
    """The study's own scheduler process drops the one ERROR Dask logs when a worker died holding finished results
    that the client then asked for (the client reschedules them, and the study records their members as
    retried); every other error, a task that keeps killing its workers among them, still gets through."""
    from linknet_core.ensemble import scheduler_process

    names = ("distributed", "tornado", "distributed.scheduler")
    levels = {name: logging.getLogger(name).level for name in names}
    scheduler = logging.getLogger("distributed.scheduler")
    seen = []

    class Keep(logging.Handler):
        def emit(self, record):
            seen.append(record.getMessage())

    keep = Keep()
    scheduler.addHandler(keep)
    try:
        scheduler_process._silence_dask_logs()
        scheduler.error("Couldn't gather keys: %s", {"linknet-ensemble-0a1b-3-1": "processing"})
        scheduler.error("Task %s marked as failed because %d workers died while trying to run it",
                        "linknet-ensemble-0a1b-3-1", 3)
        scheduler.error("Couldn't gather %s keys", 2)  # another message, though alike
    finally:
        scheduler.removeHandler(keep)
        scheduler.removeFilter(scheduler_process._LOST_RESULT_FILTER)
        for name, level in levels.items():
            logging.getLogger(name).setLevel(level)
    assert seen == ["Task linknet-ensemble-0a1b-3-1 marked as failed because 3 workers died while trying to run it",
                    "Couldn't gather 2 keys"]


KILL_SCRIPT = """
import json, os, signal, sys, time
import numpy as np
from distributed import default_client
import linknet_core as ln

def main():
    killed = []

    def kill_a_worker_holding_a_result(progress):
        # a worker whose finished result the study has not fetched yet: the study asks for it right after
        if progress.done < 2 or killed:
            return
        client = default_client()
        deadline = time.monotonic() + 60
        while not killed and time.monotonic() < deadline:
            holding = [worker for worker, keys in client.has_what().items() if keys]
            if holding:
                pid = client.run(os.getpid, workers=[holding[0]])[holding[0]]
                killed.append(pid)
                os.kill(pid, signal.SIGKILL)
            time.sleep(0.005)

    ds = ln.ensemble(MODEL, vary={"M[11]": np.linspace(0.5, 2.0, 10)}, t_end=0.3, n_out=11, dt=1e-5, workers=2,
                     members_per_task=1, progress=kill_a_worker_holding_a_result, out=OUT)
    print(json.dumps({"status": [str(s) for s in ds["status"].values], "retried": int(ds["retried"].sum()),
                      "killed": killed}))

if __name__ == "__main__":
    main()
"""


def test_a_worker_killed_on_the_studys_own_cluster_leaves_stderr_silent(tmp_path):
    """The study's own local cluster (its scheduler in a process of its own) with a worker process killed
    (SIGKILL) mid-study: the study succeeds, every member equal to its serial run, and nothing reaches stderr
    (Dask's scheduler logged "Couldn't gather keys" as an ERROR when the killed worker held finished results)."""
    import json
    import subprocess
    import sys

    from .ensemble_support import ROOT

    out = tmp_path / "killed.nc"
    script = tmp_path / "kill_a_worker.py"
    model = str(MODELS / "chain_10.json")
    script.write_text(KILL_SCRIPT.replace("MODEL", repr(model)).replace("OUT", repr(str(out))))
    # the script runs from its own folder: linknet from this checkout, for it and its workers
    path = os.pathsep.join(filter(None, [str(ROOT), os.environ.get("PYTHONPATH")]))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=str(ROOT), timeout=300,
                         env={**os.environ, "PYTHONPATH": path})
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""
    result = json.loads(run.stdout)
    assert result["killed"] and result["status"] == ["ok"] * 10
    scene = ln.load_scene(MODELS / "chain_10.json")
    with open_study(out) as ds:
        for m, mass in enumerate(np.linspace(0.5, 2.0, 10)):
            assert_member_equals(ds, m, serial_run(scene, {"M[11]": mass}, 0.3, 11, dt=1e-5))
