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

# the force model F_k of (9) and the adaptive step controller are the point-mass loops' own
from .compiled_kernels import (controlled_step, initial_step_size, next_step_size, rk_error_norm,
                               scene_forces as _forces, trial_step_size)

# building blocks of the Runge-Kutta loop: inlined by LLVM into it (a call passing ~20 array structs costs
# more than a small body's whole stage)
_inlined = njit(cache=True, error_model="numpy", forceinline=True)


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


@_inlined
def _loads(X, c, F, body_of, f, tau):
    """Resultant f and moment tau (about c, space frame) of the external forces on each body (c: the
    centres in columns 0-2, so a body state Y serves as well)."""
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
                   F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx):
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
        _forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
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
                  F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, velocity_dependent):
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
    _forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
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
            _forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
            _loads(X, c, F, body_of, f, tau)
            if velocity_dependent:
                if not _implicit_kick(c, v, q, Pi, inertia, body_of, r, R, X, U, F, f, tau, body_mass, 0.5 * hs,
                                      F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx):
                    return KICK_NOT_CONVERGED
            else:
                _kick(v, Pi, R, f, tau, body_mass, 0.5 * hs)
        for b in range(B):
            for d in range(3):
                if not (np.isfinite(c[b, d]) and np.isfinite(v[b, d]) and np.isfinite(Pi[b, d])):
                    return NON_FINITE
    mass_states(c, v, q, Pi, inertia, body_of, r, R, X, U)
    return OK


# ---- embedded Runge-Kutta on the Newton-Euler equations (adaptive methods) ---------------------------
#
# The body state is one row of Y (B, 13): c (0:3), v (3:6), q (6:10), Pi (10:13). Its derivative is
#     dc/dt = v,  dv/dt = f / m,  dq/dt = q (x) (0, w) / 2,  dPi/dt = Pi x w + R^T tau,   w = Pi / I,
# (Newton for the centre of mass, Euler's equations in the body frame, quaternion kinematics), f and tau
# the resultant and moment about c of the external forces F_k of (9) at the mass states of Y. The map
# Y -> masses uses the rotation of q / |q| (the exact flow keeps |q|, a stage may not), and after every
# accepted step q is renormalised: the analogue of the point-mass path's projection onto (11)-(12).
# The error estimate is formed as the point-mass path forms it, from the masses' velocities and
# accelerations at the stages (sum_i E_i (U_k, dU_k/dt)(Y_i)), in its norm, so that rtol/atol mean the same
# there and here (see linknet_core.rigid_adaptive for why not from the body-state derivatives).

STEP_UNDERFLOW, TOO_MANY_STEPS = 3, 4


@_inlined
def body_rotations(Y, R):
    """R[b] of the unit quaternion q[b] / |q[b]|, q[b] = Y[b, 6:10] (the homogeneous form: a rotation for any q)."""
    for b in range(Y.shape[0]):
        w, x, y, z = Y[b, 6], Y[b, 7], Y[b, 8], Y[b, 9]
        s = 2.0 / (w * w + x * x + y * y + z * z)
        R[b, 0, 0] = 1.0 - s * (y * y + z * z)
        R[b, 0, 1] = s * (x * y - w * z)
        R[b, 0, 2] = s * (x * z + w * y)
        R[b, 1, 0] = s * (x * y + w * z)
        R[b, 1, 1] = 1.0 - s * (x * x + z * z)
        R[b, 1, 2] = s * (y * z - w * x)
        R[b, 2, 0] = s * (x * z - w * y)
        R[b, 2, 1] = s * (y * z + w * x)
        R[b, 2, 2] = 1.0 - s * (x * x + y * y)


@_inlined
def body_mass_states(Y, R, inertia, body_of, r, X, U):
    """X_k = c + R r_k, U_k = v + R (w x r_k), w = Pi / I, for the masses of a body (R from body_rotations)."""
    for k in range(X.shape[0]):
        b = body_of[k]
        if b < 0:
            continue
        r0, r1, r2 = r[k, 0], r[k, 1], r[k, 2]
        w0, w1, w2 = Y[b, 10] / inertia[b, 0], Y[b, 11] / inertia[b, 1], Y[b, 12] / inertia[b, 2]
        u0, u1, u2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0  # w x r, body frame
        for d in range(3):
            X[k, d] = Y[b, d] + R[b, d, 0] * r0 + R[b, d, 1] * r1 + R[b, d, 2] * r2
            U[k, d] = Y[b, 3 + d] + R[b, d, 0] * u0 + R[b, d, 1] * u1 + R[b, d, 2] * u2


@_inlined
def body_derivative(Y, R, inertia, body_mass, body_of, r, X, U, F, f, tau, F_base, drag_idx, drag_coef, sa, sb, sk,
                    sr, sc, fixed_idx, dY):
    """dY/dt at Y; leaves R, the mass states X, U and the forces F of (9) at Y in their arrays."""
    body_rotations(Y, R)
    body_mass_states(Y, R, inertia, body_of, r, X, U)
    _forces(X, U, F_base, drag_idx, drag_coef, sa, sb, sk, sr, sc, fixed_idx, F)
    _loads(X, Y, F, body_of, f, tau)
    for b in range(Y.shape[0]):
        P0, P1, P2 = Y[b, 10], Y[b, 11], Y[b, 12]
        w0, w1, w2 = P0 / inertia[b, 0], P1 / inertia[b, 1], P2 / inertia[b, 2]
        qw, qx, qy, qz = Y[b, 6], Y[b, 7], Y[b, 8], Y[b, 9]
        for d in range(3):
            dY[b, d] = Y[b, 3 + d]
            dY[b, 3 + d] = f[b, d] / body_mass[b]
            # Euler's equations in the body frame: dPi/dt = Pi x w + R^T tau
            dY[b, 10 + d] = R[b, 0, d] * tau[b, 0] + R[b, 1, d] * tau[b, 1] + R[b, 2, d] * tau[b, 2]
        dY[b, 10] += P1 * w2 - P2 * w1
        dY[b, 11] += P2 * w0 - P0 * w2
        dY[b, 12] += P0 * w1 - P1 * w0
        # dq/dt = q (x) (0, w) / 2: R <- R Rot(w dt), the body-frame angular velocity on the right
        dY[b, 6] = -0.5 * (qx * w0 + qy * w1 + qz * w2)
        dY[b, 7] = 0.5 * (qw * w0 + qy * w2 - qz * w1)
        dY[b, 8] = 0.5 * (qw * w1 + qz * w0 - qx * w2)
        dY[b, 9] = 0.5 * (qw * w2 + qx * w1 - qy * w0)


@_inlined
def mass_tangent(Y, e, R, inertia, body_of, r, dX, dU, th):
    """(dX, dU): the change of the mass states for a change e of the body states at Y, to first order.
    The quaternion change is taken as the body-frame rotation vector theta = 2 vec(q* (x) e_q) / |q|^2; its
    part along q (a change of |q|, which the renormalisation removes) moves no mass. Applied to dY/dt at Y it
    gives exactly the masses' (U_k, dU_k/dt) there."""
    for b in range(Y.shape[0]):
        qw, qx, qy, qz = Y[b, 6], Y[b, 7], Y[b, 8], Y[b, 9]
        pw, px, py, pz = e[b, 6], e[b, 7], e[b, 8], e[b, 9]
        s = 2.0 / (qw * qw + qx * qx + qy * qy + qz * qz)
        # vec(q* (x) p) = q_w p_v - p_w q_v - q_v x p_v
        th[b, 0] = s * (qw * px - pw * qx - (qy * pz - qz * py))
        th[b, 1] = s * (qw * py - pw * qy - (qz * px - qx * pz))
        th[b, 2] = s * (qw * pz - pw * qz - (qx * py - qy * px))
    for k in range(dX.shape[0]):
        b = body_of[k]
        if b < 0:
            dX[k, 0] = dX[k, 1] = dX[k, 2] = 0.0
            dU[k, 0] = dU[k, 1] = dU[k, 2] = 0.0
            continue
        r0, r1, r2 = r[k, 0], r[k, 1], r[k, 2]
        t0, t1, t2 = th[b, 0], th[b, 1], th[b, 2]
        w0, w1, w2 = Y[b, 10] / inertia[b, 0], Y[b, 11] / inertia[b, 1], Y[b, 12] / inertia[b, 2]
        a0, a1, a2 = e[b, 10] / inertia[b, 0], e[b, 11] / inertia[b, 1], e[b, 12] / inertia[b, 2]
        x0, x1, x2 = t1 * r2 - t2 * r1, t2 * r0 - t0 * r2, t0 * r1 - t1 * r0  # theta x r
        u0, u1, u2 = w1 * r2 - w2 * r1, w2 * r0 - w0 * r2, w0 * r1 - w1 * r0  # w x r
        # theta x (w x r) + (e_Pi / I) x r
        y0 = t1 * u2 - t2 * u1 + a1 * r2 - a2 * r1
        y1 = t2 * u0 - t0 * u2 + a2 * r0 - a0 * r2
        y2 = t0 * u1 - t1 * u0 + a0 * r1 - a1 * r0
        for d in range(3):
            dX[k, d] = e[b, d] + R[b, d, 0] * x0 + R[b, d, 1] * x1 + R[b, d, 2] * x2
            dU[k, d] = e[b, 3 + d] + R[b, d, 0] * y0 + R[b, d, 1] * y1 + R[b, d, 2] * y2


@_inlined
def _combine_rows(Y, h, coef, row, n, KY, out):
    """out = Y + h sum_{j<n} coef[row, j] KY[j]."""
    for b in range(Y.shape[0]):
        for i in range(Y.shape[1]):
            acc = 0.0
            for j in range(n):
                acc += coef[row, j] * KY[j, b, i]
            out[b, i] = Y[b, i] + h * acc
    return out


@njit(cache=True, error_model="numpy")
def _starting_step(Y, dY, R, inertia, body_mass, body_of, r, X, U, F, f, tau, F_base, drag_idx, drag_coef, sa, sb,
                   sk, sr, sc, fixed_idx, free, rtol, atol, exponent, span):
    """Hairer-Wanner's starting step on the masses' states, as the point-mass path chooses it (the same
    kernels): from (U, dU/dt) of the masses at Y and at Y + h0 dY/dt."""
    th = np.empty((Y.shape[0], 3))
    dX, dU, dXs, dUs = np.empty_like(X), np.empty_like(X), np.empty_like(X), np.empty_like(X)
    mass_tangent(Y, dY, R, inertia, body_of, r, dX, dU, th)  # (U_k, a_k)
    h0 = trial_step_size(X, U, dU, free, rtol, atol, span)
    Ys = Y + h0 * dY
    dYs = np.empty_like(Y)
    Rs = np.empty_like(R)
    Xs = X.copy()
    Us = U.copy()
    body_derivative(Ys, Rs, inertia, body_mass, body_of, r, Xs, Us, F, f, tau, F_base, drag_idx, drag_coef, sa, sb,
                    sk, sr, sc, fixed_idx, dYs)
    mass_tangent(Ys, dYs, Rs, inertia, body_of, r, dXs, dUs, th)
    return initial_step_size(X, U, dU, dXs, dUs, h0, free, rtol, atol, exponent, span)


@njit(cache=True, error_model="numpy")
def rigid_rk_advance(Y, t, t_target, h_next, AB, E1, E2, error_kind, exponent, rtol, atol, max_steps, n_fixed,
                     safety, min_factor, max_factor, inertia, body_mass, body_of, r, free, X, U, F_base, drag_idx,
                     drag_coef, sa, sb, sk, sr, sc, fixed_idx):
    """Advance the body states Y (B, 13) in place from t to t_target with the explicit embedded pair (AB: A with
    the weights b as row s; E1, E2: error weights, s + 1 each). The step-size controller is that of the
    point-mass path (linknet_core.compiled_rk): the same starting step, safety factor and bounds, no sliver
    of a last step; the error is measured on the masses' positions and velocities. ``h_next`` <= 0 asks for
    the starting step; ``n_fixed`` > 0 takes n_fixed steps of exactly h_next with no error control (order
    measurements). On return Y holds the last accepted state and X, U its masses' states.
    Returns (status, t, h_next, accepted steps, rejected steps, right-hand side evaluations)."""
    B = Y.shape[0]
    K = X.shape[0]
    s = AB.shape[1]
    KY = np.empty((s + 1, B, 13))
    Ys = np.empty((B, 13))
    Yn = np.empty((B, 13))
    R = np.empty((B, 3, 3))
    R0 = np.empty((B, 3, 3))
    F = np.empty((K, 3))
    f = np.empty((B, 3))
    tau = np.empty((B, 3))
    # masses of no body (anchored spring attachment points) keep their states in every copy
    Xs = X.copy()
    Us = U.copy()
    Xn = X.copy()
    Un = U.copy()
    # the masses' velocities and accelerations at every stage: the error estimate is formed from them
    MX = np.zeros((s + 1, K, 3))
    MU = np.zeros((s + 1, K, 3))
    th = np.empty((B, 3))
    steps = 0
    rejected = 0
    n_rhs = 1
    body_derivative(Y, R0, inertia, body_mass, body_of, r, X, U, F, f, tau, F_base, drag_idx, drag_coef, sa, sb, sk, sr,
                    sc, fixed_idx, KY[0])
    mass_tangent(Y, KY[0], R0, inertia, body_of, r, MX[0], MU[0], th)
    if h_next <= 0.0:
        n_rhs += 1
        h_next = _starting_step(Y, KY[0], R0, inertia, body_mass, body_of, r, X, U, F, f, tau, F_base, drag_idx,
                                drag_coef, sa, sb, sk, sr, sc, fixed_idx, free, rtol, atol, exponent, t_target - t)
    while (steps < n_fixed) if n_fixed > 0 else (t < t_target):
        remaining = t_target - t
        h = h_next if n_fixed > 0 else controlled_step(h_next, t, t_target)
        if h < 0.0:
            return STEP_UNDERFLOW, t, h_next, steps, rejected, n_rhs
        for i in range(1, s):
            _combine_rows(Y, h, AB, i, i, KY, Ys)
            body_derivative(Ys, R, inertia, body_mass, body_of, r, Xs, Us, F, f, tau, F_base, drag_idx, drag_coef, sa,
                            sb, sk, sr, sc, fixed_idx, KY[i])
            if n_fixed == 0:
                mass_tangent(Ys, KY[i], R, inertia, body_of, r, MX[i], MU[i], th)
        _combine_rows(Y, h, AB, s, s, KY, Yn)
        body_derivative(Yn, R, inertia, body_mass, body_of, r, Xn, Un, F, f, tau, F_base, drag_idx, drag_coef, sa, sb,
                        sk, sr, sc, fixed_idx, KY[s])
        mass_tangent(Yn, KY[s], R, inertia, body_of, r, MX[s], MU[s], th)
        n_rhs += s
        if n_fixed > 0:
            err = 0.0
            for b in range(B):
                for i in range(13):
                    if not np.isfinite(Yn[b, i]):
                        return NON_FINITE, t, h_next, steps, rejected, n_rhs
        else:
            err = rk_error_norm(X, U, Xn, Un, MX, MU, h, free, E1, E2, error_kind, rtol, atol)
            if not np.isfinite(err):
                rejected += 1
                h_next = h * min_factor
                continue
        if err <= 1.0:
            if n_fixed > 0:
                t = t + h
            else:
                t = t_target if h == remaining else t + h
                h_next = next_step_size(h, h_next, err, exponent, safety, min_factor, max_factor)
            # renormalise q (the projection of this path). The mass states do not change (the map uses
            # q / |q|), and the derivative at the new point only scales its dq/dt by 1/|q|: it stays the
            # first stage of the next step (no extra evaluation)
            for b in range(B):
                norm = np.sqrt(Yn[b, 6] ** 2 + Yn[b, 7] ** 2 + Yn[b, 8] ** 2 + Yn[b, 9] ** 2)
                for i in range(6, 10):
                    Yn[b, i] /= norm
                    KY[s, b, i] /= norm
            Y[:, :] = Yn
            KY[0, :, :] = KY[s]
            MX[0, :, :] = MX[s]
            MU[0, :, :] = MU[s]
            X[:, :] = Xn
            U[:, :] = Un
            R0[:, :, :] = R
            steps += 1
            if n_fixed == 0 and steps > max_steps:
                return TOO_MANY_STEPS, t, h_next, steps, rejected, n_rhs
        else:
            rejected += 1
            h_next = next_step_size(h, h_next, err, exponent, safety, min_factor, max_factor)
    return OK, t, h_next, steps, rejected, n_rhs
