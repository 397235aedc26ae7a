"""The failure texts' numbers in C (src/explain.c) against the numpy reference: the fastest oscillation of a mass
between its tensioned links, omega_k^2 = sum |T_l| / (M_k R_l) (equations.fastest_oscillation), which the FMU
computes in C for its stability advice."""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics.equations import fastest_oscillation
from linknet_core.clib import library as lib
from linknet_core.native.model import NativeModel
from linknet_core.scene import builders
from linknet_core.structure.topology import analyse

MODELS = Path(__file__).resolve().parents[2] / "models"
_omega = lib.lib.ln_fastest_oscillation
_omega.restype, _omega.argtypes = ctypes.c_double, [lib.Model_p, lib.c_double_p]


@pytest.mark.parametrize("scene", [
    builders.chain(10, total_length=1.0, masses=np.geomspace(1e-6, 1e6, 11), shape="hanging"),
    ln.load_scene(MODELS / "crane.json"), ln.load_scene(MODELS / "redundant_truss.json"),
    ln.load_scene(MODELS / "net_10x10.json")], ids=["mass_ratio_chain", "crane", "redundant_truss", "net_10x10"])
def test_fastest_oscillation_in_c_is_the_reference(scene):
    model = NativeModel(scene, analyse(scene))
    rng = np.random.default_rng(7)
    tensions = [rng.normal(size=scene.L) * 10.0 ** rng.uniform(-3, 6, scene.L),  # either sign: |T| counts
                ln.Simulator(scene, method="rattle", dt=1e-3).integrator.tensions(scene.X0, scene.U0)]
    assert fastest_oscillation(scene, tensions[0]) > 0.0
    for T in tensions:
        T = np.ascontiguousarray(T, np.float64)
        expected = fastest_oscillation(scene, T)
        assert _omega(model.pointer, lib.pointer(T)) == pytest.approx(expected, rel=4e-16)
    # no oscillation where nothing pulls; none estimated from tensions that are not finite
    assert _omega(model.pointer, lib.pointer(np.zeros(scene.L))) == 0.0 == fastest_oscillation(scene, np.zeros(scene.L))
    T = np.full(scene.L, np.nan)
    assert _omega(model.pointer, lib.pointer(T)) == 0.0 == fastest_oscillation(scene, T)
