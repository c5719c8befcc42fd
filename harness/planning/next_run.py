"""``abu next``: the run that shrinks the combined interval on mu most.

The intervals measured so far (``abu measure`` summaries, or ``abu simulate`` summaries of
co-simulated runs) all contain mu, so mu lies in their intersection [L, H]. The next run is the
staircase :func:`harness.planning.design.design_staircase` plans for the prior range [L, H]: for every
mu there it keeps the ball stuck through the first step, puts the slip inside the record and
has the smallest worst-case predicted interval. Its predicted combined interval at mu is
[max(L, low(mu)), min(H, high(mu))]; the proposal reports its worst case over [L, H] beside
the current width.

With the design's predicted ``abu measure`` width w(mu) (:mod:`.width_model`, expected and 90 %
range) the measured interval at mu is about mu [1 - w/2, 1 + w/2] (w relative to its mid), and
the combined one its intersection with [L, H]: ``predicted_combined_width`` gives its relative
width (hi - lo) / mid, mean over the log-spaced mu grid of the range, expected and 90 % range.
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


@dataclass
class Proposal:
    """The proposed next run and its predicted effect."""

    current: tuple[float, float]
    design: Design
    combined_low: np.ndarray
    combined_high: np.ndarray

    def combined_relative_width(self) -> dict[str, float | None]:
        """Predicted relative width of the combined interval after the run (expected and
        90 % range), mean over the mu grid; None without a width prediction."""
        pred = self.design.width
        if pred is None:
            return {"expected": None, "low90": None, "high90": None}
        lo, hi = self.current
        mu = self.design.mu
        out: dict[str, float | None] = {}
        for key in ("expected", "low90", "high90"):
            w = np.minimum(getattr(pred, key), 2.0)        # a null bound: nothing gained
            a, b = np.maximum(lo, mu * (1 - w / 2)), np.minimum(hi, mu * (1 + w / 2))
            out[key] = float(np.mean((b - a) / (0.5 * (a + b))))
        return out

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
