"""The ball's track as a perfect lighting model would leave it: the true centre plus the
tracker's white noise (what issue 18's item 1 calls "beta at the tracking noise").

The tracked ball's error against the twin's true centre is split by frequency. The sensor's
noise on a tracked centre is white; the lighting's apparent-centre shift is a smooth function
of the ball's and the CD's angles (harmonics of order <= 12 of a ball turning at <= 60 Hz lie
below ~750 Hz) and motion blur is smoother still. So the error's power in the band
[``HIGH_BAND`` x Nyquist, Nyquist] (>= 1350 Hz at 4500 frames/s) measures the white level
alone, and the rest of the error's variance is the lighting leftover. The ideal track is the
true centre plus white Gaussian noise of that level, lost frames kept lost.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: the error's white level is read from this share of the band up to Nyquist (its top part)
HIGH_BAND = 0.6


@dataclass(frozen=True)
class BallError:
    """The tracked ball's error against its true centre [px], per axis pooled.

    Attributes:
        white_px: the white (tracking) noise's standard deviation.
        leftover_px: RMS of the rest (the lighting's smooth apparent-centre shift), its mean
            removed.
    """

    white_px: float
    leftover_px: float


def _filled(e: np.ndarray) -> np.ndarray:
    """``e`` with NaN (lost) samples linearly interpolated (ends held)."""
    ok = np.isfinite(e)
    idx = np.arange(e.size)
    return np.interp(idx, idx[ok], e[ok])


def ball_error(tracked_xy: np.ndarray, true_xy: np.ndarray) -> BallError:
    """The white and the leftover part of ``tracked_xy - true_xy`` ((N, 2) [px])."""
    white_var, total_var = [], []
    for k in range(2):
        e = _filled(tracked_xy[:, k] - true_xy[:, k])
        e = e - e.mean()
        spec = np.abs(np.fft.rfft(e)) ** 2 / e.size   # white: each bin ~ its variance
        band = slice(int(HIGH_BAND * spec.size), spec.size)
        white_var.append(float(np.mean(spec[band])))
        total_var.append(float(np.var(e)))
    white = float(np.mean(white_var))
    return BallError(white_px=float(np.sqrt(white)),
                     leftover_px=float(np.sqrt(max(np.mean(total_var) - white, 0.0))))


def ideal_ball(x_px: np.ndarray, y_px: np.ndarray, true_xy: np.ndarray, white_px: float,
               seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Copies of the tracks ((N, 3), columns centre, CD, ball) with the ball's column replaced
    by ``true_xy`` plus white noise of ``white_px``; lost (NaN) ball samples stay lost."""
    rng = np.random.default_rng([seed, 18])
    x, y = x_px.copy(), y_px.copy()
    lost = ~np.isfinite(x[:, 2]) | ~np.isfinite(y[:, 2])
    x[:, 2] = true_xy[:, 0] + rng.normal(0.0, white_px, len(x))
    y[:, 2] = true_xy[:, 1] + rng.normal(0.0, white_px, len(y))
    x[lost, 2] = y[lost, 2] = np.nan
    return x, y
