"""A rolling shutter's marker positions brought back to the frame times
(:mod:`measurement.imaging.rolling_shutter`).

The truth is the twin's plant: for seeds of the harsh family (``twin.scenario``) each marker is
placed where the plant had it when its row was read (``rolling_shutter_positions``: rows over a
whole frame interval, top first, and bottom first), plus 0.02 px of white tracking noise. The
module sees only the noisy positions and the line time. Printed per seed: theta and beta RMS
errors [rad] of the raw rolling-shutter tracks, the corrected ones and the global shutter's
with the same noise.
"""
from __future__ import annotations

import numpy as np
import pytest

from abu_model.errors import ParameterError
from measurement.imaging.rolling_shutter import positions_at_frame_times
from measurement.imaging.tracks_io import angles_from_pixels
from twin.scenario import random_scenario, rolling_shutter_positions, simulate_scenario

SEEDS = (5000, 5001, 5002, 5003, 5004, 5005)
KEYS = ("centre", "cd", "ball")


def _xy(pos: dict) -> tuple[np.ndarray, np.ndarray]:
    return (np.stack([pos[k][:, 0] for k in KEYS], 1), np.stack([pos[k][:, 1] for k in KEYS], 1))


def _rms(a: np.ndarray) -> float:
    return float(np.std(a))


@pytest.mark.parametrize("readout", [1.0, -1.0])
def test_rolling_shutter_positions_corrected_to_the_tracking_noise(readout):
    for seed in SEEDS:
        scn = random_scenario(seed, n_frames=1500)
        state, pos = simulate_scenario(scn)
        if readout > 0:
            rolled = rolling_shutter_positions(scn, state, pos, readout)
        else:   # bottom row first: row y read at (H - 1 - y) / H of the read-out
            rows = {k: np.stack([v[:, 0], scn.height - 1 - v[:, 1]], 1) for k, v in pos.items()}
            rolled = rolling_shutter_positions(scn, state, rows, 1.0)
            # the top row, read last, sets the time the corrected positions refer to: the
            # truth there (a time shift common to all markers, harmless to mu)
            last = {k: np.full_like(v, scn.height - 1.0) for k, v in pos.items()}
            pos = rolling_shutter_positions(scn, state, last, 1.0)
        x0, y0 = _xy(pos)
        xr, yr = _xy(rolled)
        rng = np.random.default_rng(seed)
        nx, ny = rng.normal(0, 0.02, xr.shape), rng.normal(0, 0.02, xr.shape)
        line_time = readout / scn.fps / scn.height
        xc, yc = positions_at_frame_times(scn.times, xr + nx, yr + ny, line_time)
        th0, b0 = angles_from_pixels(x0, y0)
        th_g, b_g = angles_from_pixels(x0 + nx, y0 + ny)       # a global shutter, same noise
        th_r, b_r = angles_from_pixels(xr + nx, yr + ny)
        th_c, b_c = angles_from_pixels(xc, yc)
        g, r, c = ((_rms(th - th0), _rms(b - b0)) for th, b in
                   ((th_g, b_g), (th_r, b_r), (th_c, b_c)))
        print(f"seed {seed} read-out {readout:+.0f}: theta / beta RMS [rad] raw "
              f"{r[0]:.2e} / {r[1]:.2e}, corrected {c[0]:.2e} / {c[1]:.2e}, global shutter "
              f"{g[0]:.2e} / {g[1]:.2e}")
        assert r[0] > 5 * g[0]                      # the effect is there, and large
        assert c[0] < 1.1 * g[0] and c[1] < 1.1 * g[1]
        assert np.abs((th_c - th0) - (th_g - th0)).max() < 5e-4   # no once-per-turn residue


def test_global_shutter_unchanged_and_an_impossible_read_out_refused():
    t = np.arange(200) / 4500.0
    x = np.tile([128.0, 228.0, 166.0], (200, 1))
    y = np.tile([128.0, 28.0, 128.0], (200, 1)) + np.linspace(0, 200, 200)[:, None] * [0, 1, 0]
    xc, yc = positions_at_frame_times(t, x, y, 0.0)
    assert np.array_equal(xc, x) and np.array_equal(yc, y)
    with pytest.raises(ParameterError, match="line_time_s"):
        positions_at_frame_times(t, x, y, 2.0 / 4500.0 / 200.0)   # 400 rows > an interval
    with pytest.raises(ParameterError, match="line_time_s"):
        positions_at_frame_times(t, x, y, float("nan"))


def test_abu_measure_line_time_brings_the_tracks_to_the_frame_times(tmp_path):
    """``abu measure --tracks --line-time S``: theta as analysed is the global shutter's (with
    the same noise) to within the noise, without the option it carries the read-out's error;
    the line time is recorded in summary.json."""
    from abu.cli.main import main
    scn = random_scenario(5006, n_frames=3072)
    state, pos = simulate_scenario(scn)
    rng = np.random.default_rng(5006)
    x0, y0 = _xy(pos)
    nx, ny = rng.normal(0, 0.02, x0.shape), rng.normal(0, 0.02, x0.shape)
    xr, yr = _xy(rolling_shutter_positions(scn, state, pos, 1.0))
    rows = ["time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"] + [
        f"{t:.9f}," + ",".join(f"{v:.6f}" for v in np.ravel(np.c_[xi, yi]))
        for t, xi, yi in zip(scn.times, xr + nx, yr + ny)]
    csv = tmp_path / "tracks.csv"
    csv.write_text("\n".join(rows) + "\n")
    line_time = 1.0 / scn.fps / scn.height
    theta_global, _ = angles_from_pixels(x0 + nx, y0 + ny)
    errors = {}
    for name, extra in (("corrected", ["--line-time", repr(line_time)]), ("raw", [])):
        out = tmp_path / name
        assert main(["measure", str(csv), "--tracks", "--out", str(out), "--no-plots",
                     "--quiet", "--l", repr(scn.ball.l),
                     "--d", repr(scn.ball.d), *extra]) == 0
        summary = __import__("json").loads((out / "summary.json").read_text())
        assert summary["input"].get("line_time_s") == (line_time if extra else None)
        table = np.genfromtxt(out / "kinematics.csv", delimiter=",", names=True)
        errors[name] = _rms(table["theta_rad"] - theta_global)
    th_noise = _rms(theta_global - angles_from_pixels(x0, y0)[0])
    print(f"theta vs the global shutter's [rad]: corrected {errors['corrected']:.2e}, raw "
          f"{errors['raw']:.2e} (the noise itself {th_noise:.2e})")
    assert errors["corrected"] < th_noise and errors["raw"] > 5 * th_noise


def test_the_line_time_option_is_checked():
    from measurement.inference.options import AnalysisOptions
    for bad in (float("nan"), float("inf"), 0.01, -1.0, "1e-6", True):
        with pytest.raises(ParameterError, match="line_time_s"):
            AnalysisOptions(line_time_s=bad)
    assert AnalysisOptions(line_time_s=-2e-7).line_time_s == -2e-7
