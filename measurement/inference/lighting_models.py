"""Two lighting models of the record, and the union of their sets where they disagree.

The whole-record fit removes the lighting harmonics of the ball's angle phi from beta
(:mod:`measurement.kinematics.harmonic`, orders ``AnalysisOptions.harmonic_orders``). Which
orders to remove is not a detail: a two-spot or blurred ball has harmonics up to order 6 and
more, and orders left in the data move the slip's onset (seeds 2046 and 3011 of the harsh
twin's unseen slices missed mu by 16 % and 11 % with orders 1-4, and held it with 1-6);
orders removed that are not there trade against the slip in the record fit (seed 5019 held mu
with 1-4, and missed it by 7 % with 1-6). Where the fit window covers about one turn of phi
or less, the record does not tell the two apart.

So the analysis keeps both models. Each gives a confidence set at the stated level, valid if
its lighting model holds; their union holds mu whenever one of them is right (the union of
two sets, each covering with probability >= 1 - alpha under its model, covers with
probability >= 1 - alpha under either). Where the two cleaned betas differ in the fit window
by less than beta's white noise can show -- the part of the difference that the window's own
nuisance columns (offset, orders ``InferenceOptions.harmonic_orders``) cannot absorb has a
chi^2 of at most :data:`DISAGREEMENT_CHI2` against that noise (the record fit's robust residual sigma) -- the second model cannot
move the likelihood by a unit and its set is not computed (the cost of a second inference
is spent only where the choice matters).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from measurement.inference.fit_window import harmonic_design
from measurement.inference.noise_models import TriangularWhitener, leftover_whitener_of
from measurement.inference.types import LOST_ACROSS_SLIP, Inference

#: The second lighting model of a ball showing two reflections: orders 1-6 (a two-spot ball's
#: highlights put harmonics up to order 6 into beta; see the module doc).
TWO_SPOT_ORDERS = (1, 2, 3, 4, 5, 6)


def alternative_orders(ball_reflections: int | None) -> tuple[int, ...]:
    """The default second lighting model (``AnalysisOptions.harmonic_orders_alternative``
    None): :data:`TWO_SPOT_ORDERS` where the tracking found the ball with two reflections,
    none with one or where the tracks do not say (a CSV of tracks alone). The two-spot
    recordings are where orders 1-4 were seen to miss (seeds 2046, 3011, 106), and only they
    pay the second inference: a one-spot recording is analysed as before."""
    return TWO_SPOT_ORDERS if ball_reflections == 2 else ()


#: The second lighting model's set is computed when replacing the first model's cleaned beta
#: by the second's changes the likelihood-ratio statistic at a bound by more than this [chi^2]
#: (the set's edge is where the statistic crosses its critical value, 3.84 at 95 %: a change
#: of one unit moves a bound visibly, a tenth of one does not).
DISAGREEMENT_CHI2 = 1.0


def window_of(inference: Inference) -> np.ndarray:
    """(N,) bool: the samples of the record the set's fit window covered."""
    return np.isfinite(np.asarray(inference.beta_model, float))


def bound_shift_chi2(inference: Inference, beta_a: np.ndarray, beta_b: np.ndarray,
                     theta: np.ndarray, orders: tuple[int, ...], with_theta: bool,
                     whitener: TriangularWhitener) -> float:
    """The largest change [chi^2 units] that replacing beta_a by beta_b (two cleaned betas
    [rad]) makes, to first order, in the likelihood-ratio statistic of each bound of
    ``inference`` against its best fit: 2 (W d)^T W (m_best - m_bound), with d the difference
    and the model curves' difference both clear of the window's nuisance columns (offset and
    ``orders`` of phi = theta + beta_a, generalised least squares), W the window's
    ``whitener``. 0 without a bound's curve."""
    window = window_of(inference)
    if not window.any():
        return 0.0
    th = np.asarray(theta, float)[window]
    xw = whitener.columns(harmonic_design(th, th + np.asarray(beta_a, float)[window],
                                          tuple(orders), with_theta))
    q, _ = np.linalg.qr(xw)

    def clear(v: np.ndarray) -> np.ndarray:          # whitened, nuisances projected out
        vw = whitener.columns(v)
        return vw - q @ (q.T @ vw)

    d = clear((np.asarray(beta_b, float) - np.asarray(beta_a, float))[window])
    best = np.asarray(inference.beta_model, float)[window]
    shifts = [abs(2.0 * float(d @ clear(best - np.asarray(curve, float)[window])))
              for curve in (inference.beta_model_low, inference.beta_model_high)
              if curve is not None]
    return max(shifts, default=0.0)


def whitener(inference: Inference, n: int, h_s: float, sigma_white_rad: float
             ) -> TriangularWhitener:
    """The whitener (inverse Cholesky factor) of beta's noise covariance in the set's fit
    window of ``n`` samples: its white + exponential leftover model
    (``details["noise_model"]``), else white noise of ``sigma_white_rad`` [rad]; ``h_s`` the
    sample interval [s]."""
    info = inference.details.get("noise_model") or {}
    if all(info.get(k) for k in ("sigma_white_rad", "sigma_leftover_rad", "leftover_tau_s")):
        return leftover_whitener_of(info, n, h_s)
    return TriangularWhitener(np.eye(n) * max(float(sigma_white_rad), 1e-12))


def _hull(a: float | None, b: float | None, pick) -> float | None:
    return None if a is None or b is None else pick(a, b)


def union_sets(primary: Inference, other: Inference, orders: tuple[tuple[int, ...], ...]
               ) -> Inference:
    """The union of two sets on mu (and mu_d) under two lighting models; ``primary`` (the
    first model's) supplies the best fit, the model curves and the details. A bound that one
    model leaves null is null in the union; so is everything when a marker was lost across
    the slip under either."""
    models = [{"harmonic_orders": list(o), "mu_low": s.mu_low, "mu_high": s.mu_high,
               "status": s.status} for o, s in zip(orders, (primary, other))]
    details = {**primary.details, "lighting_models": models,
               "lighting_combination": "union of the sets under both lighting models"}
    lost = [s for s in (primary, other) if s.status == LOST_ACROSS_SLIP]
    if lost:
        return replace(primary, mu_low=None, mu_high=None, mu_d_low=None, mu_d_high=None,
                       mu_d=None, status=LOST_ACROSS_SLIP, details=details)
    lo = _hull(primary.mu_low, other.mu_low, min)
    hi = _hull(primary.mu_high, other.mu_high, max)
    status = primary.status
    if (lo is None) != (primary.mu_low is None) or (hi is None) != (primary.mu_high is None):
        status = other.status          # the bound the other model leaves null: its reason
    mud_lo = _hull(primary.mu_d_low, other.mu_d_low, min)
    mud_hi = _hull(primary.mu_d_high, other.mu_d_high, max)
    mu_d = primary.mu_d if mud_lo is not None and mud_hi is not None else None
    return replace(primary, mu_low=lo, mu_high=hi, mu_d_low=mud_lo if mu_d is not None else None,
                   mu_d_high=mud_hi if mu_d is not None else None, mu_d=mu_d, status=status,
                   details=details)
