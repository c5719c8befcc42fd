"""Synthetic camera: geometry and sign convention, exact disk areas, lighting, noise, blur."""
from __future__ import annotations

import math

import numpy as np
import pytest

from abu_model.errors import ParameterError
from twin.render import (CameraGeometry, MarkerStyle, RenderSettings, angles_from_pixels,
                                lighting_image, render_frames, render_markers)
from measurement.imaging.tracking import track_recording

QUIET = dict(width=64, height=64, background=50.0, gradient=0.0, noise_sigma=0.0)


def centroid(img: np.ndarray, background: float) -> tuple[float, float, float, float, float]:
    """Sum, centroid x, y and variances of (img - background) [grey levels, px, px^2]."""
    w = img.astype(float) - background
    yy, xx = np.mgrid[0:img.shape[0], 0:img.shape[1]]
    s = w.sum()
    cx, cy = (w * xx).sum() / s, (w * yy).sum() / s
    return s, cx, cy, (w * (xx - cx) ** 2).sum() / s, (w * (yy - cy) ** 2).sum() / s


def test_geometry_round_trip_and_clockwise_sign():
    geo = CameraGeometry(pixel_size=0.25e-3, centre_x=120.2, centre_y=131.7, r_cd=0.028,
                         l=1.15e-2)
    t = np.linspace(0.0, 0.3, 400)
    theta = 0.3 - 2 * np.pi * 12.0 * t - 40.0 * t ** 2   # several clockwise turns
    beta = 0.8 + 2.5 * t ** 2                              # the ball slips forward
    c, p, b = geo.marker_positions(theta, beta)
    np.testing.assert_allclose(np.hypot(*(p - c).T), geo.r_cd_px, rtol=1e-12)
    np.testing.assert_allclose(np.hypot(*(b - c).T), geo.l_px, rtol=1e-12)
    th, be = angles_from_pixels(c, p, b)
    # unwrapped theta reproduces the simulation's, offset by a whole number of turns at most
    k = np.round((th[0] - theta[0]) / (2 * np.pi))
    np.testing.assert_allclose(th - 2 * np.pi * k, theta, atol=1e-12)
    np.testing.assert_allclose(be, beta, atol=1e-12)
    # clockwise on screen: from 3 o'clock (right of the axis) the CD marker moves DOWN the image
    c, p, _ = geo.marker_positions(np.array([0.0, -0.05]), np.zeros(2))
    assert p[0, 0] > c[0, 0] and abs(p[0, 1] - c[0, 1]) < 1e-12
    assert p[1, 1] > p[0, 1]           # image rows grow downward
    # and negative omega from finite differences of the recovered theta
    assert np.all(np.diff(th) < 0)


def test_disk_area_and_centre_are_exact():
    """Supersampled coverage: the marker's grey-level mass is contrast * pi r^2, centred on truth."""
    rng = np.random.default_rng(0)
    settings = RenderSettings(**QUIET)
    for radius in (3.3, 5.0, 7.2):
        true = 32.0 + rng.uniform(-0.5, 0.5, size=(1, 1, 2))
        img = render_markers(true, [MarkerStyle(radius, 170.0)], settings, 0)[0]
        s, cx, cy, _, _ = centroid(img, 50.0)
        assert s == pytest.approx(120.0 * math.pi * radius ** 2, rel=3e-3)
        assert abs(cx - true[0, 0, 0]) < 0.01 and abs(cy - true[0, 0, 1]) < 0.01
        assert img.max() == 170 and img.min() == 50


def test_lighting_gradient_direction_and_slope():
    settings = RenderSettings(width=40, height=30, background=100.0, gradient=1.5,
                              gradient_direction=math.pi / 3, noise_sigma=0.0)
    img = lighting_image(settings)
    # grey level grows toward +x and toward the TOP of the image (y up on screen)
    np.testing.assert_allclose(np.diff(img, axis=1), 1.5 * math.cos(math.pi / 3), atol=1e-4)
    np.testing.assert_allclose(np.diff(img, axis=0), -1.5 * math.sin(math.pi / 3), atol=1e-4)
    assert img[14:16, 19:21].mean() == pytest.approx(100.0, abs=1e-4)  # centre level
    off_image = np.full((1, 3, 2), -500.0)
    frame = render_frames(off_image[:, 0], off_image[:, 1], off_image[:, 2], settings, 0)[0]
    np.testing.assert_array_equal(frame, np.clip(np.rint(img), 0, 255).astype(np.uint8))


def test_noise_quantisation_and_seed():
    settings = RenderSettings(width=64, height=64, background=100.0, gradient=0.0,
                              noise_sigma=4.0)
    far = np.full((3, 1, 2), -500.0)
    a = render_markers(far, [MarkerStyle(4.0, 200.0)], settings, 1)
    b = render_markers(far, [MarkerStyle(4.0, 200.0)], settings, 1)
    c = render_markers(far, [MarkerStyle(4.0, 200.0)], settings, 2)
    np.testing.assert_array_equal(a, b)
    assert (a != c).mean() > 0.5
    # rounding adds 1/12 grey level^2 of variance to the sensor noise
    assert a.std() == pytest.approx(math.sqrt(16.0 + 1.0 / 12.0), rel=0.02)
    assert a.mean() == pytest.approx(100.0, abs=4 * 4.0 / math.sqrt(a.size))  # 4 standard errors
    # clipping: a marker brighter than white saturates at 255, darker than black at 0
    bright = render_markers(np.array([[[32.0, 32.0], [10.0, 10.0]]]),
                            [MarkerStyle(6.0, 400.0), MarkerStyle(4.0, -300.0)],
                            RenderSettings(**QUIET), 0)[0]
    assert bright[32, 32] == 255 and bright[10, 10] == 0


def test_motion_blur_spreads_along_the_motion_only():
    """Linear motion of v px/frame, exposure fraction f, S sub-frames: the blurred blob is the
    mean of S still disks spaced v f / S apart, so its x variance exceeds theirs by
    (v f)^2 (S^2 - 1) / (12 S^2); its centroid stays at the frame-time position."""
    v, f, S = 4.0, 0.5, 7
    n = 9
    true = np.stack([20.0 + v * np.arange(n), np.full(n, 31.3)], axis=1)[:, None, :]
    still = RenderSettings(**QUIET)
    blur = still.with_(exposure_fraction=f, blur_samples=S)
    style = [MarkerStyle(5.0, 170.0)]
    b = render_markers(true, style, blur, 0, chunk=4)
    offsets = ((np.arange(S) + 0.5) / S - 0.5) * f * v  # sub-frame displacements [px]
    for k in (3, 5):
        subs = true[k, 0] + np.stack([offsets, np.zeros(S)], axis=1)
        stills = render_markers(subs[:, None, :], style, still, 0)
        moments = np.array([centroid(img, 50.0) for img in stills])
        sb, xb, yb, vxb, vyb = centroid(b[k], 50.0)
        assert sb == pytest.approx(moments[:, 0].mean(), rel=3e-3)
        assert xb == pytest.approx(true[k, 0, 0], abs=0.01)
        assert yb == pytest.approx(true[k, 0, 1], abs=0.01)
        spread = (v * f) ** 2 * (S * S - 1) / (12.0 * S * S)
        assert spread == pytest.approx(np.var(offsets))
        assert vxb == pytest.approx(moments[:, 3].mean() + spread, abs=0.01)
        assert vyb == pytest.approx(moments[:, 4].mean(), abs=0.01)
        assert vxb - moments[:, 3].mean() > 0.3  # the blur is there


def test_ball_lighting_offset_is_a_harmonic_of_the_absolute_angle():
    """A fixed apparent offset A toward the lamp at psi shows in beta as
    (A / l_px) sin(psi - phi), phi = theta + beta: at the rotation frequency."""
    geo = CameraGeometry()
    settings = RenderSettings(ball_shift_px=0.6, light_direction=2.2, noise_sigma=0.0,
                              gradient=0.0)
    n = 240  # one clockwise turn, 2.6 px/frame at the CD marker
    theta = -np.linspace(0.0, 2 * np.pi, n, endpoint=False)
    beta = np.full(n, 1.0)
    c, p, b = geo.marker_positions(theta, beta)
    frames = render_frames(c, p, b, settings, seed=0)
    # the rendered ball's grey-level centroid is the true centre plus the offset vector
    shift = settings.ball_shift_vector
    assert shift[0] == pytest.approx(0.6 * math.cos(2.2)) and shift[1] < 0  # lamp up-left
    for k in (0, 70, 150):
        x0, y0 = np.rint(b[k]).astype(int) - 10
        win = frames[k, y0:y0 + 21, x0:x0 + 21]
        _, cx, cy, _, _ = centroid(win, settings.background)
        assert cx + x0 == pytest.approx(b[k, 0] + shift[0], abs=0.01)
        assert cy + y0 == pytest.approx(b[k, 1] + shift[1], abs=0.01)
    tracks = track_recording(frames, np.stack([c[0], p[0], b[0]]))
    assert not tracks.lost.any()
    _, beta_seen = angles_from_pixels(tracks.xy(0), tracks.xy(1), tracks.xy(2))
    phi = theta + beta
    expected = 0.6 / geo.l_px * np.sin(2.2 - phi)
    np.testing.assert_allclose(beta_seen - beta, expected, atol=0.02 / geo.l_px * 3)


def test_bad_settings_and_inputs():
    with pytest.raises(ParameterError, match="noise_sigma"):
        RenderSettings(noise_sigma=-1.0)
    with pytest.raises(ParameterError, match="exposure_fraction"):
        RenderSettings(exposure_fraction=1.5)
    with pytest.raises(ParameterError, match="radius_px"):
        MarkerStyle(0.0, 100.0)
    with pytest.raises(ParameterError, match="marker positions"):
        render_frames(np.zeros((3, 2)), np.zeros((3, 2)), np.zeros((2, 2)))
    with pytest.raises(ParameterError, match="positions"):
        render_markers(np.full((2, 1, 2), np.nan), [MarkerStyle(3.0, 100.0)], RenderSettings())
    with pytest.raises(ParameterError, match="pixel_size"):
        CameraGeometry(pixel_size=0.0)


# --- digital twin ---------------------------------------------------------------------------


def test_sample_at_frames_takes_rows_and_interpolates_between():
    """Rows on frame times are taken as they are (right limits at jumps); between rows the
    cubic Hermite interpolant reproduces a cubic theta(t) exactly."""
    from twin.report_twin import TwinError, sample_at_frames

    t = np.array([0.0, 0.1, 0.2, 0.2, 0.3, 0.4])
    side = np.array([0, 0, -1, 1, 0, 0])

    def theta(x):
        return 1.0 - 2.0 * x + 3.0 * x ** 2 - 4.0 * x ** 3

    def omega(x):
        return -2.0 + 6.0 * x - 12.0 * x ** 2

    table = {"time": t, "side": side, "theta": theta(t), "omega": omega(t),
             "alpha": 6.0 - 24.0 * t, "beta": 0.5 * t, "beta_dot": np.full(6, 0.5),
             "mu_req": t / 10, "mode": np.array([0, 0, 0, 1, 1, 1]),
             "omega_ref": np.array([1.0, 1.0, 1.0, 2.0, 2.0, 2.0])}
    times = np.array([0.0, 0.05, 0.2, 0.27, 0.4])
    st = sample_at_frames(table, times)
    np.testing.assert_allclose(st["theta"], theta(times), atol=1e-12)
    np.testing.assert_allclose(st["beta"], 0.5 * times, atol=1e-12)
    np.testing.assert_array_equal(st["mode"], [0, 0, 1, 1, 1])       # right limit at 0.2
    np.testing.assert_array_equal(st["omega_ref"], [1, 1, 2, 2, 2])
    with pytest.raises(TwinError, match=r"covers \[0, 0.4\] s"):
        sample_at_frames(table, np.array([0.0, 0.5]))


def test_twin_drive_reproduces_the_reports_recordings(fmu_dir):
    """Default twin (report sec. 5.3, mu = 0.03): stick first, slip inside the report's window
    t_slip in [0.10, 0.33] s, omega on the staircase, acceleration of the order the report's
    bounds imply; the identified loop (zeta 0.5, omega_n 2.2 rad/s) cannot do that."""
    from controller.reference import Staircase
    from twin.report_twin import DriveSettings, TwinSettings, simulate_twin

    s = TwinSettings()
    state, (centre, cd, ball), _ = simulate_twin(s, fmu_dir=fmu_dir)
    t = s.frame_times
    mode = state["mode"]
    assert np.all(mode[t < 0.12] == 0)                       # the first steps: stick
    slip = t[np.flatnonzero(mode != 0)[0]]
    assert 0.10 <= slip <= 0.33
    assert np.ptp(state["beta"]) > 0.05                       # a visible slip [rad]
    ref = Staircase(s.omega0, s.omega_end, s.t0, s.te, s.drive.step, s.drive.rounding)
    assert np.max(np.abs(state["omega"] - ref.values(t))) < 2.5 * 2 * np.pi
    # report: mu_1 = 0.0286 at t1 = 0.160 s, mu_2 = 0.0312 at t2 = 0.245 s, with
    # |omega_dot| = mu l omega^2 / (l - d/5) on the staircase's omega
    lever = s.ball.lever_ratio
    a1 = 0.0286 * ref.value(0.160) ** 2 / lever
    a2 = 0.0312 * ref.value(0.245) ** 2 / lever
    peak = np.max(np.abs(state["alpha"][(t > 0.1) & (t < 0.35)]))
    assert 0.8 * a1 <= peak <= 1.6 * a2
    # the geometry of the rendered markers follows theta and beta
    th, be = angles_from_pixels(centre, cd, ball)
    np.testing.assert_allclose(th, state["theta"], atol=1e-9)
    np.testing.assert_allclose(be, state["beta"], atol=1e-9)
    # the identified loop lags the staircase by several Hz and never makes the ball slip
    slow, _, _ = simulate_twin(s.with_(drive=DriveSettings(zeta=0.5, omega_n=2.2, tau_motor=0.0)),
                               fmu_dir=fmu_dir)
    assert np.all(slow["mode"] == 0)
    assert np.max(np.abs(slow["omega"] - ref.values(t))) > 4.0 * 2 * np.pi


def test_render_twin_writes_a_trackable_recording(fmu_dir, tmp_path):
    import json

    from measurement.imaging.frames_io import read_recording
    from measurement.imaging.markers import parse_seeds
    from twin.report_twin import TRUTH_COLUMNS, TwinSettings, render_twin

    s = TwinSettings(n_frames=300, record_start=0.19)  # around the slip at ~0.20 s
    out = render_twin(tmp_path / "twin", s, fmu_dir=fmu_dir)
    assert sorted(f.name for f in out.iterdir()) == ["frames.tif", "meta.json", "truth.csv"]
    rec = read_recording(out / "frames.tif")
    assert rec.shape == (300, 256, 256)
    header = (out / "truth.csv").read_text().splitlines()[0].split(",")
    assert tuple(header) == TRUTH_COLUMNS
    truth = np.genfromtxt(out / "truth.csv", delimiter=",", names=True)
    np.testing.assert_allclose(truth["time_s"], 0.19 + np.arange(300) / 4500.0, atol=1e-12)
    assert set(np.unique(truth["mode"])) == {0.0, 1.0}      # stick, then slip
    meta = json.loads((out / "meta.json").read_text())
    assert meta["fps"] == 4500.0 and meta["mu"] == 0.03 and meta["seed"] == 0
    assert meta["drive"] == {**meta["drive"], "zeta": 0.7, "omega_n_rad_s": 12.0,
                             "tau_motor_s": 0.02}
    assert meta["geometry"]["l_m"] == 1.15e-2 and meta["geometry"]["pixel_size_m_per_px"] > 0
    assert meta["render"]["exposure_fraction"] == 0.25
    tracks = track_recording(rec.frames, parse_seeds(meta["seeds"]))
    assert not tracks.lost.any()
    for m, (cx, cy) in enumerate([("x_center_px", "y_center_px"), ("x_cd_px", "y_cd_px"),
                                  ("x_ball_apparent_px", "y_ball_apparent_px")]):
        e = np.hypot(tracks.x[:, m] - truth[cx], tracks.y[:, m] - truth[cy])
        assert np.sqrt(np.mean(e ** 2)) < 0.02, m
    th, be = angles_from_pixels(tracks.xy(0), tracks.xy(1), tracks.xy(2))
    l_px = meta["geometry"]["l_px"]
    # beta carries the lighting harmonic (ball_shift_px / l_px) plus tracking noise
    assert np.max(np.abs(be - truth["beta_rad"])) < (0.5 + 0.06) / l_px
    k = np.round((th[0] - truth["theta_rad"][0]) / (2 * np.pi))
    assert np.max(np.abs(th - 2 * np.pi * k - truth["theta_rad"])) < 0.06 / meta["geometry"]["r_cd_px"]
