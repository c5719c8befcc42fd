"""The master's direct FMI calls (the plan compiled into closures over argtype-free ctypes
functions, :mod:`harness.cosim.point`, :func:`harness.cosim.fmi.bare`) change nothing: every
recorded value, switch, note and counter equals that of the plan walk through fmpy's own
wrappers (which an FMI call logger selects), to the last bit, on seeded staircases of
tests/test_cosim_accuracy.py's family (native and Python FMUs), with reused instances, and on
the ramp (time-function sources, a plan rebuilt per run).
"""
from __future__ import annotations

import math
import random

import numpy as np
import pytest

from abu_model.params import PlantParams
from harness.cosim import reuse
from harness.cosim.master import CoSimulation
from harness.experiments.staircase import RampExperiment
from staircase_family import draw_experiment

HZ = 2.0 * math.pi


def _run(system, exp, logged: bool, sim: CoSimulation | None = None):
    """One run, direct (``logged`` False) or through fmpy's logged wrappers."""
    options = {"fmi_call_logger": (lambda line: None) if logged else None}
    t0, t1 = getattr(exp, "t_start", 0.0), exp.t_end
    if sim is not None:
        sim.reuse(system, t0, t1)
        return sim.run()
    with CoSimulation(system, t0, t1, exp.comm_step, tol=exp.tol, **options) as fresh:
        return fresh.run()


def _assert_same(a, b, where: str) -> None:
    assert np.array_equal(a.time, b.time) and np.array_equal(a.side, b.side), where
    assert a.values.keys() == b.values.keys(), where
    for column in a.values:
        # bitwise: the same float64 numbers (NaN nowhere in these runs)
        assert a.values[column].tobytes() == b.values[column].tobytes(), (where, column)
    assert a.switches == b.switches and a.time_events == b.time_events, where
    assert a.notes == b.notes and a.stats == b.stats, where


@pytest.mark.parametrize("build, cases", [("native", 30), ("python", 4)])
def test_direct_calls_equal_the_logged_plan_walk_on_random_staircases(
        build, cases, native_fmu_dir, fmu_dir):
    fmus = native_fmu_dir if build == "native" else fmu_dir
    rng = random.Random(2121)
    family = [draw_experiment(rng) for _ in range(cases)]
    steps = 0
    reused = None
    try:
        for i, exp in enumerate(family):
            system = exp.system(fmus)
            direct = _run(system, exp, logged=False)
            walked = _run(system, exp, logged=True)
            _assert_same(direct, walked, f"{build} case {i}: {exp.as_dict()}")
            if reused is None:  # one loaded co-simulation reset for every later case
                reused = CoSimulation(system, exp.t_start, exp.t_end, exp.comm_step,
                                      tol=exp.tol).__enter__()
            _assert_same(_run(system, exp, False, reused), walked, f"{build} reused case {i}")
            steps += direct.stats["steps"]
    finally:
        if reused is not None:
            reused.close()
    print(f"\n{build}: {cases} staircases (seed 2121), {steps} steps: identical")


def test_direct_calls_equal_the_logged_plan_walk_on_the_ramp(native_fmu_dir):
    for jerk in (3000.0, 5000.0):
        exp = RampExperiment(PlantParams(), -20 * HZ, jerk, 0.1)
        system = exp.system(native_fmu_dir)
        direct = reuse.run_system(system, 0.0, exp.t_end)
        _assert_same(direct, _run(system, exp, logged=True), f"ramp K = {jerk}")
        assert direct.stats["fmi_calls"] > 0 and direct.switches  # a slip was located
