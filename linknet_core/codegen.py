"""Scene-specialised compiled kernels of the right-hand side, generated with casadi.

For one scene, :func:`compiled_rhs` generates C code for

    (X, U, F_input) -> forces F_k (9) -> A(X) (25), B(X, U, F) (26) -> A T = B -> dU/dt (9)

from the symbolic derivation of :mod:`linknet_core.symbolic`, compiles it with the system's C compiler,
caches the shared library on disk and calls it through ctypes (no casadi in the call path, no Python
loop, preallocated buffers). The kernel contains only what the scene needs:

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
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import numpy as np
import casadi as ca

from .symbolic import SymbolicTensionSystem

__all__ = [
    "CodegenUnavailable",
    "CompiledRHS",
    "compiled_rhs",
    "compiler",
    "cache_dir",
    "plane_of",
]

KERNEL_FORMAT = 1  # bump when the generated code changes meaning (invalidates the cache)
CFLAGS = ["-O2", "-fPIC", "-shared"]


try:  # the core's error hierarchy, when present
    from .errors import LinknetError as _Base
except ImportError:  # pragma: no cover - symbolic/codegen developed before the core landed
    _Base = ValueError


class CodegenUnavailable(_Base):
    """No compiled kernel can be made for this scene here (no C compiler, singular tension matrix...)."""


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
    """The casadi Function rhs(x, u, fin) -> (acc, T) of one scene (reduced coordinates).

    Also returns the symbolic system it was made from.
    """
    sym = SymbolicTensionSystem(scene, basis=basis, origin=origin)
    Ffn = sym.forces_function(input_masses)
    x = ca.MX.sym("x", sym.n)
    u = ca.MX.sym("u", sym.n)
    fin = ca.MX.sym("fin", Ffn.size1_in(2))
    F = Ffn(x, u, fin)
    A = sym.A_fn(x)
    B = sym.B_fn(x, u, F)
    T = ca.solve(A, B, "ldl")  # sparse LDL^T on the scene's sparsity, analysed once here
    acc = sym.acc_fn(x, F, T)
    return ca.Function(name, [x, u, fin], [acc, T], ["x", "u", "fin"], ["acc", "T"]), sym


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
    """One compiled kernel (planar or 3-D) with the index arrays that feed it."""

    def __init__(self, scene, basis, origin, input_masses, so_path, n, L, n_in):
        self.basis = basis
        self.origin = origin
        self.d = basis.shape[1]
        self.free = np.flatnonzero(np.asarray(scene.inv_mass) > 0)
        self.input_masses = input_masses
        self.kernel = _CasadiKernel(so_path, "lnk_rhs", [n, n, n_in], [n, L])
        # axis-aligned basis (identity, or two coordinate axes of a plane with a zero origin in them):
        # reduction is a gather of flat indices, exact and cheap
        axes = [int(np.argmax(basis[:, j])) for j in range(self.d)]
        self.gather = bool(np.array_equal(basis, np.eye(3)[:, axes]) and not np.any(origin[axes]))
        self.free_flat = (3 * self.free[:, None] + np.asarray(axes)[None, :]).ravel()
        self.input_flat = (3 * input_masses[:, None] + np.asarray(axes)[None, :]).ravel()

    def run(self, X, U, F_input):
        k = self.kernel
        x, u, fin = k.inputs
        if self.gather:
            np.take(X, self.free_flat, out=x)
            np.take(U, self.free_flat, out=u)
            if fin.size:
                if F_input is None:
                    fin.fill(0.0)
                else:
                    np.take(F_input, self.input_flat, out=fin)
        else:
            x[:] = ((X[self.free] - self.origin) @ self.basis).ravel()
            u[:] = (U[self.free] @ self.basis).ravel()
            if fin.size:
                fin[:] = 0.0 if F_input is None else (F_input[self.input_masses] @ self.basis).ravel()
        status = k()
        acc_r, T = k.outputs
        return status, acc_r, T

    def expand(self, acc_r, K):
        acc = np.zeros((K, 3))
        if self.gather:
            acc.put(self.free_flat, acc_r)
        else:
            acc[self.free] = acc_r.reshape(-1, self.d) @ self.basis.T
        return acc


class CompiledRHS:
    """Compiled right-hand side of one scene: ``accelerations(X, U, F_input) -> (acc (K,3), T (L,))``.

    Same contract as ``Dynamics.accelerations``: acc is zero on anchored masses, T > 0 is tension.
    ``fallback(X, U, F_input)`` (the numeric path) is called when the kernel's LDL^T meets a singular A.
    A state that leaves a planar scene's plane is handed to a 3-D kernel (generated on first need).
    """

    def __init__(self, scene, input_masses=None, fallback=None, plane="auto", cache=None, cc=None):
        self._init_args = (scene, input_masses, fallback, plane, cache, cc)
        self.scene = scene
        self.K, self.L = int(scene.K), int(scene.L)
        free = np.flatnonzero(np.asarray(scene.inv_mass) > 0)
        self.input_masses = free if input_masses is None else np.asarray(input_masses, np.int64)
        self._input_mask = np.zeros(self.K, bool)
        self._input_mask[self.input_masses] = True
        self._check_inputs = not self._input_mask[free].all()
        self.fallback = fallback
        self.cache = Path(cache) if cache is not None else cache_dir() / "kernels"
        self.cc = cc or compiler()
        if self.cc is None:
            raise CodegenUnavailable("no C compiler found ($CC, cc, gcc, clang): the numeric path is used")
        self.timings: dict = {}
        self.fallback_calls = 0
        self.calls_3d = 0
        pl = plane_of(scene) if plane == "auto" else None
        self.plane = pl
        self._variant3 = None
        if pl is not None:
            basis, origin, normal = pl
            self._normal = normal
            self._plane_offset = float(origin @ normal)
            axis = int(np.argmax(np.abs(normal)))
            self._axis_aligned = bool(normal[axis] == 1.0)
            self._out_flat = 3 * np.arange(self.K) + axis    # out-of-plane coordinates
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
        n = int(np.count_nonzero(np.asarray(self.scene.inv_mass) > 0)) * d
        if so_path.exists():
            self.timings["cache_hits"] = self.timings.get("cache_hits", 0) + 1
        else:
            import time

            t0 = time.perf_counter()
            fn, _ = build_rhs_function(self.scene, basis=basis, origin=origin, input_masses=self.input_masses)
            t1 = time.perf_counter()
            so_path, t = generate_and_compile(fn, self.cache, stem, self.cc)
            self.timings.update({"symbolic_s": t1 - t0, **t})
        self.so_path = so_path
        return _Variant(self.scene, basis, origin, self.input_masses, so_path, n, self.L,
                        self.input_masses.size * d)

    def _in_plane(self, X, U, F_input) -> bool:
        if self._axis_aligned:  # exact test: the integrators keep these components exactly constant
            idx = self._out_flat
            if (X.take(idx) != self._plane_offset).any() or U.take(idx).any():
                return False
            return F_input is None or not F_input.take(idx).any()
        n = self._normal
        tol = 1e-12
        if np.abs(X @ n - self._plane_offset).max() > tol * (1.0 + float(np.abs(X).max())):
            return False
        if np.abs(U @ n).max() > tol * (1.0 + float(np.abs(U).max())):
            return False
        if F_input is not None and np.abs(F_input @ n).max() > tol * (1.0 + float(np.abs(F_input).max())):
            return False
        return True

    # -- evaluation --
    def accelerations(self, X, U, F_input=None):
        X = np.asarray(X, dtype=float)
        U = np.asarray(U, dtype=float)
        if F_input is not None:
            F_input = np.asarray(F_input, dtype=float)
            if self._check_inputs and np.any(F_input[~self._input_mask]):
                k = int(np.flatnonzero(np.any(F_input != 0, axis=1) & ~self._input_mask)[0])
                raise ValueError(f"input force on mass {k + 1}, which this kernel was built without "
                                 "(not among its input masses)")
        variant = self._primary
        if self.plane is not None and not self._in_plane(X, U, F_input):
            if self._variant3 is None:
                self._variant3 = self._build(np.eye(3), np.zeros(3))
            variant = self._variant3
            self.calls_3d += 1
        status, acc_r, T = variant.run(X, U, F_input)
        if status != 0 or not np.isfinite(T.sum() + acc_r.sum()):
            if self.fallback is None:
                raise CodegenUnavailable("the compiled kernel met a singular tension matrix and has no fallback")
            self.fallback_calls += 1
            return self.fallback(X, U, F_input)
        return variant.expand(acc_r, self.K), T.copy()


def compiled_rhs(scene, input_masses=None, fallback=None, required=False, cache=None):
    """A :class:`CompiledRHS` for ``scene``, cached on disk; None when it cannot be made here.

    None (or :class:`CodegenUnavailable` with ``required=True``) when there is no C compiler, or when the
    tension matrix is singular at the scene's initial state (redundant links: the minimum-norm tensions
    need the rank-revealing numeric path).
    """
    try:
        if compiler() is None:
            raise CodegenUnavailable("no C compiler found ($CC, cc, gcc, clang): the numeric path is used")
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
