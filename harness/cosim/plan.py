"""What the master reads and writes at a communication point, and in which order.

:func:`build_plan` turns a :class:`~harness.cosim.system.System` and its loaded instances into a
:class:`Plan`:

* **propagation order at variable level**: one node per connected variable, an edge
  ``output -> input`` per connection and ``input -> output`` per dependency the FMU declares
  in ``ModelStructure/Outputs`` (no ``dependencies`` attribute: every input, as FMI says); a
  topological order (``graphlib``) reads each output after the inputs it depends on are set.
  A cycle of variables is a real algebraic loop (:class:`AlgebraicLoopError`).
* **reads grouped so that no value is read twice per point**: outputs that depend on no
  driven input (states such as ``plant.omega``, the switch and event outputs) are read once
  right after ``fmi2DoStep``, one call per component and type (``pre_reads``); the sweep reads
  only outputs that depend on inputs set before them; what the probes and holds still miss
  is read once at the end (``tail_reads``).
"""
from __future__ import annotations

import graphlib
from dataclasses import dataclass, field
from typing import Any

from harness.cosim.fmi import GETTERS, AlgebraicLoopError, CoSimulationError, Instance
from harness.cosim.system import Hold, System, split_name

#: Output names the master looks for in every component.
NEXT_EVENT_OUTPUT = "next_event_time"
SWITCH_COUNT_OUTPUT = "switch_count"
SWITCH_TIME_OUTPUT = "t_last_switch"
SWITCH_STATE_OUTPUT = "mode"
FIRST_SWITCH_OUTPUT = "t_first_step_switch"

#: One grouped FMI read: (instance, type, value references, node names).
Read = tuple[Instance, str, list[int], list[str]]


@dataclass
class Plan:
    """The master's per-point work (see the module docstring).

    Attributes:
        order: connected variables in propagation order.
        sweep: ("get", inst, type, vrs, nodes) / ("set", inst, type, vrs, feeds, nodes)
            entries; a feed is a source node name or a callable of t.
        pre_reads: grouped reads of input-independent outputs, right after a step.
        tail_reads: grouped reads of input-dependent outputs not read by the sweep.
        probes: (column, node) of the recorded variables.
        events: (instance name, node) of each ``next_event_time`` output.
        switches: (instance name, count, time, mode | None, first | None) nodes.
        holds: the holds whose prediction error controls the step (declared or default).
    """

    order: list[str] = field(default_factory=list)
    sweep: list[tuple] = field(default_factory=list)
    pre_reads: list[Read] = field(default_factory=list)
    tail_reads: list[Read] = field(default_factory=list)
    probes: list[tuple[str, str]] = field(default_factory=list)
    events: list[tuple[str, str]] = field(default_factory=list)
    switches: list[tuple[str, str, str, str | None, str | None]] = field(default_factory=list)
    holds: list[Hold] = field(default_factory=list)


def resolve(instances: dict[str, Instance], qualified: str, role: str,
            causality: tuple[str, ...] | None = None) -> tuple[Instance, Any]:
    """The instance and model variable of ``"comp.variable"`` (checked)."""
    comp, var_name = split_name(qualified, role)
    inst = instances[comp]
    var = inst.variable(var_name, f"{role} '{qualified}'")
    if causality is not None and var.causality not in causality:
        raise CoSimulationError(f"{role} '{qualified}': the variable has causality "
                                f"'{var.causality}', expected {' or '.join(causality)}")
    if var.type not in GETTERS:
        raise CoSimulationError(f"{role} '{qualified}': unsupported type {var.type}")
    return inst, var


def check_names(system: System, instances: dict[str, Instance]) -> None:
    """Every name of the system exists with a usable causality and type."""
    for comp in system.components:
        inst = instances[comp.name]
        for name in comp.parameters:
            var = inst.variable(name, "parameter")
            if var.causality not in ("parameter", "input") or var.variability == "constant":
                raise CoSimulationError(
                    f"parameter '{comp.name}.{name}': causality '{var.causality}' "
                    f"variability '{var.variability}' cannot be set")
    for conn in system.connections:
        _, src = resolve(instances, conn.src, "connection source", ("output",))
        _, dst = resolve(instances, conn.dst, "connection destination", ("input",))
        if src.type != dst.type and not (src.type == "Integer" and dst.type == "Real"):
            raise CoSimulationError(f"connection {conn.src} -> {conn.dst}: type {src.type} "
                                    f"cannot feed type {dst.type}")
    for source in system.sources:
        resolve(instances, source.dst, "source destination", ("input",))
    for column, qualified in system.probes.items():
        resolve(instances, qualified, f"probe '{column}'")
    for hold in system.holds:
        for name in (hold.signal,) + hold.derivatives:
            _, var = resolve(instances, name, f"hold '{hold.signal}'", ("output",))
            if var.type != "Real":
                raise CoSimulationError(f"hold '{hold.signal}': '{name}' is not a Real output")


def _group(instances: dict[str, Instance], nodes: list[str]) -> list[Read]:
    groups: dict[tuple[str, str], list[str]] = {}
    for node in nodes:
        inst, var = resolve(instances, node, "variable")
        groups.setdefault((inst.name, var.type), []).append(node)
    reads = []
    for (comp, type_), members in groups.items():
        inst = instances[comp]
        vrs = [inst.variables[split_name(n)[1]].valueReference for n in members]
        reads.append((inst, type_, vrs, members))
    return reads


def build_plan(system: System, instances: dict[str, Instance]) -> Plan:
    """Topologically sort the connected variables and group every FMI call (see module)."""
    plan = Plan()
    graph: dict[str, set[str]] = {}  # node -> predecessors
    feeds: dict[str, Any] = {}  # input node -> source node or callable
    for conn in system.connections:
        graph.setdefault(conn.src, set())
        graph.setdefault(conn.dst, set()).add(conn.src)
        feeds[conn.dst] = conn.src
    for source in system.sources:
        graph.setdefault(source.dst, set())
        feeds[source.dst] = source.function
    driven = set(feeds)

    def depends(node: str) -> list[str]:
        comp, name = split_name(node)
        return [f"{comp}.{d}" for d in instances[comp].dependencies.get(name, [])
                if f"{comp}.{d}" in driven]

    for node in list(graph):
        if instances[split_name(node)[0]].variables[split_name(node)[1]].causality == "output":
            graph[node].update(depends(node))
    sorter = graphlib.TopologicalSorter(graph)
    try:
        sorter.prepare()
    except graphlib.CycleError as exc:
        raise AlgebraicLoopError(list(exc.args[1])) from None

    # Outputs needed at every point besides the sweep: probes, holds, switch, event outputs.
    plan.probes = list(system.probes.items())
    plan.holds = list(system.holds) or _default_holds(system, instances)
    for inst in instances.values():
        if inst.has_output(NEXT_EVENT_OUTPUT):
            plan.events.append((inst.name, f"{inst.name}.{NEXT_EVENT_OUTPUT}"))
        if inst.has_output(SWITCH_COUNT_OUTPUT) and inst.has_output(SWITCH_TIME_OUTPUT):
            opt = [f"{inst.name}.{n}" if inst.has_output(n) else None
                   for n in (SWITCH_STATE_OUTPUT, FIRST_SWITCH_OUTPUT)]
            plan.switches.append((inst.name, f"{inst.name}.{SWITCH_COUNT_OUTPUT}",
                                  f"{inst.name}.{SWITCH_TIME_OUTPUT}", opt[0], opt[1]))
    needed = [n for _, n in plan.probes]
    for hold in plan.holds:
        needed += [hold.signal, *hold.derivatives]
    needed += [n for _, n in plan.events]
    for sw in plan.switches:
        needed += [n for n in sw[1:] if n is not None]

    independent: set[str] = set()
    swept: set[str] = set()
    tail: list[str] = []
    while sorter.is_active():
        ready = sorted(sorter.get_ready())
        gets = [n for n in ready if n not in feeds]
        sets = [n for n in ready if n in feeds]
        # Within one batch nothing depends on anything else: read first, then write.
        dependent = []
        for node in gets:
            (independent if not depends(node) else swept).add(node)
            if depends(node):
                dependent.append(node)
        for inst, type_, vrs, members in _group(instances, dependent):
            plan.sweep.append(("get", inst, type_, vrs, members))
        for inst, type_, vrs, members in _group(instances, sets):
            plan.sweep.append(("set", inst, type_, vrs, [feeds[n] for n in members], members))
        plan.order.extend(gets + sets)
        sorter.done(*ready)
    for node in needed:
        if node in independent or node in swept:
            continue
        comp, name = split_name(node)
        inst = instances[comp]
        var = inst.variables[name]
        if var.causality == "output" and not depends(node):
            independent.add(node)
        elif node not in feeds:  # an input is recorded from what the master set
            swept.add(node)
            tail.append(node)
    plan.pre_reads = _group(instances, sorted(independent, key=_stable(plan.order, needed)))
    plan.tail_reads = _group(instances, tail)
    return plan


def _stable(*orders: list[str]):
    rank: dict[str, int] = {}
    for order in orders:
        for node in order:
            rank.setdefault(node, len(rank))
    return lambda node: rank.get(node, len(rank))


def _default_holds(system: System, instances: dict[str, Instance]) -> list[Hold]:
    """Without declared holds: every continuous Real connection from a component without
    time events, taken as held constant (its change over the step is the error)."""
    holds = []
    for conn in system.connections:
        inst, var = resolve(instances, conn.src, "connection source")
        if (var.type == "Real" and var.variability == "continuous"
                and not inst.has_output(NEXT_EVENT_OUTPUT)):
            holds.append(Hold(conn.src))
    return list(dict.fromkeys(holds))
