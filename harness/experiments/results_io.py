"""Experiment results on disk: a CSV with units in its column names and a JSON summary.

CSV: one row per communication point (a discontinuity has a left row, side -1, and a right
row, side +1, at the same time); column names carry their unit (``time_s``, ``omega_rad_s``,
``alpha_rad_s2``, ``torque_N_m``); dimensionless columns (``side``, ``mu_req``, ``mode``)
have none. Numbers are written with 17 significant digits so that they read back exactly.
Everything is written atomically.
"""
from __future__ import annotations

import csv
import io
import json
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError
from abu_model.json_text import to_jsonable  # noqa: F401  (re-exported)

#: Unit -> column-name suffix.
UNIT_SUFFIX = {"s": "s", "rad": "rad", "rad/s": "rad_s", "rad/s^2": "rad_s2", "N m": "N_m",
               "N": "N", "N m/s": "N_m_s", "kg": "kg", "m": "m", "1": ""}


def column_name(name: str, unit: str) -> str:
    """``name`` with its unit suffix (``omega`` + ``rad/s`` -> ``omega_rad_s``)."""
    suffix = UNIT_SUFFIX.get(unit)
    if suffix is None:
        raise AbuError(f"column '{name}': no CSV suffix for unit '{unit}'")
    return f"{name}_{suffix}" if suffix else name


def table_to_csv(table: Mapping[str, np.ndarray], units: Mapping[str, str]) -> str:
    """The table as CSV text (header with units)."""
    names = list(table)
    header = [column_name(n, units.get(n, "1")) for n in names]
    columns = [np.asarray(table[n]) for n in names]
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(header)
    for i in range(len(columns[0]) if columns else 0):
        writer.writerow([_fmt(col[i]) for col in columns])
    return out.getvalue()


def write_table_csv(path: str | Path, table: Mapping[str, np.ndarray],
                    units: Mapping[str, str]) -> Path:
    """Write the table to ``path`` atomically; returns the path."""
    atomic_write_text(path, table_to_csv(table, units))
    return Path(path)


def read_table_csv(path: str | Path, units: Mapping[str, str]) -> dict[str, np.ndarray]:
    """Read a table written by :func:`write_table_csv` back (names without unit suffix).

    Raises:
        AbuError: naming the file and column if a column is unknown or a value is not a number.
    """
    path = Path(path)
    by_header = {column_name(n, u): n for n, u in units.items()}
    with open(path, newline="", encoding="utf-8") as handle:
        rows = list(csv.reader(handle))
    if not rows:
        raise AbuError(f"{path}: empty file, expected a header row")
    header = rows[0]
    unknown = [h for h in header if h not in by_header]
    if unknown:
        raise AbuError(f"{path}: unknown column '{unknown[0]}' (expected one of "
                       f"{', '.join(by_header)})")
    table: dict[str, list[float]] = {by_header[h]: [] for h in header}
    for line, row in enumerate(rows[1:], start=2):
        if len(row) != len(header):
            raise AbuError(f"{path}, row {line}: {len(row)} values, expected {len(header)}")
        for h, value in zip(header, row):
            try:
                table[by_header[h]].append(float(value))
            except ValueError:
                raise AbuError(f"{path}, row {line}, column '{h}': '{value}' is not a number") \
                    from None
    return {n: np.asarray(v, dtype=int if n in ("side", "mode") else float)
            for n, v in table.items()}


def write_json(path: str | Path, data: Any) -> Path:
    """Write ``data`` as indented JSON atomically; returns the path."""
    atomic_write_text(path, json.dumps(to_jsonable(data), indent=2, allow_nan=False) + "\n")
    return Path(path)


def _fmt(value: Any) -> str:
    if isinstance(value, (np.integer, int)) and not isinstance(value, bool):
        return str(int(value))
    number = float(value)
    if math.isnan(number):
        return "nan"
    if math.isinf(number):
        return "inf" if number > 0 else "-inf"
    if number.is_integer() and abs(number) < 1e15:
        return repr(number)
    return f"{number:.17g}"
