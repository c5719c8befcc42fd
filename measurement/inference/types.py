"""Settings and result of the model-based inference (:func:`measurement.inference.infer_mu.infer_mu`).

Kept apart from the fit itself so that the analysis pipeline, the CLI and the summaries can
name the options and read the result without the numerics.
"""
from __future__ import annotations

import numbers
from dataclasses import dataclass, field

import numpy as np

from abu_model.errors import ParameterError

#: Status of a set refused because the ball or CD marker was interpolated across the slip.
LOST_ACROSS_SLIP = "markers lost (interpolated) across the slip: no bound"

#: Ratio mu_d / mu explored by the profile (the issue's family is [0.6, 1]; wider is safer).
MU_D_RATIO = (0.3, 1.0)


@dataclass(frozen=True)
class InferenceOptions:
    """Settings of :func:`infer_mu`.

    Attributes:
        confidence: level of the confidence sets [-] (default 0.95).
        harmonic_orders: orders of the lighting harmonics in phi = theta + beta (and theta)
            refitted in the fit window and profiled out (default 1-4, the whole-record fit's:
            that fit is unidentified where the slip carries the ball into angles its stick
            stretch never showed, and its monotone b(t) then absorbs the error; () uses its
            cleaned beta as is).
        theta_harmonics: also fit harmonics of theta (apparent CD-marker shift).
        n_mu, n_mu_d: grid sizes of the coarse search (refined around the bounds).
        theta_harmonic_rad: prior bound on the amplitude of a systematic first harmonic of the
            measured theta [rad] (lens distortion; not observable in one record); its
            omega_dot error A omega^2 at the slip widens the bounds like the truncation bound.
            Default 8e-4: the 90th percentile on the harsh twin's family
            (benchmarks/bench_kinematic_error.py); set it from your camera's calibration.
        mu_d_refine: shrinking 5-point refinements of mu_d per candidate mu (step / 2.5 each).
        max_episodes: slip episodes followed per candidate (re-stick, re-slip); None: all
            (a cap froze candidates with mu in q's noise before the real slip).
        ar_order_max: 1 = AR(1) residuals (0: white).
        noise_model: ``ar1`` (default) or ``leftover``: white noise + a smooth leftover with
            exponential correlation, both estimated from the first fit's residual
            (:func:`noise_models.leftover_whitener`; full-covariance GLS).
        lrv_window_s: > 0: divide the likelihood-ratio statistic by the residual's long-run
            variance factor (Bartlett window of this length [s]); 0: off.
        sigma_floor_rad: floor of the white-noise sigma of beta that sets the fit window [rad].
        kinematic_sigma_scale: factor on the kinematic 1-sigma error of q at the slip used to
            widen the bounds (1: as the kinematics estimator states it). Measured on the tracks
            family (benchmarks/bench_kinematic_error.py): the stated sigma is ~2.8x too small
            at the slip; not a default because the factor is fitted, not modelled.
        window_sigmas: the fit ends where the data have moved this many white-noise sigmas of
            beta from the stick level (see :func:`infer_mu`).
        drive_noise: add to beta's noise covariance the error of the predicted slip that
            omega_dot's noise causes (q enters the slip's drive q - mu_d, a small difference
            near the onset; :func:`noise_models.drive_noise_cov`), from the onset of the first
            pass's best pair (False: the former fit, where that error moved the onset).
        leftover_orders: harmonic orders of the ball's angle beyond ``harmonic_orders`` that
            enter beta's noise covariance as random effects, each coefficient with the
            variance of the order's squared amplitude in the record's residual
            (:mod:`lighting_leftover`; () off).
        max_fit_samples: most samples in the fit window (its dense noise covariance costs
            n^2 memory, n^3 time); a longer window is cut around the slip's first move
            (:func:`fit_window.capped_window`). The default, 3072, is the twin's whole record
            (4500 frames/s, 0.68 s): its windows are never cut.
    """

    confidence: float = 0.95
    harmonic_orders: tuple[int, ...] = (1, 2, 3, 4)
    theta_harmonics: bool = False
    n_mu: int = 48
    n_mu_d: int = 8
    max_episodes: int | None = None
    ar_order_max: int = 1
    window_sigmas: float = 20.0
    noise_model: str = "leftover"
    lrv_window_s: float = 0.0
    sigma_floor_rad: float = 0.0
    kinematic_sigma_scale: float = 1.0
    mu_d_refine: int = 7
    theta_harmonic_rad: float = 8e-4
    drive_noise: bool = True
    leftover_orders: tuple[int, ...] = (5, 6, 7, 8, 9, 10, 11, 12)
    max_fit_samples: int = 3072

    def __post_init__(self) -> None:
        if not 0.5 <= float(self.confidence) < 1.0:
            raise ParameterError("confidence", self.confidence, "a level in [0.5, 1)")
        if int(self.n_mu) < 8 or int(self.n_mu_d) < 2:
            raise ParameterError("n_mu", (self.n_mu, self.n_mu_d), "grids of >= 8 and >= 2")
        if isinstance(self.max_fit_samples, bool) or not isinstance(
                self.max_fit_samples, numbers.Integral) or self.max_fit_samples < 256:
            raise ParameterError("max_fit_samples", self.max_fit_samples,
                                 "an integer >= 256 [samples]")


@dataclass
class Inference:
    """Result of :func:`infer_mu` (SI; None where a bound does not exist, see ``status``)."""

    mu_low: float | None
    mu_high: float | None
    mu_hat: float | None
    mu_d: float | None
    mu_d_low: float | None
    mu_d_high: float | None
    status: str
    confidence: float
    t_slip: float | None
    beta_model: np.ndarray              #: model beta [rad] at (mu_hat, mu_d) incl. nuisances
    beta_model_low: np.ndarray | None   #: model beta at the lower bound [rad]
    beta_model_high: np.ndarray | None  #: model beta at the upper bound [rad]
    residual: np.ndarray                #: measured - best model [rad]
    details: dict = field(default_factory=dict)
