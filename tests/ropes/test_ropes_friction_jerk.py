"""A rope jerking a mass that rests on a rough ground, against Newton's laws and Coulomb's written here.

Along the ground: b slides away from a resting along the rope's line, decelerated by mu g, until the rope reaches
its length at the root of D + V0 t - mu g t^2 / 2 = R; the jerk (inelastic) gives both ends the rope's rate, the
momentum along the rope kept: v = m_b V / (m_a + m_b). The jerk is horizontal, so the ground takes no normal
impulse and Coulomb's law allows it no friction impulse however rough it is: a slides off with b, both decelerate
at mu g (the rope neither pulls nor pushes) and stop at t_jerk + v / (mu g), a at v^2 / (2 mu g).

Into the ground: a also hangs on a second rope from an anchor below the ground's plane, at its length, down and back
at 45 degrees (x, z); b pulls along u = (cos beta, sin beta, 0), tan beta = 1/2. The anchor's rope and the ground
block a's motion along +x, so the jerk J u presses a into the ground: P_F cos alpha = J cos beta along x, the normal
impulse P_n = P_F sin alpha; along y only friction holds a. Held, a needs |P_t| >= J sin beta, which some split of
the impulse between the anchor's rope and the grip gives where mu >= sin beta (the least |P_t| / P_n over the
splits): mu 0.6 holds it, b stops dead (J = m_b V) and both stay. Where mu < sin beta a slides along y,
P_t = -mu P_n: m_a w = J (sin beta - mu cos beta tan alpha), and the rope's rate after the jerk shared,
V - J / m_b = w sin beta."""
from __future__ import annotations

import math

import numpy as np
import pytest
from rope_references import G

import linknet_core as ln

M_A, M_B = 0.2, 0.1  # the resting mass, the thrown one (kg)
ROPE, START, V0 = 0.25, 0.2, 2.0  # the rope's length, b's distance from a and its speed away from it
BETA = math.atan(0.5)  # the pull's angle from x, into the ground's case
ALPHA, ANCHOR_ROPE = math.radians(45.0), 0.3  # the anchor's rope below the plane: its angle down, its length
STEP = 1e-9  # the velocities just after the jerk: friction's own change over it, mu g STEP < 1e-8 m/s


def jerk_time(mu):
    """b sliding away from a at V0, decelerated by mu g, reaches the rope's length: (time, its speed then)."""
    deceleration = mu * G
    t = (V0 - math.sqrt(V0 ** 2 - 2 * deceleration * (ROPE - START))) / deceleration
    return t, V0 - deceleration * t


def level_scene(mu):
    return ln.Scene.from_dict({
        "name": "jerk_along_rough_ground", "gravity": [0, 0, -G],
        "masses": [{"name": "a", "position": [0, 0, 0], "mass": M_A},
                   {"name": "b", "position": [START, 0, 0], "mass": M_B, "velocity": [V0, 0, 0]}],
        "links": [{"a": "a", "b": "b", "length": ROPE, "kind": "rope"}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_a_jerk_along_a_rough_ground_sets_the_resting_mass_sliding_until_it_stops_at_mu_g(backend):
    mu = 1.0
    t_jerk, V = jerk_time(mu)
    v = M_B * V / (M_A + M_B)  # both ends at the rope's rate, the momentum along it kept
    t_stop = t_jerk + v / (mu * G)
    slide = v ** 2 / (2 * mu * G)
    run = ln.simulate(level_scene(mu), t_end=0.12, method="dop853", rtol=1e-10, backend=backend, n_out=2,
                      error_estimate=False)
    taut = [e for e in run.events if e.kind == "taut"]
    assert len(taut) == 1  # one jerk: the held mass's chatter of jerks is gone
    assert taut[0].t == pytest.approx(t_jerk, abs=1e-12)
    assert taut[0].impulse == pytest.approx(M_A * v, rel=1e-12)
    assert [(e.kind, e.index) for e in run.events if e.kind == "slip"] == [("slip", 0)]
    stops = [e for e in run.events if e.kind == "stick"]
    assert sorted(e.index for e in stops) == [0, 1]
    assert all(e.t == pytest.approx(t_stop, abs=1e-9) for e in stops)
    np.testing.assert_allclose(run.X[-1][:, :2], [[slide, 0], [slide + ROPE, 0]], atol=1e-12)
    sim = ln.Simulator(level_scene(mu), method="dop853", rtol=1e-10, backend=backend)
    sim.advance(t_jerk + STEP)
    np.testing.assert_allclose(sim.state.U, [[v, 0, 0], [v, 0, 0]], atol=1e-8)


def anchored_scene(mu):
    u = np.array([math.cos(BETA), math.sin(BETA), 0.0])
    anchor = [-ANCHOR_ROPE * math.cos(ALPHA), 0.0, -ANCHOR_ROPE * math.sin(ALPHA)]
    return ln.Scene.from_dict({
        "name": "jerk_into_rough_ground", "gravity": [0, 0, -G],
        "masses": [{"name": "anchor", "position": anchor, "fixed": True},
                   {"name": "a", "position": [0, 0, 0], "mass": M_A},
                   {"name": "b", "position": (START * u).tolist(), "mass": M_B, "velocity": (V0 * u).tolist()}],
        "links": [{"a": "a", "b": "b", "length": ROPE, "kind": "rope"},
                  {"a": "anchor", "b": "a", "length": ANCHOR_ROPE, "kind": "rope"}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}}), u


@pytest.mark.parametrize("backend", ["numpy", "native"])
@pytest.mark.parametrize("mu", [0.6, 0.4])
def test_a_jerk_pressing_a_mass_into_a_rough_ground_holds_it_within_coulombs_cone(backend, mu):
    assert not math.sin(BETA) <= mu <= 0.5  # clear of the band where held or sliding depends on the split
    scene, u = anchored_scene(mu)
    t_jerk, V = jerk_time(mu)
    held = mu >= math.sin(BETA)
    if held:
        J, w = M_B * V, 0.0
    else:
        slip = math.sin(BETA) - mu * math.cos(BETA) * math.tan(ALPHA)
        J = V / (1 / M_B + math.sin(BETA) * slip / M_A)
        w = J * slip / M_A
    run = ln.simulate(scene, t_end=0.03, method="dop853", rtol=1e-10, backend=backend, n_out=2,
                      error_estimate=False)
    jerk = next(e for e in run.events if e.kind == "taut" and e.index == 0)
    assert jerk.t == pytest.approx(t_jerk, abs=1e-12)
    assert jerk.impulse == pytest.approx(J, rel=1e-12)
    assert any(e.kind == "slip" and e.index == 1 for e in run.events) == (not held)
    sim = ln.Simulator(scene, method="dop853", rtol=1e-10, backend=backend)
    sim.advance(t_jerk + STEP)
    np.testing.assert_allclose(sim.state.U[1:], [[0, w, 0], V * u - J / M_B * u], atol=1e-8)
    if held:  # a held, b stopped dead by the jerk and held too: nothing moves on
        np.testing.assert_allclose(run.X[-1][1:], [[0, 0, 0], ROPE * u], atol=1e-12)
