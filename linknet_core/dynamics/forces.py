"""External forces F_k of (9): gravity, constant forces, spring-dampers, viscous and quadratic drag, inputs.

All of them are array code over the scene's index arrays; none knows about the links' tensions.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from linknet_core.scene.description import FORCE_KIND, Scene, require_force_kinds


def scatter_add(K: int, index: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Sum rows of ``vectors`` (n,3) into K rows by ``index`` (bincount per component, no loop per item)."""
    out = np.empty((K, 3))
    for d in range(3):
        out[:, d] = np.bincount(index, weights=vectors[:, d], minlength=K)
    return out


def _drag(K, X, U, masses, c):
    """Viscous drag: -c U on its mass."""
    k = masses[:, 0]
    return scatter_add(K, k, -c[:, :1] * U[k])


def _quadratic_drag(K, X, U, masses, c):
    """Aerodynamic drag: -c |U| U on its mass (speed squared, against the velocity)."""
    k = masses[:, 0]
    u = U[k]
    return scatter_add(K, k, -(c[:, :1] * np.linalg.norm(u, axis=1)[:, None]) * u)


def _spring(K, X, U, masses, p):
    """Linear spring-damper between two masses: k (d - d0) + c d' along the axis, pulling the ends together
    when stretched (parameters k, d0, c)."""
    a, b = masses[:, 0], masses[:, 1]
    d = X[b] - X[a]
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(dist[:, None] > 0, d / dist[:, None], 0.0)  # no direction when the ends coincide
    rate = np.einsum("ij,ij->i", n, U[b] - U[a])
    f = (p[:, 0] * (dist - p[:, 1]) + p[:, 2] * rate)[:, None] * n
    return scatter_add(K, a, f) - scatter_add(K, b, f)


def _spring_potential(X, masses, p):
    d = X[..., masses[:, 1], :] - X[..., masses[:, 0], :]
    return 0.5 * np.sum(p[:, 0] * (np.sqrt(np.einsum("...ij,...ij->...i", d, d)) - p[:, 1]) ** 2, axis=-1)


@dataclass(frozen=True)
class ElementKind:
    """The numpy formulas of a kind of force element (linknet_core.scene.description.FORCE_KINDS): its forces on all
    masses, and its potential (None: dissipative)."""

    forces: Callable
    potential: Callable | None


# The numpy formula of every kind of FORCE_KINDS; checked against the table here, at import, so that a kind the
# reference lacks stops it instead of being skipped.
ELEMENT_KINDS = {
    "drag": ElementKind(_drag, None),
    "quadratic_drag": ElementKind(_quadratic_drag, None),
    "spring": ElementKind(_spring, _spring_potential),
}
require_force_kinds(ELEMENT_KINDS, "the numpy reference (linknet_core.dynamics.forces.ELEMENT_KINDS)")


def element_forces(scene: Scene, X: np.ndarray, U: np.ndarray) -> np.ndarray:
    """The forces of the scene's force elements (drag, springs, ...) on every mass."""
    F = np.zeros_like(X)
    elements = scene.force_elements
    for kind in dict.fromkeys(elements.kinds):
        F += ELEMENT_KINDS[kind].forces(scene.K, X, U, *elements.of_kind(kind))
    return F


def external_forces(scene: Scene, X: np.ndarray, U: np.ndarray, F_input: np.ndarray | None = None) -> np.ndarray:
    """F_k of (9) and (26): everything but the link tensions. Zero rows on anchored masses."""
    free = ~scene.fixed
    mass = np.where(free, scene.mass, 0.0)
    F = mass[:, None] * scene.gravity[None, :] + scene.force
    if scene.force_elements.count:
        F = F + element_forces(scene, X, U)
    if F_input is not None:
        F = F + F_input
    F[scene.fixed] = 0.0
    return F


def has_velocity_dependent_forces(scene: Scene) -> bool:
    """A force element that depends on the velocities (drag, a damper): RATTLE's second half kick is then
    implicit in the new velocity."""
    elements = scene.force_elements
    return any(bool(np.any(elements.of_kind(kind)[1][:, FORCE_KIND[kind].velocity_parameter] != 0))
               for kind in dict.fromkeys(elements.kinds))


def _sample_sums(a: np.ndarray) -> np.ndarray:
    """The sum of each sample's (K, 3) block of a (..., K, 3) array: one pairwise summation over its 3K entries,
    so that a sample's sum is the same alone (np.sum of the block) or among others."""
    return a.reshape(a.shape[:-2] + (-1,)).sum(axis=-1)


def potential_energy(scene: Scene, X: np.ndarray):
    """Potential of the conservative forces: gravity, constant forces and the force elements that have one
    (springs); inputs excluded. X (K,3): a float; X (n,K,3), samples of a run: n values."""
    free = ~scene.fixed
    mass = np.where(free, scene.mass, 0.0)
    V = -_sample_sums(mass[:, None] * scene.gravity[None, :] * X) - _sample_sums(scene.force[free] * X[..., free, :])
    elements = scene.force_elements
    for kind in dict.fromkeys(elements.kinds):
        if ELEMENT_KINDS[kind].potential is not None:
            V = V + ELEMENT_KINDS[kind].potential(X, *elements.of_kind(kind))
    return float(V) if X.ndim == 2 else V


def kinetic_energy(scene: Scene, U: np.ndarray):
    """U (K,3): a float; U (n,K,3), samples of a run: n values."""
    free = ~scene.fixed
    T = 0.5 * _sample_sums(scene.mass[free][:, None] * U[..., free, :] ** 2)
    return float(T) if U.ndim == 2 else T
