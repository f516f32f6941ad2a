"""Complete the modelDescription.xml that pythonfmu 0.7 writes.

pythonfmu writes the variables (with the unit, min and max attributes that
:mod:`prsm_fmu.slave` adds) and ``ModelStructure/Outputs``, but no ``UnitDefinitions``, no
``InitialUnknowns`` and no output dependencies.  :func:`complete` adds them, so that
``fmpy validate`` finds no problem:

* ``UnitDefinitions``: every unit a variable uses, with its SI base-unit exponents;
* ``ModelStructure/Outputs``: ``dependencies=""`` on every output: the outputs are computed
  from the state at the communication point and the inputs held over the last step, so a
  new input value does not reach them before the next ``doStep`` (no direct feedthrough);
* ``ModelStructure/InitialUnknowns``: every output (their ``initial`` is ``calculated``),
  without a dependency list (they depend on every parameter and input start value);
* ``TypeDefinitions``: the Enumerations (``Fidelity``, ``Stepper``) with item names, values
  and descriptions; pythonfmu 0.7 has no Enumeration variable, so the slave registers them as
  Integers (fmi2GetInteger/fmi2SetInteger reach them, as FMI 2.0 prescribes) that write
  themselves as ``<Enumeration declaredType=...>``;
* ``generationTool`` names fmu_build and pythonfmu.

:func:`check` then asserts the project's own rules (docs/fmu.md, "Variables"): every variable has a
description, every Real a defined unit, every variable an explicit variability.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from xml.dom.minidom import parseString

#: unit name -> SI base-unit exponents (FMI 2.0 BaseUnit attributes)
UNITS: dict[str, dict[str, int]] = {
    "1": {},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "kg": {"kg": 1},
    "kg.m2": {"kg": 1, "m": 2},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "s": {"s": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.s/m": {"kg": 1, "s": -1},
    "W": {"kg": 1, "m": 2, "s": -3},
    "J": {"kg": 1, "m": 2, "s": -2},
}

_TYPES = ("Real", "Integer", "Boolean", "String", "Enumeration")


def _typed(sv: ET.Element) -> ET.Element:
    for child in sv:
        if child.tag in _TYPES:
            return child
    raise ValueError(f"variable {sv.get('name')!r} has no type element")


def complete(xml: bytes, generation_tool: str | None = None,
             enumerations: dict[str, list[tuple[str, int, str]]] | None = None) -> bytes:
    """Return the completed modelDescription.xml (see module docstring).

    Parameters
    ----------
    xml : bytes
        modelDescription.xml as pythonfmu wrote it.
    generation_tool : str, optional
        Value of the ``generationTool`` attribute.
    enumerations : dict, optional
        ``TypeDefinitions`` to write: Enumeration name -> [(item name, value, description)]
        (the variables that use them carry ``declaredType``).

    Returns
    -------
    bytes
        The completed document, UTF-8, pretty-printed.
    """
    root = ET.fromstring(xml)
    for elem in root.iter():  # drop pythonfmu's indentation before pretty-printing again
        if elem.text is not None and not elem.text.strip():
            elem.text = None
        if elem.tail is not None and not elem.tail.strip():
            elem.tail = None
    if generation_tool:
        root.set("generationTool", generation_tool)
    variables = root.find("ModelVariables")
    svs = list(variables)
    used = sorted({_typed(sv).get("unit") for sv in svs} - {None})
    unknown = [u for u in used if u not in UNITS]
    if unknown:
        raise ValueError(f"units without a definition in fmu_build.model_description.UNITS: {unknown}")
    old = root.find("UnitDefinitions")
    if old is not None:
        root.remove(old)
    units = ET.Element("UnitDefinitions")
    for name in used:
        unit = ET.SubElement(units, "Unit", name=name)
        ET.SubElement(unit, "BaseUnit", {k: str(v) for k, v in UNITS[name].items()})
    # schema order: ModelExchange?, CoSimulation?, UnitDefinitions?, TypeDefinitions?, ...
    children = list(root)
    after = max(i for i, c in enumerate(children) if c.tag in ("ModelExchange", "CoSimulation"))
    root.insert(after + 1, units)
    old = root.find("TypeDefinitions")
    if old is not None:
        root.remove(old)
    if enumerations:
        types = ET.Element("TypeDefinitions")
        for name, items in enumerations.items():
            enum = ET.SubElement(ET.SubElement(types, "SimpleType", name=name), "Enumeration")
            for item, value, desc in items:
                ET.SubElement(enum, "Item", name=item, value=str(value), description=desc)
        root.insert(after + 2, types)

    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    outputs = [i for i, sv in enumerate(svs, start=1) if sv.get("causality") == "output"]
    if outputs:
        node = ET.SubElement(structure, "Outputs")
        for i in outputs:
            ET.SubElement(node, "Unknown", index=str(i), dependencies="")
        initial = [i for i in outputs if svs[i - 1].get("initial") in (None, "approx", "calculated")]
        if initial:
            node = ET.SubElement(structure, "InitialUnknowns")
            for i in initial:
                ET.SubElement(node, "Unknown", index=str(i))
    text = ET.tostring(root, encoding="utf-8")
    return parseString(text).toprettyxml(indent="  ", encoding="UTF-8")


def check(xml: bytes) -> list[str]:
    """Problems with the project's rules for the modelDescription (empty list: none).

    Every variable needs a description and an explicit variability, every Real a unit that
    ``UnitDefinitions`` defines, every output an entry in ``Outputs`` and ``InitialUnknowns``.
    """
    root = ET.fromstring(xml)
    problems = []
    defined = {u.get("name") for u in root.iterfind("UnitDefinitions/Unit")}
    declared = {t.get("name") for t in root.iterfind("TypeDefinitions/SimpleType")}
    svs = list(root.find("ModelVariables"))
    for sv in svs:
        name = sv.get("name")
        typed = _typed(sv)
        if not sv.get("description"):
            problems.append(f"{name}: no description")
        if not sv.get("variability"):
            problems.append(f"{name}: no explicit variability")
        if typed.tag == "Enumeration" and typed.get("declaredType") not in declared:
            problems.append(f"{name}: Enumeration without a declared type in TypeDefinitions")
        if typed.tag == "Real":
            unit = typed.get("unit")
            if unit is None:
                problems.append(f"{name}: Real without a unit")
            elif unit not in defined:
                problems.append(f"{name}: unit {unit!r} is not in UnitDefinitions")
    outputs = {str(i) for i, sv in enumerate(svs, start=1) if sv.get("causality") == "output"}
    # model exchange: the states' derivatives are initial unknowns too (the states here are outputs)
    derivatives = {str(i) for i, sv in enumerate(svs, start=1)
                   if _typed(sv).get("derivative") is not None}
    for section, expected in (("Outputs", outputs), ("InitialUnknowns", outputs | derivatives)):
        listed = {u.get("index") for u in root.iterfind(f"ModelStructure/{section}/Unknown")}
        if listed != expected:
            what = "the outputs" if expected == outputs else "the outputs and state derivatives"
            problems.append(f"ModelStructure/{section} does not list exactly {what}")
    return problems
