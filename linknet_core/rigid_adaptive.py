"""Adaptive methods on free rigid bodies: the method's own embedded Runge-Kutta pair on the Newton-Euler
equations of every body (see :mod:`linknet_core.rigid` for when a scene is a set of free rigid bodies).

Per body the state is the centre of mass c, its velocity v, the unit quaternion q (body -> space) and the
body angular momentum Pi; the equations are

    dc/dt = v,   dv/dt = f / m,   dq/dt = q (x) (0, w) / 2,   dPi/dt = Pi x w + R(q)^T tau,   w = Pi / I,

with f and tau the resultant and the moment about c of the external forces F_k of (9) (gravity, constant
forces, springs and dampers, drag, inputs) at the masses' states X_k = c + R r_k, U_k = v + R (w x r_k). The
link tensions are internal and cancel (31). This replaces the K masses and L links of the point-mass path
(index-1 system (9), (25)-(26) plus projections onto (11)-(12)) by 13 numbers per body.

* **Tableau**: A, b, error weights and error-estimator order are taken from the point-mass method's class
  (:class:`linknet_core.integrators.runge_kutta.DOPRI5`, ``DOP853``), so the method is the same method.
* **Error control** is on the masses' positions and velocities, not on the body state: at every stage Y_i
  the masses' velocities and accelerations (U_k, dU_k/dt)(Y_i) are formed (exactly, from dY/dt by the
  tangent of Y -> (X, U): kernels' ``mass_tangent``), and the embedded estimate sum_i E_i (U_k, dU_k/dt)(Y_i)
  is measured in exactly the point-mass path's norm (scale atol + rtol max(|y|, |y_new|) per mass
  coordinate, RMS or Hairer's combined 5th/3rd-order norm). That is the estimate the point-mass path forms
  from its stages, so a given rtol asks for the same accuracy of the mass positions on both paths. Two
  alternatives were measured and rejected: a norm on the body state mixes units (m, m/s, 1, kg m^2/s), so
  its rtol means a different position accuracy for every body; and the body-state estimate sum_i E_i
  dY/dt(Y_i) mapped to the masses at the step's start fools DOP853's combined norm on tops: their
  torque-free quaternion kinematics is linear with constant coefficients, where the 5th-order difference
  is already as small as the 8th-order error and Hairer's factor e5 / (0.1 e3) then shrinks it by 1e3-1e4
  (spinning tetrahedron, rtol 1e-10: 1.6e-6 m at t = 2 s against 4e-10 m on the point-mass path; with the
  stage estimate 7e-12 m).
* **Step-size controller**: that of the point-mass path (safety 0.9, factors 0.2..10, Hairer-Wanner
  starting step on the masses' states, no sliver of a last step, step-size underflow and step limit).
* **Projection analogue**: q is renormalised after every accepted step (the link lengths hold by
  construction: the body never changes shape).
* Velocity-dependent forces (drag, dampers) are simply part of the right-hand side of an explicit method;
  an input force is held constant over each ``advance`` (zero-order hold), as on every path.

Whole intervals run in one compiled call (:func:`linknet_core.rigid_kernels.rigid_rk_advance`).
"""
from __future__ import annotations

import numpy as np

from .compiled_rk import ERROR_KINDS, embedded_pair
from .dynamics import Dynamics
from .errors import SolverError
from .integrators import METHODS
from .integrators.base import Integrator
from .integrators.runge_kutta import MAX_FACTOR, MIN_FACTOR, SAFETY  # the point-mass path's controller
from .rigid import BodyLayout, RigidBodies


class AdaptiveRigidBodyPath(RigidBodies, Integrator):
    """An adaptive method (dopri5, dop853) on the Newton-Euler equations of free rigid bodies."""

    adaptive = True

    def __init__(self, dynamics: Dynamics, method: str, rtol: float, atol: float, bodies: BodyLayout, X0, U0,
                 h0: float | None = None):
        Integrator.__init__(self, dynamics)
        cls = METHODS[method]
        if not cls.adaptive:
            raise ValueError(f"{method} is not an adaptive method")
        self.name, self.order, self.symplectic = cls.name, cls.order, cls.symplectic
        self.rtol, self.atol = float(rtol), float(atol)
        self.h = h0
        self._AB, self._E1, self._E2, self._exponent = embedded_pair(cls.A, cls.B, cls.error_weights,
                                                                     cls.error_estimator_order)
        self._error_kind = ERROR_KINDS[cls.error_norm_kind]
        self.guarantees = (f"order {cls.order}, adaptive ({cls.name}'s embedded pair on the Newton-Euler equations "
                           "of each body; error control on the masses' positions and velocities in the point-mass "
                           "path's norm); quaternion renormalised after every step, link lengths kept to "
                           "round-off by construction; not symplectic: energy error follows the tolerance")
        self._init_bodies(dynamics, bodies, X0, U0)
        self._free = np.flatnonzero(self._inside).astype(np.int64)

    def internals(self) -> dict:
        out = super().internals()
        out["h"] = self.h
        return out

    def set_internals(self, data: dict) -> None:
        super().set_internals(data)
        self.h = data["h"]

    # ---- stepping -------------------------------------------------------------------------------
    def _body_states(self) -> np.ndarray:
        return np.ascontiguousarray(np.concatenate([self._c, self._v, self._q, self._Pi], axis=1))

    def _run(self, X, U, t, t_target, h, F_input, max_steps, n_fixed):
        """The compiled interval from the body state fitted to (X, U); returns the kernel's results with the
        new body state and mass state (nothing of self changes)."""
        self._sync(X, U)
        Y = self._body_states()
        Xw = np.array(X, float, order="C")
        Uw = np.array(U, float, order="C")
        k = self._kernels
        status, t, h_next, steps, rejected, n_rhs = k.rigid_rk_advance(
            Y, float(t), float(t_target), 0.0 if h is None else float(h), self._AB, self._E1, self._E2,
            self._error_kind, self._exponent, self.rtol, self.atol, int(max_steps), int(n_fixed), SAFETY, MIN_FACTOR,
            MAX_FACTOR, self.inertia, self.body_mass, self.bodies.body_of, self.r, self._free, Xw, Uw,
            self._base_forces(F_input), *self._force_args)
        self.dyn.rhs_evaluations += n_rhs
        return status, Y, Xw, Uw, t, h_next, steps, rejected

    def _accept(self, Y, X, U):
        self._set_bodies(Y[:, 0:3], Y[:, 3:6], Y[:, 6:10], Y[:, 10:13])
        self._last = (X.copy(), U.copy())

    def advance(self, state, t_target, F_input, max_steps):
        k = self._kernels
        status, Y, X, U, t, h_next, steps, rejected = self._run(state.X, state.U, state.t, t_target, self.h, F_input,
                                                                max_steps, 0)
        self.stats.steps += steps
        self.stats.rejected += rejected
        if status == k.STEP_UNDERFLOW:
            raise SolverError(f"step size underflow at t = {t}: the tolerance rtol = {self.rtol} cannot be met by "
                              "the rigid-body path (forces too stiff or non-finite?)")
        if status == k.TOO_MANY_STEPS:
            raise SolverError(f"more than {max_steps} steps between t = {state.t} and t = {t_target}; raise "
                              "max_steps or the tolerance")
        if status != k.OK:
            raise SolverError(f"the rigid-body state became non-finite between t = {state.t} and t = {t_target}")
        self.h = h_next if h_next > 0 else None
        self._accept(Y, X, U)
        state.X, state.U, state.t = X, U, t_target

    def fixed_steps(self, X, U, h, n, F_input=None):
        """n steps of exactly h without error control, each followed by the renormalisation (order
        measurements). Returns (X, U); the path's own state moves along."""
        status, Y, Xn, Un, *_ = self._run(X, U, 0.0, n * h, h, F_input, n, n)
        if status != self._kernels.OK:
            raise SolverError(f"the rigid-body state became non-finite in {n} fixed steps of h = {h:.3g} s")
        self._accept(Y, Xn, Un)
        return Xn, Un

    def step(self, X, U, h, F_input=None):
        return self.fixed_steps(X, U, h, 1, F_input)
