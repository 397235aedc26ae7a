#!/usr/bin/env python3
"""FMU overhead benchmark (issue 4): measures, prints and saves; asserts nothing.

    python benchmarks/bench_fmu.py [--quick] [--out build/bench_fmu.json]

1. per-doStep overhead of the FMU (fmpy -> pythonfmu binary -> Python slave -> Simulator) over
   the in-process `Simulator.advance`, with one RATTLE step per communication step, so the
   difference is the FMI round trip (inputs set every step, as a master does);
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
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "fmu_src"))

import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402


def _best_time(fn, repeats):
    """Best of `repeats` timings of fn() (name kept for the callers)."""
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append(time.perf_counter() - t0)
    return float(np.min(samples))


def _open(fmu):
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(fmu)),
                      modelIdentifier=md.coSimulation.modelIdentifier, instanceName="bench")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    return md, slave


def bench_dostep(scene_name, fmu_dir, n_steps, repeats, dt=1e-3, substeps=1, inputs="tip"):
    """doStep of dt with `substeps` RATTLE steps inside it (solver step dt / substeps) vs Simulator.advance.
    inputs: "tip" sets one force component per step, "all" every force input (a master that connects them
    all), both with the same values (0.1 N on the tip, 0 elsewhere)."""
    scene = ln.load_scene(ROOT / "models" / f"{scene_name}.json")
    h = dt / substeps
    fmu = build_fmu.build_scene_fmu(ROOT / "models" / f"{scene_name}.json",
                                    fmu_dir / f"{scene_name}_{substeps}.fmu", step=h, quiet=True)
    md, slave = _open(fmu)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    tip = int(scene.free_indices[-1])
    f_vr = [vr[f"F[{tip + 1},3]"]]
    f_val = [0.1]
    if inputs == "all":
        f_vr = [v.valueReference for v in md.modelVariables if v.causality == "input"]
        f_val = [0.1 if v.name == f"F[{tip + 1},3]" else 0.0 for v in md.modelVariables if v.causality == "input"]
    initial = slave.getFMUstate()  # every repeat runs the same span [0, n_steps * dt]

    def fmu_run():
        t = 0.0
        for n in range(n_steps):
            slave.setReal(f_vr, f_val)
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=dt)
            t += dt

    sim = ln.Simulator(scene, method="rattle", dt=h)
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
    pairs = [(timed(fmu_run, lambda: slave.setFMUstate(initial)), timed(lib_run, sim.reset))
             for _ in range(repeats)]
    t_fmu = min(p[0] for p in pairs) / n_steps
    t_lib = min(p[1] for p in pairs) / n_steps
    slave.terminate()
    return dict(scene=scene_name, K=scene.K, L=scene.L, substeps=substeps, inputs_set=len(f_vr), fmu_dostep_s=t_fmu, library_advance_s=t_lib,
                overhead_s=t_fmu - t_lib, ratio=t_fmu / t_lib)


def bench_outputs(scene_name, fmu_dir, n_steps, repeats, dt=1e-3):
    fmu = build_fmu.build_scene_fmu(ROOT / "models" / f"{scene_name}.json", fmu_dir / f"{scene_name}_out.fmu",
                                    step=dt, quiet=True)
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
                                    quiet=True)
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
    p.add_argument("--out", default=str(ROOT / "build" / "bench_fmu.json"))
    a = p.parse_args(argv)
    n_steps, repeats = (20, 2) if a.quick else (300, 9)
    fmu_dir = Path(a.out).parent / "bench_fmus"
    fmu_dir.mkdir(parents=True, exist_ok=True)
    results = {"n_steps": n_steps, "repeats": repeats,
               "dostep": [bench_dostep(s, fmu_dir, n_steps, repeats, substeps=m)
                          for m in (1, 10) for s in ("chain_10", "chain_100", "net_10x10")]
               + [bench_dostep("chain_100", fmu_dir, n_steps, repeats, substeps=m, inputs="all") for m in (1, 10)],
               "outputs": [bench_outputs(s, fmu_dir, n_steps, repeats) for s in ("chain_100", "net_10x10")],
               "getters": [bench_getter_paths(s, fmu_dir, repeats) for s in ("chain_100", "net_10x10")]}
    print("1. per-doStep cost, communication step 1 ms holding 1 or 10 RATTLE steps, inputs set each step (setReal + doStep)")
    print(f"   {'scene':10s} {'K':>4s} {'L':>4s} {'steps':>5s} {'inputs':>6s} {'FMU doStep':>12s} {'Simulator.advance':>18s} {'overhead':>10s} {'ratio':>6s}")
    for r in results["dostep"]:
        print(f"   {r['scene']:10s} {r['K']:4d} {r['L']:4d} {r['substeps']:5d} {r['inputs_set']:6d} {r['fmu_dostep_s'] * 1e6:10.1f}us {r['library_advance_s'] * 1e6:16.1f}us "
              f"{r['overhead_s'] * 1e6:8.1f}us {r['ratio']:6.2f}")
    print("2. reading all outputs per communication step through fmpy (one getReal for all X, U, T, Freact)")
    for r in results["outputs"]:
        print(f"   {r['scene']:10s} {r['n_outputs']:5d} outputs: doStep {r['dostep_s'] * 1e6:8.1f}us, doStep + read all "
              f"{r['dostep_and_read_all_s'] * 1e6:8.1f}us -> reading costs {r['read_all_cost_s'] * 1e6:7.1f}us "
              f"(getReal alone, outputs cached: {r['getreal_all_cached_s'] * 1e6:6.1f}us)")
    print("3. slave get_real for all outputs, Python level: array access vs pythonfmu's per-variable getters")
    for r in results["getters"]:
        print(f"   {r['scene']:10s} {r['n_outputs']:5d} outputs: array {r['array_get_real_s'] * 1e6:8.1f}us, "
              f"default {r['default_get_real_s'] * 1e6:9.1f}us ({r['speedup']:.0f}x)")
    Path(a.out).write_text(json.dumps(results, indent=1))
    print(f"saved {a.out}")
    return 0


if __name__ == "__main__":
    code = main()
    sys.stdout.flush()
    os._exit(code)  # pythonfmu 0.7.0 can abort while finalizing Python at exit (docs/fmu.md)
