"""mu_req, running maximum, the creep model against the exact plant, and the interval on mu
from synthetic records whose true mu and slip instant are known."""
from __future__ import annotations

import math

import numpy as np
import pytest

from abu_model.errors import ParameterError
from measurement.inference.analysis import AnalysisOptions, analyse_tracks
from measurement.inference.running_max import (BOUNDS_STATUS, IntervalOptions, mu_required,
                                               predicted_creep, running_max)
from synthetic_tracks import measured_pixels, simulate

M, D, L = 1.4e-4, 3.0e-3, 1.15e-2


@pytest.fixture(scope="module")
def ramp():
    # Linear acceleration profile (report sec. 4.1): slip at a known instant, continuous alpha.
    return simulate(0.015, "ramp")


@pytest.fixture(scope="module")
def steps():
    # Staircase-like acceleration jumps: the ball slips at a jump (t = 0.16 s).
    return simulate(0.02, "steps")


def test_mu_required_is_the_reports_eq_4_7():
    # mu = {m l^2 - (2l/d) J} |omega_dot| / (m l^2 omega^2), J = m d^2 / 10 (report eq. 4.7).
    J = M * D**2 / 10
    omega, alpha = -70.0, -95.0
    expected = (M * L**2 - 2 * L / D * J) * abs(alpha) / (M * L**2 * omega**2)
    assert mu_required(np.array([omega]), np.array([alpha]), L, D)[0] == pytest.approx(expected)


def test_running_max_over_the_trusted_region_only():
    v = np.array([9.0, 1.0, 3.0, 2.0, 5.0, 4.0, 9.0])
    trusted = np.array([0, 1, 1, 1, 1, 1, 0], dtype=bool)
    out = running_max(v, trusted)
    assert math.isnan(out[0])
    np.testing.assert_array_equal(out[1:], [1.0, 3.0, 3.0, 5.0, 5.0, 5.0])


@pytest.mark.parametrize("name", ["ramp", "steps"])
def test_creep_model_matches_the_exact_plant(name, request):
    rec = request.getfixturevalue(name)
    assert math.isfinite(rec.t_slip)
    creep = predicted_creep(rec.time, rec.omega, rec.alpha, np.array([rec.mu, 2 * rec.mu]),
                            rec.l, rec.d, +1, 0, rec.time.size - 1)
    moved = rec.beta - rec.beta[0]
    # Same stick/slip law integrated two independent ways (exact switches vs sample steps).
    assert np.abs(creep[0] - moved).max() < 0.02 * moved.max()
    before = rec.time < rec.t_slip - 1e-3
    assert np.all(creep[0][before] == 0.0)
    # More friction, less (here: no) slip.
    assert np.all(creep[1] <= creep[0] + 1e-15)


def interval_for(rec, seed, **opts):
    x, y = measured_pixels(rec, sigma_px=0.03, harmonic_px=0.4, seed=seed)
    _, summary = analyse_tracks(rec.time, x, y, l=rec.l, d=rec.d,
                                options=AnalysisOptions(**opts))
    return summary


@pytest.mark.parametrize("name", ["ramp", "steps"])
def test_interval_contains_the_true_mu(name, request):
    rec = request.getfixturevalue(name)
    for seed in range(4):
        # the reported interval (default analysis: hull of the model-based set and the
        # running max) holds mu
        d = interval_for(rec, seed)
        assert d["status"] == "ok"
        assert d["mu_low"] <= rec.mu <= d["mu_high"], (seed, d["mu_low"], d["mu_high"])
        # the onset bracket (from the model's set) holds the true slip instant (its upper end
        # is null where the measured q never reaches mu_high inside the trusted region)
        t_hi = math.inf if d["t_slip_high"] is None else d["t_slip_high"]
        assert d["t_slip_low"] is not None
        assert d["t_slip_low"] <= rec.t_slip <= t_hi, (seed, d["t_slip_low"], rec.t_slip, t_hi)
        assert d["onset_bracket"]["t_slip_low"] == d["t_slip_low"]
        # the running-max construction, with the estimator it was designed with (20 ms cubic)
        s = interval_for(rec, seed, sg_window_s=0.02, sg_polyorder=3)["running_max"]
        assert s["status"] == BOUNDS_STATUS and s["coverage_tested"] is False
        assert s["mu_low"] <= rec.mu <= s["mu_high"], (seed, s["mu_low"], s["mu_high"])
        # The surely-slipping time cannot precede the true slip, and the detection lag is short.
        assert rec.t_slip <= s["t_slip_high"] < rec.t_slip + 0.06
        assert s["t_slip_low"] < s["t_slip_high"]
        # Informative: at this noise the 3-sigma bars cost ~10 % on each side, and on the ramp
        # mu_req keeps rising during the detection lag (~30 ms, another ~15 %).
        assert s["mu_high"] < 1.35 * rec.mu and s["mu_low"] > 0.8 * rec.mu


def test_no_slip_gives_only_a_lower_bound():
    rec = simulate(0.03, "steps", n=1500)        # max mu_req ~0.023 < 0.03: the ball sticks
    assert math.isinf(rec.t_slip)
    # the running-max logic with the estimator it was designed with (Savitzky-Golay 20 ms, cubic)
    rm = interval_for(rec, 0, sg_window_s=0.02, sg_polyorder=3)["running_max"]
    s = interval_for(rec, 0)
    assert rm["mu_high"] is None and rm["t_slip_high"] is None
    assert rm["status"].startswith("no slip detected")
    assert rm["mu_low"] <= rec.mu
    # With no slip, the whole trusted record counts: the bound is close to the largest mu_req.
    true_max = np.nanmax(mu_required(rec.omega, rec.alpha, rec.l, rec.d)[100:-100])
    assert rm["mu_low"] > 0.85 * true_max
    # The model-based set: a null upper bound, never "ok" with numbers.
    assert s["mu_high"] is None and s["status"].startswith("no slip")
    assert s["mu_low"] is not None and s["mu_low"] <= rec.mu


def test_band_method_uses_the_last_time_at_the_stick_level(steps):
    s_band = interval_for(steps, 1, interval=IntervalOptions(lower="band"))["running_max"]
    s_creep = interval_for(steps, 1)["running_max"]
    assert s_band["mu_high"] == pytest.approx(s_creep["mu_high"])
    assert s_band["t_slip_low"] < s_band["t_slip_high"]


def test_interval_options_are_validated():
    with pytest.raises(ParameterError, match="lower"):
        IntervalOptions(lower="guess")
    with pytest.raises(ParameterError, match="k_sigma"):
        IntervalOptions(k_sigma=0.0)
    with pytest.raises(ParameterError, match="false_alarm"):
        IntervalOptions(false_alarm=1.5)
