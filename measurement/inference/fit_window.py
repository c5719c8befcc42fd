"""The samples :func:`measurement.inference.infer_mu.infer_mu` fits: trusted region, candidate
grid of mu and the end of the fit window."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from measurement.inference.noise_models import noise_level
from measurement.inference.slip_model import signed_mu_req
from measurement.inference.types import MU_D_RATIO, InferenceOptions


def harmonic_design(theta: np.ndarray, phi: np.ndarray, orders: tuple[int, ...],
                    with_theta: bool) -> np.ndarray:
    """Nuisance columns: offset b0 and sin/cos k phi (and k theta) for each order k."""
    cols = [np.ones_like(phi)]
    for k in orders:
        cols += [np.sin(k * phi), np.cos(k * phi)]
        if with_theta:
            cols += [np.sin(k * theta), np.cos(k * theta)]
    return np.stack(cols, axis=1)


@dataclass(frozen=True)
class Window:
    """Samples [region.start, region.start + t.size) of the record, inside the trusted region.

    Attributes:
        region: the trusted region in the record (the window may end before it).
        t: times [s]; theta, beta: measured angles [rad]; omega: ABU speed [rad/s].
        q: signed mu_req [1]; x: nuisance columns (:func:`harmonic_design`).
    """

    region: slice
    t: np.ndarray
    theta: np.ndarray
    beta: np.ndarray
    omega: np.ndarray
    q: np.ndarray
    x: np.ndarray

    @property
    def i0(self) -> int:
        """First sample of the window in the record."""
        return self.region.start

    @property
    def dof(self) -> int:
        """Degrees of freedom of beta's residual variance in the window (>= 1): samples less
        the nuisance columns, mu and mu_d."""
        return max(self.t.size - self.x.shape[1] - 2, 1)

    def head(self, n: int) -> "Window":
        """The first ``n`` samples."""
        return Window(self.region, self.t[:n], self.theta[:n], self.beta[:n], self.omega[:n],
                      self.q[:n], self.x[:n])


@dataclass(frozen=True)
class TrustedRegion:
    """The whole trusted region and the reach of its q [1] (set before the window is cut)."""

    window: Window
    run_max: np.ndarray   #: running maximum of q [1]
    q_first: float        #: first q, floored at 1e-6 [1]
    q_top: float          #: largest q [1]

    def from_sample(self, k: int) -> "TrustedRegion":
        """The region from its sample ``k`` on, as if the trusted run started there."""
        w = self.window
        q = w.q[k:]
        run_max = np.maximum.accumulate(q)
        return TrustedRegion(Window(slice(w.region.start + k, w.region.stop), w.t[k:],
                                    w.theta[k:], w.beta[k:], w.omega[k:], q, w.x[k:]),
                             run_max, float(max(q[0], 1e-6)), float(run_max[-1]))


def trusted_region(time: np.ndarray, theta: np.ndarray, beta: np.ndarray, omega: np.ndarray,
                   omega_dot: np.ndarray, trusted: np.ndarray, l: float, d: float,
                   direction: int, opt: InferenceOptions) -> TrustedRegion:
    """The record's trusted run [s, rad, rad/s] with q and its nuisance columns."""
    idx = np.flatnonzero(trusted)
    i0, i1 = int(idx[0]), int(idx[-1]) + 1
    t = np.asarray(time, float)[i0:i1]
    th = np.asarray(theta, float)[i0:i1]
    y = np.asarray(beta, float)[i0:i1]
    w = np.asarray(omega, float)[i0:i1]
    q = signed_mu_req(w, np.asarray(omega_dot, float)[i0:i1], l, d, direction)
    x = harmonic_design(th, y + th, tuple(opt.harmonic_orders), opt.theta_harmonics)
    run_max = np.maximum.accumulate(q)
    return TrustedRegion(Window(slice(i0, i1), t, th, y, w, q, x), run_max,
                         float(max(q[0], 1e-6)), float(run_max[-1]))


def candidate_grid(region: TrustedRegion, opt: InferenceOptions
                   ) -> tuple[np.ndarray, np.ndarray]:
    """(mu grid [1], mu_d / mu grid [1]) of the coarse search: mu from just below the first
    trusted q to above the record's maximum."""
    q0, q_first, q_top = region.window.q[0], region.q_first, region.q_top
    lo_mu = 0.9 * q_first if q0 > 0 else max(q_top * 1e-3, 1e-6)
    hi_mu = q_top * 1.001 if q_top > 0 else 1e-3
    if hi_mu <= lo_mu:
        hi_mu = lo_mu * 1.01
    ratios = np.linspace(MU_D_RATIO[0], MU_D_RATIO[1], int(opt.n_mu_d))
    mu_grid = np.unique(np.r_[np.geomspace(lo_mu, hi_mu, int(opt.n_mu)), hi_mu * 1.05])
    return mu_grid, ratios


def first_move(region: TrustedRegion, deviation: np.ndarray | None, sigmas: float,
               opt: InferenceOptions) -> int | None:
    """First sample of ``region`` where the data (harmonic-cleaned, smoothed ``deviation``
    [rad] over the record) have moved ``sigmas`` white-noise sigmas of beta from where they
    were at the region's start; None: never (or no deviation given)."""
    if deviation is None:
        return None
    # floor: noise-free tracks would end the window before the slip is visible
    sig_b = max(noise_level(region.window.beta), float(opt.sigma_floor_rad))
    dev = np.asarray(deviation, float)[region.window.region]
    # moved from where it was at the start of the trusted region (not from the stick level of
    # the record's first frames: the ball may already slide there)
    moved = np.flatnonzero(np.abs(dev - dev[0]) > sigmas * sig_b)
    return int(moved[0]) if moved.size else None


def fit_window(region: TrustedRegion, deviation: np.ndarray | None,
               opt: InferenceOptions) -> Window:
    """The trusted region cut where the data have left the stick level.

    The information on mu is in the stick stretch and the first few mrad of slip; far into the
    slip the predicted displacement (up to radians) carries the ~1 % kinematic error of q as a
    misfit of many noise sigmas, which the likelihood would wrongly blame on mu. So the fit
    window ends where the data (harmonic-cleaned, smoothed ``deviation`` [rad]) have moved
    ``window_sigmas`` white-noise sigmas of beta from the stick level.
    """
    win = region.window
    t, x = win.t, win.x
    moved = first_move(region, deviation, opt.window_sigmas, opt)
    n_fit = t.size if moved is None else moved + 1
    # at least 20 ms: a ball already moving at the start must be seen to move
    n_fit = max(n_fit, min(t.size, max(2 * x.shape[1] + 40, int(round(0.02 / (t[1] - t[0]))))))
    return win.head(n_fit)


#: The deviation [white-noise sigmas of beta] that marks where a capped window is centred: far
#: above the smoothed deviation's noise (its sigma is ~4x below beta's), well below where the
#: fit window ends (``window_sigmas``), so the first visible move of the slip.
_MOVE_SIGMAS = 5.0


def capped_window(region: TrustedRegion, win: Window, deviation: np.ndarray | None,
                  opt: InferenceOptions) -> tuple[TrustedRegion, Window, dict]:
    """(region, window, cut) with at most ``opt.max_fit_samples`` samples in the window;
    ``cut``: {} when ``win`` is short enough, else where the window was cut [samples, s].

    The noise model's dense covariances cost n^2 memory and n^3 time: a window of 8000 samples
    takes 2.5 GB and 20 s, one of 20000 would not fit a laptop. Such windows arise from long
    records (a ball that slips a little and sticks again never moves ``window_sigmas`` away, a
    late slip). What the data say of mu lies where the ball first moves: the stick stretch
    before it (the lower bound) and the first milliseconds of slip (the upper bound). A window
    that ends where the data left the stick level keeps its end and loses its head. One that
    runs to the region's end (the data never left it: the ball slipped a little and stuck
    again, or never slipped) ends a quarter of the cap after the first move of
    ``_MOVE_SIGMAS`` sigmas (without one, after the largest q, where "stuck" says most).
    The region starts with the window, as if the trusted run started there: the fit is then
    that of a shorter record, with its honesty; what the dropped head said (a lower q's
    stick) is lost, never double-counted.
    """
    n_max = int(opt.max_fit_samples)
    if win.t.size <= n_max:
        return region, win, {}
    end = win.t.size
    if end == region.window.t.size:
        anchor = first_move(region, deviation, _MOVE_SIGMAS, opt)
        if anchor is None:
            anchor = int(np.argmax(win.q))
        end = min(end, max(anchor + n_max // 4, n_max))
    region = region.from_sample(end - n_max)
    # the later region's window: the same end where the data left the stick level (now
    # measured from the new start, within a sample or two), else cut at the anchor's
    cut = fit_window(region, deviation, opt).head(n_max)
    return region, cut, {"uncut_samples": int(win.t.size), "samples": int(cut.t.size),
                         "start_s": float(cut.t[0]), "end_s": float(cut.t[-1])}
