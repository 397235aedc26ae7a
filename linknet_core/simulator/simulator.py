"""Driving a simulation: the stepping interface (used by the FMU) and whole runs (``simulate``)."""
from __future__ import annotations

import copy
import functools
import math
import os
import sys
import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from linknet_core.accuracy import (accuracy_text, error_goal, estimate_failure_text,
                                   position_gap, position_gaps, scene_size, warn_accuracy)
from linknet_core.dynamics.drive import AnchorDrive, anchor_jump, check_step_follows_motions
from linknet_core.dynamics.equations import Dynamics
from linknet_core.dynamics.unilateral import event_arrays, event_counts, scene_dynamics, slack_links
from linknet_core.errors import SceneError, SolverError
from linknet_core.dynamics.forces import kinetic_energy
from linknet_core.integrators import real_number
from linknet_core.simulator import native_backend, numpy_backend  # noqa: F401 (each registers its backend by name)
from linknet_core.simulator.settings import BACKEND_CLASSES, DEFAULT_LENGTH_TOL, RunSettings, run_settings
from linknet_core.simulator.specialisation import STATIC, Specialisation
from linknet_core.structure.topology import kept_per_scene
from linknet_core.scene.description import Scene, load_scene
from linknet_core.state import InitialReport, State

# Snapshots (get_state) name the simulator they come from: this format, the scene's fingerprint, the method and the
# path (backend and specialisation), so set_state refuses another scene's or another path's snapshot rather than
# projecting foreign positions onto this scene's lengths. Raise the number when a snapshot's content changes.
SNAPSHOT_FORMAT = "linknet-snapshot-4"
# Input forces are refused beyond this magnitude (N), as scene values are (scene.description.MAX_MAGNITUDE): the
# solver would overflow on them and report a projection failure that does not name the force.
MAX_FORCE = 1e100


class SimulationInterrupted(KeyboardInterrupt):
    """Ctrl-C during ``simulate``: ``result`` holds the samples computed until then (a KeyboardInterrupt, so a
    caller that does not look for it is interrupted as usual)."""

    def __init__(self, result: "Result"):
        super().__init__(f"interrupted at t = {result.t[-1]:g} s after {result.t.size} samples")
        self.result = result




def prepare_initial_state(scene: Scene, dyn: Dynamics, *, project_positions: bool | None = None,
                          length_tol: float = DEFAULT_LENGTH_TOL, consistent=None):
    """Validate and make consistent the scene's initial state.

    * positions must satisfy every link length (11) to ``length_tol`` relative, unless projection is
      asked for (argument, or ``"options": {"project_initial_positions": true}`` in the scene);
    * velocities are projected onto (12) and the correction is reported;
    * hypothesis (35) is checked: velocities that admit no consistent accelerations are refused; so are velocities
      or loads along a flex held only at second order (Dynamics.check_no_loaded_blocked_flex).

    A scene with ropes or a ground has its own rules (UnilateralDynamics.initial_state: ropes no longer than their
    length, and an inelastic impulse where they are at it), its projection and impact by ``consistent`` where a
    backend gives its own (Backend.consistent_initial_state), else by the numpy reference.
    """
    if scene.unilateral:
        return dyn.initial_state(project_positions=project_positions, length_tol=length_tol, consistent=consistent)
    if project_positions is None:
        project_positions = bool(scene.options.get("project_initial_positions", False))
    X, U = np.array(scene.X0), np.array(scene.U0)
    anchor_acc = None
    if scene.driven.any():  # driven anchors start where and as fast as their motions say (scene time 0)
        P, V, A = scene.anchor_motion(0.0)
        X[scene.driven_indices], U[scene.driven_indices] = P, V
        anchor_acc = np.zeros_like(X)
        anchor_acc[scene.driven_indices] = A
    if scene.L == 0:
        return X, U, InitialReport(0.0, False, 0.0, -1)
    d = X[scene.k2] - X[scene.k1]
    rel = np.abs(np.sqrt(np.einsum("ij,ij->i", d, d)) / scene.length - 1.0)
    worst = float(rel.max())
    projected = False
    if worst > length_tol:
        if not project_positions:
            idx = np.argsort(-rel)[:5]
            listing = "; ".join(
                f"{scene.link_label(int(l))}: distance {np.linalg.norm(d[l]):.6g} m vs length {scene.length[l]:.6g} m"
                for l in idx if rel[l] > length_tol)
            raise SceneError(
                f"{scene.name}: initial positions violate the link lengths by up to {worst:.3g} relative "
                f"(tolerance {length_tol:g}). Worst links: {listing}. Fix the positions or the lengths, or opt in "
                "to projecting them (--project-initial, or \"options\": {\"project_initial_positions\": true}).")
        try:
            X, _ = dyn.project_positions(X, tol=1e-14, max_iter=200)
        except SolverError as exc:
            raise SceneError(f"{scene.name}: the initial positions cannot be projected onto the link lengths: {exc}") from None
        projected = True
    U_projected = dyn.project_velocities(X, U)
    correction = np.linalg.norm(U_projected - U, axis=1)
    worst_mass = int(np.argmax(correction)) if correction.size else -1
    dv = float(correction.max()) if correction.size else 0.0
    if dv <= 1e-14 * max(1.0, float(np.abs(U).max())):
        dv, worst_mass = 0.0, -1
    dyn.check_consistent_velocities(X, U_projected, anchor_acc=anchor_acc)
    dyn.check_no_loaded_blocked_flex(X, U_projected)
    return X, U_projected, InitialReport(worst, projected, dv, worst_mass)


def _kept_initial_state(scene: Scene, dyn: Dynamics, project_positions: bool | None, length_tol: float,
                        consistent=None, consistent_key=None):
    """prepare_initial_state with the scene's own Dynamics, kept per scene object and settings (a scene is
    immutable: a second Simulator of it, an ensemble's member or a reset FMU skips the projections and checks);
    every caller gets its own copies of X and U. A refused state is refused again each time. ``consistent_key``
    names the backend's ``consistent`` (Backend.consistent_initial_state)."""
    X, U, report = kept_per_scene(scene, ("initial state", project_positions, length_tol, dyn.rhs_kernel,
                                          consistent_key),
                                  lambda s: prepare_initial_state(s, dyn, project_positions=project_positions,
                                                                  length_tol=length_tol, consistent=consistent))
    return X.copy(), U.copy(), report


def as_scene(scene) -> Scene:
    """A Scene as given, or the scene file at a path (str or os.PathLike), read by load_scene (whose errors name
    the file and the rule); anything else is refused naming the argument."""
    if isinstance(scene, Scene):
        return scene
    if isinstance(scene, (str, os.PathLike)):
        return load_scene(scene)
    text = repr(scene)
    raise SolverError(f"scene must be a Scene or the path of a scene file (str or os.PathLike), got "
                      f"{type(scene).__name__} {text if len(text) <= 80 else text[:77] + '...'}")


def _setup(scene: Scene, dyn: Dynamics, settings: RunSettings, own_dynamics: bool):
    """What a Simulator's settings decide for its scene before anything is built: the initial state (read-only
    arrays) and its report, the backend and the specialisation. Nothing in it refers to the scene (it is kept per
    scene object and ``settings.setup_key``)."""
    stepping = settings.stepping
    if not stepping.cls.adaptive:
        check_step_follows_motions(scene, stepping.dt)
    # one backend, chosen here before anything is built: the one asked for, the native core by default, the numpy
    # reference where the right-hand side is casadi's (a variant of the numpy Dynamics)
    backend = settings.backend
    chosen = "numpy" if dyn.rhs_kernel != "numpy" else "native" if backend == "auto" else backend
    # a rope or ground scene starts from the state its backend computes (the native core's own on the native one)
    consistent, consistent_key = BACKEND_CLASSES[chosen].consistent_initial_state(scene, dyn, settings)
    if own_dynamics:
        X0, U0, report = _kept_initial_state(scene, dyn, settings.project_initial, settings.length_tol, consistent,
                                             consistent_key)
    else:
        X0, U0, report = prepare_initial_state(scene, dyn, project_positions=settings.project_initial,
                                               length_tol=settings.length_tol, consistent=consistent)
    specialisation, U0 = BACKEND_CLASSES[chosen].choose_specialisation(scene, dyn, settings, U0)
    X0.flags.writeable = U0.flags.writeable = False
    return X0, U0, report, chosen, specialisation


def _as_time(value, what: str) -> float:
    """A time given as any real number (Python or numpy scalar, 0-d array), as a float; refused otherwise."""
    x = real_number(value)
    if x is None:
        raise SolverError(f"{what} must be a real number of seconds, got {value!r} ({type(value).__name__})")
    return x


# _within's sum of squares overflows to inf for entries beyond ~1e154: that is its answer (the caller's slow path
# then names the entry), not something to warn about
warnings.filterwarnings("ignore", message="overflow encountered in dot", category=RuntimeWarning,
                        module=r"linknet_core\.simulator\.simulator")


def _within(a: np.ndarray, bound: float) -> bool:
    """Whether every entry is finite and below ``bound``, in one dot product: the common case of every input
    check (each advance, so each FMU doStep). False may also mean an entry close below the bound: the caller's
    slow path looks entry by entry."""
    v = a.ravel()
    return float(v.dot(v)) <= bound * bound


class Simulator:
    """One scene (a Scene, or the path of a scene file), one integrator, one state: the stepping interface.

    ``advance(t_next, F_input)`` integrates from the current time to ``t_next`` with the input forces
    held constant (zero-order hold), which is exactly what an FMI co-simulation step does.

    The run's settings are one object, ``settings`` (linknet_core.RunSettings, validated once when made; every
    refusal names the setting and its rule), given as ``settings=``, as keywords (``method``, ``dt``, ``rtol``,
    ``atol``, ``project_initial``, ``length_tol``, ``max_steps_per_call``, ``backend``, ``rhs_kernel``,
    ``specialise``, ``error_estimate``: its fields), or both: a keyword that is not None replaces that field of
    ``settings=`` (the result is validated as a whole: ``dt=`` beside settings of an error-controlled method is
    refused as it would be alone). A keyword left at None leaves the field as ``settings=`` has it, or at
    RunSettings' default. ``dynamics`` (a Dynamics of the scene to run on) and ``t0`` (the start time) are not
    settings.

    ``method``: with neither a method nor a step, the error-controlled default (linknet_core.accuracy:
    DEFAULT_METHOD at rtol DEFAULT_RTOL); with a step dt and no method, RATTLE.

    ``specialise`` (default True): a static scene (0 degrees of freedom) or a scene of free rigid bodies
    takes the specialised path of :mod:`linknet_core.simulator.specialisation`, chosen once here and reported in
    ``specialisation`` and ``summary()``; False (or an explicit ``backend`` naming a point-mass loop)
    keeps the point-mass path.

    ``error_estimate`` (default True): a companion simulator (linknet_core.accuracy: half the step, or a tenth of
    the tolerances) is advanced alongside with the same inputs, and ``error_estimate`` holds the estimated largest
    position error (m) at the current time, ``error_goal`` what the run is held to, ``error_note()`` a warning's
    text where the estimate exceeds it. It about doubles the cost of an advance; False skips it.

    ``backend`` names the backend (``BACKEND_CLASSES``; "auto": the native core), chosen once here: ``engine`` is
    its object (linknet_core.simulator.backend.Backend), through which every advance, output, sample and
    linearization goes; ``integrator`` its integrator (statistics, internals).
    """

    def __init__(self, scene: Scene | str | os.PathLike, method: str | None = None, dt: float | None = None,
                 rtol: float | None = None, atol: float | None = None, *, project_initial: bool | None = None,
                 length_tol: float | None = None, max_steps_per_call: int | None = None,
                 dynamics: Dynamics | None = None, backend: str | None = None, rhs_kernel: str | None = None,
                 specialise: bool | None = None, t0: float = 0.0, error_estimate: bool | None = None,
                 settings: RunSettings | None = None):
        scene = as_scene(scene)
        t0 = t0 if type(t0) is float else _as_time(t0, "the start time t0")
        if not math.isfinite(t0):
            raise SolverError(f"the start time t0 must be finite, got {t0!r}")
        settings = run_settings(settings, method=method, dt=dt, rtol=rtol, atol=atol, project_initial=project_initial,
                                length_tol=length_tol, max_steps_per_call=max_steps_per_call, backend=backend,
                                rhs_kernel=rhs_kernel, specialise=specialise, error_estimate=error_estimate)
        stepping = settings.stepping
        self.scene, self.settings = scene, settings
        self.dyn = dynamics or scene_dynamics(scene, rhs_kernel=settings.rhs_kernel)
        self.method = stepping.method
        if dynamics is not None:
            setup = _setup(scene, self.dyn, settings, False)
        else:  # what these settings decide for this scene, decided once per scene object
            setup = kept_per_scene(scene, ("simulator set-up", settings.setup_key),
                                   lambda s: _setup(s, self.dyn, settings, True))
        X0, U0, self.initial_report, self.backend, specialisation = setup
        self.specialisation = Specialisation(specialisation.kind, specialisation.reason, specialisation.bodies,
                                             list(specialisation.notes), specialisation.tolerances)  # its own notes
        # the backend object: everything that depends on how the state is stepped and evaluated
        self.engine = BACKEND_CLASSES[self.backend].create(scene, self.dyn, settings, X0, U0, t0, self.specialisation)
        self.integrator = self.engine.integrator
        X0, U0 = self.engine.initial_state
        self.specialisation.notes.extend(self.engine.notes)
        # the scene is autonomous (no force depends on t), so starting at t0 is the scene's motion shifted in time
        # (the initial arrays are never written into: every advance replaces the state's arrays, and the state
        # handed out is a copy)
        self._initial = State(t0, X0, U0)
        self.max_steps_per_call = settings.max_steps_per_call  # may be changed between advances
        self.state = self._initial.copy()
        self._reset_arrays = (self.state.X, self.state.U)  # the state's arrays as made from the initial state
        self.engine.start(self.state)
        self.error_goal = error_goal(stepping.cls, stepping.rtol, stepping.atol, scene_size(X0))
        self.error_estimate = 0.0
        # tension_peaks: whether the backend locates them, whether the last advance's are still in the backend (taken
        # from it when asked for: a failed advance leaves them there), those taken (None: none located, or no advance
        # yet), the input the last advance held where they are not located, and whether there was an advance; a
        # companion's are never asked for
        self._locates_peaks = self.engine.locates_peaks
        self._peaks_in_engine, self._peaks, self._peak_input, self._advanced = False, None, None, False
        self._track_peaks = True
        self._error_factor, self._companion_failure, self.companion = 1.0, None, None
        if settings.error_estimate and self.specialisation.kind != STATIC:  # nothing moves in a static scene
            rule, companion_settings = settings.companion
            self._error_factor = rule.factor
            self.companion = Simulator(scene, t0=t0, settings=companion_settings)
            self.companion._track_peaks = False
        # what the Dynamics counts (the numpy reference's right-hand sides and projection floor), as reset finds it
        self._initial_counts = (self.dyn.rhs_evaluations, getattr(self.dyn, "floor_stops", 0),
                                getattr(self.dyn, "floor_reached", 0.0))

    @functools.cached_property
    def identity(self) -> dict:
        """What a snapshot of this simulator is checked against: the snapshot format, the scene's fingerprint,
        the method and the path (computed at the first snapshot: hashing the scene costs more than building the
        rest of a small simulator)."""
        return {"format": SNAPSHOT_FORMAT, "scene": self.scene.fingerprint, "method": self.method,
                "path": f"{self.backend} {self.specialisation.kind}"}

    @functools.cached_property
    def run_description(self) -> tuple:
        """(tension solver's structure, right-hand side kernel, notes on the initial state and the specialisation,
        the specialisation in words, whether the scene has driven anchors): what the stats of every run say of this
        simulator (fixed at construction)."""
        return (self.dyn.structure.kind, self.dyn.rhs_kernel,
                tuple(self.initial_report.lines(self.scene) + self.specialisation.notes), self.specialisation.text(),
                bool(self.scene.driven.any()))

    @property
    def rhs_evaluations(self) -> int:
        """Right-hand sides (9) evaluated so far."""
        return self.engine.rhs_evaluations

    # ---- stepping ----------------------------------------------------------------------------
    def check_input(self, F_input) -> np.ndarray | None:
        """Validate an input force array (K,3); rows of anchored masses are ignored. (Runs on every advance, so
        every FMU doStep: the common case costs one dot product.)"""
        if F_input is None:
            return None
        F = F_input if type(F_input) is np.ndarray and F_input.dtype == np.float64 else np.asarray(F_input, float)
        if F.shape != (self.scene.K, 3):
            raise SolverError(f"input forces must have shape ({self.scene.K}, 3), got {F.shape}")
        if _within(F, MAX_FORCE):
            return F
        bad = ~np.isfinite(F) | (np.abs(np.nan_to_num(F)) > MAX_FORCE)
        bad[self.scene.fixed] = False
        if bad.any():
            k, i = np.argwhere(bad)[0]
            rule = "forces must be finite" if not np.isfinite(F[k, i]) else \
                f"forces beyond {MAX_FORCE:g} N would overflow the solver"
            raise SolverError(f"input force F[{k + 1},{i + 1}] on {self.scene.mass_label(int(k))} is {F[k, i]}: {rule}")
        return F

    def _input_note(self, F) -> str:
        """What to add to a solver failure under input forces: the largest one, by name."""
        if F is None:
            return ""
        free = np.where(self.scene.fixed[:, None], 0.0, np.abs(F))
        if not free.any():
            return ""
        k, i = np.unravel_index(int(np.argmax(free)), free.shape)
        return (f" (the largest input force was F[{k + 1},{i + 1}] = {F[k, i]:.6g} N on "
                f"{self.scene.mass_label(int(k))}: a force too large for the step or tolerance fails this way)")

    def check_anchors(self, anchors):
        """Validate the input-driven anchors' motion for an advance: None (keep the last), a callable of t, or
        (P, V, A), each (n_input, 3) with rows the input-driven anchors in scene order (scene.input_driven_indices)."""
        if anchors is None:
            return None
        rows = self.scene.input_driven_indices
        if rows.size == 0:
            raise SolverError(f"{self.scene.name} has no input-driven anchors (a mass with \"driven\": true and "
                              "motion kind \"input\"), so anchors= has nothing to move")
        if callable(anchors):
            return anchors
        if not isinstance(anchors, (tuple, list)) or len(anchors) != 3:
            raise SolverError("anchors must be (P, V, A): position, velocity and acceleration of the input-driven "
                              f"anchors, each of shape ({rows.size}, 3), or a callable f(t) -> (P, V, A)")
        out = []
        for name, unit, value in zip("PVA", ("m", "m/s", "m/s2"), anchors):
            a = value if type(value) is np.ndarray and value.dtype == np.float64 else np.asarray(value, float)
            if a.shape != (rows.size, 3):
                raise SolverError(f"anchors {name} must have shape ({rows.size}, 3) (one row per input-driven anchor: "
                                  f"{', '.join(self.scene.mass_label(int(k)) for k in rows)}), got {a.shape}")
            if _within(a, MAX_FORCE):
                out.append(a)
                continue
            bad = ~np.isfinite(a) | (np.abs(np.nan_to_num(a)) > MAX_FORCE)
            if bad.any():
                i, j = np.argwhere(bad)[0]
                raise SolverError(f"anchor input {name}[{rows[i] + 1},{j + 1}] of {self.scene.mass_label(int(rows[i]))} "
                                  f"is {a[i, j]} {unit}: it must be finite and below {MAX_FORCE:g}")
            out.append(a)
        return tuple(out)

    def advance(self, t_next: float, F_input=None, anchors=None) -> None:
        """Integrate to t_next with F_input held, then the companion (``error_estimate``) with the same inputs. A
        companion that fails leaves the run's result standing and its estimate infinite (``error_note`` says why).
        See :meth:`_advance_run` for the run's own advance."""
        self._advance_run(t_next, F_input, anchors)
        if self.companion is None or self._companion_failure is not None:
            return
        try:
            self._advance_companion(t_next, F_input, anchors)
        except SolverError as exc:
            self._companion_failure = f"at t = {self.companion.state.t:g} s: {exc}"
            self.error_estimate = math.inf
            return
        self.error_estimate = self._error_factor * position_gap(self.state.X, self.companion.state.X)

    def _advance_companion(self, t_next: float, F_input, anchors) -> None:
        """The companion to t_next as the core's rule says (ln_companion_advance): through the interval's midpoint, so
        that it takes twice the run's steps however short the interval (fixed steps), and never the very steps of an
        error-controlled run whose steps the communication points set."""
        companion = self.companion
        t = companion.state.t
        t_mid = t + 0.5 * (float(t_next) - t)
        if t < t_mid < t_next:
            companion._advance_run(t_mid, F_input, anchors)
            anchors = None  # held from the midpoint on as set there
        companion._advance_run(t_next, F_input, anchors)

    def error_note(self) -> str | None:
        """What to warn of: the estimate beyond the goal, or a companion that could not estimate it (None if
        neither)."""
        if self._companion_failure is not None:
            return estimate_failure_text(self.scene.name, self._companion_failure)
        if self.error_estimate > self.error_goal:
            return accuracy_text(self.scene.name, self.state.t, self.error_estimate, self.error_goal)
        return None

    def _advance_run(self, t_next: float, F_input=None, anchors=None) -> None:
        """Integrate the run (not its companion) to t_next with F_input held, on the backend chosen at construction
        (``engine``). ``anchors``: the input-driven anchors' motion from now on, (P, V, A) held as
        P + V s + A s^2/2 (s from the current time), or a callable f(t) -> (P, V, A); None keeps the last. A
        composition's inner stages may call it a little outside [t, t_next] (yoshida8: up to half a step). Where
        the anchors jump (a new V, or P), the velocities are projected onto (12) first: an inelastic impulse,
        reported by ``anchor_report``. On success the state is finite; on any error the simulator is left exactly
        as before the call (state, integrator internals and the anchors' held motion)."""
        F = self.check_input(F_input)
        hold = self.check_anchors(anchors)
        t_next = t_next if type(t_next) is float else _as_time(t_next, "the target time")
        state = self.state
        if not math.isfinite(t_next) or not t_next > state.t:
            raise SolverError(f"cannot advance from t = {state.t} to t = {t_next}: the target must be later "
                              "and finite")
        try:
            self.engine.advance(state, t_next, F, hold, self.max_steps_per_call)
        except SolverError as exc:
            if F is None:
                raise
            raise SolverError(f"{exc}{self._input_note(F)}") from None
        if self._track_peaks:
            self._after_advance(F)

    def _after_advance(self, F) -> None:
        """The last advance's located peaks are the backend's now; where it locates none, the input the advance held
        (a copy: the caller's array may change) is kept, under which tension_peaks evaluates the tensions instead."""
        self._advanced = True
        if self._locates_peaks:
            self._peaks_in_engine = True
        else:
            self._peak_input = None if F is None else F.copy()

    def _taken_peaks(self):
        """The last advance's located peaks, taken from the backend where they still are (None: none located)."""
        if self._peaks_in_engine:
            self._peaks, self._peaks_in_engine = self.engine.tension_peaks(), False
        return self._peaks

    def tension_peaks(self, F_input=None, anchors=None) -> tuple[np.ndarray, np.ndarray]:
        """(T_peak, T_peak_time), (L,) each: over the last advance, each link's largest |T_l| (N), signed (the value
        of T_l there), and when it occurred (s), located between the integrator's accepted steps by the vertex of the
        quadratic through three consecutive step ends' tensions (linknet_core/native/src/tension_peaks.c; the numpy
        reference the same), both ends of the interval counting (at its start, the tensions under the input held over
        it). A tension spike between two advances that the outputs at their ends miss is here. Where the path does
        not locate them (``peaks_located`` False: free rigid bodies, ropes or a ground, a static scene): the
        tensions at the current state under the last advance's input, and the current time; before the first
        advance, under ``F_input`` and ``anchors`` (as ``outputs`` takes them: T itself, as both FMUs report it before
        their first step). Restored with a snapshot (set_state)."""
        peaks = self._taken_peaks()
        if peaks is not None:
            return peaks[0].copy(), peaks[1].copy()
        if self._advanced:
            T, _ = self.engine.outputs(self.state, self._peak_input, None)
        else:
            T, _ = self.engine.outputs(self.state, self.check_input(F_input), self.check_anchors(anchors))
        return T, np.full(self.scene.L, self.state.t)

    @property
    def peaks_located(self) -> bool:
        """Whether tension_peaks holds peaks the last advance located between its steps (False before any advance,
        and on the paths that do not locate them)."""
        return self._peaks_in_engine or self._peaks is not None

    def outputs(self, F_input=None, anchors=None) -> dict:
        """Positions, velocities, tensions (with direct feedthrough of F_input, since B of (26) contains F, and of
        the driven anchors' motion) and the force the network exerts on each anchored mass (fixed and driven, scene
        order). ``anchors``: as for :meth:`advance`, the input-driven anchors' motion to evaluate with (the held one
        is kept); the driven anchors' rows are where their motion is at the current time."""
        F = self.check_input(F_input)
        hold = self.check_anchors(anchors)
        state = self.state
        T, Freact = self.engine.outputs(state, F, hold)
        out = {"t": state.t, "X": state.X.copy(), "U": state.U.copy(), "T": T, "Freact": Freact,
               "error_estimate": self.error_estimate}
        if self.scene.driven.any():
            out["impulse"] = self.anchor_report()["impulse"]
        if self.scene.unilateral:
            out["slack"] = slack_links(self.scene, T)
        return out

    def outputs_after_jump(self, F_input, anchors) -> dict:
        """The outputs as the next advance will start from them once ``anchors`` (as for :meth:`advance`) are held:
        the driven anchors brought to their new motion at the current time and, where they jump, the free masses'
        positions projected onto (11) and velocities onto (12) (the inelastic impulse every advance starts with),
        by the numpy reference on either backend. The simulator's state is not changed: the advance does the same
        jump itself. (simulate's sample at t = 0 of a run whose anchors= set the input-driven anchors' motion.)"""
        F = self.check_input(F_input)
        hold = self.check_anchors(anchors)
        t = self.state.t
        # a drive of its own (scene time 0 is the start time t0): the input-driven anchors follow ``hold``, the others
        # their motions, so nothing of the run's own drive is needed
        drive = AnchorDrive(self.scene, self._initial.t)
        drive.set_input(t, hold)
        if self.scene.unilateral:  # an event of the event integrator, whose mode and events are put back after
            internals = copy.deepcopy(self.integrator.internals())
            try:
                X, U, impulse, _, _ = self.integrator.anchor_jump(drive, t, self.state.X, self.state.U, F)
            finally:
                self.integrator.set_internals(internals)
        else:
            X, U, impulse, _, _ = anchor_jump(self.dyn, drive, t, self.state.X, self.state.U)
        X_at, U_at, anchor_acc = drive.apply(t, X, U)
        T = self.dyn.tensions(X_at, U_at, F, anchor_acc=anchor_acc)
        out = {"t": t, "X": X_at, "U": U_at, "T": T, "Freact": self.dyn.anchor_reactions(X_at, T),
               "error_estimate": self.error_estimate, "impulse": impulse}
        if self.scene.unilateral:
            out["slack"] = slack_links(self.scene, T)
        return out

    def interface_linearization(self, F_input=None, anchors=None):
        """The exact derivatives of what :meth:`outputs` gives (T, Freact) and of the accelerations dU/dt with respect
        to the inputs (the forces F and the input-driven anchors' P, V, A) at the current state, with ``F_input``
        and ``anchors`` taken as :meth:`outputs` takes them (the simulator is left as it was). The state X, U has no
        direct feedthrough. Returns a linearization (linknet_core.dynamics.interface_jacobian): its
        ``directional(dF=, dP=, dV=, dA=)`` is the derivative along one seed (one solve with the factorisation the
        tensions used, where A is regular), its ``jacobian()`` every block by name. The native core computes it on
        the native point-mass path, the numpy reference on the others (docs/interface_jacobians.md)."""
        F = self.check_input(F_input)
        hold = self.check_anchors(anchors)
        return self.engine.linearization(self.state, F, hold)

    def interface_jacobian(self, F_input=None, anchors=None):
        """Every block of :meth:`interface_linearization` at the current state: an InterfaceJacobian, J["T", "F"],
        J["Freact", "A"], ..., and ``effective_mass(j)``, the network's apparent mass at input-driven anchor j."""
        return self.interface_linearization(F_input, anchors).jacobian()

    def sample(self, times, F_input, X: np.ndarray, U: np.ndarray, T: np.ndarray, advance_first: bool = True,
               diagnostics: np.ndarray | None = None, update_state: bool = True, T_peak: np.ndarray | None = None,
               T_peak_time: np.ndarray | None = None) -> None:
        """What ``advance(t_i, F_input)`` then ``outputs(F_input)`` do at each of ``times``, in one call into the
        native core (the point-mass path, no driven anchors: see ``samples_in_one_call``): X[i], U[i], T[i] of each
        sample into X, U (n,K,3) and T (n,L), and, unless ``diagnostics`` is None, its energy, residuals of (11) and
        (12) and kinetic energy into diagnostics[:, i] (4,n) (where ``diagnostics_in_one_call``): the values
        Dynamics.energy, constraint_residual, velocity_residual and dynamics.forces.kinetic_energy give; unless
        ``T_peak`` is None, what tension_peaks gives after each advance into T_peak[i], T_peak_time[i] (n,L) (a
        sample taken without an advance: its T and time; a static scene: T and t, its tensions standing still). Every
        array
        C-contiguous float64, ``times`` too (``diagnostics`` may be columns of one). Sample 0 is taken at the
        current state unless ``advance_first``. On a failure the samples before it are written and the SolverError
        is raised. ``update_state`` False leaves ``state`` as it was (the integrator's internals and counters move
        on): for a run's last call when the simulator is reset before any further use (simulate)."""
        F = self.check_input(F_input)
        t_before = self.state.t
        try:
            self.engine.sample(self.state, times, F, self.max_steps_per_call, X, U, T, diagnostics, advance_first,
                               update_state, T_peak, T_peak_time)
        except SolverError as exc:
            if self._track_peaks and self.state.t != t_before:  # the state of the last sample that went through
                self._after_advance(F)
            if F is None:
                raise
            raise SolverError(f"{exc}{self._input_note(F)}") from None
        if self._track_peaks and (advance_first or len(times) > 1):
            self._after_advance(F)

    @property
    def diagnostics_in_one_call(self) -> bool:
        """Whether ``sample`` can fill the samples' diagnostics too."""
        return self.engine.diagnostics_in_one_call

    @property
    def samples_in_one_call(self) -> bool:
        """Whether ``sample`` is available: the native point-mass path (free rigid bodies and the numpy reference
        step from Python) of a scene without driven anchors (fixed at construction)."""
        return self.engine.samples_in_one_call

    def anchor_report(self) -> dict:
        """What the links gave the driven anchors in impulses over the last advance: "impulse" (n_driven, 3), N s,
        the jump's at its start (the velocities projected onto (12)) and, with ropes or a ground, the impacts' of
        the events in it (a rope jerked taut: C^T Lambda on the anchor's row, Lambda the minimum-norm impulses of
        the links at their length, UnilateralDynamics.anchor_impulses); "jump_impulse", the jump's part alone;
        "jump_position" (m) and "jump_velocity" (m/s), the jump's largest coordinate changes; "jumps", how many
        advances of the run began with one."""
        return self.engine.anchor_report()

    # ---- snapshots ---------------------------------------------------------------------------
    def get_state(self) -> dict:
        """Everything needed to continue bit-identically: time, positions, velocities, integrator internals."""
        return {"identity": dict(self.identity), "state": self.state.copy(),
                "integrator": copy.deepcopy(self.integrator.internals()), "rhs_evaluations": self.dyn.rhs_evaluations,
                "error": (self.error_estimate, self._companion_failure,
                          None if self.companion is None else self.companion.get_state()),
                "peaks": (self._taken_peaks(), self._peak_input, self._advanced)}  # arrays nobody writes into

    def snapshot_problem(self, snapshot) -> str | None:
        """Why ``snapshot`` cannot be restored here (None if it can): not a snapshot, another format, another scene
        (its fingerprint), another method or another path."""
        if not isinstance(snapshot, dict) or not isinstance(snapshot.get("state"), State):
            return f"not a Simulator snapshot (got {type(snapshot).__name__})"
        identity = snapshot.get("identity")
        if not isinstance(identity, dict) or identity.get("format") != SNAPSHOT_FORMAT:
            return (f"a snapshot of format {identity.get('format') if isinstance(identity, dict) else None!r}, "
                    f"not {SNAPSHOT_FORMAT!r}")
        for key, what in (("scene", "another scene (its fingerprint differs: other masses, lengths, topology "
                                    "or initial state)"), ("method", "another method"), ("path", "another path")):
            if identity.get(key) != self.identity[key]:
                return f"a snapshot of {what}: {identity.get(key)!r}, this simulator has {self.identity[key]!r}"
        return None

    def set_state(self, snapshot: dict) -> None:
        """Restore a snapshot of this simulator (get_state); one of another scene, method or path is refused."""
        problem = self.snapshot_problem(snapshot)
        if problem:
            raise SolverError(f"{self.scene.name}: cannot restore {problem}")
        error = snapshot.get("error", (0.0, None, None))
        if (error[2] is None) != (self.companion is None):
            raise SolverError(f"{self.scene.name}: cannot restore a snapshot taken "
                              f"{'without' if error[2] is None else 'with'} an error estimate into a simulator "
                              f"{'with' if error[2] is None else 'without'} one (error_estimate=)")
        self.state = snapshot["state"].copy()
        self.integrator.set_internals(copy.deepcopy(snapshot["integrator"]))
        self.dyn.rhs_evaluations = snapshot.get("rhs_evaluations", self.dyn.rhs_evaluations)
        self.error_estimate, self._companion_failure = error[0], error[1]
        self._peaks, self._peak_input, self._advanced = snapshot["peaks"]
        self._peaks_in_engine = False
        if self.companion is not None:
            self.companion.set_state(error[2])

    def reset(self, state_untouched: bool = False) -> None:
        """Back to the initial state, as a new Simulator of the same settings: state, integrator internals, the
        driven anchors' hold and every counter (steps, right-hand sides, the projection floor's).
        ``state_untouched``: the caller vouches that nothing wrote into the state's arrays since the last reset
        (simulate's pool, whose Simulators nobody else sees): a state that still holds the arrays that reset put
        there, at the initial time, is kept instead of copied again."""
        state, initial = self.state, self._initial
        if not (state_untouched and state.X is self._reset_arrays[0] and state.U is self._reset_arrays[1]
                and state.t == initial.t):
            self.state = state = initial.copy()
            self._reset_arrays = (state.X, state.U)
        self.engine.reset()
        self.dyn.rhs_evaluations, self.dyn.floor_stops, self.dyn.floor_reached = self._initial_counts
        self.error_estimate, self._companion_failure = 0.0, None
        self._peaks_in_engine, self._peaks, self._peak_input, self._advanced = False, None, None, False
        if self.companion is not None:
            self.companion.reset(state_untouched)

    def summary(self) -> str:
        """Scene, method and the specialisation chosen for it (and why)."""
        lines = [f"{self.scene.name}: K={self.scene.K} masses, L={self.scene.L} links, method {self.method}, "
                 f"solver {self.dyn.structure.kind}, backend {self.backend}"
                 + (" (ropes, ground: the numpy reference, event by event)" if self.scene.unilateral
                    and self.backend == "numpy" else ""),
                 f"  specialisation: {self.specialisation.text()}"]
        if self.scene.driven.any():
            lines.append("  driven anchors: " + ", ".join(
                f"{self.scene.mass_label(int(k))} ({motion.kind})"
                for k, motion in zip(self.scene.driven_indices, self.scene.motions)))
        return "\n".join(lines + [f"  note: {n}" for n in self.specialisation.notes])


@dataclass
class Result:
    scene: Scene
    method: str
    t: np.ndarray
    X: np.ndarray
    U: np.ndarray
    T: np.ndarray
    energy: np.ndarray
    residual: np.ndarray  # max relative violation of (11) per sample
    velocity_residual: np.ndarray  # max violation of (12) per sample, m/s
    kinetic: np.ndarray  # kinetic energy per sample
    stats: dict = field(default_factory=dict)
    # the estimated largest position error of any mass per sample, m (linknet_core.accuracy; None: not estimated),
    # the goal it is held to, m, and why it could not be estimated where it could not (its companion run failed)
    error_estimate: np.ndarray | None = None
    error_goal: float = math.nan
    error_failure: str | None = None
    # scenes with ropes or a ground (linknet_core.dynamics.unilateral), None otherwise: which links are slack ropes at
    # each sample (n, L), and the run's events in time order (Event: t, kind, index, impulse)
    slack: np.ndarray | None = None
    events: list | None = None
    # each link's largest |T_l| over each output interval (t[i-1], t[i]], signed, and when (n, L each; row 0: T and t
    # at the start), located between the integrator's steps (Simulator.tension_peaks): a spike between two outputs
    # is here where T misses it. stats["tension_peaks"] says whether they were located or are the sampled T
    T_peak: np.ndarray | None = None
    T_peak_time: np.ndarray | None = None

    @property
    def max_error_estimate(self) -> float:
        """The largest estimated position error over the run, m (nan if not estimated)."""
        return math.nan if self.error_estimate is None else float(np.max(self.error_estimate))

    def accuracy_note(self) -> str | None:
        """What to warn of: the estimate beyond the goal (from when), or a companion run that failed; None if
        neither (or not estimated)."""
        if self.error_failure is not None:
            return estimate_failure_text(self.scene.name, self.error_failure)
        if self.error_estimate is None or not self.max_error_estimate > self.error_goal:
            return None
        first = int(np.argmax(self.error_estimate > self.error_goal))
        return accuracy_text(self.scene.name, float(self.t[first]), float(self.error_estimate[first]),
                             self.error_goal, self.max_error_estimate)

    def largest_peak(self) -> tuple[float, int, float]:
        """(the run's largest tension peak in magnitude, signed, N; its link, 0-based; when, s); (0.0, -1, t_0) for a
        scene without links."""
        if self.T_peak is None or not self.T_peak.size:
            return 0.0, -1, float(self.t[0])
        i, l = np.unravel_index(int(np.argmax(np.abs(self.T_peak))), self.T_peak.shape)
        return float(self.T_peak[i, l]), int(l), float(self.T_peak_time[i, l])

    def _peak_line(self) -> str:
        if self.T_peak is None or not self.T_peak.size:
            return ""
        peak, l, when = self.largest_peak()
        sampled = float(np.max(np.abs(self.T)))
        how = ("between outputs" if self.stats.get("tension_peaks") == "located"
               else "(sampled only: this path does not locate peaks between outputs)")
        return (f"\n  largest tension peak {how} = {peak:.6g} N on {self.scene.link_label(l)} at t = {when:.6g} s "
                f"(largest sampled |T| = {sampled:.6g} N)")

    def _accuracy_line(self) -> str:
        if self.error_estimate is None:
            return "  error estimate: not computed (error_estimate=False)\n"
        note = self.accuracy_note()
        if note is not None:
            return f"  WARNING: {note}\n"
        return (f"  estimated position error = {self.max_error_estimate:.3g} m at most (goal {self.error_goal:.3g} m: "
                "within)\n")

    @property
    def energy_scale(self) -> float:
        """|E(0)| or the largest kinetic energy of the run, whichever is larger (the potential's zero is arbitrary)."""
        return max(abs(float(self.energy[0])), float(np.max(self.kinetic)), 1e-300)

    @property
    def energy_drift(self) -> float:
        """(E(t_end) - E(0)) / energy_scale. Work of input forces, of driven anchors and dissipation show up here
        too."""
        return float(self.energy[-1] - self.energy[0]) / self.energy_scale

    def save_npz(self, path) -> None:
        """Write the run's arrays to ``path`` (.npz) whole or not at all (``linknet_core.output.atomic_write``):
        a failure raises ``WriteError`` naming the file and leaves what was there before."""
        from linknet_core.output import atomic_write

        atomic_write(path, lambda tmp: np.savez_compressed(
            tmp, t=self.t, X=self.X, U=self.U, T=self.T, energy=self.energy, residual=self.residual,
            **({} if self.T_peak is None else dict(T_peak=self.T_peak, T_peak_time=self.T_peak_time)),
            velocity_residual=self.velocity_residual, mass_names=np.array(self.scene.mass_names),
            k1=self.scene.k1 + 1, k2=self.scene.k2 + 1, fixed=self.scene.fixed, method=self.method,
            **({} if self.slack is None else dict(slack=self.slack, **event_arrays(self.events, self.scene.ground)))))

    def summary(self) -> str:
        s = self.stats
        return (f"{self.scene.name}: K={self.scene.K} masses, L={self.scene.L} links, solver {s.get('structure')}, "
                f"method {self.method}\n"
                f"  specialisation: {s.get('specialisation', 'none')}\n"
                f"  t_end = {self.t[-1]:g} s, steps = {s.get('steps')} (rejected {s.get('rejected', 0)}), "
                f"wall time = {s.get('wall_time', 0):.3f} s\n"
                + (f"  {s['split']} steps split into equal sub-steps where the position stage did not converge at "
                   f"full length (finest: {s['finest_split']} sub-steps)\n" if s.get("split") else "")
                + (f"  driven anchors: {s['anchor_jumps']} jumps of their input motion (velocities projected onto (12): "
                   "an inelastic impulse each)\n" if s.get("anchor_jumps") else "")
                + (f"  {s['floor_stops']} position projections stopped at the round-off floor the conditioning "
                   f"allows, above the tolerance (largest residual there {s['floor_reached']:.3g} relative)\n"
                   if s.get("floor_stops") else "")
                + ("  events: " + ", ".join(f"{n} {kind}" for kind, n in event_counts(self.events).items()) + "\n"
                   if self.events is not None else "")
                + self._accuracy_line()
                + f"  final energy drift = {self.energy_drift:.3e} (relative), max constraint residual = "
                f"{float(self.residual.max()):.3e} (relative), max velocity residual = "
                f"{float(self.velocity_residual.max()):.3e} m/s\n"
                f"  max tension = {float(np.max(self.T)) if self.T.size else 0.0:.6g} N, "
                f"min tension = {float(np.min(self.T)) if self.T.size else 0.0:.6g} N" + self._peak_line())


def simulate(scene: Scene | str | os.PathLike, t_end: float, method: str | None = None, dt: float | None = None,
             rtol: float | None = None, atol: float | None = None, n_out: int | None = None,
             output_dt: float | None = None, forces=None, progress: bool | None = None,
             project_initial: bool | None = None, backend: str | None = None, rhs_kernel: str | None = None,
             specialise: bool | None = None, motions: dict | None = None, anchors=None,
             error_estimate: bool | None = None, *, settings: RunSettings | None = None) -> Result:
    """Simulate ``scene`` (a Scene, or the path of a scene file) from t = 0 to ``t_end``.

    ``forces``: None, a (K,3) array held constant, or a callable ``f(t) -> (K,3)`` evaluated at each
    output time and held until the next (piecewise constant, as an FMI master does). Outputs are taken
    at ``n_out`` equally spaced times (default 201) or every ``output_dt``.

    Driven anchors: ``motions`` gives anchors (name or 1-based index) a motion as the scene file writes it
    (``{"kind": "sine", ...}``, see linknet_core.scene.motion), replacing the scene's; ``anchors`` moves the
    input-driven ones: a callable ``f(t) -> (P, V, A)`` followed wherever the integrator needs it, or (P, V, A)
    held as P + V t + A t^2/2 from t = 0.

    ``method``: with neither a method nor a step, the error-controlled default (linknet_core.accuracy); with a step
    dt and no method, RATTLE. ``error_estimate`` (default True): the run is repeated by its companion (half the step,
    or a tenth of the tolerances) over the same outputs, with the same inputs (a ``forces`` callable is called by
    both runs), and ``Result.error_estimate`` holds the estimated position error of every sample; an estimate beyond
    the run's goal is reported by an AccuracyWarning and in the summary. False skips the companion.

    The run's settings: ``settings=`` (linknet_core.RunSettings, which also holds ``length_tol`` and
    ``max_steps_per_call``) and/or the keywords that are its fields (``method``, ``dt``, ``rtol``, ``atol``,
    ``project_initial``, ``backend``, ``rhs_kernel``, ``specialise``, ``error_estimate``), a keyword that is not
    None replacing that field, as for :class:`Simulator`.
    """
    scene = as_scene(scene)
    t_end_value = t_end if type(t_end) is float else real_number(t_end)
    if t_end_value is None or not (math.isfinite(t_end_value) and t_end_value > 0):
        raise SolverError(f"t_end must be a positive finite time, got {t_end!r}")
    t_end = t_end_value
    if n_out is not None and not (type(n_out) is int and n_out >= 2) and (
            isinstance(n_out, bool) or not isinstance(n_out, (int, np.integer)) or n_out < 2):
        raise SolverError(f"n_out must be a whole number >= 2 (the samples at 0 and t_end at least), got {n_out!r}")
    if output_dt is not None:
        output_dt_value = output_dt if type(output_dt) is float else real_number(output_dt)
        if output_dt_value is None or not (math.isfinite(output_dt_value) and output_dt_value > 0):
            raise SolverError(f"output_dt must be a positive finite time, got {output_dt!r}")
        output_dt = output_dt_value
    settings = run_settings(settings, method=method, dt=dt, rtol=rtol, atol=atol, project_initial=project_initial,
                            backend=backend, rhs_kernel=rhs_kernel, specialise=specialise,
                            error_estimate=error_estimate)
    stepping = settings.stepping  # the run's stats name the settings used, defaults too
    if motions:
        scene = scene.with_motions(motions)
    # the error estimate's companion is a run of its own below, so that it samples in C too: the run's Simulator
    # has none
    run = settings.with_changes(error_estimate=False) if settings.error_estimate else settings
    # a Simulator of an earlier run of this scene object and these settings, reset, or a new one; handed back to
    # the scene's pool when the run ends, however it ends
    pool_key = None if motions else run
    sim = _take_pooled(scene, pool_key)
    if sim is None:
        sim = Simulator(scene, settings=run)
    try:
        result = _run(sim, scene, t_end, stepping.method, stepping.dt, stepping.rtol, n_out, output_dt, forces,
                      progress, anchors)
        goal, static = sim.error_goal, sim.specialisation.kind == STATIC
    finally:
        if pool_key is not None and sim.engine.reusable:
            _hand_back(scene, pool_key, sim)
    result.error_goal = goal
    if not settings.error_estimate:
        return result
    if static:  # nothing moves: no error
        result.error_estimate = np.zeros(result.t.size)
        return result
    shadow_settings, shadow_run = settings.companion
    # the companion samples every output interval's midpoint too (ln_companion_advance); the midpoints of linspace's
    # times are those of twice as many, exactly
    n_shadow = 2 * result.t.size - 1
    shadow_forces = forces
    if callable(forces):  # the input of each output interval, held over both its halves
        shadow_forces = lambda t: forces(float(result.t[min(int(np.searchsorted(result.t, t, "right")) - 1,  # noqa
                                                             result.t.size - 1)]))
    try:
        shadow = simulate(scene, t_end, n_out=n_shadow, forces=shadow_forces, progress=False, motions=motions,
                          anchors=anchors, settings=shadow_run)
    except SolverError as exc:
        result.error_estimate = np.full(result.t.size, math.inf)
        result.error_estimate[0] = 0.0
        result.error_failure = f"({_companion_words(shadow_settings)}): {exc}"
    except KeyboardInterrupt:  # the run itself is complete: hand it over, without an estimate
        raise SimulationInterrupted(result) from None
    else:
        shadow_X = shadow.X[::2]
        result.error_estimate = shadow_settings.factor * position_gaps(result.X, shadow_X)
        result.stats["companion_steps"] = shadow.stats.get("steps")
    note = result.accuracy_note()
    if note is not None:
        warn_accuracy(note)
    return result


def _companion_words(settings) -> str:
    return f"dt {settings.dt:g}" if settings.dt is not None else f"rtol {settings.rtol:g}, atol {settings.atol:g}"


class _SimulatorPool(dict):
    """Simulators that simulate has finished with, per settings key, kept on their scene object (so they live as
    long as it: the cycle scene -> pool -> Simulator -> scene is the garbage collector's to free). A copy or a
    pickle of the scene gets an empty pool: Simulators hold the native core's memory."""

    def __reduce__(self):
        return _SimulatorPool, ()

    def __copy__(self):
        return _SimulatorPool()

    def __deepcopy__(self, memo):
        return _SimulatorPool()


_POOL_ATTRIBUTE = "_simulate_pool"
_POOL_SIZE = 2  # Simulators kept per scene and settings (more only while as many runs of them are under way)


def _take_pooled(scene: Scene, key) -> Simulator | None:
    """A pooled Simulator of ``scene`` and ``key``, reset to its initial state and taken out of the pool (a run in
    another thread, or one nested in a forces callable, builds its own), or None."""
    if key is None:
        return None
    pool = scene.__dict__.get(_POOL_ATTRIBUTE)
    kept = pool.get(key) if pool is not None else None
    try:
        sim = kept.pop() if kept else None
    except IndexError:  # another thread took the last one
        return None
    if sim is not None:
        sim.reset(state_untouched=True)
    return sim


def _hand_back(scene: Scene, key, sim: Simulator) -> None:
    pool = scene.__dict__.get(_POOL_ATTRIBUTE)
    if pool is None:
        pool = _SimulatorPool()
        object.__setattr__(scene, _POOL_ATTRIBUTE, pool)  # a frozen dataclass: its fields are not touched
    kept = pool.setdefault(key, [])
    if len(kept) < _POOL_SIZE:
        kept.append(sim)


def _run(sim: Simulator, scene: Scene, t_end: float, method, dt, rtol, n_out, output_dt, forces, progress,
         anchors) -> Result:
    """simulate's run on ``sim`` (at its initial state), its arguments but the scene's checked."""
    anchor_hold = sim.check_anchors(anchors)
    if output_dt is not None:
        times = _output_times(t_end, max(1, int(round(t_end / output_dt))) + 1)
    else:
        times = _output_times(t_end, 201 if n_out is None else int(n_out))
    if callable(forces):
        def force_at(t):
            return _forces_value(forces(t), scene.K, t)
    else:
        constant = None if forces is None else _forces_value(forces, scene.K)
        force_at = lambda t: constant  # noqa: E731
    n = times.size
    K, L = scene.K, scene.L
    X = np.empty((n, K, 3))
    U = np.empty((n, K, 3))
    T = np.empty((n, L))
    T_peak, T_peak_time = np.empty((n, L)), np.empty((n, L))
    slack = np.empty((n, L), bool) if scene.unilateral else None
    in_one_call = not callable(forces) and sim.samples_in_one_call
    # the samples' diagnostics from the native core as it samples, where it can: one row per quantity (energy,
    # residual of (11), of (12), kinetic energy), as the result holds them
    diagnostics = np.empty((4, n)) if in_one_call and sim.diagnostics_in_one_call else None
    # progress on stderr: always with progress=True, never with False; by default (None) on a terminal once the run
    # has taken a second
    auto = progress is None
    show = None if auto else bool(progress)
    drawn = False
    start = time.perf_counter()
    last_print = start
    done = 0
    try:
        if in_one_call:
            # a held input and nothing else called from Python per sample: the samples in calls into C of about a
            # tenth of a second each (the first takes samples 0 and 1, one output interval, as the loop below
            # does between two looks at Ctrl-C), so that Ctrl-C and the progress bar are answered as promptly as
            # sample by sample
            F = force_at(0.0)
            chunk = 2
            while done < n:
                stop = min(n, done + chunk)
                # the run's last call leaves sim.state alone: nothing reads it (sim is dropped, or reset when
                # pooled), and a state that reset made and nothing replaced is not copied again there
                if stop - done == n:  # the whole run in one call (two samples)
                    sim.sample(times, F, X, U, T, advance_first=False, diagnostics=diagnostics, update_state=False,
                               T_peak=T_peak, T_peak_time=T_peak_time)
                else:
                    sim.sample(times[done:stop], F, X[done:stop], U[done:stop], T[done:stop], advance_first=done > 0,
                               diagnostics=None if diagnostics is None else diagnostics[:, done:stop],
                               update_state=stop < n, T_peak=T_peak[done:stop], T_peak_time=T_peak_time[done:stop])
                done = stop
                now = time.perf_counter()
                if now - start > 1.0 and show is None:
                    show = sys.stderr.isatty()
                if show and (not auto or now - start > 1.0):
                    _progress_bar(done, n, now - start)
                    drawn, last_print = True, now
                if done < n:
                    chunk = max(1, int(0.1 * done / max(now - start, 1e-9)))
        if done < n and show is None:
            show = sys.stderr.isatty()
        for i in range(done, n):
            t = times[i]
            if i > 0:
                sim.advance(t, force_at(times[i - 1]), anchor_hold if i == 1 else None)
            # tensions feel the input directly: report them with the input of the step starting at t_i,
            # and at the last sample with the input of the step that ended there; at t = 0 with the anchors' motion
            # the run starts with, after the jump to it that the first advance makes
            if i == 0 and anchor_hold is not None:
                out = sim.outputs_after_jump(force_at(times[0]), anchor_hold)
            else:
                out = sim.outputs(force_at(times[min(i, n - 2)]))
            X[i], U[i], T[i] = out["X"], out["U"], out["T"]
            if i == 0:
                T_peak[0], T_peak_time[0] = T[0], t
            else:  # over the interval just advanced, under its input
                T_peak[i], T_peak_time[i] = sim.tension_peaks()
            if slack is not None:
                slack[i] = out["slack"]
            done = i + 1
            now = time.perf_counter()
            if show and (not auto or now - start > 1.0) and (now - last_print > 0.2 or i == n - 1):
                _progress_bar(i + 1, n, now - start)
                drawn, last_print = True, now
    except KeyboardInterrupt:
        if drawn:
            sys.stderr.write("\n")
        if done == 0:
            raise
        wall = time.perf_counter() - start
        stats = _run_stats(sim, method, dt, rtol, scene, wall)
        stats["interrupted"] = True
        part = slice(0, done)
        raise SimulationInterrupted(_with_events(sim, slack, part, Result(
            scene, method, times[part], X[part], U[part], T[part],
            *_diagnostics(sim, X[part], U[part], None if diagnostics is None else diagnostics[:, part]),
            stats, T_peak=T_peak[part], T_peak_time=T_peak_time[part]))) from None
    wall = time.perf_counter() - start
    if drawn:
        sys.stderr.write("\n")
    stats = _run_stats(sim, method, dt, rtol, scene, wall)
    return _with_events(sim, slack, slice(None), Result(scene, method, times, X, U, T,
                                                        *_diagnostics(sim, X, U, diagnostics), stats, T_peak=T_peak,
                                                        T_peak_time=T_peak_time))


def _with_events(sim, slack, part, result: Result) -> Result:
    """The result with the slack ropes of its samples and the run's events, for a scene with ropes or a ground. The
    slack flags follow from the samples' tensions (slack_links), as every sample's outputs give them: the samples
    taken in one call into the native core fill no ``slack`` of their own."""
    if slack is not None:
        result.slack, result.events = slack_links(sim.scene, result.T), list(sim.integrator.events)
    return result


def _forces_value(value, K: int, t=None) -> np.ndarray:
    """simulate's ``forces`` (t None) or what its callable returned when called at ``t``, as a (K,3) array of real
    numbers; anything else is a SolverError naming ``forces``, the value and the rule (a callable returning None is
    refused: None as ``forces`` itself means no input, a return of None is more likely a missing ``return``)."""
    if type(value) is np.ndarray and value.dtype == np.float64 and value.shape == (K, 3):
        return value
    rule = f"forces must be None, a ({K}, 3) array of real numbers, or a callable f(t) returning one"
    what = "forces" if t is None else f"forces(t) called at t = {float(t)!r} returned"
    shown = " ".join(repr(value).split())
    shown = shown if len(shown) <= 80 else shown[:77] + "..."
    kind = type(value).__name__
    if value is None:  # only a callable's return reaches here with None
        raise SolverError(f"{what} None: {rule} (return np.zeros(({K}, 3)) for no input)")
    if isinstance(value, (str, bytes)):
        raise SolverError(f"{what} {shown} (a {kind}): {rule}")
    try:
        F = np.asarray(value, float)
    except (TypeError, ValueError):
        raise SolverError(f"{what} {shown} (a {kind}), which is not an array of real numbers: {rule}") from None
    if F.shape != (K, 3):
        raise SolverError(f"{what} an array of shape {F.shape}: {rule}")
    return F


def _output_times(t_end: float, n: int) -> np.ndarray:
    """np.linspace(0.0, t_end, n), n >= 2, computed as linspace does (i * (t_end / (n - 1)), the last t_end) in a
    fraction of its time (a fixed cost of every run); linspace itself where that step underflows to 0."""
    if n == 2:  # linspace's too: 0, then the last exactly t_end
        return np.array((0.0, t_end))
    step = t_end / (n - 1)
    if step == 0.0:
        return np.linspace(0.0, t_end, n)
    times = np.arange(n, dtype=np.float64)
    times *= step
    times[-1] = t_end
    return times


def _diagnostics(sim, X: np.ndarray, U: np.ndarray, from_core: np.ndarray | None):
    """(energy, residual of (11), residual of (12), kinetic energy) of every sample of a run: the native core's
    rows (4,n), where it filled them as it sampled, or the numpy reference's."""
    if from_core is None:
        return _sample_diagnostics(sim.dyn, X, U)
    return from_core[0], from_core[1], from_core[2], from_core[3]


def _sample_diagnostics(dyn: Dynamics, X: np.ndarray, U: np.ndarray):
    """(energy, residual of (11), residual of (12), kinetic energy) of every sample of a run, X and U (n,K,3): array
    code over all samples at once, each sample's value the same as computed alone."""
    return (dyn.energy(X, U), dyn.constraint_residual(X), dyn.velocity_residual(X, U),
            kinetic_energy(dyn.scene, U))


def _run_stats(sim, method, dt, rtol, scene, wall) -> dict:
    structure, rhs_kernel, initial, specialisation, driven = sim.run_description
    stats = sim.integrator.stats.as_dict()
    if driven:
        stats["anchor_jumps"] = sim.anchor_report()["jumps"]
    stats["wall_time"], stats["rhs_evaluations"] = wall, sim.rhs_evaluations
    stats["floor_stops"], stats["floor_reached"] = sim.integrator.projection_floor()
    stats["structure"], stats["method"], stats["dt"], stats["rtol"] = structure, method, dt, rtol
    stats["rhs_kernel"], stats["initial"], stats["specialisation"] = rhs_kernel, list(initial), specialisation
    stats["tension_peaks"] = "located" if sim.peaks_located else "sampled"
    return stats


def _progress_bar(done: int, total: int, elapsed: float) -> None:
    width = 30
    frac = done / total
    eta = elapsed / frac - elapsed if frac > 0 else 0.0
    bar = "#" * int(width * frac) + "-" * (width - int(width * frac))
    sys.stderr.write(f"\r[{bar}] {100 * frac:5.1f}%  {elapsed:6.1f} s elapsed, ~{eta:5.1f} s left")
    sys.stderr.flush()
