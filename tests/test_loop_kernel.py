"""The loop response's compiled kernel (``abu_model._loopc``) against its NumPy reference
(``loop_response._response_numpy``), and :func:`~abu_model.loop_response.modes` against a
second root finder (``np.roots`` and the residue formula on its roots).

The random family (seeded, each case printed on failure): 1-5000 times, equally spaced at
0.5-20 kHz from -0.2 to 0.3 s, or random sorted times, or either with every step's own time
added (samples exactly on steps); 1-14 steps of +-1 Hz at random times from -0.1 to 1 s (before,
inside and after the times) about a level of -150 to 150 rad/s; loops zeta 0.05-1.5 (and 1
exactly: a double pole), omega_n 1-200 rad/s, no lag or one up to 80 % of the stable limit,
weight 0.3-1, no setpoint filter or 0.1-50 ms (and one on the loop's double pole).
"""
from __future__ import annotations

import numpy as np
import pytest

from abu_model import loop_response as L

KERNEL = L._loopc
REL_TOL = 1e-9     # of max |x| of the case (see the test), theta, omega and alpha
needs_kernel = pytest.mark.skipif(KERNEL is None,
                                  reason="compiled kernel not built (test_the_kernel_is_built)")


def test_the_kernel_is_built():
    assert KERNEL is not None, ("abu_model._loopc is not built: run `pip install -e .` (or "
                                "`python setup.py build_ext --inplace`) with a C compiler")


def _case(seed: int):
    rng = np.random.default_rng([seed, 88])
    k = int(rng.integers(1, 15))
    tk = np.sort(rng.uniform(-0.1, 1.0, k))
    levels = rng.uniform(-150, 150) + np.cumsum(np.r_[0.0, rng.choice([-1, 1], k) * 2 * np.pi])
    n = int(rng.integers(1, 5000))
    kind = rng.integers(3)
    if kind == 0:
        t = rng.uniform(-0.2, 0.3) + np.arange(n) / rng.uniform(500, 20000)
    elif kind == 1:
        t = np.sort(rng.uniform(-0.2, 1.2, n))
    else:
        t = np.sort(np.r_[rng.uniform(-0.2, 0.3) + np.arange(n) / rng.uniform(500, 20000), tk])
    zeta = 1.0 if rng.uniform() < 0.1 else rng.uniform(0.05, 1.5)
    wn = rng.uniform(1.0, 200.0)
    tau = 0.0 if rng.uniform() < 0.3 else rng.uniform(0.0, 0.8) * 2 * zeta / wn
    tau_f = [0.0, rng.uniform(1e-4, 0.05), 1.0 / wn][int(rng.integers(3))]
    loop = (zeta, wn, tau, rng.uniform(0.3, 1.0), tau_f)
    return L.Setpoints(tuple(tk), tuple(levels)), t, loop


@needs_kernel
@pytest.mark.parametrize("seed", range(200))
def test_kernel_matches_the_reference(seed):
    sp, t, (zeta, wn, tau, b, tau_f) = _case(seed)
    poles, res = L.modes(zeta, wn, tau, b, tau_f)
    got = L.response(sp, t, zeta, wn, tau, b, True, setpoint_tau=tau_f)
    ref = L._response_numpy(sp, t, poles, res, True)
    for name in ("theta", "omega", "alpha"):
        x, y = getattr(got, name), getattr(ref, name)
        # at least 1 (alpha ~ 0 before or long after the steps), times the largest residue
        # where poles nearly coincide (terms of that size cancel to the result; the two paths
        # round them differently: a triple pole, seed 196, |c| ~ 1e9)
        scale = max(float(np.max(np.abs(y))), 1.0) * max(1.0, float(np.max(np.abs(res))))
        assert np.max(np.abs(x - y)) <= REL_TOL * scale, (seed, name, t.size, len(sp.step_times))
    fast = L.response(sp, t, zeta, wn, tau, b, False, setpoint_tau=tau_f)
    assert fast.theta.size == 0 and np.array_equal(fast.alpha, got.alpha)


def test_a_constant_setpoint_holds_its_level():
    """No steps (a setpoint held throughout): omega at the level, alpha 0, theta its ramp, in
    the kernel and the reference alike."""
    sp = L.Setpoints((), (-40.0,))
    t = np.arange(100) / 1000.0
    for r in (L.response(sp, t, 0.7, 20.0, 0.01, 0.8, setpoint_tau=0.005),
              L._response_numpy(sp, t, *L.modes(0.7, 20.0, 0.01, 0.8, 0.005), True)):
        assert np.allclose(r.omega, -40.0) and np.allclose(r.alpha, 0.0)
        assert np.allclose(r.theta, -40.0 * t)


@needs_kernel
def test_times_in_any_order_or_not_finite_take_the_reference():
    """The kernel walks increasing times; others go to the reference (same values), with no
    error and nothing half-written."""
    sp, t, (zeta, wn, tau, b, tau_f) = _case(3)
    rng = np.random.default_rng(5)
    shuffled = rng.permutation(t)
    got = L.response(sp, shuffled, zeta, wn, tau, b, True, setpoint_tau=tau_f)
    ref = L._response_numpy(sp, shuffled, *L.modes(zeta, wn, tau, b, tau_f), True)
    assert np.array_equal(got.theta, ref.theta) and np.array_equal(got.alpha, ref.alpha)
    with_nan = t.copy()
    with_nan[len(t) // 2] = np.nan
    with np.errstate(invalid="ignore"):
        got = L.response(sp, with_nan, zeta, wn, tau, b, setpoint_tau=tau_f)
    assert np.isnan(got.omega[len(t) // 2])
    # a level not finite: NaN out, no error
    bad = L.Setpoints(sp.step_times, (np.nan,) + tuple(sp.levels[1:]))
    with np.errstate(invalid="ignore"):
        got = L.response(bad, t, zeta, wn, tau, b, setpoint_tau=tau_f)
    assert np.all(np.isnan(got.omega))


@needs_kernel
def test_bad_buffers_are_refused():
    t = np.arange(10.0)
    tk, dw = np.array([1.0, 2.0]), np.array([1.0, 1.0])
    p, c = L.modes(0.7, 10.0)
    outs = [np.empty(10) for _ in range(3)]
    KERNEL.response(t, tk, dw, p, c, 0.0, True, *outs)     # the right call runs
    with pytest.raises(ValueError):                          # dW shorter than tk
        KERNEL.response(t, tk, dw[:1], p, c, 0.0, True, *outs)
    with pytest.raises(ValueError):                          # an output shorter than t
        KERNEL.response(t, tk, dw, p, c, 0.0, True, outs[0][:5], outs[1], outs[2])
    with pytest.raises(ValueError):                          # residues not one per pole
        KERNEL.response(t, tk, dw, p, c[:1], 0.0, True, *outs)
    with pytest.raises(ValueError):                          # decreasing times
        KERNEL.response(t[::-1].copy(), tk, dw, p, c, 0.0, True, *outs)
    with pytest.raises(ValueError):                          # decreasing step times
        KERNEL.response(t, tk[::-1].copy(), dw, p, c, 0.0, True, *outs)
    for bad in (np.array([1.0, np.nan]), np.array([1.0, np.inf])):
        with pytest.raises(ValueError):                      # a step time not finite
            KERNEL.response(t, bad, dw, p, c, 0.0, True, *outs)
        with pytest.raises(ValueError):                      # a step size not finite
            KERNEL.response(t, tk, bad, p, c, 0.0, True, *outs)
    with pytest.raises(ValueError):                          # the first level not finite
        KERNEL.response(t, tk, dw, p, c, np.nan, True, *outs)
    with pytest.raises(TypeError):                           # an output not writable
        KERNEL.response(t, tk, dw, p, c, 0.0, True, b"x" * 80, outs[1], outs[2])


@pytest.mark.parametrize("seed", range(40))
def test_modes_match_a_second_root_finder(seed):
    """Poles by np.roots of the whole denominator, residues N(p) / (p D'(p)) by np.polyder:
    the same to 1e-8 (cases with poles within 1e-3 of each other left out: modes() splits
    those on purpose, tests/test_drive_model.py checks them against exact solvers)."""
    rng = np.random.default_rng([seed, 9])
    for _ in range(25):
        zeta, wn = rng.uniform(0.05, 2.0), rng.uniform(1.0, 200.0)
        tau = 0.0 if rng.uniform() < 0.3 else rng.uniform(0.0, 0.9) * 2 * zeta / wn
        tau_f = 0.0 if rng.uniform() < 0.4 else rng.uniform(1e-4, 0.1)
        num, den = L.loop_polynomials(zeta, wn, tau, 0.7, tau_f)
        roots = np.roots(den)
        gaps = np.abs(roots[:, None] - roots[None, :]) + np.eye(roots.size)
        if gaps.min() < 1e-3 * np.abs(roots).max():
            continue
        res = np.polyval(num, roots) / (roots * np.polyval(np.polyder(den), roots))
        poles, residues = L.modes(zeta, wn, tau, 0.7, tau_f)
        order = [int(np.argmin(np.abs(roots - p))) for p in poles]
        assert sorted(order) == list(range(roots.size))
        assert np.allclose(poles, roots[order], rtol=1e-8, atol=0)
        assert np.allclose(residues, res[order], rtol=1e-8, atol=1e-12)
