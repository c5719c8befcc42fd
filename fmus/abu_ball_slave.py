"""AbuBall FMU: the ABU rotor with one ball (report ch. 3, app. A) as an FMI 2.0 CS slave.

Built by ``fmus.build`` into ``AbuBall.fmu`` as module ``abufmu_abuball``; ``abu_model``
travels inside the FMU as ``abuball_abu_model`` (the build rewrites the imports below).

Inputs: the commanded torque held as its Taylor polynomial inside a step,
T(tau) = torque + torque_rate tau + torque_accel tau^2/2 + torque_jerk tau^3/6
+ torque_snap tau^4/24 (the FMU has no fmi2SetRealInputDerivatives, so the derivatives are
explicit inputs; connect the SpeedController's ``torque_rate``, ``torque_accel``, ... to
them, or leave them 0 for a lower-order hold; the inputs after ``torque_rate`` are optional,
default 0, and registered after the older variables so that their value references keep
their numbers). The outputs ``jerk``, ``snap``, ``crackle`` are d^k(alpha)/dt^k, k = 1, 2, 3,
for the torque inputs set so far (exact, for the controller's next torque derivative).
``do_step`` calls ``AbuPlant.advance``, which locates every stick/slip switch
inside the step exactly; the outputs report them (``switch_count``, ``t_last_switch``,
``step_switches``, ``t_first_step_switch``) so that a master can roll back and land a
communication point on the first switch. ``mu_req_peak`` is the largest mu_req in stick over
the last step, maxima between communication points included.

The algebraic outputs (alpha, beta_ddot, friction_force, mu_req, torque_applied) are computed
from the state and the *current* torque input when read, so after fmi2SetReal at a
communication point they are right-hand limits (e.g. alpha just after a torque jump).
Switch times are reported as ``NO_SWITCH`` = -1e30 s while there is none.
"""
from __future__ import annotations

import math

from pythonfmu import Boolean, Fmi2Causality, Fmi2Slave, Fmi2Variability, Integer, Real
from pythonfmu.default_experiment import DefaultExperiment
from pythonfmu.enums import Fmi2Status

from abu_model.params import DEFAULT_J_ABU, BallParams, PlantParams, check_finite, check_record
from abu_model.plant import STATE_FIELDS, AbuPlant, Mode, PlantOutputs, PlantState

#: Reported for switch times when there is no switch (before the first one, or none in the
#: last step) [s].
NO_SWITCH = -1e30
#: Relative mismatch tolerated between the master's current time and the FMU's time [-].
TIME_TOLERANCE = 1e-9

_BALL = ("m", "d", "l", "mu", "mu_d")
_PARAMETERS = _BALL + ("J_abu", "tau_motor", "ball_reaction", "theta0", "omega0", "beta0",
                       "beta_dot0")
_INPUTS = ("torque", "torque_rate", "torque_accel", "torque_jerk", "torque_snap")

#: Kinds of the saved state's entries (see ``check_record``).
_STATE_KINDS = {**{name: "real" for name in _PARAMETERS + _INPUTS}, "ball_reaction": "bool",
                "start_time": "real", "step_switches": "int", "t_first_step_switch": "real",
                "step_peak": "real"}
_PLANT_KINDS = {**{name: "real" for name in STATE_FIELDS}, "mode": "int",
                "switch_count": "int", "t_last_switch": "extended"}


class AbuBall(Fmi2Slave):
    """ABU rotor with one ball: stick/slip hybrid plant with exact switch location."""

    author = "abu-friction"
    description = ("ABU rotor with one ball on its rim: stick/slip dynamics (report ch. 3, app. A) "
                   "with exact switch location inside each step; torque input held as its Taylor "
                   "polynomial T(tau) = torque + torque_rate tau + torque_accel tau^2/2 + ...")
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.0, step_size=1e-3)

    UNITS = {
        "m": "kg", "d": "m", "l": "m", "mu": "1", "mu_d": "1", "J_abu": "kg.m2",
        "tau_motor": "s", "theta0": "rad", "omega0": "rad/s", "beta0": "rad", "beta_dot0": "rad/s",
        "torque": "N.m", "torque_rate": "N.m/s", "torque_accel": "N.m/s2",
        "theta": "rad", "omega": "rad/s", "alpha": "rad/s2", "beta": "rad", "beta_dot": "rad/s",
        "beta_ddot": "rad/s2", "normal_force": "N", "friction_force": "N", "mu_req": "1",
        "torque_applied": "N.m", "t_last_switch": "s", "t_first_step_switch": "s",
        "jerk": "rad/s3", "torque_jerk": "N.m/s3", "torque_snap": "N.m/s4", "snap": "rad/s4",
        "crackle": "rad/s5", "mu_req_peak": "1",
    }
    OUTPUT_DEPENDENCIES = {
        "theta": (), "omega": (), "beta": (), "beta_dot": (), "normal_force": (),
        "alpha": ("torque",), "beta_ddot": ("torque",), "friction_force": ("torque",),
        "mu_req": ("torque",), "torque_applied": ("torque",),
        "jerk": ("torque", "torque_rate"),
        "snap": ("torque", "torque_rate", "torque_accel"),
        "crackle": ("torque", "torque_rate", "torque_accel", "torque_jerk"),
        "mu_req_peak": (),
        "mode": (), "switch_count": (), "t_last_switch": (), "step_switches": (),
        "t_first_step_switch": (),
    }

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self._init_values()
        # Registration order sets the value references: keep it (and append new variables
        # at the end) so that saved SSP files and masters keep working.
        self._register_parameters()
        self._register_inputs()
        self._register_outputs()
        self._register_switch_outputs()
        self._register_later_variables()

    def _init_values(self) -> None:
        """Start values of parameters [SI] and inputs, and the internal state."""
        ball = BallParams()
        self.m, self.d, self.l, self.mu = ball.m, ball.d, ball.l, ball.mu
        self.mu_d = -1.0
        self.J_abu = DEFAULT_J_ABU
        self.tau_motor = 0.0
        self.ball_reaction = False
        self.theta0 = 0.0
        self.omega0 = -2.0 * math.pi * 17.0  # the report's experiment starts at -17 Hz
        self.beta0 = 0.0
        self.beta_dot0 = 0.0
        self.torque = 0.0
        self.torque_rate = 0.0
        self.torque_accel = 0.0
        self.torque_jerk = 0.0
        self.torque_snap = 0.0
        # Internal state besides the plant's.
        self.start_time = 0.0
        self.step_switches = 0
        self.t_first_step_switch = NO_SWITCH
        self.step_peak = 0.0
        self._plant: AbuPlant | None = None
        self._cache: tuple[float, PlantOutputs] | None = None

    def _register_parameters(self) -> None:
        """Ball, rotor and initial-state parameters (fixed)."""
        fixed = dict(causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed)
        self.register_variable(Real("m", description="ball mass, > 0 [kg]", **fixed))
        self.register_variable(Real("d", description="ball diameter, > 0 and < 2 l [m]", **fixed))
        self.register_variable(Real(
            "l", description="radius of the ball centre's path, > 0 [m]", **fixed))
        self.register_variable(Real(
            "mu", description="static friction coefficient, >= 0 [1]", **fixed))
        self.register_variable(Real(
            "mu_d", description="sliding friction coefficient, 0 <= mu_d <= mu [1]; "
                                "negative (default -1) means mu_d = mu", **fixed))
        self.register_variable(Real("J_abu", description="rotor inertia, > 0 [kg m2]", **fixed))
        self.register_variable(Real(
            "tau_motor", description="time constant of the lag from commanded to applied torque, "
                                     ">= 0 [s] (0: none)", **fixed))
        self.register_variable(Boolean(
            "ball_reaction", description="true: the ball's inertial reaction acts on the rotor; "
                                         "false: J_abu alpha = T (the report's model)", **fixed))
        self.register_variable(Real("theta0", description="initial ABU angle [rad]", **fixed))
        self.register_variable(Real("omega0", description="initial ABU speed [rad/s]", **fixed))
        self.register_variable(Real(
            "beta0", description="initial ball angle relative to the ABU [rad]", **fixed))
        self.register_variable(Real(
            "beta_dot0", description="initial ball speed relative to the ABU [rad/s]; "
                                     "0 starts in stick, else in slip", **fixed))

    def _register_inputs(self) -> None:
        """The commanded torque [N m] and its rate [N m/s] (the older inputs)."""
        inp = dict(causality=Fmi2Causality.input)
        self.register_variable(Real(
            "torque", description="commanded torque at the step start [N m]",
            setter=self._set_torque, **inp))
        self.register_variable(Real(
            "torque_rate", description="rate of the commanded torque inside "
                                       "a step (first-order hold) [N m/s]", **inp))

    def _register_outputs(self) -> None:
        """Continuous outputs: state, accelerations, forces, mu_req, applied torque, jerk."""
        out = dict(causality=Fmi2Causality.output)
        state = self._state_value
        self.register_variable(Real(
            "theta", description="ABU angle [rad]", getter=lambda: state("theta"), **out))
        self.register_variable(Real(
            "omega", description="ABU speed [rad/s]", getter=lambda: state("omega"), **out))
        self.register_variable(Real(
            "alpha", description="ABU acceleration for the current torque input [rad/s2]",
            getter=lambda: self._output("alpha"), **out))
        self.register_variable(Real("beta", description="ball angle relative to the ABU [rad]",
                                    getter=lambda: state("beta"), **out))
        self.register_variable(Real(
            "beta_dot", description="ball speed relative to the ABU [rad/s]",
            getter=lambda: state("beta_dot"), **out))
        self.register_variable(Real(
            "beta_ddot", description="ball acceleration relative to the ABU [rad/s2]",
            getter=lambda: self._output("beta_ddot"), **out))
        self.register_variable(Real(
            "normal_force", description="normal force of the rim on the ball [N]",
            getter=lambda: self._output("normal_force"), **out))
        self.register_variable(Real("friction_force", description="friction force on the ball [N]",
                                    getter=lambda: self._output("friction_force"), **out))
        self.register_variable(Real(
            "mu_req", description="(l - d/5)|alpha| / (l omega^2): friction coefficient that "
                                  "sticking requires now [1] (inf at omega = 0)",
            getter=lambda: self._output("mu_req"), **out))
        self.register_variable(Real(
            "torque_applied", description="torque acting on the rotor (after the motor lag) [N m]",
            getter=self._torque_applied, **out))
        self.register_variable(Real(
            "jerk", description="d(alpha)/dt for the current torque inputs [rad/s3] (for a "
                                "second-order hold of the controller's torque)",
            getter=lambda: self._alpha_derivative(1), **out))

    def _register_switch_outputs(self) -> None:
        """Discrete mode and the stick/slip switch bookkeeping."""
        out = dict(causality=Fmi2Causality.output)
        discrete = dict(causality=Fmi2Causality.output, variability=Fmi2Variability.discrete)
        self.register_variable(Integer(
            "mode", description="-1 slip with beta_dot < 0, 0 stick, "
                                "1 slip with beta_dot > 0",
            getter=lambda: self._int_state("mode"), **discrete))
        self.register_variable(Integer(
            "switch_count", description="stick/slip switches since the start",
            getter=lambda: self._int_state("switch_count"), **discrete))
        self.register_variable(Real(
            "t_last_switch", description="time of the last stick/slip switch, "
                                         "-1e30 before the first [s]",
            getter=self._t_last_switch, **out))
        self.register_variable(Integer(
            "step_switches", description="stick/slip switches inside the "
                                         "last do_step", **discrete))
        self.register_variable(Real("t_first_step_switch", description="time of the first switch "
                                    "inside the last do_step, -1e30 if none [s]", **out))

    def _register_later_variables(self) -> None:
        """Variables added after the first versions: higher torque derivatives (inputs),
        snap, crackle and mu_req_peak (outputs)."""
        inp = dict(causality=Fmi2Causality.input)
        out = dict(causality=Fmi2Causality.output)
        # Registered last: the value references above stay those of earlier versions.
        self.register_variable(Real("torque_accel", description="second derivative of the "
                                    "commanded torque inside a step (second-order hold, "
                                    "optional) [N m/s2]", **inp))
        self.register_variable(Real("torque_jerk", description="third derivative of the "
                                    "commanded torque inside a step (third-order hold, "
                                    "optional) [N m/s3]", **inp))
        self.register_variable(Real("torque_snap", description="fourth derivative of the "
                                    "commanded torque inside a step (fourth-order hold, "
                                    "optional) [N m/s4]", **inp))
        self.register_variable(Real(
            "snap", description="d(jerk)/dt for the current torque inputs [rad/s4] (for a "
                                "third-order hold of the controller's torque)",
            getter=lambda: self._alpha_derivative(2), **out))
        self.register_variable(Real(
            "crackle", description="d(snap)/dt for the current torque inputs [rad/s5] (for a "
                                   "fourth-order hold of the controller's torque)",
            getter=lambda: self._alpha_derivative(3), **out))
        self.register_variable(Real(
            "mu_req_peak", description="largest mu_req while the ball sticks over the last "
                                       "do_step, maxima inside the step included (0 if it did "
                                       "not stick) [1]", getter=lambda: self.step_peak, **out))

    # ----------------------------------------------------------------- model
    def _plant_params(self) -> PlantParams:
        mu_d = float(self.mu_d)
        ball = BallParams(self.m, self.d, self.l, self.mu,
                          None if (math.isfinite(mu_d) and mu_d < 0.0) else mu_d)
        return PlantParams(ball, self.J_abu, self.tau_motor, bool(self.ball_reaction))

    def _new_plant(self) -> AbuPlant:
        return AbuPlant(self._plant_params(), t0=self.start_time, theta0=self.theta0,
                        omega0=self.omega0, beta0=self.beta0, beta_dot0=self.beta_dot0,
                        torque0=self.torque)

    def _current_plant(self) -> AbuPlant | None:
        """The plant; before initialization one built from the current parameters."""
        if self._plant is not None:
            return self._plant
        try:
            return self._new_plant()
        except ValueError:
            return None

    def _state_value(self, name: str):
        plant = self._current_plant()
        return math.nan if plant is None else getattr(plant.state, name)

    def _int_state(self, name: str) -> int:
        plant = self._current_plant()
        return 0 if plant is None else int(getattr(plant.state, name))

    def _t_last_switch(self) -> float:
        t = self._state_value("t_last_switch")
        return NO_SWITCH if t == -math.inf else t

    def _outputs(self) -> PlantOutputs | None:
        plant = self._current_plant()
        if plant is None:
            return None
        if self._plant is None:
            return plant.outputs(self.torque)
        if self._cache is None or self._cache[0] != self.torque:
            self._cache = (self.torque, plant.outputs(self.torque))
        return self._cache[1]

    def _output(self, name: str) -> float:
        outputs = self._outputs()
        return math.nan if outputs is None else getattr(outputs, name)

    def _alpha_derivative(self, order: int) -> float:
        """d^order(alpha)/dt^order now [rad/s^(2+order)] for the current torque inputs: exact
        (Taylor-mode recursion on the equations of motion, ``abu_model.dynamics``)."""
        plant = self._current_plant()
        if plant is None:
            return math.nan
        inputs = [getattr(self, name) for name in _INPUTS[:order + 1]]
        return plant.alpha_derivatives(inputs, order)[order]

    def _torque_applied(self) -> float:
        plant = self._current_plant()
        return math.nan if plant is None else plant.applied_torque(self.torque)

    def _set_torque(self, value: float) -> None:
        self.torque = value
        self._cache = None

    # ----------------------------------------------------------------- FMI
    def setup_experiment(self, start_time, stop_time=None, tolerance=None):
        self.start_time = float(start_time)

    def exit_initialization_mode(self):
        # A ParameterError (a ValueError) names the parameter; the runtime returns fmi2Error.
        for name in _INPUTS:
            check_finite(name, getattr(self, name), "a finite start value")
        self._plant = self._new_plant()
        self._cache = None
        self.step_switches, self.t_first_step_switch = 0, NO_SWITCH
        self.step_peak = 0.0

    def do_step(self, current_time, step_size):
        plant = self._plant
        t = plant.state.time
        if abs(current_time - t) > TIME_TOLERANCE * max(1.0, abs(t)):
            self.log(f"AbuBall '{self.instance_name}': do_step at t = {current_time!r} s but the "
                     f"FMU is at t = {t!r} s (restore a state first)", Fmi2Status.error)
            return False
        for name in _INPUTS:
            value = getattr(self, name)
            if not math.isfinite(value):
                self.log(f"AbuBall '{self.instance_name}': input '{name}' = {value!r} at "
                         f"t = {current_time!r} s is not finite", Fmi2Status.error)
                return False
        saved = plant.get_state()
        plant.state.time = current_time  # follow the master's clock through rounding
        try:
            switches = plant.advance(step_size, self.torque, self.torque_rate, self.torque_accel,
                                     self.torque_jerk, self.torque_snap)
        except Exception as exc:  # noqa: BLE001 - an exception here would be fmi2Fatal
            plant.set_state(saved)  # fmi2Discard: nothing advanced
            self.log(f"AbuBall '{self.instance_name}': step [{current_time!r}, "
                     f"{current_time + step_size!r}] s failed: {type(exc).__name__}: {exc}",
                     Fmi2Status.error)
            return False
        self.step_switches = len(switches)
        self.t_first_step_switch = switches[0].time if switches else NO_SWITCH
        self.step_peak = plant.step_peak
        self._cache = None
        return True

    # ----------------------------------------------------------------- FMU state
    def _get_fmu_state(self):
        state = {name: getattr(self, name) for name in _PARAMETERS + _INPUTS}
        state.update(start_time=self.start_time, step_switches=self.step_switches,
                     t_first_step_switch=self.t_first_step_switch, step_peak=self.step_peak,
                     plant=None if self._plant is None else self._plant.state.as_tuple())
        return state

    @staticmethod
    def _validate_fmu_state(state, before_initialization: bool) -> dict:
        """A checked copy of a saved state (ValueError if anything is missing or malformed)."""
        checked = check_record(state, _STATE_KINDS, "AbuBall state")
        plant = state.get("plant")
        if plant is None:
            if not before_initialization:
                raise ValueError("AbuBall state: an initialized instance needs its 'plant' state")
        else:
            if not isinstance(plant, (list, tuple)) or len(plant) != len(STATE_FIELDS):
                raise ValueError(f"AbuBall state: 'plant' must hold {len(STATE_FIELDS)} numbers")
            values = check_record(dict(zip(STATE_FIELDS, plant)), _PLANT_KINDS,
                                  "AbuBall plant state")
            if values["mode"] not in (Mode.SLIP_NEG, Mode.STICK, Mode.SLIP_POS):
                raise ValueError(f"AbuBall plant state: mode = {values['mode']} is not -1, 0 or 1")
            if values["switch_count"] < 0 or values["t_last_switch"] == math.inf:
                raise ValueError("AbuBall plant state: bad switch bookkeeping")
            PlantParams(BallParams(checked["m"], checked["d"], checked["l"], checked["mu"],
                                   None if checked["mu_d"] < 0.0 else checked["mu_d"]),
                        checked["J_abu"], checked["tau_motor"], checked["ball_reaction"])
            checked["plant"] = tuple(values[name] for name in STATE_FIELDS)
        if plant is None:
            checked["plant"] = None
        return checked

    def _set_fmu_state(self, state):
        for name in _PARAMETERS + _INPUTS:
            setattr(self, name, state[name])
        self.start_time = float(state["start_time"])
        self.step_switches = int(state["step_switches"])
        self.t_first_step_switch = float(state["t_first_step_switch"])
        self.step_peak = float(state["step_peak"])
        self._cache = None
        if state["plant"] is None:
            self._plant = None
            return
        if self._plant is None or self._plant.params != self._plant_params():
            self._plant = self._new_plant()
        self._plant.set_state(PlantState(*state["plant"]))
