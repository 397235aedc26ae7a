"""The model's weights in C (ln_model_weights, model_weights.c; the native model and the native FMU build them with it)
against the numpy reference: 1/M, 1/R, the base forces of (9), the weights of A (25) pair by pair and, on a chain,
the tridiagonal A in path order, and the weights of a_k in B (26) (1 on a driven anchor)."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.dynamics.tensions import TensionAssembly
from linknet_core.native.model import NativeModel
from linknet_core.structure.topology import analyse

MODELS = Path(__file__).resolve().parents[2] / "models"


def uneven(scene):
    """The scene with masses 0.3 .. 2.9 on its free masses and gravity off the axes: no weight equals another."""
    mass = np.linspace(0.3, 2.9, scene.K)
    return scene.with_parameters(mass=mass, gravity=[0.4, -0.7, -9.3])


def model_arrays(model, name, n):
    return np.ctypeslib.as_array(getattr(model.struct, name), (n,)).copy()


@pytest.mark.parametrize("name", ["chain_10", "crane", "net_10x10", "redundant_truss"])
def test_weights_match_the_reference(name):
    scene = uneven(ln.load_scene(MODELS / f"{name}.json"))
    structure = analyse(scene)
    model = NativeModel(scene, structure)
    K, L = scene.K, scene.L
    np.testing.assert_array_equal(model_arrays(model, "inv_m", K), scene.inv_mass)
    np.testing.assert_array_equal(model_arrays(model, "inv_R", L), 1.0 / scene.length)
    zero = np.zeros((K, 3))
    F = ln.Dynamics(scene).forces(scene.X0, scene.U0, zero)  # no force elements in these scenes: gravity and F
    F[scene.fixed] = 0.0
    np.testing.assert_array_equal(model_arrays(model, "F_scene", 3 * K).reshape(K, 3), F)
    assembly = TensionAssembly(scene, structure.ordering)
    n_pairs = int(model.struct.n_pairs)
    np.testing.assert_array_equal(model_arrays(model, "pair_weight", n_pairs), assembly.pair_weight)
    accel = np.array(scene.inv_mass)
    accel[scene.driven_indices] = 1.0
    np.testing.assert_array_equal(model_arrays(model, "accel_weight", K), accel)
    if model.solver == "chain":
        # with every E_l the same unit vector, A of (25) holds the bare weights
        A = assembly.matrix(np.tile([0.0, 0.6, 0.8], (L, 1))).toarray()
        order = model_arrays(model, "chain_order", L)
        path = A[np.ix_(order, order)]
        np.testing.assert_allclose(model_arrays(model, "chain_diag_weight", L), np.diag(path), rtol=1e-15)
        np.testing.assert_allclose(model_arrays(model, "chain_off_weight", L)[1:], np.diag(path, -1), rtol=1e-15)
