"""Error-controlled co-simulation against the monolithic SciPy reference (an independent
solver of the same closed loop, no FMI), and the two ways the bounds used to overclaim.

Family of the property test (printed with ``pytest -s``): mu in [1e-3, 3e-2]; |omega0| from
0.7 to 0.99 or 1.01 to 1.6 times the speed at which the first setpoint step makes the ball
slip (so about a third of the cases slip at the first step); 1 to 6 steps of 1 Hz up or down; te in
[0.3, 1.5] s; every rounding and both theta_ref readings; the end time either on a setpoint
step (not the first) or 0.5 s after the staircase.
"""
from __future__ import annotations

import json
import math

import pytest
from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import strategies as st

from abu_model.params import BallParams, PlantParams
from abu_model.reference import simulate_staircase_reference
from harness.cli import main
from harness.experiments import StaircaseExperiment, run_staircase

HZ = 2.0 * math.pi
REPORT = dict(omega0=-17 * HZ, omega_end=-22 * HZ, t0=0.0, te=1.0)
WORST: dict[str, float] = {"mu_rel": 0.0, "t_slip_s": 0.0, "switch_s": 0.0, "cases": 0,
                           "first_step_slips": 0, "end_on_step": 0, "steps": 0}


@pytest.fixture(scope="module", autouse=True)
def _print_family_figures():
    """Prints the worst differences of the property test (run with -s) after the module."""
    yield
    if WORST["cases"]:
        print(f"\n[accuracy] {WORST['cases']} random staircases at the default tolerance "
              f"({WORST['first_step_slips']} first-step slips, {WORST['end_on_step']} ending on "
              f"a step): bounds within {WORST['mu_rel']:.1e} relative, slip instants within "
              f"{WORST['t_slip_s']:.1e} s, every switch within {WORST['switch_s']:.1e} s of the "
              f"reference; at most {WORST['steps']} communication steps")


def _reference(exp: StaircaseExperiment):
    return simulate_staircase_reference(exp.plant, exp.controller, exp.staircase, exp.t_end,
                                        t_start=exp.t_start, beta0=exp.beta0)


def _rel(a: float, b: float) -> float:
    return abs(a / b - 1.0)


@settings(max_examples=30, deadline=None, derandomize=True,
          phases=(Phase.explicit, Phase.generate),
          suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
# margin within 1 % of 1 is left out: there a first-step slip can last only some 10 us, and
# the plant's slip integration (abu_model.plant, not the master) can step over the whole
# excursion of beta' when its first Runge-Kutta step spans it, missing the re-stick (e.g.
# mu = 4.0537e-3, margin = 0.99999, thesis, trail, 6 steps, te = 0.5411 s: the reference and a
# 0.1 ms fixed step re-stick after 34 us, a 1 ms step does not). Reported to the plant's owner.
@given(mu=st.floats(1e-3, 3e-2), margin=st.one_of(st.floats(0.7, 0.99), st.floats(1.01, 1.6)),
       n_steps=st.integers(1, 6),
       te=st.floats(0.3, 1.5), rounding=st.sampled_from(["lead", "nearest", "trail"]),
       mode=st.sampled_from(["integral", "thesis"]), sign=st.sampled_from([-1.0, 1.0]),
       end_step=st.sampled_from([None, 0, 1, 2, 3]))
def test_default_tolerance_matches_reference_on_random_staircases(
        fmu_dir, mu, margin, n_steps, te, rounding, mode, sign, end_step):
    plant = PlantParams(BallParams(mu=mu))
    probe = StaircaseExperiment(plant, sign, sign * (1 + n_steps * HZ), te=te, rounding=rounding)
    t1 = probe.staircase.step_times[0]
    jump = 2 * 0.5 * 2.2 * HZ + (2.2**2 * t1 * HZ if mode == "thesis" else 0.0)
    w0 = sign * margin * math.sqrt(plant.ball.lever_ratio * jump / mu)
    steps = StaircaseExperiment(plant, w0, w0 + sign * n_steps * HZ, te=te,
                                rounding=rounding).staircase.step_times
    # end on a setpoint step after the first (the first would leave no stick period at all)
    t_end = (None if end_step is None or len(steps) < 2
             else steps[1 + end_step % (len(steps) - 1)])
    exp = StaircaseExperiment(plant, w0, w0 + sign * n_steps * HZ, te=te, rounding=rounding,
                              theta_ref_mode=mode, t_end=t_end)
    s = run_staircase(exp, fmu_dir).summary
    ref = _reference(exp)
    WORST["cases"] += 1
    WORST["steps"] = max(WORST["steps"], s["cosim"]["steps"])
    WORST["end_on_step"] += bool(s["end_on_setpoint_step"])
    if ref.mu_low is None:
        WORST["first_step_slips"] += 1
        assert s["mu_low"] is None and "no lower bound" in s["message"]
    else:
        assert s["mu_low"] is not None
        WORST["mu_rel"] = max(WORST["mu_rel"], _rel(s["mu_low"], ref.mu_low))
        assert s["mu_low"] == pytest.approx(ref.mu_low, rel=1e-6)
        assert s["mu_low"] <= mu * (1 + 1e-9)  # never above the true mu
    if ref.t_slip is None:
        assert s["t_slip"] is None and s["mu_high"] is None
        if s["end_on_setpoint_step"]:
            assert "never slips" not in s["message"] and "open" in s["message"]
        return
    assert abs(s["t_slip"] - ref.t_slip) <= 1e-9
    WORST["t_slip_s"] = max(WORST["t_slip_s"], abs(s["t_slip"] - ref.t_slip))
    assert s["mu_high"] == pytest.approx(ref.mu_high, rel=1e-6)
    WORST["mu_rel"] = max(WORST["mu_rel"], _rel(s["mu_high"], ref.mu_high))
    assert mu <= s["mu_high"] * (1 + 1e-9)
    # Every switch of the reference, in order and direction; the ones inside a step (a slip
    # ending) are located by the plant from coupled inputs, to the coupling's accuracy.
    assert [(w["from_mode"], w["to_mode"]) for w in s["switches"]] == \
        [(w.from_mode, w.to_mode) for w in ref.switches]
    for ours, theirs in zip(s["switches"], ref.switches):
        WORST["switch_s"] = max(WORST["switch_s"], abs(ours["time_s"] - theirs.time))
        assert ours["time_s"] == pytest.approx(theirs.time, abs=1e-5)


def test_tighter_tolerance_gives_smaller_errors(fmu_dir):
    for mode in ("integral", "thesis"):
        errors, steps = [], []
        for tol in (1e-3, 1e-4, 1e-5, 1e-6):
            exp = StaircaseExperiment(PlantParams(), theta_ref_mode=mode, tol=tol, **REPORT)
            s = run_staircase(exp, fmu_dir).summary
            ref = _reference(exp)
            errors.append(max(_rel(s["mu_low"], ref.mu_low), _rel(s["mu_high"], ref.mu_high)))
            steps.append(s["cosim"]["steps"])
            assert s["t_slip"] == pytest.approx(ref.t_slip, abs=1e-9)
        print(f"\n[tolerance] {mode}: tol 1e-3 .. 1e-6 -> bound errors "
              f"{', '.join(f'{e:.1e}' for e in errors)}, steps {steps}")
        assert all(b < a for a, b in zip(errors[1:], errors[2:])), errors
        assert errors[-1] < errors[1] / 20 and errors[-1] <= 1e-7
        assert steps == sorted(steps)


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
