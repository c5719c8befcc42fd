"""Camera calibration: a chessboard in the ABU plane -> lens distortion -> undistorted tracks.

A camera file (JSON, ``kind`` ``abu-camera``) holds OpenCV's pinhole model with radial
distortion: ``camera_matrix`` [[fx, 0, cx], [0, fy, cy], [0, 0, 1]] [px] and ``dist_coeffs``
(k1, k2, p1, p2[, k3 ...]), i.e. an ideal pixel x maps to the observed

    x_d = c + (x - c) (1 + k1 r^2 + k2 r^4),   r = |x - c| / f      (p = k3 = 0 here),

which is the harsh twin's lens model (:mod:`measurement.optics`) with f = the half diagonal and
c = the optical centre. :func:`undistort_pixels` maps tracked (observed) pixel positions back to
ideal ones, still in pixels (``cv2.undistortPoints`` with P = the camera matrix).

:func:`calibrate_from_frames` finds the inner corners of a chessboard (``findChessboardCorners``
+ ``cornerSubPix``) in each view and fits the model (``calibrateCamera``). The file also keeps
the covariance of (cx, cy, k1, k2) the fit implies (sigma^2 (J^T J)^-1, J the reprojection
Jacobian of ``cv2.projectPoints`` over all views, sigma^2 from the residual): the residual
distortion after calibration, from which :func:`theta_harmonic_prior` bounds the first harmonic
it leaves on the measured theta.
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import AbuError

CAMERA_KIND = "abu-camera"
CAMERA_VERSION = 1
#: Fewest views with the whole pattern found: 4 unknowns of the lens + 6 of each view's pose;
#: fewer views leave the distortion centre poorly tied down.
MIN_VIEWS = 4
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
    from .json_text import dumps
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
    try:
        d = json.loads(text)
    except ValueError as exc:
        raise CameraError(f"{p}: not JSON ({exc})") from None
    if not isinstance(d, dict) or d.get("kind") != CAMERA_KIND:
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
    rms = _num_array(p, d, "reprojection_rms_px", lambda a: a.ndim == 0 and a >= 0,
                     "a reprojection RMS >= 0 px")
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
        cov = _num_array(p, {key: cv["matrix"]} if "matrix" in cv else {}, key, lambda a: a.shape == (4, 4) and np.allclose(a, a.T)
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


# ------------------------------------------------------------------------------ calibration


def parse_pattern(text: str) -> tuple[int, int]:
    """'9x6' -> (9, 6): inner corners per row and per column of the chessboard."""
    from abu_model.errors import ParameterError
    try:
        a, b = (int(v) for v in str(text).lower().split("x"))
    except ValueError:
        raise ParameterError("--pattern", text, "inner corners as COLSxROWS, e.g. 9x6") from None
    if not (3 <= a <= 50 and 3 <= b <= 50) or a == b:
        raise ParameterError("--pattern", text, "3..50 inner corners each way, not square "
                             "(e.g. 9x6: a square pattern's orientation is ambiguous)")
    return a, b


def find_corners(img: np.ndarray, pattern: tuple[int, int]) -> np.ndarray | None:
    """(n, 2) sub-pixel inner corners of the chessboard in one 8-bit view, or None.

    ``findChessboardCorners`` finds them to a pixel; ``cornerSubPix`` refines them on a copy
    of the view divided by its white level (a dilation over two squares, smoothed: takes out
    vignetting, whose gradient shifts a saddle point) and blurred by min(1.5, square / 8) px
    (a smoother saddle: on the twin's views the corner error fell from 0.045 to 0.035 px RMS,
    0.021 px without column fixed-pattern noise; /tmp diagnosis against the true corners).
    """
    import cv2

    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    ok, corners = cv2.findChessboardCorners(img, pattern, flags=flags)
    if not ok:
        return None
    c = corners.reshape(pattern[1], pattern[0], 2)
    sq = float(np.median(np.hypot(*np.diff(c, axis=1).reshape(-1, 2).T)))  # square [px]
    f = img.astype(np.float32)
    k = max(3, int(round(2 * sq)) | 1)
    white = cv2.GaussianBlur(cv2.dilate(f, np.ones((k, k), np.uint8)), (0, 0), max(sq, 1.0))
    norm = f / np.maximum(white, 1.0) * np.float32(200.0)
    norm = cv2.GaussianBlur(norm, (0, 0), min(1.5, max(sq / 8.0, 0.5)))
    win = int(np.clip(sq / 2.5, 3, 5))
    crit = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 200, 1e-5)
    refined = cv2.cornerSubPix(norm, corners.copy(), (win, win), (-1, -1), crit)
    refined = refined.reshape(-1, 2).astype(np.float64)
    # a corner put on the wrong saddle (seen on 1 of 240 twin views) breaks the grid: the
    # refined corners must follow a homography of the plate to within 1.5 px (the distortion
    # over one board leaves < 1 px on the twin); else the view is not used
    grid = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2).astype(np.float64)
    hom, _ = cv2.findHomography(grid, refined, 0)
    if hom is None:
        return None
    back = cv2.perspectiveTransform(grid.reshape(-1, 1, 2), hom).reshape(-1, 2)
    if np.max(np.hypot(*(back - refined).T)) > 1.5:
        return None
    return refined


def calibrate_from_frames(frames: np.ndarray, pattern: tuple[int, int], *,
                          focal_px: float | None = None, square: float = 1.0,
                          names: list[str] | None = None) -> tuple[Camera, list[dict]]:
    """Calibrate from (K, H, W) uint8 views of a chessboard lying in the ABU plane.

    Args:
        frames: the views; the plate moved / turned in its plane between them.
        pattern: inner corners (columns, rows).
        focal_px: the fixed focal length [px] (default: the half diagonal, the twin's r_c).
        square: side of a square (any unit: it only scales the plate's distance).
        names: view names for messages.

    Returns:
        (camera, per-view rows {view, found, rms_px}).

    Raises:
        CameraError: fewer than :data:`MIN_VIEWS` views with the whole pattern.
    """
    import cv2

    frames = np.asarray(frames)
    if frames.ndim != 3 or frames.dtype != np.uint8:
        raise CameraError(f"calibration views must be 8-bit grey images; got {frames.dtype} "
                          f"{frames.shape}")
    n, h, w = frames.shape
    names = names or [f"view {i}" for i in range(n)]
    obj = np.zeros((pattern[0] * pattern[1], 3), np.float32)
    obj[:, :2] = np.mgrid[0:pattern[0], 0:pattern[1]].T.reshape(-1, 2) * float(square)
    img_pts, used, rows = [], [], []
    for i in range(n):
        c = find_corners(frames[i], pattern)
        rows.append({"view": names[i], "found": c is not None})
        if c is not None:
            img_pts.append(c.astype(np.float32).reshape(-1, 1, 2))
            used.append(i)
    if len(used) < MIN_VIEWS:
        missing = [r["view"] for r in rows if not r["found"]]
        raise CameraError(
            f"the {pattern[0]}x{pattern[1]} chessboard (inner corners) was found whole in "
            f"{len(used)} of {n} views; at least {MIN_VIEWS} are needed (not found in: "
            f"{', '.join(missing[:8])}{' ...' if len(missing) > 8 else ''}); check --pattern "
            "(inner corners, not squares) and that the plate is whole in the views")
    f = float(focal_px) if focal_px else 0.5 * math.hypot(w, h)
    k0 = np.array([[f, 0, (w - 1) / 2.0], [0, f, (h - 1) / 2.0], [0, 0, 1]], float)
    # Flags, for a flat plate lying in the ABU plane (views nearly fronto-parallel):
    # * FIX_FOCAL_LENGTH: a fronto-parallel plane cannot separate f from its distance; any
    #   fixed f gives the same pixel mapping (k1 scales with f^2), so f is fixed to the guess;
    # * FIX_ASPECT_RATIO: square pixels (fx = fy);
    # * ZERO_TANGENT_DIST: a lens centred on its sensor; p1, p2 trade off against the centre;
    # * FIX_K3: r^6 is not separable from k1, k2 over the field a 256 px frame sees;
    # * the principal point stays free: it is the distortion centre, off the ABU axis.
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_FOCAL_LENGTH
             | cv2.CALIB_FIX_ASPECT_RATIO | cv2.CALIB_ZERO_TANGENT_DIST | cv2.CALIB_FIX_K3)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    objs = [obj] * len(used)
    rms, kk, dist, rvecs, tvecs, _, _, per_view = cv2.calibrateCameraExtended(
        objs, img_pts, (w, h), k0, np.zeros(5), flags=flags, criteria=crit)
    for j, i in enumerate(used):
        rows[i]["rms_px"] = float(per_view[j, 0])
    cov = _covariance(obj, img_pts, kk, dist, rvecs, tvecs)
    cam = Camera(camera_matrix=kk, dist_coeffs=dist.ravel(), image_size=(w, h),
                 rms_px=float(rms), n_views=len(used), n_corners=len(used) * obj.shape[0],
                 covariance=cov,
                 extra={"pattern_inner_corners": list(pattern), "square_size": float(square),
                        "flags": ["USE_INTRINSIC_GUESS", "FIX_FOCAL_LENGTH",
                                  "FIX_ASPECT_RATIO", "ZERO_TANGENT_DIST", "FIX_K3"],
                        "per_view_rms_px": [r.get("rms_px") for r in rows],
                        "views": [r["view"] for r in rows]})
    return cam, rows


def _covariance(obj, img_pts, kk, dist, rvecs, tvecs) -> np.ndarray:
    """sigma^2 (J^T J)^-1 of (cx, cy, k1, k2) with every view's pose free (Gauss-Newton)."""
    import cv2

    nv = len(img_pts)
    blocks, res = [], []
    for j in range(nv):
        proj, jac = cv2.projectPoints(obj, rvecs[j], tvecs[j], kk, dist)
        res.append((img_pts[j].reshape(-1, 2) - proj.reshape(-1, 2)).ravel())
        # columns: rvec(3) tvec(3) fx fy cx cy k1 k2 p1 p2 k3 ...
        blocks.append((jac[:, :6], jac[:, 8:12]))
    m = 2 * obj.shape[0]
    big = np.zeros((m * nv, 4 + 6 * nv))
    for j, (pose, lens) in enumerate(blocks):
        big[j * m:(j + 1) * m, :4] = lens
        big[j * m:(j + 1) * m, 4 + 6 * j:10 + 6 * j] = pose
    r = np.concatenate(res)
    sigma2 = float(r @ r) / max(r.size - big.shape[1], 1)
    cov = sigma2 * np.linalg.inv(big.T @ big)[:4, :4]  # J^T J is positive definite
    return 0.5 * (cov + cov.T)


# ------------------------------------------------------------------------------ prior


def _theta_harmonics(cam: Camera, params: np.ndarray, phi: np.ndarray, ideal: np.ndarray
                     ) -> np.ndarray:
    """(a1s, a1c, a2s, a2c) of the theta error [rad] on the CD circle when observed points
    (distorted by ``cam``) are undistorted with (cx, cy, k1, k2) = ``params``; the axis is
    re-fitted as a circle centre, as the analysis does."""
    k = np.array(cam.camera_matrix, float)
    k[0, 2], k[1, 2] = params[0], params[1]
    dc = np.array(cam.dist_coeffs, float).ravel()
    dc[0], dc[1] = params[2], params[3]
    obs = np.stack(distort_pixels(ideal[:, 0], ideal[:, 1], cam), axis=-1)
    ux, uy = undistort_pixels(obs[:, 0], obs[:, 1], Camera(k, dc, cam.image_size, 0.0, 1))
    a = np.column_stack([ux, uy, np.ones_like(ux)])
    sol = np.linalg.lstsq(a, ux ** 2 + uy ** 2, rcond=None)[0]
    cx, cy = 0.5 * sol[0], 0.5 * sol[1]
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
