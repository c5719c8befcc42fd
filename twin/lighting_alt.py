"""A second, independent model of the lamps and the ball's highlights (two reflections).

:mod:`twin.lighting` shades the ball with Blinn-Phong point lamps: round highlights of equal
size, a bright body. The two-reflection tracker was written against those frames; this module
draws recordings it was not tuned on, written apart from that model (own geometry, own spot
shapes), so that the tracker's coverage can be measured on highlights of another shape:

* **highlights** are elliptic Gaussian spots painted on the ball's image disk (not a BRDF):
  each sits at the image point whose normal bisects its lamp's and the camera's direction,
  taken at the ball's centre; elongated 1.2-3x along a random axis per lamp (an extended,
  rod-shaped lamp or a scratched, brushed brass surface), widths 0.06-0.22 of the ball's image
  radius, intensity ratio of the weaker to the stronger spot 0.25-1, the lamps' azimuths
  90-180 degrees apart at elevations of 20-60 degrees (spacing from close to far), peaks that
  saturate the sensor or not;
* **the body** is either ``dark`` (diffuse light from a white tent: polished brass mirrors the
  dark surroundings, so the ball is a dark disk 30-90 % below the plane with a soft, darker
  rim) or ``soft`` (a light body shaded smoothly by a broad source: 0-60 % brighter than the
  plane on one side, darker on the other);
* **the plane** is lit nearly evenly (a broad source) with a weak linear gradient.

:class:`AltLightingSpec` offers the interface of :class:`twin.lighting.LightingSpec` that
:mod:`twin.scenario` uses (``reflections``, ``flicker``, ``flicker_phase``, ``to_dict``), and
:func:`plane_irradiance` and :func:`ball_sprites` the same signatures as the first model's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

KIND = "two_spot_alt"


@dataclass(frozen=True)
class Spot:
    """One lamp's highlight: direction (azimuth, elevation) [rad], relative peak [1],
    width as a fraction of the ball's image radius [1], elongation [1] and its axis [rad]."""

    azimuth: float
    elevation: float
    peak: float
    width: float
    elongation: float
    axis: float
    distance: float = 0.2     #: lamp distance from the axis [m]


@dataclass(frozen=True)
class AltLightingSpec:
    """The second lighting model (module doc). Intensities are relative to the plane's
    irradiance at the axis (1)."""

    body: str                 #: ``dark`` or ``soft``
    body_level: float         #: body radiance relative to the plane [1]
    body_shade: float         #: amplitude of the body's shading across the disk [1]
    shade_angle: float        #: direction of the shading in the image [rad]
    rim_dark: float           #: extra darkening at the limb [1]
    spots: tuple[Spot, ...]
    spot_gain: float          #: peak of the strongest spot relative to the plane [1]
    gradient: tuple[float, float]   #: relative plane gradient per metre (X, Y) [1/m]
    camera_height: float      #: [m]
    flicker: float
    flicker_phase: float
    kind: str = KIND

    @property
    def reflections(self) -> int:
        return 2

    def to_dict(self) -> dict:
        return {"kind": self.kind, "model": "twin.lighting_alt", "body": self.body,
                "body_level": self.body_level, "body_shade": self.body_shade,
                "shade_angle_rad": self.shade_angle, "rim_dark": self.rim_dark,
                "spots": [{"azimuth_rad": s.azimuth, "elevation_rad": s.elevation,
                           "peak": s.peak, "width": s.width, "elongation": s.elongation,
                           "axis_rad": s.axis, "distance_m": s.distance} for s in self.spots],
                "spot_gain": self.spot_gain, "gradient_per_m": list(self.gradient),
                "camera_height_m": self.camera_height,
                "flicker_100hz_relative": self.flicker, "flicker_phase_rad": self.flicker_phase,
                "ball_reflections": 2}


def make_alt_lighting(rng: np.random.Generator) -> AltLightingSpec:
    """Draw a lighting of the second model."""
    u = rng.uniform
    body = "dark" if rng.random() < 0.5 else "soft"
    level = u(0.1, 0.7) if body == "dark" else u(1.0, 1.6)
    az0 = u(0, 2 * math.pi)
    sep = u(math.radians(90), math.radians(180))
    ratio = u(0.25, 1.0)
    spots = tuple(Spot(azimuth=az0 + k * sep, elevation=u(math.radians(20), math.radians(60)),
                       peak=1.0 if k == 0 else ratio, width=u(0.06, 0.22),
                       elongation=u(1.2, 3.0), axis=u(0, math.pi), distance=u(0.08, 0.3))
                  for k in range(2))
    return AltLightingSpec(body=body, body_level=level, body_shade=u(0.0, 0.6) * level,
                           shade_angle=u(0, 2 * math.pi), rim_dark=u(0.1, 0.5),
                           spots=spots, spot_gain=u(2.0, 6.0),
                           gradient=(u(-2.0, 2.0), u(-2.0, 2.0)), camera_height=u(0.15, 0.25),
                           flicker=u(0.0, 0.05), flicker_phase=u(0, 2 * math.pi))


def faded(spec: AltLightingSpec, factor: float) -> AltLightingSpec:
    """The same lamps and ball with the ball's contrast to the plane scaled by ``factor``
    (0-1]: body level, shading, limb and highlights drawn towards the plane's level. A faint
    ball (a body close to the plane's grey, weak highlights) stands only 1-2 noise sigma above
    the plane at its outline: the recordings the silhouette loses."""
    if not 0.0 < factor <= 1.0:
        raise ValueError(f"factor {factor!r}: expected 0 < factor <= 1")
    from dataclasses import replace
    return replace(spec, body_level=1.0 + (spec.body_level - 1.0) * factor,
                   body_shade=spec.body_shade * factor, rim_dark=spec.rim_dark * factor,
                   spot_gain=spec.spot_gain * factor)


def plane_irradiance(spec: AltLightingSpec, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Relative irradiance of the plane at world points X, Y [m]: 1 + a linear gradient."""
    gx, gy = spec.gradient
    return np.ones(np.broadcast(X, Y).shape) + gx * X + gy * Y


def _spot_position(spot: Spot, centre: np.ndarray, camera_height: float) -> tuple[float, float]:
    """Image offset (x right, y down) of a spot as a fraction of the ball's image radius."""
    lamp = spot.distance * np.array([math.cos(spot.azimuth) * math.cos(spot.elevation),
                                     math.sin(spot.azimuth) * math.cos(spot.elevation),
                                     math.sin(spot.elevation)])
    lamp_dir = (lamp - centre) / np.linalg.norm(lamp - centre)
    view = np.array([0.0, 0.0, camera_height]) - centre
    view /= np.linalg.norm(view)
    n = lamp_dir + view
    n /= np.linalg.norm(n)
    return float(n[0]), float(-n[1])


def ball_sprites(spec: AltLightingSpec, l: float, radius_px: float, ball_z: float,
                 n_phi: int = 72, oversample: int = 8
                 ) -> tuple[np.ndarray, np.ndarray, int]:
    """Sprites of the ball's radiance for ``n_phi`` world angles (as
    :func:`twin.lighting.ball_sprites`, relative to the plane's irradiance)."""
    half = int(math.ceil(radius_px)) + 4
    q = oversample
    n = 2 * half * q
    s = (np.arange(n) + 0.5) / q - half
    xx, yy = np.meshgrid(s, s)
    rho = np.hypot(xx, yy) / radius_px
    inside = rho < 1.0
    ca, sa = math.cos(spec.shade_angle), math.sin(spec.shade_angle)
    shade = spec.body_level + spec.body_shade * (xx * ca + yy * sa) / radius_px \
        - spec.rim_dark * spec.body_level * np.clip(rho, 0, 1) ** 4
    sprites = np.zeros((n_phi, n, n), dtype=np.float32)
    for k in range(n_phi):
        phi = 2 * math.pi * k / n_phi
        centre = np.array([l * math.cos(phi), l * math.sin(phi), ball_z])
        img = np.array(shade)
        for spot in spec.spots:
            px, py = _spot_position(spot, centre, spec.camera_height)
            dx = xx / radius_px - px
            dy = yy / radius_px - py
            c, sn = math.cos(spot.axis), math.sin(spot.axis)
            along = (dx * c + dy * sn) / (spot.width * spot.elongation)
            across = (-dx * sn + dy * c) / spot.width
            img = img + spec.spot_gain * spot.peak * np.exp(-0.5 * (along ** 2 + across ** 2))
        sprites[k][inside] = np.maximum(img[inside], 0.0)
    return sprites, inside.astype(np.float32), half
