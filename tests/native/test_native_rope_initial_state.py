"""The initial state of a scene with ropes or a ground on the native backend is the core's (ln_rope_initial_state, the
native FMU's with changed masses or lengths), on the numpy backend the reference's (UnilateralDynamics.
initial_state's LCP): the two agree to round-off and with the closed form where the initial impact acts and where the
positions are projected, and a state neither can make consistent is refused in the reference's words on both."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln

ROUND_OFF = 1e-14
G = 9.81


def _states(data):
    scene = ln.Scene.from_dict(data)
    return [ln.Simulator(scene, "dop853", backend=backend) for backend in ("numpy", "native")]


def test_the_initial_impact_on_a_rope_at_its_length_and_a_mass_on_the_ground():
    # a bob 0.5 m from its pivot on a rope of 0.5 m, flying outward along the rope n = (0.6, 0, -0.8), and a puck on
    # the ground (z = -2) moving down into it: the inelastic impact removes the bob's radial velocity, U = v - (v.n) n,
    # and the puck's normal one, whatever the rope's and the ground's restitution
    v_bob, v_puck, n = np.array([1.5, 0.0, -3.0]), np.array([0.7, -0.2, -1.1]), np.array([0.6, 0.0, -0.8])
    data = {"name": "bob_and_puck", "gravity": [0.0, 0.0, -G],
            "masses": [{"name": "pivot", "position": [0.0, 0.0, 0.0], "fixed": True},
                       {"name": "bob", "position": [0.3, 0.0, -0.4], "mass": 1.3, "velocity": v_bob.tolist()},
                       {"name": "puck", "position": [1.0, 0.5, -2.0], "mass": 0.4, "velocity": v_puck.tolist()}],
            "links": [{"a": "pivot", "b": "bob", "length": 0.5, "kind": "rope", "restitution": 0.5}],
            "ground": {"point": [0.0, 0.0, -2.0], "normal": [0.0, 0.0, 1.0], "restitution": 0.5}}
    numpy_sim, native_sim = _states(data)
    assert (numpy_sim.backend, native_sim.backend) == ("numpy", "native")
    expected = np.array([[0.0, 0.0, 0.0], v_bob - (v_bob @ n) * n, [v_puck[0], v_puck[1], 0.0]])
    for sim in (numpy_sim, native_sim):
        np.testing.assert_allclose(sim.state.U, expected, rtol=0, atol=ROUND_OFF * 3)
        np.testing.assert_array_equal(sim.state.X, np.array([m["position"] for m in data["masses"]]))
    np.testing.assert_allclose(native_sim.state.U, numpy_sim.state.U, rtol=0, atol=ROUND_OFF * 3)


def test_a_stretched_rope_and_a_rod_projected_where_the_scene_opts_in():
    # a bob 0.55 m from its pivot on a rope of 0.5 m goes back along the rope to 0.5 m; a dumbbell's rod of 1 m with
    # its ends 1.1 m apart is shortened symmetrically (equal masses, the closest in the mass metric)
    d = np.array([0.33, 0.0, -0.44])
    data = {"name": "stretched", "gravity": [0.0, 0.0, -G], "options": {"project_initial_positions": True},
            "masses": [{"name": "pivot", "position": [0.0, 0.0, 0.0], "fixed": True},
                       {"name": "bob", "position": d.tolist(), "mass": 1.0, "velocity": [0.0, 1.0, 0.0]},
                       {"name": "a", "position": [3.0, 0.0, 0.0], "mass": 2.0, "velocity": [0.0, 0.0, 0.0]},
                       {"name": "b", "position": [4.1, 0.0, 0.0], "mass": 2.0, "velocity": [0.0, 0.0, 0.0]}],
            "links": [{"a": "pivot", "b": "bob", "length": 0.5, "kind": "rope"},
                      {"a": "a", "b": "b", "length": 1.0}]}
    numpy_sim, native_sim = _states(data)
    expected = np.array([[0.0, 0.0, 0.0], 0.5 * d / np.linalg.norm(d), [3.05, 0.0, 0.0], [4.05, 0.0, 0.0]])
    for sim in (numpy_sim, native_sim):
        assert sim.initial_report.positions_projected
        np.testing.assert_allclose(sim.state.X, expected, rtol=0, atol=ROUND_OFF * 5)
    np.testing.assert_allclose(native_sim.state.X, numpy_sim.state.X, rtol=0, atol=ROUND_OFF * 5)
    np.testing.assert_allclose(native_sim.state.U, numpy_sim.state.U, rtol=0, atol=ROUND_OFF)


def test_a_state_that_cannot_be_made_consistent_is_refused_in_the_references_words_on_both_backends():
    # a bob between two fixed pivots 3 m apart on two ropes of 1 m: stretched, and no position satisfies both
    data = {"name": "overstretched", "gravity": [0.0, 0.0, -G], "options": {"project_initial_positions": True},
            "masses": [{"name": "left", "position": [0.0, 0.0, 0.0], "fixed": True},
                       {"name": "right", "position": [3.0, 0.0, 0.0], "fixed": True},
                       {"name": "bob", "position": [1.5, 0.0, 0.0], "mass": 1.0}],
            "links": [{"a": "left", "b": "bob", "length": 1.0, "kind": "rope"},
                      {"a": "bob", "b": "right", "length": 1.0, "kind": "rope"}]}
    scene = ln.Scene.from_dict(data)
    messages = []
    for backend in ("numpy", "native"):
        with pytest.raises(ln.SceneError) as caught:
            ln.Simulator(scene, "dop853", backend=backend)
        messages.append(str(caught.value))
    assert messages[0] == messages[1]
    assert "overstretched: the initial positions cannot be projected onto the link lengths" in messages[0]
