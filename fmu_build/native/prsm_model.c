/* The PRSM's kinematic, quasi-static and dynamic levels in C (see prsm_model.h for what it
 * mirrors).
 *
 * Every expression keeps the Python code's order of floating-point operations: the FMU's
 * outputs then equal the Python FMU's bit for bit (same libm).  Compile without value-changing
 * optimisations (no -ffast-math) and without fused multiply-add contraction
 * (-ffp-contract=off where the target has FMA, e.g. arm64), or results differ in the last bits.
 */
#include "prsm_model.h"
#include "prsm_ros.h"
#include "prsm_band.h"
#include "prsm_geometry.h"
#include "prsm_step.h"
#include "prsm_bounds.h"

#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#ifdef __clang__
#pragma STDC FP_CONTRACT OFF
#endif

double (*volatile prsm_pow)(double, double) = pow;

#define NS PRSM_N_STAGES
#define MAX_SIGN_ITERATIONS 8

/* ---- friction.py ------------------------------------------------------------------------- */
static double regularised_factor(double speed, double v_scale) {
    if (speed >= v_scale) return 1.0 / speed;
    return (2.0 - speed / v_scale) / v_scale;
}

static double regularised_sign(double v, double v_scale) {
    return v * regularised_factor(fabs(v), v_scale);
}

/* ---- mechanics.py ------------------------------------------------------------------------- */
typedef struct {
    int fi;
    double a0, a1;
    const double *co;
    double x0, x1, h0, h1, b0, b1, e, g, sm, sb;
} rec_stage;

typedef struct {
    double m0, m1;
    rec_stage s[NS];
} sweep_rec;

typedef struct {
    int have[2 * NS];
    double co[2 * NS][9];
} coef_cache;

/* Mechanism._coefficients: (kappa, gamma, pi, q, tau_v, gamma_v, p_v, pi_c, pi_d) of a flank
 * of stage s */
static void coefficients(const prsm_model *m, const prsm_stage *s, const prsm_flank *f,
                         double omega, double wp, double *co) {
    double sx = omega * f->ax + wp * f->bx;
    double sy = omega * f->ay + wp * f->by;
    double sz = omega * f->az;
    double v2 = sx * sx + sy * sy + sz * sz;
    double v = sqrt(v2);
    double mphi = m->mu * (v >= m->v_eps ? 1.0 / v : regularised_factor(v, m->v_eps));
    double q = 1.0 / (f->nz - mphi * sz);
    double kappa = f->pn - mphi * (f->px * sy - f->py * sx);
    double p_c = mphi * v2 * q;
    double p_d = 0.0;
    if (m->mu3 != 0.0) {
        double w = omega * f->radius;
        double sg = w >= m->v_eps ? 1.0 : w <= -m->v_eps ? -1.0 : regularised_sign(w, m->v_eps);
        kappa -= m->mu3 * sg;
        p_d = m->mu3 * sg * omega * q;
    }
    double sb = sx * f->bx + sy * f->by;
    double cv = s->c_viscous;
    co[0] = kappa * q;
    co[1] = -mphi * sb * q;
    co[2] = p_c + p_d;
    co[3] = q;
    co[4] = -cv * (f->px * sy - f->py * sx);
    co[5] = -cv * sb;
    co[6] = cv * v2;
    co[7] = p_c;
    co[8] = p_d;
}

/* Mechanism._sweep */
static void sweep(const prsm_model *m, double omega, const double *wps, double load, double ag,
                  coef_cache *cache, sweep_rec *rec) {
    double v_eps = m->v_eps;
    double a0 = load, a1 = m->last_mass;
    double mn0 = 0.0, mn1 = 0.0, hn0 = 0.0, hn1 = 0.0;
    for (int k = m->n - 1; k >= 0; k--) {
        const prsm_stage *s = &m->st[k];
        /* the threads carry the effective axial force A + V_z */
        double ae0 = a0 + s->vz_factor * omega;
        int fi = ae0 + a1 * ag >= 0.0 ? 0 : 1;
        int ci = 2 * k + fi;
        if (!cache->have[ci]) {
            coefficients(m, s, &m->fl[k][fi], omega, wps[k], cache->co[ci]);
            cache->have[ci] = 1;
        }
        const double *co = cache->co[ci];
        double kappa = co[0];
        double x0 = mn0 - kappa * ae0 - co[4];
        double x1 = s->j_screw + mn1 - kappa * a1;
        rec_stage *r = &rec->s[k];
        if (k == 0) {
            r->fi = fi; r->a0 = ae0; r->a1 = a1; r->co = co; r->x0 = x0; r->x1 = x1;
            r->h0 = r->h1 = r->b0 = r->b1 = r->e = r->g = 0.0;
            r->sm = r->sb = 1.0;
            rec->m0 = x0;
            rec->m1 = x1;
            return;
        }
        double y0 = a0 - hn0;
        double y1 = a1 - hn1 + s->m_sc;
        double e = 0.0, g, sm, sb, m0, m1, b0, b1;
        if (s->e_spline != 0.0) {
            double v = omega * s->spline_f;
            e = (v >= v_eps ? s->e_spline : v <= -v_eps ? -s->e_spline
                 : s->e_spline * regularised_sign(v, v_eps));
        }
        if (s->g_bearing != 0.0) {
            g = s->g_bearing * regularised_sign(omega * s->bearing_f, v_eps);
            sm = x0 + x1 * ag >= 0.0 ? 1.0 : -1.0;
            sb = y0 + y1 * ag >= 0.0 ? 1.0 : -1.0;
            m0 = m1 = b0 = b1 = 0.0;
            for (int i = 0; i < 3; i++) {
                double den = 1.0 - g * sb * e * sm;
                m0 = (x0 + g * sb * y0) / den;
                m1 = (x1 + g * sb * y1) / den;
                b0 = y0 + e * sm * m0;
                b1 = y1 + e * sm * m1;
                double sm_new = m0 + m1 * ag >= 0.0 ? 1.0 : -1.0;
                double sb_new = b0 + b1 * ag >= 0.0 ? 1.0 : -1.0;
                if (sm_new == sm && sb_new == sb) break;
                sm = sm_new;
                sb = sb_new;
            }
        } else {
            g = 0.0;
            sb = 1.0;
            m0 = x0;
            m1 = x1;
            sm = x0 + x1 * ag >= 0.0 ? 1.0 : -1.0;
            b0 = y0 + e * sm * m0;
            b1 = y1 + e * sm * m1;
        }
        double h0 = e * sm * m0, h1 = e * sm * m1;
        r->fi = fi; r->a0 = ae0; r->a1 = a1; r->co = co; r->x0 = m0; r->x1 = m1;
        r->h0 = h0; r->h1 = h1; r->b0 = b0; r->b1 = b1; r->e = e; r->g = g; r->sm = sm; r->sb = sb;
        a0 = b0;
        a1 = b1 + s->mass_below;
        mn0 = m0; mn1 = m1; hn0 = h0; hn1 = h1;
    }
}

/* Mechanism._signs_hold */
static int signs_hold(const prsm_model *m, const sweep_rec *rec, double alpha) {
    for (int k = 0; k < m->n; k++) {
        const rec_stage *r = &rec->s[k];
        if ((r->a0 + r->a1 * alpha >= 0.0 ? 0 : 1) != r->fi) return 0;
        if ((r->e != 0.0 || r->g != 0.0) && (r->x0 + r->x1 * alpha >= 0.0 ? 1.0 : -1.0) != r->sm)
            return 0;
        if (r->g != 0.0 && (r->b0 + r->b1 * alpha >= 0.0 ? 1.0 : -1.0) != r->sb) return 0;
    }
    return 1;
}

static int cmp_double(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return x < y ? -1 : x > y ? 1 : 0;
}

static double imbalance(const prsm_model *m, double omega, const double *wps, double load,
                        double torque, double a, coef_cache *cache, sweep_rec *rec) {
    sweep(m, omega, wps, load, a, cache, rec);
    return rec->m0 + rec->m1 * a - torque;
}

/* Mechanism._bracket: returns alpha, fills rec, sets *consistent */
static double bracket(const prsm_model *m, double omega, const double *wps, double load,
                      double torque, const double *visited, int n_visited, coef_cache *cache,
                      sweep_rec *rec, int *consistent) {
    double samples[MAX_SIGN_ITERATIONS + 1 + 14], vals[MAX_SIGN_ITERATIONS + 1 + 14];
    int n = 0;
    for (int i = 0; i < n_visited; i++) samples[n++] = visited[i];
    samples[n++] = 0.0;
    for (int e = 0; e <= 12; e += 2) {
        double p = prsm_pow(10.0, (double)e);
        samples[n++] = -1.0 * p;
        samples[n++] = 1.0 * p;
    }
    /* sorted(set(...)): keep the first of equal values, then sort */
    int u = 0;
    for (int i = 0; i < n; i++) {
        int dup = 0;
        for (int j = 0; j < u; j++)
            if (samples[j] == samples[i]) { dup = 1; break; }
        if (!dup) samples[u++] = samples[i];
    }
    n = u;
    qsort(samples, (size_t)n, sizeof samples[0], cmp_double);
    sweep_rec tmp;
    for (int i = 0; i < n; i++) vals[i] = imbalance(m, omega, wps, load, torque, samples[i], cache, &tmp);
    double roots[MAX_SIGN_ITERATIONS + 1 + 14];
    int n_roots = 0;
    for (int i = 0; i + 1 < n; i++) {
        double a_lo = samples[i], g_lo = vals[i], a_hi = samples[i + 1], g_hi = vals[i + 1];
        if (g_lo == 0.0) {
            roots[n_roots++] = a_lo;
        } else if ((g_lo < 0.0) != (g_hi < 0.0)) {
            double lo = a_lo, hi = a_hi;
            for (int it = 0; it < 200; it++) {
                double mid = 0.5 * (lo + hi);
                double gm = imbalance(m, omega, wps, load, torque, mid, cache, &tmp);
                if ((gm < 0.0) == (g_lo < 0.0)) lo = mid;
                else hi = mid;
                if (hi - lo <= 1e-15 * fmax(1.0, fabs(mid))) break;
            }
            roots[n_roots++] = 0.5 * (lo + hi);
        }
    }
    double a;
    if (n_roots) {
        a = roots[0];
        for (int i = 1; i < n_roots; i++)
            if (fabs(roots[i]) < fabs(a)) a = roots[i];
        *consistent = 1;
    } else {
        int best = 0;
        for (int i = 1; i < n; i++)
            if (fabs(vals[i]) < fabs(vals[best])) best = i;
        a = samples[best];
        *consistent = 0;
    }
    imbalance(m, omega, wps, load, torque, a, cache, rec);
    return a;
}

/* Mechanism._balance with a motor torque (torque drive) */
static double balance(const prsm_model *m, double omega, const double *wps, double load,
                      double torque, coef_cache *cache, sweep_rec *rec, int *consistent) {
    double visited[MAX_SIGN_ITERATIONS];
    int n_visited = 0;
    double ag = 0.0;
    for (int i = 0; i < MAX_SIGN_ITERATIONS; i++) {
        sweep(m, omega, wps, load, ag, cache, rec);
        double alpha = (torque - rec->m0) / rec->m1;
        if (rec->m1 > 0.0 && signs_hold(m, rec, alpha)) {
            *consistent = 1;
            return alpha;
        }
        visited[n_visited++] = ag;
        ag = alpha;
    }
    return bracket(m, omega, wps, load, torque, visited, n_visited, cache, rec, consistent);
}

/* Mechanism._rates: the friction power [W] */
static double rates_power(const prsm_model *m, double omega, double alpha, const sweep_rec *rec) {
    double p_fric = 0.0;
    for (int k = 0; k < m->n; k++) {
        const rec_stage *r = &rec->s[k];
        double a = r->a0 + r->a1 * alpha;
        p_fric += r->co[2] * a + r->co[6];
        if (r->e != 0.0) p_fric += (r->h0 + r->h1 * alpha) * omega * m->st[k].spline_f;
        if (r->g != 0.0) p_fric += r->g * r->sb * (r->b0 + r->b1 * alpha) * omega;
    }
    return p_fric;
}

static void carrier_speeds(const prsm_model *m, double omega, double *wps) {
    for (int k = 0; k < NS; k++) wps[k] = m->st[k].zeta * omega;
}

/* Mechanism.carrier_speeds: the state's at the dynamic level, zeta_k omega otherwise */
static void speeds_of(const prsm_model *m, const double *x, double *wps) {
    if (m->dynamic) {
        for (int k = 0; k < NS; k++) wps[k] = x[2 + k];
    } else {
        carrier_speeds(m, x[1], wps);
    }
}

/* KinematicModel._extra_loss_torque (0 for the quasi-static level) */
static double extra_loss(const prsm_model *m, double omega, double load) {
    if (!m->kinematic) return 0.0;
    double torque = m->viscous_loss * omega;
    if (m->coulomb_loss)
        torque += (m->loss_factor + m->differential_loss) * fabs(load)
                  * regularised_sign(omega * m->c_out, m->v_eps);
    return torque;
}

/* Mechanism.solve/rates with slaved carriers: the carrier speeds, alpha and the sweep record
 * (whose coefficients live in cache) for a torque on screw 1 */
static double solve(const prsm_model *m, const double *x, double load, double torque, double *wps,
                    coef_cache *cache, sweep_rec *rec, int *consistent) {
    memset(cache->have, 0, sizeof cache->have);
    speeds_of(m, x, wps);
    return balance(m, x[1], wps, load, torque, cache, rec, consistent);
}

/* Model._solve: the screw acceleration at x with inputs u (torque drive: u[0] the motor torque;
 * speed drive: u[0] the prescribed acceleration, the motor torque following, Mechanism._balance),
 * the motor torque (with the extra loss) into *motor, the carrier speeds, the sweep record and
 * the consistency flag */
static double balance_at(const prsm_model *m, const double *x, const double *u, double loss,
                         double *motor, double *wps, coef_cache *cache, sweep_rec *rec,
                         int *consistent) {
    double load = u[1];
    *consistent = 1;
    *motor = u[0];
    if (!m->speed_drive) return solve(m, x, load, u[0] - loss, wps, cache, rec, consistent);
    double alpha = u[0];
    memset(cache->have, 0, sizeof cache->have);
    speeds_of(m, x, wps);
    sweep(m, x[1], wps, load, alpha, cache, rec);
    *motor = rec->m0 + rec->m1 * alpha + loss;
    return alpha;
}

/* Model.rhs: torque drive at every level, speed drive at the dynamic level (the carrier speeds
 * are states there, slaved to the screw otherwise; an extra loss at the kinematic level only) */
static void rhs(const prsm_model *m, const double *x, const double *u, double *dx) {
    double load = u[1], omega = x[1];
    double loss = extra_loss(m, omega, load);
    double motor;
    double wps[NS];
    coef_cache cache;
    sweep_rec rec;
    int consistent;
    double alpha = balance_at(m, x, u, loss, &motor, wps, &cache, &rec, &consistent);
    double p_fric = consistent ? rates_power(m, omega, alpha, &rec) : NAN;
    if (!consistent) alpha = NAN;
    if (m->dynamic)      /* Mechanism._rates: carrier generalized forces over their inertias */
        for (int k = 0; k < NS; k++) {
            const rec_stage *r = &rec.s[k];
            dx[2 + k] = consistent ? (r->co[1] * (r->a0 + r->a1 * alpha) + r->co[5]) / m->st[k].j_carrier
                                   : NAN;
        }
    int ie = m->ie;
    dx[0] = omega;
    dx[1] = alpha;
    dx[ie] = motor * omega;
    dx[ie + 1] = load * m->c_out * omega;
    dx[ie + 2] = p_fric + loss * omega;
}

/* Model.sliding_velocities (Mechanism.sliding_velocities: per stage the thread flanks' slip
 * velocities, then the spline's and the bearing's speeds, where they have friction; then the
 * kinematic level's own loss), PRSM_SLIP_DIM slots per law, with the signature of prsm_ros's
 * slip */
static void slip_ctx(const void *ctx, const double *x, double *v) {
    const prsm_model *m = (const prsm_model *)ctx;
    double omega = x[1], wps[NS];
    speeds_of(m, x, wps);
    int j = 0;
    for (int k = 0; k < NS; k++) {
        const prsm_stage *s = &m->st[k];
        double wp = wps[k];
        for (int f = 0; f < 2; f++) {
            const prsm_flank *fl = &m->fl[k][f];
            if (m->mu != 0.0) {
                v[j] = omega * fl->ax + wp * fl->bx;
                v[j + 1] = omega * fl->ay + wp * fl->by;
                v[j + 2] = omega * fl->az;
                j += PRSM_SLIP_DIM;
            }
            if (m->mu3 != 0.0) { v[j] = omega * fl->radius; j += PRSM_SLIP_DIM; }
        }
        if (s->e_spline != 0.0) { v[j] = omega * s->spline_f; j += PRSM_SLIP_DIM; }
        if (s->g_bearing != 0.0) { v[j] = omega * s->bearing_f; j += PRSM_SLIP_DIM; }
    }
    if (m->coulomb_loss) v[j] = omega * m->c_out;
}

/* rhs with the signature of prsm_ros.h's right-hand side */
static void rhs_ctx(const void *ctx, const double *x, const double *u, double *dx) {
    rhs((const prsm_model *)ctx, x, u, dx);
}

void prsm_rhs(const prsm_model *m, const double x[PRSM_NX_MAX], const double u[2],
              double dx[PRSM_NX_MAX]) {
    rhs(m, x, u, dx);
}

/* ---- models/slaved.py ---------------------------------------------------------------------- */
static const prsm_law *law_of(prsm_model *m, double sign_w, double sign_load) {
    prsm_law *law = &m->law[sign_w > 0.0][sign_load > 0.0];
    if (law->state) return law->state == 1 ? law : NULL;
    double omega = sign_w * 100.0 * m->band_speed;
    double load = sign_load * 1000.0;
    double loss = extra_loss(m, omega, load);
    double wps[NS];
    coef_cache cache;
    sweep_rec rec;
    memset(cache.have, 0, sizeof cache.have);
    carrier_speeds(m, omega, wps);
    sweep(m, omega, wps, load, 0.0, &cache, &rec);
    if (!signs_hold(m, &rec, 0.0)) {
        law->state = 2;
        return NULL;
    }
    int n = 0;
    for (int k = 0; k < m->n; k++) {
        const rec_stage *r = &rec.s[k];
        law->c_load[n] = r->a0 / load; law->c_alpha[n] = r->a1; law->positive[n++] = r->fi == 0;
        if (r->e != 0.0 || r->g != 0.0) {
            law->c_load[n] = r->x0 / load; law->c_alpha[n] = r->x1;
            law->positive[n++] = r->sm > 0.0;
            law->c_load[n] = r->b0 / load; law->c_alpha[n] = r->b1;
            law->positive[n++] = r->sb > 0.0;
        }
    }
    law->n_checks = n;
    double a_ref = 1000.0;
    double p_0 = rates_power(m, omega, 0.0, &rec);
    double p_a = rates_power(m, omega, a_ref, &rec);
    double speed = fabs(omega);
    law->q_alpha = (p_a - p_0) / a_ref / speed;
    law->q_load = p_0 / load / speed;
    law->loss_per_load = fabs(loss / load);
    law->k_load = rec.m0 / load;
    law->k_alpha = rec.m1;
    law->state = 1;
    return law;
}

/* SlavedAdvance.advance: 1 and y if exact, 0 if the caller must integrate */
static int slaved_advance(prsm_model *m, const double *x, const double *u, double h, double *y) {
    double w0 = x[1], load = u[1], band = m->band_speed;
    if (fabs(w0) < band || load == 0.0 || m->viscous) return 0;
    double sign_w = w0 > 0.0 ? 1.0 : -1.0;
    const prsm_law *law = law_of(m, sign_w, load > 0.0 ? 1.0 : -1.0);
    if (!law) return 0;
    double loss = law->loss_per_load * fabs(load) * sign_w;
    double torque, alpha;
    if (m->speed_drive) {
        alpha = u[0];
        torque = law->k_load * load + law->k_alpha * alpha + loss;
    } else {
        torque = u[0];
        alpha = (torque - loss - law->k_load * load) / law->k_alpha;
    }
    for (int i = 0; i < law->n_checks; i++)
        if ((law->c_load[i] * load + law->c_alpha[i] * alpha >= 0.0) != law->positive[i]) return 0;
    double w1 = w0 + alpha * h;
    if (w1 * sign_w < band) return 0;
    double dth = (w0 + 0.5 * alpha * h) * h;
    double p_per_speed = law->q_load * load + law->q_alpha * alpha + law->loss_per_load * fabs(load);
    y[0] = x[0] + dth;
    y[1] = w1;
    y[2] = x[2] + torque * dth;
    y[3] = x[3] + load * m->c_out * dth;
    y[4] = x[4] + p_per_speed * sign_w * dth;
    return 1;
}

/* SlavedLevel.closed_form_advance: at a constant prescribed speed (speed drive, acceleration 0)
 * one Euler step, exact; otherwise slaved_advance.  1 and y if exact, 0 if not */
static int closed_form_advance(prsm_model *m, const double *x, const double *u, double h,
                               double *y) {
    if (m->speed_drive && u[0] == 0.0) {
        double dx[PRSM_NX_MAX];
        rhs(m, x, u, dx);
        for (int i = 0; i < PRSM_NX; i++) y[i] = x[i] + h * dx[i];
        return 1;
    }
    return slaved_advance(m, x, u, h, y);
}

/* closed_form_advance with the signature of prsm_band.h's closed-form step */
static int exact_ctx(void *ctx, const double *x, const double *u, double h, double *y) {
    return closed_form_advance((prsm_model *)ctx, x, u, h, y);
}

/* ---- model set-up ------------------------------------------------------------------------- */
static int fail(char *msg, int len, const char *text) {
    snprintf(msg, (size_t)len, "%s", text);
    return -1;
}

/* Mechanism.__init__, KinematicModel.__init__, SlavedAdvance.__init__ and the stepper's options */
int prsm_model_init(prsm_model *m, const prsm_config *cfg, char *msg, int len) {
    memset(m, 0, sizeof *m);
    m->n = NS;
    /* the parameters' ranges are checked before (prsm_fmi2.c walks the table generated from
     * prsm_fmu.param_ranges; fmu_build.native_stepper passes a model the Python package
     * validated) */
    double tol = cfg->tolerance, eff = cfg->kinematic_efficiency;
    m->kinematic = cfg->kinematic;
    m->dynamic = cfg->dynamic && !cfg->kinematic;
    m->speed_drive = cfg->speed_drive;
    m->nx = m->dynamic ? PRSM_NX_MAX : PRSM_NX;
    m->ie = m->dynamic ? 2 + NS : 2;
    m->mu = m->kinematic ? 0.0 : cfg->mu_screw_roller;
    m->mu3 = m->kinematic ? 0.0 : cfg->mu_differential;
    m->v_eps = cfg->slip_velocity_scale;
    double limit = INFINITY, zeta_ideal[NS];
    for (int k = 0; k < NS; k++) {
        const prsm_stage_values *v = &cfg->stage[k];
        prsm_stage *s = &m->st[k];
        double min_normal_z;
        /* mechanics._Stage.__init__: the contact (prsm_geometry.c) and the constants of the
         * geometry, operation for operation */
        if (prsm_stage_contact(k, v, m->fl[k], &s->zeta_geometric, &min_normal_z, msg, len))
            return -1;
        double leads = 0.0;
        for (int i = 0; i < k; i++) leads += cfg->stage[i].screw_lead;
        s->c_prev = leads / PRSM_TWO_PI;
        s->c = (leads + v->screw_lead) / PRSM_TWO_PI;
        double spline_f = k > 0 ? cfg->stage[k - 1].screw_lead / PRSM_TWO_PI : 0.0;
        zeta_ideal[k] = v->screw_radius / (v->screw_radius + v->nut_radius);
        double starts_1 = ((double)v->screw_starts - 1.0) * ((double)v->screw_starts - 1.0);
        double orbit2 = prsm_pow(v->screw_radius + v->roller_radius, 2.0);
        s->n_rollers = (double)v->n_rollers;
        s->m_assembly = v->nut_mass + (double)v->n_rollers * v->roller_mass
                        + (double)v->carriers * v->carrier_mass;
        s->m_screw = k > 0 ? v->screw_mass : 0.0;
        s->j_screw = v->screw_inertia;
        s->j_carrier = (double)v->carriers * v->carrier_inertia
                       + (double)v->n_rollers * v->roller_inertia * starts_1
                       + (double)v->n_rollers * v->roller_mass * orbit2;
        s->e_spline = (k > 0 && cfg->mu_spline > 0.0) ? cfg->mu_spline / v->spline_radius : 0.0;
        s->g_bearing = (k > 0 && cfg->mu_nut_screw > 0.0)
                       ? cfg->mu_nut_screw * cfg->stage[k - 1].bearing_radius : 0.0;
        s->spline_f = spline_f;
        s->bearing_f = k > 0 ? cfg->stage[k - 1].bearing_radius : 0.0;
        s->c_viscous = cfg->mu_viscous * (double)v->n_rollers * (double)cfg->threads_per_roller[k];
        if (m->kinematic) {
            s->e_spline = 0.0;
            s->g_bearing = 0.0;
            s->c_viscous = 0.0;
        }
        s->vz_factor = s->c_viscous * m->fl[k][0].az;
        if (s->c_viscous > 0.0) m->viscous = 1;
        if (min_normal_z < limit) limit = min_normal_z;
    }
    if (m->mu >= limit) {
        char mu[40];
        prsm_fmt_num(mu, sizeof mu, m->mu);
        snprintf(msg, (size_t)len, "mu_screw_roller = %s is out of range for this geometry: must be "
                 "< %.4f (the axial part of the contact normal); above it the thread self-locks "
                 "and the rigid model has no solution", mu, limit);
        return -1;
    }
    m->c_out = m->st[NS - 1].c;
    for (int k = 0; k < NS; k++) {          /* carriers slaved to the screw (not dynamic) */
        prsm_stage *s = &m->st[k];
        double z = m->kinematic ? zeta_ideal[k] : s->zeta_geometric;
        s->zeta = z;
        if (!m->dynamic) s->j_screw = s->j_screw + s->j_carrier * z * z;
    }
    for (int k = 0; k < NS; k++) {
        prsm_stage *s = &m->st[k];
        s->m_sc = s->m_screw * s->c_prev;
        s->mass_below = k > 0 ? m->st[k - 1].m_assembly * m->st[k - 1].c : 0.0;
    }
    m->last_mass = m->st[NS - 1].m_assembly * m->st[NS - 1].c;
    double j = 0.0;
    for (int k = 0; k < NS; k++) {
        const prsm_stage *s = &m->st[k];
        j += s->j_screw + s->m_assembly * s->c * s->c + s->m_screw * s->c_prev * s->c_prev;
    }
    m->equivalent_inertia = j;
    m->loss_factor = m->kinematic ? (1.0 / eff - 1.0) * m->c_out : 0.0;
    /* KinematicModel.__init__: the lumped viscous and differential-sliding losses */
    if (m->kinematic) {
        double c_v = 0.0, c_d = 0.0;
        for (int k = 0; k < NS; k++) {
            const prsm_flank *fl = &m->fl[k][0];
            double z = m->st[k].zeta_geometric;
            double sx = fl->ax + z * fl->bx, sy = fl->ay + z * fl->by, sz = fl->az;
            double cvis = cfg->mu_viscous * (double)cfg->stage[k].n_rollers
                          * (double)cfg->threads_per_roller[k];
            c_v += cvis * (sx * sx + sy * sy + sz * sz);
            c_d += cfg->mu_differential / fabs(fl->nz);
        }
        m->viscous_loss = c_v;
        m->differential_loss = c_d;
        m->coulomb_loss = m->loss_factor > 0.0 || c_d > 0.0;
        m->viscous = c_v > 0.0;
    }
    /* SlavedAdvance.__init__: the slowest sliding speed per unit screw speed */
    double fmin_ = INFINITY;
    int first = 1;
    for (int k = 0; k < NS; k++) {
        const prsm_stage *s = &m->st[k];
        double z = s->zeta;
        for (int f = 0; f < 2; f++) {
            const prsm_flank *fl = &m->fl[k][f];
            double dx = fl->ax + z * fl->bx, dy = fl->ay + z * fl->by, dz = fl->az;
            double v = sqrt(dx * dx + dy * dy + dz * dz);
            if (first || v < fmin_) fmin_ = v;
            first = 0;
            if (m->mu3 != 0.0 && fl->radius < fmin_) fmin_ = fl->radius;
        }
        if (s->e_spline != 0.0 && s->spline_f < fmin_) fmin_ = s->spline_f;
        if (s->g_bearing != 0.0 && s->bearing_f < fmin_) fmin_ = s->bearing_f;
    }
    if (m->coulomb_loss && m->c_out < fmin_) fmin_ = m->c_out;
    m->band_speed = m->v_eps / fmin_;
    /* SlavedLevel.smooth_breaks: 0 and +-v_eps / f for the sliding speed per unit screw speed f
     * of every regularised law that acts (SlavedAdvance.law_factors), finite, ascending */
    double edges[PRSM_MAX_BREAKS];
    int n_edges = 0;
    for (int k = 0; k < NS; k++) {
        const prsm_stage *s = &m->st[k];
        double laws[6];
        int n_laws = 0;
        for (int f = 0; f < 2; f++) {
            const prsm_flank *fl = &m->fl[k][f];
            double dx = fl->ax + s->zeta * fl->bx, dy = fl->ay + s->zeta * fl->by, dz = fl->az;
            if (m->mu != 0.0) laws[n_laws++] = sqrt(dx * dx + dy * dy + dz * dz);
            if (m->mu3 != 0.0) laws[n_laws++] = fl->radius;
        }
        if (s->e_spline != 0.0) laws[n_laws++] = s->spline_f;
        if (s->g_bearing != 0.0) laws[n_laws++] = s->bearing_f;
        for (int j = 0; j < n_laws; j++)
            if (laws[j] > 0.0) edges[n_edges++] = m->v_eps / laws[j];
    }
    if (m->coulomb_loss && m->c_out > 0.0) edges[n_edges++] = m->v_eps / m->c_out;
    qsort(edges, (size_t)n_edges, sizeof edges[0], cmp_double);
    prsm_band *bd = &m->band;
    int nb = 0;
    for (int j = n_edges - 1; j >= 0; j--)      /* -edges descending, 0, edges ascending */
        if (isfinite(edges[j]) && (j == n_edges - 1 || edges[j] != edges[j + 1]))
            bd->breaks[nb++] = -edges[j];
    bd->breaks[nb++] = 0.0;
    for (int j = 0; j < n_edges; j++)
        if (isfinite(edges[j]) && (j == 0 || edges[j] != edges[j - 1])) bd->breaks[nb++] = edges[j];
    bd->n_breaks = nb;
    bd->w_scale = 1.0;                          /* the speed's state_scale without a break */
    {
        int found = 0;
        double smallest = 0.0;
        for (int j = 0; j < nb; j++) {
            double a = fabs(bd->breaks[j]);
            if (a != 0.0 && (!found || a < smallest)) { smallest = a; found = 1; }
        }
        if (found) bd->w_scale = smallest;
    }
    /* stepper: ClosedForm or ExplicitAdaptive (order 5), tuned_stepper_options */
    m->closed_form = cfg->closed_form;
    m->rtol = tol;
    m->atol = 1e-2 * tol;
    m->h_min = 1e-14;
    m->safety = 0.9;
    m->fac_min = 0.2;
    m->fac_max = 5.0;
    m->max_substeps = cfg->max_substeps;
    m->fixed_substeps = cfg->substeps;
    /* the dynamic level: Rosenbrock with configure's options (steppers.options.TUNED_OPTIONS
     * when adaptive; plain rtol and atol with fixed substeps); quadrature states: the angle and
     * the work integrals (Model.quadrature_states) */
    prsm_ros *r = &m->ros;
    r->n = m->nx;
    r->nd = 1 + NS;
    r->nq = 4;
    for (int k = 0; k < r->nd; k++) r->dyn[k] = 1 + k;
    r->quad[0] = 0;
    for (int k = 1; k < 4; k++) r->quad[k] = 1 + NS + k;
    /* steppers.options.TOLERANCE_FACTOR when adaptive (tuned_stepper_options) */
    r->rtol = cfg->substeps ? m->rtol : m->rtol * PRSM_ROS_TOLERANCE_FACTOR;
    r->atol = cfg->substeps ? m->atol : m->atol * PRSM_ROS_TOLERANCE_FACTOR;
    r->h_min = m->h_min;
    r->safety = m->safety;
    r->fac_min = m->fac_min;
    r->fac_max = m->fac_max;
    r->jacobian_reuse = cfg->substeps ? 0.0 : 0.1;
    r->first_step_stiffness = cfg->substeps ? 0.0 : 8.0;
    r->max_substeps = cfg->max_substeps;
    r->fixed_substeps = cfg->substeps;
    /* the slaved levels' band step: ScalarExponential with the FMU's options */
    m->band_exponential = cfg->band_exponential;
    bd->rtol = m->rtol;
    bd->atol = m->atol;
    bd->h_min = m->h_min;
    bd->safety = m->safety;
    bd->fac_min = m->fac_min;
    bd->fac_max = m->fac_max;
    bd->max_substeps = cfg->max_substeps;
    bd->fixed_substeps = cfg->substeps;
    /* kink landing: the laws of slip_ctx in its order (Mechanism.kink_speeds) */
    r->n_laws = 0;
    for (int k = 0; k < NS; k++) {
        for (int f = 0; f < 2; f++) {
            if (m->mu != 0.0) r->law_dim[r->n_laws++] = 3;
            if (m->mu3 != 0.0) r->law_dim[r->n_laws++] = 1;
        }
        if (m->st[k].e_spline != 0.0) r->law_dim[r->n_laws++] = 1;
        if (m->st[k].g_bearing != 0.0) r->law_dim[r->n_laws++] = 1;
    }
    if (m->coulomb_loss) r->law_dim[r->n_laws++] = 1;
    r->band = m->v_eps;
    r->slip = r->n_laws ? slip_ctx : NULL;
    /* the speeds' bounds (from the inertias above): checked after every step */
    for (int i = 1; i < m->nx - 3; i++) m->speed_bound[i - 1] = prsm_speed_bound(m, i, m->nx);
    return 0;
}

void prsm_initial_state(const prsm_model *m, double x[PRSM_NX_MAX], double screw_angle,
                        double screw_speed, int carrier_equilibrium) {
    for (int i = 0; i < PRSM_NX_MAX; i++) x[i] = 0.0;
    x[0] = screw_angle;
    x[1] = screw_speed;
    if (m->dynamic)
        for (int k = 0; k < NS; k++)
            x[2 + k] = (carrier_equilibrium ? m->st[k].zeta_geometric : 0.0) * screw_speed;
}

/* ---- models/base.Model.outputs --------------------------------------------------------------- */
/* NaN where no power passes through (standstill |omega| <= PRSM_STANDSTILL_SPEED, both sides
   delivering or both absorbing): prsm_fmu.models.base.efficiency, its threshold generated */
static double efficiency(double p_in, double p_out, double omega) {
    if (!(fabs(omega) > PRSM_STANDSTILL_SPEED)) return NAN;
    if (p_in > 0.0 && p_out >= 0.0) return p_out / p_in;
    if (p_out < 0.0 && p_in <= 0.0) return p_in / p_out + 0.0;
    return NAN;
}

void prsm_outputs_at(prsm_model *m, const double x[PRSM_NX_MAX], const double u[2], prsm_outputs *y) {
    double omega = x[1], load = u[1];
    double loss = extra_loss(m, omega, load);
    double motor;
    double wps[NS];
    coef_cache cache;
    sweep_rec rec;
    int consistent;
    double alpha = balance_at(m, x, u, loss, &motor, wps, &cache, &rec, &consistent);
    /* Mechanism._assemble(detail=True) */
    double p_fric = 0.0, p_coulomb = 0.0, p_joints = 0.0, p_viscous = 0.0, p_differential = 0.0;
    for (int k = 0; k < m->n; k++) {
        const rec_stage *r = &rec.s[k];
        const prsm_stage *s = &m->st[k];
        double a = r->a0 + r->a1 * alpha;
        double pk = r->co[2] * a + r->co[6];
        p_coulomb += r->co[7] * a;
        p_differential += r->co[8] * a;
        p_viscous += r->co[6];
        if (k > 0) {
            double hk = r->h0 + r->h1 * alpha;
            double b = r->b0 + r->b1 * alpha;
            /* Mechanism._assemble: p_joint = h ω ℓ_(k−1) + g σ_B B ω */
            double p_joint = hk * omega * s->spline_f + r->g * r->sb * b * omega;
            pk += p_joint;
            p_joints += p_joint;
        }
        p_fric += pk;
        double f_normal = a * r->co[3] / s->n_rollers;
        y->normal_force[k] = f_normal;
        y->contact_force[k] = f_normal * m->fl[k][r->fi].nz;
        y->driven_torque[k] = k == 0 ? motor : r->x0 + r->x1 * alpha;
        y->spline_friction[k] = k == 0 ? 0.0 : r->h0 + r->h1 * alpha;
        y->carrier_speed[k] = wps[k];
        y->carrier_speed_ratio[k] = omega != 0.0 ? wps[k] / omega : 0.0;
    }
    double v_rod = m->c_out * omega;
    double p_in = motor * omega, p_out = load * v_rod;
    y->alpha = alpha;
    y->motor = motor;
    y->loss = loss;
    y->efficiency = efficiency(p_in, p_out, omega);
    y->friction_power = p_fric + loss * omega;
    y->p_coulomb = p_coulomb;
    y->p_viscous = p_viscous;
    y->p_differential = p_differential;
    if (loss != 0.0) {      /* KinematicModel._extra_loss_terms */
        double sg = regularised_sign(omega * m->c_out, m->v_eps);
        y->p_coulomb += m->loss_factor * fabs(load) * sg * omega;
        y->p_viscous += m->viscous_loss * omega * omega;
        y->p_differential += m->differential_loss * fabs(load) * sg * omega;
    }
    y->p_joints = p_joints;
    y->consistent = consistent;
    /* Mechanism.kinetic_energy */
    double ke = 0.5 * m->equivalent_inertia * omega * omega;
    if (m->dynamic)
        for (int k = 0; k < NS; k++) ke += 0.5 * m->st[k].j_carrier * wps[k] * wps[k];
    y->kinetic_energy = ke;
}

/* ---- steppers/explicit.py: Dormand-Prince 5(4) with step-size control ------------------------ */
/* AdaptiveBase._factor with the exponent 1/5 of the embedded order 4 */
static double err_factor(const prsm_model *m, double err) {
    return prsm_step_factor(err, -1.0 / 5.0, m->safety, m->fac_min, m->fac_max);
}

/* one trial step: xn, k7 = f(xn), err; returns 0, or nonzero if a value is not finite */
static int trial_dp5(const prsm_model *m, const double *x, const double *k1, double hs,
                     const double *u, double *xn, double *k7, double *err) {
    const double (*A)[5] = PRSM_DP_A;
    double k2[PRSM_NX], k3[PRSM_NX], k4[PRSM_NX], k5[PRSM_NX], k6[PRSM_NX], z[PRSM_NX];
    double h21 = hs * A[0][0];
    for (int i = 0; i < PRSM_NX; i++) z[i] = x[i] + h21 * k1[i];
    rhs(m, z, u, k2);
    double h31 = hs * A[1][0], h32 = hs * A[1][1];
    for (int i = 0; i < PRSM_NX; i++) z[i] = x[i] + h31 * k1[i] + h32 * k2[i];
    rhs(m, z, u, k3);
    double h41 = hs * A[2][0], h42 = hs * A[2][1], h43 = hs * A[2][2];
    for (int i = 0; i < PRSM_NX; i++) z[i] = x[i] + h41 * k1[i] + h42 * k2[i] + h43 * k3[i];
    rhs(m, z, u, k4);
    double h51 = hs * A[3][0], h52 = hs * A[3][1], h53 = hs * A[3][2], h54 = hs * A[3][3];
    for (int i = 0; i < PRSM_NX; i++)
        z[i] = x[i] + h51 * k1[i] + h52 * k2[i] + h53 * k3[i] + h54 * k4[i];
    rhs(m, z, u, k5);
    double h61 = hs * A[4][0], h62 = hs * A[4][1], h63 = hs * A[4][2], h64 = hs * A[4][3],
           h65 = hs * A[4][4];
    for (int i = 0; i < PRSM_NX; i++)
        z[i] = x[i] + h61 * k1[i] + h62 * k2[i] + h63 * k3[i] + h64 * k4[i] + h65 * k5[i];
    rhs(m, z, u, k6);
    double g1 = hs * PRSM_DP_B[0], g3 = hs * PRSM_DP_B[1], g4 = hs * PRSM_DP_B[2],
           g5 = hs * PRSM_DP_B[3], g6 = hs * PRSM_DP_B[4];
    for (int i = 0; i < PRSM_NX; i++)
        xn[i] = x[i] + g1 * k1[i] + g3 * k3[i] + g4 * k4[i] + g5 * k5[i] + g6 * k6[i];
    rhs(m, xn, u, k7);
    double e1 = hs * PRSM_DP_E[0], e3 = hs * PRSM_DP_E[1], e4 = hs * PRSM_DP_E[2],
           e5 = hs * PRSM_DP_E[3], e6 = hs * PRSM_DP_E[4], e7 = hs * PRSM_DP_E[5];
    double sq = 0.0;
    for (int i = 0; i < PRSM_NX; i++)
        sq += prsm_err_term(e1 * k1[i] + e3 * k3[i] + e4 * k4[i] + e5 * k5[i] + e6 * k6[i]
                            + e7 * k7[i], x[i], xn[i], m->atol, m->rtol);
    *err = prsm_rms(sq, PRSM_NX);
    int ok = finite_sum(k2, PRSM_NX) && finite_sum(k3, PRSM_NX) && finite_sum(k4, PRSM_NX) &&
             finite_sum(k5, PRSM_NX) && finite_sum(k6, PRSM_NX) && finite_sum(k7, PRSM_NX) &&
             finite_sum(xn, PRSM_NX) && isfinite(*err);
    return !ok;
}

static void start_norms(const prsm_model *m, const double *x, const double *f0, double *w,
                        double *d0, double *d1) {
    double s0 = 0.0, s1 = 0.0;
    for (int i = 0; i < PRSM_NX; i++) w[i] = m->atol + m->rtol * fabs(x[i]);
    for (int i = 0; i < PRSM_NX; i++) s0 += prsm_pow(x[i] / w[i], 2.0);
    for (int i = 0; i < PRSM_NX; i++) s1 += prsm_pow(f0[i] / w[i], 2.0);
    *d0 = sqrt(s0 / (double)PRSM_NX);
    *d1 = sqrt(s1 / (double)PRSM_NX);
}

/* ExplicitAdaptive._starting_step */
static double starting_step(const prsm_model *m, const double *x, const double *k1,
                            const double *u, double h, prsm_stats *stats) {
    double w[PRSM_NX], d0, d1, z[PRSM_NX], f1[PRSM_NX];
    start_norms(m, x, k1, w, &d0, &d1);
    if (!(d1 > 1e-5)) return h;
    double h0 = pmin(h, d0 >= 1e-5 ? 0.01 * d0 / d1 : 1e-6);
    for (int i = 0; i < PRSM_NX; i++) z[i] = x[i] + h0 * k1[i];
    rhs(m, z, u, f1);
    stats->rhs_calls += 1;
    double s = 0.0;
    for (int i = 0; i < PRSM_NX; i++) s += prsm_pow((f1[i] - k1[i]) / w[i], 2.0);
    double d2 = sqrt(s / (double)PRSM_NX) / h0;
    double dm = pmax(d1, d2);
    if (!isfinite(dm)) return pmin(h, h0);
    double h1 = dm > 1e-15 ? prsm_pow(0.01 / dm, 1.0 / 6.0) : pmax(1e-6, 1e-3 * h0);
    return pmin(pmin(h, 100.0 * h0), h1);
}

static int step_fail(char *msg, int len, const char *what, double t, double hs, double t0, double h) {
    snprintf(msg, (size_t)len, "explicit_adaptive: %s at t = %.17g s with internal step %.17g s "
             "(advance from t = %.17g s over h = %.17g s)", what, t, hs, t0, h);
    return -1;
}

/* ExplicitAdaptive.advance */
static int explicit_advance(prsm_model *m, prsm_memory *mem, double t, const double *x,
                            const double *u, double h, double *y, prsm_stats *stats, char *msg,
                            int len) {
    double k1[PRSM_NX], yn[PRSM_NX], kn[PRSM_NX], err;
    double h_or = mem->has_h_prop ? mem->h_prop : h;
    /* _first_stage: the last advance's FSAL stage when this one starts where it ended */
    int reuse = 0;
    if (mem->has_fsal && mem->fsal_u[0] == u[0] && mem->fsal_u[1] == u[1]
        && fabs(t - mem->fsal_t) <= 4e-16 * pmax(fabs(t), h)) {
        reuse = 1;
        for (int i = 0; i < PRSM_NX; i++)
            if (mem->fsal_x[i] != x[i]) reuse = 0;
    }
    if (reuse) {
        memcpy(k1, mem->fsal_f, sizeof k1);
    } else {
        rhs(m, x, u, k1);
        stats->rhs_calls += 1;
    }
    if (!finite_sum(k1, PRSM_NX))
        return step_fail(msg, len, "non-finite value (or wrong length) in stage 1 (rhs at the start point)",
                         t, h_or, t, h);
    memcpy(y, x, sizeof yn);
    if (m->fixed_substeps) {
        int n_sub = m->fixed_substeps;
        double hs = h / n_sub;
        for (int i = 0; i < n_sub; i++) {
            double ti = t + i * hs;
            int bad = trial_dp5(m, y, k1, hs, u, yn, kn, &err);
            stats->rhs_calls += 6;
            if (bad) return step_fail(msg, len, "non-finite value in a stage or the result", ti, hs, t, h);
            memcpy(y, yn, sizeof yn);
            memcpy(k1, kn, sizeof kn);
        }
        stats->substeps = n_sub;
    } else {
        double hs = mem->has_h_prop ? mem->h_prop : starting_step(m, x, k1, u, h, stats);
        double tau = 0.0;
        int attempts = 0, just_rejected = 0;
        /* kink landing (prsm_step.h) with the model's laws */
        int kinks = m->ros.slip != NULL;
        prsm_landing landing;
        prsm_landing_init(&landing, &m->ros, m, m->h_min);
        for (;;) {
            double rem = h - tau;
            /* a step cut to end on a kink has exactly the cut size, never stretched to t + h */
            int last = !landing.cuts && hs * 1.05 >= rem;
            double h_step = last ? rem : hs;
            attempts += 1;
            if (attempts > m->max_substeps) {
                char what[128];
                snprintf(what, sizeof what, "more than max_substeps = %d internal steps (accepted + rejected)",
                         m->max_substeps);
                return step_fail(msg, len, what, t + tau, h_step, t, h);
            }
            double ti = t + tau;
            int bad = trial_dp5(m, y, k1, h_step, u, yn, kn, &err);
            stats->rhs_calls += 6;
            if (bad) err = INFINITY;
            double h_cut;
            if (kinks && !bad && prsm_landing_cut(&landing, y, yn, h_step, stats, &h_cut)) {
                hs = h_cut;     /* it would cross a kink of the friction law: ends on it */
                continue;
            }
            if (err <= 1.0) {
                stats->substeps += 1;
                double fac = err_factor(m, err);
                if (just_rejected && fac > 1.0) fac = 1.0;
                double h_new = h_step * fac;
                if (kinks) h_new = prsm_landing_accepted(&landing, h_new, fac);
                memcpy(y, yn, sizeof yn);
                memcpy(k1, kn, sizeof kn);
                just_rejected = 0;
                if (last) {
                    if (h_new >= h_step) h_new = pmax(h_new, hs);
                    mem->has_h_prop = 1;
                    mem->h_prop = h_new;
                    break;
                }
                tau += h_step;
                hs = h_new;
            } else {
                stats->rejected += 1;
                just_rejected = 1;
                if (kinks) prsm_landing_rejected(&landing);
                hs = h_step * err_factor(m, err);
                if (hs < m->h_min) {
                    char what[160];
                    if (bad) snprintf(what, sizeof what, "step size %.17g s below h_min = %.17g s after rejection (non-finite value in a stage)", hs, m->h_min);
                    else snprintf(what, sizeof what, "step size %.17g s below h_min = %.17g s after rejection (error norm %.3g > 1)", hs, m->h_min, err);
                    return step_fail(msg, len, what, ti, h_step, t, h);
                }
            }
        }
    }
    mem->has_fsal = 1;
    mem->fsal_t = t + h;
    memcpy(mem->fsal_x, y, sizeof mem->fsal_x);
    mem->fsal_u[0] = u[0];
    mem->fsal_u[1] = u[1];
    memcpy(mem->fsal_f, k1, sizeof mem->fsal_f);
    return 0;
}

/* ClosedForm.advance (or ExplicitAdaptive alone); memory changes only on success */
int prsm_advance(prsm_model *m, prsm_memory *mem, double t, const double x[PRSM_NX_MAX],
                 const double u[2], double h, double x_new[PRSM_NX_MAX], prsm_stats *stats,
                 char *msg, int len) {
    stats->rhs_calls = 0;
    stats->substeps = 0;
    stats->rejected = 0;
    if (m->dynamic) {
        prsm_memory trial = *mem;
        double y[PRSM_NX_MAX] = {0.0};
        if (prsm_ros_advance(&m->ros, rhs_ctx, m, &trial, t, x, u, h, y, stats, msg, len))
            return -1;
        *mem = trial;
        memcpy(x_new, y, sizeof y);
        return 0;
    }
    if (m->closed_form && closed_form_advance(m, x, u, h, x_new)) {
        if (!finite_sum(x_new, PRSM_NX))
            return fail(msg, len, "closed_form: non-finite value in the closed-form step");
        stats->rhs_calls = 1;
        stats->substeps = 1;
        return 0;
    }
    if (m->closed_form && m->band_exponential) {
        prsm_memory trial = *mem;
        double y[PRSM_NX_MAX] = {0.0};
        if (prsm_band_advance(&m->band, rhs_ctx, exact_ctx, m, &trial, t, x, u, h, y, stats, msg,
                              len))
            return -1;
        *mem = trial;
        memcpy(x_new, y, sizeof y);
        return 0;
    }
    prsm_memory trial = *mem;
    double y[PRSM_NX];
    if (explicit_advance(m, &trial, t, x, u, h, y, stats, msg, len)) return -1;
    *mem = trial;
    memcpy(x_new, y, sizeof y);
    for (int i = PRSM_NX; i < PRSM_NX_MAX; i++) x_new[i] = 0.0;
    return 0;
}
