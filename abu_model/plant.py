"""The ABU rotor with one ball as a hybrid (stick/slip) system, stepped with exact switches.

:class:`AbuPlant` integrates one communication step with the commanded torque held as a
Taylor polynomial of any order, T(tau) = torque + torque_rate tau + torque_accel tau^2/2 +
torque_jerk tau^3/6 + ... (pythonfmu has no input derivatives, so the derivatives are
explicit inputs; missing ones are 0, a lower-order hold). Inside the step every stick/slip
switch is located exactly, with the standard library only (the plant runs inside FMUs; see
:mod:`abu_model.numerics`):

* stick without motor lag: alpha and omega are polynomials in tau, so the stick test
  mu omega^2 - (l - d/5)/l |alpha| >= 0 is a polynomial; a cheap bound rules out a sign
  change in the step before any root is looked for, else its first root is found by
  splitting into monotone pieces;
* stick with a motor lag: the trajectory is closed-form (exponential + the lag's polynomial
  particular solution sum_j (-tm)^j T^(j)); the first root is bracketed on a fine grid and
  found with a bracketing root finder;
* slip: the nonlinear ODE is integrated with a Dormand-Prince 5(4) pair at tight tolerances
  and the stop at beta' = 0 is located by re-stepping, where the ball either sticks again or
  slips back the other way.

In stick the plant also keeps the largest mu_req of the step (``step_peak``), interior
maxima included (a motor lag, or |omega| falling faster than |alpha|), so that mu_low is the
true supremum and not a maximum over communication points.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from enum import IntEnum

from .dynamics import (accelerations, alpha_taylor, mu_required, slip_direction, slip_rhs,
                       stick_holds)
from .errors import AbuError
from .numerics import (brent_root, integrate_until, poly_der, poly_eval, poly_first_negative,
                       poly_int, poly_mul, poly_shift, rk45_step)
from .params import PlantParams, check_finite

#: A switch located within this time of a step's end [s] is taken at the step's end.
END_TOLERANCE = 1e-12
#: More switches than this inside one step means chattering (a Zeno-like cascade).
MAX_SWITCHES_PER_STEP = 50
#: Grid used to bracket the stick test's first root when a motor lag makes it non-polynomial.
LAG_BRACKET_POINTS = 64
#: Relative tolerance of the slip integration (absolute ones are set per component).
SLIP_RTOL = 1e-12


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


@dataclass(slots=True)
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

    def copy(self) -> "PlantState":
        """An independent copy (cheaper than ``dataclasses.replace``)."""
        return PlantState(self.time, self.theta, self.omega, self.beta, self.beta_dot,
                          self.torque_applied, self.mode, self.switch_count, self.t_last_switch)

    def as_tuple(self) -> tuple:
        """The fields in declaration order (see :data:`STATE_FIELDS`)."""
        return (self.time, self.theta, self.omega, self.beta, self.beta_dot,
                self.torque_applied, self.mode, self.switch_count, self.t_last_switch)


#: Field names of :class:`PlantState`, in the order of :meth:`PlantState.as_tuple`.
STATE_FIELDS = ("time", "theta", "omega", "beta", "beta_dot", "torque_applied", "mode",
                "switch_count", "t_last_switch")


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


def _fall_through_zero(slope, lo: float, hi: float, lo_is_zero: bool,
                       hi_is_zero: bool) -> float | None:
    """The u in (lo, hi) where ``slope`` falls through 0 if it is > 0 next to lo and < 0 next
    to hi, else None (one maximum per piece). At an end that is a zero of alpha (``lo_is_zero``,
    ``hi_is_zero``; slope 0 there up to the root's rounding), or where slope is 0 at lo, the
    side's sign is taken by halving towards that end; at hi only for a zero of alpha (a slope
    that is 0 along the whole step is no maximum)."""
    def near(end: float, other: float, sign: float) -> tuple[float, float] | None:
        x = other
        for _ in range(60):
            x = end + 0.5 * (x - end)
            d = slope(x)
            if sign * d > 0.0:
                return x, d
        return None

    if hi_is_zero:
        right = near(hi, lo, -1.0)
    else:
        d_hi = slope(hi)
        right = (hi, d_hi) if d_hi < 0.0 else None
    if right is None:
        return None
    d_lo = 0.0 if lo_is_zero else slope(lo)
    left = (lo, d_lo) if d_lo > 0.0 else near(lo, right[0], 1.0) if d_lo == 0.0 else None
    if left is None:
        return None
    return brent_root(slope, left[0], right[0], left[1], right[1])


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
        #: largest mu_req in stick over the last step [-] (0 without stick; an output)
        self.step_peak = 0.0

    # ----------------------------------------------------------------- state handling
    def get_state(self) -> PlantState:
        """A copy of the complete state."""
        return self.state.copy()

    def set_state(self, state: PlantState) -> None:
        """Restore a state obtained from :meth:`get_state`."""
        self.state = state.copy()

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

    def alpha_derivatives(self, torque_derivatives: list[float], order: int) -> list[float]:
        """alpha, d(alpha)/dt, ... up to d^order(alpha)/dt^order now [rad/s^(2+k)], exact,
        for the commanded torque's derivatives T, T', ... [N m/s^k] (see ``alpha_taylor``)."""
        s = self.state
        return alpha_taylor(self.params, torque_derivatives,
                            self.applied_torque(torque_derivatives[0]), s.omega, s.beta_dot,
                            s.mode, order)

    # ----------------------------------------------------------------- stepping
    def advance(self, h: float, torque: float, torque_rate: float, torque_accel: float = 0.0,
                torque_jerk: float = 0.0, *higher: float) -> list[Switch]:
        """Integrate over [time, time + h] with the commanded torque held as its Taylor
        polynomial T(tau) = torque + torque_rate tau + torque_accel tau^2/2
        + torque_jerk tau^3/6 (+ higher derivatives, any order).

        Units: h [s], torque [N m], its k-th derivative [N m/s^k].

        Returns the switches that happened in the step, in time order. Raises
        :class:`SimulationError` if the ball would lift off the rim or chatter.
        ``step_peak`` is then the largest mu_req in stick over the step (0 without stick).
        """
        if not (h >= 0.0 and math.isfinite(h)):
            raise ValueError(f"step size must be finite and >= 0 s, got {h!r}")
        c = [torque, torque_rate, 0.5 * torque_accel, torque_jerk / 6.0]
        factorial = 6.0
        for k, value in enumerate(higher, start=4):
            factorial *= k
            c.append(value / factorial)
        while len(c) > 1 and c[-1] == 0.0:  # a lower-order hold keeps its cheaper polynomials
            c.pop()
        s = self.state
        if self.params.tau_motor == 0.0:
            s.torque_applied = torque
        self.step_peak = 0.0
        start_time = s.time
        switches: list[Switch] = []
        tau = 0.0
        while True:
            if s.mode == Mode.STICK:
                if not stick_holds(self.params, s.torque_applied, s.omega):
                    self._switch(switches, start_time + tau,
                                 slip_direction(self.params, s.torque_applied))
                    continue
                tau_fail = self._advance_stick(tau, h, c)
                if tau_fail is None:
                    break
                tau = tau_fail
                self._switch(switches, start_time + tau,
                             slip_direction(self.params, s.torque_applied))
            else:
                tau_zero = self._advance_slip(tau, h, c)
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
    def _advance_stick(self, tau0: float, h: float, c: list[float]) -> float | None:
        """Advance in stick from tau0; stop at the first stick-test failure (returned) or at h."""
        if self.params.tau_motor == 0.0:
            return self._advance_stick_polynomial(tau0, h, c)
        return self._advance_stick_lag(tau0, h, c)

    def _peak(self, alpha, alpha_rate, omega, u_end: float) -> None:
        """Raise ``step_peak`` to the largest mu_req = k|alpha|/omega^2 on [0, u_end] (stick).

        alpha, alpha_rate (= d alpha/du), omega: functions of u [rad/s^2, rad/s^3, rad/s].
        d(mu_req)/du has the sign of D = alpha (alpha' omega - 2 alpha^2) omega; a maximum
        inside is a fall of D through 0, looked for where D falls between the ends of each
        side of a zero of alpha (mu_req rises again after such a minimum).
        """
        ball = self.params.ball

        def mu_req(u: float) -> float:  # 0, not inf, at rest with alpha = 0 (the output's rule)
            return mu_required(ball, alpha(u), omega(u))

        def slope(u: float) -> float:
            a, w = alpha(u), omega(u)
            return a * (alpha_rate(u) * w - 2.0 * a * a) * w

        peak = max(self.step_peak, mu_req(0.0), mu_req(u_end))
        if u_end > 0.0:
            ends = [0.0, u_end]
            a0, a1 = alpha(0.0), alpha(u_end)
            if (a0 < 0.0) != (a1 < 0.0) and a0 != 0.0 and a1 != 0.0:
                # |alpha| passes through 0 (mu_req = 0, a minimum): a maximum on either side
                ends.insert(1, brent_root(alpha, 0.0, u_end, a0, a1))
            for i in range(len(ends) - 1):
                u = _fall_through_zero(slope, ends[i], ends[i + 1], i > 0, i + 2 < len(ends))
                if u is not None:
                    peak = max(peak, mu_req(u))
        self.step_peak = peak

    def _advance_stick_polynomial(self, tau0: float, h: float, c: list[float]) -> float | None:
        s, ball = self.state, self.params.ball
        J = self.params.J_total
        # Polynomials in u = tau - tau0 (ascending): T(u), alpha = T/J, omega = omega0 + int.
        T = poly_shift(c, tau0)
        alpha = [v / J for v in T]
        omega = poly_int(alpha, s.omega)
        mu_w2 = [ball.mu * v for v in poly_mul(omega, omega)]
        k = ball.lever_ratio
        span = h - tau0
        u_fail = None
        for sign in (1.0, -1.0):  # g = mu omega^2 -/+ k alpha
            g = list(mu_w2)
            for i, a in enumerate(alpha):
                g[i] -= sign * k * a
            u = poly_first_negative(g, span, END_TOLERANCE)
            if u is not None and (u_fail is None or u < u_fail):
                u_fail = u
        u = span if u_fail is None else u_fail
        d_alpha = poly_der(alpha) or [0.0]
        self._peak(lambda x: poly_eval(alpha, x), lambda x: poly_eval(d_alpha, x),
                   lambda x: poly_eval(omega, x), u)
        s.theta = poly_eval(poly_int(omega, s.theta), u)
        s.omega = poly_eval(omega, u)
        s.torque_applied = poly_eval(T, u)
        return None if u_fail is None else tau0 + u_fail

    def _lag_trajectory(self, tau0: float, c: list[float]):
        """Closed-form stick trajectory with the motor lag, as functions of u = tau - tau0.

        Commanded T(u) a polynomial; the applied torque is the lag's particular solution
        P(u) = sum_j (-tm)^j T^(j)(u) of tm Ta' + Ta = T plus D exp(-u/tm).
        """
        s, tm, J = self.state, self.params.tau_motor, self.params.J_total
        T = poly_shift(c, tau0)
        P, term, factor = list(T), T, 1.0
        for _ in range(len(T) - 1):
            term = poly_der(term)
            factor *= -tm
            for i, v in enumerate(term):
                P[i] += factor * v
        D = s.torque_applied - P[0]
        int_P = poly_int(P)
        int2_P = poly_int(int_P)
        omega0, theta0 = s.omega, s.theta
        exp, expm1 = math.exp, math.expm1

        def commanded(u: float) -> float:
            return poly_eval(T, u)

        def applied(u: float) -> float:
            return poly_eval(P, u) + D * exp(-u / tm)

        def omega(u: float) -> float:
            return omega0 + (poly_eval(int_P, u) + D * tm * -expm1(-u / tm)) / J

        def theta(u: float) -> float:
            return theta0 + omega0 * u + (poly_eval(int2_P, u)
                                          + D * tm * (u + tm * expm1(-u / tm))) / J
        return commanded, applied, omega, theta

    def _advance_stick_lag(self, tau0: float, h: float, c: list[float]) -> float | None:
        s, ball, J = self.state, self.params.ball, self.params.J_total
        tm = self.params.tau_motor
        commanded, applied, omega, theta = self._lag_trajectory(tau0, c)
        k, mu = ball.lever_ratio, ball.mu

        def margin(u: float) -> float:  # >= 0 while the ball can stick
            return mu * omega(u) ** 2 - k * abs(applied(u) / J)

        span = h - tau0
        u_fail = None
        previous = 0.0
        for i in range(LAG_BRACKET_POINTS + 1):
            u = span * i / LAG_BRACKET_POINTS
            value = margin(u)
            if value < 0.0:
                u_fail = 0.0 if i == 0 else brent_root(margin, previous, u, None, value)
                break
            previous = u
        else:  # a root within END_TOLERANCE beyond the step end is taken at the end
            if margin(span + END_TOLERANCE) < 0.0:
                u_fail = span
        u_end = span if u_fail is None else u_fail
        self._peak(lambda x: applied(x) / J,
                   lambda x: (commanded(x) - applied(x)) / (tm * J), omega, u_end)
        s.theta, s.omega = theta(u_end), omega(u_end)
        s.torque_applied = applied(u_end)
        return None if u_fail is None else tau0 + u_fail

    # -- slip -------------------------------------------------------------------------
    def _advance_slip(self, tau0: float, h: float, c: list[float]) -> float | None:
        """Integrate the slip ODE from tau0; stop at beta' = 0 (returned) or at h."""
        s, params = self.state, self.params
        direction = s.mode
        if h <= tau0:
            return None
        rhs = slip_rhs(params, direction, c)

        def stops(tau: float, y: list) -> float:  # beta' returns to zero
            return direction * y[3]

        y0 = [s.theta, s.omega, s.beta, s.beta_dot, s.torque_applied]
        scale_torque = max(max(abs(v) * h**i for i, v in enumerate(c)), 1e-12)
        atol = (1e-14, 1e-12, 1e-14, 1e-12, 1e-13 * scale_torque)
        try:
            tau, y, stopped = integrate_until(rhs, tau0, y0, h, SLIP_RTOL, atol, stops,
                                              event_slope=lambda tau, y, dy: direction * dy[3])
            if not stopped and stops(h, y) > 0.0:  # a stop within END_TOLERANCE after h
                y_late = rk45_step(rhs, h, y, END_TOLERANCE)[0]
                stopped = stops(h + END_TOLERANCE, y_late) <= 0.0
        except ArithmeticError as exc:
            raise SimulationError(f"slip integration failed at t = {s.time + tau0:.9g} s: "
                                  f"{exc}") from None
        s.theta, s.omega, s.beta, s.beta_dot, s.torque_applied = y
        tau_zero = min(tau, h) if stopped else None
        if params.tau_motor == 0.0:
            s.torque_applied = poly_eval(c, h if tau_zero is None else tau_zero)
        return tau_zero
