"""Independent references for the rope and ground tests: closed-form ballistic flights, their event times by root
finds written here, and scipy's solve_ivp of the pendulum between a rope's jerks (nothing of linknet's)."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

import linknet_core as ln

G = 9.81


def bob_scene(X0, V0, R=1.0, mass=1.0, restitution=0.0) -> ln.Scene:
    """A bob of ``mass`` on a rope of length R from a pivot at the origin, gravity -z."""
    rope = {"a": 1, "b": 2, "kind": "rope", "length": R}
    if restitution:
        rope["restitution"] = restitution
    return ln.Scene.from_dict({"name": "bob", "gravity": [0, 0, -G],
                               "masses": [{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                                          {"name": "bob", "position": list(X0), "mass": mass,
                                           "velocity": list(V0)}],
                               "links": [rope]})


def slope(alpha, mu, v_down=0.0, mass=3.0):
    """A block on a plane tilted by alpha about y, (its normal, its downhill direction)."""
    n = np.array([np.sin(alpha), 0.0, np.cos(alpha)])
    down = np.array([np.cos(alpha), 0.0, -np.sin(alpha)])
    scene = ln.Scene.from_dict({"name": "slope", "gravity": [0, 0, -G],
                                "masses": [{"name": "block", "position": [0, 0, 0], "mass": mass,
                                            "velocity": (v_down * down).tolist()}],
                                "ground": {"point": [0, 0, 0], "normal": n.tolist(), "friction": mu}})
    return scene, n, down


def ballistic(X, V, s):
    """Position and velocity s seconds into a free flight from (X, V) under gravity -z."""
    g = np.array([0.0, 0.0, -G])
    return X + V * s + 0.5 * g * s * s, V + g * s


def first_exit(X, V, R, s_max):
    """The first s in (0, s_max] at which a free flight from (X, V), |X| <= R, reaches |X(s)| = R, or None: a sign
    change of R^2 - |X(s)|^2 on a fine grid, then brentq."""
    def f(s):
        Xs, _ = ballistic(X, V, s)
        return R * R - Xs @ Xs
    grid = np.linspace(0.0, s_max, 4001)[1:]
    values = np.array([f(s) for s in grid])
    below = np.flatnonzero(values < 0)
    if below.size == 0:
        return None
    j = int(below[0])
    lo = grid[j - 1] if j else 1e-12
    return brentq(f, lo, grid[j], xtol=1e-15, rtol=1e-15, maxiter=200)


class BobReference:
    """A bob on an inelastic rope (pivot at the origin, motion in the x-z plane), event by event: ballistic flights
    (closed form) ending where |X| = R (brentq), the jerk removing the radial velocity, the pendulum theta'' =
    -(g/R) sin(theta) (solve_ivp, rtol 1e-12) until the rope's tension m (R theta'^2 + g cos(theta)) falls to 0."""

    def __init__(self, X0, V0, R, t_end, mass=1.0):
        self.R, self.mass = R, mass
        self.pieces = []  # (t0, t1, kind, data)
        self.events = []  # (t, kind, impulse)
        t, X, V = 0.0, np.array(X0, float), np.array(V0, float)
        while t < t_end:
            s = first_exit(X, V, R, t_end - t)
            if s is None:
                self.pieces.append((t, t_end, "flight", (X, V)))
                break
            self.pieces.append((t, t + s, "flight", (X, V)))
            t += s
            X, V = ballistic(X, V, s)
            r = X / R
            radial = V @ r
            self.events.append((t, "taut", mass * radial))
            V = V - radial * r
            theta = np.arctan2(X[0], -X[2])
            omega = (X[0] * V[2] - X[2] * V[0]) / R ** 2

            def slack(_, y):
                return R * y[1] ** 2 + G * np.cos(y[0])
            slack.terminal, slack.direction = True, -1
            sol = solve_ivp(lambda _, y: [y[1], -G / R * np.sin(y[0])], (t, t_end), [theta, omega],
                            method="DOP853", rtol=1e-12, atol=1e-12, dense_output=True, events=slack)
            t1 = sol.t_events[0][0] if sol.t_events[0].size else t_end
            self.pieces.append((t, t1, "pendulum", sol.sol))
            if t1 >= t_end:
                break
            self.events.append((t1, "slack", 0.0))
            theta, omega = sol.sol(t1)
            X = R * np.array([np.sin(theta), 0.0, -np.cos(theta)])
            V = R * omega * np.array([np.cos(theta), 0.0, np.sin(theta)])
            t = t1

    def position(self, t):
        for t0, t1, kind, data in self.pieces:
            if t0 <= t <= t1:
                if kind == "flight":
                    return ballistic(*data, t - t0)[0]
                theta = data(t)[0]
                return self.R * np.array([np.sin(theta), 0.0, -np.cos(theta)])
        raise ValueError(t)


def central_differences(outputs, inputs: dict, fixed, names: tuple, h: float) -> dict:
    """{(output, input): block} as InterfaceJacobian holds them: the derivatives of the first len(names) values of
    ``outputs(**inputs)`` (arrays, named ``names``) by each entry (k, i) of each input array, by central differences
    of step h; a force on an anchored mass (``fixed[k]``, input "F") is no input and its columns stay 0."""
    base = outputs(**inputs)
    blocks = {}
    for name, value in inputs.items():
        out = [np.zeros(np.shape(base[j]) + value.shape) for j in range(len(names))]
        for k in range(value.shape[0]):
            if name == "F" and fixed[k]:
                continue
            for i in range(3):
                sides = []
                for sign in (1.0, -1.0):
                    moved = {n: v.copy() for n, v in inputs.items()}
                    moved[name][k, i] += sign * h
                    sides.append(outputs(**moved))
                for j in range(len(names)):
                    out[j][..., k, i] = (sides[0][j] - sides[1][j]) / (2 * h)
        for j, o in enumerate(names):
            blocks[o, name] = out[j]
    return blocks
