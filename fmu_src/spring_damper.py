"""pythonfmu slave: a linear spring-damper between two masses of two different FMUs.

    n = (xb - xa)/|xb - xa|,  f = k (|xb - xa| - d0) + c n.(vb - va)
    Fa = f n (force on end a),  Fb = -f n (force on end b)

the same law as linknet_core's scene springs (forces.element_forces, the 'spring' kind), so a composition of
two network FMUs through this FMU converges to the monolithic scene with that spring.
Outputs have direct feedthrough from the four inputs.
"""
import linknet_fmu.libpython_global  # noqa: F401  first: C hosts need libpython's symbols global

import math

from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Fmi2Initial, Real

from linknet_fmu.component import GuardedComponent

DESCRIPTION = ("linear spring-damper between two points: Fa = (k (|xb-xa| - d0) + c n.(vb-va)) n, Fb = -Fa, "
               "n = (xb-xa)/|xb-xa| (direct feedthrough)")
AXES = ("x", "y", "z")
DEFAULT_EXPERIMENT = dict(startTime=0.0, stopTime=2.0, stepSize=1e-3)
_IN = {"xa": "Position", "va": "Velocity", "xb": "Position", "vb": "Velocity"}
DECLARED_TYPES = {**{f"{n}[{i}]": t for n, t in _IN.items() for i in (1, 2, 3)},
                  **{f"{n}[{i}]": "Force" for n in ("Fa", "Fb") for i in (1, 2, 3)},
                  "stiffness": "Stiffness", "rest_length": "Length", "damping": "Damping"}
_ALL_INPUTS = [f"{n}[{i}]" for n in _IN for i in (1, 2, 3)]
OUTPUT_DEPENDENCIES = {f"{n}[{i}]": list(_ALL_INPUTS) for n in ("Fa", "Fb") for i in (1, 2, 3)}


class SpringDamper(GuardedComponent, Fmi2Slave):
    OUTPUT_PREFIXES = ("Fa", "Fb")
    NON_NEGATIVE = ("stiffness", "rest_length", "damping")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = DESCRIPTION
        self.values = {name: 0.0 for name in DECLARED_TYPES}
        self.values.update(stiffness=100.0, rest_length=1.0, damping=0.0)
        self.bad = {}
        words = {"xa": "position of end a", "va": "velocity of end a", "xb": "position of end b",
                 "vb": "velocity of end b", "Fa": "force on end a", "Fb": "force on end b",
                 "stiffness": "stiffness (>= 0)", "rest_length": "rest length (>= 0)", "damping": "damping (>= 0)"}
        for name in DECLARED_TYPES:
            base = name.split("[")[0]
            axis = f", {AXES[int(name[-2]) - 1]}" if "[" in name else ""
            if base in _IN:
                kind = dict(causality=Fmi2Causality.input, variability=Fmi2Variability.continuous)
            elif base in ("Fa", "Fb"):
                kind = dict(causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                            initial=Fmi2Initial.calculated)
            else:
                kind = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                            initial=Fmi2Initial.exact)
            self.register_variable(Real(name, description=words[base] + axis,
                                        getter=(lambda n=name: self._get(n)),
                                        setter=(lambda value, n=name: self._set(n, value)), **kind))

    def _force_on_a(self):
        v = self.values
        d = [v[f"xb[{i}]"] - v[f"xa[{i}]"] for i in (1, 2, 3)]
        dist = math.sqrt(sum(c * c for c in d))
        if dist == 0.0:
            return [0.0, 0.0, 0.0]  # no direction when the ends coincide (as in linknet_core)
        n = [c / dist for c in d]
        rate = sum(n[i - 1] * (v[f"vb[{i}]"] - v[f"va[{i}]"]) for i in (1, 2, 3))
        f = v["stiffness"] * (dist - v["rest_length"]) + v["damping"] * rate
        return [f * c for c in n]

    def _get(self, name):
        if name[:2] in ("Fa", "Fb"):
            F = self._force_on_a()[int(name[3]) - 1]
            return F if name[1] == "a" else -F
        return self.values[name]
