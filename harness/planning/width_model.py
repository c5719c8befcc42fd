"""What ``abu measure`` will report for a planned run: its relative width, expected and 90 %
range.

Input: the planned kinematics of the ABU with the ball stuck on the camera's frame grid (time t,
theta(t), omega(t), omega_dot(t); any drive: a staircase through the identified loop or a
prescribed profile), the lever ratio (l - d/5)/l and the true mu of interest. The width is built
from what sets it in the measurement (``measurement.inference``, documented in
docs/measurement-analysis.md), each part computed from the plan:

* **the slip's emergence from beta's noise** (the profile likelihood's part). After onset the
  slip speed obeys u' = [omega^2 (q - mu_d) - mu_d |omega| (1 + lever) u] / 1.4 (q = mu_req,
  the ball re-sticks where u returns to 0); its deviation D(tau) = int u grows as tau^3 when
  mu_d = mu (q - mu grows linearly) and as tau^2 when mu_d < mu. The data tell a slip from
  noise once D reaches ``k_emerge`` sigma_beta, at tau; the onset is located to +- tau and the
  profile spans the running max of the measured q over [t_s - tau, t_s + tau]. The measured q
  is the Savitzky-Golay view of the plan (window and degree of ``abu measure``'s default
  estimator), so a staircase's steps are seen smoothed, as the measurement sees them. (The fit
  uses the whole slip, so ``k_emerge`` comes out well below 1.)
* **the kinematic noise at the slip**: the SG derivative filters' noise gains times theta's
  tracking noise, relative to omega_dot and omega at the slip; z sigma on the upper bound, the
  Rice sup quantile (about 3) on the lower one.
* **the estimator's truncation bound** (Richardson between the window and its half, as the
  estimator states it) and **the lens prior** A (omega^2 / |omega_dot| + 2), added linearly on
  both sides. At the slip omega^2 / |omega_dot| = lever / mu, so the lens part is
  2 A (lever / mu + 2) whatever the speed: a floor of the uncalibrated camera.

Free constants (:class:`WidthConstants`), calibrated on rendered designed runs
(``benchmarks/bench_designed_runs.py --calibrate``; the seeds and the fit are in
docs/design.md): the emergence threshold ``k_emerge``, beta's and theta's noise, the lower
bound's quantile and the factors of the 90 % range around the widths at mu_d / mu in [0.6, 1]
(the measurement does not know mu_d). Constants of ``abu measure`` duplicated here (harness does not import measurement):
the SG window 42 ms and degree 9, the lens prior 8e-4 rad, the confidence 95 %, the drive
model's discrepancy floor 1 %.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from abu_model.errors import ParameterError

#: ``abu measure``'s defaults (measurement.inference.options.AnalysisOptions,
#: measurement.inference.types.InferenceOptions), duplicated: harness does not import measurement.
SG_WINDOW_S = 0.042
SG_POLYORDER = 9
THETA_HARMONIC_RAD = 8e-4
Z95 = 1.959964
#: measurement.kinematics.model_fit.DriveModelSettings.error_rel, duplicated likewise
DRIVE_MODEL_ERROR_REL = 0.01
#: the kinematics ``abu measure`` can use (``--kinematics``)
KINEMATICS = ("savgol", "drive-model")
#: where the constants' camera noise and lens prior came from (``with_recorded_setup``)
SOURCES = ("typical", "summaries", "camera")
#: mu_d / mu spanned by the range (the measurement's profile; the twin's family draws 0.6-1)
MU_D_RATIOS = (0.6, 0.8, 1.0)


@dataclass(frozen=True)
class WidthConstants:
    """The width model's constants (SI; calibrated ones marked).

    Attributes:
        k_emerge: deviation of beta [in sigma_beta] at which a slip is told from noise
            (calibrated).
        sigma_beta_rad: beta's noise, tracking and lighting leftover, 1 sigma [rad]
            (calibrated: median over the calibration runs).
        sigma_theta_rad: theta's tracking noise, 1 sigma [rad] (median over the runs).
        range_log_low, range_log_high: ln of the factors below the smallest and above the
            largest width over mu_d / mu in [0.6, 1] that hold 5 % of the calibration runs
            each (calibrated): the 90 % range.
        z_low: quantile of the lower bound's kinematic noise (Rice sup quantile, typically 3).
        theta_harmonic_rad: ``abu measure``'s lens prior [rad] (0 with a calibrated camera
            that states none).
        sg_window_s, sg_polyorder: ``abu measure``'s Savitzky-Golay estimator.
        horizon_s: longest emergence followed after the onset [s].
        kinematics: the kinematics of the measurement predicted: ``"savgol"`` (the default
            estimator) or ``"drive-model"`` (the module doc).
        drive_model_error_rel: the drive model's discrepancy floor on omega_dot [1].
        noise_source, lens_source: where the camera noise and the lens prior came from:
            ``"typical"`` (these constants), ``"summaries"`` (:func:`with_recorded_setup`) or,
            for the lens, ``"camera"`` (a calibration file's prior, ``abu design --camera``).
        lens_note: how the lens prior was obtained, for the record ("" for the others).
    """

    k_emerge: float = 3.0
    sigma_beta_rad: float = 8e-4
    sigma_theta_rad: float = 1.5e-4
    range_log_low: float = -0.3
    range_log_high: float = 0.5
    z_low: float = 2.8
    theta_harmonic_rad: float = THETA_HARMONIC_RAD
    sg_window_s: float = SG_WINDOW_S
    sg_polyorder: int = SG_POLYORDER
    horizon_s: float = 0.2
    kinematics: str = "savgol"
    drive_model_error_rel: float = DRIVE_MODEL_ERROR_REL
    noise_source: str = "typical"
    lens_source: str = "typical"
    lens_note: str = ""

    def __post_init__(self) -> None:
        if self.kinematics not in KINEMATICS:
            raise ParameterError("kinematics", self.kinematics, " or ".join(KINEMATICS))
        for name in ("noise_source", "lens_source"):
            if getattr(self, name) not in SOURCES:
                raise ParameterError(name, getattr(self, name), " or ".join(SOURCES))
        if not (math.isfinite(self.theta_harmonic_rad) and self.theta_harmonic_rad >= 0):
            raise ParameterError("theta_harmonic_rad", self.theta_harmonic_rad,
                                 "a lens prior >= 0 rad")


#: The calibrated constants (docs/design.md, "Predicted width"): ``python
#: benchmarks/bench_designed_runs.py --calibrate ROWS`` on the 72 designed runs of seeds 0-71.
CALIBRATED = WidthConstants(k_emerge=0.0556, sigma_beta_rad=6.52e-4, sigma_theta_rad=2.14e-4,
                            z_low=2.80, range_log_low=-0.273, range_log_high=0.192)


#: Angles a summary may state as noise or lens prior are below this [rad]: tracking noise and
#: a lens harmonic are ~1e-4 rad; 0.1 rad is no camera's (a figure above is left out).
MAX_STATED_ANGLE_RAD = 0.1


def _numbers(values: list, low: float, low_ok: bool) -> list[float]:
    """The finite numbers of ``values`` above ``low`` (or at it, ``low_ok``) and below
    :data:`MAX_STATED_ANGLE_RAD`: what a summary states, anything else (missing, text,
    booleans, NaN, no camera's angle) left out."""
    return [float(x) for x in values
            if isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
            and (x > low or (low_ok and x == low)) and x < MAX_STATED_ANGLE_RAD]


def _field(obj: object, *keys: str) -> object:
    """obj[k1][k2]...; None where a level is missing or not an object."""
    for k in keys:
        if not isinstance(obj, dict):
            return None
        obj = obj.get(k)
    return obj


def with_recorded_setup(constants: WidthConstants, summaries: list[dict]) -> WidthConstants:
    """The constants of the set-up that ``abu measure`` summaries of earlier recordings show
    (medians over them; unchanged where the summaries lack a figure):

    * theta's and beta's noise of this camera and lighting (``noise.sigma_theta_rad``; beta:
      the model fit's white and leftover noise in quadrature);
    * the lens prior: ``camera.theta_harmonic_prior.theta_harmonic_rad`` of a summary measured
      with a calibrated camera (``--camera``), the family prior of one measured without;
    * the kinematics: ``"drive-model"`` where most summaries were measured with the drive
      model's kinematics accepted (``estimator.name``), else the default's.
    """
    th, be, lens, kin, calibrated = [], [], [], [], []
    for s in summaries:
        th.append(_field(s, "noise", "sigma_theta_rad"))
        white = _numbers([_field(s, "model_fit", "noise_model", "sigma_white_rad")], 0.0, True)
        left = _numbers([_field(s, "model_fit", "noise_model", "sigma_leftover_rad")], 0.0, True)
        if white:
            be.append(math.hypot(white[0], left[0] if left else 0.0))
        if isinstance(s.get("estimator"), dict):   # the measurement's own record of its set-up
            prior = _field(s, "camera", "theta_harmonic_prior", "theta_harmonic_rad")
            lens.append(THETA_HARMONIC_RAD if prior is None else prior)
            calibrated += _numbers([prior], 0.0, True)
            kin.append(s["estimator"].get("name") == "drive-model")
    th, be = _numbers(th, 0.0, False), _numbers(be, 0.0, False)
    lens = _numbers(lens, 0.0, True)
    return replace(
        constants,
        noise_source="summaries" if th or be else constants.noise_source,
        # a summary measured without a camera states the uncalibrated prior: still "typical"
        lens_source="summaries" if calibrated else constants.lens_source,
        sigma_theta_rad=float(np.median(th)) if th else constants.sigma_theta_rad,
        sigma_beta_rad=float(np.median(be)) if be else constants.sigma_beta_rad,
        theta_harmonic_rad=float(np.median(lens)) if lens else constants.theta_harmonic_rad,
        kinematics=("drive-model" if sum(kin) > len(kin) / 2 else "savgol") if kin
        else constants.kinematics)


@dataclass
class WidthPrediction:
    """Predicted ``abu measure`` relative width (hi - lo) / mid at each mu [-].

    Attributes:
        mu: the true mu values [-].
        t_slip_s: the planned slip time [s] (NaN: no slip in the record's trusted part).
        expected: width at mu_d / mu = 0.8 [-] (inf: a bound will be null).
        low90, high90: the 90 % range [-].
        profile, kinematic_noise, truncation, lens: the parts at mu_d / mu = 0.8: the beta
            profile's width and the relative kinematic errors at the slip (1 sigma noise,
            truncation bound, lens prior) [-].
    """

    mu: np.ndarray
    t_slip_s: np.ndarray
    expected: np.ndarray
    low90: np.ndarray
    high90: np.ndarray
    profile: np.ndarray
    kinematic_noise: np.ndarray
    truncation: np.ndarray
    lens: np.ndarray
    constants: WidthConstants = field(default_factory=WidthConstants)

    def row(self, i: int) -> dict[str, float | None]:
        """JSON-ready figures at mu[i] (None for a null bound)."""
        def f(x: float) -> float | None:
            return float(x) if math.isfinite(x) else None
        return {"mu": float(self.mu[i]), "t_slip_s": f(self.t_slip_s[i]),
                "expected": f(self.expected[i]), "low90": f(self.low90[i]),
                "high90": f(self.high90[i]), "profile": f(self.profile[i]),
                "kinematic_noise": f(self.kinematic_noise[i]),
                "truncation": f(self.truncation[i]), "lens": f(self.lens[i])}


def _sg_coeffs(window: int, polyorder: int, deriv: int, delta: float) -> np.ndarray:
    """Savitzky-Golay "dot" weights of the window's centre on positions scaled to [-1, 1]
    (as the measurement's estimator: SciPy's raw-offset weights lose accuracy at degree 9)."""
    m = window // 2
    u = np.arange(-m, m + 1) / m
    pinv = np.linalg.pinv(np.vander(u, polyorder + 1, increasing=True))
    return math.factorial(deriv) * pinv[deriv] / (m * delta) ** deriv


def _sg_views(theta: np.ndarray, h: float, c: WidthConstants
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, int]:
    """SG omega, omega_dot, truncation bound [rad/s^2] of the noise-free plan, the noise gains
    of omega and omega_dot [1/s, 1/s^2] and the half window [samples] (as the estimator)."""
    n = int(round(c.sg_window_s / h))
    n = max(n | 1, c.sg_polyorder + 2 + (c.sg_polyorder + 1) % 2)
    c1 = _sg_coeffs(n, c.sg_polyorder, 1, h)
    c2 = _sg_coeffs(n, c.sg_polyorder, 2, h)
    x = theta - theta[theta.size // 2]
    omega = np.correlate(x, c1, mode="same")
    alpha = np.correlate(x, c2, mode="same")
    half = max(int(round(0.5 * n)) | 1, c.sg_polyorder + 2 + (c.sg_polyorder + 1) % 2)
    c2h = _sg_coeffs(half, c.sg_polyorder, 2, h)
    pad = (n - half) // 2
    noise_diff = c.sigma_theta_rad * float(np.linalg.norm(c2 - np.pad(c2h, (pad, pad))))
    a_half = np.correlate(x, c2h, mode="same")
    bias = np.maximum(np.abs(alpha - a_half) - 3.0 * noise_diff, 0.0) * 3.0
    k = max(1, n // 4) | 1
    bias = np.lib.stride_tricks.sliding_window_view(np.pad(bias, k // 2, mode="edge"), k).max(1)
    return (omega, alpha, bias, float(np.linalg.norm(c1)), float(np.linalg.norm(c2)), n // 2)


def _deviation(q: np.ndarray, w2: np.ndarray, wa: np.ndarray, h: float, lever: float,
               start: np.ndarray, mu_d: np.ndarray, steps: int) -> np.ndarray:
    """Slip deviation D [rad] of lanes starting at ``start`` (indices) with ``mu_d``, over
    ``steps`` samples: (lanes, steps) (Heun's method at the frame interval, re-stick at 0)."""
    n = q.size
    u = np.zeros(start.size)
    d = np.zeros(start.size)
    out = np.empty((start.size, steps))
    for k in range(steps):
        out[:, k] = d
        i = np.minimum(start + k, n - 1)
        j = np.minimum(i + 1, n - 1)
        # Heun's step of u (the trapezoid on D): second order at the frame interval
        f0 = w2[i] * (q[i] - mu_d) - mu_d * wa[i] * (1.0 + lever) * u
        u1 = u + h * f0 / 1.4
        f1 = w2[j] * (q[j] - mu_d) - mu_d * wa[j] * (1.0 + lever) * u1
        u_new = np.maximum(u + 0.5 * h * (f0 + f1) / 1.4, 0.0)
        d += 0.5 * h * (u + u_new)
        u = u_new
    return out


def _timing_bar(t: np.ndarray, alpha: np.ndarray, i: np.ndarray, delta_s: float) -> np.ndarray:
    """The drive model's timing bar at samples ``i``, relative to |omega_dot| there [1]: half
    omega_dot's change over +- ``delta_s`` (``measurement.kinematics.drive_model``'s
    ``step_sigma``: a digital controller's sample, or a frame next to a step of a continuous
    one). It is large where the slip falls on the acceleration jump of a lag-free loop."""
    up = np.interp(t[i] + delta_s, t, alpha)
    down = np.interp(t[i] - delta_s, t, alpha)
    return 0.5 * np.abs(up - down) / np.maximum(np.abs(alpha[i]), 1e-300)


def predict_widths(t: np.ndarray, theta: np.ndarray, omega: np.ndarray, omega_dot: np.ndarray,
                   mus: np.ndarray | float, lever: float,
                   constants: WidthConstants = CALIBRATED,
                   mu_d_ratios: tuple[float, float, float] = MU_D_RATIOS,
                   controller_sample_time_s: float | None = None) -> WidthPrediction:
    """The relative width ``abu measure`` will report at each true mu (see the module doc).

    Args:
        t: the camera's frame times [s], equally spaced (the record).
        theta, omega, omega_dot: the planned ABU motion with the ball stuck [rad, rad/s,
            rad/s^2] at ``t`` (sign as planned; mu_req uses |omega_dot|).
        mus: true mu values [-].
        lever: (l - d/5) / l of the ball [-].
        mu_d_ratios: mu_d / mu at the range's low end, its expected value and its high end
            (a plan does not know mu_d: :data:`MU_D_RATIOS`; the benchmarks pass the true one
            to show what knowing it would buy).
        controller_sample_time_s: the digital controller's sample time [s] (None: a
            continuous one, timed to a frame): the drive-model kinematics' timing bar.
    """
    c = constants
    t = np.asarray(t, float)
    h = float(t[1] - t[0])
    mus = np.atleast_1d(np.asarray(mus, float))
    w_m, a_m, bias, g1, g2, half = _sg_views(np.asarray(theta, float), h, c)
    q_true = lever * np.abs(omega_dot) / np.maximum(np.asarray(omega, float) ** 2, 1e-300)
    q_meas = lever * np.abs(a_m) / np.maximum(w_m * w_m, 1e-300)
    trusted = np.zeros(t.size, bool)
    trusted[half: t.size - half] = True
    m_meas = np.maximum.accumulate(np.where(trusted, q_meas, 0.0))
    m_true = np.maximum.accumulate(q_true)
    w2, wa = np.asarray(omega, float) ** 2, np.abs(np.asarray(omega, float))
    steps = max(2, int(round(c.horizon_s / h)))
    thr = c.k_emerge * c.sigma_beta_rad

    i_s = np.searchsorted(m_true, mus, side="right")          # first sample with q > mu
    ok = (i_s >= half) & (i_s < t.size - half)
    i_sc = np.minimum(i_s, t.size - 1)
    # upper bound: the truth's deviation reaches the threshold at i_hi, for each mu_d / mu
    ratios = np.asarray(mu_d_ratios, float)
    lanes_s = np.repeat(i_sc, ratios.size)
    dev = _deviation(q_true, w2, wa, h, lever, lanes_s, np.outer(mus, ratios).ravel(), steps)
    reach = np.argmax(dev >= thr, axis=1)
    reach = np.where(dev[:, -1] >= thr, reach, steps)
    i_hi = lanes_s + reach
    upper = np.where(i_hi < t.size - half, m_meas[np.minimum(i_hi, t.size - 1)], np.inf)
    upper = upper.reshape(mus.size, ratios.size)
    # the onset is located to +- that emergence time: the profile spans the measured q's
    # running max over [t_s - tau, t_s + tau]
    i_lo = lanes_s - reach
    lower = np.where(i_lo >= half, m_meas[np.clip(i_lo, 0, t.size - 1)], np.nan)
    lower = lower.reshape(mus.size, ratios.size)

    # kinematic errors at the slip (measured view)
    a_s, w_s = np.abs(a_m[i_sc]), np.abs(w_m[i_sc])
    lens = c.theta_harmonic_rad * (w_s * w_s / a_s + 2.0)
    if c.kinematics == "drive-model":   # the fit's floor, no truncation, one model error
        noise = np.hypot(c.drive_model_error_rel,
                         _timing_bar(t, np.asarray(omega_dot, float), i_sc,
                                     controller_sample_time_s or h))
        trunc, z_low = np.zeros(mus.size), Z95
    else:
        noise = np.hypot(c.sigma_theta_rad * g2 / a_s, 2.0 * c.sigma_theta_rad * g1 / w_s)
        trunc, z_low = bias[i_sc] / a_s, c.z_low
    lo = lower * np.maximum(1.0 - z_low * noise - trunc - lens, 0.0)[:, None]
    hi = upper * (1.0 + Z95 * noise + trunc + lens)[:, None]
    with np.errstate(invalid="ignore"):   # a null bound (NaN / inf) is set to inf below
        width = (hi - lo) / (0.5 * (hi + lo))
        prof = (upper[:, 1] - lower[:, 1]) / (0.5 * (upper[:, 1] + lower[:, 1]))
    width = np.where(ok[:, None] & np.isfinite(lo) & np.isfinite(hi), width, np.inf)
    mid = 1    # mu_d / mu = 0.8
    expected = width[:, mid]
    t_slip = np.where(ok, t[i_sc], np.nan)
    return WidthPrediction(mus, t_slip, expected, np.min(width, axis=1) * math.exp(
        c.range_log_low), np.max(width, axis=1) * math.exp(c.range_log_high), prof, noise, trunc,
        lens, c)
