"""The staircase found from the record (``abu measure --kinematics drive-model
--find-staircase``, measurement.kinematics.staircase_search): on records of the harsh twin's
digital PI drives (its own controller and rotor integration, independent of the closed-form
loop response the fit uses), with a lens pattern and tracking noise."""
from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from abu.cli.main import main as abu_main  # noqa: E402
from measurement.kinematics.estimators import savgol_kinematics  # noqa: E402
from measurement.kinematics.staircase_guess import (ROUNDING_OFFSETS,  # noqa: E402
                                                    SineStaircase, progress, progress_root,
                                                    sine_guess)
from measurement.kinematics.staircase_search import FoundStaircaseInput  # noqa: E402
from test_unknown_loop import _tracks_csv  # noqa: E402

TWO_PI = 2 * math.pi
FPS = 3000.0
SIGMA = 1.5e-4      # tracking noise of theta [rad] (0.015 px on a 100 px CD marker radius)
N_FRAMES = 2048     # 0.68 s, as the benchmark family's records


def _record(seed: int, rounding: str, per_frame: int = 1, fps: float = FPS):
    """(t, theta measured, true omega_dot, DriveSpec) of a twin staircase drive whose whole
    staircase is in the record (the report's protocol): 6-14 steps of 1 Hz over 0.3-0.55 s,
    the loop, lag, setpoint weight and filter drawn as the benchmark family draws them, 0.68
    s at ``fps`` frames/s; the controller at the frame rate, or ``per_frame`` times it."""
    from twin.drives import DriveSpec, rotor_mu_req
    rng = np.random.default_rng([seed, 2718])
    u = rng.uniform
    w0 = -TWO_PI * u(6.0, 14.0)
    spec = DriveSpec(kind="staircase_pi", omega0=w0, omega_end=w0 - TWO_PI * u(6.0, 14.0),
                     t0=u(0.0, 0.05), te=u(0.3, 0.55), rounding=rounding,
                     tau_motor=u(0.0, 0.03), zeta=u(0.6, 1.0), omega_n=u(8.0, 30.0),
                     setpoint_weight=u(0.5, 1.0),
                     setpoint_tau=0.0 if u() < 0.4 else u(0.002, 0.02))
    fine = np.arange(int(N_FRAMES * fps / FPS) * per_frame) / (fps * per_frame)
    r = {k: v[::per_frame] for k, v in rotor_mu_req(spec, fine).items()}
    t = fine[::per_frame]
    lens = 4e-4 * np.cos(r["theta"] + u(0, TWO_PI))
    theta = 1.0 + r["theta"] + lens + SIGMA * rng.standard_normal(t.size)
    return t, theta, r["alpha"], spec


def test_the_vectorised_sine_progress_inverts_and_is_the_staircases_own():
    """progress is controller.reference's scalar sine_progress on arrays, and progress_root
    its inverse (the step fractions are those of controller.reference.Staircase)."""
    from controller.reference import Staircase, sine_progress
    x = np.linspace(0.0, 1.0, 1001)
    assert np.allclose(progress(x), [sine_progress(v) for v in x], rtol=0, atol=1e-15)
    assert np.allclose(progress_root(progress(x)), x, atol=1e-9)
    stair = Staircase(-TWO_PI * 9, -TWO_PI * 19.5, 0.0, 0.5, rounding="nearest")
    mine = SineStaircase(0.0, ROUNDING_OFFSETS["nearest"], 10, -TWO_PI * 9, -1.0, TWO_PI)
    assert np.allclose(mine.setpoints(0.5, 10.5).step_times, stair.step_times, atol=1e-9)


@pytest.mark.parametrize("seed, rounding", [(9102, "lead"), (9103, "nearest"),
                                            (9107, "trail")])
def test_the_staircase_is_found_and_the_kinematics_are_those_of_the_stated_one(seed, rounding):
    """One record per rounding: the fit is accepted, the staircase found is the drive's (its
    rounding, step count, and te within 0.3 %), and omega_dot while the drive turns is as
    good as with the true staircase stated (``UnknownLoopInput``, the loop fitted freely):
    RMS error within 1.5x of it (+ 0.005 rad/s^2) and below a fiftieth of Savitzky-Golay's
    (the default), its 95 % bar holding the truth at no fewer check times (- 5 points)."""
    from abu_model.loop_response import Setpoints
    from controller.reference import Staircase
    from measurement.kinematics.unknown_loop import UnknownLoopInput
    t, th, alpha, spec = _record(seed, rounding)
    fit = FoundStaircaseInput(sample_time_s=1.0 / FPS).fit(t, th, SIGMA)
    assert fit.accepted, fit.why
    p = fit.params
    span = abs(spec.omega_end - spec.omega0) / spec.step
    assert p["staircase_rounding_offset"] == ROUNDING_OFFSETS[rounding]
    assert p["staircase_steps"] == math.floor(span)
    assert abs(p["staircase_te_s"] / spec.te - 1.0) < 0.003
    stair = Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te, rounding=rounding)
    stated = UnknownLoopInput(setpoints=Setpoints(stair.step_times, stair.levels),
                              sample_time_s=1.0 / FPS).fit(t, th, SIGMA)
    assert stated.accepted, stated.why
    sg = savgol_kinematics(t, th, window_s=0.042, polyorder=9, sigma_theta=SIGMA)
    checks = np.arange(int((spec.t0 + 0.02) * FPS), int((spec.t0 + spec.te) * FPS), 20)
    figures = {}
    for name, k in (("found", fit), ("stated", stated), ("SG", sg)):
        e = k.omega_dot[checks] - alpha[checks]
        figures[name] = (float(np.sqrt(np.mean(e**2))),
                         float(np.mean(np.abs(e) <= 1.96 * k.sigma_omega_dot[checks])))
    print(f"\nseed {seed} ({rounding}): {fit.loop}; RMS omega_dot [rad/s^2] / inside the "
          "95 % bar: " + ", ".join(f"{n} {r:.3f} / {c:.0%}" for n, (r, c) in figures.items()))
    assert figures["found"][0] <= 1.5 * figures["stated"][0] + 0.005
    assert figures["found"][0] < figures["SG"][0] / 50
    assert figures["found"][1] >= figures["stated"][1] - 0.05


def _fast_record(seed: int):
    """(t, theta measured, DriveSpec) of a fast staircase (13 steps in 0.25 s, trail) of the
    twin's PI at the frame rate, 3000 frames/s: its sampling biases the continuous fit's te
    by 0.4-0.6 %, several of its standard errors."""
    from twin.drives import DriveSpec, rotor_mu_req
    spec = DriveSpec(kind="staircase_pi", omega0=-TWO_PI * 8.0,
                     omega_end=-TWO_PI * (8.0 + 13.174), t0=0.0028, te=0.253,
                     rounding="trail", tau_motor=0.0155, zeta=0.77, omega_n=36.6,
                     setpoint_weight=0.89)
    t = np.arange(1214) / 3000.0
    r = rotor_mu_req(spec, t)
    rng = np.random.default_rng([seed, 31])
    theta = 1.0 + r["theta"] + 4e-4 * np.cos(r["theta"] + 1.0) \
        + 2.7e-4 * rng.standard_normal(t.size)
    return t, theta, spec


def test_a_fast_staircase_whose_continuous_te_is_biased_is_found():
    """Step 4's box holds the sample assignment where the continuous fit's te is off by
    more than 0.2 %: accepted on 3 of 3 records, 13 steps, trail, te within 0.3 %. (With the
    box at the former +- 0.2 %, two of three are refused: residual not white.)"""
    for seed in range(3):
        t, th, spec = _fast_record(seed)
        fit = FoundStaircaseInput(sample_time_s=1.0 / 3000.0).fit(t, th, 2.7e-4)
        assert fit.accepted, (seed, fit.why)
        p = fit.params
        assert p["staircase_steps"] == 13 and p["staircase_rounding_offset"] == 0.0
        assert abs(p["staircase_te_s"] / spec.te - 1.0) < 0.003, (seed, p["staircase_te_s"])


@pytest.mark.parametrize("seed", [0, 1])
def test_a_controller_faster_than_the_camera_is_found_with_its_sample_time(seed):
    """A 10 kHz controller filmed at 5000 frames/s, nothing stated: the frame interval is
    refused, the other candidate sample times are ranked by their best assignment of steps
    to samples, and 1e-4 s is found and accepted, the staircase the drive's. (Ranked by the
    continuous fit's steps and fitted without step 4, as before, both records are refused.)"""
    t, th, _, spec = _record(seed, "lead", per_frame=2, fps=5000.0)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert fit.accepted, (seed, fit.why)
    p = fit.params
    assert p["controller_sample_time_s"] == pytest.approx(1e-4, rel=1e-9)
    span = abs(spec.omega_end - spec.omega0) / spec.step
    assert p["staircase_steps"] == math.floor(span)
    assert p["staircase_rounding_offset"] == ROUNDING_OFFSETS["lead"]
    assert abs(p["staircase_te_s"] / spec.te - 1.0) < 0.003, (seed, p["staircase_te_s"])


@pytest.mark.parametrize("seed, rounding, dn", [(9102, "lead", -1), (9103, "nearest", 1),
                                                (9107, "trail", -1)])
def test_a_step_count_one_off_in_every_grid_cell_is_mended(monkeypatch, seed, rounding, dn):
    """Every staircase the grid scores has one step fewer (dn -1) or more (+1) than the
    drive's: step 2's best fit is then beyond the acceptance limit, and the same staircase
    refitted from it with one step more (fewer) is the drive's, accepted (te within 0.3 %).
    Without that refit the records are refused. (From one step more it is not always
    mended: 1 of 3 of these records; in the benchmark family's refusals the count was one
    off either way.)"""
    from measurement.kinematics import staircase_search
    t, th, _, spec = _record(seed, rounding)
    n_true = math.floor(abs(spec.omega_end - spec.omega0) / spec.step)
    real = staircase_search.candidate_staircases
    monkeypatch.setattr(staircase_search, "candidate_staircases", lambda *a: [
        s for s in real(*a) if s.n == n_true + dn and s.rounding == rounding])
    fit = FoundStaircaseInput(sample_time_s=1.0 / FPS).fit(t, th, SIGMA)
    assert fit.accepted, fit.why
    assert fit.params["staircase_steps"] == n_true
    assert abs(fit.params["staircase_te_s"] / spec.te - 1.0) < 0.003


def test_step_2s_fit_at_the_noise_ends_the_search_where_the_frame_interval_is_refused(
        monkeypatch):
    """A 30 kHz controller (next to continuous): where the frame interval's fit is refused
    and step 2's continuous fit on all samples is at the noise, that fit is the result; the
    other sample times are not fitted (each costs seconds)."""
    from measurement.kinematics import staircase_search
    from measurement.kinematics.model_fit import DriveFit
    t, th, _, spec = _record(9103, "nearest", per_frame=10)
    refused = DriveFit(False, "refused (test)", params={"zeta": 0.7})

    def not_called(*a, **k):
        raise AssertionError("the other sample times were fitted")

    monkeypatch.setattr(FoundStaircaseInput, "_stepped", lambda *a, **k: refused)
    monkeypatch.setattr(FoundStaircaseInput, "_other_sample_times", not_called)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert fit.accepted, fit.why
    assert fit.params["controller_sample_time_s"] == 0.0
    assert fit.rms_ratio <= staircase_search.GOOD_ENOUGH_RMS
    assert abs(fit.params["staircase_te_s"] / spec.te - 1.0) < 0.01


def test_an_accepted_continuous_fit_stands_where_every_digital_fit_is_refused(monkeypatch):
    """Step 2's continuous fit of the staircase's timing with the loop is a result of its
    own: where it passes the tests on all samples and steps 3-4 refuse every sample time,
    it is returned (continuous), not the refusal."""
    from measurement.kinematics import staircase_search
    from measurement.kinematics.model_fit import DriveFit
    t, th, _, spec = _record(9103, "nearest", per_frame=10)   # a 30 kHz controller
    found = staircase_search._continuous(t, th, SIGMA, sine_guess(t, th), TWO_PI,
                                         FoundStaircaseInput().settings)
    assert found is not None and found.on_all_samples and found.fit.accepted, found
    refused = DriveFit(False, "every controller sample time tried was refused (test)")
    monkeypatch.setattr(FoundStaircaseInput, "_loop_fit", lambda *a, **k: refused)
    monkeypatch.setattr(FoundStaircaseInput, "_stepped", lambda *a, **k: refused)
    # no fit counts as at the noise, so the search's shortcut for one does not return it
    monkeypatch.setattr(staircase_search, "GOOD_ENOUGH_RMS", 0.0)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert fit.accepted, fit.why
    assert fit.params["controller_sample_time_s"] == 0.0
    assert "(continuous) over the staircase found" in fit.loop
    assert abs(fit.params["staircase_te_s"] / spec.te - 1.0) < 0.01


def test_a_step_too_small_for_the_search_is_refused_before_it_starts(monkeypatch):
    """A setpoint step far below the drive's (0.05 Hz on a 6-14 Hz staircase: 120-280 steps)
    is refused with the step count and the limit, before any fit (1000 steps took all of the
    machine's memory before the limit): no timing grid is built."""
    from measurement.kinematics import staircase_search
    t, th, _, spec = _record(9104, "lead")
    steps = abs(spec.omega_end - spec.omega0) / (0.05 * TWO_PI)

    def no_grid(*a, **k):
        raise AssertionError("the search started")
    monkeypatch.setattr(staircase_search, "timing_grid", no_grid)
    fit = FoundStaircaseInput(step_rad_s=0.05 * TWO_PI).fit(t, th, SIGMA)
    assert not fit.accepted
    assert f"at most {staircase_search.MAX_STEPS} steps" in fit.why
    found = float(re.search(r"Hz, (\d+) steps of 0.05 Hz", fit.why).group(1))
    assert abs(found / steps - 1.0) < 0.1, (found, steps)
    # at the limit the search runs (here: a steps count within it, the drive's own)
    monkeypatch.setattr(staircase_search, "MAX_STEPS", int(steps) + 2)
    with pytest.raises(AssertionError, match="the search started"):
        FoundStaircaseInput(step_rad_s=0.05 * TWO_PI).fit(t, th, SIGMA)


def test_a_step_count_one_off_near_the_limit_is_tried_again(monkeypatch):
    """Step 2 made to return the drive's staircase with a step fewer (its refit from the
    found one, as `_recounted` fits it): steps 3-4 refuse it near the acceptance limit, and
    the retry with one more step finds the drive's count and is accepted; without the retry
    (RECOUNT_RMS 0) the record is refused."""
    from controller.reference import Staircase
    from measurement.kinematics import staircase_search
    t, th, alpha, spec = _record(9107, "trail")
    n_true = len(Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te,
                           rounding=spec.rounding).step_times)
    real = staircase_search._continuous

    def one_short(time, theta, sigma, guess, step, settings):
        found = real(time, theta, sigma, guess, step, settings)
        assert found.stair.n == n_true
        return staircase_search._recounted(time, theta, sigma, found, -1, settings)
    monkeypatch.setattr(staircase_search, "_continuous", one_short)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert fit.accepted, fit.why
    assert fit.params["staircase_steps"] == n_true
    assert abs(fit.params["staircase_te_s"] / spec.te - 1.0) < 0.01
    assert "digital" in fit.loop
    assert fit.loop.endswith(f"(tried again: {n_true - 1} steps refused near the limit)")
    monkeypatch.setattr(staircase_search, "RECOUNT_RMS", 0.0)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert not fit.accepted and fit.params.get("staircase_steps") == n_true - 1


def test_another_count_passing_only_step_2s_free_timing_is_not_taken(monkeypatch):
    """The retry's other count must pass with its staircase's timing held (steps 3-4): where
    only step 2's own fit (te and span free, which can make up for a step) passes, and the
    search's own steps 3-4 hand it back as the result, the refusal of the first count
    stands, with its count (tracked seed 3042 of bench_staircase_search.py: 12 steps for 13
    accepted so, its bar holding the true omega_dot at 80 % of the check times)."""
    from dataclasses import replace
    from measurement.kinematics import staircase_search
    from measurement.kinematics.model_fit import DriveFit
    from measurement.kinematics.sine_model import count_shifted
    t, th, _, _ = _record(9107, "trail")
    near = DriveFit(False, "residual rms 1.9 x the tracking noise (test)", rms_ratio=1.9)
    real = staircase_search._continuous
    counts = []

    def continuous(*args):      # the first count: step 2's fit refused
        found = real(*args)
        counts.append(found.stair.n)
        return replace(found, fit=DriveFit(False, "step 2 (test)", dict(found.fit.params)))

    def recounted(time, theta, sigma, found, dn, settings):   # step 2 passes another count
        stair, span = count_shifted(found.stair, found.span_steps, dn)
        return replace(found, stair=stair, span_steps=span, on_all_samples=True,
                       fit=DriveFit(True, "", dict(found.fit.params), rms_ratio=1.0))
    monkeypatch.setattr(staircase_search, "_continuous", continuous)
    monkeypatch.setattr(staircase_search, "_recounted", recounted)
    # steps 3-4 refuse every staircase near the limit (the real _finish around them)
    monkeypatch.setattr(FoundStaircaseInput, "_sample_time_found", lambda *a: (None, 0.0))
    monkeypatch.setattr(FoundStaircaseInput, "_loop_fit", lambda *a: near)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert fit is near and not fit.accepted
    assert fit.params["staircase_steps"] == counts[0]
    assert "the staircase found from the record: residual rms 1.9" in fit.why
    assert "tried again" not in fit.loop


def test_the_retry_keeps_the_count_where_it_fits_from_another_loop(monkeypatch):
    """A refused count is tried again from the grid's generic loops before any other count:
    where both would pass steps 3-4, the count found stands, and the loop text says it was
    tried again (tracked seed 4042 of bench_staircase_search.py: 11 steps refused in a
    wrong loop basin, and 10 steps accepted at 1.03x the noise with an omega_dot error of
    0.65 rad/s^2, ten times the right staircase's, before the same count was tried again)."""
    from measurement.kinematics import staircase_search
    from measurement.kinematics.model_fit import DriveFit
    t, th, _, _ = _record(9102, "lead")
    near = DriveFit(False, "residual not white (test)", rms_ratio=1.04)
    tried, first = [], []
    real = staircase_search._recounted

    def recounted(time, theta, sigma, found, dn, settings):
        tried.append(dn)
        return real(time, theta, sigma, found, dn, settings)

    def finish(self, t, th, sigma, found):
        if not tried:       # the first pass: refused near the limit
            first.append(found.stair.n)
            return near, 1.0 / FPS
        return DriveFit(True, "", dict(found.fit.params), rms_ratio=1.0), 1.0 / FPS
    monkeypatch.setattr(staircase_search, "_recounted", recounted)
    monkeypatch.setattr(FoundStaircaseInput, "_finish", finish)
    fit = FoundStaircaseInput().fit(t, th, SIGMA)
    assert fit.accepted and tried == [0]
    assert fit.params["staircase_steps"] == first[0]
    assert fit.params["staircase_count_change"] == 0.0
    assert fit.loop.endswith("(tried again from another loop)"), fit.loop


def test_a_drive_that_is_no_staircase_is_refused():
    """A profile drive (smooth acceleration bumps, the benchmark family's other kind): no
    staircase fits it to the noise, so the fit is refused, with the reason."""
    from twin.drives import DriveSpec, rotor_mu_req
    rng = np.random.default_rng(77)
    w0 = -TWO_PI * 9.0
    spec = DriveSpec(kind="profile", omega0=w0, tau_motor=0.01,
                     bumps=tuple((0.1 + 0.03 * k, 0.015, -400.0 * (0.5 + 0.1 * k))
                                 for k in range(6)),
                     base_accel=-60.0, base_t0=0.02, base_rise=0.1)
    t = np.arange(N_FRAMES) / FPS
    r = rotor_mu_req(spec, t)
    theta = 1.0 + r["theta"] + SIGMA * rng.standard_normal(t.size)
    fit = FoundStaircaseInput(sample_time_s=1.0 / FPS).fit(t, theta, SIGMA)
    assert not fit.accepted
    assert fit.why.startswith("the staircase found from the record") or "no staircase" in fit.why


def test_measure_finds_the_staircase_and_says_which(tmp_path, capsys):
    """``abu measure --tracks ... --kinematics drive-model --find-staircase``: accepted on a
    twin record, summary.json's estimator names the staircase found (steps, rounding)."""
    t, th, alpha, spec = _record(9102, "lead")
    _tracks_csv(tmp_path / "tracks.csv", t, th)
    out = tmp_path / "o"
    assert abu_main(["measure", str(tmp_path / "tracks.csv"), "--tracks", "--out", str(out),
                     "--quiet", "--no-plots", "--kinematics", "drive-model",
                     "--find-staircase", "--controller-sample-time", repr(1.0 / FPS)]) == 0, \
        capsys.readouterr().err
    est = json.loads((out / "summary.json").read_text())["estimator"]
    assert est["model"] == "accepted", est["why"]
    n = math.floor(abs(spec.omega_end - spec.omega0) / spec.step)
    assert f"over the staircase found from the record: {n} steps of 1 Hz, rounding lead" \
        in est["loop"]


@pytest.mark.parametrize("extra, option", [
    (["--te", "0.5"], "--te"),
    (["--omega0-hz", "-9"], "--omega0-hz"),
    (["--drive", "DRIVE"], "--drive"),
    (["--profile", "DRIVE"], "--profile"),
    (["--step-hz", "0"], "--step-hz"),
    (["--controller-sample-time", "-1"], "--controller-sample-time"),
    (["--kinematics", "savgol"], "--find-staircase"),
])
def test_find_staircase_refuses_what_it_cannot_use_by_name(tmp_path, capsys, extra, option):
    """A stated staircase, a drive or profile file, a step that is no step, a negative sample
    time, or no drive model: refused naming the option (exit 2), nothing written."""
    from controller.drive import Drive, dumps_drive
    (tmp_path / "drive.json").write_text(dumps_drive(Drive(model="pi-lag", zeta=0.8,
                                                           omega_n=15.0, tau_motor=0.01)))
    _tracks_csv(tmp_path / "tracks.csv", np.arange(400) / FPS, -50.0 * np.arange(400) / FPS)
    out = tmp_path / "o"
    extra = [str(tmp_path / "drive.json") if a == "DRIVE" else a for a in extra]
    kin = [] if "--kinematics" in extra else ["--kinematics", "drive-model"]
    status = abu_main(["measure", str(tmp_path / "tracks.csv"), "--tracks", "--out", str(out),
                       "--find-staircase"] + kin + extra)
    assert status == 2
    assert option in capsys.readouterr().err
    assert not out.exists()


@pytest.mark.parametrize("kwargs, field", [
    ({"step_rad_s": 0.0}, "step_rad_s"), ({"step_rad_s": float("nan")}, "step_rad_s"),
    ({"sample_time_s": -1e-3}, "sample_time_s"), ({"sample_time_s": float("inf")}, "sample_time_s"),
    ({"sample_time_s": "fast"}, "sample_time_s"),
])
def test_the_python_input_refuses_a_step_or_sample_time_that_makes_no_sense(kwargs, field):
    from abu_model.errors import ParameterError
    with pytest.raises(ParameterError, match=field):
        FoundStaircaseInput(**kwargs)


def test_progress_root_is_the_same_element_by_element_and_vectorised():
    """progress_root's two paths (Python floats for a staircase's few steps, NumPy for long
    arrays) agree to 1e-15 on random values and near both ends, where p is cubic."""
    from measurement.kinematics import staircase_guess
    rng = np.random.default_rng(17)
    y = np.r_[0.0, 1.0, 1e-15, 1.0 - 1e-15, rng.uniform(0, 1, 500), rng.uniform(0, 1e-5, 100),
              1.0 - rng.uniform(0, 1e-5, 100)]
    assert y.size > staircase_guess._SMALL
    whole = progress_root(y)
    pieces = np.concatenate([progress_root(y[i:i + 10]) for i in range(0, y.size, 10)])
    assert np.max(np.abs(whole - pieces)) <= 1e-15
    assert np.max(np.abs(progress(pieces) - y)) <= 1e-8
    assert progress_root(np.array(0.3)).shape == ()


@pytest.mark.parametrize("seed", range(10))
def test_timing_grid_interpolation_is_np_interp(seed):
    """The timing grid's index arithmetic (_add_delayed: a response delayed on its own grid;
    _on_grid: read at any positions) against np.interp with left=0 on the same grid: equal
    to 1e-9 of the values, delays from 0 past the grid's end, positions before, inside and
    past it."""
    from measurement.kinematics.staircase_guess import _add_delayed, _on_grid
    rng = np.random.default_rng([seed, 5])
    du = 1.0 / rng.uniform(2000, 20000)
    u = np.arange(int(rng.integers(50, 5000))) * du
    h = np.cumsum(rng.standard_normal(u.size))
    scale = float(np.max(np.abs(h)))
    for delay in np.r_[0.0, 1.0, rng.uniform(0, 1.2 * u.size, 20)]:
        out = np.zeros_like(u)
        _add_delayed(out, h, delay)
        ref = np.interp(u - delay * du, u, h, left=0.0)
        assert np.max(np.abs(out - ref)) <= 1e-9 * scale, delay
    x = rng.uniform(-0.2, 1.3, 2000) * u[-1]
    assert np.max(np.abs(_on_grid(x / du, h) - np.interp(x, u, h, left=0.0))) <= 1e-9 * scale
