"""Interface Jacobians: how the instantaneous outputs answer the inputs at a fixed state (X, U).

A network coupled to other components takes inputs, the external forces F_k on free masses and the position,
velocity and acceleration (P_a, V_a, A_a) of its input-driven anchors, and gives outputs that depend on them at
once (direct feedthrough): the tensions T of (25)-(26), the force the network exerts on each anchor,
Freact_a = (C^T T)_a, the link term of (9) at the anchored mass, and the accelerations dU/dt of (9). The state
X, U itself has no direct feedthrough. This module gives the exact derivatives of those outputs with respect to
the inputs, derived from the tension system, not by finite differences: what a co-simulation master needs to
couple the network implicitly (fmi2GetDirectionalDerivative), and the effective mass of the network at a driven
anchor, -dFreact/dA (docs/interface_jacobians.md).

The inputs enter the equations in these places (drive.py): a driven anchor's rows of X and U hold P_a and V_a, so P
moves the link directions E_l (8) and V the relative velocities of (26); A_a stands for F/M on the anchor's side of
B (26); F enters B through a_k = F_k / M_k and the accelerations (9) directly; a force element (a spring) hooked to
a driven anchor moves its forces on free masses with P and V. Writing delta for the derivative along a seed
(dF, dP, dV, dA), with dX, dU the seed's P, V on the driven rows and zero elsewhere:

    dE_l = (dX_k2 - dX_k1) / R_l                                                                       (8)
    dF   = dF_input + (d element forces / d(X, U)) (dX, dU),  zero on anchored rows                    (9)
    da_k = dF_k / M_k on a free mass, dA_a on a driven anchor, 0 on a fixed one
    dB_l = 2 (U_k2 - U_k1) . (dU_k2 - dU_k1) / R_l + dE_l . (a_k2 - a_k1) + E_l . (da_k2 - da_k1)     (26)
    dA   = dC M^-1 C^T + C M^-1 dC^T                (A = C M^-1 C^T of (25); row l of dC: dE_l, -dE_l)

Where A is regular, A T = B gives dT = A^-1 (dB - dA T): one solve with the factorisation of A that the tensions
used. Where A is singular (self-stresses (27)-(31): redundant links, or a singular configuration) the tensions are
the minimum-norm T = A^+ B, and its derivative is that of the pseudo-inverse (Golub and Pereyra 1973) for
symmetric A, with Pi = A A^+ the projector onto range(A):

    dT = A^+ (dB - dA T) + A^+ A^+ dA (I - Pi) B + (I - Pi) dA A^+ T.

The second term vanishes where B is consistent ((32): on the manifold (11)-(12) with hypothesis (35)); it is kept,
so that the derivative is exact off the manifold too. The formula holds where the rank of A is constant near the
state along the seed: the pseudo-inverse is not differentiable where a self-stress appears or disappears (a loop
passing a flat position, a string pulled straight), and the derivative there is the one-sided derivative along
the directions that keep the rank. The rank is the solver's own (its cut at SINGULAR_RCOND), so the derivative is
that of the tensions it reports.

The outputs then follow by the product rule: d(C^T T) = C^T dT + dC^T T, the accelerations
d(dU_k/dt) = (dF_k + d(C^T T)_k) / M_k on free masses, dA_a on driven anchors, zero on fixed ones, and dFreact the
anchored rows of d(C^T T).

:class:`ReferenceLinearization` is the numpy reference, built from Dynamics' own pieces (the unit vectors, B of
(26), C^T w, C V and the tension solver, with its factorisation); linknet_core.native.interface runs the same
formulas in the C core (src/interface_jacobian.c). Both are linearizations: one object per state, whose
``directional`` is the derivative along one seed (one solve where A is regular) and whose ``jacobian`` assembles
every column into named blocks (:class:`InterfaceJacobian`).
"""
from __future__ import annotations

import numpy as np

from linknet_core.dynamics.forces import scatter_add
from linknet_core.dynamics.tensions import rhs, unit_vectors
from linknet_core.errors import SolverError
from linknet_core.scene.description import Scene, require_force_kinds

OUTPUTS = ("T", "Freact", "acc")
INPUTS = ("F", "P", "V", "A")
INPUT_UNITS = {"F": "N", "P": "m", "V": "m/s", "A": "m/s2"}


# ---- the force elements' derivatives ---------------------------------------------------------------------------
# The derivative of each kind's forces (linknet_core.dynamics.forces.ELEMENT_KINDS) along (dX, dU) at (X, U). Only
# an element that reaches a free mass from a driven anchor (a spring hooked to it) gives the inputs a path through
# the forces, but each is the kind's full derivative, checked against its forces by differences in the tests.

def _drag_derivative(K, X, U, dX, dU, masses, c):
    """d(-c U_k) = -c dU_k."""
    k = masses[:, 0]
    return scatter_add(K, k, -c[:, :1] * dU[k])


def _quadratic_drag_derivative(K, X, U, dX, dU, masses, c):
    """d(-c |U| U) = -c (|U| dU + U (U . dU) / |U|) (zero at rest, where the force is flat)."""
    k = masses[:, 0]
    u, du = U[k], dU[k]
    speed = np.linalg.norm(u, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = np.where(speed > 0, np.einsum("ij,ij->i", u, du) / speed, 0.0)
    return scatter_add(K, k, -c[:, :1] * (speed[:, None] * du + along[:, None] * u))


def _spring_derivative(K, X, U, dX, dU, masses, p):
    """The spring-damper f n, f = k (d - d0) + c (n . (U_b - U_a)), n = (X_b - X_a) / d, +f n on a and -f n on b:
    d(f n) = df n + f dn, dn = (I - n n^T) d(X_b - X_a) / d, df = k n . d(X_b - X_a) + c (dn . (U_b - U_a) +
    n . d(U_b - U_a)) (no force, so no derivative, where the ends coincide)."""
    a, b = masses[:, 0], masses[:, 1]
    d = X[b] - X[a]
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    live = dist > 0
    safe = np.where(live, dist, 1.0)[:, None]
    n = np.where(live[:, None], d / safe, 0.0)
    dd, ddu, du = dX[b] - dX[a], dU[b] - dU[a], U[b] - U[a]
    dn = np.where(live[:, None], (dd - n * np.einsum("ij,ij->i", n, dd)[:, None]) / safe, 0.0)
    f = p[:, 0] * (dist - p[:, 1]) + p[:, 2] * np.einsum("ij,ij->i", n, du)
    df = p[:, 0] * np.einsum("ij,ij->i", n, dd) + p[:, 2] * (np.einsum("ij,ij->i", dn, du) +
                                                              np.einsum("ij,ij->i", n, ddu))
    dfn = np.where(live[:, None], df[:, None] * n + f[:, None] * dn, 0.0)
    return scatter_add(K, a, dfn) - scatter_add(K, b, dfn)


ELEMENT_DERIVATIVES = {
    "drag": _drag_derivative,
    "quadratic_drag": _quadratic_drag_derivative,
    "spring": _spring_derivative,
}
require_force_kinds(ELEMENT_DERIVATIVES, "the interface Jacobians (linknet_core.dynamics.interface_jacobian."
                                         "ELEMENT_DERIVATIVES)")


def element_force_derivative(scene: Scene, X: np.ndarray, U: np.ndarray, dX: np.ndarray,
                             dU: np.ndarray) -> np.ndarray:
    """The derivative of the force elements' forces (forces.element_forces) at (X, U) along (dX, dU), (K,3)."""
    dF = np.zeros_like(X)
    elements = scene.force_elements
    for kind in dict.fromkeys(elements.kinds):
        dF += ELEMENT_DERIVATIVES[kind](scene.K, X, U, dX, dU, *elements.of_kind(kind))
    return dF


# ---- named blocks ---------------------------------------------------------------------------------------------
class InterfaceJacobian:
    """Every derivative of an output with respect to an input at one state, as named blocks.

    ``J["T", "F"]`` has shape (L, K, 3): dT_l / dF[k, i] (columns of anchored masses are zero: no force acts on an
    anchor); ``J["Freact", "A"]`` has shape (n_anchored, 3, n_seeded, 3): dFreact[a, i] / dA[j, i'], rows the
    anchored masses in scene order (``anchored``, as outputs()["Freact"]), columns the seeded driven anchors
    (``anchors``, as ``anchors=(P, V, A)`` orders them); ``J["acc", ...]`` the accelerations (K, 3). Each block is
    an output's shape followed by an input's: ``matrix(output, input)`` flattens it to 2-D."""

    def __init__(self, blocks: dict, anchored: np.ndarray, anchors: np.ndarray):
        self.blocks = blocks
        self.anchored = anchored  # mass indices of the rows of Freact
        self.anchors = anchors  # mass indices of the seeded driven anchors (the rows of P, V, A)

    def __getitem__(self, key):
        return self.blocks[key]

    def matrix(self, output: str, input: str) -> np.ndarray:
        block = self.blocks[output, input]
        n_out = {"T": 1, "Freact": 2, "acc": 2}[output]
        rows = int(np.prod(block.shape[:n_out]))
        return block.reshape(rows, -1)

    def effective_mass(self, anchor: int = 0) -> np.ndarray:
        """The effective (apparent) mass tensor (3, 3) of the network at seeded driven anchor ``anchor`` (its
        position among ``anchors``): -dFreact_a / dA_a, the force the network's inertia opposes to the anchor's
        acceleration, per unit acceleration (docs/interface_jacobians.md). Symmetric, positive semi-definite."""
        k = int(self.anchors[anchor])
        row = int(np.searchsorted(self.anchored, k))
        return -self.blocks["Freact", "A"][row, :, anchor, :]


# ---- a linearization at one state --------------------------------------------------------------------------------
class InterfaceLinearization:
    """The interface derivatives at one state: ``directional`` along one seed, ``jacobian`` every column. Subclasses
    give ``_directional(dF, dP, dV, dA) -> (dT, dFreact, dacc)`` on full seeds: dF (K,3), dP, dV, dA (n_seeded,3)."""

    def __init__(self, scene: Scene, anchors: np.ndarray):
        self.scene = scene
        self.anchors = np.asarray(anchors, np.int64)  # the seeded driven anchors, mass indices in scene order
        self.anchored = scene.fixed_indices

    def _seed(self, name: str, value, rows: int) -> np.ndarray:
        if value is None:
            return np.zeros((rows, 3))
        a = np.asarray(value, float)
        if a.shape != (rows, 3):
            what = (f"one row per mass of the scene ({self.scene.K})" if name == "F" else
                    f"one row per seeded driven anchor ({rows})")
            raise SolverError(f"the seed d{name} of a directional derivative must have shape ({rows}, 3) ({what}), "
                              f"got {a.shape}")
        if not np.all(np.isfinite(a)):
            i, j = np.argwhere(~np.isfinite(a))[0]
            k = i if name == "F" else int(self.anchors[i])
            raise SolverError(f"the seed d{name}[{k + 1},{j + 1}] ({INPUT_UNITS[name]}) of "
                              f"{self.scene.mass_label(int(k))} is {a[i, j]}: a seed must be finite")
        return a

    def directional(self, dF=None, dP=None, dV=None, dA=None) -> dict:
        """The derivatives of the outputs along one seed: dF (K,3) on the input forces, dP, dV, dA (n_seeded,3) on
        the seeded anchors' motion (None: zero). {"T": (L,), "Freact": (n_anchored,3), "acc": (K,3)}."""
        n = self.anchors.size
        if n == 0 and any(s is not None for s in (dP, dV, dA)):
            raise SolverError(f"{self.scene.name} has no input-driven anchors: a seed dP, dV or dA has nothing to move")
        dT, dFreact, dacc = self._directional(self._seed("F", dF, self.scene.K), self._seed("P", dP, n),
                                              self._seed("V", dV, n), self._seed("A", dA, n))
        return {"T": dT, "Freact": dFreact, "acc": dacc}

    def jacobian(self) -> InterfaceJacobian:
        """Every block, one directional derivative per input column (the anchored masses' F columns are zero)."""
        scene = self.scene
        K, L, n = scene.K, scene.L, self.anchors.size
        shapes = {"T": (L,), "Freact": (self.anchored.size, 3), "acc": (K, 3)}
        rows = {"F": K, "P": n, "V": n, "A": n}
        blocks = {(o, i): np.zeros(shapes[o] + (rows[i], 3)) for o in OUTPUTS for i in INPUTS}
        zero_K, zero_n = np.zeros((K, 3)), np.zeros((n, 3))
        for name in INPUTS:
            columns = scene.free_indices if name == "F" else range(n)
            for k in columns:
                for i in range(3):
                    unit = np.zeros((rows[name], 3))
                    unit[k, i] = 1.0
                    seeds = [zero_K, zero_n, zero_n, zero_n]
                    seeds[INPUTS.index(name)] = unit
                    for o, value in zip(OUTPUTS, self._directional(*seeds)):
                        blocks[o, name][..., k, i] = value
        return InterfaceJacobian(blocks, self.anchored, self.anchors)

    def _directional(self, dF, dP, dV, dA):
        raise NotImplementedError


class ReferenceLinearization(InterfaceLinearization):
    """The numpy reference at (X, U), whose driven rows hold the anchors' P, V (as Dynamics.tensions takes them),
    with the input forces ``F_input`` (K,3) and the driven anchors' accelerations ``anchor_acc`` (K,3; None: none).
    ``anchors``: the driven anchors whose P, V, A are seeded (default the input-driven ones)."""

    def __init__(self, dyn, X, U, F_input=None, anchor_acc=None, anchors=None):
        scene = dyn.scene
        super().__init__(scene, scene.input_driven_indices if anchors is None else anchors)
        if not np.all(scene.driven[self.anchors]):
            k = int(self.anchors[~scene.driven[self.anchors]][0])
            raise SolverError(f"{scene.mass_label(k)} is not a driven anchor: only a driven anchor's P, V, A are inputs")
        self.dyn = dyn
        self.X = np.array(X, float)
        self.U = np.array(U, float)
        self.anchor_acc = np.zeros_like(self.X) if anchor_acc is None else np.asarray(anchor_acc, float)
        self.F = dyn.forces(self.X, self.U, F_input)
        self.E = unit_vectors(scene, self.X)
        self.T = dyn.tensions(self.X, self.U, F_input, anchor_acc=self.anchor_acc)
        self._inv_mass3 = scene.inv_mass[:, None]
        self.a = self.F * self._inv_mass3 + self.anchor_acc  # a_k of (26): F/M, A_a on driven anchors
        self.g = self._link_accelerations(self.E, self.T)  # M^-1 C^T T
        self.singular = scene.L > 0 and (dyn.structure.kind == "redundant" or dyn._solver_singular())
        if self.singular:
            B = rhs(scene, self.X, self.U, self.F, self.E, self.anchor_acc)
            self.inconsistent = B - self._A_times(self.T)  # (I - Pi) B: B less A A^+ B
            self.T_solved = self._solve(self.T)  # A^+ T

    # C^T w, C V and the solves, with Dynamics' own pieces
    def _link_accelerations(self, E, w):
        """M^-1 C(E)^T w: what tensions w do to the free masses' accelerations (zero on anchors)."""
        return self.dyn._scatter(E, w) * self._inv_mass3

    def _A_times(self, y):
        return self.dyn.constraint_rows(self.X, self._link_accelerations(self.E, y), self.E)

    def _dA_times(self, dE, y):
        """(dC M^-1 C^T + C M^-1 dC^T) y."""
        return (self.dyn.constraint_rows(self.X, self._link_accelerations(self.E, y), dE)
                + self.dyn.constraint_rows(self.X, self._link_accelerations(dE, y), self.E))

    def _solve(self, b):
        self.dyn.factor(self.X, self.E)  # the factorisation the tensions used (kept unless X changed)
        return self.dyn.solver.solve(b)

    def _directional(self, dF, dP, dV, dA):
        scene, dyn = self.scene, self.dyn
        rows = self.anchors
        dX, dU, d_anchor_acc = np.zeros_like(self.X), np.zeros_like(self.X), np.zeros_like(self.X)
        dX[rows], dU[rows], d_anchor_acc[rows] = dP, dV, dA
        dF = dF + element_force_derivative(scene, self.X, self.U, dX, dU)
        dF[scene.fixed] = 0.0  # no force acts on an anchor
        if scene.L == 0:
            return np.zeros(0), np.zeros((self.anchored.size, 3)), dF * self._inv_mass3 + d_anchor_acc
        dE = unit_vectors(scene, dX)
        k1, k2 = scene.k1, scene.k2
        dU_link = self.U[k2] - self.U[k1]
        dB = (2.0 * np.einsum("ij,ij->i", dU_link, dU[k2] - dU[k1]) / scene.length
              + rhs(scene, self.X, np.zeros_like(self.U), self.F, dE, self.anchor_acc)  # dE . (a_k2 - a_k1)
              + rhs(scene, self.X, np.zeros_like(self.U), dF, self.E, d_anchor_acc))  # E . (da_k2 - da_k1)
        dT = self._solve(dB - self._dA_times(dE, self.T))
        if self.singular:
            # the pseudo-inverse's derivative: the range of A turns with the geometry
            dT += self._solve(self._solve(self._dA_times(dE, self.inconsistent)))
            w = self._dA_times(dE, self.T_solved)
            dT += w - self._A_times(self._solve(w))  # (I - Pi) w
        d_link_force = dyn._scatter(self.E, dT) + dyn._scatter(dE, self.T)  # d(C^T T)
        dacc = (dF + d_link_force) * self._inv_mass3 + d_anchor_acc
        dFreact = dyn.anchor_reactions(self.X, dT) + dyn.anchor_reactions(dX, self.T)  # bilinear in (X, T)
        return dT, dFreact, dacc


class SceneRowsLinearization(InterfaceLinearization):
    """A linearization of a larger network read back on ``scene``'s rows: ``inner`` linearizes a network whose first
    masses are the scene's and whose further masses are virtual anchors (a ground's contacts: links from their masses
    to anchors above them, unilateral.native_ground_scene, ModeDynamics' mode scene). ``links``: the scene's link of
    each of the inner network's first links.size links (the others, the contacts', come after). The inputs are the
    scene's: the anchors are fixed, so no force acts on them and none is an input, their rows of the seeds are 0.
    The outputs are the scene's: T of its links (0 where ``links`` leaves one out), Freact of its anchored masses
    (the inner network's first anchored rows, the virtual anchors' following), acc of its masses."""

    def __init__(self, scene: Scene, inner: InterfaceLinearization, links: np.ndarray):
        super().__init__(scene, inner.anchors)
        self.inner = inner
        self.links = np.asarray(links, np.int64)
        self.singular = inner.singular
        self._virtual = np.zeros((inner.scene.K - scene.K, 3))

    def _directional(self, dF, dP, dV, dA):
        dT_inner, dFreact, dacc = self.inner._directional(np.concatenate([dF, self._virtual]), dP, dV, dA)
        dT = np.zeros(self.scene.L)
        dT[self.links] = dT_inner[:self.links.size]
        return dT, dFreact[:self.anchored.size], dacc[:self.scene.K]


class ModeLinearization(SceneRowsLinearization):
    """The numpy reference for a scene with ropes or a frictionless ground (UnilateralDynamics ``dyn``) at (X, U), as
    ReferenceLinearization takes them: the derivatives of the current mode's outputs. The mode is the one the outputs
    are evaluated in (UnilateralDynamics.state_mode: the acceleration LCP on the touching ropes and contacts, at this
    state and these inputs), and within it the network is the seed's system with the slack ropes left out and each
    active contact a link of length R_c to a virtual anchor straight above its mass (ModeDynamics.inner), whose
    (25)-(26) ReferenceLinearization differentiates, minimum-norm (31) where the mode is redundant. A contact's link
    has E along the plane's normal n and the term (n . U_k)^2 / R_c in (26); its anchor is placed from the state
    alone (ModeDynamics.pad, pad_velocity), so it does not move with the inputs, and its acceleration (its mass's
    along the plane) would enter (26) only as E . a_Q = 0: the anchor is fixed in the linearization, exactly. The
    contact's tension, the ground's normal force, answers the inputs and moves the accelerations, but is no output.
    A slack rope's T is 0 with derivative 0. The mode is held fixed: an input that would turn a taut rope's tension
    or a contact's normal force negative (or pull a slack rope taut) changes the mode, and the derivative there is
    the one-sided one of the current mode's outputs. A rough ground's grips and sliding loads are refused
    (unilateral.linearization_refusal)."""

    def __init__(self, dyn, X, U, F_input=None, anchor_acc=None, anchors=None):
        scene = dyn.scene
        md = dyn.state_mode(X, U, F_input, anchor_acc)
        if md.stuck_masses.size or md.sliding.size:
            raise SolverError(f"{scene.name}: masses on a rough ground: the outputs' linearization is not given with "
                              "friction (linearization_refusal)")
        inner = ReferenceLinearization(md.inner, md.pad(X), md.pad_velocity(X, U), md._pad_zero(F_input),
                                       md._pad_zero(anchor_acc),
                                       anchors=scene.input_driven_indices if anchors is None else anchors)
        super().__init__(scene, inner, md.links)
        self.mode = md
        self.T = np.zeros(scene.L)
        self.T[md.links] = inner.T[:md.links.size]
