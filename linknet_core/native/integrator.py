"""The native core as an integrator: whole intervals between two outputs in one call into C.

:class:`NativeIntegrator` takes the place of the numpy reference integrator of the same method inside
:class:`linknet_core.Simulator`. It holds the model (built once per scene), the method as data and the
native data (state, internals, scratch). ``advance`` copies the held input in, calls ``ln_advance`` (which
is all or nothing), and hands out copies of the new state, so that no caller's array is ever written into.
"""
from __future__ import annotations

import copy
import ctypes
import functools
from dataclasses import dataclass

import numpy as np

from linknet_core.dynamics.drive import call_motion, motion_note
from linknet_core.errors import SolverError
from linknet_core.integrators.base import Integrator, StepStats, step_count_problem
from linknet_core.clib import library as lib
from linknet_core.native.model import NativeData, NativeModel, native_method

_explain = lib.lib.ln_explain  # void ln_explain(model, method, data, status, t, t_target, max_steps, label, out, n)
_explain.restype = None
_explain.argtypes = [lib.Model_p, lib.Method_p, lib.Data_p, ctypes.c_int, ctypes.c_double, ctypes.c_double, lib.ln_int,
                     ctypes.c_char_p, ctypes.c_char_p, ctypes.c_size_t]


_NONE = np.zeros(0, np.int64)  # no input-driven anchors (never written into)


def integrator_method(method_cls, *, dt=None, rtol=None, atol=None, static: bool = False):
    """The NativeMethod a NativeIntegrator of ``method_cls`` runs with these settings (atol None: rtol's value)."""
    return native_method(method_cls, dt=dt, rtol=rtol, atol=atol if atol is not None else rtol,
                         position_tol=getattr(method_cls, "position_tol", 1e-14), static=static)


def integrator_data(model: NativeModel, method) -> NativeData:
    """A new NativeData of ``model`` sized for ``method``'s stages (and its screen of the forces inside a step)."""
    return NativeData(model, max(method.n_stages, lib.midpoint_rows(model.pointer, method.pointer)))


def core_initial_state(model: NativeModel, method, K: int):
    """The native core's way of making a rope or ground scene's initial state consistent (ln_rope_initial_state,
    stages/ropes.c; the native FMU calls it with changed masses or lengths), as UnilateralDynamics.initial_state
    takes it (its ``consistent``): a callable (X, U, project) of the scene's K rows -> (X, U), the positions projected
    where ``project`` and the inelastic impact applied; SolverError naming the core's status where it fails.
    ``model`` is the scene's core model (with a ground, native_ground_scene's: the contacts' virtual anchors after the
    scene's masses, placed by the core), ``method`` the NativeMethod the run's integrator has."""
    def consistent(X, U, project: bool):
        Xc, Uc = np.zeros((model.K, 3)), np.zeros((model.K, 3))
        padded = getattr(model, "ground_scene", None)
        if padded is not None:  # the anchors' rows as the native FMU's resource holds them (the core places them)
            Xc[K:], Uc[K:] = padded.X0[K:], padded.U0[K:]
        Xc[:K], Uc[:K] = X, U
        data = integrator_data(model, method)
        status = lib.rope_initial_state(model.pointer, method.pointer, data._ptr, lib.pointer(Xc), lib.pointer(Uc),
                                        int(bool(project)))
        if status != lib.OK:
            d = data.struct
            where = f" at {model.scene.link_label(int(d.fail_link))}" if 0 <= d.fail_link < model.scene.L else ""
            raise SolverError(f"the native core's initial state failed (status {status}: "
                              f"{lib.STATUS.get(status, 'unknown')}){where}")
        return Xc[:K].copy(), Uc[:K].copy()
    return consistent


@dataclass
class _Internals:
    t: float
    h_next: float
    planar: int
    steps: int
    rejected: int
    n_rhs: int
    split_steps: int
    finest_split: int
    jumps: int = 0
    drive: tuple | None = None  # driven anchors: (hold time, P, V, A, callable) of the input-driven ones
    last_jump: tuple | None = None  # driven anchors: (impulse, jump's impulse, position jump, velocity jump) of the
    # last advance
    ropes: tuple | None = None  # ropes: (mode chosen, link_active, rope_impulse, the events so far, slip_reference)

    def __deepcopy__(self, memo):
        """Numbers copy as themselves: only the driven anchors' hold and last jump and the ropes' mode and events have
        anything to copy (the generic deepcopy of the dataclass cost more than a one-step advance)."""
        drive = None if self.drive is None else copy.deepcopy(self.drive, memo)
        last_jump = None if self.last_jump is None else copy.deepcopy(self.last_jump, memo)
        ropes = None if self.ropes is None else (self.ropes[0], self.ropes[1].copy(), self.ropes[2].copy(),
                                                 list(self.ropes[3]), self.ropes[4].copy())
        return _Internals(self.t, self.h_next, self.planar, self.steps, self.rejected, self.n_rhs, self.split_steps,
                          self.finest_split, self.jumps, drive, last_jump, ropes)


def _rows_of(array: np.ndarray):
    """(its first element as lib.first_double gives it, the distance between its rows in elements) of a 2-D float64
    array whose rows are contiguous: a C-contiguous array or some of its columns."""
    if array.flags.c_contiguous:
        return lib.first_double(array), array.shape[1]
    itemsize = array.itemsize
    if array.dtype != np.float64 or array.ndim != 2 or array.strides[1] != itemsize or array.strides[0] % itemsize:
        raise ValueError("the native core takes float64 rows, each contiguous")
    if not array.size:
        return None, 0
    return ctypes.c_double.from_address(array.__array_interface__["data"][0]), array.strides[0] // itemsize


class NativeIntegrator(Integrator):
    """``method_cls``: the reference integrator class whose method this runs (its gammas or tableau, name,
    order, guarantees). ``static``: a scene with no degrees of freedom (an advance moves t only)."""

    def __init__(self, model: NativeModel, method_cls, *, dt=None, rtol=None, atol=None, static: bool = False,
                 t0: float = 0.0):
        self.dyn = None  # the native data keeps the statistics (Integrator.__init__ would set its own)
        self.model = model
        self.name, self.order, self.symplectic = method_cls.name, method_cls.order, method_cls.symplectic
        self.adaptive, self.guarantees = method_cls.adaptive, method_cls.guarantees
        self.dt, self.rtol = dt, rtol
        self.atol = atol if atol is not None else rtol
        self.method = integrator_method(method_cls, dt=dt, rtol=rtol, atol=atol, static=static)
        self.data = integrator_data(model, self.method)
        self._static = static
        self._model_p, self._method_p, self._data_p = model.pointer, self.method.pointer, self.data._ptr
        self._d = self.data.struct
        self._out = (None, None)  # the arrays last handed out as the state (the data holds the same values)
        self._input_zero = True  # whether the data's held input is all zero (as a new data's is)
        # ln_sample's first arguments and its count of samples written: the data's addresses never change
        self._sample = functools.partial(lib.sample, self._model_p, self._method_p, self._data_p)
        self._written = lib.ln_int(0)
        # driven anchors: scene time 0 is t0; input-driven anchors are rows input_slots of the drive arrays
        self._d.drive_t0 = self._d.drive_hold_t = t0
        self.scene = scene = model.scene  # the model holds it weakly
        self._input_slots = (np.flatnonzero([motion.kind == "input" for motion in scene.motions]) if scene.motions
                             else _NONE)
        self._input_labels = [scene.mass_label(int(k)) for k in scene.input_driven_indices] if scene.motions else []
        self._motion = None  # the user's callable of t, when the input-driven anchors follow one
        self._motion_error = None  # what it raised inside the last advance
        self._callback = None  # the C callback that calls it, made when first needed
        # ropes (stages/ropes.c): the events of the run so far, drained from the core's log after every call
        self._ropes = int(model.struct.n_ropes) > 0
        self._events: list = []

    # ---- stats and internals: they live in the native data ------------------------------------
    @property
    def stats(self) -> StepStats:
        d = self._d
        return StepStats(int(d.steps), int(d.rejected), int(d.split_steps), int(d.finest_split))

    def projection_floor(self) -> tuple[int, float]:
        return int(self._d.floor_stops), float(self._d.floor_reached)

    @property
    def rhs_evaluations(self) -> int:
        return int(self._d.n_rhs)

    def internals(self) -> dict:
        d = self._d
        drive = last_jump = None
        if self._input_slots.size:
            data = self.data
            drive = (d.drive_hold_t, data.drive_P.copy(), data.drive_V.copy(), data.drive_A.copy(), self._motion)
        if self.scene.motions:
            last_jump = (self.data.impulse.copy(), self.data.jump_impulse.copy(), d.jump_position, d.jump_velocity)
        ropes = None
        if self._ropes:
            data = self.data
            ropes = (int(d.mode_chosen), data.link_active.copy(), data.rope_impulse.copy(), list(self.events),
                     data.slip_reference.copy())
        return {"native": _Internals(d.t, d.h_next, d.planar, d.steps, d.rejected, d.n_rhs, d.split_steps,
                                     d.finest_split, d.jumps, drive, last_jump, ropes)}

    def reset(self, internals: dict | None = None) -> None:
        """Back to a new integrator's data (NativeData.reset: every counter, the projection floor's included, the
        driven anchors' hold and the scratch), then to ``internals`` unless None (None: the internals a new
        integrator has, which the reset data holds already)."""
        self.data.reset()
        self._motion_error = None
        self._input_zero = True
        self._events = []
        if internals is not None:
            self.set_internals(internals)
            return
        self._motion = None  # the reset data follows no callable (its drive_callback is NULL)
        self._out = (None, None)

    def set_internals(self, data: dict) -> None:
        saved = data["native"]
        d = self._d
        d.t, d.h_next, d.planar = saved.t, saved.h_next, saved.planar
        d.steps, d.rejected, d.n_rhs = saved.steps, saved.rejected, saved.n_rhs
        d.split_steps, d.finest_split, d.jumps = saved.split_steps, saved.finest_split, saved.jumps
        if saved.drive is not None:
            d.drive_hold_t, P, V, A, motion = saved.drive
            self.data.drive_P[...], self.data.drive_V[...], self.data.drive_A[...] = P, V, A
            self._follow(motion)
        if saved.last_jump is not None:
            self.data.impulse[...], self.data.jump_impulse[...], d.jump_position, d.jump_velocity = saved.last_jump
        if saved.ropes is not None:
            self._drain()
            d.mode_chosen, active, impulse, events, slip_reference = saved.ropes
            self.data.link_active[...], self.data.rope_impulse[...] = active, impulse
            self.data.slip_reference[...] = slip_reference
            self._events = list(events)
        self._out = (None, None)  # the state may have been set from outside too: copy it in next time

    # ---- ropes -------------------------------------------------------------------------------------
    def _drain(self) -> None:
        """The core's log of rope events (ln_data: event_t, event_kind, event_link, event_impulse) into the run's
        events, and the log emptied."""
        if not self._ropes:
            return
        from linknet_core.dynamics.unilateral import Event

        n = int(lib.rope_events_drained(self._data_p))
        if n:
            data = self.data
            t, kind, link, impulse = (data.event_log(name, n) for name in ("event_t", "event_kind", "event_link",
                                                                          "event_impulse"))
            self._events.extend(Event(float(t[i]), lib.EVENT_KINDS[int(kind[i])], int(link[i]), float(impulse[i]))
                                for i in range(n))
        lost = int(self._d.events_lost)
        if lost:
            self._d.events_lost = 0
            raise SolverError(f"{self.scene.name}: {lost} rope events within one call into the native core were "
                              "more than its log keeps (ln_data_fields.h: LN_EVENT_LOG); advance over shorter "
                              "intervals")

    @property
    def events(self) -> list:
        """The run's rope events so far, in time order (linknet_core.dynamics.unilateral.Event; index: the link)."""
        self._drain()
        return self._events

    def rope_impulses(self) -> np.ndarray:
        """(L,) N s: each rope's impulse summed over the last advance (0 on rods)."""
        return self.data.rope_impulse.copy()

    # ---- driven anchors -----------------------------------------------------------------------------
    def set_anchors(self, t: float, anchors) -> None:
        """The input-driven anchors from t on: (P, V, A) (each (n_input, 3), checked by the caller) held as
        P + V s + A s^2/2, s = t' - t; or a callable f(t') -> (P, V, A) called wherever the core needs them."""
        if callable(anchors):
            self._follow(anchors)
            return
        self._follow(None)
        rows = self._input_slots
        P, V, A = anchors
        self.data.drive_P[rows], self.data.drive_V[rows], self.data.drive_A[rows] = P, V, A
        self._d.drive_hold_t = t

    def _follow(self, motion) -> None:
        self._motion = motion
        if motion is not None and self._callback is None:
            self._callback = lib.DRIVE_CALLBACK(self._call_motion)
        self._d.drive_callback = ctypes.cast(self._callback, ctypes.c_void_p) if motion is not None else None

    def _call_motion(self, user, t, out) -> int:
        """ln_data.drive_callback: the user's motion at t into P, V, A of each input-driven anchor (9 values
        each); 1 on any failure, whose exception the advance raises."""
        try:
            n = self._input_slots.size
            P, V, A = call_motion(self._motion, t, self._input_labels)
            values = np.ctypeslib.as_array(out, (n, 3, 3))
            values[:, 0], values[:, 1], values[:, 2] = P, V, A
            return 0
        except BaseException as exc:  # noqa: BLE001 - C cannot unwind a Python exception; it is raised below
            self._motion_error = exc
            return 1

    def anchor_jump(self, drive, t: float, X, U, F_input=None):
        """The driven anchors brought to ``drive``'s motion at t where it jumped, by the core's own jump (ln_jump_anchors:
        with ropes the rope event of stages/ropes.c, its events logged): what Simulator.outputs_after_jump asks of a
        scene with ropes, which puts the internals back after. Returns (X, U, impulse (n_driven, 3), position jump,
        velocity jump), as dynamics.drive.anchor_jump."""
        P, V, A = drive.at(t)
        rows = self._input_slots
        self._follow(None)
        self.data.drive_P[rows], self.data.drive_V[rows], self.data.drive_A[rows] = P[rows], V[rows], A[rows]
        d = self._d
        d.drive_hold_t = d.t = t
        self.data.X[...], self.data.U[...] = X, U
        self.data.F_input[...] = 0.0 if F_input is None else F_input
        self._input_zero = F_input is None
        self._out = (None, None)
        status = lib.jump_anchors(self._model_p, self._method_p, self._data_p)
        self._drain()
        if status != lib.OK:
            raise SolverError(self.explain(status, t, t, 1))
        return (self.data.X.copy(), self.data.U.copy(), self.data.impulse.copy(), float(d.jump_position),
                float(d.jump_velocity))

    def anchor_report(self) -> dict:
        """What the links gave each driven anchor in impulses over the last advance (n_driven, 3), N s: its jump's
        and, with ropes or a ground, its events'; the jump's part alone; the jump's largest position and velocity
        change; jumps counted over the run."""
        d = self._d
        return {"impulse": self.data.impulse.copy(), "jump_impulse": self.data.jump_impulse.copy(),
                "jump_position": d.jump_position,
                "jump_velocity": d.jump_velocity, "jumps": int(d.jumps)}

    # ---- stepping -------------------------------------------------------------------------------
    def _load(self, state, F_input) -> None:
        X, U = state.X, state.U
        if X is not self._out[0] or U is not self._out[1]:  # a state set from outside: copy it in
            self.data.X[...] = X
            self.data.U[...] = U
        self._d.t = state.t
        if F_input is not None:
            self.data.F_input[...] = F_input
            self._input_zero = False
        elif not self._input_zero:
            self.data.F_input.fill(0.0)
            self._input_zero = True

    def _hand_out(self, X, U) -> None:
        """X and U become the state's arrays that the data holds too: read-only, so that a change of the state
        replaces them, which the next _load sees (an edit in place would leave the data behind)."""
        X.flags.writeable = U.flags.writeable = False
        self._out = (X, U)

    def hold(self, state) -> None:
        """Put ``state``'s X and U (arrays of the Simulator's own, which become read-only) into the data now, so that
        the first advance finds them there."""
        self.data.X[...] = state.X
        self.data.U[...] = state.U
        self._hand_out(state.X, state.U)

    def advance(self, state, t_target: float, F_input, max_steps: int) -> None:
        self._load(state, F_input)
        status = lib.advance(self._model_p, self._method_p, self._data_p, t_target, max_steps)
        self._drain()
        if status != lib.OK:
            self._raise_motion_error()
            raise SolverError(self.explain(status, state.t, t_target, max_steps))
        if self._static and state.X is self._out[0] and state.U is self._out[1]:
            state.t = t_target  # 0 degrees of freedom: ln_advance moved t only, the arrays handed out still hold X, U
            return
        X, U = self._scene_rows(self.data.X).copy(), self._scene_rows(self.data.U).copy()
        state.X, state.U, state.t = X, U, t_target
        self._hand_out(X, U)

    def _scene_rows(self, A):
        """The rows of a (K,3) array of the core's data that are the scene's masses: all of them here."""
        return A

    def sample(self, state, times, F_input, max_steps: int, X, U, T, diagnostics, advance_first: bool,
               update_state: bool = True, T_peak=None, T_peak_time=None) -> None:
        """Samples at ``times`` (advance to each, then the outputs there) with F_input held, in one call into C
        (ln_sample), into X, U (n,K,3) and T (n,L), unless ``T_peak`` is None the located tension peaks of each
        sample's interval and their times into ``T_peak``, ``T_peak_time`` (n,L; see ``tension_peaks``; a sample
        taken without an advance gets its T and t), and unless ``diagnostics`` is None each sample's energy,
        residuals of (11) and (12) and kinetic energy into its column of ``diagnostics`` (4,n), one row per
        quantity (needs ``diagnostics_in_c``); X, U, T and ``times`` C-contiguous float64, ``diagnostics`` float64
        with contiguous rows (a C-contiguous array or columns of one). Sample 0 is taken at the current state
        unless ``advance_first``. On a failure the samples before it are written, ``state`` is where the run
        stopped, and the SolverError says why, as ``advance`` and ``outputs`` would. Unless ``update_state``,
        ``state`` is left as it was (the next advance starts from it again; the internals and counters move on):
        for a run whose end state nobody reads."""
        self._load(state, F_input)
        t_before = state.t
        written = self._written
        ref = lib.first_double
        if diagnostics is None:
            terms = first = None
            stride = 0
        else:
            terms = self._energy_terms
            first, stride = _rows_of(diagnostics)
        peaks = (None, None) if T_peak is None else (ref(T_peak), ref(T_peak_time))
        status = self._sample(ref(times), times.size, advance_first, max_steps, ref(X), ref(U), ref(T), *peaks, terms,
                              first, stride, written)
        self._drain()
        if not update_state:
            self._out = (None, None)  # the data no longer holds the state
        elif written.value or status != lib.OK:
            X_now, U_now = self.data.X.copy(), self.data.U.copy()
            state.X, state.U, state.t = X_now, U_now, float(self._d.t)
            self._hand_out(X_now, U_now)
        if status == lib.OK:
            return
        self._raise_motion_error()
        i = written.value
        if self._d.t == times[i]:  # the advance to sample i succeeded, its outputs did not
            raise SolverError(f"the tensions (25)-(26) cannot be evaluated at this state: {lib.STATUS[status]}")
        raise SolverError(self.explain(status, float(times[i - 1]) if i > 0 else t_before, float(times[i]),
                                       max_steps))

    @property
    def locates_peaks(self) -> bool:
        """Whether the advances locate tension peaks: not in a static scene, whose advance takes no step, nor with
        ropes, whose modes change the tensions' meaning at the events (as the numpy reference's event integrators)."""
        return not self._static and not self._ropes

    def tension_peaks(self):
        """(T_peak, T_peak_time), (L,) each, of the last advance: each link's largest |T_l| over it, signed, and
        when, located between the step ends (tension_peaks.c); None where the advance located none (a static scene:
        its tensions stand still with the input held). A failed advance leaves those of the last one that went
        through (the core publishes an interval's peaks when all its steps are done)."""
        if not self._d.history_points:
            return None
        peak, time = self._peak_views
        return peak.copy(), time.copy()

    @functools.cached_property
    def _peak_views(self):
        L = self.model.L
        return self.data._view("T_peak", L), self.data._view("T_peak_time", L)

    @functools.cached_property
    def diagnostics_in_c(self) -> bool:
        """Whether ``sample`` can fill the samples' diagnostics (a scene whose potentials the core knows, and no ropes:
        their residuals of (11) and (12) are one-sided, UnilateralDynamics's)."""
        return self._energy_terms is not None and not self._ropes

    @functools.cached_property
    def _energy_terms(self):
        return self.model.energy_terms

    def tensions(self, X, U, F_input=None) -> np.ndarray:
        """T of (25)-(26) at (X, U) with F_input held (minimum-norm where A is singular)."""
        return self.outputs(X, U, F_input)[0]

    def outputs(self, X, U, F_input=None):
        """(T, the force the network exerts on each anchor) at (X, U) with F_input held, in one call."""
        F = self.data.F_input
        if F_input is not None:
            F[...] = F_input
            self._input_zero = False
        elif not self._input_zero:
            F.fill(0.0)
            self._input_zero = True
        X = np.ascontiguousarray(X, np.float64)
        U = np.ascontiguousarray(U, np.float64)
        status = lib.evaluate(self._model_p, self._data_p, lib.pointer(X), lib.pointer(U))
        if status != lib.OK:
            self._raise_motion_error()
            raise SolverError(f"the tensions (25)-(26) cannot be evaluated at this state: {lib.STATUS[status]}")
        return self.data.T.copy(), self.data.reaction.copy()

    def _raise_motion_error(self) -> None:
        error, self._motion_error = self._motion_error, None
        if isinstance(error, (SolverError, KeyboardInterrupt)):
            raise error
        if error is not None:
            raise SolverError(f"the anchors' motion callable failed: {type(error).__name__}: {error}") from error

    def explain(self, status: int, t_start: float, t_target: float, max_steps: int) -> str:
        """The failure of an advance in words, naming the link, the residuals and what may help: the core's text
        (ln_explain, src/explain.c; the native FMU says the same)."""
        if status == lib.TOO_MANY_STEPS and not self.adaptive and self.dt is not None:
            # a fixed-step method's count is known before any step: say it, with the span and dt
            problem = step_count_problem(t_start, t_target, self.dt, max_steps)
            if problem:
                return problem
        d = self._d
        link = self.scene.link_label(int(d.fail_link)).encode() if d.fail_link >= 0 else None
        out = ctypes.create_string_buffer(4096)
        _explain(self._model_p, self._method_p, self._data_p, status, t_start, t_target, max_steps, link, out,
                 len(out))
        message = out.value.decode(errors="replace")
        if status in (lib.PROJECTION_FAILED, lib.STEP_UNDERFLOW) and d.fail_link >= 0:
            message = self._near_self_stress(message)
        if status == lib.STEP_UNDERFLOW:
            message += motion_note(self.scene, t_start - d.drive_t0, t_target - d.drive_t0)
        return message

    def _near_self_stress(self, message: str) -> str:
        """The message, and why no step can help where a near-self-stress carries the load
        (Dynamics.near_self_stress_load), judged at the state the failed advance started from (the core puts it
        back: all or nothing); the reference's dynamics is made for it, on the failure path only."""
        from linknet_core.dynamics.equations import Dynamics
        from linknet_core.structure.topology import analyse

        scene = self.scene
        try:
            diagnosis = Dynamics(scene, analyse(scene)).near_self_stress_load(self.data.X.copy(), self.data.U.copy(),
                                                                               self.data.F_input.copy())
        except SolverError:
            diagnosis = ""
        return f"{message} {diagnosis}" if diagnosis else message


class NativeGroundIntegrator(NativeIntegrator):
    """A scene with a frictionless ground on the native core: its model is unilateral.native_ground_scene's (a virtual
    anchor per free mass appended to the masses, a contact link per free mass appended to the links, each a
    unilateral link of stages/ropes.c that the core places above its mass), its state and outputs the scene's: the
    first K masses and L links of the core's, the anchors' rows filled by the core. ``scene``: the scene itself."""

    def __init__(self, model: NativeModel, scene, *args, **kwargs):
        super().__init__(model, *args, **kwargs)
        self.K, self.L = scene.K, scene.L
        self._n_fixed = int(np.asarray(scene.fixed, bool).sum())
        self._n_contacts = len(model.ground_scene.contact_masses)  # the contact links (the grips' come after)

    def _load(self, state, F_input) -> None:
        K = self.K
        if state.X is not self._out[0] or state.U is not self._out[1]:
            self.data.X[:K], self.data.U[:K] = state.X, state.U
        self._d.t = state.t
        if F_input is not None:
            self.data.F_input[:K] = F_input
            self._input_zero = False
        elif not self._input_zero:
            self.data.F_input.fill(0.0)
            self._input_zero = True

    def hold(self, state) -> None:
        self.data.X[:self.K], self.data.U[:self.K] = state.X, state.U
        self._hand_out(state.X, state.U)

    def _scene_rows(self, A):
        """The scene's masses' rows: the virtual anchors of the contacts and grips come after them."""
        return A[:self.K]

    def sample(self, state, times, F_input, max_steps: int, X, U, T, diagnostics, advance_first: bool,
               update_state: bool = True, T_peak=None, T_peak_time=None) -> None:
        """NativeIntegrator.sample into the core's own rows (the anchors' and the contacts' too), the scene's
        copied out."""
        n, K, L = times.size, self.K, self.L
        Xa, Ua = np.zeros((n, self.model.K, 3)), np.zeros((n, self.model.K, 3))
        Ta = np.zeros((n, self.model.L))
        try:
            super().sample(state, times, F_input, max_steps, Xa, Ua, Ta, diagnostics, advance_first, update_state)
        finally:
            X[...], U[...], T[...] = Xa[:, :K], Ua[:, :K], Ta[:, :L]
            if state.X.shape[0] != K:  # the core's rows handed out: the scene's (_hand_out kept them)
                state.X, state.U = self._out

    def _hand_out(self, X, U) -> None:
        if X.shape[0] != self.K:  # the core's rows (NativeIntegrator.sample's): the scene's handed out
            X, U = X[:self.K].copy(), U[:self.K].copy()
        super()._hand_out(X, U)

    def outputs(self, X, U, F_input=None):
        """(T (L,), the force the network exerts on each of the scene's anchors) at (X, U) (K,3)."""
        T, reaction = self.ground_outputs(X, U, F_input)[:2]
        return T, reaction

    def ground_outputs(self, X, U, F_input=None):
        """(T (L,), the anchors' reactions, the ground's normal force on each contact's mass (n_contacts,)) at (X, U)
        with F_input held, in the mode the state is in (ln_evaluate)."""
        pad = self.model.K - self.K
        X = np.concatenate([np.asarray(X, np.float64), np.zeros((pad, 3))])
        U = np.concatenate([np.asarray(U, np.float64), np.zeros((pad, 3))])
        F = None if F_input is None else np.concatenate([np.asarray(F_input, np.float64), np.zeros((pad, 3))])
        T, reaction = super().outputs(X, U, F)
        return T[:self.L], reaction[:self._n_fixed], T[self.L:self.L + self._n_contacts]

    def rope_impulses(self) -> np.ndarray:
        """(L,) N s: each rope's impulse summed over the last advance (0 on rods)."""
        return self.data.rope_impulse[:self.L].copy()

    def ground_impulses(self) -> np.ndarray:
        """(n_contacts,) N s: the ground's impulse on each contact's mass summed over the last advance."""
        return self.data.rope_impulse[self.L:self.L + self._n_contacts].copy()

    def anchor_jump(self, drive, t: float, X, U, F_input=None):
        pad = self.model.K - self.K
        X = np.concatenate([X, np.zeros((pad, 3))])
        U = np.concatenate([U, np.zeros((pad, 3))])
        F = None if F_input is None else np.concatenate([F_input, np.zeros((pad, 3))])
        Xj, Uj, impulse, dP, dV = super().anchor_jump(drive, t, X, U, F)
        return Xj[:self.K], Uj[:self.K], impulse, dP, dV
