"""``linknet check`` on scenes with ropes or a ground: the taut system's checks (every rope a rod of the seed), and
the complementarity conditions at the states of a run (T >= 0, gap >= 0, T gap = 0; at the acceleration level for
the touching ropes and contacts) with the LCP against enumerating the active sets. It passes on the shipped rope
scenes, a small rope net and a rope chain landing on the ground, and fails, naming the rope and the condition, on a
deliberately wrong LCP or wrong tensions."""
from __future__ import annotations

import argparse
import re
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics import unilateral
from linknet_core.dynamics.unilateral import UnilateralDynamics
from linknet_core.scene.description import load_scene
from linknet_core.symbolic import check as checks

ROOT = Path(__file__).resolve().parents[2]
CRANE = ROOT / "models" / "ropes" / "rope_crane.json"
PENDULUM = ROOT / "models" / "ropes" / "rope_pendulum.json"
COMPLEMENTARITY = ("ropes, ground: T >= 0, gap >= 0, T gap = 0", "touching: T >= 0, d2gap/dt2 >= 0, T d2gap/dt2 = 0",
                   "LCP = enumeration of the active sets")


def rope_net() -> ln.Scene:
    """Four anchors at the corners of a 2 m square and four masses inside, thrown up into ropes 4 % longer than their
    initial distances (one rod, m1-m2): jerks, slack ropes, taut again."""
    anchors = [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0]]
    free = [[0.7, 0.7, -0.4], [1.3, 0.7, -0.5], [1.3, 1.3, -0.3], [0.7, 1.3, -0.45]]
    velocity = [(0, 0, 3), (0, 1, -1), (1, 0, 2), (0, 0, 4)]
    masses = [{"name": f"A{i + 1}", "position": p, "fixed": True} for i, p in enumerate(anchors)]
    masses += [{"name": f"m{i + 1}", "position": p, "mass": 0.5 + 0.3 * i, "velocity": list(v)}
               for i, (p, v) in enumerate(zip(free, velocity))]
    links = []
    for a, b in [(1, 5), (2, 6), (3, 7), (4, 8), (5, 6), (6, 7), (7, 8), (8, 5)]:
        d = float(np.linalg.norm(np.subtract(masses[b - 1]["position"], masses[a - 1]["position"])))
        links.append({"a": a, "b": b, "length": d} if (a, b) == (5, 6) else
                     {"a": a, "b": b, "length": 1.04 * d, "kind": "rope"})
    return ln.Scene.from_dict({"name": "rope_net", "gravity": [0, 0, -9.81], "masses": masses, "links": links})


def chain_on_ground(friction=0.0) -> ln.Scene:
    """Two masses on a rope, dropped onto a frictionless (or rough) ground, the upper one moving sideways."""
    return ln.Scene.from_dict({
        "name": "rope_chain_on_ground", "gravity": [0, 0, -9.81],
        "masses": [{"name": "a", "position": [0, 0, 0.3], "mass": 1.0},
                   {"name": "b", "position": [0.4, 0, 0.6], "mass": 2.0, "velocity": [0.5, 0, 0]}],
        "links": [{"a": "a", "b": "b", "length": 0.6, "kind": "rope"}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": 0.0, "friction": friction}})


def by_name(results):
    return {r.name: r for r in results}


def counts(detail, pattern):
    return [int(x) for x in re.search(pattern, detail).groups()]


@pytest.fixture(scope="module")
def crane():
    scene = load_scene(CRANE)
    states, run = checks.unilateral_states(scene)
    return scene, states, run


def test_check_passes_on_the_shipped_rope_scenes(capsys):
    args = argparse.Namespace(scene=[str(CRANE), str(PENDULUM)], samples=3, seed=0, kernel=False)
    assert checks.main(args) == 0
    out = capsys.readouterr().out
    assert "FAIL" not in out and out.count("all checks passed") == 2
    assert out.count("the taut system: every rope taut as a rod (1 of 1 links are ropes)") == 2
    for name in COMPLEMENTARITY:  # each printed as a check line, passed (not skipped), on both scenes
        assert len(re.findall(rf"^PASS  {re.escape(name)}", out, re.M)) == 2
    # the crane's taut mode is a scene of rods, so the native core checks it too: its line is a pass, not a skip
    assert re.search(r"^PASS  native core with driven anchors = symbolic", out, re.M)


def test_the_crane_states_hold_taut_and_slack_rope_samples(crane):
    scene, states, run = crane
    assert {e.kind for e in run.events} >= {"slack", "taut"}
    _, taut, comp, _ = checks.run_unilateral_checks(scene, samples=2, states=states)
    assert all(r.passed and not r.skipped for r in taut + comp), [r.line() for r in taut + comp if not r.passed]
    position = by_name(comp)[COMPLEMENTARITY[0]]
    n_taut, n_slack = counts(position.detail, r"(\d+) taut and (\d+) slack")
    assert n_taut > 0 and n_slack > 0  # the rope is slack between the brake's jerk and the load's jerk
    assert n_slack == int(run.slack[:, 0].sum())


def test_check_passes_on_a_rope_net_with_ropes_going_slack_and_taut():
    _, taut, comp, states = checks.run_unilateral_checks(rope_net(), samples=2)
    assert all(r.passed for r in taut + comp), [r.line() for r in taut + comp if not r.passed]
    results = by_name(comp)
    n_taut, n_slack = counts(results[COMPLEMENTARITY[0]].detail, r"(\d+) taut and (\d+) slack")
    assert n_taut > 0 and n_slack > 0
    lcp = results[COMPLEMENTARITY[2]]
    assert not lcp.skipped and counts(lcp.detail, r"\((\d+) with touching")[0] > 0.5 * len(states)


def test_check_passes_on_a_rope_chain_landing_on_the_ground_and_says_why_friction_is_not_enumerated():
    _, taut, comp, _ = checks.run_unilateral_checks(chain_on_ground(), samples=2)
    assert all(r.passed and not r.skipped for r in taut + comp), [r.line() for r in taut + comp if not r.passed]
    assert "mass(es) on the ground at the start" in checks.taut_mode(chain_on_ground())[2]
    _, _, rough, _ = checks.run_unilateral_checks(chain_on_ground(friction=0.3), samples=2)
    lcp = by_name(rough)[COMPLEMENTARITY[2]]
    assert lcp.passed and "enumeration skipped at" in lcp.detail and "Coulomb friction (mu 0.3)" in lcp.detail
    # every Coulomb mode of the touching rope and contacts is enumerated at those same states (the rope taut or slack,
    # each contact off, sliding, stuck or slipping from rest), and with mu 0.3 each state has one solution
    n_friction = counts(lcp.detail, r"enumeration skipped at (\d+) state")[0]
    painleve = by_name(rough)["Coulomb friction: one solution (Painleve)"]
    assert painleve.passed and not painleve.warning and not painleve.skipped, painleve.line()
    assert f"{n_friction} state(s) with a touching contact" in painleve.detail
    assert f"{n_friction} with one solution, 0 with several (ambiguous), 0 with none" in painleve.detail


def test_an_lcp_returning_negative_tensions_fails_naming_the_rope(crane, monkeypatch):
    scene, states, _ = crane
    real = unilateral.solve_mixed_lcp

    def negated(W, b, rows_uni, start=None, release=None):
        lam, basis = real(W, b, rows_uni, start, release)
        return np.where(rows_uni, -lam, lam), basis  # the active set kept, its tensions' signs wrong

    monkeypatch.setattr(unilateral, "solve_mixed_lcp", negated)
    _, _, comp, _ = checks.run_unilateral_checks(scene, samples=2, states=states)
    lcp = by_name(comp)[COMPLEMENTARITY[2]]
    assert not lcp.passed
    assert "FAIL" in lcp.line() and "BROKEN: LCP multiplier >= 0 at rope link 1 (trolley-load)" in lcp.detail


def test_negative_reported_tensions_fail_the_position_and_acceleration_conditions(crane, monkeypatch):
    scene, states, _ = crane
    real = UnilateralDynamics.resolve

    def pushing(self, X, U, F_input=None, anchor_acc=None):
        T, normal = real(self, X, U, F_input, anchor_acc)
        return np.where(self.scene.rope, -T, T), normal

    monkeypatch.setattr(UnilateralDynamics, "resolve", pushing)
    _, _, comp, _ = checks.run_unilateral_checks(scene, samples=2, states=states)
    results = by_name(comp)
    for name in COMPLEMENTARITY[:2]:
        assert not results[name].passed
        assert "BROKEN: T >= 0 at rope link 1 (trolley-load)" in results[name].detail


def test_enumeration_above_its_limit_is_skipped_and_says_why(crane, monkeypatch):
    scene, states, _ = crane
    monkeypatch.setattr(checks, "ENUMERATION_MAX", 0)
    _, _, comp, _ = checks.run_unilateral_checks(scene, samples=2, states=states)
    lcp = by_name(comp)[COMPLEMENTARITY[2]]
    assert "more touching ropes and contacts than ENUMERATION_MAX = 0" in lcp.detail
    assert by_name(comp)[COMPLEMENTARITY[1]].passed  # the conditions themselves are still checked
