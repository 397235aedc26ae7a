"""The work-precision benchmark's rope scene (models/ropes/rope_swing.json): its event-driven reference against
closed forms, linknet's runs through the benchmark's adapter against that reference, and the MoorDyn peer against
the rigid limit it tends to (skipped where moordyn is not installed). Quick: ~3 s of CPU."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks import work_precision as wp
from benchmarks.peers.base import Unsupported
from benchmarks.peers.moordyn_peer import MoorDynLine
from benchmarks.rope_reference import RopeReference, solve_ropes

pytest.importorskip("linknet_core")

G, R, V0 = 9.81, 1.0, 5.0   # rope_swing: a 1 kg bob on a 1 m rope, swung from the bottom at 5 m/s


@pytest.fixture(scope="module")
def spec():
    return wp.load_benchmark_scene("rope_swing")


@pytest.fixture(scope="module")
def reference(spec):
    X, U, _, _, events = solve_ropes(spec, wp.SCENES["rope_swing"], 1e-13)
    return X, U, events


def test_the_scene_is_what_the_reference_and_the_peers_are_told(spec):
    assert spec.rope.tolist() == [True] and spec.restitution.tolist() == [1.0] and spec.unilateral
    assert np.allclose(spec.X0[1], [0, 0, -R]) and np.allclose(spec.U0[1], [V0, 0, 0])


def test_the_reference_swings_leaves_the_circle_where_the_tension_vanishes_and_bounces_elastically(spec, reference):
    """The slack event where m v^2 / R + m g cos(theta) = 0 with v^2 = v0^2 - 2 g R (1 - cos(theta)): cos(theta) =
    (2 g R - v0^2) / (3 g R); then flights, each ended where |X| = R, whose radial velocity the jerk reverses; the
    energy is kept (restitution 1)."""
    ref = RopeReference(spec, 1e-13)
    ref.run(1.2)
    (t_slack, kind, _, _), (t_taut, kind2, _, impulse) = ref.events[:2]
    assert (kind, kind2) == ("slack", "taut")
    cos_theta = (2 * G * R - V0 ** 2) / (3 * G * R)
    # the state at the slack event: rerun to it and compare the angle from the downward vertical
    X, U = RopeReference(spec, 1e-13).run(t_slack)
    assert abs(-X[1, 2] / R - cos_theta) < 1e-10
    # ballistic flight from there (closed form) reaches |X| = R at the taut event
    g = np.array([0.0, 0.0, -G])
    s = t_taut - t_slack
    Xf = X[1] + U[1] * s + 0.5 * g * s * s
    assert abs(np.linalg.norm(Xf) - R) < 1e-10
    # the jerk's impulse is 2 m v_r (the radial velocity reversed)
    Uf = U[1] + g * s
    assert abs(impulse - 2 * (Uf @ Xf) / R) < 1e-9
    Xe, Ue, events = reference
    energy = 0.5 * Ue[1] @ Ue[1] + G * Xe[1, 2]
    assert len(events) == 6 and abs(energy - (0.5 * V0 ** 2 - G * R)) < 1e-11


@pytest.mark.parametrize("method, knob, bound", [
    ("dop853", 1e-8, 1e-6),     # adaptive: within its stated contract, error <= 1e3 rtol (measured 1.1e-7 m)
    ("dopri5", 1e-8, 1e-6),     # (measured 4.0e-8 m)
])
def test_linknet_adaptive_methods_meet_the_reference_through_the_events(spec, reference, method, knob, bound):
    from benchmarks.peers.linknet_methods import LinknetMethod
    run = LinknetMethod(method).run(spec, wp.SCENES["rope_swing"], knob)
    assert np.abs(run.X - reference[0]).max() <= bound


def test_linknet_rattle_keeps_its_order_through_the_events(spec, reference):
    """RATTLE at dt and dt/2 through the slack event and five jerks: the error falls by 4 (order 2)."""
    from benchmarks.peers.linknet_methods import LinknetMethod
    errors = [np.abs(LinknetMethod("rattle").run(spec, wp.SCENES["rope_swing"], dt).X - reference[0]).max()
              for dt in (0.005, 0.0025)]
    order = math.log2(errors[0] / errors[1])
    assert 1.8 <= order <= 2.2 and errors[1] < 3e-3, errors


def test_peers_of_rods_refuse_the_rope_scene_and_moordyn_refuses_an_inelastic_rope(spec):
    from benchmarks.peers.scipy_baseline import ScipyIVP
    with pytest.raises(Unsupported, match="ropes"):
        wp._check_models(ScipyIVP("DOP853"), spec)
    inelastic = wp.load_benchmark_scene("rope_pendulum")
    with pytest.raises(Unsupported, match="restitution 0"):
        MoorDynLine(1e8).check_scene(inelastic)
    MoorDynLine(1e8).check_scene(spec)


def test_moordyn_missing_is_reported_not_raised(monkeypatch):
    monkeypatch.setitem(sys.modules, "moordyn", None)   # import moordyn now raises ImportError
    ok, why = MoorDynLine(1e8).available()
    assert not ok and "moordyn not importable" in why


def test_moordyn_tends_to_the_rigid_rope_as_its_stiffness_grows(spec):
    """While the rope is taut (the first 0.4 s) an elastic line's error is its model's, ~T R / EA: 100 times smaller
    for 100 times the stiffness, and within a few times the stretch T R / EA = 35 N x 1 m / EA."""
    pytest.importorskip("moordyn")
    t = 0.4
    rigid = solve_ropes(spec, t, 1e-13)[0]
    errors = []
    for EA in (1e6, 1e8):
        line = MoorDynLine(EA)
        run = line.run(spec, t, line.knobs(spec, quick=True)[2])
        errors.append(np.abs(run.X - rigid).max())
    assert errors[1] < 1e-6 and 50 < errors[0] / errors[1] < 200, errors
