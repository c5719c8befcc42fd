"""The monolithic reference solver against the report's published numbers and closed forms."""
import math

import pytest

from abu_model.params import BallParams, PlantParams
from abu_model.reference import simulate_ramp_reference, simulate_staircase_reference
from controller.pi import PISpeedController
from controller.reference import Staircase

HZ = 2 * math.pi


def test_thesis_mode_reproduces_report_eq_4_9():
    plant = PlantParams(ball=BallParams(mu=2.75e-3))
    law = PISpeedController(J_abu=plant.J_abu, theta_ref_mode="thesis")
    res = simulate_staircase_reference(plant, law, Staircase(-17 * HZ, -22 * HZ, 0.0, 1.0), 1.5)
    assert res.mu_low == pytest.approx(2.63e-3, rel=0.03)
    assert res.mu_high == pytest.approx(4.14e-3, rel=0.03)
    assert res.mu_low <= 2.75e-3 < res.mu_high


def test_integral_mode_bounds_are_mu_req_at_step_right_limits():
    """With the integral PI the alpha jump at every step is 2 zeta wn dW on top of a smooth
    response; the bounds are mu_req at the step before and at the slipping step."""
    plant = PlantParams(ball=BallParams(mu=2.75e-3))
    law = PISpeedController(J_abu=plant.J_abu)
    st = Staircase(-17 * HZ, -22 * HZ, 0.0, 1.0)
    res = simulate_staircase_reference(plant, law, st, 1.5)
    assert res.t_slip in st.step_times  # slip starts at a setpoint step
    assert res.mu_low <= 2.75e-3 < res.mu_high
    b = plant.ball
    assert res.mu_high == pytest.approx(b.lever_ratio * abs(res.alpha_slip) / res.omega_slip**2,
                                        rel=1e-12)


def test_ramp_reference_estimate_equals_mu():
    plant = PlantParams(ball=BallParams(mu=1e-2))
    res = simulate_ramp_reference(plant, -20 * HZ, 2000.0, 2.0)
    b = plant.ball
    mu_estimate = b.lever_ratio * abs(res.alpha_slip) / res.omega_slip**2
    assert mu_estimate == pytest.approx(1e-2, rel=1e-9)
    assert [(s.from_mode, s.to_mode) for s in res.switches] == [(0, 1), (1, 0)]
