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


def test_component_fmus_follow_their_laws_and_refuse_bad_parameters(tmp_path):
    """The spring-damper FMU gives linknet_core's spring force (forces.element_forces) and the PD
    FMU its control law, for random arguments; bad parameters are refused by name."""
    from fmu_harness import build_cached, FMU_CLIENT_LIB
    import linknet_core as ln
    from linknet_core.dynamics.forces import element_forces

    spring = build_cached(tmp_path, "spring_damper")
    pd = build_cached(tmp_path, "pd_controller")
    rng = np.random.default_rng(1)
    args = rng.normal(size=(5, 12))
    out = run_client(f"""
{FMU_CLIENT_LIB}
args = np.array({args.tolist()!r})
s = Fmu({str(spring)!r}, 'spring'); s.init(start=dict(stiffness=20.0, rest_length=0.7, damping=0.3))
p = Fmu({str(pd)!r}, 'pd'); p.init(start={{'Kp': 40.0, 'Kd': 3.0, 'x_target[2]': 0.5, 'F_ff[3]': 1.5}})
fa, fp = [], []
for a in args:
    s.set(dict(zip([f'{{n}}[{{i}}]' for n in ('xa', 'va', 'xb', 'vb') for i in (1, 2, 3)], a)))
    fa.append(s.get(['Fa[1]', 'Fa[2]', 'Fa[3]', 'Fb[1]', 'Fb[2]', 'Fb[3]']))
    p.set(dict(zip(['x[1]', 'x[2]', 'x[3]', 'v[1]', 'v[2]', 'v[3]'], a[:6])))
    fp.append(p.get(['F[1]', 'F[2]', 'F[3]']))
try:
    s.set({{'stiffness': -1.0}}); set_status = 0
except FMICallException as e:
    set_status = e.status
try:
    s.step(0.0, 0.01); status = 0
except FMICallException as e:
    status = e.status
save(fa=np.array(fa), fp=np.array(fp), status=status, set_status=set_status,
     log=np.array(' '.join(m for _, m in LOG)))
""", tmp_path / "client_components")
    scene = ln.Scene.from_dict({"name": "two", "masses": [{"position": [0, 0, 0], "mass": 1.0},
                                                          {"position": [1, 0, 0], "mass": 1.0}],
                                "springs": [{"a": 1, "b": 2, "stiffness": 20.0, "rest_length": 0.7, "damping": 0.3}]})
    for a, f in zip(args, out["fa"]):
        X = np.array([a[0:3], a[6:9]])
        U = np.array([a[3:6], a[9:12]])
        np.testing.assert_allclose(f, element_forces(scene, X, U).ravel(), rtol=1e-12, atol=1e-12)
    for a, f in zip(args, out["fp"]):
        expected = 40.0 * (np.array([0.0, 0.5, 0.0]) - a[:3]) - 3.0 * a[3:6] + np.array([0, 0, 1.5])
        np.testing.assert_allclose(f, expected, rtol=1e-12, atol=1e-12)
    assert out["set_status"] == 3 and out["status"] == 2 and "stiffness" in str(out["log"])  # fmi2Error, Discard
