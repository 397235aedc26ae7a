"""linknet analyze of a scene with ropes and a ground: the ropes and which are slack at the start, the ground and the
masses on it, and the path that runs it (the native core on every method, friction included)."""
from __future__ import annotations

import linknet_core as ln
from linknet_core.simulator.analysis import analyze_scene


def test_analyze_describes_the_ropes_the_ground_and_the_path():
    # a taut hanging rope (pulled by the weight), a rope shorter than its length (slack), a mass on the ground
    scene = ln.Scene.from_dict({"name": "yard", "gravity": [0, 0, -9.81],
                                "masses": [{"name": "hook", "position": [0, 0, 3], "fixed": True},
                                           {"name": "load", "position": [0, 0, 2], "mass": 1.0},
                                           {"name": "loose", "position": [1, 0, 2.5], "mass": 1.0},
                                           {"name": "crate", "position": [3, 0, 0], "mass": 2.0}],
                                "links": [{"a": "hook", "b": "load", "length": 1.0, "kind": "rope"},
                                          {"a": "hook", "b": "loose", "length": 2.0, "kind": "rope",
                                           "restitution": 0.5}],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": 0.2,
                                           "friction": 0.4}})
    text = analyze_scene(scene).text()
    assert "ropes: 2 of 2 links are ropes (pull only; restitution 0, 0.5)" in text
    assert 'slack at the start: 1 (link 2 (hook-loose))' in text
    assert ("ground: the plane through [0.0, 0.0, 0.0] with normal [0.0, 0.0, 1.0], restitution 0.2, friction 0.4 "
            "(Coulomb)") in text
    assert 'masses on the ground at the start: 1 (mass 4 ("crate"))' in text
    assert "path: the native core, event by event, on every method" in text and "Coulomb friction" in text
    assert "native path" not in text


def test_analyze_takes_a_mass_alone_on_a_rough_ground():
    """No links, so no tension system to condition: said so, and the ground and its path are described."""
    scene = ln.Scene.from_dict({"name": "block", "gravity": [0, 0, -9.81],
                                "masses": [{"name": "b", "position": [0, 0, 0], "mass": 1, "velocity": [1, 0, 0]}],
                                "links": [],
                                "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": 0.3}})
    text = analyze_scene(scene).text()
    assert "condition estimate of A at the initial state: nan (no links)" in text
    assert "friction 0.3 (Coulomb)" in text
    assert "masses on the ground at the start: 1" in text
