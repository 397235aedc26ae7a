"""The native sparse LDL^T of the tension matrix A (25) (linknet_core/native/src/engine_ldl.c), called through
linknet_core.clib.ldl on the package's library, against dense numpy solves.

A's entries come pair by pair as the model hands them to the native core: for links l, l' sharing a free mass
k, sign * (1/M_k) * (E_l . E_l') with E the unit vectors (8) (seed (18), (21)-(22), (25)).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from linknet_core.scene import builders
from linknet_core.clib.ldl import NativeLDL, amd_ordering, vector_kernels, zero_pivots
from linknet_core.tolerances import PIVOT_TOL
from linknet_core.scene.description import Scene, load_scene
from linknet_core.structure.topology import _dense_rank, _rank_from_pivots, analyse, link_pairs

MODELS = sorted((Path(__file__).resolve().parents[2] / "models").glob("*.json"))


def pair_values(scene: Scene, X: np.ndarray):
    pairs = link_pairs(scene)
    E = (X[scene.k2] - X[scene.k1]) / scene.length[:, None]
    values = pairs.sign * scene.inv_mass[pairs.mass] * np.einsum("ij,ij->i", E[pairs.first], E[pairs.second])
    return pairs.first, pairs.second, values


def dense(n, first, second, values):
    A = np.zeros((n, n))
    np.add.at(A, (first, second), values)
    off = first != second
    np.add.at(A, (second[off], first[off]), values[off])
    return A


def perturbed(scene: Scene, rng, scale=0.05) -> np.ndarray:
    """A random configuration near the initial one (lengths need not hold: A is then the Jacobian form)."""
    return scene.X0 + scale * scene.length.mean() * rng.standard_normal(scene.X0.shape)


def hanging_tree(depth=5) -> Scene:
    """A binary tree of masses hanging from one anchor: a forest with branch points (free degree 3)."""
    masses = [{"name": "root", "position": [0.0, 0.0, 0.0], "fixed": True}]
    links = []
    level = [0]
    for d in range(1, depth + 1):
        nxt = []
        for parent in level:
            for side in (-1, 1):
                x = masses[parent]["position"][0] + side * 2.0 ** -d
                masses.append({"name": f"m{len(masses)}", "position": [x, 0.0, -float(d)], "mass": 1.0})
                links.append({"a": parent + 1, "b": len(masses),
                              "length": float(np.hypot(side * 2.0 ** -d, 1.0))})
                nxt.append(len(masses) - 1)
        level = nxt
    return Scene.from_dict({"name": "tree", "masses": masses, "links": links})


def check_solves(scene: Scene, X: np.ndarray, ordering=None, rtol=1e-9):
    first, second, values = pair_values(scene, X)
    A = dense(scene.L, first, second, values)
    ldl = NativeLDL(scene.L, first, second, ordering)
    assert ldl.factor(values) == -1
    rng = np.random.default_rng(1)
    for _ in range(3):
        b = rng.standard_normal(scene.L)
        x = ldl.solve(b)
        expected = np.linalg.solve(A, b)
        # backward stable: the residual is round-off relative to |A| |x|
        assert np.linalg.norm(A @ x - b) <= 1e-13 * np.linalg.norm(A, 1) * np.linalg.norm(x, 1) * scene.L
        assert np.allclose(x, expected, rtol=rtol, atol=rtol * np.abs(expected).max())
    return ldl


@pytest.mark.parametrize("path", MODELS, ids=lambda p: p.stem)
def test_shipped_scenes_solve_as_numpy(path):
    scene = load_scene(path)
    if scene.L == 0:
        pytest.skip("no links")
    structure = analyse(scene)
    rng = np.random.default_rng(0)
    for X in (scene.X0, perturbed(scene, rng)):
        first, second, values = pair_values(scene, X)
        A = dense(scene.L, first, second, values)
        w = np.linalg.eigvalsh(A)
        if w[0] <= 1e-10 * w[-1]:  # redundant links: A is singular (27), checked below
            assert structure.kind == "redundant"
            continue
        check_solves(scene, X, structure.ordering)
        check_solves(scene, X, None)


@pytest.mark.parametrize("size", [6, 10, 30])
def test_random_configurations_of_nets(size):
    """Nets large enough for the supernodal algorithm (30 x 30) and small enough for the column one."""
    scene = builders.net(size, size)
    rng = np.random.default_rng(size)
    for _ in range(2):
        ldl = check_solves(scene, perturbed(scene, rng, 0.3))
    assert ldl.info["algorithm"] == ("supernodal" if size == 30 else "columns")


@pytest.mark.parametrize("size", [10, 30])
def test_pivots_are_those_of_the_dense_factorisation(size):
    """Every pivot d_k of the column (10 x 10 net) and the supernodal (30 x 30) algorithm is that of the dense
    LDL^T of P A P^T: the squared diagonal of its Cholesky factor."""
    scene = builders.net(size, size)
    first, second, values = pair_values(scene, perturbed(scene, np.random.default_rng(3), 0.3))
    ldl = NativeLDL(scene.L, first, second)
    assert ldl.info["algorithm"] == ("supernodal" if size == 30 else "columns")
    assert ldl.factor(values) == -1
    D, zeroed = ldl.pivots()
    order = ldl.ordering
    A = dense(scene.L, first, second, values)
    expected = np.linalg.cholesky(A[np.ix_(order, order)]).diagonal() ** 2
    assert zeroed == 0
    assert np.allclose(D, expected, rtol=1e-9)


def test_vector_kernels_give_bitwise_the_same_factorisation():
    """The supernodal factorisation's AVX2 copy (where the processor has it) and its portable copy."""
    scene = builders.net(30, 30)
    first, second, values = pair_values(scene, perturbed(scene, np.random.default_rng(4), 0.3))
    b = np.random.default_rng(5).standard_normal(scene.L)
    was = vector_kernels()
    results = []
    try:
        for enable in (False, True):
            vector_kernels(enable)
            ldl = NativeLDL(scene.L, first, second)
            assert ldl.info["algorithm"] == "supernodal" and ldl.info["avx2"] == vector_kernels()
            ldl.factor(values)
            results.append((ldl.pivots()[0], ldl.solve(b)))
    finally:
        vector_kernels(was)
    assert np.array_equal(results[0][0], results[1][0]) and np.array_equal(results[0][1], results[1][1])


def test_chains_and_trees_in_leaves_first_order_have_no_fill():
    for scene in (load_scene(Path(MODELS[0]).parent / "chain_100.json"), hanging_tree()):
        structure = analyse(scene)
        assert structure.kind in ("chain", "tree")
        first, second, _ = pair_values(scene, scene.X0)
        off = first != second
        distinct = np.unique(np.minimum(first[off], second[off]) * scene.L + np.maximum(first[off], second[off]))
        ldl = check_solves(scene, perturbed(scene, np.random.default_rng(2)), structure.ordering)
        assert ldl.nnz_L == distinct.size  # L has A's pattern: no fill
        assert ldl.info["algorithm"] == "columns"
        assert np.array_equal(ldl.ordering, structure.ordering)


def test_singular_matrix_reports_its_first_vanishing_pivot():
    """Redundant links: A is singular at every configuration; the factorisation names the first column
    (elimination order) whose pivot fell below pivot_tol times its diagonal entry, zeroes it, and the
    number of zeroed pivots is the number of self-stresses (27)."""
    scene = load_scene(Path(MODELS[0]).parent / "redundant_truss.json")
    structure = analyse(scene)
    assert structure.self_stresses > 0
    first, second, values = pair_values(scene, scene.X0)
    for ordering in (None, structure.ordering, np.arange(scene.L)):
        ldl = NativeLDL(scene.L, first, second, ordering)
        bad = ldl.factor(values)
        assert bad >= 0
        D, zeroed = ldl.pivots()
        assert zeroed == structure.self_stresses
        diag = dense(scene.L, first, second, values).diagonal()[ldl.ordering]
        vanishing = np.flatnonzero(~(D > PIVOT_TOL * np.abs(diag)))
        assert bad == vanishing[0] and vanishing.size == zeroed


def test_singular_supernodal_matrix():
    """A net with diagonals (many self-stresses) large enough for the supernodal algorithm."""
    scene = builders.net(16, 16, diagonals=True)
    first, second, values = pair_values(scene, scene.X0)
    ldl = NativeLDL(scene.L, first, second)
    assert ldl.info["algorithm"] == "supernodal"
    bad = ldl.factor(values)
    D, zeroed = ldl.pivots()
    A = dense(scene.L, first, second, values)
    w = np.linalg.eigvalsh(A)
    nullity = int(np.sum(w <= 1e-10 * w[-1]))
    assert nullity > 0 and bad >= 0
    assert zeroed == nullity
    diag = A.diagonal()[ldl.ordering]
    assert bad == np.flatnonzero(~(D > PIVOT_TOL * np.abs(diag)))[0]


def test_rank_from_pivots_matches_the_dense_rank():
    for scene in (load_scene(Path(MODELS[0]).parent / "redundant_truss.json"), builders.net(8, 8, diagonals=True),
                  load_scene(Path(MODELS[0]).parent / "net_10x10.json")):
        ordering = analyse(scene).ordering
        assert _rank_from_pivots(scene, ordering) == _dense_rank(scene, ordering)


def test_orderings_are_permutations():
    for scene in (builders.net(30, 30), load_scene(Path(MODELS[0]).parent / "net_10x10.json"), hanging_tree()):
        first, second, _ = pair_values(scene, scene.X0)
        order = amd_ordering(scene.L, first, second)
        assert np.array_equal(np.sort(order), np.arange(scene.L))
        given = np.random.default_rng(0).permutation(scene.L)
        assert np.array_equal(NativeLDL(scene.L, first, second, given).ordering, given)
    general = load_scene(Path(MODELS[0]).parent / "net_10x10.json")
    structure = analyse(general)
    assert structure.topology == "general"
    first, second, _ = pair_values(general, general.X0)
    assert np.array_equal(structure.ordering, amd_ordering(general.L, first, second))


def test_amd_fills_much_less_than_the_natural_order():
    scene = builders.net(100, 100)
    first, second, _ = pair_values(scene, scene.X0)
    amd = NativeLDL(scene.L, first, second)
    natural = NativeLDL(scene.L, first, second, np.arange(scene.L))
    assert amd.nnz_L < 0.2 * natural.nnz_L
    assert amd.info["flops"] < 0.05 * natural.info["flops"]


def test_invalid_input_is_refused():
    scene = load_scene(Path(MODELS[0]).parent / "net_10x10.json")
    first, second, _ = pair_values(scene, scene.X0)
    L = scene.L
    repeated = np.arange(L)
    repeated[5] = 4
    out_of_range = np.arange(L)
    out_of_range[-1] = L
    negative = np.arange(L)
    negative[0] = -1
    for ordering in (repeated, out_of_range, negative):
        with pytest.raises(ValueError, match="refused"):
            NativeLDL(L, first, second, ordering)
    with pytest.raises(ValueError):
        NativeLDL(L, first, second, np.arange(L - 1))
    bad_pairs = first.copy()
    bad_pairs[3] = L
    with pytest.raises(ValueError, match="refused"):
        NativeLDL(L, bad_pairs, second)


def test_zero_pivots_helper_counts_self_stresses():
    scene = load_scene(Path(MODELS[0]).parent / "redundant_truss.json")
    first, second, values = pair_values(scene, scene.X0)
    assert zero_pivots(scene.L, first, second, values) == analyse(scene).self_stresses


def test_small_and_degenerate_patterns():
    """No links; a diagonal matrix; repeated pairs (their values add up); an indefinite matrix."""
    empty = NativeLDL(0, np.zeros(0, np.int64), np.zeros(0, np.int64))
    assert empty.factor(np.zeros(0)) == -1 and empty.solve(np.zeros(0)).size == 0 and empty.nnz_L == 0
    diagonal = NativeLDL(3, [0, 1, 2], [0, 1, 2])
    assert diagonal.nnz_L == 0 and diagonal.factor([2.0, 4.0, 8.0]) == -1
    assert np.allclose(diagonal.solve([1.0, 1.0, 1.0]), [0.5, 0.25, 0.125])
    # the 2 x 2 matrix [[3, 1], [1, 2]] with its diagonal and off-diagonal entries split over repeated pairs,
    # given in both orders
    first, second = [0, 0, 1, 0, 1, 1], [0, 0, 0, 1, 1, 1]
    repeated = NativeLDL(2, first, second)
    assert repeated.factor([1.0, 2.0, 0.25, 0.75, 1.5, 0.5]) == -1
    assert np.allclose(repeated.solve([1.0, 2.0]), np.linalg.solve([[3.0, 1.0], [1.0, 2.0]], [1.0, 2.0]))
    # [[1, 2], [2, 1]] is indefinite: the second pivot, 1 - 4 = -3, is not above pivot_tol |A_11|
    indefinite = NativeLDL(2, [0, 0, 1], [0, 1, 1], [0, 1])
    assert indefinite.factor([1.0, 2.0, 1.0]) == 1
    assert indefinite.pivots()[1] == 1
