"""Naive baselines: scipy solve_ivp (RK45, DOP853) on the unprojected index-1 formulation (benchmarks.index1)."""
from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from ..index1 import Index1System
from .base import Method, RunResult, Timer


class ScipyIVP(Method):
    family = "baseline"
    knob = "rtol"

    def __init__(self, solver: str):
        self.solver = solver
        self.name = f"scipy-{solver}"
        self.order = {"RK45": 5, "DOP853": 8}[solver]

    def run(self, spec, t_end, rtol):
        with Timer() as setup:
            sys = Index1System(spec)
            y0 = sys.y0()
        atol = rtol * 1e-3   # positions are O(1 m); a small atol keeps rtol the only knob
        with Timer() as tm:
            sol = solve_ivp(sys.rhs, (0.0, t_end), y0, method=self.solver, rtol=rtol, atol=atol,
                            t_eval=None, dense_output=False)
        if sol.status != 0:
            raise RuntimeError(f"{self.name} failed: {sol.message}")
        X, U = sys.split(sol.y[:, -1])
        return RunResult(X, U, tm.seconds, setup.seconds, steps=len(sol.t) - 1, info={"nfev": int(sol.nfev)})
