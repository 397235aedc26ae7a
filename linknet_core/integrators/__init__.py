"""Integrators: choose one by name. Each is a small unit defined by its method."""
from __future__ import annotations

from ..errors import SolverError
from .base import FixedStepIntegrator, Integrator
from .composition import Composition, Suzuki4, Yoshida4, Yoshida6, Yoshida8
from .rattle import Rattle
from .runge_kutta import DOP853, DOPRI5, ProjectedRungeKutta

METHODS = {cls.name: cls for cls in (Rattle, Yoshida4, Suzuki4, Yoshida6, Yoshida8, DOPRI5, DOP853)}


def make_integrator(method: str, dynamics, dt=None, rtol=None, atol=None, backend: str = "auto") -> Integrator:
    """Build the integrator ``method`` for one scene's dynamics.

    Fixed-step methods need ``dt``; adaptive ones take ``rtol`` (and optional ``atol``). ``backend``:
    'auto' runs whole intervals in the compiled kernels (RATTLE and its compositions, the projected
    Runge-Kutta methods) where the scene allows, 'compiled' insists on it, 'numpy' never.
    """
    if method not in METHODS:
        raise SolverError(f"unknown integration method {method!r}; choose one of {sorted(METHODS)}")
    cls = METHODS[method]
    if cls.adaptive:
        if dt is not None:
            raise SolverError(f"method {method!r} chooses its own steps: give rtol (and atol), not dt")
        return cls(dynamics, rtol=1e-8 if rtol is None else rtol, atol=atol, backend=backend)
    if rtol is not None or atol is not None:
        raise SolverError(f"method {method!r} has a fixed step: give dt, not rtol/atol")
    if dt is None:
        raise SolverError(f"method {method!r} has a fixed step: give dt (seconds)")
    return cls(dynamics, dt=dt, backend=backend)


__all__ = ["METHODS", "make_integrator", "Integrator", "FixedStepIntegrator", "Rattle", "Composition",
           "Yoshida4", "Suzuki4", "Yoshida6", "Yoshida8", "ProjectedRungeKutta", "DOPRI5", "DOP853"]
