"""Second-order rigidity: configurations where a self-stress blocks a first-order flex (prestress-blocked flexes).

C is the constraint Jacobian (row l: +E_l at k1(l), -E_l at k2(l), over the free masses), a self-stress omega solves
C^T omega = 0 ((27), (31): a null vector of A = C M^-1 C^T of (25)), and a flex p solves C p = 0 (it keeps every
length (11) to first order). Differentiating |X_k2 - X_k1|^2 = R_l^2 twice along a path X + s p + s^2 a / 2 gives
(C a)_l = q_l(p) / R_l with q_l(p) = |p_k2 - p_k1|^2: the flex extends to second order only if q(p) / R lies in
the range of C, i.e. omega^T (q(p) / R) = 0 for every self-stress omega. The same sum with U for p is (34), and a
velocity U whose flex component fails it admits no accelerations consistent with the links: hypothesis (35) fails.
So where some flex p has omega^T (q(p) / R) != 0, the configuration is rigid at second order in that direction
while the minimum-norm tensions (the solution of (25)-(26) with no component along omega, which (31) shows is as
good as any) give that direction no resistance: a velocity that acquires a component along p breaks (35), and a
load along p needs tensions that grow without bound as the configuration is approached. A taut straight string
between anchors (its inner masses move across it to first order) and a flat doubly braced square (it twists out
of its plane to first order) are the two cases people build.

Dense linear algebra on the free masses: one SVD of C (L x 3 K_free) and, per self-stress, an eigen-decomposition
of its stress form on the flexes. Skipped (nothing reported) above DENSE_RIGIDITY_LIMIT links; meant for a scene's
construction and a failure's diagnosis, not for every step.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from linknet_core.scene.description import Scene
from linknet_core.structure.topology import constraint_jacobian
from linknet_core.tolerances import DENSE_RANK_LIMIT, SINGULAR_RCOND

DENSE_RIGIDITY_LIMIT = DENSE_RANK_LIMIT  # links (the SVD of C costs ~L (3 K_free)^2)
# |omega^T q(p)/R| / sum |omega_l| q_l(p)/R_l, for the flex p that omega's stress form moves most (unit stress,
# unit flex). It is exactly 0 where p extends (a rigid rotation: q/R = C a with a the centripetal term) and 1 where
# every link of the support is stretched in the same sense (a string: all omega_l > 0, q_l >= 0). Round-off leaves
# ~1e-15 on the zeros (a free tetrahedron's rotations, the flexes of net_10x10); 1e-6 lies far from both.
BLOCKED = 1e-6
# A link is in a self-stress's support when it carries at least this share of its largest tension.
SHARE = 1e-6
# ... and is named in its description when it carries at least this share: away from the exact singular
# configuration a near-self-stress keeps small components on the links around it (a flat braced top square on four
# legs that have tilted by 1e-5 rad: 1.9e-5 on each leg), which say nothing about where the lengths cannot be met.
NAMED_SHARE = 1e-3
LOCALISE_LIMIT = 400  # links: above it, self-stresses are localised by an echelon form instead of linear programmes
MOVED = 1e-2  # a mass moves with a flex when it holds at least this share of the flex's largest displacement
COLLINEAR = 1e-9  # |E_l x E_l'| below this: the links lie on one line
COPLANAR = 1e-9  # smallest singular value of the centred masses over the largest below this: one plane
# ... below this, nearly one plane: a near-self-stress at a failure's start (a flat cell a run has pushed 2e-5 of its
# size out of its plane) is described as the panel it is
NEARLY_FLAT = 1e-3


@dataclass(frozen=True)
class BlockedFlex:
    """One self-stress blocking a first-order flex at second order: ``links`` (0-based) carry the self-stress
    ``stress`` (L,); ``span`` (m, K, 3; zero on anchors, orthonormal) are the flexes it blocks, ``flex`` the most
    blocked of them, ``masses`` (0-based) those they move (at least MOVED of the largest displacement),
    ``blocking`` the ratio of :data:`BLOCKED` for ``flex``, ``description`` says it in the scene's names."""

    links: np.ndarray
    masses: np.ndarray
    stress: np.ndarray
    flex: np.ndarray
    span: np.ndarray
    blocking: float
    description: str


def second_order_rigid_flexes(scene: Scene, X: np.ndarray | None = None) -> list[BlockedFlex]:
    """The flexes of configuration X (default: the scene's initial one) that a self-stress blocks at second order,
    one per self-stress that blocks any, in the scene's terms ([] when there is none, and above
    DENSE_RIGIDITY_LIMIT links). Self-stresses and flexes are cut as everywhere else: singular values of C below
    sqrt(SINGULAR_RCOND) of the largest are zero."""
    X = scene.X0 if X is None else np.asarray(X, float)
    free = scene.free_indices
    if scene.L == 0 or free.size == 0 or scene.L > DENSE_RIGIDITY_LIMIT:
        return []
    C = constraint_jacobian(scene, X).toarray()
    left, s, right_t = np.linalg.svd(C, full_matrices=True)
    cut = np.sqrt(SINGULAR_RCOND) * (s[0] if s.size else 0.0)
    rank = int(np.sum(s > cut))
    stresses = _localised(left[:, rank:])  # (L, n_stresses)
    flexes = right_t[rank:].T  # (3 K_free, n_flexes), orthonormal
    if stresses.shape[1] == 0 or flexes.shape[1] == 0:
        return []
    # each flex as a (K, 3) field, anchors at rest; D[l] = p_k2 - p_k1 for every flex of the basis
    field = np.zeros((scene.K, 3, flexes.shape[1]))
    field[free] = flexes.reshape(free.size, 3, -1)
    D = field[scene.k2] - field[scene.k1]  # (L, 3, n_flexes)
    found = []
    for omega in stresses.T:
        support = np.flatnonzero(np.abs(omega) > SHARE * np.abs(omega).max())
        w = omega[support] / scene.length[support]
        Ds = D[support]
        # omega^T q(p)/R = a^T Q a for p = flexes @ a: the stress form on the flexes
        Q = np.einsum("l,lia,lib->ab", w, Ds, Ds)
        values, vectors = np.linalg.eigh(Q)
        # each eigenvector's ratio; the blocked ones span the directions this stress blocks (a string's inner mass
        # is blocked in both directions across it: a degenerate eigenvalue)
        moves = np.einsum("lia,aj->lij", Ds, vectors)  # p_k2 - p_k1 on the support, for each eigenvector
        stretch = np.abs(w) @ np.einsum("lij,lij->lj", moves, moves)  # sum |omega_l| q_l(p) / R_l
        ratios = np.abs(values) / np.where(stretch > 0, stretch, np.inf)
        blocked = np.flatnonzero(ratios > BLOCKED)
        if blocked.size == 0:
            continue
        i = int(blocked[np.argmax(ratios[blocked])])
        span = np.einsum("kia,aj->jki", field, vectors[:, blocked])  # orthonormal, as the flex basis is
        p = span[int(np.argmax(ratios[blocked]))]
        size = np.linalg.norm(np.sqrt(np.sum(span ** 2, axis=0)), axis=1)
        moved = np.flatnonzero(size >= MOVED * size.max())
        named = support[np.abs(omega[support]) >= NAMED_SHARE * np.abs(omega).max()]
        found.append(BlockedFlex(links=support, masses=moved, stress=omega, flex=p, span=span,
                                 blocking=float(ratios[i]), description=_describe(scene, X, named, moved)))
    return found


def _localised(basis: np.ndarray) -> np.ndarray:
    """A basis of the same self-stresses made of stresses on as few links as can be found (a string's three links,
    a braced cell's six), so that each case names its own links: for every link the stress through it of least
    sum |omega_l| (a linear programme; its optimum lies on a vertex, a stress of minimal support), then the
    smallest supports first while they add to the rank. Above LOCALISE_LIMIT links (L linear programmes), the
    reduced row echelon form of basis^T instead (exact where supports are disjoint: the echelon form of a direct sum
    is the direct sum of the echelon forms). Each vector scaled to unit norm."""
    L, n = basis.shape
    if n == 0:
        return basis
    if L <= LOCALISE_LIMIT:
        candidates = [c for c in (_least_stress_through(basis, l) for l in range(L)) if c is not None]
        candidates.sort(key=lambda c: int(np.count_nonzero(c)))
        chosen: list[np.ndarray] = []
        for c in candidates:
            if np.linalg.matrix_rank(np.column_stack(chosen + [c]), tol=1e-8) > len(chosen):
                chosen.append(c / np.linalg.norm(c))
            if len(chosen) == n:
                return np.column_stack(chosen)
    from scipy.linalg import qr

    _, _, pivots = qr(basis.T, pivoting=True, mode="economic")
    lead = pivots[:n]
    rows = np.linalg.solve(basis[lead].T, basis.T)  # rows[i] is 1 at link lead[i], 0 at the other leads
    rows[np.abs(rows) < 1e-12 * np.abs(rows).max(axis=1, keepdims=True)] = 0.0
    return (rows / np.linalg.norm(rows, axis=1, keepdims=True)).T


def _least_stress_through(basis: np.ndarray, link: int) -> np.ndarray | None:
    """The self-stress omega = basis c with omega_link = 1 and least sum |omega_l| (None where no stress runs
    through that link); entries below 1e-9 of the largest are cut to zero."""
    from scipy.optimize import linprog

    L, n = basis.shape
    if np.linalg.norm(basis[link]) < 1e-9:
        return None
    # variables (c, t): minimise sum t subject to -t <= basis c <= t and basis[link] c = 1
    cost = np.r_[np.zeros(n), np.ones(L)]
    upper = np.block([[basis, -np.eye(L)], [-basis, -np.eye(L)]])
    out = linprog(cost, A_ub=upper, b_ub=np.zeros(2 * L), A_eq=np.r_[basis[link], np.zeros(L)][None, :], b_eq=[1.0],
                  bounds=[(None, None)] * n + [(0, None)] * L, method="highs")
    if out.status != 0:
        return None
    omega = basis @ out.x[:n]
    omega[np.abs(omega) < 1e-9 * np.abs(omega).max()] = 0.0
    return omega


def _names(scene: Scene, masses) -> str:
    names = [scene.mass_names[int(k)] for k in masses]
    return names[0] if len(names) == 1 else ", ".join(names[:-1]) + " and " + names[-1]


def _link_list(links) -> str:
    numbers = [str(int(l) + 1) for l in links]
    return numbers[0] if len(numbers) == 1 else ", ".join(numbers[:-1]) + " and " + numbers[-1]


def _describe(scene: Scene, X: np.ndarray, links: np.ndarray, moved: np.ndarray) -> str:
    """The case in the scene's words: a straight string, a flat braced panel, or the links and masses in general."""
    ends = np.concatenate([scene.k1[links], scene.k2[links]])
    masses, count = np.unique(ends, return_counts=True)
    E = X[scene.k2[links]] - X[scene.k1[links]]
    E /= np.linalg.norm(E, axis=1, keepdims=True)
    moved_names = _names(scene, moved)
    if np.all(np.linalg.norm(np.cross(E, E[0]), axis=1) < COLLINEAR):
        end_masses = masses[count == 1]
        kind = "anchors" if end_masses.size and np.all(scene.fixed[end_masses]) else "masses"
        between = f" between {kind} {_names(scene, end_masses)}" if end_masses.size == 2 else ""
        return (f"links {_link_list(links)} are a straight string{between}: {moved_names} can move across it to "
                "first order, which only stretching the string could allow (held at second order only)")
    centred = X[masses] - X[masses].mean(axis=0)
    sv = np.linalg.svd(centred, compute_uv=False)
    if sv.size == 3 and sv[2] <= NEARLY_FLAT * sv[0]:
        panel = "doubly braced panel" if masses.size == 4 and links.size == 6 else "braced panel"
        motion = "twist" if masses.size == 4 else "bend"
        flat = "flat" if sv[2] <= COPLANAR * sv[0] else f"nearly flat ({sv[2]:.2g} m out of its plane)"
        return (f"the {panel} of masses {_names(scene, masses)} (links {_link_list(links)}) is {flat}: it can "
                f"{motion} out of its plane to first order (moving {moved_names}), which only stretching its links "
                "could allow (held at second order only)")
    return (f"the self-stress over links {_link_list(links)} blocks a first-order flex of {moved_names} at second "
            "order only (the flex would stretch those links)")


def describe_blocked_flexes(found: list[BlockedFlex]) -> str:
    """The cases found, in one text for a message or a report ('' for none)."""
    return "; ".join(f.description for f in found)
