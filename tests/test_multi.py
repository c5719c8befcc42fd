"""Combining several records' intervals: histogram, ranges, Turnbull NPMLE, measure-summary CLI."""
from __future__ import annotations

import json

import numpy as np
import pytest

from abu.cli.main import main
from measurement.report.multi import (IntervalInputError, combine_summaries, coverage_count,
                               innermost_intervals, level_set, read_intervals, turnbull)

# Twelve intervals built to match what the report states about its twelve runs (sec. 5.3):
# one run gave [0.0286, 0.0312]; mu = 0.03 lies in 7 of 12 intervals; the total interval is
# [0.024, 0.035]; one run's lower bound exceeds another run's upper bound.
REPORT_LIKE = np.array([
    [0.0286, 0.0312], [0.0240, 0.0262], [0.0251, 0.0285], [0.0270, 0.0305],
    [0.0281, 0.0303], [0.0292, 0.0331], [0.0295, 0.0318], [0.0300, 0.0350],
    [0.0262, 0.0298], [0.0305, 0.0340], [0.0310, 0.0336], [0.0277, 0.0301]])


def as_records(arr):
    return [{"name": f"run{i + 1}", "mu_low": lo, "mu_high": hi} for i, (lo, hi) in enumerate(arr)]


def test_report_like_histogram_and_total_interval():
    r = combine_summaries(as_records(REPORT_LIKE), bins=200)
    assert r["n_records"] == 12 and r["n_complete"] == 12
    assert coverage_count(REPORT_LIKE, np.array([0.03]))[0] == 7     # report: 7 of 12
    assert r["union_hull"] == [0.024, 0.035]                          # report: [0.024 0.035]
    assert len(r["union_pieces"]) == 1
    assert r["common_range"] is None      # a lower bound exceeds another run's upper bound
    assert max(r["histogram"]["count"]) == r["max_count"]


def test_majority_range_matches_a_brute_force_scan():
    r = combine_summaries(as_records(REPORT_LIKE))
    grid = np.linspace(0.023, 0.036, 130001)
    inside = grid[coverage_count(REPORT_LIKE, grid) > 6]
    lo, hi = r["majority_range"]
    assert lo == pytest.approx(inside.min(), abs=2e-7)
    assert hi == pytest.approx(inside.max(), abs=2e-7)
    top = grid[coverage_count(REPORT_LIKE, grid) == r["max_count"]]
    assert r["max_count_pieces"][0][0] == pytest.approx(top.min(), abs=2e-7)


def test_level_set_handles_touching_and_open_ended_intervals():
    iv = np.array([[1.0, 2.0], [2.0, 3.0], [2.5, np.inf]])
    assert level_set(iv, 2) == [[2.0, 2.0], [2.5, 3.0]]
    assert level_set(iv, 1) == [[1.0, np.inf]]


def test_turnbull_disjoint_intervals_share_the_mass_equally():
    iv = np.array([[0.01, 0.02], [0.03, 0.04], [0.05, 0.06], [0.07, 0.08]])
    t = turnbull(iv)
    np.testing.assert_allclose(t["mass"], 0.25, atol=1e-9)
    # The median of four equal masses lies between the 2nd and 3rd interval.
    assert t["median"] == [0.04, 0.05]


def test_turnbull_puts_everything_on_a_common_intersection():
    iv = np.array([[0.02, 0.05], [0.03, 0.06], [0.01, 0.035], [0.025, 0.04]])
    t = turnbull(iv)
    assert innermost_intervals(iv).tolist() == [[0.03, 0.035]]
    assert t["support"] == [{"interval": [0.03, 0.035], "mass": pytest.approx(1.0)}]
    assert t["median"] == [0.03, 0.035]


def test_turnbull_is_the_maximum_likelihood_estimate():
    t = turnbull(REPORT_LIKE)
    inner = np.array(t["innermost"])
    p = np.array(t["mass"])
    a = ((REPORT_LIKE[:, 0][:, None] <= inner[None, :, 0])
         & (inner[None, :, 1] <= REPORT_LIKE[:, 1][:, None])).astype(float)
    # Optimality (KKT) of the NPMLE: d_j = mean_i a_ij / (a_i . p) <= 1, with equality where
    # p_j > 0 (Gentleman & Geyer 1994).
    dj = (a / (a @ p)[:, None]).mean(axis=0)
    assert np.all(dj <= 1 + 1e-6)
    np.testing.assert_allclose(dj[p > 1e-4], 1.0, atol=1e-5)
    # No random point of the simplex has a higher likelihood.
    rng = np.random.default_rng(0)
    for _ in range(2000):
        q = rng.dirichlet(np.ones(p.size))
        assert np.sum(np.log(a @ q)) <= t["loglik"] + 1e-9
    assert abs(sum(p) - 1) < 1e-12


def test_read_intervals_from_summaries_and_csv(tmp_path):
    s1 = tmp_path / "a.json"
    s1.write_text(json.dumps({"mu_low": 0.028, "mu_high": 0.031, "status": "ok"}))
    s2 = tmp_path / "b.json"
    s2.write_text(json.dumps({"mu_low": 0.027, "mu_high": None, "status": "no slip"}))
    c = tmp_path / "runs.csv"
    c.write_text("# report-like\nname,mu_low,mu_high\nx,0.025,0.029\ny,0.03,0.033\n")
    got = read_intervals([s1, s2, c])
    assert [(g["mu_low"], g["mu_high"]) for g in got] == [
        (0.028, 0.031), (0.027, float("inf")), (0.025, 0.029), (0.03, 0.033)]
    assert got[2]["name"] == "x"


@pytest.mark.parametrize("content, match", [
    ('{"mu_low": 0.03, "mu_high": 0.02}', "exceeds mu_high"),
    ('{"mu_low": "abc", "mu_high": 0.02}', "expected a finite number"),
    ('{"mu": 0.03}', "keys mu_low and mu_high"),
    ('{"mu_low": null, "mu_high": null}', "neither"),
    ("not json", "not JSON"),
])
def test_bad_summaries_are_named(tmp_path, content, match):
    f = tmp_path / "s.json"
    f.write_text(content)
    with pytest.raises(IntervalInputError, match=match) as info:
        read_intervals([f])
    assert "s.json" in str(info.value)


def test_measure_summary_command(tmp_path, capsys):
    files = []
    for i, (lo, hi) in enumerate(REPORT_LIKE):
        f = tmp_path / f"summary{i}.json"
        f.write_text(json.dumps({"mu_low": lo, "mu_high": hi}))
        files.append(str(f))
    out = tmp_path / "combined"
    assert main(["measure-summary", *files, "--out", str(out), "--json"]) == 0
    printed = json.loads(capsys.readouterr().out)
    saved = json.loads((out / "measure_summary.json").read_text())
    assert printed == saved
    assert saved["union_hull"] == [0.024, 0.035]
    assert (out / "histogram.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_measure_summary_bad_file_exits_2_and_writes_nothing(tmp_path, capsys):
    good = tmp_path / "good.json"
    good.write_text(json.dumps({"mu_low": 0.02, "mu_high": 0.03}))
    out = tmp_path / "o"
    assert main(["measure-summary", str(good), str(tmp_path / "missing.json"),
                 "--out", str(out)]) == 2
    assert "missing.json" in capsys.readouterr().err
    assert not out.exists()
