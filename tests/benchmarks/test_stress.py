"""Fast cases of the numerical-stability stress suite (benchmarks/stress.py, quick sizes).

Each case measures physics against an independent yardstick (analytic motion, rigid-body reference, the
index-1 reference written from the seed, conservation) and states its criterion; these tests assert the
criteria and a few of the measured figures directly. The full sizes (pendulum 2000 s, chain_100 for 1e6
RATTLE steps, chain_100 whip, 100 x 100 net, 100000-link chain) run in `python -m benchmarks.stress`.
"""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

# the benchmarks package lives at the repository root, beside tests/ (pytest run from anywhere)
sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

pytest.importorskip("linknet_core")

from benchmarks import stress  # noqa: E402


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
def test_mass_ratios_stay_rigid_and_correct():
    c = stress.case_mass_ratios(quick=True)
    for name, m in c["measured"].items():
        # every chain has an independent reference, verified by two resolutions agreeing to 1e-9 m
        assert m["reference"]["verified"] and m["reference"]["agreement_m"] <= 1e-9, (name, m["reference"])
        d = m["dop853"]
        if name == "graded_up" and d["outcome"] == "stopped":   # stiff: may stop, but only with a SolverError
            assert d["message"].startswith("SolverError")
            continue
        assert d["outcome"] == "completed", (name, m)
        assert d["max_residual"] <= 1e-10 and d["tensions_finite"], (name, d)
        # the step controller reported success: the answer must be within its stated bound
        assert d["error_vs_reference_m"] <= 1e-5, (name, d)
    assert c["passed"], c


def test_redundant_networks_have_unique_forces_and_minimum_norm_tensions():
    c = stress.case_redundant(quick=True)
    m = c["measured"]
    assert m["redundant_truss"]["self_stresses"] == 6
    assert m["swinging_truss"]["self_stresses"] > 0
    assert m["swinging_truss"]["error_vs_rigid_pendulum_m"] <= 1e-7
    assert c["passed"], c


def test_singular_passages_continue_correctly_or_stop_clearly():
    c = stress.case_singular(quick=True)
    m = c["measured"]
    assert m["taut_string_moving"]["outcome"] == "refused"
    # its weight across the straight string: refused at the start, naming the string's links
    for method in ("rattle", "dop853"):
        v = m[f"taut_string_gravity_{method}"]
        assert v["outcome"] == "refused" and "links 1 and 2 are a straight string" in v["message"], v
    for key, v in m.items():
        assert v["outcome"] in ("continued", "stopped", "refused"), (key, v)
        if v["outcome"] == "stopped":
            # the message names the links involved, or the conditioning floor the projection kept stopping at
            assert "link" in v["message"] and ("link " in v["message"] or "conditioning floor" in v["message"]), (key, v)
    assert c["passed"], c


def test_long_runs_have_bounded_energy_and_rigid_links():
    c = stress.case_long_runs(quick=True)
    for name, m in c["measured"].items():
        assert m["max_residual"] <= 1e-12, (name, m)
    assert c["passed"], c


def test_whip_peaks_converge_with_tolerance():
    c = stress.case_whip(quick=True)
    conv = c["measured"]["relative_change_between_successive_rtols"]
    assert conv["peak_tip_speed_m_s"][-1] <= 1e-3, conv
    assert conv["peak_tension_N"][-1] <= 1e-3, conv
    assert c["passed"], c


def test_scale_runs_and_memory_is_linear_for_chains():
    c = stress.case_scale(quick=True)
    for key, m in c["measured"].items():
        if key.startswith(("net_", "chain_")) and isinstance(m, dict):
            assert "failed_with" not in m, (key, m)
            assert m["finite"] and m["residual"] <= 1e-10, (key, m)
    assert c["passed"], c
