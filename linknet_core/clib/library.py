"""The native core's shared library (built from src/ at install time) and its structs, as ctypes sees them.

ln_model, ln_method, struct ln_rigid_model, ln_energy_terms and ln_data are built from the library's table of their
fields (src/ln_model_fields.h and src/ln_data_fields.h list them once) and checked offset by offset against the
compiler's.
Everything here is declaration: what the model and data mean, and how they are filled, is in
:mod:`linknet_core.native.model`.
"""
from __future__ import annotations

import ctypes
import importlib.machinery
from pathlib import Path
from typing import NamedTuple

import numpy as np

# the compiled library and its sources live in linknet_core/native/ (setup.py builds them there)
NATIVE_DIR = Path(__file__).resolve().parent.parent / "native"
SOURCE_DIR = NATIVE_DIR / "src"

ln_int = ctypes.c_int64
c_double_p = ctypes.POINTER(ctypes.c_double)
ln_int_p = ctypes.POINTER(ln_int)
c_uint8_p = ctypes.POINTER(ctypes.c_uint8)

# enum ln_status, as the messages name them
STATUS = {0: "ok", 1: "projection failed", 2: "singular", 3: "non-finite", 4: "step underflow", 5: "too many steps",
          6: "left the plane", 7: "implicit kick failed", 8: "bad argument", 9: "out of memory",
          10: "anchor motion failed", 11: "rope event chatter", 12: "no rope mode", 13: "not linearizable"}
OK, PROJECTION_FAILED, SINGULAR, NON_FINITE, STEP_UNDERFLOW, TOO_MANY_STEPS = 0, 1, 2, 3, 4, 5
LEFT_PLANE, IMPLICIT_KICK_FAILED, BAD_ARGUMENT, NO_MEMORY, DRIVE_FAILED = 6, 7, 8, 9, 10
EVENT_CHATTER, NO_MODE, NOT_LINEARIZABLE = 11, 12, 13
# enum ln_event_kind: the kinds of a rope's event in ln_data's log, by the names linknet_core.dynamics.unilateral.Event
# gives them
EVENT_KINDS = ("taut", "slack", "contact", "release", "stick", "slip")
SOLVER_NONE, SOLVER_CHAIN, SOLVER_LDL, SOLVER_MIN_NORM = 0, 1, 2, 3
COMPOSITION, RUNGE_KUTTA, STATIC = 0, 1, 2
RMS_ERROR, HAIRER_ERROR = 0, 1


def _library_path() -> Path:
    here = NATIVE_DIR
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        candidate = here / f"_linknet{suffix}"
        if candidate.exists():
            return candidate
    raise ImportError(f"linknet's native core is not built in {here}: install the package (`pip install -e .` "
                      "compiles linknet_core/native/src with the system's C compiler)")


lib = ctypes.CDLL(str(_library_path()))


def _declare(name, restype, *argtypes):
    function = getattr(lib, name)
    function.restype = restype
    function.argtypes = list(argtypes)
    return function


# ---- the structs, mirrored from the library's own table of their fields (src/ln_model_fields.h and
# src/ln_data_fields.h list them; model_fields.c expands the lists into the table): nothing here repeats a field, and
# every offset is checked against the compiler's
_struct_fields = _declare("ln_struct_fields", ln_int, ctypes.c_int)
struct_size = _declare("ln_struct_size", ctypes.c_size_t, ctypes.c_int)
_struct_field = _declare("ln_struct_field", ctypes.c_char_p, ctypes.c_int, ln_int, ctypes.POINTER(ctypes.c_int),
                         ctypes.c_char_p, ctypes.POINTER(ln_int), ctypes.POINTER(ctypes.c_size_t),
                         ctypes.POINTER(ctypes.c_size_t))
struct_field_count = _declare("ln_struct_field_count", ln_int, ctypes.c_int, ln_int, ctypes.c_void_p, ctypes.c_void_p)
MODEL_STRUCT, METHOD_STRUCT, RIGID_MODEL_STRUCT, DATA_STRUCT, ENERGY_TERMS_STRUCT = 0, 1, 2, 3, 4  # enum ln_struct
FIELD_SCALAR, FIELD_ARRAY, FIELD_FIXED, FIELD_OPAQUE = 0, 1, 2, 3  # enum ln_field_kind
# LN_FIELD_CODE of a type: the character Python's struct module (and numpy) give the same type
CTYPES_OF_CODE = {"q": ln_int, "i": ctypes.c_int, "d": ctypes.c_double, "B": ctypes.c_uint8}


class StructField(NamedTuple):
    """One field of a core struct, as the library's table gives it."""

    name: str
    kind: int       # FIELD_SCALAR, FIELD_ARRAY, FIELD_FIXED, FIELD_OPAQUE
    code: str       # its type's code (CTYPES_OF_CODE); "" for an opaque pointer
    fixed: int      # FIELD_FIXED: entries
    offset: int
    size: int       # bytes of one entry


def struct_fields(which: int) -> list[StructField]:
    """The fields of a core struct (an enum ln_struct: MODEL_STRUCT, ...) in declaration order."""
    out = []
    kind, code, fixed, offset, size = ctypes.c_int(), ctypes.create_string_buffer(1), ln_int(), ctypes.c_size_t(), \
        ctypes.c_size_t()
    for i in range(_struct_fields(which)):
        name = _struct_field(which, i, kind, code, fixed, offset, size)
        out.append(StructField(name.decode(), kind.value, code.raw.rstrip(b"\0").decode(), fixed.value, offset.value,
                               size.value))
    return out


def _mirror(which: int, class_name: str, doc: str) -> type:
    """The ctypes Structure of a core struct, from the library's table; refused (ImportError) where ctypes would lay
    out a field elsewhere than the compiler did."""
    fields = []
    for f in struct_fields(which):
        if f.kind == FIELD_OPAQUE:
            fields.append((f.name, ctypes.c_void_p))
        elif f.kind == FIELD_ARRAY:
            fields.append((f.name, ctypes.POINTER(CTYPES_OF_CODE[f.code])))
        elif f.kind == FIELD_FIXED:
            fields.append((f.name, CTYPES_OF_CODE[f.code] * f.fixed))
        else:
            fields.append((f.name, CTYPES_OF_CODE[f.code]))
    mirror = type(class_name, (ctypes.Structure,), {"_fields_": fields, "__doc__": doc})
    for f in struct_fields(which):
        if getattr(mirror, f.name).offset != f.offset:
            raise ImportError(f"linknet's native core: ctypes lays out {class_name}.{f.name} at byte "
                              f"{getattr(mirror, f.name).offset}, the C compiler at {f.offset}")
    if ctypes.sizeof(mirror) != struct_size(which):
        raise ImportError(f"linknet's native core: ctypes makes {class_name} {ctypes.sizeof(mirror)} bytes long, the C "
                          f"compiler {struct_size(which)}")
    return mirror


Model = _mirror(MODEL_STRUCT, "Model", "ln_model (src/ln_model_fields.h: LN_MODEL_FIELDS).")
Method = _mirror(METHOD_STRUCT, "Method", "ln_method (src/ln_model_fields.h: LN_METHOD_FIELDS).")
RigidModel = _mirror(RIGID_MODEL_STRUCT, "RigidModel", "struct ln_rigid_model (src/ln_model_fields.h: "
                     "LN_RIGID_MODEL_FIELDS).")
EnergyTerms = _mirror(ENERGY_TERMS_STRUCT, "EnergyTerms", "ln_energy_terms (src/ln_model_fields.h: "
                      "LN_ENERGY_TERMS_FIELDS).")
# ln_data: its scratch and the objects it owns are the C side's own, mirrored only for their places (OWNED and
# BORROWED fields are opaque pointers)
Data = _mirror(DATA_STRUCT, "Data", "ln_data (src/ln_data_fields.h: LN_DATA_FIELDS).")

Model_p, Method_p, Data_p = ctypes.POINTER(Model), ctypes.POINTER(Method), ctypes.POINTER(Data)
data_new = _declare("ln_data_new", Data_p, Model_p, ln_int)
data_free = _declare("ln_data_free", None, Data_p)
data_reset = _declare("ln_data_reset", None, Model_p, Data_p)
advance = _declare("ln_advance", ctypes.c_int, Model_p, Method_p, Data_p, ctypes.c_double, ln_int)
evaluate = _declare("ln_evaluate", ctypes.c_int, Model_p, Data_p, c_double_p, c_double_p)
sample = _declare("ln_sample", ctypes.c_int, Model_p, Method_p, Data_p, c_double_p, ln_int, ctypes.c_int, ln_int,
                  c_double_p, c_double_p, c_double_p, c_double_p, c_double_p, ctypes.POINTER(EnergyTerms), c_double_p,
                  ln_int, ctypes.POINTER(ln_int))
sample_diagnostics = _declare("ln_sample_diagnostics", None, Model_p, ctypes.POINTER(EnergyTerms), c_double_p,
                              c_double_p, c_double_p)
evaluate_repeated = _declare("ln_evaluate_repeated", ctypes.c_int, Model_p, Data_p, ctypes.c_int, c_double_p,
                             c_double_p, ln_int)
rope_events_drained = _declare("ln_rope_events_drained", ln_int, Data_p)
jump_anchors = _declare("ln_jump_anchors", ctypes.c_int, Model_p, Method_p, Data_p)
rope_initial_state = _declare("ln_rope_initial_state", ctypes.c_int, Model_p, Method_p, Data_p, c_double_p, c_double_p,
                              ctypes.c_int)
# the stages' room a fixed-step method's screen of the ropes' forces inside its steps takes (stages/rattle.c; the
# native FMU sizes its data by it too)
midpoint_rows = _declare("ln_midpoint_rows", ln_int, Model_p, Method_p)
model_weights_size = _declare("ln_model_weights_size", ln_int, Model_p)
model_weights = _declare("ln_model_weights", ctypes.c_int, Model_p, c_double_p, c_double_p, c_double_p, c_double_p,
                         c_double_p)
_force_kind = _declare("ln_force_kind", ln_int, ctypes.c_char_p)
force_kind_name = _declare("ln_force_kind_name", ctypes.c_char_p, ln_int)
fixed_step_count = _declare("ln_fixed_step_count", ln_int, ctypes.c_double, ctypes.c_double)
# the structure analysis's graph routines (src/graph.h); arrays passed by address (np.ndarray.ctypes.data)
_graph_components = _declare("ln_graph_components", ln_int, ln_int, ln_int, ctypes.c_void_p, ctypes.c_void_p,
                             ctypes.c_void_p)
_forest_depth = _declare("ln_forest_depth", ctypes.c_int, ln_int, ln_int, ctypes.c_void_p, ctypes.c_void_p,
                         ctypes.c_void_p)
# int (*)(void *user, double t, double *PVA): the driven anchors' motion callback (ln_data.drive_callback)
DRIVE_CALLBACK = ctypes.CFUNCTYPE(ctypes.c_int, ctypes.c_void_p, ctypes.c_double, c_double_p)


def pointer(array: np.ndarray, ctype=ctypes.c_double):
    """A ctypes pointer to a C-contiguous array's first element (the array must outlive its use)."""
    if not array.flags.c_contiguous:
        raise ValueError("the native core takes C-contiguous arrays")
    return array.ctypes.data_as(ctypes.POINTER(ctype))


def first_double(array: np.ndarray):
    """A C-contiguous float64 array's first element as a ctypes c_double sharing its memory, to pass where a
    function takes double * (ctypes passes its address), or None (NULL) for an empty array: ~0.3 us against ~3 us
    for :func:`pointer`, for arguments of calls made per advance or per run."""
    return ctypes.c_double.from_buffer(array) if array.size else None


def int_array(values) -> np.ndarray:
    return np.ascontiguousarray(values, np.int64)


def float_array(values) -> np.ndarray:
    return np.ascontiguousarray(values, np.float64)


def graph_components(n_nodes: int, a: np.ndarray, b: np.ndarray) -> tuple[int, np.ndarray]:
    """(count, label (n_nodes,)) of the connected components of the graph with edges a[e]-b[e], numbered in
    the order of their smallest node (as scipy.sparse.csgraph.connected_components numbers them)."""
    a, b = int_array(a), int_array(b)
    label = np.empty(n_nodes, np.int64)
    count = _graph_components(n_nodes, a.size, a.ctypes.data, b.ctypes.data, label.ctypes.data)
    if count < 0:
        raise ValueError("graph components: an edge end out of range (or out of memory)")
    return int(count), label


def forest_depth(n_nodes: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Depth (n_nodes,) of every node of a forest below its tree's root, the tree's smallest leaf."""
    a, b = int_array(a), int_array(b)
    depth = np.empty(n_nodes, np.int64)
    if _forest_depth(n_nodes, a.size, a.ctypes.data, b.ctypes.data, depth.ctypes.data) != 0:
        raise ValueError("forest depth: the graph has a cycle (or an edge end out of range, or out of memory)")
    return depth


def force_kind_names() -> list[str]:
    """The core's force element kinds (stages/forces.c), in the order of their codes."""
    names = []
    while (name := force_kind_name(len(names))) is not None:
        names.append(name.decode())
    return names


def force_kind(name: bytes) -> int:
    """The core's code of a force element kind (-1: none). linknet_core.native.model checks every kind of the core
    against the scene's FORCE_KINDS when it loads, so a kind the core lacks stops the first native model instead of
    being skipped."""
    return _force_kind(name)
