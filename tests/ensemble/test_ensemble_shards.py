"""The members' trajectories in shard files: written by the workers beside the study file, joined by it (HDF5
virtual datasets) so that it reads as one dataset; written by the client where a worker cannot; never half a
shard, never a member in two; a write that fails does not lose a member."""
import os
import shutil

import h5py
import numpy as np
import pytest
import xarray as xr

import linknet_core as ln
from linknet_core.ensemble import members, shards, summary
from linknet_core.output import WriteError

from .ensemble_support import MODELS, assert_member_equals, client_batch, four_member_study, serial_run

T_END, N_OUT = 0.3, 16
MASSES = [0.5, 1.0, 1.5, 2.0, 2.5, 3.0]


def _mapped_members(path, name: str) -> list[tuple[int, int, str]]:
    """(first, count, shard file) of each piece of the joined variable ``name``, in member order."""
    pieces = []
    with h5py.File(path, "r") as f:
        assert f[name].is_virtual
        for mapping in f[name].virtual_sources():
            start, end = mapping.vspace.get_select_bounds()
            pieces.append((start[0], end[0] - start[0] + 1, mapping.file_name))
    return sorted(pieces)


def test_workers_write_shards_the_file_joins_them_and_moves_with_its_folder(local_client, tmp_path):
    scene = ln.load_scene(MODELS / "chain_10.json")
    out = tmp_path / "study.nc"
    ds = ln.ensemble(scene, vary={"M[11]": MASSES}, t_end=T_END, n_out=N_OUT, client=local_client, out=out,
                     outputs=["X", "U", "T", "Freact"])
    assert ds.attrs["members_written_by_workers"] == len(MASSES) and ds.attrs["members_written_by_client"] == 0
    folder = tmp_path / "study.shards"
    files = sorted(p.name for p in folder.iterdir())
    # the marker, the study's layout and one shard per task, nothing else (no temporary file)
    assert files[:2] == [shards.LAYOUT, shards.MARKER] and len(files) == 2 + int(ds.attrs["tasks"])
    assert all(name.startswith("members-") and name.endswith(".h5") for name in files[2:])
    for name in ("X", "U", "T", "Freact"):  # every member in exactly one shard, mapped by a relative path
        pieces = _mapped_members(out, name)
        assert [first for first, _, _ in pieces] == list(np.cumsum([0] + [c for _, c, _ in pieces[:-1]]))
        assert sum(count for _, count, _ in pieces) == len(MASSES)
        assert all(source.startswith("study.shards/") for _, _, source in pieces)
    ds.close()
    # the file and its folder moved together elsewhere read the same members, each its serial run bit for bit
    moved = tmp_path / "elsewhere"
    moved.mkdir()
    shutil.move(str(out), moved / "study.nc")
    shutil.move(str(folder), moved / "study.shards")
    with xr.open_dataset(moved / "study.nc", engine="h5netcdf") as again:
        for m, mass in enumerate(MASSES):
            assert_member_equals(again, m, serial_run(scene, {"M[11]": mass}, T_END, N_OUT))
        assert np.isfinite(again["Freact"].values).all()


def test_workers_that_do_not_see_the_folder_send_the_trajectories_to_the_client(threads_client, tmp_path,
                                                                                monkeypatch):
    """A worker on a machine without the client's storage (here: told it does not see the folder) returns its
    members' trajectories and the client writes their shards: the same study, bit for bit."""
    monkeypatch.setattr(members, "sees_folder", lambda folder, study_id: False)
    scene = ln.load_scene(MODELS / "chain_10.json")
    ds = ln.ensemble(scene, vary={"M[11]": MASSES[:3]}, t_end=T_END, n_out=N_OUT, client=threads_client,
                     out=tmp_path / "s.nc")
    assert ds.attrs["members_written_by_client"] == 3 and ds.attrs["members_written_by_workers"] == 0
    assert ds.attrs["client_shard_reason"] == "its worker does not see the folder"
    assert "trajectories: the client wrote those of 3 member(s), not their workers" in summary(ds)
    for m, mass in enumerate(MASSES[:3]):
        assert_member_equals(ds, m, serial_run(scene, {"M[11]": mass}, T_END, N_OUT))


def test_a_worker_whose_shard_write_fails_sends_its_members_to_the_client(threads_client, tmp_path, monkeypatch):
    def refuse(folder, study_id, batch, trajectories):
        raise WriteError(os.path.join(folder, "x.h5"), "No space left on device (errno 28)")

    monkeypatch.setattr(members, "write_shard", refuse)  # the workers' write; the client's is store's
    scene = ln.load_scene(MODELS / "chain_10.json")
    ds = ln.ensemble(scene, vary={"M[11]": MASSES[:2]}, t_end=T_END, n_out=N_OUT, client=threads_client,
                     out=tmp_path / "s.nc")
    assert ds.attrs["members_written_by_client"] == 2
    assert "No space left on device (errno 28)" in ds.attrs["client_shard_reason"]
    for m, mass in enumerate(MASSES[:2]):
        assert_member_equals(ds, m, serial_run(scene, {"M[11]": mass}, T_END, N_OUT))


def test_a_folder_of_the_shards_name_that_is_not_a_studys_is_refused_and_kept(local_client, tmp_path):
    mine = tmp_path / "study.shards"
    mine.mkdir()
    (mine / "notes.txt").write_text("mine")
    with pytest.raises(ln.LinknetError, match=r"study\.shards: it exists and is not a linknet study's shard "
                                              r"folder.*\(it was left as it is\)"):
        ln.ensemble(MODELS / "chain_10.json", vary={"M[11]": [1.0]}, t_end=0.1, out=tmp_path / "study.nc",
                    client=local_client)
    assert (mine / "notes.txt").read_text() == "mine" and not (tmp_path / "study.nc").exists()


def test_a_failed_write_goes_on_in_the_rescue_file_with_every_member(tmp_path, monkeypatch):
    """The second batch's shard cannot be written (a full disk): that write says so once, the study goes on in a
    rescue file in the temporary folder, and that file holds all four members: the first from the shard beside
    the study file, the second and third from its own shards, each member's numbers as they were given."""
    from linknet_core.ensemble import store

    monkeypatch.setenv("TMPDIR", str(tmp_path / "tmp"))
    monkeypatch.setattr("tempfile.tempdir", None)
    (tmp_path / "tmp").mkdir()
    sink = store.StudyFile(tmp_path / "s.nc", *four_member_study())
    batches = [client_batch(0, 1, 1), client_batch(1, 2, 2), client_batch(3, 1, 3)]
    sink.write(batches[0])
    real_write = store.write_shard
    calls = []

    def full_once(folder, study_id, batch, trajectories):
        calls.append(folder)
        if len(calls) == 1:
            raise WriteError(os.path.join(folder, "members-x.h5"), "No space left on device (errno 28)")
        return real_write(folder, study_id, batch, trajectories)

    monkeypatch.setattr(store, "write_shard", full_once)
    with pytest.raises(WriteError, match=r"s\.nc: No space left on device \(errno 28\)"):
        sink.write(batches[1])
    assert sink.continues()
    sink.write(batches[2])
    with pytest.raises(WriteError, match=r"the study went on in the temporary folder: its 4 finished member\(s\) "
                                         r"are in .*linknet-rescued-s-") as caught:
        sink.close({})
    rescued = str(caught.value).split(" are in ")[1].split(",")[0]
    with xr.open_dataset(rescued, engine="h5netcdf") as ds:
        assert list(ds["status"].values) == ["ok"] * 4 and ds.attrs["complete"] == 0
        for batch in batches:
            rows = slice(batch["first"], batch["first"] + batch["count"])
            for name in ("X", "T", "max_tension"):
                np.testing.assert_array_equal(ds[name].values[rows], batch["outputs"][name])


def test_a_shard_is_whole_or_absent(tmp_path, monkeypatch):
    """A shard write that fails part way (the disk fills inside HDF5) leaves no file, neither the shard nor its
    temporary; one that succeeds reads back as the batch it was."""
    folder = tmp_path / "s.shards"
    shards.prepare_folder(folder, "study")
    batch = client_batch(5, 2, 7)
    path = shards.write_shard(folder, "study", batch, members.OUTPUTS)
    back = shards.read_shard(path)
    assert (back["first"], back["count"], back["error"]) == (5, 2, ["", ""])
    for name, values in batch["outputs"].items():
        np.testing.assert_array_equal(back["outputs"][name], values)

    def full(self, *args, **kwargs):
        raise RuntimeError("file write failed: errno = 28, error message = 'No space left on device'")

    monkeypatch.setattr(h5py.Group, "create_dataset", full)
    with pytest.raises(WriteError, match=r"members-000000009-1\.study\.h5: No space left on device \(errno 28\)"):
        shards.write_shard(folder, "study", client_batch(9, 1, 8), members.OUTPUTS)
    assert sorted(p.name for p in folder.iterdir()) == sorted([shards.MARKER, path.name])


CLIENT_KILLED_AFTER = 4  # results


def test_a_client_killed_mid_study_leaves_whole_readable_shards(process_cluster, tmp_path):
    """The process running the study dies (SIGKILL) after a few results: the workers' shards already in the folder
    are whole, each holding its task's members exactly as their serial runs (nothing computed is lost with the
    client), and no half-written file bears a shard's name."""
    import signal
    import subprocess
    import sys

    out = tmp_path / "s.nc"
    masses = np.linspace(0.5, 2.0, 12)
    script = (
        "import os, signal, numpy as np, linknet_core as ln\n"
        "def die(progress):\n"
        f"    if progress.done >= {CLIENT_KILLED_AFTER}:\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n"
        f"ln.ensemble({str(MODELS / 'chain_10.json')!r}, vary={{'M[11]': np.linspace(0.5, 2.0, 12)}}, t_end={T_END},"
        f" n_out={N_OUT}, dt=1e-5, client={process_cluster!r}, members_per_task=1, out={str(out)!r},"
        " progress=die)\n")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert run.returncode == -signal.SIGKILL, run.stderr
    found = shards.shard_files(tmp_path / "s.shards")
    assert len(found) >= CLIENT_KILLED_AFTER
    scene = ln.load_scene(MODELS / "chain_10.json")
    for path in found:
        batch = shards.read_shard(path)
        assert batch["count"] == 1 and batch["error"] == [""]
        reference = serial_run(scene, {"M[11]": masses[batch["first"]]}, T_END, N_OUT, dt=1e-5)
        for name in ("X", "U", "T"):
            np.testing.assert_array_equal(batch["outputs"][name][0], getattr(reference, name))
        assert batch["outputs"]["error_estimate"][0] == reference.max_error_estimate
