"""External forces F_k of (9): gravity, constant forces, spring-dampers, viscous drag, inputs.

All of them are array code over the scene's index arrays; none knows about the links' tensions.
"""
from __future__ import annotations

import numpy as np

from .scene import Scene


def scatter_add(K: int, index: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Sum rows of ``vectors`` (n,3) into K rows by ``index`` (bincount per component, no loop per item)."""
    out = np.empty((K, 3))
    for d in range(3):
        out[:, d] = np.bincount(index, weights=vectors[:, d], minlength=K)
    return out


def spring_forces(scene: Scene, X: np.ndarray, U: np.ndarray) -> np.ndarray:
    """Linear spring-dampers: force k (d - d0) + c d' along the axis, pulling the ends together when stretched."""
    s = scene.springs
    if s.count == 0:
        return np.zeros_like(X)
    d = X[s.b] - X[s.a]
    dist = np.sqrt(np.einsum("ij,ij->i", d, d))
    with np.errstate(invalid="ignore", divide="ignore"):
        n = np.where(dist[:, None] > 0, d / dist[:, None], 0.0)  # no direction when the ends coincide
    rate = np.einsum("ij,ij->i", n, U[s.b] - U[s.a])
    f = (s.stiffness * (dist - s.rest_length) + s.damping * rate)[:, None] * n
    return scatter_add(scene.K, s.a, f) - scatter_add(scene.K, s.b, f)


def external_forces(scene: Scene, X: np.ndarray, U: np.ndarray, F_input: np.ndarray | None = None) -> np.ndarray:
    """F_k of (9) and (26): everything but the link tensions. Zero rows on anchored masses."""
    free = ~scene.fixed
    mass = np.where(free, scene.mass, 0.0)
    F = mass[:, None] * scene.gravity[None, :] + scene.force - scene.drag[:, None] * U
    if scene.springs.count:
        F = F + spring_forces(scene, X, U)
    if F_input is not None:
        F = F + F_input
    F[scene.fixed] = 0.0
    return F


def has_velocity_dependent_forces(scene: Scene) -> bool:
    """Drag on a free mass or a damper: RATTLE's second half kick is then implicit in the new velocity."""
    return bool(np.any((scene.drag != 0) & ~scene.fixed) or np.any(scene.springs.damping != 0))


def potential_energy(scene: Scene, X: np.ndarray) -> float:
    """Potential of the conservative forces: gravity, constant forces and springs (inputs excluded)."""
    free = ~scene.fixed
    mass = np.where(free, scene.mass, 0.0)
    V = -float(np.sum(mass[:, None] * scene.gravity[None, :] * X)) - float(np.sum(scene.force[free] * X[free]))
    s = scene.springs
    if s.count:
        d = X[s.b] - X[s.a]
        dist = np.sqrt(np.einsum("ij,ij->i", d, d))
        V += 0.5 * float(np.sum(s.stiffness * (dist - s.rest_length) ** 2))
    return V


def kinetic_energy(scene: Scene, U: np.ndarray) -> float:
    free = ~scene.fixed
    return 0.5 * float(np.sum(scene.mass[free][:, None] * U[free] ** 2))
