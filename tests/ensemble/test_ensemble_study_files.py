"""A study file and its shard folder: a file without its shards is refused by name (never read as NaN), one
self-contained file reads bit for bit as the joined one, a study file is rebuilt from its shards after its process
died, and a study stopped part way (Ctrl-C, an exception) leaves no temporary file and says where its members are."""
import json
import os
import shutil
import signal
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
import xarray as xr

import linknet_core as ln
from linknet_core.ensemble import (MissingShardsError, consolidate, members, open_study, recover, shards, store,
                                   summary)
from linknet_core.output import WriteError

from .ensemble_support import MODELS, ROOT, assert_member_equals, client_batch, four_member_study, serial_run

T_END, N_OUT = 0.3, 16
MASSES = [0.5, 1.0, 1.5, 2.0, 2.5]
TRAJECTORIES = ("X", "U", "T", "Freact")


def linknet(*args, timeout=180):
    return subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", *map(str, args)],
                          capture_output=True, text=True, cwd=str(ROOT), timeout=timeout)


@pytest.fixture(scope="module")
def finished_study(tmp_path_factory, local_client):
    """A finished study of five members, one per task (five shards), with every trajectory; tests copy it."""
    folder = tmp_path_factory.mktemp("finished")
    ds = ln.ensemble(MODELS / "chain_10.json", vary={"M[11]": MASSES}, t_end=T_END, n_out=N_OUT, client=local_client,
                     out=folder / "study.nc", members_per_task=1, outputs=TRAJECTORIES)
    assert list(ds["status"].values) == ["ok"] * len(MASSES)
    ds.close()
    return folder / "study.nc"


def _copy_study(study: Path, folder: Path) -> Path:
    """The study file and its shard folder copied into ``folder``, as a user moves them."""
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(study, folder / study.name)
    shutil.copytree(shards.folder_for(study), shards.folder_for(folder / study.name))
    return folder / study.name


def _member_shards(path: Path) -> list[Path]:
    """The study's shards, member by member (one member per task: names sort by first member)."""
    return shards.shard_files(shards.folder_for(path))


def assert_same_bits(a, b, members=None) -> None:
    """Every variable of the datasets a and b (or only ``members`` of those along member) holds the same values,
    bit for bit (NaNs included)."""
    assert set(a.data_vars) == set(b.data_vars) and set(a.coords) == set(b.coords)
    for name in [*a.data_vars, *a.coords]:
        x, y = a[name].values, b[name].values
        if members is not None and a[name].dims[:1] == ("member",):
            x, y = x[members], y[members]
        assert x.dtype == y.dtype and x.shape == y.shape, name
        if x.dtype.kind in "fiub":
            assert x.tobytes() == y.tobytes(), name
        else:
            assert (x == y).all(), name


def _check_serial(ds, members_ok) -> None:
    scene = ln.load_scene(MODELS / "chain_10.json")
    for m in members_ok:
        assert_member_equals(ds, m, serial_run(scene, {"M[11]": MASSES[m]}, T_END, N_OUT))


# ---- a study file without its shards -------------------------------------------------------------------------

def test_a_study_copied_without_its_shard_folder_is_refused_naming_the_folder_and_the_fix(finished_study, tmp_path):
    alone = tmp_path / "study.nc"
    shutil.copy(finished_study, alone)
    with xr.open_dataset(alone, engine="h5netcdf") as raw:
        # what the refusal prevents: read directly, every trajectory is NaN and nothing says why
        assert np.isnan(raw["X"].values).all() and (raw["status"].values == "ok").all()
        # the file says what it needs: global attributes (ncdump -h, xarray's attrs) and each trajectory's
        assert raw.attrs["shard_folder"] == "study.shards"
        assert raw.attrs["depends_on"].startswith("the folder study.shards beside this file: the trajectories")
        assert "linknet ensemble consolidate study.nc" in raw.attrs["depends_on"]
        for name in TRAJECTORIES:
            assert "study.shards beside this file" in raw[name].attrs["stored_in"]
    with pytest.raises(MissingShardsError) as caught:
        open_study(alone)
    text = str(caught.value)
    assert text.startswith(f"{alone}: its trajectories (X, U, T, Freact) of 5 member(s) (0-4) are in shard files")
    assert f"the folder {tmp_path / 'study.shards'} that holds them is not there: they would read as NaN" in text
    assert "copy study.shards beside study.nc too" in text and "linknet ensemble consolidate study.nc" in text
    assert caught.value.path == str(alone) and len(caught.value.shards) == len(MASSES)


def test_a_missing_or_damaged_shard_is_named_with_its_members(finished_study, tmp_path):
    path = _copy_study(finished_study, tmp_path)
    one = _member_shards(path)
    one[1].unlink()
    one[3].write_bytes(one[3].read_bytes()[:300])  # cut short, as a copy that stopped part way
    with pytest.raises(MissingShardsError) as caught:
        open_study(path)
    found = {shard.name: (held, why) for shard, held, why in caught.value.shards}
    assert set(found) == {one[1].name, one[3].name}
    assert found[one[1].name] == ([1], "missing")
    assert found[one[3].name][0] == [3] and found[one[3].name][1].startswith("unreadable: ")
    assert "of 2 member(s) (1, 3)" in str(caught.value) and f"{one[1]} (missing)" in str(caught.value)


def test_the_study_that_ensemble_returns_is_checked_the_same_way(finished_study, tmp_path):
    """open_study is what ln.ensemble opens its file with: whole, it reads every member as its serial run."""
    path = _copy_study(finished_study, tmp_path)
    with open_study(path) as ds:
        _check_serial(ds, range(len(MASSES)))


# ---- consolidate ---------------------------------------------------------------------------------------------

def test_consolidate_writes_a_self_contained_file_that_reads_bit_for_bit_as_the_joined_one(finished_study, tmp_path):
    path = _copy_study(finished_study, tmp_path / "a")
    out = tmp_path / "b" / "whole.nc"
    out.parent.mkdir()
    run = linknet("consolidate", path, "-o", out)
    assert run.returncode == 0 and run.stderr == "", run.stderr
    assert run.stdout.strip() == f"wrote {out}: self-contained, its trajectories in the file"
    shutil.rmtree(shards.folder_for(path))  # the copy needs no folder: the joined file it came from does
    with h5py.File(out, "r") as f:
        assert not any(f[name].is_virtual for name in TRAJECTORIES)
        assert f["X"].chunks == (1, N_OUT, 11, 3)  # a member to a chunk, as the study lays it out
    with open_study(finished_study) as joined, open_study(out) as whole:
        assert_same_bits(joined, whole)
        _check_serial(whole, range(len(MASSES)))
        assert "depends_on" not in whole.attrs and "shard_folder" not in whole.attrs
        assert "stored_in" not in whole["X"].attrs and whole["X"].attrs["units"] == "m"
        assert whole.attrs["consolidated_from"] == str(path.resolve())
    assert sorted(p.name for p in out.parent.iterdir()) == ["whole.nc"]  # no temporary file left


def test_consolidate_in_place_then_the_folder_may_go(finished_study, tmp_path):
    path = _copy_study(finished_study, tmp_path)
    assert consolidate(path, remove_shards=True) == path
    assert not shards.folder_for(path).exists()
    moved = tmp_path / "elsewhere" / "moved.nc"
    moved.parent.mkdir()
    path.rename(moved)
    with open_study(finished_study) as joined, open_study(moved) as whole:
        assert_same_bits(joined, whole)


def test_consolidate_refuses_a_study_whose_shards_are_missing_and_writes_nothing(finished_study, tmp_path):
    path = _copy_study(finished_study, tmp_path)
    gone = _member_shards(path)[2]
    gone.unlink()
    run = linknet("consolidate", path, "-o", tmp_path / "out.nc")
    assert run.returncode == 2 and "Traceback" not in run.stderr
    lines = run.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"linknet ensemble: error: {path}: its trajectories")
    assert f"{gone} (missing)" in lines[0]
    assert not (tmp_path / "out.nc").exists()
    with pytest.raises(ln.LinknetError, match="removes study.shards after study.nc itself"):
        consolidate(path, tmp_path / "out.nc", remove_shards=True)  # the original would still need the folder


def test_a_consolidation_that_cannot_be_written_names_the_file_and_leaves_nothing(finished_study, tmp_path,
                                                                                  monkeypatch):
    path = _copy_study(finished_study, tmp_path / "a")
    out = tmp_path / "b" / "whole.nc"
    out.parent.mkdir()

    def full(self, *args, **kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(h5py.Group, "create_dataset", full)
    with pytest.raises(WriteError, match=rf"cannot write {out}: No space left on device \(errno 28\) "
                                         r"\(nothing was left there\)"):
        consolidate(path, out)
    assert list(out.parent.iterdir()) == []


# ---- recover -------------------------------------------------------------------------------------------------

CLIENT_KILLED_AFTER = 3  # results


def test_recover_rebuilds_the_study_after_its_process_was_killed(process_cluster, process_client, tmp_path):
    """The process running a study dies (SIGKILL) after a few results: its study file was never closed, and
    open_study says so and names recover; ``linknet ensemble recover`` rebuilds the file from the shard folder:
    every member a shard holds is there, equal to its serial run, the others are 'missing' (NaN), and the command
    says which."""
    out = tmp_path / "s.nc"
    script = (
        "import os, signal, numpy as np, linknet_core as ln\n"
        "def die(progress):\n"
        f"    if progress.done >= {CLIENT_KILLED_AFTER}:\n"
        "        os.kill(os.getpid(), signal.SIGKILL)\n"
        f"ln.ensemble({str(MODELS / 'chain_10.json')!r}, vary={{'M[11]': {MASSES + [3.0, 3.5, 4.0]!r}}}, "
        f"t_end={T_END}, n_out={N_OUT}, dt=1e-5, client={process_cluster!r}, members_per_task=1, out={str(out)!r},"
        " progress=die)\n")
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert run.returncode == -signal.SIGKILL, run.stderr
    with pytest.raises(ln.LinknetError, match=rf"linknet ensemble recover {tmp_path / 's.shards'}"):
        open_study(out)
    _wait_until_idle(process_client)  # the cluster finishes the tasks it was running for the dead client
    held = sorted(shards.read_shard(p)["first"] for p in shards.shard_files(tmp_path / "s.shards"))
    assert len(held) >= CLIENT_KILLED_AFTER
    run = linknet("recover", tmp_path / "s.shards")
    assert run.returncode == 0, run.stderr
    lines = run.stdout.splitlines()
    assert lines[0] == (f"recovered {out} from {tmp_path / 's.shards'}: {len(held)} of 8 members ({len(held)} ok, "
                        "0 failed), its trajectories read from s.shards beside it")
    missing = [m for m in range(8) if m not in held]
    if missing:
        assert lines[1].startswith(f"  {len(missing)} member(s) missing, in no shard of the folder")
    scene = ln.load_scene(MODELS / "chain_10.json")
    masses = MASSES + [3.0, 3.5, 4.0]
    with open_study(out) as ds:
        assert ds.attrs["complete"] == 0 and ds.attrs["members_missing"] == len(missing)
        assert ds.attrs["recovered_from"] == str((tmp_path / "s.shards").resolve())
        for m in held:
            assert ds["status"].values[m] == "ok"
            assert_member_equals(ds, m, serial_run(scene, {"M[11]": masses[m]}, T_END, N_OUT, dt=1e-5))
        for m in missing:
            assert ds["status"].values[m] == "missing" and np.isnan(ds["X"].values[m]).all()
            assert "no shard in s.shards holds this member" in ds["error"].values[m]
        np.testing.assert_array_equal(ds["M[11]"].values, masses)  # the layout kept the parameters


def _wait_until_idle(client) -> None:
    """Until no worker thread runs a task (a task whose client died runs to its end, and writes its shard)."""
    import time

    deadline = time.monotonic() + 120  # a bound on the wait, not a figure the test checks
    while any(client.run(lambda dask_worker: len(dask_worker.active_threads)).values()) and \
            time.monotonic() < deadline:
        time.sleep(0.1)


def test_recover_never_replaces_a_complete_study_and_elsewhere_writes_it_self_contained(finished_study, tmp_path):
    path = _copy_study(finished_study, tmp_path / "a")
    before = path.read_bytes()
    with pytest.raises(ln.LinknetError, match=r"study\.nc is a complete study .* left as it is: nothing to recover"):
        recover(shards.folder_for(path))
    assert path.read_bytes() == before
    _member_shards(path)[2].unlink()
    open(shards.folder_for(path) / ".members-000000004-1.x.h5.0123.tmp", "w").write("a write cut short")
    recovery = recover(shards.folder_for(path), tmp_path / "b" / "r.nc")
    assert recovery.missing == [2] and recovery.self_contained and recovery.temporary_removed == 1
    assert (recovery.ok, recovery.failed, recovery.members) == (4, 0, 5)
    assert shards.temporary_files(shards.folder_for(path)) == []
    with h5py.File(recovery.path, "r") as f:
        assert not any(f[name].is_virtual for name in TRAJECTORIES) and "depends_on" not in f.attrs
    shutil.rmtree(shards.folder_for(path))  # self-contained: it reads without the folder
    with open_study(recovery.path) as ds, open_study(finished_study) as whole:
        kept = [0, 1, 3, 4]
        for name in ("X", "U", "T", "Freact", "max_tension", "max_tension_link", "min_tension", "tip_final",
                     "error_estimate", "error_goal", "run_seconds"):
            assert ds[name].values[kept].tobytes() == whole[name].values[kept].tobytes(), name
        assert list(ds["status"].values) == ["ok", "ok", "missing", "ok", "ok"]
        assert np.isnan(ds["X"].values[2]).all() and np.isnan(ds["max_tension"].values[2])
        assert "1 missing (rebuilt from" in summary(ds)


def test_recover_takes_each_member_once_from_overlapping_shards(tmp_path):
    """A batch and the single members it ran again as (its worker died) hold the same members; a shard that
    overlaps those taken gives only its other members. Each member's numbers are the ones its shard holds."""
    spec, plan, scene = four_member_study()
    sink = store.StudyFile(tmp_path / "s.nc", spec, plan, scene)
    given = client_batch(0, 2, 1)
    sink.write(given)  # the client writes its shard
    sink.close({})
    overlapping = client_batch(1, 3, 2)  # members 1-3: member 1 is taken already
    shards.write_shard(tmp_path / "s.shards", spec.study_id, overlapping, members.OUTPUTS)
    (tmp_path / "s.nc").unlink()
    recovery = recover(tmp_path / "s.shards")
    assert recovery.missing == [] and recovery.ok == 4
    with open_study(tmp_path / "s.nc") as ds:
        for name in ("X", "T", "max_tension"):
            np.testing.assert_array_equal(ds[name].values[:2], given["outputs"][name])
            np.testing.assert_array_equal(ds[name].values[2:], overlapping["outputs"][name][1:])


def test_recover_says_what_it_needs(tmp_path):
    with pytest.raises(ln.LinknetError, match="is not a linknet study's shard folder"):
        recover(tmp_path)
    run = linknet("recover", tmp_path / "nothing.shards")
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and "is not a linknet study's shard folder" in \
        run.stderr and "Traceback" not in run.stderr


# ---- a study stopped part way --------------------------------------------------------------------------------

def _folder_holds_only_what_the_file_maps(path: Path) -> list[str]:
    """The shard folder holds the marker, the layout and the shards the study file maps, nothing else (no
    temporary file); returns the mapped shards' names."""
    with h5py.File(path, "r") as f:
        mapped = sorted({Path(m.file_name).name for m in f["X"].virtual_sources()}) if f["X"].is_virtual else []
    names = sorted(p.name for p in shards.folder_for(path).iterdir())
    assert names == sorted([shards.MARKER, shards.LAYOUT, *mapped]), names
    return mapped


INTERRUPTED_STUDY = """
import json, sys
import linknet_core as ln

def interrupt(progress):
    if progress.done >= 2:
        raise KeyboardInterrupt

if __name__ == "__main__":
    try:
        ln.ensemble(MODEL, vary={"M[11]": MASSES}, t_end=T_END, n_out=N_OUT, dt=DT, workers=2, members_per_task=1,
                    progress=interrupt, out=OUT)
    except KeyboardInterrupt as stop:
        print(json.dumps(stop.__notes__))
"""
SLOW_T_END, SLOW_DT = 1.0, 1e-5  # 1e5 steps, ~0.15 s a member: the workers are inside members when the study stops


def test_ctrl_c_on_its_own_cluster_keeps_the_finished_members_and_nothing_written_after(tmp_path):
    """Ctrl-C (a KeyboardInterrupt from the progress callback) while the two worker processes of the study's own
    cluster run members: those members write no shard once the study has stopped (their workers went on to the
    end of the member, and wrote it into the folder after the study had closed its file), and nothing else is
    left but what the file maps; the study file is closed (complete = 0) with the members finished, each its
    serial run, and the exception says where they are and how to make one file of them."""
    out = tmp_path / "study.nc"
    script = tmp_path / "interrupted.py"
    script.write_text(INTERRUPTED_STUDY.replace("MODEL", repr(str(MODELS / "chain_10.json"))).replace(
        "MASSES", repr(MASSES)).replace("T_END", repr(SLOW_T_END)).replace("N_OUT", repr(N_OUT)).replace(
        "DT", repr(SLOW_DT)).replace("OUT", repr(str(out))))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, cwd=str(ROOT), timeout=300,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert run.returncode == 0 and run.stdout, run.stderr
    note = " ".join(json.loads(run.stdout))
    assert f"finished before the study stopped are in {out} (complete = 0)" in note
    assert f"their trajectories in the shard files of {tmp_path / 'study.shards'} beside it" in note
    assert f"linknet ensemble consolidate {out}" in note
    mapped = _folder_holds_only_what_the_file_maps(out)
    scene = ln.load_scene(MODELS / "chain_10.json")
    with open_study(out) as ds:
        ok = np.flatnonzero(ds["status"].values == "ok")
        assert ds.attrs["complete"] == 0 and ok.size >= 2 and len(mapped) == ok.size, list(ds["error"].values)
        assert set(ds["status"].values[ds["status"].values != "ok"]) <= {"not run"}
        for m in ok:
            assert_member_equals(ds, m, serial_run(scene, {"M[11]": MASSES[m]}, SLOW_T_END, N_OUT, dt=SLOW_DT))
        assert f"the {ok.size} member(s) finished" in note


def test_an_exception_in_a_study_leaves_the_finished_members_readable(threads_client, tmp_path):
    out = tmp_path / "study.nc"

    def fail(progress):
        raise RuntimeError("the progress display broke")

    with pytest.raises(RuntimeError, match="the progress display broke") as caught:
        ln.ensemble(MODELS / "chain_10.json", vary={"M[11]": MASSES}, t_end=T_END, n_out=N_OUT,
                    client=threads_client, members_per_task=1, progress=fail, out=out)
    assert f"linknet ensemble consolidate {out}" in " ".join(caught.value.__notes__)
    assert shards.temporary_files(tmp_path / "study.shards") == []
    with open_study(out) as ds:
        ok = np.flatnonzero(ds["status"].values == "ok")
        assert ds.attrs["complete"] == 0 and ok.size >= 1
        _check_serial(ds, ok)


def test_ctrl_c_inside_the_clients_shard_write_leaves_no_temporary_file(threads_client, tmp_path, monkeypatch):
    """Where the client writes the shards (the workers do not see the folder), a Ctrl-C that lands inside a
    shard's write: that shard's temporary file is removed, the shards written before it stay and are mapped."""
    monkeypatch.setattr(members, "sees_folder", lambda folder, study_id: False)
    real_flush = h5py.File.flush
    shard_writes = []

    def interrupted_second_shard(self):
        if self.filename.endswith(shards.TEMPORARY_SUFFIX):
            shard_writes.append(self.filename)
            if len(shard_writes) == 2:
                assert Path(self.filename).exists()  # the temporary file is there, part written
                raise KeyboardInterrupt
        return real_flush(self)

    monkeypatch.setattr(h5py.File, "flush", interrupted_second_shard)
    out = tmp_path / "study.nc"
    with pytest.raises(KeyboardInterrupt):
        ln.ensemble(MODELS / "chain_10.json", vary={"M[11]": MASSES}, t_end=T_END, n_out=N_OUT,
                    client=threads_client, members_per_task=1, out=out)
    assert not Path(shard_writes[1]).exists()
    mapped = _folder_holds_only_what_the_file_maps(out)
    with open_study(out) as ds:
        assert list(ds["status"].values).count("ok") == len(mapped) == 1
        _check_serial(ds, [0])


def test_an_interrupted_study_takes_the_shards_that_finished_but_were_not_received(threads_client, tmp_path):
    """Ctrl-C while a worker's task has written its shard but its result has not reached the study: the study
    takes that shard's members (they finished) instead of deleting it."""
    import time

    out = tmp_path / "study.nc"
    folder = tmp_path / "study.shards"

    def interrupt_once_the_next_shard_is_written(progress):
        deadline = time.monotonic() + 120  # a bound on the wait, not on the test: the worker is writing it now
        while len(shards.shard_files(folder)) < 2 and time.monotonic() < deadline:
            time.sleep(0.02)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        ln.ensemble(MODELS / "chain_10.json", vary={"M[11]": MASSES}, t_end=T_END, n_out=N_OUT,
                    client=threads_client, members_per_task=1, progress=interrupt_once_the_next_shard_is_written,
                    out=out)
    with open_study(out) as ds:
        ok = np.flatnonzero(ds["status"].values == "ok")
        assert ok.size >= 2  # one member received, at least one taken from its shard
        _check_serial(ds, ok)


def test_a_shard_write_interrupted_part_way_leaves_no_file(tmp_path, monkeypatch):
    folder = tmp_path / "s.shards"
    shards.prepare_folder(folder, "study")

    def interrupted(self):
        raise KeyboardInterrupt

    monkeypatch.setattr(h5py.File, "flush", interrupted)
    with pytest.raises(KeyboardInterrupt):
        shards.write_shard(folder, "study", client_batch(0, 2, 1), members.OUTPUTS)
    assert sorted(p.name for p in folder.iterdir()) == [shards.MARKER]


def test_the_command_says_where_an_interrupted_studys_members_are(tmp_path, monkeypatch, capsys):
    """linknet ensemble answers a Ctrl-C with one line: what the library's note says (where the members are and
    how to make one file of them), or, when the study did not get to close its file, how to rebuild it."""
    from linknet_core import cli

    ensemble_package = sys.modules["linknet_core.ensemble"]  # ln.ensemble, the function, hides the package's name

    def interrupted(*args, **kwargs):
        stop = KeyboardInterrupt()
        stop.__notes__ = ["the 3 member(s) finished before the study stopped are in x.nc (complete = 0)"]
        raise stop

    monkeypatch.setattr(ensemble_package, "ensemble", interrupted)
    args = ["ensemble", str(MODELS / "chain_10.json"), "--vary", "M[11]=1,2", "--t-end", "0.1", "--no-progress",
            "--out", str(tmp_path / "x.nc")]
    assert cli.main(args) == 130
    assert capsys.readouterr().err == ("linknet ensemble: interrupted; the 3 member(s) finished before the study "
                                       "stopped are in x.nc (complete = 0)\n")
    monkeypatch.setattr(ensemble_package, "ensemble", lambda *a, **k: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert cli.main(args) == 130
    assert capsys.readouterr().err == (f"linknet ensemble: interrupted; should {tmp_path / 'x.nc'} not open, rebuild "
                                       f"it from the shards beside it: linknet ensemble recover "
                                       f"{tmp_path / 'x.shards'}\n")


def test_the_command_lists_the_study_file_tools():
    run = subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", "--help"], capture_output=True,
                         text=True, cwd=str(ROOT), timeout=60)
    text = " ".join(run.stdout.split())  # argparse wraps the lines
    assert run.returncode == 0 and "linknet ensemble consolidate STUDY.nc [-o OUT.nc] [--remove-shards]" in text
    assert "linknet ensemble recover STUDY.shards [-o STUDY.nc]" in text
    run = subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", "recover", "--help"],
                         capture_output=True, text=True, cwd=str(ROOT), timeout=60)
    assert run.returncode == 0 and "SHARDS_DIR" in run.stdout and "-o OUT, --out OUT" in run.stdout
