"""Explicit embedded Runge-Kutta on the index-1 formulation, projected onto the constraint manifolds.

The index-1 ODE is dX/dt = U (10), dU/dt = accelerations with the tensions of (25)-(26) (9). It keeps
(13) exactly but lets (11) and (12) drift, so after every accepted step the positions are projected onto
(11) and the velocities onto (12) (mass-metric orthogonal projections). The projection does not lower
the order of the method. The step size is controlled by the embedded error estimate to meet
``rtol``/``atol`` (SI units; atol defaults to rtol). A method is defined by its tableau only; the
tableaux (linknet_core.integrators.tableaux) are those of scipy's RK45 (Dormand-Prince 5(4)) and DOP853 (Hairer's
8(5,3)).

This is the readable reference: the native core (linknet_core/native/src/stages/runge_kutta.c) runs the
same algorithm on the same tableau, and the tests hold the two together to round-off.
"""
from __future__ import annotations

import math

import numpy as np
from linknet_core.dynamics.drive import motion_note
from linknet_core.errors import SolverError, StepFailure
from linknet_core.integrators import tableaux
from linknet_core.integrators.base import Integrator, explain_step_failure
from linknet_core.tolerances import MAX_FACTOR, MIN_FACTOR, SAFETY



# The fraction of a method's stability interval on the negative real axis that a stiff decaying mode's rate times the
# step may reach (AdaptiveEvents._step_cap: a sliding contact's slip direction)
STIFF_SAFETY = 0.9
# A sliding contact whose acceleration along the plane turns its slip by a sine at most this is straight: its motion
# across the slip is round-off (a slip in a plane: 1e-30 in the tests, a turning one's 1e-9 and more), which the stiff
# mode across it cannot make more than the tolerance, and the cap spares it
STRAIGHT_SLIP = 1e-12


def real_stability_limit(A, B) -> float:
    """x > 0 where the stability function R(z) = 1 + z b^T (I - z A)^-1 1 of the explicit tableau (A, B) first leaves
    the unit disc on the negative real axis: |R(z)| <= 1 on [-x, 0] (Hairer and Wanner, Solving ODEs II, IV.2). R is
    the polynomial 1 + sum_j b^T A^(j-1) 1 z^j; x is the negative real root of R^2 - 1 nearest 0 other than 0."""
    B = np.asarray(B, float)
    s = B.size
    A_square = np.zeros((s, s))
    A = np.asarray(A, float)
    A_square[:, :min(A.shape[1], s)] = A[:s, :s]
    coefficients = [1.0]  # lowest degree first
    power = np.ones(s)
    for _ in range(s):
        coefficients.append(float(B @ power))
        power = A_square @ power
    R = np.polynomial.Polynomial(coefficients)
    roots = np.concatenate([(R - 1).roots(), (R + 1).roots()])
    real = roots[(np.abs(roots.imag) <= 1e-9 * np.abs(roots)) & (roots.real < -1e-9)].real
    return float(-real.max())


class ProjectedRungeKutta(Integrator):
    """A method is its tableau: A, B (n_stages), the error weights (n_stages + 1 each, the last for the
    right-hand side at the new point) and which error norm combines them ('rms': the RMS norm of
    h * sum E_i k_i; 'hairer': DOP853's combined 5th/3rd-order estimate from two weight vectors)."""

    adaptive = True
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    error_weights: tuple
    error_norm_kind = "rms"
    error_estimator_order: int
    n_stages: int
    keeps_stage_tensions = False  # the event-driven variants (integrators.events) screen the stages' forces
    real_stability: float  # real_stability_limit of the tableau
    stiff_safety = STIFF_SAFETY
    straight_slip = STRAIGHT_SLIP
    def __init__(self, dynamics, rtol: float = 1e-8, atol: float | None = None, h0: float | None = None):
        super().__init__(dynamics)
        for name, value in (("rtol", rtol), ("atol", atol)):
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SolverError(f"{name} must be a positive finite tolerance, got {value!r}")
        if rtol < 1e-15:
            raise SolverError(f"rtol = {rtol!r} is below what double precision can deliver (1e-15)")
        self.rtol = float(rtol)
        self.atol = float(atol if atol is not None else rtol)
        self.h = h0  # next step size; None until the first step is chosen
        self.free = dynamics.scene.free_indices

    def internals(self) -> dict:
        out = super().internals()
        out["h"] = self.h
        return out

    def set_internals(self, data: dict) -> None:
        super().set_internals(data)
        self.h = data["h"]

    # ---- one attempted step ------------------------------------------------------------------
    def _f(self, X, U, F_input, t=0.0):
        """(dX/dt, dU/dt) at (X, U, t). Driven anchors are known functions of time, not part of the integrated
        state: their rows are set to the motion at t (and the derivatives there are its V and A)."""
        if self.drive is None:
            acc, self._T = self.dyn.accelerations(X, U, F_input)
            return U, acc
        X, U, anchor_acc = self.drive.apply(t, X, U)
        acc, self._T = self.dyn.accelerations(X, U, F_input, anchor_acc)
        return U, acc

    def _attempt(self, X, U, h, k0, F_input, t=0.0, t_end=None):
        s = self.n_stages
        KX = np.empty((s + 1,) + X.shape)
        KU = np.empty((s + 1,) + U.shape)
        KX[0], KU[0] = k0
        self.stage_tensions = []  # (c_i, the tensions at stage i), kept where an event integrator looks inside steps
        keep = self.keeps_stage_tensions
        for i in range(1, s):
            a = self.A[i, :i]
            Xi = X + h * np.tensordot(a, KX[:i], axes=1)
            Ui = U + h * np.tensordot(a, KU[:i], axes=1)
            KX[i], KU[i] = self._f(Xi, Ui, F_input, t + self.C[i] * h)
            if keep:
                self.stage_tensions.append((float(self.C[i]), self._T))
        X_new = X + h * np.tensordot(self.B, KX[:s], axes=1)
        U_new = U + h * np.tensordot(self.B, KU[:s], axes=1)
        t_end = t + h if t_end is None else t_end
        if self.drive is not None:
            X_new, U_new, _ = self.drive.apply(t_end, X_new, U_new)
        KX[s], KU[s] = self._f(X_new, U_new, F_input, t_end)
        return X_new, U_new, KX, KU

    def _scale(self, X, U, X_new, U_new):
        y = np.concatenate([X[self.free].ravel(), U[self.free].ravel()])
        y_new = np.concatenate([X_new[self.free].ravel(), U_new[self.free].ravel()])
        return self.atol + self.rtol * np.maximum(np.abs(y), np.abs(y_new))

    def _stage_errors(self, KX, KU, weights):
        return np.concatenate([np.tensordot(weights, KX, axes=1)[self.free].ravel(),
                               np.tensordot(weights, KU, axes=1)[self.free].ravel()])

    def error_norm(self, KX, KU, h, scale) -> float:
        if self.error_norm_kind == "hairer":
            # Hairer's combined estimate, as in scipy's DOP853
            err5 = self._stage_errors(KX, KU, self.error_weights[0]) / scale
            err3 = self._stage_errors(KX, KU, self.error_weights[1]) / scale
            e5, e3 = float(np.dot(err5, err5)), float(np.dot(err3, err3))
            if e5 == 0.0 and e3 == 0.0:
                return 0.0
            return abs(h) * e5 / math.sqrt((e5 + 0.01 * e3) * scale.size)
        err = h * self._stage_errors(KX, KU, self.error_weights[0]) / scale
        return float(np.sqrt(np.mean(err ** 2)))

    def _initial_step(self, X, U, k0, F_input, span, t=0.0):
        """Hairer-Wanner's starting step (as scipy's select_initial_step)."""
        scale = self._scale(X, U, X, U)
        y = np.concatenate([X[self.free].ravel(), U[self.free].ravel()])
        f0 = np.concatenate([k0[0][self.free].ravel(), k0[1][self.free].ravel()])
        d0 = np.sqrt(np.mean((y / scale) ** 2))
        d1 = np.sqrt(np.mean((f0 / scale) ** 2))
        h0 = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        h0 = min(h0, span)
        k1 = self._f(X + h0 * k0[0], U + h0 * k0[1], F_input, t + h0)
        f1 = np.concatenate([k1[0][self.free].ravel(), k1[1][self.free].ravel()])
        d2 = np.sqrt(np.mean(((f1 - f0) / scale) ** 2)) / h0
        if d1 <= 1e-15 and d2 <= 1e-15:
            h1 = max(1e-6, h0 * 1e-3)
        else:
            h1 = (0.01 / max(d1, d2)) ** (1.0 / (self.error_estimator_order + 1))
        return min(100 * h0, h1, span)

    def step(self, X, U, h, F_input=None, t=0.0, t_end=None):
        """One step of size h without error control, then the projections: used to measure the
        method's order (tests) and available to callers that want a fixed step."""
        X_new, U_new, _, _ = self._attempt(X, U, h, self._f(X, U, F_input, t), F_input, t)
        X_new, _ = self.dyn.project_positions(X_new, tol=1e-14)
        return X_new, self.dyn.project_velocities(X_new, U_new)

    def fixed_steps(self, X, U, h, n, F_input=None, t=0.0):
        """n steps of size h without error control, each followed by the projections (order measurements).
        Returns (X, U)."""
        for i in range(n):
            X, U = self.step(X, U, h, F_input, t + i * h)
        return X, U

    def _step_cap(self, X, U, acc, T) -> float:
        """The longest step the dynamics allows this method from (X, U) at the step's start (acc, T the accelerations
        and tensions there), whatever its error estimate: where a stiff mode would make the method unstable
        (integrators.events: sliding friction); none for a scene of rods."""
        return math.inf

    def _event_in_step(self, X, U, t, k0, X_new, U_new, t_new, acc_new, F_input):
        """An event within the accepted step from (X, U) at t to (X_new, U_new) at t_new, or None: where it ends the
        step (X, U, t) after the event's impulse (integrators.events; scenes of rods have none)."""
        return None

    # ---- driver ------------------------------------------------------------------------------
    def advance(self, state, t_target, F_input, max_steps):
        """From the state towards t_target with error control; leaves the next step size in self.h."""
        dyn = self.dyn
        X, U, t, t_start = state.X, state.U, state.t, state.t
        k0 = self._f(X, U, F_input, t)
        cap = self._step_cap(X, U, k0[1], self._T)  # the controller's h stands where it is shorter
        self.peaks.begin(t, self._T)  # the tensions _f left: those at the start
        if self.h is None:
            self.h = self._initial_step(X, U, k0, F_input, t_target - t, t)
        exponent = -1.0 / (self.error_estimator_order + 1)
        steps = 0
        while t < t_target:
            remaining = t_target - t
            h = min(self.h, cap, remaining)
            if h < remaining < 1.1 * h:  # avoid a sliver of a last step: split the rest in two
                h = 0.5 * remaining
            if h <= 16 * np.spacing(max(abs(t), 1.0)) and h < remaining:
                note = "" if self.drive is None else motion_note(self.drive.scene, t - self.drive.t0,
                                                                   t + h - self.drive.t0)
                raise SolverError(f"step size underflow at t = {t}: the tolerance rtol = {self.rtol} cannot be "
                                  f"met (singular configuration or discontinuous input?){note}")
            t_new = t_target if h == remaining else t + h
            X_new, U_new, KX, KU = self._attempt(X, U, h, k0, F_input, t, t_new)
            T_new = self._T  # at the new point, before the projections
            err = self.error_norm(KX, KU, h, self._scale(X, U, X_new, U_new))
            if not math.isfinite(err):
                self.stats.rejected += 1
                self.h = h * MIN_FACTOR
                continue
            if err <= 1.0:
                try:
                    X_new, _ = dyn.project_positions(X_new, tol=1e-14)  # onto (11)
                except StepFailure as failure:
                    failure.start = (X, U, t)
                    raise SolverError(explain_step_failure(dyn, failure, t_start, t_target, F_input,
                                                           self.drive)) from None
                U_new = dyn.project_velocities(X_new, U_new)  # onto (12)
                event = self._event_in_step(X, U, t, k0, X_new, U_new, t_new, KU[-1], F_input)
                if event is not None:  # ropes, a ground: the step ends at an event, past its impulse, in a new mode
                    X_new, U_new, t_new = event
                    dyn = self.dyn
                t = t_new
                X, U = X_new, U_new
                factor = MAX_FACTOR if err == 0 else min(MAX_FACTOR, SAFETY * err ** exponent)
                # a step shortened only to land on t_target says nothing against the longer step
                self.h = max(self.h, h * factor) if h < self.h else h * factor
                steps += 1
                self.stats.steps += 1
                if steps > max_steps:
                    why = "raise max_steps or the tolerance"
                    if dyn.floor_stops:  # the native core's note (NativeIntegrator.explain)
                        why = (f"the position projection onto the link lengths (11) has stopped at its conditioning "
                               f"floor {dyn.floor_stops} times in this run (largest residual {dyn.floor_reached:.3g} "
                               "relative): a singular or badly conditioned configuration (a taut string, a flat "
                               "braced cell pushed out of its plane), where more steps or a looser tolerance may not "
                               "help")
                    raise SolverError(f"more than {max_steps} steps between t = {t_start} and t = {t_target}; {why}")
                if t < t_target:  # the first stage of the next step (none after the last one)
                    k0 = self._f(X, U, F_input, t)
                    T_new = self._T
                    cap = self._step_cap(X, U, k0[1], T_new)
                self.peaks.step(t, T_new)
            else:
                self.stats.rejected += 1
                self.h = h * max(MIN_FACTOR, SAFETY * err ** exponent)
        state.X, state.U, state.t = X, U, t_target


class DOPRI5(ProjectedRungeKutta):
    name = "dopri5"
    order = 5
    error_estimator_order = 4
    n_stages = 6
    A, B, C = tableaux.DOPRI5_A, tableaux.DOPRI5_B, tableaux.DOPRI5_C
    real_stability = real_stability_limit(A, B)
    error_weights = (tableaux.DOPRI5_E,)
    guarantees = ("order 5, adaptive (Dormand-Prince 5(4)); after every step positions are projected onto (11) "
                  "and velocities onto (12); not symplectic: energy error follows the tolerance and may drift")


class DOP853(ProjectedRungeKutta):
    name = "dop853"
    order = 8
    error_estimator_order = 7
    n_stages = 12
    A, B, C = tableaux.DOP853_A, tableaux.DOP853_B, tableaux.DOP853_C
    real_stability = real_stability_limit(A, B)
    error_weights = (tableaux.DOP853_E5, tableaux.DOP853_E3)
    error_norm_kind = "hairer"
    guarantees = ("order 8, adaptive (Hairer's DOP853 with its 5th/3rd-order error estimate); projected onto (11) "
                  "and (12) after every step; not symplectic: energy error follows the tolerance")
