"""One Gauss-Newton step of an edge model on the marker's disk (the last step of the
``isocontour`` method, :mod:`measurement.imaging.window_fits`: ``TrackingOptions(edge_step=True)``,
the default; the command line applies it to the centre and CD paper disks of one-reflection
recordings, :func:`measurement.imaging.edge_step_roles.edge_step_default`, and ``abu measure
--no-edge-step`` leaves it out).

The contour fit uses ~30-60 interpolated points on one level of a smoothed window; it leaves
0.010-0.012 px RMS at noise 3 on the rendered recordings, 1.3-1.4 x the Cramer-Rao bound of the
window's pixels (0.0073 / 0.0089 / 0.0071 px for the centre, CD and ball markers). A least-squares
fit of all the pixels near the edge comes closer: the window (plane-corrected, not smoothed) is
modelled as

    I(x, y) = o + C * Phi((r - |(x, y) - (a, b)|) / s)

(Phi the normal CDF: a disk whose edge is blurred over s px by the pixels' area and the motion
blur), and one Gauss-Newton step from the contour fit's (a, b, r), C the window's smoothed peak
and o = 0 moves (a, b). Only pixels within :data:`BAND_PX` of the circle enter; a step longer
than :data:`MAX_STEP_PX` (a blob that is not a disk) is refused and the contour centre kept.

Measured (docs/measurement-imaging.md): one step with s = 0.4 px takes the staircase recording
from 0.0109 / 0.0123 / 0.0102 to 0.0077 / 0.0100 / 0.0083 px; more steps were worse (the model
is not exact: 0.0091 / 0.0098 / 0.0085 with three), s = 0.35 or 0.5 px less good.

Phi and its derivative come from a table (linear interpolation, step 1/32 of s): the C kernel
uses the same table, so both paths agree to ~1e-12 px.
"""
from __future__ import annotations

import math

import numpy as np

BAND_PX = 2.5        # pixels farther than this from the fitted circle do not enter [px]
MAX_STEP_PX = 0.5    # a longer step is refused [px]
TABLE_HALF = 8.0     # the table spans u = -8 .. 8 (units of s)
TABLE_PER_UNIT = 32  # entries per unit of u


def profile_tables() -> tuple[np.ndarray, np.ndarray]:
    """Phi(u) and its derivative phi(u) at u = -8, -8 + 1/32, ..., 8 (513 values each)."""
    n = int(2 * TABLE_HALF * TABLE_PER_UNIT)
    u = np.arange(n + 1) / TABLE_PER_UNIT - TABLE_HALF
    phi = np.array([0.5 * (1.0 + math.erf(v / math.sqrt(2.0))) for v in u])
    dphi = np.exp(-0.5 * u * u) / math.sqrt(2.0 * math.pi)
    return phi, dphi


PHI, DPHI = profile_tables()


def _lookup(table: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Linear interpolation in ``table`` at u (clipped to the table), as the C kernel does."""
    q = (np.clip(u, -TABLE_HALF, TABLE_HALF) + TABLE_HALF) * TABLE_PER_UNIT
    i = np.minimum(np.floor(q).astype(np.int64), table.size - 2)
    t = q - i
    return table[i] + t * (table[i + 1] - table[i])


def edge_step(H: np.ndarray, a: np.ndarray, b: np.ndarray, r: np.ndarray, C: np.ndarray,
              width_px: float) -> tuple[np.ndarray, np.ndarray]:
    """The step on windows H (K, w, w) (plane-corrected, marker bright) from centres a, b,
    radii r [px, window coordinates] and contrasts C. Returns the new a, b (the old ones where
    the fit failed, is singular or the step exceeds :data:`MAX_STEP_PX`)."""
    K, w, _ = H.shape
    ok = np.isfinite(a) & np.isfinite(b) & np.isfinite(r)
    a0, b0, r0 = (np.where(ok, v, 0.0) for v in (a, b, r))
    jj = np.arange(w, dtype=np.float64)
    dx = jj[None, None, :] - a0[:, None, None]                      # (K, 1, w)
    dy = jj[None, :, None] - b0[:, None, None]                      # (K, w, 1)
    d = np.sqrt(dx * dx + dy * dy)                                  # (K, w, w)
    e = r0[:, None, None] - d
    k, i, j = np.nonzero((np.abs(e) < BAND_PX) & (d > 0.0))        # the band's pixels
    ds = d[k, i, j]
    u = e[k, i, j] / width_px
    f = _lookup(PHI, u)
    cfp = C[k] * (_lookup(DPHI, u) / width_px)
    res = H[k, i, j] - C[k] * f
    J = [cfp * (j - a0[k]) / ds, cfp * (i - b0[k]) / ds, cfp, f, np.ones_like(f)]
    A = np.empty((K, 5, 5))
    g = np.empty((K, 5))
    for p in range(5):
        g[:, p] = np.bincount(k, weights=J[p] * res, minlength=K)
        for q in range(p + 1):
            A[:, p, q] = A[:, q, p] = np.bincount(k, weights=J[p] * J[q], minlength=K)
    with np.errstate(invalid="ignore", over="ignore"):
        det = np.linalg.det(A)
    ok &= np.isfinite(det) & (det != 0.0)
    A[~ok] = np.eye(5)
    step = np.linalg.solve(A, g[:, :, None])[:, :, 0]
    ok &= np.isfinite(step[:, 0]) & np.isfinite(step[:, 1])
    ok &= np.hypot(step[:, 0], step[:, 1]) <= MAX_STEP_PX
    return np.where(ok, a + step[:, 0], a), np.where(ok, b + step[:, 1], b)
