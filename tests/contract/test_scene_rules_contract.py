"""Scene rules, each answered in words: a JSON null name, a mass on a driven anchor, prescribed motions a fixed step
cannot follow (a waypoint closer than one step, a sine above the step's Nyquist rate) and the step failure such a
motion causes in an adaptive method, named in the scene's terms; Scene.save written whole or not at all; and
docs/scenes.md stating every field and rule the parser enforces."""
from __future__ import annotations

import os
import subprocess
import sys

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.errors import SceneError, SolverError
from linknet_core.scene import description
from linknet_core.scene.builders import pendulum
from linknet_core.scene.description import Scene

from contract_support import ROOT


def pendulum_data() -> dict:
    return pendulum().to_dict()


def driven(motion: dict) -> dict:
    data = pendulum_data()
    pivot = data["masses"][0]
    pivot.pop("fixed", None)
    pivot["driven"], pivot["motion"] = True, motion
    return data


@pytest.mark.parametrize("where, expected", [
    (lambda d: d.__setitem__("name", None), "the scene's name must be a string, got None (a JSON null)"),
    (lambda d: d["masses"][1].__setitem__("name", None), "mass 2 name must be a string, got None (a JSON null)"),
    (lambda d: d["links"][0].__setitem__("name", None), "name must be a string, got None (a JSON null)"),
    (lambda d: d.__setitem__("description", None), "the scene's description must be a string, got None"),
], ids=["scene", "mass", "link", "description"])
def test_a_null_name_is_refused_naming_the_field(where, expected):
    data = pendulum_data()
    where(data)
    with pytest.raises(SceneError, match=expected.replace("(", r"\(").replace(")", r"\)")):
        Scene.from_dict(data, source="s.json")


def test_a_left_out_name_still_takes_its_default():
    data = pendulum_data()
    del data["name"], data["masses"][1]["name"]
    scene = Scene.from_dict(data, source="s.json")
    assert scene.name == "scene" and scene.mass_names[1] == "m2"


def test_a_mass_on_a_driven_anchor_is_refused():
    data = driven({"kind": "velocity", "velocity": [1.0, 0.0, 0.0]})
    data["masses"][0]["mass"] = 5.0
    with pytest.raises(SceneError, match=r'mass 1 \("pivot"\) is driven: .* a "mass" would have no effect'):
        Scene.from_dict(data, source="s.json")


# ------------------------------------------------------------------------------------------- motions and steps
NEAR_WAYPOINT = {"kind": "waypoints", "waypoints": [[1e-12, 1.0, 0.0, 0.0]]}


def test_a_waypoint_closer_than_one_fixed_step_is_refused_naming_it():
    scene = Scene.from_dict(driven(NEAR_WAYPOINT), source="s.json")
    with pytest.raises(SolverError, match=r'mass 1 \("pivot"\) is driven, and its waypoint 1 \(t = 1e-12 s\) comes '
                                          r"1e-12 s after the start, less than one step dt = 0.001 s"):
        ln.Simulator(scene, "rattle", dt=1e-3)


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_the_adaptive_failure_at_such_a_waypoint_names_the_anchor_and_its_acceleration(backend):
    # the clamped cubic from rest to rest over T has peak acceleration 6 d / T^2: 6e24 m/s^2 for 1 m in 1e-12 s
    scene = Scene.from_dict(driven(NEAR_WAYPOINT), source="s.json")
    with pytest.raises(SolverError) as failure:
        ln.simulate(scene, t_end=0.01, backend=backend)
    text = str(failure.value)
    assert "step size underflow" in text
    assert 'mass 1 ("pivot") is driven: its spline to waypoint 1 (t = 1e-12 s, 1e-12 s after the start)' in text
    assert "accelerates it at up to 6e+24 m/s^2" in text


def test_waypoints_a_step_apart_run():
    scene = Scene.from_dict(driven({"kind": "waypoints", "waypoints": [[0.01, 0.01, 0.0, 0.0]]}), source="s.json")
    result = ln.simulate(scene, t_end=0.02, method="rattle", dt=0.01)
    assert np.allclose(result.X[-1, 0], [0.01, 0.0, 0.0])  # the anchor reached its waypoint


def test_a_sine_above_the_steps_nyquist_rate_is_refused_and_below_it_runs_and_follows_the_motion():
    f = 100.0
    scene = Scene.from_dict(driven({"kind": "sine", "amplitude": [0.001, 0.0, 0.0], "frequency": [f, 0.0, 0.0]}),
                            source="s.json")
    nyquist_dt = 1.0 / (2.0 * f)
    with pytest.raises(SolverError, match=r"its sine of 100 Hz on axis 1 gets 1.82 steps per period at "
                                          r"dt = 0.0055 s, and a fixed step needs at least 2 \(Nyquist\): "
                                          r"dt <= 0.005 s"):
        ln.Simulator(scene, "rattle", dt=0.0055)
    # at the rule, the run follows it: the anchor's samples are the prescribed sine
    result = ln.simulate(scene, t_end=0.05, method="rattle", dt=nyquist_dt / 4, output_dt=nyquist_dt / 4)
    assert np.allclose(result.X[:, 0, 0], 0.001 * np.sin(2 * np.pi * f * result.t), atol=1e-12)


# ------------------------------------------------------------------------------------------------- Scene.save
def test_scene_save_is_whole_or_nothing(tmp_path):
    target = tmp_path / "scene.json"
    pendulum().save(target)
    previous = target.read_bytes()
    script = ("import signal, resource, sys\n"
              "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
              f"resource.setrlimit(resource.RLIMIT_FSIZE, ({len(previous) * 2}, {len(previous) * 2}))\n"
              "from linknet_core.scene.builders import chain\n"
              "from linknet_core.output import WriteError\n"
              "try:\n"
              f"    chain(2000).save({str(target)!r})\n"
              "except WriteError as exc:\n"
              "    print(exc)\n"
              "    sys.exit(3)\n")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 3, proc.stderr
    assert f"cannot write {target}" in proc.stdout
    assert target.read_bytes() == previous  # the old file intact
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]  # no temporary left beside it


# ------------------------------------------------------------------------------------------------ the docs
def test_docs_state_every_scene_field_and_the_link_rules():
    text = (ROOT / "docs" / "scenes.md").read_text()
    plain = text.replace("**", "").lower()
    for keys in (description._SCENE_KEYS, description._MASS_KEYS, description._LINK_KEYS, description._SPRING_KEYS,
                 description._OPTION_KEYS, description._GROUND_KEYS):
        for key in keys:
            assert f"`{key}`" in text, key
    for rule in ("at most one link may join a pair", "joins two anchored masses", "joins mass",
                 "a json null", "steps per period", "one step per interval between waypoints"):
        assert rule in plain, rule
