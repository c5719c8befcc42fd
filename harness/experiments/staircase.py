"""The report's simulated experiments as FMI co-simulations (report ch. 4).

* :class:`StaircaseExperiment` / :func:`run_staircase` (sec. 4.2): Staircase -> SpeedController
  -> AbuBall in closed loop; the friction bounds mu_low <= mu < mu_high from the run.
* :class:`RampExperiment` / :func:`run_ramp` (sec. 4.1): AbuBall alone, driven by a torque
  that makes the rotor's acceleration grow linearly; the slip point and eq. 4.1/4.2.

Everything is SI (rad, rad/s, s, kg, m); the command line converts Hz at its boundary.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping

from abu_model.errors import ParameterError
from abu_model.params import PlantParams, check_finite
from controller.pi import PISpeedController
from controller.reference import ROUNDINGS, Staircase

from harness.experiments.bounds import (BRACKET_RTOL, SUMMARY_UNITS, UNITS, ExperimentResult,  # noqa: F401
                     _finish_summary, _switches, _table, friction_bounds)
from harness.experiments.fmu_files import FMU_FILES, ensure_fmus  # noqa: F401
from harness.experiments.fmu_files import has_input as _has_input
from harness.cosim.reuse import run_system
from harness.cosim.system import Component, Connection, Hold, Source, System
from harness.experiments.plant_alone import (_plant_parameters, _plant_probes, ball_fields,
                                             plant_alone)


#: Time simulated before the first setpoint step so that the steady state and both limits of
#: the first step are in the table [s].
PRE_ROLL = 0.05



#: The plant's inputs T, T', T'', ... and outputs alpha, alpha', alpha'', ... of a Taylor
#: hold (the SpeedController has the same names the other way round).
_TORQUE_DERIVATIVES = ("torque", "torque_rate", "torque_accel", "torque_jerk", "torque_snap")
_ALPHA_DERIVATIVES = ("alpha", "jerk", "snap", "crackle")
#: Default order of the torque's Taylor hold in the staircase (the FMUs support up to 4).
HOLD_ORDER = 4

def _check_stepping(exp: Any) -> None:
    """comm_step and tol of an experiment: None or finite and > 0."""
    for name, expected in (("comm_step", "a communication step > 0 s"),
                           ("tol", "a coupling error tolerance > 0")):
        value = getattr(exp, name)
        if value is not None:
            value = check_finite(name, value)
            if value <= 0.0:
                raise ParameterError(name, value, expected)
            object.__setattr__(exp, name, value)


def _effective_tol(exp: Any) -> float | None:
    """The tolerance the master uses (None: fixed steps)."""
    from harness.cosim.stepping import DEFAULT_TOL
    if exp.tol is not None:
        return exp.tol
    return DEFAULT_TOL if exp.comm_step is None else None


# ---------------------------------------------------------------------------- staircase
@dataclass(frozen=True)
class StaircaseExperiment:
    """The closed-loop staircase experiment of report sec. 4.2 (SI units).

    Attributes:
        plant: rotor and ball parameters (mu is the "true" friction coefficient).
        omega0: initial speed and setpoint [rad/s] (steady rotation, ball stuck).
        omega_end: end of the inclined sine [rad/s].
        t0: start of the inclined sine (first step with ``lead`` rounding) [s].
        te: duration of the inclined sine [s] (> 0).
        t_end: end of the simulation [s]; None: t0 + te + 0.5 s.
        step: setpoint resolution [rad/s] (2 pi = 1 Hz).
        rounding: ``lead`` (report), ``nearest`` or ``trail``.
        theta_ref_mode: ``integral`` (physical PI) or ``thesis`` (theta_ref = t w_ref).
        zeta, omega_n: identified closed loop [-], [rad/s].
        comm_step: fixed communication step [s] (> 0) when ``tol`` is None; the first step
            with ``tol``; None (default) with ``tol`` None: error control at the master's
            default tolerance.
        beta0: initial ball angle relative to the ABU [rad].
        t_start: start of the simulation [s]; None: min(0, t0 - 0.05 s), so that the table
            holds the steady state and both limits of the first step.
        tol: coupling error tolerance [-] of the error-controlled steps (None: see comm_step).
        hold_order: order of the torque's Taylor hold, 1..4 (None: :data:`HOLD_ORDER`).
    """

    plant: PlantParams
    omega0: float
    omega_end: float
    t0: float = 0.0
    te: float = 1.0
    t_end: float | None = None
    step: float = 2.0 * math.pi
    rounding: str = "lead"
    theta_ref_mode: str = "integral"
    zeta: float = 0.5
    omega_n: float = 2.2
    comm_step: float | None = None
    beta0: float = 0.0
    t_start: float | None = None
    tol: float | None = None
    hold_order: int | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.plant, PlantParams):
            raise ParameterError("plant", self.plant, "a PlantParams instance")
        if self.hold_order is not None and (type(self.hold_order) is not int
                                            or self.hold_order not in (1, 2, 3, 4)):
            # an int (2.0 or True would pass the range test and fail as an index later)
            raise ParameterError("hold_order", self.hold_order, "1, 2, 3 or 4 (or None)")
        for name in ("omega0", "omega_end", "t0", "te", "step", "zeta", "omega_n", "beta0"):
            object.__setattr__(self, name, check_finite(name, getattr(self, name)))
        _check_stepping(self)
        if self.rounding not in ROUNDINGS:
            raise ParameterError("rounding", self.rounding, f"one of {', '.join(ROUNDINGS)}")
        self.staircase  # validates te, step, omega_end (at least one step)
        self.controller  # validates zeta, omega_n, theta_ref_mode
        t_start = (min(0.0, self.t0 - PRE_ROLL) if self.t_start is None
                   else check_finite("t_start", self.t_start))
        if t_start > self.t0:
            raise ParameterError("t_start", self.t_start, f"a time <= t0 = {self.t0:g} s")
        object.__setattr__(self, "t_start", t_start)
        t_end = self.t0 + self.te + 0.5 if self.t_end is None else check_finite("t_end", self.t_end)
        if t_end <= t_start:
            raise ParameterError("t_end", self.t_end, f"a time > the start {t_start:g} s")
        object.__setattr__(self, "t_end", t_end)
        if self.omega0 == 0.0:
            raise ParameterError("omega0", self.omega0, "a non-zero speed (no normal force at "
                                 "rest: the ball cannot stick)")

    @property
    def staircase(self) -> Staircase:
        """The setpoint staircase (exact step times)."""
        return Staircase(self.omega0, self.omega_end, self.t0, self.te, self.step, self.rounding)

    @property
    def controller(self) -> PISpeedController:
        """The PI speed law (gains scaled with the plant's J_abu)."""
        return PISpeedController(self.zeta, self.omega_n, self.plant.J_abu, self.theta_ref_mode)

    def system(self, fmus: Mapping[str, Path]) -> System:
        """The co-simulated system: Staircase -> SpeedController <-> AbuBall.

        The torque is held as its Taylor polynomial of order ``hold_order`` (default
        :data:`HOLD_ORDER`; lower if the FMUs lack the inputs): the controller's torque,
        torque_rate, torque_accel, torque_jerk, ... feed the plant, the plant's alpha, jerk,
        snap, ... feed the controller, whose integrator sees omega to the same order. The
        holds' scales are one setpoint step [rad/s] and its torque jump J_total 2 zeta wn
        step [N m].
        """
        plant = _plant_parameters(self.plant)
        plant.update(theta0=self.omega0 * self.t_start, omega0=self.omega0, beta0=self.beta0,
                     beta_dot0=0.0)
        order = HOLD_ORDER if self.hold_order is None else self.hold_order  # 1..4, checked
        while order > 1 and not (_has_input(fmus["AbuBall"], _TORQUE_DERIVATIVES[order])
                                 and _has_input(fmus["SpeedController"],
                                                _ALPHA_DERIVATIVES[order - 1])):
            order -= 1  # older FMUs: the highest order both have
        extra = tuple(Connection(f"plant.{_ALPHA_DERIVATIVES[k]}", f"ctrl.{_ALPHA_DERIVATIVES[k]}")
                      for k in range(1, order)) + tuple(
            Connection(f"ctrl.{_TORQUE_DERIVATIVES[k]}", f"plant.{_TORQUE_DERIVATIVES[k]}")
            for k in range(2, order + 1))
        torque_scale = self.plant.J_total * 2.0 * self.zeta * self.omega_n * abs(self.step)
        holds = (Hold("ctrl.torque", tuple(f"ctrl.{n}" for n in _TORQUE_DERIVATIVES[1:order + 1]),
                      torque_scale),
                 Hold("plant.omega", tuple(f"plant.{n}" for n in _ALPHA_DERIVATIVES[:order]),
                      abs(self.step)))
        return System(
            components=(
                Component("ref", fmus["Staircase"], {
                    "omega0": self.omega0, "omega_end": self.omega_end, "t0": self.t0,
                    "te": self.te, "step": self.step, "rounding": ROUNDINGS.index(self.rounding)}),
                Component("ctrl", fmus["SpeedController"], {
                    "zeta": self.zeta, "omega_n": self.omega_n, "J_abu": self.plant.J_abu,
                    "theta_ref_mode": ("integral", "thesis").index(self.theta_ref_mode),
                    "x_I0": 0.0}),
                Component("plant", fmus["AbuBall"], plant),
            ),
            connections=(
                Connection("ref.omega_ref", "ctrl.omega_ref"),
                Connection("plant.omega", "ctrl.omega"),
                Connection("plant.theta", "ctrl.theta"),
                Connection("plant.alpha", "ctrl.alpha"),
                Connection("ctrl.torque", "plant.torque"),
                Connection("ctrl.torque_rate", "plant.torque_rate"),
            ) + extra,
            probes={"omega_ref": "ref.omega_ref", "torque": "ctrl.torque",
                    **_plant_probes(fmus["AbuBall"])},
            holds=holds,
        )

    def as_dict(self) -> dict[str, Any]:
        """The settings, JSON-ready (SI; keys with units)."""
        b = self.plant.ball
        return {"motion": "staircase", "mu": b.mu, "mu_d": b.mu_dynamic, "m_kg": b.m, "d_m": b.d,
                "l_m": b.l, "J_abu_kg_m2": self.plant.J_abu, "tau_motor_s": self.plant.tau_motor,
                "ball_reaction": self.plant.ball_reaction, "omega0_rad_s": self.omega0,
                "omega_end_rad_s": self.omega_end, "t0_s": self.t0, "te_s": self.te,
                "t_start_s": self.t_start, "t_end_s": self.t_end, "step_rad_s": self.step,
                "rounding": self.rounding, "theta_ref_mode": self.theta_ref_mode,
                "zeta": self.zeta, "omega_n_rad_s": self.omega_n, "comm_step_s": self.comm_step,
                "tol": _effective_tol(self), "beta0_rad": self.beta0,
                "hold_order": HOLD_ORDER if self.hold_order is None else self.hold_order,
                "step_times_s": list(self.staircase.step_times)}


def run_staircase(exp: StaircaseExperiment, fmu_dir: Any = None,
                  progress: bool = False, reuse: bool = True) -> ExperimentResult:
    """Co-simulate the staircase experiment and compute the friction bounds.

    ``reuse``: take loaded FMU instances of an earlier run of the same structure and reset
    them (``fmi2Reset``, see :mod:`harness.cosim.reuse`) instead of loading new ones.
    """
    fmus = ensure_fmus(fmu_dir)
    system = exp.system(fmus)
    res = run_system(system, exp.t_start, exp.t_end, exp.comm_step, tol=exp.tol,
                     progress=progress, reuse=reuse)
    table = _table(res)
    switches = _switches(res, table)
    step_times = exp.staircase.step_times
    first_step = next((ts for ts in step_times if ts > exp.t_start), None)
    bounds = friction_bounds(table, switches, first_step=first_step)
    mu = exp.plant.ball.mu
    summary: dict[str, Any] = {"experiment": exp.as_dict(), **bounds, "mu": mu,
                               "switches": switches, "slips": bounds["t_slip"] is not None}
    # the order used, not the one asked for: FMUs without the higher inputs lower it
    summary["experiment"]["hold_order"] = len(system.holds[0].derivatives)
    summary["end_on_setpoint_step"] = any(abs(exp.t_end - ts) <= 1e-9 for ts in step_times)
    if bounds["t_slip"] is None:
        summary["brackets_mu"] = bool(bounds["mu_low"] <= mu * (1 + BRACKET_RTOL))
        if summary["end_on_setpoint_step"]:
            summary["message"] = (
                f"no slip before t_end = {exp.t_end:.6g} s, which falls on a setpoint step: the "
                "step itself is not simulated, so whether it makes the ball slip is open; mu_low "
                "is a lower bound from the stick period before it (mu_high and t_slip are null); "
                "extend t_end past the step to decide")
        else:
            summary["message"] = ("the ball never slips: mu_low is a lower bound only "
                                  "(mu_high and t_slip are null)")
    else:
        at_step = any(abs(bounds["t_slip"] - ts) <= 1e-9 for ts in step_times)
        summary["slip_at_setpoint_step"] = at_step
        if bounds["mu_low"] is None:
            summary["brackets_mu"] = bool(bounds["mu_high"] >= mu * (1 - BRACKET_RTOL))
            summary["message"] = (
                f"the ball slips at the first setpoint step (t = {bounds['t_slip']:.6g} s): there "
                "was no stick period with an acceleration, so there is no lower bound (mu_low is "
                f"null), only mu < mu_high = {bounds['mu_high']:.4g}; start the staircase at a "
                "higher |omega0| (or use smaller steps) to get one")
        else:
            # at a continuous slip mu_low = mu_high = mu up to rounding: compare with a tolerance
            summary["brackets_mu"] = bool(bounds["mu_low"] <= mu * (1 + BRACKET_RTOL)
                                          and bounds["mu_high"] >= mu * (1 - BRACKET_RTOL))
            summary["message"] = (f"mu_low = {bounds['mu_low']:.4g} <= mu < mu_high = "
                                  f"{bounds['mu_high']:.4g} (slip at t = {bounds['t_slip']:.6g} s)")
    return ExperimentResult(table, _finish_summary(summary, res), res)


# ---------------------------------------------------------------------------- ramp
@dataclass(frozen=True)
class RampExperiment:
    """Prescribed motion of report sec. 4.1: alpha(t) = sign(omega0) K t from steady rotation.

    The rotor is driven by the external torque T = J_total K sign(omega0) t (first-order held
    through the plant's torque_rate input), which with tau_motor = 0 gives exactly
    alpha = sign(omega0) K t while the ball sticks, and omega = omega0 + sign(omega0) K t^2/2.

    Attributes:
        plant: rotor and ball parameters.
        omega0: initial speed [rad/s] (non-zero).
        jerk: K, growth rate of |alpha| [rad/s^3] (> 0).
        t_end: end of the simulation [s] (> 0).
        comm_step: fixed communication step [s] (> 0) when ``tol`` is None; the first step
            with ``tol``; None with ``tol`` None: error control at the default tolerance.
        beta0: initial ball angle [rad].
        tol: coupling error tolerance [-] (the ramp's sources are exact: steps grow to the
            master's largest step; switches are located exactly by the plant).
    """

    plant: PlantParams
    omega0: float
    jerk: float
    t_end: float
    comm_step: float | None = None
    beta0: float = 0.0
    tol: float | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.plant, PlantParams):
            raise ParameterError("plant", self.plant, "a PlantParams instance")
        for name in ("omega0", "jerk", "t_end", "beta0"):
            object.__setattr__(self, name, check_finite(name, getattr(self, name)))
        if self.omega0 == 0.0:
            raise ParameterError("omega0", self.omega0, "a non-zero speed [rad/s]")
        if self.jerk <= 0.0:
            raise ParameterError("jerk", self.jerk, "a jerk K > 0 rad/s^3")
        if self.t_end <= 0.0:
            raise ParameterError("t_end", self.t_end, "a time > 0 s")
        _check_stepping(self)

    @property
    def torque_slope(self) -> float:
        """dT/dt = J_total K sign(omega0) [N m/s]."""
        return self.plant.J_total * self.jerk * math.copysign(1.0, self.omega0)

    def system(self, fmus: Mapping[str, Path]) -> System:
        """AbuBall alone with the torque ramp and its rate as sources."""
        slope = self.torque_slope
        return plant_alone(self.plant, fmus["AbuBall"], self.omega0, self.beta0,
                           (Source("plant.torque", lambda t: slope * t),
                            Source("plant.torque_rate", lambda t: slope)))

    def as_dict(self) -> dict[str, Any]:
        return {"motion": "ramp", **ball_fields(self.plant),
                "ball_reaction": self.plant.ball_reaction, "omega0_rad_s": self.omega0,
                "jerk_rad_s3": self.jerk, "t_end_s": self.t_end, "comm_step_s": self.comm_step,
                "tol": _effective_tol(self), "beta0_rad": self.beta0}


def run_ramp(exp: RampExperiment, fmu_dir: Any = None, progress: bool = False,
             reuse: bool = True) -> ExperimentResult:
    """Co-simulate the prescribed-acceleration ramp and estimate mu at the slip (eq. 4.1/4.2)."""
    fmus = ensure_fmus(fmu_dir)
    # The ramp's sources are exact (no coupling error, no holds to declare): error control
    # then lets the steps grow to the largest step; the plant locates the switches exactly.
    res = run_system(exp.system(fmus), 0.0, exp.t_end, exp.comm_step, tol=_effective_tol(exp),
                     progress=progress, reuse=reuse)
    s = math.copysign(1.0, exp.omega0)
    omega_ref = exp.omega0 + s * exp.jerk * res.time**2 / 2.0  # the prescribed speed
    table = _table(res, {"omega_ref": omega_ref})
    switches = _switches(res, table)
    bounds = friction_bounds(table, switches)
    ball = exp.plant.ball
    summary: dict[str, Any] = {"experiment": exp.as_dict(), "mu": ball.mu, "switches": switches,
                               "t_slip": bounds["t_slip"], "omega_slip": bounds["omega_slip"],
                               "alpha_slip": bounds["alpha_slip"], "slips": False,
                               "mu_estimate": None, "t_restick": None}
    if bounds["t_slip"] is not None:
        w, a = bounds["omega_slip"], bounds["alpha_slip"]
        summary["slips"] = True
        summary["mu_estimate"] = (ball.l - ball.d / 5.0) * abs(a) / (ball.l * w * w)
        restick = next((sw for sw in switches
                        if sw["time_s"] > bounds["t_slip"] and sw["to_mode"] == 0), None)
        summary["t_restick"] = None if restick is None else restick["time_s"]
        summary["message"] = (f"slip at t = {bounds['t_slip']:.9g} s: mu estimate "
                              f"{summary['mu_estimate']:.6g} (eq. 4.1/4.2)")
    else:
        summary["message"] = "the ball never slips within t_end: no estimate"
    episodes = sum(1 for sw in switches if sw["from_mode"] == 0)
    summary["slip_episodes"] = episodes
    return ExperimentResult(table, _finish_summary(summary, res), res)


def with_plant(exp: StaircaseExperiment | RampExperiment, **changes: Any):
    """A copy of ``exp`` with plant parameters changed (e.g. ``mu=...``, ``tau_motor=...``)."""
    ball_fields = {"m", "d", "l", "mu", "mu_d"}
    ball = exp.plant.ball.with_(**{k: v for k, v in changes.items() if k in ball_fields})
    plant = replace(exp.plant, ball=ball,
                    **{k: v for k, v in changes.items() if k not in ball_fields})
    return replace(exp, plant=plant)
