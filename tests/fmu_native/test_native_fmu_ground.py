"""A frictionless ground through the native FMU (`build_fmu.py --native`), driven in this process by fmpy: a ball
bouncing (restitution 0.5) and a rope chain falling onto the ground, against linknet_core.simulate on the native
backend with the same method and communication points: X, U, T, slack[l], Jrope[l], Jground[k] (the ground's impulses
on each free mass within each doStep) and one message per contact and release event in the category logEvents, in the
pythonfmu FMU's words (rope_events.event_message), a hook driven by inputs dropping its load onto the ground against
Simulator.advance(anchors=) (Jreact too), the ball's FMI 3.0 FMU against its FMI 2.0 FMU; and against the closed
forms (the ball's bounce times and impulses, the chain's landing times and impulses). An FMU state taken between two
contacts repeats the run across the next ones; RATTLE and its compositions are offered as every method is (the chain on
them equals the library too); gravity, a mass and a length may change (the library's run of Scene.with_parameters).
Friction: test_native_fmu_friction.py.

Tolerance: none. The FMU's binary (Zig's clang) and the library (gcc) compile the same core with the same flags and no
C library math (test_native_fmu_equals_library), and the FMU runs the library's own model of the ground (the scene
padded with a virtual anchor and a contact link per free mass, unilateral.native_ground_scene, baked into the
resource): every output and every event's time and impulse are the same doubles (measured: every difference 0).
"""
from __future__ import annotations

import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from native_fmu_support import ROOT, built, write_scenes
from test_native_fmu_ropes import Instance

sys.path.insert(0, str(ROOT / "fmu_src"))
import linknet_core as ln  # noqa: E402
from linknet_fmu.layout import EVENT_CATEGORY  # noqa: E402
from linknet_fmu.rope_events import event_message  # noqa: E402

G = 9.81
ERROR = 3
TOLERANCE = 1e-8  # the FMU's default rtol (build_fmu.py); the library runs with the same
BALL = dict(height=1.0, restitution=0.5, mass=2.0, vx=0.5)
CHAIN = dict(N=12, a=0.05, m=0.05)
RUNS = {"ball": (2.0, 100), "chain": (0.4, 40)}  # (seconds, communication steps): the ball's first 5 bounces; the
#                                                  chain landed whole (its last mass at sqrt(2 N a / g) = 0.35 s)


def ball_data(**changes):
    b = BALL
    return {"name": "ball", "gravity": [0, 0, -G],
            "masses": [{"name": "ball", "position": [0, 0, b["height"]], "mass": b["mass"],
                        "velocity": [b["vx"], 0, 0]}],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": b["restitution"], **changes}}


def chain_data():
    N, a, m = CHAIN["N"], CHAIN["a"], CHAIN["m"]
    return {"name": "falling_chain", "gravity": [0, 0, -G],
            "masses": [{"name": f"c{k}", "position": [0, 0, a * (k + 1)], "mass": m} for k in range(N)],
            "links": [{"a": k + 1, "b": k + 2, "kind": "rope"} for k in range(N - 1)],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1]}}


def hook_data():
    # a hook driven by inputs holding two bobs on ropes above a ground (restitution 0.4)
    return {"name": "hook", "gravity": [0, 0, -G],
            "masses": [{"name": "hook", "position": [0, 0, 0], "driven": True, "motion": {"kind": "input"}},
                       {"name": "a", "position": [0, 0, -0.5], "mass": 0.5},
                       {"name": "b", "position": [0, 0, -1.5], "mass": 2.0}],
            "links": [{"a": 1, "b": 2, "length": 0.5, "kind": "rope"},
                      {"a": 2, "b": 3, "length": 1.0, "kind": "rope", "restitution": 0.3}],
            "ground": {"point": [0, 0, -1.8], "normal": [0, 0, 1], "restitution": 0.4}}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory) -> dict[str, Path]:
    return write_scenes(tmp_path_factory.mktemp("ground_scenes"),
                        {"ball": ball_data(), "chain": chain_data(), "hook": hook_data()})


@pytest.fixture(scope="module")
def fmus(fmu_root, scenes):
    return {name: built(fmu_root, path) for name, path in scenes.items()}


def _names(fmu):
    return (fmu.names("X") + fmu.names("U") + fmu.names("T") + fmu.names("slack") + fmu.names("Jrope")
            + fmu.names("Jground"))


def _library(scene, t_end, n, method):
    return ln.simulate(scene, t_end, method, rtol=TOLERANCE, n_out=n + 1, error_estimate=False, backend="native")


def _library_rows(run, names):
    """The library's outputs in the FMU's names: Jrope[l] the impulses of rope l's taut events within each
    communication step, Jground[k] those of mass k's contact events (the first row, before any step, 0)."""
    columns = []
    for name in names:
        kind, _, index = name.partition("[")
        idx = [int(i) - 1 for i in index.rstrip("]").split(",")]
        if kind in ("X", "U"):
            columns.append(getattr(run, kind)[:, idx[0], idx[1]])
        elif kind == "T":
            columns.append(run.T[:, idx[0]])
        elif kind == "slack":
            columns.append(run.slack[:, idx[0]].astype(float))
        else:
            J = np.zeros(run.t.size)
            event_kind = {"Jrope": "taut", "Jground": "contact"}[kind]
            for e in run.events:
                if e.kind == event_kind and e.index == idx[0]:
                    J[np.searchsorted(run.t, e.t)] += e.impulse  # the step (t_i-1, t_i] that holds it
            columns.append(J)
    return np.column_stack(columns)


def _parse(message: str):
    """(t, kind, impulse) of an event's message."""
    head, _, impulse = message.partition(", impulse ")
    t, _, what = head.removeprefix("event at t=").partition(": ")
    return float(t), what.partition(" of ")[0], float(impulse.removesuffix(" N s"))


def _run_both(fmu, scene_path, name, method):
    t_end, n = RUNS[name]
    run = _library(scene_path, t_end, n, method)
    names = _names(fmu)
    instance = Instance(fmu)
    instance.initialize(integrator=method)
    first = instance.get(names)
    rows, messages = instance.run(run.t, names)
    return run, names, np.vstack([first, rows]), messages


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_the_bouncing_ball_equals_the_library_and_bounces_at_the_closed_form_times(method, fmus, scenes):
    run, names, rows, messages = _run_both(fmus["ball"], scenes["ball"], "ball", method)
    np.testing.assert_array_equal(rows, _library_rows(run, names))
    scene = ln.load_scene(scenes["ball"])
    assert messages == [event_message(e, scene) for e in run.events]
    # closed form: t_1 = sqrt(2 h / g), v_1 = sqrt(2 g h); each rebound at e v_k flies 2 e v_k / g; the ground's
    # impulse is m (1 + e) v_k, in Jground of the step that holds t_k
    h, e, m = BALL["height"], BALL["restitution"], BALL["mass"]
    t, v = np.sqrt(2 * h / G), np.sqrt(2 * G * h)
    J = rows[:, names.index("Jground[1]")]
    bounces = [_parse(msg) for msg in messages]
    assert len(bounces) >= 5
    for t_k, kind, impulse in bounces[:5]:
        assert kind == "contact"
        assert abs(t_k - t) <= 1e-9 and abs(impulse - m * (1 + e) * v) <= 1e-8 * m * v
        assert J[np.searchsorted(run.t, t_k)] == impulse
        t, v = t + 2 * e * v / G, e * v
    total = sum(impulse for _, _, impulse in bounces)  # the landings summed, those of a step in its Jground
    assert abs(J.sum() - total) <= 1e-14 * total


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
def test_the_falling_chain_equals_the_library_and_lands_mass_by_mass_as_the_closed_form_says(method, fmus, scenes):
    run, names, rows, messages = _run_both(fmus["chain"], scenes["chain"], "chain", method)
    np.testing.assert_array_equal(rows, _library_rows(run, names))
    scene = ln.load_scene(scenes["chain"])
    assert messages == [event_message(e, scene) for e in run.events]
    # the free fall of the part still in the air: mass k lands at sqrt(2 k a / g) with the momentum m sqrt(2 g k a)
    # (the links above it go slack as it stops), the ground's impulse on it
    N, a, m = CHAIN["N"], CHAIN["a"], CHAIN["m"]
    contacts = [(t, impulse) for t, kind, impulse in map(_parse, messages) if kind == "contact"]
    assert [msg.split(" of ")[1].split(",")[0] for msg in messages if ": contact of " in msg] == [
        scene.mass_label(k) for k in range(N)]
    k = np.arange(1, N + 1)
    assert np.abs(np.array([t for t, _ in contacts]) - np.sqrt(2 * k * a / G)).max() <= 1e-9
    assert np.abs(np.array([j for _, j in contacts]) - m * np.sqrt(2 * G * k * a)).max() <= 1e-9
    J = rows[:, [names.index(f"Jground[{i}]") for i in k]]
    np.testing.assert_array_equal(J.sum(axis=0), [j for _, j in contacts])  # one landing each
    assert any(": slack of link" in msg for msg in messages)


def test_a_hook_driven_by_inputs_drops_its_load_onto_the_ground_as_the_library_does(fmus, scenes):
    """The hook jerked up at 1 m/s (both ropes taut at once: the jerk's impulse on the hook, Jreact), swung, dropped
    at 2.5 m/s (the lower bob lands, its rope slack, the upper bob jerks it), stopped: X, Jreact, Jrope and Jground
    of each quarter second and the events equal Simulator.advance(anchors=) bit for bit."""
    fmu = fmus["hook"]
    scene = ln.load_scene(scenes["hook"])
    sim = ln.Simulator(scene, "dop853", rtol=TOLERANCE, error_estimate=False, backend="native")
    instance = Instance(fmu)
    instance.initialize()
    names = fmu.names("X") + fmu.names("Jreact") + fmu.names("Jrope") + fmu.names("Jground")
    axes = [f"[1,{i}]" for i in (1, 2, 3)]
    messages = []
    for i, V in enumerate([(0, 0, 1.0), (0.8, 0, 0.2), (0, 0, -2.5), (0, 0, 0)]):
        P = instance.get([f"X{a}" for a in axes])  # the hook where its held motion took it
        np.testing.assert_array_equal(P, sim.state.X[0])
        for quantity, value in (("P", P), ("V", V), ("A", (0, 0, 0))):
            instance.slave.setReal([fmu.vr[quantity + a] for a in axes], list(map(float, value)))
        instance.slave.doStep(0.25 * i, 0.25)
        messages += instance.events()
        before = len(sim.integrator.events)
        sim.advance(0.25 * (i + 1), anchors=(P[None], np.array([V], float), np.zeros((1, 3))))
        step_events = sim.integrator.events[before:]  # the jerk at the step's start (the hook's jump) included
        Jrope = [sum(e.impulse for e in step_events if e.kind == "taut" and e.index == l) for l in range(scene.L)]
        Jground = [sum(e.impulse for e in step_events if e.kind == "contact" and e.index == k) for k in (1, 2)]
        expected = np.concatenate([sim.state.X.ravel(), sim.anchor_report()["impulse"].ravel(), Jrope, Jground])
        np.testing.assert_array_equal(instance.get(names), expected)
    assert messages == [event_message(e, scene) for e in sim.integrator.events]
    assert ": contact of mass 3" in " ".join(messages)


def test_a_frictionless_grounds_fmus_give_the_librarys_directional_derivatives_bit_for_bit(fmus, scenes):
    """A frictionless ground's FMUs declare providesDirectionalDerivative (the library linearizes the current mode:
    tests/ropes/test_ground_interface_jacobian.py; a rough ground's say "false": test_native_fmu_ropes). The hook
    lowered at 0.2 m/s for 1.75 s and held for 0.25 s: the lower bob lands at 1.5 s and lies on the ground, its rope
    slack, the upper bob hangs from the still hook. Every derivative of T and Freact along each input F, P, V, A equals the library's Jacobian there bit for
    bit (the same core on the same state and inputs)."""
    from test_native_fmu_ropes import _provides_directional

    assert all(_provides_directional(fmu.path) == "true" for fmu in fmus.values())
    fmu = fmus["hook"]
    scene = ln.load_scene(scenes["hook"])
    sim = ln.Simulator(scene, "dop853", rtol=TOLERANCE, error_estimate=False, backend="native")
    instance = Instance(fmu, logging=False)
    instance.initialize()
    axes = [f"[1,{i}]" for i in (1, 2, 3)]
    for i, V in enumerate([(0, 0, -0.2)] * 7 + [(0, 0, 0)]):
        P = instance.get([f"X{a}" for a in axes])
        for quantity, value in (("P", P), ("V", V), ("A", (0, 0, 0))):
            instance.slave.setReal([fmu.vr[quantity + a] for a in axes], list(map(float, value)))
        instance.slave.doStep(0.25 * i, 0.25)
        sim.advance(0.25 * (i + 1), anchors=(P[None], np.array([V], float), np.zeros((1, 3))))
    np.testing.assert_array_equal(instance.get(fmu.names("X")), sim.state.X.ravel())
    assert sim.state.X[2, 2] == pytest.approx(-1.8, abs=1e-12) and abs(sim.state.U[2]).max() < 1e-12
    assert list(instance.get(["slack[1]", "slack[2]"])) == [0.0, 1.0]
    J = sim.interface_jacobian(anchors=(sim.state.X[:1], np.zeros((1, 3)), np.zeros((1, 3))))
    unknowns = ["T[1]", "T[2]"] + fmu.names("Freact")
    for name in INPUT_NAMES:
        quantity, _, index = name.partition("[")
        k, i = (int(j) - 1 for j in index.rstrip("]").split(","))
        expected = np.concatenate([J["T", quantity][:, k, i], J["Freact", quantity][0, :, k, i]])
        got = instance.slave.getDirectionalDerivative([fmu.vr[u] for u in unknowns], [fmu.vr[name]], [1.0])
        np.testing.assert_array_equal(got, expected, err_msg=name)
    assert J["T", "F"][0, 1, 2] != 0.0 and not J["T", "F"][1].any()  # the taut rope answers, the slack one not


INPUT_NAMES = [f"{q}[{k},{i}]" for q, ks in (("F", (2, 3)), ("P", (1,)), ("V", (1,)), ("A", (1,))) for k in ks
               for i in (1, 2, 3)]


def test_a_state_taken_between_two_contacts_repeats_the_run_across_the_next(fmus):
    """The chain's state after its first mass landed (0.10 s) and before the second (0.14 s), restored in the same
    instance and deserialized into another that has run on, gives the same outputs and events to the last bit."""
    fmu = fmus["chain"]
    names = _names(fmu)
    t_end, n = RUNS["chain"]
    times = np.linspace(0.0, t_end, n + 1)
    a = Instance(fmu, "a")
    a.initialize()
    k_between = 12  # t = 0.12 s
    _, messages = a.run(times, names, 0, k_between)
    assert [_parse(msg)[1] for msg in messages] == ["contact", "slack"]
    at_state = a.get(names)
    state = a.slave.getFMUstate()
    serialized = a.slave.serializeFMUstate(state)
    rows, messages = a.run(times, names, k_between)
    assert sum(": contact of " in msg for msg in messages) == CHAIN["N"] - 1
    a.slave.setFMUstate(state)
    np.testing.assert_array_equal(a.get(names), at_state)
    again, messages_again = a.run(times, names, k_between)
    np.testing.assert_array_equal(again, rows)
    assert messages_again == messages

    b = Instance(fmu, "b")
    b.initialize()
    b.run(times, names, 0, 30)  # t = 0.3 s: most of the chain on the ground
    b.slave.setFMUstate(b.slave.deSerializeFMUstate(serialized))
    np.testing.assert_array_equal(b.get(names), at_state)
    restored, restored_messages = b.run(times, names, k_between)
    np.testing.assert_array_equal(restored, rows)
    assert restored_messages == messages


def test_the_error_estimate_and_the_tension_peaks_are_the_librarys(fmus, scenes):
    """The companion run (a tenth of the tolerance) and the gap over the scene's own masses, not the core's virtual
    anchors: Simulator.advance's error_estimate after each step, bit for bit; T_peak, T_peak_time its tension_peaks,
    which with ropes or a ground are the step's end values (not located across the events)."""
    fmu = fmus["chain"]
    t_end, n = RUNS["chain"]
    times = np.linspace(0.0, t_end, n + 1)
    sim = ln.Simulator(ln.load_scene(scenes["chain"]), "dop853", rtol=TOLERANCE, backend="native")
    names = ["error_estimate"] + fmu.names("T_peak") + fmu.names("T_peak_time")
    instance = Instance(fmu)
    instance.initialize()
    rows, library = [], []
    for i in range(n):
        instance.slave.doStep(times[i], times[i + 1] - times[i])
        rows.append(instance.get(names))
        sim.advance(times[i + 1])
        library.append(np.concatenate([[sim.error_estimate], *sim.tension_peaks()]))
    np.testing.assert_array_equal(rows, library)
    assert 0.0 < max(row[0] for row in rows) < sim.error_goal


@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_the_chain_on_rattle_and_its_compositions_through_the_fmu_equals_the_library(method, fmus, scenes):
    # every method is offered with a ground; at the FMU's default step (1e-3
    # s), chosen at initialization, the outputs and events are the library's on the native backend to the last bit
    fmu = fmus["chain"]
    integrator = next(v for v in fmu.md.modelVariables if v.name == "integrator")
    assert {"dop853", "dopri5", "rattle", "yoshida4"} <= set(integrator.description.split(": ")[1].split(", "))
    t_end, n = RUNS["chain"]
    run = ln.simulate(scenes["chain"], t_end, method, dt=1e-3, n_out=n + 1, error_estimate=False, backend="native")
    names = _names(fmu)
    instance = Instance(fmu)
    instance.initialize(integrator=method)
    rows, messages = instance.run(run.t, names)
    np.testing.assert_array_equal(rows, _library_rows(run, names)[1:])
    scene = ln.load_scene(scenes["chain"])
    assert messages == [event_message(e, scene) for e in run.events]
    # the free fall, exact on these methods: mass k lands at sqrt(2 k a / g)
    landings = [_parse(m)[0] for m in messages if ": contact of " in m]
    k = np.arange(1, CHAIN["N"] + 1)
    assert np.abs(np.array(landings) - np.sqrt(2 * k * CHAIN["a"] / G)).max() <= 1e-14


def test_gravity_masses_and_lengths_may_change(fmus, scenes):
    fmu = fmus["chain"]
    scene = ln.load_scene(scenes["chain"])
    changed = scene.with_parameters(gravity=[0.5, 0.0, -5.0])
    run = _library(changed, 0.4, 20, "dop853")
    names = _names(fmu)
    instance = Instance(fmu)
    instance.initialize(**{"g[1]": 0.5, "g[3]": -5.0})
    rows, messages = instance.run(run.t, names)
    np.testing.assert_array_equal(rows, _library_rows(run, names)[1:])
    assert messages == [event_message(e, changed) for e in run.events]
    # the slower fall: mass k lands at sqrt(2 k a / 5)
    first = _parse(messages[0])
    assert first[1] == "contact" and abs(first[0] - np.sqrt(2 * CHAIN["a"] / 5.0)) <= 1e-9

    # a heavier second mass and a longer (slack) first rope: the initial state, made consistent by the core
    # (ln_rope_initial_state), is the library's, and so is the run, to the last bit
    mass, length = scene.mass.copy(), scene.length.copy()
    mass[1], length[0] = 0.2, 1.5 * CHAIN["a"]
    changed = scene.with_parameters(mass=mass, length=length)
    run = _library(changed, 0.4, 20, "dop853")
    other = Instance(fmu, "mass")
    other.initialize(**{"M[2]": 0.2, "R[1]": 1.5 * CHAIN["a"]})
    rows, messages = other.run(run.t, names)
    np.testing.assert_array_equal(rows, _library_rows(run, names)[1:])
    assert messages == [event_message(e, changed) for e in run.events]
    assert rows[:, names.index("slack[1]")][0] == 1.0  # the longer rope starts slack


def test_the_ball_through_the_fmi3_fmu_gives_the_fmi2_fmus_outputs_and_events(fmus, scenes, tmp_path_factory):
    """The same model behind the FMI 3.0 glue: the arrays X and Jground equal the FMI 2.0 FMU's scalars at every
    communication point, its events are logged in the same words, its integrator offers the same methods."""
    from fmpy import read_model_description
    from fmpy.fmi3 import FMU3Slave

    from native.build_fmi3 import build_scene_fmi3

    path = tmp_path_factory.mktemp("ball_fmi3") / "ball_fmi3.fmu"
    build_scene_fmi3(str(scenes["ball"]), path, platforms="host", quiet=True)
    unzipped = path.with_suffix("")
    with zipfile.ZipFile(path) as z:
        z.extractall(unzipped)
    md = read_model_description(str(path))
    vr = {v.name: v.valueReference for v in md.modelVariables}
    assert next(v for v in md.modelVariables if v.name == "integrator").description == next(
        v for v in fmus["ball"].md.modelVariables if v.name == "integrator").description
    log = []
    slave = FMU3Slave(guid=md.guid, unzipDirectory=str(unzipped), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="fmi3")
    slave.instantiate(logMessage=lambda env, status, category, message: log.append(
        (int(status), category.decode(), message.decode())))
    slave.setDebugLogging(True, [EVENT_CATEGORY])
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    fmu = fmus["ball"]
    names = fmu.names("X") + fmu.names("Jground")
    t_end, n = RUNS["ball"]
    times = np.linspace(0.0, t_end, n + 1)
    instance = Instance(fmu)
    instance.initialize()
    rows2, messages2 = instance.run(times, names)
    rows3 = []
    for i in range(n):
        slave.doStep(times[i], times[i + 1] - times[i])
        rows3.append(np.concatenate([slave.getFloat64([vr["X"]], 3), slave.getFloat64([vr["Jground"]], 1)]))
    np.testing.assert_array_equal(np.array(rows3), rows2)
    assert [m for s, c, m in log if c == EVENT_CATEGORY] == messages2 and len(messages2) >= 5
    slave.freeInstance()
