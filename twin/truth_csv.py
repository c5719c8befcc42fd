"""``truth.csv`` of a rendered recording: per frame the true state and the true marker centres.

One writer and one column list for both twins (the report's, :mod:`twin.report_twin`, and the
random family, :mod:`twin.scenario`). Positions are spelled as in ``tracks.csv``
(``x_center_px``, ``y_cd_px``, ...); :func:`read_truth_csv` also reads files written before that
(``centre_x_px``, ``cd_x_px``, ...).
"""
from __future__ import annotations

import csv
import io
import math
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

#: Columns every truth.csv has (units in the names; mu_req and mode are dimensionless).
TRUTH_COLUMNS = (
    "time_s", "x_center_px", "y_center_px", "x_cd_px", "y_cd_px", "x_ball_px", "y_ball_px",
    "x_ball_apparent_px", "y_ball_apparent_px", "theta_rad", "beta_rad", "omega_rad_s",
    "omega_dot_rad_s2", "beta_dot_rad_s", "omega_ref_rad_s", "mu_req", "mode",
)
#: Extra columns of the random family: the image of the ABU axis [px].
AXIS_COLUMNS = ("x_axis_px", "y_axis_px")
#: Names of files written before the spelling was unified.
OLD_NAMES = {"centre_x_px": "x_center_px", "centre_y_px": "y_center_px",
             "cd_x_px": "x_cd_px", "cd_y_px": "y_cd_px", "ball_x_px": "x_ball_px",
             "ball_y_px": "y_ball_px", "ball_apparent_x_px": "x_ball_apparent_px",
             "ball_apparent_y_px": "y_ball_apparent_px", "axis_x_px": "x_axis_px",
             "axis_y_px": "y_axis_px"}
INTEGER_COLUMNS = ("mode",)


def truth_csv_text(columns: Sequence[str], values: Mapping[str, np.ndarray]) -> str:
    """CSV text of ``values`` in the order ``columns``: floats as ``repr`` (they read back
    exactly), integers as integers, non-finite values as empty cells."""
    cols = [np.asarray(values[name]) for name in columns]
    buf = io.StringIO()
    buf.write(",".join(columns) + "\n")
    ints = [name in INTEGER_COLUMNS for name in columns]
    for k in range(cols[0].shape[0]):
        cells = []
        for c, is_int in zip(cols, ints):
            v = float(c[k])
            cells.append("" if not math.isfinite(v) else str(int(v)) if is_int else repr(v))
        buf.write(",".join(cells) + "\n")
    return buf.getvalue()


def read_truth_csv(path: str | Path) -> dict[str, np.ndarray]:
    """The columns of a truth.csv (old spellings renamed), empty cells as NaN."""
    with Path(path).open(newline="", encoding="utf-8") as fh:
        rows = list(csv.reader(fh))
    names = [OLD_NAMES.get(h, h) for h in rows[0]]
    data = np.array([[float(v) if v else math.nan for v in r] for r in rows[1:]], dtype=float)
    return {name: data[:, j] for j, name in enumerate(names)}
