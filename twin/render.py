"""A synthetic high-speed camera: renders marker frames from known (true) marker centres.

Image model (grey levels, before noise), at pixel (x, y) = (column, row):

    I = background + gradient * ((x, y) - image centre) . e_g            (additive lighting)
        + sum over markers of (brightness_m - background) * coverage_m(x, y)

``coverage_m`` is the fraction of the pixel's area covered by marker m's disk (supersampled
``supersample``^2 times per pixel, each sample antialiased by a linear ramp, so the area is
nearly exact). Markers are opaque disks that receive the same additive lighting as the
background. With motion blur the coverage is averaged over ``blur_samples`` sub-frame
positions spread over ``exposure_fraction`` of the frame interval, centred on the frame time.
Gaussian sensor noise (``noise_sigma`` grey levels) is added and the result rounded to the
nearest integer and clipped to 0..255 (8-bit quantisation).

Asymmetric lighting on the ball (report sec. 5.2): the lit part of the brass ball is displaced
toward the lamp, so its *apparent* centre is the true centre plus a fixed image-frame offset
``ball_shift_px`` in the direction ``light_direction``. Because beta is the angle of the
centre->ball vector, a fixed offset appears in beta as a harmonic of the ball's absolute
angle phi = theta + beta: delta_beta ~= (ball_shift_px / l_px) sin(light_direction - phi),
i.e. at the rotation frequency, as the report observed.

Directions (gradient, light) are angles counter-clockwise from the image's +x axis as seen on
screen (y up), the same convention as theta (see :class:`CameraGeometry`).

Geometry (:class:`CameraGeometry`): the camera looks down on the ABU; the ABU axis is at pixel
``centre_xy``; a world point at radius r [m] and angle a [rad] appears at

    x = x_c + (r / pixel_size) cos a,      y = y_c - (r / pixel_size) sin a

(the minus: image rows grow downward). Hence theta = atan2(-(y_cd - y_c), x_cd - x_c) computed
from pixel coordinates is the simulation's theta with its sign: the report's clockwise rotation
(negative omega) turns the markers clockwise on screen. The CD marker sits at radius r_cd and
angle theta; the ball centre at radius l and angle theta + beta.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace
from typing import Any

import numpy as np

from abu_model.errors import ParameterError
from abu_model.params import check_finite, check_nonnegative, check_positive


# --------------------------------------------------------------------------------------------
# geometry


@dataclass(frozen=True)
class CameraGeometry:
    """World-to-pixel mapping of the camera above the ABU.

    Attributes:
        pixel_size: size of one pixel on the ABU plane [m/px].
        centre_x, centre_y: image position of the ABU axis [px] (x = column, y = row).
        r_cd: radius of the CD marker's centre [m].
        l: radius of the ball centre's path [m] (the report's l).
    """

    pixel_size: float = 0.3e-3
    centre_x: float = 128.3
    centre_y: float = 126.6
    r_cd: float = 0.030
    l: float = 1.15e-2

    def __post_init__(self) -> None:
        check_positive("pixel_size", self.pixel_size, "m/px")
        check_finite("centre_x", self.centre_x, "a finite pixel position")
        check_finite("centre_y", self.centre_y, "a finite pixel position")
        check_positive("r_cd", self.r_cd, "m")
        check_positive("l", self.l, "m")

    @property
    def r_cd_px(self) -> float:
        """CD marker radius in the image [px]."""
        return self.r_cd / self.pixel_size

    @property
    def l_px(self) -> float:
        """Ball path radius in the image [px]."""
        return self.l / self.pixel_size

    def to_pixels(self, radius_m: np.ndarray | float, angle: np.ndarray | float) -> np.ndarray:
        """(..., 2) pixel positions x, y of world points at polar (radius [m], angle [rad])."""
        rp = np.asarray(radius_m, dtype=float) / self.pixel_size
        a = np.asarray(angle, dtype=float)
        return np.stack(np.broadcast_arrays(self.centre_x + rp * np.cos(a),
                                            self.centre_y - rp * np.sin(a)), axis=-1)

    def marker_positions(self, theta: np.ndarray, beta: np.ndarray
                         ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """True pixel centres (N, 2) of the ABU centre, CD marker and ball for theta, beta [rad]."""
        theta = np.atleast_1d(np.asarray(theta, dtype=float))
        beta = np.atleast_1d(np.asarray(beta, dtype=float))
        centre = np.tile([self.centre_x, self.centre_y], (theta.shape[0], 1))
        return centre, self.to_pixels(self.r_cd, theta), self.to_pixels(self.l, theta + beta)


def angles_from_pixels(centre_xy: np.ndarray, cd_xy: np.ndarray, ball_xy: np.ndarray,
                       *, unwrap: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """theta and beta [rad] from (N, 2) pixel centres, in the convention of :class:`CameraGeometry`.

    theta = atan2(-(y_cd - y_c), x_cd - x_c) (counter-clockwise on screen is positive),
    beta = atan2(-(y_ball - y_c), x_ball - x_c) - theta, wrapped to (-pi, pi].
    With ``unwrap`` (default) both are unwrapped along the frames (NaN rows are kept as NaN and
    skipped by the unwrapping).
    """
    c = np.asarray(centre_xy, dtype=float)
    p = np.asarray(cd_xy, dtype=float)
    b = np.asarray(ball_xy, dtype=float)
    theta = np.arctan2(-(p[..., 1] - c[..., 1]), p[..., 0] - c[..., 0])
    phi = np.arctan2(-(b[..., 1] - c[..., 1]), b[..., 0] - c[..., 0])
    beta = np.angle(np.exp(1j * (phi - theta)))
    if unwrap:
        theta = _unwrap_nan(theta)
        beta = _unwrap_nan(beta)
    return theta, beta


def _unwrap_nan(a: np.ndarray) -> np.ndarray:
    out = np.array(a, dtype=float)
    ok = np.isfinite(out)
    if ok.any():
        out[ok] = np.unwrap(out[ok])
    return out


# --------------------------------------------------------------------------------------------
# render settings


@dataclass(frozen=True)
class MarkerStyle:
    """One marker's look: a disk of ``radius_px`` [px] with plateau ``brightness`` [grey levels]."""

    radius_px: float
    brightness: float

    def __post_init__(self) -> None:
        check_positive("radius_px", self.radius_px, "px")
        check_finite("brightness", self.brightness, "a grey level (0..255 for a visible marker)")


@dataclass(frozen=True)
class RenderSettings:
    """Settings of the synthetic camera; every one has a default.

    Attributes:
        width, height: frame size [px].
        background: background grey level at the image centre [grey levels].
        gradient: additive lighting gradient [grey levels/px] ...
        gradient_direction: ... increasing toward this direction [rad, counter-clockwise from
            +x on screen].
        noise_sigma: Gaussian sensor noise standard deviation [grey levels].
        centre, cd, ball: the three markers' styles (radius [px], brightness [grey levels]).
            The defaults are bright markers on a darker background; a brightness below the
            background gives dark markers.
        ball_shift_px: asymmetric-lighting offset of the ball's apparent centre [px].
        light_direction: direction of that offset [rad, counter-clockwise from +x on screen].
        exposure_fraction: exposure time / frame interval [-] for motion blur (0 = none).
        blur_samples: sub-frame positions averaged when ``exposure_fraction`` > 0 [-].
        supersample: samples per pixel side for antialiasing [-].
    """

    width: int = 256
    height: int = 256
    background: float = 60.0
    gradient: float = 0.1
    gradient_direction: float = 0.6
    noise_sigma: float = 3.0
    centre: MarkerStyle = field(default_factory=lambda: MarkerStyle(6.0, 200.0))
    cd: MarkerStyle = field(default_factory=lambda: MarkerStyle(4.5, 190.0))
    ball: MarkerStyle = field(default_factory=lambda: MarkerStyle(5.0, 215.0))
    ball_shift_px: float = 0.5
    light_direction: float = 2.2
    exposure_fraction: float = 0.0
    blur_samples: int = 5
    supersample: int = 4

    def __post_init__(self) -> None:
        for name in ("width", "height", "blur_samples", "supersample"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
                raise ParameterError(name, value, "an integer >= 1")
        if self.width < 8 or self.height < 8:
            raise ParameterError("width/height", (self.width, self.height), "at least 8 px each")
        check_finite("background", self.background, "a grey level")
        check_nonnegative("gradient", self.gradient, "grey levels/px")
        check_finite("gradient_direction", self.gradient_direction, "an angle [rad]")
        check_nonnegative("noise_sigma", self.noise_sigma, "grey levels")
        check_nonnegative("ball_shift_px", self.ball_shift_px, "px")
        check_finite("light_direction", self.light_direction, "an angle [rad]")
        frac = check_nonnegative("exposure_fraction", self.exposure_fraction, "")
        if frac > 1.0:
            raise ParameterError("exposure_fraction", frac, "a fraction in [0, 1]")
        for name in ("centre", "cd", "ball"):
            if not isinstance(getattr(self, name), MarkerStyle):
                raise ParameterError(name, getattr(self, name), "a MarkerStyle")

    def with_(self, **changes: Any) -> "RenderSettings":
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)

    def to_dict(self) -> dict[str, Any]:
        """Plain dict with unit-suffixed keys (for meta.json)."""
        d = asdict(self)
        out = {
            "width_px": d["width"], "height_px": d["height"],
            "background_grey": d["background"], "gradient_grey_per_px": d["gradient"],
            "gradient_direction_rad": d["gradient_direction"],
            "noise_sigma_grey": d["noise_sigma"],
            "ball_shift_px": d["ball_shift_px"], "light_direction_rad": d["light_direction"],
            "exposure_fraction": d["exposure_fraction"], "blur_samples": d["blur_samples"],
            "supersample": d["supersample"],
        }
        for name in ("centre", "cd", "ball"):
            out[f"{name}_marker"] = {"radius_px": d[name]["radius_px"],
                                     "brightness_grey": d[name]["brightness"]}
        return out

    @property
    def ball_shift_vector(self) -> np.ndarray:
        """Apparent-minus-true ball centre (dx, dy) [px] in image coordinates (y down)."""
        return self.ball_shift_px * np.array([math.cos(self.light_direction),
                                              -math.sin(self.light_direction)])


# --------------------------------------------------------------------------------------------
# rendering


def lighting_image(settings: RenderSettings) -> np.ndarray:
    """(H, W) float32 background with the additive lighting gradient [grey levels]."""
    s = settings
    yy, xx = np.mgrid[0:s.height, 0:s.width].astype(np.float64)
    cx, cy = (s.width - 1) / 2.0, (s.height - 1) / 2.0
    ex, ey = math.cos(s.gradient_direction), -math.sin(s.gradient_direction)
    return (s.background + s.gradient * ((xx - cx) * ex + (yy - cy) * ey)).astype(np.float32)


def _subframe_positions(xy: np.ndarray, settings: RenderSettings) -> np.ndarray:
    """(N, S, 2) positions at S sub-frame times spread over the exposure around each frame.

    Positions between frames come from a cubic spline through the per-frame positions.
    """
    n = xy.shape[0]
    if settings.exposure_fraction <= 0.0 or settings.blur_samples == 1 or n < 2:
        return xy[:, None, :]
    from scipy.interpolate import CubicSpline

    s = settings.blur_samples
    offsets = ((np.arange(s) + 0.5) / s - 0.5) * settings.exposure_fraction  # [frames]
    t = np.arange(n, dtype=float)
    spline = CubicSpline(t, xy, axis=0)
    tt = (t[:, None] + offsets[None, :]).ravel()
    return spline(tt).reshape(n, s, 2)


def _add_disk(img: np.ndarray, pos: np.ndarray, style: MarkerStyle, contrast: float,
              supersample: int) -> None:
    """Add ``contrast`` * area coverage of a disk to each frame of ``img`` (in place).

    img: (n, H, W) float32; pos: (n, S, 2) sub-frame centres [px] (coverage averaged over S).
    Only a small patch around each disk is computed.
    """
    n, n_sub, _ = pos.shape
    _, hgt, wid = img.shape
    r = style.radius_px
    span = float(np.ptp(pos, axis=1).max()) if n_sub > 1 else 0.0
    half = int(math.ceil(r + span + 2.0))
    size = 2 * half + 1
    mean = pos.mean(axis=1)
    x0 = np.floor(mean[:, 0]).astype(np.int64) - half  # patch corner [px]
    y0 = np.floor(mean[:, 1]).astype(np.int64) - half
    visible = (x0 + size > 0) & (y0 + size > 0) & (x0 < wid) & (y0 < hgt)
    if not visible.any():
        return
    idx = np.flatnonzero(visible)
    x0, y0, pos = x0[idx], y0[idx], pos[idx]
    ss = supersample
    u = ((np.arange(ss) + 0.5) / ss - 0.5).astype(np.float32)          # sample offsets [px]
    grid = (np.arange(size)[:, None] + u[None, :]).ravel().astype(np.float32)  # size*ss
    cov = np.zeros((idx.size, size, size), dtype=np.float32)
    for s in range(n_sub):
        dx = (x0[:, None] + grid[None, :]) - pos[:, s, 0:1].astype(np.float32)   # (n, size*ss)
        dy = (y0[:, None] + grid[None, :]) - pos[:, s, 1:2].astype(np.float32)
        d = np.sqrt(dy[:, :, None] ** 2 + dx[:, None, :] ** 2)                  # (n, Y, X)
        # each sample is a 1/ss px square: a linear ramp over its width gives its area share
        d -= r
        d *= -ss
        d += 0.5
        np.clip(d, 0.0, 1.0, out=d)
        cov += d.reshape(-1, size, ss, size, ss).sum(axis=(2, 4))
    cov *= contrast / (n_sub * ss * ss)
    inside = (x0 >= 0) & (y0 >= 0) & (x0 + size <= wid) & (y0 + size <= hgt)
    k = np.flatnonzero(inside)
    if k.size:
        rows = (y0[k, None] + np.arange(size))[:, :, None]
        cols = (x0[k, None] + np.arange(size))[:, None, :]
        img[idx[k, None, None], rows, cols] += cov[k]  # patches of one marker never overlap
    for k in np.flatnonzero(~inside):  # patches cut by the frame edge (few): clip by slicing
        ya, xa = max(0, y0[k]), max(0, x0[k])
        yb, xb = min(hgt, y0[k] + size), min(wid, x0[k] + size)
        img[idx[k], ya:yb, xa:xb] += cov[k, ya - y0[k]:yb - y0[k], xa - x0[k]:xb - x0[k]]


def render_markers(positions: np.ndarray, styles: list[MarkerStyle], settings: RenderSettings,
                   seed: int | None = 0, *, chunk: int = 256) -> np.ndarray:
    """Render frames with any number of disk markers.

    Args:
        positions: (N, M, 2) apparent marker centres x, y per frame [px].
        styles: M marker styles.
        settings: camera settings (marker styles in ``settings`` are ignored here).
        seed: seed of ``np.random.default_rng`` for the sensor noise.
        chunk: frames rendered at once (memory bound).

    Returns:
        (N, H, W) uint8 frames.
    """
    pos = np.asarray(positions, dtype=float)
    if pos.ndim != 3 or pos.shape[2] != 2 or pos.shape[1] != len(styles):
        raise ParameterError("positions", pos.shape, f"an (N, {len(styles)}, 2) array of px")
    if not np.all(np.isfinite(pos)):
        raise ParameterError("positions", "non-finite", "finite marker centres [px]")
    s = settings
    n = pos.shape[0]
    rng = np.random.default_rng(seed)
    base = lighting_image(s) + np.float32(0.5)  # + 0.5: truncation below rounds to nearest
    sub = [_subframe_positions(pos[:, m, :], s) for m in range(len(styles))]
    out = np.empty((n, s.height, s.width), dtype=np.uint8)
    for start in range(0, n, chunk):
        stop = min(n, start + chunk)
        shape = (stop - start, s.height, s.width)
        if s.noise_sigma > 0:
            img = rng.standard_normal(shape, dtype=np.float32)
            img *= np.float32(s.noise_sigma)
            img += base
        else:
            img = np.broadcast_to(base, shape).copy()
        for m, st in enumerate(styles):
            _add_disk(img, sub[m][start:stop], st, st.brightness - s.background, s.supersample)
        np.clip(img, 0.0, 255.0, out=img)
        out[start:stop] = img  # float -> uint8 truncates: with the + 0.5 above, rounds
    return out


def render_frames(centre_xy: np.ndarray, cd_xy: np.ndarray, ball_xy: np.ndarray,
                  settings: RenderSettings | None = None, seed: int | None = 0) -> np.ndarray:
    """Render a recording from the TRUE marker centres (N, 2) [px] of each frame.

    The ball is drawn at its apparent centre (true centre + ``settings.ball_shift_vector``).

    Returns:
        (N, H, W) uint8 frames.
    """
    s = settings or RenderSettings()
    c = np.asarray(centre_xy, dtype=float)
    p = np.asarray(cd_xy, dtype=float)
    b = np.asarray(ball_xy, dtype=float) + s.ball_shift_vector
    if not (c.shape == p.shape == b.shape) or c.ndim != 2 or c.shape[1] != 2:
        raise ParameterError("marker positions", (c.shape, p.shape, b.shape),
                             "three (N, 2) arrays of x, y [px] of equal length")
    return render_markers(np.stack([c, p, b], axis=1), [s.centre, s.cd, s.ball], s, seed)
