"""The lighting leftover on beta beyond the fitted harmonic orders, as a random effect.

The ball's apparent centre moves with its angle under the lamps, phi = theta + beta (the
ball's absolute angle): periodic in phi. The whole-record fit removes orders 1-4 of it; what
is left (orders 5-12 of 0.3-1 mrad on the harsh twin's two-spot and blurred balls) is not
noise that decorrelates in milliseconds: at 50-130 rad/s an order-5 term has a period of
10-25 ms and, inside the fit window, looks like the start of a slip. Fitting these orders
freely moves the record's slip into them (tried: new misses of 4.6 % and 23 % on unseen
recordings); leaving them to the exponential leftover model treats them as short-correlated
and lets them move the onset (misses of 7-17 %).

Here each order's sine and cosine coefficient inside the fit window is a random effect: zero
mean, variance the order's squared amplitude in the whole record's residual (the record spans
many revolutions, so the orders separate there; the window's own coefficients may differ,
which a variance of the full squared amplitude per coefficient allows). Its covariance
H diag(var) H^T joins beta's noise covariance: the likelihood no longer reads such a term as
a slip, and nothing is subtracted from the data. The exponential leftover's sigma and tau are
still estimated on residuals with these orders in: counted twice, which widens rather than
narrows. (Removing them first let the exponential part shrink to white noise where the
leftover is not periodic in phi: kept tracks of seeds 2046 and 3011 then missed mu by 35 % and
4 %, against 16 % and 1.9 % with both.)
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from measurement.inference.noise_models import noise_level

#: An order enters when its amplitude in the record exceeds this many standard deviations of
#: a white-noise sinusoid's fitted amplitude over the fit window.
DETECT_SIGMAS = 3.0


@dataclass(frozen=True)
class HarmonicLeftover:
    """Random-effect lighting orders over a fit window.

    Attributes:
        orders: harmonic orders k of phi.
        var_rad2: (2 * len(orders),) variance of each coefficient (sin k phi, cos k phi) [rad^2].
        columns: (n, 2 * len(orders)) sin k phi, cos k phi over the window.
    """

    orders: tuple[int, ...]
    var_rad2: np.ndarray
    columns: np.ndarray

    def amplitudes_rad(self) -> dict[str, float]:
        """Order -> the amplitude [rad] in the record (what ``summary.json`` reports)."""
        return {str(k): float(np.sqrt(v)) for k, v in zip(self.orders, self.var_rad2[0::2])}

    def cov(self) -> np.ndarray:
        """Covariance of the window's leftover [rad^2], (n, n)."""
        return (self.columns * self.var_rad2) @ self.columns.T


def columns(phase: np.ndarray, orders: tuple[int, ...]) -> np.ndarray:
    """(n, 2 * len(orders)) sin k phase, cos k phase."""
    phase = np.asarray(phase, float)
    return np.stack([f(k * phase) for k in orders for f in (np.sin, np.cos)], axis=1)


def harmonic_leftover(phase_record: np.ndarray, record_residual: np.ndarray,
                      window: slice, orders: tuple[int, ...]) -> HarmonicLeftover | None:
    """The random-effect orders of the record's residual (``phase_record`` phi [rad] and the
    residual [rad] over the whole record, NaN where not fitted) over ``window`` (a slice of
    the record); None without orders or usable samples."""
    res = np.asarray(record_residual, float)
    phase_record = np.asarray(phase_record, float)
    ok = np.isfinite(res) & np.isfinite(phase_record)
    if not orders or ok.sum() < 4 * len(orders) + 10:
        return None
    h_rec = columns(np.where(ok, phase_record, 0.0), tuple(orders))
    r = res[ok] - float(np.mean(res[ok]))
    coef = np.linalg.lstsq(h_rec[ok], r, rcond=None)[0]
    amp2 = coef[0::2] ** 2 + coef[1::2] ** 2          # squared amplitude of each order
    # an order the window's white noise hides (amplitude below DETECT_SIGMAS of what the
    # noise alone gives a sinusoid's amplitude over the window, sigma_w sqrt(2 / n)) cannot
    # pass for a slip there either; as a random effect it would only fit that noise
    n_win = len(range(*window.indices(res.size)))
    floor = DETECT_SIGMAS * noise_level(r) * math.sqrt(2.0 / max(n_win, 1))
    keep = amp2 > floor ** 2
    if not keep.any():
        return None
    var = np.repeat(amp2[keep], 2)                     # each coefficient: the full amplitude^2
    cols = h_rec[window][:, np.repeat(keep, 2)]
    return HarmonicLeftover(tuple(int(k) for k, o in zip(orders, keep) if o), var, cols)
