"""Force elements of F_k (9) as one table: quadratic (aerodynamic) drag, the element added through the scene
parser, the numpy forces and the native core's stages/forces.c alone. Physics: the analytic fall of a body
with quadratic drag (terminal velocity), the dissipation it causes, RATTLE's order with it (its second
half kick is implicit in the new velocity), and agreement of the native core with the numpy reference."""
from __future__ import annotations

import math

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.scene import builders

G = 9.81


def falling_mass(c=0.4, m=2.0):
    return ln.Scene.from_dict({"name": "falling", "gravity": [0, 0, -G], "links": [],
                               "masses": [{"name": "a", "mass": m, "position": [0, 0, 0], "quadratic_drag": c}]})


def chain_with_quadratic_drag():
    d = builders.chain(6).to_dict()
    for entry in d["masses"][2:]:
        entry["quadratic_drag"] = 0.2
    d["masses"][4]["drag"] = 0.1
    return ln.Scene.from_dict(d)


def test_the_scene_carries_quadratic_drag_and_refuses_a_negative_one():
    scene = chain_with_quadratic_drag()
    assert scene.force_elements.kinds.count("quadratic_drag") == 5
    assert ln.Scene.from_dict(scene.to_dict()).force_elements.kinds == scene.force_elements.kinds
    d = scene.to_dict()
    d["masses"][3]["quadratic_drag"] = -1.0
    with pytest.raises(ln.SceneError, match=r'mass 4 \("m3"\) quadratic_drag must not be negative'):
        ln.Scene.from_dict(d)


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_a_falling_body_follows_the_analytic_fall_to_its_terminal_velocity(backend):
    """m dv/dt = -m g + c v^2 (falling): v = -v_t tanh(g t / v_t), z = -(v_t^2 / g) ln cosh(g t / v_t)."""
    c, m, t = 0.4, 2.0, 3.0
    v_t = math.sqrt(m * G / c)
    sim = ln.Simulator(falling_mass(c, m), method="dop853", rtol=1e-11, atol=1e-12, backend=backend)
    sim.advance(t)
    assert sim.state.U[0, 2] == pytest.approx(-v_t * math.tanh(G * t / v_t), rel=1e-9)
    assert sim.state.X[0, 2] == pytest.approx(-(v_t ** 2 / G) * math.log(math.cosh(G * t / v_t)), rel=1e-9)


def test_quadratic_drag_dissipates_energy_at_the_rate_c_speed_cubed():
    scene = chain_with_quadratic_drag()
    res = ln.simulate(scene, 1.0, method="dop853", rtol=1e-10, n_out=101)
    assert np.all(np.diff(res.energy) < 0)  # drag only takes energy away
    # dE/dt = -sum_k (c_k |U_k|^3 + d_k |U_k|^2) at every sample, checked with central differences
    speed = np.linalg.norm(res.U, axis=2)
    rate = -(scene.quadratic_drag * speed ** 3 + scene.drag * speed ** 2).sum(axis=1)
    dE = np.gradient(res.energy, res.t)
    np.testing.assert_allclose(dE[5:-5], rate[5:-5], rtol=2e-3, atol=1e-3 * np.abs(rate).max())


@pytest.mark.parametrize("method,kw", [("rattle", {"dt": 2e-3}), ("yoshida4", {"dt": 2e-3}),
                                       ("dopri5", {"rtol": 1e-8}), ("dop853", {"rtol": 1e-10})])
def test_the_native_core_agrees_with_the_reference(method, kw):
    scene = chain_with_quadratic_drag()
    F = np.zeros((scene.K, 3))
    F[3, 1] = 0.4
    native = ln.Simulator(scene, method=method, backend="native", **kw)
    reference = ln.Simulator(scene, method=method, backend="numpy", **kw)
    for t in (0.05, 0.15):
        native.advance(t, F)
        reference.advance(t, F)
    np.testing.assert_allclose(native.state.X, reference.state.X, rtol=0, atol=1e-11)
    np.testing.assert_allclose(native.state.U, reference.state.U, rtol=0, atol=1e-9)


def test_rattle_keeps_second_order_with_quadratic_drag():
    scene = chain_with_quadratic_drag()
    t_end = 0.4
    reference = ln.simulate(scene, t_end, method="dop853", rtol=1e-13, atol=1e-14, n_out=2).X[-1]
    counts = [25, 50, 100, 200]
    errors = []
    for n in counts:
        sim = ln.Simulator(scene, method="rattle", dt=t_end / n)
        sim.advance(t_end)
        errors.append(np.abs(sim.state.X - reference).max())
    slopes = -np.diff(np.log(errors)) / np.diff(np.log(counts))
    assert np.all(np.abs(slopes - 2.0) < 0.25), (errors, slopes)
