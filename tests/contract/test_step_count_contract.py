"""Step counts: an advance that would take more fixed steps than can be counted or than the limit of one
advance is refused naming the span, dt, the count and the limit (the native core's rule and words,
ln_step_count_problem), by the library on both backends, the CLI in one line and both FMUs with fmi2Discard and a
logged message, the instance usable after; never 0 steps reported as done. An h below half an ulp of t is an
exact no-op (t + h == t: the FMU is at the master's t + h), fmi2OK from both FMUs alike."""
import subprocess
import sys

import numpy as np
import pytest

from contract_support import MODELS, ROOT, extract
from fmu_harness import FMU_CLIENT_LIB, build_cached, run_client
import linknet_core as ln
from linknet_core.integrators.base import MAX_STEP_COUNT
from linknet_core.clib.library import fixed_step_count

DISCARD = 2
PENDULUM = MODELS / "double_pendulum.json"


@pytest.mark.parametrize("span,dt", [(0.1, 1e-300), (1e17, 1e-3), (1e300, 1e-300), (1.0, 5e-324)])
def test_a_count_beyond_the_limit_is_more_than_the_limit_never_a_wrapped_number(span, dt):
    """(ln_int) of a ratio above 2^63 was INT64_MIN, a run of 0 steps; a ratio beyond 2^53, or not a number, counts
    as one more than the limit."""
    assert fixed_step_count(span, dt) == MAX_STEP_COUNT + 1
    assert fixed_step_count(1.0, 1e-3) == 1000 and fixed_step_count(float(2 ** 53), 1.0) == 2 ** 53


@pytest.mark.parametrize("backend", ["native", "numpy"])
@pytest.mark.parametrize("t_end,dt,count", [(1e17, 1e-3, "about 1e+20 steps"), (0.1, 1e-300, "about 1e+299 steps"),
                                            (1e4, 1e-4, "100000000 steps")])
def test_advance_refuses_a_span_of_too_many_steps_naming_span_dt_and_count(backend, t_end, dt, count):
    sim = ln.Simulator(ln.load_scene(PENDULUM), method="rattle", dt=dt, backend=backend, error_estimate=False,
                       max_steps_per_call=10 ** 7)
    X0 = sim.state.X.copy()
    with pytest.raises(ln.SolverError) as err:
        sim.advance(t_end)
    message = str(err.value)
    assert f"reaching t = {t_end:g} from t = 0" in message and f"takes {count} of dt = {dt:g}" in message, message
    assert "more than 10000000 steps, the limit of one advance" in message
    assert sim.state.t == 0.0 and np.array_equal(sim.state.X, X0)  # nothing done, nothing claimed
    sim.advance(10 * dt)  # and the simulator goes on
    assert sim.state.t == 10 * dt and sim.integrator.stats.as_dict()["steps"] == 10


def test_simulate_refuses_too_many_steps_rather_than_reporting_zero():
    with pytest.raises(ln.SolverError, match=r"takes about 5e\+298 steps of dt = 1e-300"):
        ln.simulate(ln.load_scene(PENDULUM), t_end=0.1, method="rattle", dt=1e-300, n_out=3)


def test_an_adaptive_advance_over_a_huge_span_stops_at_the_step_limit_with_the_reason():
    """Its count is not known before the steps: it runs to the limit of one advance and says so (the default limit,
    1e8 steps, takes minutes on a double pendulum; a small one here)."""
    sim = ln.Simulator(ln.load_scene(PENDULUM), method="dop853", rtol=1e-8, max_steps_per_call=1000)
    with pytest.raises(ln.SolverError, match=r"more than 1000 steps between t = 0.0 and t = 1e\+17"):
        sim.advance(1e17)
    assert sim.state.t == 0.0


@pytest.mark.parametrize("args", [["--t-end", "0.1", "--dt", "1e-300"], ["--t-end", "1e17", "--n-out", "2", "--dt", "1e-3"]])
def test_cli_refuses_too_many_steps_in_one_line_with_a_nonzero_exit(args):
    proc = subprocess.run([sys.executable, "-m", "linknet_core.cli", "simulate", str(PENDULUM), *args, "--no-progress"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert proc.returncode != 0 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("linknet simulate: error: reaching t = ") and proc.stderr.count("\n") == 1
    assert "steps of dt = " in proc.stderr and "steps = 0" not in proc.stdout


@pytest.mark.parametrize("native", [False, True], ids=["pythonfmu", "native"])
def test_fmus_discard_a_step_of_too_many_steps_with_a_message_and_treat_t_plus_h_equal_t_as_done(native, tmp_path):
    fmu = build_cached(tmp_path, str(MODELS / "pendulum.json"), integrator="rattle", step=1e-3, native=native)
    out = run_client(f"""
{FMU_CLIENT_LIB}
import json
from fmpy.fmi1 import FMICallException
f = Fmu({str(fmu)!r}); f.init()
names = f.names('X')
statuses, logs, moved = {{}}, {{}}, {{}}
def step(name, t, h):
    LOG.clear()
    before = f.get(names)
    try:
        f.step(t, h); statuses[name] = 0
    except FMICallException as e:
        statuses[name] = e.status
    logs[name] = [m for s, m in LOG]
    moved[name] = bool((f.get(names) != before).any())
step('first', 0.0, 0.01)
for h in (1e16, 1e17, 1e20, 1e300):
    step(f'h={{h:g}}', 0.01, h)
step('after', 0.01, 0.01)
step('sub-ulp', 0.02, 1e-18)
step('after sub-ulp', 0.02, 0.01)
save(result=np.array(json.dumps([statuses, logs, moved])))
""", tmp_path / "client")
    statuses, logs, moved = __import__("json").loads(str(out["result"]))
    for name in ("first", "after", "after sub-ulp"):
        assert statuses[name] == 0 and moved[name], (name, statuses[name], logs[name])
    for h in ("1e+16", "1e+17", "1e+20", "1e+300"):
        name = f"h={h}"
        assert statuses[name] == DISCARD and not moved[name], (name, statuses[name], logs[name])
        text = " ".join(logs[name])
        assert "reaching t = " in text and "steps of dt = 0.001: more than" in text and "limit of one advance" in text
    assert statuses["sub-ulp"] == 0 and not moved["sub-ulp"] and not logs["sub-ulp"]


@pytest.mark.parametrize("native", [False, True], ids=["pythonfmu", "native"])
def test_a_c_host_gets_discard_and_the_message_for_a_span_of_too_many_steps(native, exit_host, tmp_path):
    fmu = build_cached(tmp_path, str(MODELS / "pendulum.json"), integrator="rattle", step=1e-3, native=native)
    folder, ident, guid = extract(fmu, tmp_path / "unzipped")
    proc = subprocess.run([str(exit_host), str(folder), ident, guid, "span:1e17", "0"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0, proc.stderr
    assert "step 0\nspan step 2\nafter span step 0\n" in proc.stdout, proc.stdout
    assert "takes about 1e+20 steps of dt = 0.001: more than" in proc.stderr, proc.stderr


def test_free_rigid_bodies_refuse_too_many_steps_in_the_same_words():
    sim = ln.Simulator(ln.load_scene(MODELS / "spinning_tetrahedron.json"), method="yoshida4", dt=1e-3)
    assert sim.specialisation.kind == "rigid"
    with pytest.raises(ln.SolverError, match=r"takes about 1e\+20 steps of dt = 0.001: more than 100000000 steps"):
        sim.advance(1e17)
    assert sim.state.t == 0.0
