"""The pythonfmu FMU's binary: a thin C library that answers the status queries itself.

pythonfmu 0.7's C++ layer answers ``fmi2GetBooleanStatus(fmi2Terminated)`` true from the first
refused ``fmi2DoStep`` on, so hosts that ask after fmi2Discard (fmpy's ``simulate_fmu``, fmusim,
the FMU Compliance Checker) end a run "successfully" at a step a retry could take, whereas
docs/fmu.md's error table (and the native FMU) answer false while a retry may succeed.
:func:`wrap_binaries` moves pythonfmu's library of each platform to
``binaries/<platform>/pythonfmu-export.<suffix>`` and packs in its place, as
``binaries/<platform>/<modelIdentifier>.<suffix>``, ``native/prsm_status_wrapper.c`` compiled
for that platform: it forwards every ``fmi2*`` call to pythonfmu's library and answers
``fmi2GetBooleanStatus`` and ``fmi2GetStatus`` as the native FMU does.  It is compiled with
the native FMU's toolchain (Zig's C compiler, :func:`fmu_build.platforms.compile_for`; gcc for
this platform where ziglang is missing).
"""

from __future__ import annotations

import shutil
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from prsm_fmu.fmu_exit import PYTHONFMU_LIBRARY_STEM

from . import platforms
from .errors import BuildError

__all__ = ["wrap_binaries", "WRAPPER_SOURCE", "INNER_STEM", "input_references"]

#: the wrapper's source, in fmu_build/native
WRAPPER_SOURCE = "prsm_status_wrapper.c"
#: file name (without suffix) of pythonfmu's library inside the FMU, beside the wrapper (where
#: prsm_fmu.fmu_exit finds it at exit)
INNER_STEM = PYTHONFMU_LIBRARY_STEM
#: the functions the wrapper exports: FMI 2.0 co-simulation's
EXPORTS = tuple("""fmi2GetTypesPlatform fmi2GetVersion fmi2SetDebugLogging fmi2Instantiate
fmi2FreeInstance fmi2SetupExperiment fmi2EnterInitializationMode fmi2ExitInitializationMode
fmi2Terminate fmi2Reset fmi2GetReal fmi2GetInteger fmi2GetBoolean fmi2GetString fmi2SetReal
fmi2SetInteger fmi2SetBoolean fmi2SetString fmi2GetFMUstate fmi2SetFMUstate fmi2FreeFMUstate
fmi2SerializedFMUstateSize fmi2SerializeFMUstate fmi2DeSerializeFMUstate
fmi2GetDirectionalDerivative fmi2SetRealInputDerivatives fmi2GetRealOutputDerivatives
fmi2DoStep fmi2CancelStep fmi2GetStatus fmi2GetRealStatus fmi2GetIntegerStatus
fmi2GetBooleanStatus fmi2GetStringStatus""".split())
#: the inputs whose values are part of a refused call (docs/fmu.md, Errors)
INPUTS = ("screw_torque", "load_force")
#: libraries the wrapper links besides the C runtime: dlopen/dladdr (in libdl before glibc 2.34)
_LINK = {"linux64": ("-ldl",)}
_ALLOW = {"linux64": ("libdl.so.2",)}


def input_references(md: bytes) -> tuple[int, ...]:
    """Value references of :data:`INPUTS` in the modelDescription ``md``.

    Raises
    ------
    BuildError
        If an input is missing.
    """
    refs = {sv.get("name"): int(sv.get("valueReference"))
            for sv in ET.fromstring(md).iter("ScalarVariable")}
    missing = [n for n in INPUTS if n not in refs]
    if missing:
        raise BuildError(f"the modelDescription has no input {', '.join(missing)}")
    return tuple(refs[n] for n in INPUTS)


def _compile(platform: str, src: Path, out: Path, defines: tuple[str, ...]) -> Path:
    """The wrapper for ``platform``: Zig's C compiler, or gcc for this platform."""
    from .native import compile_library
    from prsm_fmu.engine import platform_folder

    if platforms.zig_available():
        return platforms.compile_for(platform, src, (WRAPPER_SOURCE,), out, EXPORTS, defines,
                                     link=_LINK.get(platform, ()),
                                     allow=_ALLOW.get(platform, ()))
    if platform != platform_folder():
        raise BuildError(f"wrapping pythonfmu's {platform} library needs Zig's C compiler: "
                         "pip install ziglang")
    out.parent.mkdir(parents=True, exist_ok=True)
    compile_library(src, out, (WRAPPER_SOURCE,), defines=defines, link=_LINK.get(platform, ()))
    return out


def wrap_binaries(fmu: Path, wanted: tuple[str, ...]) -> list[str]:
    """Put the status wrapper in front of pythonfmu's library in ``fmu`` (rewritten in place)
    for each platform of ``wanted`` the FMU has a binary for.

    Parameters
    ----------
    fmu : Path
        A pythonfmu FMU (its modelDescription names the modelIdentifier and the inputs).
    wanted : tuple of str
        Platforms (keys of :data:`fmu_build.platforms.PLATFORMS`) to wrap; pythonfmu's library
        of any other platform stays as it is.

    Returns
    -------
    list of str
        The platforms wrapped.

    Raises
    ------
    BuildError
        When the wrapper cannot be compiled for a platform of ``wanted`` the FMU has.
    """
    from .native import SOURCE_DIR, FMI_HEADERS, _fmi_headers

    with zipfile.ZipFile(fmu) as z:
        md = z.read("modelDescription.xml")
        names = set(z.namelist())
    root = ET.fromstring(md)
    identifier = root.find("CoSimulation").get("modelIdentifier")
    torque, load = input_references(md)
    defines = (f"PRSM_VR_TORQUE={torque}u", f"PRSM_VR_LOAD={load}u",
               f'PRSM_INNER_STEM="{INNER_STEM}"')
    done: dict[str, tuple[str, Path]] = {}
    with tempfile.TemporaryDirectory(prefix="prsm_wrapper_") as tmp:
        tmp = Path(tmp)
        src = tmp / "src"
        src.mkdir()
        shutil.copy(SOURCE_DIR / WRAPPER_SOURCE, src / WRAPPER_SOURCE)
        headers = _fmi_headers()
        for f in FMI_HEADERS:
            shutil.copy(headers / f, src / f)
        for plat in wanted:
            suffix = platforms.PLATFORMS[plat].suffix
            binary = f"binaries/{plat}/{identifier}{suffix}"
            if binary not in names:
                continue
            out = tmp / plat / f"{identifier}{suffix}"
            done[binary] = (f"binaries/{plat}/{INNER_STEM}{suffix}", _compile(plat, src, out, defines))
        if not done:
            return []
        part = tmp / "wrapped.fmu"
        with zipfile.ZipFile(fmu) as z, zipfile.ZipFile(part, "w", zipfile.ZIP_DEFLATED) as dst:
            for item in z.infolist():
                data = z.read(item)
                if item.filename in done:
                    inner, wrapper = done[item.filename]
                    dst.writestr(inner, data)
                    dst.write(wrapper, item.filename)
                else:
                    dst.writestr(item, data)
        shutil.move(str(part), fmu)
    return [b.split("/")[1] for b in done]
