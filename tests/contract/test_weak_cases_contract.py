"""Weak cases made clear answers: each bad value is refused with an error naming the option or value
and the rule, never a traceback or a silent default (docs/contract.md)."""
import numpy as np
import pytest

from contract_support import MODELS
import linknet_core as ln

PENDULUM2 = MODELS / "double_pendulum.json"  # K = 3


# ---- simulate's forces (linknet_core/simulator/simulator.py, _forces_value) ----------------------------------------
def test_a_forces_callable_returning_none_is_refused_naming_the_time():
    with pytest.raises(ln.SolverError) as err:
        ln.simulate(PENDULUM2, 0.1, forces=lambda t: None, error_estimate=False)
    text = str(err.value)
    assert "forces(t) called at t = 0.0 returned None" in text and "a (3, 3) array of real numbers" in text, text


def test_a_forces_callable_returning_none_later_names_that_time():
    def forces(t):
        return np.zeros((3, 3)) if t < 0.05 else None

    with pytest.raises(ln.SolverError, match=r"called at t = 0\.05\d* returned None"):
        ln.simulate(PENDULUM2, 0.1, forces=forces, n_out=11, error_estimate=False)


@pytest.mark.parametrize("forces,words", [
    ("abc", "forces 'abc' (a str): forces must be None, a (3, 3) array of real numbers, or a callable"),
    (lambda t: "abc", "forces(t) called at t = 0.0 returned 'abc' (a str): forces must be None, a (3, 3) array"),
    ([["a", "b", "c"]] * 3, "which is not an array of real numbers: forces must be None, a (3, 3) array"),
    ({"F": 1}, "forces {'F': 1} (a dict), which is not an array of real numbers"),
    (np.zeros((2, 3)), "forces an array of shape (2, 3): forces must be None, a (3, 3) array"),
    (lambda t: np.zeros(3), "returned an array of shape (3,): forces must be None, a (3, 3) array"),
])
def test_forces_that_are_not_a_k_by_3_array_of_numbers_are_refused_naming_forces(forces, words):
    with pytest.raises(ln.SolverError) as err:
        ln.simulate(PENDULUM2, 0.1, forces=forces, error_estimate=False)
    assert words in str(err.value), str(err.value)


def test_good_forces_still_run():
    F = np.zeros((3, 3))
    F[-1, 0] = 0.1
    held = ln.simulate(PENDULUM2, 0.1, forces=F, n_out=3, error_estimate=False)
    called = ln.simulate(PENDULUM2, 0.1, forces=lambda t: F.tolist(), n_out=3, error_estimate=False)
    assert np.array_equal(held.X, called.X)
    assert ln.simulate(PENDULUM2, 0.1, forces=None, n_out=3, error_estimate=False).X.shape == (3, 3, 3)


# ---- ensembles (linknet_core/ensemble: command.py, parameters.py, __init__.py) ----------------------------------------
CHAIN = MODELS / "chain_10.json"


def linknet_ensemble(*args, cwd=None):
    import subprocess
    import sys

    from contract_support import ROOT

    return subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", str(CHAIN), "--t-end", "0.01",
                           "--no-progress", *args], capture_output=True, text=True, timeout=120, cwd=cwd or ROOT)


def _one_line(run, words):
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("linknet ensemble: error: "), run.stderr
    assert words in lines[0], run.stderr
    return lines[0]


@pytest.mark.parametrize("args,words", [
    (["--vary", "M[3]=1,2", "--vary", "M[3]=0.5:2:3"],
     "--vary M[3] is given twice ('M[3]=1,2' and 'M[3]=0.5:2:3'): vary each parameter once"),
    (["--vary", "integrator=rattle", "--vary", "integrator=dop853"], "--vary integrator is given twice"),
    (["--sample", "M[3]=uniform:1:2", "--sample", "M[3]=normal:1:0.1", "--n-samples", "2"],
     "--sample 'M[3]=normal:1:0.1': M[3] is already set by an earlier --sample; sample each parameter once"),
    (["--samples", "CSV", "--sample", "M[3]=normal:1:0.1", "--n-samples", "2"],
     "M[3] is already set by --samples"),
    (["--samples", "TWICE"], "the header names M[3] twice (column 2); give each parameter one column"),
])
def test_a_parameter_given_twice_is_refused_naming_it(args, words, tmp_path):
    csv, twice = tmp_path / "samples.csv", tmp_path / "twice.csv"
    csv.write_text("M[3]\n1\n2\n")
    twice.write_text("M[3],M[3]\n1,2\n")
    args = [str(csv) if a == "CSV" else str(twice) if a == "TWICE" else a for a in args]
    _one_line(linknet_ensemble(*args), words)


def test_an_unknown_integrator_is_named_as_a_plain_string_with_the_allowed_names():
    from linknet_core.integrators import METHODS

    line = _one_line(linknet_ensemble("--vary", "integrator=rk99,rattle"),
                     "parameter integrator: unknown method(s) 'rk99'; choose from " + ", ".join(sorted(METHODS)))
    assert "np.str_" not in line and "[" not in line.partition("method(s)")[2], line
    with pytest.raises(ln.LinknetError) as err:
        ln.ensemble(CHAIN, vary={"integrator": ["rk99", "rk98"]}, t_end=0.01)
    assert "unknown method(s) 'rk98', 'rk99'; choose from dop853" in str(err.value) and "np.str_" not in str(err.value)


@pytest.mark.parametrize("name", ["x.txt", "x", "x.nc.bak", "x.h5"])
def test_an_out_that_is_not_a_netcdf_name_is_refused_saying_the_format(name, tmp_path):
    _one_line(linknet_ensemble("--vary", "M[3]=1,2", "--out", str(tmp_path / name)),
              f"argument --out: '{tmp_path / name}': the study (a netCDF file) is written as .nc")
    assert not (tmp_path / name).exists()
    with pytest.raises(ln.LinknetError, match=r"the study is written as a netCDF file, whose name ends in \.nc"):
        ln.ensemble(CHAIN, vary={"M[3]": [1.0]}, t_end=0.01, out=tmp_path / name)
    assert not (tmp_path / name).exists()


@pytest.mark.parametrize("vary,samples", [(None, None), ({}, None), (None, {})])
def test_the_library_with_nothing_to_vary_is_refused_as_the_cli_is(vary, samples):
    from linknet_core.ensemble.parameters import NOTHING_TO_VARY

    with pytest.raises(ln.LinknetError) as err:
        ln.ensemble(CHAIN, vary=vary, samples=samples, t_end=0.01)
    assert str(err.value) == NOTHING_TO_VARY
    assert _one_line(linknet_ensemble(), "nothing to vary") == f"linknet ensemble: error: {NOTHING_TO_VARY}"
