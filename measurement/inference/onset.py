"""The slip-onset bracket [t_slip_low, t_slip_high] from the model's confidence set on mu.

The ball starts to slip at the first time t_s at which the friction it needs exceeds mu:
q_true(t_s) > mu, with q = (l - d/5) (-s omega_dot) / (l omega^2) the signed mu_req. So the
onset is a function of mu and of the true kinematics only (mu_d enters after it): the onset
times of all pairs (mu, mu_d) of the confidence set are those of its mu, and with the
kinematics' error the bracket follows from two simultaneous statements,

* mu in [mu_low, mu_high] (the model's set, kinematic nuisance included, at the stated level);
* q_lo(t) <= q_true(t) <= q_hi(t) over the trusted region: q with omega_dot pushed by k sigma
  plus its truncation bound and the lens prior's A omega^2, omega by k sigma plus A omega, each
  in the unfavourable direction (k = ``k_sigma``, the running max's bands),

as

* t_slip_low = the last time t with max_{t' <= t} q_hi(t') <= mu_low: before it q_true <= mu
  everywhere, the ball surely sticks (the start of the trusted region if q_hi starts above
  mu_low: the model's own test rejected a ball slipping from the start there, or mu_low would be
  null);
* t_slip_high = the first time t with max_{t' <= t} q_lo(t') >= mu_high: q_true exceeded mu at
  or before t. Not beta's departure from its stick level (the running max's t_b): on the harsh
  twin a lighting leftover moved beta for good up to 11 ms before the true onset
  (benchmarks/bench_coverage.py, seeds 0-39: 2 of 40).

The earlier bracket (the running max's t_a / t_b, still under ``running_max`` in summary.json)
took t_a from the creep model's smallest candidate mu, not from the confidence set, and lay
after the true onset in many recordings.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: What the bracket is (summary.json ``onset_bracket.method``).
METHOD = ("onset times of the model's confidence set on mu: the measured q's running maximum "
          "crossing mu_low and mu_high (the set's bounds, kinematic nuisance included)")
BAND_METHOD = ("q's k-sigma band (+ truncation and lens bounds) crossing mu_low / mu_high: "
               "simultaneous bands, no error-scale model")


@dataclass(frozen=True)
class OnsetBracket:
    """[t_low, t_high] [s] (None where not bracketed), how each end was set, and the
    band-based bracket [t_low_band, t_high_band] (wider; reported beside it)."""

    t_low: float | None
    t_high: float | None
    low_from: str
    high_from: str
    t_low_band: float | None = None
    t_high_band: float | None = None

    def summary(self, k_sigma: float) -> dict:
        return {"t_slip_low": self.t_low, "t_slip_high": self.t_high,
                "t_slip_low_from": self.low_from, "t_slip_high_from": self.high_from,
                "method": METHOD,
                "band": {"t_slip_low": self.t_low_band, "t_slip_high": self.t_high_band,
                         "k_sigma": float(k_sigma), "method": BAND_METHOD}}


def q_band(omega: np.ndarray, omega_dot: np.ndarray, sigma_omega: np.ndarray,
           sigma_omega_dot: np.ndarray, bias_omega_dot: np.ndarray, l: float, d: float,
           direction: int, k_sigma: float, theta_harmonic_rad: float
           ) -> tuple[np.ndarray, np.ndarray]:
    """(q_lo, q_hi) [1]: the signed mu_req with the kinematic errors pushed down / up."""
    w = np.abs(np.asarray(omega, float))
    a = -float(direction) * np.asarray(omega_dot, float)
    amp = float(theta_harmonic_rad)
    da = k_sigma * np.asarray(sigma_omega_dot, float) + np.asarray(bias_omega_dot, float) \
        + amp * w * w
    dw = k_sigma * np.asarray(sigma_omega, float) + amp * w
    c = (l - d / 5.0) / l
    w_lo = np.maximum(w - dw, 1e-9)
    w_hi = w + dw
    a_hi, a_lo = a + da, a - da
    q_hi = c * a_hi / np.where(a_hi > 0, w_lo, w_hi) ** 2
    q_lo = c * a_lo / np.where(a_lo > 0, w_hi, w_lo) ** 2
    return q_lo, q_hi


def _crossings(time: np.ndarray, q_stuck: np.ndarray, q_slip: np.ndarray, i0: int, i1: int,
               mu_low: float | None, mu_high: float | None
               ) -> tuple[float | None, float | None, str, str]:
    """(last time the running max of ``q_stuck`` <= mu_low, first time that of ``q_slip`` >=
    mu_high) over the trusted run [i0, i1), with where each came from."""
    t_low = t_high = None
    low_from = high_from = "not bracketed"
    if mu_low is not None:
        below = np.flatnonzero(np.maximum.accumulate(q_stuck[i0:i1]) <= mu_low)
        if below.size:
            t_low, low_from = float(time[i0 + int(below[-1])]), "q reaches mu_low"
        else:
            t_low, low_from = float(time[i0]), "start of the trusted region"
    if mu_high is not None:
        above = np.flatnonzero(np.maximum.accumulate(q_slip[i0:i1]) >= mu_high)
        if above.size:
            t_high, high_from = float(time[i0 + int(above[0])]), "q reaches mu_high"
    return t_low, t_high, low_from, high_from


def onset_bracket(time: np.ndarray, q: np.ndarray, q_lo: np.ndarray, q_hi: np.ndarray,
                  trusted: np.ndarray, mu_low: float | None, mu_high: float | None
                  ) -> OnsetBracket:
    """The bracket of the module docstring.

    Args:
        time: sample times [s]; q: the measured signed mu_req; q_lo, q_hi: :func:`q_band` [1];
        trusted: (N,) bool, one run.
        mu_low, mu_high: the confidence set's bounds [1] (None: not bounded).
    """
    t = np.asarray(time, float)
    idx = np.flatnonzero(np.asarray(trusted, bool))
    i0, i1 = int(idx[0]), int(idx[-1]) + 1
    t_low, t_high, low_from, high_from = _crossings(t, q, q, i0, i1, mu_low, mu_high)
    tb_low, tb_high, _, _ = _crossings(t, q_hi, q_lo, i0, i1, mu_low, mu_high)
    return OnsetBracket(t_low, t_high, low_from, high_from, tb_low, tb_high)
