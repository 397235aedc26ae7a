"""``linknet check`` with Coulomb friction enumerates the contact modes at each sampled state (each touching contact
off the ground, sliding along its velocity, or at rest stuck or slipping from rest; each touching rope taut or
slack) and says how many satisfy Coulomb's law: one (PASS), several (WARN: the rigid problem is ambiguous there,
Painleve's non-uniqueness, naming linknet's mode and the others), none (FAIL: inconsistent, naming each mode and the
condition it breaks).

The reference is Painleve's problem for a dumbbell, written here from Newton's laws: a foot of mass m1 sliding along
+x on the rough ground z = 0 at speed v, a head of mass m2 on a rigid massless rod of length R at an angle phi
above the ground, behind the foot (trailing) or ahead of it (leading), the rod turning at the rate omega. With e the
unit vector from foot to head, T the rod's pull on the foot (along e; -e on the head) and N the ground's normal
force, the foot sliding (friction -mu N x):

    m2 a2 = -m2 g z - T e,   m1 a1 = -m1 g z + T e + N z - mu N x,   a1 . z = 0,   e . (a2 - a1) = -R omega^2

(the last: the rod's length, differentiated twice). Eliminating: with e = (-s cos phi, 0, sin phi) (s = +1
trailing, -1 leading),

    N = (g (m1 + m2) / m2 - R omega^2 sin phi) / D,   D = 1 / m2 + (cos^2 phi - s mu sin phi cos phi) / m1.

Off the ground (N = 0) the foot's vertical acceleration is a_z = -g + R omega^2 sin phi m2 / (m1 + m2) (the rod's
pull m1 m2 / (m1 + m2) R omega^2). The numerator of N is -(m1 + m2) / m2 a_z: for D > 0 exactly one of the two modes
holds (N >= 0 or a_z >= 0); for D < 0, a trailing head with mu above

    mu_c(phi) = (m1 / m2 + cos^2 phi) / (sin phi cos phi),

both hold (a_z > 0) or neither (a_z < 0). A leading head has D > 0 for every mu."""
from __future__ import annotations

import argparse
import json
import math
import re

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.symbolic import check as checks

G = 9.81
M_FOOT, M_HEAD, R, V = 0.5, 2.0, 1.0, 1.0
PAINLEVE = "Coulomb friction: one solution (Painleve)"


def critical_mu(phi):
    return (M_FOOT / M_HEAD + math.cos(phi) ** 2) / (math.sin(phi) * math.cos(phi))


def lifting_rate(phi, factor):
    """The rod's rate omega at which the rod's pull alone would lift the foot with a_z = (factor - 1) g."""
    return math.sqrt(factor * G * (M_FOOT + M_HEAD) / (M_HEAD * R * math.sin(phi)))


def closed_form(phi, mu, omega, sign):
    """(N of the sliding mode, a_z of the foot off the ground) from the module's derivation."""
    D = 1 / M_HEAD + (math.cos(phi) ** 2 - sign * mu * math.sin(phi) * math.cos(phi)) / M_FOOT
    N = (G * (M_FOOT + M_HEAD) / M_HEAD - R * omega ** 2 * math.sin(phi)) / D
    a_z = -G + R * omega ** 2 * math.sin(phi) * M_HEAD / (M_FOOT + M_HEAD)
    return N, a_z


def dumbbell(phi, mu, omega, sign=1.0) -> dict:
    e = np.array([-sign * math.cos(phi), 0.0, math.sin(phi)])
    de = np.array([-sign * math.sin(phi), 0.0, -math.cos(phi)])  # d e / d phi: the head's motion as phi grows
    foot_u = np.array([V, 0.0, 0.0])
    return {"name": "painleve_dumbbell", "gravity": [0, 0, -G],
            "masses": [{"name": "foot", "position": [0.0, 0.0, 0.0], "mass": M_FOOT, "velocity": foot_u.tolist()},
                       {"name": "head", "position": (R * e).tolist(), "mass": M_HEAD,
                        "velocity": (foot_u + R * omega * de).tolist()}],
            "links": [{"a": "foot", "b": "head", "length": R}],
            "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "restitution": 0.0, "friction": mu}}


def painleve_line(scene):
    """The check's Painleve line at the scene's initial state alone."""
    states = [(0.0, np.array(scene.X0, float), np.array(scene.U0, float), None)]
    _, _, comp, _ = checks.run_unilateral_checks(scene, samples=1, states=states)
    return {r.name: r for r in comp}[PAINLEVE]


CASES = [  # (phi, mu as a multiple of mu_c(phi), omega as a multiple of the lifting rate (0: none), head trailing)
    (math.radians(60), 0.9, 0.0, 1.0), (math.radians(60), 1.1, 0.0, 1.0),
    (math.radians(60), 0.9, 1.3, 1.0), (math.radians(60), 1.1, 1.3, 1.0),
    (math.radians(45), 0.95, 0.0, 1.0), (math.radians(45), 1.05, 0.0, 1.0),
    (math.radians(45), 0.95, 1.2, 1.0), (math.radians(45), 1.05, 1.2, 1.0),
    (math.radians(60), 4.0, 0.0, -1.0), (math.radians(60), 4.0, 1.3, -1.0)]


@pytest.mark.parametrize("phi, mu_factor, lift, sign", CASES)
def test_the_dumbbells_count_of_solutions_follows_painleves_closed_form(phi, mu_factor, lift, sign):
    mu = mu_factor * critical_mu(phi)
    omega = lifting_rate(phi, lift) if lift else 0.0
    N, a_z = closed_form(phi, mu, omega, sign)
    sliding_holds, lift_off_holds = N >= 0, a_z >= 0
    line = painleve_line(ln.Scene.from_dict(dumbbell(phi, mu, omega, sign)))
    assert not line.skipped
    expected = int(sliding_holds) + int(lift_off_holds)
    if sign < 0 or mu_factor < 1:  # D > 0: one of the two, whatever omega
        assert expected == 1
    else:  # D < 0: both with a rod fast enough to lift the foot, else neither
        assert expected == (2 if lift else 0)
    slide = re.escape('the ground contact of mass 1 ("foot") sliding along [1.0, 0.0, 0.0]')
    off = re.escape('the ground contact of mass 1 ("foot") off the ground')
    if expected == 1:
        assert line.passed and not line.warning, line.line()
        assert "1 with one solution, 0 with several (ambiguous), 0 with none" in line.detail
    elif expected == 2:
        assert line.passed and line.warning and line.line().startswith("WARN"), line.line()
        assert "0 with one solution, 1 with several (ambiguous), 0 with none" in line.detail
        ambiguous = re.search(r"AMBIGUOUS at t = 0 s: 2 solutions of Coulomb's law: linknet's \[(.*?)\], and "
                              r"\[(.*?)\]", line.detail)
        assert ambiguous and {re.escape(x) for x in ambiguous.groups()} == {slide, off}
    else:
        assert not line.passed and line.line().startswith("FAIL")
        assert "0 with one solution, 0 with several (ambiguous), 1 with none (inconsistent)" in line.detail
        assert "INCONSISTENT at t = 0 s: no mode satisfies Coulomb's law (2 tried" in line.detail
        # each mode breaks the condition the closed form says, by the closed form's amount
        normal = re.search(rf"\[{slide}\] breaks .*?normal force (\S+) N", line.detail)
        lift_off = re.search(rf"\[{off}\] breaks .*?d2gap/dt2 (\S+) m/s\^2", line.detail)
        assert float(normal.group(1)) == pytest.approx(N, rel=1e-5) and N < 0
        assert float(lift_off.group(1)) == pytest.approx(a_z, rel=1e-5, abs=1e-9) and a_z < 0


def test_an_ambiguous_run_warns_and_exits_0_an_inconsistent_one_fails(tmp_path, capsys):
    phi = math.radians(60)
    for lift, status in ((1.3, 0), (0.0, 1)):
        path = tmp_path / f"painleve_{lift}.json"
        path.write_text(json.dumps(dumbbell(phi, 1.1 * critical_mu(phi), lifting_rate(phi, lift) if lift else 0.0)))
        args = argparse.Namespace(scene=[str(path)], samples=1, seed=0, kernel=False)
        assert checks.main(args) == status
        out = capsys.readouterr().out
        if status == 0:
            assert re.search(rf"^WARN  {re.escape(PAINLEVE)}", out, re.M)
            assert "all checks passed, 1 with a WARNING" in out and "FAIL" not in out
        else:
            assert re.search(rf"^FAIL  {re.escape(PAINLEVE)}", out, re.M) and "INCONSISTENT at t = 0 s" in out


def block(mu, velocity=(0.0, 0.0, 0.0), slope=0.0, push=(0.0, 0.0, 0.0)):
    """A block on a rough plane through the origin tilted by ``slope`` about the y axis (down the slope: +x)."""
    normal = [math.sin(slope), 0.0, math.cos(slope)]
    return ln.Scene.from_dict({
        "name": "block", "gravity": [0, 0, -G],
        "masses": [{"name": "block", "position": [0.0, 0.0, 0.0], "mass": 1.5, "velocity": list(velocity),
                    "force": list(push)}],
        "links": [], "ground": {"point": [0, 0, 0], "normal": normal, "restitution": 0.0, "friction": mu}})


@pytest.mark.parametrize("mu", [0.2, 1.5])
def test_a_sliding_block_has_one_solution(mu):
    line = painleve_line(block(mu, velocity=(1.0, 0.5, 0.0), push=(3.0, -1.0, 0.0)))
    assert line.passed and not line.warning and not line.skipped
    assert "1 with one solution, 0 with several (ambiguous), 0 with none" in line.detail


@pytest.mark.parametrize("mu, slips", [(0.4, True), (0.6, False)])
def test_a_block_at_rest_on_a_slope_sticks_or_slips_down_it_as_tan_alpha_against_mu(mu, slips):
    alpha = math.atan(0.5)  # tan(alpha) = 0.5
    scene = block(mu, slope=alpha)
    line = painleve_line(scene)
    assert line.passed and not line.warning and "1 with one solution" in line.detail
    # the one mode that holds, against m a = m g sin(alpha) - mu m g cos(alpha) down the slope, or rest
    from linknet_core.dynamics.unilateral import UnilateralDynamics
    uni = UnilateralDynamics(scene)
    X, U = np.array(scene.X0, float), np.array(scene.U0, float)
    modes = checks._painleve_modes(scene, uni, X, U, np.array(scene.mass)[:, None] * np.array(scene.gravity),
                                   None, np.array([0]), ["the ground contact"], (1.5 * G, math.sqrt(G), G))
    holding = [(words, a) for words, a, value, _ in modes if value <= checks.RTOL_COMPLEMENTARITY]
    assert len(holding) == 1
    words, a = holding[0]
    down = np.array([math.cos(alpha), 0.0, -math.sin(alpha)])
    if slips:
        assert words.startswith("the ground contact slipping from rest along")
        expected = G * (math.sin(alpha) - mu * math.cos(alpha)) * down
    else:
        assert words == "the ground contact stuck"
        expected = np.zeros(3)
    np.testing.assert_allclose(a[0], expected, atol=1e-12 * G)


def test_more_modes_than_the_limit_are_not_enumerated_and_the_line_says_why(monkeypatch):
    monkeypatch.setattr(checks, "COULOMB_MODES_MAX", 1)
    phi = math.radians(60)
    line = painleve_line(ln.Scene.from_dict(dumbbell(phi, 1.1 * critical_mu(phi), 0.0)))
    assert line.skipped and line.passed
    assert "1 state(s) not enumerated: more Coulomb modes than COULOMB_MODES_MAX = 1 (2 of 1 touching" in line.detail
