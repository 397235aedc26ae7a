"""Helpers of the ensemble tests: the serial in-process runs the members are compared with."""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln

ROOT = Path(__file__).resolve().parents[2]
MODELS = ROOT / "models"


def _span(text: str) -> slice:
    """'3' or '1..10' (1-based, inclusive) -> a 0-based slice."""
    first, _, last = text.partition("..")
    return slice(int(first) - 1, int(last or first))


def serial_run(scene, setting: dict, t_end: float, n_out: int, method=None, dt=None, rtol=None,
               project_initial=None):
    """The member run serially in this process through the library's public API only (its own reading of
    the parameter names, not the ensemble module's): ``ln.simulate`` on the scene with the member's values (with
    neither method nor dt, the library's default, as a study's)."""
    mass, length, gravity = np.array(scene.mass), np.array(scene.length), np.array(scene.gravity)
    U0 = np.array(scene.U0)
    forces = np.zeros((scene.K, 3))
    data = scene.to_dict()
    for name, value in setting.items():
        family, index = re.fullmatch(r"(\w+)(?:\[(.*)\])?", name).groups()
        slots = tuple(_span(s) for s in index.split(",")) if index else ()
        target = {"M": mass, "R": length, "g": gravity, "F": forces, "U0": U0}.get(family)
        if target is not None:
            target[slots] = value
        elif family in ("stiffness", "damping", "rest_length"):
            for spring in data["springs"][slots[0]]:
                spring[family] = value
        elif family == "drag":
            for entry in data["masses"][slots[0]]:
                entry["drag"] = value
        else:
            raise AssertionError(f"serial_run does not know {name}")
    changed = ln.Scene.from_dict(data).with_parameters(mass=mass, length=length, gravity=gravity).with_state(U0=U0)
    return ln.simulate(changed, t_end, method=method, dt=dt, rtol=rtol, n_out=n_out,
                       forces=forces if any(n.startswith("F[") for n in setting) else None,
                       project_initial=project_initial)


def assert_member_equals(ds, member: int, reference) -> None:
    """X, U, T, the quantities of interest and the error estimate of one member are bit for bit those of its
    serial run (a study runs each member as that same ln.simulate call, on whichever worker)."""
    np.testing.assert_array_equal(ds["X"].values[member], reference.X)
    np.testing.assert_array_equal(ds["U"].values[member], reference.U)
    np.testing.assert_array_equal(ds["T"].values[member], reference.T)
    assert ds["max_tension"].values[member] == reference.T.max()
    assert ds["min_tension"].values[member] == reference.T.min()
    tip = int(ds.attrs["tip_mass"]) - 1
    np.testing.assert_array_equal(ds["tip_final"].values[member], reference.X[-1, tip])
    # the member's error estimate is its run's companion's, as the serial run computes it
    assert ds["error_estimate"].values[member] == reference.max_error_estimate
    assert ds["error_goal"].values[member] == reference.error_goal


def four_member_study(outputs=("X", "T")):
    """(spec, plan, scene) of a small study written without a cluster: double_pendulum, M[2] at 1 .. 4 kg, three
    samples to 0.1 s, RATTLE at 1 ms."""
    from linknet_core.ensemble.members import StudySpec
    from linknet_core.ensemble.parameters import make_plan

    scene = ln.load_scene(MODELS / "double_pendulum.json")
    plan = make_plan(scene, {"M[2]": [1.0, 2.0, 3.0, 4.0]}, None)
    spec = StudySpec(study_id="0123456789abcdef", scene=scene.to_dict(), parameters=plan.parameters,
                     times=np.linspace(0, 0.1, 3), method="rattle", dt=1e-3, rtol=None, atol=None,
                     project_initial=None, outputs=outputs, tip=2)
    return spec, plan, scene


def client_batch(first, count, seed):
    """A batch as a worker returns it when the client is to write its shard: arbitrary numbers, each member's."""
    rng = np.random.default_rng(seed)
    return {"first": first, "count": count, "worker": "tcp://w:1", "error": [""] * count,
            "run_seconds": rng.random(count),
            "outputs": {"X": rng.random((count, 3, 3, 3)), "T": rng.random((count, 3, 2)),
                        "max_tension": rng.random(count)}}
