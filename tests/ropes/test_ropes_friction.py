"""Coulomb friction on the ground against closed forms: a block on a tilted plane slides at g (sin a - mu cos a) or
stays stuck; a block thrown along the ground stops after v^2 / (2 mu g) at v / (mu g) and sticks; thrown up a slope
steeper than its friction angle it stops and slides back down; a mass landing at a slant keeps the tangential speed
left by the impulse-level law (stopped where v_t <= mu v_n); a rod standing on a rough floor with a mass on top slips
where the floor's force leaves the friction cone; a pendulum swinging into a rough ground lands, slides and stops."""
from __future__ import annotations

import numpy as np
import pytest
from rope_references import G, slope
from scipy.integrate import solve_ivp

import linknet_core as ln
from linknet_core.dynamics.unilateral import UnilateralDynamics

METHODS = [("dop853", {"rtol": 1e-10}), ("rattle", {"dt": 1e-2})]


@pytest.mark.parametrize("method,kw", METHODS)
def test_a_block_below_its_friction_angle_slides_down_at_g_sin_minus_mu_cos(method, kw):
    alpha, mu, m = 0.3, 0.2, 3.0
    scene, n, down = slope(alpha, mu, mass=m)
    run = ln.simulate(scene, 1.0, method, n_out=21, error_estimate=False, **kw)
    assert run.events == []
    a = G * (np.sin(alpha) - mu * np.cos(alpha))
    assert np.abs(run.X[:, 0] - 0.5 * a * run.t[:, None] ** 2 * down).max() < 1e-12
    dyn = UnilateralDynamics(scene)
    for X, U in zip(run.X[1:], run.U[1:]):
        normal, tangential = dyn.ground_forces(X, U)
        assert normal[0] == pytest.approx(m * G * np.cos(alpha), rel=1e-12)
        assert np.allclose(tangential[0], -mu * m * G * np.cos(alpha) * down, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method,kw", METHODS)
def test_a_block_above_its_friction_angle_stays_stuck_held_by_the_weights_tangential_part(method, kw):
    alpha, mu, m = 0.3, 0.5, 3.0  # tan(0.3) = 0.309 < 0.5
    scene, n, down = slope(alpha, mu, mass=m)
    run = ln.simulate(scene, 1.0, method, n_out=11, error_estimate=False, **kw)
    assert run.events == []
    assert np.abs(run.X[:, 0]).max() < 1e-13 and np.abs(run.U[:, 0]).max() < 1e-13
    normal, tangential = UnilateralDynamics(scene).ground_forces(run.X[-1], run.U[-1])
    assert normal[0] == pytest.approx(m * G * np.cos(alpha), rel=1e-12)
    assert np.allclose(tangential[0], -m * G * np.sin(alpha) * down, rtol=0, atol=1e-12)


@pytest.mark.parametrize("method,kw", METHODS)
def test_a_block_thrown_along_the_ground_stops_after_v2_over_2_mu_g_at_v_over_mu_g(method, kw):
    v, mu, m = 3.0, 0.4, 2.0
    scene = ln.Scene.from_dict({"name": "thrown", "gravity": [0, 0, -G],
                                "masses": [{"name": "block", "position": [0, 0, 0], "mass": m,
                                            "velocity": [v * 0.6, v * 0.8, 0]}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})
    run = ln.simulate(scene, 1.5, method, n_out=16, error_estimate=False, **kw)
    t_stop, distance = v / (mu * G), v * v / (2 * mu * G)
    assert [(e.kind, e.index) for e in run.events] == [("stick", 0)]
    assert run.events[0].t == pytest.approx(t_stop, abs=1e-12)
    assert run.events[0].impulse < 1e-10  # friction brought it to rest: nothing left to stop
    s = np.minimum(run.t, t_stop)
    along = v * s - 0.5 * mu * G * s * s
    assert np.abs(run.X[:, 0, :2] - along[:, None] * [0.6, 0.8]).max() < 1e-12
    assert np.abs(run.X[-1, 0, :2] - distance * np.array([0.6, 0.8])).max() < 1e-12
    assert np.abs(run.U[run.t > t_stop, 0]).max() < 1e-13


def test_a_block_thrown_up_a_slope_steeper_than_its_friction_angle_stops_and_slides_back():
    alpha, mu, v = 0.5, 0.2, 2.0  # tan(0.5) = 0.546 > 0.2
    scene, n, down = slope(alpha, mu, v_down=-v)
    run = ln.simulate(scene, 1.5, "dop853", rtol=1e-10, n_out=31, error_estimate=False)
    up = G * (np.sin(alpha) + mu * np.cos(alpha))  # deceleration going up
    back = G * (np.sin(alpha) - mu * np.cos(alpha))  # acceleration coming down
    t_stop = v / up
    assert run.events == []  # it stops and slides on: no stick, no event recorded
    for t, X in zip(run.t, run.X[:, 0]):
        s = -v * t + 0.5 * up * t * t if t <= t_stop else -v * v / (2 * up) + 0.5 * back * (t - t_stop) ** 2
        assert X == pytest.approx(s * down, abs=1e-11)


@pytest.mark.parametrize("v_t,mu", [(1.0, 0.4), (3.0, 0.4)])
def test_a_mass_landing_at_a_slant_takes_the_impulse_level_coulomb_law(v_t, mu):
    # it lands with the normal speed v_n: the normal impulse m v_n (inelastic), the tangential one m v_t if that is
    # within mu m v_n (it stops), else mu m v_n, leaving v_t - mu v_n to slide off and stop under mu g
    h, m = 0.8, 1.5
    v_n = np.sqrt(2 * G * h)
    t_land = v_n / G
    scene = ln.Scene.from_dict({"name": "slant", "gravity": [0, 0, -G],
                                "masses": [{"name": "ball", "position": [0, 0, h], "mass": m,
                                            "velocity": [v_t, 0, 0]}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})
    run = ln.simulate(scene, 2.0, "dop853", rtol=1e-10, n_out=41, error_estimate=False)
    assert run.events[0].kind == "contact" and run.events[0].t == pytest.approx(t_land, abs=1e-12)
    assert run.events[0].impulse == pytest.approx(m * v_n, rel=1e-12)
    left = max(v_t - mu * v_n, 0.0)
    x_land = v_t * t_land
    if left == 0:
        assert len(run.events) == 1
        x_rest = x_land
    else:
        t_stop = t_land + left / (mu * G)
        assert [e.kind for e in run.events] == ["contact", "stick"]
        assert run.events[1].t == pytest.approx(t_stop, abs=1e-12)
        after = (run.t > t_land) & (run.t < t_stop)
        s = run.t[after] - t_land
        assert np.abs(run.X[after, 0, 0] - (x_land + left * s - 0.5 * mu * G * s * s)).max() < 1e-12
        x_rest = x_land + left * left / (2 * mu * G)
    assert run.X[-1, 0, 0] == pytest.approx(x_rest, abs=1e-12)
    assert np.abs(run.U[-1, 0]).max() < 1e-13


def test_a_rod_standing_on_a_rough_floor_slips_where_the_floor_force_leaves_the_friction_cone():
    # a mass m_b on a rod r above a base mass m_a on the floor, tilted by theta0 and let go: while the base sticks
    # the top falls as an inverted pendulum, theta'' = (g/r) sin(theta), the rod's compression C = m_b g (3 cos(theta)
    # - 2 cos(theta0)); the floor holds the base with C sin(theta) against a normal force m_a g + C cos(theta), and
    # the base slips where C sin(theta) = mu (m_a g + C cos(theta))
    m_a, m_b, r, theta0, mu = 1.0, 1.0, 1.0, 0.1, 0.15
    scene = ln.Scene.from_dict({"name": "standing_rod", "gravity": [0, 0, -G],
                                "masses": [{"name": "base", "position": [0, 0, 0], "mass": m_a},
                                           {"name": "top", "position": [r * np.sin(theta0), 0, r * np.cos(theta0)],
                                            "mass": m_b}],
                                "links": [{"a": "base", "b": "top"}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})

    def cone(_, y):
        C = m_b * G * (3 * np.cos(y[0]) - 2 * np.cos(theta0))
        return C * np.sin(y[0]) - mu * (m_a * G + C * np.cos(y[0]))
    cone.terminal, cone.direction = True, 1
    sol = solve_ivp(lambda _, y: [y[1], G / r * np.sin(y[0])], (0, 5), [theta0, 0.0], method="DOP853",
                    rtol=1e-12, atol=1e-12, events=cone)
    t_slip = sol.t_events[0][0]
    run = ln.simulate(scene, t_slip + 0.01, "dop853", rtol=1e-10, n_out=11, error_estimate=False)
    slips = [e for e in run.events if e.kind == "slip"]
    assert [(e.kind, e.index) for e in run.events][:1] == [("slip", 0)]
    assert slips[0].t == pytest.approx(t_slip, abs=1e-9)
    before = run.t < t_slip
    assert np.abs(run.X[before, 0]).max() < 1e-13


def test_a_pendulum_swinging_into_a_rough_ground_lands_slides_and_stops():
    # the bob of the frictionless test (a rope of 1 m from a pivot 0.8 m up, released from the horizontal) lands at
    # x = 0.6 with v0 = sqrt(2 g 0.8) along the circle: normal part 0.6 v0 (the normal impulse), tangential 0.8 v0,
    # more than mu 0.6 v0: it keeps 0.8 v0 - mu 0.6 v0 and slides (its rope slack) to rest after (that)^2 / (2 mu g)
    mu = 0.5
    scene = ln.Scene.from_dict({"name": "rough_swing", "gravity": [0, 0, -G],
                                "masses": [{"name": "pivot", "position": [0, 0, 0.8], "fixed": True},
                                           {"name": "bob", "position": [1.0, 0, 0.8], "mass": 1.0}],
                                "links": [{"a": 1, "b": 2, "kind": "rope"}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})
    run = ln.simulate(scene, 1.5, "dop853", rtol=1e-10, n_out=151, error_estimate=False)
    sol = solve_ivp(lambda _, y: [y[1], -G * np.sin(y[0])], (0, 2), [np.pi / 2, 0.0], method="DOP853", rtol=1e-12,
                    atol=1e-12, events=lambda _, y: y[0] - np.arccos(0.8))
    t_land = sol.t_events[0][0]
    v0 = np.sqrt(2 * G * 0.8)
    left = 0.8 * v0 - mu * 0.6 * v0
    t_stop = t_land + left / (mu * G)
    assert [(e.kind, e.index) for e in run.events] == [("contact", 1), ("slack", 0), ("stick", 1)]
    assert run.events[0].t == pytest.approx(t_land, abs=1e-9)
    assert run.events[0].impulse == pytest.approx(0.6 * v0, rel=1e-9)
    assert run.events[2].t == pytest.approx(t_stop, abs=1e-9)
    assert run.X[-1, 1] == pytest.approx([0.6 - left * left / (2 * mu * G), 0, 0], abs=1e-9)
    assert run.slack[run.t > t_land + 1e-6, 0].all()
