"""Lens and sensor of the harsh camera twin: distortion, blur, vignetting, flicker, noise.

Order of the image chain (:func:`sensor_frames`), per frame, in grey levels:

1. the scene radiance (scene.py) is blurred by the lens PSF (Gaussian, ``psf_sigma`` px);
2. multiplied by the vignetting V(r) = 1 / (1 + v (r / r_c)^2)^2 (cos^4 law of a thin lens,
   r from the optical centre, r_c the half diagonal) and by the lamps' 100 Hz flicker
   1 + a cos(2 pi 100 t + p) (TL tubes on 50 Hz mains flicker at twice the mains frequency);
3. multiplied by a fixed per-column gain 1 + g_c and offset by a fixed per-column level o_c
   (column fixed-pattern noise of a CMOS read-out);
4. shot noise (variance S / conversion gain, grey levels^2 per grey level) and read noise
   (``read_noise`` grey levels) added as one Gaussian of standard deviation
   sqrt(read^2 + S / gain);
5. saturation at the full well (255) and 8-bit quantisation (round, clip 0..255).

Radial lens distortion (:func:`distort`) maps ideal pixel positions to distorted ones,
x_d = c + (x - c) (1 + k1 r_n^2 + k2 r_n^4), r_n = |x - c| / r_c; the twin applies it to the
markers' centres (at 0.3 mm/px a marker spans 10-15 px, over which the change of the distortion
is below 0.01 px, so the shapes are left undistorted).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np


@dataclass(frozen=True)
class OpticsSpec:
    """Lens and sensor settings (see the module doc).

    Attributes:
        k1, k2: radial distortion coefficients [-] (per half diagonal squared / to the fourth).
        optical_centre: (x, y) of the distortion and vignetting centre [px].
        psf_sigma: Gaussian lens blur [px].
        vignetting: v of the cos^4 falloff [-] (0 = none).
        conversion_gain: grey levels per electron^-1: shot-noise variance = S / gain [-].
        read_noise: Gaussian read noise [grey levels].
        column_offset_sigma, column_gain_sigma: column fixed-pattern noise [grey levels], [-].
        exposure_fraction: exposure / frame interval (motion blur) [-].
    """

    k1: float = 0.0
    k2: float = 0.0
    optical_centre: tuple[float, float] = (127.5, 127.5)
    psf_sigma: float = 0.6
    vignetting: float = 0.0
    conversion_gain: float = 8.0
    read_noise: float = 2.0
    column_offset_sigma: float = 1.0
    column_gain_sigma: float = 0.01
    exposure_fraction: float = 0.25

    def to_dict(self) -> dict:
        d = asdict(self)
        return {"k1": d["k1"], "k2": d["k2"], "optical_centre_px": list(d["optical_centre"]),
                "psf_sigma_px": d["psf_sigma"], "vignetting": d["vignetting"],
                "conversion_gain_grey_per_e": d["conversion_gain"],
                "read_noise_grey": d["read_noise"],
                "column_offset_sigma_grey": d["column_offset_sigma"],
                "column_gain_sigma": d["column_gain_sigma"],
                "exposure_fraction": d["exposure_fraction"]}


def half_diagonal(width: int, height: int) -> float:
    """Normalising radius r_c of the distortion and vignetting [px]."""
    return 0.5 * math.hypot(width, height)


def distort(xy: np.ndarray, spec: OpticsSpec, width: int, height: int) -> np.ndarray:
    """Distorted pixel positions of ideal positions xy (..., 2) [px]."""
    xy = np.asarray(xy, dtype=float)
    c = np.asarray(spec.optical_centre, dtype=float)
    d = xy - c
    r2 = (d * d).sum(axis=-1, keepdims=True) / half_diagonal(width, height) ** 2
    return c + d * (1.0 + spec.k1 * r2 + spec.k2 * r2 * r2)


def vignetting_map(spec: OpticsSpec, width: int, height: int) -> np.ndarray:
    """(H, W) float32 relative illumination V(r) of the lens."""
    yy, xx = np.mgrid[0:height, 0:width].astype(float)
    cx, cy = spec.optical_centre
    r2 = ((xx - cx) ** 2 + (yy - cy) ** 2) / half_diagonal(width, height) ** 2
    return (1.0 / (1.0 + spec.vignetting * r2) ** 2).astype(np.float32)


class Sensor:
    """Applies steps 1-5 of the module doc to chunks of radiance frames."""

    def __init__(self, spec: OpticsSpec, width: int, height: int, flicker: float,
                 flicker_phase: float, rng: np.random.Generator, bank_frames: int = 24):
        self.spec, self.flicker, self.flicker_phase = spec, flicker, flicker_phase
        self.vig = vignetting_map(spec, width, height)
        self.col_gain = (1.0 + spec.column_gain_sigma * rng.standard_normal(width)
                         ).astype(np.float32)
        self.col_off = (spec.column_offset_sigma * rng.standard_normal(width)).astype(np.float32)
        self.gain_map = self.vig * self.col_gain[None, :]
        # a bank of standard normals read at random offsets: drawing 10^8 fresh normals costs
        # ~1.5 s; a 24-frame bank shifted by random (dy, dx) per frame gives >10^6 distinct
        # noise fields at a fraction of the cost (measured 5x faster)
        self.pad = 32
        self.bank = rng.standard_normal((bank_frames, height + self.pad, width + self.pad),
                                        dtype=np.float32)
        self.rng = rng
        self.h, self.w = height, width

    def apply(self, radiance: np.ndarray, times: np.ndarray) -> np.ndarray:
        """(n, H, W) float32 radiance [grey levels before vignetting] -> (n, H, W) uint8."""
        import cv2

        s = self.spec
        n = radiance.shape[0]
        out = np.empty(radiance.shape, dtype=np.uint8)
        gains = 1.0 + self.flicker * np.cos(2 * math.pi * 100.0 * times + self.flicker_phase)
        picks = self.rng.integers(0, [self.bank.shape[0], self.pad, self.pad], size=(n, 3))
        rn2 = np.float32(s.read_noise ** 2)
        inv_g = np.float32(1.0 / s.conversion_gain)
        for i in range(n):
            img = radiance[i]
            if s.psf_sigma > 0:
                img = cv2.GaussianBlur(img, (0, 0), s.psf_sigma, borderType=cv2.BORDER_REFLECT)
            sig = img * (self.gain_map * np.float32(gains[i]))
            sig += self.col_off
            np.maximum(sig, 0.0, out=sig)
            b, dy, dx = picks[i]
            noise = np.sqrt(sig * inv_g + rn2)
            noise *= self.bank[b, dy:dy + self.h, dx:dx + self.w]
            sig += noise
            sig += np.float32(0.5)                         # truncation below rounds
            np.clip(sig, 0.0, 255.0, out=sig)              # saturation (full well) and 8 bits
            out[i] = sig
        return out
