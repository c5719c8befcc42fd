"""The tracking drive of the report's chapter 6 as an FMI co-simulation (``abu simulate
--motion profile --drive tracking.json --profile profile.json``).

The tracking loop is modelled exactly rather than sampled: the rotor does not feel the ball
(the report's model, ``ball_reaction`` off), so its motion under the loop is the loop's exact
response to the profile (:mod:`abu_model.tracking_response`), and the torque the controller
commands is known in closed form, T_cmd = J_total (alpha + tau_motor alpha') (the plant's lag
then applies J_total alpha). The master feeds AbuBall that torque and its derivatives
(``torque``, ``torque_rate``, ``torque_accel``, ``torque_jerk``: the plant's Taylor hold) as
sources at every communication point; the plant locates every stick/slip switch exactly. No
FMU changes: the FMUs' interface stays as it is. A staircase needs the PI SpeedController
FMU; a smooth profile through a P law needs no controller state the master does not have.

With mu_req continuous (no acceleration steps) the slip happens where mu_req reaches mu:
mu_low = mu_high = mu up to the communication step (the bounds of the staircase collapse),
and eq. 4.1/4.2 at the slip instant is the estimate, as for the ramp of sec. 4.1.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from abu_model.errors import ParameterError
from abu_model.params import PlantParams, check_finite
from abu_model.tracking_response import alpha_derivatives, response
from controller.drive import Drive
from controller.profile import Profile

from harness.experiments.bounds import (ExperimentResult, _finish_summary, _switches, _table,
                                        friction_bounds)
from harness.experiments.fmu_files import ensure_fmus
from harness.experiments.plant_alone import ball_fields, plant_alone
from harness.cosim.reuse import run_system
from harness.cosim.system import Source, System

#: Time simulated before the profile's first knot (steady state) [s].
PRE_ROLL = 0.05
#: Default communication step [s]: the torque is a third-order Taylor polynomial over it.
COMM_STEP = 2e-4


@dataclass(frozen=True)
class ProfileExperiment:
    """A tracking drive following a profile, co-simulated on AbuBall.

    Attributes:
        plant: rotor and ball (its tau_motor is the drive's; ball_reaction must be off).
        drive: a ``tracking`` drive (bandwidth; its tau_motor must be the plant's).
        profile: the prescribed speed profile (times on the simulation clock).
        t_end: end of the simulation [s] (None: the last knot + PRE_ROLL).
        comm_step: fixed communication step [s].
        beta0: initial ball angle [rad].
    """

    plant: PlantParams
    drive: Drive
    profile: Profile
    t_end: float | None = None
    comm_step: float = COMM_STEP
    beta0: float = 0.0

    def __post_init__(self) -> None:
        if not self.drive.is_tracking:
            raise ParameterError("--drive", self.drive.source, "a drive of model 'tracking'")
        if self.plant.ball_reaction:
            raise ParameterError("--ball-reaction", True, "off with --motion profile (the "
                                 "loop's motion is exact only for a rotor that does not feel "
                                 "the ball, the report's model)")
        if abs(self.plant.tau_motor - self.drive.tau_motor) > 1e-15:
            raise ParameterError("--tau-motor", self.plant.tau_motor,
                                 f"the drive's tau_motor_s {self.drive.tau_motor:g} s")
        check_finite("beta0", self.beta0)
        if not (math.isfinite(self.comm_step) and 0 < self.comm_step <= 0.01):
            raise ParameterError("--comm-step", self.comm_step, "a step in (0, 0.01] s")
        if self.t_end is not None and not (math.isfinite(self.t_end)
                                           and self.t_end > self.t_start):
            raise ParameterError("--t-end", self.t_end, f"a time after the start "
                                 f"{self.t_start:g} s")

    @property
    def t_start(self) -> float:
        return min(0.0, self.profile.times[0] - PRE_ROLL)

    @property
    def stop(self) -> float:
        return self.profile.times[-1] + PRE_ROLL if self.t_end is None else float(self.t_end)

    def torque_sources(self) -> tuple[Source, ...]:
        """T_cmd = J_total (alpha + tau alpha') and its first three derivatives as sources."""
        wb, tau, J = float(self.drive.bandwidth), self.plant.tau_motor, self.plant.J_total
        memo: dict[float, np.ndarray] = {}

        def derivs(t: float) -> np.ndarray:
            if t not in memo:
                memo.clear()
                d = alpha_derivatives(self.profile, np.array([t]), wb, tau, order=4)[:, 0]
                memo[t] = J * (d[:4] + tau * d[1:5])
            return memo[t]

        names = ("torque", "torque_rate", "torque_accel", "torque_jerk")
        return tuple(Source(f"plant.{n}", (lambda k: lambda t: float(derivs(t)[k]))(k))
                     for k, n in enumerate(names))

    def system(self, fmus: Mapping[str, Path]) -> System:
        """AbuBall alone, the loop's exact torque as its sources."""
        r = response(self.profile, np.array([self.t_start]), float(self.drive.bandwidth),
                     self.plant.tau_motor)
        return plant_alone(self.plant, fmus["AbuBall"], float(r.omega[0]), self.beta0,
                           self.torque_sources())

    def as_dict(self) -> dict[str, Any]:
        return {"motion": "profile", **ball_fields(self.plant),
                "bandwidth_rad_s": self.drive.bandwidth, "t_start_s": self.t_start,
                "t_end_s": self.stop, "comm_step_s": self.comm_step, "beta0_rad": self.beta0,
                "profile": {"time_s": list(self.profile.times),
                            "omega_rad_s": list(self.profile.omegas)}}


def run_profile(exp: ProfileExperiment, fmu_dir: Any = None, progress: bool = False,
                reuse: bool = True) -> ExperimentResult:
    """Co-simulate the tracking drive and estimate mu at the slip (eq. 4.1/4.2)."""
    fmus = ensure_fmus(fmu_dir)
    res = run_system(exp.system(fmus), exp.t_start, exp.stop, exp.comm_step, progress=progress,
                     reuse=reuse)
    ref = response(exp.profile, res.time, float(exp.drive.bandwidth), exp.plant.tau_motor)
    table = _table(res, {"omega_ref": ref.omega_ref})
    switches = _switches(res, table)
    bounds = friction_bounds(table, switches)
    ball = exp.plant.ball
    summary: dict[str, Any] = {"experiment": exp.as_dict(), "mu": ball.mu, "switches": switches,
                               **bounds, "slips": bounds["t_slip"] is not None,
                               "mu_estimate": None, "t_restick": None}
    if bounds["t_slip"] is not None:
        w, a = bounds["omega_slip"], bounds["alpha_slip"]
        summary["mu_estimate"] = (ball.l - ball.d / 5.0) * abs(a) / (ball.l * w * w)
        restick = next((sw for sw in switches
                        if sw["time_s"] > bounds["t_slip"] and sw["to_mode"] == 0), None)
        summary["t_restick"] = None if restick is None else restick["time_s"]
        summary["message"] = (f"slip at t = {bounds['t_slip']:.9g} s: mu estimate "
                              f"{summary['mu_estimate']:.6g} (eq. 4.1/4.2)")
    else:
        summary["message"] = ("the ball never slips during the profile: mu_low is a lower "
                              "bound only")
    # the rotor against the loop's exact motion (a check of the torque sources and holds)
    summary["max_omega_error_rad_s"] = float(np.max(np.abs(table["omega"] - ref.omega)))
    return ExperimentResult(table, _finish_summary(summary, res), res)


__all__ = ["ProfileExperiment", "run_profile"]
