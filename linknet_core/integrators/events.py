"""Events of ropes and a ground: every integrator, stepping one mode at a time and stopping at each event.

Between events a scene with ropes or a ground is a network of rods (linknet_core.dynamics.unilateral.ModeDynamics:
the rods, the taut ropes, the masses on the ground), which every method integrates as it integrates any scene. An
event ends a mode:

* **taut** / **contact**: a slack rope reaches its length, a free mass the ground (its gap g crosses 0 from above);
* **slack** / **release**: a taut rope's tension, the ground's force on a mass, falls through 0.

Each step is checked after it is taken: the gaps of the slack constraints along the step's dense interpolant (the
cubic Hermite of X from X and U at both ends: exact for a ballistic flight, O(h^4) otherwise), everywhere in the
step however briefly they dip (their sign is a polynomial in the step's fraction, bounded by its Bernstein
coefficients and looked at exactly where the bound allows a dip), each dip confirmed on the method's own step to its
lowest point; and the forces of the active ones at its end and at its inner stages, where a force that falls through
zero and rises again within the step shows (EventHandling._force_dip_at_stages: an adaptive step's stages, a fixed
step's RATTLE stages' midpoints, FixedStepEvents._midpoint_tensions). The first event is located there by a
bracketing root find (Illinois' regula falsi) and the step is taken again from its start to the event, by the method's own step; a
gap event's time is then made exact by Newton's method on that step's length (the gap and its rate at its end), so
that the event lies on the method's own trajectory, not on the interpolant. At the event the impulse is applied and
the next mode chosen (UnilateralDynamics.impact, select_mode), and the integration restarts from there:

* the adaptive methods (dopri5, dop853) end the step at the event and go on with their step-size controller;
* the fixed-step methods (rattle and its compositions) finish the step from the event in the new mode, so that
  their steps stay where they are: a step holds the event at its located time, every other step is the method's.
"""
from __future__ import annotations

import functools
import math

import numpy as np

from linknet_core.dynamics.drive import driven_rows_at
from linknet_core.dynamics.roots import bracketed_root
from linknet_core.dynamics.unilateral import CROSS_TOL, FORCE_TOL, TOUCH_TOL, Event
from linknet_core.errors import SolverError, StepFailure
from linknet_core.integrators.base import TensionPeaks
from linknet_core.tolerances import MIN_FACTOR, SAFETY

# More events than this within one step (or one adaptive step attempt) means a chatter the rest rule did not stop
MAX_EVENTS_PER_STEP = 200
# A part of a fixed step shorter than this fraction of dt is taken by a Taylor step (FixedStepEvents._plain_step)
SHORT_STEP = 1e-3
# Newton's iterations on a gap event's time (quadratic convergence from the interpolant's O(h^4) root)
GAP_NEWTON_ITERATIONS = 4


def hermite(y0, d0, y1, d1, h, theta):
    """The cubic Hermite interpolant at theta in [0, 1] of a step of length h from (y0, d0) to (y1, d1)."""
    t2 = theta * theta
    t3 = t2 * theta
    return ((2 * t3 - 3 * t2 + 1) * y0 + (t3 - 2 * t2 + theta) * h * d0 + (3 * t2 - 2 * t3) * y1
            + (t3 - t2) * h * d1)


def hermite_coefficients(y0, d0, y1, d1, h):
    """(c0, c1, c2, c3): the cubic Hermite interpolant of a step as c0 + c1 theta + c2 theta^2 + c3 theta^3."""
    return (y0, h * d0, 3 * (y1 - y0) - h * (2 * d0 + d1), 2 * (y0 - y1) + h * (d0 + d1))


def _bernstein_matrix(n: int) -> np.ndarray:
    """(n+1, n+1): the map from a polynomial's power coefficients (lowest degree first) to its coefficients in the
    Bernstein basis of degree n on [0, 1]: b_j = sum_{i <= j} C(j, i) / C(n, i) a_i (Farouki and Rajan, Computer
    Aided Geometric Design 5, 1988, eq. 2)."""
    M = np.zeros((n + 1, n + 1))
    for j in range(n + 1):
        for i in range(j + 1):
            M[j, i] = math.comb(j, i) / math.comb(n, i)
    return M


# the gap polynomials are sextic at most (a rope's R^2 - |d|^2 along the cubic Hermite of X)
_BERNSTEIN_6 = _bernstein_matrix(6)


def may_fall_below(P, depth) -> np.ndarray:
    """(n,) bool: which of the polynomials P (n, 7: coefficients, lowest degree first, sextic at most) can fall
    below -depth somewhere on [0, 1]. A polynomial lies within the convex hull of its Bernstein coefficients
    (Farouki and Rajan 1988): where all are >= -depth it does not, for certain, and gap_dips need not look;
    the others are looked at exactly."""
    return (np.asarray(P, float) @ _BERNSTEIN_6.T).min(axis=1) < -np.asarray(depth, float)


def gap_dips(p, depth) -> list[tuple[float, float]]:
    """Each excursion of the polynomial p (coefficients, lowest degree first) below -depth (depth >= 0) on [0, 1],
    in order, however brief (a rope that would come taut and slack again within the step, a mass that grazes the
    ground): [(theta where p crosses zero on its way down into it, theta of its lowest point), ...]. Exact on the
    polynomial: [0, 1] is cut at the real parts of every root of p' (its critical points, and spurious cuts that only
    split a monotone piece), so p is monotone between the cuts, its lowest values are at them, and an excursion is a
    run of consecutive cuts below -depth. Its zero is on the last piece before it that starts at p >= 0 (after the
    excursion before it), found by the bracketing root find; where there is none (p starts below 0 within round-off,
    as a rebound does, and stays there) the crossing of -depth is taken. An excursion from theta = 0 crosses at 0."""
    p = np.trim_zeros(np.asarray(p, float), "b")
    if p.size < 2:
        return [(0.0, 0.0)] if p.size and p[0] < -depth else []
    dp = np.arange(1, p.size) * p[1:]
    cuts = np.roots(dp[::-1]).real if dp.size > 1 else np.zeros(0)
    cuts = np.unique(np.concatenate([[0.0, 1.0], cuts[(cuts > 0.0) & (cuts < 1.0)]]))
    values = np.polyval(p[::-1], cuts)
    below = values < -depth
    out = []
    after = -1  # the last cut of the excursion before
    j = 0
    while j < cuts.size:
        if not below[j]:
            j += 1
            continue
        k = j
        while k + 1 < cuts.size and below[k + 1]:
            k += 1
        lowest = float(cuts[j + int(np.argmin(values[j:k + 1]))])
        if j == 0:
            out.append((0.0, lowest))
        else:
            above = after + 1 + np.flatnonzero(values[after + 1:j] >= 0.0)
            shift = 0.0 if above.size else depth
            i = int(above[-1]) if above.size else j - 1

            def f(theta, shift=shift):
                return float(np.polyval(p[::-1], theta)) + shift
            out.append((float(bracketed_root(f, cuts[i], cuts[i + 1], values[i] + shift, values[i + 1] + shift)[1]),
                        lowest))
        after = k
        j = k + 1
    return out


class EventHandling:
    """What the event-driven variants of every method share: the mode, the events so far, detection, location and
    the event itself. ``self.dyn`` is the current mode's ModeDynamics; ``self.unilateral`` the scene's
    UnilateralDynamics."""

    def _init_events(self, unilateral):
        self.unilateral = unilateral
        self.peaks = TensionPeaks(located=False)
        self.mode = None  # chosen from the state at the first advance
        self.stuck = None  # the contacts friction holds (one per contact)
        self.events: list[Event] = []

    def internals(self) -> dict:
        out = super().internals()
        out["mode"] = None if self.mode is None else self.mode.copy()
        out["stuck"] = None if self.stuck is None else self.stuck.copy()
        out["slip_reference"] = self.unilateral.slip_reference.copy()
        out["events"] = list(self.events)
        return out

    def set_internals(self, data: dict) -> None:
        super().set_internals(data)
        self.events = list(data.get("events", []))
        if data.get("slip_reference") is not None:
            self.unilateral.slip_reference = np.array(data["slip_reference"])
        mode = data.get("mode")
        if mode is None:
            self.mode, self.stuck, self.dyn = None, None, self.unilateral
        else:
            self._set_mode(mode, stuck=data.get("stuck"))

    def projection_floor(self):
        return int(self.unilateral.floor_stops), float(self.unilateral.floor_reached)

    @property
    def rhs_evaluations(self) -> int:
        return self.unilateral.rhs_evaluations

    # ---- the mode ---------------------------------------------------------------------------------------
    def _set_mode(self, active, X=None, U=None, stuck=None):
        self.mode = np.array(active, bool)
        self.dyn = self.unilateral.mode(self.mode, X, U, stuck)
        self.stuck = self.dyn.stuck.copy()

    def _slip_reference(self, t, X, U, F_input):
        """The sliding contacts' slip directions at the start of a step: the step's reference (friction)."""
        if self.unilateral.friction > 0 and self.dyn.sliding.size:
            Xd, Ud, acc = self._at(t, X, U)
            self.unilateral.set_slip_reference(Xd, Ud, self.dyn, F_input, acc)

    def _at(self, t, X, U):
        """(X, U, anchor accelerations) with the driven anchors where their motion is at t."""
        if self.drive is None:
            return X, U, None
        return self.drive.apply(t, X, U)

    def _ensure_mode(self, X, U, t, F_input):
        if self.mode is None:
            self._choose_mode(*self._at(t, X, U), F_input, X, U)
            self.unilateral.slip_reference[:] = 0.0
            self._slip_reference(t, X, U, F_input)

    def _choose_mode(self, Xd, Ud, acc, F_input, X, U):
        """The mode the state (Xd, Ud: the driven anchors where their motion has them, accelerating at acc) is in:
        the acceleration LCP on the touching constraints, with the resting contacts friction can hold stuck."""
        uni = self.unilateral
        candidates = uni.touching(Xd, Ud)
        resting = uni.resting(Ud)
        active, _, _ = uni.select_mode(Xd, Ud, F_input, acc, candidates, start=candidates, stuck=resting)
        self._set_mode(active, X, U, uni.choose_stuck(Xd, Ud, active, resting, F_input, acc))

    # ---- detection and location -------------------------------------------------------------------------------
    def _forces_at(self, t, X, U, F_input):
        """(values, tolerances, watched): what must stay >= 0 in the mode, and how far below 0 each may go before
        it is an event: the active unilateral constraints' forces (n_unilateral, FORCE_TOL of the largest |force| of
        the mode's rows); with friction, then one per contact: a stuck one's margin mu N - |F_t| (the same
        tolerance), a sliding one's velocity along the step's slip reference (TOUCH_TOL of the velocity scale)."""
        uni, dyn = self.unilateral, self.dyn
        Xd, Ud, acc = self._at(t, X, U)
        T = dyn.tensions(Xd, Ud, F_input, acc)
        scale = float(np.abs(T).max()) if T.size else 0.0
        values = dyn.unilateral_forces(T)
        if uni.friction == 0:
            return values, np.full(values.size, FORCE_TOL * scale), self.mode
        sliding = np.zeros(uni.contact_masses.size, bool)
        sliding[dyn.sliding] = True
        slip = np.einsum("ij,ij->i", uni.tangential_velocities(Ud), uni.slip_reference)
        friction = np.where(dyn.stuck, uni.stick_margins(dyn, T), slip)
        friction_tol = np.where(dyn.stuck, FORCE_TOL * scale, TOUCH_TOL * uni.velocity_scale(Ud))
        return (np.concatenate([values, friction]), np.concatenate([np.full(values.size, FORCE_TOL * scale),
                                                                    friction_tol]),
                np.concatenate([self.mode, dyn.stuck | sliding]))

    def _first_event(self, X0, U0, t0, X1, U1, t1, F_input, step):
        """The first event within the step from (X0, U0) at t0 to (X1, U1) at t1, or None: (theta in [0, 1], kind
        'gap' or 'force', constraint u). ``step(h)``: the method's own step from t0 of length h (what a gap's dip
        on the interpolant is confirmed on)."""
        uni = self.unilateral
        h = t1 - t0
        mode = self.mode
        found = None
        inactive = ~mode
        if inactive.any():
            # the slack constraints whose gap along the step's interpolant falls below -tol anywhere in it (however
            # briefly): the gap's sign is a polynomial in theta (the Hermite of X is cubic, a rope's R^2 - |d|^2
            # sextic), screened by its Bernstein coefficients and then looked at exactly (exact on a ballistic
            # flight however many bounces the step spans); each dip, in order, is then confirmed on the method's own
            # step to its lowest point: where the interpolant's error (h^4 times X's fourth derivative) makes a dip
            # that the method's trajectory does not have, as it can just after a slack event (gap, rate and second
            # derivative all zero, the gap growing as t^3), it is no event
            tol = CROSS_TOL * np.maximum(uni.scale, np.abs(X1).max())
            P = uni.gap_polynomials(hermite_coefficients(X0, U0, X1, U1, h))
            depth = uni.gap_polynomial_depths(tol)
            dips = sorted((crossing, lowest, int(u)) for u in np.flatnonzero(inactive & may_fall_below(P, depth))
                          for crossing, lowest in gap_dips(P[u], float(depth[u])))
            for crossing, lowest, u in dips:
                Xm = X0 if lowest == 0.0 else X1 if lowest == 1.0 else step(lowest * h)[0]
                if uni.gaps(Xm)[u] < -tol[u]:
                    found = (crossing, "gap", u)
                    break
        if mode.any():
            forces, tol, watched = self._forces_at(t1, X1, U1, F_input)
            dropped = np.flatnonzero(watched & (forces < -tol))
            if dropped.size:
                A0, A1 = self._acceleration_at(t0, X0, U0, F_input), self._acceleration_at(t1, X1, U1, F_input)
                for u in dropped:
                    def force(th, u=u):
                        Xh = hermite(X0, U0, X1, U1, h, th)
                        Uh = hermite(U0, A0, U1, A1, h, th)
                        return float(self._forces_at(t0 + th * h, Xh, Uh, F_input)[0][u])
                    f0 = force(0.0)
                    # the order of the events only: the time itself is found on the method's steps (_to_force_root)
                    root = 0.0 if f0 < 0 else bracketed_root(force, 0.0, 1.0, f0, float(forces[u]), xtol=1e-6)[1]
                    if found is None or root < found[0]:
                        found = (root, "force", int(u))
        return found

    def _acceleration_at(self, t, X, U, F_input):
        Xd, Ud, acc = self._at(t, X, U)
        return self.dyn.accelerations(Xd, Ud, F_input, acc)[0]

    def _locate(self, step, X0, U0, t0, h_max, X1, U1, F_input, found):
        """The state at the event ``found`` (theta, kind, u) on the method's own trajectory: (X, U, h), h the step
        from t0 to it."""
        theta, kind, u = found
        if kind == "gap":
            return self._to_gap_root(step, X0, U0, t0, h_max, u, theta)
        return self._to_force_root(step, X0, U0, t0, h_max, X1, U1, F_input, u, theta)

    def _to_force_root(self, step, X0, U0, t0, h_max, X1, U1, F_input, u, theta):
        """The method's own step from t0 to just past the zero of constraint u's force (the interpolant's root
        theta the first guess), by the bracketing root find on the step's length: the event's state has the force
        at or just below zero. Returns (X, U, h)."""
        kept = {}

        def force(h):
            kept[h] = step(h)
            return float(self._forces_at(t0 + h, *kept[h], F_input)[0][u])
        f0 = float(self._forces_at(t0, X0, U0, F_input)[0][u])
        f1 = float(self._forces_at(t0 + h_max, X1, U1, F_input)[0][u])
        if not f0 >= 0:
            return X0, U0, 0.0
        kept[h_max] = (X1, U1)
        _, h = bracketed_root(force, 0.0, h_max, f0, f1, xtol=1e-13, guess=theta * h_max)
        Xe, Ue = kept[h] if h in kept else step(h)
        return Xe, Ue, h

    def _to_gap_root(self, step, X0, U0, t0, h_max, u, theta):
        """The method's own step from t0 to a gap event located on the interpolant at theta, its length corrected
        by Newton's method until the gap of constraint u at its end is zero to round-off. Returns (X, U, h)."""
        uni = self.unilateral
        h = theta * h_max
        Xe, Ue = step(h) if h > 0 else (X0, U0)
        for _ in range(GAP_NEWTON_ITERATIONS):
            g = float(uni.gaps(Xe)[u])
            rate = float(uni.gap_rates(Xe, Ue)[u])
            if abs(g) <= 4 * np.finfo(float).eps * max(uni.scale[u], float(np.abs(Xe).max())) or not rate < 0:
                break
            h_new = min(max(h - g / rate, 0.0), h_max)
            if h_new == h:
                break
            h = h_new
            Xe, Ue = step(h) if h > 0 else (X0, U0)
        return Xe, Ue, h

    def _force_dip_at_stages(self, X0, U0, t0, h, F_input, stages, step):
        """A force event inside a step whose end _first_event found clear: an active constraint's force (a taut
        rope's tension, the ground's normal force) that falls through zero and rises again within the step (a rope
        barely slack at the top of a loop). The forces at the step's inner stages (nodes c_i in (0, 1): an adaptive
        method's stage tensions, computed there at no cost; a fixed-step method's at its RATTLE stages' midpoints,
        FixedStepEvents._midpoint_tensions) are screened: at each node below its tolerance, and at the vertex of
        the parabola through every three consecutive nodes whose middle one is lowest (a smooth minimum between
        nodes, found as the tension peaks are); a candidate is confirmed on the method's own step to it. Returns
        (found, t1, X1, U1) for _take_event (the event lies in the step to the candidate), or None."""
        if not self.mode.any():
            return None
        samples = sorted((c, T) for c, T in stages if 0.0 < c < 1.0 and T is not None and T.size)
        if len(samples) < 1:
            return None
        nodes = np.array([c for c, _ in samples])
        forces = np.array([self.dyn.unilateral_forces(T) for _, T in samples])  # (n_nodes, n_unilateral)
        scale = max(float(np.abs(T).max()) for _, T in samples)
        tol = FORCE_TOL * scale
        candidates = []  # (theta, constraint)
        for u in np.flatnonzero(self.mode):
            f = forces[:, u]
            low = np.flatnonzero(f < -tol)
            if low.size:
                candidates.append((float(nodes[low[0]]), int(u)))
                continue
            for j in range(1, nodes.size - 1):
                if f[j] <= f[j - 1] and f[j] <= f[j + 1] and nodes[j - 1] < nodes[j] < nodes[j + 1]:
                    theta, value = _parabola_vertex(nodes[j - 1:j + 2], f[j - 1:j + 2])
                    if value < -tol:
                        candidates.append((theta, int(u)))
                        break
        for theta, u in sorted(candidates):
            Xc, Uc = step(theta * h)
            values, tolerances, watched = self._forces_at(t0 + theta * h, Xc, Uc, F_input)
            if watched[u] and values[u] < -tolerances[u]:
                return (0.5, "force", u), t0 + theta * h, Xc, Uc
        return None

    # ---- the driven anchors' jump --------------------------------------------------------------------------
    def anchor_jump(self, drive, t, X, U, F_input=None):
        """The driven anchors brought to their motion at t where it jumped (an input-driven anchor's new held motion
        at a communication point), as an event: the ropes the jump stretched and the masses it pushed below the
        ground are put back onto them with the touching ones, the impact law takes the jerk (UnilateralDynamics.
        impact, each rope with its restitution, the rods' rates (12) to zero as the rods' jump projection does),
        and the mode is chosen from the state after it, the ropes' taut and slack events recorded at t. Returns
        (X, U, impulse (n_driven, 3): what the links gave each driven anchor, position jump (m), velocity jump
        (m/s)), as dynamics.drive.anchor_jump does for rods."""
        Xj, Uj, dP, dV = driven_rows_at(drive, t, X, U)
        if dP == 0.0 and dV == 0.0:
            return X, U, np.zeros((drive.rows.size, 3)), 0.0, 0.0
        if self.mode is None:  # before the first advance: the mode of the state before the jump
            self._choose_mode(X, U, None, F_input, X, U)
        X_after, U_after = self._apply_event(Xj, Uj, t, F_input, "anchor", None, drive.rows)
        return X_after, U_after, self.event_anchor_impulse, dP, dV

    # ---- the event -------------------------------------------------------------------------------------------
    def _apply_event(self, X, U, t, F_input, kind, trigger, anchor_rows=None):
        """At an event at t (state X, U of the old mode): positions onto the touching constraints, the impact's
        impulse, the next mode; the events recorded, and what the links gave the driven anchors in the impact
        (event_anchor_impulse, on ``anchor_rows``, default the drive's) added to the advance's (AnchorDrive.
        advance_impulse; a jump's own is the jump's, EventHandling.anchor_jump). Returns (X, U)."""
        uni = self.unilateral
        n_uni, n_ropes = uni.n_unilateral, uni.rope_links.size
        # a trigger past the unilateral constraints is a contact's friction: its stick margin (stuck -> slip) or its
        # slip speed (sliding -> a stop, where it sticks if the ground can hold it)
        friction_contact = trigger - n_uni if kind == "force" and trigger >= n_uni else None
        touching = self.mode | uni.touching(X)
        if kind == "gap":
            touching[trigger] = True
        elif kind == "anchor":  # the ropes a driven anchor's jump stretched, the masses it pushed into the ground
            touching |= uni.gaps(X) < 0.0
        stuck_before = self.stuck
        X, _ = uni.mode(touching, X, U).project_positions(X, tol=1e-14)
        U_after, impulses, took, tangential = uni.coulomb_impact(X, U, touching, tangential_vectors=True)
        Xd, Ud, acc = self._at(t, X, U_after)
        # the touching constraints that do not separate, or separate slower than the rest speed (an inelastic
        # collapse: neighbouring ropes jerking each other slack in turn, the speeds shrinking by a factor per turn,
        # would take infinitely many events); those the LCP keeps have their rates set to zero by the projection below
        rates = uni.gap_rates(Xd, Ud)
        candidates = touching & (rates <= max(TOUCH_TOL * uni.velocity_scale(Ud), uni.rest_speed(Ud)))
        release = np.zeros(uni.n_unilateral, bool)
        if kind == "force" and friction_contact is None:
            release[trigger] = True
        # the contacts that may stick: those at rest along the plane after the impact, one whose slip stopped; not one
        # whose stick margin fell through zero. A contact stuck before that the impact set moving is not held: its
        # grip would take the velocity the impact gave it, a friction impulse that coulomb_impact's cone |P_t| <=
        # mu P_n refused (no normal impulse, no friction impulse: a rope jerking a resting mass along the ground)
        may_stick = uni.resting(Ud)
        if friction_contact is not None:
            may_stick[friction_contact] = not stuck_before[friction_contact]
        # every candidate starts taut: where the LCP is degenerate (a force and a gap acceleration both zero, a rope
        # at its length at rest), taut is kept, and a force that then turns negative is a slack event at once
        active, _, _ = uni.select_mode(Xd, Ud, F_input, acc, candidates, start=candidates, release=release,
                                       stuck=may_stick)
        if (kind == "force" and friction_contact is None and active[trigger]
                and not (active != self.mode).any()):
            active[trigger] = False  # its force is at zero to round-off and falling: it leaves
        stuck = stuck_before
        if uni.friction > 0:  # which contacts the ground holds after the impact (coulomb_impact stopped some)
            stuck = uni.choose_stuck(Xd, Ud, active, may_stick, F_input, acc)
        md = uni.mode(active, X, U_after, stuck)
        U_before_grip = U_after
        U_after = md.project_velocities(X, U_after)
        jerked = (took | active) & ~self.mode
        if kind == "anchor":  # a rope already taut that a driven anchor's jump jerks: its impulse is reported too
            jerked |= took
        for u in np.flatnonzero(jerked):
            self.events.append(Event(float(t), "taut" if uni.is_rope[u] else "contact", int(uni.index[u]),
                                     float(impulses[u])))
        for u in np.flatnonzero(self.mode & ~active):
            self.events.append(Event(float(t), "slack" if uni.is_rope[u] else "release", int(uni.index[u]), 0.0))
        if uni.friction > 0:
            on_before, on_after = self.mode[n_ropes:], active[n_ropes:]
            grip = np.linalg.norm(U_after - U_before_grip, axis=1)[uni.contact_masses] / uni._inv_mass3[
                uni.contact_masses, 0]
            for c in np.flatnonzero(on_before & on_after & (md.stuck != stuck_before)):
                self.events.append(Event(float(t), "stick" if md.stuck[c] else "slip", int(uni.contact_masses[c]),
                                         float(np.linalg.norm(tangential[c]) + grip[c]) if md.stuck[c] else 0.0))
        if anchor_rows is None and self.drive is not None:
            anchor_rows = self.drive.rows
        if anchor_rows is not None:  # what the links gave the driven anchors in the impact
            self.event_anchor_impulse = self._event_anchor_impulse(X, U, U_before_grip, U_after, tangential,
                                                                   md.stuck, anchor_rows)
            if kind != "anchor":
                self.drive.advance_impulse = self.drive.advance_impulse + self.event_anchor_impulse
        self._set_mode(active, X, U_after, stuck)
        if uni.friction > 0:
            uni.slip_reference[:] = 0.0  # from the velocities after the event, or the accelerations where at rest
            self._slip_reference(t, X, U_after, F_input)
        return X, U_after

    def _event_anchor_impulse(self, X, U_before, U_impact, U_after, tangential, stuck, rows):
        """(len(rows), 3): what the links gave the driven anchors ``rows`` in an event at X that took the velocities
        from U_before through the impact (U_impact) to the projection onto the next mode (U_after): the impact's
        link impulses, the ground's tangential impulses ``tangential`` (n_contacts, 3: the sliding contacts'
        friction, the stuck ones' grips) taken out of its velocity change, and the projection's, whose mode holds
        the contacts ``stuck`` by their grips (UnilateralDynamics.anchor_impulses)."""
        uni = self.unilateral
        if uni.friction == 0:  # no impulse along the plane: the whole velocity change is the links' and contacts'
            return uni.anchor_impulses(X, U_before, U_after, rows)
        ground = np.zeros_like(U_before)
        np.add.at(ground, uni.contact_masses, tangential)
        return (uni.anchor_impulses(X, U_before, U_impact, rows, ground=ground)
                + uni.anchor_impulses(X, U_impact, U_after, rows, stuck=stuck))

    def _zeno(self, t):
        return SolverError(f"more than {MAX_EVENTS_PER_STEP} rope or ground events within one step at t = {t:g} "
                           "(a chatter of impacts): reduce the step or the tolerance, or the restitution")


class FixedStepEvents(EventHandling):
    """The event-driven variant of a fixed-step method: a step that holds an event is taken to the event, the
    impulse applied and the step finished in the new mode; every other step is the method's."""

    def advance(self, state, t_target, F_input, max_steps):
        self._ensure_mode(state.X, state.U, state.t, F_input)
        super().advance(state, t_target, F_input, max_steps)

    def _advance_steps(self, X, U, n, h, F_input, t=0.0, t_target=None):
        for i in range(n):
            end = t_target if i == n - 1 and t_target is not None else t + (i + 1) * h
            X, U = self._step_with_events(X, U, t + i * h, end, F_input)
        return X, U

    def _plain_step(self, X, U, t0, t1, F_input):
        """The method's step from t0 to t1 (split where its position stage fails), or, for a part of a step shorter
        than SHORT_STEP of dt (the rest of a step after an event just before its end, a step to an event just after
        its start), the second-order Taylor step X + h U + h^2 A / 2, U + h A projected onto the mode: RATTLE's
        velocity takes its position stage's correction over h, whose round-off a very short step would magnify, and
        the Taylor step's own error, h^3 times the jerk, is below round-off there."""
        h = t1 - t0
        if h < SHORT_STEP * self.dt:
            A = self._acceleration_at(t0, X, U, F_input)
            X1, U1 = X + h * U + (0.5 * h * h) * A, U + h * A
            if self.drive is not None:
                X1, U1, _ = self.drive.apply(t1, X1, U1)
            X1, _ = self.dyn.project_positions(X1, tol=1e-14)
            return X1, self.dyn.project_velocities(X1, U1)
        try:
            return self.step(X, U, h, F_input, t0, t1)
        except StepFailure as failure:
            kept = self.stage_midpoints
            if kept is not None:  # a split step keeps no samples of the forces inside it (as the native core)
                kept.clear()
                self.stage_midpoints = None
            try:
                return self._split_step(X, U, h, F_input, t0, t1, failure)
            finally:
                self.stage_midpoints = kept

    def _step_with_events(self, X, U, t0, t1, F_input):
        for _ in range(MAX_EVENTS_PER_STEP):
            self._slip_reference(t0, X, U, F_input)
            self.stage_midpoints = []  # the step's RATTLE stages' midpoints (Rattle.step), for the screen below
            X1, U1 = self._plain_step(X, U, t0, t1, F_input)
            midpoints, self.stage_midpoints = self.stage_midpoints, None

            def step(h, X=X, U=U, t0=t0):
                return self._plain_step(X, U, t0, t0 + h, F_input)
            found = self._first_event(X, U, t0, X1, U1, t1, F_input, step)
            t_to = t1  # the step the event is located in: to the step's end, or to a dip inside it
            if found is None:
                stages = self._midpoint_tensions(t0, t1 - t0, midpoints, F_input)
                inside = self._force_dip_at_stages(X, U, t0, t1 - t0, F_input, stages, step)
                if inside is None:
                    return X1, U1
                found, t_to, X1, U1 = inside  # a force that fell through zero and rose again within the step
            _, kind, u = found
            h_max = t_to - t0
            Xe, Ue, h_e = self._locate(step, X, U, t0, h_max, X1, U1, F_input, found)
            t_e = t_to if h_e >= h_max else t0 + h_e
            X, U = self._apply_event(Xe, Ue, t_e, F_input, kind, u)
            if t_e >= t1:
                return X, U
            t0 = t_e
        raise self._zeno(t0)

    def _midpoint_tensions(self, t0, h, midpoints, F_input):
        """[(c, the mode's tensions)] at the midpoints (t, X, U) of the RATTLE stages of the step of length h from t0,
        c = (t - t0) / h: the fixed-step method's samples of the forces inside its step, which the adaptive methods'
        stages give (_force_dip_at_stages screens both). A RATTLE stage has no state inside it but the middle of its
        drift, X + hs/2 U_half with the half kick's velocity, within O(hs^2) of the motion there (a composition's
        stages lie at their own fractions, the triple jump's at 0.32, 0.5 and 0.68 of the step, some of its stages'
        ends outside the step); plain RATTLE has its midpoint alone, so a dip is seen where the force there is below
        zero. Empty where no unilateral constraint is active (nothing to screen)."""
        if not self.mode.any():
            return []
        out = []
        for t, Xm, Um in midpoints:
            Xd, Ud, acc = self._at(t, Xm, Um)
            out.append(((t - t0) / h, self.dyn.tensions(Xd, Ud, F_input, acc)))
        return out


class AdaptiveEvents(EventHandling):
    """The event-driven variant of an embedded Runge-Kutta method: an accepted step that holds an event ends at it
    (ProjectedRungeKutta.advance asks _event_in_step after every accepted step)."""

    keeps_stage_tensions = True

    def advance(self, state, t_target, F_input, max_steps):
        self._ensure_mode(state.X, state.U, state.t, F_input)
        self._events_this_step = 0
        super().advance(state, t_target, F_input, max_steps)

    def _event_in_step(self, X, U, t, k0, X_new, U_new, t_new, acc_new, F_input):
        stages = self.stage_tensions  # the accepted attempt's (a confirmation step below takes others)

        def step(h):
            return self.step(X, U, h, F_input, t, t + h)
        found = self._first_event(X, U, t, X_new, U_new, t_new, F_input, step)
        if found is None:
            inside = self._force_dip_at_stages(X, U, t, t_new - t, F_input, stages, step)
            if inside is not None:  # a force that fell through zero and rose again within the step
                return self._take_event(step, X, U, t, inside, F_input)
            self._events_this_step = 0
            shorter = self._young_slip_step(X, U, t, k0, X_new, U_new, t_new, F_input, step)
            if shorter is not None:
                X_new, U_new, t_new = shorter
            self._slip_reference(t_new, X_new, U_new, F_input)  # the next step's
            return shorter
        return self._take_event(step, X, U, t, (found, t_new, X_new, U_new), F_input)

    def _take_event(self, step, X, U, t, where, F_input):
        """The step from (X, U) at t ended at the event ``where`` = (found, t1, X1, U1): ``found`` (theta, kind, u)
        as _first_event gives it within the step to (X1, U1) at t1; its impulse applied. Returns (X, U, t)."""
        found, t1, X1, U1 = where
        self._events_this_step += 1
        if self._events_this_step > MAX_EVENTS_PER_STEP:
            raise self._zeno(t)
        _, kind, u = found
        h_max = t1 - t
        Xe, Ue, h_e = self._locate(step, X, U, t, h_max, X1, U1, F_input, found)
        t_e = t1 if h_e >= h_max else t + h_e
        Xe, Ue = self._apply_event(Xe, Ue, t_e, F_input, kind, u)
        return Xe, Ue, t_e

    def _step_cap(self, X, U, acc, T) -> float:
        """The longest step the method may take from (X, U) while contacts slide (acc, T: the mode's accelerations and
        tensions there). A sliding contact's friction -mu N v_t / |v_t| damps its velocity across the slip at the rate
        mu N w / |v_t|, w the inverse mass of the contact along the plane, taken as 1/M_k (the mode's constraints only
        lower it; exact for a mass alone and across a rod's end): a stiff mode where the slip is slow, on which an
        explicit method is stable while h times the rate is within its stability interval on the negative real axis
        (real_stability; a fraction stiff_safety of it). The speed counts from the slowest slip whose direction the
        step resolves: below TOUCH_TOL of the velocity scale the friction keeps the step's reference direction
        (UnilateralDynamics.slip_directions), and below the error control's own scale atol + rtol |U_k| the error a
        wrong direction leaves is within the tolerance. A slip its acceleration does not turn (the sine between its
        velocity and its acceleration along the plane at most straight_slip: in a plane, or turned by round-off) has
        no motion across it to lose, and is spared."""
        dyn = self.dyn
        if not (dyn.sliding.size and self.stiff_safety > 0):
            return math.inf
        uni = self.unilateral
        masses = uni.contact_masses[dyn.sliding]
        N = T[dyn.sliding_rows]
        n = uni.scene.ground.normal
        v = uni.tangential_velocities(U)[dyn.sliding]
        a = acc[masses] - np.outer(acc[masses] @ n, n)
        speed = np.linalg.norm(v, axis=1)
        turning = np.abs(np.cross(v, a) @ n) > self.straight_slip * np.sqrt(speed ** 2 * np.einsum("ij,ij->i", a, a))
        resolved = self.atol + self.rtol * np.linalg.norm(U[masses], axis=1)
        slowest = np.maximum(resolved, TOUCH_TOL * uni.velocity_scale(U))
        rate = (uni.friction * N * uni._inv_mass3[masses, 0] / np.maximum(speed, slowest))[(N > 0) & turning]
        return self.stiff_safety * self.real_stability / float(rate.max()) if rate.size else math.inf

    def _young_slip_step(self, X, U, t, k0, X_new, U_new, t_new, F_input, step):
        """None where the accepted step from (X, U) at t to (X_new, U_new) at t_new stands, else (X, U, t) of a
        shorter step that replaces it. A sliding contact's friction points along its slip velocity, U_t / |U_t|,
        singular at rest: in the first step of a slip from rest the stages' velocities err by more than their own
        size allows, the method loses its order (the step errs as h^3) and its error estimate does not see it
        (the first step is chosen long, the acceleration being smooth). That step is checked against two half
        steps of the method; where they differ beyond the tolerance (the controller's norm) it is replaced by the
        method's step of the length where that error, taken as h^3, meets it. The later steps start from a speed
        that dominates their stages' errors."""
        dyn = self.dyn
        if not dyn.sliding.size:
            return None
        h = t_new - t
        uni = self.unilateral
        speed = np.linalg.norm(uni.tangential_velocities(U)[dyn.sliding], axis=1)
        if not np.any(speed <= TOUCH_TOL * uni.velocity_scale(U)):
            return None
        X_half, U_half = step(0.5 * h)
        X_two, U_two = self.step(X_half, U_half, 0.5 * h, F_input, t + 0.5 * h, t_new)
        free = self.free
        difference = np.concatenate([(X_two - X_new)[free].ravel(), (U_two - U_new)[free].ravel()])
        error = float(np.sqrt(np.mean((difference / self._scale(X, U, X_new, U_new)) ** 2)))
        if error <= 1.0:
            return None
        h_ok = h * max(SAFETY * error ** (-1.0 / 3.0), MIN_FACTOR)
        X_ok, U_ok = step(h_ok)
        return X_ok, U_ok, t + h_ok

def _parabola_vertex(x, y) -> tuple[float, float]:
    """(x, y) of the vertex of the parabola through three points with x[0] < x[1] < x[2] and y[1] the lowest,
    clamped to [x[0], x[2]]."""
    d01, d12 = (y[1] - y[0]) / (x[1] - x[0]), (y[2] - y[1]) / (x[2] - x[1])
    a = (d12 - d01) / (x[2] - x[0])
    if not a > 0.0:
        return float(x[1]), float(y[1])
    b = d01 - a * (x[0] + x[1])
    xv = min(max(-b / (2.0 * a), float(x[0])), float(x[2]))
    return xv, float(y[1] + (xv - x[1]) * (d01 + a * (xv - x[0])))


@functools.lru_cache(maxsize=None)
def event_driven(cls):
    """The event-driven variant of integrator class ``cls`` (same name, order and settings)."""
    base = AdaptiveEvents if cls.adaptive else FixedStepEvents

    def __init__(self, dynamics, *args, **kwargs):
        cls.__init__(self, dynamics, *args, **kwargs)
        self._init_events(dynamics)

    return type(cls.__name__, (base, cls), {"__init__": __init__, "__doc__": cls.__doc__,
                                             "__module__": cls.__module__})
