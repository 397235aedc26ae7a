"""Integrators: choose one by name. Each is a small unit defined by its method."""
from __future__ import annotations

import math

from linknet_core.errors import SolverError
from linknet_core.integrators.base import FixedStepIntegrator, Integrator
from linknet_core.integrators.composition import Composition, Suzuki4, Yoshida4, Yoshida6, Yoshida8
from linknet_core.integrators.rattle import Rattle
from linknet_core.integrators.runge_kutta import DOP853, DOPRI5, ProjectedRungeKutta

METHODS = {cls.name: cls for cls in (Rattle, Yoshida4, Suzuki4, Yoshida6, Yoshida8, DOPRI5, DOP853)}


def method_settings(method: str, dt=None, rtol=None, atol=None):
    """The method's class and its validated settings (dt for fixed-step methods; rtol, atol for adaptive
    ones, atol defaulting to rtol): one set of rules for every backend."""
    if method not in METHODS:
        raise SolverError(f"unknown integration method {method!r}; choose one of {sorted(METHODS)}")
    cls = METHODS[method]
    if cls.adaptive:
        if dt is not None:
            raise SolverError(f"method {method!r} chooses its own steps: give rtol (and atol), not dt")
        rtol = 1e-8 if rtol is None else rtol
        for name, value in (("rtol", rtol), ("atol", atol)):
            if value is not None and not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise SolverError(f"{name} must be a positive finite tolerance, got {value!r}")
        if rtol < 1e-15:
            raise SolverError(f"rtol = {rtol!r} is below what double precision can deliver (1e-15)")
        return cls, None, float(rtol), float(atol if atol is not None else rtol)
    if rtol is not None or atol is not None:
        raise SolverError(f"method {method!r} has a fixed step: give dt, not rtol/atol")
    if dt is None:
        raise SolverError(f"method {method!r} has a fixed step: give dt (seconds)")
    if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise SolverError(f"dt must be a positive finite step in seconds, got {dt!r}")
    return cls, float(dt), None, None


def make_integrator(method: str, dynamics, dt=None, rtol=None, atol=None) -> Integrator:
    """The numpy reference integrator ``method`` for one scene's dynamics (the native core runs the same
    methods: linknet_core.native)."""
    cls, dt, rtol, atol = method_settings(method, dt, rtol, atol)
    if cls.adaptive:
        return cls(dynamics, rtol=rtol, atol=atol)
    return cls(dynamics, dt=dt)


__all__ = ["METHODS", "make_integrator", "method_settings", "Integrator", "FixedStepIntegrator", "Rattle", "Composition",
           "Yoshida4", "Suzuki4", "Yoshida6", "Yoshida8", "ProjectedRungeKutta", "DOPRI5", "DOP853"]
