"""A master that retries a discarded step as it was (fmpy's simulate_fmu, fmusim) ends, and its user reads why in
the log. fmpy retries a discarded step with the same size for as long as fmi2GetBooleanStatus(fmi2Terminated) is
false; the native FMU answered false after every discard, so fmpy never ended (fmusim wrote 895 MB so).

Now, after a discard:
* where no retry of the step can succeed, however short (a fixed step that still fails at the split bound, a
  projection of the driven anchors' jump to new inputs that stalls at the conditioning floor, with a fixed-step and
  an error-controlled integrator), the native FMU reports
  fmi2Terminated = true at once, fmi2LastSuccessfulTime = the time it stayed at, and logs why: fmpy calls fmi2DoStep
  once;
* where a shorter step can succeed (a span of more fixed steps than one advance takes), fmi2Terminated stays false,
  and a shorter step goes on; the very same step asked again with nothing set or restored in between fails the
  same way, so it is answered fmi2Discard without being computed, with fmi2Terminated = true and the reason: fmpy
  calls fmi2DoStep twice.
The pythonfmu FMU's front layer answers fmi2Terminated the second way for every discard (it cannot tell which
failures no shorter step fixes), so fmpy ends there after the repeat, where pythonfmu 0.7.0 itself answered true
after any discard.

fmpy runs in a subprocess with a time limit (tests/fmu_harness.run_client): a master that does not end fails the
test instead of hanging it."""
from __future__ import annotations

import json

import numpy as np
import pytest

from fmu_harness import FMU_CLIENT_LIB, run_client
from native_fmu_support import MODELS, built
from test_native_fmu_failures import PULLED_TO, mass_ratio_chain, taut_string

TIME_LIMIT = 120  # seconds for a client that ends after one or two steps

# case -> the scene (a models/ name or a builder), build options, the step fmpy takes, start values of inputs,
# words of the discard's reason, and whether the native FMU knows at once that no retry can succeed
CASES = {
    "split_bound": (mass_ratio_chain, dict(integrator="rattle", step=1e-4), 0.01, {},
                    "the step exceeds the stability limit of explicit steps", True),
    "anchor_jump_at_floor": (taut_string, dict(integrator="rattle", step=1e-3), 0.01, {"P[3,1]": PULLED_TO},
                             "it stalls at the floor this configuration allows", True),
    "anchor_jump_at_floor_adaptive": (taut_string, dict(integrator="dop853"), 0.01, {"P[3,1]": PULLED_TO},
                                      "it stalls at the floor this configuration allows", True),
    "too_many_steps": ("pendulum", dict(integrator="rattle", step=1e-3), 1e17, {},
                       "advance over intervals of at most 100000 s", False),
}
FINAL = "No retry of this step can succeed, however short"
TERMINATED = "fmi2Terminated is true (fmi2LastSuccessfulTime = 0)"
REPEATED = "was discarded before, from this same state with these same inputs, so it fails again the same way"


@pytest.fixture(scope="module")
def scene_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("terminate_scenes")
    files = {}
    for name, (scene, *_rest) in CASES.items():
        if isinstance(scene, str):
            files[name] = MODELS / f"{scene}.json"
        else:
            files[name] = folder / f"{name}.json"
            files[name].write_text(json.dumps(scene().to_dict()))
    return files


@pytest.mark.parametrize("native", [True, False], ids=["native", "pythonfmu"])
@pytest.mark.parametrize("case", list(CASES))
def test_fmpy_simulate_fmu_ends_on_a_failing_step_and_logs_why(case, native, scene_files, fmu_root, tmp_path):
    _scene, options, h, start, reason, known_final = CASES[case]
    fmu = built(fmu_root, scene_files[case], native=native, **options)
    out = run_client(f"""
import json
import fmpy
LOG, CALLS = [], []
def logger(env, instance, status, category, message):
    LOG.append((int(status), message.decode("utf-8", "replace")))
result = fmpy.simulate_fmu({str(fmu.path)!r}, stop_time={2 * h!r}, output_interval={h!r}, start_values={start!r},
                           logger=logger, fmi_call_logger=CALLS.append)
save(t=result["time"], log=np.array(json.dumps(LOG)),
     steps=np.array(json.dumps([c for c in CALLS if c.startswith("fmi2DoStep(")])))
""", tmp_path, timeout=TIME_LIMIT)
    steps = json.loads(str(out["steps"]))
    log = [message for status, message in json.loads(str(out["log"])) if status == 2]  # fmi2Discard
    final_at_once = native and known_final
    assert len(steps) == (1 if final_at_once else 2) and all(s.endswith("-> DISCARD") for s in steps), steps
    assert out["t"].size >= 1 and np.all(out["t"] == 0.0)  # stopped where the FMU stayed: its last good time
    assert len(log) == len(steps) and reason in log[0], log
    if final_at_once:
        assert FINAL in log[0] and TERMINATED in log[0], log[0]
    else:
        assert FINAL not in log[0] and "fmi2Terminated" not in log[0], log[0]
        assert TERMINATED in log[1] and REPEATED in log[1] and reason in log[1], log[1]  # the repeat says why too


@pytest.mark.parametrize("native", [True, False], ids=["native", "pythonfmu"])
def test_a_retry_with_a_shorter_step_or_other_inputs_goes_on(native, fmu_root, tmp_path):
    """fmi2Terminated stays false where a shorter step can succeed, and a master that takes one goes on; the same
    step asked again from the same state makes it true and is not computed again; other inputs make the step worth
    computing again. A restored state that is the one the step failed from: the native FMU compares the model's
    state and knows the step fails again; the pythonfmu FMU's front, which cannot compare pythonfmu's states,
    computes it again."""
    fmu = built(fmu_root, "pendulum", native=native, integrator="rattle", step=1e-3)
    out = run_client(f"""
{FMU_CLIENT_LIB}
from fmpy.fmi2 import fmi2Terminated, fmi2LastSuccessfulTime
f = Fmu({str(fmu.path)!r}); f.init()
s = f.slave
seen = []
def attempt(t, h):
    LOG.clear()
    try:
        s.doStep(t, h); status = 0
    except FMICallException as e:
        status = e.status
    discards = [m for st, m in LOG if st == 2]
    seen.append((status, bool(s.getBooleanStatus(fmi2Terminated)), s.getRealStatus(fmi2LastSuccessfulTime),
                 len(discards), sum({REPEATED!r} in m for m in discards)))
attempt(0.0, 1e17)      # too many fixed steps: a shorter step can succeed
attempt(0.0, 1e17)      # the same again: known to fail
attempt(0.0, 0.01)      # shorter: goes on
state = s.getFMUstate()
attempt(0.01, 1e17)
s.setFMUstate(state)    # back to the state that step failed from
attempt(0.01, 1e17)
f.set({{'F[2,3]': 1.0}})
attempt(0.01, 1e17)     # other inputs: computed again (and fails again)
attempt(0.01, 1e17)     # the same again
save(seen=np.array(seen, dtype=float))
""", tmp_path, timeout=TIME_LIMIT)
    # per attempt: status, fmi2Terminated, fmi2LastSuccessfulTime, discard messages logged, of them repeats
    restored = (2, True, 0.01, 1, 1) if native else (2, False, 0.01, 1, 0)
    expected = [(2, False, 0.0, 1, 0), (2, True, 0.0, 1, 1), (0, False, 0.01, 0, 0), (2, False, 0.01, 1, 0), restored,
                (2, False, 0.01, 1, 0), (2, True, 0.01, 1, 1)]
    got = [(int(a), bool(b), c, int(d), int(e)) for a, b, c, d, e in out["seen"]]
    assert len(got) == len(expected)
    for i, (g, e) in enumerate(zip(got, expected)):  # pythonfmu's last successful time is t + h as it added them
        assert g[:2] == e[:2] and abs(g[2] - e[2]) <= 1e-15 and g[3:] == e[3:], (i, got)
