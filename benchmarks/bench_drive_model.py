"""Drive-model kinematics against the default Savitzky-Golay ones, at the tracks level.

The staircase drives of the harsh family (``twin.scenario.random_scenario(seed)``, kind
``staircase_pi``: a digital PI loop at the frame rate with torque lag, setpoint weighting
and, in 60 % of them, a setpoint filter), tracks as in
``tests/test_inference.py::scenario_tracks`` (camera geometry, lens, white tracking noise,
lighting shift of the ball). The drive model is given the true loop parameters as drive.json
(no intervals: all fitted freely), with the drive's setpoint filter (``setpoint_tau_s``, where
it has one) and its controller's sample time (``sample_time_s`` = the frame interval), and the
true staircase; ``--continuous`` leaves the last two out (the model before they existed).
Printed:

* omega_dot error at the true slip (first stick -> slip frame): RMS for SG and the model,
  and the share of errors inside the stated 95 % bar (2 sigma + bias bound);
* how often the whiteness test refuses the model (and why);
* the interval on mu (``analyse_tracks``): coverage, median relative width, for the default,
  the drive model as specified (refused fits fall back to SG), the drive model with a relative
  discrepancy floor ``--error-rel`` on omega_dot instead of the default 1 %, and the exact
  kinematics (the plant's omega and omega_dot with ~0 bars, as ``bench_width_floor.py``: the
  floor no kinematic estimator can beat);
* wrong drives: the lag in drive.json 30 % off with a tight 95 % interval (+-3 %), and a
  once-per-turn torque ripple (amplitude ``--ripple`` x |omega_dot| at the slip) added to the
  motion: share refused and, of the accepted, share covered.

Run::

    nice python benchmarks/bench_drive_model.py --first 0 --n 60
"""
from __future__ import annotations

import argparse
import os
import sys
import time as _time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]

import numpy as np  # noqa: E402

from abu_model.loop_response import as_setpoints  # noqa: E402
from controller.drive import Drive  # noqa: E402
from controller.reference import Staircase  # noqa: E402
from measurement.imaging import tracks_io  # noqa: E402
from measurement.imaging.geometry import fixed_axis  # noqa: E402
from measurement.inference import analysis  # noqa: E402
from measurement.inference.analysis import AnalysisOptions, _estimator, analyse_tracks  # noqa
from measurement.kinematics.drive_model import DriveModelInput, fit_drive_model  # noqa: E402
from measurement.kinematics.model_fit import DriveModelSettings  # noqa: E402
from test_inference import scenario_tracks  # noqa: E402
from twin.scenario import random_scenario  # noqa: E402


#: The twin's controller samples at the frame rate (``--continuous``: None, no filter).
SAMPLE_TIME: list[float | None] = [1.0 / 4500.0]


def drive_of(spec, tau_scale: float = 1.0, tau_ci_rel: float | None = None) -> Drive:
    tau = spec.tau_motor * tau_scale
    ci = {} if tau_ci_rel is None else {"tau_motor_s": (tau * (1 - tau_ci_rel),
                                                        tau * (1 + tau_ci_rel))}
    digital = SAMPLE_TIME[0] is not None
    return Drive(model="pi-lag-weighted", zeta=spec.zeta, omega_n=spec.omega_n,
                 tau_motor=max(tau, 1e-5), setpoint_weight=spec.setpoint_weight, ci95=ci,
                 setpoint_tau=spec.setpoint_tau if digital else 0.0,
                 sample_time=SAMPLE_TIME[0])


def setpoints_of(spec):
    return as_setpoints(Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te,
                                  step=spec.step, rounding=spec.rounding))


def covered(err: float, sd: float, bias: float = 0.0) -> bool:
    return abs(err) <= 1.96 * sd + bias


def one(seed: int, error_rel: float, ripple: float) -> dict | None:
    scn = random_scenario(seed, n_frames=2400)
    spec = scn.drive
    if spec.kind != "staircase_pi":
        return None
    times, x, y, ball, state = scenario_tracks(seed)
    theta, _ = tracks_io.angles_from_pixels(*fixed_axis(x, y))
    i = int(np.argmax(state["mode"] != 0)) if np.any(state["mode"] != 0) else times.size // 2
    alpha = float(state["alpha"][i])
    sg = _estimator(times, theta, AnalysisOptions())
    sp = setpoints_of(spec)
    row = {"seed": seed, "filter": spec.setpoint_tau > 0, "alpha": alpha,
           "sg_err": sg.omega_dot[i] - alpha,
           "sg_cov": covered(sg.omega_dot[i] - alpha, sg.sigma_omega_dot[i],
                             sg.bias_omega_dot[i])}
    c0 = _time.process_time()
    fit = fit_drive_model(times, theta, drive_of(spec), sp, sigma_theta=sg.sigma_theta,
                          settings=DriveModelSettings(error_rel=error_rel, check_white=False))
    row["cpu_s"] = _time.process_time() - c0
    row.update(model_err=fit.omega_dot[i] - alpha, accepted_rms=fit.accepted,
               white=all(p >= 0.001 / len(fit.block_p) for p in fit.block_p.values()),
               model_cov=covered(fit.omega_dot[i] - alpha, fit.sigma_omega_dot[i]))
    # wrong lag: 30 % off, held by a tight interval
    bad = fit_drive_model(times, theta, drive_of(spec, 1.3, 0.03), sp, sigma_theta=sg.sigma_theta,
                          settings=DriveModelSettings(error_rel=error_rel))
    row.update(lag_acc=bad.accepted, lag_cov=covered(bad.omega_dot[i] - alpha,
                                                     bad.sigma_omega_dot[i]))
    # once-per-turn torque ripple: alpha + A sin(theta), theta - A sin(theta) / omega^2
    amp = ripple * abs(alpha)
    th_true = state["theta"]
    rip_theta = theta - amp * np.sin(th_true) / state["omega"] ** 2
    alpha_r = alpha + amp * np.sin(th_true[i])
    rf = fit_drive_model(times, rip_theta, drive_of(spec), sp, sigma_theta=sg.sigma_theta,
                         settings=DriveModelSettings(error_rel=error_rel))
    row.update(rip_acc=rf.accepted, rip_cov=covered(rf.omega_dot[i] - alpha_r,
                                                     rf.sigma_omega_dot[i]))
    # intervals
    mu = ball.mu
    measured = analysis._kinematics
    for name, opt in (
            ("savgol (default)", AnalysisOptions()),
            ("drive-model, as specified", AnalysisOptions(
                kinematics="drive-model", drive_model=DriveModelInput(drive_of(spec), sp))),
            (f"drive-model, floor {error_rel:g}", AnalysisOptions(
                kinematics="drive-model", drive_model=DriveModelInput(
                    drive_of(spec), sp, DriveModelSettings(error_rel=error_rel)))),
            ("exact kinematics", None)):
        if opt is None:   # the plant's motion, as bench_width_floor.py's oracle
            from bench_width_floor import exact_kinematics
            analysis._kinematics, opt = exact_kinematics(state), AnalysisOptions()
        try:
            _, s = analyse_tracks(times, x, y, l=ball.l, d=ball.d, options=opt)
        finally:
            analysis._kinematics = measured
        lo, hi = s["mu_low"], s["mu_high"]
        row[name] = ((lo is None or lo <= mu) and (hi is None or mu <= hi), s["relative_width"],
                     s["estimator"].get("model"))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--n", type=int, default=60)
    ap.add_argument("--error-rel", type=float, default=0.02,
                    help="relative discrepancy floor on the model's omega_dot [-]")
    ap.add_argument("--ripple", type=float, default=0.1,
                    help="torque ripple amplitude / |omega_dot| at the slip [-]")
    ap.add_argument("--continuous", action="store_true",
                    help="drive.json without setpoint_tau_s and sample_time_s")
    a = ap.parse_args()
    if a.continuous:
        SAMPLE_TIME[0] = None
    rows = [r for r in (one(s, a.error_rel, a.ripple) for s in range(a.first, a.first + a.n))
            if r is not None]
    n = len(rows)
    col = lambda k: np.array([r[k] for r in rows], float)  # noqa: E731
    rel = np.abs(col("model_err") / col("alpha"))
    declared = ", continuous" if a.continuous else ", its setpoint filter and sample time"
    print(f"staircase drives of the harsh family, tracks level, seeds {a.first}.."
          f"{a.first + a.n - 1}: {n} recordings ({int(col('filter').sum())} with a setpoint "
          f"filter); drive.json = the true loop (fitted freely){declared}, discrepancy floor "
          f"{a.error_rel:g}")
    print(f"  omega_dot error at the slip: RMS SG {np.sqrt(np.mean(col('sg_err') ** 2)):.2f}, "
          f"model {np.sqrt(np.mean(col('model_err') ** 2)):.2f} rad/s^2; median |err| SG "
          f"{np.median(np.abs(col('sg_err'))):.2f}, model {np.median(np.abs(col('model_err'))):.2f};"
          f" model |err|/|omega_dot| 50/90/max {100 * np.median(rel):.1f}/"
          f"{100 * np.percentile(rel, 90):.1f}/{100 * rel.max():.1f} %")
    print(f"  inside the stated 95 % bar: SG {100 * col('sg_cov').mean():.0f} %, model "
          f"{100 * col('model_cov').mean():.0f} %; model residual white (p >= 0.001): "
          f"{int(col('white').sum())} of {n}; rms gate passed {int(col('accepted_rms').sum())}"
          f"; model CPU {np.median(col('cpu_s')):.2f} s median a fit")
    lag_acc, rip_acc = col("lag_acc").astype(bool), col("rip_acc").astype(bool)
    print(f"  wrong lag (x1.3, +-3 %): refused {int((~lag_acc).sum())} of {n}, accepted and "
          f"covered {int((lag_acc & col('lag_cov').astype(bool)).sum())} of "
          f"{int(lag_acc.sum())}; ripple {a.ripple:g} x |omega_dot|: refused "
          f"{int((~rip_acc).sum())} of {n}, accepted and covered "
          f"{int((rip_acc & col('rip_cov').astype(bool)).sum())} of {int(rip_acc.sum())}")
    for name in [k for k in rows[0] if k.startswith(("savgol", "drive-model", "exact"))]:
        inside = [r[name][0] for r in rows]
        widths = [r[name][1] for r in rows if r[name][1] is not None]
        used = sum(r[name][2] == "accepted" for r in rows)
        both = [(r[name][1], r["exact kinematics"][1]) for r in rows
                if r[name][1] is not None and r["exact kinematics"][1] is not None]
        ratio = np.median([w for w, _ in both]) / np.median([e for _, e in both]) \
            if both else np.nan
        print(f"  {name:30s} coverage {100 * np.mean(inside):5.1f} %, median width "
              f"{100 * np.median(widths):5.1f} % ({ratio:.2f}x exact on the {len(both)} with "
              f"both finite), finite {len(widths)} of {n}, model used {used}")


if __name__ == "__main__":
    main()
