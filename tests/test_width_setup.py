"""The width model for the set-up a measurement will use (harness.planning.width_model).

* a calibrated camera's lens prior, read from ``abu measure --camera`` summaries
  (``--noise-from``, ``abu next``), scales the lens part exactly as A (lever / mu + 2);
* the drive-model kinematics (``--kinematics drive-model``, or summaries measured with it): the
  kinematic error is the fit's 1 % floor and its timing bar (closed form on a polynomial
  motion), no truncation, z on the lower bound;
* what a summary cannot say (missing, text, NaN, booleans) leaves the constants as they are;
  options that do not apply (a tracking drive) are refused by name.

The benchmark that checks these predictions against rendered, calibrated and measured runs is
``benchmarks/bench_designed_runs.py --camera 30 --kinematics drive-model`` (README).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from abu.cli.main import main
from abu_model.errors import ParameterError
from abu_model.params import BallParams
from harness.planning import width_model as wm

LEVER = BallParams().lever_ratio


def _motion(fps: float = 4500.0, n: int = 3072):
    """A polynomial motion whose SG view is exact: omega_dot = j t (mu_req rising)."""
    t = np.arange(n) / fps
    w0, j = -300.0, 1000.0
    return t, w0 * t + j * t**3 / 6, w0 + j * t**2 / 2, j * t


def _summary(lens: float | None = None, estimator: str = "savgol", **extra) -> dict:
    s = {"kind": "abu-measure-summary", "mu_low": 0.02, "mu_high": 0.04,
         "noise": {"sigma_theta_rad": 2.14e-4},
         "model_fit": {"noise_model": {"sigma_white_rad": 5e-4, "sigma_leftover_rad": 4e-4}},
         "estimator": {"name": estimator}}
    if lens is not None:
        s["camera"] = {"theta_harmonic_prior": {"theta_harmonic_rad": lens}}
    return {**s, **extra}


def test_a_calibrated_lens_prior_scales_the_lens_part_exactly():
    t, th, w, a = _motion()
    mu = np.array([0.02])
    base = wm.predict_widths(t, th, w, a, mu, LEVER, wm.CALIBRATED)
    cal = wm.with_recorded_setup(wm.CALIBRATED, [_summary(2e-4), _summary(3e-4),
                                                 _summary(1e-3)])
    assert cal.theta_harmonic_rad == pytest.approx(3e-4)          # the median of three
    p = wm.predict_widths(t, th, w, a, mu, LEVER, cal)
    assert p.lens[0] == pytest.approx(base.lens[0] * 3e-4 / wm.THETA_HARMONIC_RAD, rel=1e-12)
    assert p.kinematic_noise[0] == base.kinematic_noise[0]        # the rest unchanged
    assert p.expected[0] < base.expected[0]
    # a summary measured without a camera counts as the family prior (8e-4)
    mixed = wm.with_recorded_setup(wm.CALIBRATED, [_summary(2e-4), _summary(), _summary()])
    assert mixed.theta_harmonic_rad == pytest.approx(wm.THETA_HARMONIC_RAD)


def test_drive_model_kinematics_have_the_fits_floor_and_timing_bar():
    t, th, w, a = _motion()
    mu = np.array([0.02])
    c = wm.with_recorded_setup(wm.CALIBRATED, [_summary(estimator="drive-model")] * 2
                               + [_summary()])
    assert c.kinematics == "drive-model"                            # 2 of 3
    p = wm.predict_widths(t, th, w, a, mu, LEVER, c)
    sg = wm.predict_widths(t, th, w, a, mu, LEVER, wm.CALIBRATED)
    i = int(np.argmin(np.abs(t - p.t_slip_s[0])))
    h = t[1] - t[0]
    # omega_dot = j t: half its change over +- one frame, relative, is h / t
    assert p.kinematic_noise[0] == pytest.approx(math.hypot(0.01, h / t[i]), rel=1e-9)
    assert p.truncation[0] == 0.0
    # a 1 ms controller sample widens the timing bar 4.5x
    ms = wm.predict_widths(t, th, w, a, mu, LEVER, c, controller_sample_time_s=1e-3)
    assert ms.kinematic_noise[0] == pytest.approx(math.hypot(0.01, 1e-3 / t[i]), rel=1e-9)
    assert ms.expected[0] > p.expected[0]
    assert sg.constants.kinematics == "savgol" and p.constants.kinematics == "drive-model"


@pytest.mark.parametrize("bad", [
    {"camera": "calibrated"}, {"camera": {"theta_harmonic_prior": {"theta_harmonic_rad": "x"}}},
    {"camera": {"theta_harmonic_prior": {"theta_harmonic_rad": float("nan")}}},
    {"camera": {"theta_harmonic_prior": {"theta_harmonic_rad": True}}},
    {"camera": {"theta_harmonic_prior": {"theta_harmonic_rad": -1e-4}}},
    {"noise": [1, 2]}, {"model_fit": {"noise_model": {"sigma_white_rad": "5e-4"}}},
    {"camera": {"theta_harmonic_prior": {"theta_harmonic_rad": 5.0}}},    # no lens's
    {"noise": {"sigma_theta_rad": 1e3}},                                    # no camera's
    {"model_fit": {"noise_model": {"sigma_white_rad": float("inf")}}},
])
def test_what_a_summary_cannot_say_leaves_the_constants(bad):
    s = {"kind": "abu-measure-summary", "estimator": {"name": "savgol"}, **bad}
    c = wm.with_recorded_setup(wm.CALIBRATED, [s])
    assert c.theta_harmonic_rad == wm.THETA_HARMONIC_RAD
    assert c.sigma_theta_rad == wm.CALIBRATED.sigma_theta_rad
    assert c.sigma_beta_rad == wm.CALIBRATED.sigma_beta_rad
    with pytest.raises(ParameterError, match="kinematics"):
        wm.WidthConstants(kinematics="spline")
    with pytest.raises(ParameterError, match="theta_harmonic_rad"):
        wm.WidthConstants(theta_harmonic_rad=-1.0)


def test_where_the_set_up_came_from_is_recorded_not_guessed(tmp_path, capsys):
    """A summary that states exactly the typical noise, measured without a camera, still reads
    as the user's own noise and an uncalibrated lens (the source is recorded by
    ``with_recorded_setup``, not derived by comparing values)."""
    typical = {"kind": "abu-measure-summary", "estimator": {"name": "savgol"},
               "noise": {"sigma_theta_rad": wm.CALIBRATED.sigma_theta_rad},
               "model_fit": {"noise_model": {"sigma_white_rad": wm.CALIBRATED.sigma_beta_rad,
                                            "sigma_leftover_rad": 0.0}}}
    c = wm.with_recorded_setup(wm.CALIBRATED, [typical])
    assert (c.sigma_theta_rad, c.sigma_beta_rad) == (wm.CALIBRATED.sigma_theta_rad,
                                                     wm.CALIBRATED.sigma_beta_rad)
    assert (c.noise_source, c.lens_source) == ("summaries", "typical")
    assert wm.with_recorded_setup(wm.CALIBRATED, [_summary(3e-4)]).lens_source == "summaries"
    assert wm.with_recorded_setup(wm.CALIBRATED, [{"kind": "x"}]).noise_source == "typical"
    path = tmp_path / "typical.json"
    path.write_text(json.dumps(typical))
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check", "--noise-from",
                 str(path)]) == 0
    text = capsys.readouterr().out
    assert "(from the summaries), lens prior 0.0008 rad (uncalibrated" in text, text
    with pytest.raises(ParameterError, match="noise_source"):
        wm.WidthConstants(noise_source="guessed")


def _camera_file(tmp_path, cov_scale: float = 1.0):
    from measurement.imaging import camera as cam_mod
    cam = cam_mod.Camera(np.array([[300.0, 0, 128.0], [0, 300.0, 127.0], [0, 0, 1]]),
                         np.array([-0.05, 0.01, 0, 0, 0]), (256, 256), 0.03, 30, 1620,
                         np.diag([0.04, 0.04, 1e-6, 1e-6]) * cov_scale)
    path = tmp_path / f"camera{cov_scale:g}.json"
    cam_mod.write_camera(path, cam)
    return path, cam


def test_design_takes_a_calibrated_cameras_lens_prior(tmp_path, capsys):
    """``abu design --camera`` predicts with the calibration's prior at the CD circle (the
    function ``abu measure --camera`` states it with), exactly and scaled with the
    calibration's covariance; the circle's default is stated; bad circles, a circle without a
    camera and a missing camera file are refused by name (exit 2, one line)."""
    from measurement.imaging.camera import theta_harmonic_prior

    path, cam = _camera_file(tmp_path)
    base = ["design", "--mu-range", "0.02", "0.04", "--no-check"]
    assert main([*base, "--json", "--camera", str(path), "--cd-circle", "120,130,90"]) == 0
    w = json.loads(capsys.readouterr().out)["width_prediction"]
    prior = theta_harmonic_prior(cam, (120.0, 130.0), 90.0)["theta_harmonic_rad"]
    assert 0 < prior < wm.THETA_HARMONIC_RAD
    assert w["camera_noise"]["theta_harmonic_rad"] == pytest.approx(prior, rel=1e-12)
    assert w["camera_noise"]["lens_source"] == "camera"
    for row in w["table"]:
        assert row["lens"] == pytest.approx(prior * (LEVER / row["mu"] + 2), rel=0.25)
    # four times the covariance: twice the prior (the bound is linear in the parameters' sd)
    path4, _ = _camera_file(tmp_path, 4.0)
    assert main([*base, "--json", "--camera", str(path4), "--cd-circle", "120,130,90"]) == 0
    w4 = json.loads(capsys.readouterr().out)["width_prediction"]
    # (to the finite-difference Jacobian's step, one sd: 0.2 %)
    assert w4["camera_noise"]["theta_harmonic_rad"] == pytest.approx(2 * prior, rel=0.01)
    assert main([*base, "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)["width_prediction"]
    assert w["expected"] < w4["expected"] < plain["expected"]
    assert main([*base, "--camera", str(path)]) == 0
    text = capsys.readouterr().out
    assert "assumed to circle the image centre at 95 px" in text and "--cd-circle" in text
    for bad in ("1,2", "a,b,c", "128,128,nan", "128,128,0", "128,128,200", "-5,128,20"):
        assert main([*base, "--camera", str(path), f"--cd-circle={bad}"]) == 2, bad
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "--cd-circle" in err[0] and "256x256" in err[0], err
    assert main([*base, "--cd-circle", "128,128,90"]) == 2
    assert "--cd-circle" in capsys.readouterr().err
    # abu next: the camera's prior replaces that of the summaries it combines
    summary = tmp_path / "s.json"
    summary.write_text(json.dumps(_summary(6e-4)))
    assert main(["next", str(summary), "--no-check", "--json", "--camera", str(path),
                 "--cd-circle", "120,130,90"]) == 0
    cn = json.loads(capsys.readouterr().out)["design"]["width_prediction"]["camera_noise"]
    assert cn["lens_source"] == "camera"
    assert cn["theta_harmonic_rad"] == pytest.approx(prior, rel=1e-12)
    assert main([*base, "--camera", str(tmp_path / "missing.json")]) == 2
    err = capsys.readouterr().err
    assert "missing.json" in err and "Traceback" not in err


def test_design_and_next_use_the_recorded_set_up(tmp_path, capsys):
    """``abu design --noise-from`` and ``abu next`` on summaries measured with a calibrated
    camera and the drive model predict with their lens prior and kinematics; ``--kinematics``
    overrides; with a tracking drive both options are refused by name."""
    paths = []
    for k, lens in enumerate((2.5e-4, 3.5e-4)):
        p = tmp_path / f"s{k}.json"
        p.write_text(json.dumps(_summary(lens, "drive-model")))
        paths.append(str(p))
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check", "--json"]) == 0
    plain = json.loads(capsys.readouterr().out)["width_prediction"]
    assert plain["kinematics"] == "savgol"
    assert plain["camera_noise"]["theta_harmonic_rad"] == pytest.approx(8e-4)
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check", "--json",
                 "--noise-from", *paths]) == 0
    cam = json.loads(capsys.readouterr().out)["width_prediction"]
    assert cam["kinematics"] == "drive-model"
    assert cam["camera_noise"]["theta_harmonic_rad"] == pytest.approx(3e-4)
    for row in cam["table"]:
        assert row["lens"] == pytest.approx(3e-4 * (LEVER / row["mu"] + 2), rel=0.25)
        assert row["truncation"] == 0.0 and row["kinematic_noise"] >= 0.01
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check", "--json",
                 "--noise-from", *paths, "--kinematics", "savgol"]) == 0
    assert json.loads(capsys.readouterr().out)["width_prediction"]["kinematics"] == "savgol"
    # the text says what the prediction assumed, and how to state the user's own set-up
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check"]) == 0
    text = capsys.readouterr().out
    assert "lens prior 0.0008 rad (uncalibrated" in text and "--noise-from" in text
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check", "--noise-from",
                 *paths]) == 0
    text = capsys.readouterr().out
    assert "lens prior 0.0003 rad (from the summaries)" in text
    assert "drive-model kinematics" in text
    assert main(["next", *paths, "--no-check", "--json"]) == 0
    w = json.loads(capsys.readouterr().out)["design"]["width_prediction"]
    assert w["kinematics"] == "drive-model"
    assert w["camera_noise"]["theta_harmonic_rad"] == pytest.approx(3e-4)
    tracking = tmp_path / "tracking.json"
    tracking.write_text(json.dumps({"kind": "abu-drive", "format_version": 1,
                                    "model": "tracking", "bandwidth_rad_s": 100.0,
                                    "tau_motor_s": 0.002}))
    for option in (["--kinematics", "drive-model"], ["--noise-from", paths[0]],
                   ["--camera", paths[0]], ["--cd-circle", "1,1,1"]):
        assert main(["design", "--mu-range", "0.02", "0.04", "--drive", str(tracking),
                     *option]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and option[0] in err[0], err


def test_abu_measure_says_what_an_uncalibrated_lens_takes():
    """``abu measure``'s text: without a camera file the lens prior's share at the slip and
    how to replace it; none with a calibration, or where the drive model fitted theta's
    harmonics (the profile drive: no prior then)."""
    from measurement.report.summary_text import lens_line
    base = {"estimator": {"name": "savgol"}, "model_fit": {"kinematic_rel_bias_at_slip": 0.017}}
    line = lens_line(base)
    assert "+-1.7 % of mu" in line and "--camera" in line and "calibrate-camera" in line
    assert lens_line({**base, "camera": {"file": "cam.json"}}) == ""
    assert lens_line({**base, "estimator": {"name": "drive-model",
                                            "theta_harmonics_fitted": True}}) == ""
    assert lens_line({"estimator": {}, "model_fit": {"kinematic_rel_bias_at_slip": None}}) == ""


def test_design_says_what_would_narrow_it(tmp_path, capsys):
    """``what_if``: each listed set-up change narrows this staircase's predicted width, all of
    them together more than any one; a change already made is not offered; the calibrated
    camera's what-if is what a design told that lens predicts (it may pick another staircase
    of the same ranking: within 3 %); stating the staircase (drive-model kinematics) is
    offered only where a design told those kinematics predicts narrower (on the report's loop
    and a PI loop with a 5 ms lag it predicts wider: the timing bar at the steps)."""
    from harness.planning.design_width import CALIBRATED_LENS_PRIOR_RAD

    base = ["design", "--mu-range", "0.02", "0.04", "--no-check", "--json"]
    pi = tmp_path / "pi.json"
    pi.write_text(json.dumps({"kind": "abu-drive", "format_version": 1, "model": "pi-lag",
                              "zeta": 0.7, "omega_n_rad_s": 12.0, "tau_motor_s": 0.005}))
    # a summary stating the typical noise and a calibration's lens prior
    calibrated = tmp_path / "calibrated.json"
    calibrated.write_text(json.dumps(
        {"kind": "abu-measure-summary", "estimator": {"name": "savgol"},
         "noise": {"sigma_theta_rad": wm.CALIBRATED.sigma_theta_rad},
         "model_fit": {"noise_model": {"sigma_white_rad": wm.CALIBRATED.sigma_beta_rad,
                                      "sigma_leftover_rad": 0.0}},
         "camera": {"theta_harmonic_prior": {"theta_harmonic_rad": CALIBRATED_LENS_PRIOR_RAD}}}))
    for drive in ([], ["--drive", str(pi)]):
        assert main([*base, *drive]) == 0
        d = json.loads(capsys.readouterr().out)
        now, changes = d["width_prediction"]["expected"], d["what_if"]
        names = [c["change"] for c in changes]
        assert any("calibrated camera" in n for n in names)
        assert any("twice as close" in n for n in names)
        # offered only where it narrows: a design told the drive-model kinematics says so
        assert main([*base, *drive, "--kinematics", "drive-model"]) == 0
        dm = json.loads(capsys.readouterr().out)["width_prediction"]["expected"]
        assert abs(dm / now - 1) > 0.03   # (not a tie the re-ranking could flip)
        assert any("drive-model" in n for n in names) == (dm < now), (names, dm, now)
        assert all(c["expected"] < now for c in changes)
        assert names[-1] == "all of these"
        assert changes[-1]["expected"] <= min(c["expected"] for c in changes[:-1])
        assert main([*base, *drive, "--noise-from", str(calibrated)]) == 0
        told = json.loads(capsys.readouterr().out)
        cal = next(c for c in changes if "calibrated camera" in c["change"])
        assert told["width_prediction"]["expected"] == pytest.approx(cal["expected"], rel=0.03)
        assert not any("calibrated camera" in c["change"] for c in told["what_if"])
    assert main([*base, "--drive", str(pi), "--kinematics", "drive-model"]) == 0
    assert not any("drive-model" in c["change"]
                   for c in json.loads(capsys.readouterr().out)["what_if"])
    # a camera with ten times the typical theta noise: the Savitzky-Golay kinematics dominate,
    # and stating the staircase narrows it (as a design told it predicts)
    noisy = tmp_path / "noisy.json"
    noisy.write_text(json.dumps(_summary(noise={"sigma_theta_rad": 2e-3})))
    assert main([*base, "--drive", str(pi), "--noise-from", str(noisy)]) == 0
    d = json.loads(capsys.readouterr().out)
    offered = [c for c in d["what_if"] if "drive-model" in c["change"]]
    assert main([*base, "--drive", str(pi), "--noise-from", str(noisy), "--kinematics",
                 "drive-model"]) == 0
    dm = json.loads(capsys.readouterr().out)["width_prediction"]["expected"]
    assert dm < 0.8 * d["width_prediction"]["expected"]
    # a design told those kinematics may move the staircase too: at most the what-if's width
    assert len(offered) == 1 and dm <= 1.03 * offered[0]["expected"]
    assert offered[0]["expected"] < d["width_prediction"]["expected"]
    assert main(["design", "--mu-range", "0.02", "0.04", "--no-check"]) == 0
    text = capsys.readouterr().out
    assert "what would narrow it (this staircase, predicted; now" in text
