"""Closed-form response of the closed speed loop to a piecewise-constant setpoint (SI).

The loop of :mod:`controller.drive` (PI on the rotor, torque lag tau, setpoint weight b) is

    G(s) = w / w_ref = (2 zeta wn b s + wn^2) / (tau s^3 + s^2 + 2 zeta wn s + wn^2),

times 1 / (tau_f s + 1) with a first-order setpoint filter (time constant tau_f; one more pole).
A digital controller with sample time h sees each step at its first sample at or after the
step's time (:func:`sampled`: the steps moved onto the controller's grid k h).

Its unit-step response is S(u) = 1 + sum_i c_i exp(p_i u) with the poles p_i (roots of the
denominator) and residues c_i = N(p_i) / (p_i D'(p_i)). A setpoint sequence (level L0 held
since long before, steps dW_k at t_k) gives, with the modal sums z_i(t) = sum_{t_k <= t} dW_k
exp(p_i (t - t_k)) (advanced step to step, so nothing overflows):

    omega(t) = L(t) + sum_i c_i z_i(t)
    alpha(t) = sum_i c_i p_i z_i(t)                          (right-hand limit at a step)
    theta(t) = L0 t + sum_k dW_k (t - t_k) + sum_i c_i / p_i (z_i(t) - (L(t) - L0))

(theta relative to theta(0) - the offset of a record is fitted apart). This is exact (no time
stepping), vectorised over the sample times, and O(samples x poles): the identification's
least squares, the design's search and the measurement's drive-model kinematics
(:mod:`measurement.kinematics.drive_model`) evaluate it thousands of times. It is the rotor
alone (the ball's reaction neglected, as in the report); tests compare it with
``control.forced_response`` and with the monolithic SciPy solver. NumPy only (no
python-control: ``abu measure`` does not pay its import); :mod:`harness.planning.loop_response`
re-exports it with the python-control transfer functions.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np

try:   # the compiled kernel (setup.py; optional: without a C compiler the NumPy path runs)
    from abu_model import _loopc
except ImportError:   # pragma: no cover - depends on the build
    _loopc = None

#: Relative separation below which two poles count as repeated; they are then split by this
#: much (the residue formula needs simple poles; the response changes by ~1e-7 relative).
#: Poles that np.roots returns just farther apart (a setpoint filter on one of the loop's
#: poles, a triple pole) keep their residues' cancellation: up to ~1e-5 relative, see
#: tests/test_drive_model.py::test_setpoint_filter_on_another_pole_is_split_and_stays_accurate.
_SPLIT = 1e-7
#: A setpoint filter faster than this [s] is none (its pole would not be representable).
_NO_FILTER_S = 1e-7
#: A setpoint filter's pole closer than this (relative) to one of the loop's is found with
#: them as a root of the whole denominator (:func:`modes`).
_NEAR_FILTER = 1e-3


@dataclass(frozen=True)
class Setpoints:
    """A piecewise-constant speed setpoint (right-continuous).

    Attributes:
        step_times: times of the steps [s], increasing.
        levels: levels [rad/s]; ``levels[0]`` holds before the first step (steady state),
            ``levels[k]`` from ``step_times[k-1]`` on. len(levels) = len(step_times) + 1.
    """

    step_times: tuple[float, ...]
    levels: tuple[float, ...]

    def value(self, t: np.ndarray) -> np.ndarray:
        """Setpoint at the times t [rad/s]."""
        idx = np.searchsorted(np.asarray(self.step_times, float), np.asarray(t, float), "right")
        return np.asarray(self.levels, float)[idx]


def sampled(setpoints: Setpoints, period: float | None) -> Setpoints:
    """The staircase as a digital controller with sample time ``period`` [s] applies it: each
    step at the first sample k * period at or after its time (the controller's clock; None or
    0: unchanged). Steps that fall on the same sample merge."""
    if not period:
        return setpoints
    # a step within 1e-9 of a sample counts as on it (the times carry rounding errors)
    times = np.ceil(np.asarray(setpoints.step_times, float) / period - 1e-9) * period
    # one step per sample (the last level wins): a zero gap would cut the drive model's
    # step-locked test to nothing (its window is the shortest gap between steps)
    last = np.append(np.diff(times) > 0, True)
    levels = (setpoints.levels[0],) + tuple(np.asarray(setpoints.levels[1:])[last].tolist())
    return Setpoints(tuple(float(v) for v in times[last]), levels)


def as_setpoints(obj) -> Setpoints:
    """A :class:`Setpoints` from anything with ``step_times`` and ``levels`` (a Staircase)."""
    return Setpoints(tuple(float(t) for t in obj.step_times), tuple(float(v) for v in obj.levels))


def loop_polynomials(zeta: float, omega_n: float, tau: float = 0.0, weight: float = 1.0,
                     setpoint_tau: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Numerator and denominator coefficients of w / w_ref (highest power first);
    ``setpoint_tau`` [s] > 0 puts a first-order setpoint filter 1 / (setpoint_tau s + 1) before
    the loop (one more real pole)."""
    num = np.array([2.0 * zeta * omega_n * weight, omega_n**2])
    den = np.array([tau, 1.0, 2.0 * zeta * omega_n, omega_n**2]) if tau > 0 else \
        np.array([1.0, 2.0 * zeta * omega_n, omega_n**2])
    if setpoint_tau > _NO_FILTER_S:
        den = np.convolve(den, [setpoint_tau, 1.0])   # np.polymul's product, ~30x cheaper
    return num, den


@lru_cache(maxsize=256)  # the design's search asks for the same drive thousands of times
def modes(zeta: float, omega_n: float, tau: float = 0.0, weight: float = 1.0,
          setpoint_tau: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Poles p_i [1/s] and step-response residues c_i [-] of the loop (complex arrays, not
    to be modified: cached).

    The fits call this with new parameters at every evaluation, so it works on Python
    complex numbers (NumPy's per-call overhead on arrays of 2-4 was most of its cost): the
    loop's poles in closed form without a lag (the quadratic's cancellation-free form), the
    cubic's from its companion matrix with one (as np.roots, without its checks), and the
    setpoint filter's pole -1/tau_f."""
    num, den = loop_polynomials(zeta, omega_n, tau, weight, 0.0)
    poles = list(_loop_poles(zeta, omega_n, tau))
    lead = float(den[0])
    if setpoint_tau > _NO_FILTER_S:
        lead *= setpoint_tau
        poles.append(complex(-1.0 / setpoint_tau))
        if min(abs(poles[-1] - v) for v in poles[:-1]) < _NEAR_FILTER * abs(poles[-1]):
            # the filter on (or next to) a loop pole, maybe a double one: the whole
            # denominator's roots, which come apart by ~eps^(1/m) (a split by _SPLIT of a
            # triple pole would lose 1e-3 of alpha in the residues' cancellation)
            poles = _roots(loop_polynomials(zeta, omega_n, tau, weight, setpoint_tau)[1])
    scale = max(abs(v) for v in poles)
    for i in range(len(poles)):
        for j in range(i):
            if abs(poles[i] - poles[j]) < _SPLIT * scale:
                poles[i] += _SPLIT * scale * (1 + i)
    # D'(p) from the (possibly split) poles: lead * prod_{j != i} (p_i - p_j)
    residues = []
    for i, p_i in enumerate(poles):
        dprime = lead
        for j, p_j in enumerate(poles):
            if j != i:
                dprime *= p_i - p_j
        residues.append((float(num[0]) * p_i + float(num[1])) / (p_i * dprime))
    return np.array(poles, dtype=complex), np.array(residues, dtype=complex)


@lru_cache(maxsize=64)   # a fit's Jacobian moves the weight and the filter alone too
def _loop_poles(zeta: float, omega_n: float, tau: float) -> tuple[complex, ...]:
    """The PI loop's poles without the setpoint filter (the weight does not move them)."""
    if tau > 0:
        return tuple(_roots(np.array([tau, 1.0, 2.0 * zeta * omega_n, omega_n**2])))
    disc = zeta * zeta - 1.0
    if disc >= 0.0:
        big = -omega_n * (zeta + math.sqrt(disc))
        return complex(big), complex(omega_n * omega_n / big)
    im = omega_n * math.sqrt(-disc)
    return complex(-zeta * omega_n, im), complex(-zeta * omega_n, -im)


def _roots(den: np.ndarray) -> list[complex]:
    """Roots of the polynomial ``den`` (highest power first): np.roots' companion matrix,
    built here without its checks (den has no zero coefficient at either end: omega_n > 0 and
    a positive leading one)."""
    companion = np.diag(np.ones(den.size - 2), -1)
    companion[0, :] = -den[1:] / den[0]
    return [complex(v) for v in np.linalg.eigvals(companion)]


@dataclass
class LoopResponse:
    """omega [rad/s], alpha [rad/s^2], theta [rad] (theta(t) relative, see module) at t [s]."""

    t: np.ndarray
    omega: np.ndarray
    alpha: np.ndarray
    theta: np.ndarray


def response(setpoints: Setpoints, t: Sequence[float] | np.ndarray, zeta: float,
             omega_n: float, tau: float = 0.0, weight: float = 1.0,
             need_theta: bool = True, setpoint_tau: float = 0.0) -> LoopResponse:
    """The loop's response at the times ``t`` [s] (any order) to ``setpoints``.

    Starts in the steady state at ``levels[0]`` (integrator, lag and setpoint filter at rest).
    ``setpoint_tau``: time constant of a first-order setpoint filter [s] (0 = none).
    """
    t = np.asarray(t, dtype=float)
    poles, res = modes(zeta, omega_n, tau, weight, setpoint_tau)
    if _loopc is not None and t.ndim == 1 and t.size:
        t_c = np.ascontiguousarray(t)
        out = np.empty((3, t.size))
        try:
            _loopc.response(t_c, np.asarray(setpoints.step_times, dtype=float),
                            np.diff(np.asarray(setpoints.levels, dtype=float)), poles, res,
                            float(setpoints.levels[0]), need_theta, *out)
            return LoopResponse(t, out[1], out[2], out[0] if need_theta else np.empty(0))
        except ValueError:   # times not increasing or not finite: the reference below
            pass
    return _response_numpy(setpoints, t, poles, res, need_theta)


def _response_numpy(setpoints: Setpoints, t: np.ndarray, poles: np.ndarray, res: np.ndarray,
                    need_theta: bool) -> LoopResponse:
    """The NumPy reference of :func:`response` (times in any order), the compiled kernel's
    (``_loopc.c``) check in tests/test_loop_kernel.py."""
    tk = np.asarray(setpoints.step_times, dtype=float)
    levels = np.asarray(setpoints.levels, dtype=float)
    dw = np.diff(levels)
    k = np.searchsorted(tk, t, side="right")  # steps done at t (0..K)
    level = levels[k]
    # Z[k, i]: modal sum just after step k (Z[0] = 0 before any step)
    Z = np.zeros((len(tk) + 1, len(poles)), dtype=complex)
    for j in range(len(tk)):
        gap = tk[j] - tk[j - 1] if j else 0.0
        Z[j + 1] = Z[j] * np.exp(poles * gap) + dw[j]
    # before the first step z = 0 (no exp of a time before it: it could overflow)
    since = np.where(k > 0, t - tk[np.maximum(k - 1, 0)], 0.0) if tk.size else np.zeros_like(t)
    z = (Z[k] * np.exp(np.outer(since, poles))).view(np.float64)   # (times, 2 poles) reals
    omega = level + _real_sum(z, res)
    alpha = _real_sum(z, res * poles)
    theta = np.empty(0)
    if need_theta:
        ramp = levels[0] * t + np.concatenate([[0.0], np.cumsum(dw)])[k] * t \
            - np.concatenate([[0.0], np.cumsum(dw * tk)])[k]
        c = res / poles
        theta = ramp + _real_sum(z, c) - (level - levels[0]) * float(np.real(c.sum()))
    return LoopResponse(t, omega, alpha, theta)


def _real_sum(z_pairs: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Re(sum_i c_i z_i) of each row, z as (re, im) pairs of reals. einsum, not '@' nor a
    complex product and sum: a threaded BLAS call costs more than these tiny products, and
    the complex temporaries 3x more than this (the fits evaluate the response thousands of
    times)."""
    w = np.empty(2 * c.size)
    w[0::2], w[1::2] = c.real, -c.imag
    return np.einsum("ij,j->i", z_pairs, w)
