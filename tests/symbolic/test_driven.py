"""Driven anchors in the casadi derivation and in ``linknet check``.

Physics from the derivation alone (a pendulum on an accelerating pivot, a mass whirling about a moving
pivot, the anchor's acceleration acting as gravity in the anchor's frame), then the checker: it passes on
scenes with every kind of motion and catches numeric sides that drop the anchor's velocity or acceleration.
"""
import argparse

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.errors import SolverError
from linknet_core.symbolic import check as checks
from linknet_core.symbolic import codegen
from linknet_core.symbolic.derivation import SymbolicTensionSystem

G = 9.81


def _scene(masses, links, gravity=(0, 0, -G), **extra):
    return ln.Scene.from_dict({"name": "driven", "gravity": list(gravity), "masses": masses, "links": links,
                               **extra})


def _pendulum(pivot_at, bob_at, m=1.3, motion=None):
    pivot = {"name": "pivot", "position": list(pivot_at), "driven": True}
    if motion is not None:
        pivot["motion"] = motion
    return _scene([pivot, {"name": "bob", "mass": m, "position": list(bob_at)}], [{"a": "pivot", "b": "bob"}])


def _every_motion_scene():
    """Hook (sine) with a hanging chain and a spring to an input-driven winch, a towing point (waypoints), a
    drone (constant velocity), a standing post with a spring."""
    return _scene(
        [{"name": "hook", "position": [0, 0, 0], "driven": True,
          "motion": {"kind": "sine", "amplitude": [0.5, 0.2, 0.1], "frequency": [0.7, 1.1, 0.3],
                     "phase": [0.3, 0, 1]}},
         {"name": "m1", "mass": 1.0, "position": [0, 0, -1]},
         {"name": "m2", "mass": 2.0, "position": [0.3, 0, -1.9], "drag": 0.2},
         {"name": "m3", "mass": 0.5, "position": [0.6, 0.1, -2.8]},
         {"name": "winch", "position": [2, 0, 0], "driven": True},
         {"name": "post", "position": [-2, 0, -3], "fixed": True},
         {"name": "tow", "position": [1, 1, -3], "driven": True,
          "motion": {"kind": "waypoints", "waypoints": [[1, 1.5, 1, -3], [2, 1.5, 1.5, -2.8]]}},
         {"name": "m4", "mass": 1.5, "position": [1, 1, -4]},
         {"name": "drone", "position": [0, 3, 0], "driven": True,
          "motion": {"kind": "velocity", "velocity": [0.5, 0, 0.2]}},
         {"name": "m5", "mass": 0.7, "position": [0, 3, -1.2]}],
        [{"a": "hook", "b": "m1"}, {"a": "m1", "b": "m2"}, {"a": "m2", "b": "m3"}, {"a": "tow", "b": "m4"},
         {"a": "drone", "b": "m5"}, {"a": "m4", "b": "post"}],
        springs=[{"a": "winch", "b": "m3", "stiffness": 10, "damping": 0.5}, {"a": "post", "b": "m2", "stiffness": 3}])


# ---------------------------------------------------------------------------------------------
# the derivation
# ---------------------------------------------------------------------------------------------

def test_pendulum_on_a_uniformly_accelerating_pivot_hangs_at_atan_a_over_g():
    """Pivot accelerating with a along x: at rest relative to the pivot, tilted back by atan(a/g), the bob
    accelerates with the pivot and the tension is m sqrt(g^2 + a^2) (the weight in g_eff)."""
    m, R, a = 1.3, 0.8, 3.7
    g_eff = np.array([-a, 0.0, -G])                              # gravity minus the frame's acceleration
    r = R * g_eff / np.linalg.norm(g_eff)
    assert np.degrees(np.arctan2(-r[0], -r[2])) == pytest.approx(np.degrees(np.arctan(a / G)), rel=1e-14)
    scene = _pendulum([0.2, 0.1, 0.0], np.array([0.2, 0.1, 0.0]) + r, m)
    sym = SymbolicTensionSystem(scene)
    V = np.array([1.5, -0.4, 0.3])                               # any common velocity: relative rest
    U = np.array([V, V])
    A = np.array([[a, 0.0, 0.0], [0.0, 0.0, 0.0]])
    F = np.array([[0.0, 0, 0], [0, 0, -m * G]])
    acc, T = sym.solve(scene.X0, U, F, anchor_acc=A)
    assert T[0] == pytest.approx(m * np.hypot(G, a), rel=1e-14)
    np.testing.assert_allclose(acc, [[a, 0, 0], [a, 0, 0]], atol=1e-14)
    # the same state with the pivot held still: the bob swings towards the vertical, T = m g cos(tilt)
    acc0, T0 = sym.solve(scene.X0, 0 * U, F)
    assert T0[0] == pytest.approx(m * G * G / np.hypot(G, a), rel=1e-14)
    assert acc0[1, 0] > 0


def test_whirling_about_a_moving_pivot_sees_the_relative_velocity_only():
    """No gravity, bob moving at V + w (w perpendicular to the link), pivot at V: T = m |w|^2 / R for any V."""
    m, R = 0.9, 1.1
    scene = _scene([{"name": "pivot", "position": [0, 0, 0], "driven": True},
                    {"name": "bob", "mass": m, "position": [0, R, 0]}], [{"a": "pivot", "b": "bob"}],
                   gravity=(0, 0, 0))
    sym = SymbolicTensionSystem(scene)
    w = np.array([2.3, 0.0, -0.7])
    for V in ([0, 0, 0], [5.0, -3.0, 1.0], [0, 40.0, 0]):
        U = np.array([V, np.add(V, w)])
        assert np.abs(sym.velocity_constraint(scene.X0, U)).max() == 0.0        # (12): relative velocity
        _, T = sym.solve(scene.X0, U, np.zeros((2, 3)))
        assert T[0] == pytest.approx(m * w @ w / R, rel=1e-14)
    # moving along the link instead: (12) measures exactly that relative speed
    U = np.array([[0, 1.0, 0], [0, 3.0, 0]])
    assert sym.velocity_constraint(scene.X0, U)[0] == pytest.approx(2.0, rel=1e-15)


def test_anchor_acceleration_acts_as_gravity_in_the_anchor_frame():
    """Every anchor driven with the same acceleration A and velocity V: B (26) equals that of anchors at rest
    with every free mass given the force -M A and the velocities U - V (equivalence principle, Galilean
    invariance), at any state (on or off (11))."""
    scene = _every_motion_scene()
    post = scene.mass_names.index("post")
    # make the post driven too (all anchors then share A)
    d = scene.to_dict()
    d["masses"][post] = {"name": "post", "position": d["masses"][post]["position"], "driven": True}
    scene = ln.Scene.from_dict(d)
    sym = SymbolicTensionSystem(scene)
    rng = np.random.default_rng(5)
    anchors = np.asarray(scene.fixed)
    mass = np.where(anchors, 0.0, np.asarray(scene.mass))
    for _ in range(3):
        X = np.asarray(scene.X0) + 0.2 * rng.standard_normal((scene.K, 3))
        U = rng.standard_normal((scene.K, 3))
        F = rng.standard_normal((scene.K, 3)) * ~anchors[:, None]
        A, V = rng.standard_normal(3), rng.standard_normal(3)
        U[anchors] = V
        Aa = np.where(anchors[:, None], A, 0.0)
        B = sym.B(X, U, F, anchor_acc=Aa)
        U_frame = U - V
        B_frame = sym.B(X, U_frame, F - mass[:, None] * A)
        np.testing.assert_allclose(B, B_frame, rtol=1e-12, atol=1e-12 * np.abs(B).max())


def test_driven_anchor_is_a_symbol_and_A_ignores_its_velocity_and_acceleration():
    scene = _every_motion_scene()
    sym = SymbolicTensionSystem(scene)
    assert sym.nd == 4 and list(sym.driven) == list(scene.driven_indices)
    assert set(sym.still) == {scene.mass_names.index("post")}
    assert sym.p_sym.numel() == 12 and sym.a_sym.numel() == 12
    # A depends on the anchors' positions (a link's direction), B on their velocity and acceleration
    import casadi as ca

    A = sym.A_fn(sym.x_sym, sym.p_sym)
    assert ca.depends_on(A, sym.p_sym)
    B = sym.B_fn(sym.x_sym, sym.u_sym, sym.f_sym, sym.p_sym, sym.v_sym, sym.a_sym)
    assert ca.depends_on(B, sym.v_sym) and ca.depends_on(B, sym.a_sym)
    # the constraint Jacobian in p is the negative of the one in x at the anchor's far end: row l of
    # -(11)/(2R) differentiated in P_a is -E_l (a at k1) or +E_l (a at k2)
    X = np.asarray(scene.X0, float)
    Gp = sym.Gp(X).toarray()
    hook, link = 0, 0                                              # link hook -> m1: hook is k1
    E = (X[scene.k2[link]] - X[scene.k1[link]]) / scene.length[link]
    np.testing.assert_allclose(Gp[link, 3 * hook:3 * hook + 3], E, atol=1e-15)


# ---------------------------------------------------------------------------------------------
# the checker
# ---------------------------------------------------------------------------------------------

DRIVEN_LINE = "driven anchors: (12) and (26) with V_a, A_a"
NATIVE_LINE = "native core with driven anchors = symbolic"
JUMP_LINE = "anchor velocity jump: impulse, projection (12)"
RATTLE_LINE = "RATTLE: (11) at P_a(t+h), (12) at V_a(t+h)"


def test_every_check_passes_with_every_kind_of_motion():
    scene = _every_motion_scene()
    results = checks.run_checks(scene, samples=2, seed=4)
    assert all(r.passed for r in results), "\n".join(r.line() for r in results if not r.passed)
    line = next(r for r in results if r.name == DRIVEN_LINE)
    assert line.discrepancy < 1e-13
    assert "4 driven anchor(s) (input, sine, velocity, waypoints)" in line.detail
    rattle = next(r for r in results if r.name == RATTLE_LINE)
    assert not rattle.skipped and "numpy: anchors vs P(t+h), V(t+h)" in rattle.detail, rattle.line()
    native = next(r for r in results if r.name == NATIVE_LINE)
    assert native.skipped or "2 state(s) through Simulator(backend='native')" in native.detail, native.line()


def test_a_driven_anchor_on_a_rigid_path_to_a_post_is_reported(capsys, tmp_path):
    """Post - mass - driven hook in a straight line (a taut rope): the (35)-violating velocity of the middle
    mass and the (35)-violating acceleration of the hook are found at the scene's own positions, and the CLI
    prints the driven lines."""
    path = tmp_path / "rope.json"
    path.write_text('{"name": "rope", "gravity": [0, 0, -9.81], "masses": ['
                    '{"name": "post", "position": [0, 0, 0], "fixed": true},'
                    '{"name": "m", "mass": 1.0, "position": [1, 0, 0]},'
                    '{"name": "hook", "position": [2, 0, 0], "driven": true}],'
                    '"links": [{"a": "post", "b": "m"}, {"a": "m", "b": "hook"}],'
                    # the weight of m across the straight rope is refused at the start unless asked for: the checks
                    # look at the scene's own states all the same
                    '"options": {"run_loaded_blocked_flexes": true}}')
    parser = argparse.ArgumentParser()
    checks.add_arguments(parser)
    assert checks.main(parser.parse_args([str(path), "--samples", "2"])) == 0
    out = capsys.readouterr().out
    assert out.count("PASS") + out.count("SKIP") == 13 and "FAIL" not in out and DRIVEN_LINE in out
    assert JUMP_LINE in out and RATTLE_LINE in out
    assert "rope at its initial positions" in out
    # the hook accelerating along the taut rope: no consistent accelerations, reported and refused
    assert "violation by the prescribed motion REPORTED; the solver refuses it with ConsistencyError" in out


class _NumericDouble:
    """The real Dynamics with B (26) (and the reactions) replaced: a wrong treatment of the driven anchors."""

    def __init__(self, scene, rhs=None, reactions=None):
        self.real = ln.Dynamics(scene)
        self.scene = scene
        self._rhs, self._reactions = rhs, reactions

    def __getattr__(self, name):
        return getattr(self.real, name)

    def tension_rhs(self, X, U, F, anchor_acc=None):
        return self._rhs(X, U, F, anchor_acc)

    def tensions(self, X, U, F_input=None, anchor_acc=None):
        B = self.tension_rhs(X, U, self.forces(X, U, F_input), anchor_acc)
        self.real.factor(X)
        return self.real.solver.solve(B)

    def accelerations(self, X, U, F_input=None, anchor_acc=None):
        T = self.tensions(X, U, F_input, anchor_acc)
        acc = (self.forces(X, U, F_input) + self.real.link_forces(X, T)) * self.scene.inv_mass[:, None]
        return acc + (0.0 if anchor_acc is None else anchor_acc), T

    def anchor_reactions(self, X, T):
        R = self.real.anchor_reactions(X, T)
        return R if self._reactions is None else self._reactions(R)


@pytest.fixture(scope="module")
def hook_scene():
    return _scene([{"name": "hook", "position": [0, 0, 0], "driven": True},
                   {"name": "m1", "mass": 1.0, "position": [0, 0, -1]},
                   {"name": "m2", "mass": 2.0, "position": [0.3, 0, -1.9]}],
                  [{"a": "hook", "b": "m1"}, {"a": "m1", "b": "m2"}])


@pytest.mark.parametrize("mistake", ["anchor acceleration dropped", "absolute velocity at the anchor",
                                     "reaction sign"])
def test_checker_catches_a_wrong_treatment_of_driven_anchors(hook_scene, mistake):
    from linknet_core.dynamics.tensions import rhs

    scene = hook_scene
    driven = np.asarray(scene.driven)

    def no_acceleration(X, U, F, anchor_acc):
        return rhs(scene, X, U, F)

    def absolute_velocity(X, U, F, anchor_acc):
        U = np.where(driven[:, None], 0.0, U)
        return rhs(scene, X, U, F, anchor_acc=anchor_acc)

    def correct(X, U, F, anchor_acc):
        return rhs(scene, X, U, F, anchor_acc=anchor_acc)

    dyn = {"anchor acceleration dropped": lambda: _NumericDouble(scene, no_acceleration),
           "absolute velocity at the anchor": lambda: _NumericDouble(scene, absolute_velocity),
           "reaction sign": lambda: _NumericDouble(scene, correct, reactions=lambda R: -R)}[mistake]()
    results = {r.name: r for r in checks.run_checks(scene, samples=2, seed=0, dynamics=dyn)}
    assert not results[DRIVEN_LINE].passed, results[DRIVEN_LINE].line()
    if mistake != "reaction sign":
        assert not results["A and B numeric = symbolic on the manifold"].passed
        assert not results["accelerations (9) and tensions: solver = symbolic"].passed


def test_the_casadi_kernel_is_refused_for_driven_scenes(hook_scene):
    with pytest.raises(codegen.CodegenUnavailable, match="driven anchors"):
        codegen.compiled_rhs(hook_scene, required=True)
    assert codegen.compiled_rhs(hook_scene) is None
    with pytest.raises(SolverError, match="driven anchors"):
        ln.Dynamics(hook_scene, rhs_kernel="casadi")
    line = checks.run_checks(hook_scene, samples=1, seed=0, kernel=True)[-1]
    assert line.skipped and "driven anchors" in line.detail


MOTION_LINE = "driven anchors' motions: V = dP/dt, A = dV/dt"


class _FakeMotion:
    """A motion with the scene's spec but another evaluation (what a wrong motion module would give)."""

    def __init__(self, real, evaluate):
        self.kind, self.origin, self.spec, self.evaluate = real.kind, real.origin, real.spec, evaluate


@pytest.mark.parametrize("mistake", ["natural spline", "acceleration 1% off", "sine velocity sign"])
def test_motion_line_catches_wrong_motions(mistake):
    import dataclasses

    from scipy.interpolate import CubicSpline

    waypoints = [[0.5, 1.0, 0.0, 0.0], [1.5, 1.0, 1.0, 0.2], [2.0, 0.0, 0.5, 0.0]]
    kind = {"kind": "sine", "amplitude": [0.3, 0, 0.1], "frequency": [1.0, 0, 2.0]} if "sine" in mistake else \
        {"kind": "waypoints", "waypoints": waypoints}
    scene = _pendulum([0, 0, 0], [0, 0, -1], motion=kind)
    real = scene.motions[0]
    if mistake == "natural spline":
        spline = CubicSpline([0.0] + [w[0] for w in waypoints], [[0, 0, 0]] + [w[1:] for w in waypoints],
                             bc_type="natural")

        def evaluate(t):
            t = min(max(t, 0.0), 2.0)
            return spline(t), spline(t, 1), spline(t, 2)
    elif mistake == "acceleration 1% off":
        def evaluate(t):
            P, V, A = real.evaluate(t)
            return P, V, 1.01 * A
    else:
        def evaluate(t):
            P, V, A = real.evaluate(t)
            return P, -V, A
    good = {r.name: r for r in checks.run_checks(scene, samples=3, seed=1)}
    assert good[MOTION_LINE].passed, good[MOTION_LINE].line()
    wrong = dataclasses.replace(scene, motions=(_FakeMotion(real, evaluate),))
    results = {r.name: r for r in checks.run_checks(wrong, samples=3, seed=1)}
    assert not results[MOTION_LINE].passed


def test_native_line_catches_a_core_whose_reactions_are_wrong(hook_scene, monkeypatch):
    from linknet_core.simulator.simulator import Simulator

    real = Simulator.outputs

    def reactions_off(self, F_input=None, anchors=None):
        out = real(self, F_input, anchors)
        out["Freact"] = 1.001 * out["Freact"]
        return out

    good = {r.name: r for r in checks.run_checks(hook_scene, samples=2, seed=0)}[NATIVE_LINE]
    if good.skipped:
        pytest.skip(good.detail)
    assert good.passed, good.line()
    monkeypatch.setattr(Simulator, "outputs", reactions_off)
    wrong = {r.name: r for r in checks.run_checks(hook_scene, samples=2, seed=0)}[NATIVE_LINE]
    assert not wrong.passed


def test_jump_line_compares_both_cores_and_catches_a_wrong_impulse(hook_scene, monkeypatch):
    """The impulse of a velocity jump of the hook, numpy and native, against the mass-metric projection onto
    (12) from AD's G and G_p; an impulse 0.1 % off is caught."""
    from linknet_core.simulator.simulator import Simulator

    good = {r.name: r for r in checks.run_checks(hook_scene, samples=2, seed=0)}[JUMP_LINE]
    assert good.passed and not good.skipped, good.line()
    assert "numpy" in good.detail and ("native" in good.detail or "not compared" in good.detail)
    real = Simulator.anchor_report

    def impulse_off(self):
        report = real(self)
        report["impulse"] = 1.001 * report["impulse"]
        return report

    monkeypatch.setattr(Simulator, "anchor_report", impulse_off)
    wrong = {r.name: r for r in checks.run_checks(hook_scene, samples=2, seed=0)}[JUMP_LINE]
    assert not wrong.passed
