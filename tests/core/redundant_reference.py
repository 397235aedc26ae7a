"""An independent reference for scenes in motion, written from the seed's equations apart from the solver:
scipy's DOP853 on the index-1 form (9)-(10) with the tensions of (25)-(26) from a dense least-squares solve
(numpy.linalg.lstsq: minimum-norm where A is singular, as (31) allows). No linknet dynamics code is used: only
the scene's data (masses, links, lengths, gravity)."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp


def reference_run(scene, t_end: float, rtol: float = 1e-12, atol: float = 1e-12) -> np.ndarray:
    """Positions (K,3) at t_end from the scene's initial state."""
    K = scene.K
    k1, k2, R = np.asarray(scene.k1), np.asarray(scene.k2), np.asarray(scene.length, float)
    inv_m = np.where(scene.fixed, 0.0, 1.0 / np.where(scene.fixed, 1.0, scene.mass))
    g = np.asarray(scene.gravity, float)
    F = np.where(scene.fixed, 0.0, np.where(scene.fixed, 0.0, scene.mass))[:, None] * g[None, :]  # gravity (4)
    L = len(R)

    def rhs(_t, y):
        X, U = y[:3 * K].reshape(K, 3), y[3 * K:].reshape(K, 3)
        E = (X[k2] - X[k1]) / R[:, None]                                  # (8)
        C = np.zeros((L, 3 * K))                                          # force of T_l: +E_l on k1, -E_l on k2 (9)
        for l in range(L):
            C[l, 3 * k1[l]:3 * k1[l] + 3] = E[l]
            C[l, 3 * k2[l]:3 * k2[l] + 3] = -E[l]
        Minv = np.repeat(inv_m, 3)
        A = (C * Minv) @ C.T                                              # (25)
        dU = U[k2] - U[k1]
        a_free = (F.reshape(-1) * Minv).reshape(K, 3)
        B = np.einsum("ij,ij->i", dU, dU) / R + np.einsum("ij,ij->i", E, a_free[k2] - a_free[k1])  # (26)
        T = np.linalg.lstsq(A, B, rcond=1e-12)[0]
        acc = ((F.reshape(-1) + C.T @ T) * Minv).reshape(K, 3)            # (9)
        return np.concatenate([U.reshape(-1), acc.reshape(-1)])          # (10)

    y0 = np.concatenate([np.asarray(scene.X0, float).reshape(-1), np.asarray(scene.U0, float).reshape(-1)])
    sol = solve_ivp(rhs, (0.0, t_end), y0, method="DOP853", rtol=rtol, atol=atol)
    assert sol.success, sol.message
    return sol.y[:3 * K, -1].reshape(K, 3)
