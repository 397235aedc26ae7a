"""casadi-generated, compiled right-hand-side kernels against the numeric path of the solver."""
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.symbolic import codegen
from linknet_core.symbolic.check import sample_states
from linknet_core.symbolic.derivation import SymbolicTensionSystem

MODELS = Path(__file__).resolve().parents[2] / "models"
SCENES = sorted(MODELS.glob("*.json"))

needs_cc = pytest.mark.skipif(codegen.compiler() is None, reason="no C compiler")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("linknet-kernels")


def _in_plane(scene, dyn, X, U, F):
    """Move a sampled state into the scene's plane (and back onto (11)-(12)) for the 2-D kernel."""
    basis, origin, _ = codegen.plane_of(scene)
    P = basis @ basis.T
    X, _ = dyn.project_positions((X - origin) @ P + origin)
    return X, dyn.project_velocities(X, U @ P), F @ P


def _agree(kernel, dyn, X, U, F, rtol=1e-10):
    acc_c, T_c = kernel.accelerations(X, U, F)
    acc_n, T_n = dyn.accelerations(X, U, F)
    np.testing.assert_allclose(acc_c, acc_n, rtol=0, atol=rtol * np.abs(acc_n).max())
    np.testing.assert_allclose(T_c, T_n, rtol=0, atol=rtol * np.abs(T_n).max())
    assert np.all(acc_c[np.asarray(dyn.scene.fixed)] == 0.0)


@needs_cc
# the 10x10 net's kernel (180 links) takes ~10 s to generate and compile: CI's slow step checks it (.ci/run), make
# test every smaller scene
@pytest.mark.parametrize("path", [pytest.param(p, marks=pytest.mark.slow) if p.stem == "net_10x10" else p
                                  for p in SCENES], ids=[p.stem for p in SCENES])
def test_generated_kernel_agrees_with_numeric_path(path, cache):
    scene = ln.load_scene(path)
    dyn = ln.Dynamics(scene)
    kernel = codegen.compiled_rhs(scene, cache=cache, fallback=dyn.accelerations)
    if scene.driven.any():
        assert kernel is None  # the kernel takes no anchor motion: driven scenes stay on the numeric paths
        with pytest.raises(codegen.CodegenUnavailable, match="driven anchors"):
            codegen.compiled_rhs(scene, cache=cache, required=True)
        return
    if dyn.structure.kind == "redundant":
        assert kernel is None  # minimum-norm tensions stay on the rank-revealing numeric path
        with pytest.raises(codegen.CodegenUnavailable, match="redundant"):
            codegen.compiled_rhs(scene, cache=cache, required=True)
        return
    assert kernel is not None
    sym = SymbolicTensionSystem(scene)
    states = sample_states(scene, sym, 3, np.random.default_rng(7))
    if kernel.plane is not None:
        states = [_in_plane(scene, dyn, s.X, s.U, s.F_input) for s in states]
    else:
        states = [(s.X, s.U, s.F_input) for s in states]
    for X, U, F in [(np.array(scene.X0), np.array(scene.U0), np.zeros((scene.K, 3)))] + states:
        _agree(kernel, dyn, X, U, F)
    assert kernel.fallback_calls == 0 and kernel.calls_3d == 0


@needs_cc
def test_planar_scene_gets_a_2d_kernel_and_leaving_the_plane_uses_3d(cache):
    scene = ln.load_scene(MODELS / "double_pendulum.json")
    dyn = ln.Dynamics(scene)
    kernel = codegen.compiled_rhs(scene, cache=cache)
    assert kernel.plane is not None and kernel._primary.d == 2
    n_free = int(np.count_nonzero(~scene.fixed))
    assert kernel._primary.coordinates == kernel._primary.input_coordinates == 2 * n_free
    # anchored masses are constants of the code: moving one in the input changes nothing
    X = np.array(scene.X0)
    moved = X.copy()
    moved[scene.fixed] += 0.5 * kernel.plane[0][:, 0]     # within the plane
    np.testing.assert_array_equal(kernel.accelerations(moved, scene.U0)[0], kernel.accelerations(X, scene.U0)[0])
    # an out-of-plane velocity: the 3-D kernel takes over, results still equal the numeric path
    normal = kernel.plane[2]
    X = np.array(scene.X0)
    U = dyn.project_velocities(X, np.outer(np.arange(scene.K) % 2, normal) * (~scene.fixed)[:, None])
    assert np.abs(U @ normal).max() > 0
    _agree(kernel, dyn, X, U, np.zeros_like(X))
    assert kernel.calls_3d == 1 and kernel._variant3.d == 3


@needs_cc
def test_kernel_has_input_terms_only_for_input_masses(cache):
    scene = ln.load_scene(MODELS / "chain_10.json")
    dyn = ln.Dynamics(scene)
    tip = scene.K - 1
    kernel = codegen.compiled_rhs(scene, cache=cache, input_masses=[tip])
    assert kernel._primary.input_coordinates == kernel._primary.d  # one mass' force, nothing else
    F = np.zeros((scene.K, 3))
    F[tip] = [1.5, 0.0, -2.0]
    _agree(kernel, dyn, np.array(scene.X0), np.array(scene.U0), F)
    F[2, 0] = 1.0
    with pytest.raises(ValueError, match="mass 3"):
        kernel.accelerations(scene.X0, scene.U0, F)


@needs_cc
def test_kernels_are_cached_on_disk(cache):
    scene = ln.load_scene(MODELS / "pendulum.json")
    first = codegen.compiled_rhs(scene, cache=cache)
    second = codegen.compiled_rhs(scene, cache=cache)
    assert "compile_s" not in second.timings and second.timings["cache_hits"] == 1
    assert second.so_path == first.so_path and Path(second.so_path).exists()
    # another scene (changed mass) gets another kernel
    other = codegen.compiled_rhs(scene.with_parameters(mass=np.where(scene.fixed, 1.0, 2.0)), cache=cache)
    assert other.so_path != first.so_path


def test_no_compiler_means_numeric_path(monkeypatch):
    monkeypatch.setattr(codegen, "compiler", lambda: None)
    scene = ln.load_scene(MODELS / "pendulum.json")
    assert codegen.compiled_rhs(scene) is None
    with pytest.raises(codegen.CodegenUnavailable, match="no C compiler"):
        codegen.compiled_rhs(scene, required=True)


@needs_cc
def test_unwritable_cache_means_numeric_path(tmp_path):
    blocker = tmp_path / "not-a-directory"
    blocker.write_text("")
    scene = ln.load_scene(MODELS / "pendulum.json")
    assert codegen.compiled_rhs(scene, cache=blocker / "kernels") is None
    with pytest.raises(codegen.CodegenUnavailable, match="LINKNET_CACHE_DIR"):
        codegen.compiled_rhs(scene, cache=blocker / "kernels", required=True)


@needs_cc
def test_singular_state_goes_to_the_fallback(cache):
    scene = ln.load_scene(MODELS / "pendulum.json")
    dyn = ln.Dynamics(scene)
    calls = []

    def fallback(X, U, F):
        calls.append(1)
        return np.zeros((scene.K, 3)), np.zeros(scene.L)

    kernel = codegen.compiled_rhs(scene, cache=cache, fallback=fallback)
    X = np.array(scene.X0)
    X[~scene.fixed] = X[scene.fixed][0]          # the bob on its pivot: E = 0, A = 0
    acc, T = kernel.accelerations(X, np.zeros_like(X), None)
    assert calls and kernel.fallback_calls == 1
    kernel.fallback = None
    with pytest.raises(codegen.CodegenUnavailable, match="singular"):
        kernel.accelerations(X, np.zeros_like(X), None)
    del dyn


@needs_cc
@pytest.mark.parametrize("name", ["double_pendulum", "chain_10"])
def test_simulation_through_the_kernel_equals_the_numeric_one(name, cache):
    """DOP853 to 1 s with the compiled right-hand side: same steps, same trajectory to round-off."""
    scene = ln.load_scene(MODELS / f"{name}.json")

    class CompiledDynamics(ln.Dynamics):
        def __init__(self, scene):
            super().__init__(scene)
            self.kernel = codegen.compiled_rhs(scene, cache=cache, fallback=super().accelerations, required=True)

        def accelerations(self, X, U, F_input=None):
            self.rhs_evaluations += 1
            return self.kernel.accelerations(X, U, F_input)

    F = np.zeros((scene.K, 3))
    F[-1, 0] = 0.3                       # a held input force on the last mass
    runs = []
    for dyn in (ln.Dynamics(scene), CompiledDynamics(scene)):
        sim = ln.Simulator(scene, method="dop853", rtol=1e-10, dynamics=dyn)
        sim.advance(1.0, F)
        runs.append((sim.state.X.copy(), sim.state.U.copy(), dyn.rhs_evaluations))
    (X_n, U_n, n_n), (X_c, U_c, n_c) = runs
    assert n_c == n_n
    np.testing.assert_allclose(X_c, X_n, rtol=0, atol=1e-11)
    np.testing.assert_allclose(U_c, U_n, rtol=0, atol=1e-10)


@needs_cc
def test_kernel_with_every_force_element_in_a_tilted_plane(cache):
    """Springs (one to an anchor), drag and constant forces, all in the plane spanned by (1,1,0)/sqrt2 and
    z: the 2-D kernel works in rotated plane coordinates and matches the numeric path."""
    e = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    z = np.array([0.0, 0.0, 1.0])

    def p(a, b):
        return (a * e + b * z).tolist()

    masses = [{"name": "pivot", "position": p(0, 0), "fixed": True},
              {"name": "a", "mass": 1.0, "position": p(1, 0), "drag": 0.2, "force": p(0.5, 0.1)},
              {"name": "b", "mass": 0.7, "position": p(1, -1), "velocity": p(0.3, 0), "drag": 0.1},
              {"name": "c", "mass": 1.3, "position": p(2, -1)}]
    scene = ln.Scene.from_dict({
        "name": "tilted", "gravity": [0, 0, -9.81], "masses": masses,
        "links": [{"a": "pivot", "b": "a"}, {"a": "a", "b": "b"}, {"a": "b", "b": "c"}],
        "springs": [{"a": "pivot", "b": "c", "stiffness": 15.0, "damping": 0.4, "rest_length": 1.0},
                    {"a": "a", "b": "c", "stiffness": 3.0}]})
    dyn = ln.Dynamics(scene)
    kernel = codegen.compiled_rhs(scene, cache=cache, required=True)
    basis, origin, normal = kernel.plane
    assert kernel._primary.d == 2 and not kernel._primary.aligned
    np.testing.assert_allclose(abs(normal @ np.cross(e, z)), 1.0, atol=1e-12)
    rng = np.random.default_rng(5)
    X = np.array(scene.X0)
    for _ in range(3):
        U = dyn.project_velocities(X, np.outer(rng.standard_normal(scene.K), e) * (~scene.fixed)[:, None])
        F = np.outer(rng.standard_normal(scene.K), z) * (~scene.fixed)[:, None]
        _agree(kernel, dyn, X, U, F, rtol=1e-12)
    assert kernel.calls_3d == 0
    # a force out of the plane: the 3-D kernel takes over
    F = np.zeros((scene.K, 3))
    F[2] = np.cross(e, z)
    _agree(kernel, dyn, X, np.array(scene.U0), F)
    assert kernel.calls_3d == 1
