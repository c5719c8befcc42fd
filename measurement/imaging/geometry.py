"""Geometry of the three markers in the image: the fixed ABU axis and circle fits [px].

Used by the kinematics (theta about the axis) and by the camera step (the axis after
undistortion), so it lives with the imaging stage that both follow.
"""
from __future__ import annotations

import numpy as np


def circle_centre(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Centre of the least-squares circle through the points (x, y) [px] (algebraic, Kasa)."""
    sol = np.linalg.lstsq(np.column_stack([x, y, np.ones_like(x)]), x ** 2 + y ** 2, rcond=None)[0]
    return 0.5 * float(sol[0]), 0.5 * float(sol[1])


def fixed_axis(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates with the centre marker replaced by the fixed ABU axis [px].

    A centre marker glued slightly off the axis circles it once per turn; measured from it, theta
    carries a harmonic e/r_cd sin(theta + p) whose second derivative, e/r_cd omega^2, is tens of
    rad/s^2 for e = 0.3 px (the twin's eccentric marker). The axis is the centre of the circle the
    CD marker runs on (algebraic least-squares circle fit, Kasa 1976) when the record covers
    more than half a turn; otherwise the mean of the centre marker.
    """
    x = np.array(x, dtype=float)
    y = np.array(y, dtype=float)
    xc, yc = x[:, 1], y[:, 1]
    ang = np.unwrap(np.arctan2(-(yc - y[:, 0]), xc - x[:, 0]))
    if float(np.ptp(ang)) > np.pi:
        cx, cy = circle_centre(xc, yc)
    else:
        cx, cy = float(np.mean(x[:, 0])), float(np.mean(y[:, 0]))
    x[:, 0], y[:, 0] = cx, cy
    return x, y
