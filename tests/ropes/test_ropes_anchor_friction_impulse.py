"""Jreact where a friction impulse acts in the impact: an input-driven anchor whose velocity jumps at t = 0 drives,
through rods, a block resting on a rough ground (Coulomb's friction mu, no restitution). The impact is solved here
from Newton's laws alone, planar in x-z, and the anchor's impulse (Simulator.anchor_report()["impulse"], numpy and
native) must be minus the rod's impulse on the mass it holds, the ground's friction impulse counted as the ground's:

* slide: the anchor at P holds a block at the origin on a rod along E = (X - P) / R pointing into the ground; its
  velocity jumps to V with E . V > 0, so the rod pushes the block along and into the ground. After the impact the
  block's normal velocity is 0 and the rod's rate E . (v - V) is 0, so v = (E . V / E_x) x; it slides (v_x > 0),
  m v = Lambda E + P_n n - mu P_n x, whence P_n = -Lambda E_z and Lambda = m v_x / (E_x + mu E_z);
* stick: the anchor holds a mass A in the air, and A holds the block B on the ground by a second rod; the block
  stays (v_B = 0), m_A v_A = Lambda_1 E_1 - Lambda_2 E_2, 0 = Lambda_2 E_2 + P_n n + P_t x, E_1 . (v_A - V) = 0,
  E_2 . v_A = 0: six linear equations in (v_A, Lambda_1, Lambda_2, P_n, P_t), with |P_t| <= mu P_n checked.

The minimum-norm impulse of the whole velocity change over the links and the contact's normal (the friction taken
as the links') gives -m v_x / E_x E in the slide, 30% short of the closed form at mu = 0.4."""
import numpy as np
import pytest

import linknet_core as ln

G = 9.81
X_HOOK = np.array([-0.8, 0.0, 0.6])


def _jump(scene, V, backend):
    sim = ln.Simulator(ln.Scene.from_dict(scene), error_estimate=False, method="dop853", rtol=1e-10,
                       backend=backend)
    sim.advance(1e-6, anchors=(X_HOOK[None], np.asarray(V, float)[None], np.zeros((1, 3))))
    return sim


def _ground(mu):
    return {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": mu}


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_a_rod_pushing_a_block_to_slide_takes_the_friction_out_of_the_anchors_impulse(backend):
    m, mu, V = 0.7, 0.4, np.array([1.5, 0.0, -0.45])
    R = float(np.linalg.norm(X_HOOK))
    scene = {"name": "slide", "gravity": [0, 0, -G],
             "masses": [{"name": "hook", "position": X_HOOK.tolist(), "driven": True, "motion": {"kind": "input"}},
                        {"name": "block", "position": [0, 0, 0], "mass": m}],
             "links": [{"a": "hook", "b": "block", "length": R}], "ground": _ground(mu)}
    E = -X_HOOK / R  # from the hook to the block
    v_x = E @ V / E[0]
    assert v_x > 0.0 and E[0] + mu * E[2] > 0.0  # it slides along +x; no jam
    lam = m * v_x / (E[0] + mu * E[2])
    assert -lam * E[2] > 0.0  # the ground pushes: P_n > 0
    sim = _jump(scene, V, backend)
    J = sim.anchor_report()["impulse"][0]
    assert np.abs(J - (-lam * E)).max() <= 1e-12 * m * v_x
    # the block slides as solved (1e-6 s after, its acceleration well under 100 m/s^2 changing it less than 1e-4)
    assert np.abs(sim.state.U[1] - [v_x, 0.0, 0.0]).max() <= 1e-4 * v_x


@pytest.mark.parametrize("backend", ["numpy", "native"])
def test_a_rod_chain_holding_a_stuck_block_gives_the_anchor_its_links_impulse_alone(backend):
    mA, mB, mu, V = 0.5, 0.9, 2.0, np.array([0.8, 0.0, 0.5])
    XA, XB = np.array([0.0, 0.0, 0.9]), np.array([0.5, 0.0, 0.0])
    R1, R2 = float(np.linalg.norm(XA - X_HOOK)), float(np.linalg.norm(XB - XA))
    scene = {"name": "stick", "gravity": [0, 0, -G],
             "masses": [{"name": "hook", "position": X_HOOK.tolist(), "driven": True, "motion": {"kind": "input"}},
                        {"name": "a", "position": XA.tolist(), "mass": mA},
                        {"name": "block", "position": XB.tolist(), "mass": mB}],
             "links": [{"a": "hook", "b": "a", "length": R1}, {"a": "a", "b": "block", "length": R2}],
             "ground": _ground(mu)}
    E1, E2 = (XA - X_HOOK) / R1, (XB - XA) / R2
    # unknowns (v_Ax, v_Az, Lambda_1, Lambda_2, P_n, P_t), planar x-z
    A = np.array([[mA, 0, -E1[0], E2[0], 0, 0],
                  [0, mA, -E1[2], E2[2], 0, 0],
                  [0, 0, 0, E2[0], 0, 1],
                  [0, 0, 0, E2[2], 1, 0],
                  [E1[0], E1[2], 0, 0, 0, 0],
                  [E2[0], E2[2], 0, 0, 0, 0]], float)
    b = np.array([0, 0, 0, 0, E1 @ V, 0.0])
    vx, vz, lam1, lam2, P_n, P_t = np.linalg.solve(A, b)
    assert P_n > 0.0 and abs(P_t) < mu * P_n and abs(P_t) > 0.1 * P_n  # stuck, by a grip that takes an impulse
    sim = _jump(scene, V, backend)
    J = sim.anchor_report()["impulse"][0]
    assert np.abs(J - (-lam1 * E1)).max() <= 1e-12 * abs(lam1)
    assert np.abs(sim.state.U[2]).max() <= 1e-4 * np.linalg.norm(V)  # the block stays (1e-6 s after)
