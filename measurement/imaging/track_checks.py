"""Physical plausibility of three marker tracks (issue 19): positions the geometry excludes.

The three markers of the setup are the ABU centre, a marker on the CD and the ball. Seen by a
fixed camera above the ABU:

* they are three **distinct** points (a CD marker or ball on the centre, or the ball on the CD
  marker in every frame, is one marker tracked twice);
* the centre stays put, the CD marker turns on a circle about it and the ball runs on its own
  circle about it (radius l): the distance of each from the centre is the same in every frame
  up to the ellipse of a tilted view and the lens (:data:`RADIUS_TOLERANCE`);
* pixel coordinates are bounded (:data:`MAX_COORD_PX`).

Tracks that break one of these would still give angles and, through them, a number; the checks
refuse them naming the file, the frame and the marker.
"""
from __future__ import annotations

from typing import Callable

import numpy as np

from abu_model.errors import AbuError

#: Largest |pixel coordinate| accepted [px]: the largest sensors have about 1e4 px a side.
MAX_COORD_PX = 1.0e6
#: Smallest median distance of the CD marker and of the ball from the centre [px]: below it the
#: angle is tracking noise (0.05 px noise at 2 px is 0.025 rad, the size of a slip).
MIN_RADIUS_PX = 2.0
#: Largest relative deviation of a marker's distance from the centre from its median: a view
#: tilted by 50 degrees makes the circle an ellipse whose radius varies by +-18 %; a lens adds
#: a few per cent.
RADIUS_TOLERANCE = 0.25
#: Smallest median distance between the CD marker and the ball [px] (distinct markers).
MIN_SEPARATION_PX = 0.5
ROLE_NAMES = ("ABU centre", "CD marker", "ball")


class TrackGeometryError(AbuError, ValueError):
    """Marker tracks that three markers of the setup cannot produce."""


def check_marker_geometry(x: np.ndarray, y: np.ndarray, source: str,
                          valid: np.ndarray | None = None, *,
                          label: Callable[[int], str] = lambda k: f"frame {k}") -> None:
    """Refuse tracks that are not three distinct markers: a fixed centre, the CD marker and the
    ball each on a circle about it.

    Args:
        x, y: (N, 3) pixel coordinates, columns centre, CD marker, ball.
        source: the file or recording, for messages.
        valid: (N,) bool, the frames to check (e.g. not lost); default all.
        label: names frame k (0-based) in messages (a CSV: ``data row k + 1``).
    """
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    frames = np.arange(x.shape[0])
    if valid is not None:
        frames = frames[np.asarray(valid, dtype=bool)]
        x, y = x[frames], y[frames]
    if frames.size == 0:
        return
    big = np.abs(np.concatenate([x, y], axis=1)) > MAX_COORD_PX
    if big.any():
        k, j = np.argwhere(big)[0]
        raise TrackGeometryError(
            f"{source}, {label(int(frames[k]))}: the {ROLE_NAMES[j % 3]} at "
            f"({x[k, j % 3]:.6g}, {y[k, j % 3]:.6g}) px; expected pixel coordinates within "
            f"+-{MAX_COORD_PX:g} px (no camera has a larger sensor)")
    cx, cy = np.median(x[:, 0]), np.median(y[:, 0])
    radius = {j: np.hypot(x[:, j] - x[:, 0], y[:, j] - y[:, 0]) for j in (1, 2)}
    for j in (1, 2):
        r_med = float(np.median(radius[j]))
        if not r_med >= MIN_RADIUS_PX:
            raise TrackGeometryError(
                f"{source}: the {ROLE_NAMES[j]} lies {r_med:.3g} px from the ABU centre (median "
                f"over the frames); expected three distinct markers, the {ROLE_NAMES[j]} at "
                f"least {MIN_RADIUS_PX:g} px from the centre (one marker tracked twice, or "
                "swapped columns?)")
        dev = np.abs(radius[j] / r_med - 1.0)
        k = int(np.argmax(dev))
        if dev[k] > RADIUS_TOLERANCE:
            raise TrackGeometryError(
                f"{source}, {label(int(frames[k]))}: the {ROLE_NAMES[j]} is {radius[j][k]:.4g} px from "
                f"the ABU centre, {100 * dev[k]:.0f} % off its median {r_med:.4g} px; expected "
                f"it on a circle about the centre (within {100 * RADIUS_TOLERANCE:.0f} %: a "
                "tilted view or a lens change the radius less): a marker lost or confused?")
    drift = np.hypot(x[:, 0] - cx, y[:, 0] - cy)
    k = int(np.argmax(drift))
    r_cd = float(np.median(radius[1]))
    if drift[k] > RADIUS_TOLERANCE * r_cd:
        raise TrackGeometryError(
            f"{source}, {label(int(frames[k]))}: the ABU centre moved {drift[k]:.4g} px from its "
            f"median position; expected a fixed centre (within {100 * RADIUS_TOLERANCE:.0f} % of "
            f"the CD marker's radius {r_cd:.4g} px: the camera and the axis do not move)")
    gap = float(np.median(np.hypot(x[:, 1] - x[:, 2], y[:, 1] - y[:, 2])))
    if not gap >= MIN_SEPARATION_PX:  # the ball may pass the marker, not sit on it throughout
        raise TrackGeometryError(
            f"{source}: the CD marker and the ball are {gap:.3g} px apart (median over the "
            f"frames); expected three distinct markers (at least {MIN_SEPARATION_PX:g} px "
            "apart): one marker tracked twice?")
