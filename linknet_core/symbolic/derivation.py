"""Symbolic tension system, derived with casadi from the constraint equations.

The derivation follows the seed (../shared/seeds/000_ae42c96e03439fa9.txt) step by step, but lets
casadi's automatic differentiation do the algebra instead of copying the seed's result (25)-(26):

* (11)  phi_l(X) = |X_k2(l) - X_k1(l)|^2 - R_l^2 = 0                      (constraint)
* (12)  dphi_l/dt = (d phi_l / dX) U                                      (``jtimes``)
* (13)  d2phi_l/dt2 = (d phidot_l / dX) U + (d phidot_l / dU) dU/dt       (``jtimes`` twice)
* (9)/(14)  dU_k/dt = (F_k + sum_l' T_l' E_l' (delta_k,k1(l') - delta_k,k2(l'))) / M_k
* (15)  r_l(T) = -d2phi_l/dt2 / (2 R_l) = 0 is linear in T: A = dr/dT, B = -r(T=0).

Anchored masses (``scene.inv_mass[k] == 0``) are eliminated symbolically: their positions are
constants (their place in the scene), their velocities and accelerations are zero, so they contribute
no symbol and no 1/M term. The result is a set of casadi Functions of the free masses' coordinates:

* ``A(x)`` sparse (L x L) with the scene's own sparsity (links sharing a *free* mass),
* ``B(x, u, f)`` (L,),
* ``acc(x, f, T)`` the accelerations (9) of the free masses for given tensions,
* ``G(x)`` the constraint Jacobian (L x n) of (11), scaled by -1/(2 R_l): row l is +E_l at k1,
  -E_l at k2 (the architecture's C),
* ``A25(x)`` the seed's formula (25) written out literally from S(l,l') (21) and M(l,l') (22),
  including its diagonal 1/M_k1 + 1/M_k2 (which equals |E_l|^2 (1/M_k1 + 1/M_k2) only on the manifold).

Coordinates: ``x`` is the row-major flattening of the free masses' reduced positions
``(X[free] - origin) @ basis``: all three coordinates by default (basis = identity), two for a planar
scene (basis = two orthonormal vectors of its plane). Velocities and forces reduce as ``V[free] @ basis``.
The external forces F_k (gravity, constant forces, drag, spring-dampers, input forces) are also written
symbolically (:meth:`SymbolicTensionSystem.forces_function`), so a generated kernel needs no numeric
force evaluation.
"""

from __future__ import annotations

import numpy as np
import casadi as ca

__all__ = [
    "SymbolicTensionSystem",
    "sign_pattern",
    "shared_vertex_pairs",
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
    scene : linknet_core.scene.description.Scene (or anything with K, L, k1, k2, length, inv_mass, X0)
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
        self.free = free
        self.fixed = np.flatnonzero(inv_mass == 0)
        nf = self.nf = free.size
        self.n = nf * d

        # symbols: free coordinates, free velocities, total external force on free masses, tensions
        x = ca.SX.sym("x", nf * d)
        u = ca.SX.sym("u", nf * d)
        f = ca.SX.sym("f", nf * d)
        T = ca.SX.sym("T", L)
        self.x_sym, self.u_sym, self.f_sym, self.T_sym = x, u, f, T

        Pfree = ca.reshape(x, d, nf)                      # column j = position of free mass j
        Vfree = ca.reshape(u, d, nf)
        Ffree = ca.reshape(f, d, nf)
        # full position matrix (d x K): anchored columns are constants (eliminated masses)
        X0 = (np.asarray(scene.X0, dtype=float) - self.origin) @ self.basis
        col_of = -np.ones(K, dtype=np.int64)
        col_of[free] = np.arange(nf)
        cols_X = []
        cols_V = []
        for k in range(K):                                 # construction only, not a hot path
            if col_of[k] >= 0:
                cols_X.append(Pfree[:, int(col_of[k])])
                cols_V.append(Vfree[:, int(col_of[k])])
            else:
                cols_X.append(ca.SX(ca.DM(X0[k])))
                cols_V.append(ca.SX.zeros(d, 1))
        Xfull = ca.horzcat(*cols_X)
        Vfull = ca.horzcat(*cols_V)
        self._Xfull, self._Vfull, self._col_of = Xfull, Vfull, col_of

        # (8) link vectors
        D = Xfull[:, k2.tolist()] - Xfull[:, k1.tolist()]   # d x L
        E = D / ca.repmat(ca.DM(R).T, d, 1)
        # (11)
        phi = (ca.sum1(D * D) - ca.DM(R ** 2).T).T          # L x 1
        # (12)
        phidot = ca.jtimes(phi, x, u)
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
        # (13): total time derivative of (12) along (10) and (9)
        phiddot = ca.jtimes(phidot, x, u) + ca.jtimes(phidot, u, acc_vec)
        # (15): multiply by -1/(2 R_l) (the seed's (12)-(13) drop the factor 2 of d|D|^2/dt)
        r = -phiddot / (2.0 * ca.DM(R))
        if not ca.is_linear(r, T):
            raise AssertionError("derived tension equations are not linear in T")
        A = ca.jacobian(r, T)
        B = -ca.substitute(r, T, ca.DM.zeros(L))
        if ca.depends_on(A, T):
            raise AssertionError("derived tension matrix depends on T")
        self.A_expr, self.B_expr = A, B
        self.sparsity = A.sparsity()

        # constraint Jacobian C = d(-phi/(2R))/dx: row l = +E_l at k1, -E_l at k2
        G = ca.jacobian(-phi / (2.0 * ca.DM(R)), x)

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

        self.A_fn = ca.Function("A_sym", [x], [A], ["x"], ["A"])
        self.B_fn = ca.Function("B_sym", [x, u, f], [B], ["x", "u", "f"], ["B"])
        self.acc_fn = ca.Function("acc_sym", [x, f, T], [acc_vec], ["x", "f", "T"], ["acc"])
        self.G_fn = ca.Function("G_sym", [x], [G], ["x"], ["G"])
        self.A25_fn = ca.Function("A25_sym", [x], [A25], ["x"], ["A25"])
        self.constraint_fn = ca.Function("phi", [x], [phi / (2.0 * ca.DM(R))], ["x"], ["g"])
        self.velocity_constraint_fn = ca.Function(
            "phidot", [x, u], [phidot / (2.0 * ca.DM(R))], ["x", "u"], ["gdot"])
        self._k1, self._k2, self._R, self._inv_mass = k1, k2, R, inv_mass

    # ---- the external forces F_k of (9), symbolically ----
    def forces_function(self, input_masses=None):
        """casadi Function F(x, u, fin) -> total external force on the free masses (reduced, flat).

        Gravity M_k g, the constant force, viscous drag -c_k U_k, linear spring-dampers
        f = k (d - d0) + c d' along the spring axis (pulling its ends together when f > 0), and an input
        force for the masses in ``input_masses`` only (0-based mass indices, free masses; default all
        free masses): masses without input get no input term at all.
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
        drag = np.asarray(sc.drag, float)[free]
        if np.any(drag != 0):
            F = F - ca.reshape(u, d, nf) * ca.repmat(ca.DM(drag).T, d, 1)
        springs = sc.springs
        if springs.count:
            a = np.asarray(springs.a, np.int64)
            b = np.asarray(springs.b, np.int64)
            Dsp = self._Xfull[:, b.tolist()] - self._Xfull[:, a.tolist()]
            Vsp = self._Vfull[:, b.tolist()] - self._Vfull[:, a.tolist()]
            dist = ca.sqrt(ca.sum1(Dsp * Dsp))
            # coincident ends: no direction, no force (as the numeric force model does)
            safe = ca.if_else(dist > 0, dist, 1.0)
            e = Dsp / ca.repmat(safe, d, 1)
            rate = ca.sum1(e * Vsp)
            fs = ca.DM(springs.stiffness).T * (dist - ca.DM(springs.rest_length).T) \
                + ca.DM(springs.damping).T * rate
            S = springs.count
            rows = np.concatenate([self._col_of[a], self._col_of[b]])
            cols = np.concatenate([np.arange(S), np.arange(S)])
            vals = np.concatenate([np.ones(S), -np.ones(S)])
            keep = rows >= 0
            Inc = ca.DM.triplet(rows[keep].tolist(), cols[keep].tolist(), vals[keep].tolist(), nf, S)
            F = F + ca.mtimes(e * ca.repmat(fs, d, 1), Inc.T)
        if input_masses.size:
            sel = ca.DM.triplet(np.arange(input_masses.size).tolist(),
                                self._col_of[input_masses].tolist(),
                                [1.0] * input_masses.size, input_masses.size, nf)
            F = F + ca.mtimes(ca.reshape(fin, d, input_masses.size), sel)
        return ca.Function("forces_sym", [x, u, fin], [ca.reshape(F, nf * d, 1)],
                           ["x", "u", "fin"], ["F"])

    # ---- conversions between the (K, 3) state arrays and the reduced symbolic coordinates ----
    def reduce(self, Z, origin=False):
        """(K, 3) array -> flat vector of the free masses' reduced coordinates.

        ``origin=True`` for positions (points), False for vectors (velocities, forces).
        """
        Z = np.asarray(Z, dtype=float)[self.free]
        if origin:
            Z = Z - self.origin
        return np.ascontiguousarray(Z @ self.basis).ravel()

    def reduce_positions(self, X):
        return self.reduce(X, origin=True)

    def expand(self, z):
        """flat reduced vector (a vector quantity) -> (K, 3) array, zero on anchored masses."""
        out = np.zeros((self.K, 3), dtype=float)
        out[self.free] = np.asarray(z, float).reshape(self.nf, self.dim) @ self.basis.T
        return out

    def full_positions(self, x):
        """(K, 3) positions for reduced coordinates x, anchored masses at their scene place."""
        X = np.array(self.scene.X0, dtype=float, copy=True)
        X[self.free] = np.asarray(x, float).reshape(self.nf, self.dim) @ self.basis.T + self.origin
        return X

    # ---- numeric evaluation of the symbolic functions ----
    def A(self, X):
        """symbolic A at positions X (K,3) as scipy.sparse csc."""
        return _dm_to_scipy(self.A_fn(self.reduce_positions(X)))

    def A25(self, X):
        return _dm_to_scipy(self.A25_fn(self.reduce_positions(X)))

    def B(self, X, U, F):
        return np.asarray(self.B_fn(self.reduce_positions(X), self.reduce(U), self.reduce(F))).ravel()

    def G(self, X):
        """constraint Jacobian (L x n) with respect to the reduced free coordinates."""
        return _dm_to_scipy(self.G_fn(self.reduce_positions(X)))

    def solve(self, X, U, F, rcond=1e-12):
        """Minimum-norm tensions of the symbolic system and the resulting accelerations (K,3).

        Dense pseudo-inverse: this is the independent reference, not a fast path.
        """
        A = self.A(X).toarray()
        B = self.B(X, U, F)
        T = np.linalg.lstsq(A, B, rcond=rcond)[0]
        acc = np.asarray(self.acc_fn(self.reduce_positions(X), self.reduce(F), T)).ravel()
        return self.expand(acc), T


def _dm_to_scipy(M):
    import scipy.sparse as sp
    M = ca.DM(M)
    sp_ = M.sparsity()
    return sp.csc_matrix((np.asarray(M.nonzeros(), float), np.asarray(sp_.row()),
                          np.asarray(sp_.colind())), shape=M.shape)
