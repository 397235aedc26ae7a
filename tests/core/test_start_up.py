"""What a run needs at start-up: the Runge-Kutta tableaux written out as data agree with scipy's to the last bit,
and a simulation on the native core imports no scipy at all (a fresh process: the structure analysis, the scene's
initial state and the run need none of it)."""
from __future__ import annotations

import subprocess
import sys

import numpy as np

from linknet_core.integrators import DOP853, DOPRI5


def test_tableaux_are_scipys_to_the_last_bit():
    from scipy.integrate._ivp import dop853_coefficients as dop853
    from scipy.integrate._ivp.rk import RK45

    n = dop853.N_STAGES
    pairs = [(DOPRI5.A, RK45.A), (DOPRI5.B, RK45.B), (DOPRI5.C, RK45.C), (DOPRI5.error_weights[0], RK45.E),
             (DOP853.A, dop853.A[:n, :n]), (DOP853.B, dop853.B), (DOP853.C, dop853.C[:n]),
             (DOP853.error_weights[0], dop853.E5), (DOP853.error_weights[1], dop853.E3)]
    for ours, theirs in pairs:
        assert ours.shape == theirs.shape
        assert np.array_equal(ours.view(np.int64), np.asarray(theirs, np.float64).view(np.int64))
    assert (DOPRI5.n_stages, DOP853.n_stages) == (RK45.n_stages, n)


def test_a_native_run_imports_no_scipy(models_dir):
    code = ("import sys, linknet_core as ln\n"
            f"scene = ln.load_scene({str(models_dir / 'chain_10.json')!r})\n"
            "ln.simulate(scene, 0.05, method='rattle', dt=1e-3)\n"
            "ln.simulate(scene, 0.05, method='dop853', rtol=1e-6)\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] == 'scipy'))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
