"""The distributed sweep returns, in order, what a direct co-simulation of each point gives."""
import csv
import math

import pytest

from abu_model.errors import ParameterError
from abu_model.params import PlantParams
from abu.cli.main import main
from harness.experiments.staircase import StaircaseExperiment, run_staircase
from harness.experiments.sweep import run_sweep, sweep_grid

HZ = 2 * math.pi


def test_sweep_on_local_cluster_matches_direct_runs(fmu_dir, tmp_path):
    folder = fmu_dir["AbuBall"].parent
    base = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ)
    points = sweep_grid([2.75e-3, 6e-3], [-17.0])
    rows = run_sweep(points, base, folder, workers=2)
    assert [(r["mu"], r["omega0_hz"]) for r in rows] == [(2.75e-3, -17.0), (6e-3, -17.0)]
    for row, point in zip(rows, points):
        plant = PlantParams(ball=PlantParams().ball.with_(mu=point.mu))
        direct = run_staircase(StaircaseExperiment(plant, -17 * HZ, -22 * HZ), folder).summary
        assert row["mu_low"] == direct["mu_low"] and row["mu_high"] == direct["mu_high"]
    assert rows[0]["slipped"] and rows[0]["bracketed"]
    assert not rows[1]["slipped"]  # mu = 6e-3 holds through the whole -17 -> -22 Hz staircase


def test_sweep_command_writes_csv_with_units(fmu_dir, tmp_path, capsys):
    out = tmp_path / "sweep.csv"
    status = main(["sweep", "--mu", "2.75e-3", "--omega0-hz", "-17", "-20", "--out", str(out),
                   "--fmu-dir", str(fmu_dir["AbuBall"].parent), "--workers", "2"])
    assert status == 0
    assert "(wall time " in capsys.readouterr().out
    rows = list(csv.DictReader(out.open()))
    assert [r["omega0_hz"] for r in rows] == ["-17.0", "-20.0"]
    assert set(rows[0]) >= {"mu", "omega0_hz", "mu_low", "mu_high", "t_slip_s", "bracketed"}
    assert rows[0]["bracketed"] == "True"


def test_sweep_rejects_an_empty_grid_and_bad_workers(tmp_path, capsys):
    with pytest.raises(ParameterError):
        sweep_grid([], [-17.0])
    assert main(["sweep", "--mu", "1e-3", "--omega0-hz", "-17", "--workers", "0",
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "--workers" in capsys.readouterr().err
    assert not (tmp_path / "x.csv").exists()
