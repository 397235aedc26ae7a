"""What every integrator is: a small unit defined by its method.

An integrator advances ``(t, X, U)`` of one scene, with the input forces held constant, from the current
time to a target time. Fixed-step methods split the interval into equal steps no longer than ``dt``
(so any target, however close, is hit exactly); adaptive ones choose their steps to meet ``rtol``/``atol``.
Adding a method means adding a subclass; nothing else changes.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from linknet_core.dynamics.equations import Dynamics
from linknet_core.errors import SolverError
from linknet_core.native.library import fixed_step_count
from linknet_core.state import State


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
        for i in range(n):  # the last step ends on the target itself: the driven anchors' final position
            end = t_target if i == n - 1 and t_target is not None else t + (i + 1) * h
            X, U = self.step(X, U, h, F_input, t + i * h, end)
        return X, U

    def advance(self, state, t_target, F_input, max_steps):
        span = t_target - state.t
        n = fixed_step_count(span, self.dt)  # the native core's rule, so both paths take the same steps
        if n > max_steps:
            raise SolverError(f"reaching t = {t_target} needs {n} steps of dt = {self.dt}, more than the "
                              f"limit of {max_steps}; raise max_steps or the step")
        h = span / n
        # finiteness of the result is checked once, by Simulator.advance, for every path
        X, U = self._advance_steps(state.X, state.U, n, h, F_input, state.t, t_target)
        state.X, state.U, state.t = X, U, t_target
        self.stats.steps += n
