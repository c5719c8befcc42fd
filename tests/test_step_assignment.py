"""Which controller sample each step of a found staircase fell on
(measurement.kinematics.step_assignment): the box's enumeration is exact in the sine's start,
each row is given by its sine, and the drive's own assignment wins the score."""
from __future__ import annotations

import math

import numpy as np
import pytest

from abu_model.loop_response import response, sampled
from measurement.kinematics.staircase_guess import ROUNDING_OFFSETS, SineStaircase
from measurement.kinematics.step_assignment import assignments, best_assignment

TWO_PI = 2 * math.pi


def _k(start: float, te: float, span: float, stair: SineStaircase, period: float):
    """The samples a sine puts its steps on (sampled()'s rule: first sample at or after)."""
    return np.ceil((start + te * stair.step_fractions(span)) / period - 1e-9)


@pytest.mark.parametrize("seed", range(6))
def test_every_assignment_of_a_start_in_the_box_is_enumerated(seed):
    """For the box's durations and spans, every start within +- a sample gives one of the rows
    (4000 random starts: a grid of 17 starts misses assignments whose interval is narrower
    than its spacing), and every row is the one its sine gives."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(4, 16))
    stair = SineStaircase(0.0, ROUNDING_OFFSETS[("lead", "nearest", "trail")[seed % 3]], n,
                          -TWO_PI * 9.0, -1.0, TWO_PI)
    period = float(rng.choice([1e-4, 2.5e-4, 5e-4, 1 / 3000]))
    te, span, start = rng.uniform(0.2, 0.7), n + rng.uniform(0.1, 0.9), rng.uniform(0.0, 0.1)
    rows, sines = assignments(stair, te, span, {}, start, period)
    assert rows.shape[0] == sines.shape[0] > 0
    assert np.all(np.diff(rows, axis=1) > 0)
    for row, (shift, te_i, span_i) in zip(rows, sines):
        assert abs(shift) <= period
        assert np.array_equal(_k(start + shift, te_i, span_i, stair, period), row)
    known = {tuple(r) for r in rows.astype(int)}
    tes, spans = np.unique(sines[:, 1]), np.unique(sines[:, 2])
    for _ in range(40):   # 40 of the box's (te, span) pairs, 100 random starts each
        te_i, span_i = rng.choice(tes), rng.choice(spans)
        shifts = rng.uniform(-period, period, 100)
        k = np.ceil((start + shifts[:, None] + te_i * stair.step_fractions(span_i)[None, :])
                    / period - 1e-9).astype(int)
        for row in k[np.all(np.diff(k, axis=1) > 0, axis=1)]:
            assert tuple(row) in known, (te_i, span_i, row)

def test_the_drives_own_assignment_scores_best_against_its_loop():
    """A digital loop's record (closed form, a 2 kHz controller, noise 1e-4 rad): about the
    true loop, the best assignment in a box around a sine a little off (start 0.3 sample, te
    0.2 %, span 0.005 step) is the drive's own, step for step but for a common shift."""
    rng = np.random.default_rng(5)
    period, fps = 5e-4, 2000.0
    stair = SineStaircase(0.05, 1.0, 11, -TWO_PI * 9.0, -1.0, TWO_PI)
    te, span = 0.2992, 11.668
    setpoints = stair.setpoints(te, span)
    t = np.arange(int(0.5 * fps)) / fps
    p = np.array([0.0, 0.55, 22.0, 0.015, 0.65, 0.0])
    drive = sampled(setpoints, period)
    theta = response(drive, t, p[1], p[2], p[3], p[4], True).theta + 1e-4 * \
        rng.standard_normal(t.size)
    off = SineStaircase(0.05 + 0.3 * period, 1.0, 11, -TWO_PI * 9.0, -1.0, TWO_PI)
    chosen = best_assignment(t, theta, off, te * 1.002, span + 0.005, {}, p, period, 0)
    assert chosen is not None
    # step for step, but for a shift common to all (the time offset's, fitted after)
    d = chosen.times_s - np.asarray(drive.step_times)
    assert np.ptp(d) < 1e-9 and abs(d[0]) <= 3 * period, d


@pytest.mark.parametrize("seed", range(8))
def test_quick_scores_equal_the_direct_residuals(seed):
    """quick_scores (the loop's linearity: one response per distinct sample) against each
    assignment's own response and projection (_sse_off of _theta, the scoring before it): the
    same sums to 1e-8 relative and the same best row, on random staircases, loops (lag and
    setpoint filter or none), sample times at and below the frame interval and a box of rows
    up to two samples either way of a drive's."""
    from abu_model.loop_response import Setpoints
    from measurement.kinematics import step_assignment as sa
    rng = np.random.default_rng([seed, 31])
    fps = float(rng.choice([2000.0, 4500.0]))
    t = np.arange(int(rng.uniform(500, 3000))) / fps
    period = float(rng.choice([1.0, 0.5, 0.2])) / fps
    n = int(rng.integers(3, 12))
    levels = tuple(rng.uniform(-100, 100) + np.arange(n + 1) * TWO_PI * rng.choice([-1, 1]))
    drive_k = np.ceil(np.sort(rng.uniform(0.02, 0.8 * t[-1], n)) / period)
    rows = np.unique(drive_k[None, :] + rng.integers(-2, 3, (300, n)), axis=0)
    rows = rows[np.all(np.diff(rows, axis=1) > 0, axis=1)]
    p = np.array([rng.uniform(-1e-3, 1e-3), rng.uniform(0.5, 1.0), rng.uniform(8, 40),
                  rng.choice([0.0, rng.uniform(0, 0.01)]), rng.uniform(0.5, 1.0),
                  rng.choice([0.0, rng.uniform(0, 0.01)])])

    def at(k):
        return Setpoints(tuple(np.multiply(k, period).tolist()), levels)
    theta = sa._theta(at(rows[0]), t, p) + 1e-4 * rng.standard_normal(t.size) + 0.3
    _, q = sa._design(t, at(rows[rows.shape[0] // 2]), p, sa.linear_basis(t, theta, 3))
    direct = np.array([sa._sse_off(theta - sa._theta(at(k), t, p), q) for k in rows])
    quick = sa.quick_scores(t, theta, rows, period, levels, p, q)
    assert np.max(np.abs(quick - direct) / direct) < 1e-8
    assert int(np.argmin(quick)) == int(np.argmin(direct))
