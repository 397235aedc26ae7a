"""The native core as a backend: whole intervals in one call into C (linknet_core.native), on the point-mass path
(static scenes included) or, for a scene of free rigid bodies, on the bodies' path."""
from __future__ import annotations

import contextlib
import functools

import numpy as np

from linknet_core.errors import SolverError
from linknet_core.native.integrator import (NativeGroundIntegrator, NativeIntegrator, core_initial_state,
                                           integrator_method)
from linknet_core.native.model import native_ground_model, native_model
from linknet_core.native.rigid import NativeRigidIntegrator
from linknet_core.simulator.backend import Backend
from linknet_core.simulator.settings import BACKEND_CLASSES
from linknet_core.simulator.specialisation import NONE, RIGID, STATIC, Specialisation, choose_specialisation



class NativeBackend(Backend):
    """The point-mass path: ln_advance, ln_evaluate, ln_sample and the core's interface Jacobians. The native
    advance is all or nothing itself (the core puts its data back on failure); the anchors' hold set for an
    advance or an evaluation is put back here."""

    name = "native"
    reusable = True

    @classmethod
    def choose_specialisation(cls, scene, dyn, settings, U0):
        stepping = settings.stepping
        if scene.unilateral:  # the modes change the links: the point-mass path, event by event
            what = "ropes and ground" if scene.rope.any() and scene.ground is not None else (
                "ropes" if scene.rope.any() else "ground")
            return Specialisation(NONE, f"{what}: the point-mass path, one mode (taut ropes, masses on the ground) "
                                        "at a time"), U0
        specialisation = choose_specialisation(scene, dyn, stepping.method, enabled=settings.specialise,
                                               tolerances=(stepping.rtol, stepping.atol))
        if specialisation.kind == STATIC:
            U0 = np.zeros_like(U0)  # the only velocity (12) allows where nothing can move
        return specialisation, U0

    @classmethod
    def consistent_initial_state(cls, scene, dyn, settings):
        """A rope or ground scene's initial state by the core (ln_rope_initial_state, as the native FMU computes it
        with changed masses or lengths), with the method the run's integrator has, so that the run starts from the
        core's own state."""
        if not scene.unilateral:
            return None, None
        stepping = settings.stepping
        method = integrator_method(stepping.cls, dt=stepping.dt, rtol=stepping.rtol, atol=stepping.atol)
        model = native_ground_model(scene) if scene.ground is not None else native_model(scene, dyn.structure)
        return core_initial_state(model, method, scene.K), ("native", stepping.cls.name, stepping.dt, stepping.rtol,
                                                            stepping.atol)

    @classmethod
    def create(cls, scene, dyn, settings, X0, U0, t0, specialisation) -> "NativeBackend":
        if specialisation.kind == RIGID:
            return NativeRigidBackend.create(scene, dyn, settings, X0, U0, t0, specialisation)
        stepping = settings.stepping
        if scene.ground is not None:  # the contacts as unilateral links to virtual anchors (stages/ropes.c)
            integrator = NativeGroundIntegrator(native_ground_model(scene), scene, stepping.cls, dt=stepping.dt,
                                                rtol=stepping.rtol, atol=stepping.atol, t0=t0)
            return cls(scene, dyn, integrator, (X0, U0))
        integrator = NativeIntegrator(native_model(scene, dyn.structure), stepping.cls, dt=stepping.dt,
                                      rtol=stepping.rtol, atol=stepping.atol, static=specialisation.kind == STATIC,
                                      t0=t0)
        return cls(scene, dyn, integrator, (X0, U0))

    def start(self, state) -> None:
        # reset goes back to a new integrator's internals (NativeIntegrator.reset), which need no copy kept here
        self.integrator.hold(state)

    def reset(self) -> None:
        self.integrator.reset()

    @property
    def rhs_evaluations(self) -> int:
        return self.integrator.rhs_evaluations

    @functools.cached_property
    def samples_in_one_call(self) -> bool:
        return not self.scene.motions  # one motion per driven anchor: those are followed from Python

    @functools.cached_property
    def diagnostics_in_one_call(self) -> bool:
        return self.samples_in_one_call and self.integrator.diagnostics_in_c

    def advance(self, state, t_next, F, hold, max_steps) -> None:
        integrator = self.integrator
        saved = integrator.internals() if hold is not None else None
        try:
            if hold is not None:
                integrator.set_anchors(state.t, hold)
            integrator.advance(state, t_next, F, max_steps)
        except SolverError:
            if saved is not None:
                integrator.set_internals(saved)
            raise

    @contextlib.contextmanager
    def _holding(self, t, hold):
        """The input-driven anchors at ``hold`` (None: as they are) for one evaluation, the internals restored after."""
        integrator = self.integrator
        saved = integrator.internals() if hold is not None else None
        try:
            if hold is not None:
                integrator.set_anchors(t, hold)
            yield integrator
        finally:
            if saved is not None:
                integrator.set_internals(saved)

    def outputs(self, state, F, hold):
        with self._holding(state.t, hold) as integrator:
            return integrator.outputs(state.X, state.U, F)

    def anchor_report(self) -> dict:
        return self.integrator.anchor_report()

    def sample(self, state, times, F, max_steps, X, U, T, diagnostics, advance_first, update_state, T_peak=None,
               T_peak_time=None) -> None:
        self.integrator.sample(state, times, F, max_steps, X, U, T, diagnostics, advance_first, update_state, T_peak,
                               T_peak_time)

    @functools.cached_property
    def locates_peaks(self) -> bool:
        return self.integrator.locates_peaks

    def tension_peaks(self):
        return self.integrator.tension_peaks()

    def linearization(self, state, F, hold):
        from linknet_core.dynamics.interface_jacobian import SceneRowsLinearization
        from linknet_core.native.interface import NativeLinearization

        from linknet_core.dynamics.unilateral import linearization_refusal

        refusal = linearization_refusal(self.scene)
        if refusal:
            raise SolverError(refusal)

        with self._holding(state.t, hold) as integrator:
            try:
                if self.scene.ground is None:
                    return NativeLinearization(integrator.model, integrator.data, state.X, state.U, F)
                # the ground's model: the contacts' virtual anchors after the scene's masses (the core places them
                # from the state), the contacts' links after its links; the scene's rows read back
                pad = np.zeros((integrator.model.K - self.scene.K, 3))
                return SceneRowsLinearization(self.scene, NativeLinearization(
                    integrator.model, integrator.data, np.concatenate([state.X, pad]),
                    np.concatenate([state.U, pad]), None if F is None else np.concatenate([F, pad])),
                    np.arange(self.scene.L))
            except SolverError:
                integrator._raise_motion_error()  # a callable's own failure, where it was one
                raise


class NativeRigidBackend(NativeBackend):
    """The free rigid bodies' path: ln_advance moves the body states (NativeRigidIntegrator). The bodies start from
    the state they were frozen in (projected onto the link lengths if it had to be); a reset restores the body
    states of the start; the outputs' linearization is the numpy reference's (the core's interface Jacobians are
    of the point-mass path); no samples in one call."""

    reusable = False
    samples_in_one_call = False
    diagnostics_in_one_call = False
    start = Backend.start
    reset = Backend.reset
    linearization = Backend.linearization
    tension_peaks = Backend.tension_peaks  # the bodies' steps evaluate no tensions: none located
    locates_peaks = False

    @classmethod
    def create(cls, scene, dyn, settings, X0, U0, t0, specialisation):
        stepping = settings.stepping
        integrator = NativeRigidIntegrator(dyn, specialisation.bodies, stepping.cls, X0, U0, dt=stepping.dt,
                                           rtol=stepping.rtol, atol=stepping.atol)
        return cls(scene, dyn, integrator, integrator.initial_state, list(integrator.notes))


BACKEND_CLASSES["native"] = NativeBackend
