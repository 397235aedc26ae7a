from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..scene_spec import SceneSpec


@dataclass
class RunResult:
    X: np.ndarray                 # (K,3) positions at t_end
    U: np.ndarray | None          # (K,3) velocities at t_end (None if the method cannot give them at t_end)
    seconds: float                # wall time of the integration only
    setup_seconds: float = 0.0    # model construction (not part of `seconds`)
    steps: int = 0
    info: dict = field(default_factory=dict)


class Unsupported(Exception):
    """The method cannot model this scene faithfully; the message says why."""


class Method:
    name = "?"
    family = "peer"          # 'linknet' | 'baseline' | 'peer'
    knob = "dt"              # 'dt' (fixed step) or 'rtol' (adaptive)
    order = None             # nominal order of convergence in the knob (used by the quick test)

    def available(self) -> tuple[bool, str]:
        return True, ""

    def check_scene(self, spec: SceneSpec) -> None:
        """Raise Unsupported(reason) when the scene cannot be modelled faithfully."""

    def run(self, spec: SceneSpec, t_end: float, knob: float) -> RunResult:
        raise NotImplementedError


class Timer:
    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.seconds = time.perf_counter() - self.t0
        return False


def n_steps(t_end: float, dt: float) -> tuple[int, float]:
    """Whole number of fixed steps landing exactly on t_end, and the dt actually used."""
    n = max(1, int(round(t_end / dt)))
    return n, t_end / n
