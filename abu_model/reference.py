"""Monolithic reference solver: the whole closed loop as one event-located SciPy ODE, no FMI.

Used to cross-check the co-simulation. It shares the equations of motion
(:mod:`.dynamics`) with the FMU but not the stepping: here the controller, the setpoint and
the plant are one ODE (state theta, omega, beta, beta', x_I, applied torque) integrated by
``solve_ivp`` between setpoint steps, with event functions for the stick test
(mu omega^2 -/+ (l - d/5)/l alpha = 0) in stick and for beta' = 0 in slip. The maxima of
mu_req in stick are located too (a non-terminal event on d(mu_req)/dt = 0), so mu_low is the
supremum over the stick period and not a maximum over solver points.

The controller and the setpoint are passed duck-typed (objects with ``Kp``, ``Ki``,
``theta_ref_mode`` and with ``step_times``, ``levels``), so this package stays free of
imports from ``controller``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Protocol, Sequence

import numpy as np
from scipy.integrate import solve_ivp

from .dynamics import accelerations, mu_required, slip_direction, stick_holds
from .params import PlantParams
from .plant import Mode, SimulationError, Switch

RTOL, ATOL = 1e-11, 1e-13


class SpeedLaw(Protocol):
    Kp: float
    Ki: float
    theta_ref_mode: str


class Setpoints(Protocol):
    step_times: Sequence[float]
    levels: Sequence[float]


@dataclass
class ReferenceResult:
    """Trajectory and bounds of a reference run (SI).

    ``t`` and the state arrays hold every solver point; at a discontinuity the time appears
    twice (left limit first). ``mu_req`` is evaluated with the right-hand acceleration.
    """

    t: np.ndarray
    theta: np.ndarray
    omega: np.ndarray
    beta: np.ndarray
    beta_dot: np.ndarray
    alpha: np.ndarray
    mode: np.ndarray
    mu_req: np.ndarray
    switches: list[Switch] = field(default_factory=list)
    #: largest mu_req while stuck before the first slip [-]; None if the ball slips at (or
    #: before) the first breakpoint (setpoint step): no stick period with an acceleration
    mu_low: float | None = 0.0
    mu_high: float | None = None  #: mu_req right after the first slip instant [-]
    t_slip: float | None = None   #: first stick -> slip time [s]
    omega_slip: float | None = None  #: [rad/s]
    alpha_slip: float | None = None  #: right-hand alpha at the slip instant [rad/s^2]


class _SegmentODE:
    """The closed loop on one segment (drive frozen at its start): right-hand side and events.

    The event functions are built by small factories because ``solve_ivp`` reads their
    ``terminal`` and ``direction`` attributes (bound methods cannot carry them).
    """

    def __init__(self, plant: PlantParams, command: "_Segment") -> None:
        self.plant, self.command = plant, command
        self.tm = plant.tau_motor  # motor lag [s]; 0: the commanded torque acts directly

    def applied(self, t: float, y: np.ndarray) -> float:
        """Torque acting on the rotor [N m]."""
        return self.command.torque(t, y) if self.tm == 0.0 else y[5]

    def rhs_for(self, mode: int):
        """d/dt of the state (theta, omega, beta, beta', x_I, applied torque) in ``mode``."""
        plant, command, tm = self.plant, self.command, self.tm

        def rhs(t, y):
            acc = accelerations(plant, self.applied(t, y), y[1], y[3], mode)
            d_applied = 0.0 if tm == 0.0 else (command.torque(t, y) - y[5]) / tm
            return [y[1], acc.alpha, y[3] if mode else 0.0, acc.beta_ddot if mode else 0.0,
                    command.integral_rate(t, y), d_applied]
        return rhs

    def stick_margin(self, sign: float):
        """Terminal event: mu omega^2 - sign (l - d/5)/l alpha falls through 0 (stick ends)."""
        plant, k = self.plant, self.plant.ball.lever_ratio

        def g(t, y):
            return plant.ball.mu * y[1] ** 2 - sign * k * self.applied(t, y) / plant.J_total
        g.terminal, g.direction = True, -1
        return g

    def torque_rate(self, t: float, y: np.ndarray, alpha: float) -> float:
        """dT/dt of the commanded torque [N m/s] (segment's closed form if it has one)."""
        command = self.command
        rate = getattr(command, "torque_rate", None)
        if rate is not None:
            return rate(t, y, alpha)
        e = 1e-7 * max(1.0, abs(t))  # central difference along the trajectory
        f = self.rhs_for(Mode.STICK)(t, y)
        return (command.torque(t + e, y + e * np.asarray(f))
                - command.torque(t - e, y - e * np.asarray(f))) / (2.0 * e)

    def peak(self):
        """Non-terminal event: the maxima of mu_req in stick."""
        plant, command, tm = self.plant, self.command, self.tm

        def peak(t, y):
            # d(mu_req)/dt in stick has the sign of alpha (alpha' omega - 2 alpha^2) omega:
            # its falls through 0 are the maxima of mu_req between solver points.
            alpha = self.applied(t, y) / plant.J_total
            d_alpha = (self.torque_rate(t, y, alpha) if tm == 0.0
                       else (command.torque(t, y) - y[5]) / tm) / plant.J_total
            return alpha * (d_alpha * y[1] - 2.0 * alpha * alpha) * y[1]
        peak.terminal, peak.direction = False, -1
        return peak

    @staticmethod
    def slip_stop(direction: int):
        """Terminal event: the slip speed beta' returns to 0."""
        def g(t, y):
            return direction * y[3]
        g.terminal, g.direction = True, -1
        return g


class _Trajectory:
    """The recorded points and switches of a reference run."""

    def __init__(self, plant: PlantParams) -> None:
        self.plant = plant
        self.times: list[float] = []
        self.states: list[np.ndarray] = []
        self.modes: list[int] = []
        self.alphas: list[float] = []
        self.switches: list[Switch] = []

    def record(self, ode: _SegmentODE, t: float, y: np.ndarray, mode: int) -> None:
        self.times.append(t), self.states.append(np.array(y)), self.modes.append(int(mode))
        self.alphas.append(accelerations(self.plant, ode.applied(t, y), y[1], y[3], mode).alpha)

    def switch(self, ode: _SegmentODE, t: float, y: np.ndarray, mode: int, new: int) -> int:
        """Record a switch from ``mode`` to ``new`` at t [s]; returns the new mode."""
        self.switches.append(Switch(float(t), int(mode), int(new)))
        self.record(ode, t, y, new)
        if len(self.switches) > 10000:
            raise SimulationError("more than 10000 stick/slip switches: chattering")
        return new

    def result(self, breakpoints: Sequence[float], t_start: float) -> ReferenceResult:
        Y = np.array(self.states)
        alpha = np.array(self.alphas)
        mm = np.array(self.modes)
        ball = self.plant.ball
        mu_req = np.array([mu_required(ball, a, w) for a, w in zip(alpha, Y[:, 1])])
        result = ReferenceResult(np.array(self.times), Y[:, 0], Y[:, 1], Y[:, 2], Y[:, 3],
                                 alpha, mm, mu_req, self.switches)
        later = [b for b in breakpoints if b > t_start]
        _bounds(result, min(later) if later else None)
        return result


def _solve_to_event(ode: _SegmentODE, mode: int, t: float, t_stop: float, y: np.ndarray,
                    max_step: float):
    """(solution, terminal event hits [(t, y)]) of one ``solve_ivp`` run from t [s] in mode."""
    events = ([ode.stick_margin(1.0), ode.stick_margin(-1.0), ode.peak()]
              if mode == Mode.STICK else [ode.slip_stop(mode)])
    # An explicit first step: SciPy's automatic one can be below the spacing of t
    # (beta' = 0 with atol 1e-13), which re-fires the slip-stop event at t forever.
    first = min(t_stop - t, max_step, max(1e-10, 64 * np.spacing(abs(t))))
    sol = solve_ivp(ode.rhs_for(mode), (t, t_stop), y, method="DOP853", rtol=RTOL,
                    atol=ATOL, events=events, max_step=max_step, first_step=first)
    if not sol.success:
        raise SimulationError(f"reference integration failed at t = {t:.9g} s: "
                              f"{sol.message}")
    hits = [(te[0], ye[0]) for te, ye, ev in zip(sol.t_events, sol.y_events, events)
            if te.size and ev.terminal]
    return sol, hits


def _record_between(traj: _Trajectory, ode: _SegmentODE, sol, mode: int, t: float,
                    t_next: float) -> None:
    """Record the solver points strictly between t and t_next [s] (and, in stick, the maxima
    of mu_req between them)."""
    points = list(zip(sol.t, sol.y.T))
    if mode == Mode.STICK:  # the maxima of mu_req between solver points
        points += list(zip(sol.t_events[2], sol.y_events[2]))
        points.sort(key=lambda point: point[0])
    for ti, yi in points:
        if t < ti < t_next:
            traj.record(ode, ti, yi, mode)


def _land_on_event(traj: _Trajectory, ode: _SegmentODE, hits: list, mode: int
                   ) -> tuple[float, np.ndarray, int]:
    """(t [s], state, new mode) after switching at the first terminal event."""
    plant = ode.plant
    t_hit, y_hit = min(hits, key=lambda item: item[0])
    t, y = float(t_hit), np.array(y_hit, dtype=float)
    traj.record(ode, t, y, mode)
    if mode == Mode.STICK:
        mode = traj.switch(ode, t, y, mode, slip_direction(plant, ode.applied(t, y)))
    else:
        y[3] = 0.0
        new = Mode.STICK if stick_holds(plant, ode.applied(t, y), y[1]) \
            else slip_direction(plant, ode.applied(t, y))
        mode = traj.switch(ode, t, y, mode, new)
    return t, y, mode


def _integrate_segment(traj: _Trajectory, ode: _SegmentODE, t_a: float, t_stop: float,
                       y: np.ndarray, mode: int, max_step: float) -> tuple[np.ndarray, int]:
    """Integrate [t_a, t_stop] [s] through every switch; returns (end state, mode)."""
    t = t_a
    traj.record(ode, t, y, mode)  # right limit at the segment start
    while t < t_stop:
        if mode == Mode.STICK and not stick_holds(ode.plant, ode.applied(t, y), y[1]):
            mode = traj.switch(ode, t, y, mode, slip_direction(ode.plant, ode.applied(t, y)))
            continue
        sol, hits = _solve_to_event(ode, mode, t, t_stop, y, max_step)
        t_next = min(h[0] for h in hits) if hits else t_stop
        _record_between(traj, ode, sol, mode, t, t_next)
        if not hits:
            t, y = t_stop, sol.y[:, -1].copy()
            traj.record(ode, t, y, mode)  # left limit at the segment end
            break
        t, y, mode = _land_on_event(traj, ode, hits, mode)
    return y, mode


def _simulate(plant: PlantParams, drive: "_Drive", breakpoints: Sequence[float],
              t_start: float, t_end: float, y0: np.ndarray, max_step: float) -> ReferenceResult:
    """Integrate the hybrid system driven by ``drive`` (commanded torque [N m] and x_I')."""
    y = np.array(y0, dtype=float)
    mode = Mode.STICK if y[3] == 0.0 else int(math.copysign(1, y[3]))
    traj = _Trajectory(plant)
    for t_a, t_stop in _segments(breakpoints, t_start, t_end):
        # The drive is frozen on each segment (the setpoint level at its start), so no
        # solver stage sees the jump at the segment's end.
        ode = _SegmentODE(plant, drive.segment(t_a))
        y, mode = _integrate_segment(traj, ode, t_a, t_stop, y, mode, max_step)
    return traj.result(breakpoints, t_start)


def _segments(breakpoints: Sequence[float], t_start: float, t_end: float):
    """Consecutive (start, end) intervals of [t_start, t_end] split at the breakpoints."""
    cuts = [t_start] + sorted(b for b in breakpoints if t_start < b < t_end) + [t_end]
    return list(zip(cuts[:-1], cuts[1:]))


def _bounds(result: ReferenceResult, first_break: float | None = None) -> None:
    """mu_low, mu_high and the slip instant from the recorded points.

    Records at the slip instant come in the order [left limit,] right limit (stick mode,
    the new acceleration), switch (slip mode). mu_high is mu_req at the right limit; mu_low
    is the largest mu_req of the stick records before it, and includes the right limit itself
    when the slip is continuous (no jump of alpha there), where mu_low = mu_high = mu. A slip
    at or before ``first_break`` [s] gives mu_low = None (no lower bound).
    """
    first = next((s for s in result.switches if s.from_mode == Mode.STICK), None)
    stuck = result.mode == Mode.STICK
    if first is None:
        result.mu_low = float(result.mu_req[stuck].max()) if stuck.any() else 0.0
        return
    at_slip = np.nonzero(result.t == first.time)[0]
    i_switch = int(at_slip[result.mode[at_slip] != Mode.STICK][0])
    j = i_switch - 1  # right limit at the slip instant
    earlier = stuck & (np.arange(len(result.t)) < j)
    jump = j > 0 and result.t[j - 1] == first.time and result.alpha[j - 1] != result.alpha[j]
    if not jump:
        earlier[j] = True
    result.mu_low = float(result.mu_req[earlier].max()) if earlier.any() else 0.0
    result.t_slip = first.time
    result.omega_slip = float(result.omega[j])
    result.alpha_slip = float(result.alpha[j])
    result.mu_high = float(result.mu_req[j])
    if first_break is not None and first.time <= first_break + 1e-9:
        result.mu_low = None


class _Segment(Protocol):
    def torque(self, t: float, y: np.ndarray) -> float: ...
    def integral_rate(self, t: float, y: np.ndarray) -> float: ...


class _Drive(Protocol):
    def segment(self, t: float) -> _Segment: ...


@dataclass(frozen=True)
class _PISegment:
    """The PI law on one constant setpoint level w_ref [rad/s]."""

    law: SpeedLaw
    w_ref: float

    def torque(self, t: float, y: np.ndarray) -> float:
        e = y[4] if self.law.theta_ref_mode == "integral" else t * self.w_ref - y[0]
        return self.law.Kp * (self.w_ref - y[1]) + self.law.Ki * e

    def integral_rate(self, t: float, y: np.ndarray) -> float:
        return self.w_ref - y[1]

    def torque_rate(self, t: float, y: np.ndarray, alpha: float) -> float:
        """dT/dt = -Kp alpha + Ki (w_ref - w) [N m/s] (both readings)."""
        return -self.law.Kp * alpha + self.law.Ki * (self.w_ref - y[1])


class _PIStaircaseDrive:
    """The PI law on the staircase: constant setpoint between steps (right-continuous)."""

    def __init__(self, law: SpeedLaw, setpoints: Setpoints):
        self.law = law
        self.times = np.asarray(setpoints.step_times, dtype=float)
        self.levels = np.asarray(setpoints.levels, dtype=float)

    def segment(self, t: float) -> _PISegment:
        return _PISegment(self.law, float(self.levels[np.searchsorted(self.times, t, "right")]))


def simulate_staircase_reference(plant: PlantParams, law: SpeedLaw, setpoints: Setpoints,
                                 t_end: float, *, t_start: float = 0.0, beta0: float = 0.0,
                                 max_step: float = 0.01) -> ReferenceResult:
    """The staircase experiment (report sec. 4.2) as one ODE.

    Starts in steady rotation at the staircase's first level with the ball stuck at beta0 and
    the controller's integrator at 0. ``t_end`` [s]; ``max_step`` [s] bounds the solver
    step so that mu_low (a maximum over the stick period) is sampled densely.
    """
    omega0 = float(setpoints.levels[0])
    y0 = np.array([omega0 * t_start, omega0, beta0, 0.0, 0.0, 0.0])
    return _simulate(plant, _PIStaircaseDrive(law, setpoints), list(setpoints.step_times),
                     t_start, t_end, y0, max_step)


class _RampDrive:
    """Torque that gives alpha = sign(omega0) K t on the stuck rotor (smooth: one segment)."""

    def __init__(self, plant: PlantParams, jerk: float, omega0: float):
        self.gain = plant.J_total * jerk * math.copysign(1.0, omega0)

    def segment(self, t: float) -> "_RampDrive":
        return self

    def torque(self, t: float, y: np.ndarray) -> float:
        return self.gain * t

    def integral_rate(self, t: float, y: np.ndarray) -> float:
        return 0.0

    def torque_rate(self, t: float, y: np.ndarray, alpha: float) -> float:
        return self.gain


def simulate_ramp_reference(plant: PlantParams, omega0: float, jerk: float, t_end: float, *,
                            beta0: float = 0.0, max_step: float = 0.01) -> ReferenceResult:
    """The prescribed-motion experiment (report sec. 4.1): alpha grows at ``jerk`` [rad/s^3]
    in the direction of omega0 [rad/s] from 0, over [0, t_end] s."""
    y0 = np.array([0.0, omega0, beta0, 0.0, 0.0, 0.0])
    return _simulate(plant, _RampDrive(plant, jerk, omega0), [], 0.0, t_end, y0, max_step)
