"""``benchmarks/bench_coverage.py``'s comparison with calibrated intervals: what "no miss by
more than 2 %" asks of intervals of a given width, checked against simulated estimators whose
intervals are calibrated (or conservative) by construction."""
import numpy as np
import pytest

from benchmark_module import benchmark_module


@pytest.fixture(scope="module")
def bench():
    yield from benchmark_module("bench_coverage")


def _intervals(rng, n, rel_sigma, inflate):
    """n rows: an unbiased Gaussian estimate of mu (relative sigma ``rel_sigma``), its
    interval +- 1.96 ``inflate`` sigma (1: calibrated, > 1: conservative)."""
    mu = rng.uniform(0.005, 0.06, n)
    est = mu * (1.0 + rel_sigma * rng.standard_normal(n))
    half = 1.959964 * inflate * rel_sigma * mu
    return [{"mu": m, "mu_low": e - h, "mu_high": e + h} for m, e, h in zip(mu, est, half)]


@pytest.mark.parametrize("rel_sigma", [0.04, 0.08])
def test_expected_misses_match_calibrated_intervals(bench, rel_sigma):
    rows = _intervals(np.random.default_rng(11), 20000, rel_sigma, 1.0)
    expected, spread, n = bench.calibrated_misses(rows)
    observed = sum(bench.miss(r["mu_low"], r["mu_high"], r["mu"]) > 0.02 for r in rows)
    assert n == 20000
    # the closed form against the simulated count (binomial sd ~ sqrt(expected))
    assert abs(observed - expected) < 4.0 * np.sqrt(expected) + 5
    assert 0.97 < spread < 1.03
    # narrower intervals miss by more than a fixed 2 % more often
    if rel_sigma == 0.08:
        assert 0.02 < expected / n < 0.04


def test_conservative_intervals_show_a_spread_below_one(bench):
    rows = _intervals(np.random.default_rng(12), 20000, 0.06, 1.7)
    _, spread, _ = bench.calibrated_misses(rows)
    assert abs(spread - 1 / 1.7) < 0.02
    # rows without both bounds are not counted
    rows.append({"mu": 0.01, "mu_low": None, "mu_high": 0.02})
    assert bench.calibrated_misses(rows)[2] == 20000
