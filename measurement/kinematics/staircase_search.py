"""The staircase the drive followed, found from the record itself (SI).

``abu measure --kinematics drive-model --find-staircase``: the user knows the drive followed
one of the report's staircases (an inclined sine rounded to setpoint steps of ``--step-hz``,
report sec. 4.2) but not its figures on the camera's clock, and has not identified the loop
(``abu identify``). The staircase's timing and the loop are fitted from the record:

1. **Where the staircase lies** (:mod:`measurement.kinematics.staircase_guess`): a smooth
   guess, then each rounding and step count scored over a grid of start times and durations.
2. **The staircase with the loop, continuous** (:class:`.sine_model.SineModel`): the free loop of
   :mod:`measurement.kinematics.unknown_loop` over the staircase, its duration te and span s
   [steps] fitted with the time offset and the loop, from the grid's best cells (the first at
   the noise ends it; up to six where none of the first three is within the acceptance
   limit), on every third sample, the best then on all; where the best is beyond the
   acceptance limit, its staircase with a step fewer and one more is fitted from it too (the
   count can be one off with every other figure near the drive's). A digital controller's
   sampling is left out here: it makes the step times, and so the residual, piecewise
   constant in te and s, which least squares cannot follow.
3. **The loop over that staircase** as :mod:`.unknown_loop` fits it for a stated staircase,
   from step 2's loop first.
4. **Which sample each step fell on** (:mod:`measurement.kinematics.step_assignment`, a
   digital controller): step 2 places the steps to ~0.1-0.5 % of te (the sampling biases
   it), but a step a fraction of a sample off lands on another sample, which leaves a
   residual that is not white (without this step the three records of
   ``tests/test_staircase_search.py`` are refused). Each distinct assignment of steps to
   samples that a sine near step 2's gives is scored by its residual, and the loop is
   fitted again over the best one. The staircase reported is the sine that gives it.

The controller's sample time, unless stated (:meth:`FoundStaircaseInput._sample_time_found`):
the frame interval first (steps 3-4); where that is refused, step 2's own fit on all samples
where it is at the noise (a controller fast enough to look continuous), else the other
candidates of :mod:`.sample_time_search` ranked by their best assignment's residual about
the frame interval's loop, the best :data:`N_PERIODS` fitted over it. Ranked over step 2's
steps instead (that module's search, used here only where the frame interval's fit fails
outright), a controller faster than the camera can be ranked last: its steps fall many
samples from where step 2 put them.

Where steps 3-4 refuse every sample time but step 2's fit on all samples passed the tests
(a controller fast enough to look continuous), that fit is the result, continuous. Where the
result is refused up to :data:`RECOUNT_RMS` times the noise, steps 2-4 run again from the
grid's generic loops with the same count, then a step fewer and one more
(:meth:`FoundStaircaseInput._recount`); only what steps 3-4, its timing held, accept is taken.

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

from abu_model.loop_response import Setpoints, sampled
from controller.drive import Drive

from measurement.kinematics.drive_model import fit_drive_model
from measurement.kinematics.estimators import noise_sigma, sample_interval
from measurement.kinematics.model_fit import DriveFit, DriveModelSettings, fit_model
from measurement.kinematics.sample_time_search import candidates
from measurement.kinematics.sine_model import (SineModel, count_shifted, found_drive,
                                                refit_sine)
from measurement.kinematics.staircase_guess import (GRID_LOOPS, SineGuess, SineStaircase,
                                                    candidate_staircases, start_span,
                                                    sine_guess, timing_grid)
from measurement.kinematics.step_assignment import Assignment, best_assignment
from measurement.kinematics.unknown_loop import (FIND, GOOD_ENOUGH_RMS, UnknownLoopInput,
                                                 _free_settings, check_sample_time)

TWO_PI = 2.0 * math.pi
#: Step 2 runs on every this many samples (a search: step 3 fits on all of them).
SEARCH_EVERY = 3
#: The grid's best cells fitted in step 2: the first at the noise ends it; after the first
#: N_FIRST, one whose residual is within the acceptance limit (a digital controller's
#: timing, which steps 3 and 4 model, can leave it not white here); up to N_CANDIDATES
#: where none is (the grid's generic loops can rank the drive's staircase fourth or fifth
#: where its loop rings).
N_FIRST = 3
N_CANDIDATES = 6
#: Where the frame interval is refused: the other candidate sample times fitted over their
#: best assignment, best ranked first (seed 1014 of bench_staircase_search.py, a 10 kHz
#: controller filmed at 5000/s: its 1e-4 s ranks first of seven by the assignment's
#: residual, and was sixth of eight by the continuous fit's steps).
N_PERIODS = 2
#: The most steps a staircase found may have: step 4's box holds ~3 n^2 sample indices per
#: duration and span (1000 steps, --step-hz 0.01 on a 10 Hz record, took all of 24 GiB);
#: 30 steps 0.13 GB, 80 steps 0.46 GB (benchmarks/bench_search_limits.py --steps 30 80).
MAX_STEPS = 100
#: A final fit refused with a residual up to this many times the noise is tried again
#: (FoundStaircaseInput._recount). Records that are no staircase are mostly refused above
#: it: bench_width_floor.py's profile drives of seeds 8000-8047, 9000-9047 and 14000-14047
#: at 2.4-146x the noise, one below 3x (seed 14020, still refused after the retry).
RECOUNT_RMS = 3.0


def _key(fit: DriveFit) -> tuple[bool, float]:
    """Accepted first, then the smaller residual."""
    rms = fit.rms_ratio
    return (not fit.accepted, rms if math.isfinite(rms) else math.inf)


def _at_noise(fit: DriveFit) -> bool:
    return fit.accepted and _key(fit)[1] <= GOOD_ENOUGH_RMS


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


def _continuous(time: np.ndarray, theta: np.ndarray, sigma: float, guess: SineGuess,
                step_rad_s: float, settings: DriveModelSettings) -> _Found | None:
    """Step 2 of the module doc from the guess, on every SEARCH_EVERY-th sample, then the
    best fitted again on all of them."""
    t, th = time[::SEARCH_EVERY], theta[::SEARCH_EVERY]
    best: tuple[DriveFit, SineModel] | None = None
    for i, cell in enumerate(timing_grid(t, th, guess, candidate_staircases(guess, step_rad_s)
                                         )[:N_CANDIDATES]):
        if i >= N_FIRST and best is not None and _key(best[0])[1] <= settings.max_rms_ratio:
            break
        model = SineModel(t, cell.drive, cell.stair, cell.te_s, start_span(guess, cell.stair),
                          settings)
        fit = fit_model(t, th, model, sigma, settings)
        if "staircase_te_s" in fit.params and (best is None or _key(fit) < _key(best[0])):
            best = (fit, model)
        if best is not None and _at_noise(best[0]):
            break
    if best is None:
        return None
    if _key(best[0])[1] > settings.max_rms_ratio:
        best = _neighbour_counts(t, th, sigma, best, settings)
    stair = best[1].stair
    full = refit_sine(time, theta, sigma, stair, best[0].params, settings)
    # the fit on all samples, unless it failed or was refused where the search's was not (its
    # residual is not comparable with the search's: other samples)
    use_full = "staircase_te_s" in full.params and (full.accepted or not best[0].accepted)
    fit = full if use_full else best[0]
    q = fit.params
    return _Found(replace(stair, t0_s=stair.t0_s + q["t_off_s"]), q["staircase_te_s"],
                  q["staircase_span_steps"], fit, use_full)


def _neighbour_counts(t: np.ndarray, th: np.ndarray, sigma: float,
                      best: tuple[DriveFit, SineModel], settings: DriveModelSettings
                      ) -> tuple[DriveFit, SineModel]:
    """Step 2's best fit and the same staircase with one step fewer and one more (its
    rounding, te, loop and offset as fitted), the best of the three. Where the residual is
    beyond the acceptance limit, the step count can be one off with every other figure near
    the drive's; the grid's cells of the right count started elsewhere (seeds 0, 27 and 1000
    of bench_staircase_search.py: 11 steps for 12, 12 for 11, 11 for 10)."""
    fit, model = best
    q = fit.params
    for dn in (-1, 1):
        shifted = count_shifted(model.stair, q["staircase_span_steps"], dn)
        if shifted is None:
            continue
        other = SineModel(t, found_drive(q), shifted[0], q["staircase_te_s"], shifted[1],
                          settings, q["t_off_s"])
        moved = fit_model(t, th, other, sigma, settings)
        if "staircase_te_s" in moved.params and _key(moved) < _key(best[0]):
            best = (moved, other)
    return best


def _recounted(t: np.ndarray, th: np.ndarray, sigma: float, found: _Found, dn: int,
               settings: DriveModelSettings) -> _Found | None:
    """Step 2's result with ``dn`` steps more, fitted on every SEARCH_EVERY-th sample from
    the grid's generic loops and, for another count, its loop (seed 8024's 10 steps: 2.5x
    the noise from the found loop, 1.15x from a generic one; for the same count step 2
    ended there), the best on all samples (None: below 2 steps or every fit failed)."""
    shifted = count_shifted(found.stair, found.span_steps, dn)
    if shifted is None:
        return None
    stair, span = shifted
    ts, ths = t[::SEARCH_EVERY], th[::SEARCH_EVERY]
    best = None
    own = [] if dn == 0 else [found_drive(found.fit.params)]
    for drive in own + [Drive(model="pi-lag-weighted", **loop) for loop in GRID_LOOPS]:
        fit = fit_model(ts, ths, SineModel(ts, drive, stair, found.te_s, span, settings),
                        sigma, settings)
        if "staircase_te_s" in fit.params and (best is None or _key(fit) < _key(best)):
            best = fit
    if best is None:
        return None
    fit = refit_sine(t, th, sigma, stair, best.params, settings)
    if "staircase_te_s" not in fit.params:
        return None
    p = fit.params
    return _Found(replace(stair, t0_s=stair.t0_s + p["t_off_s"]), p["staircase_te_s"],
                  p["staircase_span_steps"], fit, True)


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
        guess = sine_guess(t, th)
        steps = abs(guess.span_rad_s) / self.step_rad_s
        step_hz = self.step_rad_s / TWO_PI
        if steps > MAX_STEPS:
            return DriveFit(False, f"the record's speed changes by about "
                                   f"{abs(guess.span_rad_s) / TWO_PI:.3g} Hz, {steps:.0f} steps "
                                   f"of {step_hz:g} Hz: the search takes staircases of at most "
                                   f"{MAX_STEPS} steps (is the drive's setpoint step "
                                   f"{step_hz:g} Hz? else state the staircase)")
        found = None if not steps >= 1 else _continuous(t, th, sigma, guess, self.step_rad_s,
                                                         self.settings)
        if found is None:
            return DriveFit(False, f"no staircase of {step_hz:g} Hz steps "
                                   "found in the record (its speed changes by less than a "
                                   "step, or no staircase fits)")
        fit, period = self._finish(t, th, sigma, found)
        if not fit.accepted and _key(fit)[1] <= RECOUNT_RMS:
            fit, period, found = self._recount(t, th, sigma, fit, period, found)
        return self._labelled(fit, found, period)

    def _recount(self, t: np.ndarray, th: np.ndarray, sigma: float, fit: DriveFit,
                 period: float, found: _Found) -> tuple[DriveFit, float, _Found]:
        """A result refused near the limit tried again: the same count first (its loop can
        be in another basin: tracked seed 4042 of bench_staircase_search.py, where 10 steps
        for 11 were accepted before it was tried), then a step fewer and one more (rendered
        seed 8024 of bench_width_floor.py: 9 steps for 10). Taken only where steps 3-4, te
        and span held, accept it: step 2's free te and span can make up for a step (tracked
        seed 3042: 12 steps for 13 passed it, its bar holding 80 %)."""
        for dn in (0, -1, 1):
            other = _recounted(t, th, sigma, found, dn, self.settings)
            if other is None:
                continue
            moved, moved_period = self._finish(t, th, sigma, other)
            if moved.accepted and moved is not other.fit:   # not step 2's own fit
                moved.params = {**moved.params, "staircase_count_change": float(dn)}
                return moved, moved_period, other
        return fit, period, found

    def _finish(self, t: np.ndarray, th: np.ndarray, sigma: float, found: _Found
                ) -> tuple[DriveFit, float]:
        """Steps 3 and 4 of the module doc over step 2's ``found``: the fit and the
        controller's sample time [s] (0: continuous)."""
        fit, period = None, 0.0
        if self.sample_time_s == FIND:
            fit, period = self._sample_time_found(t, th, sigma, found)
            if fit is not None:
                fit.params = {**fit.params, "controller_sample_time_s": period}
        if fit is None:   # a stated sample time, or the frame interval's fit failed
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
        return fit, period

    def _sample_time_found(self, t: np.ndarray, th: np.ndarray, sigma: float, found: _Found
                           ) -> tuple[DriveFit | None, float]:
        """Steps 3-4 with the controller's sample time [s] found (module doc): the best fit
        and its sample time (0: continuous), or (None, 0) where the frame interval's fit
        failed outright (no loop to start the others from)."""
        # the frame interval first (a camera and controller on one clock, the twin's): step
        # 3's sample time search ranks each sample time over the continuous fit's steps,
        # before step 4, so every candidate can look wrong there (the family's seeds 0-59:
        # 16 of 39 staircases accepted without this, against 18 of 18 with the frame
        # interval stated in the development runs)
        frame = sample_interval(t)
        fit = replace(self, sample_time_s=frame)._stepped(t, th, sigma, found, frame)
        if fit.accepted:
            return fit, frame
        if found.on_all_samples and _at_noise(found.fit):
            # step 2's own fit on all samples is at the noise: a controller fast enough to
            # look continuous (30-45 kHz in bench_staircase_search.py); the first fit at the
            # noise ends a search here
            return found.fit, 0.0
        if "zeta" not in fit.params:
            return None, 0.0
        # the other candidates ranked by their best assignment; step 3's search from the
        # scored starts after these rescued none of 8 refused records (bench seeds 0-31,
        # 1000-1047) and cost 1-21 s each, so it is not run
        return self._other_sample_times(t, th, sigma, found, fit, frame)

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
        if "staircase_count_change" in fit.params:   # FoundStaircaseInput._recount's
            dn = int(fit.params["staircase_count_change"])
            fit.loop += (f" (tried again: {found.stair.n - dn} steps refused near the limit)"
                         if dn else " (tried again from another loop)")
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
            warm = loop.fit_from(found_drive(continuous, self.sample_time_s), 0.0, t, th, sigma)
            if _at_noise(warm):
                return warm
        cold = loop.fit(t, th, sigma)
        return warm if warm is not None and _key(warm) < _key(cold) else cold

    def _assigned(self, t: np.ndarray, th: np.ndarray, sigma: float, fit: DriveFit,
                  found: _Found, period: float) -> DriveFit:
        """Step 4: the loop fitted again over the best assignment of steps to samples, where
        it fits better."""
        chosen = best_assignment(t, th, found.stair, found.te_s, found.span_steps,
                                 found.fit.std, _loop_vector(fit.params), period,
                                 self.settings.harmonics)
        moved = None if chosen is None else _refit(t, th, sigma, fit.params, found, period,
                                                   chosen, self.settings)
        return moved if moved is not None and _key(moved) < _key(fit) else fit

    def _other_sample_times(self, t: np.ndarray, th: np.ndarray, sigma: float,
                            found: _Found, fit: DriveFit, frame: float
                            ) -> tuple[DriveFit, float]:
        """The frame interval's ``fit`` refused: the other candidate sample times [s]
        (:func:`.sample_time_search.candidates`, continuous left out: step 2's fit stands
        for it) ranked by their best assignment's residual about that fit's loop, the best
        N_PERIODS fitted over their assignment; the best fit and its sample time."""
        p = _loop_vector(fit.params)
        ranked = []
        for period in candidates(frame, found.stair.setpoints(found.te_s, found.span_steps)):
            if period is None or period == frame:
                continue
            chosen = best_assignment(t, th, found.stair, found.te_s, found.span_steps,
                                     found.fit.std, p, period, self.settings.harmonics)
            if chosen is not None:
                ranked.append((chosen.sse_rad2, period, chosen))
        best = (fit, frame)
        for _, period, chosen in sorted(ranked, key=lambda r: r[0])[:N_PERIODS]:
            moved = _refit(t, th, sigma, fit.params, found, period, chosen, self.settings)
            if moved is not None and _key(moved) < _key(best[0]):
                best = (moved, period)
            if _at_noise(best[0]):
                break
        return best


def _refit(t: np.ndarray, th: np.ndarray, sigma: float, q: dict[str, float], found: _Found,
           period: float, chosen: Assignment, settings: DriveModelSettings) -> DriveFit | None:
    """The loop fitted from ``q`` with the steps on ``chosen``'s samples of ``period`` [s]
    (None where the fit failed); its params hold the sine that gives them (the continuous
    fit's te is biased by the sampling by up to 0.4 %) and how many steps moved."""
    continuous = found.stair.setpoints(found.te_s, found.span_steps)
    moved = fit_drive_model(t, th, found_drive(q, period),
                            Setpoints(tuple(chosen.times_s.tolist()), continuous.levels),
                            sigma_theta=sigma, settings=settings, t_off_s=q["t_off_s"])
    if "zeta" not in moved.params:
        return None
    start = np.asarray(sampled(continuous, period).step_times)
    moved.params = {**moved.params, **{k: v for k, v in q.items() if k not in moved.params},
                    "staircase_steps_moved": float(np.sum(np.abs(chosen.times_s - start)
                                                          > 0.5 * period))
                    if start.size == chosen.times_s.size else math.nan,
                    "staircase_t0_s": found.stair.t0_s + chosen.shift_s,
                    "staircase_te_s": chosen.te_s, "staircase_span_steps": chosen.span_steps}
    return moved


__all__ = ["FoundStaircaseInput", "FIND"]
