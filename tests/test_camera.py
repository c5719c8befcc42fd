"""Camera calibration: the twin's chessboard views, OpenCV's calibration, undistorted tracks.

Truths used: the twin's lens model (twin.optics.distort) and its drawn optics (k1, k2,
optical centre), the true corner and marker positions it renders, OpenCV's own radial model
(cv2.undistortPoints with f = the half diagonal), and the true mu of rendered recordings.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from measurement.imaging import camera as cam_mod
from measurement.imaging import camera_calibration as calib
from twin.calibration_target import render_views, undistort_map
from abu.cli.main import main
from twin.optics import OpticsSpec, distort, half_diagonal
from twin.scenario import random_scenario

CAL_SEEDS = range(200, 208)
VIEWS = 16


def test_inverse_map_round_trips_and_is_opencvs_model():
    """undistort_map inverts the twin's distortion to 1e-9 px over the whole frame, and
    OpenCV's radial model with f = the half diagonal and c = the optical centre is the same
    map (cv2.undistortPoints agrees to 1e-6 px)."""
    import cv2

    spec = OpticsSpec(k1=0.03, k2=-0.01, optical_centre=(131.0, 122.5))
    yy, xx = np.mgrid[0:256:5, 0:256:5].astype(float)
    p = np.stack([xx, yy], axis=-1)
    u = undistort_map(p, spec, 256, 256)
    assert np.abs(distort(u, spec, 256, 256) - p).max() < 1e-9
    assert np.hypot(*(u - p).reshape(-1, 2).T).max() > 3.0  # a real distortion (corners)
    f = half_diagonal(256, 256)
    k = np.array([[f, 0, 131.0], [0, f, 122.5], [0, 0, 1]])
    cam = cam_mod.Camera(k, np.array([0.03, -0.01, 0, 0, 0]), (256, 256), 0.0, 1)
    ux, uy = cam_mod.undistort_pixels(p[..., 0], p[..., 1], cam)
    assert np.abs(np.stack([ux, uy], -1) - u).max() < 1e-6
    pts = cv2.undistortPoints(p.reshape(-1, 1, 2), k, np.array([0.03, -0.01, 0, 0]), P=k)
    assert np.abs(pts.reshape(u.shape) - u).max() < 2e-3  # OpenCV's default 5 iterations


def _marker_error(scn, cam) -> tuple[float, float]:
    """Largest error [px] of undistorted CD / ball centres on their circles (as observed
    through the twin's lens) against the ideal ones: raw, and with the common shift removed
    (theta and beta do not see a shift: the axis is fitted)."""
    th = np.linspace(0, 2 * np.pi, 120, endpoint=False)
    errs = []
    for r in (scn.r_cd / scn.pixel_size, scn.ball.l / scn.pixel_size):
        ideal = np.column_stack([scn.axis_xy[0] + r * np.cos(th), scn.axis_xy[1] - r * np.sin(th)])
        obs = distort(ideal, scn.optics, scn.width, scn.height)
        ux, uy = cam_mod.undistort_pixels(obs[:, 0], obs[:, 1], cam)
        errs.append(np.stack([ux, uy], -1) - ideal)
    e = np.concatenate(errs)
    return float(np.hypot(*e.T).max()), float(np.hypot(*(e - e.mean(0)).T).max())


def test_calibration_recovers_the_lens_on_random_optics():
    """On 8 seeded optics of the harsh family (k1 in +-0.03, k2 in +-0.01, centre +-5 px off
    the frame centre), 16 views: k1 within 2e-3, k2 within 6e-3 and each of (cx, cy, k1, k2)
    within 4 of its stated sigma (the covariance in the camera file); the optical centre within
    3 px where the distortion is strong enough to show it (|k1| >= 0.015); undistorted marker
    centres within 0.05 px of the ideal ones (common shift removed) and 0.08 px raw."""
    rows = []
    for seed in CAL_SEEDS:
        scn = random_scenario(seed)
        o = scn.optics
        frames, corners, _ = render_views(o, scn.width, scn.height, VIEWS, seed)
        cam, views = calib.calibrate_from_frames(frames, (9, 6))
        k = cam.camera_matrix
        err = np.array([k[0, 2] - o.optical_centre[0], k[1, 2] - o.optical_centre[1],
                        cam.dist_coeffs[0] - o.k1, cam.dist_coeffs[1] - o.k2])
        z = err / np.sqrt(np.diag(cam.covariance))
        raw, shifted = _marker_error(scn, cam)
        rows.append((seed, o.k1, o.k2, err, z, cam.rms_px, cam.n_views, raw, shifted))
        print(f"seed {seed}: k1 {o.k1:+.4f} err {err[2]:+.1e}, k2 {o.k2:+.4f} err {err[3]:+.1e}, "
              f"centre err ({err[0]:+.2f}, {err[1]:+.2f}) px, z {np.round(z, 1)}, RMS "
              f"{cam.rms_px:.3f} px, {cam.n_views}/{VIEWS} views, marker error {raw:.3f} px "
              f"({shifted:.3f} px without the common shift)")
    for seed, k1, k2, err, z, rms, nv, raw, shifted in rows:
        assert abs(err[2]) < 2e-3 and abs(err[3]) < 6e-3, seed
        assert np.all(np.abs(z) < 4.0), (seed, z)
        if abs(k1) >= 0.015:
            assert math.hypot(err[0], err[1]) < 3.0, seed
        assert shifted < 0.05 and raw < 0.08, (seed, raw, shifted)
        assert nv >= VIEWS - 2 and rms < 0.08


def test_bad_camera_files_are_named(tmp_path):
    good = cam_mod.Camera(np.array([[181.0, 0, 128], [0, 181.0, 127], [0, 0, 1]]),
                          np.array([0.01, 0.0, 0, 0, 0]), (256, 256), 0.03, 20,
                          covariance=np.eye(4) * 1e-6)
    path = tmp_path / "cam.json"
    cam_mod.write_camera(path, good)
    back = cam_mod.read_camera(path)
    np.testing.assert_array_equal(back.camera_matrix, good.camera_matrix)
    assert back.rms_px == 0.03 and back.image_size == (256, 256)
    base = json.loads(path.read_text())
    cases = [
        ({"kind": "abu-measure-summary"}, "'kind'"),
        ({"format_version": 9}, "'format_version'"),
        ({"camera_matrix": [[1, 0], [0, 1]]}, "'camera_matrix'"),
        ({"camera_matrix": [[-5, 0, 1], [0, 5, 1], [0, 0, 1]]}, "fx > 0"),
        ({"dist_coeffs": [0.1, "x", 0, 0]}, "'dist_coeffs'"),
        ({"dist_coeffs": [0.1, 0.2, 0.3]}, "'dist_coeffs'"),
        ({"image_size_px": [256]}, "'image_size_px'"),
        ({"reprojection_rms_px": -1}, "'reprojection_rms_px'"),
        ({"distortion_covariance": {"parameters": ["a"], "matrix": []}}, "parameters"),
        # not PSD: a negative variance along (1, -1) would shrink theta's prior
        ({"distortion_covariance": {"parameters": list(cam_mod.COV_PARAMETERS),
                                    "matrix": (np.eye(4) + 2 * np.eye(4)[::-1]).tolist()}},
         "'distortion_covariance.matrix'.*positive semi-definite"),
        ({"reprojection_rms_px": float("nan")}, "NaN is not JSON"),
        ({"reprojection_rms_px": 1e300}, "'reprojection_rms_px'"),
        ({"n_corners": "many"}, "'n_corners'"),
        ({"n_corners": 1.5}, "'n_corners'"),
        ({"image_size_px": [True, True]}, "'image_size_px'"),
        ({"image_size_px": [1e300, 256]}, "'image_size_px'"),
        ({"n_views": 1e300}, "'n_views'"),
        ({"format_version": True}, "'format_version'"),
        ({"camera_matrix": [[1e300, 0, 128], [0, 1e300, 127], [0, 0, 1]]}, "at most 1e6"),
        # folds over inside the image: undistortion would silently pick a wrong root
        ({"dist_coeffs": [-3.0, 0, 0, 0, 0]}, "'dist_coeffs'.*invertible over the 256x256"),
        ({"dist_coeffs": [1e300, 0, 0, 0, 0]}, "'dist_coeffs'.*invertible"),
    ]
    for change, needle in cases:
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({**base, **change}))
        with pytest.raises(cam_mod.CameraError, match=needle) as info:
            cam_mod.read_camera(bad)
        assert str(bad) in str(info.value)
    for key in ("camera_matrix", "dist_coeffs", "image_size_px", "reprojection_rms_px",
                "n_views"):
        bad = tmp_path / "bad.json"
        bad.write_text(json.dumps({k: v for k, v in base.items() if k != key}))
        with pytest.raises(cam_mod.CameraError, match=f"missing field '{key}'"):
            cam_mod.read_camera(bad)
    (tmp_path / "broken.json").write_text("{not json")
    with pytest.raises(cam_mod.CameraError, match="not JSON"):
        cam_mod.read_camera(tmp_path / "broken.json")
    with pytest.raises(cam_mod.CameraError, match="not found"):
        cam_mod.read_camera(tmp_path / "missing.json")


def test_too_few_corners_is_refused(tmp_path, capsys):
    """Blank views, the wrong pattern or a bad --pattern: exit 2, one clear line, no file."""
    import cv2

    views = tmp_path / "views"
    views.mkdir()
    for i in range(5):
        cv2.imwrite(str(views / f"v{i}.png"), np.full((120, 160), 128, np.uint8))
    with pytest.raises(cam_mod.CameraError, match="found whole in 0 of 5 views"):
        calib.calibrate_from_frames(np.full((5, 120, 160), 128, np.uint8), (9, 6))
    out = tmp_path / "cam.json"
    assert main(["calibrate-camera", str(views), "--out", str(out)]) == 2
    assert "at least 4 are needed" in capsys.readouterr().err
    assert main(["calibrate-camera", str(views), "--pattern", "9by6", "--out", str(out)]) == 2
    assert "--pattern" in capsys.readouterr().err
    frames, _, _ = render_views(OpticsSpec(k1=0.01), 256, 256, 4, 1)
    for i, f in enumerate(frames):
        cv2.imwrite(str(views / f"v{i}.png"), f)
    # the plate has 9x6 inner corners: asking for 8x5 finds a different grid or none
    assert main(["calibrate-camera", str(views), "--pattern", "11x7", "--out", str(out)]) == 2
    assert not out.exists() and not list(tmp_path.glob(".cam.json*"))
    # colour views are read as grey (frames_io): the same camera as from the grey views
    colour = tmp_path / "colour"
    colour.mkdir()
    for i, f in enumerate(frames):
        cv2.imwrite(str(colour / f"v{i}.png"), cv2.cvtColor(f, cv2.COLOR_GRAY2BGR))
    grey_cam, _ = calib.calibrate_from_frames(frames, (9, 6))
    assert main(["calibrate-camera", str(colour), "--out", str(tmp_path / "c.json")]) == 0
    assert cam_mod.read_camera(tmp_path / "c.json").dist_coeffs[0] == \
        pytest.approx(grey_cam.dist_coeffs[0], rel=1e-6)
    # a file that is no recording, an unreadable image: named, exit 2, no file
    notes = tmp_path / "notes.txt"
    notes.write_text("not images")
    broken = tmp_path / "broken"
    broken.mkdir()
    (broken / "v0.png").write_text("not a PNG")
    for src, needle in ((notes, "notes.txt"), (broken, "v0.png")):
        capsys.readouterr()
        assert main(["calibrate-camera", str(src), "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert needle in err and "Traceback" not in err, err
    assert not out.exists()
    with pytest.raises(cam_mod.CameraError, match="8-bit grey"):
        calib.calibrate_from_frames(np.stack([frames] * 3, axis=-1), (9, 6))


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Three small rendered recordings with their calibration views (abu render)."""
    base = tmp_path_factory.mktemp("cam_rec")
    recs = []
    for seed in (5, 11, 23):
        rec = base / f"rec{seed}"
        assert main(["render", "--scenario", "random", "--seed", str(seed), "--size", "200",
                     "--frames", "1200", "--calibration-views", str(VIEWS), "--out", str(rec),
                     "--quiet"]) == 0
        recs.append(rec)
    return recs


def test_measure_with_the_camera_is_narrower_and_holds_mu(rendered, tmp_path, capsys):
    """abu calibrate-camera on the twin's views, then abu measure with and without --camera:
    every interval holds the true mu; with the camera the theta-harmonic prior is the
    calibration's and the intervals are narrower (each of the three)."""
    widths = []
    for rec in rendered:
        meta = json.loads((rec / "meta.json").read_text())
        mu, l = meta["mu"], meta["geometry"]["l_m"]
        cam = tmp_path / f"{rec.name}.json"
        assert main(["calibrate-camera", str(rec / "calibration"), "--out", str(cam)]) == 0
        s = {}
        for tag, extra in (("plain", []), ("camera", ["--camera", str(cam)])):
            out = tmp_path / f"{rec.name}_{tag}"
            assert main(["measure", str(rec), "--out", str(out), "--no-plots", "--quiet",
                         "--l", repr(l), *extra]) == 0
            s[tag] = json.loads((out / "summary.json").read_text())
        capsys.readouterr()
        c = s["camera"]["camera"]
        prior = c["theta_harmonic_prior"]["theta_harmonic_rad"]
        w = {t: s[t]["relative_width"] for t in s}
        widths.append((w["plain"], w["camera"]))
        with capsys.disabled():
            print(f"{rec.name}: mu {mu:.5f}; plain [{s['plain']['mu_low']:.5f}, "
                  f"{s['plain']['mu_high']:.5f}] width {100 * w['plain']:.1f} %; camera "
                  f"[{s['camera']['mu_low']:.5f}, {s['camera']['mu_high']:.5f}] width "
                  f"{100 * w['camera']:.1f} %, prior {prior:.1e} rad, calibration RMS "
                  f"{c['reprojection_rms_px']:.3f} px")
        assert c["file"] == str(cam) and c["reprojection_rms_px"] < 0.08
        assert 0 < prior < 2e-3
        for t in s:
            assert s[t]["status"] == "ok" and s[t]["mu_low"] <= mu <= s[t]["mu_high"], (rec, t)
        assert "camera" not in s["plain"]
    assert all(cam_w < plain_w for plain_w, cam_w in widths)
    # tracks.csv keeps the tracker's (distorted) positions: --tracks --camera repeats the result
    again = tmp_path / "again"
    assert main(["measure", str(tmp_path / f"{rec.name}_camera" / "tracks.csv"), "--tracks",
                 "--camera", str(cam), "--out", str(again), "--no-plots", "--quiet",
                 "--l", repr(l)]) == 0
    s2 = json.loads((again / "summary.json").read_text())
    assert s2["mu_low"] == pytest.approx(s["camera"]["mu_low"], rel=1e-9)
    assert s2["mu_high"] == pytest.approx(s["camera"]["mu_high"], rel=1e-9)


def test_design_predicts_the_prior_abu_measure_states(rendered, tmp_path, capsys):
    """``abu design --camera`` before a recording, ``abu measure --camera`` after it: at the
    recording's CD circle the design's lens prior is the one the measurement states, and the
    default circle (the image centre, 0.37 of the side) gives it within a factor 1.5 on the
    twin's recordings (framed like the report's)."""
    for rec in rendered:
        cam = tmp_path / f"{rec.name}.json"
        assert main(["calibrate-camera", str(rec / "calibration"), "--out", str(cam)]) == 0
        out = tmp_path / f"{rec.name}_m"
        assert main(["measure", str(rec), "--out", str(out), "--no-plots", "--quiet",
                     "--camera", str(cam)]) == 0
        c = json.loads((out / "summary.json").read_text())["camera"]
        measured = c["theta_harmonic_prior"]["theta_harmonic_rad"]
        circle = ",".join(repr(v) for v in (*c["axis_px"], c["r_cd_px"]))
        base = ["design", "--mu-range", "0.02", "0.04", "--no-check", "--json", "--camera",
                str(cam)]
        capsys.readouterr()
        assert main([*base, "--cd-circle", circle]) == 0
        at = json.loads(capsys.readouterr().out)["width_prediction"]["camera_noise"]
        assert at["theta_harmonic_rad"] == pytest.approx(measured, rel=1e-9)
        assert main(base) == 0
        default = json.loads(capsys.readouterr().out)["width_prediction"]["camera_noise"]
        with capsys.disabled():
            print(f"{rec.name}: prior stated by abu measure {measured:.3e} rad (circle "
                  f"{circle}); abu design's default circle {default['theta_harmonic_rad']:.3e}")
        assert 1 / 1.5 < default["theta_harmonic_rad"] / measured < 1.5


def test_camera_of_another_frame_size_is_refused(rendered, tmp_path, capsys):
    rec = rendered[0]
    cam = cam_mod.Camera(np.array([[181.0, 0, 128], [0, 181.0, 127], [0, 0, 1]]),
                         np.zeros(5), (256, 256), 0.03, 20)
    path = tmp_path / "cam256.json"
    cam_mod.write_camera(path, cam)
    out = tmp_path / "m"
    assert main(["measure", str(rec), "--out", str(out), "--no-plots", "--quiet",
                 "--camera", str(path)]) == 2
    err = capsys.readouterr().err
    assert "--camera" in err and "200x200" in err and not out.exists()
    assert main(["render", "--calibration-views", "5", "--out", str(tmp_path / "r")]) == 2
    assert "--calibration-views" in capsys.readouterr().err
    # fewer views than calibrate-camera needs, or more than the bound: refused before rendering
    for bad in ("3", "-1", "101"):
        assert main(["render", "--scenario", "random", "--calibration-views", bad, "--out",
                     str(tmp_path / "r")]) == 2
        assert "--calibration-views" in capsys.readouterr().err and not (tmp_path / "r").exists()


def test_views_that_leave_the_lens_free_are_refused():
    """A singular Jacobian (every corner on the principal point: nothing ties down the lens)
    is a CameraError, not a LinAlgError traceback or a covariance of inf / nan."""
    obj = np.zeros((54, 3), np.float32)
    kk = np.array([[181.0, 0, 128], [0, 181.0, 127], [0, 0, 1]])
    with pytest.raises(cam_mod.CameraError, match="do not tie down the lens"):
        calib._covariance(obj, [np.full((54, 1, 2), 128, np.float32)], kk, np.zeros(5),
                          [np.zeros(3)], [np.array([0, 0, 10.0])])


def test_repeated_views_are_not_counted_as_poses(tmp_path, capsys):
    """The same view four times (or three views and a copy) shows fewer than four poses: a
    CameraError naming the repeated views and exit 2, not a calibration with a ~5 px centre."""
    frames, _, _ = render_views(OpticsSpec(k1=0.01), 256, 256, 4, 3)
    with pytest.raises(cam_mod.CameraError, match=r"only 1 show distinct poses \(view 1 = view 0"):
        calib.calibrate_from_frames(np.stack([frames[0]] * 4), (9, 6))
    copy = np.concatenate([frames[:3], frames[1:2]])
    with pytest.raises(cam_mod.CameraError, match="only 3 show distinct poses"):
        calib.calibrate_from_frames(copy, (9, 6))
    cam, _ = calib.calibrate_from_frames(frames, (9, 6))  # the four distinct views do
    assert cam.n_views == 4
    views = tmp_path / "views"
    views.mkdir()
    np.save(views.with_suffix(".npy"), np.stack([frames[0]] * 5))
    out = tmp_path / "cam.json"
    assert main(["calibrate-camera", str(views.with_suffix(".npy")), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "distinct poses" in err and "Traceback" not in err and not out.exists()


def test_opencv_failure_is_a_camera_error(monkeypatch):
    """A cv2.error inside calibrateCameraExtended becomes a CameraError with OpenCV's reason."""
    import cv2

    frames, _, _ = render_views(OpticsSpec(k1=0.01), 256, 256, 4, 3)

    def fails(*a, **k):
        raise cv2.error("OpenCV(4.x) calibration.cpp:1 error: (-215:Assertion failed) ni > 0")

    monkeypatch.setattr(cv2, "calibrateCameraExtended", fails)
    with pytest.raises(cam_mod.CameraError, match="could not calibrate.*Assertion failed"):
        calib.calibrate_from_frames(frames, (9, 6))
