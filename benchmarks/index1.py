"""Naive baseline and reference right-hand side: the index-1 formulation without projection.

Written from the seed directly, independently of linknet_core, so that the references it produces are an
independent check of linknet (not linknet checked against itself):
  tensions from (25)-(26)  A T = B,  accelerations from (9),  dX/dt = U (10).
Off the constraint manifold the diagonal of A is taken as |E_l|^2 (1/M_k1 + 1/M_k2), i.e. A = C M^-1 C^T with
C row l = +E_l at k1, -E_l at k2, which is what differentiating (11) twice gives exactly (13); on the manifold
it equals (25). Constraint drift is not corrected: that is what makes it the *naive* baseline.

Where A is singular (redundant links) the minimum-norm tensions are used (the seed (27)-(36) proves any
solution gives the same forces).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .scene_spec import SceneSpec

DENSE_MAX_LINKS = 400


class Index1System:
    def __init__(self, spec: SceneSpec):
        self.spec = spec
        self.K, self.L = spec.K, spec.L
        self.k1, self.k2, self.R = spec.k1, spec.k2, spec.length
        self.invm = spec.inv_mass
        self.g_acc = np.where(spec.fixed[:, None], 0.0, spec.gravity[None, :])  # F_k / M_k for gravity
        self.dense = self.L <= DENSE_MAX_LINKS
        L, K = self.L, self.K
        # sparsity pattern of C (L x 3K): row l, columns 3*k1+d (+E) and 3*k2+d (-E)
        rows = np.repeat(np.arange(L), 6)
        cols = np.concatenate([3 * self.k1[:, None] + np.arange(3), 3 * self.k2[:, None] + np.arange(3)],
                              axis=1).ravel()
        self._C = sp.csr_matrix((np.ones(6 * L), (rows, cols)), shape=(L, 3 * K))
        # the csr ordering is row-major with sorted columns; remember where each (l, slot) lands
        probe = sp.csr_matrix((np.arange(6 * L, dtype=float) + 1, (rows, cols)), shape=(L, 3 * K))
        self._perm = (probe.data - 1).astype(np.int64)
        self._invm3 = np.repeat(self.invm, 3)
        self.redundant = self._is_redundant()

    def _is_redundant(self) -> bool:
        if self.L == 0:
            return False
        A = self.tension_matrix(self.spec.X0)
        if self.dense:
            s = np.linalg.svd(A, compute_uv=False)
            return bool(s[-1] <= 1e-10 * s[0])
        try:
            spla.splu(A.tocsc()).solve(np.ones(self.L))
            return False
        except RuntimeError:
            return True

    def _C_of(self, E):
        data = np.concatenate([E, -E], axis=1).ravel()
        C = self._C.copy()
        C.data = data[self._perm]
        return C

    def tension_matrix(self, X):
        E = (X[self.k2] - X[self.k1]) / self.R[:, None]
        C = self._C_of(E)
        A = (C.multiply(self._invm3[None, :]) @ C.T)
        return A.toarray() if self.dense else A.tocsc()

    def tensions(self, X, U):
        if self.L == 0:
            return np.zeros(0)
        E = (X[self.k2] - X[self.k1]) / self.R[:, None]
        dU = U[self.k2] - U[self.k1]
        # (26): B_l = |U_k2 - U_k1|^2 / R_l + E_l . (F_k2/M_k2 - F_k1/M_k1)
        B = np.einsum("ij,ij->i", dU, dU) / self.R + np.einsum("ij,ij->i", E, self.g_acc[self.k2] - self.g_acc[self.k1])
        C = self._C_of(E)
        A = C.multiply(self._invm3[None, :]) @ C.T
        if self.dense:
            A = A.toarray()
            if self.redundant:
                return np.linalg.lstsq(A, B, rcond=1e-12)[0]
            return sla.solve(A, B, assume_a="pos", check_finite=False)
        if self.redundant:
            return spla.lsqr(A, B, atol=1e-15, btol=1e-15, iter_lim=20 * self.L)[0]
        return spla.spsolve(A.tocsc(), B)

    def accelerations(self, X, U):
        T = self.tensions(X, U)
        E = (X[self.k2] - X[self.k1]) / self.R[:, None]
        f = np.zeros((self.K, 3))
        # (9): link l pulls k1 along +E_l and k2 along -E_l when T_l > 0
        np.add.at(f, self.k1, T[:, None] * E)
        np.add.at(f, self.k2, -T[:, None] * E)
        return self.g_acc + self.invm[:, None] * f, T

    def rhs(self, t, y):
        K = self.K
        X = y[: 3 * K].reshape(K, 3)
        U = y[3 * K:].reshape(K, 3)
        acc, _ = self.accelerations(X, U)
        return np.concatenate([U.ravel(), acc.ravel()])

    def y0(self):
        return np.concatenate([self.spec.X0.ravel(), self.spec.U0.ravel()])

    def split(self, y):
        K = self.K
        return y[: 3 * K].reshape(K, 3).copy(), y[3 * K:].reshape(K, 3).copy()
