"""The tension system (25)-(26): assembly from index arrays and one solver per structure.

With E_l = (X_k2 - X_k1)/R_l (8) and the constraint Jacobian C (row l = +E_l at k1, -E_l at k2), the
link forces on the masses are C^T T (9) and the tensions solve

    A T = B,   A = C M^-1 C^T,   B_l = |U_k2 - U_k1|^2 / R_l + E_l . (F_k2/M_k2 - F_k1/M_k1)   (25), (26)

On the manifold |E_l| = 1 and A is exactly the seed's (25): diagonal 1/M_k1 + 1/M_k2 (18), off-diagonal
S(l,l') (E_l . E_l') / M(l,l') (21)-(22). Off the manifold the diagonal is |E_l|^2 (1/M_k1 + 1/M_k2):
we keep the Jacobian form, because it is what makes the computed accelerations satisfy the twice
differentiated constraint (13) exactly at any configuration the integrator visits.
Anchored masses enter with 1/M = 0.
"""
from __future__ import annotations

import numpy as np
import scipy.linalg
import scipy.sparse as sp

from .ldl import SymbolicLDL
from .scene import Scene
from .structure import SINGULAR_RCOND, Structure, link_pairs

DENSE_MIN_NORM_LIMIT = 2500  # links; above it the redundant path uses MINRES (min-norm from x0 = 0)


class TensionAssembly:
    """Index arrays that assemble A of (25) as the values of a fixed sparse pattern.

    The pattern is the upper triangle of P A P^T in CSC form (P the elimination order), so that the
    values feed :class:`SymbolicLDL` directly. Assembly is one gather, one dot product per pair and one
    ``bincount``: no loop over links.
    """

    def __init__(self, scene: Scene, ordering: np.ndarray):
        self.scene = scene
        L = scene.L
        self.ordering = np.asarray(ordering, np.int64)
        self.position_of = np.empty(L, np.int64)
        self.position_of[self.ordering] = np.arange(L)
        pairs = link_pairs(scene)
        self.pair_first, self.pair_second = pairs.first, pairs.second
        # weight of each pair: S(l,l') / M(l,l') of (21)-(22), or 1/M of one end on the diagonal (18)
        self.pair_weight = pairs.sign * scene.inv_mass[pairs.mass]
        p1, p2 = self.position_of[pairs.first], self.position_of[pairs.second]
        rows, cols = np.minimum(p1, p2), np.maximum(p1, p2)
        # CSC slots of the upper triangle: sort by (column, row), unique
        key = cols * L + rows
        unique_keys, self.pair_slot = np.unique(key, return_inverse=True)
        self.nnz = unique_keys.size
        self.Ai = (unique_keys % L).astype(np.int64)
        col_of_slot = unique_keys // L
        self.Ap = np.zeros(L + 1, np.int64)
        np.cumsum(np.bincount(col_of_slot, minlength=L), out=self.Ap[1:])
        # links with no free end cannot exist (the scene forbids links between two anchors),
        # so every column has its diagonal entry.

    def pair_values(self, E: np.ndarray) -> np.ndarray:
        return self.pair_weight * np.einsum("ij,ij->i", E[self.pair_first], E[self.pair_second])

    def upper_values(self, E: np.ndarray) -> np.ndarray:
        """Values of the upper triangle of P A P^T, in the CSC order of (Ap, Ai)."""
        return np.bincount(self.pair_slot, weights=self.pair_values(E), minlength=self.nnz)

    def matrix(self, E: np.ndarray, E_right: np.ndarray | None = None) -> sp.csr_matrix:
        """A of (25) in the original link numbering, as a symmetric CSR matrix.

        With ``E_right`` it is the unsymmetric C(E) M^-1 C(E_right)^T (the exact Newton matrix of RATTLE's
        position stage, whose constraint directions are those at the start of the step).
        """
        L = self.scene.L
        off = self.pair_first != self.pair_second
        f, g = self.pair_first, self.pair_second
        if E_right is None:
            vals = self.pair_values(E)
            mirrored = vals[off]
        else:
            vals = self.pair_weight * np.einsum("ij,ij->i", E[f], E_right[g])
            mirrored = (self.pair_weight * np.einsum("ij,ij->i", E[g], E_right[f]))[off]
        rows = np.concatenate([f, g[off]])
        cols = np.concatenate([g, f[off]])
        data = np.concatenate([vals, mirrored])
        return sp.csr_matrix((data, (rows, cols)), shape=(L, L))

    def new_factorisation(self) -> SymbolicLDL:
        return SymbolicLDL(self.scene.L, self.Ap, self.Ai)


def unit_vectors(scene: Scene, X: np.ndarray) -> np.ndarray:
    """E_l of (8)."""
    return (X[scene.k2] - X[scene.k1]) / scene.length[:, None]


def rhs(scene: Scene, X: np.ndarray, U: np.ndarray, F: np.ndarray, E: np.ndarray | None = None) -> np.ndarray:
    """B of (26), with 1/M = 0 on anchored masses."""
    if E is None:
        E = unit_vectors(scene, X)
    dU = U[scene.k2] - U[scene.k1]
    a_free = F * scene.inv_mass[:, None]
    return np.einsum("ij,ij->i", dU, dU) / scene.length + np.einsum("ij,ij->i", E, a_free[scene.k2] - a_free[scene.k1])


class TensionSolver:
    """Solves A T = B for one scene. Subclasses differ in how, chosen once from the structure."""

    name = "abstract"

    def __init__(self, scene: Scene, structure: Structure):
        self.scene = scene
        self.structure = structure
        self.assembly = TensionAssembly(scene, structure.ordering)

    def factor(self, E: np.ndarray) -> None:
        raise NotImplementedError

    def solve(self, b: np.ndarray) -> np.ndarray:
        raise NotImplementedError


class SparseLDLSolver(TensionSolver):
    """Chains, trees and general graphs: LDL^T on a fixed pattern, symbolic analysis once.

    For chains and trees the ordering is leaves-first, so L has no fill and a solve costs O(L).
    If a pivot vanishes (the configuration has become singular, e.g. a loop passing through a flat
    position) the solver switches to the minimum-norm path for that evaluation, so the forces are
    still right (31); it counts such events in ``singular_events``.
    """

    name = "sparse-ldl"

    def __init__(self, scene: Scene, structure: Structure):
        super().__init__(scene, structure)
        self.ldl = self.assembly.new_factorisation()
        self.singular_events = 0
        self._fallback: MinNormSolver | None = None
        self._singular = False

    def factor(self, E: np.ndarray) -> None:
        self._singular = not self.ldl.factor(self.assembly.upper_values(E))
        if self._singular:
            self.singular_events += 1
            if self._fallback is None:
                self._fallback = MinNormSolver(self.scene, self.structure, self.assembly)
            self._fallback.factor(E)

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._singular:
            return self._fallback.solve(b)
        order = self.assembly.ordering
        x = self.ldl.solve_in_place(np.ascontiguousarray(b[order], dtype=float))  # b[order] is already a copy
        out = np.empty_like(x)
        out[order] = x
        return out


class MinNormSolver(TensionSolver):
    """Redundant links (A singular): the minimum-norm tensions T = A^+ B.

    Any solution gives the same forces on the masses (31); the minimum-norm one is the solution with no
    component along the self-stresses. Dense eigen-decomposition (rank revealing) up to
    DENSE_MIN_NORM_LIMIT links; MINRES from T = 0 above (its iterates stay in range(A), so it converges
    to the minimum-norm solution of a consistent system).
    """

    name = "min-norm"

    def __init__(self, scene: Scene, structure: Structure, assembly: TensionAssembly | None = None):
        self.scene = scene
        self.structure = structure
        self.assembly = assembly or TensionAssembly(scene, structure.ordering)
        self.rcond = SINGULAR_RCOND
        self._dense = scene.L <= DENSE_MIN_NORM_LIMIT
        self.rank = None

    def factor(self, E: np.ndarray) -> None:
        A = self.assembly.matrix(E)
        if self._dense:
            w, V = scipy.linalg.eigh(A.toarray())
            keep = w > self.rcond * max(w.max(), 1e-300)
            self.rank = int(keep.sum())
            self._V, self._winv, self._null = V[:, keep], 1.0 / w[keep], V[:, ~keep]
        else:
            self._A = A

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._dense:
            return self._V @ (self._winv * (self._V.T @ b))
        from scipy.sparse.linalg import minres

        x, _ = minres(self._A, b, rtol=1e-14, maxiter=20 * self.scene.L)
        return x

    def nullspace(self) -> np.ndarray:
        """Orthonormal basis of null(A) at the last factorisation: the self-stresses of (27), (31)."""
        if not self._dense:
            raise NotImplementedError("null space basis is computed on the dense path only")
        return self._null


def make_solver(scene: Scene, structure: Structure) -> TensionSolver:
    if structure.kind == "redundant":
        return MinNormSolver(scene, structure)
    return SparseLDLSolver(scene, structure)


def reference_tensions(scene: Scene, X, U, F) -> np.ndarray:
    """Independent dense path (tests): minimum-norm solution of C M^-1 C^T T = B by SVD least squares."""
    from .structure import constraint_jacobian

    C = constraint_jacobian(scene, X, free_only=False).toarray()
    minv = np.repeat(scene.inv_mass, 3)
    A = (C * minv) @ C.T
    B = rhs(scene, X, U, F)
    T, *_ = np.linalg.lstsq(A, B, rcond=1e-10)
    return T
