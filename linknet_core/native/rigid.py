"""The free-rigid-body part of the native core (src/rigid.h, src/engine_rigid.c) as Python builds and reads it.

Everything about the bodies that is fixed for a run is computed once here, with the geometry of
:mod:`linknet_core.structure.bodies` (principal axes, body frames, top kinds, the masses' body-frame positions, the Kabsch
fit of a body state to a mass state), and handed to C as ``struct ln_rigid_model``; the C side only steps the
body states. :func:`rigid_model` builds what ``ln_model.rigid`` points to; :class:`RigidFunctions` calls
rigid.h's state functions on a loaded library; :class:`NativeRigidIntegrator` is the native integrator of a
scene of free rigid bodies, as :class:`linknet_core.Simulator` uses it.

A body state is one row of 13 numbers: centre of mass c (0:3), its velocity v (3:6), the unit quaternion
q = (w, x, y, z) of the body's rotation (6:10) and the body-frame angular momentum Pi (10:13).
"""
from __future__ import annotations

import ctypes
from typing import NamedTuple

import numpy as np

from linknet_core.dynamics.equations import Dynamics
from linknet_core.errors import SolverError
from linknet_core.structure.bodies import BodyGeometry, BodyLayout, body_geometry, fit_bodies, freeze_initial_state
from linknet_core.clib import library as lib
from linknet_core.native.integrator import NativeIntegrator
from linknet_core.native.model import NativeModel

STATE_SIZE = 13  # LN_RIGID_STATE
MAX_STAGES = 32  # LN_RIGID_MAX_STAGES: Runge-Kutta stages the C side's body-state scratch holds
SPHERICAL_TOP, SYMMETRIC_TOP, ASYMMETRIC_TOP = 0, 1, 2  # enum ln_top, the codes of BodyGeometry.kind

_int_p, _double_p = lib.ln_int_p, lib.c_double_p


class NativeRigid(NamedTuple):
    """What :func:`rigid_model` builds. ``struct`` points into ``keepalive``'s arrays, which must live as long
    as any ln_model that points to ``struct``."""

    struct: lib.RigidModel
    keepalive: tuple
    Y0: np.ndarray            # (B,13) the initial body states (ln_rigid_set_state)
    X0: np.ndarray            # (K,3) the initial state the bodies were frozen in (projected if it had to be)
    U0: np.ndarray
    geometry: BodyGeometry    # for refitting the bodies to a mass state set from outside (body_states)
    notes: list               # what was done to the initial state, for the specialisation's report


def body_states(scene, bodies: BodyLayout, geometry: BodyGeometry, X, U) -> np.ndarray:
    """The body states (B,13) fitted to a mass state (X, U): for ln_rigid_set_state when a state is set from
    outside rather than produced by the bodies."""
    c, v, q, Pi = fit_bodies(scene, bodies, geometry, np.asarray(X, float), np.asarray(U, float))
    return np.ascontiguousarray(np.concatenate([c, v, q, Pi], axis=1), dtype=np.float64)


def rigid_model(dynamics: Dynamics, bodies: BodyLayout, X0, U0) -> NativeRigid:
    """``struct ln_rigid_model`` for the bodies of ``bodies`` (linknet_core.structure.bodies.free_rigid_bodies), frozen in
    the initial state (X0, U0), and the initial body states. ``dynamics`` is the scene's (numpy) Dynamics: it
    projects an initial state whose link lengths are off by more than round-off before the bodies are frozen."""
    scene = dynamics.scene
    X0, U0, notes = freeze_initial_state(dynamics, X0, U0)
    geometry = body_geometry(scene, bodies, X0)
    body_of = np.ascontiguousarray(bodies.body_of, np.int64)
    r = np.ascontiguousarray(geometry.r, np.float64)
    inertia = np.ascontiguousarray(geometry.inertia, np.float64)
    body_mass = np.ascontiguousarray(geometry.body_mass, np.float64)
    kind = np.ascontiguousarray(geometry.kind, np.int64)
    if body_of.shape != (scene.K,) or r.shape != (scene.K, 3) or inertia.shape != (bodies.count, 3):
        raise ValueError("the body layout does not match the scene")
    struct = lib.RigidModel(bodies.count, body_of.ctypes.data_as(_int_p), r.ctypes.data_as(_double_p),
                            inertia.ctypes.data_as(_double_p), body_mass.ctypes.data_as(_double_p),
                            kind.ctypes.data_as(_int_p))
    Y0 = body_states(scene, bodies, geometry, X0, U0)
    return NativeRigid(struct, (body_of, r, inertia, body_mass, kind), Y0, X0, U0, geometry, notes)


class RigidFunctions:
    """rigid.h's state functions on a loaded library (the package's, or a test build). Model, method and data
    are passed as ctypes pointers to ln_model, ln_method and ln_data."""

    def __init__(self, lib: ctypes.CDLL):
        vp = ctypes.c_void_p
        self._get = lib.ln_rigid_get_state
        self._get.restype, self._get.argtypes = None, [vp, vp, _double_p]
        self._set = lib.ln_rigid_set_state
        self._set.restype, self._set.argtypes = ctypes.c_int, [vp, vp, _double_p]
        self._fixed = lib.ln_rigid_rk_fixed_steps
        self._fixed.restype = ctypes.c_int
        self._fixed.argtypes = [vp, vp, vp, ctypes.c_double, ctypes.c_int64]

    def get_state(self, model, data, n_bodies: int) -> np.ndarray:
        """A copy of the body states (B,13)."""
        Y = np.empty((n_bodies, STATE_SIZE))
        self._get(model, data, Y.ctypes.data_as(_double_p))
        return Y

    def set_state(self, model, data, Y) -> int:
        """Set the body states (B,13) and the masses' X, U from them; the status (0: ok; 8: no bodies, or a
        non-finite number or zero quaternion in Y, nothing changed)."""
        Y = np.ascontiguousarray(Y, np.float64)
        return self._set(model, data, Y.ctypes.data_as(_double_p))

    def rk_fixed_steps(self, model, method, data, h: float, n: int) -> int:
        """n steps of exactly h of the method's tableau without error control (order measurements); the status."""
        return self._fixed(model, method, data, float(h), int(n))


class NativeRigidIntegrator(NativeIntegrator):
    """The native core on a scene of free rigid bodies (ln_model.rigid set: ln_advance moves the bodies).

    On top of :class:`NativeIntegrator`: the body states. A mass state set from outside (not the one this
    integrator last handed out, nor equal to it) is followed by refitting the bodies to it; snapshots carry
    the body states, so that a restored snapshot continues bit-identically. ``initial_state`` is the state the
    bodies were frozen in (projected onto exact link lengths if it had to be, as ``notes`` then says).
    Tensions at an output are those of (25)-(26) at the state (ln_evaluate)."""

    def __init__(self, dynamics: Dynamics, bodies: BodyLayout, method_cls, X0, U0, *, dt=None, rtol=None,
                 atol=None):
        self.rigid = rigid_model(dynamics, bodies, X0, U0)  # owns the arrays the model's ln_rigid_model points to
        self.bodies = bodies
        super().__init__(NativeModel(dynamics.scene, dynamics.structure, rigid=self.rigid.struct), method_cls,
                         dt=dt, rtol=rtol, atol=atol)
        self._functions = RigidFunctions(lib.lib)
        self.initial_state = (self.rigid.X0, self.rigid.U0)
        self.notes = list(self.rigid.notes)
        self._set_bodies(self.rigid.Y0, self.rigid.X0, self.rigid.U0)

    def _set_bodies(self, Y, X, U) -> None:
        """The body states Y, and (X, U) as the mass state they stand for (kept as given: set_state's own X, U
        of the bodies agree with them to round-off)."""
        if self._functions.set_state(self.model.pointer, self._data_p, Y) != lib.OK:
            raise SolverError("the rigid-body state is not finite (or has a zero quaternion)")
        self.data.X[...] = X
        self.data.U[...] = U
        self._last = (np.array(X, float), np.array(U, float))

    def body_states(self) -> np.ndarray:
        """A copy of the body states (B,13): c, v, q, Pi per body."""
        return self._functions.get_state(self.model.pointer, self._data_p, self.bodies.count)

    def internals(self) -> dict:
        out = super().internals()
        # the arrays of _last are only ever replaced, never written into: references suffice
        out["bodies"] = {"Y": self.body_states(), "X": self._last[0], "U": self._last[1]}
        return out

    def set_internals(self, data: dict) -> None:
        super().set_internals(data)
        saved = data["bodies"]
        self._set_bodies(saved["Y"], saved["X"], saved["U"])

    def _load(self, state, F_input) -> None:
        handed_out = state.X is self._out[0] and state.U is self._out[1]
        super()._load(state, F_input)
        if not handed_out and not (np.array_equal(state.X, self._last[0]) and np.array_equal(state.U, self._last[1])):
            # a state set from outside: the bodies follow it
            self._set_bodies(body_states(self.model.scene, self.bodies, self.rigid.geometry, state.X, state.U),
                             state.X, state.U)

    def advance(self, state, t_target: float, F_input, max_steps: int) -> None:
        super().advance(state, t_target, F_input, max_steps)
        self._last = (state.X, state.U)  # the arrays handed out (never written into later)
