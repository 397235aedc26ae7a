"""The MoorDyn comparison's rope scenes of several segments (models/ropes/chains): the event-driven reference against
closed forms and the energy an elastic rope keeps, linknet against that reference, the MoorDyn peer's two regimes
(its stretch ~1/EA while taut; a jerk of the whole taut rope that a stiffer line does not bring closer to the rigid
one), the seabed scenes (landing, sliding, dragged by a driven anchor) against their closed forms, and the study's
smoke runs. The MoorDyn checks skip where moordyn is not installed. Quick: ~7 s of CPU."""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from benchmarks import moordyn_study as study  # noqa: E402
from benchmarks.peers.moordyn_peer import MoorDynLine  # noqa: E402
from benchmarks.rope_reference import RopeReference, solve_ropes_at  # noqa: E402

pytest.importorskip("linknet_core")

G, R, M = 9.81, 0.25, 0.125   # both scenes: 8 segments of 0.25 m, 0.125 kg at each node


@pytest.fixture(scope="module")
def drop():
    return study.load_scene(study.STUDIES["rope_chain_drop"])


@pytest.fixture(scope="module")
def whip():
    return study.load_scene(study.STUDIES["rope_chain_whip"])


def energy(spec, X, U):
    m = spec.mass[spec.free]
    X, U = X[spec.free], U[spec.free]
    return float(0.5 * m @ np.sum(U * U, axis=1) - m @ (X @ spec.gravity))


def test_the_scenes_are_what_the_study_says(drop, whip):
    for spec in (drop, whip):
        assert spec.K == 9 and spec.L == 8 and spec.rope.all() and np.all(spec.restitution == 1.0)
        assert np.allclose(spec.length, R) and np.allclose(spec.mass[spec.free], M) and spec.fixed.tolist()[0]
    gaps = np.linalg.norm(drop.X0[drop.k2] - drop.X0[drop.k1], axis=1)
    assert np.all(gaps < 0.75 * R) and not drop.U0.any()          # every segment slack, at rest
    assert np.allclose(whip.X0[1:, 2], -R * np.arange(1, 9)) and whip.U0[8].tolist() == [2.0, 0.0, 2.0]


def test_the_dropped_rope_falls_freely_until_its_first_segment_snaps_and_keeps_its_energy(drop):
    """The free nodes fall together (the segments between them keep their lengths) until the first segment reaches
    its length: node 1 from (0.15, 0, -0.1) to z = -0.2, at t = sqrt(2 x 0.1 / g); the jerk reverses its radial
    velocity (impulse 2 m v_r, restitution 1). Every jerk after keeps the energy."""
    ref = RopeReference(drop, 1e-13)
    (X, U), (Xe, Ue) = ref.run_at([0.1, 1.0])
    t1 = math.sqrt(2 * 0.1 / G)
    assert np.allclose(X[1:], drop.X0[1:] + [0, 0, -0.5 * G * 0.1 ** 2], atol=1e-13)
    t, kind, link, impulse = ref.events[0]
    assert (kind, link) == ("taut", 0) and abs(t - t1) < 1e-12
    assert abs(impulse - 2 * M * G * t1 * 0.2 / R) < 1e-11       # v_r = g t1 (0.2 / R), the fall along the segment
    assert len(ref.events) > 100 and {e[1] for e in ref.events} == {"taut"}   # every jerk a rebound, none stays taut
    assert abs(energy(drop, Xe, Ue) - energy(drop, drop.X0, drop.U0)) < 1e-11
    lengths = np.linalg.norm(Xe[drop.k2] - Xe[drop.k1], axis=1)
    assert np.all(lengths <= R * (1 + 1e-12))


def test_the_whip_flies_its_end_on_a_parabola_until_it_jerks_the_taut_rope_and_keeps_its_energy(whip):
    """The rope above the thrown end hangs at rest, taut; the end flies from (0, 0, -2) at (2, 0, 2) m/s until it is
    0.25 m from node 7 (the root of a quartic in t); Newton's restitution 1 on the jerked segment, with the taut
    ones held, keeps the energy (every row with an impulse leaves at minus its arriving rate)."""
    ref = RopeReference(whip, 1e-13)
    (X, _), (Xe, Ue) = ref.run_at([0.1, 1.0])
    t, kind, link, _ = ref.events[0]
    P = np.polynomial.polynomial
    gap = P.polyadd(P.polypow([0, 2], 2), P.polypow([-R, 2, -G / 2], 2))   # |X8(t) - X7|^2, ascending powers of t
    gap[0] -= R * R
    roots = P.polyroots(gap)
    t_closed = min(r.real for r in roots if abs(r.imag) < 1e-12 and r.real > 1e-9)
    assert (kind, link) == ("taut", 7) and abs(t - t_closed) < 1e-12
    assert np.allclose(X[1:8], whip.X0[1:8], atol=1e-13)             # the taut rope at rest meanwhile
    assert abs(energy(whip, Xe, Ue) - energy(whip, whip.X0, whip.U0)) < 1e-10
    assert {e[2] for e in ref.events} == {7}                          # the other segments never go slack


@pytest.mark.parametrize("scene, t_end", [("rope_chain_drop", 0.5), ("rope_chain_whip", 0.6)])
def test_linknet_meets_the_reference_on_both_engines(scene, t_end):
    """Adaptive dop853 at rtol 1e-9 on the numpy reference path and the native core (where it takes ropes)."""
    import linknet_core as ln
    spec = study.load_scene(study.STUDIES[scene])
    X_ref = solve_ropes_at(spec, [t_end], 1e-13)[0][0]
    for backend in ("numpy", "native"):
        try:
            sim = ln.Simulator(ln.Scene.from_dict(spec.to_dict()), method="dop853", rtol=1e-9, backend=backend)
        except ln.SolverError:
            continue
        sim.advance(t_end)
        assert np.abs(sim.state.X - X_ref).max() < 1e-7, backend


def test_moordyn_runs_at_a_numpy_step_and_lets_free_nodes_fall_exactly(drop):
    """RK4 integrates a constant acceleration exactly: before the first jerk (0.143 s) every node has fallen
    g t^2 / 2. The step given as a numpy scalar (as a sweep computes it) runs."""
    pytest.importorskip("moordyn")
    X, _ = MoorDynLine(1e6).trajectory(drop, [0.1], np.float64(2.5e-4))
    assert np.allclose(X[0][1:], drop.X0[1:] + [0, 0, -0.5 * G * 0.1 ** 2], atol=1e-12)


def test_moordyn_stretches_the_taut_rope_then_misses_the_rigid_jerk_at_any_stiffness(whip):
    """Before the end's jerk (0.1 s) the rope above hangs still, each segment longer by T R / EA: node 7 lower by
    28 m g R / EA (T = m g (8 - i) on segment i). After the jerk (0.3 s) a stiffer line does not come closer to the
    rigid rope: its jerk travels along the elastic segments as a wave, where the rigid rope's moves them all at once
    (a single rope's jerk error falls as 1/sqrt(EA): 10 times for 100 times the stiffness)."""
    pytest.importorskip("moordyn")
    X_ref = solve_ropes_at(whip, [0.1, 0.3], 1e-13)[0]
    err = {}
    for EA in (1e6, 1e8):
        line = MoorDynLine(EA)
        dt = study.whole_steps(0.1, line.knobs(whip, quick=True)[2])
        Xs, _ = line.trajectory(whip, [0.1, 0.3], dt)
        err[EA] = [float(np.abs(X - Xr).max()) for X, Xr in zip(Xs, X_ref)]
        stretch = 28 * M * G * R / EA
        assert abs(err[EA][0] - stretch) < 0.01 * stretch, (EA, err[EA])
    assert 5e-3 < err[1e6][1] < 5e-2 and 0.5 < err[1e8][1] / err[1e6][1] < 2, err


def test_the_study_smoke_run_writes_its_tables(tmp_path):
    pytest.importorskip("moordyn")
    result = study.main(["--scene", "rope_chain_drop", "--quick", "--out", str(tmp_path)])
    saved = json.loads((tmp_path / "rope_peer_chain_drop.json").read_text())
    assert saved["quick"] and saved["times"] == [0.2, 0.3] and saved["frontier"] == json.loads(
        json.dumps(result["frontier"]))
    assert max(saved["reference_agreement"]) < 1e-10
    assert {r["EA"] for r in saved["moordyn"]} == {study.QUICK_EA}
    # between the jerks every node flies freely: linknet's only error is where it locates them
    numpy_rows = [r for r in saved["linknet"] if r["backend"] == "numpy"]
    assert numpy_rows and all(r["errors"][-1] < 1e-6 for r in numpy_rows)


# ---------------------------------------------------------------------- the seabed: a rope that lands and slides
@pytest.fixture(scope="module")
def landing():
    return study.load_scene(study.STUDIES["rope_chain_seabed_landing"])


@pytest.fixture(scope="module")
def slide():
    return study.load_scene(study.STUDIES["rope_chain_seabed_slide"])


def test_the_landing_rope_lands_node_by_node_at_sqrt_2h_over_g_and_lies_slack(landing):
    """The zig-zag falls freely onto the seabed 0.15 m below its anchor: the lower nodes (0.05 m above it) land at
    sqrt(2 x 0.05 / g), the upper ones (0.15 m) at sqrt(2 x 0.15 / g), and lie where they landed; no segment
    reaches its length (the closed form refuses a scene where one does). linknet on both engines: a contact event
    at each landing, to 1e-12 s, and nothing else; its positions meet the closed form to round-off."""
    import linknet_core as ln
    from benchmarks.rope_reference import slack_rope_on_ground
    times = [0.05, 0.15, 0.5]
    Xs, land = slack_rope_on_ground(landing, times)
    lower, upper = math.sqrt(2 * 0.05 / G), math.sqrt(2 * 0.15 / G)
    assert np.allclose(land[1::2], lower, rtol=0, atol=1e-15) and np.allclose(land[2::2], upper, rtol=0, atol=1e-15)
    assert np.allclose(Xs[0][1:, 2], landing.X0[1:, 2] - 0.5 * G * 0.05 ** 2, atol=1e-15)
    assert np.allclose(Xs[1][1::2, 2], -0.15, atol=1e-15) and np.all(Xs[1][2::2, 2] > -0.15)
    assert np.allclose(Xs[2][1:, :2], landing.X0[1:, :2], atol=1e-15) and np.allclose(Xs[2][1:, 2], -0.15, atol=1e-15)
    scene = ln.Scene.from_dict(landing.to_dict())
    for backend in ("numpy", "native"):
        run = ln.simulate(scene, t_end=0.5, method="dop853", rtol=1e-9, backend=backend, n_out=11,
                          error_estimate=False)
        assert {e.kind for e in run.events} == {"contact"}, backend
        hit = {e.index: e.t for e in run.events}
        assert sorted(hit) == list(range(1, 9)), backend
        assert max(abs(t - (lower if k % 2 else upper)) for k, t in hit.items()) < 1e-12, (backend, hit)
        for t, X in zip(times, Xs):
            i = int(np.argmin(np.abs(run.t - t)))
            assert abs(run.t[i] - t) < 1e-12 and np.abs(run.X[i] - X).max() < 1e-12, (backend, t)


def test_the_sliding_rope_stops_node_by_node_at_v_over_mu_g(slide):
    """Each node, thrown sideways at v_k = 0.5 + 0.05 k m/s on the rough seabed (mu 0.5), slides v_k^2 / (2 mu g)
    and stops at v_k / (mu g); the segments stay slack. linknet on both engines: a stick event at each stop, to
    1e-9 s, and the closed form's positions to round-off."""
    import linknet_core as ln
    from benchmarks.rope_reference import slack_rope_on_ground
    mu, v = 0.5, 0.5 + 0.05 * np.arange(1, 9)
    Xs, _ = slack_rope_on_ground(slide, [0.1, 0.3])
    assert np.allclose(Xs[1][1:, 1], v ** 2 / (2 * mu * G), atol=1e-15)   # all stopped by 0.183 s
    t = 0.1   # every node still sliding (the first stops at 0.112 s)
    assert np.allclose(Xs[0][1:, 1], v * t - 0.5 * mu * G * t * t, atol=1e-15)
    scene = ln.Scene.from_dict(slide.to_dict())
    for backend in ("numpy", "native"):
        run = ln.simulate(scene, t_end=0.3, method="dop853", rtol=1e-9, backend=backend, n_out=4,
                          error_estimate=False)
        stops = {e.index: e.t for e in run.events if e.kind == "stick"}
        assert sorted(stops) == list(range(1, 9)), (backend, run.events)
        assert max(abs(t - v[k - 1] / (mu * G)) for k, t in stops.items()) < 1e-9, (backend, stops)
        for t, X in zip([0.1, 0.3], Xs):
            i = int(np.argmin(np.abs(run.t - t)))
            assert abs(run.t[i] - t) < 1e-12 and np.abs(run.X[i] - X).max() < 1e-12, (backend, t)


def test_moordyn_sinks_into_its_seabed_by_m_g_over_its_contact_stiffness(landing):
    """At rest on MoorDyn's seabed a point sinks m g / k, k = kb d L / 2 (L its lines' summed length): the penalty's
    error, 1/kb. The end node, on one line, sinks the most: 0.125 g / (kb d R / 2). A hundred times the stiffness,
    a hundredth of the sink."""
    pytest.importorskip("moordyn")
    from benchmarks.peers.moordyn_peer import DIAMETER
    from benchmarks.peers.moordyn_seabed import MoorDynSeabedLine
    X_ref = study.references(landing, [0.5], "slack_rope")[0][0]
    sink = {}
    for EA in (1e4, 1e6):
        line = MoorDynSeabedLine(EA)
        dt = study.whole_steps(0.001, line.knobs(landing, quick=True)[1])
        X, _ = line.trajectory(landing, [0.5], dt)
        kb = line.seabed(landing)["kb"]
        sink[EA] = X_ref[8, 2] - X[0][8, 2]
        expected = M * G / (kb * DIAMETER * R / 2)
        assert abs(sink[EA] - expected) < 1e-3 * expected, (EA, sink[EA], expected)
        assert np.abs(X[0][:, :2] - X_ref[:, :2]).max() < 1e-12        # it falls straight down, as the rope does
    assert abs(sink[1e4] / sink[1e6] - 100.0) < 0.1


def test_moordyn_slides_to_rest_on_its_seabed_friction(slide):
    """MoorDyn's seabed friction (a damper saturated at mu |F_z|) stops each sliding node near v^2 / (2 mu g),
    closer as the seabed stiffens with EA (its damper's creep and the sink both shrink)."""
    pytest.importorskip("moordyn")
    from benchmarks.peers.moordyn_seabed import MoorDynSeabedLine
    X_ref = study.references(slide, [0.3], "slack_rope")[0][0]
    err = {}
    for EA in (1e4, 1e6):
        line = MoorDynSeabedLine(EA)
        dt = study.whole_steps(0.1, line.knobs(slide, quick=True)[1])
        X, _ = line.trajectory(slide, [0.3], dt)
        err[EA] = float(np.abs(X[0] - X_ref).max())
    assert err[1e6] < 1e-5 and err[1e6] < 0.1 * err[1e4], err


def test_the_seabed_peer_refuses_a_bouncing_ground(landing):
    from dataclasses import replace
    from benchmarks.peers.base import Unsupported
    from benchmarks.peers.moordyn_seabed import MoorDynSeabedLine
    bouncing = replace(landing, ground=dict(landing.ground, restitution=0.5))
    with pytest.raises(Unsupported, match="restitution 0.5"):
        MoorDynSeabedLine(1e6).check_scene(bouncing)


def test_the_seabed_study_smoke_run_writes_its_tables(tmp_path):
    pytest.importorskip("moordyn")
    study.main(["--scene", "rope_chain_seabed_slide", "--quick", "--out", str(tmp_path)])
    saved = json.loads((tmp_path / "rope_peer_chain_seabed_slide.json").read_text())
    assert saved["times"] == [0.05, 0.1] and saved["reference_agreement"] == [0.0, 0.0]
    assert all(r["mu"] == 0.5 and r["kb"] > 0 for r in saved["moordyn"])
    # no rope is taut: linknet's work is the friction's stops, which every method meets to round-off
    assert all(r["errors"][-1] < 1e-12 for r in saved["linknet"])


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_a_rope_jerks_a_resting_mass_into_a_slide_on_a_rough_ground(backend):
    """A rope snapping taut along a level rough ground gives no contact a normal impulse, so Coulomb's law allows
    no friction impulse at the jerk: the masses' in-plane momentum is kept and the resting mass slides off. Two
    0.125 kg masses, a at rest at (0, 0.1, 0), b at (0.15, 0, 0) thrown at 2 m/s along x, a 0.25 m rope of
    restitution 1, mu 0.5: the first jerk of a line dragged along a rough seabed (rope_chain_seabed_drag)."""
    import linknet_core as ln
    scene = ln.Scene.from_dict({
        "name": "jerk_on_rough_ground", "gravity": [0, 0, -G],
        "masses": [{"name": "a", "position": [0, 0.1, 0], "mass": M},
                   {"name": "b", "position": [0.15, 0, 0], "mass": M, "velocity": [2, 0, 0]}],
        "links": [{"a": 1, "b": 2, "length": R, "kind": "rope", "restitution": 1.0}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": 0.5}})
    run = ln.simulate(scene, t_end=0.1, method="dop853", rtol=1e-10, backend=backend, n_out=2, error_estimate=False)
    jerk = next(e for e in run.events if e.kind == "taut")
    momentum = []
    for dt in (-1e-9, 1e-9):   # friction's own impulse over 2 ns: 2 mu m g 1e-9 = 1.2e-9 N s per mass
        sim = ln.Simulator(scene, method="dop853", rtol=1e-10, backend=backend)
        sim.advance(jerk.t + dt)
        momentum.append(M * sim.state.U.sum(axis=0))
    assert jerk.impulse > 0.1
    assert np.abs(momentum[1] - momentum[0]).max() < 1e-8 * jerk.impulse + 1e-8


# ---------------------------------------------------------------------- the seabed: a rope dragged along it
@pytest.fixture(scope="module")
def drag():
    return study.load_scene(study.STUDIES["rope_chain_seabed_drag"])


def test_the_dragged_rope_s_first_jerk_throws_its_first_node_on_by_newton_and_coulomb(drag):
    """The anchor, driven away along -x at V = 1 m/s, jerks the first segment taut when its distance to node 1
    (0.15, 0.1, 0) reaches R: at t1 = (sqrt(R^2 - 0.1^2) - 0.15) / V. Restitution 1 against a driven anchor reverses
    the segment's rate V c (c = sqrt(R^2 - 0.1^2) / R the cosine along x): impulse 2 m V c, node 1 leaving at 2 V c
    along the segment towards the anchor. The jerk is along the ground, so no friction impulse; the node then slides
    decelerating at mu g (mu 0.5) along its velocity. Before t1 nothing but the anchor moves."""
    from benchmarks.rope_reference import rope_dragged_on_ground
    V, mu = 1.0, 0.5
    c = math.sqrt(R * R - 0.01) / R
    t1 = (R * c - 0.15) / V
    Xs, events = rope_dragged_on_ground(drag, [0.07, 0.1])
    assert np.allclose(Xs[0][1:], drag.X0[1:], rtol=0, atol=0) and Xs[0][0].tolist() == [-0.07, 0.0, 0.0]
    t, kind, link, impulse = events[0]
    assert (kind, link) == ("taut", 0) and abs(t - t1) < 1e-14 and abs(impulse - 2 * M * V * c) < 1e-14
    assert len(events) == 1                                        # nothing else happens by 0.1 s
    E = np.array([R * c, 0.1, 0.0]) / R                            # from the anchor to node 1 at the jerk
    u = -2 * V * c * E
    tau = 0.1 - t1
    expected = drag.X0[1] + u * tau - 0.5 * mu * G * (u / np.linalg.norm(u)) * tau * tau
    assert np.abs(Xs[1][1] - expected).max() < 1e-15 and np.allclose(Xs[1][2:], drag.X0[2:], rtol=0, atol=0)


def test_linknet_drags_the_rope_as_the_closed_form_on_both_engines(drag):
    """The closed form (every jerk Newton's restitution along the ground, every slide Coulomb's deceleration, event
    by event) against linknet: the same jerks, at the same times to 1e-12 s and with the same impulses to 1e-12 N s,
    and the positions to 1e-12 m; on the native core to 1 s (106 jerks), on the numpy path to 0.3 s (7 jerks)."""
    import linknet_core as ln
    from benchmarks.rope_reference import rope_dragged_on_ground
    scene = ln.Scene.from_dict(drag.to_dict())
    for backend, t_end in (("native", 1.0), ("numpy", 0.3)):
        Xs, events = rope_dragged_on_ground(drag, [t_end])
        jerks = [(t, link, impulse) for t, kind, link, impulse in events if kind == "taut"]
        run = ln.simulate(scene, t_end=t_end, method="dop853", rtol=1e-9, backend=backend, n_out=2,
                          error_estimate=False)
        found = [(e.t, e.index, e.impulse) for e in run.events if e.kind == "taut"]
        assert len(jerks) == len(found) > 5 and [j[1] for j in jerks] == [f[1] for f in found], backend
        assert max(abs(a[0] - b[0]) + abs(a[2] - b[2]) for a, b in zip(jerks, found)) < 1e-12, backend
        assert np.abs(run.X[-1] - Xs[0]).max() < 1e-12, backend


def test_moordyn_drives_its_coupled_point_as_the_anchor_and_its_jerk_error_falls_with_stiffness(drag):
    """The peer's driven anchor is a MoorDyn coupled point, which MoorDyn moves linearly within a Step call: at
    constant velocity exactly the scene's anchor. The first jerk (0.079 s) is a stiff line's: its error at 0.1 s
    falls as the line and the seabed stiffen together (EA 1e4 to 1e6 N, a quarter of the stability limit)."""
    pytest.importorskip("moordyn")
    from benchmarks.peers.moordyn_peer import _Session
    from benchmarks.peers.moordyn_seabed import MoorDynSeabedLine
    session = _Session(MoorDynSeabedLine(1e4), drag, 1e-3)
    try:
        session.md.Step(session.system, *session.coupled(0.0), 0.0, 0.05)
        assert np.abs(np.array(session.md.GetPointPos(session.points[0])) - [-0.05, 0, 0]).max() < 1e-15
    finally:
        session.close()
    X_ref = study.references(drag, [0.1], "dragged_rope")[0][0]
    err = {}
    for EA in (1e4, 1e6):
        line = MoorDynSeabedLine(EA)
        line.check_scene(drag)
        X, _ = line.trajectory(drag, [0.1], study.whole_steps(0.1, line.knobs(drag, quick=True)[2]))
        err[EA] = float(np.linalg.norm(X[0] - X_ref, axis=1).max())
    assert err[1e6] < 0.2 * err[1e4] < 2e-3, err


def test_the_moordyn_peer_refuses_a_driven_anchor_it_cannot_step_exactly(drag):
    from dataclasses import replace
    from benchmarks.peers.base import Unsupported
    from benchmarks.peers.moordyn_seabed import MoorDynSeabedLine
    shaken = replace(drag, motions=((0, {"kind": "sine", "amplitude": [0.1, 0, 0], "frequency": [1, 0, 0]}),))
    with pytest.raises(Unsupported, match="anchor 'anchor': motion 'sine'"):
        MoorDynSeabedLine(1e6).check_scene(shaken)
