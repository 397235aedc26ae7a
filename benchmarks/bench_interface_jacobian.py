"""Cost of the interface Jacobian on the native core against a step of the default method.

    python benchmarks/bench_interface_jacobian.py [--rounds 5] [--only chain_10,net_10x10]

Per scene, a Simulator of the default method (linknet_core.accuracy: dop853 at the default rtol, no error estimate)
run to t = 0.5 s first, so that the chain swings, then:

* one step of ln_advance: the CPU time of one advance over 0.5 s divided by the steps it accepted;
* one communication step: an advance of 10 ms (what an FMU doStep of 10 ms costs, without the error estimate's
  companion);
* ln_interface_prepare: the evaluation at the state (tensions and the factorisation of A) that every directional
  derivative at that state reuses, called through ctypes;
* ln_interface_directional: one directional derivative along a seed on every input force (one solve with the kept
  factorisation where A is regular), through ctypes, and through the Python method ``directional`` (seed checks and
  the copies of the results included);
* the whole Jacobian, ``jacobian()``: one directional derivative per input column, in Python.

Each figure is the best of ``--rounds`` repetitions of a timed loop (perf_counter; the garbage collector off).
Measures; asserts nothing.
"""
from __future__ import annotations

import argparse
import gc
import os
import time

import numpy as np

import linknet_core as ln

SCENES = ["chain_10", "net_10x10"]


def best_of(rounds: int, repeat: int, call) -> float:
    """The least mean time (s) of ``repeat`` calls over ``rounds`` rounds."""
    best = float("inf")
    for _ in range(rounds):
        gc.disable()
        t0 = time.perf_counter()
        for _ in range(repeat):
            call()
        best = min(best, (time.perf_counter() - t0) / repeat)
        gc.enable()
    return best


def measure(name: str, rounds: int) -> dict:
    from linknet_core.native import interface as native_interface
    from linknet_core.clib import library as lib

    scene = ln.load_scene(os.path.join(os.getcwd(), "models", f"{name}.json"))
    sim = ln.Simulator(scene, error_estimate=False)
    sim.advance(0.5)
    out = {"method": f"{sim.method} rtol {sim.integrator.rtol:g}"}

    # one accepted step: a long advance over its steps, from the same state each round
    snapshot = sim.get_state()
    best_step = float("inf")
    for _ in range(rounds):
        sim.set_state(snapshot)
        steps_before = sim.integrator.stats.steps
        gc.disable()
        t0 = time.perf_counter()
        sim.advance(1.0)
        wall = time.perf_counter() - t0
        gc.enable()
        steps = sim.integrator.stats.steps - steps_before
        best_step = min(best_step, wall / steps)
    out["step_us"] = best_step * 1e6
    out["steps_per_10ms"] = steps / 50.0
    sim.set_state(snapshot)

    def communication_step():
        sim.advance(sim.state.t + 0.01)
    out["dostep_us"] = best_of(rounds, 20, communication_step) * 1e6
    sim.set_state(snapshot)

    lin = sim.interface_linearization()
    model, data = sim.integrator.model, sim.integrator.data
    X, U = np.ascontiguousarray(sim.state.X), np.ascontiguousarray(sim.state.U)
    F = np.zeros((scene.K, 3))
    J_ptr = lin.interface._ptr
    out["prepare_us"] = best_of(rounds, 200, lambda: native_interface._prepare(
        model.pointer, J_ptr, data._ptr, lib.pointer(X), lib.pointer(U), F.ctypes.data)) * 1e6
    seed = np.random.default_rng(0).standard_normal((scene.K, 3))
    dT, dFreact, dacc = (np.empty(scene.L), np.empty((scene.fixed_indices.size, 3)), np.empty((scene.K, 3)))
    args = (model.pointer, J_ptr, seed.ctypes.data, None, None, None, dT.ctypes.data, dFreact.ctypes.data,
            dacc.ctypes.data)
    out["directional_us"] = best_of(rounds, 2000, lambda: native_interface._directional(*args)) * 1e6
    out["directional_python_us"] = best_of(rounds, 500, lambda: lin.directional(dF=seed)) * 1e6
    out["jacobian_ms"] = best_of(rounds, 3, lin.jacobian) * 1e3
    out["columns"] = 3 * scene.free_indices.size
    return out


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--only", default=None, help="comma-separated scene names")
    args = p.parse_args(argv)
    names = args.only.split(",") if args.only else SCENES
    for name in names:
        r = measure(name, args.rounds)
        print(f"{name} ({r['method']}): one step {r['step_us']:.1f} us ({r['steps_per_10ms']:.1f} steps per 10 ms); "
              f"advance of 10 ms {r['dostep_us']:.1f} us")
        print(f"  prepare {r['prepare_us']:.1f} us; one directional derivative {r['directional_us']:.2f} us in C "
              f"({r['directional_us'] / r['step_us']:.3f} of a step), {r['directional_python_us']:.1f} us through "
              f"Python; the whole Jacobian ({r['columns']} force columns) {r['jacobian_ms']:.2f} ms")


if __name__ == "__main__":
    main()
