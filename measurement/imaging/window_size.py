"""The tracking window sized from the markers found in the first frames (``--window`` not given).

The tracker (:mod:`measurement.imaging.tracking`) puts one square window of side w [px] on each
marker. What w must do follows from the geometry of the three markers in the image:

* **hold each marker** (its disk plus the blur around it, out to where its contrast has fallen
  to :data:`EDGE_LEVEL` of its peak: the outer radius R_i) inside the window's 2 px border ring
  (the plane fit of :mod:`measurement.imaging.window_fits` reads the background there), with
  room for the marker's frame-to-frame motion v_i twice (:data:`MOTION_MARGIN`: frame 1 and
  the frame after a lost one are predicted without motion): w / 2 - RING_PX - 0.5 px rounding
  >= R_i + 2 v_i (:func:`hold_px`); and the seeded pass's jump test (w / 3 px a frame) must
  let the marker move: w >= 3 * 2 v_i;
* **not reach another marker**: the ball runs on a circle of radius l (the distance between
  the centre marker's and the ball's seeds) about the centre marker and passes the CD marker at
  r_cd - l; any side of a window may face it, so its half-diagonal plus the rounding,
  sqrt(2) (w / 2 + 0.5 px), stays below each gap g minus the other marker's outer radius
  (:func:`reach_limit_px`).

Of the windows allowed, the family's :data:`FAMILY_WINDOW_PX` (30 px, on which every figure of
the benchmarks was measured: markers of radius <= 7 px at ~0.3 mm/px) is kept where it fits;
otherwise the nearest allowed size. A recording whose markers need more than the gaps allow
is refused with the numbers (:class:`WindowError`).

R_i and v_i are measured at the seeds in the first :data:`MOTION_FRAMES` + 1 frames: the
ring means of |frame - background| about the seed over the pixels nearer it than the other
markers (the background: a plane fitted to the outer rings, out to the nearest other marker),
their peak and where they fall below :data:`EDGE_LEVEL` of that peak; v_i the largest step of
the centroid of the pixels above half the peak, frame to frame. A marker too faint to measure
(peak below :data:`MIN_SNR` times the background noise; a faint ball found by the stacked
finder) is left out of the needs.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from measurement.imaging.markers import MarkerError

#: The window of the family's recordings [px] (tracking.DEFAULT_WINDOW).
FAMILY_WINDOW_PX = 30
#: Width of the window's border ring that the plane fit reads [px] (window_fits.border_ring).
RING_PX = 2.0
#: The window holds this many frame-to-frame steps of a marker.
MOTION_MARGIN = 2.0
#: A marker's outer radius: where its contrast has fallen to this share of its peak.
EDGE_LEVEL = 0.1
#: Frames after frame 0 over which the markers' motion is measured.
MOTION_FRAMES = 3
#: A marker whose peak contrast is below this many noise sigmas is not measured.
MIN_SNR = 8.0
#: Smallest and largest window the rule may choose [px] (tracking's limits: >= 8).
MIN_WINDOW_PX = 8
MAX_WINDOW_PX = 256
ROLES = ("centre", "CD", "ball")


class WindowError(MarkerError):
    """No tracking window holds every marker without reaching another one."""


@dataclass(frozen=True)
class MarkerExtent:
    """What the window must hold of one marker [px]: ``outer_px`` the radius where its contrast
    falls to EDGE_LEVEL of its peak (None: too faint to measure), ``step_px`` its largest
    frame-to-frame motion in the first frames."""

    outer_px: float | None
    step_px: float
    contrast: float


#: Farthest radius [px] of a marker's profile (a marker 4x the family's still fits).
MAX_PROFILE_PX = 64.0


def _region(shape: tuple[int, int], x: float, y: float, others: np.ndarray, r_lim: float):
    """Patch slices, pixel coordinates, distances [px] from (x, y) and the mask of the pixels
    within ``r_lim`` [px] of (x, y) and nearer to it than to any of ``others`` (K, 2) [px]."""
    h, w = shape
    n = int(math.ceil(r_lim))
    xi, yi = int(round(x)), int(round(y))
    x0, x1, y0, y1 = max(0, xi - n), min(w, xi + n + 1), max(0, yi - n), min(h, yi + n + 1)
    yy, xx = np.mgrid[y0:y1, x0:x1].astype(np.float64)
    d = np.hypot(xx - x, yy - y)
    mask = d <= r_lim
    for ox, oy in others:
        mask &= d < np.hypot(xx - ox, yy - oy)
    return (slice(y0, y1), slice(x0, x1)), xx, yy, d, mask


def _profile(img: np.ndarray, x: float, y: float, others: np.ndarray, r_lim: float
             ) -> tuple[np.ndarray, float, np.ndarray] | None:
    """Ring means (1 px rings) of |img - background| about (x, y) out to r_lim [px] over the
    pixels nearer (x, y) than the other markers; the background is a plane fitted to the
    outer rings (from max(0.6 r_lim, r_lim - 4) px). Also the background's robust noise sigma
    [grey levels] and the plane (value at (x, y), d/dx, d/dy); None: too few background
    pixels (a marker at the frame's edge)."""
    sl, xx, yy, d, mask = _region(img.shape, x, y, others, r_lim)
    patch = img[sl].astype(np.float64)
    outer = mask & (d >= max(0.6 * r_lim, r_lim - 4.0))
    if outer.sum() < 12:
        return None
    basis = np.column_stack([np.ones(int(outer.sum())), xx[outer] - x, yy[outer] - y])
    coef = np.linalg.lstsq(basis, patch[outer], rcond=None)[0]
    res = patch[outer] - basis @ coef
    noise = 1.4826 * float(np.median(np.abs(res - np.median(res))))
    dev = np.abs(patch - (coef[0] + coef[1] * (xx - x) + coef[2] * (yy - y)))
    k = np.rint(d[mask]).astype(np.int64)
    n = int(math.ceil(r_lim)) + 1
    prof = np.bincount(k, weights=dev[mask], minlength=n) / np.maximum(
        np.bincount(k, minlength=n), 1)
    return prof, noise, coef


def _outer_radius(prof: np.ndarray) -> tuple[float, float]:
    """(outer radius [px], peak) of a ring profile: the first radius outwards of the peak
    where it falls below EDGE_LEVEL of the peak (linear between rings)."""
    half = max(2, len(prof) // 2)
    i_peak = int(np.argmax(prof[:half]))
    peak = float(prof[i_peak])
    level = EDGE_LEVEL * peak
    for i in range(i_peak + 1, len(prof)):
        if prof[i] < level:
            return i - 1 + (prof[i - 1] - level) / (prof[i - 1] - prof[i]), peak
    return float(len(prof) - 1), peak


def _step(frames: np.ndarray, x: float, y: float, others: np.ndarray, reach: float,
          coef: np.ndarray, peak: float) -> float:
    """Largest frame-to-frame step [px] of the centroid of the pixels whose |value -
    background plane| is above half ``peak``, within ``reach`` [px] of the position the last
    step predicts (and nearer it than the other markers), followed from (x, y)."""
    px, py, vx, vy, largest = x, y, 0.0, 0.0, 0.0
    for k, f in enumerate(frames):
        qx, qy = px + vx, py + vy
        sl, xx, yy, _, mask = _region(f.shape, qx, qy, others, reach)
        bg = coef[0] + coef[1] * (xx - x) + coef[2] * (yy - y)
        mask &= np.abs(f[sl].astype(np.float64) - bg) > 0.5 * peak
        if not mask.any():
            break
        cx, cy = float(xx[mask].mean()), float(yy[mask].mean())
        if k:
            vx, vy = cx - px, cy - py
            largest = max(largest, math.hypot(vx, vy))
        px, py = cx, cy
    return largest


def marker_extents(frames: np.ndarray, seeds: np.ndarray) -> list[MarkerExtent]:
    """Outer radius and frame-to-frame step [px] of each marker at ``seeds`` (3, 2) [px]."""
    seeds = np.asarray(seeds, dtype=float)
    first = np.asarray(frames[0])
    head = np.asarray(frames[:MOTION_FRAMES + 1])
    out = []
    for i, (x, y) in enumerate(seeds):
        others = np.delete(seeds, i, axis=0)
        nearest = float(np.min(np.hypot(*(others - seeds[i]).T)))
        found = _profile(first, x, y, others, min(nearest, MAX_PROFILE_PX))
        if found is None:
            out.append(MarkerExtent(None, 0.0, 0.0))
            continue
        values, noise, coef = found
        outer, peak = _outer_radius(values)
        if peak < MIN_SNR * max(noise, 0.5):
            out.append(MarkerExtent(None, 0.0, peak))
            continue
        reach = min(nearest, outer + 0.25 * nearest)   # room for the motion
        out.append(MarkerExtent(outer, _step(head, x, y, others, reach, coef, peak), peak))
    return out


#: The window's centre pixel lies up to half a pixel from the marker's (rounded position).
ROUNDING_PX = 0.5


def hold_px(extent: MarkerExtent, margin: float = MOTION_MARGIN) -> float:
    """Smallest window [px] that holds a marker: (w / 2 - RING_PX) - ROUNDING_PX >= R + 2 v
    (the short side of an even window reaches w / 2 - 1 px from its centre pixel, the ring's
    inner pixels w / 2 - 2), and the seeded pass's jump limit w / 3 above 2 v (``margin``
    steps v instead of 2)."""
    e = margin * extent.step_px
    return max(2.0 * (extent.outer_px + RING_PX + ROUNDING_PX + e), 3.0 * e)


def reach_limit_px(gap_px: float, other_outer_px: float | None) -> float:
    """Largest window [px] whose farthest pixel centre (its corner, sqrt(2) w / 2 from the
    centre pixel, plus the rounding) stays short of another marker ``gap_px`` away with outer
    radius ``other_outer_px`` (0 where not measured)."""
    room = gap_px - (other_outer_px or 0.0) - math.sqrt(2.0) * ROUNDING_PX
    return math.sqrt(2.0) * room


@dataclass(frozen=True)
class WindowChoice:
    """The window chosen [px] and why (``summary.json``'s ``input.window_choice``)."""

    window_px: int
    needs_px: float            # the smallest window holding every measured marker
    allows_px: float           # the largest window reaching no other marker
    extents: tuple[MarkerExtent, ...]
    gaps_px: tuple[float, float, float]   # centre-ball (l), CD-ball (r_cd - l), centre-CD

    def summary(self) -> dict:
        return {"window_px": self.window_px, "needs_px": round(self.needs_px, 2),
                "allows_px": round(self.allows_px, 2),
                "outer_radius_px": [None if e.outer_px is None else round(e.outer_px, 2)
                                    for e in self.extents],
                "step_px": [round(e.step_px, 2) for e in self.extents],
                "ball_path_radius_px": round(self.gaps_px[0], 2),
                "ball_to_cd_px": round(self.gaps_px[1], 2),
                "rule": "the family's 30 px where it holds every marker (outer radius + 2 px "
                        "ring + 0.5 px + 2 steps, each side) and reaches no other; else the "
                        "nearest size that does"}


def window_from_extents(seeds: np.ndarray, extents: list[MarkerExtent],
                        frame_px: int = MAX_WINDOW_PX) -> WindowChoice:
    """The window [px] for markers at ``seeds`` (3, 2) [px] (centre, CD, ball) with these
    extents (see the module doc), at most ``frame_px`` (the frame's smaller side). Raises
    :class:`WindowError` where none fits."""
    seeds = np.asarray(seeds, dtype=float)
    l_px = float(np.hypot(*(seeds[2] - seeds[0])))
    r_cd = float(np.hypot(*(seeds[1] - seeds[0])))
    gaps = (l_px, abs(r_cd - l_px), r_cd)
    measured = [e for e in extents if e.outer_px is not None]
    needs = max([hold_px(e) for e in measured], default=float(MIN_WINDOW_PX))
    outer = [e.outer_px for e in extents]
    # (gap, other marker) for each ordered pair: centre-ball, CD-ball, centre-CD
    pairs = ((gaps[0], 2), (gaps[0], 0), (gaps[1], 2), (gaps[1], 1), (gaps[2], 1), (gaps[2], 0))
    allows = min(reach_limit_px(g, outer[j]) for g, j in pairs)
    low = max(MIN_WINDOW_PX, math.ceil(needs - 1e-9))
    high = min(MAX_WINDOW_PX, frame_px, math.floor(allows + 1e-9))
    if low > high:
        # two steps of room are ample, one is the least (the tracker predicts the motion from
        # frame 2 on): the family's window tracked a designed braking run at 40 Hz whose CD
        # marker (6.8 px, 5 px a frame) the two-step rule wanted in 39 px with 38.9 allowed
        low = max(MIN_WINDOW_PX, math.ceil(max([hold_px(e, 1.0) for e in measured],
                                               default=float(MIN_WINDOW_PX)) - 1e-9))
        # still too tight for the motion, but the family's window reaches no other marker:
        # track with it as before this rule existed (the tracker's own checks then decide)
        low = min(low, FAMILY_WINDOW_PX) if high >= FAMILY_WINDOW_PX else low
    if low > high:
        worst = int(np.argmax([hold_px(e) if e.outer_px is not None else 0.0
                               for e in extents]))
        e = extents[worst]
        need = (f"the {ROLES[worst]} marker (outer radius {e.outer_px:.1f} px, moving "
                f"{e.step_px:.1f} px a frame) needs >= {needs:.1f} px" if e.outer_px is not None
                else f"no marker could be measured, and the tracker's least window is "
                     f"{MIN_WINDOW_PX} px")
        raise WindowError(
            f"no tracking window fits these markers: {need}, but the ball passes "
            f"{gaps[0]:.1f} px from the centre marker and {gaps[1]:.1f} px from the CD marker, "
            f"which allows <= {allows:.1f} px. Give --window (and check --seeds), or record "
            f"with the markers farther apart")
    window = min(max(FAMILY_WINDOW_PX, low), high)
    return WindowChoice(int(window), float(needs), float(allows), tuple(extents), gaps)


def choose_window(frames: np.ndarray, seeds: np.ndarray) -> WindowChoice:
    """The tracking window [px] for ``frames`` (N, H, W) with markers at ``seeds`` (3, 2) [px]
    in frame 0 (centre, CD, ball): measured extents, then :func:`window_from_extents`."""
    return window_from_extents(seeds, marker_extents(frames, seeds), min(frames.shape[1:]))


def resolve_window(frames: np.ndarray, seeds: np.ndarray, given: int | None, source: str,
                   log=None) -> tuple[int, dict | None]:
    """The window [px] to track with and what ``summary.json`` records of its choice: ``given``
    (``--window``) as it is; None: :func:`choose_window`, recorded (``input.window_choice``)
    and logged only where it differs from the family's 30 px, so a family recording's
    summary stays as it was. A :class:`WindowError` names ``source``."""
    if given is not None:
        return int(given), None
    try:
        choice = choose_window(frames, seeds)
    except WindowError as exc:
        raise WindowError(f"{source}, frame 0: {exc}") from None
    if choice.window_px == FAMILY_WINDOW_PX:
        return choice.window_px, None
    if log is not None:
        log(f"tracking window {choice.window_px} px (the markers need >= {choice.needs_px:.1f}, "
            f"their distances allow <= {choice.allows_px:.1f}; --window overrides)")
    return choice.window_px, choice.summary()
