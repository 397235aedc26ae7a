"""Every shipped scene's native FMU runs its own DefaultExperiment (startTime to stopTime in communication steps
of stepSize) with its default integrator and parameters in the plain C host, with no Python anywhere: every
doStep returns fmi2OK and the link lengths (11) hold at the stop time. The library's runs of every scene with
every method are tests/core/test_shipped_scenes_run.py; every method in the FMU runs with -m slow."""
import json

import numpy as np
import pytest

import linknet_core as ln
from native_fmu_support import MODELS, SCENES, built, parse_rows, run_host

METHODS_IN_FMU = ["rattle", "yoshida4", "suzuki4", "yoshida6", "yoshida8", "dopri5", "dop853"]


def _default_experiment_run(fmu_root, host, env, scene: str, method: str | None):
    fmu = built(fmu_root, scene)
    experiment = fmu.md.defaultExperiment
    t0, t_end, h = float(experiment.startTime), float(experiment.stopTime), float(experiment.stepSize)
    scene_file = json.loads((MODELS / f"{scene}.json").read_text())
    assert t_end == float(scene_file.get("fmu", {}).get("stop_time", 2.0))  # the stop time the library test uses
    n = int(round((t_end - t0) / h))
    assert n > 0 and abs(t0 + n * h - t_end) <= 1e-9 * t_end
    names = fmu.names("X")
    options = [item for name in names for item in ("-o", str(fmu.vr[name]))]
    if method:
        options += ["-m", f"{fmu.vr['integrator']}={method}"]
    rows = parse_rows(run_host(host, env, "run", fmu, t0, n, h, *options))  # exits non-zero unless all fmi2OK
    assert rows.shape == (n + 1, 1 + len(names)) and abs(rows[-1, 0] - t_end) <= 1e-9 * t_end
    assert np.all(np.isfinite(rows))
    # the positions at the stop time, anchors included: the links' lengths (11)
    sc = ln.load_scene(MODELS / f"{scene}.json")
    X = np.array(sc.X0, dtype=float)
    for j, name in enumerate(names):
        k, i = (int(v) - 1 for v in name[2:-1].split(","))
        X[k, i] = rows[-1, 1 + j]
    if sc.L:
        residual = ln.Dynamics(sc).constraint_residual(X)
        assert residual <= 1e-12, (scene, method, residual)
    return rows


@pytest.mark.parametrize("scene", SCENES)
def test_every_shipped_scene_runs_its_default_experiment_in_the_native_fmu(scene, fmu_root, host, no_python_env):
    rows = _default_experiment_run(fmu_root, host, no_python_env, scene, None)
    if scene != "redundant_truss":  # a static truss: nothing moves
        assert np.ptp(rows[:, 1:], axis=0).max() > 0.0


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES)
def test_every_shipped_scene_runs_its_default_experiment_in_the_native_fmu_with_every_method(
        scene, fmu_root, host, no_python_env):
    for method in METHODS_IN_FMU:
        _default_experiment_run(fmu_root, host, no_python_env, scene, method)
