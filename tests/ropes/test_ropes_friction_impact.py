"""A rod landing on one end on a rough ground at a slant: the impact with Coulomb friction against Newton's laws
written here. The rod is two point masses joined by a massless rod (a rigid body with one contact point); its foot
lands with the velocity U1-, its top moves with U2-. The impulse equations: m1 dU1 = P_n z + P_t + Lambda e,
m2 dU2 = -Lambda e (Lambda the rod's impulse along its direction e), e . (U2+ - U1+) = 0 (the rod keeps its length),
U1+ . z = -e_n U1- . z (Newton's restitution), and Coulomb's law at the impact: the foot sticks, U1+ tangential = 0,
where that needs |P_t| <= mu P_n; else it slides, P_t = -mu P_n d with d the direction of its tangential velocity
after the impact (found here by a scan of its angle and brentq). A linear system for each case: the closed form of a
rigid body hitting with one contact point. The friction feeds back into the normal impulse through the rod: with mu
0.3 the normal impulse of a foot sliding on is 14% below the frictionless impact's, and 19% above it for a foot
slid backwards. And a dumbbell landing flat on both ends at once, its ends' slips turned by the rod, against the same
equations with two contacts (each stuck or sliding, the two slip angles by fsolve)."""
from __future__ import annotations

import warnings

import numpy as np
import pytest
from rope_references import G
from scipy.optimize import brentq, fsolve

import linknet_core as ln
from linknet_core.dynamics.unilateral import UnilateralDynamics

Z = np.array([0.0, 0.0, 1.0])
ANGLE = np.radians(50.0)
MASSES = np.array([1.0, 2.0])  # the foot, the top
ROD = np.array([[0.0, 0.0, 0.0], [np.cos(ANGLE), 0.0, np.sin(ANGLE)]])


def rod_scene(X, U, mu, restitution):
    return ln.Scene.from_dict({
        "name": "landing_rod", "gravity": [0, 0, -G],
        "masses": [{"name": f"m{i + 1}", "position": X[i].tolist(), "mass": float(MASSES[i]),
                    "velocity": U[i].tolist()} for i in range(2)],
        "links": [{"a": "m1", "b": "m2", "length": float(np.linalg.norm(X[1] - X[0]))}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu, "restitution": restitution}})


def newtons_impact(X, U, mu, restitution):
    """(U+ (2, 3), P_n, P_t (3,), 'stick' or 'slide') of the foot (mass 1, on the plane z = 0) hitting the ground."""
    e = (X[1] - X[0]) / np.linalg.norm(X[1] - X[0])

    def solve(slip=None):
        # unknowns: U1+ (3), U2+ (3), Lambda, P_n, P_t (x, y)
        A, b = np.zeros((10, 10)), np.zeros(10)
        A[0:3, 0:3], A[0:3, 6], A[0:3, 7], A[0:2, 8:10] = MASSES[0] * np.eye(3), -e, -Z, -np.eye(2)
        b[0:3] = MASSES[0] * U[0]
        A[3:6, 3:6], A[3:6, 6] = MASSES[1] * np.eye(3), e
        b[3:6] = MASSES[1] * U[1]
        A[6, 0:3], A[6, 3:6] = -e, e
        A[7, 2], b[7] = 1.0, -restitution * U[0, 2]
        if slip is None:  # the foot stops along the plane
            A[8, 0] = A[9, 1] = 1.0
        else:  # P_t = -mu P_n d
            A[8, 8] = A[9, 9] = 1.0
            A[8:10, 7] = mu * slip
        x = np.linalg.solve(A, b)
        return x[0:6].reshape(2, 3), x[7], np.array([x[8], x[9], 0.0])

    U_plus, P_n, P_t = solve()
    if np.linalg.norm(P_t) <= mu * P_n:
        return U_plus, P_n, P_t, "stick"

    def across(phi):
        d = np.array([np.cos(phi), np.sin(phi)])
        v = solve(d)[0][0, :2]
        return v[1] * d[0] - v[0] * d[1]
    grid = np.linspace(-np.pi, np.pi, 721) + 1e-3
    values = [across(p) for p in grid]
    slides = []
    for lo, hi, f_lo, f_hi in zip(grid[:-1], grid[1:], values[:-1], values[1:]):
        if f_lo * f_hi < 0:
            phi = brentq(across, lo, hi, xtol=1e-15)
            d = np.array([np.cos(phi), np.sin(phi)])
            U_plus, P_n, P_t = solve(d)
            if U_plus[0, :2] @ d > 0 and P_n > 0:
                slides.append((U_plus, P_n, P_t))
    assert len(slides) == 1, "Coulomb's impact law has one solution here"
    return (*slides[0], "slide")


def degrees(a, b):
    return float(np.degrees(np.arccos(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def kinetic_energy(U):
    return 0.5 * float(np.einsum("i,ij,ij->", MASSES, U, U))


# (the rod's velocity before the impact: foot, top), mu, restitution, the regime
CASES = [
    (([0.5, 0, -2], [0.5, 0, -2]), 0.5, 0.0, "stick"),
    (([0.2, 0.1, -2], [0.2, 0.1, -2]), 0.8, 0.0, "stick"),
    (([2.0, 0, -2], [2.0, 0, -2]), 0.3, 0.5, "stick"),
    (([2.0, 0, -2], [2.0, 0, -2]), 0.3, 0.0, "slide"),
    (([-2.0, 0, -2], [-2.0, 0, -2]), 0.3, 0.0, "slide"),
    (([1.0, 1.5, -2], [1.0, 1.5, -2]), 0.3, 0.0, "slide"),  # across the rod's plane: the slip turns by 38 degrees
    (([1.0, 1.5, -2], [1.0, 1.5, -2]), 0.3, 0.4, "slide"),
    (([1.0, 0.5, -2], [0.2, 0.5, -1.3]), 0.15, 0.0, "slide"),  # the rod rotating as it lands
]


@pytest.mark.parametrize("velocities,mu,restitution,regime", CASES)
def test_a_rod_landing_on_one_end_takes_coulombs_impact_law_with_the_normal_impulse_coupled(velocities, mu,
                                                                                             restitution, regime):
    X, U = ROD, np.array(velocities, float)
    U[1] -= ((U[1] - U[0]) @ (X[1] - X[0])) / ((X[1] - X[0]) @ (X[1] - X[0])) * (X[1] - X[0])  # a rigid motion
    U_ref, P_n, P_t, found = newtons_impact(X, U, mu, restitution)
    assert found == regime
    dyn = UnilateralDynamics(rod_scene(X, U, mu, restitution))
    U_after, normal, took, tangential = dyn.coulomb_impact(X, U, dyn.touching(X))
    scale = float(np.abs(U).max())
    assert np.abs(U_after - U_ref).max() <= 1e-14 * scale
    assert took[0] and normal[0] == pytest.approx(P_n, rel=1e-14)
    assert tangential[0] == pytest.approx(np.linalg.norm(P_t), rel=1e-13, abs=1e-14 * P_n)
    # the friction's feedback: the normal impulse is not the frictionless impact's where the foot slides
    frictionless = dyn.impact(X, U, dyn.touching(X))[1][0]
    if regime == "slide":
        assert abs(P_n / frictionless - 1.0) > 0.01
    if restitution == 0.0:
        assert kinetic_energy(U_ref) < kinetic_energy(U)


@pytest.mark.parametrize("mu,v,t_end,regime", [(0.8, [1.2, 0.7, 0.0], 0.3, "stick"),
                                                (0.2, [3.0, 1.5, 0.0], 0.6, "slide")])
def test_a_rod_dropped_at_a_slant_lands_with_coulombs_impulse_and_its_energy_never_grows(mu, v, t_end, regime):
    # the rod falls without turning (gravity acts on both masses alike) from its foot 0.3 m up, moving sideways, and
    # lands at sqrt(2 h / g) with the velocity it fell with; then it turns about its stuck foot (until 0.3164 s,
    # where the foot slips), or slides on the ground until its top lands too (0.49 s), never gaining energy
    h, v = 0.3, np.array(v)
    X0 = ROD + h * Z
    U0 = np.array([v, v])
    t_land = np.sqrt(2 * h / G)
    U_land = U0 - G * t_land * Z
    U_ref, P_n, _, found = newtons_impact(ROD, U_land, mu, 0.0)
    assert found == regime
    run = ln.simulate(rod_scene(X0, U0, mu, 0.0), t_end, "dop853", rtol=1e-10, n_out=121, error_estimate=False)
    first = run.events[0]
    assert [e.kind for e in run.events] == ["contact"] if regime == "stick" else ["contact", "contact"]
    assert (first.kind, first.index) == ("contact", 0)
    assert first.t == pytest.approx(t_land, abs=1e-12)
    assert first.impulse == pytest.approx(P_n, rel=1e-10)
    energy = 0.5 * np.einsum("i,tij,tij->t", MASSES, run.U, run.U) + G * np.einsum("i,ti->t", MASSES, run.X[..., 2])
    before = run.t < first.t
    assert np.ptp(energy[before]) < 1e-9 * energy[0]
    assert np.diff(energy).max() < 1e-9 * energy[0]
    if regime == "stick":  # the foot stays where it landed
        assert np.abs(run.X[~before, 0] - (v * t_land)).max() < 1e-12
    after = np.flatnonzero(~before)[0]
    impact_loss = kinetic_energy(U_land) - kinetic_energy(U_ref)
    assert energy[after] - (energy[0] - impact_loss) < 1e-9 * energy[0]


def newtons_flat_landing(X, U, masses, mu):
    """The dumbbell of ``masses`` lying along its rod, both ends hitting the plane z = 0 at once (inelastic): each
    end m_i dU_i = P_n,i z + P_t,i -+ Lambda e, e . (U2+ - U1+) = 0, U_i+ . z = 0, and Coulomb's law at each end
    (stuck: its tangential velocity zero, |P_t,i| <= mu P_n,i; sliding: P_t,i = -mu P_n,i d_i, d_i along its
    tangential velocity after, the two angles by fsolve from the directions before). [(the ends' regimes, U+)] of
    every combination that satisfies the law."""
    e = (X[1] - X[0]) / np.linalg.norm(X[1] - X[0])

    def solve(regimes, slips):
        # unknowns: U1+ (3), U2+ (3), Lambda, P_n (2), P_t (2 x 2)
        A, b = np.zeros((13, 13)), np.zeros(13)
        for i, sign in ((0, 1.0), (1, -1.0)):
            A[3 * i:3 * i + 3, 3 * i:3 * i + 3] = masses[i] * np.eye(3)
            A[3 * i:3 * i + 3, 6], A[3 * i:3 * i + 3, 7 + i] = -sign * e, -Z
            A[3 * i:3 * i + 2, 9 + 2 * i:11 + 2 * i] = -np.eye(2)
            b[3 * i:3 * i + 3] = masses[i] * U[i]
            A[7 + i, 3 * i + 2] = 1.0
            row = 9 + 2 * i
            if regimes[i] == "stick":
                A[row, 3 * i], A[row + 1, 3 * i + 1] = 1.0, 1.0
            else:
                A[row, row] = A[row + 1, row + 1] = 1.0
                A[row:row + 2, 7 + i] = mu * slips[i]
        A[6, 0:3], A[6, 3:6] = -e, e
        x = np.linalg.lstsq(A, b, rcond=None)[0]  # both stuck along the rod: the tangential impulses' split is free
        return x[:6].reshape(2, 3), x[7:9], x[9:13].reshape(2, 2)

    def unit(phi):
        return np.array([np.cos(phi), np.sin(phi)])
    found = []
    for regimes in (("stick", "stick"), ("stick", "slide"), ("slide", "stick"), ("slide", "slide")):
        sliding = [i for i in range(2) if regimes[i] == "slide"]

        def slips_of(phis):
            slips = [np.zeros(2), np.zeros(2)]
            for i, phi in zip(sliding, phis):
                slips[i] = unit(phi)
            return slips

        def across(phis):
            U_plus = solve(regimes, slips_of(phis))[0]
            return [U_plus[i, 1] * np.cos(p) - U_plus[i, 0] * np.sin(p) for i, p in zip(sliding, phis)]
        with warnings.catch_warnings():  # a combination without a root ends with fsolve's warning, and is refused below
            warnings.simplefilter("ignore", RuntimeWarning)
            phis = fsolve(across, [np.arctan2(U[i, 1], U[i, 0]) for i in sliding], xtol=1e-15) if sliding else []
        slips = slips_of(phis)
        U_plus, P_n, P_t = solve(regimes, slips)
        holds = bool(np.all(P_n >= 0))
        for i in range(2):
            if regimes[i] == "stick":
                holds &= bool(np.linalg.norm(P_t[i]) <= mu * P_n[i])
            else:
                v = U_plus[i, :2]
                holds &= bool(v @ slips[i] > 0 and abs(v[1] * slips[i][0] - v[0] * slips[i][1]) < 1e-13)
        if holds:
            found.append((regimes, U_plus))
    return found


@pytest.mark.parametrize("velocities,mu", [(([1.0, 0.5, -2], [1.0, -0.7, -1.5]), 0.3),
                                           (([0.3, 0.9, -2], [0.3, -0.4, -1.0]), 0.4)])
def test_a_dumbbell_landing_flat_slides_on_both_ends_their_slips_turned_by_the_rod(velocities, mu):
    # the rod carries the ends' friction along its length, not across: each end's slip turns (by 2.4 and 2.1
    # degrees, and 1.3 and 1.4), which the impact solves for both at once
    masses = np.array([1.0, 1.5])
    X, U = np.array([[0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]]), np.array(velocities, float)
    found = newtons_flat_landing(X, U, masses, mu)
    assert [regimes for regimes, _ in found] == [("slide", "slide")]
    U_ref = found[0][1]
    scene = ln.Scene.from_dict({
        "name": "flat_dumbbell", "gravity": [0, 0, -G],
        "masses": [{"name": f"m{i + 1}", "position": X[i].tolist(), "mass": float(masses[i]),
                    "velocity": U[i].tolist()} for i in range(2)],
        "links": [{"a": "m1", "b": "m2", "length": 1.0}],
        "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}})
    dyn = UnilateralDynamics(scene)
    U_after = dyn.coulomb_impact(X, U, dyn.touching(X))[0]
    assert np.abs(U_after - U_ref).max() <= 1e-14 * float(np.abs(U).max())
    turned = [degrees(U_ref[i, :2], U[i, :2]) for i in range(2)]
    assert min(turned) > 1.0
    assert 0.5 * np.einsum("i,ij,ij->", masses, U_ref, U_ref) < 0.5 * np.einsum("i,ij,ij->", masses, U, U)


@pytest.mark.parametrize("velocity,mu,rope", [([2.0, 0.0, -2.0], 0.9, "taut"), ([2.0, 0.5, -2.0], 0.6, "taut"),
                                              ([2.0, 0.0, -2.0], 0.3, "slack"), ([2.0, 1.0, -2.0], 0.3, "slack")])
def test_a_two_mass_rope_landing_sliding_jerks_taut_or_goes_slack_with_coulombs_impulse(velocity, mu, rope):
    # the rope 20 degrees up ahead of the landing mass: where the rod's impulse in the rigid body's equations pulls,
    # the rope takes it (the same impact); where it would push, the rope goes slack and the foot lands alone: P_n =
    # m1 v_n, and its tangential velocity loses mu v_n (or stops), the other mass flying on untouched
    angle = np.radians(20.0)
    X = np.array([[0.0, 0.0, 0.0], [np.cos(angle), 0.0, np.sin(angle)]])
    U = np.array([velocity, velocity], float)
    U_rod, P_n, _, _ = newtons_impact(X, U, mu, 0.0)
    pull = -MASSES[1] * (U_rod[1] - U[1]) @ (X[1] - X[0])  # the rod's impulse on the far mass, along the rope
    scene = rod_scene(X, U, mu, 0.0).to_dict()
    scene["links"][0]["kind"] = "rope"
    dyn = UnilateralDynamics(ln.Scene.from_dict(scene))
    U_after, impulses, _, _ = dyn.coulomb_impact(X, U, dyn.touching(X))
    if rope == "taut":
        assert pull > 0
        U_ref = U_rod
        assert impulses[0] > 0 and impulses[1] == pytest.approx(P_n, rel=1e-14)
    else:
        assert pull < 0
        v_n, v_t = -U[0, 2], U[0, :2]
        left = max(np.linalg.norm(v_t) - mu * v_n, 0.0)
        U_ref = np.array(U)
        U_ref[0] = np.concatenate([left * v_t / np.linalg.norm(v_t), [0.0]])
        assert impulses[0] == 0.0 and impulses[1] == pytest.approx(MASSES[0] * v_n, rel=1e-14)
    assert np.abs(U_after - U_ref).max() <= 1e-14 * float(np.abs(U).max())
