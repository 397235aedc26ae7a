"""MuJoCo peer: a tree of ball-jointed bodies in generalized coordinates (no constraint solver at all).

Each free mass is a body whose frame sits on its parent mass (the joint) and whose point mass sits at the
child end of the link (inertial pos), so the link length is exact by construction: zero constraint residual.
Integrator RK4 with a fixed timestep (the knob); contacts disabled; mj_step(nstep=n) keeps the loop in C.

What differs / what it cannot model:
- A point mass has no rotational inertia; MuJoCo needs positive inertia on moving bodies (> mjMINVAL = 1e-15),
  so each body gets an isotropic inertia eps*m*R^2 about the mass: a relative perturbation eps of the dynamics,
  which bounds MuJoCo's attainable error. The spin of the first link then has inertia ~eps/N^3 of the chain's
  (N bodies deep), so eps = max(1e-12, 1e-15 N^3): 1e-12 up to N = 10, 1e-9 for chain_100, 1e-6 for
  chain_1000. Measured: with eps = 1e-12 MuJoCo warns "Inertia matrix is too close to singular" on chain_30
  and chain_100 and is off by 0.44-0.49 m at t = 0.3 s; eps = 1e-9 gives 1.8e-10 and 6.4e-10 m there. To keep eps*m*R^2 above mjMINVAL for small links and masses (chain_1000: m R^2 ~ 1e-9)
  the model is built in scaled units, length unit = median link length, mass unit = median free mass (time
  unchanged, gravity scaled accordingly): an exact change of units, undone on the way out.
- Only trees hanging from anchored masses: every free mass has exactly one path to one anchor (links = free
  masses, each component with one anchor). Closed loops (four_bar, net, truss, tetrahedron) would need
  equality constraints, which in MuJoCo are soft (solref/solimp regularised) and only of the connect/weld kind
  (coincident points), not a distance between two masses: not a faithful rigid link, so not modelled.
"""
from __future__ import annotations

from collections import deque

import numpy as np

from .base import Method, RunResult, Timer, Unsupported, n_steps

EPS_INERTIA = 1e-12


def _f(x) -> str:
    return f"{float(x):.17g}"


def _tree(spec):
    """Parent of each free mass along the unique path to its anchor, in breadth-first order."""
    if spec.L != int(np.sum(spec.free)):
        raise Unsupported(f"mujoco: {spec.L} links for {int(np.sum(spec.free))} free masses: "
                          "not a tree hanging from anchors (closed loop or floating body)")
    adj = [[] for _ in range(spec.K)]
    for a, b in zip(spec.k1, spec.k2):
        adj[a].append(b)
        adj[b].append(a)
    parent = {}
    order = []
    q = deque(int(k) for k in np.flatnonzero(spec.fixed))
    seen = set(q)
    while q:
        k = q.popleft()
        for c in adj[k]:
            if c in seen:
                if parent.get(k) != c and not (spec.fixed[c] and spec.fixed[k]):
                    raise Unsupported("mujoco: closed loop in the link graph (needs soft equality constraints)")
                continue
            if spec.fixed[c]:
                continue
            seen.add(c)
            parent[c] = k
            order.append(c)
            q.append(c)
    if len(order) != int(np.sum(spec.free)):
        raise Unsupported("mujoco: some free masses are not connected to an anchor (floating body)")
    return parent, order


def _is_rigid_cluster(spec) -> bool:
    if np.any(spec.fixed) or spec.K < 3:
        return False
    X = spec.X0
    E = (X[spec.k2] - X[spec.k1]) / spec.length[:, None]
    C = np.zeros((spec.L, 3 * spec.K))
    for l in range(spec.L):   # setup only
        C[l, 3 * spec.k1[l]:3 * spec.k1[l] + 3] = E[l]
        C[l, 3 * spec.k2[l]:3 * spec.k2[l] + 3] = -E[l]
    return int(np.linalg.matrix_rank(C, tol=1e-9)) == 3 * spec.K - 6


class MujocoRK4(Method):
    knob = "dt"
    order = 4

    def __init__(self, integrator: str = "RK4"):
        self.integrator = integrator
        self.name = f"mujoco-{integrator.lower()}"
        self.order = 4 if integrator == "RK4" else 1

    def available(self):
        try:
            import mujoco  # noqa: F401
            return True, ""
        except ImportError as e:
            return False, f"mujoco not installed ({e})"

    MAX_DEPTH = 400

    def check_scene(self, spec):
        if not _is_rigid_cluster(spec):
            parent, order = _tree(spec)
            depth = {}
            for c in order:
                depth[c] = depth.get(parent[c], 0) + 1
            if max(depth.values()) > self.MAX_DEPTH:
                raise Unsupported(f"mujoco: {max(depth.values())} nested bodies; MuJoCo's XML parser stops at "
                                  "XML_ELEMENT_DEPTH_EXCEEDED (measured on chain_1000); building the model through "
                                  "MjSpec instead is not done here")

    def _run_rigid(self, spec, t_end, dt):
        """The whole scene is one rigid body: a free joint, exact mass properties of the point masses."""
        import mujoco
        n, dt = n_steps(t_end, dt)
        with Timer() as setup:
            m = spec.mass
            M = float(m.sum())
            com = (m[:, None] * spec.X0).sum(axis=0) / M
            r = spec.X0 - com
            inertia = np.sum(m[:, None, None] * (np.einsum("ij,ij->i", r, r)[:, None, None] * np.eye(3)
                                                 - np.einsum("ij,ik->ijk", r, r)), axis=0)
            if np.linalg.eigvalsh(inertia)[0] < 1e-9 * np.trace(inertia):   # collinear masses: keep it positive
                inertia += EPS_INERTIA * np.trace(inertia) * np.eye(3)
            v_com = (m[:, None] * spec.U0).sum(axis=0) / M
            # angular velocity from the angular momentum: L = I w (exact for a rigid motion)
            Lmom = np.sum(m[:, None] * np.cross(r, spec.U0 - v_com), axis=0)
            w = np.linalg.solve(inertia, Lmom)
            g = spec.gravity
            fi = " ".join(_f(v) for v in (inertia[0, 0], inertia[1, 1], inertia[2, 2], inertia[0, 1],
                                          inertia[0, 2], inertia[1, 2]))
            xml = (f'<mujoco><option timestep="{_f(dt)}" integrator="{self.integrator}" '
                   f'gravity="{_f(g[0])} {_f(g[1])} {_f(g[2])}"><flag contact="disable"/></option>'
                   f'<worldbody><body name="rigid" pos="{_f(com[0])} {_f(com[1])} {_f(com[2])}">'
                   f'<freejoint name="free"/><inertial pos="0 0 0" mass="{_f(M)}" fullinertia="{fi}"/>'
                   f'</body></worldbody></mujoco>')
            model = mujoco.MjModel.from_xml_string(xml)
            d = mujoco.MjData(model)
            d.qvel[:3] = v_com
            d.qvel[3:6] = w   # free joint: angular velocity in the body frame, aligned with the world at t=0
            mujoco.mj_forward(model, d)
        with Timer() as tm:
            mujoco.mj_step(model, d, nstep=n)
        R = d.xmat[1].reshape(3, 3)
        X = d.xpos[1] + r @ R.T
        wb = d.qvel[3:6]
        U = d.qvel[:3] + np.cross(R @ wb, r @ R.T)
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n, info={"model": "one free rigid body"})

    def _xml(self, spec, dt, parent, order):
        children = {}
        for c in order:
            children.setdefault(parent[c], []).append(c)

        def body(c, indent):
            p = parent[c]
            r = spec.X0[c] - spec.X0[p]
            rel = spec.X0[p] - (spec.X0[parent[p]] if p in parent else 0.0)
            pos = rel if p in parent else spec.X0[p]
            inertia = self._eps * spec.mass[c] * float(r @ r)
            s = (f'{indent}<body name="b{c}" pos="{_f(pos[0])} {_f(pos[1])} {_f(pos[2])}">\n'
                 f'{indent}  <joint name="j{c}" type="ball" damping="0" armature="0"/>\n'
                 f'{indent}  <inertial pos="{_f(r[0])} {_f(r[1])} {_f(r[2])}" mass="{_f(spec.mass[c])}" '
                 f'diaginertia="{_f(inertia)} {_f(inertia)} {_f(inertia)}"/>\n')
            for g in children.get(c, []):
                s += body(g, indent + "  ")
            return s + f"{indent}</body>\n"

        g = spec.gravity
        roots = [c for c in order if not (parent[c] in parent)]
        import sys
        sys.setrecursionlimit(max(sys.getrecursionlimit(), 4 * len(order) + 1000))   # chain_1000 nests 1000 deep
        return (f'<mujoco><option timestep="{_f(dt)}" integrator="{self.integrator}" '
                f'gravity="{_f(g[0])} {_f(g[1])} {_f(g[2])}"><flag contact="disable"/></option>'
                f'<compiler angle="radian" inertiafromgeom="false" autolimits="true"/>'
                f"<worldbody>\n" + "".join(body(c, "  ") for c in roots) + "</worldbody></mujoco>")

    def run(self, spec, t_end, dt):
        import mujoco
        if _is_rigid_cluster(spec):
            return self._run_rigid(spec, t_end, dt)
        n, dt = n_steps(t_end, dt)
        from dataclasses import replace
        lam = float(np.median(spec.length))
        mu = float(np.median(spec.mass[spec.free]))
        spec_si = spec
        spec = replace(spec, mass=spec.mass / mu, X0=spec.X0 / lam, U0=spec.U0 / lam, length=spec.length / lam,
                       gravity=spec.gravity / lam)
        with Timer() as setup:
            parent, order = _tree(spec)
            depth = {}
            for c in order:   # breadth-first: parents first
                depth[c] = depth.get(parent[c], 0) + 1
            self._eps = max(EPS_INERTIA, 1e-15 * max(depth.values()) ** 3)
            # nested body frames: a body sits on its parent mass; the XML gives its pos relative to the parent body
            # frame, whose origin is the grandparent mass (or the world for children of anchors)
            m = mujoco.MjModel.from_xml_string(self._xml(spec, dt, parent, order))
            d = mujoco.MjData(m)
            omega = {}
            for c in order:   # body angular velocity carrying the mass velocity (perpendicular to the link)
                p = parent[c]
                r = spec.X0[c] - spec.X0[p]
                omega[c] = np.cross(r, spec.U0[c] - spec.U0[p]) / float(r @ r)
            for c in order:
                jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, f"j{c}")
                adr = m.jnt_dofadr[jid]
                w_parent = omega.get(parent[c], np.zeros(3))
                d.qvel[adr:adr + 3] = omega[c] - w_parent   # frames start aligned with the world: local == world
            mujoco.mj_forward(m, d)
            bid = {c: mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, f"b{c}") for c in order}
        with Timer() as tm:
            mujoco.mj_step(m, d, nstep=n)
        X = spec.X0.copy()
        U = np.zeros_like(spec.U0)
        jacp = np.zeros((3, m.nv))
        for c in order:
            X[c] = d.xipos[bid[c]]
            mujoco.mj_jac(m, d, jacp, None, X[c], bid[c])
            U[c] = jacp @ d.qvel
        X, U = X * lam, U * lam
        X[spec_si.fixed] = spec_si.X0[spec_si.fixed]
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n, info={"inertia_eps": self._eps})
