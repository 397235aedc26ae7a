"""A frictionless ground on the native core (linknet_core/native/src/stages/ropes.c) against the numpy reference
(linknet_core.dynamics.unilateral, linknet_core.integrators.events) and against closed forms.

The core takes each contact as the reference's ModeDynamics does: a unilateral link from the mass to a virtual anchor
placed straight above it before every evaluation (its unit vector the plane's normal, its term of (26) (n . U_k)^2 /
R_c, its gap the height above the plane), the position projection repeated with the anchors re-placed until the
contacts are on the plane. The rules (the LCPs with the contacts after the ropes, the events 'contact' and 'release',
Newton's restitution and the rest rule) are the reference's, so the two agree to round-off, within the bounds of
tests/native/test_native_ropes.py (EVENT_TIME_TOL, STATE_TOL; measured here: event times 1e-15 s, positions 2e-15 m,
impulses 5e-15 N s). The same holds on RATTLE and its compositions, whose stages place the anchors as the
reference's do."""
from __future__ import annotations

import numpy as np
import pytest
from test_native_ropes import _agree, _both  # tests/native is on sys.path (pytest puts a test file's folder there)
from ropes.rope_references import G

import linknet_core as ln
from linknet_core.dynamics.unilateral import UnilateralDynamics


def dropped(height, e, vx=0.5, mass=2.0, friction=0.0):
    return ln.Scene.from_dict({"name": "ball", "gravity": [0, 0, -G],
                               "masses": [{"name": "ball", "position": [0, 0, height], "mass": mass,
                                           "velocity": [vx, 0, 0]}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": e,
                                          "friction": friction}})


def falling_chain(N=20, a=0.05, m=0.05):
    return ln.Scene.from_dict({"name": "falling_chain", "gravity": [0, 0, -G],
                               "masses": [{"name": f"c{k}", "position": [0, 0, a * (k + 1)], "mass": m}
                                          for k in range(N)],
                               "links": [{"a": k + 1, "b": k + 2, "kind": "rope"} for k in range(N - 1)],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1]}})


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_a_bouncing_ball_bounces_at_the_closed_form_times_with_the_closed_form_impulses_as_the_reference_does(method):
    h, e, m = 1.0, 0.5, 2.0
    reference, native = _both(dropped(h, e, mass=m), 2.0, method)
    assert ln.Simulator(dropped(h, e), method).backend == "native"
    _agree(reference, native, min_events=5)
    # closed form: t_1 = sqrt(2 h / g), v_1 = sqrt(2 g h); each rebound at e v_k flies 2 e v_k / g; the impulse is
    # m (1 + e) v_k
    t, v = np.sqrt(2 * h / G), np.sqrt(2 * G * h)
    for event in native.events[:6]:
        assert event.kind == "contact" and event.index == 0
        assert abs(event.t - t) <= 1e-12
        assert abs(event.impulse - m * (1 + e) * v) <= 1e-10 * m * v
        t, v = t + 2 * e * v / G, e * v
    # between bounces a parabola along z, and the uniform motion along x throughout
    assert np.abs(native.X[:, 0, 0] - 0.5 * native.t).max() <= 1e-13


def test_a_rope_chain_falling_onto_the_ground_lands_mass_by_mass_as_the_reference_and_the_closed_form_say():
    N, a, m = 20, 0.05, 0.05
    reference, native = _both(falling_chain(N, a, m), 0.5, n_out=11)
    _agree(reference, native, min_events=2 * N - 1)
    contacts = [e for e in native.events if e.kind == "contact"]
    assert [e.index for e in contacts] == list(range(N))
    k = np.arange(1, N + 1)
    assert np.abs(np.array([e.t for e in contacts]) - np.sqrt(2 * k * a / G)).max() < 1e-14
    assert np.abs(np.array([e.impulse for e in contacts]) - m * np.sqrt(2 * G * k * a)).max() < 1e-14


def swing_into_the_ground():
    return ln.Scene.from_dict({"name": "swing", "gravity": [0, 0, -G],
                               "masses": [{"name": "pivot", "position": [0, 0, 0.8], "fixed": True},
                                          {"name": "bob", "position": [1.0, 0, 0.8], "mass": 1.0}],
                               "links": [{"a": 1, "b": 2, "kind": "rope"}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1]}})


def test_a_pendulum_swinging_into_the_ground_lands_slides_and_is_jerked_off_it_as_the_reference_does():
    reference, native = _both(swing_into_the_ground(), 1.5, n_out=151)
    _agree(reference, native, min_events=6)
    assert [e.kind for e in native.events] == ["contact", "slack", "taut", "release", "contact", "slack"]


def _dumbbell():
    # a rod landing flat on both ends at once (two simultaneous contacts coupled by the rod), bouncing with e = 0.6
    return ln.Scene.from_dict({"name": "dumbbell", "gravity": [0, 0, -G],
                               "masses": [{"name": "a", "position": [0, 0, 0.5], "mass": 1.0, "velocity": [0.2, 0, 0]},
                                          {"name": "b", "position": [1, 0, 0.5], "mass": 2.0, "velocity": [0.2, 0, 0]}],
                               "links": [{"a": 1, "b": 2}],
                               "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": 0.6}})


def _net_on_a_slope():
    # four masses in a loop of ropes braced by one rod, dropped onto a slanted ground (restitution 0.2)
    free = [[1, 1, 0.3], [2, 1, 0.5], [2, 2, 0.2], [1, 2, 0.4]]
    masses = [{"name": f"m{i + 1}", "position": p, "mass": m}
              for i, (p, m) in enumerate(zip(free, (0.8, 1.3, 1.9, 0.6)))]
    links = [{"a": 1, "b": 2, "kind": "rope", "length": 1.2}, {"a": 2, "b": 3, "kind": "rope", "length": 1.1},
             {"a": 3, "b": 4, "kind": "rope", "length": 1.3}, {"a": 4, "b": 1, "kind": "rope", "length": 1.05},
             {"a": 1, "b": 3}]
    return ln.Scene.from_dict({"name": "net", "gravity": [0, 0, -G], "masses": masses, "links": links,
                               "ground": {"point": [0, 0, -0.5], "normal": [0.1, 0.05, 1.0], "restitution": 0.2}})


@pytest.mark.parametrize("make,method", [(_dumbbell, "dop853"), (_net_on_a_slope, "dop853"),
                                         (_net_on_a_slope, "dopri5")])
def test_several_contacts_at_once_and_ropes_on_a_slope_give_the_references_events_and_states(make, method):
    reference, native = _both(make(), 2.0, method)
    _agree(reference, native, min_events=15)
    assert sum(e.kind == "contact" for e in native.events) >= 5


def test_the_grounds_normal_forces_and_impulses_are_the_references():
    # a mass on a tilted plane, sliding at g sin(alpha) with the normal force m g cos(alpha); the chain partly landed:
    # each resting mass's normal force as the reference's LCP gives it
    alpha, m = 0.3, 1.5
    n = [np.sin(alpha), 0.0, np.cos(alpha)]
    tilted = ln.Scene.from_dict({"name": "tilted", "gravity": [0, 0, -G],
                                 "masses": [{"name": "m", "position": [0, 0, 0], "mass": m}],
                                 "ground": {"point": [0, 0, 0], "normal": n}})
    sim = ln.Simulator(tilted, "dop853", rtol=1e-10, error_estimate=False, backend="native")
    sim.advance(0.7)
    assert not sim.integrator.events
    along = np.array([np.cos(alpha), 0.0, -np.sin(alpha)])
    assert abs(sim.state.X[0] @ along - 0.5 * G * np.sin(alpha) * 0.7 ** 2) <= 1e-12
    normal = sim.integrator.ground_outputs(sim.state.X, sim.state.U)[2]
    assert abs(normal[0] - m * G * np.cos(alpha)) <= 1e-12 * m * G

    chain = falling_chain()
    dyn = UnilateralDynamics(chain)
    runs = {backend: ln.Simulator(chain, "dop853", rtol=1e-10, error_estimate=False, backend=backend)
            for backend in ("numpy", "native")}
    for sim in runs.values():
        sim.advance(0.25)
    native = runs["native"]
    assert np.abs(native.state.X - runs["numpy"].state.X).max() <= 1e-13
    T, _, N_native = native.integrator.ground_outputs(native.state.X, native.state.U)
    T_ref, N_ref = dyn.resolve(native.state.X, native.state.U)
    # the masses landed by 0.25 s (sqrt(2 k a / g) < 0.25: six) rest with their ropes slack, each on its own weight
    assert np.count_nonzero(N_ref) == 6
    assert np.abs(N_native[:6] - 0.05 * G).max() <= 1e-12
    assert np.abs(N_native - N_ref[chain.free_indices]).max() <= 1e-12 * float(np.abs(N_ref).max())
    assert np.abs(T - T_ref).max() <= 1e-12 * max(1.0, float(np.abs(T_ref).max()))
    # the ground's impulses over the advance: each landing's m v_k, summed per mass (the FMU's Jground[k])
    landed = [e for e in native.integrator.events if e.kind == "contact"]
    J = native.integrator.ground_impulses()
    for e in landed:
        assert abs(J[e.index] - e.impulse) <= 1e-15
    assert np.count_nonzero(J) == len(landed)


def test_a_hook_driven_by_inputs_drops_its_load_onto_the_ground_as_the_reference_does():
    # a hook holding two bobs on ropes above a ground (restitution 0.4): jerked up, swung, dropped (the lower bob lands,
    # its rope goes slack, the upper one jerks it), stopped; events, states and the hook's impulses per interval
    scene = ln.Scene.from_dict({"name": "hook", "gravity": [0, 0, -G],
                                "masses": [{"name": "hook", "position": [0, 0, 0], "driven": True,
                                            "motion": {"kind": "input"}},
                                           {"name": "a", "position": [0, 0, -0.5], "mass": 0.5},
                                           {"name": "b", "position": [0, 0, -1.5], "mass": 2.0}],
                                "links": [{"a": 1, "b": 2, "length": 0.5, "kind": "rope"},
                                          {"a": 2, "b": 3, "length": 1.0, "kind": "rope", "restitution": 0.3}],
                                "ground": {"point": [0, 0, -1.8], "normal": [0, 0, 1], "restitution": 0.4}})
    holds = [((0, 0, 0), (0, 0, 1.0)), (None, (0.8, 0, 0.2)), (None, (0, 0, -2.5)), (None, (0, 0, 0))]
    runs = {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, "dop853", rtol=1e-10, error_estimate=False, backend=backend)
        assert sim.backend == backend
        out = []
        for i, (P, V) in enumerate(holds):
            P = sim.state.X[0] if P is None else np.array(P, float)
            sim.advance(0.25 * (i + 1), anchors=(np.array([P]), np.array([V], float), np.zeros((1, 3))))
            out.append((sim.state.X.copy(), sim.anchor_report()["impulse"].copy()))
        runs[backend] = (out, list(sim.integrator.events))
    (ref, ref_events), (nat, nat_events) = runs["numpy"], runs["native"]
    assert ("contact", 2) in [(e.kind, e.index) for e in ref_events]
    assert [(e.kind, e.index) for e in nat_events] == [(e.kind, e.index) for e in ref_events]
    for a, b in zip(ref_events, nat_events):
        assert abs(a.t - b.t) <= 1e-12 and abs(a.impulse - b.impulse) <= 1e-12 * max(1.0, a.impulse)
    for (X_ref, J_ref), (X_nat, J_nat) in zip(ref, nat):
        assert np.abs(X_nat - X_ref).max() <= 1e-12 and np.abs(J_nat - J_ref).max() <= 1e-12


def test_a_snapshot_of_a_run_on_the_ground_continues_identically_and_a_reset_runs_the_same_events_again():
    sim = ln.Simulator(falling_chain(8), "dop853", rtol=1e-10, error_estimate=False, backend="native")
    sim.advance(0.15)  # two masses landed (sqrt(2 k a / g) < 0.15)
    snapshot = sim.get_state()
    sim.advance(0.3)
    X, events = sim.state.X.copy(), list(sim.integrator.events)
    assert [e.kind for e in events].count("contact") == 8
    sim.set_state(snapshot)
    assert [e.kind for e in sim.integrator.events].count("contact") == 2
    sim.advance(0.3)
    assert np.array_equal(sim.state.X, X) and sim.integrator.events == events
    sim.reset()
    assert sim.integrator.events == []
    sim.advance(0.15)
    sim.advance(0.3)
    assert np.array_equal(sim.state.X, X) and sim.integrator.events == events


FIXED_STEP = {"bouncing ball": (lambda: dropped(1.0, 0.5), 1.5, "rattle", 1e-2, 10),
              "pendulum swinging into the ground": (swing_into_the_ground, 1.5, "rattle", 5e-3, 6),
              "net on a slope": (_net_on_a_slope, 1.0, "rattle", 5e-3, 15),
              "dumbbell": (_dumbbell, 1.0, "yoshida4", 1e-2, 6)}


@pytest.mark.parametrize("name", list(FIXED_STEP))
def test_a_ground_on_rattle_and_its_compositions_runs_on_the_core_as_the_reference_does(name):
    # auto takes it to the core; the core's RATTLE stages place the contacts' anchors and
    # re-place them in the position stage as the reference's ModeDynamics does, so the two agree to round-off
    # (measured: event times 4e-13 s, positions 3e-14 m)
    make, t_end, method, dt, n_events = FIXED_STEP[name]
    assert ln.Simulator(make(), method, dt=dt).backend == "native"
    reference, native = _both(make(), t_end, method, n_out=11, dt=dt)
    _agree(reference, native, min_events=n_events)


def test_a_rope_chain_falling_onto_the_ground_lands_at_the_closed_form_times_on_rattle():
    # a free fall, which RATTLE integrates exactly: mass k lands at sqrt(2 k a / g) with the impulse m sqrt(2 g k a)
    # (each contact's time by Newton on the step's length, to round-off) however long the steps
    N, a, m = 20, 0.05, 0.05
    run = ln.simulate(falling_chain(N, a, m), 0.5, "rattle", dt=2e-3, n_out=2, error_estimate=False)
    contacts = [e for e in run.events if e.kind == "contact"]
    assert [e.index for e in contacts] == list(range(N))
    k = np.arange(1, N + 1)
    assert np.abs(np.array([e.t for e in contacts]) - np.sqrt(2 * k * a / G)).max() < 1e-14
    assert np.abs(np.array([e.impulse for e in contacts]) - m * np.sqrt(2 * G * k * a)).max() < 1e-14
    assert np.abs(run.X[-1, :, 2]).max() < 1e-15 and np.abs(run.U[-1]).max() < 1e-15  # all landed by 0.45 s, at rest
