"""OpenMM peer: particles + addConstraint (SHAKE/CCMA positions, RATTLE-style velocities), VerletIntegrator.

Units: OpenMM works in nm, ps, amu and kJ/mol, and 1 kJ/mol = 1 amu nm^2/ps^2 exactly, so reading metres as
nm, seconds as ps and kilograms as amu keeps every equation unchanged; no scaling is applied.

What differs from the linknet scene:
- OpenMM refuses constraints involving a massless (immobile) particle, so an anchored mass is a particle of
  mass 1e20 with no gravity on it: it moves by about |T| dt^2 / 1e20 per step, far below every error level.
- VerletIntegrator is a leapfrog: the velocities it holds are at half steps. We hand it v(-dt/2) computed from
  the exact initial accelerations (seed (9),(25)-(26)), and take v(t_end) ~ v(t_end-dt/2) + dt/2 a for
  the energy diagnostic only; the error metric uses positions, which it gives at t_end.
- Gravity is a CustomExternalForce with energy -m g.x per particle.
- The CPU platform computes forces in single precision and accumulates in mixed precision: its errors level
  off well above 1e-9 m; the Reference platform is double precision throughout.
"""
from __future__ import annotations

import numpy as np

from ..index1 import Index1System
from .base import Method, RunResult, Timer, n_steps

ANCHOR_MASS = 1e20


class OpenMMVerlet(Method):
    knob = "dt"
    order = 2

    def __init__(self, platform: str = "Reference", constraint_tolerance: float = 1e-12):
        self.platform = platform
        self.name = f"openmm-verlet-{platform.lower()}"
        self.constraint_tolerance = constraint_tolerance

    def available(self):
        try:
            import openmm  # noqa: F401
            return True, ""
        except ImportError as e:
            return False, f"openmm not installed ({e})"

    def run(self, spec, t_end, dt):
        n, dt = n_steps(t_end, dt)
        with Timer() as setup:
            integ, ctx = _start(_system(spec, ANCHOR_MASS), spec, dt, self.platform, self.constraint_tolerance)
        with Timer() as tm:
            integ.step(n)
            st = ctx.getState(getPositions=True, getVelocities=True)
            X = np.asarray(st.getPositions(asNumpy=True)._value, dtype=float)
            Uh = np.asarray(st.getVelocities(asNumpy=True)._value, dtype=float)
        if not (np.all(np.isfinite(X)) and np.all(np.isfinite(Uh))):
            raise RuntimeError("openmm: non-finite positions or velocities at t_end")
        acc1, _ = Index1System(spec).accelerations(X, Uh)
        U = Uh + 0.5 * dt * acc1
        U[spec.fixed] = 0.0
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n, info={"platform": self.platform})


def _system(spec, anchor_mass):
    """The scene as an OpenMM System: particles (anchors of mass anchor_mass), one constraint per link,
    gravity on the free masses."""
    import openmm as mm
    system = mm.System()
    for k in range(spec.K):
        system.addParticle(anchor_mass if spec.fixed[k] else float(spec.mass[k]))
    for a, b, r in zip(spec.k1, spec.k2, spec.length):
        system.addConstraint(int(a), int(b), float(r))
    grav = mm.CustomExternalForce("-m*(gx*x+gy*y+gz*z)")
    grav.addPerParticleParameter("m")
    for name, v in zip(("gx", "gy", "gz"), spec.gravity):
        grav.addGlobalParameter(name, float(v))
    for k in np.flatnonzero(spec.free):
        grav.addParticle(int(k), [float(spec.mass[k])])
    system.addForce(grav)
    return system


def _start(system, spec, dt, platform, tol):
    """VerletIntegrator and Context (one thread on CPU) at the scene's initial state; the leapfrog holds
    v(-dt/2), computed from the exact initial accelerations."""
    import openmm as mm
    integ = mm.VerletIntegrator(dt)
    integ.setConstraintTolerance(tol)
    ctx = mm.Context(system, integ, mm.Platform.getPlatformByName(platform),
                     {"Threads": "1"} if platform == "CPU" else {})
    acc0, _ = Index1System(spec).accelerations(spec.X0, spec.U0)
    ctx.setPositions(spec.X0)
    ctx.setVelocities(spec.U0 - 0.5 * dt * acc0)
    return integ, ctx


# ------------------------------------------------------------------------------------------ diagnosis
def jacobi_radius(spec, X, preconditioner=None) -> float:
    """Spectral radius of the iteration OpenMM's CCMA performs on this configuration. CCMA corrects all
    constraints at once with the inverse of a coupling matrix it builds once, at Context creation, from
    angles it can find (a third constraint closing a triangle, or a HarmonicAngleForce); with neither, as in
    our scenes, that matrix is the identity and the iteration is plain Jacobi on A = C M^-1 C^T, whose error
    is multiplied by I - D^-1 A per iteration (D = diag A). `preconditioner` = the t = 0 matrix D^-1 A(X0)
    gives the radius had CCMA been handed the initial angles instead. Above 1 the iteration diverges."""
    inv_m = np.where(spec.fixed, 1.0 / ANCHOR_MASS, 1.0 / np.where(spec.fixed, 1.0, spec.mass))
    M = _scaled_coupling(spec, X, inv_m)
    P = np.eye(spec.L) if preconditioner is None else np.linalg.inv(preconditioner)
    return float(np.abs(np.linalg.eigvals(np.eye(spec.L) - P @ M)).max())


def _scaled_coupling(spec, X, inv_m):
    d = X[spec.k2] - X[spec.k1]
    E = d / np.linalg.norm(d, axis=1)[:, None]
    C = np.zeros((spec.L, 3 * spec.K))   # dense: a diagnostic for scenes of a few hundred links
    rows = np.arange(spec.L)
    for a in range(3):
        C[rows, 3 * spec.k1 + a] = E[:, a]
        C[rows, 3 * spec.k2 + a] = -E[:, a]
    A = (C * np.repeat(inv_m, 3)[None, :]) @ C.T
    return A / np.diag(A)[:, None]


def _blowup_time(spec, dt, t_end, platform="Reference", anchor_mass=ANCHOR_MASS, tol=1e-12, angle_hints=False,
                 chunk_s=0.005):
    """Simulate as the benchmark does and report when the coordinates first become non-finite. angle_hints:
    add zero-stiffness HarmonicAngleForce terms at the initial angles (no force; CCMA reads its coupling
    matrix from them)."""
    import openmm as mm
    system = _system(spec, anchor_mass)
    if angle_hints:
        angles = mm.HarmonicAngleForce()
        nbrs = {}
        for a, b in zip(spec.k1, spec.k2):
            nbrs.setdefault(int(a), []).append(int(b))
            nbrs.setdefault(int(b), []).append(int(a))
        for c, ns in nbrs.items():   # diagnostic setup, once
            for i in range(len(ns)):
                for j in range(i + 1, len(ns)):
                    u, v = spec.X0[ns[i]] - spec.X0[c], spec.X0[ns[j]] - spec.X0[c]
                    cos = float(u @ v / (np.linalg.norm(u) * np.linalg.norm(v)))
                    angles.addAngle(ns[i], c, ns[j], float(np.arccos(np.clip(cos, -1.0, 1.0))), 0.0)
        system.addForce(angles)
    integ, ctx = _start(system, spec, dt, platform, tol)
    chunk = max(1, int(round(chunk_s / dt)))
    n, done, residual = int(round(t_end / dt)), 0, None
    while done < n:
        try:
            integ.step(chunk)
        except Exception as e:   # the CPU platform raises on NaN coordinates
            return f"{type(e).__name__} between t = {done * dt:.3f} and {(done + chunk) * dt:.3f} s"
        done += chunk
        X = np.asarray(ctx.getState(getPositions=True).getPositions(asNumpy=True)._value, dtype=float)
        if not np.all(np.isfinite(X)):
            return f"non-finite coordinates between t = {(done - chunk) * dt:.3f} and {done * dt:.3f} s"
        if done * dt <= 0.05 + 1e-12:
            residual = spec.constraint_residual(X)
    return f"finite to t = {t_end} s (constraint residual at 0.05 s: {residual:.2g})"


def diagnose(scene: str = "net_10x10", t_end: float = 0.25):
    """Why OpenMM's runs of `scene` blow up: CCMA's iteration radius along an independent trajectory
    (benchmarks.index1, scipy DOP853 rtol 1e-10), and when OpenMM's coordinates become NaN for several steps,
    anchor masses, tolerances and both platforms."""
    from scipy.integrate import solve_ivp

    from ..work_precision import load_benchmark_scene
    spec = load_benchmark_scene(scene)
    sys_ = Index1System(spec)
    times = [t for t in (0.0, 0.025, 0.05, 0.075, 0.09, 0.1, 0.125, 0.15, 0.2, 0.25) if t <= t_end]
    if t_end > 0.25:   # longer runs (the redundant scenes in motion): every 0.1 s beyond
        times += [float(t) for t in np.arange(0.3, t_end, 0.1)] + [t_end]
    sol = solve_ivp(sys_.rhs, (0, t_end), sys_.y0(), method="DOP853", rtol=1e-10, atol=1e-13, t_eval=times)
    inv_m = np.where(spec.fixed, 1.0 / ANCHOR_MASS, 1.0 / np.where(spec.fixed, 1.0, spec.mass))
    M0 = _scaled_coupling(spec, spec.X0, inv_m)
    print(f"{scene}: radius of CCMA's iteration along the motion (> 1: diverges)")
    for t, y in zip(sol.t, sol.y.T):
        X, _ = sys_.split(y)
        try:
            hinted = f"{jacobi_radius(spec, X, M0):.4f}"
        except np.linalg.LinAlgError:   # redundant links: the coupling matrix has a state of self-stress
            hinted = "none (the t = 0 coupling matrix is singular: self-stress)"
        print(f"  t = {t:5.3f} s   as OpenMM runs it (identity matrix, plain Jacobi): {jacobi_radius(spec, X):.4f}"
              f"   with the t = 0 angles supplied: {hinted}")
    print("when OpenMM's coordinates become non-finite:")
    for dt, kw in ((1e-3, {}), (1e-4, {}), (1e-5, {}), (1e-4, {"anchor_mass": 1e3}), (1e-4, {"tol": 1e-6}),
                   (1e-4, {"platform": "CPU"}), (1e-4, {"angle_hints": True})):
        print(f"  dt = {dt:g} s {kw or ''}: {_blowup_time(spec, dt, t_end, **kw)}", flush=True)


if __name__ == "__main__":
    import sys
    diagnose(*sys.argv[1:2], *map(float, sys.argv[2:3]))   # [scene [t_end]]
