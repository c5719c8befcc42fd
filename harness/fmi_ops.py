"""The FMI calls of a step, for :class:`harness.master.CoSimulation`: grouped gets and sets
(straight through ctypes unless an FMI call logger is attached), state save/restore/free
and ``fmi2DoStep`` of every instance, each counted in ``_calls``."""
from __future__ import annotations

from typing import Any

from .fmi import GETTERS, SETTERS, Guard, Instance, raw_accessor


class StepOps:
    """Mixin: needs ``_instances``, ``_calls``, ``_fast``, ``_last_sets``, ``fmi_call_logger``."""

    def _accessor(self, inst: Instance, kind: str, type_: str, vrs: list[int],
                  key: int | None) -> tuple:
        if self.fmi_call_logger is not None:  # fmpy's methods log every call
            method = getattr(inst.slave, (GETTERS if kind == "Get" else SETTERS)[type_])
            call = (lambda: method(vrs)) if kind == "Get" else (lambda v: method(vrs, v))
        else:
            call = raw_accessor(inst, kind, type_, vrs)
        entry = (call, Guard(inst, f"fmi2{kind}{type_}"), vrs)
        if key is not None:  # the plan's lists live as long as the plan
            self._fast[key] = entry
        return entry

    def _get(self, inst: Instance, type_: str, vrs: list[int]) -> list:
        self._calls += 1
        entry = self._fast.get(id(vrs))
        if entry is None or entry[2] is not vrs:
            entry = self._accessor(inst, "Get", type_, vrs, id(vrs))
        with entry[1]:
            return entry[0]()

    def _set(self, inst: Instance, type_: str, vrs: list[int], values: list,
             cache: bool = True) -> None:
        self._calls += 1
        entry = self._fast.get(-id(vrs))
        if entry is None or entry[2] is not vrs:
            entry = self._accessor(inst, "Set", type_, vrs, -id(vrs) if cache else None)
        with entry[1]:
            entry[0](values)

    def save_states(self) -> list[tuple[Instance, Any]]:
        states = []
        for inst in self._instances.values():
            self._calls += 1
            with Guard(inst, "fmi2GetFMUstate"):
                states.append((inst, inst.slave.getFMUstate()))
        return states

    def restore_states(self, states: list[tuple[Instance, Any]], inputs: bool) -> None:
        """Restore every FMU; with ``inputs`` also re-set the inputs of the step start (a
        sweep at the rejected point changed them; an FMU state need not hold inputs)."""
        for inst, state in states:
            self._calls += 1
            with Guard(inst, "fmi2SetFMUstate"):
                inst.slave.setFMUstate(state)
        if inputs:
            for inst, type_, vrs, values in self._last_sets:
                self._set(inst, type_, vrs, values)

    def free_states(self, states: list[tuple[Instance, Any]]) -> None:
        for inst, state in states:
            self._calls += 1
            try:
                inst.slave.freeFMUstate(state)
            except Exception:
                pass

    def do_step(self, t: float, h: float) -> None:
        for inst in self._instances.values():
            self._calls += 1
            with Guard(inst, "fmi2DoStep"):
                inst.slave.doStep(t, h, noSetFMUStatePriorToCurrentPoint=False)
