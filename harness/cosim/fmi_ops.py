"""The FMI calls of a step, for :class:`harness.cosim.master.CoSimulation`: grouped gets and sets
(straight through ctypes unless an FMI call logger is attached), state save/restore/free
and ``fmi2DoStep`` of every instance, each counted in ``_calls``."""
from __future__ import annotations

import ctypes
from typing import Any

from fmpy.fmi1 import FMICallException

from harness.cosim.fmi import GETTERS, SETTERS, Guard, Instance, raw_accessor


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

    def _raw(self, inst: Instance) -> tuple:
        """(component, fmi2GetFMUstate, fmi2SetFMUstate, fmi2FreeFMUstate, fmi2DoStep) raw
        ctypes functions of ``inst`` (fmpy's wrappers cost a few us per call)."""
        raw = self._fast.get(("raw", inst.name))
        if raw is None or raw[0] != inst.slave.component:
            f = inst.slave._functions
            raw = (inst.slave.component, f["fmi2GetFMUstate"], f["fmi2SetFMUstate"],
                   f["fmi2FreeFMUstate"], f["fmi2DoStep"])
            self._fast[("raw", inst.name)] = raw
        return raw

    def save_states(self) -> list[tuple[Instance, Any]]:
        states = []
        for inst in self._instances.values():
            self._calls += 1
            with Guard(inst, "fmi2GetFMUstate"):
                if self.fmi_call_logger is not None:
                    states.append((inst, inst.slave.getFMUstate()))
                    continue
                component, get, _, _, _ = self._raw(inst)
                state = ctypes.c_void_p()
                _check(get(component, ctypes.byref(state)), "fmi2GetFMUstate")
                states.append((inst, state))
        return states

    def restore_states(self, states: list[tuple[Instance, Any]], inputs: bool) -> None:
        """Restore every FMU; with ``inputs`` also re-set the inputs of the step start (a
        sweep at the rejected point changed them; an FMU state need not hold inputs)."""
        for inst, state in states:
            self._calls += 1
            with Guard(inst, "fmi2SetFMUstate"):
                if self.fmi_call_logger is not None:
                    inst.slave.setFMUstate(state)
                else:
                    component, _, set_, _, _ = self._raw(inst)
                    _check(set_(component, state), "fmi2SetFMUstate")
        if inputs:
            for inst, type_, vrs, values in self._last_sets:
                self._set(inst, type_, vrs, values)

    def free_states(self, states: list[tuple[Instance, Any]]) -> None:
        for inst, state in states:
            self._calls += 1
            try:
                if self.fmi_call_logger is not None:
                    inst.slave.freeFMUstate(state)
                else:
                    component, _, _, free, _ = self._raw(inst)
                    free(component, ctypes.byref(state))
            except Exception:
                pass

    def do_step(self, t: float, h: float) -> None:
        for inst in self._instances.values():
            self._calls += 1
            with Guard(inst, "fmi2DoStep"):
                if self.fmi_call_logger is not None:
                    inst.slave.doStep(t, h, noSetFMUStatePriorToCurrentPoint=False)
                else:
                    component, _, _, _, step = self._raw(inst)
                    _check(step(component, t, h, 0), "fmi2DoStep")


def _check(status: int, function: str) -> None:
    """fmpy's rule: a status above fmi2Warning is an FMICallException."""
    if status > 1:
        raise FMICallException(function=function, status=status)
