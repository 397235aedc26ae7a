"""Compiled projected Runge-Kutta: the whole interval between two output points in one numba call.

Same algorithm as :class:`linknet_core.integrators.runge_kutta.ProjectedRungeKutta` (tested against it to
round-off): the stages of an explicit embedded tableau on the index-1 formulation dX/dt = U (10),
dU/dt = accelerations (9) with the tensions of (25)-(26) (:func:`linknet_core.compiled.accelerations`),
the embedded error estimate, the same step-size controller, and after every accepted step the projection
of the positions onto (11) and of the velocities onto (12).

The method is data: the tableau (A, b) and the error weights are arguments, so adding a tableau needs no
compiled code. Two error norms exist: the RMS norm of the embedded difference (Dormand-Prince and most
pairs) and Hairer's combined 5th/3rd-order estimate of DOP853.

Whenever the kernel cannot continue (a vanishing pivot of A, a projection that does not contract,
non-finite values) it stops at the last accepted step and says why; the integrator finishes the interval
on the numpy path, which has the minimum-norm and Gauss-Newton fallbacks.
"""
from __future__ import annotations

import numpy as np

from .compiled import (NON_FINITE, OK, PROJECTION_FAILED, SINGULAR, STEP_UNDERFLOW, TOO_MANY_STEPS, CompiledScene,
                       accelerations, project_positions, project_velocities)
from .ldl import kernel, outlined_kernel

__all__ = ["rk_advance", "CompiledRungeKutta", "RMS_ERROR", "HAIRER_ERROR", "OK", "PROJECTION_FAILED", "SINGULAR",
           "NON_FINITE", "STEP_UNDERFLOW", "TOO_MANY_STEPS"]

RMS_ERROR, HAIRER_ERROR = 0, 1  # the error norms of ProjectedRungeKutta.error_norm ('rms', 'hairer')


@kernel
def _combine(Y0, h, coef, row, n, KY, out):
    """out = Y0 + h * sum_{j<n} coef[row, j] KY[j] (zero coefficients skipped)."""
    K = Y0.shape[0]
    for k in range(K):
        out[k, 0] = 0.0
        out[k, 1] = 0.0
        out[k, 2] = 0.0
    for j in range(n):
        c = coef[row, j]
        if c != 0.0:
            for k in range(K):
                out[k, 0] += c * KY[j, k, 0]
                out[k, 1] += c * KY[j, k, 1]
                out[k, 2] += c * KY[j, k, 2]
    for k in range(K):
        out[k, 0] = Y0[k, 0] + h * out[k, 0]
        out[k, 1] = Y0[k, 1] + h * out[k, 1]
        out[k, 2] = Y0[k, 2] + h * out[k, 2]


@kernel
def _store(KY, i, Y):
    """KY[i] = Y (without making a view of KY)."""
    for k in range(Y.shape[0]):
        KY[i, k, 0] = Y[k, 0]
        KY[i, k, 1] = Y[k, 1]
        KY[i, k, 2] = Y[k, 2]


@kernel
def _weighted(coef, KY, k, d):
    s = 0.0
    for j in range(coef.shape[0]):
        c = coef[j]
        if c != 0.0:
            s += c * KY[j, k, d]
    return s


@kernel
def _error_norm(X, U, Xn, Un, KX, KU, h, free, E1, E2, kind, rtol, atol):
    """The embedded error estimate in the norm of ProjectedRungeKutta.error_norm (free masses only)."""
    n = 6 * free.shape[0]
    s1 = 0.0
    s2 = 0.0
    for part in range(2):
        Y0 = X if part == 0 else U
        Y1 = Xn if part == 0 else Un
        KY = KX if part == 0 else KU
        for i in range(free.shape[0]):
            k = free[i]
            for d in range(3):
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
def _initial_step_size(X, U, acc0, Us, acc1, h0, free, rtol, atol, exponent, span):
    """Hairer-Wanner's starting step, as ProjectedRungeKutta._initial_step, from f at (X, U) and at
    (X + h0 U, U + h0 acc0) = (., Us)."""
    n = 6 * free.shape[0]
    d1 = 0.0
    d2 = 0.0
    for i in range(free.shape[0]):
        k = free[i]
        for d in range(3):
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
def _trial_step_size(X, U, acc0, free, rtol, atol, span):
    """The first guess h0 of Hairer-Wanner's starting step."""
    n = 6 * free.shape[0]
    d0 = 0.0
    d1 = 0.0
    for i in range(free.shape[0]):
        k = free[i]
        for d in range(3):
            sx = atol + rtol * abs(X[k, d])
            su = atol + rtol * abs(U[k, d])
            d0 += (X[k, d] / sx) ** 2 + (U[k, d] / su) ** 2
            d1 += (U[k, d] / sx) ** 2 + (acc0[k, d] / su) ** 2
    d0 = np.sqrt(d0 / n)
    d1 = np.sqrt(d1 / n)
    h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
    return min(h0, span)


def rk_scratch(K, L, s):
    """Scratch arrays of :func:`rk_advance` for s stages (allocated once per scene and tableau), in the order of
    :func:`_rk_steps`: KX, KU; Xs, Us, Xn, Un, acc, acc1; T; E; F; B, mu, phi, scale."""
    return (np.empty((s + 1, K, 3)), np.empty((s + 1, K, 3)), np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3)),
            np.empty((K, 3)), np.empty((K, 3)), np.empty((K, 3)), np.zeros(L), np.empty((L, 3)), np.empty((K, 3)),
            np.empty(L), np.empty(L), np.empty(L), np.empty(L))


def rk_advance(X, U, t, t_target, h_next, F_base, scene, system, scratch, AB, E1, E2, error_kind, exponent, rtol,
               atol, max_steps, n_fixed, safety, min_factor, max_factor, projection_tol):
    """Advance (X, U) in place from t to t_target with an embedded explicit pair.

    AB: the s x s matrix A of the tableau with the weights b as row s; E1, E2: error weights (s + 1 each,
    the last for the right-hand side at the new point). ``h_next`` <= 0 asks for the starting step to be
    chosen. ``n_fixed`` > 0 instead takes n_fixed steps of exactly h_next with no error control (order
    measurements). On return X, U hold the last accepted state. Returns (status, t, h_next, accepted
    steps, rejected steps, right-hand side evaluations). (A Python function: a compiled wrapper unpacking the
    tuples would make numba optimise the whole inlined step loop a second time when compiling it.)
    """
    return _rk_steps(X, U, t, t_target, h_next, F_base, *scene, *system, AB, E1, E2, error_kind, exponent, rtol, atol,
                     max_steps, n_fixed, safety, min_factor, max_factor, projection_tol, *scratch)


@outlined_kernel
def _rk_steps(X, U, t, t_target, h_next, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
              use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
              row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub, Ax, y_vals,
              solve_work, AB, E1, E2, error_kind, exponent, rtol, atol, max_steps, n_fixed, safety, min_factor,
              max_factor, projection_tol, KX, KU, Xs, Us, Xn, Un, acc, acc1, T, E, F, Bv, mu, phi, scale):
    """The step loop of :func:`rk_advance`. Scratch: stages KX, KU (s+1,K,3); Xs, Us, Xn, Un, acc, acc1, F (K,3);
    T, Bv, mu, phi, scale (L,); E (L,3)."""
    K = X.shape[0]
    s = AB.shape[1]
    n_rhs = 1
    steps = 0
    rejected = 0
    # runtime booleans rather than the constants True/False: numba compiles a separate accelerations for each
    # literal value, and both would be inlined here
    refactor = n_rhs > 0
    reuse = not refactor
    status = accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain,
                           ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D, Dinv,
                           row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight, chain_sub,
                           Ax, y_vals, solve_work, E, F, Bv, acc, T, refactor)
    if status != OK:
        return status, t, h_next, steps, rejected, n_rhs
    _store(KX, 0, U)
    _store(KU, 0, acc)
    if h_next <= 0.0:
        h0 = _trial_step_size(X, U, acc, free, rtol, atol, t_target - t)
        for k in range(K):
            for d in range(3):
                Xs[k, d] = X[k, d] + h0 * U[k, d]
                Us[k, d] = U[k, d] + h0 * acc[k, d]
        n_rhs += 1
        status = accelerations(Xs, Us, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
                               use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx,
                               D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                               chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc1, T, refactor)
        if status != OK:
            return status, t, 0.0, steps, rejected, n_rhs
        h_next = _initial_step_size(X, U, acc, Us, acc1, h0, free, rtol, atol, exponent, t_target - t)
    while (steps < n_fixed) if n_fixed > 0 else (t < t_target):
        remaining = t_target - t
        if n_fixed > 0:
            h = h_next
        else:
            h = min(h_next, remaining)
            if h < remaining < 1.1 * h:  # avoid a sliver of a last step: split the rest in two
                h = 0.5 * remaining
            tt = max(abs(t), 1.0)
            if h <= 16.0 * (np.nextafter(tt, np.inf) - tt) and h < remaining:
                return STEP_UNDERFLOW, t, h_next, steps, rejected, n_rhs
        # the stages
        for i in range(1, s):
            _combine(X, h, AB, i, i, KX, Xs)
            _combine(U, h, AB, i, i, KU, Us)
            n_rhs += 1
            status = accelerations(Xs, Us, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
                                   use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li,
                                   Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                                   chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc, T, refactor)
            if status != OK:
                return status, t, h_next, steps, rejected, n_rhs
            _store(KX, i, Us)
            _store(KU, i, acc)
        _combine(X, h, AB, s, s, KX, Xn)
        _combine(U, h, AB, s, s, KU, Un)
        n_rhs += 1
        # this evaluation also factors A(Xn), which the position projection below reuses
        status = accelerations(Xn, Un, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
                               use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx,
                               D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                               chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc, T, refactor)
        if status != OK:
            return status, t, h_next, steps, rejected, n_rhs
        _store(KX, s, Un)
        _store(KU, s, acc)
        if n_fixed > 0:
            err = 0.0
        else:
            err = _error_norm(X, U, Xn, Un, KX, KU, h, free, E1, E2, error_kind, rtol, atol)
            if not np.isfinite(err):
                rejected += 1
                h_next = h * min_factor
                continue
        if err <= 1.0:
            # positions onto (11) in the mass metric (directions and factorisation at Xn, unit vectors in E from
            # the last evaluation), then the velocities onto (12) at the projected positions
            if not project_positions(Xn, E, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain,
                                     ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
                                     Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                                     chain_off_weight, chain_sub, Ax, y_vals, solve_work, mu, phi, scale,
                                     projection_tol, 50):
                return PROJECTION_FAILED, t, h_next, steps, rejected, n_rhs
            if project_velocities(Xn, Un, E, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free, use_chain,
                                  ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp, Li, Lx, D,
                                  Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight, chain_off_weight,
                                  chain_sub, Ax, y_vals, solve_work, mu, phi) != OK:
                return SINGULAR, t, h_next, steps, rejected, n_rhs
            if n_fixed > 0:
                t = t + h
            else:
                t = t_target if h == remaining else t + h
                factor = max_factor if err == 0.0 else min(max_factor, safety * err ** exponent)
                # a step shortened only to land on t_target says nothing against the longer step
                h_next = max(h_next, h * factor) if h < h_next else h * factor
            for k in range(K):
                for d in range(3):
                    X[k, d] = Xn[k, d]
                    U[k, d] = Un[k, d]
            steps += 1
            if n_fixed == 0 and steps > max_steps:
                return TOO_MANY_STEPS, t, h_next, steps, rejected, n_rhs
            if (steps < n_fixed) if n_fixed > 0 else (t < t_target):
                # the first stage of the next step; A(X) is factored already (velocity projection)
                n_rhs += 1
                status = accelerations(X, U, F_base, k1, k2, R, inv_R, inv_m, fixed, drag, sa, sb, sk, sr, sc, free,
                                       use_chain, ordering, pair_first, pair_second, pair_weight, pair_slot, Ap, Ai, Lp,
                                       Li, Lx, D, Dinv, row_start, row_col, row_slot, chain_order, chain_diag_weight,
                                       chain_off_weight, chain_sub, Ax, y_vals, solve_work, E, F, Bv, acc, T, reuse)
                if status != OK:
                    return status, t, h_next, steps, rejected, n_rhs
                _store(KX, 0, U)
                _store(KU, 0, acc)
        else:
            rejected += 1
            h_next = h * max(min_factor, safety * err ** exponent)
    return OK, t, h_next, steps, rejected, n_rhs


class CompiledRungeKutta(CompiledScene):
    """:func:`rk_advance` for one scene and one tableau (A, b, error weights, error norm)."""

    def __init__(self, dyn, A, B, error_weights, error_kind: int, error_estimator_order: int,
                 use_chain: bool | None = None):
        super().__init__(dyn, use_chain=use_chain)
        B = np.asarray(B, np.float64)
        s = B.shape[0]
        A = np.asarray(A, np.float64)
        if A.ndim != 2 or A.shape[0] != s or A.shape[1] > s or np.any(np.triu(A[:, :s]) != 0.0):
            raise ValueError(f"an explicit tableau needs a strictly lower-triangular A with {s} rows, got {A.shape}")
        self.AB = np.zeros((s + 1, s))
        self.AB[:s, :A.shape[1]] = A
        self.AB[s] = B
        E1 = np.ascontiguousarray(error_weights[0], np.float64)
        E2 = np.ascontiguousarray(error_weights[1] if len(error_weights) > 1 else np.zeros_like(E1), np.float64)
        if E1.shape != (s + 1,) or E2.shape != (s + 1,):
            raise ValueError(f"error weights must have {s + 1} entries (one per stage and one for the new point), "
                             f"got {E1.shape} and {E2.shape}")
        self.E1, self.E2 = E1, E2
        self.scratch = rk_scratch(self.K, self.L, s)
        self.error_kind = int(error_kind)
        self.exponent = -1.0 / (error_estimator_order + 1)

    def advance(self, X, U, t, t_target, h, F_input, rtol, atol, max_steps, controller, n_fixed=0,
                projection_tol=1e-14):
        """Returns (status, X, U, t, h_next or None, steps, rejected, rhs evaluations)."""
        Xw = np.array(X, dtype=np.float64, copy=True, order="C")
        Uw = np.array(U, dtype=np.float64, copy=True, order="C")
        safety, min_factor, max_factor = controller
        status, t, h_next, steps, rejected, n_rhs = rk_advance(
            Xw, Uw, float(t), float(t_target), 0.0 if h is None else float(h), self.base_forces(F_input), self.scene,
            self.system, self.scratch, self.AB, self.E1, self.E2, self.error_kind, self.exponent, float(rtol),
            float(atol), int(max_steps), int(n_fixed), float(safety), float(min_factor), float(max_factor),
            float(projection_tol))
        return status, Xw, Uw, t, (h_next if h_next > 0.0 else None), steps, rejected, n_rhs
