"""MoorDyn peer (MoorDyn-C through its Python wrapper, `pip install moordyn`): every rope a MoorDyn line of one
segment, every mass a point (anchored masses "Fixed", the others "Free" with their mass), gravity g along -z, still
water of density 0 (no buoyancy, added mass or drag), no seabed within reach; integrated by MoorDyn's own explicit
scheme (RK4 by default) at a fixed step dtM.

What differs (docs/benchmarks/rope_peer.md): a MoorDyn line is elastic, its segment tension EA (l/l0 - 1) when
stretched and 0 when shorter than its unstretched length: a stiff spring that cannot push, against linknet's rigid
rope with exact slack and taut events. Its internal damping (BA) acts on the segment's rate of stretch whether the
segment is taut or slack (Line::getStateDeriv: Td is computed for every segment, T only for stretched ones), so a
damped line does not tend to a rope as EA grows: its slack segments resist being shortened ever more strongly. The
lines here are undamped (BA = 0); an undamped tension-only spring tends, as EA grows, to a rope whose jerks are
perfectly elastic (Newton's restitution 1: it gives back the stretch energy), so the peer runs only scenes whose
ropes all have restitution 1, and no rods (a line cannot push) or ground (benchmarks.peers.moordyn_seabed has one).

A driven anchor whose motion is a constant velocity ("velocity": P = X0 + v t) is a MoorDyn "Coupled" point: each
Step call is given its position and velocity at the call's start, and MoorDyn moves it linearly within the call
(Point::updateFairlead: r = r_ves + rd_ves t_local), which is that motion exactly. Other motions would be a
piecewise-linear approximation of it, which the peer does not make.

Two errors: the model's, which falls as 1/EA while a rope stays taut (its stretch T R / EA) but only as 1/sqrt(EA)
at each jerk (a jerk lasts pi sqrt(m R / EA) instead of an instant), and the time step's. One Method per EA,
swept over dtM from just inside the explicit scheme's stability limit, 2 / omega with omega = sqrt(EA / (R m_red))
the stiffest rope's axial frequency.

Initial state: MoorDyn's input file gives no velocities, so the state after Init_NoIC is written to MoorDyn's state
file (SaveState) with the scene's positions and velocities of the free points and read back (LoadState), the route
MoorDyn documents for initial conditions computed elsewhere. A rope taut at the start is pre-stretched by its
tension from (25)-(26) (benchmarks.index1), T R / EA, so that the line starts at the elastic equilibrium of the
rigid state instead of ringing with an amplitude T R / EA whose jerks the rigid rope does not have.
"""
from __future__ import annotations

import os
import shutil
import struct
import tempfile
import time
from dataclasses import replace

import numpy as np

from ..index1 import Index1System
from .base import Method, RunResult, Timer, Unsupported, n_steps

STABILITY = 2.0          # dtM <= STABILITY / omega: RK4 is stable for omega dt <= 2.83 on an undamped oscillator
DEPTH = 1.0e4            # water depth [m]: the seabed far below anything that moves
TOUCH = 1e-12            # a rope is taut at the start within this relative distance of its length
DIAMETER = 0.01          # the line's diameter [m]: no hydrodynamics here; the seabed's contact area (moordyn_seabed)


def moordyn_available() -> tuple[bool, str]:
    try:
        import moordyn  # noqa: F401
        return True, ""
    except Exception as e:   # ImportError, or a wheel whose C library does not load here
        return False, f"moordyn not importable ({type(e).__name__}: {e}); install with `pip install moordyn`"


class MoorDynLine(Method):
    family = "peer"
    knob = "dt"
    order = None           # no order in dt: the error levels off at the model's (1/EA, 1/sqrt(EA) at jerks)
    models_ropes = True    # the benchmark runs it on scenes with ropes...
    ropes_only = True      # ...and only on those (a line cannot push: no scene of rods has a MoorDyn counterpart)
    model_error = True     # its error levels off at the elastic model's: the sweep ends there

    def __init__(self, EA: float, scheme: str = "RK4", damping: float = 0.0):
        """``damping``: the line type's BA [N s], the internal damping (0 in the benchmark; see the docstring)."""
        self.EA, self.scheme, self.damping = float(EA), scheme, float(damping)
        self.name = f"moordyn-{scheme}-EA{EA:.0e}".replace("+", "") + (f"-BA{damping:g}" if damping else "")

    def available(self):
        return moordyn_available()

    def check_scene(self, spec):
        if spec.L == 0 or not np.all(spec.rope):
            rods = ", ".join(str(l + 1) for l in np.flatnonzero(~spec.rope)) or "none"
            raise Unsupported(f"MoorDyn lines cannot push: every link must be a rope (rods: links {rods})")
        inelastic = np.flatnonzero(spec.restitution != 1.0)
        if inelastic.size:
            raise Unsupported(
                f"rope restitution {spec.restitution[inelastic[0]]:g} (link {inelastic[0] + 1}): an undamped MoorDyn "
                "line tends to restitution 1 as EA grows, and a damped one to no rope at all (its internal damping "
                "also acts on slack segments), so only ropes of restitution 1 have a MoorDyn counterpart")
        if spec.ground is not None:
            raise Unsupported("a ground: MoorDyn's seabed is a penalty spring under the line nodes, not a plane")
        for k, motion in spec.motions:
            if motion.get("kind") != "velocity":
                raise Unsupported(f"driven anchor {spec.mass_names[k]!r}: motion {motion.get('kind')!r}: MoorDyn moves "
                                  "a coupled point linearly within a step, so only a constant velocity is exact")
        g = spec.gravity
        if g[0] != 0.0 or g[1] != 0.0 or g[2] >= 0.0:
            raise Unsupported(f"gravity {g.tolist()}: MoorDyn's gravity is along -z")

    @staticmethod
    def driven(spec) -> list:
        """The driven anchors, MoorDyn's coupled points in input order: [(mass index, its velocity)]."""
        return [(k, np.asarray(m["velocity"], float)) for k, m in spec.motions]

    # ------------------------------------------------------------------ step sizes
    def omega(self, spec) -> float:
        """The stiffest rope's axial angular frequency sqrt(EA / (R m_red)) [rad/s]."""
        inv = spec.inv_mass
        return float(np.max(np.sqrt(self.EA / spec.length * (inv[spec.k1] + inv[spec.k2]))))

    def knobs(self, spec, quick: bool) -> list[float]:
        top = STABILITY / self.omega(spec)
        return [top / 2 ** i for i in range(3 if quick else 16)]

    # ------------------------------------------------------------------ the run
    def run(self, spec, t_end, dt):
        n, dt = n_steps(t_end, dt)
        with Timer() as setup:
            session = _Session(self, spec, dt)
        try:
            with Timer() as tm:   # one call: MoorDyn takes its n steps of dtM inside
                X, U = session.step(0.0, t_end)
        finally:
            session.close()
        return RunResult(X, U, tm.seconds, setup.seconds, steps=n, info={"EA": self.EA, "scheme": self.scheme})

    def trajectory(self, spec, times, dt):
        """Positions at each of the increasing ``times`` (dt dividing every interval between them, as n_steps makes
        it for one) and the CPU seconds of MoorDyn's steps up to each."""
        session = _Session(self, spec, dt)
        X, cpu, t, spent = [], [], 0.0, 0.0
        try:
            for t_next in times:
                start = time.process_time()
                X.append(session.step(t, t_next - t)[0])
                spent += time.process_time() - start
                cpu.append(spent)
                t = t_next
        finally:
            session.close()
        return np.array(X), np.array(cpu)

    def initial_positions(self, spec) -> np.ndarray:
        """The scene's positions with the ropes taut at the start stretched by T R / EA, T their tensions from
        (25)-(26) with every such rope as a rod (a mass moves the least, in the mass metric, that does it)."""
        X, U = spec.X0.astype(float), spec.U0.astype(float)
        d = X[spec.k2] - X[spec.k1]
        r = np.linalg.norm(d, axis=1)
        rate = np.einsum("ij,ij->i", d / r[:, None], U[spec.k2] - U[spec.k1])
        taut = np.flatnonzero((r >= spec.length * (1 - TOUCH)) & (np.abs(rate) <= TOUCH * max(1.0, np.abs(U).max())))
        if not taut.size:
            return X
        sub = replace(spec, k1=spec.k1[taut], k2=spec.k2[taut], length=spec.length[taut], rope=None, restitution=None)
        T = np.maximum(Index1System(sub).tensions(X, U), 0.0)
        stretch = T * spec.length[taut] / self.EA
        inv = np.repeat(spec.inv_mass, 3)
        C = np.zeros((taut.size, 3 * spec.K))
        E = d[taut] / r[taut, None]
        for row, (a, b) in enumerate(zip(spec.k1[taut], spec.k2[taut])):
            C[row, 3 * a:3 * a + 3] -= E[row]
            C[row, 3 * b:3 * b + 3] += E[row]
        W = (C * inv) @ C.T
        move = inv * (C.T @ np.linalg.lstsq(W, stretch, rcond=1e-12)[0])
        return X + move.reshape(-1, 3)

    def input_file(self, spec, X0, dt) -> str:
        """MoorDyn v2 input: one line type (EA, massless, BA = ``damping``, no hydrodynamics), the points, one line of
        one segment per rope, the options. Numbers are written as Python floats: a numpy scalar's repr
        (np.float64(...)) is no number to MoorDyn, whose Step then never returns."""
        dt = float(dt)
        driven = {k for k, _ in self.driven(spec)}
        kinds = ["Coupled" if k in driven else "Fixed" if spec.fixed[k] else "Free" for k in range(spec.K)]
        rows = [f"{k + 1} {kinds[k]} {x[0]!r} {x[1]!r} {x[2]!r} "
                f"{0.0 if spec.fixed[k] else float(spec.mass[k])!r} 0 0 0" for k, x in enumerate(X0)]
        lines = [f"{l + 1} rope {a + 1} {b + 1} {float(R)!r} 1 -"
                 for l, (a, b, R) in enumerate(zip(spec.k1, spec.k2, spec.length))]
        return "\n".join([
            "MoorDyn v2 input file", f"linknet work-precision benchmark: {spec.name}",
            "---------------------- LINE TYPES ----------------------",
            "TypeName Diam Mass/m EA BA/-zeta EI Cd Ca CdAx CaAx",
            "(name) (m) (kg/m) (N) (N-s/-) (N-m^2) (-) (-) (-) (-)",
            f"rope {DIAMETER!r} 0.0 {self.EA!r} {self.damping!r} 0.0 0.0 0.0 0.0 0.0",
            "---------------------- POINTS ----------------------",
            "ID Attachment X Y Z Mass Volume CdA Ca",
            "(#) (-) (m) (m) (m) (kg) (m^3) (m^2) (-)",
            *rows,
            "---------------------- LINES ----------------------",
            "ID LineType AttachA AttachB UnstrLen NumSegs LineOutputs",
            "(#) (name) (#) (#) (m) (-) (-)",
            *lines,
            "---------------------- OPTIONS ----------------------",
            f"{dt!r} dtM", f"{self.scheme} tScheme", f"{-float(spec.gravity[2])!r} g", "0 rho", f"{DEPTH!r} WtrDpth",
            "0 writeLog", "1 disableOutput", "1 disableOutTime",
            "---------------------- need this line ----------------------", ""])


class _Session:
    """A MoorDyn system of the scene at step dt, from the scene's initial state (see the module's docstring)."""

    def __init__(self, line: MoorDynLine, spec, dt):
        import moordyn
        self.spec, self.md = spec, moordyn
        self.driven = line.driven(spec)
        self.folder = tempfile.mkdtemp(prefix="moordyn_peer_")
        try:
            X0 = line.initial_positions(spec)
            path = os.path.join(self.folder, "lines.txt")
            with open(path, "w") as fh:
                fh.write(line.input_file(spec, X0, dt))
            with _Quiet():
                self.system = moordyn.Create(path)
                if moordyn.Init_NoIC(self.system, *self.coupled(0.0)) != 0:
                    raise RuntimeError("MoorDyn Init_NoIC failed")
                state = os.path.join(self.folder, "state.bin")
                moordyn.SaveState(self.system, state)
                _write_state(state, _initial_state(_read_state(state), spec, X0))
                moordyn.LoadState(self.system, state)
            self.points = [moordyn.GetPoint(self.system, k + 1) for k in range(spec.K)]
        except BaseException:
            shutil.rmtree(self.folder, ignore_errors=True)
            raise

    def coupled(self, t):
        """The coupled points' positions and velocities at t, flattened in input order (MoorDyn's x and xd)."""
        x = [float(c) for k, v in self.driven for c in self.spec.X0[k] + v * t]
        xd = [float(c) for _, v in self.driven for c in v]
        return x, xd

    def step(self, t, span):
        """Advance from t by span; the masses' positions and velocities after."""
        self.md.Step(self.system, *self.coupled(t), t, span)
        X = np.array([self.md.GetPointPos(p) for p in self.points], float)
        U = np.array([self.md.GetPointVel(p) for p in self.points], float)
        X[self.spec.fixed], U[self.spec.fixed] = self.spec.X0[self.spec.fixed], 0.0
        for k, v in self.driven:
            X[k], U[k] = self.spec.X0[k] + v * (t + span), v
        return X, U

    def close(self):
        with _Quiet():
            self.md.Close(self.system)
        shutil.rmtree(self.folder, ignore_errors=True)


class _Quiet:
    """MoorDyn's C library prints its banner and set-up to the process's stdout: sent to /dev/null meanwhile."""

    def __enter__(self):
        import sys
        sys.stdout.flush()
        self.saved = os.dup(1)
        null = os.open(os.devnull, os.O_WRONLY)
        os.dup2(null, 1)
        os.close(null)

    def __exit__(self, *exc):
        os.dup2(self.saved, 1)
        os.close(self.saved)
        return False


# ---------------------------------------------------------------------- MoorDyn's state file
# "MoorDyn", major and minor version bytes, then little-endian uint64 words: the count of words that follow plus one,
# the number of instances, and per instance its rows and columns and rows x columns doubles. The instances are the
# points in input order (a row of position and velocity), then the lines (a row per inner node); the layout of
# moordyn.moorpy_export, which writes such files for MoorDyn's LoadState.
def _read_state(path):
    raw = open(path, "rb").read()
    head, words = raw[:9], raw[9:]
    if head[:7] != b"MoorDyn":
        raise RuntimeError(f"{path}: not a MoorDyn state file")
    u, f = np.frombuffer(words, "<u8"), np.frombuffer(words, "<f8")
    at, blocks = 2, []
    for _ in range(int(u[1])):
        rows, cols = int(u[at]), int(u[at + 1])
        blocks.append(f[at + 2:at + 2 + rows * cols].reshape(rows, cols).copy())
        at += 2 + rows * cols
    return head, blocks


def _write_state(path, state):
    head, blocks = state
    body = b"".join(struct.pack("<QQ", *b.shape) + b.astype("<f8").tobytes() for b in blocks)
    with open(path, "wb") as fh:
        fh.write(head + struct.pack("<QQ", len(body) // 8 + 1, len(blocks)) + body)


def _initial_state(state, spec, X0):
    head, blocks = state
    if len(blocks) != spec.K + spec.L:
        raise RuntimeError(f"MoorDyn state has {len(blocks)} instances, expected {spec.K} points + {spec.L} lines")
    for k in np.flatnonzero(spec.free):
        if blocks[k].shape != (1, 6):
            raise RuntimeError(f"MoorDyn state of point {k + 1}: shape {blocks[k].shape}, expected (1, 6)")
        blocks[k][0] = np.concatenate([X0[k], spec.U0[k]])
    return head, blocks
