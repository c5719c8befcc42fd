"""Find the three markers in the first frame and tell which is which; parse ``--seeds``.

Detection: the frame is smoothed, a large-scale background (median over a window of about
twice the largest marker diameter) is subtracted, so uneven lighting does not matter; the
remaining bright (or, with ``dark=True``, dark) spots above half the strongest spot's contrast
and at least ``min_contrast`` grey levels are labelled (8-connected). Blobs with a plausible
size (area of a disk of radius ``r_min``..``r_max`` px) and shape (filled fraction of the
bounding box near pi/4, aspect ratio near 1) are candidates, and their centres are refined with
the tracker's default (sub-pixel) method.

Roles (order returned: ABU centre, CD marker, ball):

1. the **ABU centre** marker is the candidate nearest the image centre (the camera is aimed at
   the rotation axis); it must be clearly nearer than the others (less than half the next
   distance), or the roles are ambiguous;
2. of the other two, the **ball** is the one nearer the centre marker (the ball runs at
   l = 11.5 mm; the CD marker sits further out on the CD, r_cd > l); the two distances must
   differ by at least 20 %.

If a ``CameraGeometry`` is given, the expected radii l and r_cd (in px) decide step 2 instead,
and step 1 takes the marker whose distances to the other two best match them.
Whenever the rule does not decide (not exactly three candidates, ties), :class:`MarkerError`
lists the candidates and asks for ``--seeds x,y;x,y;x,y``.
"""
from __future__ import annotations

import math
import re

import numpy as np

from abu_model.errors import AbuError

ROLES = ("centre", "cd", "ball")


class MarkerError(AbuError):
    """Markers cannot be found or told apart, or a seeds string is malformed."""


#: Smallest distance between two seeds [px]: closer ones are one marker (track_checks).
MIN_SEED_SEPARATION_PX = 2.0


def parse_seeds(text: str, count: int = 3) -> np.ndarray:
    """Parse ``"x,y;x,y;x,y"`` (pixels; x = column, y = row) into a (count, 2) float array.

    Raises:
        MarkerError: naming the offending entry and the expected form.
    """
    if not isinstance(text, str) or not text.strip():
        raise MarkerError(f"seeds {text!r}: expected '{_example(count)}' (x,y pixel positions of "
                          "the ABU centre, CD marker and ball, separated by ';')")
    parts = [p.strip() for p in text.strip().strip(";").split(";")]
    if len(parts) != count:
        raise MarkerError(f"seeds {text!r}: found {len(parts)} positions, expected {count} as "
                          f"'{_example(count)}'")
    out = np.empty((count, 2))
    for i, part in enumerate(parts):
        nums = [v for v in re.split(r"[,\s]+", part) if v]
        if len(nums) != 2:
            raise MarkerError(f"seeds {text!r}: position {i + 1} '{part}' should be 'x,y'")
        for j, v in enumerate(nums):
            try:
                out[i, j] = float(v)
            except ValueError:
                raise MarkerError(f"seeds {text!r}: position {i + 1} '{part}': '{v}' is not a "
                                  "number") from None
            if not math.isfinite(out[i, j]):
                raise MarkerError(f"seeds {text!r}: position {i + 1} '{part}' is not finite")
    for i in range(count):
        for j in range(i + 1, count):
            gap = float(np.hypot(*(out[i] - out[j])))
            if gap < MIN_SEED_SEPARATION_PX:
                raise MarkerError(
                    f"seeds {text!r}: positions {i + 1} and {j + 1} are {gap:.3g} px apart; "
                    f"expected {count} distinct markers (ABU centre; CD marker; ball) at least "
                    f"{MIN_SEED_SEPARATION_PX:g} px apart")
    return out


def format_seeds(seeds: np.ndarray) -> str:
    """The inverse of :func:`parse_seeds`: ``"x,y;x,y;x,y"`` with 0.01 px resolution."""
    return ";".join(f"{x:.2f},{y:.2f}" for x, y in np.asarray(seeds, dtype=float))


def _example(count: int) -> str:
    return ";".join(["x,y"] * count)


def detect_blobs(frame: np.ndarray, *, dark: bool = False, r_min: float = 2.0,
                 r_max: float = 12.0, min_contrast: float = 15.0,
                 fraction: float = 0.25) -> list[dict]:
    """Candidate marker blobs in one frame, strongest first.

    The blobs are thresholded at ``fraction`` of the strongest peak over the local background
    (at least half of ``min_contrast``).

    Returns a list of dicts with ``x``, ``y`` [px] (sub-pixel), ``area`` [px^2] and
    ``contrast`` [grey levels] (peak over the local background).
    """
    import cv2

    img = np.asarray(frame)
    if img.ndim != 2 or img.dtype != np.uint8:
        raise MarkerError(f"frame: expected an (H, W) uint8 image, got {img.shape} {img.dtype}")
    f = img.astype(np.float32)
    if dark:
        f = 255.0 - f
    f = cv2.GaussianBlur(f, (0, 0), 1.0)
    k = int(4 * r_max + 1) | 1                     # odd, about twice the largest diameter
    k_max = min(img.shape) if min(img.shape) % 2 else min(img.shape) - 1
    k = max(3, min(k, k_max))
    # medianBlur on uint8 allows any odd size; the background is smooth, so 8 bits are enough
    bg = cv2.medianBlur(np.clip(f, 0, 255).astype(np.uint8), k).astype(np.float32)
    top = f - bg
    strongest = float(top.max())
    if strongest < min_contrast:
        return []
    # a quarter of the strongest: a saturated brass ball must not hide a dim paper marker
    mask = (top > max(fraction * strongest, min_contrast * 0.5)).astype(np.uint8)
    n, labels, stats, cents = cv2.connectedComponentsWithStats(mask, connectivity=8)
    out = []
    a_min, a_max = math.pi * r_min ** 2 * 0.5, math.pi * r_max ** 2 * 1.5
    for i in range(1, n):
        x, y, w, h, area = stats[i]
        if not (a_min <= area <= a_max):
            continue
        if max(w, h) > 1.6 * min(w, h) + 1 or area < 0.45 * w * h:
            continue  # not round
        peak = float(top[labels == i].max())
        if peak < min_contrast:
            continue
        out.append({"x": float(cents[i][0]), "y": float(cents[i][1]), "area": float(area),
                    "contrast": peak})
    out.sort(key=lambda b: -b["contrast"] * b["area"])
    return out


def _refine(frame: np.ndarray, blobs: list[dict], dark: bool, window: int) -> None:
    """Sub-pixel centres of the blobs with the tracker's default method (in place), without
    its edge step: a seed only places the first window, and the seeds stated in tracking.json
    / summary.json stay the same whether the tracking takes the step or not."""
    from measurement.imaging.tracking import TrackingOptions, measure_windows

    plain = TrackingOptions(edge_step=False)
    h, w = frame.shape
    half = window // 2
    for b in blobs:
        x0 = int(round(b["x"])) - half
        y0 = int(round(b["y"])) - half
        if x0 < 0 or y0 < 0 or x0 + window > w or y0 + window > h:
            continue
        x, y, r, code = measure_windows(frame[None, y0:y0 + window, x0:x0 + window], dark=dark,
                                        options=plain)
        if code[0] == 0:
            b["x"], b["y"], b["radius"] = x0 + float(x[0]), y0 + float(y[0]), float(r[0])


def _merge_reflections(blobs: list[dict], distance: float) -> list[dict]:
    """Merge candidates closer than ``distance`` [px] (two reflections on one ball) into one."""
    out = list(blobs)
    merged = True
    while merged:
        merged = False
        for i in range(len(out)):
            for j in range(i + 1, len(out)):
                a, b = out[i], out[j]
                if math.hypot(a["x"] - b["x"], a["y"] - b["y"]) < distance:
                    out[i] = {"x": 0.5 * (a["x"] + b["x"]), "y": 0.5 * (a["y"] + b["y"]),
                              "area": a["area"] + b["area"],
                              "contrast": max(a["contrast"], b["contrast"]), "merged": True}
                    del out[j]
                    merged = True
                    break
            if merged:
                break
    return out


def bright_candidates(frame: np.ndarray, *, dark: bool = False, r_min: float = 2.0,
                      r_max: float = 12.0, ball_reflections: int = 1, fraction: float = 0.25
                      ) -> list[dict]:
    """The marker candidates of :func:`detect_blobs`, a ball's two reflections (closer than
    14 px, with ``ball_reflections`` 2) merged into one candidate at their mean."""
    found = detect_blobs(frame, dark=dark, r_min=r_min, r_max=r_max, fraction=fraction)
    return _merge_reflections(found, 14.0) if ball_reflections == 2 else found


#: The ball's body is taken as the third marker where it stands out of the frame's spread of
#: the disk-averaged |frame - background| by this robust z (median, 1.4826 MAD) ...
BODY_Z = 15.0
#: ... and every other such disk stays below this share of it (an unambiguous ball).
BODY_SECOND = 0.5


def ball_body(frame: np.ndarray, known: list[tuple[float, float]], r_max: float = 12.0,
              background: np.ndarray | None = None) -> dict | None:
    """The ball found by its body where its reflections are too faint to be a bright blob.

    A brass ball under diffuse light mirrors dark surroundings: its body is darker than the
    plane, its reflections small and dim (``twin.lighting_alt``: 20 % of the unseen two-spot
    recordings of seeds 11000-11039 showed only the centre and CD markers as bright blobs).
    Dark body or bright, the ball is where |frame - background| is large over a whole disk:
    the Gaussian-smoothed frame minus its median background (as :func:`detect_blobs`), its
    absolute value averaged over a disk of radius r_max / 2, the two markers found masked
    (2 r_max around each). The peak is taken if it stands BODY_Z robust sigmas out of the
    frame's own spread of that average and no other disk reaches BODY_SECOND of it (measured
    on those recordings: the ball at z 32-91, the next disk at 4-7). ``background``: the
    scene without the ball [grey levels] where known (the record's temporal median,
    :mod:`measurement.imaging.finder_stack`), instead of the frame's spatial median. Returns a
    candidate dict (``body``: True) or None.
    """
    import cv2

    f = cv2.GaussianBlur(np.asarray(frame).astype(np.float32), (0, 0), 1.0)
    if background is not None:
        bg = cv2.GaussianBlur(np.asarray(background).astype(np.float32), (0, 0), 1.0)
    else:
        k = int(4 * r_max + 1) | 1
        k_max = min(f.shape) if min(f.shape) % 2 else min(f.shape) - 1
        k = max(3, min(k, k_max))
        bg = cv2.medianBlur(np.clip(f, 0, 255).astype(np.uint8), k).astype(np.float32)
    r = 0.5 * r_max
    n = int(2 * r) + 3
    yy, xx = np.mgrid[:n, :n] - (n - 1) / 2.0
    disk = (np.hypot(xx, yy) <= r).astype(np.float32)
    e = cv2.filter2D(np.abs(f - bg), -1, disk / disk.sum())
    for x, y in known:
        cv2.circle(e, (int(round(x)), int(round(y))), int(2 * r_max), 0.0, -1)
    med = float(np.median(e))
    mad = 1.4826 * float(np.median(np.abs(e - med)))
    if not mad > 0:
        return None
    y0, x0 = np.unravel_index(int(np.argmax(e)), e.shape)
    peak = (float(e[y0, x0]) - med) / mad
    rest = e.copy()
    cv2.circle(rest, (int(x0), int(y0)), int(2 * r_max), 0.0, -1)
    second = (float(rest.max()) - med) / mad
    if peak < BODY_Z or second > BODY_SECOND * peak:
        return None
    # the centre of the disk's energy about the peak (sub-pixel)
    h = int(r) + 2
    ys, xs = slice(max(0, y0 - h), y0 + h + 1), slice(max(0, x0 - h), x0 + h + 1)
    w = np.maximum(e[ys, xs] - med, 0.0)
    gy, gx = np.mgrid[ys, xs]
    return {"x": float((w * gx).sum() / w.sum()), "y": float((w * gy).sum() / w.sum()),
            "area": float(math.pi * r * r), "contrast": float(e[y0, x0]), "body": True}


def away_px(blob: dict, r_max: float) -> float:
    """Distance [px] beyond which a fainter candidate is not part of ``blob``: 2 ``r_max``,
    or 3 of the blob's equivalent radii plus 4 px where smaller (its blur tail and, for a
    ball, its rim around the highlight)."""
    return min(2.0 * r_max, 3.0 * math.sqrt(blob["area"] / math.pi) + 4.0)


def find_markers(frame: np.ndarray, dark: bool = False, *, geometry=None, window: int = 30,
                 r_min: float = 2.0, r_max: float = 12.0, ball_reflections: int = 1,
                 background: np.ndarray | None = None) -> tuple[np.ndarray, list[str]]:
    """Find the ABU centre, CD and ball markers in one frame (see the module doc for the rule).

    Args:
        frame: (H, W) uint8 image (usually frame 0).
        dark: markers darker than the background.
        geometry: optional :class:`twin.render.CameraGeometry` (or anything with
            ``l_px`` and ``r_cd_px`` [px]) giving the expected marker radii.
        window: tracking window [px], used for the sub-pixel refinement.
        r_min, r_max: plausible marker radii [px].
        ball_reflections: 2 when the ball shows two reflections (two-spot lighting): candidates
            closer than 14 px are merged into one ball candidate at their mean.
        background: the scene without the ball, for :func:`ball_body` (None: the frame's
            spatial median).

    Returns:
        seeds (3, 2) [px] in the order centre, CD, ball, and the role names.

    Raises:
        MarkerError: not exactly three candidates, or the rule cannot tell them apart; the
            message lists the candidates and asks for ``--seeds``.
    """
    img = np.asarray(frame)

    def candidates(fraction: float, largest: float = r_max) -> list[dict]:
        return bright_candidates(img, dark=dark, r_min=r_min, r_max=largest,
                                 ball_reflections=ball_reflections, fraction=fraction)

    blobs = candidates(0.25)
    if len(blobs) < 3:
        # A saturated ball's highlight (contrast ~200) puts a quarter of it above a paper
        # marker dimmed by vignetting at the frame's edge (rendered seed 149: the CD marker's
        # contrast ~50): look again at a tenth, keeping the candidates found first and adding
        # only those away from them: 2 r_max, or less about a smaller marker (a farther
        # camera: at half our magnification the 2.5 px ball passes 19 px from the centre
        # marker) by the size it was found with.
        known = [(b["x"], b["y"], away_px(b, r_max)) for b in blobs]
        blobs += [b for b in candidates(0.1)
                  if all(math.hypot(b["x"] - x, b["y"] - y) > r for x, y, r in known)]
    if len(blobs) == 2 and ball_reflections == 2 and not dark:
        body = ball_body(img, [(b["x"], b["y"]) for b in blobs], r_max, background)
        if body is not None:
            blobs.append(body)
    try:
        return _roles(img, blobs, dark, geometry, window)
    except MarkerError:
        # Where the first look does not decide, look again, and take the first look that makes
        # three markers whose roles the rule decides:
        # * at a tenth: paper markers whose contrast is near a quarter of a saturated ball's
        #   cross that threshold only at their brightest pixels, in fragments, or not at all
        #   (rendered seed 5001 at twice our magnification: the centre marker in two pieces,
        #   the CD marker missing); their whole disks stand above a tenth;
        # * with markers up to twice r_max: a camera twice as close makes the largest centre
        #   markers 14 px in radius (seeds 5096, 6033 at 2x: 685 px^2, above r_max's bound).
        for fraction, largest in ((0.1, r_max), (0.25, 2 * r_max), (0.1, 2 * r_max)):
            again = candidates(fraction, largest)
            if len(again) == 3:
                try:
                    return _roles(img, again, dark, geometry, window)
                except MarkerError:
                    pass
        raise


def _roles(img: np.ndarray, blobs: list[dict], dark: bool, geometry, window: int
           ) -> tuple[np.ndarray, list[str]]:
    """The candidates' refined centres in the order centre, CD, ball (the module doc's rule);
    MarkerError, listing them, where they are not three or the rule does not decide."""
    hint = " Give the positions with --seeds 'x,y;x,y;x,y' (ABU centre; CD marker; ball) [px]."
    listing = "; ".join(f"({b['x']:.1f}, {b['y']:.1f}) contrast {b['contrast']:.0f}"
                        for b in blobs[:8])
    if len(blobs) != 3:
        raise MarkerError(f"found {len(blobs)} marker candidates, expected 3"
                          f"{': ' + listing if blobs else ''}.{hint}")
    _refine(img, [b for b in blobs if not (b.get("merged") or b.get("body"))], dark, window)
    p = np.array([[b["x"], b["y"]] for b in blobs])
    d = np.hypot(p[:, None, 0] - p[None, :, 0], p[:, None, 1] - p[None, :, 1])
    if geometry is not None:
        l_px, rcd_px = float(geometry.l_px), float(geometry.r_cd_px)
        best, best_cost, second = None, math.inf, math.inf
        for c in range(3):
            o = [i for i in range(3) if i != c]
            for ball, cd in (o, o[::-1]):
                cost = (d[c, ball] - l_px) ** 2 + (d[c, cd] - rcd_px) ** 2
                if cost < best_cost:
                    best, best_cost, second = (c, cd, ball), cost, best_cost
                elif cost < second:
                    second = cost
        tol = 0.15 * max(l_px, rcd_px)
        if best_cost > (2 * tol) ** 2 or second < 4 * best_cost:
            raise MarkerError(f"the marker distances do not match l = {l_px:.1f} px and r_cd = "
                              f"{rcd_px:.1f} px unambiguously: {listing}.{hint}")
        order = best
    else:
        h, w = img.shape
        dc = np.hypot(p[:, 0] - (w - 1) / 2.0, p[:, 1] - (h - 1) / 2.0)
        rank = np.argsort(dc)
        if dc[rank[0]] >= 0.5 * dc[rank[1]]:
            raise MarkerError("cannot tell which marker is the ABU centre: none is clearly nearest "
                              f"the image centre: {listing}.{hint}")
        c = int(rank[0])
        o = [i for i in range(3) if i != c]
        ball, cd = (o[0], o[1]) if d[c, o[0]] < d[c, o[1]] else (o[1], o[0])
        if d[c, ball] > 0.8 * d[c, cd]:
            raise MarkerError("cannot tell the ball from the CD marker: their distances to the "
                              f"centre marker ({d[c, ball]:.1f} and {d[c, cd]:.1f} px) are too "
                              f"close: {listing}.{hint}")
        order = (c, cd, ball)
    return p[list(order)], list(ROLES)
