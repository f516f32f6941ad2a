"""The native FMU as FMI 3.0 (co-simulation and model exchange): ``<name>-native-fmi3.fmu``.

Built from the FMI 2.0 native FMU (:mod:`fmu_build.native`): the same sources and variables.
``prsm_fmi3.c`` includes the FMI 2.0 interface and maps each FMI 3.0 function onto it, so both
FMUs run the same code.  This module

1. writes the FMI 3.0 modelDescription from the FMI 2.0 one: the same variables, value
   references, units, descriptions and start values (Real -> Float64, Integer -> Int32,
   Enumeration, Boolean, String), ``derivative`` as the state's value reference, the unit and
   type definitions, ``<ModelExchange>`` and ``<CoSimulation>``; the event indicators become
   four local Float64 variables (FMI 3.0 lists event indicators by variable), value references
   after the last one, followed by the independent variable ``time``;
2. compiles ``prsm_model.c``, ``prsm_ros.c`` and ``prsm_fmi3.c`` for FMI 3.0's platforms
   (``x86_64-linux`` for glibc 2.17 and later, ``x86_64-windows``, ``x86_64-darwin``,
   ``aarch64-darwin``: one thin library each) and checks every library
   (:mod:`fmu_build.platforms`) for the FMI 3.0 functions;
3. packs and validates it (fmpy's validation of FMI 3.0 modelDescriptions).
"""

from __future__ import annotations

import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from xml.dom.minidom import parseString

from . import native, platforms
from .builder import BuildError
from .native import N_EVENT_INDICATORS, SOURCES

__all__ = ["build_native_fmi3", "fmi3_model_description", "FMI3_FUNCTIONS"]

#: the functions the FMI 3.0 binary exports (fmi3Functions.h): every one, provided or refused
FMI3_FUNCTIONS = tuple("""fmi3GetVersion fmi3SetDebugLogging fmi3InstantiateModelExchange
fmi3InstantiateCoSimulation fmi3InstantiateScheduledExecution fmi3FreeInstance
fmi3EnterInitializationMode fmi3ExitInitializationMode fmi3EnterEventMode fmi3Terminate fmi3Reset
fmi3GetFloat32 fmi3GetFloat64 fmi3GetInt8 fmi3GetUInt8 fmi3GetInt16 fmi3GetUInt16 fmi3GetInt32
fmi3GetUInt32 fmi3GetInt64 fmi3GetUInt64 fmi3GetBoolean fmi3GetString fmi3GetBinary fmi3GetClock
fmi3SetFloat32 fmi3SetFloat64 fmi3SetInt8 fmi3SetUInt8 fmi3SetInt16 fmi3SetUInt16 fmi3SetInt32
fmi3SetUInt32 fmi3SetInt64 fmi3SetUInt64 fmi3SetBoolean fmi3SetString fmi3SetBinary fmi3SetClock
fmi3GetNumberOfVariableDependencies fmi3GetVariableDependencies fmi3GetFMUState fmi3SetFMUState
fmi3FreeFMUState fmi3SerializedFMUStateSize fmi3SerializeFMUState fmi3DeserializeFMUState
fmi3GetDirectionalDerivative fmi3GetAdjointDerivative fmi3EnterConfigurationMode
fmi3ExitConfigurationMode fmi3GetIntervalDecimal fmi3GetIntervalFraction fmi3GetShiftDecimal
fmi3GetShiftFraction fmi3SetIntervalDecimal fmi3SetIntervalFraction fmi3SetShiftDecimal
fmi3SetShiftFraction fmi3EvaluateDiscreteStates fmi3UpdateDiscreteStates
fmi3EnterContinuousTimeMode fmi3CompletedIntegratorStep fmi3SetTime fmi3SetContinuousStates
fmi3GetContinuousStateDerivatives fmi3GetEventIndicators fmi3GetContinuousStates
fmi3GetNominalsOfContinuousStates fmi3GetNumberOfEventIndicators fmi3GetNumberOfContinuousStates
fmi3EnterStepMode fmi3GetOutputDerivatives fmi3DoStep fmi3ActivateModelPartition""".split())

SOURCES3 = tuple(s for s in SOURCES if s != "prsm_fmi2_me.c") + ("prsm_fmi3.c",)
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
_TYPE3 = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String",
          "Enumeration": "Enumeration"}
#: what each event indicator of prsm_fmi2_me.c is
_INDICATORS = ("screw speed [rad/s]: zero where the friction forces reverse",
               "screw speed - friction band speed [rad/s]: the band's upper edge",
               "screw speed + friction band speed [rad/s]: the band's lower edge",
               "+1 where the rigid contact has a solution, -1 where it has none")


def fmi3_model_description(md2: bytes) -> tuple[bytes, int]:
    """The FMI 3.0 modelDescription of the FMI 2.0 native FMU's ``md2``, and the value
    reference of the first event indicator (module docstring, step 1)."""
    r2 = ET.fromstring(md2)
    me2, cs2 = r2.find("ModelExchange"), r2.find("CoSimulation")
    root = ET.Element("fmiModelDescription", fmiVersion="3.0", modelName=r2.get("modelName"),
                      instantiationToken=r2.get("guid"),
                      description=r2.get("description", ""),
                      generationTool=r2.get("generationTool", "") + " (FMI 3.0)",
                      variableNamingConvention="structured")
    for key in ("author", "version", "generationDateAndTime"):
        if r2.get(key):
            root.set(key, r2.get(key))
    ident = cs2.get("modelIdentifier")
    ET.SubElement(root, "ModelExchange", modelIdentifier=ident, needsExecutionTool="false",
                  canBeInstantiatedOnlyOncePerProcess="false", canGetAndSetFMUState="true",
                  canSerializeFMUState="true", needsCompletedIntegratorStep="false")
    ET.SubElement(root, "CoSimulation", modelIdentifier=ident, needsExecutionTool="false",
                  canBeInstantiatedOnlyOncePerProcess="false", canGetAndSetFMUState="true",
                  canSerializeFMUState="true", canHandleVariableCommunicationStepSize="true",
                  hasEventMode="false")
    assert me2 is not None
    units = r2.find("UnitDefinitions")
    if units is not None:
        u3 = ET.SubElement(root, "UnitDefinitions")
        for u in units:
            unit = ET.SubElement(u3, "Unit", name=u.get("name"))
            for b in u:
                ET.SubElement(unit, "BaseUnit", dict(b.attrib))
    enum_types = {}
    types = r2.find("TypeDefinitions")
    if types is not None:
        t3 = ET.SubElement(root, "TypeDefinitions")
        for st in types:
            enum = st.find("Enumeration")
            if enum is None:
                continue
            et = ET.SubElement(t3, "EnumerationType", name=st.get("name"))
            enum_types[st.get("name")] = et
            for item in enum:
                ET.SubElement(et, "Item", dict(item.attrib))
    de = r2.find("DefaultExperiment")
    if de is not None:
        ET.SubElement(root, "DefaultExperiment", dict(de.attrib))
    variables = list(r2.find("ModelVariables"))
    vr_of_index = {i + 1: sv.get("valueReference") for i, sv in enumerate(variables)}
    mv = ET.SubElement(root, "ModelVariables")
    for sv in variables:
        typed = next(c for c in sv if c.tag in _TYPE3)
        attrs = {k: sv.get(k) for k in ("name", "valueReference", "description", "causality",
                                         "variability", "initial") if sv.get(k) is not None}
        for k, v in typed.attrib.items():
            if k == "derivative":
                attrs["derivative"] = vr_of_index[int(v)]
            elif k != "start" or typed.tag != "String":
                attrs[k] = v
        if typed.tag == "Boolean" and "start" in attrs:
            attrs["start"] = "true" if attrs["start"] in ("true", "1") else "false"
        v3 = ET.SubElement(mv, _TYPE3[typed.tag], attrs)
        if typed.tag == "String" and typed.get("start") is not None:
            ET.SubElement(v3, "Start", value=typed.get("start"))
    ei0 = max(int(sv.get("valueReference")) for sv in variables) + 1
    for i, text in enumerate(_INDICATORS):
        ET.SubElement(mv, "Float64", name=f"event_indicator[{i + 1}]", valueReference=str(ei0 + i),
                      description=f"event indicator {i + 1}: {text}", causality="local",
                      variability="continuous", initial="calculated")
    assert len(_INDICATORS) == N_EVENT_INDICATORS
    # FMI 3.0 declares the independent variable; its value reference follows the indicators
    ET.SubElement(mv, "Float64", name="time", valueReference=str(ei0 + N_EVENT_INDICATORS),
                  description="simulation time", causality="independent",
                  variability="continuous")
    ms2, ms = r2.find("ModelStructure"), ET.SubElement(root, "ModelStructure")
    for section, tag in (("Outputs", "Output"), ("Derivatives", "ContinuousStateDerivative"),
                         ("InitialUnknowns", "InitialUnknown")):
        for u in ms2.iterfind(f"{section}/Unknown"):
            ET.SubElement(ms, tag, valueReference=vr_of_index[int(u.get("index"))])
    for i in range(N_EVENT_INDICATORS):
        ET.SubElement(ms, "EventIndicator", valueReference=str(ei0 + i))
    xml = parseString(ET.tostring(root, encoding="utf-8")).toprettyxml(indent="  ", encoding="UTF-8")
    return xml, ei0


def build_native_fmi3(fmu2: str | Path, dest: str | Path | None = None, check: bool = True,
                      targets: tuple[str, ...] = platforms.FMI2_PLATFORMS) -> Path:
    """Build ``<name>-native-fmi3.fmu`` from the FMI 2.0 native FMU ``fmu2`` (module docstring).

    Parameters
    ----------
    fmu2 : str or Path
        ``<name>-native.fmu`` (:func:`fmu_build.native.build_native`): its sources and
        modelDescription.
    dest : str or Path, optional
        Output directory (default: ``fmu2``'s).
    check : bool
        Validate with fmpy.
    targets : tuple of str
        Platforms by their FMI 2.0 folder names (``darwin64`` gives ``x86_64-darwin`` and
        ``aarch64-darwin``).

    Returns
    -------
    Path
        The FMU file.

    Raises
    ------
    BuildError
        When a library fails to build or is unfit for its platform, or the FMU is not valid.
    """
    fmu2 = Path(fmu2)
    dest = Path(dest) if dest is not None else fmu2.parent
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="prsm_fmi3_") as tmp:
        tmp = Path(tmp)
        src = tmp / "sources"
        src.mkdir()
        with zipfile.ZipFile(fmu2) as z:
            md2 = z.read("modelDescription.xml")
            for n in z.namelist():
                if n.startswith("sources/"):
                    (src / Path(n).name).write_bytes(z.read(n))
        headers = native._fmi_headers("fmi3Functions.h", "3.0")
        for f in FMI3_HEADERS:
            shutil.copy(headers / f, src / f)
        shutil.copy(native.SOURCE_DIR / "prsm_fmi3.c", src / "prsm_fmi3.c")
        md3, ei0 = fmi3_model_description(md2)
        ident = ET.fromstring(md2).find("CoSimulation").get("modelIdentifier")
        libs = {}
        for plat in targets:
            p = platforms.PLATFORMS[plat]
            for folder, arch in zip(p.fmi3, p.arches):
                rel = f"binaries/{folder}/{ident}{p.suffix}"
                libs[rel] = platforms.compile_for(plat, src, SOURCES3, tmp / rel, FMI3_FUNCTIONS,
                                                  defines=(f"PRSM_FMI3_EI_VR0={ei0}",),
                                                  arches=(arch,))
        fmu = tmp / fmu2.name.replace("-native.fmu", "-native-fmi3.fmu")
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", md3)
            for rel, lib in libs.items():
                z.write(lib, rel)
            for f in sorted(src.iterdir()):
                z.write(f, f"sources/{f.name}")
        if check:
            from fmpy.validation import validate_fmu

            problems = validate_fmu(str(fmu))
            if problems:
                raise BuildError(f"{fmu.name} is not valid:\n  " + "\n  ".join(map(str, problems)))
        target = dest / fmu.name
        shutil.move(str(fmu), target)
    return target
