"""Input-driven anchors with ropes: the anchor's held motion changes at a communication point, and the jump is an
impact like any rope event (events.EventHandling.anchor_jump). Checked against closed forms of a bob of mass m on
a rope of length R hanging at rest from an anchor that the inputs move at a constant speed v from t = 0:

* jerked up (V = +v): the rope is taut, the inelastic jerk gives the bob the anchor's velocity (impulse m v on the
  bob, -m v on the anchor), and it rides along R below the anchor;
* dropped (V = -v): the rope goes slack at once (no impulse), the bob falls freely, z = -R - g t^2 / 2, while the
  anchor is at -v t: the rope is taut again at t* = 2 v / g, where the bob's -2 v jumps to the anchor's -v (impulse
  m v up), and from there it rides along R below the anchor."""
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fmu_harness import FMU_CLIENT_LIB, build_cached, run_client  # noqa: E402

M, R, G, V = 0.5, 1.0, 9.81, 2.0


SCENE = {"name": "bob_on_input_anchor", "gravity": [0.0, 0.0, -G],
         "masses": [{"name": "hook", "position": [0.0, 0.0, 0.0], "driven": True, "motion": {"kind": "input"}},
                    {"name": "bob", "position": [0.0, 0.0, -R], "mass": M}],
         "links": [{"a": "hook", "b": "bob", "length": R, "kind": "rope"}]}


def bob_on_input_anchor() -> ln.Scene:
    return ln.Scene.from_dict(SCENE)


def _run(v, t_end, settings, steps=10):
    sim = ln.Simulator(bob_on_input_anchor(), error_estimate=False, **settings)
    times = np.linspace(0.0, t_end, steps + 1)
    impulses = []
    for t0, t1 in zip(times[:-1], times[1:]):
        P = np.array([[0.0, 0.0, -v * t0]])
        sim.advance(t1, anchors=(P, np.array([[0.0, 0.0, -v]]), np.zeros((1, 3))))
        impulses.append(sim.anchor_report()["impulse"].copy())
    return sim, impulses


SETTINGS = [{"method": "dop853", "rtol": 1e-10}, {"method": "rattle", "dt": 1e-3}]


@pytest.mark.parametrize("settings", SETTINGS)
def test_an_anchor_jerked_up_lifts_the_bob_with_an_inelastic_jerk(settings):
    sim, impulses = _run(-V, 0.5, settings)  # the anchor moves at +V (up)
    X, U = sim.state.X, sim.state.U
    assert np.allclose(U[1], [0.0, 0.0, V], atol=1e-9)
    assert np.allclose(X[1], X[0] + [0.0, 0.0, -R], atol=1e-8)
    assert np.allclose(X[0], [0.0, 0.0, 0.5 * V], atol=1e-15)
    assert np.allclose(impulses[0], [[0.0, 0.0, -M * V]], atol=1e-9)  # the rope pulls the hook down
    assert all(np.all(j == 0.0) for j in impulses[1:])  # no jump after the first
    taut = [e for e in sim.integrator.events if e.kind == "taut"]
    assert len(taut) == 1 and taut[0].t == 0.0 and taut[0].impulse == pytest.approx(M * V, rel=1e-9)


@pytest.mark.parametrize("settings", SETTINGS)
def test_a_dropped_anchor_leaves_the_rope_slack_until_the_free_fall_catches_up(settings):
    t_star = 2.0 * V / G
    t_end = 0.6
    assert t_end > t_star
    sim, impulses = _run(V, t_end, settings)  # the anchor moves at -V (down)
    assert np.all(impulses[0] == 0.0)  # going slack takes no impulse
    events = sim.integrator.events
    kinds = [(e.kind, e.t) for e in events]
    assert kinds[0] == ("slack", 0.0), kinds
    taut = [e for e in events if e.kind == "taut"]
    assert len(taut) == 1, kinds
    assert taut[0].t == pytest.approx(t_star, abs=1e-9)
    assert taut[0].impulse == pytest.approx(M * V, rel=1e-7)
    X, U = sim.state.X, sim.state.U
    assert np.allclose(U[1], [0.0, 0.0, -V], atol=1e-7)
    assert np.allclose(X[1], [0.0, 0.0, -V * t_end - R], atol=1e-7)



def test_simulate_with_the_anchor_held_from_the_start_reports_the_state_after_the_jerk():
    """simulate(anchors=) holds the anchor's motion from t = 0: its first sample is the state after the jerk (the bob
    at the anchor's +v), taken by the event integrator's own jump on a snapshot that the run then repeats."""
    hold = (np.zeros((1, 3)), np.array([[0.0, 0.0, V]]), np.zeros((1, 3)))
    res = ln.simulate(bob_on_input_anchor(), 0.5, method="dop853", rtol=1e-10, n_out=3, anchors=hold,
                      error_estimate=False)
    assert np.allclose(res.U[0, 1], [0.0, 0.0, V], atol=1e-9)
    assert np.allclose(res.X[-1, 1], [0.0, 0.0, 0.5 * V - R], atol=1e-8)
    taut = [e for e in res.events if e.kind == "taut"]
    assert len(taut) == 1 and taut[0].t == 0.0, res.events


@pytest.mark.parametrize("v", [V, -V], ids=["dropped", "jerked_up"])
def test_the_fmu_takes_the_anchors_input_jumps_as_rope_events(v, tmp_path_factory):
    """The pythonfmu FMU driven through fmpy, the master setting the anchor's P and V at every communication point
    (0.1 s): dropped, Jrope[1] is m v in the step that holds t* = 2 v / g and 0 in the others, Jreact[1,3] -m v
    there (the jerk pulls the hook down as it pulls the bob up) and 0 in the others (going slack takes none), the bob at -R - g t^2 / 2 before t* and R below the anchor after; jerked up, Jreact[1,3] is -m v and
    Jrope[1] m v in the first step, 0 after, and the bob rides R below the anchor."""
    folder = tmp_path_factory.mktemp("rope_input_anchor")
    path = folder / "bob_on_input_anchor.json"
    path.write_text(json.dumps(SCENE))
    fmu = build_cached(folder, str(path))
    out = run_client(FMU_CLIENT_LIB + f"""
f = Fmu({str(fmu)!r})
f.init(start={{"tolerance": 1e-10}}, strings={{"integrator": "dop853"}})
rows = []
for i in range(6):
    t = i * 0.1
    f.set({{"P[1,3]": -{v!r} * t, "V[1,3]": -{v!r}}})
    f.step(t, 0.1)
    rows.append(f.get(["Jrope[1]", "Jreact[1,3]", "X[2,3]", "slack[1]"]))
save(rows=np.array(rows))
""", folder)
    J_rope, J_react, z, slack = out["rows"].T
    t_end = 0.1 * np.arange(1, 7)
    if v > 0:
        t_star = 2 * v / G
        holds = (t_end - 0.1 < t_star) & (t_star <= t_end)
        assert holds.sum() == 1
        assert J_rope[holds][0] == pytest.approx(M * v, rel=1e-7) and np.all(J_rope[~holds] == 0.0)
        # the jerk pulls the hook down along the rope (straight down at t*) as it pulls the bob up: -m v
        assert J_react[holds][0] == pytest.approx(-M * v, rel=1e-7) and np.all(J_react[~holds] == 0.0)
        before = t_end < t_star
        assert np.allclose(z[before], -R - 0.5 * G * t_end[before] ** 2, atol=1e-9) and np.all(slack[before] == 1)
        assert np.allclose(z[~before], -v * t_end[~before] - R, atol=1e-7) and np.all(slack[~before] == 0)
    else:
        assert J_rope[0] == pytest.approx(M * -v, rel=1e-9) and np.all(J_rope[1:] == 0.0)
        assert J_react[0] == pytest.approx(M * v, rel=1e-9) and np.all(J_react[1:] == 0.0)
        assert np.allclose(z, -v * t_end - R, atol=1e-8) and np.all(slack == 0)
