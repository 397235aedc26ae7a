"""`linknet check`'s interface Jacobian line: the derivatives of T, dU/dt and the reactions with respect to F, P, V, A
from the numpy reference and the native core against casadi's AD of the derived system. It passes on driven and
redundant scenes, and catches a linearization missing any one of its terms (test doubles of the numeric side)."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
import linknet_core.dynamics.interface_jacobian as interface_jacobian
from linknet_core.symbolic import check as checks
from driven_anchor_scenes import drive

LINE = "interface Jacobians: dT, dU/dt, Freact by F, P, V, A = AD"


def _line(scene, native=True, samples=3):
    """The line as run_checks computes it: its check alone, on states sampled as run_checks samples them (the other
    checks, which these tests do not read, cost most of the battery's time)."""
    sym = checks.SymbolicTensionSystem(scene)
    rng = np.random.default_rng(0)
    on = checks.sample_states(scene, sym, samples, rng, on_manifold=True)
    off = checks.sample_states(scene, sym, samples, rng, on_manifold=False)
    with checks.single_threaded_blas():
        line = checks._check_interface_jacobian(scene, sym, checks._default_dynamics(scene), sym.forces_function(),
                                                on, off, 0, native)
    assert line.name == LINE
    return line


def _hooked_spring():
    return ln.Scene.from_dict({
        "name": "hooked_spring", "gravity": [0, 0, -9.81],
        "masses": [{"name": "hook", "position": [0, 0, 0], "driven": True},
                   {"name": "m1", "mass": 0.7, "position": [0.4, 0.1, -0.3]},
                   {"name": "tip", "mass": 1.2, "position": [0.6, -0.2, -0.7], "drag": 0.3}],
        "links": [{"a": "hook", "b": "m1"}, {"a": "m1", "b": "tip"}],
        "springs": [{"a": "hook", "b": "tip", "stiffness": 30.0, "damping": 0.8, "rest_length": 0.5}]})


SCENES = {
    "crane_input": lambda: ln.load_scene("models/crane.json").with_motions({1: {"kind": "input"}}),
    "redundant_truss_driven": lambda: drive(ln.load_scene("models/redundant_truss.json"), 0, None),
    "braced_tower_driven": lambda: drive(ln.load_scene("models/braced_tower.json"), 0, None),
    "hooked_spring": _hooked_spring,
}


@pytest.mark.parametrize("name", list(SCENES))
def test_the_line_passes_on_driven_and_redundant_scenes_for_both_cores(name):
    line = _line(SCENES[name]())
    assert line.passed and not line.skipped, line.line()
    assert "native" in line.detail and "P, V, A of the driven anchors" in line.detail


class _WithoutPseudoInverse(interface_jacobian.ReferenceLinearization):
    """Treats a singular A as regular: drops both terms of the pseudo-inverse's derivative."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        self.singular = False


class _WithoutInconsistentTerm(interface_jacobian.ReferenceLinearization):
    """Drops A^+ A^+ dA (I - Pi) B: right where B is consistent, wrong off the manifold."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        if self.singular:
            self.inconsistent = np.zeros_like(self.inconsistent)


class _WithoutRangeTurn(interface_jacobian.ReferenceLinearization):
    """Drops (I - Pi) dA A^+ T: the turn of range(A) with the geometry."""

    def __init__(self, *args, **kw):
        super().__init__(*args, **kw)
        if self.singular:
            self.T_solved = np.zeros_like(self.T_solved)


class _WithoutGeometry(interface_jacobian.ReferenceLinearization):
    """Drops dA T: the tension matrix held fixed as the anchor moves."""

    def _dA_times(self, dE, y):
        return np.zeros_like(y)


def _without_element_derivatives(scene, X, U, dX, dU):
    return np.zeros_like(X)


@pytest.mark.parametrize("name, wrong", [("redundant_truss_driven", _WithoutPseudoInverse),
                                         ("redundant_truss_driven", _WithoutInconsistentTerm),
                                         ("redundant_truss_driven", _WithoutRangeTurn),
                                         ("crane_input", _WithoutGeometry)])
def test_a_linearization_missing_a_term_is_caught(monkeypatch, name, wrong):
    monkeypatch.setattr(interface_jacobian, "ReferenceLinearization", wrong)
    line = _line(SCENES[name](), native=False)
    assert not line.passed and line.discrepancy > 1e3 * line.tolerance, line.line()


def test_a_spring_hooked_to_the_anchor_without_its_derivative_is_caught(monkeypatch):
    monkeypatch.setattr(interface_jacobian, "element_force_derivative", _without_element_derivatives)
    line = _line(_hooked_spring(), native=False)
    assert not line.passed and line.discrepancy > 1e3 * line.tolerance, line.line()


def test_a_numeric_side_that_is_not_a_dynamics_is_skipped_not_failed():
    class Partial:
        def __init__(self, scene):
            self.real = ln.Dynamics(scene)
            self.scene = scene

        def __getattr__(self, name):
            if name in ("_scatter", "anchor_reactions"):
                raise AttributeError(name)
            return getattr(self.real, name)

    scene = ln.load_scene("models/four_bar.json")
    results = checks.run_checks(scene, samples=1, seed=0, dynamics=Partial(scene), native=False)
    line = next(r for r in results if r.name == LINE)
    assert line.passed and line.skipped and "not a Dynamics" in line.detail
