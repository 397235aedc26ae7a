"""Free rigid bodies in a scene, analysed once: which masses form bodies that move rigidly, and their geometry.

A scene whose every linked component is free (no anchored mass), rigid (rank G_c = 3 n_c - 6: no internal
mechanism) and has >= 3 non-collinear masses (a full inertia tensor) moves as rigid bodies. This module finds
them (:func:`free_rigid_bodies`), freezes their shape and principal frames once (:func:`body_geometry`), and
fits body states (centre of mass, velocity, quaternion, body angular momentum) to a mass state
(:func:`fit_bodies`). The simulator's specialisation chooses the path; the native core moves the bodies.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from linknet_core.clib.library import graph_components
from linknet_core.scene.description import Scene

if TYPE_CHECKING:
    from linknet_core.dynamics.equations import Dynamics

TOP_TOL = 1e-12  # principal moments equal to this (relative) make a spherical or symmetric top (exact flows)
COLLINEAR_TOL = 1e-10  # smallest principal moment below this times the largest: the masses lie on a line
RESHAPE_TOL = 1e-13  # initial link lengths are made exact below this relative error before a body is frozen
TOP_NAMES = ("spherical top", "symmetric top", "asymmetric top")


@dataclass(frozen=True)
class BodyLayout:
    """Which masses form which body (topology only; the geometry is fixed when a simulation starts)."""

    count: int
    body_of: np.ndarray  # (K,) body index of each mass, -1 for anchored masses joined by no link
    links_of: list  # per body: its link indices
    masses_of: list  # per body: its mass indices


def _components(scene: Scene):
    """Connected components of the link graph over all K masses (springs do not join them)."""
    return graph_components(scene.K, scene.k1, scene.k2)


def _principal_moments(scene: Scene, X: np.ndarray, body_of: np.ndarray, count: int):
    """Per body: mass, centre of mass, inertia tensor about it and its eigen-decomposition (ascending)."""
    inside = body_of >= 0
    idx, m, Xb = body_of[inside], scene.mass[inside], X[inside]
    body_mass = np.bincount(idx, weights=m, minlength=count)
    c = np.stack([np.bincount(idx, weights=m * Xb[:, d], minlength=count) for d in range(3)], axis=1)
    c /= body_mass[:, None]
    rho = Xb - c[idx]
    # I = sum m (|rho|^2 1 - rho rho^T), six bincounts
    outer = -m[:, None, None] * rho[:, :, None] * rho[:, None, :]
    outer += (m * np.einsum("ij,ij->i", rho, rho))[:, None, None] * np.eye(3)[None]
    inertia = np.stack([np.bincount(idx, weights=outer[:, i, j], minlength=count)
                        for i in range(3) for j in range(3)], axis=1).reshape(count, 3, 3)
    moments, axes = np.linalg.eigh(inertia)
    return body_mass, c, moments, axes


def free_rigid_bodies(scene: Scene, dyn: Dynamics) -> tuple[BodyLayout | None, str]:
    """The body layout if the scene is a set of free rigid bodies, else None and the reason."""
    st = dyn.structure
    linked = np.zeros(scene.K, bool)
    linked[scene.k1] = True
    linked[scene.k2] = True
    loose = np.flatnonzero(~linked & ~scene.fixed)
    if loose.size:
        return None, f"{scene.mass_label(int(loose[0]))} is a free particle joined by no link (not a rigid body)"
    anchored = np.flatnonzero(linked & scene.fixed)
    if anchored.size:
        return None, (f"{scene.mass_label(int(anchored[0]))} is anchored and linked: its component is not a free "
                      "rigid body")
    n_comp, labels = _components(scene)
    comp_ids = np.unique(labels[linked])
    body_index = -np.ones(n_comp, np.int64)
    body_index[comp_ids] = np.arange(comp_ids.size)
    body_of = np.where(linked, body_index[labels], -1)
    B = int(comp_ids.size)
    size = np.bincount(body_of[linked], minlength=B)
    small = np.flatnonzero(size < 3)
    if small.size:
        k = int(np.flatnonzero(body_of == small[0])[0])
        return None, (f"the component of {scene.mass_label(k)} has {size[small[0]]} masses: a rigid body needs "
                      ">= 3 non-collinear ones")
    _, _, moments, _ = _principal_moments(scene, scene.X0, body_of, B)
    flat = np.flatnonzero(moments[:, 0] <= COLLINEAR_TOL * moments[:, 2])
    if flat.size:
        k = int(np.flatnonzero(body_of == flat[0])[0])
        return None, f"the masses of the component of {scene.mass_label(k)} are collinear (no full inertia tensor)"
    if not st.rank_exact:
        return None, "rank of G only estimated (scene too large): rigidity of the components not established"
    # each component has rank G_c <= 3 n_c - 6, so the total decides for all of them
    rigid_rank = 3 * int(scene.free_indices.size) - 6 * B
    if st.rank_G < rigid_rank:
        return None, (f"{rigid_rank - st.rank_G} internal mechanism(s): rank G = {st.rank_G} < 3 K_free - 6 bodies "
                      f"= {rigid_rank}")
    links_of = _group(body_of[scene.k1], B)
    masses_of = _group(np.where(linked, body_of, B), B + 1)[:B]
    return BodyLayout(B, body_of, links_of, masses_of), ""


def _group(labels: np.ndarray, n: int) -> list:
    """Indices i with labels[i] == g, for g = 0..n-1 (one stable sort, no scan per group)."""
    order = np.argsort(labels, kind="stable")
    return np.split(order, np.cumsum(np.bincount(labels, minlength=n))[:-1])


def _top_kinds(moments: np.ndarray) -> np.ndarray:
    scale = TOP_TOL * moments[:, 2]
    spherical = moments[:, 2] - moments[:, 0] <= scale
    symmetric = (moments[:, 1] - moments[:, 0] <= scale) | (moments[:, 2] - moments[:, 1] <= scale)
    return np.where(spherical, 0, np.where(symmetric, 1, 2)).astype(np.int64)


# ---- the static path ---------------------------------------------------------------------------------


def _quaternions(R: np.ndarray) -> np.ndarray:
    """Unit quaternions (w, x, y, z) of rotation matrices R (B,3,3), Shepperd's branch-by-largest."""
    t = np.trace(R, axis1=1, axis2=2)
    d0, d1, d2 = R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]
    branch = np.argmax(np.stack([t, d0, d1, d2], axis=1), axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        s = 2.0 * np.sqrt(np.maximum(1.0 + np.choose(branch, [t, d0 - d1 - d2, d1 - d0 - d2, d2 - d0 - d1]), 0.0))
        a, b, c = R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]
        e, f, g = R[:, 0, 1] + R[:, 1, 0], R[:, 0, 2] + R[:, 2, 0], R[:, 1, 2] + R[:, 2, 1]
        q = np.stack([
            np.choose(branch, [s / 4, a / s, b / s, c / s]),
            np.choose(branch, [a / s, s / 4, e / s, f / s]),
            np.choose(branch, [b / s, e / s, s / 4, g / s]),
            np.choose(branch, [c / s, f / s, g / s, s / 4])], axis=1)
    return q / np.linalg.norm(q, axis=1)[:, None]


def rotation_matrices(q: np.ndarray) -> np.ndarray:
    """R (B,3,3) of unit quaternions q (B,4) = (w, x, y, z), with the arithmetic of the step loops (so that r_k
    fitted with it is in the frame of exactly the matrix they use)."""
    w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
    R = np.empty((q.shape[0], 3, 3))
    R[:, 0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[:, 0, 1] = 2.0 * (x * y - w * z)
    R[:, 0, 2] = 2.0 * (x * z + w * y)
    R[:, 1, 0] = 2.0 * (x * y + w * z)
    R[:, 1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[:, 1, 2] = 2.0 * (y * z - w * x)
    R[:, 2, 0] = 2.0 * (x * z - w * y)
    R[:, 2, 1] = 2.0 * (y * z + w * x)
    R[:, 2, 2] = 1.0 - 2.0 * (x * x + y * y)
    return R


@dataclass(frozen=True)
class BodyGeometry:
    """What a rigid-body path fixes once from the initial positions: per body its mass, top kind (0 spherical,
    1 symmetric, 2 asymmetric), principal moments in the body frame's axis order, and per mass its position
    r_k in its body's frame (principal axes; zero off the bodies)."""

    body_mass: np.ndarray  # (B,)
    kind: np.ndarray  # (B,) int64
    inertia: np.ndarray  # (B,3)
    r: np.ndarray  # (K,3), read-only
    inside: np.ndarray  # (K,) bool: the mass belongs to a body


def freeze_initial_state(dynamics: Dynamics, X0, U0):
    """The initial state a body is frozen in: (X0, U0) as given, or, with link lengths off by more than
    RESHAPE_TOL, projected onto the exact lengths first (as RATTLE's first position stage would). Returns
    (X0, U0, notes)."""
    X0, U0 = np.array(X0, float), np.array(U0, float)
    notes = []
    if dynamics.constraint_residual(X0) > RESHAPE_TOL:
        X0, _ = dynamics.project_positions(X0, tol=1e-14)
        U0 = dynamics.project_velocities(X0, U0)
        notes.append("initial positions projected onto the exact link lengths before freezing the bodies")
    return X0, U0, notes


def body_geometry(scene: Scene, bodies: BodyLayout, X0: np.ndarray) -> BodyGeometry:
    """Body frames from the principal axes at X0 (right-handed; a symmetric top's distinct axis is the third,
    a spherical top keeps the space axes) and the masses' body-frame positions in them."""
    B, body_of = bodies.count, bodies.body_of
    inside = body_of >= 0
    body_mass, c, moments, axes = _principal_moments(scene, X0, body_of, B)
    kind = _top_kinds(moments)
    first_pair_equal = moments[:, 1] - moments[:, 0] <= TOP_TOL * moments[:, 2]
    perm = np.where((kind == 1) & ~first_pair_equal, 1, 0)
    order = np.array([[0, 1, 2], [1, 2, 0]])[perm]  # cyclic: keeps the handedness
    frames = np.take_along_axis(axes, order[:, None, :], axis=2)
    inertia = np.take_along_axis(moments, order, axis=1)
    symmetric = kind == 1  # the exact flow needs I_1 = I_2 exactly
    inertia[symmetric, :2] = inertia[symmetric, :2].mean(axis=1)[:, None]
    frames[kind == 0] = np.eye(3)
    inertia[kind == 0] = moments[kind == 0].mean(axis=1)[:, None]
    flip = np.linalg.det(frames) < 0
    frames[flip, :, 0] *= -1.0
    R0 = rotation_matrices(_quaternions(frames))
    rho = X0[inside] - c[body_of[inside]]
    r = np.zeros_like(X0)  # in the frame of exactly the matrix the step loops use
    r[inside] = np.einsum("kji,kj->ki", R0[body_of[inside]], rho)
    r.setflags(write=False)
    return BodyGeometry(body_mass, kind, inertia, r, inside)


def fit_bodies(scene: Scene, bodies: BodyLayout, geometry: BodyGeometry, X, U):
    """Body state (c, v, q, Pi) of a mass state: centre of mass and momentum, the rotation that best maps r
    onto X - c (Kabsch, mass-weighted) and the angular momentum about c in the body frame."""
    inside = geometry.inside
    B, idx = bodies.count, bodies.body_of[inside]
    m = scene.mass[inside]
    Xi, Ui, r = X[inside], U[inside], geometry.r[inside]

    def per_body(values):
        flat = values.reshape(values.shape[0], -1)
        return np.stack([np.bincount(idx, weights=flat[:, j], minlength=B) for j in range(flat.shape[1])],
                        axis=1).reshape((B,) + values.shape[1:])

    c = per_body(m[:, None] * Xi) / geometry.body_mass[:, None]
    v = per_body(m[:, None] * Ui) / geometry.body_mass[:, None]
    rho = Xi - c[idx]
    H = per_body(m[:, None, None] * rho[:, :, None] * r[:, None, :])
    W, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(W @ Vt))
    W[:, :, 2] *= d[:, None]
    q = _quaternions(W @ Vt)
    R = rotation_matrices(q)
    L = per_body(m[:, None] * np.cross(rho, Ui - v[idx]))
    Pi = np.einsum("bji,bj->bi", R, L)
    return c, v, q, Pi
