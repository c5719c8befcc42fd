"""Post-processing of the modelDescription.xml that pythonfmu 0.7 generates.

pythonfmu writes a ModelStructure with bare ``<Outputs>`` (every output then looks like
direct feedthrough of every input to a master), no ``<InitialUnknowns>`` (so
``fmpy.validation.validate_fmu`` complains) and no units. :func:`fix_model_description`
rewrites the XML from an :class:`InterfaceSpec` that each slave declares next to its
variables:

* ``unit`` attributes on every Real variable plus a ``<UnitDefinitions>`` block with the SI
  base-unit exponents (FMI 2.0 sec. 2.2.2);
* ``<Outputs>`` with the true ``dependencies`` (1-based indices of the inputs an output
  depends on directly; an empty list means the output is a function of internal states and
  parameters only);
* ``<InitialUnknowns>``: every output with initial ``approx``/``calculated`` (the default of
  outputs) and every calculatedParameter, in ascending index order, without a
  ``dependencies`` attribute, i.e. depending on all knowns (always correct, FMI 2.0 sec. 2.2.8).

:func:`rewrite_fmu_model_description` applies it to a built FMU atomically.
"""
from __future__ import annotations

import copy
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping, Sequence
from xml.etree import ElementTree as ET

from abu_model.atomic_io import atomic_open
from abu_model.errors import AbuError

#: SI base-unit exponents of the units used by the FMUs (Modelica unit syntax for the names).
UNIT_DEFINITIONS: dict[str, dict[str, int]] = {
    "1": {},
    "s": {"s": 1},
    "m": {"m": 1},
    "kg": {"kg": 1},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "rad/s3": {"rad": 1, "s": -3},
    "rad/s4": {"rad": 1, "s": -4},
    "rad/s5": {"rad": 1, "s": -5},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m/s": {"kg": 1, "m": 2, "s": -3},
    "N.m/s2": {"kg": 1, "m": 2, "s": -4},
    "N.m/s3": {"kg": 1, "m": 2, "s": -5},
    "N.m/s4": {"kg": 1, "m": 2, "s": -6},
    "kg.m2": {"kg": 1, "m": 2},
}

# Order of the children of <fmiModelDescription> in the FMI 2.0 schema.
_TOP_LEVEL_ORDER = ("ModelExchange", "CoSimulation", "UnitDefinitions", "TypeDefinitions",
                    "LogCategories", "DefaultExperiment", "VendorAnnotations",
                    "ModelVariables", "ModelStructure")

_TYPE_TAGS = ("Real", "Integer", "Boolean", "String", "Enumeration")


class FmuBuildError(AbuError):
    """An FMU could not be built or its model description is inconsistent with its spec."""


@dataclass(frozen=True)
class InterfaceSpec:
    """What a slave declares about its interface beyond what pythonfmu writes.

    Attributes:
        units: unit of every Real variable by name (``"1"`` for dimensionless), keys of
            :data:`UNIT_DEFINITIONS`.
        output_dependencies: for every output, the names of the inputs it depends on
            directly (feedthrough) during a simulation step; ``()`` for none.
        real_starts: exact start values of Real variables; written with ``repr`` so they
            round-trip (pythonfmu writes 16 significant digits, one short of a double's 17).
    """

    units: Mapping[str, str] = field(default_factory=dict)
    output_dependencies: Mapping[str, Sequence[str]] = field(default_factory=dict)
    real_starts: Mapping[str, float] = field(default_factory=dict)


def _variable_type(sv: ET.Element) -> str:
    for child in sv:
        if child.tag in _TYPE_TAGS:
            return child.tag
    raise FmuBuildError(f"variable '{sv.get('name')}' has no type element")


def fix_model_description(xml: bytes, spec: InterfaceSpec) -> bytes:
    """Return ``xml`` (a pythonfmu modelDescription.xml) with units and a complete ModelStructure.

    Raises:
        FmuBuildError: a variable lacks a description or (Real) a unit, a unit is unknown, an
            output has no declared dependencies, or a dependency is not an input.
    """
    try:
        root = ET.fromstring(xml)
    except ET.ParseError as exc:
        raise FmuBuildError(f"modelDescription.xml is not well-formed XML: {exc}") from None
    model_variables = root.find("ModelVariables")
    if model_variables is None:
        raise FmuBuildError("modelDescription.xml has no <ModelVariables>")
    variables = list(model_variables.findall("ScalarVariable"))
    index = {sv.get("name"): i + 1 for i, sv in enumerate(variables)}
    causality = {sv.get("name"): sv.get("causality", "local") for sv in variables}

    unknown_units = set(spec.units.values()) - set(UNIT_DEFINITIONS)
    if unknown_units:
        raise FmuBuildError(f"units without a definition: {sorted(unknown_units)}; "
                            f"expected one of {sorted(UNIT_DEFINITIONS)}")
    extra = set(spec.units) - set(index)
    if extra:
        raise FmuBuildError(f"units declared for unknown variables: {sorted(extra)}")

    used_units: list[str] = []
    for sv in variables:
        name = sv.get("name")
        if not sv.get("description"):
            raise FmuBuildError(f"variable '{name}' has no description")
        vtype = _variable_type(sv)
        if vtype == "Real":
            unit = spec.units.get(name)
            if unit is None:
                raise FmuBuildError(f"Real variable '{name}' has no unit in the interface spec")
            real = sv.find("Real")
            real.set("unit", unit)
            if real.get("start") is not None and name in spec.real_starts:
                real.set("start", repr(float(spec.real_starts[name])))
            if unit not in used_units:
                used_units.append(unit)
        elif name in spec.units:
            raise FmuBuildError(f"{vtype} variable '{name}' cannot carry a unit "
                                "(FMI 2.0: Real only)")

    # UnitDefinitions, placed where the schema wants it.
    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    if used_units:
        unit_defs = ET.Element("UnitDefinitions")
        for unit in sorted(used_units):
            unit_el = ET.SubElement(unit_defs, "Unit", name=unit)
            exponents = UNIT_DEFINITIONS[unit]
            ET.SubElement(unit_el, "BaseUnit", {k: str(v) for k, v in exponents.items()})
        _insert_in_schema_order(root, unit_defs)

    outputs = [sv.get("name") for sv in variables if causality[sv.get("name")] == "output"]
    missing = [name for name in outputs if name not in spec.output_dependencies]
    if missing:
        raise FmuBuildError(f"outputs without declared dependencies: {missing}")
    not_outputs = [name for name in spec.output_dependencies if causality.get(name) != "output"]
    if not_outputs:
        raise FmuBuildError("dependencies declared for variables that are not outputs: "
                            f"{not_outputs}")

    structure = root.find("ModelStructure")
    if structure is None:
        structure = ET.SubElement(root, "ModelStructure")
    for child in list(structure):
        structure.remove(child)
    if outputs:
        outputs_el = ET.SubElement(structure, "Outputs")
        for name in outputs:
            deps = []
            for dep in spec.output_dependencies[name]:
                if causality.get(dep) != "input":
                    raise FmuBuildError(
                        f"output '{name}' declares a dependency on '{dep}', which is not an input")
                deps.append(index[dep])
            ET.SubElement(outputs_el, "Unknown", index=str(index[name]),
                          dependencies=" ".join(str(i) for i in sorted(set(deps))))

    initial_unknowns = []
    for sv in variables:
        name = sv.get("name")
        if (causality[name] == "output"
                and sv.get("initial", "calculated") in ("approx", "calculated")):
            initial_unknowns.append(index[name])
        elif causality[name] == "calculatedParameter":
            initial_unknowns.append(index[name])
    if initial_unknowns:
        init_el = ET.SubElement(structure, "InitialUnknowns")
        for i in sorted(initial_unknowns):
            ET.SubElement(init_el, "Unknown", index=str(i))

    _strip_whitespace(root)
    ET.indent(root, space="  ")
    return ET.tostring(root, encoding="UTF-8", xml_declaration=True)


def _insert_in_schema_order(root: ET.Element, element: ET.Element) -> None:
    rank = _TOP_LEVEL_ORDER.index(element.tag)
    for position, child in enumerate(list(root)):
        if child.tag in _TOP_LEVEL_ORDER and _TOP_LEVEL_ORDER.index(child.tag) > rank:
            root.insert(position, element)
            return
    root.append(element)


def _strip_whitespace(element: ET.Element) -> None:
    for el in element.iter():
        if el.text is not None and not el.text.strip():
            el.text = None
        if el.tail is not None and not el.tail.strip():
            el.tail = None


def rewrite_fmu_model_description(source: str | os.PathLike, target: str | os.PathLike,
                                  spec: InterfaceSpec) -> Path:
    """Copy the FMU ``source`` to ``target`` with its modelDescription.xml fixed.

    ``target`` is written atomically (temporary file in its folder, then rename), so a reader
    never sees a half-written FMU; ``source`` may equal ``target``.
    """
    source, target = Path(source), Path(target)
    target.parent.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(source) as zin:
        try:
            fixed = fix_model_description(zin.read("modelDescription.xml"), spec)
        except KeyError:
            raise FmuBuildError(f"{source}: no modelDescription.xml in the FMU") from None
        with atomic_open(target, "wb") as handle, \
                zipfile.ZipFile(handle, "w", compression=zipfile.ZIP_DEFLATED) as zout:
            for info in zin.infolist():
                data = fixed if info.filename == "modelDescription.xml" else zin.read(info)
                new_info = copy.copy(info)  # keeps name, date and permissions
                new_info.compress_type = zipfile.ZIP_DEFLATED
                zout.writestr(new_info, data)
    return target


def variable_table_markdown(xml: bytes) -> str:
    """A Markdown table of the variables in a (fixed) modelDescription.xml.

    Columns: name, causality, type, unit, start value, value reference, direct dependencies
    (outputs only) and description. docs/fmus.md holds these tables for the three FMUs.
    """
    root = ET.fromstring(xml)
    variables = list(root.find("ModelVariables").findall("ScalarVariable"))
    by_index = {i + 1: sv.get("name") for i, sv in enumerate(variables)}
    deps: dict[str, str] = {}
    outputs = root.find("ModelStructure/Outputs")
    for unknown in [] if outputs is None else outputs.findall("Unknown"):
        names = [by_index[int(i)] for i in (unknown.get("dependencies") or "").split()]
        deps[by_index[int(unknown.get("index"))]] = ", ".join(names) if names else "-"
    rows = ["| name | causality | type | unit | start | vr | depends on | description |",
            "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for sv in variables:
        type_el = next(child for child in sv if child.tag in _TYPE_TAGS)
        name = sv.get("name")
        rows.append("| " + " | ".join([
            f"`{name}`", sv.get("causality", "local"), type_el.tag, type_el.get("unit", ""),
            type_el.get("start", ""), sv.get("valueReference"), deps.get(name, ""),
            (sv.get("description") or "").replace("|", "\\|")]) + " |")
    return "\n".join(rows) + "\n"
