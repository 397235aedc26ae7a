"""The quick work-precision benchmark runs and its results are *correct*; times are never asserted.

Checks, per scene of `python -m benchmarks.work_precision --quick`:
- the independent reference is verified (two DOP853 tolerances agree) and satisfies the constraints;
- every run of every method ends finite; adaptive methods stay within their stated bound
  (error <= 1e3 rtol over 2 s); fixed-step methods converge at their order (observed >= 0.7 x nominal);
- linknet's methods keep the links at their lengths (relative residual <= 1e-11) and its symplectic
  methods show no energy drift beyond their truncation error;
- the index-1 right-hand side written for the baselines from the seed agrees with linknet's Dynamics
  (two independent implementations of (9), (25), (26)).
"""
from __future__ import annotations

import math

import numpy as np
import sys
from pathlib import Path

import pytest

# the benchmarks package lives at the repository root, beside tests/ (pytest run from anywhere)
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks import work_precision as wp
from benchmarks.index1 import Index1System

linknet_core = pytest.importorskip("linknet_core")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("work_precision")
    return wp.main(["--quick", "--out", str(out)]), out


def _methods_by_name():
    return {m.name: m for m in wp.all_methods(quick=True)}


def _ok_runs(m):
    return [r for r in m["runs"] if r.get("status") == "ok"]


def test_references_are_verified(quick):
    res, _ = quick
    for name, s in res["scenes"].items():
        ref = s["reference"]
        # two tolerances agree; 1e-11 rather than 1e-12 because four_bar's pair agrees to ~3e-12
        assert ref["agreement"] <= 1e-11, (name, ref)
        assert ref["residual"] <= 1e-12, (name, ref)
        assert ref["energy_drift"] <= 1e-11, (name, ref)


def _exact_from_the_start(runs):
    """The first successful setting is already below the reference floor (a rigid cluster integrated as a
    rigid body is exact at any step): there is no convergence to observe, only exactness."""
    return bool(runs) and not runs[0]["resolved"]


def test_every_quick_scene_ran_every_linknet_method(quick):
    res, _ = quick
    names = [n for n in linknet_core.METHODS]
    for sname in wp.QUICK_SCENES:
        s = res["scenes"][sname]
        for n in names:
            runs = _ok_runs(s["methods"][f"linknet-{n}"])
            assert len(runs) >= 2 or _exact_from_the_start(runs), (sname, n, s["methods"][f"linknet-{n}"]["runs"])


def test_no_run_returns_garbage(quick):
    res, _ = quick
    for sname, s in res["scenes"].items():
        for mname, m in s["methods"].items():
            for r in m["runs"]:
                assert r.get("status") in ("ok", "failed", "unsupported", "timeout", "skipped"), (sname, mname, r)
                if r.get("status") != "ok":   # a failure, timeout or skipped setting must say why
                    assert r.get("message"), (sname, mname, r)
                else:
                    assert np.isfinite(r["error"]) and r["wall_seconds"] >= r["seconds"], (sname, mname, r)
            assert m["sweep"]["stop"], (sname, mname)   # every sweep says why it ended


def test_results_record_one_run_and_its_budget(quick):
    res, out = quick
    meta = res["meta"]
    assert meta["provenance"]["single_run"] is True
    assert set(meta["provenance"]["scenes"]) == set(wp.QUICK_SCENES)
    assert meta["budget"]["run_timeout"] > 0 and meta["isolated"] is True
    assert "**One run**" in (out / "results.md").read_text()


def test_a_run_over_its_timeout_is_killed_recorded_and_ends_the_sweep():
    """The worker process running a setting is killed at the timeout; the setting is recorded as a timeout,
    the finer ones as skipped, and the next request gets a fresh worker that works."""
    from benchmarks.peers.isolated import IsolatedRunner
    from benchmarks.peers.scipy_baseline import ScipyIVP
    spec = wp.load_benchmark_scene("chain_10")
    ref = {"X": spec.X0, "agreement": 1e-13}
    budget = wp.Budget(run_timeout=0.01, sweep=1.0, sweep_cap=1.0, min_ok=1)
    with IsolatedRunner() as runner:
        # scipy RK45 at rtol <= 1e-4 on chain_10 over 20 s: thousands of right-hand sides, ~1 s >> 0.01 s
        rows, summary = wp.sweep(ScipyIVP("RK45"), spec, 20.0, ref, quick=True, budget=budget, runner=runner,
                                 log=lambda *a: None)
        assert [r["status"] for r in rows] == ["timeout", "skipped", "skipped"], rows
        assert "timeout" in summary["stop"] and all(r["message"] for r in rows)
        status, result, _ = runner.run(ScipyIVP("RK45"), spec, 0.05, 1e-3, 0.0, timeout=120)
        assert status == "ok" and np.all(np.isfinite(result.X)), (status, result)
        assert runner.restarts == 1


def test_adaptive_methods_within_stated_bound(quick):
    res, _ = quick
    methods = _methods_by_name()
    for sname, s in res["scenes"].items():
        for mname, m in s["methods"].items():
            if m["knob"] != "rtol":
                continue
            for r in _ok_runs(m):
                bound = methods[mname].error_bound(r["value"])
                assert r["error"] <= bound, f"{sname} {mname} rtol={r['value']:g}: error {r['error']:.3g} > {bound:.3g}"


def test_fixed_step_methods_converge_at_their_order(quick):
    res, _ = quick
    for sname, s in res["scenes"].items():
        for mname, m in s["methods"].items():
            if m["knob"] != "dt" or not m["order"]:
                continue
            runs = sorted(_ok_runs(m), key=lambda r: -r["value"])
            checked = 0
            for a, b in zip(runs, runs[1:]):
                # only pairs in the asymptotic range, above the reference floor and round-off
                if b["error"] < 1e-10 or not b["resolved"] or a["error"] > 1e-2:
                    continue
                p = math.log(a["error"] / b["error"]) / math.log(a["value"] / b["value"])
                assert p >= 0.7 * m["order"], f"{sname} {mname}: observed order {p:.2f} < 0.7 x {m['order']}"
                checked += 1
            if mname.startswith("linknet-") and sname != "chain_10" and not _exact_from_the_start(runs):
                assert checked >= 1, (sname, mname, runs)


def test_linknet_keeps_links_rigid_and_energy(quick):
    res, _ = quick
    for sname, s in res["scenes"].items():
        for mname, m in s["methods"].items():
            if m["family"] != "linknet":
                continue
            for r in _ok_runs(m):
                assert r["residual"] <= 1e-11, (sname, mname, r["value"], r["residual"])
                if m["knob"] == "dt" and r["error"] < 1e-3:
                    # symplectic and projected: the energy error is of the size of the truncation error,
                    # never a secular drift larger than the position error it comes with
                    assert r["energy_drift"] <= max(10 * r["error"], 1e-10), (sname, mname, r)


def test_outputs_written(quick):
    res, out = quick
    md = (out / "results.md").read_text()
    for sname in wp.QUICK_SCENES:
        assert f"## {sname}" in md
        assert (out / f"{sname}.png").stat().st_size > 10_000
        for lv in ("1e-03", "1e-06", "1e-09"):
            assert lv in res["scenes"][sname]["summary"] or f"{float(lv):g}" in res["scenes"][sname]["summary"]
    assert res["meta"]["versions"]["numpy"] and res["meta"]["machine"]["cores"]


@pytest.mark.parametrize("name", ["double_pendulum", "chain_10"])
def test_mujoco_model_built_with_mjspec_equals_the_mjcf_one(name):
    """chain_1000 is built through MjSpec (MJCF stops at ~400 nested bodies): on scenes both routes can
    describe, the compiled models are the same array for array."""
    mujoco = pytest.importorskip("mujoco")
    from dataclasses import replace
    from benchmarks.peers import mujoco_peer as mp
    spec = wp.load_benchmark_scene(name)
    spec = replace(spec, mass=spec.mass / float(np.median(spec.mass[spec.free])))
    parent, order = mp._tree(spec)
    eps = mp.inertia_eps(parent, order)
    a = mp.tree_model(spec, parent, order, eps)
    a.opt.timestep = 1e-3
    b = mujoco.MjModel.from_xml_string(mp.mjcf_tree(spec, parent, order, eps, 1e-3))
    for field in ("body_parentid", "body_pos", "body_quat", "body_ipos", "body_iquat", "body_mass", "body_inertia",
                  "jnt_type", "dof_parentid", "dof_damping", "dof_armature"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field
    for field in ("timestep", "gravity", "integrator", "disableflags"):
        assert np.array_equal(getattr(a.opt, field), getattr(b.opt, field)), field


@pytest.mark.parametrize("name", ["double_pendulum", "four_bar", "redundant_truss", "net_10x10"])
def test_index1_rhs_agrees_with_linknet_dynamics(name):
    """Two independent implementations of the tensions and accelerations, at a perturbed moving state."""
    spec = wp.load_benchmark_scene(name)
    scene = linknet_core.load_scene(wp.MODELS / f"{name}.json")
    dyn = linknet_core.Dynamics(scene)
    rng = np.random.default_rng(5)
    X = spec.X0 + 1e-3 * rng.standard_normal(spec.X0.shape) * spec.free[:, None]
    X = dyn.project_positions(X)[0]
    U = dyn.project_velocities(X, rng.standard_normal(spec.X0.shape) * spec.free[:, None])
    acc_ref, T_ref = Index1System(spec).accelerations(X, U)
    acc, T = dyn.accelerations(X, U, None)
    scale = max(np.abs(acc_ref).max(), np.linalg.norm(spec.gravity))   # the truss is rigid: acc ~ 0
    assert np.abs(acc - acc_ref).max() <= 1e-10 * scale
    # tensions are unique except for redundant scenes, where both are minimum-norm
    assert np.abs(T - T_ref).max() <= 1e-8 * max(1.0, np.abs(T_ref).max())
