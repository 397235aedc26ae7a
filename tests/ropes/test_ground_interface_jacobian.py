"""The outputs' linearization of scenes on a frictionless ground (Simulator.interface_linearization): the derivatives
of the current mode's outputs, against central differences of the mode's tensions, anchor reactions and accelerations
computed here from the seed's (9), (13) with the taut links, and each active contact as the unilateral constraint of
the plane written directly, n . a_k = 0 with the ground's normal force N_k along n (no virtual anchor: the library's
way of carrying a contact is not used here). Scenes: a ball resting on a tilted plane pushed by F (no link: the hand
formula d acc / dF = (I - n n^T) / m, along the plane 1/m, across it 0), a rope pendulum's bob circling on the ground
under an input-driven pivot, and a rope chain lying partly on the ground under an input-driven anchor and turning
about it. Both backends, numpy and native, agree to round-off. Each scene's Jacobian is a few dozen solves: well
under a second of CPU for the module.

Tolerances as tests/ropes/test_rope_interface_jacobian.py: central differences of step H = 1e-6 on inputs of unit
scale leave ~1e-10 of the outputs (~10 N, ~10 m/s2); FD_TOL = 1e-7 of the largest entry; the two backends run the
same formulas on the same mode: ROUND_OFF = 1e-12.
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
INPUT = dict(driven=True, motion={"kind": "input"})
TILT = 0.3  # the ball's plane: its normal turned by 0.3 rad about x


def _mass(name, position, velocity=(0.0, 0.0, 0.0), mass=1.0, **kind):
    if kind:
        return dict(name=name, position=list(position), **kind)
    return dict(name=name, position=list(position), velocity=list(velocity), mass=mass)


def ball():
    """A 2 kg ball on a plane through the origin tilted by TILT, sliding along it: one contact, no link."""
    n = [0.0, -np.sin(TILT), np.cos(TILT)]
    along = np.cross(n, [1.0, 0.0, 0.0])
    return dict(name="ball_on_incline", gravity=list(G),
                masses=[_mass("ball", 0.3 * along, 0.4 * along + [0.2, 0, 0], mass=2.0)], links=[],
                ground={"point": [0, 0, 0], "normal": n}), [], [0]


def pendulum():
    """A 1.5 kg bob on the ground (z = 0) on a 1 m rope from an input-driven pivot 0.8 m above the ground, circling
    the pivot's foot at 1.5 m/s: the rope holds it on the circle (T = m v^2 / 0.36 = 6.25 m, its vertical part
    0.8 T less than m g, so the ground still pushes)."""
    return dict(name="rope_pendulum_on_ground", gravity=list(G),
                masses=[_mass("pivot", (0, 0, 0.8), **INPUT), _mass("bob", (0.6, 0, 0), (0, 1.5, 0), mass=1.5)],
                links=[dict(a="pivot", b="bob", length=1.0, kind="rope")],
                ground={"point": [0, 0, 0], "normal": [0, 0, 1]}), [0], [1]


def chain():
    """Three 0.5 m ropes from an input-driven anchor 0.8 m above the ground: the first mass hangs 0.4 m up, the other
    two lie on the ground in line, and the whole turns about the vertical through the anchor at 1 rad/s (velocities
    along the ground, every rope at its length with (12) met): every rope taut, the lying masses pressed on the
    ground, the hanging one in the air."""
    w = 1.0
    xs = [(0.3, 0.4), (0.6, 0.0), (1.1, 0.0)]
    masses = [_mass("anchor", (0, 0, 0.8), **INPUT)] + [
        _mass(f"m{i + 1}", (x, 0, z), (0, w * x, 0), mass=0.4 + 0.1 * i) for i, (x, z) in enumerate(xs)]
    links = [dict(a=a, b=b, length=0.5, kind="rope") for a, b in (("anchor", "m1"), ("m1", "m2"), ("m2", "m3"))]
    return dict(name="rope_chain_on_ground", gravity=list(G), masses=masses, links=links,
                ground={"point": [0, 0, 0], "normal": [0, 0, 1]}), [0, 1, 2], [2, 3]


def mode_outputs(scene, X, U, F, anchor_acc, taut, on_ground, normal):
    """(T (L,), Freact (n_anchored,3), dU/dt (K,3), N (len(on_ground),)) of the mode with the links ``taut`` and the
    masses ``on_ground`` held on the plane of unit normal ``normal``: M a_k = F_k + M g + sum_l T_l (+E_l at k1,
    -E_l at k2) + N_k n on free masses, anchor_acc on driven anchors, 0 on fixed ones; one equation per multiplier:
    (13) for a taut link, E_l . (a_k2 - a_k1) = -|U_k2 - U_k1|^2 / R_l, and the plane's n . a_k = 0 for a contact
    (its mass on the plane moving along it), solved minimum-norm (31)."""
    K, free = scene.K, ~scene.fixed
    k1, k2, R = scene.k1, scene.k2, scene.length
    E = (X[k2] - X[k1]) / R[:, None]
    inv_m = np.where(free, 1.0 / np.where(free, scene.mass, 1.0), 0.0)[:, None]
    a0 = np.where(free[:, None], F * inv_m + G, anchor_acc)
    rows = len(taut) + len(on_ground)
    per_unit = np.zeros((rows, K, 3))  # the accelerations a unit multiplier gives
    for j, l in enumerate(taut):
        per_unit[j, k1[l]] += E[l] * inv_m[k1[l]]
        per_unit[j, k2[l]] -= E[l] * inv_m[k2[l]]
    for j, k in enumerate(on_ground):
        per_unit[len(taut) + j, k] += normal * inv_m[k]

    def constraint(a):  # the left-hand sides of the mode's equations at accelerations a
        links = [E[l] @ (a[k2[l]] - a[k1[l]]) for l in taut]
        return np.array(links + [normal @ a[k] for k in on_ground])

    b = np.array([-(U[k2[l]] - U[k1[l]]) @ (U[k2[l]] - U[k1[l]]) / R[l] for l in taut] + [0.0] * len(on_ground))
    W = np.column_stack([constraint(per_unit[j]) for j in range(rows)]) if rows else np.zeros((0, 0))
    lam = np.linalg.pinv(W, rcond=1e-10) @ (b - constraint(a0)) if rows else np.zeros(0)
    T = np.zeros(scene.L)
    T[taut] = lam[:len(taut)]
    link_force = np.zeros((K, 3))  # C^T T: +T E at k1 (pulled towards k2), -T E at k2
    np.add.at(link_force, k1, T[:, None] * E)
    np.add.at(link_force, k2, -T[:, None] * E)
    acc = a0 + np.einsum("j,jki->ki", lam, per_unit)
    return T, link_force[scene.fixed_indices], acc, lam[len(taut):]


def finite_differences(scene, X, U, F, P, V, A, taut, on_ground, normal):
    """{(output, input): block} as InterfaceJacobian holds them, by central differences of mode_outputs, and the
    outputs at the point."""
    rows = scene.input_driven_indices

    def outputs(F, P, V, A):
        Xa, Ua, acc = X.copy(), U.copy(), np.zeros_like(X)
        Xa[rows], Ua[rows], acc[rows] = P, V, A
        return mode_outputs(scene, Xa, Ua, F, acc, taut, on_ground, normal)

    inputs = {"F": F, "P": P, "V": V, "A": A}
    blocks = central_differences(outputs, inputs, scene.fixed, ("T", "Freact", "acc"), H)
    return blocks, outputs(F, P, V, A)


@pytest.mark.parametrize("make", [ball, pendulum, chain])
def test_the_linearization_on_a_frictionless_ground_is_that_of_the_current_modes_outputs(make):
    data, taut, on_ground = make()
    scene = ln.Scene.from_dict(data)
    normal = np.asarray(scene.ground.normal, float)
    rows = scene.input_driven_indices
    X, U = np.array(scene.X0), np.array(scene.U0)
    F = np.zeros((scene.K, 3))
    F[scene.free_indices] = np.linspace(0.5, -0.7, 3 * scene.free_indices.size).reshape(-1, 3)
    P, V, A = X[rows], U[rows], np.tile([0.4, -0.3, 1.1], (rows.size, 1))
    blocks, (T_ref, Freact_ref, _, N_ref) = finite_differences(scene, X, U, F, P, V, A, taut, on_ground, normal)
    # the mode assumed is the state's: every taut rope pulls, every contact pushes, the others are off the ground
    assert np.all(T_ref[taut] > 0) and np.all(N_ref > 0)
    off = np.setdiff1d(scene.free_indices, on_ground)
    assert np.all((X[off] - scene.ground.point) @ normal > 0.1)
    jacobians = {}
    for backend in BACKENDS:
        sim = ln.Simulator(scene, "dop853", backend=backend)
        # the state built here: no impact moved it, the initial projection by round-off at most (the tilted plane)
        np.testing.assert_allclose(sim.state.X, X, rtol=0, atol=1e-15)
        np.testing.assert_allclose(sim.state.U, U, rtol=0, atol=1e-15)
        out = sim.outputs(F, anchors=(P, V, A)) if rows.size else sim.outputs(F)
        assert np.abs(out["T"] - T_ref).max(initial=0.0) <= ROUND_OFF * max(np.abs(T_ref).max(initial=0.0), 1.0)
        assert np.abs(out["Freact"] - Freact_ref).max(initial=0.0) <= ROUND_OFF * 10.0
        J = jacobians[backend] = (sim.interface_jacobian(F, anchors=(P, V, A)) if rows.size
                                  else sim.interface_jacobian(F))
        for (o, i), block in blocks.items():
            scale = max(np.abs(block).max(initial=0.0), 1.0)
            assert np.abs(J[o, i] - block).max(initial=0.0) <= FD_TOL * scale, (backend, o, i)
    for key in jacobians["numpy"].blocks:
        a, b = jacobians["numpy"][key], jacobians["native"][key]
        assert np.abs(a - b).max(initial=0.0) <= ROUND_OFF * max(np.abs(a).max(initial=0.0), 1.0), key


def test_a_ball_pushed_along_the_ground_accelerates_at_1_over_m_along_it_and_not_across():
    data, _, _ = ball()
    scene = ln.Scene.from_dict(data)
    n = np.asarray(scene.ground.normal, float)
    m = float(scene.mass[0])
    F = np.array([[1.0, 0.5, -2.0]])
    for backend in BACKENDS:
        J = ln.Simulator(scene, "dop853", backend=backend).interface_jacobian(F)
        assert J["T", "F"].size == 0 and J["Freact", "F"].size == 0
        np.testing.assert_allclose(J["acc", "F"][0, :, 0, :], (np.eye(3) - np.outer(n, n)) / m, rtol=0,
                                   atol=ROUND_OFF)
