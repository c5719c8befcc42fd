"""What to try when a marker is lost for too long: the hint ending the refusal's one line."""
from __future__ import annotations

import numpy as np

from measurement.imaging.window_fits import TOUCHES_EDGE


def lost_hint(reason: np.ndarray, lost: np.ndarray, seeds: np.ndarray, window_px: int,
              ball_reflections: int) -> str:
    """The hint ('' if none) for tracks whose reason codes (N, 3) and lost flags (N, 3) made
    a marker lost too long; seeds (3, 2) [px] in the order centre, CD, ball."""
    hint = ("; if the ball shows two reflections, use --ball-reflections 2"
            if ball_reflections == 1 and lost[:, 2].any() else "")
    # the ball passing inside the centre marker's window (a camera farther away than usual)
    # puts two blobs in both windows
    path_px = float(np.hypot(*(seeds[2] - seeds[0])))
    if path_px < 0.75 * window_px:
        return hint + (f"; the ball passes {path_px:.0f} px from the centre marker, inside "
                       f"--window {window_px} px: try --window {max(8, int(path_px))}")
    # most windows cutting a blob at their edge: a marker wider than the window (a closer one)
    codes = np.asarray(reason)[lost]
    if codes.size and np.mean(codes == TOUCHES_EDGE) > 0.5:
        hint += (f"; most lost windows cut a blob at their edge: markers may be too large "
                 f"for --window {window_px} px, try a larger one")
    return hint


__all__ = ["lost_hint"]
