"""Build the self-contained FMI 2.0 Co-Simulation FMU of a scene on the native C core (`build_fmu.py --native`).

The FMU holds no Python. Its binaries (PLATFORMS: linux64, win64, darwin64, aarch64-linux; --platforms chooses) are
compiled here with Zig's C compiler (PyPI's ziglang) from sources/, as a tool would compile them:

* the native core, linknet_core/native/src, copied as it is into sources/linknet/ (every .c file that no other .c
  file includes is a translation unit, so the DIM-generic stages come in through dim2.c/dim3.c and AMD through its
  amd_l*.c wrappers);
* the FMI glue, fmu_src/native/fmi2Functions.c (scene-independent, FMI only) and linknet_model.c (the core as
  the glue's model, fmu_model.h), with fmi2_api.h, fmu_model.h, lnfmu_scene.h, beside the core;
* one generated file, linknet_scene.c: the scene as constant data. The ln_model and every integrator's
  ln_method are read field by field from the structs linknet_core's own Simulator hands the core for this
  scene (the ctypes mirrors in linknet_core.native), so the FMU at its default parameters runs the library's
  arithmetic bit for bit. Plus what a changed mass, length or gravity needs, the initial state and internals,
  and the variable table of fmu_src/linknet_fmu/layout.py (the same Layout the pythonfmu FMU uses);
* at the top of sources/, one two-line file per translation unit (linknet_fmu_unit.h, then the unit: only the fmi2
  functions leave the binary, however it is built) and a CMakeLists.txt.

The top-level .c files are the <SourceFiles>, so `cc -shared -fPIC sources/*.c -lm` builds the binary on any
platform. The modelDescription.xml goes through build_fmu.postprocess_model_description, as the pythonfmu FMU's
does: the two agree on variables, units, types, DefaultExperiment and ModelStructure.
"""
from __future__ import annotations

import ctypes
import datetime
import hashlib
import importlib
import importlib.util
import inspect
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
from lxml import etree as ET  # fmpy's dependency: a large net's modelDescription written at C speed
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
if str(HERE.parent) not in sys.path:  # fmu_src: the layout both FMU kinds share
    sys.path.insert(0, str(HERE.parent))
from linknet_fmu.layout import (ERROR_ESTIMATE_CATEGORY, ERROR_ESTIMATE_CATEGORY_DESCRIPTION,  # noqa: E402
                                ESTIMATE_ERROR_DESCRIPTION)

GLUE_FILES = ("fmi2Functions.c", "linknet_model.c", "fmi2_api.h", "fmu_model.h", "fmu_states.h", "lnfmu_scene.h")
SCENE_FILE = "linknet_scene.c"
PROGRESS_VARIABLES = 100_000  # a scene with this many FMU variables builds for a minute or more: progress lines
STATE_FORMAT = 3  # keep equal to FMU_STATE_FORMAT in fmu_states.h (a part of the fingerprint)
# as setup.py compiles the core for the library: the same code generation, so the same results
CFLAGS = ["-std=c99", "-O3", "-fno-math-errno", "-ffp-contract=off"]
WARNINGS = ["-Wall", "-Wextra"]
LOG_CATEGORIES = (("logStatusWarning", "Log messages with fmi2Warning status."),
                  ("logStatusDiscard", "Log messages with fmi2Discard status."),
                  ("logStatusError", "Log messages with fmi2Error status."),
                  ("logStatusFatal", "Log messages with fmi2Fatal status (never sent by this FMU)."),
                  ("logAll", "Log all messages."),
                  (ERROR_ESTIMATE_CATEGORY, ERROR_ESTIMATE_CATEGORY_DESCRIPTION))


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


def force_parameters(src: Path) -> int:
    m = re.search(r"#define\s+LN_FORCE_PARAMETERS\s+(\d+)", (src / "linknet.h").read_text())
    if not m:
        raise NativeBuildError("linknet.h no longer defines LN_FORCE_PARAMETERS: teach fmu_src/native/build.py")
    return int(m.group(1))


# ---------------------------------------------------------------------------- C literals
def c_double(x: float) -> str:
    x = float(x)
    if math.isnan(x):
        return "NAN"
    if math.isinf(x):
        return "INFINITY" if x > 0 else "-INFINITY"
    return x.hex()  # exact: C99 hexadecimal floating constants


def c_string(s: str) -> str:
    out = []
    for ch in s.encode("utf-8"):
        c = chr(ch)
        if c in '"\\':
            out.append("\\" + c)
        elif 32 <= ch < 127 and c != "?":  # '?' escaped against trigraphs
            out.append(c)
        else:
            out.append(f"\\{ch:03o}")
    return '"' + "".join(out) + '"'


class CWriter:
    """Static const arrays and the initializers that point to them."""

    def __init__(self):
        self.lines: list[str] = []
        self._n = 0

    def array(self, ctype: str, values, fmt, hint: str) -> str:
        values = list(values)
        if not values:
            return "NULL"
        self._n += 1
        name = f"{hint}_{self._n}"
        body = []
        row = []
        for i, v in enumerate(values):
            row.append(fmt(v))
            if len(row) == 8 or i == len(values) - 1:
                body.append("    " + ", ".join(row) + ",")
                row = []
        self.lines.append(f"static const {ctype} {name}[{len(values)}] = {{\n" + "\n".join(body) + "\n};")
        return name

    def doubles(self, values, hint="d") -> str:
        return self.array("double", np.asarray(values, np.float64).ravel(), c_double, hint)

    def ints(self, values, hint="i") -> str:
        return self.array("ln_int", np.asarray(values, np.int64).ravel(), lambda v: str(int(v)), hint)

    def bytes_(self, values, hint="b") -> str:
        return self.array("uint8_t", np.asarray(values, np.uint8).ravel(), lambda v: str(int(v)), hint)

    def strings(self, values, hint="s") -> str:
        return self.array("char *const", values, c_string, hint)


def _pointer_values(ptr, n: int, ctype):
    if not ptr or n == 0:
        return None
    return np.ctypeslib.as_array(ctypes.cast(ptr, ctypes.POINTER(ctype)), (n,)).copy()


def struct_initializer(w: CWriter, struct, lengths: dict, skip: set, hint: str) -> str:
    """A C designated initializer of a ctypes mirror of a core struct, field by field. Pointer fields need a
    known length (``lengths``: field -> number of entries, from the struct's own counts) or are set at
    instantiation (``skip``); a field of a kind not known here stops the build, so that a field the core adds
    cannot be silently dropped."""
    parts = []
    for name, ctype in type(struct)._fields_:
        value = getattr(struct, name)
        if name in skip:
            continue
        if ctype in (ctypes.c_int64, ctypes.c_int, ctypes.c_int32, ctypes.c_uint8):
            parts.append(f".{name} = {int(value)}")
        elif ctype is ctypes.c_double:
            parts.append(f".{name} = {c_double(value)}")
        elif isinstance(ctype, type) and issubclass(ctype, ctypes.Array):
            if ctype._type_ is not ctypes.c_double:
                raise NativeBuildError(f"{type(struct).__name__}.{name}: array of {ctype._type_} not handled")
            parts.append(f".{name} = {{{', '.join(c_double(v) for v in value)}}}")
        elif isinstance(ctype, type) and issubclass(ctype, ctypes._Pointer):
            if name not in lengths:
                raise NativeBuildError(f"{type(struct).__name__}.{name}: a pointer field fmu_src/native/build.py does "
                                       "not know the length of (the core's struct changed: teach build.py)")
            target = ctype._type_
            values = _pointer_values(value, int(lengths[name]), target)
            if values is None:
                continue
            if target is ctypes.c_double:
                ref = w.doubles(values, f"{hint}_{name}")
            elif target is ctypes.c_int64:
                ref = w.ints(values, f"{hint}_{name}")
            elif target is ctypes.c_uint8:
                ref = w.bytes_(values, f"{hint}_{name}")
            else:
                raise NativeBuildError(f"{type(struct).__name__}.{name}: pointer to {target} not handled")
            parts.append(f".{name} = {ref}")
        elif ctype is ctypes.c_void_p:
            raise NativeBuildError(f"{type(struct).__name__}.{name}: an opaque pointer fmu_src/native/build.py does "
                                   "not know how to rebuild (the core's struct changed: teach build.py)")
        else:
            raise NativeBuildError(f"{type(struct).__name__}.{name}: field type {ctype} not handled")
    return "{\n    " + ",\n    ".join(parts) + "\n}"


# ---------------------------------------------------------------------------- the scene as data
def library_tolerance_range() -> tuple[float, float]:
    """[min, max) of an adaptive method's rtol, as linknet_core.integrators checks it."""
    import linknet_core.integrators as integrators
    return float(getattr(integrators, "RTOL_MIN", 1e-15)), float(getattr(integrators, "RTOL_MAX", 0.1))


def _simulators(scene, cfg):
    """One linknet_core Simulator per integrator, as the pythonfmu FMU builds them (dt = step, or rtol =
    tolerance), sharing one Dynamics (the structure is analysed once)."""
    import linknet_core as ln
    sims = {}
    dyn = None
    for name in [cfg["integrator"]] + [n for n in cfg["integrators"] if n != cfg["integrator"]]:
        kwargs = dict(rtol=cfg["tolerance"]) if ln.METHODS[name].adaptive else dict(dt=cfg["step"])
        # the baked model and methods are the run's; the companion's are made from them in C (linknet_model.c)
        sims[name] = ln.Simulator(scene, method=name, dynamics=dyn, error_estimate=False, **kwargs)
        dyn = sims[name].dyn
    return sims


def scene_source(scene, cfg, layout, src: Path) -> tuple[str, dict]:
    """The generated C file (without its identity lines) and facts about the scene for the caller."""
    import linknet_core as ln
    from linknet_core.clib.ldl import package_library
    from linknet_core.scene.motion import PIECE_COLUMNS, SINE_COLUMNS

    sims = _simulators(scene, cfg)
    sim = sims[cfg["integrator"]]
    integ = sim.integrator
    kind = sim.specialisation.kind
    spec = {"none": 0, "static": 1, "rigid": 2}.get(kind)
    if spec is None:
        raise NativeBuildError(f"unknown specialisation {kind!r} of the Simulator: teach fmu_src/native/build.py")
    model = integ.model.struct
    K, L = int(model.K), int(model.L)
    n_pairs, n_el, n_fixed, n_free = int(model.n_pairs), int(model.n_elements), int(model.n_fixed), int(model.n_free)
    n_driven = int(model.n_driven)
    pieces = _pointer_values(model.motion_pieces, n_driven + 1, ctypes.c_int64) if n_driven else None
    P = force_parameters(src)
    model_lengths = {"k1": L, "k2": L, "R": L, "inv_R": L, "inv_m": K, "free_idx": n_free, "fixed_idx": n_fixed,
                     "is_fixed": K, "F_scene": 3 * K, "element_kind": n_el, "element_mass": 2 * n_el,
                     "element_param": P * n_el, "pair_first": n_pairs, "pair_second": n_pairs,
                     "pair_weight": n_pairs, "pair_mass": n_pairs, "pair_sign": n_pairs, "chain_order": L,
                     "chain_diag_weight": L, "chain_off_weight": L,
                     "driven_idx": n_driven, "motion_kind": n_driven, "motion_pieces": n_driven + 1,
                     "piece": PIECE_COLUMNS * int(pieces[-1]) if n_driven else 0, "sine": SINE_COLUMNS * n_driven,
                     "accel_weight": K}
    w = CWriter()
    model_init = struct_initializer(w, model, model_lengths, {"ldl", "rigid"}, "model")

    # the elimination order the sparse LDL^T was analysed in (rebuilt at instantiation with ln_ldl_analyse)
    ordering = "NULL"
    if model.ldl:
        order = np.zeros(L, np.int64)
        package_library().ln_ldl_get_ordering(model.ldl, order.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)))
        ordering = w.ints(order, "ldl_ordering")

    rigid_ref, Y0_ref, n_bodies = "NULL", "NULL", 0
    if spec == 2:
        rstruct = integ.rigid.struct
        n_bodies = int(rstruct.n_bodies)
        rigid_init = struct_initializer(w, rstruct, {"body_of": K, "r": 3 * K, "inertia": 3 * n_bodies,
                                                     "body_mass": n_bodies, "kind": n_bodies}, set(), "rigid")
        w.lines.append(f"static const struct ln_rigid_model rigid = {rigid_init};")
        rigid_ref = "&rigid"
        Y0_ref = w.doubles(integ.body_states(), "Y0")

    internals = integ.internals()["native"]
    methods = []
    for name in cfg["integrators"]:
        s = sims[name]
        mstruct = s.integrator.method.struct
        ns = int(mstruct.n_stages)
        init = struct_initializer(w, mstruct, {"gammas": int(mstruct.n_gammas), "AB": (ns + 1) * ns, "C": ns,
                                               "E1": ns + 1, "E2": ns + 1}, set(), f"method_{name}")
        adaptive = int(bool(ln.METHODS[name].adaptive))
        methods.append(f"{{{c_string(name)}, {adaptive}, {int(ln.METHODS[name].order)}, {init}}}")
    kinds = {"F": 0, "X": 1, "U": 2, "T": 3, "Freact": 4, "M": 5, "R": 6, "g": 7, "P": 10, "V": 11, "A": 12,
             "Jreact": 13, "error_estimate": 14}  # enum lnfmu_kind
    var_rows = {}
    fixed_idx = _pointer_values(model.fixed_idx, n_fixed, ctypes.c_int64)
    fixed_row = {int(k): j for j, k in enumerate([] if fixed_idx is None else fixed_idx)}
    for vrs, masses, kind_name in ((layout.F_vr, layout.input_masses, "F"), (layout.X_vr, layout.output_masses, "X"),
                                   (layout.U_vr, layout.output_masses, "U")):
        for row, k in zip(vrs, masses):
            for i, vr in enumerate(row):
                var_rows[int(vr)] = (kinds[kind_name], 3 * int(k) + i)
    for row, k in zip(layout.Freact_vr, layout.fixed_indices):
        for i, vr in enumerate(row):
            var_rows[int(vr)] = (kinds["Freact"], 3 * fixed_row[int(k)] + i)
    # P, V, A, Jreact of a driven anchor: its row in the model's driven_idx (the data's drive_P, ..., impulse)
    driven_idx = _pointer_values(model.driven_idx, n_driven, ctypes.c_int64)
    driven_row = {int(k): j for j, k in enumerate([] if driven_idx is None else driven_idx)}
    for kind_name, vrs, masses in (("P", layout.P_vr, layout.anchor_inputs), ("V", layout.V_vr, layout.anchor_inputs),
                                   ("A", layout.A_vr, layout.anchor_inputs),
                                   ("Jreact", layout.Jreact_vr, layout.driven_indices)):
        for row, k in zip(vrs, masses):
            for i, vr in enumerate(row):
                var_rows[int(vr)] = (kinds[kind_name], 3 * driven_row[int(k)] + i)
    for l, vr in enumerate(layout.T_vr):
        var_rows[int(vr)] = (kinds["T"], l)
    for vr, k in zip(layout.M_vr, layout.free_indices):
        var_rows[int(vr)] = (kinds["M"], int(k))
    for l, vr in enumerate(layout.R_vr):
        var_rows[int(vr)] = (kinds["R"], l)
    for i, vr in enumerate(layout.g_vr):
        var_rows[int(vr)] = (kinds["g"], i)
    var_rows[int(layout.error_estimate_vr)] = (kinds["error_estimate"], 0)
    var_rows[int(layout.tolerance_vr)] = (8, 0)
    var_rows[int(layout.step_vr)] = (9, 0)
    if sorted(var_rows) != list(range(layout.n_real)):
        raise NativeBuildError("the layout's Real variables are not all mapped: teach fmu_src/native/build.py")
    variables = ",\n".join(f"    {{{c_string(layout.reals[vr].name)}, {var_rows[vr][0]}, {var_rows[vr][1]}}}"
                           for vr in range(layout.n_real))

    length_tol = inspect.signature(ln.Simulator).parameters["length_tol"].default
    tolerance_min, tolerance_max = library_tolerance_range()
    max_force = float(getattr(importlib.import_module(ln.Simulator.__module__), "MAX_FORCE", 0.0))
    out = [
        f"/* {scene.name}: {K} masses, {L} links, solver {'none chain ldl min-norm'.split()[int(model.solver)]}, "
        f"specialisation {kind}. Generated by fmu_src/native/build.py: data only, no code. */",
        "#include <math.h>",
        "#include <stddef.h>",
        "#include <stdint.h>",
        "",
        '#include "fmu_model.h"',
        '#include "lnfmu_scene.h"',
        "",
    ]
    names = w.strings(scene.mass_names, "mass_names") if K else "NULL"
    scene_mass = w.doubles(scene.mass, "scene_mass") if K else "NULL"
    scene_length = w.doubles(scene.length, "scene_length") if L else "NULL"
    scene_force = w.doubles(scene.force, "scene_force") if K else "NULL"
    X0 = w.doubles(scene.X0, "scene_X0") if K else "NULL"
    U0 = w.doubles(scene.U0, "scene_U0") if K else "NULL"
    X_init = w.doubles(sim.state.X, "X_init") if K else "NULL"
    U_init = w.doubles(sim.state.U, "U_init") if K else "NULL"
    if sim.state.t != 0.0:
        raise NativeBuildError("the Simulator does not start at t = 0")
    w.lines.append(f"static const ln_model model = {model_init};")
    w.lines.append("static const lnfmu_method methods[] = {\n" + ",\n".join(methods) + "\n};")
    w.lines.append("static const lnfmu_variable variables[] = {\n" + variables + "\n};")
    out += w.lines
    project = bool(scene.options.get("project_initial_positions", False))
    scene_init = f"""const lnfmu_scene lnfmu_scene_data = {{
    .model_identifier = {c_string(cfg['model_identifier'])},
    .scene_name = {c_string(str(scene.name))},
    .guid = LNFMU_GUID,
    .fingerprint = LNFMU_FINGERPRINT,
    .K = {K}, .L = {L},
    .mass_names = {names},
    .mass = {scene_mass},
    .length = {scene_length},
    .gravity = {{{', '.join(c_double(g) for g in scene.gravity)}}},
    .force = {scene_force},
    .X0 = {X0}, .U0 = {U0},
    .project_initial = {int(project)},
    .length_tol = {c_double(length_tol)},
    .tolerance_min = {c_double(tolerance_min)}, .tolerance_max = {c_double(tolerance_max)},
    .max_force = {c_double(max_force)},
    .model = &model,
    .ldl_ordering = {ordering},
    .specialisation = {spec},
    .rigid = {rigid_ref},
    .Y0 = {Y0_ref},
    .X_init = {X_init}, .U_init = {U_init},
    .h_next_init = {c_double(internals.h_next)},
    .planar_init = {int(internals.planar)},
    .max_steps = {int(sim.max_steps_per_call)},
    .n_methods = {len(methods)},
    .methods = methods,
    .default_method = {cfg['integrators'].index(cfg['integrator'])},
    .default_step = {c_double(cfg['step'])},
    .default_tolerance = {c_double(cfg['tolerance'])},
    .default_estimate = {int(bool(cfg.get('error_estimate', True)))},
    .n_real = {layout.n_real},
    .variables = variables,
}};

const fmu_model_info lnfmu_info = {{
    {c_string(cfg['model_identifier'])}, LNFMU_GUID, LNFMU_FINGERPRINT, {layout.n_real}, 1, 1
}};
"""
    out.append(scene_init)
    facts = dict(specialisation=kind, solver=int(model.solver), K=K, L=L, bodies=n_bodies,
                 planar=bool(model.planar))
    return "\n".join(out), facts


# ---------------------------------------------------------------------------- modelDescription.xml
def _start(value: float) -> str:
    """pythonfmu's format (16 significant digits) where it is exact, else 17."""
    text = f"{value:.16g}"
    return text if float(text) == value else f"{value:.17g}"


def raw_model_description(cfg, layout, guid: str, sources: list[str], start_values: dict) -> bytes:
    """ModelVariables as the pythonfmu FMU writes them (same names, order, value references, attributes);
    build_fmu.postprocess_model_description then adds units, types, DefaultExperiment and ModelStructure."""
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
    for name, text in LOG_CATEGORIES:
        ET.SubElement(cats, "Category", name=name, description=text)
    variables = ET.SubElement(root, "ModelVariables")
    for v in layout.reals:
        attrs = dict(name=v.name, valueReference=str(v.vr), description=v.description, causality=v.causality,
                     variability=v.variability)
        if v.initial:
            attrs["initial"] = v.initial
        sv = ET.SubElement(variables, "ScalarVariable", attrs)
        real = {}
        if v.causality in ("input", "parameter"):
            real["start"] = _start(start_values[v.vr])
        ET.SubElement(sv, "Real", real)
    sv = ET.SubElement(variables, "ScalarVariable", dict(
        name="integrator", valueReference=str(layout.integrator_vr),
        description="integration method: " + ", ".join(cfg["integrators"]), causality="parameter",
        variability="fixed", initial="exact"))
    ET.SubElement(sv, "String", start=cfg["integrator"])
    sv = ET.SubElement(variables, "ScalarVariable", dict(
        name="estimate_error", valueReference=str(layout.estimate_error_vr), description=ESTIMATE_ERROR_DESCRIPTION,
        causality="parameter", variability="fixed", initial="exact"))
    ET.SubElement(sv, "Boolean", start="true" if cfg.get("error_estimate", True) else "false")
    ET.SubElement(root, "ModelStructure")
    return ET.tostring(root, encoding="UTF-8")


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


def _cache_dir() -> Path:
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


def compile_binaries(sources_dir: Path, units: list[str], ident: str, folders: tuple[str, ...], out_dir: Path,
                     cache: bool = True) -> dict[str, Path]:
    """binaries/<folder>/<ident><suffix> of every platform in ``folders``, each from the FMU's sources/ alone, as a
    tool compiles them (the <SourceFiles>, sources/ the only include folder); returns folder -> binary.

    The objects of everything but the scene's data are the same for every scene of one checkout: they are kept in a
    per-user cache (LINKNET_FMU_CACHE, default ~/.cache/linknet/native-fmu), keyed by the compiler, the target, the
    flags and the content of every source file, so that building a further scene compiles one file per target."""
    from concurrent.futures import ThreadPoolExecutor

    cc = zig_cc()
    flags = CFLAGS + WARNINGS + ["-fPIC", "-I", str(sources_dir)]
    version = subprocess.run(cc[:-1] + ["version"], capture_output=True, text=True).stdout.strip()
    content = hashlib.sha256()  # what the compiler reads: not CMakeLists.txt, which names the scene's model
    for p in sorted(sources_dir.rglob("*.[ch]")):
        if p.is_file() and p.name != SCENE_FILE:
            content.update(p.relative_to(sources_dir).as_posix().encode() + b"\0" + p.read_bytes())
    shared = [u for u in units if u != SCENE_FILE]
    targets = [t for folder in folders for t in PLATFORMS[folder].targets]
    with tempfile.TemporaryDirectory(prefix="linknet_objects_") as tmp:
        tmp = Path(tmp)
        objects, jobs, fresh = {}, [], []
        for target in targets:
            key = hashlib.sha256("\0".join(["zig cc", version, target] + flags[:-2]).encode()
                                 + content.digest()).hexdigest()[:32]
            store = _cache_dir() / key if cache else tmp / "objects" / target
            work = tmp / "new" / target
            work.mkdir(parents=True)
            for u in units:
                name = u.replace("/", "__") + ".o"
                cached = u != SCENE_FILE
                objects[target, u] = (store if cached else work) / name
                if not objects[target, u].exists():
                    jobs.append(([*cc, "-target", target, *flags, "-c", str(sources_dir / u), "-o", str(work / name)],
                                 work))
                    if cached:
                        fresh.append((work / name, store))
        with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
            list(pool.map(lambda job: _run_compiler(*job), jobs))
        for made, store in fresh:  # rename is atomic: a concurrent build never sees half an object
            store.mkdir(parents=True, exist_ok=True)
            os.replace(made, store / made.name)

        def link(target: str) -> Path:
            folder = next(f for f in folders if target in PLATFORMS[f].targets)
            binary = tmp / "linked" / target / f"{ident}{PLATFORMS[folder].suffix}"
            binary.parent.mkdir(parents=True)  # its own folder: the Windows link leaves an import library beside it
            _run_compiler([*cc, "-target", target, "-shared", "-o", str(binary)]
                          + [str(objects[target, u]) for u in shared + [SCENE_FILE] if (target, u) in objects]
                          + _link_options(target, ident), binary.parent)
            return binary

        with ThreadPoolExecutor(max_workers=os.cpu_count() or 2) as pool:
            linked = dict(zip(targets, pool.map(link, targets)))
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
CORE_FOLDER = "linknet"  # sources/linknet/: the core's tree as it is, the FMI glue and the scene's data
UNIT_HEADER = "linknet_fmu_unit.h"  # included first by every translation unit (fmu_src/native/linknet_fmu_unit.h)


def _system_headers(text: str) -> set[str]:
    return set(re.findall(r"^\s*#\s*include\s*<([^>]+)>", text, re.M))


def stage_sources(scene_c: str, dest: Path, ident: str) -> list[str]:
    """sources/: the core's src tree as it is, the glue and the generated scene in sources/linknet/; at the top, one
    two-line wrapper per translation unit (UNIT_HEADER, then the unit), the unit header and a CMakeLists.txt.
    Returns the files to compile, the wrappers: sources/*.c."""
    inner = dest / CORE_FOLDER
    shutil.copytree(core_source_dir(), inner, ignore=shutil.ignore_patterns("__pycache__", "*.o", "*.so"))
    for name in GLUE_FILES:
        if (inner / name).exists():
            raise NativeBuildError(f"the core's sources now have a file named {name}, as the FMU glue does: rename one")
        shutil.copy2(HERE / name, inner / name)
    (inner / SCENE_FILE).write_text(scene_c)
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
# gives build/{ident}.so (.dll, .dylib), for binaries/<platform>/ of the unzipped FMU.
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


def fingerprint(sources_dir: Path, scene_c: str) -> bytes:
    """16 bytes identifying this FMU's build: every source file and the scene data (and the state format)."""
    h = hashlib.blake2b(digest_size=16)
    h.update(f"linknet native FMU state format {STATE_FORMAT}\n".encode())
    for p in sorted(sources_dir.rglob("*")):
        if p.is_file() and p.name != SCENE_FILE:
            h.update(p.relative_to(sources_dir).as_posix().encode() + b"\0" + p.read_bytes())
    h.update(scene_c.encode())
    return h.digest()


def build_native_fmu(scene, cfg: dict, layout, out: Path, experiment: dict, postprocess, quiet: bool = False,
                     platforms=None) -> Path:
    """Write the native FMU of ``scene`` to ``out``. ``cfg``, ``layout`` and ``experiment`` are build_fmu.py's
    (identifier, description, integrators and defaults; the variables; DefaultExperiment); ``postprocess`` is
    build_fmu.postprocess_model_description; ``platforms`` the binaries to build (platforms_from: None is
    $LINKNET_FMU_PLATFORMS, else all)."""
    import time
    started = time.perf_counter()
    out = Path(out)
    folders = platforms_from(platforms)
    step, tolerance = float(cfg["step"]), float(cfg["tolerance"])
    if not (math.isfinite(step) and step > 0):  # the FMU's own rules for its parameters (linknet_model.c)
        raise NativeBuildError(f"step = {step!r} must be finite and > 0 (seconds)")
    low, high = library_tolerance_range()
    if not (low <= tolerance < high):
        raise NativeBuildError(f"tolerance = {tolerance!r} must lie in [{low:g}, {high:g})")
    src = core_source_dir()
    import linknet_core as ln

    def progress(stage: str) -> None:  # a large scene's build takes minutes: say how far it is
        if not quiet and len(layout.reals) >= PROGRESS_VARIABLES:
            print(f"build_fmu: {cfg['model_identifier']}: {stage} ({time.perf_counter() - started:.0f} s)",
                  file=sys.stderr, flush=True)
    progress(f"baking the scene ({len(layout.reals)} variables)")
    try:
        scene_c, facts = scene_source(scene, cfg, layout, src)
    except ln.LinknetError as e:  # a scene the library itself refuses (e.g. inconsistent initial velocities)
        raise NativeBuildError(f"{scene.name}: {e}") from None
    ident = cfg["model_identifier"]
    with tempfile.TemporaryDirectory(prefix="linknet_native_fmu_") as tmp:
        tmp = Path(tmp)
        sources = tmp / "fmu" / "sources"
        units = stage_sources("", sources, ident)
        digest = fingerprint(sources, scene_c)
        guid = "{" + str(uuid.UUID(bytes=digest)) + "}"
        finger = int.from_bytes(digest[:8], "little")
        header = (f"#define LNFMU_GUID {c_string(guid)}\n"
                  f"#define LNFMU_FINGERPRINT UINT64_C(0x{finger:016x})\n")
        text = scene_c.replace('#include "fmu_model.h"', header + '#include "fmu_model.h"', 1)
        (sources / CORE_FOLDER / SCENE_FILE).write_text(text)
        progress(f"compiling for {', '.join(folders)}")
        binaries = compile_binaries(sources, units, ident, folders, tmp / "fmu" / "binaries")
        progress("writing the model description")
        raw = raw_model_description(cfg, layout, guid, units, start_values(scene, cfg, layout))
        inv_mass = scene.inv_mass
        md = postprocess(raw, {v.name: v.declared_type for v in layout.reals}, layout.dependencies(inv_mass),
                         layout.initial_dependencies(inv_mass), experiment, cfg["description"])
        (tmp / "fmu" / "modelDescription.xml").write_bytes(md)
        from linknet_core.output import WriteError, atomic_write

        def pack(target):  # written whole, then renamed into place: a failed build leaves no half FMU behind
            with zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as z:
                z.write(tmp / "fmu" / "modelDescription.xml", "modelDescription.xml")
                for folder, binary in binaries.items():
                    z.write(binary, f"binaries/{folder}/{binary.name}")
                for p in sorted(sources.rglob("*")):
                    if p.is_file():
                        z.write(p, "sources/" + p.relative_to(sources).as_posix())

        progress(f"packing {out}")
        try:
            atomic_write(out, pack)
        except WriteError as e:
            raise NativeBuildError(str(e)) from None
    if not quiet:
        size = out.stat().st_size
        print(f"built {out} (native model {ident}: {sum(v.causality == 'input' for v in layout.reals)} inputs, "
              f"{sum(v.causality == 'output' for v in layout.reals)} outputs; {facts['specialisation']} "
              f"specialisation; binaries for {', '.join(folders)}; {size / 1024:.0f} KiB; "
              f"{time.perf_counter() - started:.1f} s; no Python needed by hosts)")
    return out
