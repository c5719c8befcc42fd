"""The ball's silhouette under any highlights (the fallback of the two-reflection tracker,
:mod:`measurement.imaging.reflections`).

The ``outline`` fit of :mod:`reflections` clips the reflections to the ball's body level and
needs a body brighter than the plane. Under other lamps the ball can be darker than the plane
(diffuse light: polished brass mirrors dark surroundings) or its highlights can cover most of
the body (large, elongated spots); :func:`refine_silhouette` reads those too, by the outermost
point of each ray where the ball differs from the plane (dark or bright).
"""
from __future__ import annotations

import numpy as np

from measurement.imaging import window_fits as W
from measurement.imaging.window_fits import FIT_FAILED, LOW_CONTRAST


#: The ball's ring (|window - plane| over 0.5-0.85 of its radius, median of the rays) must
#: reach this many times the border's noise sigma. 2 (was 3): a dark ball under diffuse light
#: can stand only 2-3 sigma above a noisy plane (twin.lighting_alt, seeds 10042-10070: ring
#: 2.5 sigma, the circle fitted to 0.1 px of the true radius); the circle fit's own checks
#: (points, residual, radius) and, while following, the CD-guided prediction reject what the
#: noise alone draws.
RING_SNR = 2.0
#: The circle fit's residual may reach this many times the markers' limit (0.6 px). 3 (was 2):
#: faint, shaded balls of twin.lighting_alt fit their silhouette with 1.2-1.7 px residual at the
#: right radius (seeds 10055, 10077: every such frame within 0.4 px of the frame-0 radius;
#: the frames accepted before, 0.13-0.23 px RMS about the true centre's offset).
RESIDUAL_FACTOR = 3.0


def _plane_corrected(G: np.ndarray, geo: "W.WindowGeometry") -> tuple[np.ndarray, np.ndarray]:
    """The window minus the plane fitted to its border, and the border's noise [grey levels]."""
    K, w, _ = G.shape
    flat = G.reshape(K, w * w)
    ring = flat[:, geo.ring]
    coef = np.einsum("kp,cp->kc", ring, geo.plane_pinv)
    noise = (ring - np.einsum("kc,cp->kp", coef, geo.plane_basis[:, geo.ring])).std(axis=1)
    return (flat - np.einsum("kc,cp->kp", coef, geo.plane_basis)).reshape(K, w, w), noise


def refine_silhouette(G: np.ndarray, geo, opts: "W.TrackingOptions", radius_px: float
                      ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The ball's silhouette whatever its highlights: circle fit to the outermost point of each
    of 36 rays where the ball differs from the plane by half its typical contrast.

    For balls the ``outline`` fit cannot read (a body darker than the plane under diffuse
    light, large or elongated highlights covering the body): |plane-corrected window|,
    smoothed, is large anywhere on the ball (dark body, bright body, reflections) and at the
    noise outside it; the highlights' edges inside the ball (where the contrast changes sign)
    are passed over because only the outermost crossing of each ray counts. Two rounds, the
    second from the first's centre. Returns a, b, r, reason as :func:`refine_outline`.
    """
    K, w, _ = G.shape
    H, noise = _plane_corrected(G, geo)
    A = np.abs(W.smooth3(H))                                 # pixel (i, j) at (i + 1, j + 1)
    n_rays, step = 36, 0.5
    ang = np.arange(n_rays) * (2 * np.pi / n_rays)
    rho = np.arange(0.0, min(radius_px * 1.6 + 2.0, w / 2.0 - 1.5), step)
    ca, sa = np.cos(ang), np.sin(ang)
    a = np.full(K, (w - 3) / 2.0)
    b = np.full(K, (w - 3) / 2.0)
    r = np.full(K, np.nan)
    rms = np.full(K, np.inf)
    cnt = np.zeros(K)
    ring_level = np.zeros(K)
    for _round in range(2):
        X = np.clip(a[:, None, None] + ca[None, :, None] * rho, 0, w - 3.001)
        Y = np.clip(b[:, None, None] + sa[None, :, None] * rho, 0, w - 3.001)
        ix, iy = np.floor(X).astype(np.int64), np.floor(Y).astype(np.int64)
        fx, fy = X - ix, Y - iy
        kk = np.arange(K)[:, None, None]
        v = ((1 - fy) * ((1 - fx) * A[kk, iy, ix] + fx * A[kk, iy, ix + 1])
             + fy * ((1 - fx) * A[kk, iy + 1, ix] + fx * A[kk, iy + 1, ix + 1]))
        ring = (rho >= 0.5 * radius_px) & (rho <= 0.85 * radius_px)
        # low: a dark body's contrast can be a fraction of the reflections' (the ring's
        # median), and the silhouette is where the ball meets the plane's noise
        ring_level = np.median(v[:, :, ring].reshape(K, -1), axis=1)
        level = np.maximum(0.25 * ring_level, 1.6 * noise)
        above = v >= level[:, None, None]
        # the outermost sample above the level, and the crossing just outside it
        last = v.shape[2] - 1 - np.argmax(above[:, :, ::-1], axis=2)
        has = above.any(axis=2) & (last < v.shape[2] - 1)
        j = np.clip(last, 0, v.shape[2] - 2)
        v0 = np.take_along_axis(v, j[:, :, None], 2)[:, :, 0]
        v1 = np.take_along_axis(v, (j + 1)[:, :, None], 2)[:, :, 0]
        frac = np.clip((v0 - level[:, None]) / np.where(v0 - v1 > 0, v0 - v1, 1.0), 0.0, 1.0)
        edge = rho[j] + frac * step
        xs = (a[:, None] + ca * edge)[has]
        ys = (b[:, None] + sa * edge)[has]
        kidx = np.repeat(np.arange(K), n_rays).reshape(K, n_rays)[has]
        a1, b1, r, rms, cnt = W.robust_circle(kidx, xs, ys, K)
        ok = np.isfinite(a1) & np.isfinite(b1)
        a, b = np.where(ok, a1, a), np.where(ok, b1, b)
    reason = np.zeros(K, dtype=np.uint8)
    # a shaded body or a highlight on the rim leaves the silhouette less round than a
    # marker's edge, and a faint one's crossings are noisy: RESIDUAL_FACTOR x the residual
    bad = ~np.isfinite(r) | (cnt < opts.min_points) | (rms > RESIDUAL_FACTOR * opts.max_residual)
    bad |= np.abs(r - radius_px) > max(1.0, 0.3 * radius_px)
    reason[bad] = FIT_FAILED
    # the ball (reflections included) against the tracker's contrast floor, and its ring
    # against the border's noise: RING_SNR x its sigma (6 sigma of the 3x3-smoothed noise
    # the rays read; the level sits at >= 4.8 sigma of it)
    reason[(A.reshape(K, -1).max(axis=1) < opts.min_contrast) | (ring_level < RING_SNR * noise)] = \
        LOW_CONTRAST
    return a + 1.0, b + 1.0, r, reason
