"""The core's own elementary functions (linknet_core/native/src/ln_math.c, which the core calls instead of libm's):
within their stated error of the exact value (mpmath), C99's special cases (Annex F), and the exact ones exact.

ln_math.c is compiled here with the system C compiler and the library's flags, with the driver of
benchmarks/ln_math_accuracy.py, which measures the same over a million arguments of each family (the figures in
fmu_src/native/README.md). That the shipped binaries and the library call no libm function is checked in
tests/fmu_native/test_native_platforms.py, that they give the same bits everywhere there too."""
from __future__ import annotations

import math
import platform
import shutil
import subprocess
from pathlib import Path

import mpmath
import numpy as np
import pytest

from benchmarks import ln_math_accuracy as acc

pytestmark = pytest.mark.skipif(shutil.which("cc") is None and shutil.which("gcc") is None,
                                reason="no C compiler (apt-get install gcc)")

# the largest error each is stated to have, in units in the last place of the exact result (ln_math.h): fdlibm's
# bound for its sin and cos, Arm's for its pow, and a correctly rounded Newton step's half ulp (plus its ~1e-3) for
# hypot, whose subnormal results are rounded twice (the sum's rounding, below half their ulp, and their own)
BOUND_ULP = {"sin": 1.0, "cos": 1.0, "pow": 0.54, "hypot": 0.501}
SUBNORMAL_HYPOT_BOUND_ULP = 0.75
N_PER_FAMILY = 2000
INF, NAN = math.inf, math.nan
with mpmath.workprec(200):
    SQRT2_E308 = float(mpmath.sqrt(2) * mpmath.mpf(1e308))  # hypot(1e308, 1e308), correctly rounded


@pytest.fixture(scope="module")
def lib(tmp_path_factory):
    return acc.build(tmp_path_factory.mktemp("ln_math"))


def ours(lib, name: str, x, y=None) -> np.ndarray:
    x = np.atleast_1d(np.asarray(x, float))
    return acc.evaluate(lib, name, False, x, x if y is None else np.atleast_1d(np.asarray(y, float)))


def libm(lib, name: str, x, y=None) -> np.ndarray:
    x = np.atleast_1d(np.asarray(x, float))
    return acc.evaluate(lib, name, True, x, x if y is None else np.atleast_1d(np.asarray(y, float)))


@pytest.mark.parametrize("family", range(len(acc.families(np.random.default_rng(0), 1))),
                         ids=[f"{f[0]}: {f[1]}" for f in acc.families(np.random.default_rng(0), 1)])
def test_within_the_stated_error_of_the_exact_value(lib, family):
    name, what, x, y = acc.families(np.random.default_rng(family), N_PER_FAMILY)[family]
    y = x if y is None else y
    got = ours(lib, name, x, y)
    errors, bounds = [], []
    with mpmath.workprec(160):
        for i in range(len(x)):
            exact = acc.exact(name, x[i], y[i])
            errors.append(acc.ulp_error(got[i], exact))
            subnormal = name == "hypot" and abs(exact) < 2.0 ** -1022
            bounds.append(SUBNORMAL_HYPOT_BOUND_ULP if subnormal else BOUND_ULP[name])
    worst = int(np.argmax(np.array(errors) / bounds))
    assert errors[worst] < bounds[worst], f"{name}({x[worst]!r}, {y[worst]!r}): {errors[worst]:.4f} ulp ({what})"


def same(a: float, b: float) -> bool:
    """Equal, sign of zero included, or both NaN."""
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b and math.copysign(1.0, a) == math.copysign(1.0, b)


# (x, y, C99's value): Annex F.9.4.4 (pow), F.9.4.3 (hypot), F.9.1.6-7 (sin, cos); results a double holds exactly
SPECIAL = {
    "pow": [(NAN, 0.0, 1.0), (NAN, -0.0, 1.0), (1.0, NAN, 1.0), (-1.0, INF, 1.0), (-1.0, -INF, 1.0),
            (0.5, INF, 0.0), (2.0, INF, INF), (0.5, -INF, INF), (2.0, -INF, 0.0), (-0.5, INF, 0.0),
            (0.0, -3.0, INF), (-0.0, -3.0, -INF), (-0.0, 3.0, -0.0), (-0.0, 2.0, 0.0), (0.0, -2.0, INF),
            (-0.0, -0.5, INF), (-8.0, 1.0 / 3.0, NAN), (-2.0, 3.0, -8.0), (-2.0, 2.0, 4.0), (INF, -1.0, 0.0),
            (INF, 0.5, INF), (-INF, 3.0, -INF), (-INF, -3.0, -0.0), (-INF, 2.0, INF), (NAN, 1.0, NAN),
            (2.0, NAN, NAN), (2.0, 1024.0, INF), (-2.0, 1025.0, -INF), (2.0, -1074.0, 5e-324),
            (2.0, -1075.0, 0.0), (10.0, 2.0, 100.0), (4.0, 0.5, 2.0), (0.25, -0.5, 2.0), (-3.0, 1.0, -3.0)],
    "hypot": [(INF, NAN, INF), (NAN, -INF, INF), (-INF, 1.0, INF), (NAN, 1.0, NAN), (1.0, NAN, NAN),
              (3.0, 4.0, 5.0), (-3.0, 0.0, 3.0), (0.0, -0.0, 0.0), (-5e-324, 0.0, 5e-324),
              (5e-324, 5e-324, 5e-324), (1e308, 1e308, SQRT2_E308),
              (1.0, 1e-300, 1.0), (1.0, 2.0 ** -27, 1.0)],
    "sin": [(-0.0, None, -0.0), (0.0, None, 0.0), (INF, None, NAN), (-INF, None, NAN), (NAN, None, NAN),
            (1e-300, None, 1e-300), (-2.0 ** -30, None, -2.0 ** -30)],
    "cos": [(-0.0, None, 1.0), (INF, None, NAN), (NAN, None, NAN), (2.0 ** -30, None, 1.0)],
}


@pytest.mark.parametrize("name", sorted(SPECIAL))
def test_special_cases_as_c99_gives_them(lib, name):
    for x, y, expected in SPECIAL[name]:
        got = float(ours(lib, name, x, y)[0])
        assert same(got, expected), f"{name}({x!r}, {y!r}) = {got!r}, C99: {expected!r}"


def test_large_arguments_are_reduced_exactly(lib):
    """sin and cos of huge arguments (the reduction modulo pi/2 with 1,200 bits of 2/pi): an angle that grows with
    time (a sine drive over a long run) keeps its accuracy. The exact values of these are tiny or one."""
    for x in (1e22, 2.0 ** 1023, 1.7976931348623157e308, 6381956970095103.0 * 2.0 ** 797, 5.0 * 2.0 ** 20 * math.pi):
        for name in ("sin", "cos"):
            with mpmath.workprec(2400):
                error = acc.ulp_error(float(ours(lib, name, x)[0]), acc.exact(name, x, x))
            assert error < BOUND_ULP[name], (name, x, error)


EXACT_ARGUMENTS = [0.0, -0.0, 0.5, -0.5, 1.5, -1.5, 2.5, -2.5, 0.49999999999999994, -0.49999999999999994,
                   4503599627370495.5, -4503599627370495.5, 4503599627370497.0, 2.0 ** 52 + 1, 1e300, -1e300,
                   5e-324, -5e-324, 2.2250738585072014e-308, 1.0, -1.0, 1.7976931348623157e308, INF, -INF, NAN]


@pytest.mark.parametrize("name", ["round", "ceil", "next_up"])
def test_exact_functions_equal_the_c_library(lib, name):
    """round (halfway away from zero), ceil and nextafter(x, +inf) are exact: the C library's are the reference."""
    rng = np.random.default_rng(7)
    x = np.concatenate([EXACT_ARGUMENTS, rng.uniform(-10, 10, 20000), rng.integers(-50, 50, 2000) / 2.0,
                        np.exp2(rng.uniform(-1074, 1023, 20000)) * rng.choice([-1.0, 1.0], 20000)])
    got, expected = ours(lib, name, x), libm(lib, name, x)
    for a, b, v in zip(got, expected, x):
        assert same(a, b), f"{name}({v!r}) = {a!r}, the C library: {b!r}"


@pytest.mark.parametrize("name", ["fmax", "fmin"])
def test_fmax_and_fmin_ignore_a_nan(lib, name):
    values = [0.0, 1.0, -1.0, INF, -INF, NAN, 5e-324]
    x = np.repeat(values, len(values))
    y = np.tile(values, len(values))
    got, expected = ours(lib, name, x, y), libm(lib, name, x, y)
    for a, b, u, v in zip(got, expected, x, y):
        assert (math.isnan(a) and math.isnan(b)) or a == b, f"{name}({u!r}, {v!r}) = {a!r}, the C library: {b!r}"


def test_powers_of_two_are_exact(lib):
    n = np.arange(-1022, 1024, dtype=float)
    assert np.array_equal(ours(lib, "pow2", n), np.ldexp(1.0, n.astype(int)))


def _has_fma() -> bool:
    cpuinfo = Path("/proc/cpuinfo")
    return platform.machine() == "x86_64" and cpuinfo.exists() and " fma " in cpuinfo.read_text().replace("\n", " ")


@pytest.mark.skipif(not _has_fma(), reason="needs an x86-64 CPU with FMA to run code built with -mfma")
def test_a_build_that_contracts_gives_the_same_bits(lib, tmp_path):
    """A tool's own build of the sources in GCC's GNU mode for a CPU with fused multiply-add (-std=gnu99
    -march=haswell, as a -march=native build on a recent x86-64, or any aarch64 build) contracts a*b+c unless told
    not to: ln_math.c's pragma tells it, and every function gives the bits of the library's build."""
    flags = ["-std=gnu99", "-O3", "-march=haswell"]
    probe = tmp_path / "probe.c"  # the build does contract: a*b+c becomes one instruction
    probe.write_text("double f(double a, double b, double c) { return a * b + c; }\n")
    subprocess.run([shutil.which("cc") or "gcc", *flags, "-c", str(probe), "-o", str(tmp_path / "probe.o")], check=True)
    if shutil.which("objdump"):
        assert "vfmadd" in subprocess.run(["objdump", "-d", str(tmp_path / "probe.o")], capture_output=True,
                                          text=True, check=True).stdout
    contracting = acc.build(tmp_path, flags, "contracting")
    for name, what, x, y in acc.families(np.random.default_rng(11), 20000):
        y = x if y is None else y
        np.testing.assert_array_equal(ours(contracting, name, x, y), ours(lib, name, x, y), err_msg=f"{name}: {what}")
