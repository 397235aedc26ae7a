"""Driving a simulation: the path chosen once per scene (specialisation and backend), the stepping interface
the FMU uses, whole runs, and the rigidity report of ``linknet analyze``."""
from linknet_core.simulator.simulator import (InitialReport, Result, SimulationInterrupted, Simulator,
                                             prepare_initial_state, simulate)
from linknet_core.simulator.settings import RunSettings
from linknet_core.simulator.specialisation import Specialisation, choose_specialisation

__all__ = ["Simulator", "simulate", "RunSettings", "Result", "SimulationInterrupted", "InitialReport", "prepare_initial_state", "Specialisation",
           "choose_specialisation"]
