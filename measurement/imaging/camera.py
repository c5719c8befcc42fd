"""Camera calibration: a chessboard in the ABU plane -> lens distortion -> undistorted tracks.

A camera file (JSON, ``kind`` ``abu-camera``) holds OpenCV's pinhole model with radial
distortion: ``camera_matrix`` [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] [px] and ``dist_coeffs``
(k1, k2, p1, p2[, k3 ...]), i.e. an ideal pixel x maps to the observed

    x_d = c + (x - c) (1 + k1 r^2 + k2 r^4),   r = |x - c| / f      (p = k3 = 0 here),

which is the harsh twin's lens model (:mod:`twin.optics`) with f = the half diagonal and
c = the optical centre. :func:`undistort_pixels` maps tracked (observed) pixel positions back to
ideal ones, still in pixels (``cv2.undistortPoints`` with P = the camera matrix).

:func:`measurement.imaging.camera_calibration.calibrate_from_frames` finds the inner corners of a
chessboard (``findChessboardCorners`` + ``cornerSubPix``) in each view and fits the model
(``calibrateCamera``). The file also keeps
the covariance of (cx, cy, k1, k2) the fit implies (sigma^2 (J^T J)^-1, J the reprojection
Jacobian of ``cv2.projectPoints`` over all views, sigma^2 from the residual): the residual
distortion after calibration, from which :func:`theta_harmonic_prior` bounds the first harmonic
it leaves on the measured theta.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model import validate
from abu_model.errors import AbuError, ParameterError

CAMERA_KIND = "abu-camera"
CAMERA_VERSION = 1
#: Quantile of the harmonic-amplitude bound (amplitude of a 2-d Gaussian, largest variance;
#: checked on the twin: benchmarks/bench_coverage.py --camera).
PRIOR_QUANTILE = 0.95
#: Parameters whose covariance the camera file keeps.
COV_PARAMETERS = ("cx_px", "cy_px", "k1", "k2")
#: Largest image side [px] and view count a camera file may state (plausibility bounds).
MAX_IMAGE_PX = 100_000
MAX_FILE_VIEWS = 1_000_000
#: Largest round-trip error (undistort then distort) over the image border [px]: beyond it the
#: distortion folds over inside the image (not invertible there), e.g. a huge k1.
ROUND_TRIP_PX = 1e-3


class CameraError(AbuError, ValueError):
    """A camera file or a calibration input is unusable; names the file / view and field."""


@dataclass
class Camera:
    """A calibrated camera (pixels; see the module doc).

    Attributes:
        camera_matrix: (3, 3) [px].
        dist_coeffs: (n,) OpenCV distortion coefficients (k1, k2, p1, p2[, k3, ...]) [-].
        image_size: (width, height) [px] of the calibration images.
        rms_px: reprojection RMS of the fit [px] (sqrt of the mean squared 2-d residual).
        n_views, n_corners: views and corners used.
        covariance: (4, 4) covariance of (cx [px], cy [px], k1, k2), or None (unknown).
        extra: anything else kept in the file (pattern, flags, per-view RMS...).
    """

    camera_matrix: np.ndarray
    dist_coeffs: np.ndarray
    image_size: tuple[int, int]
    rms_px: float
    n_views: int
    n_corners: int = 0
    covariance: np.ndarray | None = None
    extra: dict[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        return {"kind": CAMERA_KIND, "format_version": CAMERA_VERSION,
                "model": "OpenCV pinhole + radial distortion (pixels)",
                "image_size_px": list(self.image_size),
                "camera_matrix": np.asarray(self.camera_matrix).tolist(),
                "dist_coeffs": np.asarray(self.dist_coeffs).ravel().tolist(),
                "reprojection_rms_px": self.rms_px, "n_views": self.n_views,
                "n_corners": self.n_corners,
                "distortion_covariance": None if self.covariance is None else
                {"parameters": list(COV_PARAMETERS),
                 "matrix": np.asarray(self.covariance).tolist()},
                **self.extra}


# ------------------------------------------------------------------------------ file


def write_camera(path: str | os.PathLike, cam: Camera) -> Path:
    """Write the camera file atomically."""
    from abu_model.json_text import dumps
    atomic_write_text(path, dumps(cam.to_dict()))
    return Path(path)


def _has_bool(v: Any) -> bool:
    return isinstance(v, bool) or (isinstance(v, list) and any(_has_bool(e) for e in v))


def _num_array(path: str, d: dict, key: str, shape_ok, expected: str) -> np.ndarray:
    if key not in d:
        raise CameraError(f"{path}: missing field '{key}' ({expected})")
    if _has_bool(d[key]):  # json true/false would pass as 1.0 / 0.0
        raise CameraError(f"{path}: field '{key}' = {d[key]!r}: expected {expected}")
    try:
        a = np.asarray(d[key], dtype=float)
    except (TypeError, ValueError):
        raise CameraError(f"{path}: field '{key}' is not numeric ({expected})") from None
    if not shape_ok(a) or not np.isfinite(a).all():
        raise CameraError(f"{path}: field '{key}' = {d[key]!r}: expected {expected}")
    return a


def read_camera(path: str | os.PathLike) -> Camera:
    """Read and check a camera file; :class:`CameraError` names the file and the field."""
    p = str(path)
    try:
        text = Path(path).read_text(encoding="utf-8")
    except FileNotFoundError:
        raise CameraError(f"{p}: camera file not found (make one with 'abu calibrate-camera')"
                          ) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise CameraError(f"{p}: cannot read the camera file ({exc})") from None
    d = validate.json_object(text, p, "a JSON object (a camera file of 'abu calibrate-camera')",
                             error=CameraError)
    if d.get("kind") != CAMERA_KIND:
        got = d.get("kind") if isinstance(d, dict) else type(d).__name__
        raise CameraError(f"{p}: field 'kind' = {got!r}: expected '{CAMERA_KIND}' (a file of "
                          "'abu calibrate-camera')")
    if d.get("format_version") != CAMERA_VERSION or isinstance(d.get("format_version"), bool):
        raise CameraError(f"{p}: field 'format_version' = {d.get('format_version')!r}: expected "
                          f"{CAMERA_VERSION}")
    k = _num_array(p, d, "camera_matrix", lambda a: a.shape == (3, 3),
                   "a 3x3 matrix [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] of finite numbers")
    if not (0 < k[0, 0] <= 1e6 and 0 < k[1, 1] <= 1e6 and k[2, 2] == 1 and k[1, 0] == 0
            and k[2, 0] == 0 and k[2, 1] == 0):
        raise CameraError(f"{p}: field 'camera_matrix' = {k.tolist()}: expected fx > 0, "
                          "fy > 0 (at most 1e6 px) and the last row [0, 0, 1]")
    dist = _num_array(p, d, "dist_coeffs", lambda a: a.ndim == 1 and a.size in (4, 5, 8, 12, 14),
                      "a list of 4, 5, 8, 12 or 14 finite numbers (k1, k2, p1, p2[, k3...])")
    size = _num_array(p, d, "image_size_px", lambda a: a.shape == (2,) and (a >= 1).all()
                      and (a <= MAX_IMAGE_PX).all() and (a == np.round(a)).all(),
                      f"[width, height] in px, integers in 1..{MAX_IMAGE_PX}")
    rms = _num_array(p, d, "reprojection_rms_px", lambda a: a.ndim == 0 and 0 <= a <= 100,
                     "a reprojection RMS in [0, 100] px (a calibration worth using is off by "
                     "well under a pixel)")
    views = _num_array(p, d, "n_views", lambda a: a.ndim == 0 and 1 <= a <= MAX_FILE_VIEWS
                       and a == round(float(a)), f"an integer in 1..{MAX_FILE_VIEWS}")
    corners = _num_array(p, {"n_corners": 0, **d}, "n_corners", lambda a: a.ndim == 0
                         and 0 <= a <= 1e12 and a == round(float(a)), "an integer >= 0")
    cov = None
    cv = d.get("distortion_covariance")
    if cv is not None:
        if not isinstance(cv, dict):
            raise CameraError(f"{p}: field 'distortion_covariance' must be an object with "
                              "'parameters' and 'matrix' (or null)")
        if cv.get("parameters") != list(COV_PARAMETERS):
            raise CameraError(f"{p}: field 'distortion_covariance.parameters' = "
                              f"{cv.get('parameters')!r}: expected {list(COV_PARAMETERS)}")
        # positive semi-definite (to rounding): a negative variance would shrink the prior
        key = "distortion_covariance.matrix"
        cov = _num_array(p, {key: cv["matrix"]} if "matrix" in cv else {}, key,
                         lambda a: a.shape == (4, 4) and np.allclose(a, a.T)
                         and np.linalg.eigvalsh(0.5 * (a + a.T)).min()
                         >= -1e-9 * max(float(np.abs(a).max()), 1e-300),
                         "a symmetric positive semi-definite 4x4 covariance of (cx, cy, k1, k2)")
    known = set(Camera(k, dist, (1, 1), 0.0, 1).to_dict())
    cam = Camera(camera_matrix=k, dist_coeffs=dist, image_size=(int(size[0]), int(size[1])),
                 rms_px=float(rms), n_views=int(views), n_corners=int(corners),
                 covariance=cov, extra={**{a: b for a, b in d.items() if a not in known},
                                        "path": p})
    err = _round_trip_px(cam)
    if not err <= ROUND_TRIP_PX:
        raise CameraError(f"{p}: field 'dist_coeffs' = {dist.tolist()}: expected a distortion "
                          f"invertible over the {cam.image_size[0]}x{cam.image_size[1]} px image "
                          f"(undistorting and distorting its border is off by {err:.3g} px)")
    return cam


def _round_trip_px(cam: Camera) -> float:
    """Largest |distort(undistort(p)) - p| [px] over points p on the image border (nan if
    not finite): where the lens model folds over, undistortion picks a wrong root."""
    w, h = cam.image_size
    t = np.linspace(0.0, 1.0, 33)
    bx = np.concatenate([t * (w - 1), t * (w - 1), np.zeros_like(t), np.full_like(t, w - 1)])
    by = np.concatenate([np.zeros_like(t), np.full_like(t, h - 1), t * (h - 1), t * (h - 1)])
    with np.errstate(all="ignore"):
        ux, uy = undistort_pixels(bx, by, cam)
        dx, dy = distort_pixels(ux, uy, cam)
        err = np.hypot(dx - bx, dy - by)
    return float(err.max()) if np.isfinite(err).all() else math.nan


# ------------------------------------------------------------------------------ undistortion


def undistort_pixels(x: np.ndarray, y: np.ndarray, cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Ideal (undistorted) pixel positions of observed ones, same shapes [px].

    ``cv2.undistortPoints`` with P = the camera matrix (results in pixels); its fixed-point
    inversion runs to 1e-12 (normalised units) or 50 iterations (default: 5, ~1e-4 px at
    k1 = 0.03 in a frame corner).
    """
    import cv2

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    pts = np.stack([x.ravel(), y.ravel()], axis=-1).reshape(-1, 1, 2)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-12)
    k = np.asarray(cam.camera_matrix, dtype=float)
    out = cv2.undistortPoints(pts, k, np.asarray(cam.dist_coeffs, dtype=float), P=k,
                              criteria=crit)
    out = out.reshape(-1, 2)
    return out[:, 0].reshape(x.shape), out[:, 1].reshape(y.shape)


def distort_pixels(x: np.ndarray, y: np.ndarray, cam: Camera) -> tuple[np.ndarray, np.ndarray]:
    """Observed pixel positions of ideal ones [px]: ``cv2.projectPoints`` of the normalised
    points, i.e. OpenCV's whole model (every coefficient of the file), the exact inverse of
    :func:`undistort_pixels`."""
    import cv2

    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    k = np.asarray(cam.camera_matrix, dtype=float)
    pts = np.stack([(x.ravel() - k[0, 2]) / k[0, 0], (y.ravel() - k[1, 2]) / k[1, 1],
                    np.ones(x.size)], axis=-1)
    out, _ = cv2.projectPoints(pts, np.zeros(3), np.zeros(3), k,
                               np.asarray(cam.dist_coeffs, dtype=float))
    out = out.reshape(-1, 2)
    return out[:, 0].reshape(x.shape), out[:, 1].reshape(y.shape)


# ------------------------------------------------------------------------------ prior


def _theta_harmonics(cam: Camera, params: np.ndarray, phi: np.ndarray, ideal: np.ndarray
                     ) -> np.ndarray:
    """(a1s, a1c, a2s, a2c) of the theta error [rad] on the CD circle when observed points
    (distorted by ``cam``) are undistorted with (cx, cy, k1, k2) = ``params``; the axis is
    re-fitted as a circle centre, as the analysis does."""
    from measurement.imaging.geometry import circle_centre

    k = np.array(cam.camera_matrix, float)
    k[0, 2], k[1, 2] = params[0], params[1]
    dc = np.array(cam.dist_coeffs, float).ravel()
    dc[0], dc[1] = params[2], params[3]
    obs = np.stack(distort_pixels(ideal[:, 0], ideal[:, 1], cam), axis=-1)
    ux, uy = undistort_pixels(obs[:, 0], obs[:, 1], Camera(k, dc, cam.image_size, 0.0, 1))
    cx, cy = circle_centre(ux, uy)
    th = np.unwrap(np.arctan2(-(uy - cy), ux - cx))
    err = th - phi
    design = np.column_stack([np.ones_like(phi), np.sin(phi), np.cos(phi), np.sin(2 * phi),
                              np.cos(2 * phi)])
    return np.linalg.lstsq(design, err, rcond=None)[0][1:]


def theta_harmonic_prior(cam: Camera, axis_xy: tuple[float, float], r_px: float) -> dict:
    """Bound on the systematic harmonics of theta the calibration leaves [rad].

    The calibrated (cx, cy, k1, k2) err by N(0, covariance); the theta error on the CD circle
    (radius ``r_px`` about the ideal axis ``axis_xy``) is linear in that error:
    h = J dp with h = (first-harmonic sine, cosine, second-harmonic sine, cosine). The bound
    is the PRIOR_QUANTILE quantile of a 2-d Gaussian amplitude with the largest variance of
    J_n cov J_n^T (conservative), sqrt(-2 ln(1 - q) lambda_max), for n = 1, 2; the
    returned ``theta_harmonic_rad`` is A1 + 4 A2 (a second harmonic errs omega_dot by
    4 A2 omega^2, the first by A1 omega^2). ``k`` = that bound x r_px / rms, the geometric
    factor of the form k rms / r_cd (covariance ~ rms^2).
    """
    if cam.covariance is None:
        # no covariance in the file: one RMS of tangential error on the circle (conservative)
        a = cam.rms_px / r_px
        return {"theta_harmonic_rad": a, "k": 1.0, "method": "rms / r_cd (no covariance)"}
    phi = np.linspace(0, 2 * np.pi, 64, endpoint=False)
    ideal = np.column_stack([axis_xy[0] + r_px * np.cos(phi), axis_xy[1] - r_px * np.sin(phi)])
    p0 = np.array([cam.camera_matrix[0][2], cam.camera_matrix[1][2], cam.dist_coeffs[0],
                   cam.dist_coeffs[1]], float)
    sd = np.sqrt(np.maximum(np.diag(cam.covariance), 0.0))
    steps = np.where(sd > 0, sd, np.array([1e-3, 1e-3, 1e-6, 1e-6]))
    h0 = _theta_harmonics(cam, p0, phi, ideal)
    jac = np.zeros((4, 4))
    for j in range(4):
        dp = np.zeros(4)
        dp[j] = steps[j]
        jac[:, j] = (_theta_harmonics(cam, p0 + dp, phi, ideal) - h0) / steps[j]
    cov_h = jac @ cam.covariance @ jac.T
    q = math.sqrt(-2.0 * math.log(1.0 - PRIOR_QUANTILE))
    a1 = q * math.sqrt(max(float(np.linalg.eigvalsh(cov_h[:2, :2]).max()), 0.0))
    a2 = q * math.sqrt(max(float(np.linalg.eigvalsh(cov_h[2:, 2:]).max()), 0.0))
    a = a1 + 4.0 * a2
    return {"theta_harmonic_rad": a, "first_harmonic_rad": a1, "second_harmonic_rad": a2,
            "k": a * r_px / cam.rms_px if cam.rms_px > 0 else None,
            "quantile": PRIOR_QUANTILE,
            "method": "calibration covariance of (cx, cy, k1, k2) propagated to theta's "
                      "harmonics on the CD circle"}


def undistort_tracks(path: str, cam: Camera, x: np.ndarray, y: np.ndarray,
                     frame_size: tuple[int, int] | None
                     ) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """Undistort (N, 3) tracked positions [px] with the camera ``cam`` (read from the file
    ``path``, named in the errors).

    Returns:
        (x, y, theta_harmonic_rad, info): the undistorted positions, the prior bound on theta's
        first harmonic from the calibration [rad] (:func:`theta_harmonic_prior`) and what
        summary.json records. ``frame_size`` (width, height) [px] of the recording, or None
        for a tracks file (then the positions must lie in the camera's image).
    """
    from measurement.imaging.geometry import fixed_axis

    w, h = cam.image_size
    if frame_size is not None and tuple(frame_size) != (w, h):
        raise ParameterError("camera", path, f"a camera calibrated on {frame_size[0]}x"
                             f"{frame_size[1]} px frames (it was calibrated on {w}x{h} px)")
    if not ((x > -0.5) & (x < w - 0.5) & (y > -0.5) & (y < h - 0.5)).all():
        raise ParameterError("camera", path, f"a camera whose {w}x{h} px image holds every "
                             "tracked position (some lie outside it)")
    xu, yu = undistort_pixels(x, y, cam)
    ax, ay = fixed_axis(xu, yu)
    axis = (float(ax[0, 0]), float(ay[0, 0]))
    r_cd = float(np.median(np.hypot(xu[:, 1] - axis[0], yu[:, 1] - axis[1])))
    prior = theta_harmonic_prior(cam, axis, r_cd)
    k = cam.camera_matrix
    info = {"file": str(path), "reprojection_rms_px": cam.rms_px, "n_views": cam.n_views,
            "k1": float(cam.dist_coeffs[0]), "k2": float(cam.dist_coeffs[1]),
            "optical_centre_px": [float(k[0, 2]), float(k[1, 2])],
            "axis_px": list(axis), "r_cd_px": r_cd,
            "max_correction_px": float(np.max(np.hypot(xu - x, yu - y))),
            "theta_harmonic_prior": prior,
            "note": "tracked positions undistorted before the angles; tracks.csv keeps the "
                    "tracker's (distorted) positions"}
    return xu, yu, float(prior["theta_harmonic_rad"]), info
