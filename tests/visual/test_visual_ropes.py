"""Ropes and a ground in the pictures: a rope is drawn dashed at the samples where the run says it is slack and
solid where it is taut (the matplotlib collection's per-link line styles, the HTML view's second, dashed trace),
and the ground is drawn where it is: its trace in a flat view whose plane holds its normal (a note otherwise), a
translucent patch of the plane within the 3-D view's box. Slack flags and the ground come from a Result and from
an .npz."""
from __future__ import annotations

import numpy as np
import pytest

import linknet_core as ln
from linknet_core import visual

G = 9.81


def dashed(style) -> bool:
    """Whether a matplotlib line style (offset, on-off pattern) has gaps."""
    return style[1] is not None and len(style[1]) > 0


@pytest.fixture(scope="module")
def pendulum_run():
    """A bob on a 1 m rope thrown up and out from below its pivot (slack: it flies), jerking the rope taut, over a
    tilted ground it never reaches: slack and taut samples, in the xz plane."""
    scene = ln.Scene.from_dict({
        "name": "thrown_bob", "gravity": [0, 0, -G],
        "masses": [{"name": "pivot", "position": [0, 0, 0], "fixed": True},
                   {"name": "bob", "position": [0.3, 0, -0.4], "mass": 1.0, "velocity": [1.5, 0, 3.0]}],
        "links": [{"a": "pivot", "b": "bob", "length": 1.0, "kind": "rope"}],
        "ground": {"point": [0, 0, -1.5], "normal": [0.6, 0, 0.8]}})
    return ln.simulate(scene, 1.2, "dop853", rtol=1e-9, n_out=49, error_estimate=False, progress=False)


def slack_and_taut_samples(run):
    # the rope's own state, from the distance of its ends (not from the run's flags): slack where shorter than 1 m
    d = np.linalg.norm(run.X[:, 1] - run.X[:, 0], axis=1)
    return int(np.flatnonzero(d < 1.0 - 1e-3)[0]), int(np.flatnonzero(np.abs(d - 1.0) < 1e-9)[-1])


def test_a_slack_rope_is_dashed_and_a_taut_one_solid_in_the_flat_and_3d_views(pendulum_run):
    motion = visual.Motion.from_result(pendulum_run)
    slack_i, taut_i = slack_and_taut_samples(pendulum_run)
    for view in ("xz", "3d"):
        picture = visual.NetworkFigure(motion, view)
        picture.show(slack_i)
        assert dashed(picture.links.get_linestyles()[0])
        picture.show(taut_i)
        assert not dashed(picture.links.get_linestyles()[0])
        picture.show(slack_i)  # and back: the style follows the frame
        assert dashed(picture.links.get_linestyles()[0])


def test_the_ground_is_drawn_as_its_trace_in_a_view_holding_its_normal_and_noted_otherwise(pendulum_run):
    motion = visual.Motion.from_result(pendulum_run)
    picture = visual.NetworkFigure(motion, "xz")
    x, z = picture.ground_artist.get_data()
    # both ends on the plane 0.6 x + 0.8 (z + 1.5) = 0, and on the edge of the axes' box
    assert np.allclose(0.6 * x + 0.8 * (z + 1.5), 0.0, atol=1e-12)
    (x0, x1), (z0, z1) = picture.ax.get_xlim(), picture.ax.get_ylim()
    on_edge = np.isclose(x, x0) | np.isclose(x, x1) | np.isclose(z, z0) | np.isclose(z, z1)
    assert on_edge.all() and x.min() >= x0 - 1e-12 and x.max() <= x1 + 1e-12
    assert picture.ground_note == ""
    seen_from_above = visual.NetworkFigure(motion, "xy")
    assert seen_from_above.ground_artist is None
    assert "not drawn: the xy view does not hold its normal" in seen_from_above.ground_note


def test_the_ground_patch_in_3d_is_the_plane_within_the_box(pendulum_run):
    motion = visual.Motion.from_result(pendulum_run)
    picture = visual.NetworkFigure(motion, "3d")
    low = np.array([picture.ax.get_xlim()[0], picture.ax.get_ylim()[0], picture.ax.get_zlim()[0]])
    high = np.array([picture.ax.get_xlim()[1], picture.ax.get_ylim()[1], picture.ax.get_zlim()[1]])
    polygon = picture.ground_corners
    assert picture.ground_artist.get_alpha() == visual.GROUND_ALPHA
    # the plane's normal has no y part: its section of the axes' box is a rectangle spanning y, its corners on the
    # plane and on the box's x or z faces
    assert polygon.shape == (4, 3)
    assert np.allclose(polygon @ np.array([0.6, 0, 0.8]), 0.8 * -1.5, atol=1e-12)
    assert np.all(polygon >= low - 1e-12) and np.all(polygon <= high + 1e-12)
    assert sorted(np.round(polygon[:, 1], 12)) == sorted(np.round([low[1], low[1], high[1], high[1]], 12))
    on_xz_faces = np.isclose(polygon[:, [0, 2]], low[[0, 2]]) | np.isclose(polygon[:, [0, 2]], high[[0, 2]])
    assert on_xz_faces.any(axis=1).all()
    # consecutive corners share a face of the box: the polygon is drawn in order around it, not crossed
    for a, b in zip(polygon, np.roll(polygon, -1, axis=0)):
        assert (np.isclose(a, low) & np.isclose(b, low) | np.isclose(a, high) & np.isclose(b, high)).any()


def test_a_ground_outside_the_frame_is_not_drawn():
    low, high = np.zeros(3), np.ones(3)
    assert visual.ground_polygon(np.array([0, 0, -5.0]), np.array([0, 0, 1.0]), low, high) is None
    assert visual.ground_trace(np.array([0, 0, -5.0]), np.array([0, 0, 1.0]), low, high, 0, 2).endswith(
        "outside the frame")
    # a plane through a corner diagonal: a hexagon through the cube's centre
    hexagon = visual.ground_polygon(np.full(3, 0.5), np.ones(3) / np.sqrt(3), low, high)
    assert hexagon.shape == (6, 3) and np.allclose(hexagon.sum(axis=1), 1.5)


def test_the_html_view_draws_the_slack_ropes_as_a_second_dashed_trace(pendulum_run):
    motion = visual.Motion.from_result(pendulum_run)
    figure, frames = visual.build_html_figure(motion, view="xz", max_frames=len(motion.t))
    names = [trace.name for trace in figure.data]
    assert names == ["links", "masses", "anchored masses", "ground", "slack ropes"]
    assert figure.data[4].line.dash == "dash" and figure.data[3].type == "mesh3d"
    slack_i, taut_i = slack_and_taut_samples(pendulum_run)
    by_sample = {int(i): frame for i, frame in zip(frames, figure.frames)}
    for i, rope_slack in ((slack_i, True), (taut_i, False)):
        frame = by_sample[i]
        assert list(frame.traces) == [0, 1, 4]
        taut_trace, slack_trace = frame.data[0], frame.data[2]
        assert np.isfinite(np.asarray(slack_trace.x, float)[:2]).all() == rope_slack
        assert np.isfinite(np.asarray(taut_trace.x, float)[:2]).all() == (not rope_slack)


def test_slack_and_ground_are_read_from_an_npz(pendulum_run, tmp_path):
    path = tmp_path / "bob.npz"
    pendulum_run.save_npz(path)  # what `linknet simulate --out` writes: the slack flags and the ground
    motion = visual.Motion.from_npz(path)
    assert np.array_equal(motion.slack, pendulum_run.slack)
    point, normal = motion.ground
    assert np.allclose(normal, [0.6, 0, 0.8]) and np.allclose(point, [0, 0, -1.5])


def test_slack_flags_of_the_wrong_shape_are_refused(pendulum_run):
    motion = visual.Motion.from_result(pendulum_run)
    with pytest.raises(ln.LinknetError, match=r"slack flags of shape \(3,\), expected \(n, L\)"):
        visual.Motion(title="bob", t=motion.t, X=motion.X, T=motion.T, k1=motion.k1, k2=motion.k2,
                      fixed=motion.fixed, mass_names=motion.mass_names, slack=np.zeros(3, bool))
