"""Where a staircase of the report's kind lies in a record: the smooth guess and the timing
grid that start :mod:`measurement.kinematics.staircase_search` (SI).

The report's staircase (sec. 4.2, :class:`controller.reference.Staircase`) is an inclined
sine from omega0 over a span of s setpoint steps in te, rounded to n = floor(s) steps; step k
happens where the sine's progress p(x) = x - sin(2 pi x) / (2 pi) reaches (k - offset) / s,
offset 1 (lead, the report's), 0.5 (nearest) or 0 (trail). So its timing is four numbers (t0,
te, s, offset) beside the step size, and the whole staircase is :class:`SineStaircase`.

* :func:`sine_guess`: omega (a short Savitzky-Golay derivative, every third sample) fitted by an inclined sine,
  ``omega0 + S p((t - t0) / te)``, over a grid of t0 and te (omega0 and S linear). The loop
  lags the setpoint and the staircase's rounding puts it ahead or behind the sine, so on the
  benchmark family t0 comes out 0.04-0.1 s late and te 10-35 % short or long: a guess.
* :func:`timing_grid`: each rounding and step count near the guess scored over a grid of
  start times and durations around it, with two generic PI loops, by the residual of the
  staircase's angle (a sum of the loop's unit-step responses, shifted to the steps; the
  nuisance terms of the drive model projected out). Cheap (one response per loop, then
  interpolation), and it finds the basin a least-squares fit from the guess does not: started
  from the guess alone (with timing-only fits from two offsets), seeds 5 and 20 of the family
  stopped in a local minimum (residual 9x and 2.2x the noise); from the grid's best cells both
  were found (te within 0.1 %).
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, replace

import numpy as np

from abu_model.loop_response import Setpoints, response
from controller.drive import Drive

from measurement.kinematics.estimators import sample_interval, stable_savgol_filter
from measurement.kinematics.model_fit import linear_basis

TWO_PI = 2.0 * math.pi
#: The roundings of :class:`controller.reference.Staircase` as their offsets.
ROUNDING_OFFSETS = {"lead": 1.0, "nearest": 0.5, "trail": 0.0}
#: The guess: Savitzky-Golay window of omega [s], grids of start times [s] and durations [s].
GUESS_WINDOW_S = 0.021
GUESS_T0_STEP_S = 0.004
GUESS_TE_S = tuple(np.exp(np.linspace(math.log(0.05), math.log(3.0), 60)).tolist())
GUESS_EVERY = 3
GUESS_BLOCK = 1_000_000
#: The timing grid: durations relative to the guess's (~2 % apart: late steps move by a
#: fraction of the gap between steps), start times [s] relative to the guess's, and two
#: generic loops (a slow and a fast PI with torque lag, setpoint weight and filter).
GRID_TE = tuple(np.exp(np.linspace(math.log(0.65), math.log(1.6), 46)).tolist())
GRID_T0_S = tuple(np.arange(-0.14, 0.04, 0.004).tolist())
GRID_LOOPS = (dict(zeta=0.8, omega_n=12.0, tau_motor=0.01, setpoint_weight=0.8,
                   setpoint_tau=0.005),
              dict(zeta=0.8, omega_n=30.0, tau_motor=0.01, setpoint_weight=0.8,
                   setpoint_tau=0.005))


def progress(x: np.ndarray) -> np.ndarray:
    """The inclined sine's progress p(x) = x - sin(2 pi x) / (2 pi), vectorised: the search
    evaluates it on whole grids. :func:`controller.reference.sine_progress` is the scalar
    form; that module stays standard-library only (it runs inside the Staircase FMU), so
    the NumPy form lives here (the two are compared in tests/test_staircase_search.py)."""
    x = np.asarray(x, float)
    return x - np.sin(TWO_PI * x) / TWO_PI


#: progress_root's starting table (the fits ask for the step times at every evaluation)
_X_TABLE = np.linspace(0.0, 1.0, 4001)
_PROGRESS_TABLE = progress(_X_TABLE)


#: progress_root takes arrays up to this size element by element in Python floats: the fits
#: ask for a staircase's 4-16 step times at every evaluation, where NumPy's per-call cost
#: was 8 % of the search's CPU (cProfile, bench_staircase_search.py seeds 0-7)
_SMALL = 64
_X_LIST, _PROGRESS_LIST = _X_TABLE.tolist(), _PROGRESS_TABLE.tolist()


def progress_root(y: np.ndarray) -> np.ndarray:
    """The x in [0, 1] with p(x) = y, vectorised (a table, then six Newton steps: to the last
    digits where p' > 0; p is cubic at 0 and 1, where the steps converge linearly)."""
    y = np.clip(np.asarray(y, float), 0.0, 1.0)
    if y.size <= _SMALL:
        return np.array([_root_one(v) for v in y.ravel().tolist()]).reshape(y.shape)
    x = np.interp(y, _PROGRESS_TABLE, _X_TABLE)
    for _ in range(6):
        slope = 1.0 - np.cos(TWO_PI * x)
        step = (progress(x) - y) / np.maximum(slope, 1e-12)
        x = np.clip(np.where(slope > 1e-12, x - step, x), 0.0, 1.0)
    return x


def _root_one(y: float) -> float:
    """progress_root of one y in [0, 1]: the same table and steps in Python floats."""
    j = min(bisect.bisect_right(_PROGRESS_LIST, y) - 1, len(_PROGRESS_LIST) - 2)
    p0, p1 = _PROGRESS_LIST[j], _PROGRESS_LIST[j + 1]
    x = _X_LIST[j] + (_X_LIST[j + 1] - _X_LIST[j]) * (y - p0) / (p1 - p0)
    for _ in range(6):
        slope = 1.0 - math.cos(TWO_PI * x)
        if slope > 1e-12:
            step = (x - math.sin(TWO_PI * x) / TWO_PI - y) / slope
            if step == 0.0:   # converged: the remaining steps would not move x
                break
            x = min(max(x - step, 0.0), 1.0)
    return x


@dataclass(frozen=True)
class SineGuess:
    """The smooth guess: omega ~ omega0 + span p((t - t0) / te) [s, s, rad/s, rad/s]."""

    t0_s: float
    te_s: float
    span_rad_s: float
    omega0_rad_s: float


@dataclass(frozen=True)
class SineStaircase:
    """The report's staircase (SI): start t0 [s], the rounding's offset, n steps of
    ``direction * step_rad_s`` from omega0 [rad/s]; its duration te [s] and span s [steps]
    are the arguments of :meth:`setpoints` (fitted)."""

    t0_s: float
    offset: float
    n: int
    omega0_rad_s: float
    direction: float
    step_rad_s: float

    @property
    def rounding(self) -> str:
        return next(k for k, v in ROUNDING_OFFSETS.items() if v == self.offset)

    def step_fractions(self, span_steps: float) -> np.ndarray:
        """Each step's place on the sine, x_k in [0, 1] (step k at t0 + te x_k)."""
        return progress_root((np.arange(1, self.n + 1) - self.offset) / span_steps)

    def setpoints(self, te_s: float, span_steps: float) -> Setpoints:
        times = self.t0_s + te_s * self.step_fractions(span_steps)
        levels = self.omega0_rad_s + self.direction * self.step_rad_s * np.arange(self.n + 1)
        return Setpoints(tuple(times.tolist()), tuple(levels.tolist()))


def sine_guess(time: np.ndarray, theta: np.ndarray) -> SineGuess:
    """The inclined sine that best fits omega (module doc)."""
    dt = sample_interval(time)
    longest = theta.size if theta.size % 2 else theta.size - 1
    window = min(max(7, int(round(GUESS_WINDOW_S / dt)) | 1), longest)
    omega = stable_savgol_filter(theta, window, 3, 1, dt)
    # a smooth curve: every GUESS_EVERY-th sample of it is enough for the guess
    time, omega = time[::GUESS_EVERY], omega[::GUESS_EVERY]
    oc = omega - omega.mean()
    starts = np.arange(time[0] - 0.5, time[-1], GUESS_T0_STEP_S)
    best = (math.inf, SineGuess(float(time[0]), 1.0, 0.0, float(omega.mean())))
    # start times in blocks of GUESS_BLOCK values: the (start, sample) arrays of a long
    # record would take gigabytes at once (each row is scored on its own: the same result)
    rows = max(1, GUESS_BLOCK // time.size)
    for te in GUESS_TE_S:
        for lo in range(0, starts.size, rows):
            s0 = starts[lo:lo + rows]
            x = progress(np.clip((time[None, :] - s0[:, None]) / te, 0.0, 1.0))
            xm = x.mean(axis=1, keepdims=True)
            xc = x - xm
            sxx, sxy = (xc * xc).sum(axis=1), (xc * oc).sum(axis=1)
            span = np.where(sxx > 0, sxy / np.maximum(sxx, 1e-300), 0.0)
            sse = float(oc @ oc) - span * sxy
            i = int(np.argmin(sse))
            if sse[i] < best[0]:
                best = (float(sse[i]), SineGuess(float(s0[i]), float(te), float(span[i]),
                                                float(omega.mean() - span[i] * xm[i, 0])))
    return best[1]


def candidate_staircases(guess: SineGuess, step_rad_s: float) -> list[SineStaircase]:
    """Each rounding with each step count within a step of the guess's span / step (the
    guess's span is the visible rise, n steps; off by more than a step where the rounding
    and the loop's lag bend the speed's course: seed 502 of ``tests/test_unknown_loop.py``'s
    generator, 14.7 steps, found with 15 before the counts below and above were added)."""
    s_guess = abs(guess.span_rad_s) / step_rad_s
    counts = sorted({max(2, n) for n in range(math.floor(s_guess) - 1, math.ceil(s_guess) + 2)})
    direction = math.copysign(1.0, guess.span_rad_s)
    return [SineStaircase(guess.t0_s, offset, n, guess.omega0_rad_s, direction, step_rad_s)
            for offset in ROUNDING_OFFSETS.values() for n in counts]


def start_span(guess: SineGuess, stair: SineStaircase) -> float:
    """The span [steps] a fit of ``stair`` starts from: the guess's, within [n, n + 1)."""
    return min(max(abs(guess.span_rad_s) / stair.step_rad_s, stair.n + 1e-3),
               stair.n + 1.0 - 1e-3)


def _unit_step_theta(drive: Drive, length_s: float, dt: float
                     ) -> tuple[np.ndarray, np.ndarray]:
    """The loop's angle after a unit setpoint step at 0 [rad per rad/s] on a grid of times
    since the step [s]."""
    u = np.arange(0.0, length_s + dt, 0.5 * dt)
    r = response(Setpoints((0.0,), (0.0, 1.0)), u, drive.zeta, drive.omega_n,
                 drive.tau_motor, drive.setpoint_weight, True, setpoint_tau=drive.setpoint_tau)
    return u, r.theta


def _add_delayed(out: np.ndarray, h: np.ndarray, delay: float) -> None:
    """out += h delayed by ``delay`` >= 0 grid steps, linearly interpolated, 0 before it: the
    same as np.interp(u - delay du, u, h, left=0) on the grid u = k du, by slices (no search:
    the grid scores thousands of staircases)."""
    j = int(math.floor(delay))
    f = delay - j
    if f == 0.0 and j < h.size:   # the delay on a grid point: h[0] there, as np.interp
        out[j] += h[0]
    if j + 1 < h.size:
        out[j + 1:] += (1.0 - f) * h[1:h.size - j] + f * h[:h.size - j - 1]


def _on_grid(pos: np.ndarray, values: np.ndarray) -> np.ndarray:
    """np.interp(pos du, u, values, left=0) for positions ``pos`` in grid steps on the grid
    u = k du (index arithmetic, no search)."""
    j = np.floor(pos)
    f = pos - j
    last = values.size - 1
    k = np.clip(j, 0, last - 1).astype(np.intp)
    out = values[k] * (1.0 - f) + values[k + 1] * f
    return np.where(j < 0, 0.0, np.where(j >= last, values[-1], out))


@dataclass(frozen=True)
class GridCell:
    """The timing grid's best cell of one staircase: its residual sum of squares [rad^2],
    the staircase with its start, the duration [s] and the generic loop that scored it."""

    sse: float
    stair: SineStaircase
    te_s: float
    drive: Drive


def timing_grid(time: np.ndarray, theta: np.ndarray, guess: SineGuess,
                stairs: list[SineStaircase]) -> list[GridCell]:
    """Each staircase's best cell over the grid (module doc), best first."""
    basis = linear_basis(time, theta, 3)
    proj = np.linalg.pinv(basis)
    dt = sample_interval(time)
    t0s = guess.t0_s + np.asarray(GRID_T0_S)
    since = time[None, :] - t0s[:, None]                      # (start times, samples)
    cells = []
    for stair in stairs:
        best = GridCell(math.inf, stair, guess.te_s, Drive(model="pi-lag-weighted",
                                                           **GRID_LOOPS[0]))
        x = stair.step_fractions(start_span(guess, stair))
        for loop in GRID_LOOPS:
            drive = Drive(model="pi-lag-weighted", **loop)
            u, h = _unit_step_theta(drive, float(time[-1] - t0s[0]), dt)
            du = float(u[1] - u[0])
            for scale in GRID_TE:
                te = guess.te_s * scale
                # the staircase's angle depends on time - t0 only: summed over the steps
                # once on the unit response's own grid u, then read at every start time (one
                # interpolation, not one a step: 4x faster; the scores agree to ~1e-6 rad,
                # the grid's own interpolation error); both by index arithmetic on u
                stair_theta = np.zeros_like(u)
                for xk in x:     # the levels' steady part omega0 t is a nuisance term
                    _add_delayed(stair_theta, h, te * xk / du)
                model = _on_grid(since / du, stair_theta)
                e = theta[None, :] - stair.direction * stair.step_rad_s * model
                e -= (e @ proj.T) @ basis.T
                sse = np.einsum("ij,ij->i", e, e)
                i = int(np.argmin(sse))
                if sse[i] < best.sse:
                    best = GridCell(float(sse[i]), replace(stair, t0_s=float(t0s[i])), te,
                                    drive)
        cells.append(best)
    return sorted(cells, key=lambda c: c.sse)


__all__ = ["ROUNDING_OFFSETS", "SineGuess", "SineStaircase", "GridCell", "progress",
           "progress_root", "sine_guess", "candidate_staircases", "start_span", "timing_grid"]
