"""The digital speed controller's sample time found from the record (SI).

``abu measure --kinematics drive-model`` over a staircase with the loop unknown and no
``--controller-sample-time``: the drive model puts each step of the staircase on the
controller's first sample at or after it (:func:`abu_model.loop_response.sampled`), so a wrong
sample time leaves each step's delay a different part of a sample off. That is a persistent
angle offset of (step size) x (delay) after each step (1 Hz steps, 0.1 ms: 6e-4 rad, four
times the twin's tracking noise), not a sub-frame detail, so the sample time shows in the
record even where it is shorter than the frame interval.

**Candidates** (:func:`candidates`): a continuous controller, the record's frame interval
(a camera and controller on one clock, as the twin's), and the common controller rates of
:data:`CONTROLLER_RATES_HZ`; a sample time at or above the staircase's shortest step spacing
is dropped (two steps would share a sample, which the model cannot hold), and so is a rate
within 1 % of one already listed (a 5000 frames/s camera's interval is the 5 kHz rate), and
one that moves no step from where an earlier candidate puts it (a staircase whose step times
are round, e.g. every 45 ms from 30 ms, lies on the 0.1, 0.125, 0.2, 0.25, 0.5 and 1 ms grids:
those controllers are the continuous model there, and are not told from it).

**Search** (:func:`find_sample_time`): fitting every candidate from the scored starts would
take 1-3 s each. So the loop is fitted as with a stated sample time for the frame interval
only; each candidate is then ranked by a short refit of the time offset and loop from that
fit (:func:`measurement.kinematics.drive_model.quick_fit`: :data:`QUICK_EVALUATIONS`
evaluations on every :data:`QUICK_EVERY` th sample; refitting matters: a loop fitted with one
sample time has absorbed part of the step timing, and the time offset alone then ranks the
first candidate best), and the :data:`N_REFITS` best ranked are fitted in full from their short
fits. Of these full fits the accepted one with the smallest residual is kept, else the refused
one with the smallest residual. At most three full fits are compared, each against the drive
model's own acceptance tests.
"""
from __future__ import annotations

import math

import numpy as np

from abu_model.loop_response import Setpoints, sampled
from controller.drive import Drive

from measurement.kinematics.drive_model import fitted_loop, quick_fit
from measurement.kinematics.estimators import sample_interval
from measurement.kinematics.model_fit import DriveFit

#: Common digital speed-controller rates tried beside the frame rate [Hz].
CONTROLLER_RATES_HZ = (1000.0, 2000.0, 2500.0, 4000.0, 5000.0, 8000.0, 10000.0)
#: The longest sample time taken [s] (as ``--controller-sample-time``'s range).
MAX_SAMPLE_TIME_S = 0.1
#: Candidates within this relative distance of one already listed are the same.
SAME_REL = 0.01
#: The short ranking refit: evaluations, and every how many samples it uses.
QUICK_EVALUATIONS = 10
QUICK_EVERY = 4
#: The best ranked candidates fitted in full (besides the frame interval's fit).
N_REFITS = 2


def candidates(frame_interval_s: float, setpoints: Setpoints) -> list[float | None]:
    """The sample times tried [s], None (a continuous controller) first, then the frame
    interval, then :data:`CONTROLLER_RATES_HZ`'s (module doc). A sample time that puts every
    step where another candidate does (steps on its grid already: a staircase of round step
    times) is the same model and is left out, the first listed kept."""
    gaps = np.diff(np.asarray(setpoints.step_times, float))
    shortest = float(np.min(gaps)) if gaps.size else math.inf
    out: list[float | None] = [None]
    applied = [np.asarray(setpoints.step_times, float)]
    for period in (frame_interval_s,) + tuple(1.0 / r for r in CONTROLLER_RATES_HZ):
        if not (period < shortest and period <= MAX_SAMPLE_TIME_S) or any(
                abs(period - q) <= SAME_REL * q for q in out if q is not None):
            continue
        steps = np.asarray(sampled(setpoints, period).step_times, float)
        if any(a.size == steps.size and np.allclose(a, steps, rtol=0.0, atol=1e-9)
               for a in applied):
            continue
        out.append(period)
        applied.append(steps)
    return out


def describe(period: float | None) -> str:
    """'continuous' or '2.22e-04 s'."""
    return "continuous" if period is None else f"{period:.3g} s"


def loop_drive(values: dict[str, float], period: float | None) -> Drive:
    """The staircase loop of fitted ``values`` (names of drive_model.LOOP) as a start,
    digital with ``period`` [s] (None: continuous)."""
    return fitted_loop(values, period, "unknown loop: a warm start")


def find_sample_time(inp, time: np.ndarray, theta: np.ndarray,
                     sigma_theta: float | None) -> DriveFit:
    """The best full fit over the candidate sample times (module doc). ``inp``: an
    :class:`measurement.kinematics.unknown_loop.UnknownLoopInput` over a staircase; its
    ``fit_with(period, ...)`` (the scored starts) and ``fit_from(drive, t_off_s, ...)`` (one
    warm start, the drive's own sample time) fit the loop."""
    t = np.asarray(time, dtype=float)
    th = np.asarray(theta, dtype=float)
    cands = candidates(sample_interval(t), inp.setpoints)
    first = cands[1] if len(cands) > 1 else None
    fits: dict[float | None, DriveFit] = {first: inp.fit_with(first, t, th, sigma_theta)}
    start = fits[first].params
    ranked: list[float | None] = [first]
    if "zeta" in start:   # a fit with values to start from (one that failed has none)
        quick = {p: quick_fit(t[::QUICK_EVERY], th[::QUICK_EVERY], loop_drive(start, p),
                              inp.setpoints, start["t_off_s"], inp.settings,
                              QUICK_EVALUATIONS) for p in cands}
        ranked = sorted(cands, key=lambda p: quick[p][0])
        for p in ranked[:N_REFITS]:
            if p not in fits and quick[p][1]:
                fits[p] = inp.fit_from(loop_drive(quick[p][1], p), quick[p][1]["t_off_s"],
                                       t, th, sigma_theta)
    best_p, best = min(fits.items(), key=lambda kv: (
        not kv[1].accepted, kv[1].rms_ratio if math.isfinite(kv[1].rms_ratio) else math.inf))
    best.params = {**best.params, "controller_sample_time_s": best_p or 0.0,
                   "sample_times_tried": float(len(cands)),
                   "sample_times_fitted": float(len(fits))}
    clock = "continuous" if best_p is None else f"digital, sample time {best_p:.3g} s"
    best.loop = (f"unknown, fitted freely ({clock} found among {len(cands)} candidate sample "
                 "times)")
    if not best.accepted:
        best.why = (f"every controller sample time tried was refused ({len(cands)} scored: "
                    f"{', '.join(describe(p) for p in cands)}; fitted in full: "
                    f"{', '.join(describe(p) for p in fits)}; the best, {describe(best_p)}: "
                    f"{best.why})")
    return best


__all__ = ["CONTROLLER_RATES_HZ", "candidates", "find_sample_time", "loop_drive"]
