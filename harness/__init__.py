"""Co-simulation harness: a generic FMI 2.0 master on fmpy, the report's experiments
(staircase, prescribed-acceleration ramp, Table 4.1), plots and the ``abu`` command line.

The master (:mod:`harness.master`) knows nothing about the ABU; :mod:`harness.experiments`
describes the ABU system as data (:mod:`harness.system`) and turns the recorded rows into
the friction bounds.
"""
from .master import (AlgebraicLoopError, CoSimResult, CoSimulation, CoSimulationError, FMUError,
                     SwitchEvent, simulate)
from .system import Component, Connection, Source, System

__all__ = ["AlgebraicLoopError", "CoSimResult", "CoSimulation", "CoSimulationError", "FMUError",
           "SwitchEvent", "simulate", "Component", "Connection", "Source", "System"]
