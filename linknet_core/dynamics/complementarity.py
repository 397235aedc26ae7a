"""The mixed linear complementarity problem of ropes and contacts, solved exactly.

    rows that are not unilateral (rods):   (W lambda - b)_i = 0                                  the seed's (25)-(26)
    unilateral rows (ropes, contacts):     lambda_i >= 0,  w_i = (W lambda - b)_i >= 0,  lambda_i w_i = 0

with W = C M^-1 C^T symmetric positive semi-definite (Cottle, Pang and Stone, The Linear Complementarity Problem,
1992, sec. 1.2 and 4.2). At the acceleration level b is B of (26) and lambda the tensions and normal forces; at an
impact b = -(C U + restitution terms) and lambda the impulses (linknet_core.dynamics.unilateral).
"""
from __future__ import annotations

import itertools

import numpy as np

from linknet_core.errors import SolverError
from linknet_core.tolerances import SINGULAR_RCOND

# The LCP's conditions hold to LCP_TOL of the problem's scale (|B| for w, |B| / max diag W for lambda).
LCP_TOL = 1e-11
# Murty's rule pivots at most this many times per unilateral row before the active sets are enumerated (a degenerate
# problem can cycle); enumeration takes at most 2^ENUMERATION_LIMIT sets.
PIVOTS_PER_ROW = 4
ENUMERATION_LIMIT = 16


def solve_mixed_lcp(W: np.ndarray, b: np.ndarray, unilateral: np.ndarray, start: np.ndarray | None = None,
                    release: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """lambda with (W lambda - b)_i = 0 on the rows that are not ``unilateral`` (the rods' equations) and, on the
    unilateral rows, lambda_i >= 0, w_i = (W lambda - b)_i >= 0, lambda_i w_i = 0; W symmetric positive
    semi-definite (W = C M^-1 C^T). Returns (lambda, active): ``active`` the rows solved as equalities (every rod,
    and the unilateral rows in the final basis).

    Murty's least-index principal pivoting (Cottle-Pang-Stone sec. 4.2, the "simple principal pivoting method" with
    Murty's rule): in a basis (a set of unilateral rows taken as equalities, lambda = 0 on the others) the rods and
    the basis rows are solved, minimum-norm where singular (31); the lowest-numbered row that breaks its sign
    condition (lambda_i < 0 in the basis, w_i < 0 outside) is flipped. For a positive definite Schur complement on
    the unilateral rows (independent constraints) this ends after finitely many pivots from any start; it starts
    from ``start`` (the callers give every touching constraint taut, the last mode's among them). ``release``: rows
    that leave the basis unless their lambda is clearly positive (a rope whose tension has just fallen to 0). A
    degenerate problem that cycles has its active sets enumerated
    (at most 2^ENUMERATION_LIMIT)."""
    W = np.asarray(W, float)
    b = np.asarray(b, float)
    unilateral = np.asarray(unilateral, bool)
    m = b.size
    uni = np.flatnonzero(unilateral)
    active = ~unilateral
    if start is not None:
        active[uni] = np.asarray(start, bool)[uni]
    release = np.zeros(m, bool) if release is None else np.asarray(release, bool)
    b_scale = max(float(np.abs(b).max()) if m else 0.0, np.finfo(float).tiny)
    diag = max(float(np.abs(np.diagonal(W)).max()) if m else 0.0, np.finfo(float).tiny)
    tol_w, tol_l = LCP_TOL * b_scale, LCP_TOL * b_scale / diag

    def violations(lam, w, basis):
        low = np.where(release, tol_l, -tol_l)
        bad_l = basis & unilateral & (lam < low)
        bad_w = ~basis & unilateral & (w < -tol_w)
        return bad_l | bad_w

    for _ in range(PIVOTS_PER_ROW * uni.size + 1):
        lam = basis_solution(W, b, active)
        bad = violations(lam, W @ lam - b, active)
        if not bad.any():
            return lam, active
        i = int(np.flatnonzero(bad)[0])
        active[i] = not active[i]
    if uni.size > ENUMERATION_LIMIT:
        raise SolverError(f"the complementarity problem of {uni.size} touching ropes and contacts did not settle "
                          f"after {PIVOTS_PER_ROW * uni.size} pivots (a degenerate configuration), and is too large "
                          f"to enumerate (more than {ENUMERATION_LIMIT} rows)")
    best = None
    for chosen in itertools.product((False, True), repeat=uni.size):
        basis = ~unilateral
        basis[uni] = chosen
        lam = basis_solution(W, b, basis)
        w = W @ lam - b
        worst = max(float(np.max(np.maximum(-lam[uni] * basis[uni], 0.0), initial=0.0)) / tol_l,
                    float(np.max(np.maximum(-w[uni] * ~basis[uni], 0.0), initial=0.0)) / tol_w)
        if best is None or worst < best[0]:
            best = (worst, lam, basis)
    if best[0] > 1.0 / LCP_TOL:  # off by more than the problem's own scale: no solution
        raise SolverError(f"the complementarity problem of {uni.size} touching ropes and contacts has no solution "
                          "(the constraints contradict each other, as a rope shorter than a rod beside it would)")
    return best[1], best[2]


def basis_solution(W, b, basis):
    """lambda of one basis: W_SS lambda_S = b_S on the basis rows S, minimum-norm where W_SS is singular (the seed's
    (31): the self-stresses of redundant rows take no share), lambda = 0 elsewhere."""
    lam = np.zeros(b.size)
    rows = np.flatnonzero(basis)
    if rows.size:
        lam[rows] = np.linalg.lstsq(W[np.ix_(rows, rows)], b[rows], rcond=SINGULAR_RCOND)[0]
    return lam
