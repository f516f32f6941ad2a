/* The seeded random numbers and the silent logger of the test hosts that drive the native FMU's
 * sources with random calls (tests/fmi_fuzz_host.c, tests/fmi_preview_host.c). */
#ifndef FMI_HOST_RANDOM_H
#define FMI_HOST_RANDOM_H

#include "fmi2Functions.h"

static unsigned long long rng_state;
static unsigned long long rnd(void) {      /* xorshift64* */
    rng_state ^= rng_state >> 12;
    rng_state ^= rng_state << 25;
    rng_state ^= rng_state >> 27;
    return rng_state * 2685821657736338717ULL;
}
static int pick(int n) { return (int)(rnd() % (unsigned long long)n); }

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env; (void)instance; (void)status; (void)category; (void)message;
}

#endif
