#!/usr/bin/env python3
"""FMU overhead benchmark (issue 4): measures, prints and saves; asserts nothing.

    python benchmarks/bench_fmu.py [--quick] [--out build/bench_fmu.json]

1. per-doStep overhead of the FMU over the in-process `Simulator.advance`, with 1 or 10 RATTLE steps
   per communication step (inputs set every step, as a master does), from two hosts:
   - fmpy (ctypes -> pythonfmu binary -> Python slave -> Simulator), in this process;
   - a plain C host (benchmarks/c_reference/fmi2_timing_host.c, compiled here with the system C
     compiler, run on the same extracted FMU with the same inputs and steps): setReal + doStep,
     doStep alone and setReal alone, so the FMU's own cost is separated from fmpy's marshalling;
     also, as a diagnostic, the same with the C thread's Python thread state kept between calls by
     the host: pythonfmu 0.7.0 creates and deletes one in every FMI call from a C thread unless the
     FMU keeps it (fmu_src/linknet_fmu/thread_state.py does); equal figures say that it does;
2. cost of reading all outputs per communication step through fmpy (one fmi2GetReal call for
   every X, U, T, Freact) for chain_100 and net_10x10;
3. the slave's array-backed get_real against pythonfmu's default per-variable getters
   (Python level, same slave object, no FMI binary involved).
Each figure is the best (minimum) of several alternating repeats: the machine is shared, and
other processes only ever add time, so the minimum is the least disturbed measurement.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "fmu_src"))

import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402
from linknet_core.symbolic.codegen import compiler  # noqa: E402

from benchmarks.output import build_path, write_text  # noqa: E402


def _best_time(fn, repeats):
    """Best of `repeats` timings of fn() (name kept for the callers)."""
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return float(np.min(samples))


C_TIMING_HOST = ROOT / "benchmarks" / "c_reference" / "fmi2_timing_host.c"
C_HOST_FLAGS = ["-O2", "-Wall"]


def build_c_timing_host(build_dir: Path):
    """Compile the C timing host; returns (executable or None, compiler command line or the reason it is missing)."""
    cc = compiler()  # $CC, cc, gcc or clang (linknet_core.symbolic.codegen)
    if cc is None:
        return None, "no C compiler (cc, gcc or clang) on PATH"
    exe = build_dir / "fmi2_timing_host"
    cmd = [cc, *C_HOST_FLAGS, "-o", str(exe), str(C_TIMING_HOST), "-ldl"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        return None, f"{' '.join(cmd)} failed:\n{proc.stderr}"
    return exe, " ".join([cc, *C_HOST_FLAGS, "... -ldl"])


def _c_host_env():
    """A C master's process has no Python hints: the FMU binary must find its Python through its own links
    (as in tests/test_fmu_c_host.py)."""
    return {k: v for k, v in os.environ.items() if not k.startswith("PYTHON") and k != "LD_PRELOAD"}


def run_c_timing_host(exe, unzipped, md, n_steps, repeats, dt, in_vr, in_val, out_vr):
    """One run of the C timing host; returns its JSON line as a dict, or {"error": ...}."""
    cmd = [str(exe), str(unzipped), md.coSimulation.modelIdentifier, md.guid, repr(dt), str(n_steps), str(repeats)]
    cmd += [f"in:{vr}={val!r}" for vr, val in zip(in_vr, in_val)] + [f"out:{vr}" for vr in out_vr]
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, env=_c_host_env(), timeout=3600)
    except subprocess.TimeoutExpired:
        return {"error": "C host timed out after 3600 s"}
    lines = [line for line in proc.stdout.splitlines() if line.startswith("{")]
    if not lines:
        return {"error": f"C host exit code {proc.returncode}: {proc.stderr[-2000:]}"}
    res = json.loads(lines[-1])
    if proc.returncode != 0:  # the line is printed once every span ran: a failure after it (shutdown) leaves it whole
        res["exit_code"], res["stderr"] = proc.returncode, proc.stderr[-2000:]
    return res


def _extract(fmu):
    """Unpack next to the FMU (build/, ignored by git): fmpy and the C host run the same files."""
    from fmpy import extract
    where = Path(fmu).with_suffix("")
    shutil.rmtree(where, ignore_errors=True)
    return Path(extract(str(fmu), unzipdir=str(where)))


def _open(fmu, unzipped=None):
    from fmpy import read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(unzipped or _extract(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return md, slave


def bench_dostep(scene_name, fmu_dir, n_steps, repeats, dt=1e-3, substeps=1, inputs="tip", c_host=None):
    """doStep of dt with `substeps` RATTLE steps inside it (solver step dt / substeps) vs Simulator.advance.
    inputs: "tip" sets one force component per step, "all" every force input (a master that connects them
    all), both with the same values (0.1 N on the tip, 0 elsewhere). c_host: the compiled C timing host
    (None: that column is skipped), run on the same extracted FMU twice, between three blocks of the
    fmpy/library repeats, so that the three are measured over the same stretch of machine load."""
    scene = ln.load_scene(ROOT / "models" / f"{scene_name}.json")
    h = dt / substeps
    fmu = build_fmu.build_scene_fmu(ROOT / "models" / f"{scene_name}.json",
                                    fmu_dir / f"{scene_name}_{substeps}.fmu", integrator="rattle", step=h,
                                    error_estimate=False, quiet=True)  # pinned: RATTLE without the companion
    unzipped = _extract(fmu)
    md, slave = _open(fmu, unzipped)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    tip = int(scene.free_indices[-1])
    f_vr = [vr[f"F[{tip + 1},3]"]]
    f_val = [0.1]
    if inputs == "all":
        f_vr = [v.valueReference for v in md.modelVariables if v.causality == "input"]
        f_val = [0.1 if v.name == f"F[{tip + 1},3]" else 0.0 for v in md.modelVariables if v.causality == "input"]
    # read after a run, to check that every host did the same work as the library: the tip's state, a tension
    check_names = [f"X[{tip + 1},{i}]" for i in (1, 2, 3)] + [f"U[{tip + 1},3]", "T[1]"]
    check_vr = [vr[n] for n in check_names]
    initial = slave.getFMUstate()  # every repeat runs the same span [0, n_steps * dt]

    def fmu_run():
        t = 0.0
        for n in range(n_steps):
            slave.setReal(f_vr, f_val)
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            t += dt

    sim = ln.Simulator(scene, method="rattle", dt=h, error_estimate=False)  # as the FMU: no companion
    F = np.zeros((scene.K, 3))
    F[tip, 2] = 0.1

    def lib_run():
        t = 0.0
        for n in range(n_steps):
            sim.advance(t + dt, F)
            t += dt

    fmu_run()  # warm-up (first calls import and compile)
    lib_run()
    def timed(run, restart):
        restart()  # back to t = 0, outside the timing
        t0 = time.perf_counter()
        run()
        return time.perf_counter() - t0

    # alternate the two so that load from other processes on the machine hits both alike
    def pairs(k):
        return [(timed(fmu_run, lambda: slave.setFMUstate(initial)), timed(lib_run, sim.reset)) for _ in range(k)]

    # the C host runs twice, between three blocks of fmpy/library pairs, so that a burst of load from other
    # processes cannot hit all of one host's repeats and none of the other's
    blocks = [repeats // 3 + (i < repeats % 3) for i in range(3)]
    all_pairs = pairs(blocks[0])
    c_runs = []
    for block in blocks[1:]:
        if c_host is not None:
            c_runs.append(run_c_timing_host(c_host, unzipped, md, n_steps, (repeats + 1) // 2, dt, f_vr, f_val,
                                            check_vr))
        all_pairs += pairs(block)
    c_res = _merge_c_runs(c_runs) if c_runs else None
    t_fmu = min(p[0] for p in all_pairs) / n_steps
    t_lib = min(p[1] for p in all_pairs) / n_steps
    # both ended their last run at t = n_steps * dt with the same force held
    o = sim.outputs(F)
    lib_check = [*o["X"][tip], o["U"][tip, 2], o["T"][0]]
    fmpy_check = slave.getReal(check_vr)
    slave.terminate()
    row = dict(scene=scene_name, K=scene.K, L=scene.L, substeps=substeps, inputs_set=len(f_vr), fmu_dostep_s=t_fmu,
               library_advance_s=t_lib, overhead_s=t_fmu - t_lib, ratio=t_fmu / t_lib,
               checked_outputs=check_names, fmpy_vs_library_max_abs_diff=_max_abs_diff(fmpy_check, lib_check))
    if c_res is not None:
        row["c_host"] = c_res
        if "error" not in c_res:
            row["c_host_overhead_s"] = c_res["setreal_dostep_s"] - t_lib
            if c_res.get("setreal_dostep_tstate_kept_s") is not None:
                row["c_host_tstate_kept_overhead_s"] = c_res["setreal_dostep_tstate_kept_s"] - t_lib
            row["c_host_vs_library_max_abs_diff"] = max(
                _max_abs_diff(v, lib_check) for run in c_runs for k, v in run.items() if k.startswith("outputs_after_"))
    return row


def _merge_c_runs(runs):
    """Two runs of the C host as one: every repeat's samples, the best of all, the last run's outputs."""
    errors = [r["error"] for r in runs if "error" in r]
    if errors:
        return {"error": errors[0]}
    merged = dict(runs[-1])
    merged["repeats"] = sum(r["repeats"] for r in runs)
    for key in runs[-1]:
        if key.endswith("_samples_s"):
            merged[key] = [x for r in runs for x in r[key]]
            merged[key[:-len("_samples_s")] + "_s"] = min(merged[key])
    return merged


def _max_abs_diff(a, b):
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))


def bench_outputs(scene_name, fmu_dir, n_steps, repeats, dt=1e-3):
    fmu = build_fmu.build_scene_fmu(ROOT / "models" / f"{scene_name}.json", fmu_dir / f"{scene_name}_out.fmu",
                                    integrator="rattle", step=dt, error_estimate=False, quiet=True)
    md, slave = _open(fmu)
    out_vrs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    initial = slave.getFMUstate()

    def steps(read):
        t = 0.0
        for n in range(n_steps):
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            if read:
                slave.getReal(out_vrs)
            t += dt

    def timed(read):
        slave.setFMUstate(initial)  # back to t = 0, outside the timing
        t0 = time.perf_counter()
        steps(read)
        return time.perf_counter() - t0

    timed(True)
    pairs = [(timed(True), timed(False)) for _ in range(repeats)]
    with_read = min(p[0] for p in pairs) / n_steps
    without = min(p[1] for p in pairs) / n_steps
    # the getReal call alone, repeated at one communication point (outputs cached after the first)
    get_only = _best_time(lambda: [slave.getReal(out_vrs) for _ in range(n_steps)], repeats) / n_steps
    slave.terminate()
    return dict(scene=scene_name, n_outputs=len(out_vrs), dostep_s=without, dostep_and_read_all_s=with_read,
                read_all_cost_s=with_read - without, getreal_all_cached_s=get_only)


def bench_getter_paths(scene_name, fmu_dir, repeats):
    """Python-level: the array-backed get_real vs pythonfmu's default per-variable loop."""
    import zipfile
    from pythonfmu.fmi2slave import Fmi2Slave
    fmu = build_fmu.build_scene_fmu(ROOT / "models" / f"{scene_name}.json", fmu_dir / f"{scene_name}_py.fmu",
                                    integrator="rattle", step=1e-3, error_estimate=False, quiet=True)
    res = fmu_dir / f"{scene_name}_py_resources"
    with zipfile.ZipFile(fmu) as z:
        z.extractall(res)
    import linknet_slave
    slave = linknet_slave.LinknetNetwork(instance_name="bench", resources=str(res / "resources"))
    vrs = [vr for vr, v in slave.vars.items() if v.causality is not None and v.causality.name == "output"]
    array = _best_time(lambda: [slave.get_real(vrs) for _ in range(100)], repeats) / 100
    default = _best_time(lambda: [Fmi2Slave.get_real(slave, vrs) for _ in range(10)], repeats) / 10
    return dict(scene=scene_name, n_outputs=len(vrs), array_get_real_s=array, default_get_real_s=default,
                speedup=default / array)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--quick", action="store_true", help="few steps (smoke run)")
    p.add_argument("--out", help="results (JSON; default build/bench_fmu.json, the FMUs in bench_fmus/ beside it); "
                   "not inside docs/")
    a = p.parse_args(argv)
    out = build_path("bench_fmu.json", a.out, parser=p)
    n_steps, repeats = (20, 2) if a.quick else (300, 15)
    fmu_dir = out.parent / "bench_fmus"
    fmu_dir.mkdir(parents=True, exist_ok=True)
    c_host, c_host_build = build_c_timing_host(fmu_dir)
    if c_host is None:
        print(f"note: the C-host columns are skipped: {c_host_build}")
    results = {"n_steps": n_steps, "repeats": repeats, "c_host_build": c_host_build,
               "dostep": [bench_dostep(s, fmu_dir, n_steps, repeats, substeps=m, c_host=c_host)
                          for m in (1, 10) for s in ("chain_10", "chain_100", "net_10x10")]
               + [bench_dostep("chain_100", fmu_dir, n_steps, repeats, substeps=m, inputs="all", c_host=c_host)
                  for m in (1, 10)],
               "outputs": [bench_outputs(s, fmu_dir, n_steps, repeats) for s in ("chain_100", "net_10x10")],
               "getters": [bench_getter_paths(s, fmu_dir, repeats) for s in ("chain_100", "net_10x10")]}

    def us(seconds):
        return "-" if seconds is None else f"{seconds * 1e6:.1f}us"

    c_repeats = 2 * ((repeats + 1) // 2)
    print("1. per-doStep cost, communication step 1 ms holding 1 or 10 RATTLE steps, inputs set each step. Best of "
          f"{repeats} (C host: {c_repeats}) repeats of {n_steps} steps.\n"
          "   Overhead = setReal + doStep - Simulator.advance (in this process)")
    print(f"   {'':32s} {'------ fmpy host ------':>23s} {'---------------- C host ----------------':>41s}")
    print(f"   {'scene':10s} {'steps':>5s} {'inputs':>6s} {'advance':>9s} "
          f"{'set+step':>11s} {'overhead':>11s} {'set+step':>10s} {'doStep':>9s} {'setReal':>9s} {'overhead':>10s}")
    for r in results["dostep"]:
        c = r.get("c_host") or {}
        print(f"   {r['scene']:10s} {r['substeps']:5d} {r['inputs_set']:6d} {us(r['library_advance_s']):>9s} "
              f"{us(r['fmu_dostep_s']):>11s} {us(r['overhead_s']):>11s} {us(c.get('setreal_dostep_s')):>10s} "
              f"{us(c.get('dostep_s')):>9s} {us(c.get('setreal_s')):>9s} {us(r.get('c_host_overhead_s')):>10s}")
    if any(r.get("c_host_tstate_kept_overhead_s") is not None for r in results["dostep"]):
        print("   C host with its thread's Python thread state kept by the host (diagnostic: pythonfmu 0.7.0 creates\n"
              "   and deletes one per FMI call unless the FMU keeps it; equal to the table above if it does)")
        print(f"   {'scene':10s} {'steps':>5s} {'inputs':>6s} "
              f"{'set+step':>10s} {'doStep':>9s} {'setReal':>9s} {'overhead':>10s}")
        for r in results["dostep"]:
            c = r.get("c_host") or {}
            print(f"   {r['scene']:10s} {r['substeps']:5d} {r['inputs_set']:6d} "
                  f"{us(c.get('setreal_dostep_tstate_kept_s')):>10s} {us(c.get('dostep_tstate_kept_s')):>9s} "
                  f"{us(c.get('setreal_tstate_kept_s')):>9s} {us(r.get('c_host_tstate_kept_overhead_s')):>10s}")
    for r in results["dostep"]:
        err = (r.get("c_host") or {}).get("error")
        if err:
            print(f"   note: C host failed on {r['scene']} ({r['substeps']} steps): {err}")
    worst = max(max(r["fmpy_vs_library_max_abs_diff"], r.get("c_host_vs_library_max_abs_diff", 0.0))
                for r in results["dostep"])
    print(f"   same work: the tip mass's X, U[.,3] and T[1] after the last run, fmpy and C host against the library: "
          f"max |difference| {worst:.1e}")
    print("2. reading all outputs per communication step through fmpy (one getReal for all X, U, T, Freact)")
    for r in results["outputs"]:
        print(f"   {r['scene']:10s} {r['n_outputs']:5d} outputs: doStep {r['dostep_s'] * 1e6:8.1f}us, doStep + read all "
              f"{r['dostep_and_read_all_s'] * 1e6:8.1f}us -> reading costs {r['read_all_cost_s'] * 1e6:7.1f}us "
              f"(getReal alone, outputs cached: {r['getreal_all_cached_s'] * 1e6:6.1f}us)")
    print("3. slave get_real for all outputs, Python level: array access vs pythonfmu's per-variable getters")
    for r in results["getters"]:
        print(f"   {r['scene']:10s} {r['n_outputs']:5d} outputs: array {r['array_get_real_s'] * 1e6:8.1f}us, "
              f"default {r['default_get_real_s'] * 1e6:9.1f}us ({r['speedup']:.0f}x)")
    write_text(out, json.dumps(results, indent=1))
    print(f"saved {out}")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)  # pythonfmu 0.7.0 can abort while finalizing Python at exit (docs/fmu.md)
