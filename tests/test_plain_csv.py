"""Every CSV the toolkit writes loads with ``pandas.read_csv(path)`` and ``csv.DictReader`` with
no options: no comment lines, the header first, units in the column names (issue 7, item 5).
pandas is an independent reader (C parser); each test also checks the values, not only names.
"""
from __future__ import annotations

import csv
import json

import numpy as np
import pandas as pd
import pytest

from abu.cli.main import main as measure_main
from measurement.imaging.tracks_io import OUTPUT_COLUMNS, read_tracks_csv

from synthetic_tracks import measured_pixels, simulate


def both_readers(path):
    frame = pd.read_csv(path)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(frame.columns) == list(rows[0].keys())
    assert len(frame) == len(rows)
    return frame, rows


@pytest.fixture(scope="module")
def measured(tmp_path_factory):
    rec = simulate(0.02, "steps", n=1500)
    x, y = measured_pixels(rec, sigma_px=0.02, harmonic_px=0.3, seed=4)
    folder = tmp_path_factory.mktemp("plain")
    src = folder / "in.csv"
    # the OLD column names (no units): --tracks still reads them
    lines = ["time,x_center,y_center,x_cd,y_cd,x_ball,y_ball"]
    lines += [",".join(repr(float(v)) for v in (rec.time[i], x[i, 0], y[i, 0], x[i, 1], y[i, 1],
                                                 x[i, 2], y[i, 2])) for i in range(rec.time.size)]
    src.write_text("\n".join(lines) + "\n")
    out = folder / "out"
    assert measure_main(["measure", str(src), "--tracks", "--out", str(out), "--no-plots",
                         "--quiet", "--json"]) == 0
    return rec, x, y, out


def test_tracks_csv_is_plain_and_reads_back(measured):
    rec, x, y, out = measured
    frame, rows = both_readers(out / "tracks.csv")
    assert tuple(frame.columns) == OUTPUT_COLUMNS
    assert OUTPUT_COLUMNS[:3] == ("time_s", "theta_rad", "beta_rad")
    assert "x_ball_px" in frame.columns and "lost" in frame.columns
    np.testing.assert_allclose(frame["time_s"].to_numpy(), rec.time, rtol=0, atol=1e-15)
    np.testing.assert_allclose(frame["x_ball_px"].to_numpy(), x[:, 2], atol=1e-12)
    assert float(rows[10]["y_cd_px"]) == pytest.approx(y[10, 1], abs=1e-12)
    assert frame["lost"].dtype.kind == "i"
    # and it is a valid --tracks input with the new names
    back = read_tracks_csv(out / "tracks.csv")
    np.testing.assert_allclose(back.x, x, atol=1e-12)


def test_kinematics_csv_is_plain_with_units_in_names(measured):
    rec, _, _, out = measured
    frame, rows = both_readers(out / "kinematics.csv")
    for name in ("time_s", "theta_rad", "beta_rad", "omega_rad_s", "omega_dot_rad_s2",
                 "sigma_omega_dot_rad_s2", "mu_req", "beta_model_rad", "trusted", "lost"):
        assert name in frame.columns, name
    assert len(frame) == rec.time.size
    # numbers, not text: empty cells (outside the trusted region) are NaN for pandas
    assert frame["omega_rad_s"].dtype.kind == "f"
    trusted = frame["trusted"].to_numpy() == 1
    # omega from the file is the ABU speed (independent truth: the exact plant)
    np.testing.assert_allclose(frame["omega_rad_s"].to_numpy()[trusted], rec.omega[trusted],
                               rtol=0.01)
    assert frame["mu_req"].isna().to_numpy()[~trusted].all()
    assert rows[0]["time_s"] == "0"


def test_summary_keys_of_the_model_interval(measured):
    _, _, _, out = measured
    s = json.loads((out / "summary.json").read_text())
    for key in ("mu_low", "mu_high", "status", "confidence", "mu_d", "mu_d_low", "mu_d_high",
                "running_max"):
        assert key in s, key
    assert s["confidence"] == 0.95
    assert {"mu_low", "mu_high", "status"} <= set(s["running_max"])


def test_result_csv_of_abu_simulate(tmp_path, fmu_dir):
    from abu.cli.main import main
    folder = str(next(iter(fmu_dir.values())).parent)
    out = tmp_path / "sim"
    assert main(["simulate", "--fmu-dir", folder, "--out", str(out), "--json"]) == 0
    frame, rows = both_readers(out / "result.csv")
    for name in ("time_s", "omega_rad_s", "alpha_rad_s2", "beta_rad", "mu_req"):
        assert name in frame.columns, name
    summary = json.loads((out / "summary.json").read_text())
    # the slip instant is a row of the table
    assert np.min(np.abs(frame["time_s"].to_numpy() - summary["t_slip"])) < 1e-12


def test_truth_csv_of_the_twin(tmp_path):
    from twin.scenario import _truth_csv, random_scenario, simulate_scenario
    scn = random_scenario(3, n_frames=1000)
    state, pos = simulate_scenario(scn)
    path = tmp_path / "truth.csv"
    path.write_text(_truth_csv(scn, state, pos))
    frame, _ = both_readers(path)
    assert "time_s" in frame.columns and "theta_rad" in frame.columns
    np.testing.assert_allclose(frame["theta_rad"].to_numpy(), state["theta"], rtol=1e-15)


def test_table_text_cells_match_python_formatting_and_non_finite_cells_are_empty():
    """``table_csv_text`` formats every cell as Python's ``%`` does (integers as integers) and
    leaves exactly the nan / inf / -inf cells empty, on random tables (seeded), checked cell
    by cell against a plain loop over the cells."""
    from measurement.imaging.tracks_io import table_csv_text

    rng = np.random.default_rng(20)
    for case in range(200):
        n, m = int(rng.integers(0, 30)), int(rng.integers(1, 6))
        cols = []
        for _ in range(m):
            if rng.random() < 0.3:
                cols.append(rng.integers(-10 ** 6, 10 ** 6, n))
                continue
            a = rng.standard_normal(n) * 10.0 ** rng.integers(-20, 20)
            for value, share in ((np.nan, 0.2), (np.inf, 0.1), (-np.inf, 0.1)):
                a[rng.random(n) < share] = value
            cols.append(a)
        names = [f"c{j}_inf_nan" for j in range(m)]     # header words are never emptied
        fmt = "%.17g" if case % 2 else "%.10g"
        lines = [",".join(names)] + [",".join(
            "%d" % c[i] if c.dtype.kind == "i" else (fmt % c[i] if np.isfinite(c[i]) else "")
            for c in cols) for i in range(n)]
        assert table_csv_text(names, cols, fmt) == "\n".join(lines) + "\n", case
