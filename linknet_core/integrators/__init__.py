"""Integrators: choose one by name. Each is a small unit defined by its method."""
from __future__ import annotations

import math

from linknet_core.accuracy import DEFAULT_RTOL, RTOL_MIN
from linknet_core.errors import SolverError
from linknet_core.integrators.base import FixedStepIntegrator, Integrator
from linknet_core.integrators.composition import Composition, Suzuki4, Yoshida4, Yoshida6, Yoshida8
from linknet_core.integrators.rattle import Rattle
from linknet_core.integrators.runge_kutta import DOP853, DOPRI5, ProjectedRungeKutta

METHODS = {cls.name: cls for cls in (Rattle, Yoshida4, Suzuki4, Yoshida6, Yoshida8, DOPRI5, DOP853)}

# The rules for the settings, written once: the library, the CLI, the FMUs' parameter checks and build_fmu.py all
# ask these functions. rtol lies in [RTOL_MIN, RTOL_MAX): below, double precision cannot deliver it; from 0.1 on
# the error control accepts steps whose projections onto the link lengths no longer converge, so the run fails
# later with a projection error instead of being refused here.
RTOL_MAX = 0.1


def real_number(value) -> float | None:
    """value as a float if it is a real number (Python or numpy scalar, or a 0-d array; not a bool), else None."""
    try:
        import numpy as np
        if isinstance(value, np.ndarray) and value.ndim == 0:
            value = value[()]
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            return None
    except ImportError:  # pragma: no cover (numpy is a dependency)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return None
    return float(value)


def rtol_problem(value) -> str | None:
    """Why value is no relative tolerance (None if it is one)."""
    x = real_number(value)
    if x is None or not math.isfinite(x) or x <= 0:
        return f"must be a positive finite tolerance in [{RTOL_MIN:g}, {RTOL_MAX:g}), got {value!r}"
    if x < RTOL_MIN:
        return f"= {value!r} is below what double precision can deliver ({RTOL_MIN:g})"
    if x >= RTOL_MAX:
        return f"= {value!r} must be < {RTOL_MAX:g} (looser tolerances let the projections onto the lengths fail)"
    return None


def positive_problem(value) -> str | None:
    """Why value is no positive finite number, such as a step dt or an absolute tolerance (None if it is one)."""
    x = real_number(value)
    if x is None or not math.isfinite(x):
        return f"must be a positive finite number, got {value!r}"
    if not x > 0:
        return f"= {value!r} must be > 0"
    return None


def method_problem(name) -> str | None:
    """Why name is no integration method (None if it is one)."""
    if isinstance(name, str) and name in METHODS:
        return None
    return f"= {name!r} is not one of {', '.join(sorted(METHODS))}"


def method_settings(method: str, dt=None, rtol=None, atol=None):
    """The method's class and its validated settings (dt for fixed-step methods; rtol, atol for adaptive
    ones, atol defaulting to rtol): one set of rules for every backend."""
    if method_problem(method):
        raise SolverError(f"unknown integration method {method!r}; choose one of {sorted(METHODS)}")
    cls = METHODS[method]
    if cls.adaptive:
        if dt is not None:
            raise SolverError(f"method {method!r} chooses its own steps: give rtol (and atol), not dt")
        rtol = DEFAULT_RTOL if rtol is None else rtol
        if rtol_problem(rtol):
            raise SolverError(f"rtol {rtol_problem(rtol)}")
        if atol is not None and positive_problem(atol):
            raise SolverError(f"atol must be a positive finite tolerance, got {atol!r}")
        rtol = real_number(rtol)
        return cls, None, rtol, (real_number(atol) if atol is not None else rtol)
    if rtol is not None or atol is not None:
        raise SolverError(f"method {method!r} has a fixed step: give dt, not rtol/atol")
    if dt is None:
        raise SolverError(f"method {method!r} has a fixed step: give dt (seconds)")
    if positive_problem(dt):
        raise SolverError(f"dt must be a positive finite step in seconds, got {dt!r}")
    return cls, real_number(dt), None, None


def make_integrator(method: str, dynamics, dt=None, rtol=None, atol=None) -> Integrator:
    """The numpy reference integrator ``method`` for one scene's dynamics (the native core runs the same
    methods: linknet_core.native); for a scene with ropes or a ground (``dynamics`` its UnilateralDynamics) its
    event-driven variant (linknet_core.integrators.events)."""
    cls, dt, rtol, atol = method_settings(method, dt, rtol, atol)
    if getattr(dynamics.scene, "unilateral", False):  # ropes, a ground: the method, stopping at every event
        from linknet_core.integrators.events import event_driven

        cls = event_driven(cls)
    if cls.adaptive:
        return cls(dynamics, rtol=rtol, atol=atol)
    return cls(dynamics, dt=dt)


__all__ = ["METHODS", "make_integrator", "method_settings", "RTOL_MIN", "RTOL_MAX", "real_number", "rtol_problem",
           "positive_problem", "method_problem", "Integrator", "FixedStepIntegrator", "Rattle", "Composition",
           "Yoshida4", "Suzuki4", "Yoshida6", "Yoshida8", "ProjectedRungeKutta", "DOPRI5", "DOP853"]
