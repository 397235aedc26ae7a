"""The free-rigid-body path of the native core (src/engine_rigid.c, linknet_core/native/rigid.py).

Physics: exact free fall of the centre of mass, the exact flow of spherical and
  symmetric tops, conservation of momentum, angular momentum and energy of a free body, agreement with the
  point-mass path within the methods' accuracy, measured convergence orders, time reversibility, and the
  all-or-nothing advance.
"""
from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import linknet_core as ln
from linknet_core.scene import builders
from linknet_core.integrators import METHODS
from linknet_core.clib import library as lib
from linknet_core.native.rigid import NativeRigidIntegrator, RigidFunctions, body_states
from linknet_core.structure.bodies import free_rigid_bodies
from linknet_core.simulator.simulator import prepare_initial_state
from scene_builders import IRREGULAR, body

ROOT = Path(__file__).resolve().parents[2]
FN = RigidFunctions(lib.lib)
G = np.array([0.0, 0.0, -9.81])

# ---- scenes --------------------------------------------------------------------------------------

def scene_of(name, masses, links, **extra):
    return ln.Scene.from_dict({"name": name, "masses": masses, "links": links, **extra})


def spherical_top():
    """The regular tetrahedron, thrown and spun under gravity."""
    return builders.tetrahedron(edge=0.7, mass=0.3, spin=(2.0, -3.0, 6.5), velocity=(0.4, -0.2, 1.5), gravity=G)


def symmetric_top():
    """The tetrahedron with a heavier apex: a symmetric top about its 3-fold axis, spun off that axis."""
    d = builders.tetrahedron(spin=(3.0, 1.0, 8.0)).to_dict()
    d["masses"][3]["mass"] = 2.5
    return ln.Scene.from_dict(d)


def asymmetric_top(gravity=(0.0, 0.0, 0.0)):
    """4 unequal masses at the corners of an irregular tetrahedron: three distinct principal moments."""
    masses, links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], velocity=(0.3, 0.1, -0.2), spin=(3.0, -5.0, 7.0))
    return scene_of("asymmetric_top", masses, links, gravity=list(gravity))


def two_bodies(damping=True):
    """An asymmetric and a spherical body joined by two spring-dampers, under gravity, one mass with drag."""
    a_masses, a_links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], name="a", velocity=(0.2, 0, 0.5), spin=(1, -2, 3))
    tet = builders.tetrahedron(edge=0.6).X0
    b_masses, b_links = body(tet, [0.8] * 4, name="b", offset=(2.0, 0.3, 0.4), spin=(0, 4, -1))
    springs = [{"a": "a1", "b": "b0", "stiffness": 40.0, "rest_length": 0.8, "damping": 0.5 if damping else 0.0},
               {"a": "a3", "b": "b3", "stiffness": 25.0, "damping": 0.2 if damping else 0.0}]
    if damping:
        b_masses[2]["drag"] = 0.3
    return scene_of("two_bodies", a_masses + b_masses, a_links + b_links, gravity=G.tolist(), springs=springs)


def hooked_body():
    """A body hanging from an anchor by a spring: the anchor belongs to no body (body_of = -1)."""
    masses, links = body(IRREGULAR, [1.0, 2.0, 0.5, 1.5], spin=(0, 2, 1))
    masses.append({"name": "hook", "position": [0.0, 0.0, 2.0], "fixed": True})
    return scene_of("hooked", masses, links, gravity=G.tolist(),
                    springs=[{"a": "body3", "b": "hook", "stiffness": 50.0, "rest_length": 0.5, "damping": 0.3}])


SCENES = {
    "spinning_tetrahedron": lambda: ln.load_scene(ROOT / "models" / "spinning_tetrahedron.json"),
    "spherical top": spherical_top,
    "symmetric top": symmetric_top,
    "asymmetric top": asymmetric_top,
    "two bodies, springs, dampers, drag, inputs": two_bodies,
    "anchored spring hook": hooked_body,
}
SETTINGS = {"rattle": {"dt": 2e-3}, "yoshida4": {"dt": 1e-2}, "yoshida6": {"dt": 2e-2}, "suzuki4": {"dt": 1e-2},
            "dopri5": {"rtol": 1e-7}, "dop853": {"rtol": 1e-9}}


# ---- the native rigid-body path, built as the Simulator builds it ----------------------------------

class Bodies:
    """A scene's bodies on the native core, built as the Simulator builds them: the body layout
    (free_rigid_bodies), then NativeRigidIntegrator (ln_rigid_model from rigid_model, the ln_model pointing to
    it, the method, the data started from the initial body states); low-level access to its data."""

    def __init__(self, scene, method, dt=None, rtol=None, atol=None):
        self.scene = scene
        dyn = ln.Dynamics(scene)
        X0, U0, _ = prepare_initial_state(scene, dyn)
        self.layout, why = free_rigid_bodies(scene, dyn)
        assert self.layout is not None, why
        self.integrator = NativeRigidIntegrator(dyn, self.layout, METHODS[method], X0, U0, dt=dt, rtol=rtol,
                                                atol=atol)
        self.rigid, self.model = self.integrator.rigid, self.integrator.model
        self.method, self.data = self.integrator.method, self.integrator.data

    def set_bodies(self, Y, X=None, U=None):
        assert FN.set_state(self.model.pointer, self.data._ptr, Y) == lib.OK
        if X is not None:  # the mass state as given (set_state wrote the one of the bodies, equal to round-off)
            self.data.X[...] = X
            self.data.U[...] = U

    def refit(self, X, U, t=0.0):
        """A state set from outside: the bodies fitted to it."""
        self.set_bodies(body_states(self.scene, self.layout, self.rigid.geometry, X, U), X, U)
        self.data.struct.t = t

    @property
    def Y(self):
        return FN.get_state(self.model.pointer, self.data._ptr, self.layout.count)

    @property
    def t(self):
        return self.data.struct.t

    def advance(self, t, F=None, max_steps=10 ** 7) -> int:
        self.data.F_input[...] = 0.0 if F is None else F
        return lib.advance(self.model.pointer, self.method.pointer, self.data._ptr, float(t), int(max_steps))

    def run(self, t, F=None):
        status = self.advance(t, F)
        assert status == lib.OK, lib.STATUS[status]
        return self.data.X.copy(), self.data.U.copy()

    def fixed_steps(self, h, n, F=None):
        self.data.F_input[...] = 0.0 if F is None else F
        status = FN.rk_fixed_steps(self.model.pointer, self.method.pointer, self.data._ptr, h, n)
        assert status == lib.OK, lib.STATUS[status]
        return self.data.X.copy(), self.data.U.copy()


def point_mass(scene, method, t, F=None, **settings):
    """The point-mass path (specialise=False): (9), (25)-(26) with no knowledge of the bodies."""
    sim = ln.Simulator(scene, method=method, specialise=False, **settings)
    assert sim.specialisation.kind == "none"
    sim.advance(t, F)
    return sim.state


def centre_of_mass(scene, X):
    return (scene.mass[:, None] * X).sum(axis=0) / scene.mass.sum()


def invariants(scene, X, U):
    """Momentum, angular momentum about the centre of mass, kinetic energy."""
    m = scene.mass[:, None]
    P = (m * U).sum(axis=0)
    c = centre_of_mass(scene, X)
    L = np.cross(X - c, m * (U - P / scene.mass.sum())).sum(axis=0)
    return P, L, 0.5 * float((m * U * U).sum())


# ---- layout and state ----------------------------------------------------------------------------

def test_body_states_round_trip_and_bad_states_are_refused():
    b = Bodies(two_bodies(), "rattle", dt=1e-3)
    Y0 = b.Y
    assert Y0.shape == (2, 13)
    np.testing.assert_array_equal(Y0, b.rigid.Y0)
    np.testing.assert_allclose(np.linalg.norm(Y0[:, 6:10], axis=1), 1.0, rtol=1e-15)
    # set_state writes the masses of the bodies: the initial state the bodies were fitted to, to round-off
    b.set_bodies(Y0)
    np.testing.assert_allclose(b.data.X, b.rigid.X0, rtol=0, atol=1e-15 * np.abs(b.rigid.X0).max())
    np.testing.assert_allclose(b.data.U, b.rigid.U0, rtol=0, atol=1e-14 * np.abs(b.rigid.U0).max())
    X = b.data.X.copy()
    for bad in (np.nan, np.inf):
        Y = Y0.copy()
        Y[1, 11] = bad
        assert FN.set_state(b.model.pointer, b.data._ptr, Y) == lib.BAD_ARGUMENT
    Y = Y0.copy()
    Y[0, 6:10] = 0.0
    assert FN.set_state(b.model.pointer, b.data._ptr, Y) == lib.BAD_ARGUMENT
    np.testing.assert_array_equal(b.Y, Y0)
    np.testing.assert_array_equal(b.data.X, X)


# ---- physics -------------------------------------------------------------------------------------

def test_spherical_top_is_an_exact_uniform_rotation_and_free_fall_after_one_big_step():
    scene = spherical_top()
    w, v, t = np.array([2.0, -3.0, 6.5]), np.array([0.4, -0.2, 1.5]), 1.7
    b = Bodies(scene, "rattle", dt=t)
    X, U = b.run(t)
    assert b.data.struct.steps == 1
    R = Rotation.from_rotvec(w * t).as_matrix()
    rho = scene.X0 @ R.T  # builders.tetrahedron: centroid at the origin
    np.testing.assert_allclose(X, v * t + 0.5 * G * t ** 2 + rho, rtol=0, atol=16e-14)
    np.testing.assert_allclose(U, v + G * t + np.cross(w, rho), rtol=0, atol=16e-14 * np.abs(U).max())


def test_symmetric_top_one_big_step_is_its_exact_flow():
    """A symmetric top spun off its axis nutates; one RATTLE step of 1 s (8 rad of spin) is the exact flow:
    it meets a tight point-mass solution to that solution's own error."""
    scene = symmetric_top()
    b = Bodies(scene, "rattle", dt=1.0)
    assert b.rigid.geometry.kind.tolist() == [1]
    X, U = b.run(1.0)
    ref = point_mass(scene, "dop853", 1.0, rtol=1e-13, atol=1e-13)
    assert np.abs(X - ref.X).max() < 1e-10
    assert np.abs(U - ref.U).max() < 1e-9


@pytest.mark.parametrize("method", list(SETTINGS))
def test_centre_of_mass_falls_exactly_under_gravity_and_an_input_off_the_centre(method):
    """Constant resultant (gravity + a held input on one mass, which also exerts a torque): the centre of
    mass moves as a point of the total mass, c0 + v0 t + (F/M + g) t^2/2, to round-off for every method
    (each integrates a quadratic exactly), whatever the rotation does."""
    scene = asymmetric_top(gravity=G)
    b = Bodies(scene, method, **SETTINGS[method])
    assert b.rigid.geometry.kind.tolist() == [2]
    F = np.zeros((scene.K, 3))
    F[1] = [3.0, -2.0, 5.0]
    M = scene.mass.sum()
    c0, v0 = centre_of_mass(scene, scene.X0), (scene.mass[:, None] * scene.U0).sum(axis=0) / M
    for t in (0.4, 1.3):
        X, U = b.run(t, F)
        c_exact = c0 + v0 * t + 0.5 * (F.sum(axis=0) / M + G) * t ** 2
        v_exact = v0 + (F.sum(axis=0) / M + G) * t
        assert np.abs(centre_of_mass(scene, X) - c_exact).max() < 1e-13 * max(1.0, np.abs(c_exact).max())
        assert np.abs(centre_of_mass(scene, U) - v_exact).max() < 1e-13 * max(1.0, np.abs(v_exact).max())


@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_free_asymmetric_top_keeps_momenta_to_round_off_and_energy_bounded(method):
    """Torque-free: every sub-flow of the splitting rotates R and Pi together, so the space angular momentum
    is kept to round-off over 20000 steps; the energy error of the splitting is bounded (no drift)."""
    scene = asymmetric_top()
    b = Bodies(scene, method, dt=0.01)
    P0, L0, E0 = invariants(scene, scene.X0, scene.U0)
    energy = []
    for t in np.linspace(10.0, 200.0, 20):
        X, U = b.run(t)
        P, L, E = invariants(scene, X, U)
        assert np.abs(L - L0).max() < 1e-12 * np.linalg.norm(L0)
        assert np.abs(P - P0).max() < 1e-13 * np.linalg.norm(P0)
        energy.append(abs(E - E0) / E0)
        d = X[scene.k2] - X[scene.k1]  # shape kept to the round-off of coordinates of size |X|
        assert np.abs(np.linalg.norm(d, axis=1) - scene.length).max() < 8e-16 * np.abs(X).max()
    # measured: 1.7e-4 (rattle), 1.1e-6 (yoshida4), the same in both halves of the run
    bound = 1e-3 if method == "rattle" else 1e-5
    assert max(energy) < bound and max(energy[10:]) < 1.5 * max(energy[:10])


def test_free_asymmetric_top_on_dop853_conserves_energy_and_angular_momentum_to_the_tolerance():
    scene, rtol = asymmetric_top(), 1e-10
    b = Bodies(scene, "dop853", rtol=rtol)
    P0, L0, E0 = invariants(scene, scene.X0, scene.U0)
    for t in np.linspace(2.0, 30.0, 8):
        X, U = b.run(t)
        P, L, E = invariants(scene, X, U)
        assert abs(E - E0) < 10 * rtol * E0
        assert np.abs(L - L0).max() < 10 * rtol * np.linalg.norm(L0)
        assert np.abs(P - P0).max() < 1e-13 * np.linalg.norm(P0)
    np.testing.assert_allclose(np.linalg.norm(b.Y[:, 6:10], axis=1), 1.0, rtol=1e-15)


def test_follows_the_point_mass_path_with_springs_dampers_drag_and_inputs():
    """Two bodies pulled together by spring-dampers, one with drag, inputs changing every 0.25 s: the
    fixed-step and adaptive rigid-body paths meet the point-mass path within their accuracy."""
    scene = two_bodies()
    inputs = np.random.default_rng(4).normal(size=(4, scene.K, 3))
    reference = ln.Simulator(scene, method="dop853", rtol=1e-12, atol=1e-12, specialise=False)
    fixed = Bodies(scene, "yoshida4", dt=1e-3)
    adaptive = Bodies(scene, "dop853", rtol=1e-10)
    for i, t in enumerate((0.25, 0.5, 0.75, 1.0)):
        reference.advance(t, inputs[i])
        X_ref, U_ref = reference.state.X, reference.state.U
        for b, tol in ((fixed, 1e-8), (adaptive, 10 * 1e-10 * np.abs(X_ref).max())):
            X, U = b.run(t, inputs[i])
            assert np.abs(X - X_ref).max() < tol, (b.method, t)
            assert np.abs(U - U_ref).max() < 10 * tol * np.abs(U_ref).max()


def test_anchored_hook_stays_put_and_the_body_follows_the_point_mass_path():
    scene = hooked_body()
    b = Bodies(scene, "yoshida6", dt=2e-3)
    assert b.layout.body_of[-1] == -1
    X, _ = b.run(0.5)
    assert np.array_equal(X[-1], scene.X0[-1])
    ref = point_mass(scene, "dop853", 0.5, rtol=1e-12, atol=1e-12)
    assert np.abs(X - ref.X).max() < 1e-9


@pytest.fixture(scope="module")
def references():
    """Tight point-mass solutions, independent of the rigid-body path."""
    out = {}
    F = np.random.default_rng(4).normal(size=(8, 3))
    for name, scene, t_end, force in (("torque-free asymmetric top", asymmetric_top(), 1.0, None),
                                      ("two bodies, springs, dampers, drag, inputs", two_bodies(), 0.5, F)):
        out[name] = (scene, t_end, force, point_mass(scene, "dop853", t_end, force, rtol=1e-13, atol=1e-13).X)
    return out


CASES = ["torque-free asymmetric top", "two bodies, springs, dampers, drag, inputs"]


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("method,counts", [("rattle", [20, 40, 80, 160]), ("yoshida4", [40, 80, 160]),
                                           ("yoshida6", [20, 40, 80])])
def test_measured_orders_of_the_compositions(references, case, method, counts):
    """Orders 2, 4, 6, also with velocity-dependent forces (the implicit second half kick keeps the base step
    symmetric, so the compositions keep their orders)."""
    scene, t_end, F, X_ref = references[case]
    errors = [np.abs(Bodies(scene, method, dt=t_end / n).run(t_end, F)[0] - X_ref).max() for n in counts]
    slopes = -np.diff(np.log(errors)) / np.diff(np.log(counts))
    assert np.median(slopes) == pytest.approx(METHODS[method].order, abs=0.35), (errors, slopes)


@pytest.mark.parametrize("case", CASES)
@pytest.mark.parametrize("method,counts", [("dopri5", [32, 64, 128, 256]), ("dop853", [6, 8, 11, 15, 20])])
def test_measured_orders_of_the_tableaux_on_the_body_state(references, case, method, counts):
    """n steps of the tableau without error control converge at the method's order (5, 8): the tableau and the
    Newton-Euler right-hand side are what they claim."""
    scene, t_end, F, X_ref = references[case]
    errors = [np.abs(Bodies(scene, method, rtol=1e-6).fixed_steps(t_end / n, n, F)[0] - X_ref).max()
              for n in counts]
    slopes = -np.diff(np.log(errors)) / np.diff(np.log(counts))
    assert np.median(slopes) == pytest.approx(METHODS[method].order, abs=0.5), (errors, slopes)


@pytest.mark.parametrize("method", ["dopri5", "dop853"])
def test_adaptive_error_is_proportional_to_rtol(references, method):
    scene, t_end, _, X_ref = references["torque-free asymmetric top"]
    rtols = np.array([1e-6, 1e-8, 1e-10, 1e-12])
    errors = np.array([np.abs(Bodies(scene, method, rtol=r).run(t_end)[0] - X_ref).max() for r in rtols])
    slopes = np.diff(np.log(errors)) / np.diff(np.log(rtols))
    assert np.all(errors < rtols * np.abs(X_ref).max()), errors
    assert np.all((slopes > 0.75) & (slopes < 1.25)), (errors, slopes)


@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_compositions_are_time_reversible_for_conservative_forces(method):
    scene = two_bodies(damping=False)
    b = Bodies(scene, method, dt=0.02)
    X, U = b.run(1.0)
    b.refit(X, -U)  # run back from the end with the velocities reversed
    X, U = b.run(1.0)
    assert np.abs(X - scene.X0).max() < 1e-12
    assert np.abs(U + scene.U0).max() < 1e-11 * np.abs(scene.U0).max()


@pytest.mark.parametrize("method", ["yoshida4", "dop853"])
def test_intervals_and_snapshots_continue_bit_identically(method):
    """The body state carries over between advances: pieces of an interval give the trajectory of one
    advance over the whole (fixed steps on the same grid, to the round-off of the step sizes span / n), and
    a restored snapshot continues bit for bit."""
    scene = two_bodies()
    settings = SETTINGS[method]
    F = np.random.default_rng(9).normal(size=(scene.K, 3))
    a, b = Bodies(scene, method, **settings), Bodies(scene, method, **settings)
    a.run(0.3, F)
    snapshot = (a.Y, a.data.X.copy(), a.data.U.copy(), a.t, a.data.struct.h_next)
    X1, U1 = a.run(0.7, F)
    if method == "yoshida4":
        X_whole, _ = b.run(0.7, F)
        assert np.abs(X_whole - X1).max() < 1e-14 * np.abs(X1).max()
    Y, X, U, t, h_next = snapshot
    b.set_bodies(Y, X, U)
    b.data.struct.t, b.data.struct.h_next = t, h_next
    X2, U2 = b.run(0.7, F)
    assert np.array_equal(X1, X2) and np.array_equal(U1, U2)


def test_a_failed_advance_changes_nothing():
    """Damping too stiff for the implicit half kick, and too many adaptive steps: the status says why, and the
    bodies, the masses, t and the step size are those before the call."""
    d = two_bodies().to_dict()
    d["springs"][0]["damping"] = 1e4  # h c / m ~ 1e3: the fixed-point iteration cannot converge
    b = Bodies(ln.Scene.from_dict(d), "rattle", dt=0.1)
    before = (b.Y, b.data.X.copy(), b.data.U.copy(), b.t)
    assert b.advance(0.1) == lib.IMPLICIT_KICK_FAILED
    after = (b.Y, b.data.X.copy(), b.data.U.copy(), b.t)
    assert all(np.array_equal(x, y) for x, y in zip(before, after))

    b = Bodies(asymmetric_top(), "dop853", rtol=1e-12)
    b.run(0.1)
    before = (b.Y, b.data.X.copy(), b.data.U.copy(), b.t, b.data.struct.h_next, b.data.struct.steps)
    assert b.advance(1.0, max_steps=5) == lib.TOO_MANY_STEPS
    after = (b.Y, b.data.X.copy(), b.data.U.copy(), b.t, b.data.struct.h_next, b.data.struct.steps)
    assert all(np.array_equal(x, y) for x, y in zip(before, after))
    X, _ = b.run(1.0)  # and it goes on from there
    assert np.isfinite(X).all()


# ---- the integrator as the Simulator uses it -------------------------------------------------------

def integrator_and_state(scene, method, **settings):
    b = Bodies(scene, method, **settings)
    return b.integrator, ln.State(0.0, *b.integrator.initial_state)


@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_integrator_follows_a_state_set_from_outside(method):
    """Time reversal through the integrator's interface: the velocities reversed from outside are followed
    (the bodies are refitted), and the run back ends where the run started."""
    scene = two_bodies(damping=False)
    integrator, state = integrator_and_state(scene, method, dt=0.02)
    integrator.advance(state, 1.0, None, 10 ** 6)
    state = ln.State(0.0, state.X, -state.U)
    integrator.advance(state, 1.0, None, 10 ** 6)
    assert np.abs(state.X - scene.X0).max() < 1e-12
    assert np.abs(state.U + scene.U0).max() < 1e-11 * np.abs(scene.U0).max()


@pytest.mark.parametrize("method", ["yoshida4", "dop853"])
def test_integrator_snapshots_continue_bit_identically(method):
    scene = two_bodies()
    F1, F2 = np.random.default_rng(9).normal(size=(2, scene.K, 3))
    integrator, state = integrator_and_state(scene, method, **SETTINGS[method])
    integrator.advance(state, 0.3, F1, 10 ** 6)
    snapshot = pickle.dumps((state.copy(), integrator.internals()))
    integrator.advance(state, 0.7, F2, 10 ** 6)
    first = state.copy()
    integrator.advance(state, 0.9, F1, 10 ** 6)  # move on, then go back to the snapshot
    saved_state, internals = pickle.loads(snapshot)
    integrator.set_internals(internals)
    integrator.advance(saved_state, 0.7, F2, 10 ** 6)
    assert np.array_equal(saved_state.X, first.X) and np.array_equal(saved_state.U, first.U)


def test_integrator_refuses_a_failed_interval_with_the_reason_and_keeps_its_state():
    d = two_bodies().to_dict()
    d["springs"][0]["damping"] = 1e4
    integrator, state = integrator_and_state(ln.Scene.from_dict(d), "rattle", dt=0.1)
    before = state.copy()
    with pytest.raises(ln.SolverError, match="too stiff for this step"):
        integrator.advance(state, 0.1, None, 10 ** 6)
    assert state.t == 0.0 and np.array_equal(state.X, before.X) and np.array_equal(state.U, before.U)
    with pytest.raises(ln.SolverError, match="more than 5 steps"):
        integrator.advance(state, 1.0, None, 5)


def test_integrator_tensions_are_the_analytic_centripetal_ones():
    """builders.tetrahedron spun about its axis: the base links carry M w^2 a / 3, the side links nothing."""
    edge, mass, w = 0.8, 0.7, 6.0
    scene = builders.tetrahedron(edge=edge, mass=mass, spin=(0, 0, w))
    integrator, state = integrator_and_state(scene, "yoshida6", dt=0.25)
    integrator.advance(state, 2.0, None, 10 ** 6)
    T = integrator.tensions(state.X, state.U)
    base = mass * w ** 2 * edge / 3.0
    np.testing.assert_allclose(T[:3], base, rtol=1e-13)
    np.testing.assert_allclose(T[3:], 0.0, atol=1e-13 * base)
