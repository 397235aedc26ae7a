"""Fixed steps whose position stage cannot converge at full length are split into equal sub-steps (each the
whole composition) by the native advance: shipped scenes run with their default step through the whips that
stopped them, and the results still converge at the method's order as dt shrinks."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln

MODELS = Path(__file__).resolve().parents[2] / "models"


@pytest.mark.parametrize("name", ["chain_100", "net_10x10"])
def test_shipped_scenes_run_through_their_whips_at_the_default_step(name):
    scene = ln.load_scene(MODELS / f"{name}.json")
    res = ln.simulate(scene, 2.0, method="rattle", dt=1e-3, n_out=21)
    assert res.stats["split"] >= 1 and res.stats["finest_split"] >= 2
    assert float(res.residual.max()) < 1e-12  # (11) after every step, split or not
    assert float(res.velocity_residual.max()) < 1e-10
    assert "split into equal sub-steps" in res.summary()


def spinning_double_pendulum():
    """Fast enough that the coarsest steps turn the links by ~1 rad: their position stage fails at full
    length and they are split."""
    return ln.Scene.from_dict({
        "name": "spin", "gravity": [0, 0, -9.81],
        "masses": [{"name": "p", "position": [0, 0, 0], "fixed": True},
                   {"name": "a", "mass": 1.0, "position": [1, 0, 0], "velocity": [0, 0, 40]},
                   {"name": "b", "mass": 0.5, "position": [2, 0, 0], "velocity": [0, 0, 90]}],
        "links": [{"a": "p", "b": "a"}, {"a": "a", "b": "b"}]})


@pytest.mark.parametrize("backend", ["native", "numpy"])
# a coarse step that must split, and the two finest, which need no split and measure the order
@pytest.mark.parametrize("method,dts", [("rattle", [0.04, 0.00125, 0.000625]),
                                        ("yoshida4", [0.02, 0.0025, 0.00125])])
def test_split_runs_converge_at_the_method_order(method, dts, backend):
    scene = spinning_double_pendulum()
    t_end = 0.5
    reference = ln.Simulator(scene, method="dop853", rtol=1e-13, atol=1e-14)
    reference.advance(t_end)
    errors, splits = [], []
    for dt in dts:
        sim = ln.Simulator(scene, method=method, dt=dt, backend=backend)
        sim.advance(t_end)
        errors.append(np.abs(sim.state.X - reference.state.X).max())
        splits.append(sim.integrator.stats.split)
    assert splits[0] > 0 and splits[-1] == 0  # the coarse runs needed sub-steps, the fine ones do not
    order = np.log(errors[-2] / errors[-1]) / np.log(2.0)
    assert abs(order - ln.METHODS[method].order) < 0.3, (errors, splits)
    assert errors[-1] < 1e-2 * errors[0]


@pytest.mark.parametrize("method,dt", [("rattle", 0.04), ("yoshida4", 0.02)])
def test_the_numpy_reference_splits_as_the_native_core_does(method, dt):
    """Every step of these runs fails at full length; both paths split each into the same sub-steps (the bound is
    the core's ln_max_split_level), count them alike and agree to round-off."""
    scene = spinning_double_pendulum()
    final, stats = {}, {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, method=method, dt=dt, backend=backend)
        sim.advance(0.5)
        final[backend], stats[backend] = sim.state.X, sim.integrator.stats
    assert stats["numpy"] == stats["native"] and stats["numpy"].split > 0 and stats["numpy"].finest_split >= 2
    assert np.abs(final["numpy"] - final["native"]).max() < 1e-11
