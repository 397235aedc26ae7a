"""The same study through a built FMU (every member one FMU run through fmpy on a worker) gives the same
numbers as through the library: for an FMU on pythonfmu (which carries its scene) and a native one (given
the scene it was built from)."""
import sys

import numpy as np
import pytest

import linknet_core as ln

from .ensemble_support import MODELS, ROOT

T_END, N_OUT = 0.5, 26
OUTPUTS = ["X", "U", "T", "Freact"]


@pytest.fixture(scope="module")
def build(tmp_path_factory):
    sys.path.insert(0, str(ROOT))
    import build_fmu

    folder = tmp_path_factory.mktemp("fmu")
    built = {}

    def fmu(native: bool):
        if native not in built:
            built[native] = build_fmu.build_scene_fmu(MODELS / "chain_10.json", folder / f"chain_10_{native}.fmu",
                                                      step=1e-3, quiet=True, native=native)
        return built[native]
    return fmu


@pytest.fixture(scope="module")
def chain_fmu(build):
    return build(False)


@pytest.fixture(scope="module")
def library_study(local_client):
    vary = {"M[11]": [0.5, 2.0], "g[3]": [-9.81, -3.0], "F[11,3]": [0.0, 1.5]}
    return vary, ln.ensemble(MODELS / "chain_10.json", vary=vary, t_end=T_END, n_out=N_OUT, dt=1e-3,
                             client=local_client, outputs=OUTPUTS)


@pytest.mark.parametrize("native", [False, True], ids=["pythonfmu", "native"])
def test_fmu_study_equals_library_study(native, build, library_study, local_client):
    vary, library = library_study
    fmu = build(native)
    scene = MODELS / "chain_10.json" if native else None  # the pythonfmu FMU carries its scene
    through_fmu = ln.ensemble(scene, fmu=fmu, vary=vary, t_end=T_END, n_out=N_OUT, client=local_client,
                              outputs=OUTPUTS)
    assert through_fmu.attrs["runs_through"] == "FMU (fmpy)" and "the FMU's" in through_fmu.attrs["solver"]
    assert list(through_fmu["status"].values) == ["ok"] * 8, list(through_fmu["error"].values)
    # same solver, same held inputs, same communication points: agreement to round-off (the FMU reaches
    # t_i + h where the library reaches t_{i+1}, which may differ in the last bit)
    np.testing.assert_allclose(through_fmu["X"].values, library["X"].values, rtol=0, atol=1e-11)
    np.testing.assert_allclose(through_fmu["U"].values, library["U"].values, rtol=0, atol=1e-10)
    np.testing.assert_allclose(through_fmu["T"].values, library["T"].values, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(through_fmu["Freact"].values, library["Freact"].values, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(through_fmu["max_tension"].values, library["max_tension"].values, rtol=1e-9)
    assert np.ptp(library["tip_final"].values[:, 2]) > 0.05  # the parameters mattered


def test_fmu_refusal_is_the_members_error(chain_fmu, local_client):
    ds = ln.ensemble(chain_fmu, vary={"M[11]": [1.0, -1.0], "integrator": ["rattle", "dop853"]}, t_end=0.2,
                     n_out=5, client=local_client)
    assert list(ds["status"].values) == ["ok", "ok", "failed", "failed"], list(ds["error"].values)
    assert "M[11]" in ds["error"].values[2] and "must be > 0" in ds["error"].values[2]
    assert ds["error"].values[2].startswith("FmuError:")


def test_fmu_study_refuses_what_the_fmu_cannot_take(chain_fmu, build):
    with pytest.raises(ln.LinknetError, match="no parameter for U0"):
        ln.ensemble(chain_fmu, vary={"U0[11,1]": [0.1]}, t_end=0.1)
    with pytest.raises(ln.LinknetError, match="project_initial_positions"):
        ln.ensemble(chain_fmu, vary={"R[1..10]": [0.09, 0.11]}, t_end=0.1)
    with pytest.raises(ln.LinknetError, match="was not built from scene chain_100"):
        ln.ensemble(MODELS / "chain_100.json", fmu=chain_fmu, vary={"M[3]": [1.0]}, t_end=0.1)
    with pytest.raises(ln.LinknetError, match="carries no scene"):
        ln.ensemble(fmu=build(True), vary={"M[3]": [1.0]}, t_end=0.1)


def test_fmu_study_from_the_command_line(build, process_cluster, tmp_path):
    import subprocess
    import xarray as xr

    out = tmp_path / "fmu.nc"
    run = subprocess.run([sys.executable, "-m", "linknet_core.cli", "ensemble", str(MODELS / "chain_10.json"),
                          "--fmu", str(build(True)), "--vary", "M[11]=0.2,0.4", "--t-end", "0.3", "--n-out", "4",
                          "--scheduler", process_cluster, "--out", str(out), "--no-progress"],
                         capture_output=True, text=True, cwd=str(ROOT), timeout=180)
    assert run.returncode == 0, run.stderr
    assert "2 members through the FMU (fmpy)" in run.stdout
    ds = xr.open_dataset(out, engine="h5netcdf")
    assert list(ds["status"].values) == ["ok", "ok"] and ds.attrs["source"].endswith(".fmu")
