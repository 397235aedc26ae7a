"""What every integrator is: a small unit defined by its method.

An integrator advances ``(t, X, U)`` of one scene, with the input forces held constant, from the current
time to a target time. Fixed-step methods split the interval into equal steps no longer than ``dt``
(so any target, however close, is hit exactly); adaptive ones choose their steps to meet ``rtol``/``atol``.
Adding a method means adding a subclass; nothing else changes.
"""
from __future__ import annotations

import ctypes
import math
from dataclasses import dataclass

import numpy as np

from linknet_core.dynamics.drive import anchor_jump
from linknet_core.dynamics.equations import Dynamics
from linknet_core.errors import SolverError, StepFailure, projection_failure
from linknet_core.clib.library import fixed_step_count, lib as _core
from linknet_core.state import State

# A fixed step whose position stage (or implicit half kick) fails is taken again from its start as 2, 4, ...,
# 2^MAX_SPLIT_LEVEL equal sub-steps, each the whole method: the native core's bound (stages/rattle.c), read from it.
MAX_SPLIT_LEVEL = ctypes.c_int.in_dll(_core, "ln_max_split_level").value
# The most steps one advance counts (2^53, beyond which span / dt is no longer a whole number in double): the
# native core's limit, read from it; a larger max_steps means this.
MAX_STEP_COUNT = ctypes.c_int64.in_dll(_core, "ln_max_step_count").value
_step_count_problem = _core.ln_step_count_problem
_step_count_problem.restype = ctypes.c_int
_step_count_problem.argtypes = [ctypes.c_double, ctypes.c_double, ctypes.c_double, ctypes.c_int64, ctypes.c_char_p,
                                ctypes.c_size_t]


def step_count_problem(t_start: float, t_target: float, dt: float, max_steps: int) -> str | None:
    """Why a fixed-step advance from t_start to t_target cannot be taken in at most max_steps steps of dt (naming the
    span, dt, the count and the limit), or None where it can: the native core's rule and words
    (ln_step_count_problem), which the native FMU says too."""
    out = ctypes.create_string_buffer(512)
    if not _step_count_problem(t_start, t_target, dt, min(int(max_steps), MAX_STEP_COUNT), out, len(out)):
        return None
    return out.value.decode()


class TensionPeaks:
    """Each link's largest |T_l| over one advance, signed (the value of T_l there), and when: located between the
    accepted steps' ends as the native core does it (tension_peaks.c, which says how and how accurately), in array
    code. ``begin(t, T)`` with T at the advance's start, ``step(t, T)`` with T at each accepted step's end; ``peak``
    and ``time`` (L,) hold the result, None before the first advance. ``located=False``: nothing is tracked (the
    event-driven methods of ropes and a ground, whose modes' tensions jump at every event and have the mode's links
    only: their runs report the sampled T)."""

    def __init__(self, located: bool = True):
        self.located = located
        self.peak = self.time = None
        self._older = self._newer = None
        self._t0 = self._t1 = 0.0
        self._points = 0

    def begin(self, t: float, T: np.ndarray) -> None:
        if not self.located:
            return
        self.peak, self.time = T.copy(), np.full(T.shape, float(t))
        self._newer, self._t1, self._points = T, float(t), 1

    def step(self, t: float, T: np.ndarray) -> None:
        if not self.located:
            return
        t = float(t)
        peak, time = self.peak, self.time
        later = np.abs(T) > np.abs(peak)
        peak = np.where(later, T, peak)
        time = np.where(later, t, time)
        if self._points >= 2:
            # the quadratic through the last three step ends in Newton's form about the middle one: its vertex s = a / c,
            # where it lies between the outer two (a + c h1 and c h2 - a of c's sign) and beats the peak so far in
            # magnitude
            y0, y1, t1 = self._older, self._newer, self._t1
            h1, h2 = t1 - self._t0, t - t1
            d1 = (y1 - y0) * (1.0 / h1)
            c = ((T - y1) * (1.0 / h2) - d1) * (1.0 / (t - self._t0))
            slope = d1 + c * h1
            a = -0.5 * slope
            p, q = a + c * h1, c * h2 - a
            inside = ((c > 0.0) & (p > 0.0) & (q > 0.0)) | ((c < 0.0) & (p < 0.0) & (q < 0.0))
            s = a / np.where(inside, c, 1.0)
            top = y1 + 0.5 * slope * s
            vertex = inside & (np.abs(top) > np.abs(peak))
            peak = np.where(vertex, top, peak)
            time = np.where(vertex, t1 + s, time)
        self.peak, self.time = peak, time
        self._older, self._newer = self._newer, T
        self._t0, self._t1 = self._t1, t
        self._points += 1


@dataclass
class StepStats:
    steps: int = 0
    rejected: int = 0
    split: int = 0  # fixed steps split into equal sub-steps (their position stage failed at full length)
    finest_split: int = 0  # the most sub-steps one step was split into

    def as_dict(self) -> dict:
        return {"steps": self.steps, "rejected": self.rejected, "split": self.split, "finest_split": self.finest_split}


class Integrator:
    name = "abstract"
    order = 0
    symplectic = False
    adaptive = False
    guarantees = ""

    def __init__(self, dynamics: Dynamics):
        self.dyn = dynamics
        self.stats = StepStats()
        # each link's largest |T_l| over the last advance and when (ProjectedRungeKutta and FixedStepIntegrator track
        # them; the peak and time stay None where an advance does not)
        self.peaks = TensionPeaks()
        # the driven anchors' motion (linknet_core.dynamics.drive.AnchorDrive), set by the Simulator of a scene
        # that has driven anchors; None: every anchor stands still
        self.drive = None

    # snapshot of whatever the integrator carries between calls (step-size guess, ...)
    def internals(self) -> dict:
        out = {"stats": self.stats.as_dict()}
        if self.drive is not None:
            out["drive"] = self.drive.internals()
        return out

    def set_internals(self, data: dict) -> None:
        self.stats = StepStats(**data["stats"])
        if self.drive is not None and "drive" in data:
            self.drive.set_internals(data["drive"])

    def advance(self, state: State, t_target: float, F_input: np.ndarray | None, max_steps: int) -> None:
        raise NotImplementedError

    def anchor_jump(self, drive, t: float, X: np.ndarray, U: np.ndarray, F_input=None):
        """The driven anchors brought to their motion at t where it jumped, before an advance: the rods' projection
        (dynamics.drive.anchor_jump); the event-driven methods take it as an event (events.EventHandling.
        anchor_jump). Returns (X, U, impulse on each driven anchor, position jump, velocity jump)."""
        return anchor_jump(self.dyn, drive, t, X, U)

    def projection_floor(self) -> tuple[int, float]:
        """(position projections that stopped at their round-off floor above the tolerance, the largest relative
        residual at which one stopped there) over the run."""
        return int(getattr(self.dyn, "floor_stops", 0)), float(getattr(self.dyn, "floor_reached", 0.0))


class FixedStepIntegrator(Integrator):
    """Equal steps no longer than ``dt`` that land exactly on the target time."""

    def __init__(self, dynamics: Dynamics, dt: float):
        super().__init__(dynamics)
        if not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
            raise SolverError(f"dt must be a positive finite step in seconds, got {dt!r}")
        self.dt = float(dt)

    def step(self, X, U, h, F_input, t=0.0, t_end=None):
        """One step of size h from (X, U) at time t to t_end (default t + h; the times matter only to driven
        anchors)."""
        raise NotImplementedError

    def _advance_steps(self, X, U, n, h, F_input, t=0.0, t_target=None):
        peaks = self.peaks
        peaks.begin(t, self._tensions(X, U, F_input, t))
        for i in range(n):  # the last step ends on the target itself: the driven anchors' final position
            end = t_target if i == n - 1 and t_target is not None else t + (i + 1) * h
            try:
                X_new, U_new = self.step(X, U, h, F_input, t + i * h, end)
            except StepFailure as failure:
                X_new, U_new = self._split_step(X, U, h, F_input, t + i * h, end, failure)
            X, U = X_new, U_new
            peaks.step(end, self._tensions(X, U, F_input, end))
        return X, U

    def _tensions(self, X, U, F_input, t):
        """T of (25)-(26) at (X, U) and time t (the driven anchors' accelerations at t), for the located peaks: the
        steps themselves need no tensions."""
        anchor_acc = None
        if self.drive is not None:
            X, U, anchor_acc = self.drive.apply(t, X, U)
        return self.dyn.tensions(X, U, F_input, anchor_acc=anchor_acc)

    def _split_step(self, X, U, h, F_input, t, t_end, failure):
        """The step from (X, U) at t taken again as 2, 4, ... 2^MAX_SPLIT_LEVEL equal sub-steps, each the whole
        method (so each keeps its symmetry), until one split goes through (counted in the stats), as the native
        core does (split_step, stages/rattle.c). Past the bound the last failure is raised, with ``start``: the
        state the failed step started from."""
        for level in range(1, MAX_SPLIT_LEVEL + 1):
            parts = 1 << level
            hp = h / parts
            Xp, Up = X, U
            try:
                for part in range(parts):
                    Xp, Up = self.step(Xp, Up, hp, F_input, t + part * hp,
                                       t_end if part == parts - 1 else t + (part + 1) * hp)
            except StepFailure as finer:
                failure = finer
                continue
            self.stats.split += 1
            self.stats.finest_split = max(self.stats.finest_split, parts)
            return Xp, Up
        failure.start = (X, U, t)
        raise failure

    def advance(self, state, t_target, F_input, max_steps):
        span = t_target - state.t
        problem = step_count_problem(state.t, t_target, self.dt, max_steps)
        if problem:
            raise SolverError(problem)
        n = fixed_step_count(span, self.dt)  # the native core's rule, so both paths take the same steps
        h = span / n
        # finiteness of the result is checked once, by Simulator.advance, for every path
        try:
            X, U = self._advance_steps(state.X, state.U, n, h, F_input, state.t, t_target)
        except StepFailure as failure:
            raise SolverError(self.explain_failure(failure, state.t, t_target, F_input)) from None
        state.X, state.U, state.t = X, U, t_target
        self.stats.steps += n

    def explain_failure(self, failure: StepFailure, t_start: float, t_target: float, F_input) -> str:
        """A step that failed for good, in words as the native core says it: the time span of the advance, the
        projection's figures (errors.projection_failure), and, where a near-self-stress carries the load at the
        start of the failed step, why no step can help (Dynamics.near_self_stress_load)."""
        return explain_step_failure(self.dyn, failure, t_start, t_target, F_input, self.drive)


def explain_step_failure(dyn, failure: StepFailure, t_start: float, t_target: float, F_input, drive=None) -> str:
    """The message of a step failure of the numpy reference, fixed-step or adaptive (see
    FixedStepIntegrator.explain_failure)."""
    if failure.parts is None:  # the implicit half kick: its own words
        return f"between t = {t_start} and t = {t_target}: {failure}"
    parts = dict(failure.parts)
    parts["where"] = f"between t = {t_start} and t = {t_target}: {parts['where']}"
    message = projection_failure(**parts)
    start = getattr(failure, "start", None)
    if start is not None:
        X, U, t = start
        anchor_acc = None
        if drive is not None:  # the driven anchors' accelerations enter B (26)
            X, U, anchor_acc = drive.apply(t, X, U)
        diagnosis = dyn.near_self_stress_load(X, U, F_input, anchor_acc)
        if diagnosis:
            message = f"{message} {diagnosis}"
    return message
