"""Lamps fixed in the world and what they do to the scene: irradiance of the ABU plane and the
shading of the brass ball (report sec. 5.2-5.3).

World frame: origin on the ABU axis in the ABU plane, X right and Y up *as seen on screen*
(the camera's x and -y), Z toward the camera [m]. A lamp is a point source at ``position``
with intensity ``power`` (irradiance at 1 m, arbitrary units; the scenario scales the image).

* The **plane** (ABU, CD, paper markers) is Lambertian: E(P) = sum_i I_i cos(t_i) / r_i^2
  + E_amb (the ambient term is the indirect light of an umbrella / the room, from above).
* The **ball** (polished brass, radius R) has a diffuse part k_d [sum_i I_i max(0, n.L_i) /
  r_i^2 + E_amb (1 + n_z) / 2] and a glossy part k_s sum_i I_i / r_i^2 max(0, n.H_i)^s
  (Blinn-Phong; H_i the half vector of the lamp and the camera directions). The lamps are
  50-600 mm away and the ball 1.5 mm in radius, so L_i and H_i are taken at the ball centre;
  they change with the ball's world angle phi = theta + beta, which is why the apparent centre
  of the ball moves with phi with several harmonics (a fixed image offset would give only one).

Lighting kinds (:func:`make_lamps`):

* ``ring``: the report's final TL ring around the lens (sec. 5.3): 16 points on a circle of
  40-70 mm at the camera's height, its centre a few mm off the optical axis and its intensity
  uneven along the tube; the highlight is a ring-shaped blob near the ball's top.
* ``two_spot``: the report's indirect lighting (sec. 5.2): an umbrella (ambient from above)
  plus two spots placed nearly symmetrically at a low elevation, so that two bright
  reflections appear on the ball.
* ``side``: stray side lamps at a low elevation, added on top of either (a window, a desk lamp).

Ball sprites: :func:`ball_sprites` renders the ball's radiance on a fine grid (``oversample``
samples per pixel side) for ``n_phi`` ball angles; :mod:`twin.scene` integrates those over
pixel squares (summed-area tables), so the shading is computed once, not per frame.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from abu_model.errors import ParameterError

LIGHTINGS = ("ring", "two_spot")


@dataclass(frozen=True)
class Lamp:
    """A point lamp: position (X, Y, Z) [m] in the world frame, power [irradiance at 1 m]."""

    position: tuple[float, float, float]
    power: float

    def to_dict(self) -> dict:
        return {"position_m": list(self.position), "power": self.power}


@dataclass(frozen=True)
class LightingSpec:
    """Everything about the light (see the module doc).

    Attributes:
        kind: ``ring`` or ``two_spot``.
        lamps: the point lamps (ring points, spots, stray lamps).
        ambient: irradiance of the indirect light from above [same units as the lamps].
        camera_height: height of the camera's entrance pupil above the axis [m].
        kd, ks, shininess: the brass ball's diffuse and glossy reflectance [-] and exponent.
        flicker: relative amplitude of the 100 Hz TL flicker [-]; flicker_phase [rad].
        n_stray: how many of the lamps are stray side lamps (last in ``lamps``).
        wall_height: height of the ABU channel's outer wall above its floor [m] (0 = none);
            it shades the ball from low lamps behind it over part of each revolution.
        wall_soft: width of the wall's penumbra (lamp size, chamfer) [m].
    """

    kind: str
    lamps: tuple[Lamp, ...]
    ambient: float
    camera_height: float
    kd: float
    ks: float
    shininess: float
    flicker: float
    flicker_phase: float
    n_stray: int = 0
    wall_height: float = 0.0
    wall_soft: float = 0.5e-3

    def __post_init__(self) -> None:
        if self.kind not in LIGHTINGS:
            raise ParameterError("lighting", self.kind, f"one of {', '.join(LIGHTINGS)}")

    @property
    def reflections(self) -> int:
        """Number of separate bright reflections on the ball (2 for ``two_spot``, else 1)."""
        return 2 if self.kind == "two_spot" else 1

    def to_dict(self) -> dict:
        return {"kind": self.kind, "lamps": [lp.to_dict() for lp in self.lamps],
                "n_stray_lamps": self.n_stray, "ambient": self.ambient,
                "camera_height_m": self.camera_height, "ball_kd": self.kd, "ball_ks": self.ks,
                "ball_shininess": self.shininess, "flicker_100hz_relative": self.flicker,
                "flicker_phase_rad": self.flicker_phase, "ball_reflections": self.reflections,
                "wall_height_m": self.wall_height, "wall_soft_m": self.wall_soft}


def make_lamps(kind: str, rng: np.random.Generator, *, stray: bool) -> LightingSpec:
    """Draw a lighting of ``kind`` (``ring`` / ``two_spot``), optionally with stray side lamps."""
    u = rng.uniform
    lamps: list[Lamp] = []
    cam_h = u(0.15, 0.25)
    if kind == "ring":
        radius, ox, oy = u(0.04, 0.07), u(-0.006, 0.006), u(-0.006, 0.006)
        uneven, psi = u(0.0, 0.35), u(0, 2 * math.pi)
        for a in np.linspace(0, 2 * math.pi, 16, endpoint=False):
            p = (1.0 + uneven * math.cos(a - psi)) * u(0.9, 1.1) / 16.0
            lamps.append(Lamp((ox + radius * math.cos(a), oy + radius * math.sin(a),
                               cam_h - 0.01), p))
        ambient, kd, ks, shin = u(0.01, 0.1), u(0.2, 0.4), u(0.8, 3.0), u(8.0, 20.0)
        flicker = u(0.02, 0.15)
    elif kind == "two_spot":
        psi, dist = u(0, 2 * math.pi), u(0.15, 0.3)
        for side in (0.0, math.pi + u(-0.35, 0.35)):
            elev = u(math.radians(18), math.radians(35))
            a = psi + side
            lamps.append(Lamp((dist * math.cos(a) * math.cos(elev),
                               dist * math.sin(a) * math.cos(elev), dist * math.sin(elev)),
                              u(0.8, 1.2) * 0.6 * dist ** 2))
        # the 650 W lamp on the umbrella: strong indirect light from above, which the brass
        # mirrors (kd > albedo of the ABU: the body of the ball stands out, brightest on top)
        ambient, kd, ks, shin = u(0.8, 1.4), u(0.9, 1.8), u(5.0, 12.0), u(60.0, 160.0)
        flicker = u(0.0, 0.03)   # incandescent: little 100 Hz ripple
    else:
        raise ParameterError("lighting", kind, f"one of {', '.join(LIGHTINGS)}")
    if kind == "ring":  # the ambient and the stray lamps relative to the ring's irradiance
        ambient *= _irradiance_at_axis(lamps, 0.0)
    e_main = _irradiance_at_axis(lamps, ambient)
    n_stray = 0
    if stray:
        n_stray = int(rng.integers(1, 3))
        for _ in range(n_stray):
            a, elev, dist = u(0, 2 * math.pi), u(math.radians(8), math.radians(25)), u(0.3, 0.6)
            lamps.append(Lamp((dist * math.cos(a) * math.cos(elev),
                               dist * math.sin(a) * math.cos(elev), dist * math.sin(elev)),
                              u(0.03, 0.15) * e_main * dist ** 2))
    return LightingSpec(kind, tuple(lamps), ambient, cam_h, kd, ks, shin, flicker,
                        u(0, 2 * math.pi), n_stray, wall_height=u(1.1, 1.8) * 1.5e-3,
                        wall_soft=u(0.3, 0.8) * 1.5e-3)


def _irradiance_at_axis(lamps: list[Lamp], ambient: float) -> float:
    return ambient + sum(lp.power * max(lp.position[2], 0.0)
                         / math.dist(lp.position, (0.0, 0.0, 0.0)) ** 3 for lp in lamps)


def _lamp_arrays(spec: LightingSpec) -> tuple[np.ndarray, np.ndarray]:
    pos = np.array([lp.position for lp in spec.lamps], dtype=float)
    power = np.array([lp.power for lp in spec.lamps], dtype=float)
    return pos, power


def plane_irradiance(spec: LightingSpec, X: np.ndarray, Y: np.ndarray) -> np.ndarray:
    """Irradiance of the ABU plane (Z = 0) at world points X, Y [m] (Lambert, inverse square)."""
    pos, power = _lamp_arrays(spec)
    E = np.full(np.broadcast(X, Y).shape, spec.ambient, dtype=float)
    for (lx, ly, lz), p in zip(pos, power):
        r2 = (lx - X) ** 2 + (ly - Y) ** 2 + lz ** 2
        E += p * max(lz, 0.0) / r2 ** 1.5
    return E


def ball_radiance(spec: LightingSpec, centre: np.ndarray, nx: np.ndarray, ny: np.ndarray,
                  nz: np.ndarray) -> np.ndarray:
    """Radiance of the ball at surface normals (nx, ny, nz) (world frame) for a ball centred at
    ``centre`` (3,) [m]; same units as :func:`plane_irradiance` times reflectance."""
    pos, power = _lamp_arrays(spec)
    cam = np.array([0.0, 0.0, spec.camera_height])
    v = cam - centre
    v /= np.linalg.norm(v)
    out = spec.kd * spec.ambient * 0.5 * (1.0 + nz)
    for lp, p in zip(pos, power):
        d = lp - centre
        r2 = float(d @ d)
        vis = wall_visibility(spec, centre, lp)
        if vis <= 0.0:
            continue
        L = d / math.sqrt(r2)
        H = L + v
        H /= np.linalg.norm(H)
        e = vis * p / r2
        ndl = nx * L[0] + ny * L[1] + nz * L[2]
        ndh = nx * H[0] + ny * H[1] + nz * H[2]
        out = out + e * (spec.kd * np.maximum(ndl, 0.0)
                         + spec.ks * np.maximum(ndh, 0.0) ** spec.shininess)
    return out


def wall_visibility(spec: LightingSpec, centre: np.ndarray, lamp: np.ndarray) -> float:
    """Visible fraction [0, 1] of a lamp from the ball centre over the channel's outer wall.

    The ball (radius R = centre height) rests on the floor against the outer wall, a cylinder
    of radius |centre_xy| + R and height ``wall_height``. The ray to the lamp leaves that
    cylinder at height z; visibility ramps from 0 to 1 as z passes the wall's top (penumbra
    ``wall_soft``). Lamps seen across the channel (outward and low) dim and vanish over part
    of each revolution: a non-sinusoidal function of the ball's angle, rich in harmonics.
    """
    if spec.wall_height <= 0.0:
        return 1.0
    R = float(centre[2])
    d = np.asarray(lamp, dtype=float) - centre
    dh = math.hypot(d[0], d[1])
    if dh == 0.0:
        return 1.0
    ux, uy = d[0] / dh, d[1] / dh
    cu = centre[0] * ux + centre[1] * uy
    rw = math.hypot(centre[0], centre[1]) + R
    s = -cu + math.sqrt(max(cu * cu - (centre[0] ** 2 + centre[1] ** 2 - rw * rw), 0.0))
    z = R + s * d[2] / dh
    return float(np.clip((z - spec.wall_height) / spec.wall_soft + 0.5, 0.0, 1.0))


def ball_sprites(spec: LightingSpec, l: float, radius_px: float, ball_z: float,
                 n_phi: int = 72, oversample: int = 8
                 ) -> tuple[np.ndarray, np.ndarray, int]:
    """Radiance sprites of the ball for ``n_phi`` world angles phi = 2 pi k / n_phi.

    Returns (sprites (n_phi, N, N) float32, coverage (N, N) float32, half) where the sprite
    covers [-half, half] px around the ball centre with N = 2 * half * oversample samples per
    side (sample centres at ((m + 0.5) / oversample - half) px, image x right, y down).
    """
    half = int(math.ceil(radius_px)) + 4   # margins for the pixel look-ups of scene.Sprite
    q = oversample
    n = 2 * half * q
    s = (np.arange(n) + 0.5) / q - half                       # px from the centre
    xx, yy = np.meshgrid(s, s)                                # image x right, y down
    rho2 = (xx * xx + yy * yy) / radius_px ** 2
    inside = rho2 < 1.0
    nx = np.where(inside, xx / radius_px, 0.0)
    ny = np.where(inside, -yy / radius_px, 0.0)               # world Y up
    nz = np.sqrt(np.clip(1.0 - rho2, 0.0, 1.0))
    sprites = np.zeros((n_phi, n, n), dtype=np.float32)
    nxi, nyi, nzi = nx[inside], ny[inside], nz[inside]   # shade only the ball's samples
    for k in range(n_phi):
        phi = 2 * math.pi * k / n_phi
        c = np.array([l * math.cos(phi), l * math.sin(phi), ball_z])
        sprites[k][inside] = ball_radiance(spec, c, nxi, nyi, nzi)
    return sprites, inside.astype(np.float32), half
