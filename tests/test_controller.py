"""Staircase reference (exact step times) and the identified PI loop against python-control."""
import math

import control
import numpy as np
import pytest

from abu_model.errors import ParameterError
from abu_model.params import BallParams, PlantParams
from abu_model.plant import AbuPlant
from controller.closed_loop import acceleration_transfer_function, speed_transfer_function
from controller.pi import PISpeedController
from controller.reference import Staircase, inclined_sine

HZ = 2 * math.pi


@pytest.mark.parametrize("rounding, offset", [("lead", 1.0), ("nearest", 0.5), ("trail", 0.0)])
def test_step_k_happens_exactly_when_the_sine_reaches_its_level(rounding, offset):
    w0, we, t0, te = -17 * HZ, -22 * HZ, 0.3, 1.0
    st = Staircase(w0, we, t0, te, rounding=rounding)
    assert st.n_steps == 5
    assert st.levels[0] == w0 and st.levels[-1] == pytest.approx(we, rel=1e-15)
    for k, t_k in enumerate(st.step_times, start=1):
        target = w0 - (k - offset) * HZ
        assert inclined_sine(t_k, w0, we, t0, te) == pytest.approx(target, abs=1e-9)
        assert st.value(t_k) == st.levels[k]  # right-continuous
        assert st.value(np.nextafter(t_k, -1.0)) == st.levels[k - 1]
    if rounding == "lead":
        assert st.step_times[0] == t0  # "the first step starts at t0"
    if rounding == "trail":
        assert st.step_times[-1] == pytest.approx(t0 + te, abs=1e-12)


def test_staircase_of_the_report_figure_4_3_is_symmetric():
    st = Staircase(-10 * HZ, -15 * HZ, 0.0, 1.0, rounding="nearest")
    # the inclined sine is point-symmetric about t = te/2, so are nearest-rounded steps
    times = np.array(st.step_times)
    assert times + times[::-1] == pytest.approx(np.ones(5), abs=1e-12)
    assert st.step_times[2] == pytest.approx(0.5, abs=1e-12)


def test_next_event_time_and_values():
    st = Staircase(-9 * HZ, -19 * HZ, 0.0, 0.5)
    assert st.next_event_time(-1.0) == 0.0
    assert st.next_event_time(0.0) == st.step_times[1]
    assert st.next_event_time(1.0) == math.inf
    t = np.array([-1.0, 0.0, st.step_times[3], 2.0])
    assert list(st.values(t)) == [st.value(x) for x in t]


@pytest.mark.parametrize("kwargs, name", [
    ({"te": 0.0}, "te"), ({"te": -1.0}, "te"), ({"omega_end": -17.5 * HZ}, "omega_end"),
    ({"step": 0.0}, "step"), ({"rounding": "up"}, "rounding"), ({"t0": float("nan")}, "t0"),
])
def test_bad_staircase_names_the_parameter(kwargs, name):
    args = dict(omega0=-17 * HZ, omega_end=-22 * HZ, t0=0.0, te=1.0)
    args.update(kwargs)
    with pytest.raises(ParameterError) as info:
        Staircase(**args)
    assert info.value.parameter == name


def test_pi_gains_and_bad_parameters():
    c = PISpeedController(J_abu=2e-5)
    assert c.Kp == pytest.approx(2 * 0.5 * 2.2 * 2e-5)
    assert c.Ki == pytest.approx(2.2**2 * 2e-5)
    for kwargs, name in [({"zeta": -1}, "zeta"), ({"omega_n": float("inf")}, "omega_n"),
                         ({"theta_ref_mode": "x"}, "theta_ref_mode")]:
        with pytest.raises(ParameterError) as info:
            PISpeedController(**kwargs)
        assert info.value.parameter == name


def test_acceleration_jump_matches_initial_value_of_python_control_step_response():
    c = PISpeedController()
    resp = control.step_response(acceleration_transfer_function(c), T=np.linspace(0, 1e-6, 3))
    assert resp.outputs[0] == pytest.approx(c.acceleration_jump(1.0), rel=1e-6)
    thesis = PISpeedController(theta_ref_mode="thesis")
    assert thesis.acceleration_jump(HZ, 0.4) == pytest.approx(HZ * (2.2 + 2.2**2 * 0.4))


def test_pi_on_stuck_rotor_follows_python_control_closed_loop():
    """Plant + PI stepped with first-order hold vs python-control's response of eq. 4.5."""
    params = PlantParams(ball=BallParams(mu=0.5))  # large mu: the ball never slips
    ctrl = PISpeedController(J_abu=params.J_abu)
    w0, dw = -100.0, -HZ
    plant = AbuPlant(params, omega0=w0)
    h, x_i, t = 1e-3, 0.0, 0.0
    times, omegas = [0.0], [w0]
    for _ in range(2000):
        s = plant.state
        T = ctrl.torque(t, w0 + dw, s.omega, s.theta, x_i)
        alpha = plant.outputs(T).alpha
        Td = ctrl.torque_rate(w0 + dw, s.omega, alpha)
        x_i += ctrl.integral_increment(h, w0 + dw, s.omega, alpha)
        plant.advance(h, T, Td)
        t += h
        times.append(t), omegas.append(plant.state.omega)
    resp = control.step_response(speed_transfer_function(ctrl), T=np.array(times))
    expected = w0 + dw * resp.outputs
    assert np.max(np.abs(np.array(omegas) - expected)) < 1e-5 * abs(dw)
