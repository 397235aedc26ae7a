"""The numba kernels of the compiled paths, written once over the number of components DIM of a vector.

DIM is a module constant, so numba compiles it as a literal: every ``for d in range(DIM)`` is unrolled,
exactly as hand-written per-component code (the accumulators start at -0.0, which LLVM drops: the
floating-point operations and their order are those of the unrolled sums). This module is the 3-D one.
:mod:`linknet_core.compiled_kernels_2d` is generated from it with DIM = 2 (``python -m
linknet_core.compiled --write-planar``; tests/test_core_compiled_planar.py checks that it is in sync): planar
scenes run in the coordinates of their plane, two components instead of three. Two real modules rather than
closures or a literal argument, so that numba's on-disk cache keeps working (a closure's cache key pickles
the compiled functions it captures, which differ in every process) and the 3-D kernels are the same code as
before.

Building blocks (all inlined into the step loops; see linknet_core.ldl for ``kernel``):

* :func:`scene_forces` - F_k of (9): the per-interval base forces (gravity, constant and input forces, zero
  on anchors) minus drag on the masses that have it (index array) plus the spring-dampers; only called when
  the scene has drag or springs, else the base forces are the forces;
* :func:`factor_tension_matrix` / :func:`solve_tension_system` - A of (25) assembled from the pair arrays
  and factored on the pattern analysed once: general sparse LDL^T, or for chains a tridiagonal elimination
  in path order, chosen once per scene;
* :func:`accelerations` - dU/dt of (9) with the tensions of (25)-(26): the compiled right-hand side;
* :func:`project_positions` / :func:`project_velocities` - onto (11) and (12);
* the step loops :func:`_rattle_steps` (RATTLE and its compositions) and :func:`_rk_steps` (embedded
  explicit Runge-Kutta), and for planar scenes their entries :func:`_rattle_steps_in_plane` /
  :func:`_rk_steps_in_plane`, which map the (K,3) state into the plane's coordinates, refuse (LEFT_PLANE)
  a state or an input force that has left the plane, and map the result back.

On the chain path the right-hand side, each Newton iteration of the position projection and the velocity
projection are each two sweeps along the path: the elimination's dependency chain sets their speed, and the
rest of the work (unit vectors, A's entries, residuals, applying the multipliers) fits in its shadow.

Whenever a kernel cannot continue (a vanishing pivot: singular configuration; a projection that does not
contract; non-finite values) it stops and reports it, and the caller redoes the rest of the interval on the
numpy path, which has the minimum-norm and exact-Newton fallbacks.
"""
from __future__ import annotations

import numpy as np

from .ldl import kernel, ldl_factor_scheduled, ldl_solve, outlined_kernel

DIM = 3  # components of a vector (the generated planar module has 2)

OK, PROJECTION_FAILED, SINGULAR, NON_FINITE, STEP_UNDERFLOW, TOO_MANY_STEPS, LEFT_PLANE = 0, 1, 2, 3, 4, 5, 6
PIVOT_TOL = 1e-11  # as SymbolicLDL: a pivot below this times its diagonal entry means A is singular
EPS = 2.220446049250313e-16
RMS_ERROR, HAIRER_ERROR = 0, 1  # the error norms of ProjectedRungeKutta.error_norm ('rms', 'hairer')

# The entry points take a scene and its tension system as two tuples, built once per scene by
# linknet_core.compiled.CompiledScene:
#   scene  = (k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc, free)
#   system = (use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
#             row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax,
#             y_vals, solve_work)
# (fixed_idx: the anchored masses; drag_idx, drag_coef: the free masses with drag and their coefficients; the
# system holds the pattern of A, its factor storage and the factorisation's work arrays). Neither depends on
# DIM. The Python entry points unpack them and hand everything as plain arrays to a step loop compiled as an
# ``outlined_kernel``; the building blocks are ``kernel``s (inlined, no reference counting, never allocating).


# ------------------------------------------------------------------------------------------------ forces
@kernel
def zero_rows(F, rows):
    """F[k] = 0 for k in rows (the anchored masses: no force acts on them)."""
    for i in range(rows.shape[0]):
        k = rows[i]
        for d in range(DIM):
            F[k, d] = 0.0


@kernel
def has_state_forces(drag_idx, sa):
    """Whether the forces depend on the state (drag or springs): else F of (9) is the base force all interval."""
    return drag_idx.shape[0] > 0 or sa.shape[0] > 0


@kernel
def scene_forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F):
    """F_k of (9) into F: F_base (gravity, constant and input forces, zero on anchors) - drag U on the masses
    with drag + spring-dampers; zero on anchors."""
    K = X.shape[0]
    for k in range(K):
        for d in range(DIM):
            F[k, d] = F_base[k, d]
    for i in range(drag_idx.shape[0]):
        k = drag_idx[i]
        c = drag_coef[i]
        for d in range(DIM):
            F[k, d] -= c * U[k, d]
    n_springs = sa.shape[0]
    for s in range(n_springs):
        a, b = sa[s], sb[s]
        sq = -0.0
        for d in range(DIM):
            dx = X[b, d] - X[a, d]
            sq += dx * dx
        dist = np.sqrt(sq)
        if dist == 0.0:
            continue
        inv = 1.0 / dist
        rate = -0.0
        for d in range(DIM):
            rate += (X[b, d] - X[a, d]) * inv * (U[b, d] - U[a, d])
        f = sk[s] * (dist - sr[s]) + sc[s] * rate
        for d in range(DIM):
            fn = f * ((X[b, d] - X[a, d]) * inv)
            F[a, d] += fn
            F[b, d] -= fn
    if n_springs > 0:  # springs may pull on anchors
        zero_rows(F, fixed_idx)


# ------------------------------------------------------------------------------------------------ tension system
@kernel
def unit_vectors(X, k1, k2, inv_R, E):
    """E_l of (8) (inv_R = 1/R_l: a multiplication is several times cheaper than a division)."""
    for l in range(k1.shape[0]):
        a, b = k1[l], k2[l]
        r = inv_R[l]
        for d in range(DIM):
            E[l, d] = (X[b, d] - X[a, d]) * r


@kernel
def _dot_rows(E, p, q):
    """E_p . E_q"""
    s = -0.0
    for d in range(DIM):
        s += E[p, d] * E[q, d]
    return s


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
        diag = chain_diag_weight[i] * _dot_rows(E, l, l)
        dk = diag
        w = chain_off_weight[i]
        if w != 0.0:
            off = w * _dot_rows(E, previous, l)
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
def _link_terms(X, U, F, a, b, r, ia, ib, E, l):
    """E_l of (8) into E[l] and B_l of (26) for one link from k1 = a to k2 = b (r = 1/R_l, ia, ib = 1/M_a, 1/M_b);
    returns (|E_l|^2, B_l)."""
    sq = -0.0
    du2 = -0.0
    for d in range(DIM):
        e = (X[b, d] - X[a, d]) * r
        E[l, d] = e
        sq += e * e
        du = U[b, d] - U[a, d]
        du2 += du * du
    # B_l of (26): |U_k2 - U_k1|^2 / R_l + E_l . (F_k2/M_k2 - F_k1/M_k1)
    rhs = du2 * r
    for d in range(DIM):
        rhs += E[l, d] * (F[b, d] * ib - F[a, d] * ia)
    return sq, rhs


@kernel
def _scatter_link_force(x, E, l, a, b, acc):
    """(9): link l pulls k1(l) = a by +x E_l and k2(l) = b by -x E_l."""
    for d in range(DIM):
        f = x * E[l, d]
        acc[a, d] += f
        acc[b, d] -= f


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
            sq, rhs = _link_terms(X, U, F, a, b, inv_R[l], inv_m[a], inv_m[b], E, l)
            diag = chain_diag_weight[i] * sq
            dk = diag
            wt = chain_off_weight[i]
            if wt != 0.0:
                off = wt * _dot_rows(E, previous, l)
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
            sq, rhs = _link_terms(X, U, F, a, b, inv_R[l], inv_m[a], inv_m[b], E, l)
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
        _scatter_link_force(x, E, l, k1[l], k2[l], link_force)
    return -1


@kernel
def _residual_floor(Xc, k1, k2, R, tol, inv_scale):
    """Per-link convergence scale of the position projection, as Dynamics._residual_scale: the tolerance
    relative to R_l, never below the round-off floor of |X_k2 - X_k1| (from the starting point)."""
    for l in range(k1.shape[0]):
        a, b = k1[l], k2[l]
        size_a = 0.0
        size_b = 0.0
        for d in range(DIM):
            size_a = max(size_a, abs(Xc[a, d]))
            size_b = max(size_b, abs(Xc[b, d]))
        inv_scale[l] = 1.0 / (R[l] * tol + 8.0 * EPS * (size_a + size_b))


@kernel
def _length_residual(Xc, a, b, R_l, inv_R_l):
    """phi_l of (11) scaled to a length: (|X_b - X_a|^2 - R_l^2) / (2 R_l)."""
    sq = -0.0
    for d in range(DIM):
        dx = Xc[b, d] - Xc[a, d]
        sq += dx * dx
    return (sq - R_l * R_l) * (0.5 * inv_R_l)


@kernel
def project_positions_chain(Xc, E_dir, k1, k2, R, inv_R, inv_m, chain_order, chain_sub, Dinv, w, inv_scale, tol,
                            max_iter):
    """:func:`project_positions` for a chain, each Newton iteration in two sweeps along the path: the residuals
    of (11), the convergence test and the forward substitution in one; the back substitution, each
    multiplier applied to the positions as soon as it is known, in the other."""
    L = chain_order.shape[0]
    _residual_floor(Xc, k1, k2, R, tol, inv_scale)
    previous = 1e300
    for it in range(max_iter):
        worst = 0.0
        for i in range(L):
            l = chain_order[i]
            phi = _length_residual(Xc, k1[l], k2[l], R[l], inv_R[l])
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
            for d in range(DIM):
                Xc[a, d] += fa * E_dir[l, d]
                Xc[b, d] -= fb * E_dir[l, d]
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
        sq = -0.0
        rhs = -0.0
        for d in range(DIM):
            e = (X[b, d] - X[a, d]) * r
            E[l, d] = e
            sq += e * e
            rhs += e * (U[a, d] - U[b, d])
        diag = chain_diag_weight[i] * sq
        dk = diag
        wt = chain_off_weight[i]
        if wt != 0.0:
            off = wt * _dot_rows(E, previous, l)
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
        for d in range(DIM):
            U[a, d] -= fa * E[l, d]
            U[b, d] += fb * E[l, d]
    return OK


@kernel
def factor_general(E, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start,
                   row_col, row_slot, Ax, y_vals):
    """A of (25) assembled from the pair arrays on the fixed pattern and factored by sparse LDL^T."""
    for p in range(Ax.shape[0]):
        Ax[p] = 0.0
    for p in range(pair_first.shape[0]):
        Ax[pair_slot[p]] += pair_weight[p] * _dot_rows(E, pair_first[p], pair_second[p])
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
        for d in range(DIM):
            V[a, d] += fa * E[l, d]
            V[b, d] -= fb * E[l, d]


# ------------------------------------------------------------------------------------------------ right-hand side
@kernel
def accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc, free,
                  use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
                  row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals,
                  solve_work, E, F, B, acc, T, refactor):
    """The compiled right-hand side: accelerations (9) into acc, tensions (25)-(26) into T.

    F_base: gravity, constant and input forces, zero on anchors. Scratch: E (L,DIM) receives the unit vectors
    (8), F (K,DIM) the external forces (only computed when the scene has drag or springs; else F_base is
    used as it is), B (L,) the right-hand side (26). The factorisation of A(X) is left in the system arrays;
    with ``refactor`` False the caller promises that the factorisation there is already that at X. Returns
    OK, SINGULAR (a vanishing pivot) or NON_FINITE.
    """
    K = X.shape[0]
    L = k1.shape[0]
    Fx = F_base
    if has_state_forces(drag_idx, sa):
        scene_forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
        Fx = F
    for k in range(K):
        for d in range(DIM):
            acc[k, d] = Fx[k, d]
    if L > 0 and use_chain:
        # tensions and their forces on the masses (added to acc) in two sweeps along the path
        if tensions_chain(X, U, Fx, k1, k2, inv_R, inv_m, chain_order, chain_diag_weight, chain_off_weight, chain_sub,
                          D, Dinv, solve_work, E, T, acc, refactor) >= 0:
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
            du2 = -0.0
            for d in range(DIM):
                du = U[b, d] - U[a, d]
                du2 += du * du
            rhs = du2 * inv_R[l]
            for d in range(DIM):
                rhs += E[l, d] * (Fx[b, d] * ib - Fx[a, d] * ia)
            B[l] = rhs
        solve_tension_system(B, T, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                             Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                             chain_off_weight, chain_sub, Ax, y_vals, solve_work)
        for l in range(L):
            _scatter_link_force(T[l], E, l, k1[l], k2[l], acc)
    total = 0.0
    for k in range(K):
        im = inv_m[k]
        for d in range(DIM):
            acc[k, d] *= im
            total += acc[k, d]
    if not np.isfinite(total):
        return NON_FINITE
    return OK


# ------------------------------------------------------------------------------------------------ projections
@kernel
def project_positions(Xc, E_dir, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc, free,
                      use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
                      row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax,
                      y_vals, solve_work, mu, phi, inv_scale, tol, max_iter):
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
    _residual_floor(Xc, k1, k2, R, tol, inv_scale)
    previous = 1e300
    for it in range(max_iter):
        worst = 0.0
        for l in range(L):
            phi[l] = _length_residual(Xc, k1[l], k2[l], R[l], inv_R[l])
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
def project_velocities(X, U, E, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc, free,
                       use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
                       Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub,
                       Ax, y_vals, solve_work, mu, rhs):
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
        s = -0.0
        for d in range(DIM):
            s += E[l, d] * (U[a, d] - U[b, d])
        rhs[l] = s
    solve_tension_system(rhs, mu, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                         Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                         chain_sub, Ax, y_vals, solve_work)
    add_correction(E, mu, k1, k2, inv_m, -1.0, U)
    return OK


# ------------------------------------------------------------------------------------------------ RATTLE loop
@outlined_kernel
def _rattle_steps(X, U, n_steps, h, gammas, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb,
                  sk, sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp,
                  Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                  chain_sub, Ax, y_vals, solve_work, E0, E1, F, Uh, Xc, U_iterate, mu, phi, scale, tol, max_iter):
    """n_steps steps of size h, each a composition of RATTLE stages gammas, on (X, U) in place (scratch: E0, E1
    (L,DIM); F, Uh, Xc, U_iterate (K,DIM); mu, phi, scale (L,)). Returns (status, completed steps)."""
    K = X.shape[0]
    L = k1.shape[0]
    zero_rows(F_base, fixed_idx)
    state_forces = has_state_forces(drag_idx, sa)
    # drag or dampers: the second half kick is implicit in U_{n+1} (fixed-point iteration below), which keeps
    # the step symmetric and so second order; explicit in the half-step velocity it is only first order
    velocity_dependent = drag_idx.shape[0] > 0
    for s in range(sc.shape[0]):
        if sc[s] != 0.0:
            velocity_dependent = True
    unit_vectors(X, k1, k2, inv_R, E0)
    if L > 0 and factor_tension_matrix(E0, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai,
                                       Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                       chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work) >= 0:
        return SINGULAR, 0
    Fx = F_base  # the forces when they do not depend on the state
    for step in range(n_steps):
        for g in range(gammas.shape[0]):
            hs = gammas[g] * h
            # kick and drift
            if state_forces:
                scene_forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
                Fx = F
            for k in range(K):
                for d in range(DIM):
                    Uh[k, d] = U[k, d] + 0.5 * hs * inv_m[k] * Fx[k, d]
                    Xc[k, d] = X[k, d] + hs * Uh[k, d]
            # position stage: Xc + M^-1 C(X)^T mu on (11), simplified Newton with A(X) factored
            if not project_positions(Xc, E0, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr,
                                     sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot,
                                     Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                     chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu, phi,
                                     scale, tol, max_iter):
                return PROJECTION_FAILED, step
            for k in range(K):
                for d in range(DIM):
                    Uh[k, d] = (Xc[k, d] - X[k, d]) / hs
            # second kick, then the velocity projection onto (12) at the new positions
            if state_forces:
                scene_forces(Xc, Uh, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
                Fx = F
            for k in range(K):
                for d in range(DIM):
                    U[k, d] = Uh[k, d] + 0.5 * hs * inv_m[k] * Fx[k, d]
                    X[k, d] = Xc[k, d]
            if project_velocities(X, U, E1, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc,
                                  free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai,
                                  Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                                  chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu, phi) != OK:
                return SINGULAR, step
            if velocity_dependent:
                # U_{n+1} = P(U_half + hs/2 M^-1 F(X_{n+1}, U_{n+1})): contraction factor ~ hs c / (2 m)
                converged = False
                for it in range(60):
                    scene_forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
                    size = 0.0
                    for k in range(K):
                        for d in range(DIM):
                            U_iterate[k, d] = Uh[k, d] + 0.5 * hs * inv_m[k] * F[k, d]
                            size = max(size, abs(U[k, d]))
                    if project_velocities(X, U_iterate, E1, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef,
                                          sa, sb, sk, sr, sc, free, use_chain, ordering, pair_first, pair_second,
                                          pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col,
                                          row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax,
                                          y_vals, solve_work, mu, phi) != OK:
                        return SINGULAR, step
                    change = 0.0
                    for k in range(K):
                        for d in range(DIM):
                            change = max(change, abs(U_iterate[k, d] - U[k, d]))
                            U[k, d] = U_iterate[k, d]
                    if change <= 4e-16 * size or change == 0.0:
                        converged = True
                        break
                if not converged:
                    return PROJECTION_FAILED, step
            E0, E1 = E1, E0  # the factorisation at X is the next stage's A(X)
        for k in range(K):
            for d in range(DIM):
                if not np.isfinite(X[k, d]) or not np.isfinite(U[k, d]):
                    return NON_FINITE, step
    return OK, n_steps


@outlined_kernel
def _accelerations_loop(n_evals, X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk,
                        sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp,
                        Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                        chain_sub, Ax, y_vals, solve_work, E, F, B, acc, T, refactor):
    """n_evals evaluations of :func:`accelerations` at the same state: returns the status of the last
    evaluation when n_evals is 1, else a checksum (``refactor`` is a runtime True: a literal would compile
    another accelerations)."""
    zero_rows(F_base, fixed_idx)
    checksum = 0.0
    status = OK
    for i in range(n_evals):
        status = accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr,
                               sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai,
                               Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                               chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F, B, acc, T, refactor)
        checksum += acc[acc.shape[0] - 1, DIM - 1]
    if n_evals == 1:
        return float(status)
    return checksum


# ------------------------------------------------------------------------------------------------ Runge-Kutta loop
@kernel
def _combine(Y0, h, coef, row, n, KY, out):
    """out = Y0 + h * sum_{j<n} coef[row, j] KY[j] (zero coefficients skipped)."""
    K = Y0.shape[0]
    for k in range(K):
        for d in range(DIM):
            out[k, d] = 0.0
    for j in range(n):
        c = coef[row, j]
        if c != 0.0:
            for k in range(K):
                for d in range(DIM):
                    out[k, d] += c * KY[j, k, d]
    for k in range(K):
        for d in range(DIM):
            out[k, d] = Y0[k, d] + h * out[k, d]


@kernel
def _store(KY, i, Y):
    """KY[i] = Y (without making a view of KY)."""
    for k in range(Y.shape[0]):
        for d in range(DIM):
            KY[i, k, d] = Y[k, d]


@kernel
def _weighted(coef, KY, k, d):
    s = 0.0
    for j in range(coef.shape[0]):
        c = coef[j]
        if c != 0.0:
            s += c * KY[j, k, d]
    return s


@kernel
def rk_error_norm(X, U, Xn, Un, KX, KU, h, free, E1, E2, kind, rtol, atol):
    """The embedded error estimate in the norm of ProjectedRungeKutta.error_norm (free masses only). The mean
    is over the 6 coordinates of a free mass whatever DIM: in the plane the out-of-plane ones are zero and
    count as they do on the 3-D path."""
    n = 6 * free.shape[0]
    s1 = 0.0
    s2 = 0.0
    for part in range(2):
        Y0 = X if part == 0 else U
        Y1 = Xn if part == 0 else Un
        KY = KX if part == 0 else KU
        for i in range(free.shape[0]):
            k = free[i]
            for d in range(DIM):
                scale = atol + rtol * max(abs(Y0[k, d]), abs(Y1[k, d]))
                if kind == RMS_ERROR:
                    e = h * _weighted(E1, KY, k, d) / scale
                    s1 += e * e
                else:
                    e5 = _weighted(E1, KY, k, d) / scale
                    e3 = _weighted(E2, KY, k, d) / scale
                    s1 += e5 * e5
                    s2 += e3 * e3
    if kind == RMS_ERROR:
        return np.sqrt(s1 / n)
    if s1 == 0.0 and s2 == 0.0:
        return 0.0
    return abs(h) * s1 / np.sqrt((s1 + 0.01 * s2) * n)


@kernel
def initial_step_size(X, U, acc0, Us, acc1, h0, free, rtol, atol, exponent, span):
    """Hairer-Wanner's starting step, as ProjectedRungeKutta._initial_step, from f at (X, U) and at
    (X + h0 U, U + h0 acc0) = (., Us) (RMS over 6 coordinates per free mass, as :func:`rk_error_norm`)."""
    n = 6 * free.shape[0]
    d1 = 0.0
    d2 = 0.0
    for i in range(free.shape[0]):
        k = free[i]
        for d in range(DIM):
            sx = atol + rtol * abs(X[k, d])
            su = atol + rtol * abs(U[k, d])
            d1 += (U[k, d] / sx) ** 2 + (acc0[k, d] / su) ** 2
            d2 += ((Us[k, d] - U[k, d]) / sx) ** 2 + ((acc1[k, d] - acc0[k, d]) / su) ** 2
    d1 = np.sqrt(d1 / n)
    d2 = np.sqrt(d2 / n) / h0
    if d1 <= 1e-15 and d2 <= 1e-15:
        h1 = max(1e-6, h0 * 1e-3)
    else:
        h1 = (0.01 / max(d1, d2)) ** (-exponent)
    return min(100.0 * h0, h1, span)


@kernel
def trial_step_size(X, U, acc0, free, rtol, atol, span):
    """The first guess h0 of Hairer-Wanner's starting step."""
    n = 6 * free.shape[0]
    d0 = 0.0
    d1 = 0.0
    for i in range(free.shape[0]):
        k = free[i]
        for d in range(DIM):
            sx = atol + rtol * abs(X[k, d])
            su = atol + rtol * abs(U[k, d])
            d0 += (X[k, d] / sx) ** 2 + (U[k, d] / su) ** 2
            d1 += (U[k, d] / sx) ** 2 + (acc0[k, d] / su) ** 2
    d0 = np.sqrt(d0 / n)
    d1 = np.sqrt(d1 / n)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    return min(h0, span)


@kernel
def controlled_step(h_next, t, t_target):
    """The step an adaptive loop takes next from t (ProjectedRungeKutta.advance's rule): h_next, cut to land
    on t_target, the rest split in two rather than leaving a sliver of a last step. -1.0 when that step is
    within 16 ulps of t and does not finish the interval (step-size underflow). Shared with the rigid-body
    loop (rigid_kernels.rigid_rk_advance)."""
    remaining = t_target - t
    h = min(h_next, remaining)
    if h < remaining < 1.1 * h:
        h = 0.5 * remaining
    tt = max(abs(t), 1.0)
    if h <= 16.0 * (np.nextafter(tt, np.inf) - tt) and h < remaining:
        return -1.0
    return h


@kernel
def next_step_size(h, h_next, err, exponent, safety, min_factor, max_factor):
    """The step size after a step h with error norm err: grown by safety * err^exponent (at most max_factor)
    when accepted (err <= 1), shrunk (at least min_factor) when rejected."""
    if err > 1.0:
        return h * max(min_factor, safety * err ** exponent)
    factor = max_factor if err == 0.0 else min(max_factor, safety * err ** exponent)
    # a step shortened only to land on t_target says nothing against the longer step
    return max(h_next, h * factor) if h < h_next else h * factor


@outlined_kernel
def _rk_steps(X, U, t, t_target, h_next, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk,
              sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
              Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax,
              y_vals, solve_work, AB, E1, E2, error_kind, exponent, rtol, atol, max_steps, n_fixed, safety, min_factor,
              max_factor, projection_tol, KX, KU, Xs, Us, Xn, Un, acc, acc1, T, E, F, Bv, mu, phi, scale):
    """The step loop of linknet_core.compiled_rk.CompiledRungeKutta (arguments described there). Scratch: stages KX, KU (s+1,K,DIM); Xs, Us, Xn, Un,
    acc, acc1, F (K,DIM); T, Bv, mu, phi, scale (L,); E (L,DIM)."""
    K = X.shape[0]
    s = AB.shape[1]
    n_rhs = 1
    steps = 0
    rejected = 0
    zero_rows(F_base, fixed_idx)
    # runtime booleans rather than the constants True/False: numba compiles a separate accelerations for each
    # literal value, and both would be inlined here
    refactor = n_rhs > 0
    reuse = not refactor
    status = accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc,
                           free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                           Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                           chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc, T, refactor)
    if status != OK:
        return status, t, h_next, steps, rejected, n_rhs
    _store(KX, 0, U)
    _store(KU, 0, acc)
    if h_next <= 0.0:
        h0 = trial_step_size(X, U, acc, free, rtol, atol, t_target - t)
        for k in range(K):
            for d in range(DIM):
                Xs[k, d] = X[k, d] + h0 * U[k, d]
                Us[k, d] = U[k, d] + h0 * acc[k, d]
        n_rhs += 1
        status = accelerations(Xs, Us, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr,
                               sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai,
                               Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                               chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc1, T, refactor)
        if status != OK:
            return status, t, 0.0, steps, rejected, n_rhs
        h_next = initial_step_size(X, U, acc, Us, acc1, h0, free, rtol, atol, exponent, t_target - t)
    while (steps < n_fixed) if n_fixed > 0 else (t < t_target):
        remaining = t_target - t
        h = h_next if n_fixed > 0 else controlled_step(h_next, t, t_target)
        if h < 0.0:
            return STEP_UNDERFLOW, t, h_next, steps, rejected, n_rhs
        # the stages
        for i in range(1, s):
            _combine(X, h, AB, i, i, KX, Xs)
            _combine(U, h, AB, i, i, KU, Us)
            n_rhs += 1
            status = accelerations(Xs, Us, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk,
                                   sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot,
                                   Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                   chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F, Bv,
                                   acc, T, refactor)
            if status != OK:
                return status, t, h_next, steps, rejected, n_rhs
            _store(KX, i, Us)
            _store(KU, i, acc)
        _combine(X, h, AB, s, s, KX, Xn)
        _combine(U, h, AB, s, s, KU, Un)
        n_rhs += 1
        # this evaluation also factors A(Xn), which the position projection below reuses
        status = accelerations(Xn, Un, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr,
                               sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai,
                               Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                               chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc, T, refactor)
        if status != OK:
            return status, t, h_next, steps, rejected, n_rhs
        _store(KX, s, Un)
        _store(KU, s, acc)
        if n_fixed > 0:
            err = 0.0
        else:
            err = rk_error_norm(X, U, Xn, Un, KX, KU, h, free, E1, E2, error_kind, rtol, atol)
            if not np.isfinite(err):
                rejected += 1
                h_next = h * min_factor
                continue
        if err <= 1.0:
            # positions onto (11) in the mass metric (directions and factorisation at Xn, unit vectors in E from
            # the last evaluation), then the velocities onto (12) at the projected positions
            if not project_positions(Xn, E, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr, sc,
                                     free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap,
                                     Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order,
                                     chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu, phi,
                                     scale, projection_tol, 50):
                return PROJECTION_FAILED, t, h_next, steps, rejected, n_rhs
            if project_velocities(Xn, Un, E, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr,
                                  sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap,
                                  Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                                  chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu, phi) != OK:
                return SINGULAR, t, h_next, steps, rejected, n_rhs
            if n_fixed > 0:
                t = t + h
            else:
                t = t_target if h == remaining else t + h
                h_next = next_step_size(h, h_next, err, exponent, safety, min_factor, max_factor)
            for k in range(K):
                for d in range(DIM):
                    X[k, d] = Xn[k, d]
                    U[k, d] = Un[k, d]
            steps += 1
            if n_fixed == 0 and steps > max_steps:
                return TOO_MANY_STEPS, t, h_next, steps, rejected, n_rhs
            if (steps < n_fixed) if n_fixed > 0 else (t < t_target):
                # the first stage of the next step; A(X) is factored already (velocity projection)
                n_rhs += 1
                status = accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb,
                                       sk, sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight,
                                       pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot,
                                       chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals,
                                       solve_work, E, F, Bv, acc, T, reuse)
                if status != OK:
                    return status, t, h_next, steps, rejected, n_rhs
                _store(KX, 0, U)
                _store(KU, 0, acc)
        else:
            rejected += 1
            h_next = next_step_size(h, h_next, err, exponent, safety, min_factor, max_factor)
    return OK, t, h_next, steps, rejected, n_rhs


# ------------------------------------------------------------------------------------------------ planar entries
# Used from the generated 2-D module only (numba compiles a function on its first call, so the 3-D module
# never compiles them). plane = (P (3,DIM): orthonormal in-plane basis, o (3,): a point of the plane, nrm (3,):
# unit normal, length (size of the scene: the scale of the position test), tol (relative size of an
# out-of-plane component that is round-off), fixed (K,) bool: the anchored masses).

@kernel
def _enter_plane(X3, U3, F_scene3, F_in3, fixed, P, o, nrm, length, tol, X, U, F_base):
    """The (K,3) state and forces in the plane's coordinates: X = P^T (X3 - o), U = P^T U3, F_base = P^T (F_scene3
    + F_in3), zero on anchors. False (nothing usable) when the positions, velocities or the input force on a free
    mass have a component along the normal beyond round-off (tol relative to their size)."""
    c = -0.0
    for e in range(3):
        c += nrm[e] * o[e]
    for k in range(X3.shape[0]):
        x_off = -c
        x_size = abs(c) + length
        u_off = -0.0
        u_size = 0.0
        f_off = -0.0
        f_size = 0.0
        for e in range(3):
            x_off += nrm[e] * X3[k, e]
            x_size += abs(X3[k, e])
            u_off += nrm[e] * U3[k, e]
            u_size += abs(U3[k, e])
            f_off += nrm[e] * F_in3[k, e]
            f_size += abs(F_in3[k, e])
        if not (abs(x_off) <= tol * x_size and abs(u_off) <= tol * u_size):
            return False
        if fixed[k]:
            for d in range(DIM):
                F_base[k, d] = 0.0
        elif not (abs(f_off) <= tol * f_size):
            return False
        for d in range(DIM):
            x = -0.0
            u = -0.0
            f = -0.0
            for e in range(3):
                x += P[e, d] * (X3[k, e] - o[e])
                u += P[e, d] * U3[k, e]
                f += P[e, d] * (F_scene3[k, e] + F_in3[k, e])
            X[k, d] = x
            U[k, d] = u
            if not fixed[k]:
                F_base[k, d] = f
    return True


@kernel
def _leave_plane(X, U, P, o, fixed, X3_in, U3_in, X3, U3):
    """X3 = o + P X, U3 = P U (back to 3-D); the anchors keep their (K,3) X3_in, U3_in exactly (in a tilted plane
    the round trip would move them by round-off)."""
    for k in range(X.shape[0]):
        if fixed[k]:
            for e in range(3):
                X3[k, e] = X3_in[k, e]
                U3[k, e] = U3_in[k, e]
            continue
        for e in range(3):
            x = o[e]
            u = -0.0
            for d in range(DIM):
                x += P[e, d] * X[k, d]
                u += P[e, d] * U[k, d]
            X3[k, e] = x
            U3[k, e] = u


@outlined_kernel
def _rattle_steps_in_plane(X3, U3, F_scene3, F_in3, X3_out, U3_out, P, o, nrm, length, plane_tol, fixed, n_steps,
                           h, gammas, X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb,
                           sk, sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap,
                           Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                           chain_off_weight, chain_sub, Ax, y_vals, solve_work, E0, E1, F, Uh, Xc, U_iterate, mu, phi,
                           scale, tol, max_iter):
    """:func:`_rattle_steps` in the plane: the (K,3) X3, U3 (read only) and the forces mapped in, the result
    mapped back into X3_out, U3_out. Returns (LEFT_PLANE, 0) without stepping when the state or the input
    force is not in the plane."""
    if not _enter_plane(X3, U3, F_scene3, F_in3, fixed, P, o, nrm, length, plane_tol, X, U, F_base):
        return LEFT_PLANE, 0
    status, done = _rattle_steps(X, U, n_steps, h, gammas, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx,
                                 drag_coef, sa, sb, sk, sr, sc, free, use_chain, ordering, pair_first, pair_second,
                                 pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot,
                                 chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals, solve_work,
                                 E0, E1, F, Uh, Xc, U_iterate, mu, phi, scale, tol, max_iter)
    _leave_plane(X, U, P, o, fixed, X3, U3, X3_out, U3_out)
    return status, done


@outlined_kernel
def _rk_steps_in_plane(X3, U3, F_scene3, F_in3, X3_out, U3_out, P, o, nrm, length, plane_tol, fixed, t, t_target,
                       h_next, X, U, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa, sb, sk, sr,
                       sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                       Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                       chain_sub, Ax, y_vals, solve_work, AB, E1, E2, error_kind, exponent, rtol, atol, max_steps,
                       n_fixed, safety, min_factor, max_factor, projection_tol, KX, KU, Xs, Us, Xn, Un, acc, acc1, T, E,
                       F, Bv, mu, phi, scale):
    """:func:`_rk_steps` in the plane (as :func:`_rattle_steps_in_plane`; the last accepted state is mapped back
    whatever the status, as the 3-D loop leaves it in X, U)."""
    if not _enter_plane(X3, U3, F_scene3, F_in3, fixed, P, o, nrm, length, plane_tol, X, U, F_base):
        return LEFT_PLANE, t, h_next, 0, 0, 0
    result = _rk_steps(X, U, t, t_target, h_next, F_base, k1, k2, R, inv_R, inv_m, fixed_idx, drag_idx, drag_coef, sa,
                       sb, sk, sr, sc, free, use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap,
                       Ai, Lp, Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                       chain_off_weight, chain_sub, Ax, y_vals, solve_work, AB, E1, E2, error_kind, exponent, rtol,
                       atol, max_steps, n_fixed, safety, min_factor, max_factor, projection_tol, KX, KU, Xs, Us, Xn,
                       Un, acc, acc1, T, E, F, Bv, mu, phi, scale)
    _leave_plane(X, U, P, o, fixed, X3, U3, X3_out, U3_out)
    return result
