"""pythonfmu slave: a cart on a straight rail (the x axis) for compositions (examples/compositions/cart_chain.py).

    mass x'' = F + F_drive        (N, along the rail)

Inputs F (the coupling force, e.g. a chain's reaction on its hook) and F_drive (a drive or disturbance
force) are held constant over a communication step, and the step is integrated exactly for that held force:

    x(t + h) = x + v h + a h^2/2,   v(t + h) = v + a h,   a = (F + F_drive) / mass

so the cart adds no integration error of its own and its motion over [t, t + h] is exactly the quadratic
x + v tau + a tau^2/2 that a driven anchor's P, V, A inputs hold: connected output for input, the hook
follows the cart exactly. The acceleration output a has direct feedthrough from F and F_drive (declared in
ModelStructure); x and v are states (no direct feedthrough). The FMU state (get/set/serialize) is the
variable values.
"""
import linknet_fmu.libpython_global  # noqa: F401  first: C hosts need libpython's symbols global

import math

from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Fmi2Initial, Real

from linknet_fmu.component import GuardedComponent

DESCRIPTION = ("cart on a rail (x axis): mass x'' = F + F_drive, the held force integrated exactly over each "
               "communication step; outputs x, v and a = (F + F_drive)/mass (direct feedthrough)")
DEFAULT_EXPERIMENT = dict(startTime=0.0, stopTime=2.0, stepSize=1e-3)
DECLARED_TYPES = {"mass": "Mass", "x_start": "Position", "v_start": "Velocity", "F": "Force", "F_drive": "Force",
                  "x": "Position", "v": "Velocity", "a": "Acceleration"}
OUTPUT_DEPENDENCIES = {"x": [], "v": [], "a": ["F", "F_drive"]}
INITIAL_DEPENDENCIES = {"x": ["x_start"], "v": ["v_start"], "a": ["mass", "F", "F_drive"]}
_WORDS = {"mass": "mass of the cart (> 0)", "x_start": "position along the rail at the start time",
          "v_start": "velocity along the rail at the start time", "F": "force along the rail (coupling force)",
          "F_drive": "force along the rail (drive), added to F", "x": "position along the rail",
          "v": "velocity along the rail", "a": "acceleration along the rail, (F + F_drive)/mass"}


class Cart(GuardedComponent, Fmi2Slave):
    OUTPUTS = ("x", "v", "a")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = DESCRIPTION
        self.values = dict(mass=1.0, x_start=0.0, v_start=0.0, F=0.0, F_drive=0.0, x=0.0, v=0.0)
        self.bad = {}
        self.initialized = False
        for name in DECLARED_TYPES:
            if name in ("F", "F_drive"):
                kind = dict(causality=Fmi2Causality.input, variability=Fmi2Variability.continuous)
            elif name in ("x", "v", "a"):
                kind = dict(causality=Fmi2Causality.output, variability=Fmi2Variability.continuous,
                            initial=Fmi2Initial.calculated)
            elif name == "mass":
                kind = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable,
                            initial=Fmi2Initial.exact)
            else:
                kind = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
                            initial=Fmi2Initial.exact)
            self.register_variable(Real(name, description=_WORDS[name], getter=(lambda n=name: self._get(n)),
                                        setter=(lambda value, n=name: self._set(n, value)), **kind))

    def _set(self, name, value):
        if name in ("x_start", "v_start"):
            if self.initialized:
                self._error(f"{name} is a start value (variability fixed): set it before the end of initialization")
                return
            if math.isfinite(value):  # the state follows its start value until initialization ends
                self.values[name[0]] = float(value)
        elif name == "mass" and math.isfinite(value) and value <= 0:
            self.bad[name] = f"= {value!r} is out of range (finite, > 0)"
            self._error(f"{name} {self.bad[name]}; the next doStep is refused")
            return
        elif name in self.OUTPUTS:
            self._error(f"{name} is an output and cannot be set")
            return
        super()._set(name, value)

    def _get(self, name):
        if name == "a":
            v = self.values
            return (v["F"] + v["F_drive"]) / v["mass"]
        return self.values[name]

    def exit_initialization_mode(self):
        self.initialized = True

    def do_step(self, current_time, step_size):
        if not super().do_step(current_time, step_size):
            return False
        a, h = self._get("a"), step_size
        x = self.values["x"] + self.values["v"] * h + 0.5 * a * h * h
        v = self.values["v"] + a * h
        if not (math.isfinite(x) and math.isfinite(v)):
            self._error(f"doStep refused: the cart's state became non-finite (x = {x!r}, v = {v!r}; "
                        f"a = {a!r} m/s2 from F = {self.values['F']!r} N, F_drive = {self.values['F_drive']!r} N)")
            return False
        self.values["x"], self.values["v"] = x, v
        return True

    # the FMU state: every value, the pending refusals and whether initialization has ended
    def _get_fmu_state(self):
        return dict(values=dict(self.values), bad=dict(self.bad), initialized=self.initialized)

    def _set_fmu_state(self, state):
        self.values = dict(state["values"])
        self.bad = dict(state["bad"])
        self.initialized = bool(state["initialized"])
