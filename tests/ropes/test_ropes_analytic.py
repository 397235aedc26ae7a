"""Ropes that go slack and come taut: a bob thrown up and out from below its pivot, and a two-mass rope chain thrown
up, against closed-form ballistic flights, their event times found independently (brentq), the jerk's impulse and
energy in closed form and scipy's pendulum between the jerks (tests/ropes/rope_references.py)."""
from __future__ import annotations

import numpy as np
import pytest
from rope_references import G, BobReference, ballistic, bob_scene

import linknet_core as ln

X0, V0 = np.array([0.3, 0.0, -0.4]), np.array([1.5, 0.0, 3.0])  # inside the circle |X| < R = 1, thrown up and out
REFERENCE = BobReference(X0, V0, 1.0, 2.0)


@pytest.fixture(scope="module")
def bob_run():
    return ln.simulate(bob_scene(X0, V0), 2.0, "dop853", rtol=1e-10, n_out=201, error_estimate=False)


def test_bob_flies_ballistically_to_round_off_until_the_rope_comes_taut_at_the_closed_form_root(bob_run):
    t_taut = REFERENCE.events[0][0]
    # the root of |X0 + V0 t + g t^2/2| = R, polished here by Newton's method on the quartic itself
    t = t_taut
    for _ in range(3):
        X, V = ballistic(X0, V0, t)
        t -= (X @ X - 1.0) / (2 * X @ V)
    first = bob_run.events[0]
    assert first.kind == "taut" and first.index == 0
    assert abs(first.t - t) <= 4e-15
    before = bob_run.t < first.t
    flight = np.array([ballistic(X0, V0, s)[0] for s in bob_run.t[before]])
    assert np.abs(bob_run.X[before, 1] - flight).max() <= 1e-15  # an embedded RK integrates a parabola exactly
    assert bob_run.slack[before, 0].all() and not bob_run.slack[~before, 0][:50].any()
    assert np.all(bob_run.T[before, 0] == 0.0)


def test_the_inelastic_jerk_takes_the_radial_momentum_and_exactly_its_kinetic_energy(bob_run):
    first = bob_run.events[0]
    X, V = ballistic(X0, V0, first.t)
    radial = V @ X  # R = 1
    assert first.impulse == pytest.approx(radial, rel=1e-13)  # J = m v_r
    before = bob_run.t < first.t
    lost = bob_run.energy[before][-1] - bob_run.energy[~before][0]
    assert lost == pytest.approx(0.5 * radial ** 2, rel=1e-12)  # the radial kinetic energy (measured: 2e-15)


def test_after_the_jerk_it_swings_as_the_pendulum_scipy_integrates_from_the_post_jerk_state_goes_slack_and_jerks_again(
        bob_run):
    kinds = [(e.kind, e.index) for e in bob_run.events]
    assert kinds == [("taut", 0), ("slack", 0), ("taut", 0)]
    for event, (t, kind, impulse) in zip(bob_run.events, REFERENCE.events):
        assert event.t == pytest.approx(t, abs=1e-11)  # measured: 4e-13 s
        assert event.impulse == pytest.approx(impulse, abs=1e-11)
    worst = max(np.abs(bob_run.X[i, 1] - REFERENCE.position(t)).max() for i, t in enumerate(bob_run.t))
    assert worst < 1e-10  # measured: 5e-12 m
    swinging = (bob_run.t > bob_run.events[0].t) & (bob_run.t < bob_run.events[1].t)
    # the pendulum's tension m (|U|^2 / R + g cos(theta)) where the rope is taut, 0 where it is slack
    U, X = bob_run.U[swinging, 1], bob_run.X[swinging, 1]
    assert np.allclose(bob_run.T[swinging, 0], np.einsum("ij,ij->i", U, U) - G * X[:, 2], rtol=1e-9, atol=1e-9)
    assert bob_run.residual.max() < 1e-14  # never stretched: a rope's residual is its stretch


@pytest.mark.parametrize("e", [0.4, 1.0])
def test_restitution_reverses_the_radial_velocity_e_times_and_keeps_the_tangential(e):
    t_taut = REFERENCE.events[0][0]
    sim = ln.Simulator(bob_scene(X0, V0, restitution=e), "dop853", rtol=1e-10, error_estimate=False)
    delta = 1e-3
    sim.advance(t_taut + delta)
    X, V = ballistic(X0, V0, t_taut)
    r = X  # R = 1
    # after the rebound the bob flies free: the velocity just after the jerk is the one now less g delta
    after = sim.state.U[1] - np.array([0.0, 0.0, -G]) * delta
    assert after @ r == pytest.approx(-e * (V @ r), rel=1e-12)
    assert np.allclose(after - (after @ r) * r, V - (V @ r) * r, rtol=0, atol=1e-13)
    event = sim.integrator.events[0]
    assert event.kind == "taut" and event.impulse == pytest.approx((1 + e) * (V @ r), rel=1e-12)
    assert np.allclose(sim.state.X[1], ballistic(X, after, delta)[0], rtol=0, atol=1e-14)


def _chain_events(Xa, Xb, Va, Vb, ma, mb, R, e, count):
    """The first ``count`` jerks of a two-mass rope (restitution e) thrown freely: in the frame falling with gravity
    the separation moves uniformly, d(t) = d + w t, until |d| = R (the root of a quadratic, brentq here); the jerk
    reverses e times the radial part of w. Returns [(t, impulse)]."""
    from scipy.optimize import brentq

    mu = ma * mb / (ma + mb)
    d, w, t = np.array(Xb - Xa, float), np.array(Vb - Va, float), 0.0
    out = []
    for _ in range(count):
        a, b, c = w @ w, 2 * d @ w, d @ d - R * R
        # |d + w s| = R: the larger root of the quadratic (the smaller is behind, or the start itself)
        s_hi = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a) + 1e-9
        s = brentq(lambda s: (d + w * s) @ (d + w * s) - R * R, 1e-12 if c < 0 else 1e-14, s_hi, xtol=1e-16,
                   rtol=1e-15)
        t, d = t + s, d + w * s
        r = d / R
        radial = w @ r
        out.append((t, mu * (1 + e) * radial))
        w = w - (1 + e) * radial * r
    return out


@pytest.mark.parametrize("e", [0.0, 0.5])
def test_a_two_mass_rope_chain_thrown_up_jerks_at_the_independently_found_times(e):
    Xa, Xb = np.array([0.0, 0.0, 0.0]), np.array([0.5, 0.0, 0.2])
    Va, Vb = np.array([0.0, 0.0, 5.0]), np.array([2.0, 0.5, 6.0])
    ma, mb, R = 1.0, 2.0, 1.0
    rope = {"a": 1, "b": 2, "kind": "rope", "length": R}
    if e:
        rope["restitution"] = e
    scene = ln.Scene.from_dict({"name": "bola", "gravity": [0, 0, -G],
                                "masses": [{"name": "a", "position": Xa.tolist(), "mass": ma, "velocity": Va.tolist()},
                                           {"name": "b", "position": Xb.tolist(), "mass": mb, "velocity": Vb.tolist()}],
                                "links": [rope]})
    count = 1 if e == 0 else 4
    expected = _chain_events(Xa, Xb, Va, Vb, ma, mb, R, e, count)
    t_end = expected[-1][0] + 0.05
    run = ln.simulate(scene, t_end, "dop853", rtol=1e-10, n_out=101, error_estimate=False)
    taut = [ev for ev in run.events if ev.kind == "taut"]
    assert len(taut) == count
    for event, (t, impulse) in zip(taut, expected):
        assert event.t == pytest.approx(t, abs=1e-12)
        assert event.impulse == pytest.approx(impulse, rel=1e-10)
    # the centre of mass flies ballistically throughout, the jerks are internal
    com = (ma * run.X[:, 0] + mb * run.X[:, 1]) / (ma + mb)
    flight = np.array([ballistic((ma * Xa + mb * Xb) / (ma + mb), (ma * Va + mb * Vb) / (ma + mb), t)[0]
                       for t in run.t])
    assert np.abs(com - flight).max() < 1e-12
    if e == 0:  # after the inelastic jerk the pair spins rigidly: the rope's tension mu |w_t|^2 / R, constant
        d, w = (Xb - Xa) + (Vb - Va) * expected[0][0], Vb - Va
        r = d / R
        w_t = w - (w @ r) * r
        after = run.t > expected[0][0]
        assert np.allclose(run.T[after, 0], ma * mb / (ma + mb) * (w_t @ w_t) / R, rtol=1e-9)
        assert not run.slack[after, 0].any()


@pytest.mark.parametrize("method,dts,order", [("rattle", (8e-3, 4e-3, 2e-3), 2), ("yoshida4", (8e-3, 4e-3, 2e-3), 4)])
def test_fixed_step_methods_keep_their_order_through_the_jerk(method, dts, order):
    t_check = 0.9  # after the jerk at 0.465 s, on the pendulum
    scene = bob_scene(X0, V0)
    errors = [np.abs(ln.simulate(scene, t_check, method, dt=dt, n_out=2, error_estimate=False).X[-1, 1]
                     - REFERENCE.position(t_check)).max() for dt in dts]
    measured = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(np.abs(measured - order) < 0.1), measured


@pytest.mark.slow
@pytest.mark.parametrize("method,order", [("rattle", 2), ("yoshida4", 4)])
def test_fixed_step_methods_keep_their_order_through_three_events(method, order):
    scene = bob_scene(X0, V0)
    errors = [np.abs(ln.simulate(scene, 2.0, method, dt=dt, n_out=2, error_estimate=False).X[-1, 1]
                     - REFERENCE.position(2.0)).max() for dt in (8e-3, 4e-3, 2e-3, 1e-3)]
    measured = np.log2(np.array(errors[:-1]) / errors[1:])
    assert np.all(np.abs(measured - order) < 0.1), measured


@pytest.mark.parametrize("method,rtol", [("dopri5", 1e-6), ("dop853", 1e-8)])
def test_adaptive_methods_meet_their_tolerance_through_the_events(method, rtol):
    run = ln.simulate(bob_scene(X0, V0), 2.0, method, rtol=rtol, n_out=41)
    assert [e.kind for e in run.events] == ["taut", "slack", "taut"]
    worst = max(np.abs(run.X[i, 1] - REFERENCE.position(t)).max() for i, t in enumerate(run.t))
    assert worst <= run.error_goal
    assert run.max_error_estimate <= run.error_goal


@pytest.mark.slow
def test_a_whipping_hoist_rope_of_light_segments_converges_with_the_tolerance_and_its_chatter_ends():
    # a trolley that brakes hard under a rope of four 0.5 m segments (0.2 kg nodes) and a 10 kg load: the segments
    # jerk each other slack in turn (an inelastic collapse), which the rest rule ends after finitely many events; the
    # runs at rtol 1e-9 and 1e-10 approach the run at 1e-11 as the tolerance shrinks
    n, R = 4, 2.0
    masses = [{"name": "trolley", "position": [0, 0, 0], "driven": True,
               "motion": {"kind": "waypoints", "waypoints": [[1.2, 6.0, 0, 0], [1.4, 7.0, 0, 0]]}}]
    masses += [{"name": f"n{i}", "position": [0, 0, -i * R / n], "mass": 0.2 if i < n else 10.0}
               for i in range(1, n + 1)]
    scene = ln.Scene.from_dict({"name": "whip", "gravity": [0, 0, -G], "masses": masses,
                                "links": [{"a": i + 1, "b": i + 2, "length": R / n, "kind": "rope"} for i in range(n)]})
    runs = {rtol: ln.simulate(scene, 3.0, "dop853", rtol=rtol, n_out=31, error_estimate=False)
            for rtol in (1e-9, 1e-10, 1e-11)}
    assert all(len(run.events) < 100 for run in runs.values())
    far = np.abs(runs[1e-9].X - runs[1e-11].X).max()
    near = np.abs(runs[1e-10].X - runs[1e-11].X).max()
    assert near < far / 5 and near < 1e-7
