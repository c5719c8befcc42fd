"""omega_dot's noise in the predicted slip (``InferenceOptions.drive_noise``).

In slip the model integrates u' = omega^2 (q - mu_d) / 1.4 with the *measured* q. Near the
onset q - mu_d is a small difference, so a noise error of a few per cent of q changes the
emerging slip by tens of per cent, and the fit moved the onset (hence mu) to absorb it: the
scale nuisance on q covers an error of q's level, not of its course after the onset. Cases
(unseen by any tuning): harsh-family seed 3054 (lower bound 7.3 % above mu; with the true
kinematics the same beta gives [0.0133, 0.0171] around mu = 0.01354: measured q swung from
-33 % to +25 % of the truth within 10 ms of the onset) and the 2000 frames/s twin of
tests/test_frame_rate.py ([0.03014, 0.03482] for mu = 0.03; q -1 % before, +2 % after the
onset).
"""
from __future__ import annotations


import numpy as np

from measurement.inference.noise_models import drive_noise_cov
from rendered_seed import render_and_measure


def test_drive_noise_covariance_matches_a_monte_carlo_double_integration():
    rng = np.random.default_rng(5)
    n, h, i_on, gain = 120, 1e-3, 40, 0.6
    kernel = np.hanning(15)                       # correlated noise: a moving average
    rho = np.correlate(kernel, kernel, mode="full")[kernel.size - 1:] / float(kernel @ kernel)
    sigma = np.linspace(2.0, 4.0, n)              # rad/s^2, varying along the record
    draws = 20000
    white = rng.standard_normal((draws, n + kernel.size - 1))
    e = np.array([np.convolve(w, kernel, mode="valid") for w in white])
    e *= sigma / np.sqrt(float(kernel @ kernel))
    d = np.zeros((draws, n))
    d[:, i_on:] = gain * h * h * np.cumsum(np.cumsum(e[:, i_on:], axis=1), axis=1)
    emp = d.T @ d / draws
    cov = drive_noise_cov(sigma, rho, h, i_on, gain)
    assert np.all(cov[:i_on] == 0) and np.all(cov[:, :i_on] == 0)
    for i, j in ((60, 60), (90, 70), (119, 119), (119, 45)):
        np.testing.assert_allclose(cov[i, j], emp[i, j], rtol=0.05)


def test_seed_3054_holds_mu(tmp_path, capsys):
    """Rendered end to end: the interval holds mu (was [0.01453, 0.02558] for 0.01354).

    Tracked as when this was measured, by the contour fits alone (``--no-edge-step``); with
    the tracker's edge step on the centre and CD markers (the default since) the interval
    still holds mu, wider: [0.00408, 0.02223], 138 % (the step on all three: 92 %)."""
    summary, mu = render_and_measure(3054, tmp_path, "--no-edge-step")
    assert summary["mu_low"] <= mu <= summary["mu_high"]
    assert summary["relative_width"] < 0.8
    default, _ = render_and_measure(3054, tmp_path)
    assert default["mu_low"] <= mu <= default["mu_high"]
    capsys.readouterr()
