"""Prescribed motions of driven anchors: P_a(tau), V_a = dP/dtau, A_a = dV/dtau in scene time tau = t - t0.

A driven anchor is an anchored mass (1/M = 0) whose position is prescribed. Its "position" in the scene is P at
tau = 0. The kinds, as a scene file writes them (``"motion": {...}`` on the mass):

* ``{"kind": "input"}`` (or no motion): driven by inputs (the FMU's P, V, A, or ``Simulator.advance(anchors=)``),
  at rest at its scene position until the first input arrives;
* ``{"kind": "velocity", "velocity": [vx, vy, vz]}``: P = X0 + v tau;
* ``{"kind": "sine", "amplitude": [..], "frequency": [..], "phase": [..]}`` (per axis; Hz and rad):
  P_i = X0_i + a_i (sin(2 pi f_i tau + phi_i) - sin(phi_i)), so that P(0) = X0;
* ``{"kind": "waypoints", "waypoints": [[t1, x, y, z], ...]}``: the C2 cubic spline through (0, X0) and the
  waypoints, clamped (at rest at tau = 0 and at the last waypoint), at rest after the last one (before 0, where
  only the inner stages of a composition look, its first piece continues).

Every kind but "sine" is a piecewise cubic: a table of pieces (start, base, coefficients in powers of
tau - base), the form the native core evaluates (linknet_core/native/src/drive.c) and :meth:`AnchorMotion.evaluate`
reads the same way, so both paths see the same numbers.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from linknet_core.errors import SceneError

MOTION_KINDS = ("input", "velocity", "sine", "waypoints")
# the native core's codes (drive.c: enum ln_motion_kind)
MOTION_CODES = {"input": 0, "velocity": 1, "waypoints": 1, "sine": 2}
_KEYS = {"input": {"kind"}, "velocity": {"kind", "velocity"}, "sine": {"kind", "amplitude", "frequency", "phase"},
         "waypoints": {"kind", "waypoints"}}
PIECE_COLUMNS = 14  # start, base, then c0..c3 per axis
SINE_COLUMNS = 12  # origin, amplitude, angular frequency, phase: 3 each


def _frozen(a) -> np.ndarray:
    out = np.array(a, float)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class AnchorMotion:
    """One driven anchor's motion. ``pieces`` (n, PIECE_COLUMNS) for the piecewise-cubic kinds, ``sine``
    (SINE_COLUMNS,) for "sine"; ``spec`` is the scene file's dict (what to_dict writes back)."""

    kind: str
    origin: np.ndarray  # (3,) P at tau = 0
    pieces: np.ndarray  # (n, PIECE_COLUMNS)
    sine: np.ndarray  # (SINE_COLUMNS,)
    spec: dict

    @property
    def code(self) -> int:
        return MOTION_CODES[self.kind]

    def evaluate(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(P, V, A) at scene time tau. An "input" motion has none of its own: at rest at its origin."""
        if self.kind == "sine":
            s = self.sine
            origin, amplitude, omega, phase = s[0:3], s[3:6], s[6:9], s[9:12]
            angle = omega * tau + phase
            sin, cos = np.sin(angle), np.cos(angle)
            return (origin + amplitude * (sin - np.sin(phase)), amplitude * omega * cos,
                    -amplitude * omega * omega * sin)
        if self.kind == "input":
            return self.origin.copy(), np.zeros(3), np.zeros(3)
        starts = self.pieces[:, 0]
        i = max(int(np.searchsorted(starts, tau, side="right")) - 1, 0)
        row = self.pieces[i]
        s = tau - row[1]
        c = row[2:].reshape(3, 4)
        P = c[:, 0] + s * (c[:, 1] + s * (c[:, 2] + s * c[:, 3]))
        V = c[:, 1] + s * (2.0 * c[:, 2] + s * 3.0 * c[:, 3])
        A = 2.0 * c[:, 2] + 6.0 * s * c[:, 3]
        return P, V, A


def step_cannot_follow(motion: AnchorMotion, dt: float) -> str | None:
    """Why a fixed step dt cannot follow this prescribed motion, or None. A sine needs at least two steps per period
    (Nyquist: dt 2 pi f <= pi): beyond, the steps alias it into a slower motion, and so does the half-step companion
    that estimates the error, which then agrees with them. A waypoint spline needs at least one step per interval
    between waypoints: a longer step jumps over a waypoint."""
    if motion.kind == "sine":
        amplitude, omega = motion.sine[3:6], motion.sine[6:9]
        fastest = np.where(amplitude != 0, omega, 0.0)
        axis = int(np.argmax(fastest))
        if dt * fastest[axis] > math.pi:
            return (f"its sine of {fastest[axis] / (2 * math.pi):.6g} Hz on axis {axis + 1} gets "
                    f"{2 * math.pi / (dt * fastest[axis]):.3g} steps per period at dt = {dt:g} s, and a fixed step "
                    f"needs at least 2 (Nyquist): dt <= {math.pi / fastest[axis]:.3g} s")
    elif motion.kind == "waypoints":
        times = np.array([0.0] + [float(row[0]) for row in motion.spec["waypoints"]])
        gaps = np.diff(times)
        i = int(np.argmin(gaps))
        if gaps[i] < dt:
            after = "the start" if i == 0 else f"waypoint {i} (t = {times[i]:g} s)"
            return (f"its waypoint {i + 1} (t = {times[i + 1]:g} s) comes {gaps[i]:.3g} s after {after}, less than "
                    f"one step dt = {dt:g} s, which would jump over it: dt <= {gaps[i]:.3g} s")
    return None


def sharpest_waypoint(motion: AnchorMotion, tau0: float, tau1: float) -> str | None:
    """The waypoint interval of this motion overlapping [tau0, tau1] with the largest prescribed acceleration, said
    in the scene's terms (None for other kinds or no overlap). The acceleration 2 c2 + 6 c3 s is linear on a
    piece, so its largest magnitude is at one end."""
    if motion.kind != "waypoints":
        return None
    times = [0.0] + [float(row[0]) for row in motion.spec["waypoints"]]
    best = None
    for i in range(len(times) - 1):
        if times[i + 1] < tau0 or times[i] > tau1:
            continue
        c = motion.pieces[i, 2:].reshape(3, 4)
        peak = max(float(np.linalg.norm(2.0 * c[:, 2] + 6.0 * s * c[:, 3])) for s in (0.0, times[i + 1] - times[i]))
        if best is None or peak > best[0]:
            best = (peak, i, times[i], times[i + 1])
    if best is None:
        return None
    peak, i, start, end = best
    return (f"its spline to waypoint {i + 1} (t = {end:g} s, {end - start:.3g} s after "
            f"{'the start' if i == 0 else f'waypoint {i}'}) accelerates it at up to {peak:.3g} m/s^2")


def _piece(start: float, base: float, coefficients) -> np.ndarray:
    """One table row: coefficients (3, 4) of c0 + c1 s + c2 s^2 + c3 s^3, s = tau - base, per axis."""
    return np.concatenate([[start, base], np.asarray(coefficients, float).reshape(12)])


def _at_rest(start: float, position) -> np.ndarray:
    c = np.zeros((3, 4))
    c[:, 0] = position
    return _piece(start, 0.0 if not math.isfinite(start) else start, c)


def parse_motion(spec, origin: np.ndarray, what: str, source: str, vector, number) -> AnchorMotion:
    """The motion of a driven anchor at ``origin`` from its scene-file dict (None: driven by inputs). ``vector``
    and ``number`` are the scene parser's validated readers, so a bad value is named as every scene field is."""
    if spec is None:
        spec = {"kind": "input"}
    if not isinstance(spec, dict):
        raise SceneError(f"{source}: {what} must be an object such as {{\"kind\": \"velocity\", \"velocity\": "
                         f"[1, 0, 0]}}, got {spec!r}")
    kind = spec.get("kind")
    if kind not in MOTION_KINDS:
        raise SceneError(f"{source}: {what} kind must be one of {', '.join(map(repr, MOTION_KINDS))}, got {kind!r}")
    unknown = set(spec) - _KEYS[kind]
    if unknown:
        raise SceneError(f"{source}: {what} of kind {kind!r} has unknown field(s) {sorted(unknown)}; allowed: "
                         f"{sorted(_KEYS[kind])}")
    origin = np.asarray(origin, float)
    sine = np.zeros(SINE_COLUMNS)
    pieces = np.zeros((0, PIECE_COLUMNS))
    if kind == "input":
        pieces = _at_rest(-math.inf, origin)[None]
    elif kind == "velocity":
        v = vector(spec.get("velocity"), f"{what} velocity", source)
        c = np.zeros((3, 4))
        c[:, 0], c[:, 1] = origin, v
        pieces = _piece(-math.inf, 0.0, c)[None]
    elif kind == "sine":
        amplitude = vector(spec.get("amplitude"), f"{what} amplitude", source)
        frequency = vector(spec.get("frequency"), f"{what} frequency", source)
        phase = vector(spec.get("phase"), f"{what} phase", source, default=[0, 0, 0])
        if np.any(frequency < 0):
            i = int(np.argmax(frequency < 0))
            raise SceneError(f"{source}: {what} frequency must not be negative (Hz), got {frequency[i]:g} on axis "
                             f"{i + 1}")
        sine = np.concatenate([origin, amplitude, 2.0 * math.pi * frequency, phase])
    else:
        pieces = _spline_pieces(spec.get("waypoints"), origin, what, source, number)
    spec = {key: (value.tolist() if isinstance(value, np.ndarray) else value) for key, value in spec.items()}
    return AnchorMotion(kind, _frozen(origin), _frozen(pieces), _frozen(sine), spec)


def _spline_pieces(waypoints, origin, what, source, number) -> np.ndarray:
    """The clamped cubic spline through (0, origin) and the waypoints (C2 inside, at rest at both ends), with
    constant pieces before 0 and after the last waypoint."""
    from scipy.interpolate import CubicSpline

    if not isinstance(waypoints, list) or not waypoints:
        raise SceneError(f"{source}: {what} waypoints must be a non-empty list of [t, x, y, z], got {waypoints!r}")
    times, points = [0.0], [origin]
    for i, row in enumerate(waypoints):
        label = f"{what} waypoint {i + 1}"
        if not isinstance(row, (list, tuple)) or len(row) != 4:
            raise SceneError(f"{source}: {label} must be [t, x, y, z] (4 numbers), got {row!r}")
        t = number(row[0], f"{label} time", source)
        if not t > times[-1]:
            before = "0 (the anchor's scene position)" if i == 0 else f"{times[-1]:g} (waypoint {i})"
            raise SceneError(f"{source}: {label} time {t:g} must be later than {before}: times strictly increase")
        times.append(t)
        points.append([number(x, f"{label} coordinate {j + 1}", source) for j, x in enumerate(row[1:])])
    spline = CubicSpline(np.array(times), np.array(points, float), bc_type="clamped")
    # scipy's c[m, i, axis] multiplies (tau - x_i)^(3 - m). The first piece also covers tau < 0: the stages of a
    # composition with negative step fractions look a little before the start, and a motion that is smooth
    # there keeps the composition's order (a rest row before 0 would put an acceleration jump at tau = 0).
    rows = []
    for i in range(len(times) - 1):
        rows.append(_piece(-math.inf if i == 0 else times[i], times[i], spline.c[::-1, i, :].T))
    rows.append(_at_rest(times[-1], points[-1]))
    return np.array(rows)
