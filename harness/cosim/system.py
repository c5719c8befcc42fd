"""A co-simulated system described as data: components, connections, sources, probes.

Variables are named ``"component.variable"``; the component name is everything before the
first dot (variable names may contain dots, component names may not).  Nothing here touches
an FMU: :mod:`harness.cosim.master` loads the components and checks every name against the model
descriptions.
"""
from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Mapping

from abu_model.errors import ParameterError

#: A parameter or start value: FMI Real, Integer or Boolean.
Scalar = float | int | bool


def split_name(qualified: str, what: str = "variable") -> tuple[str, str]:
    """Split ``"component.variable"`` into its two parts.

    Raises:
        ParameterError: if there is no dot or either part is empty.
    """
    if not isinstance(qualified, str) or "." not in qualified:
        raise ParameterError(what, qualified, "a name of the form 'component.variable'")
    component, variable = qualified.split(".", 1)
    if not component or not variable:
        raise ParameterError(what, qualified, "a name of the form 'component.variable'")
    return component, variable


@dataclass(frozen=True)
class Component:
    """One FMU instance.

    Attributes:
        name: instance name, unique in the system, without dots.
        fmu: path of the ``.fmu`` archive (FMI 2.0 co-simulation).
        parameters: start values set before initialisation, by variable name (SI units).
    """

    name: str
    fmu: Path
    parameters: Mapping[str, Scalar] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name or "." in self.name:
            raise ParameterError("component name", self.name, "a non-empty name without dots")
        object.__setattr__(self, "fmu", Path(os.fspath(self.fmu)))
        object.__setattr__(self, "parameters", dict(self.parameters))


@dataclass(frozen=True)
class Connection:
    """An output feeding an input: ``src`` (``"comp.output"``) -> ``dst`` (``"comp.input"``)."""

    src: str
    dst: str

    def __post_init__(self) -> None:
        split_name(self.src, "connection source")
        split_name(self.dst, "connection destination")


@dataclass(frozen=True)
class Source:
    """An input driven by a function of time: ``dst`` (``"comp.input"``) = ``function(t)``.

    The master evaluates the function at every communication point (t in s) and holds the
    value over the step; feed a rate input alongside for a first-order hold.
    """

    dst: str
    function: Callable[[float], Scalar]

    def __post_init__(self) -> None:
        split_name(self.dst, "source destination")
        if not callable(self.function):
            raise ParameterError("source function", self.function, "a callable t -> value")


@dataclass(frozen=True)
class Hold:
    """How an exchanged output is held over a communication step, for the error estimate.

    ``signal`` (``"comp.output"``) is passed on together with its time derivatives
    ``derivatives`` (outputs, first derivative first), so the receiver sees the Taylor
    polynomial y + y' tau + y'' tau^2 / 2 + ... inside the step. The master predicts the
    signal at the step's end with that polynomial and compares it with the value the
    producer then outputs: the difference, divided by ``scale`` (the signal's unit; None:
    the largest |signal| seen so far), is the step's coupling error (``tol`` controls it).
    """

    signal: str
    derivatives: tuple[str, ...] = ()
    scale: float | None = None

    def __post_init__(self) -> None:
        split_name(self.signal, "hold signal")
        object.__setattr__(self, "derivatives", tuple(self.derivatives))
        for name in self.derivatives:
            split_name(name, "hold derivative")
        if self.scale is not None and not (self.scale > 0.0 and self.scale < float("inf")):
            raise ParameterError("hold scale", self.scale, "a finite scale > 0 or None")


@dataclass(frozen=True)
class System:
    """Components, connections, external sources and the variables to record.

    Attributes:
        components: the FMU instances.
        connections: output -> input links (each input driven at most once).
        sources: inputs driven by functions of time.
        probes: column name -> ``"comp.variable"`` recorded at every communication point.
        holds: the exchanged signals whose hold error controls the step size (empty: every
            continuous Real connection, taken as held constant).
    """

    components: tuple[Component, ...]
    connections: tuple[Connection, ...] = ()
    sources: tuple[Source, ...] = ()
    probes: Mapping[str, str] = field(default_factory=dict)
    holds: tuple[Hold, ...] = ()

    def __post_init__(self) -> None:
        object.__setattr__(self, "components", tuple(self.components))
        object.__setattr__(self, "connections", tuple(self.connections))
        object.__setattr__(self, "sources", tuple(self.sources))
        object.__setattr__(self, "probes", dict(self.probes))
        object.__setattr__(self, "holds", tuple(self.holds))
        names = [c.name for c in self.components]
        if not names:
            raise ParameterError("components", names, "at least one component")
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise ParameterError("component name", duplicates[0], "a name used once")
        known = set(names)
        driven: dict[str, str] = {}
        for what, ends in (("connection", [(c.src, c.dst) for c in self.connections]),
                           ("source", [(None, s.dst) for s in self.sources])):
            for src, dst in ends:
                for end in (src, dst):
                    if end is not None and split_name(end)[0] not in known:
                        raise ParameterError(f"{what} {src} -> {dst}" if src else f"{what} {dst}",
                                             end, f"a variable of a component in {sorted(known)}")
                if dst in driven:
                    raise ParameterError("input", dst,
                                         f"an input driven once (already driven by {driven[dst]})")
                driven[dst] = src if src is not None else "a source"
        for column, variable in self.probes.items():
            if split_name(variable, f"probe {column}")[0] not in known:
                raise ParameterError(f"probe {column}", variable,
                                     f"a variable of a component in {sorted(known)}")

        for hold in self.holds:
            for variable in (hold.signal,) + hold.derivatives:
                if split_name(variable)[0] not in known:
                    raise ParameterError(f"hold {hold.signal}", variable,
                                         f"a variable of a component in {sorted(known)}")

    def structure_key(self) -> tuple:
        """Everything but parameters and source functions (and the FMU files' versions):
        systems with equal keys can reuse each other's loaded instances (:mod:`harness.cosim.reuse`)."""
        comps = tuple((c.name, str(c.fmu.resolve()),
                       c.fmu.stat().st_mtime_ns if c.fmu.is_file() else None)
                      for c in self.components)  # a rebuilt FMU file is another structure
        return (comps, self.connections, tuple(s.dst for s in self.sources),
                tuple(self.probes.items()), self.holds)

    def component(self, name: str) -> Component:
        """The component called ``name``."""
        for comp in self.components:
            if comp.name == name:
                return comp
        raise ParameterError("component", name, f"one of {[c.name for c in self.components]}")

