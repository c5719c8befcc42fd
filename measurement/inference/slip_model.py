"""The ball's slip along the rim for candidate (mu, mu_d), driven by a measured ABU motion.

Vectorised over candidates and time (integrating factor + cumulative sums; episodes of slip
are looped, samples are not). Used by :mod:`measurement.inference.infer_mu` (the model-based confidence
set) and :func:`measurement.inference.running_max.predicted_creep` (the report's creep lower bound).
"""
from __future__ import annotations

import numpy as np


def signed_mu_req(omega: np.ndarray, omega_dot: np.ndarray, l: float, d: float,
                  direction: int) -> np.ndarray:
    """q = (l - d/5) (-s omega_dot) / (l omega^2) [-]: mu_req, positive when it pushes along s."""
    w2 = np.maximum(np.asarray(omega, float) ** 2, 1e-12)
    return (l - d / 5.0) * (-float(direction) * np.asarray(omega_dot, float)) / (l * w2)


def slip_displacement(t: np.ndarray, q: np.ndarray, omega: np.ndarray, mu: np.ndarray,
                      mu_d: np.ndarray, direction: int, d_over_l: float, *,
                      max_episodes: int | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Displacement along the slip direction D [rad] for candidate pairs (mu, mu_d).

    Args:
        t: uniform times [s] (N,); the ball is stuck at t[0].
        q: signed mu_req (N,) [-], see :func:`signed_mu_req`.
        omega: ABU speed (N,) [rad/s].
        mu, mu_d: (M,) candidate static and sliding coefficients [-].
        direction: slip direction s (+1 / -1).
        d_over_l: ball diameter / path radius [-].
        max_episodes: slip episodes followed per candidate; None (default): every one to the
            end of the record. A cap freezes a candidate after its last followed re-stick, as
            if it stuck for good while q exceeds its mu again: a candidate with mu in q's noise
            (a few episodes on noise near q = 0) then escapes the record's real slip.

    Returns:
        (D, onset): (M, N) displacement [rad] (>= 0) and (M,) first onset time [s] (inf: none).
    """
    mu = np.asarray(mu, float)[:, None]
    mud = np.asarray(mu_d, float)[:, None]
    n = t.size
    h = float(t[1] - t[0])
    idx = np.arange(n)[None, :]
    w = np.asarray(omega, float)[None, :]
    qq = np.asarray(q, float)[None, :]
    g = w * w * (qq - mud) / 1.4                             # (M, N) drive of u' [rad/s^2]
    c = mud * float(direction) * w * (2.0 - 0.2 * d_over_l) / 1.4   # u' = g - c u
    cumc = np.concatenate([np.zeros((mu.shape[0], 1)),
                           np.cumsum(0.5 * (c[:, 1:] + c[:, :-1]) * h, axis=1)], axis=1)
    cumc -= cumc[:, :1]
    e = np.exp(np.clip(cumc, -50.0, 50.0))                   # integrating factor
    eg = e * g
    inc = 0.5 * (eg[:, 1:] + eg[:, :-1]) * h
    cs = np.concatenate([np.zeros((mu.shape[0], 1)), np.cumsum(inc, axis=1)], axis=1)
    above = qq > mu                                          # (M, N) slip condition
    disp = np.zeros((mu.shape[0], n))
    onset_first = np.full(mu.shape[0], np.inf)
    start = np.zeros(mu.shape[0], dtype=int)                 # search onsets from here
    live_rows = np.arange(mu.shape[0])                       # rows that may slip again
    episode = 0
    while live_rows.size and (max_episodes is None or episode < int(max_episodes)):
        episode += 1
        cand = above[live_rows] & (idx >= start[live_rows, None])
        has = cand.any(axis=1)
        live_rows, cand = live_rows[has], cand[has]
        if not live_rows.size:
            break
        r_ = live_rows
        rows = np.arange(r_.size)
        i_s = np.argmax(cand, axis=1)
        # sub-sample onset between i_s - 1 and i_s (q crosses mu there)
        prev = np.clip(i_s - 1, 0, n - 1)
        ii = np.clip(i_s, 0, n - 1)
        q0, q1 = q[prev], q[ii]
        frac = np.where((i_s > start[r_]) & (q1 > q0),
                        (mu[r_, 0] - q0) / np.where(q1 > q0, q1 - q0, 1.0), 1.0)
        frac = np.clip(frac, 0.0, 1.0)
        delta = (1.0 - frac) * h                             # time from onset to t[i_s]
        t_on = t[ii] - delta
        onset_first[r_] = np.where(np.isinf(onset_first[r_]), t_on, onset_first[r_])
        g_on = np.asarray(omega, float)[prev] ** 2 * (mu[r_, 0] - mud[r_, 0]) / 1.4
        g_r, e_r, cs_r = g[r_], e[r_], cs[r_]
        u_is = 0.5 * (g_on + g_r[rows, ii]) * delta           # slip speed at t[i_s]
        d_is = 0.5 * u_is * delta
        # u_n = [E_is u_is + CS_n - CS_is] / E_n for n >= i_s
        base = e_r[rows, ii] * u_is - cs_r[rows, ii]
        u = (base[:, None] + cs_r) / e_r
        live = idx >= i_s[:, None]
        stop = live & (u < 0.0)
        stop_any = stop.any(axis=1)
        j = np.where(stop_any, np.argmax(stop, axis=1), n)  # first re-stick sample
        u = np.where(live & (idx < j[:, None]), u, 0.0)
        # displacement: trapezoid of u from t[i_s] on, plus the partial first interval
        du = 0.5 * (u[:, 1:] + u[:, :-1]) * h
        cd = np.concatenate([np.zeros((r_.size, 1)), np.cumsum(du, axis=1)], axis=1)
        cd = cd - cd[rows, ii][:, None]
        disp[r_] += np.where(live, d_is[:, None] + cd, 0.0)
        # after the re-stick the next episode starts at j (or ends the record)
        start[r_] = j
        live_rows = r_[stop_any]
    return disp, onset_first
