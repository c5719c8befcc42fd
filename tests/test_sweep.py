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


def test_journal_cuts_a_torn_line_dedupes_and_refuses_another_sweep(tmp_path):
    from harness.experiments.sweep_journal import Journal, JournalError

    path = tmp_path / "s.csv.journal"
    j = Journal(path, "abc", 3)
    assert j.append("k1", {"mu": 0.1, "x": None}) and not j.append("k1", {"mu": 0.2})
    j.append("k2", {"mu": 0.1 + 0.2})
    j.close()
    with open(path, "ab") as f:
        f.write(b'{"key": "k3", "ro')  # killed while writing
    j = Journal(path, "abc", 3)
    assert j.rows == {"k1": {"mu": 0.1, "x": None}, "k2": {"mu": 0.30000000000000004}}
    j.append("k3", {"mu": 3.0})
    j.close()
    assert path.read_bytes().count(b"\n") == 4 and b'"ro\n' not in path.read_bytes()
    with pytest.raises(JournalError, match="different settings"):
        Journal(path, "other", 3)
    assert Journal(path, "other", 3, discard=True).rows == {}


def test_sweep_progress_bar_counts_runs(fmu_dir, tmp_path, capsys):
    out = tmp_path / "sweep.csv"
    assert main(["sweep", "--mu", "2.75e-3", "--omega0-hz", "-17", "-18", "--out", str(out),
                 "--fmu-dir", str(fmu_dir["AbuBall"].parent), "--progress", "--te", "0.3",
                 "--span-hz", "-2", "--tau-motor", "1e-3", "--t0", "0.1", "--tol", "1e-8"]) == 0
    err = capsys.readouterr().err
    assert "2/2" in err and "run" in err
    import re
    assert not re.search(r"\d\.\d{6,}/", err)  # no raw floats such as 0.345499.../1.35
    assert not out.with_name("sweep.csv.journal").exists()


def test_sweep_runs_are_abu_simulate_runs(fmu_dir, tmp_path, capsys):
    """Each row is what ``abu simulate --json`` gives with the same options (drive-free)."""
    import json
    folder = str(fmu_dir["AbuBall"].parent)
    opts = ["--te", "0.5", "--tau-motor", "2e-3", "--t0", "0.05", "--tol", "1e-8",
            "--zeta", "0.6", "--step-hz", "1"]
    out = tmp_path / "sweep.csv"
    assert main(["sweep", "--mu", "2.75e-3", "--omega0-hz", "-17", "--span-hz", "-3",
                 "--out", str(out), "--fmu-dir", folder, *opts]) == 0
    capsys.readouterr()
    assert main(["simulate", "--mu", "2.75e-3", "--omega0-hz", "-17", "--omega-end-hz", "-20",
                 "--fmu-dir", folder, "--json", *opts]) == 0
    summary = json.loads(capsys.readouterr().out)
    row = next(csv.DictReader(out.open()))
    assert float(row["mu_low"]) == summary["mu_low"]
    assert (row["mu_high"] or None) == (None if summary["mu_high"] is None
                                        else repr(summary["mu_high"]))


def test_a_sweep_killed_after_its_csv_landed_finishes_when_run_again(fmu_dir, tmp_path,
                                                                     capsys, monkeypatch):
    """The last moment of a sweep: the CSV is in place, its journal not yet removed (a kill
    there). The same command again must finish (same CSV, journal gone), not refuse the CSV as
    another run's; a different command must still refuse it."""
    from harness.experiments import sweep_journal

    folder = fmu_dir["AbuBall"].parent
    out = tmp_path / "sweep.csv"
    argv = ["sweep", "--mu", "2.75e-3", "--omega0-hz", "-17", "-18", "--out", str(out),
            "--workers", "1", "--fmu-dir", str(folder)]
    with monkeypatch.context() as m:  # the journal survives, as after a kill at that moment
        m.setattr(sweep_journal.Journal, "remove", lambda self: None)
        assert main(argv) == 0
    first = out.read_text()
    journal = sweep_journal.journal_path(out.absolute())
    assert journal.exists()
    assert main(argv) == 0
    assert out.read_text() == first and not journal.exists()
    capsys.readouterr()
    assert main(argv[:2] + ["2e-3"] + argv[3:]) == 2  # another sweep: the CSV is not its own
    assert "already holds results" in capsys.readouterr().err


def test_a_scheduler_that_cannot_be_reached_fails_fast_with_one_line(tmp_path):
    """A well-formed address where no Dask scheduler listens (a closed port on loopback): the
    real command exits 2 within seconds, one line naming --scheduler, nothing written."""
    import socket
    import subprocess
    import sys
    import time

    with socket.socket() as s:  # a port that was free a moment ago: nothing listens there
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    out = tmp_path / "sweep.csv"
    started = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "abu.cli.main", "sweep", "--mu", "2.75e-3",
                           "--omega0-hz", "-17", "--scheduler", f"tcp://127.0.0.1:{port}",
                           "--out", str(out)], capture_output=True, text=True, timeout=120)
    elapsed = time.perf_counter() - started
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1 and "--scheduler" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
    assert not out.exists() and not list(tmp_path.iterdir())
    assert elapsed < 30, elapsed
