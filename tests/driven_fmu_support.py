"""Scenes and input motions of the driven-anchor FMU tests (tests/fmu, tests/fmu_native), and the same runs on
linknet_core's Simulator, which the FMUs are compared with.

Scenes:
* "driven_pendulum": a pendulum whose pivot is driven by inputs;
* "driven_chain": three coupled groups of links: a 4-link chain (generic angles) hanging from an input-driven anchor,
  a pendulum on a fixed pivot with a force input on its bob, and a pendulum on an anchor driven by a scene motion
  (a sine).

The input motion is continuous in P and V (each step's quadratic P + V tau + A tau^2/2 ends where the next one
starts), with a piecewise-constant acceleration; `jump_step` adds a jump of the anchor's velocity at the start of
that step, which the links take as an impulse.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from linknet_core.accuracy import DEFAULT_METHOD

H = 0.01        # communication step
N_STEPS = 25
ACCEL = np.array([3.0, 0.0, -2.0])      # anchor acceleration amplitude, m/s2
OMEGA = 9.0                             # rad/s of its variation
JUMP = np.array([0.2, 0.0, 0.1])        # velocity jump, m/s
BOB2_FORCE = np.array([0.5, 0.0, 0.0])  # force input on the fixed pendulum's bob (driven_chain)

SCENES = {
    "driven_pendulum": {
        "name": "driven_pendulum", "gravity": [0.0, 0.0, -9.81],
        "masses": [{"name": "hook", "position": [0.0, 0.0, 0.0], "driven": True},
                   {"name": "bob", "position": [0.6, 0.0, -0.8], "mass": 1.5}],
        "links": [{"a": 1, "b": 2, "length": 1.0}],
    },
    "driven_chain": {
        "name": "driven_chain", "gravity": [0.0, 0.0, -9.81],
        "masses": [{"name": "hook", "position": [0.0, 0.0, 0.0], "driven": True, "motion": {"kind": "input"}},
                   {"name": "c1", "position": [0.25, 0.05, -0.15], "mass": 0.2},
                   {"name": "c2", "position": [0.4, 0.2, -0.35], "mass": 0.2},
                   {"name": "c3", "position": [0.35, 0.45, -0.5], "mass": 0.2},
                   {"name": "c4", "position": [0.55, 0.5, -0.7], "mass": 0.3},
                   {"name": "pivot", "position": [2.0, 0.0, 0.0], "fixed": True},
                   {"name": "bob2", "position": [2.1, 0.4, -0.3], "mass": 1.0},
                   {"name": "shaker", "position": [4.0, 0.0, 0.0], "driven": True,
                    "motion": {"kind": "sine", "amplitude": [0.05, 0.0, 0.02], "frequency": [2.0, 0.0, 3.0]}},
                   {"name": "bob3", "position": [4.1, 0.2, -0.45], "mass": 0.5}],
        "links": [{"a": a, "b": b} for a, b in ((1, 2), (2, 3), (3, 4), (4, 5), (6, 7), (8, 9))],
    },
}
for _scene in SCENES.values():  # lengths from the initial positions (a generic, non-degenerate geometry)
    for _link in _scene["links"]:
        _a, _b = (np.array(_scene["masses"][_link[end] - 1]["position"]) for end in "ab")
        _link.setdefault("length", float(np.linalg.norm(_b - _a)))
# 1-based mass numbers
ANCHOR = {"driven_pendulum": 1, "driven_chain": 1}
FORCED = {"driven_pendulum": None, "driven_chain": 7}


def write_scene(root: Path, name: str) -> Path:
    path = Path(root) / f"{name}.json"
    path.write_text(json.dumps(SCENES[name]))
    return path


def anchor_motion(start: np.ndarray, n_steps: int = N_STEPS, h: float = H, jump_step: int | None = None):
    """(P, V, A) (n_steps + 1, 3) at the communication points: A_n = ACCEL * (cos, 1, sin)(OMEGA t_n) (libm), P and
    V carried exactly along each step's quadratic, V jumping by JUMP at the start of jump_step."""
    P, V, A = np.zeros((n_steps + 1, 3)), np.zeros((n_steps + 1, 3)), np.zeros((n_steps + 1, 3))
    P[0] = start
    for n in range(n_steps + 1):
        t = n * h
        A[n] = ACCEL * np.array([math.cos(OMEGA * t), 1.0, math.sin(OMEGA * t)])
        if n == jump_step:
            V[n] = V[n] + JUMP
        if n < n_steps:
            P[n + 1] = P[n] + V[n] * h + A[n] * (h * h / 2)
            V[n + 1] = V[n] + A[n] * h
    return P, V, A


def forces(scene) -> np.ndarray:
    F = np.zeros((scene.K, 3))
    k = FORCED[scene.name]
    if k:
        F[k - 1] = BOB2_FORCE
    return F


def output_names(md) -> list[str]:
    """Every output of the FMU, in ModelVariables order."""
    return [v.name for v in md.modelVariables if v.causality == "output"]


def library_outputs(scene, names, method=DEFAULT_METHOD, jump_step=None, n_steps=N_STEPS, h=H, read_after=False,
                    **settings) -> np.ndarray:
    """The run on linknet_core's Simulator (by default with the FMUs' default method): at each communication point the outputs `names` (FMU names) with the
    inputs of that point, then an advance to the next with them held. Rows: t, then names. ``read_after``: the
    outputs are read after each advance instead, before the next inputs (as fmpy's simulate_fmu reads them): the
    driven anchors where their held motion took them (rows t_1 .. t_N)."""
    import linknet_core as ln
    kwargs = settings or (dict(rtol=1e-8) if ln.METHODS[method].adaptive else dict(dt=1e-3))
    sim = ln.Simulator(scene, method=method, **kwargs)
    k = ANCHOR[scene.name] - 1
    P, V, A = anchor_motion(scene.X0[k], n_steps, h, jump_step)
    F = forces(scene)
    fixed_row = {int(m): j for j, m in enumerate(scene.fixed_indices)}
    driven_row = {int(m): j for j, m in enumerate(scene.driven_indices)}
    rows = []
    for n in range(n_steps + 1):
        anchors = (P[n:n + 1], V[n:n + 1], A[n:n + 1])
        if read_after:
            if n == n_steps:
                break
            sim.advance(n * h + h, F, anchors=anchors)
            out = sim.outputs(F)  # the last hold
        else:
            out = sim.outputs(F, anchors=anchors)
        row = [(n + 1) * h if read_after else n * h]
        for name in names:
            if name == "error_estimate":  # the FMU's companion run, as the Simulator's
                row.append(out["error_estimate"])
                continue
            kind, idx = name.split("[")
            idx = [int(i) - 1 for i in idx.rstrip("]").split(",")]
            if kind == "T":
                row.append(out["T"][idx[0]])
            elif kind in ("T_peak", "T_peak_time"):  # over the last advance (before the first, T and t0)
                row.append(sim.tension_peaks(F, anchors)[kind == "T_peak_time"][idx[0]])
            elif kind == "Freact":
                row.append(np.asarray(out["Freact"])[fixed_row[idx[0]], idx[1]])
            elif kind == "Jreact":
                row.append(np.asarray(out["impulse"])[driven_row[idx[0]], idx[1]])
            else:
                row.append(out[kind][idx[0], idx[1]])
        rows.append(row)
        if n < n_steps and not read_after:
            sim.advance(n * h + h, F, anchors=anchors)  # as the FMU: t + h
    return np.array(rows)
