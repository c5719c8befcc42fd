"""Table 4.1 of the report: the smallest |omega0| at which one setpoint step keeps the ball stuck.

From steady rotation at omega0 (ball stuck, controller integrator 0) one setpoint step dW at
time T makes the rotor's acceleration jump by

    integral PI: 2 zeta wn dW                 (whatever T)
    thesis:      dW (2 zeta wn + wn^2 T)      (theta_ref = t w_ref shifts by T dW)

(times J_abu / J_total with the ball's reaction). After the jump |alpha| decreases while
|omega| grows, so mu_req is largest just after the step: the ball stays stuck iff

    (l - d/5) |jump| <= mu l omega0^2,

i.e. mu omega0^2 >= (l - d/5)/l |jump| is constant for a given jump. The table gives the
smallest integer |omega0| in Hz satisfying it and checks it, and the value below it, by
co-simulation. :func:`report_implied_jump` inverts the report's table (17, 12, 10, 9, 8, 7 Hz
for mu = k 2.75e-3) into the jump it implies (see docs/harness.md).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Sequence

from abu_model.errors import ParameterError
from abu_model.params import PlantParams, check_finite
from controller.pi import PISpeedController

HZ = 2.0 * math.pi
#: The report's Table 4.1: mu -> omega0 [Hz].
REPORT_TABLE = {k * 2.75e-3: f for k, f in zip(range(1, 7), (17, 12, 10, 9, 8, 7))}
#: Time simulated after the step in the check [s] (mu_req peaks just after the step).
CHECK_HORIZON = 0.3


def acceleration_jump(plant: PlantParams, controller: PISpeedController, step: float,
                      t_step: float) -> float:
    """Jump of the rotor's acceleration at a setpoint step ``step`` [rad/s] at ``t_step`` [s],
    in rad/s^2 (the ball stuck)."""
    if plant.tau_motor != 0.0:
        raise ParameterError("tau_motor", plant.tau_motor,
                             "0 s for Table 4.1 (a motor lag removes the acceleration jump)")
    return controller.acceleration_jump(step, t_step) * plant.J_abu / plant.J_total


def stick_threshold_speed(plant: PlantParams, jump: float) -> float:
    """|omega0| [rad/s] at which the jump needs exactly mu: sqrt((l - d/5)/l |jump| / mu)."""
    if plant.ball.mu <= 0.0:
        return math.inf
    return math.sqrt(plant.ball.lever_ratio * abs(jump) / plant.ball.mu)


@dataclass(frozen=True)
class Table41Row:
    """One row: mu [-], the smallest integer |omega0| [Hz] keeping the ball stuck, and more.

    Attributes:
        mu: static friction coefficient [-].
        omega0_hz: smallest integer |omega0| [Hz] at which the step does not make the ball slip.
        threshold_hz: the exact threshold |omega0| [Hz] (closed form).
        jump_rad_s2: acceleration jump of the step [rad/s^2].
        check: simulated {omega0_hz: slips} for omega0_hz and omega0_hz - 1 (None: unchecked).
    """

    mu: float
    omega0_hz: int
    threshold_hz: float
    jump_rad_s2: float
    check: dict[int, bool] | None = None

    @property
    def consistent(self) -> bool | None:
        """True if the simulation confirms the closed form (None if unchecked)."""
        if self.check is None:
            return None
        below = self.check.get(self.omega0_hz - 1)
        return (not self.check[self.omega0_hz]) and (below is None or below)

    def as_dict(self) -> dict[str, Any]:
        return {"mu": self.mu, "omega0_hz": self.omega0_hz, "threshold_hz": self.threshold_hz,
                "jump_rad_s2": self.jump_rad_s2,
                "check": None if self.check is None else
                [{"omega0_hz": f, "slips": s} for f, s in sorted(self.check.items())],
                "consistent": self.consistent}


def _slips(plant: PlantParams, omega0_hz: int, step: float, t_step: float, mode: str,
           zeta: float, omega_n: float, comm_step: float | None, tol: float | None,
           fmu_dir: Any) -> bool:
    from harness.experiments.staircase import StaircaseExperiment, run_staircase

    w0 = -omega0_hz * HZ  # the report's ABU turns clockwise; the step speeds it up
    exp = StaircaseExperiment(plant, w0, w0 - step, t0=t_step, te=1.0, rounding="lead",
                              theta_ref_mode=mode, zeta=zeta, omega_n=omega_n,
                              t_end=t_step + CHECK_HORIZON, comm_step=comm_step, tol=tol)
    return run_staircase(exp, fmu_dir).summary["t_slip"] is not None


def table41(mus: Sequence[float], theta_ref_mode: str = "integral", t_step: float = 0.0,
            step_hz: float = 1.0, plant: PlantParams | None = None, zeta: float = 0.5,
            omega_n: float = 2.2, check: bool = True, comm_step: float | None = None,
            fmu_dir: Any = None, tol: float | None = None) -> list[Table41Row]:
    """Table 4.1 for the friction coefficients ``mus``.

    Args:
        mus: static friction coefficients [-] (> 0).
        theta_ref_mode: ``integral`` or ``thesis``.
        t_step: time of the setpoint step [s] (matters in thesis mode only).
        step_hz: setpoint step [Hz] (> 0).
        plant: the other plant parameters (mu is replaced by each value).
        check: co-simulate the found |omega0| and the one below it (reusing the loaded
            FMUs, error-controlled steps unless ``comm_step`` is given without ``tol``).
    """
    plant = PlantParams() if plant is None else plant
    if not mus:
        raise ParameterError("mu", list(mus), "at least one friction coefficient")
    t_step = check_finite("t_step", t_step)
    if theta_ref_mode == "thesis" and t_step < 0.0:
        raise ParameterError("t_step", t_step, "a time >= 0 s in thesis mode")
    step_hz = check_finite("step_hz", step_hz)
    if step_hz <= 0.0:
        raise ParameterError("step_hz", step_hz, "a setpoint step > 0 Hz")
    controller = PISpeedController(zeta, omega_n, plant.J_abu, theta_ref_mode)
    jump = acceleration_jump(plant, controller, step_hz * HZ, t_step)
    rows = []
    for mu in mus:
        mu = check_finite("mu", mu)
        if mu <= 0.0:
            raise ParameterError("mu", mu, "a friction coefficient > 0")
        with_mu = replace(plant, ball=plant.ball.with_(mu=mu, mu_d=None))
        threshold = stick_threshold_speed(with_mu, jump) / HZ
        # Smallest integer at or above the threshold (a float a hair above an integer counts
        # as that integer: the stick test holds with equality).
        omega0_hz = max(1, math.ceil(threshold - 1e-9))
        result = None
        if check:
            result = {f: _slips(with_mu, f, step_hz * HZ, t_step, theta_ref_mode, zeta, omega_n,
                                comm_step, tol, fmu_dir)
                      for f in (omega0_hz, omega0_hz - 1) if f >= 1}
        rows.append(Table41Row(mu, omega0_hz, threshold, jump, result))
    return rows


def report_implied_jump(plant: PlantParams | None = None, step_hz: float = 1.0,
                        zeta: float = 0.5, omega_n: float = 2.2) -> dict[str, Any]:
    """The acceleration jump the report's Table 4.1 implies, and what would produce it.

    Each row (mu, f) says the threshold lies in (f - 1, f] Hz, i.e.
    mu (2 pi (f-1))^2 < (l - d/5)/l jump <= mu (2 pi f)^2. The intersection over the rows is
    an interval of jumps [rad/s^2]; compared with the integral PI's 2 zeta wn dW, and the step
    time T for which the thesis reading's dW (2 zeta wn + wn^2 T) falls in it.
    """
    plant = PlantParams() if plant is None else plant
    lever = plant.ball.lever_ratio
    low, high = 0.0, math.inf
    for mu, f in REPORT_TABLE.items():
        low = max(low, mu * (HZ * (f - 1)) ** 2 / lever)
        high = min(high, mu * (HZ * f) ** 2 / lever)
    dW = step_hz * HZ
    integral = 2 * zeta * omega_n * dW
    return {
        "jump_low_rad_s2": low, "jump_high_rad_s2": high,
        "integral_jump_rad_s2": integral,
        "ratio_low": low / integral, "ratio_high": high / integral,
        "thesis_t_step_low_s": (low / dW - 2 * zeta * omega_n) / omega_n**2,
        "thesis_t_step_high_s": (high / dW - 2 * zeta * omega_n) / omega_n**2,
        "omega_n_low_rad_s": low / (2 * zeta * dW), "omega_n_high_rad_s": high / (2 * zeta * dW),
    }
