"""Time per right-hand-side evaluation: casadi-generated compiled kernel vs the numeric path.

    python benchmarks/bench_codegen.py [--scenes chain_10 chain_100 net_10x10] [--repeat N]

For each scene: symbolic derivation + C code generation + compile time (into a fresh, empty cache
directory, so nothing is reused), then the time of one evaluation of
``accelerations(X, U, F_input) -> (acc, T)`` (forces, A, B, solve, accelerations) on the numeric path
(``Dynamics.accelerations``) and through the compiled kernel (``codegen.compiled_rhs``, called via
ctypes), at a state on the constraint manifold with velocities and a force input, best of several
repeats of many calls. The two results are compared, so the timing is of the same computation.
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # the machine is shared: no BLAS thread oversubscription

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import linknet_core as ln  # noqa: E402
from linknet_core.symbolic import codegen  # noqa: E402
from linknet_core.symbolic.check import sample_states  # noqa: E402
from linknet_core.symbolic.derivation import SymbolicTensionSystem  # noqa: E402


def time_per_call(fn, min_time=0.3, repeat=5):
    n = 1
    while True:  # calibrate the batch so one batch takes ~min_time/repeat
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        dt = time.perf_counter() - t0
        if dt > min_time / repeat:
            break
        n *= 4
    best = dt / n
    for _ in range(repeat - 1):
        t0 = time.perf_counter()
        for _ in range(n):
            fn()
        best = min(best, (time.perf_counter() - t0) / n)
    return best


def bench(name, repeat):
    scene = ln.load_scene(ROOT / "models" / f"{name}.json")
    dyn = ln.Dynamics(scene)
    sym = SymbolicTensionSystem(scene)
    rng = np.random.default_rng(1)
    X, U, F_input = sample_states(scene, sym, 1, rng)[0]
    plane = codegen.plane_of(scene)
    if plane is not None:  # keep a planar scene's state in its plane (the kernel is 2-D there)
        basis, origin, normal = plane
        X = (X - origin) @ basis @ basis.T + origin
        U = U @ basis @ basis.T
        F_input = F_input @ basis @ basis.T
        X, _ = dyn.project_positions(X)
        U = dyn.project_velocities(X, U)
    with tempfile.TemporaryDirectory() as cache:
        t0 = time.perf_counter()
        kernel = codegen.compiled_rhs(scene, cache=cache, required=True)
        build = time.perf_counter() - t0
        acc_n, T_n = dyn.accelerations(X, U, F_input)
        acc_c, T_c = kernel.accelerations(X, U, F_input)
        diff = max(np.abs(acc_c - acc_n).max() / np.abs(acc_n).max(), np.abs(T_c - T_n).max() / np.abs(T_n).max())
        t_num = time_per_call(lambda: dyn.accelerations(X, U, F_input), repeat=repeat)
        t_gen = time_per_call(lambda: kernel.accelerations(X, U, F_input), repeat=repeat)
        raw = kernel._primary.kernel
        t_raw = time_per_call(raw, repeat=repeat)  # the C function alone, inputs already in place
        so_size = Path(kernel.so_path).stat().st_size
    tm = kernel.timings
    return dict(scene=name, K=scene.K, L=scene.L, dim=kernel._primary.d, numeric_us=t_num * 1e6,
                generated_us=t_gen * 1e6, kernel_only_us=t_raw * 1e6, speedup=t_num / t_gen,
                symbolic_s=tm.get("symbolic_s", 0.0), codegen_s=tm.get("codegen_s", 0.0),
                compile_s=tm.get("compile_s", 0.0), total_build_s=build, so_kB=so_size / 1024, rel_diff=diff)


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scenes", nargs="+", default=["chain_10", "chain_100", "net_10x10"])
    p.add_argument("--repeat", type=int, default=5)
    args = p.parse_args(argv)
    if codegen.compiler() is None:
        print("no C compiler: nothing to benchmark")
        return 0
    print(f"{'scene':<10} {'K':>4} {'L':>4} {'d':>2} {'numeric':>10} {'generated':>10} {'C only':>9} "
          f"{'speedup':>7} | {'symbolic':>8} {'codegen':>8} {'compile':>8} {'total':>7} {'.so':>7} {'rel.diff':>8}")
    for name in args.scenes:
        r = bench(name, args.repeat)
        print(f"{r['scene']:<10} {r['K']:>4} {r['L']:>4} {r['dim']:>2} {r['numeric_us']:>8.1f}us "
              f"{r['generated_us']:>8.1f}us {r['kernel_only_us']:>7.1f}us {r['speedup']:>6.1f}x | "
              f"{r['symbolic_s']:>7.3f}s {r['codegen_s']:>7.3f}s {r['compile_s']:>7.2f}s {r['total_build_s']:>6.2f}s "
              f"{r['so_kB']:>5.0f}kB {r['rel_diff']:>8.1e}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
