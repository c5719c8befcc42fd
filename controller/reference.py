"""Speed reference of the report (sec. 4.2.2): an inclined sine and its staircase.

The inclined sine (eq. 4.8) goes from omega0 to omega_end over [t0, t0 + te] with zero
acceleration at both ends:

    omega(t) = omega0 + (omega_end - omega0) p(s),  s = (t - t0)/te,  p(s) = s - sin(2 pi s)/(2 pi)

The setup only takes setpoints with a 1 Hz resolution, so the sine is approximated by steps of
``step`` rad/s. Step k (k = 1..n) happens when the sine reaches

* ``lead``    omega0 + (k - 1) step  (the report's choice: "the first step starts at t0"),
* ``nearest`` omega0 + (k - 1/2) step,
* ``trail``   omega0 + k step,

in the direction of omega_end. Step times are the exact roots of p(s) = target (p is
monotone), found by a safeguarded Newton iteration to the last ulp; they are never found by
sampling. Standard library only: this module runs inside the Staircase FMU.
"""
from __future__ import annotations

import bisect
import math
from dataclasses import dataclass, field
from typing import Iterable

ROUNDINGS = ("lead", "nearest", "trail")
#: Most setpoint steps a staircase may have (each step time is computed up front).
MAX_STEPS = 100_000

try:  # the shared error type; a vendored copy inside an FMU falls back to ValueError
    from abu_model.errors import ParameterError
except ImportError:  # pragma: no cover - only inside an FMU without abu_model
    class ParameterError(ValueError):  # type: ignore[no-redef]
        def __init__(self, parameter: str, value: object, expected: str):
            self.parameter, self.value, self.expected = parameter, value, expected
            super().__init__(f"invalid parameter '{parameter}' = {value!r}: expected {expected}")


def _finite(name: str, value: float) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, "a finite number") from None
    if not math.isfinite(number):
        raise ParameterError(name, value, "a finite number")
    return number


def sine_progress(s: float) -> float:
    ("""p(s) = s - sin(2 pi s)/(2 pi): the inclined sine's normalised progress, 0 at s=0, """
     """1 at s=1.""")
    return s - math.sin(2.0 * math.pi * s) / (2.0 * math.pi)


def _elementwise(f, t):
    """f(t) for a number, [f(x) for x in t] for a sequence or array (as a list)."""
    if isinstance(t, (int, float)):
        return f(float(t))
    try:
        return float(f(float(t)))  # 0-d arrays and numpy scalars
    except TypeError:
        return [f(float(x)) for x in t]


def inclined_sine(t: float | Iterable[float], omega0: float, omega_end: float, t0: float,
                  te: float) -> float | list[float]:
    """Eq. 4.8 [rad/s], held at omega0 before t0 and at omega_end after t0 + te."""
    def one(x: float) -> float:
        s = min(max((x - t0) / te, 0.0), 1.0)
        return omega0 + (omega_end - omega0) * sine_progress(s)
    return _elementwise(one, t)


def inclined_sine_rate(t: float | Iterable[float], omega0: float, omega_end: float, t0: float,
                       te: float) -> float | list[float]:
    ("""Time derivative of eq. 4.8 [rad/s^2]: (omega_end - omega0)/te (1 - cos(2 pi s)) """
     """inside [t0, t0+te].""")
    def one(x: float) -> float:
        s = (x - t0) / te
        if not 0.0 <= s <= 1.0:
            return 0.0
        return (omega_end - omega0) / te * (1.0 - math.cos(2.0 * math.pi * s))
    return _elementwise(one, t)


def _progress_root(target: float) -> float:
    """The s in [0, 1] with p(s) = target (exact root; p is strictly increasing).

    Newton steps on p (p' = 1 - cos(2 pi s) >= 0), kept inside a shrinking bracket and
    replaced by bisection where p' vanishes (s = 0, 1), until the bracket is one ulp wide.
    """
    if target <= 0.0:
        return 0.0
    if target >= 1.0:
        return 1.0
    lo, hi, s = 0.0, 1.0, target
    for _ in range(200):
        f = sine_progress(s) - target
        if f == 0.0:
            return s
        if f < 0.0:
            lo = s
        else:
            hi = s
        slope = 1.0 - math.cos(2.0 * math.pi * s)
        nxt = s - f / slope if slope > 0.0 else 0.5 * (lo + hi)
        if not lo < nxt < hi:
            nxt = 0.5 * (lo + hi)
        if nxt == s or hi - lo <= math.ulp(hi):
            break
        s = nxt
    return s if abs(sine_progress(s) - target) <= abs(sine_progress(lo) - target) else lo


@dataclass(frozen=True)
class Staircase:
    """Step-wise approximation of the inclined sine with setpoint resolution ``step``.

    Attributes:
        omega0: initial setpoint [rad/s] (held before the first step).
        omega_end: end of the inclined sine [rad/s].
        t0: start of the inclined sine [s].
        te: duration of the inclined sine [s] (> 0).
        step: setpoint resolution [rad/s] (> 0); 2 pi rad/s = 1 Hz, the setup's.
        rounding: ``lead`` (report), ``nearest`` or ``trail``.

    The staircase has n = floor(|omega_end - omega0| / step) steps and never passes
    omega_end; n = 0 is an error (a staircase with no step).
    """

    omega0: float
    omega_end: float
    t0: float = 0.0
    te: float = 1.0
    step: float = 2.0 * math.pi
    rounding: str = "lead"
    step_times: tuple[float, ...] = field(init=False)
    levels: tuple[float, ...] = field(init=False)

    def __post_init__(self) -> None:
        omega0 = _finite("omega0", self.omega0)
        omega_end = _finite("omega_end", self.omega_end)
        t0 = _finite("t0", self.t0)
        te = _finite("te", self.te)
        if te <= 0.0:
            raise ParameterError("te", self.te, "a duration > 0 s")
        step = _finite("step", self.step)
        if step <= 0.0:
            raise ParameterError("step", self.step, "a setpoint step > 0 rad/s")
        if self.rounding not in ROUNDINGS:
            raise ParameterError("rounding", self.rounding, f"one of {', '.join(ROUNDINGS)}")
        span = abs(omega_end - omega0)
        # A tiny tolerance so that 5 Hz / 1 Hz counts as 5 steps despite rounding of 2 pi.
        ratio = span / step + 1e-9
        n = int(math.floor(ratio)) if ratio <= MAX_STEPS + 1 else MAX_STEPS + 1
        if n < 1:
            raise ParameterError(
                "omega_end", self.omega_end,
                f"a value at least one step ({step:g} rad/s) away from omega0 = {omega0:g} rad/s "
                "(the staircase has no step)")
        if n > MAX_STEPS:
            raise ParameterError(
                "step", self.step, f"a setpoint step giving at most {MAX_STEPS} steps from "
                f"omega0 = {omega0:g} to omega_end = {omega_end:g} rad/s")
        direction = math.copysign(1.0, omega_end - omega0)
        offset = {"lead": 1.0, "nearest": 0.5, "trail": 0.0}[self.rounding]
        times = tuple(t0 + te * _progress_root((k - offset) * step / span) for k in range(1, n + 1))
        levels = tuple(omega0 + direction * k * step for k in range(0, n + 1))
        for name, value in (("omega0", omega0), ("omega_end", omega_end), ("t0", t0),
                            ("te", te), ("step", step)):
            object.__setattr__(self, name, value)
        object.__setattr__(self, "step_times", times)
        object.__setattr__(self, "levels", levels)

    @property
    def n_steps(self) -> int:
        """Number of setpoint steps."""
        return len(self.step_times)

    def index(self, t: float) -> int:
        """Number of steps that have happened at time t (right-continuous)."""
        return bisect.bisect_right(self.step_times, t)

    def value(self, t: float) -> float:
        """Setpoint at time t [rad/s]; at a step time the new level (right-continuous)."""
        return self.levels[self.index(t)]

    def values(self, t: Iterable[float]) -> list[float]:
        """:meth:`value` at each of the times ``t`` [rad/s], as a list."""
        return [self.levels[bisect.bisect_right(self.step_times, float(x))] for x in t]

    def next_event_time(self, t: float) -> float:
        """First step time strictly after t [s], or +inf when none is left."""
        i = bisect.bisect_right(self.step_times, t)
        return self.step_times[i] if i < len(self.step_times) else math.inf
