"""The stepping loop of :class:`harness.cosim.master.CoSimulation`: proposals, time events,
switch landing and error rejection by rollback, recording of left and right limits.

One step from t:

1. proposal: the next grid point (fixed step) or t + h from the controller, moved to the
   earliest announced time event if that lies before it (or less than 20 % of h after it,
   to avoid a sliver step), and to the stop time likewise;
2. save every FMU's state, ``fmi2DoStep`` all, read the input-independent outputs once;
3. a switch strictly inside the step: restore and redo the step up to it (several switches
   of one FMU without their first time: halve);
4. propagate at the new point (the left limit if a time event was hit) and estimate the
   coupling error; above the tolerance: restore, re-set the step start's inputs, redo
   shorter;
5. record: one row, or at a time event / switch the left and the right limit.

A time event that falls exactly on the stop time is not taken: the run ends at its left
limit (a row with side -1) and a note says so, so that no right-hand limit of a setpoint
step is recorded as if the plant had lived through it.
"""
from __future__ import annotations

from typing import Any, Protocol

from harness.cosim.plan import Plan
from harness.cosim.recording import CoSimResult, Recorder
from harness.cosim.stepping import ErrorControl, inner_switches, next_events, switch_events, \
    switch_info


class SteppedSystem(Protocol):
    """What the runner needs of a loaded co-simulation (:class:`harness.cosim.master.CoSimulation`
    implements it): the contract between the stepping loop and the FMI side, like SciPy's
    ``OdeSolver.step()`` around ``_step_impl``. Times in s."""

    plan: Plan
    start_time: float
    stop_time: float
    event_tol: float
    switch_tol: float
    max_rollbacks: int
    progress: bool

    @property
    def fixed_step(self) -> float: ...
    @property
    def fmi_calls(self) -> int: ...
    def error_control(self) -> ErrorControl | None: ...
    def first_step(self) -> float: ...
    def initialize(self) -> dict[str, Any]: ...
    def do_step(self, t: float, h: float) -> None: ...
    def save_states(self) -> Any: ...
    def restore_states(self, states: Any, inputs: bool) -> None: ...
    def free_states(self, states: Any) -> None: ...
    def read_outputs(self) -> dict[str, Any]: ...
    def propagate(self, t: float, pre: dict[str, Any], held: frozenset[str] = frozenset(),
                  commit: bool = True) -> dict[str, Any]: ...
    def commit(self) -> None: ...

#: A proposal within this fraction of h before an event or the stop time is moved onto it.
STRETCH = 0.2
#: Tolerance factor on the approach to a switch found inside a step. An FMU locates such a
#: switch from the inputs held over the step (e.g. a slip that starts from a continuous
#: acceleration: mu_req(t) = mu with the held torque), so the steps from the rollback to the
#: switch run at tol * SWITCH_TIGHTEN; only these few steps get finer. Measured on the
#: accuracy family (fourth-order hold, tol 1e-9): worst switch 3.8e-10 s at 1e-2, 5.8e-10 s
#: at 1 (no tightening), 3.4e-10 s at 1e-4 with 40 % more steps.
SWITCH_TIGHTEN = 1e-2


class Runner:
    """One run of a loaded co-simulation."""

    def __init__(self, sim: SteppedSystem):
        self.sim = sim
        self.plan = sim.plan
        self.control = sim.error_control()
        self.rec = Recorder(sim.plan.probes)
        self.stats: dict[str, Any] = {"steps": 0, "rollbacks": 0, "rejected": 0,
                                      "do_steps": 0, "max_error": 0.0}
        # While approaching a switch found inside a step: the time after which the tight
        # tolerance ends if no switch was landed on (the switch moved away) [s].
        self.approach_until: float | None = None

    def _propose(self, t: float, n_grid: int, h: float) -> tuple[float, int]:
        sim = self.sim
        if self.control is None:  # fixed step: next grid point strictly after t
            step = sim.fixed_step
            while sim.start_time + (n_grid + 1) * step <= t + sim.event_tol:
                n_grid += 1
            return sim.start_time + (n_grid + 1) * step, n_grid
        return t + h, n_grid

    def run(self) -> CoSimResult:
        sim, plan, rec = self.sim, self.plan, self.rec
        values = sim.initialize()
        t = sim.start_time
        rec.record(t, 0, values)
        before = switch_info(plan.switches, values)
        snap = self.control.snapshot(values) if self.control else None
        h = sim.first_step()
        n_grid = 0
        bar = None
        if sim.progress:
            from tqdm import tqdm
            bar = tqdm(total=sim.stop_time - sim.start_time, unit="s", leave=False,
                       bar_format="{l_bar}{bar}| {n:.3f}/{total:.3f} s simulated "
                                  "[{elapsed}<{remaining}]")
        try:
            while sim.stop_time - t > sim.event_tol:
                target, n_grid = self._propose(t, n_grid, h)
                slack = 0.0 if self.control is None else STRETCH * (target - t)
                t_event, owners = next_events(plan.events, values, t, sim.event_tol)
                limit = min(t_event, sim.stop_time)  # the earlier of the event and the end
                if limit <= target + max(slack, sim.event_tol):
                    target = limit
                hit_event = abs(t_event - target) <= sim.event_tol
                if hit_event:
                    target = t_event
                event_at_stop = hit_event and abs(target - sim.stop_time) <= sim.event_tol
                if event_at_stop:
                    target = sim.stop_time
                t_new, values, before, snap, h = self._step(
                    t, target, hit_event, owners, before, snap, event_at_stop, h)
                if bar is not None:
                    bar.update(t_new - t)
                t = t_new
        finally:
            if bar is not None:
                bar.close()
        self.stats["fmi_calls"] = sim.fmi_calls
        return rec.result(self.stats)

    def _step(self, t: float, target: float, hit_event: bool, owners: frozenset[str],
              before: list, snap: Any, event_at_stop: bool, h_prop: float):
        """One accepted step from t; returns (t_new, right-limit values, switch info,
        hold snapshot, next proposal h)."""
        sim, plan, rec, stats, control = self.sim, self.plan, self.rec, self.stats, self.control
        h = target - t
        states = sim.save_states() if (plan.switches or control) else None
        tries = 0
        rejected = False
        try:
            while True:
                sim.do_step(t, h)
                stats["do_steps"] += 1
                pre = sim.read_outputs()
                after = switch_info(plan.switches, pre)
                inner, crowded = inner_switches(t, h, before, after, sim.switch_tol)
                if (inner or crowded) and tries < sim.max_rollbacks:
                    sim.restore_states(states, inputs=False)
                    stats["rollbacks"] += 1
                    tries += 1
                    # Land on the first inner switch; halve when an FMU cannot say where.
                    h = min([ts - t for ts in inner] + ([h / 2.0] if crowded else []))
                    if control is not None and self.approach_until is None:
                        self.approach_until = t + 2.0 * h
                    continue
                if inner or crowded:
                    rec.notes.append(f"step from t = {t:.12g} s: switches not separated after "
                                     f"{tries} rollbacks; accepted the step to {t + h:.12g} s")
                t_new = t + h
                at_event = hit_event and abs(t_new - target) <= sim.event_tol
                held = owners if at_event else frozenset()
                left = sim.propagate(t_new, pre, held, commit=False)
                err = control.error(snap, left, h) if control else 0.0
                if self.approach_until is not None:
                    err /= SWITCH_TIGHTEN
                if err > 1.0 and h > control.h_min and tries < sim.max_rollbacks:
                    sim.restore_states(states, inputs=True)
                    stats["rollbacks"] += 1
                    stats["rejected"] += 1
                    tries += 1
                    rejected = True
                    h = control.retry_step(h, err)
                    continue
                break
        finally:
            if states is not None:
                sim.free_states(states)
        stats["steps"] += 1
        stats["max_error"] = max(stats["max_error"], err)
        new_switches = switch_events(plan.switches, before, after, t, t_new, sim.switch_tol,
                                     rec.notes)
        rec.switches.extend(new_switches)
        at_switch = any(s.located and abs(s.time - t_new) <= sim.switch_tol
                        for s in new_switches)
        if self.approach_until is not None and (at_switch or t_new >= self.approach_until):
            self.approach_until = None
        if at_event and event_at_stop:
            rec.record(t_new, -1, left)  # held sweep: nothing to commit
            rec.notes.append(f"the time event at the stop time {t_new:.12g} s is not taken: "
                             "the run ends at its left limit")
            values = left
        elif at_event:
            rec.time_events.append(t_new)
            rec.record(t_new, -1, left)
            values = sim.propagate(t_new, pre)
            rec.record(t_new, +1, values)
        elif at_switch:
            # An FMU reports its state after the switch: both rows are the full sweep.
            sim.commit()
            rec.record(t_new, -1, left)
            rec.record(t_new, +1, left)
            values = left
        else:
            sim.commit()
            rec.record(t_new, 0, left)
            values = left
        h_next = h
        if control is not None:
            snap = control.snapshot(values)
            # A step cut short by an event, a switch or the stop time says little about the
            # step size: keep the proposal unless the error itself asked for less.
            cut = not rejected and h < h_prop * (1.0 - 1e-9)
            h_next = h_prop if cut else control.next_step(h, err)
        return t_new, values, after, snap, h_next
