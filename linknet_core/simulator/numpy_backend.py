"""The numpy reference as a backend: linknet_core.integrators on dynamics.Dynamics (or its casadi right-hand side),
stepped from Python, with the driven anchors' jump done here before each advance."""
from __future__ import annotations

import math

import numpy as np

from linknet_core.dynamics.drive import AnchorDrive
from linknet_core.errors import SolverError
from linknet_core.integrators import make_integrator
from linknet_core.simulator.backend import Backend
from linknet_core.simulator.settings import BACKEND_CLASSES


def all_finite(*arrays: np.ndarray) -> bool:
    """Whether every entry is finite and below ~1e154, in one dot product per array: a sum of squares is
    non-finite iff an entry is non-finite or beyond ~1e154, which is no physical state or force either. For the
    state after every advance: ~0.8 us for X and U against ~2.3 us for two isfinite passes."""
    total = 0.0
    for a in arrays:
        v = a.ravel()
        total += float(v.dot(v))
    return math.isfinite(total)


class NumpyBackend(Backend):
    name = "numpy"
    # a reset (Backend.reset: the integrator's internals, the drive's hold and the events' mode as at the start;
    # Simulator.reset: the state and the Dynamics' counters) leaves nothing of the last run that the next one reads:
    # the Dynamics keeps only the factorisation of A at the last configuration it factored, a function of that
    # configuration alone. What the pool saves: docs/architecture.md
    reusable = True

    @classmethod
    def create(cls, scene, dyn, settings, X0, U0, t0, specialisation) -> "NumpyBackend":
        stepping = settings.stepping
        integrator = make_integrator(stepping.method, dyn, dt=stepping.dt, rtol=stepping.rtol, atol=stepping.atol)
        if scene.motions:
            integrator.drive = AnchorDrive(scene, t0)
        backend = cls(scene, dyn, integrator, (X0, U0))
        backend.drive = integrator.drive
        return backend

    def advance(self, state, t_next, F, hold, max_steps) -> None:
        t_before = state.t
        # The integrators never write into the state's arrays, they replace them (tests/core/test_core_validation.py
        # checks every path), so keeping references is the snapshot: copying cost ~1 us per call. Nor does a
        # later call write into what internals() hands out.
        X_before, U_before, internals = state.X, state.U, self.integrator.internals()
        peaks = self.integrator.peaks  # its arrays are replaced, never written into: the references are the snapshot
        peaks_before = peaks.peak, peaks.time
        drive = self.drive
        try:
            if drive is not None:
                if hold is not None:
                    drive.set_input(t_before, hold)
                state.X, state.U, *drive.last_jump = self.integrator.anchor_jump(drive, t_before, state.X, state.U, F)
                drive.jumps += drive.last_jump[1] > 0 or drive.last_jump[2] > 0
                drive.advance_impulse = drive.last_jump[0].copy()  # the advance's events add theirs
            self.integrator.advance(state, t_next, F, max_steps)
            if not all_finite(state.X, state.U):
                raise SolverError(f"the state became non-finite between t = {t_before} and t = {t_next} "
                                  f"(largest |X| {np.abs(state.X).max()} m); reduce the step or tolerance")
        except Exception:
            # leave the simulator where it was, so a caller can retry with other settings
            state.t, state.X, state.U = t_before, X_before, U_before
            self.integrator.set_internals(internals)
            peaks.peak, peaks.time = peaks_before
            raise

    def outputs(self, state, F, hold):
        X_at, U_at, anchor_acc = self.anchors_now(state.t, state.X, state.U, hold)
        T = self.dyn.tensions(X_at, U_at, F, anchor_acc=anchor_acc)
        return T, self.dyn.anchor_reactions(X_at, T)

    @property
    def locates_peaks(self) -> bool:
        return self.integrator.peaks.located  # not the event-driven methods of ropes and a ground

    def tension_peaks(self):
        peaks = self.integrator.peaks
        if not peaks.located or peaks.peak is None:
            return None
        return peaks.peak.copy(), peaks.time.copy()

    def anchor_report(self) -> dict:
        impulse, jump_position, jump_velocity = self.drive.last_jump
        return {"impulse": self.drive.advance_impulse.copy(), "jump_impulse": impulse.copy(),
                "jump_position": jump_position, "jump_velocity": jump_velocity, "jumps": self.drive.jumps}


BACKEND_CLASSES["numpy"] = NumpyBackend
