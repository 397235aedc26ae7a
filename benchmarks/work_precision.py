"""Work-precision benchmark: wall time against error, linknet's integrators side by side with peers.

    python -m benchmarks.work_precision            # full run, writes build/work_precision/ (--merge: docs/benchmarks/)
    python -m benchmarks.work_precision --quick    # CI-sized run (< 3 min), writes build/work_precision/quick/

For each scene: an independent reference (benchmarks.reference, verified by two tolerances agreeing), then
every method over a sweep of its accuracy knob (dt for fixed-step methods, rtol for adaptive ones), from
coarse to fine, until the error reaches the reference floor or one run exceeds the time budget.
Per run: error = max over masses |X_k(t_end) - X_ref,k(t_end)| [m], the max relative constraint residual
| |X_k2-X_k1|/R - 1 |, the relative energy drift |E(t_end)-E(0)| / E_scale, wall time of the integration
only (model construction timed separately), steps.
Outputs: results.json, results.md (per scene and error level 1e-3/1e-6/1e-9 m the fastest time of every
method and the ratio linknet-best / best-other), <scene>.png work-precision plots, with machine/versions/date.
"""
from __future__ import annotations

import argparse
import datetime as _dt
import importlib.metadata
import json
import math
import os
import platform
import subprocess
import sys
import time
import traceback
from dataclasses import asdict, dataclass, replace
from pathlib import Path

# References are computed in this process, on one core as every run in the worker is (peers/isolated.py): a
# redundant scene's dense least-squares right-hand side (triangulated_net) took 66 ms with threaded BLAS on the
# 2 shared cores against 4.3 ms on one thread. Only effective before numpy is first imported (python -m ...).
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

if __package__ in (None, ""):   # `python benchmarks/work_precision.py`
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    __package__ = "benchmarks"

from .peers.base import Unsupported  # noqa: E402
from .peers.isolated import InProcessRunner, IsolatedRunner  # noqa: E402
from .output import add_output_arguments, checked, resolve, write_text, write_with  # noqa: E402
from .reference import reference  # noqa: E402
from .scene_spec import SceneSpec, load_json  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
LEVELS = (1e-3, 1e-6, 1e-9)

# scene -> simulated time [s]: 2 s (the peers' orientation figures in issue 6 are for 2 s) wherever a
# reference can be verified to 1e-12 m. Measured (two DOP853 tolerances, 1e-13 vs 2.5e-14): chain_100
# agrees to 6e-13 m at 1 s but only to 2.3e-2 m at 2 s (the motion after the whip amplifies errors ~1e11x);
# chain_1000 to 2.2e-12 m at 1 s (21 min of reference); net_10x10 to 4e-15 m at 0.25 s, 8.8e-8 m at
# 0.5 s and 0.25 m at 2 s (the falling cloth snaps taut).
# The redundant scenes in motion (self-stresses and mechanisms at once) run shorter than their DefaultExperiment
# stopTime (2 s), for the same reason; SCENE_NOTES says so in the table.
SCENES = {
    "pendulum": 2.0, "double_pendulum": 2.0, "chain_10": 2.0, "chain_100": 1.0, "chain_1000": 1.0,
    "net_10x10": 0.25, "four_bar": 2.0, "spinning_tetrahedron": 2.0, "redundant_truss": 2.0,
    "braced_tower": 0.7, "triangulated_net": 0.5, "rope_swing": 2.0, "rope_pendulum": 2.0,
}
# rope_swing and rope_pendulum (models/ropes/): run by linknet on its native core (the default backend), refused
# by the peers that model rods only, referenced by benchmarks.rope_reference; MoorDyn is their peer where its lines
# have a rigid limit (rope_swing)
SCENE_NOTES = {
    "braced_tower": "t_end 0.7 s, not the DefaultExperiment's 2 s: between 0.7 and 0.8 s the tower passes near a "
                    "singular configuration (at 0.8 s the two smallest nonzero eigenvalues of A are 8e-6 of the "
                    "largest), where the index-1 reference needs 43 000 DOP853 steps at rtol 1e-12 and leaves (11) "
                    "by 3e-11, and between 1.0 and 1.1 s scipy stops (required step size below the spacing of "
                    "numbers); up to 0.7 s the two reference tolerances agree to 4e-14 m",
    "triangulated_net": "t_end 0.5 s, not the DefaultExperiment's 2 s: the index-1 reference, which does not "
                        "enforce (11), leaves it faster from about 0.5 s (its relative residual at rtol 1e-12: "
                        "7.5e-13 at 0.5 s, 2.8e-11 at 0.6 s, 1.4e-10 at 0.8 s); whether its two tolerances still "
                        "agree to 1e-12 m beyond 0.5 s was not measured",
    "rope_swing": "a bob on a perfectly elastic rope (restitution 1): a pendulum until the rope goes slack at "
                  "0.495 s, then flights ended by five elastic jerks. The reference is event-driven "
                  "(benchmarks/rope_reference.py: the index-1 right-hand side between the events, scipy's event "
                  "location, the impacts' impulses by enumeration of the active sets). Linknet runs it on its native "
                  "core, event by event as its numpy reference does (tests hold the two together); "
                  "the peers that model rods only cannot run it. MoorDyn's lines are "
                  "elastic: one row per stiffness EA (docs/benchmarks/rope_peer.md)",
    "rope_pendulum": "a bob on an inelastic rope (restitution 0) thrown up and out: flight, jerk, pendulum, slack "
                     "above the pivot, flight, jerk; reference as rope_swing's; energy is lost at each jerk (the "
                     "energy-drift column is that loss). No peer here models an inelastic rope: MoorDyn's undamped "
                     "line tends to restitution 1, and its internal damping acts on slack segments too",
}
# Not braced_tower (1 s in --quick): yoshida8 reaches 1.5e-11 m at its second quick step, below where the quick test
# measures orders, so it would have no order to check; the redundant scenes in motion are checked against the same
# reference with every method by tests/core/test_redundant_motion.py.
# rope_swing: the rope events through every method, and MoorDyn where it imports.
QUICK_SCENES = ("pendulum", "double_pendulum", "four_bar", "spinning_tetrahedron", "chain_10", "rope_swing")

# knob sweeps, coarse to fine. Fixed steps as divisors of t_end so every run lands on t_end exactly.
def full_dts(order):
    """Fixed steps for the full sweep, from a coarse start that depends on the order, halving 20 times."""
    top = {2: 0.02, 3: 0.04, 4: 0.04}.get(order, 0.1)
    return [top / 2 ** i for i in range(0, 21)]
# 1e-3 ... 1e-13. Not 1e-2: no method reached the 1e-3 m level at rtol 1e-2 in the 2026-11-21 run, and there
# DOP853/DOPRI5 fail on chain_1000 by step-size underflow after ~40 s of ever smaller steps.
FULL_RTOL = [10.0 ** -e for e in range(3, 14)]
QUICK_RTOL = [1e-4, 1e-6, 1e-8]


@dataclass(frozen=True)
class Budget:
    """Time budget that bounds a whole run (issue 5: the full run finishes in about half an hour here).

    run_timeout: hard limit of one setting (model construction + warm-up + repeats + integration); the worker
        process running it is killed and the setting recorded as a timeout. Finer settings are not tried.
    sweep: wall time of all of one method's settings on one scene, after which no further setting starts...
    sweep_cap: ...unless the method still has fewer than `min_ok` successful settings, or the next setting is
        predicted to reach an error level (1e-3/1e-6/1e-9 m) it has not reached yet; then up to this cap.
    A setting is only started if its predicted wall time (_predict_wall: the last successful setting's, scaled
    by the knob ratio for fixed steps, by the last growth for tolerances) fits within the applicable limit
    and the run timeout; the settings not started are recorded as skipped, with the prediction.
    Other stops: the error is below the reference floor (after min_ok settings: a method exact from the
    start still gets them); below 1e-10 m with >= min_ok settings (finer
    settings only probe round-off; the finest level is 1e-9 m); the error grew three times in a row below
    1e-6 m (round-off); max_failures failed settings in a row."""
    run_timeout: float
    sweep: float
    sweep_cap: float
    min_ok: int
    max_failures: int = 8


FULL_BUDGET = Budget(run_timeout=60.0, sweep=90.0, sweep_cap=120.0, min_ok=6)
QUICK_BUDGET = Budget(run_timeout=60.0, sweep=4.0, sweep_cap=60.0, min_ok=2)
QUICK_OK_RUNS = 3        # --quick: three successful settings a method
ENOUGH_ERROR = 1e-10     # below the finest level (1e-9 m): more settings only measure round-off


def quick_dts(order):
    """Three steps per method in --quick, coarser for higher orders so that every method is measured in its
    asymptotic range above the reference floor (the quick test checks convergence orders)."""
    top = {2: 0.01, 3: 0.02, 4: 0.02}.get(order, 0.04)
    return [top / 2 ** i for i in range(6)]   # the sweep stops after three successful runs


# ------------------------------------------------------------------------------------------------ scenes
def load_benchmark_scene(name: str) -> SceneSpec:
    """models/<name>.json through linknet_core when it imports (so the benchmark sees exactly what linknet
    sees), else through the plain JSON reader; chain_1000 from linknet_core.scene.builders."""
    try:
        import linknet_core as ln
    except Exception:
        ln = None
    path = MODELS / f"{name}.json"
    if not path.exists() and (MODELS / "ropes" / f"{name}.json").exists():
        path = MODELS / "ropes" / f"{name}.json"
    if path.exists():
        spec = SceneSpec.from_core(ln.load_scene(path)) if ln is not None else load_json(path)
        return spec if spec.name == name else _renamed(spec, name)
    if name == "chain_1000":
        return _chain_1000(ln)
    raise FileNotFoundError(f"benchmark scene {name!r}: {path} does not exist")


def _renamed(spec, name):
    from dataclasses import replace
    return replace(spec, name=name)


def _chain_1000(ln) -> SceneSpec:
    """A 1000-link chain released from horizontal: linknet_core.scene.builders.chain(1000) with the same total
    length and total mass as models/chain_100.json (= builders.chain(100))."""
    if ln is None or not hasattr(ln, "builders"):
        raise FileNotFoundError("chain_1000 needs linknet_core.scene.builders.chain")
    kw = {}
    if (MODELS / "chain_100.json").exists():
        ref = load_benchmark_scene("chain_100")
        kw = {"total_length": float(ref.length.sum()), "total_mass": float(ref.mass[ref.free].sum()) * 1001 / 1000}
    return _renamed(SceneSpec.from_core(ln.builders.chain(1000, **kw)), "chain_1000")


# ------------------------------------------------------------------------------------------------ methods
def all_methods(quick: bool):
    from .peers.ase_peer import ASEVelocityVerlet
    from .peers.exudyn_peer import ExudynGenAlpha
    from .peers.linknet_methods import LinknetMethod, linknet_method_names
    from .peers.moordyn_peer import MoorDynLine
    from .peers.mujoco_peer import MujocoRK4
    from .peers.openmm_peer import OpenMMVerlet
    from .peers.scipy_baseline import ScipyIVP
    methods = [LinknetMethod(m) for m in linknet_method_names()]
    methods += [ScipyIVP("RK45"), ScipyIVP("DOP853")]
    methods += [OpenMMVerlet("Reference")]
    if not quick:
        methods += [OpenMMVerlet("CPU")]
    methods += [ExudynGenAlpha(), MujocoRK4()]
    if not quick:   # ASE's link-by-link Python RATTLE needs ~3 ms per step even on a pendulum
        methods += [ASEVelocityVerlet()]
    # MoorDyn's elastic lines on the rope scenes, one row per stiffness (the model's error falls with EA, the cost
    # of a stable step grows with sqrt(EA)); unavailable, with the reason, where moordyn does not import
    methods += [MoorDynLine(EA) for EA in MOORDYN_EA_QUICK if quick] + [MoorDynLine(EA) for EA in MOORDYN_EA
                                                                       if not quick]
    return methods


MOORDYN_EA = (1e6, 1e8, 1e10, 1e12)   # N, on rope_swing's 1 m rope and 1 kg bob: stretch 3.5e-5 .. 3.5e-11 m
MOORDYN_EA_QUICK = (1e6,)


def _check_models(method, spec):
    """Refuse a scene with ropes or a ground for a method that models rods only (every peer but MoorDyn), then the
    method's own checks."""
    if spec.unilateral and not (method.family == "linknet" or getattr(method, "models_ropes", False)):
        what = "ropes" if spec.rope.any() else "a ground"
        raise Unsupported(f"the scene has {what} (links that go slack); {method.name} models rigid rods only")
    method.check_scene(spec)


# ------------------------------------------------------------------------------------------------ runs
def _predict_wall(rows, knob_kind: str, knob_next: float):
    """Predicted wall time [s] of the next setting (None before the first run). From the last successful
    setting: fixed steps scale with the number of steps, tolerances with the growth between the last two
    successful settings (clamped to 1..4; 1 without two). After failures only (the step still too coarse):
    the last failed setting's own wall time, unscaled -- a failed run is no guide to a successful one (a
    projection struggling at a too coarse step, or step-size underflow, costs more per step than a finer
    step that succeeds), but one that already took long is likely to be followed by a long one."""
    done = [r for r in rows if r.get("wall_seconds") is not None]
    if not done:
        return None
    oks = [r for r in done if r.get("status") == "ok"]
    if not oks:
        return done[-1]["wall_seconds"]
    last = oks[-1]
    if knob_kind == "dt":
        return last["wall_seconds"] * last["value"] / knob_next
    growth = 1.0   # one loose-tolerance run can cost more than the next (rejections at the whip)
    if len(oks) >= 2 and oks[-2]["wall_seconds"] > 0:
        growth = min(4.0, max(1.0, oks[-1]["wall_seconds"] / oks[-2]["wall_seconds"]))
    return last["wall_seconds"] * growth


def _next_level_in_reach(errs) -> bool:
    """Is the next setting predicted (geometric extrapolation of the last two errors) to reach an error
    level not reached yet?"""
    if not errs:
        return True
    best = min(errs)
    unreached = [lv for lv in LEVELS if lv < best]
    if not unreached:
        return False
    guess = errs[-1] * (errs[-1] / errs[-2]) if len(errs) >= 2 and errs[-2] > 0 else errs[-1] / 10
    return guess <= max(unreached)


def sweep(method, spec, t_end, ref, *, quick: bool, budget: Budget, runner, log=print):
    """All settings of one method on one scene, coarse to fine, within `budget` (see Budget).
    Returns (rows, summary): one row per setting tried or skipped; summary = wall time spent and why it ended."""
    rows = []
    t_sweep = time.perf_counter()
    try:
        _check_models(method, spec)
    except Unsupported as e:
        return [{"status": "unsupported", "message": str(e)}], {"wall_seconds": 0.0, "stop": "unsupported"}
    if hasattr(method, "knobs"):   # a method whose useful steps depend on the scene (MoorDyn: its stability limit)
        knobs = method.knobs(spec, quick)
    elif method.knob == "dt":
        knobs = quick_dts(method.order or 2) if quick else full_dts(method.order or 2)
    else:
        knobs = QUICK_RTOL if quick else FULL_RTOL
    method.run_budget = budget.run_timeout   # adapters that can predict their run time refuse longer runs
    floor = max(10 * float(ref["agreement"]), 1e-13)
    spent, failures = 0.0, 0
    stop, skip_from, skip_why = "all settings run", None, ""
    i = -1
    while True:
        # after a failure (step too coarse for the scene) jump a factor 4 instead of 2, until the first success
        oks = [x for x in rows if x.get("status") == "ok"]
        i += 2 if (failures and not oks and not quick) else 1
        if i >= len(knobs):
            break
        knob = knobs[i]
        errs = [x["error"] for x in oks]
        pred = _predict_wall(rows, method.knob, knob)
        if pred is not None:
            extend = len(oks) < budget.min_ok or _next_level_in_reach(errs)
            limit = budget.sweep_cap if extend else budget.sweep
            if pred > budget.run_timeout:
                stop, skip_from = f"next setting predicted {pred:.3g} s > run timeout {budget.run_timeout:g} s", i
            elif spent + pred > limit:
                stop = (f"sweep budget: {spent:.3g} s spent + {pred:.3g} s predicted > "
                        f"{'cap ' if extend else ''}{limit:g} s")
                skip_from = i
            if skip_from is not None:
                skip_why = f"not run: {stop}"
                break
        row = {"knob": method.knob, "value": knob}
        status, payload, wall = runner.run(method, spec, t_end, knob, repeat_below=0.0 if quick else 0.2,
                                           timeout=budget.run_timeout)
        spent += wall
        row["wall_seconds"] = wall
        if status == "unsupported":
            return [{"status": "unsupported", "message": payload}], {"wall_seconds": spent, "stop": "unsupported"}
        if status in ("timeout", "skipped"):   # finer settings take longer still
            row |= {"status": status, "message": payload}
            rows.append(row)
            log(f"    {method.name:28s} {method.knob}={knob:<9.3g} {status.upper()} {payload[:110]}")
            stop, skip_from = f"{status} at {method.knob} = {knob:.3g}", i + 1
            skip_why = f"not run: finer than the setting that hit the run budget ({method.knob} = {knob:.3g})"
            break
        if status == "failed":   # a failing run is a result, not a crash of the benchmark
            failures += 1
            row |= {"status": "failed", "message": payload[:300]}
            rows.append(row)
            log(f"    {method.name:28s} {method.knob}={knob:<9.3g} FAILED {payload[:100]} ({wall:.3g} s)")
            if failures >= budget.max_failures:   # a 4^7x smaller step failed too: the method cannot do this scene
                stop = f"{failures} failed settings in a row"
                break
            continue
        r = payload
        err = float(np.max(np.linalg.norm(r.X - ref["X"], axis=1)))
        finite = bool(np.all(np.isfinite(r.X)))
        row |= {"status": "ok" if finite else "nonfinite", "seconds": r.seconds,
                "setup_seconds": r.setup_seconds, "steps": int(r.steps),
                "error": err if finite else None,
                "resolved": bool(finite and err >= floor),
                "residual": spec.constraint_residual(r.X) if finite else None,
                "energy_drift": (abs(spec.energy(r.X, r.U) - spec.energy(spec.X0, spec.U0)) / spec.energy_scale()
                                 if (finite and r.U is not None) else None),
                "info": {k: v for k, v in r.info.items() if isinstance(v, (int, float, str))}}
        rows.append(row)
        if not finite:   # blew up at this setting: a failure, try finer
            row["status"], row["message"] = "failed", "non-finite state at t_end"
            failures += 1
            if failures >= budget.max_failures:
                stop = f"{failures} failed settings in a row"
                break
            continue
        failures = 0
        nan = float("nan")
        log(f"    {method.name:28s} {method.knob}={knob:<9.3g} err={err:9.3e} "
            f"res={row['residual'] if row['residual'] is not None else nan:8.1e} "
            f"dE={row['energy_drift'] if row['energy_drift'] is not None else nan:8.1e} "
            f"t={r.seconds * 1e3:10.3f} ms steps={r.steps} (wall {wall:.3g} s)")
        n_ok = len(oks) + 1
        errs.append(err)
        # a method exact from its first setting (a rigid or static scene on its specialised path) still gets
        # min_ok settings: the row then measures how its cost grows with the knob, not one point
        below_floor = err < floor
        if below_floor and (quick or n_ok >= budget.min_ok):
            stop = f"error {err:.2g} m below the reference floor {floor:.2g} m after {n_ok} settings"
            break
        if quick and n_ok >= QUICK_OK_RUNS:
            stop = f"{QUICK_OK_RUNS} settings (--quick)"
            break
        if err < ENOUGH_ERROR and n_ok >= budget.min_ok:
            stop = f"error {err:.2g} m < {ENOUGH_ERROR:g} m after {n_ok} settings"
            break
        if not below_floor and len(errs) >= 3 and errs[-1] > errs[-2] > errs[-3] and errs[-3] < 1e-6:
            stop = "round-off: the error grew three times in a row"   # finer settings only add error
            break
        if getattr(method, "model_error", False) and len(errs) >= 4 and min(errs[-3:]) > 0.5 * min(errs[:-3]):
            # a model that differs from the scene's (an elastic line for a rigid rope): a finer step buys nothing
            stop = (f"the model's error: three finer settings gained less than a factor 2 (best "
                    f"{min(errs):.2g} m)")
            break
    if skip_from is not None:
        rows += [{"knob": method.knob, "value": k, "status": "skipped", "message": skip_why}
                 for k in knobs[skip_from:]]
    return rows, {"wall_seconds": time.perf_counter() - t_sweep, "integration_wall_seconds": spent, "stop": stop}


def fastest_at(rows, level):
    ok = [r for r in rows if r.get("status") == "ok" and r["error"] is not None and r["error"] <= level]
    return min(ok, key=lambda r: r["seconds"]) if ok else None


def summarize(scene_result):
    """Per error level: fastest time of every method, linknet's best, the best of the others, the ratio."""
    out = {}
    methods = scene_result["methods"]
    for level in LEVELS:
        per = {}
        for name, m in methods.items():
            best = fastest_at(m["runs"], level)
            if best is not None:
                per[name] = {"seconds": best["seconds"], "knob": best["value"], "error": best["error"]}
        lk = {n: v for n, v in per.items() if methods[n]["family"] == "linknet"}
        other = {n: v for n, v in per.items() if methods[n]["family"] != "linknet"}
        bl = min(lk, key=lambda n: lk[n]["seconds"]) if lk else None
        bo = min(other, key=lambda n: other[n]["seconds"]) if other else None
        out[f"{level:g}"] = {"per_method": per, "linknet_best": bl, "other_best": bo,
                             "ratio": (lk[bl]["seconds"] / other[bo]["seconds"]) if (bl and bo) else None}
    return out


# ------------------------------------------------------------------------------------------------ report
def _versions():
    v = {"python": sys.version.split()[0]}
    for mod in ("numpy", "scipy", "numba", "openmm", "exudyn", "mujoco", "ase", "moordyn", "matplotlib"):
        try:
            module = __import__(mod)
        except Exception:
            v[mod] = None
            continue
        try:   # moordyn's wrapper has no __version__: its distribution's
            v[mod] = getattr(module, "__version__", None) or importlib.metadata.version(mod)
        except Exception:
            v[mod] = None
    try:
        v["linknet_commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True,
                                             text=True, timeout=10).stdout.strip() or None
    except Exception:
        v["linknet_commit"] = None
    return v


def _machine():
    cpu = platform.processor()
    try:
        for line in open("/proc/cpuinfo"):
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = None
    try:
        mem = round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (ValueError, OSError):
        pass
    return {"platform": platform.platform(), "cpu": cpu, "cores": os.cpu_count(), "memory_GiB": mem}


def _verification(ref) -> str:
    if ref["verified"]:
        return "verified ≤ 1e-12"
    floor = max(10 * ref["agreement"], 1e-13)
    if floor <= 0.1 * min(LEVELS):
        return (f"verified only to {ref['agreement']:.3g} m, not 1e-12 m: errors below {floor:.2g} m are "
                f"unresolved, ample for the {min(LEVELS):g} m level")
    return f"NOT verified: errors below {floor:.2g} m are unresolved"


def _loadavg():
    try:
        return [round(x, 2) for x in os.getloadavg()]
    except OSError:
        return None


def _fmt_t(s):
    return "—" if s is None else (f"{s * 1e3:.3g} ms" if s < 1 else f"{s:.3g} s")


def write_markdown(results, path: Path):
    meta = results["meta"]
    prov = meta.get("provenance", {})
    if prov.get("single_run"):
        provenance = (f"**One run**: every number below was measured by this single invocation "
                      f"({len(prov.get('scenes', []))} scenes, {len(prov.get('methods', []))} methods); nothing is "
                      "merged or stitched from other runs.")
    elif prov.get("merged_from"):
        provenance = ("**Assembled from several runs** (--merge): earlier runs dated "
                      + ", ".join(prov["merged_from"]) + f"; this one reran {', '.join(prov.get('scenes', []))}.")
    else:
        provenance = "Provenance not recorded (results written by an older version of this script)."
    budget = meta.get("budget")
    lines = [f"# Work-precision benchmark{' (quick)' if meta['quick'] else ''}", "",
             f"Generated {meta['date']} by `{meta['command']}` in {meta['total_seconds']:.0f} s of wall time"
             + (f" ({meta['reference_seconds']:.0f} s of it computing references)"
                if meta.get("reference_seconds") else " (references from the cache)") + ".  ",
             provenance + "  ",
             f"Machine: {meta['machine']['cpu']}, {meta['machine']['cores']} cores, "
             f"{meta['machine']['memory_GiB']} GiB; {meta['machine']['platform']}"
             + (f"; load average {meta['load_average']['start']} at the start, {meta['load_average']['end']} at the end"
                if meta.get("load_average") else "") + ".  ",
             "Versions: " + ", ".join(f"{k} {v}" for k, v in meta["versions"].items() if v) + ".",
             *([f"Note: {meta['note']}."] if meta.get("note") else []), "",
             *([f"Budget: every setting runs in a worker process killed after {budget['run_timeout']:g} s "
                f"(recorded as a timeout); a method's sweep on a scene starts no setting predicted to take it past "
                f"{budget['sweep']:g} s of wall time ({budget['sweep_cap']:g} s while it has fewer than "
                f"{budget['min_ok']} successful settings or the next one is predicted to reach a new error level). "
                "Settings not run are listed as skipped, with the reason, in results.json and counted below.", ""]
               if budget else []),
             "Error = max over masses |X_k(t_end) − X_ref,k(t_end)|. Each cell is the fastest wall time (integration "
             "only, one core) among the method's runs whose error is at or below the level; — means "
             "no run reached it (or the method cannot model the scene: see the notes). Ratio = linknet's best ÷ the "
             "best of all other methods (peers and scipy baselines); below 1 linknet is faster. Settings = "
             "ok / failed / timeout / skipped, and the wall time of the sweep (model construction, warm-up, "
             "repeats and failed runs included).", ""]
    for sname, sres in results["scenes"].items():
        ref = sres["reference"]
        lines += [f"## {sname}", "", *([f"({sres['note']}.)", ""] if sres.get("note") else []),
                  f"K = {sres['K']}, L = {sres['L']}, t_end = {sres['t_end']} s. Reference: DOP853 rtol "
                  f"{ref['rtol_ref']:g} vs {ref['rtol_check']:g} agree to {ref['agreement']:.2g} m "
                  f"({_verification(ref)}), residual "
                  f"{ref['residual']:.2g}."
                  + (f" Scene wall time {sres['wall_seconds']:.0f} s." if sres.get("wall_seconds") else ""), ""]
        summ = sres["summary"]
        hdr = ("| method | " + " | ".join(f"≤ {lv:g} m" for lv in LEVELS)
               + " | best error reached | its residual | its energy drift | max residual, all runs | settings |")
        lines += [hdr, "|" + "---|" * (len(LEVELS) + 6)]
        ends = []
        for mname, m in sres["methods"].items():
            runs = m["runs"]
            count = {st: sum(1 for r in runs if r.get("status") == st) for st in ("ok", "failed", "timeout", "skipped")}
            sw = m.get("sweep") or {}
            settings = "/".join(str(count[st]) for st in count) + (
                f", {sw['wall_seconds']:.3g} s" if sw.get("wall_seconds") is not None else "")
            if sw.get("stop"):
                ends.append(f"{mname}: {sw['stop']}")
            oks = [r for r in runs if r.get("status") == "ok"]
            if not oks:
                tried = [r for r in runs if r.get("status") != "skipped"] or runs
                msg = (tried[-1].get("message", "") if tried else m.get("message", "")) or "no successful run"
                msg = " ".join(msg.split()).replace("|", "/")
                lines.append(f"| {mname} | " + " | ".join("—" for _ in LEVELS) + f" | n/a: {msg[:120]} | | | | "
                             f"{settings} |")
                continue
            cells = []
            for lv in LEVELS:
                p = summ[f"{lv:g}"]["per_method"].get(mname)
                cells.append(_fmt_t(p["seconds"]) if p else "—")
            b = min(oks, key=lambda r: r["error"])
            resid = max(r["residual"] for r in oks)
            drift = b["energy_drift"] if b["energy_drift"] is not None else float("nan")
            lines.append(f"| {mname} | " + " | ".join(cells) + f" | {b['error']:.2e} ({m['knob']} {b['value']:.3g}) | "
                         f"{b['residual']:.1e} | {drift:.1e} | {resid:.1e} | {settings} |")
        rcells = []
        for lv in LEVELS:
            s_ = summ[f"{lv:g}"]
            rcells.append("—" if s_["ratio"] is None else f"**{s_['ratio']:.3g}** ({s_['linknet_best']} / {s_['other_best']})")
        lines += ["| **ratio linknet-best / best other** | " + " | ".join(rcells) + " | | | | | |", ""]
        if ends:
            lines += ["<details><summary>Why each sweep ended</summary>", "", *[f"- {e}" for e in ends], "",
                      "</details>", ""]
        if sres.get("plot"):
            lines += [f"![{sname}]({Path(sres['plot']).name})", ""]
    if results.get("notes"):
        lines += ["## Notes on the peers", ""] + [f"- {n}" for n in results["notes"]] + [""]
    write_text(path, "\n".join(lines))


def plot_scene(sname, sres, path: Path):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    style = {"linknet": "-", "baseline": "--", "peer": ":"}
    for mname, m in sres["methods"].items():
        # in sweep order (coarse to fine), so a curve bending back shows round-off or a costly coarse step
        pts = [(r["error"], r["seconds"]) for r in sorted((r for r in m["runs"] if r.get("status") == "ok"
                                                           and r["error"] > 0), key=lambda r: -r["value"])]
        if not pts:
            continue
        e, t = zip(*pts)
        ax.loglog(e, t, style[m["family"]], marker="o", ms=3, label=mname)
    for lv in LEVELS:
        ax.axvline(lv, color="0.85", lw=0.8, zorder=0)
    ax.axvline(max(10 * sres["reference"]["agreement"], 1e-13), color="r", lw=0.6, ls="--", label="reference floor")
    ax.set_xlabel("error max_k |X_k(t_end) - X_ref,k(t_end)|  [m]")
    ax.set_ylabel("wall time [s]")
    ax.set_title(f"{sname}: K={sres['K']}, L={sres['L']}, t_end={sres['t_end']} s")
    ax.invert_xaxis()
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=7, loc="upper left")
    fig.tight_layout()
    try:
        write_with(path, lambda tmp: fig.savefig(tmp, dpi=110))
    finally:
        plt.close(fig)


PEER_NOTES = [
    "Timing: wall time of the integration only, model construction excluded (OpenMM Context creation, Exudyn "
    "Assemble, MuJoCo compile, linknet Simulator construction, scipy RHS setup); runs under 0.2 s are repeated "
    "and the fastest kept. Every method runs in one worker process (the same for all methods, restarted only "
    "after a timeout), timed inside it.",
    "scipy-RK45 / scipy-DOP853: solve_ivp on the unprojected index-1 formulation (seed (9),(25),(26)), "
    "atol = 1e-3·rtol; the constraint drift is not corrected (naive baseline).",
    "OpenMM VerletIntegrator (leapfrog) with constraint tolerance 1e-12; anchored masses are particles of mass "
    "1e20 (OpenMM refuses constraints on massless particles); initial velocity given at -dt/2 from the exact "
    "initial accelerations. Units m→nm, s→ps, kg→amu are exact (kJ/mol = amu nm²/ps²). OpenMM's CCMA builds "
    "its constraint-coupling matrix once from angles given by triangles of constraints or angle forces; our "
    "scenes have neither, so it iterates plain Jacobi SHAKE (150 iterations at most): too slow on chains (the "
    "iteration radius is 1 - 1.2e-6 for chain_1000, hence its residuals) and divergent on net_10x10 once the "
    "falling cloth folds (radius > 1 from t ≈ 0.1 s: NaN at every step; `python -m benchmarks.peers.openmm_peer "
    "net_10x10`). On redundant links a state of self-stress is a zero eigenvalue of A, so that radius is at least "
    "1 from the start, and a coupling matrix built from the initial angles would be singular: braced_tower's "
    "radius is 1.0000 up to 0.2 s and rises to 1.02 by 0.6 s as the tower leaves its initial shape; its runs "
    "give NaN between 0.49 and 0.66 s at every dt from 2.5 ms down (5 ms and coarser get through 0.7 s), "
    "earlier with a lighter anchor mass or a looser tolerance; triangulated_net's radius is "
    "2.64 at t = 0: NaN within 10 ms (`python -m benchmarks.peers.openmm_peer braced_tower 0.7`).",
    "Exudyn generalized-alpha, spectral radius 0.9 (Exudyn's default; 1.0 fails on the whipping chain), index-3 "
    "constraints, full Newton to 1e-12; fixed step. On chain_1000 its Newton iteration contracts only "
    "linearly (factor ~0.7 per iteration with fresh Jacobians) from the second step and gives up after 50 "
    "iterations, at every step and every Newton tolerance tried (1e-12 .. 1e-6). On the redundant scenes "
    "(redundant_truss, braced_tower, triangulated_net) a state of self-stress makes its constraint Jacobian "
    "rank-deficient: its default dense solver, ignoreSingularJacobian set, stops at the first step there "
    "('System Jacobian seems to be singular' on redundant_truss and braced_tower, a Newton diverging to a "
    "relative error of 1e19 on triangulated_net), so these run with the Eigen dense solver and "
    "ignoreSingularJacobian, Exudyn's advice for redundant constraints.",
    "MuJoCo RK4 on ball-jointed bodies built with MjSpec: exact link lengths by construction, point masses "
    "given inertia eps·m·R² (eps = 1e-12 .. 1e-6 with depth); only trees hanging from anchors (no faithful "
    "rigid distance constraint for closed loops: MuJoCo's equality constraints are soft and of connect/weld "
    "type). Its joint-space mass matrix of a chain N bodies deep is dense: chain_1000 takes ~2-3 s per forward "
    "pass, so every setting is predicted past the run budget and skipped.",
    "ASE VelocityVerlet + FixBondLengths (RATTLE, link-by-link Python loop, tolerance 1e-13); anchored masses "
    "of mass 1e20. Its link-by-link sweeps converge with redundant links too (braced_tower: the errors of "
    "linknet-rattle to four digits) but slowly there, ~0.1 s a step; not run above 24 links (triangulated_net).",
    "MoorDyn (MoorDyn-C 2.7 through `pip install moordyn`), on the rope scenes only: every rope a line of one "
    "undamped segment of stiffness EA, every mass a point, no water (density 0), RK4 at a fixed dtM from just "
    "inside its stability limit 2/omega down; the initial velocities through MoorDyn's state file (LoadState) and "
    "ropes taut at the start pre-stretched by T R / EA. An elastic line that cannot push: its error is the "
    "model's (the stretch, ~1/EA; each jerk lasting pi sqrt(m R / EA), ~1/sqrt(EA)) plus the step's, so each EA "
    "is a row and its sweep ends where the error levels off. Its undamped limit is a rope of restitution 1; its "
    "internal damping acts on slack segments too, so no MoorDyn line tends to an inelastic rope (rope_pendulum). "
    "docs/benchmarks/rope_peer.md.",
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="CI-sized run: few scenes, few settings")
    ap.add_argument("--scenes", nargs="*", help="subset of scenes")
    ap.add_argument("--methods", nargs="*", help="subset of methods (names as in the table)")
    add_output_arguments(ap, "work_precision", quick=True,
                         merge_detail="an existing results.json there is updated, only the given scenes/methods rerun")
    ap.add_argument("--models", type=Path, help="folder of scene JSON files (default models/)")
    ap.add_argument("--render", type=Path, help="only rewrite results.md and the plots from this results JSON")
    ap.add_argument("--no-cache", action="store_true", help="recompute references even if cached")
    ap.add_argument("--run-timeout", type=float, help="hard limit of one setting [s] (default: Budget)")
    ap.add_argument("--sweep-budget", type=float, help="wall time of one method's sweep on one scene [s]")
    ap.add_argument("--sweep-cap", type=float, help="extended limit to reach 6 settings or a new error level [s]")
    ap.add_argument("--in-process", action="store_true",
                    help="run the methods in this process (no worker process, so no run timeout): debugging")
    args = ap.parse_args(argv)
    quick = args.quick
    if args.render:
        out = (checked(args.out, args.merge, parser=ap) if args.out else
               checked(args.render.parent, args.merge, option=f"--render {args.render}: its folder", parser=ap))
        return render(args.render, out)
    if args.models:
        global MODELS
        MODELS = args.models
    out = resolve(ap, args, "work_precision", quick=quick)
    out.mkdir(parents=True, exist_ok=True)
    budget = QUICK_BUDGET if quick else FULL_BUDGET
    budget = replace(budget, **{k: v for k, v in (("run_timeout", args.run_timeout), ("sweep", args.sweep_budget),
                                                  ("sweep_cap", args.sweep_cap)) if v is not None})
    scenes = args.scenes or (list(QUICK_SCENES) if quick else list(SCENES))
    t_start = time.perf_counter()
    load_start = _loadavg()
    date_start = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")
    methods = all_methods(quick)
    if args.methods:
        methods = [m for m in methods if m.name in args.methods]
    results = {"meta": {}, "scenes": {}, "notes": list(PEER_NOTES), "unavailable": {}}
    previous = None
    if args.merge and (out / "results.json").exists():
        previous = json.loads((out / "results.json").read_text())
        results["scenes"] = previous["scenes"]
        results["unavailable"] = previous.get("unavailable", {})
    for m in methods:
        ok, why = m.available()
        if not ok:
            results["unavailable"][m.name] = why
            print(f"  {m.name}: unavailable: {why}")
    methods = [m for m in methods if m.name not in results["unavailable"]]
    runner = InProcessRunner() if args.in_process else IsolatedRunner()
    reference_seconds = 0.0
    for sname in scenes:
        t_scene = time.perf_counter()
        t_end = SCENES[sname]
        try:
            spec = load_benchmark_scene(sname)
        except Exception as e:
            print(f"[{sname}] cannot load: {e}")
            results["scenes"][sname] = {"error": str(e)}
            continue
        print(f"[{sname}] K={spec.K} L={spec.L} t_end={t_end}")
        ref = reference(spec, t_end, cache=not args.no_cache)
        if not ref.get("cached"):
            reference_seconds += float(ref["seconds"])
        kept = {}
        if previous and sname in previous["scenes"] and previous["scenes"][sname].get("digest") == spec.digest():
            kept = {n: m for n, m in previous["scenes"][sname]["methods"].items()
                    if n not in {m_.name for m_ in methods}}
        sres = {"K": spec.K, "L": spec.L, "t_end": t_end, "digest": spec.digest(),
                **({"note": SCENE_NOTES[sname]} if sname in SCENE_NOTES else {}),
                "reference": {k: ref[k] for k in ("agreement", "verified", "rtol_ref", "rtol_check", "residual",
                                                  "energy_drift", "seconds", "steps")}, "methods": dict(kept)}
        sres["reference"] = {k: (v.item() if hasattr(v, "item") else v) for k, v in sres["reference"].items()}
        for m in methods:
            if getattr(m, "ropes_only", False) and not spec.unilateral:
                continue   # a rope model (MoorDyn's lines) has no row on the scenes of rods
            try:
                runs, summary = sweep(m, spec, t_end, ref, quick=quick, budget=budget, runner=runner)
            except Exception as e:   # never lose the other methods' results to one adapter's bug
                traceback.print_exc()
                runs, summary = [{"status": "failed", "message": f"{type(e).__name__}: {e}"}], {"stop": "driver error"}
            sres["methods"][m.name] = {"family": m.family, "knob": m.knob, "order": m.order, "runs": runs,
                                       "sweep": summary}
            print(f"    {'':28s} -> {summary.get('stop')} ({summary.get('wall_seconds', 0):.1f} s)", flush=True)
        order = [m_.name for m_ in all_methods(quick)]
        sres["methods"] = dict(sorted(sres["methods"].items(),
                                      key=lambda kv: order.index(kv[0]) if kv[0] in order else len(order)))
        sres["summary"] = summarize(sres)
        try:
            p = out / f"{sname}.png"
            plot_scene(sname, sres, p)
            sres["plot"] = str(p)
        except Exception as e:
            print(f"  plot failed: {e}")
        sres["wall_seconds"] = time.perf_counter() - t_scene
        print(f"[{sname}] done in {sres['wall_seconds']:.0f} s", flush=True)
        results["scenes"][sname] = sres
        write_text(out / "results.partial.json", json.dumps(results, indent=1, default=_json_default))
    runner.close()
    if previous:   # keep the scenes that were not rerun, in the benchmark's order
        results["scenes"] = {n: results["scenes"][n] for n in SCENES if n in results["scenes"]}
    results["meta"] = {"date": date_start,
                       "command": "python -m benchmarks.work_precision" + (" " + " ".join(argv) if argv else
                                                                           " " + " ".join(sys.argv[1:])).rstrip(),
                       "quick": quick, "machine": _machine(), "versions": _versions(),
                       "total_seconds": time.perf_counter() - t_start,
                       "reference_seconds": reference_seconds,
                       "budget": asdict(budget), "isolated": not args.in_process,
                       "worker_restarts": runner.restarts,
                       "load_average": {"start": load_start, "end": _loadavg()},
                       "provenance": {"single_run": previous is None, "scenes": scenes,
                                      "methods": [m.name for m in methods]}}
    if previous:
        results["meta"]["provenance"]["merged_from"] = (previous["meta"].get("provenance", {}).get("merged_from", [])
                                                        + previous["meta"].get("merged_from", [])
                                                        + [previous["meta"]["date"]])
    write_text(out / "results.json", json.dumps(results, indent=1, default=_json_default))
    write_markdown({k: v for k, v in results.items()} | {"scenes": {k: v for k, v in results["scenes"].items()
                                                                    if "methods" in v}}, out / "results.md")
    (out / "results.partial.json").unlink(missing_ok=True)
    print(f"wrote {out / 'results.json'} and {out / 'results.md'} in {results['meta']['total_seconds']:.0f} s")
    return results


def render(path: Path, out: Path):
    """Rewrite results.json / results.md / plots from a (possibly partial) results file."""
    results = json.loads(Path(path).read_text())
    for sname, sres in results["scenes"].items():
        if "methods" not in sres:
            continue
        sres["summary"] = summarize(sres)
        p = out / f"{sname}.png"
        plot_scene(sname, sres, p)
        sres["plot"] = str(p)
    if not results.get("meta"):
        results["meta"] = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                           "command": "python -m benchmarks.work_precision (interrupted; rendered from partial results)",
                           "quick": False, "machine": _machine(), "versions": _versions(), "total_seconds": float("nan")}
    write_text(out / "results.json", json.dumps(results, indent=1, default=_json_default))
    write_markdown(results | {"scenes": {k: v for k, v in results["scenes"].items() if "methods" in v}},
                   out / "results.md")
    return results


def _json_default(o):
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, np.bool_):
        return bool(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, float) and not math.isfinite(o):
        return None
    raise TypeError(type(o))


if __name__ == "__main__":
    main()
