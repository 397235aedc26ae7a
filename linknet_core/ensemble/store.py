"""The study file: netCDF-4 (HDF5), one slab of members at a time as they finish.

Every variable is laid out in full when the study starts (member is a fixed dimension, unfinished entries
read as NaN and their status as "not run"), so a study larger than memory streams to disk, a file opened
while the study runs or after it stopped is a valid dataset, and the members' order in the file never
depends on the order they finished in. Chunks hold one member each, so writing a member touches only its
own chunks.

h5netcdf lays the file out (dimensions, coordinates, attributes: the netCDF conventions); the members are
then written into those variables through h5py, which h5netcdf itself calls: under the profiler, in a
1000-member study, a write through h5netcdf took 2.0 ms per call, through h5py 0.55 ms.
"""
from __future__ import annotations

import json
import time

import numpy as np

from linknet_core.version import __version__
from linknet_core.scene import Scene
from linknet_core.ensemble.members import OUTPUTS, StudySpec
from linknet_core.ensemble.parameters import Plan

_AXES = np.array(["x", "y", "z"])

# long names and units of what the file holds per member
_OUTPUT_META = {
    "X": (("time", "mass", "axis"), "m", "position of each mass"),
    "U": (("time", "mass", "axis"), "m/s", "velocity of each mass"),
    "T": (("time", "link"), "N", "tension in each link (> 0 pulls the two masses together)"),
    "Freact": (("time", "anchor", "axis"), "N", "force the network exerts on each anchored mass"),
}
_QOI_META = {
    "max_tension": ((), "N", "largest tension over links and output samples"),
    "max_tension_link": ((), "1", "link carrying the largest tension (1-based; 0: no links)"),
    "min_tension": ((), "N", "smallest tension over links and output samples (< 0: compression)"),
    "tip_final": (("axis",), "m", "position of the tip mass at t_end"),
    "error_estimate": ((), "m", "largest estimated position error of any mass over the output samples "
                                "(linknet_core.accuracy; NaN where the member's FMU does not report one)"),
}
FLUSH_SECONDS = 2.0  # at most this much finished work is only in memory should the client process die


class StudyFile:
    """Creates the file, writes batches of members, records retries, and closes it with the study's facts."""

    def __init__(self, path, spec: StudySpec, plan: Plan, scene: Scene):
        import h5netcdf
        import h5py

        self.path = str(path)
        self._string = h5py.string_dtype()
        n, nt = plan.n_members, spec.times.size
        dims = {"member": n, "time": nt, "mass": scene.K, "axis": 3, "link": scene.L,
                "anchor": scene.fixed_indices.size}
        member_coordinates = " ".join(p.name for p in plan.parameters)
        with h5netcdf.File(self.path, "w") as f:
            f.dimensions = dims
            self._coordinate(f, "member", ("member",), np.arange(n), "", "member number (0-based, in plan order)")
            self._coordinate(f, "time", ("time",), spec.times, "s", "output time")
            self._coordinate(f, "mass", ("mass",), np.arange(1, scene.K + 1), "",
                             "mass number (1-based, as in M[k], X[k,i])")
            self._coordinate(f, "mass_name", ("mass",), np.array(scene.mass_names, dtype=object), "", "mass name")
            self._coordinate(f, "axis", ("axis",), _AXES.astype(object), "", "axis")
            self._coordinate(f, "link", ("link",), np.arange(1, scene.L + 1), "",
                             "link number (1-based, as in R[l], T[l])")
            self._coordinate(f, "k1", ("link",), scene.k1 + 1, "", "first mass of each link (1-based)")
            self._coordinate(f, "k2", ("link",), scene.k2 + 1, "", "second mass of each link (1-based)")
            self._coordinate(f, "anchor", ("anchor",), scene.fixed_indices + 1, "", "anchored mass number (1-based)")
            for p in plan.parameters:
                values = plan.values[p.name]
                self._coordinate(f, p.name, ("member",), values.astype(object) if p.family.text else values, p.unit,
                           p.describe(scene))
            for name in OUTPUTS:
                if name in spec.outputs:
                    extra = {"X": " mass_name", "U": " mass_name", "T": " k1 k2"}.get(name, "")
                    self._data(f, name, _OUTPUT_META[name], dims, member_coordinates + extra)
            for name, meta in _QOI_META.items():
                self._data(f, name, meta, dims, member_coordinates, integer=name == "max_tension_link")
            status = self._per_member(f, "status", "ok, failed or not run", member_coordinates, text=True)
            status[:] = np.array(["not run"] * n, dtype=object)
            self._per_member(f, "error", "why the member failed ('' if it did not)", member_coordinates, text=True)
            self._per_member(f, "worker", "address of the Dask worker that ran the member", "", text=True)
            self._per_member(f, "run_seconds", "wall time of the member on its worker", "", unit="s")
            retried = self._per_member(f, "retried", "1 if the member ran again after its worker died", "",
                                       dtype="i1")
            retried[:] = np.zeros(n, dtype="i1")
        self.h5 = h5py.File(self.path, "r+")
        self._variables = {name: self.h5[name] for name in  # looked up once: a lookup costs ~0.1 ms
                           [*spec.outputs, *_QOI_META, "status", "error", "worker", "run_seconds", "retried"]}
        self._last_flush = time.monotonic()

    def _coordinate(self, f, name, dims, values, unit, long_name):
        text = np.asarray(values).dtype == object
        var = f.create_variable(name, dims, self._string if text else np.asarray(values).dtype)
        var[:] = values
        var.attrs["long_name"] = long_name
        if unit:
            var.attrs["units"] = unit

    def _data(self, f, name, meta, dims, coordinates, integer=False):
        shape_dims, unit, long_name = meta
        all_dims = ("member",) + shape_dims
        chunks = tuple([1] + [dims[d] or 1 for d in shape_dims])
        # integers get no _FillValue: xarray would read every 0 (no link, not run) as missing
        var = f.create_variable(name, all_dims, "i4" if integer else "f8", chunks=chunks,
                                fillvalue=None if integer else np.nan)
        var.attrs.update({"units": unit, "long_name": long_name})
        if coordinates:
            var.attrs["coordinates"] = coordinates

    def _per_member(self, f, name, long_name, coordinates, text=False, unit="", dtype="f8"):
        var = f.create_variable(name, ("member",), self._string if text else dtype,
                                fillvalue=np.nan if dtype == "f8" and not text else None)
        var.attrs["long_name"] = long_name
        if unit:
            var.attrs["units"] = unit
        if coordinates:
            var.attrs["coordinates"] = coordinates
        return var

    def write(self, batch: dict) -> None:
        """One finished batch (members.run_batch's result): consecutive members, written as one slab."""
        rows = slice(batch["first"], batch["first"] + batch["count"])
        variables = self._variables
        for name, values in batch["outputs"].items():
            variables[name][rows] = values
        errors = batch["error"]
        variables["status"][rows] = np.array(["failed" if e else "ok" for e in errors], dtype=object)
        variables["error"][rows] = np.array(errors, dtype=object)
        variables["worker"][rows] = np.array([batch["worker"]] * batch["count"], dtype=object)
        variables["run_seconds"][rows] = batch["run_seconds"]
        now = time.monotonic()
        if now - self._last_flush > FLUSH_SECONDS:
            self.h5.flush()
            self._last_flush = now

    def mark_retried(self, members) -> None:
        members = sorted(members)
        if members:
            self._variables["retried"][members] = np.ones(len(members), dtype="i1")

    def close(self, attrs: dict) -> None:
        """Close the streaming writes, then write the study's facts as netCDF global attributes (None values
        are left out)."""
        import h5netcdf

        self.h5.close()
        attrs = {"title": "linknet ensemble", "linknet_version": __version__, **attrs}
        with h5netcdf.File(self.path, "a") as f:
            for key, value in attrs.items():
                if value is None:
                    continue
                f.attrs[key] = json.dumps(value) if isinstance(value, (dict, list, tuple)) else value
