"""Recorded rows of an experiment -> the result object, the switch list and the friction
bounds (DESIGN.md sec. 3), shared by the staircase and the ramp (:mod:`harness.experiments.staircase`)."""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from harness.cosim.recording import CoSimResult

#: Units of the table columns ("1": dimensionless).
UNITS: dict[str, str] = {
    "time": "s", "side": "1", "omega_ref": "rad/s", "torque": "N m", "torque_applied": "N m",
    "theta": "rad", "omega": "rad/s", "alpha": "rad/s^2", "beta": "rad", "beta_dot": "rad/s",
    "normal_force": "N", "friction_force": "N", "mu_req": "1", "mode": "1",
    "mu_req_peak": "1",
}
#: Units of the summary's numbers.
SUMMARY_UNITS: dict[str, str] = {
    "mu": "1", "mu_low": "1", "mu_high": "1", "mu_estimate": "1", "t_slip": "s",
    "omega_slip": "rad/s", "alpha_slip": "rad/s^2", "t_restick": "s", "time_s": "s",
}

#: Relative tolerance of the bracket check (rounding of mu_req at a continuous slip).
BRACKET_RTOL = 1e-9


@dataclass
class ExperimentResult:
    """A co-simulated experiment.

    Attributes:
        table: column -> values, one row per communication point (a discontinuity gives a
            left row, side -1, and a right row, side +1); units in :data:`UNITS`.
        summary: bounds, slip point, switches (JSON-ready; units in ``summary["units"]``).
        cosim: the master's raw result (statistics, notes).
    """

    table: dict[str, np.ndarray]
    summary: dict[str, Any]
    cosim: CoSimResult | None = None
    units: dict[str, str] = field(default_factory=lambda: dict(UNITS))


def _table(res: CoSimResult, extra: Mapping[str, np.ndarray] = {}) -> dict[str, np.ndarray]:
    table = {"time": res.time.astype(float), "side": res.side.astype(int)}
    for name, values in res.values.items():
        table[name] = np.asarray(values, dtype=int if name == "mode" else float)
    table.update(extra)
    order = [k for k in UNITS if k in table] + [k for k in table if k not in UNITS]
    return {k: table[k] for k in order}


def _switches(res: CoSimResult, table: Mapping[str, np.ndarray]) -> list[dict[str, Any]]:
    """Switch list {time_s, from_mode, to_mode}; unknown modes are read from the table."""
    out = []
    t, mode = table["time"], table["mode"]
    for sw in res.switches:
        before, after = sw.before, sw.after
        if before is None:
            earlier = np.flatnonzero(t < sw.time - 1e-12)
            before = int(mode[earlier[-1]]) if earlier.size else None
        if after is None:
            later = np.flatnonzero(t > sw.time + 1e-12)
            after = int(mode[later[0]]) if later.size else None
        out.append({"time_s": float(sw.time), "from_mode": None if before is None else int(before),
                    "to_mode": None if after is None else int(after),
                    "located": bool(sw.located)})
    return out


def friction_bounds(table: Mapping[str, np.ndarray], switches: list[dict[str, Any]],
                    first_step: float | None = None) -> dict[str, Any]:
    """mu_low, mu_high and the slip instant of a recorded run (DESIGN.md sec. 3).

    mu_low is the largest mu_req before the first stick -> slip switch, including the left
    limit at the slip instant, and between communication points: a row's ``mu_req_peak`` (if
    recorded) is the largest mu_req in stick over the step that ended at it, so mu_low is the
    supremum over the stick period, not a maximum over sample points; mu_high is mu_req at
    the right limit there (the last row at that time). If alpha is continuous at the slip,
    both equal mu. Without a slip, mu_high and t_slip are None and mu_low is the largest
    mu_req of the whole (stuck) run.
    A slip at or before ``first_step`` [s] (the first setpoint step) leaves no stick period
    with an acceleration: mu_low is None (there is no lower bound).
    """
    t, side, mu_req = table["time"], table["side"], table["mu_req"]
    if "mu_req_peak" in table:
        mu_req = np.maximum(mu_req, table["mu_req_peak"])
    first = next((s for s in switches if s["from_mode"] == 0 and s["to_mode"] != 0), None)
    if first is None:
        stuck = table["mode"] == 0
        return {"mu_low": float(np.max(mu_req[stuck])) if stuck.any() else 0.0,
                "mu_high": None, "t_slip": None, "omega_slip": None, "alpha_slip": None}
    t_slip = first["time_s"]
    mu_at = table["mu_req"]  # the limits themselves (mu_high is a right-hand limit)
    at = np.flatnonzero(np.abs(t - t_slip) <= 1e-9)
    if at.size == 0:  # not on a communication point: take the nearest
        at = np.array([int(np.argmin(np.abs(t - t_slip)))])
    right = int(at[-1])
    before = (t < t[right] - 1e-9) | ((np.abs(t - t[right]) <= 1e-9) & (side == -1))
    mu_low = float(np.max(mu_req[before])) if before.any() else 0.0
    if first_step is not None and t_slip <= first_step + 1e-9:
        mu_low = None
    return {"mu_low": mu_low, "mu_high": float(mu_at[right]), "t_slip": float(t_slip),
            "omega_slip": float(table["omega"][right]), "alpha_slip": float(table["alpha"][right])}


def _finish_summary(summary: dict[str, Any], res: CoSimResult) -> dict[str, Any]:
    summary["cosim"] = {"communication_points": int(res.time.size), **res.stats,
                        "notes": list(res.notes)}
    summary["units"] = {k: v for k, v in SUMMARY_UNITS.items()}
    return summary
