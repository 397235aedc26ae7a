"""Scenes with driven anchors shared by tests/core/test_driven_anchors.py and tests/native/test_driven_native.py
(tests/conftest.py puts this folder on sys.path)."""
from __future__ import annotations

import math

import numpy as np

import linknet_core as ln
from linknet_core.scene import builders

G = 9.81

# the methods with a setting each that keeps a short run cheap on the numpy reference
METHODS = [("rattle", {"dt": 2e-3}), ("yoshida4", {"dt": 4e-3}), ("suzuki4", {"dt": 4e-3}),
           ("yoshida6", {"dt": 5e-3}), ("yoshida8", {"dt": 5e-3}), ("dopri5", {"rtol": 1e-7}),
           ("dop853", {"rtol": 1e-9})]

# smooth motions of every scene kind (the spline's knots lie after the runs that use it)
MOTIONS = {
    "velocity": {"kind": "velocity", "velocity": [0.4, -0.2, 0.3]},
    "sine": {"kind": "sine", "amplitude": [0.1, 0.05, 0.08], "frequency": [1.5, 1.0, 2.0], "phase": [0.3, 0.0, 1.0]},
    "waypoints": {"kind": "waypoints", "waypoints": [[0.6, 0.05, 0.02, 0.1], [1.0, 0.3, -0.1, 0.0]]},
}


def drive(scene: ln.Scene, index: int = 0, motion: dict | None = None, name: str | None = None) -> ln.Scene:
    """``scene`` with its mass ``index`` (0-based) made a driven anchor with ``motion`` (None: input-driven)."""
    d = scene.to_dict()
    entry = d["masses"][index]
    for key in ("fixed", "mass", "velocity"):
        entry.pop(key, None)
    entry["driven"] = True
    if motion is not None:
        entry["motion"] = motion
    if name:
        d["name"] = name
    return ln.Scene.from_dict(d)


def pendulum(theta: float, length: float = 1.0, mass: float = 1.0, gravity: float = G, motion: dict | None = None,
             velocity=None) -> ln.Scene:
    """A bob on a rod from a driven pivot at the origin, ``theta`` (rad) from the downward vertical in the x-z plane."""
    bob = {"name": "bob", "mass": mass, "position": [length * math.sin(theta), 0.0, -length * math.cos(theta)]}
    if velocity is not None:
        bob["velocity"] = [float(v) for v in velocity]
    pivot = {"name": "pivot", "position": [0.0, 0.0, 0.0], "driven": True}
    if motion is not None:
        pivot["motion"] = motion
    return ln.Scene.from_dict({"name": "driven_pendulum", "gravity": [0.0, 0.0, -gravity], "masses": [pivot, bob],
                               "links": [{"a": 1, "b": 2}]})


def driven_chain(motion: dict | None, n_links: int = 3) -> ln.Scene:
    """A chain released horizontally from its first mass, a driven anchor with ``motion`` (None: input-driven)."""
    return drive(builders.chain(n_links, shape="horizontal"), 0, motion, name="driven_chain")


def hold(P, V, A):
    """The (P, V, A) of one input-driven anchor as Simulator.advance takes it: arrays (1, 3)."""
    return tuple(np.asarray(x, float).reshape(1, 3) for x in (P, V, A))
