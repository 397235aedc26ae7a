"""Ensembles on Dask: throughput, scaling, per-member overhead, time to first result (measure; never asserted).

Study: chain_10 (models/chain_10.json), 1000 members varying the tip mass M[11] and gravity g[3] (a 40 x 25
grid), t_end = 2 s, RATTLE at dt = 1e-3 s, 201 outputs of X, U, T per member streamed into a netCDF file.

1. bare: each member's ``Simulator`` run in this process, serially (scene built with the member's values,
   Simulator construction, 200 advance + 201 outputs calls): the work a member must do anyway.
2. LocalCluster with 1 and with 2 worker processes (started, and warmed with a 4-member study, outside the
   timed span; the study run 3 times on each, alternating, best of 3): members per second, scaling efficiency
   = rate(2) / (2 rate(1)), the per-member overhead (1-worker wall time per member minus the bare time), and
   the CPU time per member spent in the workers and in this process (client, and the LocalCluster's
   scheduler), which unlike wall time does not depend on what else runs on the machine; the same study on 2
   workers keeping only the quantities of interest (outputs=[]) shows what streaming X, U, T costs.
3. Cold start: ``ln.ensemble(client=None, workers=1)`` from the call to its first finished member (cluster
   start, worker process start and imports, the study's plugin, the first member), and the first member's own
   time on its worker.
4. What a bigger cluster would feel: the scheduler's cost per task (2000 empty tasks), and the client's cost
   per member streamed into the file (StudyFile.write of 1000 members' X, U, T, without Dask).

    python -m benchmarks.bench_ensemble [--quick] [--members 1000] [--rounds 3] [--out build/bench_ensemble.json]

--quick: 40 members of 0.2 s, checks one member against its serial run, prints the same table (a smoke test).
"""
from __future__ import annotations

import argparse
import json
import logging
import os
import resource
import tempfile
import time
from pathlib import Path

import numpy as np

import linknet_core as ln
from linknet_core.ensemble import make_plan

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "models" / "chain_10.json"


def study_grid(members: int) -> dict:
    """About ``members`` members as a grid of tip mass x gravity (40 x 25 for 1000)."""
    n_mass = max(2, int(round(np.sqrt(members * 40 / 25))))
    n_g = max(1, members // n_mass)
    return {"M[11]": np.linspace(0.05, 0.5, n_mass), "g[3]": np.linspace(-9.81, -1.0, n_g)}


def cpu_seconds() -> float:
    """CPU time of this process (user + system): unlike wall time, it does not grow when other jobs share the
    cores."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


def bare_and_study_member(scene, vary, t_end, dt, n_out, samples=40) -> dict:
    """One member's work done directly with the library (bare), and the same member as a worker runs it
    (StudyRuntime.run: the member's scene from its values, the Simulator run, outputs kept, quantities of
    interest), interleaved in this process: medians of wall and CPU time."""
    from linknet_core.ensemble.members import StudyRuntime, StudySpec

    plan = make_plan(scene, vary)
    times = np.linspace(0.0, t_end, n_out)
    spec = StudySpec("bench", scene.to_dict(), plan.parameters, times, "rattle", dt, None, None, None,
                     ("X", "U", "T"), 10)
    runtime = StudyRuntime(spec)

    def bare(setting):
        mass = np.array(scene.mass)
        mass[10] = setting["M[11]"]
        member = scene.with_parameters(mass=mass, gravity=[0.0, 0.0, setting["g[3]"]])
        sim = ln.Simulator(member, method="rattle", dt=dt)
        for k, t in enumerate(times):
            if k:
                sim.advance(t)
            sim.outputs()

    figures = {"bare": [], "bare_cpu": [], "study": [], "study_cpu": []}
    for i in np.linspace(0, plan.n_members - 1, samples).astype(int):
        setting = plan.setting(int(i))
        for name, run in (("bare", bare), ("study", runtime.run)):
            wall, cpu = time.perf_counter(), cpu_seconds()
            run(setting)
            figures[name].append(time.perf_counter() - wall)
            figures[name + "_cpu"].append(cpu_seconds() - cpu)
    return {f"{name}_member_s": float(np.median(values[2:])) for name, values in figures.items()}


def timed_study(client, vary, t_end, dt, n_out, out, workers=None, outputs=("X", "U", "T")) -> dict:
    """Wall time of a study from the call to its end and to its first finished member; with a given
    client also the CPU time its workers and this process (client and, for a LocalCluster, the scheduler)
    spent on it."""
    first = {}

    def worker_cpu():
        if client is None:
            return 0.0
        return sum(client.run(lambda: sum(resource.getrusage(resource.RUSAGE_SELF)[:2])).values())

    workers_before, client_before = worker_cpu(), cpu_seconds()
    start = time.perf_counter()

    def note(progress):
        first.setdefault("seconds", time.perf_counter() - start)

    ds = ln.ensemble(SCENE, vary=vary, t_end=t_end, dt=dt, n_out=n_out, client=client, workers=workers, out=out,
                     outputs=outputs, progress=note)
    wall = time.perf_counter() - start
    n = int(ds.sizes["member"])
    figures = {"members": n, "ok": int((ds["status"].values == "ok").sum()), "wall_s": wall,
               "members_per_s": n / wall, "tasks": int(ds.attrs["tasks"]),
               "worker_member_s": float(np.nanmedian(ds["run_seconds"].values)),
               "worker_cpu_member_s": (worker_cpu() - workers_before) / n,
               "client_cpu_member_s": (cpu_seconds() - client_before) / n,
               "first_result_s": first.get("seconds")}
    ds.close()
    return figures


def local_cluster(workers: int):
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address="127.0.0.1:0", silence_logs=logging.ERROR)
    return cluster, Client(cluster)


def import_seconds() -> float:
    """What a cold worker imports to run a member (the study's module, linknet_core with its native library,
    numpy, scipy, Dask's worker side), in a fresh interpreter: best of 3."""
    import subprocess
    import sys

    code = ("import time; t = time.perf_counter(); import linknet_core.ensemble.members; "
            "print(time.perf_counter() - t)")
    return min(float(subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                                    cwd=str(ROOT)).stdout) for _ in range(3))


def scheduler_seconds_per_task(client, n=2000) -> float:
    """Wall time per empty task through submit, scheduling, run and gather (the floor of any task)."""
    client.gather(client.map(int, range(50), pure=False))  # warm
    start = time.perf_counter()
    client.gather(client.map(int, range(n), pure=False))
    return (time.perf_counter() - start) / n


def client_write_seconds_per_member(scene, vary, n_out, members=1000, batch=16) -> float:
    """The client's cost of streaming one member (X, U, T of chain_10) into the study file, without Dask."""
    from linknet_core.ensemble.members import StudySpec
    from linknet_core.ensemble.store import StudyFile

    plan = make_plan(scene, vary)
    times = np.linspace(0, 2, n_out)
    spec = StudySpec("bench", scene.to_dict(), plan.parameters, times, "rattle", 1e-3, None, None, None,
                     ("X", "U", "T"), 10)
    rng = np.random.default_rng(0)
    outputs = {"X": rng.random((batch, n_out, scene.K, 3)), "U": rng.random((batch, n_out, scene.K, 3)),
               "T": rng.random((batch, n_out, scene.L)), "max_tension": rng.random(batch),
               "max_tension_link": np.ones(batch, int), "min_tension": rng.random(batch),
               "tip_final": rng.random((batch, 3))}
    with tempfile.TemporaryDirectory() as folder:
        sink = StudyFile(Path(folder) / "w.nc", spec, plan, scene)
        start = time.perf_counter()
        for first in range(0, min(members, plan.n_members) - batch + 1, batch):
            sink.write({"first": first, "count": batch, "outputs": outputs, "error": [""] * batch,
                        "run_seconds": np.zeros(batch), "worker": "tcp://127.0.0.1:1"})
        seconds = time.perf_counter() - start
        sink.close({})
    return seconds / (members // batch * batch)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="smoke mode: 40 members of 0.2 s")
    p.add_argument("--members", type=int, default=1000)
    p.add_argument("--rounds", type=int, default=3, help="studies per cluster, alternating; the best counts")
    p.add_argument("--out", default=str(ROOT / "build" / "bench_ensemble.json"))
    args = p.parse_args(argv)
    members, t_end = (40, 0.2) if args.quick else (args.members, 2.0)
    dt, n_out = 1e-3, 201
    scene = ln.load_scene(SCENE)
    vary = study_grid(members)
    results: dict = {"scene": "chain_10", "t_end": t_end, "dt": dt, "n_out": n_out, "cores": os.cpu_count(),
                     "load_before": os.getloadavg()[0]}

    # 3 first: the cold start must meet no worker process left by another measurement
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "cold.nc"
        cold = timed_study(None, {"M[11]": [0.1, 0.2]}, t_end, dt, n_out, out, workers=1)
        results["cold"] = cold

    results.update(bare_and_study_member(scene, vary, t_end, dt, n_out))
    bare = results["bare_member_s"]
    # both clusters alive, studies alternating between them: the machine's load (other jobs on the shared
    # cores) moves over minutes, so each cluster keeps its best of the rounds
    started = time.perf_counter()
    clusters = {1: local_cluster(1)}
    results["cluster_start_1_s"] = time.perf_counter() - started  # scheduler, one worker process, its imports
    clusters[2] = local_cluster(2)
    results["worker_import_s"] = import_seconds()
    try:
        with tempfile.TemporaryDirectory() as folder:
            for workers, (_, client) in clusters.items():
                timed_study(client, {"M[11]": [0.1, 0.2, 0.3, 0.4]}, 0.05, dt, 11, Path(folder) / "warm.nc")
            for _ in range(1 if args.quick else args.rounds):
                for name, workers, outputs in (("workers_1", 1, ("X", "U", "T")), ("workers_2", 2, ("X", "U", "T")),
                                               ("workers_2_qoi_only", 2, ())):
                    run = timed_study(clusters[workers][1], vary, t_end, dt, n_out, Path(folder) / "s.nc",
                                      outputs=outputs)
                    if name not in results or run["members_per_s"] > results[name]["members_per_s"]:
                        results[name] = run
        results["scheduler_task_s"] = scheduler_seconds_per_task(clusters[2][1], 500 if args.quick else 2000)
    finally:
        for cluster, client in clusters.values():
            client.close()
            cluster.close()
    results["client_write_member_s"] = client_write_seconds_per_member(scene, vary, n_out,
                                                                       members=160 if args.quick else 1000)
    one, two = results["workers_1"], results["workers_2"]
    results["scaling_efficiency"] = two["members_per_s"] / (2 * one["members_per_s"])
    # what the CPU time allows, whatever else runs: one worker is bound by its own CPU per member; two workers
    # on these 2 cores share them with this process (client and scheduler)
    results["ceiling_1_per_s"] = 1 / one["worker_cpu_member_s"]
    results["ceiling_2_per_s"] = min(2 / two["worker_cpu_member_s"],
                                     2 / (two["worker_cpu_member_s"] + two["client_cpu_member_s"]))
    results["overhead_member_s"] = one["wall_s"] / one["members"] - bare
    # in CPU time, which other jobs on the machine do not inflate: what a member costs beyond its bare run
    results["overhead_worker_cpu_member_s"] = one["worker_cpu_member_s"] - results["bare_cpu_member_s"]
    results["bookkeeping_cpu_member_s"] = results["study_cpu_member_s"] - results["bare_cpu_member_s"]
    results["load_after"] = os.getloadavg()[0]

    if args.quick:  # correctness of what was timed: one member against its serial run
        ds = ln.ensemble(SCENE, vary={"M[11]": [0.3]}, t_end=t_end, dt=dt, n_out=n_out, workers=1)
        mass = np.array(scene.mass)
        mass[10] = 0.3
        ref = ln.simulate(scene.with_parameters(mass=mass), t_end, dt=dt, n_out=n_out)
        assert np.max(np.abs(ds["X"].values[0] - ref.X)) < 1e-12, "member differs from its serial run"

    ms = 1e3
    print(f"chain_10, t_end {t_end:g} s, rattle dt {dt:g}, {n_out} outputs of X, U, T; "
          f"{one['members']} members; {results['cores']} cores, load average {results['load_before']:.1f} -> "
          f"{results['load_after']:.1f}")
    print(f"  bare Simulator run per member, in process: {bare * ms:.2f} ms wall, "
          f"{results['bare_cpu_member_s'] * ms:.2f} ms CPU; as a worker runs it (StudyRuntime.run): "
          f"{results['study_member_s'] * ms:.2f} ms wall, {results['study_cpu_member_s'] * ms:.2f} ms CPU")
    for name, label in (("workers_1", "1 worker "), ("workers_2", "2 workers"),
                        ("workers_2_qoi_only", "2 workers, quantities of interest only (outputs=[])")):
        r = results[name]
        print(f"  {label}: {r['members_per_s']:6.1f} members/s ({r['wall_s']:.2f} s, {r['tasks']} tasks, "
              f"first result {r['first_result_s']:.2f} s); per member: {r['worker_member_s'] * ms:.2f} ms wall on "
              f"the worker, CPU {r['worker_cpu_member_s'] * ms:.2f} ms in workers + "
              f"{r['client_cpu_member_s'] * ms:.2f} ms in client and scheduler")
    ceiling_efficiency = results["ceiling_2_per_s"] / (2 * results["ceiling_1_per_s"])
    print(f"  scaling efficiency 1 -> 2 workers: {results['scaling_efficiency'] * 100:.1f} % (CPU-time ceilings: "
          f"{results['ceiling_1_per_s']:.0f}/s on 1 worker, {results['ceiling_2_per_s']:.0f}/s on 2 workers sharing "
          f"these 2 cores with the client: {ceiling_efficiency * 100:.0f} %)")
    print(f"  overhead per member over the bare run, CPU time (1 worker): "
          f"{results['overhead_worker_cpu_member_s'] * ms:.2f} ms in the worker (the study's own part "
          f"{results['bookkeeping_cpu_member_s'] * ms:.2f} ms, the rest Dask's), "
          f"{one['client_cpu_member_s'] * ms:.2f} ms in client and scheduler; wall time (load-dependent): "
          f"{results['overhead_member_s'] * ms:.2f} ms")
    print(f"  cold start to first result (ln.ensemble with client=None, 1 worker): {cold['first_result_s']:.2f} s "
          f"(of which the member itself {cold['worker_member_s'] * ms:.1f} ms)")
    print(f"  of which: a LocalCluster with 1 worker starts in {results['cluster_start_1_s']:.2f} s; a fresh "
          f"interpreter imports what a member needs in {results['worker_import_s']:.2f} s")
    print(f"  scheduler round trip per empty task (2 workers): {results['scheduler_task_s'] * ms:.3f} ms")
    print(f"  client, per member written to netCDF (X, U, T, 122 kB): {results['client_write_member_s'] * ms:.3f} ms")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
