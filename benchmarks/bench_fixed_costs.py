"""Fixed costs of a run: what a call costs beyond the integration it does.

Measured on whichever linknet_core is imported, through the public API only (``ln.load_scene``,
``ln.Simulator`` with ``advance`` and ``reset``, ``ln.simulate``, ``sim.integrator.stats``), so that the same
script times any tree of the package (put it first on PYTHONPATH):

(a) a whole 2 s pendulum run (DOP853 at rtol 1e-4; RATTLE at dt 1e-3) as the first ``advance(2.0)`` of a
    fresh Simulator, and as a repeated ``advance(2.0)`` after ``reset()``; its integration part is the
    per-step time of one long advance (many steps in one call) times the run's steps;
(b) each further ``advance`` of one step (RATTLE, dt 1e-3: chain_10, chain_100, pendulum): N calls of one
    step against one call of N steps along the same trajectory; the difference per call is the cost of a call
    beyond its integration;
(c) ``Simulator(...)`` construction;
(d) ``ln.simulate`` of the pendulum run: default outputs (201 samples), and 2 samples (start and end), whose
    excess over the integration is simulate's fixed cost.

Every figure is CPU time of this process (time.process_time) over a batch of calls, divided by the batch,
best of ``--repeats`` batches, with the garbage collector off inside a batch. The scene files are the
imported tree's ``models/``. A warm-up runs every configuration once first: with a JIT-compiled core this
loads its cache, so that only the per-call work is measured.

    python benchmarks/bench_fixed_costs.py [--repeats 7] [--json OUT]            # the imported tree
    python benchmarks/bench_fixed_costs.py --trees before=/work/before after=/work/main --rounds 3 --out DIR
    python benchmarks/bench_fixed_costs.py --breakdown [--json OUT]             # native tree: where a call goes

With ``--trees`` the script runs itself once per tree and round in a fresh process (PYTHONPATH = the tree,
working directory = the tree, by file path so that nothing else shadows the package), interleaving the trees
round by round, and writes fixed_costs.json and fixed_costs.md (the best of all rounds per figure) into
build/native_vs_numba, or DIR (--out DIR), or with --merge the tracked docs/benchmarks/native_vs_numba.
"""
from __future__ import annotations

import argparse
import gc
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

STEP = 1e-3
RUN_T = 2.0
RUNS = {  # the whole-run configurations of (a) and (d): (scene, method, settings)
    "pendulum_dop853_rtol1e-4": ("pendulum", "dop853", {"rtol": 1e-4}),
    "pendulum_rattle_dt1e-3": ("pendulum", "rattle", {"dt": 1e-3}),
}
PER_CALL = {  # (b): one-step advances, RATTLE at dt 1e-3; N = calls per batch
    "pendulum": 1000, "chain_10": 500, "chain_100": 200,
}
LONG_RUN_T = {"pendulum_dop853_rtol1e-4": 400.0, "pendulum_rattle_dt1e-3": 40.0}


def _batch(fn, n, repeats):
    """Best over ``repeats`` of the CPU time of n calls of fn(i), per call (s)."""
    best = float("inf")
    for _ in range(repeats):
        gc.collect()
        gc.disable()
        try:
            start = time.process_time()
            for i in range(n):
                fn(i)
            elapsed = time.process_time() - start
        finally:
            gc.enable()
        best = min(best, elapsed / n)
    return best


def _timed(fn, repeats):
    """Best over ``repeats`` of the CPU time of one call of fn() (s), and fn's last result."""
    best, out = float("inf"), None
    for _ in range(repeats):
        gc.collect()
        gc.disable()
        try:
            start = time.process_time()
            out = fn()
            elapsed = time.process_time() - start
        finally:
            gc.enable()
        best = min(best, elapsed)
    return best, out


def measure(repeats: int = 7, log=print) -> dict:
    import linknet_core as ln

    tree = Path(ln.__file__).resolve().parent.parent
    scenes = {name: ln.load_scene(tree / "models" / f"{name}.json") for name in ("pendulum", "chain_10", "chain_100")}

    def simulator(name, method, settings):
        return ln.Simulator(scenes[name], method=method, **settings)

    # warm-up: every configuration once (a JIT-compiled core compiles or loads its cache here)
    for name, method, settings in RUNS.values():
        simulator(name, method, settings).advance(RUN_T)
        ln.simulate(scenes[name], RUN_T, method=method, n_out=2, **settings)
    for name in PER_CALL:
        sim = simulator(name, "rattle", {"dt": STEP})
        sim.advance(STEP)
        sim.advance(3 * STEP)

    out = {"linknet_core": str(Path(ln.__file__).resolve().parent), "runs": {}, "per_call": {}, "construction": {}}
    batch = 40
    for key, (name, method, settings) in RUNS.items():
        r = out["runs"][key] = {}
        # (a) first advance of a fresh Simulator: the simulators are built outside the timing
        best = float("inf")
        for _ in range(repeats):
            sims = [simulator(name, method, settings) for _ in range(batch)]
            best = min(best, _batch(lambda i: sims[i].advance(RUN_T), batch, 1))
        r["first_advance_s"] = best
        steps = simulator(name, method, settings)
        steps.advance(RUN_T)
        r["steps"] = int(steps.integrator.stats.steps)
        # the same run repeated on one Simulator (reset outside the timing)
        sim = simulator(name, method, settings)
        sim.advance(RUN_T)
        best = float("inf")
        for _ in range(repeats):
            total = 0.0
            gc.collect()
            gc.disable()
            try:
                for _ in range(batch):
                    sim.reset()
                    start = time.process_time()
                    sim.advance(RUN_T)
                    total += time.process_time() - start
            finally:
                gc.enable()
            best = min(best, total / batch)
        r["repeat_advance_s"] = best
        # integration per step: one long advance, many steps in one call
        t_long = LONG_RUN_T[key]

        def long_run():
            s = simulator(name, method, settings)
            s.advance(STEP)
            steps_before = int(s.integrator.stats.steps)
            start = time.process_time()
            s.advance(STEP + t_long)
            return time.process_time() - start, int(s.integrator.stats.steps) - steps_before

        per_step = float("inf")
        for _ in range(max(3, repeats // 2)):
            gc.collect()
            gc.disable()
            try:
                elapsed, n = long_run()
            finally:
                gc.enable()
            per_step = min(per_step, elapsed / n)
        r["integration_per_step_s"] = per_step
        r["integration_s"] = per_step * r["steps"]
        r["first_advance_fixed_s"] = r["first_advance_s"] - r["integration_s"]
        r["repeat_advance_fixed_s"] = r["repeat_advance_s"] - r["integration_s"]
        # (c) construction
        r["construction_s"] = _batch(lambda i: simulator(name, method, settings), 20, repeats)
        # (d) simulate: 2 samples (the run's start and end), and the default 201
        r["simulate_2_samples_s"] = _batch(
            lambda i: ln.simulate(scenes[name], RUN_T, method=method, n_out=2, **settings), 10, repeats)
        r["simulate_201_samples_s"] = _batch(
            lambda i: ln.simulate(scenes[name], RUN_T, method=method, **settings), 3, repeats)
        r["simulate_fixed_s"] = r["simulate_2_samples_s"] - r["integration_s"]
        log(f"{key}: steps {r['steps']}, first advance {1e6 * r['first_advance_s']:.1f} us, repeated "
            f"{1e6 * r['repeat_advance_s']:.1f} us, integration {1e6 * r['integration_s']:.1f} us "
            f"({1e9 * per_step:.0f} ns/step); construction {1e6 * r['construction_s']:.1f} us; simulate "
            f"{1e6 * r['simulate_2_samples_s']:.1f} us (2 samples), {1e6 * r['simulate_201_samples_s']:.1f} us "
            "(201)")

    # (b) one step per call against one call of all the steps, same trajectory
    for name, n in PER_CALL.items():
        r = out["per_call"][name] = {"calls": n}
        targets = [(i + 1) * STEP for i in range(n)]  # each target computed, not accumulated, as a master does
        sim_calls = simulator(name, "rattle", {"dt": STEP})
        sim_one = simulator(name, "rattle", {"dt": STEP})
        calls, one = [], []
        for _ in range(repeats):
            sim_calls.reset()
            calls.append(_batch(lambda i: sim_calls.advance(targets[i]), n, 1))
            sim_one.reset()
            one.append(_timed(lambda: sim_one.advance(targets[-1]), 1)[0] / n)
        steps_calls, steps_one = int(sim_calls.integrator.stats.steps), int(sim_one.integrator.stats.steps)
        if steps_calls != n or steps_one != n:
            raise RuntimeError(f"{name}: expected {n} steps both ways, got {steps_calls} and {steps_one}")
        r["per_call_s"], r["per_step_long_s"] = min(calls), min(one)
        r["overhead_s"] = r["per_call_s"] - r["per_step_long_s"]
        r["construction_s"] = _batch(lambda i: simulator(name, "rattle", {"dt": STEP}), 10, repeats)
        log(f"{name} rattle dt {STEP:g}: one step per call {1e6 * r['per_call_s']:.2f} us, in one long call "
            f"{1e6 * r['per_step_long_s']:.2f} us/step: {1e6 * r['overhead_s']:.2f} us per call beyond its "
            f"integration; construction {1e6 * r['construction_s']:.1f} us")
    return out


# ------------------------------------------------------------------------------------------------ breakdown
def breakdown(repeats: int = 9, n: int = 200, log=print) -> dict:
    """Where a one-step advance of the native core spends its time (native trees only: it reaches into the
    binding, ``sim.integrator``'s model, method and data pointers). Per call, RATTLE dt 1e-3:

    * ``Simulator.advance``, ``NativeIntegrator.advance`` (the binding), ``ln_advance`` through ctypes alone,
      and a ctypes call of a trivial C function (``ln_fixed_step_count``): the differences are the Python
      layers and the ctypes call;
    * ``ln_advance`` at 1, 2 and 3 steps per call, in 2-D (a planar scene's mode) and forced into 3-D: the
      intercept of time against steps is the C side's fixed cost of an interval (plus the ctypes call), the
      slope its cost per step. The 2-D and 3-D intercepts differ by entering and leaving the plane.
    """
    import linknet_core as ln
    from linknet_core.clib import library as lib

    tree = Path(ln.__file__).resolve().parent.parent
    out = {}
    for name in PER_CALL:
        sim = ln.Simulator(ln.load_scene(tree / "models" / f"{name}.json"), method="rattle", dt=STEP)
        integ = sim.integrator
        model_p, method_p, data_p, d = integ._model_p, integ._method_p, integ._data_p, integ.data.struct
        targets = [(i + 1) * STEP for i in range(3 * n)]

        def series(fn, k=1, planar=None):
            def call(i):
                if i == 0:  # every batch from the start of the same trajectory
                    sim.reset()
                    integ._load(sim.state, None)
                    if planar is not None:
                        d.planar = planar
                fn(targets[k * i + k - 1])
            return 1e6 * _batch(call, n, repeats)

        row = {"Simulator.advance": series(lambda t: sim.advance(t)),
               "NativeIntegrator.advance": series(lambda t: integ.advance(sim.state, t, None, 10 ** 8)),
               "ln_advance via ctypes": series(lambda t: lib.advance(model_p, method_p, data_p, t, 10 ** 8)),
               "ctypes call of a trivial C function": 1e6 * _batch(lambda i: lib.fixed_step_count(1.0, 1.0), n,
                                                                   repeats)}
        planar = int(d.planar)
        for dim, flag in ((2, 1), (3, 0)):
            if dim == 2 and not planar:
                continue
            t = {k: series(lambda x: lib.advance(model_p, method_p, data_p, x, 10 ** 8), k, flag) for k in (1, 2, 3)}
            slope = (t[3] - t[1]) / 2
            row[f"{dim}-D ln_advance fixed per call (intercept)"] = t[1] - slope
            row[f"{dim}-D per step (slope)"] = slope
        out[name] = row
        log(f"{name}: " + "; ".join(f"{k} {v:.2f} us" for k, v in row.items()))
    return out


# ------------------------------------------------------------------------------------------------ phases
# (label, module, attribute): the set-up and run phases timed by --phases; entries a tree does not have are
# skipped, so that the same table compares trees whose internals differ. Times are exclusive: a phase's own
# time, without the phases it calls.
PHASES = (
    ("scene file (load_scene)", "linknet_core.scene.description", "load_scene"),
    ("structure analysis", "linknet_core.structure.topology", "_analyse"),
    ("link pairs", "linknet_core.structure.topology", "_link_pairs"),
    ("leaves-first ordering", "linknet_core.structure.topology", "_tree_ordering"),
    ("Dynamics (reference) set-up", "linknet_core.dynamics.equations", "Dynamics.__init__"),
    ("reference tension solver set-up", "linknet_core.dynamics.equations", "make_solver"),
    ("method settings", "linknet_core.simulator.simulator", "method_settings"),
    ("initial state ((11), (12), (35))", "linknet_core.simulator.simulator", "prepare_initial_state"),
    ("specialisation", "linknet_core.simulator.simulator", "choose_specialisation"),
    ("native model", "linknet_core.simulator.simulator", "NativeModel"),
    ("native method and data", "linknet_core.simulator.simulator", "NativeIntegrator"),
    ("Simulator.__init__ (the rest)", "linknet_core.simulator.simulator", "Simulator.__init__"),
    ("advance calls", "linknet_core.simulator.simulator", "Simulator.advance"),
    ("outputs calls", "linknet_core.simulator.simulator", "Simulator.outputs"),
    ("per-sample diagnostics", "linknet_core.dynamics.equations", "Dynamics.energy"),
    ("per-sample diagnostics", "linknet_core.dynamics.equations", "Dynamics.constraint_residual"),
    ("per-sample diagnostics", "linknet_core.dynamics.equations", "Dynamics.velocity_residual"),
    ("per-sample diagnostics", "linknet_core.simulator.simulator", "kinetic_energy"),
    ("per-sample diagnostics", "linknet_core.simulator.simulator", "_sample_diagnostics"),
    ("simulate (the rest)", "linknet_core.simulator.simulator", "simulate"),
)


def phases(repeats: int = 200, log=print) -> dict:
    """Where a fresh ``Simulator(scene)`` and a fresh ``ln.simulate(load_scene(...))`` spend their time, phase by
    phase (PHASES, exclusive times): median over ``repeats`` runs of CPU time (process_time), the garbage
    collector off inside a run. Every run starts from a scene object of its own (the structure analysis is kept
    per scene object, so a fresh scene pays it, as a user's first run does). The wrappers cost ~0.3 us per call:
    the un-instrumented totals come with them."""
    import importlib
    import statistics

    import linknet_core as ln

    clock = time.process_time
    tree = Path(ln.__file__).resolve().parent.parent
    acc: dict = {}
    stack: list = []

    def wrap(label, fn):
        def timed(*args, **kwargs):
            stack.append(0.0)
            start = clock()
            try:
                return fn(*args, **kwargs)
            finally:
                elapsed = clock() - start
                inner = stack.pop()
                acc[label] = acc.get(label, 0.0) + elapsed - inner
                if stack:
                    stack[-1] += elapsed
        return timed

    def install():
        undo = []
        for label, module, attr in PHASES:
            owner = importlib.import_module(module)
            *path, name = attr.split(".")
            for part in path:
                owner = getattr(owner, part, None)
            if owner is None or not hasattr(owner, name):
                continue
            original = getattr(owner, name)
            setattr(owner, name, wrap(label, original))
            undo.append((owner, name, original))
        return undo

    configs = {"pendulum dop853 rtol 1e-4": ("pendulum", "dop853", {"rtol": 1e-4}),
               "pendulum rattle dt 1e-3": ("pendulum", "rattle", {"dt": 1e-3}),
               "chain_10 rattle dt 1e-3": ("chain_10", "rattle", {"dt": 1e-3})}
    out = {"linknet_core": str(Path(ln.__file__).resolve().parent), "configs": {}}
    for key, (name, method, settings) in configs.items():
        path = tree / "models" / f"{name}.json"
        rows = {}
        for what, run in (("Simulator(scene)", lambda sc: ln.Simulator(sc, method=method, **settings)),
                          ("simulate, 2 samples", lambda sc: ln.simulate(sc, RUN_T, method=method, n_out=2,
                                                                          **settings)),
                          ("simulate, 201 samples", lambda sc: ln.simulate(sc, RUN_T, method=method, **settings))):
            for _ in range(5):
                run(ln.load_scene(path))
            plain = []
            for _ in range(repeats):
                scene = ln.load_scene(path)
                gc.collect()
                gc.disable()
                start = clock()
                run(scene)
                plain.append(clock() - start)
                gc.enable()
            undo = install()
            per_run = []
            try:
                for _ in range(repeats):
                    scene = ln.load_scene(path)
                    acc.clear()
                    gc.collect()
                    gc.disable()
                    start = clock()
                    run(scene)
                    total = clock() - start
                    gc.enable()
                    per_run.append(dict(acc, total=total))
            finally:
                for owner, name, original in reversed(undo):
                    setattr(owner, name, original)
            labels = dict.fromkeys(k for r in per_run for k in r if k != "total")
            row = {label: statistics.median(r.get(label, 0.0) for r in per_run) for label in labels}
            row["total (instrumented)"] = statistics.median(r["total"] for r in per_run)
            row["total"] = statistics.median(plain)
            rows[what] = row
            log(f"{key}, {what}: " + "; ".join(f"{k} {1e6 * v:.1f}" for k, v in row.items()) + " (us)")
        scene_t = []
        for _ in range(repeats):
            gc.disable()
            start = clock()
            ln.load_scene(path)
            scene_t.append(clock() - start)
            gc.enable()
        rows["load_scene"] = {"total": statistics.median(scene_t)}
        out["configs"][key] = rows
    return out


def _phases_markdown(trees: dict, results: dict) -> str:
    names = list(trees)
    lines = []
    for key in results[names[0]]["configs"]:
        for what in results[names[0]]["configs"][key]:
            if what == "load_scene":
                continue
            labels = dict.fromkeys(l for t in names for l in results[t]["configs"][key][what])
            lines += [f"### {key}: {what}", "", "| phase | " + " | ".join(f"{t} us" for t in names) + " |",
                      "|---|" + "---:|" * len(names)]
            for label in labels:
                cells = [results[t]["configs"][key][what].get(label) for t in names]
                text = " | ".join("-" if v is None else f"{1e6 * v:.1f}" for v in cells)
                lines.append(f"| {'**' + label + '**' if label == 'total' else label} | {text} |")
            lines.append("")
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------------ driver
def _load():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def _best(results: list[dict]) -> dict:
    """Per figure, the best of the rounds; derived figures recomputed from the bests."""
    best = json.loads(json.dumps(results[0]))
    for res in results[1:]:
        for section in ("runs", "per_call"):
            for key, row in res[section].items():
                for k, v in row.items():
                    if k.endswith("_s") and "fixed" not in k and k != "overhead_s":
                        best[section][key][k] = min(best[section][key][k], v)
    for row in best["runs"].values():
        row["integration_s"] = row["integration_per_step_s"] * row["steps"]
        row["first_advance_fixed_s"] = row["first_advance_s"] - row["integration_s"]
        row["repeat_advance_fixed_s"] = row["repeat_advance_s"] - row["integration_s"]
        row["simulate_fixed_s"] = row["simulate_2_samples_s"] - row["integration_s"]
    for row in best["per_call"].values():
        row["overhead_s"] = row["per_call_s"] - row["per_step_long_s"]
    return best


def _markdown(trees: dict, best: dict, meta: dict) -> str:
    names = list(trees)

    def us(v):
        return f"{1e6 * v:.1f}" if abs(v) >= 1e-5 else f"{1e6 * v:.2f}"

    def cells(get):
        values = [get(best[t]) for t in names]
        ratio = values[-1] / values[0] if len(values) == 2 and values[0] > 0 else None
        return " | ".join(us(v) for v in values) + (f" | {ratio:.2f}" if ratio is not None else "")

    head = " | ".join(f"{t} us" for t in names) + (" | ratio" if len(names) == 2 else "")
    sep = "|---|" + "---:|" * (len(names) + (1 if len(names) == 2 else 0))
    lines = ["# Fixed costs", "", f"`{meta['command']}`, {meta['date']}, {meta['machine']}; load average "
             f"{meta['load_start']} at the start, {meta['load_end']} at the end. "
             f"Trees: " + ", ".join(f"{t} = `{p}`" for t, p in trees.items()) + f". {meta['rounds']} rounds, "
             "the trees interleaved round by round, each round best of its repeats; every figure the best of all "
             "rounds (CPU time, microseconds per call).", ""]
    for key in RUNS:
        steps = " / ".join(str(best[t]["runs"][key]["steps"]) for t in names)
        lines += [f"## {key.replace('_', ' ')}, 2 s ({steps} steps)", "", f"| figure | {head} |", sep]
        rows = [("first `advance(2.0)` of a fresh Simulator", "first_advance_s"),
                ("repeated `advance(2.0)` after `reset()`", "repeat_advance_s"),
                ("integration part (steps x per-step time of a long advance)", "integration_s"),
                ("**fixed cost of the first advance** (first - integration)", "first_advance_fixed_s"),
                ("fixed cost of a repeated advance", "repeat_advance_fixed_s"),
                ("`Simulator(...)` construction", "construction_s"),
                ("`ln.simulate`, 2 samples", "simulate_2_samples_s"),
                ("**fixed cost of `ln.simulate`** (2 samples - integration)", "simulate_fixed_s"),
                ("`ln.simulate`, 201 samples (default)", "simulate_201_samples_s")]
        for label, k in rows:
            lines.append(f"| {label} | {cells(lambda b: b['runs'][key][k])} |")
        lines.append("")
    lines += ["## One-step `advance` calls (RATTLE, dt 1e-3)", "",
              "N calls of one step each against one call of N steps along the same trajectory, per step; the "
              "difference is what a call costs beyond its integration.", "",
              f"| scene | figure | {head} |", "|---" + sep]
    for name in PER_CALL:
        for label, k in (("one step per call", "per_call_s"), ("per step in one long call", "per_step_long_s"),
                         ("**per-call cost beyond the integration**", "overhead_s"),
                         ("`Simulator(...)` construction", "construction_s")):
            lines.append(f"| {name} | {label} | {cells(lambda b: b['per_call'][name][k])} |")
    lines.append("")
    return "\n".join(lines)


def _output():
    """The checkout's benchmarks.output, for the driver only: a tree's own run (PYTHONPATH = that tree) imports
    nothing of this checkout."""
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    from benchmarks import output
    return output


def drive(trees: dict, rounds: int, repeats: int, out: Path) -> dict:
    this = Path(__file__).resolve()
    numba_cache = Path(tempfile.mkdtemp(prefix="linknet_fixed_costs_numba_"))  # no tree's cache is touched
    meta = {"command": "python benchmarks/bench_fixed_costs.py --trees " + " ".join(f"{k}={v}" for k, v in
                                                                                   trees.items())
            + f" --rounds {rounds} --repeats {repeats}", "date": time.strftime("%Y-%m-%d %H:%M %Z"),
            "machine": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs, Python "
                       f"{platform.python_version()}", "load_start": _load(), "rounds": rounds}
    results = {t: [] for t in trees}
    for i in range(rounds):
        for tree, path in trees.items():
            with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
                target = f.name
            env = dict(os.environ, PYTHONPATH=str(path), NUMBA_CACHE_DIR=str(numba_cache),
                       OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1")
            print(f"round {i + 1}/{rounds}: {tree} ({path}), load {_load()}", flush=True)
            subprocess.run([sys.executable, str(this), "--repeats", str(repeats), "--json", target], cwd=path,
                           env=env, check=True)
            res = json.loads(Path(target).read_text())
            os.unlink(target)
            if Path(res["linknet_core"]).parent != Path(path).resolve():
                raise RuntimeError(f"{tree}: measured {res['linknet_core']}, not the tree {path}")
            results[tree].append(res)
    meta["load_end"] = _load()
    best = {t: _best(r) for t, r in results.items()}
    write_text = _output().write_text
    write_text(out / "fixed_costs.json", json.dumps({"meta": meta, "trees": {k: str(v) for k, v in trees.items()},
                                                     "best": best, "rounds": results}, indent=1))
    text = _markdown(trees, best, meta)
    write_text(out / "fixed_costs.md", text)
    print(text)
    return best


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=7, help="batches per figure (best kept)")
    ap.add_argument("--json", type=Path, help="write this tree's figures here")
    ap.add_argument("--trees", nargs="+", metavar="NAME=PATH", help="run each tree in its own process, interleaved")
    ap.add_argument("--rounds", type=int, default=3, help="with --trees: rounds over all trees")
    ap.add_argument("--phases", action="store_true",
                    help="where a fresh Simulator and a fresh simulate spend their set-up, phase by phase; with "
                         "--trees: one table of every tree's phases")
    ap.add_argument("--breakdown", action="store_true",
                    help="native tree only: where a one-step advance spends its time (Python, ctypes, C)")
    ap.add_argument("--out", type=Path, metavar="DIR", help="with --trees: output folder (default "
                    "build/native_vs_numba; with --merge, docs/benchmarks/native_vs_numba); inside docs/ only with "
                    "--merge")
    ap.add_argument("--merge", action="store_true",
                    help="with --trees: write into the tracked docs/benchmarks/native_vs_numba (or --out) instead of "
                         "build/")
    args = ap.parse_args(argv)
    if args.trees and args.phases:
        trees = {k: Path(v).resolve() for k, v in (item.split("=", 1) for item in args.trees)}
        results = {}
        for tree, path in trees.items():
            with tempfile.NamedTemporaryFile(suffix=".json", delete=False) as f:
                target = f.name
            env = dict(os.environ, PYTHONPATH=str(path), OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1")
            subprocess.run([sys.executable, str(Path(__file__).resolve()), "--phases", "--json", target], cwd=path,
                           env=env, check=True)
            results[tree] = json.loads(Path(target).read_text())
            os.unlink(target)
        print(_phases_markdown(trees, results))
        return
    if args.trees:
        out = _output().resolve(ap, args, "native_vs_numba", tracked="native_vs_numba")
        trees = dict(item.split("=", 1) for item in args.trees)
        drive({k: Path(v).resolve() for k, v in trees.items()}, args.rounds, args.repeats, out.resolve())
        return
    res = breakdown(args.repeats) if args.breakdown else phases() if args.phases else measure(args.repeats)
    if args.json:
        args.json.write_text(json.dumps(res, indent=1))


if __name__ == "__main__":
    main()
