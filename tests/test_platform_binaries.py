"""The native FMU's binaries for linux64, win64 and darwin64, and the engine library, read back.

The FMU is built here for every platform (once per session, ``python -m fmu_build --native
--platform linux64 --platform win64 --platform darwin64``: tests/test_native_fmu.py's
``built_native``, whose other users build linux64 only); fmpy and the C host of
tests/test_fmu_c_host.py run its linux64 binary there.  Here each binary is read with fmu_build.binary_check and, where the
machine has one, with an independent tool (binutils' readelf/objdump, LLVM's llvm-nm/llvm-objdump).

Expected values come from the FMI 2.0 standard (the functions a co-simulation FMU exports,
§2.1 and §4.2, listed below by hand), the platforms' C runtimes, and the manylinux2014 baseline
(glibc 2.17).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import zipfile
from pathlib import Path

import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")
if shutil.which("true") is None:      # pragma: no cover - a POSIX machine is assumed below
    pytest.skip("needs a POSIX machine", allow_module_level=True)
from zig_skip import skip_without_ziglang  # noqa: E402

skip_without_ziglang("the binaries for win64, darwin64 and glibc 2.17 are cross-compiled with "
                     "its C compiler")

from fmu_build import binary_check  # noqa: E402
from fmu_build.builder import BuildError  # noqa: E402

from test_native_fmu import built_native  # noqa: E402

#: the platforms built here (FMI 2.0 folder names)
EVERY_PLATFORM = ("linux64", "win64", "darwin64")

#: FMI 2.0.4 §2.1.2 (common functions, 25) and §4.2 (co-simulation, 9): 34 functions
FMI2_CS = """fmi2GetTypesPlatform fmi2GetVersion fmi2SetDebugLogging fmi2Instantiate fmi2FreeInstance
fmi2SetupExperiment fmi2EnterInitializationMode fmi2ExitInitializationMode fmi2Terminate fmi2Reset
fmi2GetReal fmi2GetInteger fmi2GetBoolean fmi2GetString fmi2SetReal fmi2SetInteger fmi2SetBoolean
fmi2SetString fmi2GetFMUstate fmi2SetFMUstate fmi2FreeFMUstate fmi2SerializedFMUstateSize
fmi2SerializeFMUstate fmi2DeSerializeFMUstate fmi2GetDirectionalDerivative
fmi2SetRealInputDerivatives fmi2GetRealOutputDerivatives fmi2DoStep fmi2CancelStep fmi2GetStatus
fmi2GetRealStatus fmi2GetIntegerStatus fmi2GetBooleanStatus fmi2GetStringStatus""".split()


@pytest.fixture(scope="module")
def binaries(tmp_path_factory) -> dict[str, Path]:
    """The native PRSM2 FMU's binaries, extracted: platform folder -> library."""
    d = tmp_path_factory.mktemp("native_binaries")
    with zipfile.ZipFile(built_native(EVERY_PLATFORM)["PRSM2"]) as z:
        names = [n for n in z.namelist() if n.startswith("binaries/")]
        z.extractall(d, names)
    return {Path(n).parent.name: d / n for n in names}


def _tool(name: str) -> str | None:
    return shutil.which(name)


def test_the_fmu_carries_the_three_platforms_in_fmis_layout(binaries):
    assert sorted(binaries) == ["darwin64", "linux64", "win64"]
    assert binaries["linux64"].name == "PRSM2_native.so"
    assert binaries["win64"].name == "PRSM2_native.dll"
    assert binaries["darwin64"].name == "PRSM2_native.dylib"


def test_linux64_exports_fmi2_imports_glibc_2_17_at_most(binaries):
    b = binary_check.inspect(binaries["linux64"])
    assert (b.format, b.kind) == ("ELF", "shared")
    (s,) = b.slices
    assert s.arch == "x86_64"
    assert not [f for f in FMI2_CS if f not in s.exports]
    assert sorted(s.libraries) == ["libc.so.6", "libm.so.6"]
    versions = {v for v in s.imports.values() if v}
    glibc = [binary_check.glibc_version(v) for v in versions]
    assert None not in glibc, versions          # every versioned import binds to glibc
    highest = max(glibc)
    print(f"linux64: {len(s.imports)} imports, highest glibc symbol version "
          f"{'.'.join(map(str, highest))}")
    assert highest <= (2, 17)
    if _tool("readelf"):                        # binutils, independently
        out = subprocess.run(["readelf", "--dyn-syms", "-W", str(binaries["linux64"])],
                             capture_output=True, text=True, check=True).stdout
        und = dict(re.findall(r"UND (\w+)@(GLIBC_[\d.]+)", out))
        assert und == {k: v for k, v in s.imports.items() if v}
        defined = set(re.findall(r"(?:FUNC|OBJECT)\s+(?:GLOBAL|WEAK)\s+DEFAULT\s+\d+ (\w+)", out))
        assert defined == s.exports


def test_win64_exports_fmi2_imports_the_ucrt_and_kernel32_only(binaries):
    b = binary_check.inspect(binaries["win64"])
    assert (b.format, b.kind) == ("PE", "shared")
    (s,) = b.slices
    assert s.arch == "x86_64"
    assert not [f for f in FMI2_CS if f not in s.exports]
    assert s.libraries
    assert all(d.lower().startswith("api-ms-win-crt-") or d.lower() == "kernel32.dll"
               for d in s.libraries), s.libraries
    print(f"win64: {len(s.exports)} exports, DLLs {', '.join(s.libraries)}")
    if _tool("objdump"):
        out = subprocess.run(["objdump", "-p", str(binaries["win64"])], capture_output=True,
                             text=True).stdout
        if "DLL Name" in out:                   # objdump built with the PE target
            assert re.findall(r"DLL Name: (\S+)", out) == s.libraries
            table = out.split("[Ordinal/Name Pointer] Table")[1].split("\n\n")[0]
            assert set(re.findall(r"\] (\w+)", table)) == s.exports


def test_darwin64_is_universal_x86_64_and_arm64_each_exporting_fmi2(binaries):
    b = binary_check.inspect(binaries["darwin64"])
    assert (b.format, b.kind) == ("Mach-O", "shared")
    assert sorted(s.arch for s in b.slices) == ["arm64", "x86_64"]
    for s in b.slices:
        assert not [f for f in FMI2_CS if f not in s.exports], s.arch
        assert s.libraries == ["/usr/lib/libSystem.B.dylib"], s.arch
    if _tool("llvm-nm"):
        for s in b.slices:
            out = subprocess.run(["llvm-nm", f"--arch={s.arch}", "-gU", "--just-symbol-name",
                                  str(binaries["darwin64"])], capture_output=True, text=True,
                                 check=True).stdout
            assert {n[1:] for n in out.split()} == s.exports, s.arch


def test_the_check_names_what_is_wrong(binaries):
    """The same reader refuses a binary with a function missing, a library not allowed or a
    glibc symbol above the limit -- each named."""
    b = binary_check.inspect(binaries["linux64"])
    found = binary_check.problems(b, arches=("x86_64", "arm64"), exports=("fmi2DoStep", "fmi3DoStep"),
                                  libraries=("libc.so.6",), max_glibc=(2, 3))
    text = "\n".join(found)
    assert "does not export fmi3DoStep" in text and "fmi2DoStep" not in text
    assert "loads libm.so.6" in text
    assert "holds architectures ['x86_64'], expected ['arm64', 'x86_64']" in text
    assert "needs glibc newer than 2.3" in text and "memcpy@GLIBC_2.14" in text
    with pytest.raises(binary_check.BinaryFormatError, match="not an ELF, PE or Mach-O"):
        binary_check.inspect(Path(__file__))


def test_a_library_linked_against_this_machines_glibc_is_refused_naming_the_symbol(tmp_path):
    """gcc links against the build machine's glibc: where that is 2.29 or later, pow binds to
    pow@GLIBC_2.29 (glibc 2.29 gave exp, log and pow new versions), which the linux64 check
    must refuse by name."""
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    from fmu_build import platforms

    (tmp_path / "p.c").write_text("#include <math.h>\n"
                                  "double (*volatile f)(double, double) = pow;\n"
                                  "double fmi2Probe(double x) { return f(x, 2.5); }\n")
    lib = tmp_path / "p.so"
    subprocess.run(["gcc", "-shared", "-fPIC", "-O2", str(tmp_path / "p.c"), "-o", str(lib), "-lm"],
                   check=True)
    (s,) = binary_check.inspect(lib).slices
    v = binary_check.glibc_version(s.imports.get("pow", ""))
    if v is None or v <= (2, 17):
        pytest.skip(f"this machine's pow binds to {s.imports.get('pow')!r}, not above 2.17")
    with pytest.raises(BuildError, match=r"(?s)linux64/p\.so is not fit for linux64:.*needs glibc "
                                         r"newer than 2\.17: pow@GLIBC_2\.\d+"):
        platforms.check_library(lib, platforms.PLATFORMS["linux64"], ("fmi2Probe",))


@pytest.mark.parametrize("platform", ["linux64", "win64"])
def test_engine_library_for_pythonfmus_platforms(platform, tmp_path):
    """The engine library (model, ROS34PW2, flat interface) for each platform pythonfmu 0.7
    ships a wrapper for; on Linux it also loads and reports its sizes."""
    from fmu_build.engine_library import build_engine_library
    from fmu_build.mechanisms import FMUS

    make, _ = FMUS["PRSM2"]
    lib = build_engine_library(make(), platform, tmp_path)
    (s,) = binary_check.inspect(lib).slices
    # functions prsm_api.c defines (read there by hand)
    api = ("prsm_api_n_reals prsm_api_n_ints prsm_api_new prsm_api_set_tolerances "
           "prsm_api_n_states prsm_api_advance_many prsm_api_rhs prsm_api_memory_size "
           "prsm_api_get_memory prsm_api_set_memory prsm_api_free prsm_api_n_outputs "
           "prsm_api_output_name prsm_api_outputs").split()
    assert not [f for f in api if f not in s.exports]
    if platform == "linux64":
        import ctypes

        dll = ctypes.CDLL(str(lib))
        # two stages: 9 reals per stage + 6 = 24; 2 ints per stage + 4 = 8
        assert (dll.prsm_api_n_reals(), dll.prsm_api_n_ints()) == (24, 8)


def test_the_fmi3_fmu_carries_every_platform_each_exporting_fmi3(tmp_path):
    from test_fmi3 import check_fmi3_binaries

    fmu3 = built_native(EVERY_PLATFORM)["PRSM2"].with_name("PRSM2-native-fmi3.fmu")
    # FMI 3.0 names a folder per architecture: darwin64's universal file becomes two
    assert check_fmi3_binaries(fmu3, tmp_path) == ["aarch64-darwin", "x86_64-darwin",
                                                   "x86_64-linux", "x86_64-windows"]
