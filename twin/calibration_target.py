"""The twin's calibration target: views of a chessboard plate in the ABU plane, filmed through
the same lens and sensor as a scenario (:class:`twin.optics.OpticsSpec`).

Each view (:func:`render_views`): the plate (a printed chessboard on a white plate larger than
the field) lies in the ABU plane at a random in-plane position and rotation, drawn so that views
together cover the field; then

1. the ideal (pinhole) image is rendered at ``OVERSAMPLE`` x the resolution (pixel-centre
   samples of the board);
2. the lens distortion is applied by ``cv2.remap`` with the exact inverse map: a distorted
   pixel p shows the ideal point u with distort(u) = p, solved per (sub-)pixel by fixed-point
   iterations u <- c + (p - c) / (1 + k1 r(u)^2 + k2 r(u)^4) (:func:`undistort_map`; the
   round trip is tested to 1e-9 px); the result is averaged back to the sensor's pixels;
3. the sensor chain of a scenario (:class:`twin.optics.Sensor`: PSF blur, vignetting,
   column fixed-pattern noise, shot and read noise, saturation, 8 bits). A still: no motion
   blur; each view is the mean of a burst of ``AVERAGE`` exposures (rounded to 8 bits).

``abu render --scenario random --seed N --calibration-views K`` writes the views as
``calibration/view_NN.png`` beside the recording plus ``calibration/target.json`` (pattern,
square size, the true corners of every view).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from abu_model.atomic_io import atomic_write_text
from abu_model.errors import ParameterError

from twin.optics import OpticsSpec, Sensor, distort, half_diagonal

OVERSAMPLE = 4
PATTERN = (9, 6)
#: Exposures averaged per view (shot noise / 4).
AVERAGE = 16
#: Views rendered by default (``--calibration-views``).
DEFAULT_VIEWS = 30
MAX_VIEWS = 100


def undistort_map(xy: np.ndarray, spec: OpticsSpec, width: int, height: int,
                  tol_px: float = 1e-11, max_iter: int = 60) -> np.ndarray:
    """Ideal positions u with distort(u) = xy (..., 2) [px] (fixed-point iterations, each
    contracting the error by ~3 |k1|, until the largest step is below ``tol_px``)."""
    xy = np.asarray(xy, dtype=float)
    c = np.asarray(spec.optical_centre, dtype=float)
    rc2 = half_diagonal(width, height) ** 2
    dx, dy = xy[..., 0] - c[0], xy[..., 1] - c[1]
    ux, uy = dx.copy(), dy.copy()
    for _ in range(max_iter):
        r2 = (ux * ux + uy * uy) / rc2
        g = 1.0 + spec.k1 * r2 + spec.k2 * r2 * r2
        nx, ny = dx / g, dy / g
        step = max(float(np.abs(nx - ux).max(initial=0.0)),
                   float(np.abs(ny - uy).max(initial=0.0)))
        ux, uy = nx, ny
        if step < tol_px:
            break
    return np.stack([c[0] + ux, c[1] + uy], axis=-1)


def _board_corners(centre: np.ndarray, angle: float, square: float,
                   pattern: tuple[int, int]) -> np.ndarray:
    """(n, 2) ideal image positions of the inner corners [px] (row-major, x fastest)."""
    g = np.mgrid[0:pattern[1], 0:pattern[0]][::-1].reshape(2, -1).T.astype(float)
    g = (g - (np.array(pattern, float) - 1) / 2.0) * square
    ca, sa = math.cos(angle), math.sin(angle)
    return centre + g @ np.array([[ca, -sa], [sa, ca]])  # inverse of _ideal_image's turn


def draw_poses(rng: np.random.Generator, n: int, width: int, height: int, square: float,
               pattern: tuple[int, int]) -> list[tuple[np.ndarray, float]]:
    """n in-plane poses (centre [px], angle [rad]) with the board and a 1-square white margin
    inside the frame; the centres are spread over a grid of the field, so the views together
    reach its corners."""
    nx, ny = pattern[0] + 3, pattern[1] + 3  # board + margin, in squares
    poses = []
    cells = int(math.ceil(math.sqrt(n)))
    for i in range(n):
        gx, gy = (i % cells + 0.5) / cells, (i // cells % cells + 0.5) / cells
        for _ in range(2000):
            ang = rng.uniform(-0.6, 0.6) + (math.pi / 2 if rng.random() < 0.3 else 0.0)
            ca, sa = abs(math.cos(ang)), abs(math.sin(ang))
            hx = 0.5 * square * (nx * ca + ny * sa)
            hy = 0.5 * square * (nx * sa + ny * ca)
            if 2 * hx > width - 2 or 2 * hy > height - 2:
                continue
            cx = hx + (width - 1 - 2 * hx) * np.clip(gx + rng.uniform(-0.15, 0.15), 0, 1)
            cy = hy + (height - 1 - 2 * hy) * np.clip(gy + rng.uniform(-0.15, 0.15), 0, 1)
            poses.append((np.array([cx, cy]), ang))
            break
        else:
            raise ParameterError("calibration square", square, "a board that fits the frame")
    return poses


def _ideal_image(centre: np.ndarray, angle: float, square: float, pattern: tuple[int, int],
                 width: int, height: int, white: float, black: float) -> np.ndarray:
    """(OVERSAMPLE H, OVERSAMPLE W) float32 radiance of the plate at sub-pixel centres.

    Edges are antialiased by a linear ramp one sample wide across each grid line (separable:
    the product of the ramps in u and v), symmetric about the line, so the edges and corners
    stay where they are (a point-sampled board put 1/4 px steps on the edge positions: corner
    errors of ~0.03 px)."""
    s = OVERSAMPLE
    yy, xx = np.mgrid[0:height * s, 0:width * s].astype(np.float32)
    x = (xx + 0.5) / s - 0.5 - np.float32(centre[0])
    y = (yy + 0.5) / s - 0.5 - np.float32(centre[1])
    ca, sa = math.cos(angle), math.sin(angle)
    # board coordinates [squares], origin at the board's outer corner
    u = (ca * x - sa * y) / square + (pattern[0] + 1) / 2.0
    v = (sa * x + ca * y) / square + (pattern[1] + 1) / 2.0
    ramp = square * s  # samples per square: distance to a line [samples] = d [squares] * ramp

    def sign(w: np.ndarray) -> np.ndarray:
        # +-1 alternating per square; linear from -1 to +1 over one sample across each line
        fl = np.floor(w)
        frac = w - fl
        d = np.minimum(frac, 1.0 - frac) * np.float32(2.0 * ramp)  # 2 x distance [samples]
        par = np.float32(1.0) - np.float32(2.0) * (fl - np.float32(2.0) * np.floor(fl * 0.5))
        return par * np.minimum(np.float32(1.0), d)

    def inside(w: np.ndarray, n: int) -> np.ndarray:  # 1 inside [0, n], ramped at the ends
        return np.clip(np.minimum(w, n - w) * ramp + 0.5, 0.0, 1.0)

    dark = (0.5 + 0.5 * sign(u) * sign(v)) * inside(u, pattern[0] + 1) * \
        inside(v, pattern[1] + 1)
    return (white - (white - black) * dark).astype(np.float32)


def render_views(spec: OpticsSpec, width: int, height: int, n_views: int, seed: int, *,
                 pattern: tuple[int, int] = PATTERN, square_px: float | None = None,
                 white: float = 190.0, black: float = 25.0, average: int = AVERAGE
                 ) -> tuple[np.ndarray, np.ndarray, float]:
    """Render ``n_views`` calibration views through ``spec`` (see the module doc).

    Each view is the mean of ``average`` exposures of the still plate (a burst, as a lab
    averages to beat shot noise), rounded to 8 bits.

    Returns:
        (frames (K, H, W) uint8, true distorted corners (K, n, 2) [px], square size [px]).
    """
    import cv2

    if isinstance(n_views, bool) or not isinstance(n_views, (int, np.integer)) \
            or not 1 <= n_views <= MAX_VIEWS:
        raise ParameterError("--calibration-views", n_views, f"an integer in 1..{MAX_VIEWS}")
    rng = np.random.default_rng([int(seed), 7])
    square = float(square_px or min(width, height) / 20.0)
    poses = draw_poses(rng, int(n_views), width, height, square, pattern)
    s = OVERSAMPLE
    # distorted sub-pixel centres -> ideal positions -> indices of the oversampled ideal image
    yy, xx = np.mgrid[0:height * s, 0:width * s].astype(float)
    p = np.stack([(xx + 0.5) / s - 0.5, (yy + 0.5) / s - 0.5], axis=-1)
    u = undistort_map(p, spec, width, height)
    map_x = ((u[..., 0] + 0.5) * s - 0.5).astype(np.float32)
    map_y = ((u[..., 1] + 0.5) * s - 0.5).astype(np.float32)
    radiance = np.empty((n_views, height, width), np.float32)
    corners = []
    for i, (c, a) in enumerate(poses):
        ideal = _ideal_image(c, a, square, pattern, width, height, white, black)
        warped = cv2.remap(ideal, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        radiance[i] = warped.reshape(height, s, width, s).mean(axis=(1, 3))
        corners.append(distort(_board_corners(c, a, square, pattern), spec, width, height))
    sensor = Sensor(spec, width, height, 0.0, 0.0, np.random.default_rng([int(seed), 8]))
    frames = np.empty((n_views, height, width), np.uint8)
    for i in range(n_views):
        burst = sensor.apply(np.repeat(radiance[i:i + 1], average, axis=0), np.zeros(average))
        frames[i] = np.clip(np.rint(burst.mean(axis=0)), 0, 255).astype(np.uint8)
    return frames, np.stack(corners), square


def write_views(folder: str | Path, spec: OpticsSpec, width: int, height: int, n_views: int,
                seed: int, *, pixel_size_m: float | None = None) -> Path:
    """Render and write ``view_NN.png`` and ``target.json`` into ``folder``."""
    import cv2
    from abu_model.atomic_io import atomic_open
    from measurement.report.json_text import dumps

    frames, corners, square = render_views(spec, width, height, n_views, seed)
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    digits = max(2, len(str(n_views - 1)))
    for i, f in enumerate(frames):
        ok, buf = cv2.imencode(".png", f)
        if not ok:  # pragma: no cover - encoding an 8-bit array does not fail
            raise OSError("PNG encoding failed")
        with atomic_open(out / f"view_{i:0{digits}d}.png", "wb") as fh:
            fh.write(buf.tobytes())
    meta = {"kind": "abu-calibration-target", "format_version": 1,
            "pattern_inner_corners": list(PATTERN), "square_size_px": square,
            "square_size_m": None if pixel_size_m is None else square * pixel_size_m,
            "seed": int(seed), "n_views": int(n_views), "optics": spec.to_dict(),
            "corners_px": corners.tolist(),
            "note": "corners_px: the true (distorted) image positions of the inner corners"}
    atomic_write_text(out / "target.json", dumps(meta))
    return out
