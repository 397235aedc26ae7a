"""The native core (linknet_core/native) against the numpy reference path: the same methods on the same
scenes give the same trajectories and tensions to round-off, on every scene class (chain, tree, general,
planar and tilted-planar, drag, springs, inputs, a singular passage, redundant and static scenes), and the
native advance is all or nothing."""
from __future__ import annotations

import ctypes
import math
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.scene import builders
from linknet_core.dynamics.tensions import reference_tensions
from linknet_core.clib import library
from scene_builders import parallelogram, rotated, rotation

MODELS = Path(__file__).resolve().parents[2] / "models"
FIXED = [("rattle", {"dt": 2e-3}), ("yoshida4", {"dt": 2e-3}), ("suzuki4", {"dt": 4e-3})]
ADAPTIVE = [("dopri5", {"rtol": 1e-7}), ("dop853", {"rtol": 1e-9})]


def _pair(scene, method, kw, **options):
    return (ln.Simulator(scene, method=method, backend="native", **kw, **options),
            ln.Simulator(scene, method=method, backend="numpy", **kw, **options))


def _run_both(scene, method, kw, times, F=None, **options):
    native, reference = _pair(scene, method, kw, **options)
    assert native.backend == "native" and reference.backend == "numpy"
    for t in times:
        native.advance(t, F)
        reference.advance(t, F)
    return native, reference


def _assert_same(native, reference, F=None, atol=1e-10):
    scale = max(1.0, float(np.abs(reference.state.X).max()))
    np.testing.assert_allclose(native.state.X, reference.state.X, rtol=0, atol=atol * scale)
    np.testing.assert_allclose(native.state.U, reference.state.U, rtol=0, atol=atol * 100 * scale)
    T_native, T_reference = native.outputs(F)["T"], reference.outputs(F)["T"]
    np.testing.assert_allclose(T_native, T_reference, rtol=1e-8, atol=1e-8 * max(1.0, np.abs(T_reference).max()))


@pytest.mark.parametrize("mirror,which", [
    (library.Model, library.MODEL_STRUCT), (library.Method, library.METHOD_STRUCT),
    (library.RigidModel, library.RIGID_MODEL_STRUCT), (library.Data, library.DATA_STRUCT),
    (library.EnergyTerms, library.ENERGY_TERMS_STRUCT)])
def test_the_ctypes_structs_have_the_c_layout(mirror, which):
    """ctypes lays out each mirror itself; the C compiler's offsets and sizes come from the library's table."""
    fields = library.struct_fields(which)
    assert [name for name, _ in mirror._fields_] == [f.name for f in fields]
    assert [getattr(mirror, f.name).offset for f in fields] == [f.offset for f in fields]
    assert ctypes.sizeof(mirror) == library.struct_size(which)


SHIPPED = ["pendulum", "double_pendulum", "chain_10", "chain_100", "four_bar", "net_10x10"]


@pytest.mark.parametrize("name", SHIPPED)
@pytest.mark.parametrize("method,kw", FIXED + ADAPTIVE, ids=[m for m, _ in FIXED + ADAPTIVE])
def test_shipped_scenes_agree_with_the_reference(name, method, kw):
    scene = ln.load_scene(MODELS / f"{name}.json")
    native, reference = _run_both(scene, method, kw, [0.02, 0.06])
    assert native.integrator.stats.as_dict() == reference.integrator.stats.as_dict()
    _assert_same(native, reference)


@pytest.mark.parametrize("method,kw", [("yoshida6", {"dt": 5e-3}), ("yoshida8", {"dt": 5e-3})])
def test_high_order_compositions_agree_with_the_reference(method, kw):
    native, reference = _run_both(ln.load_scene(MODELS / "double_pendulum.json"), method, kw, [0.1, 0.3])
    _assert_same(native, reference)


def _springs_drag_scene():
    """Drag on some masses (one anchored: no effect), springs with and without damping, a constant force."""
    d = builders.chain(8).to_dict()
    d["masses"][0]["drag"] = 3.0
    d["masses"][3]["drag"] = 0.4
    d["masses"][6]["drag"] = 0.1
    d["masses"][5]["force"] = [0.2, 0.0, 0.5]
    d["springs"] = [{"a": 1, "b": 9, "stiffness": 30.0, "rest_length": 0.8, "damping": 0.7},
                    {"a": 3, "b": 7, "stiffness": 5.0, "rest_length": 0.2}]
    return ln.Scene.from_dict(d)


@pytest.mark.parametrize("method,kw", FIXED[:2] + ADAPTIVE, ids=[m for m, _ in FIXED[:2] + ADAPTIVE])
def test_drag_springs_and_inputs_agree_with_the_reference(method, kw):
    scene = _springs_drag_scene()
    F = np.zeros((scene.K, 3))
    F[4] = [0.3, 0.0, -0.2]
    native, reference = _run_both(scene, method, kw, [0.05, 0.1, 0.2], F)
    _assert_same(native, reference, F)


@pytest.mark.parametrize("method,kw", [("rattle", {"dt": 2e-3}), ("dop853", {"rtol": 1e-9})])
def test_planar_scenes_run_in_2d_with_the_reference_trajectory(method, kw):
    for scene in (ln.load_scene(MODELS / "chain_10.json"), rotated(ln.load_scene(MODELS / "chain_10.json"),
                                                                   rotation(), "tilted")):
        native, reference = _run_both(scene, method, kw, [0.05, 0.1])
        assert native.integrator.model.plane is not None and native.integrator.data.struct.planar == 1
        _assert_same(native, reference)


def test_an_out_of_plane_input_moves_the_run_to_3d_for_good():
    scene = ln.load_scene(MODELS / "chain_10.json")
    native, reference = _pair(scene, "rattle", {"dt": 2e-3})
    F = np.zeros((scene.K, 3))
    F[-1, 1] = 0.5  # off the x-z plane
    for sim in (native, reference):
        sim.advance(0.02)
        sim.advance(0.04, F)
        sim.advance(0.06)
    assert native.integrator.data.struct.planar == 0
    assert abs(native.state.X[-1, 1]) > 1e-6  # it really left the plane
    _assert_same(native, reference)


def _tree():
    """A Y: one anchored stem, a free fork mass with three branches (a tree, not a chain)."""
    return ln.Scene.from_dict({
        "name": "tree", "gravity": [0, 0, -9.81],
        "masses": [{"name": "top", "position": [0, 0, 0], "fixed": True},
                   {"name": "fork", "mass": 1.0, "position": [0.5, 0, 0]},
                   {"name": "a", "mass": 0.5, "position": [1.0, 0, 0]},
                   {"name": "b", "mass": 0.7, "position": [0.5, 0.5, 0]},
                   {"name": "c", "mass": 0.3, "position": [0.5, 0, -0.5], "velocity": [0.2, 0, 0]}],
        "links": [{"a": "top", "b": "fork"}, {"a": "fork", "b": "a"}, {"a": "fork", "b": "b"},
                  {"a": "fork", "b": "c"}]})


@pytest.mark.parametrize("method,kw", [("rattle", {"dt": 2e-3}), ("dopri5", {"rtol": 1e-8})])
def test_trees_take_the_sparse_ldl_path_and_agree(method, kw):
    native, reference = _run_both(_tree(), method, kw, [0.1, 0.3])
    assert native.integrator.model.solver == "ldl"
    _assert_same(native, reference)


@pytest.mark.parametrize("method,rtol,tol", [("dop853", 1e-10, 1e-9), ("dopri5", 1e-8, 1e-7)])
def test_a_singular_passage_follows_the_exact_motion(method, rtol, tol):
    """An output point exactly at the flat position: the native core meets the vanishing pivot, takes the
    minimum-norm path there, and follows the exact motion through it and the next collinear position."""
    speed, t_end = 5.0, 1.5
    scene = parallelogram(speed)
    t_flat = math.radians(120.0) / speed
    native, reference = _run_both(scene, method, {"rtol": rtol}, [t_flat, t_end])
    th = math.radians(60.0) + speed * t_end
    exact = 0.4 * np.array([math.cos(th), 0.0, math.sin(th)])
    for sim in (native, reference):
        assert np.linalg.norm(sim.state.X[1] - exact) < tol
        assert np.linalg.norm(sim.state.X[2] - exact - [1.0, 0.0, 0.0]) < tol
    assert np.max(np.abs(native.state.X - reference.state.X)) < 1e-10
    assert native.integrator.data._ptr.contents.__class__ is library.Data


def test_the_tensions_at_the_flat_position_are_the_minimum_norm_ones():
    scene = parallelogram()
    sim = ln.Simulator(scene, method="dop853", rtol=1e-10)
    sim.advance(math.radians(120.0) / 5.0)
    X, U = sim.state.X, sim.state.U
    T = sim.outputs()["T"]
    np.testing.assert_allclose(T, reference_tensions(scene, X, U, sim.dyn.forces(X, U)),
                               rtol=1e-6, atol=1e-6 * np.abs(T).max())


def test_a_static_redundant_truss_reports_minimum_norm_tensions():
    scene = ln.load_scene(MODELS / "redundant_truss.json")
    sim = ln.Simulator(scene, method="rattle", dt=1e-3)
    assert sim.specialisation.kind == "static"
    sim.advance(0.5)
    np.testing.assert_array_equal(sim.state.X, scene.X0)
    T = sim.outputs()["T"]
    reference = reference_tensions(scene, scene.X0, np.zeros_like(scene.X0),
                                               sim.dyn.forces(scene.X0, np.zeros_like(scene.X0)))
    np.testing.assert_allclose(T, reference, rtol=1e-9, atol=1e-9 * np.abs(reference).max())


def test_a_failed_advance_leaves_state_and_internals_as_they_were():
    scene = ln.load_scene(MODELS / "chain_10.json")
    sim = ln.Simulator(scene, method="dop853", rtol=1e-8, max_steps_per_call=3)
    sim.advance(1e-3)
    before = sim.get_state()
    with pytest.raises(ln.SolverError, match="more than 3 steps"):
        sim.advance(1.0)
    after = sim.get_state()
    assert after["state"].t == before["state"].t
    np.testing.assert_array_equal(after["state"].X, before["state"].X)
    np.testing.assert_array_equal(after["state"].U, before["state"].U)
    assert after["integrator"] == before["integrator"]
    sim.max_steps_per_call = 10**6
    sim.advance(0.01)  # and it goes on from there


def test_snapshots_replay_bit_for_bit():
    scene = ln.load_scene(MODELS / "four_bar.json")
    sim = ln.Simulator(scene, method="dopri5", rtol=1e-7)
    sim.advance(0.1)
    snap = sim.get_state()
    sim.advance(0.2)
    X_first = sim.state.X.copy()
    sim.set_state(snap)
    sim.advance(0.2)
    np.testing.assert_array_equal(sim.state.X, X_first)
    sim.reset()
    assert sim.state.t == 0.0
    np.testing.assert_array_equal(sim.state.X, scene.X0)


@pytest.mark.parametrize("name", ["chain_10", "four_bar", "net_10x10", "redundant_truss"])
def test_reported_outputs_agree_with_the_reference(name):
    """T and the anchor reactions (the force the network exerts on each anchor) at the same state."""
    scene = ln.load_scene(MODELS / f"{name}.json")
    native, reference = _pair(scene, "rattle", {"dt": 2e-3})
    F = np.zeros((scene.K, 3))
    F[scene.free_indices[-1]] = [0.3, -0.2, 0.5]
    native.advance(0.02, F)
    reference.set_state(dict(reference.get_state(), state=native.state.copy()))
    a, b = native.outputs(F), reference.outputs(F)
    scale = np.abs(b["T"]).max()
    np.testing.assert_allclose(a["T"], b["T"], rtol=0, atol=1e-9 * scale)
    np.testing.assert_allclose(a["Freact"], b["Freact"], rtol=0, atol=1e-9 * scale)
    assert a["Freact"].shape == (scene.fixed_indices.size, 3)


def test_a_changed_state_is_taken_by_both_backends_and_an_edit_in_place_is_refused():
    """The native core keeps the state in its data between advances: the arrays it hands out are read-only, so an
    edit in place fails loudly instead of being left behind, and replacing them moves the run as on numpy."""
    scene = ln.load_scene(MODELS / "pendulum.json")
    ends = {}
    for backend in ("numpy", "native"):
        sim = ln.Simulator(scene, method="dop853", rtol=1e-10, backend=backend)
        if backend == "native":
            with pytest.raises(ValueError):
                sim.state.X[1, 0] += 0.1
        sim.advance(0.1)
        X = sim.state.X.copy()
        X[1] = X[0] + (X[1] - X[0]) @ np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # 90 degrees
        sim.state.X = X
        sim.state.U = np.zeros_like(X)
        sim.advance(0.3)
        ends[backend] = sim.state.X
    np.testing.assert_allclose(ends["native"], ends["numpy"], atol=1e-9)
    # released from the turned position, not from where the run was: far from an untouched run's end
    untouched = ln.Simulator(scene, method="dop853", rtol=1e-10)
    untouched.advance(0.3)
    assert np.abs(ends["native"] - untouched.state.X).max() > 1e-2
