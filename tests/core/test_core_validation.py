"""Bad input is refused with a message naming the mass, link or variable and the rule; the initial state
is checked (link lengths, (12), hypothesis (35)); the stepping interface and the CLI behave."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.scene import builders
from linknet_core.native.model import NativeModel
from linknet_core.structure.topology import link_pairs

ROOT = Path(__file__).resolve().parents[2]


def base():
    return {"name": "t", "gravity": [0, 0, -9.81],
            "masses": [{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                       {"name": "a", "mass": 1.0, "position": [1, 0, 0]},
                       {"name": "b", "mass": 1.0, "position": [2, 0, 0]}],
            "links": [{"a": "pivot", "b": "a"}, {"a": "a", "b": "b", "length": 1.0}]}


def edited(fn):
    d = base()
    fn(d)
    return d


CASES = [
    ("self-link", lambda d: d["links"].append({"a": "b", "b": "b"}), r"link 3 \(b-b\) joins mass 3 to itself"),
    ("duplicate pair", lambda d: d["links"].append({"a": "b", "b": "a"}), r"link 3 \(b-a\) joins the same pair of masses as link 2"),
    ("unknown name", lambda d: d["links"].append({"a": "a", "b": "zz"}), r"link 3 end 'b' refers to unknown mass 'zz'"),
    ("index out of range", lambda d: d["links"].append({"a": 1, "b": 9}), r"refers to mass index 9, but masses are numbered 1..3"),
    ("zero mass", lambda d: d["masses"][1].update(mass=0.0), r'mass 2 \("a"\) mass must be positive'),
    ("negative mass", lambda d: d["masses"][2].update(mass=-1.0), r'mass 3 \("b"\) mass must be positive'),
    ("infinite mass", lambda d: d["masses"][2].update(mass=float("inf")), r'mass 3 \("b"\) mass must be finite'),
    ("NaN position", lambda d: d["masses"][1].update(position=[float("nan"), 0, 0]), r'mass 2 \("a"\) position must be finite'),
    ("NaN velocity", lambda d: d["masses"][2].update(velocity=[0, float("nan"), 0]), r'mass 3 \("b"\) velocity must be finite'),
    ("NaN gravity", lambda d: d.update(gravity=[0, 0, float("nan")]), r"gravity must be finite"),
    ("zero length", lambda d: d["links"][1].update(length=0.0), r"link 2 \(a-b\) length must be positive"),
    ("NaN length", lambda d: d["links"][1].update(length=float("nan")), r"link 2 \(a-b\) length must be finite"),
    ("free mass without mass", lambda d: d["masses"][1].pop("mass"), r'mass 2 \("a"\) is free but has no \'mass\' value'),
    ("duplicate names", lambda d: d["masses"][2].update(name="a"), r'mass 3 \("a"\) repeats the name of mass 2'),
    ("anchor with velocity", lambda d: d["masses"][0].update(velocity=[1, 0, 0]), r'mass 1 \("pivot"\) is fixed .* non-zero velocity'),
    ("unknown field", lambda d: d["links"][0].update(stiffnes=3), r"link 1 has unknown field\(s\) \['stiffnes'\]"),
    ("negative spring stiffness", lambda d: d.update(springs=[{"a": "a", "b": "b", "stiffness": -1}]),
     r"spring 1 stiffness must not be negative"),
]


@pytest.mark.parametrize("label,edit,message", CASES, ids=[c[0] for c in CASES])
def test_bad_scene_is_refused_with_a_message_naming_the_culprit(label, edit, message):
    with pytest.raises(ln.SceneError, match=message):
        ln.Scene.from_dict(edited(edit))


def test_all_anchored_scene_is_refused():
    d = base()
    for m in d["masses"]:
        m["fixed"] = True
        m.pop("mass", None)
    d["links"] = []
    with pytest.raises(ln.SceneError, match="every mass is anchored"):
        ln.Scene.from_dict(d)


def test_link_between_two_anchors_is_refused():
    d = base()
    d["masses"].append({"name": "p2", "position": [0, 1, 0], "fixed": True})
    d["links"].append({"a": "pivot", "b": "p2"})
    with pytest.raises(ln.SceneError, match=r"link 3 \(pivot-p2\) joins two anchored masses"):
        ln.Scene.from_dict(d)


def test_inconsistent_initial_positions_list_worst_links_or_are_projected_on_request():
    d = base()
    d["links"][1]["length"] = 1.2
    scene = ln.Scene.from_dict(d)
    with pytest.raises(ln.SceneError, match=r"violate the link lengths by up to 0.167 .*link 2 \(a-b\): distance 1 m vs length 1.2 m"):
        ln.Simulator(scene, dt=1e-3)
    sim = ln.Simulator(scene, dt=1e-3, project_initial=True)
    assert sim.initial_report.positions_projected
    assert sim.dyn.constraint_residual(sim.state.X) < 1e-14
    # the scene option does the same
    d["options"] = {"project_initial_positions": True}
    assert ln.Simulator(ln.Scene.from_dict(d), dt=1e-3).initial_report.positions_projected


def test_initial_velocities_are_projected_onto_12_and_the_correction_reported():
    d = base()
    d["masses"][2]["velocity"] = [0.5, 1.0, 0.0]  # 0.5 m/s along link 2 would stretch it
    sim = ln.Simulator(ln.Scene.from_dict(d), dt=1e-3)
    rep = sim.initial_report
    assert rep.velocity_correction > 0.1
    assert sim.dyn.velocity_residual(sim.state.X, sim.state.U) < 1e-15
    # the tangential part survives: mass b keeps its y velocity
    assert sim.state.U[2, 1] == pytest.approx(1.0)
    assert any("velocities projected onto (12)" in line for line in rep.lines(sim.scene))


def test_hypothesis_35_violation_is_refused_naming_the_self_stress():
    scene = builders.taut_string(speed=1.0)
    # (12) holds: the sideways velocity is perpendicular to both links ...
    dyn = ln.Dynamics(scene)
    assert dyn.velocity_residual(scene.X0, scene.U0) == 0.0
    # ... yet no accelerations satisfy (35)
    with pytest.raises(ln.ConsistencyError, match=r"hypothesis \(35\).*link 1 \(left-middle\), link 2 \(middle-right\)"):
        ln.Simulator(scene, dt=1e-3)
    # at rest the same string is consistent
    ln.Simulator(builders.taut_string(speed=0.0), dt=1e-3)


def test_structure_classes_are_chosen_from_topology():
    assert ln.Dynamics(builders.chain(20)).structure.kind == "chain"
    assert ln.Dynamics(builders.four_bar()).structure.kind == "chain"  # loop closes only through the ground
    tree = ln.Scene.from_dict({"name": "Y", "masses": [
        {"name": "p", "position": [0, 0, 0], "fixed": True}, {"name": "hub", "mass": 1, "position": [0, 0, -1]},
        {"name": "l", "mass": 1, "position": [-1, 0, -1]}, {"name": "r", "mass": 1, "position": [1, 0, -1]},
        {"name": "d", "mass": 1, "position": [0, 0, -2]}, {"name": "dd", "mass": 1, "position": [0, 1, -2]}],
        "links": [{"a": "p", "b": "hub"}, {"a": "hub", "b": "l"}, {"a": "hub", "b": "r"}, {"a": "hub", "b": "d"},
                  {"a": "d", "b": "dd"}]})
    dyn = ln.Dynamics(tree)
    assert dyn.structure.kind == "tree"
    # leaves-first order: no fill, L has exactly the off-diagonal entries of A (one per pair of links sharing
    # a free mass)
    model = NativeModel(tree, dyn.structure)
    pairs = link_pairs(tree)
    assert model.solver == "ldl" and model.nnz_L == len({(f, s) for f, s in zip(pairs.first, pairs.second) if f != s})
    assert ln.Dynamics(builders.net(4, 4)).structure.kind == "general"
    assert ln.Dynamics(builders.redundant_truss()).structure.kind == "redundant"
    # a net anchored at both corners of its first row: that row is a taut string, a self-stress
    assert ln.Dynamics(builders.net(3, 3, anchors="corners")).structure.self_stresses == 1


def test_stepping_interface_replays_bit_identically_and_takes_any_step():
    scene = builders.chain(6)
    for kw in ({"method": "rattle", "dt": 1e-3}, {"method": "dop853", "rtol": 1e-9}):
        sim = ln.Simulator(scene, **kw)
        F = np.zeros((scene.K, 3))
        F[-1, 1] = 0.5
        sim.advance(0.05, F)
        snap = sim.get_state()
        sim.advance(0.1, F)
        sim.advance(0.1 + 1e-13, F)  # a tiny communication step
        first = sim.outputs(F)
        sim.set_state(snap)
        sim.advance(0.1, F)
        sim.advance(0.1 + 1e-13, F)
        second = sim.outputs(F)
        for key in ("X", "U", "T"):
            assert np.array_equal(first[key], second[key]), key
        sim.reset()
        assert sim.state.t == 0.0 and np.array_equal(sim.state.X, scene.X0)


def test_stepping_interface_refuses_bad_input_and_stays_usable():
    scene = builders.chain(3)
    sim = ln.Simulator(scene, dt=1e-3)
    F = np.zeros((scene.K, 3))
    F[2, 1] = np.nan
    with pytest.raises(ln.SolverError, match=r"input force F\[3,2\] on mass 3 \(\"m2\"\) is nan"):
        sim.advance(0.01, F)
    with pytest.raises(ln.SolverError, match="must be later"):
        sim.advance(0.0)
    with pytest.raises(ln.SolverError, match=r"shape \(4, 3\)"):
        sim.advance(0.01, np.zeros(3))
    sim.advance(0.01)
    assert sim.state.t == 0.01
    with pytest.raises(ln.SolverError, match="unknown integration method 'rk99'"):
        ln.Simulator(scene, method="rk99", dt=1e-3)
    with pytest.raises(ln.SolverError, match="dt must be a positive"):
        ln.Simulator(scene, dt=-1.0)


SCENE_FILES = sorted((ROOT / "models").glob("*.json"))


@pytest.mark.parametrize("method", ["rattle", "yoshida4", "dop853"])
@pytest.mark.parametrize("backend", ["auto", "numpy"])
def test_advance_never_writes_into_the_state_it_started_from(method, backend):
    # Simulator.advance keeps references to the starting arrays as its snapshot for a failed call: every
    # path (compiled, numpy, chain/general/redundant solvers, rigid-body and static specialisations) must
    # replace the state's arrays, never write into them
    for path in SCENE_FILES:
        scene = ln.load_scene(path)
        kw = {"rtol": 1e-8} if method == "dop853" else {"dt": 1e-3}
        sim = ln.Simulator(scene, method=method, backend=backend, **kw)
        F = np.zeros((scene.K, 3))
        F[scene.free_indices[-1]] = [0.3, -0.2, 0.1]  # also takes planar scenes off their plane
        for t_next, force in ((0.002, None), (0.005, F)):
            X, U = sim.state.X, sim.state.U
            X_copy, U_copy = X.copy(), U.copy()
            sim.advance(t_next, force)
            assert np.array_equal(X, X_copy) and np.array_equal(U, U_copy), (path.name, t_next)
            assert sim.state.X is not X or sim.specialisation.kind == "static", path.name


@pytest.mark.parametrize("method,kw", [("rattle", {"dt": 1e-3}), ("dop853", {"rtol": 1e-8})])
def test_a_failed_advance_leaves_the_simulator_as_it_was(method, kw):
    scene = ln.load_scene(ROOT / "models" / "chain_10.json")
    sim = ln.Simulator(scene, method=method, **kw)
    reference = ln.Simulator(scene, method=method, **kw)
    F = np.zeros((scene.K, 3))
    F[-1, 2] = 0.5
    for s in (sim, reference):
        s.advance(0.05, F)
    before = sim.get_state()
    X_before = sim.state.X.copy()
    # a force that throws the tip out to ~1e190 m: the state goes non-finite or the projection fails
    huge = F.copy()
    huge[-1, 2] = 1e200
    with pytest.raises(ln.SolverError), np.errstate(all="ignore"):
        sim.advance(0.1, huge)
    if ln.METHODS[method].adaptive:  # and a step limit hit part way through the interval
        sim.max_steps_per_call = 3
        with pytest.raises(ln.SolverError, match="more than 3 steps"):
            sim.advance(0.5, F)
        sim.max_steps_per_call = reference.max_steps_per_call
    assert sim.state.t == 0.05 and np.array_equal(sim.state.X, X_before)
    assert sim.integrator.internals() == before["integrator"]
    for s in (sim, reference):
        s.advance(0.1, F)
    assert np.array_equal(sim.state.X, reference.state.X) and np.array_equal(sim.state.U, reference.state.U)


def test_load_scene_reports_bad_files(tmp_path):
    with pytest.raises(ln.SceneError, match="cannot read scene file"):
        ln.load_scene(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ln.SceneError, match="not valid JSON"):
        ln.load_scene(bad)


def test_scene_round_trips_through_json(tmp_path):
    for scene in builders.shipped_scenes().values():
        path = tmp_path / f"{scene.name}.json"
        scene.save(path)
        again = ln.load_scene(path)
        for attr in ("mass", "k1", "k2", "length", "X0", "U0", "gravity", "fixed"):
            assert np.array_equal(getattr(scene, attr), getattr(again, attr)), (scene.name, attr)


def test_shipped_model_files_match_their_builders():
    for name, scene in builders.shipped_scenes().items():
        shipped = ln.load_scene(ROOT / "models" / f"{name}.json")
        np.testing.assert_allclose(shipped.X0, scene.X0, atol=1e-15)
        np.testing.assert_allclose(shipped.length, scene.length, atol=1e-15)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "linknet_core.cli", *args], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)


def test_cli_simulate_writes_arrays_and_summary(tmp_path):
    out = tmp_path / "r.npz"
    png = tmp_path / "r.png"
    run = _cli("simulate", "models/double_pendulum.json", "--t-end", "0.5", "--dt", "1e-3", "--out", str(out),
               "--plot", str(png), "--n-out", "51")
    assert run.returncode == 0, run.stderr
    assert "steps = 500" in run.stdout and "max constraint residual" in run.stdout
    data = np.load(out)
    assert data["t"].shape == (51,) and data["X"].shape == (51, 3, 3) and data["U"].shape == (51, 3, 3)
    assert data["T"].shape == (51, 2) and data["energy"].shape == (51,) and data["residual"].shape == (51,)
    assert png.stat().st_size > 10_000


def test_cli_analyze_reports_maxwell_calladine_counts():
    run = _cli("analyze", "models/redundant_truss.json")
    assert run.returncode == 0, run.stderr
    assert "rank of G: 18" in run.stdout and "states of self-stress: 6" in run.stdout
    assert "rigid: yes" in run.stdout and "structure class redundant" in run.stdout


def test_cli_reports_errors_without_a_traceback(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(edited(lambda d: d["links"].append({"a": "a", "b": "a"}))))
    run = _cli("simulate", str(bad), "--t-end", "1")
    assert run.returncode == 2
    assert "joins mass 2 to itself" in run.stderr and "Traceback" not in run.stderr
