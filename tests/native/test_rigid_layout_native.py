"""The rigid-body layout in C (ln_rigid_layout, engine_rigid.c; the native FMU builds its bodies with it when a
parameter changes) against the numpy reference (structure.bodies.body_geometry and fit_bodies): the same masses,
principal moments and top kinds, and body states that give back the masses' positions, velocities and angular
momentum. The body frames may differ by the signs of their axes (both are right-handed principal frames), so the
comparison is of what the layout means, not of its numbers."""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.clib import library as lib
from linknet_core.structure.bodies import body_geometry, fit_bodies, free_rigid_bodies, rotation_matrices

MODELS = Path(__file__).resolve().parents[2] / "models"
_layout = lib.lib.ln_rigid_layout
_layout.restype = ctypes.c_int
_layout.argtypes = [lib.ln_int, lib.c_double_p, lib.c_double_p, lib.c_double_p, ctypes.POINTER(lib.RigidModel),
                    lib.c_double_p, lib.c_double_p, lib.c_double_p, lib.ln_int_p, lib.c_double_p]


def tumbling(masses):
    """Two bodies: a tetrahedron with the given masses (asymmetric unless they are equal) and a triangle,
    spinning about skew axes."""
    X = np.array([[0, 0, 0], [1, 0, 0], [0.3, 0.9, 0], [0.4, 0.3, 0.8], [3, 0, 0], [4, 0.2, 0], [3.5, 1, 0.1]], float)
    links = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3), (4, 5), (5, 6), (4, 6)]
    U = np.cross([0.3, -1.0, 2.0], X - X[:4].mean(axis=0))
    U[4:] = np.cross([1.5, 0.2, -0.4], X[4:] - X[4:].mean(axis=0)) + [0.1, 0.0, 0.2]
    return ln.Scene.from_dict({
        "name": "tumbling", "gravity": [0, 0, 0],
        "masses": [{"name": f"m{k}", "mass": float(m), "position": X[k].tolist(), "velocity": U[k].tolist()}
                   for k, m in enumerate(list(masses) + [1.0, 2.0, 1.5])],
        "links": [{"a": f"m{a}", "b": f"m{b}"} for a, b in links]})


@pytest.mark.parametrize("scene", [ln.load_scene(MODELS / "spinning_tetrahedron.json"), tumbling([1, 2, 3, 4]),
                                   tumbling([1, 1, 1, 1])], ids=["spinning_tetrahedron", "asymmetric", "equal_masses"])
def test_the_c_layout_is_the_reference_layout(scene):
    bodies, why = free_rigid_bodies(scene, ln.Dynamics(scene))
    assert bodies is not None, why
    K, B = scene.K, bodies.count
    X, U, mass = (np.ascontiguousarray(a, np.float64) for a in (scene.X0, scene.U0, scene.mass))
    body_of = np.ascontiguousarray(bodies.body_of, np.int64)
    rigid = lib.RigidModel(B, lib.pointer(body_of, lib.ln_int))
    r, inertia, body_mass, Y = np.zeros((K, 3)), np.zeros((B, 3)), np.zeros(B), np.zeros((B, 13))
    kind = np.zeros(B, np.int64)
    assert _layout(K, lib.pointer(mass), lib.pointer(X), lib.pointer(U), ctypes.byref(rigid), lib.pointer(r),
                   lib.pointer(inertia), lib.pointer(body_mass), lib.pointer(kind, lib.ln_int), lib.pointer(Y)) == 0

    reference = body_geometry(scene, bodies, X)
    c, v, q, Pi = fit_bodies(scene, bodies, reference, X, U)
    scale = np.abs(reference.inertia).max()
    np.testing.assert_array_equal(kind, reference.kind)
    np.testing.assert_allclose(body_mass, reference.body_mass, rtol=1e-15)
    np.testing.assert_allclose(inertia, reference.inertia, rtol=0, atol=1e-14 * scale)
    np.testing.assert_allclose(Y[:, :3], c, rtol=0, atol=1e-14)
    np.testing.assert_allclose(Y[:, 3:6], v, rtol=0, atol=1e-14)
    R = rotation_matrices(Y[:, 6:10])
    inside = bodies.body_of >= 0
    idx = bodies.body_of[inside]
    # the masses sit at c + R r_k, and R Pi is the reference's angular momentum in space
    np.testing.assert_allclose(Y[idx, :3] + np.einsum("kij,kj->ki", R[idx], r[inside]), X[inside], rtol=0, atol=1e-14)
    np.testing.assert_allclose(np.einsum("bij,bj->bi", R, Y[:, 10:]),
                               np.einsum("bij,bj->bi", rotation_matrices(q), Pi), rtol=0, atol=1e-13 * scale)
    np.testing.assert_allclose(np.linalg.norm(r, axis=1), np.linalg.norm(reference.r, axis=1), rtol=0, atol=1e-14)
    assert np.abs(np.linalg.norm(Y[:, 6:10], axis=1) - 1.0).max() <= 4e-16
