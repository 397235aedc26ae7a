"""The machine's own ceiling for an ensemble: N independent serial loops in N processes, no Dask (measures only).

Each process runs the serial loop of benchmarks/bench_ensemble.py (the scene with the member's values, then
``ln.simulate``; chain_10, 2 s, RATTLE dt 1e-3, 201 outputs) over its share of the members, after one warm-up
member, and all start together. Against one process alone this gives what N cores of this machine deliver to
members that share nothing: a host whose members slow down when many cores are busy (shared caches, memory
bandwidth, turbo frequency, a virtual machine's cores) caps every parallel scheme there, Dask or not, and the
ensemble's ratio to N x serial is judged against this ceiling.

    python -m benchmarks.parallel_ceiling [--processes 1,4,8,16] [--members-per-process 300]
"""
from __future__ import annotations

import argparse
import multiprocessing
import os
import time
import warnings

from benchmarks.bench_ensemble import SCENE, N_OUT, T_END, member_settings, serial_member, study_grid


def _loop(args):
    start_at, settings = args
    import linknet_core as ln
    from linknet_core.accuracy import AccuracyWarning

    # RATTLE at 1 ms is outside its error goal on some members: said by each run, the same as in the serial loop
    warnings.simplefilter("ignore", AccuracyWarning)
    scene = ln.load_scene(SCENE)
    serial_member(scene, *settings[0], T_END, N_OUT)  # warm-up: the library loaded, the pools filled
    while time.time() < start_at:  # every process starts its timed loop at the same moment
        time.sleep(0.001)
    wall, cpu = time.perf_counter(), time.process_time()
    for mass, gravity in settings:
        serial_member(scene, mass, gravity, T_END, N_OUT)
    return time.perf_counter() - wall, time.process_time() - cpu


def run(processes: int, per_process: int) -> dict:
    settings = member_settings(study_grid(processes * per_process))
    shares = [settings[i::processes][:per_process] for i in range(processes)]
    start_at = time.time() + 2.0 + 0.2 * processes  # after every process has loaded linknet and warmed up
    with multiprocessing.get_context("spawn").Pool(processes) as pool:
        results = pool.map(_loop, [(start_at, share) for share in shares])
    walls = [w for w, _ in results]
    members = sum(len(s) for s in shares)
    return {"processes": processes, "members": members, "wall_s": max(walls),
            "members_per_s": members / max(walls), "cpu_member_ms": 1e3 * sum(c for _, c in results) / members}


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--processes", default="1,4,8,16")
    p.add_argument("--members-per-process", type=int, default=300)
    args = p.parse_args(argv)
    counts = [int(n) for n in args.processes.split(",")]
    rows = [run(n, args.members_per_process) for n in counts]
    one = next((r for r in rows if r["processes"] == 1), None)
    print(f"chain_10 members, {T_END:g} s, {N_OUT} outputs; {os.cpu_count()} cores; {args.members_per_process} members "
          "per process, N independent serial loops started together (no Dask)\n")
    print("| processes | members/s | CPU time per member (ms) | against N x one process |")
    print("|---|---|---|---|")
    for r in rows:
        ratio = f"{r['members_per_s'] / (r['processes'] * one['members_per_s']):.2f}" if one else "-"
        print(f"| {r['processes']} | {r['members_per_s']:.1f} | {r['cpu_member_ms']:.3f} | {ratio} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
