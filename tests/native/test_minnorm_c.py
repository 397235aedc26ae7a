"""Minimum-norm tension solves in C (linknet_core/native/src/stages/minnorm.c) against numpy.

Where links are redundant, A = C M^-1 C^T of (25) is singular: its null space is the self-stresses, the
homogeneous solutions of (27), which put no force on any free mass (31). For a consistent B every solution of
A T = B gives the same forces, and the reported tensions are the minimum-norm solution A^+ B. Checked here on
redundant scenes (a prism truss, a net with diagonals, a triangulated net, a taut string) and regular ones:
the C solution solves the system, has no self-stress component, equals the eigen-decomposition's A^+ B, has
numpy's rank, gives the forces of any other solution; the iterative path agrees with the dense one, and the
2-D copy with the 3-D one on planar scenes.

The package's own library is not needed: a private one is compiled from tests/native/c/minnorm_driver.c,
which includes stages/minnorm.c for DIM = 3 and DIM = 2, with the package's compiler flags and -Werror.

Timings (never asserted): python tests/native/test_minnorm_c.py
"""
from __future__ import annotations

import ctypes
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from linknet_core.scene import builders
from linknet_core.scene.description import Scene
from linknet_core.structure.topology import link_pairs
from linknet_core.tolerances import SINGULAR_RCOND

HERE = Path(__file__).resolve().parent
SOURCE_DIR = HERE.parents[1] / "linknet_core" / "native" / "src"
DRIVER = HERE / "c" / "minnorm_driver.c"
FLAGS = ["-std=c99", "-O3", "-fno-math-errno", "-ffp-contract=off", "-Wall", "-Wextra", "-Werror"]
STOP_CONVERGED = 1  # enum mn_stop in minnorm.c

c_double_p = ctypes.POINTER(ctypes.c_double)
c_int64_p = ctypes.POINTER(ctypes.c_int64)


def _compilers() -> list[str]:
    names = [os.environ.get("CC"), "cc", "gcc", "clang"]
    found = []
    for name in names:
        if name and shutil.which(name) and name not in found:
            found.append(name)
    return found


def _build(compiler: str, out_dir: Path, extra=()) -> Path:
    out = out_dir / f"minnorm_driver_{Path(compiler).name}.so"
    cmd = [compiler, *FLAGS, *extra, "-fPIC", "-shared", "-I", str(SOURCE_DIR), str(DRIVER), "-o", str(out), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, f"{' '.join(cmd)}\n{proc.stderr}"
    return out


class Driver:
    """ctypes view of minnorm_driver.c."""

    def __init__(self, path: Path):
        lib = ctypes.CDLL(str(path))
        lib.mn_new.restype = ctypes.c_void_p
        lib.mn_set_model.argtypes = [ctypes.c_void_p, ctypes.c_int, ctypes.c_int64, ctypes.c_int64, c_int64_p,
                                     c_int64_p, c_double_p, ctypes.c_int64, c_int64_p, c_int64_p, c_double_p,
                                     ctypes.c_double, ctypes.c_int64]
        lib.mn_factor.argtypes = [ctypes.c_void_p, c_double_p]
        lib.mn_factor.restype = ctypes.c_int
        lib.mn_solve.argtypes = [ctypes.c_void_p, c_double_p, c_double_p]
        lib.mn_rank.argtypes = [ctypes.c_void_p]
        lib.mn_rank.restype = ctypes.c_int64
        lib.mn_cg_info.argtypes = [ctypes.c_void_p, c_int64_p, c_double_p, ctypes.POINTER(ctypes.c_int)]
        lib.mn_free.argtypes = [ctypes.c_void_p]
        self.lib = lib

    def solver(self, scene: Scene, dim=3, dense_limit=2500, handle=None) -> "Solver":
        return Solver(self, scene, dim, dense_limit, handle)


class Solver:
    """One model on a driver handle: factor(E) with E (L,3) (the first dim columns are used), solve(b)."""

    def __init__(self, driver: Driver, scene: Scene, dim: int, dense_limit: int, handle=None):
        lib = driver.lib
        self.lib, self.dim, self.L = lib, dim, scene.L
        self.owner = handle is None
        self.handle = lib.mn_new() if handle is None else handle
        pairs = link_pairs(scene)
        inv_m = np.asarray(scene.inv_mass, float)
        # kept alive: the model points into them
        self.arrays = [np.ascontiguousarray(a) for a in (
            scene.k1.astype(np.int64), scene.k2.astype(np.int64), inv_m, pairs.first.astype(np.int64),
            pairs.second.astype(np.int64), (pairs.sign * inv_m[pairs.mass]).astype(float))]
        k1, k2, im, pf, ps, pw = self.arrays
        lib.mn_set_model(self.handle, dim, scene.K, scene.L, _p(k1), _p(k2), _p(im), pf.size, _p(pf), _p(ps), _p(pw),
                         SINGULAR_RCOND, dense_limit)

    def factor(self, E):
        self.E = np.ascontiguousarray(np.asarray(E, float)[:, :self.dim])
        status = self.lib.mn_factor(self.handle, _p(self.E))
        assert status == 0
        return self

    def solve(self, b):
        b = np.ascontiguousarray(b, float)
        x = np.full(self.L, np.inf)
        self.lib.mn_solve(self.handle, _p(b), _p(x))
        return x

    def rank(self) -> int:
        return int(self.lib.mn_rank(self.handle))

    def cg_info(self):
        it, res, stop = ctypes.c_int64(), ctypes.c_double(), ctypes.c_int()
        self.lib.mn_cg_info(self.handle, ctypes.byref(it), ctypes.byref(res), ctypes.byref(stop))
        return it.value, res.value, stop.value

    def close(self):
        if self.owner and self.handle:
            self.lib.mn_free(self.handle)
            self.handle = None


def _p(a: np.ndarray):
    return a.ctypes.data_as(c_int64_p if a.dtype == np.int64 else c_double_p)


@pytest.fixture(scope="module")
def driver(tmp_path_factory) -> Driver:
    compilers = _compilers()
    if not compilers:
        pytest.skip("no C compiler (cc, gcc or clang) on PATH to build the minimum-norm test driver")
    return Driver(_build(compilers[0], tmp_path_factory.mktemp("minnorm")))


# ---- scenes and the numpy reference --------------------------------------------------------------------

def unit_vectors(scene: Scene, X) -> np.ndarray:
    """E_l of (8) (not of unit length off the manifold (11): A keeps the Jacobian form there)."""
    return (X[scene.k2] - X[scene.k1]) / scene.length[:, None]


def jacobian(scene: Scene, E) -> np.ndarray:
    """C, (L, K*dim): row l is +E_l at k1(l) and -E_l at k2(l)."""
    L, dim = E.shape
    C = np.zeros((L, scene.K * dim))
    for i in range(dim):
        C[np.arange(L), scene.k1 * dim + i] += E[:, i]
        C[np.arange(L), scene.k2 * dim + i] -= E[:, i]
    return C


class Reference:
    """A = C M^-1 C^T assembled from C (not from the pairs), and its eigen-decomposition with the numpy
    path's cut (eigenvalues below SINGULAR_RCOND times the largest are zero)."""

    def __init__(self, scene: Scene, E):
        self.C = jacobian(scene, E)
        dim = E.shape[1]
        inv_m = np.repeat(np.asarray(scene.inv_mass, float), dim)
        self.A = (self.C * inv_m) @ self.C.T
        w, V = np.linalg.eigh(self.A)
        keep = w > SINGULAR_RCOND * w.max()
        self.rank = int(keep.sum())
        self.range, self.null, self.w = V[:, keep], V[:, ~keep], w[keep]
        self.free_columns = np.repeat(~np.asarray(scene.fixed), dim)

    def pinv(self, b):
        return self.range @ ((self.range.T @ b) / self.w)

    def forces_on_free_masses(self, T):
        """C^T T on the free masses: the link forces of (9); (31) says self-stresses add nothing there."""
        return (self.C.T @ T)[self.free_columns]


def _with_masses(scene: Scene, rng) -> Scene:
    data = scene.to_dict()
    for entry in data["masses"]:
        if not entry.get("fixed"):
            entry["mass"] = float(10.0 ** rng.uniform(-1, 1))
    return Scene.from_dict(data)


def triangulated_net(n=6, m=7, spacing=0.1) -> Scene:
    """A planar n x m net with one diagonal per cell: triangulated, with self-stresses in its plane."""
    data = builders.net(n, m, spacing=spacing, anchors="four_corners").to_dict()
    for i in range(n - 1):
        for j in range(m - 1):
            data["links"].append({"a": i * m + j + 1, "b": (i + 1) * m + j + 2})
    data["name"] = f"triangulated_{n}x{m}"
    return Scene.from_dict(data)


def redundant_cases():
    rng = np.random.default_rng(7)
    truss = builders.redundant_truss(bays=3)
    heavy_light = _with_masses(builders.redundant_truss(bays=4), rng)
    # off the manifold (11) (as between an integrator's steps): E no longer of unit length
    bent = heavy_light.X0 + 0.02 * rng.standard_normal(heavy_light.X0.shape) * ~heavy_light.fixed[:, None]
    net = builders.net(6, 5, diagonals=True)
    tri = triangulated_net()
    taut = builders.taut_string(speed=0.0)
    return {
        "truss": (truss, truss.X0),
        "truss_masses_off_manifold": (heavy_light, bent),
        "net_with_diagonals": (net, net.X0),
        "triangulated_net": (tri, tri.X0),
        "taut_string": (taut, taut.X0),
    }


def regular_cases():
    rng = np.random.default_rng(3)
    n = 12
    points = np.cumsum(np.r_[[[0.0, 0.0, 0.0]], 0.1 * rng.standard_normal((n, 3))], axis=0)
    chain = builders.chain(n, shape="points", points=points, masses=list(10.0 ** rng.uniform(-1, 1, n + 1)))
    double = builders.double_pendulum(m1=0.3, m2=2.0)
    net = builders.net(4, 5)
    return {"chain": (chain, chain.X0), "double_pendulum": (double, double.X0), "plain_net": (net, net.X0)}


REDUNDANT = redundant_cases()
REGULAR = regular_cases()
PLANAR = ["net_with_diagonals", "triangulated_net", "taut_string"]


def _consistent_rhs(ref: Reference, rng, count=3):
    """B = A y for random y: consistent, as (32)-(36) make B of (26)."""
    return [(ref.A @ y, y) for y in rng.standard_normal((count, ref.A.shape[0]))]


def _rel(a, b):
    return np.linalg.norm(a - b) / max(np.linalg.norm(b), 1e-300)


# ---- tests -----------------------------------------------------------------------------------------------

@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_compiles_without_warnings(compiler, tmp_path):
    if not shutil.which(compiler):
        pytest.skip(f"{compiler} is not installed")
    _build(compiler, tmp_path, extra=["-pedantic"])


@pytest.mark.parametrize("name", list(REDUNDANT))
def test_dense_path_is_the_minimum_norm_solution(driver, name):
    scene, X = REDUNDANT[name]
    E = unit_vectors(scene, X)
    ref = Reference(scene, E)
    assert ref.rank < scene.L, "the case must have self-stresses"
    solver = driver.solver(scene).factor(E)
    try:
        assert solver.rank() == ref.rank
        for B, y in _consistent_rhs(ref, np.random.default_rng(1)):
            T = solver.solve(B)
            scale = np.linalg.norm(ref.A, 2) * np.linalg.norm(T)
            assert np.linalg.norm(ref.A @ T - B) <= 1e-13 * scale            # solves (25)
            assert np.linalg.norm(ref.null.T @ T) <= 1e-10 * np.linalg.norm(T)  # no self-stress (27)
            assert _rel(T, ref.pinv(B)) <= 1e-10                              # = A^+ B
            # (31): the forces on the masses are those of any other solution, here y and y + a self-stress
            F = ref.forces_on_free_masses(T)
            for other in (y, y + ref.null @ np.random.default_rng(2).standard_normal(ref.null.shape[1])):
                assert _rel(F, ref.forces_on_free_masses(other)) <= 1e-10
    finally:
        solver.close()


@pytest.mark.parametrize("name", list(REDUNDANT))
def test_iterative_path_agrees_with_the_dense_one(driver, name):
    scene, X = REDUNDANT[name]
    E = unit_vectors(scene, X)
    ref = Reference(scene, E)
    dense = driver.solver(scene).factor(E)
    iterative = driver.solver(scene, dense_limit=0).factor(E)
    try:
        assert iterative.rank() == -1  # CG does not reveal the rank
        for B, _ in _consistent_rhs(ref, np.random.default_rng(4)):
            T = iterative.solve(B)
            iterations, residual, stop = iterative.cg_info()
            assert stop == STOP_CONVERGED and residual <= 1e-14 and 0 < iterations <= 10 * scene.L + 100
            assert _rel(T, dense.solve(B)) <= 1e-10
            assert _rel(T, ref.pinv(B)) <= 1e-10
            assert np.linalg.norm(ref.null.T @ T) <= 1e-10 * np.linalg.norm(T)
    finally:
        dense.close()
        iterative.close()


@pytest.mark.parametrize("name", list(REGULAR))
@pytest.mark.parametrize("dense_limit", [2500, 0], ids=["dense", "iterative"])
def test_regular_system_gives_the_ordinary_solution(driver, name, dense_limit):
    scene, X = REGULAR[name]
    E = unit_vectors(scene, X)
    ref = Reference(scene, E)
    assert ref.rank == scene.L, "the case must be regular"
    solver = driver.solver(scene, dense_limit=dense_limit).factor(E)
    try:
        if dense_limit:
            assert solver.rank() == scene.L
        for B, y in _consistent_rhs(ref, np.random.default_rng(5)):
            assert _rel(solver.solve(B), np.linalg.solve(ref.A, B)) <= 1e-10
            assert _rel(solver.solve(B), y) <= 1e-10
    finally:
        solver.close()


@pytest.mark.parametrize("name", PLANAR)
@pytest.mark.parametrize("dense_limit", [2500, 0], ids=["dense", "iterative"])
def test_planar_copy_agrees_with_the_3d_one(driver, name, dense_limit):
    scene, X = REDUNDANT[name]
    E = unit_vectors(scene, X)
    assert np.all(E[:, 2] == 0.0), "the case must lie in the x-y plane"
    ref = Reference(scene, E[:, :2])
    s3 = driver.solver(scene, dim=3, dense_limit=dense_limit).factor(E)
    s2 = driver.solver(scene, dim=2, dense_limit=dense_limit).factor(E)
    try:
        if dense_limit:
            assert s2.rank() == s3.rank() == ref.rank
        for B, _ in _consistent_rhs(ref, np.random.default_rng(6)):
            T3, T2 = s3.solve(B), s2.solve(B)
            assert _rel(T2, T3) <= 1e-13
            assert _rel(T2, ref.pinv(B)) <= 1e-10
    finally:
        s3.close()
        s2.close()


@pytest.mark.parametrize("name", ["truss", "net_with_diagonals"])
def test_inconsistent_rhs_dense_gives_the_least_squares_minimum_norm(driver, name):
    """B with a self-stress component (round-off breaks (32) in practice; here much more): the dense path
    drops that component and returns A^+ B."""
    scene, X = REDUNDANT[name]
    E = unit_vectors(scene, X)
    ref = Reference(scene, E)
    rng = np.random.default_rng(8)
    solver = driver.solver(scene).factor(E)
    try:
        for eps in (1e-14, 1e-8, 1e-2):
            B0 = ref.A @ rng.standard_normal(scene.L)
            N = ref.null @ rng.standard_normal(ref.null.shape[1])
            B = B0 + eps * np.linalg.norm(B0) * N / np.linalg.norm(N)
            assert _rel(solver.solve(B), ref.pinv(B)) <= 1e-10
    finally:
        solver.close()


def test_iterative_path_with_round_off_in_the_rhs_stays_near_the_minimum_norm(driver):
    """CG cannot converge below a self-stress component of B; it returns its least-residual iterate, which
    carries about kappa times that component (relative), and does not run away along the null space."""
    scene, X = REDUNDANT["net_with_diagonals"]
    E = unit_vectors(scene, X)
    ref = Reference(scene, E)
    rng = np.random.default_rng(9)
    solver = driver.solver(scene, dense_limit=0).factor(E)
    kappa = ref.w.max() / ref.w.min()
    try:
        for eps in (1e-15, 1e-12, 1e-9):
            B0 = ref.A @ rng.standard_normal(scene.L)
            N = ref.null @ rng.standard_normal(ref.null.shape[1])
            B = B0 + eps * np.linalg.norm(B0) * N / np.linalg.norm(N)
            T = solver.solve(B)
            assert np.all(np.isfinite(T))
            assert _rel(T, ref.pinv(B)) <= max(1e-10, 10 * kappa * eps)
    finally:
        solver.close()


def test_workspace_grows_and_is_reused(driver):
    """One ln_data for a small, then a larger, then the small model again: the workspace grows once and the
    solutions are those of fresh workspaces."""
    small_scene, small_X = REDUNDANT["taut_string"]
    large_scene, large_X = REDUNDANT["net_with_diagonals"]
    rng = np.random.default_rng(10)
    handle = driver.lib.mn_new()
    try:
        for scene, X, limit in [(small_scene, small_X, 2500), (large_scene, large_X, 2500), (large_scene, large_X, 0),
                                (small_scene, small_X, 2500)]:
            E = unit_vectors(scene, X)
            B = Reference(scene, E).A @ rng.standard_normal(scene.L)
            shared = driver.solver(scene, dense_limit=limit, handle=handle).factor(E)
            fresh = driver.solver(scene, dense_limit=limit).factor(E)
            try:
                np.testing.assert_array_equal(shared.solve(B), fresh.solve(B))
            finally:
                fresh.close()
    finally:
        driver.lib.mn_free(handle)


@pytest.mark.parametrize("dense_limit", [2500, 0], ids=["dense", "iterative"])
def test_zero_and_non_finite_input(driver, dense_limit):
    scene, X = REDUNDANT["truss"]
    E = unit_vectors(scene, X)
    solver = driver.solver(scene, dense_limit=dense_limit).factor(E)
    try:
        np.testing.assert_array_equal(solver.solve(np.zeros(scene.L)), 0.0)
        bad = E.copy()
        bad[3, 1] = np.nan
        solver.factor(bad)
        assert np.all(np.isnan(solver.solve(np.ones(scene.L))))
        solver.factor(E)  # usable again
        B = Reference(scene, E).A @ np.ones(scene.L)
        assert np.all(np.isfinite(solver.solve(B)))
    finally:
        solver.close()


# ---- timings (python tests/native/test_minnorm_c.py; not a test) -----------------------------------------

def _best_of(fn, repeat):
    best = np.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def _pair_matrix(scene: Scene, E):
    """A of (25) from the pairs, sparse (CSR), as the package assembles it."""
    import scipy.sparse as sp

    pairs = link_pairs(scene)
    vals = pairs.sign * np.asarray(scene.inv_mass)[pairs.mass] * np.einsum("ij,ij->i", E[pairs.first], E[pairs.second])
    off = pairs.first != pairs.second
    rows, cols = np.r_[pairs.first, pairs.second[off]], np.r_[pairs.second, pairs.first[off]]
    return sp.csr_matrix((np.r_[vals, vals[off]], (rows, cols)), shape=(scene.L, scene.L))


def _timings():
    """Factor and solve times of both paths; the error is against T* = A z (in range(A), so the minimum-norm
    solution of A T = A T*), numpy's eigh (the numpy path's factorisation) timed beside for L <= 1000."""
    import tempfile

    import scipy.linalg
    from scipy.sparse.linalg import minres

    compilers = _compilers()
    if not compilers:
        sys.exit("no C compiler")
    with tempfile.TemporaryDirectory() as tmp:
        drv = Driver(_build(compilers[0], Path(tmp)))
        rng = np.random.default_rng(0)
        print(f"{compilers[0]} {' '.join(FLAGS)}")
        print("dense path (factor: best of 3, solve: best of 10)")
        print(f"{'scene':>26} {'L':>5} {'rank':>5} {'factor ms':>10} {'solve ms':>9} {'rel err':>8} {'eigh s':>7}")
        cases = []
        for bays, n, links in [(8, 6, 100), (25, 10, 300), (83, 17, 1000), (208, 25, 2500)]:
            cases += [(f"redundant_truss({bays})", builders.redundant_truss(bays)),
                      (f"net({n},{n},diagonals=True)", builders.net(n, n, diagonals=True)),
                      (f"chain({links})", builders.chain(links))]
        for label, scene in cases:
            E = unit_vectors(scene, scene.X0)
            A = _pair_matrix(scene, E)
            T_star = A @ rng.standard_normal(scene.L)
            B = A @ T_star
            solver = drv.solver(scene)
            tf = _best_of(lambda: solver.factor(E), 3)
            ts = _best_of(lambda: solver.solve(B), 10)
            err = _rel(solver.solve(B), T_star)
            te = f"{_best_of(lambda: scipy.linalg.eigh(A.toarray()), 1):7.2f}" if scene.L <= 1000 else "-"
            print(f"{label:>26} {scene.L:>5} {solver.rank():>5} {tf * 1e3:>10.2f} {ts * 1e3:>9.3f} {err:>8.1e} {te:>7}")
            solver.close()
        scene = builders.net(100, 100, diagonals=True)
        E = unit_vectors(scene, scene.X0)
        A = _pair_matrix(scene, E)
        T_star = A @ rng.standard_normal(scene.L)
        B = A @ T_star
        solver = drv.solver(scene)
        tf = _best_of(lambda: solver.factor(E), 3)
        ts = _best_of(lambda: solver.solve(B), 3)
        T = solver.solve(B)
        it, res, stop = solver.cg_info()
        print(f"iterative path (CG, matrix-free), net(100, 100, diagonals=True), L = {scene.L}:")
        print(f"  factor {tf * 1e3:.3f} ms, solve {ts:.3f} s ({it} iterations, {ts / it * 1e6:.0f} us each), "
              f"residual {np.linalg.norm(A @ T - B) / np.linalg.norm(B):.1e}, rel err {_rel(T, T_star):.1e}")
        t0 = time.perf_counter()
        T_minres, _ = minres(A, B, rtol=1e-14, maxiter=20 * scene.L)
        print(f"  scipy MINRES on the assembled A (the numpy path): {time.perf_counter() - t0:.3f} s, "
              f"rel err {_rel(T_minres, T_star):.1e}")
        solver.close()


if __name__ == "__main__":
    _timings()
