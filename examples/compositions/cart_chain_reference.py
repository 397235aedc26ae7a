#!/usr/bin/env python3
"""Monolithic reference of the cart-and-chain composition, written independently of linknet.

    python examples/compositions/cart_chain_reference.py        # its own checks, printed

A cart of mass m_c runs on a horizontal rail (position x along the x axis). A planar chain of n point
masses m_1..m_n hangs from the cart (the hook is the cart's position) through rigid massless links of
lengths l_1..l_n (link i joins mass i-1 to mass i, mass 0 being the hook). Gravity g acts along -z.
Generalized coordinates q = (x, theta_1..theta_n), theta_i the angle of link i from the downward vertical:

    X_j = x + sum_{i<=j} l_i sin(theta_i),    Z_j = z_hook - sum_{i<=j} l_i cos(theta_i)

With mu_i = sum_{j>=i} m_j (the mass hanging below link i), Lagrange's equations are M(q) q'' = f(q, q'):

    M_xx = m_c + mu_1,   M_x,i = mu_i l_i cos(theta_i),   M_i,k = mu_max(i,k) l_i l_k cos(theta_i - theta_k)
    f_x  = F_drive + sum_i mu_i l_i sin(theta_i) theta_i'^2
    f_i  = -sum_k mu_max(i,k) l_i l_k sin(theta_i - theta_k) theta_k'^2 - g mu_i l_i sin(theta_i)

(T = m_c x'^2/2 + sum_j m_j (X_j'^2 + Z_j'^2)/2, V = sum_j m_j g Z_j; the x'-theta_i' cross terms of
d/dt dT/dtheta_i' and dT/dtheta_i cancel.) n = 1 is the classic cart-pendulum.

The force the chain exerts on the hook (what the cart feels from the chain) is minus the rate of the chain's
momentum less gravity:  Fx = -sum_j m_j X_j'',  Fz = -sum_j m_j (Z_j'' + g).

The chain's added mass along the rail, m_eff(q) = mu_1 - b^T M_tt^-1 b (b_i = M_x,i, M_tt the angle block),
is dFx/dA for a hook acceleration A with the chain's state held: the Schur complement that an explicit
force-for-motion coupling feeds back each step (cart_chain.py). 0 <= m_eff <= mu_1.

Integrated with scipy's DOP853 at rtol 1e-12 (atol 1e-13): the energy (F_drive = 0) and the horizontal
momentum (no horizontal force) are conserved to ~1e-12 relative, which `checks()` measures.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import solve_ivp

G = 9.81


@dataclass(frozen=True)
class CartChain:
    """Parameters: cart mass m_c (kg), chain masses m (n,) kg, link lengths l (n,) m, gravity g (m/s2)."""

    m_c: float
    m: np.ndarray
    l: np.ndarray
    g: float = G

    def __post_init__(self):
        m, l = np.atleast_1d(np.asarray(self.m, float)), np.atleast_1d(np.asarray(self.l, float))
        if m.shape != l.shape or m.ndim != 1 or not m.size:
            raise ValueError(f"chain masses {m.shape} and link lengths {l.shape} must be two equal-length lists")
        if not (self.m_c > 0 and np.all(m > 0) and np.all(l > 0)):
            raise ValueError("cart mass, chain masses and link lengths must all be > 0")
        object.__setattr__(self, "m", m)
        object.__setattr__(self, "l", l)

    @property
    def n(self) -> int:
        return self.m.size

    @property
    def mu(self) -> np.ndarray:
        """mu_i: the mass below link i (mu_1 = the chain's mass)."""
        return np.cumsum(self.m[::-1])[::-1]

    def _mu_outer(self) -> np.ndarray:
        idx = np.arange(self.n)
        return self.mu[np.maximum.outer(idx, idx)]

    def mass_matrix(self, q) -> np.ndarray:
        th = q[1:]
        M = np.empty((self.n + 1, self.n + 1))
        M[0, 0] = self.m_c + self.mu[0]
        b = self.mu * self.l * np.cos(th)
        M[0, 1:] = M[1:, 0] = b
        M[1:, 1:] = self._mu_outer() * np.outer(self.l, self.l) * np.cos(np.subtract.outer(th, th))
        return M

    def forces(self, q, qd, F_drive=0.0) -> np.ndarray:
        th, thd = q[1:], qd[1:]
        f = np.empty(self.n + 1)
        f[0] = F_drive + np.sum(self.mu * self.l * np.sin(th) * thd ** 2)
        f[1:] = (-(self._mu_outer() * np.outer(self.l, self.l) * np.sin(np.subtract.outer(th, th))) @ thd ** 2
                 - self.g * self.mu * self.l * np.sin(th))
        return f

    def accelerations(self, q, qd, F_drive=0.0) -> np.ndarray:
        return np.linalg.solve(self.mass_matrix(q), self.forces(q, qd, F_drive))

    # ---- the chain's masses in Cartesian coordinates (hook at height 0)
    def positions(self, q) -> np.ndarray:
        """(n, 2): x and z of each chain mass."""
        th = q[1:]
        return np.stack([q[0] + np.cumsum(self.l * np.sin(th)), -np.cumsum(self.l * np.cos(th))], 1)

    def velocities(self, q, qd) -> np.ndarray:
        th, thd = q[1:], qd[1:]
        return np.stack([qd[0] + np.cumsum(self.l * np.cos(th) * thd), np.cumsum(self.l * np.sin(th) * thd)], 1)

    def chain_accelerations(self, q, qd, qdd) -> np.ndarray:
        th, thd, thdd = q[1:], qd[1:], qdd[1:]
        ax = qdd[0] + np.cumsum(self.l * (np.cos(th) * thdd - np.sin(th) * thd ** 2))
        az = np.cumsum(self.l * (np.sin(th) * thdd + np.cos(th) * thd ** 2))
        return np.stack([ax, az], 1)

    def hook_force(self, q, qd, F_drive=0.0) -> np.ndarray:
        """(Fx, Fz): the force the chain exerts on the hook."""
        acc = self.chain_accelerations(q, qd, self.accelerations(q, qd, F_drive))
        return np.array([-self.m @ acc[:, 0], -self.m @ (acc[:, 1] + self.g)])

    def added_mass(self, q) -> float:
        """m_eff(q) = mu_1 - b^T M_tt^-1 b: minus dFx/dA of the chain alone, its state held."""
        M = self.mass_matrix(q)
        b = M[1:, 0]
        return float(self.mu[0] - b @ np.linalg.solve(M[1:, 1:], b))

    # ---- invariants
    def energy(self, q, qd) -> float:
        V = self.velocities(q, qd)
        return float(0.5 * self.m_c * qd[0] ** 2 + 0.5 * self.m @ np.sum(V ** 2, 1)
                     + self.g * self.m @ self.positions(q)[:, 1])

    def momentum_x(self, q, qd) -> float:
        return float(self.m_c * qd[0] + self.m @ self.velocities(q, qd)[:, 0])


def simulate(model: CartChain, q0, qd0, t_eval, drive=None, rtol=1e-12, atol=1e-13) -> dict:
    """Integrate from (q0, qd0) and sample at t_eval (drive: F_drive(t), N, or None).

    Returns t, q (m, rad), qd, x, v, a (the cart's position, velocity, acceleration), F (n_t, 2) the hook
    force (x, z), P (n_t, n, 2) the chain masses' x, z and m_eff (n_t,) the chain's added mass."""
    n = model.n
    drive = drive or (lambda t: 0.0)

    def rhs(t, y):
        q, qd = y[:n + 1], y[n + 1:]
        return np.concatenate([qd, model.accelerations(q, qd, drive(t))])

    t_eval = np.asarray(t_eval, float)
    sol = solve_ivp(rhs, (t_eval[0], t_eval[-1]), np.concatenate([q0, qd0]).astype(float), method="DOP853",
                    t_eval=t_eval, rtol=rtol, atol=atol)
    if not sol.success:
        raise RuntimeError(f"reference integration failed: {sol.message}")
    q, qd = sol.y[:n + 1].T, sol.y[n + 1:].T
    qdd = np.array([model.accelerations(a, b, drive(t)) for t, a, b in zip(sol.t, q, qd)])
    return dict(t=sol.t, q=q, qd=qd, x=q[:, 0], v=qd[:, 0], a=qdd[:, 0],
                F=np.array([model.hook_force(a, b, drive(t)) for t, a, b in zip(sol.t, q, qd)]),
                P=np.array([model.positions(a) for a in q]),
                m_eff=np.array([model.added_mass(a) for a in q]),
                energy=np.array([model.energy(a, b) for a, b in zip(q, qd)]),
                momentum=np.array([model.momentum_x(a, b) for a, b in zip(q, qd)]), nfev=sol.nfev)


def cart_pendulum_accelerations(M, m, l, g, theta, thetad, F=0.0) -> tuple[float, float]:
    """The classic cart-pendulum (textbook closed form, angle from the downward vertical)."""
    s, c = np.sin(theta), np.cos(theta)
    den = M + m * s * s
    xdd = (F + m * s * (l * thetad ** 2 + g * c)) / den
    thdd = -(F * c + m * l * thetad ** 2 * s * c + (M + m) * g * s) / (l * den)
    return float(xdd), float(thdd)


def checks(verbose=True) -> dict:
    """The reference checked on its own: n = 1 against the textbook cart-pendulum, the small-oscillation
    frequency sqrt(g (m_c + m) / (m_c l)), and energy / momentum conservation of a 5-mass chain."""
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(20):
        M, m, l = rng.uniform(0.2, 3, 3)
        th, thd, F, xd = rng.uniform(-2, 2, 4)
        model = CartChain(M, [m], [l])
        got = model.accelerations(np.array([0.3, th]), np.array([xd, thd]), F)
        want = cart_pendulum_accelerations(M, m, l, G, th, thd, F)
        worst = max(worst, float(np.max(np.abs(got - want) / (1 + np.abs(want)))))
    # small oscillations: theta = eps cos(w t) with w^2 = g (M + m) / (M l)
    M, m, l, eps = 0.7, 0.4, 0.5, 1e-4
    w = np.sqrt(G * (M + m) / (M * l))
    period = 2 * np.pi / w
    r = simulate(CartChain(M, [m], [l]), [0.0, eps], [0.0, 0.0], np.linspace(0, 3 * period, 3001))
    period_error = float(np.max(np.abs(r["q"][:, 1] - eps * np.cos(w * r["t"]))) / eps)
    # a 5-mass chain released tilted, the cart moving: energy and horizontal momentum
    model = CartChain(0.5, np.full(5, 0.2), np.full(5, 0.2))
    r = simulate(model, np.r_[0.0, np.linspace(0.6, 0.2, 5)], np.r_[0.3, np.zeros(5)], np.linspace(0, 3, 301))
    energy_drift = float(np.max(np.abs(r["energy"] - r["energy"][0])) / np.max(np.abs(r["energy"])))
    momentum_drift = float(np.max(np.abs(r["momentum"] - r["momentum"][0])) / abs(r["momentum"][0]))
    out = dict(cart_pendulum=worst, small_oscillation=period_error, energy=energy_drift, momentum=momentum_drift,
               m_eff_range=(float(r["m_eff"].min()), float(r["m_eff"].max())))
    if verbose:
        print("monolithic cart-chain reference (generalized coordinates, DOP853 rtol 1e-12):")
        print(f"  n = 1 vs textbook cart-pendulum, 20 random states: max relative difference {worst:.1e}")
        print(f"  small oscillations vs eps cos(sqrt(g (M+m)/(M l)) t), 3 periods: max error / eps {period_error:.1e}")
        print(f"  5-mass chain, 3 s: relative energy drift {energy_drift:.1e}, momentum drift {momentum_drift:.1e}; "
              f"added mass m_eff in [{out['m_eff_range'][0]:.3f}, {out['m_eff_range'][1]:.3f}] kg (chain 1 kg)")
    return out


if __name__ == "__main__":
    checks()
