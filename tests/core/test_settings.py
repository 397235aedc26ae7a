"""A run's settings as one object (linknet_core.RunSettings): validated once when made, each refusal naming the
setting and its rule, the same through Simulator and simulate; given as ``settings=``, as keywords, or both (a
keyword that is not None replacing that field); normalised so that equal settings are equal whatever numeric
types they came as."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.special import ellipk

import linknet_core as ln
from linknet_core.errors import SolverError

G = 9.81  # models/pendulum.json's gravity, m/s2


def test_the_pendulum_run_with_one_settings_object_reaches_the_bottom_at_a_quarter_period(models_dir):
    """The simple pendulum (1 m, released at rest 90 degrees from the vertical) reaches the bottom after a quarter
    of its period, K(1/2) sqrt(L/g), at the speed sqrt(2 g L) that energy gives it; the run given as keywords is
    the same run."""
    quarter = float(ellipk(0.5)) * math.sqrt(1.0 / G)
    settings = ln.RunSettings(method="dop853", rtol=1e-10)
    result = ln.simulate(models_dir / "pendulum.json", quarter, n_out=3, progress=False, settings=settings)
    bob_X, bob_U = result.X[-1, 1], result.U[-1, 1]
    assert np.allclose(bob_X, (0.0, 0.0, -1.0), atol=1e-7)
    assert abs(np.linalg.norm(bob_U) - math.sqrt(2 * G)) < 1e-7
    assert result.stats["method"] == "dop853" and result.stats["rtol"] == 1e-10
    by_keywords = ln.simulate(models_dir / "pendulum.json", quarter, "dop853", rtol=1e-10, n_out=3, progress=False)
    assert np.array_equal(result.X, by_keywords.X) and np.array_equal(result.T, by_keywords.T)
    assert np.array_equal(result.error_estimate, by_keywords.error_estimate)


def test_a_keyword_beside_settings_replaces_that_field_and_keeps_the_others(models_dir):
    scene = ln.load_scene(models_dir / "chain_10.json")
    settings = ln.RunSettings(method="rattle", dt=1e-3, backend="numpy", error_estimate=False)
    sim = ln.Simulator(scene, dt=5e-4, settings=settings)
    assert sim.settings == dataclasses.replace(settings, dt=5e-4)
    assert sim.backend == "numpy" and sim.companion is None
    result = ln.simulate(scene, 0.01, dt=5e-4, n_out=2, progress=False, settings=settings)
    assert result.stats["steps"] == 20 and result.stats["dt"] == 5e-4  # 0.01 s in steps of the replaced dt
    assert result.error_estimate is None  # error_estimate=False kept from settings
    # a keyword left at None leaves the field as the settings have it
    kept = ln.Simulator(scene, settings=settings.with_changes(project_initial=True), project_initial=None)
    assert kept.settings.project_initial is True
    # the result is validated as a whole: a step beside an error-controlled method is refused as it is alone
    with pytest.raises(SolverError, match="method 'dop853' chooses its own steps: give rtol"):
        ln.Simulator(scene, dt=1e-3, settings=ln.RunSettings(method="dop853"))


def test_the_defaults_resolve_as_the_keywords_did():
    assert ln.RunSettings().stepping.method == "dop853" and ln.RunSettings().stepping.rtol == 1e-8
    stepping = ln.RunSettings(dt=1e-3).stepping  # a step and no method: RATTLE
    assert (stepping.method, stepping.dt, stepping.rtol, stepping.atol) == ("rattle", 1e-3, None, None)
    assert ln.RunSettings(method="dopri5", rtol=1e-6).stepping.atol == 1e-6  # atol defaults to rtol


BAD = [
    ("method", "euler", "unknown integration method 'euler'"),
    ("dt", -1e-3, "dt must be a positive finite step in seconds, got -0.001"),
    ("dt", "1e-3", "dt must be a positive finite step"),
    ("rtol", 0.5, "rtol = 0.5 must be < 0.1"),
    ("atol", 0.0, "atol must be a positive finite tolerance, got 0.0"),
    ("project_initial", "yes", "project_initial must be True, False or None, got 'yes'"),
    ("length_tol", -1.0, "length_tol must be a finite relative tolerance >= 0"),
    ("length_tol", math.nan, "length_tol must be a finite relative tolerance >= 0"),
    ("backend", "gpu", "backend must be one of 'auto', 'native', 'numpy', got 'gpu'"),
    ("backend", ["numpy"], "backend must be one of"),
    ("rhs_kernel", "fortran", "rhs_kernel must be 'numpy' or 'casadi', got 'fortran'"),
    ("specialise", 1, "specialise must be True or False, got 1"),
    ("max_steps_per_call", 0, "max_steps_per_call must be a whole number >= 1"),
    ("max_steps_per_call", 2.5, "max_steps_per_call must be a whole number >= 1"),
    ("max_steps_per_call", True, "max_steps_per_call must be a whole number >= 1"),
    ("error_estimate", "no", "error_estimate must be True or False, got 'no'"),
]
SIMULATE_KEYWORDS = ("method", "dt", "rtol", "atol", "project_initial", "backend", "rhs_kernel", "specialise",
                     "error_estimate")


def _with_step(name, value) -> dict:
    """A valid method and step or tolerance beside the one setting under test."""
    if name in ("rtol", "atol"):
        return {"method": "dop853", name: value}
    if name in ("method", "dt"):
        return {name: value}
    return {"dt": 1e-3, name: value}


@pytest.mark.parametrize("name, value, message", BAD, ids=[f"{n}={v!r}" for n, v, _ in BAD])
def test_each_bad_setting_is_refused_naming_it_and_its_rule_on_every_route(models_dir, name, value, message):
    scene = ln.load_scene(models_dir / "double_pendulum.json")
    given = _with_step(name, value)
    with pytest.raises(SolverError) as made:
        ln.RunSettings(**given)
    assert message in str(made.value)
    with pytest.raises(SolverError) as simulator:
        ln.Simulator(scene, **given)
    assert str(simulator.value) == str(made.value)
    with pytest.raises(SolverError) as replaced:
        ln.RunSettings(error_estimate=False).with_changes(**given)
    assert str(replaced.value) == str(made.value)
    if name in SIMULATE_KEYWORDS:
        with pytest.raises(SolverError) as run:
            ln.simulate(scene, 0.01, progress=False, **given)
        assert str(run.value) == str(made.value)
    assert "_simulate_pool" not in scene.__dict__  # refused before anything was built


def test_settings_must_be_a_run_settings(models_dir):
    with pytest.raises(SolverError, match=r"settings must be a RunSettings \(linknet_core.RunSettings\), got dict"):
        ln.Simulator(models_dir / "pendulum.json", settings={"dt": 1e-3})


def test_equal_settings_are_equal_whatever_numeric_types_they_came_as():
    plain = ln.RunSettings(dt=1e-3, length_tol=1e-6, max_steps_per_call=1000)
    numpy_typed = ln.RunSettings(dt=np.float64(1e-3), length_tol=np.array(1e-6), max_steps_per_call=np.int32(1000),
                                 specialise=np.bool_(True))
    assert numpy_typed == plain and hash(numpy_typed) == hash(plain)
    assert type(numpy_typed.dt) is float and type(numpy_typed.max_steps_per_call) is int
    assert numpy_typed.specialise is True
    assert ln.RunSettings(dt=1e-3) != ln.RunSettings(dt=2e-3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        plain.dt = 2e-3


def test_keywords_of_another_type_are_judged_again_not_taken_from_earlier_settings(models_dir):
    """Settings made from keywords are made once per set of keywords: True and 1 are told apart there, so 1 is still
    refused after True was taken."""
    scene = ln.load_scene(models_dir / "double_pendulum.json")
    assert ln.Simulator(scene, dt=1e-3, specialise=True, error_estimate=False).settings.specialise is True
    with pytest.raises(SolverError, match="specialise must be True or False, got 1"):
        ln.Simulator(scene, dt=1e-3, specialise=1, error_estimate=False)


def test_the_companion_is_the_same_settings_at_half_the_step_or_a_tenth_of_the_tolerances():
    rule, fixed = ln.RunSettings(dt=1e-3, backend="numpy", length_tol=1e-5).companion
    assert (fixed.stepping.method, fixed.dt, fixed.backend, fixed.length_tol) == ("rattle", 5e-4, "numpy", 1e-5)
    assert fixed.error_estimate is False and rule.dt == 5e-4
    _, adaptive = ln.RunSettings(method="dop853", rtol=1e-8, atol=1e-6).companion
    assert (adaptive.method, adaptive.rtol, adaptive.atol, adaptive.dt) == ("dop853", 1e-9, 1e-7, None)
    with pytest.raises(TypeError, match="RunSettings has no field 'step'"):
        ln.RunSettings().with_changes(step=1e-3)
