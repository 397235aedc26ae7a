"""The two degenerate nets that stop (models/degenerate/) have no rigid-link motion with bounded tensions: checked
on the physics, the stiff-spring limit (benchmarks.degenerate_limit), not on linknet's rigid solver. Every link
becomes a spring of stiffness k at its length; a scene whose rigid model has an answer has stretches falling like
1/k and tensions k * stretch bounded as k grows. The rigid runs' stops must say where, in the scene's terms."""
import numpy as np
import pytest

import linknet_core as ln
from benchmarks.degenerate_limit import spring_version
from linknet_core.scene.builders import tilted_tower, triangulated_net_corners


def _stretch(scene, X):
    return np.linalg.norm(X[..., scene.k2, :] - X[..., scene.k1, :], axis=-1) / scene.length - 1.0


def test_the_tilted_towers_top_square_keeps_a_stretch_that_no_stiffness_removes():
    """The tower's top square (links 10, 12, 14, 16 and the diagonals 17, 18) is flat and braced; the motion of the
    storey below twists it. Compliant links take the twist with the sides stretched and the diagonals shortened by
    ~3.3e-8, the same at every k (a stretch set by the geometry), so its tensions grow like k; every other link's
    stretch falls like 1/k (measured 3.4e-7, 3.9e-8, 1.7e-9 at k = 1e8, 1e9, 1e10; top square 3.1-3.5e-8 at each)."""
    scene = tilted_tower()
    top = np.array([10, 12, 14, 16, 17, 18]) - 1
    rest = np.setdiff1d(np.arange(scene.L), top)
    stretch = {k: _stretch(scene, ln.simulate(spring_version(scene, k), 0.3, method="dop853", rtol=1e-11, n_out=4,
                                              error_estimate=False).X[-1]) for k in (1e8, 1e9, 1e10)}
    for k in (1e8, 1e9):
        assert np.abs(stretch[10 * k][rest]).max() < 0.3 * np.abs(stretch[k][rest]).max()  # ~1/k: bounded
    sides, diagonals = stretch[1e10][top[:4]], stretch[1e10][top[4:]]
    assert np.all(sides > 2e-8) and np.all(diagonals < -2e-8)  # the flat square's self-stress pattern
    for k in (1e8, 1e9):
        assert np.allclose(stretch[k][top], stretch[1e10][top], rtol=0.2)  # not falling: tension ~ k


def test_the_corner_hung_nets_string_needs_a_tension_that_grows_with_the_stiffness():
    """The corner-hung triangulated net's diagonal (links 3, 16, 29) is a straight string between its anchors with
    the halves' weight across it. With springs, its peak tension over 0.1 s grows without bound as k grows (measured
    538 N at k = 1e8, 2263 N at 1e10: ~k^0.3, the sag-stretch law of a string loaded across)."""
    scene = triangulated_net_corners()
    string = np.array([3, 16, 29]) - 1
    peak = {}
    for k in (1e8, 1e10):
        X = ln.simulate(spring_version(scene, k), 0.1, method="dop853", rtol=1e-11, n_out=101,
                        error_estimate=False).X
        peak[k] = float((k * _stretch(scene, X)[:, string] * scene.length[string]).max())
    assert peak[1e10] > 2.5 * peak[1e8], peak


def test_the_rigid_towers_stop_names_its_top_square():
    """The rigid tower stops at ~0.2 s with every method; the message names the nearly flat top square whose twist
    the links hold at second order only, not the 18 links a near-self-stress touches."""
    with pytest.raises(ln.SolverError) as failure:
        ln.simulate(tilted_tower(), 0.3, n_out=4, error_estimate=False)
    text = str(failure.value)
    assert "doubly braced panel of masses s2_0, s2_1, s2_2 and s2_3 (links 10, 12, 14, 16, 17 and 18)" in text, text
    assert "nearly flat" in text and "twist" in text, text
