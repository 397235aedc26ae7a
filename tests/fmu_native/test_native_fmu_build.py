"""What the native FMU is made of: a binary that needs only libc and libm and exports only the FMI functions; its
own sources, which gcc and clang compile (-std=c99 -Wall -Wextra -Werror) into a binary giving the same results;
a modelDescription.xml that fmpy validates and that agrees with the pythonfmu FMU's; fmpy runs it."""
import json
import shutil
import subprocess
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

from native_fmu_support import (CLANG, GCC, MODELS, N_STEPS, H, Built, assert_round_off, built, host_options,
                                parse_rows, run_host)
import build_fmu
import linknet_core as ln


def test_binary_needs_only_libc_and_exports_only_fmi(fmu_root):
    fmu = built(fmu_root, "net_10x10")
    so = fmu.dir / "binaries" / "linux64" / f"{fmu.ident}.so"
    ldd = subprocess.run(["ldd", str(so)], capture_output=True, text=True, check=True).stdout
    libraries = {line.split()[0] for line in ldd.splitlines() if line.strip()}
    allowed = {"linux-vdso.so.1", "libc.so.6", "/lib64/ld-linux-x86-64.so.2"}  # no libm: the core's math is its own
    assert libraries <= allowed and "libc.so.6" in libraries, ldd
    nm = subprocess.run(["nm", "-D", "--defined-only", str(so)], capture_output=True, text=True, check=True).stdout
    exported = {line.split()[-1] for line in nm.splitlines() if " T " in line}
    assert exported and all(name.startswith("fmi2") for name in exported), sorted(exported)
    for name in ("fmi2Instantiate", "fmi2DoStep", "fmi2GetFMUstate", "fmi2DeSerializeFMUstate", "fmi2GetRealStatus"):
        assert name in exported


def _md(fmu: Built) -> ET.Element:
    with zipfile.ZipFile(fmu.path) as z:
        return ET.fromstring(z.read("modelDescription.xml"))


IMPLEMENTATION = {"guid", "generationTool", "generationDateAndTime"}


@pytest.mark.parametrize("scene,options", [("chain_10", {}), ("spinning_tetrahedron", {}), ("redundant_truss", {}),
                                           ("net_10x10", {"inputs": "55", "outputs": "1,55"})],
                         ids=["chain_10", "spinning_tetrahedron", "redundant_truss", "net_10x10_some_masses"])
def test_model_description_agrees_with_the_pythonfmu_fmu(scene, options, fmu_root):
    native, python = _md(built(fmu_root, scene, **options)), _md(built(fmu_root, scene, native=False, **options))
    assert {k: v for k, v in native.attrib.items() if k not in IMPLEMENTATION} == \
        {k: v for k, v in python.attrib.items() if k not in IMPLEMENTATION}
    cs_n, cs_p = native.find("CoSimulation"), python.find("CoSimulation")
    for key in ("modelIdentifier", "canHandleVariableCommunicationStepSize", "canInterpolateInputs",
                "canBeInstantiatedOnlyOncePerProcess", "canGetAndSetFMUstate", "canSerializeFMUstate"):
        assert cs_n.get(key) == cs_p.get(key), key
    assert cs_n.get("needsExecutionTool") == "false" and cs_n.get("canBeInstantiatedOnlyOncePerProcess") == "false"
    for tag in ("UnitDefinitions", "TypeDefinitions", "DefaultExperiment", "ModelStructure"):
        assert ET.tostring(native.find(tag)) == ET.tostring(python.find(tag)), tag
    categories = [[c.get("name") for c in md.find("LogCategories")] for md in (native, python)]
    assert categories[0] == categories[1]
    vars_n, vars_p = native.find("ModelVariables"), python.find("ModelVariables")
    assert len(vars_n) == len(vars_p)
    for a, b in zip(vars_n, vars_p):
        assert a.attrib == b.attrib
        (ta,), (tb,) = list(a), list(b)
        assert ta.tag == tb.tag
        sa, sb = dict(ta.attrib), dict(tb.attrib)
        start_a, start_b = sa.pop("start", None), sb.pop("start", None)
        assert sa == sb, a.get("name")
        if ta.tag == "Real" and start_a is not None:
            assert float(start_a) == pytest.approx(float(start_b), rel=1e-15)  # pythonfmu writes 16 digits
        else:
            assert start_a == start_b


def test_source_files_listed_and_present(fmu_root):
    fmu = built(fmu_root, "chain_10")
    files = [f.get("name") for f in _md(fmu).find("CoSimulation").find("SourceFiles")]
    assert {"fmi2Functions.c", "linknet_model.c", "lnfmu_scene.c", "fmu_resource.c", "data.c", "dim2.c",
            "dim3.c"} <= set(files)
    for name in files:
        assert (fmu.dir / "sources" / name).is_file(), name
    assert (fmu.dir / "resources" / "linknet_scene.bin").is_file()  # the scene, read at instantiation
    # the stage files are compiled through dim2.c / dim3.c, not on their own
    assert not any(name.startswith("stages/") for name in files)
    assert (fmu.dir / "sources" / "linknet" / "stages" / "rattle.c").is_file()


def test_fmpy_validates_clean(fmu_root):
    from fmpy.validation import validate_fmu
    for scene in ("chain_10", "spinning_tetrahedron"):
        assert validate_fmu(str(built(fmu_root, scene).path)) == []


def test_fmpy_simulates_it(fmu_root):
    """fmpy's simulate_fmu in this process (no pythonfmu binary is loaded, so no exit-time caveats)."""
    import fmpy
    fmu = built(fmu_root, "chain_10")
    signal = np.array([(0.0, 0.7), (1.0, 0.7)], dtype=[("time", float), ("F[11,3]", float)])
    res = fmpy.simulate_fmu(str(fmu.path), stop_time=0.2, output_interval=0.01, input=signal,
                            start_values={"integrator": "rattle", "step": 5e-4}, output=["X[11,3]", "T[1]"])
    scene = ln.load_scene(MODELS / "chain_10.json")
    sim = ln.Simulator(scene, method="rattle", dt=5e-4)
    F = np.zeros((scene.K, 3))
    F[10, 2] = 0.7
    ref = []
    for n in range(21):
        o = sim.outputs(F)
        ref.append([o["X"][10, 2], o["T"][0]])
        if n < 20:
            sim.advance((n + 1) * 0.01, F)
    np.testing.assert_allclose(res["time"], np.arange(21) * 0.01, atol=1e-12)
    np.testing.assert_allclose(np.column_stack([res["X[11,3]"], res["T[1]"]]), np.array(ref), rtol=1e-10, atol=1e-12)
    # a master that starts at t0 != 0 gets every row: the FMU honours the start time of fmi2SetupExperiment
    late = fmpy.simulate_fmu(str(fmu.path), start_time=1.0, stop_time=1.1, output_interval=0.01, output=["X[11,3]"])
    assert len(late) == 11 and late["time"][0] == 1.0 and abs(late["time"][-1] - 1.1) < 1e-12


def _compile(cmd):
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0, " ".join(cmd[:10]) + "\n" + proc.stderr[-4000:]


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
@pytest.mark.parametrize("compiler", ["gcc", "clang"])
def test_sources_rebuild_with_gcc_and_clang_and_give_the_same_results(compiler, fmu_root, host, no_python_env,
                                                                      tmp_path):
    """Each FMU's sources/ compiled as a tool would, from the <SourceFiles> list with sources/ as the only include
    directory. The sources are the same file for file in every scene's FMU (the scene is in resources/), so one
    binary, compiled once from the first FMU's sources, runs every scene with its shipped binary's results."""
    from concurrent.futures import ThreadPoolExecutor
    cc = GCC if compiler == "gcc" else CLANG
    if cc is None:
        pytest.skip(f"{compiler} not installed (apt-get install {compiler})")
    flags = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", "-fPIC"]
    library = None
    first_sources = None
    for scene, methods in (("net_10x10", ("dop853", "rattle")), ("spinning_tetrahedron", ("yoshida4", "dop853")),
                           ("redundant_truss", ("rattle",))):
        fmu = built(fmu_root, scene)
        copy = tmp_path / f"{scene}_{compiler}"
        shutil.copytree(fmu.dir, copy)
        files = [f.get("name") for f in _md(fmu).find("CoSimulation").find("SourceFiles")]
        sources = copy / "sources"
        if first_sources is None:
            first_sources = sources
            objdir = tmp_path / "obj"
            objdir.mkdir()
            jobs = {f: objdir / (f.replace("/", "__") + ".o") for f in files}
            with ThreadPoolExecutor(max_workers=2) as pool:
                list(pool.map(_compile, [[cc] + flags + ["-I", str(sources), "-c", str(sources / f), "-o", str(o)]
                                         for f, o in jobs.items()]))
            library = tmp_path / "rebuilt.so"
            _compile([cc, "-shared", "-o", str(library)] + [str(o) for o in jobs.values()] + ["-lm"])
        else:
            for p in sorted(first_sources.rglob("*.[ch]")):  # every source file is the same in every FMU
                assert (sources / p.relative_to(first_sources)).read_bytes() == p.read_bytes(), p
        shutil.copy2(library, copy / "binaries" / "linux64" / f"{fmu.ident}.so")
        rebuilt = Built(fmu.path, copy, fmu.ident, fmu.guid, fmu.vr, fmu.md)
        for method in methods:
            opts = host_options(fmu, method)
            shipped = parse_rows(run_host(host, no_python_env, "run", fmu, 0.0, N_STEPS, H, *opts))
            again = parse_rows(run_host(host, no_python_env, "run", rebuilt, 0.0, N_STEPS, H, *opts))
            assert_round_off(again, shipped, f"{scene} {method}: {compiler} -O2 rebuild vs shipped binary")


def test_options_and_scene_fmu_section_apply_to_the_native_fmu(tmp_path):
    data = json.loads((MODELS / "chain_10.json").read_text())
    data["fmu"] = {"inputs": [11], "outputs": [1, 11], "integrator": "dop853", "tolerance": 1e-9}
    path = tmp_path / "tip.json"
    path.write_text(json.dumps(data))
    out = build_fmu.build_scene_fmu(str(path), tmp_path / "tip.fmu", quiet=True, native=True)
    from fmpy import read_model_description
    md = read_model_description(str(out))
    names = [v.name for v in md.modelVariables]
    assert [n for n in names if n.startswith("F[")] == ["F[11,1]", "F[11,2]", "F[11,3]"]
    assert [n for n in names if n.startswith("X[")] == ["X[1,1]", "X[1,2]", "X[1,3]", "X[11,1]", "X[11,2]", "X[11,3]"]
    start = {v.name: v.start for v in md.modelVariables}
    assert start["integrator"] == "dop853" and float(start["tolerance"]) == 1e-9


def test_build_errors_are_one_line(tmp_path, capsys):
    data = json.loads((MODELS / "pendulum.json").read_text())
    data["links"][0]["length"] = 2.0  # the initial positions say 1 m
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(data))
    with pytest.raises(SystemExit) as e:
        build_fmu.main([str(path), "--native", "-o", str(tmp_path / "bad.fmu")])
    message = str(e.value)
    assert message.startswith("build_fmu:") and "\n" not in message and "link 1" in message
    assert not (tmp_path / "bad.fmu").exists()
