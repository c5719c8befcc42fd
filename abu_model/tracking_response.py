"""Exact response of the tracking loop to a prescribed profile (SI, NumPy only).

The ``tracking`` drive (:mod:`controller.drive`) follows the profile omega_p(t)
(:mod:`controller.profile`: a clamped cubic spline, constant outside its knots) through

    G(s) = w / w_p = wb / (tau s^2 + s + wb)          (tau = 0: wb / (s + wb)).

With the poles p_i of the denominator and residues r_i = wb / D'(p_i), w = sum_i r_i x_i with
x_i' = p_i x_i + w_p. On a spline segment w_p is a cubic u(v), v = t - t_k, so each mode is
exact: the particular solution x_p = -(u / p + u' / p^2 + u'' / p^3 + u''' / p^4) plus
(x(t_k) - x_p(t_k)) exp(p v); its integral (for theta) likewise. Nothing is time-stepped:
the cost is O(samples x poles + knots), so the measurement's least squares
(:mod:`measurement.kinematics.profile_model`) and the design's search evaluate it freely.
The rotor alone, as in the report (the ball's reaction neglected). Tests compare it with a
fine ODE solution.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol, Sequence

import numpy as np


class Profile(Protocol):
    """What the response needs of a :class:`controller.profile.Profile` (knots and the
    spline's per-segment power coefficients)."""

    times: Sequence[float]
    omegas: Sequence[float]

    @property
    def coefficients(self) -> list[tuple[float, float, float, float]]: ...


@dataclass(frozen=True)
class TrackingResponse:
    """theta (relative to theta at the first knot) [rad], omega [rad/s], alpha [rad/s^2]
    at the asked times, and the reference omega_p [rad/s] there."""

    theta: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    omega_ref: np.ndarray


def loop_modes(bandwidth: float, tau: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Poles p_i [1/s] and residues r_i [1/s] of wb / (tau s^2 + s + wb)."""
    if tau > 0:
        poles = np.roots([tau, 1.0, bandwidth]).astype(complex)
        if abs(poles[0] - poles[1]) < 1e-7 * abs(poles[0]):   # repeated: split (simple poles)
            poles = poles * np.array([1 + 1e-7, 1 - 1e-7])
        dprime = 2 * tau * poles + 1.0
    else:
        poles = np.array([-bandwidth], dtype=complex)
        dprime = np.ones(1, dtype=complex)
    return poles, bandwidth / dprime


def _segments(profile: Profile) -> tuple[np.ndarray, np.ndarray]:
    """Knot times (n+1) and per-segment power coefficients (n, 4); a constant segment is
    appended after the last knot."""
    coef = np.array(profile.coefficients, dtype=float)
    last = np.array([[profile.omegas[-1], 0.0, 0.0, 0.0]])
    return np.asarray(profile.times, float), np.vstack([coef, last])


def _modal(profile: Profile, t: np.ndarray, bandwidth: float, tau: float):
    """(poles, residues, modal states x_i at t (modes x samples), the reference's
    derivatives u, u', u'', u''' at t (4 x samples), theta at t relative to the first knot)."""
    knots, coef = _segments(profile)
    poles, res = loop_modes(bandwidth, tau)
    p, r = poles[:, None], res[:, None]
    w0 = profile.omegas[0]
    seg = np.searchsorted(knots, t, side="right") - 1       # -1: before the first knot
    th = np.zeros(t.shape)
    xs = np.empty((poles.size, t.size), dtype=complex)
    ud = np.zeros((4, t.size))
    pre = seg < 0                                            # steady state at w0
    th[pre] = w0 * (t[pre] - knots[0])
    x = -w0 / poles                                          # modal states at the knot
    xs[:, pre] = x[:, None]
    ud[0, pre] = w0
    theta_k = 0.0
    for k in range(len(coef)):
        sel = seg == k
        last = k + 1 == len(knots)
        # the samples of this segment, then (except after the last knot) its end
        v = t[sel] - knots[k]
        if not last:
            v = np.append(v, knots[k + 1] - knots[k])
        c0, c1, c2, c3 = coef[k]
        u = c0 + v * (c1 + v * (c2 + v * c3))
        du = c1 + v * (2 * c2 + 3 * c3 * v)
        d2u = 2 * c2 + 6 * c3 * v
        d3u = np.full(v.shape, 6 * c3)
        big_u = v * (c0 + v * (c1 / 2 + v * (c2 / 3 + v * c3 / 4)))
        xp = -(u / p + du / p**2 + d2u / p**3 + d3u / p**4)
        xp0 = -(c0 / p + c1 / p**2 + 2 * c2 / p**3 + 6 * c3 / p**4)
        xm = xp + (x[:, None] - xp0) * np.exp(p * v)
        ixp = -(big_u / p + (u - c0) / p**2 + (du - c1) / p**3 + (d2u - 2 * c2) / p**4)
        ith = theta_k + np.sum(r * (ixp + (x[:, None] - xp0) * np.expm1(p * v) / p),
                               axis=0).real
        n = int(sel.sum())
        xs[:, sel] = xm[:, :n]
        ud[:, sel] = np.vstack([u, du, d2u, d3u])[:, :n]
        th[sel] = ith[:n]
        if not last:   # advance the modal states and theta to the next knot
            x, theta_k = xm[:, -1], float(ith[-1])
    return poles, res, xs, ud, th


def response(profile: Profile, t: np.ndarray, bandwidth: float, tau: float = 0.0,
             gain: float = 1.0) -> TrackingResponse:
    """The loop's exact response at the times t [s] (any order), scaled by ``gain``."""
    t = np.asarray(t, dtype=float)
    poles, res, xs, ud, th = _modal(profile, t, bandwidth, tau)
    p, r = poles[:, None], res[:, None]
    w = np.sum(r * xs, axis=0).real
    a = np.sum(r * (p * xs + ud[0]), axis=0).real
    return TrackingResponse(gain * th, gain * w, gain * a, ud[0])


def alpha_derivatives(profile: Profile, t: np.ndarray, bandwidth: float, tau: float = 0.0,
                      order: int = 3) -> np.ndarray:
    """alpha and its time derivatives up to ``order`` at t: rows alpha, alpha', ... [rad/s^2,
    rad/s^3, ...]. From x_i' = p_i x_i + u: d^k x_i = p^k x_i + sum_j p^(k-1-j) u^(j), so
    alpha^(k) = sum_i r_i (p_i^(k+1) x_i + sum_{j<=k} p_i^(k-j) u^(j)); u^(j) = 0 for j > 3
    (a cubic segment; the spline's third derivative jumps at the knots)."""
    t = np.asarray(t, dtype=float)
    poles, res, xs, ud, _ = _modal(profile, t, bandwidth, tau)
    p, r = poles[:, None], res[:, None]
    out = np.empty((order + 1, t.size))
    for k in range(order + 1):
        acc = p ** (k + 1) * xs
        for j in range(min(k, 3) + 1):
            acc = acc + p ** (k - j) * ud[j]
        out[k] = np.sum(r * acc, axis=0).real
    return out


def reference(profile: Profile, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """omega_p(t) [rad/s] and its rate [rad/s^2] (vectorised spline evaluation)."""
    t = np.asarray(t, dtype=float)
    knots, coef = _segments(profile)
    seg = np.searchsorted(knots, t, side="right") - 1
    v = t - knots[np.maximum(seg, 0)]
    c = coef[np.maximum(seg, 0)]
    u = c[..., 0] + v * (c[..., 1] + v * (c[..., 2] + v * c[..., 3]))
    du = c[..., 1] + v * (2 * c[..., 2] + 3 * c[..., 3] * v)
    pre = seg < 0
    u = np.where(pre, profile.omegas[0], u)
    du = np.where(pre | (seg >= len(knots) - 1), 0.0, du)
    return u, du


__all__ = ["TrackingResponse", "loop_modes", "response", "reference", "alpha_derivatives"]
