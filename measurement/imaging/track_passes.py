"""The tracker's two passes (:mod:`measurement.imaging.tracking`), chunk by chunk of frames.

Each chunk of :data:`BATCH_FRAMES` frames is seeded and then refined while its windows are
still in the CPU cache (a 3072-frame recording is 200 MB: read twice from memory, the windows
cost the compiled refinement ~30 % more time).

Both passes have a compiled kernel (``_trackc``, C, built by ``pip install -e .``) and a
NumPy/OpenCV path used when the kernel is not built (or for the ``report`` and ``moments``
methods). They give the same results: the seeded pass exactly, the isocontour refinement to
~1e-12 px (tests/test_tracking_kernels.py runs both on the same frames).
"""
from __future__ import annotations

import numpy as np

from measurement.imaging import edge_step as E
from measurement.imaging import window_fits as W
from measurement.imaging.window_fits import JUMP, LOW_CONTRAST, OK, OUTSIDE, TrackingOptions

try:  # the compiled kernels, built by `pip install -e .` where a C compiler is found
    from measurement.imaging import _trackc
except ImportError:  # pragma: no cover - the NumPy/OpenCV path gives the same results
    _trackc = None

#: Frames per chunk (bounds memory: chunk * markers * window^2 floats). 128 keeps a chunk's
#: windows in the CPU cache: the NumPy refinement of 3072 frames took ~115 ms of CPU against
#: ~140 ms with 256 (same results; the chunk only groups independent windows).
BATCH_FRAMES = 128


class NoBar:
    def update(self, n: int) -> None:
        pass

    def close(self) -> None:
        pass


def compiled() -> bool:
    """True when the compiled kernels are in use."""
    return _trackc is not None


def _max_jump(window: int, opts: TrackingOptions) -> float:
    return float(opts.max_jump if opts.max_jump is not None else window / 3.0)


def initial_state(seeds: np.ndarray) -> np.ndarray:
    """Seeded-pass state per marker (x..., y..., vx..., vy...) [px, px/frame] at the seeds."""
    m_count = seeds.shape[0]
    state = np.zeros(4 * m_count)
    state[:m_count], state[m_count:2 * m_count] = seeds[:, 0], seeds[:, 1]
    return state


# --------------------------------------------------------------------------------------------
# pass 1: seeded moments (sequential)


def seeded_chunk(chunk: np.ndarray, state: np.ndarray, window: int, dark: bool,
                 opts: TrackingOptions, xs: np.ndarray, ys: np.ndarray, reason: np.ndarray
                 ) -> None:
    """Seeded pass over one chunk of frames: fills xs, ys (K, M) [px] and reason (K, M) and
    advances ``state`` (see :func:`initial_state`), all in place.

    A window (``window`` px) at the marker's last good position plus its last displacement;
    the centroid of (I - L)+, L the midpoint of the window's min and max. Where lost, xs, ys
    hold the last good position (it seeds the next frame).
    """
    if _trackc is not None:
        nf, hgt, wid = chunk.shape
        _trackc.seeded(np.ascontiguousarray(chunk), nf, hgt, wid, xs.shape[1], window,
                       bool(dark), float(opts.min_contrast), _max_jump(window, opts), state,
                       xs, ys, reason)
    else:
        _seeded_chunk_py(chunk, state, window, dark, opts, xs, ys, reason)


def _seeded_chunk_py(chunk: np.ndarray, state: np.ndarray, window: int, dark: bool,
                     opts: TrackingOptions, xs: np.ndarray, ys: np.ndarray, reason: np.ndarray
                     ) -> None:
    """:func:`seeded_chunk` with OpenCV calls per window (the kernel's fallback)."""
    import cv2

    _, hgt, wid = chunk.shape
    m_count = xs.shape[1]
    half = window // 2
    max_jump = _max_jump(window, opts)
    # last good position and velocity [px/frame] per marker, as lists: fast scalar access
    px, py, vx, vy = (state[i * m_count:(i + 1) * m_count].tolist() for i in range(4))
    minmax, subtract, moments = cv2.minMaxLoc, cv2.subtract, cv2.moments
    if dark:
        chunk = 255 - chunk  # a dark marker becomes a bright one
    for k in range(chunk.shape[0]):
        frame = chunk[k]
        for m in range(m_count):
            qx, qy = px[m] + vx[m], py[m] + vy[m]  # the prediction
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
                        # a jump is far from both the last good position (one disturbed
                        # frame must not make the next good one look like a jump) and the
                        # prediction (a fast marker moves more than max_jump a frame)
                        j2 = max_jump * max_jump
                        if (cx - px[m]) ** 2 + (cy - py[m]) ** 2 > j2 \
                                and (cx - qx) ** 2 + (cy - qy) ** 2 > j2:
                            code = JUMP
            reason[k, m] = code
            if code == OK:
                xs[k, m], ys[k, m] = cx, cy
                vx[m], vy[m] = cx - px[m], cy - py[m]
                px[m], py[m] = cx, cy
            else:
                xs[k, m], ys[k, m] = px[m], py[m]
                vx[m] = vy[m] = 0.0
    state[:] = px + py + vx + vy


def seeded_moments(frames: np.ndarray, seeds: np.ndarray, window: int, dark: bool,
                   opts: TrackingOptions, bar=None
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The seeded pass over a whole recording: x, y (N, M) [px] and reason (N, M) codes."""
    n = frames.shape[0]
    m_count = seeds.shape[0]
    xs, ys = np.empty((n, m_count)), np.empty((n, m_count))
    reason = np.zeros((n, m_count), dtype=np.uint8)
    state = initial_state(seeds)
    bar = bar or NoBar()
    for start in range(0, n, BATCH_FRAMES):
        stop = min(n, start + BATCH_FRAMES)
        seeded_chunk(np.asarray(frames[start:stop]), state, window, dark, opts,
                     xs[start:stop], ys[start:stop], reason[start:stop])
        bar.update(stop - start)
    return xs, ys, reason


# --------------------------------------------------------------------------------------------
# pass 2: refinement, vectorised over a chunk's windows (or compiled)


def refine_chunk(chunk: np.ndarray, cx: np.ndarray, cy: np.ndarray, reason0: np.ndarray,
                 window: int, dark: bool, method: str, geo: W.WindowGeometry,
                 opts: TrackingOptions
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Measure every window of a chunk again with ``method``, centred on the seeded positions
    cx, cy (K, M) [px]. Returns X, Y, R (K, M) [px] and the reason codes (K, M)."""
    nf, hgt, wid = chunk.shape
    m_count = cx.shape[1]
    half = window // 2
    fi = np.repeat(np.arange(nf), m_count)
    x0 = np.rint(cx.ravel()).astype(np.int64) - half
    y0 = np.rint(cy.ravel()).astype(np.int64) - half
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + window <= wid) & (y0 + window <= hgt)
    x0c = np.clip(x0, 0, wid - window)
    y0c = np.clip(y0, 0, hgt - window)
    if method == "isocontour" and _trackc is not None:
        a, b, r, code = _refine_compiled(chunk, fi, x0c, y0c, window, dark, geo, opts)
    else:
        G = W.gather(chunk, fi, x0c, y0c, window).astype(np.float32)
        if dark:
            G = 255.0 - G
        a, b, r, code = W.REFINERS[method](G, geo, opts)
    code[~inside] = OUTSIDE
    code = np.where(code != OK, code, reason0.ravel())  # a lost seeded pass stays lost
    shape = (nf, m_count)
    return ((x0c + a).reshape(shape), (y0c + b).reshape(shape), r.reshape(shape),
            code.reshape(shape))


def _refine_compiled(chunk: np.ndarray, fi: np.ndarray, x0: np.ndarray, y0: np.ndarray,
                     window: int, dark: bool, geo: W.WindowGeometry, opts: TrackingOptions
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``window_fits.refine_isocontour`` by the C kernel on the windows at (x0, y0) of frames fi."""
    chunk = np.ascontiguousarray(chunk)
    K = fi.shape[0]
    a, b, r = np.empty(K), np.empty(K), np.empty(K)
    code = np.empty(K, dtype=np.uint8)
    r_max = opts.r_max if opts.r_max is not None else window / 2.0 - 2.0
    fi, x0, y0, ring = (np.ascontiguousarray(v, dtype=np.int64) for v in (fi, x0, y0, geo.ring))
    nf, hgt, wid = chunk.shape
    _trackc.refine(chunk, nf, hgt, wid, fi, x0, y0, K, window, bool(dark), ring,
                   geo.plane_pinv64, bool(opts.smooth), float(opts.min_contrast),
                   float(opts.min_snr), float(opts.r_min), float(r_max),
                   float(opts.max_residual), float(opts.min_points), bool(opts.edge_step),
                   float(opts.edge_width_px), E.BAND_PX, E.MAX_STEP_PX, E.TABLE_HALF, E.PHI,
                   E.DPHI, a, b, r, code)
    return a, b, r, code


def track_passes(frames: np.ndarray, seeds: np.ndarray, window: int, dark: bool, method: str,
                 opts: TrackingOptions, bar=None
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Both passes, chunk by chunk. Returns X, Y, R (N, M) [px] and reason (N, M) codes."""
    n = frames.shape[0]
    m_count = seeds.shape[0]
    geo = W.WindowGeometry.make(window)
    X, Y, R = (np.empty((n, m_count)) for _ in range(3))
    reason = np.zeros((n, m_count), dtype=np.uint8)
    cx, cy = np.empty((BATCH_FRAMES, m_count)), np.empty((BATCH_FRAMES, m_count))
    code0 = np.zeros((BATCH_FRAMES, m_count), dtype=np.uint8)
    state = initial_state(seeds)
    bar = bar or NoBar()
    for start in range(0, n, BATCH_FRAMES):
        stop = min(n, start + BATCH_FRAMES)
        k = stop - start
        chunk = np.asarray(frames[start:stop])
        seeded_chunk(chunk, state, window, dark, opts, cx[:k], cy[:k], code0[:k])
        X[start:stop], Y[start:stop], R[start:stop], reason[start:stop] = refine_chunk(
            chunk, cx[:k], cy[:k], code0[:k], window, dark, method, geo, opts)
        bar.update(2 * k)
    return X, Y, R, reason
