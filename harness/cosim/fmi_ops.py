"""The FMI calls of a step, for :class:`harness.cosim.master.CoSimulation`: grouped gets and sets
(straight through ctypes unless an FMI call logger is attached), state save/restore/free
and ``fmi2DoStep`` of every instance, each counted in ``_calls``."""
from __future__ import annotations

import ctypes
from typing import Any

from harness.cosim.fmi import GETTERS, SETTERS, Guard, Instance, bare, fail, raw_accessor


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

    def _raws(self) -> dict[str, tuple]:
        """Instance name -> (instance, component, fmi2GetFMUstate, fmi2SetFMUstate,
        fmi2FreeFMUstate, fmi2DoStep), the functions argtype-free (:func:`bare`; fmpy's
        wrappers and argument conversion cost a few us per call)."""
        raws = self._fast.get("raws")
        if raws is None:
            raws = {}
            for inst in self._instances.values():
                component, get = bare(inst, "fmi2GetFMUstate")
                raws[inst.name] = (inst, component, get, bare(inst, "fmi2SetFMUstate")[1],
                                   bare(inst, "fmi2FreeFMUstate")[1], bare(inst, "fmi2DoStep")[1])
            self._fast["raws"] = raws
        return raws

    def save_states(self) -> list[tuple[Instance, Any]]:
        states = []
        if self.fmi_call_logger is not None:
            for inst in self._instances.values():
                self._calls += 1
                with Guard(inst, "fmi2GetFMUstate"):
                    states.append((inst, inst.slave.getFMUstate()))
            return states
        for inst, component, get, _, _, _ in self._raws().values():
            self._calls += 1
            state = ctypes.c_void_p()
            status = get(component, ctypes.byref(state))
            if status > 1:
                fail(inst, "fmi2GetFMUstate", status)
            states.append((inst, state))
        return states

    def restore_states(self, states: list[tuple[Instance, Any]], inputs: bool) -> None:
        """Restore every FMU; with ``inputs`` also re-set the inputs of the step start (a
        sweep at the rejected point changed them; an FMU state need not hold inputs)."""
        if self.fmi_call_logger is not None:
            for inst, state in states:
                self._calls += 1
                with Guard(inst, "fmi2SetFMUstate"):
                    inst.slave.setFMUstate(state)
        else:
            raws = self._raws()
            for inst, state in states:
                self._calls += 1
                _, component, _, set_, _, _ = raws[inst.name]
                status = set_(component, state)
                if status > 1:
                    fail(inst, "fmi2SetFMUstate", status)
        if inputs:
            for inst, type_, vrs, values in self._last_sets:
                self._set(inst, type_, vrs, values)

    def free_states(self, states: list[tuple[Instance, Any]]) -> None:
        raws = None if self.fmi_call_logger is not None else self._raws()
        for inst, state in states:
            self._calls += 1
            try:
                if raws is None:
                    inst.slave.freeFMUstate(state)
                else:
                    _, component, _, _, free, _ = raws[inst.name]
                    free(component, ctypes.byref(state))
            except Exception:
                pass

    def do_step(self, t: float, h: float) -> None:
        if self.fmi_call_logger is not None:
            for inst in self._instances.values():
                self._calls += 1
                with Guard(inst, "fmi2DoStep"):
                    inst.slave.doStep(t, h, noSetFMUStatePriorToCurrentPoint=False)
            return
        t_c, h_c = ctypes.c_double(t), ctypes.c_double(h)
        for inst, component, _, _, _, step in self._raws().values():
            self._calls += 1
            status = step(component, t_c, h_c, 0)  # noSetFMUStatePriorToCurrentPoint false
            if status > 1:
                fail(inst, "fmi2DoStep", status)
