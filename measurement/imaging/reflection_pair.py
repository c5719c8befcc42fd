"""The report's way with two reflections (``--ball-method pair``): the ball as the mean of its
two reflections' centroids (see :mod:`measurement.imaging.reflections` for why that mean is
not the ball's centre)."""
from __future__ import annotations

import numpy as np

from measurement.imaging import tracking as T
from measurement.imaging.silhouette import _plane_corrected

#: Reason code for a ball window without two separate reflections.
NO_PAIR = T.FIT_FAILED


def refine_pair(G: np.ndarray, geo, opts: "T.TrackingOptions"
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Report's way on windows G (K, w, w): mean of the two reflections' centroids.

    Returns centre a, b (window coordinates) [px], separation of the reflections [px] (in
    place of a radius) and reason codes.
    """
    K, w, _ = G.shape
    H, noise = _plane_corrected(G, geo)
    flat = H.reshape(K, w * w)
    hi = flat.max(axis=1)
    thr = 0.6 * hi
    W = np.maximum(H - thr[:, None, None], 0.0).reshape(K, w * w)
    yy, xx = np.divmod(np.arange(w * w), w)
    m0 = W.sum(axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cx = (W @ xx) / m0
        cy = (W @ yy) / m0
        dx = xx[None, :] - cx[:, None]
        dy = yy[None, :] - cy[:, None]
        sxx = (W * dx * dx).sum(1) / m0
        syy = (W * dy * dy).sum(1) / m0
        sxy = (W * dx * dy).sum(1) / m0
        ang = 0.5 * np.arctan2(2 * sxy, sxx - syy)            # principal axis
        proj = dx * np.cos(ang)[:, None] + dy * np.sin(ang)[:, None]
        out = []
        for side in (proj < 0, proj >= 0):
            Ws = W * side
            ms = Ws.sum(1)
            out.append(((Ws @ xx) / ms, (Ws @ yy) / ms, ms))
    (x1, y1, m1), (x2, y2, m2) = out
    a, b = 0.5 * (x1 + x2), 0.5 * (y1 + y2)
    sep = np.hypot(x2 - x1, y2 - y1)
    # each group must be a compact spot: its weighted spread well below the separation
    reason = np.zeros(K, dtype=np.uint8)
    bad = ~np.isfinite(a) | (m1 <= 0) | (m2 <= 0) | (sep < 1.5) | (sep > w / 2.0)
    bad |= np.sqrt(np.abs(sxx + syy)) < 0.35 * sep            # one blob, not two
    reason[bad] = NO_PAIR
    reason[(hi < opts.min_contrast) | (hi < opts.min_snr * noise)] = T.LOW_CONTRAST
    return a, b, sep, reason
