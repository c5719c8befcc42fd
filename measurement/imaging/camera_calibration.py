"""Lens calibration from chessboard views in the ABU plane -> :class:`measurement.imaging.camera.Camera`.

:func:`calibrate_from_frames` finds the inner corners of the chessboard in each view
(:func:`find_corners`: ``findChessboardCorners`` + ``cornerSubPix`` on a flat-fielded view)
and fits OpenCV's model (``calibrateCameraExtended``; focal length fixed, square pixels, no
tangential terms, k3 = 0); :func:`_covariance` keeps the covariance of (cx, cy, k1, k2) the fit
implies (sigma^2 (J^T J)^-1 over every view's pose), written to the camera file.
"""
from __future__ import annotations

import math

import numpy as np

from measurement.imaging.camera import Camera, CameraError

#: Fewest views with the whole pattern found: 4 unknowns of the lens + 6 of each view's pose;
#: fewer views leave the distortion centre poorly tied down.
MIN_VIEWS = 4
#: Two views whose corners all lie within this distance of each other show the plate in the
#: same pose (corner noise is ~0.03 px): the second adds no information on the lens [px].
SAME_POSE_PX = 0.5


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
    same = _same_pose_as_earlier(img_pts)
    if len(used) - len(same) < MIN_VIEWS:
        pairs = [f"{names[used[j]]} = {names[used[i]]}" for j, i in same.items()]
        raise CameraError(
            f"the chessboard was found in {len(used)} views but only {len(used) - len(same)} "
            f"show distinct poses ({', '.join(pairs[:4])}{' ...' if len(pairs) > 4 else ''}: "
            f"every corner within {SAME_POSE_PX} px); at least {MIN_VIEWS} distinct views are "
            "needed: move and turn the plate between views")
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
    try:
        rms, kk, dist, rvecs, tvecs, _, _, per_view = cv2.calibrateCameraExtended(
            objs, img_pts, (w, h), k0, np.zeros(5), flags=flags, criteria=crit)
    except cv2.error as exc:  # e.g. a degenerate set of poses: a message, not a traceback
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise CameraError(f"OpenCV could not calibrate from the {len(used)} views ({msg}): "
                          "use views with the plate moved and turned over the field") from None
    if not (np.isfinite(rms) and np.isfinite(kk).all() and np.isfinite(dist).all()):
        raise CameraError(f"the calibration from the {len(used)} views did not converge "
                          "(non-finite lens parameters): use views spread over the field")
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


def _same_pose_as_earlier(img_pts: list[np.ndarray]) -> dict[int, int]:
    """{j: i} for views j whose corners all lie within :data:`SAME_POSE_PX` of an earlier
    distinct view i (positions in the list of found views)."""
    same: dict[int, int] = {}
    for j in range(len(img_pts)):
        for i in range(j):
            if i not in same and float(np.max(np.abs(img_pts[j] - img_pts[i]))) < SAME_POSE_PX:
                same[j] = i
                break
    return same


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
    try:  # J^T J is positive definite unless the views leave a lens parameter free
        cov = sigma2 * np.linalg.inv(big.T @ big)[:4, :4]
    except np.linalg.LinAlgError:
        cov = np.full((4, 4), np.nan)
    if not (np.isfinite(cov).all() and (np.diag(cov) >= 0).all()):
        raise CameraError("the calibration views do not tie down the lens (singular "
                          "Jacobian of (cx, cy, k1, k2)): use views spread over the field")
    return 0.5 * (cov + cov.T)
