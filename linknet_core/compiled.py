"""Compiled paths: the right-hand side (9), the tension system (25)-(26), the projections onto (11)-(12) and
the RATTLE step loop in numba, for one scene at a time.

The pure numpy path pays a few microseconds of Python overhead per array operation, which dominates for
small and medium scenes. Here whole intervals between two output/communication points run in compiled
code. The kernels themselves are in :mod:`linknet_core.compiled_kernels` (written once over the number of
components of a vector, 3) and its generated planar twin :mod:`linknet_core.compiled_kernels_2d` (2); this
module holds what is decided once per scene (:class:`CompiledScene`):

* the tension solver's path: for chains a tridiagonal elimination in path order (two sweeps per
  right-hand side, see :func:`chain_elimination`), else the general sparse LDL^T on the pattern analysed
  once;
* the force terms: gravity, constant and input forces are summed once per interval; drag is applied only
  to the masses that have it (index array), springs only when there are any; a scene with neither uses the
  summed forces as they are, without a force loop per evaluation;
* planar scenes (``Structure.planar_normal``: every position, velocity, gravity and constant force in one
  plane; links, springs and drag keep a planar state planar) run in 2-D: the state in an orthonormal
  in-plane basis, two components per vector instead of three, mapped back to (K,3) for the caller. An
  interval whose input force (on a free mass) or starting state has a component along the normal beyond
  round-off (PLANE_TOL relative to its size) runs on the 3-D kernels instead, and so do all later ones
  (once the state has left the plane it does not come back).

The building blocks are shared by every compiled integrator (RATTLE and its compositions here, the
projected Runge-Kutta methods in :mod:`linknet_core.compiled_rk`). They cover scenes whose A is
non-singular along the way: whenever a kernel cannot continue (a vanishing pivot, a projection that does
not contract, non-finite values) it stops and reports it, and the caller redoes the rest of the interval
on the numpy path, which has the minimum-norm and exact-Newton fallbacks.
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from . import compiled_kernels as k3
from . import compiled_kernels_2d as k2
from .compiled_kernels import (EPS, LEFT_PLANE, NON_FINITE, OK, PIVOT_TOL, PROJECTION_FAILED,  # noqa: F401
                               SINGULAR, STEP_UNDERFLOW, TOO_MANY_STEPS, accelerations, add_correction,
                               factor_tension_matrix, project_positions, project_velocities, solve_tension_system,
                               unit_vectors)

PLANE_TOL = 1e-12  # an out-of-plane component at most this relative to its size is round-off (dropped in 2-D)
KERNELS = {3: k3, 2: k2}


def plane_normal(scene, structure_normal=None, rtol: float = PLANE_TOL):
    """Unit normal of the plane holding every position, velocity, gravity and constant force, or None.

    ``Structure.planar_normal`` when it found one; else the same test by an SVD of those vectors (thin, O(K)):
    the structure's eigenvalues of their 3 x 3 Gram matrix carry round-off of eps times the largest, far
    above its threshold tol^2 times it, so it sees only planes whose normal components are exactly zero (a
    scene in a tilted plane looks 3-D to it). A scene wrongly taken for planar here would still be safe: the
    2-D entry checks the state and the input of every interval and hands anything off the plane to 3-D.
    """
    if structure_normal is not None:
        return np.asarray(structure_normal, np.float64)
    X = np.asarray(scene.X0, np.float64)
    if X.shape[0] == 0:
        return None
    vectors = np.vstack([X - X.mean(axis=0), scene.U0, np.asarray(scene.gravity)[None, :], scene.force])
    scale = np.abs(vectors).max()
    if not scale > 0:
        return None
    _, sv, vt = np.linalg.svd(vectors / scale, full_matrices=False)
    if sv.shape[0] < 3 or sv[2] > rtol * sv[0]:
        return None
    return vt[2]


def scene_plane(scene, normal):
    """The plane of a planar scene in the form the 2-D kernels take: (P (3,2) orthonormal in-plane basis,
    o (3,) a point of the plane, n (3,) unit normal, length (size of the scene, the scale of the position
    test)), or None when ``normal`` is None.

    An axis-aligned plane gets the exact 0/1 basis and an origin with zero in-plane components, so that the
    reduction to 2-D and back is exact (no round-off): the in-plane coordinates are those of the 3-D path.
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
    return np.ascontiguousarray(P), np.ascontiguousarray(o), np.ascontiguousarray(n), length


def rattle_scratch(K, L, dim=3):
    """Scratch arrays of the RATTLE loop (allocated once per scene): E0, E1 (L,dim); F, Uh, Xc, U_iterate
    (K,dim); mu, phi, scale (L,)."""
    return (np.empty((L, dim)), np.empty((L, dim)), np.empty((K, dim)), np.empty((K, dim)), np.empty((K, dim)),
            np.empty((K, dim)), np.empty(L), np.empty(L), np.empty(L))


class DirectCall:
    """A numba dispatcher called again and again with the same argument types, minus its per-call dispatch.

    On every call numba's dispatcher works out the type of each argument and looks the compiled overload up:
    ~30 ns per argument, 1.8 us for the 66 arguments of a planar step loop, about the cost of one RATTLE step
    of a 100-link chain. A scene's step loop always gets the same types (its arrays are built once with fixed
    dtypes; the per-call X, U, F are made C-contiguous float64 (K,3) by the caller; Python floats and ints), so
    the first call goes through the dispatcher (compiling or loading the cache) and later calls go straight to
    the compiled overload of those types. Its argument conversion still rejects a wrong dtype or a
    non-array, but not a wrong layout or shape: callers must keep to the types of the first call.
    """

    def __init__(self, dispatcher):
        self.dispatcher = dispatcher
        self._entry = None

    def __call__(self, *args):
        if self._entry is not None:
            return self._entry(*args)
        result = self.dispatcher(*args)
        overload = self.dispatcher.overloads.get(tuple(self.dispatcher.typeof_pyval(a) for a in args))
        # no overload found (a numba that keys them differently): keep calling the dispatcher, only slower
        self._entry = overload.entry_point if overload is not None else self.dispatcher
        return result


def accelerations_repeated(n_evals, X, U, F_base, scene, system, acc, T):
    """n_evals evaluations of :func:`accelerations` in a row at the same state, in one compiled loop (one
    evaluation for tests; many for benchmarks: the right-hand side the compiled integrators call, timed
    without the Python call), in as many components as X has (3, or 2 in a plane's coordinates). Leaves the
    last result in acc and T; returns a checksum. F_base: gravity, constant and input forces (its rows of
    anchored masses are set to zero)."""
    K, L, dim = X.shape[0], T.shape[0], X.shape[1]
    return KERNELS[dim]._accelerations_loop(n_evals, X, U, F_base, *scene, *system, np.empty((L, dim)),
                                            np.empty((K, dim)), np.empty(L), acc, T, n_evals > 0)


def chain_elimination(scene, assembly):
    """Path order of the links of a 'chain' scene and the weights of its tridiagonal A (setup, once).

    Returns (order, diagonal weights, off-diagonal weights to the previous link in the order), or None
    if A is not tridiagonal in that order (then the general sparse path is used). The links of each path
    (a component of the graph cut at the anchors) come in the structure's leaves-first order, which for a
    path is path order; the test below checks it.
    """
    L = scene.L
    if L == 0:
        return None
    first, second, weight = assembly.pair_first, assembly.pair_second, assembly.pair_weight
    off = first != second
    graph = sp.coo_matrix((np.ones(int(off.sum())), (first[off], second[off])), shape=(L, L))
    _, component = connected_components(graph, directed=False)
    order = np.lexsort((assembly.position_of, component)).astype(np.int64)
    position = np.empty(L, np.int64)
    position[order] = np.arange(L)
    p1, p2 = position[first[off]], position[second[off]]
    if np.any(np.abs(p1 - p2) != 1):
        return None
    diag_weight = np.bincount(position[first[~off]], weights=weight[~off], minlength=L)
    off_weight = np.zeros(L)
    np.add.at(off_weight, np.maximum(p1, p2), weight[off])
    return order, diag_weight, off_weight



class CompiledScene:
    """The arrays of one scene as the compiled kernels take them (built once per Dynamics).

    Every array is C-contiguous with a fixed dtype, so each kernel compiles once. The factor storage and
    work arrays are private to this object: the kernels must not disturb the numpy path's cached
    factorisation. ``use_chain``: None picks the tridiagonal path for chain scenes (False forces the
    general sparse path, for tests). ``planar``: None runs planar scenes in 2-D, False always in 3-D (for
    comparisons), True demands a planar scene. ``self.planar`` says whether the next interval is tried in
    2-D; it turns False when an interval had to run in 3-D and stays so (the integrators keep it with their
    internals, so that a restored snapshot continues on the kernels it was taken on, bit for bit).
    """

    _rhs_work = None  # scratch of accelerations(), allocated at its first call

    def __init__(self, dyn, use_chain: bool | None = None, planar: bool | None = None):
        scene = dyn.scene
        asm = dyn.solver.assembly
        ldl = dyn.solver.ldl
        s = scene.springs
        f8 = lambda a: np.ascontiguousarray(a, np.float64)  # noqa: E731
        i8 = lambda a: np.ascontiguousarray(a, np.int64)  # noqa: E731
        self.dyn = dyn
        self.K, self.L = scene.K, scene.L
        fixed = np.asarray(scene.fixed, bool)
        drag_idx = np.flatnonzero((np.asarray(scene.drag) != 0.0) & ~fixed)
        self.scene = (i8(scene.k1), i8(scene.k2), f8(scene.length), f8(1.0 / scene.length), f8(scene.inv_mass),
                      i8(np.flatnonzero(fixed)), i8(drag_idx), f8(np.asarray(scene.drag)[drag_idx]), i8(s.a), i8(s.b),
                      f8(s.stiffness), f8(s.rest_length), f8(s.damping), i8(scene.free_indices))
        chain = chain_elimination(scene, asm) if dyn.structure.kind == "chain" else None
        if use_chain is None:
            use_chain = chain is not None
        if use_chain and chain is None:
            raise ValueError("the chain-specialised path needs a scene whose A is tridiagonal in path order")
        order, diag_weight, off_weight = chain if use_chain else (np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
        self.use_chain = bool(use_chain)
        n = max(scene.L, 1)
        self.system = (self.use_chain, i8(asm.ordering), i8(asm.pair_first), i8(asm.pair_second),
                       f8(asm.pair_weight), i8(asm.pair_slot), i8(asm.Ap), i8(asm.Ai), i8(ldl.Lp), i8(ldl.Li).copy(),
                       ldl.Lx.copy(), ldl.D.copy(), ldl.Dinv.copy(), i8(ldl.row_start), i8(ldl.row_col),
                       i8(ldl.row_slot), i8(order), f8(diag_weight), f8(off_weight), np.zeros(n),
                       np.zeros(max(asm.Ai.shape[0], 1)), np.zeros(n), np.zeros(n))
        free_mass = np.where(fixed, 0.0, scene.mass)
        F_scene = free_mass[:, None] * scene.gravity[None, :] + scene.force
        F_scene[fixed] = 0.0  # no force acts on an anchor
        self.F_scene = f8(F_scene)
        self.drag_masses = int(drag_idx.size)
        self.springs = int(s.count)
        self.damped_springs = int(np.count_nonzero(np.asarray(s.damping) != 0.0))
        plane = None if planar is False else scene_plane(scene, plane_normal(scene, dyn.structure.planar_normal))
        if planar and plane is None:
            raise ValueError(f"scene {scene.name!r} is not planar: the 2-D kernels cannot run it")
        self.planar = plane is not None
        self.is_planar_scene = self.planar
        if plane is not None:
            P, o, nrm, length = plane
            self.plane = (P, o, nrm, length, PLANE_TOL, np.ascontiguousarray(fixed, np.bool_))
            self._zero_input = np.zeros((self.K, 3))
            self._X2, self._U2, self._F2 = np.empty((self.K, 2)), np.empty((self.K, 2)), np.empty((self.K, 2))

    def force_3d(self) -> None:
        """Run every interval on the 3-D kernels, also for a planar scene (comparisons, benchmarks)."""
        self.is_planar_scene = self.planar = False

    @property
    def dim(self) -> int:
        """Components per vector of the kernels the next interval tries: 2 in a plane, else 3."""
        return 2 if self.planar else 3

    def base_forces(self, F_input) -> np.ndarray:
        """Gravity, constant forces and the held input: the part of F_k of (9) fixed over an interval, as a
        C-contiguous float64 (K,3) array."""
        if F_input is None:
            return self.F_scene
        if np.shape(F_input) != (self.K, 3):  # DirectCall does not check shapes (and + would broadcast)
            raise ValueError(f"the input forces must have shape {(self.K, 3)}, got {np.shape(F_input)}")
        return np.ascontiguousarray(self.F_scene + F_input, np.float64)

    def _plane_inputs(self, X, U, F_input):
        """(X, U, F_input) as the planar entries take them: C-contiguous float64 (K,3), zeros for no input."""
        F = self._zero_input if F_input is None else np.ascontiguousarray(F_input, np.float64)
        X, U = np.ascontiguousarray(X, np.float64), np.ascontiguousarray(U, np.float64)
        shape = (self.K, 3)
        if X.shape != shape or U.shape != shape or F.shape != shape:  # DirectCall does not check shapes
            raise ValueError(f"X, U and the input forces must have shape {shape}, got {X.shape}, {U.shape}, "
                             f"{F.shape}")
        return X, U, F

    def to_plane(self, Z, point: bool):
        """(K,3) -> (K,2) in-plane coordinates (tests, benchmarks; the step loops map inside the kernel)."""
        P, o = self.plane[0], self.plane[1]
        return np.ascontiguousarray(((np.asarray(Z) - o) if point else np.asarray(Z)) @ P)

    def from_plane(self, Z, point: bool):
        P, o = self.plane[0], self.plane[1]
        return Z @ P.T + (o if point else 0.0)

    def accelerations(self, X, U, F_input=None, planar: bool = False):
        """One compiled right-hand side evaluation from Python (the tensions Simulator.outputs reports; tests,
        benchmarks): (status, acc (K,3), T), status OK or SINGULAR (a vanishing pivot of A).
        ``planar``: evaluate it with the 2-D kernels in the plane's coordinates (the state must be planar)."""
        T = np.zeros(self.L)
        F = self.base_forces(F_input)  # (the loop zeroes its anchored rows, which are zero already)
        if planar:
            acc2 = np.empty((self.K, 2))
            status = int(accelerations_repeated(1, self.to_plane(X, True), self.to_plane(U, False),
                                                self.to_plane(F, False), self.scene, self.system, acc2, T))
            return status, self.from_plane(acc2, False), T
        X, U = np.ascontiguousarray(X, np.float64), np.ascontiguousarray(U, np.float64)
        if X.shape != (self.K, 3) or U.shape != (self.K, 3):  # DirectCall does not check shapes
            raise ValueError(f"X and U must have shape {(self.K, 3)}, got {X.shape} and {U.shape}")
        if self._rhs_work is None:  # E, F, B of one evaluation, kept: Simulator.outputs calls this every step
            self._rhs_work = (np.empty((self.L, 3)), np.empty((self.K, 3)), np.empty(self.L))
            self._rhs_3d = DirectCall(k3._accelerations_loop)
        acc = np.empty((self.K, 3))
        status = int(self._rhs_3d(1, X, U, F, *self.scene, *self.system, *self._rhs_work, acc, T, True))
        return status, acc, T

    def describe(self) -> str:
        """The compiled path this scene gets, in words (``linknet analyze``)."""
        solver = ("chain: tridiagonal A of (25) in path order, each right-hand side two sweeps along the path"
                  if self.use_chain else "general sparse LDL^T of A (25) on the pattern analysed once")
        if self.is_planar_scene:
            nrm = self.plane[2]
            aligned = bool(np.array_equal(np.abs(nrm), np.eye(3)[int(np.argmax(np.abs(nrm)))]))
            dims = (f"2-D planar (normal {np.round(nrm, 6).tolist()}, "
                    f"{'axis-aligned: exact reduction' if aligned else 'tilted: orthonormal in-plane basis'}; "
                    "an out-of-plane input force or state switches to 3-D)")
        else:
            dims = "3-D"
        terms = ["gravity, constant and input forces summed once per interval"]
        if self.drag_masses:
            terms.append(f"drag on {self.drag_masses} mass{'es' if self.drag_masses != 1 else ''}")
        if self.springs:
            terms.append(f"{self.springs} spring{'s' if self.springs != 1 else ''}"
                         + (f" ({self.damped_springs} damped)" if self.damped_springs else ""))
        if not (self.drag_masses or self.springs):
            terms.append("no drag or springs: no force evaluation per step")
        return f"{solver}; {dims}; forces: {', '.join(terms)}"


class CompiledRattle(CompiledScene):
    """The RATTLE/composition loop for one scene (in the plane's coordinates while the scene is planar)."""

    def __init__(self, dyn, use_chain: bool | None = None, planar: bool | None = None):
        super().__init__(dyn, use_chain=use_chain, planar=planar)
        self.scratch = rattle_scratch(self.K, self.L)
        if self.planar:
            self.scratch2 = rattle_scratch(self.K, self.L, 2)
        self._steps_in_plane = DirectCall(k2._rattle_steps_in_plane)
        self._steps_3d = DirectCall(k3._rattle_steps)
        self._gamma_arrays = {}  # the integrator's gammas tuple -> the float64 array the loops take

    completed_steps = 0  # steps the last advance completed (all of them on OK; before the failing one otherwise)

    def advance(self, X, U, n_steps, h, gammas, F_input, tol):
        """Returns (status, X, U): new (K,3) arrays; X, U are not modified. On a non-OK status X, U stop inside
        the failing step, after ``completed_steps`` whole ones."""
        key = gammas if isinstance(gammas, tuple) else tuple(np.ravel(gammas).tolist())
        gamma_array = self._gamma_arrays.get(key)
        if gamma_array is None:
            gamma_array = self._gamma_arrays[key] = np.array(key, np.float64)
        if self.planar:
            X3, U3, F_in = self._plane_inputs(X, U, F_input)
            X_out, U_out = np.empty((self.K, 3)), np.empty((self.K, 3))
            status, self.completed_steps = self._steps_in_plane(
                X3, U3, self.F_scene, F_in, X_out, U_out, *self.plane, int(n_steps), float(h), gamma_array,
                self._X2, self._U2, self._F2, *self.scene, *self.system, *self.scratch2, float(tol), 50)
            if status != LEFT_PLANE:
                return status, X_out, U_out
            self.planar = False  # the state or the input left the plane: 3-D from here on
        Xw = np.array(X, dtype=np.float64, copy=True, order="C")
        Uw = np.array(U, dtype=np.float64, copy=True, order="C")
        status, self.completed_steps = self._steps_3d(Xw, Uw, int(n_steps), float(h), gamma_array,
                                                      self.base_forces(F_input), *self.scene, *self.system,
                                                      *self.scratch, float(tol), 50)
        return status, Xw, Uw


def supports(dyn) -> bool:
    """The compiled kernels handle the LDL^T structures (chain, tree, general), not the redundant one."""
    return dyn.structure.kind != "redundant" and hasattr(dyn.solver, "ldl")


def describe(dyn) -> str:
    """Which compiled path a scene gets (tension solver, 2-D or 3-D, force terms), or why it gets none."""
    if not supports(dyn):
        return (f"none: {dyn.structure.kind} scenes take the numpy path (minimum-norm tensions)"
                if dyn.structure.kind == "redundant" else "none: this tension solver has no compiled path")
    return CompiledScene(dyn).describe()


# ------------------------------------------------------------------------------------------------ planar module
KERNELS_SOURCE = Path(__file__).resolve().parent / "compiled_kernels.py"
PLANAR_MODULE = Path(__file__).resolve().parent / "compiled_kernels_2d.py"
_DIM_LINE = "DIM = 3  # components of a vector (the generated planar module has 2)\n"


def planar_module_source() -> str:
    """The text of compiled_kernels_2d.py: compiled_kernels.py with DIM = 2 (and a header saying so)."""
    src = KERNELS_SOURCE.read_text()
    if not src.startswith('"""') or src.count(_DIM_LINE) != 1:
        raise RuntimeError(f"{KERNELS_SOURCE} must start with its docstring and hold the line {_DIM_LINE!r} once")
    header = ("GENERATED from linknet_core/compiled_kernels.py with DIM = 2 by "
              "`python -m linknet_core.compiled --write-planar`;\ndo not edit (tests/test_core_compiled_planar.py "
              "checks that it is in sync).\n\n")
    return '"""' + header + src[3:].replace(_DIM_LINE, "DIM = 2  # generated: the planar kernels\n")


if __name__ == "__main__":
    if sys.argv[1:] != ["--write-planar"]:
        sys.exit("usage: python -m linknet_core.compiled --write-planar")
    PLANAR_MODULE.write_text(planar_module_source())
    print(f"wrote {PLANAR_MODULE}")
