"""Round-off of the fixed-step methods as the step shrinks and where the scene sits.

The references are independent of linknet_core: the pendulum's analytic motion (Jacobi elliptic functions,
benchmarks.roundoff.pendulum_exact) and, for the scene of 1e3 m and 1e-4 m links, scipy's DOP853 on the index-1
form written from the seed (benchmarks.reference.solve_index1). A velocity read off the rounded X_new - X would make
the error grow as dt shrinks and with the distance from the origin (benchmarks/roundoff.py, docs/robust_stepping.md).
"""
from __future__ import annotations

import warnings

import numpy as np
import pytest

import linknet_core as ln
from benchmarks.reference import solve_index1
from benchmarks.roundoff import SHIFT_1KM, mixed_links, pendulum, pendulum_exact
from benchmarks.scene_spec import SceneSpec

DTS = (1e-4, 1e-5, 1e-6)
# what round-off may leave at the finest step: the position stage's tolerance (1e-14 relative) leaves a residual
# along the link each stage whose velocity leaks ~tol |U| per stage, a random walk of ~sqrt(N) tol |U| t; a 1 km
# offset adds the positions' own rounding, ~sqrt(N) ulp(1e3). Measured at most 4e-12 m at t = 0.1 s.
ROUNDOFF_FLOOR = 2e-11


def _end_error(scene, X_ref, t_end, method, dt, backend):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the run's own error estimate: these tests measure the true error
        res = ln.simulate(scene, t_end=t_end, method=method, dt=dt, n_out=2, backend=backend)
    return float(np.linalg.norm(res.X[-1] - X_ref, axis=1).max())


def _pendulum_errors(offset, t_end, method, backend, dts=DTS):
    X_ref = np.array([offset, pendulum_exact(t_end, offset)])
    return [_end_error(pendulum(offset), X_ref, t_end, method, dt, backend) for dt in dts]


def _falls_to_floor(errors):
    """Each finer step at most as far off as the coarser one, or within the round-off floor."""
    return all(fine <= max(coarse, ROUNDOFF_FLOOR) for coarse, fine in zip(errors, errors[1:]))


@pytest.mark.parametrize("method", ["rattle", "yoshida4"])
def test_native_pendulum_error_falls_with_dt_and_does_not_depend_on_where_it_sits(method):
    t_end = 0.1
    at_origin = _pendulum_errors((0.0, 0.0, 0.0), t_end, method, "native")
    far = _pendulum_errors(SHIFT_1KM, t_end, method, "native")
    assert _falls_to_floor(at_origin), at_origin
    assert _falls_to_floor(far), far
    assert max(at_origin[-1], far[-1]) <= ROUNDOFF_FLOOR, (at_origin, far)
    # the same motion 1 km away is as accurate as at the origin, up to the floor
    for here, there in zip(at_origin, far):
        assert abs(here - there) <= ROUNDOFF_FLOOR + 1e-3 * here, (at_origin, far)
    if method == "rattle":  # order 2 where truncation dominates: 100x per 10x in dt
        assert at_origin[1] <= at_origin[0] / 50 and far[1] <= far[0] / 50


@pytest.mark.parametrize("method,dts", [("rattle", DTS[:2]),
                                        pytest.param("rattle", DTS, marks=pytest.mark.slow),
                                        pytest.param("yoshida4", DTS, marks=pytest.mark.slow)])
def test_numpy_pendulum_error_falls_with_dt_and_does_not_depend_on_where_it_sits(method, dts):
    # the reference takes ~1 ms per step on a loaded machine: a run of 0.01 s (dt 1e-6 only when slow tests run)
    t_end = 0.01
    at_origin = _pendulum_errors((0.0, 0.0, 0.0), t_end, method, "numpy", dts)
    far = _pendulum_errors(SHIFT_1KM, t_end, method, "numpy", dts)
    assert _falls_to_floor(at_origin), at_origin
    assert _falls_to_floor(far), far
    assert max(at_origin[-1], far[-1]) <= ROUNDOFF_FLOOR, (at_origin, far)
    for here, there in zip(at_origin, far):
        assert abs(here - there) <= ROUNDOFF_FLOOR + 1e-3 * here, (at_origin, far)


@pytest.fixture(scope="module")
def mixed_reference():
    t_end = 0.02
    spec = SceneSpec.from_core(mixed_links())
    X_ref = solve_index1(spec, t_end, rtol=1e-13, atol=1e-16)[0]
    X_check = solve_index1(spec, t_end, rtol=2.5e-14, atol=1e-17)[0]
    return t_end, X_ref, float(np.linalg.norm(X_ref - X_check, axis=1).max())


@pytest.mark.slow  # the index-1 reference of the 1e-4 m link's whip takes minutes
@pytest.mark.parametrize("backend", ["native", "numpy"])
def test_links_of_1e3_and_1e_minus_4_m_converge_as_dt_falls(mixed_reference, backend):
    t_end, X_ref, agree = mixed_reference
    dts = DTS if backend == "native" else DTS[:2]
    errors = [_end_error(mixed_links(), X_ref, t_end, "rattle", dt, backend) for dt in dts]
    # the positions are of 1e3 m: their ulp, 1.1e-13 m, times sqrt(N) is this scene's floor
    floor = max(ROUNDOFF_FLOOR, 10 * agree)
    assert all(fine <= max(coarse / 50, floor) for coarse, fine in zip(errors, errors[1:])), errors
