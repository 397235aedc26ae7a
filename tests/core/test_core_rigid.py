"""Structure specialisation (linknet_core.simulator.specialisation): static scenes and free rigid bodies.

Physics checks: exact rigid rotation, analytic centripetal tensions, conservation laws, measured orders
against an independent point-mass reference, agreement with the point-mass path under springs, dampers,
drag, gravity and inputs, static balance against the point-mass tensions (25)-(26), snapshots, and the
fall-back of scenes the specialisations do not cover.
"""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import linknet_core as ln
from linknet_core.scene import builders
from linknet_core.simulator.analysis import analyze_scene
from linknet_core.integrators import Rattle
from linknet_core.native.integrator import NativeIntegrator
from linknet_core.native.rigid import NativeRigidIntegrator
from linknet_core.simulator.specialisation import choose_specialisation
from linknet_core.structure.topology import constraint_jacobian
from scene_builders import IRREGULAR, body

G = np.array([0.0, 0.0, -9.81])




def asymmetric_top(spin=(3.0, -5.0, 7.0), velocity=(0.3, 0.1, -0.2)):
    """4 unequal masses at the corners of an irregular tetrahedron: three distinct principal moments."""
    masses, links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], velocity=velocity, spin=spin)
    return ln.Scene.from_dict({"name": "asymmetric_top", "masses": masses, "links": links})


def exact_rotation(w, t):
    return Rotation.from_rotvec(np.asarray(w, float) * t).as_matrix()


# ---- free rigid bodies ----------------------------------------------------------------------------

def test_spherical_top_is_an_exact_uniform_rotation_after_one_big_step():
    w, v = np.array([2.0, -3.0, 6.5]), np.array([0.4, -0.2, 1.5])
    scene = builders.tetrahedron(edge=0.7, mass=0.3, spin=w, velocity=v, gravity=G)
    t = 1.7
    sim = ln.Simulator(scene, method="rattle", dt=t)
    assert sim.specialisation.kind == "rigid" and "1 spherical top" in sim.specialisation.text()
    sim.advance(t)
    assert sim.integrator.stats.steps == 1
    # centroid at the origin: free fall of the centre, uniform rotation about the fixed spin axis
    R = exact_rotation(w, t)
    rho = scene.X0 @ R.T
    X = v * t + 0.5 * G * t ** 2 + rho
    U = v + G * t + np.cross(w, rho)
    np.testing.assert_allclose(sim.state.X, X, rtol=0, atol=1e-14 * 16)
    np.testing.assert_allclose(sim.state.U, U, rtol=0, atol=1e-14 * 16 * np.abs(U).max())


def test_symmetric_top_one_big_step_matches_a_tight_point_mass_solution():
    # the tetrahedron with a heavier apex: a symmetric top about its 3-fold axis, spun off that axis
    d = builders.tetrahedron(spin=(3.0, 1.0, 8.0)).to_dict()
    d["masses"][3]["mass"] = 2.5
    scene = ln.Scene.from_dict(d)
    sim = ln.Simulator(scene, method="rattle", dt=1.0)
    assert "1 symmetric top" in sim.specialisation.text()
    sim.advance(1.0)
    ref = ln.Simulator(scene, method="dop853", rtol=1e-13, atol=1e-13, specialise=False)
    ref.advance(1.0)
    # one step of 1 s (8 rad of spin) is exact: the difference is the reference's error
    assert np.abs(sim.state.X - ref.state.X).max() < 1e-10


def test_spinning_tetrahedron_tensions_are_the_analytic_centripetal_ones():
    edge, mass, w = 0.8, 0.7, 6.0
    scene = builders.tetrahedron(edge=edge, mass=mass, spin=(0, 0, w))
    res = ln.simulate(scene, t_end=2.0, method="yoshida6", dt=0.25, n_out=9)
    assert res.stats["specialisation"].startswith("free rigid bodies: 1")
    # builders.tetrahedron: base links carry M w^2 a / 3, side links nothing
    base = mass * w ** 2 * edge / 3.0
    np.testing.assert_allclose(res.T[:, :3], base, rtol=1e-13)
    np.testing.assert_allclose(res.T[:, 3:], 0.0, atol=1e-13 * base)
    np.testing.assert_allclose(np.linalg.norm(res.X[:, scene.k2] - res.X[:, scene.k1], axis=2), edge, rtol=1e-14)


def test_asymmetric_top_keeps_angular_momentum_to_round_off_and_energy_bounded():
    scene = asymmetric_top()
    res = ln.simulate(scene, t_end=400.0, method="rattle", dt=0.01, n_out=41)  # 40000 steps
    m = scene.mass[None, :, None]
    P = np.sum(m * res.U, axis=1)
    c = np.sum(m * res.X, axis=1) / scene.mass.sum()
    Lang = np.sum(np.cross(res.X - c[:, None], m * (res.U - (P / scene.mass.sum())[:, None])), axis=1)
    scale_L = np.linalg.norm(Lang[0])
    assert np.abs(Lang - Lang[0]).max() < 1e-12 * scale_L
    assert np.abs(P - P[0]).max() < 1e-13 * np.linalg.norm(P[0])
    # the splitting does not conserve energy exactly, but its error stays bounded (O(h^2), no drift)
    err = np.abs(res.energy - res.energy[0]) / res.energy[0]
    assert err.max() < 1e-3
    assert err[21:].max() < 1.5 * err[:21].max()
    # link lengths to the round-off of coordinates of size |X| (the body drifts ~150 m away)
    assert res.residual.max() < 8 * np.finfo(float).eps * np.abs(res.X).max()


@pytest.fixture(scope="module")
def references():
    """Tight point-mass solutions (DOP853 on (9), (25)-(26), specialise=False: independent of the rigid paths)."""
    out = {}
    for name, scene, t_end, F in (("torque-free asymmetric top", asymmetric_top(), 1.0, None),
                                  ("two bodies, springs, dampers, drag, gravity, inputs", two_bodies_with_springs(),
                                   0.5, np.random.default_rng(4).normal(size=(8, 3)))):
        ref = ln.Simulator(scene, method="dop853", rtol=1e-13, atol=1e-13, specialise=False)
        assert ref.specialisation.kind == "none"
        ref.advance(t_end, F)
        out[name] = (scene, t_end, F, ref.state.X)
    return out


@pytest.mark.parametrize("case", ["torque-free asymmetric top", "two bodies, springs, dampers, drag, gravity, inputs"])
@pytest.mark.parametrize("method,counts", [("rattle", [20, 40, 80, 160]), ("yoshida4", [40, 80, 160]),
                                           ("yoshida6", [20, 40, 80])])
def test_measured_orders_against_a_point_mass_reference(references, case, method, counts):
    """Orders 2/4/6, also with velocity-dependent forces (the implicit second half kick keeps the base
    step symmetric, so the compositions keep their orders)."""
    scene, t_end, F, X_ref = references[case]
    errors = []
    for n in counts:
        sim = ln.Simulator(scene, method=method, dt=t_end / n)
        assert isinstance(sim.integrator, NativeRigidIntegrator)
        sim.advance(t_end, F)
        errors.append(np.abs(sim.state.X - X_ref).max())
    slopes = -np.diff(np.log(errors)) / np.diff(np.log(counts))
    order = ln.METHODS[method].order
    assert np.median(slopes) == pytest.approx(order, abs=0.35), f"{method}: errors {errors}, slopes {slopes}"


def two_bodies_with_springs():
    """An asymmetric and a spherical body joined by two spring-dampers, under gravity, one mass with drag."""
    a_masses, a_links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], name="a", velocity=(0.2, 0, 0.5), spin=(1, -2, 3))
    tet = builders.tetrahedron(edge=0.6).X0
    b_masses, b_links = body(tet, [0.8] * 4, name="b", offset=(2.0, 0.3, 0.4), spin=(0, 4, -1))
    b_masses[2]["drag"] = 0.3
    springs = [{"a": "a1", "b": "b0", "stiffness": 40.0, "rest_length": 0.8, "damping": 0.5},
               {"a": "a3", "b": "b3", "stiffness": 25.0, "damping": 0.2}]
    return ln.Scene.from_dict({"name": "two_bodies", "gravity": G.tolist(), "masses": a_masses + b_masses,
                               "links": a_links + b_links, "springs": springs})


def test_two_bodies_with_springs_gravity_drag_and_inputs_follow_the_point_mass_path():
    scene = two_bodies_with_springs()
    rng = np.random.default_rng(4)
    inputs = rng.normal(size=(4, scene.K, 3))
    forces = lambda t: inputs[min(int(t / 0.25), 3)]  # noqa: E731 - piecewise constant, as an FMI master
    rigid = ln.simulate(scene, 1.0, method="yoshida4", dt=1e-3, n_out=5, forces=forces)
    assert rigid.stats["specialisation"].startswith("free rigid bodies: 2")
    point = ln.simulate(scene, 1.0, method="dop853", rtol=1e-12, atol=1e-12, n_out=5, forces=forces, specialise=False)
    # stated bound: 1e-8 m, and 1e-7 relative on velocities and tensions (measured: 1.6e-10 m, 2.6e-9 N)
    assert np.abs(rigid.X - point.X).max() < 1e-8
    assert np.abs(rigid.U - point.U).max() < 1e-7 * np.abs(point.U).max()
    assert np.abs(rigid.T - point.T).max() < 1e-7 * np.abs(point.T).max()
    assert rigid.residual.max() < 1e-14


def test_base_step_and_compositions_are_time_reversible_for_conservative_forces():
    d = two_bodies_with_springs().to_dict()
    for spring in d["springs"]:
        spring["damping"] = 0.0
    for m in d["masses"]:
        m.pop("drag", None)
    scene = ln.Scene.from_dict(d)
    for method in ("rattle", "yoshida4"):
        sim = ln.Simulator(scene, method=method, dt=0.02)
        sim.advance(1.0)
        # run back with the velocities reversed (a state set from outside: the bodies are refitted to it)
        sim.state = ln.State(0.0, sim.state.X, -sim.state.U)
        sim.advance(1.0)
        assert np.abs(sim.state.X - scene.X0).max() < 1e-12, method
        assert np.abs(sim.state.U + scene.U0).max() < 1e-11 * np.abs(scene.U0).max(), method


def test_damping_too_stiff_for_the_step_is_refused_and_the_simulator_stays_usable():
    d = two_bodies_with_springs().to_dict()
    d["springs"][0]["damping"] = 1e4  # h c / m ~ 1e3: the implicit half kick cannot converge by iteration
    sim = ln.Simulator(ln.Scene.from_dict(d), method="rattle", dt=0.1)
    before = sim.state.copy()
    with pytest.raises(ln.SolverError, match=r"too stiff for this step .*; reduce dt"):
        sim.advance(0.1)
    assert sim.state.t == 0.0 and np.array_equal(sim.state.X, before.X)
    sim.advance(1e-5)  # a step the iteration can take
    assert sim.state.t == 1e-5


def test_snapshots_continue_bit_identically_and_reset_restarts():
    scene = two_bodies_with_springs()
    rng = np.random.default_rng(9)
    F1, F2 = rng.normal(size=(2, scene.K, 3))
    sim = ln.Simulator(scene, method="yoshida6", dt=0.01)
    sim.advance(0.3, F1)
    snap = pickle.dumps(sim.get_state())
    first = sim.outputs(F1)
    sim.advance(0.7, F2)
    out = sim.outputs(F2)
    sim.set_state(pickle.loads(snap))
    again = sim.outputs(F1)
    for key in ("X", "U", "T"):
        assert np.array_equal(first[key], again[key])
    sim.advance(0.7, F2)
    out2 = sim.outputs(F2)
    for key in ("X", "U", "T"):
        assert np.array_equal(out[key], out2[key]), key
    sim.reset()
    assert sim.state.t == 0.0 and np.array_equal(sim.state.X, scene.X0)
    sim.advance(0.3, F1)
    assert np.array_equal(sim.outputs(F1)["X"], first["X"])


def test_a_state_set_from_outside_is_followed():
    """A state that the rigid path did not produce (another simulator's) is refitted, not ignored."""
    scene = asymmetric_top()
    a = ln.Simulator(scene, method="yoshida4", dt=0.01)
    b = ln.Simulator(scene, method="yoshida4", dt=0.01)
    a.advance(0.5)
    b.state = a.state.copy()
    b.state.t = 0.0
    a.advance(1.0)
    b.advance(0.5)
    assert np.abs(a.state.X - b.state.X).max() < 1e-13


# ---- static scenes --------------------------------------------------------------------------------

def loaded_truss():
    d = builders.redundant_truss(bays=3).to_dict()
    d["masses"][4]["force"] = [0.5, -2.0, 1.0]
    d["masses"][6]["drag"] = 2.0
    d["springs"] = [{"a": 4, "b": 9, "stiffness": 30.0, "rest_length": 1.5, "damping": 1.0}]
    return ln.Scene.from_dict(d)


def test_static_truss_stays_put_with_point_mass_tensions_and_anchor_reactions():
    scene = loaded_truss()
    sim = ln.Simulator(scene, method="yoshida6", dt=1e-3)
    assert sim.specialisation.text().startswith("static (0 dof)") and sim.integrator.method.struct.kind == 2
    F_in = np.random.default_rng(2).normal(size=(scene.K, 3))
    sim.advance(2.0, F_in)
    assert sim.state.t == 2.0 and np.array_equal(sim.state.X, scene.X0) and not sim.state.U.any()
    out = sim.outputs(F_in)
    dyn = ln.Dynamics(scene)
    T_point = dyn.tensions(scene.X0, np.zeros_like(scene.X0), F_in)  # (25)-(26) at U = 0, minimum-norm
    np.testing.assert_allclose(out["T"], T_point, rtol=0, atol=1e-10 * np.abs(T_point).max())
    # static balance C^T T + F = 0 on the free masses, and the anchors carry the whole external load
    F = dyn.forces(scene.X0, np.zeros_like(scene.X0), F_in)
    C = constraint_jacobian(scene, scene.X0)
    np.testing.assert_allclose(C.T @ out["T"], -F[scene.free_indices].ravel(), atol=1e-11 * np.abs(F).max())
    np.testing.assert_allclose(out["Freact"].sum(axis=0), F.sum(axis=0), atol=1e-10 * np.abs(F).max())


def test_static_specialisation_holds_for_adaptive_methods_and_snapshots():
    scene = builders.redundant_truss()
    sim = ln.Simulator(scene, method="dop853", rtol=1e-8)
    assert sim.specialisation.kind == "static"
    sim.advance(0.5)
    snap = pickle.loads(pickle.dumps(sim.get_state()))
    sim.advance(1.0)
    sim.set_state(snap)
    assert sim.state.t == 0.5
    res = ln.simulate(scene, 1.0, method="rattle", dt=1e-3, n_out=3)
    total_weight = scene.mass[scene.free_indices].sum() * G
    np.testing.assert_allclose(res.X[-1], scene.X0, atol=0)
    sim.reset()
    np.testing.assert_allclose(sim.outputs()["Freact"].sum(axis=0), total_weight, atol=1e-10)


# ---- choice and fall-back -------------------------------------------------------------------------

def test_specialise_false_and_explicit_backends_keep_the_point_mass_path():
    scene = builders.tetrahedron()
    sim = ln.Simulator(scene, dt=1e-3, specialise=False)
    assert type(sim.integrator) is NativeIntegrator and "specialise=False" in sim.specialisation.reason
    sim.advance(0.01)
    assert sim.integrator.stats.steps == 10
    reference = ln.Simulator(scene, dt=1e-3, backend="numpy")
    assert reference.specialisation.kind == "none" and type(reference.integrator) is Rattle
    assert ln.Simulator(builders.redundant_truss(), dt=1e-3, specialise=False).specialisation.kind == "none"


def _scene(masses, links, **extra):
    return ln.Scene.from_dict({"name": "case", "masses": masses, "links": links, **extra})


FALLBACKS = {
    "collinear": (lambda: _scene([{"name": f"m{i}", "position": [i, 0, 0], "mass": 1.0} for i in range(3)],
                                 [{"a": 1, "b": 2}, {"a": 2, "b": 3}]), "collinear"),
    "two masses": (lambda: _scene([{"name": "a", "position": [0, 0, 0], "mass": 1.0},
                                   {"name": "b", "position": [1, 0, 0], "mass": 1.0}], [{"a": 1, "b": 2}]),
                   "has 2 masses"),
    "anchored": (lambda: ln.Scene.from_dict({**builders.tetrahedron().to_dict(), "masses": [
        {**m, "fixed": True, "mass": 1.0, "velocity": [0, 0, 0]} if i == 3 else m
        for i, m in enumerate(builders.tetrahedron(spin=(0, 0, 0)).to_dict()["masses"])]}), "anchored"),
    "mechanism": (lambda: _scene([{"name": f"m{i}", "position": p, "mass": 1.0}
                                  for i, p in enumerate([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])],
                                 [{"a": 1, "b": 2}, {"a": 2, "b": 3}, {"a": 3, "b": 4}, {"a": 4, "b": 1}]),
                  "internal mechanism"),
    "free particle": (lambda: ln.Scene.from_dict({**builders.tetrahedron().to_dict(), "masses": (
        builders.tetrahedron().to_dict()["masses"] + [{"name": "p", "position": [3, 0, 0], "mass": 1.0}])}),
        "free particle"),
}


@pytest.mark.parametrize("case", list(FALLBACKS))
def test_scenes_outside_the_specialisations_take_the_point_mass_path_with_the_reason(case):
    make, reason = FALLBACKS[case]
    scene = make()
    sim = ln.Simulator(scene, dt=1e-3)
    assert sim.specialisation.kind == "none" and reason in sim.specialisation.reason, sim.specialisation.reason
    assert type(sim.integrator) is NativeIntegrator
    assert reason in analyze_scene(scene).text()
    sim.advance(0.01)
    assert sim.state.t == 0.01


def test_anchored_spring_attachment_points_are_allowed_and_pull_the_body():
    """An anchor joined by no link only holds a spring: the body it pulls is still a free rigid body."""
    masses, links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], spin=(0, 2, 1))
    masses.append({"name": "hook", "position": [0.0, 0.0, 2.0], "fixed": True})
    scene = _scene(masses, links, gravity=G.tolist(),
                   springs=[{"a": "body3", "b": "hook", "stiffness": 50.0, "rest_length": 0.5}])
    rigid = ln.simulate(scene, 0.5, method="yoshida6", dt=2e-3, n_out=3)
    assert rigid.stats["specialisation"].startswith("free rigid bodies: 1")
    point = ln.simulate(scene, 0.5, method="dop853", rtol=1e-12, atol=1e-12, n_out=3, specialise=False)
    assert np.abs(rigid.X - point.X).max() < 1e-9
    assert np.abs(rigid.T - point.T).max() < 1e-8 * np.abs(point.T).max()


def test_analyze_reports_the_specialisation_of_the_shipped_scenes():
    scenes = builders.shipped_scenes()
    assert "specialisation: static (0 dof)" in analyze_scene(scenes["redundant_truss"]).text()
    text = analyze_scene(scenes["spinning_tetrahedron"]).text()
    assert "specialisation: free rigid bodies: 1 (1 spherical top" in text and "dop853" in text
    text = analyze_scene(scenes["double_pendulum"]).text()
    assert "specialisation: none: not static (4 degrees of freedom)" in text and "anchored" in text


# ---- adaptive methods on free rigid bodies ----------------------------------------------------------

def adaptive_rigid(scene, method, rtol, atol=None):
    """The rigid-body path of an adaptive method (as the Simulator builds it) and its initial state."""
    sim = ln.Simulator(scene, method=method, rtol=rtol, atol=atol)
    assert sim.specialisation.kind == "rigid", sim.specialisation.text()
    assert isinstance(sim.integrator, NativeRigidIntegrator)
    return sim.integrator, sim.state.copy()


def run_adaptive(scene, method, rtol, t_end, F=None, atol=None):
    path, state = adaptive_rigid(scene, method, rtol, atol)
    path.advance(state, t_end, F, 10 ** 6)
    return path, state


def point_mass(scene, method, rtol, t_end, F=None):
    sim = ln.Simulator(scene, method=method, rtol=rtol, atol=rtol, specialise=False)
    sim.advance(t_end, F)
    return sim


def centre_of_mass(scene, X):
    return (scene.mass[:, None] * X).sum(axis=0) / scene.mass.sum()


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_adaptive_spherical_top_in_free_fall_is_exact_to_the_tolerance(method):
    """Spinning tetrahedron thrown under gravity: uniform rotation about the fixed spin axis and a parabola of
    the centre. Bound: the error of the masses' positions stays below rtol times the largest coordinate
    (the norm's scale), as on the point-mass path (measured: 0.01-0.1 of it on the rigid path)."""
    w, v = np.array([1.0, 2.0, 10.0]), np.array([0.3, 0.0, 1.0])
    scene = builders.tetrahedron(spin=w, velocity=v, gravity=G)
    t = 2.0
    X_exact = v * t + 0.5 * G * t ** 2 + scene.X0 @ exact_rotation(w, t).T
    scale = np.abs(X_exact).max()
    for rtol in (1e-7, 1e-10):
        path, state = run_adaptive(scene, method, rtol, t)
        rigid_error = np.abs(state.X - X_exact).max()
        point_error = np.abs(point_mass(scene, method, rtol, t).state.X - X_exact).max()
        assert rigid_error < rtol * scale, (rtol, rigid_error)
        # comparable accuracy: the rigid path is not less accurate than the point-mass path at the same rtol
        assert rigid_error < 2 * point_error, (rtol, rigid_error, point_error)
        assert path.stats.steps > 3


def test_adaptive_symmetric_top_matches_the_exact_flow():
    """Heavier apex: a symmetric top spun off its axis (nutation). The fixed-step rigid path's single big
    step is its exact flow (Euler's equations solved in closed form); DOP853 on the body state meets it to
    the tolerance, and so does the point-mass path."""
    d = builders.tetrahedron(spin=(3.0, 1.0, 8.0)).to_dict()
    d["masses"][3]["mass"] = 2.5
    scene = ln.Scene.from_dict(d)
    exact = ln.Simulator(scene, method="rattle", dt=1.0)
    assert "1 symmetric top" in exact.specialisation.text()
    exact.advance(1.0)
    rtol = 1e-10
    _, state = run_adaptive(scene, "dop853", rtol, 1.0)
    scale = np.abs(exact.state.X).max()
    assert np.abs(state.X - exact.state.X).max() < rtol * scale
    assert np.abs(state.U - exact.state.U).max() < rtol * np.abs(exact.state.U).max()
    assert np.abs(point_mass(scene, "dop853", rtol, 1.0).state.X - state.X).max() < 10 * rtol * scale


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_adaptive_error_on_the_asymmetric_top_is_proportional_to_rtol(references, method):
    """Measured tolerance proportionality: over rtol 1e-6 .. 1e-12 the error against the tight point-mass
    reference falls like rtol (slope 1 on a log-log scale), and stays below rtol x scale."""
    scene, t_end, _, X_ref = references["torque-free asymmetric top"]
    rtols = np.array([1e-6, 1e-8, 1e-10, 1e-12])
    errors = np.array([np.abs(run_adaptive(scene, method, rtol, t_end)[1].X - X_ref).max() for rtol in rtols])
    slopes = np.diff(np.log(errors)) / np.diff(np.log(rtols))
    assert np.all(errors < rtols * np.abs(X_ref).max()), errors
    assert np.all((slopes > 0.75) & (slopes < 1.25)), (errors, slopes)


def test_adaptive_torque_free_asymmetric_top_conserves_energy_momentum_and_shape():
    """Not symplectic: energy and angular momentum errors follow the tolerance (bounded by 10 rtol over 40
    spin periods here, measured ~1e-12 relative at rtol 1e-10); momentum and the link lengths to round-off."""
    scene = asymmetric_top()
    rtol = 1e-10
    path, state = adaptive_rigid(scene, "dop853", rtol)
    dyn = ln.Dynamics(scene)
    m = scene.mass[:, None]

    def invariants(X, U):
        c = centre_of_mass(scene, X)
        P = np.sum(m * U, axis=0)
        return dyn.energy(X, U), P, np.sum(np.cross(X - c, m * (U - P / scene.mass.sum())), axis=0)

    E0, P0, L0 = invariants(state.X, state.U)
    for t in np.linspace(2.0, 30.0, 15):
        path.advance(state, t, None, 10 ** 6)
        E, P, L = invariants(state.X, state.U)
        assert abs(E - E0) < 10 * rtol * E0
        assert np.abs(L - L0).max() < 10 * rtol * np.linalg.norm(L0)
        assert np.abs(P - P0).max() < 1e-13 * np.linalg.norm(P0)
        assert dyn.constraint_residual(state.X) < 1e-14 * max(1.0, np.abs(state.X).max())


def test_adaptive_path_with_springs_dampers_drag_and_held_inputs_follows_the_point_mass_path():
    """Velocity-dependent forces and inputs held over each advance (zero-order hold), as the point-mass path;
    the tensions (C^T T = M a - F) agree too. Bound: 10 rtol x the coordinates' scale (rtol 1e-10)."""
    scene = two_bodies_with_springs()
    inputs = np.random.default_rng(4).normal(size=(4, scene.K, 3))
    rtol = 1e-10
    path, state = adaptive_rigid(scene, "dop853", rtol)
    sim = ln.Simulator(scene, method="dop853", rtol=rtol, atol=rtol, specialise=False)
    for i, t in enumerate((0.25, 0.5, 0.75, 1.0)):
        path.advance(state, t, inputs[i], 10 ** 6)
        sim.advance(t, inputs[i])
        scale = np.abs(sim.state.X).max()
        assert np.abs(state.X - sim.state.X).max() < 10 * rtol * scale
        assert np.abs(state.U - sim.state.U).max() < 10 * rtol * np.abs(sim.state.U).max()
        T_rigid = path.tensions(state.X, state.U, inputs[i])
        T_point = sim.outputs(inputs[i])["T"]
        assert np.abs(T_rigid - T_point).max() < 1e-7 * np.abs(T_point).max()
    assert path.stats.rejected >= 0 and path.stats.steps > 10


def test_adaptive_input_off_the_centre_of_mass_spins_the_body_and_the_centre_falls_exactly():
    """A constant input on one mass (off the centre of mass: a torque). The centre of mass moves exactly as a
    point of the total mass under the resultant (c = c0 + v0 t + (F/M + g) t^2 / 2); the rotation agrees with
    the point-mass path; the input's torque changes the angular momentum (it is not torque-free)."""
    masses, links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], velocity=(0.5, 0.0, 3.0), spin=(0.0, 1.0, 4.0))
    scene = _scene(masses, links, gravity=G.tolist())
    F = np.zeros((scene.K, 3))
    F[1] = [3.0, -2.0, 5.0]
    t, rtol = 1.5, 1e-10
    path, state = run_adaptive(scene, "dop853", rtol, t, F)
    M = scene.mass.sum()
    c0, v0 = centre_of_mass(scene, scene.X0), (scene.mass[:, None] * scene.U0).sum(axis=0) / M
    c_exact = c0 + v0 * t + 0.5 * (F.sum(axis=0) / M + G) * t ** 2
    assert np.abs(centre_of_mass(scene, state.X) - c_exact).max() < 1e-13 * max(1.0, np.abs(c_exact).max())
    sim = point_mass(scene, "dop853", rtol, t, F)
    assert np.abs(state.X - sim.state.X).max() < 10 * rtol * np.abs(sim.state.X).max()
    # the same resultant through the centre of mass (no torque) gives the same centre but another attitude
    through_centre = run_adaptive(scene, "dop853", rtol, t, scene.mass[:, None] * F.sum(axis=0) / M)[1]
    assert np.abs(centre_of_mass(scene, through_centre.X) - c_exact).max() < 1e-13 * max(1.0, np.abs(c_exact).max())
    assert np.abs(through_centre.X - state.X).max() > 1e-2


def test_adaptive_snapshots_continue_bit_identically():
    scene = two_bodies_with_springs()
    F1, F2 = np.random.default_rng(9).normal(size=(2, scene.K, 3))
    path, state = adaptive_rigid(scene, "dop853", 1e-9)
    path.advance(state, 0.3, F1, 10 ** 6)
    snap = pickle.dumps((state.copy(), path.internals()))
    path.advance(state, 0.7, F2, 10 ** 6)
    first = state.copy()
    saved_state, internals = pickle.loads(snap)
    path.set_internals(internals)
    path.advance(saved_state, 0.7, F2, 10 ** 6)
    assert np.array_equal(saved_state.X, first.X) and np.array_equal(saved_state.U, first.U)


def test_adaptive_method_without_tolerances_keeps_the_point_mass_path_and_step_limits_are_errors():
    scene = asymmetric_top()
    dyn = ln.Dynamics(scene)
    spec = choose_specialisation(scene, dyn, "dop853")
    assert spec.kind == "none" and "no tolerances were handed over" in spec.reason
    path, state = adaptive_rigid(scene, "dop853", 1e-12)
    with pytest.raises(ln.SolverError, match="more than 5 steps"):
        path.advance(state, 1.0, None, 5)
    assert "1 asymmetric top" in choose_specialisation(scene, dyn, "dopri5", tolerances=(1e-7, None)).text()
    assert "adaptive methods (dop853/dopri5)" in analyze_scene(scene).text()


def test_simulator_takes_the_rigid_path_for_adaptive_methods_and_reports_it():
    scene = two_bodies_with_springs()
    sim = ln.Simulator(scene, method="dop853", rtol=1e-9)
    assert isinstance(sim.integrator, NativeRigidIntegrator)
    assert "free rigid bodies: 2" in sim.summary() and "embedded Runge-Kutta pair" in sim.summary()
    assert "rtol 1e-09" in sim.summary()
    forces = lambda t: np.full((scene.K, 3), np.sin(3 * t))  # noqa: E731
    rigid = ln.simulate(scene, 0.5, method="dop853", rtol=1e-10, n_out=6, forces=forces)
    point = ln.simulate(scene, 0.5, method="dop853", rtol=1e-10, n_out=6, forces=forces, specialise=False)
    assert rigid.stats["specialisation"].startswith("free rigid bodies: 2")
    assert np.abs(rigid.X - point.X).max() < 1e-9 * np.abs(point.X).max()
    assert np.abs(rigid.T - point.T).max() < 1e-7 * np.abs(point.T).max()
