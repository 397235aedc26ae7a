"""The outputs' linearization of scenes with ropes (Simulator.interface_linearization): the derivatives of the current
mode's outputs, against central differences of the mode's tensions and accelerations computed here from the seed's
(9), (13) and (25)-(26) with the slack ropes left out (minimum-norm (31) where the taut ropes are redundant): a rope
pendulum taut under an input-driven pivot, a crane's hook on a taut rope with its load hanging on a slack one, and a
mass held by four ropes (one of them from an input-driven anchor). Both backends, numpy and native, agree to
round-off. Each scene's Jacobian is a few dozen solves: well under a second of CPU for the module.

Tolerances: the central differences' step h = 1e-6 (of the inputs' unit scale 1 N, 1 m, 1 m/s, 1 m/s2) leaves a
truncation error ~h^2 = 1e-12 and a round-off ~1e-16 / h = 1e-10 relative to the outputs (~10 N, ~10 m/s2):
FD_TOL = 1e-7 of the largest entry keeps three orders of margin and is far below any error of a derivative term
(each is of the order of the entries). The two backends run the same formulas on the same mode: ROUND_OFF = 1e-12.
"""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
from rope_references import central_differences

H = 1e-6
FD_TOL = 1e-7
ROUND_OFF = 1e-12
BACKENDS = ("numpy", "native")
G = np.array([0.0, 0.0, -9.81])


def _mass(name, position, velocity=(0.0, 0.0, 0.0), mass=1.0, **kind):
    if kind:  # an anchor: no mass, no velocity of its own
        return dict(name=name, position=list(position), **kind)
    return dict(name=name, position=list(position), velocity=list(velocity), mass=mass)


INPUT = dict(driven=True, motion={"kind": "input"})


def pendulum():
    """A 1 kg bob on a 1 m rope from an input-driven pivot, swinging through (0.6, 0, -0.8): taut."""
    return dict(name="rope_pendulum_taut", gravity=list(G),
                masses=[_mass("pivot", (0, 0, 0), **INPUT), _mass("bob", (0.6, 0, -0.8), (1.6, 0, 1.2))],
                links=[dict(a="pivot", b="bob", length=1.0, kind="rope")]), [0]


def crane():
    """A 2 kg hook hanging on a 1 m rope from an input-driven trolley, and a 5 kg load on a 1.5 m rope from the hook,
    0.9 m below it and falling away from it more slowly than the hook: the load's rope is slack."""
    return dict(name="rope_crane_slack", gravity=list(G),
                masses=[_mass("trolley", (0, 0, 0), **INPUT), _mass("hook", (0.3, 0, -0.9539392014169456),
                                                                        (0.9539392014169456, 0, 0.3), mass=2.0),
                        _mass("load", (0.3, 0, -1.8539392014169456), (0.2, 0, -0.1), mass=5.0)],
                links=[dict(a="trolley", b="hook", length=1.0, kind="rope"),
                       dict(a="hook", b="load", length=1.5, kind="rope")]), [0]


def redundant():
    """A 3 kg mass at rest below four anchors on ropes of length sqrt(2), the first anchor input-driven: four taut
    ropes on three degrees of freedom, one self-stress (31)."""
    s = float(np.sqrt(2.0))
    anchors = [(1, 0, 1), (-1, 0, 1), (0, 1, 1), (0, -1, 1)]
    masses = [_mass(f"a{i + 1}", p, **(INPUT if i == 0 else dict(fixed=True))) for i, p in enumerate(anchors)]
    masses.append(_mass("m", (0, 0, 0), mass=3.0))
    return dict(name="rope_redundant", gravity=list(G), masses=masses,
                links=[dict(a=f"a{i + 1}", b="m", length=s, kind="rope") for i in range(4)]), [0, 1, 2, 3]


def mode_outputs(scene, X, U, F, anchor_acc, taut):
    """T (L,) and dU/dt (K,3) of the seed's system with only the ropes ``taut``: the accelerations (9), M a = F + M g
    + sum T_l E_l (+ at k1, - at k2) on free masses, anchor_acc on driven anchors and 0 on fixed ones, with the
    tensions from (13) per taut rope, E_l . (a_k2 - a_k1) = -|U_k2 - U_k1|^2 / R_l: a linear system in T, solved
    minimum-norm (31)."""
    K, free = scene.K, ~scene.fixed
    k1, k2, R = scene.k1, scene.k2, scene.length
    E = (X[k2] - X[k1]) / R[:, None]
    inv_m = np.where(free, 1.0 / np.where(free, scene.mass, 1.0), 0.0)[:, None]
    a0 = np.where(free[:, None], F * inv_m + G, anchor_acc)
    per_T = np.zeros((len(taut), K, 3))  # the accelerations a unit tension of each taut rope gives
    for j, l in enumerate(taut):
        per_T[j, k1[l]] += E[l] * inv_m[k1[l]]
        per_T[j, k2[l]] -= E[l] * inv_m[k2[l]]
    A = np.array([[E[l] @ (per_T[j, k2[l]] - per_T[j, k1[l]]) for j in range(len(taut))] for l in taut])
    b = np.array([-(U[k2[l]] - U[k1[l]]) @ (U[k2[l]] - U[k1[l]]) / R[l] - E[l] @ (a0[k2[l]] - a0[k1[l]])
                  for l in taut])
    T_taut = np.linalg.pinv(A, rcond=1e-10) @ b
    T = np.zeros(scene.L)
    T[taut] = T_taut
    return T, a0 + np.einsum("j,jki->ki", T_taut, per_T)


def finite_differences(scene, X, U, F, P, V, A, taut):
    """{(output, input): block} as InterfaceJacobian holds them, by central differences of mode_outputs."""
    rows = scene.input_driven_indices

    def outputs(F, P, V, A):
        Xa, Ua, acc = X.copy(), U.copy(), np.zeros_like(X)
        Xa[rows], Ua[rows], acc[rows] = P, V, A
        return mode_outputs(scene, Xa, Ua, F, acc, taut)

    inputs = {"F": F, "P": P, "V": V, "A": A}
    blocks = central_differences(outputs, inputs, scene.fixed, ("T", "acc"), H)
    return blocks, outputs(F, P, V, A)


@pytest.mark.parametrize("make", [pendulum, crane, redundant])
def test_the_linearization_is_that_of_the_current_modes_outputs(make):
    data, taut = make()
    scene = ln.Scene.from_dict(data)
    rows = scene.input_driven_indices
    X, U = np.array(scene.X0), np.array(scene.U0)
    F = np.zeros((scene.K, 3))
    F[scene.free_indices] = np.linspace(0.5, -0.7, 3 * scene.free_indices.size).reshape(-1, 3)  # a load in it
    P, V, A = X[rows], U[rows], np.array([[0.4, -0.3, 1.1]] * rows.size)
    blocks, (T_ref, acc_ref) = finite_differences(scene, X, U, F, P, V, A, taut)
    jacobians = {}
    for backend in BACKENDS:
        sim = ln.Simulator(scene, "dop853", backend=backend)
        np.testing.assert_array_equal(sim.state.X, X)  # the state built here: no projection moved it
        out = sim.outputs(F, anchors=(P, V, A))
        assert np.abs(out["T"] - T_ref).max() <= ROUND_OFF * np.abs(T_ref).max()  # the mode is the one assumed
        assert list(np.flatnonzero(out["T"] != 0.0)) == taut
        J = jacobians[backend] = sim.interface_jacobian(F, anchors=(P, V, A))
        for (o, i), block in blocks.items():
            scale = max(np.abs(block).max(), 1.0)
            assert np.abs(J[o, i] - block).max() <= FD_TOL * scale, (backend, o, i)
        slack = np.setdiff1d(np.arange(scene.L), taut)
        for i in ("F", "P", "V", "A"):  # a slack rope: T = 0 and no derivative, exactly
            assert not J["T", i][slack].any()
    for key in jacobians["numpy"].blocks:
        a, b = jacobians["numpy"][key], jacobians["native"][key]
        assert np.abs(a - b).max() <= ROUND_OFF * max(np.abs(a).max(), 1.0), key
