"""The pythonfmu FMU's contract: every FMI entry point guarded (never fmi2Fatal, the instance usable
after any bad call), misuse refused with a logged message, startTime honoured, FMU states carrying an identity,
a C host that calls exit() ends, and the host requirements (libpython promotion, a clear reason for a failed
fmi2Instantiate). FMU clients run in fresh processes (tests/fmu_harness.py)."""
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

from contract_support import MODELS, extract
from fmu_harness import FMU_CLIENT_LIB, run_client

DISCARD, ERROR, FATAL = 2, 3, 4


def _calls(fmu, workdir, body):
    """Run `body` (which fills `cases[name] = status`) in a fresh fmpy client; returns cases and the log."""
    out = run_client(f"""
{FMU_CLIENT_LIB}
import json
from fmpy.fmi2 import fmi2ValueReference, fmi2Real, fmi2Integer, fmi2Boolean, fmi2String
cases, logs = {{}}, {{}}
def call(name, f, *args):
    LOG.clear()
    try:
        f(*args); status = 0
    except FMICallException as e:
        status = e.status
    except Exception as e:  # fmpy's own argument handling
        status = -1
    cases[name] = status
    logs[name] = [m for s, m in LOG]
{body}
save(cases=np.array(json.dumps(cases)), logs=np.array(json.dumps(logs)))
""", workdir)
    return json.loads(str(out["cases"])), json.loads(str(out["logs"]))


def test_every_entry_point_with_bad_arguments_never_fatal_and_the_instance_stays_usable(pendulum_fmu, tmp_path):
    """The general rule: each FMI entry point called with bad arguments (unknown or wrong-type value references,
    garbage states, misuse of the call order) answers without fmi2Fatal, logs a message, and a good run follows."""
    cases, logs = _calls(pendulum_fmu, tmp_path, f"""
f = Fmu({str(pendulum_fmu)!r})
s, v = f.slave, f.vr
bad = [99999]
call('doStep before initialization', s.doStep, 0.0, 0.01)
call('setupExperiment nan start', s.setupExperiment, None, float('nan'))
s.setupExperiment(startTime=0.0); s.enterInitializationMode()
call('getString unknown vr', s.getString, bad)
call('getString of a Real', s.getString, [v['T[1]']])
call('setString unknown vr', s.setString, bad, ['x'])
call('setString of a Real', s.setString, [v['M[2]']], ['x'])
call('getInteger', s.getInteger, [0])
call('setInteger', s.setInteger, [0], [1])
call('getBoolean', s.getBoolean, [0])
call('setBoolean', s.setBoolean, [0], [True])
call('getReal unknown vr', s.getReal, bad)
call('setReal unknown vr', s.setReal, bad, [1.0])
call('setReal output', s.setReal, [v['X[2,1]']], [1.0])
call('setReal tolerance 5', s.setReal, [v['tolerance']], [5.0])
s.setReal([v['tolerance']], [1e-8])
s.exitInitializationMode()
call('doStep ok', s.doStep, 0.0, 0.01)
st = s.getFMUstate()
call('deSerialize garbage', lambda: s.setFMUstate(s.deSerializeFMUstate(b'not a state at all')))
ser = bytearray(s.serializeFMUstate(st)); ser[-5] ^= 0xFF
call('deSerialize damaged', lambda: s.setFMUstate(s.deSerializeFMUstate(bytes(ser))))
call('deSerialize truncated', lambda: s.setFMUstate(s.deSerializeFMUstate(bytes(ser[:40]))))
call('doStep after all that', s.doStep, 0.01, 0.01)
call('setFMUstate own', s.setFMUstate, st)
call('doStep after restore', s.doStep, 0.01, 0.01)
call('terminate', s.terminate)
""")
    assert FATAL not in cases.values(), cases
    good = ("doStep ok", "doStep after all that", "setFMUstate own", "doStep after restore", "terminate")
    for name in good:
        assert cases[name] == 0, (name, cases[name], logs[name])
    for name, status in cases.items():  # the status the slave logged is the call's (the binary's front layer)
        if name not in good:
            assert status == ERROR and logs[name], f"{name}: answered {status}, logged {logs[name]}"
    assert "fmi2ExitInitializationMode" in logs["doStep before initialization"][0]
    words = {"getInteger": "no Integer", "setBoolean": "no Boolean", "getString of a Real": "not a String",
             "setReal output": "is an output", "getReal unknown vr": "unknown value reference",
             "setReal tolerance 5": "tolerance",
             "deSerialize garbage": "not a linknet FMU state", "deSerialize damaged": "checksum",
             "deSerialize truncated": "a state of the wrong size"}  # refused at fmi2DeSerializeFMUstate (the front)
    for name, word in words.items():
        assert any(word in m for m in logs[name]), (name, logs[name])


def test_bad_state_handles_are_refused_with_a_message_and_the_instance_stays_usable(pendulum_fmu, tmp_path):
    """NULL, made-up and freed fmi2FMUstate handles and NULL out-pointers are refused (fmi2Error, logged) by the
    binary's front layer before pythonfmu would take them for Python objects; good states still work."""
    cases, logs = _calls(pendulum_fmu, tmp_path, f"""
import ctypes
f = Fmu({str(pendulum_fmu)!r}); f.init()
s = f.slave
made_up = ctypes.c_void_p(ctypes.addressof(ctypes.create_string_buffer(64)))
size = ctypes.c_size_t()
call('setFMUstate NULL', s.fmi2SetFMUstate, s.component, None)
call('setFMUstate made-up handle', s.fmi2SetFMUstate, s.component, made_up)
call('getFMUstate NULL pointer', s.fmi2GetFMUstate, s.component, None)
call('freeFMUstate NULL pointer', s.fmi2FreeFMUstate, s.component, None)
call('freeFMUstate made-up handle', s.fmi2FreeFMUstate, s.component, ctypes.byref(made_up))
call('serializedFMUstateSize NULL', s.fmi2SerializedFMUstateSize, s.component, None, ctypes.byref(size))
call('serializeFMUstate NULL', s.fmi2SerializeFMUstate, s.component, None, ctypes.create_string_buffer(8), 8)
st = s.getFMUstate()
call('serializeFMUstate small buffer', s.fmi2SerializeFMUstate, s.component, st, ctypes.create_string_buffer(8), 8)
call('deSerializeFMUstate NULL pointer', s.fmi2DeSerializeFMUstate, s.component, b'x', 1, None)
taken = s.getFMUstate()
freed = ctypes.c_void_p(taken.value)
s.freeFMUstate(taken)
call('setFMUstate freed handle', s.fmi2SetFMUstate, s.component, freed)
call('freeFMUstate NULL handle', s.fmi2FreeFMUstate, s.component, ctypes.byref(ctypes.c_void_p()))
call('step after all that', s.doStep, 0.0, 0.01)
call('setFMUstate good', s.setFMUstate, st)
call('step after restore', s.doStep, 0.0, 0.01)
""")
    for name in ("freeFMUstate NULL handle", "step after all that", "setFMUstate good", "step after restore"):
        assert cases[name] == 0, (name, cases[name], logs[name])  # freeing NULL is allowed (FMI 2.0)
    for name, status in cases.items():
        if name.startswith(("freeFMUstate NULL handle", "step after", "setFMUstate good")):
            continue
        assert status == ERROR and logs[name], (name, status, logs[name])
    assert any("is NULL" in m for m in logs["setFMUstate NULL"])
    for name in ("setFMUstate made-up handle", "setFMUstate freed handle", "freeFMUstate made-up handle"):
        assert any("not a live state of this FMU" in m for m in logs[name]), (name, logs[name])
    assert any("buffer of 8 bytes" in m for m in logs["serializeFMUstate small buffer"])


def test_refusals_reach_the_host_without_logging_and_a_freed_instance_comes_back_fresh(pendulum_fmu, tmp_path):
    """With loggingOn = false the refusal is still logged (errors always are) under the host's instance name; an
    instance made after another was freed (the binary reuses the freed one through pythonfmu's reset) starts from
    the scene's initial state and steps as the first did."""
    out = run_client(f"""
{FMU_CLIENT_LIB}
import json
from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE
NAMED = []
def _named(env, instance, status, category, message):
    NAMED.append((instance.decode(), int(status), message.decode()))
cb = fmi2CallbackFunctions()
cb.logger = fmi2CallbackLoggerTYPE(_named)
cb.allocateMemory, cb.freeMemory = CALLBACKS.allocateMemory, CALLBACKS.freeMemory
md = read_model_description({str(pendulum_fmu)!r})
unzipped = extract({str(pendulum_fmu)!r})
vr = {{v.name: v.valueReference for v in md.modelVariables}}
runs, statuses = [], []
for name in ("first", "second"):
    s = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=name)
    s.instantiate(callbacks=cb, loggingOn=False)
    s.setupExperiment(startTime=0.0); s.enterInitializationMode(); s.exitInitializationMode()
    x0 = s.getReal([vr['X[2,1]']])[0]
    for n in range(5):
        s.doStep(n * 0.01, 0.01)
    runs.append([x0, s.getReal([vr['X[2,1]']])[0]])
    try:
        s.setReal([vr['X[2,1]']], [1.0]); statuses.append(0)
    except FMICallException as e:
        statuses.append(e.status)
    s.terminate(); s.freeInstance()
save(runs=np.array(runs), statuses=np.array(statuses), named=np.array(json.dumps(NAMED)))
""", tmp_path)
    named = json.loads(str(out["named"]))
    assert list(out["statuses"]) == [ERROR, ERROR]
    for name in ("first", "second"):
        mine = [m for who, status, m in named if who == name]
        assert len(mine) == 1 and "X[2,1] is an output" in mine[0], named
    assert all(status >= 1 for _, status, _ in named)  # nothing but the refusals with logging off
    np.testing.assert_array_equal(out["runs"][1], out["runs"][0])


def test_an_fmu_rebuilt_and_extracted_again_at_the_same_path_runs_in_the_same_process(pendulum_fmu, contract_root,
                                                                                     tmp_path):
    """The binary's front layer stays loaded after a host's dlclose (fmpy unloads at each fmi2FreeInstance): an FMU
    rebuilt with other settings (a new GUID) and extracted over the first one's folder is still served right."""
    from fmu_harness import build_cached
    other = build_cached(contract_root, str(MODELS / "pendulum.json"), step=5e-4)
    out = run_client(f"""
{FMU_CLIENT_LIB}
import shutil
where = {str(tmp_path / "pendulum_same_path")!r}
steps = []
for path in ({str(pendulum_fmu)!r}, {str(other)!r}):
    shutil.rmtree(where, ignore_errors=True)
    f = Fmu(path, unzipdir=extract(path, unzipdir=where))
    f.init()
    f.step(0.0, 0.01)
    steps.append(f.get(['step'])[0])
    f.slave.terminate(); f.slave.freeInstance()
save(steps=np.array(steps))
""", tmp_path)
    assert list(out["steps"]) == [1e-3, 5e-4]


def test_state_of_another_fmu_is_refused_and_changes_nothing(pendulum_fmu, chain_fmu, tmp_path):
    cases, logs = _calls(pendulum_fmu, tmp_path, f"""
a = Fmu({str(pendulum_fmu)!r}, 'a'); a.init()
b = Fmu({str(chain_fmu)!r}, 'b'); b.init(); b.step(0.0, 0.01)
foreign = b.slave.serializeFMUstate(b.slave.getFMUstate())
x0 = a.get(['X[2,1]'])
call('set foreign state', lambda: a.slave.setFMUstate(a.slave.deSerializeFMUstate(foreign)))
call('set foreign handle', a.slave.setFMUstate, b.slave.getFMUstate())
call('step after', a.slave.doStep, 0.0, 0.01)
save(same_time_start=np.array(float(x0[0])))
""")
    assert cases["step after"] == 0
    for name in ("set foreign state", "set foreign handle"):
        assert cases[name] != FATAL and any("another FMU" in m for m in logs[name]), (name, logs[name])


def test_start_time_is_honoured(tmp_path, chain_fmu):
    """A master starting at t0 = 1 gets the scene's motion shifted to t0 (fmpy's simulate_fmu gives every row)."""
    out = run_client(f"""
import fmpy
shifted = fmpy.simulate_fmu({str(chain_fmu)!r}, start_time=1.0, stop_time=1.1, output_interval=0.01,
                            output=['X[11,1]', 'X[11,3]'])
plain = fmpy.simulate_fmu({str(chain_fmu)!r}, start_time=0.0, stop_time=0.1, output_interval=0.01,
                          output=['X[11,1]', 'X[11,3]'])
save(t=shifted['time'], x=shifted['X[11,3]'], t0=plain['time'], x0=plain['X[11,3]'])
""", tmp_path)
    assert out["t"].size == 11 and out["t"][0] == 1.0
    np.testing.assert_allclose(out["t"], out["t0"] + 1.0, atol=1e-12)
    np.testing.assert_allclose(out["x"], out["x0"], rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("preload", [False, True], ids=["plain", "libpython preloaded"])
@pytest.mark.parametrize("mode", ["free", "step", "atexit"])
def test_c_host_that_calls_exit_ends_with_its_code(mode, preload, exit_host, pendulum_fmu, contract_root):
    folder, ident, guid = extract(pendulum_fmu, contract_root / "pendulum_exit")
    env = dict(os.environ)
    if preload:
        import sysconfig
        env["LD_PRELOAD"] = os.path.join(sysconfig.get_config_var("LIBDIR"), sysconfig.get_config_var("INSTSONAME"))
    proc = subprocess.run([str(exit_host), str(folder), ident, guid, mode, "7"], capture_output=True, text=True,
                          timeout=120, env=env)
    assert proc.returncode == 7, (proc.returncode, proc.stderr[-2000:])
    assert "freed" in proc.stdout
    if mode != "free":
        assert "step 0" in proc.stdout and "refused step 3" in proc.stdout  # fmi2Error: t is not the FMU's time
    if mode == "atexit":  # the host's own exit handler, run after the FMU's, still steps and frees the instance
        assert "late step 0" in proc.stdout and "late freed" in proc.stdout, proc.stdout


# glibc's loader compares RUNPATH strings with word-sized reads past their end while it loads libraries: not ours
LOADER_SUPPRESSION = """{
   ld.so reads RUNPATH strings with word-sized strncmp
   Memcheck:Addr8
   fun:strncmp
   fun:is_dst
}
"""


@pytest.mark.slow  # ~20-40 s: Python, numpy and scipy start under valgrind
def test_c_host_exit_makes_no_invalid_memory_access(exit_host, pendulum_fmu, contract_root, tmp_path):
    """pythonfmu 0.7.0 releases its interpreter's shared_ptr twice at exit(), the second time inside freed memory;
    whether glibc then aborts depends on the heap layout, so only a memory checker sees it every time."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        pytest.skip("valgrind is not installed")
    folder, ident, guid = extract(pendulum_fmu, contract_root / "pendulum_exit")
    suppressions = tmp_path / "loader.supp"
    suppressions.write_text(LOADER_SUPPRESSION)
    proc = subprocess.run([valgrind, "-q", "--error-exitcode=99", f"--suppressions={suppressions}",
                           str(exit_host), str(folder), ident, guid, "atexit", "7"],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 7 and "late freed" in proc.stdout, (proc.returncode, proc.stderr[-4000:])


def test_instantiate_free_cycles_do_not_grow_memory(exit_host, pendulum_fmu, contract_root):
    """pythonfmu executes the slave's module again on every instantiate and keeps what it makes (~75 KiB a cycle
    measured from this host); the binary's front layer reuses a freed instance through pythonfmu's reset."""
    folder, ident, guid = extract(pendulum_fmu, contract_root / "pendulum_cycles")
    proc = subprocess.run([str(exit_host), str(folder), ident, guid, "cycles:400", "0"], capture_output=True,
                          text=True, timeout=300)
    assert proc.returncode == 0 and proc.stdout.count("step 0") == 400, proc.stderr[-2000:]
    _, tenth, _, end = next(line for line in proc.stdout.splitlines() if line.startswith("rss_tenth")).split()
    growth = int(end) - int(tenth)  # KiB over the last 360 cycles
    assert growth < 360 * 8, proc.stdout[-500:]


def test_failed_instantiate_says_why_without_logging(exit_host, pendulum_fmu, contract_root):
    """A host whose Python cannot import numpy (the system's libpython, no PYTHONPATH) gets NULL and a reason on
    stderr naming the module and what to set, although it instantiated with loggingOn = false."""
    system = "/lib/x86_64-linux-gnu/libpython3.11.so.1.0"
    if not os.path.exists(system):
        pytest.skip("no system libpython3.11")
    folder, ident, guid = extract(pendulum_fmu, contract_root / "pendulum_noenv")
    env = {"PATH": "/usr/bin:/bin", "LD_LIBRARY_PATH": os.path.dirname(system)}
    proc = subprocess.run([str(exit_host), str(folder), ident, guid, "free", "0"], capture_output=True, text=True,
                          timeout=120, env=env)
    if proc.returncode == 0:
        pytest.skip("the system Python has numpy: nothing fails")
    assert proc.returncode == 4 and "fmi2Instantiate returned NULL" in proc.stderr
    assert "cannot import numpy" in proc.stderr and "PYTHONPATH" in proc.stderr, proc.stderr


def test_system_libpython_loads_numpy_through_the_promotion(exit_host, pendulum_fmu, contract_root):
    """Debian's libpython3.11 has math built in, so `import math` succeeds while numpy's extensions still need the
    symbols global: the FMU promotes whatever libpython is mapped."""
    system = "/lib/x86_64-linux-gnu/libpython3.11.so.1.0"
    if not os.path.exists(system):
        pytest.skip("no system libpython3.11")
    import numpy
    folder, ident, guid = extract(pendulum_fmu, contract_root / "pendulum_system")
    env = {"PATH": "/usr/bin:/bin", "LD_LIBRARY_PATH": os.path.dirname(system),
           "PYTHONPATH": os.path.dirname(os.path.dirname(numpy.__file__))}
    proc = subprocess.run([str(exit_host), str(folder), ident, guid, "step", "0"], capture_output=True, text=True,
                          timeout=120, env=env)
    assert proc.returncode == 0 and "step 0" in proc.stdout, proc.stderr[-2000:]


def test_binary_runpath_is_the_builders_only_when_the_system_would_load_another(pendulum_fmu, contract_root):
    import sysconfig
    import build_fmu
    folder, ident, _ = extract(pendulum_fmu, contract_root / "pendulum_runpath")
    from pythonfmu_front.build import inner_library_name
    pythonfmu_binary = folder / "binaries/linux64" / inner_library_name(ident)  # behind the front layer {ident}.so
    dyn = subprocess.run(["readelf", "-d", str(pythonfmu_binary)], capture_output=True, text=True).stdout
    soname = sysconfig.get_config_var("INSTSONAME")
    builder = os.path.realpath(os.path.join(sysconfig.get_config_var("LIBDIR"), soname))
    expect_runpath = build_fmu._system_library(soname) != builder
    assert ("RUNPATH" in dyn) == expect_runpath, dyn
    assert f"[{soname}]" in dyn
