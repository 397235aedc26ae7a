"""The pythonfmu FMU of a rope scene, run with fmpy, against ln.simulate of the same scene: the shipped crane whose
hoist rope goes slack when the trolley brakes. Its slack[l] outputs (0/1 Reals) at every communication point, the
impulse of each jerk in Jrope[l] of the step that holds it, one logged message per event."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from fmu_harness import FMU_CLIENT_LIB, MODELS, build_cached, run_client  # noqa: E402

import linknet_core as ln  # noqa: E402,I001


@pytest.mark.slow  # builds an FMU and runs it in a client process (~30 s)
def test_the_rope_crane_fmu_reports_slack_and_the_jerks_impulses_as_ln_simulate_does(tmp_path_factory):
    scene_path = str(MODELS / "ropes" / "rope_crane.json")
    fmu = build_cached(tmp_path_factory.mktemp("rope_fmu"), scene_path)
    t_end, h = 2.5, 0.01
    n = int(round(t_end / h))
    out = run_client(FMU_CLIENT_LIB + f"""
f = Fmu({str(fmu)!r})
f.init(start={{"tolerance": 1e-10}}, strings={{"integrator": "dop853"}})
names = ["X[2,1]", "X[2,3]", "T[1]", "slack[1]", "Jrope[1]"]
rows = [f.get(names)]
for i in range({n}):
    f.step(i * {h}, {h})
    rows.append(f.get(names))
save(rows=np.array(rows), messages=np.array([m for s, m in LOG if m.startswith("event at")]))
""", tmp_path_factory.mktemp("rope_client"))
    rows = out["rows"]
    run = ln.simulate(scene_path, t_end, "dop853", rtol=1e-10, n_out=n + 1, error_estimate=False)
    assert run.events, "the crane's rope should go slack and jerk taut"
    assert np.abs(rows[:, 0] - run.X[:, 1, 0]).max() < 1e-7 and np.abs(rows[:, 1] - run.X[:, 1, 2]).max() < 1e-7
    slack = rows[:, 3]
    assert set(np.unique(slack)) <= {0.0, 1.0}
    assert np.array_equal(slack.astype(bool), run.slack[:, 0])
    assert np.all(rows[slack == 1, 2] == 0.0)
    # each jerk's impulse in Jrope of the step that holds it, none elsewhere
    steps = np.arange(1, n + 1)
    expected = np.zeros(n)
    for event in run.events:
        if event.kind == "taut":
            expected[min(int(np.ceil(event.t / h - 1e-9)), n) - 1] += event.impulse
    assert np.allclose(rows[steps, 4], expected, rtol=1e-4, atol=1e-9)
    # one message per event, in the order of the library's events, with kind, link and impulse
    messages = [str(m) for m in out["messages"]]
    assert len(messages) == len(run.events)
    for message, event in zip(messages, run.events):
        assert f": {event.kind} of link 1 (trolley-load), impulse " in message
        assert float(message.split("impulse ")[1].split(" N s")[0]) == pytest.approx(event.impulse, rel=1e-4, abs=1e-9)
        assert abs(float(message.split("t=")[1].split(":")[0]) - event.t) < 1e-8
