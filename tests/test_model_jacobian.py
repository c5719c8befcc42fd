"""The drive models' own Jacobians (``theta_jacobian``: the time offset's column, and the
profile's gain column, in closed form; the others by forward differences) against SciPy's
central differences, and the fits they drive against the same fits with SciPy's '2-point'
Jacobian (the fits before the closed forms): the same loop, residual and omega_dot.

Models: the identified loop over a stated staircase (continuous, with a setpoint filter, and
a digital controller's sampled steps), the staircase search's sine model (te and span fitted
too), and the prescribed profile through a tracking loop (gain and bandwidth fitted).
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize._numdiff import approx_derivative

from abu_model.loop_response import Setpoints, response
from abu_model.tracking_response import response as tracking_response
from controller.drive import Drive
from controller.profile import Profile
from measurement.kinematics import model_fit
from measurement.kinematics.drive_model import LoopModel
from measurement.kinematics.model_fit import DriveModelSettings, fit_model
from measurement.kinematics.profile_model import _ProfileModel
from measurement.kinematics.staircase_guess import SineStaircase
from measurement.kinematics.sine_model import SineModel as _SineModel

FPS = 3000.0
SIGMA = 1e-4
TWO_PI = 2 * math.pi
STAIRS = Setpoints((0.05, 0.11, 0.16, 0.2, 0.26), tuple(-60.0 - TWO_PI * np.arange(6)))
PROFILE = Profile((0.05, 0.1, 0.2, 0.3, 0.4), (-200.0, -196.0, -170.0, -130.0, -120.0))


def _loop(sample_time=None) -> Drive:
    return Drive(model="pi-lag-weighted", zeta=0.75, omega_n=22.0, tau_motor=0.006,
                 setpoint_weight=0.8, setpoint_tau=0.004, sample_time=sample_time)


def _models():
    t = np.arange(1200) / FPS
    st = DriveModelSettings()
    sine = SineStaircase(0.04, 0.0, 6, -60.0, -1.0, TWO_PI)
    tracking = Drive(model="tracking", bandwidth=150.0, tau_motor=0.005)
    return {"loop": LoopModel(t, _loop(), STAIRS, st, 2e-4),
            "digital": LoopModel(t, _loop(1.0 / 6000.0), STAIRS, st, -3e-4),
            "sine": _SineModel(t, _loop(), sine, 0.3, 6.4, st, 1e-4),
            "profile": _ProfileModel(t, tracking, PROFILE, st)}


@pytest.mark.parametrize("name", ["loop", "digital", "sine", "profile"])
def test_theta_jacobian_matches_central_differences(name):
    model = _models()[name]
    p = np.array(model.x0, float)
    p[0] += 1e-4   # off the start: a time offset not 0
    lo, hi = np.array(model.lo, float), np.array(model.hi, float)
    got = model.theta_jacobian(p, lo, hi)
    ref = approx_derivative(lambda x: model.evaluate(x)[0].copy(), p, method="3-point",
                            bounds=(lo, hi))
    for j, param in enumerate(model.names):
        scale = float(np.max(np.abs(ref[:, j])))
        assert np.max(np.abs(got[:, j] - ref[:, j])) <= 1e-4 * scale, (name, param)


def _record(seed: int, model_name: str):
    rng = np.random.default_rng([seed, 17])
    t = np.arange(1500) / FPS
    if model_name == "profile":
        truth = tracking_response(PROFILE, t - 4e-4, 150.0 * rng.uniform(0.9, 1.1), 0.005,
                                  gain=1.003).theta
    else:
        drive = _loop()
        truth = response(STAIRS, t - 6e-4, drive.zeta * rng.uniform(0.9, 1.1),
                         drive.omega_n * rng.uniform(0.9, 1.1), drive.tau_motor, 0.8, True,
                         setpoint_tau=drive.setpoint_tau).theta
    return t, 1.0 + truth + 3e-4 * np.cos(truth + 1.0) + SIGMA * rng.standard_normal(t.size)


@pytest.mark.parametrize("model_name", ["loop", "profile"])
def test_fits_with_the_closed_forms_match_the_finite_difference_fits(model_name, monkeypatch):
    """Four records each: the fit with the models' Jacobians and with SciPy's '2-point' one
    reach the same residual (to 1e-4 of the noise) and omega_dot (to 1 % of its median bar;
    measured: <= 4e-4)."""
    st = DriveModelSettings(free_loop=True)
    for seed in range(4):
        t, theta = _record(seed, model_name)

        def fit():
            if model_name == "profile":
                m = _ProfileModel(t, Drive(model="tracking", bandwidth=140.0, tau_motor=0.005),
                                  PROFILE, st)
            else:
                m = LoopModel(t, _loop(), STAIRS, st)
            return fit_model(t, theta, m, SIGMA, st), m

        own, model = fit()
        assert hasattr(model, "theta_jacobian")
        with monkeypatch.context() as mp:   # the models without their Jacobians
            mp.delattr(type(model), "theta_jacobian")
            plain, _ = fit()
        assert own.accepted and plain.accepted, (seed, own.why, plain.why)
        assert abs(own.rms_ratio - plain.rms_ratio) <= 1e-4, seed
        # (the bar goes to ~0 where omega_dot does: before the steps, after the profile)
        gap = np.max(np.abs(own.omega_dot - plain.omega_dot)) / np.median(plain.sigma_omega_dot)
        assert gap <= 0.01, (seed, gap)


def test_a_wrong_closed_form_column_is_caught(monkeypatch):
    """The comparison above can fail: the time offset's column with the wrong sign."""
    model = _models()["loop"]
    p = np.array(model.x0, float)
    lo, hi = np.array(model.lo, float), np.array(model.hi, float)
    real = model_fit.forward_jacobian
    monkeypatch.setattr("measurement.kinematics.drive_model.forward_jacobian",
                        lambda m, q, a, b, exact: real(m, q, a, b, {0: -exact[0]}))
    got = model.theta_jacobian(p, lo, hi)
    ref = approx_derivative(lambda x: model.evaluate(x)[0].copy(), p, method="3-point",
                            bounds=(lo, hi))
    assert np.max(np.abs(got[:, 0] - ref[:, 0])) > 1.0 * np.max(np.abs(ref[:, 0]))
