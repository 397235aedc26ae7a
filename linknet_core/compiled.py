"""Compiled kernels: the right-hand side (9), the tension system (25)-(26), the projections onto (11)-(12),
and the RATTLE step loop, in numba.

The pure numpy path pays a few microseconds of Python overhead per array operation, which dominates for
small and medium scenes. Here whole intervals between two output/communication points run in compiled
code. The building blocks are shared by every compiled integrator (RATTLE and its compositions here,
the projected Runge-Kutta methods in :mod:`linknet_core.compiled_rk`):

* :func:`external_forces` - F_k of (9): gravity and constant forces (pre-summed), drag, spring-dampers;
* :func:`factor_tension_matrix` / :func:`solve_tension_system` - A of (25) assembled from the pair arrays
  and factored, on the pattern analysed once: general sparse LDL^T, or for chains a tridiagonal
  elimination in path order (no CSC indexing), chosen once per scene;
* :func:`accelerations` - dU/dt of (9) with the tensions of (25)-(26): the compiled right-hand side;
* :func:`project_positions` / :func:`project_velocities` - onto (11) and (12).

On the chain path the right-hand side, each Newton iteration of the position projection and the velocity
projection are each two sweeps along the path (tensions_chain, project_positions_chain,
project_velocities_chain): the elimination's dependency chain sets their speed, and the rest of the work
(unit vectors, A's entries, residuals, applying the multipliers) fits in its shadow.

They cover scenes whose A is non-singular along the way. Whenever a kernel cannot continue (a vanishing
pivot: singular configuration; a projection that does not contract; non-finite values) it stops and
reports it, and the caller redoes the rest of the interval on the numpy path, which has the
minimum-norm and exact-Newton fallbacks.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .ldl import kernel, ldl_factor_scheduled, ldl_solve, outlined_kernel

OK, PROJECTION_FAILED, SINGULAR, NON_FINITE, STEP_UNDERFLOW, TOO_MANY_STEPS = 0, 1, 2, 3, 4, 5
PIVOT_TOL = 1e-11  # as SymbolicLDL: a pivot below this times its diagonal entry means A is singular
EPS = 2.220446049250313e-16

# The entry points take a scene and its tension system as two tuples, built once per scene by CompiledScene:
#   scene  = (k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free)
#   system = (use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
#             row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax,
#             y_vals, solve_work)
# (the system holds the pattern of A, its factor storage and the factorisation's work arrays). An entry
# point unpacks them, allocates its scratch arrays and hands everything as plain arrays to a step loop
# compiled as a ``kernel`` (see linknet_core.ldl: inlined, no reference counting, never allocating), as are
# all the building blocks.


@kernel
def external_forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F):
    """F_k of (9) into F: F_base (gravity, constant and input forces) - drag U + spring-dampers; zero on anchors."""
    K = X.shape[0]
    for k in range(K):
        dk = drag[k]
        F[k, 0] = F_base[k, 0] - dk * U[k, 0]
        F[k, 1] = F_base[k, 1] - dk * U[k, 1]
        F[k, 2] = F_base[k, 2] - dk * U[k, 2]
    for s in range(sa.shape[0]):
        a, b = sa[s], sb[s]
        dx0 = X[b, 0] - X[a, 0]
        dx1 = X[b, 1] - X[a, 1]
        dx2 = X[b, 2] - X[a, 2]
        dist = np.sqrt(dx0 * dx0 + dx1 * dx1 + dx2 * dx2)
        if dist == 0.0:
            continue
        n0, n1, n2 = dx0 / dist, dx1 / dist, dx2 / dist
        rate = n0 * (U[b, 0] - U[a, 0]) + n1 * (U[b, 1] - U[a, 1]) + n2 * (U[b, 2] - U[a, 2])
        f = sk[s] * (dist - sr[s]) + sc[s] * rate
        F[a, 0] += f * n0
        F[a, 1] += f * n1
        F[a, 2] += f * n2
        F[b, 0] -= f * n0
        F[b, 1] -= f * n1
        F[b, 2] -= f * n2
    for k in range(K):
        if fixed[k]:
            F[k, 0] = 0.0
            F[k, 1] = 0.0
            F[k, 2] = 0.0


@kernel
def unit_vectors(X, k1, k2, inv_R, E):
    """E_l of (8) (inv_R = 1/R_l: a multiplication is several times cheaper than a division)."""
    for l in range(k1.shape[0]):
        a, b = k1[l], k2[l]
        r = inv_R[l]
        E[l, 0] = (X[b, 0] - X[a, 0]) * r
        E[l, 1] = (X[b, 1] - X[a, 1]) * r
        E[l, 2] = (X[b, 2] - X[a, 2]) * r


@kernel
def factor_chain(E, chain_order, chain_diag_weight, chain_off_weight, chain_sub, D, Dinv):
    """A of (25) for a chain, tridiagonal in path order, assembled and factored in one sweep.

    Diagonal (18) |E_l|^2 (1/M_k1 + 1/M_k2), off-diagonal S/M (E_l . E_l') of (21)-(22) between consecutive
    links; the LDL^T of a tridiagonal matrix is Thomas' elimination. Returns -1 or the first position whose
    pivot vanished (the same test as ldl_factor).
    """
    bad = -1
    previous = 0
    for i in range(chain_order.shape[0]):
        l = chain_order[i]
        e0, e1, e2 = E[l, 0], E[l, 1], E[l, 2]
        diag = chain_diag_weight[i] * (e0 * e0 + e1 * e1 + e2 * e2)
        dk = diag
        w = chain_off_weight[i]
        if w != 0.0:
            off = w * (E[previous, 0] * e0 + E[previous, 1] * e1 + E[previous, 2] * e2)
            m = off * Dinv[i - 1]
            chain_sub[i] = m
            dk -= m * off
        else:
            chain_sub[i] = 0.0
        D[i] = dk
        if dk > PIVOT_TOL * abs(diag):
            Dinv[i] = 1.0 / dk
        else:
            Dinv[i] = 0.0
            if bad == -1:
                bad = i
        previous = l
    return bad


@kernel
def solve_chain(b, chain_order, chain_sub, Dinv, w, out):
    """out = A^-1 b with the factorisation of :func:`factor_chain` (b, out in the original link numbering)."""
    n = chain_order.shape[0]
    if n == 0:
        return
    w[0] = b[chain_order[0]]
    for i in range(1, n):
        w[i] = b[chain_order[i]] - chain_sub[i] * w[i - 1]
    w[n - 1] *= Dinv[n - 1]
    out[chain_order[n - 1]] = w[n - 1]
    for i in range(n - 2, -1, -1):
        w[i] = w[i] * Dinv[i] - chain_sub[i + 1] * w[i + 1]
        out[chain_order[i]] = w[i]


@kernel
def _link_terms(X, U, F, a, b, r, ia, ib):
    """E_l of (8) and B_l of (26) for one link from k1 = a to k2 = b (r = 1/R_l, ia, ib = 1/M_a, 1/M_b)."""
    e0 = (X[b, 0] - X[a, 0]) * r
    e1 = (X[b, 1] - X[a, 1]) * r
    e2 = (X[b, 2] - X[a, 2]) * r
    du0 = U[b, 0] - U[a, 0]
    du1 = U[b, 1] - U[a, 1]
    du2 = U[b, 2] - U[a, 2]
    # B_l of (26): |U_k2 - U_k1|^2 / R_l + E_l . (F_k2/M_k2 - F_k1/M_k1)
    rhs = ((du0 * du0 + du1 * du1 + du2 * du2) * r + e0 * (F[b, 0] * ib - F[a, 0] * ia)
           + e1 * (F[b, 1] * ib - F[a, 1] * ia) + e2 * (F[b, 2] * ib - F[a, 2] * ia))
    return e0, e1, e2, rhs


@kernel
def tensions_chain(X, U, F, k1, k2, inv_R, inv_m, chain_order, chain_diag_weight, chain_off_weight, chain_sub, D, Dinv,
                   w, E, T, link_force, refactor):
    """The tensions of (25)-(26) for a chain in two sweeps along the path: the unit vectors (8), A's entries,
    its LDL^T pivots (unless ``refactor`` is False: the factorisation at X is there already), B of (26) and the
    forward substitution in one; the back substitution, adding each link's force T_l E_l of (9) to
    ``link_force`` (+ at k1, - at k2) as soon as T_l is known, in the other. Returns -1 or the first position
    whose pivot vanished."""
    L = chain_order.shape[0]
    bad = -1
    if refactor:  # two copies of the forward sweep: a test of refactor inside it costs ~30% of the sweep
        previous = 0
        for i in range(L):
            l = chain_order[i]
            a, b = k1[l], k2[l]
            e0, e1, e2, rhs = _link_terms(X, U, F, a, b, inv_R[l], inv_m[a], inv_m[b])
            E[l, 0] = e0
            E[l, 1] = e1
            E[l, 2] = e2
            diag = chain_diag_weight[i] * (e0 * e0 + e1 * e1 + e2 * e2)
            dk = diag
            wt = chain_off_weight[i]
            if wt != 0.0:
                off = wt * (E[previous, 0] * e0 + E[previous, 1] * e1 + E[previous, 2] * e2)
                m = off * Dinv[i - 1]
                chain_sub[i] = m
                dk -= m * off
                rhs -= m * w[i - 1]
            else:
                chain_sub[i] = 0.0
            D[i] = dk
            if dk > PIVOT_TOL * abs(diag):
                Dinv[i] = 1.0 / dk
            else:
                Dinv[i] = 0.0
                if bad == -1:
                    bad = i
            w[i] = rhs
            previous = l
    else:
        for i in range(L):
            l = chain_order[i]
            a, b = k1[l], k2[l]
            e0, e1, e2, rhs = _link_terms(X, U, F, a, b, inv_R[l], inv_m[a], inv_m[b])
            E[l, 0] = e0
            E[l, 1] = e1
            E[l, 2] = e2
            if i > 0:
                rhs -= chain_sub[i] * w[i - 1]
            w[i] = rhs
    if bad >= 0:
        return bad
    x = 0.0
    for i in range(L - 1, -1, -1):
        if i == L - 1:
            x = w[i] * Dinv[i]
        else:
            x = w[i] * Dinv[i] - chain_sub[i + 1] * x
        l = chain_order[i]
        T[l] = x
        a, b = k1[l], k2[l]
        f0, f1, f2 = x * E[l, 0], x * E[l, 1], x * E[l, 2]
        link_force[a, 0] += f0
        link_force[a, 1] += f1
        link_force[a, 2] += f2
        link_force[b, 0] -= f0
        link_force[b, 1] -= f1
        link_force[b, 2] -= f2
    return -1


@kernel
def project_positions_chain(Xc, E_dir, k1, k2, R, inv_R, inv_m, chain_order, chain_sub, Dinv, w, inv_scale, tol,
                            max_iter):
    """:func:`project_positions` for a chain, each Newton iteration in two sweeps along the path: the residuals
    of (11), the convergence test and the forward substitution in one; the back substitution, each
    multiplier applied to the positions as soon as it is known, in the other."""
    L = chain_order.shape[0]
    for l in range(L):  # per-link floor from the starting point, as Dynamics._residual_scale
        a, b = k1[l], k2[l]
        size = (max(abs(Xc[a, 0]), abs(Xc[a, 1]), abs(Xc[a, 2]))
                + max(abs(Xc[b, 0]), abs(Xc[b, 1]), abs(Xc[b, 2])))
        inv_scale[l] = 1.0 / (R[l] * tol + 8.0 * EPS * size)
    previous = 1e300
    for it in range(max_iter):
        worst = 0.0
        for i in range(L):
            l = chain_order[i]
            a, b = k1[l], k2[l]
            d0 = Xc[b, 0] - Xc[a, 0]
            d1 = Xc[b, 1] - Xc[a, 1]
            d2 = Xc[b, 2] - Xc[a, 2]
            phi = (d0 * d0 + d1 * d1 + d2 * d2 - R[l] * R[l]) * (0.5 * inv_R[l])
            r = abs(phi) * inv_scale[l]
            if not (r <= worst):
                worst = r
            if i > 0:
                phi -= chain_sub[i] * w[i - 1]
            w[i] = phi
        if worst <= 1.0:
            return True
        if not (worst < 1e300) or (it > 2 and worst > 0.3 * previous):
            return False
        previous = worst
        x = 0.0
        for i in range(L - 1, -1, -1):
            if i == L - 1:
                x = w[i] * Dinv[i]
            else:
                x = w[i] * Dinv[i] - chain_sub[i + 1] * x
            l = chain_order[i]
            a, b = k1[l], k2[l]
            fa, fb = x * inv_m[a], x * inv_m[b]
            Xc[a, 0] += fa * E_dir[l, 0]
            Xc[a, 1] += fa * E_dir[l, 1]
            Xc[a, 2] += fa * E_dir[l, 2]
            Xc[b, 0] -= fb * E_dir[l, 0]
            Xc[b, 1] -= fb * E_dir[l, 1]
            Xc[b, 2] -= fb * E_dir[l, 2]
    return False


@kernel
def project_velocities_chain(X, U, E, k1, k2, inv_R, inv_m, chain_order, chain_diag_weight, chain_off_weight,
                             chain_sub, D, Dinv, w):
    """:func:`project_velocities` for a chain in two sweeps along the path: unit vectors, A's entries and
    pivots, C U and the forward substitution in one; the back substitution with the correction of U in the
    other. Returns OK or SINGULAR."""
    L = chain_order.shape[0]
    bad = -1
    previous = 0
    for i in range(L):
        l = chain_order[i]
        a, b = k1[l], k2[l]
        r = inv_R[l]
        e0 = (X[b, 0] - X[a, 0]) * r
        e1 = (X[b, 1] - X[a, 1]) * r
        e2 = (X[b, 2] - X[a, 2]) * r
        E[l, 0] = e0
        E[l, 1] = e1
        E[l, 2] = e2
        rhs = e0 * (U[a, 0] - U[b, 0]) + e1 * (U[a, 1] - U[b, 1]) + e2 * (U[a, 2] - U[b, 2])
        diag = chain_diag_weight[i] * (e0 * e0 + e1 * e1 + e2 * e2)
        dk = diag
        wt = chain_off_weight[i]
        if wt != 0.0:
            off = wt * (E[previous, 0] * e0 + E[previous, 1] * e1 + E[previous, 2] * e2)
            m = off * Dinv[i - 1]
            chain_sub[i] = m
            dk -= m * off
            rhs -= m * w[i - 1]
        else:
            chain_sub[i] = 0.0
        D[i] = dk
        if dk > PIVOT_TOL * abs(diag):
            Dinv[i] = 1.0 / dk
        else:
            Dinv[i] = 0.0
            if bad == -1:
                bad = i
        w[i] = rhs
        previous = l
    if bad >= 0:
        return SINGULAR
    x = 0.0
    for i in range(L - 1, -1, -1):
        if i == L - 1:
            x = w[i] * Dinv[i]
        else:
            x = w[i] * Dinv[i] - chain_sub[i + 1] * x
        l = chain_order[i]
        a, b = k1[l], k2[l]
        fa, fb = x * inv_m[a], x * inv_m[b]
        U[a, 0] -= fa * E[l, 0]
        U[a, 1] -= fa * E[l, 1]
        U[a, 2] -= fa * E[l, 2]
        U[b, 0] += fb * E[l, 0]
        U[b, 1] += fb * E[l, 1]
        U[b, 2] += fb * E[l, 2]
    return OK


@kernel
def factor_general(E, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start,
                   row_col, row_slot, Ax, y_vals):
    """A of (25) assembled from the pair arrays on the fixed pattern and factored by sparse LDL^T."""
    for p in range(Ax.shape[0]):
        Ax[p] = 0.0
    for p in range(pair_first.shape[0]):
        a, b = pair_first[p], pair_second[p]
        Ax[pair_slot[p]] += pair_weight[p] * (E[a, 0] * E[b, 0] + E[a, 1] * E[b, 1] + E[a, 2] * E[b, 2])
    return ldl_factor_scheduled(Ap.shape[0] - 1, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot,
                                PIVOT_TOL, y_vals)


@kernel
def solve_general(b, ordering, Lp, Li, Lx, Dinv, w, out):
    """out = A^-1 b with the factorisation of :func:`factor_general` (b, out in the original link numbering)."""
    n = ordering.shape[0]
    for i in range(n):
        w[i] = b[ordering[i]]
    ldl_solve(n, Lp, Li, Lx, Dinv, w)
    for i in range(n):
        out[ordering[i]] = w[i]


@kernel
def factor_tension_matrix(E, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx,
                          D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                          chain_sub, Ax, y_vals, solve_work):
    """Assemble A of (25) from the unit vectors E and factor it in place, on the path chosen once per scene.

    Returns -1, or the first (elimination-order) column whose pivot vanished: singular configuration.
    """
    if use_chain:
        return factor_chain(E, chain_order, chain_diag_weight, chain_off_weight, chain_sub, D, Dinv)
    return factor_general(E, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start,
                          row_col, row_slot, Ax, y_vals)


@kernel
def solve_tension_system(b, out, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                         Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                         chain_sub, Ax, y_vals, solve_work):
    """out = A^-1 b with the last factorisation (b and out in the original link numbering)."""
    if use_chain:
        solve_chain(b, chain_order, chain_sub, Dinv, solve_work, out)
    else:
        solve_general(b, ordering, Lp, Li, Lx, Dinv, solve_work, out)


@kernel
def add_correction(E, mu, k1, k2, inv_m, scale, V):
    """V += scale * M^-1 C^T mu (C from unit vectors E): +mu_l E_l on k1(l), -mu_l E_l on k2(l), as in (9)."""
    for l in range(k1.shape[0]):
        a, b = k1[l], k2[l]
        f = scale * mu[l]
        fa, fb = f * inv_m[a], f * inv_m[b]
        V[a, 0] += fa * E[l, 0]
        V[a, 1] += fa * E[l, 1]
        V[a, 2] += fa * E[l, 2]
        V[b, 0] -= fb * E[l, 0]
        V[b, 1] -= fb * E[l, 1]
        V[b, 2] -= fb * E[l, 2]


@kernel
def accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain, ordering,
                  pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col,
                  row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F,
                  B, acc, T, refactor):
    """The compiled right-hand side: accelerations (9) into acc, tensions (25)-(26) into T.

    Scratch: E (L,3) receives the unit vectors (8), F (K,3) the external forces, B (L,) the right-hand side
    (26). The factorisation of A(X) is left in the system arrays; with ``refactor`` False the caller promises
    that the factorisation there is already that at X. Returns OK, SINGULAR (a vanishing pivot) or NON_FINITE.
    """
    K = X.shape[0]
    L = k1.shape[0]
    external_forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
    for k in range(K):
        acc[k, 0] = F[k, 0]
        acc[k, 1] = F[k, 1]
        acc[k, 2] = F[k, 2]
    if L > 0 and use_chain:
        # tensions and their forces on the masses (added to acc) in two sweeps along the path
        if tensions_chain(X, U, F, k1, k2, inv_R, inv_m, chain_order, chain_diag_weight, chain_off_weight, chain_sub, D,
                          Dinv, solve_work, E, T, acc, refactor) >= 0:
            return SINGULAR
    elif L > 0:
        unit_vectors(X, k1, k2, inv_R, E)
        if refactor and factor_tension_matrix(E, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot,
                                              Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                              chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals,
                                              solve_work) >= 0:
            return SINGULAR
        for l in range(L):
            # B_l of (26): |U_k2 - U_k1|^2 / R_l + E_l . (F_k2/M_k2 - F_k1/M_k1)
            a, b = k1[l], k2[l]
            ia, ib = inv_m[a], inv_m[b]
            du0 = U[b, 0] - U[a, 0]
            du1 = U[b, 1] - U[a, 1]
            du2 = U[b, 2] - U[a, 2]
            B[l] = ((du0 * du0 + du1 * du1 + du2 * du2) * inv_R[l]
                    + E[l, 0] * (F[b, 0] * ib - F[a, 0] * ia) + E[l, 1] * (F[b, 1] * ib - F[a, 1] * ia)
                    + E[l, 2] * (F[b, 2] * ib - F[a, 2] * ia))
        solve_tension_system(B, T, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                             Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                             chain_off_weight, chain_sub, Ax, y_vals, solve_work)
        for l in range(L):
            # (9): link l pulls k1(l) by +T_l E_l and k2(l) by -T_l E_l
            a, b = k1[l], k2[l]
            t = T[l]
            f0, f1, f2 = t * E[l, 0], t * E[l, 1], t * E[l, 2]
            acc[a, 0] += f0
            acc[a, 1] += f1
            acc[a, 2] += f2
            acc[b, 0] -= f0
            acc[b, 1] -= f1
            acc[b, 2] -= f2
    total = 0.0
    for k in range(K):
        im = inv_m[k]
        acc[k, 0] *= im
        acc[k, 1] *= im
        acc[k, 2] *= im
        total += acc[k, 0] + acc[k, 1] + acc[k, 2]
    if not np.isfinite(total):
        return NON_FINITE
    return OK


@kernel
def project_positions(Xc, E_dir, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain, ordering,
                      pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col,
                      row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu,
                      phi, inv_scale, tol, max_iter):
    """Move Xc onto (11) along M^-1 C(E_dir)^T mu, in place: simplified Newton with A(E_dir), already factored.

    The same iteration and stopping rule as Dynamics.project_positions (tolerance tol relative to R_l, never
    below the round-off floor of |X_k2 - X_k1|; give up when it contracts too slowly). Scratch: mu, phi,
    inv_scale (L,). Returns True if it converged.
    """
    L = k1.shape[0]
    if L == 0:
        return True
    if use_chain:
        return project_positions_chain(Xc, E_dir, k1, k2, R, inv_R, inv_m, chain_order, chain_sub, Dinv, solve_work,
                                       inv_scale, tol, max_iter)
    for l in range(L):  # per-link floor from the starting point, as Dynamics._residual_scale
        a, b = k1[l], k2[l]
        size = (max(abs(Xc[a, 0]), abs(Xc[a, 1]), abs(Xc[a, 2]))
                + max(abs(Xc[b, 0]), abs(Xc[b, 1]), abs(Xc[b, 2])))
        inv_scale[l] = 1.0 / (R[l] * tol + 8.0 * EPS * size)
    previous = 1e300
    for it in range(max_iter):
        worst = 0.0
        for l in range(L):
            a, b = k1[l], k2[l]
            d0 = Xc[b, 0] - Xc[a, 0]
            d1 = Xc[b, 1] - Xc[a, 1]
            d2 = Xc[b, 2] - Xc[a, 2]
            phi[l] = (d0 * d0 + d1 * d1 + d2 * d2 - R[l] * R[l]) * (0.5 * inv_R[l])
            r = abs(phi[l]) * inv_scale[l]
            if not (r <= worst):
                worst = r
        if worst <= 1.0:
            return True
        if not (worst < 1e300) or (it > 2 and worst > 0.3 * previous):
            return False
        previous = worst
        solve_tension_system(phi, mu, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp,
                             Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                             chain_off_weight, chain_sub, Ax, y_vals, solve_work)
        add_correction(E_dir, mu, k1, k2, inv_m, 1.0, Xc)
    return False


@kernel
def project_velocities(X, U, E, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain, ordering,
                       pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col,
                       row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work,
                       mu, rhs):
    """Closest U satisfying (12) at X in the mass metric, in place: U -= M^-1 C^T mu with A(X) mu = C U.

    Factors A(X) (left in the system arrays for the caller) and leaves the unit vectors at X in E.
    Scratch: mu, rhs (L,). Returns OK or SINGULAR.
    """
    L = k1.shape[0]
    if L == 0:
        return OK
    if use_chain:
        return project_velocities_chain(X, U, E, k1, k2, inv_R, inv_m, chain_order, chain_diag_weight, chain_off_weight,
                                        chain_sub, D, Dinv, solve_work)
    unit_vectors(X, k1, k2, inv_R, E)
    if factor_tension_matrix(E, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                             Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                             chain_off_weight, chain_sub, Ax, y_vals, solve_work) >= 0:
        return SINGULAR
    for l in range(L):
        a, b = k1[l], k2[l]
        rhs[l] = E[l, 0] * (U[a, 0] - U[b, 0]) + E[l, 1] * (U[a, 1] - U[b, 1]) + E[l, 2] * (U[a, 2] - U[b, 2])
    solve_tension_system(rhs, mu, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                         Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                         chain_sub, Ax, y_vals, solve_work)
    add_correction(E, mu, k1, k2, inv_m, -1.0, U)
    return OK


def rattle_scratch(K, L):
    """Scratch arrays of :func:`rattle_advance` (allocated once per scene), in the order of :func:`_rattle_steps`."""
    return (np.empty((L, 3)), np.empty((L, 3)), np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3)),
            np.empty(L), np.empty(L), np.empty(L))


def rattle_advance(X, U, n_steps, h, gammas, F_base, scene, system, scratch, tol, max_iter):
    """Advance (X, U) in place by n_steps steps of size h, each a composition of RATTLE stages gammas.

    Returns (status, completed steps). On a non-zero status X and U are partially advanced: the caller
    restores its copy and takes the numpy path. (A Python function: a compiled wrapper unpacking the tuples
    would make numba optimise the whole inlined step loop a second time when compiling it.)
    """
    return _rattle_steps(X, U, n_steps, h, gammas, F_base, *scene, *system, *scratch, tol, max_iter)


@outlined_kernel
def _rattle_steps(X, U, n_steps, h, gammas, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
                  use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
                  row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals,
                  solve_work, E0, E1, F, Uh, Xc, U_iterate, mu, phi, scale, tol, max_iter):
    """The step loop of :func:`rattle_advance` (scratch: E0, E1 (L,3); F, Uh, Xc, U_iterate (K,3); mu, phi,
    scale (L,))."""
    K = X.shape[0]
    L = k1.shape[0]
    # drag or dampers: the second half kick is implicit in U_{n+1} (fixed-point iteration below), which keeps
    # the step symmetric and so second order; explicit in the half-step velocity it is only first order
    velocity_dependent = False
    for k in range(K):
        if drag[k] != 0.0:
            velocity_dependent = True
    for s in range(sc.shape[0]):
        if sc[s] != 0.0:
            velocity_dependent = True
    unit_vectors(X, k1, k2, inv_R, E0)
    if L > 0 and factor_tension_matrix(E0, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai,
                                       Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                       chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work) >= 0:
        return SINGULAR, 0
    for step in range(n_steps):
        for g in range(gammas.shape[0]):
            hs = gammas[g] * h
            # kick and drift
            external_forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
            for k in range(K):
                for d in range(3):
                    Uh[k, d] = U[k, d] + 0.5 * hs * inv_m[k] * F[k, d]
                    Xc[k, d] = X[k, d] + hs * Uh[k, d]
            # position stage: Xc + M^-1 C(X)^T mu on (11), simplified Newton with A(X) factored
            if not project_positions(Xc, E0, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain,
                                     ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
                                     Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                                     chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu, phi, scale, tol,
                                     max_iter):
                return PROJECTION_FAILED, step
            for k in range(K):
                for d in range(3):
                    Uh[k, d] = (Xc[k, d] - X[k, d]) / hs
            # second kick, then the velocity projection onto (12) at the new positions
            external_forces(Xc, Uh, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
            for k in range(K):
                for d in range(3):
                    U[k, d] = Uh[k, d] + 0.5 * hs * inv_m[k] * F[k, d]
                    X[k, d] = Xc[k, d]
            if project_velocities(X, U, E1, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain,
                                  ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
                                  Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                                  chain_sub, Ax, y_vals, solve_work, mu, phi) != OK:
                return SINGULAR, step
            if velocity_dependent:
                # U_{n+1} = P(U_half + hs/2 M^-1 F(X_{n+1}, U_{n+1})): contraction factor ~ hs c / (2 m)
                converged = False
                for it in range(60):
                    external_forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
                    size = 0.0
                    for k in range(K):
                        for d in range(3):
                            U_iterate[k, d] = Uh[k, d] + 0.5 * hs * inv_m[k] * F[k, d]
                            size = max(size, abs(U[k, d]))
                    if project_velocities(X, U_iterate, E1, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc,
                                          free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot,
                                          Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                          chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu,
                                          phi) != OK:
                        return SINGULAR, step
                    change = 0.0
                    for k in range(K):
                        for d in range(3):
                            change = max(change, abs(U_iterate[k, d] - U[k, d]))
                            U[k, d] = U_iterate[k, d]
                    if change <= 4e-16 * size or change == 0.0:
                        converged = True
                        break
                if not converged:
                    return PROJECTION_FAILED, step
            E0, E1 = E1, E0  # the factorisation at X is the next stage's A(X)
        for k in range(K):
            for d in range(3):
                if not np.isfinite(X[k, d]) or not np.isfinite(U[k, d]):
                    return NON_FINITE, step
    return OK, n_steps


def accelerations_repeated(n_evals, X, U, F_base, scene, system, acc, T):
    """n_evals evaluations of :func:`accelerations` in a row at the same state, in one compiled loop (one
    evaluation for tests; many for benchmarks: the right-hand side the compiled integrators call, timed
    without the Python call). Leaves the last result in acc and T; returns a checksum."""
    K, L = X.shape[0], T.shape[0]
    return _accelerations_loop(n_evals, X, U, F_base, *scene, *system, np.empty((L, 3)), np.empty((K, 3)),
                               np.empty(L), acc, T, n_evals > 0)


@outlined_kernel
def _accelerations_loop(n_evals, X, U, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
                        use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
                        Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub,
                        Ax, y_vals, solve_work, E, F, B, acc, T, refactor):
    """The loop of :func:`accelerations_repeated`: returns the status of the last evaluation when n_evals is 1,
    else a checksum (``refactor`` is a runtime True: a literal would compile another accelerations)."""
    checksum = 0.0
    status = OK
    for i in range(n_evals):
        status = accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain,
                               ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
                               row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                               chain_sub, Ax, y_vals, solve_work, E, F, B, acc, T, refactor)
        checksum += acc[acc.shape[0] - 1, 2]
    if n_evals == 1:
        return float(status)
    return checksum


def chain_elimination(scene, assembly):
    """Path order of the links of a 'chain' scene and the weights of its tridiagonal A (setup, once).

    Returns (order, diagonal weights, off-diagonal weights to the previous link in the order), or None
    if A is not tridiagonal in that order (then the general sparse path is used). The links of each path
    (a component of the graph cut at the anchors) come in the structure's leaves-first order, which for a
    path is path order; the test below checks it.
    """
    L = scene.L
    if L == 0:
        return None
    first, second, weight = assembly.pair_first, assembly.pair_second, assembly.pair_weight
    off = first != second
    graph = sp.coo_matrix((np.ones(int(off.sum())), (first[off], second[off])), shape=(L, L))
    _, component = connected_components(graph, directed=False)
    order = np.lexsort((assembly.position_of, component)).astype(np.int64)
    position = np.empty(L, np.int64)
    position[order] = np.arange(L)
    p1, p2 = position[first[off]], position[second[off]]
    if np.any(np.abs(p1 - p2) != 1):
        return None
    diag_weight = np.bincount(position[first[~off]], weights=weight[~off], minlength=L)
    off_weight = np.zeros(L)
    np.add.at(off_weight, np.maximum(p1, p2), weight[off])
    return order, diag_weight, off_weight


class CompiledScene:
    """The arrays of one scene as the compiled kernels take them (built once per Dynamics).

    Every array is C-contiguous with a fixed dtype, so each kernel compiles once. The factor storage and
    work arrays are private to this object: the kernels must not disturb the numpy path's cached
    factorisation. ``use_chain``: None picks the tridiagonal path for chain scenes (False forces the
    general sparse path, for tests).
    """

    def __init__(self, dyn, use_chain: bool | None = None):
        scene = dyn.scene
        asm = dyn.solver.assembly
        ldl = dyn.solver.ldl
        s = scene.springs
        f8 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
        i8 = lambda a: np.ascontiguousarray(a, np.int64)  # noqa: E731
        self.dyn = dyn
        self.K, self.L = scene.K, scene.L
        self.scene = (i8(scene.k1), i8(scene.k2), f8(scene.length), f8(1.0 / scene.length), f8(scene.inv_mass),
                      np.ascontiguousarray(scene.fixed, np.bool_), f8(scene.drag), i8(s.a), i8(s.b), f8(s.stiffness),
                      f8(s.rest_length), f8(s.damping), i8(scene.free_indices))
        chain = chain_elimination(scene, asm) if dyn.structure.kind == "chain" else None
        if use_chain is None:
            use_chain = chain is not None
        if use_chain and chain is None:
            raise ValueError("the chain-specialised path needs a scene whose A is tridiagonal in path order")
        order, diag_weight, off_weight = chain if use_chain else (np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        self.use_chain = bool(use_chain)
        n = max(scene.L, 1)
        self.system = (self.use_chain, i8(asm.ordering), i8(asm.pair_first), i8(asm.pair_second),
                       f8(asm.pair_weight), i8(asm.pair_slot), i8(asm.Ap), i8(asm.Ai), i8(ldl.Lp), i8(ldl.Li).copy(),
                       ldl.Lx.copy(), ldl.D.copy(), ldl.Dinv.copy(), i8(ldl.row_start), i8(ldl.row_col),
                       i8(ldl.row_slot), i8(order), f8(diag_weight), f8(off_weight), np.zeros(n),
                       np.zeros(max(asm.Ai.shape[0], 1)), np.zeros(n), np.zeros(n))
        free_mass = np.where(scene.fixed, 0.0, scene.mass)
        self.F_scene = free_mass[:, None] * scene.gravity[None, :] + scene.force

    def base_forces(self, F_input) -> np.ndarray:
        """Gravity, constant forces and the held input: the part of F_k of (9) fixed over an interval."""
        F = self.F_scene if F_input is None else self.F_scene + F_input
        return np.ascontiguousarray(F, np.float64)

    def accelerations(self, X, U, F_input=None):
        """One compiled right-hand side evaluation from Python (tests, benchmarks): (status, acc, T)."""
        acc = np.empty((self.K, 3))
        T = np.zeros(self.L)
        X = np.ascontiguousarray(X, np.float64)
        U = np.ascontiguousarray(U, np.float64)
        status = int(accelerations_repeated(1, X, U, self.base_forces(F_input), self.scene, self.system, acc, T))
        return status, acc, T


class CompiledRattle(CompiledScene):
    """:func:`rattle_advance` for one scene."""

    def __init__(self, dyn, use_chain: bool | None = None):
        super().__init__(dyn, use_chain=use_chain)
        self.scratch = rattle_scratch(self.K, self.L)

    def advance(self, X, U, n_steps, h, gammas, F_input, tol):
        Xw = np.array(X, dtype=np.float64, copy=True, order="C")
        Uw = np.array(U, dtype=np.float64, copy=True, order="C")
        status, done = rattle_advance(Xw, Uw, int(n_steps), float(h), np.asarray(gammas, np.float64),
                                      self.base_forces(F_input), self.scene, self.system, self.scratch, float(tol), 50)
        return status, Xw, Uw


def supports(dyn) -> bool:
    """The compiled kernels handle the LDL^T structures (chain, tree, general), not the redundant one."""
    return dyn.structure.kind != "redundant" and hasattr(dyn.solver, "ldl")
