"""The immutable description of a rigid-link network (like MuJoCo's mjModel).

A scene holds topology, masses, link lengths, force elements and the initial state. It never changes
during a simulation: the mutable state lives in :class:`linknet_core.state.State`.

Numbering: masses k = 1..K and links l = 1..L in file order (1-based in files and messages, 0-based in
the arrays). Link l joins k1(l) and k2(l) (seed eq. (5)) and has length R_l (6).
"""
from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from linknet_core.errors import LinknetError, SceneError
from linknet_core.output import atomic_write
from linknet_core.scene.motion import AnchorMotion, parse_motion

_MASS_KEYS = {"name", "mass", "position", "velocity", "fixed", "driven", "motion", "force", "drag", "quadratic_drag"}
_LINK_KEYS = {"a", "b", "length", "name", "kind", "restitution"}
_SPRING_KEYS = {"a", "b", "stiffness", "rest_length", "damping", "name"}
_SCENE_KEYS = {"name", "description", "gravity", "masses", "links", "springs", "options", "ground"}
# "kind" of a link: a rod holds its length both ways (the seed's (11)); a rope only keeps |X_k2 - X_k1| <= R_l, with
# T_l >= 0, and goes slack (linknet_core.dynamics.unilateral)
LINK_KINDS = ("rod", "rope")
_GROUND_KEYS = {"point", "normal", "restitution", "friction"}
# A free mass may start on the ground but not below it: at most this fraction of the scene's size (the largest
# coordinate, at least 1 m) under the plane is taken for round-off of a position given on a tilted plane
GROUND_START_TOL = 1e-12
# "options": key -> what its value must be (each is a JSON boolean)
_OPTION_KEYS = {"project_initial_positions": "a JSON boolean (true or false)",
                "run_loaded_blocked_flexes": "a JSON boolean (true or false)"}

# Largest magnitude of any number in a scene (SI units). The physics multiplies up to three of them (the energy
# M |U|^2, a force M g on a lever X): below 1e100 every such product stays far from the 1.8e308 where floats
# overflow, so a scene is refused here, naming the field, rather than failing later with numpy overflow warnings
# and a misleading solver error. Positive quantities (masses, lengths) must also be at least 1/MAX_MAGNITUDE, as
# the solver divides by them.
MAX_MAGNITUDE = 1e100


def _frozen(array) -> np.ndarray:
    out = np.array(array, dtype=float, copy=True)
    out.setflags(write=False)
    return out


def _frozen_bool(array) -> np.ndarray:
    out = np.array(array, dtype=bool, copy=True)
    out.setflags(write=False)
    return out


def _frozen_int(array) -> np.ndarray:
    out = np.array(array, dtype=np.int64, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class Springs:
    """Linear spring-dampers between two masses: F = (k (d - d0) + c d') along the axis."""

    a: np.ndarray  # (S,) 0-based mass index
    b: np.ndarray  # (S,)
    stiffness: np.ndarray  # (S,) N/m
    rest_length: np.ndarray  # (S,) m
    damping: np.ndarray  # (S,) N s/m
    names: tuple[str, ...] = ()

    @property
    def count(self) -> int:
        return int(self.a.shape[0])


FORCE_ELEMENT_PARAMETERS = 4  # parameters per force element (their meaning is the kind's)


@dataclass(frozen=True)
class ForceKind:
    """One kind of force element, as every force path knows it. Its formula is written once per path (the numpy
    reference linknet_core.dynamics.forces.ELEMENT_KINDS, the native core's native/src/stages/forces.c, the casadi
    derivation linknet_core.symbolic.derivation.CASADI_ELEMENT_KINDS); each path is checked against FORCE_KINDS
    by require_force_kinds, so a kind one of them lacks stops it instead of being skipped."""

    name: str  # the kind's name in ForceElements.kinds, the paths' tables and messages
    ends: int  # 1: acts on one mass (masses column 0); 2: between two masses (columns 0 and 1)
    parameters: tuple[str, ...]  # the meaning of its parameter columns, in order
    velocity_parameter: int  # the parameter column that makes the force depend on the velocities when nonzero
    formula: str  # the force, in words (docs and messages)


# Every kind of force element. A kind's position here is its code in the native core (enum ln_force_kind_code in
# native/src/stages/forces.c; native/model.py checks the core's kinds and codes against this table when it
# loads, before any native model is built), so a new kind is appended.
FORCE_KINDS: tuple[ForceKind, ...] = (
    ForceKind("drag", 1, ("c",), 0, "-c U_k on its mass (viscous drag)"),
    ForceKind("spring", 2, ("k", "d0", "c"), 2,
              "k (d - d0) + c d' along the axis, pulling the two masses together when stretched (spring-damper)"),
    ForceKind("quadratic_drag", 1, ("c",), 0, "-c |U_k| U_k on its mass (aerodynamic drag)"),
)
FORCE_KIND = {kind.name: kind for kind in FORCE_KINDS}


class ForceKindMissing(LinknetError):
    """A force path (numpy, native, casadi) lacks a kind of FORCE_KINDS, or has one the table does not list."""


def require_force_kinds(implemented, where: str, by_code: bool = False) -> None:
    """Raise ForceKindMissing unless ``implemented`` (the kind names a force path has a formula for) are exactly
    the kinds of FORCE_KINDS; ``by_code``: ``implemented`` is a sequence whose positions are the path's codes,
    which must be the table's positions too (the native core's enum)."""
    names = [kind.name for kind in FORCE_KINDS]
    implemented = list(implemented)
    problems = [f"no formula for force element kind {name!r}" for name in names if name not in implemented]
    problems += [f"a formula for kind {name!r}, which linknet_core.scene.description.FORCE_KINDS does not list"
                 for name in implemented if name not in FORCE_KIND]
    if by_code and not problems and implemented != names:
        problems = [f"kind {name!r} has code {code} there but {names.index(name)} in FORCE_KINDS"
                    for code, name in enumerate(implemented) if names[code] != name]
    if problems:
        raise ForceKindMissing(f"{where}: " + "; ".join(problems) + " (every force path implements every kind of "
                               "FORCE_KINDS, so that none is skipped)")


@dataclass(frozen=True)
class ForceElements:
    """The state-dependent force elements of F_k (9) as one table, the form every force path takes: a kind per
    element (one of FORCE_KINDS; its formula is in each path's table), the masses it acts on (two columns, -1 where
    unused, 0-based) and its parameters (FORCE_ELEMENT_PARAMETERS columns, their meaning the kind's). Gravity,
    constant and input forces are not elements: they do not depend on the state."""

    kinds: tuple[str, ...]
    masses: np.ndarray  # (n, 2) int
    parameters: np.ndarray  # (n, FORCE_ELEMENT_PARAMETERS)

    @property
    def count(self) -> int:
        return len(self.kinds)

    def of_kind(self, kind: str) -> tuple[np.ndarray, np.ndarray]:
        """(masses, parameters) of the elements of one kind."""
        rows = np.array([k == kind for k in self.kinds], bool)
        return self.masses[rows], self.parameters[rows]


@dataclass(frozen=True, eq=False)
class Ground:
    """A plane the free masses cannot pass: n . (X_k - point) >= 0, with ``normal`` n a unit vector pointing to the
    side the masses are on. Contact is unilateral and impulsive (linknet_core.dynamics.unilateral): an impact
    reverses ``restitution`` times the normal approach velocity (Newton's law; 0: perfectly inelastic); ``friction``
    is Coulomb's coefficient mu (0: frictionless)."""

    point: np.ndarray  # (3,) a point of the plane, m
    normal: np.ndarray  # (3,) unit normal, towards the masses
    restitution: float = 0.0
    friction: float = 0.0

    def gaps(self, X: np.ndarray) -> np.ndarray:
        """n . (X_k - point) of every mass (X (..., K, 3)): the height above the plane, m."""
        return (X - self.point) @ self.normal


@dataclass(frozen=True)
class Scene:
    """Immutable description of a network of point masses joined by rigid links."""

    name: str
    mass_names: tuple[str, ...]
    mass: np.ndarray  # (K,) kg; inf for anchored masses
    fixed: np.ndarray  # (K,) bool: anchored (1/M = 0), standing still or driven
    k1: np.ndarray  # (L,) 0-based index of the first end of each link (5)
    k2: np.ndarray  # (L,) second end
    length: np.ndarray  # (L,) R_l (6)
    link_names: tuple[str, ...]
    gravity: np.ndarray  # (3,) m/s^2
    force: np.ndarray  # (K,3) constant external force per mass, N
    drag: np.ndarray  # (K,) viscous drag coefficient, N s/m (force = -drag * U)
    quadratic_drag: np.ndarray  # (K,) aerodynamic drag coefficient, N s^2/m^2 (force = -c |U| U)
    springs: Springs
    X0: np.ndarray  # (K,3) initial positions
    U0: np.ndarray  # (K,3) initial velocities
    description: str = ""
    options: dict = field(default_factory=dict)
    driven: np.ndarray | None = None  # (K,) bool: anchors whose motion is prescribed (a subset of fixed)
    motions: tuple[AnchorMotion, ...] = ()  # one per driven anchor, in driven_indices order
    rope: np.ndarray | None = None  # (L,) bool: the link is a rope (pulls, never pushes; goes slack), else a rod
    restitution: np.ndarray | None = None  # (L,) Newton's restitution of a rope coming taut (0 on rods)
    ground: Ground | None = None  # the plane the free masses land on, if any

    def __post_init__(self):
        if self.driven is None:
            object.__setattr__(self, "driven", _frozen_bool(np.zeros(self.K, bool)))
        if self.rope is None:
            object.__setattr__(self, "rope", _frozen_bool(np.zeros(self.L, bool)))
        if self.restitution is None:
            object.__setattr__(self, "restitution", _frozen(np.zeros(self.L)))

    @property
    def unilateral(self) -> bool:
        """Whether the scene has ropes or a ground: constraints that act one way only and switch on and off (the
        numpy reference's event-driven path, linknet_core.dynamics.unilateral)."""
        return bool(self.rope.any()) or self.ground is not None

    # ---- derived, read-only views -------------------------------------------------------------
    @cached_property
    def force_elements(self) -> ForceElements:
        """Drag on the free masses that have it, quadratic (aerodynamic) drag and the spring-dampers, as one table;
        each row's kind, masses and parameters are as FORCE_KINDS defines them."""
        rows = []
        for k in np.flatnonzero((self.drag != 0) & ~self.fixed):
            rows.append(("drag", (k, -1), (self.drag[k],)))
        for k in np.flatnonzero((self.quadratic_drag != 0) & ~self.fixed):
            rows.append(("quadratic_drag", (k, -1), (self.quadratic_drag[k],)))
        s = self.springs
        for i in range(s.count):
            rows.append(("spring", (s.a[i], s.b[i]), (s.stiffness[i], s.rest_length[i], s.damping[i])))
        masses = np.full((len(rows), 2), -1, np.int64)
        parameters = np.zeros((len(rows), FORCE_ELEMENT_PARAMETERS))
        for i, (kind, ends, values) in enumerate(rows):
            spec = FORCE_KIND.get(kind)
            if spec is None or sum(k >= 0 for k in ends) != spec.ends or len(values) != len(spec.parameters):
                raise ForceKindMissing(f"scene {self.name!r}: a force element of kind {kind!r} that FORCE_KINDS does "
                                       "not define (its name, masses and parameters are the table's)")
            masses[i] = ends
            parameters[i, :len(values)] = values
        masses.setflags(write=False)
        parameters.setflags(write=False)
        return ForceElements(tuple(kind for kind, _, _ in rows), masses, parameters)

    @cached_property
    def fingerprint(self) -> str:
        """A hash of everything that defines the scene (topology, masses, lengths, forces, initial state, options):
        snapshots and FMU states carry it, so a state of another scene is recognised and refused."""
        import hashlib

        text = json.dumps(self.to_dict(), sort_keys=True, separators=(",", ":"))
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    @property
    def K(self) -> int:
        return int(self.mass.shape[0])

    @property
    def L(self) -> int:
        return int(self.k1.shape[0])

    @cached_property
    def inv_mass(self) -> np.ndarray:
        """1/M_k, zero for anchored masses (they take no acceleration)."""
        return _frozen(np.where(self.fixed, 0.0, 1.0 / np.where(self.fixed, 1.0, self.mass)))

    @cached_property
    def free_indices(self) -> np.ndarray:
        return _frozen_int(np.flatnonzero(~self.fixed))

    @cached_property
    def fixed_indices(self) -> np.ndarray:
        """Every anchored mass, standing still or driven."""
        return _frozen_int(np.flatnonzero(self.fixed))

    @cached_property
    def driven_indices(self) -> np.ndarray:
        """The driven anchors (their motion prescribed), in scene order: the order of ``motions``."""
        return _frozen_int(np.flatnonzero(self.driven))

    @cached_property
    def input_driven_indices(self) -> np.ndarray:
        """The driven anchors moved by inputs (motion kind "input"), in scene order."""
        return _frozen_int([k for k, m in zip(self.driven_indices, self.motions) if m.kind == "input"])

    def anchor_motion(self, tau: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(P, V, A), each (n_driven, 3): the driven anchors' scene motions at scene time tau (input-driven
        anchors at rest at their scene position)."""
        n = len(self.motions)
        out = np.zeros((3, n, 3))
        for i, motion in enumerate(self.motions):
            out[:, i] = motion.evaluate(tau)
        return out[0], out[1], out[2]

    def mass_label(self, k: int) -> str:
        """Human label of 0-based mass k: 'mass 3 ("b")'."""
        return f'mass {k + 1} ("{self.mass_names[k]}")'

    def link_label(self, l: int) -> str:
        a, b = int(self.k1[l]), int(self.k2[l])
        return f'link {l + 1} ({self.mass_names[a]}-{self.mass_names[b]})'

    # ---- construction ------------------------------------------------------------------------
    @classmethod
    def from_dict(cls, data: dict[str, Any], *, source: str = "scene") -> "Scene":
        return _parse_scene(data, source)

    def to_dict(self) -> dict[str, Any]:
        masses = []
        for k in range(self.K):
            entry: dict[str, Any] = {"name": self.mass_names[k], "position": self.X0[k].tolist()}
            if self.driven[k]:
                entry["driven"] = True
                entry["motion"] = dict(self.motions[int(np.searchsorted(self.driven_indices, k))].spec)
            elif self.fixed[k]:
                entry["fixed"] = True
            else:
                entry["mass"] = float(self.mass[k])
                if np.any(self.U0[k] != 0):
                    entry["velocity"] = self.U0[k].tolist()
            if np.any(self.force[k] != 0):
                entry["force"] = self.force[k].tolist()
            if self.drag[k] != 0:
                entry["drag"] = float(self.drag[k])
            if self.quadratic_drag[k] != 0:
                entry["quadratic_drag"] = float(self.quadratic_drag[k])
            masses.append(entry)
        links = [
            {"a": int(self.k1[l]) + 1, "b": int(self.k2[l]) + 1, "length": float(self.length[l])}
            for l in range(self.L)
        ]
        for l in np.flatnonzero(self.rope):
            links[l]["kind"] = "rope"
            if self.restitution[l] != 0:
                links[l]["restitution"] = float(self.restitution[l])
        out: dict[str, Any] = {"name": self.name}
        if self.description:
            out["description"] = self.description
        if np.any(self.gravity != 0):
            out["gravity"] = self.gravity.tolist()
        out["masses"] = masses
        out["links"] = links
        s = self.springs
        if s.count:
            out["springs"] = [
                {"a": int(s.a[i]) + 1, "b": int(s.b[i]) + 1, "stiffness": float(s.stiffness[i]),
                 "rest_length": float(s.rest_length[i]), "damping": float(s.damping[i])}
                for i in range(s.count)
            ]
        if self.options:
            out["options"] = dict(self.options)
        if self.ground is not None:
            g = self.ground
            out["ground"] = {"point": g.point.tolist(), "normal": g.normal.tolist(), "restitution": g.restitution,
                             "friction": g.friction}
        return out

    def save(self, path: str | Path) -> None:
        """Write the scene file whole or not at all (a failure, e.g. a full disk, leaves any file there as it was
        and raises a WriteError naming it)."""
        text = json.dumps(self.to_dict(), indent=1) + "\n"
        atomic_write(path, lambda tmp: Path(tmp).write_text(text))

    def with_state(self, X0=None, U0=None) -> "Scene":
        """A copy of this scene with another initial state (the description is otherwise shared)."""
        import dataclasses

        return dataclasses.replace(
            self,
            X0=self.X0 if X0 is None else _frozen(np.asarray(X0, float).reshape(self.K, 3)),
            U0=self.U0 if U0 is None else _frozen(np.asarray(U0, float).reshape(self.K, 3)),
        )

    def with_motions(self, motions: dict) -> "Scene":
        """A copy in which the anchors named in ``motions`` (mass name or 1-based index -> a motion as the scene
        file writes it, linknet_core.scene.motion) are driven by those motions; validated again."""
        data = self.to_dict()
        if not isinstance(motions, dict):
            raise SceneError(f"{self.name}: motions must be a dict of anchor (name or 1-based index) -> motion, "
                             f"got {type(motions).__name__}")
        for ref, spec in motions.items():
            if isinstance(ref, str) and ref in self.mass_names:
                k = self.mass_names.index(ref)
            elif isinstance(ref, (int, np.integer)) and not isinstance(ref, bool) and 1 <= ref <= self.K:
                k = int(ref) - 1
            else:
                raise SceneError(f"{self.name}: motions names {ref!r}, which is neither a mass name nor an index "
                                 f"1..{self.K}")
            if not self.fixed[k]:
                raise SceneError(f"{self.name}: {self.mass_label(k)} is free; only an anchor can be driven")
            entry = data["masses"][k]
            entry.pop("fixed", None)
            entry["driven"], entry["motion"] = True, spec
        return Scene.from_dict(data, source=self.name)

    def with_parameters(self, mass=None, length=None, gravity=None) -> "Scene":
        """A copy with changed masses (free masses only), link lengths or gravity, validated again."""
        data = self.to_dict()
        if mass is not None:
            mass = np.asarray(mass, float)
            for k, entry in enumerate(data["masses"]):
                if not self.fixed[k]:
                    entry["mass"] = float(mass[k])
        if length is not None:
            for l, entry in enumerate(data["links"]):
                entry["length"] = float(np.asarray(length, float)[l])
        if gravity is not None:
            data["gravity"] = np.asarray(gravity, float).tolist()
        return Scene.from_dict(data, source=self.name)


def load_scene(path: str | Path) -> Scene:
    """Read a scene JSON file and validate it (errors name the mass or link and the rule broken)."""
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as exc:
        raise SceneError(f"cannot read scene file {path}: {exc.strerror}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise SceneError(f"{path}: not valid JSON: {exc}") from None
    if not isinstance(data, dict):
        raise SceneError(f"{path}: a scene must be a JSON object {{...}}, got a JSON {_json_type(data)}")
    data.pop("fmu", None)  # build_fmu.py's settings for the scene's FMU (docs/fmu.md), checked there
    data.setdefault("name", path.stem)
    return Scene.from_dict(data, source=str(path))


def _json_type(value) -> str:
    """The JSON name of a parsed value's type, for messages."""
    if isinstance(value, bool):
        return "boolean"
    if value is None:
        return "null"
    return {dict: "object", list: "array", str: "string", int: "number", float: "number"}.get(type(value),
                                                                                        type(value).__name__)


# ---- parsing and validation ----------------------------------------------------------------------

def _is_number(value) -> bool:
    """A JSON number (a bool is not one, although Python counts it as an int; nor is a numeric string)."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, (bool, np.bool_))


def _vector(value, what: str, source: str, default=None) -> np.ndarray:
    if value is None:
        if default is None:
            raise SceneError(f"{source}: {what} is missing")
        return np.array(default, float)
    if isinstance(value, np.ndarray):
        value = value.tolist()
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise SceneError(f"{source}: {what} must be a list of 3 numbers, got {value!r}")
    for x in value:
        if not _is_number(x):
            raise SceneError(f"{source}: {what} must be a list of 3 numbers, got {value!r} "
                             f"({x!r} is a JSON {_json_type(x)})")
    vec = np.array([float(x) for x in value])
    if not np.all(np.isfinite(vec)):
        raise SceneError(f"{source}: {what} must be finite (no NaN or infinity), got {value!r}")
    if np.any(np.abs(vec) > MAX_MAGNITUDE):
        raise SceneError(f"{source}: {what} = {value!r} is too large: every component must have magnitude "
                         f"<= {MAX_MAGNITUDE:g} (beyond it the computation would overflow)")
    return vec


def _number(value, what: str, source: str, *, positive=False, nonnegative=False) -> float:
    if not _is_number(value):
        raise SceneError(f"{source}: {what} must be a number, got {value!r}")
    x = float(value)
    if not math.isfinite(x):
        raise SceneError(f"{source}: {what} must be finite, got {value!r}")
    if positive and not x > 0:
        raise SceneError(f"{source}: {what} must be positive, got {value!r}")
    if nonnegative and x < 0:
        raise SceneError(f"{source}: {what} must not be negative, got {value!r}")
    if abs(x) > MAX_MAGNITUDE:
        raise SceneError(f"{source}: {what} = {value!r} is too large: its magnitude must be <= {MAX_MAGNITUDE:g} "
                         "(beyond it the computation would overflow)")
    if positive and x < 1.0 / MAX_MAGNITUDE:
        raise SceneError(f"{source}: {what} = {value!r} is too small: it must be >= {1.0 / MAX_MAGNITUDE:g} "
                         "(the solver divides by it)")
    return x


def _boolean(value, what: str, source: str) -> bool:
    """A JSON boolean: "false" (a string) or 0 would silently mean true or false."""
    if not isinstance(value, (bool, np.bool_)):
        raise SceneError(f"{source}: {what} must be a JSON boolean (true or false), got {value!r} "
                         f"(a JSON {_json_type(value)})")
    return bool(value)


ABSENT = object()  # a field left out, as against one given as JSON null


def _text(value, what: str, source: str, default: str) -> str:
    """A text field: its default where the field is left out (ABSENT); JSON null is refused like any non-string."""
    if value is ABSENT:
        return default
    if not isinstance(value, str):
        raise SceneError(f"{source}: {what} must be a string, got {value!r} (a JSON {_json_type(value)})")
    return value


def _check_keys(entry: dict, allowed: set, what: str, source: str) -> None:
    unknown = set(entry) - allowed
    if unknown:
        raise SceneError(f"{source}: {what} has unknown field(s) {sorted(unknown)}; allowed: {sorted(allowed)}")


def _parse_scene(data: dict, source: str) -> Scene:
    if not isinstance(data, dict):
        raise SceneError(f"{source}: a scene must be a JSON object {{...}}, got a JSON {_json_type(data)}")
    _check_keys(data, _SCENE_KEYS, "the scene", source)
    masses = data.get("masses")
    if not isinstance(masses, list) or not masses:
        raise SceneError(f"{source}: 'masses' must be a non-empty list")
    links = data.get("links", [])
    if not isinstance(links, list):
        raise SceneError(f"{source}: 'links' must be a list")

    K = len(masses)
    names: list[str] = []
    index_of: dict[str, int] = {}
    mass = np.empty(K)
    fixed = np.zeros(K, bool)
    X0 = np.empty((K, 3))
    U0 = np.zeros((K, 3))
    force = np.zeros((K, 3))
    drag = np.zeros(K)
    quadratic_drag = np.zeros(K)
    driven = np.zeros(K, bool)
    motions: list[AnchorMotion] = []
    for k, entry in enumerate(masses):
        if not isinstance(entry, dict):
            raise SceneError(f"{source}: mass {k + 1} must be an object")
        _check_keys(entry, _MASS_KEYS, f"mass {k + 1}", source)
        name = _text(entry.get("name", ABSENT), f"mass {k + 1} name", source, f"m{k + 1}")
        label = f'mass {k + 1} ("{name}")'
        if name in index_of:
            raise SceneError(f"{source}: {label} repeats the name of mass {index_of[name] + 1}; names must be unique")
        index_of[name] = k
        names.append(name)
        fixed[k] = _boolean(entry.get("fixed", False), f"{label} fixed", source)
        driven[k] = _boolean(entry.get("driven", False), f"{label} driven", source)
        X0[k] = _vector(entry.get("position"), f"{label} position", source)
        if driven[k]:  # an anchor (1/M = 0) whose motion is prescribed
            if "fixed" in entry and not fixed[k]:
                raise SceneError(f"{source}: {label} is driven, so it is an anchor: \"fixed\": false contradicts "
                                 "\"driven\": true (leave \"fixed\" out)")
            if "velocity" in entry:
                raise SceneError(f"{source}: {label} is driven: its velocity comes from its motion, so it cannot "
                                 "have a \"velocity\"; give the motion (e.g. {\"kind\": \"velocity\", ...})")
            if "mass" in entry:
                raise SceneError(f"{source}: {label} is driven: its motion is prescribed whatever pulls on it, so a "
                                 "\"mass\" would have no effect (the links' pull on it is reported as Freact); leave "
                                 "\"mass\" out, or make it a free mass")
            fixed[k] = True
            motions.append(parse_motion(entry.get("motion"), X0[k], f"{label} motion", source, _vector, _number))
        elif "motion" in entry:
            raise SceneError(f"{source}: {label} has a \"motion\" but is not driven; add \"driven\": true to "
                             "prescribe its motion")
        if fixed[k]:
            mass[k] = math.inf
            if "mass" in entry:  # an anchored mass may carry a nominal mass; it never moves
                _number(entry["mass"], f"{label} mass", source, positive=True)
            if not driven[k] and "velocity" in entry and np.any(_vector(entry["velocity"], f"{label} velocity",
                                                                          source) != 0):
                raise SceneError(f"{source}: {label} is fixed (anchored) and cannot have a non-zero velocity")
        else:
            if "mass" not in entry:
                raise SceneError(f"{source}: {label} is free but has no 'mass' value (give one or set \"fixed\": true)")
            mass[k] = _number(entry["mass"], f"{label} mass", source, positive=True)
            U0[k] = _vector(entry.get("velocity"), f"{label} velocity", source, default=[0, 0, 0])
        force[k] = _vector(entry.get("force"), f"{label} force", source, default=[0, 0, 0])
        drag[k] = _number(entry.get("drag", 0.0), f"{label} drag", source, nonnegative=True)
        quadratic_drag[k] = _number(entry.get("quadratic_drag", 0.0), f"{label} quadratic_drag", source,
                                    nonnegative=True)

    def resolve(ref, what: str) -> int:
        if isinstance(ref, bool):
            raise SceneError(f"{source}: {what} must be a mass name or a 1-based index, got {ref!r}")
        if isinstance(ref, int):
            if not 1 <= ref <= K:
                raise SceneError(f"{source}: {what} refers to mass index {ref}, but masses are numbered 1..{K}")
            return ref - 1
        if isinstance(ref, str):
            if ref not in index_of:
                raise SceneError(f"{source}: {what} refers to unknown mass {ref!r}")
            return index_of[ref]
        raise SceneError(f"{source}: {what} must be a mass name or a 1-based index, got {ref!r}")

    def two_ends(entry, what: str, allowed: set) -> tuple[int, int]:
        """The two mass indices a link or spring joins, with its fields checked."""
        if not isinstance(entry, dict):
            raise SceneError(f"{source}: {what} must be an object")
        _check_keys(entry, allowed, what, source)
        if "a" not in entry or "b" not in entry:
            raise SceneError(f"{source}: {what} needs both ends 'a' and 'b'")
        return resolve(entry["a"], f"{what} end 'a'"), resolve(entry["b"], f"{what} end 'b'")

    L = len(links)
    k1 = np.empty(L, np.int64)
    k2 = np.empty(L, np.int64)
    length = np.empty(L)
    rope = np.zeros(L, bool)
    restitution = np.zeros(L)
    link_names: list[str] = []
    seen_pairs: dict[tuple[int, int], int] = {}
    for l, entry in enumerate(links):
        a, b = two_ends(entry, f"link {l + 1}", _LINK_KEYS)
        label = f"link {l + 1} ({names[a]}-{names[b]})"
        if a == b:  # the seed assumes the two ends of a link are different masses (before (17))
            raise SceneError(f"{source}: {label} joins mass {a + 1} to itself; a link must join two different masses")
        pair = (min(a, b), max(a, b))
        if pair in seen_pairs:  # the seed assumes at most one link per pair of masses (before (17))
            raise SceneError(
                f"{source}: {label} joins the same pair of masses as link {seen_pairs[pair] + 1}; "
                "at most one link may join a pair")
        seen_pairs[pair] = l
        if fixed[a] and fixed[b]:
            raise SceneError(f"{source}: {label} joins two anchored masses; such a link carries no information")
        k1[l], k2[l] = a, b
        distance = float(np.linalg.norm(X0[b] - X0[a]))
        if "length" in entry:
            length[l] = _number(entry["length"], f"{label} length", source, positive=True)
        else:
            if not distance > 0:
                raise SceneError(f"{source}: {label} has no length and its ends coincide, so the default "
                                 "(initial distance) would be zero")
            length[l] = distance
        link_names.append(_text(entry.get("name", ABSENT), f"{label} name", source, f"l{l + 1}"))
        kind = entry.get("kind", "rod")
        if kind not in LINK_KINDS:
            raise SceneError(f"{source}: {label} kind must be one of {', '.join(map(repr, LINK_KINDS))}, got {kind!r}")
        rope[l] = kind == "rope"
        if "restitution" in entry:
            if not rope[l]:
                raise SceneError(f"{source}: {label} is a rod, which never goes slack: \"restitution\" applies to "
                                 "ropes only (\"kind\": \"rope\")")
            restitution[l] = _fraction(entry["restitution"], f"{label} restitution", source)

    springs_data = data.get("springs", [])
    if not isinstance(springs_data, list):
        raise SceneError(f"{source}: 'springs' must be a list")
    S = len(springs_data)
    sa = np.empty(S, np.int64)
    sb = np.empty(S, np.int64)
    stiffness = np.empty(S)
    rest = np.empty(S)
    damping = np.empty(S)
    spring_names = []
    for s, entry in enumerate(springs_data):
        sa[s], sb[s] = two_ends(entry, f"spring {s + 1}", _SPRING_KEYS)
        if sa[s] == sb[s]:
            raise SceneError(f"{source}: spring {s + 1} joins mass {sa[s] + 1} to itself")
        stiffness[s] = _number(entry.get("stiffness", 0.0), f"spring {s + 1} stiffness", source, nonnegative=True)
        damping[s] = _number(entry.get("damping", 0.0), f"spring {s + 1} damping", source, nonnegative=True)
        d0 = float(np.linalg.norm(X0[sb[s]] - X0[sa[s]]))
        rest[s] = _number(entry.get("rest_length", d0), f"spring {s + 1} rest_length", source, nonnegative=True)
        spring_names.append(_text(entry.get("name", ABSENT), f"spring {s + 1} name", source, f"s{s + 1}"))

    gravity = _vector(data.get("gravity"), "gravity", source, default=[0, 0, 0])
    options = data.get("options", {})
    if not isinstance(options, dict):
        raise SceneError(f"{source}: 'options' must be an object")
    _check_keys(options, set(_OPTION_KEYS), "'options'", source)
    options = {key: _boolean(value, f"options {key!r}", source) for key, value in options.items()}
    if not np.any(~fixed):
        raise SceneError(f"{source}: every mass is anchored; there is nothing to simulate")
    ground = _parse_ground(data["ground"], names, X0, fixed, source) if "ground" in data else None

    return Scene(
        name=_text(data.get("name", ABSENT), "the scene's name", source, "scene"),
        description=_text(data.get("description", ABSENT), "the scene's description", source, ""),
        mass_names=tuple(names),
        mass=_frozen(mass),
        fixed=_frozen_bool(fixed),
        k1=_frozen_int(k1),
        k2=_frozen_int(k2),
        length=_frozen(length),
        link_names=tuple(link_names),
        gravity=_frozen(gravity),
        force=_frozen(force),
        drag=_frozen(drag),
        quadratic_drag=_frozen(quadratic_drag),
        springs=Springs(_frozen_int(sa), _frozen_int(sb), _frozen(stiffness), _frozen(rest), _frozen(damping),
                        tuple(spring_names)),
        X0=_frozen(X0),
        U0=_frozen(U0),
        options=dict(options),
        driven=_frozen_bool(driven),
        motions=tuple(motions),
        rope=_frozen_bool(rope),
        restitution=_frozen(restitution),
        ground=ground,
    )


def _fraction(value, what: str, source: str) -> float:
    """A coefficient of restitution: a number in [0, 1] (1 reverses the whole approach velocity, 0 none of it)."""
    x = _number(value, what, source)
    if not 0.0 <= x <= 1.0:
        raise SceneError(f"{source}: {what} must lie in [0, 1] (the share of the approach velocity an impact "
                         f"reverses), got {value!r}")
    return x


def _parse_ground(entry, names, X0, fixed, source) -> Ground:
    """The "ground" section: a plane through "point" with "normal" towards the masses; no free mass may start below
    it (beyond round-off, GROUND_START_TOL)."""
    if not isinstance(entry, dict):
        raise SceneError(f"{source}: 'ground' must be an object with \"point\" and \"normal\", got {entry!r}")
    _check_keys(entry, _GROUND_KEYS, "'ground'", source)
    point = _vector(entry.get("point"), "ground point", source)
    normal = _vector(entry.get("normal"), "ground normal", source)
    size = float(np.linalg.norm(normal))
    if not size > 0:
        raise SceneError(f"{source}: ground normal must be a non-zero vector (the plane's normal, towards the "
                         f"masses), got {entry.get('normal')!r}")
    normal = normal / size
    restitution = _fraction(entry.get("restitution", 0.0), "ground restitution", source)
    friction = _number(entry.get("friction", 0.0), "ground friction", source, nonnegative=True)
    gaps = (X0 - point) @ normal
    scale = max(1.0, float(np.abs(X0).max()), float(np.abs(point).max()))
    below = np.flatnonzero(~fixed & (gaps < -GROUND_START_TOL * scale))
    if below.size:
        k = int(below[np.argmin(gaps[below])])
        raise SceneError(f'{source}: mass {k + 1} ("{names[k]}") starts {-gaps[k]:.6g} m below the ground (the plane '
                         f"through {point.tolist()} with normal {normal.tolist()}); free masses must start on or "
                         "above it")
    return Ground(_frozen(point), _frozen(normal), restitution, friction)
