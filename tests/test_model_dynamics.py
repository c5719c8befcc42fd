"""Equations of motion against an independent derivation from the kinetic energy (report A.10)."""
import math

import numpy as np
import pytest

from abu_model.dynamics import accelerations, mu_required, normal_force, stick_holds
from abu_model.params import BallParams, PlantParams


def kinetic_energy(plant, l, theta_dot, beta_dot):
    """Report eq. A.10 (l fixed, l' = 0) plus the rotor's 1/2 J_abu theta'^2."""
    b = plant.ball
    m, d, J = b.m, b.d, b.J
    ball = 0.5 * m * (beta_dot**2 * l**2 + theta_dot**2 * l**2 + 2 * theta_dot * beta_dot * l**2) \
        + 0.5 * J * (4 * l**2 / d**2 * beta_dot**2 - 4 * l / d * theta_dot * beta_dot + theta_dot**2)
    return ball + 0.5 * plant.J_abu * theta_dot**2


def numeric_mass_matrix(plant):
    """Hessian of the kinetic energy in (theta', beta') by central differences (exact for a quadratic)."""
    h = 1e-2
    f = lambda v: kinetic_energy(plant, plant.ball.l, v[0], v[1])
    e = np.eye(2) * h
    H = np.empty((2, 2))
    for i in range(2):
        for j in range(2):
            H[i, j] = (f(e[i] + e[j]) - f(e[i] - e[j]) - f(-e[i] + e[j]) + f(-e[i] - e[j])) / (4 * h * h)
    return H


def test_normal_force_is_dT_dl():
    plant = PlantParams()
    l = plant.ball.l
    for omega, beta_dot in [(-100.0, 0.0), (-100.0, 3.0), (50.0, -20.0)]:
        eps = 1e-7
        dT_dl = (kinetic_energy(plant, l + eps, omega, beta_dot)
                 - kinetic_energy(plant, l - eps, omega, beta_dot)) / (2 * eps)
        assert normal_force(plant.ball, omega, beta_dot) == pytest.approx(dT_dl, rel=1e-6)
    # stick: F_N = m l omega^2 (report eq. 5.3b)
    b = plant.ball
    assert normal_force(b, -80.0, 0.0) == pytest.approx(b.m * b.l * 6400.0, rel=1e-14)


@pytest.mark.parametrize("mode", [1, -1])
def test_slip_accelerations_solve_lagrange_equations_with_ball_reaction(mode):
    plant = PlantParams(ball=BallParams(mu=0.03), ball_reaction=True)
    H = numeric_mass_matrix(plant)
    torque, omega, beta_dot = 2e-3, -90.0, 2.0 * mode
    acc = accelerations(plant, torque, omega, beta_dot, mode)
    # d/dt dT/dq' = Q with Q_theta = T, Q_beta = -l F_w, F_w = mu F_N sign(beta')
    f_w = 0.03 * normal_force(plant.ball, omega, beta_dot) * mode
    lhs = H @ np.array([acc.alpha, acc.beta_ddot])
    assert lhs == pytest.approx([torque, -plant.ball.l * f_w], rel=1e-6)
    assert acc.friction_force == pytest.approx(f_w, rel=1e-14)


def test_slip_without_reaction_matches_design_closed_form():
    plant = PlantParams(ball=BallParams(mu=0.02))
    b = plant.ball
    torque, omega, beta_dot = -3e-3, -120.0, 5.0
    acc = accelerations(plant, torque, omega, beta_dot, 1)
    alpha = torque / plant.J_abu
    f_n = normal_force(b, omega, beta_dot)
    expected = -((b.l - b.d / 5) * alpha + 0.02 * f_n / b.m) / (1.4 * b.l)
    assert acc.alpha == alpha
    assert acc.beta_ddot == pytest.approx(expected, rel=1e-12)


def test_stick_test_is_the_report_inequality():
    plant = PlantParams(ball=BallParams(mu=2.75e-3))
    b = plant.ball
    omega = -17 * 2 * math.pi
    alpha_crit = b.mu * b.l * omega**2 / (b.l - b.d / 5)
    J = plant.J_total
    assert stick_holds(plant, alpha_crit * J * (1 - 1e-9), omega)
    assert not stick_holds(plant, alpha_crit * J * (1 + 1e-9), omega)
    assert not stick_holds(plant, -alpha_crit * J * (1 + 1e-9), omega)
    assert mu_required(b, alpha_crit, omega) == pytest.approx(b.mu, rel=1e-14)
