"""The native FMU's scene is a resource file (fmu_src/native/fmu_resource.h, README.md there): the binaries and
sources are the same for every scene, built once and then taken from the cache; the resource is the documented
format and holds the scene; a missing, truncated, damaged or foreign resource, or a resource location that names
none, is answered by fmi2Instantiate / fmi3InstantiateCoSimulation with NULL and one logged message naming the file
(or the location) and the rule broken, and the process goes on."""
from __future__ import annotations

import ctypes
import json
import shutil
import struct
import uuid
import zipfile
import zlib
from pathlib import Path
from urllib.parse import quote

import numpy as np
import pytest

from native_fmu_support import MODELS, Built, built, host_options, input_mass, library_rows, parse_rows, run_host
import build_fmu
import linknet_core as ln
from native import build as native_build

RESOURCE = "resources/linknet_scene.bin"


# ---------------------------------------------------------------------------- the format, read independently
def read_resource(data: bytes) -> dict:
    """The entries of a resource file (name -> numpy array, or list of texts for 'c'), read as README.md describes
    the format, every rule of it checked."""
    magic, version, bom, size, n, entry_size, crc, zero1, zero2 = struct.unpack_from("<8sIIQIIIIQ", data)
    assert magic == b"LNKSCENE" and version == 1 and bom == 0x01020304 and (zero1, zero2) == (0, 0)
    assert size == len(data) and entry_size == 64 and zlib.crc32(data[48:]) == crc
    dtypes = {"q": "<i8", "i": "<i4", "d": "<f8", "B": "u1", "Q": "<u8"}
    out = {}
    for i in range(n):
        name, code, element, count, offset = struct.unpack_from("<40sIIQQ", data, 48 + 64 * i)
        name, code = name.rstrip(b"\0").decode(), chr(code)
        assert offset % 8 == 0 and 48 + 64 * n <= offset and offset + count * element <= len(data), name
        raw = data[offset:offset + count * element]
        if code == "c":
            assert raw == b"" or raw.endswith(b"\0"), name
            out[name] = [s.decode() for s in raw.split(b"\0")[:-1]]
        else:
            assert np.dtype(dtypes[code]).itemsize == element, name
            out[name] = np.frombuffer(raw, dtypes[code])
    return out


def write_resource(entries: dict) -> bytes:
    """A resource of these entries (name -> (code, values)), through the builder's own writer."""
    resource = native_build.Resource()
    for name, (code, values) in entries.items():
        if code == "c":
            resource.texts(name, values)
        else:
            resource.add(name, code, values)
    return resource.to_bytes()


def test_the_resource_is_the_documented_format_and_holds_the_scene(fmu_root):
    fmu = built(fmu_root, "chain_10")
    entries = read_resource((fmu.dir / RESOURCE).read_bytes())
    scene = json.loads((MODELS / "chain_10.json").read_text())
    masses = scene["masses"]
    assert entries["scene.mass_names"] == [m["name"] for m in masses]
    assert entries["scene.guid"] == [fmu.guid]
    free = [k for k, m in enumerate(masses) if not m.get("fixed")]
    np.testing.assert_array_equal(entries["scene.mass"][free], [masses[k]["mass"] for k in free])
    np.testing.assert_array_equal(entries["model.inv_m"][free], [1.0 / masses[k]["mass"] for k in free])
    assert entries["model.inv_m"][0] == 0.0  # the anchor
    np.testing.assert_array_equal(entries["scene.gravity"], scene["gravity"])
    np.testing.assert_array_equal(entries["scene.X0"].reshape(-1, 3), [m["position"] for m in masses])
    ends = list(zip(entries["model.k1"] + 1, entries["model.k2"] + 1))  # the scene file numbers masses from 1
    assert ends == [(link["a"], link["b"]) for link in scene["links"]]
    np.testing.assert_array_equal(entries["model.R"], [link["length"] for link in scene["links"]])
    assert entries["scene.n_methods"][0] == len(entries["scene.method_names"]) == len(ln.METHODS)
    assert len(entries["scene.variable_names"]) == entries["scene.n_real"][0] == max(fmu.vr.values()) - 1


# ---------------------------------------------------------------------------- one binary for every scene
def _compiler_calls(monkeypatch) -> list:
    calls = []
    real = native_build._run_compiler

    def counted(cmd, cwd):
        calls.append(cmd)
        return real(cmd, cwd)

    monkeypatch.setattr(native_build, "_run_compiler", counted)
    return calls


def test_a_further_scene_compiles_nothing_and_runs_on_the_same_binary(fmu_root, tmp_path, monkeypatch, host,
                                                                      no_python_env):
    """A heavier chain under the first chain's name: its FMU's binary and sources are the first FMU's byte for byte,
    built without calling the compiler, and it runs its own scene, as linknet_core's Simulator does."""
    first = built(fmu_root, "chain_10")
    data = json.loads((MODELS / "chain_10.json").read_text())
    for m in data["masses"]:
        if "mass" in m:
            m["mass"] *= 3.0
    path = tmp_path / "chain_10.json"
    path.write_text(json.dumps(data))
    calls = _compiler_calls(monkeypatch)
    out = build_fmu.build_scene_fmu(str(path), tmp_path / "heavy.fmu", quiet=True, native=True)
    assert calls == []  # the first chain's build left the binary in the cache
    with zipfile.ZipFile(first.path) as a, zipfile.ZipFile(out) as b:
        code = [n for n in a.namelist() if n.startswith(("binaries/", "sources/"))]
        assert code and sorted(code) == sorted(n for n in b.namelist() if n.startswith(("binaries/", "sources/")))
        for name in code:
            assert a.read(name) == b.read(name), name
        assert a.read(RESOURCE) != b.read(RESOURCE)
    from fmpy import read_model_description
    md = read_model_description(str(out))
    where = tmp_path / "heavy"
    with zipfile.ZipFile(out) as z:
        z.extractall(where)
    heavy = Built(out, where, md.coSimulation.modelIdentifier, md.guid,
                  {v.name: v.valueReference for v in md.modelVariables}, md)
    got = parse_rows(run_host(host, no_python_env, "run", heavy, 0.0, 5, 0.01, *host_options(heavy, "rattle")))
    want = library_rows(ln.load_scene(path), heavy, "rattle")
    np.testing.assert_array_equal(got, want)
    assert input_mass(heavy) == input_mass(first)


def test_a_new_model_identifier_is_only_linked(tmp_path, monkeypatch):
    """The cached objects are linked under the new name (one link per target), nothing is compiled."""
    built_once = build_fmu.build_scene_fmu(str(MODELS / "pendulum.json"), tmp_path / "p.fmu", quiet=True, native=True)
    assert built_once.exists()
    data = json.loads((MODELS / "pendulum.json").read_text())
    data["name"] = f"pendulum_{uuid.uuid4().hex}"  # a name no build has used: its binary is not cached yet
    path = tmp_path / "renamed.json"
    path.write_text(json.dumps(data))
    calls = _compiler_calls(monkeypatch)
    try:
        build_fmu.build_scene_fmu(str(path), tmp_path / "renamed.fmu", quiet=True, native=True)
        assert calls and all("-c" not in cmd and "-shared" in cmd for cmd in calls), calls
        assert len(calls) == sum(len(native_build.PLATFORMS[f].targets) for f in native_build.platforms_from(None))
    finally:  # the cache keeps no binary of this throwaway name
        for linked in native_build.cache_dir().glob(f"*/linked/{data['name']}.*"):
            linked.unlink()


# ---------------------------------------------------------------------------- bad resources
def _slave(fmu: Built, where: Path):
    """An fmpy FMI 2.0 slave of the FMU unzipped at ``where`` and the messages it logs."""
    from fmpy.fmi2 import FMU2Slave, defaultCallbacks, fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
    log = []
    callbacks = fmi2CallbackFunctions()
    callbacks.logger = fmi2CallbackLoggerTYPE(lambda env, name, status, category, message:
                                              log.append((status, message.decode())))
    callbacks.allocateMemory = defaultCallbacks.allocateMemory
    callbacks.freeMemory = defaultCallbacks.freeMemory
    slave = FMU2Slave(guid=fmu.guid, unzipDirectory=str(where), modelIdentifier=fmu.ident, instanceName="probe")
    return slave, callbacks, log


def _refused(fmu: Built, where: Path) -> str:
    """The one message of an fmi2Instantiate that returned NULL for the FMU unzipped at ``where``."""
    slave, callbacks, log = _slave(fmu, where)
    with pytest.raises(Exception, match="Failed to instantiate"):
        slave.instantiate(callbacks=callbacks)
    assert len(log) == 1 and log[0][0] == 3, log  # fmi2Error
    slave.freeLibrary()
    return log[0][1]


def _still_runs(fmu: Built) -> None:
    """The good FMU, in the same process, after the refusals: instantiated and stepped."""
    slave, callbacks, log = _slave(fmu, fmu.dir)
    slave.instantiate(callbacks=callbacks)
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    tip = [fmu.vr[f"X[{max(int(n[2:].split(',')[0]) for n in fmu.vr if n.startswith('X['))},3]"]]
    before = slave.getReal(tip)[0]
    slave.doStep(0.0, 0.01)  # fmpy raises on a status other than OK
    assert slave.getReal(tip)[0] < before and log == []  # the free end of the chain falls
    slave.terminate()
    slave.freeInstance()
    slave.freeLibrary()


def _damaged(data: bytes, entries: dict) -> dict:
    def without(name):
        return {k: v for k, v in entries.items() if k != name}

    def replaced(name, code, values):
        return {**entries, name: (code, values)}

    k = entries["scene.K"][1][0]
    n_model = sum(name.startswith("model.") for name in entries)  # ln_model's fields the resource holds
    return {
        "truncated": (data[:-100], "truncated: its header says"),
        "format": (data[:8] + struct.pack("<I", 99) + data[12:], "format version 99, this FMU's binary reads "
                   "version 1"),
        "byte order": (data[:12] + struct.pack(">I", 0x01020304) + data[16:], "another byte order"),
        "one bit": (data[:-9] + bytes([data[-9] ^ 0x10]) + data[-8:], "its checksum does not match its contents"),
        "not a resource": (b"PK\x03\x04" + bytes(200), "not a linknet scene resource"),
        "empty": (b"", "shorter than the header"),
        "longer": (data + b"\0" * 8, "longer than the"),
        "missing entry": (write_resource(without("model.k1")),
                          f"has {n_model - 1} entries model.*, this FMU's binary reads {n_model}"),
        "renamed entry": (write_resource({**without("model.k1"), "model.k1x": entries["model.k1"]}),
                          "has no entry model.k1 "),
        "count": (write_resource(replaced("scene.K", "q", [k + 1])), "entry scene.mass_names holds"),
        "type": (write_resource(replaced("model.R", "i", [1] * len(entries["model.R"][1]))),
                 "entry model.R has elements of type 'i' and 4 bytes, this FMU reads 'd' of 8 bytes"),
        "index": (write_resource(replaced("model.k2", "q", [k + 5] * len(entries["model.k2"][1]))),
                  "does not hold a consistent scene: a link joins a mass out of range"),
        "extra field": (write_resource({**entries, "model.extra": ("d", [1.0])}),
                        "entries model.*, this FMU's binary reads"),
    }


def test_a_bad_resource_is_refused_at_instantiation_naming_the_file_and_the_rule(fmu_root, tmp_path):
    fmu = built(fmu_root, "chain_10")
    data = (fmu.dir / RESOURCE).read_bytes()
    codes = {"q": "q", "i": "i", "d": "d", "B": "B", "Q": "Q"}
    entries = {}
    for name, values in read_resource(data).items():
        if isinstance(values, list):
            entries[name] = ("c", values)
        else:
            entries[name] = (codes[{"<i8": "q", "<i4": "i", "<f8": "d", "|u1": "B", "<u8": "Q"}[values.dtype.str]],
                             values)
    assert read_resource(write_resource(entries)).keys() == read_resource(data).keys()  # the rewrite is faithful
    where = tmp_path / "fmu"
    shutil.copytree(fmu.dir, where)
    resource = where / RESOURCE
    for case, (damaged, rule) in _damaged(data, entries).items():
        resource.write_bytes(damaged)
        message = _refused(fmu, where)
        assert str(resource) in message and rule in message, (case, message)
    resource.unlink()
    message = _refused(fmu, where)
    assert str(resource) in message and "cannot be opened: it is missing or not readable" in message
    _still_runs(fmu)


# ---------------------------------------------------------------------------- resource locations
def _instantiate_at(fmu: Built, location) -> tuple[bool, list]:
    """fmi2Instantiate of the FMU with this fmuResourceLocation (bytes or None): whether it gave an instance (then
    freed), and what it logged."""
    slave, callbacks, log = _slave(fmu, fmu.dir)
    component = slave.fmi2Instantiate(b"probe", 1, fmu.guid.encode(), location, ctypes.byref(callbacks), 0, 0)
    if component:
        slave.fmi2FreeInstance(component)
    slave.freeLibrary()
    return bool(component), log


def test_resource_locations_as_hosts_write_them(fmu_root, tmp_path):
    """file:///path with percent-encoding (a folder with a space, a percent sign and a non-ASCII letter),
    file:/path and file://localhost/path are the resources folder, and so is the path unencoded (as hosts that build
    the URI by hand write it); NULL, another scheme, another host, a relative path and %00 are refused, naming the
    location."""
    fmu = built(fmu_root, "chain_10")
    odd = tmp_path / "an FMU 100% ünzipped"
    shutil.copytree(fmu.dir, odd)
    resources = odd / "resources"
    encoded = quote(str(resources))
    assert "%25" in encoded and "%20" in encoded and "%C3%BC" in encoded
    for location in (resources.as_uri(), "file:" + encoded, "file://localhost" + encoded, resources.as_uri() + "/",
                     "file://" + str(resources)):
        ok, log = _instantiate_at(fmu, location.encode())
        assert ok and log == [], (location, log)
    for location, rule in ((None, "fmuResourceLocation is NULL"), (b"", "fmuResourceLocation is empty"),
                           (b"http://example.com/resources", "is not a file: URI"),
                           (b"file://server/share/resources", 'names the host "server"'),
                           (b"file:resources", "has no absolute path"),
                           # the logged text has its % doubled, as the FMI 2.0 logger's format requires
                           (b"file:///tmp/a%00b", "has %%00 (a NUL character) in its path"),
                           ((odd / "binaries").as_uri().encode(), "cannot be opened")):
        ok, log = _instantiate_at(fmu, location)
        assert not ok and len(log) == 1 and rule in log[0][1], (location, log)


def test_fmi3_reads_its_resource_and_refuses_a_damaged_one(tmp_path):
    from fmpy import read_model_description
    from fmpy.fmi3 import FMU3Slave
    out = build_fmu.build_scene_fmu(str(MODELS / "chain_10.json"), tmp_path / "c3.fmu", quiet=True, native=True,
                                    fmi_version=3)
    where = tmp_path / "c3"
    with zipfile.ZipFile(out) as z:
        z.extractall(where)
    entries = read_resource((where / RESOURCE).read_bytes())
    names = entries["fmi3.names"]
    assert names[0] == "time" and {"X", "T", "F", "integrator", "estimate_error"} <= set(names)
    md = read_model_description(str(out))
    ident = md.coSimulation.modelIdentifier
    log = []

    def instantiate():
        slave = FMU3Slave(guid=md.guid, unzipDirectory=str(where), modelIdentifier=ident)
        slave.instantiate(logMessage=lambda env, status, category, message: log.append(message.decode()))
        return slave

    slave = instantiate()  # the resource as built
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    slave.doStep(0.0, 0.01)
    x = slave.getFloat64([names.index("X")], nValues=3 * 11)
    assert np.isfinite(x).all() and log == []
    slave.terminate()
    slave.freeInstance()
    data = (where / RESOURCE).read_bytes()
    (where / RESOURCE).write_bytes(data[:len(data) // 2])
    with pytest.raises(Exception, match="Failed to instantiate"):
        instantiate()
    assert len(log) == 1 and str(where / RESOURCE) in log[0] and "truncated" in log[0], log
