"""A slip that starts slowly and turns: the sliding friction -mu N v_t / |v_t| damps the velocity across the slip at
the rate mu N / (M |v_t|), a stiff mode while |v_t| is small, on which the explicit methods are stable only for steps
within their stability interval on the negative real axis (AdaptiveEvents._step_cap). A rod dropped at a slant and
thrown sideways lands on one end, sticks, and its foot slips at a slip event in a direction that turns: the run
must meet its tolerance there."""
import numpy as np
import pytest

import linknet_core as ln
from linknet_core.integrators.runge_kutta import DOP853, DOPRI5

from test_native_friction import dropped_rod


def stability_function(A, B, z):
    """R(z) = 1 + z b^T (I - z A)^-1 1 of an explicit tableau (Hairer and Wanner, Solving ODEs II, IV.2)."""
    B = np.asarray(B, float)
    s = B.size
    A_square = np.zeros((s, s))
    A = np.asarray(A, float)
    A_square[:, :min(A.shape[1], s)] = A[:s, :s]
    return 1.0 + z * B @ np.linalg.solve(np.eye(s) - z * A_square, np.ones(s))


@pytest.mark.parametrize("method", [DOPRI5, DOP853])
def test_real_stability_interval(method):
    # |R| <= 1 all along [-x, 0] and > 1 just past it, R evaluated from the tableau as the linear solve
    x = method.real_stability
    inside = [abs(stability_function(method.A, method.B, -x * f)) for f in np.linspace(1e-3, 1 - 1e-9, 400)]
    assert max(inside) <= 1.0 + 1e-12
    assert abs(stability_function(method.A, method.B, -x * (1 + 1e-6))) > 1.0
    # Dormand and Prince's 5(4) pair: about 3.3 (Hairer, Norsett and Wanner I, II.10; Hairer and Wanner II, IV.2)
    assert x == pytest.approx({"dopri5": 3.3066, "dop853": 6.3937}[method.name], abs=1e-4)


def test_turning_slip_start_meets_the_tolerance():
    # the foot sticks at 0.247 s and slips at 0.324 s, along a direction that turns; before the step cap the runs at
    # these tolerances ended 0.087 m (dop853, rtol 1e-6) and 5.5e-4 m (dopri5, 1e-8) from the tight run
    scene = dropped_rod(0.8, [1.2, 0.7, 0.0])
    reference = ln.simulate(scene, 0.5, "dop853", backend="native", rtol=1e-12, n_out=2, error_estimate=False)
    assert [e.kind for e in reference.events] == ["contact", "slip"]
    for method, rtol in [("dop853", 1e-6), ("dopri5", 1e-8)]:
        run = ln.simulate(scene, 0.5, method, backend="native", rtol=rtol, n_out=2, error_estimate=False)
        assert np.abs(run.X[-1] - reference.X[-1]).max() < 10 * rtol, method
