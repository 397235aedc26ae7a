"""Planar scenes in the compiled kernels run in 2-D (linknet_core.compiled_kernels_2d): the same physics as the
3-D numpy path, and an input force or a state off the plane is never flattened into it."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
from linknet_core import builders, compiled
from linknet_core.analysis import analyze_scene

PLANAR = ["pendulum", "double_pendulum", "chain_10", "chain_100", "four_bar"]
FIXED = [("rattle", {"dt": 1e-3}), ("yoshida4", {"dt": 2e-3})]
ADAPTIVE = [("dopri5", {"rtol": 1e-8}), ("dop853", {"rtol": 1e-10})]


def _kernel(sim):
    return sim.integrator._kernel


def _rotation(ax=0.5, az=0.3):
    cx, sx, cz, sz = np.cos(ax), np.sin(ax), np.cos(az), np.sin(az)
    return np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])


def _rotated(scene, Q, name):
    """The same scene turned rigidly by Q (positions, velocities, gravity, constant forces): a tilted plane."""
    d = scene.to_dict()
    for m in d["masses"]:
        for key in ("position", "velocity", "force"):
            if key in m:
                m[key] = (Q @ np.asarray(m[key], float)).tolist()
    d["gravity"] = (Q @ np.asarray(d.get("gravity", [0, 0, -9.81]), float)).tolist()
    d["name"] = name
    return ln.Scene.from_dict(d)


def _springs_drag_scene():
    """Drag on some masses (one of them anchored: no effect), springs with and without damping, a constant
    force, all in the x-z plane."""
    d = builders.chain(8).to_dict()
    d["masses"][0]["drag"] = 3.0  # the anchor
    d["masses"][3]["drag"] = 0.4
    d["masses"][6]["drag"] = 0.1
    d["masses"][5]["force"] = [0.2, 0.0, 0.5]
    d["springs"] = [{"a": 1, "b": 9, "stiffness": 30.0, "rest_length": 0.8, "damping": 0.7},
                    {"a": 3, "b": 7, "stiffness": 5.0, "rest_length": 0.2}]
    return ln.Scene.from_dict(d)


def test_generated_planar_module_is_in_sync_with_the_kernels():
    assert compiled.PLANAR_MODULE.read_text() == compiled.planar_module_source(), (
        "linknet_core/compiled_kernels_2d.py is stale: run python -m linknet_core.compiled --write-planar")


@pytest.mark.parametrize("name", PLANAR)
@pytest.mark.parametrize("method,kw", FIXED + ADAPTIVE)
def test_planar_scenes_run_in_2d_with_the_numpy_trajectory(name, method, kw):
    scene = builders.shipped_scenes()[name]
    planar_input = np.zeros((scene.K, 3))
    planar_input[:, 0] = np.linspace(-0.3, 0.3, scene.K)  # in the x-z plane of the shipped scenes
    runs = {}
    for backend in ("numpy", "compiled"):
        sim = ln.Simulator(scene, method=method, backend=backend, **kw)
        for t in (0.1, 0.2):
            sim.advance(t, planar_input)
        runs[backend] = sim
    a, b = runs["numpy"].state, runs["compiled"].state
    assert _kernel(runs["compiled"]).is_planar_scene and _kernel(runs["compiled"]).planar  # ran in 2-D
    assert np.max(np.abs(a.X - b.X)) < 1e-11 * max(np.abs(a.X).max(), 1.0)
    assert np.max(np.abs(a.U - b.U)) < 1e-9 * max(np.abs(a.U).max(), 1.0)
    if ln.METHODS[method].adaptive:
        assert runs["numpy"].integrator.stats.as_dict() == runs["compiled"].integrator.stats.as_dict()
    # the plane's coordinate (y) is exactly where it started: the 2-D run maps back exactly
    assert np.array_equal(b.X[:, 1], scene.X0[:, 1]) and not b.U[:, 1].any()
    res = ln.Dynamics(scene)
    assert np.abs(res.constraint_residual(b.X)).max() < 1e-12 and np.abs(res.velocity_residual(b.X, b.U)).max() < 1e-11


@pytest.mark.parametrize("method,kw", [("rattle", {"dt": 1e-3}), ("dop853", {"rtol": 1e-11})])
def test_tilted_plane_runs_in_2d_and_is_the_rotated_trajectory(method, kw):
    """A scene in a tilted plane (orthonormal in-plane basis, no exact reduction): the 2-D run agrees with
    the 3-D numpy run of the same scene and with the axis-aligned scene's run turned by the same rotation."""
    base = builders.double_pendulum()
    Q = _rotation()
    scene = _rotated(base, Q, "tilted")
    assert abs(compiled.plane_normal(scene) @ (Q @ [0, 1, 0])) == pytest.approx(1.0, abs=1e-12)
    # the structure analysis recognises the tilted plane too (linknet analyze reports it)
    assert abs(ln.Dynamics(scene).structure.planar_normal @ (Q @ [0, 1, 0])) == pytest.approx(1.0, abs=1e-12)
    off_plane = _rotated(builders.double_pendulum(), _rotation(), "tilted")
    d = off_plane.to_dict()
    d["masses"][2]["velocity"] = (np.asarray(d["masses"][2].get("velocity", [0, 0, 0])) + 1e-6 * (Q @ [0, 1, 0])).tolist()
    assert ln.Dynamics(ln.Scene.from_dict(d)).structure.planar_normal is None  # 1e-6 m/s off the plane: not planar
    sims = {b: ln.Simulator(scene, method=method, backend=b, **kw) for b in ("numpy", "compiled")}
    aligned = ln.Simulator(base, method=method, backend="compiled", **kw)
    for t in (0.25, 0.5):
        for sim in (*sims.values(), aligned):
            sim.advance(t)
    assert _kernel(sims["compiled"]).planar
    X2d = sims["compiled"].state.X
    tol = 1e-11 if method == "rattle" else 1e-10  # adaptive: the error norm is per coordinate, not rotation-invariant
    assert np.max(np.abs(X2d - sims["numpy"].state.X)) < tol
    assert np.max(np.abs(X2d - aligned.state.X @ Q.T)) < tol
    nrm = Q @ [0, 1, 0]
    assert np.max(np.abs((X2d - X2d[0]) @ nrm)) < 1e-14  # still in the plane


@pytest.mark.parametrize("tilted", [False, True])
def test_planar_right_hand_side_equals_numpy(tilted):
    """The 2-D right-hand side (drag, springs, dampers, input forces in the plane) against Dynamics.accelerations."""
    scene = _springs_drag_scene()
    Q = _rotation() if tilted else np.eye(3)
    if tilted:
        scene = _rotated(scene, Q, "tilted_springs")
    dyn = ln.Dynamics(scene)
    rng = np.random.default_rng(7)
    free = (~scene.fixed)[:, None]
    paths = [compiled.CompiledScene(dyn), compiled.CompiledScene(dyn, use_chain=False)]
    assert paths[0].use_chain and paths[0].is_planar_scene
    for _ in range(3):
        in_plane = Q @ np.diag([1.0, 0.0, 1.0]) @ Q.T  # projector onto the plane
        X = scene.X0 + 0.1 * rng.normal(size=scene.X0.shape) @ in_plane * free
        X, _ = dyn.project_positions(X)
        U = dyn.project_velocities(X, rng.normal(size=X.shape) @ in_plane * free)
        F_in = rng.normal(size=X.shape) @ in_plane
        acc, T = dyn.accelerations(X, U, F_in)
        for kernel in paths:
            status, acc_c, T_c = kernel.accelerations(X, U, F_in, planar=True)
            assert status == compiled.OK
            np.testing.assert_allclose(acc_c, acc, rtol=0, atol=1e-12 * np.abs(acc).max())
            np.testing.assert_allclose(T_c, T, rtol=0, atol=1e-12 * np.abs(T).max())


@pytest.mark.parametrize("method,kw", FIXED + [("dopri5", {"rtol": 1e-9})])
def test_springs_and_drag_keep_the_plane_and_the_numpy_trajectory(method, kw):
    scene = _springs_drag_scene()
    sims = {b: ln.Simulator(scene, method=method, backend=b, **kw) for b in ("numpy", "compiled")}
    for sim in sims.values():
        sim.advance(0.3)
    assert _kernel(sims["compiled"]).planar
    a, b = sims["numpy"].state, sims["compiled"].state
    assert np.max(np.abs(a.X - b.X)) < 1e-11
    assert np.max(np.abs(a.U - b.U)) < 1e-9


@pytest.mark.parametrize("method,kw", FIXED + ADAPTIVE)
@pytest.mark.parametrize("name", ["double_pendulum", "chain_10"])
def test_out_of_plane_input_force_gets_the_3d_trajectory(name, method, kw):
    """An input force with a component along the normal: that interval and every later one run on the 3-D
    kernels, and the trajectory (which leaves the plane) is the 3-D numpy path's."""
    scene = builders.shipped_scenes()[name]
    F_out = np.zeros((scene.K, 3))
    F_out[-1] = [0.1, 0.4, 0.0]  # y: out of the x-z plane
    runs = {}
    for backend in ("numpy", "compiled"):
        sim = ln.Simulator(scene, method=method, backend=backend, **kw)
        sim.advance(0.1)
        if backend == "compiled":
            assert _kernel(sim).planar
        sim.advance(0.2, F_out)
        sim.advance(0.3)  # no input: the state is off the plane now
        runs[backend] = sim
    a, b = runs["numpy"].state, runs["compiled"].state
    assert not _kernel(runs["compiled"]).planar
    assert np.abs(b.X[:, 1]).max() > 1e-4  # it did leave the plane
    assert np.max(np.abs(a.X - b.X)) < 1e-11
    assert np.max(np.abs(a.U - b.U)) < 1e-9 * max(np.abs(a.U).max(), 1.0)


def test_round_off_and_anchor_inputs_stay_in_2d_a_state_off_the_plane_does_not():
    scene = builders.double_pendulum()
    sim = ln.Simulator(scene, method="rattle", dt=1e-3)
    F = np.zeros((scene.K, 3))
    F[0] = [0.0, 5.0, 0.0]      # on the anchored pivot: no effect on the motion
    F[2] = [1.0, 1e-17, 0.0]    # round-off out of the plane
    sim.advance(0.05, F)
    assert _kernel(sim).planar and np.array_equal(sim.state.X[:, 1], scene.X0[:, 1])
    # a snapshot off the plane (as an FMU master could restore it) is not flattened into it
    off = sim.get_state()
    off["state"].U[2, 1] = 0.3
    reference = ln.Simulator(scene, method="rattle", dt=1e-3, backend="numpy")
    for s in (sim, reference):
        s.set_state(off)
        s.advance(0.1)
    assert not _kernel(sim).planar
    assert np.abs(sim.state.X[2, 1]) > 1e-3
    assert np.max(np.abs(sim.state.X - reference.state.X)) < 1e-11


def test_analyze_names_the_compiled_path():
    text = analyze_scene(builders.chain(10)).text()
    assert "compiled path" in text and "tridiagonal" in text and "2-D planar" in text
    assert "no drag or springs" in text
    net = analyze_scene(builders.net(4, 4)).text()
    assert "general sparse LDL^T" in net and "; 3-D;" in net
    springs = analyze_scene(_springs_drag_scene()).text()
    assert "drag on 2 masses" in springs and "2 springs (1 damped)" in springs
    assert "numpy path" in analyze_scene(builders.redundant_truss()).text()


def test_a_restored_snapshot_continues_on_the_kernels_it_was_taken_on():
    """get_state/set_state continue bit-identically: the snapshot says 2-D, even after an excursion off the
    plane sent the kernel to 3-D (in a tilted plane the two differ by round-off)."""
    scene = _rotated(builders.double_pendulum(), _rotation(), "tilted")
    F_out = np.zeros((scene.K, 3))
    F_out[-1] = _rotation() @ [0.0, 0.5, 0.0]  # along the normal
    straight = ln.Simulator(scene, method="dop853", rtol=1e-9)
    straight.advance(0.1)
    straight.advance(0.3)
    sim = ln.Simulator(scene, method="dop853", rtol=1e-9)
    sim.advance(0.1)
    snap = sim.get_state()
    sim.advance(0.2, F_out)
    assert not _kernel(sim).planar
    sim.set_state(snap)
    sim.advance(0.3)
    assert _kernel(sim).planar
    assert np.array_equal(sim.state.X, straight.state.X) and np.array_equal(sim.state.U, straight.state.U)


def test_anchors_of_a_tilted_plane_stay_exactly_where_they_are():
    scene = _rotated(builders.chain(10), _rotation(), "tilted_chain")
    sim = ln.Simulator(scene, method="rattle", dt=1e-3)
    for i in range(1, 21):
        sim.advance(0.01 * i)
    assert _kernel(sim).planar
    assert np.array_equal(sim.state.X[scene.fixed], scene.X0[scene.fixed]) and not sim.state.U[scene.fixed].any()
