"""The journal of a sweep: every finished run, appended as it lands, so a killed sweep resumes.

A journal ``<out>.journal`` (beside the sweep's CSV) is a text file of JSON lines:

* line 1, the header: ``{"kind": "abu-sweep-journal", "format_version": 1,
  "settings_sha256": ..., "runs": N}``; the hash is over the normalised settings of every run
  (:func:`settings_hash`: each run's key and every field of its experiment, floats written
  exactly), so a journal is only ever continued by the sweep that wrote it;
* then one line per finished run: ``{"key": "...", "row": {...}}``, written and flushed
  (``os.fsync``) before the next is taken.

A run killed while writing leaves at most a torn last line: it is cut off when the journal is
reopened (that run is simply computed again). Rows are deduplicated by key (a run recomputed
after a worker died lands once). Floats go through JSON as their shortest exact repr, so the
CSV written from the journal is the one an uninterrupted sweep writes.
"""
from __future__ import annotations

import csv
import dataclasses
import hashlib
import io
import json
import os
from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError

KIND = "abu-sweep-journal"
FORMAT_VERSION = 1
#: CSV columns of a sweep, with units.
COLUMNS = ("mu", "omega0_hz", "mu_low", "mu_high", "t_slip_s", "slipped", "bracketed")


class JournalError(AbuError):
    """A journal that cannot be continued (another sweep's, or not a journal at all)."""


def journal_path(out: Path) -> Path:
    """The journal beside the CSV ``out``: ``<out>.journal``."""
    return out.with_name(out.name + ".journal")


def _normalised(value: Any) -> Any:
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return {"__type__": type(value).__name__,
                **{f.name: _normalised(getattr(value, f.name)) for f in dataclasses.fields(value)}}
    if isinstance(value, float):
        return repr(value)  # exact; also NaN/inf without JSON trouble
    if isinstance(value, (list, tuple)):
        return [_normalised(v) for v in value]
    if isinstance(value, Mapping):
        return {str(k): _normalised(v) for k, v in sorted(value.items())}
    return value


def settings_hash(tasks: Iterable[tuple[str, Any]]) -> str:
    """SHA-256 of the normalised settings of every run (key and experiment), in key order."""
    digest = hashlib.sha256(f"{KIND}/{FORMAT_VERSION}/{COLUMNS}".encode())
    for key, experiment in sorted(tasks, key=lambda kv: kv[0]):
        digest.update(json.dumps([key, _normalised(experiment)], sort_keys=True).encode())
        digest.update(b"\n")
    return digest.hexdigest()


def journal_settings(path: Path) -> str | None:
    """The settings hash in the header of the journal at ``path`` (None: no such journal)."""
    try:
        with open(path, "rb") as fh:
            header = json.loads(fh.readline())
    except (OSError, ValueError):
        return None
    if not (isinstance(header, dict) and header.get("kind") == KIND
            and header.get("format_version") == FORMAT_VERSION):
        return None
    found = header.get("settings_sha256")
    return found if isinstance(found, str) else None


class Journal:
    """An open journal: the rows already there (``rows``, by key) and :meth:`append`."""

    def __init__(self, path: Path, settings_sha256: str, runs: int, *, discard: bool = False):
        """Open (or create) the journal at ``path`` for the sweep of ``settings_sha256``.

        Raises:
            JournalError: the file is another sweep's journal (or not a journal) and
                ``discard`` is false; with ``discard`` it is started afresh.
        """
        self.path = path
        self.rows: dict[str, dict] = {}
        self.discarded = False
        header = {"kind": KIND, "format_version": FORMAT_VERSION,
                  "settings_sha256": settings_sha256, "runs": runs}
        good_bytes = 0
        if path.exists():
            good_bytes, found = self._read(path)
            if found != settings_sha256:
                if not discard:
                    why = ("is not a sweep journal" if found is None else
                           "was written by a sweep with different settings (grid or options)")
                    raise JournalError(f"--out: the journal '{path}' {why}; rerun the command "
                                       "that wrote it to resume, or pass --overwrite (or delete "
                                       "it) to start this sweep afresh")
                self.rows.clear()
                good_bytes = 0
                self.discarded = True
        self._file = open(path, "r+b" if good_bytes else "wb")
        if good_bytes:
            self._file.truncate(good_bytes)  # a torn last line of a killed run
            self._file.seek(good_bytes)
        else:
            self._file.write((json.dumps(header) + "\n").encode())
            self._sync()

    def _read(self, path: Path) -> tuple[int, str | None]:
        """Rows of an existing journal; (bytes of whole lines, its settings hash or None)."""
        data = path.read_bytes()
        lines = data.split(b"\n")
        try:
            header = json.loads(lines[0])
            if not (isinstance(header, dict) and header.get("kind") == KIND
                    and header.get("format_version") == FORMAT_VERSION):
                return 0, None
        except ValueError:
            return 0, None
        good = len(lines[0]) + 1
        for line in lines[1:-1]:  # the last piece has no newline: torn (or empty)
            try:
                entry = json.loads(line)
                key, row = entry["key"], entry["row"]
                if not isinstance(key, str) or not isinstance(row, dict):
                    raise ValueError
            except (ValueError, KeyError, TypeError):
                break  # a damaged line: keep what came before, recompute the rest
            self.rows.setdefault(key, row)
            good += len(line) + 1
        return good, header.get("settings_sha256")

    def append(self, key: str, row: Mapping[str, Any]) -> bool:
        """Write one finished run (flushed to disk); False if its key is already there."""
        if key in self.rows:
            return False
        self._file.write((json.dumps({"key": key, "row": dict(row)})
                          + "\n").encode())
        self._sync()
        self.rows[key] = dict(row)
        return True

    def _sync(self) -> None:
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()

    def remove(self) -> None:
        self.close()
        self.path.unlink(missing_ok=True)


def write_sweep_csv(path: Path, rows: Sequence[Mapping[str, Any]]) -> None:
    """Write the sweep rows as CSV (atomically)."""
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if row[k] is None else row[k]) for k in COLUMNS})
    atomic_write_text(path, buffer.getvalue())
