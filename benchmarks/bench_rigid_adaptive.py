"""Adaptive methods on a free rigid body: the native rigid-body path (specialisation 'rigid') against the
point-mass path (specialise=False), as time to reach a position error at t_end.

Scene: models/spinning_tetrahedron.json (a spherical top, no gravity), whose exact solution is a uniform
rotation about the spin axis; the error is max_k |X_k(t_end) - X_k^exact| (m). For each path and rtol
(atol = rtol) the run from t = 0 to t_end in one advance is timed (best of several repeats; building the
simulator is not timed); the table lists every setting, then
for each target error the cheapest setting of each path that reaches it.

    OPENBLAS_NUM_THREADS=1 python -m benchmarks.bench_rigid_adaptive [--method dop853] [--t-end 2]
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

import linknet_core as ln

MODEL = Path(__file__).resolve().parent.parent / "models" / "spinning_tetrahedron.json"
TARGETS = (1e-6, 1e-9)


def exact_positions(scene: ln.Scene, t: float) -> np.ndarray:
    """Uniform rotation of the spherical top about its centre of mass (no external force)."""
    m = scene.mass[:, None]
    c0 = (m * scene.X0).sum(axis=0) / scene.mass.sum()
    v = (m * scene.U0).sum(axis=0) / scene.mass.sum()
    rho = scene.X0 - c0
    inertia = np.sum(scene.mass) * 0 + np.einsum("k,kij->ij", scene.mass,
                                                 np.einsum("ki,ki->k", rho, rho)[:, None, None] * np.eye(3)
                                                 - rho[:, :, None] * rho[:, None, :])
    L = np.sum(np.cross(rho, scene.mass[:, None] * (scene.U0 - v)), axis=0)
    w = np.linalg.solve(inertia, L)
    return c0 + v * t + rho @ Rotation.from_rotvec(w * t).as_matrix().T


def runner(scene: ln.Scene, method: str, rtol: float, rigid: bool):
    """A fresh simulator on the rigid-body path or the point-mass path: advance(t_end) -> (X, steps)."""
    sim = ln.Simulator(scene, method=method, rtol=rtol, atol=rtol, specialise=rigid, error_estimate=False)
    assert sim.specialisation.kind == ("rigid" if rigid else "none"), sim.specialisation.text()

    def run(t_end):
        sim.advance(t_end)
        return sim.state.X, sim.integrator.stats.steps
    return run


def measure(scene, method, rtol, rigid, t_end, min_time=0.3, max_repeats=50):
    best, repeats, spent = np.inf, 0, 0.0
    while repeats < max_repeats and (repeats < 3 or spent < min_time):
        run = runner(scene, method, rtol, rigid)
        start = time.perf_counter()
        X, steps = run(t_end)
        elapsed = time.perf_counter() - start
        best, spent, repeats = min(best, elapsed), spent + elapsed, repeats + 1
    return best, X, steps


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--method", default="dop853", choices=["dop853", "dopri5"])
    parser.add_argument("--t-end", type=float, default=2.0)
    args = parser.parse_args(argv)
    scene = ln.load_scene(MODEL)
    X_exact = exact_positions(scene, args.t_end)
    rtols = [10.0 ** -e for e in np.arange(4, 14.5, 0.5)]
    rows = {True: [], False: []}
    for rigid in (True, False):
        for rtol in rtols:
            seconds, X, steps = measure(scene, args.method, rtol, rigid, args.t_end)
            rows[rigid].append((rtol, float(np.abs(X - X_exact).max()), steps, seconds))
    name = {True: "rigid-body path", False: "point-mass path"}
    print(f"{scene.name}, {args.method}, t_end = {args.t_end} s, error = max |X - X_exact| (m), time = one advance "
          "(best of repeats)")
    print(f"{'path':<16} {'rtol':>8} {'error':>10} {'steps':>6} {'time (ms)':>10}")
    for rigid in (True, False):
        for rtol, err, steps, seconds in rows[rigid]:
            print(f"{name[rigid]:<16} {rtol:8.1e} {err:10.2e} {steps:6d} {1e3 * seconds:10.3f}")
    print()
    print(f"{'target':>8}  {'path':<16} {'rtol':>8} {'error':>10} {'steps':>6} {'time (ms)':>10}")
    best = {}
    for target in TARGETS:
        for rigid in (True, False):
            ok = [row for row in rows[rigid] if row[1] <= target]
            if not ok:
                print(f"{target:8.0e}  {name[rigid]:<16} not reached")
                continue
            rtol, err, steps, seconds = min(ok, key=lambda row: row[3])
            best[target, rigid] = seconds
            print(f"{target:8.0e}  {name[rigid]:<16} {rtol:8.1e} {err:10.2e} {steps:6d} {1e3 * seconds:10.3f}")
        if (target, True) in best and (target, False) in best:
            print(f"{'':8}  speed-up of the rigid-body path: {best[target, False] / best[target, True]:.1f}x")


if __name__ == "__main__":
    main()
