/* A seeded random FMI 2.0 host for the native FMU's sources, built with the sanitizers.
 *
 * tests/test_bad_inputs.py compiles it together with the native FMU's own sources (prsm_model.c,
 * prsm_ros.c, prsm_fmi2.c and the generated headers, taken from the FMU's sources/ folder) with
 * -fsanitize=address,undefined, and runs it.  Each round instantiates two instances, sets
 * parameters drawn from a pool of good and bad values, initializes, then makes random calls:
 * inputs and step sizes from pools (huge, tiny, subnormal, non-finite), communication points
 * that are and are not the FMU's time, FMU states got, set back after a trial step (the
 * instance's own state: its model kept), serialized, corrupted at random 8-byte offsets with
 * values from the pool, deserialized and set, a state of the other instance handed in, status
 * queries; at the end of a round a state restored after fmi2Reset (its model built again).  After every accepted doStep and every accepted state every Real
 * output is read and must be finite.
 *
 * argv: seed rounds n_real_par vr... n_int_par vr... n_out vr... vr_torque vr_load
 * stdout: one line of counts; exit status 0, or 1 if an accepted step or state gave a
 * non-finite output (each printed), or the sanitizer's own status on a report. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi_host_random.h"

static const double POOL[] = {0.0, -0.0, 1.0, -1.0, 40.0, -40.0, 1e-3, 0.5, 0.999, 1e4, -1e4,
                              1e6, -1e6, 1e8, 1e30, -1e30, 1e155, -1e155, 1e300, 1e308, -1e308,
                              5e-324, -5e-324, 1e-200, 1e-150, 2.2e-308, 1e16, 0.1, 1e-12};
#define NPOOL ((int)(sizeof POOL / sizeof POOL[0]))
static double pool_value(void) {
    int i = pick(NPOOL + 3);
    if (i == NPOOL) return NAN;
    if (i == NPOOL + 1) return INFINITY;
    if (i == NPOOL + 2) return -INFINITY;
    return POOL[i];
}
static const int IPOOL[] = {0, 1, 2, 3, 5, 9, 10, 12, 13, 100, 100000, 100001, -1, 2147483647,
                            -2147483647 - 1};
#define NIPOOL ((int)(sizeof IPOOL / sizeof IPOOL[0]))

static int n_real, n_int, n_out;
static fmi2ValueReference *real_vr, *int_vr, *out_vr, in_vr[2];
static long calls, refused, steps_ok, states_ok, nonfinite;

static void check_outputs(fmi2Component c, const char *after) {
    double y[512];
    if (n_out > 512) abort();
    if (fmi2GetReal(c, out_vr, (size_t)n_out, y) != fmi2OK) return;
    for (int i = 0; i < n_out; i++)
        if (!isfinite(y[i])) {
            nonfinite++;
            printf("NONFINITE output vr %u = %g after %s\n", out_vr[i], y[i], after);
        }
}

static void count(fmi2Status s) {
    calls++;
    if (s != fmi2OK) refused++;
}

int main(int argc, char **argv) {
    if (argc < 4) return 2;
    int a = 1;
    rng_state = strtoull(argv[a++], NULL, 10) * 0x9E3779B97F4A7C15ULL + 1;
    int rounds = atoi(argv[a++]);
    n_real = atoi(argv[a++]);
    real_vr = calloc((size_t)n_real + 1, sizeof *real_vr);
    for (int i = 0; i < n_real; i++) real_vr[i] = (fmi2ValueReference)strtoul(argv[a++], NULL, 10);
    n_int = atoi(argv[a++]);
    int_vr = calloc((size_t)n_int + 1, sizeof *int_vr);
    for (int i = 0; i < n_int; i++) int_vr[i] = (fmi2ValueReference)strtoul(argv[a++], NULL, 10);
    n_out = atoi(argv[a++]);
    out_vr = calloc((size_t)n_out + 1, sizeof *out_vr);
    for (int i = 0; i < n_out; i++) out_vr[i] = (fmi2ValueReference)strtoul(argv[a++], NULL, 10);
    in_vr[0] = (fmi2ValueReference)strtoul(argv[a++], NULL, 10);
    in_vr[1] = (fmi2ValueReference)strtoul(argv[a++], NULL, 10);
    const char *guid = argv[a++];
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    for (int r = 0; r < rounds; r++) {
        fmi2Component c = fmi2Instantiate("fuzz", fmi2CoSimulation, guid, "", &cb, 0, 1);
        fmi2Component other = fmi2Instantiate("other", fmi2CoSimulation, guid, "", &cb, 0, 1);
        if (!c || !other) return 3;
        count(fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0));
        count(fmi2SetupExperiment(other, 0, 0.0, 0.0, 0, 0.0));
        count(fmi2EnterInitializationMode(c));
        count(fmi2EnterInitializationMode(other));
        int n_set = pick(3);
        for (int k = 0; k < n_set; k++) {
            if (pick(2) && n_real) {
                double v = pool_value();
                count(fmi2SetReal(c, &real_vr[pick(n_real)], 1, &v));
            } else if (n_int) {
                int v = IPOOL[pick(NIPOOL)];
                count(fmi2SetInteger(c, &int_vr[pick(n_int)], 1, &v));
            }
        }
        fmi2Status init = fmi2ExitInitializationMode(c);
        count(init);
        count(fmi2ExitInitializationMode(other));
        if (init != fmi2OK) {       /* refused parameters: start again from the defaults */
            count(fmi2Reset(c));
            count(fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0));
            count(fmi2EnterInitializationMode(c));
            if (fmi2ExitInitializationMode(c) != fmi2OK) return 4;
        }
        check_outputs(c, "initialization");
        double t = 0.0;
        for (int k = 0; k < 40; k++) {
            int action = pick(8);
            if (action <= 2) {               /* inputs and a step */
                double u[2] = {pick(3) ? 40.0 * ((double)pick(2001) / 1000.0 - 1.0) : pool_value(),
                               pick(3) ? 3000.0 : pool_value()};
                count(fmi2SetReal(c, in_vr, 2, u));
                double h = pick(3) ? 1e-3 : pool_value();
                double tc = pick(4) ? t : t + pool_value();
                fmi2Status s = fmi2DoStep(c, tc, h, fmi2True);
                count(s);
                if (s == fmi2OK) {
                    steps_ok++;
                    double now = 0.0;
                    fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &now);
                    t = now;
                    check_outputs(c, "doStep");
                }
            } else if (action == 3) {        /* a state round trip, corrupted */
                fmi2FMUstate s = NULL;
                if (fmi2GetFMUstate(c, &s) != fmi2OK) return 5;
                /* a trial step from here (the inputs set, which may be refused) and the state
                   restored: the instance is then as it was (no random number drawn) */
                count(fmi2DoStep(c, t, 1e-3, fmi2False));
                fmi2Status back = fmi2SetFMUstate(c, s);
                count(back);
                if (back != fmi2OK) return 7;
                check_outputs(c, "a state restored after a trial step");
                size_t size = 0;
                count(fmi2SerializedFMUstateSize(c, s, &size));
                unsigned char *bytes = malloc(size);
                count(fmi2SerializeFMUstate(c, s, (fmi2Byte *)bytes, size));
                int n_bad = pick(3);
                for (int j = 0; j < n_bad && size >= 8; j++) {
                    size_t off = 8 * (size_t)pick((int)(size / 8));
                    double v = pool_value();
                    memcpy(bytes + off, &v, 8);
                }
                fmi2FMUstate d = NULL;
                fmi2Status ds = fmi2DeSerializeFMUstate(c, (fmi2Byte *)bytes, size, &d);
                count(ds);
                if (ds == fmi2OK) {
                    fmi2Status ss = fmi2SetFMUstate(c, d);
                    count(ss);
                    if (ss == fmi2OK) {
                        states_ok++;
                        fmi2GetRealStatus(c, fmi2LastSuccessfulTime, &t);
                        check_outputs(c, "a deserialized state");
                    }
                    count(fmi2FreeFMUstate(c, &d));
                }
                free(bytes);
                count(fmi2FreeFMUstate(c, &s));
            } else if (action == 4) {        /* a state of the other instance */
                fmi2FMUstate s = NULL;
                if (fmi2GetFMUstate(other, &s) != fmi2OK) return 6;
                fmi2FMUstate reuse = s;
                unsigned char buf[8];
                count(fmi2GetFMUstate(c, &reuse));
                count(fmi2SetFMUstate(c, s));
                count(fmi2SerializeFMUstate(c, s, (fmi2Byte *)buf, sizeof buf));
                count(fmi2FreeFMUstate(other, &s));
            } else if (action == 5) {        /* status queries */
                fmi2Boolean b = 7;
                fmi2Status st;
                double lt;
                int i;
                fmi2String str;
                count(fmi2GetBooleanStatus(c, (fmi2StatusKind)pick(5), &b));
                count(fmi2GetStatus(c, (fmi2StatusKind)pick(5), &st));
                count(fmi2GetRealStatus(c, (fmi2StatusKind)pick(5), &lt));
                count(fmi2GetIntegerStatus(c, (fmi2StatusKind)pick(5), &i));
                count(fmi2GetStringStatus(c, (fmi2StatusKind)pick(5), &str));
            } else if (action == 6 && n_int) {   /* reads of the Integer variables */
                int v[64];
                count(fmi2GetInteger(c, int_vr, (size_t)(n_int < 64 ? n_int : 64), v));
            } else {                         /* a parameter after initialization: refused */
                double v = pool_value();
                if (n_real) count(fmi2SetReal(c, &real_vr[pick(n_real)], 1, &v));
            }
        }
        fmi2FMUstate last = NULL;
        if (fmi2GetFMUstate(c, &last) != fmi2OK) return 8;
        count(fmi2Reset(c));
        fmi2Status back = fmi2SetFMUstate(c, last);
        count(back);
        if (back != fmi2OK) return 9;
        check_outputs(c, "a state restored after fmi2Reset");
        count(fmi2FreeFMUstate(c, &last));
        count(fmi2Terminate(c));
        fmi2FreeInstance(c);
        fmi2FreeInstance(other);
    }
    printf("rounds %d calls %ld refused %ld accepted_steps %ld accepted_states %ld nonfinite %ld\n",
           rounds, calls, refused, steps_ok, states_ok, nonfinite);
    return nonfinite ? 1 : 0;
}
