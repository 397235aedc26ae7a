"""The compiled step loop runs the same algorithm as the numpy RATTLE path: same trajectories to the
projection tolerance, the same constraint guarantees, and a hand-back to the numpy path where it cannot go."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
from linknet_core import builders


@pytest.mark.parametrize("name", ["double_pendulum", "chain_100", "four_bar", "spinning_tetrahedron", "net_10x10"])
@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_compiled_loop_matches_numpy_path(name, method):
    scene = builders.shipped_scenes()[name]
    rng = np.random.default_rng(5)
    F = rng.normal(size=(scene.K, 3)) * 0.1
    a = ln.simulate(scene, 0.05, method=method, dt=1e-3, n_out=3, backend="numpy", forces=F)
    b = ln.simulate(scene, 0.05, method=method, dt=1e-3, n_out=3, backend="compiled", forces=F)
    scale = np.abs(a.X).max()
    # the two differ only by the order of floating-point sums and where Newton stops (1e-14 relative)
    assert np.max(np.abs(a.X - b.X)) < 1e-12 * max(scale, 1.0)
    assert np.max(np.abs(a.U - b.U)) < 1e-10 * max(np.abs(a.U).max(), 1.0)
    assert b.residual.max() < 1e-12 and b.velocity_residual.max() < 1e-12


def test_compiled_loop_handles_springs_drag_and_inputs_like_the_numpy_path():
    d = builders.chain(12).to_dict()
    d["masses"][5]["drag"] = 0.4
    d["springs"] = [{"a": 1, "b": 13, "stiffness": 30.0, "rest_length": 0.8, "damping": 0.7}]
    scene = ln.Scene.from_dict(d)
    a = ln.simulate(scene, 0.2, dt=5e-4, n_out=3, backend="numpy")
    b = ln.simulate(scene, 0.2, dt=5e-4, n_out=3, backend="compiled")
    assert np.max(np.abs(a.X - b.X)) < 1e-12


def test_redundant_scenes_take_the_numpy_path():
    scene = builders.redundant_truss()
    sim = ln.Simulator(scene, dt=1e-3)
    sim.advance(0.01)
    assert sim.state.t == 0.01
    with pytest.raises(ln.SolverError, match="does not handle redundant scenes"):
        ln.Simulator(scene, dt=1e-3, backend="compiled").advance(0.01)


def test_casadi_rhs_kernel_gives_the_numpy_trajectory():
    scene = builders.shipped_scenes()["double_pendulum"]
    a = ln.simulate(scene, 0.5, method="dop853", rtol=1e-10, n_out=3)
    b = ln.simulate(scene, 0.5, method="dop853", rtol=1e-10, n_out=3, rhs_kernel="casadi")
    if b.stats["rhs_kernel"] != "casadi":
        pytest.skip("no C compiler: the casadi kernel could not be built")
    assert a.stats["steps"] == b.stats["steps"]
    assert np.max(np.abs(a.X - b.X)) < 1e-12
