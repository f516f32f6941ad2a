/* The actuator loop's step loop in C: system_models.master.Master._step for the loop of
 * system_models.ema (controller, motor, the PRSM FMU, load), operation for operation.
 *
 * What it is: the fast path of system_models.native_loop.NativeMaster.  Python builds the
 * master (connections, the step plan, the outputs read and recorded, the start values) and the
 * blocks as usual; this file only repeats the macro steps, calling the FMU through its own
 * fmi2SetReal/fmi2DoStep/fmi2GetReal/fmi2GetInteger (the instance fmpy created and
 * initialized).  Every arithmetic operation is the Python code's, in the same order, with
 * IEEE doubles and no contraction (compiled with -ffp-contract=off), so the results are the
 * Python loop's bit for bit (tests/test_native_loop.py).  Python's max(a, b) / min(a, b) keep
 * the first argument unless the second is strictly larger / smaller: written out below.
 *
 * What it leaves to Python: any step that a block refuses.  Then the Python blocks' states are
 * put back to the step's start (the FMU's is unchanged by a refused doStep) and the call
 * returns; the Python master takes that step (its retry or its error message).  A failing FMU
 * call (status above fmi2Discard) is returned as it is.
 *
 * The references and the external force, Python callables, come as arrays evaluated by Python
 * at the instants where the Python blocks would evaluate them.
 */
#define _POSIX_C_SOURCE 199309L  /* clock_gettime under -std=c99 */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define NB 4          /* blocks */
#define MAXP 16       /* ports per block (inputs or selected outputs) */
#define MAXOUT 64     /* outputs per block the master holds */

enum { K_CONTROLLER = 0, K_MOTOR = 1, K_FMU = 2, K_LOAD = 3 };
enum { MODE_POSITION = 0, MODE_SPEED = 1, MODE_CURRENT = 2 };
/* return codes of ema_loop_run */
enum { RUN_DONE = 0, RUN_REFUSED = 1, RUN_FMU_ERROR = 2, RUN_PROFILE_END = 3 };

typedef int (*set_real_fn)(void *, const unsigned int *, size_t, const double *);
typedef int (*get_real_fn)(void *, const unsigned int *, size_t, double *);
typedef int (*get_int_fn)(void *, const unsigned int *, size_t, int *);
typedef int (*do_step_fn)(void *, double, double, int);

typedef struct {
    /* parameters */
    double ts, kp_c, ki_c, kp_s, ki_s, kp_x, ki_x, vff, i_lim, v_lim, w_lim;
    double kaw_x, kaw_s, kaw_c, pole_pairs, ell, psi, c, t0;
    int speed_div, position_div, decoupling, mode;
    const double *ref, *ref_plus, *ref_minus;   /* reference(t_j), reference(t_j ± t_p) */
    long n_ref;
    /* state */
    long j;
    double cmd[6], integ[4];
} controller_t;

typedef struct {
    double r, ell, p, psi, kt, max_substep, vmax, trip;
    double x[5];
} motor_t;

typedef struct {
    void *comp;
    set_real_fn set_real;
    get_real_fn get_real;
    get_int_fn get_int;
    do_step_fn do_step;
    unsigned int vr_in[MAXP], vr_real[MAXOUT], vr_int[MAXOUT];
    int n_real, n_int, order[MAXOUT], has_order;
    double buf[MAXP];
} fmu_t;

typedef struct {
    double preload, k, d;
    const double *ext;          /* F_ext at the end of macro step k: ext[k] */
    long n_ext;
    double t, fe;               /* the load's time and F_ext(t) */
} load_t;

typedef struct {
    int kind, n_in, n_out, interpolates, feedthrough, read_after;
    int pk[MAXP], ps[MAXP], pp[MAXP], pd[MAXP];   /* the master's plan per input */
    double pc[MAXP];                              /* constant inputs */
    double u[MAXP], du[MAXP];                     /* Python blocks' inputs */
} block_t;

typedef struct {
    int gs, extrapolation;
    double t0, h;
    block_t b[NB];
    controller_t ctl;
    motor_t mot;
    fmu_t fmu;
    load_t load;
    /* master state */
    double y[NB][MAXOUT], y_prev[NB][MAXOUT], y_new[NB][MAXOUT], scale[NB][MAXOUT];
    int has_prev;
    double t_prev;
    int n_watched, watched[2 * NB * MAXOUT];
    int n_record, record[2 * NB * MAXOUT];
    /* what stopped a run */
    int stop_status, stop_call;
} loop_t;

/* Python's max(a, b) and min(a, b) for two floats: the first unless the second is larger /
 * smaller */
static double py_max(double a, double b) { return b > a ? b : a; }
static double py_min(double a, double b) { return b < a ? b : a; }

static double now(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

/* ---- controller: CascadeController._sample and do_step --------------------------------------- */
static void controller_sample(controller_t *s, double x, double w, double idd, double iq)
{
    double ts = s->ts;
    long j = s->j;
    double *cmd = s->cmd, *integ = s->integ;
    double ref = s->ref[j];
    cmd[2] = ref;
    if (s->mode == MODE_POSITION && j % s->position_div == 0) {
        double tp = ts * (double)s->position_div;
        double ff = 0.0;
        if (s->vff > 0.0)
            ff = s->vff * (s->ref_plus[j] - s->ref_minus[j]) / (2.0 * tp * s->c);
        double e = ref - x;
        double u = s->kp_x * e + integ[0] + ff;
        double us = py_min(s->w_lim, py_max(-s->w_lim, u));
        if (s->ki_x > 0.0)
            integ[0] += tp * (s->ki_x * e + s->kaw_x * (us - u));
        cmd[3] = us;
    } else if (s->mode == MODE_SPEED) {
        cmd[3] = py_min(s->w_lim, py_max(-s->w_lim, ref));
    }
    if (s->mode != MODE_CURRENT && j % s->speed_div == 0) {
        double e = cmd[3] - w;
        double u = s->kp_s * e + integ[1] + 0.0;
        double us = py_min(s->i_lim, py_max(-s->i_lim, u));
        if (s->ki_s > 0.0)
            integ[1] += (ts * (double)s->speed_div) * (s->ki_s * e + s->kaw_s * (us - u));
        cmd[4] = us;
    } else if (s->mode == MODE_CURRENT) {
        cmd[4] = py_min(s->i_lim, py_max(-s->i_lim, ref));
    }
    double we = s->pole_pairs * w;
    double ffd = 0.0, ffq = 0.0;
    if (s->decoupling) {
        ffd = -we * s->ell * iq;
        ffq = we * (s->ell * idd + s->psi);
    }
    double vmax = s->v_lim;
    double kp = s->kp_c, ki = s->ki_c, kaw = s->kaw_c;
    double ed = 0.0 - idd;
    double vd_u = kp * ed + integ[2] + ffd;
    double vd = py_min(vmax, py_max(-vmax, vd_u));
    double vq_lim = sqrt(py_max(0.0, vmax * vmax - vd * vd));
    double eq = cmd[4] - iq;
    double vq_u = kp * eq + integ[3] + ffq;
    double vq = py_min(vq_lim, py_max(-vq_lim, vq_u));
    if (ki > 0.0) {
        integ[2] += ts * (ki * ed + kaw * (vd - vd_u));
        integ[3] += ts * (ki * eq + kaw * (vq - vq_u));
    }
    cmd[0] = vd;
    cmd[1] = vq;
    cmd[5] += 1.0;
    s->j = j + 1;
}

/* 0: stepped; 1: refused (the Python block refuses too: the caller hands the step back);
 * RUN_PROFILE_END: a sample beyond the references given */
static int controller_step(controller_t *s, const double *u, const double *du, double t, double h)
{
    double ts = s->ts;
    double eps = 1e-9 * py_min(h, ts);
    for (int k = 0; k < 4; k++)
        if (!isfinite(u[k]) || !isfinite(du[k]))
            return 1;
    double t_end = t + h - eps;
    double tj = s->t0 + (double)s->j * ts;
    if (tj < t - eps && tj < t_end)
        return 1;
    while (tj < t_end) {
        if (s->j >= s->n_ref)
            return RUN_PROFILE_END;
        double dt = tj - t;
        controller_sample(s, u[0] + du[0] * dt, u[1] + du[1] * dt, u[2] + du[2] * dt,
                          u[3] + du[3] * dt);
        tj = s->t0 + (double)s->j * ts;
    }
    return 0;
}

/* ---- motor: Motor._applied, do_step (RK4) and get_outputs --------------------------------- */
static void motor_applied(const motor_t *m, const double *u, double *vd, double *vq)
{
    double mag = sqrt(u[0] * u[0] + u[1] * u[1]);
    if (mag > m->vmax) {
        double s = m->vmax / mag;
        *vd = u[0] * s;
        *vq = u[1] * s;
    } else {
        *vd = u[0];
        *vq = u[1];
    }
}

/* One RK4 stage (Motor._rk4's, term by term): the current derivatives d, q and the power rates
 * (electrical pe, copper pc, air gap pa) at the currents (a0, a1) and the speed w */
typedef struct { double d, q, pe, pc, pa; } rates_t;

static rates_t motor_rates(const motor_t *m, double vd, double vq, double a0, double a1, double w)
{
    double r = m->r, ell = m->ell;
    double we = m->p * w, wl = we * ell;
    rates_t k;
    k.d = (vd - r * a0 + wl * a1) / ell;
    k.q = (vq - r * a1 - wl * a0 - we * m->psi) / ell;
    k.pe = 1.5 * (vd * a0 + vq * a1);
    k.pc = (1.5 * r) * (a0 * a0 + a1 * a1);
    k.pa = m->kt * a1 * w;
    return k;
}

static void motor_rk4(const motor_t *m, double *x, double vd, double vq, double w0, double dw,
                      double h)
{
    double nf = ceil(h / m->max_substep - 1e-9);
    long n = nf > 1.0 ? (long)nf : 1;
    double dt = h / (double)n;
    double hdt = 0.5 * dt;
    double dt6 = dt / 6.0;
    double i0 = x[0], i1 = x[1], e_el = x[2], e_cu = x[3], e_ag = x[4];
    for (long j = 0; j < n; j++) {
        double tau = (double)j * dt;
        double wa = w0 + dw * tau, wm = w0 + dw * (tau + 0.5 * dt), wb = w0 + dw * (tau + dt);
        rates_t k1 = motor_rates(m, vd, vq, i0, i1, wa);
        rates_t k2 = motor_rates(m, vd, vq, i0 + hdt * k1.d, i1 + hdt * k1.q, wm);
        rates_t k3 = motor_rates(m, vd, vq, i0 + hdt * k2.d, i1 + hdt * k2.q, wm);
        rates_t k4 = motor_rates(m, vd, vq, i0 + dt * k3.d, i1 + dt * k3.q, wb);
        i0 = i0 + dt6 * (k1.d + 2.0 * k2.d + 2.0 * k3.d + k4.d);
        i1 = i1 + dt6 * (k1.q + 2.0 * k2.q + 2.0 * k3.q + k4.q);
        e_el = e_el + dt6 * (k1.pe + 2.0 * k2.pe + 2.0 * k3.pe + k4.pe);
        e_cu = e_cu + dt6 * (k1.pc + 2.0 * k2.pc + 2.0 * k3.pc + k4.pc);
        e_ag = e_ag + dt6 * (k1.pa + 2.0 * k2.pa + 2.0 * k3.pa + k4.pa);
    }
    x[0] = i0; x[1] = i1; x[2] = e_el; x[3] = e_cu; x[4] = e_ag;
}

/* 0: stepped; 1: refused (non-finite input or state, overcurrent) */
static int motor_step(motor_t *m, const double *u, const double *du, double h)
{
    for (int k = 0; k < 3; k++)
        if (!isfinite(u[k]) || !isfinite(du[k]))
            return 1;
    double vd, vq, x[5];
    motor_applied(m, u, &vd, &vq);
    memcpy(x, m->x, sizeof x);
    motor_rk4(m, x, vd, vq, u[2], du[2], h);
    for (int k = 0; k < 5; k++)
        if (!isfinite(x[k]))
            return 1;
    if (sqrt(x[0] * x[0] + x[1] * x[1]) > m->trip)
        return 1;
    memcpy(m->x, x, sizeof x);
    return 0;
}

static void motor_outputs(const motor_t *m, const double *u, double *y)
{
    double idd = m->x[0], iq = m->x[1], vd, vq;
    motor_applied(m, u, &vd, &vq);
    double i2 = idd * idd + iq * iq;
    y[0] = idd; y[1] = iq; y[2] = sqrt(i2); y[3] = m->kt * iq; y[4] = vd; y[5] = vq;
    y[6] = 1.5 * (vd * idd + vq * iq);
    y[7] = 1.5 * m->r * i2;
    y[8] = m->x[2]; y[9] = m->x[3]; y[10] = m->x[4];
    y[11] = 0.75 * m->ell * i2;
}

/* ---- load: SpringDamperLoad.get_outputs ---------------------------------------------------- */
static void load_outputs(const load_t *l, const double *u, double *y)
{
    double x = u[0], v = u[1];
    double fs = l->preload + l->k * x;
    double fd = l->d * v;
    double fe = l->fe;
    y[0] = fs + fd + fe; y[1] = fs; y[2] = fd; y[3] = fe;
    y[4] = 0.5 * l->k * x * x + l->preload * x;
    y[5] = fd * v;
    y[6] = fe * v;
}

/* ---- the FMU through its fmi2 functions (FMUBlock) ----------------------------------------- */
static int fmu_outputs(loop_t *L, double *y)
{
    fmu_t *f = &L->fmu;
    double real[MAXOUT];
    int ints[MAXOUT];
    if (f->n_real) {
        int st = f->get_real(f->comp, f->vr_real, (size_t)f->n_real, real);
        if (st > 1) { L->stop_status = st; L->stop_call = 2; return RUN_FMU_ERROR; }
    }
    if (f->n_int) {
        int st = f->get_int(f->comp, f->vr_int, (size_t)f->n_int, ints);
        if (st > 1) { L->stop_status = st; L->stop_call = 3; return RUN_FMU_ERROR; }
    }
    double merged[MAXOUT];
    for (int k = 0; k < f->n_real; k++) merged[k] = real[k];
    for (int k = 0; k < f->n_int; k++) merged[f->n_real + k] = (double)ints[k];
    int n = f->n_real + f->n_int;
    for (int k = 0; k < n; k++) y[k] = f->has_order ? merged[f->order[k]] : merged[k];
    return RUN_DONE;
}

/* ---- blocks behind one interface ----------------------------------------------------------- */
static void block_outputs_python(loop_t *L, int i, double *y)
{
    block_t *b = &L->b[i];
    switch (b->kind) {
    case K_CONTROLLER: memcpy(y, L->ctl.cmd, sizeof L->ctl.cmd); break;
    case K_MOTOR: motor_outputs(&L->mot, b->u, y); break;
    case K_LOAD: load_outputs(&L->load, b->u, y); break;
    }
}

static int block_outputs(loop_t *L, int i, double *y)
{
    if (L->b[i].kind == K_FMU)
        return fmu_outputs(L, y);
    block_outputs_python(L, i, y);
    return RUN_DONE;
}

/* set the inputs (values; slopes for interpolating blocks) and step; k: the macro step */
static int block_step(loop_t *L, int i, const double *vals, const double *slopes, double t,
                      double h, long k)
{
    block_t *b = &L->b[i];
    int n = b->n_in;
    if (b->kind == K_FMU) {
        fmu_t *f = &L->fmu;
        double half_h = 0.5 * h;
        for (int q = 0; q < n; q++) f->buf[q] = vals[q] + half_h * slopes[q];
        int st = f->set_real(f->comp, f->vr_in, (size_t)n, f->buf);
        if (st > 1) { L->stop_status = st; L->stop_call = 0; return RUN_FMU_ERROR; }
        st = f->do_step(f->comp, t, h, 1);
        if (st == 2) { L->stop_status = st; return RUN_REFUSED; }
        if (st > 1) { L->stop_status = st; L->stop_call = 1; return RUN_FMU_ERROR; }
        return RUN_DONE;
    }
    for (int q = 0; q < n; q++) {     /* held inputs (the load's): value + slope·h/2 */
        b->u[q] = b->interpolates ? vals[q] : vals[q] + 0.5 * h * slopes[q];
        b->du[q] = b->interpolates ? slopes[q] : 0.0;
    }
    switch (b->kind) {
    case K_CONTROLLER: {
        int r = controller_step(&L->ctl, b->u, b->du, t, h);
        return r == 0 ? RUN_DONE : (r == 1 ? RUN_REFUSED : r);
    }
    case K_MOTOR:
        return motor_step(&L->mot, b->u, b->du, h) ? RUN_REFUSED : RUN_DONE;
    case K_LOAD:
        if (k >= L->load.n_ext) return RUN_PROFILE_END;
        L->load.t = t + h;
        L->load.fe = L->load.ext[k];
        return RUN_DONE;
    }
    return RUN_DONE;
}

/* Master._step over [t, t + h] of macro step k; *err: the coupling error estimate */
static int master_step(loop_t *L, double t, double h, long k, double *err, double *timers)
{
    int first = L->extrapolation == 1 && L->has_prev;
    int hold_new = L->extrapolation == 0;
    double dtp = first ? (t - L->t_prev) : 1.0;
    int n_pred = 0, pred_s[NB * MAXP], pred_p[NB * MAXP];
    double pred_v[NB * MAXP];
    for (int i = 0; i < NB; i++) {
        block_t *b = &L->b[i];
        double vals[MAXP], slopes[MAXP];
        for (int q = 0; q < b->n_in; q++) {
            int kind = b->pk[q], s = b->ps[q], p = b->pp[q], discrete = b->pd[q];
            if (kind == 0) {
                vals[q] = b->pc[q];
                slopes[q] = 0.0;
            } else if (kind == 1) {
                if (discrete || hold_new) {
                    vals[q] = L->y_new[s][p];
                    slopes[q] = 0.0;
                } else {
                    double yc = L->y[s][p];
                    vals[q] = yc;
                    slopes[q] = (L->y_new[s][p] - yc) / h;
                }
            } else {
                double yc = L->y[s][p];
                vals[q] = yc;
                if (discrete) {
                    slopes[q] = 0.0;
                    continue;
                }
                double sl = first ? (yc - L->y_prev[s][p]) / dtp : 0.0;
                slopes[q] = sl;
                pred_s[n_pred] = s;
                pred_p[n_pred] = p;
                pred_v[n_pred] = yc + sl * h;
                n_pred++;
            }
        }
        double c0 = now();
        int r = block_step(L, i, vals, slopes, t, h, k);
        if (r != RUN_DONE) return r;
        if (L->gs && b->read_after) {
            r = block_outputs(L, i, L->y_new[i]);
            if (r != RUN_DONE) return r;
        }
        timers[i] += now() - c0;
    }
    if (!L->gs) {
        for (int i = 0; i < NB; i++) {
            double c0 = now();
            int r = block_outputs(L, i, L->y_new[i]);
            if (r != RUN_DONE) return r;
            timers[i] += now() - c0;
        }
    }
    for (int i = 0; i < NB; i++) {
        block_t *b = &L->b[i];
        if (!b->feedthrough) continue;
        double c0 = now();
        /* set_inputs(_values(i, y_new)): the sources' new outputs, no slopes */
        for (int q = 0; q < b->n_in; q++) {
            b->u[q] = b->pk[q] == 0 ? b->pc[q] : L->y_new[b->ps[q]][b->pp[q]];
            b->du[q] = 0.0;
        }
        /* update_outputs(t + h): the load's time (its F_ext is the step's end value) */
        L->load.t = t + h;
        L->load.fe = L->load.ext[k];
        block_outputs_python(L, i, L->y_new[i]);
        timers[i] += now() - c0;
    }
    double e = 0.0;
    for (int m = 0; m < n_pred; m++) {
        int s = pred_s[m], p = pred_p[m];
        double yn = L->y_new[s][p];
        double ref = py_max(L->scale[s][p], fabs(yn));
        e = py_max(e, fabs(yn - pred_v[m]) / ref);
    }
    for (int m = 0; m < L->n_watched; m++) {
        int s = L->watched[2 * m], p = L->watched[2 * m + 1];
        double v = fabs(L->y_new[s][p]);
        if (v > L->scale[s][p]) L->scale[s][p] = v;
    }
    memcpy(L->y_prev, L->y, sizeof L->y);
    memcpy(L->y, L->y_new, sizeof L->y);
    L->t_prev = t;
    L->has_prev = 1;
    *err = e;
    return RUN_DONE;
}

/* ---- the interface (doubles, ints and addresses only) -------------------------------------- */
void *ema_loop_new(void) { return calloc(1, sizeof(loop_t)); }
void ema_loop_free(void *p) { free(p); }

/* ints: gs, extrapolation, then per block: kind, n_in, n_out, interpolates, feedthrough,
 * read_after, and per input: plan kind, source block, source port, discrete; then n_watched and
 * the (block, port) pairs, n_record and the (block, port) pairs.
 * reals: t0, h, then per block its inputs' constants (n_in values). */
int ema_loop_set_plan(void *p, const int *ints, const double *reals)
{
    loop_t *L = p;
    int a = 0, r = 0;
    L->gs = ints[a++];
    L->extrapolation = ints[a++];
    L->t0 = reals[r++];
    L->h = reals[r++];
    for (int i = 0; i < NB; i++) {
        block_t *b = &L->b[i];
        b->kind = ints[a++]; b->n_in = ints[a++]; b->n_out = ints[a++];
        b->interpolates = ints[a++]; b->feedthrough = ints[a++]; b->read_after = ints[a++];
        if (b->n_in > MAXP || b->n_out > MAXOUT) return -1;
        for (int q = 0; q < b->n_in; q++) {
            b->pk[q] = ints[a++]; b->ps[q] = ints[a++]; b->pp[q] = ints[a++]; b->pd[q] = ints[a++];
            b->pc[q] = reals[r++];
        }
    }
    L->n_watched = ints[a++];
    for (int m = 0; m < 2 * L->n_watched; m++) L->watched[m] = ints[a++];
    L->n_record = ints[a++];
    for (int m = 0; m < 2 * L->n_record; m++) L->record[m] = ints[a++];
    return a;
}

/* reals: ts, kp_c, ki_c, kp_s, ki_s, kp_x, ki_x, vff, i_lim, v_lim, w_lim, kaw_x, kaw_s, kaw_c,
 * pole_pairs, ell, psi, c, t0; ints: speed_div, position_div, decoupling, mode */
void ema_loop_set_controller(void *p, const double *re, const int *in, const double *ref,
                             const double *ref_plus, const double *ref_minus, long n_ref)
{
    controller_t *s = &((loop_t *)p)->ctl;
    s->ts = re[0]; s->kp_c = re[1]; s->ki_c = re[2]; s->kp_s = re[3]; s->ki_s = re[4];
    s->kp_x = re[5]; s->ki_x = re[6]; s->vff = re[7]; s->i_lim = re[8]; s->v_lim = re[9];
    s->w_lim = re[10]; s->kaw_x = re[11]; s->kaw_s = re[12]; s->kaw_c = re[13];
    s->pole_pairs = re[14]; s->ell = re[15]; s->psi = re[16]; s->c = re[17]; s->t0 = re[18];
    s->speed_div = in[0]; s->position_div = in[1]; s->decoupling = in[2]; s->mode = in[3];
    s->ref = ref; s->ref_plus = ref_plus; s->ref_minus = ref_minus; s->n_ref = n_ref;
}

/* reals: r, ell, p, psi, kt, max_substep, vmax, trip */
void ema_loop_set_motor(void *p, const double *re)
{
    motor_t *m = &((loop_t *)p)->mot;
    m->r = re[0]; m->ell = re[1]; m->p = re[2]; m->psi = re[3]; m->kt = re[4];
    m->max_substep = re[5]; m->vmax = re[6]; m->trip = re[7];
}

/* reals: preload, k, d; ext[k]: F_ext at the end of macro step k */
void ema_loop_set_load(void *p, const double *re, const double *ext, long n_ext)
{
    load_t *l = &((loop_t *)p)->load;
    l->preload = re[0]; l->k = re[1]; l->d = re[2]; l->ext = ext; l->n_ext = n_ext;
}

/* the FMU instance and its functions; ints: n_in, vr_in..., n_real, vr_real..., n_int,
 * vr_int..., has_order, order... (n_real + n_int entries when has_order) */
int ema_loop_set_fmu(void *p, void *comp, void *set_real, void *get_real, void *get_int,
                     void *do_step, const int *ints)
{
    fmu_t *f = &((loop_t *)p)->fmu;
    int a = 0;
    f->comp = comp;
    f->set_real = (set_real_fn)set_real; f->get_real = (get_real_fn)get_real;
    f->get_int = (get_int_fn)get_int; f->do_step = (do_step_fn)do_step;
    int n_in = ints[a++];
    if (n_in > MAXP) return -1;
    for (int q = 0; q < n_in; q++) f->vr_in[q] = (unsigned int)ints[a++];
    f->n_real = ints[a++];
    if (f->n_real > MAXOUT) return -1;
    for (int q = 0; q < f->n_real; q++) f->vr_real[q] = (unsigned int)ints[a++];
    f->n_int = ints[a++];
    if (f->n_real + f->n_int > MAXOUT) return -1;
    for (int q = 0; q < f->n_int; q++) f->vr_int[q] = (unsigned int)ints[a++];
    f->has_order = ints[a++];
    if (f->has_order)
        for (int q = 0; q < f->n_real + f->n_int; q++) f->order[q] = ints[a++];
    return a;
}

/* State in and out, one flat array of doubles (the layout system_models.native_loop writes):
 * the controller's j, cmd[6], integrals[4]; the motor's x[5]; the load's t; per
 * block the inputs u and slopes du (n_in each); the master's y, y_prev, scale (n_out per
 * block each), has_prev, t_prev. */
static int state_io(loop_t *L, double *s, int out)
{
    int a = 0;
#define IO(v) do { if (out) s[a] = (v); else (v) = s[a]; a++; } while (0)
    double j = (double)L->ctl.j;
    IO(j);
    if (!out) L->ctl.j = (long)j;
    for (int q = 0; q < 6; q++) IO(L->ctl.cmd[q]);
    for (int q = 0; q < 4; q++) IO(L->ctl.integ[q]);
    for (int q = 0; q < 5; q++) IO(L->mot.x[q]);
    IO(L->load.t);
    for (int i = 0; i < NB; i++)
        for (int q = 0; q < L->b[i].n_in; q++) { IO(L->b[i].u[q]); IO(L->b[i].du[q]); }
    for (int i = 0; i < NB; i++)
        for (int q = 0; q < L->b[i].n_out; q++) { IO(L->y[i][q]); IO(L->y_prev[i][q]); IO(L->scale[i][q]); }
    double hp = (double)L->has_prev;
    IO(hp);
    if (!out) L->has_prev = hp != 0.0;
    IO(L->t_prev);
#undef IO
    return a;
}

int ema_loop_set_state(void *p, const double *s) { return state_io(p, (double *)s, 0); }
int ema_loop_get_state(void *p, double *s) { return state_io(p, s, 1); }

/* Macro steps k0 .. k1 − 1 (t_k = t0 + k h), each row of recorded outputs into rows.
 * info (out): [0] steps done, [1] largest coupling error estimate, [2] the failing FMU call's
 * status, [3] that call (0 setReal, 1 doStep, 2 getReal, 3 getInteger);
 * timers (in/out): seconds per block.  Returns RUN_DONE, or why it stopped at step k0 + info[0]
 * (the Python blocks then as at that step's start). */
int ema_loop_run(void *p, long k0, long k1, double *rows, double *info, double *timers)
{
    loop_t *L = p;
    double max_err = 0.0;
    long k;
    int code = RUN_DONE;
    for (k = k0; k < k1; k++) {
        double t = L->t0 + (double)k * L->h, t_next = L->t0 + (double)(k + 1) * L->h;
        /* the Python blocks' states at the step's start, for a step handed back */
        long j0 = L->ctl.j;
        double cmd0[6], integ0[4], x0[5], lt0 = L->load.t, lf0 = L->load.fe;
        double u0[NB][MAXP], du0[NB][MAXP];
        memcpy(cmd0, L->ctl.cmd, sizeof cmd0);
        memcpy(integ0, L->ctl.integ, sizeof integ0);
        memcpy(x0, L->mot.x, sizeof x0);
        for (int i = 0; i < NB; i++) {
            memcpy(u0[i], L->b[i].u, sizeof u0[i]);
            memcpy(du0[i], L->b[i].du, sizeof du0[i]);
        }
        double e = 0.0;
        code = master_step(L, t, t_next - t, k, &e, timers);
        if (code != RUN_DONE) {
            L->ctl.j = j0;
            memcpy(L->ctl.cmd, cmd0, sizeof cmd0);
            memcpy(L->ctl.integ, integ0, sizeof integ0);
            memcpy(L->mot.x, x0, sizeof x0);
            L->load.t = lt0;
            L->load.fe = lf0;
            for (int i = 0; i < NB; i++) {
                memcpy(L->b[i].u, u0[i], sizeof u0[i]);
                memcpy(L->b[i].du, du0[i], sizeof du0[i]);
            }
            break;
        }
        max_err = py_max(max_err, e);
        double *row = rows + (k - k0) * L->n_record;
        for (int m = 0; m < L->n_record; m++)
            row[m] = L->y[L->record[2 * m]][L->record[2 * m + 1]];
    }
    info[0] = (double)(k - k0);
    info[1] = max_err;
    info[2] = L->stop_status;
    info[3] = L->stop_call;
    return code;
}
