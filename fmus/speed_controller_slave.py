"""SpeedController FMU: the identified PI speed law (report sec. 4.2.1) as an FMI 2.0 CS slave.

Built by ``fmus.build`` into ``SpeedController.fmu`` as module ``abufmu_speedcontroller``;
``controller`` and ``abu_model`` travel inside the FMU as ``speedcontroller_controller`` and
``speedcontroller_abu_model`` (the build rewrites the project imports below).

T = Kp (omega_ref - omega) + Ki e_theta with Kp = 2 zeta omega_n J_abu, Ki = omega_n^2 J_abu;
e_theta = x_I (theta_ref_mode 0, integral: x_I' = omega_ref - omega) or t omega_ref - theta
(theta_ref_mode 1, the report's literal theta_ref = t omega_ref).

Taylor hold of the torque: the controller also outputs the torque's derivatives between
setpoint steps, T' = -Kp alpha + Ki (omega_ref - omega), T'' = -Kp jerk - Ki alpha,
T^(3) = -Kp snap - Ki jerk, T^(4) = -Kp crackle - Ki snap (both readings of theta_ref), for
the plant's ``torque_rate``, ``torque_accel``, ``torque_jerk``, ``torque_snap`` inputs, from
the plant's d^k(alpha)/dt^k (inputs ``jerk``, ``snap``, ``crackle``; unconnected: 0, a
lower-order hold). Inside a step the integrator sees omega(tau) as the same Taylor
polynomial, omega + alpha tau + jerk tau^2/2 + snap tau^3/6 + crackle tau^4/24.
The outputs are computed from the internal state and the current inputs whenever they are
read, so after new inputs are set at a communication point they are the right-hand limits.
"""
from __future__ import annotations

import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from abu_model.errors import ParameterError
from abu_model.params import check_record
from controller.pi import THETA_REF_MODES, PISpeedController

_PARAMETERS = ("zeta", "omega_n", "J_abu", "theta_ref_mode", "x_I0")
_INPUTS = ("omega_ref", "omega", "theta", "alpha", "jerk", "snap", "crackle")


class SpeedController(Fmi2Slave):
    """PI speed controller with the identified closed-loop parameters zeta, omega_n."""

    author = "abu-friction"
    description = ("PI speed law T = Kp (omega_ref - omega) + Ki e_theta, Kp = 2 zeta omega_n "
                   "J_abu, Ki = omega_n^2 J_abu (report eq. 4.4-4.5), with the torque's "
                   "derivatives as outputs for a Taylor hold of the torque (up to 4th order)")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=1e-3)

    UNITS = {
        "zeta": "1", "omega_n": "rad/s", "J_abu": "kg.m2", "x_I0": "rad",
        "omega_ref": "rad/s", "omega": "rad/s", "theta": "rad", "alpha": "rad/s2",
        "torque": "N.m", "torque_rate": "N.m/s", "x_I": "rad", "jerk": "rad/s3",
        "torque_accel": "N.m/s2", "snap": "rad/s4", "crackle": "rad/s5",
        "torque_jerk": "N.m/s3", "torque_snap": "N.m/s4",
    }
    OUTPUT_DEPENDENCIES = {
        "torque": ("omega_ref", "omega", "theta"),
        "torque_rate": ("omega_ref", "omega", "alpha"),
        "torque_accel": ("alpha", "jerk"),
        "torque_jerk": ("jerk", "snap"),
        "torque_snap": ("snap", "crackle"),
        "x_I": (),
    }

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.zeta = 0.5
        self.omega_n = 2.2
        self.J_abu = 4.5e-5
        self.theta_ref_mode = 0
        self.x_I0 = 0.0
        self.omega_ref = 0.0
        self.omega = 0.0
        self.theta = 0.0
        self.alpha = 0.0
        self.jerk = 0.0
        self.snap = 0.0
        self.crackle = 0.0
        # Internal state.
        self.time = 0.0
        self.x_I = 0.0
        self._law: PISpeedController | None = None

        fixed = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed)
        self.register_variable(Real(
            "zeta", description="damping ratio of the identified closed loop, > 0 [1]", **fixed))
        self.register_variable(Real(
            "omega_n", description="natural frequency of the identified closed loop, "
                                   "> 0 [rad/s]", **fixed))
        self.register_variable(Real(
            "J_abu", description="rotor inertia the gains are scaled with, > 0 [kg m2]", **fixed))
        self.register_variable(Integer(
            "theta_ref_mode", description="0 integral (x_I' = omega_ref - omega), "
                                          "1 thesis (e_theta = t omega_ref - theta)", **fixed))
        self.register_variable(Real(
            "x_I0", description="initial integrator state x_I [rad]", **fixed))
        inp = dict(causality=Fmi2Causality.input)
        self.register_variable(Real("omega_ref", description="speed setpoint [rad/s]", **inp))
        self.register_variable(Real("omega", description="measured ABU speed [rad/s]", **inp))
        self.register_variable(Real(
            "theta", description="ABU angle (used in thesis mode) [rad]", **inp))
        self.register_variable(Real(
            "alpha", description="ABU acceleration, for torque_rate and the integrator "
                                 "[rad/s2]", **inp))
        self.register_variable(Real(
            "jerk", description="ABU jerk d(alpha)/dt, for torque_accel and the integrator "
                                "(second-order hold; 0: first-order) [rad/s3]", **inp))
        out = dict(causality=Fmi2Causality.output)
        self.register_variable(Real("torque", description="commanded motor torque [N m]",
                                    getter=self._torque, **out))
        self.register_variable(Real(
            "torque_rate", description="time derivative of the commanded torque "
                                       "between setpoint steps, -Kp alpha + Ki (omega_ref - omega) "
                                       "[N m/s]",
            getter=self._torque_rate, **out))
        self.register_variable(Real(
            "torque_accel", description="second time derivative of the commanded "
                                        "torque between setpoint steps, -Kp jerk - Ki alpha "
                                        "[N m/s2]",
            getter=lambda: self._torque_derivative("jerk", "alpha"), **out))
        self.register_variable(Real(
            "x_I", description="integrator state (integral of omega_ref - omega) [rad]",
            getter=lambda: self.x_I, **out))
        # Registered last: the value references above stay those of earlier versions.
        self.register_variable(Real(
            "snap", description="d(jerk)/dt of the ABU, for torque_jerk and the "
                                "integrator (third-order hold; 0: lower order) [rad/s4]", **inp))
        self.register_variable(Real(
            "crackle", description="d(snap)/dt of the ABU, for torque_snap and the "
                                   "integrator (fourth-order hold; 0: lower order) [rad/s5]",
            **inp))
        self.register_variable(Real(
            "torque_jerk", description="third time derivative of the commanded "
                                       "torque between setpoint steps, -Kp snap - Ki jerk "
                                       "[N m/s3]",
            getter=lambda: self._torque_derivative("snap", "jerk"), **out))
        self.register_variable(Real(
            "torque_snap", description="fourth time derivative of the commanded "
                                       "torque between setpoint steps, -Kp crackle - Ki snap "
                                       "[N m/s4]",
            getter=lambda: self._torque_derivative("crackle", "snap"), **out))

    # ----------------------------------------------------------------- model
    def _build_law(self) -> PISpeedController:
        mode = int(self.theta_ref_mode)
        if mode not in range(len(THETA_REF_MODES)):
            raise ParameterError("theta_ref_mode", self.theta_ref_mode,
                                 "0 (integral) or 1 (thesis)")
        x_i0 = float(self.x_I0)
        if not math.isfinite(x_i0):
            raise ParameterError("x_I0", self.x_I0, "a finite number [rad]")
        return PISpeedController(self.zeta, self.omega_n, self.J_abu, THETA_REF_MODES[mode])

    def _current_law(self) -> PISpeedController | None:
        """The law; before initialization one built from the current parameters."""
        if self._law is not None:
            return self._law
        try:
            return self._build_law()
        except ValueError:
            return None

    def _x_i(self) -> float:
        return self.x_I if self._law is not None else float(self.x_I0)

    def _torque(self) -> float:
        law = self._current_law()
        if law is None:
            return math.nan
        return law.torque(self.time, self.omega_ref, self.omega, self.theta, self._x_i())

    def _torque_rate(self) -> float:
        law = self._current_law()
        return math.nan if law is None else law.torque_rate(self.omega_ref, self.omega, self.alpha)

    def _torque_derivative(self, d_k: str, d_k_minus_1: str) -> float:
        """T^(k), k >= 2, from the inputs named d_k, d_k_minus_1 (omega^(k), omega^(k-1))."""
        law = self._current_law()
        return (math.nan if law is None
                else law.torque_derivative(getattr(self, d_k), getattr(self, d_k_minus_1)))

    # ----------------------------------------------------------------- FMI
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.time = float(start_time)

    def exit_initialization_mode(self):
        # A ParameterError (a ValueError) names the parameter; the runtime returns fmi2Error.
        self._law = self._build_law()
        self.x_I = float(self.x_I0)

    def do_step(self, current_time, step_size):
        for name in _INPUTS:
            value = getattr(self, name)
            if not math.isfinite(value):
                self.log(f"SpeedController '{self.instance_name}': input '{name}' = {value!r} "
                         f"at t = {current_time!r} s is not finite", Fmi2Status.error)
                return False  # fmi2Discard: nothing advanced
        # omega(tau) = omega + alpha tau + jerk tau^2/2 + snap tau^3/6 + crackle tau^4/24
        self.x_I += self._law.integral_increment(step_size, self.omega_ref, self.omega,
                                                 self.alpha, self.jerk, self.snap, self.crackle)
        self.time = current_time + step_size
        return True

    # ----------------------------------------------------------------- FMU state
    def _get_fmu_state(self):
        state = {name: getattr(self, name) for name in _PARAMETERS + _INPUTS}
        state.update(time=self.time, x_I=self.x_I, initialized=self._law is not None)
        return state

    @staticmethod
    def _validate_fmu_state(state, before_initialization: bool) -> dict:
        """A checked copy of a saved state (ValueError if anything is missing or malformed)."""
        kinds = {**{name: "real" for name in _PARAMETERS + _INPUTS}, "theta_ref_mode": "int",
                 "time": "real", "x_I": "real", "initialized": "bool"}
        checked = check_record(state, kinds, "SpeedController state")
        if checked["initialized"] and checked["theta_ref_mode"] not in range(len(THETA_REF_MODES)):
            raise ValueError(f"SpeedController state: theta_ref_mode = {checked['theta_ref_mode']}")
        return checked

    def _set_fmu_state(self, state):
        for name in _PARAMETERS + _INPUTS:
            setattr(self, name, state[name])
        self.time = float(state["time"])
        self.x_I = float(state["x_I"])
        self._law = self._build_law() if state["initialized"] else None
