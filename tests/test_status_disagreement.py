"""A model-based interval disjoint from the report's running max is not reported as "ok".

Seed 3064 of the harsh family (unseen by any tuning) is the case that prompted it: the fit put a
slip with mu_d near 0 at 0.021 s, where the ABU barely accelerates, and reported [0, 0.0016]
"ok" for a true mu of 0.0376 while the running max gave [0.035, 0.041] (its cause, the slip
model's cap of 4 episodes, is fixed: tests/test_slip_episodes.py).
"""
from __future__ import annotations

from types import SimpleNamespace

from measurement.inference.analysis_summary import _disagreement
from rendered_seed import render_and_measure


def _sets(model, running_max, status="ok"):
    inf = SimpleNamespace(mu_low=model[0], mu_high=model[1], status=status)
    iv = SimpleNamespace(mu_low=running_max[0], mu_high=running_max[1])
    return inf, iv


def test_disjoint_intervals_are_flagged_and_overlapping_ones_are_not():
    assert _disagreement(*_sets((0.0, 0.0016), (0.035, 0.041))).startswith("check: ")
    assert _disagreement(*_sets((0.05, 0.06), (0.035, 0.041))).startswith("check: ")
    assert _disagreement(*_sets((0.03, 0.036), (0.035, 0.041))) is None      # they overlap
    assert _disagreement(*_sets((0.03, 0.035), (0.035, 0.041))) is None      # they touch
    assert _disagreement(*_sets((0.0, 0.0016), (None, 0.041))) is None       # no running max
    assert _disagreement(*_sets((None, 0.0016), (0.035, 0.041))) is None
    # a status that already says what is wrong is kept
    assert _disagreement(*_sets((0.0, 0.0016), (0.035, 0.041), "lost markers")) is None


def test_a_rendered_disagreement_is_flagged(tmp_path, capsys):
    """End to end: seed 181 of the harsh family, where the report's running max erred
    ([0.0359, 0.0401] for a true mu of 0.0482) and the model's interval holds mu: the two are
    disjoint and the status says so instead of "ok". (The rendered miss this test used, seed
    3057, holds mu since the lighting orders became random effects, tests/test_lighting_leftover.py;
    with the final default no flagged recording of the family or of seeds 2000-5099 misses mu.)"""
    summary, mu = render_and_measure(181, tmp_path)
    rm = summary["running_max"]
    assert summary["mu_low"] <= mu <= summary["mu_high"]
    assert not rm["mu_low"] <= mu <= rm["mu_high"]           # the running max erred here
    assert rm["mu_high"] < summary["mu_low"] or summary["mu_high"] < rm["mu_low"]
    assert summary["status"].startswith("check: ") and "do not overlap" in summary["status"]
    capsys.readouterr()
