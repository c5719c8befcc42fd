"""The plan's per-point reads and writes compiled into closures over direct FMI calls.

:meth:`harness.cosim.master.CoSimulation.read_outputs` and ``propagate`` walk the
:class:`~harness.cosim.plan.Plan` at every communication point; with a native FMU the Python
around each ``fmi2GetReal``/``fmi2SetReal`` (looking up the cached accessor, the error guard,
argument conversion, building lists) costs more than the call itself. :func:`compile_point`
binds, once per run, each grouped read or write to its instance's argtype-free function
(:func:`harness.cosim.fmi.bare`), its preallocated value-reference and value arrays and its
node names, with single-value groups (most of the sweep) specialised. The calls, their order,
the values and the FMI call count are exactly those of the plan walk (the walk stays for
held outputs at time events, an FMI call logger and instrumented instances).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from harness.cosim.fmi import Instance, fail, raw_call
from harness.cosim.plan import Plan

#: One compiled operation: op(t [s], values (node -> value), sets (the sweep's writes)).
Op = Callable[[float, dict, list], None]
CONVERT: dict[str, Callable[[Any], Any]] = {
    "Real": float, "Integer": lambda value: int(round(float(value))), "Boolean": bool}


@dataclass(frozen=True)
class CompiledPoint:
    """The compiled reads and writes of one plan (``plan``: the one compiled, by identity)."""

    plan: Plan
    pre: tuple[Op, ...]
    sweep: tuple[Op, ...]
    tail: tuple[Op, ...]

    @property
    def sweep_calls(self) -> int:
        """FMI calls of a full sweep (sweep and tail reads)."""
        return len(self.sweep) + len(self.tail)


def compile_point(plan: Plan) -> CompiledPoint:
    """The plan's pre-reads, sweep and tail reads as closures (see the module docstring)."""
    sweep = []
    for entry in plan.sweep:
        if entry[0] == "get":
            _, inst, type_, vrs, nodes = entry
            sweep.append(_reader(inst, type_, vrs, nodes))
        else:
            _, inst, type_, vrs, feeds, nodes = entry
            sweep.append(_writer(inst, type_, vrs, feeds, nodes))
    return CompiledPoint(plan, tuple(_reader(*read) for read in plan.pre_reads), tuple(sweep),
                         tuple(_reader(*read) for read in plan.tail_reads))


def _reader(inst: Instance, type_: str, vrs: list[int], nodes: list[str]) -> Op:
    """fmi2Get<type_> of ``vrs`` into ``values[nodes]``."""
    name, component, function, refs, n, buffer = raw_call(inst, "Get", type_, vrs)
    if len(nodes) == 1:
        node = nodes[0]

        def read_one(t: float, values: dict, sets: list) -> None:
            status = function(component, refs, n, buffer)
            if status > 1:
                fail(inst, name, status)
            values[node] = buffer[0]
        return read_one

    def read(t: float, values: dict, sets: list) -> None:
        status = function(component, refs, n, buffer)
        if status > 1:
            fail(inst, name, status)
        values.update(zip(nodes, buffer[:]))
    return read


def _writer(inst: Instance, type_: str, vrs: list[int], feeds: list, nodes: list[str]) -> Op:
    """fmi2Set<type_> of ``vrs`` from their feeds (a node's value or a function of t), the
    values converted to the input's type; records them in ``values`` and (as the plan walk
    does, for the re-set after a rollback) appends (inst, type_, vrs, values) to ``sets``."""
    name, component, function, refs, n, buffer = raw_call(inst, "Set", type_, vrs)
    convert = CONVERT[type_]
    if len(nodes) == 1 and not callable(feeds[0]) and type_ == "Real":
        feed, node = feeds[0], nodes[0]

        def write_one(t: float, values: dict, sets: list) -> None:
            value = float(values[feed])
            buffer[0] = value
            status = function(component, refs, n, buffer)
            if status > 1:
                fail(inst, name, status)
            values[node] = value
            sets.append((inst, type_, vrs, [value]))
        return write_one

    def write(t: float, values: dict, sets: list) -> None:
        new = [convert(f(t) if callable(f) else values[f]) for f in feeds]
        buffer[:] = new
        status = function(component, refs, n, buffer)
        if status > 1:
            fail(inst, name, status)
        values.update(zip(nodes, new))
        sets.append((inst, type_, vrs, new))
    return write
