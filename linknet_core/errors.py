"""Errors raised by linknet. Every message names the offending mass, link or variable and the rule."""
import ctypes

from linknet_core.clib.library import lib as _core


class LinknetError(ValueError):
    """Base class of every error linknet raises on bad input or an impossible state."""


class SceneError(LinknetError):
    """The scene description breaks a rule (unknown mass, self-link, bad mass or length, ...)."""


class ConsistencyError(LinknetError):
    """The state admits no consistent accelerations: hypothesis (35) of the seed is violated."""


class SolverError(LinknetError):
    """The integration cannot continue from the current state (step too small, non-finite values, ...)."""


class StepFailure(SolverError):
    """A step's position stage (or a fixed step's implicit half kick) did not converge: the native core's
    LN_PROJECTION_FAILED / LN_IMPLICIT_KICK_FAILED. A fixed-step method splits such a step before giving up; the
    integrator that gives up composes the final message from ``parts`` (the arguments of
    :func:`projection_failure`, its ``where`` without the time span; None for the implicit kick)."""

    def __init__(self, message: str, parts: dict | None = None):
        super().__init__(message)
        self.parts = parts


# The failure texts are the native core's (src/explain.c), for every path; so are the thresholds they use, among
# them STABILITY_LIMIT: h omega above which an explicit step amplifies an oscillation of angular frequency omega
# instead of following it.
STABILITY_LIMIT = ctypes.c_double.in_dll(_core, "ln_stability_limit").value
_projection_failure = _core.ln_projection_failure
_projection_failure.restype = None
_projection_failure.argtypes = [ctypes.c_char_p] + [ctypes.c_double] * 6 + [ctypes.c_char_p, ctypes.c_size_t]


def projection_failure(where: str, reached: float, before: float, floor: float, *, dt: float = 0.0,
                       stage_fraction: float = 1.0, omega: float = 0.0) -> str:
    """Why the position projection onto the link lengths (11) failed, in words, and what may help: the native
    core's text (ln_projection_failure, src/explain.c), so that the numpy reference, the native core and the native
    FMU say the same words. ``where``: what the iteration reached and at which link; ``reached``: the relative
    residual the iteration ended at; ``before``: the largest relative violation before projection; ``floor``: the
    relative floor its last Newton step allowed (the round-off floor plus what that step left by construction; 0:
    no Newton step taken).
    A fixed-step method also gives its ``dt``, its largest stage step over dt (``stage_fraction``, max |gamma_i|
    of a composition) and ``omega``, the fastest oscillation of its masses at the start of the step that failed
    (:func:`linknet_core.dynamics.equations.fastest_oscillation`).

    Beyond the stability limit (h omega > 2 for the largest stage step h; READS_LOW is the estimate's margin) the
    steps amplify that oscillation: light masses between tensioned links (extreme mass ratios) are thrown off (11)
    further every step until no projection converges, and the step, not the configuration, is the cause, whatever
    the iteration's floor.
    Below it: at the floor the linear model itself cannot remove the residual (a singular or badly conditioned
    Newton matrix), so a smaller step does not help; above the floor the linear model would remove the residual
    but the step does not: the iteration is outside Newton's region of convergence, which shrinks with the
    step."""
    out = ctypes.create_string_buffer(4096)
    _projection_failure(where.encode(), reached, before, floor, dt, stage_fraction, omega, out, len(out))
    return out.value.decode(errors="replace")
