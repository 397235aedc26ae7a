"""A plain, solver-neutral description of a linknet scene, the common input of every peer adapter.

Peers (OpenMM, Exudyn, MuJoCo, ASE, the scipy baselines) must not depend on linknet_core, so each adapter
reads this flat record: K masses (positions, velocities, masses, anchored flags), L links (k1, k2, R, 0-based)
and a uniform gravity vector. It is built either from the scene JSON format (``from_dict``) or from a
``linknet_core.Scene`` (``from_core``); both give the same record for the same file.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class SceneSpec:
    name: str
    mass_names: tuple
    mass: np.ndarray      # (K,), inf on anchored masses
    fixed: np.ndarray     # (K,) bool
    X0: np.ndarray        # (K,3)
    U0: np.ndarray        # (K,3), zero on anchored masses
    k1: np.ndarray        # (L,) 0-based
    k2: np.ndarray        # (L,) 0-based
    length: np.ndarray    # (L,)
    gravity: np.ndarray   # (3,)
    # driven anchors: (mass index, the scene file's motion dict), their motion prescribed (fixed is True on them)
    motions: tuple = ()

    @property
    def K(self) -> int:
        return len(self.mass)

    @property
    def L(self) -> int:
        return len(self.length)

    @property
    def inv_mass(self) -> np.ndarray:
        return np.where(self.fixed, 0.0, 1.0 / np.where(self.fixed, 1.0, self.mass))

    @property
    def free(self) -> np.ndarray:
        return ~self.fixed

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, d: dict) -> "SceneSpec":
        masses = d["masses"]
        names = tuple(m.get("name", f"m{i + 1}") for i, m in enumerate(masses))
        index = {n: i for i, n in enumerate(names)}
        fixed = np.array([bool(m.get("fixed", False) or m.get("driven", False)) for m in masses])
        mass = np.array([np.inf if f else float(m.get("mass", 1.0)) for m, f in zip(masses, fixed)])
        X0 = np.array([m["position"] for m in masses], dtype=float).reshape(-1, 3)
        U0 = np.array([m.get("velocity", [0.0, 0.0, 0.0]) for m in masses], dtype=float).reshape(-1, 3)
        U0[fixed] = 0.0

        def idx(v, link_no):
            if isinstance(v, str):
                if v not in index:
                    raise ValueError(f"link {link_no}: unknown mass name {v!r}")
                return index[v]
            if not 1 <= int(v) <= len(masses):
                raise ValueError(f"link {link_no}: mass index {v} outside 1..{len(masses)}")
            return int(v) - 1

        links = d.get("links", [])
        k1 = np.array([idx(l["a"], i + 1) for i, l in enumerate(links)], dtype=np.int64)
        k2 = np.array([idx(l["b"], i + 1) for i, l in enumerate(links)], dtype=np.int64)
        length = np.array([float(l["length"]) if l.get("length") is not None
                           else float(np.linalg.norm(X0[b] - X0[a]))
                           for l, a, b in zip(links, k1, k2)])
        g = np.array(d.get("gravity", [0.0, 0.0, -9.81]), dtype=float)
        motions = tuple((i, dict(m["motion"])) for i, m in enumerate(masses) if m.get("driven"))
        return cls(d.get("name", "scene"), names, mass, fixed, X0, U0, k1, k2, length, g, motions)

    @classmethod
    def from_core(cls, scene) -> "SceneSpec":
        """From a linknet_core.Scene (the public attributes of docs/architecture.md)."""
        fixed = np.asarray(scene.fixed, dtype=bool)
        masses = scene.to_dict()["masses"]  # the scene file's motions, not linknet's tables of them
        motions = tuple((i, dict(m["motion"])) for i, m in enumerate(masses) if m.get("driven"))
        U0 = np.array(scene.U0, dtype=float)
        U0[fixed] = 0.0
        return cls(getattr(scene, "name", "scene"), tuple(scene.mass_names),
                   np.array(scene.mass, dtype=float), fixed, np.array(scene.X0, dtype=float), U0,
                   np.array(scene.k1, dtype=np.int64), np.array(scene.k2, dtype=np.int64),
                   np.array(scene.length, dtype=float), np.array(scene.gravity, dtype=float), motions)

    def to_dict(self) -> dict:
        return {
            "name": self.name,
            "gravity": self.gravity.tolist(),
            "masses": [{"name": n, "mass": (1.0 if f else float(m)), "position": x.tolist(),
                        "velocity": u.tolist(), "fixed": bool(f)}
                       for n, m, f, x, u in zip(self.mass_names, self.mass, self.fixed, self.X0, self.U0)],
            "links": [{"a": int(a) + 1, "b": int(b) + 1, "length": float(r)}
                      for a, b, r in zip(self.k1, self.k2, self.length)],
        }

    def digest(self) -> str:
        """Content hash (not the name): a cached reference is reused only for the very same scene."""
        h = hashlib.sha256()
        for a in (self.mass, self.fixed.astype(np.int8), self.X0, self.U0, self.k1, self.k2,
                  self.length, self.gravity):
            h.update(np.ascontiguousarray(a).tobytes())
        if self.motions:  # a scene without driven anchors keeps the digest its cached references were made with
            h.update(json.dumps(self.motions, sort_keys=True).encode())
        return h.hexdigest()[:16]

    # ------------------------------------------------------------------ diagnostics shared by all methods
    def energy(self, X: np.ndarray, U: np.ndarray) -> float:
        """Kinetic + gravitational energy of the free masses."""
        f = self.free
        m = self.mass[f]
        return float(0.5 * np.sum(m * np.sum(U[f] ** 2, axis=1)) - np.sum(m * (X[f] @ self.gravity)))

    def energy_scale(self) -> float:
        """Scale for relative energy drift: E0 can be 0 (a pendulum released at the pivot height), so use
        initial kinetic energy + sum m|g|D, D the diameter of the initial bounding box."""
        f = self.free
        D = float(np.linalg.norm(self.X0.max(axis=0) - self.X0.min(axis=0))) or 1.0
        ke = 0.5 * np.sum(self.mass[f] * np.sum(self.U0[f] ** 2, axis=1))
        return float(ke + np.sum(self.mass[f]) * np.linalg.norm(self.gravity) * D) or 1.0

    def constraint_residual(self, X: np.ndarray) -> float:
        """max_l | |X_k2 - X_k1| / R_l - 1 |  (relative violation of (11))."""
        if self.L == 0:
            return 0.0
        d = np.linalg.norm(X[self.k2] - X[self.k1], axis=1)
        return float(np.max(np.abs(d / self.length - 1.0)))


def load_json(path) -> SceneSpec:
    with open(path) as fh:
        return SceneSpec.from_dict(json.load(fh))
