"""The mutable state of a simulation (like MuJoCo's mjData): time, positions, velocities."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class State:
    t: float
    X: np.ndarray  # (K,3) positions
    U: np.ndarray  # (K,3) velocities

    def copy(self) -> "State":
        return State(float(self.t), np.array(self.X, copy=True), np.array(self.U, copy=True))


@dataclass
class InitialReport:
    """What was done to the scene's initial state before the run."""

    worst_length_error: float  # relative, before any projection
    positions_projected: bool
    velocity_correction: float  # max |dU| removed to satisfy (12), m/s
    velocity_correction_mass: int  # 0-based mass where it was largest (-1 if none)

    # what the velocity correction removed, as the report's line says it
    velocity_rule = " projected onto (12)"

    def lines(self, scene) -> list[str]:
        out = []
        if self.positions_projected:
            out.append(f"initial positions projected onto the link lengths (worst error was "
                       f"{self.worst_length_error:.3g} relative)")
        if self.velocity_correction > 0:
            out.append(f"initial velocities{self.velocity_rule}: largest correction {self.velocity_correction:.3g} m/s "
                       f"at {scene.mass_label(self.velocity_correction_mass)}")
        return out
