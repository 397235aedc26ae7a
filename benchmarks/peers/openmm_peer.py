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
        import openmm as mm
        n, dt = n_steps(t_end, dt)
        with Timer() as setup:
            system = mm.System()
            for k in range(spec.K):
                system.addParticle(ANCHOR_MASS if spec.fixed[k] else float(spec.mass[k]))
            for a, b, r in zip(spec.k1, spec.k2, spec.length):
                system.addConstraint(int(a), int(b), float(r))
            grav = mm.CustomExternalForce("-m*(gx*x+gy*y+gz*z)")
            grav.addPerParticleParameter("m")
            for name, v in zip(("gx", "gy", "gz"), spec.gravity):
                grav.addGlobalParameter(name, float(v))
            for k in np.flatnonzero(spec.free):
                grav.addParticle(int(k), [float(spec.mass[k])])
            system.addForce(grav)
            integ = mm.VerletIntegrator(dt)
            integ.setConstraintTolerance(self.constraint_tolerance)
            platform = mm.Platform.getPlatformByName(self.platform)
            props = {"Threads": "1"} if self.platform == "CPU" else {}
            ctx = mm.Context(system, integ, platform, props)
            acc0, _ = Index1System(spec).accelerations(spec.X0, spec.U0)
            ctx.setPositions(spec.X0)
            ctx.setVelocities(spec.U0 - 0.5 * dt * acc0)   # leapfrog wants v(-dt/2)
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
