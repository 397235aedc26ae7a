"""Jrope and Jground across fmi2GetFMUstate / fmi2SetFMUstate, driven through fmpy: a state reports the impulses of
the step that led to it, as it did when it was taken, whichever instance or setup it is restored into, and a step
without a jerk reports none. The jerk's impulse itself against its closed form: the bob of the shipped rope
pendulum (m v_r at the root of |X(t)| = R, tests/ropes/rope_references.py) and a ball dropped onto a ground (m (1 +
e) sqrt(2 g h))."""
from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
from rope_references import G, BobReference

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fmu_harness import FMU_CLIENT_LIB, MODELS, build_cached, run_client  # noqa: E402

DROP_HEIGHT, RESTITUTION, BALL_MASS = 1.0, 0.5, 2.0


def pendulum(_folder: Path):  # the shipped scene: nothing to write
    scene = json.loads((MODELS / "ropes" / "rope_pendulum.json").read_text())
    bob = scene["masses"][1]
    reference = BobReference(bob["position"], bob["velocity"], scene["links"][0]["length"], 1.0, bob["mass"])
    t, kind, impulse = reference.events[0]
    assert kind == "taut" and 0.4 < t < 0.5  # one jerk in the step [0, 0.5], none in [0, 0.4] or [0.5, 0.55]
    return str(MODELS / "ropes" / "rope_pendulum.json"), "Jrope[1]", impulse


def dropped_ball(folder: Path):
    path = folder / "dropped_ball.json"
    path.write_text(json.dumps({
        "name": "dropped_ball", "gravity": [0, 0, -G],
        "masses": [{"name": "ball", "position": [0, 0, DROP_HEIGHT], "mass": BALL_MASS}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": RESTITUTION}}))
    # it lands at sqrt(2 h / g) = 0.4515 s and flies 2 e v / g = 0.4515 s before the next landing
    return str(path), "Jground[1]", BALL_MASS * (1 + RESTITUTION) * np.sqrt(2 * G * DROP_HEIGHT)


@pytest.mark.parametrize("make", [pendulum, dropped_ball], ids=["rope", "ground"])
def test_a_restored_state_reports_the_impulses_of_the_step_that_led_to_it(make, tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmu_state_impulses")
    scene_path, name, impulse = make(folder)
    fmu = build_cached(folder, scene_path)
    out = run_client(FMU_CLIENT_LIB + f"""
J = [{name!r}]
f = Fmu({str(fmu)!r})
f.init(start={{"tolerance": 1e-10}}, strings={{"integrator": "dop853"}})
at_start = f.slave.getFMUstate()
f.step(0.0, 0.5)
jerk = f.get(J)[0]                                   # the step that holds the jerk
after_jerk = f.slave.getFMUstate()
saved = f.slave.serializeFMUstate(after_jerk)
f.slave.setFMUstate(at_start)
restored_start = f.get(J)[0]                         # the state at the start: no step taken
f.step(0.0, 0.4)
without_jerk = f.get(J)[0]                           # a step without a jerk
f.slave.setFMUstate(after_jerk)
restored_jerk = f.get(J)[0]
f.step(0.5, 0.05)
next_step = f.get(J)[0]
other = Fmu({str(fmu)!r}, name="other", unzipdir=f.unzipdir)
other.init(start={{"step": 0.01}}, strings={{"integrator": "rattle"}})
other.step(0.0, 0.3)
other.slave.setFMUstate(other.slave.deSerializeFMUstate(saved))
into_other_setup = other.get(J)[0]                   # restored into an instance with another method
f.slave.reset()
f.init(start={{"tolerance": 1e-8}}, strings={{"integrator": "dop853"}})
f.slave.setFMUstate(after_jerk)
after_reset = f.get(J)[0]                            # and after fmi2Reset, with another tolerance
save(values=np.array([jerk, restored_start, without_jerk, restored_jerk, next_step, into_other_setup,
                      after_reset]))
""", folder / "client")
    jerk, restored_start, without_jerk, restored_jerk, next_step, into_other_setup, after_reset = out["values"]
    assert jerk == pytest.approx(impulse, rel=1e-8)
    assert restored_start == 0.0 and without_jerk == 0.0 and next_step == 0.0
    assert restored_jerk == jerk and into_other_setup == jerk and after_reset == jerk
