"""The compiled projected Runge-Kutta kernel runs the same algorithm as the numpy path: the same steps and the
same trajectory to round-off, the nominal order, exact snapshots, and a hand-back to the numpy path where a
configuration is singular."""
from __future__ import annotations

import copy
import math
import pickle

import numpy as np
import pytest
from scipy.integrate._ivp.rk import RK23

import linknet_core as ln
from linknet_core import builders
from linknet_core.integrators import ProjectedRungeKutta, make_integrator


def _springs_drag_scene():
    d = builders.chain(6).to_dict()
    d["masses"][3]["drag"] = 0.4
    d["masses"][5]["force"] = [0.2, 0.0, 0.5]
    d["springs"] = [{"a": 1, "b": 7, "stiffness": 30.0, "rest_length": 0.8, "damping": 0.7},
                    {"a": 3, "b": 6, "stiffness": 5.0, "rest_length": 0.2}]
    return ln.Scene.from_dict(d)


SCENES = {
    "pendulum": builders.pendulum,
    "double_pendulum": builders.double_pendulum,
    "chain_10": lambda: builders.chain(10),
    "net_4x4": lambda: builders.net(4, 4),
    "four_bar": builders.four_bar,
    "springs_drag_inputs": _springs_drag_scene,
}


@pytest.mark.parametrize("name", list(SCENES))
@pytest.mark.parametrize("method,rtol", [("dopri5", 1e-7), ("dop853", 1e-10)])
def test_compiled_kernel_gives_the_numpy_trajectory(name, method, rtol):
    scene = SCENES[name]()
    rng = np.random.default_rng(3)
    F = rng.normal(size=(scene.K, 3)) * 0.3  # held input forces on every mass
    runs = {}
    for backend in ("numpy", "compiled"):
        sim = ln.Simulator(scene, method=method, rtol=rtol, backend=backend)
        assert sim.integrator.compiled_available() == (backend == "compiled")
        X, U = [], []
        for t in (0.1, 0.25, 0.4):
            sim.advance(t, F)
            X.append(sim.state.X.copy())
            U.append(sim.state.U.copy())
        runs[backend] = (np.array(X), np.array(U), sim.integrator.stats.as_dict(), sim.dyn.rhs_evaluations, sim)
    (Xn, Un, sn, rn, _), (Xc, Uc, sc, rc, sim) = runs["numpy"], runs["compiled"]
    # the same steps, accepted and rejected, and the same number of right-hand side evaluations
    assert sn == sc and rn == rc
    assert sim.integrator.compiled_fallbacks == 0
    # the two differ only by the order of floating-point sums and where Newton stops (1e-14 relative)
    assert np.max(np.abs(Xn - Xc)) <= 1e-11
    assert np.max(np.abs(Un - Uc)) <= 1e-11 * max(1.0, np.abs(Un).max())
    dyn = sim.dyn
    assert dyn.constraint_residual(sim.state.X) < 1e-13
    assert dyn.velocity_residual(sim.state.X, sim.state.U) < 1e-12


class BogackiShampine3(ProjectedRungeKutta):
    """A tableau the compiled kernel has never seen (scipy's RK23): it must run there with no new code."""
    name = "bs3"
    order = 3
    error_estimator_order = 2
    n_stages = RK23.n_stages
    A, B, C = RK23.A, RK23.B, RK23.C
    error_weights = (RK23.E,)


def test_a_new_tableau_runs_compiled_without_new_code():
    scene = builders.double_pendulum()
    runs = []
    for backend in ("numpy", "compiled"):
        dyn = ln.Dynamics(scene)
        integ = BogackiShampine3(dyn, rtol=1e-6, backend=backend)
        state = ln.State(0.0, np.array(scene.X0), np.array(scene.U0))
        integ.advance(state, 0.3, None, 10 ** 6)
        runs.append((state.X, integ.stats.as_dict()))
    assert runs[0][1] == runs[1][1]
    assert np.max(np.abs(runs[0][0] - runs[1][0])) <= 1e-12


def _double_pendulum_reference(t_end):
    scene = builders.double_pendulum()
    ref = ln.simulate(scene, t_end=t_end, method="dop853", rtol=1e-14, atol=1e-14, n_out=2, backend="numpy")
    return scene, ref.X[-1]


@pytest.mark.parametrize("method,counts", [("dopri5", [16, 32, 64, 128]), ("dop853", [12, 16, 22, 30]),
                                           ("bs3", [40, 80, 160, 320])])
def test_compiled_fixed_steps_have_the_nominal_order(method, counts):
    """n steps of h = t/n without error control, in the compiled kernel: error ~ h^order."""
    t_end = 0.4
    scene, X_ref = _double_pendulum_reference(t_end)
    cls = BogackiShampine3 if method == "bs3" else ln.METHODS[method]
    errors = []
    for n in counts:
        integ = cls(ln.Dynamics(scene), rtol=1e-6, backend="compiled")
        X, _ = integ.fixed_steps(np.array(scene.X0), np.array(scene.U0), t_end / n, n)
        errors.append(np.max(np.abs(X - X_ref)))
    slopes = -np.diff(np.log(errors)) / np.diff(np.log(counts))
    assert float(np.median(slopes)) == pytest.approx(cls.order, abs=0.35), f"errors {errors}, slopes {slopes}"


def test_compiled_fixed_steps_equal_numpy_steps():
    scene = builders.chain(5)
    X0, U0 = np.array(scene.X0), np.array(scene.U0)
    out = []
    for backend in ("numpy", "compiled"):
        integ = make_integrator("dop853", ln.Dynamics(scene), rtol=1e-6, backend=backend)
        out.append(integ.fixed_steps(X0, U0, 0.01, 20))
    assert np.max(np.abs(out[0][0] - out[1][0])) <= 1e-13
    assert np.max(np.abs(out[0][1] - out[1][1])) <= 1e-12


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_snapshots_restore_the_compiled_run_exactly(method):
    scene = builders.chain(8)
    sim = ln.Simulator(scene, method=method, rtol=1e-8)
    assert sim.integrator.compiled_available()
    sim.advance(0.13)
    snap = pickle.loads(pickle.dumps(sim.get_state()))
    sim.advance(0.31)
    sim.advance(0.5)
    X_first, h_first = sim.state.X.copy(), sim.integrator.h
    sim.set_state(snap)
    sim.advance(0.31)
    sim.advance(0.5)
    assert np.array_equal(sim.state.X, X_first) and sim.integrator.h == h_first
    # a fresh simulator given the snapshot continues identically too
    other = ln.Simulator(scene, method=method, rtol=1e-8)
    other.set_state(copy.deepcopy(snap))
    other.advance(0.31)
    other.advance(0.5)
    assert np.array_equal(other.state.X, X_first)


def _parallelogram(speed=5.0):
    """Crank = rocker, coupler = ground, no gravity: the coupler translates and theta = theta0 + w t exactly;
    at theta = 180 deg all links are collinear and A of (25) is singular."""
    return builders.four_bar(ground=1.0, crank=0.4, coupler=1.0, rocker=0.4, crank_angle_deg=60.0,
                             crank_speed=speed, gravity=(0.0, 0.0, 0.0), name="parallelogram")


@pytest.mark.parametrize("method,rtol,tol", [("dop853", 1e-10, 1e-9), ("dopri5", 1e-8, 1e-7)])
def test_singular_passage_is_handed_to_the_numpy_path(method, rtol, tol):
    speed = 5.0
    scene = _parallelogram(speed)
    t_flat = math.radians(120.0) / speed  # an output point exactly at the flat (singular) position
    sims = {b: ln.Simulator(scene, method=method, rtol=rtol, backend=b) for b in ("numpy", "compiled")}
    for t in (t_flat, t_flat + 0.1, 0.6):
        th = math.radians(60.0) + speed * t
        exact = 0.4 * np.array([math.cos(th), 0.0, math.sin(th)])
        for sim in sims.values():
            sim.advance(t)
            assert np.linalg.norm(sim.state.X[1] - exact) < tol
            assert np.linalg.norm(sim.state.X[2] - exact - [1.0, 0.0, 0.0]) < tol
        assert np.max(np.abs(sims["numpy"].state.X - sims["compiled"].state.X)) < 1e-11
    compiled = sims["compiled"]
    assert compiled.integrator.compiled_fallbacks >= 1  # the kernel met the singular pivot and handed over
    assert compiled.dyn.solver.singular_events >= 1  # ... and the numpy path took the minimum-norm route
    assert compiled.integrator.stats.as_dict() == sims["numpy"].integrator.stats.as_dict()


def test_backend_choice():
    redundant = ln.Dynamics(builders.redundant_truss())
    integ = make_integrator("dop853", redundant, rtol=1e-8)  # auto: the numpy path
    assert not integ.compiled_available()
    state = ln.State(0.0, np.array(redundant.scene.X0), np.array(redundant.scene.U0))
    integ.advance(state, 0.01, None, 1000)
    assert state.t == 0.01
    with pytest.raises(ln.SolverError, match="does not handle redundant scenes"):
        make_integrator("dop853", redundant, rtol=1e-8, backend="compiled").advance(state, 0.02, None, 1000)
    with pytest.raises(ln.SolverError, match="backend must be"):
        ln.Simulator(builders.pendulum(), method="dopri5", rtol=1e-8, backend="fortran")
    assert not ln.Simulator(builders.pendulum(), method="dopri5", rtol=1e-8,
                            backend="numpy").integrator.compiled_available()


def test_step_limit_and_statistics_from_the_kernel():
    sim = ln.Simulator(builders.chain(10), method="dopri5", rtol=1e-10, max_steps_per_call=20)
    with pytest.raises(ln.SolverError, match="more than 20 steps"):
        sim.advance(1.0)
    assert sim.state.t == 0.0  # the simulator stays where it was
    res = ln.simulate(builders.chain(10), 0.5, method="dopri5", rtol=1e-8, n_out=3)
    s = res.stats
    # per attempt 6 evaluations (stages 2..6 and the new point), per interval one first stage and then one per
    # accepted step but the last, and one more for the starting step
    assert s["rhs_evaluations"] == 6 * (s["steps"] + s["rejected"]) + s["steps"] + 2 - 1
