"""The NumPy NNLS of measurement.kinematics.harmonic against SciPy's (an independent implementation)."""
import numpy as np
import pytest
from scipy.optimize import nnls as scipy_nnls

from measurement.kinematics.harmonic import nnls


@pytest.mark.parametrize("seed", range(12))
def test_nnls_matches_scipy_on_random_problems(seed):
    rng = np.random.default_rng(seed)
    m, n = rng.integers(5, 80), rng.integers(2, 60)
    a = rng.standard_normal((m, n))
    b = rng.standard_normal(m) * 3
    x, rn = nnls(a, b)
    xs, rns = scipy_nnls(a, b)
    assert np.all(x >= 0)
    assert rn == pytest.approx(rns, rel=1e-9, abs=1e-10)
    if m >= n:  # unique solution
        np.testing.assert_allclose(x, xs, atol=1e-8)


def test_nnls_exact_nonnegative_solution():
    rng = np.random.default_rng(1)
    a = np.triu(rng.uniform(0.5, 1.5, (40, 40)))
    x_true = np.where(rng.random(40) < 0.5, 0.0, rng.uniform(0, 2, 40))
    x, rn = nnls(a, a @ x_true)
    np.testing.assert_allclose(x, x_true, atol=1e-9)
    assert rn < 1e-9
