"""Bad input gives fmi2Error (a step that cannot be taken fmi2Discard) with a logged message naming the variable,
never fmi2Fatal or a crash, and the instance stays usable (or is usable again after fmi2Reset).
Any communication step h > 0 works, down to 1e-13 s."""
import numpy as np
import pytest

from fmu_harness import FMU_CLIENT_LIB, MODELS, build_cached, run_client  # first: repo on sys.path
import linknet_core as ln


@pytest.fixture(scope="module")
def fmu_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fmus_err")


def test_bad_inputs_are_refused_with_named_messages_and_the_instance_recovers(fmu_dir):
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"), step=1e-3)
    out = run_client(f"""
{FMU_CLIENT_LIB}
import json
cases = {{}}
def attempt(label, f, t, h):
    '''doStep; record the status and the log lines it produced'''
    LOG.clear()
    try:
        f.step(t, h)
        status = 0
    except FMICallException as e:
        status = e.status
    cases[label] = dict(status=status, log=[m for s, m in LOG], log_status=[s for s, m in LOG])
    return status

f = Fmu({str(fmu)!r})
f.init()
t = 0.0
attempt('ok', f, t, 0.01); t += 0.01
for bad in (float('nan'), float('inf')):
    LOG.clear()
    try:
        f.set({{'F[11,3]': bad}}); set_status = 0
    except FMICallException as e:
        set_status = e.status
    set_log = list(LOG)
    attempt(f'force {{bad}}', f, t, 0.01)
    cases[f'force {{bad}}'].update(set_log=[m for s, m in set_log], set_status=set_status)
f.set({{'F[11,3]': 1.0}})
attempt('after good force', f, t, 0.01); t += 0.01
attempt('zero step', f, t, 0.0)
attempt('negative step', f, t, -0.01)
attempt('wrong time', f, t + 0.5, 0.01)
attempt('tiny step', f, t, 1e-13); t += 1e-13
attempt('normal again', f, t, 0.01); t += 0.01
LOG.clear()
try:
    f.set({{'M[3]': 2.0}})                  # fixed parameter after initialization
except FMICallException:
    pass
attempt('fixed parameter after init', f, t, 0.01)
f.set({{'F[11,3]': 1e300}})
f.slave.reset(); f.init()               # reset clears everything
t = 0.0
attempt('after reset', f, t, 0.01); t += 0.01
f.set({{'F[11,3]': 1e300}})                 # finite but absurd: the solver cannot continue
attempt('absurd force', f, t, 0.01)
f.set({{'F[11,3]': 0.0}})
f.slave.reset(); f.init()
attempt('after second reset', f, 0.0, 0.01)

g = Fmu({str(fmu)!r}, 'g')                 # parameters out of range before initialization
g.slave.setupExperiment(startTime=0.0)
g.slave.enterInitializationMode()
LOG.clear()
param_status = []
for set_bad in (lambda: g.set({{'M[2]': -1.0, 'step': 0.0}}),
                lambda: g.slave.setString([g.vr['integrator']], ['euler'])):
    try:
        set_bad(); param_status.append(0)
    except FMICallException as e:
        param_status.append(e.status)
param_log = [m for s, m in LOG]
g.slave.exitInitializationMode()
attempt('bad parameters', g, 0.0, 0.01)
cases['bad parameters'].update(set_log=param_log, set_status=max(param_status))
g.slave.reset(); g.init()
attempt('bad parameters then reset', g, 0.0, 0.01)

k = Fmu({str(fmu)!r}, 'k')                 # a link length the initial positions violate
try:
    k.init(start={{'R[1]': 0.5}}); init_status = 0
except FMICallException as e:                # fmi2ExitInitializationMode: no valid scene
    init_status = e.status
attempt('inconsistent length', k, 0.0, 0.01)
cases['inconsistent length']['set_status'] = init_status
k.slave.reset(); k.init(start={{'M[3]': 0.2, 'g[3]': -1.62}})
attempt('valid parameters', k, 0.0, 0.01)
save(cases=np.array(json.dumps(cases)))
""", fmu_dir / "client_errors")
    import json
    cases = json.loads(str(out["cases"]))
    DISCARD, ERROR = 2, 3

    def refused(label, *words, status=DISCARD):
        c = cases[label]
        assert c["status"] == status, (label, c)
        assert c.get("set_status", ERROR) == ERROR, (label, c)  # the bad value itself: fmi2Error
        text = " ".join(c["log"] + c.get("set_log", []))
        for w in words:
            assert w in text, (label, w, text)
        assert 4 not in c["log_status"]  # never fmi2Fatal

    for label in ("ok", "after good force", "tiny step", "normal again", "after reset",
                  "after second reset", "bad parameters then reset", "valid parameters"):
        assert cases[label]["status"] == 0, (label, cases[label])
    refused("force nan", "F[11,3]", "finite")
    refused("force inf", "F[11,3]", "finite")
    refused("zero step", "h=0.0", "> 0", status=ERROR)
    refused("negative step", "h=-0.01", status=ERROR)
    refused("wrong time", "currentCommunicationPoint", status=ERROR)
    refused("fixed parameter after init", "M[3]", "after initialization")
    refused("absurd force", "doStep")
    refused("bad parameters", "M[2]", "> 0", "step", "integrator", "euler")
    refused("inconsistent length", "link 1", "length", status=ERROR)


def test_variable_and_tiny_communication_steps_match_library(fmu_dir):
    fmu = build_cached(fmu_dir, str(MODELS / "double_pendulum.json"), integrator="dop853", tolerance=1e-10)
    steps = [0.05, 1e-13, 0.02, 1e-13, 1e-13, 0.1, 1e-17, 0.003, 1e-9, 0.2]  # 1e-17: t + h == t
    out = run_client(f"""
{FMU_CLIENT_LIB}
f = Fmu({str(fmu)!r})
f.init()
t = 0.0
for h in {steps!r}:
    f.step(t, h); t += h
save(X=f.get(f.names('X')), T=f.get(f.names('T')), t=t)
""", fmu_dir / "client_steps")
    sim = ln.Simulator(ln.load_scene(MODELS / "double_pendulum.json"), method="dop853", rtol=1e-10)
    t = 0.0
    for h in steps:
        if t + h > t:
            sim.advance(t + h)
        t += h
    np.testing.assert_allclose(out["X"], sim.state.X.ravel(), rtol=0, atol=1e-13)
    np.testing.assert_allclose(out["T"], sim.outputs()["T"], rtol=1e-12, atol=1e-12)


def test_setting_every_force_input_in_one_call_matches_library_and_a_bad_entry_is_refused(fmu_dir):
    """A master that connects every force input sets them all in one fmi2SetReal per step (the slave's
    array fast path, remembering the checked list of value references). Same forces in the library: same
    trajectory. A NaN inside such a call, or an output's value reference in it, still gets the checks."""
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"), step=1e-3)
    out = run_client(f"""
{FMU_CLIENT_LIB}
f = Fmu({str(fmu)!r})
f.init()
names = f.names('F')
t, h, X = 0.0, 0.01, []
for n in range(20):
    f.set({{name: 0.3 * np.sin(7 * t + j) for j, name in enumerate(names)}})
    f.step(t, h); t += h
    X.append(f.get(f.names('X')))
LOG.clear()
values = {{name: 0.0 for name in names}}
values[names[5]] = float('nan')
try:
    f.set(values); nan_set_status = 0
except FMICallException as e:
    nan_set_status = e.status
try:
    f.step(t, h); nan_status = 0
except FMICallException as e:
    nan_status = e.status
nan_log = [m for s, m in LOG]
LOG.clear()
try:
    f.slave.setReal([f.vr[names[0]], f.vr['X[3,1]']], [0.0, 5.0])   # an input and an output in one call
except FMICallException:
    pass
mixed_log = [m for s, m in LOG]
f.set({{name: 0.0 for name in names}})
f.step(t, h)
LOG.clear()
long_read = [f.vr[n] for n in f.names('X')]      # more than 16: the remembered-list path of get_real
try:
    bad_read = np.array(f.slave.getReal(long_read + [10**6]))
except FMICallException:
    bad_read = np.array([np.nan])
bad_read_log = [m for s, m in LOG]
save(X=np.array(X), nan_status=nan_status, nan_set_status=nan_set_status, nan_log=np.array(nan_log), mixed_log=np.array(mixed_log),
     names=np.array(names), bad_read=bad_read, bad_read_log=np.array(bad_read_log),
     good_read=np.array(f.slave.getReal(long_read)), X_last=f.get(f.names('X')))
""", fmu_dir / "client_all_inputs")
    scene = ln.load_scene(MODELS / "chain_10.json")
    names = list(out["names"])
    sim = ln.Simulator(scene, method="rattle", dt=1e-3)
    t, X = 0.0, []
    for n in range(20):
        F = np.zeros((scene.K, 3))
        for j, name in enumerate(names):          # F[k,i], 1-based
            k, i = (int(v) for v in name[2:-1].split(","))
            F[k - 1, i - 1] = 0.3 * np.sin(7 * t + j)
        sim.advance(t + 0.01, F)
        t += 0.01
        X.append(sim.state.X.ravel().copy())
    np.testing.assert_allclose(out["X"], np.array(X), rtol=0, atol=1e-12)
    assert np.ptp(np.array(X)[:, -1]) > 1e-3      # the forces moved the chain
    assert out["nan_set_status"] == 3 and out["nan_status"] == 2  # fmi2Error, then the step fmi2Discard
    assert any(names[5] in m and "finite" in m for m in out["nan_log"])
    assert any("X[3,1]" in m and "output" in m for m in out["mixed_log"])
    # a long read with an unknown value reference is refused (NaNs and a message), the next read is right
    assert np.all(np.isnan(out["bad_read"]))
    assert any("unknown value reference" in m for m in out["bad_read_log"])
    np.testing.assert_array_equal(out["good_read"], out["X_last"])
