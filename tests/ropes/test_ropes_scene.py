"""The scene format of ropes and a ground, its rules and their words; the backend choice (the numpy reference, the
native core refused naming the rope or the ground); the results' slack flags and events; the shipped rope scenes
through the CLI."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rope_references import G

import linknet_core as ln
from linknet_core.scene import description

ROOT = Path(__file__).resolve().parents[2]
ROPE_MODELS = sorted((ROOT / "models" / "ropes").glob("*.json"))


def data(**changes) -> dict:
    base = {"name": "s", "gravity": [0, 0, -G],
            "masses": [{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                       {"name": "bob", "position": [0, 0, -0.5], "mass": 1.0}],
            "links": [{"a": 1, "b": 2, "length": 1.0, "kind": "rope"}]}
    base.update(changes)
    return base


@pytest.mark.parametrize("link,words", [
    ({"a": 1, "b": 2, "kind": "chain"}, "link 1 (pivot-bob) kind must be one of 'rod', 'rope', got 'chain'"),
    ({"a": 1, "b": 2, "kind": None}, "link 1 (pivot-bob) kind must be one of"),
    ({"a": 1, "b": 2, "restitution": 0.5}, "link 1 (pivot-bob) is a rod, which never goes slack: \"restitution\" "
                                           "applies to ropes only"),
    ({"a": 1, "b": 2, "kind": "rope", "restitution": 1.5}, "link 1 (pivot-bob) restitution must lie in [0, 1]"),
    ({"a": 1, "b": 2, "kind": "rope", "restitution": -0.1}, "link 1 (pivot-bob) restitution must lie in [0, 1]"),
    ({"a": 1, "b": 2, "kind": "rope", "restitution": "0.5"}, "link 1 (pivot-bob) restitution must be a number"),
    ({"a": 1, "b": 2, "kind": "rope", "length": 0.0}, "link 1 (pivot-bob) length must be positive"),
    ({"a": 1, "b": 2, "kind": "rope", "length": -1.0}, "link 1 (pivot-bob) length must be positive"),
])
def test_a_bad_rope_is_refused_naming_the_link_and_the_rule(link, words):
    with pytest.raises(ln.SceneError) as err:
        ln.Scene.from_dict(data(links=[link]))
    assert words in str(err.value)


@pytest.mark.parametrize("ground,words", [
    ({"point": [0, 0, -1], "normal": [0, 0, 0]}, "ground normal must be a non-zero vector"),
    ({"point": [0, 0, -1]}, "ground normal is missing"),
    ({"normal": [0, 0, 1]}, "ground point is missing"),
    ({"point": [0, 0, -1], "normal": [0, 0, 1], "restitution": 2}, "ground restitution must lie in [0, 1]"),
    ({"point": [0, 0, -1], "normal": [0, 0, 1], "friction": -0.2}, "ground friction must not be negative"),
    ({"point": [0, 0, -1], "normal": [0, 0, 1], "stiffness": 1e6}, "'ground' has unknown field(s) ['stiffness']"),
    ({"point": [0, 0, 0], "normal": [0, 0, 1]}, 'mass 2 ("bob") starts 0.5 m below the ground'),
    ({"point": [0, 0, -0.8], "normal": [0, 0, -3]}, 'mass 2 ("bob") starts 0.3 m below the ground'),
    ([0, 0, 1], "'ground' must be an object"),
])
def test_a_bad_ground_is_refused_naming_the_field_and_the_rule(ground, words):
    with pytest.raises(ln.SceneError) as err:
        ln.Scene.from_dict(data(ground=ground))
    assert words in str(err.value)


def test_a_mass_on_the_ground_and_an_anchor_below_it_are_allowed_and_the_fields_round_trip():
    scene = ln.Scene.from_dict(data(
        masses=[{"name": "pivot", "position": [0, 0, -3], "fixed": True},
                {"name": "bob", "position": [0, 0, -1], "mass": 1.0}],
        links=[{"a": 1, "b": 2, "length": 2.5, "kind": "rope", "restitution": 0.25}, ],
        ground={"point": [0, 0, -1], "normal": [0, 0, 2], "restitution": 0.5}))
    assert list(scene.rope) == [True] and list(scene.restitution) == [0.25]
    assert np.allclose(scene.ground.normal, [0, 0, 1]) and scene.ground.restitution == 0.5
    again = ln.Scene.from_dict(scene.to_dict())
    assert list(again.rope) == [True] and list(again.restitution) == [0.25]
    assert np.array_equal(again.ground.point, scene.ground.point) and np.array_equal(again.ground.normal,
                                                                                      scene.ground.normal)
    assert (again.ground.restitution, again.ground.friction) == (0.5, 0.0)
    assert again.fingerprint == scene.fingerprint
    rod = ln.Scene.from_dict(data(links=[{"a": 1, "b": 2, "length": 1.0}]))
    assert not rod.unilateral and rod.fingerprint != ln.Scene.from_dict(data()).fingerprint


def test_docs_state_the_rope_and_ground_fields():
    text = (ROOT / "docs" / "scenes.md").read_text()
    for key in description._GROUND_KEYS | {"kind", "restitution", "ground"}:
        assert f"`{key}`" in text, key
    for kind in description.LINK_KINDS:
        assert f'`"{kind}"`' in text, kind
    for rule in ("a free mass starting below the ground", "a zero normal is refused", "refused on a rod"):
        assert rule in text.replace("**", "").lower(), rule


def test_a_rope_longer_than_its_length_at_the_start_is_refused_or_projected():
    stretched = data(masses=[{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                             {"name": "bob", "position": [0, 0, -1.2], "mass": 1.0}])
    with pytest.raises(ln.SceneError) as err:
        ln.Simulator(ln.Scene.from_dict(stretched), "rattle", dt=1e-3)
    assert "link 1 (pivot-bob) is stretched beyond its length (distance 1.2 m vs length 1 m" in str(err.value)
    sim = ln.Simulator(ln.Scene.from_dict(stretched), "rattle", dt=1e-3, project_initial=True)
    assert np.linalg.norm(sim.state.X[1]) == pytest.approx(1.0, rel=1e-14)


def test_a_rope_at_its_length_moving_outwards_at_the_start_takes_an_inelastic_impulse_reported():
    sim = ln.Simulator(ln.Scene.from_dict(data(masses=[
        {"name": "pivot", "position": [0, 0, 0], "fixed": True},
        {"name": "bob", "position": [0, 0, -1.0], "mass": 1.0, "velocity": [1.0, 0, -2.0]}])), "dop853")
    assert np.allclose(sim.state.U[1], [1.0, 0, 0])
    assert any("largest correction 2 m/s" in line for line in sim.initial_report.lines(sim.scene))


# a ground on the adaptive methods and on RATTLE and its compositions runs on the native core
# (tests/native/test_native_ground.py, test_native_friction.py; the native FMU: tests/fmu_native)
@pytest.mark.parametrize("method,step", [("rattle", {"dt": 1e-3}), ("yoshida4", {"dt": 1e-2})])
def test_auto_takes_a_ground_and_ropes_on_the_fixed_step_methods_to_the_native_core(method, step):
    grounded = ln.Scene.from_dict(data(links=[{"a": 1, "b": 2, "length": 0.5}],
                                       ground={"point": [0, 0, -2], "normal": [0, 0, 1], "friction": 0.5}))
    sim = ln.Simulator(grounded, method, **step)
    assert sim.backend == "native" and "backend native" in sim.summary()
    assert ln.Simulator(grounded, method, backend="native", **step).backend == "native"
    assert ln.Simulator(ln.Scene.from_dict(data()), method, **step).backend == "native"


def test_the_outputs_linearization_is_given_for_ropes_and_a_frictionless_ground_and_refused_with_friction():
    # ropes and a frictionless ground: that of the current mode (tests/ropes/test_rope_interface_jacobian.py and
    # test_ground_interface_jacobian.py check it); here the bob is within the rope's length, so the rope is slack and
    # its T has no derivative, and above the ground, so it falls freely: d acc / dF = 1/m
    dF = np.zeros((2, 3))
    dF[1, 2] = 1.0
    assert ln.Simulator(ln.Scene.from_dict(data()), "dop853").interface_linearization().directional(dF=dF)["T"] == 0.0
    smooth = ln.Scene.from_dict(data(links=[], ground={"point": [0, 0, -2], "normal": [0, 0, 1]}))
    assert ln.Simulator(smooth, "dop853").interface_linearization().directional(dF=dF)["acc"][1, 2] == 1.0
    rough = ln.Scene.from_dict(data(links=[], ground={"point": [0, 0, -2], "normal": [0, 0, 1], "friction": 0.5}))
    with pytest.raises(ln.SolverError, match=r"it has a rough ground \(Coulomb friction, mu = 0.5\)"):
        ln.Simulator(rough, "dop853").interface_linearization()


def test_a_run_reports_slack_ropes_per_sample_and_its_events_and_a_snapshot_restores_the_mode():
    scene = ln.Scene.from_dict(data(masses=[{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                                            {"name": "bob", "position": [0.3, 0, -0.4], "mass": 1.0,
                                             "velocity": [1.5, 0, 3.0]}]))
    run = ln.simulate(scene, 1.0, "rattle", dt=1e-3, n_out=11, error_estimate=False)
    assert run.slack.shape == (11, 1) and run.slack.dtype == bool
    assert run.slack[:5, 0].all() and not run.slack[5:, 0].any()  # taut from 0.465 s
    assert [(e.kind, e.index) for e in run.events] == [("taut", 0)]
    assert "events: 1 taut, 0 slack, 0 contact, 0 release" in run.summary()
    sim = ln.Simulator(scene, "rattle", dt=1e-3, error_estimate=False)
    sim.advance(0.4)
    snapshot = sim.get_state()
    sim.advance(0.6)
    first = (sim.state.X.copy(), list(sim.integrator.events))
    sim.set_state(snapshot)
    assert sim.integrator.events == []
    sim.advance(0.6)
    assert np.array_equal(sim.state.X, first[0]) and sim.integrator.events == first[1]
    sim.reset()
    assert sim.integrator.events == [] and sim.outputs()["slack"][0]


@pytest.mark.parametrize("path", ROPE_MODELS, ids=[p.stem for p in ROPE_MODELS])
def test_the_shipped_rope_scenes_run_through_the_cli_and_count_their_events(path, tmp_path):
    out = tmp_path / "run.npz"
    proc = subprocess.run([sys.executable, "-m", "linknet_core.cli", "simulate", str(path), "--t-end", "3",
                           "--no-progress", "--n-out", "31", "--no-error-estimate", "--out", str(out)],
                          capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert "ropes and ground: event by event (the native core on every method" in proc.stdout
    counts = dict((kind, int(n)) for n, kind in
                  (part.split() for part in proc.stdout.split("events: ")[1].splitlines()[0].split(", ")))
    assert counts["taut"] >= 1 and counts["slack"] >= 1
    assert json.loads(path.read_text())["links"][0]["kind"] == "rope"
    saved = np.load(out)
    assert saved["slack"].shape == (31, 1) and saved["slack"].dtype == bool
    assert len(saved["event_t"]) == sum(counts.values()) and set(saved["event_kind"]) <= set(counts)
    assert np.all(saved["event_index"] == 1)  # the hoist rope, or the rope, of each scene (1-based, as k1, k2)


def test_a_runs_npz_holds_its_ground_for_the_pictures(tmp_path):
    """linknet animate/view draw the ground of a .npz from ground_point and ground_normal: save_npz writes the
    scene's, with the events."""
    scene = ln.Scene.from_dict({"name": "ball", "gravity": [0, 0, -9.81],
                                "masses": [{"name": "ball", "position": [0, 0, 1], "mass": 2.0}],
                                "ground": {"point": [0, 0, -0.5], "normal": [0, 0.6, 0.8], "restitution": 0.5}})
    run = ln.simulate(scene, 1.0, n_out=11, error_estimate=False)
    run.save_npz(tmp_path / "ball.npz")
    with np.load(tmp_path / "ball.npz") as z:
        assert np.array_equal(z["ground_point"], [0, 0, -0.5]) and np.allclose(z["ground_normal"], [0, 0.6, 0.8])
        assert list(z["event_kind"][:1]) == ["contact"] and z["event_impulse"][0] > 0
