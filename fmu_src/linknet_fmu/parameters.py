"""The rules for an FMU's settings, written once: the slave's parameter check (fmi2SetReal / fmi2SetString in
initialization mode) and build_fmu.py's option check ask the same functions, which are linknet_core's own
(linknet_core.integrators), so the library, the CLI, the FMU and its builder cannot disagree."""
from __future__ import annotations

import math

from linknet_core.integrators import method_problem, positive_problem, real_number, rtol_problem

# parameter kind -> rule; M, R: positive (a mass, a length); step: the fixed-step integrators' internal step;
# tolerance: rtol of the adaptive ones; g: any finite acceleration
RULES = {"M": positive_problem, "R": positive_problem, "step": positive_problem, "tolerance": rtol_problem,
         "integrator": method_problem}


def _finite_problem(value) -> str | None:
    x = real_number(value)
    return None if x is not None and math.isfinite(x) else f"must be a finite number, got {value!r}"


def parameter_problem(kind: str, value) -> str | None:
    """Why `value` is refused for a parameter of this kind (M, R, g, step, tolerance, integrator), or None."""
    return RULES.get(kind, _finite_problem)(value)
