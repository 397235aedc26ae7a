"""Driven anchors' inputs and the FMI call order, both FMU kinds (the native one and the pythonfmu one), in one fmpy
client.

Position jumps of an input-driven anchor (fmu_src/linknet_fmu/anchor_jumps.py, fmu_src/native/linknet_model.c): a P
that is not where the held motion P + V tau + A tau^2/2 had the anchor is taken by the core as a relocation (the free
masses projected onto the link lengths in the mass metric, their velocities onto the links relative to the anchor's
V); the FMU logs it (fmi2Warning) naming the input, its value reference and the jump, and reports the core's impulse
in Jreact; a jump the links cannot follow is discarded naming the input and the rule; a V set without P (the held
motion restarts from the P last set, docs/driven_anchors.md) is said once per instance. Checked against closed forms:
the radial projection of a bob at rest in zero gravity, and the impulse -m (e.v) e of a jump of P and V together.

The pythonfmu FMU answers misuse as the native FMU does (its front layer, fmu_src/pythonfmu_front/front.c, and the
slave): a doStep after fmi2Terminate, input derivatives before initialization, orders 0 and -1 (in the slave's words,
not the front's encoding), an order-2 value of 1e200, a call mixing a good and a bad order (nothing set), garbage
handed to fmi2DeSerializeFMUstate, a stop time before the start time and a wrong GUID are refused with fmi2Error and the
same words."""
from __future__ import annotations

import json
import sys

import numpy as np
import pytest

from contract_support import ROOT
from fmu_harness import FMU_CLIENT_LIB, build_cached, run_client

sys.path.insert(0, str(ROOT / "tests"))
import driven_fmu_support as drive  # noqa: E402

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
KINDS = ("native", "pythonfmu")
MASS, LENGTH = 1.5, 1.0
BOB = np.array([0.6, 0.0, -0.8])  # the bob's start; the hook is at the origin
# a pendulum in zero gravity: at rest it stays where it is, so a step shows where a jump put it
FLOATING = {"name": "floating_pendulum", "gravity": [0.0, 0.0, 0.0],
            "masses": [{"name": "hook", "position": [0.0, 0.0, 0.0], "driven": True},
                       {"name": "bob", "position": BOB.tolist(), "mass": MASS}],
            "links": [{"a": 1, "b": 2, "length": LENGTH}]}
H = 0.01
JUMP_P = np.array([0.5, 0.0, 0.0])   # a jump of the hook, at rest
JUMP_V = np.array([0.3, 0.0, 0.4])   # its velocity set with a second jump of P


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Build the floating pendulum and the driven chain (tests/driven_fmu_support.py) of both kinds; run every case."""
    root = tmp_path_factory.mktemp("fmu_inputs")
    (root / "floating_pendulum.json").write_text(json.dumps(FLOATING))
    chain = drive.write_scene(root, "driven_chain")
    fmus = {kind: {name: str(build_cached(root, str(path), native=(kind == "native")))
                   for name, path in (("floating", root / "floating_pendulum.json"), ("chain", chain))}
            for kind in KINDS}
    motion = [a.tolist() for a in drive.anchor_motion(np.zeros(3))]
    out = run_client(FMU_CLIENT_LIB + f"""
import json
from fmpy.fmi2 import fmi2Integer, fmi2Real, fmi2ValueReference, fmi2True
FMUS = {fmus!r}
H = {H!r}
P_MOTION, V_MOTION, A_MOTION = (np.array(a) for a in {motion!r})

def said():  # the messages of the last call a host must see: warnings and worse (not logAll's information)
    return [m for s, m in LOG if s >= 1]

def step(f, t, h=H):
    '''fmi2DoStep: (status, messages logged)'''
    LOG.clear()
    try:
        status = f.slave.fmi2DoStep(f.slave.component, t, h, fmi2True)
    except FMICallException as e:
        status = e.status
    return [int(status), said()]

def outcome(call):
    LOG.clear()
    try:
        status = call()
        status = 0 if status is None else int(status)
    except FMICallException as e:
        status = e.status
    except Exception as e:  # fmpy's own: fmi2Instantiate returned NULL
        status = "NULL: " + str(e)
    return [status, said()]

def derivatives(f, names, orders, values):
    s, n = f.slave, len(names)
    return lambda: s.fmi2SetRealInputDerivatives(s.component, (fmi2ValueReference * n)(*[f.vr[x] for x in names]), n,
                                                 (fmi2Integer * n)(*orders), (fmi2Real * n)(*values))

def bob(f):
    return f.get(["X[2,1]", "X[2,2]", "X[2,3]"]).tolist()

R = {{}}
for kind, paths in FMUS.items():
    r = R[kind] = {{}}
    vr = Fmu(paths["floating"], kind + "_vr").vr
    r["vr"] = {{name: vr[name] for name in ("P[1,1]", "P[1,3]", "V[1,1]")}}
    r["chain_vr"] = Fmu(paths["chain"], kind + "_chain_vr").vr["P[1,3]"]

    # a jump of P at rest: a relocation, no impulse; the same jump again: no jump
    f = Fmu(paths["floating"], kind + "_jump"); f.init()
    r["rest"] = step(f, 0.0)
    f.set({{"P[1,1]": {JUMP_P[0]!r}}})
    r["jump"] = step(f, H) + [bob(f), f.get(["Jreact[1,1]", "Jreact[1,2]", "Jreact[1,3]"]).tolist()]
    f.set({{"P[1,1]": {JUMP_P[0]!r}}})
    r["same_again"] = step(f, 2 * H)
    # P and V jump together: the bob takes the anchor's velocity along the link, the anchor the opposite impulse
    before = bob(f)
    f.set({{"P[1,1]": 0.0, "V[1,1]": {JUMP_V[0]!r}, "V[1,3]": {JUMP_V[2]!r}}})
    r["jump_with_velocity"] = step(f, 3 * H) + [before, f.get(["Jreact[1,1]", "Jreact[1,2]", "Jreact[1,3]"]).tolist()]

    # jumps shorter than a thousandth of the link: said once; a long one again
    f = Fmu(paths["floating"], kind + "_short"); f.init()
    r["short"] = [(f.set({{"P[1,1]": 1e-5 * (n + 1)}}), step(f, n * H))[1] for n in range(3)]
    f.set({{"P[1,1]": 0.5}})
    r["short_then_long"] = step(f, 3 * H)

    # V set without P, every step: the motion restarts from the P last set, so the hook is back at 0 + V h each time
    f = Fmu(paths["floating"], kind + "_v_only"); f.init()
    r["v_only"] = [(f.set({{"V[1,1]": 1.0}}), step(f, n * H), f.get(["X[1,1]"]).tolist())[1:] for n in range(4)]

    # a jump the links cannot follow (3 m on a chain of 0.25 m links): discarded naming P; the FMU goes on
    f = Fmu(paths["chain"], kind + "_far"); f.init()
    r["far_first"] = step(f, 0.0)
    f.set({{"P[1,3]": 3.0}})
    r["far"] = step(f, H)
    f.set({{"P[1,3]": 0.0}})
    r["far_back"] = step(f, H)

    # P, V, A continuing the held motion (tests/driven_fmu_support.py): no jump, nothing said
    f = Fmu(paths["chain"], kind + "_smooth"); f.init()
    smooth = []
    for n in range({drive.N_STEPS!r}):
        f.set({{f"{{q}}[1,{{i + 1}}]": a[n, i] for q, a in (("P", P_MOTION), ("V", V_MOTION), ("A", A_MOTION))
               for i in range(3)}})
        smooth.append(step(f, n * H))
    r["smooth"] = smooth

    # misuse, answered as the native FMU answers it
    f = Fmu(paths["floating"], kind + "_misuse")
    s = f.slave
    m = r["misuse"] = {{}}
    m["derivative before initialization"] = outcome(derivatives(f, ["P[1,1]"], [1], [1.0]))
    m["stop before start"] = outcome(lambda: s.fmi2SetupExperiment(s.component, 0, 0.0, 1.0, 1, 0.5))
    s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
    m["order 0"] = outcome(derivatives(f, ["P[1,1]"], [0], [1.0]))
    m["order -1"] = outcome(derivatives(f, ["P[1,1]"], [-1], [1.0]))
    m["order 2 of 1e200"] = outcome(derivatives(f, ["P[1,1]"], [2], [1e200]))
    m["orders 1 and 3"] = outcome(derivatives(f, ["P[1,1]", "P[1,3]"], [1, 3], [1.0, 1.0]))
    m["V after the refused call"] = f.get(["V[1,1]", "A[1,3]"]).tolist()
    m["deserialize garbage"] = outcome(lambda: s.deSerializeFMUstate(b"not a state at all" * 4))
    state = s.getFMUstate()
    damaged = bytearray(s.serializeFMUstate(state)); damaged[-5] ^= 0xFF
    m["deserialize damaged"] = outcome(lambda: s.deSerializeFMUstate(bytes(damaged)))
    m["deserialize truncated"] = outcome(lambda: s.deSerializeFMUstate(bytes(damaged[:len(damaged) // 2])))
    m["step"] = outcome(lambda: s.doStep(0.0, H))
    m["terminate"] = outcome(s.terminate)
    m["step after terminate"] = outcome(lambda: s.doStep(H, H))
    m["set after terminate"] = outcome(lambda: f.set({{"P[1,1]": 0.0}}))
    m["reset"] = outcome(s.reset)
    m["step after reset"] = outcome(lambda: (s.setupExperiment(startTime=0.0), s.enterInitializationMode(),
                                             s.exitInitializationMode(), s.doStep(0.0, H))[-1])
    md = f.md
    m["wrong guid"] = outcome(lambda: FMU2Slave(guid="{{00000000-0000-0000-0000-000000000000}}",
                                                unzipDirectory=f.unzipdir,
                                                modelIdentifier=md.coSimulation.modelIdentifier,
                                                instanceName="wrong_guid").instantiate(callbacks=CALLBACKS))
save(results=np.array(json.dumps(R)))
""", root / "client")
    return json.loads(str(out["results"]))


@pytest.fixture(params=KINDS)
def run(request, runs):
    return runs[request.param]


def test_a_jump_of_p_at_rest_moves_the_bob_onto_the_link_and_is_logged(run):
    status, log, X, J = run["jump"]
    assert run["rest"] == [OK, []]
    # the bob, at rest in zero gravity, is projected onto the sphere of the link around the hook's new position
    expected = JUMP_P + LENGTH * (BOB - JUMP_P) / np.linalg.norm(BOB - JUMP_P)
    np.testing.assert_allclose(X, expected, rtol=0, atol=1e-12)
    assert np.abs(J).max() < 1e-15  # nothing moved, no velocity to project: the core applies no impulse
    assert status == WARNING and len(log) == 1, (status, log)
    vr = run["vr"]["P[1,1]"]
    for words in (f"position jump at t={H:g}: P[1,1] (valueReference {vr}) = 0.5 m where the held motion had the "
                  "anchor at 0 m (a jump of 0.5 m)", "taken as a relocation", "Jreact[1,1] = 0, Jreact[1,2] = 0",
                  "set P, V and A together"):
        assert words in log[0], (words, log[0])
    assert run["same_again"] == [OK, []]  # P set to where the anchor is: no jump


def test_a_jump_of_p_and_v_reports_the_cores_impulse(run):
    status, log, before, J = run["jump_with_velocity"]
    # relocation towards the hook's new position (the origin), then the velocity jump along the new link direction e:
    # the bob takes (V.e) e, the anchor the impulse -m (V.e) e
    e = np.array(before) / np.linalg.norm(before)
    np.testing.assert_allclose(J, -MASS * float(JUMP_V @ e) * e, rtol=1e-12, atol=1e-14)
    assert status == WARNING and "a jump of 0.5 m" in log[0] and f"Jreact[1,1] = {J[0]:g}" in log[0], log


def test_short_jumps_are_said_once_and_long_ones_every_time(run):
    said = [log for status, log in run["short"]]
    assert [len(log) for log in said] == [1, 0, 0], said
    assert "a jump of 1e-05 m" in said[0][0] and "are logged once per instance" in said[0][0]
    assert [status for status, _ in run["short"]] == [WARNING, OK, OK]
    status, log = run["short_then_long"]
    assert status == WARNING and "a jump of 0.49997 m" in log[0] and "once per instance" not in log[0], log


def test_v_set_without_p_restarts_the_held_motion_from_p_and_is_said_once(run):
    statuses = [outcome[0] for outcome, _ in run["v_only"]]
    logs = [outcome[1] for outcome, _ in run["v_only"]]
    hook_x = [x[0] for _, x in run["v_only"]]
    # the documented behaviour: each step starts again from P = 0 (never set), so the hook ends every step at V h
    np.testing.assert_allclose(hook_x, [1.0 * H] * 4, rtol=0, atol=1e-15)
    assert statuses == [OK, WARNING, OK, OK] and [len(log) for log in logs] == [0, 1, 0, 0], logs
    text = logs[1][0]
    v, p = run["vr"]["V[1,1]"], run["vr"]["P[1,1]"]
    for words in (f"V[1,1] (valueReference {v}) was set at t={H:g} without P of its anchor",
                  f"P[1,1] (valueReference {p}) = 0 m where the held motion had the anchor at {H:g} m",
                  "logged once per instance", "Set P with V and A"):
        assert words in text, (words, text)


def test_a_jump_the_links_cannot_follow_is_discarded_naming_p_and_the_rule(run):
    assert run["far_first"] == [OK, []]
    status, log = run["far"]
    assert status == DISCARD and len(log) == 1, run["far"]
    for words in (f"P[1,3] (valueReference {run['chain_vr']}) = 3 m where the held motion had the anchor at 0 m (a "
                  "jump of 3 m)", "must continue its held motion P + V tau + A tau^2/2",
                  "move the anchor there over several steps"):
        assert words in log[0], (words, log[0])
    assert run["far_back"] == [OK, []]  # the FMU stayed where it was: the anchor back there steps on


def test_inputs_that_continue_the_held_motion_say_nothing(run):
    assert run["smooth"] == [[OK, []]] * drive.N_STEPS


def test_both_kinds_say_a_jump_in_the_same_words(runs):
    native, pythonfmu = (runs[kind]["jump"][1][0] for kind in KINDS)
    assert native == "fmi2DoStep: " + pythonfmu


# case -> the status and words both FMU kinds answer with
MISUSE = {
    "derivative before initialization": (ERROR, "fmi2SetRealInputDerivatives: not allowed in instantiated (before "
                                                "fmi2EnterInitializationMode)"),
    "stop before start": (ERROR, "fmi2SetupExperiment: stopTime = 0.5 must be finite and >= startTime = 1"),
    "order 0": (ERROR, "fmi2SetRealInputDerivatives: derivative of order 0 of P[1,1] refused: inputs take derivatives "
                       "of order 1 and 2 only; nothing set"),
    "order -1": (ERROR, "fmi2SetRealInputDerivatives: derivative of order -1 of P[1,1] refused: inputs take "
                        "derivatives of order 1 and 2 only; nothing set"),
    "order 2 of 1e200": (ERROR, "fmi2SetRealInputDerivatives: derivative of order 2 of P[1,1] = 1e+200: an anchor's "
                                "acceleration beyond 1e+100 would overflow the solver; nothing set"),
    "orders 1 and 3": (ERROR, "fmi2SetRealInputDerivatives: derivative of order 3 of P[1,3] refused: inputs take "
                              "derivatives of order 1 and 2 only; nothing set"),
    "deserialize garbage": (ERROR, "fmi2DeSerializeFMUstate: refused: not a linknet FMU state"),
    "deserialize damaged": (ERROR, "fmi2DeSerializeFMUstate: refused: the state's bytes are damaged (checksum "
                                   "mismatch)"),
    "deserialize truncated": (ERROR, "fmi2DeSerializeFMUstate: refused: a state of the wrong size"),
    "step": (OK, None),
    "terminate": (OK, None),
    "step after terminate": (ERROR, "fmi2DoStep: called after fmi2Terminate (fmi2Reset starts again)"),
    "set after terminate": (ERROR, "fmi2SetReal: not allowed in terminated"),
    "reset": (OK, None),
    "step after reset": (OK, None),
}


@pytest.mark.parametrize("case", list(MISUSE))
def test_misuse_is_answered_as_the_native_fmu_answers_it(case, run):
    status, log = run["misuse"][case]
    expected, words = MISUSE[case]
    assert status == expected, (case, status, log)
    if words is None:
        assert log == [], log
    else:
        assert log == [words], log  # one message, the native FMU's words; no encoding or other internals


def test_a_refused_call_of_input_derivatives_sets_nothing(run):
    assert run["misuse"]["V after the refused call"] == [0.0, 0.0]  # order 1 of P[1,1] came with a refused order 3


def test_a_wrong_guid_is_refused_at_instantiate(run):
    status, log = run["misuse"]["wrong guid"]
    assert str(status).startswith("NULL") and len(log) == 1, (status, log)
    assert log[0].startswith('fmi2Instantiate: GUID "{00000000-0000-0000-0000-000000000000}" is not this FMU\'s ('), log
    assert "come from different builds" in log[0]
