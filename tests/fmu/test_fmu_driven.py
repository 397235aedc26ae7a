"""Driven anchors through the pythonfmu FMU: inputs P, V, A of an input-driven anchor, outputs Freact and Jreact,
against linknet_core's Simulator.advance(anchors=) computed here; fmi2SetRealInputDerivatives (through the front
layer), FMU states, bad input and ModelStructure. One client process runs every FMU case
(fmu_harness.run_client)."""
import numpy as np
import pytest

from fmu_harness import FMU_CLIENT_LIB, ROOT, build_cached, run_client  # first: repo on sys.path
import sys

sys.path.insert(0, str(ROOT / "tests"))
import driven_fmu_support as drive  # noqa: E402
import linknet_core as ln  # noqa: E402
from fmpy import read_model_description  # noqa: E402


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Build the two scenes' FMUs, run every case in one client; (results, scenes, FMU paths)."""
    root = tmp_path_factory.mktemp("fmus_driven")
    scenes = {name: drive.write_scene(root, name) for name in drive.SCENES}
    fmus = {name: build_cached(root, str(path)) for name, path in scenes.items()}
    out = run_client(FMU_CLIENT_LIB + f"""
sys.path.insert(0, {str(ROOT / "tests")!r})
import driven_fmu_support as drive
import linknet_core as ln
scenes = {{n: ln.load_scene(p) for n, p in {({n: str(p) for n, p in scenes.items()})!r}.items()}}
fmus = {({n: str(p) for n, p in fmus.items()})!r}

def inputs(f, scene, n, motion, derivatives=False):
    P, V, A = motion
    k = drive.ANCHOR[scene.name]
    values = {{f"P[{{k}},{{i + 1}}]": P[n, i] for i in range(3)}}
    if drive.FORCED[scene.name]:
        values.update({{f"F[{{drive.FORCED[scene.name]}},{{i + 1}}]": drive.BOB2_FORCE[i] for i in range(3)}})
    if derivatives:
        p = [f.vr[f"P[{{k}},{{i + 1}}]"] for i in range(3)]
        assert derivatives_of(f, p + p, [1, 1, 1, 2, 2, 2], list(V[n]) + list(A[n])) == 0
    else:
        values.update({{f"V[{{k}},{{i + 1}}]": V[n, i] for i in range(3)}})
        values.update({{f"A[{{k}},{{i + 1}}]": A[n, i] for i in range(3)}})
    f.set(values)

def derivatives_of(f, vrs, orders, values):  # fmi2SetRealInputDerivatives; its status
    from fmpy.fmi2 import fmi2Integer, fmi2Real, fmi2ValueReference
    n = len(vrs)
    try:
        return f.slave.fmi2SetRealInputDerivatives(f.slave.component, (fmi2ValueReference * n)(*vrs), n,
                                                   (fmi2Integer * n)(*orders), (fmi2Real * n)(*values))
    except FMICallException as e:
        return e.status

def status_of(call):
    try:
        call()
        return 0
    except FMICallException as e:
        return e.status

def run(f, scene, first, last, motion, derivatives=False):
    names = [v.name for v in f.md.modelVariables if v.causality == "output"]
    rows = []
    for n in range(first, last + 1):
        inputs(f, scene, n, motion, derivatives)
        rows.append([n * drive.H] + list(f.get(names)))
        if n < last:
            f.step(n * drive.H, drive.H)
    return np.array(rows)

def case(name, instance, jump_step=None, derivatives=False):
    f = Fmu(fmus[name], instance)
    f.init()
    scene = scenes[name]
    rows = run(f, scene, 0, drive.N_STEPS, drive.anchor_motion(scene.X0[drive.ANCHOR[name] - 1], jump_step=jump_step),
               derivatives)
    f.slave.terminate()
    f.slave.freeInstance()
    return rows

def case_read_after(name, instance):  # outputs read after each doStep, before the next inputs (fmpy's way)
    f = Fmu(fmus[name], instance)
    f.init()
    scene = scenes[name]
    motion = drive.anchor_motion(scene.X0[drive.ANCHOR[name] - 1])
    names = [v.name for v in f.md.modelVariables if v.causality == "output"]
    rows = []
    for n in range(drive.N_STEPS):
        inputs(f, scene, n, motion)
        f.step(n * drive.H, drive.H)
        rows.append([(n + 1) * drive.H] + list(f.get(names)))
    f.slave.terminate()
    f.slave.freeInstance()
    return np.array(rows)

save(read_after=case_read_after("driven_chain", "r1"))
save(pendulum=case("driven_pendulum", "p1"), chain=case("driven_chain", "c1"),
     chain_derivatives=case("driven_chain", "c2", derivatives=True), jump=case("driven_pendulum", "p2", jump_step=10))

# state: taken after the step that starts with a velocity jump, replayed in place and in a fresh instance
scene = scenes["driven_chain"]
motion = drive.anchor_motion(scene.X0[0], jump_step=8)
f = Fmu(fmus["driven_chain"], "s1")
f.init()
run(f, scene, 0, 8, motion)
f.step(8 * drive.H, drive.H)
state = f.slave.getFMUstate()
first = run(f, scene, 9, 20, motion)
f.slave.setFMUstate(state)
again = run(f, scene, 9, 20, motion)
data = f.slave.serializeFMUstate(state)
g = Fmu(fmus["driven_chain"], "s2")
g.init()
g.slave.setFMUstate(g.slave.deSerializeFMUstate(data))
save(state_first=first, state_again=again, state_fresh=run(g, scene, 9, 20, motion))

# at point 20 the inputs are set and not yet stepped with: the hold goes on over steps with no new inputs
def coast(f):
    names = [v.name for v in f.md.modelVariables if v.causality == "output"]
    rows = []
    for n in (20, 21, 22):
        f.step(n * drive.H, drive.H)
        rows.append(f.get(names))
    return np.array(rows)
held = g.slave.getFMUstate()
coasted = coast(g)
g.slave.setFMUstate(held)
again = coast(g)
f.slave.setFMUstate(f.slave.deSerializeFMUstate(g.slave.serializeFMUstate(held)))
save(coasted=coasted, coasted_again=again, coasted_fresh=coast(f), motion_20=np.array([q[20] for q in motion]))

# bad input: logged with the variable's name, the next doStep refused (fmi2Discard), then the run goes on
f = Fmu(fmus["driven_pendulum"], "bad")
f.init()
LOG.clear()
statuses = [status_of(lambda: f.set({{"P[1,2]": float("nan")}})), status_of(lambda: f.set({{"A[1,3]": float("inf")}})),
            derivatives_of(f, [f.vr["P[1,1]"]], [3], [1.0]), derivatives_of(f, [f.vr["X[2,1]"]], [1], [1.0]),
            derivatives_of(f, [f.vr["F[2,1]"], f.vr["P[1,1]"]], [1, 1], [5.0, 0.25])]
statuses.append(f.slave.getReal([f.vr["V[1,1]"]])[0] == 0.25)
statuses.append(status_of(lambda: f.step(0.0, drive.H)))
bad_log = "\\n".join(f"{{s}}|{{m}}" for s, m in LOG)
scene = scenes["driven_pendulum"]
save(statuses=np.array(statuses), after_bad=run(f, scene, 0, 5, drive.anchor_motion(scene.X0[0])),
     bad_log=np.array(bad_log))
""", root / "client_driven")
    return out, {name: ln.load_scene(path) for name, path in scenes.items()}, fmus, scenes


def _names(fmu):
    return drive.output_names(read_model_description(str(fmu)))


@pytest.mark.parametrize("name,key", [("driven_pendulum", "pendulum"), ("driven_chain", "chain")])
def test_driven_anchor_runs_equal_the_library(name, key, runs):
    out, scenes, fmus, _ = runs
    ref = drive.library_outputs(scenes[name], _names(fmus[name]))
    assert np.array_equal(out[key], ref)  # the FMU runs the library itself: bit for bit


def test_outputs_read_after_a_step_see_the_held_motion(runs):
    """Read after doStep, before the next inputs: the anchor where its held quadratic took it, and the tensions of
    that motion (the library's outputs() with the last hold)."""
    out, scenes, fmus, _ = runs
    ref = drive.library_outputs(scenes["driven_chain"], _names(fmus["driven_chain"]), read_after=True)
    assert np.array_equal(out["read_after"], ref)


def test_input_derivatives_give_the_run_of_V_and_A_inputs(runs):
    out, _, _, _ = runs
    assert np.array_equal(out["chain_derivatives"], out["chain"])


def test_velocity_jump_impulse_equals_the_library(runs):
    out, scenes, fmus, _ = runs
    names = _names(fmus["driven_pendulum"])
    ref = drive.library_outputs(scenes["driven_pendulum"], names, jump_step=10)
    assert np.array_equal(out["jump"], ref)
    J = out["jump"][:, [names.index(f"Jreact[1,{i}]") + 1 for i in (1, 2, 3)]]
    assert np.abs(J[11]).max() > 0.01 and np.abs(J[:11]).max() < 1e-12 and np.abs(J[12:]).max() < 1e-12


def test_states_with_driven_anchors_replay_bit_for_bit(runs):
    """After a velocity jump (the impulse carried); and with inputs set but not yet stepped with, whose hold goes on
    over steps with no new inputs (the anchor keeps to its quadratic)."""
    out, _, fmus, _ = runs
    assert np.array_equal(out["state_again"], out["state_first"])
    assert np.array_equal(out["state_fresh"], out["state_first"])
    assert np.array_equal(out["coasted_again"], out["coasted"])
    assert np.array_equal(out["coasted_fresh"], out["coasted"])
    names = _names(fmus["driven_chain"])
    P, V, A = out["motion_20"]
    tau = drive.H * np.arange(1, 4)[:, None]
    X = out["coasted"][:, [names.index(f"X[1,{i}]") for i in (1, 2, 3)]]
    np.testing.assert_allclose(X, P + V * tau + A * tau ** 2 / 2, rtol=0, atol=1e-12)


def test_bad_anchor_inputs_are_refused_and_the_fmu_goes_on(runs):
    out, scenes, fmus, _ = runs
    log = str(out["bad_log"])
    for words in ("P[1,2] = nan is not a finite position", "A[1,3] = inf is not a finite acceleration",
                  "order 3 of P[1,1] refused", "X[2,1] is an output", "F[2,1] is held constant",
                  "doStep refused: P[1,2]"):
        assert words in log, (words, log)
    # fmi2Error for the refused values and derivatives, fmi2Warning for the held force's derivative (the P[1,1]
    # derivative in the same call is taken), fmi2Discard for the doStep with a bad input pending
    assert out["statuses"].tolist() == [3, 3, 3, 3, 1, 1, 2]
    ref = drive.library_outputs(scenes["driven_pendulum"], _names(fmus["driven_pendulum"]), n_steps=5)
    assert np.array_equal(out["after_bad"], ref)


def test_fmpy_validation_is_clean(runs):
    from fmpy.validation import validate_fmu
    _, _, fmus, _ = runs
    for fmu in fmus.values():
        assert validate_fmu(str(fmu)) == []


def test_model_description_agrees_with_the_native_fmu(runs, tmp_path):
    """Both FMU kinds write the variables and dependencies of the one Layout: the same capabilities (input
    derivatives included), variables, start values (P at the anchor's scene position) and ModelStructure
    (tests/fmu_native checks the structure against the FMU's own answers)."""
    import xml.etree.ElementTree as ET
    import zipfile
    import build_fmu
    _, _, fmus, paths = runs
    native = build_fmu.build_scene_fmu(str(paths["driven_chain"]), tmp_path / "n.fmu", quiet=True, native=True)

    def md(path):
        with zipfile.ZipFile(path) as z:
            return ET.fromstring(z.read("modelDescription.xml"))
    a, b = md(native), md(fmus["driven_chain"])
    for key in ("canInterpolateInputs", "canHandleVariableCommunicationStepSize", "canGetAndSetFMUstate",
                "canSerializeFMUstate"):
        assert a.find("CoSimulation").get(key) == b.find("CoSimulation").get(key), key
    assert a.find("CoSimulation").get("canInterpolateInputs") == "true"
    assert ET.tostring(a.find("ModelStructure")) == ET.tostring(b.find("ModelStructure"))
    assert ET.tostring(a.find("TypeDefinitions")) == ET.tostring(b.find("TypeDefinitions"))
    for va, vb in zip(a.find("ModelVariables"), b.find("ModelVariables"), strict=True):
        assert va.attrib == vb.attrib
        ra, rb = dict(list(va)[0].attrib), dict(list(vb)[0].attrib)
        start_a, start_b = ra.pop("start", None), rb.pop("start", None)
        assert ra == rb and (start_a == start_b or float(start_a) == pytest.approx(float(start_b), rel=1e-15))
