"""Co-simulation master on fmpy's ``FMU2Slave`` (FMI 2.0 co-simulation).

What it does at each communication point t_k (see docs/harness.md):

1. **Propagation in Gauss-Seidel order at variable level.** The graph has one node per
   connected variable: ``output -> input`` for each connection, ``input -> output`` for each
   dependency the FMU declares in ``ModelStructure/Outputs`` (an output without a
   ``dependencies`` attribute depends on every input, as the FMI standard says). A
   topological order of that graph reads each output only after every input it depends on
   is set, so ``plant.omega -> controller.torque -> plant.torque -> plant.alpha ->
   controller.torque_rate -> plant.torque_rate`` resolves in one sweep although the
   components form a loop. A cycle in the graph is a real algebraic loop:
   :class:`AlgebraicLoopError`.
2. **Step size.** The next point is the next multiple of the communication step, moved back
   to the earliest time event (any output called ``next_event_time``) and the end time.
3. **Switch location by rollback.** Every FMU's state is saved (``getFMUstate``) before the
   step. If an FMU's ``switch_count`` output grew and its ``t_last_switch`` lies strictly
   inside the step, every FMU is restored (``setFMUstate``) and the step is redone up to the
   switch, so that a communication point lies on each switch. More than one switch of one
   FMU in a step halves the step until they are separated.
4. **Recording.** Ordinary points give one row (``side`` 0) after propagation. A
   discontinuity (time event or switch) gives two rows with the same time: the left limit
   (``side`` -1) and the right limit (``side`` +1). A component announcing time events is
   taken as piecewise constant between them (a setpoint source): for the left limit its
   outputs keep their values from before the step and the sweep runs with them, so every
   other output (torque, acceleration) is its left limit at the event too; the right limit
   follows the full sweep. At a switch both rows come from the full sweep: an FMU reports
   its state after the switch, so only the side marks it.

FMU instances are always terminated and freed, also on errors. FMI errors become
:class:`FMUError` naming the component and the message the FMU logged.
"""
from __future__ import annotations

import ctypes
import graphlib
import math
import tempfile
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

import fmpy
from fmpy import calloc, free
from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import (
    FMU2Slave,
    fmi2CallbackAllocateMemoryTYPE,
    fmi2CallbackFreeMemoryTYPE,
    fmi2CallbackFunctions,
    fmi2CallbackLoggerTYPE,
)

from abu_model.errors import AbuError, ParameterError

from .system import System, split_name

#: Output names the master looks for in every component.
NEXT_EVENT_OUTPUT = "next_event_time"
SWITCH_COUNT_OUTPUT = "switch_count"
SWITCH_TIME_OUTPUT = "t_last_switch"
SWITCH_STATE_OUTPUT = "mode"
FIRST_SWITCH_OUTPUT = "t_first_step_switch"

_STATUS = ["ok", "warning", "discard", "error", "fatal", "pending"]
_ERROR, _FATAL = 3, 4


class CoSimulationError(AbuError):
    """The system cannot be co-simulated (bad names, types, unsupported FMU, ...)."""


class AlgebraicLoopError(CoSimulationError):
    """The declared dependencies form a cycle of variables (a real algebraic loop)."""

    def __init__(self, cycle: list[str]):
        self.cycle = cycle
        super().__init__("algebraic loop between the variables " + " -> ".join(cycle)
                         + " (each output depends directly on the next input); break it with "
                         "a component whose output does not depend on its input")


class FMUError(CoSimulationError):
    """An FMI call failed.

    Attributes:
        component: instance name.
        function: the FMI function that failed.
        messages: what the FMU logged (most recent last).
    """

    def __init__(self, component: str, fmu: Path, function: str, status: str,
                 messages: list[str]):
        self.component = component
        self.function = function
        self.messages = messages
        detail = "; ".join(messages[-3:]) if messages else "the FMU logged no message"
        super().__init__(f"component '{component}' ({fmu.name}): {function} failed "
                         f"({status}): {detail}")


@dataclass
class SwitchEvent:
    """A switch reported by a component (``switch_count`` grew).

    Attributes:
        time: the component's ``t_last_switch`` [s].
        component: instance name.
        count: ``switch_count`` after the switch.
        before: value of the component's ``mode`` output before the step (None if absent).
        after: value of the ``mode`` output after the step (None if absent).
        located: True if a communication point lies on the switch (within the tolerance).
    """

    time: float
    component: str
    count: int
    before: float | None
    after: float | None
    located: bool


@dataclass
class CoSimResult:
    """Rows recorded at every communication point.

    Attributes:
        time: communication points [s] (a discontinuity appears twice).
        side: -1 left limit, +1 right limit at a discontinuity, 0 ordinary point.
        values: probe column -> values (units of the FMU variable).
        switches: switches in time order.
        time_events: times of the time events hit [s].
        notes: remarks (switches accepted at the nearest communication point, ...).
        stats: counters: ``steps`` (accepted), ``rollbacks``, ``do_steps`` (FMU steps).
    """

    time: np.ndarray
    side: np.ndarray
    values: dict[str, np.ndarray]
    switches: list[SwitchEvent] = field(default_factory=list)
    time_events: list[float] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    stats: dict[str, int] = field(default_factory=dict)


class _Instance:
    """One loaded FMU instance with its variables and captured log."""

    def __init__(self, name: str, fmu_path: Path, unzipdir: Path):
        self.name = name
        self.path = fmu_path
        self.md = fmpy.read_model_description(str(fmu_path), validate=False)
        if self.md.fmiVersion != "2.0" or self.md.coSimulation is None:
            raise CoSimulationError(f"component '{name}': {fmu_path} is not an FMI 2.0 "
                                    "co-simulation FMU")
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.messages: deque[str] = deque(maxlen=50)
        self.slave: FMU2Slave | None = None
        self.instantiated = False
        self.initialized = False
        self.failed_status = 0  # fmi2Status of the last failed call (0: none)
        self.abandoned = False  # left unfreed after fmi2Fatal
        self.can_get_state = bool(self.md.coSimulation.canGetAndSetFMUstate)
        self.unzipdir = unzipdir
        # Output dependencies on inputs; None means "every input" (FMI default).
        inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        self.dependencies: dict[str, list[str]] = {}
        declared = {u.variable.name: u.dependencies for u in self.md.outputs}
        for var in self.md.modelVariables:
            if var.causality != "output":
                continue
            deps = declared.get(var.name)
            self.dependencies[var.name] = (list(inputs) if deps is None else
                                           [d.name for d in deps if d.causality == "input"])

    def variable(self, name: str, role: str):
        """The model variable ``name`` or a :class:`CoSimulationError` naming the role."""
        try:
            return self.variables[name]
        except KeyError:
            raise CoSimulationError(
                f"{role}: component '{self.name}' ({self.path.name}) has no variable '{name}'"
            ) from None

    def has_output(self, name: str) -> bool:
        var = self.variables.get(name)
        return var is not None and var.causality == "output"


class _Guard:
    """Turns an FMICallException of one instance into FMUError (a class: cheaper than a
    generator-based context manager on the per-step path)."""

    __slots__ = ("inst", "what")

    def __init__(self, inst: "_Instance", what: str):
        self.inst, self.what = inst, what

    def __enter__(self) -> None:
        return None

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None or not issubclass(exc_type, FMICallException):
            return False
        inst = self.inst
        inst.failed_status = exc.status
        status = _STATUS[exc.status] if 0 <= exc.status < len(_STATUS) else str(exc.status)
        raise FMUError(inst.name, inst.path, exc.function or self.what, status,
                       list(inst.messages)) from None


_GETTERS = {"Real": "getReal", "Integer": "getInteger", "Boolean": "getBoolean"}
_SETTERS = {"Real": "setReal", "Integer": "setInteger", "Boolean": "setBoolean"}


def _convert(value: Any, type_: str) -> Any:
    if type_ == "Real":
        return float(value)
    if type_ == "Integer":
        return int(round(float(value)))
    if type_ == "Boolean":
        return bool(value)
    raise CoSimulationError(f"unsupported variable type {type_}")


class CoSimulation:
    """Loads the components of a :class:`System` and runs the co-simulation.

    Use as a context manager (instances are freed on exit, also on errors)::

        with CoSimulation(system, start_time=0.0, stop_time=1.5) as sim:
            result = sim.run()

    Args:
        system: components, connections, sources and probes.
        start_time: first communication point [s].
        stop_time: last communication point [s] (> start_time).
        comm_step: nominal communication step [s] (> 0); points lie on
            start_time + k comm_step except where events cut a step.
        switch_tol: a switch closer than this to a communication point counts as lying on
            it [s].
        event_tol: a time event closer than this to a grid point replaces it [s].
        max_rollbacks: rollbacks allowed per step before the nearest point is accepted.
        progress: show a tqdm progress bar.
        fmi_call_logger: called with a text line for every FMI call (debugging).
    """

    def __init__(self, system: System, start_time: float, stop_time: float,
                 comm_step: float = 1e-3, switch_tol: float = 1e-9, event_tol: float = 1e-10,
                 max_rollbacks: int = 30, progress: bool = False,
                 fmi_call_logger: Callable[[str], None] | None = None):
        for name, value in (("start_time", start_time), ("stop_time", stop_time),
                            ("comm_step", comm_step)):
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(name, value, "a finite number of seconds")
        if comm_step <= 0:
            raise ParameterError("comm_step", comm_step, "a communication step > 0 s")
        if stop_time <= start_time:
            raise ParameterError("stop_time", stop_time, f"a time > start_time = {start_time} s")
        self.system = system
        self.start_time = float(start_time)
        self.stop_time = float(stop_time)
        self.comm_step = float(comm_step)
        self.switch_tol = float(switch_tol)
        self.event_tol = float(event_tol)
        self.max_rollbacks = int(max_rollbacks)
        self.progress = progress
        self.fmi_call_logger = fmi_call_logger
        self._instances: dict[str, _Instance] = {}
        self._callbacks: fmi2CallbackFunctions | None = None
        self._logger_ref = None
        self.propagation_order: list[str] = []
        self._plan: list[tuple] = []
        self._last_values: dict[str, Any] = {}

    # ------------------------------------------------------------------ lifecycle
    def __enter__(self) -> "CoSimulation":
        try:
            self.load()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def load(self) -> None:
        """Extract and instantiate every FMU, check names, build the propagation plan."""
        for comp in self.system.components:
            path = comp.fmu.resolve()
            if not path.is_file():
                raise CoSimulationError(f"component '{comp.name}': FMU file {comp.fmu} not found")
            self._instances[comp.name] = _Instance(comp.name, path, _extracted(path))
        self._check_names()
        self._build_plan()
        self._make_callbacks()
        for inst in self._instances.values():
            inst.slave = FMU2Slave(guid=inst.md.guid, unzipDirectory=str(inst.unzipdir),
                                   modelIdentifier=inst.md.coSimulation.modelIdentifier,
                                   instanceName=inst.name,
                                   fmiCallLogger=self.fmi_call_logger)
            with self._guard(inst, "fmi2Instantiate"):
                try:
                    inst.slave.instantiate(callbacks=self._callbacks, loggingOn=True)
                except FMICallException:
                    raise
                except Exception as exc:  # fmpy raises a bare Exception here
                    raise FMUError(inst.name, inst.path, "fmi2Instantiate", "failed",
                                   list(inst.messages) or [str(exc)]) from None
            inst.instantiated = True

    def close(self) -> None:
        """Terminate and free every instance (the extracted files stay cached, see
        :func:`_extracted`)."""
        for inst in self._instances.values():
            if inst.slave is None or not inst.instantiated:
                continue
            if inst.failed_status >= _FATAL:
                # FMI 2.0 sec. 2.1.3: after fmi2Fatal no function of the instance may be
                # called, not even fmi2FreeInstance (pythonfmu corrupts the heap if one
                # frees an instance whose exitInitializationMode raised).
                inst.instantiated = False
                inst.abandoned = True
                continue
            if inst.initialized and inst.failed_status < _ERROR:
                try:
                    inst.slave.terminate()
                except Exception:  # an instance in error state may refuse; free it anyway
                    pass
            try:
                # fmi2FreeInstance without fmpy's dlclose: unloading a pythonfmu (cppfmu)
                # library leaves the interpreter to crash at garbage collection or exit
                # (FMPy issue #147, PythonFMU issue #229). The library stays mapped; the
                # extraction cache below loads each FMU file once per process.
                inst.slave.fmi2FreeInstance(inst.slave.component)
            except Exception:
                pass
            inst.instantiated = False
            inst.initialized = False

    @property
    def live_instances(self) -> list[str]:
        """Names of the instances not yet freed (nor abandoned)."""
        return [i.name for i in self._instances.values() if i.instantiated]

    @property
    def abandoned_instances(self) -> list[str]:
        """Instances left unfreed because they reported fmi2Fatal (FMI forbids any call)."""
        return [i.name for i in self._instances.values() if i.abandoned]

    def _make_callbacks(self) -> None:
        by_name = self._instances

        def logger(env, instance_name, status, category, message):  # called from C
            try:
                name = instance_name.decode("utf-8", "replace") if instance_name else ""
                text = message.decode("utf-8", "replace") if message else ""
                label = _STATUS[status] if 0 <= status < len(_STATUS) else str(status)
                inst = by_name.get(name)
                if inst is not None:
                    inst.messages.append(f"[{label}] {_clean_message(text)}")
            except Exception:  # never let an exception cross the C boundary
                pass

        callbacks = fmi2CallbackFunctions()
        self._logger_ref = fmi2CallbackLoggerTYPE(logger)
        callbacks.logger = self._logger_ref
        callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
        callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
        try:  # formats the variadic message arguments in C
            from fmpy.logging import addLoggerProxy
            addLoggerProxy(ctypes.byref(callbacks))
        except Exception:  # pragma: no cover - missing platform library
            pass
        self._callbacks = callbacks

    def _guard(self, inst: _Instance, what: str) -> "_Guard":
        """Context turning an FMI failure of ``inst`` into :class:`FMUError`."""
        return _Guard(inst, what)

    # ------------------------------------------------------------------ structure
    def _resolve(self, qualified: str, role: str, causality: tuple[str, ...] | None = None):
        comp, var_name = split_name(qualified, role)
        inst = self._instances[comp]
        var = inst.variable(var_name, f"{role} '{qualified}'")
        if causality is not None and var.causality not in causality:
            raise CoSimulationError(f"{role} '{qualified}': the variable has causality "
                                    f"'{var.causality}', expected {' or '.join(causality)}")
        if var.type not in _GETTERS:
            raise CoSimulationError(f"{role} '{qualified}': unsupported type {var.type}")
        return inst, var

    def _check_names(self) -> None:
        for comp in self.system.components:
            inst = self._instances[comp.name]
            for name in comp.parameters:
                var = inst.variable(name, "parameter")
                if var.causality not in ("parameter", "input") or var.variability == "constant":
                    raise CoSimulationError(
                        f"parameter '{comp.name}.{name}': causality '{var.causality}' "
                        f"variability '{var.variability}' cannot be set")
        for conn in self.system.connections:
            _, src = self._resolve(conn.src, "connection source", ("output",))
            _, dst = self._resolve(conn.dst, "connection destination", ("input",))
            if src.type != dst.type and not (src.type == "Integer" and dst.type == "Real"):
                raise CoSimulationError(f"connection {conn.src} -> {conn.dst}: type {src.type} "
                                        f"cannot feed type {dst.type}")
        for source in self.system.sources:
            self._resolve(source.dst, "source destination", ("input",))
        for column, qualified in self.system.probes.items():
            self._resolve(qualified, f"probe '{column}'")

    def _build_plan(self) -> None:
        """Topologically sort connected variables and group the FMI calls."""
        graph: dict[str, set[str]] = {}  # node -> predecessors
        feeds: dict[str, Any] = {}  # input node -> source node or callable
        for conn in self.system.connections:
            graph.setdefault(conn.src, set())
            graph.setdefault(conn.dst, set()).add(conn.src)
            feeds[conn.dst] = conn.src
        for source in self.system.sources:
            graph.setdefault(source.dst, set())
            feeds[source.dst] = source.function
        driven_inputs = set(feeds)
        for node in list(graph):
            comp, var_name = split_name(node)
            inst = self._instances[comp]
            if inst.variables[var_name].causality == "output":
                for dep in inst.dependencies.get(var_name, []):
                    dep_node = f"{comp}.{dep}"
                    if dep_node in driven_inputs:
                        graph[node].add(dep_node)
        sorter = graphlib.TopologicalSorter(graph)
        try:
            sorter.prepare()
        except graphlib.CycleError as exc:
            cycle = list(exc.args[1])
            raise AlgebraicLoopError(cycle) from None
        order: list[str] = []
        plan: list[tuple] = []
        while sorter.is_active():
            ready = sorted(sorter.get_ready())
            gets = [n for n in ready if n not in feeds]
            sets = [n for n in ready if n in feeds]
            # Within one batch nothing depends on anything else: read first, then write,
            # grouped by component and type so that each group is one FMI call.
            for kind, nodes in (("get", gets), ("set", sets)):
                groups: dict[tuple[str, str], list[str]] = {}
                for node in nodes:
                    inst, var = self._resolve(node, "variable")
                    groups.setdefault((inst.name, var.type), []).append(node)
                for (comp, type_), members in groups.items():
                    inst = self._instances[comp]
                    vrs = [inst.variables[split_name(n)[1]].valueReference for n in members]
                    if kind == "get":
                        plan.append(("get", inst, type_, vrs, members))
                    else:
                        plan.append(("set", inst, type_, vrs, [feeds[n] for n in members]))
                    order.extend(members)
            sorter.done(*ready)
        self.propagation_order = order
        self._plan = plan
        # Probes grouped by component and type.
        probe_groups: dict[tuple[str, str], list[tuple[int, int]]] = {}
        self._probe_columns = list(self.system.probes)
        for col_index, (column, qualified) in enumerate(self.system.probes.items()):
            inst, var = self._resolve(qualified, f"probe '{column}'")
            probe_groups.setdefault((inst.name, var.type), []).append(
                (col_index, var.valueReference))
        self._probe_plan = [(self._instances[c], t, [i for i, _ in m], [v for _, v in m])
                            for (c, t), m in probe_groups.items()]
        # Special outputs.
        self._event_plan = []
        self._switch_plan = []
        for inst in self._instances.values():
            if inst.has_output(NEXT_EVENT_OUTPUT):
                self._event_plan.append((inst, inst.variables[NEXT_EVENT_OUTPUT].valueReference))
            if inst.has_output(SWITCH_COUNT_OUTPUT) and inst.has_output(SWITCH_TIME_OUTPUT):
                count_var = inst.variables[SWITCH_COUNT_OUTPUT]
                time_var = inst.variables[SWITCH_TIME_OUTPUT]
                mode_var = (inst.variables[SWITCH_STATE_OUTPUT]
                            if inst.has_output(SWITCH_STATE_OUTPUT) else None)
                first_var = (inst.variables[FIRST_SWITCH_OUTPUT]
                             if inst.has_output(FIRST_SWITCH_OUTPUT) else None)
                self._switch_plan.append((inst, count_var, time_var, mode_var, first_var))
        if self._switch_plan:
            missing = [i.name for i in self._instances.values() if not i.can_get_state]
            if missing:
                raise CoSimulationError(
                    f"components {missing} cannot get and set their state "
                    "(canGetAndSetFMUstate is false), which the switch rollback needs")

    # ------------------------------------------------------------------ data flow
    def _get(self, inst: _Instance, type_: str, vrs: list[int]) -> list:
        with self._guard(inst, f"fmi2Get{type_}"):
            return getattr(inst.slave, _GETTERS[type_])(vrs)

    def _set(self, inst: _Instance, type_: str, vrs: list[int], values: list) -> None:
        with self._guard(inst, f"fmi2Set{type_}"):
            getattr(inst.slave, _SETTERS[type_])(vrs, values)

    def propagate(self, t: float, held: frozenset[str] = frozenset()) -> None:
        """Set every driven input from its producer at time ``t`` (Gauss-Seidel sweep).

        Outputs of the components named in ``held`` keep the values of the previous sweep
        (their left limits at a time event of theirs, see :meth:`run`).
        """
        values: dict[str, Any] = {}
        for kind, inst, type_, vrs, payload in self._plan:
            if kind == "get":
                if inst.name in held:
                    for node in payload:
                        values[node] = self._last_values[node]
                else:
                    for node, value in zip(payload, self._get(inst, type_, vrs)):
                        values[node] = value
            else:
                new = [_convert(f(t) if callable(f) else values[f], type_) for f in payload]
                self._set(inst, type_, vrs, new)
        if not held:
            self._last_values = values

    def _read_probes(self, held: frozenset[str] = frozenset(),
                     previous: list | None = None) -> list:
        row = [0.0] * len(self._probe_columns)
        for inst, type_, columns, vrs in self._probe_plan:
            if inst.name in held and previous is not None:
                for col in columns:
                    row[col] = previous[col]
            else:
                for col, value in zip(columns, self._get(inst, type_, vrs)):
                    row[col] = value
        return row

    def _next_events(self, t: float) -> tuple[float, frozenset[str]]:
        """Earliest ``next_event_time`` after t [s] and the components that announce it."""
        earliest, owners = math.inf, set()
        for inst, vr in self._event_plan:
            value = self._get(inst, "Real", [vr])[0]
            if math.isnan(value) or value <= t + self.event_tol:
                continue
            if value < earliest - self.event_tol:
                earliest, owners = value, {inst.name}
            elif abs(value - earliest) <= self.event_tol:
                owners.add(inst.name)
        return earliest, frozenset(owners)

    def _switch_info(self) -> list[tuple[int, float, float | None, float | None]]:
        """(switch_count, t_last_switch, mode, t_first_step_switch) of each switching FMU."""
        info = []
        for inst, count_var, time_var, mode_var, first_var in self._switch_plan:
            # One FMI call per type: group the variables of each type.
            wanted = [count_var, time_var, mode_var, first_var]
            values: list[Any] = [None] * 4
            by_type: dict[str, list[int]] = {}
            for i, var in enumerate(wanted):
                if var is not None:
                    by_type.setdefault(var.type, []).append(i)
            for type_, indices in by_type.items():
                got = self._get(inst, type_, [wanted[i].valueReference for i in indices])
                for i, value in zip(indices, got):
                    values[i] = value
            count, t_last, mode, t_first = values
            info.append((int(count), float(t_last), mode,
                         None if t_first is None else float(t_first)))
        return info

    # ------------------------------------------------------------------ run
    def initialize(self) -> None:
        """Set parameters, run the initialisation mode, propagate at the start time."""
        for comp in self.system.components:
            inst = self._instances[comp.name]
            with self._guard(inst, "fmi2SetupExperiment"):
                inst.slave.setupExperiment(startTime=self.start_time, stopTime=self.stop_time)
            by_type: dict[str, tuple[list[int], list]] = {}
            for name, value in comp.parameters.items():
                var = inst.variables[name]
                vrs, vals = by_type.setdefault(var.type, ([], []))
                vrs.append(var.valueReference)
                vals.append(_convert(value, var.type))
            for type_, (vrs, vals) in by_type.items():
                self._set(inst, type_, vrs, vals)
        for inst in self._instances.values():
            with self._guard(inst, "fmi2EnterInitializationMode"):
                inst.slave.enterInitializationMode()
            inst.initialized = True
        for inst in self._instances.values():
            with self._guard(inst, "fmi2ExitInitializationMode"):
                inst.slave.exitInitializationMode()
        self.propagate(self.start_time)

    def run(self) -> CoSimResult:
        """Initialise and co-simulate from ``start_time`` to ``stop_time``."""
        if not self._instances or self.live_instances == []:
            raise CoSimulationError("the co-simulation is not loaded (use it as a context manager)")
        self.initialize()
        times: list[float] = []
        sides: list[int] = []
        rows: list[list] = []
        switches: list[SwitchEvent] = []
        time_events: list[float] = []
        notes: list[str] = []
        stats = {"steps": 0, "rollbacks": 0, "do_steps": 0}

        def record(t: float, side: int, held: frozenset[str] = frozenset()) -> None:
            times.append(t)
            sides.append(side)
            rows.append(self._read_probes(held, rows[-1] if rows else None))

        bar = None
        if self.progress:
            from tqdm import tqdm
            bar = tqdm(total=self.stop_time - self.start_time, unit="s", leave=False)
        try:
            t = self.start_time
            record(t, 0)
            n_grid = 0  # t lies at or after start + n_grid * comm_step
            switch_state = self._switch_info()
            while self.stop_time - t > self.event_tol:
                while self.start_time + (n_grid + 1) * self.comm_step <= t + self.event_tol:
                    n_grid += 1
                t_grid = self.start_time + (n_grid + 1) * self.comm_step
                t_event, event_owners = self._next_events(t)
                target = min(t_grid, self.stop_time)
                hit_event = t_event <= target + self.event_tol
                if hit_event:
                    target = t_event
                if self.stop_time - target <= self.event_tol:
                    target = self.stop_time
                t_new, new_switches, switch_state = self._advance(
                    t, target - t, switch_state, notes, stats)
                stats["steps"] += 1
                switches.extend(new_switches)
                at_switch = any(s.located and abs(s.time - t_new) <= self.switch_tol
                                for s in new_switches)
                hit_event = hit_event and abs(t_new - target) <= self.event_tol
                if hit_event:
                    time_events.append(t_new)
                if hit_event or at_switch:
                    # Left limit: the event's owners are piecewise constant between their
                    # events, so their outputs keep the values before the step.
                    held = event_owners if hit_event else frozenset()
                    self.propagate(t_new, held)
                    record(t_new, -1, held)
                    if held:
                        self.propagate(t_new)
                    record(t_new, +1)
                else:
                    self.propagate(t_new)
                    record(t_new, 0)
                if bar is not None:
                    bar.update(t_new - t)
                t = t_new
        finally:
            if bar is not None:
                bar.close()
        values = {col: np.array([row[i] for row in rows])
                  for i, col in enumerate(self._probe_columns)}
        return CoSimResult(time=np.array(times), side=np.array(sides, dtype=np.int8),
                           values=values, switches=switches, time_events=time_events,
                           notes=notes, stats=stats)

    def _do_step(self, t: float, h: float, stats: dict[str, int]) -> None:
        for inst in self._instances.values():
            with self._guard(inst, "fmi2DoStep"):
                inst.slave.doStep(t, h, noSetFMUStatePriorToCurrentPoint=False)
        stats["do_steps"] += 1

    def _advance(self, t: float, h: float, before: list, notes: list[str],
                 stats: dict[str, int]) -> tuple[float, list[SwitchEvent], list]:
        """One accepted step from ``t``: at most ``h``, cut back to the first inner switch."""
        if not self._switch_plan:
            self._do_step(t, h, stats)
            return t + h, [], before
        states = []
        try:
            for inst in self._instances.values():
                with self._guard(inst, "fmi2GetFMUstate"):
                    states.append((inst, inst.slave.getFMUstate()))
            tries = 0
            while True:
                self._do_step(t, h, stats)
                after = self._switch_info()
                inner, crowded = self._inner_switches(t, h, before, after)
                if not inner and not crowded:
                    break
                if tries >= self.max_rollbacks:
                    notes.append(f"step from t = {t:.12g} s: switches not separated after "
                                 f"{tries} rollbacks; accepted the step to {t + h:.12g} s")
                    break
                for inst, state in states:
                    with self._guard(inst, "fmi2SetFMUstate"):
                        inst.slave.setFMUstate(state)
                stats["rollbacks"] += 1
                tries += 1
                # Land on the first inner switch; halve when an FMU cannot say where it is.
                h = min([ts - t for ts in inner] + ([h / 2.0] if crowded else []))
        finally:
            for inst, state in states:
                try:
                    inst.slave.freeFMUstate(state)
                except Exception:
                    pass
        t_new = t + h
        events = []
        for (inst, *_), (c0, _, m0, _), (c1, t_last, m1, t_first) in zip(
                self._switch_plan, before, after):
            if c1 <= c0:
                continue
            # (time, count, mode before, mode after); intermediate modes are unknown.
            found = [(t_last, c1, m0 if c1 - c0 == 1 else None, m1)]
            if c1 - c0 >= 2 and t_first is not None:
                found.insert(0, (t_first, c0 + 1, m0, None))
            for t_sw, count, mode_before, mode_after in found:
                located = min(abs(t_sw - t_new), abs(t_sw - t)) <= self.switch_tol
                if not located:
                    notes.append(f"switch of '{inst.name}' at t = {t_sw:.12g} s accepted at the "
                                 f"nearest communication point {t_new:.12g} s")
                events.append(SwitchEvent(time=t_sw, component=inst.name, count=count,
                                          before=mode_before, after=mode_after, located=located))
        return t_new, events, after

    def _inner_switches(self, t: float, h: float, before: list,
                        after: list) -> tuple[list[float], bool]:
        """Switch times strictly inside (t, t + h) to land on, and whether some FMU had
        several switches in the step without saying where the first inner one is."""
        tol = self.switch_tol

        def inside(ts: float) -> bool:
            return t + tol < ts < t + h - tol

        inner: list[float] = []
        crowded = False
        for (c0, _, _, _), (c1, t_last, _, t_first) in zip(before, after):
            n = c1 - c0
            if n == 1:
                if inside(t_last):
                    inner.append(t_last)
            elif n > 1:
                if t_first is None:
                    crowded = True  # only the last switch is known
                elif inside(t_first):
                    inner.append(t_first)
                elif abs(t_first - t) <= tol and n == 2:
                    if inside(t_last):  # one at the start, the other inside
                        inner.append(t_last)
                elif t_first < t + h - tol:
                    crowded = True  # the first at the start, more than one after it
        return inner, crowded


_EXTRACT_ROOT: tempfile.TemporaryDirectory | None = None
_EXTRACTED: dict[tuple[Path, int, int], Path] = {}


def _extracted(path: Path) -> Path:
    """Directory holding the extracted ``path``, extracted once per process and file version.

    The shared libraries are never unloaded (see :meth:`CoSimulation.close`), so loading the
    same extracted library again reuses it instead of mapping one more copy per run. The
    directory is removed at interpreter exit.
    """
    global _EXTRACT_ROOT
    stat = path.stat()
    key = (path, stat.st_mtime_ns, stat.st_size)
    if key not in _EXTRACTED:
        if _EXTRACT_ROOT is None:
            _EXTRACT_ROOT = tempfile.TemporaryDirectory(prefix="abu_cosim_",
                                                        ignore_cleanup_errors=True)
        target = Path(_EXTRACT_ROOT.name) / f"{len(_EXTRACTED)}_{path.stem}"
        _EXTRACTED[key] = Path(fmpy.extract(str(path), unzipdir=str(target)))
    return _EXTRACTED[key]


def simulate(system: System, start_time: float, stop_time: float, comm_step: float = 1e-3,
             **options: Any) -> CoSimResult:
    """Load, run and free in one call (see :class:`CoSimulation` for the options)."""
    with CoSimulation(system, start_time, stop_time, comm_step, **options) as sim:
        return sim.run()


def _clean_message(text: str) -> str:
    """Shorten pythonfmu's 'Fatal py exception encountered: [...] PyObject_CallMethod\\n X("msg")'."""
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    if len(lines) > 1 and "py exception" in lines[0].lower():
        return lines[-1]
    return " ".join(lines)
