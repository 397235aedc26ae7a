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
import functools
import math
import operator
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from linknet_core.accuracy import Companion, companion, default_method
from linknet_core.dynamics.equations import rhs_kernel_problem
from linknet_core.errors import SolverError
from linknet_core.integrators import method_settings, real_number

DEFAULT_LENGTH_TOL = 1e-6  # relative violation of (11) accepted in a scene's initial positions
DEFAULT_MAX_STEPS_PER_CALL = 100_000_000
# the backends by name (subclasses of linknet_core.simulator.backend.Backend): "auto" is the native core. Each
# backend's module registers its class here when it loads (native_backend.py, numpy_backend.py; the Simulator's
# module imports both), so the settings need not import them; a backend registered here (the dict itself, which
# linknet_core.simulator.simulator names too) is accepted by name with no other change.
BACKEND_CLASSES: dict[str, type] = {}

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
        self._validate(_GIVEN_FIELDS)

    def _validate(self, names) -> None:
        """Validate and normalise the fields ``names`` (the method and its step or tolerances together, each other
        field by its own rule, in field order), then derive ``stepping`` and ``setup_key``. Writes the instance's
        dict: a frozen dataclass sets its own normalised values once, here."""
        values = self.__dict__
        if not _STEPPING_FIELDS.isdisjoint(names):
            method = default_method(values["method"], values["dt"])
            values["stepping"] = Stepping(method, *method_settings(method, values["dt"], values["rtol"],
                                                                    values["atol"]))
            # the values given, as the floats method_settings validated (it refused what it does not take)
            for name in ("dt", "rtol", "atol"):
                if values[name] is not None and type(values[name]) is not float:
                    values[name] = real_number(values[name])
        for name in names:
            check = _FIELD_RULES.get(name)
            if check is not None:
                values[name] = check(values[name])
        values["setup_key"] = _setup_fields(self)

    def with_changes(self, **changes) -> "RunSettings":
        """These settings with ``changes`` (field names) in place of their fields, the changed fields validated
        as when made (the method, dt, rtol and atol together whenever one of them changes)."""
        if not changes:
            return self
        unknown = changes.keys() - _GIVEN_FIELDS
        if unknown:
            raise TypeError(f"RunSettings has no field {sorted(unknown)[0]!r}; its fields: {', '.join(_GIVEN_FIELDS)}")
        changed = object.__new__(RunSettings)
        values = self.__dict__  # the fields and stepping, not what is derived from them later (companion)
        changed.__dict__.update({name: values[name] for name in _GIVEN_FIELDS}, stepping=values["stepping"])
        changed.__dict__.update(changes)
        changed._validate(changes.keys())
        return changed


    @functools.cached_property
    def companion(self) -> tuple[Companion, "RunSettings"]:
        """The error estimate's companion of a run with these settings, made once per settings object: its rule
        (linknet_core.accuracy.companion: its step or tolerances and the factor on the positions' gap) and its
        settings (the same, with the method named, the companion's step or tolerances and no companion of its
        own)."""
        stepping = self.stepping
        rule = companion(stepping.cls, stepping.dt, stepping.rtol, stepping.atol)
        return rule, self.with_changes(method=stepping.method, dt=rule.dt, rtol=rule.rtol, atol=rule.atol,
                                       error_estimate=False)


def _flag(name: str, value, allow_none: bool = False):
    """A yes/no setting as a bool (numpy's bool too; None where allowed); anything else is refused naming it."""
    if value is True or value is False or (value is None and allow_none):
        return value
    if isinstance(value, np.bool_):
        return bool(value)
    allowed = "True, False or None" if allow_none else "True or False"
    raise SolverError(f"{name} must be {allowed}, got {value!r} ({type(value).__name__})")


def _length_tol(value) -> float:
    x = value if type(value) is float else real_number(value)
    if x is None or not (0.0 <= x < math.inf):
        raise SolverError(f"length_tol must be a finite relative tolerance >= 0 (the violation of the link lengths "
                          f"(11) accepted in the initial positions), got {value!r}")
    return x


def _backend(value) -> str:
    if isinstance(value, str) and (value == "auto" or value in BACKEND_CLASSES):
        return value
    names = ("auto", *BACKEND_CLASSES)
    raise SolverError(f"backend must be one of {', '.join(map(repr, names))}, got {value!r}")


def _rhs_kernel(value) -> str:
    problem = rhs_kernel_problem(value)
    if problem:
        raise SolverError(problem)
    return value


def _max_steps(value) -> int:
    if type(value) is int and value >= 1:
        return value
    whole = real_number(value)
    if whole is None or not (math.isfinite(whole) and whole == int(whole) and whole >= 1):
        raise SolverError(f"max_steps_per_call must be a whole number >= 1 (the most steps one advance may take), "
                          f"got {value!r}")
    return int(value)


# each field's rule but the method's and its step's or tolerances' (method_settings, asked for the four together)
_FIELD_RULES = {"project_initial": lambda value: _flag("project_initial", value, allow_none=True),
                "length_tol": _length_tol, "backend": _backend, "rhs_kernel": _rhs_kernel,
                "specialise": lambda value: _flag("specialise", value), "max_steps_per_call": _max_steps,
                "error_estimate": lambda value: _flag("error_estimate", value)}
_STEPPING_FIELDS = frozenset(("method", "dt", "rtol", "atol"))
_GIVEN_FIELDS = tuple(f.name for f in dataclasses.fields(RunSettings) if f.init)
_setup_fields = operator.attrgetter(*(f.name for f in dataclasses.fields(RunSettings)
                                      if f.init and f.metadata.get("setup", True)))


def run_settings(settings: RunSettings | None, **given) -> RunSettings:
    """The settings of a run given as ``settings=`` and/or keywords: ``settings`` (RunSettings' defaults where
    None) with every keyword that is not None in place of its field. A keyword left at None leaves the field as it
    is (to set a field to None, use ``settings.with_changes``)."""
    changes = {name: value for name, value in given.items() if value is not None}
    if settings is None:
        return _made_from(changes)
    if not isinstance(settings, RunSettings):
        text = repr(settings)
        raise SolverError(f"settings must be a RunSettings (linknet_core.RunSettings), got {type(settings).__name__} "
                          f"{text if len(text) <= 80 else text[:77] + '...'}")
    return settings.with_changes(**changes)


# RunSettings made from keywords alone, by the keywords given with their types (True and 1, 1e-3 and numpy's 1e-3 are
# told apart, as the rules tell them apart): a Simulator or simulate called again with the same keywords takes the
# object already made and validated (a few microseconds of every call). Cleared when full.
_MADE: dict = {}
_MADE_LIMIT = 256


def _made_from(changes: dict) -> RunSettings:
    try:
        key = tuple((name, type(value), value) for name, value in changes.items())
        made = _MADE.get(key)
    except TypeError:  # an unhashable value (a 0-d array): made afresh, normalised or refused
        return RunSettings(**changes)
    if made is None:
        made = RunSettings(**changes)
        if len(_MADE) >= _MADE_LIMIT:
            _MADE.clear()
        _MADE[key] = made
    return made
