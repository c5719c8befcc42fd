"""Model-based inference of (mu, mu_d) from one record: a profile likelihood on beta(t).

The ball's equations (DESIGN sec. 2, ``abu_model.dynamics``) driven by the measured ABU motion
predict beta(t) for every candidate pair (mu, mu_d):

* stick while the friction the ball needs stays within mu: q(t) <= mu, with
  q(t) = (l - d/5) (-s omega_dot) / (l omega^2) the signed mu_req and s the slip direction;
* from the first time q crosses mu (located between samples by linear interpolation), the slip
  speed u = s beta' obeys 1.4 l u' = (l - d/5)(-s omega_dot) - mu_d F_N/m with
  F_N/m = l (omega + s u)^2 + 0.4 l u^2 - 0.2 d omega s u, linearised in u/omega (u is a few
  per cent of omega): u' = [omega^2 (q - mu_d) - mu_d s omega (2 - 0.2 d/l) u] / 1.4. That linear
  ODE is solved for all candidates at once with an integrating factor and cumulative sums (no
  per-sample Python loop); the ball re-sticks where u returns to 0 and may slip again when q
  exceeds mu again (a few episodes, looped over episodes, not samples).

Measured beta = b0 + s D(t; mu, mu_d) + sum_k [A_k sin k phi + B_k cos k phi
+ C_k sin k theta + E_k cos k theta] + noise, with phi = theta + beta the ball's angle in the
image (lamps fixed in the world shade the ball, report sec. 5.2; several reflections give higher
orders) and theta (the CD marker's apparent centre). b0 and the harmonic amplitudes enter
linearly and are profiled out by least squares. The noise is coloured: white tracking noise
plus the smooth leftover of the lighting structure the whole-record harmonic fit leaves on beta
(exponential correlation; both sizes and the correlation time estimated from the first fit's
residual, ``noise_models.leftover_whitener``); the fit is generalised least squares with that
covariance (``noise_model="ar1"``: the former AR(1) whitening), plus the error that
omega_dot's noise puts on the predicted slip (integrated twice from the best first-pass
onset, ``drive_noise``: near the onset the drive q - mu_d is a small difference, so a few per
cent of noise on q are tens of per cent of the emerging slip). mu_d is profiled out by a
shrinking grid per mu (to 1e-4 of mu; a coarse mu_d grid made the profile narrow and wrong).
The profile likelihood ratio of mu against chi^2_1 at the
stated confidence gives the set of mu the beta data allow *given* the measured kinematics.

The kinematics themselves are uncertain: mu enters the model only through q, which scales with
omega_dot / omega^2, so an error e on q is an error e on mu. The noise part of e (omega,
omega_dot noise; 1-sigma as the estimator states it) is a Gaussian nuisance independent of
beta's noise, profiled out of the likelihood (:func:`scale_nuisance_bounds`): a flat-bottomed
profile gets the full z sigma, a sharp one about the quadrature sum. For the upper bound sigma
is q's at the slip; the lower bound is set by the largest q over the stick stretch, so its
sigma is q's where q peaks there and its quantile the Rice sup quantile of the error over the
part of the stretch within reach of the bound (:mod:`sup_noise`), not the pointwise z. Added
linearly: the estimator's truncation-error bound (Richardson, ``kinematics``) and the omega_dot
error A omega^2 of a systematic first harmonic of theta of prior amplitude A
(``theta_harmonic_rad``: lens distortion about an optical centre off the ABU axis moves the CD
marker along its circle; the circle fit of the axis cannot see it). mu_d's interval keeps z
sigma added linearly (its set is taken on a coarser grid).

Null bounds (``status`` says why): the data allow a ball that never slips within the trusted
region (upper bound null); they allow a ball already slipping at its start (lower bound null);
the ball or CD marker was lost (interpolated) across the slip (both null).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from statistics import NormalDist

from measurement.inference.types import LOST_ACROSS_SLIP, MU_D_RATIO, Inference, InferenceOptions  # noqa: F401
from measurement.inference.noise_models import Gls as _Gls, ar1 as _ar1, leftover_whitener, long_run_factor  # noqa: F401
from measurement.inference.noise_models import drive_noise_cov, leftover_whitener_of
from measurement.inference.lighting_leftover import HarmonicLeftover, harmonic_leftover
from measurement.inference.noise_models import noise_level  # noqa: F401 (re-exported)
from measurement.inference import sup_noise  # noqa: F401
from measurement.inference.slip_model import signed_mu_req, slip_displacement  # noqa: F401 (re-exported)
from measurement.inference.fit_window import harmonic_design as _harmonic_design  # noqa: F401
from measurement.inference.fit_window import (TrustedRegion, Window, candidate_grid,
                                              capped_window, fit_window, trusted_region)
from measurement.inference.kinematic_nuisance import (KinematicErrors, KinematicNuisance,
                                                      kinematic_nuisance, scale_nuisance_bounds)
from measurement.inference.profile_cache import MuDProfile, SlipModelCache


@dataclass(frozen=True, eq=False)
class _NoiseFit:
    """The fit with beta's noise model: its GLS, profile RSS [rad^2] and best mu_d / mu."""

    gls: _Gls
    rss: np.ndarray
    rbest: np.ndarray     #: the first (white-noise) pass's best mu_d / mu where there is one
    rho: float            #: AR(1) coefficient of the first fit's residual [1]
    noise_info: dict      #: leftover noise model (``noise_models.leftover_whitener``)


@dataclass(frozen=True, eq=False)
class _ProfileSet:
    """The profile likelihood's confidence set on the refined mu grid."""

    mu_grid: np.ndarray   #: candidate mu [1]
    rss: np.ndarray       #: profile RSS per mu [rad^2]
    best: int             #: index of the best mu
    sig2: float           #: residual variance per degree of freedom [rad^2]
    stat: np.ndarray      #: likelihood-ratio statistic per mu [1]
    ok: np.ndarray        #: indices of the accepted mu

    @property
    def mu_hat(self) -> float:
        return float(self.mu_grid[self.best])

    @property
    def low(self) -> float:
        """Lowest accepted mu, before the kinematic nuisance [1]."""
        return float(self.mu_grid[self.ok[0]])

    @property
    def high(self) -> float:
        """Highest accepted mu, before the kinematic nuisance [1]."""
        return float(self.mu_grid[self.ok[-1]])


def _best_model(models: SlipModelCache, mu_grid: np.ndarray, rss: np.ndarray,
                rbest: np.ndarray) -> np.ndarray:
    """Model row [rad] at the profile's best mu and its best mu_d."""
    best = int(np.argmin(rss))
    m_best, _ = models.rows(mu_grid[best: best + 1], mu_grid[best: best + 1]
                            * rbest[best: best + 1])
    return m_best[0]


def _drive_cov(win: Window, models: SlipModelCache, mu: float, mu_d: float,
               drive: tuple[np.ndarray, np.ndarray | None] | None) -> np.ndarray | None:
    """Covariance [rad^2] of the predicted slip from omega_dot's noise, from the onset of the
    pair (mu, mu_d) (:func:`noise_models.drive_noise_cov`); None without it."""
    if drive is None:
        return None
    _, i_on = _slip_onset(models, win, mu, mu_d)
    if i_on is None:
        return None
    sig = np.asarray(drive[0], float)[win.i0:win.i0 + win.t.size]
    return drive_noise_cov(sig, drive[1], float(win.t[1] - win.t[0]), i_on,
                           (1.0 - 0.2 * models.d_over_l) / 1.4)


def _fit_noise_model(win: Window, mu_grid: np.ndarray, ratios: np.ndarray,
                     profile: MuDProfile, noise: dict | None,
                     record_residual: np.ndarray | None, opt: InferenceOptions,
                     drive: tuple[np.ndarray, np.ndarray | None] | None = None,
                     lighting: HarmonicLeftover | None = None) -> _NoiseFit:
    """Profile under beta's noise model: the given one, else estimated from the residual of a
    first, white-noise fit (``ar1`` or ``leftover``; ``ar_order_max`` 0: white). ``drive``:
    (sigma_omega_dot [rad/s^2] over the record, its autocorrelation): with the leftover model,
    the noise of the predicted slip from the best first-pass pair's onset is added;
    ``lighting``: the lighting orders beyond the fitted ones, as a random effect
    (:mod:`lighting_leftover`)."""
    t, y, x = win.t, win.beta, win.x
    if noise is not None and opt.ar_order_max >= 1 and opt.noise_model == "leftover":
        # the sets of several kinematics windows share the record's noise model
        info = {k: noise[k] for k in ("sigma_white_rad", "sigma_leftover_rad", "leftover_tau_s")}
        gls = _Gls(y, x, 0.0, leftover_whitener_of(info, t.size, float(t[1] - t[0]),
                                                   None if lighting is None else lighting.cov()))
        rss, rbest = profile(mu_grid, gls, ratios)
        return _NoiseFit(gls, rss, rbest, 0.0, info)
    gls = _Gls(y, x, 0.0)
    rss, rbest = profile(mu_grid, gls, ratios)
    # computed even when unused (white noise): it fills the model cache in the same order as
    # ever, and the batching of that cache's integrations shows in the last bits
    m_best = _best_model(profile.models, mu_grid, rss, rbest)
    if not opt.ar_order_max >= 1:
        return _NoiseFit(gls, rss, rbest, 0.0, {})
    fitted = gls.fit(m_best, x, y)
    rho = _ar1(y - fitted)
    info = {}
    if opt.noise_model == "leftover":
        rec = None if record_residual is None else \
            np.asarray(record_residual, float)[win.region]
        b = int(np.argmin(rss))
        extra = _drive_cov(win, profile.models, float(mu_grid[b]), float(mu_grid[b] * rbest[b]),
                           drive)
        if lighting is not None:
            extra = lighting.cov() if extra is None else extra + lighting.cov()
        whitener, info = leftover_whitener(y - fitted, float(t[1] - t[0]),
                                           record_residual=rec, extra_cov=extra)
        gls = _Gls(y, x, 0.0, whitener)
        if lighting is not None:
            info["lighting_leftover_amp_rad"] = lighting.amplitudes_rad()
    else:
        gls = _Gls(y, x, rho)
    rss, _ = profile(mu_grid, gls, ratios)  # rbest stays the white-noise pass's
    return _NoiseFit(gls, rss, rbest, rho, info)


def _long_run_factor(win: Window, fit: _NoiseFit, mu_grid: np.ndarray,
                     models: SlipModelCache, opt: InferenceOptions) -> float:
    """Long-run variance factor of the whitened residual (``lrv_window_s`` > 0), else 1."""
    lrf = 1.0
    if opt.lrv_window_s > 0:
        t, y, x, gls = win.t, win.beta, win.x, fit.gls
        m_best = _best_model(models, mu_grid, fit.rss, fit.rbest)
        res_w = gls.whiten((y - gls.fit(m_best, x, y))[None, :])[0]
        lrf = long_run_factor(res_w, int(round(opt.lrv_window_s / (t[1] - t[0]))))
    return lrf


def _noise_variance(rss: np.ndarray, best: int, lrf: float, win: Window) -> float:
    """Residual variance per degree of freedom at the best mu [rad^2] (times ``lrf``)."""
    return max(lrf * float(rss[best]) / win.dof, 1e-300)


def _refine_mu_grid(mu_grid: np.ndarray, fit: _NoiseFit, lrf: float, win: Window,
                    ratios: np.ndarray, profile: MuDProfile, crit: float,
                    opt: InferenceOptions) -> tuple[np.ndarray, np.ndarray]:
    """(mu grid, profile RSS): a finer mu grid around the acceptance region and minimum."""
    rss = fit.rss
    for _ in range(2):
        best = int(np.argmin(rss))
        stat = (rss - rss[best]) / _noise_variance(rss, best, lrf, win)
        ok = np.flatnonzero(stat <= crit)
        a = mu_grid[max(ok[0] - 1, 0)]
        b = mu_grid[min(ok[-1] + 1, mu_grid.size - 1)]
        extra = np.geomspace(a, b, int(opt.n_mu)) if b > a else np.array([a])
        mu_grid = np.unique(np.r_[mu_grid, extra])
        rss, _ = profile(mu_grid, fit.gls, ratios)
    return mu_grid, rss


def _accepted_set(mu_grid: np.ndarray, rss: np.ndarray, lrf: float, win: Window,
                  crit: float) -> _ProfileSet:
    """The candidates whose likelihood-ratio statistic stays within ``crit``."""
    best = int(np.argmin(rss))
    sig2 = _noise_variance(rss, best, lrf, win)
    stat = (rss - rss[best]) / sig2
    return _ProfileSet(mu_grid, rss, best, sig2, stat, np.flatnonzero(stat <= crit))


def _null_hypotheses(pset: _ProfileSet, region: TrustedRegion, kin: KinematicErrors,
                     z: float) -> tuple[bool, bool]:
    """("never slips" not rejected, "slipping from the start" not rejected)."""
    no_slip_ok = bool(pset.high >= region.q_top)
    # "slipping from the start" not rejected: the lowest accepted mu lies below the first
    # trusted q by more than q's own kinematic noise there (within it, a candidate that "slips"
    # from the start with mu_d ~ mu barely moves: the ball sticking at q_first, e.g. on the
    # plateau of a first setpoint step, which the start of the trusted region may just reach)
    rel0 = kin.relative_error(0)[0]
    at_start_ok = bool(pset.low <= region.q_first * (1.0 - min(z * rel0, 0.05)))
    return no_slip_ok, at_start_ok


def _mu_d_set(pset: _ProfileSet, gls: _Gls, models: SlipModelCache,
              crit: float) -> tuple[np.ndarray, float]:
    """(accepted mu_d [1], best mu_d [1]): profile over mu on a finer ratio grid near the
    accepted mu."""
    near = pset.mu_grid[pset.ok]
    if near.size > 12:
        near = near[np.linspace(0, near.size - 1, 12).astype(int)]
    fine_r = np.linspace(MU_D_RATIO[0], MU_D_RATIO[1], 36)
    mu_all = np.repeat(near, fine_r.size)
    mud_all = mu_all * np.tile(fine_r, near.size)
    m_all, _ = models.rows(mu_all, mud_all)
    rss_d = gls.rss(m_all).reshape(near.size, fine_r.size)
    rmin = min(float(rss_d.min()), float(pset.rss[pset.best]))
    stat_d = (rss_d - rmin) / pset.sig2
    mud_acc = mud_all.reshape(near.size, fine_r.size)[stat_d <= crit]
    jb = np.unravel_index(int(np.argmin(rss_d)), rss_d.shape)
    return mud_acc, float(near[jb[0]] * fine_r[jb[1]])


def _slip_onset(models: SlipModelCache, win: Window, mu: float,
                mu_d: float) -> tuple[float, int | None]:
    """(onset time [s], inf if none; its fit-window sample or None) of the pair (mu, mu_d)."""
    t = win.t
    _, onset = models.rows(np.array([mu]), np.array([mu_d]))
    if not np.isfinite(onset[0]):
        return onset[0], None
    return onset[0], int(np.clip(round((onset[0] - t[0]) / (t[1] - t[0])), 0, t.size - 1))


def _bounds_and_status(pset: _ProfileSet, nuis: KinematicNuisance, no_slip_ok: bool,
                       at_start_ok: bool, crit: float, opt: InferenceOptions
                       ) -> tuple[float | None, float | None, str]:
    """(mu_low, mu_high, status) with the kinematic nuisance profiled out."""
    # q (hence every candidate mu) scales with the measured omega_dot / omega^2: a relative
    # noise error e of q moves the whole profile by e. e is a Gaussian nuisance independent of
    # beta's noise, profiled out of the likelihood (scale_nuisance_bounds): a flat-bottomed
    # profile gets the full z sigma (the lower bound: the sup quantile z_lo), a sharp one about
    # the quadrature sum. The bias bounds (truncation, lens prior) are added linearly.
    scale = float(opt.kinematic_sigma_scale)
    n_lo, n_hi = scale_nuisance_bounds(pset.mu_grid[pset.ok], pset.stat[pset.ok],
                                       (nuis.z_lo * nuis.z_lo, crit),
                                       (nuis.rel_noise_lo * scale, nuis.rel_noise * scale),
                                       (nuis.rel_bias_lo, nuis.rel_bias))
    status = "ok"
    # A ball that may already slide at the start of the trusted region carries an unknown
    # speed from an unknown earlier slip (q before the region is unknown): no bound at all.
    mu_low = None if at_start_ok else n_lo
    mu_high = None if (no_slip_ok or at_start_ok) else n_hi
    if no_slip_ok and at_start_ok:
        status = "no bound: the data fit both a ball slipping from the start and one never slipping"
    elif no_slip_ok:
        status = "no slip in the trusted region: only a lower bound"
    elif at_start_ok:
        status = "slip before or at the start of the trusted region: no bound"
    return mu_low, mu_high, status


def _lost_across_slip(lost: np.ndarray | None, time: np.ndarray, models: SlipModelCache,
                      win: Window, pset: _ProfileSet) -> bool:
    """Whether a marker was lost (interpolated) within 2 ms of the onset times the confidence
    set allows."""
    if not (lost is not None and np.any(lost)):
        return False
    lost_t = np.asarray(time, float)[np.asarray(lost, bool)]
    _, on_lo = models.rows(np.array([pset.low]), np.array([pset.low]))
    _, on_hi = models.rows(np.array([pset.high]), np.array([pset.high * MU_D_RATIO[0]]))
    ta = on_lo[0] if np.isfinite(on_lo[0]) else win.t[0]
    tb = on_hi[0] if np.isfinite(on_hi[0]) else win.t[-1]
    return bool(np.any((lost_t >= min(ta, tb) - 0.002) & (lost_t <= max(ta, tb) + 0.002)))


def _mu_d_bounds(mud_acc: np.ndarray, mud_known: bool, nuis: KinematicNuisance,
                 z: float) -> tuple[float | None, float | None]:
    """mu_d's interval [1], widened by the kinematic error at the slip (z sigma + bias)."""
    mud_lo = float(mud_acc.min()) if mud_known and mud_acc.size else None
    mud_hi = float(mud_acc.max()) if mud_known and mud_acc.size else None
    if mud_lo is not None:
        # the same kinematic error scales mu_d
        mud_lo = mud_lo * (1.0 - z * nuis.rel_noise - nuis.rel_bias)
        mud_hi = mud_hi * (1.0 + z * nuis.rel_noise + nuis.rel_bias)
    return mud_lo, mud_hi


def _model_curve(models: SlipModelCache, gls: _Gls, win: Window, n_record: int,
                 mu: float | None, mud: float | None) -> np.ndarray | None:
    """Fitted model beta [rad] on the record (NaN outside the fit window); None without mu."""
    if mu is None:
        return None
    m, _ = models.rows(np.array([mu]), np.array([mud]))
    out = np.zeros(n_record) * np.nan
    out[win.i0:win.i0 + win.t.size] = gls.fit(m[0], win.x, win.beta)
    return out


def _details(fit: _NoiseFit, lrf: float, pset: _ProfileSet, crit: float,
             nuis: KinematicNuisance, opt: InferenceOptions) -> dict:
    """``Inference.details`` (summary.json's ``model_fit`` keys: keep names and order)."""
    return {"ar1_rho": fit.rho, "long_run_factor": lrf, **{
                k: v for k, v in fit.noise_info.items() if k != "sigma_white_rad"},
            "sigma_white_rad": math.sqrt(pset.sig2), "noise_model": dict(fit.noise_info),
            "chi2_critical": crit, "profile_mu_low": pset.low, "profile_mu_high": pset.high,
            "kinematic_rel_sigma_at_slip": nuis.rel_noise,
            "lower_bound_sup_z": nuis.z_lo, "lower_bound_reach_s": nuis.reach_s,
            "kinematic_rel_bias_at_slip": nuis.rel_bias,
            "harmonic_orders": list(opt.harmonic_orders),
            "theta_harmonics": opt.theta_harmonics,
            "mu_d_ratio_range": list(MU_D_RATIO), "candidates": int(pset.mu_grid.size)}


def infer_mu(time: np.ndarray, theta: np.ndarray, beta: np.ndarray, omega: np.ndarray,
             omega_dot: np.ndarray, sigma_omega: np.ndarray, sigma_omega_dot: np.ndarray,
             bias_omega_dot: np.ndarray, trusted: np.ndarray, *, l: float, d: float,
             direction: int, lost: np.ndarray | None = None,
             deviation: np.ndarray | None = None,
             record_residual: np.ndarray | None = None,
             omega_dot_rho: np.ndarray | None = None,
             noise: dict | None = None,
             options: InferenceOptions | None = None) -> Inference:
    """Confidence sets on mu and mu_d from beta(t) and the measured kinematics.

    Args:
        time: uniform times [s]; theta, beta: measured angles [rad] (beta with its harmonics).
        omega, omega_dot, sigma_omega, sigma_omega_dot, bias_omega_dot: kinematics and their
            1-sigma noise and truncation bounds [rad/s, rad/s^2].
        trusted: (N,) bool, one contiguous run where the kinematics hold.
        l, d: path radius and ball diameter [m].
        direction: slip direction s of beta (+1 / -1).
        lost: (N,) bool, frames where the ball or CD marker was interpolated.
        deviation: (N,) smoothed deviation of the harmonic-cleaned beta from its stick value
            along the slip direction [rad] (``interval``); it sets the end of the fit window.
        record_residual: (N,) residual of the whole-record harmonic fit [rad]; the leftover
            noise is also estimated on its trusted part (``noise_models.leftover_whitener``).
        omega_dot_rho: autocorrelation of omega_dot's noise error at lags 0, 1, ... samples
            (``Kinematics.omega_dot_rho``): the lower bound's noise term then covers the
            largest error over the stretch that could have set it (:mod:`sup_noise`); None:
            the pointwise z sigma.
        noise: beta's noise model as another set of the same record estimated it
            (``details["noise_model"]`` of its result: ``sigma_white_rad``,
            ``sigma_leftover_rad``, ``leftover_tau_s``); with ``noise_model="leftover"`` it is
            used as is (the sets of several kinematics windows share it, :mod:`window_sets`)
            and the first, white-noise pass of the profile is skipped.
    """
    opt = options or InferenceOptions()
    level = float(opt.confidence)
    z = NormalDist().inv_cdf(0.5 + 0.5 * level)
    crit = z * z  # chi^2_1 quantile at the level
    region = trusted_region(time, theta, beta, omega, omega_dot, trusted, l, d, direction, opt)
    # cut to max_fit_samples (summary.json's model_fit.fit_window_cut says where)
    region, win, cut = capped_window(region, fit_window(region, deviation, opt), deviation, opt)
    mu_grid, ratios = candidate_grid(region, opt)
    # the stages below share these caches: each pair is integrated, each mu profiled once
    models = SlipModelCache(win.t, win.q, win.omega, region.run_max, int(direction), d / l,
                            opt.max_episodes)
    # a mu the refinements of mu_d cannot bring within crit is not refined; only while the
    # statistic is the plain RSS ratio (a long-run factor divides it after the profile)
    profile = MuDProfile(models, opt.mu_d_refine, win.dof,
                         crit if opt.lrv_window_s <= 0 else None)
    lighting = None
    orders = tuple(k for k in opt.leftover_orders if k not in opt.harmonic_orders)
    if orders and opt.noise_model == "leftover" and record_residual is not None:
        # phi = theta + beta, as the nuisance columns of the window (fit_window)
        lighting = harmonic_leftover(np.asarray(theta, float) + np.asarray(beta, float),
                                     record_residual, slice(win.i0, win.i0 + win.t.size), orders)
    fit = _fit_noise_model(win, mu_grid, ratios, profile, noise, record_residual, opt,
                           (sigma_omega_dot, omega_dot_rho) if opt.drive_noise else None,
                           lighting)
    lrf = _long_run_factor(win, fit, mu_grid, models, opt)
    mu_grid, rss = _refine_mu_grid(mu_grid, fit, lrf, win, ratios, profile, crit, opt)
    pset = _accepted_set(mu_grid, rss, lrf, win, crit)
    kin = KinematicErrors(omega, omega_dot, sigma_omega, sigma_omega_dot, bias_omega_dot,
                          win.i0, float(opt.theta_harmonic_rad))
    no_slip_ok, at_start_ok = _null_hypotheses(pset, region, kin, z)
    mud_acc, mu_d_hat = _mu_d_set(pset, fit.gls, models, crit)
    # if the best pair is "no slip", mu_d is not identified
    slip_seen = not (pset.mu_hat >= region.q_top)
    best_mud = mu_d_hat if slip_seen else pset.mu_hat
    onset, onset_idx = _slip_onset(models, win, pset.mu_hat, best_mud)
    nuis = kinematic_nuisance(kin, win, onset_idx, pset.low, z, level, omega_dot_rho, opt)
    mu_low, mu_high, status = _bounds_and_status(pset, nuis, no_slip_ok, at_start_ok, crit, opt)
    if _lost_across_slip(lost, time, models, win, pset):
        mu_low = mu_high = None
        status = LOST_ACROSS_SLIP
    # mu_d is identified only when the data show a slip that starts inside the record
    mud_known = slip_seen and not (no_slip_ok or at_start_ok) and mu_low is not None
    mud_lo, mud_hi = _mu_d_bounds(mud_acc, mud_known, nuis, z)

    n_record, gls = len(beta), fit.gls
    best_curve = _model_curve(models, gls, win, n_record, pset.mu_hat, best_mud)
    low_curve = _model_curve(models, gls, win, n_record, pset.low, pset.low) \
        if mu_low is not None else None
    high_curve = _model_curve(models, gls, win, n_record, pset.high, pset.high * MU_D_RATIO[0]) \
        if mu_high is not None else None
    return Inference(
        mu_low=mu_low, mu_high=mu_high, mu_hat=pset.mu_hat if slip_seen else None,
        mu_d=mu_d_hat if mud_known else None, mu_d_low=mud_lo, mu_d_high=mud_hi,
        status=status, confidence=level,
        t_slip=float(onset) if slip_seen and np.isfinite(onset) else None,
        beta_model=best_curve, beta_model_low=low_curve, beta_model_high=high_curve,
        residual=np.asarray(beta, float) - best_curve,
        details={**_details(fit, lrf, pset, crit, nuis, opt),
                 **({"fit_window_cut": cut} if cut else {}), "model_curves": {
            # the (mu, mu_d) each drawn model curve of beta.png was integrated with
            "best": {"mu": float(pset.mu_hat), "mu_d": float(best_mud)},
            "low": None if low_curve is None else {"mu": float(pset.low),
                                                   "mu_d": float(pset.low)},
            "high": None if high_curve is None else {
                "mu": float(pset.high), "mu_d": float(pset.high * MU_D_RATIO[0])}}})
