"""Compiled step loop of the free-rigid-body specialisation (see :mod:`linknet_core.rigid`).

A rigid component of the network moves as one body: X_k = c + R r_k, U_k = v + w x (R r_k), with r_k
the body-frame positions of its masses in principal axes (fixed once per scene). The state per body is the
centre of mass c, its velocity v, the unit quaternion q of R (body -> space) and the body angular
momentum Pi. The external forces F_k of (9) (gravity, constant forces, springs and dampers, drag,
inputs) act on a body only through their resultant and their moment about c; the link tensions are
internal and cancel (31).

One base step of size h (the role RATTLE plays for point masses: 2nd order, symplectic and
time-reversible for conservative forces):

    half kick   v += h/2 f/m,   Pi += h/2 R^T tau
    drift       c += h v
    rotate      exact or split free-rotation flow over h
    half kick   with the forces at the new positions (implicit in the new velocities when the forces
                depend on them: drag, dampers)

Free rotation, T = Pi_1^2/(2 I_1) + Pi_2^2/(2 I_2) + Pi_3^2/(2 I_3):
  spherical top  (I_1 = I_2 = I_3): exact, one rotation about Pi by h |Pi| / I;
  symmetric top  (I_1 = I_2 != I_3): exact, T = |Pi|^2/(2 I_1) + (1/I_3 - 1/I_1) Pi_3^2/2 is two commuting
                 flows: a rotation about Pi by h |Pi|/I_1 and one about body axis 3 by h (1/I_3 - 1/I_1) Pi_3;
  asymmetric top: the symmetric splitting of Dullweber, Leimkuhler and McLachlan (J. Chem. Phys. 107,
                 5840, 1997) R1(h/2) R2(h/2) R3(h) R2(h/2) R1(h/2), R_i the exact flow of Pi_i^2/(2 I_i)
                 (a rotation about body axis i by h Pi_i / I_i).
Every sub-flow rotates R on the right and Pi by the inverse rotation, so the space angular momentum
L = R Pi is kept to round-off when there is no torque, and |Pi| exactly.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from .compiled import external_forces as _forces  # the force model F_k of (9), shared with the RATTLE loop

SPHERICAL, SYMMETRIC, ASYMMETRIC = 0, 1, 2
OK, NON_FINITE, KICK_NOT_CONVERGED = 0, 1, 2
EPS = 2.220446049250313e-16


@njit(cache=True)
def _rotate_right(q, b, u0, u1, u2, angle):
    """q[b] <- q[b] (x) (cos(angle/2), sin(angle/2) u) for a unit body axis u: R <- R Rot(u, angle)."""
    ch = np.cos(0.5 * angle)
    sh = np.sin(0.5 * angle)
    p1, p2, p3 = sh * u0, sh * u1, sh * u2
    w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    q[b, 0] = w * ch - x * p1 - y * p2 - z * p3
    q[b, 1] = w * p1 + x * ch + y * p3 - z * p2
    q[b, 2] = w * p2 + y * ch + z * p1 - x * p3
    q[b, 3] = w * p3 + z * ch + x * p2 - y * p1


@njit(cache=True)
def _axis_flow(q, Pi, b, i, angle):
    """Exact flow of Pi_i^2/(2 I_i) (angle = t Pi_i / I_i): R <- R Rot_i(angle), Pi <- Rot_i(angle)^T Pi."""
    if i == 0:
        _rotate_right(q, b, 1.0, 0.0, 0.0, angle)
    elif i == 1:
        _rotate_right(q, b, 0.0, 1.0, 0.0, angle)
    else:
        _rotate_right(q, b, 0.0, 0.0, 1.0, angle)
    j = (i + 1) % 3
    k = (i + 2) % 3
    c = np.cos(angle)
    s = np.sin(angle)
    pj, pk = Pi[b, j], Pi[b, k]
    Pi[b, j] = c * pj + s * pk
    Pi[b, k] = -s * pj + c * pk


@njit(cache=True)
def _about_momentum(q, Pi, b, t, inertia):
    """Exact flow of |Pi|^2/(2 I): a rotation about Pi (fixed in both frames) by t |Pi| / I."""
    p = np.sqrt(Pi[b, 0] ** 2 + Pi[b, 1] ** 2 + Pi[b, 2] ** 2)
    if p > 0.0:
        _rotate_right(q, b, Pi[b, 0] / p, Pi[b, 1] / p, Pi[b, 2] / p, t * p / inertia)


@njit(cache=True)
def free_rotation(q, Pi, kind, inertia, t):
    """Torque-free rotation of every body over time t (exact for spherical and symmetric tops)."""
    for b in range(q.shape[0]):
        I = inertia[b]
        if kind[b] == SPHERICAL:
            _about_momentum(q, Pi, b, t, I[0])
        elif kind[b] == SYMMETRIC:  # body axis 3 is the distinct one
            _about_momentum(q, Pi, b, t, I[0])
            _axis_flow(q, Pi, b, 2, t * (1.0 / I[2] - 1.0 / I[0]) * Pi[b, 2])
        else:
            _axis_flow(q, Pi, b, 0, 0.5 * t * Pi[b, 0] / I[0])
            _axis_flow(q, Pi, b, 1, 0.5 * t * Pi[b, 1] / I[1])
            _axis_flow(q, Pi, b, 2, t * Pi[b, 2] / I[2])
            _axis_flow(q, Pi, b, 1, 0.5 * t * Pi[b, 1] / I[1])
            _axis_flow(q, Pi, b, 0, 0.5 * t * Pi[b, 0] / I[0])
        norm = np.sqrt(q[b, 0] ** 2 + q[b, 1] ** 2 + q[b, 2] ** 2 + q[b, 3] ** 2)
        for d in range(4):
            q[b, d] /= norm


@njit(cache=True)
def rotation_matrices(q, R):
    """R[b] of the unit quaternion q[b] = (w, x, y, z)."""
    for b in range(q.shape[0]):
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        R[b, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
        R[b, 0, 1] = 2.0 * (x * y - w * z)
        R[b, 0, 2] = 2.0 * (x * z + w * y)
        R[b, 1, 0] = 2.0 * (x * y + w * z)
        R[b, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
        R[b, 1, 2] = 2.0 * (y * z - w * x)
        R[b, 2, 0] = 2.0 * (x * z - w * y)
        R[b, 2, 1] = 2.0 * (y * z + w * x)
        R[b, 2, 2] = 1.0 - 2.0 * (x * x + y * y)


@njit(cache=True)
def mass_states(c, v, q, Pi, inertia, body_of, r, R, X, U):
    """X_k = c + R r_k and U_k = v + w x (R r_k), w = R I^-1 Pi, for every mass of a body (others untouched)."""
    rotation_matrices(q, R)
    B = c.shape[0]
    w = np.empty((B, 3))
    for b in range(B):
        wb0, wb1, wb2 = Pi[b, 0] / inertia[b, 0], Pi[b, 1] / inertia[b, 1], Pi[b, 2] / inertia[b, 2]
        for d in range(3):
            w[b, d] = R[b, d, 0] * wb0 + R[b, d, 1] * wb1 + R[b, d, 2] * wb2
    for k in range(X.shape[0]):
        b = body_of[k]
        if b < 0:
            continue
        p0 = R[b, 0, 0] * r[k, 0] + R[b, 0, 1] * r[k, 1] + R[b, 0, 2] * r[k, 2]
        p1 = R[b, 1, 0] * r[k, 0] + R[b, 1, 1] * r[k, 1] + R[b, 1, 2] * r[k, 2]
        p2 = R[b, 2, 0] * r[k, 0] + R[b, 2, 1] * r[k, 1] + R[b, 2, 2] * r[k, 2]
        X[k, 0] = c[b, 0] + p0
        X[k, 1] = c[b, 1] + p1
        X[k, 2] = c[b, 2] + p2
        U[k, 0] = v[b, 0] + w[b, 1] * p2 - w[b, 2] * p1
        U[k, 1] = v[b, 1] + w[b, 2] * p0 - w[b, 0] * p2
        U[k, 2] = v[b, 2] + w[b, 0] * p1 - w[b, 1] * p0


@njit(cache=True)
def _loads(X, c, F, body_of, f, tau):
    """Resultant f and moment tau (about c, space frame) of the external forces on each body."""
    f[:, :] = 0.0
    tau[:, :] = 0.0
    for k in range(X.shape[0]):
        b = body_of[k]
        if b < 0:
            continue
        p0, p1, p2 = X[k, 0] - c[b, 0], X[k, 1] - c[b, 1], X[k, 2] - c[b, 2]
        f[b, 0] += F[k, 0]
        f[b, 1] += F[k, 1]
        f[b, 2] += F[k, 2]
        tau[b, 0] += p1 * F[k, 2] - p2 * F[k, 1]
        tau[b, 1] += p2 * F[k, 0] - p0 * F[k, 2]
        tau[b, 2] += p0 * F[k, 1] - p1 * F[k, 0]


@njit(cache=True)
def _kick(v, Pi, R, f, tau, body_mass, hk):
    """v += hk f / m and Pi += hk R^T tau (the torque taken into the body frame at the current attitude)."""
    for b in range(v.shape[0]):
        for d in range(3):
            v[b, d] += hk * f[b, d] / body_mass[b]
            Pi[b, d] += hk * (R[b, 0, d] * tau[b, 0] + R[b, 1, d] * tau[b, 1] + R[b, 2, d] * tau[b, 2])


@njit(cache=True)
def _implicit_kick(c, v, q, Pi, inertia, body_of, r, R, X, U, F, f, tau, body_mass, hk,
                   F_base, drag, sa, sb, sk, sr, sc, fixed):
    """(v, Pi) <- (v, Pi) + hk (f, R^T tau) evaluated at the *new* velocities (fixed-point iteration to
    round-off). Returns False if it does not converge (damping too stiff for the step)."""
    B = v.shape[0]
    v0 = v.copy()
    Pi0 = Pi.copy()
    previous_v = v.copy()
    previous_Pi = Pi.copy()
    for it in range(100):
        v[:, :] = v0
        Pi[:, :] = Pi0
        _kick(v, Pi, R, f, tau, body_mass, hk)
        dv = 0.0
        dp = 0.0
        sv = 1e-300
        sp = 1e-300
        for b in range(B):
            for d in range(3):
                dv = max(dv, abs(v[b, d] - previous_v[b, d]))
                dp = max(dp, abs(Pi[b, d] - previous_Pi[b, d]))
                sv = max(sv, abs(v[b, d]))
                sp = max(sp, abs(Pi[b, d]))
        mass_states(c, v, q, Pi, inertia, body_of, r, R, X, U)
        _forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
        _loads(X, c, F, body_of, f, tau)
        if it > 0 and dv <= 8 * EPS * sv and dp <= 8 * EPS * sp:
            return True
        if not (dv < 1e300 and dp < 1e300):
            return False
        previous_v[:, :] = v
        previous_Pi[:, :] = Pi
    return dv <= 1e-10 * sv and dp <= 1e-10 * sp


@njit(cache=True)
def rigid_advance(c, v, q, Pi, n_steps, h, gammas, kind, inertia, body_mass, body_of, r, X, U,
                  F_base, drag, sa, sb, sk, sr, sc, fixed, velocity_dependent):
    """Advance every body in place by n_steps steps of size h, each a composition of base steps of
    gammas[i] h; X, U are updated to the final state (masses of no body are left as they are).

    With velocity-dependent forces (drag, dampers) the second half kick is implicit in the velocities:
    explicit first half kick, drift, rotation, implicit second half kick is exactly symmetric (its adjoint
    swaps the two kinds of kick), so it is second order and the compositions keep their orders.
    Returns OK, NON_FINITE or KICK_NOT_CONVERGED.
    """
    K = X.shape[0]
    B = c.shape[0]
    F = np.empty((K, 3))
    f = np.empty((B, 3))
    tau = np.empty((B, 3))
    R = np.empty((B, 3, 3))
    mass_states(c, v, q, Pi, inertia, body_of, r, R, X, U)
    _forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
    _loads(X, c, F, body_of, f, tau)
    for step in range(n_steps):
        for g in range(gammas.shape[0]):
            hs = gammas[g] * h
            # forces at the start of the stage are those the last stage ended with (X and U unchanged)
            _kick(v, Pi, R, f, tau, body_mass, 0.5 * hs)
            for b in range(B):
                for d in range(3):
                    c[b, d] += hs * v[b, d]
            free_rotation(q, Pi, kind, inertia, hs)
            mass_states(c, v, q, Pi, inertia, body_of, r, R, X, U)
            _forces(X, U, F_base, drag, sa, sb, sk, sr, sc, fixed, F)
            _loads(X, c, F, body_of, f, tau)
            if velocity_dependent:
                if not _implicit_kick(c, v, q, Pi, inertia, body_of, r, R, X, U, F, f, tau, body_mass, 0.5 * hs,
                                      F_base, drag, sa, sb, sk, sr, sc, fixed):
                    return KICK_NOT_CONVERGED
            else:
                _kick(v, Pi, R, f, tau, body_mass, 0.5 * hs)
        for b in range(B):
            for d in range(3):
                if not (np.isfinite(c[b, d]) and np.isfinite(v[b, d]) and np.isfinite(Pi[b, d])):
                    return NON_FINITE
    mass_states(c, v, q, Pi, inertia, body_of, r, R, X, U)
    return OK
