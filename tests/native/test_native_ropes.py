"""Ropes on the native core (linknet_core/native/src/stages/ropes.c) against the numpy reference's event integrator
(linknet_core.integrators.events), and against closed forms.

Both backends take the same method, steps and rules (the acceleration and impact LCPs, detection on the step's cubic
Hermite, location on the method's own step), so they agree to round-off: the solves differ (the reference factors
each mode's own network, the core the scene's with the slack ropes masked out), by ~1e-16 relative per solve. What
that leaves is bounded here by:

* event times within EVENT_TIME_TOL s: a tension's zero is located by regula falsi on the step's length to 1e-13
  relative (events.py, _to_force_root: xtol=1e-13), so two runs agree there to about 1e-13 s, and a gap's by Newton
  to 4 ulps of the gap; 1e-12 s is ten times the root find's own tolerance (measured: 6e-14 s). A rope that comes
  taut slowly has its time only as well as the positions' round-off over its approach speed allows: there the bound
  is EVENT_TIME_TOL + STATE_TOL / v, with v >= J / M (J its impulse, M the heaviest mass; measured: 1.9e-12 s for a
  jerk of 1.2e-4 N s in the net);
* positions within STATE_TOL m over runs of a few seconds at rtol 1e-10 (measured: 1.4e-14 m), the same margin,
  and four orders below the runs' own error;
* impulses and tensions within STATE_TOL relative to their size; a jerk's impulse, M v, also within what the
  approach speed gains over the time's bound, M g (EVENT_TIME_TOL + STATE_TOL / v).

The run is also checked against closed forms: a bob thrown up flies ballistically to the root of |X(t)| = R, loses
its radial velocity there with the impulse m v_r and the radial kinetic energy; two free masses on a rope thrown up
jerk where their relative motion (uniform: gravity cancels) reaches R, with the reduced mass's impulse.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from ropes.rope_references import G, ballistic, bob_scene, first_exit  # tests/ropes (tests/ is on sys.path)

import linknet_core as ln

ROOT = Path(__file__).resolve().parents[2]
EVENT_TIME_TOL = 1e-12
STATE_TOL = 1e-12


def _both(scene, t_end, method="dop853", rtol=1e-10, n_out=31, dt=None):
    step = {"dt": dt} if dt is not None else {"rtol": rtol}
    runs = {backend: ln.simulate(scene, t_end, method, n_out=n_out, error_estimate=False, backend=backend, **step)
            for backend in ("numpy", "native")}
    return runs["numpy"], runs["native"]


def _agree(reference, native, min_events=1):
    assert len(reference.events) >= min_events
    assert [(e.kind, e.index) for e in native.events] == [(e.kind, e.index) for e in reference.events]
    heaviest = float(reference.scene.mass[np.isfinite(reference.scene.mass)].max())
    for a, b in zip(reference.events, native.events):
        slow = STATE_TOL * heaviest / a.impulse if a.kind == "taut" and a.impulse > 0 else 0.0
        assert abs(a.t - b.t) <= EVENT_TIME_TOL + slow
        # the approach speed at the event moves by the acceleration (~g) times the time's uncertainty
        assert abs(a.impulse - b.impulse) <= STATE_TOL * max(1.0, abs(a.impulse)) + heaviest * G * (
            EVENT_TIME_TOL + slow)
    assert np.abs(native.X - reference.X).max() <= STATE_TOL
    assert np.abs(native.U - reference.U).max() <= 100 * STATE_TOL  # velocities: the jerks' rates divide by |d|
    assert np.array_equal(native.slack, reference.slack)
    if reference.T.size:  # a ball on the ground alone has no links
        assert np.abs(native.T - reference.T).max() <= STATE_TOL * max(1.0, float(np.abs(reference.T).max()))


@pytest.mark.parametrize("name", ["rope_pendulum", "rope_crane"])
@pytest.mark.parametrize("method,dt", [("dop853", None), ("dopri5", None), ("rattle", 1e-3), ("yoshida4", 1e-2)])
def test_the_shipped_rope_scenes_give_the_references_events_and_states_to_round_off(name, method, dt):
    scene = ln.load_scene(ROOT / "models" / "ropes" / f"{name}.json")
    reference, native = _both(scene, 3.0, method, dt=dt)
    assert ln.Simulator(scene, method, dt=dt, backend="native").backend == "native"
    _agree(reference, native, min_events=2)
    assert {"taut", "slack"} <= {e.kind for e in native.events}


def _net(slack_factor, velocity):
    """Four anchors at the corners of a 3 m square, four free masses inside joined to them and to each other; every
    link a rope but one rod (m1-m2), slack_factor times the initial distances long."""
    anchors = [[0, 0, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0]]
    free = [[1, 1, -0.3], [2, 1, -0.5], [2, 2, -0.2], [1, 2, -0.4]]
    masses = [{"name": f"A{i + 1}", "position": p, "fixed": True} for i, p in enumerate(anchors)]
    masses += [{"name": f"m{i + 1}", "position": p, "mass": m, "velocity": list(v)}
               for i, (p, m, v) in enumerate(zip(free, (0.8, 1.3, 1.9, 0.6), velocity))]
    links = []
    for a, b in [(1, 5), (2, 6), (3, 7), (4, 8), (5, 6), (6, 7), (7, 8), (8, 5)]:
        d = float(np.linalg.norm(np.subtract(masses[b - 1]["position"], masses[a - 1]["position"])))
        links.append({"a": a, "b": b, "length": d} if (a, b) == (5, 6) else
                     {"a": a, "b": b, "length": slack_factor * d, "kind": "rope"})
    return ln.Scene.from_dict({"name": "rope_net", "gravity": [0, 0, -G], "masses": masses, "links": links})


@pytest.mark.parametrize("method,dt", [("dop853", None), ("rattle", 1e-3)])
def test_a_net_thrown_into_its_ropes_gives_the_references_events_where_several_ropes_meet_at_once(method, dt):
    # ropes 4 % longer than the distances, thrown up and sideways: jerks that pull neighbours taut or slack in the
    # same instant (the impact's LCP on several touching ropes, then the mode's), slack ropes, taut again
    scene = _net(1.04, [(0, 0, 3), (0, 1, -1), (1, 0, 2), (0, 0, 4)])
    reference, native = _both(scene, 1.2, method, rtol=1e-9, n_out=61, dt=dt)
    _agree(reference, native, min_events=6)
    times = [e.t for e in native.events]
    assert len(times) > len(set(times))  # some instant changes several ropes: the LCP chose among them
    assert len({tuple(row) for row in native.slack}) >= 3


def test_a_net_hanging_taut_from_the_start_chooses_its_mode_as_the_reference_does():
    # every rope at its length at rest under gravity: the first advance's acceleration LCP on all of them
    scene = _net(1.0, [(0, 0, 0)] * 4)
    reference, native = _both(scene, 0.5, rtol=1e-10, n_out=11)
    assert [(e.kind, e.index) for e in native.events] == [(e.kind, e.index) for e in reference.events]
    assert np.array_equal(native.slack, reference.slack)
    assert np.abs(native.X - reference.X).max() <= STATE_TOL


@pytest.mark.parametrize("velocity", [(0.0, 0.0, 2.0), (0.5, 0.2, 2.0)])
def test_a_mass_in_four_redundant_ropes_gives_the_references_events_on_the_minimum_norm_path(velocity):
    # four ropes from the corners of a square to one mass, all at their length at the start: A is singular (four
    # rows, three degrees of freedom), so the modes with three or four taut ropes are solved minimum-norm (31); thrown
    # straight up, all four jerk at once (a degenerate impact LCP), thrown aslant they jerk and slacken in turn
    anchors = [(1, 1, 0), (-1, 1, 0), (-1, -1, 0), (1, -1, 0)]
    masses = [{"name": f"A{i + 1}", "position": list(p), "fixed": True} for i, p in enumerate(anchors)]
    masses.append({"name": "bob", "position": [0, 0, -1.0], "mass": 1.0, "velocity": list(velocity)})
    scene = ln.Scene.from_dict({"name": "four_ropes", "gravity": [0, 0, -G], "masses": masses,
                                "links": [{"a": i + 1, "b": 5, "length": math.sqrt(3.0), "kind": "rope"}
                                          for i in range(4)]})
    reference, native = _both(scene, 1.0, n_out=11)
    _agree(reference, native, min_events=4)


X0, V0 = np.array([0.3, 0.0, -0.4]), np.array([1.5, 0.0, 3.0])


@pytest.mark.parametrize("method,step", [("dop853", {"rtol": 1e-12}), ("rattle", {"dt": 1e-2})])
def test_a_bob_thrown_up_flies_ballistically_to_the_closed_form_root_and_loses_its_radial_kinetic_energy(method, step):
    # both methods are exact on the flight (RATTLE is velocity Verlet, exact under a constant force), so the jerk is
    # at the flight's root to round-off
    scene = bob_scene(X0, V0)
    t_star = first_exit(X0, V0, 1.0, 2.0)
    times = np.linspace(0.0, 0.95 * t_star, 11)
    sim = ln.Simulator(scene, method, backend="native", **step)
    assert sim.backend == "native"
    for t in times[1:]:
        sim.advance(t)
        X, V = ballistic(X0, V0, t)
        assert np.abs(sim.state.X[1] - X).max() <= 1e-14
        assert np.abs(sim.state.U[1] - V).max() <= 1e-14
        assert sim.outputs()["slack"][0]
    sim.advance(t_star + 0.01)
    jerk = sim.integrator.events[0]
    assert jerk.kind == "taut" and jerk.index == 0
    assert abs(jerk.t - t_star) <= 1e-14
    X, V = ballistic(X0, V0, t_star)
    e_r = X / np.linalg.norm(X)
    v_r = float(V @ e_r)
    assert abs(jerk.impulse - v_r) <= 1e-12 * abs(v_r)  # m v_r, m = 1
    # just after the jerk: the radial velocity gone, the tangential kept (the flight after it is 0.01 s of pendulum)
    after = ln.Simulator(scene, method, backend="native", **step)
    after.advance(jerk.t + 1e-9)
    U = after.state.U[1]
    assert abs(U @ e_r) <= 1e-7
    kinetic_lost = 0.5 * (V @ V) - 0.5 * (U @ U) - G * 1e-9 * U[2]
    assert abs(kinetic_lost - 0.5 * v_r * v_r) <= 1e-7


@pytest.mark.parametrize("method,dt", [("dop853", None), ("rattle", 1e-2)])
def test_two_masses_on_a_rope_thrown_up_jerk_where_their_uniform_relative_motion_reaches_the_length(method, dt):
    # gravity moves both alike: d(t) = d0 + dv t exactly, |d(t)| = R a quadratic in t; the jerk's impulse is the
    # reduced mass times the approach speed (inelastic), and the centre of mass flies on ballistically
    ma, mb, R = 1.0, 3.0, 1.0
    Xa, Xb = np.array([0.0, 0.0, 0.0]), np.array([0.4, 0.1, 0.3])
    Va, Vb = np.array([0.0, 0.5, 4.0]), np.array([2.0, -0.3, 5.0])
    scene = ln.Scene.from_dict({"name": "pair", "gravity": [0, 0, -G],
                                "masses": [{"name": "a", "position": list(Xa), "mass": ma, "velocity": list(Va)},
                                           {"name": "b", "position": list(Xb), "mass": mb, "velocity": list(Vb)}],
                                "links": [{"a": 1, "b": 2, "length": R, "kind": "rope"}]})
    d0, dv = Xb - Xa, Vb - Va
    qa, qb, qc = dv @ dv, 2 * d0 @ dv, d0 @ d0 - R * R
    t_star = (-qb + math.sqrt(qb * qb - 4 * qa * qc)) / (2 * qa)
    reference, native = _both(scene, 0.6, method, n_out=13, dt=dt)
    _agree(reference, native)
    jerk = native.events[0]
    assert jerk.kind == "taut" and abs(jerk.t - t_star) <= 1e-13
    d = d0 + dv * t_star
    v_r = float(dv @ d) / R
    assert abs(jerk.impulse - ma * mb / (ma + mb) * v_r) <= 1e-12 * v_r
    centre = (ma * native.X[:, 0] + mb * native.X[:, 1]) / (ma + mb)
    c0, w0 = (ma * Xa + mb * Xb) / (ma + mb), (ma * Va + mb * Vb) / (ma + mb)
    flight = np.array([ballistic(c0, w0, t)[0] for t in native.t])
    assert np.abs(centre - flight).max() <= 1e-13


def test_a_slack_inside_one_long_step_is_found_at_the_methods_inner_stages_as_the_reference_finds_it():
    # rope_swing at rtol 1e-3, advanced to 0.4 s and on: the tension falls through zero at 0.495 s and rises again
    # within one step, both of whose ends pull; the inner stages' tensions show it (a bob thrown aside by the rope:
    # |X_bob| < R after the slack, where a missed slack keeps it on the circle, |X_bob| = R)
    scene = ln.load_scene(ROOT / "models" / "ropes" / "rope_swing.json")
    runs = {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, "dop853", rtol=1e-3, error_estimate=False, backend=backend)
        sim.advance(0.4)
        sim.advance(0.9)
        runs[backend] = sim
    reference, native = runs["numpy"], runs["native"]
    assert [e.kind for e in reference.integrator.events] == ["slack"]
    assert [(e.kind, e.index) for e in native.integrator.events] == [("slack", 0)]
    # at rtol 1e-3 the steps are long and the round-off of the two solves grows along them (measured 1.2e-13 s and
    # 1.7e-13 m); 1e-11 keeps two orders of margin and is eight orders below a missed event's effect
    assert abs(native.integrator.events[0].t - reference.integrator.events[0].t) <= 1e-11
    assert np.abs(native.state.X - reference.state.X).max() <= 1e-11
    assert np.linalg.norm(native.state.X[1]) < 0.9


def test_the_cores_linearization_refuses_a_model_with_a_rough_ground_with_its_own_status():
    # the library refuses the outputs' linearization with friction before it asks the core; the core's own check
    # guards any other caller (its friction grips and sliding loads are not linearized there)
    from linknet_core.native.interface import NativeInterface, NativeLinearization

    data = json.loads((ROOT / "models" / "ropes" / "rope_pendulum.json").read_text())
    data.pop("fmu")
    data["ground"] = {"point": [0.0, 0.0, -5.0], "normal": [0.0, 0.0, 1.0], "friction": 0.5}
    sim = ln.Simulator(ln.Scene.from_dict(data), "dop853", backend="native")
    integrator = sim.integrator
    with pytest.raises(ln.SolverError, match="not linearizable"):
        NativeLinearization(integrator.model, integrator.data, integrator.model.scene.X0,
                            integrator.model.scene.U0, interface=NativeInterface(integrator.model))


def test_a_snapshot_continues_identically_and_a_reset_runs_the_same_events_again():
    scene = ln.load_scene(ROOT / "models" / "ropes" / "rope_pendulum.json")
    sim = ln.Simulator(scene, "dop853", rtol=1e-10, backend="native")
    sim.advance(1.0)  # taut, after one jerk
    snapshot = sim.get_state()
    sim.advance(2.5)
    X, events = sim.state.X.copy(), list(sim.integrator.events)
    assert [e.kind for e in events] == ["taut", "slack", "taut"]
    sim.set_state(snapshot)
    assert [e.kind for e in sim.integrator.events] == ["taut"]
    sim.advance(2.5)
    assert np.array_equal(sim.state.X, X) and sim.integrator.events == events
    sim.reset()
    assert sim.integrator.events == [] and sim.outputs()["slack"][0]
    sim.advance(1.0)  # the same communication points: the same steps
    sim.advance(2.5)
    assert np.array_equal(sim.state.X, X) and sim.integrator.events == events


def test_an_advance_that_fails_puts_back_the_mode_and_the_events():
    scene = ln.load_scene(ROOT / "models" / "ropes" / "rope_pendulum.json")
    sim = ln.Simulator(scene, "dop853", rtol=1e-10, backend="native")
    sim.advance(0.3)
    X, mode = sim.state.X.copy(), sim.integrator.data.link_active.copy()
    with pytest.raises(ln.SolverError):
        sim.integrator.advance(sim.state, 2.0, None, 3)  # across the jerk and the slack event in 3 steps: too few
    assert np.array_equal(sim.state.X, X) and sim.integrator.events == []
    assert np.array_equal(sim.integrator.data.link_active, mode)
    sim.advance(2.0)
    assert [e.kind for e in sim.integrator.events] == ["taut", "slack", "taut"]


def test_auto_runs_ropes_and_a_ground_on_the_native_core_on_every_method():
    scene = bob_scene(X0, V0)
    assert ln.Simulator(scene, "rattle", dt=1e-3).backend == "native"
    assert ln.Simulator(scene, "dop853").backend == "native"
    grounded = ln.Scene.from_dict({"name": "grounded", "gravity": [0, 0, -G],
                                   "masses": [{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                                              {"name": "bob", "position": list(X0), "mass": 1.0}],
                                   "links": [{"a": 1, "b": 2, "length": 1.0, "kind": "rope"}],
                                   "ground": {"point": [0, 0, -2], "normal": [0, 0, 1]}})
    assert ln.Simulator(grounded, "rattle", dt=1e-3).backend == "native"
    assert ln.Simulator(grounded, "dop853").backend == "native"


@pytest.mark.parametrize("method,step", [("dop853", {"rtol": 1e-10}), ("rattle", {"dt": 1e-3})])
def test_input_driven_anchors_jumping_under_ropes_give_the_references_events_impulses_and_states(method, step):
    # a hook driven by inputs holding two bobs on ropes in a chain; at each communication point the held motion
    # changes: jerked up (both ropes jerk, an impulse on the hook), swung sideways, dropped (slack, then taut again)
    scene = ln.Scene.from_dict({"name": "hook", "gravity": [0, 0, -G],
                                "masses": [{"name": "hook", "position": [0, 0, 0], "driven": True,
                                            "motion": {"kind": "input"}},
                                           {"name": "a", "position": [0, 0, -0.5], "mass": 0.5},
                                           {"name": "b", "position": [0, 0, -1.5], "mass": 2.0}],
                                "links": [{"a": 1, "b": 2, "length": 0.5, "kind": "rope"},
                                          {"a": 2, "b": 3, "length": 1.0, "kind": "rope", "restitution": 0.3}]})
    holds = [((0, 0, 0), (0, 0, 1.0)), (None, (0.8, 0, 0.2)), (None, (0, 0, -2.5)), (None, (0, 0, 0))]
    runs = {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, method, error_estimate=False, backend=backend, **step)
        assert sim.backend == backend
        out = []
        for i, (P, V) in enumerate(holds):
            t0, t1 = 0.25 * i, 0.25 * (i + 1)
            P = sim.state.X[0] if P is None else np.array(P, float)
            sim.advance(t1, anchors=(np.array([P]), np.array([V], float), np.zeros((1, 3))))
            out.append((sim.state.X.copy(), sim.anchor_report()["impulse"].copy()))
        runs[backend] = (out, list(sim.integrator.events))
    (ref, ref_events), (nat, nat_events) = runs["numpy"], runs["native"]
    assert len(ref_events) >= 4 and {"taut", "slack"} <= {e.kind for e in ref_events}
    assert [(e.kind, e.index) for e in nat_events] == [(e.kind, e.index) for e in ref_events]
    for a, b in zip(ref_events, nat_events):
        assert abs(a.t - b.t) <= EVENT_TIME_TOL + (STATE_TOL * 2.0 / a.impulse if a.impulse > 0 else 0.0)
        assert abs(a.impulse - b.impulse) <= 1e-9 * max(1.0, a.impulse)
    for (X_ref, J_ref), (X_nat, J_nat) in zip(ref, nat):
        assert np.abs(X_nat - X_ref).max() <= 1e-10
        assert np.abs(J_nat - J_ref).max() <= 1e-9
