"""Centre of one marker per window, vectorised over many windows (tracking's second pass).

Each refiner takes a stack of grey-level windows (K, w, w) (float32, marker bright) and returns
the centres a, b [px, window coordinates], radii r [px] and a reason code per window (OK or why
the marker is lost, :data:`LOST_REASONS`); the methods are described in
:mod:`measurement.imaging.tracking`. The helpers (border-ring plane fit, bilinear iso-contour crossings,
batched Kasa circle fit with outlier rejection) are shared with :mod:`measurement.imaging.reflections`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from measurement.imaging.edge_step import edge_step

@dataclass(frozen=True)
class TrackingOptions:
    """Tuning of the tracker; the defaults suit markers of radius 3-10 px in a 30 px window.

    Attributes:
        min_contrast: smallest marker contrast over the background [grey levels].
        min_snr: smallest contrast in units of the noise measured on the window border [-].
        r_min, r_max: plausible circle radius [px]; r_max None means window/2 - 2. r_min is
            1 px: the half-peak contour of a shiny ball's specular highlight under the TL ring
            is only 1.3-1.7 px in radius (1.5 px lost 3-8 % of the ball's frames on rendered
            seeds 1008 and 1037); the contrast, point-count, residual and median-radius tests
            still reject noise.
        radius_tolerance: largest deviation from the marker's median radius, as a fraction [-]
            (or 1 px, whichever is larger).
        max_jump: largest displacement [px] from both the last good position of the marker
            and the position its last displacement predicts (a marker moving faster than
            max_jump px/frame, e.g. the CD marker at 1500 frames/s, is no jump); None means
            window/3.
        max_residual: largest RMS distance of contour points from the fitted circle [px].
        min_points: fewest contour points for a circle fit [-].
        report_levels: contour levels of the ``report`` method as fractions of the window's
            min..max range [-].
        smooth: smooth the window with a 3x3 binomial kernel (Gaussian sigma ~0.71 px) before
            the ``isocontour`` method's contouring. A sharp, pixel-sampled edge makes linear
            interpolation between pixel centres err by up to ~0.1 px per contour point, with a
            pattern that depends on the sub-pixel position; the smoothing cuts that systematic
            error about threefold at a small cost in noise (see docs/measurement-imaging.md).
        edge_step: end the ``isocontour`` method with one Gauss-Newton step of a blurred-disk
            model on the pixels near the edge (:mod:`measurement.imaging.edge_step`): 17-30 %
            less RMS error on rendered markers (the CD marker of the bench recording 0.0123 ->
            0.0100 px, its Cramer-Rao bound 0.0089 px). On by default here; the command
            line's tracker applies it to the centre and CD paper disks of a one-reflection
            recording only, never to the ball, whose image is a highlight or an outline, not a
            uniform disk (:func:`measurement.imaging.edge_step_roles.edge_step_default`).
        edge_width_px: the model's edge blur s (normal CDF) [px].
    """

    min_contrast: float = 12.0
    min_snr: float = 6.0
    r_min: float = 1.0
    r_max: float | None = None
    radius_tolerance: float = 0.25
    max_jump: float | None = None
    max_residual: float = 0.6
    min_points: int = 8
    report_levels: tuple[float, ...] = (0.3, 0.4, 0.5, 0.6, 0.7)
    smooth: bool = True
    edge_step: bool = True
    edge_width_px: float = 0.4



#: Reason codes in :attr:`Tracks.reason`.
OK, OUTSIDE, LOW_CONTRAST, TOUCHES_EDGE, FIT_FAILED, BAD_RADIUS, JUMP = range(7)
LOST_REASONS = {
    OK: "found",
    OUTSIDE: "window leaves the image",
    LOW_CONTRAST: "contrast too low (no marker in the window)",
    TOUCHES_EDGE: "blob touches the window edge",
    FIT_FAILED: "circle fit failed (too few contour points or large residual)",
    BAD_RADIUS: "implausible radius",
    JUMP: "position jumped too far from the previous frame",
}


def border_ring(window: int, width: int = 2) -> np.ndarray:
    """Flat indices of the outer ring of ``width`` pixels of a window."""
    mask = np.zeros((window, window), dtype=bool)
    mask[:width, :] = mask[-width:, :] = True
    mask[:, :width] = mask[:, -width:] = True
    return np.flatnonzero(mask)


@dataclass
class WindowGeometry:
    window: int
    ring: np.ndarray        # flat indices of the border ring used for the plane fit
    plane_pinv: np.ndarray  # (3, len(ring)) least-squares plane on the ring
    plane_basis: np.ndarray  # (3, window*window): 1, x, y at every pixel
    plane_pinv64: np.ndarray   # the same in float64 (the isocontour method and its C kernel)
    plane_basis64: np.ndarray

    @classmethod
    def make(cls, window: int) -> "WindowGeometry":
        ring = border_ring(window, 2)
        yy, xx = np.divmod(np.arange(window * window), window)
        c = (window - 1) / 2.0
        basis = np.stack([np.ones(window * window), xx - c, yy - c])
        pinv = np.linalg.pinv(basis[:, ring].T)
        return cls(window, ring, pinv.astype(np.float32), basis.astype(np.float32),
                   np.ascontiguousarray(pinv), basis)


def gather(frames: np.ndarray, frame_idx: np.ndarray, x0: np.ndarray, y0: np.ndarray,
            window: int) -> np.ndarray:
    """(K, window, window) uint8 windows with top-left corners (x0, y0) of the given frames.

    A loop of slice copies: faster than one fancy-indexing gather for 30x30 windows.
    """
    out = np.empty((frame_idx.shape[0], window, window), dtype=frames.dtype)
    for k, (f, xa, ya) in enumerate(zip(frame_idx.tolist(), x0.tolist(), y0.tolist())):
        out[k] = frames[f, ya:ya + window, xa:xa + window]
    return out


def kasa(kk: np.ndarray, xs: np.ndarray, ys: np.ndarray, K: int, weights: np.ndarray | None = None
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Batched algebraic (Kasa) circle fit of the points (xs, ys) belonging to windows kk.

    Minimises sum (x^2 + y^2 + D x + E y + F)^2 per window. Returns centre a, b, radius r and
    the number of points used (NaN where the fit is singular).
    """
    w = np.ones_like(xs) if weights is None else weights
    z = xs * xs + ys * ys

    def s(v: np.ndarray | None) -> np.ndarray:
        return np.bincount(kk, weights=w if v is None else w * v, minlength=K)

    S, Sx, Sy = s(None), s(xs), s(ys)
    Sxx, Syy, Sxy = s(xs * xs), s(ys * ys), s(xs * ys)
    Sxz, Syz, Sz = s(xs * z), s(ys * z), s(z)
    A = np.empty((K, 3, 3))
    A[:, 0, 0], A[:, 0, 1], A[:, 0, 2] = Sxx, Sxy, Sx
    A[:, 1, 0], A[:, 1, 1], A[:, 1, 2] = Sxy, Syy, Sy
    A[:, 2, 0], A[:, 2, 1], A[:, 2, 2] = Sx, Sy, S
    rhs = -np.stack([Sxz, Syz, Sz], axis=1)
    ok = S >= 3
    det = np.linalg.det(A)
    ok &= np.abs(det) > 1e-9 * np.maximum(S, 1.0) ** 3
    A[~ok] = np.eye(3)
    sol = np.linalg.solve(A, rhs[:, :, None])[:, :, 0]
    a = -sol[:, 0] / 2.0
    b = -sol[:, 1] / 2.0
    r2 = a * a + b * b - sol[:, 2]
    ok &= r2 > 0
    r = np.sqrt(np.where(ok, r2, np.nan))
    a[~ok] = np.nan
    b[~ok] = np.nan
    return a, b, r, S


def crossings(G: np.ndarray, L: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel crossings of level L[k] on the grid edges of windows G[k].

    These are the vertices of the marching-squares iso-contour of the bilinear interpolation.
    Returns window index, x and y (window pixel coordinates, pixel centres at integers) and
    the above-level mask.
    """
    K, h, w = G.shape
    above = G > L[:, None, None]
    flat = G.reshape(-1)
    # crossings between horizontal neighbours (i, j) and (i, j + 1)
    f = np.flatnonzero(above[:, :, 1:] != above[:, :, :-1])
    k1, rem = np.divmod(f, h * (w - 1))
    i1, j1 = np.divmod(rem, w - 1)
    i0 = (k1 * h + i1) * w + j1
    v0 = flat[i0]
    xh = j1 + (v0 - L[k1]) / (v0 - flat[i0 + 1])
    # crossings between vertical neighbours (i, j) and (i + 1, j)
    f = np.flatnonzero(above[:, 1:, :] != above[:, :-1, :])
    k2, rem = np.divmod(f, (h - 1) * w)
    i2, j2 = np.divmod(rem, w)
    i0 = (k2 * h + i2) * w + j2
    v0 = flat[i0]
    yv = i2 + (v0 - L[k2]) / (v0 - flat[i0 + w])
    kk = np.concatenate([k1, k2])
    xs = np.concatenate([xh.astype(np.float64), j2.astype(np.float64)])
    ys = np.concatenate([i1.astype(np.float64), yv.astype(np.float64)])
    return kk, xs, ys, above


def robust_circle(kk: np.ndarray, xs: np.ndarray, ys: np.ndarray, K: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Kasa fit, reject points far from the circle, fit again. Returns a, b, r, rms, count."""
    a, b, r, _ = kasa(kk, xs, ys, K)
    d = np.hypot(xs - a[kk], ys - b[kk]) - r[kk]
    dd = np.nan_to_num(d * d, nan=1e6)
    cnt = np.bincount(kk, minlength=K).astype(float)
    rms = np.sqrt(np.bincount(kk, weights=dd, minlength=K) / np.maximum(cnt, 1.0))
    keep = (dd <= np.maximum(0.25, 9.0 * rms[kk] ** 2)).astype(float)
    a, b, r, S = kasa(kk, xs, ys, K, keep)
    d = np.hypot(xs - a[kk], ys - b[kk]) - r[kk]
    dd = np.nan_to_num(d * d, nan=1e6) * keep
    rms = np.sqrt(np.bincount(kk, weights=dd, minlength=K) / np.maximum(S, 1.0))
    return a, b, r, rms, S


def smooth3(G: np.ndarray) -> np.ndarray:
    """3x3 binomial smoothing ([1 2 1]/4 each way, Gaussian sigma ~0.71 px), 'valid' part.

    (K, w, w) -> (K, w - 2, w - 2); output pixel (i, j) sits at input pixel (i + 1, j + 1).
    """
    A = G[:, :, :-2] + G[:, :, 2:]
    A += 2.0 * G[:, :, 1:-1]
    B = A[:, :-2, :] + A[:, 2:, :]
    B += 2.0 * A[:, 1:-1, :]
    B *= 1.0 / 16.0
    return B


def refine_isocontour(G: np.ndarray, geo: WindowGeometry, opts: TrackingOptions
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Default method on a batch of windows G (K, w, w) (bright markers).

    Returns centre a, b (window coordinates), radius and reason codes. Computed in float64,
    as its C kernel (``_trackc.refine``), which agrees with it to ~1e-12 px (tested).
    """
    K, w, _ = G.shape
    flat = G.reshape(K, w * w).astype(np.float64)
    ring = flat[:, geo.ring]
    # einsum, not matmul: BLAS threads on a busy machine cost 10x more than they save here
    coef = np.einsum("kp,cp->kc", ring, geo.plane_pinv64)               # (K, 3) plane on the ring
    noise = (ring - np.einsum("kc,cp->kp", coef, geo.plane_basis64[:, geo.ring])).std(axis=1)
    flat = flat - np.einsum("kc,cp->kp", coef, geo.plane_basis64)       # lighting removed
    G2 = flat.reshape(K, w, w)
    H = G2
    off = 0
    if opts.smooth:
        # symmetric smoothing moves no centre; a plane stays a plane, so order is free
        G2 = smooth3(G2)
        off = 1
    ws = G2.shape[1]
    peak = G2.reshape(K, ws * ws).max(axis=1)
    level = 0.5 * peak
    kk, xs, ys, above = crossings(G2, level)
    a, b, r, rms, cnt = robust_circle(kk, xs, ys, K)
    a += off
    b += off
    reason = np.zeros(K, dtype=np.uint8)
    r_max = opts.r_max if opts.r_max is not None else w / 2.0 - 2.0
    c = (w - 1) / 2.0
    bad_fit = ~np.isfinite(a) | (cnt < opts.min_points) | (rms > opts.max_residual)
    bad_fit |= np.hypot(a - c, b - c) > w / 2.0 - 1.0
    reason[bad_fit] = FIT_FAILED
    reason[(r < opts.r_min) | (r > r_max)] = BAD_RADIUS
    touches = (above[:, 0, :].any(axis=1) | above[:, -1, :].any(axis=1)
               | above[:, :, 0].any(axis=1) | above[:, :, -1].any(axis=1))
    reason[touches] = TOUCHES_EDGE
    reason[(peak < opts.min_contrast) | (peak < opts.min_snr * noise)] = LOW_CONTRAST
    if opts.edge_step:
        a, b = edge_step(H, a, b, r, peak, opts.edge_width_px)
    return a, b, r, reason


def refine_report(G: np.ndarray, geo: WindowGeometry, opts: TrackingOptions
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The report's method on a batch of windows: several levels of min..max, average centres."""
    K, w, _ = G.shape
    flat = G.reshape(K, w * w)
    lo = flat.min(axis=1)
    hi = flat.max(axis=1)
    noise = flat[:, geo.ring].std(axis=1)
    sa = np.zeros(K)
    sb = np.zeros(K)
    sr = np.zeros(K)
    n_ok = np.zeros(K)
    any_touch = np.zeros(K, dtype=bool)
    r_max = opts.r_max if opts.r_max is not None else w / 2.0 - 2.0
    c = (w - 1) / 2.0
    for frac in opts.report_levels:
        level = (lo + frac * (hi - lo)).astype(np.float32)
        kk, xs, ys, above = crossings(G, level)
        a, b, r, rms, cnt = robust_circle(kk, xs, ys, K)
        touches = (above[:, 0, :].any(axis=1) | above[:, -1, :].any(axis=1)
                   | above[:, :, 0].any(axis=1) | above[:, :, -1].any(axis=1))
        any_touch |= touches
        good = (np.isfinite(a) & (cnt >= opts.min_points) & (rms <= opts.max_residual)
                & ~touches & (r >= opts.r_min) & (r <= r_max)
                & (np.hypot(a - c, b - c) <= w / 2.0 - 1.0))
        sa += np.where(good, a, 0.0)
        sb += np.where(good, b, 0.0)
        sr += np.where(good, r, 0.0)
        n_ok += good
    with np.errstate(invalid="ignore", divide="ignore"):
        a, b, r = sa / n_ok, sb / n_ok, sr / n_ok
    reason = np.zeros(K, dtype=np.uint8)
    reason[n_ok == 0] = FIT_FAILED
    reason[(n_ok == 0) & any_touch] = TOUCHES_EDGE
    contrast = hi - lo
    reason[(contrast < opts.min_contrast) | (contrast < opts.min_snr * noise)] = LOW_CONTRAST
    return a, b, r, reason


def refine_moments(G: np.ndarray, geo: WindowGeometry, opts: TrackingOptions
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The moments method, vectorised, with the lost-marker tests.

    Centroid of (I - L)+ with L the midpoint of the window's min and max (as ``cv2.moments`` in
    the seeded pass), plus: contrast over the border noise (after a plane fit), the thresholded
    blob touching the window edge, and compactness -- the blob's second moment must match a
    single disk of its area (two blobs in the window, e.g. a reflection, fail this).
    """
    K, w, _ = G.shape
    flat = G.reshape(K, w * w)
    lo = flat.min(axis=1)
    hi = flat.max(axis=1)
    W = G - (0.5 * (lo + hi))[:, None, None]
    np.maximum(W, 0.0, out=W)
    m00 = W.sum(axis=(1, 2))
    ar = np.arange(w, dtype=np.float32)
    wx = W.sum(axis=1)                      # (K, w) column sums
    wy = W.sum(axis=2)                      # (K, w) row sums
    with np.errstate(invalid="ignore", divide="ignore"):
        a = (wx @ ar) / m00
        b = (wy @ ar) / m00
        var = ((wx @ (ar * ar)) + (wy @ (ar * ar))) / m00 - a * a - b * b  # mu20 + mu02 [px^2]
        area = (W > 0).sum(axis=(1, 2)).astype(float)
        compact = var * 2.0 * np.pi / area  # 1 for a uniform disk (var = r^2/2, area = pi r^2)
        radius = np.sqrt(area / np.pi)
    ring = flat[:, geo.ring]
    coef = np.einsum("kp,cp->kc", ring, geo.plane_pinv)
    noise = (ring - np.einsum("kc,cp->kp", coef, geo.plane_basis[:, geo.ring])).std(axis=1)
    peak = (flat - np.einsum("kc,cp->kp", coef, geo.plane_basis)).max(axis=1)
    reason = np.zeros(K, dtype=np.uint8)
    reason[~np.isfinite(a) | (compact > 1.6)] = FIT_FAILED
    above = W > 0
    touches = (above[:, 0, :].any(axis=1) | above[:, -1, :].any(axis=1)
               | above[:, :, 0].any(axis=1) | above[:, :, -1].any(axis=1))
    reason[touches] = TOUCHES_EDGE
    reason[(peak < opts.min_contrast) | (peak < opts.min_snr * noise)] = LOW_CONTRAST
    return a, b, radius, reason


REFINERS = {"isocontour": refine_isocontour, "report": refine_report,
             "moments": refine_moments}
