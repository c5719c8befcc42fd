"""A faint ball against its own appearance: the fallback of the silhouette tracker
(:mod:`measurement.imaging.reflections`) for balls whose outline stands only 1-2 noise sigma
above the plane.

One frame of such a ball is too noisy for the silhouette's ray crossings (the fit fails or
lands on noise), but its appearance changes slowly: the highlights belong to the lamps and the
silhouette to the ball. So each frame is compared with a *template*, the mean of the
neighbouring :data:`STACK_FRAMES` frames' windows aligned on the predicted positions (the frame
itself left out, so that its noise does not pull the template), whose noise is ~8 times
lower:

* the template's own silhouette (:func:`silhouette.refine_silhouette`) says where the ball sits
  in the aligned windows;
* the frame's shift against the template is the least-squares (Gauss-Newton) fit of
  template(x - d) to the frame's window: for a known shape in white noise this is the
  maximum-likelihood shift, and it uses every pixel of the outline, not 36 ray crossings.

Each position carries only its own frame's noise (white, as the inference assumes); the
template's error is common to neighbouring frames and changes slowly along the record, like
the lighting leftover the inference already models.

The windows are placed where the ball must be: it rides on the CD, so at c + k (cd - c) with
c and cd the centre and CD markers' tracks and k the complex ratio (ball - c) / (cd - c),
which changes only as the ball slips. A first pass follows the record 16 frames at a time, k
extrapolated from the frames placed so far (after the onset the ball can move tens of pixels
against the CD); a second pass aligns every window on the first pass's k (median over 17
frames), so that each template is centred on its frame. The radius is read from the first
frames' template, not from one noisy frame.

Measured (``tests/test_tracking.py -k template``; unseen seeds of twin.lighting_alt that the
silhouette loses in 24-92 % of the frames): every frame kept, 0.15-0.32 px RMS about the mean
offset; ``benchmarks/bench_coverage.py --faint-two-spot``: the coverage of the intervals.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from measurement.imaging import silhouette as S
from measurement.imaging import window_fits as W

#: Frames averaged into a template (odd; the frame itself left out). 65 frames at 4500
#: frames/s are 14 ms, in which the outline does not change (the highlights move with the
#: ball's place under the lamps: slowly, a bias like the lighting leftover); the template's
#: noise is 1/8 of a frame's. With 33 a ball faded to a fifth of its contrast (bench_coverage
#: --faint-two-spot, seed 30001) was lost in every frame from its true seed, with 65 in 1 %
#: (a one-off; the faint slices quoted in the README were run with 65).
STACK_FRAMES = 65
#: Largest accepted shift of a frame against its template [px] (or half the radius): the
#: windows are centred on the ball's predicted position.
MAX_SHIFT_PX = 1.0
#: Largest accepted standard error of a frame's shift [px] (from its fit's residual): above
#: it the frame carries too little of the ball's outline to place it.
MAX_SHIFT_SE_PX = 0.5
#: Gauss-Newton steps of the shift.
SHIFT_STEPS = 3


def ball_window(radius_px: float) -> int:
    """Window side for the ball [px]: the ball plus a ring of background for the plane."""
    return int(2 * np.ceil(radius_px) + 10)


def template_radius(frames: np.ndarray, cx: np.ndarray, cy: np.ndarray, radius_px: float,
                    opts: "W.TrackingOptions") -> float | None:
    """The ball's radius [px] from the template of the frames given, windows centred on
    (cx, cy) [px] (one frame of a faint ball can put it a pixel off or fail): the template's
    silhouette from the guesses ``radius_px``, 4, 5, 6 and 8 px, the first that fits."""
    for guess in (radius_px, 4.0, 5.0, 6.0, 8.0):
        ws = ball_window(max(guess, radius_px) + 2.0)
        geo = W.WindowGeometry.make(ws)
        G, inside = subpixel_windows(frames, cx, cy, ws)
        if not inside.all():
            continue
        H, _ = S._plane_corrected(G, geo)
        a, b, r, code = S.refine_silhouette(H.mean(axis=0, keepdims=True), geo,
                                            replace(opts, min_contrast=0.0), guess)
        if code[0] == W.OK:
            return float(r[0])
    return None


def _bilinear(G: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
    """(K, w, w) windows at fractional offsets (fx, fy) in [0, 1) (K,) [px] into the
    (K, w + 1, w + 1) windows G, by bilinear interpolation."""
    fx = np.asarray(fx, np.float32)[:, None, None]
    fy = np.asarray(fy, np.float32)[:, None, None]
    top = (1 - fx) * G[:, :-1, :-1] + fx * G[:, :-1, 1:]
    bottom = (1 - fx) * G[:, 1:, :-1] + fx * G[:, 1:, 1:]
    return (1 - fy) * top + fy * bottom


def subpixel_windows(frames: np.ndarray, cx: np.ndarray, cy: np.ndarray, ws: int
                     ) -> tuple[np.ndarray, np.ndarray]:
    """(N, ws, ws) float32 windows centred on (cx, cy) [px] (bilinear), and whether each
    lies inside the frame. Window pixel (i, j) is image point (cx - (ws-1)/2 + j, cy - (ws-1)/2
    + i)."""
    n, hgt, wid = frames.shape
    h = (ws - 1) / 2.0
    x0, y0 = cx - h, cy - h
    ix, iy = np.floor(x0).astype(np.int64), np.floor(y0).astype(np.int64)
    inside = (ix >= 0) & (iy >= 0) & (ix + ws + 1 <= wid) & (iy + ws + 1 <= hgt)
    ixc, iyc = np.clip(ix, 0, wid - ws - 1), np.clip(iy, 0, hgt - ws - 1)
    G = W.gather(frames, np.arange(n), ixc, iyc, ws + 1).astype(np.float32)
    return _bilinear(G, np.where(inside, x0 - ix, 0.0), np.where(inside, y0 - iy, 0.0)), inside


def _shifted(T: np.ndarray, d: np.ndarray) -> np.ndarray:
    """T(x - d) per window (K, w, w), shifts d (K, 2) [px] clipped to half a window, the
    edges repeated beyond the window (bilinear, as :func:`subpixel_windows`)."""
    K, w, _ = T.shape
    pad = w // 2 + 1
    s = np.clip(-np.asarray(d, float), -(w // 2), w // 2)   # sample at x + s
    ix, iy = np.floor(s[:, 0]).astype(np.int64), np.floor(s[:, 1]).astype(np.int64)
    P = np.pad(T, ((0, 0), (pad, pad), (pad, pad)), mode="edge")
    G = W.gather(P, np.arange(K), pad + ix, pad + iy, w + 1)
    return _bilinear(G, s[:, 0] - ix, s[:, 1] - iy)


def leave_one_out_means(H: np.ndarray, size: int) -> np.ndarray:
    """Mean over the ``size`` frames centred on each frame (fewer at the ends), the frame
    itself left out: (N, w, w)."""
    n = H.shape[0]
    half = size // 2
    c = np.concatenate([np.zeros((1,) + H.shape[1:], np.float64),
                        np.cumsum(H, axis=0, dtype=np.float64)])
    lo = np.clip(np.arange(n) - half, 0, n)
    hi = np.clip(np.arange(n) + half + 1, 0, n)
    total = c[hi] - c[lo] - H
    return (total / np.maximum(hi - lo - 1, 1)[:, None, None]).astype(np.float32)


def _shift(Hk: np.ndarray, Tk: np.ndarray, mask: np.ndarray
           ) -> tuple[np.ndarray, np.ndarray]:
    """Shift d (dx, dy) [px] with template(x - d) + offset ~ window, by Gauss-Newton on the
    pixels of ``mask``; returns d (K, 2) and its standard error (K,) [px] (inf where the
    template has no gradient)."""
    K = Hk.shape[0]
    d = np.zeros((K, 2))
    for _ in range(SHIFT_STEPS):
        Ts = _shifted(Tk, d)
        gy, gx = np.gradient(Ts, axis=(1, 2))
        # model: Ts - gx ddx - gy ddy + b; unknowns (ddx, ddy, b)
        J = np.stack([-gx[:, mask], -gy[:, mask], np.ones_like(gx[:, mask])], axis=2)
        r = (Hk - Ts)[:, mask]
        JtJ = np.einsum("kpi,kpj->kij", J, J)
        ok = np.linalg.det(JtJ) > 0
        step = np.zeros((K, 3))
        step[ok] = np.linalg.solve(JtJ[ok], np.einsum("kpi,kp->ki", J, r)[ok][..., None])[..., 0]
        d += step[:, :2]
    # the standard error of the last step's linearisation, scaled by its residual
    res = r - np.einsum("kpi,ki->kp", J, step)
    s2 = (res * res).sum(axis=1) / max(int(mask.sum()) - 3, 1)
    se = np.full(K, np.inf)
    inv = np.linalg.inv(JtJ[ok])
    se[ok] = np.sqrt((inv[:, 0, 0] + inv[:, 1, 1]) * s2[ok])
    return d, se


def _guided(zc: np.ndarray, zd: np.ndarray, k: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions c + k (cd - c) [px] (the ball rides on the CD; k is the complex ratio
    (ball - c) / (cd - c), which changes only as the ball slips)."""
    z = zc + k * (zd - zc)
    return z.real, z.imag


def _smooth_ratio(k: np.ndarray, ok: np.ndarray, size: int) -> np.ndarray:
    """k of the good frames, median-smoothed over ``size`` frames and interpolated over the
    others (a slip moves k by far less than a pixel within 4 ms)."""
    n = k.size
    good = np.flatnonzero(ok)
    kr = np.interp(np.arange(n), good, k.real[good])
    ki = np.interp(np.arange(n), good, k.imag[good])
    half = size // 2
    pad_r = np.pad(kr, half, mode="edge")
    pad_i = np.pad(ki, half, mode="edge")
    win_r = np.lib.stride_tricks.sliding_window_view(pad_r, size)
    win_i = np.lib.stride_tricks.sliding_window_view(pad_i, size)
    return np.median(win_r, axis=1) + 1j * np.median(win_i, axis=1)


#: Frames per step of the first, following pass.
FOLLOW_BLOCK = 16


def _place(frames: np.ndarray, frame_idx: np.ndarray, cx: np.ndarray, cy: np.ndarray,
           geo: "W.WindowGeometry", opts: "W.TrackingOptions", radius_px: float,
           targets: np.ndarray) -> tuple[np.ndarray, ...]:
    """Positions [px] of the ``targets`` (indices into ``frame_idx``) against the template of
    the frames ``frame_idx`` (consecutive) with windows centred on (cx, cy) [px]: x, y,
    radius, reason, for the targets."""
    ws = geo.window
    h = (ws - 1) / 2.0
    G, inside = subpixel_windows(frames[frame_idx[0]:frame_idx[-1] + 1], cx, cy, ws)
    H, _ = S._plane_corrected(G, geo)
    Tm = leave_one_out_means(H, STACK_FRAMES)[targets]
    H, inside, cx, cy = H[targets], inside[targets], cx[targets], cy[targets]
    # the template's noise is ~8 times lower: its ring's SNR test (RING_SNR sigma of
    # its own border) tells a ball from noise, not a frame's contrast floor
    a, b, r, code = S.refine_silhouette(Tm, geo, replace(opts, min_contrast=0.0), radius_px)
    X = np.full(targets.size, np.nan)
    Y = np.full(targets.size, np.nan)
    good = code == W.OK
    if good.any():
        # the outline and its blur: the pixels that tell where the ball is
        yy, xx = np.mgrid[0:ws, 0:ws]
        mask = np.hypot(xx - float(np.median(a[good])), yy - float(np.median(b[good]))) \
            <= min(radius_px + 2.5, h - 1.0)
        d, se = _shift(H, Tm, mask)
        X, Y = cx - h + a + d[:, 0], cy - h + b + d[:, 1]
        good &= inside & np.isfinite(X) & np.isfinite(Y) & (se <= MAX_SHIFT_SE_PX)
        good &= np.hypot(d[:, 0], d[:, 1]) <= max(MAX_SHIFT_PX, 0.5 * radius_px)
    reason = np.where(good, W.OK, np.where(code != W.OK, code, W.FIT_FAILED)).astype(np.uint8)
    reason[~inside] = W.OUTSIDE
    return X, Y, r, reason


def _predicted_ratio(k: np.ndarray, ok: np.ndarray, upto: int, at: np.ndarray) -> np.ndarray:
    """k at frames ``at`` extrapolated from the good frames before ``upto``: a line through
    the last 33 of them (the ball's slip changes k smoothly)."""
    good = np.flatnonzero(ok[:upto])[-33:]
    if good.size < 8:
        return np.full(at.size, k[good[-1]] if good.size else k[0])
    t = good - good[-1]
    cr = np.polyfit(t, k.real[good], 1)
    ci = np.polyfit(t, k.imag[good], 1)
    return np.polyval(cr, at - good[-1]) + 1j * np.polyval(ci, at - good[-1])


def template_track(frames: np.ndarray, seed: np.ndarray, guide: np.ndarray, radius_px: float,
                   opts: "W.TrackingOptions"
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The ball's centre per frame [px] from its frame-0 position ``seed`` [px] and the
    ``guide`` (N, 2, 2), the ABU centre's and CD marker's tracks [px]: x, y, radius [px] and
    reason (:data:`window_fits.OK` where placed); ``radius_px``: frame 0's estimate, checked
    on the first frames' template. See the module doc."""
    n = frames.shape[0]
    zc = guide[:, 0, 0] + 1j * guide[:, 0, 1]
    zd = guide[:, 1, 0] + 1j * guide[:, 1, 1]
    known = np.isfinite(zc) & np.isfinite(zd) & (np.abs(zd - zc) > 0)
    X, Y, R = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    reason = np.full(n, W.FIT_FAILED, np.uint8)
    if not known[0]:   # no guide in frame 0: nothing placed (the silhouette's track stands)
        return X, Y, R, reason
    # where the centre or CD is lost the guide is interpolated (the analysis refuses a
    # track with more than a few lost frames in a row anyway)
    idx = np.flatnonzero(known)
    ar = np.arange(n)
    zc = np.interp(ar, idx, zc.real[idx]) + 1j * np.interp(ar, idx, zc.imag[idx])
    zd = np.interp(ar, idx, zd.real[idx]) + 1j * np.interp(ar, idx, zd.imag[idx])
    k = np.full(n, (complex(seed[0], seed[1]) - zc[0]) / (zd[0] - zc[0]))
    ok = np.zeros(n, bool)
    first = min(n, STACK_FRAMES)
    radius = template_radius(frames[:first], *_guided(zc[:first], zd[:first], k[:first]),
                             radius_px, opts)
    if radius is None:
        return X, Y, R, reason
    radius_px = radius
    geo = W.WindowGeometry.make(ball_window(radius_px))
    half = STACK_FRAMES // 2
    # first pass: followed block by block, k extrapolated from the frames placed so far
    for start in range(0, n, FOLLOW_BLOCK):
        stop = min(n, start + FOLLOW_BLOCK)
        lo, hi = max(0, start - half), min(n, stop + half)
        span = np.arange(lo, hi)
        kk = np.where(ok[span], k[span], _predicted_ratio(k, ok, start, span))
        cx, cy = _guided(zc[span], zd[span], kk)
        x, y, r, why = _place(frames, span, cx, cy, geo, opts, radius_px,
                              np.arange(start - lo, stop - lo))
        X[start:stop], Y[start:stop], R[start:stop], reason[start:stop] = x, y, r, why
        ok[start:stop] = why == W.OK
        got = np.flatnonzero(ok[start:stop]) + start
        k[got] = (X[got] + 1j * Y[got] - zc[got]) / (zd[got] - zc[got])
    if not ok.any():
        return X, Y, R, reason
    # second pass: every window aligned on the first pass (symmetric templates)
    cx, cy = _guided(zc, zd, _smooth_ratio(k, ok, FOLLOW_BLOCK + 1))
    X, Y, R, reason = _place(frames, ar, cx, cy, geo, opts, radius_px, ar)
    return X, Y, R, reason
