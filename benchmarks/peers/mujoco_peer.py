"""MuJoCo peer: a tree of ball-jointed bodies in generalized coordinates (no constraint solver at all).

Each free mass is a body whose frame sits on its parent mass (the joint) and whose point mass sits at the
child end of the link (inertial pos), so the link length is exact by construction: zero constraint residual.
Integrator RK4 with a fixed timestep (the knob); contacts disabled; mj_step(nstep=n) keeps the loop in C.
The model is built with MuJoCo's MjSpec API (the same bodies, joints and inertials an MJCF file would give:
checked array by array against the XML route on chain_10, chain_100 and double_pendulum); MJCF itself cannot
describe chain_1000, whose 1000 nested <body> elements exceed the XML parser's depth limit
(XML_ELEMENT_DEPTH_EXCEEDED). A compiled model is cached per scene in the (worker) process and only its
timestep changed between settings: the timestep enters no compile-time quantity.

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

import time
from collections import deque

import numpy as np

from .base import Method, OverBudget, RunResult, Timer, Unsupported, n_steps

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

    def check_scene(self, spec):
        if not _is_rigid_cluster(spec):
            _tree(spec)

    def _model(self, key, build):
        """Compiled model from the per-process cache (MjSpec compile of chain_1000 takes ~40 s)."""
        if key not in _MODELS:
            _MODELS.clear()   # one scene at a time: the benchmark runs scene by scene
            _MODELS[key] = build()
        return _MODELS[key]

    def _check_budget(self, m, d, n):
        """Predict the run from the one mj_forward of the setup (RK4 = 4 of them a step) and refuse runs the
        driver would kill at its timeout; chain_1000's 1000-deep dense joint-space mass matrix costs ~2 s a
        forward pass."""
        import mujoco
        t0 = time.perf_counter()
        mujoco.mj_forward(m, d)
        per_forward = time.perf_counter() - t0
        stages = 4 if self.integrator == "RK4" else 1
        predicted = n * stages * per_forward
        if self.run_budget is not None and predicted > self.run_budget:
            raise OverBudget(f"mujoco: {n} {self.integrator} steps x {stages} forward passes x {per_forward:.3g} s "
                             f"(measured) = {predicted:.3g} s predicted > run budget {self.run_budget:.3g} s")

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
            model = self._model(("rigid", spec.digest(), self.integrator),
                                lambda: rigid_body_model(spec.gravity, M, com, inertia, self.integrator))
            model.opt.timestep = dt
            d = mujoco.MjData(model)
            d.qvel[:3] = v_com
            d.qvel[3:6] = w   # free joint: angular velocity in the body frame, aligned with the world at t=0
            self._check_budget(model, d, n)
        with Timer() as tm:
            mujoco.mj_step(model, d, nstep=n)
        R = d.xmat[1].reshape(3, 3)
        X = d.xpos[1] + r @ R.T
        wb = d.qvel[3:6]
        U = d.qvel[:3] + np.cross(R @ wb, r @ R.T)
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n, info={"model": "one free rigid body"})

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
            eps = inertia_eps(parent, order)
            m = self._model(("tree", spec.digest(), self.integrator),
                            lambda: tree_model(spec, parent, order, eps, self.integrator))
            m.opt.timestep = dt
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
            self._check_budget(m, d, n)
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
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n, info={"inertia_eps": eps})


_MODELS: dict = {}


def inertia_eps(parent, order) -> float:
    """eps = max(1e-12, 1e-15 N^3) for a tree N bodies deep (see the module docstring)."""
    depth = {}
    for c in order:   # breadth-first: parents first
        depth[c] = depth.get(parent[c], 0) + 1
    return max(EPS_INERTIA, 1e-15 * max(depth.values()) ** 3)


def _body_frames(spec, parent, order, eps):
    """Per body (parents first): name, parent body (None for the world), pos relative to the parent body frame,
    inertial pos, mass and isotropic inertia. A body's frame sits on its parent mass, so its pos is relative to
    the parent body's frame, whose origin is the grandparent mass (or the world for children of anchors)."""
    for c in order:
        p = parent[c]
        r = spec.X0[c] - spec.X0[p]
        pos = spec.X0[p] - spec.X0[parent[p]] if p in parent else spec.X0[p]
        yield c, (p if p in parent else None), pos, r, float(spec.mass[c]), eps * float(spec.mass[c]) * float(r @ r)


def _spec_options(s, gravity, integrator):
    import mujoco
    s.option.integrator = getattr(mujoco.mjtIntegrator, f"mjINT_{integrator}")
    s.option.gravity = [float(v) for v in gravity]
    s.option.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    s.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    s.compiler.autolimits = True


def tree_model(spec, parent, order, eps, integrator="RK4"):
    """Ball-jointed bodies built with MjSpec (no XML nesting limit); the same model as mjcf_tree()."""
    import mujoco
    s = mujoco.MjSpec()
    _spec_options(s, spec.gravity, integrator)
    bodies = {}
    for c, p, pos, r, mass, inertia in _body_frames(spec, parent, order, eps):
        b = (bodies[p] if p is not None else s.worldbody).add_body(name=f"b{c}", pos=[float(v) for v in pos])
        b.add_joint(name=f"j{c}", type=mujoco.mjtJoint.mjJNT_BALL, damping=0.0, armature=0.0)
        b.explicitinertial = True
        b.mass = mass
        b.ipos = [float(v) for v in r]
        b.inertia = [inertia] * 3
        bodies[c] = b
    return s.compile()


def mjcf_tree(spec, parent, order, eps, dt, integrator="RK4") -> str:
    """The same model as MJCF text (MuJoCo's usual route; its parser stops at ~400 nested bodies). Kept to
    check tree_model() against it (tests/test_benchmark_quick.py)."""
    children = {}
    for c, p, pos, r, mass, inertia in _body_frames(spec, parent, order, eps):
        children.setdefault(p, []).append((c, pos, r, mass, inertia))
    lines = []
    stack = [(item, 1) for item in reversed(children.get(None, []))]
    closing = []
    # iterative depth-first emission (no recursion limit for deep chains)
    while stack:
        (c, pos, r, mass, inertia), depth = stack.pop()
        while closing and closing[-1] >= depth:
            lines.append("  " * closing.pop() + "</body>")
        ind = "  " * depth
        lines += [f'{ind}<body name="b{c}" pos="{_f(pos[0])} {_f(pos[1])} {_f(pos[2])}">',
                  f'{ind}  <joint name="j{c}" type="ball" damping="0" armature="0"/>',
                  f'{ind}  <inertial pos="{_f(r[0])} {_f(r[1])} {_f(r[2])}" mass="{_f(mass)}" '
                  f'diaginertia="{_f(inertia)} {_f(inertia)} {_f(inertia)}"/>']
        closing.append(depth)
        stack += [(item, depth + 1) for item in reversed(children.get(c, []))]
    while closing:
        lines.append("  " * closing.pop() + "</body>")
    g = spec.gravity
    return (f'<mujoco><option timestep="{_f(dt)}" integrator="{integrator}" '
            f'gravity="{_f(g[0])} {_f(g[1])} {_f(g[2])}"><flag contact="disable"/></option>'
            f'<compiler angle="radian" inertiafromgeom="false" autolimits="true"/>'
            "<worldbody>\n" + "\n".join(lines) + "\n</worldbody></mujoco>")


def rigid_body_model(gravity, mass, com, inertia, integrator="RK4"):
    """One free body with the exact mass properties of the point masses, built with MjSpec."""
    import mujoco
    s = mujoco.MjSpec()
    _spec_options(s, gravity, integrator)
    b = s.worldbody.add_body(name="rigid", pos=[float(v) for v in com])
    b.add_freejoint(name="free")
    b.explicitinertial = True
    b.mass = float(mass)
    b.ipos = [0.0, 0.0, 0.0]
    b.fullinertia = [float(inertia[0, 0]), float(inertia[1, 1]), float(inertia[2, 2]), float(inertia[0, 1]),
                     float(inertia[0, 2]), float(inertia[1, 2])]
    return s.compile()
