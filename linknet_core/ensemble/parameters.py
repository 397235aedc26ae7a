"""What an ensemble varies: parameter names, their values, and the plan of members (grid x samples).

Names are the FMU's (docs/fmu.md), 1-based, with ``a..b`` for a range of indices that all take the same
value: ``M[3]``, ``R[1..10]``, ``g[3]``, ``F[11,3]`` (a constant input force, held over the whole run as
an FMU input would be), ``integrator``, ``step``, ``tolerance``. Names the FMU does not have (library
members only): ``X0[k,i]``, ``U0[k,i]`` (initial position and velocity), ``drag[k]``, and the spring-damper
constants ``stiffness[s]``, ``damping[s]``, ``rest_length[s]``.

This module only needs numpy: it is imported with ``linknet_core`` (which FMU hosts without Dask load too).
"""
from __future__ import annotations

import copy
import itertools
import re
from dataclasses import dataclass
from typing import Any, Mapping, Sequence

import numpy as np

from linknet_core.errors import LinknetError
from linknet_core.integrators import METHODS
from linknet_core.scene import Scene


@dataclass(frozen=True)
class Family:
    """One kind of parameter: ``M`` for masses, ``R`` for lengths, ..."""

    name: str
    slots: tuple[str, ...]  # what each index counts: "mass", "link", "axis", "spring"
    unit: str
    meaning: str
    in_fmu: bool  # the FMU has it as a parameter or input of the same name
    text: bool = False  # values are strings (the integrator's name)


FAMILIES = {f.name: f for f in (
    Family("M", ("mass",), "kg", "mass of free mass k", True),
    Family("R", ("link",), "m", "length of link l", True),
    Family("g", ("axis",), "m/s2", "gravitational acceleration, component i", True),
    Family("F", ("mass", "axis"), "N", "constant input force on free mass k, component i", True),
    Family("X0", ("mass", "axis"), "m", "initial position of mass k, component i", False),
    Family("U0", ("mass", "axis"), "m/s", "initial velocity of free mass k, component i", False),
    Family("drag", ("mass",), "N s/m", "viscous drag coefficient of free mass k", False),
    Family("stiffness", ("spring",), "N/m", "stiffness of spring s", False),
    Family("damping", ("spring",), "N s/m", "damping of spring s", False),
    Family("rest_length", ("spring",), "m", "rest length of spring s", False),
    Family("integrator", (), "", "integration method", True, text=True),
    Family("step", (), "s", "step of the fixed-step methods", True),
    Family("tolerance", (), "1", "relative tolerance of the adaptive methods", True),
)}

_NAME = re.compile(r"^(?P<family>[A-Za-z_][A-Za-z0-9_]*)(?:\[(?P<index>[^\]]*)\])?$")
_AXES = "xyz"


@dataclass(frozen=True)
class Parameter:
    """One varied name, resolved against a scene: which entries it sets (0-based index tuples)."""

    name: str  # as written, spaces removed: the dataset's coordinate name
    family: Family
    targets: tuple[tuple[int, ...], ...]

    @property
    def unit(self) -> str:
        return self.family.unit

    def fmu_variables(self) -> list[str]:
        """The FMU variables this parameter sets (1-based names)."""
        if not self.family.slots:
            return [self.family.name]
        return [f"{self.family.name}[{','.join(str(i + 1) for i in target)}]" for target in self.targets]

    def describe(self, scene: Scene) -> str:
        """Long name for the dataset: what it sets, with mass and link names."""
        where = [" ".join(_entry_label(scene, slot, i) for slot, i in zip(self.family.slots, target))
                 for target in self.targets[:3]]
        more = f" and {len(self.targets) - 3} more" if len(self.targets) > 3 else ""
        return self.family.meaning + (f": {', '.join(where)}{more}" if self.family.slots else "")


def _entry_label(scene: Scene, slot: str, i: int) -> str:
    if slot == "mass":
        return scene.mass_label(i)
    if slot == "link":
        return scene.link_label(i)
    return _AXES[i] if slot == "axis" else f"spring {i + 1}"


def _slot_range(text: str, slot: str, count: int, name: str) -> range:
    """'3' or '1..10' (1-based, inclusive) -> 0-based range, checked against the scene's count."""
    m = re.fullmatch(r"(\d+)(?:\.\.(\d+))?", text)
    if not m:
        raise LinknetError(f"parameter {name}: index {text!r} must be a number or a range a..b")
    first, last = int(m.group(1)), int(m.group(2) or m.group(1))
    plural = {"mass": "masses", "link": "links", "axis": "axes", "spring": "springs"}[slot]
    if not 1 <= first <= last <= count:
        raise LinknetError(f"parameter {name}: index {text} is outside 1..{count} (the scene has {count} {plural})"
                           if first <= last else f"parameter {name}: range {text} is empty")
    return range(first - 1, last)


def parse_name(name: str, scene: Scene) -> Parameter:
    """Resolve one parameter name against ``scene``; errors name the parameter and the rule."""
    compact = re.sub(r"\s+", "", str(name))
    m = _NAME.match(compact)
    family = FAMILIES.get(m.group("family")) if m else None
    if family is None:
        raise LinknetError(f"unknown parameter {name!r}; known: " + ", ".join(
            f"{f.name}[{','.join(f.slots)}]" if f.slots else f.name for f in FAMILIES.values()))
    index = m.group("index")
    if not family.slots:
        if index is not None:
            raise LinknetError(f"parameter {family.name} takes no index, got {name!r}")
        return Parameter(compact, family, ((),))
    items = [] if index is None else index.split(",")
    if len(items) != len(family.slots):
        raise LinknetError(f"parameter {name!r} needs {len(family.slots)} index(es): "
                           f"{family.name}[{','.join(family.slots)}]")
    counts = {"mass": scene.K, "link": scene.L, "axis": 3, "spring": scene.springs.count}
    ranges = [_slot_range(item, slot, counts[slot], compact) for item, slot in zip(items, family.slots)]
    targets = tuple(itertools.product(*ranges))
    if family.slots[0] == "mass" and family.name != "X0":
        anchored = [k for k, *_ in targets if scene.fixed[k]]
        if anchored:
            raise LinknetError(f"parameter {compact}: {scene.mass_label(anchored[0])} is anchored; "
                               f"{family.name} applies to free masses only")
    return Parameter(compact, family, targets)


def parse_values(text: str, parameter: Parameter) -> np.ndarray:
    """CLI value text: 'start:stop:count' (evenly spaced, both ends included), 'a,b,c', or one value."""
    text = text.strip()
    if parameter.family.text:
        return check_values(parameter, [v.strip() for v in text.split(",") if v.strip()])
    try:
        numbers = [float(v) for v in text.split(":" if ":" in text else ",")]
    except ValueError:
        numbers = []
    if not numbers or (":" in text and len(numbers) != 3):
        raise LinknetError(f"parameter {parameter.name}: cannot read values {text!r}; write start:stop:count, "
                           "a comma-separated list, or one number")
    if ":" not in text:
        return check_values(parameter, numbers)
    start, stop, count = numbers
    if count != int(count) or count < 1 or (count == 1 and start != stop):
        raise LinknetError(f"parameter {parameter.name}: {text!r} asks for {count:g} value(s) from {start:g} "
                           f"to {stop:g}; the count must be a whole number, at least 2 (or 1 with start = stop)")
    return check_values(parameter, np.linspace(start, stop, int(count)))


def check_values(parameter: Parameter, values) -> np.ndarray:
    """The values as a 1-D array (strings for the integrator, floats otherwise), with names checked. Numbers
    are not range-checked here: a value that makes an invalid scene is that member's recorded error."""
    if parameter.family.text:
        values = np.atleast_1d(np.asarray(values, dtype=object)).astype(str)
        unknown = sorted({str(v) for v in values} - set(METHODS))  # plain strings, not np.str_('rk99')
        if unknown:
            raise LinknetError(f"parameter integrator: unknown method(s) {', '.join(map(repr, unknown))}; "
                               f"choose from {', '.join(sorted(METHODS))}")
        return values
    try:
        values = np.atleast_1d(np.asarray(values, dtype=float))
    except (TypeError, ValueError):
        raise LinknetError(f"parameter {parameter.name}: values must be numbers, got {values!r}") from None
    if values.ndim != 1 or values.size == 0:
        raise LinknetError(f"parameter {parameter.name}: give a non-empty 1-D list of values")
    return values


@dataclass(frozen=True)
class Plan:
    """The members of a study: a full factorial grid (``vary``) times a list of parameter sets (``samples``).

    Member i has the value ``values[name][i]`` of every varied parameter; the grid runs in C order (the
    first ``vary`` entry slowest), each grid point taking every sample in turn.
    """

    parameters: tuple[Parameter, ...]
    values: dict[str, np.ndarray]
    grid_shape: tuple[int, ...]  # lengths of the ``vary`` axes, in order
    n_samples: int  # 1 without samples

    @property
    def n_members(self) -> int:
        return int(np.prod(self.grid_shape, dtype=np.int64)) * self.n_samples

    def setting(self, i: int) -> dict[str, Any]:
        """Member i's values, by parameter name (plain Python numbers and strings)."""
        return {p.name: self.values[p.name][i].item() for p in self.parameters}

    def check_fmu(self, atol: float | None) -> None:
        """Refuse, before any member runs, what an FMU cannot be given."""
        missing = [p.name for p in self.parameters if not p.family.in_fmu]
        if missing:
            raise LinknetError(f"the FMU has no parameter for {', '.join(missing)}; an FMU study can vary "
                               + ", ".join(f.name for f in FAMILIES.values() if f.in_fmu)
                               + " (run the study on the scene instead)")
        if atol is not None:
            raise LinknetError("the FMU has no absolute tolerance parameter; leave atol unset for an FMU study")


def _as_samples(samples) -> dict[str, list]:
    """Samples given as {name: values}, a list of {name: value} dicts, or a table with columns (pandas)."""
    if samples is None:
        return {}
    if hasattr(samples, "to_dict") and hasattr(samples, "columns"):  # a pandas DataFrame
        return {str(c): list(samples[c]) for c in samples.columns}
    if isinstance(samples, Mapping):
        return {str(k): list(np.atleast_1d(np.asarray(v, dtype=object))) for k, v in samples.items()}
    rows = list(samples)
    if not rows or not all(isinstance(r, Mapping) for r in rows):
        raise LinknetError("samples must be a dict of equal-length value lists, a list of dicts, or a DataFrame")
    names = list(rows[0])
    for n, row in enumerate(rows):
        if list(row) != names:
            raise LinknetError(f"sample {n} sets {sorted(row)}, but sample 0 sets {sorted(names)}; "
                               "every sample must set the same parameters")
    return {name: [row[name] for row in rows] for name in names}


# a study varies something: the rule of ln.ensemble and of linknet ensemble (whose options the text names too)
NOTHING_TO_VARY = ("nothing to vary: a study needs a varied parameter, vary={NAME: VALUES} or samples (on the command "
                   "line --vary NAME=VALUES, --sample or --samples)")


def make_plan(scene: Scene, vary: Mapping | None = None, samples=None) -> Plan:
    """Resolve the names against ``scene`` and lay out the members; errors say which parameter and why."""
    vary = dict(vary or {})
    columns = _as_samples(samples)
    if not vary and not columns:
        raise LinknetError(NOTHING_TO_VARY)
    parameters: list[Parameter] = []
    grid_values: list[np.ndarray] = []
    sample_values: list[np.ndarray] = []
    for name, values in vary.items():
        p = parse_name(name, scene)
        parameters.append(p)
        grid_values.append(check_values(p, values))
    lengths = set()
    for name, values in columns.items():
        p = parse_name(name, scene)
        parameters.append(p)
        sample_values.append(check_values(p, values))
        lengths.add(len(values))
    if len(lengths) > 1:
        raise LinknetError(f"samples have different lengths {sorted(lengths)}; every parameter needs one value "
                           "per sample")
    _refuse_overlaps(parameters)
    grid_shape = tuple(v.size for v in grid_values)
    n_samples = lengths.pop() if lengths else 1
    n_grid = int(np.prod(grid_shape, dtype=np.int64))
    if n_grid * n_samples == 0:
        raise LinknetError("the study has no members")
    values: dict[str, np.ndarray] = {}
    if grid_values:
        mesh = np.meshgrid(*[np.arange(n) for n in grid_shape], indexing="ij")
        for p, v, idx in zip(parameters, grid_values, mesh):
            values[p.name] = np.repeat(v[idx.ravel()], n_samples)
    for p, v in zip(parameters[len(grid_values):], sample_values):
        values[p.name] = np.tile(v, n_grid)
    return Plan(tuple(parameters), values, grid_shape, n_samples if columns else 1)


def _refuse_overlaps(parameters: Sequence[Parameter]) -> None:
    """Two names setting the same entry (``R[1..10]`` and ``R[3]``) would leave the value to their order."""
    owner: dict[tuple, str] = {}
    for p in parameters:
        for target in p.targets:
            key = (p.family.name, target)
            if key in owner:
                raise LinknetError(f"parameters {owner[key]} and {p.name} both set "
                                   f"{p.fmu_variables()[p.targets.index(target)]}; vary each entry once")
            owner[key] = p.name


# ---- applying a member's values ------------------------------------------------------------------------

_SCENE_FAMILIES = {"M", "R", "g", "X0", "U0", "drag", "stiffness", "damping", "rest_length"}


def member_scene(base: dict, parameters: Sequence[Parameter], setting: Mapping[str, Any]) -> dict | None:
    """The scene dictionary (``Scene.to_dict`` form) with the member's values written in, or None when the
    member changes nothing in the scene (only solver settings or input forces)."""
    changes = [p for p in parameters if p.family.name in _SCENE_FAMILIES]
    if not changes:
        return None
    data = copy.deepcopy(base)
    masses, links, springs = data["masses"], data["links"], data.get("springs", [])
    for p in changes:
        value = float(setting[p.name])
        for target in p.targets:
            family = p.family.name
            if family == "M":
                masses[target[0]]["mass"] = value
            elif family == "R":
                links[target[0]]["length"] = value
            elif family == "g":
                data.setdefault("gravity", [0.0, 0.0, 0.0])[target[0]] = value
            elif family in ("X0", "U0"):
                key = "position" if family == "X0" else "velocity"
                masses[target[0]].setdefault(key, [0.0, 0.0, 0.0])[target[1]] = value
            elif family == "drag":
                masses[target[0]]["drag"] = value
            else:  # a spring constant: the family's name is the scene file's key
                springs[target[0]][family] = value
    return data


def member_forces(parameters: Sequence[Parameter], setting: Mapping[str, Any], K: int) -> np.ndarray | None:
    """The constant input forces (K, 3) of a member, or None when it sets none."""
    forces = None
    for p in parameters:
        if p.family.name == "F":
            if forces is None:
                forces = np.zeros((K, 3))
            for k, i in p.targets:
                forces[k, i] = float(setting[p.name])
    return forces


def changes_positions(parameters: Sequence[Parameter]) -> bool:
    """Whether the members' initial positions can break the link lengths (R or X0 varied)."""
    return any(p.family.name in ("R", "X0") for p in parameters)

