"""Checks of a measurement's inputs before the analysis: what the method can stand behind.

The analysis (:mod:`measurement.inference.analysis`) computes a number from almost any array. These checks
refuse, with a message naming the option or the file, the inputs it would silently get wrong:

* **sampling**: the frame rate must put enough samples into the Savitzky-Golay window and at
  least one into each 5 ms knot interval of the monotone beta fit; the record must be short
  enough for that fit (its matrix grows with the square of the knot count: a tracks file with
  the time in ms asked for 139 GiB);
* **trim**: ``--trim-s`` must leave a trusted region;
* **motion**: the CD marker must turn (the normal force is m l omega^2: a still ABU makes any
  friction look infinite);
* **time base**: the ABU's inertia cannot double or stop its turn for one frame; a single step
  of the CD marker's angle that is a whole multiple (>= 2) or none of its neighbours' while
  those are normal is a dropped or a repeated frame (a TIFF or a folder records no frame
  times), which the analysis would take as a speed spike and widen mu's interval to nothing
  (one frame dropped from a 3072-frame render: [0, 0.24] for mu = 0.024);
* **roles**: friction can only drag the ball after the disc, so while the ABU accelerates the
  ball may lag behind the CD marker, never run ahead of it; a "ball" that runs ahead of the
  "CD marker" means the two are swapped (seed order or CSV columns).
"""
from __future__ import annotations

import math

import numpy as np

from abu_model.errors import AbuError, ParameterError

#: Knot spacing of the monotone beta fit [s] (AnalysisOptions.knot_spacing_s default).
KNOT_SPACING_S = 0.005
#: Knots of the monotone beta fit held as a dense matrix: 4000^2 doubles = 128 MB.
MAX_KNOTS = 4000
#: Slowest mean ABU speed accepted [rad/s] (0.5 Hz; the report's experiments run at 9-22 Hz).
MIN_MEAN_SPEED = math.pi
#: Net change of beta [rad] above which its sign is trusted for the role check (tracking noise
#: ~3e-4 rad per frame, averaged over a revolution; a slip moves beta by 1e-2 to 3e-1 rad).
MIN_BETA_CHANGE = 4e-3


#: Frames either side in the running median of the CD marker's speed (the time-base check).
STEP_MEDIAN_HALF = 8
#: How close a step's ratio to its neighbours' must come to a whole number to read as frames
#: dropped (2, 3, ...) or repeated (0), and its neighbours' to 1 [-].
STEP_RATIO_SLACK = 0.25
#: ... and how far above the speed's frame-to-frame noise it must stand [robust sigmas].
STEP_NOISE_SIGMAS = 10.0


class MeasurementInputError(AbuError, ValueError):
    """The marker tracks contradict what the method assumes (still ABU, swapped markers)."""


def check_sampling(time: np.ndarray, source: str, *, fps_option: str, sg_window_s: float,
                   polyorder: int, estimator: str, trim_s: float | None,
                   knot_spacing_s: float = KNOT_SPACING_S, rate_from: str | None = None) -> None:
    """Frame rate, record length and trim against what the estimators need.

    Args:
        time: frame times [s].
        source: the option or file the times come from (``--fps`` or the tracks file).
        fps_option: how to name the frame rate in a message.
        rate_from: for a recording whose file states the rate, where it states it (then the
            times are not a time column).
    """
    n = time.size
    duration = float(time[-1] - time[0]) if n > 1 else 0.0
    dt = float(np.median(np.diff(time))) if n > 1 else math.inf
    fps = 1.0 / dt if dt > 0 else math.inf

    def fail(expected: str) -> None:
        if source == fps_option:
            raise ParameterError(fps_option, float(f"{fps:.12g}"), expected)
        if rate_from is not None:
            raise MeasurementInputError(f"{source}: its frame rate ({rate_from}) gives "
                                        f"{fps:.6g} frames/s and {duration:.4g} s; expected "
                                        f"{expected} (or give the rate with {fps_option})")
        raise MeasurementInputError(f"{source}: its time column gives {fps:.6g} frames/s and "
                                    f"{duration:.4g} s; expected {expected} (time in ms instead "
                                    "of s?)")

    if estimator == "savgol":
        need = polyorder + 2
        if sg_window_s * fps < need:
            fail(f"a frame rate that puts at least {need} frames into the --sg-window-s = "
                 f"{sg_window_s:g} s window (it holds {sg_window_s * fps:.3g})")
    if fps * knot_spacing_s < 1.0:
        fail(f"at least {1 / knot_spacing_s:g} frames/s (the fit of beta has a knot every "
             f"{knot_spacing_s * 1e3:g} ms)")
    if duration / knot_spacing_s > MAX_KNOTS:
        fail(f"a record of at most {MAX_KNOTS * knot_spacing_s:g} s (one knot of the beta fit "
             f"per {knot_spacing_s * 1e3:g} ms, at most {MAX_KNOTS} knots); it lasts "
             f"{duration:.4g} s")
    if trim_s is not None and 2.0 * trim_s >= 0.8 * duration:
        raise ParameterError("--trim-s", trim_s,
                             f"a time [s] that leaves most of the {duration:.4g} s record "
                             f"trusted (2 x --trim-s < {0.8 * duration:.4g} s)")


def _angles(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    from measurement.imaging.tracks_io import angles_from_pixels
    return angles_from_pixels(x, y)


def _end_windows(theta: np.ndarray) -> tuple[slice, slice] | None:
    """The first and the last full revolution of theta; None if it turns less than twice."""
    n = theta.size
    turned = np.abs(theta - theta[0])
    if not turned[-1] >= 4 * math.pi:
        return None
    k1 = int(np.searchsorted(np.maximum.accumulate(turned), 2 * math.pi))
    back = np.maximum.accumulate(np.abs(theta[-1] - theta[::-1]))
    k2 = int(np.searchsorted(back, 2 * math.pi))
    return slice(0, max(k1, 3)), slice(n - max(k2, 3), n)


def _check_time_base(time: np.ndarray, theta: np.ndarray, source: str) -> None:
    """Refuse single-frame steps of the CD marker that read as dropped or repeated frames."""
    if theta.size < 4 * STEP_MEDIAN_HALF:
        return
    speed = np.diff(theta) / np.diff(time)           # [rad/s] per interval
    # running median over 2 h + 1 intervals, the ends repeated (scipy.ndimage.median_filter's
    # "nearest"; NumPy here: SciPy's import would cost abu measure ~0.2 s)
    h = STEP_MEDIAN_HALF
    padded = np.r_[np.full(h, speed[0]), speed, np.full(h, speed[-1])]
    typical = np.median(np.lib.stride_tricks.sliding_window_view(padded, 2 * h + 1), axis=1)
    dev = speed - typical
    sigma = 1.4826 * float(np.median(np.abs(dev - np.median(dev))))
    with np.errstate(divide="ignore", invalid="ignore"):   # a still stretch: typical 0
        ratio = speed / typical
        whole = np.rint(ratio)
        odd = (np.abs(ratio - whole) < STEP_RATIO_SLACK) & (whole != 1) & (whole >= 0) \
            & (np.abs(dev) > STEP_NOISE_SIGMAS * sigma)
        normal = np.abs(ratio - 1.0) < STEP_RATIO_SLACK
    odd[1:-1] &= normal[:-2] & normal[2:]             # neighbours normal: not a tracking glitch
    odd[[0, -1]] = False
    bad = np.flatnonzero(odd)
    if bad.size:
        i = int(bad[0])
        raise MeasurementInputError(
            f"{source}: between frames {i} and {i + 1} (t = {time[i]:.6g} s) the CD marker turned "
            f"{ratio[i]:.2f}x the step of the frames around ({bad.size} such step"
            f"{'s' if bad.size > 1 else ''}): a frame {'repeated' if whole[i] == 0 else 'dropped'}"
            "? The ABU cannot change its speed so in one frame, and the analysis takes the frames "
            "as evenly spaced: measure a recording without gaps (a camera file's image times are "
            "checked), or give a tracks CSV with the true times")


def check_motion_and_roles(time: np.ndarray, x: np.ndarray, y: np.ndarray, source: str) -> None:
    """The ABU turns, its frames are evenly spaced (no single-frame step a whole multiple or
    none of its neighbours'), and the ball never runs ahead of the CD marker while the ABU
    accelerates.

    Raises:
        MeasurementInputError: naming ``source`` (the recording or tracks file).
    """
    theta, beta = _angles(x, y)
    duration = float(time[-1] - time[0])
    mean_speed = abs(float(theta[-1] - theta[0])) / duration if duration > 0 else 0.0
    if not mean_speed >= MIN_MEAN_SPEED:
        raise MeasurementInputError(
            f"{source}: the CD marker hardly turns (mean speed {mean_speed / (2 * math.pi):.3g} "
            f"Hz over {duration:.4g} s; at least {MIN_MEAN_SPEED / (2 * math.pi):g} Hz): the "
            "normal force m l omega^2 vanishes and no bound on mu follows; are these markers "
            "on the rotating ABU?")
    _check_time_base(time, theta, source)
    # Mean speed and mean beta over the first and the last full revolution: whole turns average
    # out the lighting harmonic of beta (over a part of a turn it moved beta by 0.02 rad in the
    # twin). A record of less than two turns is not checked.
    windows = _end_windows(theta)
    if windows is None:
        return
    first, last = windows
    w_start = np.polyfit(time[first], theta[first], 1)[0]
    w_end = np.polyfit(time[last], theta[last], 1)[0]
    d_omega = w_end - w_start
    d_beta = float(np.mean(beta[last]) - np.mean(beta[first]))
    if abs(d_beta) > MIN_BETA_CHANGE and abs(d_omega) > 0 and np.sign(d_beta) == np.sign(d_omega):
        raise MeasurementInputError(
            f"{source}: the marker geometry contradicts the roles: the 'ball' moves {d_beta:+.3g} "
            f"rad relative to the 'CD marker' in the direction the ABU accelerates "
            f"({d_omega / (2 * math.pi):+.3g} Hz); friction can only make the ball lag. Are the CD "
            "and ball markers swapped (--seeds order: ABU centre; CD marker; ball, or the CSV "
            "columns x_cd,y_cd / x_ball,y_ball)?")
