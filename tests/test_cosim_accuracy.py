"""Error-controlled co-simulation against the monolithic SciPy reference (an independent
solver of the same closed loop, no FMI), and the two ways the bounds used to overclaim.

Family of the property test (tests/staircase_family.py; printed with ``pytest -s``): mu in [1e-3, 6e-2]; |omega0| from
0.7 to 1.6 (also 1 - 1e-2 to 1 - 1e-6) times the speed at which the first setpoint step
makes the ball slip (so about a third of the cases slip at the first step); 1 to 40 steps
of 1 Hz up or down in te from 0.02 to 1.5 s (setpoint steps down to a few 0.1 ms apart);
t0 from 0 to 0.5 s; every
rounding and both theta_ref readings; no motor lag or tau_motor 2 ms or 10 ms; the end time
either on a setpoint step (not the first) or 0.5 s after the staircase. Targets at the
default tolerance (issue 8): both bounds within 1e-6 relative and every switch time (slips
at setpoint steps, slip ends, continuous slip onsets) within 1e-9 s of the reference.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, Phase, example, given, settings
from hypothesis import strategies as st

from abu_model.errors import ParameterError
from abu_model.params import BallParams, PlantParams
from abu_model.reference import simulate_staircase_reference
from abu.cli.main import main
from harness.experiments.staircase import StaircaseExperiment, run_staircase
from staircase_family import family_experiment

HZ = 2.0 * math.pi
REPORT = dict(omega0=-17 * HZ, omega_end=-22 * HZ, t0=0.0, te=1.0)
WORST: dict[str, float] = {"mu_rel": 0.0, "t_slip_s": 0.0, "switch_s": 0.0, "cases": 0,
                           "first_step_slips": 0, "end_on_step": 0, "steps": 0,
                           "inner_slips": 0, "slips": 0, "switches": 0, "mu_rel_lag": 0.0}


@pytest.fixture(scope="module", autouse=True)
def _print_family_figures():
    """Prints the worst differences of the property test (run with -s) after the module."""
    yield
    if WORST["cases"]:
        print(f"\n[accuracy] {WORST['cases']} random staircases at the default tolerance "
              f"({WORST['slips']} slip, {WORST['first_step_slips']} at the first step, "
              f"{WORST['inner_slips']} from a continuous acceleration; {WORST['end_on_step']} "
              f"ending on a step; {WORST['switches']} switches): bounds within "
              f"{WORST['mu_rel']:.1e} relative (mu_low where mu_req can peak between steps, "
              f"with a motor lag or falling |omega|: {WORST['mu_rel_lag']:.1e}; target 1e-6), "
              f"slip instants at setpoint steps within {WORST['t_slip_s']:.1e} s, every switch "
              f"within {WORST['switch_s']:.1e} s of the reference (target 1e-9 s); at most "
              f"{WORST['steps']} communication steps")


def _reference(exp: StaircaseExperiment):
    return simulate_staircase_reference(exp.plant, exp.controller, exp.staircase, exp.t_end,
                                        t_start=exp.t_start, beta0=exp.beta0)


def _rel(a: float, b: float) -> float:
    return abs(a / b - 1.0)


@settings(max_examples=200, deadline=None, derandomize=True,
          phases=(Phase.explicit, Phase.generate),
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
# margins near 1 included (0.7..1.6 and 1 - 1e-2..1e-6): there a first-step slip can last
# only some 10 us, which the plant used to step over (fixed in abu_model.numerics; e.g.
# mu = 4.0537e-3, margin = 0.99999, thesis, trail, 6 steps, te = 0.5411 s re-sticks after 34 us).
@example(mu=0.01501511335634862, margin=None, n_steps=29, te=0.25927026670707437,
         rounding="lead", mode="integral", sign=-1.0, end_step=None, t0=0.234, tau_motor=0.0,
         w0_hz=-18.0, t_end=0.41, k=0, up=True)  # a slip at a setpoint step that ended inside the step
@given(mu=st.floats(1e-3, 6e-2),
       margin=st.one_of(st.floats(0.7, 1.6), st.floats(2.0, 6.0).map(lambda e: 1 - 10**-e)),
       n_steps=st.integers(1, 40), te=st.floats(0.02, 1.5),
       rounding=st.sampled_from(["lead", "nearest", "trail"]),
       mode=st.sampled_from(["integral", "thesis"]), sign=st.sampled_from([-1.0, 1.0]),
       end_step=st.sampled_from([None, 0, 1, 2, 3]), t0=st.floats(0.0, 0.5),
       tau_motor=st.sampled_from([0.0, 0.002, 0.01]), w0_hz=st.just(None), t_end=st.just(None),
       k=st.integers(0, 39), up=st.booleans())
def test_default_tolerance_matches_reference_on_random_staircases(
        fmu_dir, mu, margin, n_steps, te, rounding, mode, sign, end_step, t0, tau_motor, w0_hz,
        t_end, k, up):
    if w0_hz is None:
        exp = family_experiment(mu=mu, margin=margin, n_steps=n_steps, te=te, rounding=rounding,
                                mode=mode, sign=sign, end_step=end_step, t0=t0,
                                tau_motor=tau_motor, k=k, up=up)
    else:  # an explicit example: the staircase as given
        plant = PlantParams(BallParams(mu=mu), tau_motor=tau_motor)
        w0, direction = w0_hz * HZ, (sign if up else -sign)
        exp = StaircaseExperiment(plant, w0, w0 + direction * n_steps * HZ, t0=t0, te=te,
                                  rounding=rounding, theta_ref_mode=mode, t_end=t_end)
    res = run_staircase(exp, fmu_dir)
    s = res.summary
    ref = _reference(exp)
    WORST["cases"] += 1
    WORST["steps"] = max(WORST["steps"], s["cosim"]["steps"])
    WORST["end_on_step"] += bool(s["end_on_setpoint_step"])
    if ref.mu_low is None:
        WORST["first_step_slips"] += 1
        assert s["mu_low"] is None and "no lower bound" in s["message"]
    else:
        assert s["mu_low"] is not None
        # mu_req can peak between setpoint steps (a motor lag, or |omega| falling faster than
        # |alpha|): both solvers locate that maximum (the plant's mu_req_peak, the
        # reference's event on d(mu_req)/dt = 0), not a maximum over their own points.
        key = "mu_rel_lag" if tau_motor > 0.0 or not up else "mu_rel"
        WORST[key] = max(WORST[key], _rel(s["mu_low"], ref.mu_low))
        assert s["mu_low"] == pytest.approx(ref.mu_low, rel=1e-6)
        assert s["mu_low"] <= mu * (1 + 1e-9)  # never above the true mu
    if ref.t_slip is None:
        assert s["t_slip"] is None and s["mu_high"] is None
        if s["end_on_setpoint_step"]:
            assert "never slips" not in s["message"] and "open" in s["message"]
        return
    on_step = min(abs(np.asarray(exp.staircase.step_times) - ref.t_slip)) <= 1e-12
    if on_step:  # a slip at a setpoint step: the master lands on the step exactly
        assert abs(s["t_slip"] - ref.t_slip) <= 1e-9
        WORST["t_slip_s"] = max(WORST["t_slip_s"], abs(s["t_slip"] - ref.t_slip))
    else:  # from a continuous acceleration (motor lag): located inside a step, see below
        WORST["inner_slips"] += 1
        assert s["t_slip"] == pytest.approx(ref.t_slip, abs=1e-9)
    assert s["mu_high"] == pytest.approx(ref.mu_high, rel=1e-6)
    WORST["mu_rel"] = max(WORST["mu_rel"], _rel(s["mu_high"], ref.mu_high))
    assert mu <= s["mu_high"] * (1 + 1e-9)
    # Every switch of the reference, in order and direction, within 1e-9 s; the ones inside
    # a step (slip ends, continuous onsets) are located by the plant from the coupled
    # inputs, so this is the coupling's accuracy over the whole run.
    assert [(w["from_mode"], w["to_mode"]) for w in s["switches"]] == \
        [(w.from_mode, w.to_mode) for w in ref.switches]
    WORST["slips"] += 1
    WORST["switches"] += len(ref.switches)
    for ours, theirs in zip(s["switches"], ref.switches):
        WORST["switch_s"] = max(WORST["switch_s"], abs(ours["time_s"] - theirs.time))
        assert ours["time_s"] == pytest.approx(theirs.time, abs=1e-9)


def test_tighter_tolerance_gives_smaller_errors(fmu_dir):
    for mode in ("integral", "thesis"):
        errors, steps = [], []
        # (a fourth-order hold: above 1e-6 the largest step, 0.05 s, decides alone)
        for tol in (1e-7, 1e-8, 1e-9, 1e-10):
            exp = StaircaseExperiment(PlantParams(), theta_ref_mode=mode, tol=tol, **REPORT)
            s = run_staircase(exp, fmu_dir).summary
            ref = _reference(exp)
            errors.append(max(_rel(s["mu_low"], ref.mu_low), _rel(s["mu_high"], ref.mu_high)))
            steps.append(s["cosim"]["steps"])
            assert s["t_slip"] == pytest.approx(ref.t_slip, abs=1e-9)
        print(f"\n[tolerance] {mode}: tol 1e-7 .. 1e-10 -> bound errors "
              f"{', '.join(f'{e:.1e}' for e in errors)}, steps {steps}")
        assert all(b < a for a, b in zip(errors, errors[1:])), errors
        assert errors[-1] < errors[1] / 20 and errors[-1] <= 1e-7
        assert steps == sorted(steps)


def test_lower_order_holds_still_work_and_the_order_pays(fmu_dir):
    """Holds of order 1-4 (the plant's higher torque inputs left at their default 0 when not
    connected): every order matches the reference; at one tolerance each order takes fewer
    steps than the one below (measured: 258, 72, 37 for orders 2, 3, 4 at tol 1e-6)."""
    steps = {}
    for order, tol in ((1, 1e-5), (2, 1e-6), (3, 1e-6), (4, 1e-6)):
        exp = StaircaseExperiment(PlantParams(), hold_order=order, tol=tol, **REPORT)
        system = exp.system(fmu_dir)
        assert [len(h.derivatives) for h in system.holds] == [order, order]
        assert sum(c.dst.startswith("plant.torque") for c in system.connections) == order + 1
        s = run_staircase(exp, fmu_dir).summary
        ref = _reference(exp)
        assert s["experiment"]["hold_order"] == order
        assert s["mu_low"] == pytest.approx(ref.mu_low, rel=1e-5)
        assert s["mu_high"] == pytest.approx(ref.mu_high, rel=1e-5)
        assert s["t_slip"] == pytest.approx(ref.t_slip, abs=1e-12)
        steps[order] = s["cosim"]["steps"]
    assert steps[2] > 3 * steps[3] and steps[3] > steps[4], steps
    for bad in (5, 0, 2.0, True, "2"):
        with pytest.raises(ParameterError, match="hold_order"):
            StaircaseExperiment(PlantParams(), hold_order=bad, **REPORT)


def test_fixed_step_mode_stays_available(fmu_dir):
    exp = StaircaseExperiment(PlantParams(), comm_step=2e-3, **REPORT)
    res = run_staircase(exp, fmu_dir)
    stats = res.summary["cosim"]
    assert stats["rejected"] == 0 and res.summary["experiment"]["tol"] is None
    # Ordinary points on the grid start + k h (events and switches add their own).
    t = res.table["time"][res.table["side"] == 0]
    k = (t - exp.t_start) / 2e-3
    assert max(abs(k - k.round())) < 1e-6 and stats["steps"] >= 770


def _simulate_json(fmu_dir, capsys, *args: str) -> dict:
    status = main(["simulate", *args, "--fmu-dir", str(fmu_dir["AbuBall"].parent), "--json"])
    out = capsys.readouterr().out
    assert status == 0
    return json.loads(out)


def test_first_step_slip_has_no_lower_bound(fmu_dir, capsys):
    s = _simulate_json(fmu_dir, capsys, "--mu", "0.00275", "--omega0-hz", "-10",
                       "--omega-end-hz", "-15", "--t0", "0.7", "--theta-ref", "thesis")
    assert s["mu_low"] is None and s["t_slip"] == pytest.approx(0.7, abs=1e-12)
    assert "no lower bound" in s["message"] and "higher |omega0|" in s["message"]
    assert s["mu_high"] > 0.00275 and s["brackets_mu"]


def test_end_on_a_setpoint_step_claims_nothing_about_that_step(fmu_dir, capsys):
    common = ("--mu", "0.0015", "--omega0-hz", "-17", "--omega-end-hz", "-19",
              "--rounding", "trail")
    s = _simulate_json(fmu_dir, capsys, *common, "--t-end", "1.0")
    assert s["end_on_setpoint_step"] and s["t_slip"] is None
    assert "never slips" not in s["message"] and "open" in s["message"]
    assert s["mu_low"] <= 0.0015  # before: 0.001656, the step's right-hand limit
    longer = _simulate_json(fmu_dir, capsys, *common, "--t-end", "1.2")
    assert longer["t_slip"] == pytest.approx(1.0, abs=1e-9)
    assert longer["mu_low"] == pytest.approx(0.001148, rel=1e-3)
    assert longer["mu_high"] == pytest.approx(0.001656, rel=1e-3)
    assert s["mu_low"] == pytest.approx(longer["mu_low"], rel=1e-6)
