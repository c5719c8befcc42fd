"""The analysis pipeline: marker tracks -> theta, beta -> omega, omega_dot -> [mu_low, mu_high].

:func:`analyse_tracks` runs, in order:

1. lost markers: short gaps interpolated, long ones rejected (:func:`tracks_io.fill_lost`);
2. theta, beta from the pixel coordinates (:func:`tracks_io.angles_from_pixels`);
3. omega, omega_dot with noise error bars (:mod:`kinematics`, ``savgol`` or ``report``);
4. the lighting harmonic removed from beta (:mod:`harmonic`);
5. the slip window and the interval (:mod:`interval`);
6. the report's worst-case error analysis and, with ``mc_draws`` > 0, a Monte Carlo propagation of
   the measured tracking noise (:mod:`uncertainty`).

It returns a table of time series (column names carry their units) and a JSON-ready summary.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from abu_model.errors import AbuError, ParameterError
from abu_model.params import check_positive

from . import harmonic as harmonic_mod
from . import inference as inference_mod
from . import interval as interval_mod
from . import kinematics as kin_mod
from . import tracks_io, uncertainty, window_sets

PHASES = ("ball", "cd")


class AnalysisError(AbuError, ValueError):
    """The tracks cannot be analysed (non-uniform sampling, too short, bad shapes)."""


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

    def __post_init__(self) -> None:
        if self.estimator not in kin_mod.ESTIMATORS:
            raise ParameterError("estimator", self.estimator,
                                 f"one of {', '.join(kin_mod.ESTIMATORS)}")
        if self.harmonic_phase not in PHASES:
            raise ParameterError("harmonic_phase", self.harmonic_phase,
                                 f"one of {', '.join(PHASES)}")
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
        check_positive("knot_spacing_s", self.knot_spacing_s, "s")
        if self.trim_s is not None and not (math.isfinite(self.trim_s) and self.trim_s >= 0):
            raise ParameterError("trim_s", self.trim_s, ">= 0 s")

    def with_(self, **changes: Any) -> "AnalysisOptions":
        """A copy with ``changes`` applied (validated again)."""
        return replace(self, **changes)


def _kinematics(time: np.ndarray, theta: np.ndarray, opt: AnalysisOptions) -> kin_mod.Kinematics:
    if opt.estimator == "savgol":
        return kin_mod.savgol_kinematics(time, theta, window_s=opt.sg_window_s,
                                         polyorder=opt.sg_polyorder,
                                         # degree >= 5: the half-window comparison is too
                                         # noisy to see a kink; 2/3 of the window and 2 sigma
                                         bias_window_ratio=0.5 if opt.sg_polyorder <= 3
                                         else 2.0 / 3.0,
                                         bias_k=3.0,
                                         trim_s=0.0 if opt.trim_s is None else opt.trim_s)
    return kin_mod.report_kinematics(time, theta, decimation=opt.decimation,
                                     degree=opt.poly_degree,
                                     trim_s=0.05 if opt.trim_s is None else opt.trim_s)


def inference_windows(n_frames: int, dt: float, opt: AnalysisOptions) -> list[float]:
    """The Savitzky-Golay windows [s] whose model-based sets are intersected: ``sg_window_s``
    first, then each longer extra window the record holds with 40 trusted samples."""
    windows = [float(opt.sg_window_s)]
    if opt.estimator != "savgol":
        return windows
    for w in opt.sg_extra_windows_s:
        if float(w) > windows[0] and round(float(w) / dt) + 41 <= n_frames \
                and float(w) not in windows:
            windows.append(float(w))
    return windows


def circle_centre(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """Centre of the least-squares circle through the points (x, y) [px] (algebraic, Kasa)."""
    sol = np.linalg.lstsq(np.column_stack([x, y, np.ones_like(x)]), x ** 2 + y ** 2, rcond=None)[0]
    return 0.5 * float(sol[0]), 0.5 * float(sol[1])


def fixed_axis(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates with the centre marker replaced by the fixed ABU axis [px].

    A centre marker glued slightly off the axis circles it once per turn; measured from it, theta
    carries a harmonic e/r_cd sin(theta + p) whose second derivative, e/r_cd omega^2, is tens of
    rad/s^2 for e = 0.3 px (the twin's eccentric marker). The axis is the centre of the circle the
    CD marker runs on (algebraic least-squares circle fit, Kasa 1976) when the record covers
    more than half a turn; otherwise the mean of the centre marker.
    """
    x = np.array(x, dtype=float)
    y = np.array(y, dtype=float)
    xc, yc = x[:, 1], y[:, 1]
    ang = np.unwrap(np.arctan2(-(yc - y[:, 0]), xc - x[:, 0]))
    if float(np.ptp(ang)) > np.pi:
        cx, cy = circle_centre(xc, yc)
    else:
        cx, cy = float(np.mean(x[:, 0])), float(np.mean(y[:, 0]))
    x[:, 0], y[:, 0] = cx, cy
    return x, y


def _core(time: np.ndarray, x: np.ndarray, y: np.ndarray, l: float, d: float,
          opt: AnalysisOptions, lost: np.ndarray | None = None, infer: bool = True) -> dict:
    """Angles, kinematics, harmonic removal and interval for filled coordinates."""
    theta, beta = tracks_io.angles_from_pixels(*fixed_axis(x, y))
    kin = _kinematics(time, theta, opt)
    trusted = kin.trusted
    med = float(np.median(kin.omega_dot[trusted])) if trusted.any() else 0.0
    direction = -1 if med > 0 else 1
    if opt.harmonic:
        phase = theta + beta if opt.harmonic_phase == "ball" else theta
        harm = harmonic_mod.remove_harmonic(
            time, beta, phase, orders=tuple(opt.harmonic_orders),
            amp_degree=opt.harmonic_amp_degree, knot_spacing_s=opt.knot_spacing_s,
            direction=direction)
    else:
        harm = harmonic_mod.remove_harmonic(time, beta, theta, orders=(),
                                            knot_spacing_s=opt.knot_spacing_s,
                                            direction=direction)
    iv = interval_mod.slip_interval(time, kin.omega, kin.omega_dot, kin.sigma_omega,
                                    kin.sigma_omega_dot, trusted, harm.beta_clean, harm.residual,
                                    l=l, d=d, options=opt.interval, direction=direction,
                                    bias_omega_dot=kin.bias_omega_dot)
    inf = None
    if infer and opt.inference is not None:
        lost_any = None if lost is None else np.asarray(lost, bool)[:, 1:].any(axis=1)
        windows = inference_windows(time.size, kin_mod.sample_interval(time), opt)
        each = replace(opt.inference, confidence=window_sets.level_each(
            opt.inference.confidence, len(windows)))
        sets: list[inference_mod.Inference] = []
        for k, window in enumerate(windows):
            kin_w = kin if k == 0 else _kinematics(time, theta, opt.with_(sg_window_s=window))
            # beta with the lighting harmonics removed by the whole-record fit (monotone b(t)
            # + harmonics over all revolutions): over the short inference window a free
            # harmonic would trade off against the slip curve.
            sets.append(inference_mod.infer_mu(
                time, theta, harm.beta_clean, kin_w.omega, kin_w.omega_dot, kin_w.sigma_omega,
                kin_w.sigma_omega_dot, kin_w.bias_omega_dot, kin_w.trusted, l=l, d=d,
                direction=direction, lost=lost_any, deviation=iv.deviation,
                record_residual=harm.residual, omega_dot_rho=kin_w.omega_dot_rho,
                # beta's noise model is the record's, whatever the kinematics: estimated once
                noise=(sets[0].details.get("noise_model") or None) if sets else None,
                options=each))
        inf = window_sets.intersect_sets(sets, windows, opt.inference.confidence)
    return {"theta": theta, "beta": beta, "kin": kin, "harm": harm, "iv": iv, "inf": inf}


def _validate(time, x, y, lost, fps) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    x = np.asarray(x, dtype=float)
    y = np.asarray(y, dtype=float)
    if x.ndim != 2 or x.shape[1] != 3 or x.shape != y.shape:
        raise AnalysisError(f"marker coordinates must be two (N, 3) arrays (centre, CD, ball); "
                            f"got {x.shape} and {y.shape}")
    n = x.shape[0]
    if time is None:
        if fps is None:
            raise ParameterError("fps", fps, "a frame rate > 0 Hz when no times are given")
        fps = check_positive("fps", fps, "Hz")
        time = np.arange(n) / fps
    time = np.asarray(time, dtype=float)
    if time.shape != (n,):
        raise AnalysisError(f"{time.shape[0] if time.ndim else 0} times for {n} frames")
    if n < tracks_io.MIN_ROWS:
        raise AnalysisError(f"{n} frames; the analysis needs at least {tracks_io.MIN_ROWS}")
    try:
        kin_mod.sample_interval(time)
    except ParameterError as exc:
        raise AnalysisError(f"the frame times are not uniformly sampled: {exc}") from None
    lost = np.zeros((n, 3), dtype=bool) if lost is None else np.asarray(lost, dtype=bool)
    if lost.shape != (n, 3):
        raise AnalysisError(f"lost flags must be (N, 3); got {lost.shape}")
    bad = ~(np.isfinite(x) & np.isfinite(y)) & ~lost
    if bad.any():
        frame, marker = np.argwhere(bad)[0]
        raise AnalysisError(f"non-finite coordinate of marker '{tracks_io.MARKERS[marker]}' in "
                            f"frame {frame} (not flagged as lost)")
    return time, x, y, lost


def analyse_tracks(time: np.ndarray | None, x: np.ndarray, y: np.ndarray, *,
                   l: float = 1.15e-2, d: float = 3.0e-3, fps: float | None = None,
                   lost: np.ndarray | None = None,
                   options: AnalysisOptions | None = None) -> tuple[dict[str, np.ndarray], dict]:
    """Analyse one record of marker tracks.

    Args:
        time: frame times [s] (uniform), or None to use ``arange(N) / fps``.
        x, y: (N, 3) pixel coordinates of centre, CD, ball (OpenCV: x column, y row down).
        l, d: ball path radius and ball diameter [m].
        fps: frame rate [1/s], only used when ``time`` is None.
        lost: (N, 3) bool, markers the tracker lost (interpolated if the gaps are short).
        options: :class:`AnalysisOptions`.

    Returns:
        (table, summary): ``table`` maps column names (with units) to (N,) arrays; ``summary`` is
        JSON-ready (see docs/measurement-analysis.md for every key).

    Raises:
        AnalysisError, ParameterError, tracks_io.LostMarkerError: bad input, with the reason.
    """
    opt = options or AnalysisOptions()
    l = check_positive("l", l, "m")
    d = check_positive("d", d, "m")
    if d >= 2.0 * l:
        raise ParameterError("d", d, f"a ball diameter < 2 l = {2 * l:g} m")
    time, x, y, lost = _validate(time, x, y, lost, fps)
    x = tracks_io.fill_lost(time, x, lost, max_gap=opt.max_lost_gap,
                            max_fraction=opt.max_lost_fraction)
    y = tracks_io.fill_lost(time, y, lost, max_gap=opt.max_lost_gap,
                            max_fraction=opt.max_lost_fraction)
    core = _core(time, x, y, l, d, opt, lost=lost)
    kin, harm, iv, inf = core["kin"], core["harm"], core["iv"], core["inf"]
    dt = kin_mod.sample_interval(time)

    table = {
        "time_s": time, "theta_rad": core["theta"], "beta_rad": core["beta"],
        "beta_clean_rad": harm.beta_clean, "beta_smooth_rad": harm.beta_smooth,
        "harmonic_rad": harm.harmonic, "slip_deviation_rad": iv.deviation,
        "omega_rad_s": kin.omega, "sigma_omega_rad_s": kin.sigma_omega,
        "omega_dot_rad_s2": kin.omega_dot, "sigma_omega_dot_rad_s2": kin.sigma_omega_dot,
        "bias_omega_dot_rad_s2": kin.bias_omega_dot,
        "mu_req": iv.mu_req, "mu_req_lo": iv.mu_req_lo, "mu_req_hi": iv.mu_req_hi,
        "running_max_lo": iv.running_max_lo, "running_max_hi": iv.running_max_hi,
        "trusted": kin.trusted.astype(int), "lost": tracks_io.lost_bitmask(lost),
    }
    if inf is not None:
        nan = np.full(time.size, np.nan)
        table["beta_model_rad"] = inf.beta_model
        table["beta_model_low_rad"] = nan if inf.beta_model_low is None else inf.beta_model_low
        table["beta_model_high_rad"] = nan if inf.beta_model_high is None else \
            inf.beta_model_high
        table["beta_model_residual_rad"] = inf.residual

    def at(arr: np.ndarray, t: float | None) -> float | None:
        if t is None:
            return None
        return float(arr[int(round((t - time[0]) / dt))])

    def attained(running: np.ndarray, values: np.ndarray, t: float | None) -> float | None:
        # Time at which the running maximum's value at t was reached.
        if t is None:
            return None
        i = int(round((t - time[0]) / dt))
        seg = np.flatnonzero(kin.trusted[: i + 1])
        return float(time[seg[np.nanargmax(values[seg])]]) if seg.size else None

    t_lo_at = attained(iv.running_max_lo, iv.mu_req_lo, iv.t_a)
    t_hi_at = attained(iv.running_max_hi, iv.mu_req_hi, iv.t_b)
    measured = {}
    for tag, t_at in (("low", t_lo_at), ("high", t_hi_at)):
        if t_at is None:
            continue
        w, a = abs(at(kin.omega, t_at)), abs(at(kin.omega_dot, t_at))
        measured[f"t_{tag}_attained"] = t_at
        measured[f"e_omega_{tag}"] = at(kin.sigma_omega, t_at) / w if w > 0 else None
        measured[f"e_omega_dot_{tag}"] = at(kin.sigma_omega_dot, t_at) / a if a > 0 else None
    def rel_width(lo: float | None, hi: float | None) -> float | None:
        return None if lo is None or hi is None else (hi - lo) / (0.5 * (hi + lo))

    running = {
        "mu_low": iv.mu_low, "mu_high": iv.mu_high, "status": iv.status,
        "t_slip_low": iv.t_a, "t_slip_high": iv.t_b,
        "relative_width": rel_width(iv.mu_low, iv.mu_high),
        "mu_low_creep_model": iv.mu_creep,
        "mu_low_no_error_bars": at(iv.running_max, iv.t_a),
        "mu_high_no_error_bars": at(iv.running_max, iv.t_b),
        "k_sigma": opt.interval.k_sigma,
        "method": "report's running maximum of mu_req (sec. 5.3) with k-sigma error bands",
    }
    if inf is not None:
        model = {"method": "profile likelihood of the ball model's beta(t) (measurement."
                           "inference)",
                 "mu_low": inf.mu_low, "mu_high": inf.mu_high, "status": inf.status,
                 "relative_width": rel_width(inf.mu_low, inf.mu_high),
                 "confidence": inf.confidence, "mu_hat": inf.mu_hat, "mu_d": inf.mu_d,
                 "mu_d_low": inf.mu_d_low, "mu_d_high": inf.mu_d_high,
                 "t_slip": inf.t_slip, **inf.details}
        if opt.combine == "hull":
            # The reported interval holds both sets (wider than the model-based set alone; the
            # default before the model-based set was mended). A bound either method cannot
            # give is null; the first non-ok status is reported.
            mu_low = None if inf.mu_low is None or iv.mu_low is None else \
                min(inf.mu_low, iv.mu_low)
            mu_high = None if inf.mu_high is None or iv.mu_high is None else \
                max(inf.mu_high, iv.mu_high)
            status = inf.status if inf.status != "ok" else iv.status
            if status == "ok" and (mu_low is None or mu_high is None):
                status = "a bound is missing"
        else:
            mu_low, mu_high, status = inf.mu_low, inf.mu_high, inf.status
    else:
        mu_low, mu_high, status = iv.mu_low, iv.mu_high, iv.status
        model = None

    summary: dict[str, Any] = {
        "mu_low": mu_low, "mu_high": mu_high,
        "status": status,
        "confidence": None if inf is None else inf.confidence,
        "mu_hat": None if inf is None else inf.mu_hat,
        "mu_d": None if inf is None else inf.mu_d,
        "mu_d_low": None if inf is None else inf.mu_d_low,
        "mu_d_high": None if inf is None else inf.mu_d_high,
        "t_slip": None if inf is None else inf.t_slip,
        "relative_width": rel_width(mu_low, mu_high),
        "running_max": running,
        "model_fit": model,
        "t_slip_low": iv.t_a, "t_slip_high": iv.t_b,
        "mu_low_creep_model": iv.mu_creep,
        "mu_low_no_error_bars": at(iv.running_max, iv.t_a),
        "mu_high_no_error_bars": at(iv.running_max, iv.t_b),
        "slip_direction": iv.direction,
        "beta_stick_rad": iv.beta_stick,
        "estimator": {"name": kin.method, **kin.settings,
                      "trusted_start_s": iv.details["trusted_start_s"],
                      "trusted_end_s": iv.details["trusted_end_s"]},
        "slip_detection": {"lower_method": opt.interval.lower, "k_sigma": opt.interval.k_sigma,
                           "smooth_s": opt.interval.smooth_s,
                           "reference_s": opt.interval.reference_s,
                           "sigma_deviation_rad": iv.sigma_deviation,
                           "threshold_rad": iv.threshold,
                           **({"creep_threshold_sigma": iv.details["creep_threshold_sigma"]}
                              if "creep_threshold_sigma" in iv.details else {})},
        "noise": {
            "sigma_px": uncertainty.pixel_noise(x, y).tolist(),
            "sigma_theta_rad": kin.sigma_theta,
            "sigma_beta_rad": iv.details["sigma_beta_rad"],
            "sigma_omega_rad_s": float(np.median(kin.sigma_omega[kin.trusted])),
            "sigma_omega_dot_rad_s2": float(np.median(kin.sigma_omega_dot[kin.trusted])),
            "bias_omega_dot_max_rad_s2": float(np.max(kin.bias_omega_dot[kin.trusted])),
            "harmonic_amplitude_max_rad": float(np.max(harm.amplitude)) if opt.harmonic else 0.0,
            "beta_fit_residual_rad": harm.residual_sigma,
        },
        "frames": int(time.size), "fps_hz": 1.0 / dt, "duration_s": float(time[-1] - time[0]),
        "lost_frames": {**{name: int(lost[:, j].sum()) for j, name in
                           enumerate(tracks_io.MARKERS)}, "any": int(lost.any(axis=1).sum())},
        "geometry": {"l_m": l, "d_m": d},
        "error_analysis": uncertainty.error_analysis(mu_low, mu_high, e_omega=opt.e_omega,
                                                     e_omega_dot=opt.e_omega_dot,
                                                     measured=measured),
        "monte_carlo": None,
    }
    if opt.mc_draws > 0:
        def run(xn: np.ndarray, yn: np.ndarray) -> tuple[float | None, float | None]:
            # the running-max interval's noise spread; the model-based set carries its own
            # (likelihood) uncertainty and is not rerun per draw
            out = _core(time, xn, yn, l, d, opt, lost=lost, infer=False)["iv"]
            return out.mu_low, out.mu_high

        summary["monte_carlo"] = uncertainty.monte_carlo(
            run, x, y, np.asarray(summary["noise"]["sigma_px"]), draws=opt.mc_draws,
            seed=opt.seed)
    summary["units"] = {
        "mu_low": "1", "mu_high": "1", "mu_hat": "1", "mu_d": "1", "mu_d_low": "1",
        "mu_d_high": "1", "confidence": "1 (probability)", "t_slip": "s",
        "t_slip_low": "s", "t_slip_high": "s",
        "relative_width": "1 ((mu_high - mu_low) / mid-point)", "sigma_px": "px",
        "e_*": "1 (relative)", "t_*": "s", "*_rad": "rad", "*_rad_s": "rad/s",
        "*_rad_s2": "rad/s^2", "*_s": "s", "*_m": "m", "*_hz": "1/s",
    }
    return table, summary
