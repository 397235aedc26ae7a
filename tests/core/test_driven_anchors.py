"""Physics of driven anchors (anchors whose motion is prescribed): a uniformly accelerated pivot (tilted equilibrium,
period of g_eff), Galilean invariance under a pivot at constant velocity, the Kapitza pendulum on both sides of
a^2 w^2 = 2 g l, the inelastic impulse of an anchor's velocity jump, and the measured convergence order of every
method on chains hanging from sine- and spline-driven anchors. Run with -s to see the measured figures."""
from __future__ import annotations

import math

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.integrators import METHODS
from linknet_core.scene import builders
from driven_anchor_scenes import G, MOTIONS, drive, driven_chain, hold, pendulum

ALL_METHODS = ["rattle", "yoshida4", "suzuki4", "yoshida6", "yoshida8", "dopri5", "dop853"]
BACKENDS = ["native", "numpy"]


def _angle_from_down(sim) -> float:
    """The rod's angle from the downward vertical in the x-z plane (positive towards +x)."""
    d = sim.state.X[1] - sim.state.X[0]
    return math.atan2(d[0], -d[2])


def _zero_crossings(t, y) -> np.ndarray:
    """Where y changes sign, interpolated linearly (at a crossing of a near-sinusoid y'' ~ 0, so the error is
    third order in the sample spacing)."""
    i = np.flatnonzero(np.sign(y[:-1]) != np.sign(y[1:]))
    return t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])


# ---- uniformly accelerated pivot -------------------------------------------------------------------------------
ACCELERATION = 4.0  # m/s2 along +x


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("form", ["held", "callable"])
def test_uniformly_accelerated_pivot_holds_the_bob_at_atan_a_over_g(backend, form):
    """In the pivot's frame gravity is g - a: the bob rests at atan(a/g) behind the vertical, the rod's tension is
    M g_eff and the anchor feels M (g - a). Started there at rest, it stays there to round-off (the pivot has moved
    8 m by t = 2 s)."""
    a, length, mass = ACCELERATION, 1.0, 1.3
    tilt = math.atan(a / G)
    sim = ln.Simulator(pendulum(-tilt, length, mass), method="dop853", rtol=1e-10, backend=backend)
    A = [a, 0.0, 0.0]
    if form == "held":  # held over the whole run as P + V s + A s^2/2 from t = 0
        anchors = hold([0, 0, 0], [0, 0, 0], A)
    else:
        anchors = lambda t: hold([0.5 * a * t * t, 0, 0], [a * t, 0, 0], A)  # noqa: E731
    sim.advance(0.5, anchors=anchors)
    sim.advance(2.0)
    np.testing.assert_allclose(sim.state.X[0], [0.5 * a * 4.0, 0.0, 0.0], rtol=1e-15)
    offset = sim.state.X[1] - sim.state.X[0]
    np.testing.assert_allclose(offset, [-length * math.sin(tilt), 0.0, -length * math.cos(tilt)], atol=1e-13)
    np.testing.assert_allclose(sim.state.U[1], [2.0 * a, 0.0, 0.0], atol=1e-12)
    out = sim.outputs()
    g_eff = math.hypot(G, a)
    assert out["T"][0] == pytest.approx(mass * g_eff, rel=1e-12)
    np.testing.assert_allclose(out["Freact"][0], mass * np.array([-a, 0.0, -G]), atol=1e-11)
    print(f"\naccelerated pivot ({backend}, {form}): tilt {math.degrees(-_angle_from_down(sim)):.12f} deg, "
          f"atan(a/g) = {math.degrees(tilt):.12f} deg, T = {out['T'][0]:.12f} N, M g_eff = {mass * g_eff:.12f} N")


def test_small_oscillations_about_the_tilted_equilibrium_have_the_period_of_g_eff():
    """Released 0.01 rad off the tilted equilibrium: T = 2 pi sqrt(l / g_eff) (1 + theta0^2/16), g_eff =
    sqrt(g^2 + a^2), which differs from the fixed pivot's 2 pi sqrt(l / g) by 2.8 %; period from 10 zero crossings."""
    a, length, amplitude = ACCELERATION, 1.0, 0.01
    tilt = math.atan(a / G)
    sim = ln.Simulator(pendulum(-tilt + amplitude, length), method="dop853", rtol=1e-11, backend="native")
    times = np.arange(1, 2001) * 0.005
    swing = [amplitude]
    for i, t in enumerate(times):
        sim.advance(t, anchors=hold([0, 0, 0], [0, 0, 0], [a, 0, 0]) if i == 0 else None)
        swing.append(_angle_from_down(sim) + tilt)
    crossings = _zero_crossings(np.concatenate([[0.0], times]), np.array(swing))
    assert crossings.size >= 9
    measured = 2.0 * (crossings[-1] - crossings[0]) / (crossings.size - 1)
    g_eff = math.hypot(G, a)
    expected = 2.0 * math.pi * math.sqrt(length / g_eff) * (1.0 + amplitude ** 2 / 16.0)
    print(f"\naccelerated pivot a = {a} m/s2: period {measured:.10f} s, 2 pi sqrt(l/g_eff)(1 + th^2/16) = "
          f"{expected:.10f} s, relative error {measured / expected - 1:.2e}; fixed pivot "
          f"{2 * math.pi * math.sqrt(length / G):.6f} s")
    assert measured == pytest.approx(expected, rel=1e-7)
    # the swing is symmetric about atan(a/g): about any other angle its half periods would alternate in length
    half_periods = np.diff(crossings)
    print(f"half periods vary by {np.ptp(half_periods):.1e} s")
    assert np.ptp(half_periods) < 1e-6 * measured


# ---- Galilean invariance ----------------------------------------------------------------------------------------
VELOCITY = np.array([0.7, -0.4, 0.3])
# Step settings of the Galilean runs. The Runge-Kutta methods' error control weighs each component with
# atol + rtol |y|, and the positions differ between the frames; with atol dominating (rtol |y| ~ 1e-15), both runs
# take the same steps (checked), so the comparison measures the dynamics and not the step-size controller.
GALILEAN = {"rattle": {"dt": 2e-3}, "yoshida4": {"dt": 4e-3}, "suzuki4": {"dt": 4e-3}, "yoshida6": {"dt": 5e-3},
            "yoshida8": {"dt": 5e-3}, "dopri5": {"rtol": 1e-15, "atol": 1e-8}, "dop853": {"rtol": 1e-15, "atol": 1e-8}}


def _galilean_pair(kind: str):
    """The scene with a fixed pivot, and the same with the pivot and every mass moving at VELOCITY."""
    fixed = builders.pendulum(angle_deg=60.0) if kind == "pendulum" else builders.chain(4, shape="horizontal")
    moving = drive(fixed, 0, {"kind": "velocity", "velocity": VELOCITY.tolist()})
    U0 = np.array(moving.U0)
    U0[1:] += VELOCITY
    return fixed, moving.with_state(U0=U0)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("method", ALL_METHODS)
@pytest.mark.parametrize("kind", ["pendulum", "chain"])
def test_pivot_at_constant_velocity_is_the_fixed_pivot_in_the_moving_frame(kind, method, backend):
    """X(t) - v t and U(t) - v of the moving scene equal the fixed-pivot run's X(t), U(t) (and the tensions are
    the same) to round-off: up to 3e-14 m and 7e-13 m/s after 75 steps, the position stage's 1e-14 tolerance
    included."""
    fixed, moving = _galilean_pair(kind)
    at_rest = ln.Simulator(fixed, method=method, backend=backend, **GALILEAN[method])
    carried = ln.Simulator(moving, method=method, backend=backend, **GALILEAN[method])
    assert carried.initial_report.velocity_correction == 0.0
    errors = np.zeros(3)
    # the first advance is shorter than either run's initial step guess, so both start with the same step
    for t in (0.01, 0.05, 0.1, 0.15):
        at_rest.advance(t)
        carried.advance(t)
        T_rest, T_carried = at_rest.outputs()["T"], carried.outputs()["T"]
        errors = np.maximum(errors, [np.abs(carried.state.X - VELOCITY * t - at_rest.state.X).max(),
                                     np.abs(carried.state.U - VELOCITY - at_rest.state.U).max(),
                                     np.abs(T_carried - T_rest).max() / max(1.0, np.abs(T_rest).max())])
    assert carried.integrator.stats.steps == at_rest.integrator.stats.steps
    print(f"\nGalilean {kind} {method} {backend}: |dX| {errors[0]:.1e} m, |dU| {errors[1]:.1e} m/s, "
          f"|dT|/T {errors[2]:.1e}")
    assert errors[0] < 2e-13 and errors[1] < 5e-12 and errors[2] < 2e-12, errors


# ---- Kapitza pendulum -------------------------------------------------------------------------------------------
KAPITZA_LENGTH, KAPITZA_AMPLITUDE = 0.2, 0.01  # m; a / l = 0.05


def _kapitza(ratio: float, t_end: float, samples: int):
    """The pendulum 0.1 rad off the inverted position, its pivot vibrated vertically at w = ratio w_c, w_c =
    sqrt(2 g l) / a (phase pi/2: the pivot starts at rest). The angle from the upward vertical at the samples."""
    length, a = KAPITZA_LENGTH, KAPITZA_AMPLITUDE
    omega = ratio * math.sqrt(2.0 * G * length) / a
    motion = {"kind": "sine", "amplitude": [0.0, 0.0, a], "frequency": [0.0, 0.0, omega / (2.0 * math.pi)],
              "phase": [0.0, 0.0, math.pi / 2]}
    sim = ln.Simulator(pendulum(math.pi - 0.1, length, motion=motion), method="rattle",
                       dt=2.0 * math.pi / omega / 100, backend="native")
    assert sim.initial_report.velocity_correction == 0.0
    times = np.linspace(0.0, t_end, samples + 1)[1:]
    up = []
    for t in times:
        sim.advance(t)
        d = sim.state.X[1] - sim.state.X[0]
        up.append(math.atan2(d[0], d[2]))
    return omega, times, np.array(up)


def test_kapitza_pendulum_is_stable_inverted_above_the_threshold():
    """a^2 w^2 = 2.25 * 2 g l: the inverted pendulum stays within its initial 0.1 rad for 4 s (190 drive periods)
    and swings about the top with the averaged theory's period 2 pi / sqrt(a^2 w^2 / (2 l^2) - g / l)."""
    omega, times, up = _kapitza(1.5, 4.0, 2000)
    slow = _zero_crossings(times, up)
    measured = 2.0 * (slow[-1] - slow[0]) / (slow.size - 1)
    a, length = KAPITZA_AMPLITUDE, KAPITZA_LENGTH
    averaged = 2.0 * math.pi / math.sqrt(a * a * omega * omega / (2 * length * length) - G / length)
    print(f"\nKapitza a^2w^2/(2gl) = 2.25: max |angle from up| {np.abs(up).max():.4f} rad over "
          f"{omega * times[-1] / (2 * math.pi):.0f} drive periods; slow period {measured:.4f} s, averaged theory "
          f"{averaged:.4f} s ({measured / averaged - 1:+.2%})")
    assert np.abs(up).max() < 0.101
    assert measured == pytest.approx(averaged, rel=0.01)


def test_kapitza_pendulum_falls_below_the_threshold():
    """a^2 w^2 = 0.49 * 2 g l: the same start falls (past horizontal) within the first second."""
    omega, times, up = _kapitza(0.7, 1.5, 300)
    fell = np.flatnonzero(np.abs(up) > math.pi / 2)
    print(f"\nKapitza a^2w^2/(2gl) = 0.49: past horizontal at t = {times[fell[0]] if fell.size else None} s")
    assert fell.size and times[fell[0]] < 1.0


# ---- anchor velocity jumps ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("theta", [0.0, 0.6])
@pytest.mark.parametrize("jump", [[0.0, 0.0, 0.8], [0.8, 0.0, 0.0], [0.3, -0.5, 0.7]])
def test_anchor_velocity_jump_is_the_inelastic_impulse(jump, theta, backend):
    """A pivot at rest jumps to velocity V: (12) keeps the bob's velocity along the rod E equal to the pivot's, and
    nothing else changes, so the bob gets (V.E) E and the rod gives the pivot the impulse -M (V.E) E (a vertical
    jump under a hanging bob: -M V; a perpendicular one: nothing). No gravity, so that the state right after the
    jump is seen after 1 us, up to the centripetal term |V_perp|^2/l * 1 us."""
    mass, length = 2.0, 1.5
    scene = pendulum(theta, length, mass, gravity=0.0)
    sim = ln.Simulator(scene, method="rattle", dt=1e-3, backend=backend)
    V = np.array(jump)
    sim.advance(1e-6, anchors=hold([0, 0, 0], V, [0, 0, 0]))
    E = scene.X0[1] / length
    along = float(V @ E) * E
    report = sim.anchor_report()
    np.testing.assert_allclose(report["impulse"], [-mass * along], atol=1e-14)
    np.testing.assert_allclose(sim.state.U[1], along, atol=2e-6 * float(V @ V) / length)
    assert report["jumps"] == 1 and report["jump_velocity"] == pytest.approx(np.abs(V).max())
    np.testing.assert_allclose(sim.outputs()["impulse"], report["impulse"])


@pytest.mark.parametrize("backend", BACKENDS)
def test_hanging_chain_follows_a_vertical_jump_and_stop_of_its_anchor(backend):
    """A straight hanging chain (total mass 1) under an input-driven anchor: a jump to v upwards gives every mass v
    (impulse -M v on the anchor), the chain rides up rigidly (gravity is balanced by the tensions), and the stop
    takes the momentum back (impulse +M v)."""
    v = 0.6
    scene = drive(builders.chain(5, shape="hanging"), 0)
    total = float(np.sum(scene.mass[1:]))
    sim = ln.Simulator(scene, method="yoshida4", dt=5e-3, backend=backend)
    sim.advance(0.2, anchors=hold([0, 0, 0], [0, 0, v], [0, 0, 0]))
    np.testing.assert_allclose(sim.anchor_report()["impulse"], [[0.0, 0.0, -total * v]], atol=1e-14)
    np.testing.assert_allclose(sim.state.U[1:], np.tile([0.0, 0.0, v], (5, 1)), atol=1e-13)
    np.testing.assert_allclose(sim.state.X - scene.X0, np.tile([0.0, 0.0, 0.2 * v], (6, 1)), atol=1e-13)
    sim.advance(0.4, anchors=hold([0, 0, 0.2 * v], [0, 0, 0], [0, 0, 0]))
    report = sim.anchor_report()
    np.testing.assert_allclose(report["impulse"], [[0.0, 0.0, total * v]], atol=1e-14)
    assert report["jumps"] == 2
    np.testing.assert_allclose(sim.state.U, 0.0, atol=1e-13)
    np.testing.assert_allclose(sim.state.X - scene.X0, np.tile([0.0, 0.0, 0.2 * v], (6, 1)), atol=1e-13)


# ---- measured convergence orders ---------------------------------------------------------------------------------
ORDER_END = 0.4
# step counts per nominal order, so that the errors lie between truncation and round-off; all even, so that a spline
# knot at t = 0.2 falls on a step boundary
COUNTS = {2: [40, 80, 160, 320], 4: [20, 40, 80, 160], 5: [32, 64, 128], 6: [16, 24, 36, 54], 8: [12, 16, 22, 30]}
# a knot at 0.2 inside the run: the spline is C2 only (its third derivative jumps), so only methods whose stages stay
# inside the step keep their order across it when a step boundary falls on the knot
ACROSS_A_KNOT = {"kind": "waypoints", "waypoints": [[0.2, 0.05, 0.02, 0.1], [0.5, 0.3, -0.1, 0.0],
                                                    [0.9, 0.2, 0.0, 0.0]]}
# The waypoint spline's first piece continues before tau = 0, where the compositions' substeps of the first step
# reach (partial sums of their gammas down to -0.16 h for yoshida6, -0.50 h for yoshida8): a rest row there would put
# an acceleration jump at tau = 0 and cut their order (measured with it: yoshida6 6.04, 4.88, 3.87; yoshida8 9.27,
# 3.35, 2.68).
ORDER_CASES = ([(m, "sine") for m in ALL_METHODS] + [(m, "waypoints") for m in ALL_METHODS]
               + [(m, "waypoints across a knot") for m in ("rattle", "dopri5", "dop853")])
_references = {}


def _order_scene(motion_name: str) -> ln.Scene:
    motion = ACROSS_A_KNOT if motion_name == "waypoints across a knot" else MOTIONS[motion_name]
    return driven_chain(motion)


def _reference(motion_name: str) -> np.ndarray:
    if motion_name not in _references:
        sim = ln.Simulator(_order_scene(motion_name), method="dop853", rtol=1e-14, atol=1e-15, backend="native")
        sim.advance(ORDER_END)
        _references[motion_name] = sim.state.X
    return _references[motion_name]


@pytest.mark.parametrize("method,motion_name", ORDER_CASES)
def test_measured_convergence_order_with_a_driven_anchor_equals_nominal(method, motion_name):
    """A 3-link chain released horizontally from a driven anchor; errors of the positions at t = 0.4 against DOP853
    at rtol 1e-14. Fixed-step methods on the native core (exactly n steps); the Runge-Kutta methods in fixed steps
    (ProjectedRungeKutta.fixed_steps, stages at t + c_i h) on the numpy reference."""
    scene = _order_scene(motion_name)
    X_ref = _reference(motion_name)
    cls = METHODS[method]
    counts = COUNTS[cls.order]
    errors = []
    for n in counts:
        h = ORDER_END / n
        if cls.adaptive:
            sim = ln.Simulator(scene, method=method, rtol=1e-6, backend="numpy")
            X, _ = sim.integrator.fixed_steps(sim.state.X, sim.state.U, h, n, None, 0.0)
        else:
            sim = ln.Simulator(scene, method=method, dt=h, backend="native")
            sim.advance(ORDER_END)
            assert sim.integrator.stats.steps == n
            X = sim.state.X
        errors.append(float(np.abs(X - X_ref).max()))
    slopes = -np.diff(np.log(errors)) / np.diff(np.log(counts))
    observed = float(np.median(slopes))
    print(f"\norder {method} {motion_name}: errors {', '.join(f'{e:.2e}' for e in errors)}, slopes "
          f"{', '.join(f'{s:.2f}' for s in slopes)}, median {observed:.2f} (nominal {cls.order})")
    # above nominal is the pre-asymptotic range (the next term of the error still counts: DOP853 measures 8.9 on the
    # sine until round-off); below it is what this test is for
    assert cls.order - 0.35 <= observed <= cls.order + 1.0, f"errors {errors}, slopes {slopes}"


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_a_snapshot_carries_the_last_jumps_impulse(backend):
    """get_state/set_state bring back what anchor_report says about the last jump (the FMUs' Jreact after a
    restored state), not the impulse of whatever ran after the snapshot."""
    scene = builders.chain(10).with_motions({1: {"kind": "input"}})
    sim = ln.Simulator(scene, method="rattle", dt=1e-3, backend=backend)
    Z = np.zeros((1, 3))
    sim.advance(0.01, anchors=(Z, np.array([[1.0, 0.0, 0.0]]), Z))  # the anchor starts moving: an impulse
    report = sim.anchor_report()
    assert report["jumps"] == 1 and report["impulse"][0, 0] < 0
    snapshot = sim.get_state()
    sim.advance(0.02, anchors=(np.array([[0.01, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]), Z))
    assert not np.array_equal(sim.anchor_report()["impulse"], report["impulse"])
    sim.set_state(snapshot)
    restored = sim.anchor_report()
    assert np.array_equal(restored["impulse"], report["impulse"]) and restored["jumps"] == 1
    assert np.array_equal(sim.outputs()["impulse"], report["impulse"])


@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_the_first_sample_starts_with_the_anchors_motion_given_to_simulate(backend):
    """simulate(..., anchors=(P, V, A)): the sample at t = 0 is the state the run starts from, after the jump to the
    anchors' motion, with its tensions. A bob of 2 kg hanging at rest from an input-driven pivot: the pivot
    accelerating upwards at a gives T = m (g + a); the pivot moving up at 1 m/s carries the bob with it (an
    inelastic impulse along the rod), T = m g, and the sample shows both moving."""
    scene = pendulum(0.0, mass=2.0)
    up = ln.simulate(scene, 0.1, method="rattle", dt=1e-3, n_out=3, backend=backend,
                     anchors=hold([0, 0, 0], [0, 0, 0], [0, 0, 0.784]))
    assert up.T[0, 0] == pytest.approx(2.0 * (G + 0.784), rel=1e-12)
    moving = ln.simulate(scene, 0.1, method="rattle", dt=1e-3, n_out=3, backend=backend,
                         anchors=hold([0, 0, 0], [0, 0, 1.0], [0, 0, 0]))
    np.testing.assert_allclose(moving.U[0], [[0, 0, 1.0], [0, 0, 1.0]], atol=1e-12)
    assert moving.T[0, 0] == pytest.approx(2.0 * G, rel=1e-12)
    # the next sample continues from there: pivot and bob risen together by 5 cm (less the bob's fall under g
    # against the rod: none, the rod holds it)
    np.testing.assert_allclose(moving.X[1][:, 2], [0.05, -0.95], atol=1e-9)
