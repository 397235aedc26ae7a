"""RATTLE (Andersen 1983): velocity Verlet with the link constraints (11) and (12) enforced every step.

Order 2, symplectic and time-reversible for conservative forces, so the energy error stays bounded over
long runs (no drift). Positions satisfy (11) to the Newton tolerance (1e-14 relative by default) and
velocities satisfy (12) to round-off at the end of every step. With velocity-dependent forces (drag,
dampers) the second half kick is implicit in the new velocity (fixed-point iteration): the step stays
symmetric and second order; it is no longer symplectic (the system is not Hamiltonian then anyway).
"""
from __future__ import annotations

import numpy as np

from ..compiled_kernels import OK as COMPILED_OK
from ..errors import SolverError
from .base import FixedStepIntegrator


class Rattle(FixedStepIntegrator):
    name = "rattle"
    order = 2
    symplectic = True
    guarantees = ("order 2; symplectic and time-reversible (conservative forces); link lengths (11) to "
                  "1e-14 relative and velocity constraints (12) to round-off after every step; bounded energy error")
    position_tol = 1e-14
    gammas: tuple[float, ...] = (1.0,)
    compiled_fallbacks = 0  # intervals the compiled loop handed back to the numpy path

    def __init__(self, dynamics, dt: float, backend: str = "auto"):
        super().__init__(dynamics, dt, backend=backend)
        self._kernel = self._compiled_kernel() if self.backend != "numpy" else None

    def internals(self) -> dict:
        out = super().internals()
        if getattr(self, "_kernel", None) is not None:
            out["compiled_planar"] = self._kernel.planar  # 2-D kernels until the state left the plane
        return out

    def set_internals(self, data: dict) -> None:
        super().set_internals(data)
        kernel = getattr(self, "_kernel", None)
        if kernel is not None and "compiled_planar" in data:
            kernel.planar = bool(data["compiled_planar"]) and kernel.is_planar_scene

    def _compiled_kernel(self):
        """The compiled loop of this scene (built with the integrator), or None where the numpy path runs. Its
        ``planar`` says whether the next interval runs in the plane's coordinates (False forces 3-D)."""
        from .. import compiled

        if getattr(self, "_kernel", None) is None and compiled.supports(self.dyn):
            self._kernel = compiled.CompiledRattle(self.dyn)
        return getattr(self, "_kernel", None)

    def _advance_steps(self, X, U, n, h, F_input):
        kernel = self._kernel  # decided at construction (None: the numpy path); no per-call lookups here
        if kernel is not None:
            remaining = n
            while remaining:
                status, X_new, U_new = kernel.advance(X, U, remaining, h, self.gammas, F_input, self.position_tol)
                if status == COMPILED_OK:
                    return X_new, U_new
                # singular configuration or slow projection: the failing step takes the numpy path (it has the
                # exact-Newton and minimum-norm fallbacks), then the compiled loop resumes. Handing the whole
                # rest of the interval to numpy made a whipping chain_1000 ~100x slower after one hard step.
                self.compiled_fallbacks += 1
                done = kernel.completed_steps
                if done:
                    # the kernel's arrays stop inside the failing step: redo the completed steps (the same
                    # arithmetic, so the same bits) to land on the last step boundary
                    status, X_done, U_done = kernel.advance(X, U, done, h, self.gammas, F_input, self.position_tol)
                    if status != COMPILED_OK:
                        break
                    X, U, remaining = X_done, U_done, remaining - done
                X, U = self.step(X, U, h, F_input)
                remaining -= 1
            if not remaining:
                return X, U
            n = remaining
        elif self.backend == "compiled":
            raise SolverError(f"the compiled loop does not handle {self.dyn.structure.kind} scenes; use backend 'auto'")
        return super()._advance_steps(X, U, n, h, F_input)

    def step(self, X, U, h, F_input):
        dyn = self.dyn
        inv_m = dyn._inv_mass3
        F0 = dyn.forces(X, U, F_input)
        U_half = U + 0.5 * h * inv_m * F0
        X_free = X + h * U_half
        # position stage: X_new = X_free + M^-1 C(X)^T mu on the manifold (11); mu = (h^2/2) * multipliers
        X_new, _ = dyn.project_positions(X_free, tol=self.position_tol, direction_at=X)
        U_half = (X_new - X) / h
        # velocity stage: half kick with the new forces, then projection onto (12) at X_new
        F1 = dyn.forces(X_new, U_half, F_input)
        U_new = dyn.project_velocities(X_new, U_half + 0.5 * h * inv_m * F1)
        if self._velocity_dependent():
            U_new = self._implicit_kick(X_new, U_half, U_new, h, F_input)
        return X_new, U_new

    def _velocity_dependent(self) -> bool:
        scene = self.dyn.scene
        return bool((scene.drag != 0).any() or (scene.springs.damping != 0).any())

    def _implicit_kick(self, X_new, U_half, U_new, h, F_input):
        """Second half kick with the forces at U_{n+1} itself (drag, dampers): the step stays symmetric and
        so second order (with the half-step velocity it is first order). Fixed-point iteration, contraction
        factor ~ h c / (2 m) for a damping coefficient c on a mass m."""
        dyn = self.dyn
        for _ in range(60):
            F1 = dyn.forces(X_new, U_new, F_input)
            U_next = dyn.project_velocities(X_new, U_half + 0.5 * h * dyn._inv_mass3 * F1)
            change = float(np.abs(U_next - U_new).max())
            U_new = U_next
            if change <= 4e-16 * float(np.abs(U_new).max()) or change == 0.0:
                return U_new
        raise SolverError(f"the implicit velocity half step (drag, dampers) does not converge at dt = {h:g}: the "
                          "damping is too stiff for this step (h c / 2m near or above 1); reduce dt")
