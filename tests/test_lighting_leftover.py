"""The lighting orders beyond the fitted ones as random effects (``lighting_leftover``).

The ball's apparent centre moves periodically with its world angle phi; the whole-record fit
removes orders 1-4. Harsh-family seed 3057 (never used for a choice before it was diagnosed)
kept 0.52 mrad of order 5 and 0.27 mrad of order 7: treated as short-correlated noise they
moved the onset and the interval [0.06213, 0.07836] missed mu = 0.05796 by 7.2 %.
"""
from __future__ import annotations

import math

import numpy as np

from measurement.inference.lighting_leftover import DETECT_SIGMAS, harmonic_leftover
from measurement.inference.types import InferenceOptions
from rendered_seed import render_and_measure


def _record(rng, amp_rad: dict[int, float], sigma_rad: float, n: int = 3072):
    phi = np.linspace(0.0, 35.0, n)                     # ~5.5 turns, as a 0.68 s record
    res = sigma_rad * rng.standard_normal(n)
    for k, a in amp_rad.items():
        res += a * np.sin(k * phi + 0.3 * k)
    return phi, res


def test_the_orders_amplitudes_are_measured_on_the_record():
    rng = np.random.default_rng(3)
    phi, res = _record(rng, {5: 5e-4, 7: 2.5e-4}, 1e-3)
    lh = harmonic_leftover(phi, res, slice(100, 800), (5, 6, 7, 8))
    assert lh is not None and lh.orders == (5, 7)      # 6 and 8: noise, left out
    amp = lh.amplitudes_rad()
    assert abs(amp["5"] - 5e-4) < 0.1 * 5e-4 and abs(amp["7"] - 2.5e-4) < 0.2 * 2.5e-4
    cov = lh.cov()
    assert cov.shape == (700, 700)
    # the covariance of a_k sin + b_k cos with var(a) = var(b) = A^2: A^2 cos(k dphi)
    i, j = 10, 250
    expect = sum(a ** 2 * math.cos(k * (phi[100 + i] - phi[100 + j]))
                 for k, a in ((5, amp["5"]), (7, amp["7"])))
    assert abs(cov[i, j] - expect) < 1e-12
    assert np.linalg.eigvalsh(cov).min() > -1e-15


def test_unfitted_samples_are_left_out():
    # NaN where the record was not fitted (residual) or not tracked (phase): the amplitudes come
    # from the other samples, and the window's covariance stays finite
    rng = np.random.default_rng(4)
    phi, res = _record(rng, {5: 5e-4}, 1e-3)
    res[:200] = np.nan
    phi[3000:] = np.nan
    lh = harmonic_leftover(phi, res, slice(300, 1000), (5, 6))
    assert lh is not None and lh.orders == (5,)
    assert abs(lh.amplitudes_rad()["5"] - 5e-4) < 0.1 * 5e-4
    assert np.isfinite(lh.cov()).all()


def test_white_noise_alone_gives_no_random_effect_mostly():
    # an order enters only above DETECT_SIGMAS of a noise sinusoid's amplitude over the window
    hits = 0
    for seed in range(40):
        phi, res = _record(np.random.default_rng(seed), {}, 1e-3)
        lh = harmonic_leftover(phi, res, slice(0, 700), (5, 6, 7, 8, 9, 10, 11, 12))
        hits += lh is not None
    assert DETECT_SIGMAS >= 2.0 and hits <= 2


def test_orders_already_fitted_are_not_counted_again():
    opt = InferenceOptions()
    assert not set(opt.leftover_orders) & set(opt.harmonic_orders)
    assert min(opt.leftover_orders) == max(opt.harmonic_orders) + 1


def test_seed_3057_holds_mu(tmp_path, capsys):
    """Rendered end to end: the interval holds mu (was [0.06213, 0.07836] for 0.05796)."""
    summary, mu = render_and_measure(3057, tmp_path)
    assert summary["mu_low"] <= mu <= summary["mu_high"]
    assert summary["relative_width"] < 0.7     # measured 0.61 ([0.0412, 0.0777])
    amp = summary["model_fit"]["noise_model"]["lighting_leftover_amp_rad"]
    assert amp["5"] > 3e-4                           # the order that moved the onset
    capsys.readouterr()
