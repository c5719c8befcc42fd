"""Harsh twin: drives on the plant, the random family, physical lighting, files and CLI.

Truths used: the plant's own closed forms (the rotor alone predicts the plant's rotor), the
commanded acceleration of a prescribed profile, the family's stated ranges, and the rendered
recording tracked back to the true marker centres.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pandas as pd
import pytest

from abu_model.errors import ParameterError
from abu_model.params import BallParams
from twin.drives import DriveSpec, profile_accel, rotor_mu_req, simulate_drive
from twin.truth_csv import AXIS_COLUMNS, TRUTH_COLUMNS, read_truth_csv
from twin.scenario import (random_scenario, render_scenario_frames,
                                  simulate_scenario)
from measurement.imaging.tracking import track_recording

TIMES = np.arange(1500) / 4500.0


@pytest.mark.parametrize("spec", [
    DriveSpec(),
    DriveSpec(setpoint_weight=0.6, setpoint_tau=0.01, tau_motor=0.0, rounding="trail",
              omega_n=25.0),
    DriveSpec(kind="profile", omega0=-60.0, tau_motor=0.012, base_accel=40.0,
              bumps=((0.05, 0.015, 120.0), (0.1, 0.02, 200.0), (0.15, 0.02, 260.0))),
])
def test_rotor_alone_predicts_the_plant(spec):
    """Stuck or slipping, the rotor does not feel the ball: the closed-form rotor equals the
    plant's rotor, and the plant's first switch is where mu_req first exceeds mu."""
    ball = BallParams(mu=0.02, mu_d=0.015)
    rot = rotor_mu_req(spec, TIMES, ball)
    st = simulate_drive(spec, ball, TIMES, beta0=1.0)
    np.testing.assert_allclose(st["omega"], rot["omega"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(st["theta"], rot["theta"], rtol=0, atol=1e-9)
    np.testing.assert_allclose(st["alpha"], rot["alpha"], rtol=0, atol=1e-7)
    above = np.flatnonzero(rot["mu_req"] > ball.mu)
    assert above.size and st["switches"].size
    # the first slip lies between the last frame below mu and the first frame above it
    assert TIMES[above[0] - 1] <= st["switches"][0] <= TIMES[above[0]] + 1e-12
    assert np.all(st["mode"][:above[0]] == 0) and st["mode"][above[0]] != 0
    # while stuck, beta does not move; in slip it grows (negative alpha: the ball lags behind)
    assert np.ptp(st["beta"][:above[0]]) == 0.0
    assert st["beta"][-1] > st["beta"][above[0]]


def test_profile_drive_applies_the_commanded_acceleration():
    spec = DriveSpec(kind="profile", omega0=-50.0, tau_motor=0.0, base_accel=30.0,
                     bumps=((0.05, 0.02, 100.0), (0.09, 0.02, 150.0)))
    rot = rotor_mu_req(spec, TIMES)
    a, _ = profile_accel(spec, TIMES)
    np.testing.assert_allclose(rot["alpha"], a, rtol=1e-12, atol=1e-9)
    # the speed is the integral of the acceleration (trapezoid on a 20x finer grid; the
    # drive holds the torque to first order between frames, a 2e-6 relative difference)
    tf = np.linspace(0.0, TIMES[-1], 20 * (TIMES.size - 1) + 1)
    af, _ = profile_accel(spec, tf)
    w = -50.0 + np.concatenate([[0.0], np.cumsum(0.5 * (af[1:] + af[:-1]) * np.diff(tf))])
    np.testing.assert_allclose(rot["omega"], w[::20], atol=5e-4)
    # with a torque lag the acceleration is continuous (no jumps between frames)
    lagged = rotor_mu_req(DriveSpec(**{**spec.__dict__, "tau_motor": 0.02}), TIMES)
    assert np.max(np.abs(np.diff(lagged["alpha"]))) < 2.0


def test_random_family_covers_its_ranges_and_is_reproducible():
    scns = [random_scenario(s, size=200) for s in range(40)]
    mu = np.array([s.ball.mu for s in scns])
    ratio = np.array([s.ball.mu_dynamic / s.ball.mu for s in scns])
    assert mu.min() >= 0.005 and mu.max() <= 0.06 and np.ptp(mu) > 0.035
    assert ratio.min() >= 0.6 and ratio.max() <= 1.0 and np.ptp(ratio) > 0.25
    kinds = {s.drive.kind for s in scns}
    lights = {s.lighting.kind for s in scns}
    roundings = {s.drive.rounding for s in scns if s.drive.kind == "staircase_pi"}
    assert kinds == {"staircase_pi", "profile"} and lights == {"ring", "two_spot"}
    assert roundings == {"lead", "nearest", "trail"}
    lags = np.array([s.drive.tau_motor for s in scns])
    assert lags.min() < 0.005 and lags.max() > 0.025 and lags.max() <= 0.03
    assert any(s.lighting.n_stray for s in scns) and not all(s.lighting.n_stray for s in scns)
    for s in scns:                                  # a slip is placed inside the recording
        assert 0.12 <= s.predicted_slip_s <= 0.55
    assert random_scenario(3, size=200) == scns[3]  # one seed, one scenario
    print(f"\n40 seeds: mu {mu.min():.4f}-{mu.max():.4f}, mu_d/mu {ratio.min():.2f}-"
          f"{ratio.max():.2f}, kinds {sorted(kinds)}, lightings {sorted(lights)}")


def test_bad_scenario_options_raise_parameter_errors():
    for kw, name in (({"size": 120}, "size"), ({"lighting": "neon"}, "lighting"),
                     ({"n_frames": 10}, "frames")):
        with pytest.raises(ParameterError, match=name):
            random_scenario(1, **kw)
    with pytest.raises(ParameterError, match="drive kind"):
        DriveSpec(kind="magic")
    with pytest.raises(ParameterError, match="bumps"):
        DriveSpec(kind="profile", bumps=((0.1, -0.01, 5.0),))


def _tangential_harmonics(phi: np.ndarray, err_t: np.ndarray, kmax: int = 5) -> np.ndarray:
    ok = np.isfinite(err_t)
    cols = [np.ones(ok.sum())]
    for k in range(1, kmax + 1):
        cols += [np.cos(k * phi[ok]), np.sin(k * phi[ok])]
    c, *_ = np.linalg.lstsq(np.array(cols).T, err_t[ok], rcond=None)
    return np.array([math.hypot(c[2 * k - 1], c[2 * k]) for k in range(1, kmax + 1)])


def test_rendered_recording_tracks_back_to_the_truth_and_the_ball_centre_has_harmonics():
    """Markers found within the lighting bias of the truth; the ball's apparent centre error
    is a function of its world angle with harmonics above the first (lamps fixed in the world,
    shaded by the channel wall), not noise and not one sine."""
    amps = []
    for seed in (0, 2):  # one ring-lit (with stray lamps), one two-spot recording
        scn = random_scenario(seed, size=200, n_frames=1200,
                              lighting="two_spot" if seed == 0 else "ring")
        st, pos = simulate_scenario(scn)
        frames = render_scenario_frames(scn, st, pos)
        assert frames.shape == (1200, 200, 200) and frames.dtype == np.uint8
        seeds = np.stack([pos["centre"][0], pos["cd"][0], pos["ball"][0]])
        tr = track_recording(frames, seeds)
        assert not tr.lost.any()
        for m, name in enumerate(("centre", "cd")):
            err = np.hypot(tr.x[:, m] - pos[name][:, 0], tr.y[:, m] - pos[name][:, 1])
            assert np.sqrt(np.mean(err ** 2)) < 0.1, name
        phi = st["theta"] + st["beta"]
        ex, ey = tr.x[:, 2] - pos["ball"][:, 0], tr.y[:, 2] - pos["ball"][:, 1]
        amp = _tangential_harmonics(phi, -np.sin(phi) * ex - np.cos(phi) * ey)
        amps.append(amp)
        print(f"\nseed {seed} ({scn.lighting.kind}, {scn.lighting.n_stray} stray lamps): "
              f"ball centre error harmonics k=1..5 [px] {np.round(amp, 3)}")
        assert amp[0] > 0.02                           # the lighting moves the apparent centre
    assert max(a[1:].max() / a[0] for a in amps) > 0.2  # ... with higher harmonics


def test_cli_renders_a_random_scenario(tmp_path):
    from abu.cli.main import main

    out = tmp_path / "r"
    assert main(["render", "--scenario", "random", "--seed", "5", "--size", "200",
                 "--frames", "1100", "--out", str(out), "--quiet"]) == 0
    meta = json.loads((out / "meta.json").read_text())
    scn = random_scenario(5, size=200, n_frames=1100)
    assert meta["scenario"] == "random" and meta["seed"] == 5
    assert meta["mu"] == scn.ball.mu and meta["mu_d"] == scn.ball.mu_dynamic
    assert meta["ball_reflections"] == scn.lighting.reflections
    for key in ("drive", "lighting", "optics", "geometry", "simulation", "seeds"):
        assert key in meta
    truth = pd.read_csv(out / "truth.csv")
    assert tuple(truth.columns) == TRUTH_COLUMNS + AXIS_COLUMNS and len(truth) == 1100
    first = int(np.flatnonzero(truth["mode"].to_numpy() != 0)[0])
    assert meta["simulation"]["first_slip_frame"] == first
    assert truth["time_s"][first - 1] <= meta["simulation"]["t_slip_s"] <= truth["time_s"][first]
    assert main(["render", "--scenario", "random", "--seed", "5", "--size", "150",
                 "--out", str(tmp_path / "bad"), "--quiet"]) == 2
    assert not (tmp_path / "bad").exists()


# --------------------------------------------------------------------------- optics and light


def test_lens_distortion_and_vignetting_closed_forms():
    from twin.optics import OpticsSpec, distort, half_diagonal, vignetting_map

    spec = OpticsSpec(k1=0.02, k2=-0.005, optical_centre=(99.5, 101.0), vignetting=0.3)
    rc = half_diagonal(200, 200)
    c = np.array(spec.optical_centre)
    pts = c + rc * np.array([[1.0, 0.0], [0.0, -0.5], [0.0, 0.0]])
    d = distort(pts, spec, 200, 200)
    np.testing.assert_allclose(d[0], c + rc * np.array([1 + 0.02 - 0.005, 0]), atol=1e-12)
    np.testing.assert_allclose(d[1], c + rc * np.array([0, -0.5 * (1 + 0.02 / 4 - 0.005 / 16)]),
                               atol=1e-12)
    np.testing.assert_allclose(d[2], c, atol=1e-12)            # the centre does not move
    v = vignetting_map(spec, 200, 200)
    assert v[101, 99] == pytest.approx(1 / (1 + 0.3 * (0.25 / rc ** 2)) ** 2, rel=1e-6)
    assert v[0, 0] == pytest.approx(1 / (1 + 0.3 * (99.5 ** 2 + 101 ** 2) / rc ** 2) ** 2,
                                    rel=1e-6)


def test_sensor_noise_flicker_and_column_pattern_follow_their_laws():
    """Flat radiance S: temporal variance = read^2 + S / gain (shot noise); frame means follow
    the 100 Hz flicker; column means carry the fixed column offsets, the same in every frame."""
    from twin.optics import OpticsSpec, Sensor

    spec = OpticsSpec(psf_sigma=0.0, vignetting=0.0, conversion_gain=4.0, read_noise=2.0,
                      column_offset_sigma=3.0, column_gain_sigma=0.0)
    S, n = 100.0, 400
    times = np.arange(n) / 4500.0
    sens = Sensor(spec, 64, 48, 0.1, 0.7, np.random.default_rng(3))
    out = sens.apply(np.full((n, 48, 64), S, dtype=np.float32), times).astype(float)
    gain = 1 + 0.1 * np.cos(2 * np.pi * 100 * times + 0.7)
    frame_means = out.mean(axis=(1, 2)) - sens.col_off.mean()
    np.testing.assert_allclose(frame_means, S * gain, atol=0.35)
    cols = (out / gain[:, None, None]).mean(axis=(0, 1))
    assert np.corrcoef(cols, sens.col_off)[0, 1] > 0.98
    flat = out - out.mean(axis=0)                                  # remove the fixed pattern
    flat -= (S * gain - S)[:, None, None]                          # and the flicker
    var = flat.var()
    expected = 2.0 ** 2 + S / 4.0 + 1 / 12.0                      # + quantisation
    assert var == pytest.approx(expected, rel=0.05)
    sat = sens.apply(np.full((2, 48, 64), 400.0, dtype=np.float32), times[:2])
    assert sat.max() == 255 and (sat == 255).mean() > 0.99          # saturation


def test_disk_sprite_area_and_centre():
    from twin.scene import Sprite, disk_sprite

    spr = Sprite(*disk_sprite(4.3))
    spr.B = spr.B[None]
    rng = np.random.default_rng(0)
    pos = 50 + rng.uniform(-0.5, 0.5, size=(20, 1, 2))
    vals, x0, y0 = spr.patch(pos, None, 100, 100)
    area = vals.sum(axis=(1, 2))
    np.testing.assert_allclose(area, np.pi * 4.3 ** 2, rtol=2e-3)
    P = vals.shape[-1]
    cx = (vals.sum(axis=1) * (x0[:, None] + np.arange(P))).sum(1) / area
    cy = (vals.sum(axis=2) * (y0[:, None] + np.arange(P))).sum(1) / area
    # bilinear look-ups between 1/8 px offsets: a few thousandths of a px (the tracker's
    # noise is 0.01 px, the lighting's bias 0.1 px)
    np.testing.assert_allclose(cx, pos[:, 0, 0], atol=5e-3)
    np.testing.assert_allclose(cy, pos[:, 0, 1], atol=5e-3)


def test_highlight_sits_where_the_normal_bisects_lamp_and_camera():
    """Glossy highlight of one distant lamp at elevation e, azimuth a (camera far above): the
    normal bisects them, tilt (90 deg - e) / 2, so the highlight's peak lies R sin(tilt) from
    the centre toward the lamp (independent closed form)."""
    from twin.lighting import Lamp, LightingSpec, ball_sprites

    R = 6.0
    for elev, az in ((math.radians(30), 0.4), (math.radians(60), 2.5)):
        far = 1e3
        lamp = Lamp((far * math.cos(elev) * math.cos(az), far * math.cos(elev) * math.sin(az),
                     far * math.sin(elev)), far ** 2)
        spec = LightingSpec("two_spot", (lamp,), 0.0, 1e6, 0.0, 1.0, 4000.0, 0.0, 0.0)
        spr, inside, half = ball_sprites(spec, 0.0115, R, 1.5e-3, n_phi=1, oversample=16)
        k = np.unravel_index(np.argmax(spr[0]), spr[0].shape)
        s = (np.arange(spr.shape[1]) + 0.5) / 16 - half
        x, y = s[k[1]], -s[k[0]]                      # world y up
        tilt = (math.pi / 2 - elev) / 2
        assert math.hypot(x, y) == pytest.approx(R * math.sin(tilt), abs=0.08)
        assert math.atan2(y, x) == pytest.approx(az, abs=0.03)


def test_channel_wall_hides_low_lamps_behind_it():
    from twin.lighting import LightingSpec, wall_visibility

    spec = LightingSpec("ring", (), 0.0, 0.2, 0.3, 1.0, 10.0, 0.0, 0.0, wall_height=2.5e-3,
                        wall_soft=0.3e-3)
    c = np.array([0.0115, 0.0, 1.5e-3])                          # ball at 3 o'clock
    assert wall_visibility(spec, c, np.array([0.0, 0.0, 0.2])) == 1.0          # above
    assert wall_visibility(spec, c, np.array([0.3, 0.0, 0.05])) == 0.0         # low, outside
    assert wall_visibility(spec, c, np.array([-0.3, 0.0, 0.05])) == 1.0        # across the axis
    assert wall_visibility(spec.__class__(**{**spec.__dict__, "wall_height": 0.0}), c,
                           np.array([0.3, 0.0, 0.05])) == 1.0


def test_truth_csv_old_column_names_still_read(tmp_path):
    """truth.csv files written before the spelling was unified (centre_x_px, ...) read back
    under the new names, the same numbers."""
    values = {name: np.arange(3.0) + j for j, name in enumerate(TRUTH_COLUMNS)}
    from twin.truth_csv import OLD_NAMES, truth_csv_text
    text = truth_csv_text(TRUTH_COLUMNS, values)
    new_to_old = {v: k for k, v in OLD_NAMES.items()}
    head, body = text.split("\n", 1)
    old = ",".join(new_to_old.get(h, h) for h in head.split(",")) + "\n" + body
    assert "centre_x_px" in old
    (tmp_path / "new.csv").write_text(text)
    (tmp_path / "old.csv").write_text(old)
    a, b = read_truth_csv(tmp_path / "new.csv"), read_truth_csv(tmp_path / "old.csv")
    assert list(a) == list(b) == list(TRUTH_COLUMNS)
    for name in TRUTH_COLUMNS:
        np.testing.assert_array_equal(a[name], b[name])
