"""The study file: netCDF-4 (HDF5), its members' trajectories in shard files beside it, joined when it closes.

Every variable is laid out in full when the study starts (member is a fixed dimension, unfinished entries
read as NaN and their status as "not run"), so a file opened while the study runs or after it stopped is a valid
dataset, and the members' order in the file never depends on the order they finished in.

The trajectories (X, U, T, Freact) are written by the workers that ran the members, a shard file per task in the
folder beside the study file (shards.py); the client writes only what is small: each member's status, error,
run time, worker and quantities of interest, ~100 bytes, and keeps which members are in which shard. When the
study closes, each trajectory variable becomes an HDF5 virtual dataset that maps every task's members to its
shard: the file reads as one dataset (xarray, h5py, netCDF-4 through HDF5 1.10 or later) as long as the folder
stays beside it, and members of no shard (failed, not run) read as NaN. Without its folder it would read NaN
trajectories too: its attributes say what it depends on, and study_files.py's open_study checks the shards,
consolidate makes one self-contained file, and recover rebuilds the file from the folder, which keeps the file as
laid out when the study started (``layout.nc``). A batch whose worker did not write its
shard (a worker that does not see the folder, a failed write) brings its trajectories to the client, which writes
the shard itself.

h5netcdf lays the file out (dimensions, coordinates, attributes: the netCDF conventions); the members are
then written into those variables through h5py, which h5netcdf itself calls: under the profiler, in a
1000-member study, a write through h5netcdf took 2.0 ms per call, through h5py 0.55 ms.

A write that fails (a full disk) does not stop the study: the study goes on in a rescue file of the same layout in
the temporary folder (``$TMPDIR``), which takes every member finished so far (their small part from memory, their
trajectories from the shards already written) and those still to come, and the study ends with a WriteError
naming both files.
"""
from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path

import numpy as np

from linknet_core.output import WriteError, atomic_write, failure_reason, rescue_path
from linknet_core.version import __version__
from linknet_core.scene import Scene
from linknet_core.ensemble.members import OUTPUTS, StudySpec, output_values
from linknet_core.ensemble.parameters import Plan
from linknet_core.ensemble.shards import (LAYOUT, abandon as _abandon, folder_for, h5_reason as _h5_reason,
                                          prepare_folder, read_shard, remove_folder, remove_unlisted, shard_files,
                                          shard_study, silence as _silence, write_shard)

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
# at most this much of the members' small part (status, quantities of interest) is only in memory should the client
# process die; their trajectories are on disk in the shards as soon as each task ends
FLUSH_SECONDS = 2.0
# Members per chunk of the quantities of interest. One member per chunk would cost the client
# ~1.3 us per member and variable in HDF5's chunk handling and give the chunk index an entry per 8 bytes; a
# batch's slab touches one or two chunks of this size, which HDF5's chunk cache holds
MEMBERS_PER_CHUNK = 4096


class StudyFile:
    """Creates the file and its shard folder, takes finished batches, records retries, and closes it with the
    study's facts, the trajectories joined."""

    def __init__(self, path, spec: StudySpec, plan: Plan, scene: Scene, rescue: bool = False,
                 attrs: dict | None = None):
        import h5py

        self.path = str(path)
        self._string = h5py.string_dtype()
        self._attrs = dict(attrs or {})  # the study's facts known at its start, written with the layout
        self._setup = (spec, plan, scene)  # to lay out a rescue file like this one
        self._study_id = spec.study_id
        self._trajectories = [name for name in OUTPUTS if name in spec.outputs]
        # absolute: the workers are told this folder, and their shards' paths come back in its terms
        self.shard_folder = str(folder_for(os.path.abspath(self.path))) if self._trajectories else None
        # every batch taken: its small part (quantities of interest, status, errors) and the path of its shard
        self._records: list[dict] = []
        self._held: dict | None = None  # a batch whose trajectories are in no shard yet: the one being written
        self._retried: list[int] = []
        self._failure: WriteError | None = None
        self._failed_shard: str | None = None  # the shard whose write failed, if that was the failure
        self._is_rescue = rescue
        self._rescue: StudyFile | None = None  # where the study goes on after this file failed
        self._lost: WriteError | None = None  # the rescue failed too
        self._taken = 0  # members handed to write, in this file or its rescue
        self.client_shard_reason: str | None = None  # why the first batch whose shard the client wrote came back whole
        self.h5 = None
        problem = self._room_problem(spec, plan, scene)
        if problem:
            raise WriteError(self.path, problem)
        if self.shard_folder:
            prepare_folder(Path(self.shard_folder), spec.study_id)
        try:
            self._layout(spec, plan, scene)
            if self.shard_folder:  # kept with the shards: the study file can be rebuilt from the folder alone
                atomic_write(Path(self.shard_folder) / LAYOUT,
                             lambda temporary: shutil.copyfile(self.path, temporary))
            self.h5 = h5py.File(self.path, "r+")
            self._variables = {name: self.h5[name] for name in  # looked up once: a lookup costs ~0.1 ms
                               [*_QOI_META, "status", "error", "worker", "run_seconds", "retried"]}
        except Exception as exc:  # nothing computed yet: no half file left
            _abandon(self.h5)
            try:
                os.unlink(self.path)
            except OSError:
                pass
            if self.shard_folder:
                remove_folder(Path(self.shard_folder))
            raise WriteError(self.path, _h5_reason(exc)) from None
        self._last_flush = time.monotonic()

    def _room_problem(self, spec: StudySpec, plan: Plan, scene: Scene) -> str | None:
        """Why the study cannot fit, said before anything runs: its numbers alone (uncompressed doubles) exceed the
        free space of the file's disk or the process's file size limit (None if they fit). Disk space taken while it
        runs is answered by the rescue file instead."""
        import resource

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
            # the facts known now (no "complete" yet: a file without it was never closed), and where its
            # trajectories will be, so that even a file whose study never ended says what it needs
            attrs = {"title": "linknet ensemble", "linknet_version": __version__, **self._attrs,
                     "study_id": spec.study_id}
            if self.shard_folder:
                attrs.update(shard_attributes(self.path, [self.shard_folder], self._trajectories))
            for key, value in attrs.items():
                if value is not None:
                    f.attrs[key] = _attribute(value)
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
            status = self._per_member(f, "status", "ok, failed or not run (missing: a study rebuilt from its shards "
                                      "(linknet ensemble recover) found no shard holding the member)",
                                      member_coordinates, text=True)
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
        # a trajectory variable holds nothing until the file closes and it becomes the join of the shards (never
        # allocated, it reads as NaN meanwhile); per-member quantities go many members to a chunk
        members = 1 if "time" in shape_dims else min(dims["member"], MEMBERS_PER_CHUNK)
        chunks = tuple([members] + [dims[d] or 1 for d in shape_dims])
        # integers get no _FillValue: xarray would read every 0 (no link, not run) as missing
        var = f.create_variable(name, all_dims, "i4" if integer else "f8", chunks=chunks,
                                fillvalue=None if integer else np.nan)
        var.attrs.update({"units": unit, "long_name": long_name})
        if coordinates:
            var.attrs["coordinates"] = coordinates
        if "time" in shape_dims:  # shown with the variable (ncdump -h, xarray's attrs): where its values are
            var.attrs["stored_in"] = (f"shard files in the folder {Path(self.shard_folder).name} beside this file "
                                      "(see the global attribute depends_on)")

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
        """One finished batch (members.run_batch's result): consecutive members. Its small part goes into the
        file as one slab; trajectories that came with it (its worker did not write its shard) are written as its
        shard here. A write or flush that fails (a full disk) raises WriteError once; the batches that follow go
        to the rescue file (``continues`` says whether the study can go on)."""
        if self._failure is not None:
            if self._is_rescue:
                raise self._failure
            self._taken += batch["count"]
            return self._rescue_write(batch)
        self._taken += batch["count"]
        written_by_client = bool(batch.get("written_by_client"))
        try:
            if any(name in OUTPUTS for name in batch["outputs"]):  # the client writes this batch's shard
                self._held = batch
                if self.client_shard_reason is None:
                    self.client_shard_reason = batch.get("shard_error") or "its worker does not see the folder"
                try:
                    shard = write_shard(self.shard_folder, self._study_id, batch, OUTPUTS)
                except WriteError as exc:
                    self._failed_shard = exc.path
                    raise
                batch = {**batch, "shard": str(shard),
                         "outputs": {k: v for k, v in batch["outputs"].items() if k not in OUTPUTS}}
                self._held = None
                written_by_client = True
            record = {key: batch[key] for key in ("first", "count", "outputs", "error", "run_seconds", "worker")}
            record.update(shard=batch.get("shard"), written_by_client=written_by_client,
                          offset=batch.get("offset", 0), shard_count=batch.get("shard_count", batch["count"]))
            self._records.append(record)
            record_batch(self._variables, record)
            now = time.monotonic()
            if now - self._last_flush > FLUSH_SECONDS:
                self.h5.flush()
                self._last_flush = now
        except Exception as exc:
            raise self._fail(exc) from None

    def continues(self) -> bool:
        """Whether the study can go on after a failed write: its members go to the rescue file, unless that failed
        too."""
        return not self._is_rescue and self._lost is None

    def _fail(self, exc: BaseException) -> WriteError:
        """The file cannot be written: abandon it (nothing more is written to it) and remember why."""
        if self.h5 is not None:
            _silence(self.h5)  # before any of its objects is released: releasing one flushes it
        self._variables = {}
        _abandon(self.h5)
        self.h5 = None
        reason = exc.reason if isinstance(exc, WriteError) else _h5_reason(exc)
        self._failure = WriteError(self.path, reason)
        return self._failure

    def _rescue_write(self, batch: dict) -> None:
        if self._lost is not None:
            raise self._lost
        if self._rescue is None:
            self._start_rescue()
        try:
            self._rescue.write(batch)
        except WriteError as again:
            raise self._lose(again) from None

    def _start_rescue(self) -> None:
        """Lay out the rescue file and give it every member taken so far (their shards stay where they are)."""
        try:
            rescue = StudyFile(rescue_path(self.path), *self._setup, rescue=True, attrs=self._attrs)
        except WriteError as again:
            raise self._lose(again) from None
        self._rescue = rescue
        try:
            for record in self._records:
                rescue.write(record)
            if self._held is not None:
                rescue.write(self._held)
                self._held = None
        except WriteError as again:
            raise self._lose(again) from None

    def _lose(self, again: WriteError) -> WriteError:
        """The rescue file cannot be written either: remove it, and say what is lost and what stays."""
        if self._rescue is not None:
            self._rescue._fail(again)
            remove_study(self._rescue.path)
            self._rescue = None
        shards = f", but for the trajectories in the shard files of {self.shard_folder}" if self.shard_folder else ""
        self._lost = WriteError(self.path, self._failure.reason,
                                detail=f"{self._taken} finished member(s) could not be kept in the temporary folder "
                                       f"either ({again.reason}) and are lost{shards}")
        return self._lost

    def mark_retried(self, members) -> None:
        """The members that ran again after their worker died (written when the file closes)."""
        self._retried = sorted(members)

    def close(self, attrs: dict) -> None:
        """Join the trajectories (virtual datasets over the shards), remove what no member needs from the shard
        folder, and write the study's facts as netCDF global attributes (None values are left out; ``complete``
        is 1 unless given). A study that did not complete first takes the shards in its folder that finished but
        whose results it had not received yet: their members count as finished. If the file could not be written
        (now or before), the study's members are in the rescue file, and a WriteError says where."""
        attrs = {"title": "linknet ensemble", "linknet_version": __version__, **self._attrs, **attrs}
        attrs["complete"] = int(attrs.get("complete", 1))
        if self._failure is None and not attrs["complete"] and self.shard_folder:
            try:
                self._take_finished_shards()
            except Exception as exc:
                self._fail(exc)
        if self._trajectories:  # who wrote the trajectories (all by the client: the workers do not see the folder)
            by_client = sum(r["count"] for r in self._records if r["shard"] and r["written_by_client"])
            attrs["members_written_by_workers"] = sum(r["count"] for r in self._records if r["shard"]) - by_client
            attrs["members_written_by_client"] = by_client
            if attrs.get("client_shard_reason") is None:
                attrs["client_shard_reason"] = self.client_shard_reason if by_client else None
        if self._failure is None:
            try:
                if self._retried:
                    self._variables["retried"][self._retried] = np.ones(len(self._retried), dtype="i1")
                join_trajectories(self.h5, self._trajectories, self._records, self.shard_folder)
                self.h5.flush()  # a full disk fails here, with every object still open, not inside close
                self._variables = {}
                self.h5.close()
                self.h5 = None
                folders = shard_folders(self._records)
                write_attributes(self.path, {**attrs, **shard_attributes(self.path, folders, self._trajectories)},
                                 remove=() if folders else SHARD_ATTRIBUTES)
                if self.shard_folder:
                    remove_unlisted(self.shard_folder, [r["shard"] for r in self._records if r["shard"]])
                return
            except Exception as exc:
                self._fail(exc)
        if self._is_rescue:  # a rescue file that cannot be written either: the caller says what is lost
            raise self._failure
        if self._lost is not None:
            raise self._lost
        count = self._taken
        if not count:
            raise WriteError(self.path, self._failure.reason, detail="no member had finished")
        if self._rescue is None:
            self._start_rescue()
        rescue = self._rescue
        try:
            rescue.mark_retried(self._retried)
            rescue.close({**attrs, "complete": 0, "rescued_from": self.path})
        except WriteError as again:
            raise self._lose(again) from None
        failed = f" (writing {self._failed_shard})" if self._failed_shard else ""
        shards = f" whose trajectories are in the shard files of {self.shard_folder} and {rescue.shard_folder}" \
            if self.shard_folder else ""
        raise WriteError(self.path, self._failure.reason + failed,
                         detail=f"the study went on in the temporary folder: its {count} finished member(s) are in "
                                f"{rescue.path}, a study file of the same layout (xarray.open_dataset){shards}")

    @property
    def members_kept(self) -> int:
        """Members whose results are in the file (finished, or failed with their error), its rescue's included."""
        return self._taken

    def _take_finished_shards(self) -> None:
        """Record the members of this study's shards that finished but were not received (a study stopped while
        their results were on their way) and are in no record yet."""
        covered = np.zeros(self._variables["status"].shape[0], dtype=bool)
        for record in self._records:
            covered[record["first"]:record["first"] + record["count"]] = True
        listed = {Path(r["shard"]).name for r in self._records if r["shard"]}
        waiting = [path for path in shard_files(self.shard_folder)
                   if path.name not in listed and shard_study(path) == self._study_id[:12]]
        datasets = {**self._variables, **{name: self.h5[name] for name in self._trajectories}}
        records, _ = shard_records(waiting, covered, datasets, self._trajectories)
        for record in records:
            self._records.append(record)
            record_batch(self._variables, record)
            self._taken += record["count"]

    def tidy(self) -> int:
        """Remove from the shard folder what the closed file does not map: shards of results it did not take and
        temporary files, such as those of workers stopped part way through a write while the study ended
        (called once the study's workers are stopped). Returns how many files were removed."""
        if not self.shard_folder or not os.path.isdir(self.shard_folder):
            return 0
        return remove_unlisted(self.shard_folder, [r["shard"] for r in self._records if r["shard"]])


# the attributes saying that a study file's trajectories are read from its shard files (removed from a file that
# holds them itself)
SHARD_ATTRIBUTES = ("shard_folder", "depends_on")
_STORED_IN = "stored_in"  # the same, on each trajectory variable


def shard_folders(records) -> list[str]:
    """The folders of the shards that the records map, in order."""
    return sorted({str(Path(r["shard"]).parent) for r in records if r["shard"]})


def shard_attributes(path, folders, trajectories) -> dict:
    """The global attributes of a study file whose trajectories (the variables named) are in the shard files of
    ``folders``: a folder beside the file by its name, any other by its path; what the file needs, and what to do
    to move it."""
    here = Path(os.path.abspath(path)).parent
    names = [Path(f).name if Path(f).parent == here else str(f) for f in folders]
    file = Path(path).name
    where = " and ".join(f"the folder {n}" + (" beside this file" if n == Path(n).name else "") for n in names)
    return {"shard_folder": names[0] if len(names) == 1 else json.dumps(names),
            "depends_on": f"{where}: the trajectories ({', '.join(trajectories)}) are HDF5 virtual datasets that read "
                          f"the shard files there, and read as NaN where those are missing. Copy or move {file} with "
                          f"{'them' if len(names) > 1 else 'it'}, or make one self-contained file: linknet ensemble "
                          f"consolidate {file}. Open it with linknet_core.ensemble.open_study, which checks the "
                          "shards"}


def write_attributes(path, attrs: dict, remove=()) -> None:
    """Write netCDF global attributes into the study file at ``path`` (None values left out; dicts and lists as
    JSON), and remove those named in ``remove`` (with ``stored_in`` of every variable when the shard attributes
    go)."""
    import h5netcdf

    with h5netcdf.File(path, "a") as f:
        for key, value in attrs.items():
            if value is not None:
                f.attrs[key] = _attribute(value)
        for key in remove:
            if key in f.attrs:
                del f.attrs[key]
        if set(SHARD_ATTRIBUTES) & set(remove):
            for variable in f.variables.values():
                if _STORED_IN in variable.attrs:
                    del variable.attrs[_STORED_IN]


def _attribute(value):
    return json.dumps(value) if isinstance(value, (dict, list, tuple)) else value


def record_batch(variables: dict, batch: dict) -> None:
    """Write a batch's small part (quantities of interest, status, error, worker, run time) into the study file's
    variables (h5py datasets by name): its members first .. first + count - 1."""
    rows = slice(batch["first"], batch["first"] + batch["count"])
    for name, values in batch["outputs"].items():
        variables[name][rows] = values
    errors = batch["error"]
    variables["status"][rows] = np.array(["failed" if e else "ok" for e in errors], dtype=object)
    variables["error"][rows] = np.array(errors, dtype=object)
    variables["worker"][rows] = np.array([batch["worker"]] * batch["count"], dtype=object)
    variables["run_seconds"][rows] = batch["run_seconds"]


def shard_records(paths, covered: np.ndarray, variables: dict, trajectories) -> tuple[list[dict], list[tuple]]:
    """Records, as a StudyFile keeps them, of the members that the shards at ``paths`` hold and ``covered`` (a
    flag per member, updated) does not: a shard's members already covered are left out (a batch and the single
    members it was split into after its worker died hold the same members), so every member is taken once.
    ``variables``: the study file's datasets by name, the trajectories among them (a shard's must match their
    shape). Returns the records and the shards that cannot be taken, each with why (unreadable, not this study's
    shape)."""
    batches, refused = [], []
    for path in paths:
        try:
            batch = read_shard(path, trajectories=False)
        except Exception as exc:  # a file cut short (its disk filled), not an HDF5 file, ...
            refused.append((Path(path), _h5_reason(exc)))
            continue
        problem = _shard_problem(batch, covered.size, variables, trajectories)
        if problem:
            refused.append((Path(path), problem))
        else:
            batches.append(batch)
    records = []
    for batch in sorted(batches, key=lambda b: (b["first"], -b["count"])):
        first, count = batch["first"], batch["count"]
        free = np.flatnonzero(~covered[first:first + count])
        for run in np.split(free, np.flatnonzero(np.diff(free) != 1) + 1) if free.size else ():
            start, stop = int(run[0]), int(run[-1]) + 1
            records.append({"first": first + start, "count": stop - start, "offset": start, "shard_count": count,
                            "outputs": {name: np.asarray(values)[start:stop]
                                        for name, values in batch["outputs"].items() if name in variables},
                            "error": batch["error"][start:stop], "run_seconds": batch["run_seconds"][start:stop],
                            "worker": batch["worker"], "shard": batch["shard"], "written_by_client": False})
        covered[first:first + count] = True
    return records, refused


def _shard_problem(batch: dict, members: int, variables: dict, trajectories) -> str | None:
    """Why a shard cannot be part of the study whose variables are given (None if it can)."""
    first, count = batch["first"], batch["count"]
    if first < 0 or count < 1 or first + count > members:
        return f"it holds members {first}-{first + count - 1}, the study has {members}"
    for name in trajectories:
        shape = batch["shapes"].get(name)
        if shape is None:
            return f"it holds no {name}"
        if tuple(shape) != (count, *variables[name].shape[1:]):
            return f"its {name} has shape {tuple(shape)}, the study's members {tuple(variables[name].shape[1:])}"
    return None


def join_trajectories(h5, names, records, own_folder) -> None:
    """Each trajectory variable of the study file ``h5`` (an h5py File) becomes a virtual dataset: every record's
    members mapped to its shard (by a path relative to the file for the shards in ``own_folder``, the folder beside
    it, so the file and its folder can move together; by its absolute path elsewhere), NaN where no shard holds
    a member. The variable's attributes and dimension scales carry over."""
    import h5py

    entries = [(r["first"], r["count"], r.get("offset", 0), r.get("shard_count", r["count"]), Path(r["shard"]))
               for r in records if r["shard"]]
    if not names or not entries:
        return
    own = Path(own_folder) if own_folder else None
    for name in names:
        shape = h5[name].shape
        layout = h5py.VirtualLayout(shape=shape, dtype=h5[name].dtype)
        for first, count, offset, size, shard in entries:
            source = f"{own.name}/{shard.name}" if shard.parent == own else str(shard)
            piece = h5py.VirtualSource(source, name, shape=(size, *shape[1:]))
            layout[first:first + count] = piece if (offset, count) == (0, size) else piece[offset:offset + count]
        h5.create_virtual_dataset(_SWAP_NAME, layout, fillvalue=np.nan)
        swap_dataset(h5, name, _SWAP_NAME)


_SWAP_NAME = "linknet-replacement"  # where a dataset's replacement is made before it takes the dataset's place
COPY_BLOCK_BYTES = 64 << 20  # members copied per read and write when a trajectory is made part of the file


def materialize(h5, name: str, source) -> None:
    """Make ``name`` in the h5py File ``h5`` an ordinary dataset holding ``source``'s values (an h5py Dataset,
    virtual: read through its map), chunked a member to a chunk as the study lays its trajectories out, copied a
    block of members at a time; its attributes and dimension scales carry over."""
    shape = source.shape
    chunks = (1, *shape[1:]) if all(shape) else None  # HDF5 chunks no empty dimension
    copy = h5.create_dataset(_SWAP_NAME, shape=shape, dtype=source.dtype, chunks=chunks, fillvalue=np.nan)
    per_member = max(1, int(np.prod(shape[1:], dtype=np.int64)) * source.dtype.itemsize)
    step = max(1, COPY_BLOCK_BYTES // per_member)
    for first in range(0, shape[0], step):
        copy[first:first + step] = source[first:first + step]
    swap_dataset(h5, name, _SWAP_NAME)


def swap_dataset(h5, name: str, replacement: str) -> None:
    """Put the dataset ``replacement`` in the place of the dataset ``name`` (which is deleted), with its attributes
    and dimension scales (the netCDF dimensions xarray reads)."""
    old = h5[name]
    attrs = {key: value for key, value in old.attrs.items() if key != "DIMENSION_LIST"}
    scales = [old.dims[axis][0] for axis in range(old.ndim)]
    for axis, scale in enumerate(scales):
        old.dims[axis].detach_scale(scale)
    del h5[name]
    h5.move(replacement, name)
    new = h5[name]
    for key, value in attrs.items():
        new.attrs[key] = value
    for axis, scale in enumerate(scales):
        new.dims[axis].attach_scale(scale)


def remove_study(path) -> None:
    """Remove a study file and its shard folder (a study kept in memory, once loaded; a rescue that failed)."""
    try:
        os.unlink(path)
    except OSError:
        pass
    remove_folder(folder_for(path))
