"""Every member of a study equals the same run done serially in this process, on a LocalCluster (the default
engine and one given as a client) and on a scheduler with two workers started as separate processes."""
import json

import numpy as np
import pytest
import xarray as xr

import linknet_core as ln

from .ensemble_support import MODELS, assert_member_equals, serial_run

T_END, N_OUT = 0.5, 26


def _check_against_serial(ds, scene, **solver):
    names = json.loads(ds.attrs["varied"])
    for m in range(ds.sizes["member"]):
        setting = {name: ds[name].values[m].item() for name in names}
        assert ds["status"].values[m] == "ok", ds["error"].values[m]
        assert_member_equals(ds, m, serial_run(scene, setting, T_END, N_OUT, **solver))


def test_default_engine_local_cluster_streams_a_grid_to_netcdf(tmp_path):
    """client=None starts a LocalCluster (2 workers here); the file on disk is the dataset, labelled by the
    varied parameters, and each member equals its serial run."""
    out = tmp_path / "study.nc"
    ds = ln.ensemble(MODELS / "chain_10.json", vary={"M[11]": [0.5, 2.0], "g[3]": [-9.81, -1.62]},
                     t_end=T_END, n_out=N_OUT, out=out, workers=2)
    assert "local cluster" in ds.attrs["engine"] and ds.attrs["complete"] == 1
    assert dict(ds.sizes) == {"member": 4, "time": N_OUT, "mass": 11, "axis": 3, "link": 10, "anchor": 1}
    assert ds["X"].dims == ("member", "time", "mass", "axis") and ds["T"].dims == ("member", "time", "link")
    np.testing.assert_array_equal(ds["M[11]"].values, [0.5, 0.5, 2.0, 2.0])
    np.testing.assert_array_equal(ds["g[3]"].values, [-9.81, -1.62, -9.81, -1.62])
    on_disk = xr.open_dataset(out, engine="h5netcdf")
    assert set(on_disk.coords) >= {"M[11]", "g[3]", "member", "time", "mass", "link"}
    np.testing.assert_array_equal(on_disk["X"].values, ds["X"].values)
    # the grid unstacks into its axes with plain xarray
    grid = on_disk.set_index(member=["M[11]", "g[3]"]).unstack("member")
    assert grid["max_tension"].dims == ("M[11]", "g[3]")
    _check_against_serial(ds, ln.load_scene(MODELS / "chain_10.json"))


def test_local_cluster_client_forces_and_solver_settings(local_client):
    """A given Client is used as it is; a constant input force and a varied integrator reach every member."""
    scene = ln.load_scene(MODELS / "double_pendulum.json")
    ds = ln.ensemble(scene, vary={"F[3,1]": [0.0, 1.5], "integrator": ["rattle", "yoshida4"]}, t_end=T_END,
                     n_out=N_OUT, dt=2e-3, client=local_client)
    assert local_client.status == "running"  # not closed: it was given
    assert list(ds["integrator"].values) == ["rattle", "yoshida4", "rattle", "yoshida4"]
    for m in range(4):
        setting = {"F[3,1]": ds["F[3,1]"].values[m].item()}
        method = str(ds["integrator"].values[m])
        assert_member_equals(ds, m, serial_run(scene, setting, T_END, N_OUT, method=method, dt=2e-3))
    assert not np.allclose(ds["X"].values[0], ds["X"].values[2])  # the force mattered


def test_separate_process_cluster_grid_and_monte_carlo(process_client):
    """The same study code on a `dask scheduler` + 2 `dask worker` processes: a grid of link lengths (initial
    positions projected, as the study does when R varies) times Monte Carlo initial velocities."""
    scene = ln.load_scene(MODELS / "chain_10.json")
    rng = np.random.default_rng(7)
    ds = ln.ensemble(scene, vary={"R[1..10]": [0.095, 0.105]}, samples={"U0[11,3]": rng.normal(0, 0.2, 3)},
                     t_end=T_END, n_out=N_OUT, client=process_client.scheduler.address)
    assert ds.attrs["engine"] == f"Dask scheduler {process_client.scheduler.address}"
    assert ds.attrs["project_initial"] == 1
    assert len(set(ds["worker"].values)) == 2  # both workers took members
    _check_against_serial(ds, scene, project_initial=True)


def test_adaptive_method_members_equal_serial_runs(process_client):
    scene = ln.load_scene(MODELS / "four_bar.json")
    ds = ln.ensemble(scene, vary={"g[1]": [0.0, 2.0], "tolerance": [1e-6, 1e-9]}, t_end=T_END, n_out=N_OUT,
                     method="dop853", client=process_client)
    for m in range(4):
        setting = {"g[1]": ds["g[1]"].values[m].item()}
        reference = serial_run(scene, setting, T_END, N_OUT, method="dop853", dt=None,
                               rtol=ds["tolerance"].values[m].item())
        assert_member_equals(ds, m, reference)


def test_only_quantities_of_interest_kept(local_client):
    """outputs=[]: a study too large for its trajectories keeps the per-member quantities of interest."""
    scene = ln.load_scene(MODELS / "chain_10.json")
    ds = ln.ensemble(scene, vary={"M[11]": [1.0, 3.0]}, t_end=T_END, n_out=N_OUT, outputs=[], tip="m5",
                     client=local_client)
    assert "X" not in ds and "T" not in ds
    for m, mass in enumerate([1.0, 3.0]):
        reference = serial_run(scene, {"M[11]": mass}, T_END, N_OUT)
        assert ds["max_tension"].values[m] == pytest.approx(reference.T.max(), rel=1e-12)
        assert ds["max_tension_link"].values[m] == np.unravel_index(reference.T.argmax(), reference.T.shape)[1] + 1
        np.testing.assert_allclose(ds["tip_final"].values[m], reference.X[-1, 5], rtol=0, atol=1e-12)


def test_spring_and_drag_constants(local_client):
    """The names the FMU does not have: a spring-damper's constants and a mass's drag reach the members."""
    data = ln.load_scene(MODELS / "double_pendulum.json").to_dict()
    data["springs"] = [{"a": 1, "b": 3, "stiffness": 10.0, "rest_length": 1.5, "damping": 0.2}]
    scene = ln.Scene.from_dict(data)
    ds = ln.ensemble(scene, vary={"stiffness[1]": [5.0, 40.0], "damping[1]": [0.0, 1.0], "drag[2]": [0.3]},
                     t_end=T_END, n_out=N_OUT, client=local_client)
    _check_against_serial(ds, scene)
    assert np.ptp(ds["tip_final"].values[:, 0]) > 0.01  # the constants mattered


def test_default_engine_runs_its_scheduler_in_a_process_of_its_own_and_ends_it():
    """The study's own cluster: the scheduler is another process than the client's (they do not share a GIL),
    its workers are processes of their own, and closing the engine ends the scheduler's process."""
    import os

    import psutil

    from linknet_core.ensemble.engine import Engine

    with Engine(workers=2) as engine:
        scheduler_pid = engine.client.run_on_scheduler(os.getpid)
        worker_pids = set(engine.client.run(os.getpid).values())
        assert scheduler_pid != os.getpid() and os.getpid() not in worker_pids and len(worker_pids) == 2
        assert engine.threads() == 2
    assert not psutil.pid_exists(scheduler_pid) or psutil.Process(scheduler_pid).status() == psutil.STATUS_ZOMBIE
