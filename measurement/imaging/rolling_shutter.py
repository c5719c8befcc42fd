"""Marker positions of a rolling-shutter recording brought to the frame times.

A global-shutter camera (the usual high-speed camera) exposes every row at once. A rolling
shutter (many CMOS sensors, phones' slow motion) reads the rows one after another: row r of
frame j is taken at t_j + r * line_time. A marker centred on row y is then seen where it was at
t_j + y * line_time, not at t_j. The CD marker circles the axis at ~100 px: over a turn its row
changes by ~200 rows, so with a read-out of a whole frame interval its sample time swings by
~0.8 of an interval, once per turn. theta is then off by omega * dt (5 mrad at 60 rad/s and
4500 frames/s, thirty times the tracking noise), and by an amount that grows with the speed, so
no fixed harmonic absorbs it (measured: the intervals 1.7x as wide, ``bench_off_family.py``
variant ``rolling``).

:func:`positions_at_frame_times` undoes it from the tracks alone: around each sample a cubic is
fitted by least squares to the coordinate's neighbouring samples at their own times
t_i + y_i * line_time (``HALF_WINDOW`` frames either side), and the sample is moved by that
cubic's change from its time to the frame time. Only the small change comes from the fit, so
each sample keeps its own tracking noise (white, not resampled).
"""
from __future__ import annotations

import numpy as np

from abu_model.errors import ParameterError


#: Samples either side of each one in its local cubic fit (the CD marker turns <= 0.5 rad over
#: the window at 125 rad/s and 4500 frames/s: a cubic's error there is < 0.01 px).
HALF_WINDOW = 6
DEGREE = 3


def _moved_to(u: np.ndarray, v: np.ndarray, target: np.ndarray) -> np.ndarray:
    """v (N,) sampled at u (N,) [frames], each moved to ``target`` (N,) [frames] along the
    least-squares cubic through its 2 HALF_WINDOW + 1 neighbours (windows kept inside)."""
    n, w = v.size, 2 * HALF_WINDOW + 1
    first = np.clip(np.arange(n) - HALF_WINDOW, 0, max(0, n - w))
    idx = np.minimum(first[:, None] + np.arange(w)[None, :], n - 1)
    a = (u[idx] - u[:, None])[..., None] ** np.arange(DEGREE + 1)      # (N, w, DEGREE + 1)
    ata = np.einsum("nwi,nwj->nij", a, a)
    atv = np.einsum("nwi,nw->ni", a, v[idx])
    c = np.linalg.solve(ata, atv[..., None])[..., 0]                   # (N, DEGREE + 1)
    d = (target - u)[:, None] ** np.arange(1, DEGREE + 1)
    return v + (c[:, 1:] * d).sum(axis=1)


def positions_at_frame_times(time_s: np.ndarray, x_px: np.ndarray, y_px: np.ndarray,
                             line_time_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) (N, M) [px] of M markers at the frame times ``time_s`` (N,) [s], from positions
    taken by a rolling shutter that reads row r at frame time + r * ``line_time_s`` [s/row]
    (negative: the bottom row first; 0: a global shutter, returned unchanged)."""
    t = np.asarray(time_s, dtype=float)
    x, y = np.array(x_px, dtype=float), np.array(y_px, dtype=float)
    if not np.isfinite(line_time_s):
        raise ParameterError("line_time_s", line_time_s, "a finite time per row [s]")
    if line_time_s == 0.0 or t.size < 2 * HALF_WINDOW + 1:
        return x, y
    dt = float(np.median(np.diff(t)))
    span = (np.nanmax(y) - np.nanmin(y)) * abs(line_time_s)
    if not span < dt:   # beyond this the sample times of a marker may run backwards
        raise ParameterError("line_time_s", line_time_s, f"a read-out of the rows the markers "
                             f"cross ({span:.3g} s) shorter than a frame interval ({dt:.3g} s)")
    frames = (t - t[0]) / dt
    for k in range(x.shape[1]):
        taken = frames + y[:, k] * (line_time_s / dt)   # the row read when the marker was seen
        x[:, k], y[:, k] = _moved_to(taken, x[:, k], frames), _moved_to(taken, y[:, k], frames)
    return x, y


__all__ = ["positions_at_frame_times"]
