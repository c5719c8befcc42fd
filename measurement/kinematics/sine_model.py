"""The continuous loop over one of the report's staircases whose timing is fitted with it
(SI): step 2 of :mod:`measurement.kinematics.staircase_search`, the loop of such a fit as a
start for the next, and the same staircase with its count shifted or refitted on all
samples."""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from abu_model.loop_response import Setpoints
from controller.drive import Drive

from measurement.kinematics.drive_model import LoopModel, fitted_loop
from measurement.kinematics.model_fit import DriveFit, DriveModelSettings, fit_model
from measurement.kinematics.staircase_guess import SineStaircase

#: The time offset is fitted within +- this [s] and te within this range of its start [-]
#: (wide: tighter bounds, +- 0.05 s and 0.8-1.25, stopped the fit of seed 16 of the family
#: at a bound, residual 46 x the noise).
T_OFF_RANGE_S = 0.2
TE_RANGE = (0.4, 2.5)


class SineModel(LoopModel):
    """The continuous loop over a :class:`SineStaircase` whose te [s] and span [steps] are
    fitted beside the time offset and the loop (step 2)."""

    def __init__(self, time: np.ndarray, drive: Drive, stair: SineStaircase, te_s: float,
                 span_steps: float, settings: DriveModelSettings, t_off_s: float = 0.0):
        self.stair = stair
        super().__init__(time, drive, stair.setpoints(te_s, span_steps), settings, t_off_s)
        self.lo[0], self.hi[0] = -T_OFF_RANGE_S, T_OFF_RANGE_S
        self.add_parameter("staircase_te_s", te_s, TE_RANGE[0] * te_s, TE_RANGE[1] * te_s)
        self.add_parameter("staircase_span_steps", span_steps, float(stair.n),
                           stair.n + 1.0 - 1e-6)
        self._key = (te_s, span_steps)

    def setpoints_for(self, p: np.ndarray) -> Setpoints:
        key = (float(p[-2]), float(p[-1]))
        if key != self._key:   # the fit's Jacobian moves one parameter at a time: cached
            self.sp, self._key = self.stair.setpoints(*key), key
        return self.sp


def found_drive(params: dict[str, float], sample_time: float | None = None) -> Drive:
    """The PI loop of a fit's parameters (a lag kept above 0 too, so that a refit has it as
    a parameter)."""
    return fitted_loop(params, sample_time, "the staircase found from the record",
                       min_tau_motor_s=1e-5)


def count_shifted(stair: SineStaircase, span_steps: float, dn: int
                  ) -> tuple[SineStaircase, float] | None:
    """``stair`` with ``dn`` steps more and its span [steps] moved with it into [n, n + 1)
    (None below 2 steps)."""
    n = stair.n + dn
    if n < 2:
        return None
    return replace(stair, n=n), min(max(span_steps + dn, n + 1e-3), n + 1.0 - 1e-3)


def refit_sine(time: np.ndarray, theta: np.ndarray, sigma: float, stair: SineStaircase,
               q: dict[str, float], settings: DriveModelSettings) -> DriveFit:
    """The continuous model over ``stair`` fitted from a fit's parameters ``q`` (its loop,
    te, span and time offset) to ``time``, ``theta``."""
    model = SineModel(time, found_drive(q), stair, q["staircase_te_s"],
                      q["staircase_span_steps"], settings, q["t_off_s"])
    return fit_model(time, theta, model, sigma, settings)


__all__ = ["SineModel", "found_drive", "count_shifted", "refit_sine", "T_OFF_RANGE_S",
           "TE_RANGE"]
