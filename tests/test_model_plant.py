"""The stepped plant: exact switch location, re-stick, state restore, lag and ball-reaction options."""
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq

from abu_model.params import BallParams, PlantParams
from abu_model.plant import AbuPlant, Mode
from abu_model.reference import _simulate, simulate_ramp_reference

HZ = 2 * math.pi


def ramp_root(ball, omega0, jerk):
    """First root of (l - d/5) K t = mu l (|w0| + K t^2/2)^2 (closed-form ramp motion)."""
    f = lambda t: (ball.l - ball.d / 5) * jerk * t - ball.mu * ball.l * (abs(omega0) + 0.5 * jerk * t * t) ** 2
    grid = np.linspace(0.0, 20.0, 200001)
    i = int(np.nonzero(f(grid) > 0)[0][0])
    return brentq(f, grid[i - 1], grid[i], xtol=1e-15)


def run_ramp(plant_params, omega0, jerk, t_end, h, stop_after=None):
    plant = AbuPlant(plant_params, omega0=omega0)
    gain = plant_params.J_total * jerk * math.copysign(1, omega0)
    switches, beta_dot_stick = [], []
    n = int(round(t_end / h))
    for i in range(n):
        t = i * h
        switches += plant.advance(h, gain * t, gain)
        if plant.state.mode == Mode.STICK:
            beta_dot_stick.append(plant.state.beta_dot)
        if stop_after and len(switches) >= stop_after and t > switches[-1].time + 0.2:
            break
    return plant, switches, beta_dot_stick


@pytest.mark.parametrize("mu, jerk", [(2.75e-3, 200.0), (1e-2, 2000.0), (3e-2, 20000.0)])
def test_ramp_slip_time_is_the_closed_form_root_and_ball_sticks_again(mu, jerk):
    params = PlantParams(ball=BallParams(mu=mu))
    omega0 = -20 * HZ
    t_root = ramp_root(params.ball, omega0, jerk)
    plant, switches, beta_dot_stick = run_ramp(params, omega0, jerk, 10.0, 1e-3, stop_after=2)
    assert switches[0].from_mode == Mode.STICK and switches[0].to_mode == Mode.SLIP_POS
    assert abs(switches[0].time - t_root) < 1e-9
    # one slip episode: stick -> slip -> stick, no chattering, beta' exactly 0 in stick
    assert [(s.from_mode, s.to_mode) for s in switches] == [(0, 1), (1, 0)]
    assert all(v == 0.0 for v in beta_dot_stick)
    assert plant.state.beta > 0  # accelerating clockwise makes beta grow (report sec. 4.1)


def test_plant_agrees_with_monolithic_reference_on_ramp():
    params = PlantParams(ball=BallParams(mu=5e-3))
    plant, switches, _ = run_ramp(params, -15 * HZ, 500.0, 2.0, 1e-3)
    ref = simulate_ramp_reference(params, -15 * HZ, 500.0, 2.0)
    assert len(ref.switches) == len(switches) == 2
    for a, b in zip(switches, ref.switches):
        assert a.time == pytest.approx(b.time, abs=1e-8)
    assert plant.state.beta == pytest.approx(ref.beta[-1], rel=1e-7)


def test_stick_step_is_exact_polynomial_motion():
    params = PlantParams()
    plant = AbuPlant(params, omega0=-100.0, theta0=1.0)
    T0, Td, h = 1e-4, -2e-3, 0.05
    plant.advance(h, T0, Td)
    J = params.J_total
    assert plant.state.omega == pytest.approx(-100.0 + (T0 * h + Td * h * h / 2) / J, rel=1e-14)
    assert plant.state.theta == pytest.approx(1.0 - 100.0 * h + (T0 * h * h / 2 + Td * h**3 / 6) / J, rel=1e-13)
    assert plant.state.mode == Mode.STICK


def test_restore_state_and_continue_is_bit_identical():
    params = PlantParams(ball=BallParams(mu=3e-3), tau_motor=0.0)
    plant, _, _ = run_ramp(params, -20 * HZ, 300.0, 0.2, 1e-3)
    saved = plant.get_state()
    gain = params.J_total * 300.0 * -1

    def continue_run():
        out = []
        for i in range(400):
            t = 0.2 + i * 1e-3
            plant.advance(1e-3, gain * t, gain)
            s = plant.state
            out.append((s.theta, s.omega, s.beta, s.beta_dot, s.mode, s.switch_count, s.t_last_switch))
        return out

    first = continue_run()
    assert first[-1][5] >= 1  # the continuation crosses at least one switch
    plant.set_state(saved)
    assert continue_run() == first


def test_motor_lag_zero_is_the_report_model_and_lag_delays_the_torque():
    base = PlantParams(ball=BallParams(mu=3e-3))
    # tau_motor = 0: applied torque follows the command at once
    plant = AbuPlant(base, omega0=-100.0)
    plant.advance(1e-3, 2e-3, 0.0)
    assert plant.outputs(2e-3).alpha == pytest.approx(2e-3 / base.J_abu, rel=1e-14)
    # tau_motor > 0: first-order lag, applied torque = T (1 - exp(-t/tau)) after a step
    lagged = PlantParams(ball=BallParams(mu=3e-3), tau_motor=0.01)
    plant = AbuPlant(lagged, omega0=-100.0)
    assert plant.outputs(2e-3).alpha == 0.0  # no jump of alpha at the torque step
    plant.advance(0.01, 2e-3, 0.0)
    assert plant.state.torque_applied == pytest.approx(2e-3 * (1 - math.exp(-1)), rel=1e-12)
    expected_omega = -100.0 + 2e-3 / lagged.J_abu * (0.01 - 0.01 * (1 - math.exp(-1)))
    assert plant.state.omega == pytest.approx(expected_omega, rel=1e-12)


def test_lagged_ramp_slip_is_located_on_the_lagged_trajectory():
    params = PlantParams(ball=BallParams(mu=2.75e-3), tau_motor=0.02)
    b, J, K, w0 = params.ball, params.J_total, 200.0, -20 * HZ
    plant, switches, _ = run_ramp(params, w0, K, 0.6, 1e-3)
    # commanded T = -J K t through the lag: applied = -J K (t - tau (1 - e^{-t/tau}))
    tau = 0.02
    alpha = lambda t: -K * (t - tau * (1 - math.exp(-t / tau)))
    omega = lambda t: w0 - K * (t * t / 2 - tau * t + tau * tau * (1 - math.exp(-t / tau)))
    f = lambda t: b.lever_ratio * abs(alpha(t)) - b.mu * omega(t) ** 2
    root = brentq(f, 0.1, 0.5, xtol=1e-15)
    assert switches[0].time == pytest.approx(root, abs=1e-9)


def test_ball_reaction_slows_the_rotor_by_the_ball_inertia():
    off, on = PlantParams(), PlantParams(ball_reaction=True)
    a_off = AbuPlant(off, omega0=-100.0).outputs(1e-3).alpha
    a_on = AbuPlant(on, omega0=-100.0).outputs(1e-3).alpha
    b = on.ball
    assert a_off / a_on == pytest.approx(1 + (b.m * b.l**2 + b.J) / on.J_abu, rel=1e-14)
    assert 0 < 1 - a_on / a_off < 1e-3


def test_second_order_hold_stick_slip_time_is_the_closed_form_root():
    """T(t) = J a t^2/2 in one long step: alpha = a t^2/2, omega = w0 + a t^3/6 (stick)."""
    params = PlantParams(ball=BallParams(mu=2.75e-3))
    b, J, a, w0 = params.ball, params.J_total, -4000.0, -20 * HZ
    plant = AbuPlant(params, omega0=w0)
    switches = plant.advance(1.0, 0.0, 0.0, J * a)
    f = lambda t: b.lever_ratio * abs(a * t * t / 2) - b.mu * (w0 + a * t**3 / 6) ** 2
    grid = np.linspace(1e-6, 1.0, 100001)
    i = int(np.nonzero(f(grid) > 0)[0][0])
    root = brentq(f, grid[i - 1], grid[i], xtol=1e-15)
    assert switches[0].time == pytest.approx(root, abs=1e-12)
    assert switches[0].to_mode == Mode.SLIP_POS


@pytest.mark.parametrize("tau_motor, reaction", [(0.0, False), (0.005, False), (0.0, True)])
def test_second_order_hold_equals_the_same_quadratic_in_sub_steps(tau_motor, reaction):
    """One step with torque_accel = a equals 50 sub-steps fed with T, T' of the same quadratic
    (stick, the slip that follows and the re-stick go through all three integrators)."""
    params = PlantParams(ball=BallParams(mu=2e-3), tau_motor=tau_motor, ball_reaction=reaction)
    J = params.J_total
    T0, r, a, h = J * -40.0, J * -900.0, J * 6000.0, 0.2
    whole = AbuPlant(params, omega0=-15 * HZ)
    parts = AbuPlant(params, omega0=-15 * HZ)
    sw_whole = whole.advance(h, T0, r, a)
    sw_parts, n = [], 50
    for i in range(n):
        t = i * h / n
        sw_parts += parts.advance(h / n, T0 + r * t + a * t * t / 2, r + a * t, a)
    assert len(sw_whole) == len(sw_parts) >= 1
    for x, y in zip(sw_whole, sw_parts):
        assert (x.from_mode, x.to_mode) == (y.from_mode, y.to_mode)
        assert x.time == pytest.approx(y.time, abs=1e-11)
    for name in ("theta", "omega", "beta", "beta_dot", "torque_applied"):
        assert getattr(whole.state, name) == pytest.approx(getattr(parts.state, name),
                                                           rel=1e-9, abs=1e-12)


# -- short slips near the stick limit, stepped at coarse steps --------------------------------
class _FallingTorque:
    """Commanded torque T1 (1 - rate t) [N m] (one segment) for the monolithic reference."""

    def __init__(self, T1: float, rate: float):
        self.T1, self.rate = T1, rate

    def segment(self, t):
        return self

    def torque(self, t, y):
        return self.T1 * (1.0 - self.rate * t)

    def integral_rate(self, t, y):
        return 0.0


SHORT_SLIPS: dict = {"cases": 0, "shortest_s": math.inf, "worst_s": 0.0, "restuck": 0}


@pytest.fixture(scope="module", autouse=True)
def _print_short_slip_figures():
    yield
    if SHORT_SLIPS["cases"]:
        print(f"\n[plant] {SHORT_SLIPS['cases']} slips at a torque step beyond the stick limit "
              f"(margin 1 - 1e-2 .. 1 - 1e-6; mu 1e-3..3e-2; |omega0| 30..150 rad/s; torque "
              f"falling so the slip lasts {SHORT_SLIPS['shortest_s']:.1e} s .. one step) at "
              f"1, 20 and 50 ms steps: {SHORT_SLIPS['restuck']} re-stick inside a step, the same "
              f"switches as the SciPy reference, every switch within "
              f"{SHORT_SLIPS['worst_s']:.1e} s")


@settings(max_examples=200, deadline=None, derandomize=True)
@given(mu=st.floats(1e-3, 3e-2), omega0=st.floats(30.0, 150.0), sign=st.sampled_from([-1.0, 1.0]),
       torque_sign=st.sampled_from([-1.0, 1.0]), exponent=st.floats(2.0, 6.0),
       spread=st.floats(0.0, 1.0), h=st.sampled_from([1e-3, 20e-3, 50e-3]))
def test_short_slips_near_the_margin_are_not_stepped_over(mu, omega0, sign, torque_sign,
                                                          exponent, spread, h):
    """A torque step just beyond the stick limit (omega0 = margin x the slip speed) that then
    falls: the slip lasts from ~2 (1/margin - 1)/rate, down to microseconds, to about one
    step. The plant stepped at h must see the slip and the re-stick where the monolithic
    reference (SciPy DOP853 with events) does."""
    params = PlantParams(ball=BallParams(mu=mu))
    margin = 1.0 - 10.0 ** -exponent
    w0 = sign * omega0
    T1 = torque_sign * params.J_total * mu * w0 * w0 / (params.ball.lever_ratio * margin)
    excess = 1.0 / margin - 1.0
    lo, hi = 2.0 * excess / h, 0.5 / h  # slip of about one step .. torque halved at 2 h
    rate = lo * (hi / lo) ** spread
    t_end = 2.0 * h
    plant = AbuPlant(params, omega0=w0)
    switches = []
    for i in range(2):
        switches += plant.advance(h, T1 * (1.0 - rate * i * h), -T1 * rate)
    y0 = np.array([0.0, w0, 0.0, 0.0, 0.0, 0.0])
    ref = _simulate(params, _FallingTorque(T1, rate), [], 0.0, t_end, y0, 0.01)
    assert [(s.from_mode, s.to_mode) for s in switches] == \
        [(s.from_mode, s.to_mode) for s in ref.switches]
    assert switches[0].time == 0.0 and switches[0].from_mode == Mode.STICK
    for ours, theirs in zip(switches, ref.switches):
        assert abs(ours.time - theirs.time) <= 1e-9, (ours, theirs)
        SHORT_SLIPS["worst_s"] = max(SHORT_SLIPS["worst_s"], abs(ours.time - theirs.time))
    SHORT_SLIPS["cases"] += 1
    if len(switches) >= 2:
        SHORT_SLIPS["restuck"] += switches[1].time < h
        SHORT_SLIPS["shortest_s"] = min(SHORT_SLIPS["shortest_s"], switches[1].time)


# -- the largest mu_req between communication points (mu_low is a supremum) ------------------
def _ramp_peak(ball, omega0, jerk):
    """alpha = K t, omega = w0 + K t^2/2 (w0, K > 0): d(mu_req)/dt = 0 at t* = sqrt(2 w0/(3 K)),
    where mu_req = k K t* / (4 w0 / 3)^2 (closed form)."""
    t_star = math.sqrt(2.0 * omega0 / (3.0 * jerk))
    return t_star, ball.lever_ratio * jerk * t_star / (4.0 * omega0 / 3.0) ** 2


@pytest.mark.parametrize("h", [0.5, 0.07, 0.013])
def test_step_peak_is_the_closed_form_maximum_of_mu_req_inside_a_step(h):
    params = PlantParams(ball=BallParams(mu=0.03))
    w0, K = 100.0, 3000.0
    t_star, peak = _ramp_peak(params.ball, w0, K)
    plant = AbuPlant(params, omega0=w0)
    J, peaks, t = params.J_total, [], 0.0
    while t < 0.4:
        assert not plant.advance(h, J * K * t, J * K)  # stuck throughout
        peaks.append((t, plant.step_peak))
        t += h
    t_a, found = max(peaks, key=lambda p: p[1])
    assert found == pytest.approx(peak, rel=1e-13)
    assert t_a < t_star < t_a + h  # from the step that holds t*
    ends = [params.ball.lever_ratio * K * x / (w0 + K * x * x / 2) ** 2 for x in (t_a, t_a + h)]
    assert max(ends) < peak * (1 - 1e-6)  # the communication points alone miss it


def test_step_peak_with_a_motor_lag_matches_a_bounded_maximiser():
    """A torque step through the lag: alpha = (T/J)(1 - e^(-t/tm)) rises while omega grows,
    so mu_req peaks inside the first step (scipy's bounded maximiser on the closed form)."""
    from scipy.optimize import minimize_scalar

    params = PlantParams(ball=BallParams(mu=0.05), tau_motor=0.01)
    J, tm, w0, T = params.J_total, 0.01, 100.0, params.J_total * 400.0
    k = params.ball.lever_ratio

    def mu_req(t):
        alpha = T / J * -math.expm1(-t / tm)
        omega = w0 + T / J * (t + tm * math.expm1(-t / tm))
        return k * alpha / omega**2
    best = minimize_scalar(lambda t: -mu_req(t), bounds=(0.0, 0.2), method="bounded",
                           options={"xatol": 1e-12})
    plant = AbuPlant(params, omega0=w0)
    assert not plant.advance(0.2, T, 0.0)
    assert 0.0 < best.x < 0.2 and mu_req(0.2) < -best.fun * (1 - 1e-3)
    assert plant.step_peak == pytest.approx(-best.fun, rel=1e-12)


def test_step_peak_before_alpha_changes_sign_inside_the_step():
    """alpha = A (1 - u/u0) falls through 0 inside the step while |omega| shrinks faster:
    mu_req rises to a maximum before u0, drops to 0 there and rises again; the maximum
    before the zero of alpha is the step's peak (scipy's bounded maximiser on the closed
    form; a search over the whole step only, by the sign of d(mu_req)/dt at its ends, missed
    it by 23 %)."""
    from scipy.optimize import minimize_scalar

    params = PlantParams(ball=BallParams(mu=50.0))
    J, k = params.J_total, params.ball.lever_ratio
    w0, A, u0, h = -100.0, 4000.0, 0.025, 0.03

    def mu_req(u):
        return k * abs(A * (1.0 - u / u0)) / (w0 + A * (u - u * u / (2.0 * u0))) ** 2
    best = minimize_scalar(lambda u: -mu_req(u), bounds=(0.0, u0), method="bounded",
                           options={"xatol": 1e-12})
    assert max(mu_req(0.0), mu_req(h)) < -best.fun * (1 - 1e-2)
    plant = AbuPlant(params, omega0=w0)
    assert not plant.advance(h, J * A, -J * A / u0)  # stuck throughout
    assert plant.step_peak == pytest.approx(-best.fun, rel=1e-10)


@pytest.mark.parametrize("tau_motor", [0.0, 0.01])
def test_step_peak_at_rest_without_torque_is_zero_like_mu_req(tau_motor):
    """omega = 0, alpha = 0: the ball sticks and mu_req is 0 (dynamics.mu_required), so is
    the step's peak (it was inf, which an FMU state holding it could not restore)."""
    plant = AbuPlant(PlantParams(tau_motor=tau_motor), omega0=0.0)
    assert not plant.advance(0.01, 0.0, 0.0)
    assert plant.step_peak == 0.0 == plant.outputs(0.0).mu_req


def test_monolithic_reference_finds_the_same_peak_between_its_points():
    params = PlantParams(ball=BallParams(mu=0.03))
    w0, K = 100.0, 3000.0
    res = simulate_ramp_reference(params, w0, K, 0.4)
    assert res.t_slip is None
    assert res.mu_low == pytest.approx(_ramp_peak(params.ball, w0, K)[1], rel=1e-10)


# -- exact d^k(alpha)/dt^k for the controller's Taylor hold -----------------------------------
def test_alpha_derivatives_in_stick_are_the_closed_forms():
    d = [3e-3, -0.04, 0.9, -12.0]  # T, T', T'', T''' [N m/s^k]
    no_lag = AbuPlant(PlantParams(), omega0=-100.0)
    J = no_lag.params.J_total
    assert no_lag.alpha_derivatives(d, 3) == pytest.approx([x / J for x in d], rel=1e-15)
    tm, Ta = 0.004, 1e-3
    lag = AbuPlant(PlantParams(tau_motor=tm), omega0=-100.0, torque0=Ta)
    expected, value = [], Ta  # tm Ta' + Ta = T, differentiated: Ta^(k+1) = (T^(k) - Ta^(k))/tm
    for k in range(4):
        expected.append(value / J)
        value = (d[k] - value) / tm
    assert lag.alpha_derivatives(d, 3) == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("tau_motor, reaction", [(0.0, False), (0.004, False), (0.0, True),
                                                 (0.004, True)])
def test_alpha_derivatives_in_slip_match_the_integrated_trajectory(tau_motor, reaction):
    """Slip (beta' = 5 rad/s): d(alpha)/dt and d2(alpha)/dt2 against 5-point differences of
    alpha along the plant's own integrated trajectory."""
    params = PlantParams(ball=BallParams(mu=2e-3), tau_motor=tau_motor, ball_reaction=reaction)
    J = params.J_total
    d = [J * -40.0, J * -900.0, J * 6000.0, J * 1e4]

    def plant():
        return AbuPlant(params, omega0=-100.0, torque0=1e-3, beta_dot0=5.0, t0=-1.0)

    e0 = 1e-4
    derivs = plant().alpha_derivatives(d, 2)
    # alpha(tau) for tau in [0, 4 e0] from the state at tau = 0; one-sided 5-point formulas
    p0 = plant()
    values = []
    for i in range(5):
        p = plant()
        if i:
            p.advance(i * e0, *d)
        tau = i * e0
        T = sum(d[k] * tau**k / math.factorial(k) for k in range(4))
        values.append(p.outputs(T).alpha)
    v = values
    d1 = (-25 * v[0] + 48 * v[1] - 36 * v[2] + 16 * v[3] - 3 * v[4]) / (12 * e0)
    d2 = (35 * v[0] - 104 * v[1] + 114 * v[2] - 56 * v[3] + 11 * v[4]) / (12 * e0**2)
    assert p0.outputs(d[0]).alpha == pytest.approx(derivs[0], rel=1e-14)
    assert derivs[1] == pytest.approx(d1, rel=1e-6)
    assert derivs[2] == pytest.approx(d2, rel=1e-3)


@pytest.mark.parametrize("tau_motor, reaction", [(0.0, False), (0.004, True)])
def test_alpha_third_derivative_in_slip_is_the_rate_of_the_second(tau_motor, reaction):
    """d3(alpha)/dt3 (the FMU's crackle) in slip: the 5-point difference of the exact
    d2(alpha)/dt2 along the plant's own integrated trajectory, the torque's derivatives
    carried along the held Taylor polynomial."""
    params = PlantParams(ball=BallParams(mu=2e-3), tau_motor=tau_motor, ball_reaction=reaction)
    J = params.J_total
    d = [J * -40.0, J * -900.0, J * 6000.0, J * 1e4, J * -3e5]

    def plant():
        return AbuPlant(params, omega0=-100.0, torque0=1e-3, beta_dot0=5.0, t0=-1.0)

    def shifted(tau):  # T^(k)(tau) of the held polynomial
        return [sum(d[k + j] * tau**j / math.factorial(j) for j in range(len(d) - k))
                for k in range(len(d))]

    e0 = 1e-4
    third = plant().alpha_derivatives(d, 3)[3]
    v = []
    for i in range(5):
        p = plant()
        if i:
            p.advance(i * e0, *d)
        assert p.state.mode != 0  # still slipping
        v.append(p.alpha_derivatives(shifted(i * e0), 2)[2])
    rate = (-25 * v[0] + 48 * v[1] - 36 * v[2] + 16 * v[3] - 3 * v[4]) / (12 * e0)
    assert third == pytest.approx(rate, rel=1e-5)
