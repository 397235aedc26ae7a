"""Driven anchors answer bad input with a clear error naming the mass (or the anchor input variable) and the rule
broken: the scene's "driven"/"motion" fields, and Simulator.advance/outputs(anchors=) on both backends (which
stay usable afterwards)."""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from contract_support import ROOT
import linknet_core as ln
from linknet_core.scene import builders

HOOK = 'mass 1 ("hook")'
CRANE = {"name": "crane", "masses": [{"name": "hook", "position": [0, 0, 0], "driven": True},
                                     {"name": "bob", "mass": 1.0, "position": [1, 0, 0]}], "links": [{"a": 1, "b": 2}]}


def _crane(**hook):
    """The crane scene with the hook's entry changed (a value None removes the field)."""
    data = json.loads(json.dumps(CRANE))
    entry = data["masses"][0]
    entry.update(hook)
    for key in [k for k, v in entry.items() if v is None]:
        del entry[key]
    return data


@pytest.mark.parametrize("hook,words", [
    ({"motion": {"kind": "spin"}}, "motion kind must be one of 'input', 'velocity', 'sine', 'waypoints', got 'spin'"),
    ({"motion": {"velocity": [1, 0, 0]}}, "motion kind must be one of"),
    ({"motion": "fast"}, "motion must be an object"),
    ({"motion": {"kind": "velocity", "velocity": [1, 0, 0], "speed": 3}}, "unknown field(s) ['speed']"),
    ({"motion": {"kind": "velocity"}}, "motion velocity is missing"),
    ({"motion": {"kind": "velocity", "velocity": [1, 2]}}, "motion velocity must be a list of 3 numbers"),
    ({"motion": {"kind": "velocity", "velocity": [1, "a", 0]}}, "motion velocity must be a list of 3 numbers"),
    ({"motion": {"kind": "velocity", "velocity": [1, math.nan, 0]}}, "motion velocity must be finite"),
    ({"motion": {"kind": "sine", "amplitude": [1, 0, 0]}}, "motion frequency is missing"),
    ({"motion": {"kind": "sine", "amplitude": [1, 0], "frequency": [1, 0, 0]}},
     "motion amplitude must be a list of 3 numbers"),
    ({"motion": {"kind": "sine", "amplitude": [1, 0, 0], "frequency": [-1, 0, 0]}},
     "motion frequency must not be negative (Hz), got -1 on axis 1"),
    ({"motion": {"kind": "waypoints", "waypoints": []}}, "waypoints must be a non-empty list of [t, x, y, z]"),
    ({"motion": {"kind": "waypoints", "waypoints": [[1, 0, 0]]}}, "waypoint 1 must be [t, x, y, z] (4 numbers)"),
    ({"motion": {"kind": "waypoints", "waypoints": [[1, 0, "x", 0]]}}, "waypoint 1 coordinate 2 must be a number"),
    ({"motion": {"kind": "waypoints", "waypoints": [[0, 1, 0, 0]]}},
     "waypoint 1 time 0 must be later than 0 (the anchor's scene position): times strictly increase"),
    ({"motion": {"kind": "waypoints", "waypoints": [[1, 0, 0, 0], [0.5, 1, 0, 0]]}},
     "waypoint 2 time 0.5 must be later than 1 (waypoint 1): times strictly increase"),
    ({"motion": {"kind": "waypoints", "waypoints": [[1, 0, 0, 0], [1, 1, 0, 0]]}},
     "waypoint 2 time 1 must be later than 1"),
    ({"fixed": False}, "\"fixed\": false contradicts \"driven\": true"),
    ({"velocity": [1, 0, 0]}, "its velocity comes from its motion, so it cannot have a \"velocity\""),
    ({"driven": None, "motion": {"kind": "velocity", "velocity": [1, 0, 0]}},
     "has a \"motion\" but is not driven; add \"driven\": true"),
    ({"driven": "yes"}, "driven must be a JSON boolean"),
])
def test_bad_driven_anchor_in_a_scene_is_named_with_its_rule(hook, words):
    with pytest.raises(ln.SceneError) as err:
        ln.Scene.from_dict(_crane(**hook))
    message = str(err.value)
    assert HOOK in message and words in message, message


def test_the_cli_names_a_bad_motion_without_a_traceback(tmp_path):
    path = tmp_path / "crane.json"
    path.write_text(json.dumps(_crane(motion={"kind": "waypoints", "waypoints": [[1, 0, 0, 0], [0.5, 1, 0, 0]]})))
    proc = subprocess.run([sys.executable, "-m", "linknet_core.cli", "simulate", str(path), "--t-end", "0.1"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    assert f'{HOOK} motion waypoint 2 time 0.5 must be later than 1' in proc.stderr
    assert "Traceback" not in proc.stderr


# ---- Simulator.advance / outputs with anchors= --------------------------------------------------------------------
Z = np.zeros((1, 3))


def _raises(t):
    raise RuntimeError("the trolley's encoder is lost")


def _wrong_shape(t):
    return Z, np.zeros((2, 3)), Z


def _non_finite(t):
    return Z, np.array([[0.0, math.nan, 0.0]]), Z


@pytest.mark.parametrize("backend", ["native", "numpy"])
@pytest.mark.parametrize("anchors,words", [
    ((np.zeros((2, 3)), Z, Z), f"anchors P must have shape (1, 3) (one row per input-driven anchor: {HOOK}), "
                               "got (2, 3)"),
    ((Z, Z, np.zeros(3)), "anchors A must have shape (1, 3)"),
    ((Z, Z), "anchors must be (P, V, A)"),
    ("hook up", "anchors must be (P, V, A)"),
    ((Z, np.array([[0.0, math.inf, 0.0]]), Z), f"anchor input V[1,2] of {HOOK} is inf m/s: it must be finite"),
    ((np.array([[math.nan, 0.0, 0.0]]), Z, Z), f"anchor input P[1,1] of {HOOK} is nan m: it must be finite"),
    ((Z, Z, np.array([[0.0, 0.0, 1e200]])), f"anchor input A[1,3] of {HOOK} is 1e+200 m/s2: it must be finite and "
                                            "below 1e+100"),
    (_wrong_shape, "the anchors' motion callable returned V of shape (2, 3) at t = 0.0; expected (1, 3)"),
    (_non_finite, f"the anchors' motion callable returned V = nan m/s on axis 2 of {HOOK} at t = 0.0: it must be "
                  "finite"),
], ids=["P rows", "A shape", "two arrays", "a string", "V inf", "P nan", "A huge", "callable shape",
        "callable nan"])
def test_bad_anchor_input_is_named_and_the_simulator_stays_usable(anchors, words, backend):
    sim = ln.Simulator(ln.Scene.from_dict(CRANE), method="rattle", dt=1e-2, backend=backend)
    with pytest.raises(ln.SolverError) as err:
        sim.advance(0.1, anchors=anchors)
    assert words in str(err.value), str(err.value)
    assert sim.state.t == 0.0
    with pytest.raises(ln.SolverError):
        sim.outputs(anchors=anchors)
    sim.advance(0.1)  # still usable: the hook stands at its scene position, the bob swings from it
    assert sim.state.t == 0.1 and np.array_equal(sim.state.X[0], [0.0, 0.0, 0.0])


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_a_failing_motion_callable_is_reported_with_its_error(backend):
    """What the user's callable raised, with the time it was asked for; the advance is undone."""
    sim = ln.Simulator(ln.Scene.from_dict(CRANE), method="rattle", dt=1e-2, backend=backend)
    calls = []

    def late_failure(t):
        calls.append(t)
        if len(calls) > 3:
            raise ValueError("no trolley data after the first calls")
        return Z, Z, Z
    with pytest.raises(ln.SolverError) as err:
        sim.advance(0.1, anchors=late_failure)
    assert "no trolley data after the first calls" in str(err.value)
    assert sim.state.t == 0.0 and np.array_equal(sim.state.X, ln.Scene.from_dict(CRANE).X0)
    sim.advance(0.1)
    assert sim.state.t == 0.1


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_a_motion_callable_raising_any_exception_gives_a_solver_error(backend):
    sim = ln.Simulator(ln.Scene.from_dict(CRANE), method="rattle", dt=1e-2, backend=backend)
    with pytest.raises(ln.SolverError) as err:
        sim.advance(0.1, anchors=_raises)
    assert "motion callable" in str(err.value) and "the trolley's encoder is lost" in str(err.value)
    assert sim.state.t == 0.0


@pytest.mark.parametrize("backend", ["native", "numpy"])
@pytest.mark.parametrize("scene", ["no driven anchor", "driven by its own motion"])
def test_anchors_for_a_scene_without_input_driven_anchors_are_refused(scene, backend):
    if scene == "no driven anchor":
        built = builders.pendulum()
    else:
        built = ln.Scene.from_dict(_crane(motion={"kind": "velocity", "velocity": [1, 0, 0]}))
    sim = ln.Simulator(built, method="rattle", dt=1e-2, backend=backend)
    for call in (lambda: sim.advance(0.1, anchors=(Z, Z, Z)), lambda: sim.outputs(anchors=lambda t: (Z, Z, Z))):
        with pytest.raises(ln.SolverError) as err:
            call()
        assert "has no input-driven anchors" in str(err.value) and "motion kind \"input\"" in str(err.value)
    sim.advance(0.1)
    assert sim.state.t == 0.1
