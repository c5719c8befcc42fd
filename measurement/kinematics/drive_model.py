"""omega and omega_dot from a physical model of the drive fitted to the whole record (SI).

Where the drive is known (an identified closed speed loop, ``drive.json`` of ``abu identify``,
driven by a known setpoint staircase), the ABU's motion over the whole record is

    theta(t) = theta0 + c t + Theta(t - t_off; zeta, omega_n, tau, b[, tau_f])

with Theta the loop's exact response to the staircase (:mod:`abu_model.loop_response`), t_off
the record's time offset to the staircase (the camera's trigger) and c a constant speed offset
[rad/s]. A drive.json with ``setpoint_tau_s`` adds its first-order setpoint filter (time
constant tau_f, fitted like the loop's parameters); one with ``sample_time_s`` (a digital
controller) moves each step onto the controller's first sample at or after it
(:func:`abu_model.loop_response.sampled`). On the harsh twin's digital PI drives (frame-rate
controller, setpoint filters in 60 %) these two were what kept the residual from being white
(``benchmarks/bench_drive_model.py``). The unknowns are fitted by nonlinear least squares on
the tracked theta, weighted by the tracking noise sigma_theta; a loop parameter with a 95 %
interval in the drive file gets a Gaussian prior of that width, one without is free (within the
physical range of :data:`controller.drive.UPPER`). omega(t) and omega_dot(t) come from the
fitted model, their standard errors from the parameter covariance (the Jacobian, scaled up by
the reduced chi-square when it exceeds 1) propagated through the model, with two floors:
``error_rel`` of |omega_dot|, and half omega_dot's change over +- one controller sample
(everywhere for a digital controller, within a frame of the steps for a continuous one): a
sampled controller acts like a part-sample delay that right after a step need not be the
record's time offset, and a torque lag of a fraction of a frame and a delay look alike in theta
while omega_dot jumps.

The least squares, the error bars, the whiteness tests and the fallback are
:mod:`measurement.kinematics.model_fit`'s (shared with the profile and the unknown loop).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from abu_model.loop_response import Setpoints, response, sampled
from controller.drive import UPPER, Drive

from measurement.kinematics.estimators import noise_sigma, sample_interval
from measurement.kinematics.model_fit import (STEP_BIN_S, STEP_WINDOW_S, DriveFit,
                                              DriveModelSettings, LastEvaluation, fit_model,
                                              forward_jacobian, linear_basis, solve)

#: loop parameters: (file name, Drive attribute, lower bound)
LOOP = (("zeta", "zeta", 1e-3), ("omega_n_rad_s", "omega_n", 1e-2),
        ("tau_motor_s", "tau_motor", 0.0), ("setpoint_weight", "setpoint_weight", 1e-3),
        ("setpoint_tau_s", "setpoint_tau", 0.0))
#: The timing bar on omega_dot (:meth:`LoopModel.step_sigma`) looks this many samples either side.
TIMING_SAMPLES = 1.0


def fitted_loop(params: dict[str, float], sample_time_s: float | None, source: str,
                min_tau_motor_s: float = 0.0) -> Drive:
    """The PI loop of a fit's parameters (names of :data:`LOOP`) as a start for another fit,
    digital with ``sample_time_s`` [s] (None: continuous). A setpoint filter fitted to 0
    starts just above it (1e-4 s), and the torque lag at ``min_tau_motor_s`` at least: at 0
    the model would drop the parameter, and the refit could not move it."""
    return Drive(model="pi-lag-weighted", zeta=params["zeta"],
                 omega_n=params["omega_n_rad_s"],
                 tau_motor=max(params.get("tau_motor_s", 0.0), min_tau_motor_s),
                 setpoint_weight=params.get("setpoint_weight", 1.0),
                 setpoint_tau=max(params.get("setpoint_tau_s", 0.0), 1e-4),
                 sample_time=sample_time_s, source=source)


@dataclass(frozen=True)
class DriveModelInput:
    """What the drive-model kinematics need: the identified loop, the staircase it was driven
    by (times on the record's clock, levels [rad/s]) and the fit's settings."""

    drive: Drive
    setpoints: Setpoints
    settings: DriveModelSettings = field(default_factory=DriveModelSettings)

    def fit(self, time: np.ndarray, theta: np.ndarray, sigma_theta: float | None) -> DriveFit:
        """The fit of this drive over this staircase."""
        return fit_drive_model(time, theta, self.drive, self.setpoints,
                               sigma_theta=sigma_theta, settings=self.settings)


class LoopModel(LastEvaluation):
    """theta, omega, omega_dot of the parametrised drive at the frame times: the model that
    :func:`~measurement.kinematics.model_fit.fit_model` fits (``names``, ``x0``, ``lo``, ``hi``,
    ``prior``, :meth:`evaluate`; :meth:`step_frames` and :meth:`step_sigma` for the tests and
    the error bars).

    The parameters are the time offset, then the loop's (:data:`LOOP`). A model with more
    (a staircase whose timing is fitted, :mod:`.staircase_search`) appends them with
    :meth:`add_parameter` and overrides :meth:`setpoints_for`: everything here reads the
    loop's values by name and the staircase through that hook.
    """

    def __init__(self, time: np.ndarray, drive: Drive, setpoints: Setpoints,
                 settings: DriveModelSettings, t_off_s: float = 0.0):
        self.t, self.sp = time, sampled(setpoints, drive.sample_time)
        self.sample_time = drive.sample_time
        self.names = ["t_off_s"]
        self.x0 = [t_off_s]
        self.lo = [-settings.t_off_max_s]
        self.hi = [settings.t_off_max_s]
        self.prior: list[tuple[int, float, float]] = []   # (index, centre, sigma)
        for name, attr, low in LOOP:
            value = float(getattr(drive, attr))
            if name == "tau_motor_s" and drive.model == "second-order":
                continue
            if name == "setpoint_weight" and drive.model != "pi-lag-weighted":
                continue
            if name == "setpoint_tau_s" and not drive.has_setpoint_filter:
                continue   # the drive has no setpoint filter
            ci = drive.ci95.get(name)
            if ci is not None and not settings.free_loop:
                lo_ci, hi_ci = float(ci[0]), float(ci[1])
                self.prior.append((len(self.names), 0.5 * (lo_ci + hi_ci),
                                   max((hi_ci - lo_ci) / (2 * 1.959964), 1e-9)))
            self.names.append(name)
            if name == "setpoint_tau_s" and value == 0.0:   # declared by its interval alone
                value = float(np.mean(drive.ci95[name]))
            self.x0.append(max(value, low + 1e-6))
            self.lo.append(low)
            self.hi.append(UPPER[name])

    def add_parameter(self, name: str, x0: float, lo: float, hi: float) -> None:
        """One more fitted parameter (after the loop's), started at x0 within [lo, hi]."""
        self.names.append(name)
        self.x0.append(x0)
        self.lo.append(lo)
        self.hi.append(hi)

    def setpoints_for(self, p: np.ndarray) -> Setpoints:
        """The staircase (as the controller applies it) at the parameters p: fixed here."""
        return self.sp

    def step_frames(self, p: np.ndarray) -> tuple[np.ndarray, int]:
        """Frame index of each step's first frame (steps with a whole window in the record)
        and the window length [frames] of the step-locked whiteness test."""
        dt = float(self.t[1] - self.t[0])
        steps = np.asarray(self.setpoints_for(p).step_times, float) + p[0]
        gap = float(np.min(np.diff(steps))) if steps.size > 1 else STEP_WINDOW_S
        n_bin = max(1, int(round(STEP_BIN_S / dt)))
        window = n_bin * max(0, int(min(gap, STEP_WINDOW_S) / dt) // n_bin)
        first = np.searchsorted(self.t, steps, side="left")
        return first[(steps >= self.t[0]) & (first + window <= self.t.size)], window

    def step_sigma(self, p: np.ndarray) -> np.ndarray:
        """A timing bar on omega_dot [rad/s^2]: half its change over +- one sample time of a
        digital controller (everywhere), or +- one frame within one frame of a step (a
        continuous one). Sampled, the controller acts like a delay of part of a sample that
        differs from the whole record's time offset right after a step, where omega_dot
        changes fastest (and jumps with a torque lag of a fraction of a frame: a lag that
        short and a delay look alike in theta)."""
        dt = float(self.t[1] - self.t[0])
        delta = TIMING_SAMPLES * (self.sample_time or dt)
        near = np.ones(self.t.size, bool)
        sp = self.setpoints_for(p)
        steps = np.asarray(sp.step_times, float) + p[0]
        if not self.sample_time:
            k = np.searchsorted(steps, self.t)
            left = steps[np.clip(k - 1, 0, steps.size - 1)]
            right = steps[np.minimum(k, steps.size - 1)]
            near = np.minimum(np.abs(self.t - left), np.abs(self.t - right)) < dt
        out = np.zeros_like(self.t)
        if near.any() and steps.size:
            zeta, wn, tau, b, tau_f = self.loop(p)
            tt = self.t[near] - p[0]
            up, down = (response(sp, tt + s_, zeta, wn, tau, b, False,
                                 setpoint_tau=tau_f).alpha for s_ in (delta, -delta))
            out[near] = 0.5 * np.abs(up - down)
        return out

    def loop(self, p: np.ndarray) -> tuple[float, float, float, float, float]:
        v = dict(zip(self.names[1:], p[1:]))
        return (v["zeta"], v["omega_n_rad_s"], v.get("tau_motor_s", 0.0),
                v.get("setpoint_weight", 1.0), v.get("setpoint_tau_s", 0.0))

    def _evaluate(self, p: np.ndarray, need_theta: bool = True):
        """(Theta, omega, omega_dot) of the loop alone (no linear terms) at the frame times."""
        zeta, wn, tau, b, tau_f = self.loop(p)
        r = response(self.setpoints_for(p), self.t - p[0], zeta, wn, tau, b, need_theta,
                     setpoint_tau=tau_f)
        return (r.theta if need_theta else None), r.omega, r.alpha

    def theta_jacobian(self, p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """d Theta / d p at the frame times: the time offset's column in closed form (-omega:
        Theta is a function of t - t_off), the others by forward differences
        (:func:`~measurement.kinematics.model_fit.forward_jacobian`)."""
        _, omega, _ = self.evaluate(p)
        return forward_jacobian(self, p, lo, hi, {0: -omega})


def fit_drive_model(time: np.ndarray, theta: np.ndarray, drive: Drive, setpoints: Setpoints, *,
                    sigma_theta: float | None = None,
                    settings: DriveModelSettings | None = None,
                    t_off_s: float = 0.0) -> DriveFit:
    """Fit the drive model to theta(t) over the whole record (see the module doc), the time
    offset started at ``t_off_s`` [s] (a warm start; 0: none known)."""
    st = settings or DriveModelSettings()
    t = np.asarray(time, dtype=float)
    th = np.asarray(theta, dtype=float)
    sample_interval(t)
    sigma = noise_sigma(th) if sigma_theta is None else float(sigma_theta)
    if not sigma > 0:
        return DriveFit(False, "the tracking noise of theta is zero (cannot weight the fit)")
    levels = np.asarray(setpoints.levels, float)
    slope = float(np.polyfit(t, th, 1)[0])
    if np.sign(slope) != np.sign(levels[0]) or np.any(np.sign(levels) != np.sign(levels[0])):
        return DriveFit(False, f"the record turns at {slope:.4g} rad/s on average, the "
                               f"staircase from {levels[0]:.4g} rad/s: not the same direction")
    return fit_model(t, th, LoopModel(t, drive, setpoints, st, t_off_s), sigma, st)


def start_cost(time: np.ndarray, theta: np.ndarray, drive: Drive, setpoints: Setpoints,
               settings: DriveModelSettings | None = None) -> float:
    """The residual sum of squares [rad^2] of ``drive`` over ``setpoints`` as it stands (no
    fit; the linear nuisance terms projected out, time offset 0): ranks starting loops of a
    free fit (:mod:`measurement.kinematics.unknown_loop`)."""
    st = settings or DriveModelSettings()
    t = np.asarray(time, dtype=float)
    th = np.asarray(theta, dtype=float)
    model = LoopModel(t, drive, setpoints, st)
    basis = linear_basis(t, th, st.harmonics)
    with np.errstate(over="ignore", invalid="ignore"):
        e = th - model.evaluate(np.array(model.x0, float))[0]
        r = e - basis @ np.linalg.lstsq(basis, e, rcond=None)[0]
        cost = float(r @ r)
    return cost if math.isfinite(cost) else math.inf


def quick_fit(time: np.ndarray, theta: np.ndarray, drive: Drive, setpoints: Setpoints,
              t_off_s: float, settings: DriveModelSettings, max_evaluations: int
              ) -> tuple[float, dict[str, float]]:
    """A short least-squares fit of the time offset and the loop (started at ``drive`` and
    ``t_off_s`` [s]; the linear nuisance terms projected out; no error bars, no tests): the
    mean square residual [rad^2] and the fitted values by name. Ranks candidate controller
    sample times of a loop fitted with another one
    (:mod:`measurement.kinematics.sample_time_search`): refitting the loop matters, as a loop
    fitted with one sample time has absorbed part of its step timing."""
    t = np.asarray(time, dtype=float)
    th = np.asarray(theta, dtype=float)
    model = LoopModel(t, drive, setpoints, settings, t_off_s)
    with np.errstate(over="ignore", invalid="ignore"):
        try:
            sol, _, _ = solve(t, th, model, 1.0, settings, max_evaluations)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            return math.inf, {}
        cost = float(np.mean(sol.fun[:t.size] ** 2))
    return (cost if math.isfinite(cost) else math.inf), dict(zip(model.names,
                                                                  sol.x.tolist()))
