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
import os
import re
import time

import numpy as np

from linknet_core.output import WriteError, failure_reason, rescue_path
from linknet_core.version import __version__
from linknet_core.scene import Scene
from linknet_core.ensemble.members import OUTPUTS, StudySpec, output_values
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
    "error_goal": ((), "m", "the position error the member's run is held to (linknet_core.accuracy; NaN for FMU "
                            "members, whose FMU logs a crossing itself)"),
}
FLUSH_SECONDS = 2.0  # at most this much finished work is only in memory should the client process die
# Members per chunk of the quantities of interest. One member per chunk, as a trajectory has, would cost the client
# ~1.3 us per member and variable in HDF5's chunk handling and give the chunk index an entry per 8 bytes; a
# batch's slab touches one or two chunks of this size, which HDF5's chunk cache holds
MEMBERS_PER_CHUNK = 4096
_QOI_KEYS = frozenset(_QOI_META)


def _h5_reason(exc: BaseException) -> str:
    """What an h5py/HDF5 failure comes down to, in one line: 'No space left on device (errno 28)' where HDF5's
    text names the system error (its messages span lines and carry buffer addresses)."""
    text = str(exc)
    match = re.search(r"errno = (\d+), error message = '([^']*)'", text)
    return f"{match.group(2)} (errno {match.group(1)})" if match else failure_reason(exc)


def _abandon(h5file) -> None:
    """Close an h5py file whose writes failed without writing anything more to it. HDF5 closing a file it cannot
    write (a full disk) fails, and its objects' deallocation later crashed the process (SIGSEGV at exit): its
    descriptor is pointed at /dev/null first, so the close succeeds and what reached the disk stays as it was."""
    if h5file is None:
        return
    _silence(h5file)
    try:
        h5file.close()
    except Exception:
        pass


def _silence(h5file) -> None:
    """Point the file's descriptor at /dev/null: HDF5 writes nothing more to the disk, and its writes succeed."""
    try:
        fd = h5file.id.get_vfd_handle()
        null = os.open(os.devnull, os.O_RDWR)
        try:
            os.dup2(null, fd)
        finally:
            os.close(null)
    except Exception:  # no descriptor (closed already, another driver): close as it is
        pass


class StudyFile:
    """Creates the file, writes batches of members, records retries, and closes it with the study's facts."""

    def __init__(self, path, spec: StudySpec, plan: Plan, scene: Scene):
        import h5py

        self.path = str(path)
        self._string = h5py.string_dtype()
        self._setup = (spec, plan, scene)  # to lay out a rescue file like this one
        self._held: list = []  # batches written since the last flush that reached the disk, whole
        self._flushed: list = []  # batches on disk: their quantities of interest, status and errors only
        self._failure: WriteError | None = None
        self._is_rescue = False
        self.h5 = None
        problem = self._room_problem(spec, plan, scene)
        if problem:
            raise WriteError(self.path, problem)
        try:
            self._layout(spec, plan, scene)
            self.h5 = h5py.File(self.path, "r+")
            self._variables = {name: self.h5[name] for name in  # looked up once: a lookup costs ~0.1 ms
                               [*spec.outputs, *_QOI_META, "status", "error", "worker", "run_seconds", "retried"]}
        except Exception as exc:  # nothing computed yet: no half file left
            _abandon(self.h5)
            try:
                os.unlink(self.path)
            except OSError:
                pass
            raise WriteError(self.path, _h5_reason(exc)) from None
        self._last_flush = time.monotonic()

    def _room_problem(self, spec: StudySpec, plan: Plan, scene: Scene) -> str | None:
        """Why the study cannot fit, said before anything runs: its numbers alone (uncompressed doubles) exceed the
        free space of the file's disk or the process's file size limit (None if they fit). Disk space taken while it
        runs is answered by the rescue file instead."""
        import resource
        import shutil

        values = plan.n_members * (output_values(scene, spec.outputs, spec.times.size) + 9)
        need = 8 * values
        free = shutil.disk_usage(os.path.dirname(os.path.abspath(self.path))).free
        limit = resource.getrlimit(resource.RLIMIT_FSIZE)[0]
        room = min(free, limit if limit != resource.RLIM_INFINITY else free)
        if need > room:
            what = "the free space on its disk" if room == free else "the file size limit (ulimit -f)"
            return (f"the study's {plan.n_members} members need at least {need / 1e6:.3g} MB, {what} is "
                    f"{room / 1e6:.3g} MB; keep fewer outputs (--outputs), fewer times (--n-out) or write elsewhere")
        return None

    def _layout(self, spec: StudySpec, plan: Plan, scene: Scene) -> None:
        import h5netcdf

        n, nt = plan.n_members, spec.times.size
        dims = {"member": n, "time": nt, "mass": scene.K, "axis": 3, "link": scene.L,
                "anchor": scene.fixed_indices.size}
        member_coordinates = " ".join(p.name for p in plan.parameters)
        f = h5netcdf.File(self.path, "w")
        try:
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
            f.close()
        except BaseException:
            _abandon(f._h5file)
            raise

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
        # a member's trajectory (time first) is its own chunk; per-member quantities go many members to a chunk
        members = 1 if "time" in shape_dims else min(dims["member"], MEMBERS_PER_CHUNK)
        chunks = tuple([members] + [dims[d] or 1 for d in shape_dims])
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
        """One finished batch (members.run_batch's result): consecutive members, written as one slab. Held in
        memory until a flush has put it on the disk; a write or flush that fails (a full disk) raises WriteError,
        and ``close`` then keeps what the file could not take in a rescue file."""
        if self._failure is not None:
            raise self._failure
        self._held.append(batch)
        try:
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
                self._flushed_now()
                self._last_flush = now
        except Exception as exc:
            raise self._fail(exc) from None

    def _flushed_now(self) -> None:
        """The held batches reached the disk: keep only their small part (what a damaged file would lose)."""
        for batch in self._held:
            self._flushed.append({**batch, "outputs": {k: v for k, v in batch["outputs"].items() if k in _QOI_KEYS}})
        self._held = []

    def _fail(self, exc: BaseException) -> WriteError:
        """The file cannot be written: abandon it (nothing more is written to it) and remember why."""
        if self.h5 is not None:
            _silence(self.h5)  # before any of its objects is released: releasing one flushes it
        self._variables = {}
        _abandon(self.h5)
        self.h5 = None
        self._failure = WriteError(self.path, _h5_reason(exc))
        return self._failure

    def mark_retried(self, members) -> None:
        members = sorted(members)
        if members and self._failure is None:
            try:
                self._variables["retried"][members] = np.ones(len(members), dtype="i1")
            except Exception as exc:
                raise self._fail(exc) from None

    def close(self, attrs: dict) -> None:
        """Close the streaming writes, then write the study's facts as netCDF global attributes (None values
        are left out). If the file could not be written (now or before), the members it may lack are written to a
        rescue file in the temporary folder, and a WriteError says which members are readable where."""
        import h5netcdf

        attrs = {"title": "linknet ensemble", "linknet_version": __version__, **attrs}
        if self._failure is None:
            try:
                self.h5.flush()  # a full disk fails here, with every object still open, not inside close
                self._variables = {}
                self.h5.close()
                self.h5 = None
                self._flushed_now()
                with h5netcdf.File(self.path, "a") as f:
                    for key, value in attrs.items():
                        if value is None:
                            continue
                        f.attrs[key] = json.dumps(value) if isinstance(value, (dict, list, tuple)) else value
                return
            except Exception as exc:
                self._fail(exc)
        if self._is_rescue:  # a rescue file that cannot be written either: the caller says what is lost
            raise self._failure
        self._rescue({**attrs, "complete": 0})

    def _readable_members(self) -> int | None:
        """How many members the abandoned file shows as run (ok or failed), or None if it cannot be read as a
        dataset (xarray opens every variable's metadata; the per-member variables are read whole)."""
        import xarray as xr

        try:
            with xr.open_dataset(self.path, engine="h5netcdf") as ds:
                for name in (*_QOI_META, "status", "error"):
                    ds[name].load()
                return int(np.sum(ds["status"].values != "not run"))
        except Exception:
            return None

    def _salvage(self, batches: list) -> list:
        """The batches on the disk of a file that cannot be read back as a whole, with the outputs (X, U, T,
        Freact) that can still be read from it (HDF5 on a full disk damages the metadata it was writing: the
        string heap, a dataset's header; the others stay readable)."""
        import h5py

        try:
            f = h5py.File(self.path, "r")
        except Exception:
            return batches
        salvaged = []
        with f:
            for batch in batches:
                rows = slice(batch["first"], batch["first"] + batch["count"])
                outputs = dict(batch["outputs"])
                ran = np.array([not e for e in batch["error"]])
                for name in self._setup[0].outputs:
                    try:
                        values = f[name][rows]
                    except Exception:
                        continue
                    if np.isfinite(values[ran]).all():  # a chunk that never reached the disk reads as NaN
                        outputs[name] = values
                salvaged.append({**batch, "outputs": outputs})
        return salvaged

    def _rescue(self, attrs: dict) -> None:
        failure = self._failure
        on_disk = sum(b["count"] for b in self._flushed)
        readable = self._readable_members()
        intact = readable is not None and readable >= on_disk
        keep = self._held if intact else self._salvage(self._flushed) + self._held  # a damaged file: all held
        count = sum(b["count"] for b in keep)
        if intact:
            where = f"the {readable} members written before are readable in it" if readable else \
                "it holds no finished member"
        else:
            where = "the failed write damaged it: it cannot be opened as a dataset"
        if not count:
            raise WriteError(self.path, failure.reason, detail=f"{where}; no other member had finished") from None
        rescue = rescue_path(self.path)
        try:
            sink = StudyFile(rescue, *self._setup)
            sink._is_rescue = True
            for batch in keep:
                sink.write(batch)
            sink.close({**attrs, "rescued_from": self.path})
        except WriteError as again:
            try:
                os.unlink(rescue)
            except OSError:
                pass
            raise WriteError(self.path, failure.reason,
                             detail=f"{where}; {count} more finished member(s) could not be kept in the temporary "
                                    f"folder either ({again.reason}) and are lost") from None
        outputs = self._setup[0].outputs
        partial = 0 if intact else sum(b["count"] for b in keep if any(o not in b["outputs"] for o in outputs))
        quantities = f" ({partial} of them with their quantities of interest, status and errors only)" if partial \
            else ""
        raise WriteError(self.path, failure.reason,
                         detail=f"{where}; {count} finished member(s){quantities} are in {rescue}, a study file "
                                "of the same layout (xarray.open_dataset)") from None
