"""Build the native FMU as FMI 3.0 co-simulation, ``<name>-native-fmi3.fmu``, from the FMI 2.0 one.

The FMI 3.0 FMU is made from the FMI 2.0 native FMU (:func:`fmu_build.native.build_native`):

1. its modelDescription is the FMI 2.0 one (itself generated from the Python FMU's variable
   table) written in FMI 3.0 form (:func:`fmi3_model_description`): the same variables, names
   (``stage[1].contact_force`` ...), value references, units, start values and enumerations;
   Real becomes Float64, Integer Int32, the Enumerations stay Enumerations (accessed as Int64);
   the independent variable ``time`` is added (value reference one above the largest);
2. its binaries are compiled from the FMI 2.0 FMU's own ``sources/`` plus
   ``prsm_fmi3.c``, which answers each FMI 3.0 call with the FMI 2.0 call doing the same thing
   (one state machine, one set of refusals, one model), and ``prsm_fmi3_variables.h``, the FMI 3.0
   type of every value reference (:func:`variables3_header`); the FMI 3.0 headers are fmpy's;
3. a binary is built for every platform the FMI 2.0 FMU carries, in FMI 3.0's folders
   (``x86_64-linux``, ``x86_64-windows``, ``x86_64-darwin`` and ``aarch64-darwin``: the universal
   macOS build split into its two thin files), each read back for the ``fmi3`` exports
   (:func:`fmi3_functions`), its C runtime and, on Linux, glibc 2.17;
4. the FMU is checked with ``fmpy validate``.

The library also exports the FMI 2.0 functions it is built on (unused by an FMI 3.0 host).
"""

from __future__ import annotations

import shutil
import struct
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path
from xml.dom.minidom import parseString

from . import binary_check, model_description, native, platforms
from .builder import BuildError

__all__ = ["build_native_fmi3", "fmi3_model_description", "variables3_header", "fmi3_functions",
           "fmi3_name", "FMI3_COMMON", "FMI3_COSIMULATION", "TIME_NAME"]

#: the FMI 3.0 source compiled with the FMI 2.0 FMU's sources
FMI3_SOURCE = "prsm_fmi3.c"
FMI3_HEADERS = ("fmi3Functions.h", "fmi3FunctionTypes.h", "fmi3PlatformTypes.h")
#: the independent variable every FMI 3.0 modelDescription declares
TIME_NAME = "time"

#: the functions every FMI 3.0 binary exports (FMI 3.0 §2.3 common functions)
FMI3_COMMON = ("fmi3GetVersion", "fmi3SetDebugLogging", "fmi3InstantiateModelExchange",
               "fmi3InstantiateCoSimulation", "fmi3InstantiateScheduledExecution",
               "fmi3FreeInstance", "fmi3EnterInitializationMode", "fmi3ExitInitializationMode",
               "fmi3EnterEventMode", "fmi3Terminate", "fmi3Reset",
               *(f"fmi3{a}{t}" for a in ("Get", "Set")
                 for t in ("Float32", "Float64", "Int8", "UInt8", "Int16", "UInt16", "Int32",
                           "UInt32", "Int64", "UInt64", "Boolean", "String", "Binary", "Clock")),
               "fmi3GetNumberOfVariableDependencies", "fmi3GetVariableDependencies",
               "fmi3GetFMUState", "fmi3SetFMUState", "fmi3FreeFMUState",
               "fmi3SerializedFMUStateSize", "fmi3SerializeFMUState", "fmi3DeserializeFMUState",
               "fmi3GetDirectionalDerivative", "fmi3GetAdjointDerivative",
               "fmi3EnterConfigurationMode", "fmi3ExitConfigurationMode",
               "fmi3GetIntervalDecimal", "fmi3GetIntervalFraction", "fmi3GetShiftDecimal",
               "fmi3GetShiftFraction", "fmi3SetIntervalDecimal", "fmi3SetIntervalFraction",
               "fmi3SetShiftDecimal", "fmi3SetShiftFraction", "fmi3EvaluateDiscreteStates",
               "fmi3UpdateDiscreteStates")
#: the co-simulation functions (FMI 3.0 §4.2)
FMI3_COSIMULATION = ("fmi3EnterStepMode", "fmi3GetOutputDerivatives", "fmi3DoStep")

#: FMI 2.0 type element -> (FMI 3.0 variable element, type code of prsm_fmi3.c)
_TYPES = {"Real": ("Float64", "V3_FLOAT64"), "Integer": ("Int32", "V3_INT32"),
          "Enumeration": ("Enumeration", "V3_ENUM"), "Boolean": ("Boolean", "V3_BOOLEAN"),
          "String": ("String", "V3_STRING")}
#: FMI 2.0 attributes (variable and its type element) that FMI 3.0 keeps on the variable
_KEPT = ("name", "valueReference", "description", "causality", "variability", "initial",
         "declaredType", "quantity", "unit", "displayUnit", "relativeQuantity", "min", "max",
         "nominal", "unbounded", "start")
_CS_KEPT = ("modelIdentifier", "needsExecutionTool", "canBeInstantiatedOnlyOncePerProcess",
            "canHandleVariableCommunicationStepSize", "maxOutputDerivativeOrder")
_ROOT_KEPT = ("modelName", "description", "author", "version", "copyright", "license",
              "generationTool", "generationDateAndTime", "variableNamingConvention")


def fmi3_name(name: str) -> str:
    """File stem of the FMI 3.0 native FMU of the FMU built as ``name`` (``PRSM2`` ->
    ``PRSM2-native-fmi3``)."""
    return f"{name}-native-fmi3"


def fmi3_functions() -> tuple[str, ...]:
    """The functions every binary of the FMI 3.0 native FMU must export."""
    return FMI3_COMMON + FMI3_COSIMULATION


def _strip(root: ET.Element) -> None:
    for elem in root.iter():
        if elem.text is not None and not elem.text.strip():
            elem.text = None
        if elem.tail is not None and not elem.tail.strip():
            elem.tail = None


def fmi3_model_description(md2: bytes) -> bytes:
    """The FMI 3.0 modelDescription of the FMI 2.0 native FMU's ``md2`` (module docstring, 1).

    Raises
    ------
    BuildError
        If a variable is already called ``time`` or has a type FMI 3.0 is not given here.
    """
    old = ET.fromstring(md2)
    _strip(old)
    root = ET.Element("fmiModelDescription", fmiVersion="3.0")
    for key in _ROOT_KEPT[:1]:
        root.set(key, old.get(key))
    root.set("instantiationToken", old.get("guid"))
    for key in _ROOT_KEPT[1:]:
        if old.get(key) is not None:
            root.set(key, old.get(key))
    cs2 = old.find("CoSimulation")
    cs = ET.SubElement(root, "CoSimulation")
    for key in _CS_KEPT:
        if cs2.get(key) is not None:
            cs.set(key, cs2.get(key))
    cs.set("canGetAndSetFMUState", cs2.get("canGetAndSetFMUstate", "false"))
    cs.set("canSerializeFMUState", cs2.get("canSerializeFMUstate", "false"))
    cs.set("hasEventMode", "false")
    cs.set("providesIntermediateUpdate", "false")
    units = old.find("UnitDefinitions")          # same form in FMI 3.0 (Unit, BaseUnit)
    if units is None:
        units = ET.Element("UnitDefinitions")
    if not any(u.get("name") == "s" for u in units):     # the unit of time
        ET.SubElement(ET.SubElement(units, "Unit", name="s"), "BaseUnit",
                      {k: str(v) for k, v in model_description.UNITS["s"].items()})
    root.append(units)
    types2 = old.find("TypeDefinitions")
    if types2 is not None:
        types = ET.SubElement(root, "TypeDefinitions")
        for st in types2.iterfind("SimpleType"):
            enum = st.find("Enumeration")
            if enum is None:
                raise BuildError(f"type {st.get('name')!r}: only Enumeration types are written "
                                 "in FMI 3.0 form here")
            et = ET.SubElement(types, "EnumerationType", name=st.get("name"))
            for item in enum.iterfind("Item"):
                et.append(item)
    for tag in ("LogCategories", "DefaultExperiment"):
        if (elem := old.find(tag)) is not None:
            root.append(elem)
    svs = list(old.find("ModelVariables"))
    if any(sv.get("name") == TIME_NAME for sv in svs):
        raise BuildError(f"a variable is called {TIME_NAME!r}: the FMI 3.0 FMU's independent "
                         "variable needs that name")
    variables = ET.SubElement(root, "ModelVariables")
    time_vr = max(int(sv.get("valueReference")) for sv in svs) + 1
    ET.SubElement(variables, "Float64", name=TIME_NAME, valueReference=str(time_vr),
                  causality="independent", variability="continuous",
                  description="simulation time", unit="s")
    for sv in svs:
        typed = model_description._typed(sv)
        tag = _TYPES[typed.tag][0]
        attrs = {**sv.attrib, **typed.attrib}
        var = ET.SubElement(variables, tag, {k: attrs[k] for k in _KEPT
                                             if k in attrs and not (tag == "String" and k == "start")})
        if tag == "String" and "start" in attrs:
            ET.SubElement(var, "Start", value=attrs["start"])
    structure = ET.SubElement(root, "ModelStructure")
    for group, tag in (("Outputs", "Output"), ("InitialUnknowns", "InitialUnknown")):
        for u in old.findall(f"ModelStructure/{group}/Unknown"):
            attrs = {"valueReference": svs[int(u.get("index")) - 1].get("valueReference")}
            if u.get("dependencies") is not None:
                deps = u.get("dependencies").split()
                attrs["dependencies"] = " ".join(svs[int(i) - 1].get("valueReference") for i in deps)
            ET.SubElement(structure, tag, attrs)
    return parseString(ET.tostring(root, encoding="utf-8")).toprettyxml(indent="  ", encoding="UTF-8")


def _c_string(s: str) -> str:
    return '"' + s.replace("\\", "\\\\").replace('"', '\\"') + '"'


def variables3_header(md3: bytes) -> str:
    """``prsm_fmi3_variables.h``: the FMI 3.0 type and name of every value reference of ``md3``."""
    root = ET.fromstring(md3)
    codes = {v3: code for v3, code in _TYPES.values()}
    rows: dict[int, tuple[str, str]] = {}
    for var in root.find("ModelVariables"):
        code = "V3_TIME" if var.get("causality") == "independent" else codes[var.tag]
        rows[int(var.get("valueReference"))] = (code, var.get("name"))
    top = max(rows)
    body = ",\n".join(f"    {{{rows[vr][0]}, {_c_string(rows[vr][1])}}}" if vr in rows
                      else '    {V3_NONE, ""}' for vr in range(top + 1))
    return (f"/* Generated by fmu_build.native_fmi3 from the FMI 3.0 modelDescription. Do not edit. */\n"
            f"#define PRSM3_MAX_VR {top}u\n"
            f"static const prsm_var3 PRSM3_VARS[PRSM3_MAX_VR + 1] = {{\n{body}\n}};\n")


def _fmi3_headers() -> Path:
    found = sorted(native._fmi_headers().rglob("fmi3Functions.h"))
    if not found:
        raise BuildError("fmpy ships no fmi3Functions.h: the FMI 3.0 headers come from fmpy "
                         "(pip install -e \".[fmu]\")")
    return found[0].parent


def thin_slices(data: bytes) -> list[bytes]:
    """The thin Mach-O files of a universal one (:func:`fmu_build.platforms.universal_macho`),
    in its order; a thin file alone."""
    if data[:4] != b"\xca\xfe\xba\xbe":
        return [data]
    n, = struct.unpack_from(">I", data, 4)
    out = []
    for i in range(n):
        _, _, offset, size, _ = struct.unpack_from(">iiIII", data, 8 + 20 * i)
        out.append(data[offset:offset + size])
    return out


def _fmi3_binaries(plat: platforms.Platform, universal: Path, identifier: str,
                   tmp: Path) -> dict[str, Path]:
    """FMI 3.0 folder name -> library file: one per architecture, each checked."""
    parts = thin_slices(universal.read_bytes())
    if len(parts) != len(plat.fmi3):
        raise BuildError(f"{plat.name}: {len(parts)} architecture(s) built, {len(plat.fmi3)} expected")
    out = {}
    for folder, arch, part in zip(plat.fmi3, plat.arches, parts):
        lib = tmp / folder / f"{identifier}{plat.suffix}"
        lib.parent.mkdir(parents=True, exist_ok=True)
        lib.write_bytes(part)
        try:
            found = binary_check.problems(binary_check.inspect(lib), arches=(arch,),
                                          exports=fmi3_functions(), libraries=plat.libraries,
                                          max_glibc=plat.max_glibc)
        except binary_check.BinaryFormatError as exc:
            found = [str(exc)]
        if found:
            raise BuildError(f"{folder}/{lib.name} is not fit for {folder}:\n  " + "\n  ".join(found))
        out[folder] = lib
    return out


def build_native_fmi3(fmu2: str | Path, dest: str | Path = "dist", check: bool = True,
                      targets: tuple[str, ...] | None = None) -> Path:
    """Build ``<dest>/<name>-native-fmi3.fmu`` from the FMI 2.0 native FMU ``fmu2``
    (``<name>-native.fmu``, :func:`fmu_build.native.build_native`), for each platform it carries.

    Parameters
    ----------
    fmu2 : str or Path
        The FMI 2.0 native FMU.
    dest : str or Path
        Output directory.
    check : bool
        Validate with ``fmpy validate``.
    targets : tuple of str, optional
        Only these of its platforms (keys of :data:`fmu_build.platforms.PLATFORMS`); default all.

    Returns
    -------
    Path
        The FMI 3.0 FMU.

    Raises
    ------
    BuildError
        When ``fmu2`` is not a native FMU, a binary cannot be built or is unfit for its
        platform, or (``check``) ``fmpy validate`` finds a problem.
    """
    fmu2 = Path(fmu2)
    if not fmu2.name.endswith("-native.fmu"):
        raise BuildError(f"{fmu2.name}: not allowed: must be a native FMU <name>-native.fmu")
    name = fmu2.name.removesuffix("-native.fmu")
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="prsm_fmi3_") as tmp:
        tmp = Path(tmp)
        src = tmp / "sources"
        src.mkdir()
        with zipfile.ZipFile(fmu2) as z:
            md2 = z.read("modelDescription.xml")
            members = z.namelist()
            for m in members:
                if m.startswith("sources/") and not m.endswith("/"):
                    (src / Path(m).name).write_bytes(z.read(m))
        identifier = ET.fromstring(md2).find("CoSimulation").get("modelIdentifier")
        md3 = fmi3_model_description(md2)
        (src / "prsm_fmi3_variables.h").write_text(variables3_header(md3), encoding="utf-8")
        shutil.copy(native.SOURCE_DIR / FMI3_SOURCE, src / FMI3_SOURCE)
        (src / "README.txt").write_text(SOURCES_README.format(id=identifier), encoding="utf-8")
        for f in FMI3_HEADERS:
            shutil.copy(_fmi3_headers() / f, src / f)
        libs: dict[str, Path] = {}
        for key, plat in platforms.PLATFORMS.items():
            if (f"binaries/{plat.name}/{identifier}{plat.suffix}" not in members
                    or (targets is not None and key not in targets)):
                continue
            built = platforms.compile_for(key, src, native.SOURCES + (FMI3_SOURCE,),
                                          tmp / "build" / key / f"{identifier}{plat.suffix}",
                                          fmi3_functions())
            libs.update(_fmi3_binaries(plat, built, identifier, tmp / "fmi3" / key))
        if not libs:
            raise BuildError(f"{fmu2.name} carries no binary of "
                             f"{', '.join(targets or platforms.PLATFORMS)}")
        fmu = tmp / f"{fmi3_name(name)}.fmu"
        with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as z:
            z.writestr("modelDescription.xml", md3)
            for folder, lib in sorted(libs.items()):
                z.write(lib, f"binaries/{folder}/{lib.name}")
            for f in sorted(src.iterdir()):
                z.write(f, f"sources/{f.name}")
        if check:
            from fmpy.validation import validate_fmu
            problems = list(validate_fmu(str(fmu)))
            if problems:
                raise BuildError(f"{fmu.name} is not valid:\n  " + "\n  ".join(problems))
        target = dest / fmu.name
        shutil.move(str(fmu), target)
    return target


SOURCES_README = """Sources of the native FMU {id} as FMI 3.0 co-simulation (C99, libm only).

prsm_fmi3.c is the FMI 3.0 interface; it answers each call with the FMI 2.0 interface of
prsm_fmi2.c, compiled into the same library (which therefore exports both).  The FMU's
binaries/ were built from these with Zig's C compiler.  Compile for another platform, e.g.

  Linux    gcc -std=c99 -O2 -fPIC -shared -ffp-contract=off prsm_model.c prsm_ros.c prsm_fmi2.c prsm_fmi3.c -o {id}.so -lm
  macOS    clang -std=c99 -O2 -fPIC -shared -ffp-contract=off prsm_model.c prsm_ros.c prsm_fmi2.c prsm_fmi3.c -o {id}.dylib
  Windows  cl /O2 /fp:precise /LD prsm_model.c prsm_ros.c prsm_fmi2.c prsm_fmi3.c /Fe{id}.dll

and put the library under binaries/<architecture>-<system>/ (x86_64-linux, x86_64-windows,
x86_64-darwin, aarch64-darwin, ...).  Keep fused multiply-add off (-ffp-contract=off; MSVC
/fp:precise) and no fast-math.  prsm_constants.h, prsm_variables.h and prsm_fmi3_variables.h
were generated by prsm-fmu's fmu_build: rebuild the FMU to change them.
"""
