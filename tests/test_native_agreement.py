"""The native FMUs give the Python FMUs' results through our master (harness), on the random
staircases of tests/test_cosim_accuracy.py (the family of tests/staircase_family.py).

The experiments take the FMU files as a mapping {name: path} (``harness.experiments.fmu_files.
ensure_fmus``), so the native build drops in with no hook. Family (seeded, 200 cases): mu in
[1e-3, 6e-2]; |omega0| 0.7 to 1.6 (or 1 - 1e-2 to 1 - 1e-6) times the speed at which the
first setpoint step makes the ball slip, and where |omega| falls along the staircase a
margin to step k; 1 to 40 steps of 1 Hz up or down in te 0.02-1.5 s; t0 0-0.5 s; every
rounding and both theta_ref readings; tau_motor 0, 2 or 10 ms; the end on a setpoint step or
0.5 s after the staircase. Asserted: the same switches (direction and order) within 1e-10 s,
the same slip time and both bounds within 1e-10 relative (``pytest -s`` prints the largest
differences; measured: identical to the last bit).
"""
from __future__ import annotations

import random

import pytest

from harness.experiments.staircase import run_staircase
from staircase_family import draw_experiment

CASES = 200


def _rel(a, b) -> float:
    if a is None or b is None:
        assert a is None and b is None
        return 0.0
    return abs(a / b - 1.0) if b else abs(a)


def test_native_and_python_fmus_agree_on_random_staircases(native_fmu_dir, fmu_dir):
    rng = random.Random(21)
    worst = {"switch_s": 0.0, "bound_rel": 0.0, "switches": 0, "slips": 0}
    for case in range(CASES):
        exp = draw_experiment(rng)
        py = run_staircase(exp, fmu_dir).summary
        nat = run_staircase(exp, native_fmu_dir).summary
        where = f"case {case}: {exp.as_dict()}"
        assert [(w["from_mode"], w["to_mode"]) for w in nat["switches"]] == \
            [(w["from_mode"], w["to_mode"]) for w in py["switches"]], where
        for a, b in zip(nat["switches"], py["switches"]):
            worst["switch_s"] = max(worst["switch_s"], abs(a["time_s"] - b["time_s"]))
        if py["t_slip"] is not None:
            worst["slips"] += 1
            worst["switch_s"] = max(worst["switch_s"], abs(nat["t_slip"] - py["t_slip"]))
        else:
            assert nat["t_slip"] is None, where
        worst["switches"] += len(py["switches"])
        for key in ("mu_low", "mu_high"):
            worst["bound_rel"] = max(worst["bound_rel"], _rel(nat[key], py[key]))
        assert worst["switch_s"] <= 1e-10 and worst["bound_rel"] <= 1e-10, (where, worst)
    print(f"\n[native vs python] {CASES} random staircases ({worst['slips']} slip, "
          f"{worst['switches']} switches): switch times within {worst['switch_s']:.1e} s, "
          f"bounds within {worst['bound_rel']:.1e} relative")
