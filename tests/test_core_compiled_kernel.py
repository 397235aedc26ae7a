"""The compiled right-hand side agrees with independent implementations: the numpy Dynamics path, the plain C
reference of benchmarks/c_reference (a separate implementation of (8), (9), (25), (26) by Thomas elimination),
and, for chains, its own general sparse path. No timing is asserted anywhere."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core import builders, compiled

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))  # benchmarks/ beside tests/


def _random_state(dyn, rng):
    scene = dyn.scene
    free = (~scene.fixed)[:, None]
    X = scene.X0 + 0.2 * scene.length.min() * rng.normal(size=scene.X0.shape) * free
    X, _ = dyn.project_positions(X)
    U = dyn.project_velocities(X, rng.normal(size=X.shape) * free)
    return X, U


def _two_chains_and_a_middle_anchor():
    """Three paths in one scene (two pendulum chains, one chain anchored in its middle): the chain path must
    order the links path by path."""
    masses = [{"name": "p1", "position": [0, 0, 0], "fixed": True}, {"name": "a1", "mass": 1.0, "position": [1, 0, 0]},
              {"name": "a2", "mass": 0.5, "position": [2, 0, 0.2]},
              {"name": "p2", "position": [0, 1, 0], "fixed": True}, {"name": "b1", "mass": 2.0, "position": [0, 1, -1]},
              {"name": "c0", "mass": 1.0, "position": [-1, 2, 0]}, {"name": "mid", "position": [0, 2, 0], "fixed": True},
              {"name": "c1", "mass": 0.7, "position": [1, 2, 0]}, {"name": "c2", "mass": 0.9, "position": [1, 2, -1]}]
    links = [("p1", "a1"), ("a1", "a2"), ("b1", "p2"), ("c0", "mid"), ("mid", "c1"), ("c2", "c1")]
    return ln.Scene.from_dict({"name": "three_paths", "gravity": [0, 0, -9.81], "masses": masses,
                               "links": [{"a": a, "b": b} for a, b in links]})


SCENES = dict(builders.shipped_scenes(), three_paths=_two_chains_and_a_middle_anchor(),
              free_rope=builders.chain(7, anchor="none", gravity=(0, 0, 0)))


@pytest.mark.parametrize("name", sorted(SCENES))
def test_compiled_right_hand_side_equals_numpy(name):
    scene = SCENES[name]
    dyn = ln.Dynamics(scene)
    if not compiled.supports(dyn):
        pytest.skip(f"{dyn.structure.kind} scenes take the numpy path")
    rng = np.random.default_rng(2)
    paths = [compiled.CompiledScene(dyn)]
    if paths[0].use_chain:
        paths.append(compiled.CompiledScene(dyn, use_chain=False))
    assert paths[0].use_chain == (dyn.structure.kind == "chain")
    for _ in range(3):
        X, U = _random_state(dyn, rng)
        F_in = rng.normal(size=X.shape)
        acc, T = dyn.accelerations(X, U, F_in)
        for kernel in paths:
            status, acc_c, T_c = kernel.accelerations(X, U, F_in)
            assert status == compiled.OK
            np.testing.assert_allclose(acc_c, acc, rtol=0, atol=1e-12 * np.abs(acc).max(), err_msg=name)
            np.testing.assert_allclose(T_c, T, rtol=0, atol=1e-12 * np.abs(T).max(), err_msg=name)


def test_singular_configuration_is_reported_not_solved():
    scene = builders.pendulum()
    dyn = ln.Dynamics(scene)
    X = np.array(scene.X0)
    X[1] = X[0]  # the bob on its pivot: E = 0, A = 0
    for use_chain in (True, False):
        status, _, _ = compiled.CompiledScene(dyn, use_chain=use_chain).accelerations(X, np.zeros_like(X))
        assert status == compiled.SINGULAR


@pytest.mark.parametrize("method,kw", [("rattle", {"dt": 1e-3}), ("yoshida4", {"dt": 2e-3}),
                                       ("dop853", {"rtol": 1e-9})])
@pytest.mark.parametrize("name", ["chain_100", "three_paths"])
def test_chain_path_and_general_path_give_the_same_run(name, method, kw):
    """The tridiagonal elimination and the general sparse LDL^T inside the compiled integrators."""
    scene = SCENES[name]
    runs = []
    for use_chain in (True, False):
        sim = ln.Simulator(scene, method=method, backend="compiled", **kw)
        integ = sim.integrator
        if method == "dop853":
            kernel = integ._compiled_kernel()
            integ._kernel = type(kernel)(sim.dyn, integ.A, integ.B, integ.error_weights, kernel.error_kind,
                                         integ.error_estimator_order, use_chain=use_chain)
        else:
            integ._kernel = compiled.CompiledRattle(sim.dyn, use_chain=use_chain)
        assert integ._kernel.use_chain == use_chain
        sim.advance(0.2)
        runs.append(sim.state)
    assert np.max(np.abs(runs[0].X - runs[1].X)) < 1e-12
    assert np.max(np.abs(runs[0].U - runs[1].U)) < 1e-10


def test_c_reference_kernels_agree_with_the_compiled_and_numpy_ones(tmp_path):
    bench = pytest.importorskip("benchmarks.bench_kernel")
    try:
        lib, _, _ = bench.build_c_reference(tmp_path)
        lib_fused, _, _ = bench.build_c_reference(tmp_path, source=bench.C_SOURCE_FUSED)
    except bench.CUnavailable as exc:
        pytest.skip(str(exc))
    for n in (1, 10, 300):
        scene, dyn, X, U = bench.random_chain_state(n, seed=n)
        acc_c, T_c = bench.CChain(lib, scene, X, U).evaluate()
        acc_f, T_f = bench.CChain(lib_fused, scene, X, U).evaluate()
        acc_l, T_l = bench.LinknetChain(dyn, X, U, use_chain=True).evaluate()
        acc_n, T_n = dyn.accelerations(X, U)
        for acc, T in ((acc_c, T_c), (acc_f, T_f), (acc_l, T_l)):
            np.testing.assert_allclose(acc, acc_n, rtol=0, atol=1e-12 * np.abs(acc_n).max())
            np.testing.assert_allclose(T, T_n, rtol=0, atol=1e-12 * np.abs(T_n).max())
        # the C kernel's physics: the anchored mass does not move, and (13) holds for every link
        assert np.all(acc_c[0] == 0.0)
        dX, dU = X[scene.k2] - X[scene.k1], U[scene.k2] - U[scene.k1]
        lhs = np.einsum("ij,ij->i", dX, acc_c[scene.k2] - acc_c[scene.k1])
        np.testing.assert_allclose(lhs, -np.einsum("ij,ij->i", dU, dU), rtol=0, atol=1e-10 * np.abs(lhs).max())


@pytest.mark.parametrize("name", ["net_10x10", "spinning_tetrahedron", "chain_100", "four_bar"])
def test_scheduled_factorisation_is_qdldl_operation_for_operation(name):
    """The schedule replayed once per pattern gives bitwise the factors of the full up-looking algorithm."""
    from linknet_core.ldl import ldl_factor

    scene = SCENES[name]
    dyn = ln.Dynamics(scene)
    asm, sym = dyn.solver.assembly, dyn.solver.ldl
    rng = np.random.default_rng(4)
    for _ in range(3):
        X, _ = _random_state(dyn, rng)
        values = asm.upper_values(dyn.unit_vectors(X))
        Li, Lx, D, Dinv = np.zeros_like(sym.Li), np.zeros_like(sym.Lx), np.zeros(scene.L), np.zeros(scene.L)
        bad = ldl_factor(scene.L, sym.Ap, sym.Ai, values, sym.Lp, Li, Lx, D, Dinv, sym.etree, sym.pivot_tol)
        assert sym.factor(values) == (bad < 0)
        assert np.array_equal(Li[:sym.nnz_L], sym.Li[:sym.nnz_L])
        assert np.array_equal(Lx, sym.Lx) and np.array_equal(D, sym.D) and np.array_equal(Dinv, sym.Dinv)
    # a singular matrix is reported at the same column
    values[:] = 0.0
    bad = ldl_factor(scene.L, sym.Ap, sym.Ai, values, sym.Lp, Li, Lx, D, Dinv, sym.etree, sym.pivot_tol)
    assert not sym.factor(values) and sym.singular_column == bad == 0
