"""Step sizes: the coupling error estimate and its controller, and where switches lie.

**Error estimate.** Over a step every receiver sees each held signal y as the Taylor
polynomial of its producer's outputs at the step start, P(tau) = y + y' tau + y'' tau^2/2
(as many derivatives as the hold declares, see :class:`harness.cosim.system.Hold`). After the
step the producer outputs y(t + h) from its new state; the difference
e = |y(t + h) - P(h)| / scale is the defect the receivers integrated, of order h^(p+1) for a
hold of order p. This is a predictor-corrector estimate that costs no extra ``fmi2DoStep``
(PyFMI's step doubling costs two, an embedded lower-order hold needs the same readout).

**Controller.** A step with e > tol is rejected (every FMU is restored with
``fmi2SetFMUstate`` and the step is redone shorter); the next step is
h (0.9 tol / e)^(1/(p+1)) limited to [0.2 h, 4 h] and to ``h_max`` (the classic elementary
controller of ODE solvers, Hairer-Wanner vol. I sec. II.4).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from harness.cosim.recording import SwitchEvent
from harness.cosim.system import Hold

#: Default tolerance of the coupling error [-] (relative to each hold's scale). With the
#: staircase's fourth-order hold it gives every switch within 1e-9 s and the bounds within
#: 1e-6 relative of the monolithic reference on tests/test_cosim_accuracy.py's family (worst
#: 5e-10 s, 5e-10 rel.), 106 steps on the report's case (1e-8: 69 steps, but 2.6e-9 s).
DEFAULT_TOL = 1e-9
#: Default largest communication step in error-controlled mode [s].
DEFAULT_MAX_STEP = 0.05
#: Default first communication step in error-controlled mode [s].
DEFAULT_FIRST_STEP = 1e-3
SAFETY, GROW, SHRINK, SHRINK_REJECT = 0.9, 4.0, 0.2, 0.1


@dataclass
class ErrorControl:
    """Coupling error estimate and step-size proposals for the given holds."""

    tol: float
    holds: list[Hold]
    h_max: float = DEFAULT_MAX_STEP
    h_min: float = 1e-9
    scales: list[float] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.order = min((len(h.derivatives) for h in self.holds), default=0)
        self.scales = [h.scale or 0.0 for h in self.holds]
        self._exponent = 1.0 / (self.order + 1)

    def snapshot(self, values: dict[str, Any]) -> list[tuple[float, ...]]:
        """The Taylor coefficients y, y', y'', ... of every hold at a step start."""
        snap = []
        for i, hold in enumerate(self.holds):
            y = float(values[hold.signal])
            if hold.scale is None and abs(y) > self.scales[i]:
                self.scales[i] = abs(y)
            snap.append((y,) + tuple(float(values[d]) for d in hold.derivatives))
        return snap

    def error(self, start: list[tuple[float, ...]], values: dict[str, Any], h: float) -> float:
        """Largest |y(t+h) - P(h)| / (tol scale) over the holds (1 = at the tolerance)."""
        worst = 0.0
        for hold, coeffs, scale in zip(self.holds, start, self.scales):
            predicted, factor = 0.0, 1.0
            for k, c in enumerate(coeffs):
                predicted += c * factor
                factor *= h / (k + 1)
            actual = float(values[hold.signal])
            scale = max(scale, abs(actual)) if hold.scale is None else scale
            if scale > 0.0:
                worst = max(worst, abs(actual - predicted) / (self.tol * scale))
        return worst

    def next_step(self, h: float, err: float) -> float:
        """Proposal after an accepted step of size h [s] with normalised error ``err``."""
        factor = GROW if err <= 0.0 else min(GROW, max(SHRINK, SAFETY * err ** -self._exponent))
        return min(self.h_max, h * factor)

    def retry_step(self, h: float, err: float) -> float:
        """Shorter step after a rejection (err > 1)."""
        return max(self.h_min, h * min(0.9, max(SHRINK_REJECT, SAFETY * err ** -self._exponent)))


SwitchInfo = tuple[int, float, Any, Any]  # (switch_count, t_last_switch, mode, t_first)


def switch_info(switch_plan: list, values: dict[str, Any]) -> list[SwitchInfo]:
    """(count, t_last_switch, mode, t_first_step_switch) of each switching component."""
    info = []
    for _, count, last, mode, first in switch_plan:
        info.append((int(values[count]), float(values[last]),
                     None if mode is None else values[mode],
                     None if first is None else float(values[first])))
    return info


def inner_switches(t: float, h: float, before: list[SwitchInfo], after: list[SwitchInfo],
                   tol: float) -> tuple[list[float], bool]:
    """Switch times strictly inside (t, t + h) to land on, and whether some FMU had several
    switches in the step without saying where the first inner one is."""

    def inside(ts: float) -> bool:
        return t + tol < ts < t + h - tol

    inner: list[float] = []
    crowded = False
    for (c0, _, _, _), (c1, t_last, _, t_first) in zip(before, after):
        n = c1 - c0
        if n == 1:
            if inside(t_last):
                inner.append(t_last)
        elif n > 1:
            if t_first is None:
                crowded = True  # only the last switch is known
            elif inside(t_first):
                inner.append(t_first)
            elif abs(t_first - t) <= tol and n == 2:
                # One at the start (inputs that jumped at a time event), the other later:
                # landing on the later one would leave no point in between, so the mode
                # after the first switch would never be observed (a slip at a setpoint step
                # that ends within the step read as stick -> stick). Land in between first;
                # the next step then lands on the later switch as a single one.
                if t_last > t + tol:
                    inner.append(t + 0.5 * (t_last - t))
            elif t_first < t + h - tol:
                crowded = True  # the first at the start, more than one after it
    return inner, crowded


def switch_events(switch_plan: list, before: list[SwitchInfo], after: list[SwitchInfo],
                  t: float, t_new: float, tol: float, notes: list[str]) -> list[SwitchEvent]:
    """The switches of an accepted step [t, t_new] (at most the first and the last known)."""
    events = []
    for (name, *_), (c0, _, m0, _), (c1, t_last, m1, t_first) in zip(switch_plan, before, after):
        if c1 <= c0:
            continue
        # (time, count, mode before, mode after); intermediate modes are unknown.
        found = [(t_last, c1, m0 if c1 - c0 == 1 else None, m1)]
        if c1 - c0 >= 2 and t_first is not None:
            found.insert(0, (t_first, c0 + 1, m0, None))
        for t_sw, count, mode_before, mode_after in found:
            located = min(abs(t_sw - t_new), abs(t_sw - t)) <= tol
            if not located:
                notes.append(f"switch of '{name}' at t = {t_sw:.12g} s accepted at the "
                             f"nearest communication point {t_new:.12g} s")
            events.append(SwitchEvent(time=t_sw, component=name, count=count,
                                       before=mode_before, after=mode_after, located=located))
    return events


def next_events(event_plan: list, values: dict[str, Any], t: float,
                tol: float) -> tuple[float, frozenset[str]]:
    """Earliest ``next_event_time`` after t [s] and the components announcing it."""
    earliest, owners = math.inf, set()
    for name, node in event_plan:
        value = float(values[node])
        if math.isnan(value) or value <= t + tol:
            continue
        if value < earliest - tol:
            earliest, owners = value, {name}
        elif abs(value - earliest) <= tol:
            owners.add(name)
    return earliest, frozenset(owners)
