"""How far the largest of many correlated noise errors reaches: Rice's formula.

The model-based lower bound on mu is set by the largest measured q = mu_req over the stick
stretch (any smaller mu would have the ball slip where the data show it stuck). The measured q
carries the estimator's smooth noise error (Savitzky-Golay kernel on white theta noise, a
stationary Gaussian process of known autocorrelation); its maximum over a stretch of T seconds
in which q comes near the bound exceeds the pointwise z sigma far more often than 1 - Phi(z)
(rendered seed 177: a slow onset, q within noise of mu for ~100 ms, lower bound 3 % above mu).
For a stationary Gaussian process with unit variance and second spectral moment lambda2 =
-rho''(0), Rice's formula for the expected number of upcrossings of u gives

    P(sup_[0, T] X > u) <= 1 - Phi(u) + T sqrt(lambda2) / (2 pi) exp(-u^2 / 2)

(Rice 1945; Adler & Taylor, "Random Fields and Geometry", ch. 11), tight for the large u that
matter here. :func:`sup_quantile` solves it for u.
"""
from __future__ import annotations

import math
from statistics import NormalDist


def second_spectral_moment(rho_lag1: float, dt: float) -> float:
    """lambda2 = -rho''(0) [1/s^2] of a smooth process from its lag-one autocorrelation
    rho(dt) = 1 - lambda2 dt^2 / 2 + O(dt^4)."""
    return max(2.0 * (1.0 - float(rho_lag1)), 0.0) / (dt * dt)


def sup_exceedance(u: float, duration_s: float, lambda2: float) -> float:
    """Rice bound on P(the maximum over ``duration_s`` of the unit-variance process > u)."""
    tail = 1.0 - NormalDist().cdf(u)
    return tail + duration_s * math.sqrt(lambda2) / (2.0 * math.pi) * math.exp(-0.5 * u * u)


def sup_quantile(alpha: float, duration_s: float, lambda2: float) -> float:
    """u such that the maximum over ``duration_s`` exceeds u with probability ``alpha`` (Rice);
    the pointwise quantile for a zero duration."""
    z0 = NormalDist().inv_cdf(1.0 - alpha)
    if duration_s <= 0.0 or lambda2 <= 0.0:
        return z0
    # Bisection, not scipy.optimize.brentq: the bound falls monotonically in u (> 0), 60
    # halvings of [z0, 40] reach ~1e-16, and importing scipy.optimize cost `abu measure`
    # 0.33 s of its 2 s budget (python -X importtime).
    lo, hi = z0, 40.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if sup_exceedance(mid, duration_s, lambda2) > alpha:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)
