"""pythonfmu slave: one linknet scene as an FMI 2.0 Co-Simulation FMU.

Thin glue only: the physics is linknet_core's `Simulator` (docs/architecture.md). The scene,
linknet_core and the `linknet_fmu` support package travel in the FMU's resources folder.

Rules this file keeps (see docs/fmu.md):
- no scene data in module globals: all pythonfmu FMUs of a process share one interpreter and
  one sys.modules, so this module (and linknet_core) may be the copy of another FMU's resources;
- no exception ever leaves a method called by the FMI binary: pythonfmu 0.7.0 turns any Python
  exception into fmi2Fatal. Every entry point is wrapped by `guarded` (an unexpected exception is logged
  and answered with the entry point's neutral value); bad input is logged with fmi2Error status naming
  the variable and the next doStep returns fmi2Discard; the instance stays usable (and fmi2Reset
  restores it);
- values live in one float array indexed by value reference, so get_real/set_real are array
  operations instead of pythonfmu's per-variable getter calls.
"""
import linknet_fmu.libpython_global  # noqa: F401  first: C hosts need libpython's symbols global

import copy
import functools
import hashlib
import json
import math
import os
import pickle
import sys

try:
    import numpy as np
    import linknet_core as ln
except ImportError as _exc:  # say why fmi2Instantiate returns NULL, whether the host logs or not
    sys.stderr.write(
        f"[linknet FMU error] fmi2Instantiate: the FMU's Python cannot import {_exc.name or 'a module'} ({_exc}). "
        f"The FMU needs CPython {sys.version_info.major}.{sys.version_info.minor} with numpy and scipy: this "
        f"interpreter (prefix {sys.prefix}) searches {sys.path}; point PYTHONPATH at the site-packages that hold "
        "numpy and scipy (or PYTHONHOME at that Python's prefix) in the host's environment.\n")
    raise

from pythonfmu import Boolean, Fmi2Slave, Fmi2Causality, Fmi2Variability, Fmi2Initial, Real, String
from pythonfmu.enums import Fmi2Status

from linknet_fmu import anchor_jumps, thread_state
from linknet_fmu.layout import (DERIVATIVE_ORDER_GIVEN, DERIVATIVE_VR_BASE, ERROR_ESTIMATE_CATEGORY,
                                 ERROR_ESTIMATE_CATEGORY_DESCRIPTION, ESTIMATE_ERROR_DESCRIPTION, EVENT_CATEGORY,
                                 EVENT_CATEGORY_DESCRIPTION, Layout)
from linknet_fmu.rope_events import event_impulses, event_message
from linknet_fmu.parameters import parameter_problem

CONFIG_FILE = "linknet_fmu.json"
SCENE_FILE = "linknet_scene.json"
# An FMU state names its format and the FMU it belongs to (a fingerprint of the scene, the exposed masses and the
# model identifier): fmi2SetFMUstate refuses another FMU's state, and deserialization checks a header and a
# checksum before unpickling anything. Raise the number when the state's content changes.
STATE_FORMAT = "linknet-fmu-state-4"
STATE_MAGIC = b"LINKNET-FMU-STATE\0"
# an input's declared type -> what a refused value of it is called
INPUT_QUANTITY = {"Force": "force", "Position": "position", "Velocity": "velocity", "Acceleration": "acceleration"}
# fmi2GetDirectionalDerivative reaches the slave through the binary's front layer (pythonfmu 0.7.0 has no path for
# it) as two calls of encoded value references (fmu_src/pythonfmu_front/front.c), which pythonfmu hands to Python as
# signed 32-bit ints: one set_real of the seed, DIRECTIONAL_SEED_START first, then DIRECTIONAL_SEED + vr of each
# known with its seed; then one get_real of DIRECTIONAL_DERIVATIVE + vr of each unknown.
DIRECTIONAL_SEED = -(1 << 31)
DIRECTIONAL_SEED_START = DIRECTIONAL_SEED + DERIVATIVE_VR_BASE
DIRECTIONAL_DERIVATIVE = -(1 << 30)
# the library's bound on input forces and anchor inputs (the native FMU bakes the same, fmu_src/native/build.py)
MAX_INPUT = getattr(sys.modules[ln.Simulator.__module__], "MAX_FORCE")


def guarded(neutral):
    """Wrap an FMI entry point: no exception may reach pythonfmu 0.7.0, which would answer fmi2Fatal and leave
    the instance unusable. An unexpected one is logged with fmi2Error status (the call's status) and the entry point
    returns `neutral(self, *args)` (a list of the right length for getters, False for doStep, None for setters)."""
    def wrap(method):
        @functools.wraps(method)
        def entry(self, *args):
            thread_state.keep()
            try:
                return method(self, *args)
            except Exception as e:  # the last resort: the cases the slave knows are answered inside
                try:
                    self._error(f"{method.__name__} failed: {type(e).__name__}: {e}")
                except Exception:  # noqa: S110 (logging itself failed: nothing left to report with)
                    pass
                return neutral(self, *args)
        entry.guarded = True
        return entry
    return wrap


def _none(self, *args):
    return None


def _false(self, *args):
    return False


def _values(fill):
    def neutral(self, vrs=(), *args):
        try:
            return [fill] * len(vrs)
        except TypeError:
            return []
    return neutral


class LinknetNetwork(Fmi2Slave):
    """A network of point masses joined by rigid links (model name = the scene's name)."""

    def __init__(self, **kwargs):
        thread_state.keep()
        try:
            self._construct(**kwargs)
        except Exception as e:  # pythonfmu returns NULL; say why even when the host does not log
            sys.stderr.write(f"[linknet FMU error] fmi2Instantiate of {kwargs.get('instance_name')!r} failed: "
                             f"{type(e).__name__}: {e}\n")
            raise

    def _construct(self, **kwargs):
        super().__init__(**kwargs)
        with open(os.path.join(self.resources, CONFIG_FILE)) as f:
            cfg = json.load(f)
        with open(os.path.join(self.resources, SCENE_FILE)) as f:
            self._scene0 = ln.Scene.from_dict(json.load(f))
        self._cfg = cfg
        self.modelName = cfg["model_identifier"]
        self.description = cfg.get("description")
        self.author = cfg.get("author")
        self.version = cfg.get("version")
        self._layout = Layout.from_scene(self._scene0, cfg.get("inputs"), cfg.get("outputs"))
        lay = self._layout

        self._real = np.zeros(lay.n_real)
        self._input_vrs = self._input_idx = self._input_force_idx = None  # the last inputs set (set_real)
        # P, V, A set since the last step: the anchors move as P + V s + A s^2/2 from the time they were set (the
        # current time); until they are, the Simulator keeps the last hold (a read after a step sees where it went)
        self._anchors_set = False
        # per input-driven anchor, since the last step: whether a P of it was set, and the first V or A set (its value
        # reference; -1: none). A V or A set without P restarts the held motion from the P last set: said once per
        # instance, as position jumps shorter than anchor_jumps.LOGGED_ALWAYS of a link are (anchor_jumps)
        n_anchors = len(lay.anchor_inputs)
        self._p_set = np.zeros(n_anchors, dtype=bool)
        self._va_vr = np.full(n_anchors, -1, dtype=np.int64)
        self._said_short_jump = self._said_set_without_p = False
        self._read_vrs = self._read_idx = None  # the last list of variables read (get_real)
        # fmi2GetDirectionalDerivative: the seed of the call in progress, the linearization at the current state and
        # inputs (stale once they change), and per value reference which seed it enters (0: F, 1: P, 2: V, 3: A,
        # -1: none) at which flat index, and whether it is an output with direct feedthrough (T, Freact)
        self._seed = self._linearization = None
        self._linearization_stale = True
        self._seed_kind = np.full(lay.n_real, -1, dtype=np.int64)
        self._seed_index = np.full(lay.n_real, -1, dtype=np.int64)
        self._seed_kind[lay.F_vr.reshape(-1)] = 0
        self._seed_index[lay.F_vr.reshape(-1)] = lay.force_index[lay.F_vr.reshape(-1)]
        for kind, table in enumerate((lay.P_vr, lay.V_vr, lay.A_vr), start=1):
            self._seed_kind[table.reshape(-1)] = kind
            self._seed_index[table.reshape(-1)] = np.arange(table.size)
        self._feedthrough = np.zeros(lay.n_real, dtype=bool)
        self._feedthrough[lay.T_vr] = self._feedthrough[lay.Freact_vr.reshape(-1)] = True
        self._real[lay.P_vr] = np.asarray(self._scene0.X0)[lay.anchor_inputs]  # at rest at the scene's position
        self._real[lay.M_vr] = np.asarray(self._scene0.mass)[lay.free_indices]
        self._real[lay.R_vr] = self._scene0.length
        self._real[lay.g_vr] = self._scene0.gravity
        self._real[lay.tolerance_vr] = cfg["tolerance"]
        self._real[lay.step_vr] = cfg["step"]
        self._integrator = cfg["integrator"]
        # the error estimate (Simulator(error_estimate=...)): the parameter estimate_error, and whether the estimate
        # was beyond the goal after the last step (its warning is logged once per crossing)
        self._estimate_error = bool(cfg.get("error_estimate", True))
        self._over_goal = False
        # an instance copy (the class's dict is pythonfmu's, shared by every slave of the process)
        self.log_categories = dict(self.log_categories)
        self.log_categories[ERROR_ESTIMATE_CATEGORY] = ERROR_ESTIMATE_CATEGORY_DESCRIPTION
        if self._scene0.unilateral:
            self.log_categories[EVENT_CATEGORY] = EVENT_CATEGORY_DESCRIPTION
        self._t0 = 0.0                 # fmi2SetupExperiment's startTime: the scene's initial state is given there
        self._identity = hashlib.sha256(json.dumps(
            [STATE_FORMAT, self._scene0.fingerprint, cfg["model_identifier"], cfg.get("inputs"), cfg.get("outputs")]
        ).encode()).hexdigest()[:32]
        self._bad = {}                 # variable name -> reason; a pending bad input fails doStep
        self._broken = None            # reason the solver cannot continue (until reset / set state)
        self._initialized = False
        self._outputs_stale = self._linearization_stale = True
        self._parameters_dirty = False
        self._make_simulator(self._scene0)

        for v in lay.reals:
            self.register_variable(Real(
                v.name, causality=getattr(Fmi2Causality, v.causality),
                variability=getattr(Fmi2Variability, v.variability),
                initial=getattr(Fmi2Initial, v.initial) if v.initial else None,
                description=v.description,
                getter=(lambda vr=v.vr: self.get_real([vr])[0]),
                setter=(lambda value, vr=v.vr: self.set_real([vr], [value]))))
        self.register_variable(String(
            "integrator", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
            initial=Fmi2Initial.exact,
            description="integration method: " + ", ".join(cfg["integrators"]),
            getter=lambda: self._integrator, setter=self._set_integrator))
        self.register_variable(Boolean(
            "estimate_error", causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed,
            initial=Fmi2Initial.exact, description=ESTIMATE_ERROR_DESCRIPTION,
            getter=lambda: self._estimate_error, setter=lambda value: self.set_boolean([lay.estimate_error_vr],
                                                                                       [value])))
        assert self.vars[lay.estimate_error_vr].name == "estimate_error"

    # ------------------------------------------------------------------ helpers
    def _error(self, msg, status=Fmi2Status.error):
        # The binary's front layer (fmu_src/pythonfmu_front) makes the worst status logged during a call the
        # call's status, and hands errors, discards and warnings to the host's logger (with loggingOn or not),
        # under the host's instance name: a reused instance keeps the self.instance_name it was made with.
        self.log(msg, status)

    def _make_simulator(self, scene):
        method = self._integrator
        if ln.METHODS[method].adaptive:
            kwargs = dict(rtol=float(self._real[self._layout.tolerance_vr]))
        else:
            kwargs = dict(dt=float(self._real[self._layout.step_vr]))
        self._sim = ln.Simulator(scene, method=method, t0=self._t0, error_estimate=self._estimate_error, **kwargs)
        self._over_goal = False
        self._scene = scene
        self._F = np.zeros((scene.K, 3))
        self._F_flat = self._F.reshape(-1)  # a view: set_real writes the inputs through it
        self._F[self._layout.input_masses] = self._real[self._layout.F_vr]
        self._shortest_link = anchor_jumps.shortest_links(scene.k1, scene.k2, scene.length,
                                                          self._layout.anchor_inputs)
        self._outputs_stale = self._linearization_stale = True

    def _mark_anchor_inputs(self, vrs):
        """Note which anchors' P, V, A the value references `vrs` (an int array of inputs) set."""
        lay = self._layout
        rows = lay.anchor_row[vrs]
        position = lay.is_position_input[vrs]
        self._p_set[rows[(rows >= 0) & position]] = True
        for row, vr in zip(rows[(rows >= 0) & ~position], vrs[(rows >= 0) & ~position]):
            if self._va_vr[row] < 0:
                self._va_vr[row] = vr

    def _anchors(self):
        """The motion of the anchors driven by inputs as the Simulator takes it: (P, V, A) each (n, 3) in scene
        order, held as P + V s + A s^2/2 from the current time, if they were set since the last step; else None
        (the Simulator keeps the last hold)."""
        lay = self._layout
        if not self._anchors_set:
            return None
        return self._real[lay.P_vr], self._real[lay.V_vr], self._real[lay.A_vr]

    def _refresh_outputs(self):
        lay = self._layout
        # the companion's gap at the current time (m; inf when the companion failed), NaN when it is switched off
        self._real[lay.error_estimate_vr] = (float(self._sim.error_estimate) if self._estimate_error
                                             else float("nan"))
        try:
            out = self._sim.outputs(self._F, anchors=self._anchors())
            # X, U: the state (a driven anchor where its held motion took it, whichever backend: the numpy
            # reference's outputs() moves a driven anchor's rows to new inputs, which X and U do not depend on)
            X, U, T = self._sim.state.X, self._sim.state.U, out["T"]
            Freact = np.asarray(out["Freact"])
            if Freact.shape[0] == self._scene.K:          # (K,3) form: keep the anchored rows
                Freact = Freact[lay.fixed_indices]
            self._real[lay.X_vr] = X[lay.output_masses]
            self._real[lay.U_vr] = U[lay.output_masses]
            self._real[lay.T_vr] = T
            # the peak over the last step (Simulator.tension_peaks); before the first step, T with the inputs as set
            self._real[lay.T_peak_vr], self._real[lay.T_peak_time_vr] = self._sim.tension_peaks(self._F,
                                                                                               self._anchors())
            self._real[lay.Freact_vr] = Freact
            if lay.driven_indices.size:
                self._real[lay.Jreact_vr] = out["impulse"]
            if lay.slack_vr.size:
                self._real[lay.slack_vr] = out["slack"][lay.rope_links]
        except Exception as e:  # never let an exception reach pythonfmu (fmi2Fatal)
            self._real[lay.T_vr] = np.nan
            self._real[lay.T_peak_vr] = self._real[lay.T_peak_time_vr] = np.nan
            self._real[lay.Freact_vr] = np.nan
            self._real[lay.Jreact_vr] = np.nan
            self._error(f"tensions cannot be computed at t={self._sim.state.t!r}: {e}")
        self._outputs_stale = False

    def _check_parameter(self, vr, value):
        """Reason why `value` is out of range for parameter vr, or None (the rules: linknet_fmu.parameters)."""
        lay = self._layout
        kind = ("M" if vr in lay.M_vr else "R" if vr in lay.R_vr else "step" if vr == lay.step_vr
                else "tolerance" if vr == lay.tolerance_vr else "g")
        return parameter_problem(kind, value)

    # ------------------------------------------------------------------ FMI: values
    @guarded(_values(float("nan")))
    def get_real(self, vrs):
        if len(vrs) and DIRECTIONAL_DERIVATIVE <= vrs[0] < DIRECTIONAL_DERIVATIVE + DERIVATIVE_VR_BASE:
            return self._directional_derivative(np.asarray(vrs, dtype=np.int64) - DIRECTIONAL_DERIVATIVE)
        if self._parameters_dirty and not self._initialized:
            # initial unknowns read in initialization mode: T depends on M, R, g (ModelStructure)
            self._apply_parameters_safely()
        if self._outputs_stale:
            self._refresh_outputs()
        try:
            if len(vrs) <= 16:  # a few variables (a master reading one per connection): index directly
                if len(vrs) and min(vrs) < 0:  # numpy would wrap a negative index around
                    raise IndexError
                return self._real[vrs].tolist()
            # a master reading many variables reads the same list every communication step: its index array
            # is checked once and remembered (converting and checking 709 value references cost ~15 us a call)
            if vrs != self._read_vrs:
                idx = np.asarray(vrs)  # more than 16 entries here
                if (idx.ndim != 1 or idx.dtype.kind not in "iu"
                        or (idx.size and (idx.min() < 0 or idx.max() >= self._real.size))):
                    raise IndexError  # (numpy would wrap a negative index around)
                self._read_vrs, self._read_idx = list(vrs), idx
            return self._real[self._read_idx].tolist()
        except (IndexError, TypeError, ValueError):
            self._error(f"getReal: unknown value reference in {list(vrs)!r}")
            return [float("nan")] * len(vrs)

    @guarded(_none)
    def set_real(self, vrs, values):
        lay = self._layout
        if len(vrs) and vrs[0] == DIRECTIONAL_SEED_START:  # fmi2GetDirectionalDerivative's seed, through the front
            self._directional_seed([vr - DIRECTIONAL_SEED for vr in vrs[1:]], list(values[1:]))
            return
        if not self._bad:
            # the common call, every communication step: finite forces onto input variables. One array
            # assignment instead of a Python loop per variable (~0.5 us each: 300 inputs of chain_100 would
            # cost ~150 us, several RATTLE steps). A master sets the same variables every step, so the
            # checks on the value references are done once for a list and remembered (a list comparison
            # costs ~1.5 us for 300, the array conversion and checks ~12 us). Anything else: the loop below.
            if vrs == self._input_vrs:
                idx, force_idx = self._input_idx, self._input_force_idx
            else:
                idx = np.asarray(vrs, dtype=np.int64)
                if not (idx.ndim == 1 and idx.size and idx.min() >= 0 and idx.max() < lay.n_real
                        and lay.is_input[idx].all()):
                    idx = force_idx = None
                else:
                    force_idx = lay.force_index[idx]
                    if not lay.is_force_input[idx].all():  # P, V, A among them: only the forces go to _F
                        force_idx = (np.flatnonzero(force_idx >= 0), force_idx[force_idx >= 0])
                    self._input_vrs, self._input_idx, self._input_force_idx = list(vrs), idx, force_idx
            if idx is not None:
                vals = np.asarray(values, dtype=float)
                # finite (and below ~1e154, else the per-variable path below takes it) in one dot product
                if vals.shape == idx.shape and math.isfinite(float(vals.dot(vals))):
                    self._real[idx] = vals
                    if isinstance(force_idx, tuple):
                        self._F_flat[force_idx[1]] = vals[force_idx[0]]
                        self._anchors_set = True
                        self._mark_anchor_inputs(idx)
                    else:
                        self._F_flat[force_idx] = vals
                    self._outputs_stale = self._linearization_stale = True
                    return
        if len(vrs) and min(vrs) >= DERIVATIVE_VR_BASE:  # fmi2SetRealInputDerivatives, through the front layer
            orders = [vr // DERIVATIVE_VR_BASE for vr in vrs]
            self.set_real_input_derivatives(
                [vr % DERIVATIVE_VR_BASE for vr in vrs],
                [int(value) if order == DERIVATIVE_ORDER_GIVEN else order for order, value in zip(orders, values)],
                [float("nan") if order == DERIVATIVE_ORDER_GIVEN else value for order, value in zip(orders, values)])
            return
        changed_parameter = False
        for vr, value in zip(vrs, values):
            if vr >= DERIVATIVE_VR_BASE:  # fmi2SetRealInputDerivatives, through the binary's front layer
                self.set_real_input_derivatives([vr % DERIVATIVE_VR_BASE], [vr // DERIVATIVE_VR_BASE], [value])
                continue
            if not 0 <= vr < lay.n_real:
                self._error(f"setReal: value reference {vr} is {self._kind_of(vr)} (no Real variable); value "
                            f"{value!r} ignored")
                continue
            var = lay.reals[vr]
            if var.causality == "output":
                self._error(f"{var.name} is an output and cannot be set; value {value!r} ignored")
                continue
            if var.causality == "input":
                if not (isinstance(value, (int, float)) and math.isfinite(value)):
                    what = INPUT_QUANTITY[var.declared_type]
                    self._bad[var.name] = f"= {value!r} is not a finite {what}"
                    self._error(f"{var.name} {self._bad[var.name]}; the next doStep is refused (fmi2Discard)")
                    continue
                self._bad.pop(var.name, None)
                self._real[vr] = value
                if not lay.is_force_input[vr]:
                    self._anchors_set = True
                    self._mark_anchor_inputs(np.array([vr]))
                continue
            # parameter
            if self._initialized:
                if value == self._real[vr]:
                    continue  # re-setting the current value changes nothing (some masters do)
                self._bad[var.name] = "is a fixed parameter and cannot be changed after initialization"
                self._error(f"{var.name} {self._bad[var.name]} (value {value!r} rejected)")
                continue
            reason = self._check_parameter(vr, value)
            if reason is not None:
                self._bad[var.name] = reason if reason.startswith("=") else f"= {value!r}: {reason}"
                self._error(f"parameter {var.name} {self._bad[var.name]}; the next doStep is refused")
                continue
            self._bad.pop(var.name, None)
            self._real[vr] = value
            changed_parameter = True
        self._F[lay.input_masses] = self._real[lay.F_vr]
        self._outputs_stale = self._linearization_stale = True
        if changed_parameter:
            self._parameters_dirty = True

    @guarded(_none)
    def set_real_input_derivatives(self, vrs, orders, values):
        """fmi2SetRealInputDerivatives. An anchor's position input P[k,i] takes derivatives of order 1 (they set
        V[k,i]) and 2 (A[k,i]): its motion over the step is the quadratic P + V tau + A tau^2/2. Every other input
        is held constant over the step: a derivative of it is ignored with a warning, so that a master that sends
        derivatives of all its inputs keeps working. Orders other than 1 and 2, outputs, parameters, unknown value
        references and values that are not finite or beyond the library's bound are refused with an error naming them,
        and then nothing of the call is set. The native FMU's rules and words (fmu_model_set_real_input_derivatives)."""
        lay = self._layout
        where = "fmi2SetRealInputDerivatives: "
        held = None  # the first input held constant, whose derivative is ignored
        for vr, order, value in zip(vrs, orders, values):  # all checked first: a refused call sets nothing
            if not 0 <= vr < lay.n_real:
                self._error(f"{where}value reference {vr} is not a Real variable of this FMU (Reals are "
                            f"0..{lay.n_real - 1}); nothing set")
                return
            var = lay.reals[vr]
            if var.causality != "input":
                what = "an output" if var.causality == "output" else "a parameter"
                self._error(f"{where}{var.name} is {what}, not an input: it takes no input derivative; nothing set")
                return
            if order not in (1, 2):
                self._error(f"{where}derivative of order {order} of {var.name} refused: inputs take derivatives of "
                            "order 1 and 2 only; nothing set")
                return
            if lay.derivative_target[vr, order] >= 0:
                what = "velocity" if order == 1 else "acceleration"
                if not math.isfinite(value):
                    self._error(f"{where}derivative of order {order} of {var.name} = {value:g} is not a finite "
                                f"{what}; nothing set")
                    return
                if abs(value) > MAX_INPUT:
                    self._error(f"{where}derivative of order {order} of {var.name} = {value:g}: an anchor's {what} "
                                f"beyond {MAX_INPUT:g} would overflow the solver; nothing set")
                    return
            elif held is None:
                held = (var.name, order, value)
        targets = [(int(lay.derivative_target[vr, order]), value) for vr, order, value in zip(vrs, orders, values)
                   if lay.derivative_target[vr, order] >= 0]
        if targets:
            self.set_real([t for t, _ in targets], [v for _, v in targets])
        if held is not None:
            name, order, value = held
            others = " (as are those of any other input but an anchor's position P in this call)" if len(vrs) > 1 \
                else ""
            self._error(f"{where}{name} is held constant over a communication step: its derivative of order {order} "
                        f"({value:g}) is ignored{others}", Fmi2Status.warning)

    # ------------------------------------------------------------------ FMI: directional derivatives
    def _directional_seed(self, vrs, values):
        """The seed of one fmi2GetDirectionalDerivative on the known inputs vrs (F, P, V, A), checked whole (the
        native FMU's rules and words, fmu_model_directional_derivative): a reference that is not an input or a seed
        that is not finite is refused naming it, and no seed is kept."""
        lay = self._layout
        self._seed = None
        where = "fmi2GetDirectionalDerivative: "
        for vr, value in zip(vrs, values):
            if not 0 <= vr < lay.n_real:
                self._error(f"{where}known value reference {vr} is not a Real variable of this FMU (Reals are "
                            f"0..{lay.n_real - 1}): a directional derivative is taken with respect to the inputs F, "
                            "P, V, A")
                return
            var = lay.reals[vr]
            if var.causality != "input":
                what = "an output" if var.causality == "output" else "a parameter"
                self._error(f"{where}known {var.name} (value reference {vr}) is {what}, not an input: a directional "
                            "derivative is taken with respect to the inputs F, P, V, A")
                return
            if not math.isfinite(value):
                self._error(f"{where}the seed dvKnown of {var.name} (value reference {vr}) is {value:g}: a seed must "
                            "be finite")
                return
        self._seed = (np.asarray(vrs, dtype=np.int64), np.asarray(values, dtype=float))

    def _directional_derivative(self, vrs):
        """The derivatives of the outputs vrs along the seed just set, at the current state with the inputs as set:
        Simulator.interface_linearization (kept while the state and inputs stay) along one seed. X, U, Jreact and
        error_estimate, T_peak and T_peak_time have no direct feedthrough: 0."""
        lay = self._layout
        where = "fmi2GetDirectionalDerivative: "
        seed, self._seed = self._seed, None
        nan = [float("nan")] * len(vrs)
        outside = (vrs < 0) | (vrs >= lay.n_real)
        if outside.any():
            vr = int(vrs[outside][0])
            self._error(f"{where}unknown value reference {vr} is not a Real variable of this FMU (Reals are "
                        f"0..{lay.n_real - 1}): a directional derivative is that of an output")
            return nan
        not_output = lay.is_input[vrs] | lay.is_parameter[vrs]
        if not_output.any():
            vr = int(vrs[not_output][0])
            var = lay.reals[vr]
            what = "an input" if var.causality == "input" else "a parameter"
            self._error(f"{where}unknown {var.name} (value reference {vr}) is {what}, not an output: a "
                        "directional derivative is that of an output (X, U, T, T_peak, T_peak_time, Freact, Jreact, "
                        "error_estimate)")
            return nan
        if seed is None:
            self._error(f"{where}no seed was given before the derivative was asked for")
            return nan
        derivative = np.zeros(lay.n_real)  # by value reference; only T and Freact have direct feedthrough
        if self._feedthrough[vrs].any():
            try:
                if self._linearization_stale or self._linearization is None:
                    self._linearization = self._sim.interface_linearization(self._F, anchors=self._anchors())
                    self._linearization_stale = False
                known, values = seed
                n_anchors = len(lay.anchor_inputs)
                seeds = [np.zeros(3 * self._scene.K)] + [np.zeros(3 * n_anchors) for _ in range(3)]
                kinds = self._seed_kind[known]
                for kind, flat in enumerate(seeds):
                    mine = kinds == kind
                    np.add.at(flat, self._seed_index[known[mine]], values[mine])  # a reference twice: seeds add
                anchors = [flat.reshape(-1, 3) if n_anchors else None for flat in seeds[1:]]
                out = self._linearization.directional(dF=seeds[0].reshape(-1, 3), dP=anchors[0], dV=anchors[1],
                                                      dA=anchors[2])
            except Exception as e:  # a state the tensions cannot be linearized at: said, never raised to pythonfmu
                self._error(f"{where}the tension system (25)-(26) cannot be linearized at t={self._sim.state.t!r}: "
                            f"{e}")
                return nan
            derivative[lay.T_vr] = out["T"]
            Freact = np.asarray(out["Freact"])
            if Freact.shape[0] == self._scene.K:  # (K,3) form: keep the anchored rows
                Freact = Freact[lay.fixed_indices]
            derivative[lay.Freact_vr] = Freact
        return derivative[vrs].tolist()

    def _set_integrator(self, value):
        if self._initialized:
            self._bad["integrator"] = "is a fixed parameter and cannot be changed after initialization"
            self._error(f"integrator {self._bad['integrator']}")
            return
        if value not in self._cfg["integrators"] or parameter_problem("integrator", value):
            self._bad["integrator"] = f"= {value!r} is not one of {', '.join(self._cfg['integrators'])}"
            self._error(f"parameter integrator {self._bad['integrator']}")
            return
        self._bad.pop("integrator", None)
        self._integrator = value
        self._parameters_dirty = True

    # Integer, Boolean and String: the FMU has one String (integrator), one Boolean (estimate_error) and no Integer
    # variable.
    # pythonfmu's own versions raise on any other value reference (fmi2Fatal); these log and go on.
    @guarded(_values(""))
    def get_string(self, vrs):
        out = []
        for vr in vrs:
            if vr == self._layout.integrator_vr:
                out.append(self._integrator)
            else:
                self._error(f"getString: value reference {vr} is {self._kind_of(vr)}, not a String variable")
                out.append("")
        return out

    @guarded(_none)
    def set_string(self, vrs, values):
        for vr, value in zip(vrs, values):
            if vr == self._layout.integrator_vr:
                self._set_integrator(value)
            else:
                self._error(f"setString: value reference {vr} is {self._kind_of(vr)}, not a String variable; "
                            f"value {value!r} ignored")

    @guarded(_values(0))
    def get_integer(self, vrs):
        self._error(f"getInteger: this FMU has no Integer variables (value references {list(vrs)!r})")
        return [0] * len(vrs)

    @guarded(_none)
    def set_integer(self, vrs, values):
        self._error(f"setInteger: this FMU has no Integer variables (value references {list(vrs)!r}); nothing set")

    @guarded(_values(False))
    def get_boolean(self, vrs):
        out = []
        for vr in vrs:
            if vr == self._layout.estimate_error_vr:
                out.append(self._estimate_error)
            else:
                self._error(f"getBoolean: value reference {vr} is {self._kind_of(vr)}: no Boolean variable of this "
                            f"FMU has it (the only one is estimate_error, {self._layout.estimate_error_vr})")
                out.append(False)
        return out

    @guarded(_none)
    def set_boolean(self, vrs, values):
        for vr, value in zip(vrs, values):
            if vr != self._layout.estimate_error_vr:
                self._error(f"setBoolean: value reference {vr} is {self._kind_of(vr)}: no Boolean variable of this "
                            f"FMU has it (the only one is estimate_error, {self._layout.estimate_error_vr}); value "
                            f"{value!r} ignored")
                continue
            value = bool(value)
            if self._initialized:
                if value != self._estimate_error:
                    self._error(f"estimate_error is a fixed parameter and cannot be changed after initialization "
                                f"(value {value!r}, current {self._estimate_error!r}); nothing set")
                continue
            if value != self._estimate_error:
                self._estimate_error = value
                self._parameters_dirty = True

    def _kind_of(self, vr):
        if isinstance(vr, int) and 0 <= vr < self._layout.n_real:
            return f"the Real {self._layout.reals[vr].name}"
        if vr == self._layout.integrator_vr:
            return "the String integrator"
        if vr == self._layout.estimate_error_vr:
            return "the Boolean estimate_error"
        return "unknown"

    # ------------------------------------------------------------------ FMI: life cycle
    @guarded(_none)
    def setup_experiment(self, start_time=0.0, stop_time=None, tolerance=None):
        """startTime is honoured: the scene's initial state is given at t0 (the scene is autonomous, so this is
        its motion shifted in time). The experiment's tolerance is not used: the `tolerance` parameter is."""
        if self._initialized:
            self._error("setupExperiment after initialization is not allowed; ignored")
            return
        if start_time is None:
            start_time = 0.0
        if not (isinstance(start_time, (int, float)) and math.isfinite(start_time)):
            self._bad["startTime"] = f"= {start_time!r} must be finite"
            self._error(f"setupExperiment: startTime {self._bad['startTime']}")
            return
        self._bad.pop("startTime", None)
        if float(start_time) != self._t0:
            self._t0 = float(start_time)
            self._parameters_dirty = True  # the simulator is rebuilt to start there

    @guarded(_none)
    def enter_initialization_mode(self):
        pass

    @guarded(_none)
    def terminate(self):
        pass

    @guarded(_none)
    def exit_initialization_mode(self):
        """Rebuild the simulator if parameters changed; errors surface at the next doStep."""
        self._apply_parameters_safely()
        self._initialized = True

    def _apply_parameters_safely(self):
        try:
            self._apply_parameters()
        except Exception as e:
            self._broken = f"the parameters do not define a valid scene: {e}"
            self._error(self._broken)

    def _apply_parameters(self):
        if not self._parameters_dirty:
            return
        self._parameters_dirty = False
        lay = self._layout
        mass = np.asarray(self._scene0.mass, dtype=float).copy()
        mass[lay.free_indices] = self._real[lay.M_vr]
        scene = self._scene0.with_parameters(mass=mass, length=self._real[lay.R_vr].copy(),
                                             gravity=self._real[lay.g_vr].copy())
        self._make_simulator(scene)
        # a run that starts over has taken no step: no impulses (a restored state keeps those of its step)
        self._real[lay.Jrope_vr] = 0.0
        self._real[lay.Jground_vr] = 0.0
        self._broken = None  # parameters are applied before initialization ends: an earlier failure is gone

    @guarded(_false)
    def do_step(self, current_time, step_size):
        return self._do_step(current_time, step_size)

    def _do_step(self, t, h):
        if not self._initialized:
            self._error("doStep refused: the FMU is not initialized (call fmi2ExitInitializationMode first)")
            return False
        if self._bad:
            for name, reason in self._bad.items():  # fmi2Discard: the master can set a good value and retry
                self._error(f"doStep refused: {name} {reason}", Fmi2Status.discard)
            return False
        if self._broken:
            self._error(f"doStep refused: {self._broken}; call fmi2Reset (or restore a saved FMU state)")
            return False
        if not (math.isfinite(h) and h > 0):
            self._error(f"doStep refused: communication step size h={h!r} must be finite and > 0")
            return False
        t_fmu = self._sim.state.t
        if not (isinstance(t, (int, float)) and math.isfinite(t)) or abs(t - t_fmu) > 1e-9 * max(1.0, abs(t_fmu)):
            self._error(f"doStep refused: currentCommunicationPoint t={t!r} differs from the FMU's time {t_fmu!r}")
            return False
        if t + h <= t_fmu:
            # h > 0 but below half an ulp of t: t + h == t in floating point, nothing to integrate
            return True
        jump = self._position_jump()
        events_before = len(self._sim.integrator.events) if self._scene.unilateral else 0
        try:
            # Simulator.advance leaves the state at t when it raises (the step can be retried
            # after fmi2SetFMUstate or with other inputs) and guarantees a finite state when it returns
            self._sim.advance(t + h, self._F, anchors=self._anchors())
        except ln.LinknetError as e:
            note = ""
            if jump is not None:
                P, X, counted, _ = jump
                note = anchor_jumps.failure_note(self._jump_items(P, X, counted))
            self._error(f"doStep from t={t!r} with h={h!r} failed: {e}{note}", Fmi2Status.discard)
            return False
        if jump is not None:
            self._say_position_jump(t, *jump)
        if self._scene.unilateral:  # the step's rope and ground events: their impulses, one message each
            events = self._sim.integrator.events[events_before:]
            lay = self._layout
            self._real[lay.Jrope_vr], self._real[lay.Jground_vr] = event_impulses(events, lay.rope_links,
                                                                                  lay.ground_masses)
            for event in events:
                self.log(event_message(event, self._scene), Fmi2Status.ok, EVENT_CATEGORY)
        self._anchors_set = False
        self._p_set[:] = False
        self._va_vr[:] = -1
        self._outputs_stale = self._linearization_stale = True
        if self._estimate_error:
            # beyond the goal (or the companion failed): said once per crossing, with fmi2Warning status in its own
            # log category, and the step stays fmi2OK: its result is computed as asked, the warning is information
            # (the front layer does not count messages of the FMU's own categories towards the call's status)
            note = self._sim.error_note()
            if note and not self._over_goal:
                self.log(note, Fmi2Status.warning, ERROR_ESTIMATE_CATEGORY)
            self._over_goal = bool(note)
        return True

    def _position_jump(self):
        """(P, X, counted, long) where inputs set since the last step put an input-driven anchor elsewhere than its
        held motion had it (anchor_jumps.jumps), else None."""
        lay = self._layout
        if not (self._anchors_set and lay.anchor_inputs.size):
            return None
        P = self._real[lay.P_vr]
        X = self._sim.state.X[lay.anchor_inputs]
        counted, long = anchor_jumps.jumps(P, X, self._shortest_link)
        return (P.copy(), X.copy(), counted, long) if counted.any() else None

    def _jump_items(self, P, X, mask):
        lay = self._layout
        names = [[lay.reals[vr].name for vr in row] for row in lay.P_vr]
        return anchor_jumps.items(names, lay.P_vr, P, X, mask)

    def _say_position_jump(self, t, P, X, counted, long):
        """Log the position jump the step began with (anchor_jumps): a jump of P each time it is longer than
        anchor_jumps.LOGGED_ALWAYS of the shortest link at its anchor, shorter ones once per instance; a V or A set
        without P once per instance. One message (fmi2Warning), with the impulses the core reported."""
        lay = self._layout
        without_p = ~self._p_set & (self._va_vr >= 0)
        driven_row = {int(k): j for j, k in enumerate(lay.driven_indices)}
        J = self._sim.anchor_report()["jump_impulse"][[driven_row[int(k)] for k in lay.anchor_inputs]]
        J_names = [[lay.reals[vr].name for vr in lay.Jreact_vr[driven_row[int(k)]]] for k in lay.anchor_inputs]
        messages = []
        moved = counted & ~without_p[:, None]
        short_first = not self._said_short_jump and bool((moved & ~long).any())
        if (moved & long).any() or short_first:
            anchors = np.flatnonzero(moved.any(axis=1))
            first_short = None
            if short_first:
                self._said_short_jump = True
                first_short = anchor_jumps.LOGGED_ALWAYS * float(self._shortest_link[anchors].min())
            messages.append(anchor_jumps.position_jump_warning(t, self._jump_items(P, X, moved),
                                                               anchor_jumps.impulses(J_names, J, anchors), first_short))
        restarted = counted & without_p[:, None]
        if restarted.any() and not self._said_set_without_p:
            self._said_set_without_p = True
            anchors = np.flatnonzero(restarted.any(axis=1))
            vr = int(self._va_vr[anchors[0]])
            messages.append(anchor_jumps.set_without_p_warning(t, lay.reals[vr].name, vr,
                                                               self._jump_items(P, X, restarted),
                                                               anchor_jumps.impulses(J_names, J, anchors)))
        if messages:
            self._error(" ".join(messages), Fmi2Status.warning)

    # ------------------------------------------------------------------ FMI: FMU state
    # pythonfmu's default saves registered variables only; the full state is the simulator
    # snapshot (positions, velocities, time, integrator internals) plus inputs and parameters.
    @guarded(_none)
    def _get_fmu_state(self):
        return {
            "format": STATE_FORMAT,
            "fmu": self._identity,
            "sim": copy.deepcopy(self._sim.get_state()),
            "real": self._real.copy(),
            "integrator": self._integrator,
            "estimate_error": self._estimate_error,
            "over_goal": self._over_goal,
            "t0": self._t0,
            "scene": self._scene,
            "bad": dict(self._bad),
            "broken": self._broken,
            "initialized": self._initialized,
            "anchors_set": self._anchors_set,
        }

    def _state_problem(self, state):
        """Why `state` is not one of this FMU's states (None if it is)."""
        if not isinstance(state, dict):
            return f"not an FMU state of this FMU (a {type(state).__name__})"
        if state.get("format") != STATE_FORMAT:
            return state.get("invalid") or f"not a linknet FMU state of format {STATE_FORMAT!r}"
        if state.get("fmu") != self._identity:
            return "a state of another FMU (another scene, other exposed masses or another model)"
        return self._sim_problem(state)

    def _sim_problem(self, state):
        if not isinstance(state.get("real"), np.ndarray) or state["real"].shape != self._real.shape:
            return "a damaged state (its values do not fit this FMU)"
        return None

    @guarded(_none)
    def _set_fmu_state(self, state):
        problem = self._state_problem(state)
        if problem:  # refused: the instance is left exactly as it was
            self._error(f"setFMUstate refused: {problem}")
            return
        try:
            lay = self._layout
            params = np.concatenate([lay.M_vr, lay.R_vr, lay.g_vr, [lay.tolerance_vr, lay.step_vr]])
            same_setup = (state["integrator"] == self._integrator and state.get("t0", 0.0) == self._t0
                          and state["estimate_error"] == self._estimate_error
                          and np.array_equal(state["real"][params], self._real[params]))
            self._real = state["real"].copy()
            self._integrator = state["integrator"]
            self._estimate_error = state["estimate_error"]
            self._t0 = state.get("t0", 0.0)
            if not same_setup:  # otherwise keep the simulator (building one analyses the structure)
                self._make_simulator(state["scene"])
            self._F[lay.input_masses] = self._real[lay.F_vr]
            self._sim.set_state(copy.deepcopy(state["sim"]))
            self._anchors_set = bool(state.get("anchors_set", False))
            self._p_set[:] = False  # which inputs were set is not in the state: a jump from it is said as one of P
            self._va_vr[:] = -1
            self._over_goal = bool(state["over_goal"])
            self._bad = dict(state["bad"])
            self._broken = state["broken"]
            self._initialized = state["initialized"]
            self._parameters_dirty = False
            self._outputs_stale = self._linearization_stale = True
        except Exception as e:
            self._broken = f"setFMUstate failed: {e}"
            self._error(self._broken)

    # Serialized: STATE_MAGIC, 8 bytes of payload length, 32 bytes of SHA-256 of the payload, the payload (pickle:
    # every float bit-exact, so replay after deserialization is bit-identical). Header, length and checksum are
    # checked before the payload is unpickled: garbage, truncated and damaged bytes are refused, and a state of
    # another FMU (right format) is refused by fmi2SetFMUstate. pythonfmu calls these on the class: they cannot log,
    # so a refused deserialization returns a marker that fmi2SetFMUstate refuses with the reason.
    @staticmethod
    def _fmu_state_to_bytes(state):
        try:
            payload = pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)
        except Exception as e:  # noqa: BLE001 (never fmi2Fatal)
            sys.stderr.write(f"[linknet FMU error] serializeFMUstate failed: {e}\n")
            payload = pickle.dumps({"format": None, "invalid": f"the state could not be serialized ({e})"})
        return STATE_MAGIC + len(payload).to_bytes(8, "little") + hashlib.sha256(payload).digest() + payload

    @staticmethod
    def _fmu_state_from_bytes(data):
        try:
            data = bytes(data)
            head = len(STATE_MAGIC)
            if not data.startswith(STATE_MAGIC):
                return {"format": None, "invalid": "not a linknet FMU state (the bytes do not start with its header)"}
            size = int.from_bytes(data[head:head + 8], "little")
            digest, payload = data[head + 8:head + 40], data[head + 40:]
            if len(payload) != size:
                return {"format": None, "invalid": f"a truncated or padded state ({len(payload)} bytes of payload, "
                                                   f"its header says {size})"}
            if hashlib.sha256(payload).digest() != digest:
                return {"format": None, "invalid": "a damaged state (its checksum does not match)"}
            return pickle.loads(payload)
        except Exception as e:  # noqa: BLE001 (never fmi2Fatal)
            return {"format": None, "invalid": f"not a readable linknet FMU state ({type(e).__name__}: {e})"}
