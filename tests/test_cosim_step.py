"""The master's per-step work: no value read twice at a point, and the FMI calls of an
ordinary step counted (the report's staircase, fourth-order hold)."""
from __future__ import annotations

import math
from collections import Counter

from abu_model.params import PlantParams
from harness.experiments.staircase import StaircaseExperiment
from harness.cosim.master import CoSimulation

HZ = 2.0 * math.pi


def test_no_value_is_read_twice_per_point_and_an_ordinary_step_costs_32_calls(fmu_dir):
    exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ, t0=0.0, te=1.0)
    segments: list[list[tuple[str, int]]] = [[]]
    calls_at_step: list[int] = []
    with CoSimulation(exp.system(fmu_dir), exp.t_start, exp.t_end) as sim:
        get, do_step = sim._get, sim.do_step

        def logged_get(inst, type_, vrs):
            segments[-1].extend((inst.name, type_, vr) for vr in vrs)
            return get(inst, type_, vrs)

        def logged_step(t, h):
            segments.append([])
            calls_at_step.append(sim.fmi_calls)
            return do_step(t, h)

        sim._get, sim.do_step = logged_get, logged_step
        res = sim.run()
    discontinuities = len(res.time_events) + len(res.switches) + 1  # + the stop time
    twice = [seg for seg in segments[1:] if max(Counter(seg).values()) > 1]
    # Only points with two sweeps (left and right limit of a time event) read an
    # input-dependent output again; every other point reads each value once.
    assert len(twice) <= discontinuities, len(twice)
    per_step = Counter(b - a for a, b in zip(calls_at_step, calls_at_step[1:]))
    # 3 fmi2GetFMUstate + 3 fmi2DoStep + 3 reads after the step + 19 in the sweep (the
    # fourth-order hold's chain torque -> alpha -> torque_rate -> jerk -> ... -> torque_snap,
    # a get and a set per link) + 1 for the remaining probes + 3 fmi2FreeFMUstate
    assert per_step.most_common(1)[0][0] == 32, per_step
    print(f"\n[step] {res.stats['steps']} steps, {res.stats['fmi_calls']} FMI calls; calls "
          f"between successive steps: {dict(per_step)}")


def test_an_event_just_before_the_stop_time_is_still_taken(fmu_dir):
    # The stop time 0.1 ms after a setpoint step: within the 20 % stretch of a step that would
    # otherwise reach past both; the master must land on the step, then on the stop time.
    base = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ, t0=0.0, te=1.0)
    t_step = base.staircase.step_times[1]
    exp = StaircaseExperiment(PlantParams(), -17 * HZ, -22 * HZ, t0=0.0, te=1.0,
                              t_end=t_step + 1e-4)
    with CoSimulation(exp.system(fmu_dir), exp.t_start, exp.t_end) as sim:
        res = sim.run()
    at_step = res.side[res.time == t_step]
    assert list(at_step) == [-1, 1] and t_step in res.time_events
    assert res.time[-1] == exp.t_end and res.side[-1] == 0
