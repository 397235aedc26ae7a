"""Sparse LDL^T factorisation with the symbolic analysis done once per scene.

The tension matrix A (seed (25)) keeps its sparsity pattern for the whole run (it is fixed by the
topology), so the elimination tree and the column counts of L are computed once, and each step only
repeats the numeric factorisation. The numeric part is the up-looking algorithm of QDLDL (Stellato,
Banjac et al., Apache-2.0), compiled with numba: it touches only the non-zeros of L, so for chains and
trees in a perfect elimination order it costs O(L).

The matrix is given as the upper triangle (row <= column, diagonal included) in CSC form, already
permuted by the fill-reducing ordering chosen in :mod:`linknet_core.structure`.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from numba.core.cpu import CPUTargetOptions

# Decorator of the compiled building blocks that never allocate (here and in linknet_core.compiled): cached,
# inlined into their callers, and compiled without numba's reference counting. With it, every call passing
# arrays costs two atomic operations per array, more than a small scene's whole right-hand side.
# error_model='numpy': a division by zero gives inf/nan as in C (the kernels check for non-finite values)
# instead of raising.
if hasattr(CPUTargetOptions, "_nrt"):
    kernel = njit(cache=True, error_model="numpy", _nrt=False, forceinline=True)
    outlined_kernel = njit(cache=True, error_model="numpy", _nrt=False)
else:  # a numba without the option: the same code, with reference counting
    kernel = njit(cache=True, error_model="numpy", forceinline=True)
    outlined_kernel = njit(cache=True, error_model="numpy")


@njit(cache=True)
def elimination_tree(n, Ap, Ai):
    """Elimination tree and column counts of L for an upper-triangular CSC pattern."""
    work = np.full(n, -1, np.int64)
    Lnz = np.zeros(n, np.int64)
    etree = np.full(n, -1, np.int64)
    for j in range(n):
        work[j] = j
        for p in range(Ap[j], Ap[j + 1]):
            i = Ai[p]
            while work[i] != j:
                if etree[i] == -1:
                    etree[i] = j
                Lnz[i] += 1
                work[i] = j
                i = etree[i]
    return etree, Lnz


@njit(cache=True)
def ldl_factor(n, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, etree, pivot_tol):
    """Numeric LDL^T of the upper-CSC matrix (Ap, Ai, Ax) into (Lp, Li, Lx), D, Dinv.

    Returns -1 on success, or the 0-based column whose pivot fell below pivot_tol * its diagonal
    entry (the matrix is singular or nearly so: redundant links at this configuration).
    """
    return ldl_factor_work(n, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, etree, pivot_tol, np.zeros(n),
                           np.zeros(n, np.bool_), np.empty(n, np.int64), np.empty(n, np.int64),
                           np.empty(n, np.int64))


@outlined_kernel
def ldl_factor_work(n, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, etree, pivot_tol, y_vals, y_markers, y_idx, elim_buffer,
                    next_space):
    """:func:`ldl_factor` with caller-owned work arrays (length n), for kernels that factor every step.

    ``y_vals`` must be all zero and ``y_markers`` all False on entry; the factorisation leaves them so.
    """
    for i in range(n):
        next_space[i] = Lp[i]
    bad = -1
    for k in range(n):
        nnz_y = 0
        diag = 0.0
        for p in range(Ap[k], Ap[k + 1]):
            bidx = Ai[p]
            if bidx == k:
                diag = Ax[p]
                continue
            y_vals[bidx] = Ax[p]
            if not y_markers[bidx]:
                y_markers[bidx] = True
                elim_buffer[0] = bidx
                nnz_e = 1
                nxt = etree[bidx]
                while nxt != -1 and nxt < k:
                    if y_markers[nxt]:
                        break
                    y_markers[nxt] = True
                    elim_buffer[nnz_e] = nxt
                    nnz_e += 1
                    nxt = etree[nxt]
                while nnz_e > 0:
                    nnz_e -= 1
                    y_idx[nnz_y] = elim_buffer[nnz_e]
                    nnz_y += 1
        dk = diag
        for i in range(nnz_y - 1, -1, -1):
            c = y_idx[i]
            slot = next_space[c]
            yc = y_vals[c]
            for j in range(Lp[c], slot):
                y_vals[Li[j]] -= Lx[j] * yc
            Li[slot] = k
            Lx[slot] = yc * Dinv[c]
            dk -= yc * Lx[slot]
            next_space[c] = slot + 1
            y_vals[c] = 0.0
            y_markers[c] = False
        D[k] = dk
        if not (dk > pivot_tol * abs(diag)):
            if bad == -1:
                bad = k
            Dinv[k] = 0.0
        else:
            Dinv[k] = 1.0 / dk
    return bad


@outlined_kernel
def ldl_solve(n, Lp, Li, Lx, Dinv, x):
    """Solve L D L^T x = b in place (x holds b on entry)."""
    for i in range(n):
        xi = x[i]
        for j in range(Lp[i], Lp[i + 1]):
            x[Li[j]] -= Lx[j] * xi
    for i in range(n):
        x[i] *= Dinv[i]
    for i in range(n - 1, -1, -1):
        s = x[i]
        for j in range(Lp[i], Lp[i + 1]):
            s -= Lx[j] * x[Li[j]]
        x[i] = s


class SymbolicLDL:
    """Symbolic analysis (elimination tree, pattern sizes) of one fixed upper-CSC pattern.

    ``factor(values)`` repeats only the numeric factorisation; ``solve(b)`` uses the last one.
    """

    def __init__(self, n: int, Ap: np.ndarray, Ai: np.ndarray, pivot_tol: float = 1e-11):
        self.n = int(n)
        self.Ap = np.ascontiguousarray(Ap, np.int64)
        self.Ai = np.ascontiguousarray(Ai, np.int64)
        self.etree, Lnz = elimination_tree(self.n, self.Ap, self.Ai)
        self.Lp = np.zeros(self.n + 1, np.int64)
        np.cumsum(Lnz, out=self.Lp[1:])
        nnz_L = int(self.Lp[-1])
        self.Li = np.zeros(max(nnz_L, 1), np.int64)
        self.Lx = np.zeros(max(nnz_L, 1))
        self.D = np.zeros(self.n)
        self.Dinv = np.zeros(self.n)
        self.pivot_tol = pivot_tol
        self.singular_column = -1

    @property
    def nnz_L(self) -> int:
        return int(self.Lp[-1])

    def factor(self, Ax: np.ndarray) -> bool:
        """Numeric factorisation; False where a pivot vanished (singular at this configuration)."""
        self.singular_column = ldl_factor(self.n, self.Ap, self.Ai, Ax, self.Lp, self.Li, self.Lx,
                                          self.D, self.Dinv, self.etree, self.pivot_tol)
        return self.singular_column < 0

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.solve_in_place(np.array(b, dtype=float, copy=True))

    def solve_in_place(self, x: np.ndarray) -> np.ndarray:
        """Overwrite the float64 contiguous x (holding b) with the solution, and return it."""
        ldl_solve(self.n, self.Lp, self.Li, self.Lx, self.Dinv, x)
        return x
