"""Dynamics of one scene: forces, tensions (25)-(26), accelerations (9), projections onto (11)-(12).

``Dynamics`` is built once per scene (it analyses the structure and prepares the tension solver) and is
then a pure function of (X, U, F_input): it holds no state of the simulation.
"""
from __future__ import annotations

import numpy as np

from .errors import ConsistencyError, SolverError
from .forces import external_forces, kinetic_energy, potential_energy
from .scene import Scene
from .structure import Structure, analyse, rank_and_nullspace
from .tensions import TensionSolver, make_solver, rhs, unit_vectors


class Dynamics:
    def __init__(self, scene: Scene, structure: Structure | None = None):
        self.scene = scene
        self.structure = structure or analyse(scene)
        self.solver: TensionSolver = make_solver(scene, self.structure)
        self._factored_at: np.ndarray | None = None
        self._k1, self._k2 = scene.k1, scene.k2
        self._inv_mass = scene.inv_mass
        self._inv_mass3 = scene.inv_mass[:, None]
        self.rhs_evaluations = 0
        self.exact_newton_projections = 0

    # ---- building blocks ----------------------------------------------------------------------
    def forces(self, X, U, F_input=None) -> np.ndarray:
        return external_forces(self.scene, X, U, F_input)

    def unit_vectors(self, X) -> np.ndarray:
        return unit_vectors(self.scene, X)

    def tension_matrix(self, X):
        """A of (25) (symmetric scipy.sparse CSR, original link numbering)."""
        return self.solver.assembly.matrix(self.unit_vectors(X))

    def tension_rhs(self, X, U, F) -> np.ndarray:
        """B of (26) for total external forces F."""
        return rhs(self.scene, X, U, F)

    def factor(self, X) -> None:
        """Factor A(X) unless the last factorisation was at this very configuration."""
        if self._factored_at is not None and np.array_equal(self._factored_at, X):
            return
        self.solver.factor(self.unit_vectors(X))
        self._factored_at = np.array(X, copy=True)

    def solve(self, X, b) -> np.ndarray:
        if self.scene.L == 0:
            return np.zeros(0)
        self.factor(X)
        return self.solver.solve(b)

    def link_forces(self, X, T) -> np.ndarray:
        """C^T T: the force the links exert on each mass, sum_l T_l E_l (delta_k,k1 - delta_k,k2) of (9)."""
        f = T[:, None] * self.unit_vectors(X)
        K = self.scene.K
        out = np.empty((K, 3))
        for d in range(3):  # three bincounts, not a loop over links
            out[:, d] = np.bincount(self._k1, f[:, d], K) - np.bincount(self._k2, f[:, d], K)
        return out

    def constraint_rows(self, X, V) -> np.ndarray:
        """(C V)_l = E_l . (V_k1 - V_k2) for a field V on the masses."""
        E = self.unit_vectors(X)
        return np.einsum("ij,ij->i", E, V[self._k1] - V[self._k2])

    # ---- the physics ----------------------------------------------------------------------------
    def tensions(self, X, U, F_input=None, F=None) -> np.ndarray:
        """Tensions T solving (25) with right-hand side (26); minimum-norm where A is singular."""
        if F is None:
            F = self.forces(X, U, F_input)
        B = rhs(self.scene, X, U, F)
        return self.solve(X, B)

    def accelerations(self, X, U, F_input=None):
        """(dU/dt of (9), T): accelerations of every mass (zero on anchored ones) and the tensions."""
        self.rhs_evaluations += 1
        F = self.forces(X, U, F_input)
        T = self.tensions(X, U, F=F)
        acc = (F + self.link_forces(X, T)) * self._inv_mass3
        if not np.all(np.isfinite(acc)):
            raise SolverError("non-finite accelerations: the state or the forces contain NaN or infinity")
        return acc, T

    # ---- manifolds (11) and (12) ----------------------------------------------------------------
    def position_residual(self, X) -> np.ndarray:
        """phi_l = (|X_k2 - X_k1|^2 - R_l^2) / (2 R_l): zero on the manifold (11)."""
        d = X[self._k2] - X[self._k1]
        return (np.einsum("ij,ij->i", d, d) - self.scene.length ** 2) / (2 * self.scene.length)

    def constraint_residual(self, X) -> float:
        """max_l | |X_k2 - X_k1| - R_l | / R_l (relative violation of (11))."""
        if self.scene.L == 0:
            return 0.0
        d = X[self._k2] - X[self._k1]
        return float(np.max(np.abs(np.sqrt(np.einsum("ij,ij->i", d, d)) / self.scene.length - 1.0)))

    def velocity_residual(self, X, U) -> float:
        """max_l |E_l . (U_k2 - U_k1)|, the violation of (12) in m/s."""
        if self.scene.L == 0:
            return 0.0
        return float(np.max(np.abs(self.constraint_rows(X, U))))

    def project_positions(self, X, tol=1e-14, max_iter=50, direction_at=None):
        """Point of the manifold (11) reached from X along M^-1 C(X0)^T mu (X0 = ``direction_at``, default X).

        With X0 = X this is the mass-metric projection; RATTLE passes the start of its step as X0.
        Simplified Newton first (the matrix A(X0), already factored, reused every iteration); if it
        contracts too slowly (large steps, near-singular configurations) exact Newton with the
        unsymmetric C(X) M^-1 C(X0)^T takes over. Returns (X_projected, iterations).
        """
        if self.scene.L == 0:
            return np.array(X, float, copy=True), 0
        X0 = X if direction_at is None else direction_at
        self.factor(X0)
        E0 = self.unit_vectors(X0)
        Xc = np.array(X, float, copy=True)
        scale = self._residual_scale(Xc, tol)
        previous = np.inf
        for it in range(1, max_iter + 1):
            phi = self.position_residual(Xc)
            err = float(np.max(np.abs(phi) / scale)) * tol
            if err <= tol:
                return Xc, it - 1
            if not np.isfinite(err) or (it > 3 and err > 0.3 * previous):
                break  # slow or no contraction: exact Newton below
            previous = err
            Xc += self._correction(E0, self.solver.solve(phi))
        else:
            it = max_iter
        if direction_at is None:
            return self._project_gauss_newton(X, tol, max_iter, it)
        return self._project_exact_newton(X, X0, E0, tol, max_iter, it)

    def _project_gauss_newton(self, X, tol, max_iter, used):
        """Projection with the directions updated every iteration (large initial violations)."""
        Xc = np.array(X, float, copy=True)
        scale = self._residual_scale(Xc, tol)
        err = np.inf
        for it in range(1, max_iter + 1):
            phi = self.position_residual(Xc)
            err = float(np.max(np.abs(phi) / scale)) * tol
            if err <= tol:
                return Xc, used + it - 1
            if not np.isfinite(err):
                break
            self.factor(Xc)
            Xc += self._correction(self.unit_vectors(Xc), self.solver.solve(phi))
        self._raise_not_converged(X, err, used + max_iter)

    def _residual_scale(self, X, tol):
        """Per-link |phi| that counts as converged: tol relative to R_l, but never below the round-off
        floor of computing |X_k2 - X_k1| from coordinates of size |X| (short links far from the origin)."""
        R = self.scene.length
        size = np.abs(X[self._k1]).max(axis=1) + np.abs(X[self._k2]).max(axis=1)
        return R * tol + 8 * np.finfo(float).eps * size

    def _project_exact_newton(self, X, X0, E0, tol, max_iter, used):
        from scipy.sparse.linalg import splu

        R = self.scene.length
        Xc = np.array(X, float, copy=True)
        scale = self._residual_scale(Xc, tol)
        err = np.inf
        for it in range(1, max_iter + 1):
            phi = self.position_residual(Xc)
            err = float(np.max(np.abs(phi) / scale)) * tol
            if err <= tol:
                self.exact_newton_projections += 1
                return Xc, used + it - 1
            if not np.isfinite(err):
                break
            J = self.solver.assembly.matrix(self.unit_vectors(Xc), E0)
            try:
                if self.structure.kind == "redundant":
                    raise RuntimeError("singular by construction")
                mu = splu(J.tocsc()).solve(phi)
            except RuntimeError:  # singular Newton matrix: minimum-norm Gauss-Newton step
                mu = np.linalg.lstsq(J.toarray(), phi, rcond=1e-12)[0]
            Xc += self._correction(E0, mu)
        self._raise_not_converged(X, err, used + max_iter)

    def _raise_not_converged(self, X, err, iterations):
        R = self.scene.length
        phi = self.position_residual(X)
        worst = int(np.argmax(np.abs(phi) / R))
        raise SolverError(
            f"position projection onto the link lengths (11) did not converge: after {iterations} iterations "
            f"the residual is {err:.3g} relative; {self.scene.link_label(worst)} was worst before projection "
            f"({abs(phi[worst]) / R[worst]:.3g} relative). Reduce the step (or tighten the tolerance); if the "
            "configuration is singular (a taut string, a loop passing a flat position), no step may be small enough")

    def _correction(self, E, mu) -> np.ndarray:
        """M^-1 C^T mu with C taken from unit vectors E."""
        f = mu[:, None] * E
        K = self.scene.K
        out = np.empty((K, 3))
        for d in range(3):
            out[:, d] = np.bincount(self._k1, f[:, d], K) - np.bincount(self._k2, f[:, d], K)
        return out * self._inv_mass3

    def project_velocities(self, X, U):
        """Closest velocities satisfying (12) in the mass metric: U - M^-1 C^T mu with A mu = C U."""
        if self.scene.L == 0:
            return np.array(U, float, copy=True)
        self.factor(X)
        mu = self.solver.solve(self.constraint_rows(X, U))
        return U - self._correction(self.unit_vectors(X), mu)

    # ---- hypothesis (35) ------------------------------------------------------------------------
    def check_consistent_velocities(self, X, U, rtol=1e-8) -> None:
        """Refuse (X, U) that admit no accelerations consistent with the constraints (35).

        Consistent accelerations exist iff b_l = |U_k2 - U_k1|^2 / R_l lies in the range of C, i.e. is
        orthogonal to every self-stress (the proof (34)-(36) read backwards). Only scenes with
        self-stresses can fail.
        """
        if self.structure.self_stresses == 0 or self.scene.L == 0:
            return
        if not self.structure.rank_exact:
            return  # large redundant scenes: the MINRES residual reports inconsistency during the run
        _, N = rank_and_nullspace(self.scene, X)
        if N.shape[1] == 0:
            return
        dU = U[self._k2] - U[self._k1]
        b = np.einsum("ij,ij->i", dU, dU) / self.scene.length
        scale = np.linalg.norm(b)
        proj = N.T @ b
        if scale > 0 and np.max(np.abs(proj)) > rtol * scale:
            i = int(np.argmax(np.abs(proj)))
            stress = N[:, i]
            links = np.flatnonzero(np.abs(stress) > 1e-6 * np.abs(stress).max())
            named = ", ".join(self.scene.link_label(int(l)) for l in links[:12])
            more = "" if links.size <= 12 else f" and {links.size - 12} more"
            raise ConsistencyError(
                "the initial velocities admit no accelerations consistent with the links (hypothesis (35) of "
                f"the seed): the state of self-stress over {named}{more} is not orthogonal to |dU|^2/R "
                f"(|projection| = {abs(proj[i]):.3g} vs |b| = {scale:.3g}). Velocities that satisfy (12) can "
                "still do this, e.g. a taut string whose middle mass moves sideways; change the velocities "
                "or remove the redundant link(s).")

    # ---- diagnostics ----------------------------------------------------------------------------
    def energy(self, X, U) -> float:
        return kinetic_energy(self.scene, U) + potential_energy(self.scene, X)
