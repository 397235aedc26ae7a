"""Chains of 10 links whose masses span 1e3 .. 1e12 (geometric along the chain; light next to the anchor or at the
tip), released horizontal under gravity. A light mass between tensioned links swings across them at
omega ~ sqrt(T / (m R)); an explicit step (RATTLE, its compositions) follows that only below h omega ~ 2. Beyond
it the run fails, and the failure says so and gives a step: at that step (after at most a few rounds, since omega
grows with the tensions as the chain falls) the run goes through, agrees with dop853, and its statistics report
the projection's floor."""
import re

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics.equations import fastest_oscillation
from linknet_core.tolerances import FLOOR_CAP_OVER_TOL
from linknet_core.errors import STABILITY_LIMIT
from linknet_core.scene import builders

T_END = 0.05
ADVICE = re.compile(r"use dt below ([0-9.e+-]+) s")


def chain(ratio, light_at_anchor):
    masses = np.geomspace(1 / np.sqrt(ratio), np.sqrt(ratio), 11)  # the first entry is the anchor's (unused)
    return builders.chain(10, total_length=1.0, masses=masses if light_at_anchor else masses[::-1])


def test_the_estimate_is_the_stability_limit_of_a_hanging_chain():
    """At rest the tensions are constant and the estimate is sharp: RATTLE runs at h omega = 1.9 and fails at 2.1
    (a light mass next to the anchor, nudged sideways)."""
    scene = builders.chain(10, total_length=1.0, masses=np.geomspace(1e-6, 1e6, 11), shape="hanging")
    sim = ln.Simulator(scene, method="rattle", backend="native", dt=1e-3)
    omega = fastest_oscillation(scene, sim.integrator.tensions(sim.state.X, sim.state.U))
    for h_omega, runs in ((1.9, True), (2.1, False)):
        sim = ln.Simulator(scene, method="rattle", backend="native", dt=h_omega / omega)
        U = sim.state.U.copy()
        U[1, 0] = 1e-9
        sim.state.U = U
        if runs:
            sim.advance(2000 * h_omega / omega)
        else:
            with pytest.raises(ln.SolverError, match="stability limit of explicit steps"):
                sim.advance(2000 * h_omega / omega)


@pytest.mark.parametrize("light_at_anchor", [True, False], ids=["light_at_anchor", "heavy_at_anchor"])
@pytest.mark.parametrize("ratio", [1e3, 1e6, 1e9, 1e12])
def test_a_step_beyond_the_limit_fails_saying_so_and_its_advice_runs(ratio, light_at_anchor):
    """The advice's first remedy, the error-controlled default, runs at the first retry. Its fixed-step remedy is
    taken at omega read where the failing step started, and omega grows about in proportion to time as the chain
    loads up from rest (9.2e4 rad/s at 5 ms, 7.6e5 at 50 ms for ratio 1e12), so each dt it advises carries the run
    further before the next failure: how many rounds that takes depends on round-off (the run near the limit is
    chaotic; 1e12: 5 to 7 rounds on the native core, 2 on the numpy reference), so the loop allows 10."""
    scene = chain(ratio, light_at_anchor)
    dt, failures = 0.03, []
    for _ in range(10):
        try:
            result = ln.simulate(scene, T_END, method="rattle", dt=dt, backend="native", n_out=2)
            break
        except ln.SolverError as e:
            message = str(e)
            assert "stability limit of explicit steps" in message and "cannot help" not in message, message
            if not failures:
                assert "Use dop853 (the default" in message, message
                default = ln.simulate(scene, T_END, backend="native", n_out=2)  # the first remedy, at once
                assert default.method == "dop853"
            h_omega = float(re.search(r"h omega = ([0-9.e+-]+),", message).group(1))
            assert h_omega > STABILITY_LIMIT / 4, message
            advised = float(ADVICE.search(message).group(1))
            assert advised < dt, message
            failures.append(dt)
            dt = advised
    else:
        pytest.fail(f"still failing after following the advice: steps {failures}")
    # the chain is stiff only with its light masses next to the anchor, holding the heavy ones' weight
    assert bool(failures) == (light_at_anchor and ratio >= 1e6), failures
    reference = ln.simulate(scene, T_END, method="dop853", rtol=1e-8, backend="native", n_out=2)
    assert np.abs(result.X[-1] - reference.X[-1]).max() < 1e-3  # 1 % of a link; the chain falls 1.2 cm
    for run in (result, reference):
        stops, reached = run.stats["floor_stops"], run.stats["floor_reached"]
        assert (stops > 0) == (reached > 0) and reached <= FLOOR_CAP_OVER_TOL * 1e-14
        assert run.residual[-1] <= max(1e-12, 2 * reached)


def test_both_paths_give_the_stability_advice():
    """The numpy reference and the native core, RATTLE and a composition (whose largest stage sets h)."""
    scene = chain(1e12, True)
    for backend, method, dt in (("numpy", "rattle", 1e-4), ("native", "rattle", 1e-4), ("native", "yoshida4", 1e-3)):
        sim = ln.Simulator(scene, method=method, backend=backend, dt=dt)
        with pytest.raises(ln.SolverError) as failure:
            sim.advance(T_END)
        message = str(failure.value)
        assert "stability limit of explicit steps" in message and ADVICE.search(message), (backend, method, message)
        assert ("largest stage" in message) == (method != "rattle"), message


def test_a_run_that_stops_at_the_floor_reports_it():
    """yoshida4 at dt 1e-4 on the 1e12 chain runs on split steps (its stages are beyond the limit at full length),
    and a few of its projections stop at the floor the conditioning allows, just above the 1e-14 tolerance: the
    run's statistics and summary say how often and how far."""
    result = ln.simulate(chain(1e12, True), T_END, method="yoshida4", dt=1e-4, backend="native", n_out=2)
    stops, reached = result.stats["floor_stops"], result.stats["floor_reached"]
    assert stops > 0 and 1e-14 < reached <= FLOOR_CAP_OVER_TOL * 1e-14
    assert result.residual[-1] <= 2 * reached
    assert f"{stops} position projections stopped at the round-off floor" in result.summary()
