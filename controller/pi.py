"""The identified PI speed controller of the setup (report sec. 4.2.1, eq. 4.4-4.5).

The closed loop identified on the setup is

    theta'' + 2 zeta wn theta' + wn^2 theta = 2 zeta wn theta_ref' + wn^2 theta_ref,
    zeta = 0.5, wn = 2.2 rad/s,

which on the rotor J_abu theta'' = T is the PI law T = Kp (w_ref - w) + Ki e_theta with
Kp = 2 zeta wn J_abu and Ki = wn^2 J_abu. Two readings of theta_ref:

* ``integral`` (default, physical): e_theta = x_I with x_I' = w_ref - w, i.e. theta_ref is the
  integral of the speed setpoint. A setpoint step dW makes the acceleration jump by
  2 zeta wn dW whenever it happens.
* ``thesis``: theta_ref = t * w_ref as printed in the report, e_theta = t w_ref - theta. A step
  dW at time t_s then also shifts theta_ref by t_s dW, so the acceleration jumps by
  dW (2 zeta wn + wn^2 t_s). This reproduces the report's eq. 4.9.

Between setpoint steps both readings give the same torque rate
T' = -Kp alpha + Ki (w_ref - w).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

THETA_REF_MODES = ("integral", "thesis")

try:
    from abu_model.errors import ParameterError
except ImportError:  # pragma: no cover - only inside an FMU without abu_model
    from .reference import ParameterError  # type: ignore[assignment]


def _positive(name: str, value: float, unit: str) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ParameterError(name, value, f"a finite number > 0 {unit}") from None
    if not math.isfinite(number) or number <= 0.0:
        raise ParameterError(name, value, f"a finite number > 0 {unit}")
    return number


@dataclass(frozen=True)
class PISpeedController:
    """PI speed law with the identified closed-loop parameters.

    Attributes:
        zeta: damping ratio of the identified closed loop [-].
        omega_n: natural frequency of the identified closed loop [rad/s].
        J_abu: rotor inertia the gains are scaled with [kg m^2].
        theta_ref_mode: ``integral`` or ``thesis`` (see module docstring).
    """

    zeta: float = 0.5
    omega_n: float = 2.2
    J_abu: float = 4.5e-5
    theta_ref_mode: str = "integral"

    def __post_init__(self) -> None:
        object.__setattr__(self, "zeta", _positive("zeta", self.zeta, ""))
        object.__setattr__(self, "omega_n", _positive("omega_n", self.omega_n, "rad/s"))
        object.__setattr__(self, "J_abu", _positive("J_abu", self.J_abu, "kg m^2"))
        if self.theta_ref_mode not in THETA_REF_MODES:
            raise ParameterError("theta_ref_mode", self.theta_ref_mode,
                                 f"one of {', '.join(THETA_REF_MODES)}")

    @property
    def Kp(self) -> float:
        """Proportional gain 2 zeta wn J_abu [N m s/rad]."""
        return 2.0 * self.zeta * self.omega_n * self.J_abu

    @property
    def Ki(self) -> float:
        """Integral gain wn^2 J_abu [N m/rad]."""
        return self.omega_n**2 * self.J_abu

    def angle_error(self, t: float, omega_ref: float, theta: float, x_i: float) -> float:
        """e_theta [rad]: x_I (integral) or t w_ref - theta (thesis)."""
        if self.theta_ref_mode == "integral":
            return x_i
        return t * omega_ref - theta

    def torque(self, t: float, omega_ref: float, omega: float, theta: float, x_i: float) -> float:
        """Commanded torque T = Kp (w_ref - w) + Ki e_theta [N m]."""
        return self.Kp * (omega_ref - omega) + self.Ki * self.angle_error(t, omega_ref, theta, x_i)

    def torque_rate(self, omega_ref: float, omega: float, alpha: float) -> float:
        """dT/dt between setpoint steps, -Kp alpha + Ki (w_ref - w) [N m/s]."""
        return -self.Kp * alpha + self.Ki * (omega_ref - omega)

    def torque_derivative(self, d_k: float, d_k_minus_1: float) -> float:
        """k-th time derivative of T between setpoint steps, k >= 2, from the rotor speed's
        k-th and (k-1)-th derivatives: -Kp omega^(k) - Ki omega^(k-1) [N m/s^k]."""
        return -self.Kp * d_k - self.Ki * d_k_minus_1

    def integral_increment(self, h: float, omega_ref: float, omega: float, alpha: float,
                           *higher: float) -> float:
        """x_I(t+h) - x_I(t) [rad] with omega(tau) = omega + alpha tau + sum_k
        higher[k] tau^(k+2)/(k+2)! inside the step (higher: jerk [rad/s^3], snap, ...)."""
        value = (omega_ref - omega) * h - 0.5 * alpha * h * h
        power, factorial = h * h, 2.0
        for k, derivative in enumerate(higher, start=3):
            power *= h
            factorial *= k
            value -= derivative * power / factorial
        return value

    def acceleration_jump(self, d_omega_ref: float, t_step: float = 0.0) -> float:
        """Jump of the rotor acceleration at a setpoint step d_omega_ref [rad/s] at t_step [s].

        Returns [rad/s^2]: 2 zeta wn dW (integral) or dW (2 zeta wn + wn^2 t_step) (thesis),
        for the rotor alone (J_abu theta'' = T).
        """
        jump = 2.0 * self.zeta * self.omega_n * d_omega_ref
        if self.theta_ref_mode == "thesis":
            jump += self.omega_n**2 * t_step * d_omega_ref
        return jump
