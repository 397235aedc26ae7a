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

from linknet_core.scene.description import Scene
from linknet_core.tolerances import DENSE_MIN_NORM_LIMIT, PIVOT_TOL, SINGULAR_RCOND
from linknet_core.structure.topology import Structure, link_pairs

# scipy (sparse matrices, dense and sparse factorisations) is imported inside the functions of this reference path
# that use it: a Simulator on the native core never calls them, and importing scipy.sparse and scipy.linalg costs
# ~0.2 s of every command's start-up.
DENSE_FACTOR_LIMIT = 200  # links; up to here the reference factors A densely


class TensionAssembly:
    """Index arrays that assemble A of (25): one gather, one dot product per pair of links sharing a free mass
    and one sparse matrix, no loop over links."""

    def __init__(self, scene: Scene, ordering: np.ndarray):
        self.scene = scene
        self.ordering = np.asarray(ordering, np.int64)
        pairs = link_pairs(scene)
        self.pair_first, self.pair_second = pairs.first, pairs.second
        # weight of each pair: S(l,l') / M(l,l') of (21)-(22), or 1/M of one end on the diagonal (18)
        self.pair_weight = pairs.sign * scene.inv_mass[pairs.mass]

    def pair_values(self, E: np.ndarray) -> np.ndarray:
        return self.pair_weight * np.einsum("ij,ij->i", E[self.pair_first], E[self.pair_second])

    def matrix(self, E: np.ndarray, E_right: np.ndarray | None = None) -> sp.csr_matrix:
        """A of (25) in the original link numbering, as a symmetric CSR matrix.

        With ``E_right`` it is the unsymmetric C(E) M^-1 C(E_right)^T (the exact Newton matrix of RATTLE's
        position stage, whose constraint directions are those at the start of the step).
        """
        import scipy.sparse as sp

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


def unit_vectors(scene: Scene, X: np.ndarray) -> np.ndarray:
    """E_l of (8) (X (..., K, 3): of every sample)."""
    return (X[..., scene.k2, :] - X[..., scene.k1, :]) / scene.length[:, None]


def rhs(scene: Scene, X: np.ndarray, U: np.ndarray, F: np.ndarray, E: np.ndarray | None = None,
        anchor_acc: np.ndarray | None = None) -> np.ndarray:
    """B of (26), with 1/M = 0 on anchored masses; ``anchor_acc`` (K,3): the accelerations A_a of driven anchors
    (zero elsewhere), which take the place of F/M on their side of a link (linknet_core.dynamics.drive)."""
    if E is None:
        E = unit_vectors(scene, X)
    dU = U[scene.k2] - U[scene.k1]
    a_free = F * scene.inv_mass[:, None]
    if anchor_acc is not None:
        a_free = a_free + anchor_acc
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


class SparseSolver(TensionSolver):
    """Chains, trees and general graphs: a factorisation of the positive definite A in the structure's
    elimination order without pivoting, so that its pivots are those of LDL^T: dense Cholesky up to
    DENSE_FACTOR_LIMIT links (cheaper than a sparse factorisation's set-up there), SuperLU above.

    If a pivot falls below PIVOT_TOL times its diagonal entry (the configuration has become singular, e.g. a
    loop passing through a flat position) the solver switches to the minimum-norm path for that evaluation,
    so the forces are still right (31); it counts such events in ``singular_events``.
    """

    name = "sparse"

    def __init__(self, scene: Scene, structure: Structure):
        super().__init__(scene, structure)
        self.singular_events = 0
        self.rcond = SINGULAR_RCOND  # the minimum-norm fallback's cut
        self._fallback: MinNormSolver | None = None
        self._singular = False
        self._lu = None

    def factor(self, E: np.ndarray) -> None:
        import scipy.linalg
        from scipy.sparse.linalg import splu

        order = self.assembly.ordering
        A = self.assembly.matrix(E)
        try:
            if self.scene.L <= DENSE_FACTOR_LIMIT:
                self._lu = None
                A = A.toarray()[np.ix_(order, order)]
                diagonal = np.abs(np.diagonal(A))
                self._cholesky = scipy.linalg.cho_factor(A, lower=True, check_finite=False)
                pivots = np.diagonal(self._cholesky[0]) ** 2
            else:
                A = A[order][:, order]
                diagonal = np.abs(A.diagonal())
                self._lu = splu(A.tocsc(), permc_spec="NATURAL", diag_pivot_thresh=0.0, options={"SymmetricMode": True})
                pivots = self._lu.U.diagonal()
            self._singular = not np.all(pivots > PIVOT_TOL * diagonal)
        except (RuntimeError, np.linalg.LinAlgError):  # a zero or negative pivot
            self._singular = True
        if self._singular:
            self.singular_events += 1
            if self._fallback is None:
                self._fallback = MinNormSolver(self.scene, self.structure, self.assembly)
            self._fallback.rcond = self.rcond
            self._fallback.factor(E)

    def solve(self, b: np.ndarray) -> np.ndarray:
        if self._singular:
            return self._fallback.solve(b)
        import scipy.linalg

        order = self.assembly.ordering
        out = np.empty(b.shape[0])
        b_ordered = np.ascontiguousarray(b[order], dtype=float)
        out[order] = (self._lu.solve(b_ordered) if self._lu is not None
                      else scipy.linalg.cho_solve(self._cholesky, b_ordered, check_finite=False))
        return out


class MinNormSolver(TensionSolver):
    """Redundant links (A singular): the minimum-norm tensions T = A^+ B.

    Any solution gives the same forces on the masses (31); the minimum-norm one is the solution with no
    component along the self-stresses. Up to DENSE_MIN_NORM_LIMIT links, the native core's algorithm
    (native/src/stages/minnorm.c), so that both paths draw the line between a self-stress and a stiff direction
    in the same place: Cholesky with complete pivoting, P A P^T = R^T R (LAPACK dpstrf), stopped at rank r when
    every remaining diagonal entry of the Schur complement is at most ``rcond`` times the largest diagonal entry
    of A; the null space of P A P^T is spanned by the columns of Z = [-W; I], W = R11^-1 R12, and

        T = P^T Pz([R11^-1 R11^-T c_1; 0]),  c = Pz(P B),  Pz(y) = y - Z (Z^T Z)^-1 Z^T y

    (projecting B first drops its component along the self-stresses, so a B inconsistent at round-off gets the
    minimum-norm least-squares answer). Above that size MINRES from T = 0 (its iterates stay in range(A), so it
    converges to the minimum-norm solution of a consistent system).
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
        if not self._dense:
            self._A = A
            return
        import scipy.linalg
        from scipy.linalg.lapack import dpstrf

        A = A.toarray()
        L = A.shape[0]
        largest = float(A.diagonal().max()) if L else 0.0
        if not np.isfinite(A).all():  # not usable: the solves give NaN, for the caller's finiteness test
            self.rank, self._perm = -1, None
            return
        if not largest > 0.0:  # A = 0: T = 0 is the minimum-norm answer to any B
            self.rank, self._perm = 0, np.arange(L)
            return
        R, pivots, rank, info = dpstrf(A, tol=self.rcond * largest, lower=0)
        r = int(rank) if info > 0 else L
        self.rank, self._perm = r, pivots[:L] - 1
        self._R11 = np.triu(R[:r, :r])
        if r < L:
            W = scipy.linalg.solve_triangular(self._R11, R[:r, r:])
            self._W = W
            self._ZtZ = scipy.linalg.cho_factor(np.eye(L - r) + W.T @ W)

    def _without_null(self, y: np.ndarray) -> np.ndarray:
        """Pz(y): y (pivoted numbering) less its component along the null space Z = [-W; I]."""
        import scipy.linalg

        r = self.rank
        t = scipy.linalg.cho_solve(self._ZtZ, y[r:] - self._W.T @ y[:r])
        out = y.copy()
        out[:r] += self._W @ t
        out[r:] -= t
        return out

    def solve(self, b: np.ndarray) -> np.ndarray:
        if not self._dense:
            from scipy.sparse.linalg import minres

            x, _ = minres(self._A, b, rtol=1e-14, maxiter=20 * self.scene.L)
            return x
        import scipy.linalg

        L, r = b.shape[0], self.rank
        if r is None or r < 0:
            return np.full(L, np.nan)
        x = np.zeros(L)
        if r == 0:
            return x
        c = np.asarray(b, float)[self._perm]
        if r < L:
            c = self._without_null(c)  # B's self-stress component carries no equation
        basic = np.zeros(L)  # R11^T R11 x_1 = c_1, x_2 = 0
        basic[:r] = scipy.linalg.solve_triangular(
            self._R11, scipy.linalg.solve_triangular(self._R11, c[:r], trans="T"))
        if r < L:
            basic = self._without_null(basic)  # minimum norm: drop the self-stresses (27)
        x[self._perm] = basic
        return x


def make_solver(scene: Scene, structure: Structure) -> TensionSolver:
    if structure.kind == "redundant":
        return MinNormSolver(scene, structure)
    return SparseSolver(scene, structure)


def reference_tensions(scene: Scene, X, U, F) -> np.ndarray:
    """Independent dense path (tests): minimum-norm solution of C M^-1 C^T T = B by SVD least squares."""
    from linknet_core.structure.topology import constraint_jacobian

    C = constraint_jacobian(scene, X, free_only=False).toarray()
    minv = np.repeat(scene.inv_mass, 3)
    A = (C * minv) @ C.T
    B = rhs(scene, X, U, F)
    T, *_ = np.linalg.lstsq(A, B, rcond=1e-10)
    return T
