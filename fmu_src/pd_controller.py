"""pythonfmu slave: a PD position controller for compositions (examples/compositions/).

    F = Kp (x_target - x) - Kd v + F_ff        (3 components, N)

Inputs x[i] (m) and v[i] (m/s) are the measured position and velocity of one mass; the
output F[i] is the force to apply to it. F has direct feedthrough from x and v, so in a loop
the plant's output must not depend directly on F (linknet's X and U do not). Stateless: the
FMU state is just the variable values.
"""
import linknet_fmu.libpython_global  # noqa: F401  first: C hosts need libpython's symbols global

from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Fmi2Initial, Real

from linknet_fmu.component import GuardedComponent

DESCRIPTION = "PD position controller: F = Kp (x_target - x) - Kd v + F_ff (direct feedthrough from x, v)"
AXES = ("x", "y", "z")
DEFAULT_EXPERIMENT = dict(startTime=0.0, stopTime=2.0, stepSize=1e-3)
DECLARED_TYPES = {**{f"x[{i}]": "Position" for i in (1, 2, 3)}, **{f"v[{i}]": "Velocity" for i in (1, 2, 3)},
                  **{f"F[{i}]": "Force" for i in (1, 2, 3)}, **{f"x_target[{i}]": "Position" for i in (1, 2, 3)},
                  **{f"F_ff[{i}]": "Force" for i in (1, 2, 3)}, "Kp": "Stiffness", "Kd": "Damping"}
OUTPUT_DEPENDENCIES = {f"F[{i}]": [f"x[{i}]", f"v[{i}]"] for i in (1, 2, 3)}


class PDController(GuardedComponent, Fmi2Slave):
    OUTPUT_PREFIXES = ("F[",)
    NON_NEGATIVE = ("Kp", "Kd")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = DESCRIPTION
        self.values = {name: 0.0 for name in DECLARED_TYPES}
        self.values.update(Kp=100.0, Kd=10.0)
        self.bad = {}
        for name in DECLARED_TYPES:
            base = name.split("[")[0]
            axis = f", {AXES[int(name[-2]) - 1]}" if "[" in name else ""
            if base in ("x", "v"):
                kind = dict(causality=Fmi2Causality.input, variability=Fmi2Variability.continuous)
                what = {"x": "measured position", "v": "measured velocity"}[base]
            elif base == "F":
                kind = dict(causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                            initial=Fmi2Initial.calculated)
                what = "control force"
            else:
                kind = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                            initial=Fmi2Initial.exact)
                what = {"x_target": "target position", "F_ff": "feedforward force",
                        "Kp": "proportional gain (>= 0)", "Kd": "derivative gain (>= 0)"}[base]
            self.register_variable(Real(name, description=what + axis,
                                        getter=(lambda n=name: self._get(n)),
                                        setter=(lambda value, n=name: self._set(n, value)), **kind))

    def _get(self, name):
        if name.startswith("F["):
            i = name[2]
            v = self.values
            return (v["Kp"] * (v[f"x_target[{i}]"] - v[f"x[{i}]"]) - v["Kd"] * v[f"v[{i}]"] + v[f"F_ff[{i}]"])
        return self.values[name]
