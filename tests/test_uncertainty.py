"""The report's worst-case error analysis (sec. 5.4) and the Monte Carlo noise propagation."""
from __future__ import annotations

import numpy as np
import pytest

from abu_model.errors import ParameterError
from measurement.inference.analysis import AnalysisOptions, analyse_tracks
from measurement.inference.running_max import mu_required
from measurement.inference.uncertainty import (monte_carlo, perturbed_mu_factor, pixel_noise,
                                     widen_interval, worst_case_relative_error)
from synthetic_tracks import measured_pixels, simulate


def test_reports_worst_case_is_11_6_percent():
    low, high = worst_case_relative_error(0.03, 0.05)
    # Report sec. 5.4: "an error of 3 % in omega and 5 % in omega_dot ... maximum error 11.6 %".
    assert round(100 * high, 1) == 11.6
    assert high == pytest.approx(1.05 / 0.97**2 - 1)
    assert low == pytest.approx(0.95 / 1.03**2 - 1)


def test_factor_equals_recomputing_mu_from_perturbed_kinematics():
    omega, alpha, l, d = np.array([-70.0]), np.array([-95.0]), 1.15e-2, 3.0e-3
    mu = mu_required(omega, alpha, l, d)[0]
    for e_w, e_a in [(0.03, 0.05), (-0.03, 0.05), (0.02, -0.04)]:
        mu_t = mu_required(omega * (1 + e_w), alpha * (1 + e_a), l, d)[0]
        assert mu_t / mu == pytest.approx(perturbed_mu_factor(e_w, e_a))


def test_widened_interval_contains_every_true_value_behind_the_computed_bounds():
    lo, hi = widen_interval(0.0286, 0.0312)
    rng = np.random.default_rng(0)
    for _ in range(200):
        e_w, e_a = rng.uniform(-0.03, 0.03), rng.uniform(-0.05, 0.05)
        factor = perturbed_mu_factor(e_w, e_a)
        # A true value mu computed with these errors gives mu * factor; if that computed value is
        # a bound, the true value lies within the widened interval.
        assert lo <= 0.0286 / factor and 0.0312 / factor <= hi
    assert widen_interval(None, 0.03)[0] is None


def test_error_inputs_are_validated():
    with pytest.raises(ParameterError, match="e_omega"):
        worst_case_relative_error(1.2, 0.05)
    with pytest.raises(ParameterError, match="mc_draws"):
        monte_carlo(lambda x, y: (0.0, 0.0), np.zeros((5, 3)), np.zeros((5, 3)),
                    np.zeros((3, 2)), draws=0)


def test_monte_carlo_engine_against_a_closed_form_spread():
    # run = mean x of the centre marker: its spread over draws is sigma / sqrt(N).
    n = 400
    x = np.zeros((n, 3))
    y = np.zeros((n, 3))
    sigma = np.array([[0.2, 0.1], [0.0, 0.0], [0.0, 0.0]])
    res = monte_carlo(lambda xn, yn: (xn[:, 0].mean(), yn[:, 0].mean()), x, y, sigma,
                      draws=400, seed=7)
    assert res["mu_low"]["std"] == pytest.approx(0.2 / np.sqrt(n), rel=0.12)
    assert res["mu_high"]["std"] == pytest.approx(0.1 / np.sqrt(n), rel=0.12)
    assert res["mu_low"]["p2.5"] < res["mu_low"]["p50"] < res["mu_low"]["p97.5"]
    again = monte_carlo(lambda xn, yn: (xn[:, 0].mean(), yn[:, 0].mean()), x, y, sigma,
                        draws=400, seed=7)
    assert again == res


def test_pixel_noise_measures_tracking_noise_on_moving_markers():
    rec = simulate(0.02, "steps", n=1200)
    x, y = measured_pixels(rec, sigma_px=0.04, seed=3)
    np.testing.assert_allclose(pixel_noise(x, y), 0.04, rtol=0.1)


def test_monte_carlo_spread_of_the_bounds_grows_with_the_noise():
    rec = simulate(0.02, "steps", n=1500)
    spreads = []
    for sigma_px in (0.01, 0.05):
        x, y = measured_pixels(rec, sigma_px=sigma_px, seed=1)
        # the Monte Carlo propagates noise through the running-max interval; its estimator
        # of design (20 ms cubic Savitzky-Golay)
        _, s = analyse_tracks(rec.time, x, y, options=AnalysisOptions(
            mc_draws=8, seed=2, sg_window_s=0.02, sg_polyorder=3))
        mc = s["monte_carlo"]
        assert mc["draws"] == 8 and mc["mu_low"]["n_defined"] == 8
        np.testing.assert_allclose(mc["sigma_px"], sigma_px, rtol=0.15)
        spreads.append(mc["mu_low"]["p97.5"] - mc["mu_low"]["p2.5"])
    assert spreads[1] > 2.0 * spreads[0]


def test_whitener_matches_numpy_inverse_on_covariance_factors():
    """The whitener equals ``np.linalg.inv`` of the same Cholesky factor (sizes below, at and
    across its block of 128 rows; white + exponential covariances of several tau)."""
    from measurement.inference.noise_models import leftover_whitener_of

    rng = np.random.default_rng(5)
    for n in (1, 7, 64, 128, 129, 300, 827):
        for tau in (1e-4, 4e-3, 2e-2):
            noise = {"sigma_white_rad": rng.uniform(1e-4, 1e-3),
                     "sigma_leftover_rad": rng.uniform(0.0, 2e-3), "leftover_tau_s": tau}
            winv = leftover_whitener_of(noise, n, 1 / 4500).matrix()
            h = 1 / 4500
            corr = noise["sigma_leftover_rad"] ** 2 * np.exp(-(np.arange(n) * h) / tau)
            cov = corr[np.abs(np.arange(n)[:, None] - np.arange(n)[None, :])]
            cov[np.diag_indices(n)] += noise["sigma_white_rad"] ** 2
            ref = np.linalg.inv(np.linalg.cholesky(cov))
            assert np.abs(winv - ref).max() <= 1e-12 * np.abs(ref).max(), (n, tau)
            assert np.allclose(winv @ cov @ winv.T, np.eye(n), atol=1e-9)
            assert np.all(np.triu(winv, 1) == 0.0)
