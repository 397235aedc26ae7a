"""A ground the masses land on: a bouncing mass against the closed-form bounce times, impulses and heights, a mass
sliding down a tilted frictionless ground against its constant acceleration g sin(alpha), and the rest rule that ends
a bouncing sequence after finitely many events."""
from __future__ import annotations

import numpy as np
import pytest
from rope_references import G, ballistic

import linknet_core as ln
from linknet_core.dynamics.unilateral import UnilateralDynamics


def dropped(height, e, vx=0.5, mass=2.0):
    return ln.Scene.from_dict({"name": "ball", "gravity": [0, 0, -G],
                               "masses": [{"name": "ball", "position": [0, 0, height], "mass": mass,
                                           "velocity": [vx, 0, 0]}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": e}})


def bounces(height, e, count):
    """(t_k, speed at impact v_k) of the first ``count`` impacts: t_1 = sqrt(2 h / g), v_1 = sqrt(2 g h), and each
    rebound at e v_k flies 2 e v_k / g."""
    t, v = np.sqrt(2 * height / G), np.sqrt(2 * G * height)
    out = []
    for _ in range(count):
        out.append((t, v))
        t, v = t + 2 * e * v / G, e * v
    return out


@pytest.mark.parametrize("method,kw", [("dop853", {"rtol": 1e-10}), ("rattle", {"dt": 2e-3})])
def test_a_dropped_mass_bounces_at_the_closed_form_times_and_heights_then_rests(method, kw):
    h, e, m, vx = 1.0, 0.5, 2.0, 0.5
    expected = bounces(h, e, 8)
    t_rest = expected[0][0] + 2 * e * expected[0][1] / (G * (1 - e))  # the bounces' accumulation point
    run = ln.simulate(dropped(h, e, vx, m), 1.6, method, n_out=161, error_estimate=False, **kw)
    contacts = [ev for ev in run.events if ev.kind == "contact"]
    for event, (t, v) in zip(contacts, expected):
        assert event.t == pytest.approx(t, abs=1e-12)
        assert event.impulse == pytest.approx(m * (1 + e) * v, rel=1e-10)  # Newton: v -> -e v
    assert all(ev.kind == "contact" and ev.t < t_rest for ev in run.events)
    assert len(contacts) < 40  # the rest rule ends the sequence: finitely many events
    # between the impacts the flight is a parabola of apex e^(2k) h
    for i, t in enumerate(run.t):
        k = int(np.searchsorted([c[0] for c in expected], t)) - 1
        if t >= expected[-1][0]:
            break
        if k < 0:
            z = ballistic(np.array([0, 0, h]), np.zeros(3), t)[0][2]
        else:
            z = ballistic(np.zeros(3), np.array([0, 0, e * expected[k][1]]), t - expected[k][0])[0][2]
        assert run.X[i, 0, 2] == pytest.approx(z, abs=1e-11)
    # frictionless: the horizontal motion never changes; at rest on the ground after the accumulation point
    assert np.allclose(run.X[:, 0, 0], vx * run.t, rtol=0, atol=1e-12)
    resting = run.t > t_rest + 1e-6
    assert np.abs(run.X[resting, 0, 2]).max() < 1e-14 and np.abs(run.U[resting, 0, 2]).max() < 1e-12
    assert run.residual.max() < 1e-14 and run.velocity_residual.max() < 1e-12


def test_three_masses_dropped_from_three_heights_bounce_each_at_its_own_closed_form_times():
    heights, e = (1.0, 0.6, 0.3), 0.5
    scene = ln.Scene.from_dict({"name": "balls", "gravity": [0, 0, -G],
                                "masses": [{"name": f"b{i}", "position": [i, 0, h], "mass": 1.0 + i}
                                           for i, h in enumerate(heights)],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": e}})
    run = ln.simulate(scene, 1.0, "dop853", rtol=1e-10, n_out=11, error_estimate=False)
    for i, h in enumerate(heights):
        mine = [ev for ev in run.events if ev.index == i]
        expected = [b for b in bounces(h, e, 12) if b[0] < 1.0]
        assert len(mine) >= 2
        for event, (t, v) in zip(mine, expected):
            assert event.kind == "contact" and event.t == pytest.approx(t, abs=1e-12)
            assert event.impulse == pytest.approx((1.0 + i) * (1 + e) * v, rel=1e-10)


@pytest.mark.parametrize("method,kw", [("dop853", {"rtol": 1e-10}), ("rattle", {"dt": 1e-2})])
def test_a_mass_slides_down_a_tilted_frictionless_ground_at_g_sin_alpha(method, kw):
    alpha = 0.3
    n = np.array([np.sin(alpha), 0.0, np.cos(alpha)])
    down = np.array([np.cos(alpha), 0.0, -np.sin(alpha)])
    scene = ln.Scene.from_dict({"name": "slope", "gravity": [0, 0, -G],
                                "masses": [{"name": "block", "position": [0, 0, 0], "mass": 3.0}],
                                "ground": {"point": [0, 0, 0], "normal": n.tolist()}})
    run = ln.simulate(scene, 1.0, method, n_out=21, error_estimate=False, **kw)
    assert run.events == []
    expected = 0.5 * G * np.sin(alpha) * run.t[:, None] ** 2 * down
    assert np.abs(run.X[:, 0] - expected).max() < 1e-12
    # the ground's normal force is the weight's normal part, m g cos(alpha), at every sample
    dyn = UnilateralDynamics(scene)
    for X, U in zip(run.X, run.U):
        _, normal = dyn.resolve(X, U)
        assert normal[0] == pytest.approx(3.0 * G * np.cos(alpha), rel=1e-12)


def test_a_pendulum_swinging_into_the_ground_lands_slides_and_is_jerked_off_it_by_its_rope():
    # a bob on a rope of 1 m from a pivot 0.8 m above the ground, released from the horizontal, reaches the ground
    # at x = 0.6 (cos(theta) = 0.8); the inelastic contact takes the normal velocity and the rope goes slack; the bob
    # slides (frictionless) to x = -0.6, where the rope jerks it off the ground; it swings up and, the pendulum being
    # symmetric, comes down to the same point with the velocity reversed and lands again
    from scipy.integrate import solve_ivp

    scene = ln.Scene.from_dict({"name": "swing", "gravity": [0, 0, -G],
                                "masses": [{"name": "pivot", "position": [0, 0, 0.8], "fixed": True},
                                           {"name": "bob", "position": [1.0, 0, 0.8], "mass": 1.0}],
                                "links": [{"a": 1, "b": 2, "kind": "rope"}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1]}})
    run = ln.simulate(scene, 1.5, "dop853", rtol=1e-10, n_out=151, error_estimate=False)
    theta_ground = np.arccos(0.8)

    def swing(theta0, omega0, t_span, direction):
        def ground(_, y):
            return y[0] - direction * theta_ground
        ground.terminal, ground.direction = True, -direction
        sol = solve_ivp(lambda _, y: [y[1], -G * np.sin(y[0])], t_span, [theta0, omega0], method="DOP853",
                        rtol=1e-12, atol=1e-12, events=ground)
        return sol.t_events[0][0]
    v0 = np.sqrt(2 * G * 0.8)  # energy: the fall from the horizontal to the ground
    t_land = swing(np.pi / 2, 0.0, (0, 2), 1)
    t_taut = t_land + 1.2 / (0.8 * v0)  # sliding at the horizontal part 0.8 v0
    # the jerk at x = -0.6 takes the radial part 0.6 of the 0.8 v0 the bob slides with; the tangential velocity left,
    # 0.8 * 0.8 v0 along the circle, swings it up and back to the ground
    t_again = swing(-theta_ground, -0.64 * v0, (t_taut, t_taut + 2), -1)
    expected = [(t_land, "contact", 1, v0 * np.sin(theta_ground)), (t_land, "slack", 0, 0.0),
                (t_taut, "taut", 0, 0.6 * 0.8 * v0), (t_taut, "release", 1, 0.0),
                (t_again, "contact", 1, 0.64 * v0 * np.sin(theta_ground)), (t_again, "slack", 0, 0.0)]
    assert [(e.kind, e.index) for e in run.events] == [(k, i) for _, k, i, _ in expected]
    for event, (t, _, _, impulse) in zip(run.events, expected):
        assert event.t == pytest.approx(t, abs=1e-9)
        assert event.impulse == pytest.approx(impulse, rel=1e-9, abs=1e-12)
    sliding = (run.t > t_land) & (run.t < t_taut)
    assert np.abs(run.X[sliding, 1, 2]).max() < 1e-14
    assert np.allclose(run.U[sliding, 1], [-0.8 * v0, 0, 0], rtol=0, atol=1e-9)
    assert run.slack[sliding, 0].all() and not run.slack[(run.t > t_taut) & (run.t < t_again), 0].any()
    assert run.residual.max() < 1e-13


def test_a_rope_chain_falling_onto_the_ground_lands_mass_by_mass_and_loads_it_with_three_times_the_resting_weight():
    # N masses of lambda a on ropes of a, hanging straight up from a height a, released: they fall freely (the ropes
    # at their length with no tension), each lands inelastically at t_k = sqrt(2 k a / g) with the impulse m v_k and
    # its rope to the next goes slack. The falling-chain law (a flexible chain falling onto a table): the force on
    # the table is the weight of the part at rest plus the momentum flux lambda v^2 = 2 lambda g y, 3 lambda g y in
    # all; the discrete chain's force, averaged over a few landings, tends to it as a / y
    N, a, lam = 20, 0.05, 1.0
    m = lam * a
    scene = ln.Scene.from_dict({"name": "falling_chain", "gravity": [0, 0, -G],
                                "masses": [{"name": f"c{k}", "position": [0, 0, a * (k + 1)], "mass": m}
                                           for k in range(N)],
                                "links": [{"a": k + 1, "b": k + 2, "kind": "rope"} for k in range(N - 1)],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1]}})
    run = ln.simulate(scene, 0.5, "dop853", rtol=1e-10, n_out=11, error_estimate=False)
    contacts = [e for e in run.events if e.kind == "contact"]
    assert [e.index for e in contacts] == list(range(N))
    assert [e.index for e in run.events if e.kind == "slack"] == list(range(N - 1))
    k = np.arange(1, N + 1)
    t = np.array([e.t for e in contacts])
    J = np.array([e.impulse for e in contacts])
    assert np.abs(t - np.sqrt(2 * k * a / G)).max() < 1e-14
    assert np.abs(J - m * np.sqrt(2 * G * k * a)).max() < 1e-14
    ratios = []
    for first in range(5, N - 5, 3):  # windows of five landings
        w0, w1 = t[first], t[first + 5]
        delivered = J[first + 1:first + 6].sum() + sum(m * G * (w1 - max(tk, w0)) for tk in t if tk < w1)
        y = 0.5 * G * (0.5 * (w0 + w1)) ** 2  # the length at rest in the continuum at the window's middle
        ratios.append(delivered / (w1 - w0) / (lam * G * y))
    assert all(2.99 < r < 3.03 for r in ratios), ratios
    assert all(abs(b - 3) < abs(a_ - 3) for a_, b in zip(ratios, ratios[1:]))  # closer to 3 as y grows
