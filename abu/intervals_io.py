"""The intervals ``abu next`` combines, read from the files earlier runs wrote: ``abu measure``
summaries, ``abu simulate`` summaries and CSV files with columns mu_low,mu_high.

It reads both halves' formats, so it sits above ``harness`` and ``measurement``.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

from abu_model import validate

from harness.experiments.simulate_output import SIMULATE_KIND
from harness.planning.next_run import IntervalsError


def read_intervals(paths: Sequence[str | Path]) -> list[dict[str, Any]]:
    """Every interval of ``paths``: summary.json files (:func:`read_interval`) and CSV files
    with columns mu_low,mu_high (one interval per row, as ``abu measure-summary`` reads)."""
    out: list[dict[str, Any]] = []
    for path in paths:
        if Path(path).suffix.lower() == ".csv":
            from measurement.report.multi import read_intervals as read_csv
            for row in read_csv([path]):
                out.append(_checked(row["name"], row["mu_low"], row["mu_high"], None))
        else:
            out.append(read_interval(path))
    return out


def _checked(name: str, lo: Any, hi: Any, drive: dict | None) -> dict[str, Any]:
    for key, value in (("mu_low", lo), ("mu_high", hi)):
        if value is None or (validate.is_number(value) and math.isinf(value)):
            raise IntervalsError(f"{name}: '{key}' is {value!r}; 'abu next' needs both bounds "
                                 "(a run whose ball slipped inside the record)")
        validate.number(value, f"{name}, field '{key}'", lo=0.0, error=IntervalsError,
                        why="a friction coefficient")
    if not lo < hi:
        raise IntervalsError(f"{name}: mu_low = {lo!r} is not below mu_high = {hi!r}")
    return {"name": name, "mu_low": float(lo), "mu_high": float(hi), "drive": drive}


def read_interval(path: str | Path) -> dict[str, Any]:
    """{"name", "mu_low", "mu_high", "drive"} from an ``abu measure`` or ``abu simulate``
    summary.json (``drive``: the drive.json object a measurement recorded, or None)."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise IntervalsError(f"{p}: not a readable JSON summary ({exc})") from None
    data = validate.json_object(text, str(p), "a JSON object (a summary.json)",
                                error=IntervalsError)
    simulated = data.get("kind") == SIMULATE_KIND or (data.get("kind") is None
                                                      and "experiment" in data)
    if simulated:
        lo, hi = data.get("mu_low"), data.get("mu_high")
    else:
        from measurement.report.multi import read_intervals
        row = read_intervals([p])[0]
        lo, hi = row["mu_low"], row["mu_high"]
    drive = data.get("drive") if isinstance(data.get("drive"), dict) else None
    return _checked(str(p), lo, hi, drive)
