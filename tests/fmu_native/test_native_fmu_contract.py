"""The native FMU's behaviour contract, exercised by the plain C host with no Python in its environment: bad
input and misuse answered with fmi2Error (a solver failure with fmi2Discard) and a logged message, never
fmi2Fatal, the instance usable afterwards; startTime honoured; FMU states replayed bit for bit and foreign ones
refused; independent instances, also on two threads at once; no memory growth over instantiate/free cycles;
parameters changed before initialization give the library's run of the changed scene."""
import json

import numpy as np
import pytest

from native_fmu_support import (MODELS, N_STEPS, H, assert_round_off, built, host_options, library_rows, output_names,
                                parse_rows, run_host)
import linknet_core as ln

OK, DISCARD, ERROR, FATAL = 0, 2, 3, 4

# case -> (status, words the logged message must contain)
EXPECTED = {
    "instantiate_wrong_guid": (ERROR, "GUID"),
    "instantiate_model_exchange": (ERROR, "Co-Simulation"),
    "instantiate_null_guid": (ERROR, "GUID"),
    "step_before_initialization": (ERROR, "fmi2ExitInitializationMode"),
    "set_start_time": (OK, ""),
    "setup_nan_start": (ERROR, "startTime"),
    "enter_initialization": (OK, ""),
    "step_in_initialization": (ERROR, "initialization mode"),
    "setup_in_initialization": (ERROR, "not allowed"),
    "set_mass_negative": (ERROR, "M[2] = -1 must be > 0"),
    "set_mass_nan": (ERROR, "must be finite"),
    "set_tolerance_5": (ERROR, "tolerance = 5"),
    "set_tolerance_tiny": (ERROR, "tolerance"),
    "set_step_zero": (ERROR, "step = 0 must be > 0"),
    "set_length_misfit": (ERROR, "link 1"),
    "set_output_in_batch": (ERROR, "is an output"),
    "set_unknown_vr": (ERROR, "999999"),
    "get_unknown_vr": (ERROR, "999999"),
    "get_null_vr": (ERROR, "NULL"),
    "get_integer": (ERROR, "Integer"),
    "set_integer": (ERROR, "Integer"),
    "get_boolean": (ERROR, "Boolean"),
    "get_string_of_real": (ERROR, "String"),
    "set_integrator_unknown": (ERROR, "rk99"),
    "set_integrator_dop853": (OK, ""),
    "get_integrator": (OK, ""),
    "exit_initialization": (OK, ""),
    "get_time_start": (OK, ""),
    "set_input_nan": (ERROR, "not a finite force"),
    "set_input_inf": (ERROR, "not a finite force"),
    "set_output": (ERROR, "is an output"),
    "set_parameter_same_after_init": (OK, ""),
    "set_parameter_after_init": (ERROR, "fixed parameter"),
    "step_negative_h": (ERROR, "h=-0.01"),
    "step_zero_h": (ERROR, "h=0"),
    "step_nan_h": (ERROR, "h=nan"),
    "step_wrong_t": (ERROR, "differs from the FMU's time 1.5"),
    "step_ok": (OK, ""),
    "step_sub_ulp": (OK, ""),
    "set_input_beyond_limit": (ERROR, "would overflow the solver"),
    "set_input_huge": (OK, ""),
    "step_with_huge_input": (DISCARD, "stays at t=1.51"),
    "set_input_zero": (OK, ""),
    "step_after_discard": (OK, ""),
    "get_tension": (OK, ""),
    "get_state": (OK, ""),
    "get_state_null": (ERROR, "NULL"),
    "set_state_garbage": (ERROR, "not a live state of this FMU instance"),
    "set_state_null": (ERROR, "NULL"),
    "deserialize_garbage": (ERROR, "not a linknet FMU state"),
    "deserialize_truncated": (ERROR, "size"),
    "deserialize_flipped_payload": (ERROR, "checksum"),
    "deserialize_other_byte_order": (ERROR, "byte order"),
    "deserialize_foreign": (ERROR, "another FMU"),
    "set_state_own": (OK, ""),
    "free_state": (OK, ""),
    "free_state_again": (OK, ""),
    "step_at_end": (OK, ""),
    "terminate": (OK, ""),
    "step_after_terminate": (ERROR, "fmi2Terminate"),
    "reset": (OK, ""),
    "setup_after_reset": (OK, ""),
    "enter_after_reset": (OK, ""),
    "exit_after_reset": (OK, ""),
    "step_after_reset": (OK, ""),
    "debug_logging_unknown_category": (ERROR, "logNothing"),
    "null_component_step": (ERROR, ""),
}


def test_contract_bad_input_and_misuse_answered_never_fatal(fmu_root, host, no_python_env, tmp_path):
    fmu = built(fmu_root, "pendulum")
    other = built(fmu_root, "chain_10")
    foreign = tmp_path / "chain_10.state"
    run_host(host, no_python_env, "savestate", other, foreign)
    v = fmu.vr
    out = run_host(host, no_python_env, "contract", fmu, foreign, v["F[2,3]"], v["X[2,1]"], v["T[1]"], v["M[2]"],
                   v["R[1]"], v["tolerance"], v["step"])
    cases, values = {}, {}
    for line in out.splitlines():
        parts = line.split(" ", 3)
        if parts[0] == "CASE":
            cases[parts[1]] = (int(parts[2]), parts[3] if len(parts) > 3 else "")
        elif parts[0] == "VALUE":
            values[parts[1]] = parts[2]
    assert set(cases) == set(EXPECTED), set(cases) ^ set(EXPECTED)
    for name, (status, words) in EXPECTED.items():
        got, message = cases[name]
        assert got == status, f"{name}: status {got}, expected {status} ({message})"
        assert words in message, f"{name}: message {message!r} does not say {words!r}"
        if status != OK and name != "null_component_step":
            assert message, f"{name}: refused without a message"
    assert all(status != FATAL for status, _ in cases.values())
    assert "FATAL_SEEN 0" in out
    assert values["input_after_refused_batch"] == "0"          # a refused call changes nothing
    assert values["integrator"] == "dop853"
    assert float(values["time_after_init"]) == 1.5              # startTime honoured
    assert float(values["time_after_discard"]) == 1.51         # a discarded step leaves the FMU where it was
    assert values["tension_finite"] == "1"
    assert float(values["mass_after_reset"]) == 1.0


@pytest.mark.parametrize("scene,method", [("chain_10", "rattle"), ("chain_10", "dop853"), ("net_10x10", "yoshida4"),
                                          ("spinning_tetrahedron", "dop853"), ("spinning_tetrahedron", "suzuki4"),
                                          ("redundant_truss", "rattle")])
def test_state_get_set_serialize_replay_bit_identically(scene, method, fmu_root, host, no_python_env):
    fmu = built(fmu_root, scene)
    out = run_host(host, no_python_env, "replay", fmu, 8, 0.013, *host_options(fmu, method))
    assert "replay_identical 1" in out and "fresh_identical 1" in out, out


@pytest.mark.parametrize("scene,method", [("double_pendulum", "dop853"), ("spinning_tetrahedron", "rattle")])
def test_instances_are_independent_interleaved_and_on_two_threads(scene, method, fmu_root, host, no_python_env):
    fmu = built(fmu_root, scene)
    out = run_host(host, no_python_env, "twins", fmu, 40, 0.01, *host_options(fmu, method))
    assert "interleaved_identical 1" in out and "other_differs 1" in out and "threads_identical 1" in out, out


def test_start_time_is_honoured(fmu_root, host, no_python_env):
    """From t0 = 100 (fmi2SetupExperiment) the FMU runs the scene from its initial state at t0: the library's
    Simulator(t0=100) (the scene is autonomous: the motion of t0 = 0 shifted in time)."""
    fmu = built(fmu_root, "double_pendulum")
    scene = ln.load_scene(MODELS / "double_pendulum.json")
    for method in ("rattle", "dop853"):
        shifted = parse_rows(run_host(host, no_python_env, "run", fmu, 100.0, 20, 0.01, *host_options(fmu, method)))
        library = library_rows(scene, fmu, method, n=20, h=0.01, t0=100.0)
        assert_round_off(shifted, library, f"double pendulum from t0 = 100, {method}", output_names(fmu))
        np.testing.assert_allclose(shifted[:, 0], 100.0 + 0.01 * np.arange(21), rtol=1e-15)


def test_memory_does_not_grow_over_instantiate_free_cycles(fmu_root, host, no_python_env):
    fmu = built(fmu_root, "chain_100")
    out = run_host(host, no_python_env, "cycles", fmu, 2000)
    values = dict(line.split() for line in out.splitlines())
    assert int(values["resident_after_all"]) - int(values["resident_after_tenth"]) <= 256, out  # KiB


def _changed_scene_rows(fmu, scene, host, env, method, parameters, changed_scene):
    native = parse_rows(run_host(host, env, "run", fmu, 0.0, N_STEPS, H, *host_options(fmu, method, parameters)))
    step = parameters.get("step", 1e-3)
    tolerance = parameters.get("tolerance", 1e-8)
    library = library_rows(changed_scene, fmu, method, step=step, tolerance=tolerance)
    return native, library


@pytest.mark.parametrize("method", ["rattle", "dop853"])
def test_changed_mass_gravity_step_tolerance_give_the_library_run_of_the_changed_scene(method, fmu_root, host,
                                                                                       no_python_env):
    fmu = built(fmu_root, "chain_10")
    scene = ln.load_scene(MODELS / "chain_10.json")
    mass = scene.mass.copy()
    mass[4] = 0.37
    gravity = np.array([1.5, -2.0, -9.0])
    parameters = {"M[5]": 0.37, "g[1]": 1.5, "g[2]": -2.0, "g[3]": -9.0,
                  "step": 4e-4 if method == "rattle" else 1e-3, "tolerance": 1e-10 if method == "dop853" else 1e-8}
    changed = scene.with_parameters(mass=mass, gravity=gravity)
    native, library = _changed_scene_rows(fmu, scene, host, no_python_env, method, parameters, changed)
    assert_round_off(native, library, f"chain_10 {method}, changed M, g, step, tolerance", output_names(fmu))
    default = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, N_STEPS, H, *host_options(fmu, method)))
    assert np.abs(default - native).max() > 1e-3  # the parameters did change the run


def test_changed_length_of_a_scene_that_projects_its_initial_positions(fmu_root, host, no_python_env, tmp_path):
    data = json.loads((MODELS / "double_pendulum.json").read_text())
    data["options"] = {"project_initial_positions": True}
    data["name"] = "double_pendulum_projected"
    path = tmp_path / "double_pendulum_projected.json"
    path.write_text(json.dumps(data))
    scene = ln.load_scene(path)
    fmu = built(fmu_root, path)
    length = scene.length.copy()
    length[1] *= 1.01
    native, library = _changed_scene_rows(fmu, scene, host, no_python_env, "rattle", {"R[2]": float(length[1])},
                                          scene.with_parameters(length=length))
    assert_round_off(native, library, "double pendulum, R[2] changed and the initial positions projected",
                     output_names(fmu))


def test_changed_masses_of_free_rigid_bodies(fmu_root, host, no_python_env):
    """The body geometry (principal axes, top kinds, body frames, initial body states) rebuilt in C."""
    fmu = built(fmu_root, "spinning_tetrahedron")
    scene = ln.load_scene(MODELS / "spinning_tetrahedron.json")
    free = [int(name[2:-1]) for name in fmu.names("M")]
    mass = scene.mass.copy()
    parameters = {}
    for j, k in enumerate(free):
        mass[k - 1] = 0.5 + 0.25 * j
        parameters[f"M[{k}]"] = float(mass[k - 1])
    changed = scene.with_parameters(mass=mass)
    for method in ("rattle", "dop853"):
        native, library = _changed_scene_rows(fmu, scene, host, no_python_env, method, parameters, changed)
        # the body frames may differ from numpy's eigenvectors by a sign: the motion agrees to round-off
        scale = np.maximum(np.abs(library).max(axis=0), 1.0)
        assert (np.abs(native - library) / scale).max() < 1e-9, f"tetrahedron {method}: changed masses"


def test_outputs_in_initialization_mode_follow_the_parameters_set(fmu_root, tmp_path):
    """Initial unknowns (ModelStructure): T at the start depends on M, R and g; read before the end of
    initialization it reflects them (fmpy, in this process: the native FMU has no Python to clash with)."""
    from fmpy.fmi2 import FMU2Slave
    fmu = built(fmu_root, "pendulum")
    slave = FMU2Slave(guid=fmu.guid, unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident, instanceName="init")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    v = fmu.vr
    slave.setReal([v["g[1]"], v["g[3]"]], [9.81, 0.0])  # gravity along the link, away from the pivot (+x)
    T = slave.getReal([v["T[1]"]])[0]
    slave.exitInitializationMode()
    slave.terminate()
    slave.freeInstance()
    assert abs(T - 9.81) < 1e-9  # the bob (1 kg) hangs on the link: T = M g
