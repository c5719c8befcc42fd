"""Staircase FMU: the speed setpoint of the experiment (report sec. 4.2.2) as an FMI 2.0 CS slave.

Built by ``fmus.build`` into ``Staircase.fmu`` as module ``abufmu_staircase``; the
``controller`` package travels inside the FMU as ``staircase_controller`` (the build rewrites
the project imports below to the vendored names).

Outputs (no inputs):
* ``omega_ref`` [rad/s]: setpoint at the FMU's current time, right-continuous: at a step time
  it is already the new level.
* ``next_event_time`` [s]: the first step time strictly after the current time, or
  ``NO_EVENT`` = 1e30 s when no step is left. A master shortens its communication step to land
  on it. A step end within ``EVENT_SNAP`` of a step time is snapped onto it, so that
  ``t + (t_s - t)`` rounding one ulp short still lands on the new level.
"""
from __future__ import annotations

import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from abu_model.errors import ParameterError
from abu_model.params import check_record
from controller.reference import ROUNDINGS, Staircase as StaircaseModel

#: Reported for next_event_time when no setpoint step is left [s].
NO_EVENT = 1e30
#: Relative distance within which a step end is snapped onto a setpoint step time [-].
EVENT_SNAP = 1e-12

_PARAMETERS = ("omega0", "omega_end", "t0", "te", "step", "rounding")


class Staircase(Fmi2Slave):
    """Staircase approximation of the inclined sine from omega0 to omega_end over [t0, t0+te]."""

    author = "abu-friction"
    description = ("Speed setpoint: staircase approximation (resolution 'step') of the inclined "
                   "sine from omega0 to omega_end over [t0, t0+te] (report eq. 4.8); "
                   "right-continuous; next_event_time = next step time (1e30 s if none)")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.2, step_size=1e-3)

    UNITS = {
        "omega0": "rad/s", "omega_end": "rad/s", "t0": "s", "te": "s", "step": "rad/s",
        "omega_ref": "rad/s", "next_event_time": "s",
    }
    OUTPUT_DEPENDENCIES = {"omega_ref": (), "next_event_time": (), "step_index": ()}

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        # Parameters (report sec. 4.2.3: -17 Hz -> -22 Hz in 1 s, 1 Hz steps).
        self.omega0 = -2.0 * math.pi * 17.0
        self.omega_end = -2.0 * math.pi * 22.0
        self.t0 = 0.0
        self.te = 1.0
        self.step = 2.0 * math.pi
        self.rounding = 0
        # Internal state.
        self.time = 0.0
        self._model: StaircaseModel | None = None

        fixed = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed)
        self.register_variable(Real(
            "omega0", description="setpoint before the first step [rad/s]", **fixed))
        self.register_variable(Real(
            "omega_end", description="end value of the inclined sine [rad/s]", **fixed))
        self.register_variable(Real("t0", description="start of the inclined sine [s]", **fixed))
        self.register_variable(Real(
            "te", description="duration of the inclined sine, > 0 [s]", **fixed))
        self.register_variable(Real(
            "step", description="setpoint resolution, > 0 [rad/s] (2 pi rad/s = 1 Hz)", **fixed))
        self.register_variable(Integer(
            "rounding", description="step k at the sine crossing omega0 + (k - r) step: "
                                    "0 lead (r = 1, report), 1 nearest (r = 1/2), 2 trail (r = 0)",
            **fixed))
        self.register_variable(Real(
            "omega_ref", causality=Fmi2Causality.output,
            description="speed setpoint at the current time, right-continuous [rad/s]",
            getter=self._omega_ref))
        self.register_variable(Real(
            "next_event_time", causality=Fmi2Causality.output,
            description="first setpoint step time after the current time, 1e30 if none [s]",
            getter=self._next_event_time))
        self.register_variable(Integer(
            "step_index", causality=Fmi2Causality.output, variability=Fmi2Variability.discrete,
            description="number of setpoint steps taken at the current time",
            getter=self._step_index))

    # ----------------------------------------------------------------- model
    def _build_model(self) -> StaircaseModel:
        rounding = int(self.rounding)
        if rounding not in range(len(ROUNDINGS)):
            raise ParameterError("rounding", self.rounding, "0 (lead), 1 (nearest) or 2 (trail)")
        return StaircaseModel(self.omega0, self.omega_end, self.t0, self.te, self.step,
                              ROUNDINGS[rounding])

    def _current_model(self) -> StaircaseModel | None:
        """The staircase; before initialization one built from the current parameters."""
        if self._model is not None:
            return self._model
        try:
            return self._build_model()
        except ValueError:
            return None

    def _omega_ref(self) -> float:
        model = self._current_model()
        return math.nan if model is None else model.value(self.time)

    def _next_event_time(self) -> float:
        model = self._current_model()
        if model is None:
            return math.nan
        t = model.next_event_time(self.time)
        return NO_EVENT if math.isinf(t) else t

    def _step_index(self) -> int:
        model = self._current_model()
        return -1 if model is None else model.index(self.time)

    # ----------------------------------------------------------------- FMI
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.time = float(start_time)

    def exit_initialization_mode(self):
        # A ParameterError (a ValueError) names the parameter; the runtime returns fmi2Error.
        self._model = self._build_model()

    def do_step(self, current_time, step_size):
        end = current_time + step_size
        upcoming = self._model.next_event_time(current_time)
        if math.isfinite(upcoming) and abs(end - upcoming) <= EVENT_SNAP * max(1.0, abs(upcoming)):
            end = upcoming  # land exactly on the step: the new level is output
        self.time = end
        return True

    # ----------------------------------------------------------------- FMU state
    def _get_fmu_state(self):
        state = {name: getattr(self, name) for name in _PARAMETERS}
        state.update(time=self.time, initialized=self._model is not None)
        return state

    @staticmethod
    def _validate_fmu_state(state, before_initialization: bool) -> dict:
        """A checked copy of a saved state (ValueError if anything is missing or malformed)."""
        kinds = {**{name: "real" for name in _PARAMETERS}, "rounding": "int", "time": "real",
                 "initialized": "bool"}
        return check_record(state, kinds, "Staircase state")

    def _set_fmu_state(self, state):
        for name in _PARAMETERS:
            setattr(self, name, state[name])
        self.time = float(state["time"])
        self._model = self._build_model() if state["initialized"] else None
