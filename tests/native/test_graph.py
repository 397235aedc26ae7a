"""The structure analysis's graph routines (native src/graph.c) against scipy.sparse.csgraph, an independent
implementation: the same components with the same numbering, and in a forest the same depths below each tree's
smallest leaf (breadth-first search from a virtual root joined to those leaves)."""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from linknet_core.clib.library import forest_depth, graph_components


def test_components_numbered_as_csgraph_numbers_them():
    rng = np.random.default_rng(7)
    for _ in range(300):
        n = int(rng.integers(1, 30))
        m = int(rng.integers(0, 40))
        a, b = rng.integers(0, n, m), rng.integers(0, n, m)
        expected = connected_components(sp.coo_matrix((np.ones(m), (a, b)), shape=(n, n)), directed=False)
        count, label = graph_components(n, a, b)
        assert count == expected[0]
        assert np.array_equal(label, expected[1])


def _csgraph_depth(n, a, b):
    sym = sp.coo_matrix((np.ones(a.size), (a, b)), shape=(n, n)).tocsr()
    sym = (sym + sym.T).tocsr()
    _, labels = connected_components(sym, directed=False)
    leaves = np.flatnonzero(np.diff(sym.indptr) <= 1)
    _, first = np.unique(labels[leaves], return_index=True)
    roots = leaves[first]
    edges = sp.coo_matrix((np.ones(roots.size), (np.full(roots.size, n), roots)), shape=(n + 1, n + 1))
    forest = (sp.block_diag([sym, sp.csr_matrix((1, 1))]) + edges + edges.T).tocsr()
    order, pred = breadth_first_order(forest, n, directed=False, return_predecessors=True)
    depth = np.zeros(n + 1, np.int64)
    for node in order[1:]:
        depth[node] = depth[pred[node]] + 1
    return depth[:n] - 1


def test_forest_depths_as_a_breadth_first_search_finds_them():
    rng = np.random.default_rng(8)
    for _ in range(200):
        n = int(rng.integers(1, 40))
        edges = np.array([(i, int(rng.integers(0, i))) for i in range(1, n) if rng.random() < 0.8],
                         np.int64).reshape(-1, 2)
        perm = rng.permutation(n)  # node numbers in no particular order along the trees
        edges = perm[edges][rng.permutation(len(edges))]
        a, b = edges[:, 0], edges[:, 1]
        assert np.array_equal(forest_depth(n, a, b), _csgraph_depth(n, a, b))


def test_cycle_and_bad_edges_refused():
    with pytest.raises(ValueError, match="cycle"):
        forest_depth(3, np.array([0, 1, 2]), np.array([1, 2, 0]))
    with pytest.raises(ValueError, match="out of range"):
        graph_components(2, np.array([0]), np.array([2]))
