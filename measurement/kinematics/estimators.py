"""omega and omega_dot from the ABU angle theta(t) sampled at a constant frame rate.

Two estimators, both *linear* in theta, so the effect of white tracking noise of standard deviation
sigma_theta on each output sample is exactly sigma_theta times the Euclidean norm of that sample's
row of the linear operator. That is the noise error bar returned with every estimate.

* ``report`` (report sec. 5.2): block-average theta over ``decimation`` samples (10 in the report),
  central difference (eq. 5.1) on the decimated series for omega, a global polynomial fitted to
  omega (least squares, Legendre basis on the scaled time axis) and its derivative for omega_dot.
  The polynomial smears every acceleration step and is unreliable near both ends: the report
  trusts it from t = 0.05 s on, and so do we at both ends (``trim``).
* ``savgol`` (default): Savitzky-Golay filters on theta itself (:func:`stable_savgol_filter`),
  deriv=1 for omega and deriv=2 for omega_dot. The window is short (20 ms by default), so an
  acceleration step is spread over one window only. The first and last half-window use
  SciPy's edge fits and are not trusted. Besides the noise bar it returns a bound on its own
  truncation error where the data show one (Richardson: comparison with a half-length window).

sigma_theta, the white-noise level of theta, is estimated from the data by
:func:`noise_sigma` (median absolute deviation of the third difference, which removes any smooth
signal: theta''' dt^3 is ~1e-6 rad at 4500 frames/s, far below tracking noise).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.polynomial import legendre as leg

from abu_model.errors import ParameterError

ESTIMATORS = ("savgol", "report")


@dataclass(frozen=True)
class Kinematics:
    """omega, omega_dot and their noise error bars on the frame times.

    Attributes:
        time: frame times [s], (N,).
        omega: angular velocity [rad/s], (N,).
        omega_dot: angular acceleration [rad/s^2], (N,).
        sigma_omega: 1-sigma noise error bar of omega [rad/s], (N,).
        sigma_omega_dot: 1-sigma noise error bar of omega_dot [rad/s^2], (N,).
        trusted: (N,) bool, where the estimator is reliable (edges excluded).
        bias_omega_dot: bound on the estimator's own (truncation) error of omega_dot where the
            data show one [rad/s^2], (N,); zero where it is not significant (see
            :func:`savgol_kinematics`). Added to k sigma in the interval's bands.
        sigma_theta: white-noise standard deviation of theta used for the error bars [rad].
        method: ``savgol`` or ``report``.
        settings: the estimator's settings (window, degree, ... with units in the key names).
        omega_dot_rho: autocorrelation of omega_dot's noise error at lags 0, 1, ... samples
            (its kernel applied to white theta noise); None where not known.
    """

    time: np.ndarray
    omega: np.ndarray
    omega_dot: np.ndarray
    sigma_omega: np.ndarray
    sigma_omega_dot: np.ndarray
    trusted: np.ndarray
    sigma_theta: float
    method: str
    settings: dict = field(default_factory=dict)
    bias_omega_dot: np.ndarray | None = None
    omega_dot_rho: np.ndarray | None = None

    def __post_init__(self) -> None:
        if self.bias_omega_dot is None:
            object.__setattr__(self, "bias_omega_dot", np.zeros_like(self.omega_dot))


def noise_sigma(signal: np.ndarray, order: int = 3) -> float:
    """Robust standard deviation of the white noise on a smooth signal.

    The ``order``-th difference of white noise of variance s^2 has variance s^2 * C(2 order, order);
    a smooth signal contributes almost nothing to it. The median absolute deviation (x 1.4826)
    makes the estimate robust against the few samples where the signal is not smooth (steps).
    """
    x = np.asarray(signal, dtype=float)
    if x.size < order + 2:
        raise ParameterError("signal", f"{x.size} samples", f"at least {order + 2} samples")
    diff = np.diff(x, n=order)
    mad = np.median(np.abs(diff - np.median(diff)))
    return float(1.4826 * mad / math.sqrt(math.comb(2 * order, order)))


def sample_interval(time: np.ndarray, tolerance: float = 0.01) -> float:
    """The constant sample interval [s] of ``time``; raises if the sampling is not uniform.

    The times must lie on a uniform grid t0 + i dt (dt from the first and last time) within
    ``tolerance`` frame intervals, which accepts times rounded to a few digits (e.g. 1 us at
    4500 frames/s is 0.005 frame) but not dropped or duplicated frames.
    """
    t = np.asarray(time, dtype=float)
    if t.size < 3:
        raise ParameterError("time", f"{t.size} samples", "at least 3 samples")
    dt = float(t[-1] - t[0]) / (t.size - 1)
    if not dt > 0.0:
        raise ParameterError("time", "non-increasing", "strictly increasing times")
    off = (t - t[0]) / dt - np.arange(t.size)
    worst = int(np.argmax(np.abs(off)))
    if abs(off[worst]) > tolerance:
        raise ParameterError(
            "time", f"{float(t[worst])!r} s at sample {worst}, {float(off[worst]):+.3f} frame "
            "intervals off the uniform grid",
            f"uniform sampling (every time within {tolerance:g} frame interval of "
            f"t0 + i * {dt!r} s)")
    return dt


def running_max_filter(x: np.ndarray, size: int) -> np.ndarray:
    """Centred moving maximum over ``size`` (odd) samples, edges repeated (NumPy only: SciPy's
    ``maximum_filter1d`` would cost the ``abu measure`` process ~0.3 s of imports)."""
    h = size // 2
    padded = np.pad(np.asarray(x, dtype=float), h, mode="edge")
    return np.lib.stride_tricks.sliding_window_view(padded, size).max(axis=1)


def moving_average(x: np.ndarray, size: int) -> np.ndarray:
    """Centred moving average over ``size`` samples, edges repeated (as SciPy's
    ``uniform_filter1d(mode="nearest")``; odd sizes are centred, even ones lean left)."""
    x = np.asarray(x, dtype=float)
    size = max(1, int(size))
    lo = size // 2
    hi = size - 1 - lo
    padded = np.pad(x, [(0, 0)] * (x.ndim - 1) + [(lo, hi)], mode="edge")
    c = np.cumsum(padded, axis=-1)
    c = np.concatenate([np.zeros(x.shape[:-1] + (1,)), c], axis=-1)
    return (c[..., size:] - c[..., :-size]) / size


def stable_savgol_coeffs(window: int, polyorder: int, deriv: int, delta: float) -> np.ndarray:
    """Savitzky-Golay "dot" coefficients for the window's centre, computed on positions scaled
    to [-1, 1]. SciPy's ``savgol_coeffs`` works on raw sample offsets and loses accuracy at
    degree 7 and windows over ~150 samples (its deriv-2 weights sum to 0.06 instead of 0 at
    161 samples, i.e. 1.7 rad/s^2 of error on theta ~ 30 rad); these are exact to rounding.
    """
    m = window // 2
    u = np.arange(-m, m + 1) / m
    pinv = np.linalg.pinv(np.vander(u, polyorder + 1, increasing=True))
    return math.factorial(deriv) * pinv[deriv] / (m * delta) ** deriv


def stable_savgol_filter(x: np.ndarray, window: int, polyorder: int, deriv: int,
                         delta: float) -> np.ndarray:
    """Savitzky-Golay derivative of ``x`` with :func:`stable_savgol_coeffs`.

    Interior samples use the centred window; the first and last half window are evaluated on
    the polynomial fitted to the first / last window (SciPy's ``mode="interp"``).
    """
    x = np.asarray(x, dtype=float)
    n, m = x.size, window // 2
    x0 = x - x[m] if n > m else x - x[0]        # small values: no cancellation
    c = stable_savgol_coeffs(window, polyorder, deriv, delta)
    out = np.empty(n)
    out[m: n - m] = np.correlate(x0, c, mode="valid")
    u = np.arange(-m, m + 1) / m
    vand = np.vander(u, polyorder + 1, increasing=True)
    for seg, where in ((slice(0, window), slice(0, m)), (slice(n - window, n), slice(n - m, n))):
        coef = np.linalg.lstsq(vand, x0[seg], rcond=None)[0]
        der = np.polynomial.polynomial.polyder(coef, deriv) / (m * delta) ** deriv
        pos = u[:m] if where.start == 0 else u[m + 1:]
        out[where] = np.polynomial.polynomial.polyval(pos, der)
    return out


def _odd_window(window_s: float, dt: float, minimum: int) -> int:
    n = int(round(window_s / dt))
    n = max(n, minimum)
    return n if n % 2 == 1 else n + 1


def savgol_kinematics(time: np.ndarray, theta: np.ndarray, *, window_s: float = 0.02,
                      polyorder: int = 3, sigma_theta: float | None = None,
                      trim_s: float = 0.0, bias_window_ratio: float = 0.5,
                      bias_k: float = 3.0) -> Kinematics:
    """omega and omega_dot by Savitzky-Golay filters on theta.

    Args:
        time: uniformly sampled times [s].
        theta: ABU angle [rad], unwrapped.
        window_s: filter window [s], rounded to an odd number of samples (at least polyorder + 3).
        polyorder: local polynomial degree (>= 2; 2 and 3 give the same omega_dot).
        sigma_theta: noise level of theta [rad]; estimated by :func:`noise_sigma` when None.
        trim_s: extra time [s] excluded from the trusted region at each end, beyond the half window.
        bias_window_ratio: length of the comparison window of the truncation bound / window.
        bias_k: the difference counts where it exceeds ``bias_k`` times its own noise.
    """
    dt = sample_interval(time)
    theta = np.asarray(theta, dtype=float)
    if polyorder < 2:
        raise ParameterError("polyorder", polyorder, "an integer >= 2 (omega_dot needs deriv=2)")
    if not window_s > 0:
        raise ParameterError("sg_window_s", window_s, "> 0 s")
    window = _odd_window(window_s, dt, polyorder + 3 if polyorder % 2 == 0 else polyorder + 2)
    if window > theta.size:
        raise ParameterError("sg_window_s", window_s,
                             f"a window shorter than the record ({theta.size * dt:g} s)")
    sigma = noise_sigma(theta) if sigma_theta is None else float(sigma_theta)
    omega = stable_savgol_filter(theta, window, polyorder, 1, dt)
    omega_dot = stable_savgol_filter(theta, window, polyorder, 2, dt)
    c1 = stable_savgol_coeffs(window, polyorder, 1, dt)
    c2 = stable_savgol_coeffs(window, polyorder, 2, dt)
    # Truncation error (Richardson): the window's bias grows as its length squared where the
    # motion is smooth (bias(w) = 4/3 (a_w - a_{w/2})) and linearly at a kink of omega_dot, e.g.
    # a setpoint step through a motor lag (bias(w) = 2 (a_w - a_{w/2}) for the same shape; the
    # error profiles of the two windows are not aligned in time, and 3 is what bounds the error
    # of a kink in tests); we take 3 times the largest difference within a quarter window.
    # It is kept only where the difference exceeds three times its own noise, so noisy
    # records keep their noise bars and noise-free ones get an honest bar.
    half_window = _odd_window(bias_window_ratio * window * dt, dt,
                              polyorder + 3 if polyorder % 2 == 0 else polyorder + 2)
    bias = np.zeros_like(omega_dot)
    if half_window < window:
        a_half = stable_savgol_filter(theta, half_window, polyorder, 2, dt)
        c2h = stable_savgol_coeffs(half_window, polyorder, 2, dt)
        pad = (window - half_window) // 2
        c_diff = c2 - np.pad(c2h, (pad, pad))
        noise_diff = sigma * float(np.linalg.norm(c_diff))
        # at a kink the bias grows linearly with the window: bias(w) = diff / (1 - ratio)
        factor = max(3.0, 1.0 / (1.0 - bias_window_ratio))
        bias = np.maximum(np.abs(omega_dot - a_half) - bias_k * noise_diff, 0.0) * factor
        bias = running_max_filter(bias, max(1, window // 4) | 1)
    n = theta.size
    half = window // 2
    trusted = np.zeros(n, dtype=bool)
    extra = int(round(trim_s / dt))
    trusted[half + extra: n - half - extra] = True
    return Kinematics(
        time=np.asarray(time, dtype=float), omega=omega, omega_dot=omega_dot,
        sigma_omega=np.full(n, sigma * float(np.linalg.norm(c1))),
        sigma_omega_dot=np.full(n, sigma * float(np.linalg.norm(c2))),
        trusted=trusted, sigma_theta=sigma, method="savgol",
        settings={"window_samples": window, "window_s": window * dt, "polyorder": polyorder,
                  "trim_s": trim_s}, bias_omega_dot=bias,
        omega_dot_rho=np.correlate(c2, c2, mode="full")[c2.size - 1:] / float(c2 @ c2))


def report_kinematics(time: np.ndarray, theta: np.ndarray, *, decimation: int = 10,
                      degree: int = 10, sigma_theta: float | None = None,
                      trim_s: float = 0.05) -> Kinematics:
    """The report's estimator: decimation, central difference, global polynomial on omega.

    Args:
        time: uniformly sampled times [s].
        theta: ABU angle [rad], unwrapped.
        decimation: block length of the averaging (10 in the report).
        degree: degree of the polynomial fitted to omega (the report does not give it).
        sigma_theta: noise level of theta [rad]; estimated by :func:`noise_sigma` when None.
        trim_s: time [s] excluded from the trusted region at each end (the report: 0.05 s).

    omega is the central difference of the decimated theta, interpolated linearly to the frame
    times; omega_dot is the derivative of the polynomial, evaluated at the frame times.
    """
    dt = sample_interval(time)
    t = np.asarray(time, dtype=float)
    theta = np.asarray(theta, dtype=float)
    q = int(decimation)
    if q < 1:
        raise ParameterError("decimation", decimation, "an integer >= 1")
    k = theta.size // q
    if k < degree + 3:
        raise ParameterError("poly_degree", degree,
                             f"a degree below {k - 2} (the record has {k} decimated samples)")
    sigma = noise_sigma(theta) if sigma_theta is None else float(sigma_theta)
    theta_d = theta[: k * q].reshape(k, q).mean(axis=1)
    t_d = t[: k * q].reshape(k, q).mean(axis=1)
    h = q * dt
    omega_d = (theta_d[2:] - theta_d[:-2]) / (2.0 * h)
    t_w = t_d[1:-1]

    # Noise covariance of omega_d in units of sigma^2: omega_d = E @ theta_d, cov(theta_d) = I/q.
    m = omega_d.size
    gram = np.zeros((m, m))
    idx = np.arange(m)
    gram[idx, idx] = 2.0 / (4.0 * h * h * q)
    gram[idx[:-2], idx[:-2] + 2] = -1.0 / (4.0 * h * h * q)
    gram[idx[2:], idx[2:] - 2] = -1.0 / (4.0 * h * h * q)

    # omega on the frame times: linear interpolation (clamped at the ends), weights w.
    pos = np.clip((t - t_w[0]) / h, 0.0, m - 1.0)
    lo = np.minimum(pos.astype(int), m - 2)
    frac = pos - lo
    omega = (1.0 - frac) * omega_d[lo] + frac * omega_d[lo + 1]
    var_w = ((1.0 - frac) ** 2 * gram[lo, lo] + frac ** 2 * gram[lo + 1, lo + 1]
             + 2.0 * frac * (1.0 - frac) * gram[lo, lo + 1])

    # Global polynomial (Legendre basis on u in [-1, 1]) fitted to omega_d; derivative in t.
    centre, scale = 0.5 * (t_w[0] + t_w[-1]), 0.5 * (t_w[-1] - t_w[0])
    design = leg.legvander((t_w - centre) / scale, degree)
    pinv = np.linalg.pinv(design)
    coef = pinv @ omega_d
    u = (t - centre) / scale
    deriv_basis = np.zeros((t.size, degree + 1))
    for j in range(degree + 1):
        unit = np.zeros(degree + 1)
        unit[j] = 1.0
        deriv_basis[:, j] = leg.legval(u, leg.legder(unit)) / scale
    omega_dot = deriv_basis @ coef
    cov_coef = pinv @ gram @ pinv.T
    var_a = np.einsum("ij,jk,ik->i", deriv_basis, cov_coef, deriv_basis)

    n = t.size
    trusted = np.zeros(n, dtype=bool)
    first = max(int(round(trim_s / dt)), q)
    trusted[first: n - first] = True
    return Kinematics(
        time=t, omega=omega, omega_dot=omega_dot,
        sigma_omega=sigma * np.sqrt(var_w), sigma_omega_dot=sigma * np.sqrt(np.maximum(var_a, 0)),
        trusted=trusted, sigma_theta=sigma, method="report",
        settings={"decimation": q, "poly_degree": degree, "trim_s": trim_s})


def estimate_kinematics(time: np.ndarray, theta: np.ndarray, method: str = "savgol",
                        **kwargs) -> Kinematics:
    """Dispatch to :func:`savgol_kinematics` or :func:`report_kinematics` by ``method``."""
    if method == "savgol":
        return savgol_kinematics(time, theta, **kwargs)
    if method == "report":
        return report_kinematics(time, theta, **kwargs)
    raise ParameterError("estimator", method, f"one of {', '.join(ESTIMATORS)}")

