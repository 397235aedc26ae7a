"""Pictures of a run's motion: an animation (GIF or MP4, matplotlib), a still (PNG) and an interactive
3-D view (one self-contained HTML file, plotly).

Every picture draws the network itself: masses as points, anchored masses marked, links as segments
coloured by their tension T on a diverging colour scale centred on T = 0 (T > 0 tension, red; T < 0
compression, blue), with a time stamp and a colour bar. Ropes that are slack at a sample are drawn dashed, and a
ground plane is drawn (its trace in a flat view whose plane holds its normal, a translucent patch in 3-D). Links
are one collection (one LineCollection, one plotly trace; two where ropes are slack), so a 100 x 100 net draws as
fast as the renderer can fill its 19800 segments.

Used by ``linknet animate``, ``linknet view``, ``linknet simulate --animate`` and the demo. matplotlib
and plotly are imported only when a picture is drawn, so the CLI starts fast.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
import zipfile
import zlib
from dataclasses import dataclass
from typing import Callable
from pathlib import Path

import numpy as np

from linknet_core.errors import LinknetError
from linknet_core.output import atomic_write
from linknet_core.options import (_output, count, finite_number, positive_number, readable_file, validated,
                                  writable_path_problem)

VIEWS = ("auto", "xz", "xy", "yz", "3d")
PLANES = {"xz": (0, 2), "xy": (0, 1), "yz": (1, 2)}  # the two coordinates a flat view shows
AXIS_NAMES = "xyz"
DEFAULT_CMAP = "coolwarm"  # diverging, perceptually balanced; its T = 0 grey stays visible on white
DENSE_MASSES = 300  # more masses are not drawn by default: their markers would bury the links (_shows_free_masses)
TENSION_PERCENTILE = 95.0  # of |T| over a run: the default half range of the colour scale (Motion.tension_limit)
DEFAULT_SIZE = (800, 600)  # pixels of an animation or still
DPI = 100
DEFAULT_FPS = 25.0
DEFAULT_ELEV, DEFAULT_AZIM = 25.0, -60.0  # degrees: the 3d view's viewer, in matplotlib's convention
DEFAULT_MAX_FRAMES = 250  # ten seconds of animation at the default frame rate
GIF_MAX_FPS = 50.0  # GIF delays are whole centiseconds, and browsers slow anything under 2 cs to 10 cs
HTML_MAX_FRAMES = 100
HTML_VIEW_PX = 450  # width of the scene box on a 1000 px wide page at the default zoom (measured in Chromium)
ORTHOGRAPHIC_ZOOM = 2.5  # a flat view's network fills about the plot's width (measured in Chromium)
HTML_FRAME_BUDGET = 40e6  # bytes of frame data in an HTML view before frames are thinned by default
ANIMATION_SUFFIXES = (".gif", ".mp4")
STILL_SUFFIX = ".png"
# a frame box this many times the network's own size gets a note: the network is a dot in it
SCALE_NOTE_RATIO = 1e3
PROGRESS_EVERY = 5.0  # seconds between the progress lines of a long animation write
SLACK_DASHES = (0, (3.0, 2.0))  # a slack rope's line style (matplotlib's offset, on-off pattern in line widths)
GROUND_COLOUR = "#8c6d46"  # the ground's trace and patch: earth brown, apart from the tension scale's colours
GROUND_ALPHA = 0.25  # the 3-D ground patch's opacity: the masses below it stay visible
# a flat view holds the ground's normal (and draws its trace) when the normal's part along the dropped axis is below
# this; a ground further from the masses than GROUND_REACH times the frame's size is left outside the frame
EDGE_ON_TOL = 1e-9
GROUND_REACH = 2.0


@dataclass(frozen=True)
class Motion:
    """What a picture of a run needs: sample times, positions, tensions, the links and the anchors."""

    title: str
    t: np.ndarray  # (n,) s
    X: np.ndarray  # (n, K, 3) m
    T: np.ndarray  # (n, L) N
    k1: np.ndarray  # (L,) 0-based ends of each link
    k2: np.ndarray
    fixed: np.ndarray  # (K,) bool: anchored masses
    mass_names: tuple[str, ...]
    notes: tuple[str, ...] = ()  # what the reader had to assume, printed by the CLI
    slack: np.ndarray | None = None  # (n, L) bool: the ropes slack at each sample (drawn dashed); None: no ropes
    ground: tuple[np.ndarray, np.ndarray] | None = None  # (point, unit normal) of the ground plane, or None

    def __post_init__(self):
        n = self.t.shape[0] if self.t.ndim == 1 else -1
        K, L = len(self.mass_names), self.k1.shape[0]
        if n < 1 or self.X.shape != (n, K, 3) or self.T.shape != (n, L) or self.k2.shape != (L,) \
                or self.fixed.shape != (K,):
            raise LinknetError(f"{self.title}: inconsistent arrays: t {self.t.shape}, X {self.X.shape}, "
                               f"T {self.T.shape}, {K} mass names, k1 {self.k1.shape}, k2 {self.k2.shape}, "
                               f"fixed {self.fixed.shape} (expected t (n,), X (n, K, 3), T (n, L))")
        if L and (min(self.k1.min(), self.k2.min()) < 0 or max(self.k1.max(), self.k2.max()) >= K):
            raise LinknetError(f"{self.title}: a link end is not one of the {K} masses")
        if np.any(np.diff(self.t) <= 0):
            raise LinknetError(f"{self.title}: sample times are not increasing")
        if self.slack is not None and np.shape(self.slack) != (n, L):
            raise LinknetError(f"{self.title}: slack flags of shape {np.shape(self.slack)}, expected (n, L) = "
                               f"({n}, {L})")
        if self.ground is not None:
            point, normal = (np.asarray(v, float) for v in self.ground)
            if point.shape != (3,) or normal.shape != (3,) or not np.isfinite(np.r_[point, normal]).all() \
                    or not abs(float(np.linalg.norm(normal)) - 1.0) <= 1e-9:
                raise LinknetError(f"{self.title}: the ground is a point and a unit normal, finite 3-vectors (got "
                                   f"point {point.tolist()}, normal {normal.tolist()})")
        for name, values in (("positions X", self.X), ("tensions T", self.T)):
            bad = np.flatnonzero(~np.isfinite(values.reshape(n, -1)).all(axis=1))
            if bad.size:
                raise LinknetError(f"{self.title}: {name} are not finite at t = {self.t[bad[0]]:g} s "
                                   f"(sample {bad[0] + 1} of {n})")

    @property
    def K(self) -> int:
        return len(self.mass_names)

    @property
    def L(self) -> int:
        return self.k1.shape[0]

    @classmethod
    def from_arrays(cls, scene, t, X, T, title: str | None = None, slack=None) -> "Motion":
        """A run given as arrays (for example read back from an FMU) of ``scene``; ``slack`` (n, L) the ropes'
        slack flags (an FMU's slack[l] outputs), the ground from the scene."""
        ground = getattr(scene, "ground", None)
        return cls(title=title or scene.name, t=np.asarray(t, float), X=np.asarray(X, float),
                   T=np.asarray(T, float).reshape(len(t), scene.L), k1=np.asarray(scene.k1),
                   k2=np.asarray(scene.k2), fixed=np.asarray(scene.fixed, bool), mass_names=tuple(scene.mass_names),
                   slack=None if slack is None else np.asarray(slack, bool).reshape(len(t), scene.L),
                   ground=None if ground is None else (np.array(ground.point, float), np.array(ground.normal, float)))

    @classmethod
    def from_result(cls, res) -> "Motion":
        return cls.from_arrays(res.scene, res.t, res.X, res.T, title=f"{res.scene.name}, {res.method}",
                               slack=getattr(res, "slack", None))

    @classmethod
    def from_npz(cls, path) -> "Motion":
        """A run written by ``Result.save_npz`` (``linknet simulate --out``)."""
        path = Path(path)
        not_a_result = f"{path}: not a result file written by `linknet simulate --out`"
        try:
            data = np.load(path, allow_pickle=False)
        except FileNotFoundError:
            raise LinknetError(f"{path}: no such file") from None
        except ValueError:  # numpy found neither an .npz nor an .npy and refused to unpickle it
            raise LinknetError(f"{not_a_result} (not an .npz archive)") from None
        except OSError as exc:  # a directory, no permission
            raise LinknetError(f"{path}: {exc.strerror or exc}") from None
        except (EOFError, zipfile.BadZipFile) as exc:  # a damaged archive
            raise LinknetError(f"{not_a_result} ({exc})") from None
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise LinknetError(f"{not_a_result} (it holds one array, not an .npz archive)")
        try:
            with data:
                arrays = {key: data[key] for key in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:  # a damaged archive
            raise LinknetError(f"{not_a_result} ({exc})") from None
        missing = [key for key in ("t", "X", "T", "k1", "k2", "mass_names") if key not in arrays]
        if missing:
            raise LinknetError(f"{not_a_result}: it has no {', '.join(missing)} "
                               f"(it has: {', '.join(sorted(arrays)) or 'nothing'})")
        names = tuple(str(name) for name in np.atleast_1d(arrays["mass_names"]))
        notes = ()
        if "fixed" in arrays:
            fixed = arrays["fixed"].astype(bool)
        else:
            fixed = np.zeros(len(names), bool)
            notes = (f"{path.name} does not say which masses are anchored (written before linknet saved "
                     "'fixed'): anchored masses are drawn as free ones",)
        method = str(arrays["method"]) if "method" in arrays else ""
        slack = arrays["slack"].astype(bool) if "slack" in arrays else None
        ground = None
        if "ground_point" in arrays and "ground_normal" in arrays:
            ground = (arrays["ground_point"].astype(float), arrays["ground_normal"].astype(float))
        try:
            return cls(title=f"{path.stem}, {method}" if method else path.stem, t=arrays["t"].astype(float),
                       X=arrays["X"].astype(float), T=arrays["T"].astype(float), k1=arrays["k1"].astype(int) - 1,
                       k2=arrays["k2"].astype(int) - 1, fixed=fixed, mass_names=names, notes=notes, slack=slack,
                       ground=ground)
        except LinknetError as exc:  # the arrays do not fit together
            raise LinknetError(f"{path}: {exc}") from None
        except (TypeError, ValueError) as exc:  # arrays of the wrong kind
            raise LinknetError(f"{not_a_result} ({exc})") from None

    def tension_peak(self) -> float:
        """max |T| over the whole run."""
        return float(np.max(np.abs(self.T))) if self.T.size else 0.0

    def tension_limit(self) -> float:
        """The colour scale's default half range: the 95th percentile of |T| over all links and samples, so
        that a short spike (a whipping tip, a jerk) saturates instead of washing every other link out to the
        T = 0 colour; the largest |T| if that percentile is 0, and 1 N if no link ever carries a force."""
        if not self.T.size:
            return 1.0
        typical = float(np.percentile(np.abs(self.T), TENSION_PERCENTILE))
        return typical if typical > 0 else self.tension_peak() or 1.0

    def resolve_view(self, view: str) -> str:
        """``auto``: the coordinate plane the whole run stays in (xz for a motion in a vertical plane), else 3d."""
        if view != "auto":
            return view
        spread = np.ptp(self.X.reshape(-1, 3), axis=0)
        flat = spread <= 1e-9 * max(float(spread.max()), 1e-300)
        for dropped, plane in ((1, "xz"), (2, "xy"), (0, "yz")):
            if flat[dropped]:
                return plane
        return "3d"

    def frame_indices(self, max_frames: int, fps: float, speed: float) -> np.ndarray:
        """Samples to show, evenly spaced in time: as many as playing at ``speed`` x real time at ``fps``
        needs, at most ``max_frames`` and at most every sample (samples are shown, never interpolated)."""
        if len(self.t) == 1:
            return np.zeros(1, int)
        span = float(self.t[-1] - self.t[0])
        wanted = int(round(span / speed * fps)) + 1
        count = max(1, min(len(self.t), max_frames, wanted))
        targets = np.linspace(self.t[0], self.t[-1], count)
        right = np.clip(np.searchsorted(self.t, targets), 1, len(self.t) - 1)
        left = right - 1
        nearest = np.where(np.abs(self.t[left] - targets) <= np.abs(self.t[right] - targets), left, right)
        return np.unique(nearest)

    def scale_notes(self) -> tuple[str, ...]:
        """A note where the frames' box (bounds) is more than SCALE_NOTE_RATIO times the network's own size (the
        median over samples of its extent): a mass that ran away (1e300 m) makes every frame a dot."""
        extent = np.ptp(self.X, axis=1).max(axis=1)  # (n,) the network's size at each sample
        own = float(np.median(extent))
        low, high = self.X.reshape(-1, 3).min(axis=0), self.X.reshape(-1, 3).max(axis=0)
        box = float(np.max(high - low))
        if not box > SCALE_NOTE_RATIO * own:
            return ()
        centre = np.median(self.X, axis=1)  # (n, 3) a centre that one runaway mass does not drag along
        distance = np.abs(self.X - centre[:, None, :]).max(axis=2)  # the largest coordinate: no overflow at 1e300
        i, k = np.unravel_index(int(np.argmax(distance)), distance.shape)
        return (f"the frames span {box:.3g} m, {box / max(own, 1e-300):.3g} times the network's own size "
                f"({own:.3g} m): mass {k + 1} (\"{self.mass_names[k]}\") is {distance[i, k]:.3g} m from the others along an axis "
                f"at t = {self.t[i]:g} s, so the network is a dot in every frame",)

    def bounds(self, view: str) -> tuple[np.ndarray, np.ndarray]:
        """Lower and upper corner of a box holding every mass at every sample, with a margin, so that the
        axes stay still while the network moves. A ground within GROUND_REACH times the box's size is brought
        into it (the foot of the perpendicular from the box's centre), so that the masses land on a drawn plane."""
        low, high = self.X.reshape(-1, 3).min(axis=0), self.X.reshape(-1, 3).max(axis=0)
        shown = list(PLANES.get(view, (0, 1, 2)))
        if self.ground is not None:
            point, normal = self.ground
            centre = 0.5 * (low + high)
            foot = centre - float(normal @ (centre - point)) * normal
            if np.linalg.norm(foot - centre) <= GROUND_REACH * max(float(np.max(high[shown] - low[shown])), 1e-9):
                low, high = np.minimum(low, foot), np.maximum(high, foot)
        size = max(float(np.max(high[shown] - low[shown])), 1e-9)
        margin = 0.06 * size
        return low - margin, high + margin


@dataclass(frozen=True)
class Written:
    """What one output holds and how long it took to write (printed by the CLI and the demo)."""

    path: Path
    frames: int
    samples: int
    seconds: float
    detail: str

    def line(self) -> str:
        size = self.path.stat().st_size
        return (f"wrote {self.path}: {self.frames} frame{'s' if self.frames != 1 else ''} of {self.samples} "
                f"samples, {self.detail}, {size / 1e6:.2f} MB, in {self.seconds:.2f} s")


def tension_colours(cmap_name: str, limit: float):
    """The colour scale of every picture: ``cmap_name`` with 0 N at its centre and +-``limit`` at its ends
    (values beyond take the end colours)."""
    import matplotlib
    from matplotlib.colors import CenteredNorm

    try:
        cmap = matplotlib.colormaps[cmap_name]
    except KeyError:
        raise LinknetError(f"unknown colour map {cmap_name!r}; use a diverging one such as coolwarm, RdBu_r, "
                           "PuOr_r or bwr") from None
    return cmap, CenteredNorm(vcenter=0.0, halfrange=limit)


def _marker_size(count: int) -> float:
    """Mass marker diameter (points in the animation, pixels in the HTML view) for ``count`` masses."""
    return 7.0 if count <= 30 else 4.0 if count <= DENSE_MASSES else 2.0


def _shows_free_masses(motion: Motion) -> bool:
    """Up to DENSE_MASSES masses are drawn; more would bury the links' colours under their markers, and the links
    draw the network's shape anyway (the HTML view keeps them one legend click away)."""
    return motion.K <= DENSE_MASSES


def _line_width(count: int) -> float:
    """Link width (points) for ``count`` links: thick on a few, thin enough to keep a 100 x 100 net's cells apart."""
    return 3.0 if count <= 30 else 2.5 if count <= 300 else 1.8 if count <= 3000 else 0.8


def _time_format(times: np.ndarray) -> str:
    """Enough decimals to tell neighbouring frames apart."""
    steps = np.diff(times)
    step = float(steps.min()) if steps.size else 1.0
    return f"{{:.{int(min(9, max(1, math.ceil(-math.log10(step) - 1e-6))))}f}}"


class NetworkFigure:
    """The matplotlib picture of a motion. ``show(i)`` draws sample i: links as one LineCollection
    (Line3DCollection in the 3-D view) coloured by T, free and anchored masses as two marker sets, the time
    stamp with the range of T at that sample, the colour bar and a legend."""

    def __init__(self, motion: Motion, view: str = "auto", size=DEFAULT_SIZE, cmap: str = DEFAULT_CMAP,
                 tension_range: float | None = None, elev: float = DEFAULT_ELEV, azim: float = DEFAULT_AZIM,
                 frame_times=None):
        from matplotlib.collections import LineCollection
        from matplotlib.figure import Figure

        self.motion = motion
        self.view = motion.resolve_view(view)
        limit = tension_range or motion.tension_limit()
        colour_map, norm = tension_colours(cmap, limit)
        # pyplot-free figure: no global state and no GUI backend, in the CLI as in a notebook
        self.fig = Figure(figsize=(size[0] / DPI, size[1] / DPI), dpi=DPI, layout="constrained")
        low, high = motion.bounds(self.view)
        width, mass_size = _line_width(motion.L), _marker_size(motion.K)
        free, anchored = ~motion.fixed, motion.fixed
        if self.view == "3d":
            from mpl_toolkits.mplot3d.art3d import Line3DCollection

            ax = self.fig.add_subplot(projection="3d", computed_zorder=False)
            ax.set(xlim=(low[0], high[0]), ylim=(low[1], high[1]), zlim=(low[2], high[2]),
                   xlabel="x, m", ylabel="y, m")
            ax.set_zlabel("z, m", labelpad=12)  # clear of the z tick labels
            ax.set_box_aspect(high - low)  # equal scale on the three axes: the network keeps its shape
            ax.view_init(elev=elev, azim=azim)
            self.links = Line3DCollection(np.zeros((motion.L, 2, 3)), cmap=colour_map, norm=norm,
                                          linewidths=width, zorder=2)
        else:
            a, b = PLANES[self.view]
            ax = self.fig.add_subplot()
            ax.set(xlim=(low[a], high[a]), ylim=(low[b], high[b]),
                   xlabel=f"{AXIS_NAMES[a]}, m", ylabel=f"{AXIS_NAMES[b]}, m")
            ax.set_aspect("equal", adjustable="box")
            self.links = LineCollection(np.zeros((motion.L, 2, 2)), cmap=colour_map, norm=norm,
                                        linewidths=width, zorder=2, capstyle="round")
        ax.add_collection(self.links)
        self.ax = ax
        self.ground_artist, self.ground_note = self._draw_ground(low, high)
        nothing = ([], [], []) if self.view == "3d" else ([], [])
        (self.free_marks,) = ax.plot(*nothing, ls="none", marker="o", ms=mass_size, color="0.15", zorder=3,
                                     label="mass")
        self.free_marks.set_visible(_shows_free_masses(motion))
        (self.anchor_marks,) = ax.plot(*nothing, ls="none", marker="s", ms=max(1.6 * mass_size, 7.0), mfc="black",
                                       mec="white", mew=0.6, zorder=4, label="anchored mass")
        self._free, self._anchored = free, anchored
        ax.set_title(motion.title, loc="right", fontsize=10)
        extend = "neither" if limit >= motion.tension_peak() else "both"
        self.fig.colorbar(self.links, ax=ax, shrink=0.85, extend=extend, pad=0.1 if self.view == "3d" else 0.05,
                          label="link tension T, N   (> 0 pulls, < 0 pushes)")
        # time stamp and legend outside the axes, where they never cover the network
        self.stamp = ax.set_title("\n", loc="left", fontsize=9, family="monospace")
        handles = [marks for marks, shown in ((self.free_marks, _shows_free_masses(motion)),
                                              (self.anchor_marks, anchored.any())) if shown]
        if motion.slack is not None and motion.slack.any():
            from matplotlib.lines import Line2D

            handles.append(Line2D([], [], color="0.4", lw=1.5, ls=SLACK_DASHES, label="slack rope"))
        if self.ground_artist is not None:
            handles.append(self.ground_artist)
        if self.ground_note:
            (ax.text2D if self.view == "3d" else ax.text)(0.01, 0.01, self.ground_note, transform=ax.transAxes,
                                                          fontsize=7, color=GROUND_COLOUR)
        self.fig.legend(handles=handles, loc="outside lower center", fontsize=8, frameon=False, ncols=len(handles))
        # the time stamp's decimals tell the frames shown apart (frame_times; default every sample)
        self._time_format = _time_format(motion.t if frame_times is None else frame_times)
        # lay the figure out once (nothing that sizes it changes between frames), then keep that layout: the
        # constrained layout engine would otherwise measure every text again for each frame, half of its cost
        self.fig.draw_without_rendering()
        self.fig.set_layout_engine("none")

    def _draw_ground(self, low, high):
        """The ground of the motion, if any: in a flat view whose plane holds the ground's normal, its trace (a line
        across the axes' box); in 3-D a translucent patch, the plane within the box; otherwise nothing. Returns
        (the artist or None, a note for the picture or ""); ``ground_corners`` holds what it draws (the patch's
        corners, (m, 3), or the trace's ends in the view's coordinates, (2, 2))."""
        self.ground_corners = None
        if self.motion.ground is None:
            return None, ""
        point, normal = self.motion.ground
        where = f"ground: the plane through {np.round(point, 4).tolist()} with normal {np.round(normal, 4).tolist()}"
        if self.view == "3d":
            polygon = ground_polygon(point, normal, low, high)
            if polygon is None:
                return None, where + ", outside the frame"
            from mpl_toolkits.mplot3d.art3d import Poly3DCollection

            self.ground_corners = polygon
            patch = Poly3DCollection([polygon], facecolors=GROUND_COLOUR, edgecolors=GROUND_COLOUR, alpha=GROUND_ALPHA,
                                     linewidths=0.8, zorder=1, label="ground")
            self.ax.add_collection3d(patch)
            return patch, ""
        a, b = PLANES[self.view]
        trace = ground_trace(point, normal, low, high, a, b)
        if isinstance(trace, str):
            return None, f"{where}: {trace}"
        self.ground_corners = trace
        (line,) = self.ax.plot(trace[:, 0], trace[:, 1], color=GROUND_COLOUR, lw=2.0, zorder=1, label="ground")
        return line, ""

    def show(self, i: int) -> None:
        """Draw sample i of the motion."""
        motion = self.motion
        X, T = motion.X[i], motion.T[i]
        ends = np.stack([X[motion.k1], X[motion.k2]], axis=1)  # (L, 2, 3)
        if self.view == "3d":
            self.links.set_segments(ends)
            self.free_marks.set_data_3d(*X[self._free].T)
            self.anchor_marks.set_data_3d(*X[self._anchored].T)
        else:
            a, b = PLANES[self.view]
            self.links.set_segments(ends[:, :, [a, b]])
            self.free_marks.set_data(X[self._free, a], X[self._free, b])
            self.anchor_marks.set_data(X[self._anchored, a], X[self._anchored, b])
        self.links.set_array(T)
        if motion.slack is not None:
            self.links.set_linestyles([SLACK_DASHES if slack else "solid" for slack in motion.slack[i]])
        stamp = f"t = {self._time_format.format(motion.t[i])} s"
        if T.size:
            stamp += f"\nT from {T.min():.4g} to {T.max():.4g} N"
        self.stamp.set_text(stamp)


def ground_trace(point, normal, low, high, a: int, b: int):
    """The ground's trace in the flat view of coordinates (a, b) within the box [low, high]: (2, 2) the ends of the
    segment {x : n . (x - p) = 0} across the box's (a, b) rectangle, where the view's plane holds the normal (its part
    along the dropped axis within EDGE_ON_TOL); else, or where the trace misses the rectangle, why it is not drawn."""
    dropped = ({0, 1, 2} - {a, b}).pop()
    n2 = np.array([normal[a], normal[b]], float)
    if abs(float(normal[dropped])) > EDGE_ON_TOL or not np.linalg.norm(n2) > 0:
        return (f"not drawn: the {AXIS_NAMES[a]}{AXIS_NAMES[b]} view does not hold its normal (the plane is "
                "not seen edge-on)")
    n2 = n2 / np.linalg.norm(n2)
    base = np.array([point[a], point[b]], float)
    direction = np.array([-n2[1], n2[0]])
    # the parameters s where base + s direction is inside the rectangle (Liang-Barsky clipping)
    s_low, s_high = -np.inf, np.inf
    for j, (lo, hi) in enumerate(((low[a], high[a]), (low[b], high[b]))):
        if abs(direction[j]) <= 1e-15:
            if not lo <= base[j] <= hi:
                return "not drawn: it lies outside the frame"
            continue
        s1, s2 = sorted(((lo - base[j]) / direction[j], (hi - base[j]) / direction[j]))
        s_low, s_high = max(s_low, s1), min(s_high, s2)
    if not s_low < s_high:
        return "not drawn: it lies outside the frame"
    return np.array([base + s_low * direction, base + s_high * direction])


def ground_polygon(point, normal, low, high):
    """(m, 3) the corners, in order around it, of the ground plane n . (x - p) = 0 within the box [low, high]: where
    the plane crosses the box's 12 edges; None where it misses the box."""
    corners = np.array([[(low, high)[i][0], (low, high)[j][1], (low, high)[k][2]]
                        for i in (0, 1) for j in (0, 1) for k in (0, 1)], float)
    height = (corners - point) @ normal
    crossings = list(corners[height == 0.0])
    for u in range(8):
        for v in range(u + 1, 8):
            hu, hv = height[u], height[v]
            if bin(u ^ v).count("1") == 1 and ((hu < 0.0 < hv) or (hv < 0.0 < hu)):  # an edge the plane crosses
                crossings.append(corners[u] + hu / (hu - hv) * (corners[v] - corners[u]))
    if len(crossings) < 3:
        return None
    points = np.unique(np.round(np.array(crossings), 12), axis=0)
    if len(points) < 3:
        return None
    centre = points.mean(axis=0)
    t1 = points[0] - centre
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(normal, t1)
    angles = np.arctan2((points - centre) @ t2, (points - centre) @ t1)
    return points[np.argsort(angles)]


@validated("picture size WxH")
def parse_size(text: str) -> tuple[int, int]:
    """'800x600' -> (800, 600), for argparse (which prints the message as its one-line usage error)."""
    try:
        width, height = (int(part) for part in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"WIDTHxHEIGHT in pixels, like 800x600 (got {text!r})") from None
    if not (16 <= width <= 8000 and 16 <= height <= 8000):
        raise argparse.ArgumentTypeError(f"16 to 8000 pixels each way (got {text!r})")
    return width, height


def check_animation_path(path, fps: float = DEFAULT_FPS, size=DEFAULT_SIZE) -> str:
    """Refuse, before any work, an output an animation cannot be written to: returns its suffix."""
    suffix = Path(path).suffix.lower()
    if suffix not in ANIMATION_SUFFIXES + (STILL_SUFFIX,):
        raise LinknetError(f"{path}: an animation is written as .gif or .mp4 (a still frame as .png), "
                           f"not {suffix or 'a file without a suffix'}")
    if suffix == ".gif" and fps > GIF_MAX_FPS:
        raise LinknetError(f"{path}: a GIF plays at most {GIF_MAX_FPS:g} frames per second (its delays are whole "
                           f"centiseconds and browsers slow shorter ones down); use --fps {GIF_MAX_FPS:g} or less, "
                           "or --speed to slow the motion down")
    if suffix == ".mp4":
        from matplotlib import animation, rcParams

        if not animation.writers.is_available("ffmpeg"):
            raise LinknetError(f"{path}: writing MP4 needs ffmpeg, which was not found (matplotlib looks for "
                               f"{rcParams['animation.ffmpeg_path']!r}); install ffmpeg (Debian: apt-get install "
                               "ffmpeg) or write a .gif, which needs nothing more")
        if size[0] % 2 or size[1] % 2:
            raise LinknetError(f"{path}: MP4 (H.264) frames need an even width and height (got {size[0]}x{size[1]})")
    return suffix


def _output_dir(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LinknetError(f"cannot write {path}: {exc.strerror or exc}") from None


def write_animation(motion: Motion, path, *, view: str = "auto", max_frames: int = DEFAULT_MAX_FRAMES,
                    fps: float = DEFAULT_FPS, speed: float = 1.0, size=DEFAULT_SIZE, cmap: str = DEFAULT_CMAP,
                    tension_range: float | None = None, elev: float = DEFAULT_ELEV,
                    azim: float = DEFAULT_AZIM, progress: Callable[[int, int, float], None] | None = None) -> Written:
    """Write the motion as a GIF (Pillow, always available) or MP4 (ffmpeg) with matplotlib's writers.
    ``progress(done, frames, seconds)`` is called after each frame (the CLI prints it every few seconds)."""
    from matplotlib import animation

    path = Path(path)
    suffix = check_animation_path(path, fps, size)
    if suffix == STILL_SUFFIX:
        raise LinknetError(f"{path}: a .png holds one frame; write it with write_still (linknet animate --at)")
    _output_dir(path)
    start = time.perf_counter()
    frames = motion.frame_indices(max_frames, fps, speed)
    picture = NetworkFigure(motion, view, size, cmap, tension_range, elev, azim, frame_times=motion.t[frames])
    writer = animation.PillowWriter(fps=fps) if suffix == ".gif" else animation.FFMpegWriter(fps=fps, codec="h264")

    def write(tmp):
        with writer.saving(picture.fig, tmp, dpi=DPI):
            for done, i in enumerate(frames, 1):
                picture.show(int(i))
                writer.grab_frame()
                if progress is not None:
                    progress(done, len(frames), time.perf_counter() - start)

    atomic_write(path, write, errors=(RuntimeError, ValueError))  # ffmpeg failing part way: RuntimeError
    seconds = time.perf_counter() - start
    span = float(motion.t[frames[-1]] - motion.t[frames[0]])
    playback = (len(frames) - 1) / fps
    pace = f", plays at {span / playback:.3g}x real time" if span > 0 else ""
    return Written(path, len(frames), len(motion.t), seconds,
                   f"{size[0]}x{size[1]} px, {picture.view} view, {fps:g} fps{pace}")


def write_still(motion: Motion, path, *, at: float | None = None, view: str = "auto", size=DEFAULT_SIZE,
                cmap: str = DEFAULT_CMAP, tension_range: float | None = None, elev: float = DEFAULT_ELEV,
                azim: float = DEFAULT_AZIM) -> Written:
    """Write one frame as PNG: the sample nearest to time ``at`` (default: the last sample)."""
    path = Path(path)
    _output_dir(path)
    start = time.perf_counter()
    if at is not None and not motion.t[0] <= at <= motion.t[-1]:
        raise LinknetError(f"{path}: the frame's time at = {at:g} s is outside the run, which has samples from "
                           f"t = {motion.t[0]:g} to {motion.t[-1]:g} s")
    i = len(motion.t) - 1 if at is None else int(np.argmin(np.abs(motion.t - at)))
    picture = NetworkFigure(motion, view, size, cmap, tension_range, elev, azim)
    picture.show(i)
    atomic_write(path, lambda tmp: picture.fig.savefig(tmp, dpi=DPI))
    return Written(path, 1, len(motion.t), time.perf_counter() - start,
                   f"t = {motion.t[i]:g} s, {size[0]}x{size[1]} px, {picture.view} view")


def plotly_colorscale(cmap_name: str, stops: int = 21) -> list:
    """The matplotlib colour map as a plotly colour scale, so the HTML view colours T as the animation does."""
    from matplotlib.colors import to_hex

    cmap, _ = tension_colours(cmap_name, 1.0)
    return [[float(s), to_hex(cmap(float(s)))] for s in np.linspace(0.0, 1.0, stops)]


def _html_bytes_per_frame(motion: Motion) -> float:
    """Frame data an HTML view stores per frame. Per link: 3 vertices (k1 end, k2 end, a NaN gap) of 3
    coordinates and a colour value, float32 in base64, whose '/' plotly writes as a 6-character escape (a NaN
    holds one): about 100 bytes, measured on chain_10, net_10x10 and a 100 x 100 net. Per mass: 3 float32."""
    return 100.0 * motion.L + 18.0 * motion.K


def html_default_max_frames(motion: Motion) -> int:
    """Up to HTML_MAX_FRAMES, fewer where the frames of a large scene would pass HTML_FRAME_BUDGET bytes."""
    return int(max(2, min(HTML_MAX_FRAMES, HTML_FRAME_BUDGET // _html_bytes_per_frame(motion))))


def _link_shortening(motion: Motion, radius_px: float) -> float:
    """Fraction of its length a link leaves out at each end so that it ends about ``radius_px`` from its masses
    on the screen, in a view whose box spans HTML_VIEW_PX pixels (at most 0.3: every link stays visible)."""
    if not motion.L:
        return 0.0
    lengths = np.linalg.norm(motion.X[0, motion.k2] - motion.X[0, motion.k1], axis=1)
    low, high = motion.bounds("3d")
    link_px = float(np.median(lengths)) / float(np.max(high - low)) * HTML_VIEW_PX
    return min(0.3, radius_px / link_px) if link_px > 0 else 0.0


def _camera(view: str, elev: float, azim: float) -> dict:
    """plotly camera looking along the dropped axis for a flat view (orthographic, as the animation's 2-D
    axes), or from (elev, azim) as matplotlib's 3-D view for 3d."""
    if view == "3d":
        e, a = math.radians(elev), math.radians(azim)
        eye = 2.0 * np.array([math.cos(e) * math.cos(a), math.cos(e) * math.sin(a), math.sin(e)])
        return dict(eye=dict(zip("xyz", eye.tolist())), up=dict(x=0, y=0, z=1), projection=dict(type="perspective"))
    eye, up = {"xz": ((0, -2, 0), (0, 0, 1)), "xy": ((0, 0, 2), (0, 1, 0)), "yz": ((2, 0, 0), (0, 0, 1))}[view]
    return dict(eye=dict(zip("xyz", eye)), up=dict(zip("xyz", up)), projection=dict(type="orthographic"))


def build_html_figure(motion: Motion, *, view: str = "auto", max_frames: int | None = None,
                      fps: float = DEFAULT_FPS, speed: float = 1.0, cmap: str = DEFAULT_CMAP,
                      tension_range: float | None = None, elev: float = DEFAULT_ELEV, azim: float = DEFAULT_AZIM):
    """The plotly figure of the HTML view: trace 0 the links (one line trace, coloured per vertex by T, a gap
    between links; hovering a link shows its number, its masses and T), trace 1 the free masses, trace 2 the
    anchored ones; with a ground trace 3, the plane within the view's box (translucent, still); with ropes
    (motion.slack) a last trace, the slack ropes, dashed (trace 0 then holds the others: a plotly line has one dash
    pattern, so each frame splits the links between the two traces); one frame per shown sample, a time slider and
    play / pause buttons. Returns (figure, frame indices)."""
    import plotly.graph_objects as go

    view = motion.resolve_view(view)
    frames = motion.frame_indices(max_frames or html_default_max_frames(motion), fps, speed)
    limit = tension_range or motion.tension_limit()
    scale = dict(colorscale=plotly_colorscale(cmap), cmin=-limit, cmax=limit)
    free, anchored = ~motion.fixed, motion.fixed
    L = motion.L

    mass_px, masses_shown = _marker_size(motion.K), _shows_free_masses(motion)
    # plotly draws a marker as a flat disc facing the camera, so a link running toward the viewer covers the half
    # of each of its masses it passes in front of: links stop short of their masses by a marker radius at the
    # default zoom, where the disc hides the gap
    shortening = _link_shortening(motion, mass_px / 2) if masses_shown else 0.0

    def link_vertices(i, shown=None):  # (3L, 3) float32: near k1 end, near k2 end, a NaN gap, per link
        X = motion.X[i]
        along = X[motion.k2] - X[motion.k1]
        vertices = np.full((L, 3, 3), np.nan, np.float32)
        vertices[:, 0], vertices[:, 1] = X[motion.k1] + shortening * along, X[motion.k2] - shortening * along
        if shown is not None:  # the other links' vertices NaN: not drawn in this trace
            vertices[~shown] = np.nan
        return vertices.reshape(-1, 3)

    ropes = motion.slack is not None

    def line_trace(i, shown=None):
        vertices = link_vertices(i, shown)
        return go.Scatter3d(x=vertices[:, 0], y=vertices[:, 1], z=vertices[:, 2],
                            line=dict(color=np.repeat(motion.T[i].astype(np.float32), 3)))

    def moving_traces(i):
        X = motion.X[i].astype(np.float32)
        out = [line_trace(i, ~motion.slack[i] if ropes else None),
               go.Scatter3d(x=X[free, 0], y=X[free, 1], z=X[free, 2])]
        return out + [line_trace(i, motion.slack[i])] if ropes else out

    first = int(frames[0])
    links, masses, *slack_links = moving_traces(first)
    # every vertex of a link carries the link's number and its masses: the hover label of whichever is nearest
    link_ends = np.repeat(np.stack([np.arange(1, L + 1), motion.k1 + 1, motion.k2 + 1], axis=1), 3, axis=0)
    links.update(mode="lines", name="links", customdata=link_ends,
                 line=dict(width=max(2.0, 2 * _line_width(L)), showscale=True,
                           colorbar=dict(title=dict(text="T, N"), len=0.75), **scale),
                 hovertemplate="link %{customdata[0]} (masses %{customdata[1]}-%{customdata[2]})"
                               "<br>T = %{line.color:.5g} N<extra></extra>")
    free_numbers = np.flatnonzero(free) + 1
    masses.update(mode="markers", name="masses", marker=dict(size=mass_px, color="#262626"),
                  visible=True if masses_shown else "legendonly",
                  text=[f"mass {k} ({motion.mass_names[k - 1]})" for k in free_numbers],
                  hovertemplate="%{text}<br>(%{x:.4g}, %{y:.4g}, %{z:.4g}) m<extra></extra>")
    X0 = motion.X[first]
    anchors = go.Scatter3d(x=X0[anchored, 0], y=X0[anchored, 1], z=X0[anchored, 2], mode="markers",
                           name="anchored masses",
                           marker=dict(size=max(1.6 * mass_px, 7.0), color="black", symbol="square"),
                           text=[f"mass {k + 1} ({motion.mass_names[k]}), anchored" for k in np.flatnonzero(anchored)],
                           hovertemplate="%{text}<br>(%{x:.4g}, %{y:.4g}, %{z:.4g}) m<extra></extra>")
    for slack in slack_links:  # the slack ropes: the links' colours and hover, dashed, one legend entry of their own
        slack.update(mode="lines", name="slack ropes", customdata=link_ends,
                     line=dict(width=max(2.0, 2 * _line_width(L)), dash="dash", **scale),
                     hovertemplate="link %{customdata[0]} (masses %{customdata[1]}-%{customdata[2]}), slack"
                                   "<br>T = %{line.color:.5g} N<extra></extra>")
    still = [anchors]
    low, high = motion.bounds("3d")
    if motion.ground is not None:
        polygon = ground_polygon(*motion.ground, low, high)
        if polygon is not None:
            # a fan of triangles from the first corner (the polygon is convex: a plane's section of a box)
            fan = np.arange(1, len(polygon) - 1)
            still.append(go.Mesh3d(x=polygon[:, 0], y=polygon[:, 1], z=polygon[:, 2], i=np.zeros_like(fan), j=fan,
                                   k=fan + 1, color=GROUND_COLOUR, opacity=GROUND_ALPHA, name="ground",
                                   showlegend=True, hoverinfo="name"))
    time_format = _time_format(motion.t[frames])
    labels = [time_format.format(motion.t[i]) for i in frames]
    moving = [0, 1] + ([2 + len(still)] if ropes else [])  # the traces each frame replaces
    figure_frames = [go.Frame(name=str(i), data=moving_traces(int(i)), traces=moving) for i in frames]
    animate = dict(mode="immediate", frame=dict(duration=0, redraw=True), transition=dict(duration=0))
    slider = dict(active=0, x=0.13, len=0.85, y=0.02, pad=dict(t=30, b=10),
                  currentvalue=dict(prefix="t = ", suffix=" s", font=dict(size=14)),
                  steps=[dict(method="animate", label=label, args=[[str(i)], animate])
                         for label, i in zip(labels, frames)])
    play = dict(type="buttons", direction="left", x=0.0, y=0.02, xanchor="left", yanchor="top",
                pad=dict(t=30, r=10), showactive=False,
                buttons=[dict(label="Play", method="animate",
                              args=[None, dict(frame=dict(duration=1000.0 / fps, redraw=True), fromcurrent=True,
                                               transition=dict(duration=0))]),
                         dict(label="Pause", method="animate", args=[[None], animate])])
    aspect = np.maximum((high - low) / float(np.max(high - low)), 0.02)  # equal scale: the network keeps its shape
    axes = {f"{c}axis": dict(range=[float(low[j]), float(high[j])], autorange=False, title=dict(text=f"{c}, m"))
            for j, c in enumerate(AXIS_NAMES)}
    if view != "3d":
        # plotly zooms an orthographic camera through the aspect ratio, not the eye distance: this fills the view
        aspect = ORTHOGRAPHIC_ZOOM * aspect
        seen_edge_on = AXIS_NAMES[({0, 1, 2} - set(PLANES[view])).pop()]
        axes[f"{seen_edge_on}axis"].update(showticklabels=False, title=dict(text=""))
    layout = go.Layout(
        title=dict(text=f"{motion.title}: {motion.K} masses, {L} links, {len(frames)} of {len(motion.t)} samples"
                        "<br><sup>T > 0 tension (red), T < 0 compression (blue). Drag to rotate, scroll to zoom, "
                        "hover on a link for its tension.</sup>", x=0.01),
        template="plotly_white", sliders=[slider], updatemenus=[play], margin=dict(l=0, r=0, t=70, b=0),
        legend=dict(x=0.01, y=0.92),
        scene=dict(aspectmode="manual", aspectratio=dict(zip("xyz", aspect.tolist())),
                   camera=_camera(view, elev, azim), **axes))
    return go.Figure(data=[links, masses] + still + slack_links, layout=layout, frames=figure_frames), frames


def write_html(motion: Motion, path, **options) -> Written:
    """Write the interactive 3-D view: one HTML file with plotly.js inline, so it opens with no network."""
    import plotly.io as pio

    path = Path(path)
    if path.suffix.lower() not in (".html", ".htm"):
        raise LinknetError(f"{path}: the interactive view is written as .html")
    _output_dir(path)
    start = time.perf_counter()
    largest, float32_max = float(np.abs(motion.X).max()), float(np.finfo(np.float32).max)
    if largest > float32_max:
        raise LinknetError(f"{path}: positions reach {largest:.3g} m, beyond the float32 range the HTML view stores "
                           f"({float32_max:.3g}); draw this run with linknet animate (float64) instead")
    figure, frames = build_html_figure(motion, **options)
    atomic_write(path, lambda tmp: pio.write_html(figure, tmp, include_plotlyjs=True, full_html=True, auto_play=False,
                                                  config=dict(displaylogo=False, scrollZoom=True)))
    return Written(path, len(frames), len(motion.t), time.perf_counter() - start,
                   f"{figure.layout.scene.camera.projection.type} camera, plotly.js inline")


# ---- command line (wired in linknet_core.cli) ------------------------------------------------------------

@validated("writable animation path")
def animation_path(text: str) -> str:
    problem = writable_path_problem(text)
    if problem:
        raise argparse.ArgumentTypeError(f"{text!r} {problem}")
    try:
        check_animation_path(text)
    except LinknetError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


@validated("colour map name")
def colour_map_name(text: str) -> str:
    try:
        tension_colours(text, 1.0)  # the pictures' own rule (a matplotlib colour map)
    except LinknetError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text



def _add_picture_arguments(p, max_frames_help: str) -> None:
    p.add_argument("result", type=readable_file,
                   help="a run written by `linknet simulate --out RESULT.npz`")
    p.add_argument("--view", choices=VIEWS, default="auto",
                   help="projection: a coordinate plane (xz, xy, yz) or 3d; auto picks the plane the whole run "
                        "stays in, else 3d")
    p.add_argument("--elev", type=finite_number, default=DEFAULT_ELEV,
                   help=f"3d view: elevation of the viewer, degrees (default {DEFAULT_ELEV:g})")
    p.add_argument("--azim", type=finite_number, default=DEFAULT_AZIM,
                   help=f"3d view: azimuth of the viewer, degrees (default {DEFAULT_AZIM:g})")
    p.add_argument("--max-frames", type=count, default=None, help=max_frames_help)
    p.add_argument("--fps", type=positive_number, default=DEFAULT_FPS,
                   help=f"frames per second of playback (default {DEFAULT_FPS:g})")
    p.add_argument("--speed", type=positive_number, default=1.0,
                   help="playback speed relative to real time (default 1; 0.25 is four times slower); "
                        "sets how many samples are shown")
    p.add_argument("--tension-range", type=positive_number, metavar="N",
                   help="colour scale from -N to N newtons (default: the 95th percentile of |T| over the run, so "
                        "that short spikes saturate rather than wash the rest out)")
    p.add_argument("--cmap", type=colour_map_name, default=DEFAULT_CMAP, help=f"diverging matplotlib colour map (default {DEFAULT_CMAP})")


def add_animate_arguments(p) -> None:
    _add_picture_arguments(p, f"at most this many frames (default {DEFAULT_MAX_FRAMES}); samples are thinned "
                              "evenly in time")
    p.add_argument("-o", "--out", type=animation_path, required=True,
                   help="OUT.gif or OUT.mp4 (needs ffmpeg), or OUT.png for one frame")
    p.add_argument("--size", type=parse_size, default=DEFAULT_SIZE, metavar="WxH",
                   help=f"picture size in pixels (default {DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]})")
    p.add_argument("--at", type=finite_number, metavar="TIME", help="OUT.png: time of the frame, s (default: the last sample)")


def add_view_arguments(p) -> None:
    _add_picture_arguments(p, f"at most this many frames (default {HTML_MAX_FRAMES}, fewer for large scenes so "
                              f"the file stays near {HTML_FRAME_BUDGET / 1e6:.0f} MB)")
    p.add_argument("-o", "--out", type=_output((".html",), "the page"), required=True,
                   help="OUT.html (self-contained: opens without network access)")


class ProgressLine:
    """Prints ``writing OUT: frame i of n, s`` to stderr every PROGRESS_EVERY seconds of a long write (a GIF of a
    large net takes minutes, its integration seconds), and nothing for a write shorter than that."""

    def __init__(self, path):
        self.path, self.next_at = path, PROGRESS_EVERY

    def __call__(self, done: int, frames: int, seconds: float) -> None:
        if seconds >= self.next_at and done < frames:
            print(f"writing {self.path}: frame {done} of {frames}, {seconds:.0f} s", file=sys.stderr, flush=True)
            self.next_at = seconds + PROGRESS_EVERY


def _print_notes(motion: Motion) -> None:
    for note in motion.notes + motion.scale_notes():
        print("note:", note)


def _picture_options(args) -> dict:
    return dict(view=args.view, cmap=args.cmap, tension_range=args.tension_range, elev=args.elev, azim=args.azim)


def cmd_animate(args) -> int:
    if args.at is not None and Path(args.out).suffix.lower() != STILL_SUFFIX:
        raise LinknetError(f"--at picks the one frame of a still (OUT.png), and {args.out} is an animation of the "
                           "whole run: leave --at out, or write OUT.png")
    motion = Motion.from_npz(args.result)
    _print_notes(motion)
    options = _picture_options(args)
    if Path(args.out).suffix.lower() == STILL_SUFFIX:
        written = write_still(motion, args.out, at=args.at, size=args.size, **options)
    else:
        written = write_animation(motion, args.out, max_frames=args.max_frames or DEFAULT_MAX_FRAMES, fps=args.fps,
                                  speed=args.speed, size=args.size, progress=ProgressLine(args.out), **options)
    print(written.line())
    return 0


def cmd_view(args) -> int:
    motion = Motion.from_npz(args.result)
    _print_notes(motion)
    written = write_html(motion, args.out, max_frames=args.max_frames, fps=args.fps, speed=args.speed,
                         **_picture_options(args))
    print(written.line())
    return 0


def animate_result(res, path) -> None:
    """``linknet simulate --animate PATH``: the run just computed, with the default picture options."""
    motion = Motion.from_result(res)
    if Path(path).suffix.lower() == STILL_SUFFIX:
        print(write_still(motion, path).line())
    else:
        print(write_animation(motion, path).line())
