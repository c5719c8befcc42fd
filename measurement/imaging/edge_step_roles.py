"""Which markers the command line's tracker ends with the edge step by default
(:mod:`measurement.imaging.edge_step`), and tracking with the step on some markers only."""
from __future__ import annotations

import numpy as np

from measurement.imaging import tracking as T


def edge_step_default(ball_reflections: int) -> tuple[bool, bool, bool]:
    """Which markers (centre, CD, ball) the command line's tracker ends with the edge step
    (:mod:`measurement.imaging.edge_step`) when the user says neither ``--edge-step`` nor
    ``--no-edge-step``: the centre and CD paper disks with one reflection on the ball; never
    the ball; nothing with two reflections.

    The step's model is a uniform disk with a blurred edge: what a paper marker is. The
    brass ball's image is its highlight (a ring-shaped or round spot that fades outwards) or,
    with two reflections, its outline: on the harsh twin's one-reflection recordings the step
    raised the ball's frame-to-frame noise from 0.039 to 0.056 px (medians, 10 of 10 seeds
    1001-1013) while leaving the paper markers' as they were (0.024 / 0.039 px). With two
    reflections the ball's outline error (0.04-0.33 px RMS, median 0.10) dominates beta and the
    step hardly changes the paper markers (33 recordings: 0.0256 -> 0.0253 px and 0.0366 ->
    0.0354 px RMS, better in about half); on the unseen seeds 3000-3099 it moved two of their
    intervals off mu (3011: missed by 16.8 -> 40.0 %, 3038: held -> missed by 27.1 %;
    docs/measurement-imaging.md, "Where it is the default"), so it stays off there."""
    one = ball_reflections == 1
    return (one, one, False)


def track_by_step(frames: np.ndarray, seeds: np.ndarray, steps: tuple[bool, ...], *,
                  method: str, window: int, dark: bool, progress: bool) -> "T.Tracks":
    """:func:`tracking.track_recording` with the edge step on the markers ``steps`` names:
    one call per setting (the markers are tracked independently: the same positions as one
    call), the columns in the seeds' order."""
    groups = [[m for m, s in enumerate(steps) if s == on] for on in (True, False)]
    parts = {on: T.track_recording(frames, seeds[idx], method=method, window=window, dark=dark,
                                   progress=progress, options=T.TrackingOptions(edge_step=on))
             for on, idx in zip((True, False), groups) if idx}
    pos = {m: (on, k) for on, idx in zip((True, False), groups) for k, m in enumerate(idx)}

    def column(name: str) -> np.ndarray:
        return np.column_stack([getattr(parts[pos[m][0]], name)[:, pos[m][1]]
                                for m in range(len(steps))])

    first = parts[steps[0]]
    return T.Tracks(x=column("x"), y=column("y"), lost=column("lost"), reason=column("reason"),
                    radius=column("radius"), method=method, window=first.window, dark=bool(dark),
                    options=first.options,
                    edge_step_markers=tuple(bool(on) and method == "isocontour" for on in steps))
