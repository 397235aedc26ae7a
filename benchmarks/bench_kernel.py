"""Is linknet's native core near the machine's limit?

Part 1 - right-hand side vs plain C. One evaluation of the right-hand side for a chain with one anchored end
(external forces = gravity, A of (25) tridiagonal and B of (26), the tension solve, accelerations (9)), timed
for chains of 10, 100, 1000 and 10000 links:

* C: benchmarks/c_reference/chain_rhs.c, plain C (Thomas elimination), compiled here with the system C
  compiler (``cc -O2 -shared -fPIC``, no -march, no -ffast-math), loaded with ctypes, N evaluations in a loop
  inside C (one ctypes call per timing); and chain_rhs_fused.c, the same kernel hand-fused into two sweeps
  (same flags), for what hand-written C reaches. The fused kernel is also built with the native core's own
  optimisation flags (setup.py), so that a difference of flags is not taken for a difference of code;
* linknet: the native core's right-hand side, the stage the integrators call (``ln_accelerations``), N
  evaluations in one C call (``ln_evaluate_repeated``), same inputs: on the chain path the scene gets
  (tridiagonal, two sweeps), and on the sparse LDL^T path (a model built from the same structure declared a
  tree: what a chain would get without its specialisation), for comparison.

Before timing, the C results, the native ones and the numpy ``Dynamics.accelerations`` are checked to agree
to round-off. Times are CPU time of this process (time.process_time: robust to other processes on a shared
machine), best of several interleaved timings. Inputs: a random-walk chain (random link directions and
masses, total length and mass 1) with random velocities projected onto (12), so that every term of
(25)-(26) is exercised.

Planar scenes: part 1 also times the right-hand side of a planar chain (and a pendulum) in 2-D, in the
plane's coordinates, against the same stage in 3-D.

Part 2 (``--integrators``) - whole runs: time per step and total time of one ``Simulator.advance(2.0)``,
native vs the numpy reference (adaptive Runge-Kutta, several scenes and tolerances), the difference of the
two paths' final positions, and how much the scene amplifies a 1e-13 m change of its initial state; and the
planar scenes (pendulum, double pendulum, chain_10, chain_100; RATTLE, DOPRI5, DOP853) run in 2-D and forced
onto 3-D.

    python -m benchmarks.bench_kernel [--quick] [--integrators] [--no-kernel] [--out DIR] [--merge]

Writes DIR/kernel.json and DIR/kernel.md (default build/kernel, or build/kernel/quick with --quick; with --merge the
tracked docs/benchmarks).
Measures only; asserts nothing but the agreement of the implementations.
"""
from __future__ import annotations

import argparse
import ctypes
import dataclasses
import json
import os
import platform
import subprocess
import sys
import sysconfig
import tempfile
import time
from pathlib import Path

# One BLAS thread, as the work-precision benchmark's references: the numpy reference factors A of a general scene
# of up to 200 links densely (LAPACK dpotrf), which OpenBLAS threads; on the 2 shared cores a 180-link factorisation
# then took 35 ms of CPU time (the helper threads spin while descheduled) against 85 us on one thread, and the
# numpy column timed that contention instead of the reference. Only effective before numpy is first imported.
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import linknet_core as ln
from linknet_core.scene import builders
from linknet_core.clib import library as native_lib
from linknet_core.native.model import NativeData, NativeModel
from linknet_core.symbolic.codegen import compiler

from benchmarks.output import add_output_arguments, resolve, write_text

C_SOURCE = Path(__file__).resolve().parent / "c_reference" / "chain_rhs.c"
C_SOURCE_FUSED = Path(__file__).resolve().parent / "c_reference" / "chain_rhs_fused.c"
C_FLAGS = ["-O2", "-shared", "-fPIC"]
# the optimisation flags the native core is built with (python's CFLAGS, then setup.py's extra_compile_args;
# the warnings and -g do not change the code): the fused reference is built with them too
CORE_FLAGS = ["-O3", "-fwrapv", "-std=c99", "-fno-math-errno", "-ffp-contract=off", "-shared", "-fPIC"]
SIZES = (10, 100, 1000, 10000)
AGREEMENT_TOL = 1e-9  # relative (to the largest entry) agreement demanded of the implementations

_P = ctypes.POINTER(ctypes.c_double)


class CUnavailable(RuntimeError):
    pass


def build_c_reference(workdir: Path | None = None, source: Path = C_SOURCE, flags=C_FLAGS):
    """Compile a C reference (default chain_rhs.c) into a shared library and load it; returns (library,
    compiler command line, compiler version)."""
    cc = compiler()  # $CC, cc, gcc or clang
    if cc is None:
        raise CUnavailable("no C compiler (cc, gcc or clang) on PATH")
    workdir = Path(workdir or tempfile.mkdtemp(prefix="linknet_c_reference_"))
    lib_path = workdir / (source.stem + "_" + str(abs(hash(tuple(flags)))) + ".so")
    cmd = [cc, *flags, "-o", str(lib_path), str(source)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise CUnavailable(f"{' '.join(cmd)} failed:\n{proc.stderr}")
    lib = ctypes.CDLL(str(lib_path))
    lib.chain_rhs.restype = None
    lib.chain_rhs.argtypes = [ctypes.c_int] + [_P] * 12
    lib.chain_rhs_repeat.restype = ctypes.c_double
    lib.chain_rhs_repeat.argtypes = [ctypes.c_long, ctypes.c_int] + [_P] * 12
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()
    return lib, " ".join([Path(cc).name, *flags]), (version[0] if version else cc)


def random_chain_state(n_links: int, seed: int = 0, planar: bool = False):
    """A chain anchored at its first mass in a random-walk shape, random masses, consistent random velocities
    (``planar``: walk and velocities in the x-z plane, gravity in it too)."""
    rng = np.random.default_rng(seed)
    steps = rng.normal(size=(n_links, 3))
    if planar:
        steps[:, 1] = 0.0
    steps *= (1.0 / n_links) / np.linalg.norm(steps, axis=1)[:, None]
    points = np.vstack([np.zeros(3), np.cumsum(steps, axis=0)])
    masses = rng.uniform(0.5, 1.5, n_links + 1)
    masses /= masses.sum()
    scene = builders.chain(n_links, shape="points", points=points, masses=masses, name=f"chain_{n_links}_walk")
    dyn = ln.Dynamics(scene)
    U = rng.normal(size=points.shape) * (~scene.fixed)[:, None]
    if planar:
        U[:, 1] = 0.0
    U = dyn.project_velocities(scene.X0, U)
    return scene, dyn, np.ascontiguousarray(scene.X0, np.float64), np.ascontiguousarray(U, np.float64)


class CChain:
    """The C kernel's arrays for one chain (masses 0..n, mass 0 anchored, link l joins l and l+1)."""

    def __init__(self, lib, scene, X, U):
        if not (np.array_equal(scene.k1, np.arange(scene.L)) and np.array_equal(scene.k2, np.arange(1, scene.L + 1))
                and scene.fixed[0] and not scene.fixed[1:].any()):
            raise ValueError("the C reference takes a chain k1 = l, k2 = l + 1 anchored at mass 0 only")
        n = scene.L
        self.lib, self.n = lib, n
        self.arrays = [X, U, np.ascontiguousarray(scene.length, np.float64),
                       np.ascontiguousarray(np.where(scene.fixed, 0.0, scene.mass), np.float64),
                       np.ascontiguousarray(scene.inv_mass, np.float64),
                       np.ascontiguousarray(scene.gravity, np.float64),
                       np.zeros((n + 1, 3)), np.zeros(n), np.zeros((n, 3)), np.zeros((n + 1, 3)), np.zeros(n),
                       np.zeros(n)]
        self.pointers = [a.ctypes.data_as(_P) for a in self.arrays]

    def evaluate(self):
        self.lib.chain_rhs(self.n, *self.pointers)
        return self.arrays[6].copy(), self.arrays[7].copy()

    def run(self, n_evals: int) -> float:
        """CPU seconds for n_evals evaluations in a loop inside C."""
        start = time.process_time()
        self.lib.chain_rhs_repeat(n_evals, self.n, *self.pointers)
        return time.process_time() - start


class NativeChain:
    """The native core's right-hand side for one scene and state: ``solver`` 'chain' (the path a chain gets)
    or 'ldl' (the sparse LDL^T on the same elimination order, by declaring the structure a tree); ``planar``:
    the 2-D stage in the plane's coordinates (the scene and state must be planar)."""

    def __init__(self, dyn, X, U, solver: str = "chain", planar: bool = False):
        structure = dyn.structure
        if solver == "ldl":
            structure = dataclasses.replace(structure, kind="tree")
        self.model = NativeModel(dyn.scene, structure, planar=None if planar else False)
        if self.model.solver != solver:
            raise RuntimeError(f"asked for the {solver} path, the model took {self.model.solver}")
        if planar and self.model.plane is None:
            raise RuntimeError("the scene is not planar")
        self.data = NativeData(self.model)
        self.data.F_input.fill(0.0)
        self.dim = 2 if planar else 3
        if planar:
            P, o, _, _ = self.model.plane
            self.P = P
            X, U = (X - o) @ P, U @ P
        self.X, self.U = np.ascontiguousarray(X, np.float64), np.ascontiguousarray(U, np.float64)
        self._args = (self.model.pointer, self.data._ptr, self.dim, native_lib.pointer(self.X),
                      native_lib.pointer(self.U))
        self.K = dyn.scene.K

    def evaluate(self):
        """(accelerations (K, 3) in world coordinates, tensions) of one evaluation."""
        status = native_lib.evaluate_repeated(*self._args, 1)
        if status != native_lib.OK:
            raise RuntimeError(f"native right-hand side returned {native_lib.STATUS.get(status, status)}")
        acc = self.data.acc.ravel()[:self.dim * self.K].reshape(self.K, self.dim).copy()
        if self.dim == 2:
            acc = acc @ self.P.T
        return acc, self.data.T.copy()

    def run(self, n_evals: int) -> float:
        """CPU seconds for n_evals evaluations in one C call."""
        start = time.process_time()
        native_lib.evaluate_repeated(*self._args, n_evals)
        return time.process_time() - start


def _relative(a, b):
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300))


def _time_per_eval(runner, budget: float, repeats: int) -> float:
    """Best of ``repeats`` timings of N evaluations, N chosen so that one timing takes about ``budget`` s."""
    n = 1
    while True:
        elapsed = runner.run(n)
        if elapsed >= 0.02 or n >= 10 ** 9:
            break
        n *= 10
    n = max(1, int(n * budget / max(elapsed, 1e-9)))
    return min(runner.run(n) for _ in range(repeats)) / n


def kernel_table(sizes=SIZES, budget=0.2, repeats=5, log=print):
    lib, flags, compiler = build_c_reference()
    lib_fused, _, _ = build_c_reference(source=C_SOURCE_FUSED)
    lib_fused_core, core_flags, _ = build_c_reference(source=C_SOURCE_FUSED, flags=CORE_FLAGS)
    rows = []
    for n in sizes:
        scene, dyn, X, U = random_chain_state(n)
        runners = {"c": CChain(lib, scene, X, U), "c_fused": CChain(lib_fused, scene, X, U),
                   "c_fused_core_flags": CChain(lib_fused_core, scene, X, U),
                   "native_chain": NativeChain(dyn, X, U, "chain"), "native_ldl": NativeChain(dyn, X, U, "ldl")}
        acc_np, T_np = dyn.accelerations(X, U)
        acc_c, T_c = runners["c"].evaluate()
        agreement = {}
        for label, runner in runners.items():
            acc, T = runner.evaluate()
            agreement[label] = {"acc_vs_numpy": _relative(acc, acc_np), "T_vs_numpy": _relative(T, T_np),
                                "acc_vs_c": _relative(acc, acc_c), "T_vs_c": _relative(T, T_c)}
        worst = max(v for d in agreement.values() for v in d.values())
        if not worst <= AGREEMENT_TOL:
            raise RuntimeError(f"chain of {n} links: the implementations disagree ({agreement}); not timing")
        # interleave the timings so that a change in the machine's load hits all of them alike
        times = {key: [] for key in runners}
        for _ in range(repeats):
            for key, runner in runners.items():
                times[key].append(_time_per_eval(runner, budget, 1))
        ns = {key: 1e9 * min(v) for key, v in times.items()}
        row = {"links": n, "c_ns": ns["c"], "c_fused_ns": ns["c_fused"],
               "c_fused_core_flags_ns": ns["c_fused_core_flags"], "linknet_ns": ns["native_chain"],
               "linknet_general_ns": ns["native_ldl"], "agreement": agreement, "worst_disagreement": worst}
        row["ratio"] = row["linknet_ns"] / row["c_ns"]
        row["ratio_fused"] = row["linknet_ns"] / row["c_fused_ns"]
        row["ratio_fused_core_flags"] = row["linknet_ns"] / row["c_fused_core_flags_ns"]
        row["ratio_general"] = row["linknet_general_ns"] / row["c_ns"]
        row["linknet_ns_per_link"] = row["linknet_ns"] / n
        row["c_ns_per_link"] = row["c_ns"] / n
        rows.append(row)
        log(f"{n:>6} links: C {row['c_ns']:>10.0f} ns  native {row['linknet_ns']:>10.0f} ns  ratio "
            f"{row['ratio']:5.2f}  ({row['linknet_ns_per_link']:.1f} ns/link; fused C {row['c_fused_ns']:.0f} ns, "
            f"ratio {row['ratio_fused']:.2f}; fused C at the core's flags {row['c_fused_core_flags_ns']:.0f} ns, "
            f"ratio {row['ratio_fused_core_flags']:.2f}; sparse LDL^T path {row['linknet_general_ns']:.0f} ns, "
            f"ratio {row['ratio_general']:.2f}); agreement {worst:.1e}")
    return {"compiler": compiler, "flags": flags, "core_flags": core_flags, "rows": rows}


def planar_kernel_table(sizes=(1,) + SIZES, budget=0.2, repeats=5, log=print):
    """The right-hand side of a planar chain (random walk in the x-z plane; 1 link: a pendulum) on the 3-D
    stage and on the 2-D one in the plane's coordinates, same state; both checked against numpy first."""
    rows = []
    for n in sizes:
        scene, dyn, X, U = random_chain_state(n, planar=True)
        paths = {"3d": NativeChain(dyn, X, U, "chain"), "2d": NativeChain(dyn, X, U, "chain", planar=True)}
        acc_np, T_np = dyn.accelerations(X, U)
        worst = 0.0
        for runner in paths.values():
            acc, T = runner.evaluate()
            worst = max(worst, _relative(acc, acc_np), _relative(T, T_np))
        if not worst <= AGREEMENT_TOL:
            raise RuntimeError(f"planar chain of {n} links: 2-D/3-D stages disagree with numpy ({worst:.1e})")
        times = {key: [] for key in paths}
        for _ in range(repeats):
            for key, runner in paths.items():
                times[key].append(_time_per_eval(runner, budget, 1))
        row = {"links": n, "ns_3d": 1e9 * min(times["3d"]), "ns_2d": 1e9 * min(times["2d"]), "agreement": worst}
        row["ratio_2d_3d"] = row["ns_2d"] / row["ns_3d"]
        rows.append(row)
        log(f"planar chain {n:>6} links: 3-D {row['ns_3d']:>10.0f} ns  2-D {row['ns_2d']:>10.0f} ns  "
            f"2-D/3-D {row['ratio_2d_3d']:.2f}; agreement with numpy {worst:.1e}")
    return {"rows": rows}


# ------------------------------------------------------------------------------------------------ part 2
INTEGRATOR_SCENES = {
    "pendulum": builders.pendulum,
    "double_pendulum": builders.double_pendulum,
    "chain_10": lambda: builders.chain(10),
    "chain_100": lambda: builders.chain(100),
    "net_10x10": lambda: builders.net(10, 10),
}


def _native_dim(sim):
    """2 or 3: the dimension the native core ran the last interval in (None off the native core)."""
    data = getattr(sim.integrator, "data", None)
    if data is None or not hasattr(data, "struct"):
        return None
    return 2 if data.struct.planar else 3


def _no_estimate() -> dict:
    """The kernel's time alone: no companion run of the error estimate (a tree before it has no such option)."""
    import inspect
    return {"error_estimate": False} if "error_estimate" in inspect.signature(ln.Simulator).parameters else {}


def _time_advance(scene, method, rtol, backend, t_end, repeats, numpy_budget, planar=True, dt=None):
    """CPU time of one Simulator.advance(t_end) (best of ``repeats``); ``planar`` False makes the native core
    run a planar scene in 3-D; ``dt`` for fixed-step methods (then rtol is None)."""
    sim = ln.Simulator(scene, method=method, rtol=rtol, dt=dt, backend=backend, **_no_estimate())
    if not planar and _native_dim(sim) == 2:
        # the data's mode is what the core reads at each interval: 3-D from the start, and after every reset
        sim.integrator.data.struct.planar = 0
        sim._initial_internals = sim.integrator.internals()
    sim.advance(1e-3)  # warm up (page in the library, allocate) outside the timing
    best = None
    for i in range(repeats):
        sim.reset()
        if backend == "numpy":
            sim.integrator.stats = type(sim.integrator.stats)()
        start = time.process_time()
        sim.advance(t_end)
        elapsed = time.process_time() - start
        best = elapsed if best is None else min(best, elapsed)
        if elapsed > numpy_budget:
            break
    stats = sim.integrator.stats.as_dict()
    return {"seconds": best, "steps": stats["steps"], "rejected": stats["rejected"],
            "us_per_step": 1e6 * best / max(stats["steps"], 1), "X": sim.state.X, "dim": _native_dim(sim)}


PLANAR_SCENES = ("pendulum", "double_pendulum", "chain_10", "chain_100")
PLANAR_METHODS = (("rattle", None, 1e-3), ("dopri5", 1e-8, None), ("dop853", 1e-10, None))
ROUND_RUNS, SHORT_RUN_S = 3, 2e-3
RATTLE_DT = {"chain_100": 1e-4}  # at 1e-3 the falling chain's tip whips faster than a step can follow


def planar_integrator_table(t_end=2.0, quick=False, log=print):
    """One Simulator.advance(t_end) of planar scenes on the native core in 2-D (the default) and forced onto
    3-D: time per run and per step, and the difference of the final positions."""
    rows = []
    scenes = PLANAR_SCENES[:3] if quick else PLANAR_SCENES
    for name in scenes:
        scene = INTEGRATOR_SCENES[name]()
        for method, rtol, dt in PLANAR_METHODS:
            dt = RATTLE_DT.get(name, dt) if dt else dt
            r = {"scene": name, "method": method, "rtol": rtol, "dt": dt}
            runs = {}
            rounds = 3 if quick else 5
            done = 0
            while done < rounds:  # interleaved: a change of the machine's load hits both alike
                for key, planar in (("3d", False), ("2d", True)):
                    out = _time_advance(scene, method, rtol, "native", t_end, repeats=ROUND_RUNS, numpy_budget=1e9,
                                        planar=planar, dt=dt)
                    if key not in runs or out["seconds"] < runs[key]["seconds"]:
                        runs[key] = out
                done += 1
                if done == 1 and runs["3d"]["seconds"] < SHORT_RUN_S and not quick:
                    rounds = 4 * rounds  # sub-millisecond runs: the machine's noise is as large as the difference
            r["runs_each"] = rounds * ROUND_RUNS
            for key in ("3d", "2d"):
                r[key] = {k: v for k, v in runs[key].items() if k != "X"}
            if runs["2d"]["dim"] != 2 or runs["3d"]["dim"] != 3:
                raise RuntimeError(f"{name} {method}: the runs did not stay in 2-D and 3-D")
            r["ratio_2d_3d"] = runs["2d"]["seconds"] / runs["3d"]["seconds"]
            r["max_position_difference_m"] = float(np.max(np.abs(runs["2d"]["X"] - runs["3d"]["X"])))
            rows.append(r)
            setting = f"dt {dt:g}" if dt else f"rtol {rtol:.0e}"
            log(f"{name:>16} {method:>7} {setting}: 3-D {1e3 * r['3d']['seconds']:8.3f} ms "
                f"({r['3d']['us_per_step']:7.2f} us/step) | 2-D {1e3 * r['2d']['seconds']:8.3f} ms "
                f"({r['2d']['us_per_step']:7.2f} us/step) | 2-D/3-D {r['ratio_2d_3d']:.2f}, |dX| "
                f"{r['max_position_difference_m']:.0e} m")
    return {"t_end": t_end, "rows": rows}


def _sensitivity(scene, method, rtol, t_end, kick=1e-13):
    """How far apart two native runs end when one starts with the last mass moved by ``kick`` metres: the
    amplification of round-off by the dynamics (chaotic scenes), the scale for comparing the two paths."""
    ends = []
    for dz in (0.0, kick):
        sim = ln.Simulator(scene, method=method, rtol=rtol, backend="native", **_no_estimate())
        sim.state.X = sim.state.X.copy()
        sim.state.X[-1, 2] += dz
        sim.advance(t_end)
        ends.append(sim.state.X)
    return float(np.max(np.abs(ends[0] - ends[1])))


def integrator_table(t_end=2.0, quick=False, log=print):
    rows = []
    methods = ("dopri5", "dop853")
    scenes = ["pendulum", "double_pendulum", "chain_10"] if quick else list(INTEGRATOR_SCENES)
    for name in scenes:
        scene = INTEGRATOR_SCENES[name]()
        for method in methods:
            for rtol in (1e-6, 1e-10):
                r = {"scene": name, "method": method, "rtol": rtol}
                for backend in ("numpy", "native"):
                    out = _time_advance(scene, method, rtol, backend, t_end, repeats=1 if backend == "numpy" else 5,
                                        numpy_budget=1.0)
                    r[backend] = {k: v for k, v in out.items() if k != "X"}
                    r[backend + "_X"] = out["X"]
                r["speedup"] = r["numpy"]["seconds"] / r["native"]["seconds"]
                r["max_position_difference_m"] = float(np.max(np.abs(r.pop("numpy_X") - r.pop("native_X"))))
                r["sensitivity_m"] = _sensitivity(scene, method, rtol, t_end)
                rows.append(r)
                log(f"{name:>16} {method:>6} rtol {rtol:.0e}: numpy {r['numpy']['steps']:>6} steps "
                    f"{1e3 * r['numpy']['seconds']:>10.2f} ms ({r['numpy']['us_per_step']:8.1f} us/step) | native "
                    f"{r['native']['steps']:>6} steps {1e3 * r['native']['seconds']:>9.3f} ms "
                    f"({r['native']['us_per_step']:7.2f} us/step) | x{r['speedup']:.0f}, |dX| "
                    f"{r['max_position_difference_m']:.1e} m (1e-13 m kick: {r['sensitivity_m']:.1e} m)")
    return {"t_end": t_end, "rows": rows}


# ------------------------------------------------------------------------------------------------ output
def write_outputs(out: Path, result: dict) -> None:
    write_text(out / "kernel.json", json.dumps(result, indent=1, sort_keys=True))
    meta = result["meta"]
    lines = ["# Native core vs plain C", "",
             f"`{meta['command']}` on {meta['machine']} ({meta['cpus']} CPUs), Python {meta['python']}, "
             f"{meta['date']}, load average {meta['load_start']} at the start, {meta['load_end']} at the end.", ""]
    k = result.get("kernel")
    if k:
        lines += [
            "## Right-hand side of a chain with one anchored end",
            "",
            "One evaluation: gravity, A of (25) (tridiagonal) and B of (26), the tension solve, accelerations (9). "
            f"C: `benchmarks/c_reference/chain_rhs.c` built with `{k['flags']}` ({k['compiler']}), N evaluations "
            "in a loop inside C. linknet: the native core's right-hand side stage (`ln_accelerations`, what its "
            "integrators call; tridiagonal path chosen for chains), N evaluations in one C call "
            "(`ln_evaluate_repeated`). CPU time (time.process_time), best of "
            f"{meta['repeats']} interleaved timings. Inputs: random-walk chain, random masses, random velocities "
            "projected onto (12). Before timing the implementations (C, native, numpy) agree to the relative "
            "difference in the last column.",
            "",
            "The plain C reference does forces, assembly of A and B, Thomas forward elimination, back substitution "
            "and accelerations in separate loops. The native chain path does the assembly, the pivots, B and the "
            "forward substitution in one sweep and the back substitution, with the link forces, in a second. "
            "`c_reference/chain_rhs_fused.c` is the same two-sweep kernel written by hand for this one chain "
            f"layout: built with the reference's flags, and with the native core's (`{k['core_flags']}`). The "
            "sparse LDL^T path (the same chain declared a tree: what it would get without the specialisation) is "
            "in the second-to-last column.",
            "",
            "| links | C ns/eval | native ns/eval | ratio | native ns/link | C ns/link | fused C ns/eval (ratio) "
            "| fused C, core's flags (ratio) | sparse LDL^T path ns/eval (ratio) | agreement |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in k["rows"]:
            lines.append(f"| {r['links']} | {r['c_ns']:.0f} | {r['linknet_ns']:.0f} | {r['ratio']:.2f} | "
                         f"{r['linknet_ns_per_link']:.1f} | {r['c_ns_per_link']:.1f} | {r['c_fused_ns']:.0f} "
                         f"({r['ratio_fused']:.2f}) | {r['c_fused_core_flags_ns']:.0f} "
                         f"({r['ratio_fused_core_flags']:.2f}) | {r['linknet_general_ns']:.0f} "
                         f"({r['ratio_general']:.2f}) | {r['worst_disagreement']:.0e} |")
        lines.append("")
    pk = result.get("planar_kernel")
    if pk:
        lines += [
            "## Planar scenes: right-hand side in 2-D vs 3-D",
            "",
            "A chain anchored at one end in a random-walk shape in the x-z plane (1 link: a pendulum), random "
            "masses and in-plane velocities projected onto (12), gravity in the plane. Same state, same "
            "tridiagonal path: the native stage compiled for 3 components per vector (`ln_accelerations_3d`) vs "
            "for 2 (`ln_accelerations_2d`, state in the plane's coordinates), N evaluations in one C call, best "
            "of interleaved CPU timings. Both agree with the numpy path to the last column before timing.",
            "",
            "| links | 3-D ns/eval | 2-D ns/eval | 2-D / 3-D | agreement |",
            "|---:|---:|---:|---:|---:|"]
        for r in pk["rows"]:
            lines.append(f"| {r['links']} | {r['ns_3d']:.0f} | {r['ns_2d']:.0f} | {r['ratio_2d_3d']:.2f} | "
                         f"{r['agreement']:.0e} |")
        lines.append("")
    pi = result.get("planar_integrators")
    if pi:
        lines += [
            f"## Planar scenes: one native `Simulator.advance({pi['t_end']:g})` in 2-D vs 3-D",
            "",
            "The same native integrator in 2-D (what a planar scene gets) and forced onto 3-D; CPU time of one "
            "call covering the whole run, best of the interleaved runs (5 rounds of 3 runs each, 20 rounds for "
            "runs under 2 ms, where the shared machine's noise is ~10-30%), after a warm-up call (includes the "
            "Simulator's per-call work and, in 2-D, the mapping into the plane and back). abs(dX): largest "
            "difference of the final positions (the shipped scenes lie in the x-z plane: the reduction is exact, "
            "and the two runs do the same arithmetic on the in-plane coordinates).",
            "",
            "| scene | method | dt / rtol | steps | 3-D ms | 3-D us/step | 2-D ms | 2-D us/step | 2-D / 3-D "
            "| abs(dX) m |",
            "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in pi["rows"]:
            a, b = r["3d"], r["2d"]
            setting = f"dt {r['dt']:g}" if r["dt"] else f"rtol {r['rtol']:.0e}"
            lines.append(f"| {r['scene']} | {r['method']} | {setting} | {b['steps']} | {1e3 * a['seconds']:.3f} | "
                         f"{a['us_per_step']:.2f} | {1e3 * b['seconds']:.3f} | {b['us_per_step']:.2f} | "
                         f"{r['ratio_2d_3d']:.2f} | {r['max_position_difference_m']:.0e} |")
        lines.append("")
    it = result.get("integrators")
    if it:
        lines += [
            f"## Adaptive Runge-Kutta, numpy vs native: one `Simulator.advance({it['t_end']:g})`",
            "",
            "CPU time of one call covering the whole run (native: best of 5; numpy: one run), after a warm-up "
            "call; it includes the Simulator's per-call work. abs(dX): largest difference of the final positions "
            "of the two paths. kick: the same for two native runs whose initial positions differ by 1e-13 m (one "
            "coordinate of the last mass): where it is large the scene is chaotic over the run and round-off "
            "differences between the paths grow the same way (and can change the step sequence).",
            "",
            "| scene | method | rtol | steps (rejected) numpy / native | numpy ms | numpy us/step | native ms "
            "| native us/step | speed-up | abs(dX) m | kick 1e-13 m: abs(dX) m |",
            "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in it["rows"]:
            n, c = r["numpy"], r["native"]
            lines.append(f"| {r['scene']} | {r['method']} | {r['rtol']:.0e} | {n['steps']} ({n['rejected']}) / "
                         f"{c['steps']} ({c['rejected']}) | {1e3 * n['seconds']:.2f} | {n['us_per_step']:.1f} | "
                         f"{1e3 * c['seconds']:.3f} | {c['us_per_step']:.2f} | {r['speedup']:.0f} | "
                         f"{r['max_position_difference_m']:.0e} | {r['sensitivity_m']:.0e} |")
        lines.append("")
    write_text(out / "kernel.md", "\n".join(lines))


def _load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="short timings (and fewer integrator scenes)")
    ap.add_argument("--integrators", action="store_true", help="also part 2: whole runs, numpy vs native")
    ap.add_argument("--no-kernel", action="store_true", help="skip part 1")
    add_output_arguments(ap, "kernel", quick=True)
    args = ap.parse_args(argv)
    out = resolve(ap, args, "kernel", quick=args.quick)

    repeats = 3 if args.quick else 5
    result = {"meta": {"command": "python -m benchmarks.bench_kernel " + " ".join(argv if argv is not None
                                                                                  else sys.argv[1:]),
                       "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                       "python": platform.python_version(), "repeats": repeats, "quick": args.quick,
                       "python_cflags": sysconfig.get_config_var("CFLAGS"),
                       "date": time.strftime("%Y-%m-%d %H:%M %Z"), "load_start": _load()}}
    if not args.no_kernel:
        result["kernel"] = kernel_table(budget=0.05 if args.quick else 0.2, repeats=repeats)
        result["planar_kernel"] = planar_kernel_table(budget=0.05 if args.quick else 0.2, repeats=repeats)
    if args.integrators:
        result["planar_integrators"] = planar_integrator_table(quick=args.quick)
        result["integrators"] = integrator_table(quick=args.quick)
    result["meta"]["load_end"] = _load()
    write_outputs(out, result)
    print(f"wrote {out / 'kernel.json'} and {out / 'kernel.md'}")
    return result


if __name__ == "__main__":
    main()
