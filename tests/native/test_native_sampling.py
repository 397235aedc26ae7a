"""simulate's output loop in one call into C (ln_sample) against the same run sample by sample through the public
stepping interface (advance, then outputs), and what is kept per scene object (the native model, the initial
state) against a scene built afresh: two independent routes to the same samples, bit for bit."""
from __future__ import annotations

import gc
import weakref

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.native.model import native_model
from linknet_core.structure.topology import analyse


def step_by_step(scene, times, method, forces=None, **settings):
    """X, U, T at ``times`` by one advance and one outputs call per sample (the loop simulate runs in Python for
    a callable input)."""
    sim = ln.Simulator(scene, method=method, **settings)
    X, U, T = [], [], []
    for i, t in enumerate(times):
        if i > 0:
            sim.advance(t, forces)
        out = sim.outputs(forces)
        X.append(out["X"]), U.append(out["U"]), T.append(out["T"])
    return np.array(X), np.array(U), np.array(T)


@pytest.mark.parametrize("name,method,settings", [("pendulum", "dop853", {"rtol": 1e-8}),
                                                  ("chain_10", "rattle", {"dt": 1e-3}),
                                                  ("net_10x10", "dopri5", {"rtol": 1e-6})])
def test_samples_in_one_call_are_the_samples_step_by_step(shipped_scene, name, method, settings):
    scene = shipped_scene(name)
    forces = np.zeros((scene.K, 3))
    forces[-1] = [0.3, -0.2, 0.1]  # a held input, with its direct feedthrough into T
    res = ln.simulate(scene, 0.5, method=method, n_out=26, forces=forces, progress=False, **settings)
    X, U, T = step_by_step(scene, res.t, method, forces, **settings)
    assert np.array_equal(res.X, X) and np.array_equal(res.U, U) and np.array_equal(res.T, T)
    # and the Python loop of a callable input giving the same held force
    again = ln.simulate(scene, 0.5, method=method, n_out=26, forces=lambda t: forces, progress=False, **settings)
    assert np.array_equal(again.X, res.X) and np.array_equal(again.T, res.T)


def test_a_failed_sample_says_why_as_a_failed_advance_does(shipped_scene):
    scene = shipped_scene("pendulum")
    huge = np.zeros((scene.K, 3))
    huge[1] = [1e90, 0.0, 0.0]
    with pytest.raises(ln.SolverError) as in_one_call:
        ln.simulate(scene, 0.1, method="rattle", dt=1e-3, n_out=3, forces=huge, progress=False)
    sim = ln.Simulator(scene, method="rattle", dt=1e-3)
    with pytest.raises(ln.SolverError) as stepping:
        sim.advance(0.05, huge)
    assert str(in_one_call.value) == str(stepping.value)
    assert "largest input force was F[2,1]" in str(in_one_call.value)


def test_what_is_kept_per_scene_is_shared_and_dropped_with_the_scene(shipped_scene):
    scene = ln.Scene.from_dict(shipped_scene("chain_10").to_dict())  # a scene object of this test's own
    a, b = ln.Simulator(scene, method="rattle", dt=1e-3), ln.Simulator(scene, method="dop853", rtol=1e-6)
    assert a.integrator.model is b.integrator.model is native_model(scene, analyse(scene))
    assert a.state.X is not b.state.X and np.array_equal(a.state.X, b.state.X)
    # a fresh copy of the scene takes its own model and the same initial state, and runs the same
    fresh = ln.Scene.from_dict(scene.to_dict())
    c = ln.Simulator(fresh, method="rattle", dt=1e-3)
    assert c.integrator.model is not a.integrator.model
    a.advance(0.1), c.advance(0.1)
    assert np.array_equal(a.state.X, c.state.X) and np.array_equal(a.state.U, c.state.U)
    # nothing kept refers back to the scene: it goes when its last user goes
    gone = weakref.ref(scene)
    del a, b, scene
    gc.collect()
    assert gone() is None
