"""The shared caches of :func:`measurement.inference.infer_mu.infer_mu`: model rows and the
profile over mu_d.

Every stage of the inference (noise model, mu grid refinement, mu_d set, onset, status,
curves) asks for model displacements of candidate pairs (mu, mu_d) and for the profile RSS of
candidate mu; both are cached so that a pair is integrated once and a mu profiled once per fit.

Bit-for-bit note: with the NumPy fallback of the slip model (no compiled ``_slipc``),
:meth:`SlipModelCache.rows` integrates all missing pairs of one call together from the earliest
onset among them, and its running sums cancel from that column, so the numbers depend (to
~1e-7 relative of an RSS) on the order and batching of the calls; the compiled kernel
integrates each row from its own onset and does not depend on them.
"""
from __future__ import annotations

import numpy as np

from measurement.inference.noise_models import Gls
from measurement.inference.slip_model import slip_displacement
from measurement.inference.types import MU_D_RATIO


class SlipModelCache:
    """Model displacement rows s D(t; mu, mu_d) [rad] on the fit window, cached per pair.

    Args:
        t, q, omega: fit-window times [s], signed mu_req [1], ABU speed [rad/s].
        run_max: running maximum of q over the whole trusted region [1] (locates the first
            sample with q > mu).
        direction: slip direction s (+1 / -1).
        d_over_l: ball diameter over path radius [1].
        max_episodes: slip episodes followed per candidate (None: all).
    """

    def __init__(self, t: np.ndarray, q: np.ndarray, omega: np.ndarray, run_max: np.ndarray,
                 direction: int, d_over_l: float, max_episodes: int | None) -> None:
        self.t, self.q, self.omega, self.run_max = t, q, omega, run_max
        self.direction, self.d_over_l, self.max_episodes = direction, d_over_l, max_episodes
        self._rows: dict = {}

    def rows(self, mu: np.ndarray, mud: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(model rows [rad], onset times [s]) for candidate pairs (mu, mu_d)."""
        n = self.t.size
        keys = [(a, b, n) for a, b in zip(np.asarray(mu, float).tolist(),
                                           np.asarray(mud, float).tolist())]
        missing = sorted({k for k in keys if k not in self._rows})
        if missing:
            self._integrate(missing)
        out = [self._rows[k] for k in keys]
        return np.array([o[0] for o in out]), np.array([o[1] for o in out])

    def _integrate(self, missing: list[tuple[float, float, int]]) -> None:
        # One call for all missing pairs, on the columns from just before the earliest onset
        # among them: before it the ball sticks (the per-call overhead of many small calls
        # cost more than the stuck columns of the later-onset rows).
        t = self.t
        mus = np.array([k[0] for k in missing])
        # the first sample with q > mu is where q's running maximum first exceeds mu
        first_above = np.searchsorted(self.run_max, mus, side="right")
        c0 = max(int(first_above.min()) - 1, 0)
        rows = np.zeros((len(missing), t.size))
        onset = np.full(len(missing), np.inf)
        if c0 < t.size - 1:
            disp, onset = slip_displacement(
                t[c0:], self.q[c0:], self.omega[c0:], mus, np.array([k[1] for k in missing]),
                self.direction, self.d_over_l, max_episodes=self.max_episodes)
            np.multiply(disp, self.direction, out=rows[:, c0:])
        for r, k in enumerate(missing):
            self._rows[k] = (rows[r], float(onset[r]))


class MuDProfile:
    """Profile RSS over mu_d for each candidate mu, cached per (fit, ratio grid).

    Args:
        models: the fit window's :class:`SlipModelCache`.
        refinements: shrinking 5-point refinements of mu_d / mu per mu (step / 2.5 each).
        dof: degrees of freedom of the residual variance that scales the statistic
            (``Window.dof``).
        prune_stat: skip the refinements of a mu whose likelihood-ratio statistic stays above
            this many chi^2 units whatever they find (:func:`refinement_needed`); None: refine
            every mu.
    """

    def __init__(self, models: SlipModelCache, refinements: int, dof: int,
                 prune_stat: float | None = None) -> None:
        self.models = models
        self.refinements = int(refinements)
        self.dof = dof
        self.prune_stat = prune_stat
        self._known: dict = {}

    def __call__(self, mu_grid: np.ndarray, gls: Gls, ratio_grid: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray]:
        """(profile RSS, best mu_d / mu) per mu of ``mu_grid``; values already computed for
        this fit (``gls``) are reused."""
        known = self._known.setdefault((gls, ratio_grid.size), {})
        new = np.array([m for m in mu_grid if float(m) not in known])
        if new.size:
            best_known = min((v[0] for v in known.values()), default=np.inf)
            val, cur = self._minimise_over_mu_d(new, gls, ratio_grid, best_known)
            for k, mu_k in enumerate(new):
                known[float(mu_k)] = (float(val[k]), float(cur[k]))
        vals = [known[float(m)] for m in mu_grid]
        return np.array([v[0] for v in vals]), np.array([v[1] for v in vals])

    def _minimise_over_mu_d(self, new: np.ndarray, gls: Gls, ratio_grid: np.ndarray,
                            best_known: float = np.inf) -> tuple[np.ndarray, np.ndarray]:
        """(smallest RSS, its mu_d / mu) per mu of ``new``: grid, then shrinking grids (for
        the mu that can still matter, see ``prune_stat``)."""
        mu_all = np.repeat(new, ratio_grid.size)
        mud_all = mu_all * np.tile(ratio_grid, new.size)
        m, _ = self.models.rows(mu_all, mud_all)
        rss = gls.rss(m).reshape(new.size, ratio_grid.size)
        j = np.argmin(rss, axis=1)
        # Minimise over mu_d by shrinking 5-point grids around each minimum: the data pin
        # mu_d to a fraction of a per cent, and a coarse mu_d grid inflates the profile at
        # the true mu (its best mu_d is off the grid) while some other mu happens to have a
        # grid point that fits: a narrow, wrong set (measured: with the true kinematics and
        # the true beta + white noise, a 0.05 ratio grid covered 58 % of 60 drives).
        cur, val = ratio_grid[j].astype(float), rss[np.arange(new.size), j]
        step = float(ratio_grid[1] - ratio_grid[0]) if ratio_grid.size > 1 else 0.1
        live = np.arange(new.size)
        if self.prune_stat is not None:
            live = np.flatnonzero(refinement_needed(rss, min(best_known, float(val.min())),
                                                    self.dof, self.prune_stat))
        rows = np.arange(live.size)
        for _ in range(self.refinements):
            if live.size == 0:
                break
            offs = np.linspace(-step, step, 5)
            r_loc = np.clip(cur[live, None] + offs[None, :], MU_D_RATIO[0], MU_D_RATIO[1])
            m, _ = self.models.rows(np.repeat(new[live], offs.size),
                                    (new[live, None] * r_loc).ravel())
            rss2 = gls.rss(m).reshape(live.size, offs.size)
            jj = np.argmin(rss2, axis=1)
            better = rss2[rows, jj] < val[live]
            cur[live] = np.where(better, r_loc[rows, jj], cur[live])
            val[live] = np.where(better, rss2[rows, jj], val[live])
            step /= 2.5
        return val, cur


def refinement_needed(rss: np.ndarray, rss_best: float, dof: float,
                      prune_stat: float) -> np.ndarray:
    """Which candidate mu (rows of ``rss``: the profile RSS on the coarse mu_d grid) can still
    reach a likelihood-ratio statistic of ``prune_stat`` when mu_d is refined.

    The refinements search mu_d between the coarse grid's neighbours of each row's minimum b.
    Were the RSS convex in mu_d there, its minimum would be >= b - r, with r the largest rise
    between neighbouring grid values next to b (two on each side); ``b - 2 r`` is taken as the
    floor. The statistic (RSS - best) / (best / dof) only grows as the best RSS falls (and the
    best known now bounds the final best from above), so a row whose floor is above
    ``prune_stat`` stays rejected: skipping its refinements changes no accepted set while the
    RSS keeps above that floor (tests/test_profile_pruning.py compares with refining every mu;
    the kept tracks of the benchmark family and slices gave the same intervals). The rows
    skipped are the candidates far from the data, e.g. those slipping from the window's start
    (measured: the analysis of a 3072-frame rendered recording 0.26 -> 0.18 s CPU, of synthetic
    tracks 8-25 % less)."""
    rss = np.asarray(rss, float)
    n_rows, n_grid = rss.shape
    j = np.argmin(rss, axis=1)
    b = rss[np.arange(n_rows), j]
    if n_grid < 2 or not np.isfinite(rss_best) or rss_best <= 0.0:
        return np.ones(n_rows, bool)
    rise = np.abs(np.diff(rss, axis=1))                      # (rows, n_grid - 1)
    k = np.arange(n_grid - 1)[None, :]
    near = (k >= j[:, None] - 2) & (k <= j[:, None] + 1)     # the 2 steps on each side of b
    floor = b - 2.0 * np.max(np.where(near, rise, 0.0), axis=1)
    return (floor - rss_best) * max(float(dof), 1.0) / rss_best <= prune_stat
