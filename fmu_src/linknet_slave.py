"""pythonfmu slave: one linknet scene as an FMI 2.0 Co-Simulation FMU.

Thin glue only: the physics is linknet_core's `Simulator` (docs/architecture.md). The scene,
linknet_core and the `linknet_fmu` support package travel in the FMU's resources folder.

Rules this file keeps (see docs/fmu.md):
- no scene data in module globals: all pythonfmu FMUs of a process share one interpreter and
  one sys.modules, so this module (and linknet_core) may be the copy of another FMU's resources;
- no exception ever leaves a method called by the FMI binary: pythonfmu 0.7.0 turns any Python
  exception into fmi2Fatal. Bad input is logged with fmi2Error status naming the variable and
  the next doStep returns fmi2Discard; the instance stays usable (and fmi2Reset restores it);
- values live in one float array indexed by value reference, so get_real/set_real are array
  operations instead of pythonfmu's per-variable getter calls.
"""
import linknet_fmu.libpython_global  # noqa: F401  first: C hosts need libpython's symbols global

import copy
import json
import math
import os
import pickle
import sys

import numpy as np

from pythonfmu import Fmi2Slave, Fmi2Causality, Fmi2Variability, Fmi2Initial, Real, String
from pythonfmu.enums import Fmi2Status

import linknet_core as ln
from linknet_fmu import thread_state
from linknet_fmu.layout import Layout

CONFIG_FILE = "linknet_fmu.json"
SCENE_FILE = "linknet_scene.json"
STATE_FORMAT = "linknet-fmu-state-1"


class LinknetNetwork(Fmi2Slave):
    """A network of point masses joined by rigid links (model name = the scene's name)."""

    def __init__(self, **kwargs):
        thread_state.keep()
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
        self._read_vrs = self._read_idx = None  # the last list of variables read (get_real)
        self._real[lay.M_vr] = np.asarray(self._scene0.mass)[lay.free_indices]
        self._real[lay.R_vr] = self._scene0.length
        self._real[lay.g_vr] = self._scene0.gravity
        self._real[lay.tolerance_vr] = cfg["tolerance"]
        self._real[lay.step_vr] = cfg["step"]
        self._integrator = cfg["integrator"]
        self._bad = {}                 # variable name -> reason; a pending bad input fails doStep
        self._broken = None            # reason the solver cannot continue (until reset / set state)
        self._initialized = False
        self._outputs_stale = True
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

    # ------------------------------------------------------------------ helpers
    def _error(self, msg, status=Fmi2Status.error):
        msg = f"{self.instance_name}: {msg}"
        self.log(msg, status)
        # pythonfmu 0.7.0 forwards log messages only when the host instantiated with
        # loggingOn=true; errors also go to stderr so they are never silent.
        sys.stderr.write(f"[linknet FMU error] {msg}\n")

    def _make_simulator(self, scene):
        method = self._integrator
        if ln.METHODS[method].adaptive:
            kwargs = dict(rtol=float(self._real[self._layout.tolerance_vr]))
        else:
            kwargs = dict(dt=float(self._real[self._layout.step_vr]))
        self._sim = ln.Simulator(scene, method=method, **kwargs)
        self._scene = scene
        self._F = np.zeros((scene.K, 3))
        self._F_flat = self._F.reshape(-1)  # a view: set_real writes the inputs through it
        self._F[self._layout.input_masses] = self._real[self._layout.F_vr]
        self._outputs_stale = True

    def _refresh_outputs(self):
        lay = self._layout
        try:
            out = self._sim.outputs(self._F)
            X, U, T = out["X"], out["U"], out["T"]
            Freact = np.asarray(out["Freact"])
            if Freact.shape[0] == self._scene.K:          # (K,3) form: keep the anchored rows
                Freact = Freact[lay.fixed_indices]
            self._real[lay.X_vr] = X[lay.output_masses]
            self._real[lay.U_vr] = U[lay.output_masses]
            self._real[lay.T_vr] = T
            self._real[lay.Freact_vr] = Freact
        except Exception as e:  # never let an exception reach pythonfmu (fmi2Fatal)
            self._real[lay.T_vr] = np.nan
            self._real[lay.Freact_vr] = np.nan
            self._error(f"tensions cannot be computed at t={self._sim.state.t!r}: {e}")
        self._outputs_stale = False

    def _check_parameter(self, vr, value):
        """Reason why `value` is out of range for parameter vr, or None."""
        lay = self._layout
        if not math.isfinite(value):
            return "must be finite"
        if vr in lay.M_vr or vr in lay.R_vr or vr == lay.step_vr:
            return None if value > 0 else "must be > 0"
        if vr == lay.tolerance_vr:
            return None if 0 < value < 0.1 else "must lie in (0, 0.1)"
        return None

    # ------------------------------------------------------------------ FMI: values
    def get_real(self, vrs):
        thread_state.keep()
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

    def set_real(self, vrs, values):
        thread_state.keep()
        lay = self._layout
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
                    self._input_vrs, self._input_idx, self._input_force_idx = list(vrs), idx, force_idx
            if idx is not None:
                vals = np.asarray(values, dtype=float)
                # finite (and below ~1e154, else the per-variable path below takes it) in one dot product
                if vals.shape == idx.shape and math.isfinite(float(vals.dot(vals))):
                    self._real[idx] = vals
                    self._F_flat[force_idx] = vals
                    self._outputs_stale = True
                    return
        changed_parameter = False
        for vr, value in zip(vrs, values):
            if not 0 <= vr < lay.n_real:
                self._error(f"setReal: unknown value reference {vr}")
                continue
            var = lay.reals[vr]
            if var.causality == "output":
                self._error(f"{var.name} is an output and cannot be set; value {value!r} ignored")
                continue
            if var.causality == "input":
                if not math.isfinite(value):
                    self._bad[var.name] = f"= {value!r} is not a finite force"
                    self._error(f"{var.name} {self._bad[var.name]}; the next doStep is refused (fmi2Discard)")
                    continue
                self._bad.pop(var.name, None)
                self._real[vr] = value
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
                self._bad[var.name] = f"= {value!r} {reason}"
                self._error(f"parameter {var.name} {self._bad[var.name]}; the next doStep is refused")
                continue
            self._bad.pop(var.name, None)
            self._real[vr] = value
            changed_parameter = True
        self._F[lay.input_masses] = self._real[lay.F_vr]
        self._outputs_stale = True
        if changed_parameter:
            self._parameters_dirty = True

    def _set_integrator(self, value):
        if self._initialized:
            self._bad["integrator"] = "is a fixed parameter and cannot be changed after initialization"
            self._error(f"integrator {self._bad['integrator']}")
            return
        if value not in self._cfg["integrators"]:
            self._bad["integrator"] = f"= {value!r} is not one of {', '.join(self._cfg['integrators'])}"
            self._error(f"parameter integrator {self._bad['integrator']}")
            return
        self._bad.pop("integrator", None)
        self._integrator = value
        self._parameters_dirty = True

    # ------------------------------------------------------------------ FMI: life cycle
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
        self._broken = None  # parameters are applied before initialization ends: an earlier failure is gone

    def do_step(self, current_time, step_size):
        thread_state.keep()
        try:
            return self._do_step(current_time, step_size)
        except Exception as e:  # last resort: an exception here would be fmi2Fatal
            self._broken = f"unexpected error in doStep: {type(e).__name__}: {e}"
            self._error(self._broken)
            return False

    def _do_step(self, t, h):
        if not self._initialized:
            self.exit_initialization_mode()
        if self._bad:
            for name, reason in self._bad.items():
                self._error(f"doStep refused: {name} {reason}")
            return False
        if self._broken:
            self._error(f"doStep refused: {self._broken}; call fmi2Reset (or restore a saved FMU state)")
            return False
        if not (math.isfinite(h) and h > 0):
            self._error(f"doStep refused: communication step size h={h!r} must be finite and > 0")
            return False
        t_fmu = self._sim.state.t
        if not math.isfinite(t) or abs(t - t_fmu) > 1e-9 * max(1.0, abs(t_fmu)):
            self._error(f"doStep refused: currentCommunicationPoint t={t!r} differs from the FMU's time {t_fmu!r}")
            return False
        if t + h <= t_fmu:
            # h > 0 but below half an ulp of t: t + h == t in floating point, nothing to integrate
            return True
        try:
            # Simulator.advance leaves the state at t when it raises (the step can be retried
            # after fmi2SetFMUstate or with other inputs) and guarantees a finite state when it returns
            self._sim.advance(t + h, self._F)
        except ln.LinknetError as e:
            self._error(f"doStep from t={t!r} with h={h!r} failed: {e}")
            return False
        self._outputs_stale = True
        return True

    # ------------------------------------------------------------------ FMI: FMU state
    # pythonfmu's default saves registered variables only; the full state is the simulator
    # snapshot (positions, velocities, time, integrator internals) plus inputs and parameters.
    def _get_fmu_state(self):
        return {
            "format": STATE_FORMAT,
            "sim": copy.deepcopy(self._sim.get_state()),
            "real": self._real.copy(),
            "integrator": self._integrator,
            "scene": self._scene,
            "bad": dict(self._bad),
            "broken": self._broken,
            "initialized": self._initialized,
        }

    def _set_fmu_state(self, state):
        try:
            if not isinstance(state, dict) or state.get("format") != STATE_FORMAT:
                self._error("setFMUstate: not a state saved by this FMU")
                return
            lay = self._layout
            params = np.concatenate([lay.M_vr, lay.R_vr, lay.g_vr, [lay.tolerance_vr, lay.step_vr]])
            same_setup = (state["integrator"] == self._integrator
                          and np.array_equal(state["real"][params], self._real[params]))
            self._real = state["real"].copy()
            self._integrator = state["integrator"]
            if not same_setup:  # otherwise keep the simulator (building one analyses the structure)
                self._make_simulator(state["scene"])
            self._F[lay.input_masses] = self._real[lay.F_vr]
            self._sim.set_state(copy.deepcopy(state["sim"]))
            self._bad = dict(state["bad"])
            self._broken = state["broken"]
            self._initialized = state["initialized"]
            self._parameters_dirty = False
            self._outputs_stale = True
        except Exception as e:
            self._broken = f"setFMUstate failed: {e}"
            self._error(self._broken)

    @staticmethod
    def _fmu_state_to_bytes(state):
        # pickle keeps every float bit-exact (replay after deserialization is bit-identical).
        return pickle.dumps(state, protocol=pickle.HIGHEST_PROTOCOL)

    @staticmethod
    def _fmu_state_from_bytes(data):
        # Only deserialize states this host serialized from this FMU (pickle trusts its input).
        return pickle.loads(data)
