"""Write an SSP 1.0 archive (System Structure and Parameterization) of connected FMUs.

The archive holds ``SystemStructure.ssd`` (components, typed connectors with units,
connections, unit definitions, the default experiment), the FMUs under ``resources/`` and
the parameter set ``resources/<name>.ssv``. It is written for the SSP readers that exist in
Python hosts, which differ in what they implement (checked in ``tests/test_ssp.py``):

* **libcosim** (libcosimpy ``CosimExecution.from_ssp_file``) parses the SSD with fixed
  namespace prefixes (``ssd:``, ``ssc:``, ``ssv:``, ``osp:``), applies only parameter bindings on
  *components* (bare variable names) and takes the step size from an OSP annotation of
  ``DefaultExperiment`` (``osp:FixedStepAlgorithm baseStepSize``);
* **fmpy.ssp** (``simulate_ssp``) validates the SSD against the SSP 1.0 schema, applies no
  binding itself but a ``parameter_set`` argument with hierarchical names
  (``plant.mu``), ignores ``DefaultExperiment``, drives every declared input connector (0.0
  until connected outputs arrive) and records every declared connector;
* **ecos** (ecospy, the ``ecos`` CLI) applies the component parameter sets of one *name*
  (``init(parameter_set=...)``, ``--parameterSet``) and refuses a negative start time.

So each component gets an inline binding with bare names (libcosim, ecos) and the system a
binding to the SSV file with hierarchical names (fmpy: ``read_ssd(p).system.parameterBindings[0]
.parameterValues[0]``); the SSP standard gives the system level precedence, and both hold the
same values; every parameter set is called ``name`` (``abu``). Every output and every connected
input of every FMU is a connector, so every output is recorded and no unconnected input is
overwritten. Pure standard library (xml, zipfile): writing needs neither numpy nor lxml.
"""
from __future__ import annotations

import math
import os
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Protocol, Sequence
from xml.etree import ElementTree as ET

from abu_model.atomic_io import atomic_open
from abu_model.errors import AbuError, ParameterError

NS = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
}
# libcosim reads the XML with boost::property_tree, which knows no namespaces: the prefixes
# must be exactly these.
for _prefix, _uri in NS.items():
    ET.register_namespace(_prefix, _uri)

SSD_NAME = "SystemStructure.ssd"
_BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")
_TYPES = ("Real", "Integer", "Boolean", "String")
Scalar = float | int | bool


class SspError(AbuError):
    """An SSP archive cannot be written from the given components (names the culprit)."""


# ---------------------------------------------------------------------------- FMU interface
@dataclass(frozen=True)
class FmuVariable:
    """A scalar variable of an FMU's model description (``unit`` "" when none)."""

    name: str
    causality: str
    type: str
    unit: str
    start: str | None


@dataclass(frozen=True)
class FmuInterface:
    """What the SSD needs from a model description: variables and unit definitions.

    ``units`` maps a unit name to its SI base-unit exponents plus ``factor``/``offset``.
    """

    variables: tuple[FmuVariable, ...]
    units: Mapping[str, Mapping[str, float]]

    def variable(self, name: str) -> FmuVariable:
        for var in self.variables:
            if var.name == name:
                return var
        raise KeyError(name)


def read_fmu_interface(fmu: str | os.PathLike) -> FmuInterface:
    """Variables and unit definitions of an FMI 2.0 FMU (its ``modelDescription.xml``)."""
    path = Path(fmu)
    try:
        with zipfile.ZipFile(path) as zf:
            root = ET.fromstring(zf.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError) as exc:
        raise SspError(f"{path}: not a readable FMU with a modelDescription.xml ({exc})") from None
    units: dict[str, dict[str, float]] = {}
    for unit in root.iterfind("UnitDefinitions/Unit"):
        base = unit.find("BaseUnit")
        attrs = {} if base is None else base.attrib
        units[unit.get("name", "")] = {k: float(v) for k, v in attrs.items()
                                       if k in _BASE_UNITS + ("factor", "offset")}
    variables = []
    for sv in root.iterfind("ModelVariables/ScalarVariable"):
        typed = next((child for child in sv if child.tag in _TYPES + ("Enumeration",)), None)
        if typed is None:
            raise SspError(f"{path}: variable {sv.get('name')!r} has no type element")
        variables.append(FmuVariable(sv.get("name", ""), sv.get("causality", "local"), typed.tag,
                                     typed.get("unit", ""), typed.get("start")))
    return FmuInterface(tuple(variables), units)


# ---------------------------------------------------------------------------- the system
class ComponentLike(Protocol):
    """An FMU instance: :class:`harness.cosim.system.Component` has this shape."""

    name: str
    fmu: Path
    parameters: Mapping[str, Scalar]


class ConnectionLike(Protocol):
    """``src`` ("comp.output") -> ``dst`` ("comp.input"): :class:`harness.cosim.system.Connection`."""

    src: str
    dst: str


@dataclass(frozen=True)
class Experiment:
    """The SSD's default experiment: start and stop time [s] and the fixed step [s]."""

    start_time: float
    stop_time: float
    step_size: float

    def __post_init__(self) -> None:
        for name in ("start_time", "stop_time", "step_size"):
            if not math.isfinite(getattr(self, name)):
                raise ParameterError(name, getattr(self, name), "a finite time [s]")
        if self.stop_time <= self.start_time:
            raise ParameterError("stop_time", self.stop_time,
                                 f"a time > start_time = {self.start_time!r} s")
        if self.step_size <= 0.0:
            raise ParameterError("step_size", self.step_size, "a step > 0 s")


def _format_value(value: Scalar, type_: str, where: str) -> str:
    """The SSV spelling of a parameter value; exact for floats (repr round-trips)."""
    if type_ == "Real":
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value):
            raise ParameterError(where, value, "a finite Real")
        return repr(float(value))
    if type_ == "Integer":
        if isinstance(value, bool) or not isinstance(value, (int, float)) \
                or not math.isfinite(value) or int(value) != value:
            raise ParameterError(where, value, "an Integer")
        return str(int(value))
    if type_ == "Boolean":
        if not isinstance(value, bool):
            raise ParameterError(where, value, "a Boolean (True/False)")
        return "true" if value else "false"
    raise ParameterError(where, value, f"a Real, Integer or Boolean parameter (not {type_})")


def _bound_parameters(comp: ComponentLike, iface: FmuInterface) -> list[tuple[str, str, str]]:
    """(name, SSV type, value text) of the parameters written for one component."""
    out = []
    for name, value in comp.parameters.items():
        where = f"{comp.name}.{name}"
        try:
            var = iface.variable(name)
        except KeyError:
            raise SspError(f"component {comp.name!r} ({comp.fmu}): no variable {name!r}") from None
        if var.causality not in ("parameter", "input"):
            raise SspError(f"component {comp.name!r}: {name!r} is an {var.causality}, "
                           "not a parameter or input")
        text = _format_value(value, var.type, where)
        # fmpy 0.3's simulate_ssp sets a Boolean to (value != 0.0), i.e. True for any text,
        # "false" included: a Boolean equal to the FMU's start value is left out instead.
        if var.type == "Boolean" and text == (var.start or "false"):
            continue
        out.append((name, var.type, text))
    return out


def _sub(parent: ET.Element, prefix: str, tag: str, **attrs: str) -> ET.Element:
    return ET.SubElement(parent, f"{{{NS[prefix]}}}{tag}", attrs)


def _parameter_set(parent: ET.Element | None, name: str,
                   params: Iterable[tuple[str, str, str]]) -> ET.Element:
    attrs = {"version": "1.0", "name": name}
    tag = f"{{{NS['ssv']}}}ParameterSet"
    pset = ET.Element(tag, attrs) if parent is None else ET.SubElement(parent, tag, attrs)
    plist = _sub(pset, "ssv", "Parameters")
    for pname, type_, text in params:
        _sub(_sub(plist, "ssv", "Parameter", name=pname), "ssv", type_, value=text)
    return pset


def _unit_element(parent: ET.Element, name: str, definition: Mapping[str, float]) -> None:
    unit = _sub(parent, "ssc", "Unit", name=name)
    attrs = {}
    for key in _BASE_UNITS:
        if definition.get(key, 0):
            attrs[key] = str(int(definition[key]))
    for key, neutral in (("factor", 1.0), ("offset", 0.0)):
        if definition.get(key, neutral) != neutral:
            attrs[key] = repr(float(definition[key]))
    _sub(unit, "ssc", "BaseUnit", **attrs)


def _xml_bytes(root: ET.Element) -> bytes:
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True) + b"\n"


def build_ssp_documents(name: str, components: Sequence[ComponentLike],
                        connections: Sequence[ConnectionLike], experiment: Experiment,
                        interfaces: Mapping[str, FmuInterface], ssv_name: str
                        ) -> tuple[bytes, bytes, dict[str, str]]:
    """The SSD and SSV documents (bytes) and component name -> FMU path inside the archive.

    Raises:
        SspError: a duplicate FMU file name, an unknown variable, a connection that does not
            go from an output to an input, or two FMUs defining one unit differently.
    """
    ssd = ET.Element(f"{{{NS['ssd']}}}SystemStructureDescription",
                     {"version": "1.0", "name": name, "generationTool": "abu export-ssp"})
    system = _sub(ssd, "ssd", "System", name=name,
                  description="Staircase -> SpeedController <-> AbuBall (abu-friction)")
    # schema order: the system's own ParameterBindings come before its Elements
    system_bindings = _sub(system, "ssd", "ParameterBindings")
    elements = _sub(system, "ssd", "Elements")
    sources: dict[str, str] = {}
    units: dict[str, Mapping[str, float]] = {}
    system_params: list[tuple[str, str, str]] = []
    for comp in components:
        iface = interfaces[comp.name]
        source = f"resources/{Path(comp.fmu).name}"
        clash = [c.name for c in components if c.name in sources and sources[c.name] == source
                 and Path(c.fmu).resolve() != Path(comp.fmu).resolve()]
        if clash:  # two instances of one FMU may share its file, two FMUs may not
            raise SspError(f"components {clash[0]!r} and {comp.name!r}: different FMUs with "
                           f"one file name {Path(comp.fmu).name!r}")
        sources[comp.name] = source
        element = _sub(elements, "ssd", "Component", name=comp.name, source=source,
                       type="application/x-fmu-sharedlibrary")
        connectors = _sub(element, "ssd", "Connectors")
        driven = {link.dst.split(".", 1)[1] for link in connections
                  if link.dst.split(".", 1)[0] == comp.name}
        for var in iface.variables:
            # fmpy drives every declared input (0.0 until a connection delivers): declare the
            # connected inputs only, so an unconnected one keeps its start value
            if not (var.causality == "output" or (var.causality == "input" and var.name in driven)):
                continue
            if var.type not in _TYPES:
                raise SspError(f"component {comp.name!r}: connector {var.name!r} has type "
                               f"{var.type}, which libcosim cannot read")
            conn = _sub(connectors, "ssd", "Connector", name=var.name, kind=var.causality)
            if var.type == "Real" and var.unit:
                _sub(conn, "ssc", "Real", unit=var.unit)
                definition = iface.units.get(var.unit)
                if definition is None:
                    raise SspError(f"{comp.fmu}: unit {var.unit!r} of {var.name!r} is not in "
                                   "its UnitDefinitions")
                if units.setdefault(var.unit, definition) != definition:
                    raise SspError(f"unit {var.unit!r} is defined differently in {comp.fmu}")
            else:
                _sub(conn, "ssc", var.type)
        params = _bound_parameters(comp, iface)
        if params:
            binding = _sub(_sub(element, "ssd", "ParameterBindings"), "ssd", "ParameterBinding")
            _parameter_set(_sub(binding, "ssd", "ParameterValues"), name, params)
        system_params += [(f"{comp.name}.{p}", t, v) for p, t, v in params]
    if system_params:
        _sub(system_bindings, "ssd", "ParameterBinding", source=f"resources/{ssv_name}")
    else:
        system.remove(system_bindings)
    connections_el = _sub(system, "ssd", "Connections")
    for link in connections:
        ends = []
        for end, kind in ((link.src, "output"), (link.dst, "input")):
            comp_name, var_name = end.split(".", 1)
            if comp_name not in interfaces:
                raise SspError(f"connection {link.src} -> {link.dst}: no component {comp_name!r}")
            try:
                var = interfaces[comp_name].variable(var_name)
            except KeyError:
                raise SspError(f"connection {link.src} -> {link.dst}: no variable "
                               f"{var_name!r} in {comp_name!r}") from None
            if var.causality != kind:
                raise SspError(f"connection {link.src} -> {link.dst}: {end} is an "
                               f"{var.causality}, expected an {kind}")
            ends.append((comp_name, var_name))
        _sub(connections_el, "ssd", "Connection", startElement=ends[0][0],
             startConnector=ends[0][1], endElement=ends[1][0], endConnector=ends[1][1])
    if units:
        units_el = _sub(ssd, "ssd", "Units")
        for unit_name in sorted(units):
            _unit_element(units_el, unit_name, units[unit_name])
    default = _sub(ssd, "ssd", "DefaultExperiment", startTime=repr(experiment.start_time),
                   stopTime=repr(experiment.stop_time))
    annotation = _sub(_sub(default, "ssd", "Annotations"), "ssc", "Annotation",
                      type="com.opensimulationplatform")
    _sub(_sub(annotation, "osp", "Algorithm"), "osp", "FixedStepAlgorithm",
         baseStepSize=repr(experiment.step_size))
    ssv = _parameter_set(None, name, system_params)
    return _xml_bytes(ssd), _xml_bytes(ssv), sources


def write_ssp(out: str | os.PathLike, components: Sequence[ComponentLike],
              connections: Sequence[ConnectionLike], experiment: Experiment,
              name: str = "abu") -> Path:
    """Write the SSP archive ``out`` (atomically) holding the components' FMUs.

    Args:
        out: the ``.ssp`` file to write.
        components: FMU instances with their parameter values (SI units).
        connections: output -> input links between them.
        experiment: default experiment (start, stop, fixed communication step) [s].
        name: name of the system and of the parameter set (``resources/<name>.ssv``).

    Returns:
        The path written.
    """
    out_path = Path(out)
    interfaces = {comp.name: read_fmu_interface(comp.fmu) for comp in components}
    ssv_name = f"{name}.ssv"
    ssd, ssv, sources = build_ssp_documents(name, components, connections, experiment,
                                            interfaces, ssv_name)
    files = {comp.name: Path(comp.fmu) for comp in components}
    with atomic_open(out_path, "wb") as handle:
        with zipfile.ZipFile(handle, "w", compression=zipfile.ZIP_DEFLATED) as zf:
            zf.writestr(SSD_NAME, ssd)
            zf.writestr(f"resources/{ssv_name}", ssv)
            for source in sorted(set(sources.values())):
                comp_name = next(c for c, s in sources.items() if s == source)
                # FMUs are zip archives already: store them uncompressed
                zf.write(files[comp_name], source, compress_type=zipfile.ZIP_STORED)
    return out_path


def read_default_experiment(ssp: str | os.PathLike) -> Experiment:
    """Start, stop and fixed step [s] of an SSP archive's default experiment.

    fmpy's ``simulate_ssp`` ignores ``DefaultExperiment``; pass these to it.
    """
    from abu_model import validate

    path = Path(ssp)
    try:
        with zipfile.ZipFile(path) as zf:
            root = ET.fromstring(zf.read(SSD_NAME))
        default = root.find("ssd:DefaultExperiment", NS)
        fixed = default.find("ssd:Annotations/ssc:Annotation/osp:Algorithm/"
                             "osp:FixedStepAlgorithm", NS)
        texts = (default.get("startTime", "0"), default.get("stopTime"),
                 fixed.get("baseStepSize"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError, AttributeError) as exc:
        raise SspError(f"{path}: no SSP default experiment with a fixed step ({exc})") from None
    place = f"{path}, {SSD_NAME}, DefaultExperiment"

    def attribute(text, name: str, **limits) -> float:
        if text is None:
            raise SspError(f"{place}: attribute '{name}' is missing; expected a number [s]")
        return validate.cell(text, f"{place} attribute '{name}'", unit="s", error=SspError,
                             **limits)

    start = attribute(texts[0], "startTime")
    stop = attribute(texts[1], "stopTime", lo=start, lo_open=True)
    step = attribute(texts[2], "baseStepSize", lo=0.0, lo_open=True, hi=stop - start)
    return Experiment(start, stop, step)
