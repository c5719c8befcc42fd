"""Drives of the harsh camera twin: what turns the ABU, simulated with the project's own plant.

Two kinds of drive, both a *digital* controller sampled at the camera's frame rate that feeds
:class:`abu_model.plant.AbuPlant` a first-order-hold torque (value and rate at each sample):

* ``staircase_pi``: the report's staircase reference (``controller.reference.Staircase``, 1 Hz
  steps, rounding ``lead`` / ``nearest`` / ``trail``) through a first-order **setpoint filter**
  (time constant ``setpoint_tau`` [s], 0 = none) into a PI speed loop with **setpoint
  weighting** b: T = Kp (b w_f - w) + Ki x_I, x_I' = w_f - w, Kp = 2 zeta wn J, Ki = wn^2 J.
* ``profile``: a prescribed smooth acceleration shaped like the report's fig. 5.8: a slow base
  ramp plus several raised-cosine bumps (C1, so omega_dot is continuous),
  alpha_cmd(t) = s [a_base r(t) + sum_k A_k bump((t - t_k) / w_k)], s = sign(omega0);
  the torque is J alpha_cmd.

* ``tracking``: the drive the report's chapter 6 recommends: a digital P law on the speed
  error to a prescribed smooth profile omega_p(t) (:mod:`controller.profile`, knots
  ``profile_t`` / ``profile_w``), T = J wb (omega_p - w), so that the continuous loop is
  w / w_p = wb / (tau_motor s^2 + s + wb) (``drive.json`` model ``tracking``); being digital at
  the frame rate it is not exactly that loop (the measurement fits the difference as a
  time offset).

All pass through the plant's **torque lag** ``tau_motor`` (0-30 ms). The rotor does not feel
the ball (the report's model, ``ball_reaction`` off), so :func:`rotor_mu_req` can predict
mu_req(t) with the ball stuck from the rotor alone (closed form per sample, the same formulas as
the plant's stick branch); :mod:`twin.scenario` uses it to place the slip inside the
recording before the full run. :func:`simulate_drive` then runs the plant, whose stick/slip
switches are exact, and returns the true state at every frame.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from abu_model.errors import ParameterError
from abu_model.params import DEFAULT_J_ABU, BallParams, PlantParams, check_finite, \
    check_nonnegative, check_positive

KINDS = ("staircase_pi", "profile", "tracking")
TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class DriveSpec:
    """One drive (SI units; Hz only in the derived meta fields).

    Attributes:
        kind: ``staircase_pi`` or ``profile``.
        omega0: speed at the start [rad/s] (negative = clockwise, the report's sign).
        tau_motor: first-order lag from commanded to applied torque [s].
        omega_end, t0, te, step, rounding: staircase (inclined sine from omega0 to omega_end
            over [t0, t0 + te] in steps of ``step`` rad/s) [rad/s, s, s, rad/s, -].
        zeta, omega_n: PI loop damping [-] and natural frequency [rad/s].
        setpoint_weight: b in T = Kp (b w_f - w) + Ki x_I [-].
        setpoint_tau: setpoint filter time constant [s] (0 = no filter).
        bumps: ``profile``: ((t_k [s], half-width w_k [s], amplitude A_k [rad/s^2]), ...).
        base_accel: ``profile``: base acceleration magnitude [rad/s^2] reached by a smooth
            ramp between ``base_t0`` and ``base_t0 + base_rise`` [s].
        bandwidth: ``tracking``: the loop's bandwidth wb [rad/s].
        profile_t, profile_w: ``tracking``: the profile's knots [s], [rad/s] (omega0 must be
            profile_w[0]).
    """

    kind: str = "staircase_pi"
    omega0: float = -9.0 * TWO_PI
    tau_motor: float = 0.02
    omega_end: float = -19.0 * TWO_PI
    t0: float = 0.0
    te: float = 0.5
    step: float = TWO_PI
    rounding: str = "lead"
    zeta: float = 0.7
    omega_n: float = 12.0
    setpoint_weight: float = 1.0
    setpoint_tau: float = 0.0
    bumps: tuple = ()
    base_accel: float = 0.0
    base_t0: float = 0.0
    base_rise: float = 0.1
    bandwidth: float = 150.0
    profile_t: tuple = ()
    profile_w: tuple = ()

    def __post_init__(self) -> None:
        if self.kind not in KINDS:
            raise ParameterError("drive kind", self.kind, f"one of {', '.join(KINDS)}")
        for name in ("omega0", "omega_end", "t0", "base_accel", "base_t0"):
            check_finite(name, getattr(self, name))
        if self.omega0 == 0.0:
            raise ParameterError("omega0", self.omega0, "a non-zero speed [rad/s]")
        check_nonnegative("tau_motor", self.tau_motor, "s")
        check_nonnegative("setpoint_tau", self.setpoint_tau, "s")
        for name, unit in (("te", "s"), ("step", "rad/s"), ("zeta", ""), ("omega_n", "rad/s"),
                           ("setpoint_weight", ""), ("base_rise", "s")):
            check_positive(name, getattr(self, name), unit)
        if self.rounding not in ("lead", "nearest", "trail"):
            raise ParameterError("rounding", self.rounding, "lead, nearest or trail")
        if self.kind == "tracking":
            check_positive("bandwidth", self.bandwidth, "rad/s")
            from controller.profile import ProfileFileError
            try:
                self.profile()
            except ProfileFileError as exc:
                raise ParameterError("profile", "knots", str(exc)) from None
            if self.omega0 != self.profile_w[0]:
                raise ParameterError("omega0", self.omega0, "the profile's first speed "
                                     f"{self.profile_w[0]!r} rad/s")
        for b in self.bumps:
            if len(b) != 3 or not all(math.isfinite(float(v)) for v in b) or b[1] <= 0:
                raise ParameterError("bumps", b, "(time [s], half-width > 0 [s], amplitude "
                                     "[rad/s^2]) triples")

    def profile(self):
        """The ``tracking`` drive's profile (:class:`controller.profile.Profile`)."""
        from controller.profile import Profile
        return Profile(tuple(self.profile_t), tuple(self.profile_w), source="drive spec")

    def to_dict(self) -> dict:
        """Unit-suffixed plain dict (meta.json)."""
        d = asdict(self)
        out = {"kind": self.kind, "omega0_rad_s": self.omega0, "omega0_hz": self.omega0 / TWO_PI,
               "tau_motor_s": self.tau_motor, "J_abu_kg_m2": DEFAULT_J_ABU}
        if self.kind == "staircase_pi":
            out.update(omega_end_rad_s=self.omega_end, omega_end_hz=self.omega_end / TWO_PI,
                       t0_s=self.t0, te_s=self.te, step_rad_s=self.step, rounding=self.rounding,
                       zeta=self.zeta, omega_n_rad_s=self.omega_n,
                       setpoint_weight=self.setpoint_weight, setpoint_tau_s=self.setpoint_tau)
        elif self.kind == "tracking":
            out.update(bandwidth_rad_s=self.bandwidth, profile_time_s=list(self.profile_t),
                       profile_omega_rad_s=list(self.profile_w))
        else:
            out.update(bumps=[{"t_s": b[0], "half_width_s": b[1], "amplitude_rad_s2": b[2]}
                              for b in d["bumps"]],
                       base_accel_rad_s2=self.base_accel, base_t0_s=self.base_t0,
                       base_rise_s=self.base_rise)
        return out


# ------------------------------------------------------------------------ prescribed profile


def _bump(u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Raised cosine (1 + cos(pi u)) / 2 on |u| < 1 and its derivative d/du (C1 bump)."""
    inside = np.abs(u) < 1.0
    val = np.where(inside, 0.5 * (1.0 + np.cos(np.pi * u)), 0.0)
    der = np.where(inside, -0.5 * np.pi * np.sin(np.pi * u), 0.0)
    return val, der


def profile_accel(spec: DriveSpec, t: np.ndarray | float) -> tuple[np.ndarray, np.ndarray]:
    """Commanded acceleration alpha_cmd(t) [rad/s^2] of a ``profile`` drive and its rate."""
    t = np.asarray(t, dtype=float)
    s = math.copysign(1.0, spec.omega0)
    u = np.clip((t - spec.base_t0) / spec.base_rise, 0.0, 1.0)
    ramp = u * u * (3.0 - 2.0 * u)                      # smoothstep
    d_ramp = np.where((u > 0) & (u < 1), 6.0 * u * (1.0 - u) / spec.base_rise, 0.0)
    a = spec.base_accel * ramp
    da = spec.base_accel * d_ramp
    for tk, wk, ak in spec.bumps:
        v, dv = _bump((t - tk) / wk)
        a = a + ak * v
        da = da + ak * dv / wk
    return s * a, s * da


# ------------------------------------------------------------------------ digital controller


class _Controller:
    """The drive's digital controller: torque value and rate at each sample."""

    def __init__(self, spec: DriveSpec, J: float, h: float, t_first: float, n: int):
        self.spec, self.J, self.h = spec, J, h
        if spec.kind == "profile":  # prescribed: evaluated once on the whole sample grid
            self.a, self.da = profile_accel(spec, t_first + h * np.arange(n))
            self.a, self.da = (J * self.a).tolist(), (J * self.da).tolist()
        elif spec.kind == "tracking":  # the reference is evaluated once on the sample grid
            from abu_model.tracking_response import reference
            wp, dwp = reference(spec.profile(), t_first + h * np.arange(n))
            self.wp, self.dwp = wp.tolist(), dwp.tolist()
            self.kp = J * spec.bandwidth
        else:
            from controller.reference import Staircase

            self.stair = Staircase(spec.omega0, spec.omega_end, spec.t0, spec.te,
                                   step=spec.step, rounding=spec.rounding)
            self.Kp = 2.0 * spec.zeta * spec.omega_n * J
            self.Ki = spec.omega_n ** 2 * J
            self.wf = spec.omega0
            # steady state at omega0 (T = 0): Kp (b - 1) w0 + Ki x_I = 0
            self.xI = self.Kp * (1.0 - spec.setpoint_weight) * spec.omega0 / self.Ki
            self.filt = 1.0 - math.exp(-h / spec.setpoint_tau) if spec.setpoint_tau > 0 else 1.0

    def command(self, k: int, t: float, omega: float, applied: float | None
                ) -> tuple[float, float, float]:
        """(torque [N m], torque rate [N m/s], reference [rad/s]) at sample k, time t.

        ``applied``: the torque acting on the rotor now (motor lag), None without a lag.
        """
        sp = self.spec
        if sp.kind == "profile":
            return self.a[k], self.da[k], math.nan
        if sp.kind == "tracking":   # P law on the speed error: T = J wb (w_p - w)
            torque = self.kp * (self.wp[k] - omega)
            alpha = (torque if applied is None else applied) / self.J
            return torque, self.kp * (self.dwp[k] - alpha), self.wp[k]
        w_ref = float(self.stair.value(t))
        self.wf += self.filt * (w_ref - self.wf)
        dwf = (w_ref - self.wf) / sp.setpoint_tau if sp.setpoint_tau > 0 else 0.0
        torque = self.Kp * (sp.setpoint_weight * self.wf - omega) + self.Ki * self.xI
        alpha = (torque if applied is None else applied) / self.J
        rate = self.Kp * (sp.setpoint_weight * dwf - alpha) + self.Ki * (self.wf - omega)
        self.xI += self.h * (self.wf - omega)           # the digital integrator (Euler)
        return torque, rate, w_ref


def _rotor_step(state: list[float], h: float, T0: float, r: float, tm: float, J: float) -> None:
    """Advance [theta, omega, applied torque] by h under T(u) = T0 + r u (closed form)."""
    th, w, a0 = state
    if tm == 0.0:
        state[0] = th + w * h + (T0 * h * h / 2.0 + r * h ** 3 / 6.0) / J
        state[1] = w + (T0 * h + r * h * h / 2.0) / J
        state[2] = T0 + r * h
        return
    A, B, C = T0 - r * tm, r, a0 - T0 + r * tm
    e = -math.expm1(-h / tm)
    state[0] = th + w * h + (A * h * h / 2.0 + B * h ** 3 / 6.0 + C * tm * (h - tm * e)) / J
    state[1] = w + (A * h + B * h * h / 2.0 + C * tm * e) / J
    state[2] = A + B * h + C * (1.0 - e)


def rotor_mu_req(spec: DriveSpec, times: np.ndarray, ball: BallParams | None = None,
                 pre_roll: float = 0.05) -> dict[str, np.ndarray]:
    """The rotor alone (ball stuck) at the frame times: theta, omega, alpha, mu_req.

    ``times`` must be equally spaced (the frame times); the controller samples at them,
    starting ``pre_roll`` s (whole frames) earlier at rest on omega0. mu_req uses the ball's
    lever ratio (l - d/5)/l.
    """
    lever = (ball or BallParams()).lever_ratio
    h, k0, n_total = _sampling(times, pre_roll)
    J = DEFAULT_J_ABU
    t_first = float(times[0]) - k0 * h
    ctl = _Controller(spec, J, h, t_first, n_total)
    st = [0.0, spec.omega0, 0.0]
    out = np.empty((len(times), 3))
    for k in range(n_total):
        t = t_first + k * h
        T, r, _ = ctl.command(k, t, st[1], st[2] if spec.tau_motor > 0 else None)
        if spec.tau_motor == 0.0:
            st[2] = T
        if k >= k0:
            out[k - k0] = (st[0], st[1], st[2] / J)
        _rotor_step(st, h, T, r, spec.tau_motor, J)
    theta, omega, alpha = out.T
    return {"theta": theta, "omega": omega, "alpha": alpha,
            "mu_req": lever * np.abs(alpha) / np.maximum(omega * omega, 1e-300)}


def _sampling(times: np.ndarray, pre_roll: float) -> tuple[float, int, int]:
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or times.size < 2:
        raise ParameterError("times", times.shape, "at least two equally spaced frame times [s]")
    h = float(times[1] - times[0])
    if h <= 0 or not np.allclose(np.diff(times), h, rtol=1e-9, atol=1e-12):
        raise ParameterError("times", "unequal spacing", "equally spaced frame times [s]")
    k0 = int(math.ceil(pre_roll / h))
    return h, k0, k0 + times.size


def simulate_drive(spec: DriveSpec, ball: BallParams, times: np.ndarray, *, beta0: float = 0.0,
                   pre_roll: float = 0.05) -> dict[str, np.ndarray]:
    """Run the drive on :class:`abu_model.plant.AbuPlant`; the true state at the frame times.

    Returns arrays (one value per frame): theta, omega, alpha (= omega_dot, right limit),
    beta, beta_dot [SI], mu_req [-], mode (-1/0/+1), omega_ref [rad/s] (NaN for a profile),
    torque [N m] (applied), and ``switches`` (times [s] of every stick/slip switch).
    """
    from abu_model.plant import AbuPlant

    h, k0, n_total = _sampling(times, pre_roll)
    params = PlantParams(ball=ball, tau_motor=spec.tau_motor)
    J = params.J_abu
    t_first = float(times[0]) - k0 * h
    plant = AbuPlant(params, t0=t_first, omega0=spec.omega0, beta0=beta0)
    ctl = _Controller(spec, J, h, t_first, n_total)
    names = ("theta", "omega", "alpha", "beta", "beta_dot", "mu_req", "mode", "omega_ref",
             "torque")
    out = {n: np.empty(times.size) for n in names}
    switches: list[float] = []
    for k in range(n_total):
        s = plant.state
        T, r, w_ref = ctl.command(k, t_first + k * h, s.omega,
                                  s.torque_applied if spec.tau_motor > 0 else None)
        if k >= k0:
            o = plant.outputs(T)
            i = k - k0
            for n, v in (("theta", s.theta), ("omega", s.omega), ("alpha", o.alpha),
                         ("beta", s.beta), ("beta_dot", s.beta_dot), ("mu_req", o.mu_req),
                         ("mode", s.mode), ("omega_ref", w_ref),
                         ("torque", plant.applied_torque(T))):
                out[n][i] = v
        switches.extend(sw.time for sw in plant.advance(h, T, r))
    out["mode"] = out["mode"].astype(int)
    out["switches"] = np.asarray(switches)
    return out


def first_slip_time(mu_req: np.ndarray, times: np.ndarray, mu: float) -> float | None:
    """First frame time at which mu_req exceeds mu (None if never) [s]."""
    idx = np.flatnonzero(np.asarray(mu_req) > mu)
    return float(times[idx[0]]) if idx.size else None


__all__ = ["DriveSpec", "KINDS", "profile_accel", "rotor_mu_req", "simulate_drive",
           "first_slip_time"]
