"""`linknet analyze` on large scenes: the condition of A (25) estimated from a sparse factorisation above the dense
limit, checked against the exact 1-norm condition on scenes small enough for both, and the whole analysis of a
100,000-link chain (whose dense eigen-decomposition would need 80 GB and hours)."""
import numpy as np
import pytest

import linknet_core.simulator.analysis as analysis
from linknet_core.dynamics.equations import Dynamics
from linknet_core.scene.builders import chain, net, redundant_truss, tetrahedron, pendulum


@pytest.mark.parametrize("scene", [chain(400), net(12, 12), net(6, 9, anchors="edge")],
                         ids=lambda s: s.name)
def test_the_sparse_condition_estimate_equals_the_exact_1_norm_condition(scene, monkeypatch):
    A = Dynamics(scene).tension_matrix(scene.X0)
    exact_2, how_2 = analysis.condition_of_tension_matrix(A, 0)
    assert how_2 == "exact, 2-norm"
    assert exact_2 == pytest.approx(np.linalg.cond(A.toarray(), 2), rel=1e-9)
    monkeypatch.setattr(analysis, "DENSE_CONDITION_LIMIT", 0)
    estimate, how = analysis.condition_of_tension_matrix(A, 0)
    assert how.startswith("1-norm, estimated")
    # Hager-Higham is exact on these matrices (it may underestimate in general, never by more than a factor L)
    assert estimate == pytest.approx(np.linalg.cond(A.toarray(), 1), rel=1e-8)
    # the two norms' condition numbers differ by at most a factor L
    assert exact_2 / scene.L <= estimate <= exact_2 * scene.L


def test_a_singular_A_above_the_dense_limit_is_reported_singular_without_a_figure(monkeypatch):
    scene = redundant_truss()
    dyn = Dynamics(scene)
    assert dyn.structure.self_stresses > 0
    monkeypatch.setattr(analysis, "DENSE_CONDITION_LIMIT", 0)
    cond, how = analysis.condition_of_tension_matrix(dyn.tension_matrix(scene.X0), dyn.structure.self_stresses)
    assert cond == float("inf")
    assert f"{dyn.structure.self_stresses} zero eigenvalues" in how


@pytest.mark.parametrize("scene, motions", [
    (pendulum(), 2),                     # a bob about its pivot: two rotations move it
    (chain(5), 2),                       # a straight chain from one anchor: the spin about its own line moves nothing
    (net(4, 4), 1),                      # hung from two corners: the rotation about the line through them
    (net(4, 4, anchors="edge"), 1),      # a row of anchors on a line: the rotation about that line
    (net(4, 4, anchors="four_corners"), 0),
    (tetrahedron(), 6),                  # free: all six
], ids=["pendulum", "chain", "net_corners", "net_edge", "net_four_corners", "tetrahedron"])
def test_rigid_body_motions_counted_from_the_anchors(scene, motions):
    assert analysis._rigid_body_motions(scene) == motions


def test_analyze_a_100000_link_chain():
    scene = chain(100_000)
    report = analysis.analyze_scene(scene)
    assert report.rank_G == 100_000 and report.self_stresses == 0
    assert report.condition_note.startswith("1-norm, estimated")
    # a uniform horizontal chain from one anchor: A is tridiagonal with the rod's second-difference pattern, whose
    # condition grows like L^2; at 100,000 links it is of order 1e10
    assert 1e9 < report.condition_A < 1e12
    text = report.text()
    assert "K = 100001 masses, L = 100000 links" in text
