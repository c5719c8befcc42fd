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


#: The lens prior a calibration states: median over the designed runs' 30-view calibrations
#: (``bench_designed_runs.py --camera 30``: 2.6e-4 and 2.8e-4 rad on two slices of 72) [rad]
CALIBRATED_LENS_PRIOR_RAD = 2.8e-4
#: theta's and beta's noise [rad] of a camera twice as close, relative to the family's camera:
#: ratios of the medians that ``abu measure`` stated on rendered designed runs
#: (``bench_designed_runs.py --camera 30``, seeds 1000-1071 at 1x: theta 2.73e-4, beta
#: 6.07e-4 rad; ``--zoom 2``, seeds 5000-5071: 1.11e-4, 3.37e-4). Tracking noise in px falls
#: as 1 / sqrt(edge pixels) and the angle's as the path radius in px grows.
CLOSER_THETA_NOISE_FACTOR = 0.41
CLOSER_BETA_NOISE_FACTOR = 0.56


def what_ifs(spec: Any, staircase: Staircase, mus: np.ndarray) -> list[dict[str, Any]]:
    """The predicted width of this staircase after each set-up change that narrows it and
    that rendered runs have checked: a calibrated lens (where the prior is the uncalibrated
    one), a camera twice as close, the staircase stated to ``abu measure`` (drive-model
    kinematics, where the prediction is for the default's), those that narrow it, and all of
    those together. [{"change": what to do, "expected": mean predicted width over ``mus``
    (None where a bound will be null), "constants": the changed width constants}]."""
    from dataclasses import replace

    c = spec.width
    changes = []
    if c.lens_source == "typical" and c.theta_harmonic_rad > CALIBRATED_LENS_PRIOR_RAD:
        changes.append(("a calibrated camera (abu calibrate-camera, then abu measure --camera)",
                        {"theta_harmonic_rad": CALIBRATED_LENS_PRIOR_RAD}))
    changes.append(("a camera twice as close (pixel size / 2, the frame twice as wide; "
                    f"theta's noise x {CLOSER_THETA_NOISE_FACTOR:g}, beta's x "
                    f"{CLOSER_BETA_NOISE_FACTOR:g}, as rendered runs measured)",
                    {"sigma_theta_rad": c.sigma_theta_rad * CLOSER_THETA_NOISE_FACTOR,
                     "sigma_beta_rad": c.sigma_beta_rad * CLOSER_BETA_NOISE_FACTOR}))
    if c.kinematics == "savgol":
        changes.append(("the staircase stated to abu measure (--kinematics drive-model)",
                        {"kinematics": "drive-model"}))

    def predicted(change: dict) -> float:
        w = predict_staircase(replace(spec, width=replace(c, **change)), staircase, mus).expected
        return float(np.mean(w)) if np.isfinite(w).all() else math.inf

    now = predicted({})
    # only what narrows it (the drive model's timing bar widens a staircase whose slips fall
    # on acceleration jumps), then those together
    out = [{"change": label, "expected": e, "constants": change}
           for label, change in changes if (e := predicted(change)) < now]
    if len(out) > 1:
        together = {k: v for o in out for k, v in o["constants"].items()}
        out.append({"change": "all of these", "expected": predicted(together),
                    "constants": together})
    for o in out:   # JSON has no inf: a null bound is None, as in the width table
        o["expected"] = o["expected"] if math.isfinite(o["expected"]) else None
    return out


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
