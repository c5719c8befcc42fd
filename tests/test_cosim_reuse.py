"""Runs that share FMUs reset and reuse their instances (fmi2Reset) instead of reloading:
same results as a fresh load, and a batch of 1,000 runs keeps sys.path and memory flat."""
from __future__ import annotations

import math
import os
import sys
import time
from dataclasses import replace
from pathlib import Path

import pytest

from abu_model.params import BallParams, PlantParams
from harness.cosim import reuse
from harness.experiments.staircase import RampExperiment, StaircaseExperiment, run_staircase
from harness.cosim.master import CoSimulation, CoSimulationError
from harness.cosim.system import Source

HZ = 2.0 * math.pi
#: One 1 Hz step at t0 = 0.02 s from -12 Hz, 0.1 s simulated: about 15 communication steps.
SHORT = dict(omega0=-12 * HZ, omega_end=-13 * HZ, t0=0.02, te=0.05, t_end=0.12)
#: Largest |omega0| [rad/s] at which that step makes the ball slip, per mu: slips iff
#: mu < lever (2 zeta wn dW) / omega0^2.
JUMP = 2 * 0.5 * 2.2 * HZ


def _rss_bytes() -> int:
    """Resident set size of this process [bytes] (Linux /proc)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


def _experiment(mu: float) -> StaircaseExperiment:
    return StaircaseExperiment(PlantParams(BallParams(mu=mu)), **SHORT)


def test_reused_run_equals_a_fresh_load(fmu_dir):
    exp = _experiment(2e-3)
    fresh = run_staircase(exp, fmu_dir, reuse=False)
    run_staircase(replace(exp, plant=PlantParams(BallParams(mu=5e-3))), fmu_dir)  # other params
    reused = run_staircase(exp, fmu_dir)
    assert reuse.pooled() >= 1
    for column, values in fresh.table.items():
        assert list(values) == list(reused.table[column]), column
    assert fresh.summary["mu_low"] == reused.summary["mu_low"]


def test_reuse_refuses_another_structure(fmu_dir):
    a = _experiment(2e-3).system(fmu_dir)
    b = replace(a, probes={"omega": "plant.omega"})
    with CoSimulation(a, -0.03, 0.1) as sim:
        sim.run()
        with pytest.raises(CoSimulationError, match="same structure"):
            sim.reuse(b)
        sim.reuse(a, -0.03, 0.05)  # same structure, new times: fine
        assert sim.run().time[-1] == pytest.approx(0.05, abs=1e-12)


def test_thousand_runs_keep_sys_path_and_memory_flat(fmu_dir):
    lever = PlantParams().ball.lever_ratio
    mu_crit = lever * JUMP / (12 * HZ) ** 2  # the step needs exactly this mu
    started = time.perf_counter()
    path_after_first = rss_after_100 = None
    for i in range(1000):
        mu = mu_crit * (0.8 if i % 2 else 1.25)  # alternately slips and holds
        s = run_staircase(_experiment(mu), fmu_dir).summary
        assert s["slips"] == bool(i % 2), (i, mu)  # the new parameters are in effect
        if i == 0:
            path_after_first = list(sys.path)
        if i == 99:
            rss_after_100 = _rss_bytes()
    elapsed = time.perf_counter() - started
    growth = _rss_bytes() - rss_after_100
    print(f"\n[reuse] 1000 staircase runs (0.14 s simulated each) in one process: "
          f"{elapsed:.1f} s ({1e3 * elapsed / 1000:.1f} ms per run), sys.path "
          f"{len(path_after_first)} -> {len(sys.path)} entries, RSS growth after run 100: "
          f"{growth / 2**20:+.1f} MB")
    assert sys.path == path_after_first
    assert growth <= 20 * 2**20


def test_modules_of_the_master_stay_small():
    harness = Path(__file__).resolve().parents[1] / "harness"
    for name in ("cosim/master", "cosim/fmi", "cosim/fmi_ops", "cosim/plan", "cosim/stepping",
                 "cosim/runner", "cosim/recording", "cosim/reuse", "cosim/system",
                 "experiments/bounds", "experiments/staircase", "experiments/fmu_files"):
        lines = (harness / f"{name}.py").read_text().count("\n")
        assert lines <= 400, (name, lines)


def test_a_failed_run_is_not_pooled_and_the_next_one_works(fmu_dir):
    # The ramp's torque sources; a source that fails mid-run stands for any failure.
    ramp = RampExperiment(PlantParams(), -20 * HZ, 3000.0, 0.1)
    good = ramp.system(fmu_dir)
    expected = reuse.run_system(good, 0.0, 0.1).values["omega"]

    def broken(t: float) -> float:
        if t > 0.02:
            raise RuntimeError("source failure requested")
        return 0.0

    bad = replace(good, sources=(Source("plant.torque", broken), good.sources[1]))
    assert bad.structure_key() == good.structure_key()  # so the pooled instances are taken
    before = reuse.pooled()
    with pytest.raises(RuntimeError, match="source failure"):
        reuse.run_system(bad, 0.0, 0.1)
    assert reuse.pooled() == before - 1  # the failed co-simulation was freed, not pooled
    again = reuse.run_system(good, 0.0, 0.1).values["omega"]
    assert list(again) == list(expected)


def test_a_failing_parameter_on_pooled_instances_is_an_error_and_the_next_run_works(fmu_dir):
    # mu = -1 fails fmi2ExitInitializationMode of the reused AbuBall (fmi2Error, a message).
    good = _experiment(2e-3).system(fmu_dir)
    expected = reuse.run_system(good, -0.03, 0.1).values["omega"]
    reuse.run_system(good, -0.03, 0.1, reuse=False)  # another co-simulation loaded and freed
    plant = good.component("plant")
    bad_plant = replace(plant, parameters={**plant.parameters, "mu": -1.0})
    bad = replace(good, components=tuple(bad_plant if c.name == "plant" else c
                                         for c in good.components))
    before = reuse.pooled()
    with pytest.raises(CoSimulationError, match="'mu' = -1"):
        reuse.run_system(bad, -0.03, 0.1)
    assert reuse.pooled() == before - 1
    again = reuse.run_system(good, -0.03, 0.1).values["omega"]
    assert list(again) == list(expected)
