"""Weak cases of issue 25 made clear answers: each bad value is refused with an error naming the option or value
and the rule, never a traceback or a silent default (docs/contract.md, the rows marked "issue 25, weak")."""
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
