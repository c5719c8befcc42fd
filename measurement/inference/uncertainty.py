"""Error analysis of the bounds on mu: the report's worst case (sec. 5.4) and a Monte Carlo
propagation of the measured tracking noise.

Report, eq. 5.4-5.6: relative errors e_w on omega and e_a on omega_dot change the computed
friction coefficient to mu~ = mu (1 + e_a) / (1 + e_w)^2. With |e_w| <= 3 % and |e_a| <= 5 % the
largest change is (1.05 / 0.97^2) - 1 = +11.6 % (and the smallest 0.95 / 1.03^2 - 1 = -10.5 %). As a
statement about the true value behind a computed bound: mu = mu~ / (1 + e_mu), so a computed
interval [lo, hi] widens to [lo / (1 + e_max), hi / (1 + e_min)].

Monte Carlo (JCGM 101, "Propagation of distributions using a Monte Carlo method"): the
measurand (mu_low, mu_high) is a function of the marker coordinates; the coordinates carry white
tracking noise whose standard deviation is measured on the record (per marker and axis, from the
third differences, see :func:`measurement.kinematics.estimators.noise_sigma`). Each draw adds fresh noise of
that size to the measured coordinates and reruns the whole analysis (a parametric bootstrap, the
usual practical form of JCGM 101 when only the measured data are at hand); the spread of the
results is the noise part of the uncertainty of the bounds. Systematic effects (lens distortion,
lighting bias, model error) are not in it.
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

from abu_model.errors import ParameterError

from measurement.kinematics.estimators import noise_sigma

#: The report's guessed relative errors on omega and omega_dot (sec. 5.4).
REPORT_E_OMEGA = 0.03
REPORT_E_OMEGA_DOT = 0.05


def perturbed_mu_factor(e_omega: float, e_omega_dot: float) -> float:
    """(1 + e_a) / (1 + e_w)^2: the factor mu~/mu of eq. 5.6."""
    if e_omega <= -1.0:
        raise ParameterError("e_omega", e_omega, "a relative error > -1")
    return (1.0 + e_omega_dot) / (1.0 + e_omega) ** 2


def worst_case_relative_error(e_omega: float = REPORT_E_OMEGA,
                              e_omega_dot: float = REPORT_E_OMEGA_DOT) -> tuple[float, float]:
    """(smallest, largest) relative error e_mu of mu for |e_w| <= e_omega, |e_a| <= e_omega_dot.

    The factor is monotone in each error, so the extremes are at the corners of the box:
    (1 - e_a) / (1 + e_w)^2 - 1 and (1 + e_a) / (1 - e_w)^2 - 1.
    """
    if not (0.0 <= e_omega < 1.0):
        raise ParameterError("e_omega", e_omega, "a relative error bound in [0, 1)")
    if not (0.0 <= e_omega_dot):
        raise ParameterError("e_omega_dot", e_omega_dot, "a relative error bound >= 0")
    low = perturbed_mu_factor(e_omega, -e_omega_dot) - 1.0
    high = perturbed_mu_factor(-e_omega, e_omega_dot) - 1.0
    return low, high


def widen_interval(mu_low: float | None, mu_high: float | None, e_omega: float = REPORT_E_OMEGA,
                   e_omega_dot: float = REPORT_E_OMEGA_DOT) -> tuple[float | None, float | None]:
    """The interval of true values compatible with computed bounds off by the worst case."""
    e_min, e_max = worst_case_relative_error(e_omega, e_omega_dot)
    lo = None if mu_low is None else mu_low / (1.0 + e_max)
    hi = None if mu_high is None else mu_high / (1.0 + e_min)
    return lo, hi


def error_analysis(mu_low: float | None, mu_high: float | None, *,
                   e_omega: float = REPORT_E_OMEGA,
                   e_omega_dot: float = REPORT_E_OMEGA_DOT,
                   measured: dict | None = None) -> dict:
    """The report's error analysis as a JSON-ready dict (relative errors as fractions).

    ``measured`` may hold the relative 1-sigma errors of omega and omega_dot at the bounds from
    the estimator's own error bars (keys ``e_omega_low`` etc.); the worst case is then also given
    for 3 sigma of those.
    """
    e_min, e_max = worst_case_relative_error(e_omega, e_omega_dot)
    lo, hi = widen_interval(mu_low, mu_high, e_omega, e_omega_dot)
    out = {
        "e_omega": e_omega, "e_omega_dot": e_omega_dot,
        "e_mu_min": e_min, "e_mu_max": e_max,
        "mu_low_widened": lo, "mu_high_widened": hi,
    }
    if measured:
        out["measured"] = dict(measured)
    return out


def pixel_noise(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """(3, 2) white-noise standard deviation [px] of each marker's x and y track."""
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    return np.array([[noise_sigma(x[:, j]), noise_sigma(y[:, j])] for j in range(x.shape[1])])


def monte_carlo(run: Callable[[np.ndarray, np.ndarray], tuple[float | None, float | None]],
                x: np.ndarray, y: np.ndarray, sigma_px: np.ndarray, *, draws: int = 100,
                seed: int = 0, percentiles: tuple[float, ...] = (2.5, 50.0, 97.5)) -> dict:
    """Propagate tracking noise to (mu_low, mu_high) by Monte Carlo.

    Args:
        run: the analysis, (x, y) -> (mu_low, mu_high); None for a bound it cannot give.
        x, y: measured pixel coordinates (N, 3).
        sigma_px: (3, 2) noise standard deviations [px] per marker and axis.
        draws: number of Monte Carlo draws (>= 1).
        seed: seed of the NumPy generator (results are reproducible).
        percentiles: percentiles reported [%].

    Returns:
        JSON-ready dict: draws, seed, sigma_px, and per bound the percentiles, mean, standard
        deviation and the number of draws that gave the bound.
    """
    if int(draws) < 1:
        raise ParameterError("mc_draws", draws, "an integer >= 1")
    sigma = np.asarray(sigma_px, dtype=float)
    if sigma.shape != (np.asarray(x).shape[1], 2) or not np.all(np.isfinite(sigma)) \
            or np.any(sigma < 0):
        raise ParameterError("sigma_px", sigma.tolist(), "(markers, 2) finite values >= 0 px")
    rng = np.random.default_rng(seed)
    lows, highs = [], []
    for _ in range(int(draws)):
        xn = x + rng.standard_normal(x.shape) * sigma[None, :, 0]
        yn = y + rng.standard_normal(y.shape) * sigma[None, :, 1]
        lo, hi = run(xn, yn)
        lows.append(math.nan if lo is None else lo)
        highs.append(math.nan if hi is None else hi)
    out = {"draws": int(draws), "seed": int(seed), "sigma_px": sigma.tolist()}
    for name, values in (("mu_low", np.array(lows)), ("mu_high", np.array(highs))):
        ok = values[np.isfinite(values)]
        entry = {"n_defined": int(ok.size)}
        if ok.size:
            entry.update({f"p{p:g}": float(np.percentile(ok, p)) for p in percentiles})
            entry["mean"] = float(ok.mean())
            entry["std"] = float(ok.std(ddof=1)) if ok.size > 1 else 0.0
        out[name] = entry
    return out
