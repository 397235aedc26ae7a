"""A study's shard files: each task's members, written by the worker that ran them, beside the study file.

A study with trajectories (X, U, T, Freact) keeps them in a folder beside its file (``study.nc`` ->
``study.shards/``), one HDF5 file per task (``members-FIRST-COUNT.STUDY.h5``): the worker that ran the task's members
writes them there itself, so the trajectories never pass through the client, whose one process would otherwise
receive and write every member's bytes (the ceiling of a large cluster: docs/ensemble.md, Scale). The study file
joins the shards (HDF5 virtual datasets, store.py), so it reads as one dataset.

A shard holds everything its task returned: the trajectories (member first, one dataset each), the quantities
of interest, each member's error, run time and CPU time, and the worker's address, so a shard read alone
(:func:`read_shard`) is the task's whole result. It is written under a temporary name and renamed when complete:
a file named ``members-*.h5`` is never half written, whatever happens to its worker, and a task run again
(after its worker died) renames an identical file over it.

The folder also keeps the study file as laid out when the study started (``layout.nc``), from which the study file
can be rebuilt with the shards present (``linknet ensemble recover``, study_files.py).

Workers write shards only where they see the folder the client made: the folder holds a marker naming the
study, which a worker looks for before its first task. A worker that does not see it (another machine without the
storage shared) or whose write fails (a full disk) returns its members' trajectories to the client as a task's
result, and the client writes the shard.
"""
from __future__ import annotations

import json
import os
import re
import shutil
import uuid
from pathlib import Path

import numpy as np

from linknet_core.output import WriteError, failure_reason

MARKER = "linknet-study"  # file in a shard folder naming its study (its id)
# the study file as laid out when the study started (every member "not run"), kept in its shard folder: what
# ``linknet ensemble recover`` rebuilds the study file from, with the shards, when the study file was lost
LAYOUT = "layout.nc"
SHARD_PREFIX = "members-"
SHARD_SUFFIX = ".h5"
TEMPORARY_SUFFIX = ".tmp"  # a shard being written; renamed to its name once complete
_SHARD_NAME = re.compile(rf"{SHARD_PREFIX}(\d+)-(\d+)\.(\w+){re.escape(SHARD_SUFFIX)}")


def folder_for(path) -> Path:
    """The shard folder of the study file at ``path``: study.nc -> study.shards beside it."""
    path = Path(path)
    return path.with_name(path.stem + ".shards")


def shard_name(study_id: str, first: int, count: int) -> str:
    """A task's shard: its members, and its study (an earlier study's task still running on a cluster, after the
    folder was made anew for another study at the same place, cannot write over this study's shard)."""
    return f"{SHARD_PREFIX}{first:09d}-{count}.{study_id[:12]}{SHARD_SUFFIX}"


def shard_study(path) -> str | None:
    """The first 12 characters of the study id in a shard's name (None: not a shard's name)."""
    match = _SHARD_NAME.fullmatch(Path(path).name)
    return match.group(3) if match else None


def prepare_folder(folder: Path, study_id: str) -> None:
    """Make the shard folder of a new study (an earlier study's at the same place is removed with its file, as
    the study file is overwritten) and put the marker in it. A folder of that name that is not a study's shard
    folder is refused, never removed."""
    folder = Path(folder)
    if folder.exists() or folder.is_symlink():
        if not folder.is_dir() or folder.is_symlink() or not (folder / MARKER).is_file():
            raise WriteError(folder, "it exists and is not a linknet study's shard folder (a study keeps its "
                                     "members' trajectories in a folder of that name beside its file): move it, "
                                     "or write the study elsewhere", detail="it was left as it is")
        shutil.rmtree(folder)
    try:
        folder.mkdir()
        (folder / MARKER).write_text(study_id)
    except OSError as exc:
        shutil.rmtree(folder, ignore_errors=True)
        raise WriteError(folder, failure_reason(exc)) from None


def remove_folder(folder: Path) -> None:
    """Remove a shard folder (a study kept in memory, once loaded); only a study's, with its marker."""
    folder = Path(folder)
    if (folder / MARKER).is_file():
        shutil.rmtree(folder, ignore_errors=True)


def sees_folder(folder: str | None, study_id: str) -> bool:
    """Whether this process sees the study's shard folder (the marker naming this study is in it)."""
    if not folder:
        return False
    try:
        return (Path(folder) / MARKER).read_text() == study_id
    except (OSError, UnicodeDecodeError):
        return False


def h5_reason(exc: BaseException) -> str:
    """What an h5py/HDF5 failure comes down to, in one line: 'No space left on device (errno 28)' where HDF5's
    text names the system error (its messages span lines and carry buffer addresses)."""
    text = str(exc)
    match = re.search(r"errno = (\d+), error message = '([^']*)'", text)
    return f"{match.group(2)} (errno {match.group(1)})" if match else failure_reason(exc)


def abandon(h5file) -> None:
    """Close an h5py file whose writes failed without writing anything more to it. HDF5 closing a file it cannot
    write (a full disk) fails, and its objects' deallocation later crashed the process (SIGSEGV at exit): its
    descriptor is pointed at /dev/null first, so the close succeeds and what reached the disk stays as it was."""
    if h5file is None:
        return
    silence(h5file)
    try:
        h5file.close()
    except Exception:
        pass


def silence(h5file) -> None:
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


def write_shard(folder, study_id: str, batch: dict, trajectories) -> Path:
    """Write one task's result (``members.run_batch``'s, its outputs whole) as a shard in ``folder``: a temporary
    file, renamed to its name when complete. Returns the shard's path; a failure (a full disk, the folder gone)
    raises WriteError naming the shard, and leaves no file behind.

    The trajectories are a dataset each (contiguous: one write of the whole array, and what the study file's
    virtual datasets map); everything else per member is one table (a dataset of a compound type) and the errors
    a dataset only where a member failed: each dataset costs ~0.07 ms of CPU time to create, the file ~0.15 ms."""
    import h5py

    path = Path(folder) / shard_name(study_id, batch["first"], batch["count"])
    temporary = path.with_name(f".{path.name}.{uuid.uuid4().hex[:12]}{TEMPORARY_SUFFIX}")
    kept = [name for name in batch["outputs"] if name in trajectories]
    columns = {name: np.asarray(values) for name, values in batch["outputs"].items() if name not in trajectories}
    columns.update((name, np.asarray(batch[name], dtype=float)) for name in ("run_seconds", "cpu_seconds")
                   if name in batch)
    table = np.empty(batch["count"], dtype=[(name, values.dtype, values.shape[1:])
                                            for name, values in columns.items()])
    for name, values in columns.items():
        table[name] = values
    contents = [(name, np.asarray(batch["outputs"][name]), None) for name in kept] + [("members", table, None)]
    if any(batch["error"]):
        contents.append(("error", np.array(batch["error"], dtype=object), h5py.string_dtype()))
    f = None
    # every dataset is created before any is written, and held until the file is closed or abandoned: an object
    # released while its file fails to write flushes into the failure, and HDF5 prints that release's error
    datasets = []
    try:
        f = h5py.File(temporary, "w")
        f.attrs["batch"] = json.dumps({"first": int(batch["first"]), "count": int(batch["count"]),
                                       "worker": batch["worker"], "trajectories": kept})
        datasets = [(f.create_dataset(name, shape=values.shape, dtype=dtype or values.dtype), values)
                    for name, values, dtype in contents]
        for dataset, values in datasets:
            dataset[...] = values
        f.flush()  # a full disk fails here, with the file still open, not inside close
        datasets = []
        f.close()
        f = None
        os.replace(temporary, path)
    except BaseException as exc:  # a Ctrl-C in the client's write too: no temporary file outlives its write
        if f is not None:
            silence(f)
        datasets = []
        abandon(f)
        try:
            os.unlink(temporary)
        except OSError:
            pass
        if not isinstance(exc, Exception):
            raise
        raise WriteError(path, h5_reason(exc)) from None
    return path


def read_shard(path, trajectories: bool = True) -> dict:
    """A shard read back: the task's result as ``members.run_batch`` returned it (outputs whole), with ``shard``
    its path and ``shapes`` the shape of each trajectory it holds; ``trajectories=False`` leaves those out of the
    outputs (the small part only)."""
    import h5py

    with h5py.File(path, "r") as f:
        facts = json.loads(f.attrs["batch"])
        table = f["members"][()]
        errors = [e.decode() if isinstance(e, bytes) else str(e) for e in f["error"][()]] if "error" in f else \
            [""] * facts["count"]
        shapes = {name: f[name].shape for name in facts["trajectories"]}
        outputs = {name: f[name][()] for name in facts["trajectories"]} if trajectories else {}
    columns = {name: table[name] for name in table.dtype.names}
    batch = {"first": facts["first"], "count": facts["count"], "worker": facts["worker"], "error": errors,
             "run_seconds": columns.pop("run_seconds"), "shard": str(path), "shapes": shapes}
    if "cpu_seconds" in columns:
        batch["cpu_seconds"] = columns.pop("cpu_seconds")
    batch["outputs"] = {**outputs, **columns}
    return batch


def shard_files(folder) -> list[Path]:
    """The complete shards in a folder (temporary files left by a task that did not finish are not shards)."""
    folder = Path(folder)
    if not folder.is_dir():
        return []
    return sorted(p for p in folder.iterdir() if shard_study(p) is not None)


def temporary_files(folder) -> list[Path]:
    """The files of a shard folder still being written, or left by a writer that was killed part way."""
    folder = Path(folder)
    return sorted(p for p in folder.iterdir() if p.name.endswith(TEMPORARY_SUFFIX)) if folder.is_dir() else []


def remove_unlisted(folder, keep) -> int:
    """Remove from a shard folder every file but the marker, the layout and the shards in ``keep`` (paths): shards
    of tasks whose results the study did not take (a batch that finished on a worker that then died, and ran again
    split into single members) and temporary files of tasks that never finished. Returns how many were removed."""
    folder = Path(folder)
    keep = {Path(p).name for p in keep}
    removed = 0
    for entry in folder.iterdir() if folder.is_dir() else ():
        if entry.name in (MARKER, LAYOUT) or entry.name in keep:
            continue
        try:
            entry.unlink()
            removed += 1
        except OSError:  # a folder someone put there, a file already gone
            pass
    return removed
