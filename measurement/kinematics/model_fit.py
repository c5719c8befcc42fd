"""Fit a parametrised drive model to the ABU angle over the whole record (SI): the least
squares, the error bars, and the refusal when the residual shows the model is wrong.

Shared by the identified staircase loop (:mod:`measurement.kinematics.drive_model`), the
prescribed profile (:mod:`measurement.kinematics.profile_model`) and the loop fitted from the
record alone (:mod:`measurement.kinematics.unknown_loop`). A model gives the parameter names,
start, bounds and Gaussian priors, and ``evaluate(p) -> (Theta, omega, omega_dot)`` at the
frame times; the linear nuisance terms (theta0, a speed offset c t, theta's harmonics 1..3: the
camera's fixed pattern) are projected out. omega(t) and omega_dot(t) come from the fitted model,
their standard errors from the parameter covariance (the Jacobian, scaled up by the reduced
chi-square when it exceeds 1) propagated through the model, with a floor of ``error_rel`` of
|omega_dot| (and the model's own timing bar, ``step_sigma``, where it has one).

**Honest when wrong.** A drive the model does not contain (an undeclared setpoint filter,
torque ripple, a wrong lag held by a tight prior) leaves a systematic residual. The fit is
*refused* when the residual is not white: for block lengths of 8, 32 and 128 ms the means of
non-overlapping blocks of the normalised residual must be consistent with white noise of the
residual's own spread (chi-square over the blocks), and so must the residual averaged over a
staircase's steps (a model with ``step_frames``), aligned on them (2 ms bins over the first
16 ms after each step: a model error at the steps, such as an undeclared setpoint filter,
repeats at every step and adds up there while it drowns in the plain blocks); each test at
``level`` / their number. The residual's spread must not exceed the tracking noise by more
than ``max_rms_ratio``. A refused fit returns the reason; the caller then keeps the
Savitzky-Golay kinematics (:mod:`measurement.kinematics.estimators`).

No 2 ms blocks, and a residual up to 1.5x the noise estimate (first chosen for the profile
model): the tracker's error on a slowly moving CD marker is correlated over a few frames (lag-1
autocorrelation up to 0.54 below 1.8 px/frame), which 2 ms blocks (9 frames) flag and which
makes the noise estimate from third differences low, although the model is right
(``benchmarks/bench_drive_refusals.py``: 9 of 69 rendered staircase recordings were refused
so, omega_dot at the slip within 0.43 stated sigma). The wrong drives show over 8 ms and
longer and at the steps: a lag 30 % off, a torque ripple and an undeclared setpoint filter are
refused as often as with 2 ms blocks (``tests/test_drive_model.py``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from measurement.kinematics.estimators import Kinematics, sample_interval

#: Block lengths of the whiteness test [s] (no 2 ms: see the module doc).
BLOCKS_S = (0.008, 0.032, 0.128)
#: Step-locked whiteness test: bins of this length [s] over at most this long after each
#: step [s] (cut to the shortest gap between steps, so that no sample counts twice).
STEP_BIN_S, STEP_WINDOW_S = 0.002, 0.016


@dataclass(frozen=True)
class DriveModelSettings:
    """Settings of the drive-model fit.

    Attributes:
        level: false-refusal level of the whiteness test (all block lengths together) [-].
        max_rms_ratio: largest accepted residual rms / tracking noise [-] (1.5: the noise
            estimate runs low on correlated tracking error; the covariance is scaled up by
            the ratio either way).
        t_off_max_s: the record's time offset to the staircase is fitted within +- this [s].
        free_loop: fit every loop parameter freely (ignore the drive file's intervals).
        harmonics: harmonics of theta fitted as a fixed pattern of the camera (lens, axis).
        max_evaluations: most model evaluations of the least squares.
        error_rel: a model-discrepancy floor on omega_dot's standard error, relative to
            |omega_dot| [-] (default 1 %: a lag 30 % off held by a tight interval is not
            refused and errs by ~0.1 %; 0: the parameter covariance alone).
        check_white: refuse a fit whose residual is not white (off: only a fit that did not
            converge or whose residual rms exceeds ``max_rms_ratio`` is refused).
    """

    level: float = 0.001
    max_rms_ratio: float = 1.5
    t_off_max_s: float = 0.05
    free_loop: bool = False
    harmonics: int = 3
    max_evaluations: int = 200
    error_rel: float = 0.01
    check_white: bool = True


@dataclass
class DriveFit:
    """Result of :func:`fit_drive_model`.

    Attributes:
        accepted: the residual passed the whiteness test.
        why: the reason of a refusal ('' when accepted).
        params: fitted values by name (theta0_rad, t_off_s, omega_offset_rad_s and the loop's).
        std: their standard errors.
        omega, omega_dot, sigma_omega, sigma_omega_dot: at the frame times [rad/s, rad/s^2].
        rms_ratio: residual rms / tracking noise [-]; block_p: whiteness p-value per block [s].
        loop: the loop the fit assumed, where the fit itself decided it (a controller sample
            time found from the record), for summary.json's ``estimator.loop``; '' otherwise.
    """

    accepted: bool
    why: str
    params: dict[str, float] = field(default_factory=dict)
    std: dict[str, float] = field(default_factory=dict)
    omega: np.ndarray | None = None
    omega_dot: np.ndarray | None = None
    sigma_omega: np.ndarray | None = None
    sigma_omega_dot: np.ndarray | None = None
    rms_ratio: float = math.nan
    block_p: dict[str, float] = field(default_factory=dict)
    residual: np.ndarray | None = None
    loop: str = ""

    def summary(self) -> dict:
        """JSON-ready record for summary.json's ``estimator.model``."""
        return {"model": "accepted" if self.accepted else "refused", "why": self.why,
                "params": self.params, "std": self.std, "rms_ratio": self.rms_ratio,
                "whiteness_p": self.block_p}


def whiteness(res: np.ndarray, dt: float, blocks_s: tuple[float, ...] = BLOCKS_S
               ) -> dict[str, float]:
    """p-value per block length of 'the block means are those of white noise'."""
    from scipy.special import chdtrc   # chi2.sf; scipy.stats' import would cost ~0.7 s

    s = float(np.std(res))
    out = {}
    for block_s in blocks_s:
        m = max(1, int(round(block_s / dt)))
        k = res.size // m
        if k < 4:
            continue
        means = res[: k * m].reshape(k, m).mean(axis=1)
        stat = float(np.sum(means**2) * m / (s * s))
        out[f"{block_s:g}"] = float(chdtrc(k, stat))
    return out


def step_locked(res: np.ndarray, frames: np.ndarray, window: int, dt: float
                 ) -> dict[str, float]:
    """p-value of 'the residual averaged over the steps, aligned on them, in bins of
    STEP_BIN_S, is white noise' (empty with fewer than 3 steps or no whole bin)."""
    from scipy.special import chdtrc

    n_bin = max(1, int(round(STEP_BIN_S / dt)))
    if frames.size < 3 or window < n_bin:
        return {}
    s = float(np.std(res))
    stack = res[frames[:, None] + np.arange(window)[None, :]]          # (steps, window)
    means = stack.reshape(frames.size, window // n_bin, n_bin).mean(axis=(0, 2))
    stat = float(np.sum(means**2) * frames.size * n_bin / (s * s))
    return {"steps": float(chdtrc(means.size, stat))}


def fit_model(t: np.ndarray, th: np.ndarray, model: Any, sigma: float,
              st: DriveModelSettings) -> DriveFit:
    """Fit a drive model (``names``, ``x0``, ``lo``, ``hi``, ``prior``, ``evaluate``) to
    theta over the whole record; the residual tests of the module doc decide acceptance.
    Shared by the staircase loop and the prescribed profile
    (:mod:`measurement.kinematics.profile_model`)."""
    # Within the bounds the optimiser may try an unstable loop (a torque lag too long for its
    # gain, tau > 2 zeta / omega_n): its response overflows to inf / nan, which least_squares
    # rejects as a step. NumPy's warnings about it would reach the user's terminal (or stop a
    # run that treats warnings as errors), so they are silenced here, and a fit whose own
    # kinematics are not finite is refused.
    with np.errstate(over="ignore", invalid="ignore"):
        fit = _fit_model(t, th, model, sigma, st)
    if fit.accepted and not (np.all(np.isfinite(fit.omega_dot))
                             and np.all(np.isfinite(fit.sigma_omega_dot))):
        fit.accepted, fit.why = False, "the fitted loop's response is not finite (unstable)"
    return fit


def solve(t: np.ndarray, th: np.ndarray, model: Any, sigma: float, st: DriveModelSettings,
          max_evaluations: int) -> tuple[Any, np.ndarray, np.ndarray]:
    """The least-squares solution of the model's nonlinear parameters with the linear
    nuisance terms projected out: (SciPy's result, whose ``fun`` starts with the residuals
    [in sigma], the basis, its pseudo-inverse). Raises what least_squares raises on a
    failed fit (ValueError, FloatingPointError, LinAlgError)."""
    from scipy.optimize import least_squares

    # linear nuisance terms: theta0, a speed offset c t, and harmonics 1..3 of theta itself
    # (a camera's lens and the eccentric axis put a fixed pattern on the tracked angle)
    basis = linear_basis(t, th, st.harmonics)
    proj = np.linalg.pinv(basis)
    prior_idx = np.array([i for i, _, _ in model.prior], int)
    prior_c = np.array([c for _, c, _ in model.prior])
    prior_s = np.array([s for _, _, s in model.prior])

    lo, hi = np.array(model.lo, float), np.array(model.hi, float)
    prior_rows = np.zeros((prior_idx.size, lo.size))
    prior_rows[np.arange(prior_idx.size), prior_idx] = 1.0 / prior_s

    def residuals(p: np.ndarray) -> np.ndarray:
        e = th - model.evaluate(p)[0]
        r = (e - basis @ (proj @ e)) / sigma
        return np.concatenate([r, (p[prior_idx] - prior_c) / prior_s]) if prior_idx.size else r

    def jacobian(p: np.ndarray) -> np.ndarray:
        g = model.theta_jacobian(p, lo, hi)
        return np.vstack([(basis @ (proj @ g) - g) / sigma, prior_rows])

    x0 = np.clip(np.array(model.x0, float), lo + 1e-9, hi - 1e-9)
    # a model that knows its own Jacobian (the loop's, :mod:`.drive_model`) gives it
    sol = least_squares(residuals, x0, bounds=(lo, hi), x_scale="jac", method="trf",
                        max_nfev=max_evaluations,
                        jac=jacobian if hasattr(model, "theta_jacobian") else "2-point")
    return sol, basis, proj


def _fit_model(t: np.ndarray, th: np.ndarray, model: Any, sigma: float,
               st: DriveModelSettings) -> DriveFit:
    dt = sample_interval(t)
    try:
        sol, basis, proj = solve(t, th, model, sigma, st, st.max_evaluations)
    except (ValueError, FloatingPointError, np.linalg.LinAlgError) as exc:
        return DriveFit(False, f"the fit failed: {exc}")
    p = sol.x
    e = th - model.evaluate(p)[0]
    lin = proj @ e
    res = (e - basis @ lin) / sigma
    n_par = p.size + basis.shape[1]
    rms_ratio = float(math.sqrt(np.sum(res**2) / max(res.size - n_par, 1)))
    # full covariance of (nonlinear, linear) parameters from the full Jacobian and the prior
    g_th, g_w, g_a = output_jacobian(model, p)
    jac = np.hstack([g_th, basis]) / sigma
    info = jac.T @ jac
    for i, _, s_i in model.prior:
        info[i, i] += 1.0 / s_i**2
    try:   # a loop at the edge of stability can leave non-finite derivatives
        if not np.all(np.isfinite(info)):
            raise np.linalg.LinAlgError("non-finite derivatives")
        cov = np.linalg.pinv(info) * max(1.0, rms_ratio**2)
    except np.linalg.LinAlgError as exc:
        return DriveFit(False, f"the fitted loop's covariance cannot be computed ({exc})",
                        rms_ratio=rms_ratio)
    k = p.size
    c_nl = cov[:k, :k]
    # omega also carries the speed offset c (linear parameter 1)
    g_w_full = np.hstack([g_w, np.zeros((t.size, 1)), np.ones((t.size, 1))])
    cov_w = cov[np.ix_(list(range(k)) + [k, k + 1], list(range(k)) + [k, k + 1])]
    _, omega, alpha = model.evaluate(p, need_theta=False)
    omega = omega + lin[1]
    se_w = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g_w_full, cov_w, g_w_full), 0.0))
    se_a = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", g_a, c_nl, g_a), 0.0))
    se_a = np.hypot(se_a, st.error_rel * np.abs(alpha))
    if hasattr(model, "step_sigma"):
        se_a = np.hypot(se_a, model.step_sigma(p))
    params = {n: float(v) for n, v in zip(model.names, p)}
    params.update(theta0_rad=float(lin[0]), omega_offset_rad_s=float(lin[1]))
    std = {n: float(math.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(model.names)}
    std.update(theta0_rad=float(math.sqrt(cov[k, k])), omega_offset_rad_s=float(
        math.sqrt(cov[k + 1, k + 1])))
    block_p = whiteness(res, dt)
    if hasattr(model, "step_frames"):
        block_p.update(step_locked(res, *model.step_frames(p), dt))
    fit = DriveFit(True, "", params, std, omega, alpha, se_w, se_a, rms_ratio, block_p,
                   residual=res * sigma)
    level_each = st.level / max(len(block_p), 1)
    bad = [b for b, pv in block_p.items() if pv < level_each]
    if not sol.success:
        fit.accepted, fit.why = False, f"the fit did not converge ({sol.message})"
    elif rms_ratio > st.max_rms_ratio:
        fit.accepted, fit.why = False, (
            f"residual rms {rms_ratio:.3g} x the tracking noise (accepted up to "
            f"{st.max_rms_ratio:g}): the drive model does not describe the record")
    elif bad and st.check_white:
        fit.accepted, fit.why = False, (
            f"residual not white: block means over "
            f"{', '.join(b + ' s' if b[0].isdigit() else 'the ' + b for b in bad)} "
            f"(p = {min(block_p[b] for b in bad):.2g} < {level_each:.2g}): a motion the drive "
            "model does not contain")
    return fit


def linear_basis(t: np.ndarray, theta: np.ndarray, harmonics: int) -> np.ndarray:
    """Columns 1, t - mean(t), cos(k theta), sin(k theta) for k = 1..harmonics."""
    cols = [np.ones_like(t), t - float(np.mean(t))]
    for k in range(1, harmonics + 1):
        cols += [np.cos(k * theta), np.sin(k * theta)]
    return np.column_stack(cols)


class LastEvaluation:
    """Mixin of the drive models: :meth:`evaluate` remembers its last parameters and outputs
    (with theta), which :func:`solve`'s least squares asks for again for the Jacobian where
    it just evaluated the residual. A model defines ``_evaluate(p, need_theta)``."""

    _last: tuple[bytes | None, Any] = (None, None)

    def evaluate(self, p: np.ndarray, need_theta: bool = True):
        """(Theta, omega, omega_dot) of the model at the frame times (``_evaluate``'s)."""
        key = p.tobytes()
        if need_theta and self._last[0] == key:
            return self._last[1]
        out = self._evaluate(p, need_theta)
        if need_theta:
            self._last = (key, out)
        return out


#: Forward-difference step of :func:`forward_jacobian` relative to max(1, |p|) (SciPy's for
#: '2-point').
FD_STEP = float(np.finfo(float).eps) ** 0.5


def forward_jacobian(model: Any, p: np.ndarray, lo: np.ndarray, hi: np.ndarray,
                     exact: dict[int, np.ndarray]) -> np.ndarray:
    """d Theta / d p at the frame times, (frames, parameters): the columns in ``exact`` as
    given (a model's closed forms), the others by forward differences of ``model.evaluate``
    with SciPy's '2-point' steps (turned back where a bound is in the way). A model with
    such a ``theta_jacobian`` saves an evaluation a closed-form column at every iteration of
    :func:`solve`, and those columns (the time offset's: the most sensitive) are exact."""
    theta = model.evaluate(p)[0]
    h = FD_STEP * np.where(p >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(p))
    h = np.where((p + h > hi) | (p + h < lo), -h, h)
    h = (p + h) - p   # the step as the sum rounds it
    jac = np.empty((theta.size, p.size))
    for i in range(p.size):
        if i in exact:
            jac[:, i] = exact[i]
            continue
        up = p.copy()
        up[i] += h[i]
        jac[:, i] = (model.evaluate(up)[0] - theta) / h[i]
    return jac


def output_jacobian(model: Any, p: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """d Theta / d p, d omega / d p and d omega_dot / d p at the frame times (central
    differences)."""
    outs = [np.zeros((model.t.size, p.size)) for _ in range(3)]
    for j in range(p.size):
        h = 1e-7 if j == 0 else 1e-6 * max(abs(p[j]), 1e-3)
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        for out, v1, v0 in zip(outs, model.evaluate(up), model.evaluate(down)):
            out[:, j] = (v1 - v0) / (2 * h)
    return outs[0], outs[1], outs[2]


def model_kinematics(fallback: Kinematics, theta: np.ndarray, inp: Any
                     ) -> tuple[Kinematics, DriveFit]:
    """The drive model's kinematics (``inp``: a :class:`DriveModelInput` or a
    ``ProfileModelInput``), or ``fallback`` (the Savitzky-Golay ones) when the fit is
    refused; the fit either way (its :meth:`DriveFit.summary` goes into summary.json)."""
    fit = inp.fit(fallback.time, theta, fallback.sigma_theta)
    info = {**fallback.settings, "model": "accepted" if fit.accepted else "refused",
            "why": fit.why,
            "loop": fit.loop or getattr(inp, "loop_description", "from the drive file"),
            "theta_harmonics_fitted": bool(fit.accepted and getattr(
                inp, "theta_harmonics_fitted", False))}
    if not fit.accepted:
        return replace(fallback, settings=info), fit
    return replace(fallback, omega=fit.omega, omega_dot=fit.omega_dot,
                   sigma_omega=fit.sigma_omega, sigma_omega_dot=fit.sigma_omega_dot,
                   bias_omega_dot=np.zeros_like(fit.omega_dot), method="drive-model",
                   settings=info, omega_dot_rho=None), fit


def apply(fallback: Kinematics, theta: np.ndarray, inp: Any) -> Kinematics:
    """The analysis's hook: the drive model's kinematics where ``inp`` is given and the fit
    is accepted, else ``fallback`` (with the refusal's reason in its settings)."""
    if inp is None:
        return replace(fallback, settings={**fallback.settings, "model": "refused",
                                           "why": "no drive and staircase given"})
    return model_kinematics(fallback, theta, inp)[0]
