"""Events that last less than a fraction of a step: a bob whose free flight would leave its rope's circle only for a
few milliseconds near the top, and a mass thrown up so that its flight would pass just above a ceiling (a ground
facing down), both inside one step of a coarse fixed step (dt = 0.1 s) and of adaptive steps at a loose tolerance.
Each must be found at its first crossing, and the motion after it must be the closed-form flight from the
post-impact state (the inelastic jerk or contact removes the approach velocity; the rope, or the ceiling, cannot
hold the bob there, so it flies on). The references are written here: the flight's crossing as a root of its own
polynomial in t (numpy's roots, polished by Newton's method on |X(t)|^2 - R^2), the impulse m v_r and the later
flight in closed form."""
from __future__ import annotations

import numpy as np
import pytest
from rope_references import G, ballistic, bob_scene, first_exit

import linknet_core as ln
from linknet_core.integrators.events import gap_dips, may_fall_below

R = 1.0
VX, EPS, T_APEX = 2.0, 2e-5, 0.30625  # apex 20 um above the rope's reach, midway between two eighths of a 0.1 s step
T_END = 0.7
N_OUT = 8  # outputs every 0.1 s: a fixed step of 0.1 s is not cut by them
METHODS = [("rattle", {"dt": 0.1}), ("yoshida4", {"dt": 0.1}), ("dopri5", {"rtol": 1e-3}), ("dop853", {"rtol": 1e-3})]


def thrown_to_the_apex(height):
    """Start of a flight whose apex is at (0, 0, height) at T_APEX, moving along +x at VX."""
    return (np.array([-VX * T_APEX, 0.0, height - 0.5 * G * T_APEX ** 2]), np.array([VX, 0.0, G * T_APEX]))


def real_roots_in(poly, lo, hi):
    return sorted(float(r.real) for r in poly.roots() if abs(r.imag) < 1e-9 and lo < r.real < hi)


class GrazingBob:
    """The bob's motion in closed form: a flight that leaves |X| <= R on (t1, t2), the inelastic jerk at t1 taking
    its radial velocity (impulse m v_r), a rope that cannot hold it there (the tension it would need, m (v_t^2 / R +
    g . e_r), is negative near the top for v_t^2 < g R cos(theta)), and a flight from the post-jerk state."""

    def __init__(self):
        self.X0, self.V0 = thrown_to_the_apex(R + EPS)
        P = np.polynomial.Polynomial
        x, z = P([self.X0[0], self.V0[0]]), P([self.X0[2], self.V0[2], -0.5 * G])
        quartic = x * x + z * z - R * R
        self.window = real_roots_in(quartic, 0.0, T_END)
        t = self.window[0]
        for _ in range(3):
            X, V = ballistic(self.X0, self.V0, t)
            t -= (X @ X - R * R) / (2 * X @ V)
        self.t_taut = t
        X, V = ballistic(self.X0, self.V0, t)
        e_r = X / np.linalg.norm(X)
        self.v_r = float(V @ e_r)
        self.X1, self.V1 = X, V - self.v_r * e_r
        v_t2 = float(self.V1 @ self.V1)
        self.tension_needed = v_t2 / R + np.array([0.0, 0.0, -G]) @ e_r  # per unit mass

    def state(self, t):
        if t <= self.t_taut:
            return ballistic(self.X0, self.V0, t)
        return ballistic(self.X1, self.V1, t - self.t_taut)


BOB = GrazingBob()


def test_the_reference_grazes_between_two_eighths_of_one_coarse_step_and_cannot_hold_the_rope_taut():
    t1, t2 = BOB.window[:2]
    assert 0.3 < t1 < t2 < 0.3125 and t2 - t1 < 0.006  # within [0.3, 0.4], between its points at 0/8 and 1/8
    assert BOB.v_r > 0 and BOB.tension_needed < 0
    assert first_exit(BOB.X1, BOB.V1, R, T_END - BOB.t_taut) is None  # no other jerk before T_END


@pytest.mark.parametrize("method,kw", METHODS)
def test_a_rope_taut_for_five_milliseconds_inside_one_step_jerks_at_the_closed_form_time(method, kw):
    run = ln.simulate(bob_scene(BOB.X0, BOB.V0, R), T_END, method, n_out=N_OUT, error_estimate=False, **kw)
    assert [(ev.kind, ev.index) for ev in run.events] == [("taut", 0)]
    event = run.events[0]
    # a grazing crossing's time is ill-conditioned: the positions' round-off (1e-14 m) over the approach speed v_r
    assert abs(event.t - BOB.t_taut) <= 1e-14 / BOB.v_r
    # the impulse m v_r, v_r = 0.0152 m/s; its error is d(v_r)/dt ~ 6 m/s^2 times the time's
    assert event.impulse == pytest.approx(BOB.v_r, abs=1e-11)
    # the rope never holds: slack at every sample, and the flight from the post-jerk state
    assert run.slack[:, 0].all() and np.all(run.T[:, 0] == 0.0)
    for i, t in enumerate(run.t):
        X, V = BOB.state(t)
        assert np.abs(run.X[i, 1] - X).max() <= 1e-12
        assert np.abs(run.U[i, 1] - V).max() <= 1e-11
    # the energy lost is exactly the radial kinetic energy of the jerk
    energy = 0.5 * np.einsum("ij,ij->i", run.U[:, 1], run.U[:, 1]) + G * run.X[:, 1, 2]
    assert energy[0] - energy[-1] == pytest.approx(0.5 * BOB.v_r ** 2, rel=1e-6)


def ceiling_scene(X0, V0, height, mass=2.0):
    return ln.Scene.from_dict({"name": "ceiling", "gravity": [0, 0, -G],
                               "masses": [{"name": "ball", "position": list(X0), "mass": mass,
                                           "velocity": list(V0)}],
                               "ground": {"point": [0, 0, height], "normal": [0, 0, -1], "restitution": 0.5}})


@pytest.mark.parametrize("method,kw", METHODS)
def test_a_flight_that_grazes_a_ceiling_inside_one_step_touches_it_at_the_closed_form_time(method, kw):
    """The ceiling at 1 m, the apex 20 um above it: the mass reaches it at T_APEX - sqrt(2 EPS / g) with the normal
    speed sqrt(2 g EPS), rebounds at half that (restitution 0.5) and falls from there."""
    H, m, e = 1.0, 2.0, 0.5
    X0, V0 = thrown_to_the_apex(H + EPS)
    t_c = T_APEX - np.sqrt(2 * EPS / G)
    v_n = np.sqrt(2 * G * EPS)
    assert 0.3 < t_c < 2 * T_APEX - t_c < 0.3125  # above the ceiling between two eighths of the step [0.3, 0.4]
    run = ln.simulate(ceiling_scene(X0, V0, H, m), T_END, method, n_out=N_OUT, error_estimate=False, **kw)
    assert [(ev.kind, ev.index) for ev in run.events] == [("contact", 0)]
    assert abs(run.events[0].t - t_c) <= 1e-14 / v_n  # as the bob's: round-off over the approach speed
    assert run.events[0].impulse == pytest.approx(m * (1 + e) * v_n, rel=1e-8)
    X_c, V_c = ballistic(X0, V0, t_c)
    V_after = V_c * np.array([1.0, 1.0, -e])
    for i, t in enumerate(run.t):
        X, V = ballistic(X0, V0, t) if t <= t_c else ballistic(X_c, V_after, t - t_c)
        # after the contact: its time's uncertainty (5e-13 s) moves the rebound speed by (1 + e) g times it
        assert np.abs(run.X[i, 0] - X).max() <= 1e-11
        assert np.abs(run.U[i, 0] - V).max() <= 1e-11


@pytest.mark.parametrize("a,b", [(0.3, 0.31), (0.0501, 0.05011), (0.98, 0.999)])
def test_a_short_dip_crosses_at_its_closed_form_first_root_and_is_lowest_at_the_closed_form_minimum(a, b):
    """(theta - a)(theta - b)(1 + theta^2)^2 dips below 0 only on (a, b): it crosses at a, wherever the dip lies and
    however short; a dip shallower than the depth asked is none."""
    P = np.polynomial.Polynomial
    p = P([-a, 1]) * P([-b, 1]) * P([1, 0, 1]) ** 2
    dip = (b - a) ** 2 / 4  # the depth of the dip at its middle, to O(dip (a + b)^2)
    lowest = real_roots_in(p.deriv(), a, b)
    conditioning = 1e-14 / (b - a)  # the expanded coefficients' round-off over p's slope at a
    for depth in (0.0, 0.1 * dip):
        [(crossing, deepest)] = gap_dips(p.coef, depth)
        assert crossing == pytest.approx(a, abs=conditioning)
        assert deepest == pytest.approx(lowest[0], abs=1e-9)
    assert may_fall_below(p.coef[None, :], [0.1 * dip])[0]
    assert gap_dips(p.coef, 2 * dip * (1 + (a + b) ** 2) ** 2) == []


def test_a_graze_shallower_than_the_depth_is_passed_over_and_every_deeper_dip_is_given_in_order():
    """((theta - 0.3)^2 - 1e-14) (0.6 - theta): a first dip 3e-15 deep on 0.3 -/+ 1e-7, then a real one from 0.6 on."""
    P = np.polynomial.Polynomial
    p = -(P([-0.3, 1]) ** 2 - 1e-14) * P([-0.6, 1])
    assert [c for c, _ in gap_dips(p.coef, 1e-9)] == [pytest.approx(0.6, abs=1e-15)]
    both = gap_dips(p.coef, 0.0)
    assert [c for c, _ in both] == [pytest.approx(0.3 - 1e-7, abs=1e-9), pytest.approx(0.6, abs=1e-15)]
    assert [m for _, m in both] == [pytest.approx(0.3, abs=1e-9), 1.0]
    # a rebound: starting at round-off below zero and rising, the crossing is where it falls again
    rebound = P([-1e-17, 1]) * P([0.5, -1])
    assert [c for c, _ in gap_dips(rebound.coef, 1e-12)] == [pytest.approx(0.5, abs=1e-15)]
