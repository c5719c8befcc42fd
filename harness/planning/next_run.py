"""``abu next``: the run that shrinks the combined interval on mu most.

The intervals measured so far (``abu measure`` summaries, or ``abu simulate`` summaries of
co-simulated runs) all contain mu, so mu lies in their intersection [L, H]. The next run is the
staircase :func:`harness.planning.design.design_staircase` plans for the prior range [L, H]: for every
mu there it keeps the ball stuck through the first step, puts the slip inside the record and
has the smallest worst-case predicted interval. Its predicted combined interval at mu is
[max(L, low(mu)), min(H, high(mu))]; the proposal reports its worst case over [L, H] beside
the current width.

``predicted_combined_width`` (expected and 90 % range) is the relative width (hi - lo) / mid
of the intersection of [L, H] with the next run's interval, whose width w(mu) is the design's
predicted ``abu measure`` width (:mod:`.width_model`). Where mu lies in a measured interval sets
how much of it the intersection keeps. mu is not anywhere in [L, H] with equal weight: the
margins of ``abu measure``'s interval are bounds (the lens prior, the truncation bound) that the
actual error seldom reaches, and the lower one takes the Rice sup quantile (about 2.8 sigma,
1.96 above), so mu sits a little above the middle of each interval, and of their intersection,
and rarely near an end. The prediction averages over mu at the fraction x of [L, H] and the new
interval holding mu at the fraction p of its width, x and p independent normal with the
measured :data:`POSITION_MEAN` and :data:`POSITION_SD` (truncated to [0, 1]); the 90 % range
is the 5 % quantile over (x, p) with the run's ``low90`` width and the 95 % one with its
``high90``. (The former rule, the mean over a log-uniform mu in [L, H] of a new interval
centred on mu, predicted combined widths 0.87x the ones measured on rendered chains of runs,
``benchmarks/bench_next_runs.py``; at the true mu it was unbiased.)
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Sequence

import numpy as np

from abu_model.errors import AbuError

from harness.planning.design import Design, DesignSpec, design_staircase


class IntervalsError(AbuError):
    """The given intervals cannot be combined (unreadable, unbounded or disjoint)."""


def combine(intervals: Sequence[dict[str, Any]]) -> tuple[float, float]:
    """Intersection [L, H] of the intervals; IntervalsError if it is empty."""
    lo = max(i["mu_low"] for i in intervals)
    hi = min(i["mu_high"] for i in intervals)
    if not lo < hi:
        raise IntervalsError(
            f"the intervals have no common point (largest lower bound {lo:.6g} >= smallest upper "
            f"bound {hi:.6g}): " + ", ".join(f"{i['name']} [{i['mu_low']:.6g}, "
                                             f"{i['mu_high']:.6g}]" for i in intervals))
    return lo, hi


#: Where the true mu lies in a measured interval [lo, hi] (and in the intersection of several),
#: as the fraction (mu - lo) / (hi - lo): mean and standard deviation measured on 48 rendered
#: chains of designed runs (``benchmarks/bench_next_runs.py --calibrate`` on seeds 0-47: 0.56
#: and 0.13 after one run, 0.55 and 0.12 after two).
POSITION_MEAN = 0.56
POSITION_SD = 0.13
#: the 90 % range: the 5 % quantile over where mu lies with the run's low90 width, the 95 %
#: one with its high90 width (the spread of mu's position widens it, as it does the measured)
RANGE_QUANTILES = {"expected": None, "low90": 0.05, "high90": 0.95}
#: quadrature nodes per position (x in [L, H], p in the new interval) on [0, 1]
_NODES = 41


def combined_width(current: tuple[float, float], mu: np.ndarray, width: np.ndarray,
                   mean: float = POSITION_MEAN, sd: float = POSITION_SD,
                   quantile: float | None = None) -> float:
    """Expected relative width (hi - lo) / mid of [L, H] intersected with the next run's
    interval [-]; with ``quantile``, that quantile of it over where mu lies.

    Args:
        current: the combined interval so far [L, H] [-].
        mu, width: the next run's predicted ``abu measure`` relative width ``width`` at the
            grid ``mu`` of [L, H] (interpolated in log mu; from 2 on, e.g. inf: a null bound,
            nothing gained).
        mean, sd: where mu lies in a measured interval, as a fraction of its width.
    """
    lo, hi = current
    x = (np.arange(_NODES) + 0.5) / _NODES
    weight = np.exp(-0.5 * ((x - mean) / sd) ** 2)
    weight /= weight.sum()
    m = lo + x * (hi - lo)                                       # mu at fraction x of [L, H]
    w = np.interp(np.log(m), np.log(mu), np.minimum(width, 3.0))
    null = w >= 2.0                                # a null bound (inf): nothing gained
    w = np.where(null, 1.0, w)
    # the new interval holding mu at fraction p: [mu - p S, mu + (1 - p) S] with
    # S / (its mid) = w  (rows: mu at x; columns: p)
    p = x[None, :]
    span = (w * m)[:, None] / (1.0 - w[:, None] * (0.5 - p))
    a = np.where(null[:, None], lo, np.maximum(lo, m[:, None] - p * span))
    b = np.where(null[:, None], hi, np.minimum(hi, m[:, None] + (1.0 - p) * span))
    rel = (b - a) / (0.5 * (a + b))
    if quantile is None:
        return float(weight @ rel @ weight)
    order = np.argsort(rel, axis=None)
    cum = np.cumsum(np.outer(weight, weight).ravel()[order])
    return float(rel.ravel()[order][min(np.searchsorted(cum, quantile), cum.size - 1)])


@dataclass
class Proposal:
    """The proposed next run and its predicted effect."""

    current: tuple[float, float]
    design: Design
    combined_low: np.ndarray
    combined_high: np.ndarray

    def combined_relative_width(self) -> dict[str, float | None]:
        """Predicted relative width of the combined interval after the run (expected and
        90 % range, :func:`combined_width`); None without a width prediction."""
        pred = self.design.width
        if pred is None:
            return {"expected": None, "low90": None, "high90": None}
        return {key: combined_width(self.current, self.design.mu, getattr(pred, key),
                                    quantile=q) for key, q in RANGE_QUANTILES.items()}

    @property
    def worst_combined_width(self) -> float:
        """Largest predicted width of the combined interval over the range [-]."""
        return float(np.max(self.combined_high - self.combined_low))

    def as_dict(self) -> dict[str, Any]:
        lo, hi = self.current
        d = self.design.as_dict()
        return {"kind": "abu-next", "format_version": 1, "current_interval": [lo, hi],
                "current_width": hi - lo,
                "predicted_worst_combined_width": self.worst_combined_width,
                "predicted_median_combined_width":
                    float(np.median(self.combined_high - self.combined_low)),
                "current_relative_width": (hi - lo) / (0.5 * (hi + lo)),
                "predicted_combined_width": self.combined_relative_width(),
                "predicted_combined": [{"mu": float(m), "mu_low": float(a), "mu_high": float(b)}
                                       for m, a, b in zip(self.design.mu, self.combined_low,
                                                          self.combined_high)],
                "design": d, "simulate_args": d["simulate_args"]}


def propose_next(intervals: Sequence[dict[str, Any]], spec: DesignSpec | None = None
                 ) -> Proposal:
    """The staircase designed for the combined interval, with its predicted combined interval.

    ``spec`` gives everything but the range (drive, limits, camera); its range is replaced.
    """
    lo, hi = combine(intervals)
    base = spec or DesignSpec(lo, hi)
    design = design_staircase(replace(base, mu_lo=lo, mu_hi=hi))
    return Proposal((lo, hi), design, np.maximum(design.mu_low, lo),
                    np.minimum(design.mu_high, hi))
