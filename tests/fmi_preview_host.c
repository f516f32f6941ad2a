/* A seeded random FMI 2.0 host for the native FMU's outputs in initialization mode.
 *
 * Before fmi2ExitInitializationMode the native FMU's outputs are a preview of the start state on
 * a model built from the parameters; the FMU keeps that model until the parameters (or, for
 * fidelity auto, the inputs) change.  This host proves on seeded random call sequences that the
 * kept model gives what a fresh one gives: tests/test_native_preview.py compiles it together
 * with the native FMU's own sources (with -fsanitize=address,undefined, or plain for valgrind)
 * and runs it.
 *
 * Each round instantiates an instance A, enters initialization mode and makes random calls on it:
 * a Real parameter set to its start value, to its start value scaled by 1 + 1e-12, 1 + 1e-3 or
 * 1 + 0.05 (radii then mesh or not), or to a bad value (0, -1, NaN, 1e30); an Integer or
 * Enumeration parameter set to its start value, one more or less, or 0..3; the fidelity set to
 * one of its four items; a Boolean parameter flipped; the inputs set; an FMU state got, or set
 * back; fmi2Reset (then setupExperiment and enterInitializationMode again).  After each call,
 * every Real output is read from A in one fmi2GetReal, and one output alone, and compared with
 * a fresh instance F given A's parameter and input values (read back from A with the getters):
 * equal as doubles (NaN where F has NaN, the sign of zero included).  A is freed at the end of
 * the round (the sanitizer's leak check sees the preview's model freed with it).
 *
 * argv: seed rounds calls n_real vr... n_int vr... n_bool vr... n_out vr... vr_torque vr_load
 *       vr_fidelity guid
 * stdout: "checks N finite F mismatches M" (F: checks whose outputs were not all NaN, a model
 * built); exit status 0, or 1 on a mismatch (each printed). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmi_host_random.h"

static double uniform(double lo, double hi) {
    return lo + (hi - lo) * (double)(rnd() >> 11) / 9007199254740992.0;
}

#define MAXV 256
static int n_real, n_int, n_bool, n_out;
static fmi2ValueReference real_vr[MAXV], int_vr[MAXV], bool_vr[MAXV], out_vr[MAXV], in_vr[2];
static fmi2ValueReference fid_vr;
static double real_start[MAXV];
static int int_start[MAXV];
static const char *guid;
static fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
static long checks, finite, mismatches;

static fmi2Component make(const char *name) {
    fmi2Component c = fmi2Instantiate(name, fmi2CoSimulation, guid, NULL, &cb, fmi2False,
                                      fmi2False);
    if (!c) {
        printf("cannot instantiate\n");
        exit(2);
    }
    fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    fmi2EnterInitializationMode(c);
    return c;
}

/* equal as doubles: the same number with the same sign, or both NaN */
static int same(double a, double b) {
    return (isnan(a) && isnan(b)) || (a == b && signbit(a) == signbit(b));
}

/* A's outputs (all in one call, and output k alone) against a fresh instance's given A's values */
static void check(fmi2Component a, long round, int call) {
    double rv[MAXV], in[2], ya[MAXV], yf[MAXV], one;
    int iv[MAXV];
    fmi2Boolean bv[MAXV];
    fmi2GetReal(a, real_vr, (size_t)n_real, rv);
    fmi2GetInteger(a, int_vr, (size_t)n_int, iv);
    fmi2GetBoolean(a, bool_vr, (size_t)n_bool, bv);
    fmi2GetReal(a, in_vr, 2, in);
    int k = pick(n_out);
    fmi2GetReal(a, out_vr, (size_t)n_out, ya);
    fmi2GetReal(a, &out_vr[k], 1, &one);
    fmi2Component f = make("fresh");
    fmi2SetReal(f, real_vr, (size_t)n_real, rv);
    fmi2SetInteger(f, int_vr, (size_t)n_int, iv);
    fmi2SetBoolean(f, bool_vr, (size_t)n_bool, bv);
    fmi2SetReal(f, in_vr, 2, in);
    fmi2GetReal(f, out_vr, (size_t)n_out, yf);
    fmi2FreeInstance(f);
    checks++;
    int any_finite = 0;      /* a model was built (else every output is NaN) */
    for (int i = 0; i < n_out; i++) {
        any_finite |= isfinite(yf[i]) != 0;
        if (!same(ya[i], yf[i])) {
            mismatches++;
            printf("round %ld call %d: output vr %u = %.17g, fresh instance %.17g\n", round, call,
                   (unsigned)out_vr[i], ya[i], yf[i]);
        }
    }
    if (!same(one, yf[k])) {
        mismatches++;
        printf("round %ld call %d: output vr %u alone = %.17g, fresh instance %.17g\n", round,
               call, (unsigned)out_vr[k], one, yf[k]);
    }
    finite += any_finite;
}

static double real_value(int i) {
    static const double scale[] = {0.0, 1e-12, 1e-3, 0.05};
    static const double bad[] = {0.0, -1.0, NAN, 1e30};
    int how = pick(10);
    if (how == 0) return bad[pick(4)];
    if (how < 4) return real_start[i];
    return real_start[i] * (1.0 + (pick(2) ? 1.0 : -1.0) * scale[pick(4)]);
}

static int read_list(char **argv, int *at, fmi2ValueReference *vr) {
    int n = atoi(argv[(*at)++]);
    if (n < 0 || n > MAXV) exit(2);
    for (int i = 0; i < n; i++) vr[i] = (fmi2ValueReference)strtoul(argv[(*at)++], NULL, 10);
    return n;
}

int main(int argc, char **argv) {
    if (argc < 8) return 2;
    int at = 1;
    rng_state = strtoull(argv[at++], NULL, 10) * 0x9E3779B97F4A7C15ULL + 1;
    long rounds = atol(argv[at++]);
    int calls = atoi(argv[at++]);
    n_real = read_list(argv, &at, real_vr);
    n_int = read_list(argv, &at, int_vr);
    n_bool = read_list(argv, &at, bool_vr);
    n_out = read_list(argv, &at, out_vr);
    in_vr[0] = (fmi2ValueReference)strtoul(argv[at++], NULL, 10);
    in_vr[1] = (fmi2ValueReference)strtoul(argv[at++], NULL, 10);
    fid_vr = (fmi2ValueReference)strtoul(argv[at++], NULL, 10);
    guid = argv[at++];
    {   /* the start values, from an instance that was never set */
        fmi2Component c = make("starts");
        fmi2GetReal(c, real_vr, (size_t)n_real, real_start);
        fmi2GetInteger(c, int_vr, (size_t)n_int, int_start);
        fmi2FreeInstance(c);
    }
    for (long r = 0; r < rounds; r++) {
        fmi2Component a = make("kept");
        fmi2FMUstate saved = NULL;
        check(a, r, -1);
        for (int call = 0; call < calls; call++) {
            int op = pick(100);
            if (op < 35) {
                int i = pick(n_real);
                double v = real_value(i);
                fmi2SetReal(a, &real_vr[i], 1, &v);
            } else if (op < 50) {
                int i = pick(n_int), w = pick(5);
                int v = w == 0 ? int_start[i] : w == 1 ? int_start[i] + 1
                        : w == 2 ? int_start[i] - 1 : pick(4);
                fmi2SetInteger(a, &int_vr[i], 1, &v);
            } else if (op < 60) {
                int v = pick(4);
                fmi2SetInteger(a, &fid_vr, 1, &v);
            } else if (op < 65) {
                if (n_bool) {
                    int i = pick(n_bool);
                    fmi2Boolean v;
                    fmi2GetBoolean(a, &bool_vr[i], 1, &v);
                    v = !v;
                    fmi2SetBoolean(a, &bool_vr[i], 1, &v);
                }
            } else if (op < 85) {
                double u[2] = {uniform(-50.0, 50.0), pick(3) ? uniform(-2e4, 2e4) : 0.0};
                fmi2SetReal(a, in_vr, 2, u);
            } else if (op < 91) {
                fmi2GetFMUstate(a, &saved);
            } else if (op < 97) {
                if (saved) fmi2SetFMUstate(a, saved);
            } else {
                fmi2Reset(a);
                fmi2SetupExperiment(a, fmi2False, 0.0, 0.0, fmi2False, 0.0);
                fmi2EnterInitializationMode(a);
            }
            check(a, r, call);
        }
        if (saved) fmi2FreeFMUstate(a, &saved);
        fmi2FreeInstance(a);
    }
    printf("checks %ld finite %ld mismatches %ld\n", checks, finite, mismatches);
    return mismatches ? 1 : 0;
}
