/* Minimal FMI 2.0 co-simulation host: a PI speed loop around a PRSM FMU (no Python in it).
 *
 * Used by tests/test_fmu_c_host.py and tests/test_native_fmu.py (outputs of every step on
 * stdout) and by benchmarks/native_step_cost.py (no output rows; on stderr, in ns per step:
 * PRSM_HOST_TIME=loop the process CPU time of the whole loop, PRSM_HOST_TIME=step the
 * monotonic-clock time of the fmi2DoStep calls alone; PRSM_HOST_TIME=restore as a master that
 * tries each step first: fmi2GetFMUstate, the trial fmi2DoStep, fmi2SetFMUstate back, then the
 * step again, with the monotonic-clock time per call of the trial doStep, of fmi2SetFMUstate and
 * of fmi2GetFMUstate; the loop's values are those of the other modes). */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
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
    const char *mode = getenv("PRSM_HOST_TIME");
    const int timing = mode != NULL, per_step = mode != NULL && mode[0] == 's';
    const int restore = mode != NULL && mode[0] == 'r';
    /* looked up in restore mode only: the other modes run FMUs without FMU states too */
    fmi2GetFMUstateTYPE *get_state = restore ? (fmi2GetFMUstateTYPE *)sym(lib, "fmi2GetFMUstate") : NULL;
    fmi2SetFMUstateTYPE *set_state = restore ? (fmi2SetFMUstateTYPE *)sym(lib, "fmi2SetFMUstate") : NULL;
    fmi2FreeFMUstateTYPE *free_state = restore ? (fmi2FreeFMUstateTYPE *)sym(lib, "fmi2FreeFMUstate") : NULL;

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
    struct timespec t0, t1, s0, s1;
    double step_ns = 0.0, set_ns = 0.0, get_ns = 0.0;
    fmi2FMUstate state = NULL;
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t0);
    CHECK(get_real(c, &vr_speed, 1, &speed));
    for (int k = 0; k < steps; k++) {          /* test_fmu.controller, operation for operation */
        double ref = k < 150 ? 100.0 : -60.0;
        double err = ref - speed;
        integral = integral + err * h;
        double torque = 0.05 * err + 2.0 * integral;
        torque = fmin(40.0, fmax(-40.0, torque));
        fmi2Real u[2] = {torque, 3000.0};
        CHECK(set_real(c, vr_in, 2, u));
        if (restore) {      /* the trial step and its undoing; the step itself follows */
            clock_gettime(CLOCK_MONOTONIC, &s0);
            CHECK(get_state(c, &state));
            clock_gettime(CLOCK_MONOTONIC, &s1);
            get_ns += (s1.tv_sec - s0.tv_sec) * 1e9 + (s1.tv_nsec - s0.tv_nsec);
            clock_gettime(CLOCK_MONOTONIC, &s0);
            CHECK(do_step(c, k * h, h, fmi2False));
            clock_gettime(CLOCK_MONOTONIC, &s1);
            step_ns += (s1.tv_sec - s0.tv_sec) * 1e9 + (s1.tv_nsec - s0.tv_nsec);
            clock_gettime(CLOCK_MONOTONIC, &s0);
            CHECK(set_state(c, state));
            clock_gettime(CLOCK_MONOTONIC, &s1);
            set_ns += (s1.tv_sec - s0.tv_sec) * 1e9 + (s1.tv_nsec - s0.tv_nsec);
        }
        if (per_step) clock_gettime(CLOCK_MONOTONIC, &s0);
        CHECK(do_step(c, k * h, h, fmi2True));
        if (per_step) {
            clock_gettime(CLOCK_MONOTONIC, &s1);
            step_ns += (s1.tv_sec - s0.tv_sec) * 1e9 + (s1.tv_nsec - s0.tv_nsec);
        }
        if (!timing) {
            CHECK(get_real(c, vr_out, n_out, y));
            for (int i = 0; i < n_out; i++) printf(i ? " %.17g" : "%.17g", y[i]);
            printf("\n");
        }
        CHECK(get_real(c, &vr_speed, 1, &speed));
    }
    clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t1);
    if (restore) {
        fprintf(stderr, "dostep_ns_per_step %.6g\nsetstate_ns_per_call %.6g\n"
                "getstate_ns_per_call %.6g\n", step_ns / steps, set_ns / steps, get_ns / steps);
        CHECK(free_state(c, &state));
    } else if (per_step) fprintf(stderr, "dostep_ns_per_step %.6g\n", step_ns / steps);
    else if (timing)
        fprintf(stderr, "loop_ns_per_step %.6g\n",
                ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / steps);
    CHECK(terminate(c));
    free_instance(c);
    fprintf(stderr, "freed\n");
    fflush(stdout);
    fflush(stderr);
    /* pythonfmu 0.7's embedded interpreter can crash the process in its exit-time teardown,
       after fmi2FreeInstance has returned (docs/fmu.md, "Non-Python hosts"): leave without it */
    _Exit(0);
}
