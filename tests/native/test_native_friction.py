"""Coulomb friction on the ground on the native core (linknet_core/native/src/stages/friction.c and ropes.c: a stuck
contact's grips, a sliding one's friction -mu N d carried through the links, its slip direction, the stick and slip
events, the impact with friction) against the numpy reference (linknet_core.dynamics.unilateral,
linknet_core.integrators.events) to round-off and against closed forms. Masses alone: a block on a tilted plane that
slides at g (sin a - mu cos a) or stays stuck, a block thrown along the ground that stops at v / (mu g) and sticks,
one thrown up a slope steeper than its friction angle that stops and slides back, a mass landing at a slant (the
impulse-level law), a puck pushed across its slide (its slip direction turning), a stuck block pushed by an input
until it slips. Masses joined by links: a rod leaning on the ground with its foot pushed sideways and a dumbbell
pushed at a slant (the slip from rest turned by the rod), a rod dropped at a slant landing on one end (stuck, and
sliding until its top lands), a rod standing on the floor until its base slips, a pendulum swinging into the ground
(its rope jerked slack, the bob sliding to a stop). backend="auto" takes every one of them to the core, on the adaptive
methods and on RATTLE and its compositions (the native FMU offers every method too)."""
from __future__ import annotations

import numpy as np
import pytest
from test_native_ropes import _agree, _both  # tests/native is on sys.path (pytest puts a test file's folder there)
from ropes.rope_references import G, slope

import linknet_core as ln

METHODS = ["dop853", "dopri5"]


def thrown(v=3.0, mu=0.4, m=2.0):
    return ln.Scene.from_dict({"name": "thrown", "gravity": [0, 0, -G],
                               "masses": [{"name": "block", "position": [0, 0, 0], "mass": m,
                                           "velocity": [v * 0.6, v * 0.8, 0]}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})


def slant(v_t, mu=0.4, h=0.8, m=1.5):
    return ln.Scene.from_dict({"name": "slant", "gravity": [0, 0, -G],
                               "masses": [{"name": "ball", "position": [0, 0, h], "mass": m, "velocity": [v_t, 0, 0]}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})


def puck():
    return ln.Scene.from_dict({"name": "puck", "gravity": [0, 0, -G],
                               "masses": [{"name": "puck", "position": [0, 0, 0], "mass": 1.0,
                                           "velocity": [1.5, 0, 0], "force": [0, 2.0, 0]}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": 0.1}})


def rod(X, masses, mu, U=None, forces=None, restitution=0.0):
    X = np.asarray(X, float)
    return ln.Scene.from_dict({
        "name": "rod", "gravity": [0, 0, -G],
        "masses": [{"name": f"m{i + 1}", "position": X[i].tolist(), "mass": masses[i],
                    "velocity": [0, 0, 0] if U is None else list(U[i]),
                    "force": [0, 0, 0] if forces is None else list(forces[i])} for i in range(2)],
        "links": [{"a": "m1", "b": "m2", "length": float(np.linalg.norm(X[1] - X[0]))}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu, "restitution": restitution}})


def dropped_rod(mu, v, h=0.3, angle=0.9):
    X = np.array([[0.0, 0.0, h], [np.cos(angle), 0.0, h + np.sin(angle)]])
    return rod(X, [1.0, 2.0], mu, U=[v, v])


def swing(mu=0.5):
    return ln.Scene.from_dict({"name": "rough_swing", "gravity": [0, 0, -G],
                               "masses": [{"name": "pivot", "position": [0, 0, 0.8], "fixed": True},
                                          {"name": "bob", "position": [1.0, 0, 0.8], "mass": 1.0}],
                               "links": [{"a": 1, "b": 2, "kind": "rope"}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})


SCENES = {"sliding block": (lambda: slope(0.3, 0.2)[0], 1.0, 21, 0),
          "stuck block": (lambda: slope(0.3, 0.5)[0], 1.0, 21, 0),
          "block thrown up a slope": (lambda: slope(0.5, 0.2, v_down=-2.0)[0], 1.5, 31, 0),
          "block thrown along the ground": (thrown, 1.5, 16, 1),
          "mass landing, stopped": (lambda: slant(1.0), 2.0, 41, 1),
          "mass landing, sliding on": (lambda: slant(3.0), 2.0, 41, 2),
          "puck pushed across its slide": (puck, 0.5, 21, 0)}
LINKED = {"rod leaning, its foot pushed": (lambda: rod([[0, 0, 0], [0.6, 0, 0.8]], [1.0, 2.0], 0.1,
                                                       forces=[[0, 4.0, 0], [0, 0, 0]]), 0.3, 31, 0),
          "dumbbell pushed at a slant": (lambda: rod([[0.5, 0, 0], [-0.5, 0, 0]], [1.0, 1.5], 0.3,
                                                     forces=[[8.0, 6.0, 0], [0, 0, 0]]), 0.3, 31, 0),
          "rod landing on one end, stuck": (lambda: dropped_rod(0.8, [1.2, 0.7, 0.0]), 0.3, 61, 1),
          "rod landing on one end, sliding": (lambda: dropped_rod(0.2, [3.0, 1.5, 0.0]), 0.6, 61, 2),
          "rod standing until its base slips": (lambda: rod([[0, 0, 0], [np.sin(0.1), 0, np.cos(0.1)]], [1.0, 1.0],
                                                            0.15), 0.6, 13, 1),
          "pendulum swinging into the ground": (swing, 1.5, 51, 3)}


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("name", list(SCENES) + list(LINKED))
def test_masses_alone_or_linked_on_a_rough_ground_give_the_references_events_and_states_to_round_off(name, method):
    make, t_end, n_out, n_events = {**SCENES, **LINKED}[name]
    scene = make()
    assert ln.Simulator(scene, method, backend="auto").backend == "native"
    reference, native = _both(scene, t_end, method, n_out=n_out)
    assert len(reference.events) == n_events
    _agree(reference, native, min_events=n_events)
    assert native.stats["steps"] == reference.stats["steps"]


@pytest.mark.parametrize("method", METHODS)
def test_a_block_below_its_friction_angle_slides_at_g_sin_minus_mu_cos_and_above_it_stays(method):
    alpha = 0.3
    for mu, a in ((0.2, G * (np.sin(alpha) - 0.2 * np.cos(alpha))), (0.5, 0.0)):
        scene, _, down = slope(alpha, mu)
        run = ln.simulate(scene, 1.0, method, n_out=21, error_estimate=False, rtol=1e-10, backend="native")
        assert run.events == []
        assert np.abs(run.X[:, 0] - 0.5 * a * run.t[:, None] ** 2 * down).max() < 1e-12


@pytest.mark.parametrize("method", METHODS)
def test_a_block_thrown_along_the_ground_stops_at_v_over_mu_g_after_v2_over_2_mu_g_and_sticks(method):
    v, mu = 3.0, 0.4
    run = ln.simulate(thrown(v, mu), 1.5, method, n_out=16, error_estimate=False, rtol=1e-10, backend="native")
    t_stop, distance = v / (mu * G), v * v / (2 * mu * G)
    assert [(e.kind, e.index) for e in run.events] == [("stick", 0)]
    assert run.events[0].t == pytest.approx(t_stop, abs=1e-12)
    assert np.abs(run.X[-1, 0, :2] - distance * np.array([0.6, 0.8])).max() < 1e-12
    assert np.abs(run.U[run.t > t_stop, 0]).max() < 1e-13


def test_a_mass_landing_at_a_slant_keeps_v_t_minus_mu_v_n_and_slides_to_the_closed_form_place():
    h, m, mu, v_t = 0.8, 1.5, 0.4, 3.0
    v_n = np.sqrt(2 * G * h)
    t_land = v_n / G
    run = ln.simulate(slant(v_t, mu, h, m), 2.0, "dop853", n_out=41, error_estimate=False, rtol=1e-10,
                      backend="native")
    assert [e.kind for e in run.events] == ["contact", "stick"]
    assert run.events[0].t == pytest.approx(t_land, abs=1e-12)
    assert run.events[0].impulse == pytest.approx(m * v_n, rel=1e-12)
    left = v_t - mu * v_n
    assert run.events[1].t == pytest.approx(t_land + left / (mu * G), abs=1e-12)
    assert run.X[-1, 0, 0] == pytest.approx(v_t * t_land + left * left / (2 * mu * G), abs=1e-12)


def test_a_stuck_block_pushed_beyond_its_friction_slips_as_the_reference_says():
    # at rest on a flat ground with mu 0.3 (it holds 0.3 m g), then pushed with 0.5 m g along x: a 'slip' at once,
    # and it slides at (0.5 - 0.3) g
    scene = ln.Scene.from_dict({"name": "pushed", "gravity": [0, 0, -G],
                                "masses": [{"name": "block", "position": [0, 0, 0], "mass": 2.0}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": 0.3}})
    runs = {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, "dop853", rtol=1e-10, error_estimate=False, backend=backend)
        sim.advance(0.2)
        push = np.array([[0.5 * 2.0 * G, 0.0, 0.0]])
        sim.advance(0.7, F_input=push)
        runs[backend] = (sim.state.X.copy(), sim.state.U.copy(), list(sim.integrator.events))
    X, U, events = runs["native"]
    assert [(e.kind, e.index) for e in events] == [(e.kind, e.index) for e in runs["numpy"][2]] == [("slip", 0)]
    assert abs(events[0].t - runs["numpy"][2][0].t) <= 1e-12
    assert np.abs(X - runs["numpy"][0]).max() <= 1e-12 and np.abs(U - runs["numpy"][1]).max() <= 1e-12
    s = 0.5
    assert X[0, 0] == pytest.approx(0.5 * 0.2 * G * s * s, abs=1e-12)


def test_a_snapshot_taken_mid_slide_continues_identically_on_native():
    sim = ln.Simulator(thrown(), "dop853", rtol=1e-10, error_estimate=False, backend="native")
    sim.advance(0.3)  # sliding, its slip reference set
    snapshot = sim.get_state()
    sim.advance(1.2)
    X, events = sim.state.X.copy(), list(sim.integrator.events)
    sim.set_state(snapshot)
    sim.advance(1.2)
    assert np.array_equal(sim.state.X, X) and sim.integrator.events == events
    assert [e.kind for e in events] == ["stick"]


FIXED_STEP = {"block thrown along the ground": (thrown, 1.0, "rattle", 1e-2, 1),
              "mass landing, sliding on": (lambda: slant(3.0), 1.0, "rattle", 1e-2, 2),
              "stuck block": (lambda: slope(0.3, 0.5)[0], 1.0, "rattle", 1e-2, 0),
              "rod landing on one end, stuck": (lambda: dropped_rod(0.8, [1.2, 0.7, 0.0]), 0.3, "yoshida4", 1e-2, 1),
              "rod landing on one end, sliding": (lambda: dropped_rod(0.2, [3.0, 1.5, 0.0]), 0.6, "rattle", 5e-3, 2),
              "pendulum swinging into the ground": (swing, 1.5, "rattle", 5e-3, 3)}


@pytest.mark.parametrize("name", list(FIXED_STEP))
def test_friction_on_rattle_and_its_compositions_runs_on_the_core_as_the_reference_does(name):
    # the core's RATTLE kicks with the sliding contacts' friction, implicit in the second kick, with the slip reference
    # set at each step's start, as the reference's (measured: event times and states within 3e-14)
    make, t_end, method, dt, n_events = FIXED_STEP[name]
    assert ln.Simulator(make(), method, dt=dt).backend == "native"
    reference, native = _both(make(), t_end, method, n_out=11, dt=dt)
    assert len(reference.events) == n_events
    _agree(reference, native, min_events=n_events)
    if name == "block thrown along the ground":
        # a constant deceleration mu g, which RATTLE integrates exactly: the stop at v / (mu g) to round-off
        assert [(e.kind, e.index) for e in native.events] == [("stick", 0)]
        assert native.events[0].t == pytest.approx(3.0 / (0.4 * G), abs=1e-14)
