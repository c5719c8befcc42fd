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
covariance (``noise_model="ar1"``: the former AR(1) whitening). mu_d is profiled out by a
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

import numpy as np
from statistics import NormalDist

from .inference_types import LOST_ACROSS_SLIP, MU_D_RATIO, Inference, InferenceOptions  # noqa: F401
from .noise_models import Gls as _Gls, ar1 as _ar1, leftover_whitener, long_run_factor  # noqa: F401
from .noise_models import leftover_whitener_of
from .noise_models import noise_level  # noqa: F401 (re-exported)
from . import sup_noise
from .slip_model import signed_mu_req, slip_displacement  # noqa: F401 (re-exported)

def _harmonic_design(theta: np.ndarray, phi: np.ndarray, orders: tuple[int, ...],
                     with_theta: bool) -> np.ndarray:
    cols = [np.ones_like(phi)]
    for k in orders:
        cols += [np.sin(k * phi), np.cos(k * phi)]
        if with_theta:
            cols += [np.sin(k * theta), np.cos(k * theta)]
    return np.stack(cols, axis=1)


def scale_nuisance_bounds(mu: np.ndarray, stat: np.ndarray, budget: tuple[float, float],
                          sigma_e: tuple[float, float], bias: tuple[float, float] = (0.0, 0.0)
                          ) -> tuple[float, float]:
    """Bounds of a confidence set on mu with a Gaussian relative scale error of q profiled out.

    The data of (mu, mu_d) under q (1 + e) are those of (mu, mu_d) / (1 + e) under q, and e is
    independent of beta's noise with 1-sigma ``sigma_e``: the deviance is the profile's
    statistic plus (e / sigma_e)^2, minimised over e. So mu is accepted if it lies within a
    factor 1 -+ sigma_e sqrt(budget - stat(mu')) of a candidate mu' the profile accepts: a
    flat-bottomed profile [a, b] gives [a (1 - z sigma_e), b (1 + z sigma_e)] (z^2 = budget),
    a sharp quadratic one about the quadrature sum of the two half-widths.

    Args:
        mu: the candidates the profile accepts [1]; stat: their likelihood-ratio statistic.
        budget: (lower, upper) deviance budgets: z^2 at the level, or a larger quantile
            squared where the error is the largest of many (``sup_noise``).
        sigma_e: (lower, upper) relative 1-sigma error of q [1].
        bias: (lower, upper) relative bias bounds of q, added linearly [1].

    Returns:
        (lower, upper); the lower bound is 0 where the relative errors reach 100 % (mu >= 0).
    """
    lo = mu * (1.0 - sigma_e[0] * np.sqrt(np.maximum(budget[0] - stat, 0.0)) - bias[0])
    hi = mu * (1.0 + sigma_e[1] * np.sqrt(np.maximum(budget[1] - stat, 0.0)) + bias[1])
    return max(0.0, float(np.min(lo))), float(np.max(hi))


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
    idx = np.flatnonzero(trusted)
    i0, i1 = int(idx[0]), int(idx[-1]) + 1
    t = np.asarray(time, float)[i0:i1]
    th = np.asarray(theta, float)[i0:i1]
    y = np.asarray(beta, float)[i0:i1]
    w = np.asarray(omega, float)[i0:i1]
    q = signed_mu_req(w, np.asarray(omega_dot, float)[i0:i1], l, d, direction)
    s = int(direction)
    x = _harmonic_design(th, y + th, tuple(opt.harmonic_orders), opt.theta_harmonics)
    run_max = np.maximum.accumulate(q)
    q_first, q_top = float(max(q[0], 1e-6)), float(run_max[-1])
    level = float(opt.confidence)
    z = NormalDist().inv_cdf(0.5 + 0.5 * level)
    crit = z * z  # chi^2_1 quantile at the level
    full = np.zeros(len(beta))

    mcache: dict = {}

    def models(mu: np.ndarray, mud: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Model displacement rows for candidate pairs (cached; computed on the columns from
        just before the earliest first onset among the new pairs: before it the ball sticks)."""
        keys = [(float(a), float(b), t.size) for a, b in zip(mu, mud)]
        missing = sorted({k for k in keys if k not in mcache})
        if missing:
            # one call for all missing pairs, on the columns from just before the earliest
            # onset among them (the per-call overhead of many small calls cost more than the
            # stuck columns of the later-onset rows)
            mus = np.array([k[0] for k in missing])
            # the first sample with q > mu is where q's running maximum first exceeds mu
            first_above = np.searchsorted(run_max, mus, side="right")
            c0 = max(int(first_above.min()) - 1, 0)
            rows = np.zeros((len(missing), t.size))
            onset = np.full(len(missing), np.inf)
            if c0 < t.size - 1:
                disp, onset = slip_displacement(
                    t[c0:], q[c0:], w[c0:], mus, np.array([k[1] for k in missing]), s, d / l,
                    max_episodes=opt.max_episodes)
                rows[:, c0:] = s * disp
            for r, k in enumerate(missing):
                mcache[k] = (rows[r], float(onset[r]))
        out = [mcache[k] for k in keys]
        return np.array([o[0] for o in out]), np.array([o[1] for o in out])

    # candidate mu: from just below the first trusted q to above the record's maximum
    lo_mu = 0.9 * q_first if q[0] > 0 else max(q_top * 1e-3, 1e-6)
    hi_mu = q_top * 1.001 if q_top > 0 else 1e-3
    if hi_mu <= lo_mu:
        hi_mu = lo_mu * 1.01
    ratios = np.linspace(MU_D_RATIO[0], MU_D_RATIO[1], int(opt.n_mu_d))

    cache: dict = {}

    def profile(mu_grid: np.ndarray, gls: _Gls, ratio_grid: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
        # profile RSS over mu_d for each mu; values already computed for this fit are reused
        key = (gls, ratio_grid.size)
        known = cache.setdefault(key, {})
        new = np.array([m for m in mu_grid if float(m) not in known])
        if new.size:
            mu_all = np.repeat(new, ratio_grid.size)
            mud_all = mu_all * np.tile(ratio_grid, new.size)
            m, _ = models(mu_all, mud_all)
            rss = gls.rss(m).reshape(new.size, ratio_grid.size)
            j = np.argmin(rss, axis=1)
            # Minimise over mu_d by shrinking 5-point grids around each minimum: the data pin
            # mu_d to a fraction of a per cent, and a coarse mu_d grid inflates the profile at
            # the true mu (its best mu_d is off the grid) while some other mu happens to have a
            # grid point that fits: a narrow, wrong set (measured: with the true kinematics and
            # the true beta + white noise, a 0.05 ratio grid covered 58 % of 60 drives).
            rows = np.arange(new.size)
            cur, val = ratio_grid[j].astype(float), rss[rows, j]
            step = float(ratio_grid[1] - ratio_grid[0]) if ratio_grid.size > 1 else 0.1
            for _ in range(int(opt.mu_d_refine)):
                offs = np.linspace(-step, step, 5)
                r_loc = np.clip(cur[:, None] + offs[None, :], MU_D_RATIO[0], MU_D_RATIO[1])
                m, _ = models(np.repeat(new, offs.size), (new[:, None] * r_loc).ravel())
                rss2 = gls.rss(m).reshape(new.size, offs.size)
                jj = np.argmin(rss2, axis=1)
                better = rss2[rows, jj] < val
                cur = np.where(better, r_loc[rows, jj], cur)
                val = np.where(better, rss2[rows, jj], val)
                step /= 2.5
            for k, mu_k in enumerate(new):
                known[float(mu_k)] = (float(val[k]), float(cur[k]))
        vals = [known[float(m)] for m in mu_grid]
        return np.array([v[0] for v in vals]), np.array([v[1] for v in vals])

    mu_grid = np.unique(np.r_[np.geomspace(lo_mu, hi_mu, int(opt.n_mu)), hi_mu * 1.05])
    # The information on mu is in the stick stretch and the first few mrad of slip; far into
    # the slip the predicted displacement (up to radians) carries the ~1 % kinematic error of q
    # as a misfit of many noise sigmas, which the likelihood would wrongly blame on mu. So the
    # fit window ends where the data (harmonic-cleaned, smoothed) have moved
    # ``window_sigmas`` white-noise sigmas of beta from the stick level.
    n_fit = t.size
    if deviation is not None:
        # floor: noise-free tracks would end the window before the slip is visible
        sig_b = max(noise_level(y), float(opt.sigma_floor_rad))
        dev = np.asarray(deviation, float)[i0:i1]
        # moved from where it was at the start of the trusted region (not from the stick
        # level of the record's first frames: the ball may already slide there)
        moved = np.flatnonzero(np.abs(dev - dev[0]) > opt.window_sigmas * sig_b)
        if moved.size:
            n_fit = int(moved[0]) + 1
    # at least 20 ms: a ball already moving at the start must be seen to move
    n_fit = max(n_fit, min(t.size, max(2 * x.shape[1] + 40, int(round(0.02 / (t[1] - t[0]))))))
    t, th, y, w, q, x = t[:n_fit], th[:n_fit], y[:n_fit], w[:n_fit], q[:n_fit], x[:n_fit]
    rho = 0.0
    noise_info: dict = {}
    reuse = noise is not None and opt.ar_order_max >= 1 and opt.noise_model == "leftover"
    if reuse:
        noise_info = {k: noise[k] for k in ("sigma_white_rad", "sigma_leftover_rad",
                                             "leftover_tau_s")}
        gls = _Gls(y, x, 0.0, leftover_whitener_of(noise_info, t.size, float(t[1] - t[0])))
        rss, rbest = profile(mu_grid, gls, ratios)
    else:
        gls = _Gls(y, x, 0.0)
        rss, rbest = profile(mu_grid, gls, ratios)
        best = int(np.argmin(rss))
        m_best, _ = models(mu_grid[best: best + 1],
                           mu_grid[best: best + 1] * rbest[best: best + 1])
    if opt.ar_order_max >= 1 and not reuse:
        fitted = gls.fit(m_best[0], x, y)
        rho = _ar1(y - fitted)
        if opt.noise_model == "leftover":
            rec = None if record_residual is None else \
                np.asarray(record_residual, float)[i0:i1]
            winv, noise_info = leftover_whitener(y - fitted, float(t[1] - t[0]),
                                                 record_residual=rec)
            gls = _Gls(y, x, 0.0, winv)
        else:
            gls = _Gls(y, x, rho)
        rss, _ = profile(mu_grid, gls, ratios)
    lrf = 1.0
    if opt.lrv_window_s > 0:
        best = int(np.argmin(rss))
        m_best, _ = models(mu_grid[best: best + 1], mu_grid[best: best + 1]
                           * rbest[best: best + 1])
        res_w = gls.whiten((y - gls.fit(m_best[0], x, y))[None, :])[0]
        lrf = long_run_factor(res_w, int(round(opt.lrv_window_s / (t[1] - t[0]))))
    # refine: a finer mu grid around the profile's acceptance region and minimum
    for _ in range(2):
        best = int(np.argmin(rss))
        sig2 = max(lrf * float(rss[best]) / max(t.size - x.shape[1] - 2, 1), 1e-300)
        stat = (rss - rss[best]) / sig2
        ok = np.flatnonzero(stat <= crit)
        a = mu_grid[max(ok[0] - 1, 0)]
        b = mu_grid[min(ok[-1] + 1, mu_grid.size - 1)]
        extra = np.geomspace(a, b, int(opt.n_mu)) if b > a else np.array([a])
        mu_grid = np.unique(np.r_[mu_grid, extra])
        rss, rbest = profile(mu_grid, gls, ratios)
    best = int(np.argmin(rss))
    sig2 = max(lrf * float(rss[best]) / max(t.size - x.shape[1] - 2, 1), 1e-300)
    stat = (rss - rss[best]) / sig2
    ok = np.flatnonzero(stat <= crit)
    mu_hat = float(mu_grid[best])
    no_slip_ok = bool(mu_grid[ok[-1]] >= q_top)       # "never slips" not rejected
    # "slipping from the start" not rejected: the lowest accepted mu lies below the first
    # trusted q by more than q's own kinematic noise there (within it, a candidate that "slips"
    # from the start with mu_d ~ mu barely moves: the ball sticking at q_first, e.g. on the
    # plateau of a first setpoint step, which the start of the trusted region may just reach)
    a0, w0 = abs(float(omega_dot[i0])), abs(float(omega[i0]))
    rel0 = math.hypot(float(sigma_omega_dot[i0]) / a0, 2.0 * float(sigma_omega[i0]) / w0) \
        if a0 > 0 and w0 > 0 else 0.0
    at_start_ok = bool(mu_grid[ok[0]] <= q_first * (1.0 - min(z * rel0, 0.05)))
    m_lo_b, m_hi_b = float(mu_grid[ok[0]]), float(mu_grid[ok[-1]])

    # mu_d: profile over mu on a finer ratio grid near the best mu
    near = mu_grid[ok]
    if near.size > 12:
        near = near[np.linspace(0, near.size - 1, 12).astype(int)]
    fine_r = np.linspace(MU_D_RATIO[0], MU_D_RATIO[1], 36)
    mu_all = np.repeat(near, fine_r.size)
    mud_all = mu_all * np.tile(fine_r, near.size)
    m_all, _ = models(mu_all, mud_all)
    rss_d = gls.rss(m_all).reshape(near.size, fine_r.size)
    rmin = min(float(rss_d.min()), float(rss[best]))
    stat_d = (rss_d - rmin) / sig2
    acc = stat_d <= crit
    mud_acc = mud_all.reshape(near.size, fine_r.size)[acc]
    jb = np.unravel_index(int(np.argmin(rss_d)), rss_d.shape)
    mu_d_hat = float(near[jb[0]] * fine_r[jb[1]])
    # if the best pair is "no slip", mu_d is not identified
    slip_seen = not (mu_hat >= q_top)

    # kinematic error of q at the slip: relative 1-sigma noise and truncation bound
    onset_idx = None
    m_hat, onset = models(np.array([mu_hat]), np.array([mu_d_hat if slip_seen else mu_hat]))
    if np.isfinite(onset[0]):
        onset_idx = int(np.clip(round((onset[0] - t[0]) / (t[1] - t[0])), 0, t.size - 1))
    def kinematic_error(j: int) -> tuple[float, float]:
        """(relative 1-sigma noise, relative bias bound) of q at fit-window sample j."""
        a = abs(float(omega_dot[i0 + j]))
        wv = abs(float(omega[i0 + j]))
        if not (a > 0 and wv > 0):
            return 0.0, 0.0
        noise = math.hypot(float(sigma_omega_dot[i0 + j]) / a,
                           2.0 * float(sigma_omega[i0 + j]) / wv)
        # + a systematic harmonic of theta of amplitude A (lens distortion about an optical
        # centre off the axis: the circle fit of the axis cannot see it) errs omega_dot by up
        # to A omega^2 and omega by A omega (worst phase)
        bias = (float(bias_omega_dot[i0 + j]) / a
                + float(opt.theta_harmonic_rad) * (wv * wv / a + 2.0))
        return noise, bias

    rel_noise = rel_bias = 0.0
    if onset_idx is not None:
        rel_noise, rel_bias = kinematic_error(onset_idx)
    # The lower bound is set by the largest q over the stick stretch (before the best fit's
    # onset; the whole window if it never slips): its error is that of q where q peaks there,
    # and the largest of the noise errors over the part of the stretch whose q comes within
    # reach of the bound, not one pointwise error (sup_noise: Rice's formula).
    stick_end = onset_idx if onset_idx is not None else t.size
    j_peak = int(np.argmax(q[:max(stick_end, 1)]))
    rel_noise_lo, rel_bias_lo = kinematic_error(j_peak)
    if onset_idx is not None and rel_noise > 0.0:
        rel_noise_lo, rel_bias_lo = max(rel_noise_lo, rel_noise), max(rel_bias_lo, rel_bias)
    z_lo, reach_s = z, 0.0
    rho_q = None if omega_dot_rho is None else np.asarray(omega_dot_rho, float)
    if rho_q is not None and rho_q.size > 1:
        h = float(t[1] - t[0])
        lam2 = sup_noise.second_spectral_moment(float(rho_q[1]), h)
        sq = np.abs(q[:stick_end]) * rel_noise_lo * float(opt.kinematic_sigma_scale)
        for _ in range(3):  # the stretch within reach depends on the quantile: fixed point
            reach_s = h * int(np.count_nonzero(q[:stick_end] + 2.0 * z_lo * sq >= m_lo_b))
            z_lo = max(z, sup_noise.sup_quantile(0.5 * (1.0 - level), reach_s, lam2))

    # q (hence every candidate mu) scales with the measured omega_dot / omega^2: a relative
    # noise error e of q moves the whole profile by e. e is a Gaussian nuisance independent of
    # beta's noise, profiled out of the likelihood (scale_nuisance_bounds): a flat-bottomed
    # profile gets the full z sigma (the lower bound: the sup quantile z_lo), a sharp one about
    # the quadrature sum. The bias bounds (truncation, lens prior) are added linearly.
    scale = float(opt.kinematic_sigma_scale)
    n_lo, n_hi = scale_nuisance_bounds(mu_grid[ok], stat[ok], (z_lo * z_lo, crit),
                                       (rel_noise_lo * scale, rel_noise * scale),
                                       (rel_bias_lo, rel_bias))

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
    lost_note = None
    if lost is not None and np.any(lost):
        lost_t = np.asarray(time, float)[np.asarray(lost, bool)]
        # onset times allowed by the confidence set, +- 2 ms
        _, on_lo = models(np.array([m_lo_b]), np.array([m_lo_b]))
        _, on_hi = models(np.array([m_hi_b]), np.array([m_hi_b * MU_D_RATIO[0]]))
        ta = on_lo[0] if np.isfinite(on_lo[0]) else t[0]
        tb = on_hi[0] if np.isfinite(on_hi[0]) else t[-1]
        if np.any((lost_t >= min(ta, tb) - 0.002) & (lost_t <= max(ta, tb) + 0.002)):
            lost_note = LOST_ACROSS_SLIP
            mu_low = mu_high = None
            status = lost_note
    # mu_d is identified only when the data show a slip that starts inside the record
    mud_known = slip_seen and not (no_slip_ok or at_start_ok) and mu_low is not None
    mud_lo = float(mud_acc.min()) if mud_known and mud_acc.size else None
    mud_hi = float(mud_acc.max()) if mud_known and mud_acc.size else None
    if mud_lo is not None:
        # the same kinematic error scales mu_d
        mud_lo = mud_lo * (1.0 - z * rel_noise - rel_bias)
        mud_hi = mud_hi * (1.0 + z * rel_noise + rel_bias)

    def curve(mu: float | None, mud: float | None) -> np.ndarray | None:
        if mu is None:
            return None
        m, _ = models(np.array([mu]), np.array([mud]))
        out = full.copy() * np.nan
        out[i0:i0 + t.size] = gls.fit(m[0], x, y)
        return out

    best_curve = curve(mu_hat, mu_d_hat if slip_seen else mu_hat)
    residual = np.asarray(beta, float) - best_curve
    return Inference(
        mu_low=mu_low, mu_high=mu_high, mu_hat=mu_hat if slip_seen else None,
        mu_d=mu_d_hat if mud_known else None, mu_d_low=mud_lo, mu_d_high=mud_hi,
        status=status, confidence=level,
        t_slip=float(onset[0]) if slip_seen and np.isfinite(onset[0]) else None,
        beta_model=best_curve,
        beta_model_low=curve(m_lo_b, m_lo_b) if mu_low is not None else None,
        beta_model_high=curve(m_hi_b, m_hi_b * MU_D_RATIO[0]) if mu_high is not None else None,
        residual=residual,
        details={"ar1_rho": rho, "long_run_factor": lrf, **{
                     k: v for k, v in noise_info.items() if k != "sigma_white_rad"},
                 "sigma_white_rad": math.sqrt(sig2), "noise_model": dict(noise_info),
                 "chi2_critical": crit, "profile_mu_low": m_lo_b, "profile_mu_high": m_hi_b,
                 "kinematic_rel_sigma_at_slip": rel_noise,
                 "lower_bound_sup_z": z_lo, "lower_bound_reach_s": reach_s,
                 "kinematic_rel_bias_at_slip": rel_bias,
                 "harmonic_orders": list(opt.harmonic_orders),
                 "theta_harmonics": opt.theta_harmonics,
                 "mu_d_ratio_range": list(MU_D_RATIO), "candidates": int(mu_grid.size)})
