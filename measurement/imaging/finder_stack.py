"""The marker finder on the first frames turned back onto frame 0: a faint ball found where one
frame shows only the ABU centre and the CD marker.

:func:`markers.find_markers` reads frame 0. A ball whose body and highlights stand only 1-2
noise sigma above the plane (``twin.lighting_alt`` faded, ``benchmarks/bench_coverage.py
--faint-two-spot``) is no blob there and its body's disk average is below
:data:`markers.BODY_Z`. But at the start of a record the ball is stuck: it turns with the CD.
So the first :data:`STACK_FRAMES` frames, each rotated about the centre marker by the CD
marker's angle since frame 0 (both tracked, :func:`tracking.track_recording`), show the ball
where it was in frame 0 with the noise ~sqrt(STACK_FRAMES) times lower, and the finder is run
again on their mean. Only for two-reflection balls when frame 0 shows exactly the two bright
markers (the case of a faint ball); everything else keeps frame 0's answer or error.
"""
from __future__ import annotations

import math

import numpy as np

from measurement.imaging import markers as M
from measurement.imaging import tracking as T
from measurement.imaging.static_scene import static_scene

#: Frames averaged (7 ms at 4500 frames/s: the ball is stuck at the start of a record).
STACK_FRAMES = 32
#: Frames, spread over the record, whose median is the scene without the ball.
SCENE_FRAMES = 63


def derotated_mean(frames: np.ndarray, centre: np.ndarray, cd: np.ndarray) -> np.ndarray:
    """Mean of ``frames`` [grey levels], each rotated and shifted so that its centre and CD
    markers ((K, 2) [px] per frame) sit where they are in the first: what turns with the CD
    stands still."""
    import cv2

    acc = np.zeros(frames.shape[1:], np.float64)
    a0 = math.atan2(cd[0, 1] - centre[0, 1], cd[0, 0] - centre[0, 0])
    for f, c, d in zip(frames, centre, cd):
        turn = math.atan2(d[1] - c[1], d[0] - c[0]) - a0
        # rotate by -turn about this frame's centre, then move it onto frame 0's centre
        m = cv2.getRotationMatrix2D((float(c[0]), float(c[1])), math.degrees(turn), 1.0)
        m[:, 2] += centre[0] - c
        acc += cv2.warpAffine(np.asarray(f, np.float32), m, (f.shape[1], f.shape[0]),
                              flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    return acc / len(frames)


def find_markers_stacked(frames: np.ndarray, *, dark: bool = False, ball_reflections: int = 1
                         ) -> tuple[np.ndarray, list[str], str]:
    """Seeds (3, 2) [px] of frame 0, their roles and where they were found (``frame 0`` or
    ``the first N frames turned back onto frame 0``); raises :class:`markers.MarkerError` as
    :func:`markers.find_markers` on frame 0 where the stack does not help."""
    first = np.asarray(frames[0])
    try:
        seeds, roles = M.find_markers(first, dark=dark, ball_reflections=ball_reflections)
        return seeds, roles, "found in frame 0"
    except M.MarkerError as err:
        k = min(STACK_FRAMES, frames.shape[0])
        two = _centre_and_cd(first)
        if dark or ball_reflections != 2 or k < 8 or two is None:
            raise
        try:
            tr = T.track_recording(np.asarray(frames[:k]), two)
        except T.TrackingError:
            raise err from None
        if tr.lost.any():
            raise err from None
        centre = np.column_stack([tr.x[:, 0], tr.y[:, 0]])
        cd = np.column_stack([tr.x[:, 1], tr.y[:, 1]])
        stack = np.asarray(frames[:k])
        mean = np.clip(np.rint(derotated_mean(stack, centre, cd)), 0, 255).astype(np.uint8)
        # the scene without the ball, turned as the frames were: the ball is what moves
        still = np.broadcast_to(static_scene(frames, SCENE_FRAMES), stack.shape)
        try:
            seeds, roles = M.find_markers(mean, ball_reflections=2,
                                          background=derotated_mean(still, centre, cd))
        except M.MarkerError:
            raise err from None
        return seeds, roles, f"found in the first {k} frames turned back onto frame 0"


def _centre_and_cd(frame: np.ndarray) -> np.ndarray | None:
    """(2, 2) [px]: the ABU centre (nearest the image centre) and the CD marker, where frame 0
    shows exactly two bright candidates; else None."""
    blobs = M.bright_candidates(frame, ball_reflections=2)
    if len(blobs) != 2:
        return None
    p = np.array([[b["x"], b["y"]] for b in blobs])
    h, w = frame.shape
    dc = np.hypot(p[:, 0] - (w - 1) / 2.0, p[:, 1] - (h - 1) / 2.0)
    return p[np.argsort(dc)]
