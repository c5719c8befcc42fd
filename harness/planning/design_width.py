"""The width model (:mod:`.width_model`) applied to a staircase design: the planned motion on
the camera's frame grid, the predicted ``abu measure`` width across the prior range, and the
re-ranking of the design search's candidates by it."""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from controller.drive import Drive
from controller.reference import Staircase

from harness.planning.loop_response import as_setpoints, drive_response
from harness.planning.width_model import CALIBRATED, MU_D_RATIOS, WidthConstants, \
    WidthPrediction, predict_widths

HZ = 2.0 * math.pi


def staircase_motion(drive: Drive, staircase: Staircase, fps: float, frames: int
                     ) -> tuple[np.ndarray, ...]:
    """(t, theta, omega, omega_dot) of the loop's response to the staircase at the frame times
    k / fps, k < frames [s, rad, rad/s, rad/s^2] (steady state at omega0 before it)."""
    t = np.arange(frames) / fps
    r = drive_response(drive, as_setpoints(staircase), t, need_theta=True)
    return t, r.theta, r.omega, r.alpha


def predict_staircase(spec: Any, staircase: Staircase, mus: np.ndarray) -> WidthPrediction:
    """The width model at ``mus`` for ``staircase`` under ``spec`` (a DesignSpec, whose
    ``width`` holds the model's constants)."""
    t, th, w, a = staircase_motion(spec.drive, staircase, spec.fps, spec.frames)
    return predict_widths(t, th, w, a, mus, spec.ball.lever_ratio, spec.width,
                          controller_sample_time_s=spec.drive.sample_time)


def score(pred: WidthPrediction, objective: str) -> float:
    """Mean (``expected``) or largest (``worst``) predicted width over the mu grid [-]."""
    w = pred.expected
    return float(np.mean(w) if objective == "expected" else np.max(w))


def summary(pred: WidthPrediction, objective: str) -> dict[str, Any]:
    """The ``width_prediction`` object of design.json / next.json."""
    fin = np.isfinite(pred.expected)
    return {
        "method": "harness.planning.width_model: slip emergence from beta's noise, "
                  "kinematic noise and truncation (Savitzky-Golay, or the drive model's "
                  "floor), lens prior; calibrated on rendered designed runs (docs/design.md)",
        "definition": "abu measure's relative_width, (mu_high - mu_low) / mid",
        "objective": objective,
        "camera_noise": {"sigma_theta_rad": pred.constants.sigma_theta_rad,
                         "sigma_beta_rad": pred.constants.sigma_beta_rad,
                         "theta_harmonic_rad": pred.constants.theta_harmonic_rad,
                         "noise_source": pred.constants.noise_source,
                         "lens_source": pred.constants.lens_source,
                         "lens_note": pred.constants.lens_note},
        "kinematics": pred.constants.kinematics,
        "expected": float(np.mean(pred.expected)) if fin.all() else None,
        "low90": float(np.mean(pred.low90)) if fin.all() else None,
        "high90": float(np.mean(pred.high90)) if fin.all() else None,
        "worst_expected": float(np.max(pred.expected)) if fin.all() else None,
        "finite_share": float(np.mean(fin)),
        "table": [pred.row(i) for i in range(pred.mu.size)],
    }


def predict_run_width(design: dict[str, Any], drive: Drive, mu: float, lever: float | None = None,
                      constants: WidthConstants = CALIBRATED,
                      mu_d_ratios: tuple[float, float, float] = MU_D_RATIOS
                      ) -> dict[str, float | None]:
    """The prediction at one true mu for a design.json object (``abu design --json``);
    ``mu_d_ratios``: as :func:`predict_widths`."""
    from abu_model.params import BallParams

    stair = Staircase(design["omega0_hz"] * HZ, design["omega_end_hz"] * HZ, design["t0_s"],
                      design["te_s"], design["step_hz"] * HZ, design["rounding"])
    t, th, w, a = staircase_motion(drive, stair, design["fps_hz"], design["frames"])
    lev = BallParams().lever_ratio if lever is None else lever
    return predict_widths(t, th, w, a, np.array([mu]), lev, constants,
                          mu_d_ratios, drive.sample_time).row(0)
