"""The row summaries of ``benchmarks/bench_width_floor.py`` (the rendering and analysis it runs are
tested elsewhere): width ratios on the recordings where both sets are finite, coverage and miss
counts, and the ``--camera`` table's ratios to both exact rows."""
import pytest

from benchmark_module import benchmark_module


@pytest.fixture(scope="module")
def bench():
    yield from benchmark_module("bench_width_floor")


def _row(kind, mu, **bounds):
    return {"seed": 0, "mu": mu, "kind": kind, "model": "accepted", "bounds": bounds}


ROWS = [  # relative widths: a 0.4, 0.2 (and unbounded); ref 0.1, 0.2, 0.3
    _row("staircase_pi", 0.02, a=(0.016, 0.024), ref=(0.019, 0.021)),
    _row("profile", 0.02, a=(0.018, 0.022), ref=(0.018, 0.022)),
    _row("profile", 0.02, a=(0.021, None), ref=(0.017, 0.023)),
]


def test_width_ratio_uses_the_recordings_where_both_are_finite(bench):
    # a: median of 0.4, 0.2 = 0.3; ref on the same two: median of 0.1, 0.2 = 0.15
    assert bench.width_ratio(ROWS, "a", "ref") == pytest.approx(2.0)
    assert bench.width_ratio(ROWS, "ref", "a") == pytest.approx(0.5)
    assert bench.width_ratio(ROWS[2:], "a", "ref") != bench.width_ratio(ROWS[2:], "a", "ref")
    # recording by recording: 0.4 / 0.1 = 4 and 0.2 / 0.2 = 1, median 2.5
    assert bench.per_recording_ratio(ROWS, "a", "ref") == pytest.approx(2.5)
    inside, misses, widths = bench.scores(ROWS, "a")
    assert inside == [True, True, False]
    assert misses[2] == pytest.approx(0.05) and misses[:2] == [0.0, 0.0]


def test_camera_table_prints_both_ratios(bench, capsys, monkeypatch):
    names = ["42 ms (default)", "default + camera", bench.KNOWN, "known drive + camera",
             "exact + camera", bench.EXACT, bench.NO_LENS]
    rows = []
    for r in ROWS[:2]:   # every analysis the reference bounds, but one
        b = {n: r["bounds"]["ref"] for n in names}
        b["default + camera"] = r["bounds"]["a"]
        rows.append({**r, "bounds": b, "cal": {"cal_k1_err": 1e-4, "cal_rms_px": 0.03,
                                                "cal_s": 1.0}, "lens_prior_rad": 3e-4})
    bench.report_camera(rows)
    out = capsys.readouterr().out
    line = next(s for s in out.splitlines() if s.strip().startswith("all: default + camera"))
    assert line.split()[-2:] == ["2.00x", "2.00x"]
    assert "/ no lens" in out and "lens prior on theta's harmonic median 3.0e-04" in out
