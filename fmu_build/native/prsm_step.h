/* The adaptive steppers' shared rules in C (prsm_fmu/steppers/control.py): the elementary
 * controller's step-size factor, the weighted RMS error norm's terms, the slip error norm and the
 * landing on the friction law's kinks.  Used by prsm_ros.c (ROS34PW2), prsm_band.c (the band's
 * exponential step) and prsm_model.c (Dormand-Prince 5(4)); every expression keeps control.py's
 * order of floating-point operations (no fast-math, no FMA contraction: compile as
 * prsm_model.c).
 */
#ifndef PRSM_STEP_H
#define PRSM_STEP_H

#include <math.h>
#include <string.h>

#include "prsm_model.h"

#ifdef __clang__
#pragma STDC FP_CONTRACT OFF
#endif

/* AdaptiveBase._factor: the step-size ratio for error norm err, exponent -1/(q+1) with q the
 * embedded order (-1/3 for ROS34PW2 and the band's exprb32, -1/5 for Dormand-Prince 5(4)) */
static inline double prsm_step_factor(double err, double exponent, double safety, double fac_min,
                                      double fac_max) {
    if (err == 0.0) return fac_max;
    if (!(err < INFINITY)) return fac_min;
    return pmin(fac_max, pmax(fac_min, safety * prsm_pow(err, exponent)));
}

/* one term of the weighted RMS error norm: (e / (atol + rtol max(|p|, |pn|)))^2 for a state
 * that goes from p to pn with error estimate e */
static inline double prsm_err_term(double e, double p, double pn, double atol, double rtol) {
    return prsm_pow(e / (atol + rtol * pmax(fabs(p), fabs(pn))), 2.0);
}

/* the weighted RMS norm from the sum of n terms */
static inline double prsm_rms(double sq, int n) {
    return sqrt(sq / (double)n);
}

/* control.slip_error: the largest weighted error |ds| / (atol v_eps + rtol max(|s0|, v_eps)) of
 * the laws' sliding velocities (PRSM_SLIP_DIM slots per law, law_dim[l] of them used): ds the
 * error estimate's, s0 those at the step's start */
static inline double prsm_slip_error(int n_laws, const int *law_dim, double band, const double *ds,
                                     const double *s0, double rtol, double atol) {
    double worst = 0.0;
    double floor_ = atol * band;
    for (int l = 0; l < n_laws; l++) {
        const double *d = ds + PRSM_SLIP_DIM * l, *s = s0 + PRSM_SLIP_DIM * l;
        double dn, sn;
        if (law_dim[l] == 1) {
            dn = fabs(d[0]);
            sn = fabs(s[0]);
        } else {
            dn = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            sn = sqrt(s[0] * s[0] + s[1] * s[1] + s[2] * s[2]);
        }
        double e = dn / (floor_ + rtol * pmax(sn, band));
        if (e > worst) worst = e;
    }
    return worst;
}

/* control.kink_fraction: 1 and the fraction of the step in (0, 1) at which it should end in
 * *frac, or 0 if the step may stand; v0, v1 the sliding velocities at its ends (as above) */
static inline int prsm_kink_fraction(int n_laws, const int *law_dim, double band, const double *v0,
                                     const double *v1, double *frac) {
    double tol = PRSM_KINK_BAND * band;
    double best = 2.0;
    for (int l = 0; l < n_laws; l++) {
        const double *s0 = v0 + PRSM_SLIP_DIM * l, *s1 = v1 + PRSM_SLIP_DIM * l;
        double r0, r1;
        if (law_dim[l] == 1) {
            double a0 = s0[0], a1 = s1[0];
            double d = a1 - a0;
            double dn = fabs(d);
            if (!(dn > tol)) continue;
            r0 = fabs(a0);
            r1 = fabs(a1);
            if (a0 * a1 <= 0.0 || r0 <= band || r1 <= band) {
                /* kinks 0 and v_eps: the roots -a0/d, then (v_eps - a0)/d and (-v_eps - a0)/d */
                double roots[3] = {-a0 / d, (band - a0) / d, (-band - a0) / d};
                for (int i = 0; i < 3; i++) {
                    double root = roots[i];
                    if (0.0 < root && root < 1.0 && root * dn > tol && (1.0 - root) * dn > tol
                        && root < best)
                        best = root;
                }
            }
        } else {
            double x0 = s0[0], y0 = s0[1], z0 = s0[2];
            double dx = s1[0] - x0, dy = s1[1] - y0, dz = s1[2] - z0;
            double aa = dx * dx + dy * dy + dz * dz;
            double dn = sqrt(aa);
            if (!(dn > tol)) continue;
            double rr0 = x0 * x0 + y0 * y0 + z0 * z0;
            r0 = sqrt(rr0);
            r1 = sqrt(s1[0] * s1[0] + s1[1] * s1[1] + s1[2] * s1[2]);
            double b = x0 * dx + y0 * dy + z0 * dz;
            /* the kink v_eps: |s0 + theta dv| = v_eps, where |s| may reach it */
            double disc = b * b - aa * (rr0 - band * band);
            if (r0 + r1 - dn <= 2.0 * band && !(disc < 0.0)) {
                double sq = sqrt(disc);
                double roots[2] = {(-b - sq) / aa, (-b + sq) / aa};
                for (int i = 0; i < 2; i++) {
                    double root = roots[i];
                    if (0.0 < root && root < 1.0 && root * dn > tol && (1.0 - root) * dn > tol
                        && root < best)
                        best = root;
                }
            }
        }
        double change = fabs(r1 - r0);
        double limit = PRSM_APPROACH * pmax(band, r1 < r0 ? r0 / (1.0 + PRSM_APPROACH) : r0);
        if (change > limit && limit / change < best) best = limit / change;
    }
    if (!(best < 1.0)) return 0;
    *frac = best;
    return 1;
}

/* control.KinkLanding: one advance's landing on the kinks of the laws of r (its slip function
 * with context ctx, its laws and v_eps): the sliding velocities at the accepted point (v0) and at
 * the trial's end (v_new), the cuts of the internal step being tried and the step size [s] the
 * first cut shortened */
typedef struct {
    const prsm_ros *r;
    const void *ctx;
    double h_min;
    int have_v0, have_v_new, cuts;
    double v0[PRSM_SLIP_DIM * PRSM_MAX_LAWS], v_new[PRSM_SLIP_DIM * PRSM_MAX_LAWS], h_uncut;
} prsm_landing;

static inline void prsm_landing_init(prsm_landing *l, const prsm_ros *r, const void *ctx,
                                     double h_min) {
    l->r = r;
    l->ctx = ctx;
    l->h_min = h_min;
    l->have_v0 = l->have_v_new = l->cuts = 0;
    l->h_uncut = 0.0;
}

/* KinkLanding.start: the sliding velocities at the accepted point y (computed once per point) */
static inline const double *prsm_landing_start(prsm_landing *l, const double *y) {
    if (!l->have_v0) {
        memset(l->v0, 0, sizeof l->v0);
        l->r->slip(l->ctx, y, l->v0);
        l->have_v0 = 1;
    }
    return l->v0;
}

/* KinkLanding.cut: 1 and the size [s] to retry the trial from y to y_new of size h_step with
 * (counted in stats->rejected), or 0, as well once PRSM_MAX_KINK_CUTS cuts were made or below
 * h_min */
static inline int prsm_landing_cut(prsm_landing *l, const double *y, const double *y_new,
                                   double h_step, prsm_stats *stats, double *h_cut) {
    double s_cut;
    l->have_v_new = 0;
    if (l->cuts >= PRSM_MAX_KINK_CUTS) return 0;
    prsm_landing_start(l, y);
    memset(l->v_new, 0, sizeof l->v_new);
    l->r->slip(l->ctx, y_new, l->v_new);
    l->have_v_new = 1;
    if (!prsm_kink_fraction(l->r->n_laws, l->r->law_dim, l->r->band, l->v0, l->v_new, &s_cut)
        || !(h_step * s_cut >= l->h_min))
        return 0;
    if (!l->cuts) l->h_uncut = h_step;
    l->cuts += 1;
    stats->rejected += 1;
    *h_cut = h_step * s_cut;
    return 1;
}

/* KinkLanding.accepted: the next step's size [s] after an accepted one whose controller proposed
 * h_new with factor fac: after a landing the size the cut shortened, unless the controller asks
 * for less */
static inline double prsm_landing_accepted(prsm_landing *l, double h_new, double fac) {
    if (l->cuts) {
        if (fac >= 1.0) h_new = pmax(h_new, l->h_uncut);
        l->cuts = 0;
    }
    l->have_v0 = l->have_v_new;
    if (l->have_v_new) memcpy(l->v0, l->v_new, sizeof l->v0);
    return h_new;
}

/* KinkLanding.rejected: a trial failed its error test, no return to the uncut size after it */
static inline void prsm_landing_rejected(prsm_landing *l) {
    l->h_uncut = 0.0;
}

#endif
