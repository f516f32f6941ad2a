/* fidelity = "auto" in C (see prsm_auto.h for what it mirrors). */
#include <math.h>
#include <string.h>

#include "prsm_auto.h"
#include "prsm_quantity.h"

#define NS PRSM_N_STAGES

/* ---- models/auto.py: carrier_time_constants ------------------------------------------------ */
/* Each carrier's linearised time constant [s] at screw speed omega [rad/s] and load [N], the
 * carriers at their equilibrium: a central difference of the dynamic level's right-hand side
 * under the speed drive (m), inf where the carrier is not driven. */
static void time_constants(const prsm_model *m, double omega, double load, double *taus) {
    double u[2] = {0.0, load};
    double x[PRSM_NX_MAX];
    prsm_initial_state(m, x, 0.0, omega, 1);
    double v_eps = m->v_eps;
    for (int k = 0; k < NS; k++) {
        int i = 2 + k;
        const prsm_flank *fl = &m->fl[k][0];
        /* a thousandth of the carrier speed change that moves the slip across the friction band
         * (auto.py computes |b| with the same IEEE operations) */
        double b = sqrt(fl->bx * fl->bx + fl->by * fl->by);
        double dw = pmax(1e-3 * v_eps / b, 1e-9 * pmax(fabs(x[i]), 1.0));
        double xp[PRSM_NX_MAX], xm[PRSM_NX_MAX], fp[PRSM_NX_MAX], fm[PRSM_NX_MAX];
        memcpy(xp, x, sizeof xp);
        memcpy(xm, x, sizeof xm);
        xp[i] += dw;
        xm[i] -= dw;
        prsm_rhs(m, xp, u, fp);
        prsm_rhs(m, xm, u, fm);
        double rate = -(fp[i] - fm[i]) / (2.0 * dw);
        taus[k] = rate > 0.0 ? 1.0 / rate : INFINITY;
    }
}

/* a model of cfg's mechanism at the dynamic (dynamic = 1) or quasi-static level and the given
 * drive (speed = 1), allocated; NULL with the reason in msg */
static prsm_model *new_model(const prsm_config *cfg, int dynamic, int speed, char *msg, int len) {
    prsm_config c = *cfg;
    c.kinematic = 0;
    c.dynamic = dynamic;
    c.speed_drive = speed;
    c.closed_form = 1;
    c.band_exponential = 1;
    prsm_model *m = (prsm_model *)malloc(sizeof *m);
    if (!m) {
        snprintf(msg, (size_t)len, "out of memory");
        return NULL;
    }
    if (prsm_model_init(m, &c, msg, len)) {
        free(m);
        return NULL;
    }
    return m;
}

/* ---- models/adaptive.py: AdaptiveModel --------------------------------------------------- */
void prsm_auto_set_tolerances(prsm_auto *a, double rtol, double atol) {
    prsm_model *d = &a->dyn, *q = &a->qs;
    d->rtol = d->band.rtol = rtol;
    d->atol = d->band.atol = atol;
    d->ros.rtol = d->ros.fixed_substeps ? rtol : rtol * PRSM_ROS_TOLERANCE_FACTOR;
    d->ros.atol = d->ros.fixed_substeps ? atol : atol * PRSM_ROS_TOLERANCE_FACTOR;
    /* SwitchingStepper: the quasi-static closed form gets the dynamic stepper's rtol and atol */
    q->rtol = q->band.rtol = d->ros.rtol;
    q->atol = q->band.atol = d->ros.atol;
}

/* -1 with the message if the tolerance is not a finite number > 0, else 0 */
static int bad_tolerance(double tolerance, char *msg, int len) {
    if (isfinite(tolerance) && tolerance > 0.0) return 0;
    char v[40];
    prsm_fmt_num(v, sizeof v, tolerance);
    snprintf(msg, (size_t)len, "tolerance = %s is out of range: must be a finite number > 0", v);
    return -1;
}

int prsm_auto_init(prsm_auto *a, const prsm_config *cfg, double tolerance, int start, char *msg,
                   int len) {
    memset(a, 0, sizeof *a);
    if (bad_tolerance(tolerance, msg, len)) return -1;
    if (start != PRSM_AUTO_DYNAMIC && start != PRSM_AUTO_QUASI_STATIC) {
        snprintf(msg, (size_t)len, "start = %d is not allowed: must be 0 (dynamic) or 1 "
                 "(quasi-static)", start);
        return -1;
    }
    prsm_config c = *cfg;
    c.kinematic = 0;
    c.dynamic = 1;
    if (prsm_model_init(&a->dyn, &c, msg, len)) return -1;
    /* the quasi-static level: the closed form, the exponential band step (ClosedForm's default),
     * adaptive (SwitchingStepper does not pass fixed_substeps on to it) */
    c.dynamic = 0;
    c.closed_form = 1;
    c.band_exponential = 1;
    c.substeps = 0;
    if (prsm_model_init(&a->qs, &c, msg, len)) return -1;
    a->tolerance = tolerance;
    a->start = start;
    prsm_auto_set_tolerances(a, a->dyn.rtol, a->dyn.atol);
    /* effective_load(params, 0, 1): m c_out alpha of the last nut with alpha = 1 */
    a->nut_term = 0.0 + cfg->stage[NS - 1].nut_mass * a->dyn.c_out * 1.0;
    /* 2 x the quasi-static kinetic energy at 1 rad/s */
    {
        double x[PRSM_NX_MAX] = {0.0}, u[2] = {1.0, 0.0};
        prsm_outputs y;
        x[1] = 1.0;
        prsm_outputs_at(&a->qs, x, u, &y);
        a->slaved_inertia = 2.0 * y.kinetic_energy;
    }
    /* lag_coefficients: the time constants of the dynamic level under the speed drive at
     * 100 rad/s and +-1000 N (outside the friction band tau is proportional to |omega|/|F|) */
    {
        prsm_model *spd = new_model(cfg, 1, 1, msg, len);
        if (!spd) return -1;
        for (int forward = 0; forward < 2; forward++) {
            double omega = 100.0, load = forward ? 1000.0 : -1000.0, taus[NS];
            time_constants(spd, omega, load, taus);
            for (int k = 0; k < NS; k++) a->coef[forward][k] = taus[k] * fabs(load) / omega;
        }
        free(spd);
    }
    return 0;
}

/* AdaptiveModel.advance_lag: each carrier's lag after a step h [s] at screw acceleration alpha
 * [rad/s2], mean screw speed omega [rad/s] and load [N] */
static void advance_lag(const prsm_auto *a, const double *d, double alpha, double omega,
                        double load, double h, double *out) {
    int any = 0;
    for (int k = 0; k < NS; k++)
        if (d[k] != 0.0) any = 1;             /* Python's any(d): NaN counts */
    if (alpha == 0.0 && !any) {
        memcpy(out, d, sizeof(double) * NS);
        return;
    }
    double f_eff = load + a->nut_term * alpha;
    if (omega == 0.0) {
        for (int k = 0; k < NS; k++) out[k] = 0.0;
        return;
    }
    if (f_eff == 0.0) {
        for (int k = 0; k < NS; k++) out[k] = d[k] - alpha * h;
        return;
    }
    const double *coef = a->coef[omega * f_eff > 0.0];
    double ratio = fabs(omega) / fabs(f_eff);
    for (int k = 0; k < NS; k++) {
        double tau = coef[k] * ratio;
        if (!isfinite(tau)) {
            out[k] = d[k] - alpha * h;
        } else if (tau == 0.0) {
            out[k] = 0.0;
        } else {
            double e = exp(-h / tau);
            out[k] = d[k] * e - alpha * tau * (1.0 - e);
        }
    }
}

/* AdaptiveModel.deviation: largest |omega_Pk - zeta_k omega| / (|zeta_k| omega_max) */
static double deviation(const prsm_auto *a, const double *x, double omega_scale) {
    double omega = x[1], dev = 0.0;
    for (int k = 0; k < NS; k++) {
        double z = a->qs.st[k].zeta;
        double diff = fabs(x[2 + k] - z * omega);
        if (diff == 0.0) continue;
        double scale = fabs(z) * omega_scale;
        if (scale == 0.0) return INFINITY;
        dev = pmax(dev, diff / scale);
    }
    return dev;
}

/* the quasi-static layout of a dynamic state (AdaptiveModel.reduced) */
static void reduced(const double *x, double *xr) {
    double v[PRSM_NX_MAX] = {0.0};
    v[0] = x[0];
    v[1] = x[1];
    for (int i = 0; i < 3; i++) v[2 + i] = x[2 + NS + i];
    memcpy(xr, v, sizeof v);
}

/* the dynamic layout of a quasi-static state, carriers at zeta* omega (AdaptiveModel.expanded) */
static void expanded(const prsm_auto *a, const double *xr, double omega, double *x) {
    double v[PRSM_NX_MAX];
    v[0] = xr[0];
    v[1] = xr[1];
    for (int k = 0; k < NS; k++) v[2 + k] = a->qs.st[k].zeta * omega;
    for (int i = 0; i < 3; i++) v[2 + NS + i] = xr[2 + i];
    memcpy(x, v, sizeof v);
}

/* one output's change on switching, relative to its scale (AdaptiveModel.switch_error's loop) */
static double relative(double yd, double yq, double s, double err) {
    double diff = fabs(yd - yq);
    if (!(diff > 0.0)) return err;          /* equal, or NaN: the efficiency where no power flows */
    return pmax(err, s > 0.0 ? diff / s : INFINITY);
}

/* AdaptiveModel.switch_error: the largest change of an output on switching to the quasi-static
 * level at x, each relative to the scale of its kind */
static double switch_error(prsm_auto *a, const double *x, const double *u, double omega_scale) {
    prsm_outputs od, oq;
    double xr[PRSM_NX_MAX];
    prsm_outputs_at(&a->dyn, x, u, &od);
    reduced(x, xr);
    prsm_outputs_at(&a->qs, xr, u, &oq);
    const prsm_model *d = &a->dyn, *q = &a->qs;
#define YD(Q, K) prsm_quantity(d, x, u, &od, Q, K)
#define YQ(Q, K) prsm_quantity(q, xr, u, &oq, Q, K)
    double force = fabs(YD(Q_LOAD_FORCE, 0)), torque = fabs(YD(Q_SCREW_TORQUE, 0));
    for (int k = 0; k < NS; k++) {
        force = pmax(force, fabs(YD(Q_CONTACT_FORCE, k)));
        force = pmax(force, fabs(YD(Q_NORMAL_FORCE, k)));
        torque = pmax(torque, fabs(YD(Q_DRIVEN_TORQUE, k)));
    }
    double power = pmax(pmax(fabs(YD(Q_INPUT_POWER, 0)), fabs(YD(Q_OUTPUT_POWER, 0))),
                        fabs(YD(Q_FRICTION_POWER, 0)));
    double energy = pmax(fabs(YD(Q_KINETIC_ENERGY, 0)), fabs(YQ(Q_KINETIC_ENERGY, 0)));
    double acceleration = torque / a->slaved_inertia;
    double err = 0.0;
    err = relative(YD(Q_SCREW_ACCELERATION, 0), YQ(Q_SCREW_ACCELERATION, 0), acceleration, err);
    err = relative(YD(Q_SCREW_TORQUE, 0), YQ(Q_SCREW_TORQUE, 0), torque, err);
    for (int k = 0; k < NS; k++) {
        double z = fabs(q->st[k].zeta);
        err = relative(YD(Q_CONTACT_FORCE, k), YQ(Q_CONTACT_FORCE, k), force, err);
        err = relative(YD(Q_NORMAL_FORCE, k), YQ(Q_NORMAL_FORCE, k), force, err);
        err = relative(YD(Q_DRIVEN_TORQUE, k), YQ(Q_DRIVEN_TORQUE, k), torque, err);
        err = relative(YD(Q_SPLINE_FRICTION, k), YQ(Q_SPLINE_FRICTION, k), force, err);
        err = relative(YD(Q_CARRIER_SPEED, k), YQ(Q_CARRIER_SPEED, k), z * omega_scale, err);
        err = relative(YD(Q_CARRIER_SPEED_RATIO, k), YQ(Q_CARRIER_SPEED_RATIO, k), z, err);
    }
    err = relative(YD(Q_EFFICIENCY, 0), YQ(Q_EFFICIENCY, 0), 1.0, err);
    err = relative(YD(Q_FRICTION_POWER, 0), YQ(Q_FRICTION_POWER, 0), power, err);
    err = relative(YD(Q_INPUT_POWER, 0), YQ(Q_INPUT_POWER, 0), power, err);
    err = relative(YD(Q_OUTPUT_POWER, 0), YQ(Q_OUTPUT_POWER, 0), power, err);
    err = relative(YD(Q_KINETIC_ENERGY, 0), YQ(Q_KINETIC_ENERGY, 0), energy, err);
#undef YD
#undef YQ
    return err;
}

const prsm_model *prsm_auto_outputs_at(prsm_auto *a, int mode, const double x[PRSM_NX_MAX],
                                       const double u[2], double x_level[PRSM_NX_MAX],
                                       prsm_outputs *y) {
    if (mode == PRSM_AUTO_QUASI_STATIC) {
        reduced(x, x_level);
        prsm_outputs_at(&a->qs, x_level, u, y);
        return &a->qs;
    }
    memcpy(x_level, x, sizeof(double) * PRSM_NX_MAX);
    prsm_outputs_at(&a->dyn, x_level, u, y);
    return &a->dyn;
}

/* ---- models/adaptive.py: SwitchingStepper -------------------------------------------------- */
void prsm_auto_reset(const prsm_auto *a, prsm_auto_memory *mem) {
    memset(mem, 0, sizeof *mem);
    mem->mode = a->start;
    mem->backoff = 1;
    mem->gain = 1.0;
}

static void add_stats(prsm_stats *a, const prsm_stats *b) {
    a->rhs_calls += b->rhs_calls;
    a->substeps += b->substeps;
    a->rejected += b->rejected;
}

/* SwitchingStepper._advance on a copy of the memory */
static int step(prsm_auto *a, prsm_auto_memory *mem, double t, const double *x, const double *u,
                double h, double *x_new, prsm_stats *stats, char *msg, int len) {
    double w0 = x[1];
    double scale = pmax(mem->omega_scale, fabs(w0));
    if (mem->mode == PRSM_AUTO_QUASI_STATIC) {
        /* the lag at the step's start: the carried estimate plus the stored carriers' offset
         * from the equilibrium of this step's speed (a prescribed speed that jumped) */
        double d0[NS], d1[NS];
        memcpy(d0, mem->lag, sizeof d0);
        for (int k = 0; k < NS; k++) {
            double z = a->qs.st[k].zeta;
            if (z != 0.0) d0[k] += x[2 + k] / z - w0;
        }
        double xr[PRSM_NX_MAX], yr[PRSM_NX_MAX];
        reduced(x, xr);
        if (prsm_advance(&a->qs, &mem->qs, t, xr, u, h, yr, stats, msg, len)) return -1;
        double w1 = yr[1];
        advance_lag(a, d0, (w1 - w0) / h, 0.5 * (w0 + w1), u[1], h, d1);
        if (fabs(w1) > scale) scale = fabs(w1);
        double worst = 0.0;
        for (int k = 0; k < NS; k++)
            if (fabs(d1[k]) > worst) worst = fabs(d1[k]);
        if (PRSM_AUTO_MARGIN * worst <= a->tolerance * scale) {
            memcpy(mem->lag, d1, sizeof d1);
            mem->omega_scale = scale;
            expanded(a, yr, w1, x_new);
            return 0;
        }
        /* the carriers trail too far: this step again with the dynamic level, carriers at the
         * estimated lag, from a fresh stepper */
        double xd[PRSM_NX_MAX];
        memcpy(xd, x, sizeof xd);
        for (int k = 0; k < NS; k++) xd[2 + k] = a->qs.st[k].zeta * (w0 + d0[k]);
        prsm_stats st2;
        memset(&mem->dyn, 0, sizeof mem->dyn);
        if (prsm_advance(&a->dyn, &mem->dyn, t, xd, u, h, x_new, &st2, msg, len)) return -1;
        add_stats(stats, &st2);
        mem->mode = PRSM_AUTO_DYNAMIC;
        mem->switches += 1;
        mem->wait = 0;
        mem->backoff = 1;
        mem->omega_scale = pmax(scale, fabs(x_new[1]));
        return 0;
    }
    if (prsm_advance(&a->dyn, &mem->dyn, t, x, u, h, x_new, stats, msg, len)) return -1;
    scale = pmax(scale, fabs(x_new[1]));
    mem->omega_scale = scale;
    if (mem->wait > 0) {
        mem->wait -= 1;
        return 0;
    }
    double dev = deviation(a, x_new, scale);
    if (2.0 * PRSM_AUTO_MARGIN * dev * mem->gain <= a->tolerance) {
        double err = switch_error(a, x_new, u, scale);
        if (2.0 * PRSM_AUTO_MARGIN * err <= a->tolerance) {
            mem->mode = PRSM_AUTO_QUASI_STATIC;
            for (int k = 0; k < NS; k++) mem->lag[k] = 0.0;
            mem->switches += 1;
            mem->gain = 1.0;
            memset(&mem->qs, 0, sizeof mem->qs);
        } else if (dev > 0.0 && err / dev > mem->gain) {
            /* the outputs move more than the carriers: wait until the deviation times this
             * gain is within the limit */
            mem->gain = err / dev;
        } else {
            mem->wait = mem->backoff;
            mem->backoff = 2 * mem->backoff < PRSM_AUTO_MAX_WAIT ? 2 * mem->backoff
                                                                 : PRSM_AUTO_MAX_WAIT;
        }
    }
    return 0;
}

int prsm_auto_advance(prsm_auto *a, prsm_auto_memory *mem, double t, const double x[PRSM_NX_MAX],
                      const double u[2], double h, double x_new[PRSM_NX_MAX], prsm_stats *stats,
                      char *msg, int len) {
    prsm_auto_memory trial = *mem;
    double y[PRSM_NX_MAX] = {0.0};
    stats->rhs_calls = stats->substeps = stats->rejected = 0;
    if (step(a, &trial, t, x, u, h, y, stats, msg, len)) return -1;
    trial.alpha = (y[1] - x[1]) / h;
    *mem = trial;
    memcpy(x_new, y, sizeof y);
    return 0;
}

/* ---- models/auto.py: choose_for_start (torque drive, no communication step) ----------------- */
/* Python's max(v[0], v[1], ...): the first of the largest */
static double first_max(const double *v, int n) {
    double m = v[0];
    for (int i = 1; i < n; i++) m = pmax(m, v[i]);
    return m;
}

int prsm_auto_choose(const prsm_config *cfg, double tolerance, const double inputs[2],
                     double screw_speed, int carriers_at_rest, double kinematic_efficiency,
                     double errors[2], char *msg, int len) {
    if (bad_tolerance(tolerance, msg, len)) return -1;
    prsm_model *qs = new_model(cfg, 0, 0, msg, len);
    prsm_model *qs_speed = qs ? new_model(cfg, 0, 1, msg, len) : NULL;
    prsm_model *spd = qs_speed ? new_model(cfg, 1, 1, msg, len) : NULL;
    if (!spd) {
        free(qs);
        free(qs_speed);
        return -1;
    }
    double load = inputs[1], omega = screw_speed, eff = kinematic_efficiency;
    /* the quasi-static level's acceleration under the start inputs */
    double x[PRSM_NX_MAX] = {0.0}, u[2] = {inputs[0], load};
    prsm_outputs y;
    x[1] = omega;
    prsm_outputs_at(qs, x, u, &y);
    double alpha = y.alpha;
    double per_stage[NS];
    double deviation = 0.0;
    if (omega != 0.0 && carriers_at_rest) {
        for (int k = 0; k < NS; k++) per_stage[k] = fabs(0.0 / qs->st[k].zeta - 1.0);
        deviation = first_max(per_stage, NS);
    }
    /* estimate_errors */
    double taus[NS];
    double nut_term = 0.0 + cfg->stage[NS - 1].nut_mass * qs->c_out * 1.0;
    time_constants(spd, omega, load + nut_term * alpha, taus);
    double tau = first_max(taus, NS);
    double h = 0.0;
    double jump = 0.0 * (isfinite(tau) && tau > 0.0 ? exp(-h / tau) : 1.0);
    double lag;
    if (alpha == 0.0) lag = 0.0;
    else if (omega == 0.0 || !isfinite(tau)) lag = INFINITY;
    else lag = fabs(alpha) * tau / fabs(omega);
    double e_qs = pmax(pmax(deviation, jump), lag);
    /* steady_efficiency and friction_output_gap: the quasi-static level in steady forward
     * motion outside the friction band */
    double xs[PRSM_NX_MAX] = {0.0}, us[2] = {0.0, PRSM_AUTO_EFFICIENCY_LOAD};
    xs[1] = PRSM_AUTO_EFFICIENCY_SPEED;
    prsm_outputs_at(qs_speed, xs, us, &y);
    double eta = y.efficiency;
    double loss = fabs(eta / eff - 1.0);
    for (int k = 0; k < NS; k++)
        per_stage[k] = fabs(cfg->stage[k].screw_radius
                            / (cfg->stage[k].screw_radius + cfg->stage[k].nut_radius)
                            / qs->st[k].zeta_geometric - 1.0);
    double ratio = first_max(per_stage, NS);
    int spline = 0;
    for (int k = 0; k < NS; k++)
        if (y.spline_friction[k] != 0.0) spline = 1;
    double power = eta < 1.0 ? fabs(eta - eff) / (1.0 - eta) : 0.0;
    double gap = pmax(spline ? 1.0 : 0.0, power);
    double e_kin = pmax(pmax(pmax(e_qs, loss), ratio), gap);
    free(qs);
    free(qs_speed);
    free(spd);
    errors[0] = e_kin;
    errors[1] = e_qs;
    /* _pick: the cheapest level with MARGIN x estimated error <= tolerance */
    if (PRSM_AUTO_MARGIN * e_kin <= tolerance) return 0;
    if (PRSM_AUTO_MARGIN * e_qs <= tolerance) return 1;
    return 2;
}
