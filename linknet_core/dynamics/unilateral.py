"""Ropes that go slack and a ground the masses land on: unilateral constraints, with the seed's links as equalities.

A rope l keeps its ends within its length: the gap g_l = R_l - |X_k2 - X_k1| >= 0, and its tension T_l >= 0 (it pulls,
never pushes). A ground (a plane through p with unit normal n) keeps every free mass on its side: g_k = n . (X_k - p)
>= 0, with a normal force lambda_k >= 0. While such a constraint is *active* it is a link of the seed: a taut rope is
exactly a rod in (9), (11)-(13) and (25)-(26); a contact is a link from the mass to a virtual anchor straight above
it (see ``ModeDynamics``). Which ones are active is the *mode*; between events the integrators follow one mode as
a network of rods, with every tool of the rod path (the tension solvers, the minimum-norm tensions (31) where the
active set is redundant, the projections onto (11)-(12)).

Which unilateral constraints carry force is a complementarity problem (Moreau 1966, Lotstedt 1982; Pfeiffer and
Glocker, Multibody Dynamics with Unilateral Contacts, 1996, ch. 5-7). With C the constraint Jacobian (a rope's row
is the seed's +E_l at k1, -E_l at k2, so C U = dg/dt), W = C M^-1 C^T (A of (25)) and B of (26), the accelerations
give d2g/dt2 = W lambda - B. At a state where some unilateral constraints touch (g = 0) with dg/dt = 0:

    rods:               (W lambda - B)_i = 0                                   (25)-(26), equalities
    touching ropes,
    contacts:           lambda_i >= 0,  w_i = (W lambda - B)_i >= 0,  lambda_i w_i = 0

a mixed linear complementarity problem (LCP) on the unilateral subset (Cottle, Pang and Stone, The Linear
Complementarity Problem, 1992, sec. 1.2 and 4.2). ``solve_mixed_lcp`` solves it exactly by principal pivoting
(Murty's least-index rule, 1974, "Note on a Bard-type scheme for solving the complementarity problem": finite for
a P-matrix from any start; linknet_core.dynamics.complementarity), each basis being the rods' equations (25) with
the chosen unilateral rows as equalities; it starts from every touching constraint taut (the last mode's taut ones
among them), so that a degenerate row (force and gap acceleration both zero) stays taut; a problem that still
cycles has its active sets enumerated.

Impacts: when a slack rope reaches its length or a mass the ground, the velocities jump. The impulse Lambda solves
the same LCP one level down (Moreau's impact law with Newton's restitution on the normal, for a rope the radial,
velocity): Lambda_i >= 0, xi_i = dg/dt_i+ + e_i min(dg/dt_i-, 0) >= 0, Lambda_i xi_i = 0, with M dU = C^T Lambda.
Perfectly inelastic (e = 0) it is the projection of the velocities onto the active set in the mass metric, the very
projection of the driven anchors' jumps (Dynamics.project_velocities); with a common e it is U- + (1 + e) (P U- -
U-): the approach velocity reversed e times.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from linknet_core.dynamics.complementarity import basis_solution, solve_mixed_lcp
from linknet_core.dynamics.roots import bracketed_root
from linknet_core.dynamics.equations import Dynamics
from linknet_core.errors import ConsistencyError, SceneError, SolverError
from linknet_core.scene.description import Scene
from linknet_core.state import InitialReport

# A unilateral constraint touches (it may carry force, and an acceleration LCP takes it) when its gap is at most
# TOUCH_TOL of its length scale (a rope's length; the contact scale for the ground) and it does not separate faster
# than TOUCH_TOL of the scene's velocity scale: far above the round-off of states the projections put on (11)-(12)
# (~1e-15), far below any gap a step opens.
TOUCH_TOL = 1e-9
# A slack constraint is crossed (an event) when its gap is below -CROSS_TOL of its scale: above the round-off of
# computing the gap, so that a rope that has just gone slack (gap 0, rate 0) is not found taut again at round-off.
CROSS_TOL = 1e-12
# An active constraint goes slack (an event) when its force falls below -FORCE_TOL of the largest force the
# mode's links carry at that state (round-off of the tension solve is ~1e-15 of it).
FORCE_TOL = 1e-10
# An impact whose rebound would lift the constraint by less than REST_HEIGHT of its scale under the scene's
# acceleration scale is perfectly inelastic: a ball bouncing with e < 1 comes to rest after finitely many events
# instead of infinitely many in finite time.
REST_HEIGHT = 1e-9
# An impact's impulse on a unilateral constraint is no impulse when it would change that constraint's own rate by
# less than IMPULSE_ROUNDOFF of the velocity scale (Lambda_u W_uu, W_uu = C_u M^-1 C_u^T its diagonal of W: a rope's
# |E|^2 (1/M_k1 + 1/M_k2), a contact's 1/M_k): a few ulps of the rates the impact's LCP is solved from, whose round-off
# alone gives a constraint the impact leaves as it was (a rope taut already under a jump of the driven anchors) an
# impulse of ~1e-17 N s, either sign as the rounding falls; no velocity the state can show changes by that.
IMPULSE_ROUNDOFF = 8 * float(np.finfo(float).eps)


class Event(NamedTuple):
    """What happened at a time t of a run: ``kind`` 'taut' (a slack rope reached its length: an impulse), 'slack'
    (a taut rope's tension fell to 0: it leaves, no impulse), 'contact' (a mass reached the ground: an impulse) or
    'release' (the ground's force on a mass fell to 0), 'stick' (a mass sliding on the ground stopped and friction
    holds it) or 'slip' (the force holding a stuck mass reached mu times the normal force: it slides); ``index`` the
    0-based link (taut, slack) or mass (contact, release, stick, slip); ``impulse`` N s: what the rope or the ground
    gave (>= 0; the normal impulse of a contact; the tangential one that stopped a stick; 0 for slack, release and
    slip)."""

    t: float
    kind: str
    index: int
    impulse: float


def scene_size(scene: Scene) -> float:
    """The scene's length scale, m: its extent or longest link, at least 1 m (a single mass on the ground has
    none). What the events' tolerances and the rest speed are measured against (the native core takes it too)."""
    extent = float(np.ptp(scene.X0, axis=0).max()) if scene.K > 1 else 0.0
    return max(extent, float(scene.length.max()) if scene.L else 0.0, 1.0)


def linearization_refusal(scene: Scene) -> str:
    """Why the outputs' linearization (Simulator.interface_linearization, the FMUs' directional derivatives) is not
    given for ``scene``; "" where it is given. It is given for rods (the seed's (25)-(26)), ropes and a frictionless
    ground: with ropes or a ground, the derivatives of the current mode's outputs (interface_jacobian.ModeLinearization:
    the slack ropes and the masses off the ground left out, each contact a link to its virtual anchor, the mode held,
    one-sided where an input would change it). It is refused with a rough ground: the sliding contacts' load -mu N d
    enters the mode's system as non-symmetric columns (ModeDynamics.normal_system) that the linearization's solves
    with the factorisation of A do not carry, and a stuck contact leaves its mode at the friction cone's edge. The
    FMUs declare providesDirectionalDerivative(s) from this: "true" only where it is ""."""
    if scene.ground is None or scene.ground.friction == 0:
        return ""
    return (f"{scene.name}: it has a rough ground (Coulomb friction, mu = {scene.ground.friction:g}), and the "
            "outputs' linearization (interface_linearization, directional derivatives) is given for rods, ropes and "
            "a frictionless ground only (within the current mode); it is not given with friction, which turns with "
            "the slip and switches between stick and slip")


def describe(scene: Scene) -> list[str]:
    """What ``linknet analyze`` says of a scene's ropes and ground: how many ropes and which are slack at the start
    (shorter than their length, or not pulled: the acceleration LCP there), the ground's plane, restitution and
    friction and the masses on it at the start, and the path that runs them."""
    dyn = UnilateralDynamics(scene)
    X, U = np.array(scene.X0), np.array(scene.U0)
    lines = []
    try:
        T, normal = dyn.resolve(X, U)
        slack = [scene.link_label(int(l)) for l in dyn.rope_links if T[l] == 0.0]
    except Exception as exc:  # an inconsistent initial state: said, not raised (analyze describes any scene)
        slack, normal = None, None
        lines.append(f"ropes and ground: the initial state's forces cannot be computed ({exc})")
    if dyn.rope_links.size:
        lines.append(f"ropes: {dyn.rope_links.size} of {scene.L} links are ropes (pull only; restitution "
                     f"{', '.join(f'{e:g}' for e in np.unique(scene.restitution[dyn.rope_links]))})")
        if slack is not None:
            shown = ", ".join(slack[:8]) + (f" and {len(slack) - 8} more" if len(slack) > 8 else "")
            lines.append(f"slack at the start: {len(slack)}" + (f" ({shown})" if slack else ""))
    ground = scene.ground
    if ground is not None:
        lines.append(f"ground: the plane through {np.round(ground.point, 6).tolist()} with normal "
                     f"{np.round(ground.normal, 6).tolist()}, restitution {ground.restitution:g}, friction "
                     f"{ground.friction:g}" + (" (frictionless)" if ground.friction == 0 else " (Coulomb)"))
        if normal is not None:
            on = [scene.mass_label(int(k)) for k in dyn.contact_masses[dyn.touching(X)[dyn.rope_links.size:]]]
            shown = ", ".join(on[:8]) + (f" and {len(on) - 8} more" if len(on) > 8 else "")
            lines.append(f"masses on the ground at the start: {len(on)}" + (f" ({shown})" if on else ""))
    friction = ("; stages/friction.c, Coulomb friction: a stuck contact's grips, a sliding one's friction"
                if ground is not None and ground.friction > 0 else "")
    lines.append("path: the native core, event by event, on every method (linknet_core/native/src/stages/ropes.c"
                 + (f", each contact a unilateral link to a virtual anchor{friction}" if ground is not None else "")
                 + "; the numpy reference with backend=\"numpy\")")
    return lines


def scene_dynamics(scene: Scene, rhs_kernel: str = "numpy") -> Dynamics:
    """The Dynamics a simulation of ``scene`` runs on: UnilateralDynamics for a scene with ropes or a ground."""
    if not scene.unilateral:
        return Dynamics(scene, rhs_kernel=rhs_kernel)
    if rhs_kernel != "numpy":
        raise SolverError(f"rhs_kernel={rhs_kernel!r} does not take ropes or a ground (its generated kernel is of rods "
                          "only); use rhs_kernel='numpy'")
    return UnilateralDynamics(scene)


def slack_links(scene: Scene, T: np.ndarray) -> np.ndarray:
    """(L,) bool: the ropes that carry no tension at a state whose tensions (from UnilateralDynamics.tensions) are
    T: those the complementarity problem leaves out (their T is exactly 0). Rods are never slack."""
    return scene.rope & (np.asarray(T) == 0.0)


# ------------------------------------------------------------------------------------------- one mode's dynamics
@dataclass(frozen=True)
class _ModeScene(Scene):
    """The scene of one mode: the rods and the active ropes as links, and each active contact as a link from its
    mass to a virtual anchor appended after the scene's masses. ``labels`` names each link in the scene's words."""

    labels: tuple = ()

    def link_label(self, l: int) -> str:
        return self.labels[l]


class ModeDynamics:
    """One mode (which ropes are taut, which masses touch the ground) as a network of rods: what the integrators
    take as their ``dyn`` between events.

    A contact of mass k is a link of length R_c from k to a virtual anchor Q placed straight above it, Q = X_k +
    (R_c - g_k) n, whose velocity is the mass's tangential velocity: its direction E is then n (the plane's normal),
    its row of C is n at k, the term |U_k - V_Q|^2 / R_c of (26) is (n . U_k)^2 / R_c, zero on the ground, and its gap
    R_c - |X_k - Q| is g_k: the plane's constraint exactly at the velocity and acceleration levels, and its tension
    the ground's normal force. Every call re-places Q from the state it is given. The position projection moves the
    masses onto |X_k - Q| = R_c, a sphere that touches the plane under Q; a mass that the links move sideways by tau
    within one projection ends tau^2 / (2 R_c) off the plane, so the projection is repeated with Q re-placed until the
    gaps are within the tolerance (twice at most, in practice)."""

    def __init__(self, parent: "UnilateralDynamics", active: np.ndarray, X: np.ndarray, U: np.ndarray,
                 stuck: np.ndarray | None = None):
        scene = parent.scene
        self.parent = parent
        self.scene = scene
        self.active = np.array(active, bool)
        self.K = scene.K
        self._inv_mass3 = parent._inv_mass3
        n_ropes = parent.rope_links.size
        self.links = np.concatenate([parent.rod_links, parent.rope_links[self.active[:n_ropes]]])
        on_ground = self.active[n_ropes:]
        self.contact_masses = parent.contact_masses[on_ground]
        # Coulomb friction: the contacts (numbered as parent.contact_masses) that stick, held in place along the
        # plane by two links each to virtual anchors at rest, and those that slide, loaded by -mu N d
        stuck = np.zeros(on_ground.size, bool) if stuck is None else np.asarray(stuck, bool) & on_ground
        self.stuck = stuck
        self.stuck_masses = parent.contact_masses[stuck]
        self.sliding = np.flatnonzero(on_ground & ~stuck) if parent.friction > 0 else np.zeros(0, np.int64)
        self.n_virtual = self.contact_masses.size + 2 * self.stuck_masses.size
        # the aug row of every unilateral constraint (-1 where inactive), and the constraint of every aug row (the
        # stuck contacts' tangential rows, last, are equalities: -1)
        self.row_of = np.full(parent.n_unilateral, -1, np.int64)
        on = np.flatnonzero(self.active)
        self.row_of[on] = parent.rod_links.size + np.arange(on.size)
        self.constraint_of_row = np.concatenate([np.full(parent.rod_links.size, -1, np.int64), on,
                                                 np.full(2 * self.stuck_masses.size, -1, np.int64)])
        self.grip_rows = parent.rod_links.size + on.size + np.arange(2 * self.stuck_masses.size).reshape(-1, 2)
        self.sliding_rows = self.row_of[n_ropes + self.sliding]
        self.inner = Dynamics(self._mode_scene(X, U))

    def _mode_scene(self, X, U) -> _ModeScene:
        """The scene with the mode's links (the rods, the active ropes, a link per contact) and a virtual anchor per
        contact appended to the masses. Every per-mass field of Scene is padded as the anchors need it (an anchor:
        infinite mass, fixed, not driven, at its place above its mass) or with zeros (no force, no drag: whatever
        per-mass field Scene has); the per-link fields are taken at the mode's links (named here: a new per-link
        field of Scene is added to them); the ropes' fields are left to their defaults (a mode's links are rods)."""
        scene, parent = self.scene, self.parent
        n_c = self.n_virtual
        K = self.K
        gripped = np.repeat(self.stuck_masses, 2)
        own = {"mass": np.concatenate([scene.mass, np.full(n_c, math.inf)]),
               "fixed": np.concatenate([scene.fixed, np.ones(n_c, bool)]),
               "driven": np.concatenate([scene.driven, np.zeros(n_c, bool)]),
               "X0": self.pad(X), "U0": self.pad_velocity(X, U),
               "mass_names": scene.mass_names + tuple(f"ground above {scene.mass_names[k]}"
                                                      for k in self.contact_masses) + tuple(
                   f"ground grip {i % 2 + 1} of {scene.mass_names[k]}" for i, k in enumerate(gripped)),
               "k1": np.concatenate([scene.k1[self.links], self.contact_masses, gripped]),
               "k2": np.concatenate([scene.k2[self.links], K + np.arange(n_c)]),
               "length": np.concatenate([scene.length[self.links], np.full(n_c, parent.contact_length)]),
               "link_names": tuple(scene.link_names[l] for l in self.links) + tuple(
                   f"ground{k + 1}" for k in self.contact_masses) + tuple(
                   f"grip{i % 2 + 1}_{k + 1}" for i, k in enumerate(gripped)),
               "rope": None, "restitution": None, "ground": None, "gravity": scene.gravity}
        fields = _padded_fields(scene, n_c, own)
        labels = tuple(scene.link_label(int(l)) for l in self.links) + tuple(
            f"the ground contact of {scene.mass_label(int(k))}" for k in self.contact_masses) + tuple(
            f"the ground's friction grip on {scene.mass_label(int(k))}" for k in gripped)
        return _ModeScene(labels=labels, **fields)

    # ---- the virtual anchors of the contacts --------------------------------------------------------------
    def _pad_zero(self, A):
        if self.n_virtual == 0 or A is None:
            return A
        return np.concatenate([A, np.zeros((self.n_virtual, 3))])

    def pad(self, X, grips_at=None):
        """X with each contact's virtual anchor straight above its mass, at R_c from the plane, and each stuck
        contact's two grip anchors beside it along the plane's tangents t_1, t_2, at R_c (beside its place in
        ``grips_at`` where given: a position projection then holds the mass where the step began)."""
        if self.n_virtual == 0:
            return X
        ground = self.scene.ground
        Xc = X[self.contact_masses]
        gap = ground.gaps(Xc)
        R = self.parent.contact_length
        held = X if grips_at is None else grips_at
        grips = (held[self.stuck_masses][:, None, :] + R * self.parent.tangents[None, :, :]).reshape(-1, 3)
        return np.concatenate([X, Xc + (R - gap)[:, None] * ground.normal, grips])

    def pad_velocity(self, X, V):
        """A velocity field V (or any field on the masses) at positions X with each virtual anchor above a mass
        moving as its mass does along the plane: its row of C (12) is then n . V_k (the plane's normal is the same
        everywhere, so X does not enter); the grip anchors are at rest, so their rows are t_i . V_k."""
        if self.n_virtual == 0:
            return V
        n = self.scene.ground.normal
        Vc = V[self.contact_masses]
        return np.concatenate([V, Vc - (Vc @ n)[:, None] * n, np.zeros((2 * self.stuck_masses.size, 3))])

    def _unpad(self, A):
        return A if self.n_virtual == 0 else A[:self.K]

    # ---- what the integrators call ------------------------------------------------------------------------
    @property
    def exact_newton_projections(self) -> int:
        return self.inner.exact_newton_projections

    @property
    def floor_stops(self) -> int:
        return self.parent.floor_stops

    @property
    def floor_reached(self) -> float:
        return self.parent.floor_reached

    @property
    def rhs_kernel(self) -> str:
        return "numpy"

    @property
    def sliding_friction(self) -> bool:
        """Whether a contact slides in this mode: its friction -mu N d in ``forces`` then depends on the velocities
        (d along its tangential velocity), and RATTLE's second half kick is implicit in them, as for drag."""
        return bool(self.sliding.size)

    def forces(self, X, U, F_input=None):
        """The external forces on the masses (F_input included) and the sliding contacts' friction: what the
        integrators that take the constraint forces from projections (RATTLE) kick with."""
        F = self.parent.forces(X, U, F_input)
        if self.sliding.size:
            F = F + self.friction(X, U, F_input)
        return F

    def _with_friction(self, X, U, F_input, anchor_acc):
        """F_input with the sliding contacts' friction added (the mode's own load)."""
        if not self.sliding.size:
            return F_input
        friction = self.friction(X, U, F_input, anchor_acc)
        return friction if F_input is None else F_input + friction

    def friction(self, X, U, F_input=None, anchor_acc=None, directions=None) -> np.ndarray:
        """(K,3): Coulomb's sliding friction -mu N_c d_c on each sliding contact's mass, d_c its slip direction
        (UnilateralDynamics.slip_directions) and N_c its normal force. The friction loads the masses, so N depends
        on it: with B(F) of (26) affine in the forces, W N = B(F + sum_c -mu N_c d_c at k_c) is the linear system
        (W - D) N = B(F), D's column c being B's response to the unit load -mu d_c at k_c (B at zero velocity, where
        (26) is linear in the load). It is not symmetric; it is solved directly (least squares, minimum-norm where
        the mode is redundant, as (31)). For a mass alone on the ground D = 0 (its friction is tangential, its
        normal row sees only its own normal load)."""
        return self.friction_and_tensions(X, U, F_input, anchor_acc, directions)[0]

    def friction_and_tensions(self, X, U, F_input=None, anchor_acc=None, directions=None):
        """(the friction of ``friction`` (K,3), the mode's tensions in its row order that go with it: the solution
        of (W - D) T = B(F))."""
        W, B, directions = self.normal_system(X, U, F_input, anchor_acc, directions)
        T = np.linalg.lstsq(W, B, rcond=None)[0]
        out = np.zeros((self.K, 3))
        np.add.at(out, self.parent.contact_masses[self.sliding],
                  -self.parent.friction * T[self.sliding_rows][:, None] * directions)
        return out, T

    def normal_system(self, X, U, F_input=None, anchor_acc=None, directions=None):
        """(W - D, B(F), slip directions (n_sliding, 3)): the mode's (25)-(26) with the sliding contacts' friction
        carried into the matrix (``friction``); W and B of (25)-(26) where nothing slides."""
        parent, inner = self.parent, self.inner
        Xa, Ua = self.pad(X), self.pad_velocity(X, U)
        F = inner.forces(Xa, Ua, self._pad_zero(F_input))
        W = inner.tension_matrix(Xa).toarray()
        B = inner.tension_rhs(Xa, Ua, F, self._pad_zero(anchor_acc))
        if not self.sliding.size:
            return W, B, np.zeros((0, 3))
        if directions is None:
            directions = parent.slip_directions(X, U, self, F_input, anchor_acc)
        still = np.zeros_like(Ua)
        for row, k, d in zip(self.sliding_rows, parent.contact_masses[self.sliding], directions):
            load = np.zeros_like(F)
            load[k] = -parent.friction * d
            W[:, row] -= inner.tension_rhs(Xa, still, load)
        return W, B, directions

    def accelerations(self, X, U, F_input=None, anchor_acc=None):
        """(dU/dt of (9) on the scene's masses, the mode's tensions in its row order)."""
        self.parent.rhs_evaluations += 1
        F_input = self._with_friction(X, U, F_input, anchor_acc)
        acc, T = self.inner.accelerations(self.pad(X), self.pad_velocity(X, U), self._pad_zero(F_input),
                                          self._pad_zero(anchor_acc))
        return self._unpad(acc), T

    def tensions(self, X, U, F_input=None, anchor_acc=None) -> np.ndarray:
        """The mode's tensions (25)-(26), rods and active ropes and contacts and the stuck contacts' grips, in its
        row order (minimum-norm (31) where the mode is redundant), with the sliding contacts' friction as a load."""
        F_input = self._with_friction(X, U, F_input, anchor_acc)
        return self.inner.tensions(self.pad(X), self.pad_velocity(X, U), self._pad_zero(F_input),
                                   anchor_acc=self._pad_zero(anchor_acc))

    def grip_forces(self, T_rows) -> np.ndarray:
        """(n_stuck, 3): the tangential force the ground holds each stuck contact's mass with, T_1 t_1 + T_2 t_2 of
        its grip rows (a grip link pulls its mass towards its anchor, along +t_i)."""
        T = T_rows[self.grip_rows]
        return T @ self.parent.tangents if T.size else np.zeros((0, 3))

    def project_velocities(self, X, U):
        """The closest velocities in the mass metric with every active constraint's rate (12) zero:
        Dynamics.project_velocities of the mode."""
        return self._unpad(self.inner.project_velocities(self.pad(X), self.pad_velocity(X, U)))

    def project_positions(self, X, tol=1e-14, max_iter=50, direction_at=None, step=None):
        """Dynamics.project_positions of the mode (onto (11) of its rods and taut ropes and onto the ground of its
        contacts), repeated with the contacts' anchors re-placed until every contact's gap is within the tolerance.
        Returns (X, iterations)."""
        inner, parent = self.inner, self.parent
        X0 = None if direction_at is None else self.pad(direction_at)
        if step is not None and self.n_virtual:
            dt, fraction, U, F_input = step
            step = (dt, fraction, self.pad_velocity(direction_at, U), self._pad_zero(F_input))
        stops = inner.floor_stops
        total = 0
        Xc = X
        for _ in range(4):
            Xa, used = inner.project_positions(self.pad(Xc, direction_at), tol=tol, max_iter=max_iter, direction_at=X0, step=step)
            Xc, total = self._unpad(Xa), total + used
            if self.contact_masses.size == 0 or np.all(np.abs(self.scene.ground.gaps(Xc[self.contact_masses]))
                                                       <= tol * parent.contact_length
                                                       + 8 * np.finfo(float).eps * np.abs(Xc).max()):
                break
        parent.floor_stops += inner.floor_stops - stops
        parent.floor_reached = max(parent.floor_reached, inner.floor_reached if inner.floor_stops > stops else 0.0)
        return Xc, total

    def near_self_stress_load(self, X, U, F_input=None, anchor_acc=None) -> str:
        return self.inner.near_self_stress_load(self.pad(X), self.pad_velocity(X, U), self._pad_zero(F_input),
                                                self._pad_zero(anchor_acc))

    def link_impulse_velocities(self, X, lam_rows):
        """M^-1 C^T Lambda on the scene's masses for impulses Lambda in the mode's row order: the velocity change
        they make ((9) integrated over the impulse)."""
        Xa = self.pad(X)
        return self._unpad(self.inner.link_forces(Xa, lam_rows)) * self._inv_mass3

    def unilateral_forces(self, T_rows) -> np.ndarray:
        """(n_unilateral,): each active rope's tension and contact's normal force from the mode's tensions T_rows;
        0 on the inactive ones."""
        out = np.zeros(self.parent.n_unilateral)
        on = self.row_of >= 0
        out[on] = T_rows[self.row_of[on]]
        return out


def _padded_fields(scene: Scene, n_virtual: int, own: dict) -> dict:
    """The fields of a Scene with n_virtual masses appended: those in ``own`` as given (the masses' own fields and
    every per-link field), every other per-mass field padded with zeros (no force, no drag: whatever per-mass field
    Scene has), the rest as the scene's."""
    import dataclasses

    K = scene.K
    fields = {}
    for field in dataclasses.fields(Scene):
        value = getattr(scene, field.name)
        if field.name in own:
            value = own[field.name]
        elif isinstance(value, np.ndarray) and value.shape[:1] == (K,):  # a per-mass field (the per-link ones
            value = np.concatenate([value, np.zeros((n_virtual,) + value.shape[1:], value.dtype)])  # are in ``own``)
        elif isinstance(value, dict):
            value = dict(value)
        if isinstance(value, np.ndarray):
            value = _frozen(value, value.dtype)
        fields[field.name] = value
    return fields


@dataclass(frozen=True)
class GroundModelScene(_ModeScene):
    """What the native core runs a scene with a frictionless ground as (native_ground_scene): the scene's masses and
    links in their order, then a virtual anchor per free mass (infinite mass, fixed) and a contact link from each
    free mass to its anchor, a rope of length ``contact_length`` with the ground's restitution (the core places the
    anchor above its mass before every evaluation: ModeDynamics' contact). ``contact_masses``: the free mass of
    each contact, in order; ``size``: the scene's length scale (scene_size of the scene, not of this one);
    ``ground_plane``: the scene's ground (this scene's own ``ground`` is None: its contacts are links)."""

    contact_masses: tuple = ()
    contact_length: float = 1.0
    size: float = 1.0
    ground_plane: object = None


def native_ground_scene(scene: Scene) -> GroundModelScene:
    """The scene the native core runs for ``scene`` with its (frictionless) ground: GroundModelScene. The anchors
    start R_c above their masses (each contact as it is on the ground, what the structure analysis sees); the core
    places them from every state it evaluates."""
    ground = scene.ground
    masses = scene.free_indices
    n_c, K = masses.size, scene.K
    R = scene_size(scene)
    X0 = np.asarray(scene.X0, float)
    anchors = X0[masses] + R * ground.normal
    U0 = np.asarray(scene.U0, float)
    Vc = U0[masses]
    own = {"mass": np.concatenate([scene.mass, np.full(n_c, math.inf)]),
           "fixed": np.concatenate([scene.fixed, np.ones(n_c, bool)]),
           "driven": np.concatenate([scene.driven, np.zeros(n_c, bool)]),
           "X0": np.concatenate([X0, anchors]),
           "U0": np.concatenate([U0, Vc - (Vc @ ground.normal)[:, None] * ground.normal]),
           "mass_names": scene.mass_names + tuple(f"ground above {scene.mass_names[k]}" for k in masses),
           "k1": np.concatenate([scene.k1, masses]), "k2": np.concatenate([scene.k2, K + np.arange(n_c)]),
           "length": np.concatenate([scene.length, np.full(n_c, R)]),
           "link_names": scene.link_names + tuple(f"ground{k + 1}" for k in masses),
           "rope": np.concatenate([scene.rope, np.ones(n_c, bool)]),
           "restitution": np.concatenate([scene.restitution, np.full(n_c, float(ground.restitution))]),
           "ground": None, "gravity": scene.gravity}
    labels = tuple(scene.link_label(l) for l in range(scene.L)) + tuple(
        f"the ground contact of {scene.mass_label(int(k))}" for k in masses)
    return GroundModelScene(labels=labels, contact_masses=tuple(int(k) for k in masses), contact_length=R, size=R,
                            ground_plane=ground, **_padded_fields(scene, n_c, own))


def _tangents(normal) -> np.ndarray:
    """(2, 3): two orthonormal vectors perpendicular to the unit vector ``normal``."""
    helper = np.eye(3)[int(np.argmin(np.abs(normal)))]
    t1 = np.cross(normal, helper)
    t1 /= np.linalg.norm(t1)
    return np.array([t1, np.cross(normal, t1)])


def _frozen(a, dtype=float):
    out = np.array(a, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


# ------------------------------------------------------------------------------------- the scene's dynamics
class UnilateralDynamics(Dynamics):
    """The Dynamics of a scene with ropes or a ground: the seed's rods plus unilateral constraints, numbered
    u = 0 .. n_unilateral - 1, the ropes first (link order), then a contact per free mass (mass order) when there is
    a ground. As a Dynamics of the whole scene (every link a rod) it supplies the forces, energies and reactions;
    ``tensions`` solves the acceleration LCP at the state (a pure function of it: ropes that are slack there get T =
    0); ``mode`` gives the rods of one mode (ModeDynamics), which the event-driven integrators follow between
    events."""

    def __init__(self, scene: Scene):
        super().__init__(scene)
        self.rope_links = np.flatnonzero(scene.rope)
        self.rod_links = np.flatnonzero(~scene.rope)
        ground = scene.ground
        self.contact_masses = scene.free_indices if ground is not None else np.zeros(0, np.int64)
        self.n_unilateral = self.rope_links.size + self.contact_masses.size
        self.is_rope = np.concatenate([np.ones(self.rope_links.size, bool), np.zeros(self.contact_masses.size, bool)])
        self.index = np.concatenate([self.rope_links, self.contact_masses])  # the link or mass of each constraint
        self.size = scene_size(scene)
        # the virtual link length of a contact (any positive length is exact; this keeps its coordinates at the
        # scene's scale)
        self.contact_length = self.size
        self.scale = np.concatenate([scene.length[self.rope_links], np.full(self.contact_masses.size, self.size)])
        self.restitution = np.concatenate([scene.restitution[self.rope_links],
                                           np.full(self.contact_masses.size, ground.restitution if ground else 0.0)])
        # Coulomb's friction coefficient of the ground, and an orthonormal pair of tangents of its plane (the grips
        # of a stuck contact pull along them)
        self.friction = float(ground.friction) if ground is not None else 0.0
        self.tangents = _tangents(ground.normal) if ground is not None else np.zeros((2, 3))
        # each contact's slip direction at the start of the step being taken (zero: none): a sliding contact's
        # friction keeps it while its velocity along it has not fallen to zero (the stop is an event, 'stick')
        self.slip_reference = np.zeros((self.contact_masses.size, 3))
        self._modes: dict = {}

    # ---- the constraints' gaps and rates -----------------------------------------------------------------
    def gaps(self, X) -> np.ndarray:
        """g_u of every unilateral constraint (m): R_l - |X_k2 - X_k1| of a rope, computed as (R^2 - |d|^2) / (R + |d|)
        (no cancellation at g ~ 0); n . (X_k - p) of a contact."""
        scene = self.scene
        l = self.rope_links
        d = X[scene.k2[l]] - X[scene.k1[l]]
        dd = np.einsum("ij,ij->i", d, d)
        R = scene.length[l]
        rope = (R * R - dd) / (R + np.sqrt(dd))
        if self.contact_masses.size == 0:
            return rope
        return np.concatenate([rope, scene.ground.gaps(X[self.contact_masses])])

    def gap_rates(self, X, U) -> np.ndarray:
        """dg_u/dt (m/s): -(d . dU) / |d| of a rope, n . U_k of a contact."""
        scene = self.scene
        l = self.rope_links
        d = X[scene.k2[l]] - X[scene.k1[l]]
        dU = U[scene.k2[l]] - U[scene.k1[l]]
        rope = -np.einsum("ij,ij->i", d, dU) / np.sqrt(np.einsum("ij,ij->i", d, d))
        if self.contact_masses.size == 0:
            return rope
        return np.concatenate([rope, U[self.contact_masses] @ self.scene.ground.normal])

    def gap_polynomials(self, coefficients) -> np.ndarray:
        """(n_unilateral, 7): for every unilateral constraint a polynomial in theta (coefficients, lowest degree
        first) with the sign of its gap along the positions c0 + c1 theta + c2 theta^2 + c3 theta^3
        (``coefficients``: four (K,3) arrays): R_l^2 - |X_k2 - X_k1|^2 of a rope (sextic), n . (X_k - p) of a
        contact (cubic, its higher coefficients zero)."""
        scene = self.scene
        out = np.zeros((self.n_unilateral, 7))
        l = self.rope_links
        if l.size:
            D = np.stack([c[scene.k2[l]] - c[scene.k1[l]] for c in coefficients])  # (4, n_ropes, 3)
            products = np.einsum("irx,jrx->ijr", D, D)
            for i in range(4):
                for j in range(4):
                    out[:l.size, i + j] -= products[i, j]
            out[:l.size, 0] += scene.length[l] ** 2
        if self.contact_masses.size:
            n = scene.ground.normal
            out[l.size:, :4] = np.stack([c[self.contact_masses] @ n for c in coefficients], axis=1)
            out[l.size:, 0] -= scene.ground.point @ n
        return out

    def gap_polynomial_depths(self, depth) -> np.ndarray:
        """(n_unilateral,): the value of each constraint's gap_polynomials below which its gap is below -``depth``
        (m, one per constraint): R^2 - |d|^2 < -depth (2 R + depth) <=> |d| > R + depth for a rope; the gap itself
        for a contact."""
        depth = np.broadcast_to(np.asarray(depth, float), (self.n_unilateral,))
        R = self.scene.length[self.rope_links]
        return np.concatenate([depth[:R.size] * (2.0 * R + depth[:R.size]), depth[R.size:]])

    def velocity_scale(self, U) -> float:
        """A speed to measure rates against: the fastest free mass, or what gravity gives over the scene's size."""
        free = U[self.scene.free_indices]
        fastest = float(np.sqrt(np.einsum("ij,ij->i", free, free).max())) if free.size else 0.0
        return max(fastest, math.sqrt(float(np.linalg.norm(self.scene.gravity)) * self.size), 1e-300)

    def touching(self, X, U=None) -> np.ndarray:
        """The unilateral constraints at contact: gap within TOUCH_TOL of their scale, and (given U) not separating
        faster than TOUCH_TOL of the velocity scale."""
        near = np.abs(self.gaps(X)) <= TOUCH_TOL * self.scale
        if U is None:
            return near
        return near & (self.gap_rates(X, U) <= TOUCH_TOL * self.velocity_scale(U))

    def label(self, u: int) -> str:
        """A unilateral constraint in the scene's words."""
        if self.is_rope[u]:
            return f"rope {self.scene.link_label(int(self.index[u]))}"
        return f"the ground contact of {self.scene.mass_label(int(self.index[u]))}"

    # ---- modes -------------------------------------------------------------------------------------------
    def mode(self, active: np.ndarray, X: np.ndarray | None = None, U: np.ndarray | None = None,
             stuck: np.ndarray | None = None) -> ModeDynamics:
        """The ModeDynamics of the unilateral constraints ``active`` (bool, n_unilateral) with the contacts
        ``stuck`` (bool, one per contact; default none) held by friction, made once per pair of sets (its structure
        analysed at the state X, U it is first asked at)."""
        active = np.asarray(active, bool)
        n_ropes = self.rope_links.size
        stuck = (np.zeros(self.contact_masses.size, bool) if stuck is None or self.friction == 0
                 else np.asarray(stuck, bool) & active[n_ropes:])
        key = active.tobytes() + stuck.tobytes()
        kept = self._modes.get(key)
        if kept is None:
            X = self.scene.X0 if X is None else X
            U = self.scene.U0 if U is None else U
            kept = self._modes[key] = ModeDynamics(self, active, X, U, stuck)
        return kept

    # ---- Coulomb friction ----------------------------------------------------------------------------------
    def tangential_velocities(self, U) -> np.ndarray:
        """(n_contacts, 3): each contact mass's velocity along the plane."""
        n = self.scene.ground.normal
        Vc = U[self.contact_masses]
        return Vc - (Vc @ n)[:, None] * n

    def slip_directions(self, X, U, md: ModeDynamics, F_input=None, anchor_acc=None) -> np.ndarray:
        """(n_sliding, 3): the unit direction each of md's sliding contacts slips in, which its friction opposes:
        its tangential velocity's, while that is above TOUCH_TOL of the velocity scale and not against the step's
        reference (slip_reference); else the reference (the slip went through zero within the step: the stop is
        an event, and up to it the friction keeps its direction); else, a contact starting to slip from rest, the
        direction of the tangential acceleration its friction leaves it (starting_slip_directions)."""
        c = md.sliding
        v = self.tangential_velocities(U)[c]
        speed = np.linalg.norm(v, axis=1)
        ref = self.slip_reference[c]
        out = np.array(ref)
        moving = (speed > TOUCH_TOL * self.velocity_scale(U)) & (np.einsum("ij,ij->i", v, ref) >= 0)
        out[moving] = v[moving] / speed[moving, None]
        unknown = ~moving & (np.linalg.norm(ref, axis=1) == 0)
        if unknown.any():
            out[unknown] = self.starting_slip_directions(X, U, md, unknown, out, F_input, anchor_acc)
        return out

    def starting_slip_directions(self, X, U, md: ModeDynamics, starting, directions, F_input=None, anchor_acc=None):
        """(n_starting, 3): the directions d_j in which md's sliding contacts ``starting`` (bool over md.sliding; at
        rest along the plane) start to slip, the other sliding contacts slipping along their ``directions`` (rows
        of ``starting`` ignored). Coulomb's law at the acceleration level, at the first instant of a slip from rest:
        the friction -mu N_j d_j opposes the tangential acceleration it leaves, a_j = lambda_j d_j with lambda_j >= 0
        (Pfeiffer and Glocker, Multibody Dynamics with Unilateral Contacts, 1996; Glocker, Set-Valued Force Laws,
        2001). The mode's accelerations and normal forces are affine in the loads (the rod path's (9), (25)-(26),
        the other contacts' friction carried in W - D as ``friction`` does): with the starting contacts' friction
        forces f_k taken as loads, a_j = a0_j + sum_k G_jk f_k and N_j = N0_j + sum_k k_jk . f_k, measured by
        1 + 2 n_starting solves. Each d_j (an angle phi on the plane) then solves (a0_j + sum_{k != j} G_jk f_k -
        s_j G_jj d_j) x d_j = 0 with s_j = mu N_j = mu (N0_j + sum_{k != j} k_jk . f_k) / (1 + mu k_jj . d_j) and
        a_j . d_j >= 0, by a scan of phi and a bracketing root find (_slip_direction); of several roots the one
        nearest the direction of the frictionless acceleration a0_j (exact for a mass alone on the ground, where G_jj
        is isotropic and k_jj = 0, and kept as it is where it satisfies the law to round-off). With several contacts
        starting at once the roots are taken in turn (Gauss-Seidel) until the directions settle. Where the law has
        no root (the ground could hold the mass) the frictionless direction is kept."""
        tangents = self.tangents
        starting = np.asarray(starting, bool)
        masses = self.contact_masses[md.sliding[starting]]
        rows = md.sliding_rows[starting]
        others = np.array(directions, float)
        others[starting] = 0.0  # the starting contacts' friction: loads below, not in W - D
        F0 = np.zeros((self.scene.K, 3)) if F_input is None else np.asarray(F_input, float)
        Xa, Ua = md.pad(X), md.pad_velocity(X, U)

        def response(load):
            F = F0 + load
            friction, T = md.friction_and_tensions(X, U, F, anchor_acc, others)
            acc = md._unpad(md.inner.accelerations(Xa, Ua, md._pad_zero(F + friction), md._pad_zero(anchor_acc))[0])
            return acc[masses] @ tangents.T, T[rows]

        return self._coulomb_directions(response, masses)

    def _coulomb_directions(self, response, masses) -> np.ndarray:
        """(m, 3): the slip directions d_j of the contacts of ``masses`` under Coulomb's law at one level (the
        acceleration level from rest, or an impact): ``response(load)`` gives, for a load (K, 3) on the masses (a
        force, or an impulse), the tangential quantity a_j the law acts on (their accelerations, or their velocities
        after the impact), on the plane's tangents (m, 2), and their normal forces or impulses N_j (m,). Both are
        affine in the load (one mode, one basis), measured by 1 + 2 m responses: a_j = a0_j + sum_k G_jk f_k and
        N_j = N0_j + sum_k k_jk . f_k for friction loads f_k at the masses; each d_j then solves the scalar law of
        _slip_direction, taken in turn (Gauss-Seidel) until the directions settle."""
        mu = self.friction
        tangents = self.tangents
        a0, N0 = response(np.zeros((self.scene.K, 3)))
        m = masses.size
        # the loads' responses, measured with loads of the size of the friction (a unit load on a heavy scene would
        # be lost in the round-off of a0)
        probe = mu * max(float(np.abs(N0).max()), np.finfo(float).tiny)
        G = np.zeros((m, 2, m, 2))
        k = np.zeros((m, m, 2))
        for j in range(m):
            for i in range(2):
                load = np.zeros((self.scene.K, 3))
                load[masses[j]] = probe * tangents[i]
                a, N = response(load)
                G[:, :, j, i] = (a - a0) / probe
                k[:, j, i] = (N - N0) / probe
        size = np.linalg.norm(a0, axis=1)
        d = np.divide(a0, size[:, None], out=np.zeros_like(a0), where=size[:, None] > 0)
        f = np.zeros((m, 2))
        for _ in range(100 if m > 1 else 1):
            moved = 0.0
            for j in range(m):
                others_j = np.arange(m) != j
                a_j = a0[j] + np.einsum("xky,ky->x", G[j, :, others_j, :].transpose(1, 0, 2), f[others_j])
                N_j = N0[j] + np.einsum("ky,ky->", k[j, others_j], f[others_j])
                d_j = self._slip_direction(a_j, N_j, G[j, :, j, :], k[j, j], d[j])
                moved = max(moved, float(np.abs(d_j - d[j]).max()))
                d[j] = d_j
                f[j] = -mu * N_j / (1.0 + mu * (k[j, j] @ d_j)) * d_j
            if moved <= 1e-15:
                break
        return d @ tangents

    def _slip_direction(self, a, N, G, k, guess) -> np.ndarray:
        """The slip direction d from rest of one contact, on the plane's tangents: (a - s G d) x d = 0 with s = mu
        N / (1 + mu k . d) > 0 and (a - s G d) . d >= 0 (starting_slip_directions); ``guess`` (the frictionless
        acceleration's direction) where it satisfies this to round-off (kept exactly: a planar motion stays
        planar), else the root nearest it, else ``guess``. At a slip event the tangential acceleration starts from
        0 (the friction mu N equals the force that held the mass): the root there is the one with (a - s G d) = 0,
        d along the force the ground can no longer give, which is kept to round-off of a."""
        mu = self.friction
        slack = 64 * np.finfo(float).eps * max(float(np.linalg.norm(a)), mu * abs(N) * float(np.abs(G).max()))

        def law(phi):
            d = np.array([math.cos(phi), math.sin(phi)])
            s = mu * N / (1.0 + mu * (k @ d))
            acc = a - s * (G @ d)
            return float(acc[1] * d[0] - acc[0] * d[1]), float(acc @ d), s

        def holds(phi):
            _, along, s = law(phi)
            return along >= -slack and s > 0

        if not guess.any():
            return guess
        angle = math.atan2(guess[1], guess[0])
        cross, along, s = law(angle)
        if abs(cross) <= slack and along >= -slack and s > 0:
            return guess
        grid = angle - math.pi + 2 * math.pi * (np.arange(65) + 0.5) / 64
        values = [law(phi)[0] for phi in grid]
        roots = [float(phi) for phi, value in zip(grid, values) if value == 0.0 and holds(phi)]
        for lo, hi, v_lo, v_hi in zip(grid[:-1], grid[1:], values[:-1], values[1:]):
            if v_lo * v_hi < 0:
                sign = 1.0 if v_lo > 0 else -1.0
                phi = bracketed_root(lambda x, sign=sign: sign * law(x)[0], lo, hi, sign * v_lo, sign * v_hi)[1]
                if holds(phi):
                    roots.append(float(phi))
        if not roots:
            return guess
        phi = min(roots, key=lambda root: abs(math.remainder(root - angle, 2 * math.pi)))
        return np.array([math.cos(phi), math.sin(phi)])

    def set_slip_reference(self, X, U, md: ModeDynamics, F_input=None, anchor_acc=None) -> None:
        """The sliding contacts' slip directions at the start of a step become the step's reference (the others'
        are cleared)."""
        ref = np.zeros_like(self.slip_reference)
        if md.sliding.size:
            ref[md.sliding] = self.slip_directions(X, U, md, F_input, anchor_acc)
        self.slip_reference = ref

    def stick_margins(self, md: ModeDynamics, T_rows) -> np.ndarray:
        """(n_contacts,): mu N - |F_t| of each of md's stuck contacts (N its normal force, F_t the grip's force),
        >= 0 while the ground can hold it; +inf on the others."""
        out = np.full(self.contact_masses.size, np.inf)
        if md.stuck_masses.size:
            N = md.unilateral_forces(T_rows)[self.rope_links.size:][md.stuck]
            out[md.stuck] = self.friction * N - np.linalg.norm(md.grip_forces(T_rows), axis=1)
        return out

    def choose_stuck(self, X, U, active, candidates, F_input=None, anchor_acc=None) -> np.ndarray:
        """Which of the ``candidates`` (contacts, bool) the ground holds in the mode ``active``: all of them stuck,
        then the one whose tangential force is furthest beyond mu N let slip, until every stuck one is within the
        friction cone |F_t| <= mu N (to FORCE_TOL of the largest force)."""
        stuck = np.asarray(candidates, bool) & np.asarray(active, bool)[self.rope_links.size:]
        if self.friction == 0:
            return np.zeros_like(stuck)
        while stuck.any():
            md = self.mode(active, X, U, stuck)
            T = md.tensions(X, U, F_input, anchor_acc)
            margins = self.stick_margins(md, T)
            worst = int(np.argmin(margins))
            if margins[worst] >= -FORCE_TOL * float(np.abs(T).max()):
                break
            stuck[worst] = False
        return stuck

    def resting(self, U) -> np.ndarray:
        """(n_contacts,) bool: the contacts whose masses do not slip (tangential speed within TOUCH_TOL of the
        velocity scale): those that may stick."""
        if self.friction == 0:
            return np.zeros(self.contact_masses.size, bool)
        speed = np.linalg.norm(self.tangential_velocities(U), axis=1)
        return speed <= TOUCH_TOL * self.velocity_scale(U)

    def coulomb_impact(self, X, U, touching, tangential_vectors: bool = False):
        """The impact at a state where the unilateral constraints ``touching`` are at contact, with Coulomb's
        friction on the ground: Moreau's impact law with Coulomb friction as one problem in the normal and the
        tangential impulses (Pfeiffer and Glocker, Multibody Dynamics with Unilateral Contacts, 1996; Glocker,
        Set-Valued Force Laws, 2001): with the velocity jump M dU = C^T Lambda + sum_c P_t,c at the
        contacts' masses,

            rods:               (C U+)_i = 0
            ropes, contacts:    Lambda_i >= 0,  xi_i = (C U+)_i + e_i min((C U-)_i, 0) >= 0,  Lambda_i xi_i = 0
            friction:           |P_t,c| <= mu P_n,c;  P_t,c = -mu P_n,c v_t,c+ / |v_t,c+| where v_t,c+ != 0

        (Newton's restitution on the normal, none along the plane). A stuck contact (v_t,c+ = 0) is a pair of grip
        rows, equalities of the impact's LCP whose multipliers are P_t,c; a sliding one's friction is -mu P_n,c d_c
        with d_c its slip direction after the impact: Coulomb's law one level down, solved as at the first instant of
        a slip (_coulomb_directions, with the velocities after the impact in place of the accelerations; exact for a
        planar motion). Every contact that took an impulse or rests starts stuck; the one furthest outside its cone
        slides, in turn, until every stuck one is inside it. With e = 0 the impact dissipates: P_n v_n+ = 0, P_t .
        v_t+ = -mu P_n |v_t+| <= 0 and the kinetic energy changes by P . v+ - P . W P / 2 <= 0 (Newton's restitution
        with friction on coupled masses can add energy where a slip reverses: Stronge, J. Appl. Mech. 58, 1991).
        Where no contact takes a normal impulse the frictionless impact is the solution. Returns (U after, normal
        impulses (n_unilateral,) N s, the constraints that took one, |P_t| (n_contacts,) N s, or with
        ``tangential_vectors`` the tangential impulses P_t themselves (n_contacts, 3))."""
        U_free, impulses, took = self.impact(X, U, touching)
        n_ropes = self.rope_links.size
        if self.friction == 0 or not took[n_ropes:].any():
            none = np.zeros((self.contact_masses.size, 3) if tangential_vectors else self.contact_masses.size)
            return U_free, impulses, took, none
        touching = np.asarray(touching, bool)
        stuck = touching[n_ropes:] & (took[n_ropes:] | self.resting(U))
        while True:
            md = self.mode(touching, X, U, stuck)
            lam, friction = self._coulomb_impulses(md, X, U)
            P_n = md.unilateral_forces(lam)[n_ropes:]
            P_t = np.zeros((self.contact_masses.size, 3))
            P_t[md.stuck] = md.grip_forces(lam)
            margins = np.where(md.stuck, self.friction * P_n - np.linalg.norm(P_t, axis=1), np.inf)
            worst = int(np.argmin(margins))
            if margins[worst] >= -FORCE_TOL * float(np.abs(lam).max()):
                break
            stuck[worst] = False
        U_after = U + md.link_impulse_velocities(X, lam) + self._inv_mass3 * friction
        P_t[md.sliding] = friction[self.contact_masses[md.sliding]]
        impulses = md.unilateral_forces(lam)
        return U_after, impulses, self.took_impulse(X, U, impulses), P_t if tangential_vectors else np.linalg.norm(
            P_t, axis=1)

    def _coulomb_impulses(self, md: ModeDynamics, X, U):
        """(Lambda in md's row order, the sliding contacts' friction impulses (K, 3)) of the impact with md's stuck
        contacts held (their grip rows) and the others sliding (coulomb_impact). A friction impulse f on the
        masses shifts the rows' rates by C M^-1 f: the slip directions d_c are found with the sliding contacts'
        friction as loads (the velocities after the impact and the impulses are affine in them within one basis of
        the impact's LCP: the ropes and contacts that take an impulse), then the impact is solved with -mu P_n,c d_c
        carried into the columns of W, (W - D) Lambda + q as the acceleration level's W - D carries the sliding
        friction (ModeDynamics.normal_system); where that changes the basis (a rope the friction jerks slack or
        taut), the directions are found again in the new one."""
        W, rates, q, _, rows_uni = self._impact_problem(md, X, U)
        Xa = md.pad(X)
        masses = self.contact_masses[md.sliding]
        friction = np.zeros((self.scene.K, 3))
        lam, basis = solve_mixed_lcp(W, -q, rows_uni, rows_uni & (rates < 0))
        if not masses.size:
            return lam, friction

        def rate_shift(load):
            return md.inner.constraint_rows(Xa, md.pad_velocity(X, self._inv_mass3 * load))

        def response(load):  # in the impact's basis (its rows taken as equalities): affine in the load
            lam = basis_solution(W, -(q + rate_shift(load)), basis)
            U_plus = U + md.link_impulse_velocities(X, lam) + self._inv_mass3 * load
            return self.tangential_velocities(U_plus)[md.sliding] @ self.tangents.T, lam[md.sliding_rows]

        for _ in range(self.n_unilateral + 1):  # until the basis the directions were found in is the impact's
            directions = self._coulomb_directions(response, masses)
            coupled = np.array(W)
            for row, k, d in zip(md.sliding_rows, masses, directions):
                load = np.zeros((self.scene.K, 3))
                load[k] = -self.friction * d
                coupled[:, row] += rate_shift(load)
            lam, found = solve_mixed_lcp(coupled, -q, rows_uni, basis)
            if (found == basis).all():
                break
            basis = found
        np.add.at(friction, masses, -self.friction * lam[md.sliding_rows][:, None] * directions)
        return lam, friction

    def select_mode(self, X, U, F_input=None, anchor_acc=None, candidates=None, start=None, release=None,
                    stuck=None):
        """The active set at (X, U): the acceleration LCP on the ``candidates`` (default: those touching with no
        separating rate), warm-started from ``start`` (default: every candidate, so that a degenerate problem, force
        and gap acceleration both zero, keeps them taut); ``release``: constraints whose force has just fallen to 0
        (they stay only with a clearly positive force); ``stuck``: the contacts friction holds (their grips are
        equalities of the LCP; the other contacts' sliding friction is in its matrix, which is then not symmetric:
        normal_system). Returns (active, the multipliers of the candidates' mode in its row order, that mode)."""
        candidates = self.touching(X, U) if candidates is None else np.asarray(candidates, bool)
        start = candidates if start is None else start
        md = self.mode(candidates, X, U, stuck)
        W, B, _ = md.normal_system(X, U, F_input, anchor_acc)
        rows_uni = md.constraint_of_row >= 0
        start_rows = np.zeros(B.size, bool)
        release_rows = np.zeros(B.size, bool)
        if start is not None:
            start_rows[rows_uni] = np.asarray(start, bool)[md.constraint_of_row[rows_uni]]
        if release is not None:
            release_rows[rows_uni] = np.asarray(release, bool)[md.constraint_of_row[rows_uni]]
        lam, basis = solve_mixed_lcp(W, B, rows_uni, start_rows, release_rows)
        active = np.zeros(self.n_unilateral, bool)
        active[md.constraint_of_row[basis & rows_uni]] = True
        return active, lam, md

    def rest_speed(self, U) -> float:
        """Below this rebound speed an impact is perfectly inelastic (REST_HEIGHT): the speed a fall of REST_HEIGHT
        of the scene's size reaches under its acceleration scale (gravity, or the velocity scale over the size)."""
        acceleration = max(float(np.linalg.norm(self.scene.gravity)), self.velocity_scale(U) ** 2 / self.size)
        return math.sqrt(2.0 * acceleration * REST_HEIGHT * self.size)

    def impact(self, X, U, touching, inelastic: bool = False):
        """The impulse at a state where the unilateral constraints ``touching`` are at contact: Moreau's impact law
        with Newton's restitution as an LCP on them (the module's docstring). Returns (U after, impulses
        (n_unilateral,) N s, the constraints that took an impulse). The velocities are Dynamics.project_velocities
        of the impulse's active set (and U- + (1 + e)(P U- - U-) with a restitution e), the driven anchors' jump
        projection; only where different restitutions meet at one instant are they U- + M^-1 C^T Lambda of the
        LCP's impulses. ``inelastic``: e = 0 for all (the initial state)."""
        md = self.mode(touching, X, U)
        W, rates, q, e, rows_uni = self._impact_problem(md, X, U, inelastic)
        lam, basis = solve_mixed_lcp(W, -q, rows_uni, rows_uni & (rates < 0))
        impulses = md.unilateral_forces(lam)
        took = self.took_impulse(X, U, impulses)
        sub = basis & rows_uni
        active = np.zeros(self.n_unilateral, bool)
        active[md.constraint_of_row[sub]] = True
        approaching = basis & (rates < 0) & rows_uni
        separating = basis & (rates > TOUCH_TOL * self.velocity_scale(U))
        common = np.unique(e[approaching])
        if common.size <= 1 and not separating.any():
            e0 = float(common[0]) if common.size else 0.0
            projected = self.mode(active, X, U).project_velocities(X, U)
            U_after = projected if e0 == 0.0 else U + (1.0 + e0) * (projected - U)
        else:
            U_after = U + md.link_impulse_velocities(X, lam)
        return U_after, impulses, took

    def took_impulse(self, X, U, impulses) -> np.ndarray:
        """(n_unilateral,) bool: the constraints whose impulse in an impact at (X, U) (velocities before it) is one,
        not round-off: Lambda_u W_uu above IMPULSE_ROUNDOFF of the velocity scale, W_uu = C_u M^-1 C_u^T (a rope's
        |E_l|^2 (1/M_k1 + 1/M_k2) with E_l = d / R_l, a contact's 1/M_k; 0 where both ends are anchored, which no
        impulse moves)."""
        scene, inv = self.scene, self._inv_mass3[:, 0]
        ropes = self.rope_links
        d = X[scene.k2[ropes]] - X[scene.k1[ropes]]
        W_rope = np.einsum("ij,ij->i", d, d) / scene.length[ropes] ** 2 * (inv[scene.k1[ropes]] + inv[scene.k2[ropes]])
        W_uu = np.concatenate([W_rope, inv[self.contact_masses]])
        return np.asarray(impulses) * W_uu > IMPULSE_ROUNDOFF * self.velocity_scale(U)

    def _impact_problem(self, md: ModeDynamics, X, U, inelastic: bool = False):
        """(W, rates, q, e, unilateral rows) of Moreau's impact law on md's rows: W = C M^-1 C^T, the rows' rates C U
        (each row's dg/dt, scaled by |d|/R off the manifold), Newton's restitution e of each unilateral row (0 on
        the others, and where the rebound would be slower than rest_speed), and q = C U + e min(C U, 0), so that
        xi = W Lambda + q >= 0 on the unilateral rows and = 0 on the others (a stuck contact's grip rows among
        them: its tangential velocity after the impact is zero)."""
        Xa, Ua = md.pad(X), md.pad_velocity(X, U)
        W = md.inner.tension_matrix(Xa).toarray()
        rates = md.inner.constraint_rows(Xa, Ua)
        rows_uni = md.constraint_of_row >= 0
        e = np.zeros(rates.size)
        if not inelastic:
            e[rows_uni] = self.restitution[md.constraint_of_row[rows_uni]]
        e[e * np.maximum(-rates, 0.0) < self.rest_speed(U)] = 0.0
        return W, rates, rates + e * np.minimum(rates, 0.0), e, rows_uni

    def anchor_impulses(self, X, U_before, U_after, rows, ground=None, stuck=None) -> np.ndarray:
        """(len(rows), 3): what the links gave the driven anchors ``rows`` in an impact that took the free masses from
        U_before to U_after at X (both with the anchors' rows at their motion): the link impulses Lambda with
        M dU = C^T Lambda + P on the free masses (9), P the ground's impulses along its plane (``ground`` (K, 3),
        a friction or grip impulse the impact solved: not the links'), the minimum-norm ones A^+ C M^-1 (M dU - P)
        of the mode of the links that carried them (the touching links, contacts along n, and the grips of the
        contacts ``stuck``, whose impulse is the mode's; any other Lambda gives the same forces, (31)), and
        C^T Lambda on the anchors' rows."""
        dU = U_after - U_before
        if ground is not None:
            dU = dU - self._inv_mass3 * ground
        dU = np.where(self.scene.fixed[:, None], 0.0, dU)
        if not rows.size or not dU.any():
            return np.zeros((rows.size, 3))
        md = self.mode(self.touching(X), X, U_after, stuck)
        Xa = md.pad(X)
        inner = md.inner
        A = inner.tension_matrix(Xa).toarray()
        lam = np.linalg.lstsq(A, inner.constraint_rows(Xa, md._pad_zero(dU)), rcond=None)[0]
        return md._unpad(inner.link_forces(Xa, lam))[rows]

    # ---- the pure functions of the state (outputs, diagnostics) ------------------------------------------------
    def resolve(self, X, U, F_input=None, anchor_acc=None):
        """(T (L,) of every link, normal force (K,) of the ground on every mass) at (X, U): the acceleration LCP on
        the touching constraints, then the tensions of its mode (25)-(26) by the rod path's solver."""
        md = self.state_mode(X, U, F_input, anchor_acc)
        T_rows = md.tensions(X, U, F_input, anchor_acc)
        T = np.zeros(self.scene.L)
        T[md.links] = T_rows[:md.links.size]
        normal = np.zeros(self.scene.K)
        forces = md.unilateral_forces(T_rows)
        normal[self.contact_masses] = forces[self.rope_links.size:]
        return T, normal

    def ground_forces(self, X, U, F_input=None, anchor_acc=None):
        """(normal (K,), tangential (K,3)): the ground's force on every mass at (X, U), its normal force and its
        friction (a stuck mass's grip, a sliding one's -mu N d), in the mode state_mode chooses there."""
        md = self.state_mode(X, U, F_input, anchor_acc)
        T_rows = md.tensions(X, U, F_input, anchor_acc)
        normal = np.zeros(self.scene.K)
        normal[self.contact_masses] = md.unilateral_forces(T_rows)[self.rope_links.size:]
        tangential = np.zeros((self.scene.K, 3))
        tangential[md.stuck_masses] = md.grip_forces(T_rows)
        if md.sliding.size:
            tangential += md.friction(X, U, F_input, anchor_acc)
        return normal, tangential

    def tensions(self, X, U, F_input=None, F=None, E=None, anchor_acc=None) -> np.ndarray:
        """Every link's tension at (X, U): rods and taut ropes from (25)-(26) of the mode the LCP chooses there,
        slack ropes 0."""
        return self.resolve(X, U, F_input, anchor_acc)[0]

    def state_mode(self, X, U, F_input=None, anchor_acc=None) -> ModeDynamics:
        """The mode at (X, U) as a pure function of the state: the acceleration LCP on the touching constraints,
        with the resting contacts that friction can hold stuck (choose_stuck)."""
        resting = self.resting(U)
        active, _, _ = self.select_mode(X, U, F_input, anchor_acc, stuck=resting)
        return self.mode(active, X, U, self.choose_stuck(X, U, active, resting, F_input, anchor_acc))

    def accelerations(self, X, U, F_input=None, anchor_acc=None):
        acc, _ = self.state_mode(X, U, F_input, anchor_acc).accelerations(X, U, F_input, anchor_acc)
        return acc, self.tensions(X, U, F_input, anchor_acc=anchor_acc)

    def constraint_residual(self, X):
        """The largest relative violation: a rod's | |d|/R - 1 |, a rope's stretch max(0, |d|/R - 1), a mass's depth
        below the ground over the scene's size. X (n,K,3): n values."""
        scene = self.scene
        d = X[..., scene.k2, :] - X[..., scene.k1, :]
        rel = np.sqrt(np.einsum("...ij,...ij->...i", d, d)) / scene.length - 1.0
        rel = np.where(scene.rope, np.maximum(rel, 0.0), np.abs(rel))
        worst = rel.max(axis=-1) if scene.L else np.zeros(X.shape[:-2])
        if scene.ground is not None:
            depth = np.maximum(-scene.ground.gaps(X[..., self.contact_masses, :]), 0.0) / self.size
            worst = np.maximum(worst, depth.max(axis=-1))
        return float(worst) if X.ndim == 2 else worst

    def velocity_residual(self, X, U):
        """The largest violation of (12), m/s: a rod's |E . (U_k2 - U_k1)|; a rope at its length (within TOUCH_TOL)
        stretching, max(0, -dg/dt); a mass on the ground moving into it."""
        scene = self.scene
        d = X[..., scene.k2, :] - X[..., scene.k1, :]
        dist = np.sqrt(np.einsum("...ij,...ij->...i", d, d))
        rate = np.einsum("...ij,...ij->...i", d, U[..., scene.k2, :] - U[..., scene.k1, :]) / dist  # d|d|/dt
        at_length = dist >= scene.length * (1.0 - TOUCH_TOL)
        viol = np.where(scene.rope, np.where(at_length, np.maximum(rate, 0.0), 0.0),
                        np.abs(rate * dist / scene.length))
        worst = viol.max(axis=-1) if scene.L else np.zeros(X.shape[:-2])
        if scene.ground is not None:
            k = self.contact_masses
            gap = scene.ground.gaps(X[..., k, :])
            into = np.maximum(-(U[..., k, :] @ scene.ground.normal), 0.0)
            worst = np.maximum(worst, np.where(gap <= TOUCH_TOL * self.size, into, 0.0).max(axis=-1))
        return float(worst) if X.ndim == 2 else worst

    # ---- the initial state -------------------------------------------------------------------------------------
    def initial_state(self, project_positions: bool | None = None, length_tol: float = 1e-6, consistent=None):
        """The scene's initial state made consistent, as simulator.prepare_initial_state does for rods: rods within
        length_tol of their lengths, ropes not longer than theirs (else refused, or projected where asked); the
        ropes at their length and the masses on the ground take the impulse of an impact (their approach velocities
        removed, as (12) removes a rod's); hypothesis (35) is checked on the mode that results. Returns (X, U,
        report).

        ``consistent``: None (the projection and the impact by this reference), or a backend's own way of doing
        those two, a callable (X, U, project) -> (X, U) that raises SolverError where it cannot (the native core's,
        linknet_core.native.integrator.core_initial_state), so that a backend's run starts from its own state. Where
        it fails, the reference's failure is what is said, in its words."""
        scene = self.scene
        if project_positions is None:
            project_positions = bool(scene.options.get("project_initial_positions", False))
        X, U = np.array(scene.X0), np.array(scene.U0)
        anchor_acc = None
        if scene.driven.any():
            P, V, A = scene.anchor_motion(0.0)
            X[scene.driven_indices], U[scene.driven_indices] = P, V
            anchor_acc = np.zeros_like(X)
            anchor_acc[scene.driven_indices] = A
        d = X[scene.k2] - X[scene.k1]
        rel = np.sqrt(np.einsum("ij,ij->i", d, d)) / scene.length - 1.0
        off = np.where(scene.rope, np.maximum(rel, 0.0), np.abs(rel))
        worst = float(off.max()) if scene.L else 0.0
        projected = False
        if worst > length_tol:
            l = int(np.argmax(off))
            if not project_positions:
                what = "is stretched beyond its length" if scene.rope[l] else "violates its length"
                raise SceneError(
                    f"{scene.name}: initial positions: {scene.link_label(l)} {what} (distance "
                    f"{np.linalg.norm(d[l]):.6g} m vs length {scene.length[l]:.6g} m, {worst:.3g} relative; tolerance "
                    f"{length_tol:g}; a rope may be shorter than its length, never longer). Fix the positions or the "
                    "lengths, or opt in to projecting them (--project-initial, or \"options\": "
                    "{\"project_initial_positions\": true})")
            projected = True
        if consistent is None:
            X, U_new = self._consistent_start(X, U, rel, projected)
        else:
            try:
                X, U_new = consistent(X, U, projected)
            except SolverError as exc:
                self._consistent_start(X, U, rel, projected)  # the reference's words where it fails too
                raise SceneError(f"{scene.name}: the initial state cannot be made consistent: {exc}") from None
        correction = np.linalg.norm(U_new - U, axis=1)
        worst_mass = int(np.argmax(correction)) if correction.size else -1
        dv = float(correction.max()) if correction.size else 0.0
        if dv <= 1e-14 * max(1.0, float(np.abs(U).max())):
            dv, worst_mass = 0.0, -1
        active, _, _ = self.select_mode(X, U_new, None, anchor_acc)
        md = self.mode(active, X, U_new)
        Xa, Ua = md.pad(X), md.pad_velocity(X, U_new)
        try:
            md.inner.check_consistent_velocities(Xa, Ua, anchor_acc=md._pad_zero(anchor_acc))
            md.inner.check_no_loaded_blocked_flex(Xa, Ua)
        except ConsistencyError as exc:
            raise ConsistencyError(f"{scene.name}: with the ropes and contacts that are taut at the start: {exc}") \
                from None
        return X, U_new, UnilateralReport(worst, projected, dv, worst_mass, int(active[:self.rope_links.size].sum()),
                                          self.rope_links.size, int(active[self.rope_links.size:].sum()))

    def _consistent_start(self, X, U, rel, project: bool):
        """initial_state's positions and velocities: where ``project``, X projected onto the rods and the ropes
        longer than their length (``rel``: each link's relative excess) in the mass metric, the contacts onto the
        ground; then the inelastic impact at X (the ropes at their length and the masses on the ground). Returns
        (X, U)."""
        if project:
            stretched = np.zeros(self.n_unilateral, bool)
            stretched[:self.rope_links.size] = rel[self.rope_links] > 0
            try:
                X, _ = self.mode(stretched, X, U).project_positions(X, tol=1e-14, max_iter=200)
            except SolverError as exc:
                raise SceneError(f"{self.scene.name}: the initial positions cannot be projected onto the link "
                                 f"lengths: {exc}") from None
        # the ropes at their length and the masses on the ground take an inelastic impulse, the rods' rates (12) go
        # to zero with it (the impact LCP's equalities): one projection
        U_new, _, _ = self.impact(X, U, self.touching(X), inelastic=True)
        return X, U_new


@dataclass
class UnilateralReport(InitialReport):
    """What was done to the initial state of a scene with ropes or a ground: the InitialReport of rods, and the
    ropes and contacts it starts with."""

    taut_ropes: int
    ropes: int
    contacts: int

    velocity_rule = ": the approach along taut ropes, the ground and (12) removed (an inelastic impulse)"

    def lines(self, scene: Scene) -> list[str]:
        what = []
        if self.ropes:
            what.append(f"{self.taut_ropes} of {self.ropes} ropes taut at the start")
        if scene.ground is not None:
            what.append(f"{self.contacts} masses on the ground")
        return super().lines(scene) + [
            "ropes and ground: event by event (the native core on every method, the numpy reference with "
            "backend=\"numpy\"); "
            + ", ".join(what)]


def event_arrays(events, ground=None) -> dict:
    """The events as arrays for a run's .npz: event_t (s), event_kind, event_index (1-based: the link of taut and
    slack, the mass of contact and release, as the files number them) and event_impulse (N s); with the scene's
    ``ground`` also ground_point and ground_normal (what the pictures draw it from)."""
    out = {"event_t": np.array([e.t for e in events], float), "event_kind": np.array([e.kind for e in events], str),
           "event_index": np.array([e.index + 1 for e in events], np.int64),
           "event_impulse": np.array([e.impulse for e in events], float)}
    if ground is not None:
        out.update(ground_point=np.array(ground.point, float), ground_normal=np.array(ground.normal, float))
    return out


def event_counts(events) -> dict:
    """How many events of each kind a run had."""
    counts = {"taut": 0, "slack": 0, "contact": 0, "release": 0, "stick": 0, "slip": 0}
    for event in events:
        counts[event.kind] += 1
    return counts

