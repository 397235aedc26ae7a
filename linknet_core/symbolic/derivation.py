"""Symbolic tension system, derived with casadi from the constraint equations.

The derivation follows the seed (../shared/seeds/000_ae42c96e03439fa9.txt) step by step, but lets
casadi's automatic differentiation do the algebra instead of copying the seed's result (25)-(26):

* (11)  phi_l(X) = |X_k2(l) - X_k1(l)|^2 - R_l^2 = 0                      (constraint)
* (12)  dphi_l/dt = (d phi_l / dX) U                                      (``jtimes``)
* (13)  d2phi_l/dt2 = (d phidot_l / dX) U + (d phidot_l / dU) dU/dt       (``jtimes`` twice)
* (9)/(14)  dU_k/dt = (F_k + sum_l' T_l' E_l' (delta_k,k1(l') - delta_k,k2(l'))) / M_k
* (15)  r_l(T) = -d2phi_l/dt2 / (2 R_l) = 0 is linear in T: A = dr/dT, B = -r(T=0).

Anchors (``scene.inv_mass[k] == 0``) carry no 1/M term. A fixed anchor is eliminated: its position
is a constant (its place in the scene), its velocity and acceleration are zero, so it contributes no
symbol. A driven anchor a (``scene.driven[a]``) moves along a prescribed P_a(t) with V_a = dP_a/dt and
A_a = dV_a/dt: it contributes the symbols p (its position), v (its velocity) and a (its acceleration),
and the time derivatives above become total derivatives along both the free masses' motion and the
prescribed one:

* (11)  phi_l(X, P(t)) = |D_l|^2 - R_l^2 with X_a = P_a(t) at a driven end of l,
* (12)  dphi_l/dt = (d phi_l / dX) U + (d phi_l / dP) V                 (``jtimes`` in x and in p)
        = 2 D_l . (U_k2 - U_k1)   with U_a = V_a at a driven end: the *relative* velocity,
* (13)  d2phi_l/dt2 = (d phidot/dX) U + (d phidot/dU) dU/dt + (d phidot/dP) V + (d phidot/dV) A
        = 2 |U_k2 - U_k1|^2 + 2 D_l . (a_k2 - a_k1),
  with a_k = (F_k + sum_l' T_l' E_l' (delta_k,k1(l') - delta_k,k2(l'))) / M_k for a free mass (9) and
  a_a = A_a for a driven anchor (its 1/M = 0: no tension enters it, the motion is imposed),
* (15)  so A (25) keeps its form (links meeting at any anchor, fixed or driven, do not couple: 1/M = 0),
  and B (26) becomes  B_l = |U_k2 - U_k1|^2 / R_l + E_l . (a0_k2 - a0_k1)  with a0_k = F_k / M_k for a
  free mass, A_a for a driven anchor, 0 for a fixed one, and U_a = V_a in the first term.

The same total derivative gives the integrators' targets: RATTLE's position stage solves
phi_l(X(t+h), P(t+h)) = 0 (the anchor already at P_a(t+h)), its velocity stage (12) at t+h with
V_a(t+h). The mass-metric projection of a velocity jump of the anchors onto (12) is
u+ = u - M^-1 G^T lambda with A lambda = G u + G_p v+ (G_p: the Jacobian of (11) in p, scaled like G);
the impulse the links give driven anchor a is the anchor rows of -G_p^T lambda.

The result is a set of casadi Functions of the free masses' coordinates x (velocities u, external
forces f) and the driven anchors' p, v, a (empty without driven anchors):

* ``A(x, p)`` sparse (L x L) with the scene's own sparsity (links sharing a *free* mass),
* ``B(x, u, f, p, v, a)`` (L,),
* ``acc(x, f, T, p)`` the accelerations (9) of the free masses for given tensions,
* ``G(x, p)`` the constraint Jacobian (L x n) of (11) in x, scaled by -1/(2 R_l): row l is +E_l at k1,
  -E_l at k2 (the architecture's C); ``Gp(x, p)`` the same in p (the driven anchors' columns),
* ``A25(x, p)`` the seed's formula (25) written out literally from S(l,l') (21) and M(l,l') (22),
  including its diagonal 1/M_k1 + 1/M_k2 (which equals |E_l|^2 (1/M_k1 + 1/M_k2) only on the manifold).

Coordinates: ``x`` is the row-major flattening of the free masses' reduced positions
``(X[free] - origin) @ basis`` (``p`` the same for the driven anchors, in scene order): all three
coordinates by default (basis = identity), two for a planar scene (basis = two orthonormal vectors of
its plane). Velocities and forces reduce as ``V[free] @ basis``.
The external forces F_k (gravity, constant forces, input forces and every force element kind of
``linknet_core.scene.description.FORCE_KINDS``: drag, quadratic drag, spring-dampers) are also written
symbolically (:meth:`SymbolicTensionSystem.forces_function`, one casadi formula per kind in
``CASADI_ELEMENT_KINDS``), so a generated kernel needs no numeric force evaluation.
"""

from __future__ import annotations

import numpy as np
import casadi as ca

from linknet_core.scene.description import ForceKindMissing, require_force_kinds

__all__ = [
    "SymbolicTensionSystem",
    "sign_pattern",
    "shared_vertex_pairs",
    "CASADI_ELEMENT_KINDS",
]


def shared_vertex_pairs(k1, k2):
    """All ordered pairs (l, l', i, j, k) with l != l' and k_i(l) = k_j(l') = k (19).

    i, j are 1 or 2 as in the seed. Vectorised over masses: for each mass the incident link ends are
    grouped and every ordered pair of distinct ends is emitted.
    """
    k1 = np.asarray(k1, dtype=np.int64)
    k2 = np.asarray(k2, dtype=np.int64)
    L = k1.size
    ends_mass = np.concatenate([k1, k2])              # the mass at each link end
    ends_link = np.concatenate([np.arange(L), np.arange(L)])
    ends_side = np.concatenate([np.ones(L, np.int64), 2 * np.ones(L, np.int64)])
    order = np.argsort(ends_mass, kind="stable")
    m_sorted = ends_mass[order]
    # group boundaries of equal masses
    starts = np.flatnonzero(np.r_[True, m_sorted[1:] != m_sorted[:-1]])
    counts = np.diff(np.r_[starts, m_sorted.size])
    rows, cols, si, sj, ks = [], [], [], [], []
    for c in np.unique(counts):
        if c < 2:
            continue
        groups = starts[counts == c]                  # all masses of degree c at once
        idx = groups[:, None] + np.arange(c)[None, :]  # (g, c) positions in the sorted ends
        a, b = np.meshgrid(np.arange(c), np.arange(c), indexing="ij")
        off = a != b
        ea = order[idx[:, a[off]]]                    # (g, c*(c-1)) end ids
        eb = order[idx[:, b[off]]]
        rows.append(ends_link[ea].ravel())
        cols.append(ends_link[eb].ravel())
        si.append(ends_side[ea].ravel())
        sj.append(ends_side[eb].ravel())
        ks.append(ends_mass[ea].ravel())
    if not rows:
        e = np.zeros(0, np.int64)
        return e, e, e, e, e
    return (np.concatenate(rows), np.concatenate(cols), np.concatenate(si),
            np.concatenate(sj), np.concatenate(ks))


def sign_pattern(k1, k2):
    """S(l, l') of (21) as a dense (L, L) int array, and M-index (22): the shared mass or -1."""
    L = len(k1)
    l, lp, i, j, k = shared_vertex_pairs(k1, k2)
    S = np.zeros((L, L), dtype=np.int64)
    shared = -np.ones((L, L), dtype=np.int64)
    S[l, lp] = (-1) ** (i + j)
    shared[l, lp] = k
    return S, shared


class SymbolicTensionSystem:
    """casadi Functions for the tension system of one scene, derived from (11) by AD.

    Parameters
    ----------
    scene : linknet_core.scene.description.Scene (or anything with K, L, k1, k2, length, inv_mass, X0;
        ``driven`` (K,) bool marks the driven anchors, none when absent)
    basis : (3, d) array with orthonormal columns spanning the coordinates kept; the identity (d = 3)
        in general, two columns for a planar scene (its plane). Reduced coordinates of a point X are
        ``(X - origin) @ basis``.
    origin : (3,) point of the plane (zero in general).
    """

    def __init__(self, scene, basis=None, origin=None):
        self.scene = scene
        self.basis = np.eye(3) if basis is None else np.asarray(basis, dtype=float)
        self.origin = np.zeros(3) if origin is None else np.asarray(origin, dtype=float)
        d = self.dim = self.basis.shape[1]
        K, L = int(scene.K), int(scene.L)
        self.K, self.L = K, L
        k1 = np.asarray(scene.k1, dtype=np.int64)
        k2 = np.asarray(scene.k2, dtype=np.int64)
        R = np.asarray(scene.length, dtype=float)
        inv_mass = np.asarray(scene.inv_mass, dtype=float)
        free = np.flatnonzero(inv_mass > 0)
        driven_mask = getattr(scene, "driven", None)
        driven_mask = np.zeros(K, bool) if driven_mask is None else np.asarray(driven_mask, bool)
        heavy = np.flatnonzero(driven_mask & (inv_mass > 0))
        if heavy.size:
            raise ValueError(f"mass {int(heavy[0]) + 1} is driven but has 1/M > 0: a driven anchor is massless")
        driven = np.flatnonzero(driven_mask)
        self.free = free
        self.fixed = np.flatnonzero(inv_mass == 0)          # every anchor, standing or driven
        self.driven = driven
        self.still = np.flatnonzero((inv_mass == 0) & ~driven_mask)
        nf = self.nf = free.size
        nd = self.nd = driven.size
        self.n = nf * d

        # symbols: free coordinates, free velocities, total external force on free masses, tensions;
        # the driven anchors' prescribed position, velocity and acceleration
        x = ca.SX.sym("x", nf * d)
        u = ca.SX.sym("u", nf * d)
        f = ca.SX.sym("f", nf * d)
        T = ca.SX.sym("T", L)
        p = ca.SX.sym("p", nd * d)
        v = ca.SX.sym("v", nd * d)
        a = ca.SX.sym("a", nd * d)
        self.x_sym, self.u_sym, self.f_sym, self.T_sym = x, u, f, T
        self.p_sym, self.v_sym, self.a_sym = p, v, a

        Pfree = ca.reshape(x, d, nf)                      # column j = position of free mass j
        Vfree = ca.reshape(u, d, nf)
        Ffree = ca.reshape(f, d, nf)
        Pdrv = ca.reshape(p, d, nd)                       # column j = position of driven anchor j
        Vdrv = ca.reshape(v, d, nd)
        # full position matrix (d x K): standing anchors' columns are constants (eliminated masses)
        X0 = (np.asarray(scene.X0, dtype=float) - self.origin) @ self.basis
        col_of = -np.ones(K, dtype=np.int64)
        col_of[free] = np.arange(nf)
        drv_col = -np.ones(K, dtype=np.int64)
        drv_col[driven] = np.arange(nd)
        cols_X = []
        cols_V = []
        for k in range(K):                                 # construction only, not a hot path
            if col_of[k] >= 0:
                cols_X.append(Pfree[:, int(col_of[k])])
                cols_V.append(Vfree[:, int(col_of[k])])
            elif drv_col[k] >= 0:
                cols_X.append(Pdrv[:, int(drv_col[k])])
                cols_V.append(Vdrv[:, int(drv_col[k])])
            else:
                cols_X.append(ca.SX(ca.DM(X0[k])))
                cols_V.append(ca.SX.zeros(d, 1))
        Xfull = ca.horzcat(*cols_X)
        Vfull = ca.horzcat(*cols_V)
        self._Xfull, self._Vfull, self._col_of, self._drv_col = Xfull, Vfull, col_of, drv_col

        # (8) link vectors
        D = Xfull[:, k2.tolist()] - Xfull[:, k1.tolist()]   # d x L
        E = D / ca.repmat(ca.DM(R).T, d, 1)
        # (11)
        phi = (ca.sum1(D * D) - ca.DM(R ** 2).T).T          # L x 1
        # (12): total time derivative, through the free masses (dX/dt = U) and the prescribed motion
        # (dP/dt = V): the relative velocity at a driven end
        phidot = ca.jtimes(phi, x, u) + ca.jtimes(phi, p, v)
        # (9): link forces on the free masses, sum_l T_l E_l (delta_k,k1(l) - delta_k,k2(l))
        inc_rows = np.concatenate([col_of[k1], col_of[k2]])
        inc_cols = np.concatenate([np.arange(L), np.arange(L)])
        inc_vals = np.concatenate([np.ones(L), -np.ones(L)])
        keep = inc_rows >= 0                                # anchored ends drop out: 1/M = 0
        Inc = ca.DM.triplet(inc_rows[keep].tolist(), inc_cols[keep].tolist(),
                            inc_vals[keep].tolist(), nf, L)
        ET = E * ca.repmat(T.T, d, 1)                      # d x L, columns T_l E_l
        link_force = ca.mtimes(ET, Inc.T)                  # d x nf
        invm = ca.DM(inv_mass[free]).T
        acc = (Ffree + link_force) * ca.repmat(invm, d, 1)  # (9), d x nf
        acc_vec = ca.reshape(acc, nf * d, 1)
        # (13): total time derivative of (12) along (10) and (9), and along the prescribed motion
        # (dP/dt = V, dV/dt = A): the driven anchors' acceleration enters B, never A (it holds no T)
        phiddot = (ca.jtimes(phidot, x, u) + ca.jtimes(phidot, u, acc_vec)
                   + ca.jtimes(phidot, p, v) + ca.jtimes(phidot, v, a))
        # (15): multiply by -1/(2 R_l) (the seed's (12)-(13) drop the factor 2 of d|D|^2/dt)
        r = -phiddot / (2.0 * ca.DM(R))
        if not ca.is_linear(r, T):
            raise AssertionError("derived tension equations are not linear in T")
        A = ca.jacobian(r, T)
        B = -ca.substitute(r, T, ca.DM.zeros(L))
        if ca.depends_on(A, T) or ca.depends_on(A, ca.vertcat(u, f, v, a)):
            raise AssertionError("derived tension matrix depends on more than the positions")
        self.A_expr, self.B_expr = A, B
        self.sparsity = A.sparsity()

        # constraint Jacobian C = d(-phi/(2R))/dx: row l = +E_l at k1, -E_l at k2
        G = ca.jacobian(-phi / (2.0 * ca.DM(R)), x)
        Gp = ca.jacobian(-phi / (2.0 * ca.DM(R)), p)        # the same in the driven anchors' positions

        # seed's (25) written out literally from (18), (21), (22)
        l_, lp_, i_, j_, k_ = shared_vertex_pairs(k1, k2)
        sgn = (-1.0) ** (i_ + j_)
        w_off = sgn * inv_mass[k_]                          # S(l,l') / M(l,l')
        nz = w_off != 0                                    # pairs meeting at an anchor vanish
        l_, lp_, w_off = l_[nz], lp_[nz], w_off[nz]
        diag25 = inv_mass[k1] + inv_mass[k2]                # (18)
        EdotE = ca.sum1(E[:, l_.tolist()] * E[:, lp_.tolist()]).T if l_.size else ca.SX(0, 1)
        rows25 = np.r_[np.arange(L), l_]
        cols25 = np.r_[np.arange(L), lp_]
        vals25 = ca.vertcat(ca.SX(ca.DM(diag25)), EdotE * ca.DM(w_off))
        A25 = ca.SX.triplet(rows25.tolist(), cols25.tolist(), vals25, L, L)

        self.A_fn = ca.Function("A_sym", [x, p], [A], ["x", "p"], ["A"])
        self.B_fn = ca.Function("B_sym", [x, u, f, p, v, a], [B], ["x", "u", "f", "p", "v", "a"], ["B"])
        self.acc_fn = ca.Function("acc_sym", [x, f, T, p], [acc_vec], ["x", "f", "T", "p"], ["acc"])
        self.G_fn = ca.Function("G_sym", [x, p], [G], ["x", "p"], ["G"])
        self.Gp_fn = ca.Function("Gp_sym", [x, p], [Gp], ["x", "p"], ["Gp"])
        self.A25_fn = ca.Function("A25_sym", [x, p], [A25], ["x", "p"], ["A25"])
        self.constraint_fn = ca.Function("phi", [x, p], [phi / (2.0 * ca.DM(R))], ["x", "p"], ["g"])
        self.velocity_constraint_fn = ca.Function(
            "phidot", [x, u, p, v], [phidot / (2.0 * ca.DM(R))], ["x", "u", "p", "v"], ["gdot"])
        self._k1, self._k2, self._R, self._inv_mass = k1, k2, R, inv_mass

    # ---- the external forces F_k of (9), symbolically ----
    def forces_function(self, input_masses=None):
        """casadi Function F(x, u, fin, p, v) -> total external force on the free masses (reduced, flat).

        Gravity M_k g, the constant force, the scene's force elements (``scene.force_elements``, each kind by its
        casadi formula in CASADI_ELEMENT_KINDS: a kind without one raises ForceKindMissing here, at derivation
        time; a spring's driven end moves with the anchor's p, v), and an input force for the masses in
        ``input_masses`` only (0-based mass indices, free masses; default all free masses): masses without input
        get no input term at all.
        """
        sc = self.scene
        d, nf, free = self.dim, self.nf, self.free
        x, u = self.x_sym, self.u_sym
        if input_masses is None:
            input_masses = free
        input_masses = np.asarray(input_masses, dtype=np.int64)
        bad = input_masses[self._col_of[input_masses] < 0]
        if bad.size:
            raise ValueError(f"mass {int(bad[0]) + 1} is anchored and cannot take an input force")
        fin = ca.SX.sym("fin", input_masses.size * d)
        P = self.basis
        mass_free = np.asarray(sc.mass, float)[free]
        g = np.asarray(sc.gravity, float) @ P
        const = np.asarray(sc.force, float)[free] @ P                       # (nf, d)
        F = ca.SX(ca.DM((mass_free[:, None] * g[None, :] + const).T))        # d x nf
        elements = sc.force_elements
        for kind in dict.fromkeys(elements.kinds):
            formula = CASADI_ELEMENT_KINDS.get(kind)
            if formula is None:
                raise ForceKindMissing(f"scene {sc.name!r}: the casadi derivation has no formula for force element "
                                       f"kind {kind!r} (CASADI_ELEMENT_KINDS)")
            masses, parameters = elements.of_kind(kind)
            F = F + formula(self, np.asarray(masses, np.int64), np.asarray(parameters, float))
        if input_masses.size:
            sel = ca.DM.triplet(np.arange(input_masses.size).tolist(),
                                self._col_of[input_masses].tolist(),
                                [1.0] * input_masses.size, input_masses.size, nf)
            F = F + ca.mtimes(ca.reshape(fin, d, input_masses.size), sel)
        return ca.Function("forces_sym", [x, u, fin, self.p_sym, self.v_sym], [ca.reshape(F, nf * d, 1)],
                           ["x", "u", "fin", "p", "v"], ["F"])

    def on_masses(self, f, masses):
        """Forces f (d x n), column i acting on mass masses[i], summed onto the free masses (d x nf); columns on
        anchors drop out (no force acts on an anchor)."""
        cols = self._col_of[masses]
        keep = np.flatnonzero(cols >= 0)
        scatter = ca.DM.triplet(keep.tolist(), cols[keep].tolist(), [1.0] * keep.size, len(masses), self.nf)
        return ca.mtimes(f, scatter)

    # ---- conversions between the (K, 3) state arrays and the reduced symbolic coordinates ----
    def reduce(self, Z, origin=False, rows=None):
        """(K, 3) array -> flat vector of the free masses' reduced coordinates (of ``rows`` if given).

        ``origin=True`` for positions (points), False for vectors (velocities, forces).
        """
        Z = np.asarray(Z, dtype=float)[self.free if rows is None else rows]
        if origin:
            Z = Z - self.origin
        return np.ascontiguousarray(Z @ self.basis).ravel()

    def reduce_positions(self, X):
        return self.reduce(X, origin=True)

    def anchor_state(self, X, U=None, anchor_acc=None):
        """The driven anchors' (p, v, a) in reduced coordinates, read from their rows of the (K, 3) arrays
        X, U and anchor_acc (None: at rest / not accelerating)."""
        rows = self.driven
        p = self.reduce(X, origin=True, rows=rows)
        v = np.zeros_like(p) if U is None else self.reduce(U, rows=rows)
        a = np.zeros_like(p) if anchor_acc is None else self.reduce(anchor_acc, rows=rows)
        return p, v, a

    def forces(self, Ffn, X, U, F_input):
        """(K, 3) external forces of the casadi force model ``Ffn`` (:meth:`forces_function`), zero on anchors."""
        p, v, _ = self.anchor_state(X, U)
        return self.expand(np.asarray(Ffn(self.reduce_positions(X), self.reduce(U), self.reduce(F_input),
                                          p, v)).ravel())

    def expand(self, z):
        """flat reduced vector (a vector quantity) -> (K, 3) array, zero on anchored masses."""
        out = np.zeros((self.K, 3), dtype=float)
        out[self.free] = np.asarray(z, float).reshape(self.nf, self.dim) @ self.basis.T
        return out

    def full_positions(self, x, p=None):
        """(K, 3) positions for reduced coordinates x (and driven anchors' p), other anchors at their scene
        place (driven ones too when p is None)."""
        X = np.array(self.scene.X0, dtype=float, copy=True)
        X[self.free] = np.asarray(x, float).reshape(self.nf, self.dim) @ self.basis.T + self.origin
        if p is not None:
            X[self.driven] = np.asarray(p, float).reshape(self.nd, self.dim) @ self.basis.T + self.origin
        return X

    # ---- numeric evaluation of the symbolic functions ----
    # The (K, 3) arrays hold the driven anchors' P_a, V_a in their rows of X, U (and A_a in anchor_acc),
    # as the numeric side's do.
    def A(self, X):
        """symbolic A at positions X (K,3) as scipy.sparse csc."""
        return _dm_to_scipy(self.A_fn(self.reduce_positions(X), self.reduce(X, True, self.driven)))

    def A25(self, X):
        return _dm_to_scipy(self.A25_fn(self.reduce_positions(X), self.reduce(X, True, self.driven)))

    def B(self, X, U, F, anchor_acc=None):
        p, v, a = self.anchor_state(X, U, anchor_acc)
        return np.asarray(self.B_fn(self.reduce_positions(X), self.reduce(U), self.reduce(F), p, v, a)).ravel()

    def G(self, X):
        """constraint Jacobian (L x n) with respect to the reduced free coordinates."""
        return _dm_to_scipy(self.G_fn(self.reduce_positions(X), self.reduce(X, True, self.driven)))

    def Gp(self, X):
        """constraint Jacobian (L x nd*dim) with respect to the driven anchors' reduced positions."""
        return _dm_to_scipy(self.Gp_fn(self.reduce_positions(X), self.reduce(X, True, self.driven)))

    def constraint(self, X):
        """(11) as (|D_l|^2 - R_l^2) / (2 R_l) ~ |D_l| - R_l, per link."""
        return np.asarray(self.constraint_fn(self.reduce_positions(X), self.reduce(X, True, self.driven))).ravel()

    def velocity_constraint(self, X, U):
        """(12) as dphi_l/dt / (2 R_l) = E_l . (U_k2 - U_k1) (relative velocity at driven ends), per link."""
        p, v, _ = self.anchor_state(X, U)
        return np.asarray(self.velocity_constraint_fn(self.reduce_positions(X), self.reduce(U), p, v)).ravel()

    def solve(self, X, U, F, anchor_acc=None, rcond=1e-12):
        """Minimum-norm tensions of the symbolic system and the resulting accelerations (K,3): zero on
        standing anchors, A_a (``anchor_acc``) on driven ones.

        Dense pseudo-inverse: this is the independent reference, not a fast path.
        """
        A = self.A(X).toarray()
        B = self.B(X, U, F, anchor_acc)
        T = np.linalg.lstsq(A, B, rcond=rcond)[0]
        acc = np.asarray(self.acc_fn(self.reduce_positions(X), self.reduce(F), T,
                                     self.reduce(X, True, self.driven))).ravel()
        acc = self.expand(acc)
        if anchor_acc is not None:
            acc[self.driven] = (np.asarray(anchor_acc, float)[self.driven] @ self.basis) @ self.basis.T
        return acc, T


# ---- the casadi formula of every force element kind (linknet_core.scene.description.FORCE_KINDS) ----
# Each takes the system, the kind's rows of scene.force_elements (masses (n, 2), parameters (n, 4)) and returns its
# forces on the free masses (d x nf), written from the kind's definition, not from the numpy reference.

def _drag_sym(sys, masses, parameters):
    """-c U_k on mass k."""
    k = masses[:, 0]
    U = sys._Vfull[:, k.tolist()]
    return sys.on_masses(-U * ca.repmat(ca.DM(parameters[:, 0]).T, sys.dim, 1), k)


def _quadratic_drag_sym(sys, masses, parameters):
    """-c |U_k| U_k on mass k."""
    k = masses[:, 0]
    U = sys._Vfull[:, k.tolist()]
    speed = ca.sqrt(ca.sum1(U * U))                      # 1 x n
    return sys.on_masses(-U * ca.repmat(ca.DM(parameters[:, 0]).T * speed, sys.dim, 1), k)


def _spring_sym(sys, masses, parameters):
    """f = k (d - d0) + c d' along the axis from a to b, +f e on a and -f e on b (pulling the ends together when
    f > 0); an end on a driven anchor moves with its p, v."""
    a, b = masses[:, 0], masses[:, 1]
    D = sys._Xfull[:, b.tolist()] - sys._Xfull[:, a.tolist()]
    V = sys._Vfull[:, b.tolist()] - sys._Vfull[:, a.tolist()]
    dist = ca.sqrt(ca.sum1(D * D))
    e = D / ca.repmat(ca.if_else(dist > 0, dist, 1.0), sys.dim, 1)  # coincident ends: no direction, no force
    rate = ca.sum1(e * V)
    f = ca.DM(parameters[:, 0]).T * (dist - ca.DM(parameters[:, 1]).T) + ca.DM(parameters[:, 2]).T * rate
    fe = e * ca.repmat(f, sys.dim, 1)
    return sys.on_masses(fe, a) - sys.on_masses(fe, b)


CASADI_ELEMENT_KINDS = {
    "drag": _drag_sym,
    "quadratic_drag": _quadratic_drag_sym,
    "spring": _spring_sym,
}
# checked against the table at import (a kind the derivation lacks stops it here), and again per scene at derivation
require_force_kinds(CASADI_ELEMENT_KINDS,
                    "the casadi derivation (linknet_core.symbolic.derivation.CASADI_ELEMENT_KINDS)")


def _dm_to_scipy(M):
    import scipy.sparse as sp
    M = ca.DM(M)
    sp_ = M.sparsity()
    return sp.csc_matrix((np.asarray(M.nonzeros(), float), np.asarray(sp_.row()),
                          np.asarray(sp_.colind())), shape=M.shape)
