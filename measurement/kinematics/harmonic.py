"""Removal of the harmonic disturbance on beta at the rotation frequency (report sec. 5.2).

Asymmetric lighting shifts the tracked ball centre by an amount that depends on where the ball is
in the image, so beta carries a disturbance periodic in the ball's angular position (the report's
"harmonic with a frequency close to the rotational velocity"). We model the measured beta as

    beta(t) = b(t) + sum_k [ A_k(t) sin(k phi(t)) + B_k(t) cos(k phi(t)) ] + noise,

with phi the phase angle (by default the ball's angle in the image, theta + beta; theta alone is
the alternative), A_k, B_k slowly varying amplitudes (Legendre polynomials of degree
``amp_degree`` in time) and b(t) the true relative angle. b is *monotone*: the ball sticks
(b constant) or slips in one direction, -sign(omega_dot), while the ABU accelerates one way. So b is
a monotone piecewise-quadratic C1 spline: the integral of non-negative hat functions (linear
B-splines) on knots every ``knot_spacing_s``; it is monotone if and only if its coefficients are
>= 0 (an I-spline basis). All coefficients are found together by bounded linear least squares
(the free coefficients are projected out, the rest is ``scipy.optimize.nnls``). The monotone
constraint is what keeps the harmonic identifiable although the knots are much closer than its
period: a monotone curve cannot oscillate, so it cannot absorb the harmonic, which
unconstrained splines of that flexibility would.

The amplitudes are constant by default (``amp_degree=0``), as the report observed and as a lamp
fixed in the world implies. Higher degrees are possible but weakly identified: while the ball slips
faster than the harmonic's own rate (beta' > A omega), a monotone curve plus a harmonic is still
monotone, so only the stick stretches pin the amplitude, and a free polynomial amplitude then
trades off against the monotone part at the record's ends (we measured spurious harmonics of
5x the noise with degree 2 on a record ending in a slip).

``direction=0`` replaces the monotone basis by an unconstrained cubic B-spline with knots every
``smooth_knot_spacing_s`` (which must exceed the harmonic's period to leave it to the sine terms).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.polynomial import legendre as leg

from abu_model.errors import ParameterError


@dataclass(frozen=True)
class HarmonicFit:
    """Result of :func:`remove_harmonic` (all angles in rad, on the sample times).

    Attributes:
        beta_clean: measured beta minus the fitted harmonic.
        beta_smooth: the fitted smooth (monotone) part b(t).
        harmonic: the fitted harmonic sum.
        amplitude: sqrt(A_1^2 + B_1^2)(t) of the first order [rad].
        residual: beta - beta_smooth - harmonic.
        residual_sigma: robust standard deviation of the residual [rad].
        direction: +1 (b non-decreasing), -1 (non-increasing) or 0 (unconstrained).
        n_parameters: number of fitted coefficients.
    """

    beta_clean: np.ndarray
    beta_smooth: np.ndarray
    harmonic: np.ndarray
    amplitude: np.ndarray
    residual: np.ndarray
    residual_sigma: float
    direction: int
    n_parameters: int


def robust_std(x: np.ndarray) -> float:
    """1.4826 x median absolute deviation: the standard deviation for Gaussian data."""
    x = np.asarray(x, dtype=float)
    return float(1.4826 * np.median(np.abs(x - np.median(x))))


def monotone_basis(time: np.ndarray, knot_spacing_s: float) -> np.ndarray:
    """(N, K) columns rising from 0 to 1: integrals of hat functions on knots every spacing [s]."""
    t = np.asarray(time, dtype=float)
    h = float(knot_spacing_s)
    n_knots = int(np.ceil((t[-1] - t[0]) / h)) + 1
    knots = t[0] + h * np.arange(n_knots)

    def integral(x: np.ndarray) -> np.ndarray:
        # Integral of the unit hat of half-width h centred at 0, from -inf to x.
        out = np.where(x <= -h, 0.0, 0.0)
        out = np.where((x > -h) & (x <= 0.0), (x + h) ** 2 / (2.0 * h), out)
        out = np.where((x > 0.0) & (x <= h), h - (h - x) ** 2 / (2.0 * h), out)
        return np.where(x > h, h, out)

    rel = t[:, None] - knots[None, :]
    cols = integral(rel) - integral(t[0] - knots)[None, :]
    total = cols[-1, :]
    keep = total > 1e-12 * h
    return cols[:, keep] / total[keep]


def nnls(a: np.ndarray, b: np.ndarray, maxiter: int | None = None) -> tuple[np.ndarray, float]:
    """min ||a x - b|| subject to x >= 0: Lawson & Hanson's active-set algorithm (1974, ch. 23).

    NumPy only, so that ``abu measure`` does not import ``scipy.optimize`` (~0.3-1 s on the
    development machine, more than the fit); the same algorithm as ``scipy.optimize.nnls``,
    checked against it in tests/test_harmonic_nnls.py. Returns (x, residual norm).
    """
    a = np.asarray(a, dtype=float)
    b = np.asarray(b, dtype=float)
    m, n = a.shape
    maxiter = 3 * n if maxiter is None else int(maxiter)
    x = np.zeros(n)
    passive = np.zeros(n, dtype=bool)
    w = a.T @ (b - a @ x)
    tol = 10.0 * np.finfo(float).eps * np.linalg.norm(a, 1) * max(m, n)
    it = 0
    while (~passive).any() and np.max(np.where(passive, -np.inf, w)) > tol and it < maxiter:
        j = int(np.argmax(np.where(passive, -np.inf, w)))
        passive[j] = True
        while True:
            it += 1
            z = np.zeros(n)
            z[passive] = np.linalg.lstsq(a[:, passive], b, rcond=None)[0]
            if np.all(z[passive] > 0) or it >= maxiter:
                x = z
                break
            # step back to the feasible boundary and drop the variables that hit zero
            neg = passive & (z <= 0)
            alpha = np.min(x[neg] / (x[neg] - z[neg]))
            x = x + alpha * (z - x)
            passive &= x > tol
            x[~passive] = 0.0
        w = a.T @ (b - a @ x)
    return x, float(np.linalg.norm(a @ x - b))


def _smooth_basis(time: np.ndarray, knot_spacing_s: float) -> np.ndarray:
    from scipy.interpolate import BSpline  # only for direction=0 (not the default path)
    t = np.asarray(time, dtype=float)
    k = 3
    n_int = max(1, int(np.ceil((t[-1] - t[0]) / knot_spacing_s)))
    inner = np.linspace(t[0], t[-1], n_int + 1)
    knots = np.r_[[inner[0]] * k, inner, [inner[-1]] * k]
    return BSpline.design_matrix(t, knots, k).toarray()


def harmonic_basis(time: np.ndarray, phase: np.ndarray, orders: tuple[int, ...],
                   amp_degree: int) -> np.ndarray:
    """(N, 2 * len(orders) * (amp_degree + 1)) columns P_j(s) sin(k phi), P_j(s) cos(k phi)."""
    t = np.asarray(time, dtype=float)
    s = 2.0 * (t - t[0]) / (t[-1] - t[0]) - 1.0
    amp = leg.legvander(s, amp_degree)
    cols = []
    for k in orders:
        sin_k, cos_k = np.sin(k * phase), np.cos(k * phase)
        cols += [amp * sin_k[:, None], amp * cos_k[:, None]]
    return np.hstack(cols)


def _partly_nonnegative_lstsq(design: np.ndarray, target: np.ndarray,
                              nonneg: slice) -> np.ndarray:
    """min ||design x - target|| with x[nonneg] >= 0 and the other coefficients free.

    The free columns are projected out (QR), the constrained problem is reduced to its
    triangular (Cholesky) factor and solved by Lawson-Hanson NNLS; then the free coefficients
    follow.
    """
    idx = np.arange(design.shape[1])
    cons = idx[nonneg]
    free = np.setdiff1d(idx, cons)
    a_free, a_cons = design[:, free], design[:, cons]
    q, _ = np.linalg.qr(a_free)
    a_proj = a_cons - q @ (q.T @ a_cons)
    b_proj = target - q @ (q.T @ target)
    # Triangular factor from the Gram matrix (much cheaper than a QR of the tall matrix; the
    # I-spline columns are well enough conditioned for it).
    r2 = np.linalg.cholesky(a_proj.T @ a_proj).T           # upper triangular, r2^T r2 = G
    rhs = np.linalg.solve(r2.T, a_proj.T @ b_proj)
    x_cons, _ = nnls(r2, rhs, maxiter=50 * len(cons))
    x_free, *_ = np.linalg.lstsq(a_free, target - a_cons @ x_cons, rcond=None)
    coef = np.empty(design.shape[1])
    coef[cons] = x_cons
    coef[free] = x_free
    return coef


def remove_harmonic(time: np.ndarray, beta: np.ndarray, phase: np.ndarray, *,
                    orders: tuple[int, ...] = (1,), amp_degree: int = 0,
                    knot_spacing_s: float = 0.005, direction: int | None = None,
                    smooth_knot_spacing_s: float = 0.15) -> HarmonicFit:
    """Fit and remove the harmonic disturbance on beta (see the module docstring).

    Args:
        time: sample times [s].
        beta: measured relative angle [rad].
        phase: phase angle of the disturbance [rad] (ball angle in the image, or theta).
        orders: harmonic orders fitted (1 = rotation frequency; add 2 for its double).
        amp_degree: degree in time of the amplitudes' Legendre polynomials.
        knot_spacing_s: knot spacing of the monotone basis [s].
        direction: +1 / -1 monotone b, 0 unconstrained smooth b, None: both monotone
            directions are fitted and the smaller residual wins.
        smooth_knot_spacing_s: knot spacing of the unconstrained basis [s] (direction=0).
    """
    t = np.asarray(time, dtype=float)
    b = np.asarray(beta, dtype=float)
    phi = np.asarray(phase, dtype=float)
    if not (t.shape == b.shape == phi.shape) or t.ndim != 1:
        raise ParameterError("beta", f"shapes {t.shape}, {b.shape}, {phi.shape}",
                             "time, beta and phase of the same length")
    if amp_degree < 0:
        raise ParameterError("harmonic_amp_degree", amp_degree, "an integer >= 0")
    if any(int(k) < 1 for k in orders):
        raise ParameterError("harmonic_orders", orders, "orders >= 1")
    if not knot_spacing_s > 0:
        raise ParameterError("knot_spacing_s", knot_spacing_s, "> 0 s")
    if direction is None:
        fits = [remove_harmonic(t, b, phi, orders=orders, amp_degree=amp_degree,
                                knot_spacing_s=knot_spacing_s, direction=sgn)
                for sgn in (+1, -1)]
        return min(fits, key=lambda f: float(np.sum(f.residual ** 2)))
    if direction not in (-1, 0, 1):
        raise ParameterError("direction", direction, "-1, 0, +1 or None")

    harm = harmonic_basis(t, phi, tuple(int(k) for k in orders), amp_degree) if orders else \
        np.zeros((t.size, 0))
    if direction == 0:
        smooth = _smooth_basis(t, smooth_knot_spacing_s)
        design = np.hstack([smooth, harm])
        coef, *_ = np.linalg.lstsq(design, b, rcond=None)
        n_smooth = smooth.shape[1]
    else:
        mono = direction * monotone_basis(t, knot_spacing_s)
        smooth = np.hstack([np.ones((t.size, 1)), mono])
        design = np.hstack([smooth, harm])
        n_smooth = smooth.shape[1]
        coef = _partly_nonnegative_lstsq(design, b, nonneg=slice(1, n_smooth))
    beta_smooth = smooth @ coef[:n_smooth]
    harmonic = harm @ coef[n_smooth:]
    if orders:
        na = amp_degree + 1
        s = 2.0 * (t - t[0]) / (t[-1] - t[0]) - 1.0
        a_sin = leg.legval(s, coef[n_smooth: n_smooth + na])
        a_cos = leg.legval(s, coef[n_smooth + na: n_smooth + 2 * na])
        amplitude = np.hypot(a_sin, a_cos)
    else:
        amplitude = np.zeros_like(t)
    residual = b - beta_smooth - harmonic
    n_par = design.shape[1]
    sigma = robust_std(residual) * np.sqrt(t.size / max(t.size - n_par, 1))
    return HarmonicFit(beta_clean=b - harmonic, beta_smooth=beta_smooth, harmonic=harmonic,
                       amplitude=amplitude, residual=residual, residual_sigma=float(sigma),
                       direction=int(direction), n_parameters=int(n_par))
