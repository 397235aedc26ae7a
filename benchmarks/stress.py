"""Numerical-stability stress suite for linknet_core.

    python -m benchmarks.stress            # every case at full size (long runs included), writes
                                           # build/stress/stress.json and stress.md
    python -m benchmarks.stress --quick    # the reduced sizes the default tests use: build/stress/stress_quick.*
    python -m benchmarks.stress --case whip scale            # stress_whip_scale.json and .md
    python -m benchmarks.stress --case whip --merge          # into the tracked docs/benchmarks
    python -m benchmarks.stress --combine --merge            # docs/benchmarks/stress.json from its stress_*.json

Every case states its pass criterion, measures the figures, and says whether it passed. A case that makes
linknet raise a clear LinknetError where the criterion allows it ("continue correctly or stop with a clear
message") passes; an uncaught crash, a NaN, or a silent wrong answer fails. Independent checks come from
physics (analytic solutions, conservation) or from the index-1 reference of benchmarks.index1.
"""
from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    __package__ = "benchmarks"

import linknet_core as ln  # noqa: E402

from .index1 import Index1System  # noqa: E402
from .output import add_output_arguments, resolve, write_text  # noqa: E402
from .scene_spec import SceneSpec  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def _case(name, criterion, measured, passed, t0, note=""):
    return {"case": name, "criterion": criterion, "measured": measured, "passed": bool(passed),
            "seconds": round(time.perf_counter() - t0, 3), "note": note}


class _Budget(Exception):
    pass


REFERENCE_AGREEMENT = 1e-9   # [m]: a reference is verified when two independent resolutions agree this well


def _independent_reference(scene, t_end, rtol=1e-12, max_rhs=300_000):
    """scipy DOP853 on the unprojected index-1 formulation (benchmarks.index1); raises _Budget after
    max_rhs right-hand sides (stiff mass-ratio chains can need millions)."""
    spec = SceneSpec.from_core(scene)
    sys_ = Index1System(spec)
    count = [0]

    def rhs(t, y):
        count[0] += 1
        if count[0] > max_rhs:
            raise _Budget(f"independent reference needs more than {max_rhs} right-hand sides")
        return sys_.rhs(t, y)
    sol = solve_ivp(rhs, (0, t_end), sys_.y0(), method="DOP853", rtol=rtol, atol=rtol * 1e-3)
    if sol.status != 0:
        raise RuntimeError(sol.message)
    return sys_.split(sol.y[:, -1])[0], count[0]


def _rk4_index1(sys_, t_end, n):
    """Classical RK4 with n fixed steps on the index-1 equations: no step controller, so the right-hand side's
    round-off (cond A ~ 1e12 on graded_up) cannot make it thrash, and halving the step shows its error."""
    y = sys_.y0()
    h = t_end / n
    for i in range(n):
        t = i * h
        k1 = sys_.rhs(t, y)
        k2 = sys_.rhs(t + h / 2, y + h / 2 * k1)
        k3 = sys_.rhs(t + h / 2, y + h / 2 * k2)
        k4 = sys_.rhs(t + h, y + h * k3)
        y = y + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    return sys_.split(y)[0]


def _dop853_pair(scene, t_end, max_rhs):
    """scipy DOP853 at rtol 1e-10 and 1e-11: (X at 1e-11, their difference, right-hand sides used)."""
    X1, n1 = _independent_reference(scene, t_end, rtol=1e-10, max_rhs=max_rhs)
    X2, n2 = _independent_reference(scene, t_end, rtol=1e-11, max_rhs=max_rhs)
    return X2, float(np.linalg.norm(X1 - X2, axis=1).max()), n1 + n2


def verified_reference(scene, t_end, max_rhs, cheap_rhs=50_000, rk4_rhs=300_000):
    """An answer independent of linknet_core (benchmarks.index1: the seed's (9), (25), (26), written
    separately, no projection), verified by two resolutions agreeing to REFERENCE_AGREEMENT. Cheapest first:
    1. scipy DOP853 at rtol 1e-10 and 1e-11 (two tolerances), each within cheap_rhs right-hand sides;
    2. classical RK4 at n fixed steps, n doubling from 2^10 (within rk4_rhs in all): no step controller, so
       a right-hand side with round-off noise (cond A ~ 1e12 on graded_up) cannot make it thrash; accepted
       when the last two resolutions agree and the pair before agrees too or differs >= 8x more (converging
       at RK4's order: its error is then about 1/15 of the last difference);
    3. the DOP853 pair again, each within max_rhs (stiff chains: the step is stability-bound).
    Returns X and how it was verified; 'verified' False when no route got there."""
    t0 = time.perf_counter()
    out = {"formulation": "benchmarks.index1 (seed (9), (25), (26); independent of linknet_core)", "tried": []}

    def done(X, method, diff, rhs):
        return X, out | {"method": method, "agreement_m": diff, "rhs_evaluations": rhs,
                         "verified": diff <= REFERENCE_AGREEMENT, "seconds": time.perf_counter() - t0}

    def dop853(budget):
        try:
            X, diff, rhs = _dop853_pair(scene, t_end, budget)
            if diff <= REFERENCE_AGREEMENT:
                return done(X, "scipy DOP853 rtol 1e-11, checked against rtol 1e-10", diff, rhs)
            out["tried"].append(f"DOP853 rtol 1e-10 vs 1e-11 differ by {diff:.2g} m")
        except _Budget as e:
            out["tried"].append(f"DOP853: {e}")
        return None

    r = dop853(min(cheap_rhs, max_rhs))
    if r:
        return r
    sys_ = Index1System(SceneSpec.from_core(scene))
    n, used, Xs, diffs = 2 ** 10, 0, [], []
    with np.errstate(all="ignore"):   # a too coarse RK4 step on a stiff chain overflows: that is the test
        while used + 4 * n <= rk4_rhs:
            Xs.append(_rk4_index1(sys_, t_end, n))
            used += 4 * n
            if len(Xs) >= 2:
                a, b = Xs[-2], Xs[-1]
                diffs.append(float(np.linalg.norm(a - b, axis=1).max()) if np.all(np.isfinite(a))
                             and np.all(np.isfinite(b)) else float("inf"))
            # three resolutions: the last two agree and the pair before either agrees too or differs 8x more
            # (RK4 converging at its order); two alone can agree by accident before the asymptotic range (the
            # stiff light_cart: 4096 and 8192 steps agree to 8e-10 m, both 3.3e-7 m off; 16384 is 5e-7 off)
            if len(diffs) >= 2 and diffs[-1] <= REFERENCE_AGREEMENT and (
                    diffs[-2] <= REFERENCE_AGREEMENT or diffs[-2] >= 8 * diffs[-1]):
                return done(Xs[-1], f"RK4 with {n} fixed steps, checked against {n // 2} and {n // 4}",
                            diffs[-1], used)
            n *= 2
    prev = Xs[-1] if Xs else sys_.split(sys_.y0())[0]
    diff = diffs[-1] if diffs else float("inf")
    out["tried"].append(f"RK4 up to {n // 2} steps ({used} right-hand sides): last pair differs by {diff:.2g} m")
    if max_rhs > cheap_rhs:
        r = dop853(max_rhs)
        if r:
            return r
    return prev, out | {"method": "none verified", "verified": False, "seconds": time.perf_counter() - t0}


# ------------------------------------------------------------------------------------------ mass ratios
def mass_ratio_scenes(n_links=10):
    """Chains of n_links from a pivot, released from horizontal, with mass ratios 1e-6 .. 1e6 along them."""
    n = n_links
    base = np.ones(n + 1)
    heavy_tip = base.copy(); heavy_tip[-1] = 1e6                    # light chain, heavy end
    light_tip = base.copy(); light_tip[-1] = 1e-6                   # heavy chain, light tip
    light_cart = base.copy(); light_cart[1] = 1e-6                  # a light "cart" carrying the rest
    graded_down = np.concatenate([[1.0], np.logspace(6, -6, n)])    # 1e6 next to the pivot .. 1e-6 at the tip
    graded_up = np.concatenate([[1.0], np.logspace(-6, 6, n)])      # 1e-6 next to the pivot .. 1e6 at the tip
    return {name: ln.builders.chain(n, total_length=1.0, masses=m, name=f"ratio_{name}")
            for name, m in (("heavy_tip", heavy_tip), ("light_tip", light_tip), ("light_cart", light_cart),
                            ("graded_down", graded_down), ("graded_up", graded_up))}


def _run(scene, t_end, method, max_steps, n_out=50, **kw):
    """Run with outputs at n_out equally spaced times: the largest residual and tension seen there."""
    sim = ln.Simulator(scene, method=method, max_steps_per_call=max_steps, error_estimate=False, **kw)
    resid, finite, tmax = 0.0, True, 0.0
    for t in np.linspace(0, t_end, n_out + 1)[1:]:
        sim.advance(t)
        out = sim.outputs()
        resid = max(resid, float(sim.dyn.constraint_residual(out["X"])))
        finite &= bool(np.all(np.isfinite(out["T"])) and np.all(np.isfinite(out["X"])))
        tmax = max(tmax, float(np.abs(out["T"]).max()))
    return sim, {"outcome": "completed", "max_residual": resid, "tensions_finite": finite,
                 "max_abs_tension_N": tmax, "steps": sim.integrator.stats.steps,
                 "rejected": sim.integrator.stats.rejected}


def case_mass_ratios(quick=True):
    """Criterion: on chains with mass ratios 1e-6..1e6 DOP853 (rtol=1e-8) either completes -- with relative
    constraint residual <= 1e-10 at each of 50 outputs, finite tensions there, and within its stated bound
    1e3*rtol = 1e-5 m of an independent, verified reference (benchmarks.index1, the seed's equations written
    separately from linknet_core: scipy DOP853 at rtol 1e-10 and 1e-11 agreeing to 1e-9 m, or RK4 at n and 2n
    fixed steps agreeing to 1e-9 m and converging at RK4's order, cheapest first), i.e. it never reports
    success with a
    wrong answer -- or stops with a clear SolverError. The four non-stiff chains must complete; a chain whose
    reference cannot be verified fails the case. Each chain runs as long as its reference can be verified
    (full size: 0.5 s; light_cart 0.1 s, graded_down 0.2 s; quick: 0.05 s). graded_up (1e-6 kg next to the
    pivot under a 1e6 kg tip) is stiff and its tension matrix has condition ~1e12 (physically: a light mass
    between links whose tensions must nearly balance), so it runs 1 ms only and may stop with a clear
    SolverError."""
    t0 = time.perf_counter()
    # simulated time per chain: as long as an independent reference can be verified to 1e-9 m (measured at
    # full size with the DOP853 pair: graded_down agrees to 3e-11 m at 0.2 s but 1.5e-7 m at 0.3 s and 0.1 m
    # at 0.5 s, its light tail whips; light_cart's stiff cart mode (~2e5 rad/s) needs 5e5 right-hand sides
    # for 0.1 s, which agree to 8e-10 m, and 1.3e6 for 0.2 s, which agree only to 2.3e-9 m)
    t_ends = ({"heavy_tip": 0.05, "light_tip": 0.05, "light_cart": 0.05, "graded_down": 0.05, "graded_up": 1e-3}
              if quick else
              {"heavy_tip": 0.5, "light_tip": 0.5, "light_cart": 0.1, "graded_down": 0.2, "graded_up": 1e-3})
    max_steps = 20_000 if quick else 400_000
    max_rhs = 60_000 if quick else 2_000_000   # per scipy solve (see verified_reference)
    measured, ok = {}, True
    for name, scene in mass_ratio_scenes(10 if quick else 30).items():
        te = t_ends[name]
        free_mass = np.asarray(scene.mass)[~np.asarray(scene.fixed)]
        m = {"t_end_s": te, "free_masses_kg_min_max": [float(free_mass.min()), float(free_mass.max())]}
        Xr, m["reference"] = verified_reference(scene, te, max_rhs)
        try:
            sim, r = _run(scene, te, "dop853", max_steps, rtol=1e-8)
            r["error_vs_reference_m"] = float(np.linalg.norm(sim.state.X - Xr, axis=1).max())
            r["within_stated_bound_1e-5_m"] = r["error_vs_reference_m"] <= 1e-5
            ok &= m["reference"]["verified"] and r["within_stated_bound_1e-5_m"]
            ok &= r["max_residual"] <= 1e-10 and r["tensions_finite"]
            m["dop853"] = r
        except ln.LinknetError as e:
            m["dop853"] = {"outcome": "stopped", "message": f"{type(e).__name__}: {e}"[:300]}
            ok &= isinstance(e, ln.SolverError) and name == "graded_up"
        measured[name] = m
    return _case("mass_ratios", case_mass_ratios.__doc__.split("Criterion: ")[1].strip(), measured, ok, t0)


# ------------------------------------------------------------------------------------------ redundancy
def swinging_truss():
    """The shipped redundant truss (2 bays, both diagonals on every face) hung from only two wall anchors
    (w0, w1: a hinge along y) instead of three: a *mobile* and overconstrained network, like Bricard's
    linkage; it swings as one rigid body about the hinge while carrying 6 states of self-stress."""
    d = ln.load_scene(ROOT / "models" / "redundant_truss.json").to_dict()
    for m in d["masses"]:
        if m["name"] == "w2":
            m["fixed"] = False
            m["mass"] = 1.0
    d["name"] = "swinging_truss"
    return ln.Scene.from_dict(d)


def _rigid_pendulum_reference(scene, t_end):
    """Rigid body rotating about the hinge through the two anchors: I phi'' = torque of gravity, solved by
    scipy to 1e-12, then the initial positions rotated by phi(t_end). Independent of the link network."""
    X0 = np.asarray(scene.X0)
    fixed = np.asarray(scene.fixed)
    a, b = X0[fixed][:2]
    axis = (b - a) / np.linalg.norm(b - a)
    free = ~fixed
    m = np.asarray(scene.mass)[free]
    r = X0[free] - a
    r_perp = r - np.outer(r @ axis, axis)
    inertia = float(np.sum(m * np.einsum("ij,ij->i", r_perp, r_perp)))
    g = np.asarray(scene.gravity)

    def rot(phi):
        K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        return np.eye(3) + math.sin(phi) * K + (1 - math.cos(phi)) * K @ K

    def rhs(t, y):
        R = rot(y[0])
        rr = r @ R.T
        torque = np.sum(np.cross(rr, m[:, None] * g[None, :]), axis=0) @ axis
        return [y[1], torque / inertia]

    sol = solve_ivp(rhs, (0, t_end), [0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-14)
    X = X0.copy()
    X[free] = a + r @ rot(sol.y[0, -1]).T
    return X


def case_redundant(quick=True):
    """Criterion: redundant networks run without failure; link forces on the masses are unique (linknet's
    C^T T equals that of an independent least-squares T to 1e-9 relative); linknet's tensions are the
    minimum-norm ones (orthogonal to every self-stress to 1e-9 relative); the overconstrained swinging
    truss follows the rigid-body pendulum about its hinge to 1e-7 m (DOP853 rtol 1e-10) and the fixed
    redundant truss stays at rest (|X - X0| <= 1e-9 m)."""
    t0 = time.perf_counter()
    measured, ok = {}, True
    t_end = 0.5 if quick else 2.0
    for name, scene in (("redundant_truss", ln.load_scene(ROOT / "models" / "redundant_truss.json")),
                        ("swinging_truss", swinging_truss())):
        m = {}
        try:
            res = ln.simulate(scene, t_end, method="dop853", rtol=1e-10, n_out=11)
            dyn = ln.Dynamics(scene)
            X, U = res.X[-1], res.U[-1]
            T = dyn.tensions(X, U, None)
            # independent: dense C, least squares on A T = B from benchmarks.index1 (seed (25)-(26))
            spec = SceneSpec.from_core(scene)
            T_ind = Index1System(spec).tensions(X, U)
            f_lk, f_ind = dyn.link_forces(X, T), dyn.link_forces(X, T_ind)
            fscale = max(np.abs(f_ind).max(), 1e-300)
            E = (X[scene.k2] - X[scene.k1]) / scene.length[:, None]
            C = np.zeros((scene.L, 3 * scene.K))
            for l in range(scene.L):   # once, for the check only
                C[l, 3 * scene.k1[l]:3 * scene.k1[l] + 3] = E[l]
                C[l, 3 * scene.k2[l]:3 * scene.k2[l] + 3] = -E[l]
            C = C[:, np.repeat(~np.asarray(scene.fixed), 3)]
            _, s, Vt = np.linalg.svd(C.T, full_matrices=True)
            rank = int(np.sum(s > 1e-10 * s[0]))
            N = Vt[rank:].T   # self-stresses: C^T N = 0
            m.update({"self_stresses": int(N.shape[1]), "structure": dyn.structure.kind,
                      "max_residual": float(res.residual.max()),
                      "force_difference_rel": float(np.abs(f_lk - f_ind).max() / fscale),
                      "tension_selfstress_component_rel": float(np.abs(N.T @ T).max() / max(np.abs(T).max(), 1e-300))
                      if N.size else 0.0})
            ok &= m["force_difference_rel"] <= 1e-9 and m["tension_selfstress_component_rel"] <= 1e-9
            ok &= m["max_residual"] <= 1e-10 and m["self_stresses"] > 0
            if name == "swinging_truss":
                Xr = _rigid_pendulum_reference(scene, t_end)
                m["error_vs_rigid_pendulum_m"] = float(np.linalg.norm(X - Xr, axis=1).max())
                ok &= m["error_vs_rigid_pendulum_m"] <= 1e-7
            else:
                m["max_displacement_m"] = float(np.abs(res.X - np.asarray(scene.X0)[None]).max())
                ok &= m["max_displacement_m"] <= 1e-9
        except Exception as e:
            m["failed_with"] = f"{type(e).__name__}: {e}"
            ok = False
        measured[name] = m
    return _case("redundant", case_redundant.__doc__.split("Criterion: ")[1].strip(), measured, ok, t0)


# ------------------------------------------------------------------------------------------ singular passages
def parallelogram_four_bar(speed=5.0):
    """A parallelogram four-bar (crank = rocker, coupler = ground) in zero gravity: its crank turns through
    the flat position, where all links are collinear, the tension matrix is singular and the
    antiparallelogram branch crosses. On the parallelogram branch the coupler translates, so the kinetic
    energy (m_B + m_C) r^2 w^2 / 2 keeps w constant: theta(t) = theta0 + w t exactly."""
    return ln.builders.four_bar(ground=1.0, crank=0.4, coupler=1.0, rocker=0.4, crank_angle_deg=60.0,
                                crank_speed=speed, gravity=(0.0, 0.0, 0.0), name="parallelogram_four_bar")


def taut_string_under_gravity():
    """A mass between two anchors on two collinear links, at rest, with gravity across the links: the only
    position allowed by (11) is the middle, yet (13) allows any vertical acceleration (A is singular)."""
    return ln.Scene.from_dict({
        "name": "taut_string_gravity", "gravity": [0, 0, -9.81],
        "masses": [{"name": "left", "position": [0, 0, 0], "fixed": True},
                   {"name": "middle", "mass": 1.0, "position": [1, 0, 0]},
                   {"name": "right", "position": [2, 0, 0], "fixed": True}],
        "links": [{"a": "left", "b": "middle"}, {"a": "middle", "b": "right"}]})


def case_singular(quick=True):
    """Criterion: through a singular configuration the solver either continues correctly or stops with a
    clear LinknetError naming the problem; never NaN, never a silent wrong answer. Parallelogram four-bar
    through flat: matches theta0 + w t to 1e-6 m or stops clearly. Taut string moving sideways: refused at
    load with a ConsistencyError (hypothesis (35)). Taut string at rest under gravity (the only position
    (11) allows is the middle; (13) leaves the vertical acceleration free, and no finite tension holds it): refused
    at the start, its weight loading a flex the string holds only at second order (ConsistencyError), or, run
    anyway, the middle mass stays within what the projection's reported floor allows, sqrt(2 floor) R (a residual eps of (11)
    leaves a mass at a singular configuration up to that far off), and at most 1e-5 m, at every output (every
    0.01 s), up to the end or to a clear stop (step budget 2000 per 0.01 s)."""
    t0 = time.perf_counter()
    measured, ok = {}, True
    # parallelogram four-bar
    speed = 5.0
    scene = parallelogram_four_bar(speed)
    t_end = 1.0   # theta from 60 deg through 180 deg (flat) to ~346 deg
    th = math.radians(60.0) + speed * t_end
    exact = {"B": 0.4 * np.array([math.cos(th), 0, math.sin(th)])}
    exact["C"] = np.array([1.0, 0, 0]) + exact["B"]
    names = list(scene.mass_names)
    for method, kw in (("rattle", {"dt": 1e-4}), ("dop853", {"rtol": 1e-10}), ("dopri5", {"rtol": 1e-8})):
        key = f"parallelogram_{method}"
        try:
            res = ln.simulate(scene, t_end, method=method, n_out=101, **kw)
            X = res.X[-1]
            err = max(np.linalg.norm(X[names.index(k)] - v) for k, v in exact.items())
            finite = bool(np.all(np.isfinite(res.X)) and np.all(np.isfinite(res.T)))
            measured[key] = {"outcome": "continued", "error_vs_parallelogram_m": float(err),
                             "max_residual": float(res.residual.max()), "finite": finite,
                             "max_abs_tension_N": float(np.abs(res.T).max())}
            ok &= finite and err <= 1e-6
        except ln.LinknetError as e:
            measured[key] = {"outcome": "stopped", "message": f"{type(e).__name__}: {e}"[:400]}
        except Exception as e:
            measured[key] = {"outcome": "crashed", "message": f"{type(e).__name__}: {e}"[:400]}
            ok = False
    # taut string moving sideways
    try:
        ln.Simulator(ln.builders.taut_string(speed=1.0), method="rattle", dt=1e-3)
        measured["taut_string_moving"] = {"outcome": "accepted (wrong: violates (35))"}
        ok = False
    except ln.ConsistencyError as e:
        measured["taut_string_moving"] = {"outcome": "refused", "message": str(e)[:300]}
    except Exception as e:
        measured["taut_string_moving"] = {"outcome": "crashed", "message": f"{type(e).__name__}: {e}"[:300]}
        ok = False
    # taut string at rest under gravity
    # (a step budget turns a controller that shrinks its step without end into a stop, so the case cannot hang;
    # what it had output before stopping must still be right: a stop does not excuse a wrong answer given earlier)
    scene = taut_string_under_gravity()
    middle = np.array([1.0, 0.0, 0.0])
    for method, kw in (("rattle", {"dt": 1e-3}), ("dop853", {"rtol": 1e-8})):
        key = f"taut_string_gravity_{method}"
        dev, resid, finite, t_reached = 0.0, 0.0, True, 0.0
        allowed = 1e-6  # before any floor stop: the tolerance's own sqrt(2 * 1e-14) R, rounded up
        try:  # its weight loads the flex the straight string holds only at second order: refused at the start
            sim = ln.Simulator(scene, method=method, max_steps_per_call=2000, **kw)
        except ln.ConsistencyError as e:
            measured[key] = {"outcome": "refused", "message": str(e)[:300]}
            continue
        try:
            for t in np.linspace(0.0, 0.2, 21)[1:]:
                sim.advance(t)
                X = sim.state.X
                finite &= bool(np.all(np.isfinite(X)))
                dev = max(dev, float(np.abs(X[1] - middle).max()))
                resid = max(resid, float(sim.dyn.constraint_residual(X)))
                t_reached = float(t)
                allowed = min(max(allowed, math.sqrt(2.0 * sim.integrator.projection_floor()[1])), 1e-5)
                if dev > allowed or not finite:   # the verdict is in: a wrong answer reported as success
                    break
            measured[key] = {"outcome": "continued", "max_displacement_m": dev, "finite": finite,
                             "max_residual": resid, "output_until_s": t_reached,
                             "floor_reached": sim.integrator.projection_floor()[1], "allowed_m": allowed,
                             "steps": sim.integrator.stats.steps, "rejected": sim.integrator.stats.rejected}
            ok &= finite and dev <= allowed
        except ln.LinknetError as e:
            measured[key] = {"outcome": "stopped", "message": f"{type(e).__name__}: {e}"[:400],
                             "output_until_stop_s": t_reached, "max_displacement_before_stop_m": dev}
            ok &= finite and dev <= allowed
        except Exception as e:
            measured[key] = {"outcome": "crashed", "message": f"{type(e).__name__}: {e}"[:400]}
            ok = False
    return _case("singular", case_singular.__doc__.split("Criterion: ")[1].strip(), measured, ok, t0)


# ------------------------------------------------------------------------------------------ long runs
def _drift_stats(res):
    e = (res.energy - res.energy[0]) / res.energy_scale
    # secular drift: slope of a straight-line fit, times the run length; vs the bounded oscillation
    slope = np.polyfit(res.t, e, 1)[0]
    half = len(e) // 2
    return {"max_energy_error_rel": float(np.abs(e).max()),
            "energy_error_first_half": float(np.abs(e[:half]).max()),
            "energy_error_second_half": float(np.abs(e[half:]).max()),
            "fitted_drift_over_run_rel": float(slope * (res.t[-1] - res.t[0])),
            "max_residual": float(res.residual.max())}


def case_long_runs(quick=True):
    """Criterion: RATTLE keeps the energy error bounded (no drift: the second half of the run's maximum
    energy error is no more than 3x the first half's -- chains whip irregularly, so the bound is loose --
    and the fitted secular drift over the run is below the maximum oscillation) and the link lengths
    within 1e-12 relative at every output. Full size: pendulum 2000 s at dt = 1e-3 (2e6 steps) and
    chain_100 for 1e6 steps at dt = 1e-4 (100 s); quick: pendulum 200 s at dt = 1e-2 and chain_10 20 s at
    dt = 1e-3 (2e4 steps each)."""
    t0 = time.perf_counter()
    measured, ok = {}, True
    runs = ([("pendulum", "pendulum.json", 200.0, 1e-2, 2001), ("chain_10", "chain_10.json", 20.0, 1e-3, 2001)]
            if quick else
            [("pendulum", "pendulum.json", 2000.0, 1e-3, 20001), ("chain_100", "chain_100.json", 100.0, 1e-4, 10001)])
    for name, f, t_end, dt, n_out in runs:
        scene = ln.load_scene(ROOT / "models" / f)
        tt = time.perf_counter()
        res = ln.simulate(scene, t_end, method="rattle", dt=dt, n_out=n_out)
        m = _drift_stats(res) | {"t_end_s": t_end, "dt_s": dt, "steps": res.stats.get("steps"),
                                 "wall_s": time.perf_counter() - tt}
        m["us_per_step"] = 1e6 * m["wall_s"] / max(1, m["steps"] or 1)
        measured[name] = m
        ok &= m["max_residual"] <= 1e-12
        ok &= m["energy_error_second_half"] <= 3 * m["energy_error_first_half"] + 1e-14
        ok &= abs(m["fitted_drift_over_run_rel"]) <= m["max_energy_error_rel"] + 1e-14
    return _case("long_runs", case_long_runs.__doc__.split("Criterion: ")[1].strip(), measured, ok, t0)


# ------------------------------------------------------------------------------------------ whip
def _peaks(scene, rtol, t_end, window=0.01, fine=2e-5):
    """Peak tip speed and peak tension: coarse outputs every 1 ms find the whip, then outputs every `fine`
    seconds across +-window/2 around it resolve the peaks."""
    sim = ln.Simulator(scene, method="dop853", rtol=rtol)
    tip = scene.K - 1
    best_t, best_v, best_T = 0.0, 0.0, 0.0
    for t in np.arange(1, int(round(t_end / 1e-3)) + 1) * 1e-3:
        sim.advance(t)
        out = sim.outputs()
        v = float(np.linalg.norm(out["U"][tip]))
        if v > best_v:
            best_t, best_v = t, v
        best_T = max(best_T, float(np.max(out["T"])))
    sim = ln.Simulator(scene, method="dop853", rtol=rtol)
    t_start = max(best_t - window / 2, fine)
    sim.advance(t_start)
    peak_v, peak_T, t_peak = 0.0, best_T, best_t
    for t in t_start + np.arange(1, int(round(window / fine)) + 1) * fine:
        sim.advance(t)
        out = sim.outputs()
        v = float(np.linalg.norm(out["U"][tip]))
        if v > peak_v:
            peak_v, t_peak = v, t
        peak_T = max(peak_T, float(np.max(out["T"])))
    return {"peak_tip_speed_m_s": peak_v, "peak_tension_N": peak_T, "t_peak_s": t_peak,
            "steps": sim.integrator.stats.steps}


def case_whip(quick=True):
    """Criterion: chain released from horizontal; the peak tip speed and peak tension found by DOP853 converge
    as rtol decreases: relative change between the two tightest tolerances <= 1e-3 and no larger than
    between the two loosest (step control resolves the spike). Full: chain_100, rtol 1e-4 .. 1e-10; quick:
    chain_10, rtol 1e-5 .. 1e-9."""
    t0 = time.perf_counter()
    if quick:
        scene, rtols, t_end = ln.load_scene(ROOT / "models" / "chain_10.json"), [1e-5, 1e-7, 1e-9], 1.0
    else:
        scene, rtols, t_end = ln.load_scene(ROOT / "models" / "chain_100.json"), [1e-4, 1e-6, 1e-8, 1e-10], 1.0
    per = {f"{r:g}": _peaks(scene, r, t_end) for r in rtols}
    keys = list(per)

    def rel(a, b, q):
        return abs(per[a][q] - per[b][q]) / abs(per[b][q])
    conv = {q: [rel(a, b, q) for a, b in zip(keys, keys[1:])] for q in ("peak_tip_speed_m_s", "peak_tension_N")}
    ok = all(c[-1] <= 1e-3 and c[-1] <= c[0] + 1e-12 for c in conv.values())
    return _case("whip", case_whip.__doc__.split("Criterion: ")[1].strip(),
                 {"scene": scene.name, "per_rtol": per, "relative_change_between_successive_rtols": conv}, ok, t0)


# ------------------------------------------------------------------------------------------ scale
_SCALE_CHILD = r"""
import json, sys, time, numpy as np, linknet_core as ln
kind, n, steps, dt = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
t0 = time.perf_counter()
scene = ln.builders.chain(n) if kind == "chain" else ln.builders.net(n, n)
sim = ln.Simulator(scene, method="rattle", dt=dt)
t1 = time.perf_counter()
sim.advance(dt)                      # first step (warm-up: factorisations, compilation)
t2 = time.perf_counter()
sim.advance(dt * (steps + 1))
t3 = time.perf_counter()
X = sim.state.X
hwm = None
try:   # the kernel's own record of this process's peak resident set
    for line in open("/proc/self/status"):
        if line.startswith("VmHWM:"):
            hwm = int(line.split()[1]) / 1024.0
except OSError:
    pass
print(json.dumps({"K": scene.K, "L": scene.L, "setup_s": t1 - t0, "first_step_s": t2 - t1,
                  "steps_timed": steps, "dt_s": dt, "simulated_s": dt * (steps + 1),
                  "ms_per_step": 1e3 * (t3 - t2) / steps, "structure": sim.dyn.structure.kind,
                  "finite": bool(np.all(np.isfinite(X))), "residual": float(sim.dyn.constraint_residual(X)),
                  "vmhwm_MiB": hwm}))
"""


def _run_child(args, timeout):
    """Run one scale case in a fresh interpreter; peak RSS from wait4 (this child only)."""
    p = subprocess.Popen([sys.executable, "-c", _SCALE_CHILD, *map(str, args)], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, cwd=ROOT, text=True,
                         env=os.environ | {"PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")})
    t_end = time.time() + timeout
    while True:
        pid, status, ru = os.wait4(p.pid, os.WNOHANG)
        if pid:
            break
        if time.time() > t_end:
            p.kill()
            os.wait4(p.pid, 0)
            return {"failed_with": f"timeout after {timeout} s"}
        time.sleep(0.05)
    out, err = p.stdout.read(), p.stderr.read()
    if status != 0:
        return {"failed_with": err.strip().splitlines()[-1] if err.strip() else f"exit status {status}"}
    d = json.loads(out.strip().splitlines()[-1])
    d["peak_rss_MiB"] = ru.ru_maxrss / 1024.0   # wait4's rusage of this child, the fork before exec included
    return d


def case_scale(quick=True):
    """Criterion: a 100 x 100 net (19800 links) and a 100000-link chain run at all (finite state, residual
    <= 1e-10 after a few RATTLE steps of 1e-4 s for the net, 1e-5 s for the 1 m chains of 1e-4 and 1e-5 m
    links: a scale check, not a long run) with setup time, time per
    step and peak memory reported (each in a fresh interpreter; peak resident set of that process from
    wait4 and from /proc/self/status VmHWM, the ~190 MiB of imports included); in the full run chain memory
    must grow linearly in L: the extra peak memory of 100000 links at most 15x that of 10000. Quick: a
    30 x 30 net and 2000- and 4000-link chains, memory ratio reported, not judged."""
    t0 = time.perf_counter()
    # the step must suit the links: builders.chain(n) is 1 m long, so 100000 links are 1e-5 m each, and
    # RATTLE's position stage at dt = 1e-4 s does not converge there from the second step on (the tension
    # wave at the anchor moves across many links per step); 3e-5 s works, the chains run at 1e-5 s
    if quick:
        plan = [("net", 30, 5, 1e-4), ("chain", 2000, 5, 1e-4), ("chain", 4000, 3, 1e-4)]
    else:
        plan = [("net", 100, 5, 1e-4), ("chain", 10000, 5, 1e-5), ("chain", 100000, 3, 1e-5)]
    base = _run_child(["chain", 1, 1, 1e-3], 120)
    measured, ok = {"baseline_chain_1": base}, True
    for kind, n, steps, dt in plan:
        d = _run_child([kind, n, steps, dt], 1800)
        measured[f"{kind}_{n}"] = d
        ok &= "failed_with" not in d and d.get("finite", False) and d.get("residual", 1) <= 1e-10
    chains = [k for k in measured if k.startswith("chain_") and k != "baseline_chain_1"]
    # VmHWM, read by the child itself, is its own peak; wait4's ru_maxrss also counts the forked copy of this
    # process before exec (this benchmark's own ~190 MiB), which hides a child smaller than that
    if len(chains) == 2 and all("vmhwm_MiB" in measured[c] for c in chains) and "vmhwm_MiB" in base:
        small, large = (measured[c]["vmhwm_MiB"] - base["vmhwm_MiB"] for c in chains)
        measured["chain_extra_memory_ratio"] = large / max(small, 1e-9)
        measured["chain_length_ratio"] = 2.0 if quick else 10.0
        if not quick:
            ok &= measured["chain_extra_memory_ratio"] <= 15
    return _case("scale", case_scale.__doc__.split("Criterion: ")[1].strip(), measured, ok, t0)


CASES = {"mass_ratios": case_mass_ratios, "redundant": case_redundant, "singular": case_singular,
         "long_runs": case_long_runs, "whip": case_whip, "scale": case_scale}


def write_markdown(results, path):
    lines = ["# Stress suite" + (" (quick sizes)" if results["quick"] else ""), "",
             f"Generated {results['date']} by `{results['command']}`.", ""]
    for c in results["cases"]:
        lines += [f"## {c['case']}: {'PASS' if c['passed'] else 'FAIL'} ({c['seconds']:.1f} s)", "",
                  *( [f"Run by `{c['command']}` on {c['date']}.", ""] if c.get("command") else []),
                  f"Criterion: {c['criterion']}", "", "```json", json.dumps(c["measured"], indent=1, default=str), "```", ""]
    write_text(path, "\n".join(lines))


def combine(out: Path):
    """One stress.json / stress.md from the per-case runs (cases were run separately to fit the machine):
    the newest result of every case among the existing stress.json and the stress_<cases>.json files."""
    newest = {}
    if (out / "stress.json").exists():
        for c in json.loads((out / "stress.json").read_text())["cases"]:
            c.setdefault("command", "(earlier run)")
            c.setdefault("date", "")
            newest[c["case"]] = c
    for f in sorted(out.glob("stress_*.json")):
        if f.name.startswith("stress_quick"):
            continue
        r = json.loads(f.read_text())
        for c in r["cases"]:
            c["command"] = r["command"]
            c["date"] = r["date"]
            if c["case"] not in newest or c["date"] >= newest[c["case"]]["date"]:
                newest[c["case"]] = c
    results = {"date": max((c["date"] for c in newest.values()), default=""), "quick": False,
               "command": "python -m benchmarks.stress --case <name> (per case; see each case) then --combine",
               "cases": [newest[n] for n in CASES if n in newest]}
    write_text(out / "stress.json", json.dumps(results, indent=1, default=str))
    write_markdown(results, out / "stress.md")
    print(f"wrote {out / 'stress.json'}: " + ", ".join(f"{c['case']} {'PASS' if c['passed'] else 'FAIL'}"
                                                      for c in results["cases"]))
    return results


def main(argv=None):
    ap = argparse.ArgumentParser(description="linknet numerical-stability stress suite")
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--case", nargs="*", choices=list(CASES))
    add_output_arguments(ap, "stress")
    ap.add_argument("--combine", action="store_true",
                    help="gather the newest result of every case from the stress_*.json in the output folder into "
                         "its stress.json/.md")
    args = ap.parse_args(argv)
    out = resolve(ap, args, "stress")  # a quick run's files are named stress_quick*
    if args.combine:
        return combine(out)
    import datetime as _dt
    results = {"date": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"), "quick": args.quick,
               "command": "python -m benchmarks.stress" + (" --quick" if args.quick else "")
               + (" --case " + " ".join(args.case) if args.case else ""), "cases": []}
    for name in args.case or CASES:
        print(f"[{name}] ...", flush=True)
        c = CASES[name](quick=args.quick)
        print(f"[{name}] {'PASS' if c['passed'] else 'FAIL'} in {c['seconds']:.1f} s\n"
              + json.dumps(c["measured"], indent=1, default=str), flush=True)
        results["cases"].append(c)
    stem = "stress_quick" if args.quick else "stress"
    if args.case:
        stem += "_" + "_".join(args.case)
    write_text(out / f"{stem}.json", json.dumps(results, indent=1, default=str))
    write_markdown(results, out / f"{stem}.md")
    print(f"wrote {out / (stem + '.json')}")
    return results


if __name__ == "__main__":
    main()
