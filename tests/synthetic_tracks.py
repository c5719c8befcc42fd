"""Synthetic measurement records for the analysis tests (not a test module itself).

The truth comes from the project's exact stick/slip plant (``abu_model.plant.AbuPlant``, an
implementation independent of the analysis code) driven by a prescribed torque, so omega,
omega_dot, beta and the slip instant are known exactly. Tracking noise, a lighting harmonic and
the camera geometry (pixels, y down) are added here.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from abu_model.params import BallParams, PlantParams
from abu_model.plant import AbuPlant, Mode

J_ABU = 4.5e-5  # kg m^2; the decoupled plant's alpha = T / J_ABU


@dataclass
class Record:
    time: np.ndarray       # s
    theta: np.ndarray      # rad
    omega: np.ndarray      # rad/s
    alpha: np.ndarray      # rad/s^2 (right-hand limit at the sample)
    beta: np.ndarray       # rad
    mode: np.ndarray       # -1, 0, 1
    mu: float
    t_slip: float          # first stick -> slip switch [s] (inf if none)
    l: float
    d: float


def alpha_profile(kind: str, t: np.ndarray) -> np.ndarray:
    """Commanded ABU acceleration [rad/s^2] (negative: the ABU speeds up clockwise).

    ``ramp``: linear in time (report sec. 4.1), -300 t. ``steps``: a staircase-like profile,
    a jump of -25 rad/s^2 every 50 ms from 10 ms on, each decaying with a 0.8 s time constant
    (the slow PI loop of the report). ``rundown`` / ``slowdown``: ``steps``, then from 0.6 s
    a brake through standstill / to two thirds of the speed.
    """
    if kind == "ramp":
        return -300.0 * t
    if kind in ("steps", "rundown", "slowdown"):
        out = np.zeros_like(t)
        for k in range(20):
            ts = 0.01 + 0.05 * k
            out -= np.where(t >= ts, 25.0 * np.exp(-(t - ts) / 0.8), 0.0)
        if kind == "steps":
            return out
        # from 0.6 s the drive brakes: ``rundown`` through standstill into the other sense
        # (+600 rad/s^2 reached in 50 ms), ``slowdown`` by 300 rad/s^2 for 0.15 s
        t_b = 0.6
        held = out[np.searchsorted(t, t_b)] * np.exp(-(t - t_b) / 0.05)
        brake = (600.0 * np.minimum((t - t_b) / 0.05, 1.0) if kind == "rundown"
                 else np.where(t < t_b + 0.15, 300.0, 0.0))
        return np.where(t < t_b, out, held + brake)
    raise ValueError(kind)


def simulate(mu: float, kind: str = "ramp", *, fps: float = 4500.0, n: int = 3072,
             omega0: float = -2 * math.pi * 9, beta0: float = 0.4, l: float = 1.15e-2,
             d: float = 3.0e-3) -> Record:
    """Sample the exact plant at ``fps``; the torque is linear between samples."""
    params = PlantParams(ball=BallParams(mu=mu, l=l, d=d), J_abu=J_ABU)
    plant = AbuPlant(params, omega0=omega0, beta0=beta0)
    t = np.arange(n) / fps
    # Evaluate the commanded acceleration on a grid with the steps placed exactly on samples'
    # right-hand side: the torque between samples is the first-order hold of these values.
    alpha_cmd = alpha_profile(kind, t)
    theta = np.empty(n); omega = np.empty(n); beta = np.empty(n); alpha = np.empty(n)
    mode = np.empty(n, dtype=int)
    t_slip = math.inf
    for i in range(n):
        s = plant.state
        theta[i], omega[i], beta[i], mode[i] = s.theta, s.omega, s.beta, s.mode
        torque = J_ABU * alpha_cmd[i]
        alpha[i] = plant.outputs(torque).alpha
        if i == n - 1:
            break
        rate = J_ABU * (alpha_cmd[i + 1] - alpha_cmd[i]) * fps if kind == "ramp" else 0.0
        for sw in plant.advance(1.0 / fps, torque, rate):
            if sw.from_mode == Mode.STICK and math.isinf(t_slip):
                t_slip = sw.time
    return Record(t, theta, omega, alpha, beta, mode, mu, t_slip, l, d)


def to_pixels(theta: np.ndarray, beta: np.ndarray, *, centre=(128.0, 128.0), r_cd: float = 95.0,
              r_ball: float = 46.0) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) pixel coordinates (N, 3) of centre, CD, ball; image y points down."""
    n = theta.size
    cx, cy = centre
    x = np.empty((n, 3)); y = np.empty((n, 3))
    x[:, 0], y[:, 0] = cx, cy
    x[:, 1], y[:, 1] = cx + r_cd * np.cos(theta), cy - r_cd * np.sin(theta)
    x[:, 2], y[:, 2] = cx + r_ball * np.cos(theta + beta), cy - r_ball * np.sin(theta + beta)
    return x, y


def measured_pixels(rec: Record, *, sigma_px: float = 0.03, harmonic_px: float = 0.0,
                    harmonic_phase: float = 0.7, seed: int = 0,
                    r_ball: float = 46.0) -> tuple[np.ndarray, np.ndarray]:
    """Pixel tracks with white noise ``sigma_px`` on every coordinate and a lighting harmonic.

    The harmonic shifts the ball centre by ``harmonic_px`` along a fixed image direction times
    the cosine of the ball's image angle (an asymmetric light): it shows on beta at the rotation
    frequency with amplitude about harmonic_px / r_ball rad.
    """
    rng = np.random.default_rng(seed)
    x, y = to_pixels(rec.theta, rec.beta, r_ball=r_ball)
    phi = rec.theta + rec.beta
    shift = harmonic_px * np.cos(phi + harmonic_phase)
    # Tangential shift (changes beta): along the direction perpendicular to the radius.
    x[:, 2] += -shift * np.sin(phi)
    y[:, 2] += -shift * np.cos(phi)
    x = x + sigma_px * rng.standard_normal(x.shape)
    y = y + sigma_px * rng.standard_normal(y.shape)
    return x, y


def write_tracks_csv(path, rec: Record, x: np.ndarray, y: np.ndarray):
    """``rec``'s times with pixel tracks ``x``, ``y`` (N, 3) as the tracks CSV ``abu measure
    --tracks`` reads (6 decimals); returns ``path``."""
    rows = ["time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"] + [
        ",".join(f"{v:.6f}" for v in (t, *np.ravel(np.c_[xi, yi])))
        for t, xi, yi in zip(rec.time, x, y)]
    path.write_text("\n".join(rows) + "\n")
    return path
