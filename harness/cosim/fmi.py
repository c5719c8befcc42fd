"""FMI plumbing of the master: errors, loaded instances, the FMI error guard, the logger
callback and the extraction cache (one extracted copy per FMU file version and process)."""
from __future__ import annotations

import ctypes
import tempfile
from collections import deque
from pathlib import Path
from typing import Any

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

from abu_model.errors import AbuError

NEXT_EVENT_OUTPUT = "next_event_time"
SWITCH_COUNT_OUTPUT = "switch_count"
SWITCH_TIME_OUTPUT = "t_last_switch"
SWITCH_STATE_OUTPUT = "mode"
FIRST_SWITCH_OUTPUT = "t_first_step_switch"

STATUS = ["ok", "warning", "discard", "error", "fatal", "pending"]
ERROR, FATAL = 3, 4


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




class Instance:
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
        self.bare: dict[str, Any] = {}  # component and argtype-free functions (see bare())
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


class Guard:
    """Turns an FMICallException of one instance into FMUError (a class: cheaper than a
    generator-based context manager on the per-step path)."""

    __slots__ = ("inst", "what")

    def __init__(self, inst: "Instance", what: str):
        self.inst, self.what = inst, what

    def __enter__(self) -> None:
        return None

    def __exit__(self, exc_type, exc, tb) -> bool:
        if exc_type is None or not issubclass(exc_type, FMICallException):
            return False
        fail(self.inst, exc.function or self.what, exc.status)


def fail(inst: "Instance", function: str, status: int) -> None:
    """Raise the FMUError of ``inst``'s failed call ``function`` (fmi2Status ``status``)."""
    inst.failed_status = status
    label = STATUS[status] if 0 <= status < len(STATUS) else str(status)
    raise FMUError(inst.name, inst.path, function, label, list(inst.messages)) from None


GETTERS = {"Real": "getReal", "Integer": "getInteger", "Boolean": "getBoolean"}
SETTERS = {"Real": "setReal", "Integer": "setInteger", "Boolean": "setBoolean"}


def convert(value: Any, type_: str) -> Any:
    if type_ == "Real":
        return float(value)
    if type_ == "Integer":
        return int(round(float(value)))
    if type_ == "Boolean":
        return bool(value)
    raise CoSimulationError(f"unsupported variable type {type_}")


def make_callbacks(instances: dict[str, Instance]) -> tuple[fmi2CallbackFunctions, Any]:
    """FMI callbacks whose logger files each message under its instance (and the ctypes
    logger object, which the caller must keep alive)."""

    def logger(env, instance_name, status, category, message):  # called from C
        try:
            name = instance_name.decode("utf-8", "replace") if instance_name else ""
            text = message.decode("utf-8", "replace") if message else ""
            text = text.replace("%%", "%")  # the message is a printf format (see below)
            label = STATUS[status] if 0 <= status < len(STATUS) else str(status)
            inst = instances.get(name)
            if inst is not None:
                inst.messages.append(f"[{label}] {clean_message(text)}")
        except Exception:  # never let an exception cross the C boundary
            pass

    callbacks = fmi2CallbackFunctions()
    logger_ref = fmi2CallbackLoggerTYPE(logger)
    callbacks.logger = logger_ref
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    # No fmpy.logging.addLoggerProxy: its C proxy keeps ONE process-wide logger (the last one
    # registered, by any fmpy user), so a pooled co-simulation's FMU logged through the freed
    # logger of a later, closed one (segfault in fmi2ExitInitializationMode on a reused
    # instance). The toolkit's FMUs pass the message as a format string without arguments
    # ('%' escaped), so a plain callback loses nothing; another FMU's printf arguments would
    # show unformatted.
    return callbacks, logger_ref


_EXTRACT_ROOT: tempfile.TemporaryDirectory | None = None
_EXTRACTED: dict[tuple[Path, int, int], Path] = {}


def extracted(path: Path) -> Path:
    """Directory holding the extracted ``path``, extracted once per process and file version.

    The shared libraries are never unloaded (see :meth:`harness.cosim.master.CoSimulation.close`),
    so loading the same extracted library again reuses it instead of mapping one more copy
    per run. The directory is removed at interpreter exit.
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


def clean_message(text: str) -> str:
    """Shorten pythonfmu's 'Fatal py exception encountered: [...]' to its last line."""
    lines = [line.strip() for line in text.strip().splitlines() if line.strip()]
    if len(lines) > 1 and "py exception" in lines[0].lower():
        return lines[-1]
    return " ".join(lines)


_CTYPES = {"Real": ctypes.c_double, "Integer": ctypes.c_int, "Boolean": ctypes.c_int}


def bare(inst: Instance, name: str) -> tuple[ctypes.c_void_p, Any]:
    """(component, FMI function ``name``) of ``inst`` for direct calls: the component as a
    ``c_void_p`` and the function WITHOUT ctypes ``argtypes`` (its own pointer, fmpy's is
    untouched), returning the fmi2Status as an int. The caller passes ctypes objects of the
    exact C types (arrays, ``c_size_t``, ``c_double``, ``byref``): converting each argument
    through ``argtypes`` costs about 1 us per call, more than a native FMU's work."""
    cache = inst.bare
    component = inst.slave.component
    if cache.get("") is None or cache[""].value != component:
        cache.clear()
        cache[""] = ctypes.c_void_p(component)
    function = cache.get(name)
    if function is None:
        function = inst.slave.dll[name]  # a new function pointer, not fmpy's attribute
        function.restype = ctypes.c_int
        cache[name] = function
    return cache[""], function


def raw_call(inst: Instance, kind: str, type_: str, vrs: list[int]) -> tuple:
    """(function name, component, function, value references, count, buffer) of
    fmi2<kind><type_> on fixed value references, preallocated for :func:`bare` calls."""
    name = f"fmi2{kind}{type_}"
    component, function = bare(inst, name)
    n = len(vrs)
    return (name, component, function, (ctypes.c_uint * n)(*vrs), ctypes.c_size_t(n),
            (_CTYPES[type_] * n)())


def raw_accessor(inst: Instance, kind: str, type_: str, vrs: list[int]):
    """fmi2Get<type> (``kind`` "Get") or fmi2Set<type> ("Set") of fixed value references,
    straight through ctypes with preallocated arrays (:func:`raw_call`): fmpy's ``getReal``
    allocates both arrays, converts every argument and inspects the log state on every call.
    A status above fmi2Warning raises FMICallException, as fmpy does."""
    name, component, function, refs, n, buffer = raw_call(inst, kind, type_, vrs)

    if kind == "Get":
        def get() -> list:
            status = function(component, refs, n, buffer)
            if status > 1:
                raise FMICallException(function=name, status=status)
            return buffer[:]
        return get

    def set_(values: list) -> None:
        buffer[:] = values
        status = function(component, refs, n, buffer)
        if status > 1:
            raise FMICallException(function=name, status=status)
    return set_
