"""Inputs of ``abu identify``: speed/angle records, pulse records and setpoint sequences (CSV).

* record CSV: ``time_s`` (or ``time``) and ``omega_rad_s`` (or ``omega``) or ``theta_rad`` (or
  ``theta``); a ``tracks.csv`` of ``abu track`` / ``abu measure`` works. Lines starting with
  ``#`` are comments; other columns are ignored.
* pulse CSV: ``time_s`` (or ``time``), one row per pulse of the optical sensor.
* setpoint CSV: ``time_s,omega_ref_rad_s``; each row: from this time on, this setpoint. The
  first row's level is taken as the steady state before it.

Errors name the file, the line and the column (:class:`RecordFileError`, an AbuError).
"""
from __future__ import annotations

import csv
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abu_model import validate
from abu_model.errors import AbuError

from harness.planning.loop_response import Setpoints

TIME_NAMES = ("time_s", "time")
OMEGA_NAMES = ("omega_rad_s", "omega")
THETA_NAMES = ("theta_rad", "theta")


class RecordFileError(AbuError):
    """An input CSV of ``abu identify`` is unreadable or malformed."""


@dataclass(frozen=True)
class Record:
    """A measured response (SI).

    Attributes:
        t: sample times [s], strictly increasing.
        y: the samples: omega [rad/s], theta [rad], or for pulses the pulse count [-].
        kind: ``omega``, ``theta`` or ``pulses``.
        pulses_per_rev: pulses per revolution (``pulses`` only).
        source: file name.
    """

    t: np.ndarray
    y: np.ndarray
    kind: str
    pulses_per_rev: int = 0
    source: str = ""

    def angle(self, direction: float) -> np.ndarray:
        """Angle [rad] of the samples (pulses: +-2 pi k / N in ``direction``; theta: itself)."""
        if self.kind == "pulses":
            return direction * 2.0 * math.pi * self.y / self.pulses_per_rev
        return self.y


def _read(path: str | Path, option: str) -> tuple[list[str], list[list[str]], list[int]]:
    p = Path(path)
    try:
        with p.open(newline="", encoding="utf-8") as fh:
            lines = [(i + 1, row) for i, row in enumerate(csv.reader(fh))]
    except OSError as exc:
        raise RecordFileError(f"{option} {p}: cannot be read ({exc.strerror or exc})") from None
    except (UnicodeDecodeError, csv.Error) as exc:
        raise RecordFileError(f"{option} {p}: not a CSV text file ({exc})") from None
    lines = [(n, r) for n, r in lines if r and not r[0].lstrip().startswith("#")
             and any(c.strip() for c in r)]
    if not lines:
        raise RecordFileError(f"{option} {p}: empty (expected a header line and data rows)")
    header = [c.strip() for c in lines[0][1]]
    validate.unique_names(header, f"{option} {p}: line {lines[0][0]}", error=RecordFileError)
    for names in (TIME_NAMES, OMEGA_NAMES, THETA_NAMES):
        if sum(n in header for n in names) > 1:
            raise RecordFileError(f"{option} {p}: line {lines[0][0]}: columns "
                                  f"{' and '.join(repr(n) for n in names)} both present; expected "
                                  "one (which one is meant?)")
    return header, [r for _, r in lines[1:]], [n for n, _ in lines[1:]]


def _column(path, option, header, rows, numbers, names: tuple[str, ...]) -> np.ndarray | None:
    name = next((n for n in names if n in header), None)
    if name is None:
        return None
    j = header.index(name)
    out = np.empty(len(rows))
    for i, (row, line) in enumerate(zip(rows, numbers)):
        out[i] = validate.cell(row[j] if j < len(row) else "", f"{option} {path}: line {line}, "
                               f"column '{name}'", error=RecordFileError)
    return out


def _times(path, option, header, rows, numbers, min_rows: int) -> np.ndarray:
    t = _column(path, option, header, rows, numbers, TIME_NAMES)
    if t is None:
        raise RecordFileError(f"{option} {path}: no column {' or '.join(TIME_NAMES)} "
                              f"(header: {','.join(header)})")
    if len(t) < min_rows:
        raise RecordFileError(f"{option} {path}: {len(t)} data rows, expected at least {min_rows}")
    bad = np.flatnonzero(np.diff(t) <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        column = header[[h in TIME_NAMES for h in header].index(True)]
        raise validate.order_error(f"{option} {path}", f"line {numbers[k]}, column '{column}'",
                                   t[k - 1], t[k], error=RecordFileError)
    return t


def read_record(path: str | Path, option: str = "--record") -> Record:
    """An omega(t) or theta(t) record (omega preferred when both are present)."""
    header, rows, numbers = _read(path, option)
    t = _times(path, option, header, rows, numbers, 10)
    for kind, names in (("omega", OMEGA_NAMES), ("theta", THETA_NAMES)):
        y = _column(path, option, header, rows, numbers, names)
        if y is not None:
            return Record(t, y, kind, source=str(path))
    raise RecordFileError(f"{option} {path}: no column {' or '.join(OMEGA_NAMES + THETA_NAMES)} "
                          f"(header: {','.join(header)})")


def read_pulses(path: str | Path, pulses_per_rev: int, option: str = "--pulses") -> Record:
    """Pulse times of the optical sensor; the pulse count is the record's y."""
    if isinstance(pulses_per_rev, bool) or not isinstance(pulses_per_rev, int) \
            or pulses_per_rev < 1:
        raise RecordFileError(f"--pulses-per-rev: expected an integer >= 1, got {pulses_per_rev!r}")
    header, rows, numbers = _read(path, option)
    t = _times(path, option, header, rows, numbers, 10)
    return Record(t, np.arange(len(t), dtype=float), "pulses", pulses_per_rev, str(path))


def read_setpoints(path: str | Path, option: str = "--setpoints") -> Setpoints:
    """A setpoint sequence: rows (time_s, omega_ref_rad_s), each from its time on."""
    header, rows, numbers = _read(path, option)
    t = _times(path, option, header, rows, numbers, 1)
    v = _column(path, option, header, rows, numbers, ("omega_ref_rad_s",))
    if v is None:
        raise RecordFileError(f"{option} {path}: no column omega_ref_rad_s "
                              f"(header: {','.join(header)})")
    if len(v) < 2:
        raise RecordFileError(f"{option} {path}: one row gives no step; expected at least two")
    return Setpoints(tuple(t[1:]), tuple(v))


def omega_from_pulses(record: Record, direction: float) -> tuple[np.ndarray, np.ndarray]:
    """Mid-interval times [s] and speeds [rad/s] from successive pulses (the report's way)."""
    dt = np.diff(record.t)
    return record.t[:-1] + dt / 2, direction * 2.0 * math.pi / record.pulses_per_rev / dt
