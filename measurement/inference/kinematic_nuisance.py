"""The kinematic nuisance of :func:`measurement.inference.infer_mu.infer_mu`: the error of q.

mu enters the model only through q = mu_req, which scales with omega_dot / omega^2, so an error
e on q is an error e on mu. The noise part of e is a Gaussian nuisance profiled out of the
likelihood (:func:`scale_nuisance_bounds`); the truncation bound and the lens prior are bias
bounds added linearly. The lower bound's noise term is the Rice sup quantile of the error over
the stick stretch within reach of the bound (:mod:`sup_noise`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from measurement.inference import sup_noise
from measurement.inference.fit_window import Window
from measurement.inference.types import InferenceOptions


def scale_nuisance_bounds(mu: np.ndarray, stat: np.ndarray, budget: tuple[float, float],
                          sigma_e: tuple[float, float], bias: tuple[float, float] = (0.0, 0.0)
                          ) -> tuple[float, float]:
    """Bounds of a confidence set on mu with a Gaussian relative scale error of q profiled out.

    The data of (mu, mu_d) under q (1 + e) are those of (mu, mu_d) / (1 + e) under q, and e is
    independent of beta's noise with 1-sigma ``sigma_e``: the deviance is the profile's
    statistic plus (e / sigma_e)^2, minimised over e. So mu is accepted if it lies within a
    factor 1 -+ sigma_e sqrt(budget - stat(mu')) of a candidate mu' the profile accepts: a
    flat-bottomed profile [a, b] gives [a (1 - z sigma_e), b (1 + z sigma_e)] (z^2 = budget),
    a sharp quadratic one about the quadrature sum of the two half-widths.

    Args:
        mu: the candidates the profile accepts [1]; stat: their likelihood-ratio statistic.
        budget: (lower, upper) deviance budgets: z^2 at the level, or a larger quantile
            squared where the error is the largest of many (``sup_noise``).
        sigma_e: (lower, upper) relative 1-sigma error of q [1].
        bias: (lower, upper) relative bias bounds of q, added linearly [1].

    Returns:
        (lower, upper); the lower bound is 0 where the relative errors reach 100 % (mu >= 0).
    """
    lo = mu * (1.0 - sigma_e[0] * np.sqrt(np.maximum(budget[0] - stat, 0.0)) - bias[0])
    hi = mu * (1.0 + sigma_e[1] * np.sqrt(np.maximum(budget[1] - stat, 0.0)) + bias[1])
    return max(0.0, float(np.min(lo))), float(np.max(hi))


@dataclass(frozen=True, eq=False)
class KinematicErrors:
    """The measured kinematics' errors, read at fit-window samples.

    Attributes:
        omega, omega_dot: the record's kinematics [rad/s, rad/s^2].
        sigma_omega, sigma_omega_dot: their 1-sigma noise [rad/s, rad/s^2].
        bias_omega_dot: truncation-error bound of omega_dot [rad/s^2].
        i0: first sample of the fit window in the record.
        theta_harmonic_rad: prior amplitude of a systematic first harmonic of theta [rad].
    """

    omega: np.ndarray
    omega_dot: np.ndarray
    sigma_omega: np.ndarray
    sigma_omega_dot: np.ndarray
    bias_omega_dot: np.ndarray
    i0: int
    theta_harmonic_rad: float

    def relative_error(self, j: int) -> tuple[float, float]:
        """(relative 1-sigma noise, relative bias bound) of q at fit-window sample j [1]."""
        a = abs(float(self.omega_dot[self.i0 + j]))
        wv = abs(float(self.omega[self.i0 + j]))
        if not (a > 0 and wv > 0):
            return 0.0, 0.0
        noise = math.hypot(float(self.sigma_omega_dot[self.i0 + j]) / a,
                           2.0 * float(self.sigma_omega[self.i0 + j]) / wv)
        # + a systematic harmonic of theta of amplitude A (lens distortion about an optical
        # centre off the axis: the circle fit of the axis cannot see it) errs omega_dot by up
        # to A omega^2 and omega by A omega (worst phase)
        bias = (float(self.bias_omega_dot[self.i0 + j]) / a
                + float(self.theta_harmonic_rad) * (wv * wv / a + 2.0))
        return noise, bias


@dataclass(frozen=True)
class KinematicNuisance:
    """Relative errors of q [1] at the slip and at the stick peak, and the lower bound's
    quantile (Rice sup quantile over ``reach_s`` [s])."""

    rel_noise: float
    rel_bias: float
    rel_noise_lo: float
    rel_bias_lo: float
    z_lo: float
    reach_s: float


def kinematic_nuisance(kin: KinematicErrors, win: Window, onset_idx: int | None,
                        mu_low_profile: float, z: float, level: float,
                        omega_dot_rho: np.ndarray | None,
                        opt: InferenceOptions) -> KinematicNuisance:
    """Relative errors of q at the slip (upper bound) and over the stick stretch (lower)."""
    rel_noise = rel_bias = 0.0
    if onset_idx is not None:
        rel_noise, rel_bias = kin.relative_error(onset_idx)
    # The lower bound is set by the largest q over the stick stretch (before the best fit's
    # onset; the whole window if it never slips): its error is that of q where q peaks there,
    # and the largest of the noise errors over the part of the stretch whose q comes within
    # reach of the bound, not one pointwise error (sup_noise: Rice's formula).
    stick_end = onset_idx if onset_idx is not None else win.t.size
    j_peak = int(np.argmax(win.q[:max(stick_end, 1)]))
    rel_noise_lo, rel_bias_lo = kin.relative_error(j_peak)
    if onset_idx is not None and rel_noise > 0.0:
        rel_noise_lo, rel_bias_lo = max(rel_noise_lo, rel_noise), max(rel_bias_lo, rel_bias)
    z_lo, reach_s = lower_bound_quantile(win, stick_end, rel_noise_lo, mu_low_profile, z,
                                          level, omega_dot_rho, opt)
    return KinematicNuisance(rel_noise, rel_bias, rel_noise_lo, rel_bias_lo, z_lo, reach_s)


def lower_bound_quantile(win: Window, stick_end: int, rel_noise_lo: float,
                          mu_low_profile: float, z: float, level: float,
                          omega_dot_rho: np.ndarray | None,
                          opt: InferenceOptions) -> tuple[float, float]:
    """(quantile of the largest noise error of q over the stretch within reach of the lower
    bound, that stretch's length [s]); (z, 0) without omega_dot's noise autocorrelation."""
    z_lo, reach_s = z, 0.0
    rho_q = None if omega_dot_rho is None else np.asarray(omega_dot_rho, float)
    if rho_q is not None and rho_q.size > 1:
        t, q = win.t, win.q
        h = float(t[1] - t[0])
        lam2 = sup_noise.second_spectral_moment(float(rho_q[1]), h)
        sq = np.abs(q[:stick_end]) * rel_noise_lo * float(opt.kinematic_sigma_scale)
        for _ in range(3):  # the stretch within reach depends on the quantile: fixed point
            reach_s = h * int(np.count_nonzero(q[:stick_end] + 2.0 * z_lo * sq >= mu_low_profile))
            z_lo = max(z, sup_noise.sup_quantile(0.5 * (1.0 - level), reach_s, lam2))
    return z_lo, reach_s
