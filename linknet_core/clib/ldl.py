"""The native sparse LDL^T (src/engine_ldl.c, src/ldl.h) called from Python, for work done once per scene.

The structure analysis uses it for the AMD ordering of a general graph and for the rank of A (25) from the
zero pivots of one factorisation; benchmarks and tests use it to factor and solve A directly. A step never
goes through here: the stage code calls the same functions from C.
"""
from __future__ import annotations

import ctypes

import numpy as np

from linknet_core.tolerances import PIVOT_TOL

ln_int = ctypes.c_int64
_ln_int_p = ctypes.POINTER(ln_int)
_double_p = ctypes.POINTER(ctypes.c_double)



def declare(lib: ctypes.CDLL) -> ctypes.CDLL:
    """Give the LDL^T functions of a loaded native library their C signatures (idempotent)."""
    for name, restype, argtypes in (
        ("ln_ldl_analyse", ctypes.c_void_p, [ln_int, ln_int, _ln_int_p, _ln_int_p, _ln_int_p]),
        ("ln_ldl_symbolic_free", None, [ctypes.c_void_p]),
        ("ln_ldl_nnz_L", ln_int, [ctypes.c_void_p]),
        ("ln_ldl_get_ordering", None, [ctypes.c_void_p, _ln_int_p]),
        ("ln_ldl_info", None, [ctypes.c_void_p, _double_p]),
        ("ln_ldl_numeric_new", ctypes.c_void_p, [ctypes.c_void_p]),
        ("ln_ldl_numeric_free", None, [ctypes.c_void_p]),
        ("ln_ldl_factor", ln_int, [ctypes.c_void_p, ctypes.c_void_p, _double_p, ctypes.c_double]),
        ("ln_ldl_get_pivots", ln_int, [ctypes.c_void_p, ctypes.c_void_p, _double_p]),
        ("ln_ldl_vector_kernels", ctypes.c_int, [ctypes.c_int]),
        ("ln_ldl_solve", None, [ctypes.c_void_p, ctypes.c_void_p, _double_p, _double_p]),
    ):
        function = getattr(lib, name)
        function.restype = restype
        function.argtypes = argtypes
    return lib


def package_library() -> ctypes.CDLL:
    """The package's native library with the LDL^T functions declared."""
    from linknet_core.clib.library import lib

    return declare(lib)


def _ints(values) -> np.ndarray:
    return np.ascontiguousarray(values, np.int64)


class NativeLDL:
    """One symbolic analysis of an n x n symmetric pattern given as (first, second) pairs, and its numeric
    factorisation: the pair-wise form in which the model hands A (25) to the native core.

    ``ordering=None`` lets the analysis choose AMD's fill-reducing order. Raises ValueError where the native
    analysis refuses the input (an ordering that is not a permutation, an index out of range).
    """

    def __init__(self, n: int, first, second, ordering=None, lib: ctypes.CDLL | None = None):
        self._lib = declare(lib) if lib is not None else package_library()
        self.n = int(n)
        self._first, self._second = _ints(first), _ints(second)
        if self._first.shape != self._second.shape or self._first.ndim != 1:
            raise ValueError("first and second must be 1-D arrays of the same length")
        self.n_pairs = self._first.size
        order = None if ordering is None else _ints(ordering)
        if order is not None and order.shape != (self.n,):
            raise ValueError(f"ordering must have {self.n} entries, not {order.shape}")
        self._symbolic = self._lib.ln_ldl_analyse(
            self.n, self.n_pairs, self._first.ctypes.data_as(_ln_int_p), self._second.ctypes.data_as(_ln_int_p),
            None if order is None else order.ctypes.data_as(_ln_int_p))
        if not self._symbolic:
            raise ValueError("the native LDL^T analysis refused the pattern (an index out of range, an ordering "
                             "that is not a permutation, or out of memory)")
        self._numeric = self._lib.ln_ldl_numeric_new(self._symbolic)
        if not self._numeric:
            self._lib.ln_ldl_symbolic_free(self._symbolic)
            self._symbolic = None
            raise MemoryError("native LDL^T: out of memory")
        self.singular_column = -1

    def close(self) -> None:
        if getattr(self, "_numeric", None):
            self._lib.ln_ldl_numeric_free(self._numeric)
            self._numeric = None
        if getattr(self, "_symbolic", None):
            self._lib.ln_ldl_symbolic_free(self._symbolic)
            self._symbolic = None

    def __del__(self):
        self.close()

    @property
    def ordering(self) -> np.ndarray:
        """Elimination order, position -> index."""
        out = np.empty(self.n, np.int64)
        self._lib.ln_ldl_get_ordering(self._symbolic, out.ctypes.data_as(_ln_int_p))
        return out

    @property
    def nnz_L(self) -> int:
        return int(self._lib.ln_ldl_nnz_L(self._symbolic))

    @property
    def info(self) -> dict:
        raw = np.zeros(6)
        self._lib.ln_ldl_info(self._symbolic, raw.ctypes.data_as(_double_p))
        return {"algorithm": "supernodal" if raw[0] else "columns", "nnz_L": int(raw[1]), "blocks": int(raw[2]),
                "stored": int(raw[3]), "flops": float(raw[4]), "avx2": bool(raw[5])}

    def factor(self, pair_values, pivot_tol: float = PIVOT_TOL) -> int:
        """Numeric factorisation; returns -1, or the first elimination column whose pivot was zeroed."""
        values = np.ascontiguousarray(pair_values, np.float64)
        if values.shape != (self.n_pairs,):
            raise ValueError(f"pair_values must have {self.n_pairs} entries")
        self.singular_column = int(self._lib.ln_ldl_factor(self._symbolic, self._numeric,
                                                           values.ctypes.data_as(_double_p), float(pivot_tol)))
        return self.singular_column

    def pivots(self) -> tuple[np.ndarray, int]:
        """The pivots d_k of the last factorisation (elimination order) and how many of them were zeroed."""
        D = np.empty(self.n)
        zeroed = int(self._lib.ln_ldl_get_pivots(self._symbolic, self._numeric, D.ctypes.data_as(_double_p)))
        return D, zeroed

    def count_zero_pivots(self) -> int:
        return int(self._lib.ln_ldl_get_pivots(self._symbolic, self._numeric, None))

    def solve(self, b) -> np.ndarray:
        """A^-1 b with the last factorisation (zeroed pivots drop their columns)."""
        x = np.array(b, dtype=np.float64, copy=True, order="C")
        if x.shape != (self.n,):
            raise ValueError(f"b must have {self.n} entries")
        pointer = x.ctypes.data_as(_double_p)
        self._lib.ln_ldl_solve(self._symbolic, self._numeric, pointer, pointer)
        return x


def vector_kernels(enable: bool | None = None, lib: ctypes.CDLL | None = None) -> bool:
    """Whether analyses from now on use the AVX2 copy of the supernodal factorisation (where the processor has
    it); ``enable`` switches it for the whole process (tests and benchmarks: both copies agree bitwise)."""
    lib = declare(lib) if lib is not None else package_library()
    return bool(lib.ln_ldl_vector_kernels(-1 if enable is None else int(bool(enable))))


def amd_ordering(n: int, first, second, lib: ctypes.CDLL | None = None) -> np.ndarray:
    """AMD's fill-reducing elimination order (position -> index) of the symmetric pattern of the pairs."""
    ldl = NativeLDL(n, first, second, None, lib)
    try:
        return ldl.ordering
    finally:
        ldl.close()


def zero_pivots(n: int, first, second, pair_values, ordering=None, pivot_tol: float = PIVOT_TOL,
                lib: ctypes.CDLL | None = None) -> int:
    """How many pivots one native LDL^T of the matrix (pairs with their values) zeroes: n - rank, as the
    factorisation sees it."""
    ldl = NativeLDL(n, first, second, ordering, lib)
    try:
        ldl.factor(pair_values, pivot_tol)
        return ldl.count_zero_pivots()
    finally:
        ldl.close()
