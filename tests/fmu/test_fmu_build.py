"""FMU build: every shipped scene gives a valid FMI 2.0 CS FMU with units and truthful structure.

These tests read the model description only (no FMU binary is loaded in this process).
"""
import json
import shutil
import zipfile

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.validation import validate_fmu

from fmu_harness import MODELS, build_cached, build_fmu  # first: puts the repo on sys.path
import linknet_core as ln

SCENES = sorted(p for p in MODELS.glob("*.json"))


@pytest.fixture(scope="session")
def fmu_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("fmus")


def _reals(md):
    return [v for v in md.modelVariables if v.type == "Real"]


@pytest.mark.parametrize("scene_path", SCENES, ids=lambda p: p.stem)
def test_scene_fmu_validates_with_units_and_structure(scene_path, fmu_dir):
    fmu = build_cached(fmu_dir, str(scene_path))
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu), validate=True)
    scene = ln.load_scene(scene_path)
    units = {u.name for u in md.unitDefinitions}
    for v in _reals(md):
        assert v.declaredType is not None and v.unit in units, v.name
    assert md.defaultExperiment is not None and float(md.defaultExperiment.stepSize) > 0
    assert md.coSimulation.canGetAndSetFMUstate and md.coSimulation.canSerializeFMUstate
    names = {v.name for v in md.modelVariables}
    free, fixed = scene.free_indices, scene.fixed_indices
    # the interface of issue 4: F for free masses, X/U for all, T per link, Freact for anchored masses
    assert {f"F[{k + 1},{i}]" for k in free for i in (1, 2, 3)} <= names
    assert not any(f"F[{k + 1},1]" in names for k in fixed)
    assert {f"X[{k + 1},{i}]" for k in range(scene.K) for i in (1, 2, 3)} <= names
    assert {f"T[{l + 1}]" for l in range(scene.L)} <= names
    assert {f"Freact[{k + 1},{i}]" for k in fixed for i in (1, 2, 3)} <= names
    assert {f"M[{k + 1}]" for k in free} | {f"R[{l + 1}]" for l in range(scene.L)} | {"g[1]", "g[2]", "g[3]"} <= names
    # start values are the scene's
    start = {v.name: v.start for v in md.modelVariables}
    np.testing.assert_allclose([float(start[f"R[{l + 1}]"]) for l in range(scene.L)], scene.length, rtol=1e-15)

    deps = {u.variable.name: {d.name for d in (u.dependencies or [])} for u in md.outputs}
    inputs = {v.name for v in md.modelVariables if v.causality == "input"}
    for k in range(scene.K):
        assert deps[f"X[{k + 1},1]"] == set() and deps[f"U[{k + 1},3]"] == set()  # no direct feedthrough
    # T_l depends on the forces on the free masses its link group touches: check against the
    # coupling of the tension matrix A (25) itself, evaluated by the library at a generic
    # configuration (random positions, so that no E_l.E_l' vanishes by symmetry)
    X = scene.X0 + np.random.default_rng(0).normal(scale=0.1, size=scene.X0.shape)
    A = ln.Dynamics(scene).tension_matrix(X).toarray() != 0
    reach = A | np.eye(scene.L, dtype=bool)
    for _ in range(int(np.ceil(np.log2(max(scene.L, 2)))) + 1):
        reach = (reach.astype(np.int64) @ reach.astype(np.int64)) > 0
    for l in range(scene.L):
        masses = {int(m) for j in np.flatnonzero(reach[l]) for m in (scene.k1[j], scene.k2[j]) if not scene.fixed[m]}
        expected = {f"F[{k + 1},{i}]" for k in masses for i in (1, 2, 3)} & inputs
        assert deps[f"T[{l + 1}]"] == expected, f"T[{l + 1}]"


@pytest.mark.parametrize("component", ["pd_controller", "spring_damper"])
def test_component_fmus_validate(component, fmu_dir):
    fmu = build_cached(fmu_dir, component)
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    assert all(v.unit for v in _reals(md))
    deps = {u.variable.name: {d.name for d in (u.dependencies or [])} for u in md.outputs}
    if component == "pd_controller":
        assert deps["F[1]"] == {"x[1]", "v[1]"}
    else:
        assert len(deps["Fa[1]"]) == 12


def test_exposing_only_some_masses(fmu_dir):
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"), out_name="chain_10_tip", inputs="11", outputs="1,11")
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    names = [v.name for v in md.modelVariables]
    assert [n for n in names if n.startswith("F[")] == ["F[11,1]", "F[11,2]", "F[11,3]"]
    assert [n for n in names if n.startswith("X[")] == [f"X[{k},{i}]" for k in (1, 11) for i in (1, 2, 3)]
    assert sum(n.startswith("T[") for n in names) == 10


def test_fmu_carries_scene_core_and_linked_binary(fmu_dir):
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"))
    with zipfile.ZipFile(fmu) as z:
        files = set(z.namelist())
        scene = json.loads(z.read("resources/linknet_scene.json"))
        so = z.read("binaries/linux64/chain_10_pythonfmu.so")  # pythonfmu's binary, behind the front layer
    assert "resources/linknet_core/__init__.py" in files and "resources/linknet_slave.py" in files
    assert scene == ln.load_scene(MODELS / "chain_10.json").to_dict()
    assert b"libpython3" in so  # DT_NEEDED added by build_fmu.link_libpython


def test_the_front_layer_is_compiled_once_per_compiler_and_model_identifier(tmp_path, monkeypatch):
    """The pythonfmu FMU's front layer comes from the per-user cache when the compiler, its flags and what it reads
    are those of a build before: built twice, one compile and the same front; another compiler, a compile of its own."""
    import subprocess

    from pythonfmu_front import build as front_build

    monkeypatch.setenv("LINKNET_FMU_CACHE", str(tmp_path / "cache"))
    compiles = []
    real = subprocess.run
    monkeypatch.setattr(front_build.subprocess, "run", lambda cmd, **kw: (
        compiles.append(cmd) if "-shared" in cmd else None, real(cmd, **kw))[1])
    fronts = []
    for n in range(2):
        build_fmu.build_scene_fmu(str(MODELS / "pendulum.json"), tmp_path / f"p{n}.fmu", quiet=True)
        with zipfile.ZipFile(tmp_path / f"p{n}.fmu") as z:
            fronts.append(z.read("binaries/linux64/pendulum.so"))
    assert len(compiles) == 1 and fronts[0] == fronts[1]
    assert len(list((tmp_path / "cache" / "pythonfmu-front").glob("pendulum.*.so"))) == 1
    other = "gcc" if front_build.compiler() != "gcc" and shutil.which("gcc") else None
    if other:
        monkeypatch.setenv("CC", other)
        build_fmu.build_scene_fmu(str(MODELS / "pendulum.json"), tmp_path / "p2.fmu", quiet=True)
        assert len(compiles) == 2


def test_bad_scene_is_refused_with_a_message_naming_the_link(tmp_path):
    bad = {"name": "bad", "masses": [{"name": "a", "position": [0, 0, 0], "fixed": True},
                                      {"name": "b", "position": [1, 0, 0], "mass": 1.0}],
           "links": [{"a": 1, "b": 2}, {"a": 2, "b": 2}]}
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(bad))
    with pytest.raises(SystemExit, match="link 2"):
        build_fmu.build_scene_fmu(path, tmp_path / "bad.fmu", quiet=True)


def test_fmpy_info_shows_units(fmu_dir):
    import subprocess
    import sys
    fmu = build_cached(fmu_dir, str(MODELS / "chain_10.json"))
    info = subprocess.run([sys.executable, "-m", "fmpy", "info", str(fmu)], capture_output=True, text=True)
    assert info.returncode == 0, info.stderr
    lines = {line.split()[0]: line.split() for line in info.stdout.splitlines() if line.strip()[:2] in ("F[", "X[", "T[")}
    assert "N" in lines["F[11,3]"] and "m" in lines["X[11,3]"] and "N" in lines["T[1]"]


def test_scene_file_fmu_section_selects_masses_and_integrator(tmp_path):
    scene = json.loads((MODELS / "chain_10.json").read_text())
    scene["fmu"] = {"inputs": [11], "outputs": ["m10"], "integrator": "dop853", "tolerance": 1e-9}
    path = tmp_path / "chain_10_tip.json"
    path.write_text(json.dumps(scene))
    fmu = build_fmu.build_scene_fmu(path, tmp_path / "tip.fmu", quiet=True)
    assert validate_fmu(str(fmu)) == []
    md = read_model_description(str(fmu))
    names = [v.name for v in md.modelVariables]
    start = {v.name: v.start for v in md.modelVariables}
    assert [n for n in names if n.startswith(("F[", "X["))] == ["F[11,1]", "F[11,2]", "F[11,3]",
                                                                 "X[11,1]", "X[11,2]", "X[11,3]"]
    assert start["integrator"] == "dop853" and float(start["tolerance"]) == 1e-9


def test_force_input_on_an_anchored_mass_is_refused_by_name(tmp_path):
    with pytest.raises(SystemExit, match="mass 1 cannot take a force input"):
        build_fmu.build_scene_fmu(MODELS / "chain_10.json", tmp_path / "x.fmu", inputs="1", quiet=True)
    with pytest.raises(SystemExit, match="no mass 'nope'"):
        build_fmu.build_scene_fmu(MODELS / "chain_10.json", tmp_path / "x.fmu", outputs="nope", quiet=True)
