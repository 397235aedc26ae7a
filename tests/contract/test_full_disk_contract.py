"""A full disk: every output is written whole or not at all (linknet_core/output.py,
atomic_write), a failed write is one line naming the file with a non-zero exit and no traceback, the target holds
no file or the previous one intact, and what was computed is kept (simulate's arrays, an ensemble's members).

A full disk is simulated two ways: a file size limit (RLIMIT_FSIZE lowered in the child, SIGXFSZ ignored, so a
write past it fails with EFBIG), which needs no privileges; and a small tmpfs (ENOSPC, as a real full disk),
where mounting one is allowed (skipped otherwise, with the reason).
"""
from __future__ import annotations

import importlib
import os
import resource
import shutil
import signal
import subprocess
import sys

import numpy as np
import pytest

from contract_support import MODELS, ROOT

DOUBLE_PENDULUM = str(MODELS / "double_pendulum.json")
NPZ_BYTES = 23838  # double_pendulum, --t-end 0.1, 201 samples, with T_peak and T_peak_time (measured); the limits below are under it


def _limit(size: int):
    def set_limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (size, size))
    return set_limit


def run(args, tmp_path, limit: int | None = None, prelude: str = ""):
    """Run `python -c prelude + main(args)` of linknet (args[0] 'build_fmu.py' runs that script instead), with
    its temporary folder in tmp_path/tmp and, if given, a file size limit."""
    tmp = tmp_path / "tmp"
    tmp.mkdir(exist_ok=True)
    env = dict(os.environ, TMPDIR=str(tmp), PYTHONPATH=str(ROOT))
    if args[0] == "build_fmu.py":
        command = [sys.executable, str(ROOT / "build_fmu.py"), *args[1:]]
    else:
        command = [sys.executable, "-c", prelude + "import sys\nfrom linknet_core.cli import main\n"
                   "sys.exit(main(sys.argv[1:]))", *args]
    return subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600,
                          preexec_fn=_limit(limit) if limit else None)


def assert_refused(proc, target, previous: bytes | None = None) -> str:
    """Non-zero exit (not a signal), one line on stderr naming the file, no traceback, and at the target nothing
    or the previous file intact, with no temporary left beside it. Returns the line."""
    assert proc.returncode > 0, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1, proc.stderr
    assert f"cannot write {target}" in lines[0], lines[0]
    if previous is None:
        assert not target.exists()
        assert "nothing was left there" in lines[0] or "damaged" in lines[0] or "readable" in lines[0]
    else:
        assert target.read_bytes() == previous
        assert "the previous file there is kept" in lines[0]
    assert [p.name for p in target.parent.iterdir() if p.name.startswith(f".{target.name}.")] == []
    return lines[0]


@pytest.fixture
def small_disk(tmp_path):
    """A factory of small tmpfs folders (a real full disk: ENOSPC); skips where mounting needs privileges."""
    mounted = []

    def make(size: str):
        where = tmp_path / f"disk{len(mounted)}"
        where.mkdir()
        mount = shutil.which("mount")
        done = subprocess.run([mount, "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)],
                              capture_output=True, text=True) if mount else None
        if done is None or done.returncode:
            pytest.skip("a full disk is simulated by a small tmpfs, and mounting one needs privileges "
                        f"(CAP_SYS_ADMIN): {done.stderr.strip() if done else 'no mount command'}")
        mounted.append(where)
        return where

    yield make
    for where in mounted:
        subprocess.run(["umount", str(where)], capture_output=True)


@pytest.fixture(scope="module")
def result_npz(tmp_path_factory):
    path = tmp_path_factory.mktemp("full_disk") / "run.npz"
    subprocess.run([sys.executable, "-m", "linknet_core.cli", "simulate", DOUBLE_PENDULUM, "--t-end", "0.1",
                    "--out", str(path), "--no-progress"], cwd=ROOT, check=True, capture_output=True)
    return path


# ---- the one helper ---------------------------------------------------------------------------------------

def test_atomic_write_leaves_nothing_or_the_previous_file(tmp_path):
    from linknet_core.output import WriteError, atomic_write

    target = tmp_path / "a" / "b.txt"

    def half(tmp):
        with open(tmp, "w") as f:
            f.write("half")
        raise OSError(28, "No space left on device")

    with pytest.raises(WriteError, match=r"cannot write .*b.txt: No space left on device \(errno 28\) "
                                         r"\(nothing was left there\)"):
        atomic_write(target, half)
    assert list(target.parent.iterdir()) == []
    atomic_write(target, lambda tmp: open(tmp, "w").write("whole"))
    assert target.read_text() == "whole"
    assert oct(target.stat().st_mode & 0o777) == oct(0o666 & ~_umask())
    with pytest.raises(WriteError, match="the previous file there is kept"):
        atomic_write(target, half)
    assert target.read_text() == "whole"
    assert sorted(p.name for p in target.parent.iterdir()) == ["b.txt"]
    with pytest.raises(KeyboardInterrupt):  # any other exception passes through, the temporary removed
        atomic_write(target, lambda tmp: (_ for _ in ()).throw(KeyboardInterrupt()))
    assert sorted(p.name for p in target.parent.iterdir()) == ["b.txt"]


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


# ---- simulate, animate, view: a file size limit -------------------------------------------------------------

def test_simulate_out_past_the_limit(tmp_path):
    target = tmp_path / "x.npz"
    proc = run(["simulate", DOUBLE_PENDULUM, "--t-end", "0.1", "--out", str(target), "--no-progress"], tmp_path,
               limit=NPZ_BYTES // 2)
    line = assert_refused(proc, target)
    assert "File too large (errno 27)" in line
    # the rescue in the temporary folder is under the same limit: said, not claimed
    assert "keeping them in the temporary folder failed too" in line
    assert "wrote" not in proc.stdout


def test_simulate_out_keeps_the_previous_file(tmp_path):
    target = tmp_path / "x.npz"
    target.write_bytes(b"previous")
    proc = run(["simulate", DOUBLE_PENDULUM, "--t-end", "0.1", "--out", str(target), "--no-progress"], tmp_path,
               limit=NPZ_BYTES // 2)
    assert_refused(proc, target, previous=b"previous")


@pytest.mark.parametrize("option, name", [("--plot", "p.png"), ("--animate", "a.gif")])
def test_simulate_plot_and_animate_past_the_limit(tmp_path, option, name):
    target = tmp_path / name
    proc = run(["simulate", DOUBLE_PENDULUM, "--t-end", "0.1", option, str(target), "--no-progress"], tmp_path,
               limit=8000)
    assert_refused(proc, target)


def test_simulate_writes_what_fits_and_fails_the_rest(tmp_path):
    """--out fits, --plot does not: the npz is written and said, the plot's line follows, exit 1."""
    out, plot = tmp_path / "x.npz", tmp_path / "p.png"
    proc = run(["simulate", DOUBLE_PENDULUM, "--t-end", "0.1", "--out", str(out), "--plot", str(plot),
                "--no-progress"], tmp_path, limit=NPZ_BYTES + 1000)
    assert_refused(proc, plot)
    assert f"wrote {out}" in proc.stdout
    assert np.load(out)["X"].shape == (201, 3, 3)


@pytest.mark.parametrize("command, name", [("animate", "a.gif"), ("animate", "a.png"), ("view", "a.html")])
def test_pictures_past_the_limit(tmp_path, result_npz, command, name):
    target = tmp_path / name
    proc = run([command, str(result_npz), "-o", str(target)], tmp_path, limit=8000)
    assert_refused(proc, target)
    target.write_bytes(b"previous")
    proc = run([command, str(result_npz), "-o", str(target)], tmp_path, limit=8000)
    assert_refused(proc, target, previous=b"previous")


# ---- a real full disk (tmpfs): simulate's rescue, the FMU builds ------------------------------------------------

def test_simulate_out_on_a_full_disk_keeps_the_arrays(tmp_path, small_disk):
    target = small_disk("8k") / "x.npz"
    proc = run(["simulate", DOUBLE_PENDULUM, "--t-end", "0.1", "--out", str(target), "--no-progress"], tmp_path)
    line = assert_refused(proc, target)
    assert "No space left on device (errno 28)" in line
    rescued = line.split("the results are in ")[1].split(" instead")[0]
    assert rescued.startswith(str(tmp_path / "tmp"))
    assert np.load(rescued)["X"].shape == (201, 3, 3)


@pytest.mark.parametrize("native", [False, True], ids=["pythonfmu", "native"])
def test_build_fmu_on_a_full_disk(tmp_path, small_disk, native):
    disk = small_disk("200k")  # both FMUs of the double pendulum are larger (measured: 1.0 MB, 316 KiB)
    target = disk / "dp.fmu"
    args = ["build_fmu.py", DOUBLE_PENDULUM, "-o", str(target)] + (["--native"] if native else [])
    proc = run(args, tmp_path)
    assert "build_fmu: cannot write" in assert_refused(proc, target)
    target.write_bytes(b"previous")
    assert_refused(run(args, tmp_path), target, previous=b"previous")


# ---- the ensemble -------------------------------------------------------------------------------------------

ENSEMBLE = ["ensemble", DOUBLE_PENDULUM, "--vary", "M[2]=0.5:2:20", "--t-end", "0.2", "--workers", "1",
            "--no-progress"]
STUDY_BYTES = 645_000  # the 20 members' X, U, T and quantities of interest as doubles (the up-front bound)


def test_ensemble_refused_up_front_past_the_limit(tmp_path):
    target = tmp_path / "s.nc"
    proc = run(ENSEMBLE + ["--out", str(target)], tmp_path, limit=STUDY_BYTES // 2)
    line = assert_refused(proc, target)
    assert "the study's 20 members need at least 0.645 MB, the file size limit (ulimit -f) is 0.323 MB" in line


def test_ensemble_refused_up_front_on_a_full_disk(tmp_path, small_disk):
    target = small_disk("100k") / "s.nc"
    line = assert_refused(run(ENSEMBLE + ["--out", str(target)], tmp_path), target)
    assert "the free space on its disk is" in line


def test_ensemble_disk_full_while_running_keeps_every_member(tmp_path, small_disk):
    """The disk fills while the members stream in (every batch flushed, as a long study would be): no segfault,
    exit 1, one line naming the study file and the rescue file, and every member computed readable from the two
    (the failed flush may damage the study file's metadata: what it still holds is salvaged into the rescue)."""
    import xarray as xr

    target = small_disk("660k") / "s.nc"  # above the up-front bound, below the file's 706 KB (measured)
    prelude = ("import importlib\nimportlib.import_module('linknet_core.ensemble.store').FLUSH_SECONDS = 0.0\n")
    proc = run(ENSEMBLE + ["--members-per-task", "1", "--out", str(target)], tmp_path, prelude=prelude)
    assert proc.returncode == 1, (proc.returncode, proc.stderr)
    assert "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and f"cannot write {target}: No space left on device (errno 28)" in lines[0], lines
    rescued = lines[0].split(" are in ")[1].split(",")[0]
    status = np.array(["not run"] * 20, dtype=object)
    finite = np.zeros(20, dtype=bool)
    sources = [rescued] + (["study"] if "readable in it" in lines[0] else [])
    for source in sources:
        with xr.open_dataset(target if source == "study" else source, engine="h5netcdf") as ds:
            run_here = ds["status"].values != "not run"
            status[run_here] = ds["status"].values[run_here]
            finite |= np.isfinite(ds["X"].values).all(axis=(1, 2, 3)) & run_here
            if source == rescued:
                assert ds.attrs["complete"] == 0 and ds.attrs["rescued_from"] == str(target)
    assert list(status) == ["ok"] * 20
    assert finite.all()


def test_study_file_write_failure_is_a_write_error(tmp_path, monkeypatch):
    """In process: a failing HDF5 write (h5py's RuntimeError) stops the file, and close writes what it held to the
    rescue file and raises one WriteError naming both."""
    import h5py

    from linknet_core.ensemble.members import StudySpec
    from linknet_core.ensemble.parameters import make_plan
    from linknet_core.output import WriteError
    from linknet_core.scene import load_scene

    store = importlib.import_module("linknet_core.ensemble.store")
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    scene = load_scene(DOUBLE_PENDULUM)
    plan = make_plan(scene, {"M[2]": [1.0, 2.0]}, None)
    times = np.linspace(0, 0.1, 3)
    spec = StudySpec(study_id="t", scene=scene.to_dict(), parameters=plan.parameters, times=times, method="rattle",
                     dt=1e-3, rtol=None, atol=None, project_initial=None, outputs=("T",), tip=2, fmu=None)
    sink = store.StudyFile(tmp_path / "s.nc", spec, plan, scene)
    batch = {"first": 0, "count": 2, "outputs": {"T": np.ones((2, 3, 2)), "max_tension": np.ones(2)},
             "error": ["", ""], "run_seconds": [0.1, 0.1], "worker": "w"}

    def refuse(*args, **kwargs):
        raise RuntimeError("Can't decrement id ref count (file write failed: errno = 28, error message = "
                           "'No space left on device')")

    monkeypatch.setattr(h5py.File, "flush", refuse)
    monkeypatch.setattr(store, "FLUSH_SECONDS", 0.0)
    with pytest.raises(WriteError, match=r"No space left on device \(errno 28\)"):
        sink.write(batch)  # written, then flushed at once
    monkeypatch.undo()
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.setattr("tempfile.tempdir", None)
    with pytest.raises(WriteError, match=r"cannot write .*s\.nc: No space left on device \(errno 28\) \(.*2 "
                                         r"finished member\(s\) are in .*linknet-rescued-s-") as caught:
        sink.close({})
    import xarray as xr

    rescued = str(caught.value).split(" are in ")[1].split(",")[0]
    with xr.open_dataset(rescued, engine="h5netcdf") as ds:
        assert list(ds["status"].values) == ["ok", "ok"]
        assert float(ds["T"].sum()) == 12.0


def test_ensemble_plot_on_a_full_disk(tmp_path, small_disk):
    """The study fits, its --plot does not: the study is written and said, the plot is one error line, exit 1.
    (report.py's own matplotlib warning on a one-parameter plot may precede it on stderr: not an error.)"""
    study, plot = tmp_path / "s.nc", small_disk("16k") / "s.png"  # the plot is ~40 KB (measured)
    proc = run(ENSEMBLE + ["--outputs", "none", "--out", str(study), "--plot", str(plot)], tmp_path)
    assert proc.returncode == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    errors = [line for line in proc.stderr.splitlines() if "error:" in line]
    assert errors == [f"linknet ensemble: error: cannot write {plot}: No space left on device (errno 28) (nothing "
                      "was left there)"], proc.stderr
    assert f"wrote {study}" in proc.stdout and not plot.exists()
    assert list(plot.parent.iterdir()) == []


def test_an_out_path_that_cannot_be_written_is_refused_before_the_run(tmp_path):
    # as root, access() passes /proc; the pre-check tries the write itself, so the run is not made for nothing
    proc = run(["simulate", DOUBLE_PENDULUM, "--t-end", "0.1", "--out", "/proc/x.npz"], tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.strip() == ("linknet simulate: error: argument --out: '/proc/x.npz' cannot be created in "
                                   "/proc: No such file or directory (see linknet simulate --help)"), proc.stderr
    assert "t_end" not in proc.stdout  # refused before the run
    assert not list((tmp_path / "tmp").iterdir())  # no rescue file: nothing was computed
