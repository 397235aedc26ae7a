"""The native core's model, method and data, built from a scene, its structure and an integrator.

:class:`NativeModel` is ln_model of one scene: topology, masses, lengths, force elements and what the
structure analysis decided (the tension solver, its elimination order, the plane of a planar scene, the
rigid-body layout), built once. :class:`NativeMethod` is ln_method: an integrator's method as data (the
step fractions of a RATTLE composition, or the tableau and controller of an embedded Runge-Kutta pair).
:class:`NativeData` is ln_data: the state, the integrator's internals and the scratch, allocated by C.
"""
from __future__ import annotations

import ctypes
import functools
import weakref

import numpy as np
from linknet_core.dynamics.forces import ELEMENT_KINDS, has_velocity_dependent_forces
from linknet_core.structure.topology import analyse, kept_per_scene, link_pairs
from linknet_core.tolerances import (DENSE_MIN_NORM_LIMIT, FLOOR_CAP_OVER_TOL, FLOOR_SAFETY, MAX_FACTOR, MIN_FACTOR,
                                     PIVOT_TOL, PLANE_TOL, RETRY_SINGULAR_RCOND, SAFETY, SINGULAR_RCOND)
from linknet_core.clib.ldl import package_library
from linknet_core.clib import library as lib
from linknet_core.clib.library import float_array, int_array, pointer
from linknet_core.scene.description import require_force_kinds


_interface_kind_name = lib._declare("ln_interface_kind_name", ctypes.c_char_p, lib.ln_int)


def interface_kind_names() -> list[str]:
    """The force element kinds the core's interface Jacobians differentiate (src/interface_jacobian.c)."""
    names = []
    while (name := _interface_kind_name(len(names))) is not None:
        names.append(name.decode())
    return names


def check_core_force_kinds() -> None:
    """The core's force element kinds (stages/forces.c, with the scene's codes) and those its interface Jacobians
    differentiate (interface_jacobian.c) are the scene's FORCE_KINDS, or ForceKindMissing names the kind and the
    file: checked when this module loads, before any native model is built, so that neither skips a kind."""
    require_force_kinds(lib.force_kind_names(), "the native core (native/src/stages/forces.c)", by_code=True)
    require_force_kinds(interface_kind_names(), "the native interface Jacobians (native/src/interface_jacobian.c)")


check_core_force_kinds()


def scene_plane(scene, normal):
    """(P (3,2) orthonormal in-plane basis, o (3,) a point of the plane, n (3,) unit normal, length (size of the
    scene: the scale of the in-plane test)), or None when ``normal`` is None.

    An axis-aligned plane gets the exact 0/1 basis and an origin with zero in-plane components, so that the
    reduction to 2-D and back is exact: the in-plane coordinates are those of the 3-D path.
    """
    if normal is None:
        return None
    n = np.asarray(normal, np.float64)
    n = n / np.linalg.norm(n)
    X0 = np.asarray(scene.X0, np.float64)
    axis = int(np.argmax(np.abs(n)))
    others = [a for a in range(3) if a != axis]
    if np.all(np.abs(n[others]) <= PLANE_TOL):
        P = np.eye(3)[:, others]
        n = np.eye(3)[axis]
        o = np.zeros(3)
        o[axis] = X0[0, axis] if X0.shape[0] else 0.0
    else:
        a = np.eye(3)[int(np.argmin(np.abs(n)))]
        p0 = a - (a @ n) * n
        p0 /= np.linalg.norm(p0)
        P = np.column_stack([p0, np.cross(n, p0)])
        o = n * float(n @ X0.mean(axis=0)) if X0.shape[0] else np.zeros(3)
    length = float(np.abs(X0 - o).sum(axis=1).max()) if X0.shape[0] else 0.0
    return P, o, n, length


def chain_order(L, first, second, ordering, component):
    """Path order of a chain's links, or None where A is not tridiagonal in that order. The links of each path
    (``component``: a component of the graph cut at the anchors) come in the structure's leaves-first order, which
    for a path is path order; the test below checks it."""
    off = first != second
    position_of = np.empty(L, np.int64)
    position_of[ordering] = np.arange(L)
    order = np.lexsort((position_of, component)).astype(np.int64)
    position = np.empty(L, np.int64)
    position[order] = np.arange(L)
    p1, p2 = position[first[off]], position[second[off]]
    if np.any(np.abs(p1 - p2) != 1):
        return None
    return order


class NativeModel:
    """ln_model of one scene. ``solver`` is decided from the structure: 'chain' (tridiagonal in path order),
    'ldl' (trees and general graphs: sparse LDL^T in the structure's elimination order) or 'min-norm'
    (self-stresses). ``planar``: None runs a planar scene in 2-D, False always in 3-D. ``rigid``: the
    ln_rigid_model of a free-rigid-body specialisation (with the arrays it points into), or None."""

    def __init__(self, scene, structure, planar: bool | None = None, rigid=None):
        self._scene = weakref.ref(scene)  # a model may be kept per scene (native_model): it must not keep it alive
        self.K, self.L = K, L = scene.K, scene.L
        fixed = np.asarray(scene.fixed, bool)
        keep = self._keep = []

        def f8(a):
            a = float_array(a)
            keep.append(a)
            return pointer(a)

        def i8(a):
            a = int_array(a)
            keep.append(a)
            return pointer(a, lib.ln_int)

        m = self.struct = lib.Model()
        m.K, m.L = K, L
        m.k1, m.k2 = i8(scene.k1), i8(scene.k2)
        self._fill_driven(m, scene, f8, i8)
        m.n_free, m.free_idx = scene.free_indices.size, i8(scene.free_indices)
        m.n_fixed, m.fixed_idx = int(fixed.sum()), i8(np.flatnonzero(fixed))
        is_fixed = np.ascontiguousarray(fixed, np.uint8)
        keep.append(is_fixed)
        m.is_fixed = pointer(is_fixed, ctypes.c_uint8)
        elements = scene.force_elements
        kinds = [lib.force_kind(kind.encode()) for kind in elements.kinds]
        if -1 in kinds:
            raise ValueError(f"the native core has no force element of kind {elements.kinds[kinds.index(-1)]!r}")
        m.n_elements, m.element_kind = elements.count, i8(kinds)
        m.element_mass, m.element_param = i8(elements.masses), f8(elements.parameters)
        m.velocity_dependent = int(has_velocity_dependent_forces(scene))

        pairs = link_pairs(scene)
        m.n_pairs, m.pair_first, m.pair_second = pairs.first.size, i8(pairs.first), i8(pairs.second)
        m.pair_mass, m.pair_sign = i8(pairs.mass), f8(pairs.sign)
        m.pivot_tol, m.rank_tol, m.dense_min_norm_limit = PIVOT_TOL, SINGULAR_RCOND, DENSE_MIN_NORM_LIMIT
        m.retry_rank_tol = RETRY_SINGULAR_RCOND  # a failing Gauss-Newton's retry, as the reference's
        m.floor_safety, m.floor_cap = FLOOR_SAFETY, FLOOR_CAP_OVER_TOL  # the reference's projection stopping rule
        self._ldl = None
        if L == 0:
            self.solver = "none"
            m.solver = lib.SOLVER_NONE
        elif structure.kind == "redundant":
            self.solver = "min-norm"
            m.solver = lib.SOLVER_MIN_NORM
        else:
            order = None
            if structure.kind == "chain":
                order = chain_order(L, pairs.first, pairs.second, structure.ordering, structure.link_component)
            if order is not None:
                self.solver = "chain"
                m.solver = lib.SOLVER_CHAIN
                m.chain_order = i8(order)
            else:
                self.solver = "ldl"
                m.solver = lib.SOLVER_LDL
                ordering = int_array(structure.ordering)
                first, second = int_array(pairs.first), int_array(pairs.second)
                self._ldl_free = package_library().ln_ldl_symbolic_free  # bound now: __del__ may run at exit
                self._ldl = package_library().ln_ldl_analyse(L, first.size, pointer(first, lib.ln_int),
                                                             pointer(second, lib.ln_int), pointer(ordering, lib.ln_int))
                if not self._ldl:
                    raise MemoryError("the sparse LDL^T analysis of the tension matrix failed (out of memory)")
                m.ldl = self._ldl
        # 1/M, the base forces, 1/R, the weights of A (25) and of a_k in B (26): the core's one formula for them
        weights = np.empty(lib.model_weights_size(ctypes.pointer(m)))
        parameters = [float_array(a) for a in (scene.mass, scene.length, scene.gravity, scene.force)]
        keep += [weights, parameters[1]]  # the model points into both
        if lib.model_weights(ctypes.pointer(m), *(pointer(a) for a in parameters), pointer(weights)) != lib.OK:
            raise MemoryError("the native core could not compute the model's weights (out of memory)")
        if self._ldl:
            self.nnz_L = int(package_library().ln_ldl_nnz_L(self._ldl))
        else:  # a chain's L has one entry per link after the first; no links, no L
            self.nnz_L = max(L - 1, 0) if self.solver == "chain" else 0

        # driven anchors move where they are told, in or out of a plane: such scenes run in 3-D
        plane = None if planar is False or m.n_driven else scene_plane(scene, structure.planar_normal)
        self.plane = plane
        if plane is not None:
            P, o, n, length = plane
            m.planar = 1
            m.plane_P[:] = np.ascontiguousarray(P, np.float64).ravel().tolist()
            m.plane_o[:], m.plane_n[:] = list(o), list(n)
            m.plane_length, m.plane_tol = length, PLANE_TOL
        self._fill_ropes(m, scene, f8, i8)
        self.rigid = rigid
        if rigid is not None:
            m.rigid = ctypes.cast(ctypes.pointer(rigid), ctypes.c_void_p)
        self.pointer = ctypes.pointer(m)

    @staticmethod
    def _fill_driven(m, scene, f8, i8) -> None:
        """The driven anchors: their masses and motions as the tables of drive.c (linknet_core.scene.motion)."""
        motions = scene.motions
        m.n_driven = len(motions)
        if not motions:
            return
        from linknet_core.scene.motion import PIECE_COLUMNS, SINE_COLUMNS

        m.driven_idx = i8(scene.driven_indices)
        m.motion_kind = i8([motion.code for motion in motions])
        m.motion_pieces = i8(np.concatenate([[0], np.cumsum([motion.pieces.shape[0] for motion in motions])]))
        m.piece = f8(np.concatenate([motion.pieces for motion in motions]).reshape(-1, PIECE_COLUMNS))
        m.sine = f8(np.array([motion.sine for motion in motions]).reshape(-1, SINE_COLUMNS))

    @staticmethod
    def _fill_ropes(m, scene, f8, i8) -> None:
        """The ropes (stages/ropes.c): their links and restitutions, the events' tolerances from the numpy
        reference's single source, and the scene's length and gravity scales as UnilateralDynamics takes them."""
        ropes = np.flatnonzero(scene.rope)
        m.n_ropes = ropes.size
        if not ropes.size:
            return
        from linknet_core.dynamics import complementarity, unilateral
        from linknet_core.integrators import events

        m.rope_link, m.rope_restitution = i8(ropes), f8(scene.restitution[ropes])
        m.touch_tol, m.cross_tol = unilateral.TOUCH_TOL, unilateral.CROSS_TOL
        m.force_tol, m.rest_height = unilateral.FORCE_TOL, unilateral.REST_HEIGHT
        m.impulse_roundoff = unilateral.IMPULSE_ROUNDOFF
        m.lcp_tol, m.pivots_per_row = complementarity.LCP_TOL, complementarity.PIVOTS_PER_ROW
        m.enumeration_limit = complementarity.ENUMERATION_LIMIT
        m.max_events_per_step, m.gap_newton_iterations = events.MAX_EVENTS_PER_STEP, events.GAP_NEWTON_ITERATIONS
        m.short_step = events.SHORT_STEP
        m.scene_size = unilateral.scene_size(scene)
        m.gravity_norm = float(np.linalg.norm(scene.gravity))
        contacts = getattr(scene, "contact_masses", ())
        if contacts:  # a ground (unilateral.native_ground_scene): its size is the scene's, not the anchors'
            m.scene_size = scene.size
            m.n_contacts, m.contact_mass = len(contacts), i8(np.array(contacts, np.int64))
            ground = scene.ground_plane
            m.ground_point[:], m.ground_normal[:] = ground.point, ground.normal
            m.friction = float(ground.friction)
            m.ground_tangent[:] = unilateral._tangents(np.asarray(ground.normal, float)).ravel()
            m.n_grips = 2 * len(contacts) if ground.friction > 0 else 0  # _with_grips appended them

    @property
    def scene(self):
        """The scene (held weakly; whoever uses the model holds the scene)."""
        return self._scene()

    @functools.cached_property
    def energy_terms(self):
        """ln_energy_terms of the scene: what a sample's diagnostics (ln_sample_diagnostics) need beyond the
        model, as the numpy reference forms them (linknet_core.dynamics.forces.potential_energy, kinetic_energy).
        None when a force element with a potential other than a spring's is present: the reference computes that
        scene's energy."""
        scene = self.scene
        elements = scene.force_elements
        if any(ELEMENT_KINDS[kind].potential is not None and kind != "spring" for kind in elements.kinds):
            return None
        free = ~np.asarray(scene.fixed, bool)
        springs, parameters = elements.of_kind("spring")
        arrays = (float_array(scene.mass),
                  float_array(np.where(free, scene.mass, 0.0)[:, None] * scene.gravity[None, :]),
                  float_array(scene.force), int_array(springs[:, :2]), float_array(parameters[:, :2]))
        terms = lib.EnergyTerms()
        terms.mass, terms.weight, terms.force = (pointer(a) for a in arrays[:3])
        terms.n_springs = springs.shape[0]
        terms.spring_mass, terms.spring_param = pointer(arrays[3], lib.ln_int), pointer(arrays[4])
        terms.keep = arrays  # the arrays the struct points into live as long as it
        return terms

    def __del__(self):
        if getattr(self, "_ldl", None):
            self._ldl_free(self._ldl)
            self._ldl = None

    def describe(self) -> str:
        """The native path this scene gets, in words (``linknet analyze``)."""
        solver = {"chain": "chain: tridiagonal A of (25) in path order, each right-hand side two sweeps along the path",
                  "ldl": f"sparse LDL^T of A (25) on the pattern analysed once (nnz(L) = {self.nnz_L})",
                  "min-norm": "minimum-norm tensions (self-stresses: A singular)",
                  "none": "no links"}[self.solver]
        if self.plane is not None:
            n = self.plane[2]
            aligned = bool(np.array_equal(np.abs(n), np.eye(3)[int(np.argmax(np.abs(n)))]))
            dims = (f"2-D planar (normal {np.round(n, 6).tolist()}, "
                    f"{'axis-aligned: exact reduction' if aligned else 'tilted: orthonormal in-plane basis'}; "
                    "an out-of-plane input force or state switches to 3-D)")
        else:
            dims = "3-D"
        terms = ["gravity, constant and input forces summed once per interval"]
        kinds = self.scene.force_elements.kinds
        for kind in dict.fromkeys(kinds):
            terms.append(f"{kinds.count(kind)} {kind} element{'s' if kinds.count(kind) != 1 else ''}")
        if not kinds:
            terms.append("no force elements: no force evaluation per step")
        return f"{solver}; {dims}; forces: {', '.join(terms)}"


def native_model(scene, structure) -> NativeModel:
    """The NativeModel of ``scene`` run on ``structure``: built once per scene object when the structure is the
    scene's own analysis (ln_model is immutable, so every Simulator of the scene, an ensemble's members or a reset
    FMU, shares it), built anew otherwise."""
    if structure is not analyse(scene):
        return NativeModel(scene, structure)
    return kept_per_scene(scene, "native model", lambda s: NativeModel(s, structure))


def native_ground_model(scene) -> NativeModel:
    """The NativeModel of ``scene`` with its ground: that of unilateral.native_ground_scene (contacts as unilateral
    links to virtual anchors), on the 3-D path (the anchors leave any plane the masses keep), built once per scene
    object; the model keeps the scene it is built from (its own reference to it is weak)."""
    from linknet_core.dynamics.unilateral import native_ground_scene

    def build(s):
        padded = native_ground_scene(s)
        if s.ground.friction > 0:
            padded = _with_grips(padded)
        model = NativeModel(padded, analyse(padded), planar=False)
        model.ground_scene = padded
        return model
    return kept_per_scene(scene, "native ground model", build)


@functools.lru_cache(maxsize=64)
def native_method(cls, *, dt=None, rtol=None, atol=None, position_tol=1e-14, static=False) -> "NativeMethod":
    """The NativeMethod of an integrator class and its settings, built once per distinct set (ln_method is
    immutable and only read by C)."""
    return NativeMethod(cls, dt=dt, rtol=rtol, atol=atol, position_tol=position_tol, static=static)


class NativeMethod:
    """ln_method of an integrator: the method as data. Compositions of RATTLE are their step fractions
    ``gammas`` (RATTLE itself: one, 1.0); embedded Runge-Kutta pairs are their tableau (A, B), error weights,
    error norm and the order of their estimate. Adding a method of either kind needs no code here."""

    def __init__(self, cls, *, dt=None, rtol=None, atol=None, position_tol=1e-14, max_projection_iter=50,
                 static=False):
        s = self.struct = lib.Method()
        self._keep = []
        s.position_tol, s.max_projection_iter = position_tol, max_projection_iter
        self.n_stages = 0
        if static:
            s.kind = lib.STATIC
        elif getattr(cls, "adaptive", False):
            s.kind = lib.RUNGE_KUTTA
            AB, E1, E2, exponent = embedded_pair(cls.A, cls.B, cls.error_weights, cls.error_estimator_order)
            self._keep += [AB, E1, E2]
            s.n_stages = self.n_stages = AB.shape[1]
            C = float_array(cls.C)
            self._keep.append(C)
            s.AB, s.C, s.E1, s.E2 = pointer(AB), pointer(C), pointer(E1), pointer(E2)
            s.error_norm = lib.HAIRER_ERROR if cls.error_norm_kind == "hairer" else lib.RMS_ERROR
            s.exponent = exponent
            s.safety, s.min_factor, s.max_factor = SAFETY, MIN_FACTOR, MAX_FACTOR  # the reference's controller
            s.real_stability, s.stiff_safety, s.straight_slip = (cls.real_stability, cls.stiff_safety,
                                                                 cls.straight_slip)
            s.rtol, s.atol = rtol, atol
        else:
            s.kind = lib.COMPOSITION
            gammas = float_array(cls.gammas)
            self._keep.append(gammas)
            s.n_gammas, s.gammas, s.dt = gammas.size, pointer(gammas), dt
        self.pointer = ctypes.pointer(s)


def embedded_pair(A, B, error_weights, error_estimator_order):
    """An explicit embedded tableau as ln_method takes it: AB (A with the weights b as row s), the error
    weights E1, E2 (s + 1 each; E2 zero for a single-estimate norm) and the controller's exponent
    -1 / (order of the estimate + 1)."""
    B = np.asarray(B, np.float64)
    s = B.shape[0]
    A = np.asarray(A, np.float64)
    if A.ndim != 2 or A.shape[0] != s or A.shape[1] > s or np.any(np.triu(A[:, :s]) != 0.0):
        raise ValueError(f"an explicit tableau needs a strictly lower-triangular A with {s} rows, got {A.shape}")
    AB = np.zeros((s + 1, s))
    AB[:s, :A.shape[1]] = A
    AB[s] = B
    E1 = float_array(error_weights[0])
    E2 = float_array(error_weights[1] if len(error_weights) > 1 else np.zeros_like(E1))
    if E1.shape != (s + 1,) or E2.shape != (s + 1,):
        raise ValueError(f"error weights must have {s + 1} entries (one per stage and one for the new point), "
                         f"got {E1.shape} and {E2.shape}")
    return AB, E1, E2, -1.0 / (error_estimator_order + 1)


_DATA_OFFSET = {name: getattr(lib.Data, name).offset for name, _ in lib.Data._fields_}


class NativeData:
    """ln_data for one model: the state t, X, U, the held input F_input, the last tensions T, and the
    integrator's internals, with numpy views of C's arrays (X, U, F_input, T, reaction: (K,3), (K,3), (K,3), (L,),
    (anchors,3))."""

    def __init__(self, model: NativeModel, n_stages: int = 0):
        self.model = model  # the data points into nothing of the model's, but C reads both together
        self._ptr = lib.data_new(model.pointer, n_stages)
        if not self._ptr:
            raise MemoryError("the native core could not allocate its data (out of memory)")
        self.struct = self._ptr.contents
        self._reset = functools.partial(lib.data_reset, model.pointer, self._ptr)  # reset's arguments, made once
        K = model.K
        # what every advance and output reads or writes; the other views are made when first used
        self.X, self.U, self.F_input = self._view("X", K, 3), self._view("U", K, 3), self._view("F_input", K, 3)
        self.T = self._view("T", model.L)

    def _view(self, field: str, rows: int, columns: int = 0, dtype=np.float64) -> np.ndarray:
        """A numpy view of the C array ``field`` of the data (~1 us, against ~3 us for np.ctypeslib.as_array)."""
        shape = (rows, columns) if columns else (rows,)
        if not rows:
            return np.zeros(shape, dtype)
        address = ctypes.c_void_p.from_address(ctypes.addressof(self.struct) + _DATA_OFFSET[field]).value
        size = rows * max(columns, 1) * np.dtype(dtype).itemsize
        return np.frombuffer((ctypes.c_char * size).from_address(address), dtype).reshape(shape)

    def reset(self) -> None:
        """Back to what a new data of the model holds (ln_data_reset: state, internals, counters, the driven
        anchors' hold, scratch), keeping its allocations, its views and its scene time origin."""
        self._reset()

    acc = functools.cached_property(lambda self: self._view("acc", self.model.K, 3))
    reaction = functools.cached_property(lambda self: self._view("reaction", int(self.model.struct.n_fixed), 3))
    drive_P = functools.cached_property(lambda self: self._view("drive_P", int(self.model.struct.n_driven), 3))
    drive_V = functools.cached_property(lambda self: self._view("drive_V", int(self.model.struct.n_driven), 3))
    drive_A = functools.cached_property(lambda self: self._view("drive_A", int(self.model.struct.n_driven), 3))
    impulse = functools.cached_property(lambda self: self._view("impulse", int(self.model.struct.n_driven), 3))
    jump_impulse = functools.cached_property(lambda self: self._view("jump_impulse", int(self.model.struct.n_driven), 3))
    # ropes: the mode (1 for rods and taut ropes) and each rope's impulse over the last advance (L each)
    link_active = functools.cached_property(lambda self: self._view("link_active", self.model.L, dtype=np.uint8))
    rope_impulse = functools.cached_property(lambda self: self._view("rope_impulse", self.model.L))
    # friction on the ground: each contact's slip reference (n_contacts, 3), part of the state
    slip_reference = functools.cached_property(
        lambda self: self._view("slip_reference", int(self.model.struct.n_grips) // 2, 3))

    def event_log(self, field: str, n: int) -> np.ndarray:
        """The first n entries of the event log's array ``field`` (event_t, event_kind, event_link, event_impulse)."""
        return self._view(field, n, dtype=np.int64 if field in ("event_kind", "event_link") else np.float64).copy()

    def __del__(self):
        if getattr(self, "_ptr", None):
            lib.data_free(self._ptr)
            self._ptr = None


def _with_grips(padded):
    """The ground scene ``padded`` (unilateral.native_ground_scene) with Coulomb friction's grips appended: per
    contact, two rods from its mass to two virtual anchors (infinite mass, fixed) at R_c along the plane's tangents
    t_1, t_2 beside it, at rest (ModeDynamics.pad: the core places them from every state it evaluates, and takes a
    grip into the mode while its contact sticks): the model's last 2 n_contacts links and masses."""
    import dataclasses
    import math

    from linknet_core.dynamics.unilateral import GroundModelScene, Scene, _padded_fields, _tangents

    masses = np.repeat(np.array(padded.contact_masses, np.int64), 2)
    n_g, K = masses.size, padded.K
    tangents = _tangents(np.asarray(padded.ground_plane.normal, float))
    X0 = np.asarray(padded.X0, float)
    anchors = X0[masses] + padded.contact_length * np.tile(tangents, (n_g // 2, 1))
    names = padded.mass_names
    own = {"mass": np.concatenate([padded.mass, np.full(n_g, math.inf)]),
           "fixed": np.concatenate([padded.fixed, np.ones(n_g, bool)]),
           "driven": np.concatenate([padded.driven, np.zeros(n_g, bool)]),
           "X0": np.concatenate([X0, anchors]), "U0": np.concatenate([padded.U0, np.zeros((n_g, 3))]),
           "mass_names": names + tuple(f"ground grip {i % 2 + 1} of {names[k]}" for i, k in enumerate(masses)),
           "k1": np.concatenate([padded.k1, masses]), "k2": np.concatenate([padded.k2, K + np.arange(n_g)]),
           "length": np.concatenate([padded.length, np.full(n_g, padded.contact_length)]),
           "link_names": padded.link_names + tuple(f"grip{i % 2 + 1}_{k + 1}" for i, k in enumerate(masses)),
           "rope": np.concatenate([padded.rope, np.zeros(n_g, bool)]),
           "restitution": np.concatenate([padded.restitution, np.zeros(n_g)]),
           "ground": None, "gravity": padded.gravity}
    labels = padded.labels + tuple(f"the ground's friction grip on {names[k]}" for k in masses)
    extra = {f.name: getattr(padded, f.name) for f in dataclasses.fields(GroundModelScene)
             if f.name not in {g.name for g in dataclasses.fields(Scene)} and f.name != "labels"}
    return GroundModelScene(labels=labels, **extra, **_padded_fields(padded, n_g, own))

