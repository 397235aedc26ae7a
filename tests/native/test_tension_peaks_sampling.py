"""The located tension peaks of simulate's output loop in one call into C (ln_sample) against the same run advanced
interval by interval through the public stepping interface (Simulator.advance, then tension_peaks): two routes to the
same peaks, bit for bit, and for a static scene the tensions it holds at every output."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln


@pytest.mark.parametrize("name,method,settings", [("pendulum", "dop853", {}),
                                                  ("chain_10", "rattle", {"dt": 1e-3}),
                                                  ("net_10x10", "yoshida4", {"dt": 2e-3})])
def test_peaks_in_one_call_are_the_peaks_interval_by_interval(name, method, settings):
    scene = ln.load_scene(f"models/{name}.json")
    forces = np.zeros((scene.K, 3))
    forces[-1] = [0.3, -0.2, 0.1]  # a held input: B (26) and so T feel it
    res = ln.simulate(scene, 0.3, method=method, n_out=7, forces=forces, progress=False, error_estimate=False,
                      **settings)
    sim = ln.Simulator(scene, method=method, error_estimate=False, **settings)
    assert np.array_equal(res.T_peak[0], res.T[0]) and np.all(res.T_peak_time[0] == 0.0)
    for i, t in enumerate(res.t[1:], start=1):
        sim.advance(t, forces)
        peak, when = sim.tension_peaks()
        assert np.array_equal(res.T_peak[i], peak) and np.array_equal(res.T_peak_time[i], when), (name, i)
    assert np.all(np.abs(res.T_peak) >= np.abs(res.T) - 1e-9 * np.abs(res.T).max())  # the ends count


def test_a_static_scene_in_one_call_reports_the_tension_it_holds():
    """redundant_truss does not move: its tensions under a held input stand still, so every interval's peak is the
    sample at its end, in one call into C as in the loop of a callable input."""
    scene = ln.load_scene("models/redundant_truss.json")
    forces = np.zeros((scene.K, 3))
    forces[scene.free_indices[0]] = [0.0, 0.0, -50.0]
    one_call = ln.simulate(scene, 1.0, n_out=4, forces=forces, progress=False)
    loop = ln.simulate(scene, 1.0, n_out=4, forces=lambda t: forces, progress=False)
    assert one_call.stats["tension_peaks"] == loop.stats["tension_peaks"] == "sampled"
    for res in (one_call, loop):
        assert np.array_equal(res.T_peak, res.T)
        assert np.array_equal(res.T_peak_time, np.repeat(res.t[:, None], scene.L, axis=1))
