"""Tension peaks between outputs (Result.T_peak, Simulator.tension_peaks): a spike between two outputs that the sampled
T misses is located between the integrator's steps, against closed forms and densely sampled runs.

The pendulum released at rest from horizontal has its bottom-of-swing tension 3 m g (energy: m v^2 / R = 2 m g there)
at the quarter period K(1/sqrt 2) sqrt(R/g) and three quarters of it (K the complete elliptic integral of the first
kind, scipy.special.ellipk(1/2) = 1.8540746773013719)."""
import math

import numpy as np
import pytest

import linknet_core as ln
from linknet_core.cli import main
from linknet_core.integrators.base import TensionPeaks

K_HALF = 1.8540746773013719  # K(m = k^2 = 1/2)
G, R, M = 9.81, 1.0, 1.0
QUARTER = K_HALF * math.sqrt(R / G)

# the located accuracy (docs/accuracy.md, "Tension peaks between outputs"): the method's own error in T plus the
# quadratic's between its step ends. dop853 at its default takes steps of ~0.08 s on this pendulum, about a third
# of the width of the tension's peak at the bottom: measured 2.7e-4 and 1.7e-2 N, 1e-4 and 2.3e-4 s at the two
# bottoms; rattle at 1 ms its O(dt^2) error in T, 7.2e-5 N, 8.3e-7 s; yoshida4 at 1 ms 2e-9 N, 2.3e-10 s
PENDULUM_CASES = [  # method, settings, bound on |T_peak - 3 m g| (N), bound on the time's error (s)
    ("dop853", {}, 0.05, 1e-3),
    ("rattle", {"dt": 1e-3}, 3e-4, 1e-5),
    ("yoshida4", {"dt": 1e-3}, 1e-7, 1e-8),
]


@pytest.mark.parametrize("method,settings,value_bound,time_bound", PENDULUM_CASES)
def test_the_bottom_of_the_swing_between_three_outputs(method, settings, value_bound, time_bound):
    """Outputs at 0, 1 and 2 s: the samples miss both bottoms (T is 4.9 and 17.9 N there), T_peak finds 3 m g at
    the quarter period in (0, 1] and at three quarters of the period in (1, 2]."""
    r = ln.simulate("models/pendulum.json", 2.0, n_out=3, method=method, error_estimate=False, **settings)
    three_mg = 3 * M * G
    assert np.abs(r.T).max() < 0.7 * three_mg
    assert r.stats["tension_peaks"] == "located"
    assert r.T_peak[0, 0] == r.T[0, 0] and r.T_peak_time[0, 0] == 0.0
    for row, bottom in ((1, QUARTER), (2, 3 * QUARTER)):
        assert abs(r.T_peak[row, 0] - three_mg) <= value_bound, (row, r.T_peak[row, 0] - three_mg)
        assert abs(r.T_peak_time[row, 0] - bottom) <= time_bound, (row, r.T_peak_time[row, 0] - bottom)


def test_a_peak_at_an_output_time_is_the_sample_there():
    """Outputs every 0.05 s of the pendulum's swing down: T rises over each interval up to the bottom, so each
    interval's peak is its end, the sample itself."""
    r = ln.simulate("models/pendulum.json", 0.55, output_dt=0.05, error_estimate=False)
    np.testing.assert_allclose(r.T_peak[1:, 0], r.T[1:, 0], rtol=1e-9)
    np.testing.assert_allclose(r.T_peak_time[1:, 0], r.t[1:], rtol=0, atol=1e-12)


def test_the_quadratic_between_step_ends_against_a_closed_form():
    """TensionPeaks on T = a cos(w (t - t*)) + b at uneven step ends (steps of 0.02-0.06 s, w = 10/s): the peak a + b
    (in magnitude) within the quadratic's interpolation error |T'''| h^3 / 15 (h the longest step), its time within
    |T'''| h^2 / (3 |T''|); and where |T| only falls over the interval, the value at its start."""
    rng = np.random.default_rng(3)
    a, b, w = np.array([5.0, -4.0]), np.array([1.0, -1.0]), 10.0
    t_star = np.array([0.33, 0.51])
    times = np.concatenate([[0.0], np.cumsum(rng.uniform(0.02, 0.06, 30))])
    times = times[times <= 1.0]
    peaks, falling = TensionPeaks(), TensionPeaks()
    T = lambda t: a * np.cos(w * (t - t_star)) + b  # noqa: E731
    decay = lambda t: np.array([-3.0 * math.exp(-2.0 * t)])  # noqa: E731
    peaks.begin(times[0], T(times[0]))
    falling.begin(times[0], decay(times[0]))
    for t in times[1:]:
        peaks.step(t, T(t))
        falling.step(t, decay(t))
    h = np.diff(times).max()
    value_bound = np.abs(a) * w ** 3 * h ** 3 / 15
    time_bound = w * h ** 2 / 3
    np.testing.assert_array_less(np.abs(peaks.peak - (a + b)), value_bound)
    np.testing.assert_array_less(np.abs(peaks.time - t_star), time_bound)
    assert falling.peak[0] == -3.0 and falling.time[0] == 0.0


def _link(scene, name):
    return next(l for l in range(scene.L) if scene.link_label(l).endswith(f"({name})"))


def test_net_10x10_spikes_at_its_first_snap():
    """The net's first snap (docs/robust_stepping.md: ~10 ms in which a link force jumps from a few N). With outputs
    every 0.05 s the samples at 0.35 and 0.40 s show at most 18.6 N anywhere; T_peak over (0.35, 0.40] shows the
    spikes a dense sampling finds: n7_3-n8_3 in compression beyond the -76.4 N that samples every 10 ms saw at 0.37 s,
    and n4_6-n5_6 at ~1869 N, 100 times the samples, for ~0.3 ms. Reference: dop853 at rtol 1e-12 sampled every 2 us
    around each spike (its samples, not its peaks)."""
    scene = ln.load_scene("models/net_10x10.json")
    r = ln.simulate(scene, 0.4, output_dt=0.05, error_estimate=False)
    assert r.stats["tension_peaks"] == "located"
    row = int(np.argmin(np.abs(r.t - 0.40)))
    assert np.abs(r.T[row - 1:row + 1]).max() < 20.0
    reference = ln.Simulator(scene, rtol=1e-12, error_estimate=False)
    for name, window, bound in (("n4_6-n5_6", (0.3644, 0.3650), 0.02), ("n7_3-n8_3", (0.3686, 0.3698), 0.02)):
        l = _link(scene, name)
        reference.advance(window[0])
        sampled = []
        for t in np.arange(window[0], window[1], 2e-6)[1:]:
            reference.advance(t)
            sampled.append((reference.outputs()["T"][l], t))
        T_ref, t_ref = max(sampled, key=lambda p: abs(p[0]))
        assert abs(r.T_peak[row, l] - T_ref) <= bound * abs(T_ref), (name, r.T_peak[row, l], T_ref)
        assert abs(r.T_peak_time[row, l] - t_ref) <= 2e-5, (name, r.T_peak_time[row, l], t_ref)
        assert abs(r.T_peak[row, l]) > 4 * np.abs(r.T[row - 1:row + 1, l]).max()
    assert r.T_peak[row, _link(scene, "n7_3-n8_3")] < -76.4
    peak, l, when = r.largest_peak()
    assert scene.link_label(l).endswith("(n4_6-n5_6)") and peak > 1800.0 and 0.364 < when < 0.365


def test_numpy_and_native_paths_locate_the_same_peaks():
    """The numpy reference (integrators.base.TensionPeaks) and the native core (tension_peaks.c) on the same steps:
    the same peaks and times to round-off, for the Runge-Kutta, RATTLE and composition loops, on a chain (2-D path)
    and on the crane, whose driven trolley sets anchor accelerations in B (26)."""
    for scene, t_end in (("models/chain_10.json", 0.3), ("models/crane.json", 0.5)):
        for method, settings in (("dop853", {}), ("dopri5", {"rtol": 1e-6}), ("rattle", {"dt": 1e-3}),
                                 ("yoshida4", {"dt": 5e-3})):
            peaks = []
            for backend in ("native", "numpy"):
                sim = ln.Simulator(scene, method=method, backend=backend, error_estimate=False, **settings)
                for t in np.linspace(0.0, t_end, 4)[1:]:
                    sim.advance(t)
                assert sim.peaks_located
                peaks.append(sim.tension_peaks())
            scale = np.abs(peaks[0][0]).max()
            np.testing.assert_allclose(peaks[1][0], peaks[0][0], rtol=0, atol=1e-9 * scale, err_msg=(scene, method))
            np.testing.assert_allclose(peaks[1][1], peaks[0][1], rtol=0, atol=1e-9, err_msg=(scene, method))


def test_a_snapshot_keeps_the_peaks_of_the_advance_that_led_to_it():
    sim = ln.Simulator("models/pendulum.json", error_estimate=False)
    sim.advance(0.3)
    snapshot = sim.get_state()
    before = sim.tension_peaks()
    sim.advance(1.0)
    assert sim.tension_peaks()[0][0] > 2 * before[0][0]
    sim.set_state(snapshot)
    assert sim.peaks_located
    np.testing.assert_array_equal(np.array(sim.tension_peaks()), np.array(before))
    sim.reset()  # no advance: the tensions now, at the start
    assert not sim.peaks_located and sim.tension_peaks()[1][0] == 0.0


def test_paths_that_do_not_locate_peaks_report_the_sampled_tension():
    """A static scene (its tensions stand still with the input held) and free rigid bodies: the sample at each
    output, said in the stats."""
    for scene in ("models/redundant_truss.json", "models/spinning_tetrahedron.json"):
        r = ln.simulate(scene, 0.2, n_out=3, error_estimate=False)
        assert r.stats["tension_peaks"] == "sampled"
        np.testing.assert_array_equal(r.T_peak, r.T)
        np.testing.assert_array_equal(r.T_peak_time, np.repeat(r.t[:, None], r.T.shape[1], axis=1))


def test_the_summary_and_the_file_carry_the_largest_peak(tmp_path, capsys):
    out = tmp_path / "run.npz"
    assert main(["simulate", "models/pendulum.json", "--t-end", "2", "--n-out", "3", "--no-progress",
                 "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "largest tension peak between outputs = 29.4" in text and "at t = 0.592" in text
    assert "largest sampled |T| = 17.9" in text
    saved = np.load(out)
    assert saved["T_peak"].shape == (3, 1) and saved["T_peak_time"][1, 0] == pytest.approx(QUARTER, abs=1e-3)
