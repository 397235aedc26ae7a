"""New masses M and lengths R in the native FMU of a rope scene: the core makes the initial state consistent
(ln_rope_initial_state, as UnilateralDynamics.initial_state does in the library) and the run is the library's run of
Scene.with_parameters on the native backend. A bob on a rope of 1 m from a fixed pivot, 0.5 m from it and flying
outward along the rope at 3.3 m/s (velocity (1.5, 0, -3), the rope's direction n = (0.6, 0, -0.8)):

* R = 0.8 m, M = 2 kg: the rope starts slack, nothing to make consistent: every output and event the library's, to
  the last bit;
* R = 0.5 m: the rope starts at its length with the bob flying away, and the initial impact (inelastic, whatever
  the rope's restitution) removes the radial velocity: U = v - (v . n) n = (-0.48, 0, -0.36) m/s, the closed form;
  the library's native backend computes its initial state with the core's function too, so the runs are equal to
  the last bit;
* R = 0.4 m (the rope stretched at the start), R = 0, M = -1: each refused with fmi2Error and a message naming the
  variable and the rule, nothing set; the instance then runs with the values it has, as the library's run.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from native_fmu_support import built
from test_native_fmu_ropes import ERROR, Instance, _library_rows, _names

import linknet_core as ln

V0, N_DIR = np.array([1.5, 0.0, -3.0]), np.array([0.6, 0.0, -0.8])
SCENE = {"name": "bob_flying_out", "gravity": [0.0, 0.0, -9.81],
         "masses": [{"name": "pivot", "position": [0.0, 0.0, 0.0], "fixed": True},
                    {"name": "bob", "position": [0.3, 0.0, -0.4], "mass": 1.0, "velocity": V0.tolist()}],
         "links": [{"a": "pivot", "b": "bob", "length": 1.0, "kind": "rope", "restitution": 0.5}]}
T_END, N = 1.0, 50


@pytest.fixture(scope="module")
def bob(fmu_root, tmp_path_factory):
    path = tmp_path_factory.mktemp("bob_flying_out") / "bob_flying_out.json"
    path.write_text(json.dumps(SCENE))
    return built(fmu_root, path), ln.load_scene(path)


def _runs(bob, **parameters):
    """The FMU's outputs at each communication point (the first before any step) and events' messages, and the
    library's run of the scene with the same M and R."""
    fmu, scene = bob
    mass, length = scene.mass.copy(), scene.length.copy()
    mass[1], length[0] = parameters.get("M[2]", mass[1]), parameters.get("R[1]", length[0])
    run = ln.simulate(scene.with_parameters(mass=mass, length=length), T_END, "dop853", rtol=1e-8, n_out=N + 1,
                      error_estimate=False, backend="native")
    names = _names(fmu)
    instance = Instance(fmu)
    instance.initialize(integrator="dop853", **parameters)
    first = instance.get(names)
    rows, messages = instance.run(run.t, names)
    return np.vstack([first, rows]), messages, _library_rows(run, names), run, names


def test_a_longer_rope_and_a_heavier_bob_give_the_librarys_run_to_the_last_bit(bob):
    rows, messages, expected, run, names = _runs(bob, **{"R[1]": 0.8, "M[2]": 2.0})
    np.testing.assert_array_equal(rows, expected)
    assert len(messages) == len(run.events) and [e.kind for e in run.events][0] == "taut"
    assert rows[0, names.index("slack[1]")] == 1.0


def test_a_rope_at_its_length_takes_the_initial_impact(bob):
    rows, _, expected, run, names = _runs(bob, **{"R[1]": 0.5})
    U0 = rows[0, [names.index(f"U[2,{i}]") for i in (1, 2, 3)]]
    np.testing.assert_allclose(U0, V0 - (V0 @ N_DIR) * N_DIR, rtol=0, atol=1e-15 * np.abs(V0).max())
    assert run.events == [] or run.events[0].t > 0.0  # the initial impact is the start's, no event of the run
    np.testing.assert_array_equal(rows, expected)


@pytest.mark.parametrize("name, value, rule", [
    ("R[1]", 0.4, "a rope may be shorter than its length, never longer"),
    ("R[1]", 0.0, "must be > 0"),
    ("M[2]", -1.0, "must be > 0")])
def test_a_bad_mass_or_length_is_refused_and_the_instance_goes_on(bob, name, value, rule):
    from fmpy.fmi1 import FMICallException

    fmu, scene = bob
    instance = Instance(fmu)
    instance.slave.setupExperiment(startTime=0.0)
    instance.slave.enterInitializationMode()
    with pytest.raises(FMICallException):
        instance.slave.setReal([fmu.vr[name]], [value])
    status, _, message = instance.log.pop()
    assert status == ERROR and name in message and rule in message and message.endswith("nothing set")
    instance.slave.exitInitializationMode()
    instance.slave.doStep(0.0, 0.1)
    run = ln.simulate(scene, 0.1, "dop853", rtol=1e-8, n_out=2, error_estimate=False, backend="native")
    np.testing.assert_array_equal(instance.get(["X[2,1]", "X[2,3]"]), run.X[-1, 1, [0, 2]])
