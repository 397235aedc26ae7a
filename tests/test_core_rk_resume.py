"""After the compiled Runge-Kutta kernel stops (singular configuration, stalled projection, non-finite values),
the numpy path takes the trouble and the compiled kernel resumes within the same output interval: the trajectory
is the uninterrupted one, the step limit counts every piece, and a real singular passage ends where the pure
numpy backend and the exact solution do, with most steps taken in the kernel."""
from __future__ import annotations

import math

import numpy as np
import pytest

import linknet_core as ln
from linknet_core import builders
from linknet_core import compiled_rk as ck


def _record_kernel_calls(sim, fail=lambda call_index, t: None):
    """Wrap the simulator's compiled kernel: every call is recorded as a dict (t, h, max_steps, status, steps).
    ``fail(call_index, t)`` may return k: that call then stops after k accepted steps and reports SINGULAR,
    as the real kernel does at a vanishing pivot (the last accepted state, its t and its next step size)."""
    kernel = sim.integrator._compiled_kernel()
    real_advance, calls = kernel.advance, []

    def advance(X, U, t, t_target, h, F_input, rtol, atol, max_steps, controller, **kw):
        k = fail(len(calls), t)
        if k is None:
            result = real_advance(X, U, t, t_target, h, F_input, rtol, atol, max_steps, controller, **kw)
        else:
            # a step limit of k - 1 makes the kernel return right after its k-th accepted step (or k = 0: no
            # step); whatever it says then, this call reports a singular configuration from that state
            result = real_advance(X, U, t, t_target, h, F_input, rtol, atol, k - 1, controller, **kw) if k else \
                (ck.OK, np.array(X), np.array(U), t, h, 0, 0, 1)
            if result[0] in (ck.OK, ck.TOO_MANY_STEPS):  # an interval finished by the k-th step stays finished
                result = (ck.OK if result[3] == t_target else ck.SINGULAR,) + tuple(result[1:])
        calls.append({"t": t, "h": h, "max_steps": max_steps, "status": result[0], "steps": result[5]})
        return result

    kernel.advance = advance
    return calls


def _chain_with_inputs():
    scene = builders.chain(8)
    F = np.random.default_rng(5).normal(size=(scene.K, 3)) * 0.2
    return scene, F


@pytest.mark.parametrize("method,rtol", [("dopri5", 1e-8), ("dop853", 1e-10)])
def test_a_failure_inside_an_interval_resumes_the_kernel_after_one_numpy_step(method, rtol):
    """The kernel stops at its 9th accepted step of a 0.8 s interval (injected: a real hard step, the whip of a
    1000-link chain, is too slow for a unit test). The numpy path takes one step, the kernel takes the rest,
    and the result is the uninterrupted run's: same steps accepted and rejected, same state to round-off."""
    scene, F = _chain_with_inputs()
    reference = ln.Simulator(scene, method=method, rtol=rtol)
    reference.advance(0.8, F)
    sim = ln.Simulator(scene, method=method, rtol=rtol)
    calls = _record_kernel_calls(sim, fail=lambda i, t: 9 if i == 0 else None)
    sim.advance(0.8, F)

    assert sim.state.t == 0.8
    assert [c["status"] for c in calls] == [ck.SINGULAR, ck.OK]
    assert calls[0]["steps"] == 9
    total = reference.integrator.stats.steps
    assert total > 20  # the failure is well inside the interval
    # the kernel resumed one numpy step later with what is left of the step limit; the same accepted and rejected
    # steps as the reference show it also got the step size the numpy step left (a restarted controller would not)
    assert 0.0 < calls[1]["t"] < 0.8
    assert calls[1]["max_steps"] == sim.max_steps_per_call - 10
    assert calls[1]["steps"] == total - 10
    assert sim.integrator.compiled_fallbacks == 1
    assert sim.integrator.stats.as_dict() == reference.integrator.stats.as_dict()
    # both runs are the same algorithm on the same steps; they differ by the numpy step's round-off and
    # where its Newton projection stops (1e-14 relative), which the chain's dynamics amplify over 0.8 s
    assert np.max(np.abs(sim.state.X - reference.state.X)) < 1e-10
    assert np.max(np.abs(sim.state.U - reference.state.U)) < 1e-9
    assert sim.dyn.constraint_residual(sim.state.X) < 1e-13


def test_repeated_failures_give_the_uninterrupted_run():
    """A kernel that fails after every 4 accepted steps, and one that fails at once on every call: the interval
    is still the uninterrupted run's. Failing at once makes the numpy pieces grow (1, 2, 4, ... steps), so the
    kernel is asked only a few times, not once per step."""
    scene, F = _chain_with_inputs()
    reference = ln.Simulator(scene, method="dop853", rtol=1e-9)
    reference.advance(0.6, F)
    total = reference.integrator.stats.steps
    for every, expect_calls in ((4, None), (0, math.ceil(math.log2(total + 1)) + 1)):
        sim = ln.Simulator(scene, method="dop853", rtol=1e-9)
        calls = _record_kernel_calls(sim, fail=lambda i, t: every)
        sim.advance(0.6, F)
        assert sim.state.t == 0.6
        assert sim.integrator.stats.as_dict() == reference.integrator.stats.as_dict()
        assert np.max(np.abs(sim.state.X - reference.state.X)) < 1e-10
        assert np.max(np.abs(sim.state.U - reference.state.U)) < 1e-9
        if every:
            # 4 kernel steps, then 1 numpy step, and again
            assert all(c["steps"] == 4 for c in calls[:-1]) and len(calls) >= total // 5
        else:
            assert sum(c["steps"] for c in calls) == 0 and len(calls) <= expect_calls


def test_the_step_limit_counts_the_compiled_and_numpy_pieces_together():
    scene, F = _chain_with_inputs()
    reference = ln.Simulator(scene, method="dopri5", rtol=1e-8)
    reference.advance(0.5, F)
    n = reference.integrator.stats.steps  # steps the interval needs
    for limit, fails in ((n - 1, True), (n, False)):
        sim = ln.Simulator(scene, method="dopri5", rtol=1e-8, max_steps_per_call=limit)
        calls = _record_kernel_calls(sim, fail=lambda i, t: 5 if i == 0 else None)
        if fails:
            with pytest.raises(ln.SolverError, match=f"more than {n - 1} steps between t = 0.0 and t = 0.5"):
                sim.advance(0.5, F)
            assert sim.state.t == 0.0 and calls[-1]["status"] == ck.TOO_MANY_STEPS
        else:
            sim.advance(0.5, F)
            assert sim.state.t == 0.5 and sim.integrator.stats.steps == n
        assert calls[0]["status"] == ck.SINGULAR and calls[1]["max_steps"] == limit - 6


def _parallelogram(speed=5.0):
    """Crank = rocker, coupler = ground, no gravity: the coupler translates and theta = theta0 + w t exactly;
    at theta = 180 deg all links are collinear and A of (25) is singular (as in test_core_compiled_rk)."""
    return builders.four_bar(ground=1.0, crank=0.4, coupler=1.0, rocker=0.4, crank_angle_deg=60.0,
                             crank_speed=speed, gravity=(0.0, 0.0, 0.0), name="parallelogram")


@pytest.mark.parametrize("method,rtol,tol", [("dop853", 1e-10, 1e-9), ("dopri5", 1e-8, 1e-7)])
def test_a_real_singular_passage_runs_mostly_compiled(method, rtol, tol):
    """An output point exactly at the flat (singular) position: the kernel meets the vanishing pivot on the last
    step into it and again at the start of the next interval. The numpy path takes those steps (minimum-norm
    tensions) and the kernel the rest, also of the long interval after the passage (1.1 s, through the next
    collinear position at 360 deg): the end state is the exact motion's and the pure numpy backend's."""
    speed, t_end = 5.0, 1.5
    scene = _parallelogram(speed)
    t_flat = math.radians(120.0) / speed
    sims = {b: ln.Simulator(scene, method=method, rtol=rtol, backend=b) for b in ("numpy", "compiled")}
    calls = _record_kernel_calls(sims["compiled"])
    for t in (t_flat, t_end):
        for sim in sims.values():
            sim.advance(t)
    th = math.radians(60.0) + speed * t_end
    exact = 0.4 * np.array([math.cos(th), 0.0, math.sin(th)])
    compiled, numpy_run = sims["compiled"], sims["numpy"]
    for sim in sims.values():
        assert np.linalg.norm(sim.state.X[1] - exact) < tol
        assert np.linalg.norm(sim.state.X[2] - exact - [1.0, 0.0, 0.0]) < tol
    assert np.max(np.abs(compiled.state.X - numpy_run.state.X)) < 1e-11
    assert compiled.integrator.stats.as_dict() == numpy_run.integrator.stats.as_dict()
    assert compiled.integrator.compiled_fallbacks >= 2  # into the flat position and out of it
    assert compiled.dyn.solver.singular_events >= 1  # the numpy path took the minimum-norm route
    # the kernel was called again after the hand-over in the long interval and took most of all steps
    assert calls[-1]["t"] > t_flat and calls[-1]["status"] == ck.OK
    compiled_steps = sum(c["steps"] for c in calls)
    assert compiled_steps >= 0.8 * compiled.integrator.stats.steps
