"""Every shipped scene's native FMU runs its own DefaultExperiment (startTime to stopTime in communication steps
of stepSize) with its default integrator and parameters in the plain C host, with no Python anywhere: every
doStep returns fmi2OK and the link lengths (11) hold at the stop time. Its error_estimate output equals the library's
default run's (dop853 at rtol 1e-8 and its own companion run) at every communication point, stays within the run's
goal wherever the library's does, and every crossing of the goal is logged once (category logErrorEstimate) while
the steps stay fmi2OK. The library's runs of every scene with
every method are tests/core/test_shipped_scenes_run.py; every method in the FMU runs with -m slow."""
import json
import subprocess

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
    names = fmu.names("X") + ["error_estimate"]
    options = [item for name in names for item in ("-o", str(fmu.vr[name]))]
    if method:
        options += ["-m", f"{fmu.vr['integrator']}={method}"]
    # the host exits non-zero unless every call returns fmi2OK; verbose, it writes what the FMU logs to stderr
    cmd = [str(host), "run", str(fmu.dir), fmu.ident, fmu.guid, repr(t0), str(n), repr(h)] + options
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=300, env=dict(env, NATIVE_HOST_VERBOSE="1"))
    assert proc.returncode == 0, f"{scene}: the host exited {proc.returncode}\n{proc.stderr[-3000:]}"
    rows = parse_rows(proc.stdout)
    assert rows.shape == (n + 1, 1 + len(names)) and abs(rows[-1, 0] - t_end) <= 1e-9 * t_end
    assert np.all(np.isfinite(rows))
    # the positions at the stop time, anchors included: the links' lengths (11)
    sc = ln.load_scene(MODELS / f"{scene}.json")
    X = np.array(sc.X0, dtype=float)
    for j, name in enumerate(names[:-1]):
        k, i = (int(v) - 1 for v in name[2:-1].split(","))
        X[k, i] = rows[-1, 1 + j]
    if sc.L:
        residual = ln.Dynamics(sc).constraint_residual(X)
        assert residual <= 1e-12, (scene, method, residual)
    return rows, [line for line in proc.stderr.splitlines() if " logErrorEstimate " in line]


# After ~1.05 s these two pass a singular configuration that no tolerance resolves at rtol 1e-8: the estimate exceeds
# the goal there and stays above it (net_10x10 already from t = 0.5 s: 1.11e-6 m against its goal of 1e-6 m)
SINGULAR_PASSAGE = {"net_10x10": 0.45, "chain_100": 1.0}  # scene -> until when the estimate is within its goal


@pytest.mark.parametrize("scene", SCENES)
def test_every_shipped_scene_runs_its_default_experiment_in_the_native_fmu(scene, fmu_root, host, no_python_env):
    rows, notes = _default_experiment_run(fmu_root, host, no_python_env, scene, None)
    if scene != "redundant_truss":  # a static truss: nothing moves
        assert np.ptp(rows[:, 1:-1], axis=0).max() > 0.0
    # the library's default run over the same communication points, with its own companion
    t, estimate = rows[:, 0], rows[:, -1]
    sim = ln.Simulator(ln.load_scene(MODELS / f"{scene}.json"))
    start = {v.name: v.start for v in built(fmu_root, scene).md.modelVariables}
    assert start["integrator"] == "dop853" and float(start["tolerance"]) == 1e-8 and start["estimate_error"] in (
        True, "true"), scene  # error-controlled by default, with its estimate
    library = [sim.error_estimate]
    for tn in t[1:]:
        sim.advance(tn)
        library.append(sim.error_estimate)
    library, goal = np.array(library), sim.error_goal
    # Where the library's run is within its goal the two agree far inside it (the same arithmetic; a C host and a
    # Python process differ at round-off, ~1e-16 m, from the first steps) and the FMU's is within the goal too.
    # Beyond it (net_10x10, chain_100) the passage through a singular configuration amplifies that round-off: the
    # estimates part, and both stay beyond the goal. braced_tower passes near one between 0.7 and 0.8 s (A's two
    # smallest eigenvalues 8e-6 of the largest): from 1.85 s its estimates part by up to 3.1e-9 m, 1.5e-3 of its goal
    # (measured: FMU 2.1e-9 m, library 4.1e-11 m, both far within the goal).
    within = library <= goal
    np.testing.assert_allclose(estimate[within], library[within], rtol=0, atol=1e-2 * goal, err_msg=scene)
    assert np.all(estimate[within] <= goal), scene
    assert np.all(estimate[t >= 1.5] > goal) == np.all(library[t >= 1.5] > goal), scene
    # every crossing of the goal is said once, naming the time, the estimate and the goal
    over = estimate > goal
    crossings = np.flatnonzero(over & ~np.concatenate([[False], over[:-1]]))
    assert len(notes) == len(crossings), (scene, notes, t[crossings])
    for i, note in zip(crossings, notes):
        assert f"at t = {t[i]:g} s" in note and f"{estimate[i]:.3g} m" in note and f"goal {goal:.3g} m" in note, note
    if scene in SINGULAR_PASSAGE:
        assert np.all(estimate[t <= SINGULAR_PASSAGE[scene]] <= goal), scene
        assert np.all(estimate[t >= 1.5] > goal) and notes, scene


@pytest.mark.slow
@pytest.mark.parametrize("scene", SCENES)
def test_every_shipped_scene_runs_its_default_experiment_in_the_native_fmu_with_every_method(
        scene, fmu_root, host, no_python_env):
    for method in METHODS_IN_FMU:
        rows, _ = _default_experiment_run(fmu_root, host, no_python_env, scene, method)
        assert np.all(rows[:, -1] >= 0.0), (scene, method)  # an estimate (+inf where a companion failed), no NaN
