"""A step the native FMU cannot take is discarded with the words the library gives for the same run (the core's
ln_explain): the stability limit of explicit steps, with the step that would do, for a light mass hung between
tensioned links at too large a step; the floor the conditioning allows for a taut string whose anchor is pulled
beyond the links' reach, where no step helps."""
from __future__ import annotations

import json
import re
import subprocess

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.scene import builders
from native_fmu_support import built

H = 0.01  # the communication step
N = 5


def mass_ratio_chain():
    """Ten links whose masses grow geometrically by 1e12 from the anchor: the light masses next to the anchor
    carry the heavy ones' weight and swing across their links at omega ~ 2e4 rad/s."""
    return builders.chain(10, total_length=1.0, masses=np.geomspace(1e-6, 1e6, 11))


def taut_string():
    """A mass between two anchors on two collinear links, the right anchor driven by the inputs: pulled 1 mm beyond
    the links' reach, no position satisfies (11), and A of (25) is singular there; the projection of the jump
    stalls at the floor that leaves."""
    return ln.Scene.from_dict({
        "name": "taut_string_pulled", "gravity": [0, 0, 0],
        "masses": [{"name": "left", "position": [0, 0, 0], "fixed": True},
                   {"name": "middle", "mass": 1.0, "position": [1, 0, 0]},
                   {"name": "right", "position": [2, 0, 0], "fixed": True, "driven": True,
                    "motion": {"kind": "input"}}],
        "links": [{"a": "left", "b": "middle"}, {"a": "middle", "b": "right"}]})


PULLED_TO = 2.001


def library_failure(scene, method, **settings) -> str:
    sim = ln.Simulator(scene, method=method, **settings)
    anchors = None
    if scene.driven.any():
        anchors = (np.array([[PULLED_TO, 0.0, 0.0]]), np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ln.SolverError) as failure:
        for n in range(1, N + 1):
            sim.advance(n * H, anchors=anchors)
    return str(failure.value)


def fmu_failure(host, env, fmu) -> str:
    """The message the FMU logged with the discarded step (the host stops at the first call that is not fmi2OK)."""
    cmd = [str(host), "run", str(fmu.dir), fmu.ident, fmu.guid, "0", str(N), repr(H)]
    if "P[3,1]" in fmu.vr:
        cmd += ["-i", f"{fmu.vr['P[3,1]']}={PULLED_TO!r}"]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 4 and "returned 2:" in proc.stderr, (proc.returncode, proc.stderr[-2000:])
    return proc.stderr.split("returned 2: ", 1)[1].strip()


@pytest.mark.parametrize("case", ["stability_limit", "floor"])
def test_the_fmu_discards_with_the_library_words(case, fmu_root, host, no_python_env, tmp_path):
    if case == "stability_limit":
        scene, method, settings, build = mass_ratio_chain(), "rattle", dict(dt=1e-4), dict(step=1e-4)
    else:
        scene, method, settings, build = taut_string(), "rattle", dict(dt=1e-3), dict(step=1e-3)
    expected = library_failure(scene, method, **settings)
    path = tmp_path / f"{case}.json"
    path.write_text(json.dumps(scene.to_dict()))
    fmu = built(fmu_root, path, integrator=method, **build)
    message = fmu_failure(host, no_python_env, fmu)
    head = re.match(r"fmi2DoStep: step from t=\S+ with h=\S+ failed, the FMU stays at t=\S+: ", message)
    assert head, message
    # the same words and numbers as the library's; then, since no shorter step helps here either, the FMU says so
    # and asks the master to stop (tests/fmu_native/test_native_fmu_terminate.py)
    reason, _, after = message[head.end():].partition(". No retry of this step can succeed, however short: ")
    if case == "floor":  # the step began with the anchor's jump to the input: named, with the rule it broke
        reason, _, jump = reason.partition(". The step began with a position jump: ")
        assert jump.startswith(f"P[3,1] (valueReference {fmu.vr['P[3,1]']}) = 2.001 m where the held motion had the "
                               "anchor at 2 m") and "must continue its held motion" in jump, message
    assert reason == expected, message
    assert after.endswith("; so fmi2Terminated is true (fmi2LastSuccessfulTime = 0)"), message
    if case == "stability_limit":
        assert "stability limit of explicit steps" in message and re.search(r"use dt below [0-9.e+-]+ s", message)
        assert "Reduce the step" not in message and "cannot help" not in message
    else:
        assert "it stalls at the floor this configuration allows" in message and "stability limit" not in message
