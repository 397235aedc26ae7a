"""``linknet check SCENE``: the solver's numeric tension system against the symbolic derivation.

Every check compares two independent paths: the numeric assembly of the solver (``Dynamics``:
index-array assembly of (25)-(26)) and the casadi derivation of :mod:`linknet_core.symbolic.derivation`, which
differentiates the constraints (11) twice in time by AD (12)-(13) and substitutes (9)/(14). The theory
checks (symmetry, positive semidefiniteness, self-stresses, existence) use the constraint Jacobian G
obtained by AD of (11), never the solver's own matrices, as the reference.

States: ``--samples`` random states on the manifold (positions satisfy (11), obtained by Gauss-Newton
projection of random perturbations of the scene's configuration; velocities satisfy (12), by projection
onto null(G)) and as many off the manifold (positions perturbed by a few per cent of the link lengths,
arbitrary velocities). Random input forces on every free mass.

The numeric side is anything with the ``Dynamics`` methods used here (``forces``, ``tension_matrix``,
``tension_rhs``, ``tensions``, ``accelerations``, ``link_forces``, optionally
``check_consistent_velocities``), so the checker itself can be tested with a deliberately wrong assembly.

A scene with ropes or a ground (``run_unilateral_checks``): the checks above on its taut system (every rope a rod of
the seed, the masses on the ground at the start as links to virtual anchors: the mode the scene runs in with all of
them active, ``taut_mode``), and at the states of a run the complementarity conditions (T >= 0, gap >= 0, T gap = 0;
for the touching ropes and contacts the same at the acceleration level) with the LCP's solution against an
enumeration of the active sets from the seed's (9), (25)-(26) written again here (``_check_unilateral``); with
Coulomb friction, the mode linknet chose against Newton's laws with Coulomb's law, and every Coulomb mode of the
touching ropes and contacts, to tell the user where the rigid problem has several solutions (a WARN) or none (a FAIL):
Painleve's paradoxes (``_Painleve``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from linknet_core.scene.description import FORCE_KINDS
from linknet_core.tolerances import SINGULAR_RCOND
from linknet_core.symbolic.derivation import SymbolicTensionSystem, sign_pattern

__all__ = ["CheckResult", "Sample", "run_checks", "add_arguments", "main", "sample_states", "taut_string_scene",
           "run_unilateral_checks", "taut_mode", "unilateral_states"]

# tolerances, relative to the scale of the compared quantity (round-off is ~1e-16 relative)
RTOL_EXACT = 1e-11       # same formula, different arithmetic order
RTOL_SOLVE = 1e-13       # times cond(A) for solved quantities (tensions, accelerations)
# The rank cut, one for every line: an eigenvalue of A below RTOL_NULL times the largest is a self-stress. It is the
# solver's own definition of singular (structure.SINGULAR_RCOND, which its pivoted Cholesky applies to A's diagonal):
# the minimum-norm tensions (31) depend on where the cut falls, so a reference that cut elsewhere would compare
# another answer (a reference cut at 1e-12 kept an eigenvalue of 1.3e-12 lambda_max on triangulated_net that the
# solver drops, and the tensions differed by their own size).
RTOL_NULL = SINGULAR_RCOND


@dataclass
class CheckResult:
    name: str
    passed: bool
    discrepancy: float           # the largest relative discrepancy found
    tolerance: float
    detail: str = ""
    extra: dict = field(default_factory=dict)
    skipped: bool = False
    # passed, but the user must be told (a state where the physics has more than one answer): printed WARN, and the
    # exit status stays 0
    warning: bool = False

    def line(self) -> str:
        tag = "SKIP" if self.skipped else ("FAIL" if not self.passed else ("WARN" if self.warning else "PASS"))
        return f"{tag}  {self.name:<48s} max discrepancy {self.discrepancy:9.2e} (tol {self.tolerance:.0e})" + \
            (f"\n      {self.detail}" if self.detail else "")


# ------------------------------------------------------------------------------------------------
# sampling
# ------------------------------------------------------------------------------------------------

def _min_norm_solve(G, g):
    """Minimum-norm z with G z = g (least squares where inconsistent), via G G^T: cheap for sparse G.

    A relative 1e-13 ridge keeps redundant (rank-deficient) G usable; the ridge's bias is far below the
    projection tolerance because every step is repeated until the residual vanishes.
    """
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    if G.shape[0] == 0:
        return np.zeros(G.shape[1])
    Gs = sp.csr_matrix(G)
    GG = (Gs @ Gs.T).tocsc()
    ridge = 1e-13 * max(float(GG.diagonal().sum()) / GG.shape[0], 1e-300)
    y = spla.splu((GG + ridge * sp.identity(GG.shape[0], format="csc")).tocsc()).solve(np.asarray(g, float))
    return Gs.T @ y


@dataclass
class Sample:
    """One sampled state: positions, velocities (driven anchors' rows hold P_a, V_a), input forces and the
    driven anchors' accelerations A_a ((K, 3), zero on other rows; None for a scene without driven anchors).
    Unpacks as (X, U, F_input, anchor_acc). ``tau``: the scene time at which the anchors with a scene motion
    were sampled (None without driven anchors); ``moved``: whether the projection onto (11) moved them."""

    X: np.ndarray
    U: np.ndarray
    F_input: np.ndarray
    anchor_acc: np.ndarray | None
    tau: float | None = None
    moved: bool = False

    def __iter__(self):
        return iter((self.X, self.U, self.F_input, self.anchor_acc))


def _project_positions(sym: SymbolicTensionSystem, x, p=None, tol=1e-14, max_iter=50, joint=False):
    """Gauss-Newton onto (11) with backtracking: x <- x + alpha G^+ g. Returns (x, p) or None.

    ``p``: the driven anchors' reduced positions (the scene's when None). They stay where they are
    unless ``joint``: then (x, p) move together (an anchor placed where (11) cannot hold, e.g. a taut
    rope between it and a standing anchor, is moved to the nearest place where it can).
    The backtracking matters near singular configurations (a taut row of a net, a redundant truss),
    where a full minimum-norm step overshoots along the nearly singular direction.
    """
    import scipy.sparse as sp

    R = sym._R
    p = sym.reduce(sym.scene.X0, True, sym.driven) if p is None else np.asarray(p, float)
    n = x.size

    def residual(z):
        g = np.asarray(sym.constraint_fn(z[:n], z[n:])).ravel()   # (|D|^2 - R^2)/(2R) ~ |D| - R
        return g, float(np.max(np.abs(g) / R, initial=0.0))

    z = np.concatenate([x, p])
    g, r = residual(z)
    for _ in range(max_iter):
        if r <= tol:
            return z[:n], z[n:]
        # G = d(-g)/dx, so the Newton step for g(x + dx) = 0 is dx = G^+ g
        X = sym.full_positions(z[:n], z[n:])
        J = sp.hstack([sym.G(X), sym.Gp(X)]) if joint else sym.G(X)
        dz = _min_norm_solve(J, g)
        if not joint:
            dz = np.concatenate([dz, np.zeros(p.size)])
        alpha = 1.0
        while True:
            g_new, r_new = residual(z + alpha * dz)
            if r_new < r or alpha < 1e-3:
                break
            alpha *= 0.5
        z, g, r = z + alpha * dz, g_new, r_new
    return (z[:n], z[n:]) if r <= 1e3 * tol else None


def _null_projector_apply(G, v):
    """v minus its component in range(G^T): the part satisfying G v = 0 (12).

    Dense SVD with a relative cut of 1e-12: near-singular positions (a redundant truss a round-off away
    from its singular configuration) must not keep velocity along their nearly-null rows.
    """
    if G.shape[0] == 0:
        return v
    Gd = G.toarray() if hasattr(G, "toarray") else np.asarray(G)
    _, s, vt = np.linalg.svd(Gd, full_matrices=False)
    rows = vt[s > 1e-12 * (s[0] if s.size else 0.0)]
    v = v - rows.T @ (rows @ v)
    return v - rows.T @ (rows @ v)


def _velocities_on_12(sym, X, u_random, v):
    """Velocities (u, v) satisfying (12) G u + G_p v = 0 at X: u = -G^+ G_p v plus u_random projected onto
    null(G). If the anchors' v admits no such u (a self-stress loads a driven anchor: the motion would
    stretch a rigid path), (u, v) are projected onto (12) together."""
    G = sym.G(X).toarray()
    u = _null_projector_apply(G, u_random)
    if sym.nd == 0:
        return u, v
    Gp = sym.Gp(X).toarray()
    c = Gp @ v
    u_drive = -np.linalg.lstsq(G, c, rcond=1e-12)[0] if G.shape[1] else np.zeros(0)
    if np.abs(G @ u_drive + c).max(initial=0.0) <= 1e-12 * max(np.abs(c).max(initial=0.0), 1e-300):
        return u + u_drive, v
    z = _null_projector_apply(np.hstack([G, Gp]), np.concatenate([u, v]))
    return z[:u.size], z[u.size:]


def _motion_horizon(motion, ell):
    """A scene-time span over which a motion shows its character (random sample times are drawn in it)."""
    spec = motion.spec or {}
    if motion.kind == "waypoints":
        return 1.2 * float(spec["waypoints"][-1][0])
    if motion.kind == "sine":
        f = np.asarray(spec.get("frequency", [0, 0, 0]), float)
        return 1.0 / float(f[f > 0].min()) if np.any(f > 0) else 1.0
    if motion.kind == "velocity":
        speed = float(np.linalg.norm(spec.get("velocity", [0, 0, 0])))
        return ell / speed if speed > 0 else 1.0
    return 1.0


def _anchor_motion_sample(scene, sym, rng, ell, g):
    """The driven anchors' (P, V, A), each (nd, 3), and the scene time tau: the anchors with a scene motion
    where it has them at a random tau (one for all), input-driven ones random (about their scene position,
    speeds of a link length per second, accelerations of the order of g)."""
    nd = sym.nd
    P = np.array(scene.X0, float)[sym.driven]
    V, A = np.zeros((nd, 3)), np.zeros((nd, 3))
    motions = getattr(scene, "motions", ()) or ()
    horizons = [_motion_horizon(m, ell) for m in motions if m.kind != "input"]
    tau = float(rng.uniform(0.0, max(horizons, default=1.0)))
    for j in range(nd):
        motion = motions[j] if j < len(motions) else None
        if motion is not None and motion.kind != "input":
            P[j], V[j], A[j] = motion.evaluate(tau)
        else:
            P[j] = P[j] + 0.3 * ell * rng.standard_normal(3)
            V[j] = ell * rng.standard_normal(3)
            A[j] = g * rng.standard_normal(3)
    # keep the samples in the coordinates of the symbolic system (a planar basis drops the normal part)
    Pb = (P - sym.origin) @ sym.basis
    return Pb, V @ sym.basis, A @ sym.basis, tau


def sample_states(scene, sym: SymbolicTensionSystem, n, rng, on_manifold=True):
    """n :class:`Sample` states; on the manifold (11)-(12) or deliberately off it.

    Driven anchors: P, V, A from their scene motion at a random time (random for input-driven ones);
    the free masses follow the anchors' mean displacement before the projection onto (11).
    """
    R = np.asarray(scene.length, float)
    ell = float(np.median(R)) if R.size else 1.0
    speed = ell  # 1 link length per second
    mass_free = np.asarray(scene.mass, float)[sym.free]
    g = float(np.linalg.norm(scene.gravity)) or 9.81
    x0 = sym.reduce_positions(scene.X0)
    p0 = sym.reduce(scene.X0, True, sym.driven)
    driven = sym.nd > 0

    def anchors():
        if not driven:
            return p0, np.zeros(0), np.zeros(0), None
        P, V, A, tau = _anchor_motion_sample(scene, sym, rng, ell, g)
        return P.ravel(), V.ravel(), A.ravel(), tau

    def anchor_acc(a):
        if not driven:
            return None
        out = np.zeros((sym.K, 3))
        out[sym.driven] = a.reshape(sym.nd, sym.dim) @ sym.basis.T
        return out

    def follow(p):
        """x0 moved by the driven anchors' mean displacement (the network hangs from them)."""
        if not driven or sym.nf == 0:
            return x0
        shift = (p - p0).reshape(sym.nd, sym.dim).mean(axis=0)
        return x0 + np.tile(shift, sym.nf)

    def forces():
        return sym.expand((np.repeat(mass_free, sym.dim) * g) * rng.standard_normal(x0.size))

    out = []
    failures = 0
    while len(out) < n and failures < 2 + n:          # a manifold GN cannot reach: give up early
        sigma = 0.3 * ell / (1 + 3 * failures)               # smaller kicks if projection keeps failing
        p, v, a, tau = anchors()
        x = follow(p) + sigma * rng.standard_normal(x0.size)
        xp = _project_positions(sym, x, p)
        if xp is None and driven:
            xp = _project_positions(sym, x, p, joint=True)
        if xp is None:
            failures += 1
            continue
        moved = not np.array_equal(xp[1], p)
        x, p = xp
        X = sym.full_positions(x, p)
        u, v_12 = _velocities_on_12(sym, X, speed * rng.standard_normal(x0.size), v)
        moved = moved or not np.array_equal(v_12, v)
        U = sym.expand(u)
        if driven:
            U[sym.driven] = v_12.reshape(sym.nd, sym.dim) @ sym.basis.T
        out.append(Sample(X, U, forces(), anchor_acc(a), tau, moved))
    if len(out) < n:
        # the manifold may be (locally) a single point (e.g. a taut string): use the scene's own state
        X = np.array(scene.X0, float)
        while len(out) < n:
            _, v, a, tau = anchors()
            u, v = _velocities_on_12(sym, X, speed * rng.standard_normal(x0.size), 0.0 * v)
            U = sym.expand(u)
            out.append(Sample(X, U, forces(), anchor_acc(a), tau, driven))
    if not on_manifold:
        # off (11)-(12): positions moved by a few per cent of the link lengths, arbitrary velocities
        moved = []
        for s in out:
            x = sym.reduce_positions(s.X) + 0.05 * ell * rng.standard_normal(x0.size)
            p = sym.reduce(s.X, True, sym.driven) + 0.05 * ell * rng.standard_normal(p0.size)
            U = sym.expand(speed * rng.standard_normal(x0.size))
            if driven:
                U[sym.driven] = (speed * rng.standard_normal(p0.size)).reshape(sym.nd, sym.dim) @ sym.basis.T
            moved.append(Sample(sym.full_positions(x, p), U, s.F_input, s.anchor_acc, s.tau, driven))
        out = moved
    return out


# ------------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------------

def _dense(M):
    return M.toarray() if hasattr(M, "toarray") else np.asarray(M, float)


def _takes_anchor_acc(method) -> bool:
    import inspect

    try:
        return "anchor_acc" in inspect.signature(method).parameters
    except (TypeError, ValueError):
        return False


def _numeric_rhs(dyn, X, U, F, anchor_acc=None):
    """B of (26) from the numeric side; with driven anchors through its ``anchor_acc`` (the module function
    ``linknet_core.dynamics.tensions.rhs`` when the numeric object's ``tension_rhs`` takes none)."""
    if anchor_acc is None:
        return np.asarray(dyn.tension_rhs(X, U, F), float)
    if _takes_anchor_acc(dyn.tension_rhs):
        return np.asarray(dyn.tension_rhs(X, U, F, anchor_acc=anchor_acc), float)
    from linknet_core.dynamics.tensions import rhs

    return np.asarray(rhs(dyn.scene, X, U, F, anchor_acc=anchor_acc), float)


def _numeric_tensions(dyn, X, U, F_input, anchor_acc=None):
    if anchor_acc is None:
        return np.asarray(dyn.tensions(X, U, F_input), float)
    return np.asarray(dyn.tensions(X, U, F_input, anchor_acc=anchor_acc), float)


def _numeric_accelerations(dyn, X, U, F_input, anchor_acc=None):
    if anchor_acc is None:
        acc, T = dyn.accelerations(X, U, F_input)
    else:
        acc, T = dyn.accelerations(X, U, F_input, anchor_acc=anchor_acc)
    return np.asarray(acc, float), np.asarray(T, float)


def _rel(diff, scale):
    return float(diff) / max(float(scale), 1e-300)


def _force_scale(sym, X, U, F, anchor_acc=None):
    """Scale of the terms of B (26): |dU|^2/R and E.(F/M) (E.A_a at a driven end)."""
    k1, k2, R, im = sym._k1, sym._k2, sym._R, sym._inv_mass
    dU = U[k2] - U[k1]
    a = F * im[:, None] + (0.0 if anchor_acc is None else anchor_acc)
    return max(float(np.max(np.einsum("ij,ij->i", dU, dU) / R, initial=0.0)),
               float(np.max(np.abs(a[k1]).sum(1) + np.abs(a[k2]).sum(1), initial=0.0)) * float(
                   np.max(np.linalg.norm(X[k2] - X[k1], axis=1) / R, initial=1.0)), 1e-300)


def _nullspace(A, rtol=RTOL_NULL):
    w, V = np.linalg.eigh(A)
    wmax = max(float(np.abs(w).max(initial=0.0)), 1e-300)
    keep = w <= rtol * wmax
    return w, V[:, keep], wmax


def _self_stress_quadratic(sym, X, N):
    """For a (35)-violating velocity: max over self-stresses n and U in null(G) of sum_l n_l |dU_l|^2 / R_l.

    Returns (value, U) with |U| = 1 in the reduced coordinates, or (0, None). At regular points of the
    manifold this vanishes (consistent accelerations exist); at singular points (a taut string) it does not.
    """
    if N.shape[1] == 0:
        return 0.0, None
    G = sym.G(X).toarray()
    _, s, vt = np.linalg.svd(G, full_matrices=True)
    rank = int(np.sum(s > 1e-10 * (s[0] if s.size else 1)))
    Z = vt[rank:].T                                     # basis of null(G): velocities satisfying (12)
    if Z.shape[1] == 0:
        return 0.0, None
    # difference operator D: (L*d) x n, rows U_k2 - U_k1 restricted to free coordinates
    d, L = sym.dim, sym.L
    col = sym._col_of
    rows, cols, vals = [], [], []
    for kk, sign in ((sym._k2, 1.0), (sym._k1, -1.0)):
        keep = np.flatnonzero(col[kk] >= 0)
        rows.append((keep[:, None] * d + np.arange(d)).ravel())
        cols.append((col[kk][keep][:, None] * d + np.arange(d)).ravel())
        vals.append(np.full(keep.size * d, sign))
    import scipy.sparse as sp

    Dm = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))), shape=(L * d, sym.n))
    DZ = Dm @ Z
    best, best_u = 0.0, None
    for i in range(N.shape[1]):
        wgt = np.repeat(N[:, i] / sym._R, d)
        H = DZ.T @ (wgt[:, None] * DZ)
        ev, evec = np.linalg.eigh(H)
        j = int(np.argmax(np.abs(ev)))
        if abs(ev[j]) > best:
            best, best_u = abs(float(ev[j])), Z @ evec[:, j]
    return best, best_u


def taut_string_scene():
    """The case of the seed's acknowledgment: a string fixed at both ends, pulled straight.

    Two links of length 1 between anchors 2 apart: the only position is straight, velocities with the
    middle mass moving sideways satisfy (12) but admit no consistent accelerations (35).
    """
    from linknet_core.scene.description import Scene

    return Scene.from_dict({
        "name": "taut_string",
        "masses": [{"name": "left", "position": [0, 0, 0], "fixed": True},
                   {"name": "middle", "mass": 1.0, "position": [1, 0, 0]},
                   {"name": "right", "position": [2, 0, 0], "fixed": True}],
        "links": [{"a": "left", "b": "middle", "length": 1.0}, {"a": "middle", "b": "right", "length": 1.0}],
    })


def _default_dynamics(scene):
    from linknet_core.dynamics.equations import Dynamics

    return Dynamics(scene)


# ------------------------------------------------------------------------------------------------
# the checks
# ------------------------------------------------------------------------------------------------

def run_checks(scene, samples=5, seed=0, dynamics=None, dynamics_factory=None, sym=None, kernel=False,
               native=True):
    """Run every check on ``scene``; returns a list of :class:`CheckResult`.

    ``dynamics``: the numeric side (default ``Dynamics(scene)``); ``dynamics_factory(scene)`` makes the
    numeric side for the reference taut-string scene of the existence check (default: same class).
    ``kernel``: also compare the generated compiled kernel (codegen) with the numeric path.
    ``native``: with driven anchors, also compare the native core's tensions and reactions (through
    ``Simulator(backend="native")``; skipped with the reason when there is no native core).
    """
    with single_threaded_blas():
        return _run_checks(scene, samples, seed, dynamics, dynamics_factory, sym, kernel, native)


def _run_checks(scene, samples, seed, dynamics, dynamics_factory, sym, kernel, native):
    factory = dynamics_factory or _default_dynamics
    dyn = dynamics if dynamics is not None else factory(scene)
    sym = sym or SymbolicTensionSystem(scene)
    rng = np.random.default_rng(seed)
    on = sample_states(scene, sym, samples, rng, on_manifold=True)
    off = sample_states(scene, sym, samples, rng, on_manifold=False)
    Ffn = sym.forces_function()
    if sym.L == 0:  # no links: nothing but the forces (the accelerations are F/M)
        return [_check_forces(scene, sym, dyn, Ffn, on + off), _check_accelerations(scene, sym, dyn, Ffn, on)]
    results = [
        _check_forces(scene, sym, dyn, Ffn, on + off),
        _check_on_manifold(scene, sym, dyn, on),
        _check_off_manifold(scene, sym, dyn, off),
        _check_symmetry_sign(scene, sym, dyn, on + off),
        _check_gmg_psd(scene, sym, dyn, on + off),
    ]
    null_result, null_info = _check_null_space(scene, sym, dyn, on)
    results.append(null_result)
    results.append(_check_existence(scene, sym, dyn, on, null_info, factory))
    results.append(_check_accelerations(scene, sym, dyn, Ffn, on))
    results.append(_check_interface_jacobian(scene, sym, dyn, Ffn, on, off, seed, native))
    if sym.nd:
        results.append(_check_driven(scene, sym, dyn, Ffn, on, off))
        if any(m.kind != "input" for m in getattr(scene, "motions", ())):
            results.append(_check_motions(scene, sym, rng, samples))
        if native:
            results.append(_check_native(scene, sym, Ffn, on))
        if len(getattr(scene, "input_driven_indices", ())) and sym.L:
            results.append(_check_jump(scene, sym, on, rng))
        if sym.L:
            results.append(_check_rattle_targets(scene, sym, on))
    if kernel:
        results.append(_check_kernel(scene, dyn, on))
    return results


def _check_forces(scene, sym, dyn, Ffn, states):
    worst = 0.0
    for X, U, Fin, _ in states:
        Fn = np.asarray(dyn.forces(X, U, Fin), float)
        Fs = sym.forces(Ffn, X, U, Fin)
        scale = np.abs(Fs).max() + np.abs(Fin).max()
        worst = max(worst, _rel(np.abs(Fn[sym.free] - Fs[sym.free]).max(initial=0.0), scale))
    kinds = ", ".join(kind.name for kind in FORCE_KINDS)
    present = ", ".join(dict.fromkeys(scene.force_elements.kinds)) or "none"
    return CheckResult("external forces F_k of (9) numeric = symbolic", worst <= RTOL_EXACT, worst, RTOL_EXACT,
                       f"gravity, constant forces, inputs and force elements (kinds {kinds}; this scene: {present}) "
                       "on the free masses")


def _check_on_manifold(scene, sym, dyn, states):
    worstA = worstB = 0.0
    for X, U, Fin, Aa in states:
        F = np.asarray(dyn.forces(X, U, Fin), float)
        An = _dense(dyn.tension_matrix(X))
        As = sym.A(X).toarray()
        worstA = max(worstA, _rel(np.abs(An - As).max(initial=0.0), np.abs(As).max(initial=0.0)))
        Bn = _numeric_rhs(dyn, X, U, F, Aa)
        Bs = sym.B(X, U, F, Aa)
        worstB = max(worstB, _rel(np.abs(Bn - Bs).max(initial=0.0), _force_scale(sym, X, U, F, Aa)))
    worst = max(worstA, worstB)
    return CheckResult("A and B numeric = symbolic on the manifold", worst <= RTOL_EXACT, worst, RTOL_EXACT,
                       f"A: {worstA:.2e}, B: {worstB:.2e} relative, over {len(states)} states satisfying (11)-(12)")


def _check_off_manifold(scene, sym, dyn, states):
    """Off (11) the seed's (25) and G M^-1 G^T differ on the diagonal; find which one the solver uses."""
    to_gmg = to_25 = diag_gap = norm_gap = worstB = 0.0
    for X, U, Fin, Aa in states:
        An = _dense(dyn.tension_matrix(X))
        Ag = sym.A(X).toarray()                    # AD of (11)-(13): = G M^-1 G^T at any X
        A25 = sym.A25(X).toarray()                 # literal (25) with diagonal 1/M_k1 + 1/M_k2
        scale = np.abs(Ag).max(initial=0.0)
        to_gmg = max(to_gmg, _rel(np.abs(An - Ag).max(initial=0.0), scale))
        to_25 = max(to_25, _rel(np.abs(An - A25).max(initial=0.0), scale))
        diag_gap = max(diag_gap, _rel(np.abs(np.diag(Ag) - np.diag(A25)).max(initial=0.0), scale))
        E = (X[sym._k2] - X[sym._k1]) / sym._R[:, None]
        norm_gap = max(norm_gap, float(np.abs(np.einsum("ij,ij->i", E, E) - 1).max(initial=0.0)))
        F = np.asarray(dyn.forces(X, U, Fin), float)
        worstB = max(worstB, _rel(np.abs(_numeric_rhs(dyn, X, U, F, Aa) - sym.B(X, U, F, Aa)).max(initial=0.0),
                                  _force_scale(sym, X, U, F, Aa)))
    uses_gmg = to_gmg <= RTOL_EXACT
    uses_25 = to_25 <= RTOL_EXACT
    if uses_gmg:
        which = ("the solver uses G M^-1 G^T (diagonal |E_l|^2 (1/M_k1+1/M_k2)), the documented choice: it is what "
                 "AD of (11)-(13) gives at any X, so the accelerations satisfy the twice-differentiated "
                 "constraint (13) exactly even where the integrator is slightly off (11), and A stays G M^-1 G^T "
                 "(PSD, null space = self-stresses)")
    elif uses_25:
        which = ("the solver uses the seed's (25) diagonal 1/M_k1+1/M_k2 off the manifold, not G M^-1 G^T as the "
                 "architecture prescribes: its accelerations then violate (13) off (11)")
    else:
        which = "the solver's A matches neither G M^-1 G^T nor the seed's (25) off the manifold"
    detail = (f"(25) vs G M^-1 G^T: diagonal differs by up to {diag_gap:.2e} relative (| |E_l|^2 - 1 | up to "
              f"{norm_gap:.2e}); solver vs G M^-1 G^T {to_gmg:.2e}, vs (25) {to_25:.2e}; B vs (26) {worstB:.2e}. "
              + which)
    passed = uses_gmg and worstB <= RTOL_EXACT
    return CheckResult("off the manifold: solver's A is G M^-1 G^T", passed, max(to_gmg, worstB), RTOL_EXACT,
                       detail, {"diag_gap": diag_gap, "uses": "GMG" if uses_gmg else ("25" if uses_25 else "?")})


def _check_symmetry_sign(scene, sym, dyn, states):
    S, shared = sign_pattern(sym._k1, sym._k2)
    sym_S = int(np.abs(S - S.T).max(initial=0))                      # (23)
    sym_M = int(np.abs(shared - shared.T).max(initial=0))            # (24): same shared vertex
    im = sym._inv_mass
    Minv = np.where(shared >= 0, im[np.maximum(shared, 0)], 0.0)     # 1/M(l,l') (22), 0 at anchors
    offdiag = ~np.eye(sym.L, dtype=bool)
    worst_sym = worst_pattern = 0.0
    wrong_signs = 0
    first_wrong = None
    for X, *_ in states:
        An = _dense(dyn.tension_matrix(X))
        scale = max(np.abs(An).max(initial=0.0), 1e-300)
        worst_sym = max(worst_sym, np.abs(An - An.T).max(initial=0.0) / scale)
        E = (X[sym._k2] - X[sym._k1]) / sym._R[:, None]
        EE = E @ E.T
        expected = S * EE * Minv                                       # off-diagonal of (25)
        diff = np.abs(An - expected) * offdiag
        worst_pattern = max(worst_pattern, diff.max(initial=0.0) / scale)
        # sign pattern: sign(A_ll') must be S(l,l') sign(E_l . E_l') wherever that product is clearly non-zero
        clear = offdiag & (np.abs(expected) > 1e-8 * scale)
        bad = clear & (np.sign(An) != np.sign(expected))
        if bad.any():
            wrong_signs += int(bad.sum())
            if first_wrong is None:
                l, lp = np.argwhere(bad)[0]
                first_wrong = (int(l), int(lp), int(S[l, lp]))
    worst = max(worst_sym, worst_pattern)
    passed = worst <= RTOL_EXACT and sym_S == 0 and sym_M == 0 and wrong_signs == 0
    detail = (f"S(l,l')=S(l',l) {'holds' if sym_S == 0 else 'FAILS'}, M(l,l')=M(l',l) "
              f"{'holds' if sym_M == 0 else 'FAILS'}; |A-A^T| {worst_sym:.2e}; off-diagonal vs "
              f"S(l,l') E_l.E_l'/M(l,l') {worst_pattern:.2e}; entries with the wrong sign: {wrong_signs}")
    if first_wrong is not None:
        l, lp, s = first_wrong
        detail += f" (first: {scene.link_label(l)} / {scene.link_label(lp)}, S = {s:+d})" \
            if hasattr(scene, "link_label") else f" (first: links {l + 1}/{lp + 1}, S = {s:+d})"
    return CheckResult("symmetry (23)-(24) and sign pattern S (21)", passed, worst, RTOL_EXACT, detail)


def _check_gmg_psd(scene, sym, dyn, states):
    worst = 0.0
    min_eig = 0.0
    im_red = np.repeat(sym._inv_mass[sym.free], sym.dim)
    for X, *_ in states:
        An = _dense(dyn.tension_matrix(X))
        G = sym.G(X).toarray()                       # AD of (11), not the solver's Jacobian
        GMG = (G * im_red) @ G.T
        scale = max(np.abs(GMG).max(initial=0.0), 1e-300)
        worst = max(worst, np.abs(An - GMG).max(initial=0.0) / scale)
        w = np.linalg.eigvalsh(0.5 * (An + An.T))
        min_eig = min(min_eig, float(w.min(initial=0.0)) / max(float(np.abs(w).max(initial=0.0)), 1e-300))
    psd = min_eig >= -RTOL_EXACT
    passed = worst <= RTOL_EXACT and psd
    return CheckResult("A = G M^-1 G^T and A positive semidefinite", passed, max(worst, -min_eig), RTOL_EXACT,
                       f"|A - G M^-1 G^T| {worst:.2e} relative (G by AD of (11)); smallest eigenvalue / largest "
                       f"{min_eig:.2e}" + ("" if psd else " -> A is NOT positive semidefinite"))


def _weights(sym):
    """1/M of the free coordinates: the W of A = G W G^T."""
    return np.repeat(sym._inv_mass[sym.free], sym.dim)


def _check_null_space(scene, sym, dyn, states):
    """(27) => (31): every null vector of A is a self-stress; forces do not depend on the solution.

    Null vectors are eigenvectors of A with eigenvalue below RTOL_NULL * lambda_max. For such an n,
    (30) reads n^T A n = sum_k |f_k(n)|^2 / M_k with f(n) = G^T n the force of the self-stress on the
    masses; the check measures |W^1/2 G^T n| / sqrt(lambda_max) with G by AD of (11), which (31) says is
    zero and which is at most sqrt(RTOL_NULL) at a sampled state that is singular only to within the
    projection's round-off (redundant links make (11) overdetermined: a Gauss-Newton projection leaves
    positions ~sqrt(eps) off the exactly singular configuration).
    """
    tol = np.sqrt(RTOL_NULL)
    worst31 = worst_force = worst_minnorm = 0.0
    max_force_abs = 0.0
    dims = []
    info = []
    W = _weights(sym)
    for X, U, Fin, Aa in states:
        An = _dense(dyn.tension_matrix(X))
        w, N, wmax = _nullspace(0.5 * (An + An.T))
        ws = np.linalg.eigvalsh(sym.A(X).toarray())
        dims.append((N.shape[1], int(np.sum(ws <= RTOL_NULL * max(ws.max(initial=0.0), 1e-300)))))
        info.append((N, wmax))
        if N.shape[1] == 0:
            continue
        G = sym.G(X).toarray()
        f_null = G.T @ N                                   # force of each self-stress on the free masses
        worst31 = max(worst31, float(np.sqrt((W[:, None] * f_null ** 2).sum(0)).max() / np.sqrt(wmax)))
        max_force_abs = max(max_force_abs, float(np.abs(f_null).max()))
        T1 = _numeric_tensions(dyn, X, U, Fin, Aa)
        c = np.cos(np.arange(1, N.shape[1] + 1) * 1.7) * (1 + np.abs(T1).max())   # some other solution
        T2 = T1 + N @ c
        df = (np.asarray(dyn.link_forces(X, T2)) - np.asarray(dyn.link_forces(X, T1)))[sym.free].ravel()
        # in the reduced coordinates: df_j . basis, weighted by 1/M
        df_r = (df.reshape(-1, 3) @ sym.basis).ravel()
        worst_force = max(worst_force, float(np.sqrt((W * df_r ** 2).sum()) / (np.sqrt(wmax) * np.linalg.norm(c))))
        # minimum norm: no component on the null vectors every rank rule drops (below the band of _RankCut, where
        # the solver's pivoted Cholesky may keep what the eigenvalue cut drops), up to the lean of the solver's null
        # space on them: |S| / gap (Davis-Kahan; S the Schur complement it drops, below dim N times its cut; the
        # gap at least the smallest eigenvalue it may keep)
        cut = _RankCut.of(An)
        dropped = cut.w < cut.band[0]
        gap = float(cut.w[~dropped].min(initial=wmax))
        lean = N.shape[1] * RTOL_NULL * float(An.diagonal().max()) / max(gap, 1e-300)
        component = float(np.abs(cut.V[:, dropped].T @ T1).max(initial=0.0) / max(np.abs(T1).max(), 1e-300))
        worst_minnorm = max(worst_minnorm, component / (1e-6 + lean))
    dims_ok = all(a == b for a, b in dims)
    nullity = sorted({a for a, _ in dims})
    if max(nullity, default=0) == 0:
        detail = "A is regular at every sampled state: no self-stress, tensions unique"
    else:
        detail = (f"dim null(A) {nullity} equals that of G M^-1 G^T (AD): {'yes' if dims_ok else 'NO'}; (31) "
                  f"|M^-1/2 G^T n|/sqrt(lambda_max) {worst31:.2e} (largest force of a unit self-stress "
                  f"{max_force_abs:.1e} N); link forces for T and T + self-stresses differ by {worst_force:.2e} "
                  f"(same scale); the solver's T has a self-stress component {worst_minnorm:.2e} of what it may "
                  "have (minimum norm: 1e-6 plus the lean of its pivoted Cholesky's null space on the null vectors "
                  "every rank rule drops, dim N RTOL_NULL max(diag A) / the smallest eigenvalue it may keep)")
    worst = max(worst31, worst_force)
    passed = dims_ok and worst <= tol and worst_minnorm <= 1.0
    return CheckResult("null(A) = self-stresses (31), forces unique", passed, worst, tol, detail), info


def _violating_velocity(sym, X, N):
    """A unit velocity satisfying (12) at X for which (35) has no solution, or None."""
    q, u_bad = _self_stress_quadratic(sym, X, N)
    if u_bad is None or q <= 1e-8 / sym._R.min():
        return None
    return sym.expand(u_bad)


def _check_existence(scene, sym, dyn, states, nulls, factory):
    """(32)-(36): B is orthogonal to null(A) when (35) can hold; a (35)-violating state is reported.

    B = w + b_F + b_A with w_l = |dU_l|^2 / R_l (relative velocity at a driven end),
    b_F = E_l.(F_k2/M_k2 - F_k1/M_k1) and b_A = E_l.(A_k2 - A_k1) over driven ends. (33): N^T b_F = 0 for
    any forces. (34)-(36): N^T (w + b_A) = 0 exactly when consistent accelerations (35) exist. Without
    driven anchors b_A = 0. With them, a self-stress that loads a driven anchor (a rigid path from it to
    another anchor) makes N^T b_A = 0 a condition on the prescribed motion: an anchor accelerating along
    such a path would have to stretch it.
    """
    tol_F = np.sqrt(RTOL_NULL)
    worst_F = worst_consistent = 0.0
    n_with_null = n_consistent = n_inconsistent = n_accepted = n_motion = 0
    W = _weights(sym)
    for (X, U, Fin, Aa), (N, wmax) in zip(states, nulls):
        if N.shape[1] == 0:
            continue
        n_with_null += 1
        F = np.asarray(dyn.forces(X, U, Fin), float)
        B = _numeric_rhs(dyn, X, U, F, Aa)
        dU = U[sym._k2] - U[sym._k1]
        w = np.einsum("ij,ij->i", dU, dU) / sym._R
        bA = np.zeros(sym.L)
        if Aa is not None:
            E = (X[sym._k2] - X[sym._k1]) / sym._R[:, None]
            bA = np.einsum("ij,ij->i", E, Aa[sym._k2] - Aa[sym._k1])
        bF = B - w - bA
        Fr = sym.reduce(F)
        worst_F = max(worst_F, float(np.abs(N.T @ bF).max() / max(np.sqrt(wmax * (W * Fr ** 2).sum()), 1e-300)))
        # relative to |w|, or to the sampler's velocity scale (1 link length per second) where the
        # velocities are round-off (a rigid anchored scene: null(G) = {0})
        w_ref = float(np.median(sym._R))
        r_w = float(np.abs(N.T @ w).max() / max(np.abs(w).max(initial=0.0), w_ref))
        r_A = float(np.abs(N.T @ bA).max() / max(np.abs(bA).max(initial=0.0), 1e-300)) if bA.any() else 0.0
        # (35) holds to within what a state sqrt(RTOL_NULL) from the singular configuration allows (as (33))
        if r_w <= tol_F and r_A > 1e-6:
            n_motion += 1              # velocities fine, the prescribed anchor accelerations load a self-stress
        elif r_w <= tol_F:
            n_consistent += 1
            worst_consistent = max(worst_consistent, float(np.abs(N.T @ B).max() / max(np.abs(B).max(), 1e-300)))
        else:
            n_inconsistent += 1
            if hasattr(dyn, "check_consistent_velocities"):
                from linknet_core.errors import ConsistencyError

                try:
                    dyn.check_consistent_velocities(X, U)
                    n_accepted += 1
                except ConsistencyError:
                    pass
    # a state that violates (35): at the scene's own (exact) configuration if it admits one
    X0 = np.array(scene.X0, float)
    A0 = _dense(dyn.tension_matrix(X0))
    _, N0, _ = _nullspace(0.5 * (A0 + A0.T))
    U_bad = _violating_velocity(sym, X0, N0)
    if U_bad is not None:
        vscene, vdyn, vsym, Xv, Uv = scene, dyn, sym, X0, U_bad
        where = f"{getattr(scene, 'name', 'this scene')} at its initial positions"
    else:
        vscene = taut_string_scene()
        vdyn = factory(vscene)
        vsym = SymbolicTensionSystem(vscene)
        Xv = np.array(vscene.X0, float)
        Uv = np.zeros_like(Xv)
        Uv[1] = [0.0, 1.0, 0.0]                        # sideways: satisfies (12), violates (35)
        where = "the reference taut string (this scene's initial positions admit no (35)-violating velocity)"
    Av = _dense(vdyn.tension_matrix(Xv))
    _, Nv, _ = _nullspace(0.5 * (Av + Av.T))
    Bv = np.asarray(vdyn.tension_rhs(Xv, Uv, np.asarray(vdyn.forces(Xv, Uv, np.zeros_like(Xv)), float)), float)
    v12 = float(np.abs(vsym.velocity_constraint(Xv, Uv)).max(initial=0.0))
    violation = float(np.abs(Nv.T @ Bv).max(initial=0.0) / max(np.abs(Bv).max(initial=0.0), 1e-300))
    detected = violation > 1e-6 and v12 <= 1e-12
    refused = None
    if hasattr(vdyn, "check_consistent_velocities"):
        from linknet_core.errors import ConsistencyError

        try:
            vdyn.check_consistent_velocities(Xv, Uv)
            refused = False
        except ConsistencyError:
            refused = True
    passed = worst_F <= tol_F and worst_consistent <= tol_F and detected and refused is not False
    detail = (f"{n_with_null} sampled state(s) with self-stress: (33) N^T b_F {worst_F:.2e} (scaled); (35) holds at "
              f"{n_consistent}, and there |N^T B|/|B| = {worst_consistent:.2e}; (35) fails at {n_inconsistent} "
              f"(velocities in null(G) at singular positions"
              + (f"; the solver's check_consistent_velocities accepts {n_accepted} of them: its singularity cut "
                 "differs from this check's" if n_accepted else "")
              + (f"; at {n_motion} more the driven anchors' accelerations load a self-stress (N^T b_A != 0: "
                 "the prescribed motion would stretch a rigid path)" if n_motion else "")
              + f"). Violating state on {where}: (12) residual "
              f"{v12:.1e}, |N^T B|/|B| = {violation:.2e} -> (35) violation {'REPORTED' if detected else 'NOT detected'}")
    if refused is not None:
        detail += ("; the solver refuses it with ConsistencyError" if refused else
                   "; the solver's check_consistent_velocities ACCEPTS it")
    motion = _motion_violation(sym, dyn, X0, N0)
    if motion is not None:
        motion_detected, motion_refused, text = motion
        passed = passed and motion_detected and motion_refused is not False
        detail += text
    return CheckResult("existence (32)-(36) and hypothesis (35)", passed, max(worst_F, worst_consistent), tol_F,
                       detail)


def _motion_violation(sym, dyn, X0, N0):
    """A prescribed motion that (35) forbids, at the scene's initial positions: a self-stress n that loads a
    driven anchor (G_p^T n != 0) and the anchors at rest accelerating with A = -G_p^T n, so that
    N^T b_A = |G_p^T n|^2 > 0 (b_A = -G_p A: the anchors' part of B (26)). None without such a self-stress.
    Returns (reported, refused (None: the numeric side has no such check), text)."""
    if sym.nd == 0 or N0.shape[1] == 0:
        return None
    Gp = sym.Gp(X0).toarray()
    loads = Gp.T @ N0                                   # each self-stress's force on the driven anchors
    j = int(np.argmax(np.linalg.norm(loads, axis=0)))
    if np.linalg.norm(loads[:, j]) <= 1e-8 * max(np.abs(N0[:, j]).max(), 1e-300):
        return None
    anchor_acc = np.zeros((sym.K, 3))
    anchor_acc[sym.driven] = (-loads[:, j]).reshape(sym.nd, sym.dim) @ sym.basis.T
    U0 = np.zeros((sym.K, 3))
    F = np.zeros((sym.K, 3))
    B = _numeric_rhs(dyn, X0, U0, F, anchor_acc)
    violation = float(np.abs(N0.T @ B).max(initial=0.0) / max(np.abs(B).max(initial=0.0), 1e-300))
    reported = violation > 1e-6
    refused = None
    check = getattr(dyn, "check_consistent_velocities", None)
    if check is not None and _takes_anchor_acc(check):
        from linknet_core.errors import ConsistencyError

        try:
            check(X0, U0, anchor_acc=anchor_acc)
            refused = False
        except ConsistencyError:
            refused = True
    text = (f". Driven anchors at rest at the initial positions, accelerating against a self-stress that loads "
            f"them (A = -G_p^T n): |N^T B|/|B| = {violation:.2e} -> (35) violation by the prescribed motion "
            f"{'REPORTED' if reported else 'NOT detected'}")
    if refused is not None:
        text += ("; the solver refuses it with ConsistencyError" if refused else
                 "; the solver's check_consistent_velocities ACCEPTS it")
    return reported, refused, text


@dataclass
class _RankCut:
    """Where the rank cut RTOL_NULL falls in the spectrum of a symmetric positive semidefinite A.

    The reference cuts the eigenvalues at ``RTOL_NULL * lambda_max``; the solver's pivoted Cholesky stops at a pivot
    below ``RTOL_NULL * max(diag A)`` (LAPACK dpstrf), which by Weyl's inequality has dropped only eigenvalues up to
    (L - rank) times that, and whose kept pivots exceed the kept eigenvalues by small factors in practice (a factor 10
    is allowed here). Eigenvalues in ``band`` may thus be kept by one rule and dropped by the other: there the
    minimum-norm tensions are not one answer, and only their part on the eigenvectors above the band (``firm``),
    which every such rule keeps, is compared."""

    w: np.ndarray                # eigenvalues, ascending
    V: np.ndarray                # eigenvectors (columns)
    kept: np.ndarray             # w above the reference's cut
    firm: np.ndarray             # w above the band
    band: tuple[float, float]

    @classmethod
    def of(cls, A):
        A = 0.5 * (A + A.T)
        w, V = np.linalg.eigh(A)
        wmax = max(float(w.max(initial=0.0)), 1e-300)
        diag = max(float(A.diagonal().max(initial=0.0)), 1e-300)
        band = (RTOL_NULL * diag / 10.0, max(A.shape[0], 1) * RTOL_NULL * diag)
        return cls(w, V, w > RTOL_NULL * wmax, w > band[1], band)

    @property
    def ambiguous(self) -> bool:
        return bool(np.any((self.w >= self.band[0]) & (self.w <= self.band[1])))

    def condition(self, part=None) -> float:
        """cond(A) on the kept eigenvectors (or those of ``part``): the scale of a solved quantity's error."""
        w = self.w[self.kept if part is None else part]
        return float(w.max() / w.min()) if w.size else 1.0


def _check_accelerations(scene, sym, dyn, Ffn, states):
    """The solver's accelerations (9) and minimum-norm tensions (31) against the AD system solved by a dense
    pseudo-inverse cut at RTOL_NULL; differences divided by cond(A) on its range. Where an eigenvalue of A lies
    where the solver's and the reference's rank rules may differ (:class:`_RankCut`), the tensions are compared on
    the eigenvectors above it, and the accelerations not at all (a direction kept by one side gives it forces that
    the other has not)."""
    worst_acc = worst_T = 0.0
    worst_cond = 1.0
    ambiguous = []
    for X, U, Fin, Aa in states:
        acc_n, T_n = _numeric_accelerations(dyn, X, U, Fin, Aa)
        Fs = sym.forces(Ffn, X, U, Fin)
        acc_s, T_s = sym.solve(X, U, Fs, Aa, rcond=RTOL_NULL)
        cut = _RankCut.of(sym.A(X).toarray())
        T_n = np.asarray(T_n, float)
        if cut.ambiguous:
            firm = cut.V[:, cut.firm]
            ambiguous.append(cut)
            cond = cut.condition(cut.firm)
            worst_cond = max(worst_cond, cond)
            worst_T = max(worst_T, _rel(np.abs(firm.T @ (T_n - T_s)).max(initial=0.0),
                                        np.abs(firm.T @ T_s).max(initial=0.0)) / cond)
            continue
        cond = cut.condition()
        worst_cond = max(worst_cond, cond)
        scale = max(np.abs(acc_s).max(initial=0.0), np.abs(Fs * sym._inv_mass[:, None]).max(initial=0.0), 1e-300)
        worst_acc = max(worst_acc, np.abs(acc_n[sym.free] - acc_s[sym.free]).max(initial=0.0) / scale / cond)
        # anchors: standing ones do not accelerate, driven ones exactly as prescribed
        anchored = np.abs(acc_n[sym.still]).max(initial=0.0)
        if Aa is not None:
            anchored = max(anchored, np.abs(acc_n[sym.driven] - Aa[sym.driven]).max(initial=0.0))
        worst_acc = max(worst_acc, anchored / scale)
        worst_T = max(worst_T, _rel(np.abs(T_n - T_s).max(initial=0.0), np.abs(T_s).max(initial=0.0)) / cond)
    worst = max(worst_acc, worst_T)
    detail = (f"differences divided by cond(A) (up to {worst_cond:.1e}): accelerations {worst_acc:.2e}, "
              f"minimum-norm tensions {worst_T:.2e}; symbolic side: AD system, dense pseudo-inverse cut at "
              f"{RTOL_NULL:.0e} lambda_max (the solver's rank cut)")
    if ambiguous:
        detail += (f"; {len(ambiguous)} of {len(states)} state(s) with an eigenvalue of A between "
                   f"{min(c.band[0] / c.w.max() for c in ambiguous):.1e} and "
                   f"{max(c.band[1] / c.w.max() for c in ambiguous):.1e} lambda_max, where the solver's pivoted "
                   "Cholesky and an eigenvalue cut may rank it differently: tensions compared on the eigenvectors "
                   "above it only")
    return CheckResult("accelerations (9) and tensions: solver = symbolic", worst <= RTOL_SOLVE * 1e2, worst,
                       RTOL_SOLVE * 1e2, detail)


def _interface_ad(sym, Ffn, X, U, Fin, Aa, cut, seeds):
    """AD of the outputs' derivatives along ``seeds`` (columns over the input forces on the free masses and the
    driven anchors' p, v, a, in reduced coordinates) at one state: T, the accelerations (9) of the free masses and
    G_p^T T (the links' force on the driven anchors), as casadi expressions of those inputs, differentiated forward
    by casadi at the state (x, u fixed). Rows T, acc, reactions.

    The minimum-norm tensions are written without a pseudo-inverse: with V_r, Lambda_r the eigenvectors and
    eigenvalues of A that the rank cut keeps at the state (numbers, ``cut``), Q(p) = A(p) V_r Lambda_r^-1 spans
    range(A(p)) wherever the rank of A stays r (its r columns lie in it and are independent near the state; at the
    state Q = V_r), and T = Q (Q^T A Q)^-1 Q^T B is then A^+ B (T lies in range(A), and A T - B is orthogonal to
    it), an inconsistent B included: a regular r x r solve that AD differentiates. With r = L it is A^-1 B."""
    import casadi as ca

    x = ca.DM(sym.reduce_positions(X))
    u = ca.DM(sym.reduce(U))
    p0, v0, a0 = sym.anchor_state(X, U, Aa)
    fin, p, v, a = (ca.MX.sym(name, n) for name, n in (("fin", sym.n), ("p", p0.size), ("v", v0.size),
                                                       ("a", a0.size)))
    F = Ffn(x, u, fin, p, v)
    A = sym.A_fn(x, p)
    B = sym.B_fn(x, u, F, p, v, a)
    if cut.kept.sum() < sym.L:
        Q = ca.mtimes(A, ca.DM(cut.V[:, cut.kept] / cut.w[cut.kept]))
        T = ca.mtimes(Q, ca.solve(ca.mtimes([Q.T, A, Q]), ca.mtimes(Q.T, B)))
    else:
        T = ca.solve(A, B)
    acc = sym.acc_fn(x, F, T, p)
    reaction = ca.mtimes(sym.Gp_fn(x, p).T, T)
    inputs = ca.vertcat(fin, p, v, a)
    direction = ca.MX.sym("seeds", inputs.shape[0], seeds.shape[1])
    forward = ca.Function("interface_ad", [fin, p, v, a, direction],
                          [ca.jtimes(ca.vertcat(T, acc, reaction), inputs, direction)])
    return np.asarray(forward(sym.reduce(Fin), p0, v0, a0, seeds), float)


def _interface_numeric(lin, sym, seeds):
    """The same derivatives (rows T, acc of the free masses, reactions on the driven anchors, in reduced
    coordinates) along the same ``seeds`` from a linearization's ``directional``, seeded on every driven anchor
    (``lin.anchors`` = ``sym.driven``)."""
    d, basis, nf, nd = sym.dim, sym.basis, sym.nf, sym.nd
    anchor_rows = np.searchsorted(sym.fixed, sym.driven)
    out = np.zeros((sym.L + sym.n + nd * d, seeds.shape[1]))
    for j, seed in enumerate(seeds.T):
        dF = np.zeros((sym.K, 3))
        dF[sym.free] = seed[:sym.n].reshape(nf, d) @ basis.T
        motion = [part.reshape(nd, d) @ basis.T for part in np.split(seed[sym.n:], 3)] if nd else [None] * 3
        o = lin.directional(dF, *motion)
        out[:, j] = np.concatenate([o["T"], (o["acc"][sym.free] @ basis).ravel(),
                                    (o["Freact"][anchor_rows] @ basis).ravel()])
    return out


def _interface_seeds(scene, sym, rng, per_kind=2):
    """Random seeds in natural units (a typical weight m g for forces, a link length for positions, sqrt(g l) for
    velocities, g for accelerations), ``per_kind`` on each kind of input alone (F; P, V, A of the driven anchors),
    and the units of the outputs (rows: m g for tensions and reactions, g for accelerations), in which the
    derivatives are compared, so that blocks of different dimensions weigh alike."""
    g = float(np.linalg.norm(scene.gravity)) or 9.81
    m = float(np.median(np.asarray(scene.mass, float)[sym.free])) if sym.nf else 1.0
    ell = float(np.median(sym._R)) if sym.L else 1.0
    d, n, nd = sym.dim, sym.n, sym.nd
    kinds = [(slice(0, n), m * g)]
    if nd:
        for i, unit in enumerate((ell, np.sqrt(g * ell), g)):
            kinds.append((slice(n + i * nd * d, n + (i + 1) * nd * d), unit))
    seeds = np.zeros((n + 3 * nd * d, per_kind * len(kinds)))
    for i, (part, unit) in enumerate(kinds):
        seeds[part, per_kind * i:per_kind * (i + 1)] = unit * rng.standard_normal((part.stop - part.start, per_kind))
    rows = np.concatenate([np.full(sym.L, m * g), np.full(n, g), np.full(nd * d, m * g)])
    return seeds, rows


def _check_interface_jacobian(scene, sym, dyn, Ffn, on, off, seed, native):
    """The interface Jacobians (linknet_core.dynamics.interface_jacobian): the derivatives of T, the accelerations
    and the reactions on the driven anchors along random seeds on the input forces and the driven anchors' P, V,
    A (every driven anchor's: the inputs are the input-driven ones', and a scene motion's anchor enters the same
    equations in the same places), from the numpy reference (and the native core) against casadi's AD of the AD system
    (:func:`_interface_ad`), on and off the manifold. Compared in natural units (:func:`_interface_seeds`), relative
    to the largest derivative and divided by cond(A) on its kept range, as the other solved quantities. States with an
    eigenvalue of A in the band where the solver's and the reference's rank rules may differ (:class:`_RankCut`)
    are counted and not compared: the minimum-norm tensions are not one function there. The seeds are drawn from a
    generator of their own (``seed``), so that the other lines' draws are those they have without this one."""
    from linknet_core.dynamics.interface_jacobian import ReferenceLinearization

    rng = np.random.default_rng((seed, 28))

    name = "interface Jacobians: dT, dU/dt, Freact by F, P, V, A = AD"
    if not all(hasattr(dyn, attr) for attr in ("_scatter", "solver", "factor", "anchor_reactions", "structure")):
        return CheckResult(name, True, 0.0, RTOL_SOLVE * 1e2, "the numeric side is not a Dynamics: not compared",
                           skipped=True)
    inputs, with_motion = _driven_groups(scene, sym)
    native_side = None
    if native:
        try:
            from linknet_core.native.interface import NativeInterface
            from linknet_core.native.model import NativeData, native_model

            model = native_model(scene, dyn.structure)
            native_side = (model, NativeData(model), NativeInterface(model))
        except Exception as exc:  # noqa: BLE001 - a missing native core is reported, not raised
            native_side = f"{type(exc).__name__}: {exc}"
    worst = {"numpy": 0.0}
    if isinstance(native_side, tuple):
        worst["native"] = 0.0
    worst_cond, ambiguous, used, n_seeds = 1.0, 0, 0, 0
    for s in on + off:
        X, U, Aa = np.array(s.X, float), np.array(s.U, float), None if s.anchor_acc is None else np.array(s.anchor_acc)
        if with_motion.size:  # where the core places them at the sample's scene time
            P, V, A = scene.anchor_motion(s.tau)
            rows = np.searchsorted(sym.driven, with_motion)
            X[with_motion], U[with_motion], Aa[with_motion] = P[rows], V[rows], A[rows]
        cut = _RankCut.of(sym.A(X).toarray())
        if cut.ambiguous:
            ambiguous += 1
            continue
        cond = cut.condition()
        worst_cond = max(worst_cond, cond)
        seeds, row_unit = _interface_seeds(scene, sym, rng)
        reference = _interface_ad(sym, Ffn, X, U, s.F_input, Aa, cut, seeds) / row_unit[:, None]
        sides = {"numpy": ReferenceLinearization(dyn, X, U, s.F_input, Aa, anchors=sym.driven)}
        if isinstance(native_side, tuple):
            from linknet_core.native.interface import NativeLinearization

            model, data, interface = native_side
            data.struct.t = data.struct.drive_hold_t = s.tau if s.tau is not None else 0.0
            data.struct.drive_t0 = 0.0
            if inputs.size:
                slots = np.searchsorted(sym.driven, inputs)
                data.drive_P[slots], data.drive_V[slots], data.drive_A[slots] = X[inputs], U[inputs], Aa[inputs]
            sides["native"] = NativeLinearization(model, data, X, U, s.F_input, interface, anchors=sym.driven)
        for side, lin in sides.items():
            got = _interface_numeric(lin, sym, seeds) / row_unit[:, None]
            worst[side] = max(worst[side], float(np.abs(got - reference).max(initial=0.0))
                              / max(float(np.abs(reference).max(initial=0.0)), 1.0) / cond)
        used += 1
        n_seeds = seeds.shape[1]
    tol = RTOL_SOLVE * 1e2
    detail = (f"{used} of {len(on) + len(off)} state(s) on and off the manifold, {n_seeds} random seeds each (on F"
              + (", and on P, V, A of the driven anchors" if sym.nd else "") + "): "
              + ", ".join(f"{side} {w:.2e}" for side, w in worst.items())
              + f" (natural units, relative, divided by cond(A), up to {worst_cond:.1e});"
              " AD of T = Q (Q^T A Q)^-1 Q^T B, Q = A V_r Lambda_r^-1 spanning range(A)")
    if ambiguous:
        detail += f"; {ambiguous} state(s) with an eigenvalue of A in the rank band not compared"
    if isinstance(native_side, str):
        detail += f"; native: not compared ({native_side})"
    passed = all(w <= tol for w in worst.values())
    return CheckResult(name, passed, max(worst.values()), tol, detail, skipped=used == 0)


def _check_driven(scene, sym, dyn, Ffn, on, off):
    """Driven anchors: the terms the prescribed motion adds to (12) and (26), and the reactions on the anchors.

    * (26): the anchors' part of B, B(X, U, F, A_a) - B(X, U with the anchors' rows at rest, F, 0), from the
      numeric side and from AD, where AD differentiates |X_k - P_a(t)|^2 - R^2 twice along dP/dt = V,
      dV/dt = A (never the numeric formula): |U_k - V_a|^2 / R and E.(a_k2 - a_k1) with a_a = A_a;
    * (12): the numeric C U (``constraint_rows``, E_l.(U_k1 - U_k2)) against AD's d phi/dt / (2R) with the
      anchors' velocities, and the sampled states' own (12) residual (the relative velocity vanishes
      along every link on the manifold);
    * the force the links exert on each driven anchor (``anchor_reactions``) against G_p^T T, G_p the
      Jacobian of (11) in the anchors' positions by AD.
    """
    worst_B = worst_12 = worst_react = sample_12 = 0.0
    share = 0.0
    anchor_rows = np.searchsorted(sym.fixed, sym.driven)      # the driven anchors among all anchors
    for X, U, Fin, Aa in on + off:
        F = np.asarray(dyn.forces(X, U, Fin), float)
        U_rest = np.array(U, float)
        U_rest[sym.driven] = 0.0
        dB_n = _numeric_rhs(dyn, X, U, F, Aa) - _numeric_rhs(dyn, X, U_rest, F, np.zeros_like(Aa))
        dB_s = sym.B(X, U, F, Aa) - sym.B(X, U_rest, F, None)
        scale = _force_scale(sym, X, U, F, Aa)
        worst_B = max(worst_B, _rel(np.abs(dB_n - dB_s).max(initial=0.0), scale))
        share = max(share, _rel(np.abs(dB_s).max(initial=0.0), np.abs(sym.B(X, U, F, Aa)).max(initial=0.0)))
        c_s = sym.velocity_constraint(X, U)
        v_scale = max(np.abs(U).max(initial=0.0), 1e-300)
        if hasattr(dyn, "constraint_rows"):
            worst_12 = max(worst_12, _rel(np.abs(np.asarray(dyn.constraint_rows(X, U)) + c_s).max(initial=0.0),
                                          v_scale))
        if hasattr(dyn, "anchor_reactions"):
            _, T_s = sym.solve(X, U, sym.forces(Ffn, X, U, Fin), Aa, rcond=RTOL_NULL)
            on_anchors = (sym.Gp(X).T @ T_s).reshape(sym.nd, sym.dim) @ sym.basis.T
            R_n = np.asarray(dyn.anchor_reactions(X, T_s), float)[anchor_rows]
            worst_react = max(worst_react, _rel(np.abs(R_n - on_anchors).max(initial=0.0),
                                                max(np.abs(on_anchors).max(initial=0.0), np.abs(T_s).max(initial=0.0))))
    for X, U, *_ in on:
        sample_12 = max(sample_12, _rel(np.abs(sym.velocity_constraint(X, U)).max(initial=0.0),
                                        max(np.abs(U).max(initial=0.0), 1e-300)))
    worst = max(worst_B, worst_12, worst_react)
    passed = worst <= RTOL_EXACT and sample_12 <= 1e-12
    kinds = sorted({m.kind for m in getattr(scene, "motions", ())}) or ["?"]
    detail = (f"{sym.nd} driven anchor(s) ({', '.join(kinds)}), {len(on)} + {len(off)} states with P, V, A from "
              f"the motion (random for inputs): anchors' part of B (26) (relative velocity, A_a) {worst_B:.2e} "
              f"relative (it is up to {share:.0%} of B); (12) with V_a: C U vs AD {worst_12:.2e}, sampled states' "
              f"residual {sample_12:.1e}; reactions on the driven anchors vs G_p^T T {worst_react:.2e}")
    return CheckResult("driven anchors: (12) and (26) with V_a, A_a", passed, worst, RTOL_EXACT, detail)


def _motion_expression(motion, tau):
    """P(tau) of a motion written in casadi from the scene file's formula (velocity, sine), or None."""
    import casadi as ca

    X0 = ca.DM(np.asarray(motion.origin, float))
    spec = motion.spec
    if motion.kind == "velocity":
        return X0 + ca.DM(np.asarray(spec["velocity"], float)) * tau
    if motion.kind == "sine":
        a = ca.DM(np.asarray(spec["amplitude"], float))
        f = ca.DM(np.asarray(spec["frequency"], float))
        phi = ca.DM(np.asarray(spec.get("phase", [0, 0, 0]), float))
        return X0 + a * (ca.sin(2 * np.pi * f * tau + phi) - ca.sin(phi))
    return None


def _check_motions(scene, sym, rng, samples):
    """The driven anchors' scene motions: V = dP/dtau and A = dV/dtau, and what each kind promises.

    Velocity and sine: P(tau) written in casadi from the scene file's formula, V and A by AD, against
    ``AnchorMotion.evaluate`` (the numbers both cores use). Waypoints: the clamped C2 cubic spline is the
    only piecewise cubic through (0, X0) and the waypoints, twice continuously differentiable and at rest
    at both ends, so those properties are checked (P at every waypoint, P, V, A continuous across every
    knot, V = 0 at the ends, at rest after the last waypoint), and V, A against central differences of
    P, V at random times (exact for a cubic up to h^2 P''' / 6 and round-off).
    """
    import casadi as ca

    tau = ca.SX.sym("tau")
    worst_ad = worst_fd = worst_spline = 0.0
    kinds = []
    h = 1e-5
    for motion in getattr(scene, "motions", ()):
        if motion.kind == "input":
            continue
        kinds.append(motion.kind)
        horizon = _motion_horizon(motion, float(np.median(sym._R)) if sym.L else 1.0)
        times = np.concatenate([[0.0], rng.uniform(0.0, horizon, samples)])
        P_expr = _motion_expression(motion, tau)
        if P_expr is not None:
            V_expr = ca.jacobian(P_expr, tau)
            fn = ca.Function("motion", [tau], [P_expr, V_expr, ca.jacobian(V_expr, tau)])
            for t in times:
                ref = [np.asarray(z, float).ravel() for z in fn(t)]
                got = motion.evaluate(float(t))
                scale = max(np.abs(motion.origin).max(), 1.0)
                for r, g in zip(ref, got):
                    worst_ad = max(worst_ad, float(np.abs(r - g).max()) / max(np.abs(r).max(), scale * 1e-3))
            continue
        knots = [0.0] + [float(w[0]) for w in motion.spec["waypoints"]]
        points = [np.asarray(motion.origin, float)] + [np.asarray(w[1:], float) for w in motion.spec["waypoints"]]
        span = max(float(np.abs(np.array(points) - points[0]).max()), 1e-300)
        t_end = knots[-1]
        for t, p in zip(knots, points):
            worst_spline = max(worst_spline, float(np.abs(motion.evaluate(t)[0] - p).max()) / span)
        delta = 1e-9 * t_end
        for t in knots[1:-1]:
            left, right = motion.evaluate(t - delta), motion.evaluate(t + delta)
            for order, (a, b) in enumerate(zip(left, right)):
                worst_spline = max(worst_spline, float(np.abs(a - b).max()) * t_end ** order / span)
        for t in (0.0, t_end, t_end * 1.5):
            P, V, A = motion.evaluate(t)
            worst_spline = max(worst_spline, float(np.abs(V).max()) * t_end / span)
            if t > t_end:
                worst_spline = max(worst_spline, float(np.abs(P - points[-1]).max()) / span,
                                   float(np.abs(A).max()) * t_end ** 2 / span)
        for t in rng.uniform(h, t_end - h, samples):
            if min(abs(t - k) for k in knots) < 2 * h:
                continue
            (Pm, Vm, _), (P0, V0, A0), (Pp, Vp, _) = (motion.evaluate(t + s) for s in (-h, 0.0, h))
            worst_fd = max(worst_fd, float(np.abs((Pp - Pm) / (2 * h) - V0).max()) * t_end / span,
                           float(np.abs((Vp - Vm) / (2 * h) - A0).max()) * t_end ** 2 / span)
    tol_fd = 1e-6          # the finite differences' truncation and the knots' 1e-9 offsets, with margin
    passed = worst_ad <= RTOL_EXACT and worst_fd <= tol_fd and worst_spline <= tol_fd
    parts = []
    if set(kinds) & {"velocity", "sine"}:
        parts.append(f"velocity/sine P, V, A vs AD of the scene formula {worst_ad:.2e} (tol {RTOL_EXACT:.0e})")
    if "waypoints" in kinds:
        parts.append(f"waypoint splines: through the waypoints, C2 across the knots, at rest at the ends "
                     f"{worst_spline:.2e}, V and A vs central differences {worst_fd:.2e} (relative to the "
                     "spline's span and duration)")
    detail = f"{len(kinds)} motion(s) ({', '.join(sorted(set(kinds)))}) at {samples + 1} times each: " + "; ".join(parts)
    return CheckResult("driven anchors' motions: V = dP/dt, A = dV/dt", passed, max(worst_ad, worst_fd, worst_spline),
                       tol_fd, detail)


def _condition(sym, X):
    """cond(A) on its range (eigenvalues above the rank cut): the scale of a solved quantity's error."""
    return _RankCut.of(sym.A(X).toarray()).condition()


def _driven_groups(scene, sym):
    """(input-driven anchors, anchors with a scene motion), mass indices in scene order."""
    inputs = np.asarray(getattr(scene, "input_driven_indices", np.zeros(0, np.int64)), np.int64)
    return inputs, np.setdiff1d(sym.driven, inputs)


REACH_STEP = 0.01  # the largest RATTLE step of the runs that bring a simulator to a sample's scene time


def _simulator_at(scene, sym, sample, backend):
    """(sim, X, U, anchor_acc): a RATTLE ``Simulator`` of ``backend`` holding the sample's state at the sample's
    scene time, through the public API only: run from the scene's start to tau (only the scene motions run on
    the simulator's clock; what the run did to the free masses is then replaced; steps of at most
    REACH_STEP, tau divided evenly), the sample's X, U put in by a snapshot, with the anchors that have a
    scene motion exactly where it has them at tau (where the core places them). ``sim.dt`` is the step.
    Raises SolverError when the scene's own run cannot reach tau."""
    from linknet_core.simulator.simulator import Simulator

    inputs, with_motion = _driven_groups(scene, sym)
    tau = sample.tau if with_motion.size else 0.0
    dt = tau / math.ceil(tau / REACH_STEP) if tau > 0 else REACH_STEP
    sim = Simulator(scene, method="rattle", dt=dt, backend=backend)
    sim.dt = dt
    if with_motion.size and sample.tau > 0:
        sim.advance(sim.state.t + sample.tau)
    X, U = np.array(sample.X, float), np.array(sample.U, float)
    Aa = np.array(sample.anchor_acc, float)
    if with_motion.size:
        P, V, A = scene.anchor_motion(sample.tau)
        rows = np.searchsorted(sym.driven, with_motion)
        X[with_motion], U[with_motion], Aa[with_motion] = P[rows], V[rows], A[rows]
    snapshot = sim.get_state()
    snapshot["state"].X, snapshot["state"].U = X.copy(), U.copy()
    sim.set_state(snapshot)
    return sim, X, U, Aa


def _first_clause(exc) -> str:
    """An error message up to its first colon: what failed, without the advice (kept short in a check line)."""
    return str(exc).split(":")[0]


def _backends_detail(worst, skipped, failed):
    return ("".join(f"; {b}: not compared ({why})" for b, why in skipped.items())
            + "".join(f"; {b}: {n} sample(s) not run (last: {why})" for b, (n, why) in failed.items()))


def _check_native(scene, sym, Ffn, states):
    """The native core's tensions and reactions with driven anchors against the symbolic system.

    A native ``Simulator`` at each sample (:func:`_simulator_at`), then ``outputs(F_input, anchors=(P, V, A))``
    for the input-driven anchors. The symbolic side is evaluated at the state the core sees.
    """
    from linknet_core.errors import SolverError

    name = "native core with driven anchors = symbolic"
    inputs, _ = _driven_groups(scene, sym)
    anchor_rows = np.searchsorted(sym.fixed, sym.driven)
    worst_T = worst_react = 0.0
    worst_cond = 1.0
    used = 0
    skipped, failed = {}, {}
    for s in states:
        try:
            sim, X, U, Aa = _simulator_at(scene, sym, s, "native")
        except SolverError as exc:
            failed["native"] = (failed.get("native", (0, ""))[0] + 1, _first_clause(exc))
            continue
        except Exception as exc:  # noqa: BLE001 - any reason the native core is not here is reported, not raised
            skipped["native"] = f"no native core: {type(exc).__name__}: {exc}"
            break
        out = sim.outputs(F_input=s.F_input, anchors=(X[inputs], U[inputs], Aa[inputs]) if inputs.size else None)
        _, T_s = sym.solve(X, U, sym.forces(Ffn, X, U, s.F_input), Aa, rcond=RTOL_NULL)
        cond = _condition(sym, X)
        worst_cond = max(worst_cond, cond)
        scale_T = max(np.abs(T_s).max(initial=0.0), 1e-300)
        worst_T = max(worst_T, float(np.abs(np.asarray(out["T"]) - T_s).max(initial=0.0)) / scale_T / cond)
        on_anchors = (sym.Gp(X).T @ T_s).reshape(sym.nd, sym.dim) @ sym.basis.T
        R_n = np.asarray(out["Freact"], float)[anchor_rows]
        worst_react = max(worst_react, float(np.abs(R_n - on_anchors).max(initial=0.0)) / scale_T / cond)
        used += 1
    worst = max(worst_T, worst_react)
    tol = RTOL_SOLVE * 1e2
    detail = (f"{used} state(s) through Simulator(backend='native').outputs(anchors=...) at the samples' scene "
              f"times: tensions {worst_T:.2e}, reactions on the driven anchors vs G_p^T T {worst_react:.2e} "
              f"(relative, divided by cond(A) up to {worst_cond:.1e})" + _backends_detail({}, skipped, failed))
    return CheckResult(name, worst <= tol and used > 0, worst, tol, detail, skipped=used == 0)


def _check_jump(scene, sym, states, rng):
    """A jump of the input-driven anchors' velocity: the impulse both cores report against the projection onto
    (12) in the mass metric, derived here from AD's G and G_p: u+ = u - M^-1 G^T lambda with
    (G M^-1 G^T) lambda = G u + G_p v+ (minimum norm), the links giving driven anchor a the impulse
    -(G_p^T lambda)_a. A ``Simulator`` of each backend at each sample (:func:`_simulator_at`: no position
    jump), then an advance whose anchors= keeps P and A and changes V, by a nanosecond (the impulse is taken
    at its start; a longer step could fail afterwards where the new velocity drives the anchor against a
    taut path). Differences are divided by cond(A), as for the other solved quantities."""
    from linknet_core.errors import SolverError

    name = "anchor velocity jump: impulse, projection (12)"
    inputs, _ = _driven_groups(scene, sym)
    m_typical = float(np.median(np.asarray(scene.mass, float)[sym.free])) if sym.nf else 1.0
    ell = float(np.median(sym._R))
    worst = {}
    skipped, failed = {}, {}
    used = 0
    worst_cond = 1.0
    for s in states:
        jump = ell * rng.standard_normal((inputs.size, 3))
        for backend in ("numpy", "native"):
            if backend in skipped:
                continue
            try:
                sim, X, U, Aa = _simulator_at(scene, sym, s, backend)
                U_after = U.copy()
                U_after[inputs] += jump
                sim.advance(sim.state.t + 1e-9, anchors=(X[inputs], U_after[inputs], Aa[inputs]))
            except SolverError as exc:
                failed[backend] = (failed.get(backend, (0, ""))[0] + 1, _first_clause(exc))
                continue
            except Exception as exc:  # noqa: BLE001 - a missing native core is reported, not raised
                skipped[backend] = f"{type(exc).__name__}: {exc}"
                continue
            G, Gp = sym.G(X).toarray(), sym.Gp(X).toarray()
            lam = np.linalg.lstsq(sym.A(X).toarray(), G @ sym.reduce(U) + Gp @ sym.reduce(U_after, rows=sym.driven),
                                  rcond=RTOL_NULL)[0]
            J_s = -(Gp.T @ lam).reshape(sym.nd, sym.dim) @ sym.basis.T
            cond = _condition(sym, X)
            worst_cond = max(worst_cond, cond)
            # the impulse this jump would give one typical free mass: the scale where the links take none
            scale = max(np.abs(J_s).max(initial=0.0), m_typical * float(np.abs(jump).max(initial=0.0))) * cond
            J_n = np.asarray(sim.anchor_report()["impulse"], float)
            worst[backend] = max(worst.get(backend, 0.0), float(np.abs(J_n - J_s).max(initial=0.0)) / scale)
        used += 1
    tol = RTOL_SOLVE * 1e2
    passed = bool(worst) and all(w <= tol for w in worst.values())
    detail = (f"{used} state(s), velocity jumps of ~{ell:.2g} m/s on {inputs.size} input-driven anchor(s): "
              + ", ".join(f"{b} {w:.2e}" for b, w in worst.items())
              + f" relative to the largest impulse, divided by cond(A) (up to {worst_cond:.1e})"
              + _backends_detail(worst, skipped, failed))
    return CheckResult(name, passed, max(worst.values(), default=0.0), tol, detail, skipped=not worst)


def _check_rattle_targets(scene, sym, states):
    """One RATTLE step of each core with driven anchors lands on (11) with P_a(t+h) and on (12) with V_a(t+h).

    A ``Simulator`` of each backend at each sample (:func:`_simulator_at`), input-driven anchors held as the
    sample's P + V s + A s^2/2 (no jump), one step h (the simulator's, at most REACH_STEP). After it the anchors' rows must be the motion at
    t + h (the scene motion's evaluate, the held quadratic), and the state must satisfy AD's (11) and (12)
    with them: what RATTLE's position and velocity stages target."""
    from linknet_core.errors import SolverError

    name = "RATTLE: (11) at P_a(t+h), (12) at V_a(t+h)"
    inputs, with_motion = _driven_groups(scene, sym)
    rows_in = np.searchsorted(sym.driven, inputs)
    rows_motion = np.searchsorted(sym.driven, with_motion)
    ell = float(np.median(sym._R))
    worst = {}
    skipped, failed = {}, {}
    for s in states:
        for backend in ("numpy", "native"):
            if backend in skipped:
                continue
            try:
                sim, X, U, Aa = _simulator_at(scene, sym, s, backend)
                h = sim.dt
                sim.advance(sim.state.t + h, anchors=(X[inputs], U[inputs], Aa[inputs]) if inputs.size else None)
            except SolverError as exc:
                failed[backend] = (failed.get(backend, (0, ""))[0] + 1, _first_clause(exc))
                continue
            except Exception as exc:  # noqa: BLE001 - a missing native core is reported, not raised
                skipped[backend] = f"{type(exc).__name__}: {exc}"
                continue
            P_h, V_h = np.array(X[sym.driven]), np.array(U[sym.driven])
            P_h[rows_in] = X[inputs] + h * U[inputs] + 0.5 * h * h * Aa[inputs]
            V_h[rows_in] = U[inputs] + h * Aa[inputs]
            if with_motion.size:
                P1, V1, _ = scene.anchor_motion(s.tau + h)
                P_h[rows_motion], V_h[rows_motion] = P1[rows_motion], V1[rows_motion]
            Xn, Un = sim.state.X, sim.state.U
            v_scale = max(np.abs(Un).max(initial=0.0), ell / 1.0)
            at = max(float(np.abs(Xn[sym.driven] - P_h).max()) / ell, float(np.abs(Un[sym.driven] - V_h).max()) / v_scale)
            c11 = float(np.abs(sym.constraint(Xn) / sym._R).max(initial=0.0))
            c12 = float(np.abs(sym.velocity_constraint(Xn, Un)).max(initial=0.0)) / v_scale
            a, b, c = worst.get(backend, (0.0, 0.0, 0.0))
            worst[backend] = (max(a, at), max(b, c11), max(c, c12))
    tol = 1e-12
    passed = bool(worst) and all(max(w) <= tol for w in worst.values())
    detail = (f"one step h <= {REACH_STEP:g} s from each sample: "
              + "; ".join(f"{b}: anchors vs P(t+h), V(t+h) {w[0]:.1e}, (11) {w[1]:.1e}, (12) {w[2]:.1e}"
                          for b, w in worst.items())
              + " (relative to the median link length, the largest speed)" + _backends_detail(worst, skipped, failed))
    return CheckResult(name, passed, max((max(w) for w in worst.values()), default=0.0), tol, detail,
                       skipped=not worst)


def _check_kernel(scene, dyn, states):
    """The casadi-generated compiled kernel (codegen) against the solver's numeric accelerations."""
    from linknet_core.symbolic import codegen

    name = "generated kernel = numeric accelerations"
    try:
        kernel = codegen.compiled_rhs(scene, required=True)
    except codegen.CodegenUnavailable as exc:
        return CheckResult(name, True, 0.0, 1e-10, f"no kernel: {exc}", skipped=True)
    worst = 0.0
    for X, U, Fin, _ in states:
        if kernel.plane is not None:  # keep the state in the scene's plane: the 2-D kernel is tested
            basis, origin, _ = kernel.plane
            P = basis @ basis.T
            X = (X - origin) @ P + origin
            U, Fin = U @ P, Fin @ P
        acc_c, T_c = kernel.accelerations(X, U, Fin)
        acc_n, T_n = dyn.accelerations(X, U, Fin)
        worst = max(worst, np.abs(acc_c - acc_n).max() / max(np.abs(acc_n).max(), 1e-300),
                    np.abs(T_c - T_n).max(initial=0.0) / max(np.abs(T_n).max(initial=0.0), 1e-300))
    return CheckResult(name, worst <= 1e-10, worst, 1e-10,
                       f"{kernel._primary.d}-D kernel {Path(kernel.so_path).name}; "
                       f"{kernel.fallback_calls} fallback call(s) to the numeric path")


# ------------------------------------------------------------------------------------------------
# ropes and a ground: the taut system, and the complementarity conditions along a run
# ------------------------------------------------------------------------------------------------

UNILATERAL_RUN_TIME = 2.0  # s: the run the complementarity checks sample
UNILATERAL_STATES = 41     # output states of that run, evenly spaced, every one checked
UNILATERAL_RTOL = 1e-9     # the run's tolerance (dop853)
# A rope or contact touches (its acceleration-level conditions apply) when its gap is within TOUCH_RTOL of its
# length scale and it separates no faster than TOUCH_RTOL of the velocity scale: the run's states are projected to
# ~1e-15, and a step opens gaps far above this.
TOUCH_RTOL = 1e-9
# T >= 0, gap >= 0, d2gap/dt2 >= 0 and the products' zeros hold to this, relative to the state's force, length and
# acceleration scales: the LCP's conditions hold to 1e-11 of its scale (complementarity.LCP_TOL), and the run's
# positions sit on their constraints to its tolerance.
RTOL_COMPLEMENTARITY = 1e-9
# Enumerating the active sets of more touching ropes and contacts than this (2^n dense solves per state) is skipped.
ENUMERATION_MAX = 12


def taut_mode(scene):
    """(mode scene, its Dynamics, what it is in words): the mode of ``scene`` with every rope taut (a rod of the
    seed) and every free mass that touches the ground at the start in contact (a link to a virtual anchor straight
    above it): the system (25)-(26) that today's checks take, built by the path that runs the scene
    (UnilateralDynamics.mode)."""
    from linknet_core.dynamics.unilateral import UnilateralDynamics

    uni = UnilateralDynamics(scene)
    X, U = np.array(scene.X0, float), np.array(scene.U0, float)
    active = np.zeros(uni.n_unilateral, bool)
    active[:uni.rope_links.size] = True
    active[uni.rope_links.size:] = uni.touching(X)[uni.rope_links.size:]
    md = uni.mode(active, X, U)
    n_contacts = int(active[uni.rope_links.size:].sum())
    words = (f"the taut system: every rope taut as a rod ({uni.rope_links.size} of {scene.L} links are ropes)"
             + (f", {n_contacts} mass(es) on the ground at the start as links to virtual anchors above them"
                if scene.ground is not None else ""))
    return md.inner.scene, md.inner, words


def unilateral_states(scene, t_end=None, n=UNILATERAL_STATES):
    """[(t, X, U, anchor_acc)]: the states of a run of ``scene`` (dop853, rtol UNILATERAL_RTOL) at n even times to
    t_end (default UNILATERAL_RUN_TIME), the driven anchors' accelerations from
    their motions at each time; and the run (its events)."""
    from linknet_core.simulator.simulator import simulate

    t_end = UNILATERAL_RUN_TIME if t_end is None else t_end
    run = simulate(scene, t_end, "dop853", rtol=UNILATERAL_RTOL, n_out=n, error_estimate=False, progress=False)
    states = []
    for t, X, U in zip(run.t, run.X, run.U):
        Aa = None
        if scene.driven.any():
            _, _, A = scene.anchor_motion(float(t))
            Aa = np.zeros((scene.K, 3))
            Aa[scene.driven_indices] = A
        states.append((float(t), np.array(X), np.array(U), Aa))
    return states, run


def _seed_rows(scene, X, U, F, anchor_acc, links, contacts):
    """The seed's (25)-(26) written again for a set of constraints: C (rows: +E_l at k1 and -E_l at k2 with E_l =
    (X_k2 - X_k1) / R_l for each link of ``links``; the ground's normal n at k for each mass of ``contacts``), W = C
    M^-1 C^T, B with W lambda - B the constraints' second time derivatives at zero gap rate (a link's |dU|^2 / R +
    E . (a_k2 - a_k1), a contact's -n . a_k, a = F / M on free masses, the motion's acceleration on driven anchors),
    and M^-1 as a (K,) vector. C lambda's forces pull a rope's ends together and push a mass off the ground."""
    K = scene.K
    inv_mass = np.where(scene.fixed | scene.driven, 0.0, 1.0 / np.where(scene.fixed | scene.driven, 1.0, scene.mass))
    a = F * inv_mass[:, None]
    if anchor_acc is not None:
        a = a + np.where((scene.driven)[:, None], anchor_acc, 0.0)
    rows = len(links) + len(contacts)
    C = np.zeros((rows, 3 * K))
    B = np.zeros(rows)
    for i, l in enumerate(links):
        k1, k2, R = int(scene.k1[l]), int(scene.k2[l]), float(scene.length[l])
        E = (X[k2] - X[k1]) / R
        C[i, 3 * k1:3 * k1 + 3], C[i, 3 * k2:3 * k2 + 3] = E, -E
        dU = U[k2] - U[k1]
        B[i] = dU @ dU / R + E @ (a[k2] - a[k1])
    for j, k in enumerate(contacts):
        n = scene.ground.normal
        C[len(links) + j, 3 * k:3 * k + 3] = n
        B[len(links) + j] = -n @ a[k]
    W = (C * np.repeat(inv_mass, 3)) @ C.T
    return C, W, B, inv_mass, a


def _enumerate_active_sets(W, B, n_rods, tol_lam, tol_w):
    """Every active set S of the unilateral rows (those after the first n_rods, the rods always in) for which the
    rods' and S's equations W_SS lambda_S = B_S (minimum norm where singular, (31)) give lambda_S >= 0 and W lambda -
    B >= 0 on the other unilateral rows: [(S as a bool array over the unilateral rows, lambda)]."""
    import itertools

    m = B.size - n_rods
    found = []
    for chosen in itertools.product((False, True), repeat=m):
        chosen = np.array(chosen, bool)
        rows = np.concatenate([np.arange(n_rods), n_rods + np.flatnonzero(chosen)]).astype(int)
        lam = np.zeros(B.size)
        if rows.size:
            lam[rows] = np.linalg.lstsq(W[np.ix_(rows, rows)], B[rows], rcond=RTOL_NULL)[0]
        w = W @ lam - B
        if np.abs(w[rows]).max(initial=0.0) > tol_w:  # the chosen equations themselves inconsistent
            continue
        if np.all(lam[n_rods:][chosen] >= -tol_lam) and np.all(w[n_rods:][~chosen] >= -tol_w):
            found.append((chosen, lam))
    return found


def _plane_tangents(normal):
    """(2, 3): an orthonormal pair spanning the plane perpendicular to the unit vector ``normal`` (its SVD's other
    right singular vectors)."""
    return np.linalg.svd(np.asarray(normal, float)[None, :])[2][1:]


def _coulomb_mode_solution(scene, X, U, F, anchor_acc, links, contacts, stuck, directions, mu):
    """Newton's laws with Coulomb's friction written again for one mode: the ``links`` (rods, taut ropes) and the
    masses ``contacts`` on the ground as in _seed_rows, of which those ``stuck`` (bool per contact) are held along
    the plane by a tangential force F_t (two unknowns on the plane's tangents) and the others slide, loaded by
    -mu N d with d their row of ``directions`` (3,). M a = F + C^T lambda + sum F_t + sum -mu N d; every row's
    second derivative zero (W lambda - B plus the friction's C M^-1 f = 0), a stuck mass's tangential acceleration
    zero. Returns (a (K, 3), lambda per row (links, then contacts: N), F_t (n_contacts, 3): the stuck ones' grip,
    the sliding ones' -mu N d)."""
    C, W, B, inv_mass, a_free = _seed_rows(scene, X, U, F, anchor_acc, links, contacts)
    K, n_links, n_c = scene.K, len(links), len(contacts)
    tangents = _plane_tangents(scene.ground.normal)
    held = np.flatnonzero(stuck)
    columns = np.zeros((3 * K, n_links + n_c + 2 * held.size))  # the force each unknown puts on the masses
    columns[:, :n_links + n_c] = C.T
    for j, k in enumerate(contacts):
        if not stuck[j]:
            columns[3 * k:3 * k + 3, n_links + j] -= mu * np.asarray(directions[j], float)
    for i, j in enumerate(held):
        k = contacts[j]
        columns[3 * k:3 * k + 3, n_links + n_c + 2 * i:n_links + n_c + 2 * i + 2] = tangents.T
    response = np.repeat(inv_mass, 3)[:, None] * columns  # a - a_free per unknown
    grip_rows = np.zeros((2 * held.size, 3 * K))
    for i, j in enumerate(held):
        k = contacts[j]
        grip_rows[2 * i:2 * i + 2, 3 * k:3 * k + 3] = tangents
    A = np.vstack([C @ response, grip_rows @ response])
    b = np.concatenate([B, -grip_rows @ a_free.ravel()])
    x = np.linalg.lstsq(A, b, rcond=RTOL_NULL)[0] if b.size else np.zeros(0)
    a = a_free + (response @ x).reshape(K, 3)
    lam = x[:n_links + n_c]
    friction = np.zeros((n_c, 3))
    for j in range(n_c):
        friction[j] = -mu * lam[n_links + j] * np.asarray(directions[j], float) if not stuck[j] else 0.0
    for i, j in enumerate(held):
        friction[j] = x[n_links + n_c + 2 * i:n_links + n_c + 2 * i + 2] @ tangents
    return a, lam, friction, float(np.abs(A @ x - b).max(initial=0.0))


class _Worst:
    """The largest violation of one condition over the states, with what broke it (in the scene's words)."""

    def __init__(self):
        self.value, self.where = 0.0, ""

    def add(self, value, where):
        if value > self.value:
            self.value, self.where = float(value), where


def _gap_second_derivatives(d, dU, dA):
    """d2/dt2 of R - |d| for a link vector d(t) with rates dU and dA: -(|dU|^2 + d . dA) / |d| + (d . dU)^2 /
    |d|^3."""
    r = np.sqrt(np.einsum("ij,ij->i", d, d))
    return (-(np.einsum("ij,ij->i", dU, dU) + np.einsum("ij,ij->i", d, dA)) / r
            + np.einsum("ij,ij->i", d, dU) ** 2 / r ** 3)


def _check_unilateral(scene, sym, states, dynamics=None):
    """The complementarity conditions at ``states`` (unilateral_states) and the LCP against enumeration.

    At every state, with linknet's tensions and normal forces (UnilateralDynamics.resolve: the acceleration LCP,
    then the chosen mode's (25)-(26)) and accelerations, and gaps computed here from the positions (a rope's R -
    |X_k2 - X_k1|, a mass's height n . (X_k - p)):
      position level, every rope and contact: T >= 0, gap >= 0, T gap = 0;
      acceleration level, those that touch (gap and its rate zero): T >= 0, d2gap/dt2 >= 0 (from linknet's
      accelerations, differentiated here), T d2gap/dt2 = 0.
    And the LCP (UnilateralDynamics.select_mode's multipliers) and linknet's accelerations against every active
    set of the touching constraints that satisfies the conditions, from the seed's (9) and (25)-(26) written again
    here (_seed_rows), the external forces from the symbolic model: the accelerations are unique (W is positive
    semidefinite), and so are the multipliers where the active rows are independent. Skipped at states with more
    than ENUMERATION_MAX touching constraints. Where a touching contact has Coulomb friction (its friction enters
    the LCP's matrix), the mode linknet chose is checked instead against Newton's laws with Coulomb's friction
    written again (_check_coulomb_mode): stuck within the cone, sliding at -mu N d, slipping from rest against the
    tangential acceleration the friction leaves; and every Coulomb mode of the touching constraints is solved there
    (_Painleve, up to COULOMB_MODES_MAX modes): with friction the rigid problem may have several solutions (a WARN
    naming them, linknet's among them) or none (a FAIL naming each mode and the condition it breaks)."""
    from linknet_core.dynamics.unilateral import UnilateralDynamics

    uni = dynamics if dynamics is not None else UnilateralDynamics(scene)
    Ffn = sym.forces_function()
    ropes = np.flatnonzero(scene.rope)
    rods = np.flatnonzero(~scene.rope)
    contacts = uni.contact_masses
    ground = scene.ground
    size = uni.size
    scale_len = np.concatenate([scene.length[ropes], np.full(contacts.size, size)])
    names = [f"rope {scene.link_label(int(l))}" for l in ropes] + \
            [f"the ground contact of {scene.mass_label(int(k))}" for k in contacts]
    pos = {c: _Worst() for c in ("T >= 0", "gap >= 0", "T gap = 0")}
    acc = {c: _Worst() for c in ("T >= 0", "d2gap/dt2 >= 0", "T d2gap/dt2 = 0")}
    lcp = {c: _Worst() for c in ("LCP multiplier >= 0", "LCP multipliers = enumeration", "tensions = enumeration",
                                 "accelerations = enumeration", "one solution")}
    coulomb = {c: _Worst() for c in COULOMB_CONDITIONS}
    coulomb_modes = np.zeros(4, int)  # contacts stuck, sliding, slipping from rest; touching ones left out
    painleve = _Painleve()
    n_touching = n_enumerated = n_enumerated_touching = n_coulomb = 0
    skipped = {}
    slack_seen = taut_seen = 0
    for t, X, U, Aa in states:
        at = f"t = {t:.6g} s"
        T, normal = uni.resolve(X, U, None, Aa)
        A, _ = uni.accelerations(X, U, None, Aa)
        F = sym.forces(Ffn, X, U, np.zeros_like(X))
        force = np.concatenate([T[ropes], normal[contacts]])
        d = X[scene.k2[ropes]] - X[scene.k1[ropes]]
        dU = U[scene.k2[ropes]] - U[scene.k1[ropes]]
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        gap = np.concatenate([scene.length[ropes] - dist,
                              ground.gaps(X[contacts]) if ground is not None else np.zeros(0)])
        rate = np.concatenate([-np.einsum("ij,ij->i", d, dU) / dist,
                               U[contacts] @ ground.normal if ground is not None else np.zeros(0)])
        g2 = np.concatenate([_gap_second_derivatives(d, dU, A[scene.k2[ropes]] - A[scene.k1[ropes]]),
                             A[contacts] @ ground.normal if ground is not None else np.zeros(0)])
        f_scale = max(float(np.abs(np.concatenate([T, normal])).max(initial=0.0)),
                      float(np.abs(F).max(initial=0.0)), 1e-300)
        free = ~(scene.fixed | scene.driven)
        v_scale = max(float(np.abs(U[free]).max(initial=0.0)),
                      math.sqrt(float(np.linalg.norm(scene.gravity)) * size), 1e-300)
        a_scale = max(float(np.abs(A).max(initial=0.0)), float(np.linalg.norm(scene.gravity)),
                      v_scale ** 2 / size, 1e-300)
        slack_seen += int(np.sum(force == 0))
        taut_seen += int(np.sum(force > 0))
        for u in range(force.size):
            pos["T >= 0"].add(-force[u] / f_scale, f"{names[u]} at {at}: force {force[u]:.6g} N")
            pos["gap >= 0"].add(-gap[u] / scale_len[u], f"{names[u]} at {at}: gap {gap[u]:.6g} m")
            pos["T gap = 0"].add(abs(force[u] * gap[u]) / (f_scale * scale_len[u]),
                                 f"{names[u]} at {at}: force {force[u]:.6g} N, gap {gap[u]:.6g} m")
        touching = (np.abs(gap) <= TOUCH_RTOL * scale_len) & (rate <= TOUCH_RTOL * v_scale)
        n_touching += int(touching.sum())
        for u in np.flatnonzero(touching):
            acc["T >= 0"].add(-force[u] / f_scale, f"{names[u]} at {at}: force {force[u]:.6g} N")
            acc["d2gap/dt2 >= 0"].add(-g2[u] / a_scale, f"{names[u]} at {at}: d2gap/dt2 {g2[u]:.6g} m/s^2")
            acc["T d2gap/dt2 = 0"].add(abs(force[u] * g2[u]) / (f_scale * a_scale),
                                       f"{names[u]} at {at}: force {force[u]:.6g} N, d2gap/dt2 {g2[u]:.6g} m/s^2")
        # the LCP's own multipliers on the touching constraints, and brute force
        cand = np.flatnonzero(touching)
        if cand.size > ENUMERATION_MAX:
            skipped["size"] = (skipped.get("size", (0,))[0] + 1,
                               f"more touching ropes and contacts than ENUMERATION_MAX = {ENUMERATION_MAX} (2^n dense "
                               f"solves; {cand.size} at {at})")
            continue
        n_ropes = ropes.size
        if uni.friction > 0 and (cand >= n_ropes).any():
            skipped["friction"] = (skipped.get("friction", (0,))[0] + 1,
                                   f"a touching contact with Coulomb friction (mu {uni.friction:g}), whose friction "
                                   "enters the LCP's matrix: the mode chosen there is checked against Newton's laws "
                                   f"with Coulomb's law instead (the friction check; last at {at})")
            n_coulomb += 1
            coulomb_modes += _check_coulomb_mode(scene, uni, X, U, F, Aa, A, T, at, names, cand, coulomb,
                                                 (f_scale, v_scale, a_scale))
            painleve.add(scene, uni, X, U, F, Aa, A, cand, names, at, (f_scale, v_scale, a_scale))
            continue
        candidates = np.zeros(uni.n_unilateral, bool)
        candidates[cand] = True
        _, lam_rows, md = uni.select_mode(X, U, None, Aa, candidates=candidates)
        lam_lcp = md.unilateral_forces(lam_rows)
        for u in cand:
            lcp["LCP multiplier >= 0"].add(-lam_lcp[u] / f_scale,
                                           f"{names[u]} at {at}: the LCP's multiplier {lam_lcp[u]:.6g} N")
        links = np.concatenate([rods, ropes[cand[cand < n_ropes]]]).astype(int)
        cmasses = contacts[cand[cand >= n_ropes] - n_ropes]
        C, W, B, inv_mass, a_free = _seed_rows(scene, X, U, F, Aa, links, cmasses)
        b_scale = max(float(np.abs(B).max(initial=0.0)), a_scale)
        diag = max(float(np.abs(np.diagonal(W)).max(initial=0.0)), 1e-300)
        found = _enumerate_active_sets(W, B, rods.size, RTOL_COMPLEMENTARITY * b_scale / diag,
                                       RTOL_COMPLEMENTARITY * b_scale)
        n_enumerated += 1
        n_enumerated_touching += bool(cand.size)
        if not found:
            lcp["one solution"].add(1.0, f"at {at}: no active set of the {cand.size} touching constraint(s) "
                                         "satisfies the conditions")
            continue
        acc_b = [(a_free + (inv_mass[:, None] * (C.T @ lam).reshape(-1, 3))) for _, lam in found]
        spread = max(float(np.abs(x - acc_b[0]).max(initial=0.0)) for x in acc_b) / a_scale
        lcp["one solution"].add(spread, f"at {at}: {len(found)} active sets with accelerations {spread:.3g} apart")
        worst_acc = float(np.abs((A - acc_b[0])[free]).max(initial=0.0)) / a_scale
        lcp["accelerations = enumeration"].add(worst_acc, f"at {at}: accelerations differ by {worst_acc:.3g} of "
                                                          f"{a_scale:.3g} m/s^2")
        chosen, lam_b = found[0]
        rows = np.concatenate([np.arange(rods.size), rods.size + np.flatnonzero(chosen)]).astype(int)
        sub = W[np.ix_(rows, rows)]
        eig = np.linalg.eigvalsh(sub) if rows.size else np.ones(1)
        if len(found) == 1 and eig.min(initial=1.0) > RTOL_NULL * max(eig.max(initial=0.0), 1e-300):
            # independent active rows: the multipliers are unique, compare them one by one
            labels = [scene.link_label(int(l)) for l in rods] + [names[u] for u in cand]
            mine = np.concatenate([T[rods], force[cand]])
            theirs = np.concatenate([lam_b[:rods.size], lam_b[rods.size:]])
            lcp_own = np.concatenate([lam_rows[:rods.size], lam_lcp[cand]])
            for i, label in enumerate(labels):
                lcp["tensions = enumeration"].add(abs(mine[i] - theirs[i]) / f_scale,
                                                  f"{label} at {at}: {mine[i]:.6g} N, enumeration {theirs[i]:.6g} N")
                lcp["LCP multipliers = enumeration"].add(
                    abs(lcp_own[i] - theirs[i]) / f_scale,
                    f"{label} at {at}: the LCP's {lcp_own[i]:.6g} N, enumeration {theirs[i]:.6g} N")
    tol = RTOL_COMPLEMENTARITY
    results = []

    def result(name, table, detail):
        worst = max(w.value for w in table.values())
        broken = "".join(f"; BROKEN: {c} at {w.where}" for c, w in table.items() if w.value > tol)
        results.append(CheckResult(name, worst <= tol, worst, tol, detail + broken))

    result("ropes, ground: T >= 0, gap >= 0, T gap = 0", pos,
           f"{len(states)} states along the run, {len(names)} rope(s) and contact(s): " + ", ".join(
               f"{c} {w.value:.1e}" for c, w in pos.items()) + f" (relative to the force and length scales); "
           f"{taut_seen} taut and {slack_seen} slack or off the ground")
    if n_touching:
        result("touching: T >= 0, d2gap/dt2 >= 0, T d2gap/dt2 = 0", acc,
               f"{n_touching} touching rope(s)/contact(s) over the states: " + ", ".join(
                   f"{c} {w.value:.1e}" for c, w in acc.items())
               + " (d2gap/dt2 from linknet's accelerations; relative to the force and acceleration scales)")
    else:
        results.append(CheckResult("touching: T >= 0, d2gap/dt2 >= 0, T d2gap/dt2 = 0", True, 0.0, tol,
                                   "no rope or contact touched at the sampled states", skipped=True))
    why = "; ".join(f"enumeration skipped at {count} state(s): {reason}" for count, reason in skipped.values())
    if n_enumerated:
        result("LCP = enumeration of the active sets", lcp,
               f"{n_enumerated} state(s) ({n_enumerated_touching} with touching ropes or contacts), every active set "
               "of those from (9), (25)-(26) written again: " + ", ".join(f"{c} {w.value:.1e}" for c, w in lcp.items()) + (f"; {why}" if why
                                                                                             else ""))
    else:
        results.append(CheckResult("LCP = enumeration of the active sets", True, 0.0, tol,
                                   why or "no rope or contact touched at the sampled states", skipped=True))
    if n_coulomb:
        result("Coulomb friction: the mode against Newton's laws", coulomb,
               f"{n_coulomb} state(s) with a touching contact on the rough ground (mu {uni.friction:g}; over them "
               f"{coulomb_modes[0]} stuck, {coulomb_modes[1]} sliding, {coulomb_modes[2]} slipping from rest, "
               f"{coulomb_modes[3]} touching and left out), the mode the LCP chose (taut, on the ground, stuck or "
               "sliding) solved again from (9), (25)-(26) with Coulomb's friction: "
               + ", ".join(f"{c} {w.value:.1e}" for c, w in coulomb.items())
               + " (relative to the force, velocity and acceleration scales)")
    elif uni.friction > 0:
        results.append(CheckResult("Coulomb friction: the mode against Newton's laws", True, 0.0, tol,
                                   "no contact touched the rough ground at the sampled states", skipped=True))
    if uni.friction > 0:
        results.append(painleve.result(uni.friction))
    return results


COULOMB_CONDITIONS = ("N >= 0, T >= 0", "stuck: |F_t| <= mu N", "sliding: F_t = -mu N d", "slip direction",
                      "off the ground: d2gap/dt2 >= 0", "forces = Newton's laws", "accelerations = Newton's laws")


def _check_coulomb_mode(scene, uni, X, U, F, anchor_acc, A, T, at, names, cand, table, scales):
    """Coulomb's law at one state, on the mode linknet chose there (UnilateralDynamics.state_mode: which ropes are
    taut, which masses are on the ground, which of those stick), against Newton's laws with Coulomb's friction
    written again (_coulomb_mode_solution), the slip directions taken from the state: a sliding mass's tangential
    velocity where it moves, else (a slip from rest) the direction of the friction linknet gives it, which must then
    be that of the tangential acceleration it leaves (a_t = lambda d, lambda >= 0). The conditions: the normal forces
    and taut ropes' tensions >= 0; a stuck mass's tangential force within the cone |F_t| <= mu N; a sliding mass's
    friction -mu N d (linknet's against the one solved here); the touching constraints left out separating, d2gap/dt2
    >= 0; and linknet's accelerations, tensions, normal forces and friction equal to those solved here. ``cand``: the
    touching constraints (as check.py found them); ``table``: {condition: _Worst}. Returns how many contacts were
    stuck, sliding and slipping from rest, and how many touching constraints the mode left out."""
    f_scale, v_scale, a_scale = scales
    n_ropes, mu = uni.rope_links.size, uni.friction
    ground = scene.ground
    md = uni.state_mode(X, U, None, anchor_acc)
    normal_l, tangential_l = uni.ground_forces(X, U, None, anchor_acc)
    rods = np.flatnonzero(~scene.rope)
    taut = uni.rope_links[md.active[:n_ropes]]
    links = np.concatenate([rods, taut]).astype(int)
    contacts = uni.contact_masses[md.active[n_ropes:]]
    stuck = md.stuck[md.active[n_ropes:]]
    v_t = U[contacts] - np.outer(U[contacts] @ ground.normal, ground.normal)
    speed = np.linalg.norm(v_t, axis=1)
    moving = speed > TOUCH_RTOL * v_scale
    directions = np.zeros((contacts.size, 3))
    directions[moving] = v_t[moving] / speed[moving, None]
    at_rest = ~moving & ~stuck
    given = np.linalg.norm(tangential_l[contacts], axis=1)
    directions[at_rest] = -np.divide(tangential_l[contacts][at_rest], given[at_rest, None],
                                     out=np.zeros((int(at_rest.sum()), 3)), where=given[at_rest, None] > 0)
    a, lam, friction, residual = _coulomb_mode_solution(scene, X, U, F, anchor_acc, links, contacts, stuck,
                                                        directions, mu)
    N = lam[links.size:]
    label = dict(zip(uni.contact_masses.tolist(), names[n_ropes:]))
    for i, l in enumerate(links[rods.size:]):
        table["N >= 0, T >= 0"].add(-lam[rods.size + i] / f_scale,
                                    f"rope {scene.link_label(int(l))} at {at}: tension {lam[rods.size + i]:.6g} N")
    for j, k in enumerate(contacts):
        where = f"{label[int(k)]} at {at}"
        table["N >= 0, T >= 0"].add(-N[j] / f_scale, f"{where}: normal force {N[j]:.6g} N")
        if stuck[j]:
            margin = float(np.linalg.norm(friction[j])) - mu * N[j]
            table["stuck: |F_t| <= mu N"].add(margin / f_scale, f"{where} (stuck): |F_t| "
                                              f"{np.linalg.norm(friction[j]):.6g} N, mu N {mu * N[j]:.6g} N")
        else:
            off = float(np.linalg.norm(tangential_l[k] - friction[j]))
            table["sliding: F_t = -mu N d"].add(off / f_scale, f"{where} (sliding): linknet's friction "
                                                f"{np.round(tangential_l[k], 9).tolist()} N, -mu N d "
                                                f"{np.round(friction[j], 9).tolist()} N")
            if at_rest[j]:  # the slip from rest: the friction opposes the tangential acceleration it leaves
                a_t = a[k] - (a[k] @ ground.normal) * ground.normal
                along = float(a_t @ directions[j])
                across = float(np.linalg.norm(a_t - along * directions[j]))
                table["slip direction"].add(max(across, -along) / a_scale,
                                            f"{where} (slipping from rest along {np.round(directions[j], 9).tolist()}): "
                                            f"its tangential acceleration {np.round(a_t, 9).tolist()} m/s^2")
        table["forces = Newton's laws"].add(abs(normal_l[k] - N[j]) / f_scale,
                                            f"{where}: normal force {normal_l[k]:.6g} N, Newton's laws {N[j]:.6g} N")
    for i, l in enumerate(links):
        table["forces = Newton's laws"].add(abs(T[l] - lam[i]) / f_scale, f"{scene.link_label(int(l))} at {at}: "
                                            f"tension {T[l]:.6g} N, Newton's laws {lam[i]:.6g} N")
    # the touching ropes and contacts the mode leaves out: separating (their gap's second derivative >= 0)
    for u in cand:
        if md.active[u]:
            continue
        if u < n_ropes:
            l = uni.rope_links[u]
            d = X[scene.k2[l]] - X[scene.k1[l]]
            g2 = float(_gap_second_derivatives(d[None], (U[scene.k2[l]] - U[scene.k1[l]])[None],
                                               (a[scene.k2[l]] - a[scene.k1[l]])[None])[0])
        else:
            g2 = float(a[uni.contact_masses[u - n_ropes]] @ ground.normal)
        table["off the ground: d2gap/dt2 >= 0"].add(-g2 / a_scale, f"{names[u]} at {at} (left out): d2gap/dt2 "
                                                                   f"{g2:.6g} m/s^2")
    free = ~(scene.fixed | scene.driven)
    worst = float(np.abs((A - a)[free]).max(initial=0.0))
    table["accelerations = Newton's laws"].add(max(worst, residual) / a_scale,
                                               f"at {at}: accelerations differ by {worst:.3g} m/s^2 (Newton's laws "
                                               f"solved to {residual:.3g})")
    return np.array([stuck.sum(), (~stuck).sum(), at_rest.sum(), sum(not md.active[u] for u in cand)])


# Painleve: with friction the rigid-body problem at a state can have several solutions or none (Painleve, Comptes
# rendus 121, 1895; Stewart, SIAM Review 42, 2000). The Coulomb modes of a state's touching ropes and contacts are
# enumerated when there are at most this many (one to a few solves of Newton's laws per mode).
COULOMB_MODES_MAX = 81
# Two modes that both satisfy Coulomb's law are one solution when their accelerations agree to this, relative to the
# acceleration scale: at a slip or lift-off event the modes on either side both hold (to RTOL_COMPLEMENTARITY) with
# the same accelerations, up to the distance of the state from the event.
RTOL_DISTINCT_SOLUTIONS = 1e-6
# The slip angle from rest is scanned at this many angles on the plane before the law's roots are refined.
SLIP_ANGLE_SCAN = 360
# How many ambiguous or inconsistent states the line names (it counts them all).
PAINLEVE_NAMED = 3


def _slip_angle_roots(a0, N0, G, k, mu, along_tol):
    """The directions (unit 2-vectors on the plane's tangents) in which a contact starting to slip from rest may
    slip, by Coulomb's law at the first instant of the slip: its friction f = -mu N d is a load on the mode, whose
    tangential acceleration a0 + G f and normal force N0 + k . f are affine in it (one mode, one linear system), so
    N = N0 / (1 + mu k . d), and the friction opposes the tangential acceleration it leaves: (a0 - mu N G d) x d = 0
    with (a0 - mu N G d) . d >= -along_tol and N > 0 (Pfeiffer and Glocker, Multibody Dynamics with Unilateral
    Contacts, 1996). Every root: a scan of the angle and a bracketing root find on each sign change. Where the cross
    product is round-off at every angle (a0 = 0 and G isotropic: a mass alone with no tangential load), the friction
    opposes every slip (a . d = -mu N d . G d < 0, G the positive mobility), and there is none."""
    from linknet_core.dynamics.roots import bracketed_root

    a0, N0, G, k = (float(a0[0]), float(a0[1])), float(N0), np.asarray(G, float), np.asarray(k, float)

    def law(phi):  # (a x d, a . d, 1 + mu k . d, N) at the angles phi (an array)
        d = np.stack([np.cos(phi), np.sin(phi)], axis=-1)
        den = 1.0 + mu * (d @ k)
        with np.errstate(divide="ignore", invalid="ignore"):
            N = N0 / den
            acc = np.asarray(a0) - mu * N[..., None] * (d @ G.T)
        return acc[..., 1] * d[..., 0] - acc[..., 0] * d[..., 1], (acc * d).sum(-1), den, N

    def cross_at(phi):  # the law's scalar at one angle (the root find's many calls), inside a bracket without a pole
        c, s = math.cos(phi), math.sin(phi)
        sN = mu * N0 / (1.0 + mu * (k[0] * c + k[1] * s))
        return (a0[1] - sN * (G[1, 0] * c + G[1, 1] * s)) * c - (a0[0] - sN * (G[0, 0] * c + G[0, 1] * s)) * s

    grid = 2 * math.pi * (np.arange(SLIP_ANGLE_SCAN + 1) + 0.5) / SLIP_ANGLE_SCAN
    cross, along, den, N = law(grid)
    roundoff = 64 * np.finfo(float).eps * max(abs(a0[0]), abs(a0[1]), mu * abs(N0) * float(np.abs(G).max()))
    if np.all(np.abs(cross) <= roundoff):
        return []
    roots = [float(p) for p, c in zip(grid[:-1], cross[:-1]) if c == 0.0]
    for i in range(SLIP_ANGLE_SCAN):
        if (not cross[i] * cross[i + 1] < 0 or not den[i] * den[i + 1] > 0
                or max(along[i], along[i + 1]) < -along_tol or max(N[i], N[i + 1]) <= 0):
            continue  # no sign change; a pole of N (1 + mu k . d = 0), not a root; or the law fails at both ends
        sign = 1.0 if cross[i] > 0 else -1.0
        lo, hi = bracketed_root(lambda p, s=sign: s * cross_at(p), float(grid[i]), float(grid[i + 1]),
                                sign * float(cross[i]), sign * float(cross[i + 1]))
        roots.append(0.5 * (lo + hi))
    out = []
    for phi in roots:
        _, along_r, _, N_r = law(np.array([phi]))
        if along_r[0] >= -along_tol and N_r[0] > 0:
            out.append(np.array([math.cos(phi), math.sin(phi)]))
    return out


def _slip_from_rest_directions(scene, X, U, F, anchor_acc, links, contacts, stuck, directions, starting, mu,
                               f_scale, along_tol):
    """The sets of slip directions (each (n_contacts, 3), ``directions`` with the rows of the contacts ``starting``
    filled) in which those contacts, at rest, may start to slip in the mode (links, contacts, stuck) by Coulomb's
    law, the accelerations and normal forces from Newton's laws written here (_coulomb_mode_solution) with the
    starting contacts' friction as loads, measured by 1 + 2 m solves: a0 + G f, N0 + k . f. One starting contact:
    every root of its law (_slip_angle_roots). Several: their laws in turn (Gauss-Seidel, each contact's root nearest
    its last direction, from the frictionless accelerations' directions) until they settle, one set of directions
    (a second set of coupled slips from rest is not looked for). Empty where the law has no root."""
    tangents = _plane_tangents(scene.ground.normal)
    idx = np.flatnonzero(starting)
    masses = np.asarray(contacts)[idx]
    n_links, m = len(links), idx.size
    others = np.array(directions, float)
    others[idx] = 0.0  # the starting contacts' friction: loads below

    def response(load):
        a, lam, _, _ = _coulomb_mode_solution(scene, X, U, F + load, anchor_acc, links, contacts, stuck, others, mu)
        return a[masses] @ tangents.T, lam[n_links + idx]

    a0, N0 = response(np.zeros_like(F))
    G = np.zeros((m, 2, m, 2))
    k = np.zeros((m, m, 2))
    for j in range(m):
        for i in range(2):
            load = np.zeros_like(F)
            load[masses[j]] = f_scale * tangents[i]
            a, N = response(load)
            G[:, :, j, i] = (a - a0) / f_scale
            k[:, j, i] = (N - N0) / f_scale
    if m == 1:
        found = [d[None] for d in _slip_angle_roots(a0[0], N0[0], G[0, :, 0, :], k[0, 0], mu, along_tol)]
    else:
        size = np.linalg.norm(a0, axis=1)
        d = np.where(size[:, None] > 0, a0 / np.where(size > 0, size, 1.0)[:, None], np.array([1.0, 0.0]))
        f = np.zeros((m, 2))
        for _ in range(50):
            moved = 0.0
            for j in range(m):
                rest = np.arange(m) != j
                a_j = a0[j] + np.einsum("kxy,ky->x", G[j][:, rest, :].transpose(1, 0, 2), f[rest])
                N_j = N0[j] + np.einsum("ky,ky->", k[j, rest], f[rest])
                roots = _slip_angle_roots(a_j, N_j, G[j, :, j, :], k[j, j], mu, along_tol)
                if not roots:
                    return []
                new = min(roots, key=lambda r: float(np.linalg.norm(r - d[j])))
                moved = max(moved, float(np.abs(new - d[j]).max()))
                d[j] = new
                f[j] = -mu * N_j / (1.0 + mu * (k[j, j] @ new)) * new
            if moved <= 1e-14:
                break
        found = [d]
    out = []
    for d2 in found:
        full = np.array(directions, float)
        full[idx] = d2 @ tangents
        out.append(full)
    return out


def _coulomb_choices(uni, U, cand, v_scale):
    """Each touching constraint's modes (cand: unilateral indices): a rope taut or slack; a contact off the ground,
    or on it sliding along its tangential velocity where that is above TOUCH_RTOL of the velocity scale, else (at
    rest along the plane) stuck or slipping from rest."""
    n_ropes, normal = uni.rope_links.size, uni.scene.ground.normal
    choices = []
    for u in cand:
        if u < n_ropes:
            choices.append(("slack", "taut"))
            continue
        v = U[uni.contact_masses[u - n_ropes]]
        moving = np.linalg.norm(v - (v @ normal) * normal) > TOUCH_RTOL * v_scale
        choices.append(("off", "sliding") if moving else ("off", "stuck", "slipping"))
    return choices


def _painleve_modes(scene, uni, X, U, F, anchor_acc, cand, names, scales):
    """Every Coulomb mode of the touching constraints ``cand`` (unilateral indices, as check.py found them) at one
    state, solved from Newton's laws with Coulomb's friction written here (_coulomb_mode_solution): each touching
    rope taut or slack, each touching contact off the ground or on it, and on it sliding along its tangential
    velocity (friction -mu N d, d that velocity's direction) where it moves, else stuck (a grip within the cone) or
    slipping from rest in a direction Coulomb's law allows (_slip_from_rest_directions). A mode satisfies Coulomb's
    law when its taut ropes' tensions and its contacts' normal forces are >= 0, its stuck contacts' grips within
    |F_t| <= mu N, its slips from rest accelerate along their slip (a_t = lambda d, lambda >= 0), the constraints
    it leaves out separate (d2gap/dt2 >= 0), and its equations are consistent, each to RTOL_COMPLEMENTARITY of the
    scales. Returns [(mode in words, accelerations (K, 3), worst violation relative to the scales, which)]."""
    import itertools

    f_scale, v_scale, a_scale = scales
    ground, mu, n_ropes = scene.ground, uni.friction, uni.rope_links.size
    rods = np.flatnonzero(~scene.rope)
    v_t = U - np.outer(U @ ground.normal, ground.normal)
    out = []
    for choice in itertools.product(*_coulomb_choices(uni, U, cand, v_scale)):
        taut = [int(uni.rope_links[u]) for u, c in zip(cand, choice) if c == "taut"]
        on = [(int(uni.contact_masses[u - n_ropes]), c) for u, c in zip(cand, choice) if u >= n_ropes and c != "off"]
        links = np.concatenate([rods, taut]).astype(int)
        contacts = np.array([k for k, _ in on], int)
        stuck = np.array([c == "stuck" for _, c in on], bool)
        starting = np.array([c == "slipping" for _, c in on], bool)
        directions = np.zeros((contacts.size, 3))
        for j, k in enumerate(contacts):
            if not stuck[j] and not starting[j]:
                directions[j] = v_t[k] / np.linalg.norm(v_t[k])
        options = [directions]
        if starting.any():
            options = _slip_from_rest_directions(scene, X, U, F, anchor_acc, links, contacts, stuck, directions,
                                                 starting, mu, f_scale, RTOL_COMPLEMENTARITY * a_scale)
        if not options:
            words = ", ".join(f"{names[u]} {c}" for u, c in zip(cand, choice))
            out.append((words, None, math.inf, "no slip direction from rest satisfies Coulomb's law"))
        for dirs in options:
            a, lam, friction, residual = _coulomb_mode_solution(scene, X, U, F, anchor_acc, links, contacts, stuck,
                                                                dirs, mu)
            worst = [(residual / a_scale, f"its equations inconsistent by {residual:.3g} m/s^2")]
            parts = []
            j = 0
            for u, c in zip(cand, choice):
                if u < n_ropes:
                    l = int(uni.rope_links[u])
                    if c == "taut":
                        T = lam[rods.size + taut.index(l)]
                        worst.append((-T / f_scale, f"{names[u]}: tension {T:.6g} N"))
                        parts.append(f"{names[u]} taut")
                    else:
                        d = X[scene.k2[l]] - X[scene.k1[l]]
                        g2 = float(_gap_second_derivatives(d[None], (U[scene.k2[l]] - U[scene.k1[l]])[None],
                                                           (a[scene.k2[l]] - a[scene.k1[l]])[None])[0])
                        worst.append((-g2 / a_scale, f"{names[u]} (slack): d2gap/dt2 {g2:.6g} m/s^2"))
                        parts.append(f"{names[u]} slack")
                    continue
                k = int(uni.contact_masses[u - n_ropes])
                if c == "off":
                    g2 = float(a[k] @ ground.normal)
                    worst.append((-g2 / a_scale, f"{names[u]} (off the ground): d2gap/dt2 {g2:.6g} m/s^2"))
                    parts.append(f"{names[u]} off the ground")
                    continue
                N = lam[links.size + j]
                worst.append((-N / f_scale, f"{names[u]} ({c}): normal force {N:.6g} N"))
                if c == "stuck":
                    grip = float(np.linalg.norm(friction[j]))
                    worst.append(((grip - mu * N) / f_scale,
                                  f"{names[u]} (stuck): |F_t| {grip:.6g} N beyond mu N {mu * N:.6g} N"))
                    parts.append(f"{names[u]} stuck")
                elif c == "slipping":
                    a_t = a[k] - (a[k] @ ground.normal) * ground.normal
                    along = float(a_t @ dirs[j])
                    across = float(np.linalg.norm(a_t - along * dirs[j]))
                    worst.append((max(-along, across) / a_scale,
                                  f"{names[u]} (slipping from rest along {np.round(dirs[j], 6).tolist()}): tangential "
                                  f"acceleration {np.round(a_t, 6).tolist()} m/s^2"))
                    parts.append(f"{names[u]} slipping from rest along {np.round(dirs[j], 6).tolist()}")
                else:
                    parts.append(f"{names[u]} sliding along {np.round(dirs[j], 6).tolist()}")
                j += 1
            value, which = max(worst, key=lambda w: w[0])
            out.append((", ".join(parts), a, float(value), which))
    return out


class _Painleve:
    """How many solutions Coulomb's law has at each state with a touching contact on the rough ground, and the
    states where it has several or none, in the scene's words."""

    def __init__(self):
        self.unique = self.capped = 0
        self.ambiguous, self.inconsistent = [], []  # (t, words, relative size)
        self.cap_reason = ""

    def add(self, scene, uni, X, U, F, anchor_acc, A, cand, names, at, scales):
        """Enumerate the Coulomb modes at one state (_painleve_modes) and file it: one solution, several (their
        accelerations more than RTOL_DISTINCT_SOLUTIONS of the scale apart; linknet's named, and the others), or
        none (each mode with the condition it breaks worst)."""
        count = math.prod(len(c) for c in _coulomb_choices(uni, U, cand, scales[1]))
        if count > COULOMB_MODES_MAX:
            self.capped += 1
            self.cap_reason = (f"more Coulomb modes than COULOMB_MODES_MAX = {COULOMB_MODES_MAX} ({count} of "
                               f"{cand.size} touching rope(s) and contact(s) at {at})")
            return
        a_scale = scales[2]
        modes = _painleve_modes(scene, uni, X, U, F, anchor_acc, cand, names, scales)
        valid = [(words, a) for words, a, value, _ in modes if value <= RTOL_COMPLEMENTARITY]
        free = ~(scene.fixed | scene.driven)
        solutions = []  # [(accelerations, [words of the modes giving them])]
        for words, a in valid:
            for sol in solutions:
                if np.abs((sol[0] - a)[free]).max(initial=0.0) <= RTOL_DISTINCT_SOLUTIONS * a_scale:
                    sol[1].append(words)
                    break
            else:
                solutions.append((a, [words]))
        if not solutions:
            broken = "; ".join(f"[{words}] breaks {which}" for words, _, _, which in modes)
            nearest = min(value for _, _, value, _ in modes)
            self.inconsistent.append((at, f"no mode satisfies Coulomb's law ({len(modes)} tried: {broken})", nearest))
        elif len(solutions) == 1:
            self.unique += 1
        else:
            apart = [float(np.abs((a - A)[free]).max(initial=0.0)) for a, _ in solutions]
            mine = int(np.argmin(apart))
            spread = max(float(np.abs((a - b)[free]).max(initial=0.0)) for a, _ in solutions for b, _ in solutions)
            if apart[mine] <= RTOL_DISTINCT_SOLUTIONS * a_scale:
                chosen = f"linknet's [{solutions[mine][1][0]}]"
                others = [i for i in range(len(solutions)) if i != mine]
            else:
                chosen = f"linknet's accelerations are none of them ({apart[mine]:.3g} m/s^2 from the nearest)"
                others = list(range(len(solutions)))
            rest = " and ".join(f"[{solutions[i][1][0]}] (accelerations {apart[i]:.3g} m/s^2 from linknet's)"
                                for i in others)
            self.ambiguous.append((at, f"{len(solutions)} solutions of Coulomb's law: {chosen}, and {rest}",
                                   spread / a_scale))

    def result(self, mu):
        name = "Coulomb friction: one solution (Painleve)"
        n = self.unique + len(self.ambiguous) + len(self.inconsistent)
        cap = f"; {self.capped} state(s) not enumerated: {self.cap_reason}" if self.capped else ""
        if not n:
            return CheckResult(name, True, 0.0, RTOL_COMPLEMENTARITY, cap.lstrip("; ") or
                               "no contact touched the rough ground at the sampled states", skipped=True)

        def named(cases, what):
            listed = "".join(f"; {what} at {at}: {words}" for at, words, _ in cases[:PAINLEVE_NAMED])
            more = len(cases) - PAINLEVE_NAMED
            return listed + (f"; and {more} more such state(s)" if more > 0 else "")

        detail = (f"{n} state(s) with a touching contact on the rough ground (mu {mu:g}), every Coulomb mode of their "
                  "touching ropes and contacts (ropes taut or slack; contacts off the ground, sliding along their "
                  "velocity, or at rest stuck or slipping from rest in the law's directions) solved from (9), "
                  f"(25)-(26) with Coulomb's friction: {self.unique} with one solution, {len(self.ambiguous)} with "
                  f"several (ambiguous), {len(self.inconsistent)} with none (inconsistent){cap}")
        if self.inconsistent:
            worst = max(value for _, _, value in self.inconsistent)
            return CheckResult(name, False, worst, RTOL_COMPLEMENTARITY,
                               detail + named(self.inconsistent, "INCONSISTENT") + named(self.ambiguous, "AMBIGUOUS"))
        if self.ambiguous:
            spread = max(value for _, _, value in self.ambiguous)
            return CheckResult(name, True, spread, RTOL_DISTINCT_SOLUTIONS,
                               detail + " (the run follows one of several rigid motions there)"
                               + named(self.ambiguous, "AMBIGUOUS"), warning=True)
        return CheckResult(name, True, 0.0, RTOL_DISTINCT_SOLUTIONS, detail)


def run_unilateral_checks(scene, samples=5, seed=0, kernel=False, native=True, states=None):
    """The checks of a scene with ropes or a ground: today's checks (run_checks) on its taut system (taut_mode), and
    the complementarity conditions and the LCP against enumeration at the states of a run (unilateral_states, or
    ``states``). Returns (taut system in words, the taut checks, the complementarity checks, the run's states)."""
    mode_scene, mode_dyn, words = taut_mode(scene)
    with single_threaded_blas():
        taut = _run_checks(mode_scene, samples, seed, mode_dyn, None, None, kernel, native)
        if states is None:
            states, _ = unilateral_states(scene)
        comp = _check_unilateral(scene, SymbolicTensionSystem(scene), states)
    return words, taut, comp, states


# ------------------------------------------------------------------------------------------------
# command line
# ------------------------------------------------------------------------------------------------

class single_threaded_blas:
    """Context manager: OpenBLAS (numpy's and scipy's copies) limited to one thread, restored after.

    The checks do many small dense decompositions (a few hundred rows). On a machine whose cores are
    busy, OpenBLAS's threads spin against each other: a 420-link net took 114 s instead of 3.7 s.
    Linux only (the loaded libraries are found in /proc/self/maps); elsewhere it does nothing.
    """

    _SETTERS = ("scipy_openblas_set_num_threads64_", "scipy_openblas_set_num_threads",
                "openblas_set_num_threads64_", "openblas_set_num_threads")

    def __enter__(self):
        import ctypes

        self._restore = []
        try:
            with open("/proc/self/maps") as maps:
                paths = {line.split()[-1] for line in maps if "openblas" in line.lower() and "/" in line}
        except OSError:
            return self
        for path in sorted(paths):
            try:
                lib = ctypes.CDLL(path)
            except OSError:
                continue
            for name in self._SETTERS:
                setter = getattr(lib, name, None)
                getter = getattr(lib, name.replace("set_", "get_"), None)
                if setter is not None and getter is not None:
                    previous = int(getter())
                    setter(1)
                    self._restore.append((setter, getter, previous))
                    break
        return self

    def __exit__(self, *exc):
        for setter, _, previous in self._restore:
            setter(previous)
        return False

    def thread_counts(self):
        return [int(getter()) for _, getter, _ in self._restore]


def add_arguments(parser: argparse.ArgumentParser) -> None:
    from linknet_core.options import count, random_seed, readable_file

    parser.add_argument("scene", nargs="+", type=readable_file, help="scene JSON file(s), e.g. models/chain_10.json")
    parser.add_argument("--samples", type=count, default=5,
                        help="random states on the manifold, and as many off it (default 5)")
    parser.add_argument("--seed", type=random_seed, default=0, help="random seed (default 0)")
    parser.add_argument("--kernel", action="store_true",
                        help="also generate and compile the scene's casadi kernel and compare it (needs a C compiler)")


def main(args) -> int:
    from linknet_core.scene.description import load_scene

    if args.samples < 1:
        print("linknet check: --samples must be at least 1", file=sys.stderr)
        return 2
    failed = 0
    for path in args.scene:
        t0 = time.perf_counter()
        try:
            scene = load_scene(path)
        except ValueError as exc:
            print(f"linknet check: {exc}", file=sys.stderr)
            return 2
        n_fixed = int(np.count_nonzero(np.asarray(scene.inv_mass) == 0))
        print(f"{path}: K={scene.K} masses ({n_fixed} anchored), L={scene.L} links; {args.samples} states on and "
              f"{args.samples} off the manifold, seed {args.seed}")
        if scene.unilateral:
            words, taut, comp, states = run_unilateral_checks(scene, samples=args.samples, seed=args.seed,
                                                              kernel=getattr(args, "kernel", False))
            print(f"{words}:")
            for r in taut:
                print(r.line())
            print(f"the complementarity conditions at {len(states)} states of a dop853 run (rtol "
                  f"{UNILATERAL_RTOL:g}) to {states[-1][0]:g} s:")
            for r in comp:
                print(r.line())
            results = taut + comp
        else:
            results = run_checks(scene, samples=args.samples, seed=args.seed, kernel=getattr(args, "kernel", False))
            for r in results:
                print(r.line())
        bad = sum(not r.passed for r in results)
        warned = sum(r.passed and r.warning for r in results)
        failed += bad
        print(f"{'all checks passed' if not bad else f'{bad} check(s) FAILED'}"
              f"{f', {warned} with a WARNING' if warned else ''} in "
              f"{time.perf_counter() - t0:.2f} s\n")
    return 1 if failed else 0


if __name__ == "__main__":  # python -m linknet_core.symbolic.check SCENE
    p = argparse.ArgumentParser(prog="linknet check")
    add_arguments(p)
    sys.exit(main(p.parse_args()))
