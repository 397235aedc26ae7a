"""Compiled projected Runge-Kutta: the whole interval between two output points in one numba call.

Same algorithm as :class:`linknet_core.integrators.runge_kutta.ProjectedRungeKutta` (tested against it to
round-off): the stages of an explicit embedded tableau on the index-1 formulation dX/dt = U (10),
dU/dt = accelerations (9) with the tensions of (25)-(26) (:func:`linknet_core.compiled.accelerations`),
the embedded error estimate, the same step-size controller, and after every accepted step the projection
of the positions onto (11) and of the velocities onto (12).

The method is data: the tableau (A, b) and the error weights are arguments, so adding a tableau needs no
compiled code. Two error norms exist: the RMS norm of the embedded difference (Dormand-Prince and most
pairs) and Hairer's combined 5th/3rd-order estimate of DOP853.

The step loop itself is ``_rk_steps`` in :mod:`linknet_core.compiled_kernels` (3-D) and its generated 2-D
twin; a planar scene runs in its plane's coordinates until an input force or the state leaves the plane
(see :mod:`linknet_core.compiled`).

Whenever the kernel cannot continue (a vanishing pivot of A, a projection that does not contract,
non-finite values) it stops at the last accepted step and says why; the integrator takes the trouble on
the numpy path, which has the minimum-norm and Gauss-Newton fallbacks, and the kernel resumes after it in
the same interval (:meth:`linknet_core.integrators.runge_kutta.ProjectedRungeKutta.advance`).

The class is called once per output interval (every FMU doStep), so its step loops are called through
:class:`linknet_core.compiled.DirectCall`, without numba's per-call type dispatch.
"""
from __future__ import annotations

import numpy as np

from .compiled import KERNELS, CompiledScene, DirectCall
from .compiled_kernels import (HAIRER_ERROR, LEFT_PLANE, NON_FINITE, OK, PROJECTION_FAILED, RMS_ERROR, SINGULAR,
                               STEP_UNDERFLOW, TOO_MANY_STEPS)
from . import compiled_kernels_2d as k2

__all__ = ["CompiledRungeKutta", "embedded_pair", "ERROR_KINDS", "RMS_ERROR", "HAIRER_ERROR", "OK",
           "PROJECTION_FAILED", "SINGULAR", "NON_FINITE", "STEP_UNDERFLOW", "TOO_MANY_STEPS", "LEFT_PLANE"]


def rk_scratch(K, L, s, dim=3):
    """Scratch arrays of :class:`CompiledRungeKutta`'s step loop for s stages (allocated once per scene and tableau), in the order of
    compiled_kernels._rk_steps: KX, KU; Xs, Us, Xn, Un, acc, acc1; T; E; F; B, mu, phi, scale."""
    return (np.empty((s + 1, K, dim)), np.empty((s + 1, K, dim)), np.empty((K, dim)), np.empty((K, dim)),
            np.empty((K, dim)), np.empty((K, dim)), np.empty((K, dim)), np.empty((K, dim)), np.zeros(L),
            np.empty((L, dim)), np.empty((K, dim)), np.empty(L), np.empty(L), np.empty(L), np.empty(L))


ERROR_KINDS = {"rms": RMS_ERROR, "hairer": HAIRER_ERROR}  # ProjectedRungeKutta.error_norm_kind -> kernel code


def embedded_pair(A, B, error_weights, error_estimator_order):
    """The arrays an explicit embedded tableau is handed to a compiled loop as (this one and
    rigid_kernels.rigid_rk_advance): AB (A with the weights b as row s), the error weights E1, E2 (s + 1
    each; E2 zero for a single-estimate norm) and the controller's exponent -1 / (order of the estimate + 1)."""
    B = np.asarray(B, np.float64)
    s = B.shape[0]
    A = np.asarray(A, np.float64)
    if A.ndim != 2 or A.shape[0] != s or A.shape[1] > s or np.any(np.triu(A[:, :s]) != 0.0):
        raise ValueError(f"an explicit tableau needs a strictly lower-triangular A with {s} rows, got {A.shape}")
    AB = np.zeros((s + 1, s))
    AB[:s, :A.shape[1]] = A
    AB[s] = B
    E1 = np.ascontiguousarray(error_weights[0], np.float64)
    E2 = np.ascontiguousarray(error_weights[1] if len(error_weights) > 1 else np.zeros_like(E1), np.float64)
    if E1.shape != (s + 1,) or E2.shape != (s + 1,):
        raise ValueError(f"error weights must have {s + 1} entries (one per stage and one for the new point), "
                         f"got {E1.shape} and {E2.shape}")
    return AB, E1, E2, -1.0 / (error_estimator_order + 1)


class CompiledRungeKutta(CompiledScene):
    """The compiled step loop (``_rk_steps`` of linknet_core.compiled_kernels, or its planar twin) for one scene
    and one tableau (A, b, error weights, error norm): AB, the s x s matrix A with the weights b as row s;
    E1, E2, error weights (s + 1 each, the last for the right-hand side at the new point)."""

    def __init__(self, dyn, A, B, error_weights, error_kind: int, error_estimator_order: int,
                 use_chain: bool | None = None, planar: bool | None = None):
        super().__init__(dyn, use_chain=use_chain, planar=planar)
        self.AB, self.E1, self.E2, self.exponent = embedded_pair(A, B, error_weights, error_estimator_order)
        s = self.AB.shape[1]
        self.scratch = rk_scratch(self.K, self.L, s)
        if self.planar:
            self.scratch2 = rk_scratch(self.K, self.L, s, 2)
        self.error_kind = int(error_kind)
        self._steps_in_plane = DirectCall(k2._rk_steps_in_plane)
        self._steps_3d = DirectCall(KERNELS[3]._rk_steps)

    def advance(self, X, U, t, t_target, h, F_input, rtol, atol, max_steps, controller, n_fixed=0,
                projection_tol=1e-14):
        """From (X, U) at t towards t_target. ``h`` None asks for the starting step to be chosen; ``n_fixed`` > 0
        instead takes n_fixed steps of exactly h with no error control (order measurements). Returns (status,
        X, U, t, h_next or None, accepted steps, rejected steps, rhs evaluations); X, U are new (K,3) arrays
        (the last accepted state), the arguments are not modified."""
        safety, min_factor, max_factor = controller
        h0 = 0.0 if h is None else float(h)
        if self.planar:
            X3, U3, F_in = self._plane_inputs(X, U, F_input)
            X_out, U_out = np.empty((self.K, 3)), np.empty((self.K, 3))
            status, t_end, h_next, steps, rejected, n_rhs = self._steps_in_plane(
                X3, U3, self.F_scene, F_in, X_out, U_out, *self.plane, float(t), float(t_target), h0, self._X2,
                self._U2, self._F2, *self.scene, *self.system, self.AB, self.E1, self.E2, self.error_kind,
                self.exponent, float(rtol), float(atol), int(max_steps), int(n_fixed), float(safety),
                float(min_factor), float(max_factor), float(projection_tol), *self.scratch2)
            if status != LEFT_PLANE:
                return status, X_out, U_out, t_end, (h_next if h_next > 0.0 else None), steps, rejected, n_rhs
            self.planar = False  # the state or the input left the plane: 3-D from here on
        Xw = np.array(X, dtype=np.float64, copy=True, order="C")
        Uw = np.array(U, dtype=np.float64, copy=True, order="C")
        status, t, h_next, steps, rejected, n_rhs = self._steps_3d(
            Xw, Uw, float(t), float(t_target), h0, self.base_forces(F_input), *self.scene, *self.system, self.AB,
            self.E1, self.E2, self.error_kind, self.exponent, float(rtol), float(atol), int(max_steps), int(n_fixed),
            float(safety), float(min_factor), float(max_factor), float(projection_tol), *self.scratch)
        return status, Xw, Uw, t, (h_next if h_next > 0.0 else None), steps, rejected, n_rhs
