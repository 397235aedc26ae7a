"""simulate keeps the Simulator of a run on its scene object and resets it for the next run of the same settings:
that run must be the run of a new Simulator, bit for bit, after a finished, an interrupted and a failed run, with
a driven anchor, with counters of the projection floor (triangulated_net under load), nested in a forces callable;
and the kept Simulator must neither keep the scene alive nor travel with a copy or pickle of it."""
from __future__ import annotations

import copy
import gc
import pickle
import weakref

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.errors import SolverError
from linknet_core.simulator.simulator import SimulationInterrupted
from driven_anchor_scenes import MOTIONS, driven_chain

FIELDS = ("t", "X", "U", "T", "energy", "residual", "velocity_residual", "kinetic")


def _same_run(a: ln.Result, b: ln.Result) -> None:
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert x.shape == y.shape and np.array_equal(x, y, equal_nan=True), name
    strip = lambda stats: {k: v for k, v in stats.items() if k != "wall_time"}  # noqa: E731
    assert strip(a.stats) == strip(b.stats)


def _fresh(path, *args, **kwargs) -> ln.Result:
    """The run on a scene object of its own (a new Simulator)."""
    return ln.simulate(ln.load_scene(path), *args, **kwargs)


@pytest.mark.parametrize("name, t_end, settings", [
    ("pendulum", 2.0, {"method": "dop853", "rtol": 1e-6}),
    ("chain_10", 0.3, {"method": "yoshida4", "dt": 1e-3, "forces": lambda t: np.full((11, 3), 0.1 * t)}),
    ("triangulated_net", 0.02, {"method": "rattle", "dt": 1e-3, "forces": "ones"}),
])
def test_repeated_runs_are_new_runs(models_dir, name, t_end, settings):
    path = models_dir / f"{name}.json"
    scene = ln.load_scene(path)
    if settings.get("forces") == "ones":
        settings = dict(settings, forces=np.ones((scene.K, 3)))
    first = ln.simulate(scene, t_end, n_out=5, **settings)
    second = ln.simulate(scene, t_end, n_out=5, **settings)
    _same_run(first, second)
    _same_run(second, _fresh(path, t_end, n_out=5, **settings))
    if name == "triangulated_net":  # the load stops projections at their floor: that count starts at 0 again
        assert second.stats["floor_stops"] == first.stats["floor_stops"] > 0


def test_driven_anchor_runs_repeat():
    scene = driven_chain(MOTIONS["sine"])
    runs = [ln.simulate(scene, 0.2, method="dopri5", rtol=1e-8, n_out=4) for _ in range(2)]
    _same_run(*runs)
    _same_run(runs[1], ln.simulate(driven_chain(MOTIONS["sine"]), 0.2, method="dopri5", rtol=1e-8, n_out=4))


def test_run_after_an_interrupted_run(models_dir):
    path = models_dir / "double_pendulum.json"
    scene = ln.load_scene(path)

    def interrupting(t):
        if t > 0.4:
            raise KeyboardInterrupt
        return np.zeros((scene.K, 3))

    with pytest.raises(SimulationInterrupted):
        ln.simulate(scene, 1.0, method="dop853", rtol=1e-8, n_out=11, forces=interrupting)
    _same_run(ln.simulate(scene, 1.0, method="dop853", rtol=1e-8, n_out=11),
              _fresh(path, 1.0, method="dop853", rtol=1e-8, n_out=11))


def test_run_after_a_failed_run(models_dir):
    path = models_dir / "double_pendulum.json"
    scene = ln.load_scene(path)

    def kick(t):  # a force no step of 0.1 s can follow, from t = 0.5 on: the run fails in its middle
        F = np.zeros((scene.K, 3))
        F[-1, 0] = 1e6 if t >= 0.5 else 0.0
        return F

    with pytest.raises(SolverError, match="did not converge"):
        ln.simulate(scene, 1.0, method="rattle", dt=0.1, n_out=3, forces=kick)
    _same_run(ln.simulate(scene, 1.0, method="rattle", dt=0.1, n_out=11),
              _fresh(path, 1.0, method="rattle", dt=0.1, n_out=11))


def test_nested_run_builds_its_own(models_dir):
    """A run inside a run's forces callable (or in another thread) cannot take the Simulator in use."""
    path = models_dir / "pendulum.json"
    scene = ln.load_scene(path)
    inner = []

    def forces(t):
        inner.append(ln.simulate(scene, 0.5, method="dop853", rtol=1e-8, n_out=3))
        return np.zeros((scene.K, 3))

    outer = ln.simulate(scene, 0.5, method="dop853", rtol=1e-8, n_out=3, forces=forces)
    reference = _fresh(path, 0.5, method="dop853", rtol=1e-8, n_out=3)
    _same_run(outer, reference)
    for run in inner:
        _same_run(run, reference)


def test_reset_restores_every_counter(models_dir):
    scene = ln.load_scene(models_dir / "triangulated_net.json")
    sim = ln.Simulator(scene, method="rattle", dt=1e-3)
    load = np.ones((scene.K, 3))
    sim.advance(0.01, load)
    floor, steps, X = sim.integrator.projection_floor(), sim.integrator.stats.steps, sim.state.X.copy()
    assert floor[0] > 0
    sim.reset()
    assert sim.integrator.projection_floor() == (0, 0.0) and sim.integrator.stats.steps == 0
    sim.advance(0.01, load)
    assert sim.integrator.projection_floor() == floor and sim.integrator.stats.steps == steps
    assert np.array_equal(sim.state.X, X)


def test_kept_simulator_does_not_keep_the_scene(models_dir):
    scene = ln.load_scene(models_dir / "pendulum.json")
    ln.simulate(scene, 0.1, method="dop853", n_out=2)
    # a copy or pickle of the scene carries no Simulator (they hold the native core's memory)
    for other in (copy.copy(scene), copy.deepcopy(scene), pickle.loads(pickle.dumps(scene))):
        _same_run(ln.simulate(other, 0.1, method="dop853", n_out=2), ln.simulate(scene, 0.1, method="dop853", n_out=2))
    alive = weakref.ref(scene)
    del scene, other
    gc.collect()
    assert alive() is None


def test_samples_that_leave_the_state_alone(models_dir):
    """Simulator.sample(update_state=False), simulate's last call on a Simulator it resets before reuse: the
    samples are those of the stepping interface, the state stays where it was and the next advance starts from it
    (fixed steps: the run from there is the same run again); a reset then gives the initial state."""
    sim = ln.Simulator(ln.load_scene(models_dir / "chain_10.json"), method="rattle", dt=1e-3)
    X0, U0 = sim.state.X.copy(), sim.state.U.copy()
    times = np.array([0.0, 0.05, 0.1])
    n, K, L = times.size, sim.scene.K, sim.scene.L
    X, U, T, diagnostics = np.empty((n, K, 3)), np.empty((n, K, 3)), np.empty((n, L)), np.empty((4, n))
    sim.sample(times, None, X, U, T, advance_first=False, diagnostics=diagnostics, update_state=False)
    assert sim.state.t == 0.0 and np.array_equal(sim.state.X, X0) and np.array_equal(sim.state.U, U0)
    sim.advance(0.05)
    sim.advance(0.1)
    out = sim.outputs()
    assert np.array_equal(out["X"], X[-1]) and np.array_equal(out["U"], U[-1]) and np.array_equal(out["T"], T[-1])
    assert diagnostics[3, -1] > 0  # the kinetic energy of the moving chain, in its row
    sim.reset(state_untouched=True)  # the state was replaced by the advances: made afresh
    assert sim.state.t == 0.0 and np.array_equal(sim.state.X, X0) and np.array_equal(sim.state.U, U0)
