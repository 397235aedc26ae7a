"""A plain, solver-neutral description of a linknet scene, the common input of every peer adapter.

Peers (OpenMM, Exudyn, MuJoCo, ASE, the scipy baselines) must not depend on linknet_core, so each adapter
reads this flat record: K masses (positions, velocities, masses, anchored flags), L links (k1, k2, R, 0-based)
and a uniform gravity vector; which links are ropes (they pull, never push, and go slack; docs/ropes.md) with their
restitution, and the ground plane if there is one (the scene file's entry), for the adapters that model them and
so that the others can refuse them. It is built either from the scene JSON format (``from_dict``) or from a
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
    rope: np.ndarray | None = None          # (L,) bool: the link is a rope, else a rod (all rods when None)
    restitution: np.ndarray | None = None   # (L,) Newton's restitution of a rope coming taut (0 on rods)
    ground: dict | None = None              # the scene file's "ground" entry (point, normal, restitution, friction)

    def __post_init__(self):
        if self.rope is None:
            object.__setattr__(self, "rope", np.zeros(len(self.length), bool))
        if self.restitution is None:
            object.__setattr__(self, "restitution", np.zeros(len(self.length)))

    @property
    def unilateral(self) -> bool:
        """Ropes or a ground: constraints that act one way and switch on and off."""
        return bool(np.any(self.rope)) or self.ground is not None

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
        rope = np.array([l.get("kind", "rod") == "rope" for l in links], bool)
        restitution = np.array([float(l.get("restitution", 0.0)) for l in links])
        return cls(d.get("name", "scene"), names, mass, fixed, X0, U0, k1, k2, length, g, motions, rope, restitution,
                   dict(d["ground"]) if d.get("ground") else None)

    @classmethod
    def from_core(cls, scene) -> "SceneSpec":
        """From a linknet_core.Scene (the public attributes of docs/architecture.md)."""
        fixed = np.asarray(scene.fixed, dtype=bool)
        as_file = scene.to_dict()   # the scene file's motions and ground, not linknet's tables of them
        motions = tuple((i, dict(m["motion"])) for i, m in enumerate(as_file["masses"]) if m.get("driven"))
        U0 = np.array(scene.U0, dtype=float)
        U0[fixed] = 0.0
        return cls(getattr(scene, "name", "scene"), tuple(scene.mass_names),
                   np.array(scene.mass, dtype=float), fixed, np.array(scene.X0, dtype=float), U0,
                   np.array(scene.k1, dtype=np.int64), np.array(scene.k2, dtype=np.int64),
                   np.array(scene.length, dtype=float), np.array(scene.gravity, dtype=float), motions,
                   np.array(getattr(scene, "rope", np.zeros(len(scene.length), bool)), dtype=bool),
                   np.array(getattr(scene, "restitution", np.zeros(len(scene.length))), dtype=float),
                   dict(as_file["ground"]) if as_file.get("ground") else None)

    def to_dict(self) -> dict:
        out = {
            "name": self.name,
            "gravity": self.gravity.tolist(),
            "masses": [{"name": n, "mass": (1.0 if f else float(m)), "position": x.tolist(),
                        "velocity": u.tolist(), "fixed": bool(f)}
                       for n, m, f, x, u in zip(self.mass_names, self.mass, self.fixed, self.X0, self.U0)],
            "links": [{"a": int(a) + 1, "b": int(b) + 1, "length": float(r),
                       **({"kind": "rope", "restitution": float(e)} if rope else {})}
                      for a, b, r, rope, e in zip(self.k1, self.k2, self.length, self.rope, self.restitution)],
        }
        for k, motion in self.motions:   # a driven anchor takes neither a mass nor a velocity nor a fixed flag
            out["masses"][k] = {"name": self.mass_names[k], "position": self.X0[k].tolist(), "driven": True,
                                "motion": dict(motion)}
        if self.ground is not None:
            out["ground"] = dict(self.ground)
        return out

    def digest(self) -> str:
        """Content hash (not the name): a cached reference is reused only for the very same scene."""
        h = hashlib.sha256()
        for a in (self.mass, self.fixed.astype(np.int8), self.X0, self.U0, self.k1, self.k2,
                  self.length, self.gravity):
            h.update(np.ascontiguousarray(a).tobytes())
        if self.motions:  # a scene without driven anchors keeps the digest its cached references were made with
            h.update(json.dumps(self.motions, sort_keys=True).encode())
        if self.unilateral:  # likewise a scene of rods only
            for a in (self.rope.astype(np.int8), self.restitution):
                h.update(np.ascontiguousarray(a).tobytes())
            h.update(json.dumps(self.ground, sort_keys=True).encode())
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
        """max_l | |X_k2 - X_k1| / R_l - 1 |  (relative violation of (11)); a rope violates its constraint only
        where it is longer than R_l (a slack rope is shorter)."""
        if self.L == 0:
            return 0.0
        strain = np.linalg.norm(X[self.k2] - X[self.k1], axis=1) / self.length - 1.0
        return float(np.max(np.where(self.rope, np.maximum(strain, 0.0), np.abs(strain))))


def load_json(path) -> SceneSpec:
    with open(path) as fh:
        return SceneSpec.from_dict(json.load(fh))
