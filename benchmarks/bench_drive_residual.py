"""Why the drive model's residual was not white on the harsh twin's staircase drives: each
cause switched off in the twin, or added to the model, one at a time.

The twin's ``staircase_pi`` drive (``twin/drives.py``) is a *digital* PI at the frame rate
(4500 Hz: steps seen at the next sample, forward-Euler integrator, first-order-hold torque)
with a torque lag, setpoint weighting and, in 60 % of the drives, a first-order setpoint filter.
For the first ``--n`` staircase seeds from ``--first`` of ``twin.scenario.random_scenario``, the
rotor's exact theta (``twin.drives.rotor_mu_req``) gets white noise of 1.5e-4 rad (the camera's
fixed pattern is left out: with harmonics 1-3 fitted it leaves a white residual) and the drive
model (``measurement.kinematics.drive_model``, the true staircase) is fitted with the loop's
parameters free. Printed per case: how many fits pass the whiteness test, the median residual
rms / noise, and omega_dot's error at the slip (median and largest |error|), for

* the twin as it is, the continuous model without a filter (the model before drive.json's
  ``setpoint_tau_s`` and ``sample_time_s``);
* the twin without its filter (same model): what the digital controller alone does;
* the twin without filter, its controller 20x faster (near-continuous);
* the twin without filter, the model with the steps on the controller's samples;
* the twin as it is, the model with the filter and the steps on the samples;
* the same, the loop's parameters held at the truth (tight intervals): the forward-Euler
  integrator, which shifts zeta by about omega_n h / 4, is then left in the residual.

Run::

    nice python benchmarks/bench_drive_residual.py --first 0 --n 12
"""
from __future__ import annotations

import argparse
import os
import sys
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from abu_model.loop_response import as_setpoints  # noqa: E402
from controller.drive import Drive  # noqa: E402
from controller.reference import Staircase  # noqa: E402
from measurement.kinematics.drive_model import fit_drive_model  # noqa: E402
from twin.drives import rotor_mu_req  # noqa: E402
from twin.scenario import random_scenario  # noqa: E402

SIGMA = 1.5e-4      # rad, tracking noise of theta
FAST = 20           # the near-continuous controller samples this many times per frame

CASES = ("twin as is, continuous model", "no filter, continuous model",
         "no filter, 20x faster controller", "no filter, steps on the samples",
         "twin as is, filter + steps on the samples", "same, loop held at the truth")


def _drive(spec, filtered: bool, h: float | None, held: bool) -> Drive:
    values = {"zeta": spec.zeta, "omega_n_rad_s": spec.omega_n,
              "tau_motor_s": max(spec.tau_motor, 1e-5), "setpoint_weight": spec.setpoint_weight}
    tau_f = spec.setpoint_tau if filtered else 0.0
    if tau_f > 0:
        values["setpoint_tau_s"] = tau_f
    ci = {k: (v * (1 - 1e-6), v * (1 + 1e-6)) for k, v in values.items()} if held else {}
    return Drive(model="pi-lag-weighted", zeta=spec.zeta, omega_n=spec.omega_n,
                 tau_motor=values["tau_motor_s"], setpoint_weight=spec.setpoint_weight,
                 setpoint_tau=tau_f, sample_time=h, ci95=ci)


def one(seed: int) -> dict | None:
    scn = random_scenario(seed, n_frames=2400)
    spec, t = scn.drive, scn.times
    if spec.kind != "staircase_pi":
        return None
    h = float(t[1] - t[0])
    sp = as_setpoints(Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te, step=spec.step,
                                rounding=spec.rounding))
    plain = replace(spec, setpoint_tau=0.0)
    as_is, no_filter = rotor_mu_req(spec, t), rotor_mu_req(plain, t)
    fast = {k: v[::FAST] for k, v in rotor_mu_req(plain, np.arange(t.size * FAST) * h / FAST)
            .items()}
    i = int(np.argmax(as_is["mu_req"] > scn.ball.mu))     # the slip (the rotor alone)
    noise = SIGMA * np.random.default_rng([seed, 5]).standard_normal(t.size)
    runs = dict(zip(CASES, (
        (as_is, _drive(spec, False, None, False)), (no_filter, _drive(spec, False, None, False)),
        (fast, _drive(spec, False, None, False)), (no_filter, _drive(spec, False, h, False)),
        (as_is, _drive(spec, True, h, False)), (as_is, _drive(spec, True, h, True)))))
    row = {"seed": seed, "filter": spec.setpoint_tau > 0}
    for name, (truth, drive) in runs.items():
        fit = fit_drive_model(t, truth["theta"] + noise, drive, sp, sigma_theta=SIGMA)
        white = all(p >= 0.001 / len(fit.block_p) for p in fit.block_p.values())
        row[name] = (white, fit.rms_ratio, fit.omega_dot[i] - truth["alpha"][i])
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--n", type=int, default=12, help="staircase recordings")
    a = ap.parse_args()
    rows, seed = [], a.first
    while len(rows) < a.n:
        row = one(seed)
        seed += 1
        if row is not None:
            rows.append(row)
    n_f = sum(r["filter"] for r in rows)
    print(f"harsh twin's staircase drives, seeds {a.first}..{seed - 1}: {len(rows)} recordings "
          f"({n_f} with a setpoint filter), rotor theta + {SIGMA:g} rad white noise, loop free")
    print(f"  {'case':44s} {'white':>8s} {'rms/noise':>10s} {'|err| at slip: median':>22s} "
          f"{'max':>7s} rad/s^2")
    for name in CASES:
        white = sum(r[name][0] for r in rows)
        rms = np.median([r[name][1] for r in rows])
        err = np.abs([r[name][2] for r in rows])
        print(f"  {name:44s} {white:3d} of {len(rows):2d} {rms:10.2f} {np.median(err):22.3f} "
              f"{err.max():7.3f}")


if __name__ == "__main__":
    main()
