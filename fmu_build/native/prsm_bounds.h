/* The bounds of the inputs and of the state (prsm_fmu.param_ranges.input_violation,
 * state_violation; the bounds PRSM_MAX_TORQUE ... PRSM_MAX_QUOTIENT generated into prsm_constants.h
 * from param_ranges.INPUT_BOUNDS, STATE_BOUNDS, KINETIC_ENERGY_MAX, SMALLEST and MAX_QUOTIENT): a step that starts or
 * would end beyond them is refused, by the native FMU (prsm_fmi2.c) and by the engine's one-call
 * step of the pythonfmu FMU (prsm_api.c).  Each check returns 0, or -1 with the Python FMU's
 * message in msg. */
#ifndef PRSM_BOUNDS_H
#define PRSM_BOUNDS_H

#include <math.h>
#include <stdio.h>

#include "prsm_model.h"

static inline int prsm_in_bounds(double v, double bound) {
    return v == 0.0 || (PRSM_SMALLEST <= fabs(v) && fabs(v) <= bound);
}

static inline int prsm_input_violation(const double u[2], char *msg, int len) {
    static const char *const names[2] = {"screw_torque", "load_force"}, *const units[2] = {"N.m", "N"};
    const double bounds[2] = {PRSM_MAX_TORQUE, PRSM_MAX_LOAD};
    for (int i = 0; i < 2; i++) {
        if (prsm_in_bounds(u[i], bounds[i])) continue;
        char v[40], lo[40], hi[40];
        prsm_fmt_num(v, sizeof v, u[i]);
        prsm_fmt_num(lo, sizeof lo, PRSM_SMALLEST);
        prsm_fmt_num(hi, sizeof hi, bounds[i]);
        snprintf(msg, (size_t)len, "input %s = %s %s is out of range: must be 0 or of magnitude in "
                 "[%s, %s] %s", names[i], v, units[i], lo, hi, units[i]);
        return -1;
    }
    return 0;
}

/* the bound of speed state i (1 .. n-4) [rad/s] of model m: param_ranges.speed_bounds of the
 * inertias prsm_fmu.models.base.model_speed_bounds takes from the kinetic energy (2 x the energy
 * at 1 rad/s: the same operations, so the same double), sqrt(2 E / (n_speeds J_i)),
 * E = PRSM_KINETIC_ENERGY_MAX */
static inline double prsm_speed_bound(const prsm_model *m, int i, int n) {
    double inertia = i == 1 ? m->equivalent_inertia : m->st[i - 2].j_carrier;
    double j = 2.0 * (0.5 * inertia * 1.0 * 1.0);
    return j > 0.0 ? sqrt(2.0 * PRSM_KINETIC_ENERGY_MAX / ((double)(n - 4) * j)) : INFINITY;
}

/* param_ranges.state_violation(x, speeds): speeds[i - 1] the bound of speed state i (NULL: the
 * speeds not checked) */
static inline int prsm_state_violation(const double *x, int n, const double *speeds, char *msg,
                                       int len) {
    char v[40], w[40], q[40];
    for (int i = 0; i < n; i++) {
        int angle = i == 0, work = i >= n - 3;
        if (!angle && !work) {
            if (!speeds || fabs(x[i]) <= speeds[i - 1]) continue;
            prsm_fmt_num(v, sizeof v, x[i]);
            prsm_fmt_num(w, sizeof w, speeds[i - 1]);
            prsm_fmt_num(q, sizeof q, PRSM_KINETIC_ENERGY_MAX);
            snprintf(msg, (size_t)len, "state x[%d] (speed) = %s rad/s is out of range: must be in "
                     "[-%s, %s] rad/s (kinetic energy at most %s J)", i, v, w, w, q);
            return -1;
        }
        double bound = angle ? PRSM_MAX_ANGLE : PRSM_MAX_WORK;
        if (fabs(x[i]) <= bound) continue;
        prsm_fmt_num(v, sizeof v, x[i]);
        prsm_fmt_num(w, sizeof w, bound);
        const char *unit = angle ? "rad" : "J";
        snprintf(msg, (size_t)len, "state x[%d] (%s) = %s %s is out of range: must be in [-%s, %s] %s",
                 i, angle ? "angle" : "work", v, unit, w, w, unit);
        return -1;
    }
    double omega = x[1], w_in = x[n - 3], w_out = x[n - 2];
    /* (the numbers are written only for a message: prsm_fmt_num's snprintf and strtod would
       cost every step far more than the checks) */
    for (int i = 2; i < n - 3; i++)
        if (omega != 0.0 && fabs(x[i]) > PRSM_MAX_QUOTIENT * fabs(omega)) {
            prsm_fmt_num(q, sizeof q, PRSM_MAX_QUOTIENT);
            prsm_fmt_num(v, sizeof v, x[i]);
            prsm_fmt_num(w, sizeof w, omega);
            snprintf(msg, (size_t)len, "state x[%d] (carrier speed) = %s rad/s is out of range for the "
                     "screw speed %s rad/s: carrier_speed_ratio must stay within %s", i, v, w, q);
            return -1;
        }
    if (w_in > 0.0 && fabs(w_out) > PRSM_MAX_QUOTIENT * w_in) {
        prsm_fmt_num(q, sizeof q, PRSM_MAX_QUOTIENT);
        prsm_fmt_num(v, sizeof v, w_out);
        prsm_fmt_num(w, sizeof w, w_in);
        snprintf(msg, (size_t)len, "state x[%d] (output work) = %s J is out of range for the input "
                 "work %s J: overall_efficiency must stay within %s", n - 2, v, w, q);
        return -1;
    }
    return 0;
}

/* prsm_state_violation with the speed bounds of model m (prsm_speed_bound, computed once by
 * prsm_model_init: not on every step) */
static inline int prsm_model_state_violation(const double *x, const prsm_model *m, char *msg,
                                             int len) {
    return prsm_state_violation(x, m->nx, m->speed_bound, msg, len);
}

#endif
