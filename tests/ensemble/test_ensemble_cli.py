"""`linknet ensemble`: the issue's command on a real cluster, the summary table, the plot; errors are one
clear line, never a traceback."""
import subprocess
import sys

import numpy as np
import pytest
import xarray as xr

from .ensemble_support import MODELS, ROOT


def linknet(*args, timeout=180):
    return subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", *map(str, args)],
                          capture_output=True, text=True, cwd=str(ROOT), timeout=timeout)


def test_grid_study_with_summary_table_progress_and_plot(process_cluster, tmp_path):
    out, png = tmp_path / "study.nc", tmp_path / "study.png"
    run = linknet(MODELS / "chain_10.json", "--vary", "M[3]=0.5:2:3", "--vary", "R[1..10]=0.09:0.11:2",
                  "--t-end", "0.3", "--n-out", "11", "--out", out, "--scheduler", process_cluster, "--plot", png)
    assert run.returncode == 0, run.stderr
    assert "6/6 members, 0 failed, 0 retried" in run.stderr  # the progress bar's last state
    lines = run.stdout.splitlines()
    header = next(line for line in lines if line.lstrip().startswith("member"))
    assert header.split()[:3] == ["member", "M[3]", "R[1..10]"] and "max T [N]" in header
    assert sum(line.rstrip().endswith(" ok") for line in lines) == 6
    ds = xr.open_dataset(out, engine="h5netcdf")
    np.testing.assert_allclose(ds["M[3]"].values, [0.5, 0.5, 1.25, 1.25, 2.0, 2.0])
    np.testing.assert_allclose(ds["R[1..10]"].values, [0.09, 0.11] * 3)
    assert (ds["status"].values == "ok").all() and png.stat().st_size > 10_000


def test_monte_carlo_from_the_command_line(process_cluster, tmp_path):
    run = linknet(MODELS / "double_pendulum.json", "--sample", "U0[3,3]=normal:0:0.5", "--n-samples", "40",
                  "--seed", "3", "--t-end", "0.2", "--n-out", "5", "--outputs", "none", "--no-progress",
                  "--out", tmp_path / "mc.nc", "--scheduler", process_cluster)
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""  # --no-progress
    assert "min / mean / max over the members with each value" in run.stdout  # 40 members: per value
    ds = xr.open_dataset(tmp_path / "mc.nc", engine="h5netcdf")
    assert "X" not in ds and ds.sizes["member"] == 40
    np.testing.assert_allclose(ds["U0[3,3]"].values, np.random.default_rng(3).normal(0, 0.5, 40))


@pytest.mark.parametrize("args,words", [
    (["--vary", "Q[1]=1,2"], "unknown parameter 'Q[1]'"),
    (["--vary", "M[1]=1,2"], "anchored"),
    (["--vary", "M[3]=1:2"], "write start:stop:count"),
    # a second of waiting says the same as the default ten (the default's own wait: test_scheduler_address_contract)
    (["--vary", "M[3]=1,2", "--scheduler", "tcp://127.0.0.1:9", "--connect-timeout", "1"],
     "cannot reach the Dask scheduler"),
    (["--vary", "M[3]=1,2", "--out", "/nonexistent-folder/x.nc"], "does not exist"),
    ([], "nothing to vary"),
])
def test_errors_are_one_line(args, words):
    run = linknet(MODELS / "chain_10.json", "--t-end", "0.1", *args)
    assert run.returncode == 2
    assert "Traceback" not in run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith("linknet ensemble: error: ") and words in lines[0], run.stderr


def test_missing_scene_is_one_line(tmp_path):
    run = linknet(tmp_path / "missing.json", "--t-end", "1", "--vary", "M[2]=1")
    assert run.returncode == 2 and "missing.json' is not a file" in run.stderr and "Traceback" not in run.stderr


def test_a_successful_run_on_its_own_local_cluster_says_nothing_on_stderr(tmp_path):
    """The default engine, a LocalCluster the command starts and closes: nothing from Dask on stderr, neither
    while it runs nor at its shutdown (no heartbeat or CommClosedError traceback, no log line), in each of two
    runs (shutdown messages depend on timing)."""
    for n in range(2):
        out = tmp_path / f"study{n}.nc"
        run = linknet(MODELS / "chain_10.json", "--vary", "M[11]=0.5:2:16", "--t-end", "0.3", "--n-out", "11",
                      "--workers", "2", "--no-progress", "--out", out)
        assert run.returncode == 0, run.stderr
        assert run.stderr == "", run.stderr
        assert (xr.open_dataset(out, engine="h5netcdf")["status"].values == "ok").all()
