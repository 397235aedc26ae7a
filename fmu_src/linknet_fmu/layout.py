"""Map a linknet scene onto FMI 2.0 variables.

One `Layout` per FMU instance (never module-global: several scenes' FMUs share one
interpreter and one sys.modules). Real variables get value references 0..n_real-1 in the
order of `self.reals`; the one String parameter (`integrator`) comes last.
Names are Modelica-style, 1-based: F[k,i], P[k,i], V[k,i], A[k,i], X[k,i], U[k,i], T[l], T_peak[l], T_peak_time[l],
Freact[k,i],
Jreact[k,i], error_estimate, slack[l], Jrope[l], Jground[k], M[k], R[l], g[i], tolerance, step; then the String parameter integrator (value reference
n_real) and the Boolean parameter estimate_error (n_real + 1). P, V, A (the motion of an anchor driven by inputs) and Jreact (the impulse on a
driven anchor) exist only for scenes with driven anchors, so a scene without them keeps its value references; slack
and Jrope (per rope link, l its link number) only for scenes with ropes, Jground (per free mass) only for scenes with a
ground.

slack[l] is a Real of value 0 or 1, not a Boolean: the FMU's outputs are one Real vector (value references 0..n_real-1,
read by one fmi2GetReal), and its modelDescription writer and fmi2GetBoolean know the one Boolean parameter only;
a 0/1 Real keeps slack beside T, its tension, in the same call and the same dependency table.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

AXES = ("x", "y", "z")

# fmi2SetRealInputDerivatives reaches the pythonfmu slave as fmi2SetReal of the value reference
# order * DERIVATIVE_VR_BASE + vr (pythonfmu's own binary has no path for it): the front layer of the binary
# encodes, linknet_slave.py decodes and answers. Far above any FMU's value references.
DERIVATIVE_VR_BASE = 1 << 28
# The last of the slots order * DERIVATIVE_VR_BASE that pythonfmu hands to Python intact (as a signed 32-bit int)
# carries an order the encoding cannot (below 1, or this slot and beyond), with the order itself as the value: the slave
# refuses it in its own words.
DERIVATIVE_ORDER_GIVEN = (1 << 31) // DERIVATIVE_VR_BASE - 1

# The Boolean parameter that switches the error estimate's companion run on (the default) or off, and the log
# category of the message an FMU logs when its estimate exceeds the run's goal: both FMU kinds write these.
ESTIMATE_ERROR_DESCRIPTION = ("estimate the run's global error with a companion run (output error_estimate; about "
                              "2 to 2.5 times the work of a step); false: no companion, error_estimate is NaN")
ERROR_ESTIMATE_CATEGORY = "logErrorEstimate"  # = LINKNET_NOTE_CATEGORY of fmu_src/native/fmi2_api.h
# The log category of the rope and ground events (one message per event: time, kind, link or mass, impulse)
EVENT_CATEGORY = "logEvents"
EVENT_CATEGORY_DESCRIPTION = ("A rope or ground event within a doStep: its time, kind (taut, slack, contact, release, "
                              "stick, slip), link or mass and impulse (N s), logged with fmi2OK status")
ERROR_ESTIMATE_CATEGORY_DESCRIPTION = (
    "The error estimate exceeded the run's goal (or its companion run failed): logged with fmi2Warning status once "
    "per crossing; the doStep still returns fmi2OK (its result is computed as asked).")

# declaredType -> (quantity, unit); written into TypeDefinitions by build_fmu.py
TYPES = {
    "Force": ("Force", "N"),
    "Position": ("Length", "m"),
    "Velocity": ("Velocity", "m/s"),
    "Mass": ("Mass", "kg"),
    "Length": ("Length", "m"),
    "Acceleration": ("Acceleration", "m/s2"),
    "Time": ("Time", "s"),
    "Tolerance": ("Tolerance", "1"),
    "Stiffness": ("TranslationalSpringConstant", "N/m"),
    "Damping": ("TranslationalDampingConstant", "N.s/m"),
    "Impulse": ("Impulse", "N.s"),
}

# unit -> SI base-unit exponents (UnitDefinitions)
UNITS = {
    "N": dict(kg=1, m=1, s=-2),
    "m": dict(m=1),
    "m/s": dict(m=1, s=-1),
    "kg": dict(kg=1),
    "m/s2": dict(m=1, s=-2),
    "s": dict(s=1),
    "1": dict(),
    "N/m": dict(kg=1, s=-2),
    "N.s/m": dict(kg=1, s=-1),
    "N.s": dict(kg=1, m=1, s=-1),
}


@dataclass
class RealVar:
    name: str
    causality: str          # input | output | parameter
    variability: str        # continuous | fixed
    initial: str | None     # exact | calculated | None (inputs)
    declared_type: str
    description: str
    vr: int = -1


@dataclass
class Layout:
    """Variables of one scene's FMU.

    input_masses / output_masses: 0-based mass indices whose force input / position and
    velocity outputs are exposed (a scene may expose only some: "skip what a scene doesn't need").
    driven_indices: the driven anchors (a subset of fixed_indices), scene order; anchor_inputs: those driven by
    inputs (motion kind "input"), whose P, V, A are inputs, always all of them (they have no other motion).
    """
    K: int
    L: int
    mass_names: list
    fixed_indices: np.ndarray
    free_indices: np.ndarray
    k1: np.ndarray
    k2: np.ndarray
    input_masses: np.ndarray
    output_masses: np.ndarray
    driven_indices: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    anchor_inputs: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    rope_links: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    ground_masses: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    reals: list = field(default_factory=list)

    @classmethod
    def from_scene(cls, scene, inputs=None, outputs=None) -> "Layout":
        free = np.asarray(scene.free_indices, dtype=int)
        fixed = np.asarray(scene.fixed_indices, dtype=int)
        inp = free if inputs is None else np.asarray(sorted(inputs), dtype=int)
        out = np.arange(scene.K) if outputs is None else np.asarray(sorted(outputs), dtype=int)
        free_set = set(free.tolist())
        for k in inp:
            if k not in free_set:
                raise ValueError(f"mass {k + 1} cannot take a force input: it is anchored or does not exist")
        for k in out:
            if not 0 <= k < scene.K:
                raise ValueError(f"mass {k + 1} does not exist (scene has {scene.K} masses)")
        lay = cls(K=int(scene.K), L=int(scene.L), mass_names=list(scene.mass_names),
                  fixed_indices=fixed, free_indices=free,
                  k1=np.asarray(scene.k1, dtype=int), k2=np.asarray(scene.k2, dtype=int),
                  input_masses=inp, output_masses=out,
                  driven_indices=np.asarray(scene.driven_indices, dtype=int),
                  anchor_inputs=np.asarray(scene.input_driven_indices, dtype=int),
                  rope_links=np.flatnonzero(scene.rope),
                  ground_masses=free if scene.ground is not None else np.zeros(0, dtype=int))
        lay._build()
        return lay

    # ------------------------------------------------------------------ variables
    def _add(self, *args) -> int:
        v = RealVar(*args)
        v.vr = len(self.reals)
        self.reals.append(v)
        return v.vr

    def _mass_label(self, k: int) -> str:
        return f"mass {k + 1} ({self.mass_names[k]})"

    def _build(self):
        held = "held constant over each communication step"
        self.F_vr = np.array([[self._add(f"F[{k + 1},{i + 1}]", "input", "continuous", None, "Force",
                                         f"external force on {self._mass_label(k)}, {AXES[i]} component, {held}")
                               for i in range(3)] for k in self.input_masses], dtype=int).reshape(-1, 3)
        quadratic = ("the anchor moves as P + V tau + A tau^2/2, tau from the communication point where they were set, "
                     "until they are set again; fmi2SetRealInputDerivatives of P[k,i] sets V[k,i] (order 1) and "
                     "A[k,i] (order 2)")
        self.P_vr, self.V_vr, self.A_vr = (
            np.array([[self._add(f"{name}[{k + 1},{i + 1}]", "input", "continuous", None, dtype,
                                 f"{what} of driven anchor {self._mass_label(k)}, {AXES[i]}; {quadratic}")
                       for i in range(3)] for k in self.anchor_inputs], dtype=int).reshape(-1, 3)
            for name, dtype, what in (("P", "Position", "position"), ("V", "Velocity", "velocity"),
                                      ("A", "Acceleration", "acceleration")))
        self.X_vr = np.array([[self._add(f"X[{k + 1},{i + 1}]", "output", "continuous", "calculated", "Position",
                                         f"position of {self._mass_label(k)}, {AXES[i]}")
                               for i in range(3)] for k in self.output_masses], dtype=int).reshape(-1, 3)
        self.U_vr = np.array([[self._add(f"U[{k + 1},{i + 1}]", "output", "continuous", "calculated", "Velocity",
                                         f"velocity of {self._mass_label(k)}, {AXES[i]}")
                               for i in range(3)] for k in self.output_masses], dtype=int).reshape(-1, 3)
        self.T_vr = np.array([self._add(f"T[{l + 1}]", "output", "continuous", "calculated", "Force",
                                        f"tension in link {l + 1} (masses {self.k1[l] + 1}-{self.k2[l] + 1}); "
                                        "> 0 pulls the masses together; depends directly on the inputs of its "
                                        "group of links")
                              for l in range(self.L)], dtype=int)
        self.T_peak_vr = np.array([self._add(f"T_peak[{l + 1}]", "output", "continuous", "calculated", "Force",
                                             f"largest tension in link {l + 1} (masses {self.k1[l] + 1}-"
                                             f"{self.k2[l] + 1}) in magnitude over the last communication step, "
                                             "signed (T then): located between the integrator's steps, so a spike "
                                             "between two communication points that T misses is here; before the "
                                             "first step, T")
                                   for l in range(self.L)], dtype=int)
        self.T_peak_time_vr = np.array([self._add(f"T_peak_time[{l + 1}]", "output", "continuous", "calculated",
                                                  "Time", f"when T_peak[{l + 1}] occurred (s), within the last "
                                                  "communication step (its ends included)")
                                        for l in range(self.L)], dtype=int)
        anchor = {int(k): "driven anchor" for k in self.driven_indices}
        self.Freact_vr = np.array([[self._add(f"Freact[{k + 1},{i + 1}]", "output", "continuous", "calculated",
                                              "Force", f"force the network exerts on {anchor.get(int(k), 'anchored')} "
                                              f"{self._mass_label(k)}, {AXES[i]}")
                                    for i in range(3)] for k in self.fixed_indices], dtype=int).reshape(-1, 3)
        self.Jreact_vr = np.array([[self._add(f"Jreact[{k + 1},{i + 1}]", "output", "continuous", "calculated",
                                              "Impulse", f"impulse the network gave driven anchor "
                                              f"{self._mass_label(k)}, {AXES[i]}, over the last communication step: "
                                              "a jump of its motion at the step's start (the links take it at once, "
                                              "as in an inelastic collision) and every rope or ground event in the "
                                              "step (a rope jerked taut); 0 if none")
                                    for i in range(3)] for k in self.driven_indices], dtype=int).reshape(-1, 3)
        self.error_estimate_vr = self._add(
            "error_estimate", "output", "continuous", "calculated", "Position",
            "estimated largest position error of any mass at the current time (a companion run of the same scene with "
            "half the step, or a tenth of the tolerances, never re-synchronised: the run's global error); NaN when "
            "the estimate is switched off (estimate_error = false), +inf when the companion run failed")
        self.slack_vr = np.array([self._add(f"slack[{l + 1}]", "output", "continuous", "calculated", "Tolerance",
                                            f"1 where rope link {l + 1} (masses {self.k1[l] + 1}-{self.k2[l] + 1}) is "
                                            "slack (carries no tension: T is 0), 0 where it is taut")
                                  for l in self.rope_links], dtype=int)
        self.Jrope_vr = np.array([self._add(f"Jrope[{l + 1}]", "output", "continuous", "calculated", "Impulse",
                                            f"impulse of rope link {l + 1} coming taut (a jerk) within the last "
                                            "communication step, summed over its events; 0 if none")
                                  for l in self.rope_links], dtype=int)
        self.Jground_vr = np.array([self._add(f"Jground[{k + 1}]", "output", "continuous", "calculated", "Impulse",
                                              f"normal impulse of the ground on {self._mass_label(k)} landing within "
                                              "the last communication step, summed over its events; 0 if none")
                                    for k in self.ground_masses], dtype=int)
        self.M_vr = np.array([self._add(f"M[{k + 1}]", "parameter", "fixed", "exact", "Mass",
                                        f"mass of {self._mass_label(k)} (> 0)")
                              for k in self.free_indices], dtype=int)
        self.R_vr = np.array([self._add(f"R[{l + 1}]", "parameter", "fixed", "exact", "Length",
                                        f"length of link {l + 1} (> 0; the initial positions must satisfy it)")
                              for l in range(self.L)], dtype=int)
        self.g_vr = np.array([self._add(f"g[{i + 1}]", "parameter", "fixed", "exact", "Acceleration",
                                        f"gravitational acceleration, {AXES[i]}") for i in range(3)], dtype=int)
        self.tolerance_vr = self._add("tolerance", "parameter", "fixed", "exact", "Tolerance",
                                      "relative tolerance of the adaptive integrators (dop853, dopri5); in (0, 0.1)")
        self.step_vr = self._add("step", "parameter", "fixed", "exact", "Time",
                                 "internal step of the fixed-step integrators (rattle, yoshida*); > 0")
        self.n_real = len(self.reals)
        self.integrator_vr = self.n_real  # the String parameter, registered after all Reals
        self.estimate_error_vr = self.n_real + 1  # the Boolean parameter, after it
        kinds = np.empty(self.n_real, dtype=object)
        for v in self.reals:
            kinds[v.vr] = v.causality
        self.is_input = kinds == "input"
        self.is_force_input = np.zeros(self.n_real, dtype=bool)
        self.is_force_input[self.F_vr.reshape(-1)] = True
        # fmi2SetRealInputDerivatives: derivative_target[vr, order] is the input that order of vr's derivative
        # sets (P -> V for order 1, P -> A for order 2), -1 where there is none
        self.derivative_target = np.full((self.n_real, 3), -1, dtype=np.int64)
        self.derivative_target[self.P_vr.reshape(-1), 1] = self.V_vr.reshape(-1)
        self.derivative_target[self.P_vr.reshape(-1), 2] = self.A_vr.reshape(-1)
        # value reference of an anchor input (P, V, A) -> its anchor's row in anchor_inputs (-1: none), and whether
        # it is a position
        self.anchor_row = np.full(self.n_real, -1, dtype=np.int64)
        for vrs in (self.P_vr, self.V_vr, self.A_vr):
            self.anchor_row[vrs] = np.arange(len(vrs))[:, None]
        self.is_position_input = np.zeros(self.n_real, dtype=bool)
        self.is_position_input[self.P_vr.reshape(-1)] = True
        # value reference of an input -> its entry in the simulator's (K,3) force array, flattened (-1: none)
        self.force_index = np.full(self.n_real, -1, dtype=np.int64)
        self.force_index[self.F_vr.reshape(-1)] = (3 * np.asarray(self.input_masses, dtype=np.int64)[:, None]
                                                   + np.arange(3)).reshape(-1)
        self.is_parameter = kinds == "parameter"

    # ------------------------------------------------------------------ dependencies
    def link_components(self, inv_mass) -> np.ndarray:
        """Label of the coupled group of each link.

        The tension system A T = B (25)/(26) couples links l, l' only through a shared
        *free* mass (S(l,l')/M(l,l') vanishes at an anchored mass, 1/M = 0), so T_l depends
        on the forces on the free masses of its group and on no other input.
        """
        parent = list(range(self.L))

        def find(a):
            while parent[a] != a:
                parent[a] = parent[parent[a]]
                a = parent[a]
            return a

        by_mass = {}
        for l in range(self.L):
            for k in (self.k1[l], self.k2[l]):
                if inv_mass[k] > 0:
                    by_mass.setdefault(int(k), []).append(l)
        for links in by_mass.values():
            for l in links[1:]:
                parent[find(l)] = find(links[0])
        return np.array([find(l) for l in range(self.L)], dtype=int)

    def dependencies(self, inv_mass) -> dict:
        """name -> list of names of the inputs it depends on at a communication point.

        X and U are integrated states: no direct feedthrough (nor has error_estimate: the gap between two integrated
        states; nor have T_peak and T_peak_time: the peak over the step that ended) (the rows of a driven anchor are
        where its held
        motion took it at the end of the step). T (via B (26)) and Freact (= the link forces on the anchored
        masses) depend on the inputs of their coupled group of links: the forces on its free masses, and the
        position, velocity and acceleration of its anchors driven by inputs (a driven anchor's P sets the link
        directions E, its V the relative velocities in |U_k2 - U_k1|^2 / R and its A the term E.(a_k2 - a_k1)
        of B (26)). Jreact is the impulse of the step that ended: no direct feedthrough.

        The links of one group share one list object (and so do anchors touching the same groups): the table is
        linear in the scene, though the lists it stands for may be L x inputs long (postprocess_model_description
        writes a list that holds every input as the standard's "all knowns").
        """
        comp = self.link_components(inv_mass)
        inputs_of_mass = {int(k): [self.reals[vr].name for vr in row]
                          for k, row in zip(self.input_masses, self.F_vr)}
        for j, k in enumerate(self.anchor_inputs):
            inputs_of_mass[int(k)] = [self.reals[vr].name for vrs in (self.P_vr, self.V_vr, self.A_vr)
                                      for vr in vrs[j]]
        inputs_of_comp = {}
        for l in range(self.L):
            names = inputs_of_comp.setdefault(comp[l], {})  # a dict as an ordered set
            for k in (self.k1[l], self.k2[l]):
                names.update(dict.fromkeys(inputs_of_mass.get(int(k), ())))
        inputs_of_comp = {c: list(names) for c, names in inputs_of_comp.items()}
        deps = {}
        for row in np.concatenate([self.X_vr.ravel(), self.U_vr.ravel(), self.Jreact_vr.ravel(),
                                   [self.error_estimate_vr], self.Jrope_vr, self.Jground_vr, self.T_peak_vr,
                                   self.T_peak_time_vr]):
            deps[self.reals[row].name] = []
        for l in range(self.L):
            deps[self.reals[self.T_vr[l]].name] = inputs_of_comp[comp[l]]
        for l, vr in zip(self.rope_links, self.slack_vr):  # slack where its tension, T, would turn negative
            deps[self.reals[vr].name] = inputs_of_comp[comp[l]]
        for k, row, groups in self._anchor_groups(comp):
            names = _union(inputs_of_comp[c] for c in groups)
            for vr in row:
                deps[self.reals[vr].name] = names
        return deps

    def _anchor_groups(self, comp):
        """(anchored mass, its Freact value references, the groups of the links it holds) per anchored mass, in
        one pass over the links."""
        groups = {int(k): {} for k in self.fixed_indices}
        for l in range(self.L):
            for k in (int(self.k1[l]), int(self.k2[l])):
                if k in groups:
                    groups[k][comp[l]] = None
        return [(k, row, tuple(groups[int(k)])) for k, row in zip(self.fixed_indices, self.Freact_vr)]

    def initial_dependencies(self, inv_mass) -> dict:
        """InitialUnknowns: as `dependencies`, plus the parameters a value depends on at start.

        X and U start at the scene's initial state (no parameter moves them); T and Freact
        depend on the masses and lengths of their group of links (A (25), B (26)) and on g, and so does T_peak, which
        is T before the first step.
        """
        running = self.dependencies(inv_mass)
        comp = self.link_components(inv_mass)
        m_name = {int(k): self.reals[vr].name for k, vr in zip(self.free_indices, self.M_vr)}
        g_names = [self.reals[vr].name for vr in self.g_vr]
        params_of_comp = {}
        for l in range(self.L):
            names = params_of_comp.setdefault(comp[l], {})
            names[self.reals[self.T_vr[l]].name.replace("T[", "R[")] = None
            for k in (self.k1[l], self.k2[l]):
                if int(k) in m_name:
                    names[m_name[int(k)]] = None
        deps = {name: [] for name, d in running.items() if not d}  # no feedthrough, no parameter either
        of_comp = {}  # one list per group: its inputs, then its parameters and g
        for l in range(self.L):
            c = comp[l]
            if c not in of_comp:
                of_comp[c] = running[self.reals[self.T_vr[l]].name] + list(params_of_comp[c]) + g_names
            deps[self.reals[self.T_vr[l]].name] = deps[self.reals[self.T_peak_vr[l]].name] = of_comp[c]
        for l, vr in zip(self.rope_links, self.slack_vr):
            deps[self.reals[vr].name] = of_comp[comp[l]]
        for k, row, groups in self._anchor_groups(comp):
            names = _union([running[self.reals[row[0]].name]] + [list(params_of_comp[c]) for c in groups]
                           + [g_names])
            for vr in row:
                deps[self.reals[vr].name] = names
        return deps


def _union(lists) -> list:
    """The names of several lists, each once, in first-seen order."""
    out = {}
    for names in lists:
        out.update(dict.fromkeys(names))
    return list(out)
