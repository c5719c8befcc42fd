"""The noise model's structured linear algebra against the dense expressions it replaces
(``measurement.inference.noise_models``): the whitener's forward substitution by blocks,
the symmetric Toeplitz builder, the drive noise covariance's in-place sums, and the whitening
of :class:`Gls` from a model row's first non-zero column.

Each was checked against a deliberate bug: a substitution that skips the last block, or
reads the factor one row off, fails the whitener's comparisons; a window start inside a
block taken from the block's start fails the leading-zeros test; a Toeplitz builder whose
rows are not reversed fails its comparison (its first row would be the last lag's).
"""
from __future__ import annotations

import numpy as np
import pytest

from measurement.inference.noise_models import (Gls, TriangularWhitener, drive_noise_cov,
                                                leftover_whitener_of, toeplitz_symmetric)


def _lower(rng: np.random.Generator, n: int) -> np.ndarray:
    return np.tril(rng.normal(size=(n, n))) + n * np.eye(n)


@pytest.mark.parametrize("n", [1, 5, 128, 129, 256, 300, 1031])
def test_whitener_equals_the_inverse_factor(n):
    """Below, at and across the block of 128 rows, and an odd size with a ragged last
    block: rows, columns and the matrix against ``np.linalg.inv`` of the factor."""
    rng = np.random.default_rng(n)
    lower = _lower(rng, n)
    ref = np.linalg.inv(lower)
    w = TriangularWhitener(lower)
    np.testing.assert_allclose(w.matrix(), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    for rows in (1, 7, 230):
        a = rng.normal(size=(rows, n))
        want = a @ ref.T
        np.testing.assert_allclose(w.rows(a), want, rtol=0, atol=1e-12 * np.abs(want).max())
        want = ref @ a.T
        np.testing.assert_allclose(w.columns(a.T), want, rtol=0,
                                   atol=1e-12 * np.abs(want).max())
    x = rng.normal(size=n)
    assert w.columns(x).shape == (n,)


def test_symmetric_toeplitz_equals_the_index_matrix():
    rng = np.random.default_rng(3)
    for n in (1, 2, 9, 400):
        first = rng.normal(size=n)
        ref = first[np.abs(np.arange(n)[:, None] - np.arange(n)[None, :])]
        got = toeplitz_symmetric(first)
        assert np.array_equal(got, ref)
        assert got.flags.writeable and got.flags.c_contiguous   # a copy, not a strided view


def test_drive_noise_covariance_equals_the_dense_double_sum():
    """The in-place cumulative sums give the double sum P C P^T as matrix products."""
    rng = np.random.default_rng(11)
    n, i_on, h, gain = 700, 230, 1 / 4500, 0.68
    sigma = rng.uniform(0.5, 2.0, n)
    rho = np.exp(-np.arange(60) / 12.0)
    got = drive_noise_cov(sigma, rho, h, i_on, gain)
    s, m = sigma[i_on:], n - i_on
    r = np.zeros(m)
    r[:rho.size] = rho
    c = s[:, None] * s[None, :] * r[np.abs(np.arange(m)[:, None] - np.arange(m)[None, :])]
    p = np.tril(np.arange(m)[:, None] - np.arange(m)[None, :] + 1.0)   # double cumulative sum
    ref = np.zeros((n, n))
    ref[i_on:, i_on:] = (gain * h * h) ** 2 * (p @ c @ p.T)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-12 * np.abs(ref).max())
    assert np.all(got[:i_on] == 0.0) and np.all(got[:, :i_on] == 0.0)


@pytest.mark.parametrize("zeros", [0, 1, 127, 128, 317, 899])
def test_whitening_with_leading_zeros_equals_the_dense_product(zeros):
    """Gls whitens model rows that are zero while the candidate ball sticks from their first
    non-zero column on (inside a block, at its edge, the last column): the same as the whole
    product, for a window of several blocks."""
    rng = np.random.default_rng(7)
    n = 900
    w = leftover_whitener_of({"sigma_white_rad": 5e-4, "sigma_leftover_rad": 3e-4,
                              "leftover_tau_s": 0.004}, n, 1 / 4500)
    winv = w.matrix()
    gls = Gls(rng.normal(size=n), np.ones((n, 1)), 0.0, w)
    a = rng.normal(size=(40, n))
    a[:, :zeros] = 0.0
    ref = a @ winv.T
    np.testing.assert_allclose(gls.whiten(a), ref, rtol=0, atol=1e-12 * np.abs(ref).max())
    assert np.all(gls.whiten(np.zeros((3, n))) == 0.0)
