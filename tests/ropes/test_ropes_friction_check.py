"""`linknet check` on scenes with Coulomb friction: the mode chosen at each sampled state (stuck, sliding, slipping
from rest) is solved again from Newton's laws with Coulomb's friction (check.py's own rows), and Coulomb's
conditions are checked on it; a friction that breaks them (too large, held beyond the cone, slipping where the
ground holds) fails, naming the mass."""
from __future__ import annotations

import re

import numpy as np
import pytest
from test_ropes_friction_coupled import DUMBBELL, LEANING

from linknet_core.dynamics.unilateral import UnilateralDynamics
from linknet_core.symbolic import check as checks

FRICTION_CHECK = "Coulomb friction: the mode against Newton's laws"


def counts(result):
    return [int(x) for x in re.search(r"over them (\d+) stuck, (\d+) sliding, (\d+) slipping from rest",
                                      result.detail).groups()]


@pytest.fixture(scope="module")
def sliding_states():
    """The leaning rod and the dumbbell slipping from rest, 0.3 s of each (their first state at rest)."""
    return {name: (case.scene(), checks.unilateral_states(case.scene(), t_end=0.3, n=4)[0])
            for name, case in (("leaning", LEANING), ("dumbbell", DUMBBELL))}


def friction_result(scene, states):
    _, _, comp, _ = checks.run_unilateral_checks(scene, samples=1, states=states)
    return {r.name: r for r in comp}


@pytest.mark.parametrize("name", ["leaning", "dumbbell"])
def test_the_slip_from_rest_and_the_sliding_pass_coulombs_conditions(sliding_states, name):
    scene, states = sliding_states[name]
    results = friction_result(scene, states)
    assert all(r.passed for r in results.values()), [r.line() for r in results.values() if not r.passed]
    coulomb = results[FRICTION_CHECK]
    assert not coulomb.skipped and coulomb.discrepancy < 1e-12
    stuck, sliding, from_rest = counts(coulomb)
    n_contacts = 1 if name == "leaning" else 2
    assert (stuck, sliding, from_rest) == (0, 4 * n_contacts, n_contacts)


def test_a_friction_larger_than_mu_n_fails_naming_the_mass(sliding_states, monkeypatch):
    scene, states = sliding_states["dumbbell"]
    real = UnilateralDynamics.ground_forces

    def rougher(self, X, U, F_input=None, anchor_acc=None):
        normal, tangential = real(self, X, U, F_input, anchor_acc)
        return normal, 1.01 * tangential
    monkeypatch.setattr(UnilateralDynamics, "ground_forces", rougher)
    coulomb = friction_result(scene, states)[FRICTION_CHECK]
    assert not coulomb.passed and coulomb.discrepancy == pytest.approx(0.01 * 0.3, rel=1e-6)  # 1% of mu N, of N
    assert re.search(r'BROKEN: sliding: F_t = -mu N d at the ground contact of mass [12] \("m[12]"\) at t = ',
                     coulomb.detail)


def test_a_mass_held_beyond_the_cone_fails(sliding_states, monkeypatch):
    scene, states = sliding_states["leaning"]
    monkeypatch.setattr(UnilateralDynamics, "choose_stuck",
                        lambda self, X, U, active, candidates, F_input=None, anchor_acc=None:
                        np.asarray(candidates, bool) & np.asarray(active, bool)[self.rope_links.size:])
    coulomb = friction_result(scene, states[:1])[FRICTION_CHECK]
    assert not coulomb.passed
    assert 'BROKEN: stuck: |F_t| <= mu N at the ground contact of mass 1 ("m1")' in coulomb.detail


def test_a_mass_slipping_where_the_ground_holds_it_fails(monkeypatch):
    # a block on a slope below its friction angle (0.3 rad, mu 0.5) stays; let it slip (nothing may stick) and its
    # friction mu m g cos a, larger than the weight's pull m g sin a, leaves an acceleration against the slip
    from rope_references import slope
    scene = slope(0.3, 0.5)[0]
    states, _ = checks.unilateral_states(scene, t_end=0.1, n=2)
    assert friction_result(scene, states)[FRICTION_CHECK].passed
    monkeypatch.setattr(UnilateralDynamics, "choose_stuck",
                        lambda self, X, U, active, candidates, F_input=None, anchor_acc=None:
                        np.zeros(self.contact_masses.size, bool))
    coulomb = friction_result(scene, states[:1])[FRICTION_CHECK]
    assert not coulomb.passed
    assert 'BROKEN: slip direction at the ground contact of mass 1 ("block")' in coulomb.detail
