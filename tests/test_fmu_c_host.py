"""A non-Python host: a small C program runs the FMU the way any FMI 2.0 tool would.

The program (written below, compiled with gcc against the FMI 2.0 headers that fmpy ships)
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
#: the Fidelity Enumeration's item values (docs/fmu.md's table)
ENUM_VALUE = {"kinematic": 0, "quasi-static": 1, "dynamic": 2, "auto": 3}
OUTPUTS = ["screw_speed", "screw_angle", "rod_position", "rod_velocity", "stage[1].contact_force",
           "stage[2].contact_force", "stage[2].driven_torque", "stage[2].spline_friction",
           "stage[1].carrier_speed_ratio", "efficiency", "friction_power", "friction_work"]

C_HOST = r"""
/* Minimal FMI 2.0 co-simulation host: a PI speed loop around a PRSM FMU. */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    fprintf(stderr, "[%d] %s %s: %s\n", (int)status, instance, category ? category : "", message);
}

static void *sym(void *lib, const char *name) {
    void *f = dlsym(lib, name);
    if (!f) { fprintf(stderr, "missing %s\n", name); exit(3); }
    return f;
}

#define CHECK(call) do { fmi2Status s_ = (call); \
    if (s_ != fmi2OK) { fprintf(stderr, "%s -> %d\n", #call, (int)s_); return 2; } } while (0)

/* argv: library resourceURI guid fidelity steps vr_torque vr_load vr_fidelity vr_speed vr_out... */
int main(int argc, char **argv) {
    if (argc < 11) { fprintf(stderr, "usage\n"); return 1; }
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 1; }
    fmi2InstantiateTYPE *instantiate = (fmi2InstantiateTYPE *)sym(lib, "fmi2Instantiate");
    fmi2SetupExperimentTYPE *setup = (fmi2SetupExperimentTYPE *)sym(lib, "fmi2SetupExperiment");
    fmi2EnterInitializationModeTYPE *enter =
        (fmi2EnterInitializationModeTYPE *)sym(lib, "fmi2EnterInitializationMode");
    fmi2ExitInitializationModeTYPE *exit_init =
        (fmi2ExitInitializationModeTYPE *)sym(lib, "fmi2ExitInitializationMode");
    fmi2SetRealTYPE *set_real = (fmi2SetRealTYPE *)sym(lib, "fmi2SetReal");
    fmi2GetRealTYPE *get_real = (fmi2GetRealTYPE *)sym(lib, "fmi2GetReal");
    fmi2SetIntegerTYPE *set_integer = (fmi2SetIntegerTYPE *)sym(lib, "fmi2SetInteger");
    fmi2DoStepTYPE *do_step = (fmi2DoStepTYPE *)sym(lib, "fmi2DoStep");
    fmi2TerminateTYPE *terminate = (fmi2TerminateTYPE *)sym(lib, "fmi2Terminate");
    fmi2FreeInstanceTYPE *free_instance = (fmi2FreeInstanceTYPE *)sym(lib, "fmi2FreeInstance");

    fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};
    fmi2Component c = instantiate("c_host", fmi2CoSimulation, argv[3], argv[2], &callbacks,
                                  fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 2; }
    int steps = atoi(argv[5]);
    fmi2ValueReference vr_in[2] = {(fmi2ValueReference)atol(argv[6]), (fmi2ValueReference)atol(argv[7])};
    fmi2ValueReference vr_fidelity = (fmi2ValueReference)atol(argv[8]);
    fmi2ValueReference vr_speed = (fmi2ValueReference)atol(argv[9]);
    int n_out = argc - 10;
    fmi2ValueReference *vr_out = malloc(n_out * sizeof *vr_out);
    fmi2Real *y = malloc(n_out * sizeof *y);
    for (int i = 0; i < n_out; i++) vr_out[i] = (fmi2ValueReference)atol(argv[10 + i]);
    fmi2Integer fidelity = (fmi2Integer)atol(argv[4]);   /* the Enumeration's value */

    CHECK(setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
    CHECK(enter(c));
    CHECK(set_integer(c, &vr_fidelity, 1, &fidelity));
    CHECK(exit_init(c));

    const double h = 1e-3;
    double speed, integral = 0.0;
    CHECK(get_real(c, &vr_speed, 1, &speed));
    for (int k = 0; k < steps; k++) {          /* test_fmu.controller, operation for operation */
        double ref = k < 150 ? 100.0 : -60.0;
        double err = ref - speed;
        integral = integral + err * h;
        double torque = 0.05 * err + 2.0 * integral;
        torque = fmin(40.0, fmax(-40.0, torque));
        fmi2Real u[2] = {torque, 3000.0};
        CHECK(set_real(c, vr_in, 2, u));
        CHECK(do_step(c, k * h, h, fmi2True));
        CHECK(get_real(c, vr_out, n_out, y));
        for (int i = 0; i < n_out; i++) printf(i ? " %.17g" : "%.17g", y[i]);
        printf("\n");
        CHECK(get_real(c, &vr_speed, 1, &speed));
    }
    CHECK(terminate(c));
    free_instance(c);
    fprintf(stderr, "freed\n");
    fflush(stdout);
    fflush(stderr);
    /* pythonfmu 0.7's embedded interpreter can crash the process in its exit-time teardown,
       after fmi2FreeInstance has returned (docs/fmu.md, "Non-Python hosts"): leave without it */
    _Exit(0);
}
"""


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
