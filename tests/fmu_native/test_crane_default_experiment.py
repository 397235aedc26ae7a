"""A plain `fmpy simulate crane.fmu` covers the crane's motion: its DefaultExperiment (the scene's "fmu" section)
runs past the trolley's travel (the scene's waypoint: 3 m at t = 3 s) by at least one swing of the load on its 2 m
rope (small-angle period 2 pi sqrt(L / g)), which goes on swinging after the trolley stops (the rope has no
damping, so there is no settling to wait for). The default of 2 s stopped mid-travel."""
from __future__ import annotations

import csv
import json
import math
import shutil
import subprocess
import sys

import numpy as np
import pytest

import linknet_core as ln
from native_fmu_support import MODELS, built


def _travel(scene):
    """The trolley's (the driven anchor's) last waypoint: when it arrives, and where."""
    spec = scene.motions[0].spec
    t_end, *position = spec["waypoints"][-1]
    return float(t_end), np.array(position, dtype=float)


def test_fmpy_simulate_of_the_crane_fmu_covers_the_travel_and_a_swing_after_it(fmu_root, tmp_path):
    scene = ln.load_scene(MODELS / "crane.json")
    arrival, destination = _travel(scene)
    trolley = int(np.flatnonzero(scene.driven)[0])
    load = int(np.argmax(np.where(scene.fixed, -np.inf, scene.mass)))  # the heaviest free mass
    rope = float(np.linalg.norm(scene.X0[load] - scene.X0[trolley]))
    swing = 2 * math.pi * math.sqrt(rope / float(np.linalg.norm(scene.gravity)))

    fmu = built(fmu_root, "crane")
    stop = float(fmu.md.defaultExperiment.stopTime)
    assert stop >= arrival + swing, (stop, arrival, swing)
    assert stop == json.loads((MODELS / "crane.json").read_text())["fmu"]["stop_time"]

    # the plain command, with nothing but the FMU and an output file
    fmpy_cli = shutil.which("fmpy")
    command = [fmpy_cli] if fmpy_cli else [sys.executable, "-m", "fmpy.command_line"]
    out = tmp_path / "crane.csv"
    proc = subprocess.run(command + ["simulate", str(fmu.path), "--output-file", str(out)], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    with open(out, newline="") as f:
        rows = list(csv.DictReader(f))
    t = np.array([float(r["time"]) for r in rows])
    k, j = trolley + 1, load + 1
    trolley_x = np.array([[float(r[f"X[{k},{i}]"]) for i in (1, 2, 3)] for r in rows])
    load_u = np.array([float(r[f"U[{j},1]"]) for r in rows])
    assert t[-1] == pytest.approx(stop, abs=1e-9)
    arrived = t >= arrival
    np.testing.assert_allclose(trolley_x[arrived], np.broadcast_to(destination, trolley_x[arrived].shape), atol=1e-12)
    assert np.ptp(trolley_x[~arrived][:, 0]) == pytest.approx(destination[0], abs=0.05)  # the travel is in the run
    # after the stop the load swings back and forth: its velocity changes sign within the run
    after = load_u[arrived]
    assert after.max() > 0.1 and after.min() < -0.1, (after.min(), after.max())


def test_both_fmu_kinds_carry_the_scenes_default_experiment(fmu_root):
    stops = {native: float(built(fmu_root, "crane", native=native).md.defaultExperiment.stopTime)
             for native in (True, False)}
    assert stops[True] == stops[False] == json.loads((MODELS / "crane.json").read_text())["fmu"]["stop_time"]
