"""The ball under two reflections (report sec. 5.2, indirect lighting with two spots).

Under that lighting the brass ball shows a faint body and two small, often saturated
reflections of the two spots. A single-marker tracker sees two blobs in the ball's window and
cannot fit one circle (it flags the ball lost: never a silent wrong centre). Two ways to get the
ball centre (``ball_method``):

* ``pair`` (the report's way): one marker per reflection, the ball = their mean. Each
  reflection is located as the intensity-weighted centroid of the pixels above 60 % of the
  window's range, split into two groups along their principal axis. The mean of the two
  reflections is *not* the ball centre: each reflection sits where the ball's normal bisects
  the lamp and camera directions, so the mean is offset toward the lamps' mean azimuth by
  R sin(tilt), and that offset changes with the ball's world angle (the lamps are at a finite
  distance): a harmonic disturbance of beta, as in the report.
* ``outline`` (default, ours): the ball's silhouette. The window is plane-corrected on its
  border (as the default tracker), the reflections are clipped to the body level b (median of
  the inner disk), a circle is fitted to the sub-pixel crossings of the level b/3, then
  refitted on 36 radial profiles, each crossed half-way between its own inside and outside
  levels (robust to one side of the body being dimmer), with outlier rejection. The outline
  does not depend on where the reflections are, only (weakly) on the shading of the body.

* ``silhouette`` (:mod:`silhouette`): the outermost point of each ray where the ball differs
  from the plane, dark or bright: for balls the outline cannot read (a body darker than the
  plane under diffuse light, highlights covering the body; the second highlight model
  :mod:`twin.lighting_alt`). ``outline`` falls back to it for the whole recording when it
  fails on most of the first frames or loses more than 2 % of them (then only if the
  silhouette loses fewer), so recordings the outline reads keep their results; where the
  silhouette loses more than 2 %, a faint ball is placed against its own template
  (:mod:`ball_template`).

:func:`track_with_reflections` tracks the ABU centre and CD markers with the default tracker
and the ball with one of these, returning ordinary :class:`tracking.Tracks` (3 markers). A
ball window without two reflections (``pair``) or without a plausible outline (``outline``)
is flagged lost with its reason, exactly like a lost marker.
"""
from __future__ import annotations

import numpy as np

from abu_model.errors import ParameterError

from measurement.imaging import tracking as T
from measurement.imaging.ball_template import ball_window as _ball_window, template_track
from measurement.imaging.edge_step_roles import edge_step_default, track_by_step
from measurement.imaging.reflection_pair import refine_pair
from measurement.imaging import window_fits as W
from measurement.imaging.silhouette import _plane_corrected, refine_silhouette

BALL_METHODS = ("outline", "pair", "silhouette")
DEFAULT_BALL_METHOD = "outline"
#: Level of the silhouette as a fraction of the body level [-] (first fit).
LEVEL = 0.33
#: Refit the silhouette on 72 radial profiles ...
EDGE_REFINE = True
#: ... at each ray's half-way level ("local") or at its steepest point ("gradient").
EDGE_MODE = "local"


def refine_outline(G: np.ndarray, geo, opts: "T.TrackingOptions", radius_px: float,
                   edges: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Our way: circle fit to the ball's silhouette with the reflections clipped.

    ``radius_px``: the ball's expected image radius [px] (sets the inner disk whose median
    gives the body level). Returns centre a, b [px], radius [px], reason codes.
    """
    K, w, _ = G.shape
    H, noise = _plane_corrected(G, geo)
    c = (w - 1) / 2.0
    yy, xx = np.mgrid[0:w, 0:w]
    inner = np.hypot(xx - c, yy - c) <= 0.6 * radius_px
    body = np.median(H.reshape(K, -1)[:, inner.ravel()], axis=1).astype(np.float32)
    Hc = np.minimum(H, body[:, None, None])                  # reflections -> body level
    if opts.smooth:
        Hc = W.smooth3(Hc)
        off = 1
    else:
        off = 0
    # the limb is darker than the top (shading) and the PSF spreads the edge: the silhouette
    # is where the profile falls to a third of the body level
    level = (LEVEL * body).astype(np.float32)
    kk, xs, ys, above = W.crossings(Hc, level)
    a, b, r, rms, cnt = W.robust_circle(kk, xs, ys, K)
    if EDGE_REFINE and edges:
        a, b, r, rms, cnt = _gradient_edge(Hc, a, b, r)
    a += off
    b += off
    reason = np.zeros(K, dtype=np.uint8)
    bad = ~np.isfinite(a) | (cnt < opts.min_points) | (rms > opts.max_residual)
    bad |= np.abs(r - radius_px) > max(1.0, 0.3 * radius_px)
    reason[bad] = T.FIT_FAILED
    touches = (above[:, 0, :].any(1) | above[:, -1, :].any(1) | above[:, :, 0].any(1)
               | above[:, :, -1].any(1))
    reason[touches] = T.TOUCHES_EDGE
    reason[(body < opts.min_contrast) | (body < opts.min_snr * noise)] = T.LOW_CONTRAST
    return a, b, r, reason


def _gradient_edge(H: np.ndarray, a: np.ndarray, b: np.ndarray, r: np.ndarray, n_rays: int = 36,
                   span: float = 2.0, step: float = 0.5
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Refit the silhouette on radial profiles (per-ray half-way level, or steepest point).

    A fixed level lands inside the edge where the body is dimmer (a lamp shaded by the wall
    darkens one side). Rays from the first circle's centre (a, b), radii r - span .. r + span
    [px], bilinear samples of H; each ray is crossed half-way between its own inside and
    outside levels (``EDGE_MODE = "local"``, used: as little jitter as a fixed level, less bias)
    or at the parabolic peak of -dI/drho (``"gradient"``: height-independent too, but 3x the
    jitter). Returns a, b, r, rms, count as _robust_circle.
    """
    K, h, w = H.shape
    ang = np.arange(n_rays) * (2 * np.pi / n_rays)
    rho = np.arange(-span, span + step / 2, step)                       # (P,)
    ca, sa = np.cos(ang), np.sin(ang)
    good = np.isfinite(a) & np.isfinite(r)
    a0, b0, r0 = np.where(good, a, (w - 1) / 2), np.where(good, b, (h - 1) / 2), \
        np.where(good, r, 1.0)
    rr = r0[:, None, None] + rho[None, None, :]                          # (K, 1, P)
    X = a0[:, None, None] + ca[None, :, None] * rr                       # (K, R, P)
    Y = b0[:, None, None] + sa[None, :, None] * rr
    X = np.clip(X, 0, w - 1.001)
    Y = np.clip(Y, 0, h - 1.001)
    ix, iy = np.floor(X).astype(np.int64), np.floor(Y).astype(np.int64)
    fx, fy = X - ix, Y - iy
    kk = np.arange(K)[:, None, None]
    v = ((1 - fy) * ((1 - fx) * H[kk, iy, ix] + fx * H[kk, iy, ix + 1])
         + fy * ((1 - fx) * H[kk, iy + 1, ix] + fx * H[kk, iy + 1, ix + 1]))
    if EDGE_MODE == "gradient":
        # -dI/drho over 1 px (4 steps): a shorter difference made the peak twice as noisy
        g = (v[:, :, :-4] + v[:, :, 1:-3]) - (v[:, :, 3:-1] + v[:, :, 4:])
        j = np.clip(g.argmax(axis=2), 1, g.shape[2] - 2)
        gm, g0, gp = (np.take_along_axis(g, (j + d)[:, :, None], 2)[:, :, 0]
                      for d in (-1, 0, 1))
        den = gm - 2 * g0 + gp
        frac = np.where(den < 0, 0.5 * (gm - gp) / np.where(den < 0, den, -1.0), 0.0)
        edge = r0[:, None] + rho[2:-2][j] + np.clip(frac, -1, 1) * step  # (K, R) radius [px]
    else:
        # half-way between this ray's own inside (limb) and outside levels
        lev = 0.5 * (v[:, :, :3].mean(axis=2) + v[:, :, -3:].mean(axis=2))
        below = v < lev[:, :, None]
        j = np.clip(np.argmax(below, axis=2), 1, v.shape[2] - 1)       # first sample below
        v1 = np.take_along_axis(v, j[:, :, None], 2)[:, :, 0]
        v0 = np.take_along_axis(v, (j - 1)[:, :, None], 2)[:, :, 0]
        frac = np.clip((v0 - lev) / np.where(v0 - v1 > 0, v0 - v1, 1.0), 0.0, 1.0)
        edge = r0[:, None] + rho[j - 1] + frac * step
    xs = (a0[:, None] + ca * edge).ravel()
    ys = (b0[:, None] + sa * edge).ravel()
    kidx = np.repeat(np.arange(K), n_rays)
    out = W.robust_circle(kidx, xs, ys, K)
    for arr in out[:3]:
        arr[~good] = np.nan
    return out


def _refine(G: np.ndarray, geo, opts: "T.TrackingOptions", ball_method: str,
            radius_px: float, final: bool) -> tuple[np.ndarray, ...]:
    if ball_method == "pair":
        return refine_pair(G, geo, opts)
    if ball_method == "silhouette":
        return refine_silhouette(G, geo, opts, radius_px)
    # the radial-profile refit only in the final pass (the first one re-centres)
    return refine_outline(G, geo, opts, radius_px, edges=final)


def _one_pass(frames: np.ndarray, cx: np.ndarray, cy: np.ndarray, reason0: np.ndarray,
              geo, ws: int, opts: "T.TrackingOptions", ball_method: str, radius_px: float,
              final: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One pass over the frames with windows of side ``ws`` centred on (cx, cy) [px]."""
    n, hgt, wid = frames.shape
    half = ws // 2
    X, Y, R = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    reason = reason0.copy()
    for start in range(0, n, T.BATCH_FRAMES):
        stop = min(n, start + T.BATCH_FRAMES)
        x0 = np.rint(cx[start:stop]).astype(np.int64) - half
        y0 = np.rint(cy[start:stop]).astype(np.int64) - half
        inside = (x0 >= 0) & (y0 >= 0) & (x0 + ws <= wid) & (y0 + ws <= hgt)
        x0c, y0c = np.clip(x0, 0, wid - ws), np.clip(y0, 0, hgt - ws)
        G = W.gather(np.asarray(frames[start:stop]), np.arange(stop - start), x0c, y0c,
                     ws).astype(np.float32)
        a, b, r, code = _refine(G, geo, opts, ball_method, radius_px, final)
        code[~inside] = T.OUTSIDE
        code = np.where(code != T.OK, code, reason0[start:stop])
        X[start:stop], Y[start:stop], R[start:stop] = x0c + a, y0c + b, r
        reason[start:stop] = code
    return X, Y, R, reason


#: Frames per step of :func:`_follow_silhouette` (the ball moves < 1 px per frame).
FOLLOW_FRAMES = 4


def _follow_silhouette(frames: np.ndarray, seed: np.ndarray, geo, ws: int,
                       opts: "T.TrackingOptions", radius_px: float,
                       guide: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """(N, 1) x, y [px]: the silhouette followed from the seed, a few frames at a time, each
    step's windows centred on the predicted position (kept where a frame is lost).

    ``guide`` (N, 2, 2): the ABU centre's and the CD marker's tracks [px] (NaN where lost).
    The ball rides on the CD, so it is predicted frame by frame as c + k (cd - c), with k the
    complex ratio (ball - c) / (cd - c) of the last good fit: k changes only as the ball slips
    (slowly, against the CD's turning), so a faint ball is looked for where it must be, not
    where noise fitted last. Without a guide (or where c or cd are lost): the last good
    position, extrapolated linearly."""
    n = frames.shape[0]
    xs, ys = np.empty((n, 1)), np.empty((n, 1))
    px, py, k_last = float(seed[0]), float(seed[1]), 0
    vx = vy = 0.0                                  # [px/frame] from the last two good steps
    zc = zd = None
    k_ratio = None
    if guide is not None:
        zc = guide[:, 0, 0] + 1j * guide[:, 0, 1]
        zd = guide[:, 1, 0] + 1j * guide[:, 1, 1]
        if np.isfinite(zc[0]) and np.isfinite(zd[0]) and abs(zd[0] - zc[0]) > 0:
            k_ratio = (px + 1j * py - zc[0]) / (zd[0] - zc[0])
    for start in range(0, n, FOLLOW_FRAMES):
        stop = min(n, start + FOLLOW_FRAMES)
        m = stop - start
        ahead = start + 0.5 * m - k_last             # frames from the last good one
        qx, qy = np.full(m, px + vx * ahead), np.full(m, py + vy * ahead)
        if k_ratio is not None:
            zq = zc[start:stop] + k_ratio * (zd[start:stop] - zc[start:stop])
            known = np.isfinite(zq)
            qx, qy = np.where(known, zq.real, qx), np.where(known, zq.imag, qy)
        X, Y, _, reason = _one_pass(frames[start:stop], qx, qy, np.zeros(m, np.uint8), geo, ws,
                                    opts, "silhouette", radius_px, False)
        ok = reason == T.OK
        if k_ratio is not None:   # a fit far from where the ball must be is noise
            ok &= np.hypot(X - qx, Y - qy) <= max(1.0, 0.5 * radius_px)
        xs[start:stop, 0] = np.where(ok, X, qx)
        ys[start:stop, 0] = np.where(ok, Y, qy)
        if ok.any():
            j = int(np.flatnonzero(ok)[-1])
            k = start + j
            if k > k_last:
                vx = (float(X[j]) - px) / (k - k_last) if start else 0.0
                vy = (float(Y[j]) - py) / (k - k_last) if start else 0.0
            px, py, k_last = float(X[j]), float(Y[j]), k
            if zc is not None and np.isfinite(zc[k]) and np.isfinite(zd[k]) \
                    and abs(zd[k] - zc[k]) > 0:
                k_ratio = (px + 1j * py - zc[k]) / (zd[k] - zc[k])
    return xs, ys


#: Frames on which the ``outline`` fit is tried before the tracker falls back to the
#: ``silhouette`` (if the outline fails in more than half of them).
PROBE_FRAMES = 64


#: Lost share above which ``outline`` is redone with ``silhouette`` (the analysis interpolates
#: at most 2 % of the frames), and ``silhouette`` against the template.
MAX_LOST_SHARE = 0.02


def _passes(frames: np.ndarray, xs: np.ndarray, ys: np.ndarray, reason0: np.ndarray,
            opts: "T.TrackingOptions", ball_method: str, radius_px: float
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Two passes: the seeded centroid (reflections only) can sit 2-3 px off the centre; the
    second pass re-centres the window on the first estimate."""
    ws = _ball_window(radius_px)
    geo = W.WindowGeometry.make(ws)
    cx, cy = xs, ys
    for final in (False, True):
        X, Y, R, reason = _one_pass(frames, cx, cy, reason0, geo, ws, opts, ball_method,
                                    radius_px, final)
        ok = reason == T.OK
        cx = np.where(ok, X, xs)
        cy = np.where(ok, Y, ys)
    return X, Y, R, reason


def _silhouette_track(frames: np.ndarray, seed: np.ndarray, opts: "T.TrackingOptions",
                      guide: np.ndarray | None = None
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """The ``silhouette`` track, followed from the seed (the seeded centroid follows the
    bright pixels, which on a dark ball with faint reflections are noise), guided by the
    centre and CD tracks where given (:func:`_follow_silhouette`); where it loses more than
    :data:`MAX_LOST_SHARE` of the frames, the ball against its own template
    (:func:`ball_template.template_track`, method ``template``) if that loses fewer."""
    radius_px = _estimate_radius(frames[0], seed, method="silhouette")
    ws = _ball_window(radius_px)
    xs, ys = _follow_silhouette(frames, seed, W.WindowGeometry.make(ws), ws, opts, radius_px,
                                guide)
    out = _passes(frames, xs[:, 0], ys[:, 0], np.zeros(frames.shape[0], np.uint8), opts,
                  "silhouette", radius_px)
    lost = np.mean(out[3] != T.OK)
    if lost > MAX_LOST_SHARE and guide is not None:   # a faint ball: against its template
        alt = template_track(frames, seed, guide, radius_px, opts)
        if np.mean(alt[3] != T.OK) < lost:
            return (*alt, "template")
    return (*out, "silhouette")


def track_ball(frames: np.ndarray, seed: np.ndarray, *, ball_method: str = DEFAULT_BALL_METHOD,
               radius_px: float | None = None, window: int = T.DEFAULT_WINDOW,
               options: "T.TrackingOptions | None" = None, guide: np.ndarray | None = None
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """Ball centre per frame under two reflections: x, y [px], radius/separation, reason and
    the method used. ``outline`` falls back to ``silhouette`` for the whole recording when it
    fails on most of the first :data:`PROBE_FRAMES` frames (a dark ball, large highlights) or
    loses more than :data:`MAX_LOST_SHARE` of all frames and the silhouette loses fewer.
    ``guide``: the centre and CD tracks (N, 2, 2) [px] that guide the silhouette's windows."""
    if ball_method not in BALL_METHODS:
        raise ParameterError("--ball-method", ball_method, f"one of {', '.join(BALL_METHODS)}")
    opts = options or T.TrackingOptions()
    seed = np.asarray(seed, dtype=float).reshape(1, 2)
    frames, seed, window = T._check_inputs(frames, seed, window, "moments")
    if ball_method == "silhouette":
        return _silhouette_track(frames, seed[0], opts, guide)
    xs, ys, reason0 = T._seeded_moments(frames, seed, window, False, opts)
    if radius_px is None:
        radius_px = _estimate_radius(frames[0], seed[0])
    if ball_method == "outline":
        m = min(frames.shape[0], PROBE_FRAMES)
        ws = _ball_window(radius_px)
        probe = _one_pass(frames[:m], xs[:m, 0], ys[:m, 0], reason0[:m, 0],
                          W.WindowGeometry.make(ws), ws, opts, "outline", radius_px, False)[3]
        if np.mean(probe != T.OK) > 0.5:
            return _silhouette_track(frames, seed[0], opts, guide)
    out = _passes(frames, xs[:, 0], ys[:, 0], reason0[:, 0], opts, ball_method, radius_px)
    lost = np.mean(out[3] != T.OK)
    if ball_method == "outline" and lost > MAX_LOST_SHARE:
        alt = _silhouette_track(frames, seed[0], opts, guide)
        if np.mean(alt[3] != T.OK) < lost:
            return alt
    return (*out, ball_method)


def _estimate_radius(frame: np.ndarray, seed: np.ndarray, default: float = 5.0,
                     method: str = "outline") -> float:
    """The ball's image radius [px] from frame 0 (``method`` fit in a generous window): the
    family's (~4-6 px) first, then larger ones (a camera with ~2x its magnification: ~10 px;
    the ``default`` kept for those lost the ball in every frame)."""
    family = (default, 4.0, 6.0)
    for ws, guesses in ((24, family), (20, family), (16, family), (32, (8.0, 11.0)),
                        (44, (11.0, 14.0)), (56, (14.0, 18.0))):
        x0, y0 = int(round(seed[0])) - ws // 2, int(round(seed[1])) - ws // 2
        if x0 < 0 or y0 < 0 or x0 + ws > frame.shape[1] or y0 + ws > frame.shape[0]:
            continue
        G = frame[None, y0:y0 + ws, x0:x0 + ws].astype(np.float32)
        geo = W.WindowGeometry.make(ws)
        for guess in guesses:
            a, b, r, code = (refine_outline(G, geo, T.TrackingOptions(), guess)
                             if method == "outline" else
                             refine_silhouette(G, geo, T.TrackingOptions(), guess))
            if code[0] == T.OK:
                return float(r[0])
    return default


def track_with_reflections(frames: np.ndarray, seeds: np.ndarray, *,
                           ball_method: str = DEFAULT_BALL_METHOD, method: str = T.DEFAULT_METHOD,
                           window: int = T.DEFAULT_WINDOW, dark: bool = False,
                           radius_px: float | None = None,
                           options: "T.TrackingOptions | None" = None) -> "T.Tracks":
    """Track ABU centre and CD marker (``method``) and the ball under two reflections.

    Returns :class:`tracking.Tracks` with the three markers in the usual order; the ball's
    ``radius`` column holds the outline radius (``outline``) or the reflections' separation
    (``pair``) [px]; ``method`` reads e.g. ``isocontour+outline``. ``options`` None: the
    defaults with the edge step as
    :func:`measurement.imaging.edge_step_roles.edge_step_default` says (off).
    """
    if dark:
        raise ParameterError("--dark-markers", True, "bright markers with --ball-reflections 2")
    seeds = np.asarray(seeds, dtype=float)
    if seeds.shape != (3, 2):
        raise T.TrackingError(f"seeds: expected 3 positions (centre, CD, ball), got {seeds.shape}")
    opts = options or T.TrackingOptions(edge_step=any(edge_step_default(2)))
    tr = T.track_recording(frames, seeds[:2], method=method, window=window, options=opts)
    guide = np.stack([np.column_stack([tr.x[:, j], tr.y[:, j]]) for j in (0, 1)], axis=1)
    X, Y, R, reason, used = track_ball(frames, seeds[2], ball_method=ball_method,
                                       radius_px=radius_px, window=window, options=opts,
                                       guide=guide)
    Xa = np.column_stack([tr.x, X])
    Ya = np.column_stack([tr.y, Y])
    Ra = np.column_stack([tr.radius, R])
    reasons = np.column_stack([tr.reason, reason]).astype(np.uint8)
    T._post_checks(Xa, Ya, Ra, reasons, window, opts, check_radius=False)
    lost = reasons != T.OK
    nan = np.nan
    step = bool(opts.edge_step) and method == "isocontour"
    return T.Tracks(x=np.where(lost, nan, Xa), y=np.where(lost, nan, Ya), lost=lost,
                    reason=reasons, radius=np.where(lost, nan, Ra),
                    method=f"{method}+{used}", window=window, dark=False, options=opts,
                    edge_step_markers=(step, step, False))


def track_markers(frames: np.ndarray, seeds: np.ndarray, *, method: str = T.DEFAULT_METHOD,
                  window: int = T.DEFAULT_WINDOW, dark: bool = False, progress: bool = False,
                  ball_reflections: int = 1, ball_method: str = DEFAULT_BALL_METHOD,
                  edge_step: bool | None = None) -> "T.Tracks":
    """The command line's tracker: :func:`tracking.track_recording` for ``ball_reflections``
    = 1 (the default), :func:`track_with_reflections` for 2; ``edge_step`` as
    :class:`tracking.TrackingOptions`, None: per marker as
    :func:`measurement.imaging.edge_step_roles.edge_step_default` says."""
    if ball_reflections not in (1, 2):
        raise ParameterError("--ball-reflections", ball_reflections, "1 or 2")
    if edge_step is None:
        steps = edge_step_default(ball_reflections)
        if ball_reflections == 1 and len(seeds) == len(steps) and len(set(steps)) > 1:
            return track_by_step(frames, np.asarray(seeds, dtype=float), steps, method=method,
                                 window=window, dark=dark, progress=progress)
        edge_step = any(steps)
    opts = T.TrackingOptions(edge_step=bool(edge_step))
    if ball_reflections == 1:
        return T.track_recording(frames, seeds, method=method, window=window, dark=dark,
                                 progress=progress, options=opts)
    return track_with_reflections(frames, seeds, ball_method=ball_method, method=method,
                                  window=window, dark=dark, options=opts)
