"""Sub-pixel tracking of the three markers (ABU centre, CD marker, ball) through a recording.

Coordinates follow OpenCV: x = column, y = row, pixel centres at integers, origin at the
centre of the top-left pixel. All positions are in pixels [px].

How it works (two passes, so that most of the work is vectorised over all frames):

1. **Seeded pass** (sequential, cheap): for each frame and marker, a square window (default
   30x30 px) is put at the marker's position in the previous frame (plus the last frame-to-frame
   displacement) and the centroid of ``(I - L)+`` is taken with ``cv2.moments``, L being the
   midpoint of the window's darkest and brightest grey levels. This is the report's seeding
   (appendix B).
2. **Refinement** (vectorised over all windows): a window is put at the seeded-pass position of
   the *same* frame and the centre is measured again with the chosen method:

   * ``isocontour`` (default): subtract a plane fitted to the window's border ring (removes an
     additive lighting gradient), smooth with a 3x3 binomial kernel, take the 50 % iso-contour
     of the bilinear interpolation of the pixels (its vertices are the sub-pixel crossings of
     the level on the pixel grid's edges, as in marching squares), fit a circle algebraically
     (Kasa), reject outlier points, fit again.
   * ``report``: the report's method (appendix B): several contour levels between percentage
     bounds of the window's min..max grey levels (no lighting correction), a circle fit to each
     contour, the centres averaged. MATLAB's ``contour`` interpolates linearly, so the contour
     points are the same sub-pixel grid crossings.
   * ``moments``: the seeded pass's centroid again, vectorised, in the re-centred window (the
     fast baseline), with the lost-marker tests below plus a compactness test.

Speed (benchmarks/bench_tracking.py, 3072 frames of 256x256 px, 3 markers, one core): the
default method runs at about 2.5-3x the camera's 4500 frames/s; measured accuracy is in
docs/measurement-imaging.md.

A marker is flagged ``lost`` in a frame (and its coordinates set to NaN) when: the window leaves
the image; the contrast is too low (below ``min_contrast`` grey levels or ``min_snr`` times the
noise measured on the border); the blob touches the window edge; the circle fit fails, has too
few points or a large residual; the radius is implausible (outside [r_min, r_max] or far from the
marker's median radius); or the position jumps more than ``max_jump`` px from the last good one.
The reason is kept per frame and marker (:data:`LOST_REASONS`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from abu_model.errors import AbuError, ParameterError

METHODS = ("isocontour", "report", "moments")
DEFAULT_METHOD = "isocontour"
DEFAULT_WINDOW = 30

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
#: Frames per vectorised batch (bounds memory: batch * markers * window^2 floats).
BATCH_FRAMES = 256


class TrackingError(AbuError):
    """Tracking cannot start (bad seeds, window or frames)."""


@dataclass(frozen=True)
class TrackingOptions:
    """Tuning of the tracker; the defaults suit markers of radius 3-10 px in a 30 px window.

    Attributes:
        min_contrast: smallest marker contrast over the background [grey levels].
        min_snr: smallest contrast in units of the noise measured on the window border [-].
        r_min, r_max: plausible circle radius [px]; r_max None means window/2 - 2.
        radius_tolerance: largest deviation from the marker's median radius, as a fraction [-]
            (or 1 px, whichever is larger).
        max_jump: largest displacement from the last good position of the marker [px];
            None means window/3.
        max_residual: largest RMS distance of contour points from the fitted circle [px].
        min_points: fewest contour points for a circle fit [-].
        report_levels: contour levels of the ``report`` method as fractions of the window's
            min..max range [-].
        smooth: smooth the window with a 3x3 binomial kernel (Gaussian sigma ~0.71 px) before
            the ``isocontour`` method's contouring. A sharp, pixel-sampled edge makes linear
            interpolation between pixel centres err by up to ~0.1 px per contour point, with a
            pattern that depends on the sub-pixel position; the smoothing cuts that systematic
            error about threefold at a small cost in noise (see docs/measurement-imaging.md).
    """

    min_contrast: float = 12.0
    min_snr: float = 6.0
    r_min: float = 1.5
    r_max: float | None = None
    radius_tolerance: float = 0.25
    max_jump: float | None = None
    max_residual: float = 0.6
    min_points: int = 8
    report_levels: tuple[float, ...] = (0.3, 0.4, 0.5, 0.6, 0.7)
    smooth: bool = True


@dataclass
class Tracks:
    """Tracked marker centres.

    Attributes:
        x, y: (N, M) marker centres [px] (x = column, y = row), NaN where lost. With three
            markers the column order is ABU centre, CD marker, ball.
        lost: (N, M) True where the marker was not found in that frame.
        reason: (N, M) uint8 reason codes (:data:`LOST_REASONS`), 0 where found.
        radius: (N, M) fitted circle radius [px] (NaN where lost; for ``moments`` the radius of
            the disk with the thresholded blob's area).
        method: the centre-finding method used.
        window: the window size [px].
        dark: True if the markers are darker than their background.
    """

    x: np.ndarray
    y: np.ndarray
    lost: np.ndarray
    reason: np.ndarray
    radius: np.ndarray
    method: str
    window: int
    dark: bool = False
    options: TrackingOptions = field(default_factory=TrackingOptions)

    @property
    def n_frames(self) -> int:
        return int(self.x.shape[0])

    def xy(self, marker: int) -> np.ndarray:
        """(N, 2) centres of one marker [px]."""
        return np.stack([self.x[:, marker], self.y[:, marker]], axis=1)

    def lost_summary(self) -> dict[str, int]:
        """Number of lost frames per reason (all markers together)."""
        codes, counts = np.unique(self.reason[self.lost], return_counts=True)
        return {LOST_REASONS[int(c)]: int(n) for c, n in zip(codes, counts)}


# --------------------------------------------------------------------------------------------
# checks


def _check_inputs(frames: np.ndarray, seeds: np.ndarray, window: int, method: str
                  ) -> tuple[np.ndarray, np.ndarray, int]:
    if method not in METHODS:
        raise ParameterError("method", method, f"one of {', '.join(METHODS)}")
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 8:
        raise ParameterError("window", window, "an integer >= 8 px")
    window = int(window)
    if not isinstance(frames, np.ndarray) or frames.ndim != 3 or frames.dtype != np.uint8:
        shape = getattr(frames, "shape", None)
        dtype = getattr(frames, "dtype", None)
        raise TrackingError(f"frames: expected an (N, H, W) uint8 array, got shape {shape} "
                            f"dtype {dtype}")
    n, h, w = frames.shape
    if n < 1:
        raise TrackingError("frames: the recording holds no frames")
    if window > min(h, w):
        raise ParameterError("window", window, f"at most the frame size {min(h, w)} px")
    seeds = np.asarray(seeds, dtype=float)
    if seeds.ndim != 2 or seeds.shape[1] != 2 or seeds.shape[0] < 1:
        raise TrackingError(f"seeds: expected an (M, 2) array of x, y positions [px], got shape "
                            f"{seeds.shape}")
    for m, (sx, sy) in enumerate(seeds):
        if not (np.isfinite(sx) and np.isfinite(sy) and 0 <= sx <= w - 1 and 0 <= sy <= h - 1):
            raise TrackingError(f"seed {m} = ({sx}, {sy}) px lies outside the {w}x{h} px frame")
    return frames, seeds, window


# --------------------------------------------------------------------------------------------
# pass 1: seeded moments (sequential)


def _seeded_moments(frames: np.ndarray, seeds: np.ndarray, window: int, dark: bool,
                    opts: TrackingOptions, bar=None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sequential moments tracker. Returns x, y (N, M) [px] and reason (N, M) codes.

    Where lost, x and y hold the predicted position (used to seed the next frame).
    """
    import cv2

    n, hgt, wid = frames.shape
    m_count = seeds.shape[0]
    half = window // 2
    max_jump = opts.max_jump if opts.max_jump is not None else window / 3.0
    xs = np.empty((n, m_count))
    ys = np.empty((n, m_count))
    reason = np.zeros((n, m_count), dtype=np.uint8)
    # State per marker: last good position and its velocity [px/frame].
    px = [float(s[0]) for s in seeds]
    py = [float(s[1]) for s in seeds]
    vx = [0.0] * m_count
    vy = [0.0] * m_count
    minmax = cv2.minMaxLoc
    subtract = cv2.subtract
    moments = cv2.moments
    bar = bar or _NoBar()
    for start in range(0, n, BATCH_FRAMES):
        chunk = np.asarray(frames[start:start + BATCH_FRAMES])
        if dark:
            chunk = 255 - chunk  # a dark marker becomes a bright one
        for ci in range(chunk.shape[0]):
            frame = chunk[ci]
            k = start + ci
            for m in range(m_count):
                qx = px[m] + vx[m]
                qy = py[m] + vy[m]
                x0 = int(round(qx)) - half
                y0 = int(round(qy)) - half
                code = OK
                if x0 < 0 or y0 < 0 or x0 + window > wid or y0 + window > hgt:
                    code = OUTSIDE
                else:
                    win = frame[y0:y0 + window, x0:x0 + window]
                    lo, hi, _, _ = minmax(win)
                    if hi - lo < opts.min_contrast:
                        code = LOW_CONTRAST
                    else:
                        mom = moments(subtract(win, (lo + hi) * 0.5))
                        m00 = mom["m00"]
                        if m00 <= 0.0:
                            code = LOW_CONTRAST
                        else:
                            cx = x0 + mom["m10"] / m00
                            cy = y0 + mom["m01"] / m00
                            # against the last good position, not the prediction: one
                            # disturbed frame must not make the next good one look like a jump
                            if (cx - px[m]) ** 2 + (cy - py[m]) ** 2 > max_jump * max_jump:
                                code = JUMP
                if code == OK:
                    xs[k, m] = cx
                    ys[k, m] = cy
                    vx[m] = cx - px[m]
                    vy[m] = cy - py[m]
                    px[m] = cx
                    py[m] = cy
                else:
                    xs[k, m] = px[m]
                    ys[k, m] = py[m]
                    vx[m] = 0.0
                    vy[m] = 0.0
                    reason[k, m] = code
        bar.update(chunk.shape[0])
    return xs, ys, reason


class _NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def _progress_bar(total: int, enabled: bool, desc: str):
    if not enabled:
        return _NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame")


# --------------------------------------------------------------------------------------------
# pass 2: vectorised refinement


def _border_ring(window: int, width: int = 2) -> np.ndarray:
    """Flat indices of the outer ring of ``width`` pixels of a window."""
    mask = np.zeros((window, window), dtype=bool)
    mask[:width, :] = mask[-width:, :] = True
    mask[:, :width] = mask[:, -width:] = True
    return np.flatnonzero(mask)


@dataclass
class _WindowGeometry:
    window: int
    ring: np.ndarray        # flat indices of the border ring used for the plane fit
    plane_pinv: np.ndarray  # (3, len(ring)) least-squares plane on the ring
    plane_basis: np.ndarray  # (3, window*window): 1, x, y at every pixel

    @classmethod
    def make(cls, window: int) -> "_WindowGeometry":
        ring = _border_ring(window, 2)
        yy, xx = np.divmod(np.arange(window * window), window)
        c = (window - 1) / 2.0
        basis = np.stack([np.ones(window * window), xx - c, yy - c])
        pinv = np.linalg.pinv(basis[:, ring].T)
        return cls(window, ring, pinv.astype(np.float32), basis.astype(np.float32))


def _gather(frames: np.ndarray, frame_idx: np.ndarray, x0: np.ndarray, y0: np.ndarray,
            window: int) -> np.ndarray:
    """(K, window, window) uint8 windows with top-left corners (x0, y0) of the given frames.

    A loop of slice copies: faster than one fancy-indexing gather for 30x30 windows.
    """
    out = np.empty((frame_idx.shape[0], window, window), dtype=frames.dtype)
    for k, (f, xa, ya) in enumerate(zip(frame_idx.tolist(), x0.tolist(), y0.tolist())):
        out[k] = frames[f, ya:ya + window, xa:xa + window]
    return out


def _kasa(kk: np.ndarray, xs: np.ndarray, ys: np.ndarray, K: int, weights: np.ndarray | None = None
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


def _crossings(G: np.ndarray, L: np.ndarray
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


def _robust_circle(kk: np.ndarray, xs: np.ndarray, ys: np.ndarray, K: int
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Kasa fit, reject points far from the circle, fit again. Returns a, b, r, rms, count."""
    a, b, r, _ = _kasa(kk, xs, ys, K)
    d = np.hypot(xs - a[kk], ys - b[kk]) - r[kk]
    dd = np.nan_to_num(d * d, nan=1e6)
    cnt = np.bincount(kk, minlength=K).astype(float)
    rms = np.sqrt(np.bincount(kk, weights=dd, minlength=K) / np.maximum(cnt, 1.0))
    keep = (dd <= np.maximum(0.25, 9.0 * rms[kk] ** 2)).astype(float)
    a, b, r, S = _kasa(kk, xs, ys, K, keep)
    d = np.hypot(xs - a[kk], ys - b[kk]) - r[kk]
    dd = np.nan_to_num(d * d, nan=1e6) * keep
    rms = np.sqrt(np.bincount(kk, weights=dd, minlength=K) / np.maximum(S, 1.0))
    return a, b, r, rms, S


def _smooth3(G: np.ndarray) -> np.ndarray:
    """3x3 binomial smoothing ([1 2 1]/4 each way, Gaussian sigma ~0.71 px), 'valid' part.

    (K, w, w) -> (K, w - 2, w - 2); output pixel (i, j) sits at input pixel (i + 1, j + 1).
    """
    A = G[:, :, :-2] + G[:, :, 2:]
    A += 2.0 * G[:, :, 1:-1]
    B = A[:, :-2, :] + A[:, 2:, :]
    B += 2.0 * A[:, 1:-1, :]
    B *= 1.0 / 16.0
    return B


def _refine_isocontour(G: np.ndarray, geo: _WindowGeometry, opts: TrackingOptions
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Default method on a batch of windows G (K, w, w) float32 (bright markers).

    Returns centre a, b (window coordinates), radius and reason codes.
    """
    K, w, _ = G.shape
    flat = G.reshape(K, w * w)
    ring = flat[:, geo.ring]
    # einsum, not matmul: BLAS threads on a busy machine cost 10x more than they save here
    coef = np.einsum("kp,cp->kc", ring, geo.plane_pinv)                 # (K, 3) plane on the ring
    noise = (ring - np.einsum("kc,cp->kp", coef, geo.plane_basis[:, geo.ring])).std(axis=1)
    flat = flat - np.einsum("kc,cp->kp", coef, geo.plane_basis)         # lighting removed
    G2 = flat.reshape(K, w, w)
    off = 0
    if opts.smooth:
        # symmetric smoothing moves no centre; a plane stays a plane, so order is free
        G2 = _smooth3(G2)
        off = 1
    ws = G2.shape[1]
    peak = G2.reshape(K, ws * ws).max(axis=1)
    level = (0.5 * peak).astype(np.float32)
    kk, xs, ys, above = _crossings(G2, level)
    a, b, r, rms, cnt = _robust_circle(kk, xs, ys, K)
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
    return a, b, r, reason


def _refine_report(G: np.ndarray, geo: _WindowGeometry, opts: TrackingOptions
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
        kk, xs, ys, above = _crossings(G, level)
        a, b, r, rms, cnt = _robust_circle(kk, xs, ys, K)
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


def _refine_moments(G: np.ndarray, geo: _WindowGeometry, opts: TrackingOptions
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


_REFINERS = {"isocontour": _refine_isocontour, "report": _refine_report,
             "moments": _refine_moments}


def _refine(frames: np.ndarray, cx: np.ndarray, cy: np.ndarray, reason0: np.ndarray,
            window: int, dark: bool, method: str, opts: TrackingOptions, bar=None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Measure every window again with ``method``, centred on the seeded-pass positions."""
    n, hgt, wid = frames.shape
    m_count = cx.shape[1]
    half = window // 2
    geo = _WindowGeometry.make(window)
    refine = _REFINERS[method]
    X = np.full((n, m_count), np.nan)
    Y = np.full((n, m_count), np.nan)
    R = np.full((n, m_count), np.nan)
    reason = reason0.copy()
    for start in range(0, n, BATCH_FRAMES):
        stop = min(n, start + BATCH_FRAMES)
        chunk = np.asarray(frames[start:stop])
        fi, mi = np.divmod(np.arange((stop - start) * m_count), m_count)
        x0 = np.rint(cx[start:stop].ravel()).astype(np.int64) - half
        y0 = np.rint(cy[start:stop].ravel()).astype(np.int64) - half
        inside = (x0 >= 0) & (y0 >= 0) & (x0 + window <= wid) & (y0 + window <= hgt)
        x0c = np.clip(x0, 0, wid - window)
        y0c = np.clip(y0, 0, hgt - window)
        G = _gather(chunk, fi, x0c, y0c, window).astype(np.float32)
        if dark:
            G = 255.0 - G
        a, b, r, code = refine(G, geo, opts)
        code[~inside] = OUTSIDE
        prev = reason[start:stop].ravel()
        code = np.where(code != OK, code, prev)  # a lost seeded pass stays lost
        X[start:stop] = (x0c + a).reshape(-1, m_count)
        Y[start:stop] = (y0c + b).reshape(-1, m_count)
        R[start:stop] = r.reshape(-1, m_count)
        reason[start:stop] = code.reshape(-1, m_count)
        if bar is not None:
            bar.update(stop - start)
    return X, Y, R, reason


# --------------------------------------------------------------------------------------------
# post checks


def _post_checks(X: np.ndarray, Y: np.ndarray, R: np.ndarray, reason: np.ndarray,
                 window: int, opts: TrackingOptions, check_radius: bool) -> None:
    """Radius consistency and jump tests (in place)."""
    n, m_count = X.shape
    max_jump = opts.max_jump if opts.max_jump is not None else window / 3.0
    for m in range(m_count):
        good = reason[:, m] == OK
        if check_radius and good.any():
            med = np.median(R[good, m])
            tol = max(1.0, opts.radius_tolerance * med)
            bad = good & (np.abs(R[:, m] - med) > tol)
            reason[bad, m] = BAD_RADIUS
            good &= ~bad
        # distance from the last good position (forward fill of the good indices)
        idx = np.where(good, np.arange(n), -1)
        last = np.maximum.accumulate(idx)
        prev = np.concatenate([[-1], last[:-1]])
        has_prev = good & (prev >= 0)
        k = np.flatnonzero(has_prev)
        pk = prev[k]
        jump = np.hypot(X[k, m] - X[pk, m], Y[k, m] - Y[pk, m]) > max_jump * (k - pk)
        reason[k[jump], m] = JUMP


# --------------------------------------------------------------------------------------------
# public API


def track_recording(frames: np.ndarray, seeds: np.ndarray, *, method: str = DEFAULT_METHOD,
                    window: int = DEFAULT_WINDOW, dark: bool = False, progress: bool = False,
                    options: TrackingOptions | None = None) -> Tracks:
    """Track markers through a recording.

    Args:
        frames: (N, H, W) uint8 frames (a memory-mapped stack is fine).
        seeds: (M, 2) x, y positions [px] of the markers in frame 0 (within a few px). With
            three markers use the order ABU centre, CD marker, ball.
        method: ``isocontour`` (default, most accurate, robust to uneven lighting),
            ``report`` (the report's multi-level contours) or ``moments`` (fast baseline).
        window: side of the square search window [px].
        dark: True for markers darker than their surroundings.
        progress: show a progress bar (tqdm) on stderr.
        options: thresholds of the lost-marker tests.

    Returns:
        :class:`Tracks` with x, y (N, M) [px] (NaN where lost), lost flags and reasons.

    Raises:
        ParameterError: unknown method or bad window size.
        TrackingError: frames or seeds of the wrong shape, seeds outside the frame.
    """
    frames, seeds, window = _check_inputs(frames, seeds, window, method)
    opts = options or TrackingOptions()
    bar = _progress_bar(2 * frames.shape[0], progress, f"tracking ({method}, 2 passes)")
    try:
        xs, ys, reason = _seeded_moments(frames, seeds, window, dark, opts, bar)
        X, Y, R, reason = _refine(frames, xs, ys, reason, window, dark, method, opts, bar)
    finally:
        bar.close()
    _post_checks(X, Y, R, reason, window, opts, check_radius=True)
    lost = reason != OK
    X = np.where(lost, np.nan, X)
    Y = np.where(lost, np.nan, Y)
    R = np.where(lost, np.nan, R)
    return Tracks(x=X, y=Y, lost=lost, reason=reason, radius=R, method=method, window=window,
                  dark=bool(dark), options=opts)


def measure_windows(windows: np.ndarray, *, method: str = DEFAULT_METHOD, dark: bool = False,
                    options: TrackingOptions | None = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Centre of the marker in each of a batch of windows (K, w, w) uint8 (no seeding).

    Returns x, y [px, window coordinates], radius [px] and reason codes (0 = found).
    Useful for tests and for measuring single images.
    """
    if method not in METHODS:
        raise ParameterError("method", method, f"one of {', '.join(METHODS)}")
    opts = options or TrackingOptions()
    win = np.asarray(windows)
    if win.ndim != 3 or win.shape[1] != win.shape[2] or win.dtype != np.uint8:
        raise TrackingError(f"windows: expected (K, w, w) uint8, got {win.shape} {win.dtype}")
    K, w, _ = win.shape
    G = win.astype(np.float32)
    if dark:
        G = 255.0 - G
    a, b, r, code = _REFINERS[method](G, _WindowGeometry.make(w), opts)
    lost = code != OK
    return (np.where(lost, np.nan, a), np.where(lost, np.nan, b), np.where(lost, np.nan, r),
            code)
