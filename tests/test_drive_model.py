"""Drive-model kinematics (measurement.kinematics.drive_model): the loop fitted to the whole
record, its error bars, and its refusal when the drive is not the model."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from abu.cli.main import main as abu_main  # noqa: E402
from abu_model.loop_response import Setpoints, modes, response  # noqa: E402
from controller.drive import Drive  # noqa: E402
from measurement.kinematics.drive_model import fit_drive_model  # noqa: E402
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



def _tally(fit, sg, alpha: np.ndarray, checks, inside: list, err_m: list,
           err_sg: list) -> None:
    """Add one record's omega_dot errors at ``checks`` (model and SG) and whether the model's
    95 % bar holds the truth there."""
    e = fit.omega_dot[checks] - alpha[checks]
    inside.extend(np.abs(e) <= 1.96 * fit.sigma_omega_dot[checks])
    err_m.extend(e)
    err_sg.extend(sg.omega_dot[checks] - alpha[checks])


def _rms(errors: list) -> float:
    return float(np.sqrt(np.mean(np.square(errors))))

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
        _tally(fit, sg, alpha, checks, inside, err_m, err_sg)
    rms_m, rms_sg = _rms(err_m), _rms(err_sg)
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


def test_measure_refuses_drive_model_without_a_reference(tmp_path, capsys):
    """Neither a staircase nor a profile: refused naming the option and what it needs (the
    drive itself may be left to the fit, the reference it followed may not)."""
    status = abu_main(["measure", str(tmp_path / "none.csv"), "--tracks", "--out",
                       str(tmp_path / "o"), "--kinematics", "drive-model"])
    assert status == 2
    err = capsys.readouterr().err
    assert "--kinematics" in err and "--omega0-hz" in err and "--profile" in err
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
    # a controller sampling slower than the steps come (25-130 ms apart) cannot act on each
    drive_json.write_text(dumps_drive(Drive("pi-lag", 0.5, 2.2, 0.0, sample_time=0.05)))
    argv = base + [a for k, v in stair.items() for a in (k, v)]
    assert abu_main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "sample_time_s" in err[0] and "--drive" in err[0], err
    # the staircase options serve only the drive model: without it they are refused
    assert abu_main(["measure", str(tmp_path / "none.csv"), "--tracks", "--out",
                     str(tmp_path / "o"), "--omega0-hz", "-9"]) == 2
    assert "--kinematics drive-model" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()


# ------------------------------------------------- the harsh twin's digital PI with a filter
def _twin_record(seed: int, setpoint_tau: float, tau_motor: float | None = None, *,
                 fps: float = FPS, every: int = 1):
    """(t, theta measured, true omega_dot, DriveSpec, setpoints) of the harsh twin's digital PI
    drive (controller at the frame rate, Euler integrator, first-order-hold torque: an
    implementation independent of the closed form) with lens pattern and tracking noise.
    ``every`` > 1: the controller runs at ``every`` x ``fps`` and the camera films every
    ``every`` th of its samples (the twin's controller samples at its time grid)."""
    from controller.reference import Staircase
    from twin.drives import DriveSpec, rotor_mu_req
    rng = np.random.default_rng([seed, 18])
    spec = DriveSpec(kind="staircase_pi", omega0=-TWO_PI * rng.uniform(6, 12),
                     tau_motor=rng.uniform(0.0, 0.03) if tau_motor is None else tau_motor,
                     t0=rng.uniform(0.0, 0.05),
                     omega_end=-TWO_PI * rng.uniform(20, 26), te=rng.uniform(0.3, 0.7),
                     zeta=rng.uniform(0.6, 1.0), omega_n=rng.uniform(8.0, 30.0),
                     setpoint_weight=rng.uniform(0.5, 1.0), setpoint_tau=setpoint_tau,
                     rounding=str(rng.choice(["lead", "nearest", "trail"])))
    t = np.arange(2400) / fps
    r = {k: v[::every] for k, v in rotor_mu_req(spec, np.arange(2400 * every) / (fps * every)
                                                ).items()}
    lens = 4e-4 * np.cos(r["theta"] + rng.uniform(0, TWO_PI))
    theta = 1.0 + r["theta"] + lens + SIGMA * rng.standard_normal(t.size)
    stair = Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te, rounding=spec.rounding)
    return t, theta, r["alpha"], spec, Setpoints(stair.step_times, stair.levels)


def _declared(spec, filtered: bool, digital: bool) -> Drive:
    return Drive(model="pi-lag-weighted", zeta=spec.zeta, omega_n=spec.omega_n,
                 tau_motor=max(spec.tau_motor, 1e-5), setpoint_weight=spec.setpoint_weight,
                 setpoint_tau=spec.setpoint_tau if filtered else 0.0,
                 sample_time=1.0 / FPS if digital else None)


def test_setpoint_filter_response_matches_python_control():
    control = pytest.importorskip("control")   # third party, a second implementation
    from harness.planning.loop_response import loop_tf
    sp = Setpoints((0.1, 0.25), (3.0, 10.0, 4.0))
    t = np.linspace(0.0, 1.0, 100001)  # steps on the grid: forced_response is exact there
    u = sp.value(t)
    for zeta, wn, tau, b, tau_f in [(0.7, 12.0, 0.02, 0.6, 0.015), (0.9, 25.0, 0.0, 1.0, 0.003)]:
        fr = control.forced_response(loop_tf(zeta, wn, tau, b, tau_f), T=t, U=u - u[0])
        r = response(sp, t, zeta, wn, tau, b, setpoint_tau=tau_f)
        assert np.max(np.abs(fr.outputs + u[0] - r.omega)) < 2e-3 * np.ptp(u)
        # the filter changes the response by far more than that
        assert np.max(np.abs(response(sp, t, zeta, wn, tau, b).omega - r.omega)) > 0.05 * np.ptp(u)


def test_setpoint_filter_on_another_pole_is_split_and_stays_accurate():
    """tau_f on one of the loop's real poles (a double pole: zeta > 1, or the torque lag's pole)
    and on the double pole of zeta = 1 (a triple one): modes() must split them (residues are
    finite) and the response must match an independent exact solver, SciPy's state-space
    zero-order hold (exact for steps on the grid), to 1e-4 of the setpoint's range in omega
    and of |alpha|'s peak (measured: <= 1.3e-5, vs 1e-13 for distinct poles)."""
    from scipy import signal

    from abu_model.loop_response import loop_polynomials
    sp = Setpoints((0.1, 0.25), (3.0, 10.0, 4.0))
    t = np.linspace(0.0, 1.0, 20001)
    u = sp.value(t) - 3.0
    slow, fast = np.sort(np.roots([1.0, 2 * 1.5 * 20.0, 400.0]).real)[::-1]
    lag = np.roots([0.02, 1.0, 2 * 0.7 * 12.0, 144.0])
    lag = float(lag[np.abs(lag.imag) < 1e-9].real[0])
    for zeta, wn, tau, b, tau_f in [(1.5, 20.0, 0.0, 1.0, -1 / slow),
                                    (1.5, 20.0, 0.0, 1.0, -1 / fast),
                                    (0.7, 12.0, 0.02, 0.6, -1 / lag),
                                    (1.0, 20.0, 0.0, 1.0, 1 / 20.0),
                                    (1.0, 20.0, 0.0, 0.7, 1 / 20.0)]:
        poles, res = modes(zeta, wn, tau, b, tau_f)
        assert np.all(np.isfinite(res)) and np.min(np.abs(np.diff(np.sort_complex(poles)))) > 0
        a, bb, c, d = signal.tf2ss(*loop_polynomials(zeta, wn, tau, b, tau_f))
        _, y, x = signal.lsim((a, bb, c, d), u, t, interp=False)
        alpha = (c @ a @ x.T).ravel()          # relative degree >= 2: no feed-through in w'
        r = response(sp, t, zeta, wn, tau, b, setpoint_tau=tau_f)
        assert np.max(np.abs(y + 3.0 - r.omega)) < 1e-4 * np.ptp(u), (zeta, tau, tau_f)
        assert np.max(np.abs(alpha - r.alpha)) < 1e-4 * np.max(np.abs(alpha)), (zeta, tau, tau_f)


def test_steps_on_one_controller_sample_merge_and_keep_the_step_locked_test():
    """Two steps within one sample time of the controller act at the same sample: sampled()
    gives one step to the later level (same response), so the step-locked whiteness test keeps
    its window (a zero gap between steps used to cut it to nothing, silently)."""
    from abu_model.loop_response import sampled
    from measurement.kinematics.drive_model import LoopModel
    from measurement.kinematics.model_fit import DriveModelSettings
    sp = Setpoints((0.0101, 0.0105, 0.03, 0.05, 0.07), (0.0, 1.0, 2.0, 3.0, 4.0, 5.0))
    merged = sampled(sp, 1e-3)
    assert np.allclose(merged.step_times, (0.011, 0.03, 0.05, 0.07))
    assert merged.levels == (0.0, 2.0, 3.0, 4.0, 5.0)
    t = np.arange(1000) / 1000.0
    raw = Setpoints((0.011, 0.011, 0.03, 0.05, 0.07), sp.levels)   # the old, unmerged form
    assert np.allclose(response(merged, t, 0.7, 12.0).theta, response(raw, t, 0.7, 12.0).theta,
                       rtol=0, atol=1e-12)
    model = LoopModel(t, Drive("pi-lag", 0.7, 12.0, 0.02, sample_time=1e-3), sp,
                   DriveModelSettings())
    frames, window = model.step_frames(np.asarray(model.x0))
    assert frames.tolist() == [11, 30, 50, 70] and window == 16


def test_digital_twin_drive_with_its_filter_and_sample_time_is_accepted():
    """12 records of the harsh twin's digital PI (8 with a 2-20 ms setpoint filter): declared
    with its filter and sample time, the fit (loop fitted freely) is accepted in >= 10, its
    omega_dot error is inside 1.96 sigma at >= 90 % of the check times and 5x below SG's RMS;
    declared as the continuous loop without the filter it is refused in >= 10 (the residual is
    not white: the behaviour before these fields existed)."""
    checks = np.arange(300, 2100, 150)
    acc_new = acc_old = 0
    inside, err_m, err_sg = [], [], []
    for seed in range(12):
        t, th, alpha, spec, sp = _twin_record(seed, 0.0 if seed % 3 == 0 else
                                              0.002 + 0.0015 * seed)
        fit = fit_drive_model(t, th, _declared(spec, True, True), sp, sigma_theta=SIGMA)
        old = fit_drive_model(t, th, _declared(spec, False, False), sp, sigma_theta=SIGMA)
        sg = savgol_kinematics(t, th, window_s=0.042, polyorder=9, sigma_theta=SIGMA)
        acc_new += fit.accepted
        acc_old += old.accepted
        _tally(fit, sg, alpha, checks, inside, err_m, err_sg)
    rms_m, rms_sg = _rms(err_m), _rms(err_sg)
    print(f"\ntwin's digital PI, 12 records: accepted {acc_new} (continuous, no filter: "
          f"{acc_old}), coverage {np.mean(inside):.0%}, RMS omega_dot model {rms_m:.3f} SG "
          f"{rms_sg:.3f} rad/s^2")
    assert acc_new >= 10
    assert acc_old <= 2
    assert np.mean(inside) >= 0.90
    assert rms_m < 0.2 * rms_sg


def test_a_filter_the_drive_file_does_not_declare_is_refused_or_covered():
    """The twin's drive with a 10 ms setpoint filter, declared digital but without it (a drive
    the model does not contain): each fit is refused with the reason, or its bars cover the
    true omega_dot at >= 90 % of the check times."""
    checks = np.arange(300, 2100, 150)
    refused = 0
    for seed in range(5):
        t, th, alpha, spec, sp = _twin_record(100 + seed, 0.01)
        fit = fit_drive_model(t, th, _declared(spec, False, True), sp, sigma_theta=SIGMA)
        refused += not fit.accepted
        assert fit.accepted != bool(fit.why)
        if fit.accepted:
            e = np.abs(fit.omega_dot[checks] - alpha[checks])
            assert np.mean(e <= 1.96 * fit.sigma_omega_dot[checks]) >= 0.9, seed
    print(f"\nundeclared 10 ms setpoint filter: refused {refused} of 5")


def test_omega_dot_after_the_steps_of_a_short_lag_has_an_honest_bar():
    """A 0.3 ms torque lag (omega_dot jumps within ~1 frame at each step; a lag that short and a
    delay look alike in theta, so the fit may place the step a frame early): over the frames
    from one before to 19 after each step the model's bar covers the true omega_dot in >= 93 %
    (without the timing term of ``LoopModel.step_sigma`` the jump frames err by up to ~100 %)."""
    inside, worst = [], []
    for seed in range(4):
        t, th, alpha, spec, sp = _twin_record(200 + seed, 0.0, tau_motor=0.0003)
        fit = fit_drive_model(t, th, _declared(spec, False, True), sp, sigma_theta=SIGMA)
        assert fit.accepted, fit.why
        for k in np.ceil(np.asarray(sp.step_times) * FPS - 1e-9).astype(int):
            for j in range(k - 1, min(k + 20, t.size)):
                ok = abs(fit.omega_dot[j] - alpha[j]) <= 1.96 * fit.sigma_omega_dot[j] + 1e-9
                inside.append(ok)
                if j <= k + 2:
                    worst.append(ok)
    print(f"\n0.3 ms lag: inside the 95 % bar {np.mean(inside):.1%} of the frames after the "
          f"steps, {np.mean(worst):.0%} of the 4 frames around them")
    assert np.mean(inside) >= 0.93


def test_drive_file_filter_and_sample_time_fields(tmp_path):
    from controller.drive import DriveFileError, drive_from_dict, dumps_drive, load_drive
    d = Drive("pi-lag-weighted", 0.7, 12.0, 0.02, 0.8, setpoint_tau=0.01, sample_time=1e-3,
              ci95={"setpoint_tau_s": (0.005, 0.02)})
    (tmp_path / "d.json").write_text(dumps_drive(d))
    back = load_drive(tmp_path / "d.json")
    assert (back.setpoint_tau, back.sample_time, back.ci95["setpoint_tau_s"]) == \
        (0.01, 1e-3, (0.005, 0.02))
    plain = Drive("pi-lag", 0.7, 12.0, 0.02).to_dict()   # absent: none, continuous
    assert "setpoint_tau_s" not in plain and "sample_time_s" not in plain
    assert (drive_from_dict(plain).setpoint_tau, drive_from_dict(plain).sample_time) == (0.0, None)
    good = d.to_dict()
    # null is absent, for every optional field alike (no filter, a continuous controller)
    nulls = drive_from_dict({**good, "setpoint_tau_s": None, "sample_time_s": None}, "x.json")
    assert (nulls.setpoint_tau, nulls.sample_time) == (0.0, None)
    assert nulls.has_setpoint_filter      # its interval alone still declares the filter
    for change, name in [({"setpoint_tau_s": -0.01}, "setpoint_tau_s"),
                         ({"setpoint_tau_s": True}, "setpoint_tau_s"),
                         ({"setpoint_tau_s": 5.0}, "setpoint_tau_s"),
                         ({"sample_time_s": 0.0}, "sample_time_s"),
                         ({"sample_time_s": "1 ms"}, "sample_time_s"),
                         ({"setpoint_tau_s": float("nan")}, "setpoint_tau_s"),
                         ({"setpoint_tau_s": float("inf")}, "setpoint_tau_s"),
                         ({"sample_time_s": -1e-3}, "sample_time_s"),
                         ({"sample_time_s": float("nan")}, "sample_time_s"),
                         ({"sample_time_s": 1e300}, "sample_time_s"),
                         ({"setpoint_tau_s_ci95": [0.02, 0.01]}, "setpoint_tau_s_ci95"),
                         ({"setpoint_tau_s_ci95": [-0.01, 0.02]}, "setpoint_tau_s_ci95"),
                         ({"setpoint_tau_s_ci95": [0.01, 1e300]}, "setpoint_tau_s_ci95"),
                         ({"setpoint_tau_s_ci95": [0.01, float("inf")]}, "setpoint_tau_s_ci95")]:
        with pytest.raises(DriveFileError, match=name):
            drive_from_dict({**good, **change}, "x.json")
    tracking = {"kind": "abu-drive", "format_version": 1, "model": "tracking",
                "bandwidth_rad_s": 150.0}
    for name in ("setpoint_tau_s", "sample_time_s"):
        with pytest.raises(DriveFileError, match=name):
            drive_from_dict({**tracking, name: 0.01}, "t.json")


def test_simulate_refuses_a_drive_with_a_filter_or_a_sample_time(tmp_path, capsys):
    for name, kw in (("setpoint_tau_s", {"setpoint_tau": 0.01}),
                     ("setpoint_tau_s", {"ci95": {"setpoint_tau_s": (0.005, 0.02)}}),
                     ("sample_time_s", {"sample_time": 1e-3})):
        from controller.drive import dumps_drive
        (tmp_path / "f.json").write_text(dumps_drive(Drive("pi-lag", 0.7, 12.0, 0.02, **kw)))
        assert abu_main(["simulate", "--drive", str(tmp_path / "f.json")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and name in err[0]


def test_unseen_miss_5078_holds_with_the_drive_model(tmp_path, capsys):
    """Rendered end to end (harsh twin, unseen seed 5078: a staircase on a digital PI with a
    1.6 ms torque lag and a 9 ms setpoint filter; mu = 0.00803). With the default kinematics
    the interval misses mu by ~30 % (the last miss of the unseen slices that two lighting
    models do not mend); `--kinematics drive-model` with the drive's loop, filter and sample
    time (what `abu identify` and the run's plan give a user) is accepted and holds it."""
    import json

    from rendered_seed import render_and_measure

    one, mu = render_and_measure(5078, tmp_path)
    assert one["mu_low"] > 1.02 * mu                       # the miss the drive model mends
    meta = json.loads((tmp_path / "rec" / "meta.json").read_text())
    d = meta["drive"]
    assert d["kind"] == "staircase_pi"
    drive = Drive(model="pi-lag-weighted", zeta=d["zeta"], omega_n=d["omega_n_rad_s"],
                  tau_motor=d["tau_motor_s"], setpoint_weight=d["setpoint_weight"],
                  setpoint_tau=d["setpoint_tau_s"], sample_time=meta["frame_interval_s"])
    (tmp_path / "drive.json").write_text(json.dumps(drive.to_dict()))
    model, _ = render_and_measure(
        5078, tmp_path, "--kinematics", "drive-model", "--drive", str(tmp_path / "drive.json"),
        "--omega0-hz", repr(d["omega0_hz"]), "--omega-end-hz", repr(d["omega_end_hz"]),
        "--t0", repr(d["t0_s"]), "--te", repr(d["te_s"]),
        "--step-hz", repr(d["step_rad_s"] / (2 * np.pi)), "--rounding", d["rounding"])
    print(f"\nseed 5078, mu {mu:.5f}: default [{one['mu_low']:.5f}, {one['mu_high']:.5f}], "
          f"drive model [{model['mu_low']:.5f}, {model['mu_high']:.5f}] "
          f"({model['estimator']['model']})")
    assert model["estimator"]["model"] == "accepted"
    assert model["mu_low"] <= mu <= model["mu_high"]
    assert model["relative_width"] < 0.5


def test_a_fit_whose_kinematics_are_not_finite_is_refused():
    """``fit_model`` refuses a fit whose own omega_dot is not finite (an unstable trial loop
    overflows), and NumPy's overflow warnings stay inside it. The model: theta fitted exactly
    by a free speed, its omega_dot overflowing where the data end."""
    import warnings
    from types import SimpleNamespace

    from measurement.kinematics.model_fit import DriveModelSettings, fit_model

    t = np.arange(400) / 4500.0
    rng = np.random.default_rng(3)
    th = 30.0 * t + 0.5 * t**2 + 1e-4 * rng.standard_normal(t.size)

    def evaluate(p, need_theta=True):
        alpha = np.full(t.size, p[0])
        alpha[-1] = np.exp(1e3) * p[0]            # overflows: inf
        return 0.5 * p[0] * t**2, 30.0 + p[0] * t, alpha

    model = SimpleNamespace(names=("a",), x0=(0.3,), lo=(-10.0,), hi=(10.0,), prior=(),
                            evaluate=evaluate, t=t)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fit = fit_model(t, th, model, 1e-4, DriveModelSettings(check_white=False))
    assert not fit.accepted and "not finite" in fit.why
    # the same model without the overflow is accepted: the refusal is the overflow's
    model.evaluate = lambda p, need_theta=True: (0.5 * p[0] * t**2, 30.0 + p[0] * t,
                                                 np.full(t.size, p[0]))
    assert fit_model(t, th, model, 1e-4, DriveModelSettings(check_white=False)).accepted


def test_a_fit_whose_covariance_cannot_be_computed_is_refused_not_raised(monkeypatch):
    """A loop at the edge of stability can leave non-finite output derivatives; the SVD of
    the information matrix then fails (seen in a free fit of a rendered record: LinAlgError
    "SVD did not converge" reached the caller). Now a refusal with the reason."""
    from types import SimpleNamespace

    from measurement.kinematics import model_fit as dm

    t = np.arange(400) / 4500.0
    th = 30.0 * t + 0.5 * t**2 + 1e-4 * np.random.default_rng(3).standard_normal(t.size)
    model = SimpleNamespace(names=("a",), x0=(0.3,), lo=(-10.0,), hi=(10.0,), prior=(), t=t,
                            evaluate=lambda p, need_theta=True: (
                                0.5 * p[0] * t**2, 30.0 + p[0] * t, np.full(t.size, p[0])))
    settings = dm.DriveModelSettings(check_white=False)
    assert dm.fit_model(t, th, model, 1e-4, settings).accepted
    nan = np.full((t.size, 1), np.nan)
    monkeypatch.setattr(dm, "output_jacobian", lambda m, p: (nan, nan, nan))
    fit = dm.fit_model(t, th, model, 1e-4, settings)
    assert not fit.accepted and "covariance" in fit.why
