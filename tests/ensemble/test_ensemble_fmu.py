"""The same study through a built FMU (every member one FMU run through fmpy on a worker) gives the same
numbers as through the library."""
import sys

import numpy as np
import pytest

import linknet_core as ln

from .ensemble_support import MODELS, ROOT

T_END, N_OUT = 0.5, 26


@pytest.fixture(scope="module")
def chain_fmu(tmp_path_factory):
    sys.path.insert(0, str(ROOT))
    import build_fmu

    return build_fmu.build_scene_fmu(MODELS / "chain_10.json", tmp_path_factory.mktemp("fmu") / "chain_10.fmu",
                                     step=1e-3, quiet=True)


def test_fmu_study_equals_library_study(chain_fmu, local_client):
    vary = {"M[11]": [0.5, 2.0], "g[3]": [-9.81, -3.0], "F[11,3]": [0.0, 1.5]}
    through_fmu = ln.ensemble(chain_fmu, vary=vary, t_end=T_END, n_out=N_OUT, client=local_client,
                              outputs=["X", "U", "T", "Freact"])
    library = ln.ensemble(MODELS / "chain_10.json", vary=vary, t_end=T_END, n_out=N_OUT, dt=1e-3,
                          client=local_client, outputs=["X", "U", "T", "Freact"])
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


def test_fmu_study_refuses_what_the_fmu_cannot_take(chain_fmu):
    with pytest.raises(ln.LinknetError, match="no parameter for U0"):
        ln.ensemble(chain_fmu, vary={"U0[11,1]": [0.1]}, t_end=0.1)
    with pytest.raises(ln.LinknetError, match="project_initial_positions"):
        ln.ensemble(chain_fmu, vary={"R[1..10]": [0.09, 0.11]}, t_end=0.1)
