"""The failure path's diagnosis of loads across near-self-stresses (Dynamics.near_self_stress_load): a braced square
(both diagonals) hinged on two anchors, one free corner lifted by delta out of the others' plane, is a tetrahedron of
height ~delta: its self-stress is near (eigenvalue ~(delta/R)^2 of A's largest) and a force F across the cell needs
tensions ~F R / delta, so the diagnosis names the cell's links and figures that grow as the cell flattens."""
import re

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics.equations import Dynamics


def braced_square(lift, force):
    return ln.Scene.from_dict({
        "name": "braced_square", "gravity": [0, 0, 0],
        "masses": [{"name": "a1", "position": [0, 0, 0], "fixed": True},
                   {"name": "a2", "position": [1, 0, 0], "fixed": True},
                   {"name": "b2", "mass": 1.0, "position": [1, 1, 0]},
                   {"name": "b1", "mass": 1.0, "position": [0, 1, lift], "force": force}],
        "links": [{"a": "a1", "b": "b1"}, {"a": "a2", "b": "b2"}, {"a": "b1", "b": "b2"},
                  {"a": "a1", "b": "b2"}, {"a": "a2", "b": "b1"}]})


def figures(text):
    eigenvalue = float(re.search(r"eigenvalue ([0-9.e+-]+) of the largest", text).group(1))
    tension = float(re.search(r"tensions of ~([0-9.e+-]+) N", text).group(1))
    return eigenvalue, tension


@pytest.mark.parametrize("lift", [1e-4, 1e-6])
def test_a_load_across_a_nearly_flat_braced_cell_is_named_with_its_figures(lift):
    scene = braced_square(lift, [0.0, 0.0, 10.0])
    text = Dynamics(scene).near_self_stress_load(scene.X0, scene.U0)
    for link in ("a1-b1", "a2-b2", "b1-b2", "a1-b2", "a2-b1"):
        assert link in text
    assert "smaller step cannot help" in text and "spring" in text
    eigenvalue, tension = figures(text)
    assert 0.1 * lift ** 2 < eigenvalue < 10 * lift ** 2  # (delta/R)^2
    assert 0.5 * 10.0 / lift < tension < 5 * 10.0 / lift  # ~F R / delta


def test_loads_the_links_can_carry_get_no_diagnosis():
    # the same cell flat, pushed in its plane: B is orthogonal to the self-stress (32), the tensions are finite
    flat = braced_square(0.0, [3.0, 5.0, 0.0])
    assert Dynamics(flat).near_self_stress_load(flat.X0, flat.U0) == ""
    # a cell well out of plane (a tetrahedron of height 0.3 R) pushed across: stiff, no near-self-stress
    raised = braced_square(0.3, [0.0, 0.0, 10.0])
    assert Dynamics(raised).near_self_stress_load(raised.X0, raised.U0) == ""
