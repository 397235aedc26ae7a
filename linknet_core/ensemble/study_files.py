"""A study file read back, made self-contained, or rebuilt from its shards.

A study file with trajectories reads them from the shard files in the folder beside it (``study.nc`` ->
``study.shards/``, store.py): HDF5 fills what it cannot read of a virtual dataset with its fill value, so a file
copied without its folder would read NaN trajectories without a word. So:

* :func:`open_study` opens a study with xarray after checking that every shard its trajectories map exists and
  holds what the map expects, and refuses, naming the file, the missing shards and the fix, when one does not;
* :func:`consolidate` writes a self-contained copy (the trajectories copied in, no virtual dataset), which reads
  bit for bit as the joined file did;
* :func:`recover` rebuilds a study file from its shard folder alone (the study's process died, or its file was
  lost): the folder keeps the file as laid out when the study started (``layout.nc``), and every whole shard in
  it gives its members; the members no shard holds are ``missing``.

Each writes its file through a temporary file renamed when complete (``output.atomic_write``): a file of the
target's name is whole, or the one that was there before.
"""
from __future__ import annotations

import os
import shutil
from dataclasses import dataclass, field
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

from linknet_core.errors import LinknetError
from linknet_core.output import atomic_write
from linknet_core.ensemble.members import OUTPUTS
from linknet_core.ensemble.shards import (LAYOUT, MARKER, folder_for, h5_reason, shard_files, shard_study,
                                          temporary_files)
from linknet_core.ensemble.store import (SHARD_ATTRIBUTES, join_trajectories, materialize, record_batch,
                                         shard_attributes, shard_records, write_attributes)

LISTED_SHARDS = 5  # an error names this many missing shards, then counts the others
# HDF5 and h5py's failures while a study file is written (an OSError is one already)
_WRITE_ERRORS = (RuntimeError, ValueError, KeyError)


class MissingShardsError(LinknetError):
    """A study file whose trajectories are in shard files that are missing or unreadable. ``path``: the study
    file; ``shards``: (shard path, members it holds, what is wrong) for each; ``variables``: the trajectories
    they hold (X, U, ...)."""

    def __init__(self, path, shards, variables):
        self.path, self.shards, self.variables = str(path), shards, variables
        super().__init__(_missing_text(Path(path), shards, variables))


def open_study(path):
    """Open a study file (``ln.ensemble(..., out=)``, ``linknet ensemble --out``) as an xarray Dataset, lazily, as
    ``xr.open_dataset(path, engine="h5netcdf")`` does, after checking it: a study whose trajectories are in shard
    files that are missing or unreadable (the file copied without the folder beside it) raises MissingShardsError,
    and a file whose study never closed it (its process died, or it still runs) raises LinknetError naming
    ``linknet ensemble recover``, where xarray alone would read NaN trajectories."""
    import xarray as xr

    check_study(path)
    return xr.open_dataset(path, engine="h5netcdf")


def check_study(path) -> None:
    """Raise unless the study file at ``path`` reads whole: it was closed by its study, and every shard its
    trajectories map exists and holds a dataset of the shape mapped."""
    import h5py

    path = Path(path)
    if not path.is_file():
        raise LinknetError(f"{path}: no such study file")
    try:
        with h5py.File(path, "r") as f:
            if f.attrs.get("title") == "linknet ensemble" and "complete" not in f.attrs:
                raise LinknetError(_unclosed_text(path))
            sources = _virtual_sources(f)
    except OSError as exc:
        raise LinknetError(f"cannot read the study file {path}: {h5_reason(exc)}") from None
    problems, variables = [], set()
    for shard, pieces in sources.items():
        problem = _shard_problem(shard, pieces)
        if problem:
            members = sorted({m for _, first, count, _ in pieces for m in range(first, first + count)})
            problems.append((shard, members, problem))
            variables.update(name for name, _, _, _ in pieces)
    if problems:
        raise MissingShardsError(path, problems, [name for name in OUTPUTS if name in variables])


def _virtual_sources(f) -> dict:
    """{shard path: [(dataset, first member, count, shape of one member)]} of every virtual dataset of an h5py
    File: a relative shard path is taken from the file's folder, as HDF5 takes it."""
    import h5py

    here = Path(os.path.abspath(f.filename)).parent
    sources: dict = {}
    for name, item in f.items():
        if not (isinstance(item, h5py.Dataset) and item.is_virtual):
            continue
        for mapping in item.virtual_sources():
            if mapping.file_name == ".":  # a dataset of this file itself
                continue
            start, end = mapping.vspace.get_select_bounds()
            shard = Path(mapping.file_name)
            shard = shard if shard.is_absolute() else here / shard
            sources.setdefault(shard, []).append((mapping.dset_name, start[0], end[0] - start[0] + 1,
                                                  item.shape[1:]))
    return sources


def _shard_problem(shard: Path, pieces) -> str | None:
    """What keeps ``shard`` from giving what the study's map reads from it (None: nothing)."""
    import h5py

    if not shard.exists():
        return "missing"
    try:
        with h5py.File(shard, "r") as f:
            for name, _, count, member in pieces:
                if name not in f:
                    return f"unreadable: it holds no {name}"
                shape = f[name].shape
                if shape[1:] != tuple(member) or shape[0] < count:
                    return (f"unreadable: its {name} has shape {shape}, the study maps {count} member(s) of shape "
                            f"{tuple(member)} from it")
    except OSError as exc:  # not an HDF5 file, cut short, no permission to read
        return f"unreadable: {h5_reason(exc)}"
    return None


def _missing_text(path: Path, problems, variables) -> str:
    from linknet_core.ensemble.report import _ranges

    members = sorted({m for _, held, _ in problems for m in held})
    folders = sorted({shard.parent for shard, _, _ in problems})
    gone = [folder for folder in folders if not folder.exists()]
    listed = "; ".join(f"{shard} ({problem})" for shard, _, problem in problems[:LISTED_SHARDS])
    more = f"; and {len(problems) - LISTED_SHARDS} more" if len(problems) > LISTED_SHARDS else ""
    where = (f"the folder {', '.join(map(str, gone))} that holds them is not there" if gone else
             f"{len(problems)} shard file(s) are missing or unreadable: {listed}{more}")
    folder = folder_for(path).name
    return (f"{path}: its trajectories ({', '.join(variables)}) of {len(members)} member(s) ({_ranges(members)}) are "
            f"in shard files, and {where}: they would read as NaN. A study file and its shard folder belong "
            f"together: copy {folder} beside {path.name} too, or, where the two are whole, make one self-contained "
            f"file: linknet ensemble consolidate {path.name}")


def _unclosed_text(path: Path) -> str:
    folder = folder_for(path)
    return (f"{path} was never closed by its study: the study is still running, or its process stopped before the "
            f"end (killed, a crash), and its trajectories are not joined (they would read as NaN). Once the study "
            f"has ended, rebuild the file from its shards with: linknet ensemble recover {folder}")


def consolidate(path, out=None, remove_shards: bool = False) -> Path:
    """Write the study file at ``path`` as one self-contained file, ``out`` (default: ``path`` itself, replaced):
    each trajectory variable's members copied from its shards into the file (chunked a member to a chunk, as the
    study lays them out), everything else as it is; it reads bit for bit as the joined file. The shards are checked
    first (a missing one is refused, as :func:`open_study` refuses it). ``remove_shards`` removes the study's shard
    folder once the file replacing ``path`` holds everything (only when consolidating in place: a copy elsewhere
    leaves ``path`` needing it). Returns the path written; a write that fails raises WriteError naming it."""
    import h5py

    path, target = Path(path), Path(out) if out is not None else Path(path)
    _check_suffix(target)
    same = target.resolve() == path.resolve()
    if remove_shards and not same:
        raise LinknetError(f"remove_shards (--remove-shards) removes {folder_for(path).name} after {path.name} itself "
                           f"is made self-contained; {path} still needs it when the self-contained copy is {target}")
    check_study(path)
    with h5py.File(path, "r") as f:
        virtual = [name for name, item in f.items() if isinstance(item, h5py.Dataset) and item.is_virtual]
    if not virtual and same:
        return target

    def write(temporary):
        shutil.copyfile(path, temporary)
        with h5py.File(path, "r") as source, h5py.File(temporary, "r+") as h5:
            for name in virtual:
                materialize(h5, name, source[name])
        write_attributes(temporary, {"consolidated_from": str(path.resolve())}, remove=SHARD_ATTRIBUTES)

    atomic_write(target, write, errors=_WRITE_ERRORS)
    if remove_shards:
        from linknet_core.ensemble.shards import remove_folder

        remove_folder(folder_for(path))
    return target


@dataclass
class Recovery:
    """What :func:`recover` rebuilt: the file, from which folder, and what it could not take."""

    path: Path
    folder: Path
    members: int
    ok: int
    failed: int
    missing: list[int]
    self_contained: bool
    refused: list[tuple[Path, str]] = field(default_factory=list)  # shards present that could not be taken
    other_studies: list[Path] = field(default_factory=list)  # shards of another study, ignored
    temporary_removed: int = 0  # files of writes that never finished, removed from the folder

    def text(self) -> str:
        """The recovery in a few lines, for a person."""
        from linknet_core.ensemble.report import _ranges

        lines = [f"recovered {self.path} from {self.folder}: {self.ok + self.failed} of {self.members} members "
                 f"({self.ok} ok, {self.failed} failed)"
                 + (", self-contained" if self.self_contained else f", its trajectories read from {self.folder.name} "
                    "beside it")]
        if self.missing:
            lines.append(f"  {len(self.missing)} member(s) missing, in no shard of the folder (status 'missing', "
                         f"values NaN): {_ranges(self.missing)}")
        for shard, why in self.refused:
            lines.append(f"  shard not taken: {shard.name}: {why}")
        if self.other_studies:
            lines.append(f"  {len(self.other_studies)} shard(s) of another study ignored")
        if self.temporary_removed:
            lines.append(f"  {self.temporary_removed} temporary file(s) of writes that never finished removed")
        return "\n".join(lines)


def recover(folder, out=None) -> Recovery:
    """Rebuild a study file from its shard folder: the study as laid out when it started (the folder's
    ``layout.nc``), each member held by a whole shard of the study in the folder taken from it (status, error,
    quantities of interest, trajectories), and every other member ``missing`` (status and error say so, its values
    NaN). Temporary files of writes that never finished are removed. ``out`` (default: the study file the folder
    belongs to, ``study.shards`` -> ``study.nc``) beside the folder reads its trajectories from the shards, as a
    finished study does; anywhere else it is made self-contained. A complete study at ``out`` is refused, never
    replaced (nothing to recover; :func:`consolidate` makes it self-contained). ``complete`` is 0 in the file, and
    ``recovered_from`` names the folder."""
    import h5py

    folder = Path(folder)
    if not (folder / MARKER).is_file():
        raise LinknetError(f"{folder} is not a linknet study's shard folder (it has no {MARKER} file): give the "
                           "folder beside the study file, study.shards for study.nc")
    layout = folder / LAYOUT
    if not layout.is_file():
        raise LinknetError(f"{folder} holds no {LAYOUT}, the study file as laid out when the study started, which "
                           "a study keeps with its shards: a folder written by an earlier linknet cannot be "
                           "rebuilt into a study (each shard still reads alone: linknet_core.ensemble.shards."
                           "read_shard)")
    if out is None:
        if not folder.name.endswith(".shards"):
            raise LinknetError(f"{folder}: give the study file to write (-o STUDY.nc): the folder's name does not "
                               "say its study's (study.shards for study.nc)")
        out = folder.with_name(folder.name[:-len(".shards")] + ".nc")
    target = Path(out)
    _check_suffix(target)
    if _complete(target):
        raise LinknetError(f"{target} is a complete study (its attribute complete is 1), left as it is: nothing to "
                           f"recover. To make it self-contained: linknet ensemble consolidate {target}; to rebuild "
                           f"another file from {folder}: -o OTHER.nc")
    study_id = (folder / MARKER).read_text().strip()
    removed = 0
    for temporary in temporary_files(folder):
        try:
            temporary.unlink()
            removed += 1
        except OSError:
            pass
    present = shard_files(folder)
    mine = [p for p in present if shard_study(p) == study_id[:12]]
    beside = folder_for(os.path.abspath(target)) == Path(os.path.abspath(folder))
    found: dict = {}

    def write(temporary):
        shutil.copyfile(layout, temporary)
        with h5py.File(temporary, "r+") as h5:
            variables = {name: h5[name] for name in ("max_tension", "max_tension_link", "min_tension", "tip_final",
                                                     "error_estimate", "error_goal", "status", "error", "worker",
                                                     "run_seconds") if name in h5}
            trajectories = [name for name in OUTPUTS if name in h5]
            covered = np.zeros(h5["member"].shape[0], dtype=bool)
            records, refused = shard_records(mine, covered, {**variables, **{n: h5[n] for n in trajectories}},
                                             trajectories)
            for record in records:
                record_batch(variables, record)
            missing = np.flatnonzero(~covered)
            if missing.size:
                variables["status"][missing] = np.array(["missing"] * missing.size, dtype=object)
                variables["error"][missing] = np.array(
                    [f"no shard in {folder.name} holds this member: it had not finished when the study stopped, "
                     "or its task failed as a whole"] * missing.size, dtype=object)
            join_trajectories(h5, trajectories, records, folder_for(os.path.abspath(target)))
            if not beside:
                for name in trajectories:
                    if h5[name].is_virtual:
                        materialize(h5, name, h5[name])
            status = h5["status"].asstr()[()]
            found.update(records=records, refused=refused, missing=missing, members=covered.size,
                         trajectories=trajectories, ok=int((status == "ok").sum()),
                         failed=int((status == "failed").sum()))
        linked = beside and any(r["shard"] for r in found["records"])
        attrs = {"complete": 0, "recovered_from": str(folder.resolve()), "members_missing": int(found["missing"].size),
                 "recovered": datetime.now(timezone.utc).isoformat(timespec="seconds")}
        shard_facts = shard_attributes(target, [folder.resolve()], found["trajectories"]) if linked else {}
        write_attributes(temporary, {**attrs, **shard_facts},
                         remove=() if linked else SHARD_ATTRIBUTES)

    atomic_write(target, write, errors=_WRITE_ERRORS)
    return Recovery(path=target, folder=folder, members=found["members"], ok=found["ok"], failed=found["failed"],
                    missing=found["missing"].tolist(), self_contained=not beside, refused=found["refused"],
                    other_studies=[p for p in present if p not in mine], temporary_removed=removed)


def _complete(path: Path) -> bool:
    """Whether ``path`` is a study file its study closed complete."""
    import h5py

    if not path.is_file():
        return False
    try:
        with h5py.File(path, "r") as f:
            return f.attrs.get("title") == "linknet ensemble" and np.ravel(f.attrs.get("complete", 0))[0] == 1
    except (OSError, ValueError, TypeError):  # cut short, not HDF5: a file to replace
        return False


def _check_suffix(path: Path) -> None:
    if path.suffix.lower() != ".nc":
        raise LinknetError(f"{path}: a study is written as a netCDF file, whose name ends in .nc")
