"""Python side of the FMUs' native layer (``fmus/native/abufmu.c``); standard library only.

The build copies this file into each FMU as ``resources/<module>_rt.py`` with ``SLAVE_MODULE``
and ``SLAVE_CLASS`` filled in. The C binary imports it once per process (with the resources
folder on ``sys.path`` only during that import, so ``sys.path`` does not grow) and calls
:func:`instantiate` and the methods of :class:`Instance`. Every method returns
``(status, payload)``: an fmi2Status, OR-ed with ``LOG_PENDING`` when messages wait in
:meth:`Instance.drain_logs`, and the call's result (bytes of packed values, a state object) or
None. Nothing raises: a bad call order, value reference, value, time or state, and any error
of the slave, is an ``fmi2Error`` with a logged message (recoverable, as FMI 2.0 intends);
the C layer turns only a failure of this module itself into ``fmi2Fatal``.

Values cross the C boundary as bytes (value references as uint32, Reals as doubles, Integers
and Booleans as int32), which is cheaper than building Python lists element by element.
"""
from __future__ import annotations

import importlib
import json
import math
from array import array

SLAVE_MODULE = "@SLAVE_MODULE@"
SLAVE_CLASS = "@SLAVE_CLASS@"

# Imported now, while the C layer has the resources folder on sys.path.
_CLASS = getattr(importlib.import_module(SLAVE_MODULE), SLAVE_CLASS)

OK, WARNING, DISCARD, ERROR, FATAL = 0, 1, 2, 3, 4
LOG_PENDING = 0x100
STATE_FORMAT = "abufmu-state-1"
#: Relative mismatch tolerated between doStep's current time and the FMU's time [-].
TIME_TOLERANCE = 1e-9
INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED = (
    "instantiated", "initialization mode", "step mode", "terminated")
_PHASES = (INSTANTIATED, INITIALIZATION, STEPPING, TERMINATED)
_VR = "I" if array("I").itemsize == 4 else "L"
_STATUS_NAMES = ("logStatusOK", "logStatusWarning", "logStatusDiscard", "logStatusError",
                 "logStatusFatal")


_META: dict[int, tuple[str, str, str, str]] = {}


def _meta(variables) -> dict[int, tuple[str, str, str, str]]:
    """vr -> (type, name, causality, variability): the same for every instance of the class,
    read once (the enums' attribute access is slow on a per-call path)."""
    if not _META:
        for vr, var in variables.items():
            _META[vr] = (type(var).__name__, var.name,
                         var.causality.name if var.causality is not None else "local",
                         var.variability.name if var.variability is not None else "continuous")
    return _META


def instantiate(name: str, resources: str, visible: int, logging_on: int):
    """(OK, Instance) or (ERROR, message)."""
    try:
        return OK, Instance(name, resources, visible, logging_on)
    except Exception as exc:  # noqa: BLE001 - reported to the host, never raised
        return ERROR, (f"{SLAVE_CLASS} '{name}': cannot create the slave: "
                       f"{type(exc).__name__}: {exc}")


def _calls(method):
    """Wrap an FMI method: any exception becomes fmi2Error with a message naming the call."""
    fmi_name = "fmi2" + "".join(part.capitalize() for part in method.__name__.strip("_").split("_"))

    def call(self, *args):
        try:
            status, payload = method(self, *args)
        except MemoryError:
            return FATAL, None
        except Exception as exc:  # noqa: BLE001 - the host gets a status, never an exception
            self.message(ERROR, f"{fmi_name} failed: {type(exc).__name__}: {exc}")
            status, payload = ERROR, None
        if self.logs or (self.slave is not None and self.slave.log_queue):
            status |= LOG_PENDING
        return status, payload
    call.__name__ = method.__name__
    return call


class Instance:
    """One FMU instance: call-order, value and time checks around a pythonfmu-style slave."""

    def __init__(self, name: str, resources: str, visible: int, logging_on: int):
        self.name, self.resources, self.visible = name, resources, bool(visible)
        self.logging_on = bool(logging_on)
        self.logs: list[tuple[int, str, str]] = []
        self.slave = None
        self._new_slave()

    def _new_slave(self) -> None:
        if self.slave is not None:
            self._drop_slave()
        self.slave = _CLASS(instance_name=self.name, resources=self.resources, visible=self.visible)
        self.vars = self.slave.vars
        self._getters: dict = {}  # (type, vrs bytes) -> getters of the slave
        self._setters: dict = {}  # (type, vrs bytes) -> (setter, name, fixed) of the slave
        self.phase = INSTANTIATED
        self.time = 0.0
        self.last_successful_time = 0.0

    def _drop_slave(self) -> None:
        # The slave's getters are closures over it (a reference cycle): break it now so the
        # memory is returned at once, not at the next garbage collection.
        self.slave.__dict__.clear()
        self.slave = None
        self._getters, self._setters = {}, {}

    # ---------------------------------------------------------------- messages
    def message(self, status: int, text: str) -> None:
        self.logs.append((status, _STATUS_NAMES[status],
                          f"{SLAVE_CLASS} '{self.name}': {text}"))

    def _error(self, text: str):
        self.message(ERROR, text)
        return ERROR, None

    def drain_logs(self) -> list[tuple[int, str, str]]:
        """Pending messages (status, category, text); below fmi2Warning only with logging on."""
        out, self.logs = self.logs, []
        if self.slave is not None and self.slave.log_queue:
            for msg in self.slave.log_queue:
                out.append((int(msg.status), str(msg.category or "logAll"), str(msg.msg)))
            self.slave.log_queue.clear()
        if not self.logging_on:
            out = [m for m in out if m[0] >= WARNING]
        return out

    @_calls
    def set_debug_logging(self, on: int):
        self.logging_on = bool(on)
        return OK, None

    # ---------------------------------------------------------------- life cycle
    def _require(self, fn: str, *phases: str):
        if self.phase not in phases:
            return self._error(f"{fn} is not allowed in {self.phase} "
                               f"(allowed in: {', '.join(phases)})")
        return None

    @_calls
    def setup_experiment(self, tol_defined: int, tolerance: float, start: float,
                         stop_defined: int, stop: float):
        refused = self._require("fmi2SetupExperiment", INSTANTIATED)
        if refused:
            return refused
        if not math.isfinite(start):
            return self._error(f"fmi2SetupExperiment: startTime = {start!r} s is not finite")
        if stop_defined and not (math.isfinite(stop) and stop >= start):
            return self._error(f"fmi2SetupExperiment: stopTime = {stop!r} s must be finite and "
                               f">= startTime = {start!r} s")
        if tol_defined and not (math.isfinite(tolerance) and tolerance > 0.0):
            return self._error(f"fmi2SetupExperiment: tolerance = {tolerance!r} must be > 0")
        self.slave.setup_experiment(start, stop if stop_defined else None,
                                    tolerance if tol_defined else None)
        self.time = self.last_successful_time = start
        return OK, None

    @_calls
    def enter_initialization_mode(self):
        refused = self._require("fmi2EnterInitializationMode", INSTANTIATED)
        if refused:
            return refused
        self.slave.enter_initialization_mode()
        self.phase = INITIALIZATION
        return OK, None

    @_calls
    def exit_initialization_mode(self):
        refused = self._require("fmi2ExitInitializationMode", INITIALIZATION)
        if refused:
            return refused
        try:
            self.slave.exit_initialization_mode()
        except ValueError as exc:  # ParameterError: fix the parameter and call again
            return self._error(str(exc))
        self.phase = STEPPING
        return OK, None

    @_calls
    def terminate(self):
        refused = self._require("fmi2Terminate", STEPPING, INITIALIZATION)
        if refused:
            return refused
        self.slave.terminate()
        self.phase = TERMINATED
        return OK, None

    @_calls
    def reset(self):
        self._new_slave()
        return OK, None

    def free(self) -> tuple[int, None]:
        if self.slave is not None:
            self._drop_slave()
        self.vars = {}
        self.logs = []
        return OK, None

    @_calls
    def cancel_step(self):
        return self._error("fmi2CancelStep: no step is pending (doStep never returns fmi2Pending)")

    @_calls
    def do_step(self, t: float, h: float, no_set_prior: int):
        if t == self.time and self.phase == STEPPING and 0.0 <= h < math.inf:
            pass  # the usual call: skip the checks below (same answers, less work)
        elif self.phase != STEPPING:
            return self._require("fmi2DoStep", STEPPING)
        elif not (math.isfinite(t) and math.isfinite(h) and h >= 0.0):
            return self._error(f"fmi2DoStep: currentCommunicationPoint = {t!r} s and "
                               f"communicationStepSize = {h!r} s must be finite, the step >= 0")
        elif abs(t - self.time) > TIME_TOLERANCE * max(1.0, abs(t)):
            return self._error(f"fmi2DoStep: currentCommunicationPoint = {t!r} s but the FMU "
                               f"is at t = {self.time!r} s (restore a state to step from "
                               "another time)")
        if self.slave.do_step(t, h):
            self.time = self.last_successful_time = t + h
            return OK, None
        self.last_successful_time = t
        return DISCARD, None

    # ---------------------------------------------------------------- status
    @_calls
    def get_status(self, kind: int):
        self.message(WARNING, f"status kind {kind} is not available (doStep is synchronous)")
        return DISCARD, None

    @_calls
    def get_real_status(self, kind: int):
        if kind == 2:  # fmi2LastSuccessfulTime
            return OK, float(self.last_successful_time)
        self.message(WARNING, f"Real status kind {kind} is not available")
        return DISCARD, None

    @_calls
    def get_boolean_status(self, kind: int):
        if kind == 3:  # fmi2Terminated: the FMU never asks to stop
            return OK, 0
        self.message(WARNING, f"Boolean status kind {kind} is not available")
        return DISCARD, None

    # ---------------------------------------------------------------- values
    def _variables(self, fn: str, vrs: bytes, kind: str):
        """The value references (all of type ``kind``) as a list, or an error message."""
        refs = array(_VR)
        refs.frombytes(vrs)
        meta = _meta(self.vars)
        for vr in refs:
            m = meta.get(vr)
            if m is None or m[0] != kind:
                known = [v for v, x in meta.items() if x[0] == kind]
                what = "unknown" if m is None else f"'{m[1]}' is a {m[0]}"
                return None, (f"{fn}: value reference {vr} is not a {kind} variable of "
                              f"{SLAVE_CLASS} ({what}; {kind} value references: "
                              f"{known[0] if known else '-'}..{known[-1] if known else '-'})")
        return refs, None

    def _get(self, fn: str, vrs: bytes, kind: str, code: str, convert):
        getters = self._getters.get((kind, vrs))
        if getters is None:  # checked once per list of value references (a master repeats it)
            refs, problem = self._variables(fn, vrs, kind)
            if problem:
                return self._error(problem)
            getters = [self.vars[vr].getter for vr in refs]
            if len(self._getters) < 256:
                self._getters[(kind, vrs)] = getters
        return OK, array(code, [convert(g()) for g in getters]).tobytes()

    def _set(self, fn: str, vrs: bytes, values: list, kind: str):
        plan = self._setters.get((kind, vrs))
        if plan is None:  # type and causality checked once per list of value references
            refs, problem = self._variables(fn, vrs, kind)
            if problem:
                return self._error(problem)
            meta, plan = _meta(self.vars), []
            for vr in refs:
                _, name, causality, variability = meta[vr]
                setter = self.vars[vr].setter
                if causality not in ("parameter", "input") or setter is None:
                    return self._error(f"{fn}: '{name}' is a {causality} variable "
                                       "and cannot be set")
                plan.append((setter, name, variability in ("fixed", "constant")))
            if len(self._setters) < 256:
                self._setters[(kind, vrs)] = plan
        phase = self.phase
        for (_, name, fixed), value in zip(plan, values):  # check all before changing any
            if phase == TERMINATED:
                return self._error(f"{fn}: '{name}' cannot be set after fmi2Terminate")
            if fixed and phase not in (INSTANTIATED, INITIALIZATION):
                return self._error(f"{fn}: '{name}' is a fixed parameter and cannot be set in "
                                   f"{phase} (only before fmi2ExitInitializationMode)")
            if value.__class__ is float and not math.isfinite(value):
                return self._error(f"{fn}: '{name}' = {value!r} is not a finite number")
        for (setter, _, _), value in zip(plan, values):
            setter(value)
        return OK, None

    # The two calls a master makes most: a fast path once the value references are known (the
    # same answers as the checked path, which they fall back to for anything unusual).
    def get_real(self, vrs: bytes):
        getters = self._getters.get(("Real", vrs))
        if getters is not None and not self.logs:
            try:
                values = array("d", [float(g()) for g in getters]).tobytes()
            except Exception:  # noqa: BLE001 - the checked path reports it
                return self._get_real(vrs)
            return (OK | LOG_PENDING) if self.slave.log_queue else OK, values
        return self._get_real(vrs)

    def get_integer(self, vrs: bytes):
        getters = self._getters.get(("Integer", vrs))
        if getters is not None and not self.logs:
            try:
                values = array("i", [int(g()) for g in getters]).tobytes()
            except Exception:  # noqa: BLE001 - the checked path reports it
                return self._get_integer(vrs)
            return (OK | LOG_PENDING) if self.slave.log_queue else OK, values
        return self._get_integer(vrs)

    @_calls
    def _get_real(self, vrs: bytes):
        return self._get("fmi2GetReal", vrs, "Real", "d", float)

    @_calls
    def _get_integer(self, vrs: bytes):
        return self._get("fmi2GetInteger", vrs, "Integer", "i", int)

    @_calls
    def get_boolean(self, vrs: bytes):
        return self._get("fmi2GetBoolean", vrs, "Boolean", "i", lambda v: 1 if v else 0)

    @_calls
    def get_string(self, vrs: bytes):
        refs, problem = self._variables("fmi2GetString", vrs, "String")
        if problem:
            return self._error(problem)
        return OK, [str(self.vars[vr].getter()).encode("utf-8") for vr in refs]

    @_calls
    def set_real(self, vrs: bytes, values: bytes):
        return self._set("fmi2SetReal", vrs, array("d", values).tolist(), "Real")

    @_calls
    def set_integer(self, vrs: bytes, values: bytes):
        return self._set("fmi2SetInteger", vrs, array("i", values).tolist(), "Integer")

    @_calls
    def set_boolean(self, vrs: bytes, values: bytes):
        return self._set("fmi2SetBoolean", vrs, [v != 0 for v in array("i", values)], "Boolean")

    @_calls
    def set_string(self, vrs: bytes, values: list):
        if any(v is None for v in values):
            return self._error("fmi2SetString: a value is a NULL pointer")
        return self._set("fmi2SetString", vrs,
                         [v.decode("utf-8", errors="replace") for v in values], "String")

    # ---------------------------------------------------------------- FMU state
    def _snapshot(self, phase: str, time: float, last: float, slave_state) -> tuple:
        return (STATE_FORMAT, SLAVE_CLASS, phase, time, last, slave_state)

    def _check_snapshot(self, state) -> tuple:
        """The validated snapshot (raises ValueError naming what is wrong)."""
        if not (isinstance(state, tuple) and len(state) == 6 and state[0] == STATE_FORMAT):
            raise ValueError("not an FMU state of this runtime")
        _, model, phase, time, last, slave_state = state
        if model != SLAVE_CLASS:
            raise ValueError(f"a state of {model!r}, not of {SLAVE_CLASS}")
        if phase not in _PHASES:
            raise ValueError(f"unknown phase {phase!r}")
        for name, value in (("time", time), ("last successful time", last)):
            if not (isinstance(value, float) and math.isfinite(value)):
                raise ValueError(f"{name} = {value!r} is not a finite number")
        phase = _PHASES[_PHASES.index(phase)]  # the canonical string object
        return (STATE_FORMAT, model, phase, time, last,
                _CLASS._validate_fmu_state(slave_state, phase in (INSTANTIATED, INITIALIZATION)))

    @_calls
    def get_state(self):
        return OK, self._snapshot(self.phase, float(self.time), float(self.last_successful_time),
                                  self.slave._get_fmu_state())

    @_calls
    def set_state(self, state):
        try:
            state = self._check_snapshot(state)
        except (ValueError, TypeError, KeyError) as exc:
            return self._error(f"fmi2SetFMUstate: invalid state: {exc}")
        previous = self.slave._get_fmu_state()
        try:
            self.slave._set_fmu_state(state[5])
        except Exception as exc:  # noqa: BLE001 - put the slave back as it was
            self.slave._set_fmu_state(previous)
            return self._error(f"fmi2SetFMUstate: cannot restore the state: {exc}")
        self.phase, self.time, self.last_successful_time = state[2], state[3], state[4]
        return OK, None

    @_calls
    def serialize(self, state):
        state = self._check_snapshot(state)
        _, model, phase, time, last, slave_state = state
        return OK, json.dumps({"format": STATE_FORMAT, "model": model, "phase": phase,
                               "time": time, "last_successful_time": last,
                               "slave": slave_state}).encode("utf-8")

    @_calls
    def deserialize(self, data: bytes):
        try:
            doc = json.loads(data.decode("utf-8"))
            if not isinstance(doc, dict) or doc.get("format") != STATE_FORMAT:
                raise ValueError(f"no '{STATE_FORMAT}' header")
            state = self._check_snapshot((STATE_FORMAT, doc.get("model"), doc.get("phase"),
                                          doc.get("time"), doc.get("last_successful_time"),
                                          doc.get("slave")))
        except (ValueError, TypeError, KeyError, UnicodeDecodeError, RecursionError) as exc:
            return self._error(f"fmi2DeSerializeFMUstate: {len(data)} bytes are not a "
                               f"serialized state of {SLAVE_CLASS}: {type(exc).__name__}: {exc}")
        return OK, state
