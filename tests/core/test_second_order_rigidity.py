"""Second-order rigid (prestress-blocked) configurations (structure.rigidity.second_order_rigid_flexes), checked
against the hand-derived answers:

* a taut straight string between two anchors: self-stress omega = (1, 1)/sqrt(2) on its two links (27), flexes the
  middle mass moving across it; q_l(p) = |p|^2 on both links, so omega^T q(p)/R = sqrt(2)|p|^2 > 0 for every flex:
  blocked, ratio exactly 1;
* a flat doubly braced unit square (four free masses, six links): self-stress -1 on the sides, +sqrt(2) on the
  diagonals (each corner: sqrt(2)/sqrt(2) = 1 along each side); its flexes are the six rigid motions (which extend:
  omega^T q = 0) and the twist, corners moving +-1 across the plane alternately: q = 4 on the sides, 0 on the
  diagonals, omega^T q/R = -16: blocked, ratio 1, the flex the twist;
* configurations with no such flex: a chain, the same square lifted out of plane (a tetrahedron: no flex but the
  rigid motions), the string with its middle mass also held by a link off the line (no flex across it)."""
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics.equations import Dynamics
from linknet_core.scene import builders
from linknet_core.structure.rigidity import second_order_rigid_flexes

SQUARE = [(0, 0), (1, 0), (1, 1), (0, 1)]


def braced_square(lift=0.0):
    masses = [{"name": f"c{i}", "mass": 1.0, "position": [x, y, lift if i == 3 else 0.0]}
              for i, (x, y) in enumerate(SQUARE)]
    links = [{"a": f"c{i}", "b": f"c{(i + 1) % 4}"} for i in range(4)] + [{"a": "c0", "b": "c2"},
                                                                         {"a": "c1", "b": "c3"}]
    return ln.Scene.from_dict({"name": "braced_square", "masses": masses, "links": links})


def test_a_taut_string_between_anchors_is_named_as_one():
    scene = builders.taut_string(speed=0.0)
    (case,) = second_order_rigid_flexes(scene)
    assert sorted(case.links) == [0, 1]
    assert list(case.masses) == [1]  # the middle mass, and only it
    assert case.blocking == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(np.abs(case.stress), 1 / np.sqrt(2), atol=1e-12)
    assert abs(case.flex[1, 0]) < 1e-12 and np.linalg.norm(case.flex[1]) == pytest.approx(1.0)  # across the line
    assert "links 1 and 2 are a straight string between anchors left and right" in case.description


def test_a_flat_doubly_braced_square_can_twist_only_to_first_order():
    (case,) = second_order_rigid_flexes(braced_square())
    assert sorted(case.links) == list(range(6))
    assert sorted(case.masses) == [0, 1, 2, 3]
    assert case.blocking == pytest.approx(1.0, abs=1e-12)
    stress = case.stress / case.stress[4]  # diagonal 1 -> sides -1/sqrt(2), diagonals 1
    assert np.allclose(stress, [-1 / np.sqrt(2)] * 4 + [1, 1], atol=1e-12)
    # the twist: every corner across the plane by the same amount, neighbours in opposite senses
    assert np.allclose(case.flex[:, :2], 0, atol=1e-12)
    assert np.allclose(case.flex[:, 2] * np.sign(case.flex[0, 2]), [0.5, -0.5, 0.5, -0.5], atol=1e-12)
    assert "doubly braced panel of masses c0, c1, c2 and c3" in case.description and "twist" in case.description


@pytest.mark.parametrize("scene", [builders.chain(5), braced_square(lift=0.3), builders.redundant_truss(),
                                   builders.net(4, 4)], ids=["chain", "lifted_square", "truss", "net"])
def test_configurations_without_blocked_flexes_report_none(scene):
    assert second_order_rigid_flexes(scene) == []


def test_a_string_held_off_its_line_has_no_flex_across_it():
    d = builders.taut_string(speed=0.0).to_dict()
    d["masses"].append({"name": "below", "position": [1.0, 0.5, -0.5], "fixed": True})
    d["masses"].append({"name": "aside", "position": [1.0, -0.5, -0.5], "fixed": True})
    d["links"] += [{"a": "middle", "b": "below"}, {"a": "middle", "b": "aside"}]
    assert second_order_rigid_flexes(ln.Scene.from_dict(d)) == []


def test_the_new_degenerate_scenes_are_named_in_their_own_terms():
    (string, *_) = second_order_rigid_flexes(builders.triangulated_net_corners())
    assert "links 3, 16 and 29 are a straight string between anchors n0_0 and n3_3" in string.description
    assert {5, 10} <= set(string.masses)  # n1_1 and n2_2 (the flat net moves with them)
    panels = [c.description for c in second_order_rigid_flexes(builders.braced_panel_net())]
    assert any("doubly braced panel of masses n2_2, n2_3, n3_2 and n3_3" in p for p in panels)


def test_a_failure_diagnosis_names_a_string_loaded_across():
    d = builders.taut_string(speed=0.0).to_dict()
    d["gravity"] = [0.0, 0.0, -9.81]  # the middle mass pulled across the straight string
    scene = ln.Scene.from_dict(d)
    text = Dynamics(scene).near_self_stress_load(scene.X0, scene.U0)
    assert "links 1 and 2 are a straight string between anchors left and right" in text
    assert "smaller step cannot help" in text


def test_linknet_analyze_names_the_flat_braced_panels():
    """`linknet analyze` reports the flexes blocked only at second order: the braced panel net's flat cells, none
    on the braced tower (its posts block the top square's twist at first order)."""
    from linknet_core.simulator.analysis import analyze_scene
    models = Path(__file__).resolve().parents[2] / "models"
    panels = analyze_scene(ln.load_scene(models / "degenerate" / "braced_panel_net.json"))
    assert len(panels.blocked_flexes) == 11
    assert "doubly braced panel of masses n0_0, n0_1, n1_0 and n1_1" in panels.text()
    tower = analyze_scene(ln.load_scene(models / "braced_tower.json"))
    assert tower.blocked_flexes == [] and "no flex blocked only at second order" in tower.text()
