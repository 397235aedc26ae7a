"""FMU state handles a host gets wrong are refused with fmi2Error and a message naming the rule, never read or
written through, and the instance goes on working: a NULL handle or address, a handle never handed out (a
look-alike copy of a state's bytes, and a pointer to memory that cannot be read), a freed state set, sized,
serialized or freed again through a copy of its handle (a double free), the handle itself passed where the address
of the host's variable belongs (fmusim 0.0.39 frees with fmi2FreeFMUstate(c, (fmi2FMUstate *)state)), and a state
of another instance. Before this the native FMU crashed (SIGSEGV) on a made-up handle and on the handle-for-address
free, returned fmi2OK for a freed state, and aborted the process on a double free.

The host is a small C program (state_handle_host.c) run in its own process, so that a crash or an abort fails the
test by the exit status. Both FMU kinds answer with the same rules and words (the pythonfmu FMU through its front
layer, fmu_src/pythonfmu_front/front.c). After the misuse, a restored state and one more step give the outputs a
fresh instance gives bit for bit, and the library's run gives to round-off."""
from __future__ import annotations

import os
import subprocess

import numpy as np
import pytest

import linknet_core as ln
from native_fmu_support import MODELS, built, compile_host

OK, ERROR = 0, 3
H = 0.01  # the host's communication step (state_handle_host.c)
SCENE = "chain_10"  # a state of 3.5 KB: the old glue took it freed for live, and freed it twice
OUTPUTS = ["X[11,1]", "X[11,3]", "U[11,1]", "U[11,3]"]

NULL = "FMUstate is NULL"
NOT_LIVE = "FMUstate is not a live state of this FMU instance"
HANDLE_FOR_ADDRESS = "FMUstate is a state handle itself where the address of the host's fmi2FMUstate variable belongs"

# case -> (status, words the message logged during the call must contain, the FMI function it must name)
EXPECTED = {
    "set_null": (ERROR, NULL, "fmi2SetFMUstate"),
    "free_null_address": (ERROR, NULL, "fmi2FreeFMUstate"),
    "get_null_address": (ERROR, NULL, "fmi2GetFMUstate"),
    "size_null": (ERROR, NULL, "fmi2SerializedFMUstateSize"),
    "set_look_alike": (ERROR, NOT_LIVE, "fmi2SetFMUstate"),
    "set_made_up": (ERROR, NOT_LIVE, "fmi2SetFMUstate"),
    "size_made_up": (ERROR, NOT_LIVE, "fmi2SerializedFMUstateSize"),
    "serialize_made_up": (ERROR, NOT_LIVE, "fmi2SerializeFMUstate"),
    "free_made_up": (ERROR, NOT_LIVE, "fmi2FreeFMUstate"),
    "get_overwriting_made_up": (ERROR, NOT_LIVE, "fmi2GetFMUstate"),
    "free_taken": (OK, "", ""),
    "free_again_variable_null": (OK, "", ""),
    "set_freed": (ERROR, NOT_LIVE, "fmi2SetFMUstate"),
    "size_freed": (ERROR, NOT_LIVE, "fmi2SerializedFMUstateSize"),
    "serialize_freed": (ERROR, NOT_LIVE, "fmi2SerializeFMUstate"),
    "double_free": (ERROR, NOT_LIVE, "fmi2FreeFMUstate"),
    "free_handle_for_address": (ERROR, HANDLE_FOR_ADDRESS, "fmi2FreeFMUstate(c, &state)"),
    "get_into_handle_for_address": (ERROR, HANDLE_FOR_ADDRESS, "fmi2GetFMUstate(c, &state)"),
    "deserialize_into_handle_for_address": (ERROR, HANDLE_FOR_ADDRESS, "fmi2DeSerializeFMUstate(c, &state)"),
    "free_handle_for_address_again": (ERROR, HANDLE_FOR_ADDRESS, "fmi2FreeFMUstate"),
    "set_held_after": (OK, "", ""),
    "free_held": (OK, "", ""),
    "set_other_instances": (ERROR, NOT_LIVE, "fmi2SetFMUstate"),
    "free_other_instances": (ERROR, NOT_LIVE, "fmi2FreeFMUstate"),
    "set_saved": (OK, "", ""),
    "step_after": (OK, "", ""),
    "free_saved": (OK, "", ""),
}


@pytest.fixture(scope="module")
def state_host(tmp_path_factory):
    return compile_host(tmp_path_factory, "state_handle_host.c", "-ldl")


def _run(host, fmu, env, *args):
    cmd = [str(host), str(fmu.dir), fmu.ident, fmu.guid, *map(str, args)]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=180, env=env)
    # a crash (SIGSEGV -11), an abort (-6) or a call that failed where it must not (4) ends the test here
    assert proc.returncode == 0, f"host exited {proc.returncode}\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return proc.stdout


def _library_outputs() -> np.ndarray:
    """The FMU's default run (dop853 at rtol 1e-8) of the same two steps on linknet_core's Simulator."""
    scene = ln.load_scene(MODELS / f"{SCENE}.json")
    sim = ln.Simulator(scene, method="dop853", rtol=1e-8)
    sim.advance(H)
    sim.advance(2 * H)
    values = []
    for name in OUTPUTS:
        kind, idx = name[0], [int(i) - 1 for i in name[2:-1].split(",")]
        values.append((sim.state.X if kind == "X" else sim.state.U)[idx[0], idx[1]])
    return np.array(values)


@pytest.mark.parametrize("native", [True, False], ids=["native", "pythonfmu"])
def test_misused_state_handles_are_refused_and_the_instance_keeps_working(native, state_host, fmu_root,
                                                                          no_python_env):
    fmu = built(fmu_root, SCENE, native=native)
    env = no_python_env if native else dict(os.environ)  # the pythonfmu FMU's binary needs its Python
    out = _run(state_host, fmu, env, "handles", *(fmu.vr[name] for name in OUTPUTS))
    cases, values = {}, {}
    for line in out.splitlines():
        kind, _, rest = line.partition(" ")
        if kind == "CASE":
            name, status, message = (rest.split(" ", 2) + [""])[:3]
            cases[name] = (int(status), message)
        elif kind == "VALUES":
            label, *numbers = rest.split()
            values[label] = np.array([float.fromhex(x) for x in numbers])
    assert set(cases) == set(EXPECTED), set(cases) ^ set(EXPECTED)
    for name, (status, words, function) in EXPECTED.items():
        got, message = cases[name]
        assert got == status, f"{name}: status {got}, expected {status} ({message})"
        assert words in message and function in message, f"{name}: {message!r} lacks {words!r} / {function!r}"
        if status == ERROR:
            assert message.count(" | ") == 0, f"{name}: one message per refusal, got {message!r}"
    assert "VALUE variable_after_free NULL" in out  # fmi2FreeFMUstate set the host's variable to NULL
    assert "FATAL_SEEN 0" in out
    # the misuse changed nothing: a restored state and a step give what a fresh instance gives, bit for bit
    np.testing.assert_array_equal(values["after"], values["clean"])
    reference = _library_outputs()
    assert np.abs(values["after"] - reference).max() <= 1e-12 * max(1.0, np.abs(reference).max())


def test_states_the_host_never_freed_are_freed_with_the_instance(state_host, fmu_root, no_python_env):
    """fmi2FreeInstance frees the states still registered: over 2000 instances that each leave 4 states behind, the
    resident memory after the first tenth of them does not grow by anything like the states' size."""
    fmu = built(fmu_root, SCENE)  # a state of some kilobytes, so that leaked ones would show
    cycles, per_cycle = 2000, 4
    out = dict(line.split() for line in _run(state_host, fmu, no_python_env, "leave", cycles, per_cycle).splitlines())
    growth_kib = int(out["rss_end"]) - int(out["rss_tenth"])
    leaked_kib = 0.9 * cycles * per_cycle * int(out["state_bytes"]) / 1024  # were none of them freed
    assert leaked_kib > 10_000, leaked_kib  # the check below can see a leak
    assert growth_kib < 0.05 * leaked_kib, (growth_kib, leaked_kib)
