"""The ``abu`` command line: simulate, table41, demo, build-fmus, errors and outputs."""
from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from abu_model.params import BallParams, PlantParams
from abu_model.reference import simulate_staircase_reference
from abu.cli.main import build_parser, main
from harness.experiments.staircase import UNITS, StaircaseExperiment, friction_bounds
from harness.experiments.results_io import read_table_csv
from harness.experiments.table41 import REPORT_TABLE, report_implied_jump

HZ = 2 * math.pi
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def fmu_folder(fmu_dir):
    return str(next(iter(fmu_dir.values())).parent)


def test_simulate_writes_csv_summary_and_plots(tmp_path, fmu_folder, capsys):
    out = tmp_path / "run"
    assert main(["simulate", "--fmu-dir", fmu_folder, "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "mu_low = " in printed and "[-]" in printed and " s" in printed
    header = (out / "result.csv").read_text().splitlines()[0].split(",")
    for column in ("time_s", "side", "omega_ref_rad_s", "torque_N_m", "omega_rad_s",
                   "alpha_rad_s2", "beta_rad", "beta_dot_rad_s", "normal_force_N", "mu_req"):
        assert column in header
    table = read_table_csv(out / "result.csv", UNITS)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["units"]["t_slip"] == "s"
    # The CSV holds everything the bounds come from, exactly.
    bounds = friction_bounds(table, summary["switches"])
    assert bounds["mu_low"] == summary["mu_low"] and bounds["mu_high"] == summary["mu_high"]
    # ... and they are the monolithic reference's for the report's default case.
    exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ)
    ref = simulate_staircase_reference(exp.plant, exp.controller, exp.staircase, exp.t_end,
                                       t_start=exp.t_start)
    assert summary["mu_low"] == pytest.approx(ref.mu_low, rel=5e-3)
    assert summary["mu_high"] == pytest.approx(ref.mu_high, rel=5e-3)
    for name in ("omega", "omega_dot", "beta", "beta_dot", "mu_req"):
        data = (out / f"{name}.png").read_bytes()
        assert data.startswith(PNG_MAGIC) and len(data) > 5000
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary files left


def test_simulate_json_ramp(fmu_folder, capsys):
    assert main(["simulate", "--motion", "ramp", "--jerk", "5000", "--omega0-hz", "-20",
                 "--t-end", "0.06", "--mu", "0.01", "--fmu-dir", fmu_folder, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["mu_estimate"] == pytest.approx(0.01, rel=1e-6)
    b = BallParams()
    w, a = summary["omega_slip"], summary["alpha_slip"]
    assert a == pytest.approx(-5000 * summary["t_slip"], rel=1e-12)
    assert w == pytest.approx(-20 * HZ - 2500 * summary["t_slip"] ** 2, rel=1e-12)
    assert (b.l - b.d / 5) * abs(a) == pytest.approx(0.01 * b.l * w * w, rel=1e-6)


def test_stdout_closed_by_its_reader_is_a_quiet_exit_141(fmu_folder, tmp_path):
    """``abu simulate --json | head -c 0``: the reader is gone before the output; no
    'internal error', no 'Exception ignored', the shell's SIGPIPE status; the CSV is written."""
    import os

    read_end, write_end = os.pipe()
    os.close(read_end)
    out = tmp_path / "run"
    try:
        proc = subprocess.run(
            [sys.executable, "-m", "abu.cli.main", "simulate", "--motion", "ramp", "--jerk", "5000",
             "--omega0-hz", "-20", "--t-end", "0.06", "--mu", "0.01", "--fmu-dir", fmu_folder,
             "--out", str(out), "--json"],
            stdout=write_end, stderr=subprocess.PIPE, text=True, timeout=120)
    finally:
        os.close(write_end)
    assert proc.returncode == 141, proc.stderr
    assert proc.stderr == ""
    assert (out / "result.csv").is_file() and (out / "summary.json").is_file()


@pytest.mark.parametrize("argv,option", [
    (["simulate", "--te", "0"], "--te"),
    (["simulate", "--omega-end-hz", "-17.5"], "--omega-end-hz"),
    (["simulate", "--comm-step", "0"], "--comm-step"),
    (["simulate", "--omega0-hz", "nan"], "--omega0-hz"),
    (["simulate", "--omega0-hz", "0"], "--omega0-hz"),
    (["simulate", "--mu-d", "0.01"], "--mu-d"),
    (["simulate", "--d", "0.1"], "--d"),
    (["simulate", "--step-hz", "-1"], "--step-hz"),
    (["simulate", "--motion", "ramp", "--jerk", "0"], "--jerk"),
    (["table41", "--mu", "-1"], "--mu"),
    (["table41", "--mu", "0.01", "--step-hz", "0"], "--step-hz"),
])
def test_user_errors_name_the_option_and_exit_2(argv, option, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"'{option}'" in err and "expected" in err and "Traceback" not in err


def test_entry_point_error_has_no_traceback(tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    proc = subprocess.run([sys.executable, "-m", "abu.cli.main", "simulate", "--te", "-1"],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "'--te'" in proc.stderr and "Traceback" not in proc.stderr
    proc = subprocess.run([sys.executable, "-m", "abu.cli.main", "build-fmus", "--out",
                           str(blocker / "sub")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr and str(blocker) in proc.stderr


def _closed_form_hz(mu: float, jump: float) -> int:
    b = BallParams()
    return math.ceil(math.sqrt((b.l - b.d / 5) / b.l * jump / mu) / HZ)


def test_table41_integral_is_the_closed_form_and_checked(fmu_folder, capsys):
    mus = [2.75e-3, 1.1e-2]
    assert main(["table41", "--mu", *map(str, mus), "--fmu-dir", fmu_folder, "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert table["kind"] == "abu-table41" and table["units"]["omega0_hz"] == "Hz"
    rows = table["rows"]
    assert [r["mu"] for r in rows] == mus
    assert [r["omega0_hz"] for r in rows] == [_closed_form_hz(mu, 2 * 0.5 * 2.2 * HZ) for mu in mus]
    assert [r["omega0_hz"] for r in rows] == [11, 6]
    for r in rows:  # the simulation confirms: no slip at the value, slip one Hz below
        assert r["consistent"] is True
        assert {c["omega0_hz"]: c["slips"] for c in r["check"]} == \
            {r["omega0_hz"]: False, r["omega0_hz"] - 1: True}


def test_report_table_is_reproduced_by_a_late_step_in_thesis_mode(fmu_folder, capsys):
    implied = report_implied_jump()
    # The report's values imply a jump 2.1-2.4 times the integral PI's 2 zeta wn dW ...
    assert 2.0 < implied["ratio_low"] < implied["ratio_high"] < 2.5
    # ... which the thesis reading gives for a step at T = 0.51-0.63 s.
    t_step = 0.5 * (implied["thesis_t_step_low_s"] + implied["thesis_t_step_high_s"])
    assert 0.5 < implied["thesis_t_step_low_s"] < t_step < implied["thesis_t_step_high_s"] < 0.65
    mus = sorted(REPORT_TABLE)
    assert main(["table41", "--mu", *map(str, mus), "--theta-ref", "thesis", "--t-step",
                 str(t_step), "--no-check", "--json"]) == 0
    table = json.loads(capsys.readouterr().out)
    assert table["kind"] == "abu-table41" and table["units"]["omega0_hz"] == "Hz"
    rows = table["rows"]
    assert [r["omega0_hz"] for r in rows] == [REPORT_TABLE[mu] for mu in mus]  # 17 12 10 9 8 7
    # One row checked by co-simulation.
    assert main(["table41", "--mu", str(mus[0]), "--theta-ref", "thesis", "--t-step",
                 str(t_step), "--fmu-dir", fmu_folder, "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["rows"][0]["consistent"] is True


def test_demo_builds_and_reproduces_the_report(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    printed = capsys.readouterr().out
    assert "[integral] mu_low = " in printed and "[thesis] mu_low = " in printed
    assert "report eq. 4.9" in printed and "[-]" in printed
    thesis = json.loads((tmp_path / "thesis" / "summary.json").read_text())
    assert thesis["mu_low"] == pytest.approx(2.63e-3, rel=0.03)
    assert thesis["mu_high"] == pytest.approx(4.14e-3, rel=0.03)
    for mode in ("integral", "thesis"):
        assert (tmp_path / mode / "mu_req.png").read_bytes().startswith(PNG_MAGIC)
    assert sorted(p.name for p in (tmp_path / "fmus").glob("*.fmu")) == \
        ["AbuBall.fmu", "SpeedController.fmu", "Staircase.fmu"]


def test_measurement_commands_are_registered():
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    assert {"build-fmus", "simulate", "table41", "demo", "track", "measure", "measure-summary",
            "render"} <= set(commands)
