"""The ropes' complementarity problem against brute force: at states of a rope net where every rope is at its length
(random velocities along the links and random loads) and at the samples of a run of a net that falls into its ropes,
the tensions and accelerations linknet gives satisfy T >= 0, gap >= 0, T gap = 0 and, at the acceleration level,
d2gap/dt2 >= 0 with T d2gap/dt2 = 0, and equal the one active set that enumerating all 2^n allows (from the seed's
(25)-(26) written again here, a dense solve per set)."""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from rope_references import G

import linknet_core as ln
from linknet_core.dynamics.complementarity import solve_mixed_lcp
from linknet_core.dynamics.unilateral import UnilateralDynamics


def net_scene(slack_factor=1.0, velocity=None, ropes_between=True) -> ln.Scene:
    """Four anchors at the corners of a 3 m square, four free masses inside joined to them and to each other; every
    link a rope but one rod (m1-m2); lengths slack_factor times the initial distances."""
    rng = np.random.default_rng(4)
    anchors = [[0, 0, 0], [3, 0, 0], [3, 3, 0], [0, 3, 0]]
    free = [[1, 1, -0.3], [2, 1, -0.5], [2, 2, -0.2], [1, 2, -0.4]]
    masses = [{"name": f"A{i + 1}", "position": p, "fixed": True} for i, p in enumerate(anchors)]
    masses += [{"name": f"m{i + 1}", "position": p, "mass": float(m)}
               for i, (p, m) in enumerate(zip(free, rng.uniform(0.5, 2.0, 4)))]
    if velocity is not None:
        for entry, v in zip(masses[4:], velocity):
            entry["velocity"] = list(v)
    pairs = [(1, 5), (2, 6), (3, 7), (4, 8), (5, 6), (6, 7), (7, 8), (8, 5)]
    links = []
    for a, b in pairs:
        d = float(np.linalg.norm(np.subtract(masses[b - 1]["position"], masses[a - 1]["position"])))
        link = {"a": a, "b": b, "length": d}
        if (a, b) != (5, 6):
            link["kind"], link["length"] = "rope", slack_factor * d
        links.append(link)
    return ln.Scene.from_dict({"name": "rope_net", "gravity": [0, 0, -G], "masses": masses, "links": links})


def seed_system(scene, X, U, F):
    """C (rows +E_l at k1, -E_l at k2), W = C M^-1 C^T and B of (26), from the seed's formulas."""
    K, L = scene.K, scene.L
    C = np.zeros((L, 3 * K))
    B = np.zeros(L)
    inv_mass = np.where(scene.fixed, 0.0, 1.0 / np.where(scene.fixed, 1.0, scene.mass))
    a_free = F * inv_mass[:, None]
    for l in range(L):
        k1, k2, R = scene.k1[l], scene.k2[l], scene.length[l]
        E = (X[k2] - X[k1]) / R
        C[l, 3 * k1:3 * k1 + 3], C[l, 3 * k2:3 * k2 + 3] = E, -E
        dU = U[k2] - U[k1]
        B[l] = dU @ dU / R + E @ (a_free[k2] - a_free[k1])
    W = (C * np.repeat(inv_mass, 3)) @ C.T
    return C, W, B, inv_mass


def enumerate_active_sets(W, B, unilateral, candidates):
    """Every active set S of the candidate ropes (the rods always in) for which W_SS T_S = B_S gives T_S >= 0 and
    W T - B >= 0 on the other candidates: [(S, T)]."""
    rods = np.flatnonzero(~unilateral)
    cand = np.flatnonzero(candidates)
    scale = np.abs(B).max()
    found = []
    for chosen in itertools.product((False, True), repeat=cand.size):
        rows = np.concatenate([rods, cand[np.array(chosen, bool)]]).astype(int)
        T = np.zeros(B.size)
        T[rows] = np.linalg.solve(W[np.ix_(rows, rows)], B[rows])
        w = W @ T - B
        off = cand[~np.array(chosen, bool)]
        if np.all(T[cand] >= -1e-12 * scale) and np.all(w[off] >= -1e-12 * scale):
            found.append((set(cand[np.array(chosen, bool)].tolist()), T))
    return found


def gap_accelerations(scene, X, U, A):
    """d2g/dt2 of every link where its gap and rate are zero: -(|dU|^2 / R + E . (A_k2 - A_k1))."""
    d = X[scene.k2] - X[scene.k1]
    dU = U[scene.k2] - U[scene.k1]
    E = d / scene.length[:, None]
    return -(np.einsum("ij,ij->i", dU, dU) / scene.length + np.einsum("ij,ij->i", E, A[scene.k2] - A[scene.k1]))


def check_state(scene, dyn, X, U, F_input):
    F = np.where(scene.fixed, 0.0, scene.mass)[:, None] * scene.gravity + F_input
    F[scene.fixed] = 0.0
    C, W, B, inv_mass = seed_system(scene, X, U, F)
    touching = dyn.touching(X, U)
    candidates = np.zeros(scene.L, bool)
    candidates[dyn.rope_links[touching[:dyn.rope_links.size]]] = True
    solutions = enumerate_active_sets(W, B, scene.rope, candidates)
    assert len(solutions) == 1  # W positive definite: one solution
    active, T_brute = solutions[0]
    T, _ = dyn.resolve(X, U, F_input)
    A, _ = dyn.accelerations(X, U, F_input)
    scale = np.abs(T_brute).max()
    assert np.allclose(T, T_brute, rtol=1e-10, atol=1e-10 * scale)
    ropes = np.flatnonzero(scene.rope)
    assert set(np.flatnonzero(scene.rope & (T > 0)).tolist()) == active
    # complementarity at the position level: T >= 0, gap >= 0, T gap = 0
    gap = scene.length - np.linalg.norm(X[scene.k2] - X[scene.k1], axis=1)
    assert np.all(T[ropes] >= 0) and np.all(gap[ropes] >= -1e-12)
    assert np.all(np.abs(T[ropes] * gap[ropes]) <= 1e-9 * scale)
    # and at the acceleration level, with linknet's accelerations, where the gap and its rate are zero
    g2 = gap_accelerations(scene, X, U, A)
    acc_scale = np.abs(B).max()
    on = candidates
    assert np.all(g2[on] >= -1e-9 * acc_scale)
    assert np.all(np.abs(T[on] * g2[on]) <= 1e-9 * acc_scale * scale)
    assert np.all(np.abs(g2[~scene.rope]) <= 1e-9 * acc_scale)  # the rod holds (13)
    # the masses' accelerations are (9) with these tensions
    assert np.allclose(A.reshape(-1), np.repeat(inv_mass, 3) * (F.reshape(-1) + C.T @ T), rtol=0,
                       atol=1e-9 * acc_scale)
    return active


def test_at_random_states_of_a_taut_net_the_tensions_are_the_one_solution_enumeration_finds():
    scene = net_scene()
    dyn = UnilateralDynamics(scene)
    X = np.array(scene.X0)
    rng = np.random.default_rng(7)
    C, W, _, inv_mass = seed_system(scene, X, np.zeros_like(X), np.zeros_like(X))
    seen = set()
    for _ in range(12):
        U = rng.normal(0, 1.0, X.shape)
        U[scene.fixed] = 0.0
        # velocities along the links' constraints (every rate zero): the mass-metric projection, by least squares
        u = U.reshape(-1)
        mu = np.linalg.lstsq(W, C @ u, rcond=None)[0]
        U = (u - np.repeat(inv_mass, 3) * (C.T @ mu)).reshape(X.shape)
        F_input = rng.normal(0, 15.0, X.shape)
        active = check_state(scene, dyn, X, U, F_input)
        seen.add(frozenset(active))
    assert len(seen) >= 4  # the loads made different ropes go slack


def test_at_the_samples_of_a_net_falling_into_its_ropes_the_conditions_hold_and_match_enumeration():
    # thrown up and sideways into ropes 4 % longer than the masses' distances: jerks, slack ropes, taut again
    scene = net_scene(slack_factor=1.04, velocity=[(0, 0, 3), (0, 1, -1), (1, 0, 2), (0, 0, 4)])
    run = ln.simulate(scene, 1.2, "dop853", rtol=1e-9, n_out=61, error_estimate=False)
    kinds = {e.kind for e in run.events}
    assert {"taut", "slack"} <= kinds
    dyn = UnilateralDynamics(scene)
    patterns = set()
    for X, U in zip(run.X, run.U):
        patterns.add(frozenset(check_state(scene, dyn, X, U, np.zeros_like(X))))
    assert len(patterns) >= 3


def test_the_lcp_solver_agrees_with_enumeration_on_random_positive_definite_problems():
    rng = np.random.default_rng(11)
    for size in range(1, 9):
        for _ in range(20):
            G_ = rng.normal(size=(size, size + 3))
            W = G_ @ G_.T
            b = rng.normal(size=size)
            unilateral = rng.random(size) < 0.7
            start = rng.random(size) < 0.5
            lam, active = solve_mixed_lcp(W, b, unilateral, start)
            found = enumerate_active_sets(W, b, unilateral, unilateral)
            assert len(found) == 1
            assert np.allclose(lam, found[0][1], rtol=1e-9, atol=1e-9 * np.abs(found[0][1]).max())


def test_a_self_stressed_pair_of_ropes_started_taut_gets_the_minimum_norm_tensions():
    # two identical rope rows (W singular: a self-stress between them, as two ropes side by side): every split of
    # their load solves the LCP; started taut (as linknet starts every touching rope) the basis holds both and its
    # minimum-norm solve (31) shares the load evenly
    W = np.array([[2.0, 2.0, 1.0], [2.0, 2.0, 1.0], [1.0, 1.0, 3.0]])
    b = np.array([4.0, 4.0, 1.0])
    unilateral = np.array([True, True, True])
    lam, active = solve_mixed_lcp(W, b, unilateral, start=unilateral)
    w = W @ lam - b
    assert np.all(lam >= -1e-12) and np.all(w >= -1e-12) and np.all(np.abs(lam * w) < 1e-12)
    assert lam[0] == pytest.approx(lam[1], rel=1e-12)
    # the third rope is slack (W lambda - b = 1 there), the pair's share is the pseudo-inverse's of their block
    assert list(active) == [True, True, False] and lam[2] == 0.0
    assert np.allclose(lam[:2], np.linalg.pinv(W[:2, :2]) @ b[:2], rtol=1e-12)
