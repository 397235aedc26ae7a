"""The interface Jacobians in the native core (src/interface_jacobian.c): a linearization at one state whose
directional derivatives reuse the factorisation of A (25) that the state's tensions used.

The formulas and their derivation are the numpy reference's (linknet_core.dynamics.interface_jacobian); this is
their ctypes binding, with the same :class:`InterfaceLinearization` interface (``directional``, ``jacobian``).
"""
from __future__ import annotations

import ctypes

import numpy as np

from linknet_core.dynamics.interface_jacobian import InterfaceLinearization
from linknet_core.errors import SolverError
from linknet_core.clib import library as lib

Interface_p = ctypes.c_void_p
_new = lib._declare("ln_interface_new", Interface_p, lib.Model_p)
_free = lib._declare("ln_interface_free", None, Interface_p)
_prepare = lib._declare("ln_interface_prepare", ctypes.c_int, lib.Model_p, Interface_p, lib.Data_p, lib.c_double_p,
                        lib.c_double_p, ctypes.c_void_p)
_directional = lib._declare("ln_interface_directional", ctypes.c_int, lib.Model_p, Interface_p, ctypes.c_void_p,
                            ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p,
                            ctypes.c_void_p)
_singular = lib._declare("ln_interface_singular", ctypes.c_int, Interface_p)


class NativeInterface:
    """ln_interface of one model: the workspace (its own ln_data, hence its own factorisation of A) that
    linearizations at successive states share. Not for use by two linearizations at once: preparing one state
    replaces the last."""

    def __init__(self, model):
        self.model = model
        self._free = _free  # bound now: __del__ may run at exit
        self._ptr = _new(model.pointer)
        if not self._ptr:
            raise MemoryError("the native core could not allocate the interface Jacobian's workspace (out of memory)")

    def __del__(self):
        if getattr(self, "_ptr", None):
            self._free(self._ptr)
            self._ptr = None


class NativeLinearization(InterfaceLinearization):
    """The C core's linearization at the state X, U (K,3) with the input forces ``F_input`` (K,3; None: none) and
    what an integrator's data ``data`` (NativeData) holds: its time and driven anchors' motion, as
    Simulator.outputs evaluates them. ``interface``: the NativeInterface to prepare (a new one by default); its
    last preparation is this linearization's state. ``anchors``: the driven anchors whose P, V, A are seeded
    (default the input-driven ones, the inputs; any driven anchor's derivative is defined)."""

    def __init__(self, model, data, X, U, F_input=None, interface: NativeInterface | None = None, anchors=None):
        scene = model.scene
        super().__init__(scene, scene.input_driven_indices if anchors is None else anchors)
        if not np.all(scene.driven[self.anchors]):
            k = int(self.anchors[~scene.driven[self.anchors]][0])
            raise SolverError(f"{scene.mass_label(k)} is not a driven anchor: only a driven anchor's P, V, A are inputs")
        self.interface = interface or NativeInterface(model)
        self._model_p = model.pointer
        X = np.ascontiguousarray(X, np.float64)
        U = np.ascontiguousarray(U, np.float64)
        F = None if F_input is None else np.ascontiguousarray(F_input, np.float64)
        status = _prepare(self._model_p, self.interface._ptr, data._ptr, lib.pointer(X), lib.pointer(U),
                          None if F is None else F.ctypes.data)
        if status != lib.OK:
            raise SolverError(f"the interface Jacobian cannot be evaluated at this state: the tensions (25)-(26) "
                              f"failed ({lib.STATUS[status]})")
        self.singular = bool(_singular(self.interface._ptr))
        # the seeded anchors among the driven ones (the C seeds have a row per driven anchor)
        self._slots = np.searchsorted(scene.driven_indices, self.anchors)
        self._n_driven = scene.driven_indices.size
        K, L = scene.K, scene.L
        self._out = (np.empty(L), np.empty((self.anchored.size, 3)), np.empty((K, 3)))
        self._seeds = [np.zeros((self._n_driven, 3)) for _ in range(3)]

    def _directional(self, dF, dP, dV, dA):
        dF = np.ascontiguousarray(dF, np.float64)
        driven = []
        for full, part in zip(self._seeds, (dP, dV, dA)):
            full[self._slots] = part
            driven.append(full.ctypes.data if full.size else None)
        dT, dFreact, dacc = self._out
        status = _directional(self._model_p, self.interface._ptr, dF.ctypes.data, *driven,
                              dT.ctypes.data if dT.size else None, dFreact.ctypes.data if dFreact.size else None,
                              dacc.ctypes.data)
        if status != lib.OK:
            raise SolverError(f"the interface Jacobian's directional derivative failed: {lib.STATUS[status]} (a "
                              "seed or the state gives a non-finite derivative)")
        return dT.copy(), dFreact.copy(), dacc.copy()
