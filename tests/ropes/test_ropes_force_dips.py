"""A rope's tension that falls through zero and rises again within one adaptive step: a bob whirled in a vertical
circle with slightly too little speed to keep its rope taut over the top. The tension m (v^2 / R - g cos phi)
(phi from the top) is negative only over a short arc around the top, a few ms where the adaptive step is tens of
ms: the step's ends both have the rope pulling. The event integrators screen the forces at the method's inner
stages and find the slack there; the reference is the closed form: the slack angle where the tension vanishes,
its time by quadrature of the pendulum's energy, then the ballistic flight to |X| = R. Both the numpy reference
(events.py, EventHandling._force_dip_at_stages) and the native core (stages/ropes.c, rope_force_dip_at_stages)
are held to it. A fixed-step composition screens the forces at its RATTLE stages' midpoints the same way
(FixedStepEvents._midpoint_tensions, rope_keep_midpoint): Suzuki's order-4 composition finds a dip that lies inside
one of its steps, at the closed-form times within its own order-4 error; plain RATTLE (its midpoint alone) and the
triple jump find a bob's slack inside one step of a hand shaking it, a motion they follow exactly, to round-off."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import quad
from scipy.optimize import brentq

import linknet_core as ln
from tests.ropes.rope_references import G, ballistic, bob_scene, first_exit

R = 1.0


def loop_reference(shortfall):
    """(slack time, taut time, radial speed at the jerk) of a bob started at the bottom with the speed that would
    bring it over the top with v^2 = g R (1 - shortfall)."""
    vb2 = G * R * (1.0 - shortfall) + 4.0 * G * R
    cos_top = (vb2 - 2.0 * G * R) / (3.0 * G * R)  # T = 0: v^2 / R = g cos(phi), v^2 = vb2 - 2 g R (1 + cos phi)
    theta = np.pi - np.arccos(cos_top)  # from the bottom
    t_slack = quad(lambda th: R / np.sqrt(vb2 - 2.0 * G * R * (1.0 - np.cos(th))), 0.0, theta,
                   epsabs=0.0, epsrel=1e-13, limit=200)[0]
    v = np.sqrt(vb2 - 2.0 * G * R * (1.0 - np.cos(theta)))
    X = R * np.array([np.sin(theta), 0.0, -np.cos(theta)])
    V = v * np.array([np.cos(theta), 0.0, np.sin(theta)])
    s = first_exit(X, V, R, 0.2)
    Xt, Vt = ballistic(X, V, s)
    return t_slack, t_slack + s, float(Xt @ Vt) / R, np.sqrt(vb2)


@pytest.mark.parametrize("backend", ["numpy", "native"])
@pytest.mark.parametrize("method, time_tol", [("dop853", 2e-8), ("dopri5", 1e-7)])
@pytest.mark.parametrize("shortfall", [1e-4, 1e-5])
def test_slack_over_the_top_inside_a_step(method, time_tol, shortfall, backend):
    t_slack, t_taut, radial, v_bottom = loop_reference(shortfall)
    # the dip in tension lasts (t_taut - t_slack): a few ms, well inside one step at this tolerance
    assert t_taut - t_slack < 0.011
    run = ln.simulate(bob_scene([0, 0, -R], [v_bottom, 0, 0], R), 0.8, method=method, rtol=1e-10, n_out=5,
                      backend=backend)
    events = [e for e in run.events if e.t > 1e-3]
    assert [e.kind for e in events] == ["slack", "taut"]
    assert events[0].t == pytest.approx(t_slack, abs=time_tol)
    assert events[1].t == pytest.approx(t_taut, abs=5 * time_tol)
    # the jerk takes the radial velocity of the flight's end: impulse m |v_r| (mass 1)
    assert events[1].impulse == pytest.approx(radial, rel=1e-3)
    assert run.stats["steps"] < 200  # the adaptive steps stayed long: the dip was found inside one


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_a_loop_with_speed_to_spare_keeps_its_rope_taut(backend):
    v_bottom = np.sqrt(G * R * (1.0 + 1e-3) + 4.0 * G * R)  # over the top with v^2 = 1.001 g R: T > 0 throughout
    run = ln.simulate(bob_scene([0, 0, -R], [v_bottom, 0, 0], R), 0.8, rtol=1e-10, n_out=5, backend=backend)
    assert [e.kind for e in run.events if e.t > 1e-3] == []
    assert np.all(run.T[:, 0] > 0)


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_slack_over_the_top_inside_one_fixed_step_of_an_order_4_composition(backend):
    # shortfall 1e-3: slack for 33 ms around the top; at 19 steps over 0.8 s (42 ms) the whole dip lies inside the
    # step [15 h, 16 h], whose ends both have the rope pulling: it is found at the step's RATTLE stages' midpoints
    # (Suzuki's five, at 0.21, 0.38, 0.5, 0.62, 0.79 of the step). Its events' errors are the method's own: they fall
    # by 2^4 with the step (at 38 steps the dip spans two steps, seen at their ends). Plain RATTLE has its midpoint
    # alone, and in this scene its own order-2 error exceeds the dip at any step long enough to hold it (it finds no
    # slack at steps of 6.2 ms and longer).
    t_slack, t_taut, _, v_bottom = loop_reference(1e-3)
    h = 0.8 / 19
    assert 15 * h < t_slack and t_taut < 16 * h
    errors = []
    for n in (19, 38):
        run = ln.simulate(bob_scene([0, 0, -R], [v_bottom, 0, 0], R), 0.8, method="suzuki4", dt=0.8 / n, n_out=2,
                          error_estimate=False, backend=backend)
        events = [e for e in run.events if e.t > 1e-3]
        assert [e.kind for e in events] == ["slack", "taut"]
        errors.append(np.array([events[0].t - t_slack, events[1].t - t_taut]))
    assert np.abs(errors[0]).max() < 2e-3  # measured: 4.8e-4 s, 1.6e-3 s
    ratio = np.abs(errors[0] / errors[1])
    assert np.all((12 < ratio) & (ratio < 20)), ratio  # measured: 15.8, 15.9


@pytest.mark.parametrize("backend", ["numpy", "native"])
@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_a_bob_shaken_slack_inside_one_step_by_its_hand_is_found_at_its_midpoint(method, backend):
    # a bob hanging 1 m under a hand driven along z by a sine of 1 Hz whose crest accelerates it downward 2% faster
    # than g: the rope's tension m (g + a_hand) is below zero for 63 ms around the crest at 0.25 s, inside the step
    # [1/6, 2/6] s of six steps a second (both ends pulling); RATTLE's midpoint, at the crest, sees it. The bob
    # follows the hand rigidly (RATTLE's projections put it at the hand's distance and speed) and then flies
    # ballistically, both exact on these methods: slack where sin(w t) = 1 / 1.02, taut where the flight is 1 m
    # under the hand again, with the impulse m times their relative speed there, all to round-off
    w, a, R = 2 * np.pi, 1.02 * G / (2 * np.pi) ** 2, 1.0
    scene = ln.Scene.from_dict({"name": "shaken", "gravity": [0, 0, -G],
                                "masses": [{"name": "hand", "position": [0, 0, 0], "driven": True,
                                            "motion": {"kind": "sine", "amplitude": [0, 0, a],
                                                       "frequency": [0, 0, 1.0]}},
                                           {"name": "bob", "position": [0, 0, -R], "mass": 1.0}],
                                "links": [{"a": 1, "b": 2, "kind": "rope", "length": R}]})
    t_slack = np.arcsin(1 / 1.02) / w
    assert 1 / 6 < t_slack and t_slack + 2 * (0.25 - t_slack) < 2 / 6  # the dip inside one step

    def flight(t):  # the bob's height and speed after the slack
        s = t - t_slack
        return (a * np.sin(w * t_slack) - R + a * w * np.cos(w * t_slack) * s - 0.5 * G * s * s,
                a * w * np.cos(w * t_slack) - G * s)
    t_taut = brentq(lambda t: a * np.sin(w * t) - flight(t)[0] - R, 0.3, 0.4, xtol=1e-15)
    run = ln.simulate(scene, 1.0, method, dt=1 / 6, n_out=2, error_estimate=False, backend=backend)
    slack, taut = run.events[:2]
    assert (slack.kind, taut.kind) == ("slack", "taut")
    assert abs(slack.t - t_slack) < 1e-12 and abs(taut.t - t_taut) < 1e-12  # measured: 6e-14 s, 6e-15 s
    # measured: 3e-13 relative
    assert taut.impulse == pytest.approx(a * w * np.cos(w * t_taut) - flight(t_taut)[1], rel=1e-11)
