"""The scene without what moves: the per-pixel median of frames spread over a recording."""
from __future__ import annotations

import numpy as np


def static_scene(frames: np.ndarray, count: int) -> np.ndarray:
    """(H, W) float32 per-pixel median [grey levels] of ``count`` frames spread evenly over
    the (N, H, W) recording (all of them if fewer): the plane, the lamps' gradient, the
    static centre marker and any stuck pixel. The CD marker and the ball turn several times in
    a record, so each covers a given pixel in few of the frames and drops out of the median."""
    n = frames.shape[0]
    idx = np.unique(np.linspace(0, n - 1, min(n, count)).round().astype(np.int64))
    return np.median(np.asarray(frames[idx], np.float32), axis=0)


__all__ = ["static_scene"]
