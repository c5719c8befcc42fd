"""Drive-model kinematics (measurement.kinematics.drive_model): the loop fitted to the whole
record, its error bars, and its refusal when the drive is not the model."""
from __future__ import annotations

import math
import os
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from abu.cli.main import main as abu_main  # noqa: E402
from abu_model.loop_response import Setpoints, modes, response  # noqa: E402
from controller.drive import Drive  # noqa: E402
from measurement.kinematics.drive_model import (DriveModelSettings,  # noqa: E402
                                                fit_drive_model)
from measurement.kinematics.estimators import savgol_kinematics  # noqa: E402

FPS = 4500.0
TWO_PI = 2 * math.pi
SP = Setpoints(tuple(0.03 + 0.045 * k for k in range(10)),
               tuple(-TWO_PI * (9.0 + k) for k in range(11)))
TRUE = dict(zeta=0.8, omega_n=15.0, tau=0.02, weight=0.7)
SIGMA = 1.5e-4          # rad, the tracking noise of theta on the twin


def drive(tau_scale: float = 1.0, ci: dict | None = None) -> Drive:
    return Drive(model="pi-lag-weighted", zeta=TRUE["zeta"], omega_n=TRUE["omega_n"],
                 tau_motor=TRUE["tau"] * tau_scale, setpoint_weight=TRUE["weight"],
                 ci95=ci or {})


def record(seed: int, ripple: float = 0.0):
    """(t, theta measured, true omega_dot) of the loop's exact motion + lens pattern + noise;
    ``ripple``: once-per-turn torque ripple amplitude [rad/s^2] added to the motion."""
    t = np.arange(2400) / FPS
    r = response(SP, t, TRUE["zeta"], TRUE["omega_n"], TRUE["tau"], TRUE["weight"])
    theta = 1.0 + r.theta - ripple * np.sin(r.theta) / r.omega**2
    alpha = r.alpha + ripple * np.sin(r.theta)
    rng = np.random.default_rng(seed)
    lens = 4e-4 * np.cos(r.theta + rng.uniform(0, TWO_PI))       # a fixed camera pattern
    return t, theta + lens + SIGMA * rng.standard_normal(t.size), alpha


def test_poles_are_those_of_python_control():
    control = pytest.importorskip("control")   # third party, a second implementation
    p, _ = modes(0.8, 15.0, 0.02, 0.7)
    ref = control.tf([2 * 0.8 * 15 * 0.7, 225.0], [0.02, 1.0, 24.0, 225.0]).poles()
    assert np.allclose(np.sort_complex(p), np.sort_complex(ref), rtol=1e-12)


def test_exact_model_is_accepted_covered_and_beats_savgol():
    """20 noisy records of the model itself: the fit is accepted in >= 18, its omega_dot
    error is inside 1.96 sigma at >= 90 % of the check times, and 5x below SG's RMS."""
    checks = np.arange(300, 2100, 150)
    inside, err_m, err_sg, accepted = [], [], [], 0
    for seed in range(20):
        t, th, alpha = record(seed)
        fit = fit_drive_model(t, th, drive(1.1), SP, sigma_theta=SIGMA)
        sg = savgol_kinematics(t, th, window_s=0.042, polyorder=9, sigma_theta=SIGMA)
        accepted += fit.accepted
        e = fit.omega_dot[checks] - alpha[checks]
        inside.extend(np.abs(e) <= 1.96 * fit.sigma_omega_dot[checks])
        err_m.extend(e)
        err_sg.extend(sg.omega_dot[checks] - alpha[checks])
    rms_m, rms_sg = np.sqrt(np.mean(np.square(err_m))), np.sqrt(np.mean(np.square(err_sg)))
    print(f"\nexact loop + lens + noise, 20 seeds: accepted {accepted}, coverage "
          f"{np.mean(inside):.0%}, RMS omega_dot model {rms_m:.3f} SG {rms_sg:.3f} rad/s^2")
    assert accepted >= 18
    assert np.mean(inside) >= 0.90
    assert rms_m < 0.2 * rms_sg


@pytest.mark.parametrize("case", ["wrong lag", "ripple"])
def test_drives_the_model_does_not_contain_are_refused_or_covered(case):
    """A lag 30 % off held by a tight interval, or a once-per-turn torque ripple of 10 rad/s^2
    (~5 % of omega_dot): each fit is refused (the SG kinematics are then used, the reason
    given) or its bars cover the true omega_dot at >= 90 % of the check times."""
    checks = np.arange(300, 2100, 150)
    refused = 0
    for seed in range(5):
        if case == "wrong lag":
            t, th, alpha = record(seed)
            d = drive(1.3, {"tau_motor_s": (0.026 * 0.97, 0.026 * 1.03)})
        else:
            t, th, alpha = record(seed, ripple=10.0)
            d = drive()
        fit = fit_drive_model(t, th, d, SP, sigma_theta=SIGMA)
        refused += not fit.accepted
        assert fit.accepted != bool(fit.why)
        if fit.accepted:
            e = np.abs(fit.omega_dot[checks] - alpha[checks])
            assert np.mean(e <= 1.96 * fit.sigma_omega_dot[checks]) >= 0.9, (case, seed)
    print(f"\n{case}: refused {refused} of 5")


def test_turning_the_other_way_is_refused_with_a_reason():
    t, th, _ = record(0)
    fit = fit_drive_model(t, -th, drive(), SP, sigma_theta=SIGMA)
    assert not fit.accepted and "direction" in fit.why


def test_measure_refuses_drive_model_without_a_drive(tmp_path, capsys):
    status = abu_main(["measure", str(tmp_path / "none.csv"), "--tracks", "--out",
                       str(tmp_path / "o"), "--kinematics", "drive-model"])
    assert status == 2
    assert "--drive" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


def test_measure_names_each_bad_staircase_option_and_refuses_them_without_the_model(tmp_path,
                                                                                     capsys):
    drive_json = tmp_path / "drive.json"
    from controller.drive import Drive, dumps_drive
    drive_json.write_text(dumps_drive(Drive("pi-lag", 0.5, 2.2, 0.0)))
    base = ["measure", str(tmp_path / "none.csv"), "--tracks", "--out", str(tmp_path / "o"),
            "--kinematics", "drive-model", "--drive", str(drive_json)]
    stair = {"--omega0-hz": "-9", "--omega-end-hz": "-19", "--te": "0.5"}
    for option, value in [("--step-hz", "0"), ("--step-hz", "nan"), ("--te", "0"),
                          ("--t0", "inf"), ("--omega0-hz", "0"), ("--omega-end-hz", "5")]:
        argv = base + [a for k, v in {**stair, option: value}.items() for a in (k, v)]
        assert abu_main(argv) == 2, option
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and option in err[0], (option, err)
    # the staircase options serve only the drive model: without it they are refused
    assert abu_main(["measure", str(tmp_path / "none.csv"), "--tracks", "--out",
                     str(tmp_path / "o"), "--omega0-hz", "-9"]) == 2
    assert "--kinematics drive-model" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
