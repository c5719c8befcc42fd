"""Scene radiance of the harsh camera twin: the lit ABU plane, paper markers, the shaded ball.

Per frame (grey levels before the lens and sensor of :mod:`twin.optics`):

    R(x) = s [ E(x) a_bg + sum_markers E(x) (a_m - a_bg) c_m(x) + (B_phi(x) - E(x) a_bg c_ball(x)) ]

E the plane irradiance of the lamps (:func:`lighting.plane_irradiance`; static, since the lamps
are fixed in the world), a_bg and a_m the albedos of the ABU surface and the paper markers,
c_m the fraction of pixel x covered by marker m's disk, B_phi the ball's radiance integrated
over the pixel (sprites of :func:`lighting.ball_sprites` for the ball's world angle phi,
nearest of ``n_phi`` angles), s the exposure scale.

Pixel integrals: each sprite (fine grid, ``oversample`` samples per px) is box-filtered once over
one pixel's area with a summed-area table, so a pixel's value for any sub-pixel centre is one
bilinear look-up (exact area to 1/oversample px, no per-frame supersampling). Motion blur
averages ``blur_samples`` sub-frame centres over ``exposure_fraction`` of the frame interval
(cubic spline between frame centres).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

OVERSAMPLE = 8


def _pixel_integrated(sprite: np.ndarray, q: int) -> np.ndarray:
    """Box filter of (..., N, N) over q x q samples: B[a, b] = mean of sprite[a:a+q, b:b+q]."""
    F = np.zeros(sprite.shape[:-2] + (sprite.shape[-2] + 1, sprite.shape[-1] + 1))
    F[..., 1:, 1:] = sprite.cumsum(-1).cumsum(-2)
    B = F[..., q:, q:] - F[..., :-q, q:] - F[..., q:, :-q] + F[..., :-q, :-q]
    return (B / (q * q)).astype(np.float32)


def disk_sprite(radius_px: float, q: int = OVERSAMPLE) -> tuple[np.ndarray, int]:
    """Pixel-integrated coverage of a disk: (B, half) (see :func:`lookup`)."""
    half = int(math.ceil(radius_px)) + 4
    n = 2 * half * q
    s = (np.arange(n) + 0.5) / q - half
    xx, yy = np.meshgrid(s, s)
    # each sample antialiased by a linear ramp over its width: nearly exact area
    cov = np.clip((radius_px - np.hypot(xx, yy)) * q + 0.5, 0.0, 1.0)
    return _pixel_integrated(cov, q), half


@dataclass
class Sprite:
    """A pixel-integrated sprite B (K, M, M) (K = 1 or n_phi) and its half size [px]."""

    B: np.ndarray
    half: int
    q: int = OVERSAMPLE

    def patch(self, pos: np.ndarray, kidx: np.ndarray | None, width: int, height: int
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Values of the sprite on a pixel patch around each of n frames' S sub-positions.

        pos: (n, S, 2) centres [px]; kidx: (n,) sprite index (None: 0). Returns
        (values (n, P, P) averaged over S, x0 (n,), y0 (n,)) with the patch's top-left pixel.
        """
        n, S, _ = pos.shape
        q, half = self.q, self.half
        P = 2 * half - 2
        mean = pos.mean(axis=1)
        x0 = np.floor(mean[:, 0]).astype(np.int64) - half + 2
        y0 = np.floor(mean[:, 1]).astype(np.int64) - half + 2
        M = self.B.shape[-1]
        k = np.zeros(n, dtype=np.int64) if kidx is None else kidx
        ar = np.arange(P)
        acc = np.zeros((n, P, P), dtype=np.float32)
        for s in range(S):
            ax = ((x0[:, None] + ar) - pos[:, s, 0:1] + half - 0.5) * q     # (n, P)
            ay = ((y0[:, None] + ar) - pos[:, s, 1:2] + half - 0.5) * q
            ix = np.floor(ax).astype(np.int64)
            iy = np.floor(ay).astype(np.int64)
            fx = (ax - ix).astype(np.float32)
            fy = (ay - iy).astype(np.float32)
            okx = (ix >= 0) & (ix + 1 < M)
            oky = (iy >= 0) & (iy + 1 < M)
            ix = np.clip(ix, 0, M - 2)
            iy = np.clip(iy, 0, M - 2)
            kk = k[:, None, None]
            r0, r1 = iy[:, :, None], iy[:, :, None] + 1
            c0, c1 = ix[:, None, :], ix[:, None, :] + 1
            wx, wy = fx[:, None, :], fy[:, :, None]
            v = ((1 - wy) * ((1 - wx) * self.B[kk, r0, c0] + wx * self.B[kk, r0, c1])
                 + wy * ((1 - wx) * self.B[kk, r1, c0] + wx * self.B[kk, r1, c1]))
            v *= (oky[:, :, None] & okx[:, None, :])
            acc += v
        acc *= np.float32(1.0 / S)
        return acc, x0, y0


def subframe_positions(xy: np.ndarray, exposure_fraction: float, samples: int) -> np.ndarray:
    """(N, S, 2) centres at S sub-frame times over the exposure around each frame [px]."""
    n = xy.shape[0]
    if exposure_fraction <= 0.0 or samples == 1 or n < 2:
        return xy[:, None, :]
    from scipy.interpolate import CubicSpline

    offsets = ((np.arange(samples) + 0.5) / samples - 0.5) * exposure_fraction
    t = np.arange(n, dtype=float)
    spline = CubicSpline(t, xy, axis=0)
    return spline((t[:, None] + offsets[None, :]).ravel()).reshape(n, samples, 2)


def add_patch(img: np.ndarray, vals: np.ndarray, x0: np.ndarray, y0: np.ndarray,
              weight: np.ndarray | None = None) -> None:
    """img[i, y0:y0+P, x0:x0+P] += vals[i] (* weight[same window]) for every frame, clipped."""
    n, hgt, wid = img.shape
    P = vals.shape[-1]
    for i in range(n):
        ya, xa = max(0, y0[i]), max(0, x0[i])
        yb, xb = min(hgt, y0[i] + P), min(wid, x0[i] + P)
        if ya >= yb or xa >= xb:
            continue
        v = vals[i, ya - y0[i]:yb - y0[i], xa - x0[i]:xb - x0[i]]
        if weight is not None:
            v = v * weight[ya:yb, xa:xb]
        img[i, ya:yb, xa:xb] += v
