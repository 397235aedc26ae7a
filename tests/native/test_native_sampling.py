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


def sprung_chain(shipped_scene) -> ln.Scene:
    """chain_10 with what a sample's energy sums over: springs (between masses and to the anchor), a constant
    force, viscous and quadratic drag (no potential), a tilted gravity, and a push to move."""
    data = shipped_scene("chain_10").to_dict()
    data["gravity"] = [0.5, -0.3, -9.81]
    masses = data["masses"]
    masses[3]["force"] = [0.2, 0.1, -0.4]
    masses[5]["drag"] = 0.05
    masses[7]["quadratic_drag"] = 0.02
    masses[-1]["velocity"] = [0.0, 0.3, 0.2]
    data["springs"] = [{"a": 1, "b": 5, "stiffness": 40.0, "rest_length": 0.35, "damping": 0.1},
                       {"a": 3, "b": 11, "stiffness": 7.5, "rest_length": 0.9}]
    return ln.Scene.from_dict(data)


@pytest.mark.parametrize("method,settings", [("rattle", {"dt": 1e-3}), ("dop853", {"rtol": 1e-8})])
def test_diagnostics_filled_while_sampling_are_the_reference_diagnostics(shipped_scene, method, settings):
    """Energy (kinetic, gravity, constant forces, springs), the residuals of (11) and (12) and the kinetic energy
    the native core fills as it samples, against the numpy reference's functions on the same samples and against
    the run whose samples are taken from Python (a callable input), which uses those functions."""
    from linknet_core.dynamics.forces import kinetic_energy
    from linknet_core.native.integrator import NativeIntegrator

    scene = sprung_chain(shipped_scene)
    assert scene.force_elements.count == 4
    res = ln.simulate(scene, 0.3, method=method, n_out=31, progress=False, **settings)
    sim = ln.Simulator(scene, method=method, **settings)
    assert type(sim.integrator) is NativeIntegrator and sim.diagnostics_in_one_call
    dyn = sim.dyn
    reference = (dyn.energy(res.X, res.U), dyn.constraint_residual(res.X), dyn.velocity_residual(res.X, res.U),
                 kinetic_energy(scene, res.U))
    energy_scale = float(np.max(np.abs(reference[0]))) + float(np.max(reference[3]))
    # the core sums in numpy's order (bit for bit with the numpy of this writing); a sum in another order may
    # differ in the last bits of the largest term
    eps = np.finfo(float).eps
    for got, want, scale in zip((res.energy, res.residual, res.velocity_residual, res.kinetic), reference,
                                (energy_scale, 1.0, float(np.abs(res.U).max()), energy_scale)):
        assert got.shape == want.shape == (31,)
        np.testing.assert_allclose(got, want, rtol=0, atol=16 * eps * scale)
    assert res.kinetic[-1] > 0.01 * energy_scale and res.residual.max() > 0  # the run moved and the checks see it
    looped = ln.simulate(scene, 0.3, method=method, n_out=31, progress=False,  # a callable input: the Python loop
                         forces=lambda t: np.zeros((scene.K, 3)), **settings)
    assert np.array_equal(looped.X, res.X)
    for field in ("energy", "residual", "velocity_residual", "kinetic"):
        np.testing.assert_allclose(getattr(res, field), getattr(looped, field), rtol=0,
                                   atol=16 * eps * max(energy_scale, 1.0))


@pytest.mark.parametrize("t_end,n", [(2.0, 2), (2.0, 201), (0.3, 31), (1e-300, 7), (7.77, 1000), (1e6, 3)])
def test_output_times_are_linspace(t_end, n):
    from linknet_core.simulator.simulator import _output_times

    assert np.array_equal(_output_times(t_end, n), np.linspace(0.0, t_end, n))


def test_a_scene_may_be_given_as_the_path_of_its_file(tmp_path):
    from pathlib import Path

    models = Path(ln.__file__).resolve().parent.parent / "models"
    scene = ln.load_scene(models / "pendulum.json")
    by_object = ln.simulate(scene, 0.5, method="dop853", rtol=1e-8, n_out=5, progress=False)
    for path in (str(models / "pendulum.json"), models / "pendulum.json"):
        by_path = ln.simulate(path, 0.5, method="dop853", rtol=1e-8, n_out=5, progress=False)
        assert np.array_equal(by_path.X, by_object.X) and np.array_equal(by_path.energy, by_object.energy)
        sim = ln.Simulator(path, method="rattle", dt=1e-3)
        sim.advance(0.01)
        assert sim.scene.K == scene.K and sim.state.t == 0.01
    missing = tmp_path / "nowhere.json"
    for call in (lambda s: ln.simulate(s, 1.0), lambda s: ln.Simulator(s)):
        with pytest.raises(ln.SceneError, match="cannot read scene file .*nowhere.json"):
            call(missing)
        for bad, name in ((42, "int"), (None, "NoneType"), ({"masses": []}, "dict"), (b"models/pendulum.json", "bytes")):
            with pytest.raises(ln.SolverError, match=f"scene must be a Scene or the path of a scene file .*got {name}"):
                call(bad)
