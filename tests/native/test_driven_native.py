"""Driven anchors on the native core against the numpy reference: every motion kind (velocity, sine, waypoints,
inputs held as P + V s + A s^2/2 with velocity jumps between advances, inputs from a callable) under every method
gives the same trajectory, tensions, anchor reactions and jump impulses to round-off; and a snapshot taken under a
held anchor input continues bit-identically on both backends."""
from __future__ import annotations

import math

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.scene import builders
from driven_anchor_scenes import METHODS, MOTIONS, drive, driven_chain, hold

TIMES = (0.02, 0.06, 0.1)


def _input_holds():
    """Holds for the three advances: the second keeps P continuous but changes V (an impulse), the third keeps the
    second's hold (None)."""
    P0, V0, A0 = np.zeros(3), np.array([0.3, 0.0, 0.2]), np.array([1.0, 0.5, -0.5])
    s = TIMES[0]
    P1 = P0 + V0 * s + 0.5 * A0 * s * s
    return [hold(P0, V0, A0), hold(P1, [-0.2, 0.4, 0.0], [0.0, -1.0, 2.0]), None]


def _crane(t):
    """An input motion given as a callable of time: a trolley swinging out while its hoist lifts."""
    w = 2.0 * math.pi * 1.3
    return hold([0.2 * (1 - math.cos(w * t)), 0.0, 0.05 * t * t],
                [0.2 * w * math.sin(w * t), 0.0, 0.1 * t],
                [0.2 * w * w * math.cos(w * t), 0.0, 0.1])


KINDS = ["velocity", "sine", "waypoints", "input held", "input callable"]


def _scene_and_inputs(kind):
    if kind == "input held":
        return driven_chain(None), _input_holds()
    if kind == "input callable":
        return driven_chain(None), [_crane, None, None]
    return driven_chain(MOTIONS[kind]), [None, None, None]


@pytest.mark.parametrize("method,kw", METHODS, ids=[m for m, _ in METHODS])
@pytest.mark.parametrize("kind", KINDS)
def test_native_and_numpy_agree_on_driven_scenes(kind, method, kw):
    scene, inputs = _scene_and_inputs(kind)
    native = ln.Simulator(scene, method=method, backend="native", **kw)
    reference = ln.Simulator(scene, method=method, backend="numpy", **kw)
    assert native.backend == "native" and reference.backend == "numpy"
    worst = np.zeros(5)
    for t, anchors in zip(TIMES, inputs):
        native.advance(t, anchors=anchors)
        reference.advance(t, anchors=anchors)
        out_n, out_r = native.outputs(), reference.outputs()
        worst = np.maximum(worst, [np.abs(out_n["X"] - out_r["X"]).max(), np.abs(out_n["U"] - out_r["U"]).max(),
                                   np.abs(out_n["T"] - out_r["T"]).max(),
                                   np.abs(out_n["Freact"] - out_r["Freact"]).max(),
                                   np.abs(out_n["impulse"] - out_r["impulse"]).max()])
        assert native.anchor_report()["jumps"] == reference.anchor_report()["jumps"]
    assert native.integrator.stats.as_dict() == reference.integrator.stats.as_dict()
    if kind == "input held":  # the anchor at rest jumped to V0 at t = 0 and to another V at the second advance
        assert reference.anchor_report()["jumps"] == 2
    print(f"\nnative vs numpy, {kind}, {method}: |dX| {worst[0]:.1e} m, |dU| {worst[1]:.1e} m/s, "
          f"|dT| {worst[2]:.1e} N, |dFreact| {worst[3]:.1e} N, |dJ| {worst[4]:.1e} N s")
    assert worst[0] < 1e-13 and worst[1] < 2e-12, worst
    assert worst[2] < 1e-11 and worst[3] < 1e-11 and worst[4] < 1e-14, worst


def test_jump_impulse_agrees_between_backends_on_a_tilted_chain():
    """A chain at rest in a tilted straight line (every link along one direction) under an input-driven anchor
    that jumps to V: the whole chain takes the component of V along the line (impulse -M (V.E) E), on both paths."""
    direction = np.array([0.6, 0.0, -0.8])
    points = np.outer(np.arange(4) * 0.3, direction)
    scene = drive(builders.chain(3, shape="points", points=points), 0)
    total = float(np.sum(scene.mass[1:]))
    V = np.array([0.5, 0.2, 0.4])
    impulses, states = [], []
    for backend in ("native", "numpy"):
        sim = ln.Simulator(scene, method="rattle", dt=1e-3, backend=backend)
        sim.advance(1e-3, anchors=hold([0, 0, 0], V, [0, 0, 0]))
        impulses.append(sim.anchor_report()["impulse"])
        states.append((sim.state.X, sim.state.U))
    expected = -total * float(V @ direction) * direction
    np.testing.assert_allclose(impulses[0], [expected], atol=1e-14)
    np.testing.assert_allclose(impulses[1], impulses[0], atol=1e-15)
    np.testing.assert_allclose(states[1][0], states[0][0], atol=1e-15)
    np.testing.assert_allclose(states[1][1], states[0][1], atol=1e-14)


@pytest.mark.parametrize("backend", ["native", "numpy"])
@pytest.mark.parametrize("method,kw", [METHODS[0], METHODS[1], METHODS[6]], ids=["rattle", "yoshida4", "dop853"])
def test_snapshot_under_a_held_anchor_input_continues_bit_identically(backend, method, kw):
    """get_state under hold H1; then another hold H2 is applied; set_state brings H1 back with the state, and the
    continuation with anchors=None equals (bit for bit) a run that never saw H2."""
    scene = driven_chain(None)
    H1, H2, _ = _input_holds()
    straight = ln.Simulator(scene, method=method, backend=backend, **kw)
    straight.advance(0.02, anchors=H1)
    straight.advance(0.05)
    straight.advance(0.08)

    sim = ln.Simulator(scene, method=method, backend=backend, **kw)
    sim.advance(0.02, anchors=H1)
    snapshot = sim.get_state()
    sim.advance(0.05, anchors=H2)
    detour = sim.state.X.copy()
    sim.set_state(snapshot)
    sim.advance(0.05)
    sim.advance(0.08)
    assert np.abs(detour - straight.state.X).max() > 1e-6  # H2 did move the chain elsewhere
    assert np.array_equal(sim.state.X, straight.state.X) and np.array_equal(sim.state.U, straight.state.U)
    out, expected = sim.outputs(), straight.outputs()
    assert np.array_equal(out["T"], expected["T"]) and np.array_equal(out["Freact"], expected["Freact"])
    # one jump each: the anchor at rest taking H1's velocity at t = 0 (the detour's jump left with the snapshot)
    assert sim.anchor_report()["jumps"] == straight.anchor_report()["jumps"] == 1
