"""The compiled step loop runs the same algorithm as the numpy RATTLE path: same trajectories to the
projection tolerance, the same constraint guarantees, and a hand-back to the numpy path where it cannot go."""
from __future__ import annotations

from pathlib import Path

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


@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_a_step_the_compiled_loop_cannot_take_goes_to_numpy_and_the_loop_resumes(method):
    """When the compiled loop stops inside step j of an interval (a projection it cannot converge), steps
    0..j-1 are kept (recomputed to the same bits), step j alone runs on the numpy path and the compiled loop
    takes the rest: no step lost or repeated, and the partial state of the failed step is never used. Here
    the failure is injected at step 8 of 20 (a hard step on a real scene, e.g. the whipping tip of a
    1000-link chain, is too slow for a unit test); the result must be the uninterrupted run's."""
    from linknet_core import compiled

    scene = builders.shipped_scenes()["chain_10"]
    reference = ln.Simulator(scene, method=method, dt=1e-3)
    reference.advance(0.02)
    sim = ln.Simulator(scene, method=method, dt=1e-3)
    kernel = sim.integrator._kernel
    real_advance, calls = kernel.advance, []

    def fails_inside_step_8_once(X, U, n, h, gammas, F, tol):
        calls.append(n)
        if len(calls) == 1:
            _, Xp, Up = real_advance(X, U, 7, h, gammas, F, tol)
            kernel.completed_steps = 7
            return compiled.PROJECTION_FAILED, Xp + 0.1, Up - 0.1  # a partial, wrong state inside step 8
        return real_advance(X, U, n, h, gammas, F, tol)

    kernel.advance = fails_inside_step_8_once
    sim.advance(0.02)
    assert calls == [20, 7, 12]  # the interval, the 7 completed steps again, the 12 after the numpy step
    assert sim.integrator.compiled_fallbacks == 1
    assert np.max(np.abs(sim.state.X - reference.state.X)) < 1e-13
    assert np.max(np.abs(sim.state.U - reference.state.U)) < 1e-11


def _scenes_for_outputs():
    scenes = [ln.load_scene(p) for p in sorted((Path(__file__).resolve().parents[1] / "models").glob("*.json"))]
    d = builders.chain(12).to_dict()
    d["masses"][5]["drag"] = 0.4
    d["springs"] = [{"a": 1, "b": 13, "stiffness": 30.0, "rest_length": 0.8, "damping": 0.7}]
    return scenes + [ln.Scene.from_dict(d)]


@pytest.mark.parametrize("method", ["rattle", "dop853"])
def test_reported_tensions_and_anchor_reactions_match_the_numpy_path(method):
    # outputs() solves (25)-(26) in one compiled call where the compiled kernels take the scene: the same
    # tensions as the numpy path's solve at the same state, and the anchors' rows of C^T T
    from linknet_core import compiled

    for scene in _scenes_for_outputs():
        kw = {"rtol": 1e-9} if method == "dop853" else {"dt": 1e-3}
        sim = ln.Simulator(scene, method=method, **kw)
        F = np.zeros((scene.K, 3))
        F[scene.free_indices[-1]] = [0.3, -0.2, 0.4]
        sim.advance(0.03, F)
        out = sim.outputs(F)
        X, U = sim.state.X, sim.state.U
        scale = max(float(np.abs(out["T"]).max(initial=0.0)), 1.0)
        if sim.specialisation.kind == "none":
            assert bool(sim._compiled_tensions) == compiled.supports(sim.dyn), scene.name
            T_numpy = sim.dyn.tensions(X, U, F)
            assert np.max(np.abs(out["T"] - T_numpy), initial=0.0) <= 1e-12 * scale, scene.name
        reactions = sim.dyn.link_forces(X, out["T"])[scene.fixed]
        assert out["Freact"].shape == reactions.shape
        assert np.max(np.abs(out["Freact"] - reactions), initial=0.0) <= 1e-13 * scale, scene.name


def test_reported_tensions_at_a_singular_configuration_are_the_minimum_norm_ones():
    # the parallelogram four-bar at its flat position: A of (25) is singular, the compiled solve declines
    # and the numpy path's minimum-norm tensions (31) are reported
    from linknet_core import compiled

    scene = builders.four_bar(ground=1.0, crank=0.4, coupler=1.0, rocker=0.4, crank_angle_deg=60.0,
                              crank_speed=5.0, gravity=(0.0, 0.0, 0.0), name="parallelogram")
    sim = ln.Simulator(scene, method="dop853", rtol=1e-10)
    sim.advance(np.radians(120.0) / 5.0)
    X, U = sim.state.X, sim.state.U
    T = sim.outputs()["T"]
    assert sim._compiled_tensions.accelerations(X, U, None)[0] != compiled.OK  # the vanishing pivot
    assert np.all(np.isfinite(T))
    assert np.array_equal(T, sim.dyn.tensions(X, U, None))
    assert sim.dyn.solver.singular_events >= 1
