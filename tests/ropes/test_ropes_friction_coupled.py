"""Coulomb friction on masses coupled by a rod, slipping from rest, against Newton's laws written here: each mass's
m a = m g + the rod's force + the ground's normal force N and friction -mu N d + its push, the rod's length and
the ground as equations on the accelerations (a linear system for given slip directions d), and Coulomb's law at
the first instant of a slip from rest: d such that the tangential acceleration the friction leaves is lambda d,
lambda > 0, found by a scan of the angle and brentq (one contact) or scipy's fsolve (two). After the first instant
the friction opposes the velocity, and scipy's solve_ivp integrates the same equations.

The scenes are built so that the friction of the coupled masses turns the slip away from the direction of the
acceleration without friction (by 2.9 and 9.7 degrees): a rod leaning on the ground with its foot pushed sideways
(the rod resists the foot's motion along its own plane, not across it), and a dumbbell lying on the ground pushed
at one end at a slant."""
from __future__ import annotations

import numpy as np
import pytest
from rope_references import G
from scipy.integrate import solve_ivp
from scipy.optimize import brentq, fsolve

import linknet_core as ln
from linknet_core.dynamics.unilateral import UnilateralDynamics

Z = np.array([0.0, 0.0, 1.0])
GRAVITY = np.array([0.0, 0.0, -G])


class RodOnGround:
    """Two masses joined by a rod of length R, the ones in ``on_ground`` on the rough plane z = 0, pushes P (2, 3)."""

    def __init__(self, X, masses, pushes, on_ground, mu):
        self.X0, self.m, self.P = np.array(X, float), np.array(masses, float), np.array(pushes, float)
        self.on_ground, self.mu = list(on_ground), mu
        self.R = float(np.linalg.norm(self.X0[1] - self.X0[0]))

    def scene(self):
        return ln.Scene.from_dict({
            "name": "rod_on_ground", "gravity": GRAVITY.tolist(),
            "masses": [{"name": f"m{i + 1}", "position": self.X0[i].tolist(), "mass": float(self.m[i]),
                        "force": self.P[i].tolist()} for i in range(2)],
            "links": [{"a": "m1", "b": "m2", "length": self.R}],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": self.mu}})

    def solve(self, X, U, directions):
        """(accelerations (2, 3), rod tension T (pulling the masses together), normal forces (one per contact))
        with the friction -mu N_c d_c on the contacts: m_i a_i = m_i g + P_i + T s_i e + sum of the ground's forces,
        e . (a_2 - a_1) = -|U_2 - U_1|^2 / R (the length's second derivative), a_c . z = 0."""
        n_c = len(self.on_ground)
        e = (X[1] - X[0]) / np.linalg.norm(X[1] - X[0])
        A = np.zeros((7 + n_c, 7 + n_c))
        b = np.zeros(7 + n_c)
        for i, sign in ((0, 1.0), (1, -1.0)):
            A[3 * i:3 * i + 3, 3 * i:3 * i + 3] = self.m[i] * np.eye(3)
            A[3 * i:3 * i + 3, 6] = -sign * e
            b[3 * i:3 * i + 3] = self.m[i] * GRAVITY + self.P[i]
        for c, (k, d) in enumerate(zip(self.on_ground, directions)):
            A[3 * k:3 * k + 3, 7 + c] = -Z + self.mu * np.asarray(d)
        A[6, 0:3], A[6, 3:6] = -e, e
        b[6] = -float((U[1] - U[0]) @ (U[1] - U[0])) / self.R
        for c, k in enumerate(self.on_ground):
            A[7 + c, 3 * k:3 * k + 3] = Z
        x = np.linalg.solve(A, b)
        return x[:6].reshape(2, 3), x[6], x[7:]

    def starting_directions(self):
        """The slip directions from rest: one angle per contact with each contact's tangential acceleration along
        its d (brentq on a scan for one contact, fsolve from the frictionless directions for two), and lambda > 0."""
        rest = np.zeros((2, 3))

        def unit(phi):
            return np.array([np.cos(phi), np.sin(phi), 0.0])

        def across(phis):
            a = self.solve(self.X0, rest, [unit(p) for p in phis])[0]
            return [a[k, 1] * np.cos(p) - a[k, 0] * np.sin(p) for k, p in zip(self.on_ground, phis)]

        free = self.solve(self.X0, rest, [np.zeros(3)] * len(self.on_ground))[0]
        guess = [np.arctan2(free[k, 1], free[k, 0]) for k in self.on_ground]
        if len(guess) == 1:
            grid = guess[0] + np.linspace(-np.pi, np.pi, 721)[:-1] + 1e-3
            values = [across([p])[0] for p in grid]
            roots = [brentq(lambda p: across([p])[0], lo, hi, xtol=1e-15)
                     for lo, hi, f_lo, f_hi in zip(grid[:-1], grid[1:], values[:-1], values[1:]) if f_lo * f_hi < 0]
            phis = [[p] for p in roots]
        else:
            phis = [list(fsolve(across, guess, xtol=1e-14))]
        good = []
        for p in phis:
            a = self.solve(self.X0, rest, [unit(q) for q in p])[0]
            if all(a[k] @ unit(q) > 0 for k, q in zip(self.on_ground, p)):
                good.append([unit(q) for q in p])
        assert len(good) == 1, "the reference's law has one solution here"
        return good[0], [unit(q) for q in guess]

    def trajectory(self, t_end, n_out):
        start, _ = self.starting_directions()

        def rhs(_, y):
            X, U = y[:6].reshape(2, 3), y[6:].reshape(2, 3)
            directions = []
            for c, k in enumerate(self.on_ground):
                speed = np.linalg.norm(U[k])
                directions.append(U[k] / speed if speed > 0 else start[c])
            a = self.solve(X, U, directions)[0]
            return np.concatenate([U.ravel(), a.ravel()])
        times = np.linspace(0.0, t_end, n_out)
        sol = solve_ivp(rhs, (0.0, t_end), np.concatenate([self.X0.ravel(), np.zeros(6)]), method="DOP853",
                        rtol=1e-13, atol=1e-16, t_eval=times)
        return sol.y[:6].T.reshape(-1, 2, 3), sol.y[6:].T.reshape(-1, 2, 3)


LEANING = RodOnGround([[0, 0, 0], [0.6, 0, 0.8]], [1.0, 2.0], [[0, 4.0, 0], [0, 0, 0]], [0], 0.1)
DUMBBELL = RodOnGround([[0.5, 0, 0], [-0.5, 0, 0]], [1.0, 1.5], [[8.0, 6.0, 0], [0, 0, 0]], [0, 1], 0.3)


def degrees(a, b):
    return np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1, 1)))


@pytest.mark.parametrize("case", [LEANING, DUMBBELL], ids=["leaning rod", "dumbbell"])
def test_friction_at_the_first_instant_of_a_slip_from_rest_opposes_the_acceleration_it_leaves(case):
    start, frictionless = case.starting_directions()
    assert max(degrees(d, f) for d, f in zip(start, frictionless)) > 2.0  # the coupling turns the slip
    a_ref, T_ref, N_ref = case.solve(case.X0, np.zeros((2, 3)), start)
    dyn = UnilateralDynamics(case.scene())
    X, U = np.array(case.X0), np.zeros((2, 3))
    acc, T = dyn.accelerations(X, U)
    normal, tangential = dyn.ground_forces(X, U)
    scale = float(np.abs(a_ref).max())
    assert np.abs(acc - a_ref).max() <= 1e-13 * scale
    assert abs(T[0] - T_ref) <= 1e-13 * abs(T_ref)
    for c, k in enumerate(case.on_ground):
        assert normal[k] == pytest.approx(N_ref[c], rel=1e-13)
        assert np.abs(tangential[k] + case.mu * N_ref[c] * start[c]).max() <= 1e-13 * N_ref[c]


@pytest.mark.parametrize("case", [LEANING, DUMBBELL], ids=["leaning rod", "dumbbell"])
def test_the_slip_from_rest_follows_newtons_laws_with_coulombs_friction(case):
    t_end, n = 0.3, 31
    X_ref, U_ref = case.trajectory(t_end, n)
    run = ln.simulate(case.scene(), t_end, "dop853", rtol=1e-12, n_out=n, error_estimate=False)
    assert run.events == []  # sliding throughout, on the ground
    assert np.abs(run.X - X_ref).max() < 2e-12
    assert np.abs(run.U - U_ref).max() < 2e-11
