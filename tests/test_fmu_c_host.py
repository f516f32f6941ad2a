"""A non-Python host: a small C program runs the FMU the way any FMI 2.0 tool would.

The program (tests/fmi_c_host.c, compiled with gcc against the FMI 2.0 headers that fmpy ships)
loads the FMU's shared library with dlopen, instantiates it, sets the Enumeration ``fidelity``
with fmi2SetInteger, and closes the torque-speed loop of ``test_fmu.controller`` for 1,000 steps.
The pythonfmu binary has no Python of its own: the process gets libpython through
``LD_PRELOAD``, the interpreter's home through ``PYTHONHOME`` and numpy/scipy through
``PYTHONPATH`` (docs/fmu.md, "Non-Python hosts").  Its outputs must equal fmpy's run of the
same FMU to 1e-12.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

fmpy = pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from test_fmu import Host, built_fmus, max_relative_difference, run_fmu, unzipped  # noqa: E402

STEPS = 1000
OUTPUTS = ["screw_speed", "screw_angle", "rod_position", "rod_velocity", "stage[1].contact_force",
           "stage[2].contact_force", "stage[2].driven_torque", "stage[2].spline_friction",
           "stage[1].carrier_speed_ratio", "efficiency", "friction_power", "friction_work"]

#: the item values of the FMU's Enumeration ``Fidelity`` (its modelDescription's TypeDefinitions)
ENUM_VALUE = {"kinematic": 0, "quasi-static": 1, "dynamic": 2, "auto": 3}

#: the host program (also run by tests/test_native_fmu.py and benchmarks/native_step_cost.py)
C_HOST = (Path(__file__).resolve().parent / "fmi_c_host.c").read_text()


def _libpython() -> Path | None:
    if not sysconfig.get_config_var("Py_ENABLE_SHARED"):
        return None
    path = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("INSTSONAME") or "")
    return path if path.is_file() else None


def _headers() -> Path:
    found = sorted(Path(fmpy.__file__).parent.rglob("fmi2Functions.h"))
    assert found, "fmpy ships no fmi2Functions.h"
    return found[0].parent


@pytest.fixture(scope="module")
def c_host(tmp_path_factory) -> Path:
    if shutil.which("gcc") is None:
        pytest.skip("gcc is not installed")
    if sys.platform != "linux":
        pytest.skip("the C host test is written for Linux (dlopen, LD_PRELOAD)")
    d = tmp_path_factory.mktemp("c_host")
    (d / "host.c").write_text(C_HOST)
    proc = subprocess.run(["gcc", "-std=c99", "-O2", "-Wall", "-Werror", f"-I{_headers()}",
                           str(d / "host.c"), "-o", str(d / "host"), "-ldl", "-lm"],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    return d / "host"


@pytest.mark.parametrize("fidelity", ["quasi-static", "dynamic"])
def test_c_host_closed_loop_equals_fmpy_to_1e_12(c_host, fidelity):
    lib = _libpython()
    if lib is None:
        pytest.skip("this Python has no shared libpython to preload")
    built_fmus()
    unzip = unzipped("PRSM2")
    ref_host = Host("PRSM2", start={"fidelity": fidelity})
    try:
        expected = run_fmu(ref_host, STEPS, OUTPUTS)
        vr = {n: v.valueReference for n, v in ref_host.vars.items()}
        guid = ref_host.md.guid
    finally:
        ref_host.free()
    env = dict(os.environ)
    env["LD_PRELOAD"] = str(lib)
    env["PYTHONHOME"] = f"{sys.base_prefix}:{sys.base_exec_prefix}"
    env["PYTHONPATH"] = os.pathsep.join(p for p in sys.path if p and Path(p).is_dir())
    args = [str(c_host), str(unzip / "binaries" / "linux64" / "PRSM2.so"),
            (unzip / "resources").as_uri(), guid, str(ENUM_VALUE[fidelity]), str(STEPS),
            str(vr["screw_torque"]), str(vr["load_force"]), str(vr["fidelity"]),
            str(vr["screw_speed"])] + [str(vr[n]) for n in OUTPUTS]
    proc = subprocess.run(args, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert proc.stderr.rstrip().endswith("freed"), "the host did not get past fmi2FreeInstance"
    got = [[float(v) for v in line.split()] for line in proc.stdout.splitlines()]
    assert len(got) == STEPS
    assert max_relative_difference(got, expected) <= 1e-12
    assert min(r[0] for r in got) < -50.0 < 90.0 < max(r[0] for r in got)   # it did reverse
