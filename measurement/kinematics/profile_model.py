"""omega and omega_dot from the known prescribed profile through the known tracking loop (SI).

A ``tracking`` drive (``drive.json``, :mod:`controller.drive`) follows a prescribed smooth
speed trajectory (``profile.json``, :mod:`controller.profile`) through the loop
G(s) = wb / (tau s^2 + s + wb). The ABU's motion over the whole record is then

    theta(t) = theta0 + c t + g Theta(t - t_off; wb, tau)

with Theta the loop's exact response to the profile (:mod:`abu_model.tracking_response`).
Only a few nuisance parameters are fitted: the time offset t_off of the camera's trigger to
the profile's clock (within +- ``t_off_max_s``), a gain g (speed sensor scale, 0.5-2), the
bandwidth wb (a Gaussian prior of its ``bandwidth_rad_s_ci95`` when the drive states one,
else free) and the lag tau (likewise; fitted only when the drive has a lag or states its
interval), beside the linear ones of the staircase model (theta0, a speed offset c, the
camera's harmonics of theta). The least squares, the covariance, the error bars and the
refusal when the residual shows the model is wrong are those of
:func:`measurement.kinematics.drive_model.fit_model`: the same machinery as the staircase's
PI loop (``--kinematics drive-model``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abu_model.tracking_response import response
from controller.drive import UPPER, Drive
from controller.profile import Profile

from measurement.kinematics.model_fit import (DriveFit, DriveModelSettings, LastEvaluation,
                                              fit_model, forward_jacobian)
from measurement.kinematics.estimators import noise_sigma, sample_interval

#: the gain's fitted range [-]
GAIN_RANGE = (0.5, 2.0)
# The whiteness test's blocks (8, 32, 128 ms) and rms limit (1.5x) are the drive model's
# defaults (measurement.kinematics.drive_model), first chosen here: at the profile's speeds
# (up to 40 Hz, the markers cross several pixels a frame) the tracker's noise is correlated
# over a few frames, which 2 ms blocks (9 frames) flag although the model is right (seed 105
# of bench_profile_drive: fitted bandwidth, lag, gain and offset all at the truth, refused at
# 2 ms only), and which makes the noise estimate low (seed 107: rms 1.2504 x with every
# parameter at the truth and white blocks); a wrong loop or a torque ripple shows over 8 ms
# and longer.
Z95 = 1.959964


class _ProfileModel(LastEvaluation):
    """theta, omega, omega_dot of the profile through the parametrised loop."""

    def __init__(self, time: np.ndarray, drive: Drive, profile: Profile,
                 settings: DriveModelSettings):
        self.t, self.profile = time, profile
        self.names = ["t_off_s", "gain"]
        self.x0 = [0.0, 1.0]
        self.lo = [-settings.t_off_max_s, GAIN_RANGE[0]]
        self.hi = [settings.t_off_max_s, GAIN_RANGE[1]]
        self.prior: list[tuple[int, float, float]] = []
        self.fixed_tau = float(drive.tau_motor)
        loop = [("bandwidth_rad_s", float(drive.bandwidth), 1e-2)]
        if drive.tau_motor > 0 or "tau_motor_s" in drive.ci95:
            loop.append(("tau_motor_s", float(drive.tau_motor), 0.0))
        for name, value, low in loop:
            ci = drive.ci95.get(name)
            if ci is not None and not settings.free_loop:
                self.prior.append((len(self.names), 0.5 * (ci[0] + ci[1]),
                                   max((ci[1] - ci[0]) / (2 * Z95), 1e-9)))
            self.names.append(name)
            self.x0.append(max(value, low + 1e-6))
            self.lo.append(low)
            self.hi.append(UPPER[name])

    def _evaluate(self, p: np.ndarray, need_theta: bool = True):
        """(g Theta, g omega, g omega_dot) of the loop alone at the frame times."""
        tau = p[3] if len(p) > 3 else self.fixed_tau
        r = response(self.profile, self.t - p[0], p[2], tau, gain=p[1])
        return (r.theta if need_theta else None), r.omega, r.alpha

    def theta_jacobian(self, p: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
        """d (g Theta) / d p: the time offset's column (-g omega) and the gain's (Theta) in
        closed form, the loop's by forward differences."""
        theta, omega, _ = self.evaluate(p)
        return forward_jacobian(self, p, lo, hi, {0: -omega, 1: theta / p[1]})


def fit_profile_model(time: np.ndarray, theta: np.ndarray, drive: Drive, profile: Profile, *,
                      sigma_theta: float | None = None,
                      settings: DriveModelSettings | None = None) -> DriveFit:
    """Fit the known profile through the known loop to theta(t) (see the module doc)."""
    st = settings or DriveModelSettings()
    t = np.asarray(time, dtype=float)
    th = np.asarray(theta, dtype=float)
    sample_interval(t)
    if not drive.is_tracking:
        return DriveFit(False, f"the drive is a {drive.model} loop, not a tracking one: a "
                               "profile needs a drive.json of model 'tracking'")
    sigma = noise_sigma(th) if sigma_theta is None else float(sigma_theta)
    if not sigma > 0:
        return DriveFit(False, "the tracking noise of theta is zero (cannot weight the fit)")
    slope = float(np.polyfit(t, th, 1)[0])
    if np.sign(slope) != np.sign(profile.omegas[0]):
        return DriveFit(False, f"the record turns at {slope:.4g} rad/s on average, the "
                               f"profile at {profile.omegas[0]:.4g} rad/s: not the same "
                               "direction")
    return fit_model(t, th, _ProfileModel(t, drive, profile, st), sigma, st)


@dataclass(frozen=True)
class ProfileModelInput:
    """What the profile kinematics need: the tracking drive, its profile (times on the
    record's clock) and the fit's settings."""

    drive: Drive
    profile: Profile
    settings: DriveModelSettings = field(default_factory=DriveModelSettings)
    #: the fit's linear basis holds theta's harmonics 1-3 (the camera's fixed pattern: lens,
    #: eccentric axis), so a lens harmonic does not pass into omega_dot: the analysis drops
    #: its lens prior (``theta_harmonic_rad``) for these kinematics (measured:
    #: benchmarks/bench_profile_drive.py)
    theta_harmonics_fitted: bool = True

    def fit(self, time: np.ndarray, theta: np.ndarray, sigma_theta: float | None) -> DriveFit:
        """The fit of this drive following this profile."""
        return fit_profile_model(time, theta, self.drive, self.profile,
                                 sigma_theta=sigma_theta, settings=self.settings)


__all__ = ["ProfileModelInput", "fit_profile_model", "GAIN_RANGE"]
