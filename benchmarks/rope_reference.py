"""Event-driven reference for scenes with ropes, independent of linknet_core.

A rope keeps |X_k2 - X_k1| <= R with a tension T >= 0 (docs/ropes.md states the model). Between events the taut
ropes are rods: the motion is the index-1 formulation of benchmarks.index1 (written from the seed) for the rods and
the taut ropes, integrated by scipy's DOP853, with scipy's event location (root find on the dense output) for

* a slack rope reaching its length: R^2 - |X_k2 - X_k1|^2 falling through 0, an impact;
* a taut rope's tension falling through 0: it goes slack.

Which of the ropes at their length carry tension, and which impulses an impact gives, are linear complementarity
problems; this reference solves them by enumerating the active sets (written here, not linknet's pivoting) and
takes the one that satisfies every condition:

* tensions:  T_i >= 0 on the active ropes, and on the inactive ones at their length the length does not grow,
  d^2|d_i|/dt^2 <= 0 (with d|d_i|/dt = 0);
* impulses (Newton's restitution on the rate of length s = d|d|/dt, M dU = -C^T Lambda):  Lambda_i >= 0 and
  s_i(after) <= -e_i max(s_i(before), 0), with equality where Lambda_i > 0; rods take s(after) = 0.

The reference refuses (ScopeError) what it does not resolve: a ground, driven anchors, an active-set problem with
no or several admissible solutions, more than ``MAX_ENUMERATED`` ropes at their length at once. A rope that stays
slack over a ground has a closed form instead (slack_rope_on_ground: flights, inelastic landings, sliding with
Coulomb friction to rest).
"""
from __future__ import annotations

import itertools
import math
import time
from dataclasses import replace

import numpy as np
from scipy.integrate import solve_ivp

from .index1 import Index1System
from .scene_spec import SceneSpec

MAX_ENUMERATED = 10
MAX_EVENTS = 10_000


class ScopeError(RuntimeError):
    """The scene leaves what this reference resolves (the message says where and why)."""


def _rate(X, U, k1, k2):
    """Unit directions E (X_k2 - X_k1 normalised) and the rates of length s = E . (U_k2 - U_k1)."""
    d = X[k2] - X[k1]
    E = d / np.linalg.norm(d, axis=1)[:, None]
    return E, np.einsum("ij,ij->i", E, U[k2] - U[k1])


class RopeReference:
    """One run of a rope scene from its initial state, event by event."""

    def __init__(self, spec: SceneSpec, rtol: float, atol: float | None = None, time_tol: float = 1e-12):
        if spec.ground is not None:
            raise ScopeError(f"{spec.name}: the rope reference does not model a ground")
        if spec.motions:
            raise ScopeError(f"{spec.name}: the rope reference does not model driven anchors")
        self.spec, self.rtol = spec, rtol
        self.atol = rtol * 1e-3 if atol is None else atol
        self.rods = np.flatnonzero(~spec.rope)
        self.ropes = np.flatnonzero(spec.rope)
        self.invm = spec.inv_mass
        self.touch_tol = 1e3 * rtol          # a rope is at its length within this relative gap
        self.time_tol = time_tol
        self.events: list[tuple[float, str, int, float]] = []   # (t, 'taut' | 'slack', link, impulse)
        self.steps = 0

    # ------------------------------------------------------------------ one mode's system
    def _system(self, links, X):
        """The index-1 system of the rods and the given taut ropes, at the current positions (its redundancy test
        looks at them)."""
        sub = replace(self.spec, X0=X, k1=self.spec.k1[links], k2=self.spec.k2[links], length=self.spec.length[links],
                      rope=np.zeros(len(links), bool), restitution=np.zeros(len(links)), ground=None)
        return Index1System(sub)

    def _mode_links(self, taut):
        return np.sort(np.concatenate([self.rods, self.ropes[taut]])).astype(np.int64)

    def _at_length(self, X):
        d = np.linalg.norm(X[self.spec.k2[self.ropes]] - X[self.spec.k1[self.ropes]], axis=1)
        return d >= self.spec.length[self.ropes] * (1.0 - self.touch_tol)

    # ------------------------------------------------------------------ tensions: which ropes carry force
    def _choose_taut(self, X, U, touching):
        """The active set among the touching ropes (at their length, not separating) that satisfies the tension
        conditions; every subset is tried."""
        cand = np.flatnonzero(touching)
        if len(cand) > MAX_ENUMERATED:
            raise ScopeError(f"{len(cand)} ropes at their length at once (more than {MAX_ENUMERATED})")
        spec = self.spec
        admissible = []
        for size in range(len(cand), -1, -1):
            for subset in itertools.combinations(cand, size):
                taut = np.zeros(len(self.ropes), bool)
                taut[list(subset)] = True
                links = self._mode_links(taut)
                acc, T = self._system(links, X).accelerations(X, U)
                scale = max(1.0, float(np.abs(T).max(initial=0.0)))
                tension = dict(zip(links, T))
                if any(tension[self.ropes[i]] < -1e-9 * scale for i in subset):
                    continue
                ok = True
                for i in set(cand) - set(subset):
                    l = self.ropes[i]
                    k1, k2 = spec.k1[l], spec.k2[l]
                    d, v = X[k2] - X[k1], U[k2] - U[k1]
                    r = np.linalg.norm(d)
                    # d^2|d|/dt^2 at a rate of length 0: (d . a + |v|^2 - s^2) / |d|
                    s = d @ v / r
                    length_acc = (d @ (acc[k2] - acc[k1]) + v @ v - s * s) / r
                    if length_acc > 1e-9 * max(1.0, np.linalg.norm(spec.gravity)):
                        ok = False
                        break
                if ok:
                    admissible.append(taut)
        if len(admissible) != 1:
            raise ScopeError(f"{len(admissible)} admissible sets of taut ropes among {len(cand)} at their length")
        return admissible[0]

    # ------------------------------------------------------------------ impacts
    def _impact(self, X, U, arriving):
        """Velocities after the impact of the rope ``arriving`` (index into self.ropes) with the ropes at their length
        and the rods; returns (U after, {rope index: impulse})."""
        spec = self.spec
        at_length = self._at_length(X)
        at_length[arriving] = True
        k1, k2 = spec.k1, spec.k2
        cand = [i for i in np.flatnonzero(at_length)]
        if len(cand) > MAX_ENUMERATED:
            raise ScopeError(f"{len(cand)} ropes at their length at an impact (more than {MAX_ENUMERATED})")
        links_all = np.concatenate([self.rods, self.ropes[cand]]).astype(np.int64)
        E, s_before = _rate(X, U, k1[links_all], k2[links_all])
        n_rod = len(self.rods)
        e = np.concatenate([np.zeros(n_rod), spec.restitution[self.ropes[cand]]])
        # rates wanted after the impact: rods 0, ropes -e max(s, 0) where they take an impulse
        target = -e * np.maximum(s_before, 0.0)
        target[:n_rod] = 0.0
        # W = C M^-1 C^T for the rows of C: +E at k2, -E at k1 (s = C U)
        inv = self.invm
        c1, c2 = k1[links_all], k2[links_all]
        W = ((inv[c1] + inv[c2])[:, None] * np.eye(len(links_all))) * np.einsum("ij,ij->i", E, E)[:, None]
        for a in range(len(links_all)):
            for b in range(len(links_all)):
                if a == b:
                    continue
                w = 0.0
                for ka, sa in ((c1[a], -1.0), (c2[a], 1.0)):
                    for kb, sb in ((c1[b], -1.0), (c2[b], 1.0)):
                        if ka == kb:
                            w += sa * sb * inv[ka] * (E[a] @ E[b])
                W[a, b] = w
        admissible = []
        rope_rows = np.arange(n_rod, len(links_all))
        for size in range(len(rope_rows), -1, -1):
            for subset in itertools.combinations(rope_rows, size):
                rows = np.concatenate([np.arange(n_rod), np.array(subset, int)]).astype(int)
                Lam = np.zeros(len(links_all))
                if len(rows):
                    # M dU = -C^T Lambda  =>  s_after = s_before - W Lambda
                    Lam[rows] = np.linalg.lstsq(W[np.ix_(rows, rows)], s_before[rows] - target[rows], rcond=1e-12)[0]
                s_after = s_before - W @ Lam
                scale = max(1e-12, float(np.abs(s_before).max()))
                if any(Lam[r] < -1e-9 * scale * max(1.0, W[r, r] ** -1) for r in subset):
                    continue
                free_rows = [r for r in rope_rows if r not in subset]
                if any(s_after[r] > target[r] + 1e-9 * scale for r in free_rows):
                    continue
                admissible.append((Lam, s_after))
        if len(admissible) != 1:
            raise ScopeError(f"{len(admissible)} admissible impulse sets at an impact of {len(cand)} ropes")
        Lam, s_after = admissible[0]
        dU = np.zeros_like(U)
        for j, (a, b) in enumerate(zip(c1, c2)):
            dU[a] += inv[a] * Lam[j] * E[j]
            dU[b] -= inv[b] * Lam[j] * E[j]
        U = U + dU
        impulses = {cand[j - n_rod]: float(Lam[j]) for j in rope_rows}
        return U, impulses, s_after[n_rod:]

    # ------------------------------------------------------------------ the run
    def run(self, t_end: float):
        """The state (X, U) at t_end."""
        return self.run_at([t_end])[0]

    def run_at(self, times):
        """The states (X, U) at each of the increasing ``times``, in one run: the integration stops at each (a mode
        goes on from there), so a state is the same whether it is asked alone or with others, to the tolerance."""
        times = [float(t) for t in times]
        if any(b <= a for a, b in zip(times, times[1:])) or times[0] < 0.0:
            raise ValueError(f"sample times must increase from 0: {times}")
        spec = self.spec
        X, U = spec.X0.astype(float).copy(), spec.U0.astype(float).copy()
        t, states, t_end = 0.0, [], times[-1]
        _, s = _rate(X, U, spec.k1[self.ropes], spec.k2[self.ropes])
        taut = self._choose_taut(X, U, self._at_length(X) & (np.abs(s) <= self.touch_tol * max(1.0, np.abs(U).max())))
        k1, k2, R = spec.k1, spec.k2, spec.length
        while len(states) < len(times):
            if t >= times[len(states)]:   # a sample time at the start, or at an event
                states.append((X.copy(), U.copy()))
                continue
            t_next = times[len(states)]
            if len(self.events) > MAX_EVENTS:
                raise ScopeError(f"more than {MAX_EVENTS} events before t = {t_end}")
            links = self._mode_links(taut)
            system = self._system(links, X)
            where = {l: j for j, l in enumerate(links)}
            K = spec.K
            functions, meaning = [], []
            for i, l in enumerate(self.ropes):
                if taut[i]:
                    def tension(_t, y, j=where[l]):
                        Xy, Uy = y[:3 * K].reshape(K, 3), y[3 * K:].reshape(K, 3)
                        return system.tensions(Xy, Uy)[j]
                    fn = tension
                    meaning.append(("slack", i))
                else:
                    def gap(_t, y, a=k1[l], b=k2[l], r=R[l]):
                        d = y[3 * b:3 * b + 3] - y[3 * a:3 * a + 3]
                        return r * r - d @ d
                    fn = gap
                    meaning.append(("taut", i))
                fn.terminal, fn.direction = True, -1
                functions.append(fn)
            y0 = np.concatenate([X.ravel(), U.ravel()])
            sol = solve_ivp(system.rhs, (t, t_next), y0, method="DOP853", rtol=self.rtol, atol=self.atol,
                            events=functions or None)
            if sol.status == -1:
                raise RuntimeError(f"rope reference for {spec.name} failed at t = {t}: {sol.message}")
            self.steps += len(sol.t) - 1
            fired = [j for j, te in enumerate(sol.t_events or []) if len(te)]
            if sol.status == 0 or not fired:
                X, U = system.split(sol.y[:, -1])
                t = t_next
                states.append((X.copy(), U.copy()))
                continue
            t_ev = min(sol.t_events[j][0] for j in fired)
            first = [j for j in fired if sol.t_events[j][0] <= t_ev + self.time_tol]
            if len(first) > 1:
                raise ScopeError(f"{len(first)} events within {self.time_tol:g} s at t = {t_ev}")
            j = first[0]
            X, U = system.split(sol.y_events[j][0])
            t = t_ev
            kind, i = meaning[j]
            if kind == "slack":
                taut[i] = False
                self.events.append((t, "slack", int(self.ropes[i]), 0.0))
                continue
            U, impulses, s_after = self._impact(X, U, i)
            self.events.append((t, "taut", int(self.ropes[i]), impulses.get(i, 0.0)))
            at = self._at_length(X)
            at[i] = True
            scale = max(1e-12, float(np.abs(s_after).max(initial=0.0)))
            touching = np.zeros(len(self.ropes), bool)
            for n, c in enumerate(sorted(impulses)):
                # a rope left at rate 0 touches; one separating (a rebound) is slack
                touching[c] = at[c] and abs(s_after[n]) <= 1e-9 * scale
            taut = self._choose_taut(X, U, touching)
        return states


def solve_ropes_at(spec: SceneSpec, times, rtol: float, atol: float | None = None):
    """The scene's positions at each of the increasing ``times`` by the event-driven reference, in one run:
    (list of X, the events)."""
    ref = RopeReference(spec, rtol, atol)
    return [X for X, _ in ref.run_at(times)], ref.events


def solve_ropes(spec: SceneSpec, t_end: float, rtol: float, atol: float | None = None):
    """The scene's state at t_end by the event-driven reference: (X, U, seconds, steps, events)."""
    t0 = time.perf_counter()
    ref = RopeReference(spec, rtol, atol)
    X, U = ref.run(t_end)
    return X, U, time.perf_counter() - t0, ref.steps, ref.events



def slack_rope_on_ground(spec: SceneSpec, times, samples: int = 2_001):
    """A scene whose ropes all stay slack, over an inelastic ground (restitution 0) with Coulomb friction mu >= 0,
    in closed form: every free mass flies on its parabola X0 + U0 t + g t^2 / 2 until its height above the plane,
    n . (X - p), reaches 0 (the later root of a quadratic). Landing takes its normal velocity v_n away and, by
    Coulomb's law for a mass alone, up to mu |v_n| of its tangential speed. On the plane it slides: frictionless
    under the tangential part of gravity; with friction (only on a level ground: gravity along -n) decelerating at
    mu |g| along its velocity until it stops, then at rest. Returns (positions at each of the ``times``, each mass's
    landing time: 0 for one lying on the ground at the start, inf for one not landed by the last time, nan for an
    anchor). ScopeError where the scene is another: a rope that reaches its length by the last time (checked at
    ``samples`` instants and at every landing and stop), a ground with restitution, friction on a slope, a mass
    starting below the ground or leaving it."""
    ground = spec.ground
    if ground is None:
        raise ScopeError(f"{spec.name}: no ground")
    if float(ground.get("restitution", 0.0)) != 0.0:
        raise ScopeError(f"{spec.name}: the closed form is for an inelastic ground (restitution 0)")
    if spec.motions:
        raise ScopeError(f"{spec.name}: driven anchors")
    mu = float(ground.get("friction", 0.0))
    p = np.asarray(ground["point"], float)
    n = np.asarray(ground["normal"], float)
    n = n / np.linalg.norm(n)
    g = spec.gravity
    a = float(g @ n)
    g_t = g - a * n
    if a >= 0.0:
        raise ScopeError(f"{spec.name}: gravity not towards the ground")
    if mu > 0.0 and np.linalg.norm(g_t) > 1e-12 * abs(a):
        raise ScopeError(f"{spec.name}: friction on a slope (the closed form takes friction on a level ground)")
    h0, v0 = (spec.X0 - p) @ n, spec.U0 @ n
    free = np.flatnonzero(spec.free)
    if np.any(h0[free] < -1e-12) or np.any((np.abs(h0[free]) <= 1e-12) & (v0[free] > 0.0)):
        raise ScopeError(f"{spec.name}: a mass below the ground, or leaving it at the start")
    landing = np.full(spec.K, np.nan)
    for k in free:   # h0 + v0 t + a t^2 / 2 = 0 with a < 0: the later root
        landing[k] = 0.0 if h0[k] <= 1e-12 else (-v0[k] - math.sqrt(v0[k] ** 2 - 2 * a * h0[k])) / a
    t_last = float(max(times))

    # where each mass lands, its tangential velocity after landing, and when it stops (inf: never)
    X_land, U_t, stop = np.zeros((spec.K, 3)), np.zeros((spec.K, 3)), np.full(spec.K, np.inf)
    for k in free:
        tl = landing[k]
        X_land[k] = spec.X0[k] + spec.U0[k] * tl + 0.5 * g * tl * tl
        X_land[k] -= ((X_land[k] - p) @ n) * n            # on the plane, not a rounding below it
        U = spec.U0[k] + g * tl
        v_n, U_t[k] = U @ n, U - (U @ n) * n
        speed = float(np.linalg.norm(U_t[k]))
        if mu > 0.0 and speed > 0.0:
            U_t[k] *= max(0.0, 1.0 - mu * abs(v_n) / speed)
            stop[k] = tl + float(np.linalg.norm(U_t[k])) / (mu * abs(a))
    speed = np.linalg.norm(U_t, axis=1)
    along = U_t / np.where(speed > 0.0, speed, 1.0)[:, None]

    def positions(t):
        X = spec.X0 + spec.U0 * t + 0.5 * g * t * t
        down = spec.free & (landing <= t)
        tau = (np.minimum(t, stop) - landing)[down, None]
        if mu > 0.0:
            X[down] = X_land[down] + along[down] * (speed[down, None] * tau - 0.5 * mu * abs(a) * tau * tau)
        else:
            X[down] = X_land[down] + U_t[down] * tau + 0.5 * g_t * tau * tau
        X[spec.fixed] = spec.X0[spec.fixed]
        return X

    events = [t for t in np.concatenate([landing[free], stop[free]]) if np.isfinite(t) and t <= t_last]
    for t in np.union1d(np.linspace(0.0, t_last, samples), events):
        X = positions(t)
        r = np.linalg.norm(X[spec.k2[spec.rope]] - X[spec.k1[spec.rope]], axis=1)
        if np.any(r >= spec.length[spec.rope]):
            l = int(np.flatnonzero(spec.rope)[np.argmax(r - spec.length[spec.rope])])
            raise ScopeError(f"{spec.name}: rope {l + 1} reaches its length at t = {t:g} s: its ropes are not slack")
    landing[free[landing[free] > t_last]] = np.inf
    return [positions(float(t)) for t in times], landing


def _first_crossing(coeffs, horizon):
    """The first tau in (0, horizon] where the quartic sum(coeffs[i] tau^(4-i)) (a rope's |d|^2 - R^2) crosses zero
    upwards, or inf: numpy's companion-matrix roots, polished by Newton's steps on the polynomial itself."""
    poly = np.poly1d(coeffs)
    slope = poly.deriv()
    best = math.inf
    for z in np.roots(np.trim_zeros(coeffs, "f")) if np.any(coeffs) else ():
        if abs(z.imag) > 1e-6 * max(1.0, abs(z.real)) or z.real <= 0.0:
            continue
        tau = float(z.real)
        for _ in range(3):
            d = slope(tau)
            if d == 0.0:
                break
            tau -= poly(tau) / d
        if 1e-13 < tau <= horizon and slope(tau) > 0.0:
            best = min(best, tau)
    return best


def rope_dragged_on_ground(spec: SceneSpec, times):
    """A rope lying slack on a level rough ground (Coulomb friction mu > 0, gravity along -n), every mass on the
    plane, dragged by anchors driven at constant velocities in the plane ("velocity" motions), in closed form,
    event by event. Nothing ever leaves the plane: a rope's jerk is along the ground and gives no normal impulse,
    so by Coulomb's law no friction impulse either; between events every mass slides in a straight line,
    decelerating at mu |g| along its velocity, X0 + v t - mu |g| v_hat t^2 / 2, until it stops at |v| / (mu |g|)
    and stays (the slack ropes put no force on it). The events are the stops and the ropes reaching their length:
    the first root of the quartic |d(t)|^2 - R^2 crossing upwards (d = X_k2 - X_k1, quadratic in t between events).
    At a jerk, Newton's restitution e on that rope alone: its rate of length s = E . (U_k2 - U_k1) leaves at -e s,
    the impulse (1 + e) s / (w_k1 + w_k2) along E (w the inverse masses, 0 on an anchor). Returns (positions at each
    of the increasing ``times``, the events [(t, "taut", link, impulse) or (t, "stop", mass, 0)]). ScopeError where
    the scene is another: a rod, a ground with restitution or on a slope or without friction, a mass off the plane
    or a velocity out of it, another motion than a constant velocity, two ropes at their length at one jerk."""
    ground = spec.ground
    if ground is None or float(ground.get("friction", 0.0)) <= 0.0:
        raise ScopeError(f"{spec.name}: the closed form is for a rough ground (friction > 0)")
    if float(ground.get("restitution", 0.0)) != 0.0:
        raise ScopeError(f"{spec.name}: the closed form is for an inelastic ground (restitution 0)")
    if not np.all(spec.rope):
        raise ScopeError(f"{spec.name}: a rod (the closed form takes ropes only)")
    mu = float(ground["friction"])
    p = np.asarray(ground["point"], float)
    n = np.asarray(ground["normal"], float)
    n = n / np.linalg.norm(n)
    g = spec.gravity
    if float(g @ n) >= 0.0 or np.linalg.norm(g - (g @ n) * n) > 1e-12 * np.linalg.norm(g):
        raise ScopeError(f"{spec.name}: gravity not along the ground's normal, towards it")
    decel = mu * float(np.linalg.norm(g))
    X, U = spec.X0.astype(float), spec.U0.astype(float)
    for k, motion in spec.motions:
        if motion.get("kind") != "velocity":
            raise ScopeError(f"{spec.name}: mass {k + 1}'s motion {motion.get('kind')!r} (only 'velocity')")
        U[k] = np.asarray(motion["velocity"], float)
    if np.any(np.abs((X - p) @ n) > 1e-12) or np.any(np.abs(U @ n) > 1e-12):
        raise ScopeError(f"{spec.name}: a mass off the ground's plane or moving out of it")
    A = np.zeros_like(X)          # each mass's acceleration until its next event
    free = spec.free
    inv = spec.inv_mass
    e_rest = spec.restitution
    t, out, events = 0.0, [], []
    for t_sample in times:
        while True:
            speed = np.linalg.norm(U, axis=1)
            sliding = free & (speed > 0.0)
            A[:] = 0.0
            A[sliding] = -decel * U[sliding] / speed[sliding, None]
            stops = np.where(sliding, speed / decel, np.inf)
            to_sample, to_stop = max(t_sample - t, 0.0), float(stops.min())
            D0, DV, DA = (Y[spec.k2] - Y[spec.k1] for Y in (X, U, A))
            quartics = np.stack([np.einsum("ij,ij->i", DA, DA) / 4, np.einsum("ij,ij->i", DV, DA),
                                 np.einsum("ij,ij->i", DV, DV) + np.einsum("ij,ij->i", D0, DA),
                                 2 * np.einsum("ij,ij->i", D0, DV), np.einsum("ij,ij->i", D0, D0) - spec.length ** 2],
                                axis=1)
            to_taut = np.array([_first_crossing(q, min(to_sample, to_stop)) for q in quartics])
            tau = min(to_sample, to_stop, float(to_taut.min()))
            X = X + U * tau + 0.5 * A * tau * tau
            U = U + A * tau
            if tau == to_taut.min():              # a jerk
                t += tau
                l = int(np.argmin(to_taut))
                a, b = spec.k1[l], spec.k2[l]
                E = (X[b] - X[a]) / np.linalg.norm(X[b] - X[a])
                impulse = (1.0 + e_rest[l]) * float(E @ (U[b] - U[a])) / (inv[a] + inv[b])
                U[a] += inv[a] * impulse * E
                U[b] -= inv[b] * impulse * E
                events.append((t, "taut", l, impulse))
                d = X[spec.k2] - X[spec.k1]
                gap = np.linalg.norm(d, axis=1) - spec.length
                rate = np.einsum("ij,ij->i", d, U[spec.k2] - U[spec.k1])
                others = np.flatnonzero((np.abs(gap) < 1e-9 * spec.length) & (rate > 0.0))
                if others.size:
                    raise ScopeError(f"{spec.name}: ropes {l + 1} and {others[0] + 1} at their length at one jerk "
                                     f"(t = {t:.15g} s)")
            elif tau == to_stop:                  # a mass stops
                t += tau
                k = int(np.argmin(stops))
                U[k] = 0.0
                events.append((t, "stop", k, 0.0))
            else:                                 # the sample time
                t = t_sample
                break
            if len(events) > MAX_EVENTS:
                raise ScopeError(f"{spec.name}: more than {MAX_EVENTS} events by t = {t:g} s")
        out.append(X.copy())
    return out, events
