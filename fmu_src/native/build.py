"""Build the self-contained FMI 2.0 Co-Simulation FMU of a scene on the native C core (`build_fmu.py --native`).

The FMU holds no Python. It is made of three parts:

* sources/: the same for every scene. The native core, linknet_core/native/src, copied as it is into
  sources/linknet/ (every .c file that no other .c file includes is a translation unit, so the DIM-generic stages
  come in through dim2.c/dim3.c and AMD through its amd_l*.c wrappers); the FMI glue beside it, fmu_src/native's
  fmi2Functions.c (FMI only), linknet_model.c (the core as the glue's model, fmu_model.h), lnfmu_scene.c (the
  scene read from the resource) and fmu_resource.c (the resource file read and checked), with their headers; at the
  top, one two-line file per translation unit (linknet_fmu_unit.h, then the unit: only the fmi2 functions leave the
  binary, however it is built) and a CMakeLists.txt.
* binaries/ (PLATFORMS: linux64, win64, darwin64, aarch64-linux; --platforms chooses): compiled from sources/ with
  Zig's C compiler (PyPI's ziglang), as a tool would compile them. Since the sources are the same for every scene,
  so are the binaries: each platform's binary is built once per content of the sources, compiler and flags and then
  taken from a per-user cache (LINKNET_FMU_CACHE, default ~/.cache/linknet/native-fmu), so that a further scene
  compiles nothing; its objects are kept by what each unit reads, so that the FMI 2.0 and FMI 3.0 FMUs share all
  but their glue's.
* resources/linknet_scene.bin: the scene as data (fmu_resource.h gives the format), read when the FMU is
  instantiated. The ln_model and every integrator's ln_method are written field by field from the structs
  linknet_core's own Simulator hands the core for this scene (the core's lists of their fields, ln_model_fields.h,
  through the library's table of them), so the FMU at its default parameters runs the library's arithmetic bit for
  bit; then what a changed mass, length or gravity needs, the initial state and internals, and the variable table of
  fmu_src/linknet_fmu/layout.py (the same Layout the pythonfmu FMU uses), as lnfmu_scene.h lists them.

The top-level .c files are the <SourceFiles>, so `cc -shared -fPIC sources/*.c -lm` builds the binary on any
platform, and that binary reads the same resource. The modelDescription.xml is written by
build_fmu.finish_model_description, as the pythonfmu FMU's is: the two agree on variables, units, types,
DefaultExperiment and ModelStructure.
"""
from __future__ import annotations

import contextlib
import ctypes
import datetime
import hashlib
import importlib
import importlib.util
import math
import os
import platform
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import uuid
import zipfile
import zlib
from lxml import etree as ET  # fmpy's dependency: a large net's modelDescription written at C speed
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:  # fmu_src: the layout both FMU kinds share
    sys.path.insert(0, str(HERE.parent))
from linknet_fmu.layout import (ERROR_ESTIMATE_CATEGORY, ERROR_ESTIMATE_CATEGORY_DESCRIPTION,  # noqa: E402
                                ESTIMATE_ERROR_DESCRIPTION, EVENT_CATEGORY, EVENT_CATEGORY_DESCRIPTION)

GLUE_FILES = ("fmi2Functions.c", "linknet_model.c", "lnfmu_scene.c", "fmu_resource.c", "fmi2_api.h", "fmu_model.h",
              "fmu_states.h", "lnfmu_scene.h", "fmu_resource.h")
PROGRESS_VARIABLES = 100_000  # a scene with this many FMU variables builds for many seconds: progress lines
# as setup.py compiles the core for the library: the same code generation, so the same results
CFLAGS = ["-std=c99", "-O3", "-fno-math-errno", "-ffp-contract=off"]
WARNINGS = ["-Wall", "-Wextra"]
LOG_CATEGORIES = (("logStatusWarning", "Log messages with fmi2Warning status."),
                  ("logStatusDiscard", "Log messages with fmi2Discard status."),
                  ("logStatusError", "Log messages with fmi2Error status."),
                  ("logStatusFatal", "Log messages with fmi2Fatal status (never sent by this FMU)."),
                  ("logAll", "Log all messages."),
                  (ERROR_ESTIMATE_CATEGORY, ERROR_ESTIMATE_CATEGORY_DESCRIPTION))


def log_categories(layout) -> tuple:
    """The FMU's log categories: LOG_CATEGORIES, and the events' where the scene has ropes (one message per event
    of a doStep; the glue accepts it in SetDebugLogging for these FMUs only, fmi2_api.h) where it has ropes or a
    ground, in the pythonfmu FMU's order."""
    if layout.rope_links.size or layout.ground_masses.size:
        return LOG_CATEGORIES + ((EVENT_CATEGORY, EVENT_CATEGORY_DESCRIPTION),)
    return LOG_CATEGORIES


class NativeBuildError(RuntimeError):
    """The native FMU cannot be built (message says why)."""


# ---------------------------------------------------------------------------- the core's sources
def core_source_dir() -> Path:
    import linknet_core.clib.library as library  # where the package's native sources are
    return Path(library.SOURCE_DIR)


def translation_units(src: Path) -> list[str]:
    """The .c files under src (relative paths) that no other source file (.c or .h) includes: the ones to
    compile."""
    files = sorted(p for p in src.rglob("*.c") if "__pycache__" not in p.parts)
    included = set()
    for p in sorted(p for p in src.rglob("*.[ch]") if "__pycache__" not in p.parts):
        for name in re.findall(r'^\s*#\s*include\s+"([^"]+\.c)"', p.read_text(errors="replace"), re.M):
            included.add((p.parent / name).resolve())
    return [p.relative_to(src).as_posix() for p in files if p.resolve() not in included]


# ---------------------------------------------------------------------------- what the C side defines, read from it
def _header_value(path: Path, pattern: str, what: str) -> list:
    """Every match of pattern in a header, or NativeBuildError naming what build.py looked for."""
    found = re.findall(pattern, path.read_text(), re.M)
    if not found:
        raise NativeBuildError(f"{path.name} no longer defines {what}: teach fmu_src/native/build.py")
    return found


def _macro_body(text: str, name: str) -> str:
    """The body of a multi-line #define (its continuation lines joined), comments removed."""
    m = re.search(rf"^#define\s+{name}\b\(.*?\)(.*?[^\\])$", text, re.M | re.S)
    if not m:
        raise NativeBuildError(f"no list {name}: teach fmu_src/native/build.py")
    return re.sub(r"/\*.*?\*/", " ", m.group(1).replace("\\\n", " "), flags=re.S)


def resource_format() -> tuple[str, int]:
    """The resource file's name and format version, as fmu_resource.h defines them (its reader's)."""
    header = HERE / "fmu_resource.h"
    name = _header_value(header, r'^#define\s+FMU_RESOURCE_FILE\s+"([^"]+)"', "FMU_RESOURCE_FILE")[0]
    version = int(_header_value(header, r"^#define\s+FMU_RESOURCE_FORMAT\s+(\d+)", "FMU_RESOURCE_FORMAT")[0])
    return name, version


def event_kinds() -> tuple[list[str], list[int]]:
    """The names of the core's kinds of events (enum ln_event_kind of linknet.h, in its order) as the library names
    them (linknet_core.clib.library.EVENT_KINDS, which gives the library's events their kinds), and for each 1 where
    its event's index is a link, 0 a mass (rope_events.LINK_KINDS): what the native FMU's log words them by, as the
    pythonfmu FMU's rope_events.event_message does. NativeBuildError where the enum and the library's names differ."""
    from linknet_core.clib import library
    from linknet_fmu.rope_events import LINK_KINDS
    header = core_source_dir() / "linknet.h"
    enum = re.search(r"enum\s+ln_event_kind\s*\{(.*?)\}", header.read_text(), re.S)
    if not enum:
        raise NativeBuildError("linknet.h no longer defines enum ln_event_kind: teach fmu_src/native/build.py")
    codes = {name.lower(): int(code) for name, code in
             re.findall(r"LN_EVENT_(\w+)\s*=\s*(\d+)", re.sub(r"/\*.*?\*/", " ", enum.group(1), flags=re.S))}
    names = list(library.EVENT_KINDS)
    if codes != {name: code for code, name in enumerate(names)}:
        raise NativeBuildError(f"enum ln_event_kind of linknet.h ({codes}) and linknet_core.clib.library.EVENT_KINDS "
                               f"({names}) name the events differently: keep them in step")
    return names, [int(name in LINK_KINDS) for name in names]


def state_format() -> int:
    """FMU_STATE_FORMAT of fmu_states.h: a part of the FMU's fingerprint, so that states of other formats are
    refused."""
    return int(_header_value(HERE / "fmu_states.h", r"^#define\s+FMU_STATE_FORMAT\s+(\d+)u?", "FMU_STATE_FORMAT")[0])


def variable_kinds() -> dict[str, int]:
    """enum lnfmu_kind of lnfmu_scene.h: a Real variable's kind by its name there (F, FREACT, G, ERROR_ESTIMATE)."""
    text = (HERE / "lnfmu_scene.h").read_text()
    m = re.search(r"enum\s+lnfmu_kind\s*\{(.*?)\};", text, re.S)
    if not m:
        raise NativeBuildError("lnfmu_scene.h no longer has enum lnfmu_kind: teach fmu_src/native/build.py")
    return {name: int(value) for name, value in re.findall(r"LNFMU_(\w+)\s*=\s*(\d+)", m.group(1))}


def field_codes() -> dict[str, str]:
    """LN_FIELD_CODE of each C type of the lists (ln_model_fields.h): 'q' for ln_int, ..."""
    found = _header_value(core_source_dir() / "ln_model_fields.h", r"^#define\s+LN_FIELD_CODE_(\w+)\s+'(.)'",
                          "LN_FIELD_CODE")
    return dict(found)


def scene_fields() -> list[tuple[str, str, str]]:
    """(kind, C type, name) of each entry of LNFMU_SCENE_FIELDS (lnfmu_scene.h), in order; kind SCALAR, ARRAY,
    OPTIONAL, FIXED, TEXT or TEXTS (type "char" for the texts)."""
    body = _macro_body((HERE / "lnfmu_scene.h").read_text(), "LNFMU_SCENE_FIELDS")
    out = []
    for kind, args in re.findall(r"\b(SCALAR|ARRAY|OPTIONAL|FIXED|TEXTS|TEXT)\s*\(([^()]*(?:\([^()]*\)[^()]*)*)\)",
                                 body):
        parts = [p.strip() for p in args.split(",")]
        out.append((kind, "char", parts[0]) if kind.startswith("TEXT") else (kind, parts[0], parts[1]))
    return out


# ---------------------------------------------------------------------------- the resource file
class Resource:
    """The FMU's resource file (fmu_resource.h describes the format): named arrays, each of one type code."""

    HEADER, ENTRY, NAME = 48, 64, 40
    SIZES = {"q": 8, "i": 4, "d": 8, "B": 1, "Q": 8, "c": 1}

    def __init__(self):
        self.entries: dict[str, tuple[str, int, bytes]] = {}  # name -> (code, count, data)

    def add(self, name: str, code: str, values) -> None:
        if name in self.entries:
            raise NativeBuildError(f"the resource's entry {name} is written twice")
        if len(name.encode()) >= self.NAME:
            raise NativeBuildError(f"the resource's entry name {name!r} is too long ({self.NAME - 1} bytes at most)")
        array = np.ascontiguousarray(values, dtype=np.dtype(code).newbyteorder("<")).ravel()
        self.entries[name] = (code, array.size, array.tobytes())

    def texts(self, name: str, items) -> None:
        """A list of texts, each ending with a NUL (a text with a NUL inside it is refused)."""
        encoded = [str(s).encode() for s in items]
        if any(b"\0" in s for s in encoded):
            raise NativeBuildError(f"the resource's entry {name}: a text holds a NUL character")
        data = b"".join(s + b"\0" for s in encoded)
        self.entries[name] = ("c", len(data), data)

    def struct(self, prefix: str, which: int, value, model=None) -> None:
        """Every field of a core struct (ctypes mirror ``value``; ``model``: the ln_model it belongs to) as
        "<prefix>.<field>", from the library's table of the struct's fields: a pointer field's entries are as many
        as the core's list says (ln_struct_field_count), none where it is NULL; an opaque pointer is not data."""
        from linknet_core.clib import library
        address = ctypes.addressof(value)
        model_address = ctypes.addressof(model if model is not None else value)
        for i, f in enumerate(library.struct_fields(which)):
            name = f"{prefix}.{f.name}"
            if f.kind == library.FIELD_OPAQUE:
                continue
            if f.kind == library.FIELD_ARRAY:
                count = library.struct_field_count(which, i, address, model_address)
                pointer = ctypes.cast(getattr(value, f.name), ctypes.c_void_p).value
                data = ctypes.string_at(pointer, count * f.size) if pointer and count > 0 else b""
                self.entries[name] = (f.code, len(data) // f.size, data)
            elif f.kind == library.FIELD_FIXED:
                self.add(name, f.code, list(getattr(value, f.name)))
            else:
                self.add(name, f.code, [getattr(value, f.name)])

    def digest(self, *prefix: bytes) -> bytes:
        """16 bytes of the prefix and every entry (name, type, data) in order."""
        h = hashlib.blake2b(digest_size=16)
        for p in prefix:
            h.update(p)
        for name, (code, count, data) in self.entries.items():
            h.update(f"{name}\0{code}\0{count}\0".encode())
            h.update(data)
        return h.digest()

    def to_bytes(self) -> bytes:
        _, version = resource_format()
        table, parts = [], []
        offset = self.HEADER + self.ENTRY * len(self.entries)
        for name, (code, count, data) in self.entries.items():
            table.append(struct.pack("<40sIIQQ", name.encode(), ord(code), self.SIZES[code], count, offset))
            pad = -len(data) % 8
            parts.append(data + b"\0" * pad)
            offset += len(data) + pad
        body = b"".join(table + parts)
        head = struct.pack("<8sIIQIIIIQ", b"LNKSCENE", version, 0x01020304, self.HEADER + len(body),
                           len(self.entries), self.ENTRY, zlib.crc32(body), 0, 0)
        return head + body


# ---------------------------------------------------------------------------- the scene as data
def library_tolerance_range() -> tuple[float, float]:
    """[min, max) of an adaptive method's rtol, as linknet_core.integrators checks it."""
    import linknet_core.integrators as integrators
    return float(getattr(integrators, "RTOL_MIN", 1e-15)), float(getattr(integrators, "RTOL_MAX", 0.1))


def _simulators(scene, cfg):
    """One linknet_core Simulator per integrator, as the pythonfmu FMU builds them (dt = step, or rtol =
    tolerance), each on the scene's own Dynamics: the structure, and the initial state with its checks, are the
    scene's and computed once for all of them (kept per scene object by the library)."""
    import linknet_core as ln
    sims = {}
    for name in [cfg["integrator"]] + [n for n in cfg["integrators"] if n != cfg["integrator"]]:
        kwargs = dict(rtol=cfg["tolerance"]) if ln.METHODS[name].adaptive else dict(dt=cfg["step"])
        # the scene data's model and methods are the run's; the companion's are made from them in C (linknet_model.c)
        sims[name] = ln.Simulator(scene, method=name, error_estimate=False, backend="native", **kwargs)
    return sims


def _pointer_values(ptr, n: int, ctype):
    if not ptr or n == 0:
        return None
    return np.ctypeslib.as_array(ctypes.cast(ptr, ctypes.POINTER(ctype)), (n,)).copy()


@dataclass(frozen=True)
class VariableFamily:
    """A family of the Layout's Real variables (fmu_src/linknet_fmu/layout.py) that has the shape of an array: one
    quantity of each of a list of masses (x, y, z columns, or one value each), of each link, or of each axis."""

    name: str                   # the Layout's name of its variables (F of F[k,i]), the FMI 3.0 array's name
    kind: str                   # its code's name in enum lnfmu_kind (lnfmu_scene.h): what the C side reads
    vrs: str                    # the Layout's attribute of its value references: (rows, 3) or (rows,)
    masses: str | None          # the Layout's attribute of the masses its rows are; None: links or axes, in order
    among: str | None           # the rows the C side numbers them by: the mass's row in ln_model.fixed_idx ("fixed")
    #                             or driven_idx ("driven"), its ground contact's link in the model ("contacts"); None:
    #                             the mass itself
    description: str            # the whole family, as the FMI 3.0 array variable describes it
    links: str | None = None    # the Layout's attribute of the links its rows are (masses None); None with masses
    #                             None: every link or axis, in order


_HELD = "held constant over each communication step"
_MOTION = ("the anchor moves as P + V tau + A tau^2/2, tau from the communication point where they were set, until "
           "they are set again")
# in the Layout's order of value references
VARIABLE_FAMILIES = (
    VariableFamily("F", "F", "F_vr", "input_masses", None,
                   f"external forces on the masses (N), columns x, y, z, {_HELD}"),
    VariableFamily("P", "P", "P_vr", "anchor_inputs", "driven",
                   f"positions of the input-driven anchors (m); {_MOTION}"),
    VariableFamily("V", "V", "V_vr", "anchor_inputs", "driven",
                   f"velocities of the input-driven anchors (m/s); {_MOTION}"),
    VariableFamily("A", "A", "A_vr", "anchor_inputs", "driven",
                   f"accelerations of the input-driven anchors (m/s2); {_MOTION}"),
    VariableFamily("X", "X", "X_vr", "output_masses", None, "positions of the masses (m), columns x, y, z"),
    VariableFamily("U", "U", "U_vr", "output_masses", None, "velocities of the masses (m/s), columns x, y, z"),
    VariableFamily("T", "T", "T_vr", None, None, "tensions in the links (N), in the scene's link order; > 0 pulls the "
                   "masses together; each depends directly on the inputs of its group of links"),
    VariableFamily("T_peak", "T_PEAK", "T_peak_vr", None, None, "each link's largest tension in magnitude over the "
                   "last communication step (N), signed, located between the integrator's steps; before the first "
                   "step, T"),
    VariableFamily("T_peak_time", "T_PEAK_TIME", "T_peak_time_vr", None, None, "when each T_peak occurred (s)"),
    VariableFamily("Freact", "FREACT", "Freact_vr", "fixed_indices", "fixed",
                   "forces the network exerts on the anchored masses (N)"),
    VariableFamily("Jreact", "JREACT", "Jreact_vr", "driven_indices", "driven",
                   "impulses the network gave the driven anchors over the last communication step (N.s): a jump of "
                   "their motion at its start and every rope or ground event in it (a rope jerked taut); 0 if none"),
    VariableFamily("slack", "SLACK", "slack_vr", None, None, "1 where a rope is slack (carries no tension: its T is "
                   "0), 0 where it is taut", links="rope_links"),
    VariableFamily("Jrope", "JROPE", "Jrope_vr", None, None, "each rope's impulse of coming taut (its jerks) within "
                   "the last communication step, summed (N.s); 0 if none", links="rope_links"),
    VariableFamily("Jground", "JROPE", "Jground_vr", "ground_masses", "contacts", "the ground's normal impulse on "
                   "each free mass landing within the last communication step, summed (N.s); 0 if none"),
    VariableFamily("M", "M", "M_vr", "free_indices", None, "masses of the free masses (kg, > 0)"),
    VariableFamily("R", "R", "R_vr", None, None, "lengths of the links (m, > 0; the initial positions must satisfy "
                   "them), in the scene's link order"),
    VariableFamily("g", "G", "g_vr", None, None, "gravitational acceleration (m/s2), x, y, z"),
)
# the Layout's single Real variables: the Layout's attribute of the value reference, the code's name in enum lnfmu_kind
SCALAR_VARIABLES = (("error_estimate_vr", "ERROR_ESTIMATE"), ("tolerance_vr", "TOLERANCE"), ("step_vr", "STEP"))


def variable_table(layout, model) -> tuple[np.ndarray, np.ndarray]:
    """(kind, index) of every Real variable by value reference (enum lnfmu_kind of lnfmu_scene.h: what the variable
    is, and its index into the model's arrays)."""
    kinds = variable_kinds()
    n_fixed, n_driven = int(model.n_fixed), int(model.n_driven)
    kind = np.full(layout.n_real, -1, np.int32)
    index = np.full(layout.n_real, -1, np.int64)
    row_of = {}  # mass -> its row among the anchors (fixed_idx) and among the driven anchors (driven_idx)
    for name, ptr, n in (("fixed", model.fixed_idx, n_fixed), ("driven", model.driven_idx, n_driven)):
        rows = np.full(int(model.K), -1, np.int64)
        values = _pointer_values(ptr, n, ctypes.c_int64)
        if values is not None:
            rows[values] = np.arange(n)
        row_of[name] = rows
    # a ground's contacts are the model's links after the scene's own, one per mass of contact_mass
    # (unilateral.native_ground_scene)
    n_contacts = int(model.n_contacts)
    contacts = np.full(int(model.K), -1, np.int64)
    masses = _pointer_values(model.contact_mass, n_contacts, ctypes.c_int64)
    if masses is not None:
        contacts[masses] = layout.L + np.arange(n_contacts)
    row_of["contacts"] = contacts

    def put(name, vrs, idx):
        vrs = np.asarray(vrs, np.int64)
        if vrs.size:
            kind[vrs.ravel()] = kinds[name]
            index[vrs.ravel()] = np.broadcast_to(np.asarray(idx, np.int64), vrs.shape).ravel()

    for family in VARIABLE_FAMILIES:
        vrs = np.asarray(getattr(layout, family.vrs), np.int64)
        if family.links is not None:  # some links: the link's number
            rows = np.asarray(getattr(layout, family.links), np.int64)
        elif family.masses is None:  # links or axes, in order
            rows = np.arange(vrs.shape[0], dtype=np.int64)
        else:
            rows = np.asarray(getattr(layout, family.masses), np.int64)
            if family.among is not None:
                rows = row_of[family.among][rows]
        # a row of x, y, z columns is three entries of the C side's (rows, 3) array
        put(family.kind, vrs, 3 * rows.reshape(-1, 1) + np.arange(3) if vrs.ndim == 2 else rows)
    for attribute, name in SCALAR_VARIABLES:
        put(name, [getattr(layout, attribute)], [0])
    if (kind < 0).any() or (index < 0).any():
        raise NativeBuildError("the layout's Real variables are not all mapped: teach fmu_src/native/build.py")
    return kind, index


def scene_resource(scene, cfg, layout) -> tuple[Resource, dict]:
    """The scene's resource (without its identity, scene.guid and scene.fingerprint: build_native_fmu adds them) and
    facts about the scene for the caller."""
    import linknet_core as ln
    from linknet_core.clib import library
    from linknet_core.clib.ldl import package_library
    from linknet_core.dynamics.unilateral import linearization_refusal

    sims = _simulators(scene, cfg)
    sim = sims[cfg["integrator"]]
    integ = sim.integrator
    kind = sim.specialisation.kind
    spec = {"none": 0, "static": 1, "rigid": 2}.get(kind)
    if spec is None:
        raise NativeBuildError(f"unknown specialisation {kind!r} of the Simulator: teach fmu_src/native/build.py")
    if sim.state.t != 0.0:
        raise NativeBuildError("the Simulator does not start at t = 0")
    model = integ.model.struct
    K, L = int(model.K), int(model.L)
    # the scene the core runs: with a ground, its masses and links then a virtual anchor and a contact link per free
    # mass (unilateral.native_ground_scene); the FMU's variables are the scene's own rows of it (variable_table)
    core_scene = getattr(integ.model, "ground_scene", None) or scene
    values = dict(model_identifier=cfg["model_identifier"], scene_name=str(scene.name), K=K, L=L, own_K=scene.K,
                  mass_names=list(core_scene.mass_names), mass=core_scene.mass, length=core_scene.length,
                  gravity=core_scene.gravity, force=core_scene.force, X0=core_scene.X0, U0=core_scene.U0,
                  project_initial=int(bool(scene.options.get("project_initial_positions", False))),
                  length_tol=sim.settings.length_tol)  # the run's own rule for the initial lengths
    values["tolerance_min"], values["tolerance_max"] = library_tolerance_range()
    values["max_force"] = float(getattr(importlib.import_module(ln.Simulator.__module__), "MAX_FORCE", 0.0))
    values["linearization_refusal"] = linearization_refusal(scene)
    values["event_kind_names"], values["event_names_link"] = event_kinds()
    values["n_event_kinds"] = len(values["event_kind_names"])
    # the elimination order the sparse LDL^T was analysed in (analysed again at instantiation with ln_ldl_analyse)
    values["ldl_ordering"] = []
    if model.ldl:
        order = np.zeros(L, np.int64)
        package_library().ln_ldl_get_ordering(model.ldl, order.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)))
        values["ldl_ordering"] = order
    values["specialisation"] = spec
    values["n_bodies"], values["Y0"] = 0, []
    resource = Resource()
    rigid = None
    if spec == 2:
        rigid = integ.rigid.struct
        values["n_bodies"], values["Y0"] = int(rigid.n_bodies), integ.body_states()
    internals = integ.internals()["native"]
    # the core's rows (the anchors' too, which the core places before each evaluation), the scene's = sim.state's
    X_init, U_init = (integ.data.X.copy(), integ.data.U.copy()) if core_scene is not scene else (sim.state.X,
                                                                                                sim.state.U)
    if not (np.array_equal(X_init[:scene.K], sim.state.X) and np.array_equal(U_init[:scene.K], sim.state.U)):
        raise NativeBuildError("the core's initial state is not the Simulator's: teach fmu_src/native/build.py")
    values.update(X_init=X_init, U_init=U_init, h_next_init=internals.h_next,
                  planar_init=int(internals.planar), max_steps=int(sim.max_steps_per_call))
    names = list(cfg["integrators"])
    values.update(n_methods=len(names), method_names=names,
                  method_adaptive=[int(bool(ln.METHODS[n].adaptive)) for n in names],
                  method_order=[int(ln.METHODS[n].order) for n in names],
                  default_method=names.index(cfg["integrator"]), default_step=cfg["step"],
                  default_tolerance=cfg["tolerance"], default_estimate=int(bool(cfg.get("error_estimate", True))))
    values["variable_kind"], values["variable_index"] = variable_table(layout, model)
    values.update(n_real=layout.n_real, variable_names=[v.name for v in layout.reals])
    unknown = sorted(name for name, value in values.items() if value is None)
    if unknown:  # a field of the list that neither the library's table nor build.py gives a value
        raise NativeBuildError(f"the scene's resource: no value for {', '.join(unknown)}: teach fmu_src/native/build.py")
    identity = {"guid", "fingerprint"}  # added by build_native_fmu, from the digest of everything else
    codes = field_codes()
    listed = scene_fields()
    missing = {name for _, _, name in listed} - identity - set(values)
    unknown = set(values) - {name for _, _, name in listed}
    if missing or unknown:
        raise NativeBuildError(f"the scene's resource and lnfmu_scene.h's LNFMU_SCENE_FIELDS disagree (not written: "
                               f"{sorted(missing)}, not listed: {sorted(unknown)}): teach fmu_src/native/build.py")
    for kind_, ctype, name in listed:
        if name in identity:
            continue
        if kind_ == "TEXT":
            resource.texts(f"scene.{name}", [values[name]])
        elif kind_ == "TEXTS":
            resource.texts(f"scene.{name}", values[name])
        else:
            resource.add(f"scene.{name}", codes[ctype], values[name])
    resource.struct("model", library.MODEL_STRUCT, model)
    if rigid is not None:
        resource.struct("rigid", library.RIGID_MODEL_STRUCT, rigid, model)
    for i, name in enumerate(names):
        resource.struct(f"method{i}", library.METHOD_STRUCT, sims[name].integrator.method.struct, model)
    facts = dict(specialisation=kind, solver=int(model.solver), K=K, L=L, bodies=int(values["n_bodies"]),
                 planar=bool(model.planar), linearization_refusal=values["linearization_refusal"])
    return resource, facts


def with_identity(resource: Resource, sources_digest: bytes) -> tuple[bytes, str]:
    """The resource file with its identity (scene.guid, scene.fingerprint) and the GUID: 16 bytes of the state
    format, the sources and the scene's data, so another scene, other options, another FMI version or other sources
    give another GUID (and FMU states that the others refuse)."""
    digest = resource.digest(f"linknet native FMU state format {state_format()}\n".encode(), sources_digest)
    guid = "{" + str(uuid.UUID(bytes=digest)) + "}"
    identity = Resource()
    identity.texts("scene.guid", [guid])
    identity.add("scene.fingerprint", "Q", [int.from_bytes(digest[:8], "little")])
    ordered = Resource()  # the identity where lnfmu_scene.h lists it: the reader finds entries by name, a reader of
    listed = [f"scene.{name}" for _, _, name in scene_fields()]  # the file by eye reads them in the list's order
    for name in listed + [n for n in resource.entries if n not in listed]:
        source = identity if name in identity.entries else resource
        if name in source.entries:
            ordered.entries[name] = source.entries[name]
    return ordered.to_bytes(), guid

# ---------------------------------------------------------------------------- modelDescription.xml
def _start(value: float) -> str:
    """pythonfmu's format (16 significant digits) where it is exact, else 17."""
    text = f"{value:.16g}"
    return text if float(text) == value else f"{value:.17g}"


def model_description_parts(cfg, layout, guid: str, sources: list[str], start_values: dict) -> tuple:
    """The modelDescription's header (an lxml fmiModelDescription with CoSimulation and LogCategories) and its
    variables as build_fmu.finish_model_description takes them: the pythonfmu FMU's variables (same names, order,
    value references, attributes), to which it adds units, types, DefaultExperiment and ModelStructure."""
    now = datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")
    root = ET.Element("fmiModelDescription", dict(
        fmiVersion="2.0", modelName=cfg["model_identifier"], guid=guid,
        generationTool="linknet build_fmu.py --native", generationDateAndTime=now,
        variableNamingConvention="structured", description=cfg["description"], version=str(cfg.get("version", "1"))))
    cs = ET.SubElement(root, "CoSimulation", dict(
        modelIdentifier=cfg["model_identifier"], needsExecutionTool="false",
        canHandleVariableCommunicationStepSize="true",
        # inputs an anchor's position takes derivatives of (fmi2SetRealInputDerivatives: its V and A)
        canInterpolateInputs="true" if layout.anchor_inputs.size else "false", maxOutputDerivativeOrder="0",
        canRunAsynchronuously="false", canBeInstantiatedOnlyOncePerProcess="false",
        canNotUseMemoryManagementFunctions="true", canGetAndSetFMUstate="true", canSerializeFMUstate="true",
        providesDirectionalDerivative="false"))
    files = ET.SubElement(cs, "SourceFiles")
    for name in sources:
        ET.SubElement(files, "File", name=name)
    cats = ET.SubElement(root, "LogCategories")
    for name, text in log_categories(layout):
        ET.SubElement(cats, "Category", name=name, description=text)
    variables = []
    for v in layout.reals:
        attrs = dict(name=v.name, valueReference=str(v.vr), description=v.description, causality=v.causality,
                     variability=v.variability)
        if v.initial:
            attrs["initial"] = v.initial
        given = v.causality in ("input", "parameter")
        variables.append((attrs, "Real", {"start": _start(start_values[v.vr])} if given else {}))
    variables.append((dict(name="integrator", valueReference=str(layout.integrator_vr),
                           description="integration method: " + ", ".join(cfg["integrators"]), causality="parameter",
                           variability="fixed", initial="exact"), "String", {"start": cfg["integrator"]}))
    estimate = "true" if cfg.get("error_estimate", True) else "false"
    variables.append((dict(name="estimate_error", valueReference=str(layout.estimate_error_vr),
                           description=ESTIMATE_ERROR_DESCRIPTION, causality="parameter", variability="fixed",
                           initial="exact"), "Boolean", {"start": estimate}))
    return root, variables


def start_values(scene, cfg, layout) -> dict:
    out = {}
    for vr in np.concatenate([layout.F_vr.ravel(), layout.V_vr.ravel(), layout.A_vr.ravel()]):
        out[int(vr)] = 0.0
    for row, k in zip(layout.P_vr, layout.anchor_inputs):  # the anchor starts at rest at its scene position
        for i, vr in enumerate(row):
            out[int(vr)] = float(scene.X0[k, i])
    for vr, k in zip(layout.M_vr, layout.free_indices):
        out[int(vr)] = float(scene.mass[k])
    for l, vr in enumerate(layout.R_vr):
        out[int(vr)] = float(scene.length[l])
    for i, vr in enumerate(layout.g_vr):
        out[int(vr)] = float(scene.gravity[i])
    out[int(layout.tolerance_vr)] = float(cfg["tolerance"])
    out[int(layout.step_vr)] = float(cfg["step"])
    return out


# ---------------------------------------------------------------------------- platforms and the compiler
@dataclass(frozen=True)
class Platform:
    """A folder of binaries/ and how its binary is made: one Zig target, or two slices of one universal Mach-O."""

    folder: str
    targets: tuple[str, ...]
    suffix: str
    runs_on: str


# The FMI 2.0 folders (win64, linux64, darwin64) and, for Linux on ARM, the FMI 3.0 platform tuple that FMI 2.0.4
# prescribes for platforms 2.0 does not name (see fmu_src/native/README.md). Versions are minimums: glibc 2.17 is
# the manylinux2014 baseline (RHEL/CentOS 7, Ubuntu 14.04, Debian 8), 2.17 also the first glibc for aarch64; macOS
# 10.13 for Intel and 11.0, the first for Apple silicon.
PLATFORMS = {
    "linux64": Platform("linux64", ("x86_64-linux-gnu.2.17",), ".so", "Linux x86-64 with glibc 2.17 or newer"),
    "win64": Platform("win64", ("x86_64-windows-gnu",), ".dll",
                      "Windows x86-64 with the Universal C Runtime (Windows 10 and later, 7 and 8.1 updated)"),
    "darwin64": Platform("darwin64", ("x86_64-macos.10.13", "aarch64-macos.11.0"), ".dylib",
                         "macOS 10.13 or newer on Intel, 11.0 or newer on Apple silicon (one universal binary)"),
    "aarch64-linux": Platform("aarch64-linux", ("aarch64-linux-gnu.2.17",), ".so",
                              "Linux on 64-bit ARM with glibc 2.17 or newer"),
}
PLATFORMS_VARIABLE = "LINKNET_FMU_PLATFORMS"  # the default of --platforms where it is set (e.g. host, for speed)


def host_platform() -> str | None:
    """The binaries/ folder of this machine, None where no platform of PLATFORMS runs here."""
    machine = platform.machine().lower()
    if sys.platform.startswith("linux"):
        return {"x86_64": "linux64", "amd64": "linux64", "aarch64": "aarch64-linux", "arm64": "aarch64-linux"}.get(machine)
    if sys.platform == "win32":
        return "win64" if machine in ("amd64", "x86_64") else None
    if sys.platform == "darwin":
        return "darwin64"
    return None


def platforms_from(spec) -> tuple[str, ...]:
    """The folders a --platforms value names: "all", "host", or a comma-separated list of PLATFORMS' keys (None:
    $LINKNET_FMU_PLATFORMS, else all). Refuses an unknown name, naming it and the known ones."""
    if spec is None:
        spec = os.environ.get(PLATFORMS_VARIABLE) or "all"
    items = [s.strip() for s in (spec.split(",") if isinstance(spec, str) else spec) if s.strip()]
    if not items:
        raise NativeBuildError(f"platforms {spec!r} names none (give all, host, or some of {', '.join(PLATFORMS)})")
    chosen = []
    for item in items:
        if item == "all":
            names = list(PLATFORMS)
        elif item == "host":
            if host_platform() is None:
                raise NativeBuildError(f"platforms: this machine ({sys.platform}, {platform.machine()}) is none of "
                                       f"{', '.join(PLATFORMS)}: name the platforms to build")
            names = [host_platform()]
        elif item in PLATFORMS:
            names = [item]
        else:
            raise NativeBuildError(f"platforms: unknown platform {item!r} (known: all, host, {', '.join(PLATFORMS)})")
        chosen += [n for n in names if n not in chosen]
    return tuple(chosen)


def zig_cc() -> list[str]:
    """Zig's C compiler (PyPI's ziglang): clang with the C libraries of every target, glibc 2.17 included."""
    if importlib.util.find_spec("ziglang") is None:
        raise NativeBuildError("the native FMU's binaries are compiled with Zig's C compiler, which is not installed: "
                               "pip install ziglang")
    return [sys.executable, "-m", "ziglang", "cc"]


def cache_dir() -> Path:
    """The per-user cache of compiled FMU code (LINKNET_FMU_CACHE, default ~/.cache/linknet/native-fmu): the native
    FMU's objects and linked binaries, and the pythonfmu FMU's front layer (pythonfmu_front.build)."""
    root = os.environ.get("LINKNET_FMU_CACHE") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "linknet", "native-fmu")
    return Path(root)


def _run_compiler(cmd: list[str], cwd: Path) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=cwd)
    if proc.returncode != 0:
        raise NativeBuildError(f"compiling the native FMU failed ({' '.join(cmd)}):\n{proc.stderr[-4000:]}")
    if proc.stderr.strip():
        print(proc.stderr.strip(), file=sys.stderr)


def _link_options(target: str, ident: str) -> list[str]:
    if "-linux-" in target:  # -s: no symbol table beyond the dynamic one
        return ["-Wl,--no-undefined", f"-Wl,-soname,{ident}.so", "-s", "-lm"]
    if "-macos" in target:
        return [f"-Wl,-install_name,@rpath/{ident}.dylib", "-s"]
    return ["-s"]  # windows: only the dllexport'ed fmi2 functions are exported


def sources_digest(sources_dir: Path) -> bytes:
    """What the compiler reads: every .c and .h file under sources/ (not CMakeLists.txt, which names the model)."""
    content = hashlib.sha256()
    for p in sorted(sources_dir.rglob("*.[ch]")):
        if p.is_file():
            content.update(p.relative_to(sources_dir).as_posix().encode() + b"\0" + p.read_bytes())
    return content.digest()


def unit_digest(sources_dir: Path, unit: str, sources: bytes) -> str:
    """What compiling one translation unit of sources/ reads besides the C library: the unit and every file it
    includes with quotes, transitively, found beside the including file or else in sources/ (the one include folder),
    as the compiler looks them up; every #include line counts, whatever conditions it stands under. An #include the
    compiler would resolve otherwise (a macro, a file in neither place) makes it the digest of all of sources/
    (``sources``, sources_digest's)."""
    sources_dir = Path(os.path.normpath(sources_dir))
    content, seen, todo = hashlib.sha256(), set(), [sources_dir / unit]
    while todo:
        path = Path(os.path.normpath(todo.pop()))
        if path in seen:
            continue
        seen.add(path)
        text = path.read_bytes()
        content.update(path.relative_to(sources_dir).as_posix().encode() + b"\0" + text + b"\0")
        for line in re.findall(rb"^[ \t]*#[ \t]*include\b(.*)$", text, re.M):
            quoted = re.match(rb'\s*"([^"]+)"', line)
            if quoted is None:
                if re.match(rb"\s*<[^>]+>", line):
                    continue  # the C library's headers, which the compiler's version in the key pins
                return hashlib.sha256(b"every source\0" + sources).hexdigest()
            name = quoted.group(1).decode()
            found = [p for p in (path.parent / name, sources_dir / name) if p.is_file()]
            if not found or not Path(os.path.normpath(found[0])).is_relative_to(sources_dir):
                return hashlib.sha256(b"every source\0" + sources).hexdigest()
            todo.append(found[0])
    return content.hexdigest()


def object_name(sources_dir: Path, unit: str, sources: bytes) -> str:
    """The cached object of a translation unit: its name and its unit_digest."""
    return f"{unit.replace('/', '__')}.{unit_digest(sources_dir, unit, sources)[:32]}.o"


_zig_versions: dict = {}


def _zig_version(cc: list[str]) -> str:
    key = tuple(cc)
    if key not in _zig_versions:
        _zig_versions[key] = subprocess.run(cc[:-1] + ["version"], capture_output=True, text=True).stdout.strip()
    return _zig_versions[key]


def store_by_rename(made: Path, store: Path) -> Path:
    """made moved into the cache folder store (a rename: a concurrent build never sees half a file)."""
    store.mkdir(parents=True, exist_ok=True)
    os.replace(made, store / made.name)
    return store / made.name


@contextlib.contextmanager
def _one_build_at_a_time(cache: bool):
    """Builds that use the per-user cache compile one at a time: a second build in another process (a second test
    worker, a second shell) waits, then finds the first one's objects in the cache instead of compiling them again.
    Where the lock cannot be had (no fcntl on Windows, a cache folder that cannot be written) builds go on side by
    side, as each object and binary is stored by a rename."""
    if not cache:
        yield
        return
    try:
        import fcntl
        cache_dir().mkdir(parents=True, exist_ok=True)
        lock = open(cache_dir() / "build.lock", "a")
    except (ImportError, OSError):
        yield
        return
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield


def compile_binaries(sources_dir: Path, units: list[str], ident: str, folders: tuple[str, ...], out_dir: Path,
                     cache: bool = True) -> dict[str, Path]:
    """binaries/<folder>/<ident><suffix> of every platform in ``folders``, each from the FMU's sources/ alone, as a
    tool compiles them (the <SourceFiles>, sources/ the only include folder); returns folder -> binary.

    The sources are the same for every scene, so the binaries are too: each target's objects and its linked binary
    (which carries the model identifier in its name) are kept in a per-user cache (LINKNET_FMU_CACHE, default
    ~/.cache/linknet/native-fmu), keyed by the compiler, the target and the flags, an object also by the content of
    what its unit reads (unit_digest) and a linked binary by that of every source file, so that a further scene
    compiles nothing, and links nothing if its model identifier was built before; the FMI 2.0 and FMI 3.0 FMUs, whose
    sources differ in the glue only, share every other object."""
    from concurrent.futures import ThreadPoolExecutor

    cc = zig_cc()
    flags = CFLAGS + WARNINGS + ["-fPIC", "-I", str(sources_dir)]
    digest = sources_digest(sources_dir)
    targets = [t for folder in folders for t in PLATFORMS[folder].targets]
    suffix = {t: PLATFORMS[f].suffix for f in folders for t in PLATFORMS[f].targets}
    with _one_build_at_a_time(cache), tempfile.TemporaryDirectory(prefix="linknet_objects_") as tmp:
        tmp = Path(tmp)
        stores, linked, jobs, fresh = {}, {}, [], []
        object_names = {u: object_name(sources_dir, u, digest) for u in units}
        object_stores = {}
        for target in targets:
            compiler = hashlib.sha256("\0".join(["zig cc", _zig_version(cc), target] + flags[:-2]).encode())
            object_stores[target] = (cache_dir() / f"{compiler.hexdigest()[:32]}-objects" if cache
                                     else tmp / "objects" / target)
            compiler.update(digest)
            stores[target] = cache_dir() / compiler.hexdigest()[:32] if cache else tmp / "objects" / target
            binary = stores[target] / "linked" / f"{ident}{suffix[target]}"
            if binary.exists():
                linked[target] = binary
                continue
            work = tmp / "new" / target
            work.mkdir(parents=True)
            for u in units:
                name = object_names[u]
                if not (object_stores[target] / name).exists():
                    jobs.append(([*cc, "-target", target, *flags, "-c", str(sources_dir / u), "-o", str(work / name)],
                                 work))
                    fresh.append((work / name, object_stores[target]))
        with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
            list(pool.map(lambda job: _run_compiler(*job), jobs))
        for made, store in fresh:
            store_by_rename(made, store)

        def link(target: str) -> Path:
            work = tmp / "linked" / target  # its own folder: the Windows link leaves an import library beside it
            work.mkdir(parents=True)
            binary = work / f"{ident}{suffix[target]}"
            objects = [str(object_stores[target] / object_names[u]) for u in units]
            _run_compiler([*cc, "-target", target, "-shared", "-o", str(binary)] + objects
                          + _link_options(target, ident), work)
            return store_by_rename(binary, stores[target] / "linked")

        with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
            linked.update(zip([t for t in targets if t not in linked],
                              pool.map(link, [t for t in targets if t not in linked])))
        built = {}
        for folder in folders:
            spec = PLATFORMS[folder]
            binary = out_dir / folder / f"{ident}{spec.suffix}"
            binary.parent.mkdir(parents=True, exist_ok=True)
            slices = [linked[t].read_bytes() for t in spec.targets]
            binary.write_bytes(slices[0] if len(slices) == 1 else universal_mach_o(slices))
            built[folder] = binary
    return built


# ---------------------------------------------------------------------------- the universal Mach-O
MACH_O_64 = 0xFEEDFACF  # a thin 64-bit Mach-O, little-endian on x86-64 and arm64
FAT_MAGIC = 0xCAFEBABE  # the universal header: big-endian, 32-bit offsets
FAT_ALIGN = 14  # each slice at a 2^14 (16 KiB, arm64's page) boundary, as lipo places arm64


def universal_mach_o(slices: list[bytes]) -> bytes:
    """One universal ("fat") Mach-O holding the thin ones, as lipo -create writes it: a fat_header, one fat_arch per
    slice (CPU type and subtype read from the slice's own header), each slice at a page boundary after them."""
    page = 1 << FAT_ALIGN
    offset = -(-(8 + 20 * len(slices)) // page) * page
    arches, placed = [], []
    for data in slices:
        magic, cputype, cpusubtype = struct.unpack_from("<Iii", data)
        if magic != MACH_O_64:
            raise NativeBuildError("a macOS slice is not a 64-bit Mach-O: the universal binary cannot be made")
        arches.append(struct.pack(">iiIII", cputype, cpusubtype, offset, len(data), FAT_ALIGN))
        placed.append((offset, data))
        offset = -(-(offset + len(data)) // page) * page
    fat = bytearray(placed[-1][0] + len(placed[-1][1]))
    head = struct.pack(">II", FAT_MAGIC, len(slices)) + b"".join(arches)
    fat[:len(head)] = head
    for at, data in placed:
        fat[at:at + len(data)] = data
    return bytes(fat)


# ---------------------------------------------------------------------------- sources/
CORE_FOLDER = "linknet"  # sources/linknet/: the core's tree as it is and the FMI glue
UNIT_HEADER = "linknet_fmu_unit.h"  # included first by every translation unit (fmu_src/native/linknet_fmu_unit.h)


def _system_headers(text: str) -> set[str]:
    return set(re.findall(r"^\s*#\s*include\s*<([^>]+)>", text, re.M))


def stage_sources(dest: Path, ident: str) -> list[str]:
    """sources/: the core's src tree as it is and the glue in sources/linknet/; at the top, one two-line wrapper per
    translation unit (UNIT_HEADER, then the unit), the unit header and a CMakeLists.txt. The same for every scene
    (CMakeLists.txt names the model identifier). Returns the files to compile, the wrappers: sources/*.c."""
    inner = dest / CORE_FOLDER
    shutil.copytree(core_source_dir(), inner, ignore=shutil.ignore_patterns("__pycache__", "*.o", "*.so"))
    for name in GLUE_FILES:
        if (inner / name).exists():
            raise NativeBuildError(f"the core's sources now have a file named {name}, as the FMU glue does: rename one")
        shutil.copy2(HERE / name, inner / name)
    shutil.copy2(HERE / UNIT_HEADER, dest / UNIT_HEADER)
    allowed = _system_headers((HERE / UNIT_HEADER).read_text())
    for p in sorted(inner.rglob("*.[ch]")):
        extra = _system_headers(p.read_text(errors="replace")) - allowed
        if extra:
            raise NativeBuildError(f"{p.relative_to(inner)} includes <{'>, <'.join(sorted(extra))}>, which "
                                   f"fmu_src/native/{UNIT_HEADER} does not declare before hiding the FMU's symbols: "
                                   "add it there")
    units = []
    for unit in translation_units(inner):
        name = Path(unit).name
        if name in units:
            raise NativeBuildError(f"two translation units of the FMU are named {name}: rename one")
        units.append(name)
        (dest / name).write_text(f'/* {CORE_FOLDER}/{unit}, compiled after {UNIT_HEADER} (see there). */\n'
                                 f'#include "{UNIT_HEADER}"\n#include "{CORE_FOLDER}/{unit}"\n')
    units.sort()
    (dest / "CMakeLists.txt").write_text(cmake_lists(ident, units))
    return units


def cmake_lists(ident: str, units: list[str]) -> str:
    """sources/CMakeLists.txt: the shared library from the <SourceFiles> with the arithmetic of the shipped binaries."""
    files = "\n".join(f"  {u}" for u in units)
    return f"""# The FMU's binary from its sources, as the binaries/ in this FMU were built (fmu_src/native/build.py):
#   cmake -S sources -B build -DCMAKE_BUILD_TYPE=Release && cmake --build build --config Release
# gives build/{ident}.so (.dll, .dylib), for binaries/<platform>/ of the unzipped FMU; it reads the scene from the
# FMU's resources/ when it is instantiated.
# cc -shared -fPIC -std=c99 -O2 -ffp-contract=off sources/*.c -lm -o {ident}.so does the same by hand.
cmake_minimum_required(VERSION 3.10)
project({ident} C)
if(NOT CMAKE_BUILD_TYPE AND NOT CMAKE_CONFIGURATION_TYPES)
  set(CMAKE_BUILD_TYPE Release)
endif()
add_library({ident} SHARED
{files}
)
set_target_properties({ident} PROPERTIES PREFIX "" C_STANDARD 99 C_STANDARD_REQUIRED ON C_EXTENSIONS OFF)
if(CMAKE_C_COMPILER_ID MATCHES "GNU|Clang")
  # no fused multiply-add (a*b+c rounded twice, as on every platform) and no errno from libm: the shipped arithmetic
  target_compile_options({ident} PRIVATE -ffp-contract=off -fno-math-errno)
endif()
if(UNIX AND NOT APPLE)
  target_link_libraries({ident} PRIVATE m)
endif()
"""


def check_settings(cfg: dict) -> None:
    """The FMU's own rules for its parameters step and tolerance (linknet_model.c), before anything is built."""
    step, tolerance = float(cfg["step"]), float(cfg["tolerance"])
    if not (math.isfinite(step) and step > 0):
        raise NativeBuildError(f"step = {step!r} must be finite and > 0 (seconds)")
    low, high = library_tolerance_range()
    if not (low <= tolerance < high):
        raise NativeBuildError(f"tolerance = {tolerance!r} must lie in [{low:g}, {high:g})")


def bake(scene, cfg, layout, progress=lambda stage: None) -> tuple[Resource, dict]:
    """scene_resource, a scene the library itself refuses (e.g. inconsistent initial velocities) answered with a
    NativeBuildError naming the scene."""
    import linknet_core as ln
    progress(f"baking the scene ({len(layout.reals)} variables)")
    try:
        return scene_resource(scene, cfg, layout)
    except ln.LinknetError as e:  # named once: the library's messages mostly name the scene themselves
        text = str(e)
        raise NativeBuildError(text if text.startswith(f"{scene.name}: ") else f"{scene.name}: {text}") from None


def pack(out: Path, files: dict) -> None:
    """The FMU at ``out``: its files (name in the archive -> bytes or a Path) written whole and renamed into place,
    so a failed build leaves no half FMU behind. The scene's resource, the largest file, is stored with the fastest
    compression."""
    from linknet_core.output import WriteError, atomic_write

    def write(target):
        with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data in files.items():
                level = 1 if name.startswith("resources/") else None
                if isinstance(data, Path):
                    z.write(data, name, compresslevel=level)
                else:
                    z.writestr(name, data, compresslevel=level)

    try:
        atomic_write(out, write)
    except WriteError as e:
        raise NativeBuildError(str(e)) from None


def sources_files(sources: Path) -> dict:
    return {"sources/" + p.relative_to(sources).as_posix(): p for p in sorted(sources.rglob("*")) if p.is_file()}


def build_native_fmu(scene, cfg: dict, layout, out: Path, experiment: dict, postprocess, quiet: bool = False,
                     platforms=None) -> Path:
    """Write the native FMU of ``scene`` to ``out``. ``cfg``, ``layout`` and ``experiment`` are build_fmu.py's
    (identifier, description, integrators and defaults; the variables; DefaultExperiment); ``postprocess`` is
    build_fmu.finish_model_description; ``platforms`` the binaries to build (platforms_from: None is
    $LINKNET_FMU_PLATFORMS, else all)."""
    import time
    started = time.perf_counter()
    out = Path(out)
    folders = platforms_from(platforms)
    check_settings(cfg)

    def progress(stage: str) -> None:  # a large scene's build takes a while: say how far it is
        if not quiet and len(layout.reals) >= PROGRESS_VARIABLES:
            print(f"build_fmu: {cfg['model_identifier']}: {stage} ({time.perf_counter() - started:.0f} s)",
                  file=sys.stderr, flush=True)
    resource, facts = bake(scene, cfg, layout, progress)
    ident = cfg["model_identifier"]
    resource_name, _ = resource_format()
    with tempfile.TemporaryDirectory(prefix="linknet_native_fmu_") as tmp:
        tmp = Path(tmp)
        sources = tmp / "fmu" / "sources"
        units = stage_sources(sources, ident)
        data, guid = with_identity(resource, sources_digest(sources))
        progress(f"compiling for {', '.join(folders)}")
        binaries = compile_binaries(sources, units, ident, folders, tmp / "fmu" / "binaries")
        progress("writing the model description")
        header, variables = model_description_parts(cfg, layout, guid, units, start_values(scene, cfg, layout))
        inv_mass = scene.inv_mass
        md = postprocess(header, variables, {v.name: v.declared_type for v in layout.reals},
                         layout.dependencies(inv_mass), layout.initial_dependencies(inv_mass), experiment,
                         cfg["description"], directional=not facts["linearization_refusal"])
        progress(f"packing {out}")
        pack(out, {"modelDescription.xml": md,
                   **{f"binaries/{folder}/{binary.name}": binary for folder, binary in binaries.items()},
                   **sources_files(sources), f"resources/{resource_name}": data})
    if not quiet:
        size = out.stat().st_size
        print(f"built {out} (native model {ident}: {sum(v.causality == 'input' for v in layout.reals)} inputs, "
              f"{sum(v.causality == 'output' for v in layout.reals)} outputs; {facts['specialisation']} "
              f"specialisation; binaries for {', '.join(folders)}; {size / 1024:.0f} KiB; "
              f"{time.perf_counter() - started:.1f} s; no Python needed by hosts)")
    return out
