"""What the animation and the stills draw: frames, size, the colour of each link against its tension,
anchored masses, the chosen view, the time stamp and the colour bar."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from picture_probes import CRAFTED_LIMIT, pixel_of, render, tension_rgb
from linknet_core import visual
from linknet_core.errors import LinknetError


def midpoint(motion, i, link):
    return 0.5 * (motion.X[i, motion.k1[link]] + motion.X[i, motion.k2[link]])


def test_rendered_link_colours_are_their_tension_colours(crafted):
    picture = visual.NetworkFigure(crafted, "xz", size=(640, 480), tension_range=CRAFTED_LIMIT)
    for i in (0, 3):
        picture.show(i)
        image = render(picture)
        for link in range(crafted.L):
            row, column = pixel_of(picture, midpoint(crafted, i, link))
            expected = tension_rgb(crafted.T[i, link], CRAFTED_LIMIT)
            np.testing.assert_allclose(image[row, column, :3], expected, atol=2,
                                       err_msg=f"link {link + 1} at sample {i}, T = {crafted.T[i, link]} N")


def test_tension_is_red_and_compression_blue(crafted):
    picture = visual.NetworkFigure(crafted, "xz", size=(640, 480), tension_range=CRAFTED_LIMIT)
    picture.show(1)
    image = render(picture).astype(int)
    pulling = image[pixel_of(picture, midpoint(crafted, 1, 0))]
    pushing = image[pixel_of(picture, midpoint(crafted, 1, 1))]
    assert pulling[0] > pulling[2] + 100 and pushing[2] > pushing[0] + 100


def test_links_are_one_collection_whose_colours_follow_the_tensions(net_npz):
    motion = visual.Motion.from_npz(net_npz)
    picture = visual.NetworkFigure(motion, "3d")
    assert picture.view == "3d"
    i = len(motion.t) // 2
    picture.show(i)
    render(picture)
    collections = [c for c in picture.ax.collections if len(c.get_segments()) == motion.L]
    assert collections == [picture.links]
    limit = motion.tension_limit()
    expected = np.array([tension_rgb(T, limit) for T in np.clip(motion.T[i], -limit, limit)]) / 255
    np.testing.assert_allclose(picture.links.get_colors()[:, :3], expected, atol=1 / 255)


def test_masses_are_drawn_where_they_are_in_3d(net_npz):
    motion = visual.Motion.from_npz(net_npz)
    picture = visual.NetworkFigure(motion, "3d")
    i = len(motion.t) - 1
    picture.show(i)
    image = render(picture).astype(int)
    for k in range(motion.K):
        row, column = pixel_of(picture, motion.X[i, k])
        patch = image[row - 1:row + 2, column - 1:column + 2, :3]
        assert patch.max(axis=2).min() < 90, f"mass {k + 1} is not drawn at its projected pixel"


def test_anchored_masses_are_marked(crafted):
    picture = visual.NetworkFigure(crafted, "xz", size=(640, 480), tension_range=CRAFTED_LIMIT)
    picture.show(0)
    image = render(picture).astype(int)
    anchor = image[pixel_of(picture, crafted.X[0, 0])][:3]
    free = image[pixel_of(picture, crafted.X[0, 1])][:3]
    assert anchor.max() < 10 and 25 < free.min() and free.max() < 60  # black square, dark grey dot
    assert picture.anchor_marks.get_marker() == "s" and len(picture.anchor_marks.get_xdata()) == 1
    assert [t.get_text() for t in picture.fig.legends[0].get_texts()] == ["mass", "anchored mass"]


def test_time_stamp_and_centred_colour_bar(crafted):
    picture = visual.NetworkFigure(crafted, "xz", tension_range=CRAFTED_LIMIT)
    picture.show(2)
    assert picture.stamp.get_text() == "t = 0.2 s\nT from -5 to 7 N"
    colour_bar = picture.links.colorbar
    assert (colour_bar.vmin, colour_bar.vmax) == (-CRAFTED_LIMIT, CRAFTED_LIMIT)
    assert "tension" in colour_bar.ax.get_ylabel()
    assert colour_bar.extend == "neither"  # the crafted tensions stay within +-10 N


def two_masses(n):
    """One link from an anchor along x, n samples over 2 s, T = 1 N."""
    X = np.zeros((n, 2, 3))
    X[:, 1, 0] = 1.0
    return visual.Motion(title="link", t=np.linspace(0.0, 2.0, n), X=X, T=np.ones((n, 1)), k1=np.array([0]),
                         k2=np.array([1]), fixed=np.array([True, False]), mass_names=("a", "b"))


def test_default_colour_range_lets_a_spike_saturate():
    motion = two_masses(201)
    motion.T[100] = 1000.0  # one sample's jerk
    assert motion.tension_limit() == 1.0
    assert visual.NetworkFigure(motion, "xz").links.colorbar.extend == "both"


def test_auto_view_is_the_plane_of_the_motion(crafted, chain_npz, net_npz):
    assert crafted.resolve_view("auto") == "xz"
    assert visual.Motion.from_npz(chain_npz).resolve_view("auto") == "xz"
    assert visual.Motion.from_npz(net_npz).resolve_view("auto") == "3d"
    in_xy = visual.Motion(**{**crafted.__dict__, "X": crafted.X[:, :, [0, 2, 1]]})
    assert in_xy.resolve_view("auto") == "xy"


def test_frames_are_thinned_evenly_and_keep_both_ends():
    motion = two_masses(201)
    real_time = motion.frame_indices(max_frames=1000, fps=25, speed=1.0)
    assert len(real_time) == 51 and real_time[0] == 0 and real_time[-1] == 200
    assert np.ptp(np.diff(real_time)) == 0
    assert len(motion.frame_indices(max_frames=10, fps=25, speed=1.0)) == 10
    assert len(motion.frame_indices(max_frames=1000, fps=25, speed=0.25)) == 201  # every sample, never more


def test_gif_has_the_frames_and_size_asked_for(chain_npz, tmp_path):
    motion = visual.Motion.from_npz(chain_npz)
    written = visual.write_animation(motion, tmp_path / "chain.gif", max_frames=12, size=(320, 240), fps=20)
    with Image.open(written.path) as gif:
        assert (gif.n_frames, gif.size) == (12, (320, 240))
        assert gif.info["duration"] == 50  # ms, 20 fps
    assert written.frames == 12 and written.samples == 41 and written.seconds > 0


def test_gif_frames_show_each_links_tension_colour(crafted, tmp_path):
    written = visual.write_animation(crafted, tmp_path / "crafted.gif", view="xz", size=(640, 480),
                                     tension_range=CRAFTED_LIMIT)
    picture = visual.NetworkFigure(crafted, "xz", size=(640, 480), tension_range=CRAFTED_LIMIT)
    with Image.open(written.path) as gif:
        assert gif.n_frames == len(crafted.t)
        for i in (0, 4):
            gif.seek(i)
            frame = np.asarray(gif.convert("RGB")).astype(int)
            picture.show(i)
            render(picture)
            for link in range(crafted.L):
                expected = tension_rgb(crafted.T[i, link], CRAFTED_LIMIT)
                np.testing.assert_allclose(frame[pixel_of(picture, midpoint(crafted, i, link))], expected, atol=8,
                                           err_msg=f"link {link + 1} in GIF frame {i}")


def test_still_png_is_the_frame_at_the_time_asked_for(crafted, tmp_path):
    written = visual.write_still(crafted, tmp_path / "still.png", at=0.31, size=(640, 480),
                                 tension_range=CRAFTED_LIMIT)
    picture = visual.NetworkFigure(crafted, "xz", size=(640, 480), tension_range=CRAFTED_LIMIT)
    picture.show(3)  # t = 0.3 s is the sample nearest to 0.31 s
    with Image.open(written.path) as png:
        assert png.size == (640, 480)
        np.testing.assert_array_equal(np.asarray(png.convert("RGBA")), render(picture))


def test_mp4_has_the_frames_and_size_asked_for(chain_npz, tmp_path):
    import shutil
    import subprocess

    if not (shutil.which("ffmpeg") and shutil.which("ffprobe")):
        pytest.skip("ffmpeg is not installed (Debian: apt-get install ffmpeg); the MP4 writer needs it")
    written = visual.write_animation(visual.Motion.from_npz(chain_npz), tmp_path / "chain.mp4", max_frames=9,
                                     size=(320, 240))
    probe = subprocess.run(["ffprobe", "-v", "error", "-count_frames", "-select_streams", "v:0", "-show_entries",
                            "stream=nb_read_frames,width,height,codec_name", "-of", "csv=p=0", str(written.path)],
                           capture_output=True, text=True, check=True)
    assert probe.stdout.strip() == "h264,320,240,9"


def test_mp4_without_ffmpeg_is_refused_naming_it(chain_npz, tmp_path, monkeypatch):
    from matplotlib import animation

    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    with pytest.raises(LinknetError, match="needs ffmpeg"):
        visual.write_animation(visual.Motion.from_npz(chain_npz), tmp_path / "chain.mp4")
    assert not (tmp_path / "chain.mp4").exists()


def test_a_large_net_draws_its_links_as_one_collection(tmp_path):
    """A 100 x 100 net (19800 links): one LineCollection, and an HTML view thinned to its frame budget."""
    import linknet_core as ln

    scene = ln.builders.net(100, 100)
    X = np.stack([scene.X0, scene.X0 - [0.0, 0.0, 0.1]])
    motion = visual.Motion.from_arrays(scene, [0.0, 0.1], X, np.ones((2, scene.L)))
    written = visual.write_animation(motion, tmp_path / "net.gif", size=(200, 150))
    with Image.open(written.path) as gif:
        assert gif.n_frames == 2
    picture = visual.NetworkFigure(motion, "3d")
    picture.show(1)
    render(picture)
    assert [len(c.get_segments()) for c in picture.ax.collections] == [scene.L] == [19800]
    assert 2 <= visual.html_default_max_frames(motion) < visual.HTML_MAX_FRAMES
