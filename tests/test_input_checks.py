"""measurement.kinematics.input_checks on a broad family of records: valid ones pass, still or swapped refused.

Family: the exact stick/slip plant (tests/synthetic_tracks.py) with mu in {0.01, 0.02, 0.05, 0.3}
(0.3: the ball never slips), ramp and staircase-like drives, tracking noise 0.05 px, lighting
harmonic 0, 0.4 and 1 px, three noise seeds: 72 records. Printed with ``pytest -s``.
"""
from __future__ import annotations

import numpy as np
import pytest

from abu_model.errors import AbuError, ParameterError
from measurement.kinematics.input_checks import check_motion_and_roles, check_sampling

from synthetic_tracks import measured_pixels, simulate


def _swap(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    xs, ys = x.copy(), y.copy()
    xs[:, [1, 2]] = xs[:, [2, 1]]
    ys[:, [1, 2]] = ys[:, [2, 1]]
    return xs, ys


def test_role_check_on_a_family_of_records():
    refused_valid, swapped_slipping, caught = 0, 0, 0
    n = 0
    for mu in (0.01, 0.02, 0.05, 0.3):
        for kind in ("ramp", "steps"):
            rec = simulate(mu, kind, n=1500)
            slipped_by = float(np.ptp(rec.beta))  # how far the ball moved on the rim [rad]
            for seed in range(3):
                for harmonic in (0.0, 0.4, 1.0):
                    x, y = measured_pixels(rec, sigma_px=0.05, harmonic_px=harmonic, seed=seed)
                    n += 1
                    try:
                        check_motion_and_roles(rec.time, x, y, "record")
                    except AbuError:
                        refused_valid += 1
                    if slipped_by > 0.02:
                        swapped_slipping += 1
                        try:
                            check_motion_and_roles(rec.time, *_swap(x, y), "record")
                        except AbuError as exc:
                            caught += 1
                            assert "swapped" in str(exc)
    print(f"\nrole check: {n} valid records, {refused_valid} refused; swapped roles in the "
          f"{swapped_slipping} records whose ball slips by > 0.02 rad: {caught} refused")
    assert refused_valid == 0
    assert swapped_slipping >= 18 and caught == swapped_slipping


def test_still_markers_are_refused_and_a_slow_abu_passes():
    rec = simulate(0.02, "steps", n=1500)
    x, y = measured_pixels(rec, sigma_px=0.05, seed=0)
    still_x = np.repeat(x[:1], len(x), axis=0)
    still_y = np.repeat(y[:1], len(y), axis=0)
    with pytest.raises(AbuError, match="hardly turns"):
        check_motion_and_roles(rec.time, still_x, still_y, "record")
    check_motion_and_roles(rec.time, x, y, "record")


@pytest.mark.parametrize("fps,ok", [(4500.0, True), (1000.0, True), (240.0, False),
                                    (45.0, False)])
def test_sampling_limits(fps, ok):
    time = np.arange(3000) / fps
    kwargs = dict(fps_option="--fps", sg_window_s=0.02, polyorder=3, estimator="savgol",
                  trim_s=None)
    if ok:
        check_sampling(time[: int(0.6 * fps)], "--fps", **kwargs)
    else:
        with pytest.raises(ParameterError, match="--fps"):
            check_sampling(time, "--fps", **kwargs)


def test_time_in_ms_names_the_file():
    time_ms = np.arange(3000) / 4500.0 * 1e3
    with pytest.raises(AbuError, match=r"tracks\.csv.*ms instead of s"):
        check_sampling(time_ms, "tracks.csv", fps_option="--fps", sg_window_s=0.02,
                       polyorder=3, estimator="savgol", trim_s=None)


def test_a_dropped_or_repeated_frame_is_refused_a_glitch_or_a_stated_gap_is_not():
    """The time base: on the family above (72 records, none refused: the first test), one
    frame taken out of the frames (the times left evenly spaced, as a TIFF gives them) or one
    frame given twice is refused naming the frames; the same gap stated in the times (a tracks
    CSV with the true times) passes, and so does a CD marker mislocated by a whole step in one
    frame (a tracking glitch: the next step makes up for it)."""
    caught, n = 0, 0
    for mu in (0.01, 0.05):
        for kind in ("ramp", "steps"):
            rec = simulate(mu, kind, n=1500)
            for seed in range(3):
                x, y = measured_pixels(rec, sigma_px=0.05, harmonic_px=0.4, seed=seed)
                at = 300 + 250 * seed
                keep = np.r_[0:at, at + 1:x.shape[0]]
                # dropped: the frames after it keep the even time base
                for xs, ys, word in ((x[keep], y[keep], "dropped"),
                                     (np.insert(x, at, x[at], axis=0),
                                      np.insert(y, at, y[at], axis=0), "repeated")):
                    n += 1
                    even = rec.time[0] + np.arange(xs.shape[0]) * (rec.time[1] - rec.time[0])
                    first = at - 1 if word == "dropped" else at
                    with pytest.raises(AbuError, match=rf"frames {first} and .*{word}"):
                        check_motion_and_roles(even, xs, ys, "record")
                    caught += 1
                check_motion_and_roles(rec.time[keep], x[keep], y[keep], "record")   # stated
                xg, yg = x.copy(), y.copy()
                step = np.hypot(*(np.array([x[at + 1, 1] - x[at, 1], y[at + 1, 1] - y[at, 1]])))
                r = np.hypot(x[at, 1] - x[at, 0], y[at, 1] - y[at, 0])
                c, s = np.cos(step / r), np.sin(step / r)   # the CD marker one step further on
                dx, dy = xg[at, 1] - xg[at, 0], yg[at, 1] - yg[at, 0]
                xg[at, 1], yg[at, 1] = xg[at, 0] + c * dx + s * dy, yg[at, 0] - s * dx + c * dy
                check_motion_and_roles(rec.time, xg, yg, "record")
    print(f"time base: {caught} of {n} dropped or repeated frames refused")
    assert caught == n


def test_time_base_check_is_quiet_over_a_still_stretch():
    """A CD marker held still for 50 frames, then a single step, then turning: the running
    median is 0 there, the ratios infinite; no NumPy warning escapes (a run with warnings as
    errors stopped inside the check) and nothing is called a dropped frame."""
    import warnings

    from measurement.kinematics.input_checks import _check_time_base
    t = np.arange(200) / 4500.0
    theta = np.r_[np.zeros(50), 0.01, np.full(49, 0.01), 0.01 + np.cumsum(np.full(100, 0.01))]
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        _check_time_base(t, theta, "still.csv")
