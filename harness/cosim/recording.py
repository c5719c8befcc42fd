"""Recording of the co-simulation: rows at communication points, left and right limits,
switches, and the result object.

An ordinary point gives one row (``side`` 0). A time event or a switch gives two rows at
the same time: the left limit (``side`` -1) and the right limit (``side`` +1).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass
class SwitchEvent:
    """A switch reported by a component (``switch_count`` grew).

    Attributes:
        time: the component's ``t_last_switch`` (or ``t_first_step_switch``) [s].
        component: instance name.
        count: ``switch_count`` after the switch.
        before: value of the component's ``mode`` output before the step (None if unknown).
        after: value of the ``mode`` output after the step (None if unknown).
        located: True if a communication point lies on the switch (within the tolerance).
    """

    time: float
    component: str
    count: int
    before: float | None
    after: float | None
    located: bool


@dataclass
class CoSimResult:
    """Rows recorded at every communication point.

    Attributes:
        time: communication points [s] (a discontinuity appears twice).
        side: -1 left limit, +1 right limit at a discontinuity, 0 ordinary point.
        values: probe column -> values (units of the FMU variable).
        switches: switches in time order.
        time_events: times of the time events taken [s].
        notes: remarks (switches accepted at the nearest point, an event at the stop time...).
        stats: counters: ``steps`` (accepted), ``rollbacks`` (for switches and rejected
            steps), ``rejected`` (steps whose coupling error exceeded the tolerance),
            ``do_steps`` (rounds of fmi2DoStep), ``fmi_calls``; and ``max_error`` (largest
            accepted error estimate / tol, 0 in fixed-step mode).
    """

    time: np.ndarray
    side: np.ndarray
    values: dict[str, np.ndarray]
    switches: list[SwitchEvent] = field(default_factory=list)
    time_events: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    stats: dict[str, Any] = field(default_factory=dict)


class Recorder:
    """Collects the rows of one run (probe values in the plan's column order)."""

    def __init__(self, columns: list[tuple[str, str]]):
        self.columns = columns
        self.times: list[float] = []
        self.sides: list[int] = []
        self.rows: list[list] = []
        self.switches: list[SwitchEvent] = []
        self.time_events: list[float] = []
        self.notes: list[str] = []

    def record(self, t: float, side: int, values: dict[str, Any]) -> None:
        """One row at ``t`` [s] from the point's values (node -> value)."""
        self.times.append(t)
        self.sides.append(side)
        self.rows.append([values[node] for _, node in self.columns])

    def result(self, stats: dict[str, Any]) -> CoSimResult:
        rows = self.rows
        values = {col: np.array([row[i] for row in rows])
                  for i, (col, _) in enumerate(self.columns)}
        return CoSimResult(time=np.array(self.times), side=np.array(self.sides, dtype=np.int8),
                           values=values, switches=self.switches,
                           time_events=self.time_events, notes=self.notes, stats=stats)
