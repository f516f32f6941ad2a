/* The friction band's exponential Rosenbrock step (see prsm_band.h for what it mirrors).
 *
 * Every expression keeps band.py's order of floating-point operations; compile as
 * prsm_model.c (no fast-math, no FMA contraction).
 */
#include "prsm_band.h"
#include "prsm_step.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#ifdef __clang__
#pragma STDC FP_CONTRACT OFF
#endif

#define N PRSM_NX
#define FREE 1          /* the screw speed: the one state that is not a quadrature */

/* 1/k! for k = 0..4 (phi.py's _INV_FACT) */
static const double INV_FACT[5] = {1.0, 1.0, 0.5, 1.0 / 6.0, 1.0 / 24.0};

/* phi.phi_scalar(z, 4)[1:]: returns 0, or -1 where e^z overflows (OverflowError) */
static int phi_functions(double z, double *p) {
    double out[5];
    if (fabs(z) < 1.0) {
        double term = INV_FACT[4], s = term;
        for (int m = 1; m < 30; m++) {
            term *= z / (double)(m + 4);
            s += term;
            if (fabs(term) <= 1e-17 * fabs(s)) break;
        }
        out[4] = s;
        for (int k = 3; k >= 0; k--) out[k] = z * out[k + 1] + INV_FACT[k];
    } else {
        out[0] = exp(z);
        if (isinf(out[0]) && isfinite(z)) return -1;
        for (int k = 0; k < 4; k++) out[k + 1] = (out[k] - INV_FACT[k]) / z;
    }
    for (int k = 0; k < 4; k++) p[k] = out[k + 1];
    return 0;
}

/* AdaptiveBase._factor with the exponent 1/3 of the embedded order 2 */
static double factor(const prsm_band *b, double err) {
    return prsm_step_factor(err, -1.0 / 3.0, b->safety, b->fac_min, b->fac_max);
}

/* ScalarExponential._linearise: f0 and the Jacobian column (2 rhs calls) */
static void linearise(const prsm_band *b, prsm_rhs_fn f, const void *ctx, const double *x,
                      const double *u, double *f0, double *col, prsm_stats *stats) {
    f(ctx, x, u, f0);
    stats->rhs_calls += 1;
    double w = x[FREE];
    double step = PRSM_SQRT_EPS * pmax(fabs(w), b->w_scale);
    if (f0[FREE] < 0.0) step = -step;
    double xd[PRSM_NX_MAX];
    memcpy(xd, x, sizeof(double) * N);
    xd[FREE] = w + step;
    step = xd[FREE] - w;
    double fd[PRSM_NX_MAX];
    f(ctx, xd, u, fd);
    stats->rhs_calls += 1;
    for (int k = 0; k < N; k++) col[k] = (fd[k] - f0[k]) / step;
}

/* ScalarExponential._trial: 1 and x1, err, or 0 (err = inf) when not finite */
static int trial(const prsm_band *b, prsm_rhs_fn f, const void *ctx, const double *x,
                 const double *u, const double *f0, const double *col, double hs, double *x1,
                 double *err, prsm_stats *stats) {
    double lam = col[FREE], g0 = f0[FREE], p[4];
    *err = INFINITY;
    if (phi_functions(lam * hs, p)) return 0;
    double dw = hs * p[0] * g0;
    double hp2g = hs * p[1] * g0;
    double u2[PRSM_NX_MAX], fu[PRSM_NX_MAX], est[N];
    for (int k = 0; k < N; k++) u2[k] = x[k] + hs * (f0[k] + hp2g * col[k]);
    u2[FREE] = x[FREE] + dw;
    f(ctx, u2, u, fu);
    stats->rhs_calls += 1;
    double d_w = fu[FREE] - g0 - lam * dw;
    double h2 = 2.0 * hs;
    double e_w = h2 * p[2] * d_w;
    double hp4d = hs * p[3] * d_w;
    for (int k = 0; k < N; k++) est[k] = h2 * ((fu[k] - f0[k] - col[k] * dw) / 6.0 + hp4d * col[k]);
    est[FREE] = e_w;
    for (int k = 0; k < N; k++) x1[k] = u2[k] + est[k];
    double sq = 0.0;
    for (int k = 0; k < N; k++) sq += prsm_err_term(est[k], x[k], x1[k], b->atol, b->rtol);
    double e = prsm_rms(sq, N);
    if (!(finite_sum(x1, N) && isfinite(e))) return 0;
    *err = e;
    return 1;
}

/* the breaks ahead of w0 in the direction of g0, nearest first (stable: sorted(key=|b - w0|)) */
static int breaks_ahead(const prsm_band *b, double w0, double g0, double *ahead) {
    int n = 0;
    for (int j = 0; j < b->n_breaks; j++) {
        double v = b->breaks[j];
        if (g0 > 0.0 ? v > w0 : v < w0) {
            int i = n++;
            while (i > 0 && fabs(ahead[i - 1] - w0) > fabs(v - w0)) {
                ahead[i] = ahead[i - 1];
                i--;
            }
            ahead[i] = v;
        }
    }
    return n;
}

/* ScalarExponential._break_time: 1 and *tau if a step of size hs should end at a break; ahead:
 * the n breaks ahead of w0 (breaks_ahead, sorted once per accepted point) */
static int break_time(const double *ahead, int n, double w0, double g0, double lam, double hs,
                      double *tau_out) {
    if (g0 == 0.0) return 0;
    for (int j = 0; j < n; j++) {
        double d = ahead[j] - w0;
        double a = lam * d / g0;
        if (a <= -1.0) return 0;
        double tau = d / g0 * (a != 0.0 ? log1p(a) / a : 1.0);
        if (tau <= 1e-3 * hs) continue;
        if (tau < 0.95 * hs) {
            *tau_out = tau;
            return 1;
        }
        return 0;
    }
    return 0;
}

/* ScalarExponential._traverse: 1 and (time, state at the break, err), or 0; ahead: the n breaks
 * ahead of x's speed (as break_time's) */
static int traverse(const prsm_band *b, prsm_rhs_fn f, const void *ctx, const double *x,
                    const double *u, const double *f0, const double *col, const double *ahead,
                    int n, double rem, double *dt, double *y, double *err, prsm_stats *stats) {
    double w0 = x[FREE], g0 = f0[FREE], lam = col[FREE];
    if (g0 == 0.0) return 0;
    if (!n) return 0;
    double bk = ahead[0];                         /* min(ahead, key=|v - w0|): the first */
    double d = bk - w0;
    double a = lam * d / g0;
    if (a < -0.5) return 0;
    if (d / g0 * (a != 0.0 ? log1p(a) / a : 1.0) > 0.95 * rem) return 0;
    static const double *const NODES[2] = {PRSM_GAUSS5_X, PRSM_GAUSS3_X};
    static const double *const WEIGHTS[2] = {PRSM_GAUSS5_W, PRSM_GAUSS3_W};
    static const int COUNT[2] = {5, 3};
    for (int attempt = 0; attempt < 3; attempt++) {
        double mid = w0 + 0.5 * d, half = 0.5 * d;
        double seen_x[8], seen_f[8][PRSM_NX_MAX];
        int n_seen = 0;
        double time[2], acc[2][N];
        for (int r = 0; r < 2; r++) {
            time[r] = 0.0;
            for (int k = 0; k < N; k++) acc[r][k] = 0.0;
            for (int q = 0; q < COUNT[r]; q++) {
                double xi = NODES[r][q], wt = WEIGHTS[r][q];
                const double *fk = NULL;
                for (int s = 0; s < n_seen; s++)
                    if (seen_x[s] == xi) fk = seen_f[s];
                if (!fk) {
                    double xk[PRSM_NX_MAX];
                    memcpy(xk, x, sizeof(double) * N);
                    xk[FREE] = mid + xi * half;
                    f(ctx, xk, u, seen_f[n_seen]);
                    stats->rhs_calls += 1;
                    fk = seen_f[n_seen];
                    if (!(fk[FREE] * g0 > 0.0 && finite_sum(fk, N))) return 0;
                    seen_x[n_seen++] = xi;
                }
                double c = wt * half / fk[FREE];
                time[r] += c;
                for (int k = 0; k < N; k++) acc[r][k] = acc[r][k] + c * fk[k];
            }
        }
        double t5 = time[0], t3 = time[1];
        if (!(0.0 < t5 && t5 <= rem)) return 0;
        double yy[N], est[N];
        for (int k = 0; k < N; k++) yy[k] = x[k] + acc[0][k];
        yy[FREE] = w0 + d;
        for (int k = 0; k < N; k++) est[k] = acc[0][k] - acc[1][k];
        est[FREE] = g0 * (t5 - t3);
        double sq = 0.0;
        for (int k = 0; k < N; k++) sq += prsm_err_term(est[k], x[k], yy[k], b->atol, b->rtol);
        double e = prsm_rms(sq, N);
        if (e <= 1.0) {
            if (d == bk - w0) yy[FREE] = bk;
            *dt = t5;
            memcpy(y, yy, sizeof yy);
            *err = e;
            return 1;
        }
        d *= 0.25;
    }
    return 0;
}

static int band_fail(char *msg, int len, const char *what, double ti, double hs, double t,
                     double h) {
    snprintf(msg, (size_t)len, "scalar_exponential: %s at t = %.17g s with internal step %.17g s "
             "(advance from t = %.17g s over h = %.17g s)", what, ti, hs, t, h);
    return -1;
}

/* ScalarExponential._checked_linearise */
static int checked_linearise(const prsm_band *b, prsm_rhs_fn f, const void *ctx, const double *y,
                             const double *u, double *f0, double *col, prsm_stats *stats,
                             double ti, double t, double h, double hs, char *msg, int len) {
    linearise(b, f, ctx, y, u, f0, col, stats);
    if (!(finite_sum(f0, N) && finite_sum(col, N)))
        return band_fail(msg, len, "non-finite value (or wrong length) in the rhs or its Jacobian "
                         "at the step's start", ti, hs, t, h);
    return 0;
}

/* ScalarExponential._rest_exact: 1 if the closed form answers for the rest of the advance */
static int rest_exact(prsm_exact_fn exact, void *ctx, const double *y, const double *u,
                      double rem, double *ye, prsm_stats *stats) {
    if (!exact(ctx, y, u, rem, ye) || !finite_sum(ye, N)) return 0;
    stats->rhs_calls += 1;
    stats->substeps += 1;
    return 1;
}

int prsm_band_advance(const prsm_band *b, prsm_rhs_fn f, prsm_exact_fn exact, void *ctx,
                      prsm_memory *mem, double t, const double *x, const double *u, double h,
                      double *x_new, prsm_stats *stats, char *msg, int len) {
    double y[PRSM_NX_MAX] = {0.0}, f0[PRSM_NX_MAX], col[PRSM_NX_MAX], y_new[PRSM_NX_MAX] = {0.0};
    double err;
    memcpy(y, x, sizeof(double) * N);
    if (b->fixed_substeps) {
        int n_sub = b->fixed_substeps;
        double hs = h / n_sub;
        for (int k = 0; k < n_sub; k++) {
            double tk = t + k * hs;
            if (checked_linearise(b, f, ctx, y, u, f0, col, stats, tk, t, h, hs, msg, len))
                return -1;
            if (!trial(b, f, ctx, y, u, f0, col, hs, y_new, &err, stats))
                return band_fail(msg, len, "non-finite value in the step", tk, hs, t, h);
            memcpy(y, y_new, sizeof(double) * N);
        }
        stats->substeps = n_sub;
        memcpy(x_new, y, sizeof(double) * N);
        return 0;
    }
    double hs = mem->has_h_prop ? mem->h_prop : h;
    double tau = 0.0;
    int attempts = 0;
    for (;;) {
        double ti = t + tau;
        if (checked_linearise(b, f, ctx, y, u, f0, col, stats, ti, t, h, hs, msg, len)) return -1;
        /* the breaks ahead of this point, nearest first: sorted once for the traversal and every
         * trial's break_time from it */
        double ahead[PRSM_MAX_BREAKS];
        int n_ahead = f0[FREE] != 0.0 ? breaks_ahead(b, y[FREE], f0[FREE], ahead) : 0;
        double dt;
        if (traverse(b, f, ctx, y, u, f0, col, ahead, n_ahead, h - tau, &dt, y_new, &err, stats)) {
            memcpy(y, y_new, sizeof(double) * N);
            stats->substeps += 1;
            tau += dt;
            if (rest_exact(exact, ctx, y, u, h - tau, x_new, stats)) {
                mem->has_h_prop = 1;
                mem->h_prop = hs;
                return 0;
            }
            continue;
        }
        int just_rejected = 0, last;
        double h_step;
        for (;;) {
            double rem = h - tau;
            last = hs * 1.05 >= rem;
            h_step = last ? rem : hs;
            double cut;
            if (break_time(ahead, n_ahead, y[FREE], f0[FREE], col[FREE], h_step, &cut)) {
                h_step = cut;
                last = 0;
            }
            attempts += 1;
            if (attempts > b->max_substeps) {
                char what[128];
                snprintf(what, sizeof what, "more than max_substeps = %d internal steps "
                         "(accepted + rejected)", b->max_substeps);
                return band_fail(msg, len, what, ti, h_step, t, h);
            }
            int ok = trial(b, f, ctx, y, u, f0, col, h_step, y_new, &err, stats);
            if (err <= 1.0) break;
            stats->rejected += 1;
            just_rejected = 1;
            hs = h_step * factor(b, err);
            if (hs < b->h_min) {
                char what[200];
                if (!ok) snprintf(what, sizeof what, "step size %.17g s below h_min = %.17g s after "
                                  "rejection (non-finite value)", hs, b->h_min);
                else snprintf(what, sizeof what, "step size %.17g s below h_min = %.17g s after "
                              "rejection (error norm %.3g > 1)", hs, b->h_min, err);
                return band_fail(msg, len, what, ti, h_step, t, h);
            }
        }
        stats->substeps += 1;
        double fac = factor(b, err);
        if (just_rejected && fac > 1.0) fac = 1.0;
        double h_new = h_step * fac;
        hs = h_new >= h_step ? pmax(h_new, hs) : h_new;
        memcpy(y, y_new, sizeof(double) * N);
        if (last) {
            mem->has_h_prop = 1;
            mem->h_prop = hs;
            memcpy(x_new, y, sizeof(double) * N);
            return 0;
        }
        tau += h_step;
        if (rest_exact(exact, ctx, y, u, h - tau, x_new, stats)) {
            mem->has_h_prop = 1;
            mem->h_prop = hs;
            return 0;
        }
    }
}
