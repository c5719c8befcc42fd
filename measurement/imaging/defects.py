"""Defective sensor pixels (stuck bright, hot or dead), found and replaced before tracking.

High-speed camera sensors have pixels that stay bright or dark whatever the scene; cameras
map most of them out, not all. One such pixel in a marker's tracking window sets the window's
largest (or smallest) grey level, so the seeded pass's threshold (the midpoint of the two)
leaves the marker out and its centroid falls on the pixel: on harsh-twin recordings with 30
pixels stuck at 255 (0.05 % of 256x256), 4 of 8 lost the CD marker for good and were refused.

Found on the per-pixel median of :data:`SAMPLE_FRAMES` frames spread over the recording: the
moving CD marker and ball pass any pixel in few of them and vanish from it; what stays is the
background and the static centre marker, a blurred disk. A defect is a pixel of that median
image that lies more than :data:`THRESHOLD` grey levels above the third brightest of its 8
neighbours (or below the third darkest): on an edge or inside a disk (radius >= 2.5 px) at
least three neighbours are about as bright as the pixel, and the optics blur a real point
over several pixels. The third, not the brightest, so that stuck pixels side by side (a
pair, a column of three: sensors have such clusters) are found too: against every
neighbour two adjacent ones hid each other (``benchmarks/bench_off_family.py``, variant
hotpix, seed 20001: the ball lost in its first 627 frames). The median of the neighbours
would also take the rim of a small static disk for defects. In every frame a defect is
replaced by the median of its 8 neighbours. The frame's outermost pixels are left as they are
(no tracking window reaches them).
"""
from __future__ import annotations

import numpy as np

from measurement.imaging.static_scene import static_scene

#: Frames whose per-pixel median the defects are found on [-] (~11 ms of CPU for 256x256 px;
#: a moving marker covers a pixel in far fewer than half of them).
SAMPLE_FRAMES = 15
#: Least excess over the CLUSTER-th brightest of the 8 neighbours (or deficit under the
#: CLUSTER-th darkest) of a defect [grey levels].
THRESHOLD = 40
#: Stuck neighbours a defect may have (a pair, a column of three) [-], plus one.
CLUSTER = 3

_NEIGHBOURS = ((-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1))


def find_defects(frames: np.ndarray) -> np.ndarray:
    """(row, column) [px] of the defective pixels of an (N, H, W) uint8 stack, shape (D, 2)."""
    n, h, w = frames.shape
    if h < 3 or w < 3:
        return np.zeros((0, 2), dtype=np.int64)
    med = static_scene(frames, SAMPLE_FRAMES).astype(np.int16)
    core = med[1:-1, 1:-1]
    around = np.stack([med[1 + dy:h - 1 + dy, 1 + dx:w - 1 + dx] for dy, dx in _NEIGHBOURS])
    ranked = np.sort(around, axis=0)
    hot = core - ranked[-CLUSTER] > THRESHOLD
    dead = ranked[CLUSTER - 1] - core > THRESHOLD
    return np.argwhere(hot | dead) + 1


def replace_defects(frames: np.ndarray, defects: np.ndarray) -> np.ndarray:
    """A copy of ``frames`` with each defect replaced by the median of its 8 neighbours."""
    out = np.array(frames)  # a memory-mapped recording stays untouched
    if len(defects) == 0:
        return out
    rows, cols = defects[:, 0], defects[:, 1]
    around = np.stack([frames[:, rows + dy, cols + dx] for dy, dx in _NEIGHBOURS], axis=-1)
    out[:, rows, cols] = np.median(around, axis=-1).round().astype(out.dtype)
    return out


def correct_defects(frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(frames with the defects replaced, the defects' (row, column) [px]); the frames are
    returned as given (not copied) when there is none."""
    defects = find_defects(frames)
    if len(defects) == 0:
        return frames, defects
    return replace_defects(frames, defects), defects


__all__ = ["SAMPLE_FRAMES", "THRESHOLD", "CLUSTER", "find_defects", "replace_defects", "correct_defects"]
