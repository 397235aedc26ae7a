"""RATTLE (Andersen 1983): velocity Verlet with the link constraints (11) and (12) enforced every step.

Order 2, symplectic and time-reversible for conservative forces, so the energy error stays bounded over
long runs (no drift). Positions satisfy (11) to the Newton tolerance (1e-14 relative by default) and
velocities satisfy (12) to round-off at the end of every step. With velocity-dependent forces (drag,
dampers, a sliding mass's Coulomb friction on a ground) the second half kick is implicit in the new velocity
(fixed-point iteration): the step stays symmetric and second order; it is no longer symplectic (the system is
not Hamiltonian then anyway).
"""
from __future__ import annotations

import numpy as np

from linknet_core.errors import StepFailure
from linknet_core.dynamics.forces import has_velocity_dependent_forces
from linknet_core.integrators.base import FixedStepIntegrator


class Rattle(FixedStepIntegrator):
    name = "rattle"
    order = 2
    symplectic = True
    guarantees = ("order 2; symplectic and time-reversible (conservative forces); link lengths (11) to "
                  "1e-14 relative and velocity constraints (12) to round-off after every step; bounded energy error")
    position_tol = 1e-14
    gammas: tuple[float, ...] = (1.0,)
    # a list where the event-driven variant (integrators.events) screens the forces inside a step: each stage's
    # (time, X, U) at the middle of its drift, X + h/2 U_half with the half kick's velocity U_half
    stage_midpoints: list | None = None

    def step(self, X, U, h, F_input, t=0.0, t_end=None):
        dyn, drive = self.dyn, self.drive
        t_end = t + h if t_end is None else t_end
        inv_m = dyn._inv_mass3
        F0 = dyn.forces(X, U, F_input)
        U_half = U + 0.5 * h * inv_m * F0
        if self.stage_midpoints is not None:
            self.stage_midpoints.append((t + 0.5 * (t_end - t), X + 0.5 * h * U_half, U_half))
        X_free = X + h * U_half
        if drive is not None:  # driven anchors: the position stage targets |X_k - P_a(t + h)| = R_l (11)
            X_free = drive.place(t_end, X_free)
        # position stage: X_new = X_free + M^-1 C(X)^T mu on the manifold (11); mu = (h^2/2) * multipliers
        newton_projections = dyn.exact_newton_projections
        X_new, _ = dyn.project_positions(X_free, tol=self.position_tol, direction_at=X,
                                         step=(self.dt, max(abs(g) for g in self.gammas), U, F_input))
        U_half = self._velocity_after_position_stage(X, X_free, X_new, U_half, h,
                                                     newton_projections == dyn.exact_newton_projections)
        # velocity stage: half kick with the new forces, then projection onto (12) at X_new (relative to the
        # driven anchors' V_a(t + h))
        F1 = dyn.forces(X_new, U_half, F_input)
        U_kicked = U_half + 0.5 * h * inv_m * F1
        if drive is not None:
            U_kicked = drive.move_velocities(t_end, U_kicked)
        U_new = dyn.project_velocities(X_new, U_kicked)
        drag = has_velocity_dependent_forces(self.dyn.scene)
        if drag or getattr(self.dyn, "sliding_friction", False):  # Coulomb friction on a sliding mass (ropes, ground)
            U_new = self._implicit_kick(X_new, U_half, U_new, h, F_input, t_end, stiff_ok=not drag)
        return X_new, U_new

    def _velocity_after_position_stage(self, X, X_free, X_new, U_half, h, factored_at_X):
        """U_half plus the position stage's correction M^-1 C(X)^T mu over h (seed (9), (11)), as the native core
        takes it (velocity_after_position_stage, stages/rattle.c): not read off as the rounded X_new - X, whose
        coordinates' rounding, ulp(|X|) / h per step, would make the positions drift like ulp(|X|) N^1.5 over N
        steps, but as the normal part of X_new - X_free at X in the mass metric (what the velocity projection at X
        removes, on A(X) still factored), whose leftover rounding lies along the links. After exact Newton or
        Gauss-Newton (A no longer factored at X), or in a scene without any constraint: (X_new - X) / h. Anchors:
        (X_new - X) / h. A scene with a ground has its contacts' rows (the native core's model keeps them, off while
        a mass flies): a mass alone on a ground takes the correction too, as the rounded difference would spoil its
        slide along the plane."""
        scene = self.dyn.scene
        if not factored_at_X or (scene.L == 0 and scene.ground is None):
            return (X_new - X) / h
        shift = X_new - X_free
        normal = shift - self.dyn.project_velocities(X, shift)
        return np.where(self.dyn._inv_mass3 == 0.0, (X_new - X) / h, U_half + normal / h)

    def _implicit_kick(self, X_new, U_half, U_new, h, F_input, t_end, stiff_ok=False):
        """Second half kick with the forces at U_{n+1} itself (drag, dampers, a sliding mass's Coulomb friction
        along its velocity): the step stays symmetric and so second order (with the half-step velocity it is first
        order). Fixed-point iteration, contraction factor ~ h c / (2 m) for a damping coefficient c on a mass m, and
        ~ h mu N / (2 m |v_t|) for friction, which a slow slip (its first steps from rest) takes above 1. With
        ``stiff_ok`` (friction alone) an iteration that stops contracting ends with its first iterate instead: the
        kick with the forces at the explicit kick's velocity, whose error O(h^2) leaves the step second order."""
        dyn = self.dyn
        first, last_change = None, np.inf
        for _ in range(60):
            F1 = dyn.forces(X_new, U_new, F_input)
            U_kicked = U_half + 0.5 * h * dyn._inv_mass3 * F1
            if self.drive is not None:
                U_kicked = self.drive.move_velocities(t_end, U_kicked)
            U_next = dyn.project_velocities(X_new, U_kicked)
            change = float(np.abs(U_next - U_new).max())
            U_new = U_next
            first = U_new if first is None else first
            if change <= 4e-16 * float(np.abs(U_new).max()) or change == 0.0:
                return U_new
            if stiff_ok and change >= last_change:
                return first
            last_change = change
        if stiff_ok:
            return first
        raise StepFailure(f"the implicit velocity half step (drag, dampers) does not converge at dt = {h:g}: the "
                          "damping is too stiff for this step (h c / 2m near or above 1); reduce dt")
