"""abu next: after one interval, the proposed run narrows the combined interval (predicted and
confirmed by co-simulating the proposal)."""
from __future__ import annotations

import json

import pytest

from abu.cli.main import main
from abu.intervals_io import read_interval
from harness.planning.next_run import IntervalsError, combine

MU = 2.75e-3  # the report's simulations (sec. 4.2.3)


def test_next_proposes_a_run_that_narrows_the_interval(tmp_path, capsys, fmu_dir):
    fmus = str(fmu_dir["AbuBall"].parent)
    # run 1: the report's own staircase (-17 Hz -> -22 Hz in 1 s, report's loop)
    assert main(["simulate", "--mu", str(MU), "--fmu-dir", fmus, "--out",
                 str(tmp_path / "run1")]) == 0
    capsys.readouterr()
    first = read_interval(tmp_path / "run1" / "summary.json")
    width1 = first["mu_high"] - first["mu_low"]
    # co-simulated runs have no camera: the noise-free ranking is the one that fits them
    assert main(["next", str(tmp_path / "run1" / "summary.json"), "--fmu-dir", fmus,
                 "--objective", "expected", "--json"]) == 0
    proposal = json.loads(capsys.readouterr().out)
    assert proposal["current_interval"] == [first["mu_low"], first["mu_high"]]
    predicted = proposal["predicted_worst_combined_width"]
    assert predicted < width1
    assert all(r["first_step_stuck"] and r["slip_inside"] and r["brackets"]
               for r in proposal["check"])
    # run 2: the proposal, co-simulated at the true mu
    assert main(["simulate", *proposal["simulate_args"], "--mu", str(MU), "--fmu-dir", fmus,
                 "--out", str(tmp_path / "run2")]) == 0
    capsys.readouterr()
    second = read_interval(tmp_path / "run2" / "summary.json")
    lo, hi = combine([first, second])
    print(f"\nnext: run 1 (report's staircase) [{first['mu_low']:.5g}, {first['mu_high']:.5g}] "
          f"width {width1:.3g}; proposed {proposal['design']['omega0_hz']} Hz -> "
          f"{proposal['design']['omega_end_hz']} Hz, te {proposal['design']['te_s']:.3g} s: "
          f"predicted combined width <= {predicted:.3g}; co-simulated run 2 "
          f"[{second['mu_low']:.5g}, {second['mu_high']:.5g}], combined [{lo:.5g}, {hi:.5g}] "
          f"width {hi - lo:.3g} ({100 * (hi - lo) / width1:.0f} % of run 1's)")
    assert lo <= MU <= hi
    assert hi - lo < width1
    # the README's figure: the combined interval is 32 % of run 1's width
    assert (hi - lo) / width1 == pytest.approx(0.32, abs=0.01)
    # the predictor samples mu_req on the frame grid (1/4500 s), the co-simulation takes the
    # exact right limit at the setpoint step: they agree to well under 1 %
    assert hi - lo <= predicted * 1.01


def test_next_refuses_disjoint_or_open_intervals(tmp_path, capsys):
    a = {"name": "a", "mu_low": 0.01, "mu_high": 0.02, "drive": None}
    b = {"name": "b", "mu_low": 0.03, "mu_high": 0.04, "drive": None}
    with pytest.raises(IntervalsError, match="no common point"):
        combine([a, b])
    path = tmp_path / "summary.json"
    path.write_text(json.dumps({"kind": "abu-simulate-summary", "format_version": 1,
                                "mu_low": 0.01, "mu_high": None}))
    assert main(["next", str(path), "--no-check"]) == 2
    assert "mu_high" in capsys.readouterr().err


def test_combined_width_keeps_mu_near_the_middle_of_the_interval():
    """Where mu lies in the measured intervals sets what their intersection keeps. With mu at
    the fractions x of [L, H] and p of the next interval, x and p independent normal (mean m,
    sd s), a next interval as wide as [L, H] keeps 1 - E|x - p| = 1 - 2 s / sqrt(pi) of it
    (0.853 for s = 0.13; the former rule, mu log-uniform in [L, H] and the next interval centred
    on it, kept 0.75: it predicted 0.87x the combined width measured on rendered chains of
    runs, benchmarks/bench_next_runs.py). A much narrower run sets the width alone, a much
    wider one leaves [L, H]."""
    import math

    import numpy as np

    from harness.planning.next_run import POSITION_SD, combined_width

    lo, hi = 0.02, 0.0202                    # narrow: relative widths ~ absolute / mu
    current = (lo + hi) / 2
    rel = (hi - lo) / current
    grid = np.geomspace(lo, hi, 25)
    same = combined_width((lo, hi), grid, np.full(25, rel))
    assert same / rel == pytest.approx(1 - 2 * POSITION_SD / math.sqrt(math.pi), rel=5e-3)
    assert combined_width((lo, hi), grid, np.full(25, rel / 50)) == pytest.approx(rel / 50,
                                                                                 rel=1e-3)
    assert combined_width((lo, hi), grid, np.full(25, 20 * rel)) == pytest.approx(rel, rel=1e-3)
    # the 90 % range spans where mu lies: quantiles around the expected width
    lo90 = combined_width((lo, hi), grid, np.full(25, rel), quantile=0.05)
    hi90 = combined_width((lo, hi), grid, np.full(25, rel), quantile=0.95)
    assert lo90 < 0.75 * rel < same < hi90 <= rel * (1 + 1e-12)
    # a null bound (inf) gains nothing
    assert combined_width((0.02, 0.04), np.geomspace(0.02, 0.04, 25),
                          np.full(25, np.inf)) == pytest.approx(2 / 3, rel=1e-9)
