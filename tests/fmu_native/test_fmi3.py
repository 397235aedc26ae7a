"""The native FMI 3.0 Co-Simulation FMU (fmu_src/native/build_fmi3.py): fmpy validates it and simulates it; its
array variables give the FMI 2.0 native FMU's outputs bit for bit on every shipped scene and on a scene with an
input-driven anchor, with the same inputs; its directional derivatives are those of finite differences (the tensions
are affine in the forces); FMU states replay bit for bit; bad input is answered with fmi3Error and a logged message,
and the FMU goes on.

Both FMUs run in this process through fmpy (FMU2Slave, FMU3Slave); each FMU is built once per module."""
from __future__ import annotations

import ctypes
import math
import os
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from native_fmu_support import GCC, MODELS, ROOT, SCENES, built

os.environ.setdefault("LINKNET_FMU_PLATFORMS", "host")  # this machine's binary only (the suite's setting)
sys.path.insert(0, str(ROOT / "tests"))
import driven_fmu_support as drive  # noqa: E402

sys.path.insert(0, str(ROOT / "fmu_src"))
from native.build_fmi3 import build_scene_fmi3  # noqa: E402

OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
H, N_STEPS = 0.01, 4
OUTPUTS = ("X", "U", "T", "Freact", "Jreact", "error_estimate")
DRIVEN = "driven_chain"  # a force input, an input-driven anchor and a sine-driven one (tests/driven_fmu_support.py)


class Fmi3Built:
    """An FMI 3.0 FMU, extracted, with its variables by name."""

    def __init__(self, path: Path):
        from fmpy import read_model_description
        self.path = path
        self.dir = path.with_suffix("")
        with zipfile.ZipFile(path) as z:
            z.extractall(self.dir)
        self.md = read_model_description(str(path))
        self.ident = self.md.coSimulation.modelIdentifier
        self.var = {v.name: v for v in self.md.modelVariables}

    def size(self, name: str) -> int:
        return int(np.prod([int(d.start) for d in self.var[name].dimensions])) if self.var[name].dimensions else 1


_fmi3_cache: dict = {}


def fmi3_built(root: Path, scene: Path, **options) -> Fmi3Built:
    key = (str(scene), tuple(sorted(options.items())))
    if key not in _fmi3_cache:
        tag = "_".join(f"{k}{v}" for k, v in sorted(options.items()))
        out = root / f"{scene.stem}_fmi3{'_' + tag if tag else ''}.fmu"
        build_scene_fmi3(str(scene), out, platforms="host", quiet=True, **options)
        _fmi3_cache[key] = Fmi3Built(out)
    return _fmi3_cache[key]


@pytest.fixture(scope="module")
def scene_paths(tmp_path_factory) -> dict:
    paths = {name: MODELS / f"{name}.json" for name in SCENES}
    paths[DRIVEN] = drive.write_scene(tmp_path_factory.mktemp("fmi3_scenes"), DRIVEN)
    return paths


@pytest.fixture(scope="module")
def fmi3_root(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("fmi3")


class Slave3:
    """One FMI 3 instance through fmpy; log messages collected as (status, category, message)."""

    def __init__(self, fmu: Fmi3Built, name="fmi3"):
        from fmpy.fmi3 import FMU3Slave
        self.fmu, self.log = fmu, []
        self.slave = FMU3Slave(guid=fmu.md.guid, unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident,
                               instanceName=name)
        self.slave.instantiate(logMessage=self._logger)

    def _logger(self, env, status, category, message):
        self.log.append((int(status), category.decode(), message.decode("utf-8", "replace")))

    def vr(self, name):
        return self.fmu.var[name].valueReference

    def get(self, name) -> np.ndarray:
        return np.array(self.slave.getFloat64([self.vr(name)], self.fmu.size(name)))

    def set(self, name, values):
        self.slave.setFloat64([self.vr(name)], [float(x) for x in np.ravel(values)])

    def raw(self, function, *args) -> int:
        """An FMI 3 function called as it is, its status returned (fmpy raises on fmi3Error)."""
        return self.slave._functions[function](self.slave.component, *args)

    def initialize(self):
        self.slave.enterInitializationMode(startTime=0.0)
        self.slave.exitInitializationMode()

    def step(self, t, h=H):
        event, terminate, early, last = self.slave.doStep(t, h)
        assert (event, terminate, early, last) == (False, False, False, t + h)

    def errors(self):
        return [message for status, _, message in self.log if status == ERROR]

    def free(self):
        self.slave.freeInstance()


class Slave2:
    """The FMI 2.0 native FMU of the same scene, by the FMI 3 FMU's array names (its scalars in Layout order)."""

    def __init__(self, fmu):
        from fmpy.fmi2 import FMU2Slave
        self.fmu = fmu
        self.slave = FMU2Slave(guid=fmu.guid, unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident, instanceName="2")
        self.slave.instantiate()
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def vrs(self, name):
        return [self.fmu.vr[name]] if name in self.fmu.vr else self.fmu.vrs(name)

    def get(self, name) -> np.ndarray:
        return np.array(self.slave.getReal(self.vrs(name)))

    def set(self, name, values):
        self.slave.setReal(self.vrs(name), [float(x) for x in np.ravel(values)])

    def step(self, t, h=H):
        self.slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)


def forces(n: int, t: float) -> np.ndarray:
    """Nonzero forces on every input row, varying in time (N)."""
    return np.array([0.4 * math.sin(1.3 * (j + 1) + 7.0 * t) + 0.1 for j in range(n)])


def run(slave, fmu3: Fmi3Built, motion=None, n_steps=N_STEPS) -> dict:
    """Outputs at every communication point of a run with the forces above (and the anchor's motion)."""
    rows = {name: [] for name in OUTPUTS if name in fmu3.var}
    for n in range(n_steps + 1):
        t = n * H
        if "F" in fmu3.var:
            slave.set("F", forces(fmu3.size("F"), t))
        if motion is not None:
            for name, values in zip("PVA", motion):
                slave.set(name, values[n])
        for name in rows:
            rows[name].append(slave.get(name))
        if n < n_steps:
            slave.step(t)
    return {name: np.array(values) for name, values in rows.items()}


# ---------------------------------------------------------------------------- validation and structure
@pytest.mark.parametrize("name", ["chain_10", DRIVEN])
def test_fmpy_validates_the_fmi3_fmu_and_its_build_description(name, scene_paths, fmi3_root):
    from fmpy.validation import validate_fmu
    from lxml import etree
    import fmpy
    fmu = fmi3_built(fmi3_root, scene_paths[name])
    assert fmu.md.fmiVersion == "3.0"
    assert validate_fmu(str(fmu.path)) == []
    schema = etree.XMLSchema(etree.parse(os.path.join(os.path.dirname(fmpy.__file__), "schema", "fmi3",
                                                      "fmi3BuildDescription.xsd")))
    description = etree.parse(str(fmu.dir / "sources" / "buildDescription.xml"))
    assert schema.validate(description), schema.error_log
    listed = [f.get("name") for f in description.iter("SourceFile")]
    assert "fmi3Functions.c" in listed and "fmi2Functions.c" not in listed
    assert sorted(listed) == sorted(p.name for p in (fmu.dir / "sources").glob("*.c"))


def test_arrays_hold_the_fmi2_scalars_with_their_start_values_and_units(scene_paths, fmi3_root, fmu_root):
    """Each FMI 3 array has the FMI 2.0 FMU's scalars of its name, row-major, with their start values and unit."""
    fmu3 = fmi3_built(fmi3_root, scene_paths[DRIVEN])
    fmu2 = built(fmu_root, scene_paths[DRIVEN])
    scalars2 = {v.name: v for v in fmu2.md.modelVariables}
    for v in fmu3.md.modelVariables:
        if v.name in ("time", "integrator", "estimate_error", "tolerance", "step", "error_estimate"):
            continue
        names = fmu2.names(v.name)
        assert len(names) == fmu3.size(v.name) > 0, v.name
        assert all(scalars2[n].causality == v.causality and scalars2[n].unit == v.unit for n in names), v.name
        if v.causality in ("input", "parameter"):
            starts = [float(x) for x in str(v.start).split()]
            assert starts == [float(scalars2[n].start) for n in names], v.name
    assert [int(d.start) for d in fmu3.var["X"].dimensions] == [9, 3]
    assert [int(d.start) for d in fmu3.var["P"].dimensions] == [1, 3]
    # the tensions depend on the forces and on the input anchor's motion (feedthrough); positions on nothing
    outputs = {u.variable.name: {d.name for d in u.dependencies} for u in fmu3.md.outputs}
    assert outputs["T"] == {"F", "P", "V", "A"} and outputs["X"] == set() and outputs["Jreact"] == set()


# ---------------------------------------------------------------------------- FMI 3 = FMI 2, bit for bit
@pytest.mark.parametrize("name", SCENES + [DRIVEN])
def test_fmi3_outputs_equal_the_fmi2_fmu_bit_for_bit(name, scene_paths, fmi3_root, fmu_root):
    fmu3 = fmi3_built(fmi3_root, scene_paths[name])
    fmu2 = built(fmu_root, scene_paths[name])
    motion = None
    if "P" in fmu3.var:
        import linknet_core as ln
        scene = ln.Scene.from_dict(drive.SCENES[DRIVEN])
        motion = drive.anchor_motion(scene.X0[drive.ANCHOR[DRIVEN] - 1], n_steps=N_STEPS, h=H)
    s3 = Slave3(fmu3)
    s3.initialize()
    s2 = Slave2(fmu2)
    # the pushed triangulated net costs more with every step (its flat braced cells near a self-stress:
    # test_native_fmu_results): two steps hold the glue to it, as four do on the other scenes
    n_steps = 2 if name == "triangulated_net" else N_STEPS
    got, want = run(s3, fmu3, motion, n_steps), run(s2, fmu3, motion, n_steps)
    s3.free()
    s2.slave.freeInstance()
    assert "F" in fmu3.var, f"{name}: no force input to drive the run"
    for key in want:
        np.testing.assert_array_equal(got[key], want[key], err_msg=f"{name}: {key}")
    # the run is not a still one: the masses move, or (a static truss) the tensions follow the varying forces
    assert max(np.ptp(got[key], axis=0).max() for key in ("X", "T") if got[key].size) > 0, f"{name}: nothing changed"


def test_fmpy_simulate_fmu_gives_the_fmi2_run(scene_paths, fmi3_root, fmu_root):
    import fmpy
    fmu3 = fmi3_built(fmi3_root, scene_paths["chain_10"])
    fmu2 = built(fmu_root, scene_paths["chain_10"])
    r3 = fmpy.simulate_fmu(str(fmu3.path), stop_time=0.05, output_interval=0.01, output=["X", "T"])
    r2 = fmpy.simulate_fmu(str(fmu2.path), stop_time=0.05, output_interval=0.01,
                           output=fmu2.names("X") + fmu2.names("T"))
    np.testing.assert_array_equal(r3["time"], r2["time"])
    X2 = np.stack([r2[n] for n in fmu2.names("X")], axis=1).reshape(len(r2), -1, 3)
    T2 = np.stack([r2[n] for n in fmu2.names("T")], axis=1)
    np.testing.assert_array_equal(np.asarray(r3["X"]).reshape(len(r3), -1, 3), X2)
    np.testing.assert_array_equal(np.asarray(r3["T"]).reshape(len(r3), -1), T2)
    assert np.ptp(X2[:, -1, 2]) > 0  # the chain falls


# ---------------------------------------------------------------------------- directional derivatives
def test_directional_derivative_of_the_tensions_is_the_finite_difference(scene_paths, fmi3_root):
    """T is affine in F ((25)-(26): B is linear in the forces), so a difference quotient with a large step is exact to
    round-off: the derivative along a seed on all of F."""
    fmu = fmi3_built(fmi3_root, scene_paths["chain_10"])
    s = Slave3(fmu)
    s.initialize()
    s.step(0.0)
    n = fmu.size("F")
    F0 = forces(n, 0.01)
    seed = np.array([math.cos(0.7 * j) for j in range(n)])
    s.set("F", F0)
    T0 = s.get("T")
    d = s.slave.getDirectionalDerivative([s.vr("T")], [s.vr("F")], list(seed), nSensitivity=fmu.size("T"))
    eps = 1.0
    s.set("F", F0 + eps * seed)
    fd = (s.get("T") - T0) / eps
    scale = np.abs(T0).max()
    assert np.abs(np.array(d) - fd).max() <= 1e-10 * scale, (d, fd)
    assert np.abs(fd).max() > 1e-3 * scale  # the seed moves the tensions
    # no feedthrough into the positions
    assert s.slave.getDirectionalDerivative([s.vr("X")], [s.vr("F")], list(seed), nSensitivity=fmu.size("X")) == \
        [0.0] * fmu.size("X")
    s.free()


# ---------------------------------------------------------------------------- FMU states
def test_fmu_states_replay_bit_for_bit_and_serialize_into_a_fresh_instance(scene_paths, fmi3_root, fmu_root):
    fmu = fmi3_built(fmi3_root, scene_paths[DRIVEN])
    import linknet_core as ln
    scene = ln.Scene.from_dict(drive.SCENES[DRIVEN])
    motion = drive.anchor_motion(scene.X0[drive.ANCHOR[DRIVEN] - 1], n_steps=6, h=H)

    def coast(s, n_first, n_last):
        rows = []
        for n in range(n_first, n_last):
            s.set("F", forces(fmu.size("F"), n * H))
            for name, values in zip("PVA", motion):
                s.set(name, values[n])
            s.step(n * H)
            rows.append(np.concatenate([s.get("X"), s.get("U"), s.get("T"), s.get("Jreact")]))
        return np.array(rows)

    a = Slave3(fmu, "a")
    a.initialize()
    coast(a, 0, 2)
    state = a.slave.getFMUState()
    first = coast(a, 2, 6)
    a.slave.setFMUState(state)
    np.testing.assert_array_equal(coast(a, 2, 6), first)
    data = a.slave.serializeFMUState(state)
    a.slave.freeFMUState(state)
    b = Slave3(fmu, "b")
    b.initialize()
    restored = b.slave.deserializeFMUState(data)
    b.slave.setFMUState(restored)
    np.testing.assert_array_equal(coast(b, 2, 6), first)
    # damaged bytes and another FMU's state are refused, naming why; the instance goes on
    from fmpy.fmi1 import FMICallException
    damaged = bytearray(data)
    damaged[-1] ^= 1
    with pytest.raises(FMICallException):
        b.slave.deserializeFMUState(bytes(damaged))
    other = Slave3(fmi3_built(fmi3_root, scene_paths["chain_10"]), "other")
    other.initialize()
    with pytest.raises(FMICallException):
        other.slave.deserializeFMUState(data)
    # the FMI 2.0 FMU of the same scene: its state is another build's
    s2 = Slave2(built(fmu_root, scene_paths[DRIVEN]))
    fmi2_state = s2.slave.serializeFMUstate(s2.slave.getFMUstate())
    s2.slave.freeInstance()
    with pytest.raises(FMICallException):
        b.slave.deserializeFMUState(fmi2_state)
    assert any("checksum mismatch" in m for m in b.errors()), b.log
    assert sum("a state of another FMU" in m for m in b.errors()) == 1, b.log
    assert any("a state of another FMU" in m for m in other.errors()), other.log
    b.slave.setFMUState(restored)
    np.testing.assert_array_equal(coast(b, 2, 6), first)
    for s in (a, b, other):
        s.free()


# ---------------------------------------------------------------------------- bad input
def test_bad_input_is_fmi3_error_with_a_message_and_the_fmu_goes_on(scene_paths, fmi3_root):
    from fmpy.fmi3 import fmi3Boolean, fmi3Float64, fmi3Int32, fmi3ValueReference
    fmu = fmi3_built(fmi3_root, scene_paths["chain_10"])
    s = Slave3(fmu)
    vr = fmi3ValueReference
    nF = fmu.size("F")

    def set_float64(vrs, values):
        return s.raw("fmi3SetFloat64", (vr * len(vrs))(*vrs), len(vrs), (fmi3Float64 * len(values))(*values),
                     len(values))

    step_outputs = [fmi3Boolean(), fmi3Boolean(), fmi3Boolean(), fmi3Float64()]
    refs = [ctypes.byref(x) for x in step_outputs]
    cases = [  # (call, words of the logged message)
        (lambda: s.raw("fmi3DoStep", fmi3Float64(0.0), fmi3Float64(H), fmi3Boolean(True), *refs),
         "call fmi3ExitInitializationMode first"),
        (lambda: set_float64([s.vr("F")], [1.0] * (nF - 1)), f"hold {nF} values, but nValues is {nF - 1}"),
        (lambda: set_float64([s.vr("X")], [0.0] * fmu.size("X")), "X[1,1]"),
        (lambda: set_float64([999], [1.0]), "999 is not a value reference of this FMU"),
        (lambda: set_float64([s.vr("F")], [float("nan")] + [0.0] * (nF - 1)), "F[2,1]"),
        (lambda: set_float64([s.vr("time")], [1.0]), "time, the independent variable"),
        (lambda: set_float64([s.vr("integrator")], [1.0]), "a variable of type String"),
        (lambda: s.raw("fmi3GetInt32", (vr * 1)(s.vr("F")), 1, (fmi3Int32 * nF)(), nF), "not Int32"),
        (lambda: s.raw("fmi3SetFloat64", None, 1, None, 0), "valueReferences is NULL"),
        (lambda: s.raw("fmi3EnterEventMode"), "no event mode"),
        (lambda: s.raw("fmi3SetFMUState", ctypes.c_void_p(12345)), "not a live state of this FMU instance"),
    ]
    for call, words in cases:
        before = len(s.log)
        assert call() == ERROR, words
        new = [m for status, _, m in s.log[before:] if status == ERROR]
        assert len(new) == 1 and words in new[0], (words, new)
    s.initialize()
    cases = [
        (lambda: s.raw("fmi3DoStep", fmi3Float64(0.0), fmi3Float64(-H), fmi3Boolean(True), *refs),
         "must be finite and > 0"),
        (lambda: s.raw("fmi3DoStep", fmi3Float64(0.5), fmi3Float64(H), fmi3Boolean(True), *refs),
         "differs from the FMU's time"),
        (lambda: s.raw("fmi3DoStep", fmi3Float64(0.0), fmi3Float64(H), fmi3Boolean(True), None, *refs[1:]),
         "eventHandlingNeeded is NULL"),
        (lambda: set_float64([s.vr("R")], [2.0] * fmu.size("R")), "R["),
        (lambda: s.raw("fmi3GetDirectionalDerivative", (vr * 1)(s.vr("T")), 1, (vr * 1)(s.vr("M")), 1,
                       (fmi3Float64 * fmu.size("M"))(), fmu.size("M"), (fmi3Float64 * fmu.size("T"))(), fmu.size("T")),
         "M[2]"),
    ]
    for call, words in cases:
        before = len(s.log)
        assert call() == ERROR, words
        new = [m for status, _, m in s.log[before:] if status == ERROR]
        assert len(new) == 1 and words in new[0], (words, new)
    # after all that, the instance runs as a fresh one does
    fresh = Slave3(fmu, "fresh")
    fresh.initialize()
    np.testing.assert_array_equal(run(s, fmu, n_steps=2)["X"], run(fresh, fmu, n_steps=2)["X"])
    for x in (s, fresh):
        x.free()


def test_instantiation_refusals_are_logged(scene_paths, fmi3_root):
    from fmpy.fmi3 import FMU3Slave
    fmu = fmi3_built(fmi3_root, scene_paths["chain_10"])
    log = []
    slave = FMU3Slave(guid="{not-this-one}", unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident)
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(logMessage=lambda env, status, category, message: log.append(message.decode()))
    assert len(log) == 1 and "is not this FMU's" in log[0]
    slave = FMU3Slave(guid=fmu.md.guid, unzipDirectory=str(fmu.dir), modelIdentifier=fmu.ident)
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(eventModeUsed=True,
                          logMessage=lambda env, status, category, message: log.append(message.decode()))
    assert "no event mode" in log[-1]


def test_a_repeated_discarded_step_asks_the_master_to_stop(scene_paths, fmi3_root):
    """A step the solver cannot take (more internal steps than one advance allows) is fmi3Discard with
    terminateSimulation false (a shorter step can succeed); the same step asked again from the same state is
    answered at once with terminateSimulation true; lastSuccessfulTime stays at the start; a shorter step goes on."""
    from fmpy.fmi3 import fmi3Boolean, fmi3Float64
    fmu = fmi3_built(fmi3_root, scene_paths["pendulum"], integrator="rattle", step=1e-3)
    s = Slave3(fmu)
    s.initialize()
    out = [fmi3Boolean(), fmi3Boolean(), fmi3Boolean(), fmi3Float64()]

    def step(h):
        status = s.raw("fmi3DoStep", fmi3Float64(0.0), fmi3Float64(h), fmi3Boolean(True),
                       *[ctypes.byref(x) for x in out])
        return status, out[1].value, out[3].value

    assert step(1e17) == (DISCARD, False, 0.0)
    assert step(1e17) == (DISCARD, True, 0.0)
    assert "discarded before, from this same state" in s.log[-1][2]
    assert step(H) == (OK, False, H)
    s.free()


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
# ---------------------------------------------------------------------------- sources/
@pytest.mark.skipif(GCC is None, reason="no C compiler")
def test_sources_build_a_binary_exporting_only_fmi3_with_the_shipped_results(scene_paths, fmi3_root, tmp_path):
    """A tool compiles sources/*.c as the buildDescription.xml lists them (gcc, warnings as errors, pedantic C99):
    the binary exports every function fmi3Functions.h declares and nothing else, and runs as the shipped one, bit
    for bit."""
    import shutil
    import subprocess
    fmu = fmi3_built(fmi3_root, scene_paths["chain_10"])
    copy = tmp_path / "unzipped"
    shutil.copytree(fmu.dir, copy)
    binary = copy / "binaries" / "x86_64-linux" / f"{fmu.ident}.so"
    binary.unlink()
    subprocess.run([GCC, "-std=c99", "-O2", "-ffp-contract=off", "-fno-math-errno", "-Wall", "-Wextra", "-Werror",
                    "-pedantic", "-shared", "-fPIC", *sorted(str(p) for p in (copy / "sources").glob("*.c")), "-lm",
                    "-o", str(binary)], check=True, capture_output=True, text=True)
    exports = subprocess.run(["nm", "-D", "--defined-only", str(binary)], check=True, capture_output=True,
                             text=True).stdout.split()[2::3]
    import re
    declared = re.findall(r"FMI3_Export\s+\w+TYPE\s+(\w+);",
                          (ROOT / "fmu_src" / "native" / "fmi3" / "fmi3Functions.h").read_text())
    assert len(declared) > 70 and sorted(exports) == sorted(declared)  # every function of the standard, no other
    rebuilt = Fmi3Built.__new__(Fmi3Built)
    rebuilt.__dict__.update(fmu.__dict__, dir=copy)
    runs = []
    for f in (fmu, rebuilt):
        s = Slave3(f)
        s.initialize()
        runs.append(run(s, f))
        s.free()
    for key in runs[0]:
        np.testing.assert_array_equal(runs[1][key], runs[0][key], err_msg=key)


@pytest.mark.slow  # CI's slow step runs it (.ci/run): kept out of make test's 5 minutes
def test_every_platform_in_its_fmi3_folder(scene_paths, fmi3_root):
    """binaries/<FMI 3.0 platform tuple>/: each binary is of its tuple's machine (read from its header); the macOS
    universal binary is split into a thin slice per tuple; the host's binary runs (the other tests)."""
    import struct
    out = fmi3_root / "pendulum_all_platforms.fmu"
    build_scene_fmi3(str(scene_paths["pendulum"]), out, platforms="all", quiet=True)
    with zipfile.ZipFile(out) as z:
        binaries = {n: z.read(n) for n in z.namelist() if n.startswith("binaries/")}
    machine = {}
    for name, data in binaries.items():
        if data[:4] == b"\x7fELF":
            machine[name] = ("elf", struct.unpack_from("<H", data, 18)[0])
        elif data[:2] == b"MZ":
            machine[name] = ("pe", struct.unpack_from("<H", data, struct.unpack_from("<I", data, 0x3C)[0] + 4)[0])
        else:
            machine[name] = ("mach-o", *struct.unpack_from("<Ii", data))
    assert machine == {
        "binaries/x86_64-linux/pendulum.so": ("elf", 0x3E),
        "binaries/aarch64-linux/pendulum.so": ("elf", 0xB7),
        "binaries/x86_64-windows/pendulum.dll": ("pe", 0x8664),
        "binaries/x86_64-darwin/pendulum.dylib": ("mach-o", 0xFEEDFACF, 0x01000007),
        "binaries/aarch64-darwin/pendulum.dylib": ("mach-o", 0xFEEDFACF, 0x0100000C),
    }


def test_a_step_no_retry_can_fix_sets_terminate_simulation_at_once(fmi3_root):
    """Explicit steps beyond their stability limit (a chain whose masses grow by 1e12, RATTLE at 1e-4 s): the model
    knows that no shorter communication step succeeds, so the first discard already says terminateSimulation, with
    the reason logged, and lastSuccessfulTime is the start."""
    import json

    from fmpy.fmi3 import fmi3Boolean, fmi3Float64
    from test_native_fmu_failures import mass_ratio_chain
    path = fmi3_root / "mass_ratio_chain.json"
    path.write_text(json.dumps(mass_ratio_chain().to_dict()))
    fmu = fmi3_built(fmi3_root, path, integrator="rattle", step=1e-4)
    s = Slave3(fmu)
    s.initialize()
    out = [fmi3Boolean(), fmi3Boolean(), fmi3Boolean(), fmi3Float64()]
    status = s.raw("fmi3DoStep", fmi3Float64(0.0), fmi3Float64(0.01), fmi3Boolean(True),
                   *[ctypes.byref(x) for x in out])
    assert (status, out[1].value, out[3].value) == (DISCARD, True, 0.0)
    discards = [m for status, _, m in s.log if status == DISCARD]
    assert discards and "the step exceeds the stability limit of explicit steps" in discards[-1]
    assert "terminateSimulation is true" in discards[-1]
    s.free()


# ---------------------------------------------------------------------------- a C host, no Python
@pytest.mark.skipif(GCC is None, reason="no C compiler")
def test_a_plain_c_host_runs_it_without_python_leaks_nothing_and_gets_the_same_numbers(scene_paths, fmi3_root,
                                                                                     tmp_path, no_python_env):
    """tests/fmu_native/fmi3_host.c (dlopen, an environment of only an empty PATH): a run with forces, a state
    serialized, restored and replayed, seven bad calls refused, three instantiate/free cycles, under valgrind where
    it is installed (no memory error, nothing left allocated); its positions equal fmpy's run of the FMU bit for
    bit."""
    import shutil
    import subprocess
    exe = tmp_path / "fmi3_host"
    subprocess.run([GCC, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", "-I",
                    str(ROOT / "fmu_src" / "native" / "fmi3"), "-o", str(exe),
                    str(Path(__file__).parent / "fmi3_host.c"), "-ldl", "-lm"], check=True)
    fmu = fmi3_built(fmi3_root, scene_paths["chain_10"])
    steps, cycles = 4, 3
    command = [str(exe), str(fmu.dir / "binaries" / "x86_64-linux" / f"{fmu.ident}.so"), fmu.md.guid,
               str(fmu.var["F"].valueReference), str(fmu.size("F")), str(fmu.var["X"].valueReference),
               str(fmu.size("X")), str(steps), str(cycles)]
    valgrind = shutil.which("valgrind")
    if valgrind:
        command = [valgrind, "-q", "--error-exitcode=9", "--leak-check=full", "--show-leak-kinds=all",
                   "--errors-for-leak-kinds=all"] + command
    proc = subprocess.run(command, capture_output=True, text=True, env=no_python_env, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    lines = proc.stdout.split()
    assert lines[-3:] == ["errors", "logged", str(7 * cycles)]
    host_X = np.array([[float.fromhex(x) for x in line.split(",")] for line in lines[:-3]])
    s = Slave3(fmu)
    s.initialize()
    fmpy_X = run(s, fmu, n_steps=steps)["X"][1:]
    s.free()
    np.testing.assert_array_equal(host_X, fmpy_X)
