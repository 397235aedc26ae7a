"""The independent index-1 reference with driven anchors (benchmarks/index1.py, written from the scene format):
Galilean invariance of a pendulum whose pivot moves at constant velocity, and agreement with linknet's default on
the shipped crane, whose trolley runs a waypoint spline (its acceleration jumps when it stops at 3 s)."""
import numpy as np

import linknet_core as ln
from benchmarks.reference import solve_index1
from benchmarks.scene_spec import SceneSpec

PENDULUM = {"name": "p", "gravity": [0, 0, -9.81],
            "masses": [{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                       {"name": "bob", "position": [0.6, 0, -0.8], "mass": 1.0}],
            "links": [{"a": 1, "b": 2, "length": 1.0}]}


def test_a_pivot_at_constant_velocity_is_the_resting_pendulum_carried_along():
    v = np.array([0.7, -0.2, 0.3])
    moving = {**PENDULUM, "masses": [{"name": "pivot", "position": [0, 0, 0], "driven": True,
                                      "motion": {"kind": "velocity", "velocity": v.tolist()}},
                                     {"name": "bob", "position": [0.6, 0, -0.8], "mass": 1.0,
                                      "velocity": v.tolist()}]}
    t = 1.3
    X_rest, U_rest, _, _ = solve_index1(SceneSpec.from_dict(PENDULUM), t, rtol=1e-12)
    X_moving, U_moving, _, _ = solve_index1(SceneSpec.from_dict(moving), t, rtol=1e-12)
    assert np.allclose(X_moving, X_rest + v * t, atol=1e-10)
    assert np.allclose(U_moving, U_rest + v, atol=1e-10)


def test_the_crane_reference_agrees_with_linknet_across_the_trolleys_stop():
    scene = ln.load_scene("models/crane.json")
    spec = SceneSpec.from_core(scene)
    t_end = 3.2  # past the last waypoint (3 s), where the trolley's acceleration jumps to zero
    X_ref, _, _, _ = solve_index1(spec, t_end, rtol=1e-12)
    X_check, _, _, _ = solve_index1(spec, t_end, rtol=1e-13)
    assert np.abs(X_ref - X_check).max() < 1e-10  # the reference converged
    assert np.allclose(X_ref[0], [3.0, 0.0, 0.0], atol=1e-14)  # the trolley at its waypoint, at rest
    run = ln.simulate(scene, t_end, method="dop853", rtol=1e-12, n_out=2)
    assert np.linalg.norm(run.X[-1] - X_ref, axis=1).max() < 1e-9
