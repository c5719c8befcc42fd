"""Co-simulation master on fmpy's ``FMU2Slave`` (FMI 2.0 co-simulation): the entry point.

The master's parts, one job each (like ``scipy.integrate._ivp``'s entry function, solver
classes and event functions):

* :mod:`harness.cosim.fmi`: loaded instances, FMI error guard, logger, extraction cache;
* :mod:`harness.cosim.plan`: propagation order and grouped reads/writes of a point;
* :mod:`harness.cosim.stepping`: coupling error estimate, step-size controller, switch location;
* :mod:`harness.cosim.recording`: rows, left/right limits, the result;
* here: :class:`CoSimulation` (load, reset for reuse, initialise, the stepping loop, free)
  and :func:`simulate`.

At each step from t the master saves every FMU's state, steps all FMUs to the proposal
(cut to the earliest announced time event and to the stop time), lands on the first switch
inside the step by rollback, propagates (Gauss-Seidel at variable level), estimates the
coupling error and rejects the step by rollback if it exceeds ``tol``. Error control is the
default; with ``comm_step`` and no ``tol`` the points lie on ``start + k comm_step`` (fixed
step), still cut at events and switches.
"""
from __future__ import annotations

import math
from typing import Any, Callable

from fmpy.fmi1 import FMICallException
from fmpy.fmi2 import FMU2Slave

from abu_model.errors import ParameterError

from harness.cosim.fmi import (ERROR, FATAL, AlgebraicLoopError, CoSimulationError, FMUError, Guard,
                  Instance, convert, extracted, make_callbacks)
from harness.cosim.fmi_ops import StepOps
from harness.cosim.plan import build_plan, check_names
from harness.cosim.point import CompiledPoint, compile_point
from harness.cosim.recording import CoSimResult, SwitchEvent
from harness.cosim.stepping import DEFAULT_FIRST_STEP, DEFAULT_MAX_STEP, DEFAULT_TOL, ErrorControl
from harness.cosim.system import System

__all__ = ["AlgebraicLoopError", "CoSimResult", "CoSimulation", "CoSimulationError",
           "FMUError", "SwitchEvent", "simulate", "DEFAULT_TOL"]


class CoSimulation(StepOps):
    """Loads the components of a :class:`System` and runs the co-simulation.

    Use as a context manager (instances are freed on exit, also on errors)::

        with CoSimulation(system, start_time=0.0, stop_time=1.5) as sim:
            result = sim.run()
            sim.reuse(other_system_same_structure)   # fmi2Reset instead of reloading
            result2 = sim.run()

    Args:
        system: components, connections, sources, probes and holds.
        start_time, stop_time: first and last communication point [s].
        comm_step: communication step [s]; without ``tol`` the fixed step (points on
            start_time + k comm_step), with ``tol`` the first step.
        tol: coupling error tolerance [-] (see :mod:`harness.cosim.stepping`). Neither
            ``comm_step`` nor ``tol``: :data:`DEFAULT_TOL` if the system declares holds
            (:class:`~harness.cosim.system.Hold`), else fixed steps of 1 ms.
        max_step: largest step in error-controlled mode [s].
        switch_tol: a switch closer than this to a communication point lies on it [s].
        event_tol: a time event closer than this to a proposed point replaces it [s].
        max_rollbacks: rollbacks allowed per step before the nearest point is accepted.
        progress: show a tqdm progress bar; fmi_call_logger: called with a text line for
            every FMI call (debugging).
    """

    def __init__(self, system: System, start_time: float, stop_time: float,
                 comm_step: float | None = None, *, tol: float | None = None,
                 max_step: float = DEFAULT_MAX_STEP, switch_tol: float = 1e-9,
                 event_tol: float = 1e-10, max_rollbacks: int = 30, progress: bool = False,
                 fmi_call_logger: Callable[[str], None] | None = None):
        self.system = system
        self.set_stepping(comm_step, tol, max_step)
        self._set_times(start_time, stop_time)
        self.switch_tol = float(switch_tol)
        self.event_tol = float(event_tol)
        self.max_rollbacks = int(max_rollbacks)
        self.progress = progress
        self.fmi_call_logger = fmi_call_logger
        self._instances: dict[str, Instance] = {}
        self._callbacks: Any = None
        self._logger_ref = None
        self.plan = None
        self._last: dict[str, Any] = {}
        self._last_sets: list[tuple] = []
        self._calls = 0
        self._used = False
        self._fast: dict[Any, Any] = {}
        self._point: CompiledPoint | None = None  # the plan compiled (run), see propagate

    def set_stepping(self, comm_step: float | None = None, tol: float | None = None,
                     max_step: float = DEFAULT_MAX_STEP) -> None:
        """Fixed step ``comm_step`` [s] (no ``tol``) or error control (``tol``, first step
        ``comm_step``, largest ``max_step`` [s]); neither: error control at DEFAULT_TOL."""
        if comm_step is not None:
            _check_positive("comm_step", comm_step, "a communication step > 0 s")
        if tol is not None:
            _check_positive("tol", tol, "a tolerance > 0")
        _check_positive("max_step", max_step, "a largest step > 0 s")
        # Neither given: error control at DEFAULT_TOL if the system declares its holds,
        # else fixed steps of DEFAULT_FIRST_STEP (see error_control).
        self._default_mode = comm_step is None and tol is None
        if self._default_mode:
            tol = DEFAULT_TOL
        self.comm_step = None if comm_step is None else float(comm_step)
        self.tol = None if tol is None else float(tol)
        self.max_step = float(max_step)

    def _set_times(self, start_time: float, stop_time: float) -> None:
        for name, value in (("start_time", start_time), ("stop_time", stop_time)):
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ParameterError(name, value, "a finite number of seconds")
        if stop_time <= start_time:
            raise ParameterError("stop_time", stop_time, f"a time > start_time = {start_time} s")
        self.start_time, self.stop_time = float(start_time), float(stop_time)

    @property
    def propagation_order(self) -> list[str]:
        return [] if self.plan is None else list(self.plan.order)

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
            self._instances[comp.name] = Instance(comp.name, path, extracted(path))
        self._prepare()
        self._callbacks, self._logger_ref = make_callbacks(self._instances)
        for inst in self._instances.values():
            inst.slave = FMU2Slave(guid=inst.md.guid, unzipDirectory=str(inst.unzipdir),
                                   modelIdentifier=inst.md.coSimulation.modelIdentifier,
                                   instanceName=inst.name, fmiCallLogger=self.fmi_call_logger)
            with Guard(inst, "fmi2Instantiate"):
                try:
                    inst.slave.instantiate(callbacks=self._callbacks, loggingOn=True)
                except FMICallException:
                    raise
                except Exception as exc:  # fmpy raises a bare Exception here
                    raise FMUError(inst.name, inst.path, "fmi2Instantiate", "failed",
                                   list(inst.messages) or [str(exc)]) from None
            inst.instantiated = True

    def _prepare(self) -> None:
        check_names(self.system, self._instances)
        self.plan = build_plan(self.system, self._instances)
        self._node_comp = {}
        for reads in (self.plan.pre_reads, self.plan.tail_reads):
            for inst, _, _, nodes in reads:
                self._node_comp.update((n, inst.name) for n in nodes)
        if self.plan.switches:
            missing = [i.name for i in self._instances.values() if not i.can_get_state]
            if missing:
                raise CoSimulationError(
                    f"components {missing} cannot get and set their state "
                    "(canGetAndSetFMUstate is false), which the switch rollback needs")
        if self.error_control_on and not all(i.can_get_state for i in self._instances.values()):
            raise CoSimulationError("error-controlled steps need fmi2GetFMUstate in every "
                                    "component: give a fixed comm_step instead")

    def reuse(self, system: System | None = None, start_time: float | None = None,
              stop_time: float | None = None) -> None:
        """Make the loaded instances ready for another run (``fmi2Reset``): new parameters
        and source functions, same structure (:meth:`System.structure_key`)."""
        if system is not None:
            if system.structure_key() != self.system.structure_key():
                raise CoSimulationError("reuse needs a system of the same structure "
                                        "(components, FMUs, connections, probes, holds)")
            self.system = system
            if system.sources:  # new source functions (without them: the same plan)
                self.plan = build_plan(system, self._instances)
                self._fast.clear()
        self._set_times(self.start_time if start_time is None else start_time,
                        self.stop_time if stop_time is None else stop_time)
        self._reset_instances()

    def _reset_instances(self) -> None:
        for inst in self._instances.values():
            if not inst.instantiated:
                raise CoSimulationError(f"component '{inst.name}' is not loaded")
            with Guard(inst, "fmi2Reset"):
                inst.slave.reset()
            inst.initialized = False
        self._used = False

    def close(self) -> None:
        """Terminate and free every instance (the extracted files stay cached)."""
        for inst in self._instances.values():
            if inst.slave is None or not inst.instantiated:
                continue
            if inst.failed_status >= FATAL:
                # FMI 2.0 sec. 2.1.3: after fmi2Fatal no function of the instance may be
                # called, not even fmi2FreeInstance (pythonfmu corrupts the heap if one
                # frees an instance whose exitInitializationMode raised).
                inst.instantiated = False
                inst.abandoned = True
                continue
            if inst.initialized and inst.failed_status < ERROR:
                try:
                    inst.slave.terminate()
                except Exception:  # an instance in error state may refuse; free it anyway
                    pass
            try:
                # fmi2FreeInstance without fmpy's dlclose: unloading a Python FMU's library
                # crashes the interpreter later (FMPy issue #147, PythonFMU issue #229).
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

    @property
    def healthy(self) -> bool:
        """True if every instance is loaded and none has failed (safe to reuse)."""
        return bool(self._instances) and all(
            i.instantiated and i.failed_status < ERROR for i in self._instances.values())

    # ------------------------------------------------------------------ data flow

    def read_outputs(self) -> dict[str, Any]:
        """Input-independent outputs (states, switch and event outputs), once per point."""
        values: dict[str, Any] = {}
        point = self._point
        if point is not None and point.plan is self.plan:
            for read in point.pre:
                read(0.0, values, None)
            self._calls += len(point.pre)
            return values
        for inst, type_, vrs, nodes in self.plan.pre_reads:
            values.update(zip(nodes, self._get(inst, type_, vrs)))
        return values

    def propagate(self, t: float, pre: dict[str, Any], held: frozenset[str] = frozenset(),
               commit: bool = True) -> dict[str, Any]:
        """Set every driven input from its producer at ``t`` [s]; the point's values.

        Outputs of the components in ``held`` keep the values of the last full sweep (their
        left limits at a time event of theirs: they are piecewise constant between events).
        """
        point = self._point
        if not held and point is not None and point.plan is self.plan:
            values, sets = dict(pre), []
            for op in point.sweep:
                op(t, values, sets)
            for read in point.tail:
                read(t, values, sets)
            self._calls += point.sweep_calls
            self._trial = (values, sets)
            if commit:
                self.commit()
            return values
        last = self._last
        values = dict(pre)
        if held:
            comp = self._node_comp
            for node in pre:
                if comp[node] in held:
                    values[node] = last[node]
        sets = []
        for entry in self.plan.sweep:
            if entry[0] == "get":
                _, inst, type_, vrs, nodes = entry
                if inst.name in held:
                    for node in nodes:
                        values[node] = last[node]
                else:
                    values.update(zip(nodes, self._get(inst, type_, vrs)))
            else:
                _, inst, type_, vrs, feeds, nodes = entry
                new = [convert(f(t) if callable(f) else values[f], type_) for f in feeds]
                self._set(inst, type_, vrs, new)
                values.update(zip(nodes, new))
                sets.append((inst, type_, vrs, new))
        for inst, type_, vrs, nodes in self.plan.tail_reads:
            if inst.name in held:
                for node in nodes:
                    values[node] = last[node]
            else:
                values.update(zip(nodes, self._get(inst, type_, vrs)))
        self._trial = (values, sets)
        if not held and commit:
            self.commit()
        return values

    @property
    def fmi_calls(self) -> int:
        """FMI calls made by this run so far (counted by :mod:`harness.cosim.fmi_ops`)."""
        return self._calls

    def commit(self) -> None:
        """Make the last full sweep the reference for held outputs and for re-setting the
        inputs after a rollback (call once its point is accepted)."""
        self._last, self._last_sets = self._trial

    # ------------------------------------------------------------------ run
    def initialize(self) -> dict[str, Any]:
        """Set parameters, run the initialisation mode, propagate at the start time."""
        if self._used:
            self._reset_instances()
        self._used = True
        for comp in self.system.components:
            inst = self._instances[comp.name]
            with Guard(inst, "fmi2SetupExperiment"):
                inst.slave.setupExperiment(startTime=self.start_time, stopTime=self.stop_time)
            by_type: dict[str, tuple[list[int], list]] = {}
            for name, value in comp.parameters.items():
                var = inst.variables[name]
                vrs, vals = by_type.setdefault(var.type, ([], []))
                vrs.append(var.valueReference)
                vals.append(convert(value, var.type))
            for type_, (vrs, vals) in by_type.items():
                self._set(inst, type_, vrs, vals, cache=False)
        for inst in self._instances.values():
            with Guard(inst, "fmi2EnterInitializationMode"):
                inst.slave.enterInitializationMode()
            inst.initialized = True
        for inst in self._instances.values():
            with Guard(inst, "fmi2ExitInitializationMode"):
                inst.slave.exitInitializationMode()
        pre = self.read_outputs()
        self._last = pre
        return self.propagate(self.start_time, pre)

    def run(self) -> CoSimResult:
        """Initialise and co-simulate from ``start_time`` to ``stop_time``."""
        if not self._instances or self.live_instances == []:
            raise CoSimulationError("the co-simulation is not loaded (use it as a context manager)")
        from harness.cosim.runner import Runner  # the stepping loop

        self._calls = 0
        # The plan compiled into direct calls, unless every call must pass through the
        # logged fmpy wrappers or through _get/_set replaced on this instance (a test's probe).
        direct = self.fmi_call_logger is None and not {"_get", "_set"} & vars(self).keys()
        if not direct:
            self._point = None
        elif self._point is None or self._point.plan is not self.plan:
            self._point = compile_point(self.plan)
        return Runner(self).run()

    def error_control(self) -> ErrorControl | None:
        """The step-size controller, or None for fixed steps of :attr:`fixed_step`."""
        if not self.error_control_on:
            return None
        return ErrorControl(self.tol, self.plan.holds, h_max=self.max_step)

    @property
    def error_control_on(self) -> bool:
        return self.tol is not None and not (self._default_mode and not self.system.holds)

    @property
    def fixed_step(self) -> float:
        """Step of the fixed-step mode [s]."""
        return self.comm_step if self.comm_step is not None else DEFAULT_FIRST_STEP

    def first_step(self) -> float:
        return self.comm_step if self.comm_step is not None else DEFAULT_FIRST_STEP


def _check_positive(name: str, value: Any, expected: str) -> None:
    if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
        raise ParameterError(name, value, expected)


def simulate(system: System, start_time: float, stop_time: float,
             comm_step: float | None = None, **options: Any) -> CoSimResult:
    """Load, run and free in one call (see :class:`CoSimulation` for the options)."""
    with CoSimulation(system, start_time, stop_time, comm_step, **options) as sim:
        return sim.run()
