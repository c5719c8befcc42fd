"""The command line of the co-simulation: --tol / --comm-step select the stepping, and the
batch commands report their wall time."""
from __future__ import annotations

import json

from abu.cli.main import main
from harness.cosim.stepping import DEFAULT_TOL


def test_tol_and_comm_step_select_the_stepping(fmu_dir, capsys):
    folder = str(fmu_dir["AbuBall"].parent)
    runs = {}
    for name, args in (("default", []), ("tight", ["--tol", "1e-10"]),
                       ("fixed", ["--comm-step", "5e-3"])):
        assert main(["simulate", *args, "--fmu-dir", folder, "--json"]) == 0
        runs[name] = json.loads(capsys.readouterr().out)
    assert runs["default"]["experiment"]["tol"] == DEFAULT_TOL == 1e-9
    assert runs["tight"]["experiment"]["tol"] == 1e-10
    assert runs["fixed"]["experiment"]["tol"] is None
    assert runs["fixed"]["cosim"]["rejected"] == 0 and runs["fixed"]["cosim"]["steps"] >= 310
    # a tighter tolerance takes more, smaller steps, and moves the bounds by less than 1e-6
    assert runs["tight"]["cosim"]["steps"] > runs["default"]["cosim"]["steps"]
    assert abs(runs["default"]["mu_low"] / runs["tight"]["mu_low"] - 1) < 1e-6


def test_table41_reports_its_wall_time(fmu_dir, capsys):
    folder = str(fmu_dir["AbuBall"].parent)
    assert main(["table41", "--mu", "2.75e-3", "--fmu-dir", folder]) == 0
    out = capsys.readouterr().out
    assert "yes" in out.splitlines()[1]  # 11 Hz confirmed by co-simulation
    wall = float(out.strip().splitlines()[-1].split()[2])
    assert out.strip().splitlines()[-1].startswith("wall time") and 0 < wall < 60
