"""The reported set is the intersection of the sets of several Savitzky-Golay windows, each at
level 1 - alpha / K (measurement.inference.window_sets): the combination rules, and on the harsh-twin
tracks family that it is sharper than the primary window alone while every set still holds mu.
"""
from __future__ import annotations

import os

import numpy as np
import pytest

from abu_model.errors import ParameterError

from measurement.inference.analysis import AnalysisOptions, analyse_tracks, inference_windows
from measurement.inference.types import LOST_ACROSS_SLIP, Inference
from measurement.inference.window_sets import intersect_sets, level_each

from test_inference import scenario_tracks


def _set(lo, hi, status="ok", mud=(None, None), mu_d=None) -> Inference:
    z = np.zeros(4)
    return Inference(mu_low=lo, mu_high=hi, mu_hat=None, mu_d=mu_d, mu_d_low=mud[0],
                     mu_d_high=mud[1], status=status, confidence=0.975, t_slip=None,
                     beta_model=z, beta_model_low=None, beta_model_high=None, residual=z,
                     details={"profile_mu_low": lo})


def test_level_each_is_the_union_bound():
    assert level_each(0.95, 1) == 0.95
    assert abs(level_each(0.95, 2) - 0.975) < 1e-15
    assert abs(level_each(0.9, 4) - 0.975) < 1e-15


def test_intersection_takes_the_tightest_bounds_and_states_the_joint_level():
    out = intersect_sets([_set(0.02, 0.05, mud=(0.01, 0.04), mu_d=0.035),
                          _set(0.025, 0.06, mud=(0.015, 0.03))], [0.042, 0.06], 0.95)
    assert (out.mu_low, out.mu_high, out.status, out.confidence) == (0.025, 0.05, "ok", 0.95)
    assert (out.mu_d_low, out.mu_d_high) == (0.015, 0.03)
    assert out.mu_d == 0.03                     # the primary's best, within the common set
    windows = out.details["windows"]
    assert [w["sg_window_s"] for w in windows] == [0.042, 0.06]
    assert [w["mu_low"] for w in windows] == [0.02, 0.025]
    assert "Bonferroni" in out.details["combination"]


def test_the_default_reports_one_window_as_it_is():
    times, x, y, ball, _ = scenario_tracks(40)
    _, s = analyse_tracks(times, x, y, l=ball.l, d=ball.d)
    mf = s["model_fit"]
    assert mf["combination"] == "one window" and len(mf["windows"]) == 1
    only = mf["windows"][0]
    assert (only["sg_window_s"], only["confidence"]) == (0.042, 0.95)
    assert (only["mu_low"], only["mu_high"]) == (s["mu_low"], s["mu_high"])


def test_a_null_bound_of_one_window_is_no_constraint():
    only_low = "no slip in the trusted region: only a lower bound"
    out = intersect_sets([_set(0.02, 0.05), _set(0.03, None, only_low)], [0.042, 0.06], 0.95)
    assert (out.mu_low, out.mu_high, out.status) == (0.03, 0.05, "ok")
    at_start = "slip before or at the start of the trusted region: no bound"
    out = intersect_sets([_set(0.02, 0.05), _set(None, None, at_start)], [0.042, 0.06], 0.95)
    assert (out.mu_low, out.mu_high, out.status) == (0.02, 0.05, "ok")
    # every window without an upper bound: the status says why, the bound stays null
    out = intersect_sets([_set(0.02, None, only_low), _set(0.03, None, only_low)],
                         [0.042, 0.06], 0.95)
    assert (out.mu_low, out.mu_high, out.status) == (0.03, None, only_low)


def test_lost_markers_or_disjoint_sets_give_no_bound():
    lost = LOST_ACROSS_SLIP
    out = intersect_sets([_set(0.02, 0.05), _set(None, None, lost)], [0.042, 0.06], 0.95)
    assert (out.mu_low, out.mu_high, out.status) == (None, None, lost)
    out = intersect_sets([_set(0.02, 0.03), _set(0.04, 0.05)], [0.042, 0.06], 0.95)
    assert out.mu_low is None and out.mu_high is None and "do not overlap" in out.status


def test_extra_windows_are_checked():
    for bad in (0.06, (0.06, float("nan")), (0.0,), (-0.06,), (float("inf"),)):
        with pytest.raises(ParameterError, match="sg_extra_windows_s"):
            AnalysisOptions(sg_extra_windows_s=bad)


def test_windows_the_record_cannot_hold_are_left_out():
    # off by default (docs: a longer window's own set is not honest enough on its own)
    assert inference_windows(3072, 1 / 4500, AnalysisOptions()) == [0.042]
    opt = AnalysisOptions(sg_extra_windows_s=(0.06,))
    assert inference_windows(3072, 1 / 4500, opt) == [0.042, 0.06]
    # 60 ms is 270 samples: with 40 trusted samples the record needs 311
    assert inference_windows(310, 1 / 4500, opt) == [0.042]
    assert inference_windows(3072, 1 / 4500, opt.with_(sg_extra_windows_s=())) == [0.042]
    assert inference_windows(3072, 1 / 4500, opt.with_(estimator="report")) == [0.042]
    # a shorter "extra" window is not one
    assert inference_windows(3072, 1 / 4500, opt.with_(sg_window_s=0.08)) == [0.08]


def test_intersection_is_sharper_than_the_primary_window_on_the_harsh_family():
    """12 tracks-level recordings of the harsh twin: the reported set lies inside every
    window's set, holds mu, and its median width is below the primary window's own 95 % set
    (the feature's reason to exist; the test prints both medians)."""
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    inter = AnalysisOptions(sg_extra_windows_s=(0.06,))
    both, alone = [], []
    for seed in range(40, 52):
        times, x, y, ball, _ = scenario_tracks(seed)
        _, s = analyse_tracks(times, x, y, l=ball.l, d=ball.d, options=inter)
        _, s1 = analyse_tracks(times, x, y, l=ball.l, d=ball.d)
        lo, hi = s["mu_low"], s["mu_high"]
        assert lo is not None and hi is not None and lo <= ball.mu <= hi, (seed, lo, hi)
        assert s["confidence"] == 0.95
        for w in s["model_fit"]["windows"]:
            assert abs(w["confidence"] - 0.975) < 1e-12
            assert w["mu_low"] is None or w["mu_low"] <= lo
            assert w["mu_high"] is None or w["mu_high"] >= hi
        both.append(s["relative_width"])
        alone.append(s1["relative_width"])
    print(f"\nseeds 40-51: median relative width {np.median(both):.1%} intersected (42 + 60 ms, "
          f"each at 97.5 %), {np.median(alone):.1%} for 42 ms alone at 95 %")
    assert np.median(both) < 0.9 * np.median(alone)
