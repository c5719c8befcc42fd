"""Legacy numpy/scipy plant (before the standard-library numerics), the peer of benchmarks/bench_plant.py.

The ABU rotor with one ball as a hybrid (stick/slip) system, stepped with exact switches.

:class:`AbuPlant` integrates one communication step with the commanded torque held to first
order, T(tau) = torque + torque_rate * tau (pythonfmu has no input derivatives, so the rate is
an explicit input). Inside the step every stick/slip switch is located exactly:

* stick without motor lag: alpha is linear and omega quadratic in tau, so the stick test
  mu omega^2 - (l - d/5)/l |alpha| >= 0 is a quartic polynomial; its first root is found with
  numpy's polynomial roots and polished by Newton steps;
* stick with a motor lag: the trajectory is closed-form (exponential + polynomial); the first
  root is bracketed on a fine grid and found with ``scipy.optimize.brentq``;
* slip: the nonlinear ODE is integrated with ``scipy.integrate.solve_ivp`` (DOP853, tight
  tolerances) with a terminal event at beta' = 0, where the ball either sticks again or slips
  back the other way.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from enum import IntEnum

import numpy as np
from numpy.polynomial import polynomial as P
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from abu_model.dynamics import accelerations, mu_required, slip_direction, stick_holds
from abu_model.errors import AbuError
from abu_model.params import PlantParams, check_finite

#: A switch located within this time of a step's end [s] is taken at the step's end.
END_TOLERANCE = 1e-12
#: More switches than this inside one step means chattering (a Zeno-like cascade).
MAX_SWITCHES_PER_STEP = 50
#: Grid used to bracket the stick test's first root when a motor lag makes it non-polynomial.
LAG_BRACKET_POINTS = 64


class Mode(IntEnum):
    """Ball mode: the sign of beta_dot in slip, 0 in stick."""

    SLIP_NEG = -1
    STICK = 0
    SLIP_POS = 1


class SimulationError(AbuError):
    """The integration failed or chattered (more switches in a step than any physical cascade).

    The ball cannot lift off the rim: F_N is a positive-definite quadratic form in
    (omega, beta'), since 1.4 l^2 > (l - d/10)^2.
    """


@dataclass
class PlantState:
    """Complete internal state of the plant (everything a rollback must restore)."""

    time: float = 0.0            #: [s]
    theta: float = 0.0           #: ABU angle [rad]
    omega: float = 0.0           #: ABU speed [rad/s]
    beta: float = 0.0            #: ball angle relative to the ABU [rad]
    beta_dot: float = 0.0        #: [rad/s]
    torque_applied: float = 0.0  #: torque acting on the rotor (after the motor lag) [N m]
    mode: int = Mode.STICK       #: -1, 0, +1
    switch_count: int = 0        #: number of stick/slip switches so far
    t_last_switch: float = -math.inf  #: time of the last switch [s]; -inf before any


@dataclass(frozen=True)
class Switch:
    """One stick/slip switch."""

    time: float      #: [s]
    from_mode: int
    to_mode: int


@dataclass(frozen=True)
class PlantOutputs:
    """Algebraic outputs at one instant (SI)."""

    alpha: float           #: [rad/s^2]
    beta_ddot: float       #: [rad/s^2]
    normal_force: float    #: [N]
    friction_force: float  #: [N]
    mu_req: float          #: (l - d/5)|alpha| / (l omega^2) [-]


class AbuPlant:
    """Rotor + one ball, advanced step by step with exact stick/slip switches.

    Args:
        params: plant parameters.
        t0: initial time [s]; theta0 [rad], omega0 [rad/s], beta0 [rad], beta_dot0 [rad/s].
        torque0: initial applied torque [N m] (the motor lag's state).
    The ball starts in stick if beta_dot0 == 0, else in slip in the direction of beta_dot0.
    """

    def __init__(self, params: PlantParams, *, t0: float = 0.0, theta0: float = 0.0,
                 omega0: float = 0.0, beta0: float = 0.0, beta_dot0: float = 0.0,
                 torque0: float = 0.0):
        self.params = params
        values = {name: check_finite(name, value) for name, value in (
            ("t0", t0), ("theta0", theta0), ("omega0", omega0), ("beta0", beta0),
            ("beta_dot0", beta_dot0), ("torque0", torque0))}
        mode = Mode.STICK if beta_dot0 == 0.0 else Mode(int(math.copysign(1, beta_dot0)))
        self.state = PlantState(values["t0"], values["theta0"], values["omega0"], values["beta0"],
                                values["beta_dot0"], values["torque0"], int(mode))

    # ----------------------------------------------------------------- state handling
    def get_state(self) -> PlantState:
        """A copy of the complete state."""
        return replace(self.state)

    def set_state(self, state: PlantState) -> None:
        """Restore a state obtained from :meth:`get_state`."""
        self.state = replace(state)

    # ----------------------------------------------------------------- outputs
    def applied_torque(self, torque: float) -> float:
        """Torque on the rotor now [N m]: the commanded one without lag, else the lag state."""
        return torque if self.params.tau_motor == 0.0 else self.state.torque_applied

    def outputs(self, torque: float) -> PlantOutputs:
        """Outputs at the current state for the commanded torque ``torque`` [N m]."""
        s = self.state
        acc = accelerations(self.params, self.applied_torque(torque), s.omega, s.beta_dot, s.mode)
        return PlantOutputs(acc.alpha, acc.beta_ddot, acc.normal_force, acc.friction_force,
                            mu_required(self.params.ball, acc.alpha, s.omega))

    # ----------------------------------------------------------------- stepping
    def advance(self, h: float, torque: float, torque_rate: float) -> list[Switch]:
        """Integrate over [time, time + h] with T(tau) = torque + torque_rate tau.

        Returns the switches that happened in the step, in time order. Raises
        :class:`SimulationError` if the ball would lift off the rim or chatter.
        """
        if not (h >= 0.0 and math.isfinite(h)):
            raise ValueError(f"step size must be finite and >= 0 s, got {h!r}")
        s = self.state
        if self.params.tau_motor == 0.0:
            s.torque_applied = torque
        start_time = s.time
        switches: list[Switch] = []
        tau = 0.0
        while True:
            if s.mode == Mode.STICK:
                if not stick_holds(self.params, s.torque_applied, s.omega):
                    self._switch(switches, start_time + tau,
                                 slip_direction(self.params, s.torque_applied))
                    continue
                tau_fail = self._advance_stick(tau, h, torque, torque_rate)
                if tau_fail is None:
                    break
                tau = tau_fail
                self._switch(switches, start_time + tau,
                             slip_direction(self.params, s.torque_applied))
            else:
                tau_zero = self._advance_slip(tau, h, torque, torque_rate)
                if tau_zero is None:
                    break
                tau = tau_zero
                s.beta_dot = 0.0
                if stick_holds(self.params, s.torque_applied, s.omega):
                    new_mode = Mode.STICK
                else:
                    new_mode = slip_direction(self.params, s.torque_applied)
                self._switch(switches, start_time + tau, new_mode)
            if len(switches) > MAX_SWITCHES_PER_STEP:
                raise SimulationError(
                    f"more than {MAX_SWITCHES_PER_STEP} stick/slip switches in the step at "
                    f"t = {start_time:.9g} s (chattering)")
            if tau >= h:
                break
        s.time = start_time + h
        return switches

    def _switch(self, switches: list[Switch], t: float, new_mode: int) -> None:
        s = self.state
        switches.append(Switch(float(t), int(s.mode), int(new_mode)))
        s.mode = int(new_mode)
        s.switch_count += 1
        s.t_last_switch = float(t)

    # -- stick ------------------------------------------------------------------------
    def _advance_stick(self, tau0: float, h: float, torque: float, rate: float) -> float | None:
        """Advance in stick from tau0; stop at the first stick-test failure (returned) or at h."""
        if self.params.tau_motor == 0.0:
            return self._advance_stick_polynomial(tau0, h, torque, rate)
        return self._advance_stick_lag(tau0, h, torque, rate)

    def _advance_stick_polynomial(self, tau0: float, h: float, torque: float,
                                  rate: float) -> float | None:
        s, ball = self.state, self.params.ball
        J = self.params.J_total
        # Polynomials in u = tau - tau0 (ascending coefficients).
        T0 = torque + rate * tau0
        alpha = np.array([T0 / J, rate / J])
        omega = np.array([s.omega, T0 / J, 0.5 * rate / J])
        theta = np.array([s.theta, s.omega, 0.5 * T0 / J, rate / (6.0 * J)])
        mu_w2 = ball.mu * P.polymul(omega, omega)
        k = ball.lever_ratio
        span = h - tau0
        u_fail = None
        for sign in (1.0, -1.0):  # g = mu omega^2 -/+ k alpha
            g = P.polysub(mu_w2, sign * k * alpha)
            u = _first_negative_root(g, span)
            if u is not None and (u_fail is None or u < u_fail):
                u_fail = u
        u_end = span if u_fail is None else u_fail
        s.theta = float(P.polyval(u_end, theta))
        s.omega = float(P.polyval(u_end, omega))
        s.torque_applied = T0 + rate * u_end
        return None if u_fail is None else tau0 + u_fail

    def _lag_trajectory(self, tau0: float, torque: float, rate: float):
        """Closed-form stick trajectory with the motor lag, as functions of u = tau - tau0."""
        s, tm, J = self.state, self.params.tau_motor, self.params.J_total
        T0 = torque + rate * tau0
        A, B = T0 - rate * tm, rate
        C = s.torque_applied - A
        omega0, theta0 = s.omega, s.theta

        def applied(u):
            return A + B * u + C * np.exp(-u / tm)

        def omega(u):
            return omega0 + (A * u + 0.5 * B * u * u + C * tm * -np.expm1(-u / tm)) / J

        def theta(u):
            return theta0 + omega0 * u + (0.5 * A * u * u + B * u**3 / 6.0
                                          + C * tm * (u + tm * np.expm1(-u / tm))) / J
        return applied, omega, theta

    def _advance_stick_lag(self, tau0: float, h: float, torque: float, rate: float) -> float | None:
        s, ball, J = self.state, self.params.ball, self.params.J_total
        applied, omega, theta = self._lag_trajectory(tau0, torque, rate)
        k, mu = ball.lever_ratio, ball.mu

        def margin(u):  # >= 0 while the ball can stick
            return mu * omega(u) ** 2 - k * np.abs(applied(u) / J)

        span = h - tau0
        grid = np.linspace(0.0, span, LAG_BRACKET_POINTS + 1)
        values = margin(grid)
        u_fail = None
        negative = np.nonzero(values < 0.0)[0]
        if negative.size:
            i = int(negative[0])
            u_fail = 0.0 if i == 0 else brentq(margin, grid[i - 1], grid[i], xtol=1e-15,
                                               rtol=1e-15)
        else:  # a root within END_TOLERANCE beyond the step end is taken at the end
            if margin(span + END_TOLERANCE) < 0.0:
                u_fail = span
        u_end = span if u_fail is None else u_fail
        s.theta, s.omega = float(theta(u_end)), float(omega(u_end))
        s.torque_applied = float(applied(u_end))
        return None if u_fail is None else tau0 + u_fail

    # -- slip -------------------------------------------------------------------------
    def _advance_slip(self, tau0: float, h: float, torque: float, rate: float) -> float | None:
        """Integrate the slip ODE from tau0; stop at beta' = 0 (returned) or at h."""
        s, params = self.state, self.params
        direction = s.mode
        tm = params.tau_motor

        def rhs(tau, y):
            theta, omega, beta, beta_dot, applied = y
            acc = accelerations(params, applied, omega, beta_dot, direction)
            d_applied = rate if tm == 0.0 else (torque + rate * tau - applied) / tm
            return (omega, acc.alpha, beta_dot, acc.beta_ddot, d_applied)

        def stops(tau, y):  # beta' returns to zero
            return direction * y[3]
        stops.terminal, stops.direction = True, -1

        y0 = [s.theta, s.omega, s.beta, s.beta_dot, s.torque_applied]
        tau_end = h + END_TOLERANCE if h > tau0 else h
        if tau_end <= tau0:
            return None
        scale_torque = max(abs(torque), abs(rate) * h, 1e-12)
        sol = solve_ivp(rhs, (tau0, tau_end), y0, method="DOP853", rtol=1e-11,
                        atol=[1e-13, 1e-11, 1e-13, 1e-11, 1e-12 * scale_torque],
                        events=(stops,), dense_output=True)
        if not sol.success:
            raise SimulationError(f"slip integration failed at t = {s.time + tau0:.9g} s: "
                                  f"{sol.message}")
        if sol.t_events[0].size:
            tau_zero = min(float(sol.t_events[0][0]), h)
            y = sol.y_events[0][0]
        else:
            # integrated to h + tolerance (to catch a stop at the step's end): state at h
            tau_zero, y = None, sol.sol(h)
        s.theta, s.omega, s.beta, s.beta_dot, s.torque_applied = (float(v) for v in y)
        if tm == 0.0:
            s.torque_applied = torque + rate * (h if tau_zero is None else tau_zero)
        return tau_zero


def _first_negative_root(g: np.ndarray, span: float) -> float | None:
    """First u in [0, span] after which the polynomial g (ascending) turns negative, or None.

    Returns 0 if g is negative right after 0. A root within END_TOLERANCE beyond span is
    returned as span.
    """
    g = np.trim_zeros(np.asarray(g, dtype=float), "b")
    if g.size == 0:
        return None
    if g.size == 1:
        return 0.0 if g[0] < 0.0 else None
    limit = span + END_TOLERANCE
    roots = []
    for r in P.polyroots(g):
        if abs(r.imag) > 1e-7 * max(1.0, abs(r.real)):
            continue
        x = r.real
        dg = P.polyder(g)
        for _ in range(3):  # Newton polish: companion-matrix roots lose digits
            d = P.polyval(x, dg)
            if d == 0.0:
                break
            x -= P.polyval(x, g) / d
        if 0.0 < x <= limit:
            roots.append(x)
    points = [0.0] + sorted(roots) + [limit]
    if P.polyval(0.0, g) < 0.0:
        return 0.0
    for a, b in zip(points[:-1], points[1:]):
        if b > a and P.polyval(0.5 * (a + b), g) < 0.0:
            return min(a, span)
    return None
