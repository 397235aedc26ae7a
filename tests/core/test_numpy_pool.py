"""simulate keeps the numpy reference's Simulators too (the backend's ``reusable``): a run that takes a pooled,
reset Simulator must be the run of a new one, bit for bit, after another run of the same scene object with other
inputs and after a run that failed half-way: on a chain (fixed steps and error control), on the crane (driven
anchors: the drive's hold and jumps) and on a rope pendulum (events: the mode and the event list)."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln

FIELDS = ("t", "X", "U", "T", "energy", "residual", "velocity_residual", "kinetic", "error_estimate")


def _assert_same_run(a: ln.Result, b: ln.Result) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and np.array_equal(x, y, equal_nan=True), name
    assert (a.events is None) == (b.events is None) and (a.events is None or len(a.events) == len(b.events))
    strip = lambda stats: {k: v for k, v in stats.items() if k != "wall_time"}  # noqa: E731
    assert strip(a.stats) == strip(b.stats)


def _pooled(scene) -> list:
    pool = scene.__dict__.get("_simulate_pool", {})
    return [sim for kept in pool.values() for sim in kept]


@pytest.mark.parametrize("path, settings", [
    ("chain_10.json", {"method": "rattle", "dt": 1e-3}),
    ("chain_10.json", {"method": "dop853", "rtol": 1e-6}),
    ("crane.json", {"method": "yoshida4", "dt": 1e-3}),
    ("ropes/rope_pendulum.json", {"method": "rattle", "dt": 1e-3}),
])
def test_a_pooled_numpy_simulator_runs_as_a_new_one(models_dir, path, settings):
    scene = ln.load_scene(models_dir / path)
    push = np.zeros((scene.K, 3))
    push[-1] = (0.5, 0.2, 0.0)
    run = dict(n_out=5, progress=False, backend="numpy", **settings)
    ln.simulate(scene, 0.02, **run)  # another run first: no input force
    kept = _pooled(scene)
    assert kept and all(sim.backend == "numpy" for sim in kept)  # the run and its companion, kept

    def fails_half_way(t):
        if t > 0.01:
            raise RuntimeError("the input source went away")
        return push

    with pytest.raises(RuntimeError, match="went away"):
        ln.simulate(scene, 0.02, forces=fails_half_way, **run)
    pooled = ln.simulate(scene, 0.02, forces=push, **run)
    assert set(map(id, _pooled(scene))) == set(map(id, kept))  # the same Simulators served every run
    fresh = ln.simulate(ln.load_scene(models_dir / path), 0.02, forces=push, **run)
    _assert_same_run(pooled, fresh)
    # and it is the run from the scene's initial state, the links at their lengths (11)
    assert np.array_equal(pooled.X[0, scene.free_indices], scene.X0[scene.free_indices])
    assert pooled.residual.max() < 1e-9
