"""Ensembles on Dask against the serial loop: throughput, CPU time per component, projection to big clusters
(measures; asserts only the members' correctness).

Study: chain_10 (models/chain_10.json), 1000 members varying the tip mass M[11] and gravity g[3] (a 40 x 25
grid), t_end = 2 s, RATTLE at dt = 1e-3 s, 201 outputs of X, U, T per member, written by the workers as shard files
beside the study's netCDF file, which joins them (linknet_core/ensemble/shards.py, store.py).

1. Throughput, in one run: the serial loop (each member's scene from ``with_parameters``, then ``ln.simulate``,
   in this process, over ``--serial-members`` members spread over the grid: its figure is a time per member) and
   the study on a cluster of each ``--workers`` count only, as ln.ensemble starts one (engine.local_cluster: the
   scheduler in a process of its own; started and warmed outside the timed span), and on the 2-worker one (or the
   largest) keeping the quantities of interest only, interleaved round by round (``--rounds``). A round's ratio
   is the serial loop's time per member over the study's, both from that round, so the machine's load (other
   jobs on shared cores) moves both alike; the table gives the median over rounds and the range. Beside wall
   time, every study's CPU time: the worker processes, the members' own runs (as the workers measured them), the
   scheduler's process, this process's main thread (the study loop, the file writes) and its other threads (the
   client's communication; a LocalCluster's scheduler, where the cluster is one). CPU time grows far less than wall time when other jobs share the cores: the
   CPU-time ratio, min(N / w, 1 / c, cores / (w + c)) times the serial loop's CPU time per member (w, c: the
   workers' and the client's CPU time per member), is what the machine would give without them.
2. Per-member CPU breakdown, in this process (thread CPU time, medians of interleaved repeats over members of
   the grid): scene build, structure analysis, Simulator construction, the integration with its companion,
   a worker's bookkeeping, its shard write, the serialisation of a batch's result, the client's record of it;
   and what the client pays for a batch whose trajectories come to it (a worker that does not see the folder):
   their serialisation and the client's shard write.
3. Costs by cause, on the 2-worker cluster: idle (CPU time per second of an idle cluster); per study and per
   task (studies of 2 and of 200 trivial members, one per task, with the quantities of interest only and with
   X, U, T: a shard per task); per member beyond its run (studies of 2000 short members in batches of 200, with
   X, U, T and with the quantities of interest only, each less the per-task costs of its kind). With them, each
   study's CPU time per member is split by cause ("of it file writes": the client's, from the study's
   client_write_cpu_seconds; the workers' shard writes are part of their per-member figure, and said apart from
   worker_write_cpu_seconds).
4. Projection to 16 and 100 workers from these figures, and the same model against the run's own studies (wall
   time predicted from their figures against measured; the model is printed with them; docs/ensemble.md).
   ``--explain RUN.json`` prints that fit for an earlier run's JSON and stops.

The wall time of each phase (cold start, the clusters' start, the rounds by kind, each calibration) is said on
stderr as it ends and printed at the end.

    python -m benchmarks.bench_ensemble [--workers 1,2] [--members 1000] [--serial-members N] [--rounds 5]
                                        [--out build/bench_ensemble.json]
    python -m benchmarks.bench_ensemble --workers 8,16 --members 4000 --serial-members 500 --rounds 2
    python -m benchmarks.bench_ensemble --explain build/bench_ensemble.json
    python -m benchmarks.bench_ensemble --quick    # CI: 16 short members on 1 worker, checked against serial runs

--quick is a smoke test of correctness only (each member bit-identical to its serial ln.simulate run); it times
nothing.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import tempfile
import threading
import time
import warnings
from pathlib import Path

import numpy as np

import linknet_core as ln
from linknet_core.accuracy import AccuracyWarning
from linknet_core.ensemble import make_plan
from linknet_core.ensemble.engine import local_cluster, quiet_shutdown  # the cluster ln.ensemble starts

from benchmarks.output import build_path, write_text

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "models" / "chain_10.json"
DT, N_OUT, T_END = 1e-3, 201, 2.0
OUTPUTS = ("X", "U", "T")
PROJECTED_WORKERS = (16, 100)


def study_grid(members: int) -> dict:
    """About ``members`` members as a grid of tip mass x gravity (40 x 25 for 1000)."""
    n_mass = max(2, int(round(np.sqrt(members * 40 / 25))))
    n_g = max(1, members // n_mass)
    return {"M[11]": np.linspace(0.05, 0.5, n_mass), "g[3]": np.linspace(-9.81, -1.0, n_g)}


def member_settings(vary: dict) -> list[tuple[float, float]]:
    return [(m, g) for m in vary["M[11]"] for g in vary["g[3]"]]


def serial_member(scene, mass: float, gravity: float, t_end: float, n_out: int):
    """One member as a user's serial loop runs it: the scene with the member's values, then ln.simulate."""
    masses = np.array(scene.mass)
    masses[10] = mass
    member = scene.with_parameters(mass=masses, gravity=[0.0, 0.0, gravity])
    return ln.simulate(member, t_end, dt=DT, n_out=n_out)


def serial_loop(scene, settings: list[tuple[float, float]], t_end: float, n_out: int) -> dict:
    wall, cpu = time.perf_counter(), time.thread_time()
    for mass, gravity in settings:
        serial_member(scene, mass, gravity, t_end, n_out)
    wall, cpu = time.perf_counter() - wall, time.thread_time() - cpu
    return {"members": len(settings), "wall_s": wall, "members_per_s": len(settings) / wall,
            "cpu_member_s": cpu / len(settings)}


# ---- CPU time of processes and threads ----------------------------------------------------------------

def cluster_processes(client) -> list:
    """The worker processes of a cluster and their nannies (psutil handles, read from here: asking the workers
    themselves would cost them CPU time)."""
    import psutil

    pids = set()
    for pid, parent in client.run(lambda: (os.getpid(), os.getppid())).values():
        pids.add(pid)
        if parent != os.getpid():  # a nanny (a LocalCluster's workers are its nannies' children)
            pids.add(parent)
    return [psutil.Process(pid) for pid in sorted(pids)]


def processes_cpu(processes) -> float:
    total = 0.0
    for p in processes:
        times = p.cpu_times()
        total += times.user + times.system
    return total


def other_threads_cpu() -> float:
    """CPU time of this process's threads but the main one (the event loop: a LocalCluster's scheduler and the
    client's communication)."""
    total = 0.0
    for thread in threading.enumerate():
        if thread is not threading.main_thread() and thread.ident is not None:
            try:
                total += time.clock_gettime(time.pthread_getcpuclockid(thread.ident))
            except OSError:  # a thread that just ended
                pass
    return total


def scheduler_processes(client) -> list:
    """The scheduler's process, where it is not this one (ln.ensemble's own cluster runs it in a process of its
    own; a LocalCluster runs it here, where the other threads' CPU time holds it)."""
    import psutil

    pid = client.run_on_scheduler(os.getpid)
    return [] if pid == os.getpid() else [psutil.Process(pid)]


class CpuMeter:
    """CPU time over a span: the cluster's worker processes (with nannies of their own), the scheduler's process
    (``scheduler``, where it has one), this main thread, this process's other threads. Threads that end inside the
    span (none do in a study) would be missed."""

    def __init__(self, processes, scheduler=()):
        self.processes = processes
        self.scheduler_processes = list(scheduler)

    def _now(self):
        return (processes_cpu(self.processes), processes_cpu(self.scheduler_processes), time.thread_time(),
                other_threads_cpu(), time.perf_counter())

    def __enter__(self):
        self._start = self._now()
        return self

    def __exit__(self, *exc):
        end = self._now()
        self.workers, self.scheduler, self.main, self.others, self.wall = (b - a for a, b in zip(self._start, end))

    @property
    def client_process(self) -> float:
        """This process: the study's loop and file writes (main thread), the client's communication (and a
        LocalCluster's scheduler) on its event loop."""
        return self.main + self.others

    @property
    def client(self) -> float:
        """Client and scheduler, wherever the scheduler runs."""
        return self.main + self.others + self.scheduler


def timed_study(client, processes, vary, t_end, n_out, out, outputs=OUTPUTS, members_per_task=None,
                scheduler=()) -> dict:
    """One study on an existing cluster: its wall time, and CPU time of the workers (with their nannies), of the
    members' own runs (as the workers measured them), of this main thread and of this process's other threads."""
    with CpuMeter(processes, scheduler) as meter:
        ds = ln.ensemble(SCENE, vary=vary, t_end=t_end, dt=DT, n_out=n_out, client=client, out=out,
                         outputs=outputs, members_per_task=members_per_task)
    n = int(ds.sizes["member"])
    figures = {"members": n, "ok": int((ds["status"].values == "ok").sum()), "wall_s": meter.wall,
               "members_per_s": n / meter.wall, "tasks": int(ds.attrs["tasks"]),
               "first_result_s": float(ds.attrs["first_result_seconds"]), "workers_cpu_s": meter.workers,
               "member_cpu_s": float(ds.attrs["member_cpu_seconds"]), "client_main_cpu_s": meter.main,
               "client_other_cpu_s": meter.others, "scheduler_cpu_s": meter.scheduler,
               "client_write_cpu_s": float(ds.attrs["client_write_cpu_seconds"]),
               "worker_write_cpu_s": float(ds.attrs.get("worker_write_cpu_seconds", 0.0)),
               "client_written_members": int(ds.attrs.get("members_written_by_client", 0))}
    ds.close()
    if figures["ok"] != n:
        raise RuntimeError(f"{n - figures['ok']} members of the benchmark's study failed")
    return figures


def decompose(row: dict, idle: dict, costs: dict) -> dict:
    """A study's CPU time per member, by cause: the members' runs; per study, per task and idle (per second of
    wall time, from the separate measurements) on the workers and in the client and scheduler; the rest is per
    member (Dask sending and receiving the results, the client writing them)."""
    n, wall, tasks = row["members"], row["wall_s"], row["tasks"]
    client = row["client_main_cpu_s"] + row["client_other_cpu_s"] + row.get("scheduler_cpu_s", 0.0)
    parts = {"member": row["member_cpu_s"] / n,
             "workers_idle": idle["workers"] * wall / n, "workers_task": costs["workers_task_s"] * tasks / n,
             "workers_study": costs["workers_study_s"] / n,
             "client_idle": idle["client"] * wall / n, "client_task": costs["client_task_s"] * tasks / n,
             "client_study": costs["client_study_s"] / n, "client_write": row["client_write_cpu_s"] / n,
             "workers_write": row.get("worker_write_cpu_s", 0.0) / n}
    parts["workers_total"] = row["workers_cpu_s"] / n
    parts["client_total"] = client / n
    parts["workers_member"] = parts["workers_total"] - parts["member"] - parts["workers_idle"] - \
        parts["workers_task"] - parts["workers_study"]
    parts["client_member"] = parts["client_total"] - parts["client_idle"] - parts["client_task"] - parts["client_study"]
    return parts


# ---- in-process breakdown ------------------------------------------------------------------------------

def median_cpu(function, repeats: int) -> float:
    """Median thread CPU time of ``function(i)`` over i = 0 .. repeats - 1."""
    values = []
    for i in range(repeats):
        start = time.thread_time()
        function(i)
        values.append(time.thread_time() - start)
    return float(np.median(values))


def member_breakdown(scene, vary, t_end, n_out, batch: int, samples: int = 30) -> dict:
    """CPU time of each part of a member and of its batch, medians over members spread over the grid, the
    parts interleaved member by member."""
    from distributed.protocol import dumps, loads, to_serialize

    from linknet_core.ensemble.members import OUTPUTS as TRAJECTORIES, StudyRuntime, StudySpec, \
        quantities_of_interest
    from linknet_core.ensemble.parameters import member_scene
    from linknet_core.ensemble.shards import prepare_folder, write_shard
    from linknet_core.ensemble.store import StudyFile
    from linknet_core.structure.topology import analyse

    plan = make_plan(scene, vary)
    times = np.linspace(0.0, t_end, n_out)
    spec = StudySpec("bench", scene.to_dict(), plan.parameters, times, "rattle", DT, None, None, None, OUTPUTS, 10)
    runtime = StudyRuntime(spec)
    base = spec.scene
    picks = np.linspace(0, plan.n_members - 1, samples).astype(int)
    settings = [plan.setting(int(i)) for i in picks]
    built = [ln.Scene.from_dict(member_scene(base, plan.parameters, s)) for s in settings]
    pooled = built[0]
    ln.simulate(pooled, t_end, dt=DT, n_out=n_out)  # its Simulators are now in the scene's pool

    parts = {
        "serial": lambda i: serial_member(scene, settings[i]["M[11]"], settings[i]["g[3]"], t_end, n_out),
        "worker_member": lambda i: runtime.run(settings[i]),
        "scene_build": lambda i: ln.Scene.from_dict(member_scene(base, plan.parameters, settings[i])),
        # on a scene of its own, as every member's is: nothing is kept for it yet
        "structure_analysis": lambda i: analyse(ln.Scene.from_dict(built[i].to_dict())),
        "scene_copy": lambda i: ln.Scene.from_dict(built[i].to_dict()),
        # the run's Simulator and its companion's (half the step), as simulate builds them for a new scene
        "simulators": lambda i: ln.Simulator(ln.Scene.from_dict(built[i].to_dict()), method="rattle", dt=DT),
        # the integration and its companion, no construction: simulate's pooled Simulators of one scene
        "integration": lambda i: ln.simulate(pooled, t_end, dt=DT, n_out=n_out),
    }
    figures = {name: [] for name in parts}
    for i in range(len(settings)):
        for name, part in parts.items():
            start = time.thread_time()
            part(i)
            figures[name].append(time.thread_time() - start)
    out = {f"{name}_s": float(np.median(values[2:])) for name, values in figures.items()}
    # analysis and Simulators were timed on a scene rebuilt from its dict: that part is the scene's, not theirs
    copy = out.pop("scene_copy_s")
    out["structure_analysis_s"] -= copy
    out["simulators_s"] -= copy + out["structure_analysis_s"]

    result = ln.simulate(pooled, t_end, dt=DT, n_out=n_out)
    blank = runtime.blank_batch(batch)

    def bookkeeping(i):
        member = {"X": result.X, "U": result.U, "T": result.T,
                  **quantities_of_interest(result.T, result.X, 10), "error_estimate": 0.0, "error_goal": 0.0}
        for name, value in member.items():
            blank[name][i % batch] = value

    out["worker_bookkeeping_s"] = median_cpu(bookkeeping, 200)
    payload = {"first": 0, "count": batch, "outputs": runtime.blank_batch(batch), "error": [""] * batch,
               "run_seconds": np.zeros(batch), "cpu_seconds": np.zeros(batch), "worker": "tcp://127.0.0.1:1"}
    for name in payload["outputs"]:
        payload["outputs"][name][...] = 1.0
    # what a worker returns once it wrote the batch's shard: the quantities of interest, errors, times
    sharded = {**payload, "outputs": {k: v for k, v in payload["outputs"].items() if k not in TRAJECTORIES},
               "shard": "members.h5"}
    for label, result in (("", payload), ("sharded_", sharded)):
        frames = dumps({"data": to_serialize(result)})
        out[f"{label}batch_bytes_member"] = sum(len(memoryview(f).cast("B")) for f in frames) / batch
        out[f"{label}serialise_s"] = median_cpu(lambda i: dumps({"data": to_serialize(result)}), 50) / batch
        out[f"{label}deserialise_s"] = median_cpu(lambda i: loads(frames), 50) / batch
    rounds = plan.n_members // batch
    with tempfile.TemporaryDirectory() as folder:
        shard_folder = Path(folder) / "worker.shards"
        prepare_folder(shard_folder, "bench")
        out["worker_shard_write_s"] = median_cpu(
            lambda i: write_shard(shard_folder, "bench", {**payload, "first": (i % rounds) * batch}, TRAJECTORIES),
            max(rounds, 20)) / batch
        single = {**payload, "count": 1, "outputs": {k: v[:1] for k, v in payload["outputs"].items()},
                  "error": [""], "run_seconds": np.zeros(1), "cpu_seconds": np.zeros(1)}
        out["shard_task_s"] = median_cpu(lambda i: write_shard(shard_folder, "bench", {**single, "first": i},
                                                               TRAJECTORIES), 50)
    for label, result in (("client_record_s", sharded), ("client_write_s", payload)):
        with tempfile.TemporaryDirectory() as folder:
            sink = StudyFile(Path(folder) / "w.nc", spec, plan, scene)

            def write(i):
                sink.write({**result, "first": (i % rounds) * batch})

            out[label] = median_cpu(write, max(rounds, 20)) / batch
            sink.close({})
    out["batch"] = batch
    return out


def cold_start(folder) -> dict:
    """ln.ensemble(client=None, workers=1) from the call to its first finished member (the LocalCluster's start:
    scheduler, a worker process and its imports; the study's plugin; the first member) and to its end."""
    first = {}
    start = time.perf_counter()
    ds = ln.ensemble(SCENE, vary={"M[11]": [0.1, 0.2]}, t_end=T_END, dt=DT, n_out=N_OUT, workers=1,
                     out=Path(folder) / "cold.nc",
                     progress=lambda progress: first.setdefault("s", time.perf_counter() - start))
    figures = {"first_result_s": first["s"], "wall_s": time.perf_counter() - start,
               "member_s": float(np.nanmax(ds["run_seconds"].values))}
    ds.close()
    return figures


def idle_costs(client, processes, seconds: float = 4.0, scheduler=()) -> dict:
    """CPU time per second of wall time of an idle cluster: client and scheduler (heartbeats, health checks), of
    it this process's and the scheduler's process's, and the workers with their nannies."""
    time.sleep(0.5)
    with CpuMeter(processes, scheduler) as meter:
        time.sleep(seconds)
    return {"client": meter.client / meter.wall, "client_process": meter.client_process / meter.wall,
            "client_others": meter.others / meter.wall, "scheduler": meter.scheduler / meter.wall,
            "workers": meter.workers / meter.wall}


def trivial_study(client, processes, folder, members: int, idle: dict, outputs=(), scheduler=()) -> dict:
    """A study of ``members`` trivial members (one step, two output times; ``outputs`` kept), one per task: its
    CPU time beyond the idle cluster's and, on the workers, beyond the members' own runs."""
    with CpuMeter(processes, scheduler) as meter:
        ds = ln.ensemble(SCENE, vary={"M[11]": np.linspace(0.1, 0.5, members)}, t_end=DT, dt=DT, n_out=2,
                         outputs=outputs, client=client, out=Path(folder) / "trivial.nc", members_per_task=1)
    tasks, member_cpu = int(ds.attrs["tasks"]), float(ds.attrs["member_cpu_seconds"])
    ds.close()
    return {"tasks": tasks, "client": meter.client - idle["client"] * meter.wall,
            "client_process": meter.client_process - idle.get("client_process", idle["client"]) * meter.wall,
            "scheduler": meter.scheduler - idle.get("scheduler", 0.0) * meter.wall,
            "client_others": meter.others - idle.get("client_others", 0.0) * meter.wall,
            "workers": meter.workers - member_cpu - idle["workers"] * meter.wall, "wall": meter.wall}


def fixed_and_task_costs(client, processes, folder, idle: dict, outputs=(), repeats: int = 3, scheduler=()) -> dict:
    """What a study costs whatever its size (F: the file's layout, the plugin on every worker, the dataset opened
    at the end; with trajectories, their shard folder and the join) and per task (k: submit, scheduling, the
    result's fetch and release, the batch's record; with trajectories, the worker's shard file), in the client and
    scheduler and in the workers: from studies of 2 and of 200 trivial members, one per task (F + 2 k and
    F + 200 k), keeping ``outputs``, medians of ``repeats``."""
    small, large = [], []
    for _ in range(repeats):
        small.append(trivial_study(client, processes, folder, 2, idle, outputs, scheduler))
        large.append(trivial_study(client, processes, folder, 200, idle, outputs, scheduler))
    out = {}
    for side in ("client", "client_process", "client_others", "scheduler", "workers"):
        a = float(np.median([r[side] for r in small]))
        b = float(np.median([r[side] for r in large]))
        task = (b - a) / (large[0]["tasks"] - small[0]["tasks"])
        out[f"{side}_task_s"], out[f"{side}_study_s"] = task, a - small[0]["tasks"] * task
    out["wall_task_s"] = float(np.median([r["wall"] for r in large])) / large[0]["tasks"]
    return out


def per_member_costs(client, processes, folder, idle: dict, costs: dict, outputs, members: int = 2000,
                     per_task: int = 200, repeats: int = 5, scheduler=()) -> dict:
    """CPU time per member beyond its own run, per study, per task and idle: on the workers (d: writing the
    member's shard, Dask sending the rest of its result) and in the client and scheduler (c: receiving it,
    recording it in the file). From
    a study of short members (t_end 0.2 s: one step per output interval, the same 201 outputs) in batches of
    ``per_task``: the per-member part is a large share of its CPU time there, and the study is over before the
    machine's load moves much. Medians of ``repeats``."""
    vary = {"M[11]": np.linspace(0.05, 0.5, members)}
    figures = []
    for _ in range(repeats):
        with CpuMeter(processes, scheduler) as meter:
            ds = ln.ensemble(SCENE, vary=vary, t_end=0.2, dt=DT, n_out=N_OUT, outputs=outputs, client=client,
                             out=Path(folder) / "short.nc", members_per_task=per_task)
        tasks, member_cpu = int(ds.attrs["tasks"]), float(ds.attrs["member_cpu_seconds"])
        shard_cpu = float(ds.attrs.get("worker_write_cpu_seconds", 0.0))
        ds.close()
        client_cpu = meter.client - idle["client"] * meter.wall - costs["client_study_s"] - \
            costs["client_task_s"] * tasks
        workers_cpu = meter.workers - member_cpu - idle["workers"] * meter.wall - costs["workers_study_s"] - \
            costs["workers_task_s"] * tasks
        figures.append((client_cpu / members, workers_cpu / members, shard_cpu / members))
    c, d, shard = np.median(figures, axis=0)
    return {"client_member_s": float(c), "workers_member_s": float(d), "workers_shard_s": float(shard)}


def client_all_in(client, processes, folder, members: int = 4000, per_task: int = 500, repeats: int = 3,
                  scheduler=()) -> dict:
    """The client's and scheduler's CPU time per member with nothing taken off but the idle cluster's, in studies
    shaped like a 100-worker one's (short members, ``per_task`` to a task), with X, U, T and with the quantities of
    interest only: a check of c + k_c / B that does not rest on the per-task and per-study calibrations (it
    includes them, over this many members). Medians of ``repeats``."""
    vary = {"M[11]": np.linspace(0.05, 0.5, members)}
    rows: dict = {}
    for _ in range(repeats):
        for name, outputs in (("outputs", OUTPUTS), ("qoi_only", ())):
            with CpuMeter(processes, scheduler) as meter:
                ds = ln.ensemble(SCENE, vary=vary, t_end=0.2, dt=DT, n_out=N_OUT, outputs=outputs, client=client,
                                 out=Path(folder) / "allin.nc", members_per_task=per_task)
            ds.close()
            rows.setdefault(name, []).append((meter.client / members, members / meter.wall))
    return {name: {"client_s": float(np.median([r[0] for r in v])), "members_per_s": float(np.median([r[1] for r in v])),
                   "members": members, "per_task": per_task} for name, v in rows.items()}


# ---- projection ----------------------------------------------------------------------------------------

def heartbeats_per_second(workers: int) -> float:
    from distributed.scheduler import heartbeat_interval

    return workers / heartbeat_interval(workers)


GIL_HANDOFFS_PER_TASK = 2  # the study's thread waits on the event loop for a task's result, and for its submit


def client_turnaround(client_task: float, client_member: float, idle_client: float, batch: float,
                      loop_busy: float) -> float:
    """Wall time the client's process takes to turn one task over (fetch its result, record it, submit the next):
    its CPU time per task and per member, slowed by the share of its core its idle upkeep takes, and the GIL's
    hand-offs between the study's thread and the event-loop thread (GIL_HANDOFFS_PER_TASK): a thread that wants
    the GIL while the other runs Python waits ``sys.getswitchinterval()`` (5 ms) before it may take it, so each
    hand-off costs that times ``loop_busy``, the share of the time the event-loop thread runs (a LocalCluster's
    scheduler runs there: then it is busy most of the time)."""
    handoffs = GIL_HANDOFFS_PER_TASK * sys.getswitchinterval() * min(max(loop_busy, 0.0), 1.0)
    return (client_task + batch * client_member) / max(1.0 - idle_client, 1e-3) + handoffs


def projection(s: float, m: float, worker_member: float, client_member: float, costs: dict, idle: dict,
               member_bytes: int) -> dict:
    """Members per second on N single-threaded workers with a core each; the client's process and the scheduler's
    each on a core of their own (ln.ensemble's local cluster), or sharing one and its GIL (a LocalCluster's):

        rate(N) = min( N (1 - i_w) / (m + d + k_w / B),         the workers
                       B / ((k_c + B c) / (1 - i_c) + h),        the client's process, one task at a time
                       B (1 - i_s) / k_s )                       the scheduler's process

    m: a member's own CPU time on a worker; d: the worker's per member beyond it (its result, its shard write);
    c: the client's per member (receiving and recording its result); k_w, k_c, k_s: per task, on the worker, in
    the client's process and in the scheduler's (with the scheduler in the client's process, k_c holds its part
    and there is no third bound); i_w, i_c, i_s: the share of a core the idle worker, client process and scheduler
    take; h: the GIL's switch interval (client_turnaround); B(N): the members per task the study chooses on N
    threads (engine._BatchSizer, without the first single-member tasks and the last shrinking ones). Against N
    times the serial loop's rate 1 / s."""
    from linknet_core.ensemble.engine import MAX_TASK_BYTES, MAX_TASKS_PER_SECOND, TASK_SECONDS

    separate = "scheduler_task_s" in costs and idle.get("separate_scheduler", False)
    k_c = costs["client_process_task_s"] if separate else costs["client_task_s"]
    rows = {}
    for n in PROJECTED_WORKERS:
        batch = max(1, min(int(max(TASK_SECONDS, n / MAX_TASKS_PER_SECOND) / m), MAX_TASK_BYTES // member_bytes))
        idle_client = idle["client_process"] if separate else idle["a"] + idle["b"] * heartbeats_per_second(n)
        workers_rate = n * (1 - idle["worker"]) / (m + worker_member + costs["workers_task_s"] / batch)
        # the event loop's share of the time at the workers' pace (an upper bound on the tasks per second)
        loop_busy = idle.get("client_others", 0.0) + workers_rate / batch * costs.get("client_others_task_s", 0.0)
        client_rate = batch / client_turnaround(k_c, client_member, idle_client, batch, loop_busy)
        scheduler_rate = batch * (1 - idle["scheduler"]) / max(costs["scheduler_task_s"], 1e-9) if separate else math.inf
        rate = min(workers_rate, client_rate, scheduler_rate)
        bound = {workers_rate: "workers", client_rate: "the client's process", scheduler_rate: "the scheduler"}[rate]
        rows[n] = {"members_per_task": batch, "idle_client": idle_client, "workers_rate": workers_rate,
                   "client_rate": client_rate, "scheduler_rate": scheduler_rate, "rate": rate, "ratio": rate * s / n,
                   "bound_by": bound}
    return rows


def explain(results: dict) -> dict:
    """The model against each study of a run: its wall time predicted from the run's own figures,

        wall = t_first + max( W / N,  tasks x t_c,  tasks x k_s / (1 - i_s),  (W + C) / cores )

    W: the workers' CPU time in the study (the members' runs as they ran there, with what each worker paid per
    member and per task), t_c: client_turnaround (the per-task and per-member costs and the idle share from the
    run's calibrations, B the study's members per task), the scheduler's bound where it has a process of its own,
    t_first: the study's time to its first result (its start); C: the client's and scheduler's CPU time in the
    study, so that the last bound is the machine's cores shared by all (other jobs' load is not in it); the event loop's share of the time in
    client_turnaround is the study's own (its other threads' CPU time over its wall time). Printed and returned per cluster size: medians over
    rounds of the measured and predicted wall times and of the ratios against the serial loop they give."""
    rounds, idle = results["rounds"], results["idle"]
    costs = results.get("costs_outputs", results["costs"])
    c = max(results["member_costs"]["outputs"]["client_member_s"], 0.0)
    serial = rounds["serial"]
    out = {}
    print("Model against the run's studies (wall time per study, s; ratio against the serial loop, from the same round):")
    print("| workers | tasks | B | W / N | tasks x t_c | tasks x t_s | (W + C) / cores | first result | wall, predicted "
          "| wall, measured | ratio, predicted | ratio, measured | bound |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for n in results["workers"]:
        rows = rounds[f"workers_{n}"]
        figures = []
        for row, base in zip(rows, serial):
            idle_n = idle[str(n)] if str(n) in idle else idle[n]
            separate = row.get("scheduler_cpu_s", 0.0) > 0 and "client_process_task_s" in costs
            batch = row["members"] / row["tasks"]
            loop_busy = row["client_other_cpu_s"] / row["wall_s"]  # the event-loop thread's share, in this study
            if separate:
                t_c = client_turnaround(costs["client_process_task_s"], c, idle_n["client_process"], batch, loop_busy)
                t_s = costs["scheduler_task_s"] / max(1 - idle_n["scheduler"], 1e-3)
            else:  # the scheduler on the client's GIL: its part is in the client's figures
                t_c, t_s = client_turnaround(costs["client_task_s"], c, idle_n["client"], batch, loop_busy), 0.0
            everything = row["workers_cpu_s"] + row["client_main_cpu_s"] + row["client_other_cpu_s"] + \
                row.get("scheduler_cpu_s", 0.0)
            bounds = {"workers": row["workers_cpu_s"] / n, "client": row["tasks"] * t_c, "scheduler": row["tasks"] * t_s,
                      "cores": everything / (results.get("cores") or 1)}
            predicted = row["first_result_s"] + max(bounds.values())
            per_member = base["wall_s"] / base["members"]
            figures.append({"B": batch, **bounds, "first": row["first_result_s"], "predicted": predicted,
                            "measured": row["wall_s"], "ratio_predicted": per_member * row["members"] / predicted,
                            "ratio_measured": per_member * row["members"] / row["wall_s"],
                            "bound": max(bounds, key=bounds.get), "tasks": row["tasks"]})
        med = {key: float(np.median([f[key] for f in figures])) for key in figures[0] if key != "bound"}
        med["bound"] = max(("workers", "client", "scheduler", "cores"), key=lambda k: sum(f["bound"] == k for f in figures))
        out[n] = med
        print(f"| {n} | {med['tasks']:.0f} | {med['B']:.1f} | {med['workers']:.2f} | {med['client']:.2f} | "
              f"{med['scheduler']:.2f} | {med['cores']:.2f} | {med['first']:.2f} | {med['predicted']:.2f} | {med['measured']:.2f} | "
              f"{med['ratio_predicted']:.2f} | {med['ratio_measured']:.2f} | {med['bound']} |")
    return out


# ---- the run -------------------------------------------------------------------------------------------

def quick(args) -> int:
    """CI's smoke test: a short study on a 1-worker LocalCluster, every member bit-identical to its serial run,
    and nothing on stderr from Dask."""
    scene = ln.load_scene(SCENE)
    vary = {"M[11]": np.linspace(0.05, 0.5, 4), "g[3]": np.linspace(-9.81, -1.0, 4)}
    t_end, n_out = 0.2, 21
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", AccuracyWarning)
        ds = ln.ensemble(SCENE, vary=vary, t_end=t_end, dt=DT, n_out=n_out, workers=1)
        for m, (mass, gravity) in enumerate(member_settings(vary)):
            reference = serial_member(scene, mass, gravity, t_end, n_out)
            for name in OUTPUTS:
                if not np.array_equal(ds[name].values[m], getattr(reference, name)):
                    raise AssertionError(f"member {m}: {name} differs from its serial ln.simulate run")
            if ds["error_estimate"].values[m] != reference.max_error_estimate:
                raise AssertionError(f"member {m}: its error estimate differs from its serial run's")
    if ds.attrs["members_written_by_workers"] != ds.sizes["member"]:
        raise AssertionError(f"the worker wrote the trajectories of {ds.attrs['members_written_by_workers']} of "
                             f"{ds.sizes['member']} members (their shards), the client the others")
    print(f"bench_ensemble --quick: {ds.sizes['member']} members on 1 worker, each bit-identical to its serial "
          "ln.simulate run, their trajectories written by the worker")
    return 0


class Phases:
    """Wall time of each phase of the run, said on stderr as each ends and kept for the report."""

    def __init__(self):
        self.seconds: dict[str, float] = {}
        self._start = time.perf_counter()

    def __call__(self, name: str):
        phases = self

        class _Phase:
            def __enter__(self):
                self.start = time.perf_counter()

            def __exit__(self, *exc):
                spent = time.perf_counter() - self.start
                phases.seconds[name] = phases.seconds.get(name, 0.0) + spent
                print(f"  [{name}: {spent:.1f} s, {time.perf_counter() - phases._start:.0f} s so far]", file=sys.stderr)

        return _Phase()


def serial_subset(vary: dict, members: int) -> list[tuple[float, float]]:
    """``members`` members of the grid, evenly spread over it (the serial loop's baseline on fewer members than the
    studies: its figure is a time per member)."""
    settings = member_settings(vary)
    if members >= len(settings):
        return settings
    return [settings[int(i)] for i in np.linspace(0, len(settings) - 1, members).round()]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="CI smoke test: correctness of a short study only")
    p.add_argument("--workers", default="1,2", help="comma-separated cluster sizes (default 1,2): only these start")
    p.add_argument("--members", type=int, default=1000)
    p.add_argument("--serial-members", type=int, default=None,
                   help="members of the serial loop's baseline in each round, spread over the grid (default: the "
                        "studies' members, at most 1000); its figure is a time per member")
    p.add_argument("--rounds", type=int, default=5, help="rounds of serial loop and studies, interleaved")
    p.add_argument("--members-per-task", type=int, default=None, help="fixed batch size (default: the study's)")
    p.add_argument("--client-check", action="store_true",
                   help="also the client's CPU time per member with only the idle cluster's taken off, in studies of "
                        "4000 short members, 500 to a task (as at 100 workers)")
    p.add_argument("--explain", metavar="JSON", default=None,
                   help="print the model's fit to the studies of an earlier run's JSON (wall time predicted against "
                        "measured, per study) and stop")
    p.add_argument("--out", help="results (JSON; default build/bench_ensemble.json); not inside docs/")
    args = p.parse_args(argv)
    out = build_path("bench_ensemble.json", args.out, parser=p)
    if args.quick:
        return quick(args)
    if args.explain:
        explain(json.loads(Path(args.explain).read_text()))
        return 0
    try:
        sizes = sorted({int(w) for w in args.workers.split(",") if w.strip()})
    except ValueError:
        p.error(f"--workers must be comma-separated whole numbers, got {args.workers!r}")
    if not sizes or min(sizes) < 1:
        p.error("--workers needs at least one size, each at least 1")
    if args.serial_members is not None and args.serial_members < 1:
        p.error("--serial-members must be at least 1")
    warnings.simplefilter("ignore", AccuracyWarning)  # the serial loop's; a study warns once, on the client
    phase = Phases()
    scene = ln.load_scene(SCENE)
    vary = study_grid(args.members)
    n_members = len(member_settings(vary))
    serial_settings = serial_subset(vary, args.serial_members or min(n_members, 1000))
    results: dict = {"scene": "chain_10", "t_end": T_END, "dt": DT, "n_out": N_OUT,
                     "members": n_members, "serial_members": len(serial_settings), "cores": os.cpu_count(),
                     "workers": sizes, "load_before": os.getloadavg()[0], "python": sys.version.split()[0]}
    qoi_size = 2 if 2 in sizes else sizes[-1]
    with phase("cold start"), tempfile.TemporaryDirectory() as folder:  # first: no other worker process around yet
        results["cold"] = cold_start(folder)
    clusters = {}
    try:
        with phase("clusters start"):
            for n in sizes:
                clusters[n] = local_cluster(n)
            processes = {n: cluster_processes(client) for n, (_, client) in clusters.items()}
            schedulers = {n: scheduler_processes(client) for n, (_, client) in clusters.items()}
        rounds: dict[str, list] = {"serial": [], **{f"workers_{n}": [] for n in sizes}, "workers_qoi_only": []}
        qoi = (clusters[qoi_size][1], processes[qoi_size])
        with tempfile.TemporaryDirectory() as folder:
            with phase("warm"):
                for n, (_, client) in clusters.items():  # imports, the study's code on every worker
                    ln.ensemble(SCENE, vary={"M[11]": [0.1, 0.2, 0.3, 0.4]}, t_end=0.05, dt=DT, n_out=11,
                                client=client, out=Path(folder) / "warm.nc").close()
            for r in range(args.rounds):
                with phase("serial loops"):
                    rounds["serial"].append(serial_loop(scene, serial_settings, T_END, N_OUT))
                for n, (_, client) in clusters.items():
                    with phase(f"studies, {n} worker(s)"):
                        rounds[f"workers_{n}"].append(timed_study(client, processes[n], vary, T_END, N_OUT,
                                                                  Path(folder) / "s.nc",
                                                                  members_per_task=args.members_per_task,
                                                                  scheduler=schedulers[n]))
                with phase(f"studies, {qoi_size} worker(s), quantities of interest only"):
                    rounds["workers_qoi_only"].append(timed_study(*qoi, vary, T_END, N_OUT, Path(folder) / "q.nc",
                                                                  outputs=(), members_per_task=args.members_per_task,
                                                                  scheduler=schedulers[qoi_size]))
                print(f"  round {r + 1}/{args.rounds}: serial {rounds['serial'][-1]['members_per_s']:.1f}/s, "
                      + ", ".join(f"{n} worker(s) {rounds[f'workers_{n}'][-1]['members_per_s']:.1f}/s" for n in sizes),
                      file=sys.stderr)
            with phase("idle clusters"):
                results["idle"] = {n: idle_costs(client, processes[n], scheduler=schedulers[n])
                                   for n, (_, client) in clusters.items()}
            idle_qoi, scheduler_qoi = results["idle"][qoi_size], schedulers[qoi_size]
            with phase("per-task and per-study costs"):
                # with the quantities of interest only, and with X, U, T (a shard per task)
                results["costs"] = fixed_and_task_costs(*qoi, folder, idle_qoi, scheduler=scheduler_qoi)
                results["costs_outputs"] = fixed_and_task_costs(*qoi, folder, idle_qoi, OUTPUTS, scheduler=scheduler_qoi)
            if args.client_check:
                with phase("client check"):
                    results["client_all_in"] = client_all_in(*qoi, folder, scheduler=scheduler_qoi)
            with phase("per-member costs"):
                results["member_costs"] = {
                    name: per_member_costs(*qoi, folder, idle_qoi, results[key], outputs, scheduler=scheduler_qoi)
                    for name, key, outputs in (("outputs", "costs_outputs", OUTPUTS), ("qoi_only", "costs", ()))}
    finally:
        with phase("clusters close"):
            # the last started first: each cluster restores, when it closes, the log level it found when it started,
            # so closing the first one first would let the others' shutdown messages through
            for cluster, client in reversed(clusters.values()):
                with quiet_shutdown(client):
                    client.close()
                    cluster.close()
    results["rounds"] = rounds
    streamed = sum(r.get("client_written_members", 0) for rows in rounds.values() for r in rows)
    if streamed:  # the workers did not see the study's folder (they would on a local cluster): said, not hidden
        print(f"note: the client wrote the trajectories of {streamed} members (their workers did not)", file=sys.stderr)
    typical = rounds[f"workers_{sizes[-1]}"][-1]
    batch = max(1, round(typical["members"] / max(typical["tasks"], 1)))
    with phase("in-process breakdown"):
        results["breakdown"] = member_breakdown(scene, vary, T_END, N_OUT, batch=batch)
    results["load_after"] = os.getloadavg()[0]
    results["phases_s"] = phase.seconds
    report(results, sizes, qoi_size)
    print()
    print("Wall time of each phase: " + ", ".join(f"{name} {seconds:.1f} s" for name, seconds in phase.seconds.items())
          + f"; {time.perf_counter() - phase._start:.0f} s in all")
    write_text(out, json.dumps(results, indent=1) + "\n")
    print(f"wrote {out}")
    return 0


def _median(rows, key):
    return float(np.median([r[key] for r in rows]))


def _idle_model(idle: dict) -> dict:
    """i_c(N) = a + b h(N) from the idle client's CPU time per second at the cluster sizes measured, and a
    worker's share i_w (their mean per worker)."""
    sizes = sorted(idle)
    hb = [heartbeats_per_second(n) for n in sizes]
    values = [idle[n]["client"] for n in sizes]
    if len(sizes) > 1 and hb[-1] > hb[0]:
        b = max((values[-1] - values[0]) / (hb[-1] - hb[0]), 0.0)
    else:
        b = values[0] / hb[0]  # one size: all of it taken as per heartbeat (the pessimistic reading)
    a = max(values[0] - b * hb[0], 0.0)
    worker = float(np.mean([idle[n]["workers"] / n for n in sizes]))
    # the client's process and the scheduler's apart, where the scheduler has a process of its own: the largest
    # share measured over the sizes
    separate = all(idle[n].get("scheduler", 0.0) > 0 for n in sizes)
    return {"a": a, "b": b, "worker": worker, "separate_scheduler": separate,
            "client_process": max(idle[n].get("client_process", idle[n]["client"]) for n in sizes),
            "scheduler": max(idle[n].get("scheduler", 0.0) for n in sizes),
            "client_others": max(idle[n].get("client_others", 0.0) for n in sizes)}


def report(results: dict, sizes: list[int], qoi_size: int) -> None:
    ms = 1e3
    rounds = results["rounds"]
    serial = rounds["serial"]
    s = _median(serial, "cpu_member_s")
    names = [f"workers_{n}" for n in sizes] + ["workers_qoi_only"]
    size_of = {**{f"workers_{n}": n for n in sizes}, "workers_qoi_only": qoi_size}
    print(f"chain_10, {results['members']} members (the serial loop {results.get('serial_members', results['members'])} "
          f"of them), t_end {T_END:g} s, rattle dt {DT:g}, {N_OUT} outputs of X, U, T; "
          f"{results['cores']} cores, load average {results['load_before']:.1f} -> {results['load_after']:.1f}; "
          f"{len(serial)} rounds, interleaved")
    print()
    print("| | members/s (median, range) | against serial, wall (median, range) | against serial, CPU time | tasks |")
    print("|---|---|---|---|---|")
    print(f"| serial loop (`ln.simulate` per member) | {_median(serial, 'members_per_s'):.1f} "
          f"({min(r['members_per_s'] for r in serial):.1f}-{max(r['members_per_s'] for r in serial):.1f}) | 1.00 | "
          f"1.00 ({s * ms:.2f} ms per member) | |")
    results["ratios"] = {}
    cores = results["cores"] or 1
    for name in names:
        rows, n = rounds[name], size_of[name]
        ratios = [a["wall_s"] / a["members"] / (b["wall_s"] / b["members"]) for a, b in zip(serial, rows)]
        worker = _median(rows, "workers_cpu_s") / rows[0]["members"]
        client = float(np.median([r["client_main_cpu_s"] + r["client_other_cpu_s"] for r in rows])) / rows[0]["members"]
        scheduler = float(np.median([r.get("scheduler_cpu_s", 0.0) for r in rows])) / rows[0]["members"]
        # each worker, the client's process and the scheduler's a core of their own, or all sharing the cores
        cpu_ratio = min(n / worker, 1 / client, 1 / max(scheduler, 1e-12), cores / (worker + client + scheduler)) * s
        label = f"{n} worker(s)" if name != "workers_qoi_only" else f"{n} workers, quantities of interest only"
        results["ratios"][name] = {"wall_median": float(np.median(ratios)), "wall_min": min(ratios),
                                   "wall_max": max(ratios), "cpu": cpu_ratio}
        print(f"| {label} | {_median(rows, 'members_per_s'):.1f} ({min(r['members_per_s'] for r in rows):.1f}-"
              f"{max(r['members_per_s'] for r in rows):.1f}) | {np.median(ratios):.2f} ({min(ratios):.2f}-"
              f"{max(ratios):.2f}) | {cpu_ratio:.2f} | {_median(rows, 'tasks'):.0f} |")
    idle, costs = results["idle"], results["costs"]
    print()
    print("CPU time per member in the studies, by cause (ms; medians over rounds; idle, per task and per study from the "
          "separate measurements below, per member the rest):")
    print("| | workers, all | members' runs | per member (Dask, shard writes) | of it shard writes | per task | idle | "
          "per study | client and scheduler, all | per member | of it file writes | per task | idle | per study |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    results["decomposed"] = {}
    for name in names:
        # each study's per-task and per-study costs measured with its own outputs
        kind_costs = costs if name == "workers_qoi_only" else results.get("costs_outputs", costs)
        parts = [decompose(r, idle[size_of[name]], kind_costs) for r in rounds[name]]
        med = {key: float(np.median([p[key] for p in parts])) for key in parts[0]}
        results["decomposed"][name] = med
        print(f"| {name} | " + " | ".join(f"{med[key] * ms:.3f}" for key in (
            "workers_total", "member", "workers_member", "workers_write", "workers_task", "workers_idle", "workers_study",
            "client_total", "client_member", "client_write", "client_task", "client_idle", "client_study")) + " |")
    b = results["breakdown"]
    print()
    print("Per-member CPU time by part, in one process (ms, medians over 28 members, the parts interleaved):")
    print("| part | ms |")
    print("|---|---|")
    rows = [("serial loop's member (`with_parameters` + `ln.simulate`)", b["serial_s"]),
            ("a worker's member (`StudyRuntime.run`: scene from its values, `ln.simulate`, quantities of interest)",
             b["worker_member_s"]),
            ("  scene from the member's values (`member_scene` + `Scene.from_dict`)", b["scene_build_s"]),
            ("  structure analysis of the new scene (`analyse`)", b["structure_analysis_s"]),
            ("  Simulator construction, run and companion, beyond the analysis", b["simulators_s"]),
            ("  integration with its companion, and the error estimate (pooled Simulators)", b["integration_s"]),
            ("worker bookkeeping (quantities of interest, copy into the batch)", b["worker_bookkeeping_s"]),
            (f"worker's shard write (batches of {b['batch']}; {b['shard_task_s'] * ms:.2f} ms for a 1-member shard)",
             b["worker_shard_write_s"]),
            (f"serialise a batch's result, its shard written (Dask's protocol; "
             f"{b['sharded_batch_bytes_member']:.0f} bytes per member)", b["sharded_serialise_s"]),
            ("deserialise it on the client", b["sharded_deserialise_s"]),
            (f"client's record of it in the study file (batches of {b['batch']})", b["client_record_s"]),
            (f"where the worker does not write the shard: serialise the batch's result with its trajectories "
             f"({b['batch_bytes_member'] / 1e3:.0f} kB per member)", b["serialise_s"]),
            ("  deserialise it on the client", b["deserialise_s"]),
            (f"  client's shard write and record (batches of {b['batch']})", b["client_write_s"])]
    for label, seconds in rows:
        print(f"| {label} | {seconds * ms:.3f} |")
    print()
    costs_outputs = results.get("costs_outputs", costs)
    print(f"Per task (studies of trivial members, one per task, {qoi_size} workers), quantities of interest only: "
          f"k_c = {costs['client_task_s'] * ms:.2f} ms CPU in client and scheduler, k_w = "
          f"{costs['workers_task_s'] * ms:.2f} ms in the workers ({costs['wall_task_s'] * ms:.2f} ms wall per task); "
          f"with X, U, T (a shard per task): k_c = {costs_outputs['client_task_s'] * ms:.2f} ms, k_w = "
          f"{costs_outputs['workers_task_s'] * ms:.2f} ms ({costs_outputs['wall_task_s'] * ms:.2f} ms wall). Per study: "
          f"{costs['client_study_s'] * ms:.0f} / {costs_outputs['client_study_s'] * ms:.0f} ms in client and scheduler, "
          f"{costs['workers_study_s'] * ms:.0f} / {costs_outputs['workers_study_s'] * ms:.0f} ms in the workers. Idle "
          "cluster, CPU time per second: " + ", ".join(
              f"{n} worker(s): {v['client'] * ms:.1f} ms client and scheduler, {v['workers'] * ms:.1f} ms workers"
              for n, v in idle.items()))
    cold = results["cold"]
    print(f"Cold start (ln.ensemble with client=None, 1 worker, 2 members): first result after "
          f"{cold['first_result_s']:.2f} s (the member itself {cold['member_s'] * ms:.1f} ms on its worker), "
          f"{cold['wall_s']:.2f} s to the end (the LocalCluster closed).")
    model = _idle_model(idle)
    results["idle_model"] = model
    # a member's own CPU time and the serial loop's, both from the in-process breakdown: one measurement, without
    # the contention of the studies' processes (which inflates a member's CPU time on this machine's 2 cores)
    m, s_alone = b["worker_member_s"], b["serial_s"]
    results["projection"] = {}
    print()
    print("Per member beyond its run (studies of 2000 members of 0.2 s, the same outputs, 200 per task, 5 repeats; "
          "per study, per task (each with the same outputs) and idle taken off): " + "; ".join(
              f"{label}: d = {v['workers_member_s'] * ms:.3f} ms on the workers (of it shard writes "
              f"{v.get('workers_shard_s', 0.0) * ms:.3f}), c = {v['client_member_s'] * ms:.3f} ms in "
              "client and scheduler" for label, v in (("X, U, T", results["member_costs"]["outputs"]),
                                                      ("quantities of interest only", results["member_costs"]["qoi_only"]))))
    if "client_all_in" in results:
        idle_client = idle[qoi_size]["client"]
        print()
        print("Check (--client-check): the client's and scheduler's CPU time per member, studies of 4000 members of "
              "0.2 s in tasks of 500, per study and per task included: " + "; ".join(
                  f"{label}: {v['client_s'] * ms:.3f} ms, of which the idle cluster's {idle_client / v['members_per_s'] * ms:.3f} "
                  f"({v['members_per_s']:.0f} members/s), the rest {(v['client_s'] - idle_client / v['members_per_s']) * ms:.3f}"
                  for label, v in (("X, U, T", results["client_all_in"]["outputs"]),
                                   ("quantities of interest only", results["client_all_in"]["qoi_only"]))))
    for label, name, outputs, kind_costs in (
            ("X, U, T written by the workers (shards)", "outputs", OUTPUTS, costs_outputs),
            ("quantities of interest only", "qoi_only", (), costs)):
        per_member = results["member_costs"][name]
        d, c = max(per_member["workers_member_s"], 0.0), max(per_member["client_member_s"], 0.0)
        member_bytes = 8 * N_OUT * sum({"X": 33, "U": 33, "T": 10}[o] for o in outputs) + 100
        rows_p = projection(s_alone, m, d, c, kind_costs, model, member_bytes)
        results["projection"][name] = rows_p
        print()
        print(f"Projection, {label}: s = {s_alone * ms:.3f} ms, m = {m * ms:.3f} ms, d = {d * ms:.3f} ms, "
              f"c = {c * ms:.3f} ms, k_w = {kind_costs['workers_task_s'] * ms:.2f} ms, k_c = "
              f"{kind_costs['client_task_s'] * ms:.2f} ms, i_w = {model['worker'] * 100:.1f} %, i_c(N) = "
              f"{model['a'] * 100:.2f} % + {model['b'] * 100:.3f} % per heartbeat per second")
        if model["separate_scheduler"]:
            print(f"  the scheduler in its own process: k_c = {kind_costs['client_process_task_s'] * ms:.2f} ms in the "
                  f"client's process, k_s = {kind_costs['scheduler_task_s'] * ms:.2f} ms in the scheduler's; i_c = "
                  f"{model['client_process'] * 100:.1f} %, i_s = {model['scheduler'] * 100:.1f} %; h = "
                  f"{sys.getswitchinterval() * ms:.0f} ms")
        print("| workers | members per task | i_c | workers' rate | client's rate | scheduler's rate | members/s "
              "| against N x serial | bound by |")
        print("|---|---|---|---|---|---|---|---|---|")
        for n, row in rows_p.items():
            print(f"| {n} | {row['members_per_task']} | {row['idle_client'] * 100:.1f} % | {row['workers_rate']:.0f}/s | "
                  f"{row['client_rate']:.0f}/s | {row['scheduler_rate']:.0f}/s | {row['rate']:.0f} | {row['ratio']:.2f} | "
                  f"{row['bound_by']} |")
    print()
    results["explained"] = explain(results)


if __name__ == "__main__":
    raise SystemExit(main())
