"""Accuracy of the core's own elementary functions (linknet_core/native/src/ln_math.c) against mpmath.

    python3 -m benchmarks.ln_math_accuracy [--n N] [--seed S]

ln_math.c is compiled here with the system C compiler (the library's flags) into a small library together with a
driver that evaluates it, and the C library's function, over arrays. For each function and each family of random
arguments (N each, default 1,000,000) it prints the largest error of ln_math in units in the last place of the exact
result (mpmath at 160 bits), where that maximum occurs, the share of arguments on which the C library (glibc here)
gives other bits, and the C library's largest error over the same arguments. Takes ~15 us per argument.
tests/native/test_ln_math.py runs the same on a few thousand arguments of each family.
"""
from __future__ import annotations

import argparse
import ctypes
import shutil
import subprocess
import tempfile
from pathlib import Path

import mpmath
import numpy as np

SRC = Path(__file__).resolve().parents[1] / "linknet_core" / "native" / "src"
DRIVER = r"""
#include <math.h>
#include "ln_math.h"
void evaluate(int which, int libm, const double *x, const double *y, double *out, long n)
{
    for (long i = 0; i < n; i++) {
        switch (which) {
        case 0: out[i] = libm ? sin(x[i]) : ln_sin(x[i]); break;
        case 1: out[i] = libm ? cos(x[i]) : ln_cos(x[i]); break;
        case 2: out[i] = libm ? pow(x[i], y[i]) : ln_pow(x[i], y[i]); break;
        case 3: out[i] = libm ? hypot(x[i], y[i]) : ln_hypot(x[i], y[i]); break;
        case 4: out[i] = libm ? round(x[i]) : ln_round(x[i]); break;
        case 5: out[i] = libm ? ceil(x[i]) : ln_ceil(x[i]); break;
        case 6: out[i] = libm ? nextafter(x[i], INFINITY) : ln_next_up(x[i]); break;
        case 7: out[i] = libm ? fmax(x[i], y[i]) : ln_fmax(x[i], y[i]); break;
        case 8: out[i] = libm ? fmin(x[i], y[i]) : ln_fmin(x[i], y[i]); break;
        default: out[i] = libm ? ldexp(1.0, (int)x[i]) : ln_pow2((int)x[i]); break;
        }
    }
}
"""
FUNCTIONS = {"sin": 0, "cos": 1, "pow": 2, "hypot": 3,
             # the exact ones, for tests/native/test_ln_math.py (x^y and the like are not measured here)
             "round": 4, "ceil": 5, "next_up": 6, "fmax": 7, "fmin": 8, "pow2": 9}


LIBRARY_FLAGS = ["-std=c99", "-O3", "-fno-math-errno", "-ffp-contract=off"]  # setup.py's


def build(where: Path, flags=LIBRARY_FLAGS, name: str = "ln_math_driver") -> ctypes.CDLL:
    """ln_math.c and the driver compiled with the system C compiler and ``flags`` into where/name.so."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        raise SystemExit("no C compiler")
    (where / "driver.c").write_text(DRIVER)
    lib = where / f"{name}.so"
    subprocess.run([cc, *flags, "-shared", "-fPIC", "-I", str(SRC), str(where / "driver.c"), str(SRC / "ln_math.c"),
                    "-o", str(lib), "-lm"], check=True)
    return ctypes.CDLL(str(lib))


def evaluate(lib, name: str, libm: bool, x, y) -> np.ndarray:
    p = ctypes.POINTER(ctypes.c_double)
    x, y = np.ascontiguousarray(x, float), np.ascontiguousarray(y, float)
    out = np.empty_like(x)
    lib.evaluate(FUNCTIONS[name], int(libm), x.ctypes.data_as(p), y.ctypes.data_as(p), out.ctypes.data_as(p),
                 ctypes.c_long(len(x)))
    return out


def exact(name: str, x: float, y: float):
    x, y = mpmath.mpf(x), mpmath.mpf(y)
    if name == "sin":
        return mpmath.sin(x)
    if name == "cos":
        return mpmath.cos(x)
    if name == "pow":
        return mpmath.power(x, y)
    return mpmath.sqrt(x * x + y * y)


def ulp_error(got: float, ref) -> float:
    """|got - ref| in units of the last place of ref as a double (subnormal spacing below 2^-1022)."""
    if ref == 0:
        return 0.0 if got == 0 else float("inf")
    _, k = mpmath.frexp(ref)  # |ref| in [2^(k-1), 2^k)
    ulp = mpmath.ldexp(1, max(int(k) - 53, -1074))
    return float(abs(mpmath.mpf(got) - ref) / ulp)


def families(rng, n: int):
    """(function, description, x, y): the arguments the core meets and the whole range."""
    sign = lambda: rng.choice([-1.0, 1.0], n)  # noqa: E731
    return [
        ("sin", "x uniform in [-100, 100]", rng.uniform(-100, 100, n), None),
        ("sin", "|x| log-uniform in [2^-30, 2^1000]", sign() * np.exp2(rng.uniform(-30, 1000, n)), None),
        ("cos", "x uniform in [-100, 100]", rng.uniform(-100, 100, n), None),
        ("cos", "|x| log-uniform in [2^-30, 2^1000]", sign() * np.exp2(rng.uniform(-30, 1000, n)), None),
        ("pow", "x log-uniform in [2^-40, 2^40], y uniform in [-8, 8]", np.exp2(rng.uniform(-40, 40, n)),
         rng.uniform(-8, 8, n)),
        ("pow", "x log-uniform in [2^-1000, 2^1000], y uniform in [-1, 1]", np.exp2(rng.uniform(-1000, 1000, n)),
         rng.uniform(-1, 1, n)),
        ("hypot", "x, y standard normal", rng.standard_normal(n), rng.standard_normal(n)),
        ("hypot", "|x|, |y| log-uniform in [2^-1070, 2^1020]", sign() * np.exp2(rng.uniform(-1070, 1020, n)),
         sign() * np.exp2(rng.uniform(-1070, 1020, n))),
    ]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=1_000_000, help="arguments per family")
    ap.add_argument("--seed", type=int, default=20261128)
    args = ap.parse_args(argv)
    mpmath.mp.prec = 160
    rng = np.random.default_rng(args.seed)
    with tempfile.TemporaryDirectory() as tmp:
        lib = build(Path(tmp))
        print(f"{'function':8} {'arguments':58} {'max ulp':>8} {'at':>26} {'libm differs':>12} {'libm max ulp':>12}")
        for name, what, x, y in families(rng, args.n):
            y = x if y is None else y
            ours, theirs = evaluate(lib, name, False, x, y), evaluate(lib, name, True, x, y)
            worst, where, worst_libm = 0.0, None, 0.0
            for i in range(len(x)):
                ref = exact(name, x[i], y[i])
                e = ulp_error(ours[i], ref)
                if e > worst:
                    worst, where = e, (x[i], y[i])
                worst_libm = max(worst_libm, e if theirs[i] == ours[i] else ulp_error(theirs[i], ref))
            at = f"{where[0]:.6g}" + (f", {where[1]:.6g}" if name in ("pow", "hypot") else "")
            print(f"{name:8} {what:58} {worst:8.4f} {at:>26} {np.mean(ours != theirs):12.4%} {worst_libm:12.4f}",
                  flush=True)


if __name__ == "__main__":
    main()
