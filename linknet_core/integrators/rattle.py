"""RATTLE (Andersen 1983): velocity Verlet with the link constraints (11) and (12) enforced every step.

Order 2, symplectic and time-reversible for conservative forces, so the energy error stays bounded over
long runs (no drift). Positions satisfy (11) to the Newton tolerance (1e-14 relative by default) and
velocities satisfy (12) to round-off at the end of every step. With velocity-dependent forces (drag,
dampers) the second force evaluation uses the half-step velocity: still second order, no longer
symplectic (the system is not Hamiltonian then anyway).
"""
from __future__ import annotations


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

    def _advance_steps(self, X, U, n, h, F_input):
        from .. import compiled

        if self.backend != "numpy" and compiled.supports(self.dyn):
            if not hasattr(self, "_kernel"):
                self._kernel = compiled.CompiledRattle(self.dyn)
            status, X_new, U_new = self._kernel.advance(X, U, n, h, self.gammas, F_input, self.position_tol)
            if status == compiled.OK:
                return X_new, U_new
            # singular configuration or slow projection: the numpy path has the fallbacks
            self.compiled_fallbacks += 1
        elif self.backend == "compiled":
            from ..errors import SolverError

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
        return X_new, U_new
