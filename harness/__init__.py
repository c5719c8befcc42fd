"""Co-simulation harness: a generic FMI 2.0 master on fmpy, the report's experiments
(staircase, prescribed-acceleration ramp, Table 4.1), plots and the ``abu`` command line.

The master (:mod:`harness.master`) knows nothing about the ABU; :mod:`harness.experiments`
describes the ABU system as data (:mod:`harness.system`) and turns the recorded rows into
the friction bounds.
"""
import os

# The toolkit's linear algebra is small (solver steps, local fits): a multi-threaded BLAS is
# slower on it (measured 10-15x on a busy 2-core machine). Respect a user's own setting.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
from .master import (AlgebraicLoopError, CoSimResult, CoSimulation, CoSimulationError, FMUError,
                     SwitchEvent, simulate)
from .system import Component, Connection, Source, System

__all__ = ["AlgebraicLoopError", "CoSimResult", "CoSimulation", "CoSimulationError", "FMUError",
           "SwitchEvent", "simulate", "Component", "Connection", "Source", "System"]
