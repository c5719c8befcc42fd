"""Identify the closed speed loop from a record of its response to a known setpoint sequence.

Least squares on the exact simulated response (:mod:`.loop_response`, python-control poles):

* ``omega`` records: residual omega_model(t) - omega(t);
* ``theta`` records (a camera's tracks.csv): theta_model(t) + c - theta(t), c fitted;
* ``pulses`` (the report's optical sensor): the angle at each pulse time is known, +-2 pi k/N,
  so the residual is theta_model(t_k) + c - 2 pi k / N: timing jitter and quantisation enter as
  white angle errors (omega from pulse intervals would correlate neighbours).

Parameters are fitted on a log scale (positive by construction); the covariance is
s^2 (J^T J)^-1, widened by (1 + r1)/(1 - r1) when the residuals' lag-1 autocorrelation r1 > 0
(an AR(1) effective sample size), and the 95 % intervals are exp(q +- t_{0.975} se). The
residual check says the model does not fit when r1 > :data:`R1_MAX` (most of the residual is a
smooth systematic curve, not noise). The report's method (overshoot and 2 % settling time of
one step response, standard second-order formulas) is computed beside the fit.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.optimize import least_squares
from scipy.signal import savgol_filter
from scipy.stats import t as student_t

from abu_model.errors import AbuError, ParameterError
from controller.drive import MODEL_PARAMETERS, MODELS, Drive, lag_limit_s

from harness.planning.loop_response import Setpoints, response
from harness.planning.record_io import Record, omega_from_pulses

#: Lag-1 autocorrelation of the residuals above which the model is said not to fit.
R1_MAX = 0.5
_LOG_TAU_MIN = math.log(1e-5)  # tau_motor below 10 us is indistinguishable from 0
#: Largest |log| of a fitted parameter (e^50 ~ 5e21): beyond it the fit has run off to zero or
#: infinity (zeta, omega_n [rad/s], tau_motor [s] and b are physically within 1e-6..1e6).
_LOG_LIMIT = 50.0


class IdentifyError(AbuError, ValueError):
    """The loop model cannot describe the record (the fit diverged or did not converge)."""


class _Diverged(Exception):
    """Raised inside the residual function to stop a fit that runs off."""


@dataclass
class IdentifyResult:
    """A fitted drive with its statistics (SI).

    Attributes:
        drive: the fitted drive (parameters, 95 % intervals, fit information).
        params: parameter name -> value; ``std``: -> standard deviation.
        cov: covariance of the model parameters (order of MODEL_PARAMETERS[model]).
        t, y, y_fit, residual: the fitted samples (y: omega [rad/s] or angle [rad]).
        omega_t, omega_data, omega_fit: speed data for plots [s], [rad/s].
        check: residual check (rms, lag-1 autocorrelation, verdict, message).
        report_method: the report's overshoot/settling identification (or None).
    """

    drive: Drive
    params: dict[str, float]
    std: dict[str, float]
    cov: np.ndarray
    t: np.ndarray
    y: np.ndarray
    y_fit: np.ndarray
    residual: np.ndarray
    kind: str
    omega_t: np.ndarray
    omega_data: np.ndarray
    omega_fit: np.ndarray
    setpoints: Setpoints
    check: dict[str, Any] = field(default_factory=dict)
    report_method: dict[str, Any] | None = None

    def as_dict(self) -> dict[str, Any]:
        """The ``--json`` output: the drive.json object plus the report's method."""
        out = self.drive.to_dict()
        out["report_method"] = self.report_method
        return out


def _direction(setpoints: Setpoints) -> float:
    levels = np.asarray(setpoints.levels)
    return math.copysign(1.0, levels[np.argmax(np.abs(levels))])


def _unpack(q: np.ndarray, model: str) -> tuple[float, float, float, float]:
    zeta, wn = math.exp(q[0]), math.exp(q[1])
    tau = math.exp(q[2]) if model != "second-order" else 0.0
    b = math.exp(q[3]) if model == "pi-lag-weighted" else 1.0
    return zeta, wn, tau, b


def _model_values(q, model, setpoints, t, kind):
    zeta, wn, tau, b = _unpack(q, model)
    r = response(setpoints, t, zeta, wn, tau, b, need_theta=kind != "omega")
    return r.omega if kind == "omega" else r.theta


def _start_grid(model: str) -> list[np.ndarray]:
    taus = [0.0] if model == "second-order" else [0.003, 0.03]
    return [np.log([z, w] + ([tau] if tau else []) + ([1.0] if model == "pi-lag-weighted" else []))
            for z in (0.35, 0.7, 1.2) for w in np.geomspace(0.7, 120.0, 14) for tau in taus]


def residual_check(residual: np.ndarray) -> dict[str, Any]:
    """RMS and lag-1 autocorrelation of the residuals, and whether the model fits."""
    r = residual - residual.mean()
    rms = float(np.sqrt(np.mean(r**2)))
    r1 = float(np.sum(r[1:] * r[:-1]) / np.sum(r**2)) if rms > 0 else 0.0
    fits = r1 <= R1_MAX
    msg = ("residuals look like noise: the model fits" if fits else
           f"residuals are systematic (lag-1 autocorrelation {r1:.2f} > {R1_MAX}): the model "
           "does not fit this record; try a richer --model or check the setpoints")
    return {"rms": rms, "lag1_autocorrelation": r1, "durbin_watson": 2.0 * (1.0 - r1),
            "fits": bool(fits), "message": msg}


def fit_drive(record: Record, setpoints: Setpoints, model: str = "pi-lag") -> IdentifyResult:
    """Least-squares fit of ``model`` to ``record`` driven by ``setpoints``."""
    if model not in MODELS:
        raise ParameterError("--model", model, f"one of {', '.join(MODELS)}")
    names = MODEL_PARAMETERS[model]
    direction = _direction(setpoints)
    t = np.asarray(record.t, float)
    kind = "omega" if record.kind == "omega" else "theta"
    y = record.angle(direction) if kind == "theta" else np.asarray(record.y, float)
    n_p = len(names) + (kind == "theta")
    if t.size <= n_p + 2:
        raise ParameterError("--record", record.source, f"more than {n_p + 2} samples")
    steps = np.asarray(setpoints.step_times)[np.diff(np.asarray(setpoints.levels)) != 0]
    if steps.size == 0:
        raise ParameterError("--setpoints", [float(v) for v in setpoints.levels],
                             "a setpoint sequence with at least one step (a constant setpoint "
                             "shows nothing of the loop)")
    if np.count_nonzero(t > steps[0]) < 2 * n_p + 5:
        raise ParameterError("--record", record.source,
                             f"a record that covers the response to the setpoint steps (it has "
                             f"{np.count_nonzero(t > steps[0])} samples after the first step at "
                             f"{steps[0]:g} s; check the time origin of the setpoints)")

    def disagree(why: str) -> IdentifyError:
        return _disagree(record.source, model, why)

    def resid(q: np.ndarray) -> np.ndarray:
        if not np.all(np.abs(q[:len(names)]) <= _LOG_LIMIT):
            raise _Diverged("the parameters ran off to zero or infinity")
        with np.errstate(all="ignore"):
            r = _model_values(q[:len(names)], model, setpoints, t, kind) - y
            r = r + q[-1] if kind == "theta" else r
        if not np.all(np.isfinite(r)):
            raise _Diverged("the simulated response overflows")
        return r

    def profiled(q: np.ndarray) -> float:  # offset eliminated for the start search
        with np.errstate(all="ignore"):
            r = _model_values(q, model, setpoints, t, kind) - y
            cost = float(np.sum((r - r.mean()) ** 2) if kind == "theta" else np.sum(r**2))
        return cost if math.isfinite(cost) else math.inf

    starts = _start_grid(model)
    q0 = min(starts, key=profiled)
    if not math.isfinite(profiled(q0)):
        raise disagree("no starting value gives a finite response")
    if kind == "theta":
        q0 = np.append(q0, -np.mean(_model_values(q0, model, setpoints, t, kind) - y))
    lower = np.full(q0.size, -np.inf)
    if model != "second-order":
        lower[2] = _LOG_TAU_MIN
        q0[2] = max(q0[2], _LOG_TAU_MIN + 1e-3)
    sol = _solve(resid, q0, lower, disagree)
    residual = sol.fun
    check = residual_check(residual)
    dof = max(1, t.size - n_p)
    s2 = 2.0 * sol.cost / dof
    inflate = (1 + check["lag1_autocorrelation"]) / (1 - check["lag1_autocorrelation"]) \
        if 0 < check["lag1_autocorrelation"] < 0.999 else (1.0 if check["lag1_autocorrelation"] <= 0
                                                           else 1e6)
    cov_q = s2 * inflate * np.linalg.pinv(sol.jac.T @ sol.jac)
    k = len(names)
    se_q = np.sqrt(np.clip(np.diag(cov_q)[:k], 0.0, None))
    qt = float(student_t.ppf(0.975, dof))
    if not (np.all(np.isfinite(cov_q)) and np.all(np.abs(sol.x[:k]) + qt * se_q <= _LOG_LIMIT)):
        raise disagree("the fitted parameters are not determined by the record: their 95 % "
                       "intervals span zero to infinity")
    values = dict(zip(names, np.exp(sol.x[:k])))
    ci95 = {n: (float(math.exp(sol.x[i] - qt * se_q[i])), float(math.exp(sol.x[i] + qt * se_q[i])))
            for i, n in enumerate(names)}
    scale = np.exp(sol.x[:k])
    cov = cov_q[:k, :k] * np.outer(scale, scale)  # delta method, for reporting
    std = {n: float(math.sqrt(max(cov[i, i], 0.0))) for i, n in enumerate(names)}
    zeta, wn, tau, b = _unpack(sol.x, model)
    if tau >= lag_limit_s(zeta, wn):   # what drive.json refuses
        raise disagree(f"the fitted loop is unstable: tau_motor {tau:.4g} s >= 2 zeta / "
                       f"omega_n = {lag_limit_s(zeta, wn):.4g} s, a speed oscillation that "
                       "grows without bound, which no running drive shows")
    if model != "second-order" and tau <= 1.01e-5:
        check["message"] += "; tau_motor is at its lower limit (no lag seen)"
    fit_info = {"record": record.source, "record_kind": record.kind, "samples": int(t.size),
                "residual_rms": check["rms"],
                "residual_unit": "rad/s" if kind == "omega" else "rad",
                "lag1_autocorrelation": check["lag1_autocorrelation"], "fits": check["fits"],
                "message": check["message"], "std": std}
    drive = Drive(model=model, zeta=zeta, omega_n=wn, tau_motor=tau, setpoint_weight=b,
                  ci95=ci95, fit=fit_info, source=f"abu identify {record.source}")
    fitted = resid(sol.x) + y
    omega_t, omega_data = _omega_samples(record, direction)
    omega_fit = response(setpoints, omega_t, zeta, wn, tau, b, need_theta=False).omega
    result = IdentifyResult(drive, {n: float(v) for n, v in values.items()}, std, cov, t, y,
                            fitted, residual, kind, omega_t, omega_data, omega_fit, setpoints,
                            check)
    result.report_method = report_method(omega_t, omega_data, setpoints)
    return result


def _disagree(source: str, model: str, why: str) -> IdentifyError:
    return IdentifyError(
        f"{source}: the {model} model and the record disagree ({why}); check that the "
        "setpoints (--setpoints, or --omega0-hz, --omega-end-hz, --t0, --te, --step-hz, "
        "--rounding) are the ones that drove this record, and its time origin and units")


def _solve(resid, q0: np.ndarray, lower: np.ndarray, disagree):
    """least_squares with its failures (divergence, overflow, no convergence) turned into
    ``disagree(why)`` errors."""
    try:
        sol = least_squares(resid, q0, bounds=(lower, np.inf), x_scale="jac", method="trf",
                            xtol=1e-12, ftol=1e-12, gtol=1e-12, max_nfev=400)
    except _Diverged as exc:
        raise disagree(f"the fit diverged: {exc}") from None
    except (ValueError, np.linalg.LinAlgError, FloatingPointError, OverflowError) as exc:
        raise disagree(f"the fit failed: {' '.join(str(exc).split())[:120]}") from None
    if sol.status <= 0:
        raise disagree(f"the fit did not converge: {sol.message}")
    return sol


def _omega_samples(record: Record, direction: float) -> tuple[np.ndarray, np.ndarray]:
    """Speed samples for plots and the report's method [s], [rad/s]."""
    if record.kind == "omega":
        return record.t, record.y
    if record.kind == "pulses":
        return omega_from_pulses(record, direction)
    dt = float(np.median(np.diff(record.t)))
    window = max(5, int(round(0.01 / dt)) | 1)  # 10 ms Savitzky-Golay derivative
    if window >= record.t.size:
        return record.t[1:], np.diff(record.y) / np.diff(record.t)
    return record.t, savgol_filter(record.y, window, 2, deriv=1, delta=dt)


def report_method(t: np.ndarray, omega: np.ndarray, setpoints: Setpoints) -> dict[str, Any] | None:
    """The report's identification (sec. 4.2.1) from the largest setpoint step in the record.

    Overshoot Mp of the step response -> zeta = -ln Mp / sqrt(pi^2 + ln^2 Mp); 2 % settling
    time ts -> omega_n = 4 / (zeta ts) (standard second-order formulas). The window runs from
    the step to the next step or the record's end. None when the record shows no full step.
    """
    tk = np.asarray(setpoints.step_times)
    levels = np.asarray(setpoints.levels)
    if tk.size == 0:
        return None
    dw = np.diff(levels)
    for j in np.argsort(-np.abs(dw)):
        end = tk[j + 1] if j + 1 < tk.size else t[-1]
        inside = (t > tk[j]) & (t <= end)
        if inside.sum() < 5 or t[0] > tk[j]:
            continue
        e = (omega[inside] - levels[j + 1]) / dw[j]  # normalised: 0 = on the new setpoint
        mp = float(np.max(e))
        if mp <= 0.0:
            return {"usable": False, "message": "no overshoot: the report's method needs one"}
        out = np.flatnonzero(np.abs(e) > 0.02)
        if out.size == 0 or out[-1] == e.size - 1:
            return {"usable": False, "message": "the response does not settle within 2 % "
                                                "before the next step or the record's end"}
        ts = float(t[inside][out[-1] + 1] - tk[j])
        ln = math.log(mp)
        zeta = -ln / math.sqrt(math.pi**2 + ln**2)
        return {"usable": True, "step_time_s": float(tk[j]), "step_rad_s": float(dw[j]),
                "overshoot": mp, "settling_time_s": ts, "zeta": zeta,
                "omega_n_rad_s": 4.0 / (zeta * ts)}
    return None
