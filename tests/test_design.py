"""abu design: the planned staircase holds in co-simulation across the prior range of mu.

For three ranges (the report's [2.75e-3, 6 x 2.75e-3] with the report's loop, and two with
lagged drives) the design is co-simulated on the FMUs at 20 values of mu across the range: the
first step keeps the ball stuck, the slip falls inside the camera's record away from its ends,
the bounds bracket mu, and the slip time is where the closed-form predictor put it. The
predicted widths are printed against the report's (``pytest -s``).
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from controller.drive import Drive
from abu.cli.main import main
from harness.planning.design import REPORT_INTERVALS, DesignSpec, design_staircase, predict
from harness.planning.design_check import check_design

REPORT_MU = 2.75e-3
CASES = [
    ("report range, report loop", (REPORT_MU, 6 * REPORT_MU), Drive()),
    ("twin drive", (0.02, 0.04), Drive("pi-lag", 0.7, 12.0, 0.02)),
    ("wide range, other drive", (0.008, 0.05), Drive("pi-lag", 0.6, 8.0, 0.01)),
]


@pytest.mark.parametrize("name,mu_range,drive", CASES, ids=[c[0] for c in CASES])
def test_design_holds_in_cosimulation_at_20_mu(name, mu_range, drive, fmu_dir):
    spec = DesignSpec(*mu_range, drive=drive)
    design = design_staircase(spec)
    mus = np.geomspace(*mu_range, 20)
    rows = check_design(design, mus, fmu_dir)
    predicted = predict(spec, design.staircase, mus)
    stair = design.staircase
    assert design.t0_s + 0.0 <= stair.step_times[1]  # the second step is after t0
    for row, t_pred in zip(rows, predicted["t_slip_s"]):
        assert row["first_step_stuck"], row
        assert row["slip_inside"], row
        assert row["brackets"], row
        assert row["t_slip_s"] > stair.step_times[1]
        assert abs(row["t_slip_s"] - t_pred) <= 1.5 / spec.fps, (row, t_pred)
    widths = [(r["mu_high"] - r["mu_low"]) / r["mu"] for r in rows]
    report = ", ".join(f"{k}: {100 * (b - a) / ((a + b) / 2):.1f} %"
                       for k, (a, b) in REPORT_INTERVALS.items())
    print(f"\n[{name}] mu in [{mu_range[0]:.4g}, {mu_range[1]:.4g}], drive zeta {drive.zeta}, "
          f"omega_n {drive.omega_n} rad/s, tau {drive.tau_motor} s: {design.omega0_hz} Hz -> "
          f"{design.omega_end_hz:g} Hz, t0 = {design.t0_s} s, te = {design.te_s:.4g} s, "
          f"{design.rounding}; slips at {min(r['t_slip_s'] for r in rows):.3f}-"
          f"{max(r['t_slip_s'] for r in rows):.3f} s of the {spec.record_s:.3f} s record; "
          f"20/20 stuck through the first step, slip inside, bracketed. Predicted measured width "
          f"(slip located within +-{1e3 * spec.slip_window_s:g} ms): expected (log-uniform "
          f"prior) {100 * design.expected_width:.1f} %, worst {100 * design.worst_width:.1f} %; "
          f"co-simulation bounds width median {100 * np.median(widths):.2f} %; the report: "
          f"{report}")


def test_design_cli_json_and_simulate_args_run_the_design(tmp_path, capsys, fmu_dir):
    drive = Drive("pi-lag", 0.7, 12.0, 0.02)
    (tmp_path / "drive.json").write_text(json.dumps(drive.to_dict()))
    assert main(["design", "--mu-range", "0.02", "0.04", "--drive", str(tmp_path / "drive.json"),
                 "--no-check", "--json", "--out", str(tmp_path / "d")]) == 0
    out = json.loads(capsys.readouterr().out)
    for key in ("omega0_hz", "omega_end_hz", "t0_s", "te_s", "rounding", "step_hz",
                "simulate_args"):
        assert key in out
    assert (tmp_path / "d" / "design.png").stat().st_size > 1000
    fmus = str(fmu_dir["AbuBall"].parent)
    assert main(["simulate", *out["simulate_args"], "--mu", "0.03", "--fmu-dir", fmus,
                 "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert out["edge_s"] <= s["t_slip"] <= out["record_s"] - out["edge_s"]
    assert s["brackets_mu"]
    row = min(out["table"], key=lambda r: abs(r["mu"] - 0.03))
    assert abs(s["t_slip"] - row["t_slip_s"]) < 0.02


def test_design_refuses_a_range_no_staircase_can_cover(capsys):
    assert main(["design", "--mu-range", "1e-4", "0.5", "--no-check"]) == 2
    err = capsys.readouterr().err
    assert "--mu-range" in err and "none found" in err
    assert main(["design", "--mu-range", "0.03", "0.02", "--no-check"]) == 2
    assert "--mu-range" in capsys.readouterr().err


def test_design_holds_at_the_corners_of_the_drive_intervals(fmu_dir):
    """A drive known to +-15 %: the design holds (predicted) at all 8 corners of its intervals,
    and co-simulating two opposite corners at the range's ends confirms it."""
    from dataclasses import replace

    from harness.planning.design import drive_corners, holds

    ci = {"zeta": (0.6, 0.8), "omega_n_rad_s": (10.0, 14.0), "tau_motor_s": (0.017, 0.023)}
    drive = Drive("pi-lag", 0.7, 12.0, 0.02, ci95=ci)
    spec = DesignSpec(0.02, 0.04, drive=drive)
    design = design_staircase(spec)
    corners = drive_corners(drive)
    assert len(corners) == 8 and design.ci_corners_hold
    # a setpoint filter's interval is a fourth axis (declared by its interval alone, too)
    for tau_f in (0.01, 0.0):
        filt = drive_corners(replace(drive, setpoint_tau=tau_f,
                                     ci95={**ci, "setpoint_tau_s": (0.005, 0.02)}))
        assert len(filt) == 16 and {c.setpoint_tau for c in filt} == {0.005, 0.02}
    assert drive_corners(Drive()) == [] and design_staircase(
        DesignSpec(0.02, 0.04)).ci_corners_hold is None  # no intervals: nothing claimed
    assert all(holds(replace(spec, drive=c), design.staircase) for c in corners)
    for corner in (corners[0], corners[-1]):  # all low, all high
        rows = check_design(replace(design, spec=replace(spec, drive=corner)), None, fmu_dir)
        assert all(r["first_step_stuck"] and r["slip_inside"] and r["brackets"] for r in rows)


def test_unstable_corners_of_the_drive_intervals_are_not_held_to():
    """A drive whose interval box reaches beyond the Routh-Hurwitz limit (tau_motor >= 2 zeta
    / omega_n; checked by the loop polynomial's roots): those corners are dropped, the stable
    ones kept, and the design's corner claim is about those."""
    from harness.planning.design import drive_corners

    ci = {"zeta": (0.4, 0.6), "omega_n_rad_s": (18.0, 22.0), "tau_motor_s": (0.035, 0.045)}
    drive = Drive("pi-lag", 0.5, 20.0, 0.04, ci95=ci)
    corners = drive_corners(drive)

    def stable(d):
        roots = np.roots([d.tau_motor, 1.0, 2 * d.zeta * d.omega_n, d.omega_n**2])
        return roots.real.max() < 0

    every = [(z, w, t) for z in ci["zeta"] for w in ci["omega_n_rad_s"]
             for t in ci["tau_motor_s"]]
    expected = {c for c in every if stable(Drive("pi-lag", *c))}
    assert 0 < len(expected) < 8
    assert {(c.zeta, c.omega_n, c.tau_motor) for c in corners} == expected
    design = design_staircase(DesignSpec(0.02, 0.04, drive=drive))
    assert design.ci_corners_hold is not None


def test_render_args_render_the_designed_staircase():
    """``render_args`` carry the rounding and the step: ``abu render`` given them films the
    designed staircase, not the report's lead rounding at 1 Hz."""
    from abu.cli.main import build_parser
    from abu.cli.render import _twin_settings

    for spec in (DesignSpec(0.02, 0.04, step_hz=2.0),
                 DesignSpec(0.02, 0.04, drive=Drive("pi-lag", 0.7, 12.0, 0.005))):
        design = design_staircase(spec)
        args = build_parser().parse_args(["render", "--out", "x", *design.render_args(),
                                          "--mu", "0.03"])
        s = _twin_settings(args)
        stair = design.staircase
        assert s.drive.rounding == design.rounding
        assert s.drive.step == pytest.approx(stair.step)
        assert (s.omega0, s.omega_end, s.t0, s.te) == pytest.approx(
            (stair.omega0, stair.omega_end, stair.t0, stair.te), rel=1e-5)
