"""The outputs T_peak and T_peak_time of both FMUs through fmpy: each link's largest tension over the last doStep,
located between the integrator's steps, as the library's Simulator locates it over the same communication steps
(Simulator.tension_peaks, tested against closed forms in tests/core/test_tension_peaks.py), and the bottom of the
pendulum's swing (3 m g at the quarter period K(1/sqrt 2) sqrt(R/g)) that T at the communication points misses."""
import math

import numpy as np
import pytest

import linknet_core as ln
from native_fmu_support import MODELS, built, fmpy_instance

QUARTER = 1.8540746773013719 * math.sqrt(1.0 / 9.81)


class Slave:
    """An FMI 2.0 FMU through fmpy's FMU2Slave, initialized at t = 0."""

    def __init__(self, fmu):
        self.fmu, self.log = fmu, []
        self.slave, self.callbacks = fmpy_instance(fmu, "peaks", self.log)
        self.slave.setupExperiment(startTime=0.0)
        self.slave.enterInitializationMode()
        self.slave.exitInitializationMode()

    def get(self, prefix) -> np.ndarray:
        return np.array(self.slave.getReal(self.fmu.vrs(prefix)))

    def set_forces(self, F: np.ndarray, masses) -> None:
        self.slave.setReal([self.fmu.vr[f"F[{k + 1},{i + 1}]"] for k in masses for i in range(3)],
                           [float(x) for k in masses for x in F[k]])

    def step(self, t, h):
        self.slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)  # fmpy raises unless fmi2OK

    def free(self):
        self.slave.terminate()
        self.slave.freeInstance()


@pytest.mark.parametrize("native", [True, False], ids=["native", "pythonfmu"])
def test_the_fmu_reports_the_swing_bottom_between_communication_points(native, fmu_root):
    """Communication steps of 1 s from the pendulum released horizontal: T at 0, 1 and 2 s misses both bottoms;
    T_peak of each step is 3 m g at the bottom's time, as the library finds it over the same steps."""
    fmu = built(fmu_root, "pendulum", native=native)
    slave = Slave(fmu)
    try:
        assert slave.get("T_peak")[0] == slave.get("T")[0] and slave.get("T_peak_time")[0] == 0.0
        sim = ln.Simulator(MODELS / "pendulum.json")
        for t, bottom in ((0.0, QUARTER), (1.0, 3 * QUARTER)):
            slave.step(t, 1.0)
            sim.advance(t + 1.0)
            peak, when = sim.tension_peaks()
            assert slave.get("T")[0] < 0.7 * 3 * 9.81
            np.testing.assert_allclose(slave.get("T_peak"), peak, rtol=1e-12)
            np.testing.assert_allclose(slave.get("T_peak_time"), when, rtol=0, atol=1e-12)
            assert abs(peak[0] - 3 * 9.81) < 0.05 and abs(when[0] - bottom) < 1e-3  # the library's located accuracy
    finally:
        slave.free()


def test_native_fmu_peaks_per_communication_step_are_the_library_s(fmu_root):
    """chain_10 under a force on its tip that changes every communication step (10 ms), with dop853 and rattle: each
    step's T_peak and T_peak_time as the library's Simulator gives them over the same steps with the same held
    inputs, to round-off; and an FMU state taken after a step reports that step's peaks once restored."""
    fmu = built(fmu_root, "chain_10")
    scene = ln.load_scene(MODELS / "chain_10.json")
    masses = [int(name.split("[")[1].split(",")[0]) - 1 for name in fmu.names("F")[::3]]
    h = 0.01
    for method, settings in (("dop853", {}), ("rattle", {"dt": 1e-3})):
        slave = Slave(fmu)
        try:
            if method != "dop853":
                slave.slave.terminate()
                slave.slave.reset()
                slave.slave.setString([fmu.vr["integrator"]], [method])
                slave.slave.setReal([fmu.vr["step"]], [settings["dt"]])
                slave.slave.setupExperiment(startTime=0.0)
                slave.slave.enterInitializationMode()
                slave.slave.exitInitializationMode()
            sim = ln.Simulator(scene, method=method, **settings)
            saved = None
            for n in range(20):
                t = n * h
                F = np.zeros((scene.K, 3))
                F[masses[-1]] = [3.0 * math.sin(40.0 * t), 0.0, -2.0 * math.cos(25.0 * t)]
                slave.set_forces(F, masses)
                slave.step(t, h)
                sim.advance(t + h, F)
                peak, when = sim.tension_peaks()
                np.testing.assert_allclose(slave.get("T_peak"), peak, rtol=0, atol=1e-11 * np.abs(peak).max(),
                                           err_msg=f"{method} step {n}")
                np.testing.assert_allclose(slave.get("T_peak_time"), when, rtol=0, atol=1e-12)
                assert np.all(when >= t - 1e-12) and np.all(when <= t + h + 1e-12)
                if n == 9:
                    saved, at_save = slave.slave.getFMUstate(), (peak, when)
            slave.slave.setFMUstate(saved)
            np.testing.assert_allclose(slave.get("T_peak"), at_save[0], rtol=0, atol=1e-11 * np.abs(at_save[0]).max())
            np.testing.assert_allclose(slave.get("T_peak_time"), at_save[1], rtol=0, atol=1e-12)
            slave.slave.freeFMUstate(saved)
        finally:
            slave.free()
