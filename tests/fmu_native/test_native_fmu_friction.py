"""Coulomb friction on the ground through the native FMU (`build_fmu.py --native`), driven in this process by fmpy:
a block thrown along a rough ground (it slides to a stop and sticks), a rod dropped at a slant onto it (masses joined
by a link: it lands on one end, slides, its top lands) and a rod standing on it until its base slips, against
linknet_core.simulate on the native backend with the same method and communication points (X, U, Jground, and one
message per event in the pythonfmu FMU's words, rope_events.event_message: the block's stop is a 'stick', the base's
slip a 'slip'), the dropped rod on RATTLE too, and against the closed form of the block's slide (it stops at v / (mu g)
after v^2 / (2 mu g)). An FMU state taken mid-slide (the contact's slip reference part of it), restored in the same
instance and deserialized into another that has run past the stop, repeats the run.

Tolerance: none (as test_native_fmu_ground: the FMU runs the library's own model of the ground with its grips, baked
into the resource, on the same core compiled with the same flags).
"""
from __future__ import annotations

import numpy as np
import pytest

from native_fmu_support import built, write_scenes
from test_native_fmu_ground import _library, _library_rows, _parse
from test_native_fmu_ropes import Instance

import linknet_core as ln  # noqa: E402
from linknet_fmu.rope_events import event_message  # noqa: E402

G = 9.81
BLOCK = dict(v=3.0, mu=0.4, mass=2.0)
# (seconds, communication steps): the block stops at 0.76 s, the standing rod's base slips at 0.59 s
RUNS = {"block": (1.5, 30), "rod": (0.6, 30), "standing": (0.6, 12)}


def block_data():
    b = BLOCK
    return {"name": "thrown_block", "gravity": [0, 0, -G],
            "masses": [{"name": "block", "position": [0, 0, 0], "mass": b["mass"],
                        "velocity": [0.6 * b["v"], 0.8 * b["v"], 0]}],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": b["mu"]}}


def rod_data():
    # a rod dropped at a slant, moving sideways: it lands on its lower end and slides (mu 0.2) until its top lands
    h, angle, v = 0.3, 0.9, [3.0, 1.5, 0.0]
    return {"name": "dropped_rod", "gravity": [0, 0, -G],
            "masses": [{"name": "foot", "position": [0, 0, h], "mass": 1.0, "velocity": v},
                       {"name": "top", "position": [np.cos(angle), 0, h + np.sin(angle)], "mass": 2.0,
                        "velocity": v}],
            "links": [{"a": 1, "b": 2, "length": 1.0}],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": 0.2}}


def standing_data():
    # a rod standing on its base 0.1 rad off the vertical (mu 0.15): held at first, its base slips as it tips
    angle = 0.1
    return {"name": "standing_rod", "gravity": [0, 0, -G],
            "masses": [{"name": "base", "position": [0, 0, 0], "mass": 1.0},
                       {"name": "top", "position": [np.sin(angle), 0, np.cos(angle)], "mass": 1.0}],
            "links": [{"a": 1, "b": 2, "length": 1.0}],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": 0.15}}


@pytest.fixture(scope="module")
def scenes(tmp_path_factory):
    return write_scenes(tmp_path_factory.mktemp("friction_scenes"),
                        {"block": block_data(), "rod": rod_data(), "standing": standing_data()})


@pytest.fixture(scope="module")
def fmus(fmu_root, scenes):
    """Each scene's FMU, built when a test first asks for it (once per session)."""
    class Built(dict):
        def __missing__(self, name):
            return built(fmu_root, scenes[name])
    return Built()


def _names(fmu):
    return fmu.names("X") + fmu.names("U") + fmu.names("Jground")


@pytest.mark.parametrize("method", ["dop853", "dopri5"])
@pytest.mark.parametrize("name", ["block", "rod", "standing"])
def test_a_rough_ground_through_the_native_fmu_equals_the_library(name, method, fmus, scenes):
    fmu = fmus[name]
    t_end, n = RUNS[name]
    run = _library(scenes[name], t_end, n, method)
    names = _names(fmu)
    instance = Instance(fmu)
    instance.initialize(integrator=method)
    first = instance.get(names)
    rows, messages = instance.run(run.t, names)
    np.testing.assert_array_equal(np.vstack([first, rows]), _library_rows(run, names))
    scene = ln.load_scene(scenes[name])
    assert messages == [event_message(e, scene) for e in run.events]
    kinds = [_parse(message)[1] for message in messages]
    if name == "block":
        # it slides to a stop at v / (mu g), v^2 / (2 mu g) along its throw, and sticks there
        v, mu = BLOCK["v"], BLOCK["mu"]
        assert kinds == ["stick"] and messages[0].split(" of ")[1].startswith('mass 1 ("block")')
        assert abs(_parse(messages[0])[0] - v / (mu * G)) <= 1e-9
        distance = v * v / (2 * mu * G)
        np.testing.assert_allclose(rows[-1, :3], [0.6 * distance, 0.8 * distance, 0.0], rtol=0, atol=1e-9)
        assert not rows[:, names.index("Jground[1]")].any()  # no landing: the ground held it all along
    elif name == "standing":
        assert kinds == ["slip"] and 'slip of mass 1 ("base")' in messages[0]
    else:
        # the foot lands (its impulse in Jground[1]), the top lands later (Jground[2])
        assert kinds.count("contact") == 2
        J = rows[:, [names.index("Jground[1]"), names.index("Jground[2]")]]
        landings = [_parse(m) for m in messages if ": contact of " in m]
        np.testing.assert_array_equal(J.sum(axis=0), [impulse for _, _, impulse in landings])


def test_the_rod_dropped_onto_the_rough_ground_on_rattle_through_the_fmu_equals_the_library(fmus, scenes):
    # RATTLE at the FMU's default step (1e-3 s), chosen at initialization: the friction a force of its kicks, implicit
    # in the second (stages/rattle.c), the same doubles as the library's on the native backend
    fmu = fmus["rod"]
    t_end, n = RUNS["rod"]
    run = ln.simulate(scenes["rod"], t_end, "rattle", dt=1e-3, n_out=n + 1, error_estimate=False, backend="native")
    names = _names(fmu)
    instance = Instance(fmu)
    instance.initialize(integrator="rattle")
    rows, messages = instance.run(run.t, names)
    np.testing.assert_array_equal(rows, _library_rows(run, names)[1:])
    assert messages == [event_message(e, ln.load_scene(scenes["rod"])) for e in run.events]
    assert [_parse(m)[1] for m in messages].count("contact") == 2


def test_a_state_taken_mid_slide_repeats_the_run(fmus):
    """The block's state at 0.75 s, sliding 15 ms before its stop (its contact's slip reference set: the direction
    whose velocity's crossing of zero is the stop, which the step after the state takes from it), restored in the
    same instance and deserialized into another that has run past the stop (its contact stuck, no slip reference),
    gives the same outputs and the same stick event to the last bit."""
    fmu = fmus["block"]
    names = _names(fmu)
    t_end, n = RUNS["block"]
    times = np.linspace(0.0, t_end, n + 1)
    a = Instance(fmu, "a")
    a.initialize()
    mid = 15  # t = 0.75 s
    _, messages = a.run(times, names, 0, mid)
    assert messages == []
    at_state = a.get(names)
    speed = np.hypot(*at_state[3:5])  # sliding still: v - mu g t = 0.057 m/s
    assert abs(speed - (BLOCK["v"] - BLOCK["mu"] * G * times[mid])) <= 1e-9
    state = a.slave.getFMUstate()
    serialized = a.slave.serializeFMUstate(state)
    rows, messages = a.run(times, names, mid)
    assert [_parse(m)[1] for m in messages] == ["stick"]
    a.slave.setFMUstate(state)
    np.testing.assert_array_equal(a.get(names), at_state)
    again, messages_again = a.run(times, names, mid)
    np.testing.assert_array_equal(again, rows)
    assert messages_again == messages

    b = Instance(fmu, "b")
    b.initialize()
    b.run(times, names, 0, 20)  # t = 1.0 s: stopped, stuck
    b.slave.setFMUstate(b.slave.deSerializeFMUstate(serialized))
    np.testing.assert_array_equal(b.get(names), at_state)
    restored, restored_messages = b.run(times, names, mid)
    np.testing.assert_array_equal(restored, rows)
    assert restored_messages == messages
