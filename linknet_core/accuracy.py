"""How accurate a run is: the default method, the companion run that estimates a run's global error, and the goal
the estimate is held to.

The rules are the native core's (src/error_estimate.c), read from it, so that the library on either backend and
the native FMU follow the same ones:

* a fixed-step method of order p is compared with itself at half the step (Richardson): the run's error is about
  2^p / (2^p - 1) times the largest position gap between the two;
* an error-controlled method is compared with itself at a tenth of its tolerances: the gap is the run's error
  within some ten per cent to a factor two (tolerance proportionality);
* the goal is 100 times max(rtol times the scene's size, atol) metres: 1e-6 of the scene's size at the default
  rtol 1e-8 (fixed-step runs are held to the default's goal). docs/accuracy.md gives the measurements behind
  these numbers.
"""
from __future__ import annotations

import ctypes
import warnings
from dataclasses import dataclass

import numpy as np

from linknet_core.clib.library import lib as _core

_c_double_p = ctypes.POINTER(ctypes.c_double)

_companion_settings = _core.ln_companion_settings
_companion_settings.restype = ctypes.c_double
_companion_settings.argtypes = [ctypes.c_int, ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                                _c_double_p, _c_double_p, _c_double_p]
_error_goal = _core.ln_error_goal
_error_goal.restype = ctypes.c_double
_error_goal.argtypes = [ctypes.c_int, ctypes.c_double, ctypes.c_double, ctypes.c_double]

_scene_size = _core.ln_scene_size
_scene_size.restype = ctypes.c_double
_scene_size.argtypes = [ctypes.c_int64, _c_double_p]
_position_gap = _core.ln_position_gap
_position_gap.restype = ctypes.c_double
_position_gap.argtypes = [ctypes.c_int64, _c_double_p, _c_double_p]
_position_gaps = _core.ln_position_gaps
_position_gaps.restype = None
_position_gaps.argtypes = [ctypes.c_int64, ctypes.c_int64, _c_double_p, _c_double_p, _c_double_p]

_accuracy_text = _core.ln_accuracy_text
_accuracy_text.restype = None
_accuracy_text.argtypes = [ctypes.c_char_p, ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_double,
                           ctypes.c_char_p, ctypes.c_size_t]

_estimate_failure_text = _core.ln_estimate_failure_text
_estimate_failure_text.restype = None
_estimate_failure_text.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_size_t]

RTOL_MIN = ctypes.c_double.in_dll(_core, "ln_rtol_min").value
DEFAULT_RTOL = ctypes.c_double.in_dll(_core, "ln_default_rtol").value

# With neither a method nor a step given, every entry point (library, CLI, ensembles, FMUs) runs this one:
# error-controlled, and on every shipped scene the fastest of linknet's methods to 1e-6 m and below
# (docs/benchmarks/results.md).
DEFAULT_METHOD = "dop853"
# Given a step dt and no method, a fixed-step method: RATTLE. A fixed-step method named without a step on the
# command line or in a study steps DEFAULT_STEP (the library asks for dt).
DEFAULT_FIXED_STEP_METHOD = "rattle"
DEFAULT_STEP = 1e-3


def default_method(method: str | None, dt) -> str:
    """The method a run uses: ``method`` if given, else RATTLE when a step dt is given, else DEFAULT_METHOD."""
    if method is not None:
        return method
    return DEFAULT_FIXED_STEP_METHOD if dt is not None else DEFAULT_METHOD


@dataclass(frozen=True)
class Companion:
    """The companion run's settings and the factor that turns the largest position gap into the run's error."""

    dt: float | None
    rtol: float | None
    atol: float | None
    factor: float


def companion(method_cls, dt: float | None, rtol: float | None, atol: float | None) -> Companion:
    """The companion of a run of ``method_cls`` with its validated settings (dt, or rtol and atol)."""
    dt_c, rtol_c, atol_c = ctypes.c_double(), ctypes.c_double(), ctypes.c_double()
    factor = _companion_settings(int(method_cls.adaptive), int(method_cls.order), dt or 0.0, rtol or 0.0,
                                 atol or 0.0, ctypes.byref(dt_c), ctypes.byref(rtol_c), ctypes.byref(atol_c))
    if method_cls.adaptive:
        return Companion(None, rtol_c.value, atol_c.value, factor)
    return Companion(dt_c.value, None, None, factor)


def scene_size(X: np.ndarray) -> float:
    """The largest extent of positions X (K,3) along an axis, m (1 if they all coincide): ln_scene_size."""
    X = np.ascontiguousarray(X, dtype=np.float64)
    return _scene_size(X.shape[0], X.ctypes.data_as(_c_double_p))


def error_goal(method_cls, rtol: float | None, atol: float | None, size: float) -> float:
    """The position error (m) a run is held to: ln_error_goal."""
    return _error_goal(int(method_cls.adaptive), rtol or 0.0, atol or 0.0, size)


def position_gap(Xa: np.ndarray, Xb: np.ndarray) -> float:
    """The largest distance between the same mass in two states (K,3), m: ln_position_gap (NaN if not finite)."""
    Xa = np.ascontiguousarray(Xa, dtype=np.float64)
    Xb = np.ascontiguousarray(Xb, dtype=np.float64)
    return _position_gap(Xa.shape[0], Xa.ctypes.data_as(_c_double_p), Xb.ctypes.data_as(_c_double_p))


def position_gaps(Xa: np.ndarray, Xb: np.ndarray) -> np.ndarray:
    """position_gap of every pair of samples (n, K, 3), in one call (ln_position_gaps)."""
    Xa = np.ascontiguousarray(Xa, dtype=np.float64)
    Xb = np.ascontiguousarray(Xb, dtype=np.float64)
    if Xa.shape != Xb.shape or Xa.ndim != 3:
        raise ValueError(f"position_gaps: samples of shape {Xa.shape} and {Xb.shape}, expected two (n, K, 3)")
    out = np.empty(Xa.shape[0])
    _position_gaps(Xa.shape[0], Xa.shape[1], Xa.ctypes.data_as(_c_double_p), Xb.ctypes.data_as(_c_double_p),
                   out.ctypes.data_as(_c_double_p))
    return out


def accuracy_text(name: str, t: float, estimate: float, goal: float, largest: float | None = None) -> str:
    """The warning of a run whose estimated error exceeds its goal from time t on (the core's ln_accuracy_text,
    the native FMU's words too)."""
    out = ctypes.create_string_buffer(1024)
    _accuracy_text(str(name).encode("utf-8", "replace"), t, estimate, goal, largest or 0.0, out, len(out))
    return out.value.decode("utf-8", "replace")


def estimate_failure_text(name: str, why: str) -> str:
    """The note of a run whose companion failed (``why``: where and how) where the run went through (the core's
    ln_estimate_failure_text, the native FMU's words too)."""
    out = ctypes.create_string_buffer(4096)
    _estimate_failure_text(str(name).encode("utf-8", "replace"), str(why).encode("utf-8", "replace"), out, len(out))
    return out.value.decode("utf-8", "replace")


class AccuracyWarning(UserWarning):
    """A run's estimated error exceeds its goal, or its companion run could not estimate it."""


def warn_accuracy(text: str) -> None:
    warnings.warn(text, AccuracyWarning, stacklevel=3)
