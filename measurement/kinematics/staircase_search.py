"""The staircase the drive followed, found from the record itself (SI).

``abu measure --kinematics drive-model --find-staircase``: the user knows the drive followed
one of the report's staircases (an inclined sine rounded to setpoint steps of ``--step-hz``,
report sec. 4.2) but not its figures on the camera's clock, and has not identified the loop
(``abu identify``). The staircase's timing and the loop are fitted from the record:

1. **Where the staircase lies** (:mod:`measurement.kinematics.staircase_guess`): a smooth
   guess, then each rounding and step count scored over a grid of start times and durations.
2. **The staircase with the loop, continuous** (:class:`_SineModel`): the free loop of
   :mod:`measurement.kinematics.unknown_loop` over the staircase, its duration te and span s
   [steps] fitted with the time offset and the loop, from the grid's best cells (the first at
   the noise ends it; up to six where none of the first three is within the acceptance
   limit), on every third sample, the best then on all. A digital controller's sampling is
   left out here: it makes the step times, and so the residual, piecewise constant in te and
   s, which least squares cannot follow.
3. **The loop over that staircase** as :mod:`.unknown_loop` fits it for a stated staircase,
   the controller's sample time stated or found (:mod:`.sample_time_search`), from step 2's
   loop first.
4. **Which sample each step fell on** (:func:`_sine_assignment`, a digital controller): step
   2 places the steps to ~0.1-0.5 % of te (the sampling biases it), but a step a fraction of
   a sample off lands on another sample, which leaves a residual that is not white (without
   this step the three records of ``tests/test_staircase_search.py`` are refused). The
   sine's start within +- a sample, its duration within +- 0.6 % and its span within +- 0.01
   step (or 3 of step 2's standard errors where wider, up to three times those) are searched;
   each distinct assignment of steps to samples is scored by its residual (the loop and
   offset linearised, projected out with the nuisance terms), and the loop is fitted again
   over the best one. The staircase reported is the sine that gives that assignment.

Where steps 3-4 refuse every sample time but step 2's fit on all samples passed the tests
(a controller fast enough to look continuous), that fit is the result, continuous.

The result is the drive model's own fit with its acceptance tests and error bars, and with
the fallback to the Savitzky-Golay kinematics on refusal. The staircase found is in the fit's
``params`` (``staircase_*``) and ``loop`` text. Not in the error bars: the discrete choices
(rounding, step count, sample assignment), each made by the residual. Measured on the
benchmark family (``benchmarks/bench_width_floor.py --find-staircase``, see the README).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from abu_model.loop_response import Setpoints, response, sampled
from controller.drive import Drive

from measurement.kinematics.drive_model import LoopModel, fit_drive_model
from measurement.kinematics.estimators import noise_sigma, sample_interval
from measurement.kinematics.model_fit import (DriveFit, DriveModelSettings, fit_model,
                                              linear_basis)
from measurement.kinematics.staircase_guess import (SineStaircase, candidate_staircases,
                                                    start_span, sine_guess, timing_grid)
from measurement.kinematics.unknown_loop import (FIND, GOOD_ENOUGH_RMS, UnknownLoopInput,
                                                 _free_settings, check_sample_time)

TWO_PI = 2.0 * math.pi
#: Step 2 fits the time offset within +- this [s] and te within this range of the grid's
#: [-] (wide: tighter bounds, +- 0.05 s and 0.8-1.25, stopped the fit of seed 16 of the
#: family at a bound, residual 46 x the noise).
T_OFF_RANGE_S = 0.2
TE_RANGE = (0.4, 2.5)
#: Step 2 runs on every this many samples (a search: step 3 fits on all of them).
SEARCH_EVERY = 3
#: The grid's best cells fitted in step 2: the first at the noise ends it; after the first
#: N_FIRST, one whose residual is within the acceptance limit (a digital controller's
#: timing, which steps 3 and 4 model, can leave it not white here); up to N_CANDIDATES
#: where none is (the grid's generic loops can rank the drive's staircase fourth or fifth
#: where its loop rings).
N_FIRST = 3
N_CANDIDATES = 6
#: Step 4's search: start shifts over +- a sample in 2 SINE_SHIFTS + 1 points, durations
#: over +- SINE_TE_REL (at least 2 SINE_SHIFTS + 1 points, at most SINE_TE_MAX), spans within
#: +- SINE_SPAN steps in 5; the best SINE_RESCORE assignments scored again. +- 0.6 %, not
#: 0.2 %: a frame-rate controller's sampling biases the continuous fit's te by up to 0.4 %
#: (8 of its standard errors: the fast staircase of tests/test_staircase_search.py).
SINE_SHIFTS = 8
SINE_TE_REL = 0.006
SINE_TE_MAX = 161
SINE_SPAN = 0.01
SINE_RESCORE = 5


class _SineModel(LoopModel):
    """The continuous loop over a :class:`SineStaircase` whose te [s] and span [steps] are
    fitted beside the time offset and the loop (step 2)."""

    def __init__(self, time: np.ndarray, drive: Drive, stair: SineStaircase, te_s: float,
                 span_steps: float, settings: DriveModelSettings, t_off_s: float = 0.0):
        self.stair = stair
        super().__init__(time, drive, stair.setpoints(te_s, span_steps), settings, t_off_s)
        self.lo[0], self.hi[0] = -T_OFF_RANGE_S, T_OFF_RANGE_S
        self.add_parameter("staircase_te_s", te_s, TE_RANGE[0] * te_s, TE_RANGE[1] * te_s)
        self.add_parameter("staircase_span_steps", span_steps, float(stair.n),
                           stair.n + 1.0 - 1e-6)
        self._key = (te_s, span_steps)

    def setpoints_for(self, p: np.ndarray) -> Setpoints:
        key = (float(p[-2]), float(p[-1]))
        if key != self._key:   # the fit's Jacobian moves one parameter at a time: cached
            self.sp, self._key = self.stair.setpoints(*key), key
        return self.sp


def _key(fit: DriveFit) -> tuple[bool, float]:
    """Accepted first, then the smaller residual."""
    rms = fit.rms_ratio
    return (not fit.accepted, rms if math.isfinite(rms) else math.inf)


def _at_noise(fit: DriveFit) -> bool:
    return fit.accepted and _key(fit)[1] <= GOOD_ENOUGH_RMS


def _drive_of(params: dict[str, float], sample_time: float | None = None) -> Drive:
    """The PI loop of a fit's parameters (a lag and a setpoint filter kept above 0, so that a
    refit has them as parameters)."""
    return Drive(model="pi-lag-weighted", zeta=params["zeta"], omega_n=params["omega_n_rad_s"],
                 tau_motor=max(params.get("tau_motor_s", 0.0), 1e-5),
                 setpoint_weight=params.get("setpoint_weight", 1.0),
                 setpoint_tau=max(params.get("setpoint_tau_s", 0.0), 1e-4),
                 sample_time=sample_time, source="the staircase found from the record")


def _loop_vector(q: dict[str, float]) -> np.ndarray:
    """(t_off, zeta, omega_n, tau, b, tau_f) of a fit's parameters."""
    return np.array([q["t_off_s"], q["zeta"], q["omega_n_rad_s"], q.get("tau_motor_s", 0.0),
                     q.get("setpoint_weight", 1.0), q.get("setpoint_tau_s", 0.0)])


@dataclass
class _Found:
    """Step 2's result: the staircase (its start on the record's clock), te [s], span
    [steps] and the fit."""

    stair: SineStaircase
    te_s: float
    span_steps: float
    fit: DriveFit
    on_all_samples: bool = False


def _continuous(time: np.ndarray, theta: np.ndarray, sigma: float, step_rad_s: float,
                settings: DriveModelSettings) -> _Found | None:
    """Steps 1 and 2 of the module doc on every SEARCH_EVERY-th sample, then the best fitted
    again on all of them."""
    guess = sine_guess(time, theta)
    if not abs(guess.span_rad_s) >= step_rad_s:
        return None
    t, th = time[::SEARCH_EVERY], theta[::SEARCH_EVERY]
    best: tuple[DriveFit, _SineModel] | None = None
    for i, cell in enumerate(timing_grid(t, th, guess, candidate_staircases(guess, step_rad_s)
                                         )[:N_CANDIDATES]):
        if i >= N_FIRST and best is not None and _key(best[0])[1] <= settings.max_rms_ratio:
            break
        model = _SineModel(t, cell.drive, cell.stair, cell.te_s, start_span(guess, cell.stair),
                           settings)
        fit = fit_model(t, th, model, sigma, settings)
        if "staircase_te_s" in fit.params and (best is None or _key(fit) < _key(best[0])):
            best = (fit, model)
        if best is not None and _at_noise(best[0]):
            break
    if best is None:
        return None
    q, stair = best[0].params, best[1].stair
    model = _SineModel(time, _drive_of(q), stair, q["staircase_te_s"],
                       q["staircase_span_steps"], settings, q["t_off_s"])
    full = fit_model(time, theta, model, sigma, settings)
    # the fit on all samples, unless it failed or was refused where the search's was not (its
    # residual is not comparable with the search's: other samples)
    use_full = "staircase_te_s" in full.params and (full.accepted or not best[0].accepted)
    fit = full if use_full else best[0]
    q = fit.params
    return _Found(replace(stair, t0_s=stair.t0_s + q["t_off_s"]), q["staircase_te_s"],
                  q["staircase_span_steps"], fit, use_full)


def _theta(setpoints: Setpoints, time: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The loop's angle [rad] at ``time`` for p = (t_off, zeta, omega_n, tau, b, tau_f)."""
    return response(setpoints, time - p[0], p[1], p[2], max(p[3], 0.0), p[4], True,
                    setpoint_tau=max(p[5], 0.0)).theta


def _design(time: np.ndarray, setpoints: Setpoints, p: np.ndarray, basis: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The loop's angle over ``setpoints`` at p and the columns that the residual is
    projected off: the nuisance ``basis`` and the loop and offset linearised (forward
    differences), orthonormalised."""
    base = _theta(setpoints, time, p)
    cols = [basis]
    for j in range(p.size):
        h = 1e-6 if j == 0 else 1e-4 * max(abs(p[j]), 1e-3)
        up = p.copy()
        up[j] += h
        cols.append(((_theta(setpoints, time, up) - base) / h)[:, None])
    return base, np.linalg.qr(np.hstack(cols))[0]


def _sse_off(e: np.ndarray, q: np.ndarray) -> float:
    e = e - q @ (q.T @ e)
    return float(e @ e)


def _assignments(found: _Found, start: float, period: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Every distinct assignment of the steps to controller samples (rows of sample
    indices) that the sine gives near the continuous fit (step 4's box, module doc), and a
    sine that gives each (rows of start shift [s], te [s], span [steps])."""
    stair = found.stair
    # the box: at least SINE_TE_REL and SINE_SPAN, and 3 standard errors of the continuous
    # fit; durations dense enough that the last step moves by half a sample at most
    std = found.fit.std
    te_rel = min(max(SINE_TE_REL, 3.0 * std.get("staircase_te_s", 0.0) / found.te_s),
                 3 * SINE_TE_REL)
    span_box = min(max(SINE_SPAN, 3.0 * std.get("staircase_span_steps", 0.0)), 3 * SINE_SPAN)
    n_te = int(min(2 * math.ceil(te_rel * found.te_s / (0.5 * period)) + 1, SINE_TE_MAX))
    shifts = np.linspace(-period, period, 2 * SINE_SHIFTS + 1)[:, None, None]
    rel = np.linspace(-te_rel, te_rel, max(n_te, 2 * SINE_SHIFTS + 1))[None, :, None]
    rows, sines = [], []
    grid = np.broadcast_arrays(shifts, found.te_s * (1 + rel))
    for span in found.span_steps + np.linspace(-span_box, span_box, 5):
        if not stair.n <= span < stair.n + 1:
            continue
        x = stair.step_fractions(span)[None, None, :]
        k = np.ceil((start + shifts + found.te_s * (1 + rel) * x) / period - 1e-9)
        k = k.reshape(-1, x.size)
        ok = np.all(np.diff(k, axis=1) > 0, axis=1)
        rows.append(k[ok])
        sines.append(np.column_stack([grid[0].ravel(), grid[1].ravel(),
                                      np.full(ok.size, span)])[ok])
    if not rows:
        return np.empty((0, stair.n)), np.empty((0, 3))
    rows_all, first = np.unique(np.vstack(rows), axis=0, return_index=True)
    return rows_all, np.vstack(sines)[first]


def _sine_assignment(time: np.ndarray, theta: np.ndarray, found: _Found, p: np.ndarray,
                     period: float, harmonics: int) -> tuple[np.ndarray, _Found] | None:
    """Step 4 of the module doc: the steps' sample times [s] (the model's clock, before its
    time offset) that leave the smallest residual, and the sine that gives them (``found``
    with its start, te and span; None where the box holds no assignment). Each assignment
    is scored with the loop linearised once, at the continuous fit's steps (one response an
    assignment); the best SINE_RESCORE are scored again, linearised at their own steps."""
    start = found.stair.t0_s - p[0]   # the sine's start on the model's clock
    basis = linear_basis(time, theta, harmonics)
    levels = found.stair.setpoints(found.te_s, found.span_steps).levels
    rows, sines = _assignments(found, start, period)
    if rows.shape[0] == 0:
        return None
    at = (lambda k: Setpoints(tuple(np.multiply(k, period).tolist()), levels))
    _, q = _design(time, at(rows[rows.shape[0] // 2]), p, basis)
    quick = [_sse_off(theta - _theta(at(k), time, p), q) for k in rows]
    best = []
    for i in np.argsort(quick)[:SINE_RESCORE]:
        base, q_i = _design(time, at(rows[i]), p, basis)
        best.append((_sse_off(theta - base, q_i), int(i)))
    i = min(best)[1]
    shift, te, span = sines[i]
    return rows[i].astype(float) * period, replace(found, stair=replace(
        found.stair, t0_s=found.stair.t0_s + float(shift)), te_s=float(te),
        span_steps=float(span))


@dataclass(frozen=True)
class FoundStaircaseInput:
    """The drive-model input of ``--find-staircase`` (module doc): the setpoint's step
    [rad/s] (the setup's 1 Hz by default) and the controller's sample time [s] (a number,
    None for a continuous controller, :data:`FIND` to find it); the loop is fitted freely."""

    step_rad_s: float = TWO_PI
    sample_time_s: float | str | None = FIND
    settings: DriveModelSettings = field(default_factory=_free_settings)

    def __post_init__(self) -> None:
        from abu_model.errors import ParameterError
        if not (math.isfinite(self.step_rad_s) and self.step_rad_s > 0):
            raise ParameterError("step_rad_s", self.step_rad_s, "a setpoint step > 0 rad/s")
        check_sample_time(self.sample_time_s)

    @property
    def theta_harmonics_fitted(self) -> bool:
        """As a stated staircase: the lens prior on theta's harmonic is kept."""
        return False

    @property
    def loop_description(self) -> str:
        return "unknown, fitted freely over the staircase found from the record"

    def fit(self, time: np.ndarray, theta: np.ndarray, sigma_theta: float | None) -> DriveFit:
        """The drive model's fit over the staircase found (module doc), with its tests."""
        t = np.asarray(time, dtype=float)
        th = np.asarray(theta, dtype=float)
        sigma = noise_sigma(th) if sigma_theta is None else float(sigma_theta)
        found = _continuous(t, th, sigma, self.step_rad_s, self.settings)
        if found is None:
            return DriveFit(False, f"no staircase of {self.step_rad_s / TWO_PI:g} Hz steps "
                                   "found in the record (its speed changes by less than a "
                                   "step, or no staircase fits)")
        fit, period = None, 0.0
        if self.sample_time_s == FIND:
            # the frame interval first (a camera and controller on one clock, the twin's):
            # the search below ranks each sample time over the continuous fit's steps, before
            # step 4, so every candidate can look wrong there (the family's seeds 0-59: 16 of
            # 39 staircases accepted without this, against 18 of 18 with the frame interval
            # stated in the development runs)
            frame = sample_interval(t)
            fit = replace(self, sample_time_s=frame)._stepped(t, th, sigma, found, frame)
            period = frame
            if fit.accepted:
                fit.params = {**fit.params, "controller_sample_time_s": frame}
            else:
                fit = None
        if fit is None:
            fit = self._loop_fit(t, th, sigma, found.stair.setpoints(found.te_s,
                                                                     found.span_steps),
                                 found.fit.params)
            period = (fit.params.get("controller_sample_time_s", 0.0)
                      if self.sample_time_s == FIND else self.sample_time_s) or 0.0
            if period > 0 and "zeta" in fit.params and not _at_noise(fit):
                fit = self._assigned(t, th, sigma, fit, found, float(period))
        if not fit.accepted and self.sample_time_s in (FIND, None) and found.on_all_samples \
                and found.fit.accepted:
            # step 2's own fit passed the tests: the staircase's timing fitted with the loop,
            # continuous (a controller fast enough to look continuous, whose sample time is
            # not among the candidates: tests/test_staircase_search.py, a 30 kHz controller)
            fit, period = found.fit, 0.0
            if self.sample_time_s == FIND:
                fit.params = {**fit.params, "controller_sample_time_s": 0.0}
        return self._labelled(fit, found, period)

    def _labelled(self, fit: DriveFit, found: _Found, period: float) -> DriveFit:
        """``fit`` with the staircase found in its params and loop text (its own sine where
        step 4 chose one)."""
        q = found.fit.params
        # step 4's sine where it chose one (its params hold it), else step 2's
        sine = {k: fit.params.get(k, v) for k, v in (
            ("staircase_t0_s", found.stair.t0_s), ("staircase_te_s", found.te_s),
            ("staircase_span_steps", found.span_steps))}
        fit.params = {**fit.params, **sine, "staircase_steps": float(found.stair.n),
                      "staircase_rounding_offset": found.stair.offset,
                      "staircase_omega0_rad_s": found.stair.omega0_rad_s
                      + q.get("omega_offset_rad_s", 0.0),
                      "staircase_step_rad_s": found.stair.direction * self.step_rad_s}
        clock = f"digital, {period:g} s" if period > 0 else "continuous"
        fit.loop = (f"unknown, fitted freely ({clock}) over the staircase found from the "
                    f"record: {found.stair.n} steps of {self.step_rad_s / TWO_PI:g} Hz, "
                    f"rounding {found.stair.rounding}, te {sine['staircase_te_s']:.4g} s")
        if not fit.accepted:
            fit.why = f"the staircase found from the record: {fit.why}"
        return fit

    def _stepped(self, t: np.ndarray, th: np.ndarray, sigma: float, found: _Found,
                 period: float) -> DriveFit:
        """Steps 3 and 4 with the controller's sample time ``period`` [s]."""
        fit = self._loop_fit(t, th, sigma, found.stair.setpoints(found.te_s, found.span_steps),
                             found.fit.params)
        if "zeta" in fit.params and not _at_noise(fit):
            fit = self._assigned(t, th, sigma, fit, found, period)
        return fit

    def _loop_fit(self, t: np.ndarray, th: np.ndarray, sigma: float, setpoints: Setpoints,
                  continuous: dict[str, float]) -> DriveFit:
        """Step 3: from step 2's loop (a warm start) where the sample time is known, and
        from the scored starts (with the sample time search) where that is not at the
        noise."""
        loop = UnknownLoopInput(setpoints=setpoints, sample_time_s=self.sample_time_s,
                                settings=self.settings)
        warm = None
        if self.sample_time_s != FIND:
            warm = loop.fit_from(_drive_of(continuous, self.sample_time_s), 0.0, t, th, sigma)
            if _at_noise(warm):
                return warm
        cold = loop.fit(t, th, sigma)
        return warm if warm is not None and _key(warm) < _key(cold) else cold

    def _assigned(self, t: np.ndarray, th: np.ndarray, sigma: float, fit: DriveFit,
                  found: _Found, period: float) -> DriveFit:
        """Step 4: the loop fitted again over the best assignment of steps to samples, where
        it fits better."""
        q = fit.params
        p = _loop_vector(q)
        chosen = _sine_assignment(t, th, found, p, period, self.settings.harmonics)
        if chosen is None:
            return fit
        times, sine = chosen
        levels = found.stair.setpoints(found.te_s, found.span_steps).levels
        moved = fit_drive_model(t, th, _drive_of(q, period),
                                Setpoints(tuple(times.tolist()), levels), sigma_theta=sigma,
                                settings=self.settings, t_off_s=float(p[0]))
        if "zeta" not in moved.params or not _key(moved) < _key(fit):
            return fit
        start = np.asarray(sampled(found.stair.setpoints(found.te_s, found.span_steps),
                                   period).step_times)
        moved.params = {**moved.params, **{k: v for k, v in q.items()
                                           if k not in moved.params},
                        "staircase_steps_moved": float(np.sum(np.abs(times - start)
                                                              > 0.5 * period))
                        if start.size == times.size else math.nan,
                        # the sine that puts the steps on these samples (the continuous
                        # fit's te is biased by the sampling by up to 0.4 %)
                        "staircase_t0_s": sine.stair.t0_s, "staircase_te_s": sine.te_s,
                        "staircase_span_steps": sine.span_steps}
        return moved


__all__ = ["FoundStaircaseInput", "FIND"]
