/* ROS34PW2 with error control (see prsm_ros.h for what it mirrors).
 *
 * Every expression keeps the Python code's order of floating-point operations; compile as
 * prsm_model.c (no fast-math, no fused multiply-add).  Python's min(a, b) and max(a, b) of two
 * floats are pmin/pmax (prsm_model.h).
 */
#include "prsm_ros.h"
#include "prsm_step.h"

#include <math.h>
#include <stdio.h>
#include <string.h>

#ifdef __clang__
#pragma STDC FP_CONTRACT OFF
#endif

#define NX PRSM_NX_MAX
#define ND (PRSM_N_STAGES + 1)
/* rosenbrock.QUIET: a continuing advance is quiet when its motion changes at most this fraction
 * of the fastest rate */
#define QUIET 0.01
/* control._TIME_MATCH */
#define TIME_MATCH 4e-16

/* ---- linalg.py: factors of (d I - J_dd) --------------------------------------------------- */
typedef struct {
    int nd;
    /* unrolled 1-3 unknowns (_lu_small1..3): pivoted positions and factors */
    int i0, i1, i2;
    double l10, l20, l21, u01, u02, u12, d0, d1, d2;
    /* lu_factor for more: pivot rows, L's rows, U's rows right of the diagonal (reversed) */
    int perm[ND];
    double lower[ND][ND], upper_rev[ND][ND], inv_diag[ND];
} ros_lu;

/* 0, or -1 for a zero pivot */
static int lu_factor(const double jdd[ND][ND], int nd, double d, ros_lu *lu) {
    lu->nd = nd;
    if (nd == 1) {
        double a00 = d - jdd[0][0];
        if (a00 == 0.0) return -1;
        lu->i0 = 0;
        lu->d0 = 1.0 / a00;
        return 0;
    }
    if (nd == 2) {
        double a00 = d - jdd[0][0], a01 = -jdd[0][1], a10 = -jdd[1][0], a11 = d - jdd[1][1];
        int i0 = 0, i1 = 1;
        if (fabs(a10) > fabs(a00)) {
            double t0 = a00, t1 = a01;
            a00 = a10; a01 = a11; a10 = t0; a11 = t1;
            i0 = 1; i1 = 0;
        }
        if (a00 == 0.0) return -1;
        double d0 = 1.0 / a00;
        double l10 = a10 * d0;
        a11 -= l10 * a01;
        if (a11 == 0.0) return -1;
        lu->i0 = i0; lu->i1 = i1; lu->l10 = l10; lu->u01 = a01; lu->d0 = d0; lu->d1 = 1.0 / a11;
        return 0;
    }
    if (nd == 3) {
        double a00 = d - jdd[0][0], a01 = -jdd[0][1], a02 = -jdd[0][2];
        double a10 = -jdd[1][0], a11 = d - jdd[1][1], a12 = -jdd[1][2];
        double a20 = -jdd[2][0], a21 = -jdd[2][1], a22 = d - jdd[2][2];
        int i0 = 0, i1 = 1, i2 = 2;
        double c0 = fabs(a00), c1 = fabs(a10), c2 = fabs(a20);
        if (c1 > c0 && c1 >= c2) {
            double t0 = a00, t1 = a01, t2 = a02;
            a00 = a10; a01 = a11; a02 = a12; a10 = t0; a11 = t1; a12 = t2;
            i0 = 1; i1 = 0;
        } else if (c2 > c0) {
            double t0 = a00, t1 = a01, t2 = a02;
            a00 = a20; a01 = a21; a02 = a22; a20 = t0; a21 = t1; a22 = t2;
            i0 = 2; i2 = 0;
        }
        if (a00 == 0.0) return -1;
        double d0 = 1.0 / a00;
        double l10 = a10 * d0, l20 = a20 * d0;
        a11 -= l10 * a01;
        a12 -= l10 * a02;
        a21 -= l20 * a01;
        a22 -= l20 * a02;
        if (fabs(a21) > fabs(a11)) {
            double t1 = a11, t2 = a12, tl = l10;
            int ti = i1;
            a11 = a21; a12 = a22; a21 = t1; a22 = t2; l10 = l20; l20 = tl; i1 = i2; i2 = ti;
        }
        if (a11 == 0.0) return -1;
        double d1 = 1.0 / a11;
        double l21 = a21 * d1;
        a22 -= l21 * a12;
        if (a22 == 0.0) return -1;
        lu->i0 = i0; lu->i1 = i1; lu->i2 = i2; lu->l10 = l10; lu->l20 = l20; lu->l21 = l21;
        lu->u01 = a01; lu->u02 = a02; lu->u12 = a12; lu->d0 = d0; lu->d1 = d1; lu->d2 = 1.0 / a22;
        return 0;
    }
    /* lu_factor: rows of A = d I - J with their columns reversed; the current column is the
     * last entry of each active row ("pop") */
    double tails[ND][ND], mults[ND][ND];
    /* the active rows are tails[slot[0..n_active)] in list order, orig[] their rows of A */
    int len = nd, n_active = nd, n_mult[ND], slot[ND], orig[ND];
    for (int i = 0; i < nd; i++) {
        for (int j = 0; j < nd; j++) tails[i][j] = -jdd[i][nd - 1 - j];
        tails[i][nd - 1 - i] += d;
        n_mult[i] = 0;
        slot[i] = orig[i] = i;
    }
    for (int k = 0; k < nd; k++) {
        int p = 0;
        double amax = fabs(tails[slot[0]][len - 1]);
        for (int i = 1; i < n_active; i++) {
            double v = fabs(tails[slot[i]][len - 1]);
            if (v > amax) { amax = v; p = i; }
        }
        if (!(amax > 0.0)) return -1;
        int ps = slot[p];
        lu->perm[k] = orig[p];
        for (int j = 0; j < n_mult[ps]; j++) lu->lower[k][j] = mults[ps][j];
        double inv_piv = 1.0 / tails[ps][len - 1];
        lu->inv_diag[k] = inv_piv;
        for (int j = 0; j < len - 1; j++) lu->upper_rev[k][j] = tails[ps][j];
        for (int i = p; i + 1 < n_active; i++) { slot[i] = slot[i + 1]; orig[i] = orig[i + 1]; }
        n_active -= 1;
        for (int i = 0; i < n_active; i++) {
            double *r = tails[slot[i]];
            double f = r[len - 1] * inv_piv;
            mults[slot[i]][n_mult[slot[i]]++] = f;
            if (f != 0.0)
                for (int j = 0; j < len - 1; j++) r[j] = r[j] - f * tails[ps][j];
        }
        len -= 1;
    }
    return 0;
}

/* solve (d I - J_dd) y = b (_solve_small1..3, lu_solve) */
static void lu_solve(const ros_lu *lu, const double *b, double *y) {
    int nd = lu->nd;
    if (nd == 1) {
        y[0] = b[lu->i0] * lu->d0;
    } else if (nd == 2) {
        double y0 = b[lu->i0];
        double x1 = (b[lu->i1] - lu->l10 * y0) * lu->d1;
        y[0] = (y0 - lu->u01 * x1) * lu->d0;
        y[1] = x1;
    } else if (nd == 3) {
        double y0 = b[lu->i0];
        double y1 = b[lu->i1] - lu->l10 * y0;
        double x2 = (b[lu->i2] - lu->l20 * y0 - lu->l21 * y1) * lu->d2;
        double x1 = (y1 - lu->u12 * x2) * lu->d1;
        y[0] = (y0 - lu->u01 * x1 - lu->u02 * x2) * lu->d0;
        y[1] = x1;
        y[2] = x2;
    } else {
        double yy[ND], xr[ND];
        for (int i = 0; i < nd; i++) {
            double s = 0.0;
            for (int j = 0; j < i; j++) s += lu->lower[i][j] * yy[j];
            yy[i] = b[lu->perm[i]] - s;
        }
        int n_xr = 0;
        for (int i = nd - 1; i >= 0; i--) {
            double s = 0.0;
            for (int j = 0; j < n_xr; j++) s += lu->upper_rev[i][j] * xr[j];
            xr[n_xr++] = (yy[i] - s) * lu->inv_diag[i];
        }
        for (int i = 0; i < nd; i++) y[i] = xr[nd - 1 - i];
    }
}

/* ---- the Jacobian (base._block_jacobian, forward differences) ------------------------------- */
typedef struct {
    double dd[ND][ND];          /* rows and columns: the states d */
    double qd[NX][ND];          /* rows: the quadrature states q; columns: d */
    double norm;                /* ||J_dd||_inf [1/s] (0 when neither reuse nor a first-step bound) */
} ros_jac;

/* ||J_dd||_inf [1/s]: the largest row sum of magnitudes */
static double inf_norm(const prsm_ros *r, const ros_jac *jac) {
    double norm = 0.0;
    for (int k = 0; k < r->nd; k++) {
        double s = 0.0;
        for (int c = 0; c < r->nd; c++) s += fabs(jac->dd[k][c]);
        norm = k == 0 ? s : pmax(norm, s);
    }
    return norm;
}

/* Rosenbrock._fresh_jac: 0, or -1 for a non-finite entry */
static int fresh_jac(const prsm_ros *r, prsm_rhs_fn f, const void *ctx, const double *x,
                     const double *f0, const double *u, prsm_stats *stats, ros_jac *jac) {
    const double sqrt_eps = sqrt(2.220446049250313e-16);
    double xp[NX], fp[NX];
    for (int c = 0; c < r->nd; c++) {
        int i = r->dyn[c];
        double xi = x[i];
        memcpy(xp, x, sizeof(double) * (size_t)r->n);
        xp[i] = xi + sqrt_eps * pmax(fabs(xi), 1.0);
        double inv = 1.0 / (xp[i] - xi);
        f(ctx, xp, u, fp);
        stats->rhs_calls += 1;
        for (int k = 0; k < r->nd; k++) jac->dd[k][c] = (fp[r->dyn[k]] - f0[r->dyn[k]]) * inv;
        for (int k = 0; k < r->nq; k++) jac->qd[k][c] = (fp[r->quad[k]] - f0[r->quad[k]]) * inv;
    }
    double sums[2 * NX];
    int n_rows = 0;
    for (int k = 0; k < r->nd; k++) {
        double s = 0.0;
        for (int c = 0; c < r->nd; c++) s += jac->dd[k][c];
        sums[n_rows++] = s;
    }
    for (int k = 0; k < r->nq; k++) {
        double s = 0.0;
        for (int c = 0; c < r->nd; c++) s += jac->qd[k][c];
        sums[n_rows++] = s;
    }
    if (!finite_sum(sums, n_rows)) return -1;
    jac->norm = r->jacobian_reuse != 0.0 || r->first_step_stiffness != 0.0 ? inf_norm(r, jac) : 0.0;
    return 0;
}

/* Rosenbrock._quiet */
static int quiet(const prsm_ros *r, const double *x, const double *f0, const ros_jac *jac) {
    double jac_norm = jac->norm != 0.0 ? jac->norm : inf_norm(r, jac);
    double num = 0.0, den = 0.0;
    for (int k = 0; k < r->nd; k++) {
        int i = r->dyn[k];
        double w = r->atol + r->rtol * fabs(x[i]);
        double s = 0.0;
        for (int c = 0; c < r->nd; c++) s += jac->dd[k][c] * f0[r->dyn[c]];
        num = pmax(num, fabs(s) / w);
        den = pmax(den, fabs(f0[i]) / w);
    }
    return num <= QUIET * jac_norm * den;
}

/* Rosenbrock._drift */
static double drift(const prsm_ros *r, const double *y, const double *y_jac) {
    double dmax = 0.0;
    for (int k = 0; k < r->nd; k++) {
        int i = r->dyn[k];
        double v = fabs(y[i] - y_jac[i]) / pmax(fabs(y_jac[i]), 1.0);
        dmax = k == 0 ? v : pmax(dmax, v);
    }
    return dmax;
}

/* AdaptiveBase._factor with the exponent 1/3 of the embedded order 2 */
static double factor(const prsm_ros *r, double err) {
    return prsm_step_factor(err, -1.0 / 3.0, r->safety, r->fac_min, r->fac_max);
}

/* Rosenbrock._initial_step_stiff (with AdaptiveBase._initial_step) */
static double initial_step_stiff(const prsm_ros *r, const double *x, const double *f0,
                                 const ros_jac *jac, double h) {
    int n = r->n;
    double w[NX], s0 = 0.0, s1 = 0.0;
    for (int i = 0; i < n; i++) w[i] = r->atol + r->rtol * fabs(x[i]);
    for (int i = 0; i < n; i++) s0 += prsm_pow(x[i] / w[i], 2.0);
    for (int i = 0; i < n; i++) s1 += prsm_pow(f0[i] / w[i], 2.0);
    double d0 = sqrt(s0 / (double)n), d1 = sqrt(s1 / (double)n);
    double h0 = !(d1 > 1e-5) ? h : pmin(h, 0.01 * pmax(d0, 1.0) / d1);
    double jf[NX];
    for (int k = 0; k < r->nd; k++) {
        double s = 0.0;
        for (int c = 0; c < r->nd; c++) s += jac->dd[k][c] * f0[r->dyn[c]];
        jf[r->dyn[k]] = s;
    }
    for (int k = 0; k < r->nq; k++) {
        double s = 0.0;
        for (int c = 0; c < r->nd; c++) s += jac->qd[k][c] * f0[r->dyn[c]];
        jf[r->quad[k]] = s;
    }
    double s2 = 0.0;
    for (int i = 0; i < n; i++) s2 += prsm_pow(jf[i] / w[i], 2.0);
    double d2 = sqrt(s2 / (double)n);
    double dm = pmax(d1, d2);
    if (!(dm > 1e-15)) return h0;
    return pmin(h0, prsm_pow(0.01 / dm, 1.0 / 3.0));
}

/* Rosenbrock._trial: 0, the first stage (2..4) with a non-finite value, or -1 for a non-finite
 * result; xn and err are set in every case.  v0: the sliding velocities at x (NULL: none), with
 * which err is at least the estimate's slip error norm (control.slip_error) */
static int trial(const prsm_ros *r, prsm_rhs_fn f, const void *ctx, const double *x,
                 const double *f0, const ros_lu *lu, const ros_jac *jac, double hs,
                 const double *u, const double *v0, double *xn, double *err) {
    const double *T = PRSM_ROS_TRIAL;
    double a21 = T[0], a31 = T[1], a32 = T[2], a41 = T[3], a42 = T[4], a43 = T[5];
    double c21 = T[6], c31 = T[7], c32 = T[8], c41 = T[9], c42 = T[10], c43 = T[11];
    int n = r->n, nd = r->nd, nq = r->nq;
    const int *dyn = r->dyn, *quad = r->quad;
    double ih = 1.0 / hs;
    double xd[ND], b[ND], u1[ND], u2[ND], u3[ND], u4[ND], xs[NX], f2[NX], f3[NX], f4[NX];
    for (int k = 0; k < nd; k++) { xd[k] = x[dyn[k]]; b[k] = f0[dyn[k]]; }
    lu_solve(lu, b, u1);
    memcpy(xs, x, sizeof(double) * (size_t)n);
    for (int k = 0; k < nd; k++) xs[dyn[k]] = xd[k] + a21 * u1[k];
    f(ctx, xs, u, f2);
    double d1 = c21 * ih;
    for (int k = 0; k < nd; k++) b[k] = f2[dyn[k]] + d1 * u1[k];
    lu_solve(lu, b, u2);
    memcpy(xs, x, sizeof(double) * (size_t)n);
    for (int k = 0; k < nd; k++) xs[dyn[k]] = xd[k] + a31 * u1[k] + a32 * u2[k];
    f(ctx, xs, u, f3);
    d1 = c31 * ih;
    double d2 = c32 * ih;
    for (int k = 0; k < nd; k++) b[k] = f3[dyn[k]] + d1 * u1[k] + d2 * u2[k];
    lu_solve(lu, b, u3);
    memcpy(xs, x, sizeof(double) * (size_t)n);
    for (int k = 0; k < nd; k++) xs[dyn[k]] = xd[k] + a41 * u1[k] + a42 * u2[k] + a43 * u3[k];
    f(ctx, xs, u, f4);
    d1 = c41 * ih;
    d2 = c42 * ih;
    double d3 = c43 * ih;
    for (int k = 0; k < nd; k++) b[k] = f4[dyn[k]] + d1 * u1[k] + d2 * u2[k] + d3 * u3[k];
    lu_solve(lu, b, u4);
    double m1 = PRSM_ROS_M[0], m2 = PRSM_ROS_M[1], m3 = PRSM_ROS_M[2], m4 = PRSM_ROS_M[3];
    double e1 = PRSM_ROS_E[0], e2 = PRSM_ROS_E[1], e3 = PRSM_ROS_E[2], e4 = PRSM_ROS_E[3];
    double w1 = PRSM_ROS_WQ[0], w2 = PRSM_ROS_WQ[1], w3 = PRSM_ROS_WQ[2], w4 = PRSM_ROS_WQ[3];
    double v1 = PRSM_ROS_EQ[0], v2 = PRSM_ROS_EQ[1], v3 = PRSM_ROS_EQ[2], v4 = PRSM_ROS_EQ[3];
    double rtol = r->rtol, at = r->atol, sq = 0.0, uw[ND], ue[ND], ed[ND];
    for (int k = 0; k < nd; k++) {
        double p = xd[k], q = u1[k], rr = u2[k], s = u3[k], v = u4[k];
        double pn = p + m1 * q + m2 * rr + m3 * s + m4 * v;
        ed[k] = e1 * q + e2 * rr + e3 * s + e4 * v;
        sq += prsm_err_term(ed[k], p, pn, at, rtol);
        xn[dyn[k]] = pn;
        uw[k] = w1 * q + w2 * rr + w3 * s + w4 * v;
        ue[k] = v1 * q + v2 * rr + v3 * s + v4 * v;
    }
    for (int j = 0; j < nq; j++) {
        int i = quad[j];
        double p = x[i], g1 = f0[i], g2 = f2[i], g3 = f3[i], g4 = f4[i];
        double sw = 0.0, se = 0.0;
        for (int c = 0; c < nd; c++) sw += jac->qd[j][c] * uw[c];
        for (int c = 0; c < nd; c++) se += jac->qd[j][c] * ue[c];
        double pn = p + hs * (w1 * g1 + w2 * g2 + w3 * g3 + w4 * g4 + sw);
        double eq = hs * (v1 * g1 + v2 * g2 + v3 * g3 + v4 * g4 + se);
        sq += prsm_err_term(eq, p, pn, at, rtol);
        xn[i] = pn;
    }
    *err = prsm_rms(sq, n);
    if (v0 != NULL) {
        /* the estimate's sliding velocities: the quadrature components enter none */
        double ef[NX] = {0.0}, ds[PRSM_SLIP_DIM * PRSM_MAX_LAWS] = {0.0};
        for (int k = 0; k < nd; k++) ef[dyn[k]] = ed[k];
        r->slip(ctx, ef, ds);
        double slip = prsm_slip_error(r->n_laws, r->law_dim, r->band, ds, v0, rtol, at);
        if (slip > *err) *err = slip;
    }
    double chk = 0.0;
    for (int i = 0; i < n; i++) chk += xn[i];
    chk += *err;
    if (chk - chk != 0.0) {
        if (!finite_sum(f2, n)) return 2;
        if (!finite_sum(f3, n)) return 3;
        if (!finite_sum(f4, n)) return 4;
        return -1;
    }
    return 0;
}

static int ros_fail(char *msg, int len, const char *what, double t, double hs, double t0, double h) {
    snprintf(msg, (size_t)len, "rosenbrock: %s at t = %.17g s with internal step %.17g s "
             "(advance from t = %.17g s over h = %.17g s)", what, t, hs, t0, h);
    return -1;
}

static void bad_text(int bad, char *out, int len) {
    if (bad > 0) snprintf(out, (size_t)len, "non-finite value (or wrong length) in stage %d", bad);
    else snprintf(out, (size_t)len, "non-finite value in the result");
}

/* AdaptiveBase._continues: 1 and the last advance's final proposal if this one continues it */
static int continues(const prsm_ros *r, const prsm_memory *mem, double t, const double *x,
                     const double *u, double h, double *h_cont) {
    if (!mem->has_cont || fabs(t - mem->cont_t) > TIME_MATCH * pmax(fabs(t), h)
        || !(mem->cont_u[0] == u[0] && mem->cont_u[1] == u[1]))
        return 0;
    for (int i = 0; i < r->n; i++)
        if (!(mem->cont_x[i] == x[i])) return 0;
    *h_cont = mem->cont_h;
    return 1;
}

int prsm_ros_advance(const prsm_ros *r, prsm_rhs_fn f, const void *ctx, prsm_memory *mem,
                     double t, const double *x, const double *u, double h, double *x_new,
                     prsm_stats *stats, char *msg, int len) {
    int n = r->n, fixed = r->fixed_substeps;
    double hs = 0.0, h_cont = 0.0;
    int has_hs = 0, has_cont = 0;
    if (fixed) {
        hs = h / fixed;
        has_hs = 1;
    } else {
        has_cont = continues(r, mem, t, x, u, h, &h_cont);
        if (has_cont) { hs = h_cont; has_hs = 1; }
        else { hs = mem->h_prop; has_hs = mem->has_h_prop; }
    }
    double tau = 0.0, y[NX], f0[NX], y_jac[NX], y_new[NX], err = 0.0, h_mem = 0.0;
    memcpy(y, x, sizeof(double) * (size_t)n);
    int attempts = 0, just_rejected = 0, have_f0 = 0, have_jac = 0, jac_at_y = 0, has_h_mem = 0;
    int i_fixed = 0;
    /* kink landing (prsm_step.h) */
    int kinks = !fixed && r->slip != NULL;
    prsm_landing landing;
    prsm_landing_init(&landing, r, ctx, r->h_min);
    ros_jac jac;
    ros_lu lu;
    char reason[160] = "", what[320];
    jac.norm = 0.0;
    for (;;) {
        double ti, h_step = 0.0;
        int last = 0;
        if (fixed) {
            ti = t + i_fixed * hs;
            h_step = hs;
            last = i_fixed == fixed - 1;
        } else {
            ti = t + tau;
        }
        if (!have_f0) {
            f(ctx, y, u, f0);
            stats->rhs_calls += 1;
            if (!finite_sum(f0, n))
                return ros_fail(msg, len, "non-finite value (or wrong length) in stage 1 (rhs at an "
                                "accepted point)", ti, has_hs && hs != 0.0 ? hs : h, t, h);
            if (!have_jac) {
                if (fresh_jac(r, f, ctx, y, f0, u, stats, &jac))
                    return ros_fail(msg, len, "non-finite value in the Jacobian", ti,
                                    has_hs && hs != 0.0 ? hs : h, t, h);
                have_jac = 1;
                memcpy(y_jac, y, sizeof(double) * (size_t)n);
                jac_at_y = 1;
            }
            have_f0 = 1;
            if (has_cont && tau == 0.0 && !quiet(r, y, f0, &jac)) {
                /* continuing a fast transient: the first-step bound, as after an input change */
                has_cont = 0;
                hs = mem->h_prop;
                has_hs = mem->has_h_prop;
            }
            if (!fixed && tau == 0.0 && !has_cont) {
                double limit = r->first_step_stiffness;
                if (limit != 0.0 && jac.norm != 0.0 && !has_hs) {
                    hs = limit / jac.norm;
                    has_hs = 1;
                } else if (limit != 0.0 && jac.norm != 0.0 && hs * jac.norm > limit) {
                    hs = pmax(limit / jac.norm, hs / r->fac_max);
                } else if (!has_hs) {
                    hs = initial_step_stiff(r, y, f0, &jac, h);
                    has_hs = 1;
                }
            }
        }
        if (!fixed) {
            double rem = h - tau;
            last = !landing.cuts && hs * 1.05 >= rem;
            h_step = last ? rem : hs;
            attempts += 1;
            if (attempts > r->max_substeps) {
                snprintf(what, sizeof what, "more than max_substeps = %d internal steps (accepted + "
                         "rejected)", r->max_substeps);
                return ros_fail(msg, len, what, ti, h_step, t, h);
            }
        }
        if (!jac_at_y && (just_rejected
                          || h_step * jac.norm * drift(r, y, y_jac) > r->jacobian_reuse)) {
            /* the Jacobian of an earlier point is too stale for this step: evaluate it here */
            if (fresh_jac(r, f, ctx, y, f0, u, stats, &jac))
                return ros_fail(msg, len, "non-finite value in the Jacobian", ti, h_step, t, h);
            memcpy(y_jac, y, sizeof(double) * (size_t)n);
            jac_at_y = 1;
        }
        int singular = lu_factor(jac.dd, r->nd, 1.0 / (h_step * PRSM_ROS_GAMMA), &lu);
        if (singular)
            return ros_fail(msg, len, "singular iteration matrix I/(h gamma) - J", ti, h_step, t, h);
        int bad = trial(r, f, ctx, y, f0, &lu, &jac, h_step, u,
                        kinks ? prsm_landing_start(&landing, y) : NULL, y_new, &err);
        stats->rhs_calls += 3;
        if (bad) {
            bad_text(bad, reason, sizeof reason);
            if (fixed) return ros_fail(msg, len, reason, ti, h_step, t, h);
            err = INFINITY;
        } else if (!(err <= 1.0)) {
            snprintf(reason, sizeof reason, "error norm %.3g > 1", err);
        }
        if (fixed) {
            stats->substeps += 1;
            memcpy(y, y_new, sizeof(double) * (size_t)n);
            have_f0 = have_jac = jac_at_y = 0;
            if (last) break;
            i_fixed += 1;
            continue;
        }
        double h_cut;
        if (kinks && !bad && prsm_landing_cut(&landing, y, y_new, h_step, stats, &h_cut)) {
            hs = h_cut;     /* it would cross a kink of the friction law: ends on it instead */
            continue;
        }
        if (err <= 1.0) {
            stats->substeps += 1;
            double fac = factor(r, err);
            if (just_rejected && fac > 1.0) fac = 1.0;
            double h_new = h_step * fac;
            if (kinks) h_new = prsm_landing_accepted(&landing, h_new, fac);
            if (!has_h_mem) {
                h_mem = last && h_new >= h_step ? pmax(h_new, hs) : h_new;
                has_h_mem = 1;
            }
            memcpy(y, y_new, sizeof(double) * (size_t)n);
            have_f0 = 0;
            jac_at_y = 0;
            if (r->jacobian_reuse == 0.0 || fac < 1.0) have_jac = 0;
            just_rejected = 0;
            if (last) {
                mem->has_h_prop = 1;
                mem->h_prop = h_mem;
                mem->has_cont = 1;
                mem->cont_t = t + h;
                memcpy(mem->cont_x, y, sizeof(double) * (size_t)n);
                mem->cont_u[0] = u[0];
                mem->cont_u[1] = u[1];
                mem->cont_h = h_new >= h_step ? pmax(h_new, hs) : h_new;
                break;
            }
            tau += h_step;
            hs = h_new;
        } else {
            stats->rejected += 1;
            just_rejected = 1;
            if (kinks) prsm_landing_rejected(&landing);
            hs = h_step * factor(r, err);
            if (hs < r->h_min) {
                snprintf(what, sizeof what, "step size %.17g s below h_min = %.17g s after "
                         "rejection (%s)", hs, r->h_min, reason);
                return ros_fail(msg, len, what, ti, h_step, t, h);
            }
        }
    }
    memcpy(x_new, y, sizeof(double) * (size_t)n);
    return 0;
}
