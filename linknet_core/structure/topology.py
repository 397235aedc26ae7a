"""Structure of a scene, analysed once: which tension solver it needs, and its rigidity.

The tension matrix A (seed (25)) couples two links only when they share a *free* mass (an anchored mass
has 1/M = 0, so the term S(l,l')/M(l,l') of (25) vanishes there). Cutting the graph at the anchors
therefore tells the solver what it faces:

* chain     - the cut graph is a union of paths: A is tridiagonal in path order, O(L);
* tree      - the cut graph is a forest: eliminating links from the leaves inwards creates no fill, O(L);
* general   - loops among free masses: sparse LDL^T with AMD's fill-reducing ordering computed once;
* redundant - the links admit states of self-stress (A singular, the homogeneous solutions of (27),
              equivalently (31)): minimum-norm tensions by a rank-revealing path.
"""
from __future__ import annotations

import weakref
from dataclasses import dataclass, field

import numpy as np

from linknet_core.clib.ldl import amd_ordering, zero_pivots
from linknet_core.clib.library import forest_depth, graph_components
from linknet_core.scene.description import Scene
from linknet_core.tolerances import DENSE_RANK_LIMIT, PLANE_TOL, SINGULAR_RCOND



@dataclass(frozen=True)
class LinkPairs:
    """Pairs of links that share a free mass, with the sign S(l, l') of (21) (+1 on the diagonal).

    ``first[p] <= second[p]``; each link appears twice on the diagonal (once per free end), so that
    summing ``sign * inv_mass[mass] * (E_first . E_second)`` over the pairs assembles A of (25).
    """

    first: np.ndarray
    second: np.ndarray
    mass: np.ndarray
    sign: np.ndarray


def link_pairs(scene: Scene) -> LinkPairs:
    """All (l, l', k) with links l, l' incident to the same free mass k (setup, not per step; kept per scene)."""
    return kept_per_scene(scene, "pairs", _link_pairs)


def _link_pairs(scene: Scene) -> LinkPairs:
    L = scene.L
    if L == 0:
        empty = np.zeros(0, np.int64)
        return LinkPairs(empty, empty, empty, np.zeros(0))
    links = np.concatenate([np.arange(L), np.arange(L)])
    masses = np.concatenate([scene.k1, scene.k2])
    # sigma = +1 at the k1 end and -1 at the k2 end, so sigma_l * sigma_l' = (-1)^(i+j) of (21)
    sigma = np.concatenate([np.ones(L), -np.ones(L)])
    keep = ~scene.fixed[masses]
    links, masses, sigma = links[keep], masses[keep], sigma[keep]
    order = np.lexsort((links, masses))
    links, masses, sigma = links[order], masses[order], sigma[order]
    starts = np.flatnonzero(np.r_[True, masses[1:] != masses[:-1]])
    degree = np.diff(np.r_[starts, masses.size])
    # the ends around each free mass pair up with themselves and the ends after them (i <= j, row by row of the
    # upper triangle), masses taken by degree and then in order: one set of array operations, no loop per mass
    by_degree = np.argsort(degree, kind="stable")
    group_start, group_size = starts[by_degree], degree[by_degree]
    end = np.repeat(group_start - np.cumsum(group_size) + group_size, group_size) + np.arange(group_size.sum())
    partners = np.repeat(group_start + group_size, group_size) - end  # ends j >= i in the same group
    i = np.repeat(end, partners)
    j = i + np.arange(partners.sum()) - np.repeat(np.cumsum(partners) - partners, partners)
    a, b = links[i], links[j]
    return LinkPairs(np.minimum(a, b), np.maximum(a, b), masses[i], sigma[i] * sigma[j])


def _cut_graph(scene: Scene):
    """The masses-and-links graph with every link end at an anchor given its own node: (node_of_end (L, 2), the
    nodes of each link's two ends; number of nodes). Free masses are nodes 0 .. K_free - 1 in scene order."""
    n_free = scene.free_indices.size
    free_ids = np.full(scene.K, -1, np.int64)
    free_ids[scene.free_indices] = np.arange(n_free)
    next_id = n_free
    node_of_end = np.empty((scene.L, 2), np.int64)
    for side, kk in enumerate((scene.k1, scene.k2)):
        ids = free_ids[kk]
        anchored = scene.fixed[kk]
        n_anchored = int(np.count_nonzero(anchored))
        ids[anchored] = next_id + np.arange(n_anchored)
        next_id += n_anchored
        node_of_end[:, side] = ids
    return node_of_end, next_id


@dataclass
class Structure:
    """What the solver was chosen from (computed once per scene)."""

    kind: str  # 'chain' | 'tree' | 'general' | 'redundant'
    topology: str  # 'chain' | 'tree' | 'general' (ignoring redundancy)
    ordering: np.ndarray  # elimination order of the links
    max_free_degree: int
    closed_loops: int  # independent loops of the graph with all anchors merged into one ground node
    self_stresses: int  # states of self-stress at the initial configuration, L - rank(G)
    rank_G: int
    rank_exact: bool  # False where rank was estimated from LDL pivots (very large scenes)
    planar_normal: np.ndarray | None = None  # unit normal when every mass and force stays in one plane
    link_component: np.ndarray | None = None  # (L,) component of each link in the graph cut at the anchors
    notes: list = field(default_factory=list)


def _tree_ordering(node_of_end: np.ndarray, n_nodes: int) -> np.ndarray:
    """Leaves-first order of the links in a forest: no fill in the LDL^T of A. Each tree is rooted at a leaf
    (every tree has one), so that chains come out in path order (tridiagonal A); a link is as deep as its
    deeper end, and the deepest links come first."""
    depth = forest_depth(n_nodes, node_of_end[:, 0], node_of_end[:, 1])
    link_depth = np.maximum(depth[node_of_end[:, 0]], depth[node_of_end[:, 1]])
    return np.argsort(-link_depth, kind="stable")


def constraint_jacobian(scene: Scene, X: np.ndarray, free_only: bool = True) -> sp.csr_matrix:
    """C (L x 3K, or L x 3K_free) with row l = +E_l at k1(l) and -E_l at k2(l) (see (9), (12))."""
    import scipy.sparse as sp  # here only: the analysis of most scenes needs no sparse matrix (start-up time)

    E = (X[scene.k2] - X[scene.k1]) / scene.length[:, None]
    L = scene.L
    rows = np.repeat(np.arange(L), 6)
    cols = np.concatenate([3 * scene.k1[:, None] + np.arange(3), 3 * scene.k2[:, None] + np.arange(3)], axis=1).ravel()
    vals = np.concatenate([E, -E], axis=1).ravel()
    C = sp.csr_matrix((vals, (rows, cols)), shape=(L, 3 * scene.K))
    if free_only:
        free_cols = (3 * scene.free_indices[:, None] + np.arange(3)).ravel()
        C = C[:, free_cols]
    return C


def rank_and_nullspace(scene: Scene, X: np.ndarray, rtol: float = SINGULAR_RCOND ** 0.5):
    """Rank of C (free columns) and an orthonormal basis of the self-stresses (null space of C^T).

    Self-stresses are the T~ of (27)/(31): link tensions in equilibrium with no external load.
    """
    C = constraint_jacobian(scene, X).toarray()
    if C.size == 0:
        return 0, np.zeros((scene.L, scene.L))
    U, s, _ = np.linalg.svd(C, full_matrices=True)  # full U: its trailing columns are the null space of C^T
    tol = rtol * (s[0] if s.size else 0.0)
    rank = int(np.sum(s > tol))
    return rank, U[:, rank:]


def planar_normal(scene: Scene, tol: float = PLANE_TOL) -> np.ndarray | None:
    """Normal of the plane holding every mass, velocity, gravity and constant force, if there is one."""
    X = scene.X0
    origin = X.mean(axis=0)
    vectors = np.vstack([X - origin, scene.U0, scene.gravity[None, :], scene.force])
    scale = max(np.abs(vectors).max(), 1e-300)
    # thin SVD: O(K) memory (full_matrices would build a (K+2)^2 matrix). Not the eigenvalues of the 3 x 3
    # Gram matrix: their round-off (~eps times the largest) is far above tol^2 times it, so a tilted plane
    # was never recognised; singular values carry round-off ~eps relative, below tol
    _, sv, vt = np.linalg.svd(vectors / scale, full_matrices=False)
    if sv.size == 3 and sv[2] <= tol * max(sv[0], 1e-300):
        return vt[2]
    return None


def analyse(scene: Scene) -> Structure:
    """Classify the scene once, from its topology and its initial configuration. A scene is immutable, so
    its analysis is kept while the scene lives: every Simulator, Dynamics and native model of the same scene
    (an ensemble's members, a reset FMU) shares it."""
    return kept_per_scene(scene, "structure", _analyse)


def kept_per_scene(scene: Scene, what: str, compute):
    """compute(scene), computed once per scene object and what, dropped with the scene. What is derived from an
    immutable scene is kept here rather than on the scene (which pickles and copies as its fields); the value must
    not refer to the scene, or the scene would never be dropped."""
    key = (id(scene), what)
    kept = _per_scene.get(key)
    if kept is not None and kept[0]() is scene:
        return kept[1]
    value = compute(scene)
    _per_scene[key] = (weakref.ref(scene, lambda _, key=key: _per_scene.pop(key, None)), value)
    return value


_per_scene: dict = {}


def _analyse(scene: Scene) -> Structure:
    node_of_end, n_nodes = _cut_graph(scene)
    n_comp, node_component = graph_components(n_nodes, node_of_end[:, 0], node_of_end[:, 1])
    is_forest = scene.L == n_nodes - n_comp
    free_degree = np.bincount(np.concatenate([scene.k1, scene.k2]), minlength=scene.K)[scene.free_indices]
    max_free_degree = int(free_degree.max()) if free_degree.size else 0
    # loops with all anchors merged into one ground node (closed kinematic loops through the ground)
    ground_ids = np.where(scene.fixed, scene.free_indices.size, -1)
    ground_ids[scene.free_indices] = np.arange(scene.free_indices.size)
    n_ground_nodes = scene.free_indices.size + (1 if scene.fixed.any() else 0)
    n_comp_ground, _ = graph_components(n_ground_nodes, ground_ids[scene.k1], ground_ids[scene.k2])
    closed_loops = int(scene.L - n_ground_nodes + n_comp_ground)

    if is_forest:
        topology = "chain" if max_free_degree <= 2 else "tree"
        ordering = _tree_ordering(node_of_end, n_nodes)
    else:
        topology = "general"
        pairs = link_pairs(scene)
        ordering = amd_ordering(scene.L, pairs.first, pairs.second)

    notes = []
    rank_exact = True
    if closed_loops == 0:
        # no loop, even through the ground: peeling links from the free leaves inwards forces every
        # T~ of (31) to vanish, so there is no self-stress and G has full row rank
        rank = scene.L
    elif scene.L <= DENSE_RANK_LIMIT:
        rank = _dense_rank(scene, ordering)
    else:
        rank = _rank_from_pivots(scene, ordering)
        rank_exact = False
        notes.append("rank of G estimated from the LDL^T pivots (scene too large for a dense eigen-decomposition)")
    self_stresses = scene.L - rank
    kind = "redundant" if self_stresses > 0 else topology
    return Structure(kind=kind, topology=topology, ordering=np.asarray(ordering, np.int64),
                     max_free_degree=max_free_degree, closed_loops=closed_loops,
                     self_stresses=int(self_stresses), rank_G=int(rank), rank_exact=rank_exact,
                     planar_normal=planar_normal(scene), link_component=node_component[node_of_end[:, 0]],
                     notes=notes)


def _dense_rank(scene: Scene, ordering: np.ndarray, rtol: float = SINGULAR_RCOND) -> int:
    """rank(G) = rank(A), A = C M^-1 C^T (M^-1 is positive on the free masses): eigenvalues of the L x L A."""
    C = constraint_jacobian(scene, scene.X0).toarray()  # free columns: M^-1 is positive there
    w = np.linalg.eigvalsh((C * np.repeat(scene.inv_mass[scene.free_indices], 3)) @ C.T)
    return int(np.sum(w > rtol * max(w.max(), 1e-300)))


def _rank_from_pivots(scene: Scene, ordering: np.ndarray) -> int:
    """L minus the pivots one native LDL^T of A (25) at the initial configuration zeroes."""
    pairs = link_pairs(scene)
    E = (scene.X0[scene.k2] - scene.X0[scene.k1]) / scene.length[:, None]
    values = pairs.sign * scene.inv_mass[pairs.mass] * np.einsum("ij,ij->i", E[pairs.first], E[pairs.second])
    return int(scene.L - zero_pivots(scene.L, pairs.first, pairs.second, values, ordering))
