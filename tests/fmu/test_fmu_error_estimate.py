"""Both FMU kinds say when their error estimate exceeds the run's goal: once per crossing, with fmi2Warning status in
the category logErrorEstimate, in the library's words (Simulator.error_note), while every doStep returns fmi2OK; the
estimate equals the library's. A pendulum on RATTLE at a coarse step crosses the goal within a few steps."""
import numpy as np
import pytest

from fmu_harness import MODELS, build_cached, run_client  # first: repo on sys.path
import linknet_core as ln

STEP, H, N = 0.01, 0.01, 40


@pytest.mark.parametrize("native", [False, True], ids=["pythonfmu", "native"])
def test_a_crossing_of_the_goal_is_logged_once_and_the_steps_stay_ok(native, tmp_path_factory):
    fmu = build_cached(tmp_path_factory.mktemp("fmus_estimate"), str(MODELS / "pendulum.json"), step=STEP,
                       native=native)
    out = run_client(f"""
from fmpy import read_model_description, extract
from fmpy.fmi2 import FMU2Slave, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, defaultCallbacks
LOG = []
def _log(env, instance, status, category, message):
    LOG.append((int(status), category.decode(), message.decode()))
cb = fmi2CallbackFunctions()
cb.logger = fmi2CallbackLoggerTYPE(_log)
cb.allocateMemory, cb.freeMemory = defaultCallbacks.allocateMemory, defaultCallbacks.freeMemory
md = read_model_description({str(fmu)!r})
vr = {{v.name: v.valueReference for v in md.modelVariables}}
s = FMU2Slave(guid=md.guid, unzipDirectory=extract({str(fmu)!r}), modelIdentifier=md.coSimulation.modelIdentifier,
              instanceName='estimate')
s.instantiate(callbacks=cb, loggingOn=False)   # the note reaches the host with logging off
s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
status, estimate, notes = [], [s.getReal([vr['error_estimate']])[0]], []
for n in range({N}):
    del LOG[:]
    status.append(int(s.fmi2DoStep(s.component, n * {H!r}, {H!r}, 1)))
    estimate.append(s.getReal([vr['error_estimate']])[0])
    notes.append(' | '.join(f'{{st}} {{cat}} {{m}}' for st, cat, m in LOG))
save(status=np.array(status), estimate=np.array(estimate), notes=np.array(notes))
""", tmp_path_factory.mktemp("client_estimate"))
    assert (out["status"] == 0).all(), out["status"]  # fmi2OK throughout
    sim = ln.Simulator(ln.load_scene(MODELS / "pendulum.json"), method="rattle", dt=STEP)
    library, notes = [sim.error_estimate], []
    for n in range(N):
        sim.advance((n + 1) * H)
        library.append(sim.error_estimate)
        notes.append(sim.error_note())
    np.testing.assert_allclose(out["estimate"], library, rtol=0, atol=1e-12)  # round-off of 1 m positions
    over = np.array(library[1:]) > sim.error_goal
    assert over[-1] and not over[0]  # the run crosses its goal
    for n, logged in enumerate(out["notes"]):
        first = over[n] and (n == 0 or not over[n - 1])
        if first:  # fmi2Warning in its category, the library's words (the native glue names its function first)
            assert logged.startswith("1 logErrorEstimate ") and logged.endswith(notes[n]), (n, logged, notes[n])
            assert "fmi2DoStep: " + notes[n] in logged if native else logged == "1 logErrorEstimate " + notes[n]
        else:
            assert logged == "", (n, logged)
