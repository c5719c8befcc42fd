"""Settings of the analysis (:func:`measurement.inference.analysis.analyse_tracks`), validated on
construction (SI units; names ending ``_s`` are seconds)."""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field, replace
from typing import Any

from abu_model.errors import ParameterError
from abu_model.params import check_positive

from measurement.inference import infer_mu as inference_mod
from measurement.inference import running_max as interval_mod
from measurement.inference import uncertainty
from measurement.kinematics import estimators as kin_mod

PHASES = ("ball", "cd")


@dataclass(frozen=True)
class AnalysisOptions:
    """Settings of :func:`analyse_tracks` (SI units; names ending ``_s`` are seconds).

    Attributes:
        estimator: ``savgol`` (default) or ``report`` (decimation + central difference + global
            polynomial, report sec. 5.2).
        sg_window_s, sg_polyorder: Savitzky-Golay window [s] and degree.
        sg_extra_windows_s: longer Savitzky-Golay windows [s] whose kinematics give the
            model-based set again; the reported set is the intersection of all windows' sets,
            each at level 1 - alpha / K (:mod:`window_sets`). A window is left out where the
            record cannot hold it with 40 trusted samples; () (default) or the ``report``
            estimator: ``sg_window_s`` alone. Off by default: a longer window's own set is
            not honest enough (its q errs along the early slip in a way the scale nuisance
            does not cover; docs/measurement-analysis.md, "Several windows").
        decimation, poly_degree: the report estimator's block length and polynomial degree.
        trim_s: time excluded from the trusted region at each end [s]; None: 0 for ``savgol``
            (beyond its half window), 0.05 s for ``report`` (the report's own choice).
        harmonic: remove the lighting harmonic from beta.
        harmonic_orders: harmonic orders fitted (1 = rotation frequency).
        harmonic_orders_alternative: a second lighting model of the record (``abu measure
            --lighting-models two``: orders 1-6); where it changes beta in the fit window
            beyond the window's nuisances, the reported set is the union of both models' sets
            (:mod:`lighting_models`); () off (it costs a second inference); None (default):
            chosen by the ball's highlights where the tracking states them
            (:func:`lighting_models.alternative_orders`: orders 1-6 for a ball showing two
            reflections, none for one), none where it does not (tracks alone).
        harmonic_amp_degree: polynomial degree in time of the harmonic's amplitude.
        harmonic_phase: ``ball`` (ball angle in the image, theta + beta) or ``cd`` (theta).
        knot_spacing_s: knot spacing of the monotone beta basis [s].
        interval: :class:`interval.IntervalOptions` (the report's running-max interval).
        inference: :class:`inference.InferenceOptions` (the model-based confidence set, the
            reported ``mu_low``, ``mu_high``); None: the running-max interval only.
        combine: ``model`` (default): the reported [mu_low, mu_high] is the model-based set
            (honest on its own since its mu_d profile, noise model and kinematic prior were
            mended: see docs/measurement-analysis.md); ``hull``: it holds both the model-based
            set and the running-max interval (the running max stays under ``running_max``).
        mc_draws: Monte Carlo draws (0: none).
        seed: Monte Carlo seed.
        e_omega, e_omega_dot: relative error bounds of the report's worst case (0.03, 0.05).
        max_lost_gap, max_lost_fraction: limits for interpolating lost markers.
        kinematics: ``savgol`` (default: the estimator alone) or ``drive-model`` (omega and
            omega_dot from the known drive fitted to the whole record, the estimator's where
            the fit is refused; :mod:`measurement.kinematics.drive_model`).
        drive_model: the drive and staircase (``DriveModelInput``) for ``drive-model``.
        line_time_s: a rolling shutter's read-out time per sensor row [s/row] (negative: the
            bottom row first; 0, the default: a global shutter): the tracked positions are
            brought back to the frame times before the analysis
            (:func:`measurement.imaging.rolling_shutter.positions_at_frame_times`).
    """

    estimator: str = "savgol"
    sg_window_s: float = 0.042
    sg_polyorder: int = 9
    sg_extra_windows_s: tuple[float, ...] = ()
    decimation: int = 10
    poly_degree: int = 10
    trim_s: float | None = None
    harmonic: bool = True
    harmonic_orders: tuple[int, ...] = (1, 2, 3, 4)
    harmonic_orders_alternative: tuple[int, ...] | None = None
    harmonic_amp_degree: int = 0
    harmonic_phase: str = "ball"
    knot_spacing_s: float = 0.005
    interval: interval_mod.IntervalOptions = field(default_factory=interval_mod.IntervalOptions)
    inference: inference_mod.InferenceOptions | None = field(
        default_factory=inference_mod.InferenceOptions)
    combine: str = "model"
    mc_draws: int = 0
    seed: int = 0
    e_omega: float = uncertainty.REPORT_E_OMEGA
    e_omega_dot: float = uncertainty.REPORT_E_OMEGA_DOT
    max_lost_gap: int = 5
    max_lost_fraction: float = 0.02
    kinematics: str = "savgol"
    drive_model: Any = None
    line_time_s: float = 0.0

    def __post_init__(self) -> None:
        if self.estimator not in kin_mod.ESTIMATORS:
            raise ParameterError("estimator", self.estimator,
                                 f"one of {', '.join(kin_mod.ESTIMATORS)}")
        if self.harmonic_phase not in PHASES:
            raise ParameterError("harmonic_phase", self.harmonic_phase,
                                 f"one of {', '.join(PHASES)}")
        if self.kinematics not in ("savgol", "drive-model"):
            raise ParameterError("kinematics", self.kinematics, "savgol or drive-model")
        if self.combine not in ("hull", "model"):
            raise ParameterError("combine", self.combine, "hull or model")
        if int(self.mc_draws) < 0:
            raise ParameterError("mc_draws", self.mc_draws, "an integer >= 0")
        check_positive("sg_window_s", self.sg_window_s, "s")
        if not isinstance(self.sg_extra_windows_s, (tuple, list)):
            raise ParameterError("sg_extra_windows_s", self.sg_extra_windows_s,
                                 "a tuple of windows > 0 s")
        for w in self.sg_extra_windows_s:
            check_positive("sg_extra_windows_s", w, "s")
        if self.harmonic_orders_alternative is not None and not all(
                isinstance(k, numbers.Integral) and k >= 1
                for k in self.harmonic_orders_alternative):
            raise ParameterError("harmonic_orders_alternative", self.harmonic_orders_alternative,
                                 "harmonic orders >= 1 (() for one lighting model, None to "
                                 "choose by the ball's reflections)")
        check_positive("knot_spacing_s", self.knot_spacing_s, "s")
        if self.trim_s is not None and not (math.isfinite(self.trim_s) and self.trim_s >= 0):
            raise ParameterError("trim_s", self.trim_s, ">= 0 s")
        if isinstance(self.line_time_s, bool) or not isinstance(self.line_time_s, numbers.Real) \
                or not (math.isfinite(self.line_time_s) and abs(self.line_time_s) <= 1e-3):
            raise ParameterError("line_time_s", self.line_time_s,
                                 "a read-out time per sensor row in [-1e-3, 1e-3] s")

    def with_(self, **changes: Any) -> "AnalysisOptions":
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)
