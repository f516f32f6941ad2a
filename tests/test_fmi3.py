"""The native FMU as FMI 3.0 (``<name>-native-fmi3.fmu``, built beside ``<name>-native.fmu`` by
``python -m fmu_build --native``): valid, its binaries export the FMI 3.0 functions, and fmpy
runs it -- co-simulation and model exchange -- with the FMI 2.0 FMU's results to 1e-12.

Expected values: the FMI 3.0 functions are read from the standard's header fmpy ships
(fmi3Functions.h), the results from the FMI 2.0 FMU run by fmpy the same way.
"""

from __future__ import annotations

import re
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")
from zig_skip import skip_without_ziglang  # noqa: E402

skip_without_ziglang()
if sys.platform != "linux":
    pytest.skip("the tests run the native FMU's Linux binary", allow_module_level=True)

from fmpy.validation import validate_fmu  # noqa: E402

from fmu_build import binary_check  # noqa: E402

from test_native_fmu import built_native  # noqa: E402

OUTPUTS = ["screw_speed", "rod_position", "friction_work", "stage[1].contact_force",
           "stage[2].carrier_speed", "stage[2].carrier_speed_ratio", "efficiency"]


@pytest.fixture(scope="module")
def fmus() -> tuple[Path, Path]:
    fmu2 = built_native()["PRSM2"]
    fmu3 = fmu2.with_name("PRSM2-native-fmi3.fmu")
    assert fmu3.is_file(), "python -m fmu_build --native builds the FMI 3.0 FMU too"
    return fmu2, fmu3


def _fmi3_functions() -> list[str]:
    header = sorted(Path(fmpy.__file__).parent.rglob("fmi3Functions.h"))[0].read_text()
    return re.findall(r"FMI3_Export\s+fmi3\w+TYPE\s+(fmi3\w+);", header)


def check_fmi3_binaries(fmu3: Path, where: Path) -> list[str]:
    """Check every binary of an FMI 3.0 FMU (one architecture per folder, every FMI 3.0
    function exported; the Linux one needs libc and libm of glibc 2.17 at most); returns the
    folders, sorted."""
    functions = _fmi3_functions()
    assert len(functions) > 70 and "fmi3DoStep" in functions
    with zipfile.ZipFile(fmu3) as z:
        libs = sorted(n for n in z.namelist() if n.startswith("binaries/"))
        z.extractall(where, libs)
    arch = {"aarch64-darwin": "arm64"}
    for n in libs:
        folder = Path(n).parent.name
        b = binary_check.inspect(where / n)
        (s,) = b.slices                      # one architecture per FMI 3.0 folder
        assert s.arch == arch.get(folder, "x86_64"), n
        assert not [f for f in functions if f not in s.exports], n
        if folder == "x86_64-linux":
            assert sorted(s.libraries) == ["libc.so.6", "libm.so.6"]
            highest = max(binary_check.glibc_version(v) for v in s.imports.values() if v)
            assert highest <= (2, 17)
    return [Path(n).parent.name for n in libs]


def test_fmi3_fmu_is_valid_and_its_binaries_export_every_fmi3_function(fmus, tmp_path):
    # built for linux64 here; every platform's: tests/test_platform_binaries.py
    _, fmu3 = fmus
    assert validate_fmu(str(fmu3)) == []
    assert check_fmi3_binaries(fmu3, tmp_path) == ["x86_64-linux"]


@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("fidelity", [1, 2])
def test_fmpy_runs_fmi3_with_the_fmi2_results_to_1e_12(fmus, interface, fidelity):
    """A reversal through zero speed (-20 N.m against 100 rad/s, 5 kN, 50 ms)."""
    fmu2, fmu3 = fmus
    start = {"screw_torque": -20.0, "load_force": 5000.0, "fidelity": fidelity,
             "initial_screw_speed": 100.0, "initial_carrier_equilibrium": True}
    kw = dict(stop_time=0.05, output_interval=1e-4, start_values=start, output=OUTPUTS,
              fmi_type=interface)
    if interface == "CoSimulation":
        kw["step_size"] = 1e-4
    a = fmpy.simulate_fmu(str(fmu2), **kw)
    b = fmpy.simulate_fmu(str(fmu3), **kw)
    assert len(a) == len(b) and np.array_equal(a["time"], b["time"])
    worst = 0.0
    for name in OUTPUTS:
        scale = max(np.max(np.abs(a[name])), 1e-300)
        worst = max(worst, np.max(np.abs(a[name] - b[name])) / scale)
    print(f"\nFMI 3.0 vs 2.0, {interface}, fidelity {fidelity}: {len(a)} rows, "
          f"max relative difference {worst:.2e}")
    assert worst <= 1e-12
    assert a["screw_speed"][0] == 100.0 and a["screw_speed"][-1] < -1000.0   # it reversed
