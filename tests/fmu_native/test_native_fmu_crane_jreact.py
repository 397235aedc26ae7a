"""A rope's jerk on an anchor driven by inputs is in Jreact: the shipped crane (models/ropes/rope_crane.json) with its
trolley driven by the master instead of its waypoints. The master accelerates the trolley at 5 m/s^2 for 1 s, brakes
it at 25 m/s^2 for 0.2 s and holds it there (P, V, A set at every communication point, P continuing the held motion:
no position jump); the hoist rope goes slack as the braking starts, the load flies, and the rope jerks taut again at
~1.48 s, pulling the trolley along the rope.

Reference, independent of the core: the load flies ballistically while the rope is slack, so its state at the jerk's
time t_e (the event's time as logged) follows in closed form from its state at the communication point before, and
the trolley's from the inputs. The jerk is inelastic (the rope's restitution is 0): it removes the load's velocity
along the rope relative to the trolley, v_r = (U_load - V_trolley) . n, n = (X_load - P_trolley) / R, so the rope
gives the load -m v_r n and the trolley m v_r n (momentum balance across the jerk: nothing else acts impulsively, and
gravity's and the inputs' impulses over an instant are zero). Jreact over the step that holds the jerk is that, Jrope
there m v_r; Jreact is round-off in every other step.

The native FMU equals Simulator.advance(anchors=) on the native backend to round-off (the same core); the pythonfmu
FMU runs the library itself (default backend) and equals it too; the numpy reference (backend="numpy") agrees
within the run's tolerance.
"""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from native_fmu_support import MODELS, ROOT, built
from test_native_fmu_ropes import FMU_TOLERANCE, ROUND_OFF, Instance, _parse

sys.path.insert(0, str(ROOT / "tests"))
import linknet_core as ln  # noqa: E402

A_RUN, T_BRAKE, A_BRAKE, T_STOP = 5.0, 1.0, -25.0, 1.2  # m/s^2, s: the master's trolley motion
H, N = 0.01, 160  # communication steps: past the jerk (~1.48 s)
NAMES = ["X[2,1]", "X[2,2]", "X[2,3]", "U[2,1]", "U[2,2]", "U[2,3]", "slack[1]", "Jrope[1]", "Jreact[1,1]",
         "Jreact[1,2]", "Jreact[1,3]"]


def trolley(t):
    """(P, V, A) of the trolley at t (x only): the master's motion, quadratic on each phase."""
    if t < T_BRAKE:
        return 0.5 * A_RUN * t * t, A_RUN * t, A_RUN
    x1, v1 = 0.5 * A_RUN * T_BRAKE ** 2, A_RUN * T_BRAKE
    s = min(t, T_STOP) - T_BRAKE
    x, v = x1 + v1 * s + 0.5 * A_BRAKE * s * s, v1 + A_BRAKE * s
    return (x, v, A_BRAKE) if t < T_STOP else (x, 0.0, 0.0)


def inputs(t):
    P, V, A = trolley(t)
    return {"P[1,1]": P, "P[1,2]": 0.0, "P[1,3]": 0.0, "V[1,1]": V, "V[1,2]": 0.0, "V[1,3]": 0.0, "A[1,1]": A,
            "A[1,2]": 0.0, "A[1,3]": 0.0}


@pytest.fixture(scope="module")
def crane(tmp_path_factory):
    data = json.loads((MODELS / "ropes" / "rope_crane.json").read_text())
    data["name"] = "rope_crane_input"
    data["masses"][0].pop("motion")
    data["masses"][0]["motion"] = {"kind": "input"}
    path = tmp_path_factory.mktemp("rope_crane_input") / "rope_crane_input.json"
    path.write_text(json.dumps(data))
    return path


@pytest.fixture(scope="module")
def native_run(crane, fmu_root):
    fmu = built(fmu_root, crane)
    instance = Instance(fmu)
    instance.initialize(integrator="dop853")
    vr = [fmu.vr[name] for name in inputs(0.0)]
    rows = []
    for i in range(N):
        instance.slave.setReal(vr, list(inputs(i * H).values()))
        instance.slave.doStep(i * H, H)
        rows.append(instance.get(NAMES))
    messages = instance.events()
    assert not [m for s, _, m in instance.log if s != 0]  # P continued the held motion: no position jump said
    return np.array(rows), messages


def _library(crane, backend):
    scene = ln.load_scene(crane)
    sim = ln.Simulator(scene, "dop853", rtol=FMU_TOLERANCE, backend=backend, error_estimate=False)
    rows = []
    for i in range(N):
        P, V, A = (np.array([[value, 0.0, 0.0]]) for value in trolley(i * H))
        sim.advance((i + 1) * H, anchors=(P, V, A))
        rows.append(np.concatenate([sim.state.X[1], sim.state.U[1], [sim.outputs()["slack"][0]],
                                    [sim.integrator.rope_impulses()[0] if backend == "native" else np.nan],
                                    sim.anchor_report()["impulse"][0]]))
    return np.array(rows)


def test_the_jerk_on_the_trolley_is_the_loads_radial_momentum_along_the_rope(crane, native_run):
    rows, messages = native_run
    at = {name: rows[:, j] for j, name in enumerate(NAMES)}
    assert [_parse(m)[1] for m in messages] == ["slack", "taut"]
    t_e = _parse(messages[1])[0]
    jerk = int(np.flatnonzero(at["Jrope[1]"])[0])
    assert jerk * H < t_e <= (jerk + 1) * H
    # the state at the step's start (the rope slack), flown ballistically to t_e
    assert at["slack[1]"][jerk - 1] == 1.0
    scene = ln.load_scene(crane)
    m, R, g = scene.mass[1], scene.length[0], np.asarray(scene.gravity)
    tau = t_e - jerk * H
    X0 = np.array([at[f"X[2,{i}]"][jerk - 1] for i in (1, 2, 3)])
    U0 = np.array([at[f"U[2,{i}]"][jerk - 1] for i in (1, 2, 3)])
    X_load, U_load = X0 + U0 * tau + 0.5 * g * tau ** 2, U0 + g * tau
    P, V, _ = trolley(t_e)
    d = X_load - np.array([P, 0.0, 0.0])
    assert abs(np.linalg.norm(d) - R) <= 1e-9 * R  # the rope is at its length at the logged time
    n = d / R
    v_r = float((U_load - np.array([V, 0.0, 0.0])) @ n)
    assert v_r > 0.0  # the load was flying away from the trolley along the rope
    J = np.array([at[f"Jreact[1,{i}]"][jerk] for i in (1, 2, 3)])
    np.testing.assert_allclose(J, m * v_r * n, rtol=0, atol=1e-8 * m * v_r)
    assert at["Jrope[1]"][jerk] == pytest.approx(m * v_r, rel=1e-8)
    others = np.delete(rows[:, -3:], jerk, axis=0)
    assert np.abs(others).max() <= ROUND_OFF * m * v_r  # round-off of the held motion's restarts, no impulse


def test_the_native_fmu_equals_the_library_on_the_native_core(crane, native_run):
    rows, _ = native_run
    expected = _library(crane, "native")
    scale = np.maximum(np.abs(expected).max(axis=0), 1.0)
    assert (np.abs(rows - expected) / scale).max() <= ROUND_OFF


def test_the_pythonfmu_fmu_and_the_numpy_reference_give_the_same_jerk(crane, native_run, tmp_path_factory):
    from fmu_harness import FMU_CLIENT_LIB, build_cached, run_client

    rows, _ = native_run
    folder = tmp_path_factory.mktemp("rope_crane_input_pythonfmu")
    fmu = build_cached(folder, str(crane))
    steps = [inputs(i * H) for i in range(N)]
    out = run_client(FMU_CLIENT_LIB + f"""
f = Fmu({str(fmu)!r})
f.init(strings={{"integrator": "dop853"}})
rows = []
for i, values in enumerate({steps!r}):
    f.set(values)
    f.step(i * {H!r}, {H!r})
    rows.append(f.get({NAMES!r}))
save(rows=np.array(rows))
""", folder)
    python_rows = out["rows"]
    J = slice(len(NAMES) - 4, None)  # Jrope[1], Jreact[1,:]
    scale = np.abs(rows[:, J]).max()
    assert np.abs(python_rows[:, J] - rows[:, J]).max() <= ROUND_OFF * scale
    numpy_rows = _library(crane, "numpy")
    Jreact = slice(len(NAMES) - 3, None)
    assert np.abs(numpy_rows[:, Jreact] - rows[:, Jreact]).max() <= FMU_TOLERANCE * scale
