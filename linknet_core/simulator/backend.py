"""The one interface between the Simulator and a backend: what a backend provides, and what the backends share.

A backend is chosen once per Simulator, by name (``Simulator(backend=)``, a field of the run's settings: the names are
``simulator.settings.BACKEND_CLASSES``), and built once by its class's :meth:`Backend.create` from the run's
settings (``simulator.settings.RunSettings``, one object). The Simulator then calls only this interface: it validates
the arguments (input forces, the anchors' motion, the target time), adds the input forces' note to a failure, keeps
the snapshots' identity and the error estimate's companion; everything that depends on how the state is stepped
and evaluated lives in the backend's own module:

* ``simulator.numpy_backend``: the numpy reference (``linknet_core.integrators`` on ``dynamics.Dynamics``);
* ``simulator.native_backend``: the native core, on the point-mass path (static scenes included) or on the free
  rigid bodies' path.

A new backend is a subclass in a module of its own and its name in ``simulator.settings.BACKEND_CLASSES``.
"""
from __future__ import annotations

import copy
from typing import TYPE_CHECKING

import numpy as np

from linknet_core.dynamics.equations import Dynamics
from linknet_core.errors import SolverError
from linknet_core.scene.description import Scene
from linknet_core.simulator.specialisation import Specialisation, choose_specialisation
from linknet_core.state import State

if TYPE_CHECKING:
    from linknet_core.simulator.settings import RunSettings


class Backend:
    """How one Simulator's state is stepped and evaluated. ``integrator`` is what ``Simulator.integrator`` shows
    (its ``stats``, ``projection_floor()``, ``internals()`` and ``set_internals()``, the snapshots' content).

    The defaults here are the numpy reference's ways, which a backend keeps where it has nothing better: the
    outputs' linearization by the reference (``linearization``), a reset to a deep copy of the internals the
    integrator had at the start (``start``, ``reset``), no samples in one call."""

    name = "abstract"
    # what simulate may ask for: samples of a held input in one call (sample), with their diagnostics
    samples_in_one_call = False
    diagnostics_in_one_call = False
    # whether simulate may keep the Simulator after a run, to reset and reuse it for the next run of the same scene
    # and settings
    reusable = False
    # whether the advances locate tension peaks between their steps (tension_peaks)
    locates_peaks = False
    drive = None  # the driven anchors' motion the numpy reference evaluates with (dynamics.drive.AnchorDrive)

    def __init__(self, scene: Scene, dyn: Dynamics, integrator, initial_state: tuple, notes: list | None = None):
        self.scene, self.dyn, self.integrator = scene, dyn, integrator
        self.initial_state = initial_state  # (X0, U0) the run starts from (the backend may have refined them)
        self.notes = notes or []  # what the backend did to the initial state, for the specialisation's report
        self._initial_internals = None

    @classmethod
    def choose_specialisation(cls, scene: Scene, dyn: Dynamics, settings: "RunSettings",
                              U0: np.ndarray) -> tuple[Specialisation, np.ndarray]:
        """The path this backend takes for ``scene`` (linknet_core.simulator.specialisation) with ``settings`` and
        the initial velocities on it: decided once per scene and settings, before anything is built. The reference
        takes the point-mass path always."""
        return choose_specialisation(scene, dyn, settings.stepping.method, enabled=False), U0

    @classmethod
    def consistent_initial_state(cls, scene: Scene, dyn: Dynamics, settings: "RunSettings"):
        """How this backend makes a rope or ground scene's initial positions and velocities consistent, as
        UnilateralDynamics.initial_state takes it (``consistent``), and a key naming it for the kept initial states;
        (None, None): the numpy reference's own."""
        return None, None

    @classmethod
    def create(cls, scene: Scene, dyn: Dynamics, settings: "RunSettings", X0: np.ndarray, U0: np.ndarray, t0: float,
               specialisation: Specialisation) -> "Backend":
        """The backend of one Simulator: its integrator for ``settings.stepping`` (the method, its class and the
        validated dt, rtol, atol) on ``specialisation``'s path, starting at (t0, X0, U0)."""
        raise NotImplementedError

    # ---- the run's start and reset --------------------------------------------------------------
    def start(self, state: State) -> None:
        """The Simulator's initial state is ``state`` (its own arrays): what reset goes back to."""
        self._initial_internals = copy.deepcopy(self.integrator.internals())

    def reset(self) -> None:
        """The integrator's internals (counters, step size, the anchors' hold) back to those at ``start``."""
        self.integrator.set_internals(copy.deepcopy(self._initial_internals))

    @property
    def rhs_evaluations(self) -> int:
        """Right-hand sides (9) evaluated so far."""
        return self.dyn.rhs_evaluations

    # ---- stepping and evaluating ----------------------------------------------------------------
    def advance(self, state: State, t_next: float, F: np.ndarray | None, hold, max_steps: int) -> None:
        """``state`` to ``t_next`` (later than state.t and finite: the Simulator checked it) with the input forces F
        held and the input-driven anchors' motion ``hold`` from now on (None: keep the last), all or nothing: on
        any error the state, the integrator's internals and the anchors' hold are as before the call. A failure of
        the integration is a SolverError saying why."""
        raise NotImplementedError

    def outputs(self, state: State, F: np.ndarray | None, hold) -> tuple[np.ndarray, np.ndarray]:
        """(T, the force of the network on each anchor) at ``state`` with F held (direct feedthrough) and the
        driven anchors where their motion, or ``hold`` (then only for this evaluation), has them now."""
        raise NotImplementedError

    def anchor_report(self) -> dict:
        """The driven anchors' jump at the start of the last advance (Simulator.anchor_report)."""
        raise NotImplementedError

    def sample(self, state: State, times, F, max_steps: int, X, U, T, diagnostics, advance_first: bool,
               update_state: bool, T_peak=None, T_peak_time=None) -> None:
        """Simulator.sample, where ``samples_in_one_call``."""
        raise SolverError(f"the {self.name} backend does not sample in one call (samples_in_one_call is False)")

    def tension_peaks(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(T_peak, T_peak_time), (L,) each, of the last advance: each link's largest |T_l| over it, signed, and when,
        located between the accepted steps' ends (linknet_core/native/src/tension_peaks.c says how); None where the
        backend's path does not locate them (``locates_peaks``). A failed advance leaves those of the last one that
        went through."""
        return None

    def linearization(self, state: State, F: np.ndarray | None, hold):
        """The outputs' linearization at ``state`` (Simulator.interface_linearization), here by the numpy
        reference at the state the outputs are evaluated at."""
        from linknet_core.dynamics.interface_jacobian import ModeLinearization, ReferenceLinearization
        from linknet_core.dynamics.unilateral import linearization_refusal

        refusal = linearization_refusal(self.scene)
        if refusal:
            raise SolverError(refusal)
        X_at, U_at, anchor_acc = self.anchors_now(state.t, state.X, state.U, hold)
        if self.scene.unilateral:  # ropes, a ground: within the mode the outputs are evaluated in
            return ModeLinearization(self.dyn, X_at, U_at, F, anchor_acc)
        return ReferenceLinearization(self.dyn, X_at, U_at, F, anchor_acc)

    def anchors_now(self, t: float, X: np.ndarray, U: np.ndarray, hold):
        """X, U with the driven anchors' rows where their motion (or the held input ``hold``) has them at t, and
        their accelerations (None without driven anchors): the state the numpy reference evaluates outputs at, as
        the native core does; the drive's own internals are left as they were."""
        drive = self.drive
        if drive is None:
            return X, U, None
        saved = drive.internals()
        try:
            if hold is not None:
                drive.set_input(t, hold)
            return drive.apply(t, X, U)
        finally:
            drive.set_internals(saved)
