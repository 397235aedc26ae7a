"""Issue 6: is linknet's compiled kernel near the machine's limit?

Part 1 - right-hand side vs plain C. One evaluation of the right-hand side for a chain with one anchored end
(external forces = gravity, A of (25) tridiagonal and B of (26), the tension solve, accelerations (9)), timed
for chains of 10, 100, 1000 and 10000 links:

* C: benchmarks/c_reference/chain_rhs.c, plain C (Thomas elimination), compiled here with the system C
  compiler (``cc -O2 -shared -fPIC``, no -march, no -ffast-math), loaded with ctypes, N evaluations in a loop
  inside C (one ctypes call per timing); and chain_rhs_fused.c, the same kernel hand-fused into two sweeps
  (same flags), for what hand-written C reaches;
* linknet: the compiled right-hand side the compiled integrators call (linknet_core.compiled.accelerations,
  on the path the scene gets: tridiagonal for chains; the general sparse LDL^T path is timed too, for
  comparison), N evaluations in a numba loop (compiled.accelerations_repeated), same inputs.

Before timing, the C result, the compiled one and the numpy Dynamics.accelerations are checked to agree to
round-off. Times are CPU time of this process (time.process_time: robust to other processes on a shared
machine), best of several interleaved timings. Inputs: a random-walk chain (random link directions and
masses, total length and mass 1) with random velocities projected onto (12), so that every term of
(25)-(26) is exercised.

Part 2 (``--integrators``) - adaptive Runge-Kutta, numpy vs compiled: time per step and total time of one
``Simulator.advance(2.0)`` for several scenes and tolerances (CPU time), the difference of the two paths'
final positions, and how much the scene amplifies a 1e-13 m change of its initial state.

Planar scenes: part 1 also times the right-hand side of a planar chain (and a pendulum) on the 2-D kernels
against the 3-D ones; part 2 also times whole compiled runs of the planar scenes (pendulum, double
pendulum, chain_10, chain_100; RATTLE, DOPRI5, DOP853) in 2-D and forced onto the 3-D kernels.

    python -m benchmarks.bench_kernel [--quick] [--integrators] [--out DIR]

Writes DIR/kernel.json and DIR/kernel.md (default docs/benchmarks, or docs/benchmarks/quick with --quick).
Measures only; asserts nothing but the agreement of the implementations.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import linknet_core as ln
from linknet_core import builders, compiled
from linknet_core.codegen import compiler

ROOT = Path(__file__).resolve().parent.parent
C_SOURCE = Path(__file__).resolve().parent / "c_reference" / "chain_rhs.c"
C_SOURCE_FUSED = Path(__file__).resolve().parent / "c_reference" / "chain_rhs_fused.c"
C_FLAGS = ["-O2", "-shared", "-fPIC"]
SIZES = (10, 100, 1000, 10000)
AGREEMENT_TOL = 1e-9  # relative (to the largest entry) agreement demanded of the three implementations

_P = ctypes.POINTER(ctypes.c_double)


class CUnavailable(RuntimeError):
    pass


def build_c_reference(workdir: Path | None = None, source: Path = C_SOURCE):
    """Compile a C reference (default chain_rhs.c) into a shared library and load it; returns (library,
    compiler command line, compiler version)."""
    cc = compiler()  # $CC, cc, gcc or clang (linknet_core.codegen)
    if cc is None:
        raise CUnavailable("no C compiler (cc, gcc or clang) on PATH")
    workdir = Path(workdir or tempfile.mkdtemp(prefix="linknet_c_reference_"))
    lib_path = workdir / (source.stem + ".so")
    cmd = [cc, *C_FLAGS, "-o", str(lib_path), str(source)]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise CUnavailable(f"{' '.join(cmd)} failed:\n{proc.stderr}")
    lib = ctypes.CDLL(str(lib_path))
    lib.chain_rhs.restype = None
    lib.chain_rhs.argtypes = [ctypes.c_int] + [_P] * 12
    lib.chain_rhs_repeat.restype = ctypes.c_double
    lib.chain_rhs_repeat.argtypes = [ctypes.c_long, ctypes.c_int] + [_P] * 12
    version = subprocess.run([cc, "--version"], capture_output=True, text=True).stdout.splitlines()
    return lib, " ".join([cc, *C_FLAGS]), (version[0] if version else cc)


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


class LinknetChain:
    """linknet's compiled right-hand side for one scene (chain path, or the general sparse path)."""

    def __init__(self, dyn, X, U, use_chain, planar=False):
        """``planar``: the 2-D kernels in the plane's coordinates (the scene and state must be planar)."""
        self.kernel = compiled.CompiledScene(dyn, use_chain=use_chain, planar=True if planar else False)
        self.planar = planar
        self.X, self.U = X, U
        self.F_base = self.kernel.base_forces(None)
        if planar:
            k = self.kernel
            self.X, self.U, self.F_base = k.to_plane(X, True), k.to_plane(U, False), k.to_plane(self.F_base, False)
        self.acc = np.zeros((dyn.scene.K, self.X.shape[1]))
        self.T = np.zeros(dyn.scene.L)
        self.run(2)  # compile (or load from the cache) outside the timing

    def evaluate(self):
        if self.planar:
            status, acc, T = self.kernel.accelerations(self.kernel.from_plane(self.X, True),
                                                       self.kernel.from_plane(self.U, False), planar=True)
        else:
            status, acc, T = self.kernel.accelerations(self.X, self.U)
        if status != compiled.OK:
            raise RuntimeError(f"compiled right-hand side returned status {status}")
        return acc, T

    def run(self, n_evals: int) -> float:
        k = self.kernel
        start = time.process_time()
        compiled.accelerations_repeated(n_evals, self.X, self.U, self.F_base, k.scene, k.system, self.acc, self.T)
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
    rows = []
    for n in sizes:
        scene, dyn, X, U = random_chain_state(n)
        c_kernel = CChain(lib, scene, X, U)
        c_fused = CChain(lib_fused, scene, X, U)
        chain_path = LinknetChain(dyn, X, U, use_chain=True)
        general_path = LinknetChain(dyn, X, U, use_chain=False)
        acc_np, T_np = dyn.accelerations(X, U)
        acc_c, T_c = c_kernel.evaluate()
        agreement = {}
        for label, (acc, T) in (("c", (acc_c, T_c)), ("c_fused", c_fused.evaluate()),
                                ("linknet_chain", chain_path.evaluate()),
                                ("linknet_general", general_path.evaluate())):
            agreement[label] = {"acc_vs_numpy": _relative(acc, acc_np), "T_vs_numpy": _relative(T, T_np),
                                "acc_vs_c": _relative(acc, acc_c), "T_vs_c": _relative(T, T_c)}
        worst = max(v for d in agreement.values() for v in d.values())
        if not worst <= AGREEMENT_TOL:
            raise RuntimeError(f"chain of {n} links: the implementations disagree ({agreement}); not timing")
        # interleave the timings so that a change in the machine's load hits all three alike
        t_c, t_fused, t_chain, t_general = [], [], [], []
        for _ in range(repeats):
            t_c.append(_time_per_eval(c_kernel, budget, 1))
            t_fused.append(_time_per_eval(c_fused, budget, 1))
            t_chain.append(_time_per_eval(chain_path, budget, 1))
            t_general.append(_time_per_eval(general_path, budget, 1))
        row = {"links": n, "c_ns": 1e9 * min(t_c), "c_fused_ns": 1e9 * min(t_fused), "linknet_ns": 1e9 * min(t_chain),
               "linknet_general_ns": 1e9 * min(t_general), "agreement": agreement, "worst_disagreement": worst}
        row["ratio"] = row["linknet_ns"] / row["c_ns"]
        row["ratio_fused"] = row["linknet_ns"] / row["c_fused_ns"]
        row["ratio_general"] = row["linknet_general_ns"] / row["c_ns"]
        row["linknet_ns_per_link"] = row["linknet_ns"] / n
        row["c_ns_per_link"] = row["c_ns"] / n
        rows.append(row)
        log(f"{n:>6} links: C {row['c_ns']:>12.0f} ns  linknet {row['linknet_ns']:>12.0f} ns  ratio "
            f"{row['ratio']:5.2f}  ({row['linknet_ns_per_link']:.1f} ns/link; fused C {row['c_fused_ns']:.0f} ns, "
            f"ratio {row['ratio_fused']:.2f}; general sparse path "
            f"{row['linknet_general_ns']:.0f} ns, ratio {row['ratio_general']:.2f}); agreement {worst:.1e}")
    return {"compiler": compiler, "flags": flags, "rows": rows}


def planar_kernel_table(sizes=(1,) + SIZES, budget=0.2, repeats=5, log=print):
    """The right-hand side of a planar chain (random walk in the x-z plane; 1 link: a pendulum) on the 3-D
    kernels and on the 2-D ones in the plane's coordinates, same state; both checked against numpy first."""
    rows = []
    for n in sizes:
        scene, dyn, X, U = random_chain_state(n, planar=True)
        paths = {"3d": LinknetChain(dyn, X, U, use_chain=True), "2d": LinknetChain(dyn, X, U, use_chain=True,
                                                                                 planar=True)}
        acc_np, T_np = dyn.accelerations(X, U)
        worst = 0.0
        for runner in paths.values():
            acc, T = runner.evaluate()
            worst = max(worst, _relative(acc, acc_np), _relative(T, T_np))
        if not worst <= AGREEMENT_TOL:
            raise RuntimeError(f"planar chain of {n} links: 2-D/3-D kernels disagree with numpy ({worst:.1e})")
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


def _time_advance(scene, method, rtol, backend, t_end, repeats, numpy_budget, planar=True, dt=None):
    """CPU time of one Simulator.advance(t_end) (best of ``repeats``); ``planar`` False makes the compiled
    kernel of a planar scene run on the 3-D kernels; ``dt`` for fixed-step methods (then rtol is None)."""
    sim = ln.Simulator(scene, method=method, rtol=rtol, dt=dt, backend=backend)
    if not planar and getattr(sim.integrator, "_kernel", None) is not None:
        sim.integrator._kernel.force_3d()
    sim.advance(1e-3)  # compile / warm up outside the timing
    best = None
    for i in range(repeats):
        sim.reset()
        sim.integrator.stats = type(sim.integrator.stats)()
        start = time.process_time()
        sim.advance(t_end)
        elapsed = time.process_time() - start
        best = elapsed if best is None else min(best, elapsed)
        if elapsed > numpy_budget:
            break
    stats = sim.integrator.stats.as_dict()
    kernel = getattr(sim.integrator, "_kernel", None)
    return {"seconds": best, "steps": stats["steps"], "rejected": stats["rejected"],
            "us_per_step": 1e6 * best / max(stats["steps"], 1), "X": sim.state.X,
            "dim": None if kernel is None else kernel.dim}


PLANAR_SCENES = ("pendulum", "double_pendulum", "chain_10", "chain_100")
PLANAR_METHODS = (("rattle", None, 1e-3), ("dopri5", 1e-8, None), ("dop853", 1e-10, None))
ROUND_RUNS, SHORT_RUN_S = 3, 2e-3
RATTLE_DT = {"chain_100": 1e-4}  # at 1e-3 the falling chain's tip whips faster than a step can follow


def planar_integrator_table(t_end=2.0, quick=False, log=print):
    """One Simulator.advance(t_end) of planar scenes with the compiled kernels in 2-D (the default) and
    forced onto the 3-D kernels: time per run and per step, and the difference of the final positions."""
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
                    out = _time_advance(scene, method, rtol, "compiled", t_end, repeats=ROUND_RUNS, numpy_budget=1e9,
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
                raise RuntimeError(f"{name} {method}: the runs did not take the 2-D and 3-D kernels")
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
    """How far apart two compiled runs end when one starts with the last mass moved by ``kick`` metres: the
    amplification of round-off by the dynamics (chaotic scenes), the scale for comparing the two paths."""
    ends = []
    for dz in (0.0, kick):
        sim = ln.Simulator(scene, method=method, rtol=rtol)
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
                for backend in ("numpy", "compiled"):
                    out = _time_advance(scene, method, rtol, backend, t_end, repeats=1 if backend == "numpy" else 5,
                                        numpy_budget=1.0)
                    r[backend] = {k: v for k, v in out.items() if k != "X"}
                    r[backend + "_X"] = out["X"]
                r["speedup"] = r["numpy"]["seconds"] / r["compiled"]["seconds"]
                r["max_position_difference_m"] = float(np.max(np.abs(r.pop("numpy_X") - r.pop("compiled_X"))))
                r["sensitivity_m"] = _sensitivity(scene, method, rtol, t_end)
                rows.append(r)
                log(f"{name:>16} {method:>6} rtol {rtol:.0e}: numpy {r['numpy']['steps']:>6} steps "
                    f"{1e3 * r['numpy']['seconds']:>10.2f} ms ({r['numpy']['us_per_step']:8.1f} us/step) | compiled "
                    f"{r['compiled']['steps']:>6} steps {1e3 * r['compiled']['seconds']:>9.3f} ms "
                    f"({r['compiled']['us_per_step']:7.2f} us/step) | x{r['speedup']:.0f}, |dX| "
                    f"{r['max_position_difference_m']:.1e} m (1e-13 m kick: {r['sensitivity_m']:.1e} m)")
    return {"t_end": t_end, "rows": rows}


# ------------------------------------------------------------------------------------------------ output
def write_outputs(out: Path, result: dict) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "kernel.json").write_text(json.dumps(result, indent=1, sort_keys=True))
    meta = result["meta"]
    lines = ["# Compiled kernel vs plain C (issue 6)", "",
             f"`{meta['command']}` on {meta['machine']} ({meta['cpus']} CPUs), Python {meta['python']}, "
             f"numba {meta['numba']}.", ""]
    k = result.get("kernel")
    if k:
        lines += [
            "## Right-hand side of a chain with one anchored end",
            "",
            "One evaluation: gravity, A of (25) (tridiagonal) and B of (26), the tension solve, accelerations (9). "
            f"C: `benchmarks/c_reference/chain_rhs.c` built with `{k['flags']}` ({k['compiler']}), N evaluations "
            "in a loop inside C. linknet: `linknet_core.compiled.accelerations` (the right-hand side the compiled "
            "integrators call; tridiagonal path chosen for chains), N evaluations in a numba loop. CPU time "
            f"(time.process_time), best of {meta['repeats']} interleaved timings. Inputs: random-walk chain, random "
            "masses, random velocities projected onto (12). Before timing the three implementations (C, compiled, "
            "numpy) agree to the relative difference in the last column.",
            "",
            "The C reference is written plainly: forces, assembly of A and B, Thomas forward elimination, back "
            "substitution and accelerations in separate loops. linknet's chain path does the assembly, the pivots, "
            "B and the forward substitution in one sweep and the back substitution in a second, so the arithmetic "
            "hides in the shadow of the elimination's dependency chain; that is why it beats this C. A second C "
            "kernel written the same fused way (`c_reference/chain_rhs_fused.c`, same flags) shows what "
            "hand-written C reaches: linknet stays behind it by the cost of its generality (index arrays for the "
            "link ends and the path order, the general scatter of the link forces). "
            "linknet's general sparse LDL^T path (what a chain would get without the specialisation) is in the "
            "second-to-last column.",
            "",
            "| links | C ns/eval | linknet ns/eval | ratio | linknet ns/link | C ns/link | fused C ns/eval (ratio) "
            "| general sparse path ns/eval (ratio) | agreement |",
            "|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in k["rows"]:
            lines.append(f"| {r['links']} | {r['c_ns']:.0f} | {r['linknet_ns']:.0f} | {r['ratio']:.2f} | "
                         f"{r['linknet_ns_per_link']:.1f} | {r['c_ns_per_link']:.1f} | {r['c_fused_ns']:.0f} "
                         f"({r['ratio_fused']:.2f}) | {r['linknet_general_ns']:.0f} ({r['ratio_general']:.2f}) | "
                         f"{r['worst_disagreement']:.0e} |")
        lines.append("")
    pk = result.get("planar_kernel")
    if pk:
        lines += [
            "## Planar scenes: right-hand side on the 2-D kernels vs the 3-D ones",
            "",
            "A chain anchored at one end in a random-walk shape in the x-z plane (1 link: a pendulum), random "
            "masses and in-plane velocities projected onto (12), gravity in the plane. Same state, same "
            "tridiagonal path: `compiled_kernels.accelerations` (3 components per vector) vs "
            "`compiled_kernels_2d.accelerations` in the plane's coordinates (2 components), N evaluations in a "
            "numba loop, best of interleaved CPU timings. Both agree with the numpy path to the last column "
            "before timing.",
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
            f"## Planar scenes: one compiled `Simulator.advance({pi['t_end']:g})` in 2-D vs 3-D",
            "",
            "The same compiled integrator on the 2-D kernels (what a planar scene gets) and forced onto the 3-D "
            "kernels; CPU time of one call covering the whole run, best of the interleaved runs (5 rounds of 3 "
            "runs each, 20 rounds for runs under 2 ms, where the shared machine's noise is ~10-30%), after a warm-up "
            "call (includes the Simulator's per-call work and, in 2-D, the mapping into the plane and back). "
            "abs(dX): largest difference of the final positions (the shipped scenes lie in the x-z plane: the "
            "reduction is exact, and the two runs do the same arithmetic on the in-plane coordinates).",
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
            f"## Adaptive Runge-Kutta, numpy vs compiled: one `Simulator.advance({it['t_end']:g})`",
            "",
            "CPU time of one call covering the whole run (compiled: best of 5; numpy: one run), after a warm-up "
            "call; it includes the Simulator's per-call work. abs(dX): largest difference of the final positions "
            "of the two paths. kick: the same for two compiled runs whose initial positions differ by 1e-13 m (one "
            "coordinate of the last mass): where it is large the scene is chaotic over the run and round-off "
            "differences between the paths grow the same way (and can change the step sequence).",
            "",
            "| scene | method | rtol | steps (rejected) numpy / compiled | numpy ms | numpy us/step | compiled ms "
            "| compiled us/step | speed-up | abs(dX) m | kick 1e-13 m: abs(dX) m |",
            "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|"]
        for r in it["rows"]:
            n, c = r["numpy"], r["compiled"]
            lines.append(f"| {r['scene']} | {r['method']} | {r['rtol']:.0e} | {n['steps']} ({n['rejected']}) / "
                         f"{c['steps']} ({c['rejected']}) | {1e3 * n['seconds']:.2f} | {n['us_per_step']:.1f} | "
                         f"{1e3 * c['seconds']:.3f} | {c['us_per_step']:.2f} | {r['speedup']:.0f} | "
                         f"{r['max_position_difference_m']:.0e} | {r['sensitivity_m']:.0e} |")
        lines.append("")
    (out / "kernel.md").write_text("\n".join(lines))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="short timings (and fewer integrator scenes)")
    ap.add_argument("--integrators", action="store_true", help="also part 2: adaptive Runge-Kutta numpy vs compiled")
    ap.add_argument("--no-kernel", action="store_true", help="skip part 1")
    ap.add_argument("--out", type=Path, help="output folder (default docs/benchmarks, or docs/benchmarks/quick)")
    args = ap.parse_args(argv)
    import numba

    repeats = 3 if args.quick else 5
    result = {"meta": {"command": "python -m benchmarks.bench_kernel " + " ".join(argv if argv is not None
                                                                                  else sys.argv[1:]),
                       "machine": platform.processor() or platform.machine(), "cpus": os.cpu_count(),
                       "python": platform.python_version(), "numba": numba.__version__, "repeats": repeats,
                       "quick": args.quick}}
    if not args.no_kernel:
        result["kernel"] = kernel_table(budget=0.05 if args.quick else 0.2, repeats=repeats)
        result["planar_kernel"] = planar_kernel_table(budget=0.05 if args.quick else 0.2, repeats=repeats)
    if args.integrators:
        result["planar_integrators"] = planar_integrator_table(quick=args.quick)
        result["integrators"] = integrator_table(quick=args.quick)
    out = args.out or (ROOT / "docs" / "benchmarks" / ("quick" if args.quick else ""))
    write_outputs(out, result)
    print(f"wrote {out / 'kernel.json'} and {out / 'kernel.md'}")
    return result


if __name__ == "__main__":
    main()
