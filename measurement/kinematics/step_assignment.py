"""Which controller sample each step of a found staircase fell on (SI): step 4 of
:mod:`measurement.kinematics.staircase_search`.

A digital speed controller applies a setpoint step at its first sample at or after the step
(:func:`abu_model.loop_response.sampled`). The staircase's continuous fit places the steps to
~0.1-0.5 % of te (the sampling biases it), but a step a fraction of a sample off lands on
another sample, which leaves a residual that is not white. So the sine near the continuous
fit is searched (:func:`assignments`: its start within +- a sample, its duration within +-
:data:`SINE_TE_REL`, its span within +- :data:`SINE_SPAN` step, or 3 of the continuous
fit's standard errors where wider, up to three times those), and each distinct assignment
of steps to samples is scored by its residual with the loop and time offset linearised and
projected out beside the nuisance terms (:func:`best_assignment`).

The same score ranks candidate sample times (the staircase search's
``_other_sample_times``): for a controller faster than the camera the continuous fit's
steps can fall many samples from the drive's, so a sample time is judged by its best
assignment, not by the steps as the continuous fit put them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from abu_model.loop_response import Setpoints, response

from measurement.kinematics.model_fit import linear_basis
from measurement.kinematics.staircase_guess import SineStaircase

#: Start shifts over +- a sample: one inside each interval between the shifts where a step
#: changes sample (exact: a grid of 17 shifts missed the drive's assignment of seed 1004 of
#: bench_staircase_search.py, whose interval is narrower than its spacing); durations over
#: +- SINE_TE_REL in SINE_TE_MIN to SINE_TE_MAX points; spans over +- the largest of
#: SINE_SPAN, 3 standard errors and the span change that moves a step by one sample (at most
#: SINE_SPAN_MAX), in 5 to SINE_SPAN_POINTS_MAX points; the best SINE_RESCORE assignments scored again.
#: Why so wide: the continuous fit's te and span are biased by the sampling, each step up to
#: a sample late, by up to 0.4 % in te (8 of its standard errors: the fast staircase of
#: tests/test_staircase_search.py) and up to a sample's worth in span (seed 1004: 0.022
#: step, 9 standard errors; its drive's assignment is outside +- 0.01 and refused there,
#: residual 2.1x the noise, against 1.01x over the drive's).
SINE_TE_MIN = 17
SINE_TE_REL = 0.006
SINE_TE_MAX = 161
SINE_SPAN = 0.01
SINE_SPAN_MAX = 0.1
SINE_SPAN_POINTS_MAX = 9
SINE_RESCORE = 5
#: The first scoring of every assignment runs on every this many samples (a ranking: the
#: best SINE_RESCORE are scored again on all of them).
QUICK_EVERY = 3


@dataclass(frozen=True)
class Assignment:
    """The steps' sample times [s] on the model's clock (before its time offset), the
    residual's sum of squares [rad^2] they leave (loop and offset linearised and projected
    out), and a sine that gives them: its start shift [s] against the continuous fit's,
    duration [s] and span [steps]."""

    sse_rad2: float
    times_s: np.ndarray
    shift_s: float
    te_s: float
    span_steps: float


def _theta(setpoints: Setpoints, time: np.ndarray, p: np.ndarray) -> np.ndarray:
    """The loop's angle [rad] at ``time`` for p = (t_off, zeta, omega_n, tau, b, tau_f)."""
    return response(setpoints, time - p[0], p[1], p[2], max(p[3], 0.0), p[4], True,
                    setpoint_tau=max(p[5], 0.0)).theta


def _design(time: np.ndarray, setpoints: Setpoints, p: np.ndarray, basis: np.ndarray
            ) -> tuple[np.ndarray, np.ndarray]:
    """The loop's angle over ``setpoints`` at p and the columns that the residual is
    projected off: the nuisance ``basis`` and the loop and offset linearised (forward
    differences), orthonormalised."""
    base = _theta(setpoints, time, p)
    cols = [basis]
    for j in range(p.size):
        h = 1e-6 if j == 0 else 1e-4 * max(abs(p[j]), 1e-3)
        up = p.copy()
        up[j] += h
        cols.append(((_theta(setpoints, time, up) - base) / h)[:, None])
    return base, np.linalg.qr(np.hstack(cols))[0]


def quick_scores(time: np.ndarray, theta: np.ndarray, rows: np.ndarray, period_s: float,
                 levels: tuple[float, ...], p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """The residual sum of squares [rad^2] of each assignment (rows of sample indices) about
    the loop p with the orthonormal columns q projected off: _sse_off(theta - _theta(...),
    q) of every row, from the loop's linearity. The loop's angle over steps dW_k at samples
    s_k is L0 t + sum_k dW_k U(t - s_k h) (U its response to a unit step), so against the
    residual r of a reference row (its samples s_k^0; projected off q, as every vector here)
    and w_{k,s} = dW_k (U(t - s h) - U(t - s_k^0 h)),

        SSE = |r|^2 - 2 sum_k <r, w_{k,s_k}> + sum_k sum_l <w_{k,s_k}, w_{l,s_l}>:

    one response per distinct sample index instead of one per assignment (a record that is
    no staircase, whose box is wide, scored ~20000 assignments a sample time one by one: 20
    of its 28 s). The reference row keeps the sums small: they agree with the direct ones to
    ~1e-9 relative (tests/test_step_assignment.py)."""
    dw = np.diff(np.asarray(levels, float))
    ref = rows[rows.shape[0] // 2]
    samples, index = np.unique(rows, return_inverse=True)
    index = index.reshape(rows.shape)
    unit = Setpoints((0.0,), (0.0, 1.0))
    u = np.column_stack([_theta(unit, time - s * period_s, p) for s in samples])
    u -= q @ (q.T @ u)
    ref_col = np.searchsorted(samples, ref)
    r = theta - levels[0] * (time - p[0]) - u[:, ref_col] @ dw
    r -= q @ (q.T @ r)
    # the (step, sample) pairs that occur, and each row's pair per step
    pairs, pair_of = np.unique(index + np.arange(rows.shape[1]) * samples.size,
                               return_inverse=True)
    pair_of = pair_of.reshape(rows.shape)
    step_of, col_of = np.divmod(pairs, samples.size)
    w = (u[:, col_of] - u[:, ref_col[step_of]]) * dw[step_of]
    b, gram = w.T @ r, w.T @ w
    out = np.empty(rows.shape[0])
    for lo in range(0, rows.shape[0], 4096):   # (rows, steps, steps) in blocks: memory
        k = pair_of[lo:lo + 4096]
        quad = gram[k[:, :, None], k[:, None, :]].sum(axis=(1, 2))
        out[lo:lo + 4096] = float(r @ r) - 2.0 * b[k].sum(axis=1) + quad
    return out


def _sse_off(e: np.ndarray, q: np.ndarray) -> float:
    e = e - q @ (q.T @ e)
    return float(e @ e)


def _span_per_sample(stair: SineStaircase, te_s: float, span_steps: float,
                     period_s: float) -> float:
    """The span change [steps] that moves the step most sensitive to it by one sample."""
    h = 1e-4
    dx = stair.step_fractions(span_steps + h) - stair.step_fractions(span_steps)
    return period_s * h / max(te_s * float(np.max(np.abs(dx))), 1e-12)


def assignments(stair: SineStaircase, te_s: float, span_steps: float, std: dict[str, float],
                start_s: float, period_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Every distinct assignment of the steps to controller samples (rows of sample
    indices) that the sine gives near the continuous fit (te_s, span_steps; its standard
    errors in ``std``; its start ``start_s`` on the model's clock), and a sine that gives
    each (rows of start shift [s], te [s], span [steps]); the box of the module doc."""
    te_rel = min(max(SINE_TE_REL, 3.0 * std.get("staircase_te_s", 0.0) / te_s),
                 3 * SINE_TE_REL)
    one = _span_per_sample(stair, te_s, span_steps, period_s)
    span_box = min(max(SINE_SPAN, 3.0 * std.get("staircase_span_steps", 0.0), one),
                   SINE_SPAN_MAX)
    # spans dense enough that a step moves by half a sample at most
    n_span = min(max(2 * math.ceil(span_box / (0.5 * one)) + 1, 5), SINE_SPAN_POINTS_MAX)
    # durations dense enough that the last step moves by half a sample at most
    n_te = int(min(max(2 * math.ceil(te_rel * te_s / (0.5 * period_s)) + 1, SINE_TE_MIN),
                   SINE_TE_MAX))
    te = te_s * (1.0 + np.linspace(-te_rel, te_rel, n_te))
    rows, sines = [], []
    for span in span_steps + np.linspace(-span_box, span_box, n_span):
        if not stair.n <= span < stair.n + 1:
            continue
        u = start_s + te[:, None] * stair.step_fractions(span)[None, :]   # (te, step) [s]
        # the start shifts in [-T, T] where a step crosses onto another sample (each step
        # crosses at most three times), then one shift inside each interval between them:
        # every assignment of the shifts, none missed between grid points
        first = np.ceil((u - period_s) / period_s)
        cross = (first[..., None] + np.arange(3.0)) * period_s - u[..., None]
        edges = np.sort(np.hstack([np.clip(cross.reshape(te.size, -1), -period_s, period_s),
                                   np.full((te.size, 2), [-period_s, period_s])]), axis=1)
        shifts = 0.5 * (edges[:, 1:] + edges[:, :-1])                     # (te, intervals)
        k = np.ceil((u[:, None, :] + shifts[:, :, None]) / period_s - 1e-9)
        k = k.reshape(-1, u.shape[1])
        ok = np.all(np.diff(k, axis=1) > 0, axis=1)
        rows.append(k[ok])
        sines.append(np.column_stack([shifts.ravel(),
                                      np.repeat(te, shifts.shape[1]),
                                      np.full(k.shape[0], span)])[ok])
    if not rows:
        return np.empty((0, stair.n)), np.empty((0, 3))
    rows_all, first = np.unique(np.vstack(rows), axis=0, return_index=True)
    return rows_all, np.vstack(sines)[first]


def best_assignment(time: np.ndarray, theta: np.ndarray, stair: SineStaircase, te_s: float,
                    span_steps: float, std: dict[str, float], p: np.ndarray, period_s: float,
                    harmonics: int) -> Assignment | None:
    """The assignment of the staircase's steps to samples of ``period_s`` [s] that leaves
    the smallest residual about the loop p = (t_off, zeta, omega_n, tau, b, tau_f) (None
    where the box holds none). Each is scored on every QUICK_EVERY-th sample with the loop
    linearised once, at the assignment in the box's middle (one response an assignment);
    the best SINE_RESCORE are scored again on all samples, linearised at their own steps
    (that residual is the one returned)."""
    start = stair.t0_s - p[0]   # the sine's start on the model's clock
    basis = linear_basis(time, theta, harmonics)
    levels = stair.setpoints(te_s, span_steps).levels
    rows, sines = assignments(stair, te_s, span_steps, std, start, period_s)
    if rows.shape[0] == 0:
        return None
    at = (lambda k: Setpoints(tuple(np.multiply(k, period_s).tolist()), levels))
    t_q, th_q = time[::QUICK_EVERY], theta[::QUICK_EVERY]
    _, q = _design(t_q, at(rows[rows.shape[0] // 2]), p, basis[::QUICK_EVERY])
    quick = quick_scores(t_q, th_q, rows, period_s, levels, p, q)
    best = []
    for i in np.argsort(quick)[:SINE_RESCORE]:
        base, q_i = _design(time, at(rows[i]), p, basis)
        best.append((_sse_off(theta - base, q_i), int(i)))
    sse, i = min(best)
    shift, te, span = sines[i]
    return Assignment(sse, rows[i].astype(float) * period_s, float(shift), float(te),
                      float(span))


__all__ = ["Assignment", "assignments", "best_assignment", "SINE_TE_REL", "SINE_SPAN"]
