"""Compositions driven by fmpy (examples/compositions): the PD feedback loop settles as the
controller predicts, and two networks coupled through a spring-damper FMU converge to the
monolithic library run at first order in the communication step."""
import numpy as np
import pytest

from fmu_harness import ROOT, run_client  # first: repo on sys.path

EXAMPLES = ROOT / "examples" / "compositions"


def _orders(steps, errs):
    return [np.log(errs[i] / errs[i + 1]) / np.log(steps[i] / steps[i + 1]) for i in range(len(steps) - 1)]


def test_pd_feedback_follows_the_closed_form_prediction_at_first_order(tmp_path):
    steps = [0.004, 0.002]
    out = run_client(f"""
sys.path.insert(0, {str(EXAMPLES)!r})
from pathlib import Path
import pd_feedback as pd
chain, ctrl = pd.build(Path({str(tmp_path)!r}))
runs = [pd.run(chain, ctrl, h, 1.5) for h in {steps!r}]
container = [pd.run_container(chain, ctrl, h, 1.5, Path({str(tmp_path)!r})) for h in {steps!r}]
save(container_error=np.array([r['max_error'] for r in container]),
     container_final=np.array([r['final_error'] for r in container]),
     max_error=np.array([r['max_error'] for r in runs]), final=np.array([r['final_error'] for r in runs]),
     lateral=np.array([r['lateral'] for r in runs]), z=runs[-1]['top'][:, 2], z_pred=runs[-1]['z_pred'],
     target=runs[-1]['target'])
""", tmp_path / "client_pd")
    order = _orders(steps, out["max_error"])[0]
    assert 0.9 < order < 1.1, order                      # zero-order-hold coupling: O(h)
    assert out["max_error"][-1] < 0.01 * 0.1             # < 1 % of the 0.1 m step at h = 2 ms
    assert np.all(out["lateral"] < 1e-12)                 # the vertical chain stays vertical
    overshoot = (out["z"].max() - out["target"][2]) / 0.1
    predicted = np.exp(-np.pi * 0.5 / np.sqrt(1 - 0.25))  # zeta = 0.5
    assert abs(overshoot - predicted) < 0.01
    assert out["final"][-1] < 1e-3                      # settled at the target
    # fmpy's container FMU (same explicit coupling) gives the same loop
    assert 0.9 < _orders(steps, out["container_error"])[0] < 1.1
    np.testing.assert_allclose(out["container_error"], out["max_error"], rtol=0.02)
    assert out["container_final"][-1] < 1e-3


@pytest.mark.parametrize("which,steps", [("master", [0.02, 0.01, 0.005]), ("ssp", [0.02, 0.01])])
def test_spring_damper_coupling_converges_to_monolithic_library_run(which, steps, tmp_path):
    out = run_client(f"""
sys.path.insert(0, {str(EXAMPLES)!r})
from pathlib import Path
import coupling as c
out = Path({str(tmp_path)!r})
fmus = c.build(out)
ref = c.monolithic_reference(1.0)
runs = [c.master(fmus, h, 1.0) if {which!r} == 'master' else c.ssp_master(fmus, h, 1.0, out) for h in {steps!r}]
save(errors=np.array([c.errors(r, ref) for r in runs]), moved=np.ptp(ref['xa'], axis=0))
""", tmp_path / f"client_coupling_{which}")
    errs = out["errors"]
    assert np.max(out["moved"]) > 0.5  # the coupled masses really move (swing under gravity)
    orders = _orders(steps, errs)
    print(f"{which}: errors {errs}, observed orders {orders}")
    assert all(0.85 < o < 1.15 for o in orders), orders
    assert errs[-1] < (5e-3 if which == "master" else 3e-2)


@pytest.mark.slow
def test_spring_damper_coupling_fine_steps(tmp_path):
    steps = [0.005, 0.0025, 0.00125]
    out = run_client(f"""
sys.path.insert(0, {str(EXAMPLES)!r})
from pathlib import Path
import coupling as c
fmus = c.build(Path({str(tmp_path)!r}))
ref = c.monolithic_reference(1.0)
save(errors=np.array([c.errors(c.master(fmus, h, 1.0), ref) for h in {steps!r}]))
""", tmp_path / "client_coupling_fine")
    orders = _orders(steps, out["errors"])
    assert all(0.9 < o < 1.1 for o in orders), orders
