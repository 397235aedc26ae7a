"""ln_data as its field list (src/ln_data_fields.h) makes it: a reset data holds what a new one holds, field by field.

The fields come from the library's table, so that a field added to the list is checked here without a line of this
file: every scalar the reset zeroes and every array it allocates, entry by entry.
"""
from __future__ import annotations

import ctypes
from pathlib import Path

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.clib import library as lib
from linknet_core.native.model import NativeData

MODELS = Path(__file__).resolve().parents[2] / "models"
# what ln_data_reset keeps by design (the list's KEPT fields): the time origin and the sizes of allocations
KEPT = {"drive_t0", "n_stages_allocated", "krylov_size"}


def _fields(data: NativeData) -> dict:
    """Every scalar and array of the data, by name: scalars as numbers, arrays as copies of their entries."""
    struct, out = data.struct, {}
    for i, f in enumerate(lib.struct_fields(lib.DATA_STRUCT)):
        if f.kind == lib.FIELD_SCALAR:
            out[f.name] = getattr(struct, f.name)
        elif f.kind == lib.FIELD_ARRAY:
            count = lib.struct_field_count(lib.DATA_STRUCT, i, ctypes.addressof(struct), data.model.pointer)
            assert count >= 0, f.name
            pointer = getattr(struct, f.name)
            out[f.name] = np.ctypeslib.as_array(pointer, (count,)).copy() if count else np.zeros(0)
    return out


@pytest.mark.parametrize("name", ["crane", "net_10x10", "braced_tower"])  # driven anchor, LDL, minimum-norm
def test_a_reset_data_is_a_new_data(name):
    scene = ln.load_scene(MODELS / f"{name}.json")
    sim = ln.Simulator(scene, method="dopri5", rtol=1e-6, backend="native")
    F = np.zeros((scene.K, 3))
    F[scene.free_indices[-1]] = [0.3, -0.2, 0.5]
    sim.advance(0.05, F)
    data = sim.integrator.data
    run = _fields(data)
    fresh = _fields(NativeData(data.model, sim.integrator.method.n_stages))
    # the run moved the state and the counters: the comparison after the reset has something to undo
    assert run["t"] != fresh["t"] and run["steps"] > 0 and not np.array_equal(run["X"], fresh["X"])
    assert np.any(run["F_input"] != 0.0)

    data.reset()
    after = _fields(data)
    assert after.keys() == fresh.keys() and {"X", "KX", "steps", "drive_hold_t"} <= after.keys()
    for field, value in fresh.items():
        if field in KEPT:
            assert after[field] == run[field], field
        elif isinstance(value, np.ndarray):
            np.testing.assert_array_equal(after[field], value, err_msg=field)
        else:
            assert after[field] == value, field
