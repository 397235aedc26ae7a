"""Naive baseline and reference right-hand side: the index-1 formulation without projection.

Written from the seed directly, independently of linknet_core, so that the references it produces are an
independent check of linknet (not linknet checked against itself):
  tensions from (25)-(26)  A T = B,  accelerations from (9),  dX/dt = U (10).
A is assembled entry by entry as in (25): diagonal (1/M_k1 + 1/M_k2) |E_l|^2 and, for links l, l' sharing
the mass k = k_i(l) = k_j(l'), the entry S(l,l') (E_l . E_l') / M(l,l') with S = (-1)^(i+j) (21)-(22).
Off the constraint manifold the diagonal carries |E_l|^2 (= 1 on it): that is what differentiating (11)
twice gives exactly (13). Constraint drift is not corrected: that is what makes it the *naive* baseline.

Where A is singular (redundant links) the minimum-norm tensions are used (the seed (27)-(36) proves any
solution gives the same forces).

Driven anchors (1/M = 0, position prescribed) follow their scene-file motion, written here from the scene format
(docs/scenes.md), not read from linknet: at every evaluation their rows of X and U are P(t) and V(t), and their
acceleration A(t) enters (26) as a_k of that end: B_l = |U_k2 - U_k1|^2 / R_l + E_l . (a_k2 - a_k1).
"""
from __future__ import annotations

import numpy as np
import scipy.linalg as sla
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .scene_spec import SceneSpec

DENSE_MAX_LINKS = 400


def motion_function(spec: dict, origin: np.ndarray):
    """(t, left) -> (P, V, A) of a driven anchor's motion, from the scene format: velocity P = X0 + v t; sine
    P_i = X0_i + a_i (sin(2 pi f_i t + phi_i) - sin(phi_i)); waypoints: the clamped cubic spline through (0, X0)
    and [t, x, y, z] rows, at rest after the last (where A jumps: ``left`` asks for the limit from before it);
    input: at rest (no input is given to a reference)."""
    origin = np.asarray(origin, float)
    kind = spec.get("kind", "input")
    if kind == "velocity":
        v = np.asarray(spec["velocity"], float)
        return lambda t, left=False: (origin + v * t, v.copy(), np.zeros(3))
    if kind == "sine":
        a, w = np.asarray(spec["amplitude"], float), 2.0 * np.pi * np.asarray(spec["frequency"], float)
        phi = np.asarray(spec.get("phase", [0.0, 0.0, 0.0]), float)
        return lambda t, left=False: (origin + a * (np.sin(w * t + phi) - np.sin(phi)),
                                      a * w * np.cos(w * t + phi), -a * w * w * np.sin(w * t + phi))
    if kind == "waypoints":
        from scipy.interpolate import CubicSpline

        rows = np.asarray(spec["waypoints"], float)
        times = np.concatenate([[0.0], rows[:, 0]])
        spline = CubicSpline(times, np.vstack([origin, rows[:, 1:]]), bc_type="clamped")
        last = rows[-1, 1:]

        def at(t, left=False):
            if t > times[-1] or (t == times[-1] and not left):
                return last.copy(), np.zeros(3), np.zeros(3)
            return spline(t), spline(t, 1), spline(t, 2)
        return at
    return lambda t, left=False: (origin.copy(), np.zeros(3), np.zeros(3))


class Index1System:
    def __init__(self, spec: SceneSpec):
        self.spec = spec
        self.K, self.L = spec.K, spec.L
        self.k1, self.k2, self.R = spec.k1, spec.k2, spec.length
        self.invm = spec.inv_mass
        self.g_acc = np.where(spec.fixed[:, None], 0.0, spec.gravity[None, :])  # F_k / M_k for gravity
        self.driven = np.array([k for k, _ in spec.motions], np.int64)
        self.motion = [motion_function(m, spec.X0[k]) for k, m in spec.motions]
        self.dense = self.L <= DENSE_MAX_LINKS
        L, K = self.L, self.K
        # pairs (l, l') of distinct links sharing a mass k, with S(l,l') = (-1)^(i+j)  (19)-(22)
        ends = np.concatenate([self.k1, self.k2])
        link = np.concatenate([np.arange(L), np.arange(L)])
        side = np.concatenate([np.zeros(L, int), np.ones(L, int)])
        order = np.argsort(ends, kind="stable")
        ends, link, side = ends[order], link[order], side[order]
        starts = np.searchsorted(ends, np.arange(K + 1))
        pl, pm, pk, ps = [], [], [], []
        for k in range(K):   # once per scene, not per step
            s, e = starts[k], starts[k + 1]
            if e - s < 2:
                continue
            ll, ss = link[s:e], side[s:e]
            a, b = np.meshgrid(np.arange(e - s), np.arange(e - s), indexing="ij")
            m = a != b
            pl.append(ll[a[m]]); pm.append(ll[b[m]]); pk.append(np.full(m.sum(), k))
            ps.append(np.where(ss[a[m]] == ss[b[m]], 1.0, -1.0))
        cat = (lambda xs, dt: np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt))
        self.pl, self.pm, self.pk = cat(pl, np.int64), cat(pm, np.int64), cat(pk, np.int64)
        self.pcoef = cat(ps, float) * self.invm[self.pk]          # S(l,l') / M(l,l')
        self.dcoef = self.invm[self.k1] + self.invm[self.k2]       # 1/M_k1 + 1/M_k2   (18)
        # incidence D (K x L): link force on mass k is sum_l T_l E_l (delta(k,k1) - delta(k,k2))  (9)
        self.D = sp.csr_matrix((np.concatenate([np.ones(L), -np.ones(L)]),
                                (np.concatenate([self.k1, self.k2]), np.concatenate([np.arange(L)] * 2))),
                               shape=(K, L))
        if not self.dense:
            rows = np.concatenate([np.arange(L), self.pl])
            cols = np.concatenate([np.arange(L), self.pm])
            probe = sp.csc_matrix((np.arange(len(rows), dtype=float) + 1, (rows, cols)), shape=(L, L))
            self._pattern = probe
            self._perm = (probe.data - 1).astype(np.int64)
        self.redundant = self._is_redundant()

    def _assemble(self, E):
        diag = self.dcoef * np.einsum("ij,ij->i", E, E)
        off = self.pcoef * np.einsum("ij,ij->i", E[self.pl], E[self.pm])
        if self.dense:
            A = np.zeros((self.L, self.L))
            A[self.pl, self.pm] = off
            A[np.arange(self.L), np.arange(self.L)] = diag
            return A
        A = self._pattern.copy()
        A.data = np.concatenate([diag, off])[self._perm]
        return A

    def _is_redundant(self) -> bool:
        """Do the links admit a state of self-stress (seed (27)-(36))? Decided on the constraint Jacobian C
        (rows +-E_l over the free masses), which does not involve the masses: a test on A = C M^-1 C^T would
        take a chain with mass ratios 1e-6..1e6 (cond A ~ 1e12, physically ill-conditioned but of full rank)
        for a redundant one and give it truncated least-squares tensions."""
        if self.L == 0:
            return False
        X = self.spec.X0
        E = (X[self.k2] - X[self.k1]) / self.R[:, None]
        free = np.flatnonzero(~self.spec.fixed)
        col = np.full(self.K, -1)
        col[free] = np.arange(len(free))
        rows, cols, vals = [], [], []
        for ends, sign in ((self.k1, 1.0), (self.k2, -1.0)):
            keep = col[ends] >= 0
            for a in range(3):
                rows.append(np.flatnonzero(keep))
                cols.append(3 * col[ends[keep]] + a)
                vals.append(sign * E[keep, a])
        C = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(self.L, 3 * len(free)))
        if self.L > 3 * len(free):
            return True
        if self.dense:
            s = np.linalg.svd(C.toarray(), compute_uv=False)
            return bool(s[-1] <= 1e-10 * s[0])
        try:   # C C^T is the tension matrix of unit masses: singular exactly when C has dependent rows
            spla.splu((C @ C.T).tocsc()).solve(np.ones(self.L))
            return False
        except RuntimeError:
            return True

    def tension_matrix(self, X):
        return self._assemble((X[self.k2] - X[self.k1]) / self.R[:, None])

    def tensions(self, X, U, E=None, known_acc=None):
        """T of (25)-(26); ``known_acc`` (K, 3): F_k/M_k on free masses, A(t) on driven anchors (default: gravity
        on free masses, anchors at rest)."""
        if self.L == 0:
            return np.zeros(0)
        if E is None:
            E = (X[self.k2] - X[self.k1]) / self.R[:, None]
        a = self.g_acc if known_acc is None else known_acc
        dU = U[self.k2] - U[self.k1]
        # (26): B_l = |U_k2 - U_k1|^2 / R_l + E_l . (a_k2 - a_k1), a_k = F_k/M_k, or A(t) on a driven anchor
        B = np.einsum("ij,ij->i", dU, dU) / self.R + np.einsum("ij,ij->i", E, a[self.k2] - a[self.k1])
        A = self._assemble(E)
        if self.redundant:   # minimum-norm T: no rescaling (it would change which solution is minimal)
            if self.dense:
                return np.linalg.lstsq(A, B, rcond=1e-12)[0]
            return spla.lsqr(A, B, atol=1e-15, btol=1e-15, iter_lim=20 * self.L)[0]
        # symmetric diagonal (Jacobi) scaling: mass ratios 1e-6..1e6 give A a condition number ~1e12 that
        # the scaled matrix D A D (unit diagonal) does not have (~2 for a graded chain)
        d = 1.0 / np.sqrt(self.dcoef * np.einsum("ij,ij->i", E, E))
        if self.dense:
            As = A * d[:, None] * d[None, :]
            return d * sla.solve(As, d * B, assume_a="pos", check_finite=False)
        Dm = sp.diags(d)
        return d * spla.spsolve((Dm @ A @ Dm).tocsc(), d * B)

    def accelerations(self, X, U, known_acc=None):
        a = self.g_acc if known_acc is None else known_acc
        E = (X[self.k2] - X[self.k1]) / self.R[:, None]
        T = self.tensions(X, U, E, a)
        return a + self.invm[:, None] * (self.D @ (T[:, None] * E)), T

    def breakpoints(self) -> list:
        """The times where a driven anchor's prescribed acceleration may jump: its waypoints."""
        return sorted({float(row[0]) for _, m in self.spec.motions if m.get("kind") == "waypoints"
                       for row in m["waypoints"]})

    def drive(self, t, X, U, left=False):
        """X, U with the driven anchors' rows at P(t), V(t), and the known accelerations with A(t) on them (at a
        breakpoint, ``left``: the limits from before it)."""
        if not self.driven.size:
            return X, U, self.g_acc
        X, U, a = X.copy(), U.copy(), self.g_acc.copy()
        for k, motion in zip(self.driven, self.motion):
            X[k], U[k], a[k] = motion(t, left)
        return X, U, a

    segment_end = np.inf  # the end of the smooth piece being integrated (solve_index1): its motion seen from before

    def rhs(self, t, y):
        K = self.K
        X, U, a = self.drive(t, y[: 3 * K].reshape(K, 3), y[3 * K:].reshape(K, 3), left=t >= self.segment_end)
        acc, _ = self.accelerations(X, U, a)
        return np.concatenate([U.ravel(), acc.ravel()])

    def y0(self):
        return np.concatenate([self.spec.X0.ravel(), self.spec.U0.ravel()])

    def split(self, y):
        K = self.K
        return y[: 3 * K].reshape(K, 3).copy(), y[3 * K:].reshape(K, 3).copy()
