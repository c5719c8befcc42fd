"""Sub-pixel tracking of the three markers (ABU centre, CD marker, ball) through a recording.

Coordinates follow OpenCV: x = column, y = row, pixel centres at integers, origin at the
centre of the top-left pixel. All positions are in pixels [px].

How it works (two passes, chunk by chunk of frames, :mod:`measurement.imaging.track_passes`):

1. **Seeded pass** (sequential, cheap): for each frame and marker, a square window (default
   30x30 px) is put at the marker's position in the previous frame (plus the last frame-to-frame
   displacement) and the centroid of ``(I - L)+`` is taken, L being the midpoint of the window's
   darkest and brightest grey levels (as ``cv2.moments`` computes it). This is the report's
   seeding (appendix B).
2. **Refinement**: a window is put at the seeded-pass position of the *same* frame and the
   centre is measured again with the chosen method (:mod:`measurement.imaging.window_fits`):

   * ``isocontour`` (default): subtract a plane fitted to the window's border ring (removes an
     additive lighting gradient), smooth with a 3x3 binomial kernel, take the 50 % iso-contour
     of the bilinear interpolation of the pixels (its vertices are the sub-pixel crossings of
     the level on the pixel grid's edges, as in marching squares), fit a circle algebraically
     (Kasa), reject outlier points, fit again. Then (``TrackingOptions(edge_step=True)``, the
     default; off with ``TrackingOptions(edge_step=False)`` or ``--no-edge-step``) one
     least-squares (Gauss-Newton) step of a blurred-disk model on the unsmoothed pixels near
     the edge moves the centre (:mod:`measurement.imaging.edge_step`: 17-30 % less RMS
     error). The command line's tracker applies it to the centre and CD paper disks of a
     one-reflection recording only (:func:`measurement.imaging.edge_step_roles.edge_step_default`).
   * ``report``: the report's method (appendix B): several contour levels between percentage
     bounds of the window's min..max grey levels (no lighting correction), a circle fit to each
     contour, the centres averaged. MATLAB's ``contour`` interpolates linearly, so the contour
     points are the same sub-pixel grid crossings.
   * ``moments``: the seeded pass's centroid again, vectorised, in the re-centred window (the
     fast baseline), with the lost-marker tests below plus a compactness test.

The seeded pass and the ``isocontour`` refinement run in compiled kernels
(``measurement/imaging/_trackc.c``, built by ``pip install -e .``) one window at a time; without
them the same arithmetic runs in OpenCV and NumPy (vectorised over the windows of a chunk),
with the same results (tests/test_tracking_kernels.py: seeded pass identical, positions within
1e-9 px).

Speed (benchmarks/bench_tracking.py, 3072 frames of 256x256 px, 3 markers, one core, CPU
time): the command line's tracker (the edge step on the centre and CD markers) with the
kernels runs at ~0.9x the speed of a plain ``cv2.moments`` tracker without sub-pixel fit or
lost-marker tests (~39,000 frames/s, ~9x the camera's 4500 frames/s) at 0.0077 / 0.0100 /
0.0102 px RMS on the rendered staircase recording; the step on all three markers ~0.8-0.9x
(~37,000 frames/s) at 0.0077 / 0.0100 / 0.0083 px; without it ~1.1-1.2x (~49,000 frames/s) at
0.0109 / 0.0123 / 0.0102 px; the NumPy fallback at ~7,500 frames/s (~13,000 without the step).
Measured accuracy is in docs/measurement-imaging.md.

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

from measurement.imaging import window_fits as W
from measurement.imaging.track_passes import (  # noqa: F401  (BATCH_FRAMES re-exported)
    BATCH_FRAMES, NoBar, track_passes)
from measurement.imaging.track_passes import seeded_moments as _seeded_moments  # noqa: F401
from measurement.imaging.window_fits import (  # noqa: F401  (re-exported names)
    BAD_RADIUS, FIT_FAILED, JUMP, LOST_REASONS, LOW_CONTRAST, OK, OUTSIDE, TOUCHES_EDGE,
    TrackingOptions)

METHODS = ("isocontour", "report", "moments")
DEFAULT_METHOD = "isocontour"
DEFAULT_WINDOW = 30


class TrackingError(AbuError):
    """Tracking cannot start (bad seeds, window or frames)."""


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
        options: the tracker's options (of the first markers where they differed).
        edge_step_markers: per marker, whether its fit ended with the edge step (None: as
            ``options.edge_step`` for every marker).
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
    edge_step_markers: tuple[bool, ...] | None = None

    def stepped(self) -> tuple[bool, ...]:
        """Per marker, whether the edge step ended its fit (``isocontour`` only)."""
        if self.edge_step_markers is not None:
            return tuple(self.edge_step_markers)
        on = bool(self.options.edge_step) and self.method == "isocontour"
        return (on,) * int(self.x.shape[1])

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


def _progress_bar(total: int, enabled: bool, desc: str):
    if not enabled:
        return NoBar()
    from tqdm import tqdm

    return tqdm(total=total, desc=desc, unit="frame")


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
        limit = max_jump * (k - pk)
        jump = np.hypot(X[k, m] - X[pk, m], Y[k, m] - Y[pk, m]) > limit
        # ... and from the position the good frame before predicts (the seeded pass's test):
        # a marker faster than max_jump px/frame (a low frame rate) is no jump
        ppk = prev[np.maximum(pk, 0)]
        moving = jump & (ppk >= 0)
        i = np.flatnonzero(moving)
        a, b, c = k[i], pk[i], ppk[i]
        steps = (a - b) / (b - c)
        ex = X[a, m] - X[b, m] - steps * (X[b, m] - X[c, m])
        ey = Y[a, m] - Y[b, m] - steps * (Y[b, m] - Y[c, m])
        jump[i] = np.hypot(ex, ey) > limit[i]
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
        X, Y, R, reason = track_passes(frames, seeds, window, dark, method, opts, bar)
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
    a, b, r, code = W.REFINERS[method](G, W.WindowGeometry.make(w), opts)
    lost = code != OK
    return (np.where(lost, np.nan, a), np.where(lost, np.nan, b), np.where(lost, np.nan, r),
            code)
