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

from dataclasses import replace

import numpy as np

from abu_model.errors import AbuError, ParameterError
from abu_model.params import check_positive

from measurement.imaging import tracks_io
from measurement.imaging.geometry import circle_centre, fixed_axis  # noqa: F401  (re-exported)
from measurement.inference import infer_mu as inference_mod
from measurement.inference import running_max as interval_mod
from measurement.inference import onset as onset_mod
from measurement.inference.slip_model import signed_mu_req, slip_direction, spinning_run
from measurement.inference import lighting_models, uncertainty, window_sets
from measurement.inference.analysis_summary import SUMMARY_UNITS, record_summary, record_table
from measurement.inference.options import PHASES, AnalysisOptions  # noqa: F401  (re-exported)
from measurement.kinematics import estimators as kin_mod
from measurement.kinematics import harmonic as harmonic_mod


class AnalysisError(AbuError, ValueError):
    """The tracks cannot be analysed (non-uniform sampling, too short, bad shapes)."""


def _kinematics(time: np.ndarray, theta: np.ndarray, opt: AnalysisOptions) -> kin_mod.Kinematics:
    kin = _estimator(time, theta, opt)
    if opt.kinematics == "drive-model":
        # imported only for this option (the inputs load the loop response and drive code)
        from measurement.kinematics import model_fit
        kin = model_fit.apply(kin, theta, opt.drive_model)
    # the ball model needs the ABU spinning (a stop or reversal leaves the trusted run)
    trusted = spinning_run(kin.omega, kin.trusted)
    return kin if trusted is kin.trusted else replace(kin, trusted=trusted)


def _estimator(time: np.ndarray, theta: np.ndarray, opt: AnalysisOptions) -> kin_mod.Kinematics:
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


def _core(time: np.ndarray, x: np.ndarray, y: np.ndarray, l: float, d: float,
          opt: AnalysisOptions, lost: np.ndarray | None = None, infer: bool = True) -> dict:
    """Angles, kinematics, harmonic removal and interval for filled coordinates."""
    theta, beta = tracks_io.angles_from_pixels(*fixed_axis(x, y))
    kin = _kinematics(time, theta, opt)
    trusted = kin.trusted
    direction = slip_direction(kin.omega, kin.omega_dot, trusted)
    harm = _lighting_fit(time, theta, beta, tuple(opt.harmonic_orders) if opt.harmonic else (),
                         direction, opt)
    iv = interval_mod.slip_interval(time, kin.omega, kin.omega_dot, kin.sigma_omega,
                                    kin.sigma_omega_dot, trusted, harm.beta_clean, harm.residual,
                                    l=l, d=d, options=opt.interval, direction=direction,
                                    bias_omega_dot=kin.bias_omega_dot)
    inf = None
    if infer and opt.inference is not None:
        lost_any = None if lost is None else np.asarray(lost, bool)[:, 1:].any(axis=1)
        inf = _model_set(time, theta, harm, kin, iv, lost_any, l, d, direction, opt)
        inf = _second_lighting_model(time, theta, beta, harm, kin, iv, lost_any, l, d,
                                     direction, opt, inf)
    bracket = None if inf is None else _onset(time, kin, l, d, direction, inf, opt)
    return {"theta": theta, "beta": beta, "kin": kin, "harm": harm, "iv": iv, "inf": inf,
            "onset": bracket}


def _lighting_fit(time: np.ndarray, theta: np.ndarray, beta: np.ndarray,
                  orders: tuple[int, ...], direction: int,
                  opt: AnalysisOptions) -> harmonic_mod.HarmonicFit:
    """The whole-record fit of beta: monotone b(t) + the lighting harmonics of ``orders`` (none:
    b(t) alone) in the ball's angle or theta (``harmonic_phase``)."""
    phase = theta + beta if opt.harmonic_phase == "ball" and orders else theta
    return harmonic_mod.remove_harmonic(time, beta, phase, orders=orders,
                                        amp_degree=opt.harmonic_amp_degree,
                                        knot_spacing_s=opt.knot_spacing_s, direction=direction)


def _model_set(time: np.ndarray, theta: np.ndarray, harm: harmonic_mod.HarmonicFit,
               kin: kin_mod.Kinematics, iv, lost_any: np.ndarray | None, l: float, d: float,
               direction: int, opt: AnalysisOptions) -> inference_mod.Inference:
    """The model-based set on mu from beta cleaned by ``harm`` (one set per kinematics
    window, intersected: :mod:`window_sets`)."""
    windows = inference_windows(time.size, kin_mod.sample_interval(time), opt)
    each = replace(opt.inference, confidence=window_sets.level_each(
        opt.inference.confidence, len(windows)), theta_harmonic_rad=_lens_prior(kin, opt))
    sets: list[inference_mod.Inference] = []
    for k, window in enumerate(windows):
        kin_w = kin if k == 0 else _kinematics(time, theta, opt.with_(sg_window_s=window))
        # beta with the lighting harmonics removed by the whole-record fit (monotone b(t)
        # + harmonics over all revolutions); the window refits the low orders as nuisances
        sets.append(inference_mod.infer_mu(
            time, theta, harm.beta_clean, kin_w.omega, kin_w.omega_dot, kin_w.sigma_omega,
            kin_w.sigma_omega_dot, kin_w.bias_omega_dot, kin_w.trusted, l=l, d=d,
            direction=direction, lost=lost_any, deviation=iv.deviation,
            record_residual=harm.residual, omega_dot_rho=kin_w.omega_dot_rho,
            # beta's noise model is the record's, whatever the kinematics: estimated once
            noise=(sets[0].details.get("noise_model") or None) if sets else None,
            options=each))
    return window_sets.intersect_sets(sets, windows, opt.inference.confidence)


def _second_lighting_model(time: np.ndarray, theta: np.ndarray, beta: np.ndarray,
                           harm: harmonic_mod.HarmonicFit, kin: kin_mod.Kinematics, iv,
                           lost_any: np.ndarray | None, l: float, d: float, direction: int,
                           opt: AnalysisOptions, inf: inference_mod.Inference
                           ) -> inference_mod.Inference:
    """``inf`` joined with the set under the alternative lighting orders where the two
    models' cleaned betas disagree in the fit window (:mod:`lighting_models`)."""
    alt_orders = tuple(opt.harmonic_orders_alternative or ())   # None (not chosen): none
    if not opt.harmonic or not alt_orders or alt_orders == tuple(opt.harmonic_orders):
        return inf
    alt = _lighting_fit(time, theta, beta, alt_orders, direction, opt)
    whitener = lighting_models.whitener(inf, int(lighting_models.window_of(inf).sum()),
                                        kin_mod.sample_interval(time),
                                        float(harm.residual_sigma))
    chi2 = lighting_models.bound_shift_chi2(inf, harm.beta_clean, alt.beta_clean, theta,
                                            tuple(opt.inference.harmonic_orders),
                                            opt.inference.theta_harmonics, whitener)
    if chi2 <= lighting_models.DISAGREEMENT_CHI2:
        return replace(inf, details={**inf.details, "lighting_disagreement_chi2": chi2,
                                     "second_lighting_orders": list(alt_orders)})
    other = _model_set(time, theta, alt, kin, iv, lost_any, l, d, direction, opt)
    union = lighting_models.union_sets(inf, other, (tuple(opt.harmonic_orders), alt_orders))
    return replace(union, details={**union.details, "lighting_disagreement_chi2": chi2,
                                   "second_lighting_orders": list(alt_orders)})


def _onset(time: np.ndarray, kin: kin_mod.Kinematics, l: float, d: float, direction: int,
           inf: inference_mod.Inference,
           opt: AnalysisOptions) -> onset_mod.OnsetBracket:
    """The slip-onset bracket from the model's set on mu (:mod:`onset`)."""
    q_lo, q_hi = onset_mod.q_band(kin.omega, kin.omega_dot, kin.sigma_omega,
                                  kin.sigma_omega_dot, kin.bias_omega_dot, l, d, direction,
                                  float(opt.interval.k_sigma),
                                  _lens_prior(kin, opt))
    q = signed_mu_req(kin.omega, kin.omega_dot, l, d, direction)
    return onset_mod.onset_bracket(time, q, q_lo, q_hi, kin.trusted, inf.mu_low, inf.mu_high)


def _lens_prior(kin: kin_mod.Kinematics, opt: AnalysisOptions) -> float:
    """The lens prior on theta's first harmonic [rad]; 0 where the kinematics fitted theta's
    harmonics as nuisances (the profile model: a lens harmonic then does not enter omega_dot)."""
    if kin.settings.get("theta_harmonics_fitted"):
        return 0.0
    return float(opt.inference.theta_harmonic_rad)


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


def _check_geometry(l: float, d: float) -> tuple[float, float]:
    """(l, d) [m], checked: both > 0 and the ball fits its path (d < 2 l)."""
    l = check_positive("l", l, "m")
    d = check_positive("d", d, "m")
    if d >= 2.0 * l:
        raise ParameterError("d", d, f"a ball diameter < 2 l = {2 * l:g} m")
    return l, d


def _fill_lost(time: np.ndarray, x: np.ndarray, y: np.ndarray, lost: np.ndarray,
               opt: AnalysisOptions) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) [px] with the short gaps of lost markers interpolated (long ones rejected)."""
    x = tracks_io.fill_lost(time, x, lost, max_gap=opt.max_lost_gap,
                            max_fraction=opt.max_lost_fraction)
    y = tracks_io.fill_lost(time, y, lost, max_gap=opt.max_lost_gap,
                            max_fraction=opt.max_lost_fraction)
    return x, y


def _monte_carlo(time: np.ndarray, x: np.ndarray, y: np.ndarray, lost: np.ndarray, l: float,
                 d: float, sigma_px: list, opt: AnalysisOptions) -> dict:
    """Spread of the running-max interval over redrawn tracking noise ``sigma_px`` [px]."""
    def run(xn: np.ndarray, yn: np.ndarray) -> tuple[float | None, float | None]:
        # the running-max interval's noise spread; the model-based set carries its own
        # (likelihood) uncertainty and is not rerun per draw
        out = _core(time, xn, yn, l, d, opt, lost=lost, infer=False)["iv"]
        return out.mu_low, out.mu_high

    return uncertainty.monte_carlo(run, x, y, np.asarray(sigma_px), draws=opt.mc_draws,
                                   seed=opt.seed)


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
    l, d = _check_geometry(l, d)
    time, x, y, lost = _validate(time, x, y, lost, fps)
    x, y = _fill_lost(time, x, y, lost, opt)
    core = _core(time, x, y, l, d, opt, lost=lost)
    table = record_table(time, core, lost)
    summary = record_summary(time, x, y, lost, l, d, core, opt)
    if opt.mc_draws > 0:
        summary["monte_carlo"] = _monte_carlo(time, x, y, lost, l, d,
                                              summary["noise"]["sigma_px"], opt)
    summary["units"] = dict(SUMMARY_UNITS)
    return table, summary
