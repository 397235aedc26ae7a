"""Interface Jacobians (linknet_core.dynamics.interface_jacobian, src/interface_jacobian.c): the derivatives of the
outputs T, Freact and dU/dt with respect to the inputs F, P, V, A at a fixed state.

References, each independent of the code under test: closed forms (a pendulum on a driven pivot; a straight chain
at rest, whose effective mass is its whole mass along it and nothing across it), the variational bound of Gauss's
principle (0 <= m_eff <= the network's mass for a network hanging from one anchor), and central differences of the
Simulator's own outputs, on a chain, a net, a crane whose trolley is an input, a redundant truss and a spring
hooked to a driven anchor, on both backends. The casadi AD comparison is `linknet check`'s
(tests/symbolic/test_interface_jacobian_check.py)."""
from __future__ import annotations

import math

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics.forces import element_forces
from linknet_core.dynamics.interface_jacobian import element_force_derivative
from linknet_core.scene import builders
from driven_anchor_scenes import G, drive, pendulum

BACKENDS = ["native", "numpy"]


def _simulator(scene, backend, **kw):
    return ln.Simulator(scene, method="rattle", dt=1e-3, backend=backend, error_estimate=False, **kw)


def _hold(P, V, A):
    return tuple(np.asarray(x, float).reshape(-1, 3) for x in (P, V, A))


# ---- closed forms ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
def test_pendulum_on_a_driven_pivot_answers_as_its_closed_form(backend):
    """A bob M on a rod R from a pivot driven with (P, V, A): the rod's tension is
    T = M |u - V|^2 / R + e . F - M e . A (e the unit vector from pivot to bob, F the force on the bob), and the
    pivot feels Freact = T e. So dT/dF = e, dT/dA = -M e, dT/dV = -2 M (u - V) / R, and the effective mass at the
    pivot is -dFreact/dA = M e e^T, whatever the velocities and forces."""
    mass, length, theta = 1.7, 0.8, 0.6
    scene = pendulum(theta, length, mass)
    sim = _simulator(scene, backend)
    P, V, A = [0.0, 0.0, 0.0], [0.3, -0.2, 0.1], [1.0, 0.5, -2.0]
    e = np.array([math.sin(theta), 0.0, -math.cos(theta)])
    u = 0.9 * np.cross(e, [0.0, 1.0, 0.0]) + np.asarray(V)  # the bob swinging, relative to the pivot, across the rod
    snapshot = sim.get_state()
    snapshot["state"].U = np.array([V, u])
    sim.set_state(snapshot)
    F = np.array([[0.0, 0.0, 0.0], [0.4, -1.1, 0.7]])
    J = sim.interface_jacobian(F, _hold(P, V, A))
    np.testing.assert_allclose(J["T", "F"][0, 1], e, atol=1e-14)
    np.testing.assert_allclose(J["T", "A"][0, 0], -mass * e, atol=1e-14)
    np.testing.assert_allclose(J["T", "V"][0, 0], -2 * mass * (u - V) / length, atol=1e-13)
    np.testing.assert_allclose(J.effective_mass(0), mass * np.outer(e, e), atol=1e-14)
    # the bob's acceleration answers the pivot's along the rod only: d(dU_bob/dt)/dA = e e^T
    np.testing.assert_allclose(J["acc", "A"][1, :, 0, :], np.outer(e, e), atol=1e-14)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("theta", [0.0, 0.7])
def test_a_straight_chain_at_rest_weighs_its_whole_mass_along_itself_and_nothing_across(backend, theta):
    """A straight chain of unequal masses at rest, hanging at theta from the vertical from a driven anchor: every
    link lies along e, so the tensions hold only the component along e, every mass follows the anchor's
    acceleration along e, and the whole chain's mass opposes it: m_eff = M_total e e^T (along the rail
    x: M_total sin^2 theta, the limit of examples/compositions/cart_chain.py). Hanging straight down (theta = 0) the
    horizontal effective mass is zero: the links are perpendicular to the motion."""
    masses = [0.3, 1.1, 0.5, 2.0]
    e = np.array([math.sin(theta), 0.0, -math.cos(theta)])
    points = [list(0.25 * i * e) for i in range(len(masses) + 1)]
    scene = drive(builders.chain(len(masses), shape="points", points=points, masses=[1.0] + masses), 0, None)
    sim = _simulator(scene, backend)
    m_eff = sim.interface_jacobian(None, _hold([0, 0, 0], [0, 0, 0], [0, 0, 0])).effective_mass(0)
    np.testing.assert_allclose(m_eff, sum(masses) * np.outer(e, e), atol=1e-13)
    assert m_eff[0, 0] == pytest.approx(sum(masses) * math.sin(theta) ** 2, abs=1e-13)


@pytest.mark.parametrize("backend", BACKENDS)
def test_effective_mass_is_symmetric_and_bounded_by_the_hanging_mass(backend):
    """Gauss's principle: m_eff = C_a^T A^+ C_a, and A^T m_eff A / 2 is the least 'acceleration energy'
    sum M_k |a_k|^2 / 2 of the masses over the accelerations the links allow when the anchor accelerates by A. A
    network hanging from one anchor may follow it rigidly (a_k = A), so 0 <= m_eff <= M_total in every direction;
    m_eff depends on the positions only (A (25) does), not on the velocities or the forces. A chain touches its
    anchor with one link, which alone pulls on it: m_eff = mu e_1 e_1^T, rank one along the first link. A bent,
    moving chain."""
    rng = np.random.default_rng(3)
    masses = [0.4, 0.9, 0.2, 1.3, 0.6]
    points = [[0, 0, 0], [0.3, 0.1, -0.2], [0.5, 0.3, -0.5], [0.4, 0.6, -0.8], [0.1, 0.7, -1.0], [-0.2, 0.9, -1.1]]
    scene = drive(builders.chain(5, shape="points", points=points, masses=[1.0] + masses), 0, None)
    sim = _simulator(scene, backend)
    hold = _hold([0, 0, 0], [0.2, -0.1, 0.3], [1.0, 0.0, -0.5])
    sim.advance(0.05, rng.standard_normal((scene.K, 3)), hold)
    m_eff = [sim.interface_jacobian(rng.standard_normal((scene.K, 3)), _hold(sim.state.X[0], v, a)).effective_mass(0)
             for v, a in ((rng.standard_normal(3), rng.standard_normal(3)) for _ in range(2))]
    np.testing.assert_allclose(m_eff[0], m_eff[1], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(m_eff[0], m_eff[0].T, atol=1e-13)
    eigenvalues = np.linalg.eigvalsh(m_eff[0])
    assert eigenvalues.min() > -1e-12 and 0.0 < eigenvalues.max() < sum(masses)
    e1 = (sim.state.X[1] - sim.state.X[0]) / scene.length[0]
    np.testing.assert_allclose(m_eff[0], eigenvalues.max() * np.outer(e1, e1), atol=1e-12)


# ---- central differences of the Simulator's own outputs ------------------------------------------------------------
def _spring_on_driven_anchor():
    """A two-link chain from an input-driven hook, with a spring-damper from the hook to the tip and drag on the tip:
    the forces on a free mass then move with the hook's P and V."""
    return ln.Scene.from_dict({
        "name": "hooked_spring", "gravity": [0, 0, -G],
        "masses": [{"name": "hook", "position": [0, 0, 0], "driven": True},
                   {"name": "m1", "mass": 0.7, "position": [0.4, 0.1, -0.3]},
                   {"name": "tip", "mass": 1.2, "position": [0.6, -0.2, -0.7], "drag": 0.3}],
        "links": [{"a": "hook", "b": "m1"}, {"a": "m1", "b": "tip"}],
        "springs": [{"a": "hook", "b": "tip", "stiffness": 30.0, "damping": 0.8, "rest_length": 0.5}]})


CASES = {  # scene, inputs whose columns are differenced, how far to run first
    "chain_10": (lambda: ln.load_scene("models/chain_10.json"), 0.05),
    "net_10x10": (lambda: ln.load_scene("models/net_10x10.json"), 0.02),
    "crane_input": (lambda: ln.load_scene("models/crane.json").with_motions({1: {"kind": "input"}}), 0.05),
    "redundant_truss_driven": (lambda: drive(ln.load_scene("models/redundant_truss.json"), 0, None), 0.0),
    "braced_tower": (lambda: ln.load_scene("models/braced_tower.json"), 0.05),
    "hooked_spring": (_spring_on_driven_anchor, 0.05),
}


def _units(scene):
    """Natural units of the inputs: a typical weight, a link length, sqrt(g l), g."""
    m = float(np.median(scene.mass[~scene.fixed]))
    ell = float(np.median(scene.length))
    return {"F": m * G, "P": ell, "V": math.sqrt(G * ell), "A": G}


def _state(name, backend):
    make, run = CASES[name]
    scene = make()
    rng = np.random.default_rng(7)
    sim = _simulator(scene, backend)
    n = scene.input_driven_indices.size
    moving = name != "redundant_truss_driven"  # a rigid truss cannot follow a moving anchor
    F = 0.5 * _units(scene)["F"] * rng.standard_normal((scene.K, 3))
    hold = None
    if n:
        P = np.asarray(scene.X0, float)[scene.input_driven_indices]
        hold = _hold(P, 0.3 * moving * rng.standard_normal((n, 3)), moving * rng.standard_normal((n, 3)))
    if run:
        sim.advance(run, F, hold)
    if n:  # the anchors where their hold has them now, with a new velocity and acceleration
        out = sim.outputs(F)
        rows = scene.input_driven_indices
        hold = _hold(sim.state.X[rows], 0.3 * moving * rng.standard_normal((n, 3)),
                     moving * rng.standard_normal((n, 3)))
        assert out["T"].shape == (scene.L,)
    return sim, F, hold, rng


def _central_difference(sim, F, hold, name, seed, h):
    """Central differences of T, Freact and the accelerations along ``seed``, Richardson-extrapolated: (4 D(h) -
    D(2h)) / 3, D(h) = (outputs(inputs + h seed) - outputs(inputs - h seed)) / 2h, whose truncation error is O(h^4)
    (the tensions' curvature in P is large: a trolley's position moves every link direction of a crane)."""
    fine, coarse = _difference(sim, F, hold, name, seed, h), _difference(sim, F, hold, name, seed, 2 * h)
    return [(4 * a - b) / 3 for a, b in zip(fine, coarse)]


def _difference(sim, F, hold, name, seed, h):
    """(outputs(inputs + h seed) - outputs(inputs - h seed)) / 2h of T, Freact, and the accelerations (the numpy
    reference's at the state the outputs see: the Simulator reports no accelerations)."""
    values = []
    for sign in (1.0, -1.0):
        Fs, hs = F.copy(), [a.copy() for a in hold] if hold is not None else None
        if name == "F":
            Fs = F + sign * h * seed
        else:
            hs["PVA".index(name)] += sign * h * seed
        out = sim.outputs(Fs, tuple(hs) if hs is not None else None)
        values.append((out["T"], out["Freact"], lin_accelerations(sim, Fs, hs)))
    return [(a - b) / (2 * h) for a, b in zip(*values)]


def lin_accelerations(sim, F, hold):
    """dU/dt of (9) at the state the outputs see: the reference's right-hand side with the driven rows set."""
    X, U = sim.state.X.copy(), sim.state.U.copy()
    anchor_acc = None
    if hold is not None:
        rows = sim.scene.input_driven_indices
        X[rows], U[rows] = hold[0], hold[1]
        anchor_acc = np.zeros_like(X)
        anchor_acc[rows] = hold[2]
    return sim.dyn.accelerations(X, U, F, anchor_acc=anchor_acc)[0]


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", list(CASES))
def test_directional_derivatives_equal_central_differences_of_the_outputs(name, backend):
    """Along random seeds on each input (F; P, V, A of the input-driven anchors), the linearization's directional
    derivative of T and Freact equals central differences of the Simulator's own outputs(), and that of the
    accelerations central differences of the right-hand side (9): to 1e-7 of the derivative's size, the
    differences' truncation (h = 1e-3 in natural units, extrapolated) and round-off."""
    sim, F, hold, rng = _state(name, backend)
    if sim.scene.motions and sim.scene.input_driven_indices.size == 0:
        pytest.skip("no input-driven anchor")
    lin = sim.interface_linearization(F, hold)
    units = _units(sim.scene)
    inputs = ["F"] + (["P", "V", "A"] if hold is not None else [])
    for kind in inputs:
        rows = sim.scene.K if kind == "F" else hold[0].shape[0]
        seed = units[kind] * rng.standard_normal((rows, 3))
        exact = lin.directional(**{f"d{kind}": seed})
        differences = _central_difference(sim, F, hold, kind, seed, 1e-4)
        for output, difference in zip(("T", "Freact", "acc"), differences):
            scale = max(float(np.abs(exact[output]).max(initial=0.0)), 1e-3 * units["F"] if output != "acc" else 1e-3 * G)
            error = float(np.abs(exact[output] - difference).max(initial=0.0))
            assert error <= 1e-7 * scale, f"{name} {backend}: d{output}/d{kind} {error:.2e} of {scale:.2e}"


@pytest.mark.parametrize("name", list(CASES))
def test_numpy_and_native_jacobians_agree_to_round_off(name):
    """The numpy reference and the C core at the same state, every block: to 1e-12 times cond(A) (the solves'
    round-off), in natural units (a typical weight for forces and tensions, g for accelerations, a link length for
    positions, sqrt(g l) for velocities), relative to the block's size or 1."""
    sim, F, hold, _ = _state(name, "numpy")
    native, *_ = _state(name, "native")  # the same run on the native core, then the very same X, U put in
    snapshot = native.get_state()
    assert snapshot["state"].t == sim.state.t
    snapshot["state"].X, snapshot["state"].U = sim.state.X.copy(), sim.state.U.copy()
    native.set_state(snapshot)
    J_numpy, J_native = sim.interface_jacobian(F, hold), native.interface_jacobian(F, hold)
    A = sim.dyn.tension_matrix(sim.state.X).toarray()
    w = np.linalg.eigvalsh(A)
    kept = w[w > 1e-10 * w.max()]
    cond = kept.max() / kept.min()
    units = _units(sim.scene)
    output_unit = {"T": units["F"], "Freact": units["F"], "acc": G}
    for (output, name), block in J_numpy.blocks.items():
        to_natural = units[name] / output_unit[output]
        scale = max(float(np.abs(block).max(initial=0.0)) * to_natural, 1.0)
        np.testing.assert_allclose(J_native[output, name] * to_natural, block * to_natural, rtol=0,
                                   atol=1e-12 * cond * scale, err_msg=f"d{output}/d{name}")
    assert isinstance(native.interface_linearization(F, hold).singular, bool)


def test_force_element_derivatives_equal_central_differences():
    """Each kind's derivative (drag, quadratic drag, spring-damper) against differences of its forces along a random
    (dX, dU), at a state where the spring is stretched and everything moves."""
    scene = ln.Scene.from_dict({
        "name": "elements", "gravity": [0, 0, 0],
        "masses": [{"name": "a", "mass": 1.0, "position": [0, 0, 0], "drag": 0.4},
                   {"name": "b", "mass": 2.0, "position": [0.7, 0.2, -0.1]},
                   {"name": "c", "mass": 0.5, "position": [0.1, 0.9, 0.3], "quadratic_drag": 0.6}],
        "links": [{"a": "a", "b": "b"}],
        "springs": [{"a": "a", "b": "c", "stiffness": 12.0, "damping": 0.7, "rest_length": 0.4}]})
    rng = np.random.default_rng(11)
    X, U = np.asarray(scene.X0, float), rng.standard_normal((3, 3))
    dX, dU = rng.standard_normal((3, 3)), rng.standard_normal((3, 3))
    h = 1e-6
    difference = (element_forces(scene, X + h * dX, U + h * dU) - element_forces(scene, X - h * dX, U - h * dU)) / (2 * h)
    exact = element_force_derivative(scene, X, U, dX, dU)
    np.testing.assert_allclose(exact, difference, rtol=0, atol=1e-8 * np.abs(exact).max())
    assert np.abs(exact).max() > 1.0  # every kind contributed


# ---- the interface ------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("backend", BACKENDS)
def test_jacobian_blocks_are_named_and_shaped_as_the_outputs_and_inputs(backend):
    scene = ln.load_scene("models/crane.json").with_motions({1: {"kind": "input"}})
    sim = _simulator(scene, backend)
    J = sim.interface_jacobian(None, _hold(scene.X0[0], [0, 0, 0], [0, 0, 0]))
    K, L = scene.K, scene.L
    assert J["T", "F"].shape == (L, K, 3) and J["T", "A"].shape == (L, 1, 3)
    assert J["Freact", "P"].shape == (1, 3, 1, 3) and J["acc", "V"].shape == (K, 3, 1, 3)
    assert J.matrix("Freact", "F").shape == (3, 3 * K)
    assert not np.any(J["T", "F"][:, 0, :])  # no force acts on the anchor: its column is zero
    # the load's weight hangs on every link: a downward force on the load pulls each link by its size
    np.testing.assert_allclose(J["T", "F"][:, K - 1, 2], -np.ones(L), atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_bad_seeds_are_refused_naming_the_seed_and_the_rule(backend):
    scene = ln.load_scene("models/crane.json").with_motions({1: {"kind": "input"}})
    lin = _simulator(scene, backend).interface_linearization()
    with pytest.raises(ln.SolverError, match=r"seed dF .* shape \(6, 3\)"):
        lin.directional(dF=np.zeros((5, 3)))
    with pytest.raises(ln.SolverError, match=r"seed dA .* shape \(1, 3\)"):
        lin.directional(dA=np.zeros(3))
    bad = np.zeros((1, 3))
    bad[0, 2] = np.nan
    with pytest.raises(ln.SolverError, match=r"dV\[1,3\] .*trolley.* must be finite"):
        lin.directional(dV=bad)
    plain = _simulator(ln.load_scene("models/chain_10.json"), backend).interface_linearization()
    with pytest.raises(ln.SolverError, match="no input-driven anchors"):
        plain.directional(dP=np.zeros((1, 3)))


@pytest.mark.parametrize("backend", BACKENDS)
def test_anchors_following_a_callable_are_linearized_at_its_values_and_its_failure_is_named(backend):
    """anchors= a callable of t: the linearization is that of the (P, V, A) it gives at the current time; a callable
    that raises is one SolverError naming it, as outputs() and advance() say."""
    sim = _simulator(pendulum(0.4), backend)
    P, V, A = [[0.1, 0.0, 0.0]], [[0.2, 0.1, 0.0]], [[0.0, 0.5, 1.0]]
    by_callable = sim.interface_jacobian(None, lambda t: _hold(P, V, A))
    held = sim.interface_jacobian(None, _hold(P, V, A))
    for key, block in held.blocks.items():
        np.testing.assert_array_equal(by_callable[key], block)

    def broken(t):
        raise RuntimeError("the trolley's controller is down")
    with pytest.raises(ln.SolverError, match="motion callable failed .*controller is down"):
        sim.interface_linearization(None, broken)
