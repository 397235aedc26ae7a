"""The native FMU's error estimate (output error_estimate) against the true error, and kept bit for bit by a reset, a
parameter detour and an FMU state round trip; switched off, the run is the same and the output NaN. The pythonfmu
FMU reports the library's own estimate (tests/fmu_native/test_native_fmu_results.py compares all three)."""
import numpy as np
import pytest

import linknet_core as ln
from linknet_core.accuracy import position_gap
from native_fmu_support import MODELS, built, host_options, parse_rows, run_host

H = 0.01


def _final_positions(fmu, rows):
    X = np.zeros((len(fmu.names("X")) // 3, 3))
    for j, name in enumerate(fmu.names("X")):
        k, i = (int(v) - 1 for v in name[2:-1].split(","))
        X[k, i] = rows[-1, 1 + j]
    return X


# scene, integrator (None: the FMU's default, dop853 at rtol 1e-8), stop time: runs whose error lies far above the
# references' own (the two references agree to within 10 % of it: 3 % on net_10x10, far less elsewhere)
CASES = [("chain_10", None, 2.0), ("chain_100", None, 1.0), ("net_10x10", None, 1.0),
         ("chain_10", "rattle", 1.0), ("double_pendulum", "rattle", 2.0), ("four_bar", "rattle", 1.0)]


@pytest.mark.parametrize("scene,method,t_end", CASES)
def test_the_estimate_lies_within_10x_of_the_true_error(scene, method, t_end, fmu_root, host, no_python_env):
    """True error: the distance of the FMU's positions from the library's dop853 at rtol 1e-12, integrated to the
    stop time in one call (its own steps, no communication points), checked against rtol 1e-13."""
    fmu = built(fmu_root, scene)
    n = int(round(t_end / H))
    options = [o for name in fmu.names("X") + ["error_estimate"] for o in ("-o", str(fmu.vr[name]))]
    if method:
        options += ["-m", f"{fmu.vr['integrator']}={method}"]
    rows = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, n, H, *options))
    sc = ln.load_scene(MODELS / f"{scene}.json")
    refs = []
    for rtol in (1e-12, 1e-13):
        ref = ln.Simulator(sc, method="dop853", rtol=rtol, error_estimate=False)
        ref.advance(rows[-1, 0])
        refs.append(ref.state.X)
    true = position_gap(_final_positions(fmu, rows), refs[0])
    assert position_gap(refs[0], refs[1]) <= 0.1 * true, (scene, method, true)
    estimate = rows[-1, -1]
    assert true / 10 <= estimate <= 10 * true, (scene, method, estimate, true)


@pytest.mark.parametrize("scene,method", [("chain_100", "dop853"), ("chain_10", "rattle"), ("double_pendulum", "yoshida4"),
                                          ("spinning_tetrahedron", "rattle"), ("net_10x10", "dop853")])
def test_reset_and_a_parameter_detour_keep_the_estimate_bit_identical(scene, method, fmu_root, host, no_python_env):
    """A fresh run, the same instance after fmi2Reset, and an instance whose mass was first set to another value and
    applied (an output read in initialization mode: model and companion rebuilt there) before it was set back: the
    same outputs bit for bit, the error estimate among them (the FMU state round trip: test_native_fmu_contract's
    replay, whose outputs include it)."""
    fmu = built(fmu_root, scene)
    mass = fmu.names("M")[0]
    value = float(next(v.start for v in fmu.md.modelVariables if v.name == mass))
    options = host_options(fmu, method, {mass: value}) + ["-q", f"{fmu.vr[mass]}={2.5 * value!r}"]
    out = run_host(host, no_python_env, "rerun", fmu, 30, H, *options)
    assert "reset_identical 1" in out and "detour_identical 1" in out, out
    rows = parse_rows("\n".join(line for line in out.splitlines() if "," in line))
    assert rows[:, -1].max() > 0.0  # there is an estimate to keep


def test_switched_off_the_run_is_the_same_and_the_estimate_nan(fmu_root, host, no_python_env):
    fmu = built(fmu_root, "double_pendulum")
    on = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, 20, H, *host_options(fmu, "dop853")))
    off = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, 20, H, *host_options(fmu, "dop853"),
                              "-b", f"{fmu.vr['estimate_error']}=0"))
    np.testing.assert_array_equal(off[:, :-1], on[:, :-1])  # the companion never touches the run
    assert np.isnan(off[:, -1]).all() and np.isfinite(on[:, -1]).all()
