"""Noise models of the beta residual for :mod:`measurement.inference.infer_mu`.

White tracking noise (robust sigma from first differences), AR(1), white + a smooth leftover of
the lighting harmonics with exponential correlation (full covariance, whitened by forward
substitution with its Cholesky factor), and the long-run variance factor (Newey-West) of a residual.
"""
from __future__ import annotations

import math

import numpy as np

#: Rows of a Cholesky factor per step of :class:`TriangularWhitener`'s forward substitution.
TRIANGLE_BLOCK = 128


def noise_level(res: np.ndarray) -> float:
    """Robust white-noise sigma of a residual [rad] (MAD of first differences / sqrt 2)."""
    dr = np.diff(res)
    return float(1.4826 * np.median(np.abs(dr - np.median(dr))) / math.sqrt(2.0)) or 1e-12


def ar1(res: np.ndarray) -> float:
    """Lag-1 autocorrelation of a residual, clipped to [0, 0.99]."""
    r = res - res.mean()
    den = float(r @ r)
    if den <= 0:
        return 0.0
    return float(np.clip((r[1:] @ r[:-1]) / den, 0.0, 0.99))


def _leftover_params(res: np.ndarray, h: float, max_tau_s: float) -> tuple[float, float, float]:
    """(sigma_w^2, sigma_L^2, tau) of white noise + an exponentially correlated leftover."""
    r = np.asarray(res, float) - float(np.mean(res))
    n = r.size
    sw2 = noise_level(r) ** 2
    # the excess variance over the white part, also after a 2 ms moving average (which keeps
    # a leftover of milliseconds and divides the white variance by m): a small leftover under
    # large white noise is visible there and not in the raw variance
    m = max(3, int(round(0.002 / h)))
    sm = np.convolve(r, np.ones(m) / m, mode="valid")
    sl2 = max(float(r @ r) / n - sw2, float(sm @ sm) / sm.size - sw2 / m, 0.0)
    tau = h
    if sl2 > 0.0:
        kmax = min(n - 1, int(max_tau_s * 3 / h))
        acov = np.array([float(r[k:] @ r[:-k]) / n for k in range(1, kmax + 1)])
        neg = np.flatnonzero(acov <= 0.0)
        m = int(neg[0]) if neg.size else acov.size
        tau = float(np.clip(h * (0.5 + np.sum(acov[:m]) / sl2), h, max_tau_s))
    return sw2, sl2, tau


def leftover_whitener(res: np.ndarray, h: float, max_tau_s: float = 0.02,
                      record_residual: np.ndarray | None = None,
                      extra_cov: np.ndarray | None = None) -> tuple[TriangularWhitener, dict]:
    """The whitener (inverse Cholesky factor) of white noise + a smooth leftover
    (exponential correlation), and the noise figures.

    Residual = white tracking noise (sigma_w, from first differences, which the smooth part
    hardly moves) + the lighting structure the whole-record harmonic fit leaves on beta
    (sigma_L, its variance the residual's excess over sigma_w^2; correlation time tau, the
    residual's integrated autocorrelation up to its first zero). Covariance
    sigma_w^2 I + sigma_L^2 exp(-|t_i - t_j| / tau). Pure AR(1) fitted to such a sum sees mostly
    the white part at lag 1 and treats a 0.3 mrad, 10 ms structure as nearly white: the
    likelihood then trusts the first mrad of slip too much (misplaced onsets).

    ``record_residual``: the whole-record harmonic fit's residual (monotone b(t) + harmonics);
    the leftover is also estimated on it and the larger sigma_L is used. The fit window's own
    residual is taken at the best model, whose in-window harmonics and slip curve absorb part
    of the leftover: alone it can report none (sigma_L = 0) where the record shows ~0.3 mrad
    over milliseconds (rendered seed 58: then a confidently wrong, 12 ms late onset).
    """
    sw2, sl2, tau = _leftover_params(res, h, max_tau_s)
    if record_residual is not None and np.asarray(record_residual).size > 10:
        _, sl2_r, tau_r = _leftover_params(record_residual, h, max_tau_s)
        if sl2_r > sl2:
            sl2, tau = sl2_r, tau_r
    info = {"sigma_white_rad": math.sqrt(sw2), "sigma_leftover_rad": math.sqrt(sl2),
            "leftover_tau_s": tau}
    return leftover_whitener_of(info, np.asarray(res).size, h, extra_cov), info


def drive_noise_cov(sigma_omega_dot: np.ndarray, rho: np.ndarray | None, h: float, i_on: int,
                    gain: float) -> np.ndarray:
    """Covariance [rad^2] of the slip displacement's error that omega_dot's noise causes.

    In slip the model drives u' = omega^2 (q - mu_d) / 1.4 with the measured q; q's error
    omega^2 dq = gain * d(omega_dot) (gain = (1 - d / (5 l)) / 1.4, omega cancels) is
    integrated twice from the onset sample ``i_on``. Near the onset q - mu_d is a small
    difference (when mu_d ~ mu) and a noise error of a few per cent of q changes the emerging
    slip by tens of per cent: the fit then moves the onset (and mu) instead. omega_dot's
    error: sigma_omega_dot [rad/s^2] per sample, autocorrelation ``rho`` at lags 0, 1, ...
    (``Kinematics.omega_dot_rho``; None: no covariance).
    """
    n = np.asarray(sigma_omega_dot).size
    cov = np.zeros((n, n))
    if rho is None or i_on >= n - 1:
        return cov
    s = np.asarray(sigma_omega_dot, float)[i_on:]
    m = s.size
    r = np.zeros(m)
    k = min(m, np.asarray(rho).size)
    r[:k] = np.asarray(rho, float)[:k]
    c = toeplitz_symmetric(r)
    c *= s[:, None]
    c *= s[None, :]
    for axis in (0, 0, 1, 1):   # D = h^2 * double cumulative sum of the error
        np.cumsum(c, axis=axis, out=c)   # in place: a 3000-sample window's c is 72 MB
    c *= (gain * h * h) ** 2
    cov[i_on:, i_on:] = c
    return cov


def toeplitz_symmetric(first: np.ndarray) -> np.ndarray:
    """The symmetric Toeplitz matrix T[i, j] = first[|i - j|], (n, n): the rows of one
    strided view copied (an index matrix of |i - j| would take n^2 integers more)."""
    first = np.asarray(first, float)
    n = first.size
    both = np.concatenate([first[:0:-1], first])          # first[n-1], ..., first[1], first
    return np.lib.stride_tricks.sliding_window_view(both, n)[::-1].copy()


def leftover_whitener_of(noise: dict, n: int, h: float,
                         extra_cov: np.ndarray | None = None) -> TriangularWhitener:
    """The whitener (inverse Cholesky factor) of the covariance of :func:`leftover_whitener`
    for ``n`` samples of spacing ``h`` [s], from its ``noise`` info (the sigmas [rad], tau
    [s]): the sets of several Savitzky-Golay windows share beta's noise model
    (:mod:`window_sets`)."""
    sw2, sl2 = noise["sigma_white_rad"] ** 2, noise["sigma_leftover_rad"] ** 2
    # Toeplitz: the correlation of each lag |i - j| computed once (the same numbers as the
    # element-wise matrix, n times fewer exponentials)
    cov = toeplitz_symmetric(sl2 * np.exp(-(np.arange(n) * h) / noise["leftover_tau_s"]))
    cov[np.diag_indices(n)] += sw2
    if extra_cov is not None:
        cov = cov + extra_cov
    return TriangularWhitener(np.linalg.cholesky(cov))


class TriangularWhitener:
    """W = L^-1 for the Cholesky factor L of a noise covariance, applied by forward
    substitution by blocks of rows; W itself is never formed (its inverse of a 2884-sample
    factor took 0.4 s of CPU on one core, a third of the whitening it serves).

    ``rows(a)`` whitens each row of ``a`` (``a @ W.T``), ``columns(x)`` each column
    (``W @ x``). Why not SciPy's ``solve_triangular``: it would cost SciPy's import on the
    measure path.
    """

    def __init__(self, lower: np.ndarray, block: int = TRIANGLE_BLOCK) -> None:
        self.lower = np.asarray(lower, float)
        self.block = int(block)
        n = self.lower.shape[0]
        # inverses of the diagonal blocks; the inverse of a trailing part of a lower-
        # triangular block is the trailing part of its inverse (a window started mid-block)
        self._diag_inv = [np.linalg.inv(self.lower[i0:i0 + block, i0:i0 + block])
                          for i0 in range(0, n, block)]

    @property
    def n(self) -> int:
        return self.lower.shape[0]

    def rows(self, a: np.ndarray, start: int = 0) -> np.ndarray:
        """``a @ W.T`` for ``a`` (rows, n) whose columns before ``start`` are zero (the
        whitened ones are then zero too: W is lower triangular)."""
        a = np.asarray(a, float)
        out = np.zeros((a.shape[0], self.n))
        low, b = self.lower, self.block
        for k, d_inv in enumerate(self._diag_inv):
            i0, i1 = k * b, min(self.n, (k + 1) * b)
            if i1 <= start:
                continue
            lo = max(i0, start)
            rhs = a[:, lo:i1] - out[:, start:lo] @ low[lo:i1, start:lo].T
            out[:, lo:i1] = rhs @ d_inv[lo - i0:, lo - i0:].T
        return out

    def columns(self, x: np.ndarray) -> np.ndarray:
        """``W @ x`` for ``x`` (n,) or (n, k)."""
        x = np.asarray(x, float)
        return self.rows(x.reshape(self.n, -1).T).T.reshape(x.shape)

    def matrix(self) -> np.ndarray:
        """W itself, (n, n) (tests and small windows)."""
        return self.columns(np.eye(self.n))


def long_run_factor(res: np.ndarray, lags: int) -> float:
    """Long-run variance / variance of a residual (Bartlett kernel, Newey-West 1987), >= 1.

    What the AR(1) whitening leaves (misfit of the kinematics along the slip, leftover lighting
    structure) is correlated over milliseconds; it inflates the likelihood-ratio statistic by
    this factor (a sum of correlated squares), so the statistic is divided by it.
    """
    r = np.asarray(res, float) - float(np.mean(res))
    g0 = float(r @ r)
    if g0 <= 0.0 or lags < 1:
        return 1.0
    k = np.arange(1, min(int(lags), r.size - 1) + 1)
    acov = np.array([float(r[j:] @ r[:-j]) for j in k])
    return max(1.0, 1.0 + 2.0 * float(np.sum((1.0 - k / (k[-1] + 1.0)) * acov)) / g0)


class Gls:
    """Least squares with nuisance columns profiled out, after AR(1) pre-whitening."""

    def __init__(self, y: np.ndarray, x: np.ndarray, rho: float,
                 whitener: TriangularWhitener | None = None):
        self.rho = float(rho)
        self.whitener = whitener    # a full covariance's (overrides rho)
        self.yw = self.whiten(y[None, :])[0]
        xw = self.whiten(x.T).T
        # orthonormal basis of the whitened nuisance columns (drop collinear ones)
        u, s, _ = np.linalg.svd(xw, full_matrices=False)
        self.q = u[:, s > s[0] * 1e-9]

    def whiten(self, a: np.ndarray) -> np.ndarray:
        if self.whitener is not None:
            # W is lower triangular: columns before a's first non-zero one stay 0 (model
            # rows are 0 while the candidate ball sticks), so only the trailing block is used
            nz = np.flatnonzero(np.any(a != 0.0, axis=0))
            if nz.size == 0:
                return np.zeros_like(a)
            return self.whitener.rows(a, int(nz[0]))
        if self.rho == 0.0:
            return a
        out = np.empty_like(a)
        out[:, 0] = a[:, 0] * math.sqrt(1.0 - self.rho ** 2)
        out[:, 1:] = a[:, 1:] - self.rho * a[:, :-1]
        return out

    def rss(self, model: np.ndarray) -> np.ndarray:
        """Residual sum of squares (whitened) of y - model - nuisances for each row of model."""
        r = self.yw[None, :] - self.whiten(model)
        proj = r @ self.q
        # >= 0: on noise-free tracks the nuisance columns can fit to rounding
        return np.maximum(np.einsum("ij,ij->i", r, r) - np.einsum("ij,ij->i", proj, proj), 0.0)

    def fit(self, model: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """Nuisance-fitted model curve (unwhitened) for one model row."""
        r = self.yw - self.whiten(model[None, :])[0]
        coef = np.linalg.lstsq(self.whiten(x.T).T, r, rcond=None)[0]
        return model + x @ coef
