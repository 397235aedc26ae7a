"""Compiled step loop: many RATTLE (or RATTLE-composition) steps in one numba call.

The pure numpy path (``Rattle.step``) pays a few microseconds of Python overhead per array operation,
which dominates for small and medium scenes. Here the whole interval between two output/communication
points runs in compiled code: forces, the assembly of A (25) from the pair arrays, the numeric LDL^T on
the pattern analysed once, the simplified-Newton position stage and the velocity projection. It is the
same algorithm as :class:`linknet_core.integrators.rattle.Rattle` (tested against it to round-off).

It covers scenes whose A is non-singular along the way. Whenever it cannot continue (a vanishing pivot:
singular configuration; a position stage that does not contract) it stops and reports it, and the caller
redoes the interval on the numpy path, which has the minimum-norm and exact-Newton fallbacks.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .ldl import ldl_factor, ldl_solve

OK, PROJECTION_FAILED, SINGULAR, NON_FINITE = 0, 1, 2, 3


@njit(cache=True)
def _forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F):
    K = X.shape[0]
    for k in range(K):
        for d in range(3):
            F[k, d] = F_base[k, d] - drag[k] * U[k, d]
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


@njit(cache=True)
def _unit_vectors(X, k1, k2, R, E):
    for l in range(k1.shape[0]):
        for d in range(3):
            E[l, d] = (X[k2[l], d] - X[k1[l], d]) / R[l]


@njit(cache=True)
def _factor(E, pair_first, pair_second, pair_weight, pair_slot, Ax, Ap, Ai, Lp, Li, Lx, D, Dinv, etree):
    Ax[:] = 0.0
    for p in range(pair_first.shape[0]):
        a, b = pair_first[p], pair_second[p]
        Ax[pair_slot[p]] += pair_weight[p] * (E[a, 0] * E[b, 0] + E[a, 1] * E[b, 1] + E[a, 2] * E[b, 2])
    return ldl_factor(Ap.shape[0] - 1, Ap, Ai, Ax, Lp, Li, Lx, D, Dinv, etree, 1e-11)


@njit(cache=True)
def _solve(b, ordering, Lp, Li, Lx, Dinv, work, out):
    n = b.shape[0]
    for i in range(n):
        work[i] = b[ordering[i]]
    ldl_solve(n, Lp, Li, Lx, Dinv, work)
    for i in range(n):
        out[ordering[i]] = work[i]


@njit(cache=True)
def _add_correction(E, mu, k1, k2, inv_m, scale, V):
    """V += scale * M^-1 C^T mu (C from unit vectors E)."""
    for l in range(k1.shape[0]):
        a, b = k1[l], k2[l]
        for d in range(3):
            f = scale * mu[l] * E[l, d]
            V[a, d] += inv_m[a] * f
            V[b, d] -= inv_m[b] * f


@njit(cache=True)
def rattle_advance(X, U, n_steps, h, gammas, k1, k2, R, inv_m, fixed, F_base, drag, sa, sb, sk, sr, sc,
                   pair_first, pair_second, pair_weight, pair_slot, ordering, Ap, Ai, Lp, Li, Lx, D, Dinv, etree,
                   tol, max_iter):
    """Advance (X, U) in place by n_steps steps of size h, each a composition of RATTLE stages gammas.

    Returns (status, completed steps). On a non-zero status X and U are partially advanced: the caller
    restores its copy and takes the numpy path.
    """
    K = X.shape[0]
    L = k1.shape[0]
    eps = 2.220446049250313e-16
    E0 = np.empty((L, 3))
    E1 = np.empty((L, 3))
    Ax = np.empty(Ai.shape[0])
    F = np.empty((K, 3))
    Uh = np.empty((K, 3))
    Xc = np.empty((K, 3))
    phi = np.empty(L)
    mu = np.empty(L)
    work = np.empty(L)
    rhs = np.empty(L)
    _unit_vectors(X, k1, k2, R, E0)
    if L > 0 and _factor(E0, pair_first, pair_second, pair_weight, pair_slot, Ax, Ap, Ai, Lp, Li, Lx, D, Dinv,
                         etree) >= 0:
        return SINGULAR, 0
    for step in range(n_steps):
        for g in range(gammas.shape[0]):
            hs = gammas[g] * h
            # kick and drift
            _forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
            for k in range(K):
                for d in range(3):
                    Uh[k, d] = U[k, d] + 0.5 * hs * inv_m[k] * F[k, d]
                    Xc[k, d] = X[k, d] + hs * Uh[k, d]
            # position stage: Xc + M^-1 C(X)^T mu on (11), simplified Newton with A(X) factored
            converged = L == 0
            previous = 1e300
            for it in range(max_iter):
                worst = 0.0
                for l in range(L):
                    a, b = k1[l], k2[l]
                    d0 = Xc[b, 0] - Xc[a, 0]
                    d1 = Xc[b, 1] - Xc[a, 1]
                    d2 = Xc[b, 2] - Xc[a, 2]
                    phi[l] = (d0 * d0 + d1 * d1 + d2 * d2 - R[l] * R[l]) / (2.0 * R[l])
                    size = max(abs(Xc[a, 0]), abs(Xc[a, 1]), abs(Xc[a, 2])) + max(abs(Xc[b, 0]), abs(Xc[b, 1]),
                                                                                 abs(Xc[b, 2]))
                    r = abs(phi[l]) / (R[l] * tol + 8.0 * eps * size)
                    if not (r <= worst):
                        worst = r
                if worst <= 1.0:
                    converged = True
                    break
                if not (worst < 1e300) or (it > 3 and worst > 0.3 * previous):
                    break
                previous = worst
                _solve(phi, ordering, Lp, Li, Lx, Dinv, work, mu)
                _add_correction(E0, mu, k1, k2, inv_m, 1.0, Xc)
            if not converged:
                return PROJECTION_FAILED, step
            for k in range(K):
                for d in range(3):
                    Uh[k, d] = (Xc[k, d] - X[k, d]) / hs
            # second kick, then the velocity projection onto (12) at the new positions
            _forces(Xc, Uh, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
            for k in range(K):
                for d in range(3):
                    U[k, d] = Uh[k, d] + 0.5 * hs * inv_m[k] * F[k, d]
                    X[k, d] = Xc[k, d]
            if L > 0:
                _unit_vectors(X, k1, k2, R, E1)
                if _factor(E1, pair_first, pair_second, pair_weight, pair_slot, Ax, Ap, Ai, Lp, Li, Lx, D, Dinv,
                           etree) >= 0:
                    return SINGULAR, step
                for l in range(L):
                    a, b = k1[l], k2[l]
                    rhs[l] = (E1[l, 0] * (U[a, 0] - U[b, 0]) + E1[l, 1] * (U[a, 1] - U[b, 1])
                              + E1[l, 2] * (U[a, 2] - U[b, 2]))
                _solve(rhs, ordering, Lp, Li, Lx, Dinv, work, mu)
                _add_correction(E1, mu, k1, k2, inv_m, -1.0, U)
                E0[:, :] = E1  # the factorisation at X is the next stage's A(X)
        for k in range(K):
            for d in range(3):
                if not np.isfinite(X[k, d]) or not np.isfinite(U[k, d]):
                    return NON_FINITE, step
    return OK, n_steps


class CompiledRattle:
    """Arrays of one scene prepared for :func:`rattle_advance` (built once per Dynamics)."""

    def __init__(self, dyn):
        scene = dyn.scene
        solver = dyn.solver
        asm = solver.assembly
        ldl = solver.ldl
        s = scene.springs
        self.dyn = dyn
        self.args_scene = (scene.k1, scene.k2, np.ascontiguousarray(scene.length), np.ascontiguousarray(scene.inv_mass),
                           np.ascontiguousarray(scene.fixed))
        self.drag = np.ascontiguousarray(scene.drag)
        self.springs = (s.a, s.b, np.ascontiguousarray(s.stiffness), np.ascontiguousarray(s.rest_length),
                        np.ascontiguousarray(s.damping))
        self.pairs = (asm.pair_first, asm.pair_second, np.ascontiguousarray(asm.pair_weight),
                      asm.pair_slot.astype(np.int64), asm.ordering)
        # private factor storage: the kernel must not disturb the numpy path's cached factorisation
        self.ldl_arrays = (asm.Ap, asm.Ai, ldl.Lp, ldl.Li.copy(), ldl.Lx.copy(), ldl.D.copy(), ldl.Dinv.copy(),
                           ldl.etree)
        free_mass = np.where(scene.fixed, 0.0, scene.mass)
        self.F_scene = free_mass[:, None] * scene.gravity[None, :] + scene.force

    def advance(self, X, U, n_steps, h, gammas, F_input, tol):
        F_base = self.F_scene if F_input is None else self.F_scene + F_input
        F_base = np.ascontiguousarray(F_base)
        Xw = np.array(X, dtype=float, copy=True, order="C")
        Uw = np.array(U, dtype=float, copy=True, order="C")
        status, done = rattle_advance(Xw, Uw, int(n_steps), float(h), np.asarray(gammas, float), *self.args_scene,
                                      F_base, self.drag, *self.springs, *self.pairs, *self.ldl_arrays, float(tol), 50)
        return status, Xw, Uw


def supports(dyn) -> bool:
    """The compiled loop handles the LDL^T structures (chain, tree, general), not the redundant one."""
    return dyn.structure.kind != "redundant" and hasattr(dyn.solver, "ldl")
