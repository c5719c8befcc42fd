"""Marker tracks on disk and the angles theta, beta computed from them.

Input CSV (already-tracked coordinates, one row per frame)::

    time_s,x_center_px,y_center_px,x_cd_px,y_cd_px,x_ball_px,y_ball_px

or the older names without units (``time,x_center,y_center,x_cd,y_cd,x_ball,y_ball``);
``time`` in s (strictly increasing), coordinates in pixels. Pixel coordinates follow OpenCV: ``x``
is the column, ``y`` the row, and ``y`` points *down* the image. Lines starting with ``#`` are
comments; extra columns are ignored, except ``lost`` (see below) which is read when present.

Output ``tracks.csv`` (plain CSV: no comment line, units in the column names, so
``pandas.read_csv(path)`` and ``csv.DictReader`` read it with no options)::

    time_s,theta_rad,beta_rad,x_center_px,y_center_px,x_cd_px,y_cd_px,x_ball_px,y_ball_px,lost

``theta``, ``beta`` in rad, ``lost`` an integer bit mask of the markers the tracker lost in that
frame (1 = centre, 2 = CD, 4 = ball; 0 = all found). Coordinates of a lost marker are interpolated
in time before they are written (see :func:`fill_lost`), so every written number is finite; the
mask says which ones are not measurements. The file is a valid input for :func:`read_tracks_csv`.

Angles (report sec. 3.2). The image is the view from the camera above the ABU. Its right-handed
world frame has X along the image columns and Y *up* the image (Y = -y), so a counter-clockwise turn
on the displayed image is positive. theta is the angle of the vector centre -> CD marker, beta the
angle of centre -> ball minus theta (the angle CBm of the report), both unwrapped. With this sign a
clockwise-turning ABU, as in the report's experiments, has negative omega.
"""
from __future__ import annotations

import csv
import io
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from abu_model import validate
from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError

from measurement.imaging.track_checks import check_marker_geometry

#: Column names of an input tracks CSV, in the order centre, CD, ball.
COORD_COLUMNS = ("x_center", "y_center", "x_cd", "y_cd", "x_ball", "y_ball")
INPUT_COLUMNS = ("time",) + COORD_COLUMNS
#: Column names written (units in the names); the reader accepts these and the old ones.
UNIT_SUFFIX = {"time": "_s", "theta": "_rad", "beta": "_rad", **{c: "_px" for c in COORD_COLUMNS}}
OUTPUT_COLUMNS = tuple(c + UNIT_SUFFIX[c]
                       for c in ("time", "theta", "beta") + COORD_COLUMNS) + ("lost",)
MARKERS = ("center", "cd", "ball")
#: Minimum number of frames a tracks file must hold for the analysis (its smallest filters).
MIN_ROWS = 20
#: Largest tracks file read [bytes] (held in memory; ~100 bytes per row).
MAX_BYTES = 1 << 30


class TracksFileError(AbuError, ValueError):
    """A tracks CSV is malformed. Names the file, the data row / line and the column."""

    def __init__(self, path: str | os.PathLike, message: str, *, row: int | None = None,
                 line: int | None = None, column: str | None = None):
        self.path = str(path)
        self.row = row
        self.line = line
        self.column = column
        where = [self.path]
        if row is not None:
            where.append(f"data row {row}")
        if line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column '{column}'")
        super().__init__(f"{', '.join(where)}: {message}")


class LostMarkerError(AbuError, ValueError):
    """The tracker lost a marker for too long (or too often) to interpolate over it."""


@dataclass(frozen=True)
class TrackTable:
    """Marker coordinates read from a tracks CSV.

    Attributes:
        time: frame times [s], shape (N,), strictly increasing.
        x, y: pixel coordinates [px], shape (N, 3), columns centre, CD, ball (OpenCV x = column,
            y = row pointing down).
        lost: shape (N, 3) bool, True where the tracker lost that marker (all False when the file
            has no ``lost`` column).
        path: the file read.
    """

    time: np.ndarray
    x: np.ndarray
    y: np.ndarray
    lost: np.ndarray
    path: str


def read_tracks_csv(path: str | os.PathLike, *, min_rows: int = MIN_ROWS) -> TrackTable:
    """Read a CSV of tracked marker coordinates (see the module docstring for the format).

    Raises:
        TracksFileError: unreadable file, missing column, empty, non-numeric or non-finite cell,
            time not strictly increasing, fewer than ``min_rows`` data rows. The message names
            the file, the 1-based data row, the 1-based line of the file and the column.
    """
    p = Path(path)
    try:
        size = p.stat().st_size
    except OSError:
        size = 0  # reported below by read_text
    if size > MAX_BYTES:
        raise TracksFileError(p, f"{size / 2**20:.0f} MiB; at most {MAX_BYTES / 2**20:.0f} MiB "
                                 f"(about {MAX_BYTES // 100:,} rows; the report's record has 3072)")
    try:
        text = p.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise TracksFileError(p, "file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise TracksFileError(p, f"cannot read the file as UTF-8 text ({exc})") from None

    reader = csv.reader(io.StringIO(text, newline=""))
    header: list[str] | None = None
    header_line = 0
    rows: list[tuple[int, list[str]]] = []
    for record in reader:
        line_no = reader.line_num
        if not record or all(not cell.strip() for cell in record):
            continue
        if record[0].lstrip().startswith("#"):
            continue
        if header is None:
            header = [cell.strip() for cell in record]
            header_line = line_no
            continue
        rows.append((line_no, record))
    if header is None:
        raise TracksFileError(p, f"no header line; expected the columns {','.join(INPUT_COLUMNS)}")
    _check_header(p, header, header_line)
    index = {}
    # name a missing column in the style of the header (old names without units, or new)
    old_style = any(c in header for c in INPUT_COLUMNS) and \
        not any(c + UNIT_SUFFIX[c] in header for c in INPUT_COLUMNS)
    for name in INPUT_COLUMNS:
        # the unit-suffixed name (written since issue 7) or the old one
        found = [c for c in (name + UNIT_SUFFIX[name], name) if c in header]
        if not found:
            raise TracksFileError(p, f"missing column (header has {','.join(header)}; expected "
                                     f"{','.join(c + UNIT_SUFFIX[c] for c in INPUT_COLUMNS)} "
                                     f"or {','.join(INPUT_COLUMNS)})", line=header_line,
                                  column=name if old_style else name + UNIT_SUFFIX[name])
        index[name] = header.index(found[0])
    lost_index = header.index("lost") if "lost" in header else None
    if len(rows) < min_rows:
        raise TracksFileError(p, f"{len(rows)} data rows; the analysis needs at least {min_rows}")

    n = len(rows)
    data = np.empty((n, len(INPUT_COLUMNS)))
    lost_mask = np.zeros(n, dtype=int)
    for r, (line_no, record) in enumerate(rows, start=1):
        for j, name in enumerate(INPUT_COLUMNS):
            k = index[name]
            cell = record[k].strip() if k < len(record) else ""
            if cell == "":
                raise TracksFileError(p, "empty or missing cell", row=r, line=line_no, column=name)
            if "_" in cell:  # Python reads 1_0 as 10; no CSV writer means that
                raise TracksFileError(p, f"non-numeric value {cell!r}", row=r, line=line_no,
                                      column=name)
            try:
                value = float(cell)
            except ValueError:
                raise TracksFileError(p, f"non-numeric value {cell!r}", row=r, line=line_no,
                                      column=name) from None
            if not math.isfinite(value):
                raise TracksFileError(p, f"non-finite value {cell!r} (NaN or infinity)", row=r,
                                      line=line_no, column=name)
            data[r - 1, j] = value
        if lost_index is not None and lost_index < len(record) and record[lost_index].strip():
            lost_mask[r - 1] = _lost_cell(p, record[lost_index], r, line_no)

    time = data[:, 0]
    steps = np.diff(time)
    bad = np.flatnonzero(steps <= 0.0)
    if bad.size:
        r = int(bad[0]) + 2  # 1-based data row of the second sample of the pair
        raise validate.order_error(str(p), f"data row {r}, line {rows[r - 1][0]}, column 'time'",
                                   time[r - 2], time[r - 1],
                                   error=lambda m: TracksFileError(p, m.split(", ", 1)[1]))
    x = data[:, [1, 3, 5]].copy()
    y = data[:, [2, 4, 6]].copy()
    lost = np.stack([(lost_mask >> bit) & 1 for bit in range(3)], axis=1).astype(bool)
    check_marker_geometry(x, y, str(p), valid=~lost.any(axis=1),
                          label=lambda k: f"data row {k + 1} (line {rows[k][0]})")
    return TrackTable(time=time, x=x, y=y, lost=lost, path=str(p))


def _lost_cell(p: Path, cell: str, row: int, line: int) -> int:
    """The ``lost`` bit mask of one row (an integer 0-7)."""
    return int(validate.cell(cell, "lost", lo=0, hi=7, integer=True,
                             why="a bit mask: 1 centre, 2 CD, 4 ball",
                             error=lambda m: TracksFileError(p, m.split(": ", 1)[1], row=row,
                                                             line=line, column="lost")))


def _check_header(p: Path, header: list[str], header_line: int) -> None:
    """Each column once: no repeated name, not both the old and the unit-suffixed name."""
    validate.unique_names(header, f"{p}, line {header_line}",
                          error=lambda m: TracksFileError(p, m.split(": ", 1)[1],
                                                          line=header_line))
    both = [c for c in INPUT_COLUMNS if c in header and c + UNIT_SUFFIX[c] in header]
    if both:
        raise TracksFileError(p, f"both '{both[0]}' and '{both[0]}{UNIT_SUFFIX[both[0]]}'; "
                                 "expected one column per quantity (which one is meant?)",
                              line=header_line, column=both[0])


def lost_bitmask(lost: np.ndarray) -> np.ndarray:
    """(N, 3) bool lost flags -> (N,) int bit mask (1 = centre, 2 = CD, 4 = ball)."""
    lost = np.asarray(lost, dtype=bool)
    return (lost * np.array([1, 2, 4])).sum(axis=1).astype(int)


def fill_lost(time: np.ndarray, values: np.ndarray, lost: np.ndarray, *,
              max_gap: int = 5, max_fraction: float = 0.02) -> np.ndarray:
    """Interpolate (linearly in time) the samples of each marker flagged lost.

    Args:
        time: frame times [s], (N,).
        values: (N, 3) coordinates [px] (one column per marker).
        lost: (N, 3) bool flags.
        max_gap: longest run of consecutive lost frames of one marker that is interpolated.
        max_fraction: largest fraction of lost frames per marker.

    Raises:
        LostMarkerError: a marker is lost in the first or last frame, for more than ``max_gap``
            consecutive frames, or in more than ``max_fraction`` of the frames; the message names
            the marker and the (0-based) frame.
    """
    out = np.array(values, dtype=float, copy=True)
    lost = np.asarray(lost, dtype=bool)
    n = len(time)
    for j, name in enumerate(MARKERS):
        flags = lost[:, j]
        if not flags.any():
            continue
        frames = np.flatnonzero(flags)
        # Runs of consecutive lost frames.
        breaks = np.flatnonzero(np.diff(frames) > 1)
        starts = np.r_[frames[0], frames[breaks + 1]]
        ends = np.r_[frames[breaks], frames[-1]]
        if flags[0] or flags[-1]:
            k = 0 if flags[0] else len(starts) - 1
            edge = "first" if flags[0] else "last"
            raise LostMarkerError(f"marker '{name}' lost in frames {starts[k]}-{ends[k]} (up to "
                                  f"the {edge} frame, {n} frames in all): cannot interpolate; "
                                  "re-track with other seeds or another method")
        longest = int(np.argmax(ends - starts))
        if ends[longest] - starts[longest] + 1 > max_gap:
            raise LostMarkerError(
                f"marker '{name}' lost in frames {starts[longest]}-{ends[longest]} "
                f"({ends[longest] - starts[longest] + 1} consecutive frames, at most {max_gap} "
                "are interpolated)")
        if frames.size > max_fraction * n:
            raise LostMarkerError(f"marker '{name}' lost in {frames.size} of {n} frames (first "
                                  f"lost frame {frames[0]}); at most {max_fraction:.0%} are "
                                  "interpolated")
        good = ~flags
        out[flags, j] = np.interp(time[flags], time[good], out[good, j])
    return out


def angles_from_pixels(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """theta and beta [rad] from pixel coordinates of centre, CD and ball.

    Args:
        x, y: (N, 3) pixel coordinates (OpenCV: x column, y row pointing down), columns centre,
            CD, ball.

    Returns:
        (theta, beta), each (N,), unwrapped. theta = angle of centre -> CD in the world frame
        (X = x, Y = -y, counter-clockwise positive); beta = angle of centre -> ball minus theta,
        taken in (-pi, pi] at the first frame.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    dx_cd, dy_cd = x[:, 1] - x[:, 0], -(y[:, 1] - y[:, 0])
    dx_b, dy_b = x[:, 2] - x[:, 0], -(y[:, 2] - y[:, 0])
    theta = np.unwrap(np.arctan2(dy_cd, dx_cd))
    # The relative angle from the cross and dot products: exact wrapping, one unwrap.
    rel = np.arctan2(dx_cd * dy_b - dy_cd * dx_b, dx_cd * dx_b + dy_cd * dy_b)
    beta = np.unwrap(rel)
    return theta, beta


def table_csv_text(names: list[str], cols: list[np.ndarray], float_format: str = "%.10g") -> str:
    """Plain CSV text (header, rows) of equal-length columns; integer columns as integers,
    non-finite floats as empty cells. All rows formatted by one ``%`` in C (a Python loop over
    cells cost ~0.3 s of ``abu measure`` for 3072 frames; ``np.savetxt``'s loop over rows and a
    regular expression for the non-finite cells, 0.05 s)."""
    arrays = [np.asarray(c) for c in cols]
    fmts = ["%d" if np.issubdtype(a.dtype, np.integer) else float_format for a in arrays]
    data = np.column_stack([a.astype(float) for a in arrays]) if arrays else np.zeros((0, 0))
    body = ((",".join(fmts) + "\n") * data.shape[0]) % tuple(data.ravel().tolist()) \
        if data.size else ""
    # a formatted number holds no letter but 'e': "nan", "inf" and "-inf" are whole cells
    body = body.replace("-inf", "").replace("inf", "").replace("nan", "")
    return ",".join(names) + "\n" + body


def format_tracks_csv(time: np.ndarray, theta: np.ndarray, beta: np.ndarray, x: np.ndarray,
                      y: np.ndarray, lost: np.ndarray | None = None) -> str:
    """The text of a ``tracks.csv`` (header with units in the names, one row per frame)."""
    n = len(time)
    mask = np.zeros(n, dtype=int) if lost is None else lost_bitmask(lost)
    cols = [np.asarray(time), np.asarray(theta), np.asarray(beta)]
    for j in range(3):
        cols += [np.asarray(x)[:, j], np.asarray(y)[:, j]]
    # 17 significant digits: the file round-trips exactly
    return table_csv_text(list(OUTPUT_COLUMNS), cols + [np.asarray(mask, dtype=int)], "%.17g")


def write_tracks_csv(path: str | os.PathLike, time: np.ndarray, x: np.ndarray, y: np.ndarray,
                     lost: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Write ``tracks.csv`` atomically; returns the (theta, beta) written [rad].

    Lost coordinates must already be filled (see :func:`fill_lost`); ``lost`` only sets the mask.
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if not (np.isfinite(x).all() and np.isfinite(y).all()):
        raise LostMarkerError("non-finite marker coordinates: fill lost frames before writing")
    theta, beta = angles_from_pixels(x, y)
    atomic_write_text(path, format_tracks_csv(time, theta, beta, x, y, lost))
    return theta, beta
