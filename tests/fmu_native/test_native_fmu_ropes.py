"""Rope scenes through the native FMU, driven in this process by fmpy: the shipped crane whose hoist rope goes slack
when the trolley brakes hard (models/ropes/rope_crane.json) and a bob thrown up on a rope (rope_pendulum.json),
against linknet_core.simulate on the native backend with the same method and communication points: X, U, T, the
slack[l] flags, the jerks' impulses Jrope[l] and one message per event in the category logEvents. An FMU state taken
mid-run (in memory, or serialized into another instance that is in another mode) repeats the run; bad input is
answered as the contract says (fmi2Error, a logged message naming the variable, the instance still usable); the
scenes the native core cannot take are refused at build with the library's reason, no FMU written. The crane's
pythonfmu FMU (in a client process) gives the same slack flags, positions and events.

Tolerances. The FMU's binary (Zig's clang) and the library (the system's gcc) compile the same C core with
-ffp-contract=off, without -ffast-math and without the C library's math (test_native_fmu_equals_library: every
output of the rod scenes equal bit for bit). The ropes' events are found by the same root finds on the same steps,
so the two runs are the same arithmetic here too (measured: every difference 0, every event's time and impulse the
same double). The bound asserted is round-off, ROUND_OFF of each output's largest magnitude: any difference of
compilation (an operation reordered) stays at that level, while a physics difference (an event located elsewhere
within the tolerance, ~1e-9 s at rtol 1e-8, moves the crane's load by ~1e-8 m of its 9 m) would not. The slack flags
are compared exactly (0 or 1), the events' kinds and links exactly, their times and impulses to ROUND_OFF.
"""
from __future__ import annotations

import json
import sys
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

from native_fmu_support import MODELS, ROOT, built

sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "fmu_src"))
import build_fmu  # noqa: E402
import linknet_core as ln  # noqa: E402
from linknet_core.dynamics.unilateral import Event, linearization_refusal  # noqa: E402
from linknet_fmu.layout import EVENT_CATEGORY  # noqa: E402
from linknet_fmu.rope_events import event_message  # noqa: E402

ROUND_OFF = 1e-12
OK, ERROR = 0, 3
ROPES = MODELS / "ropes"
# (seconds, communication steps): past the crane's slack (1.21 s) and jerk (1.66 s); the bob's first jerk (0.47 s),
# slack over the top (1.46 s) and second jerk (1.67 s)
RUNS = {"rope_crane": (2.5, 250), "rope_pendulum": (2.0, 200)}
FMU_STEP, FMU_TOLERANCE = 1e-3, 1e-8  # the FMUs' defaults (build_fmu.py): the library runs with the same


class Instance:
    """One instance of a native FMU with ropes or a ground through fmpy's FMU2Slave, with callbacks of its own (as
    native_fmu_support.fmpy_instance makes them) whose logger keeps each message's status and category."""

    def __init__(self, fmu, name="ropes", logging=True):
        from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE

        self.fmu, self.log = fmu, []

        def logger(env, instance, status, category, message):
            self.log.append((int(status), category.decode(), message.decode("utf-8", "replace")))

        self.callbacks = fmi2CallbackFunctions()
        self.callbacks.logger = fmi2CallbackLoggerTYPE(logger)
        self.callbacks.allocateMemory = defaultCallbacks.allocateMemory
        self.callbacks.freeMemory = defaultCallbacks.freeMemory
        self.slave = FMU2Slave(guid=fmu.guid, unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident,
                               instanceName=name)
        self.slave.instantiate(callbacks=self.callbacks, loggingOn=False)
        if logging:
            self.slave.setDebugLogging(True, [EVENT_CATEGORY])

    def initialize(self, integrator=None, **reals):
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        if integrator:
            self.slave.setString([self.fmu.vr["integrator"]], [integrator])
        for name, value in reals.items():
            self.slave.setReal([self.fmu.vr[name]], [value])
        self.slave.exitInitializationMode()

    def get(self, names):
        return np.array(self.slave.getReal([self.fmu.vr[n] for n in names]))

    def events(self):
        """The messages logged in the events' category (each with fmi2OK status), and the log emptied."""
        out = [m for s, c, m in self.log if c == EVENT_CATEGORY]
        assert all(s == OK for s, c, _ in self.log if c == EVENT_CATEGORY)
        self.log.clear()
        return out

    def run(self, times, names, first=0, last=None):
        """doStep over times[first..last] (the library's communication points, each step times[i+1] - times[i],
        which lands on times[i+1] exactly); the outputs at each point after the first, and the events' messages."""
        last = len(times) - 1 if last is None else last
        rows = []
        for i in range(first, last):
            self.slave.doStep(times[i], times[i + 1] - times[i])
            rows.append(self.get(names))
        return np.array(rows).reshape(-1, len(names)), self.events()


def _names(fmu):
    return fmu.names("X") + fmu.names("U") + fmu.names("T") + fmu.names("slack") + fmu.names("Jrope")


def _library(scene: str, method: str):
    t_end, n = RUNS[scene]
    setting = dict(rtol=FMU_TOLERANCE) if ln.METHODS[method].adaptive else dict(dt=FMU_STEP)
    return ln.simulate(ROPES / f"{scene}.json", t_end, method, n_out=n + 1, error_estimate=False, backend="native",
                       **setting)


def _library_rows(run, names):
    """The library's outputs in the FMU's names: Jrope[l] the impulses of rope l's taut events within each
    communication step (the first row, before any step, 0)."""
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
            for e in run.events:
                if e.kind == "taut" and e.index == idx[0]:
                    J[np.searchsorted(run.t, e.t)] += e.impulse  # the step (t_i-1, t_i] that holds it
            columns.append(J)
    return np.column_stack(columns)


def _assert_outputs(fmu_rows, library_rows, names, what):
    assert fmu_rows.shape == library_rows.shape, what
    for j, name in enumerate(names):
        a, b = fmu_rows[:, j], library_rows[:, j]
        if name.startswith("slack["):
            assert set(np.unique(a)) <= {0.0, 1.0}, f"{what}: {name} takes values other than 0 and 1"
            np.testing.assert_array_equal(a, b, err_msg=f"{what}: {name}")
        else:
            scale = max(np.abs(b).max(), 1e-300)
            assert np.abs(a - b).max() <= ROUND_OFF * scale, \
                f"{what}: {name} differs by {np.abs(a - b).max():.3g} (scale {scale:.3g})"


def _parse(message: str):
    """(t, kind, link label, impulse) of an event's message."""
    head, _, impulse = message.partition(", impulse ")
    t, _, what = head.removeprefix("event at t=").partition(": ")
    kind, _, label = what.partition(" of ")
    return float(t), kind, label, float(impulse.removesuffix(" N s"))


def _assert_events(messages, events, scene, what):
    """The FMU's messages are the library's events, one each in order, in rope_events.event_message's words."""
    assert len(messages) == len(events), f"{what}: {len(messages)} messages, {len(events)} events"
    for message, e in zip(messages, events):
        t, kind, label, impulse = _parse(message)
        assert (kind, label) == (e.kind, scene.link_label(e.index)), f"{what}: {message}"
        assert abs(t - e.t) <= ROUND_OFF * max(1.0, abs(e.t)), f"{what}: {message} vs {e}"
        assert abs(impulse - e.impulse) <= ROUND_OFF * max(1.0, abs(e.impulse)), f"{what}: {message} vs {e}"
        # the words, with the FMU's own numbers (the time read back is the double it wrote)
        assert message == event_message(Event(t, kind, e.index, impulse), scene), message


@pytest.fixture(scope="module")
def fmus(fmu_root):
    return {name: built(fmu_root, ROPES / f"{name}.json") for name in RUNS}


@pytest.mark.parametrize("method", ["dop853", "rattle"])
@pytest.mark.parametrize("scene", list(RUNS))
def test_rope_scenes_equal_the_library_to_round_off(scene, method, fmus):
    fmu = fmus[scene]
    names = _names(fmu)
    run = _library(scene, method)
    expected = _library_rows(run, names)
    instance = Instance(fmu)
    instance.initialize(integrator=method)
    first = instance.get(names)
    rows, messages = instance.run(run.t, names)
    _assert_outputs(np.vstack([first, rows]), expected, names, f"{scene}, {method}")
    _assert_events(messages, run.events, ln.load_scene(ROPES / f"{scene}.json"), f"{scene}, {method}")
    kinds = [e.kind for e in run.events]
    assert "slack" in kinds and "taut" in kinds  # the rope went slack and jerked taut within the run
    T, slack = rows[:, [j for j, n in enumerate(names) if n.startswith("T[")]], rows[:, [
        j for j, n in enumerate(names) if n.startswith("slack[")]]
    assert np.all(T[slack == 1.0] == 0.0) and np.all(T[slack == 0.0] > 0.0)  # slack exactly where T is 0
    J = rows[:, [j for j, n in enumerate(names) if n.startswith("Jrope[")]]
    assert J.max() > 0.0 and np.all(J >= 0.0)  # the jerks pull


def test_the_crane_load_flies_after_the_trolley_brakes(fmus):
    """The shipped crane through the FMU: taut while the trolley runs, slack from the braking (from 1.2 s) until the
    jerk, whose impulse is the load's radial momentum taken by the rope (m v_r, inelastic: v_r from the load's
    velocity along the rope, just before the step that holds the jerk)."""
    fmu = fmus["rope_crane"]
    names = _names(fmu)
    t_end, n = RUNS["rope_crane"]
    times = np.linspace(0.0, t_end, n + 1)
    instance = Instance(fmu)
    instance.initialize()
    rows, messages = instance.run(times, names)
    at = {name: rows[:, j] for j, name in enumerate(names)}
    slack = at["slack[1]"]
    assert np.all(slack[times[1:] < 1.2] == 0.0) and slack.max() == 1.0
    first_slack = times[1:][np.argmax(slack == 1.0)]
    assert 1.2 < first_slack < 1.4  # the trolley brakes over (1.2, 1.4) s
    assert [_parse(m)[1] for m in messages] == ["slack", "taut"]
    jerk = int(np.flatnonzero(at["Jrope[1]"])[0])
    t_jerk = _parse(messages[1])[0]
    assert times[jerk] < t_jerk <= times[jerk + 1]
    assert at["Jrope[1]"][jerk] == _parse(messages[1])[3]


def test_an_fmu_state_mid_run_repeats_the_run(fmus):
    """A state taken in the flight before the bob's first jerk (the rope slack, its mode chosen) and restored in the
    same instance, and serialized into another instance that has run on into the taut mode, repeats the same
    outputs and events to the last bit; a state taken just after the jerk gives back that step's Jrope."""
    fmu = fmus["rope_pendulum"]
    names = _names(fmu)
    t_end, n = RUNS["rope_pendulum"]
    times = np.linspace(0.0, t_end, n + 1)
    a = Instance(fmu, "a")
    a.initialize()
    k_flight = 30  # t = 0.3 s: flying, the rope slack
    a.run(times, names, 0, k_flight)
    at_flight = a.get(names)
    assert a.get(["slack[1]"])[0] == 1.0
    state = a.slave.getFMUstate()
    serialized = a.slave.serializeFMUstate(state)
    rows, messages = a.run(times, names, k_flight)
    assert len(messages) == 3
    a.slave.setFMUstate(state)
    again, messages_again = a.run(times, names, k_flight)
    np.testing.assert_array_equal(again, rows)
    assert messages_again == messages

    b = Instance(fmu, "b")
    b.initialize()
    b.run(times, names, 0, 100)  # t = 1 s: swinging on the taut rope
    assert b.get(["slack[1]"])[0] == 0.0
    b.slave.setFMUstate(b.slave.deSerializeFMUstate(serialized))
    np.testing.assert_array_equal(b.get(names), at_flight)
    restored, restored_messages = b.run(times, names, k_flight)
    np.testing.assert_array_equal(restored, rows)
    assert restored_messages == messages

    # just after the step that holds the first jerk (0.46 to 0.47 s): its impulse comes back with the state
    a.slave.setFMUstate(state)
    a.run(times, names, k_flight, 47)
    J = a.get(["Jrope[1]"])[0]
    assert J > 0.0
    after_jerk = a.slave.serializeFMUstate(a.slave.getFMUstate())
    c = Instance(fmu, "c")
    c.initialize()
    assert c.get(["Jrope[1]"])[0] == 0.0  # before any step
    c.slave.setFMUstate(c.slave.deSerializeFMUstate(after_jerk))
    assert c.get(["Jrope[1]"])[0] == J
    np.testing.assert_array_equal(c.run(times, names, 47)[0], a.run(times, names, 47)[0])


def test_bad_input_is_refused_with_a_message_and_the_instance_goes_on(fmus, fmu_root):
    from fmpy.fmi1 import FMICallException

    fmu = fmus["rope_pendulum"]
    scene = ln.load_scene(ROPES / "rope_pendulum.json")
    instance = Instance(fmu)
    instance.initialize()
    for name in ("slack[1]", "Jrope[1]"):  # outputs: never set
        with pytest.raises(FMICallException):
            instance.slave.setReal([fmu.vr[name]], [0.0])
        status, _, message = instance.log[-1]
        assert status == ERROR and f"{name} is an output and cannot be set" in message
    # the directional derivatives, of the current mode's outputs: the rope slack at the start (T = 0, derivative 0)
    assert instance.slave.getDirectionalDerivative([fmu.vr["T[1]"]], [fmu.vr["F[2,3]"]], [1.0]) == [0.0]
    with pytest.raises(FMICallException):
        instance.slave.setDebugLogging(True, ["logRopes"])
    assert "logRopes" in instance.log[-1][2] and EVENT_CATEGORY in instance.log[-1][2]
    instance.log.clear()
    instance.slave.doStep(0.0, 0.5)  # still usable: the flight and the first jerk
    assert instance.get(["slack[1]"])[0] == 0.0 and instance.get(["Jrope[1]"])[0] > 0.0
    assert [_parse(m)[1] for m in instance.events()] == ["taut"]
    # taut: the FMU's derivative is the library's (the same core on the same state), bit for bit
    library = ln.Simulator(scene, "dop853", rtol=FMU_TOLERANCE, backend="native")
    library.advance(0.5)
    np.testing.assert_array_equal(instance.get(["X[2,1]", "X[2,2]", "X[2,3]"]), library.state.X[1])
    dF = np.zeros((2, 3))
    dF[1, 2] = 1.0
    expected = library.interface_linearization().directional(dF=dF)["T"][0]
    assert expected != 0.0
    assert instance.slave.getDirectionalDerivative([fmu.vr["T[1]"]], [fmu.vr["F[2,3]"]], [1.0]) == [expected]
    # a scene without ropes logs no events: its FMU does not take their category
    rods = Instance(built(fmu_root, "chain_10"), "rods", logging=False)
    with pytest.raises(FMICallException):
        rods.slave.setDebugLogging(True, [EVENT_CATEGORY])
    assert rods.log[-1][0] == ERROR and f'unknown log category "{EVENT_CATEGORY}"' in rods.log[-1][2]


def _log_categories(path) -> list:
    with zipfile.ZipFile(path) as z:
        return [c.get("name") for c in ET.fromstring(z.read("modelDescription.xml")).find("LogCategories")]


def _provides_directional(path) -> str:
    """The model description's providesDirectionalDerivative (FMI 2.0) or providesDirectionalDerivatives (FMI 3.0)
    as written ("true", "false"; "false" where absent, the standard's default)."""
    with zipfile.ZipFile(path) as z:
        cs = ET.fromstring(z.read("modelDescription.xml")).find("CoSimulation")
    return cs.get("providesDirectionalDerivative", cs.get("providesDirectionalDerivatives", "false"))


def test_rope_scenes_declare_the_events_category(fmus):
    for fmu in fmus.values():
        names = _log_categories(fmu.path)
        assert names[-1] == EVENT_CATEGORY and names.count(EVENT_CATEGORY) == 1


def _pendulum_changed(root, name, **changes):
    """rope_pendulum.json under another name, with changes: ground=..., or input_pivot=True (the pivot driven by
    inputs instead of fixed)."""
    data = json.loads((ROPES / "rope_pendulum.json").read_text())
    data["name"] = name
    if "ground" in changes:
        data["ground"] = changes["ground"]
    if changes.get("input_pivot"):
        pivot = data["masses"][0]
        pivot.pop("fixed")
        pivot.update(driven=True, motion={"kind": "input"})
    path = root / f"{name}.json"
    path.write_text(json.dumps(data))
    return path


def test_a_rope_scene_with_a_ground_with_friction_builds_offering_every_method(tmp_path):
    # the pendulum above a rough ground (test_native_fmu_friction.py runs friction through the FMU): RATTLE and its
    # compositions offered as the adaptive methods are (the native core runs a ground on every method)
    path = _pendulum_changed(tmp_path, "rope_ground", ground={"point": [0.0, 0.0, -5.0], "normal": [0.0, 0.0, 1.0],
                                                              "friction": 0.5})
    from fmpy import read_model_description
    out = tmp_path / "rough.fmu"
    build_fmu.build_scene_fmu(str(path), out, native=True, quiet=True, platforms="host")
    integrator = next(v for v in read_model_description(str(out)).modelVariables if v.name == "integrator")
    assert {"dop853", "dopri5", "rattle", "yoshida4"} <= set(integrator.description.split(": ")[1].split(", "))
    # its directional derivatives are refused for the whole scene, and the flag says so
    assert linearization_refusal(ln.load_scene(path)) and _provides_directional(out) == "false"


def test_a_pivot_driven_by_inputs_jerks_and_slackens_the_rope_as_the_library(fmu_root, tmp_path_factory):
    """The bob's pivot moved by the inputs P, V (held as P + V tau from each communication point, P continuing the
    held motion): at rest, jerked up at 2 m/s at 1.0 s (the taut rope stretched: a jerk at once, its impulse on the
    rope and, the same, on the anchor), dropped at 4 m/s at 1.3 s (the rope slackens at once), stopped at 1.6 s. The
    FMU against Simulator.advance(anchors=) on the native backend at the same points: X, U, T, slack, Jrope, Jreact
    and the events' messages."""
    path = _pendulum_changed(tmp_path_factory.mktemp("rope_input"), "rope_input_pivot", input_pivot=True)
    fmu = built(fmu_root, path)
    scene = ln.load_scene(path)
    names = _names(fmu) + fmu.names("Jreact")
    h, n = 0.01, 200
    times = np.arange(n + 1) * h

    def velocity(t):
        return np.array([0.0, 0.0, 2.0 if 1.0 <= t < 1.3 else -4.0 if 1.3 <= t < 1.6 else 0.0])

    instance = Instance(fmu)
    instance.initialize()
    sim = ln.Simulator(scene, "dop853", rtol=FMU_TOLERANCE, backend="native", error_estimate=False)
    inputs = [fmu.vr[f"P[1,{i}]"] for i in (1, 2, 3)] + [fmu.vr[f"V[1,{i}]"] for i in (1, 2, 3)]
    P = np.array(scene.X0[0])
    rows, expected = [], []
    for i in range(n):
        V = velocity(times[i])
        instance.slave.setReal(inputs, list(P) + list(V))
        instance.slave.doStep(times[i], times[i + 1] - times[i])
        rows.append(instance.get(names))
        sim.advance(times[i + 1], None, anchors=(P[None], V[None], np.zeros((1, 3))))
        out = sim.outputs()
        expected.append(np.concatenate([out["X"].ravel(), out["U"].ravel(), out["T"], out["slack"].astype(float),
                                        sim.integrator.rope_impulses(), out["impulse"].ravel()]))
        P = P + V * (times[i + 1] - times[i])
    rows, expected = np.array(rows), np.array(expected)
    _assert_outputs(rows, expected, names, "rope_input_pivot")
    _assert_events(instance.events(), sim.integrator.events, scene, "rope_input_pivot")
    assert not [m for s, c, m in instance.log if s != OK]  # P continued the held motion: no position jump to say
    at = {name: rows[:, j] for j, name in enumerate(names)}
    jerk = int(np.flatnonzero(times[:-1] == 1.0)[0])  # the step that begins with the jerk up
    Jreact = np.array([at[f"Jreact[1,{i}]"][jerk] for i in (1, 2, 3)])
    assert at["Jrope[1]"][jerk] > 0.0
    assert abs(np.linalg.norm(Jreact) - at["Jrope[1]"][jerk]) <= ROUND_OFF * at["Jrope[1]"][jerk]
    drop = int(np.flatnonzero(times[:-1] == 1.3)[0])
    assert at["slack[1]"][drop] == 1.0 and at["T[1]"][drop] == 0.0


def test_the_crane_through_the_native_and_the_pythonfmu_fmu(fmus, tmp_path_factory):
    from fmu_harness import FMU_CLIENT_LIB, build_cached, run_client

    fmu = fmus["rope_crane"]
    names = fmu.names("X") + fmu.names("slack") + fmu.names("Jrope")
    t_end, n = RUNS["rope_crane"]
    times = np.linspace(0.0, t_end, n + 1)
    seed_names = ["F[2,1]", "F[2,2]", "F[2,3]"]
    python_fmu = build_cached(tmp_path_factory.mktemp("rope_crane_pythonfmu"), str(ROPES / "rope_crane.json"))
    assert _log_categories(python_fmu) == _log_categories(fmu.path)
    # both kinds give the directional derivatives of a rope scene (within the current mode), and their flags say so
    assert _provides_directional(python_fmu) == _provides_directional(fmu.path) == "true"
    out = run_client(FMU_CLIENT_LIB + f"""
f = Fmu({str(python_fmu)!r})
f.slave.setDebugLogging(True, [{EVENT_CATEGORY!r}])  # declared by both FMU kinds for rope scenes, and taken
f.init()
times = np.linspace(0.0, {t_end!r}, {n + 1})
rows = [f.get({names!r})]
for i in range({n}):
    f.step(times[i], times[i + 1] - times[i])
    rows.append(f.get({names!r}))
seed = [f.vr[n] for n in {seed_names!r}]
derivative = f.slave.getDirectionalDerivative([f.vr["T[1]"]], seed, [1.0] * len(seed))
save(rows=np.array(rows), messages=np.array([m for s, m in LOG if m.startswith("event at")]),
     derivative=np.array(derivative))
""", tmp_path_factory.mktemp("rope_crane_client"))
    instance = Instance(fmu)
    instance.initialize()
    first = instance.get(names)
    rows, messages = instance.run(times, names)
    rows = np.vstack([first, rows])
    # taut again at the end: the tension's derivative along the load's force (1, 1, 1) N, the same within the run's
    # tolerance from both kinds (their states agree to it)
    derivative = instance.slave.getDirectionalDerivative([fmu.vr["T[1]"]], [fmu.vr[n] for n in seed_names],
                                                          [1.0] * len(seed_names))
    assert rows[-1, names.index("slack[1]")] == 0.0 and derivative[0] != 0.0
    assert abs(derivative[0] - out["derivative"][0]) <= FMU_TOLERANCE * abs(derivative[0])
    python_rows = out["rows"]
    slack = [j for j, name in enumerate(names) if name.startswith("slack[")]
    np.testing.assert_array_equal(rows[:, slack], python_rows[:, slack])
    X = [j for j, name in enumerate(names) if name.startswith("X[")]
    scale = np.abs(python_rows[:, X]).max()
    assert np.abs(rows[:, X] - python_rows[:, X]).max() <= FMU_TOLERANCE * scale  # within the run's tolerance
    J = [j for j, name in enumerate(names) if name.startswith("Jrope[")]
    assert np.abs(rows[:, J] - python_rows[:, J]).max() <= FMU_TOLERANCE * np.abs(python_rows[:, J]).max()
    python_messages = [str(m) for m in out["messages"]]
    assert [_parse(m)[1:3] for m in messages] == [_parse(m)[1:3] for m in python_messages] == [
        ("slack", "link 1 (trolley-load)"), ("taut", "link 1 (trolley-load)")]
    for m, pm in zip(messages, python_messages):
        assert abs(_parse(m)[0] - _parse(pm)[0]) <= FMU_TOLERANCE * t_end


def test_the_crane_through_the_fmi3_fmu_gives_the_fmi2_fmus_outputs_and_events(fmus, tmp_path_factory):
    """The same model behind the FMI 3.0 glue: the arrays X, slack and Jrope equal the FMI 2.0 FMU's scalars at every
    communication point, and its events are logged in the same category and words."""
    from fmpy import read_model_description
    from fmpy.fmi3 import FMU3Slave

    from native.build_fmi3 import build_scene_fmi3

    path = tmp_path_factory.mktemp("rope_crane_fmi3") / "rope_crane_fmi3.fmu"
    build_scene_fmi3(str(ROPES / "rope_crane.json"), path, platforms="host", quiet=True)
    unzipped = path.with_suffix("")
    with zipfile.ZipFile(path) as z:
        z.extractall(unzipped)
    md = read_model_description(str(path))
    assert _provides_directional(path) == "true"  # as the FMI 2.0 FMU's: the rope scene's derivatives given
    vr = {v.name: v.valueReference for v in md.modelVariables}
    log = []
    slave = FMU3Slave(guid=md.guid, unzipDirectory=str(unzipped), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="fmi3")
    slave.instantiate(logMessage=lambda env, status, category, message: log.append(
        (int(status), category.decode(), message.decode())))
    slave.setDebugLogging(True, [EVENT_CATEGORY])
    slave.enterInitializationMode(startTime=0.0)
    slave.exitInitializationMode()
    fmu = fmus["rope_crane"]
    names = fmu.names("X") + fmu.names("slack") + fmu.names("Jrope")
    t_end, n = RUNS["rope_crane"]
    times = np.linspace(0.0, t_end, n + 1)
    instance = Instance(fmu)
    instance.initialize()
    rows2, messages2 = instance.run(times, names)
    rows3 = []
    for i in range(n):
        slave.doStep(times[i], times[i + 1] - times[i])
        rows3.append(np.concatenate([slave.getFloat64([vr["X"]], 6), slave.getFloat64([vr["slack"]], 1),
                                     slave.getFloat64([vr["Jrope"]], 1)]))
    np.testing.assert_array_equal(np.array(rows3), rows2)
    assert [m for s, c, m in log if c == EVENT_CATEGORY] == messages2 and len(messages2) == 2
    slave.freeInstance()
