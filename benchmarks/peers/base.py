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


class OverBudget(Exception):
    """The run would exceed its time budget (`Method.run_budget`), predicted from a measurement made while
    setting it up (e.g. one force evaluation); the message gives the measurement and the prediction."""


class Method:
    name = "?"
    family = "peer"          # 'linknet' | 'baseline' | 'peer'
    knob = "dt"              # 'dt' (fixed step) or 'rtol' (adaptive)
    order = None             # nominal order of convergence in the knob (used by the quick test)

    # Stated accuracy contract checked by tests/test_benchmark_quick.py (never timings):
    # adaptive methods: error <= RTOL_BOUND_FACTOR * rtol [m] over the 2 s benchmark runs;
    # fixed-step methods: observed order between successive settings >= ORDER_FRACTION * order.
    RTOL_BOUND_FACTOR = 1e3
    ORDER_FRACTION = 0.7

    # wall-time budget [s] of one run, set by the driver; an adapter that can predict its run time cheaply
    # during setup raises OverBudget instead of starting a run that the driver would kill at its timeout
    run_budget: float | None = None

    def error_bound(self, knob_value: float) -> float | None:
        """Largest error [m] this method promises at this knob value (None: no promise for one run)."""
        return self.RTOL_BOUND_FACTOR * knob_value if self.knob == "rtol" else None

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
