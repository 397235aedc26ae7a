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
