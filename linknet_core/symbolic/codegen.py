"""Scene-specialised compiled kernels of the right-hand side, generated with casadi.

For one scene, :func:`compiled_rhs` generates C code for

    (X, U, F_input) -> forces F_k (9) -> A(X) (25), B(X, U, F) (26) -> A T = B -> dU/dt (9)

from the symbolic derivation of :mod:`linknet_core.symbolic.derivation`, compiles it with the system's C compiler,
caches the shared library on disk and calls it through ctypes (no casadi in the call path, no Python
loop; the caller's (K,3) arrays are passed by pointer, and the gather of the free coordinates, the
scatter of the accelerations and the input validation happen in the generated code). The kernel
contains only what the scene needs:

* anchored masses are eliminated (their positions are constants of the code, 1/M = 0 terms vanish),
* only the masses named as force inputs get an input term (default: every free mass),
* force elements the scene does not have (springs, drag, ...) produce no code,
* a planar scene (every position, velocity, gravity and constant force in one plane) gets a 2-D
  kernel in the plane's coordinates; a state that leaves the plane is handed to a 3-D kernel,
* A is handled with the scene's own sparsity: casadi's sparse LDL^T (``ldl`` plugin) with a
  symbolic analysis fixed at generation time.

The tension solve has no pivoting, like the core's LDL^T path: a singular A (redundant links, or a loop
passing through a singular position) produces non-finite values, which are detected and the call is
handed to the ``fallback`` (the numeric path), which gives the minimum-norm tensions. Scenes whose
tension matrix is singular at the initial state (redundant structures) get no kernel.

Cache: ``$LINKNET_CACHE_DIR``, else ``$XDG_CACHE_HOME/linknet``, else ``~/.cache/linknet``; files under
``kernels/`` are named by a hash of the scene description, the kernel variant and the casadi version.
"""

from __future__ import annotations

import ctypes
import hashlib
import json
import math
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import casadi as ca

from linknet_core.symbolic.derivation import SymbolicTensionSystem

__all__ = [
    "CodegenUnavailable",
    "CompiledRHS",
    "compiled_rhs",
    "compiler",
    "cache_dir",
    "plane_of",
]

KERNEL_FORMAT = 3  # bump when the generated code changes meaning (invalidates the cache); 3: quadratic drag
CFLAGS = ["-O2", "-fPIC", "-shared"]


try:  # the core's error hierarchy, when present
    from linknet_core.errors import LinknetError as _Base
except ImportError:  # pragma: no cover - symbolic/codegen developed before the core landed
    _Base = ValueError


class CodegenUnavailable(_Base):
    """No compiled kernel can be made for this scene here (no C compiler, singular tension matrix...)."""


_DRIVEN_REFUSAL = ("scene {name!r} has driven anchors: the generated kernel takes no anchor motion "
                   "(P, V, A); the numeric path is used")


def compiler() -> str | None:
    """Path of the C compiler to use ($CC, else cc, else gcc), or None."""
    for candidate in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if candidate:
            path = shutil.which(candidate)
            if path:
                return path
    return None


def cache_dir() -> Path:
    root = os.environ.get("LINKNET_CACHE_DIR")
    if root:
        return Path(root)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "linknet"


def plane_of(scene, rtol: float = 1e-12):
    """(basis (3,2), origin (3,), normal (3,)) of the plane holding the whole scene, or None.

    The scene is planar when positions, velocities, gravity and constant forces all lie in one plane
    (springs, drag and links then keep every motion in it). Axis-aligned planes get an exact 0/1 basis
    and a zero origin component along the normal, so reducing to the plane introduces no round-off.
    """
    X = np.asarray(scene.X0, float)
    origin = X.mean(axis=0)
    vectors = np.vstack([X - origin, scene.U0, np.asarray(scene.gravity)[None, :], scene.force])
    scale = np.abs(vectors).max()
    if not scale > 0:
        return None
    _, s, vt = np.linalg.svd(vectors / scale, full_matrices=True)
    if s[2] > rtol * max(s[0], 1e-300):
        return None
    normal = vt[2]
    axis = int(np.argmax(np.abs(normal)))
    others = [a for a in range(3) if a != axis]
    if np.all(np.abs(normal[others]) <= rtol):  # axis-aligned: exact reduction
        basis = np.eye(3)[:, others]
        normal = np.eye(3)[axis]
        plane_origin = np.zeros(3)
        plane_origin[axis] = X[0, axis]
        return basis, plane_origin, normal
    basis = vt[:2].T.copy()
    return basis, origin, normal


def _scene_key(scene, variant: dict) -> str:
    payload = json.dumps({"scene": scene.to_dict(), "variant": variant, "casadi": ca.__version__,
                          "format": KERNEL_FORMAT, "cflags": CFLAGS}, sort_keys=True, default=float)
    return hashlib.sha256(payload.encode()).hexdigest()[:24]


def build_rhs_function(scene, basis=None, origin=None, input_masses=None, name="lnk_rhs"):
    """The casadi Function rhs(X, U, F_in) -> (acc, T, flags) of one scene, on full (K,3) arrays.

    X, U, F_in are the row-major flattenings of (K,3) arrays (so numpy buffers are passed as they are);
    acc is (K,3) flattened, zero on anchored masses. Inside, only the free masses' coordinates in the
    kept basis are read, only the input masses' forces. ``flags`` (4,) lets the caller validate the
    call without touching the arrays again:

    * flags[0]: out-of-plane content sum |n.(X_k - o)| + |n.U_k| + |n.F_k| (0 for a 3-D kernel),
    * flags[1]: sum |F_in| over masses that are not inputs of this kernel (must be 0),
    * flags[2]: sum(acc) + sum(T), non-finite when the LDL^T met a singular A,
    * flags[3]: scale sum |X_k - o| + |U_k| + |F_k| for the relative out-of-plane test of tilted planes.

    Also returns the symbolic system it was made from.
    """
    sym = SymbolicTensionSystem(scene, basis=basis, origin=origin)
    K, L, d, nf = sym.K, sym.L, sym.dim, sym.nf
    free = sym.free
    inputs = free if input_masses is None else np.asarray(input_masses, np.int64)
    Ffn = sym.forces_function(inputs)
    P = sym.basis
    o = sym.origin
    Xf = ca.MX.sym("X", 3 * K)
    Uf = ca.MX.sym("U", 3 * K)
    Fi = ca.MX.sym("F_in", 3 * K)
    Xm, Um, Fm = (ca.reshape(v, 3, K) for v in (Xf, Uf, Fi))   # column k = mass k
    axes = [int(np.argmax(P[:, j])) for j in range(d)]
    aligned = bool(np.array_equal(P, np.eye(3)[:, axes]) and not np.any(o[axes]))

    def reduce(M, cols, point):
        if aligned:  # pure gather: exact, no arithmetic
            return ca.reshape(M[axes, cols.tolist()], d * cols.size, 1)
        Z = M[:, cols.tolist()]
        if point:
            Z = Z - ca.repmat(ca.DM(o), 1, cols.size)
        return ca.reshape(ca.mtimes(ca.sparsify(ca.DM(P.T)), Z), d * cols.size, 1)

    x = reduce(Xm, free, True)
    u = reduce(Um, free, False)
    fin = reduce(Fm, inputs, False) if inputs.size else ca.MX(0, 1)
    if sym.nd:
        raise CodegenUnavailable(_DRIVEN_REFUSAL.format(name=scene.name))
    none = ca.MX(0, 1)                                  # no driven anchors: their p, v, a are empty
    F = Ffn(x, u, fin, none, none)
    A = sym.A_fn(x, none)
    B = sym.B_fn(x, u, F, none, none, none)
    T = ca.solve(A, B, "ldl")  # sparse LDL^T on the scene's sparsity, analysed once here
    acc_r = ca.reshape(sym.acc_fn(x, F, T, none), d, nf)
    acc3 = acc_r if d == 3 and aligned and axes == [0, 1, 2] else ca.mtimes(ca.sparsify(ca.DM(P)), acc_r)
    scatter = ca.DM.triplet(list(range(nf)), free.tolist(), [1.0] * nf, nf, K)   # free column j -> mass
    acc_full = ca.reshape(ca.mtimes(acc3, scatter), 3 * K, 1)
    if d < 3:
        normal = np.cross(P[:, 0], P[:, 1])
        nd = ca.sparsify(ca.DM(normal).T)
        off_plane = (ca.sum2(ca.fabs(ca.mtimes(nd, Xm) - float(normal @ o)))
                     + ca.sum2(ca.fabs(ca.mtimes(nd, Um))) + ca.sum2(ca.fabs(ca.mtimes(nd, Fm))))
        scale = ca.sum1(ca.sum2(ca.fabs(Xm - ca.repmat(ca.DM(o), 1, K)))) + ca.sum1(ca.sum2(ca.fabs(Um))) \
            + ca.sum1(ca.sum2(ca.fabs(Fm)))
    else:
        off_plane = ca.MX(0.0)
        scale = ca.MX(1.0)
    others = np.setdiff1d(np.arange(K), inputs)
    ignored = ca.sum1(ca.sum2(ca.fabs(Fm[:, others.tolist()]))) if others.size else ca.MX(0.0)
    finite = ca.sum1(ca.reshape(acc_r, d * nf, 1)) + ca.sum1(T)
    flags = ca.vertcat(off_plane, ignored, finite, scale)
    # dense outputs: the C function writes every entry of the caller's buffers (structural zeros too)
    fn = ca.Function(name, [Xf, Uf, Fi], [ca.densify(acc_full), ca.densify(T), ca.densify(flags)],
                     ["X", "U", "F_in"], ["acc", "T", "flags"])
    return fn, sym


def generate_and_compile(fn: ca.Function, directory: Path, stem: str, cc: str) -> tuple[Path, dict]:
    """Write C code for ``fn`` and compile it to ``directory/stem.so`` (atomic). Returns path, timings."""
    import time

    directory.mkdir(parents=True, exist_ok=True)
    so_path = directory / f"{stem}.so"
    c_path = directory / f"{stem}.c"
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory(dir=directory) as tmp:
        cg = ca.CodeGenerator(f"{stem}.c", {"casadi_int": "long long int", "with_header": False})
        cg.add(fn)
        generated = cg.generate(str(tmp) + os.sep)
        t1 = time.perf_counter()
        tmp_so = Path(tmp) / f"{stem}.so"
        proc = subprocess.run([cc, *CFLAGS, generated, "-o", str(tmp_so), "-lm"],
                              capture_output=True, text=True)
        if proc.returncode != 0:
            raise CodegenUnavailable(f"compiling the generated kernel with {cc} failed:\n{proc.stderr[-2000:]}")
        t2 = time.perf_counter()
        os.replace(generated, c_path)
        os.replace(tmp_so, so_path)
    return so_path, {"codegen_s": t1 - t0, "compile_s": t2 - t1}


class _CasadiKernel:
    """ctypes binding of one generated casadi function (fixed-size dense vector inputs/outputs)."""

    def __init__(self, so_path: Path, name: str, n_in: list[int], n_out: list[int]):
        self.lib = ctypes.CDLL(str(so_path))
        LL = ctypes.c_longlong
        work = getattr(self.lib, f"{name}_work")
        sz = [LL() for _ in range(4)]
        if work(*[ctypes.byref(v) for v in sz]) != 0:
            raise CodegenUnavailable(f"{so_path}: {name}_work failed")
        sz_arg, sz_res, sz_iw, sz_w = (int(v.value) for v in sz)
        self.inputs = [np.zeros(n) for n in n_in]
        self.outputs = [np.zeros(n) for n in n_out]
        self._iw = np.zeros(max(sz_iw, 1), dtype=np.int64)
        self._w = np.zeros(max(sz_w, 1))
        self._arg = (ctypes.c_void_p * max(sz_arg, len(n_in)))()
        self._res = (ctypes.c_void_p * max(sz_res, len(n_out)))()
        for i, buf in enumerate(self.inputs):
            self._arg[i] = buf.ctypes.data
        for i, buf in enumerate(self.outputs):
            self._res[i] = buf.ctypes.data
        incref = getattr(self.lib, f"{name}_incref", None)
        if incref is not None:
            incref()
        checkout = getattr(self.lib, f"{name}_checkout", None)
        self._mem = int(checkout()) if checkout is not None else 0
        self._fn = getattr(self.lib, name)
        self._fn.restype = ctypes.c_int
        self._fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int]
        self._call_args = (ctypes.addressof(self._arg), ctypes.addressof(self._res),
                           self._iw.ctypes.data, self._w.ctypes.data, self._mem)

    def __call__(self) -> int:
        return self._fn(*self._call_args)


class _Variant:
    """One compiled kernel (planar or 3-D): the (K,3) arrays are handed to C by pointer, no copies."""

    def __init__(self, so_path, K, L, d, aligned):
        self.d = d
        self.aligned = aligned
        self.kernel = _CasadiKernel(so_path, "lnk_rhs", [0, 0, 0], [3 * K, L, 4])
        self.acc_out, self.T_out, self.flags = self.kernel.outputs
        self._arg = self.kernel._arg

    def run(self, X, U, F):
        arg = self._arg
        arg[0] = X.ctypes.data
        arg[1] = U.ctypes.data
        arg[2] = F.ctypes.data
        return self.kernel()


class CompiledRHS:
    """Compiled right-hand side of one scene: ``accelerations(X, U, F_input) -> (acc (K,3), T (L,))``.

    Same contract as ``Dynamics.accelerations``: acc is zero on anchored masses, T > 0 is tension.
    ``fallback(X, U, F_input)`` (the numeric path) is called when the kernel's LDL^T meets a singular A.
    A state that leaves a planar scene's plane is handed to a 3-D kernel (generated on first need).
    Not thread-safe: one set of output buffers per object.
    """

    def __init__(self, scene, input_masses=None, fallback=None, plane="auto", cache=None, cc=None):
        self._init_args = (scene, input_masses, fallback, plane, cache, cc)
        self.scene = scene
        self.K, self.L = int(scene.K), int(scene.L)
        free = np.flatnonzero(np.asarray(scene.inv_mass) > 0)
        self.input_masses = free if input_masses is None else np.asarray(input_masses, np.int64)
        self.fallback = fallback
        self.cache = Path(cache) if cache is not None else cache_dir() / "kernels"
        self.cc = cc or compiler()
        if self.cc is None:
            raise CodegenUnavailable("no C compiler found ($CC, cc, gcc, clang): the numeric path is used")
        self.timings: dict = {}
        self.fallback_calls = 0
        self.calls_3d = 0
        self._zeros = np.zeros((self.K, 3))
        self._zeros.setflags(write=False)
        pl = plane_of(scene) if plane == "auto" else None
        self.plane = pl
        self._variant3 = None
        if pl is not None:
            basis, origin, normal = pl
            self._aligned_plane = bool(np.max(np.abs(normal)) == 1.0)
            self._primary = self._build(basis, origin)
        else:
            self._primary = self._variant3 = self._build(np.eye(3), np.zeros(3))

    def __reduce__(self):
        """Pickle / deepcopy by rebuilding: the kernel itself is reloaded from the disk cache."""
        return (type(self), self._init_args)

    # -- building --
    def _build(self, basis, origin):
        variant = {"basis": np.round(basis, 15).tolist(), "origin": np.asarray(origin).tolist(),
                   "inputs": self.input_masses.tolist(), "cc": Path(self.cc).name}
        stem = "lnk_" + _scene_key(self.scene, variant)
        so_path = self.cache / f"{stem}.so"
        d = basis.shape[1]
        axes = [int(np.argmax(basis[:, j])) for j in range(d)]
        aligned = bool(np.array_equal(basis, np.eye(3)[:, axes]) and not np.any(np.asarray(origin)[axes]))
        if so_path.exists():
            self.timings["cache_hits"] = self.timings.get("cache_hits", 0) + 1
        else:
            import time

            t0 = time.perf_counter()
            fn, _ = build_rhs_function(self.scene, basis=basis, origin=origin, input_masses=self.input_masses)
            t1 = time.perf_counter()
            try:
                so_path, t = generate_and_compile(fn, self.cache, stem, self.cc)
            except OSError as exc:
                raise CodegenUnavailable(f"cannot write the kernel cache {self.cache} (set LINKNET_CACHE_DIR): "
                                         f"{exc}") from None
            self.timings.update({"symbolic_s": t1 - t0, **t})
        self.so_path = so_path
        variant = _Variant(so_path, self.K, self.L, d, aligned)
        n_free = int(np.count_nonzero(np.asarray(self.scene.inv_mass) > 0))
        variant.coordinates = d * n_free                    # symbols of the kernel: free masses only
        variant.input_coordinates = d * int(self.input_masses.size)
        return variant

    def _left_plane(self, flags) -> bool:
        if self._aligned_plane:  # exact: integrators keep these components exactly constant
            return flags[0] != 0.0
        return flags[0] > 1e-12 * (1.0 + flags[3])

    # -- evaluation --
    def _as_array(self, Z, what):
        Z = np.ascontiguousarray(Z, dtype=float)
        if Z.shape != (self.K, 3):
            raise ValueError(f"{what} must have shape ({self.K}, 3), got {Z.shape}")
        return Z

    def accelerations(self, X, U, F_input=None):
        X = self._as_array(X, "positions X")
        U = self._as_array(U, "velocities U")
        F = self._zeros if F_input is None else self._as_array(F_input, "input forces F_input")
        variant = self._primary
        status = variant.run(X, U, F)
        flags = variant.flags
        if flags[1] != 0.0:
            others = np.setdiff1d(np.arange(self.K), self.input_masses)
            k = int(others[np.flatnonzero(np.any(F[others] != 0, axis=1))[0]])
            raise ValueError(f"input force on mass {k + 1}, which this kernel was built without "
                             "(not among its input masses)")
        if variant is not self._variant3 and self._left_plane(flags):
            if self._variant3 is None:
                self._variant3 = self._build(np.eye(3), np.zeros(3))
            variant = self._variant3
            self.calls_3d += 1
            status = variant.run(X, U, F)
            flags = variant.flags
        if status != 0 or not math.isfinite(flags[2]):
            if self.fallback is None:
                raise CodegenUnavailable("the compiled kernel met a singular tension matrix and has no fallback")
            self.fallback_calls += 1
            return self.fallback(X, U, F_input)
        return variant.acc_out.reshape(self.K, 3).copy(), variant.T_out.copy()


def compiled_rhs(scene, input_masses=None, fallback=None, required=False, cache=None):
    """A :class:`CompiledRHS` for ``scene``, cached on disk; None when it cannot be made here.

    None (or :class:`CodegenUnavailable` with ``required=True``) when there is no C compiler, or when the
    tension matrix is singular at the scene's initial state (redundant links: the minimum-norm tensions
    need the rank-revealing numeric path).
    """
    try:
        if compiler() is None:
            raise CodegenUnavailable("no C compiler found ($CC, cc, gcc, clang): the numeric path is used")
        driven = getattr(scene, "driven", None)
        if driven is not None and np.any(driven):
            raise CodegenUnavailable(_DRIVEN_REFUSAL.format(name=scene.name))
        _require_regular(scene)
        return CompiledRHS(scene, input_masses=input_masses, fallback=fallback, cache=cache)
    except CodegenUnavailable:
        if required:
            raise
        return None


def _require_regular(scene):
    """Refuse redundant scenes: A = C M^-1 C^T singular at the initial state (rank of C < L)."""
    L = int(scene.L)
    if L == 0:
        raise CodegenUnavailable(f"scene {scene.name!r} has no links")
    X = np.asarray(scene.X0, float)
    E = (X[scene.k2] - X[scene.k1]) / np.asarray(scene.length)[:, None]
    free = np.flatnonzero(np.asarray(scene.inv_mass) > 0)
    col = -np.ones(int(scene.K), np.int64)
    col[free] = np.arange(free.size)
    if 3 * free.size < L:
        raise CodegenUnavailable(f"scene {scene.name!r} has more links ({L}) than free coordinates: redundant")
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    rows, cols, vals = [], [], []
    for side, kk, sign in ((0, scene.k1, 1.0), (1, scene.k2, -1.0)):
        c = col[kk]
        keep = c >= 0
        rows.append(np.repeat(np.flatnonzero(keep), 3))
        cols.append((3 * c[keep][:, None] + np.arange(3)).ravel())
        vals.append((sign * E[keep]).ravel())
    C = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(L, 3 * free.size))
    if L <= 1500:
        s = np.linalg.svd(C.toarray(), compute_uv=False)
        regular = s.size == L and s[-1] > 1e-9 * s[0]
    else:  # large: a sparse LU of C C^T (no pivoting trouble for the regular case)
        try:
            lu = spla.splu((C @ C.T).tocsc())
            d = np.abs(lu.U.diagonal())
            regular = d.min() > 1e-12 * d.max()
        except RuntimeError:
            regular = False
    if not regular:
        raise CodegenUnavailable(f"scene {scene.name!r}: the tension matrix is singular at the initial state "
                                 "(redundant links); the minimum-norm numeric path is used")
