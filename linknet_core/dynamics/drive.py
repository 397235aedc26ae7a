"""Driven anchors in the numpy reference: where each one is, how fast it moves and how it accelerates at time t.

A driven anchor a has 1/M = 0 and a prescribed motion P_a(t). Its rows of X and U hold P_a and V_a, so that for a
link l between a free mass k and a, with (8) E_l = (X_k2 - X_k1)/R_l:

* (11) |X_k - P_a(t)| = R_l: RATTLE's position stage targets P_a(t + h) (the anchor's row of the new X);
* (12), its time derivative, E_l . (U_k2 - U_k1) = 0 holds with the relative velocity U_k - V_a;
* differentiating (12) once more, (13) reads E_l . (dU_k2/dt - dU_k1/dt) = -|U_k2 - U_k1|^2 / R_l with
  dU_a/dt = A_a(t) on the anchor's side: so B_l of (26) is |U_k2 - U_k1|^2 / R_l + E_l . (a_k2 - a_k1) with
  a_k = F_k / M_k on a free mass and a_a = A_a on a driven anchor, while A of (25) is unchanged (1/M_a = 0).

A velocity that jumps (an input V that changes between communication steps) is an impulse in a rigid network:
the velocities are projected onto (12) in the mass metric, U -= M^-1 C^T mu, and the links give the anchor the
impulse -(C^T mu)_a, which is reported. The native core does the same in linknet_core/native/src/drive.c.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from linknet_core.errors import SolverError
from linknet_core.scene.description import Scene
from linknet_core.scene.motion import sharpest_waypoint, step_cannot_follow


class AnchorDrive:
    """The motions of a scene's driven anchors during a simulation: the scene's own motions (velocity, sine,
    waypoints) in scene time t - t0, and for input-driven anchors the input held over an advance, either the
    quadratic P + V (t - t_hold) + A (t - t_hold)^2 / 2 or a callable of t."""

    def __init__(self, scene: Scene, t0: float = 0.0):
        self.scene = scene
        self.t0 = float(t0)
        self.rows = scene.driven_indices
        self.n = int(self.rows.size)
        is_input = np.array([m.kind == "input" for m in scene.motions], bool)
        self.input_slots = np.flatnonzero(is_input)  # positions among the driven anchors
        self.input_labels = [scene.mass_label(int(k)) for k in scene.input_driven_indices]
        self.hold_t = self.t0
        P0 = np.asarray(scene.X0, float)[scene.input_driven_indices]
        self.hold = (P0.copy(), np.zeros_like(P0), np.zeros_like(P0))
        self.callable: Callable | None = None
        self.last_jump = [np.zeros((self.n, 3)), 0.0, 0.0]  # impulse (n_driven, 3), position and velocity jump
        # (n_driven, 3) what the links gave each driven anchor in impulses over the last advance: the jump's at its
        # start, and the impacts' of the rope and ground events in it (events.EventHandling._apply_event)
        self.advance_impulse = np.zeros((self.n, 3))
        self.jumps = 0

    def set_input(self, t: float, anchors) -> None:
        """Hold ``anchors`` from time t on: (P, V, A), each (n_input, 3), or a callable f(t) -> (P, V, A)."""
        if callable(anchors):
            self.callable = anchors
            return
        self.callable = None
        self.hold_t = float(t)
        self.hold = tuple(np.array(a, float) for a in anchors)

    def internals(self):
        impulse, jump_position, jump_velocity = self.last_jump
        return (self.hold_t, tuple(a.copy() for a in self.hold), self.callable, self.jumps,
                (impulse.copy(), jump_position, jump_velocity), self.advance_impulse.copy())

    def set_internals(self, saved) -> None:
        self.hold_t, hold, self.callable, self.jumps, (impulse, jump_position, jump_velocity), advance = saved
        self.hold = tuple(a.copy() for a in hold)
        self.last_jump = [impulse.copy(), jump_position, jump_velocity]
        self.advance_impulse = advance.copy()

    def input_at(self, t: float):
        """(P, V, A) of the input-driven anchors at t, each (n_input, 3)."""
        if self.callable is not None:
            return call_motion(self.callable, t, self.input_labels)
        P, V, A = self.hold
        s = t - self.hold_t
        return P + s * V + (0.5 * s * s) * A, V + s * A, A

    def at(self, t: float):
        """(P, V, A) of every driven anchor at t, each (n_driven, 3)."""
        P, V, A = self.scene.anchor_motion(t - self.t0)
        if self.input_slots.size:
            P[self.input_slots], V[self.input_slots], A[self.input_slots] = self.input_at(t)
        return P, V, A

    def apply(self, t: float, X: np.ndarray, U: np.ndarray):
        """(X, U, anchor_acc): copies of X and U whose driven rows hold P(t) and V(t), and the (K,3) accelerations
        of the driven anchors (zero elsewhere) that B of (26) takes."""
        P, V, A = self.at(t)
        X, U = X.copy(), U.copy()
        X[self.rows], U[self.rows] = P, V
        acc = np.zeros_like(X)
        acc[self.rows] = A
        return X, U, acc

    def place(self, t: float, X: np.ndarray) -> np.ndarray:
        """A copy of X with the driven anchors at P(t): the target of RATTLE's position stage."""
        X = X.copy()
        X[self.rows] = self.at(t)[0]
        return X

    def move_velocities(self, t: float, U: np.ndarray) -> np.ndarray:
        """A copy of U with the driven anchors' velocities V(t): the target of RATTLE's velocity stage."""
        U = U.copy()
        U[self.rows] = self.at(t)[1]
        return U


def call_motion(function, t: float, labels) -> tuple:
    """A user's motion callable at t, checked: three arrays (P, V, A) of shape (n, 3), finite, one row per
    input-driven anchor (``labels`` names them). Whatever goes wrong is a SolverError that says what."""
    n = len(labels)
    try:
        result = function(t)
    except SolverError:
        raise
    except Exception as exc:  # noqa: BLE001 - the user's code: any failure is reported, named, as a solver error
        raise SolverError(f"the anchors' motion callable failed at t = {t}: {type(exc).__name__}: {exc}") from exc
    try:
        P, V, A = (np.asarray(a, float) for a in result)
    except (TypeError, ValueError) as exc:
        raise SolverError(f"the anchors' motion callable must return (P, V, A), three arrays of shape ({n}, 3), at "
                          f"t = {t}; it returned {type(result).__name__} ({exc})") from None
    for name, unit, a in (("P", "m", P), ("V", "m/s", V), ("A", "m/s2", A)):
        if a.shape != (n, 3):
            raise SolverError(f"the anchors' motion callable returned {name} of shape {a.shape} at t = {t}; "
                              f"expected ({n}, 3): one row per input-driven anchor ({', '.join(labels)})")
        if not np.all(np.isfinite(a)):
            i, j = np.argwhere(~np.isfinite(a))[0]
            raise SolverError(f"the anchors' motion callable returned {name} = {a[i, j]} {unit} on axis {j + 1} of "
                              f"{labels[i]} at t = {t}: it must be finite")
    return P, V, A


def driven_rows_at(drive: AnchorDrive, t: float, X: np.ndarray, U: np.ndarray):
    """(X, U with the driven rows at the motion at t, position jump (m), velocity jump (m/s)): copies where the rows
    jump, X and U themselves where they do not (both jumps 0)."""
    P, V, _ = drive.at(t)
    rows = drive.rows
    dP = float(np.abs(P - X[rows]).max()) if rows.size else 0.0
    dV = float(np.abs(V - U[rows]).max()) if rows.size else 0.0
    if dP == 0.0 and dV == 0.0:
        return X, U, 0.0, 0.0
    X, U = X.copy(), U.copy()
    X[rows], U[rows] = P, V
    return X, U, dP, dV


def anchor_jump(dyn, drive: AnchorDrive, t: float, X: np.ndarray, U: np.ndarray):
    """Bring the state's driven rows to the motion at t. Where they jump, positions are projected onto (11) and
    velocities onto (12) in the mass metric (an inelastic impulse). Returns (X, U, impulse (n_driven, 3): what the
    links gave each driven anchor, position jump (m), velocity jump (m/s))."""
    rows = drive.rows
    impulse = np.zeros((rows.size, 3))
    X, U, dP, dV = driven_rows_at(drive, t, X, U)
    if dP == 0.0 and dV == 0.0:
        return X, U, impulse, 0.0, 0.0
    if dP > 0.0:
        X, _ = dyn.project_positions(X, tol=1e-14)
    if dyn.scene.L:
        E = dyn.unit_vectors(X)
        dyn.factor(X, E)
        mu = dyn.solver.solve(dyn.constraint_rows(X, U, E))
        CT_mu = dyn._scatter(E, mu)
        U = U - CT_mu * dyn._inv_mass3
        impulse = -CT_mu[rows]
    return X, U, impulse, dP, dV


def check_step_follows_motions(scene: Scene, dt: float) -> None:
    """Refuse a fixed step dt that cannot follow a driven anchor's prescribed motion (scene.motion.step_cannot_follow),
    naming the anchor, rather than run a motion the steps alias or jump over."""
    for k, motion in zip(scene.driven_indices, scene.motions):
        problem = step_cannot_follow(motion, dt)
        if problem:
            raise SolverError(f"{scene.name}: {scene.mass_label(int(k))} is driven, and {problem}; or leave the "
                              "method and step out for the error-controlled default, whose steps follow the motion")


def motion_note(scene: Scene, tau0: float, tau1: float) -> str:
    """What to add to a step-size failure between scene times tau0 and tau1: the driven anchors' waypoint splines
    there, if any, with their prescribed accelerations (a waypoint a short time away needs an enormous one)."""
    notes = [f"{scene.mass_label(int(k))} is driven: {note}" for k, motion in zip(scene.driven_indices, scene.motions)
             if (note := sharpest_waypoint(motion, tau0, tau1))]
    return f" ({'; '.join(notes)})" if notes else ""
