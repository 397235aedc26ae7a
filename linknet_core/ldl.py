"""Sparse LDL^T factorisation with the symbolic analysis done once per scene.

The tension matrix A (seed (25)) keeps its sparsity pattern for the whole run (it is fixed by the
topology), so everything that depends only on the pattern is computed once: the elimination tree, the
column counts of L, and the whole schedule of the numeric factorisation (for each column k, which
columns c update it, in which order, and where L(k, c) is stored). Each step then only repeats the
arithmetic. The algorithm is the up-looking one of QDLDL (Stellato, Banjac et al., Apache-2.0), compiled
with numba: it touches only the non-zeros of L, so for chains and trees in a perfect elimination order it
costs O(L). :func:`ldl_schedule` replays its symbolic part once; :func:`ldl_factor_scheduled` does the
same floating-point operations in the same order as :func:`ldl_factor` (bitwise identical results),
without the elimination-tree walks and markers.

The matrix is given as the upper triangle (row <= column, diagonal included) in CSC form, already
permuted by the fill-reducing ordering chosen in :mod:`linknet_core.structure`.
"""
from __future__ import annotations

import numpy as np
from numba import njit
from numba.core.cpu import CPUTargetOptions

# Decorators of the compiled building blocks that never allocate (here and in linknet_core.compiled): cached
# and compiled without numba's reference counting (with it, every call passing arrays costs two atomic
# operations per array, more than a small scene's whole right-hand side); ``kernel`` is also inlined into
# its callers, ``outlined_kernel`` (large routines called from several places) is not.
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
def _reach(bidx, k, etree, y_markers, elim_buffer, y_idx, nnz_y):
    """Append to y_idx[nnz_y:] the unmarked columns on the elimination-tree path from bidx towards k, marking
    them, in the order column k's factorisation must take them (QDLDL's symbolic step). Returns the new count."""
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
    return nnz_y


@njit(cache=True)
def ldl_factor(n, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, etree, pivot_tol):
    """Numeric LDL^T of the upper-CSC matrix (Ap, Ai, Ax) into (Lp, Li, Lx), D, Dinv (QDLDL's up-looking
    algorithm, symbolic part included; :func:`ldl_factor_scheduled` is the same arithmetic without it).

    Returns -1 on success, or the 0-based column whose pivot fell below pivot_tol * its diagonal
    entry (the matrix is singular or nearly so: redundant links at this configuration).
    """
    y_vals = np.zeros(n)
    y_markers = np.zeros(n, np.bool_)
    y_idx = np.empty(n, np.int64)
    elim_buffer = np.empty(n, np.int64)
    next_space = Lp[:n].copy()
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
                nnz_y = _reach(bidx, k, etree, y_markers, elim_buffer, y_idx, nnz_y)
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


@njit(cache=True)
def ldl_schedule(n, Ap, Ai, Lp, etree):
    """The symbolic part of :func:`ldl_factor`, replayed once for a fixed pattern.

    Returns (row_start, row_col, row_slot, Li): for column k, the columns c = row_col[q] that update it, for
    q in row_start[k]:row_start[k+1] in the order the factorisation takes them, and the slot row_slot[q] of
    L(k, c) in (Lp, Li, Lx); and the row indices Li of L (fixed by the pattern).
    """
    y_markers = np.zeros(n, np.bool_)
    y_idx = np.empty(n, np.int64)
    elim_buffer = np.empty(n, np.int64)
    next_space = Lp[:n].copy()
    nnz_L = Lp[n]
    row_start = np.zeros(n + 1, np.int64)
    row_col = np.empty(nnz_L, np.int64)
    row_slot = np.empty(nnz_L, np.int64)
    Li = np.zeros(max(nnz_L, 1), np.int64)
    q = 0
    for k in range(n):
        nnz_y = 0
        for p in range(Ap[k], Ap[k + 1]):
            bidx = Ai[p]
            if bidx == k or y_markers[bidx]:
                continue
            nnz_y = _reach(bidx, k, etree, y_markers, elim_buffer, y_idx, nnz_y)
        for i in range(nnz_y - 1, -1, -1):
            c = y_idx[i]
            slot = next_space[c]
            row_col[q] = c
            row_slot[q] = slot
            Li[slot] = k
            next_space[c] = slot + 1
            y_markers[c] = False
            q += 1
        row_start[k + 1] = q
    return row_start, row_col, row_slot, Li


@outlined_kernel
def ldl_factor_scheduled(n, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, pivot_tol, y_vals):
    """Numeric LDL^T with the schedule of :func:`ldl_schedule` (and Li from it): the arithmetic of
    :func:`ldl_factor`, operation for operation. ``y_vals`` (n) must be zero on entry and is left so.

    Returns -1 on success, or the first column whose pivot fell below pivot_tol * its diagonal entry.
    """
    bad = -1
    for k in range(n):
        diag = 0.0
        for p in range(Ap[k], Ap[k + 1]):
            i = Ai[p]
            if i == k:
                diag = Ax[p]
            else:
                y_vals[i] = Ax[p]
        dk = diag
        for q in range(row_start[k], row_start[k + 1]):
            c = row_col[q]
            slot = row_slot[q]
            yc = y_vals[c]
            for j in range(Lp[c], slot):
                y_vals[Li[j]] -= Lx[j] * yc
            lx = yc * Dinv[c]
            Lx[slot] = lx
            dk -= yc * lx
            y_vals[c] = 0.0
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
    """Symbolic analysis (elimination tree, pattern of L, factorisation schedule) of one fixed upper-CSC pattern.

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
        self.row_start, self.row_col, self.row_slot, self.Li = ldl_schedule(self.n, self.Ap, self.Ai, self.Lp,
                                                                            self.etree)
        self.Lx = np.zeros(max(nnz_L, 1))
        self.D = np.zeros(self.n)
        self.Dinv = np.zeros(self.n)
        self._y = np.zeros(max(self.n, 1))
        self.pivot_tol = pivot_tol
        self.singular_column = -1

    @property
    def nnz_L(self) -> int:
        return int(self.Lp[-1])

    def factor(self, Ax: np.ndarray) -> bool:
        """Numeric factorisation; False where a pivot vanished (singular at this configuration)."""
        Ax = np.ascontiguousarray(Ax, np.float64)
        self.singular_column = ldl_factor_scheduled(self.n, self.Ap, self.Ai, Ax, self.Lp, self.Li, self.Lx, self.D,
                                                    self.Dinv, self.row_start, self.row_col, self.row_slot,
                                                    self.pivot_tol, self._y)
        return self.singular_column < 0

    def solve(self, b: np.ndarray) -> np.ndarray:
        return self.solve_in_place(np.array(b, dtype=float, copy=True))

    def solve_in_place(self, x: np.ndarray) -> np.ndarray:
        """Overwrite the float64 contiguous x (holding b) with the solution, and return it."""
        ldl_solve(self.n, self.Lp, self.Li, self.Lx, self.Dinv, x)
        return x
