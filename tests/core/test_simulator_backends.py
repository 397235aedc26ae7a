"""The Simulator and its backends: one interface (linknet_core.simulator.backend.Backend), the backend chosen once by
name, the arguments checked by the Simulator for every backend alike."""
import numpy as np
import pytest

import linknet_core as ln
from linknet_core.simulator import simulator as simulator_module
from linknet_core.simulator.numpy_backend import NumpyBackend


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_a_refused_target_time_reads_the_same_on_every_backend_and_changes_nothing(backend):
    scene = ln.load_scene("models/chain_10.json")
    sim = ln.Simulator(scene, method="rattle", dt=1e-3, backend=backend, error_estimate=False)
    push = np.zeros((scene.K, 3))
    push[-1] = (1.0, 0.0, 0.0)
    sim.advance(0.1, push)
    X, U = sim.state.X.copy(), sim.state.U.copy()
    for target in (0.1, 0.05, float("nan"), float("inf")):
        with pytest.raises(ln.SolverError) as refused:
            sim.advance(target, push)
        # the target is the argument at fault: the input forces are not mentioned
        assert str(refused.value) == (f"cannot advance from t = 0.1 to t = {target}: the target must be later and "
                                      "finite")
        assert sim.state.t == 0.1 and np.array_equal(sim.state.X, X) and np.array_equal(sim.state.U, U)
    sim.advance(0.2, push)  # still usable
    assert sim.state.t == 0.2


class _CountingBackend(NumpyBackend):
    """A backend of the test's own, in the test's module: the numpy reference, counting what the Simulator asks."""

    name = "counting"
    calls: dict = {}

    def advance(self, state, t_next, F, hold, max_steps):
        self.calls["advance"] = self.calls.get("advance", 0) + 1
        super().advance(state, t_next, F, hold, max_steps)

    def outputs(self, state, F, hold):
        self.calls["outputs"] = self.calls.get("outputs", 0) + 1
        return super().outputs(state, F, hold)


def test_a_backend_in_a_module_of_its_own_is_chosen_by_its_name_alone(monkeypatch):
    """Registering the class under a name is all a new backend needs: the Simulator and simulate take every advance
    and every output through it."""
    monkeypatch.setitem(simulator_module.BACKEND_CLASSES, "counting", _CountingBackend)
    monkeypatch.setattr(_CountingBackend, "calls", {})
    scene = ln.load_scene("models/double_pendulum.json")
    sim = ln.Simulator(scene, method="rattle", dt=1e-3, backend="counting", error_estimate=False)
    assert sim.backend == "counting" and type(sim.engine) is _CountingBackend
    assert "backend counting" in sim.summary()
    sim.advance(0.01)
    sim.outputs()
    assert _CountingBackend.calls == {"advance": 1, "outputs": 1}
    result = ln.simulate(scene, 0.01, method="rattle", dt=1e-3, n_out=6, backend="counting", error_estimate=False,
                         progress=False)
    assert _CountingBackend.calls == {"advance": 1 + 5, "outputs": 1 + 6}  # sample by sample: no samples in one call
    # the run is the swinging double pendulum: both masses move, the links keep their lengths (11)
    assert result.residual.max() < 1e-12 and np.abs(result.X[-1] - result.X[0]).max() > 0
    with pytest.raises(ln.SolverError, match="backend must be one of 'auto', 'native', 'numpy', 'counting'"):
        ln.Simulator(scene, backend="Counting")
