"""Equations of motion of one ball on the rim of the ABU (report ch. 3 and app. A, checked).

Generalised coordinates beta (ball angle relative to the ABU) and theta (ABU angle); the
radial coordinate l is held by the normal force. With c = m l^2 - J 2l/d = m l (l - d/5) and
M = m l^2 + J (2l/d)^2 = 1.4 m l^2 the equations are

    J_abu theta'' [+ (m l^2 + J) theta'' + c beta''] = T          (rotor; [..] = ball reaction)
    c theta'' + M beta'' = -l F_w                                 (ball)
    F_N = m [ l (theta' + beta')^2 + 0.4 l beta'^2 - 0.2 d theta' beta' ]

with F_w the friction force, opposing positive beta' when positive:

* stick (beta' = beta'' = 0): F_w = -c alpha / l, held while |F_w| <= mu F_N;
* slip in direction s = sign(beta'): F_w = mu_d F_N s.

Without the ball reaction (the report's model) the rotor obeys J_abu theta'' = T alone.
All functions take and return SI values.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from .numerics import poly_der
from .params import BallParams, PlantParams

STICK = 0


def normal_force(ball: BallParams, omega: float, beta_dot: float) -> float:
    """Normal force of the rim on the ball [N] (positive = pressing the ball inwards)."""
    m, l, d = ball.m, ball.l, ball.d
    return m * (l * (omega + beta_dot) ** 2 + 0.4 * l * beta_dot**2 - 0.2 * d * omega * beta_dot)


def stick_friction(ball: BallParams, alpha: float) -> float:
    """Friction force that keeps the ball in stick at rotor acceleration alpha [N]."""
    return -ball.coupling * alpha / ball.l


def mu_required(ball: BallParams, alpha: float, omega: float) -> float:
    """mu_req = (l - d/5) |alpha| / (l omega^2) [-], eq. 4.1/4.2/5.3 (inf at omega = 0)."""
    if omega == 0.0:
        return math.inf if alpha != 0.0 else 0.0
    return ball.lever_ratio * abs(alpha) / (omega * omega)


def stick_alpha(plant: PlantParams, torque: float) -> float:
    """Rotor acceleration while the ball sticks [rad/s^2] for the applied torque [N m]."""
    return torque / plant.J_total


@dataclass(frozen=True)
class Accelerations:
    """Accelerations and contact forces at one instant (SI)."""

    alpha: float          #: rotor acceleration theta'' [rad/s^2]
    beta_ddot: float      #: ball acceleration relative to the ABU [rad/s^2]
    normal_force: float   #: F_N [N]
    friction_force: float  #: F_w [N]


def accelerations(plant: PlantParams, torque: float, omega: float, beta_dot: float,
                  mode: int) -> Accelerations:
    """Accelerations for the applied torque [N m] in ``mode`` (0 stick, +1/-1 slip direction)."""
    ball = plant.ball
    if mode == STICK:
        alpha = stick_alpha(plant, torque)
        return Accelerations(alpha, 0.0, normal_force(ball, omega, 0.0),
                             stick_friction(ball, alpha))
    f_n = normal_force(ball, omega, beta_dot)
    f_w = ball.mu_dynamic * f_n * mode
    c, M, l = ball.coupling, ball.M_bb, ball.l
    if plant.ball_reaction:
        # [J_tot c; c M] [alpha; beta''] = [T; -l F_w]
        J_tot = plant.J_total
        det = J_tot * M - c * c
        alpha = (M * torque + c * l * f_w) / det
        beta_ddot = (-J_tot * l * f_w - c * torque) / det
    else:
        alpha = torque / plant.J_abu
        beta_ddot = -(c * alpha + l * f_w) / M
    return Accelerations(alpha, beta_ddot, f_n, f_w)


def stick_holds(plant: PlantParams, torque: float, omega: float, rtol: float = 1e-12) -> bool:
    """Whether static friction can hold the ball at beta' = 0 for the applied torque."""
    ball = plant.ball
    f_w = stick_friction(ball, stick_alpha(plant, torque))
    return abs(f_w) <= ball.mu * normal_force(ball, omega, 0.0) * (1.0 + rtol)


def slip_direction(plant: PlantParams, torque: float) -> int:
    """Direction (+1/-1) in which a ball leaving stick moves: sign of the friction it would need."""
    f_w = stick_friction(plant.ball, stick_alpha(plant, torque))
    return 1 if f_w > 0.0 else -1


def _slip_gains(plant: PlantParams) -> tuple[float, float, float, float]:
    """(a_t, a_w, b_t, b_w) of the slip equations alpha = a_t T + a_w F_w,
    beta'' = b_t T + b_w F_w (T applied torque [N m], F_w friction force [N]); see
    :func:`accelerations`."""
    ball = plant.ball
    c, M, l = ball.coupling, ball.M_bb, ball.l
    if plant.ball_reaction:
        J_tot = plant.J_total
        det = J_tot * M - c * c
        return M / det, c * l / det, -c / det, -J_tot * l / det
    J_abu = plant.J_abu
    return 1.0 / J_abu, 0.0, -c / (M * J_abu), -l / M


def slip_rhs(plant: PlantParams, direction: int, torque_poly: Sequence[float]):
    """Right-hand side f(tau, y) of the slip ODE for y = [theta, omega, beta, beta', T_applied].

    The same equations as :func:`accelerations` in slip, inlined for speed (one call per
    Runge-Kutta stage). Commanded torque T(tau) = sum c_i tau^i [N m] (``torque_poly``,
    ascending, any degree); without a motor lag T_applied follows it (T_applied' = T'(tau)),
    with a lag T_applied' = (T - T_applied)/tau_motor.
    """
    ball = plant.ball
    m, l, d = ball.m, ball.l, ball.d
    f_scale = ball.mu_dynamic * direction * m
    tm = plant.tau_motor
    a_t, a_w, b_t, b_w = _slip_gains(plant)
    # T (lag) or T' (no lag) as a polynomial in tau, evaluated by Horner in the closure
    drive = tuple(reversed((torque_poly if tm != 0.0 else poly_der(torque_poly)) or [0.0]))

    def rhs(tau: float, y: list) -> list:
        omega, v, applied = y[1], y[3], y[4]
        f_w = f_scale * (l * (omega + v) ** 2 + 0.4 * l * v * v - 0.2 * d * omega * v)
        value = 0.0
        for coefficient in drive:
            value = value * tau + coefficient
        d_applied = value if tm == 0.0 else (value - applied) / tm
        return [omega, a_t * applied + a_w * f_w, v, b_t * applied + b_w * f_w, d_applied]
    return rhs


def alpha_taylor(plant: PlantParams, torque_derivatives: Sequence[float], applied: float,
                 omega: float, beta_dot: float, mode: int, order: int) -> list[float]:
    """d^k alpha / dt^k for k = 0..order [rad/s^(2+k)] at one instant, exact.

    ``torque_derivatives`` are T, T', T'', ... of the commanded torque [N m/s^k] (missing
    ones are 0); ``applied`` is the torque on the rotor [N m] (the lag's state, or T without
    a lag). Taylor-mode recursion on the equations of motion: the right-hand side is a
    quadratic in (omega, beta'), so the Taylor coefficients follow by Cauchy products.
    """
    tm = plant.tau_motor
    if mode == STICK and tm == 0.0:  # alpha = T / J_total: the input's own derivatives
        J = plant.J_total
        return [applied / J] + [(torque_derivatives[k] if k < len(torque_derivatives) else 0.0)
                                / J for k in range(1, order + 1)]
    ball = plant.ball
    n = order + 1
    fact = [1.0] * (n + 1)
    for i in range(1, n + 1):
        fact[i] = fact[i - 1] * i
    T = [(torque_derivatives[k] if k < len(torque_derivatives) else 0.0) / fact[k]
         for k in range(n)]
    Ta = [applied] + T[1:]
    if tm != 0.0:  # tm Ta' + Ta = T
        for k in range(n - 1):
            Ta[k + 1] = (T[k] - Ta[k]) / (tm * (k + 1))
    if mode == STICK:
        J = plant.J_total
        return [Ta[k] / J * fact[k] for k in range(n)]
    m, l, d = ball.m, ball.l, ball.d
    f_scale = ball.mu_dynamic * mode * m
    a_t, a_w, b_t, b_w = _slip_gains(plant)
    w, v = [omega] + [0.0] * n, [beta_dot] + [0.0] * n
    alpha = []
    for k in range(n):
        # k-th Taylor coefficient of f_w / f_scale = l (w+v)^2 + 0.4 l v^2 - 0.2 d w v
        f_k = 0.0
        for i in range(k + 1):
            s_i, s_j = w[i] + v[i], w[k - i] + v[k - i]
            f_k += l * s_i * s_j + 0.4 * l * v[i] * v[k - i] - 0.2 * d * w[i] * v[k - i]
        f_k *= f_scale
        a_k = a_t * Ta[k] + a_w * f_k
        alpha.append(a_k * fact[k])
        w[k + 1] = a_k / (k + 1)
        v[k + 1] = (b_t * Ta[k] + b_w * f_k) / (k + 1)
    return alpha
