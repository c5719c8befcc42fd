"""One confidence set on mu from the kinematics of several Savitzky-Golay windows (Bonferroni).

The model-based set (:func:`measurement.inference.infer_mu.infer_mu`) is as sharp as q = mu_req at the
slip, and q's error there is a trade between noise and smoothing bias that no single window
wins everywhere: a long window averages the noise of omega_dot down (its 1-sigma error falls as
window^-2.5) but is biased across a kink of the drive, which the estimator's truncation bound
then has to cover; a short one is nearly unbiased but noisy. Each window's set is honest on its
own where its error terms hold (noise bar + truncation bound + lens prior), and then the
sets of K windows, each at level 1 - alpha / K, all hold mu together with probability
>= 1 - alpha whatever their dependence (union bound): their intersection is a confidence set
at the stated level 1 - alpha, as sharp as the best window of each record, chosen by the data
without any selection bias.
The union bound is only as good as each set, and that is why it is off by default
(``AnalysisOptions.sg_extra_windows_s = ()``). Measured (``benchmarks/bench_width_floor.py``,
the 220 rendered recordings of ``bench_coverage.py``): 42 + 60 ms, each at 97.5 %, median
width 26.1 % against 34.9 % for 42 ms alone, but coverage 98.2 % with 2 misses by more than
2 % (rendered seed 58 by 40 %) against 100 % and none: a 60 ms window's q errs along the first
milliseconds of slip after a kink of the drive (its error is not the constant scale the set's
kinematic nuisance assumes), and a slip with mu_d ~ mu turns that into a misplaced onset. The
42 ms set's larger noise bar happens to cover it. Use it where the drive has no kinks near the
slip, or once the kinematic error enters the likelihood as a process rather than a scale.

A window's bound is no constraint where that window cannot give it (null: no slip within its
trusted region, a slip before its trusted start); a set that refuses both bounds because the
markers were lost across the slip makes the intersection refuse them too. Sets that do not
overlap are a contradiction of the data at the stated level: both bounds are then null.
"""
from __future__ import annotations

from dataclasses import replace

from measurement.inference.types import LOST_ACROSS_SLIP, Inference


def level_each(confidence: float, k: int) -> float:
    """Level of each of ``k`` sets whose intersection holds at ``confidence`` [-]."""
    return 1.0 - (1.0 - float(confidence)) / max(int(k), 1)


def _tightest(values: list[float | None], pick) -> float | None:
    known = [v for v in values if v is not None]
    return pick(known) if known else None


def intersect_sets(sets: list[Inference], windows_s: list[float], confidence: float
                   ) -> Inference:
    """The intersection of per-window sets; the first set (the primary window's) supplies the
    best fit, the model curves and the details.

    Args:
        sets: one :class:`Inference` per window, each at ``level_each(confidence, len(sets))``.
        windows_s: the Savitzky-Golay windows [s], in the order of ``sets``.
        confidence: the level the intersection is stated at [-].
    """
    primary = sets[0]
    per_window = [{"sg_window_s": w, "mu_low": s.mu_low, "mu_high": s.mu_high,
                   "mu_d_low": s.mu_d_low, "mu_d_high": s.mu_d_high, "status": s.status,
                   "confidence": s.confidence} for w, s in zip(windows_s, sets)]
    combination = "one window" if len(sets) == 1 else \
        f"intersection of {len(sets)} windows' sets, each at level " \
        f"{level_each(confidence, len(sets)):.4g} (Bonferroni)"
    details = {**primary.details, "windows": per_window, "combination": combination}
    if len(sets) == 1:
        return replace(primary, confidence=confidence, details=details)
    lost = [s for s in sets if s.status == LOST_ACROSS_SLIP]
    if lost:
        return replace(primary, mu_low=None, mu_high=None, mu_d_low=None, mu_d_high=None,
                       mu_d=None, status=lost[0].status, confidence=confidence,
                       details=details)
    lo = _tightest([s.mu_low for s in sets], max)
    hi = _tightest([s.mu_high for s in sets], min)
    mud_lo = _tightest([s.mu_d_low for s in sets], max)
    mud_hi = _tightest([s.mu_d_high for s in sets], min)
    status = "ok"
    if lo is not None and hi is not None and lo > hi:
        lo = hi = mud_lo = mud_hi = None
        status = "no bound: the windows' confidence sets do not overlap (the data contradict " \
                 "the model at the stated level)"
    elif lo is None or hi is None:
        # the reason of a window that leaves the same bounds null (the primary's first)
        same = [s.status for s in sets
                if (s.mu_low is None) == (lo is None) and (s.mu_high is None) == (hi is None)]
        status = same[0] if same else ("no slip in the trusted regions: only a lower bound"
                                       if lo is not None else "no bound")
    if mud_lo is not None and mud_hi is not None and mud_lo > mud_hi:
        mud_lo = mud_hi = None
    mu_d = primary.mu_d if (mud_lo is not None and mud_hi is not None and lo is not None
                            and hi is not None) else None
    if mu_d is not None:
        mu_d = min(max(mu_d, mud_lo), mud_hi)   # the primary's best within the common set
    return replace(primary, mu_low=lo, mu_high=hi, mu_d_low=mud_lo if mu_d is not None else None,
                   mu_d_high=mud_hi if mu_d is not None else None, mu_d=mu_d, status=status,
                   confidence=confidence, details=details)
