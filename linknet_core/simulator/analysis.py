"""Rigidity analysis (``linknet analyze``): Maxwell-Calladine counts at the initial configuration.

With n = 3 K_free velocity unknowns and L links, rank r of the constraint Jacobian G (rows of (12)):
    degrees of freedom   m = n - r   (first-order motions allowed by the links)
    states of self-stress s = L - r  (the homogeneous solutions of (27), i.e. the T~ of (31))
so that n - L = m - s (Maxwell's rule corrected by Calladine). Of the m motions, those that move the
whole network as a rigid body (allowed by the anchors) are trivial; the rest are internal mechanisms.
The structure is rigid when there are none.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linknet_core.dynamics.equations import Dynamics
from linknet_core.native.model import NativeModel
from linknet_core.simulator.specialisation import Specialisation, choose_specialisation
from linknet_core.scene.description import Scene
from linknet_core.structure.rigidity import DENSE_RIGIDITY_LIMIT, second_order_rigid_flexes


@dataclass
class RigidityReport:
    scene: Scene
    dyn: Dynamics
    K: int
    L: int
    anchored: list
    rank_G: int
    rank_exact: bool
    dof: int
    rigid_body_motions: int
    mechanisms: int
    self_stresses: int
    condition_A: float
    condition_note: str
    specialisation: Specialisation  # the path a Simulator takes for this scene (linknet_core.simulator.specialisation)
    # flexes of the initial configuration blocked only at second order by a self-stress (structure.rigidity): the
    # minimum-norm tensions (31) give them no resistance, so a run that loads one stops or loses the motion
    blocked_flexes: list = None

    @property
    def rigid(self) -> bool:
        return self.mechanisms == 0

    def text(self) -> str:
        st = self.dyn.structure
        s = self.scene
        anchored = ", ".join(s.mass_label(k) for k in self.anchored[:8]) or "none"
        if len(self.anchored) > 8:
            anchored += f" and {len(self.anchored) - 8} more"
        native = NativeModel(s, st)
        specialisations = [f"structure class {st.kind} (topology {st.topology}); tension solver {native.solver}"]
        if native.solver == "ldl":
            specialisations.append(f"LDL^T with symbolic analysis once: nnz(L) = {native.nnz_L} "
                                   f"({'no fill, O(L)' if st.topology in ('chain', 'tree') else 'fill-reducing ordering'})")
        if st.planar_normal is not None:
            normal = np.round(st.planar_normal, 6).tolist()
            specialisations.append(f"planar scene (normal {normal})" if native.plane is not None else
                                   f"planar at the start (normal {normal}), run in 3-D: driven anchors may leave "
                                   "the plane")
        if self.anchored:
            specialisations.append(f"{len(self.anchored)} anchored masses eliminated (1/M = 0)")
        lines = [
            f"scene {s.name}: K = {self.K} masses, L = {self.L} links, {s.springs.count} springs",
            f"anchored masses: {anchored}",
            f"rank of G: {self.rank_G}{'' if self.rank_exact else ' (estimated from LDL pivots)'} "
            f"(of {self.L} links, {3 * (self.K - len(self.anchored))} free coordinates)",
            f"degrees of freedom: {self.dof} = {self.rigid_body_motions} rigid-body motions + {self.mechanisms} "
            "internal mechanisms",
            f"states of self-stress: {self.self_stresses}"
            + (" (redundant links: minimum-norm tensions)" if self.self_stresses else ""),
            f"Maxwell-Calladine check: 3K_free - L = {3 * (self.K - len(self.anchored)) - self.L} = "
            f"mechanisms + rigid-body motions - self-stresses = {self.dof - self.self_stresses}",
            f"rigid: {'yes' if self.rigid else 'no'}" + ("" if self.rigid else f" ({self.mechanisms} mechanisms)"),
            f"closed loops (anchors merged): {st.closed_loops}",
            f"condition estimate of A at the initial state: {self.condition_A:.3e} ({self.condition_note})",
            "solver: " + "; ".join(specialisations),
        ]
        lines.append(f"specialisation: {self.specialisation.text()}")
        native_path = native.describe()
        if self.specialisation.kind != "none":
            native_path += f" (not used: the {self.specialisation.kind} specialisation stands in)"
        if s.unilateral:  # ropes or a ground: their own description says which path runs them
            from linknet_core.dynamics.unilateral import describe

            lines += describe(s)
        else:
            lines.append(f"native path (RATTLE, compositions, Runge-Kutta): {native_path}")
        if self.blocked_flexes is None:
            lines.append("second-order rigidity: not checked (no self-stress, or above the check's size limit)")
        elif not self.blocked_flexes:
            lines.append("second-order rigidity: no flex blocked only at second order")
        else:
            lines.append(f"second-order rigidity: {len(self.blocked_flexes)} flexes blocked only at second order (a "
                         "run that loads one stops, naming them, or its error estimate flags it; docs/accuracy.md):")
            lines += [f"  {flex.description}" for flex in self.blocked_flexes]
        lines += [f"note: {n}" for n in st.notes]
        return "\n".join(lines)


def _rigid_body_motions(scene: Scene) -> int:
    """Dimension of the rigid velocity fields v_k = t + w x X_k that leave the anchors at rest, as seen
    on the free masses."""
    X = scene.X0

    def fields(idx):  # rows of v_k = t + w x X_k = [I | skew(X_k)] (t, w), three per mass
        x = X[idx]
        rows = np.zeros((idx.size, 3, 6))
        rows[:, [0, 1, 2], [0, 1, 2]] = 1.0
        rows[:, 0, 4], rows[:, 0, 5] = x[:, 2], -x[:, 1]
        rows[:, 1, 3], rows[:, 1, 5] = -x[:, 2], x[:, 0]
        rows[:, 2, 3], rows[:, 2, 4] = x[:, 1], -x[:, 0]
        return rows.reshape(-1, 6)

    anchors = scene.fixed_indices
    basis = np.eye(6)
    if anchors.size:
        # six zero rows below: a thin SVD then still gives all six right singular vectors
        _, sv, vt = np.linalg.svd(np.vstack([fields(anchors), np.zeros((6, 6))]), full_matrices=False)
        rank = int(np.sum(sv > 1e-10 * max(sv.max(), 1e-300)))
        basis = vt[rank:].T
    if basis.shape[1] == 0:
        return 0
    Rf = fields(scene.free_indices) @ basis
    sv = np.linalg.svd(Rf, compute_uv=False)
    return int(np.sum(sv > 1e-10 * max(sv.max(), 1e-300)))


# links: a dense eigen-decomposition of A costs ~L^3 (0.3 s at 1,000 links, 3.6 s at 3,000); above, the 1-norm
# condition is estimated from a sparse factorisation, O(nnz of its factor) (0.5 s for a 100,000-link chain)
DENSE_CONDITION_LIMIT = 1000


def condition_of_tension_matrix(A, self_stresses: int) -> tuple[float, str]:
    """The condition number of A of (25) and how it was had: exact in the 2-norm up to DENSE_CONDITION_LIMIT links,
    above it estimated in the 1-norm (Hager-Higham, as LAPACK's condition estimators: ||A||_1 exact, ||A^-1||_1 from
    a few solves with a sparse LU of A). The two norms' condition numbers differ by at most a factor L."""
    L = A.shape[0]
    if L == 0:  # no links (a mass alone on a ground): no tension system
        return float("nan"), "no links"
    if L <= DENSE_CONDITION_LIMIT:
        w = np.linalg.eigvalsh(A.toarray())
        positive = w[w > 1e-12 * max(w.max(), 1e-300)]
        if w.min() > 1e-12 * w.max():
            return float(w.max() / w.min()), "exact, 2-norm"
        return float("inf"), (f"A singular: {L - positive.size} zero eigenvalues; on range(A): "
                              f"{positive.max() / positive.min():.3e}")
    if self_stresses:
        return float("inf"), (f"A singular: {self_stresses} zero eigenvalues (the self-stresses); its condition on "
                              f"range(A) is not estimated above {DENSE_CONDITION_LIMIT} links")
    from scipy.sparse.linalg import LinearOperator, onenormest, splu

    try:
        lu = splu(A.tocsc())
    except RuntimeError:  # an exactly singular pivot that the rank estimate missed
        return float("inf"), "A singular (its sparse LU met a zero pivot)"
    inverse = LinearOperator(A.shape, matvec=lu.solve, rmatvec=lu.solve, dtype=float)  # A is symmetric
    norm_A = float(abs(A).sum(axis=0).max())
    return norm_A * float(onenormest(inverse)), "1-norm, estimated (Hager-Higham) from a sparse LU of A"


def analyze_scene(scene: Scene) -> RigidityReport:
    dyn = Dynamics(scene)
    st = dyn.structure
    n_free = scene.free_indices.size
    dof = 3 * n_free - st.rank_G
    rbm = min(_rigid_body_motions(scene), dof)
    cond, note = condition_of_tension_matrix(dyn.tension_matrix(scene.X0), st.self_stresses)
    blocked = second_order_rigid_flexes(scene) if st.self_stresses and scene.L <= DENSE_RIGIDITY_LIMIT else None
    return RigidityReport(scene, dyn, scene.K, scene.L, scene.fixed_indices.tolist(), st.rank_G, st.rank_exact, dof,
                          rbm, dof - rbm, st.self_stresses, cond, note, choose_specialisation(scene, dyn), blocked)
