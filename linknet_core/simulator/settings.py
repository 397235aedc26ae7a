"""A run's settings as one object: how a scene is integrated, as opposed to what is integrated (the scene), over
what (the time span, the start time) and with what (input forces, the anchors' motion, the outputs asked for).

``RunSettings`` is validated once, when it is made: every bad value is refused there with a SolverError naming the
setting and its rule (the rules are those the CLI, the FMUs and build_fmu.py ask too: linknet_core.integrators'
``method_settings``, ``real_number``, ``positive_problem``; the backends' names are ``BACKEND_CLASSES``; the right-hand
side kernels are ``linknet_core.dynamics.equations.rhs_kernel_problem``'s). A Simulator, simulate, its pool of
Simulators, the per-scene set-up cache and the backends then take the object as it is, and read the validated
method and its step or tolerances from ``stepping``.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from linknet_core.accuracy import default_method
from linknet_core.dynamics.equations import rhs_kernel_problem
from linknet_core.errors import SolverError
from linknet_core.integrators import method_settings, real_number
from linknet_core.simulator.backend import Backend
from linknet_core.simulator.native_backend import NativeBackend
from linknet_core.simulator.numpy_backend import NumpyBackend

DEFAULT_LENGTH_TOL = 1e-6  # relative violation of (11) accepted in a scene's initial positions
DEFAULT_MAX_STEPS_PER_CALL = 100_000_000
# the backends by name (linknet_core.simulator.backend): "auto" is the native core. A backend registered here (the
# dict itself, which linknet_core.simulator.simulator names too) is accepted by name with no other change.
BACKEND_CLASSES: dict[str, type[Backend]] = {"native": NativeBackend, "numpy": NumpyBackend}

# a field so marked does not change what a Simulator's set-up (initial state, backend, specialisation) is for a scene
_NOT_SETUP = {"setup": False}


class Stepping(NamedTuple):
    """What the integrator is given: the method (named, default_method's choice where none was) and its class,
    with its validated settings: ``dt`` for a fixed step; ``rtol`` and ``atol`` for error control (rtol DEFAULT_RTOL
    where none was given, atol rtol), as floats."""

    method: str
    cls: type
    dt: float | None
    rtol: float | None
    atol: float | None


@dataclass(frozen=True)
class RunSettings:
    """How a run is integrated, validated as a whole when made (a SolverError names the setting and the rule).

    ``method``, ``dt``, ``rtol``, ``atol``: the integration method and its step (fixed-step methods) or tolerances
    (error-controlled ones). With neither a method nor a step, the error-controlled default (linknet_core.accuracy:
    DEFAULT_METHOD at DEFAULT_RTOL); with a step and no method, RATTLE. ``stepping`` holds what that resolves to.
    ``project_initial``: project the initial positions onto the link lengths (None: as the scene's
    ``"options": {"project_initial_positions": ...}`` says); ``length_tol``: the relative violation of (11)
    accepted in the initial positions without it. ``backend``: "auto" (the native core), or a name of
    ``BACKEND_CLASSES``. ``rhs_kernel``: "numpy" or "casadi" (the generated right-hand side, numpy reference).
    ``specialise``: let a static scene or a scene of free rigid bodies take its specialised path.
    ``max_steps_per_call``: the most steps one advance may take. ``error_estimate``: run the companion that
    estimates the position error.

    Fields are stored as given but normalised (floats, bools, ints), so equal settings are equal and hash alike
    whatever numeric types they were given as. ``with_changes(**fields)`` is a copy with fields replaced, validated
    again as a whole.
    """

    method: str | None = None
    dt: float | None = None
    rtol: float | None = None
    atol: float | None = None
    project_initial: bool | None = None
    length_tol: float = DEFAULT_LENGTH_TOL
    backend: str = "auto"
    rhs_kernel: str = "numpy"
    specialise: bool = True
    max_steps_per_call: int = field(default=DEFAULT_MAX_STEPS_PER_CALL, metadata=_NOT_SETUP)
    error_estimate: bool = field(default=True, metadata=_NOT_SETUP)
    # derived when made (not compared, not given)
    stepping: Stepping = field(init=False, repr=False, compare=False)
    setup_key: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        set_field = object.__setattr__  # a frozen dataclass: its own normalised values are set once, here
        method = default_method(self.method, self.dt)
        stepping = Stepping(method, *method_settings(method, self.dt, self.rtol, self.atol))
        # the values given, as the floats method_settings validated (it refused what it does not take)
        for name in ("dt", "rtol", "atol"):
            if getattr(self, name) is not None:
                set_field(self, name, real_number(getattr(self, name)))
        set_field(self, "stepping", stepping)
        set_field(self, "project_initial", _flag("project_initial", self.project_initial, allow_none=True))
        length_tol = real_number(self.length_tol)
        if length_tol is None or not (math.isfinite(length_tol) and length_tol >= 0):
            raise SolverError(f"length_tol must be a finite relative tolerance >= 0 (the violation of the link "
                              f"lengths (11) accepted in the initial positions), got {self.length_tol!r}")
        set_field(self, "length_tol", length_tol)
        names = ("auto", *BACKEND_CLASSES)
        if self.backend not in names:  # a tuple: an unhashable value is refused too
            raise SolverError(f"backend must be one of {', '.join(map(repr, names))}, got {self.backend!r}")
        problem = rhs_kernel_problem(self.rhs_kernel)
        if problem:
            raise SolverError(problem)
        set_field(self, "specialise", _flag("specialise", self.specialise))
        steps = self.max_steps_per_call
        whole = real_number(steps)
        if whole is None or not (math.isfinite(whole) and whole == int(whole) and whole >= 1):
            raise SolverError(f"max_steps_per_call must be a whole number >= 1 (the most steps one advance may "
                              f"take), got {steps!r}")
        set_field(self, "max_steps_per_call", int(steps))
        set_field(self, "error_estimate", _flag("error_estimate", self.error_estimate))
        set_field(self, "setup_key", tuple(getattr(self, f.name) for f in dataclasses.fields(self)
                                           if f.init and f.metadata.get("setup", True)))

    def with_changes(self, **changes) -> "RunSettings":
        """These settings with ``changes`` (field names) in place of their fields, validated again as a whole."""
        return dataclasses.replace(self, **changes) if changes else self


def _flag(name: str, value, allow_none: bool = False):
    """A yes/no setting as a bool (numpy's bool too; None where allowed); anything else is refused naming it."""
    if value is None and allow_none:
        return None
    if value is True or value is False:
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    allowed = "True, False or None" if allow_none else "True or False"
    raise SolverError(f"{name} must be {allowed}, got {value!r} ({type(value).__name__})")


def run_settings(settings: RunSettings | None, **given) -> RunSettings:
    """The settings of a run given as ``settings=`` and/or keywords: ``settings`` (RunSettings' defaults where
    None) with every keyword that is not None in place of its field. A keyword left at None leaves the field as it
    is (to set a field to None, use ``settings.with_changes``)."""
    changes = {name: value for name, value in given.items() if value is not None}
    if settings is None:
        return RunSettings(**changes)
    if not isinstance(settings, RunSettings):
        text = repr(settings)
        raise SolverError(f"settings must be a RunSettings (linknet_core.RunSettings), got {type(settings).__name__} "
                          f"{text if len(text) <= 80 else text[:77] + '...'}")
    return settings.with_changes(**changes)
