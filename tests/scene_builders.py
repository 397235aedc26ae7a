"""Scene builders shared by the test folders (bodies of linked masses, rotated copies of a scene, the
parallelogram four-bar with its singular flat position). tests/conftest.py puts this folder on sys.path."""
from __future__ import annotations

import numpy as np

import linknet_core as ln
from linknet_core.scene import builders

# four masses of an irregular body: an asymmetric top
IRREGULAR = [[0.0, 0.0, 0.0], [1.1, 0.1, 0.0], [0.2, 0.9, 0.1], [0.3, 0.2, 0.8]]


def body(points, masses, name="body", velocity=(0, 0, 0), spin=(0, 0, 0), offset=(0, 0, 0)):
    """Masses fully linked (every pair) at ``points + offset``, moving rigidly with ``velocity`` and ``spin``
    about their centre of mass: (masses, links) entries of a scene dict, names prefixed by ``name``."""
    P = np.asarray(points, float) + np.asarray(offset, float)
    m = np.asarray(masses, float)
    c = (m[:, None] * P).sum(axis=0) / m.sum()
    U = np.asarray(velocity, float) + np.cross(np.asarray(spin, float), P - c)
    entries = [{"name": f"{name}{i}", "position": P[i].tolist(), "mass": float(m[i]), "velocity": U[i].tolist()}
               for i in range(len(m))]
    links = [{"a": f"{name}{i}", "b": f"{name}{j}"} for i in range(len(m)) for j in range(i + 1, len(m))]
    return entries, links


def rotation(ax=0.5, az=0.3):
    """A rotation matrix about x then z."""
    cx, sx, cz, sz = np.cos(ax), np.sin(ax), np.cos(az), np.sin(az)
    return np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]) @ np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])


def rotated(scene, Q, name):
    """The same scene turned rigidly by Q (positions, velocities, gravity, constant forces): a tilted plane."""
    d = scene.to_dict()
    for m in d["masses"]:
        for key in ("position", "velocity", "force"):
            if key in m:
                m[key] = (Q @ np.asarray(m[key], float)).tolist()
    d["gravity"] = (Q @ np.asarray(d.get("gravity", [0, 0, -9.81]), float)).tolist()
    d["name"] = name
    return ln.Scene.from_dict(d)


def parallelogram(speed=5.0):
    """Crank = rocker, coupler = ground, no gravity: theta = theta0 + w t exactly; at theta = 180 deg every link
    is collinear and A of (25) is singular."""
    return builders.four_bar(ground=1.0, crank=0.4, coupler=1.0, rocker=0.4, crank_angle_deg=60.0,
                             crank_speed=speed, gravity=(0.0, 0.0, 0.0), name="parallelogram")
