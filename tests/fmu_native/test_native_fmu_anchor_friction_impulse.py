"""The native FMU's Jreact where a friction impulse acts in the impact: an input-driven anchor holds a block on a
rough ground by a rod pointing into it, and the master jerks the anchor's velocity to V at the first communication
point (P unchanged). The rod pushes the block along and into the ground and it slides; from Newton's laws at the
impact (the block's normal velocity 0 after it, the rod's rate E . (v - V) 0, m v = Lambda E + P_n n - mu P_n x):
v_x = E . V / E_x, Lambda = m v_x / (E_x + mu E_z), and the rod gives the anchor -Lambda E over the first step, the
friction impulse -mu P_n x being the ground's (tests/ropes/test_ropes_anchor_friction_impulse.py for the library)."""
from __future__ import annotations

import json

import numpy as np

from native_fmu_support import built
from test_native_fmu_ropes import Instance

M, MU, G = 0.7, 0.4, 9.81
X_HOOK = np.array([-0.8, 0.0, 0.6])
V = np.array([1.5, 0.0, -0.45])


def test_the_native_fmus_jreact_leaves_the_friction_impulse_to_the_ground(fmu_root, tmp_path_factory):
    R = float(np.linalg.norm(X_HOOK))
    scene = {"name": "rod_block_slide", "gravity": [0, 0, -G],
             "masses": [{"name": "hook", "position": X_HOOK.tolist(), "driven": True, "motion": {"kind": "input"}},
                        {"name": "block", "position": [0, 0, 0], "mass": M}],
             "links": [{"a": "hook", "b": "block", "length": R}],
             "ground": {"point": [0, 0, 0], "normal": [0, 0, 1], "friction": MU}}
    path = tmp_path_factory.mktemp("rod_block_slide") / "rod_block_slide.json"
    path.write_text(json.dumps(scene))
    fmu = built(fmu_root, path)
    instance = Instance(fmu)
    instance.initialize(integrator="dop853")
    names = [f"{q}[1,{i}]" for q in "PVA" for i in (1, 2, 3)]
    instance.slave.setReal([fmu.vr[n] for n in names], [*X_HOOK, *V, 0.0, 0.0, 0.0])
    instance.slave.doStep(0.0, 1e-4)
    J = np.array(instance.get([f"Jreact[1,{i}]" for i in (1, 2, 3)]))
    E = -X_HOOK / R  # from the hook to the block
    v_x = E @ V / E[0]
    assert v_x > 0.0 and E[0] + MU * E[2] > 0.0  # it slides along +x; no jam
    lam = M * v_x / (E[0] + MU * E[2])
    assert np.abs(J - (-lam * E)).max() <= 1e-12 * M * v_x
