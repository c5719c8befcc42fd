"""The tracking drive of the report's chapter 6: drive.json model 'tracking', profile.json, the
loop's exact response, the twin's drive, the profile-model kinematics, and the commands
(design -> render -> measure) end to end."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.interpolate import CubicSpline

from abu.cli.main import main as abu_main
from abu_model.tracking_response import reference, response
from abu_model.params import BallParams
from controller.drive import Drive, DriveFileError, drive_from_dict
from controller.profile import Profile, ProfileFileError, profile_from_dict
from measurement.kinematics.profile_model import fit_profile_model

TWO_PI = 2 * math.pi
FPS = 4500.0
KNOTS_T = (0.05, 0.1, 0.2, 0.3, 0.4, 0.5)
KNOTS_W = (-200.0, -198.0, -170.0, -120.0, -90.0, -85.0)
PROFILE = Profile(KNOTS_T, KNOTS_W)
TRACKING = {"kind": "abu-drive", "format_version": 1, "model": "tracking",
            "bandwidth_rad_s": 150.0, "bandwidth_rad_s_ci95": [135.0, 165.0],
            "tau_motor_s": 0.005}


# ------------------------------------------------------------------------------ schemas
def test_tracking_drive_round_trips():
    d = drive_from_dict(TRACKING)
    assert d.is_tracking and d.bandwidth == 150.0 and d.tau_motor == 0.005
    assert d.ci95 == {"bandwidth_rad_s": (135.0, 165.0)}
    again = drive_from_dict(json.loads(json.dumps(d.to_dict())))
    assert again.bandwidth == d.bandwidth and again.ci95 == d.ci95
    assert "zeta" not in d.to_dict()


@pytest.mark.parametrize("change, field", [
    ({"bandwidth_rad_s": None}, "bandwidth_rad_s"),          # removed below
    ({"bandwidth_rad_s": -3.0}, "bandwidth_rad_s"),
    ({"bandwidth_rad_s": "150"}, "bandwidth_rad_s"),
    ({"bandwidth_rad_s": True}, "bandwidth_rad_s"),
    ({"zeta": 0.7}, "zeta"),
    ({"omega_n_rad_s": 12.0}, "omega_n_rad_s"),
    ({"setpoint_weight": 1.0}, "setpoint_weight"),
    ({"theta_ref_mode": "integral"}, "theta_ref_mode"),
    ({"tau_motor_s": -0.01}, "tau_motor_s"),
    ({"bandwidth_rad_s_ci95": [170.0, 130.0]}, "bandwidth_rad_s_ci95"),
    ({"model": "tracker"}, "model"),
])
def test_bad_tracking_drive_fields_are_refused_by_name(change, field):
    obj = {**TRACKING, **change}
    if change.get("bandwidth_rad_s", 0) is None:
        del obj["bandwidth_rad_s"]
    with pytest.raises(DriveFileError) as exc:
        drive_from_dict(obj, "d.json")
    assert exc.value.field == field and f"field '{field}'" in str(exc.value)


def test_a_pi_drive_with_a_bandwidth_is_refused_by_name():
    obj = {"kind": "abu-drive", "format_version": 1, "model": "pi-lag", "zeta": 0.7,
           "omega_n_rad_s": 12.0, "bandwidth_rad_s": 100.0}
    with pytest.raises(DriveFileError) as exc:
        drive_from_dict(obj, "d.json")
    assert exc.value.field == "bandwidth_rad_s"


GOOD_PROFILE = {"kind": "abu-profile", "format_version": 1, "interpolation": "cubic-clamped",
                "time_s": [0.0, 0.1, 0.2], "omega_rad_s": [-100.0, -90.0, -80.0]}


@pytest.mark.parametrize("change, field", [
    ({"kind": "abu-drive"}, "kind"),
    ({"format_version": 2}, "format_version"),
    ({"interpolation": "linear"}, "interpolation"),
    ({"time_s": [0.0, 0.2, 0.1]}, "time_s"),
    ({"time_s": [0.0, 0.1, 0.1]}, "time_s"),
    ({"time_s": [0.0]}, "time_s"),
    ({"time_s": [0.0, "0.1", 0.2]}, "time_s"),
    ({"omega_rad_s": [-100.0, 90.0, -80.0]}, "omega_rad_s"),
    ({"omega_rad_s": [-100.0, 0.0, -80.0]}, "omega_rad_s"),
    ({"omega_rad_s": [-100.0, -90.0]}, "omega_rad_s"),
    ({"omega_rad_s": [-100.0, -90.0, -1e9]}, "omega_rad_s"),
    ({"omega": [1, 2, 3]}, "omega"),
])
def test_bad_profile_fields_are_refused_by_name(change, field):
    with pytest.raises(ProfileFileError) as exc:
        profile_from_dict({**GOOD_PROFILE, **change}, "p.json")
    assert exc.value.field == field and "p.json" in str(exc.value)


def test_profile_file_with_nan_or_missing_field_is_refused(tmp_path):
    from controller.profile import load_profile
    p = tmp_path / "p.json"
    p.write_text(json.dumps(GOOD_PROFILE).replace("-80.0", "NaN"))
    with pytest.raises(ProfileFileError, match="p.json"):
        load_profile(p)
    obj = dict(GOOD_PROFILE)
    del obj["time_s"]
    with pytest.raises(ProfileFileError) as exc:
        profile_from_dict(obj)
    assert exc.value.field == "time_s"


def test_spline_is_scipys_clamped_spline():
    """The stdlib spline equals scipy's clamped CubicSpline (an independent implementation)
    and is held constant outside the knots."""
    ref = CubicSpline(KNOTS_T, KNOTS_W, bc_type="clamped")
    t = np.linspace(0.0, 0.6, 1201)
    inside = (t >= KNOTS_T[0]) & (t <= KNOTS_T[-1])
    u, du = reference(PROFILE, t)
    assert np.allclose(u[inside], ref(t[inside]), atol=1e-9)
    assert np.allclose(du[inside], ref(t[inside], 1), atol=1e-7)
    assert np.all(u[t < KNOTS_T[0]] == KNOTS_W[0]) and np.all(u[t > KNOTS_T[-1]] == KNOTS_W[-1])
    for tt in (0.07, 0.25, 0.45):
        w, dw, d2w = PROFILE.evaluate(tt)
        assert w == pytest.approx(float(ref(tt)), abs=1e-9)
        assert d2w == pytest.approx(float(ref(tt, 2)), rel=1e-7, abs=1e-6)


# ------------------------------------------------------------------------------ the loop
@pytest.mark.parametrize("wb, tau", [(150.0, 0.0), (150.0, 0.01), (60.0, 0.002)])
def test_loop_response_is_the_ode_solution(wb, tau):
    t = np.linspace(0.0, 0.6, 1201)
    r = response(PROFILE, t, wb, tau)

    def rhs(tt, y):
        u = reference(PROFILE, np.array([tt]))[0][0]
        if tau > 0:
            return [y[1], y[2], (wb * (u - y[1]) - y[2]) / tau]
        return [y[1], wb * (u - y[1])]

    y0 = [0.0, KNOTS_W[0], 0.0] if tau > 0 else [0.0, KNOTS_W[0]]
    sol = solve_ivp(rhs, (0.0, 0.6), y0, t_eval=t, rtol=1e-11, atol=1e-11, max_step=1e-3)
    theta = sol.y[0] - np.interp(KNOTS_T[0], t, sol.y[0])
    alpha = sol.y[2] if tau > 0 else wb * (reference(PROFILE, t)[0] - sol.y[1])
    assert np.max(np.abs(r.omega - sol.y[1])) < 1e-6
    assert np.max(np.abs(r.theta - theta)) < 1e-8
    assert np.max(np.abs(r.alpha - alpha)) < 1e-5 * np.max(np.abs(alpha))


def test_twin_tracking_drive_follows_the_loop_model():
    """The twin's digital P law at the frame rate moves the rotor as the continuous loop."""
    from twin.drives import DriveSpec, rotor_mu_req
    spec = DriveSpec(kind="tracking", omega0=KNOTS_W[0], tau_motor=0.005, bandwidth=150.0,
                     profile_t=KNOTS_T, profile_w=KNOTS_W)
    t = np.arange(3072) / FPS
    rot = rotor_mu_req(spec, t)
    r = response(PROFILE, t, 150.0, 0.005)
    assert np.max(np.abs(rot["omega"] - r.omega)) < 1e-3
    assert np.max(np.abs(rot["alpha"] - r.alpha)) < 1e-3 * np.max(np.abs(r.alpha))


# ------------------------------------------------------------------------------ kinematics
SIGMA = 1.5e-4   # rad, the tracking noise of theta on the twin


def record(seed: int, wb: float, t_off: float = 3e-4, gain: float = 1.002,
           ripple: float = 0.0):
    """(t, measured theta, true omega, true omega_dot): the loop's exact motion with a trigger
    offset and a speed-sensor gain, a fixed lens pattern and white noise; ``ripple``: a
    once-per-turn torque ripple [rad/s^2] the model does not contain."""
    t = np.arange(3000) / FPS
    r = response(PROFILE, t - t_off, wb, 0.005, gain=gain)
    theta = r.theta - ripple * np.sin(r.theta) / r.omega**2
    alpha = r.alpha + ripple * np.sin(r.theta)
    rng = np.random.default_rng(seed)
    lens = 4e-4 * np.cos(r.theta + rng.uniform(0, TWO_PI))
    return t, 2.0 + theta + lens + SIGMA * rng.standard_normal(t.size), r.omega, alpha


def tracking_drive(wb: float = 150.0, ci_rel: float = 0.1) -> Drive:
    return Drive(model="tracking", bandwidth=wb, tau_motor=0.005,
                 ci95={"bandwidth_rad_s": (wb * (1 - ci_rel), wb * (1 + ci_rel))})


def test_profile_kinematics_against_the_exact_truth():
    """20 records, true bandwidth anywhere in the stated interval (seeds 0-19): the fit is
    accepted in >= 18, omega_dot inside its 95 % bar at >= 90 % of the check times and within
    1 % of the truth everywhere in the sweep; omega within 0.05 %."""
    checks = np.arange(300, 2500, 100)
    accepted, inside, worst_a, worst_w = 0, [], 0.0, 0.0
    for seed in range(20):
        wb = 150.0 * np.random.default_rng([seed, 1]).uniform(0.92, 1.08)
        t, theta, omega, alpha = record(seed, wb)
        fit = fit_profile_model(t, theta, tracking_drive(), PROFILE, sigma_theta=SIGMA)
        accepted += fit.accepted
        err = fit.omega_dot[checks] - alpha[checks]
        inside += list(np.abs(err) <= 1.96 * fit.sigma_omega_dot[checks])
        big = np.abs(alpha[checks]) > 50
        worst_a = max(worst_a, float(np.max(np.abs(err[big] / alpha[checks][big]))))
        worst_w = max(worst_w, float(np.max(np.abs(fit.omega[checks] / omega[checks] - 1))))
    print(f"profile kinematics, 20 records: accepted {accepted}, inside the 95 % bar "
          f"{100 * np.mean(inside):.0f} %, worst |omega_dot err| {100 * worst_a:.2f} %, "
          f"worst omega err {100 * worst_w:.3f} %")
    assert accepted >= 18
    assert np.mean(inside) >= 0.9
    assert worst_a < 0.01 and worst_w < 5e-4


def test_wrong_drives_are_refused():
    """A loop 2x slower than the drive file states with a tight interval, and a once-per-turn
    torque ripple of 15 % of the peak acceleration: the residual shows it, the fit is
    refused with the reason (seeds 0-4)."""
    for seed in range(5):
        t, theta, _, _ = record(seed, 75.0)
        fit = fit_profile_model(t, theta, tracking_drive(150.0, 0.02), PROFILE,
                                sigma_theta=SIGMA)
        assert not fit.accepted and fit.why
        t, theta, _, alpha = record(seed, 150.0, ripple=0.15 * 400.0)
        fit = fit_profile_model(t, theta, tracking_drive(), PROFILE, sigma_theta=SIGMA)
        assert not fit.accepted and ("white" in fit.why or "rms" in fit.why)


def test_profile_kinematics_refuse_a_pi_drive_and_the_wrong_direction():
    t, theta, _, _ = record(0, 150.0)
    pi = Drive(model="pi-lag", zeta=0.7, omega_n=12.0, tau_motor=0.01)
    assert "tracking" in fit_profile_model(t, theta, pi, PROFILE).why
    fit = fit_profile_model(t, -theta, tracking_drive(), PROFILE, sigma_theta=SIGMA)
    assert not fit.accepted and "direction" in fit.why


# ------------------------------------------------------------------------------ design
def test_design_sweeps_mu_req_through_the_range_inside_the_camera_limits():
    """Through the loop (exact), mu_req rises continuously through the prior range; every mu
    of it slips inside the record; the speed stays within the cap and the alpha limit."""
    from harness.planning.design_profile import ProfileDesignSpec, crossing, design_profile
    spec = ProfileDesignSpec(0.02, 0.04, tracking_drive())
    des = design_profile(spec)
    c = crossing(spec, des.profile, np.linspace(0.02, 0.04, 21))
    assert np.all(c["reached"])
    assert np.all((c["t_slip"] > spec.edge_s) & (c["t_slip"] < spec.record_s - spec.edge_s))
    assert np.max(np.abs(c["omega"])) <= spec.speed_cap() * (1 + 1e-6)
    assert np.max(np.abs(c["alpha"])) <= spec.alpha_max * 1.01
    assert np.max(np.abs(np.diff(c["q"]))) < 0.002        # continuous: no acceleration steps
    # the braking sweep puts the low mu at the higher speed
    assert c["speed"][0] > c["speed"][-1]


# ------------------------------------------------------------------------------ commands
def test_design_render_measure_end_to_end(tmp_path, capsys):
    """abu design (tracking drive) -> profile.json; abu render with it at mu = 0.03; abu measure
    with the profile-model kinematics: the model is accepted and the interval holds mu and is
    at most 12 % wide (the render's mu_d = mu: the slowest, cubic onset; measured 8.7 % here;
    the benchmark's median with mu_d in [0.6, 1] mu is 4.2-4.4 %)."""
    drive = tmp_path / "drive.json"
    drive.write_text(json.dumps(TRACKING))
    assert abu_main(["design", "--mu-range", "0.02", "0.04", "--drive", str(drive), "--out",
                     str(tmp_path / "plan"), "--speed-max-hz", "40"]) == 0
    prof = tmp_path / "plan" / "profile.json"
    assert json.loads(prof.read_text())["kind"] == "abu-profile"
    assert abu_main(["render", "--drive", str(drive), "--profile", str(prof), "--mu", "0.03",
                     "--seed", "3", "--out", str(tmp_path / "rec"), "--quiet"]) == 0
    meta = json.loads((tmp_path / "rec" / "meta.json").read_text())
    assert meta["drive"]["kind"] == "tracking" and meta["mu"] == 0.03
    assert meta["simulation"]["t_slip_s"] is not None
    capsys.readouterr()
    assert abu_main(["measure", str(tmp_path / "rec" / "frames.tif"), "--kinematics",
                     "drive-model", "--drive", str(drive), "--profile", str(prof), "--out",
                     str(tmp_path / "m"), "--json", "--no-plots"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["estimator"]["model"] == "accepted"
    assert s["mu_low"] <= 0.03 <= s["mu_high"]
    assert (s["mu_high"] - s["mu_low"]) / 0.03 < 0.12


@pytest.mark.parametrize("argv, option", [
    (["render", "--profile", "P", "--out", "O"], "--drive"),
    (["render", "--drive", "D", "--profile", "P", "--zeta", "0.7", "--out", "O"], "--zeta"),
    (["render", "--drive", "D", "--out", "O"], "--drive"),
    (["simulate", "--drive", "D", "--mu", "0.01"], "--drive"),
    (["measure", "M", "--tracks", "--profile", "P", "--out", "O"], "--profile"),
    (["measure", "M", "--tracks", "--kinematics", "drive-model", "--drive", "D",
      "--out", "O"], "--profile"),
    (["measure", "M", "--tracks", "--kinematics", "drive-model", "--drive", "D", "--profile",
      "P", "--te", "0.5", "--out", "O"], "--te"),
    (["design", "--mu-range", "0.02", "0.04", "--drive", "D", "--step-hz", "1"], "--step-hz"),
    (["next", "S", "--drive", "D"], "--drive"),
])
def test_tracking_options_refused_by_name(tmp_path, capsys, argv, option):
    drive = tmp_path / "drive.json"
    drive.write_text(json.dumps(TRACKING))
    prof = tmp_path / "profile.json"
    prof.write_text(json.dumps(GOOD_PROFILE))
    summary = tmp_path / "s.json"
    subst = {"D": str(drive), "P": str(prof), "O": str(tmp_path / "out"), "M": str(tmp_path /
             "tracks.csv"), "S": str(summary)}
    (tmp_path / "tracks.csv").write_text("time_s\n")
    assert abu_main([subst.get(a, a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert option in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "out").exists()


# ------------------------------------------------------------------------------ co-simulation
@pytest.mark.parametrize("mu, tau", [(0.012, 0.005), (0.02, 0.0)])
def test_cosimulated_tracking_drive_slips_where_the_exact_mu_req_reaches_mu(mu, tau, fmu_dir):
    """abu simulate --motion profile's experiment: the rotor follows the loop's exact motion
    (1e-5 rad/s), the ball slips where mu_req of that motion first reaches mu (within 2e-6 s:
    the check's grid), and mu_low = mu_high = mu (continuous acceleration)."""
    from abu_model.params import PlantParams
    from harness.experiments.profile_run import ProfileExperiment, run_profile
    drive = Drive(model="tracking", bandwidth=150.0, tau_motor=tau)
    plant = PlantParams(BallParams(mu=mu, mu_d=0.8 * mu), tau_motor=tau)
    res = run_profile(ProfileExperiment(plant, drive, PROFILE, t_end=0.45), fmu_dir=fmu_dir)
    s = res.summary
    assert s["max_omega_error_rad_s"] < 1e-5
    t = np.arange(0.0, 0.45, 1e-6)
    r = response(PROFILE, t, 150.0, tau)
    q = BallParams().lever_ratio * np.abs(r.alpha) / r.omega**2
    t_cross = t[np.argmax(q >= mu)]
    assert s["t_slip"] == pytest.approx(t_cross, abs=2e-6)
    assert s["mu_low"] == pytest.approx(mu, rel=1e-6) and s["mu_high"] == pytest.approx(mu,
                                                                                        rel=1e-6)


def test_simulate_profile_command(tmp_path, capsys, fmu_dir):
    drive = tmp_path / "drive.json"
    drive.write_text(json.dumps(TRACKING))
    prof = tmp_path / "profile.json"
    prof.write_text(json.dumps(PROFILE.to_dict()))
    folder = str(next(iter(fmu_dir.values())).parent)
    assert abu_main(["simulate", "--motion", "profile", "--drive", str(drive), "--profile",
                     str(prof), "--mu", "0.015", "--fmu-dir", folder, "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["experiment"]["motion"] == "profile" and s["slips"]
    assert s["mu_estimate"] == pytest.approx(0.015, rel=1e-6)
