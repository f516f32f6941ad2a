/* A flat C interface to the model and its steppers, for Python's ctypes
 * (fmu_build/native_stepper.py): only doubles, ints and char buffers cross it, so no struct
 * layout has to be mirrored on the other side.  Not part of the FMU.
 */
#include <stdlib.h>
#include <string.h>

#include <stddef.h>

#include "prsm_auto.h"
#include "prsm_model.h"
#include "prsm_bounds.h"

/* The block of doubles prsm_api_step reads its arguments from and writes its result to (the
 * pythonfmu FMU writes into it and reads from it through a ctypes array over it: one call per
 * doStep, nothing converted):
 *   [0] the FMU's time t [s] (becomes current + step after a step), [1] the communication point
 *   current [s], [2] the step size [s], [3..4] the inputs (torque [N.m], load [N]), [5..7] the
 *   last step's rhs calls, accepted and rejected substeps, [8] how far current may lie from t,
 *   relative to max(1 s, |t|) (prsm_fmu.slave.TIME_MATCH), [9..9+nx) the state at time t;
 *   from [9 + PRSM_NX_MAX] the outputs prsm_api_step_outputs writes. */
#define PRSM_IO_T 0
#define PRSM_IO_CURRENT 1
#define PRSM_IO_STEP 2
#define PRSM_IO_U 3
#define PRSM_IO_STATS 5
#define PRSM_IO_MATCH 8
#define PRSM_IO_X 9
#define PRSM_IO_OUT (PRSM_IO_X + PRSM_NX_MAX)
#define PRSM_IO_SIZE (PRSM_IO_OUT + PRSM_API_N_OUTPUTS)

/* fidelity = auto: the switching stepper and its memory (now and before the last advance) */
typedef struct {
    prsm_auto a;
    prsm_auto_memory memory, before;
} prsm_auto_part;

typedef struct {
    prsm_model model;
    prsm_memory memory;
    prsm_memory before;        /* the memory before the last prsm_api_advance_many */
    prsm_auto_part *au;        /* fidelity = auto (prsm_api_new_auto), else NULL */
    double io[PRSM_IO_SIZE];   /* prsm_api_step's arguments and result */
} prsm_handle;

/* the model whose states, right-hand side and tolerances a handle has: auto's dynamic level */
static prsm_model *model_of(prsm_handle *h) { return h->au ? &h->au->a.dyn : &h->model; }

/* Number of doubles and ints prsm_api_new reads. */
int prsm_api_n_reals(void) { return 9 * PRSM_N_STAGES + 6; }
int prsm_api_n_ints(void) { return 2 * PRSM_N_STAGES + 4; }

/* Number of doubles and ints prsm_api_new_terms reads besides prsm_api_new's. */
int prsm_api_n_term_reals(void) { return 2; }
int prsm_api_n_term_ints(void) { return PRSM_N_STAGES; }

/* Number of doubles and ints prsm_api_new_geometry reads besides prsm_api_new_terms'. */
int prsm_api_n_geometry_reals(void) { return 5 * PRSM_N_STAGES; }
int prsm_api_n_geometry_ints(void) { return PRSM_N_STAGES; }

static int refuse(char *msg, int len, const char *text) {
    strncpy(msg, text, (size_t)len - 1);
    msg[len - 1] = 0;
    return -1;
}

/* the configuration prsm_api_new_geometry reads (its comment) */
static void fill_config(prsm_config *cfg_, const double *reals, const int *ints,
                        const double *term_reals, const int *term_ints,
                        const double *geo_reals, const int *geo_ints) {
    prsm_config cfg;
    memset(&cfg, 0, sizeof cfg);
    for (int k = 0; k < PRSM_N_STAGES; k++) {
        const double *r = reals + 9 * k;
        prsm_stage_values *v = &cfg.stage[k];
        v->screw_mass = r[0]; v->nut_mass = r[1]; v->roller_mass = r[2]; v->carrier_mass = r[3];
        v->screw_inertia = r[4]; v->roller_inertia = r[5]; v->carrier_inertia = r[6];
        v->spline_radius = r[7]; v->bearing_radius = r[8];
        v->n_rollers = ints[2 * k];
        v->carriers = ints[2 * k + 1];
        cfg.threads_per_roller[k] = term_ints ? term_ints[k] : 1;
        const double *g = geo_reals ? geo_reals + 5 * k : PRSM_GEOMETRY[k];
        v->screw_radius = g[0]; v->roller_radius = g[1]; v->nut_radius = g[2];
        v->screw_lead = g[3]; v->flank_angle = g[4];
        v->screw_starts = geo_ints ? geo_ints[k] : PRSM_SCREW_STARTS[k];
    }
    const double *r = reals + 9 * PRSM_N_STAGES;
    const int *i = ints + 2 * PRSM_N_STAGES;
    cfg.mu_screw_roller = r[0]; cfg.mu_spline = r[1]; cfg.mu_nut_screw = r[2];
    cfg.slip_velocity_scale = r[3]; cfg.tolerance = r[4]; cfg.kinematic_efficiency = r[5];
    if (term_reals) {
        cfg.mu_viscous = term_reals[0];
        cfg.mu_differential = term_reals[1];
    }
    cfg.kinematic = i[0] == 0;
    cfg.dynamic = i[0] == 2;
    cfg.speed_drive = i[1];
    cfg.closed_form = 1;
    cfg.substeps = i[2];
    cfg.max_substeps = i[3];
    *cfg_ = cfg;
}

/* A model with its stepper from
 *   geo_reals (NULL: the built-in geometry, prsm_constants.h): per stage screw_radius,
 *          roller_radius, nut_radius, screw_lead [m], flank_angle [rad];
 *   geo_ints (NULL: the built-in): per stage screw_starts;
 *   reals: per stage screw_mass, nut_mass, roller_mass, carrier_mass [kg], screw_inertia,
 *          roller_inertia, carrier_inertia [kg m2], spline_radius, bearing_radius [m]; then
 *          mu_screw_roller, mu_spline, mu_nut_screw [-], slip_velocity_scale [m/s],
 *          tolerance [-], kinematic_efficiency [-];
 *   ints:  per stage n_rollers, carriers; then the level (0 kinematic, 1 quasi-static,
 *          2 dynamic), the drive (0 torque, 1 speed), substeps (0: adaptive), max_substeps;
 *   term_reals (NULL: zeros): mu_viscous [N.s/m], mu_differential [m];
 *   term_ints (NULL: ones): per stage threads_per_roller.
 * The contact geometry is solved from the geometry (prsm_geometry.c).  Returns NULL with the
 * reason in msg when a value is out of range or the geometry gives no contact. */
void *prsm_api_new_geometry(const double *reals, const int *ints, const double *term_reals,
                            const int *term_ints, const double *geo_reals, const int *geo_ints,
                            char *msg, int len) {
    const int *i = ints + 2 * PRSM_N_STAGES;
    if (i[0] < 0 || i[0] > 2 || i[1] < 0 || i[1] > 1) {
        refuse(msg, len, "level must be 0, 1 or 2 and drive 0 or 1");
        return NULL;
    }
    prsm_config cfg;
    fill_config(&cfg, reals, ints, term_reals, term_ints, geo_reals, geo_ints);
    prsm_handle *h = (prsm_handle *)calloc(1, sizeof *h);
    if (!h) {
        refuse(msg, len, "out of memory");
        return NULL;
    }
    if (prsm_model_init(&h->model, &cfg, msg, len)) {
        free(h);
        return NULL;
    }
    return h;
}

/* prsm_api_new_geometry with the built-in geometry (prsm_constants.h). */
void *prsm_api_new_terms(const double *reals, const int *ints, const double *term_reals,
                         const int *term_ints, char *msg, int len) {
    return prsm_api_new_geometry(reals, ints, term_reals, term_ints, NULL, NULL, msg, len);
}

/* fidelity = "auto" (prsm_auto.h): reals, ints, term_reals, term_ints, geo_reals and geo_ints
 * as for prsm_api_new_geometry, with the level 3; the accepted model error tolerance [-] (finite, > 0)
 * and the level of the first step, start (0 dynamic, 1 quasi-static).  The dynamic steps are
 * ROS34PW2's; prsm_api_set_band does not apply.  Returns NULL with the reason in msg when a
 * value is out of range. */
void *prsm_api_new_auto(const double *reals, const int *ints, const double *term_reals,
                        const int *term_ints, const double *geo_reals, const int *geo_ints,
                        double tolerance, int start, char *msg, int len) {
    const int *i = ints + 2 * PRSM_N_STAGES;
    if (i[0] != 3 || i[1] < 0 || i[1] > 1) {
        refuse(msg, len, "level must be 3 (auto) and drive 0 or 1");
        return NULL;
    }
    prsm_config cfg;
    fill_config(&cfg, reals, ints, term_reals, term_ints, geo_reals, geo_ints);
    prsm_handle *h = (prsm_handle *)calloc(1, sizeof *h);
    prsm_auto_part *p = (prsm_auto_part *)calloc(1, sizeof *p);
    if (!h || !p) {
        free(h);
        free(p);
        refuse(msg, len, "out of memory");
        return NULL;
    }
    if (prsm_auto_init(&p->a, &cfg, tolerance, start, msg, len)) {
        free(h);
        free(p);
        return NULL;
    }
    prsm_auto_reset(&p->a, &p->memory);
    p->before = p->memory;
    h->au = p;
    return h;
}

/* The level fidelity = "auto" starts with under the torque drive (prsm_auto_choose, what the
 * native FMU runs at initialization): 0 kinematic, 1 quasi-static, 2 dynamic, with the estimated
 * model errors of the kinematic and the quasi-static level in errors[2]; -1 with the reason in
 * msg.  reals, ints, term_reals, term_ints, geo_reals, geo_ints as for prsm_api_new_geometry
 * (level and drive ignored);
 * inputs: motor torque [N.m], load [N]; screw_speed [rad/s]; carriers_at_rest 1 or 0
 * (equilibrium); kinematic_efficiency [-]. */
int prsm_api_auto_choose(const double *reals, const int *ints, const double *term_reals,
                         const int *term_ints, const double *geo_reals, const int *geo_ints,
                         double tolerance, const double *inputs,
                         double screw_speed, int carriers_at_rest, double kinematic_efficiency,
                         double *errors, char *msg, int len) {
    prsm_config cfg;
    fill_config(&cfg, reals, ints, term_reals, term_ints, geo_reals, geo_ints);
    cfg.speed_drive = 0;
    return prsm_auto_choose(&cfg, tolerance, inputs, screw_speed, carriers_at_rest,
                            kinematic_efficiency, errors, msg, len);
}

/* The level of the last step of an auto handle (2 dynamic, 1 quasi-static: the FMU's
 * step_fidelity codes), or -1 for a handle of one level. */
int prsm_api_auto_mode(void *handle) {
    prsm_handle *h = (prsm_handle *)handle;
    if (!h->au) return -1;
    return h->au->memory.mode == PRSM_AUTO_QUASI_STATIC ? 1 : 2;
}

/* What an auto handle computed on construction, into out[3 + 2 * PRSM_N_STAGES]: the inertia
 * on the screw axis with the carriers slaved [kg m2], m c_out of the last nut [kg m/rad], the
 * tolerance [-], then per carrier c_k = tau_k |F| / |omega| [N s2/rad] driving, then
 * back-driven.  Returns 0, or -1 for a handle of one level. */
int prsm_api_auto_info(void *handle, double *out) {
    prsm_handle *h = (prsm_handle *)handle;
    if (!h->au) return -1;
    const prsm_auto *a = &h->au->a;
    out[0] = a->slaved_inertia;
    out[1] = a->nut_term;
    out[2] = a->tolerance;
    for (int k = 0; k < PRSM_N_STAGES; k++) {
        out[3 + k] = a->coef[1][k];
        out[3 + PRSM_N_STAGES + k] = a->coef[0][k];
    }
    return 0;
}

/* prsm_api_new_terms with Coulomb friction only (no viscous or differential-sliding term). */
void *prsm_api_new(const double *reals, const int *ints, char *msg, int len) {
    return prsm_api_new_terms(reals, ints, NULL, NULL, msg, len);
}

/* The adaptive steppers' relative [-] and absolute [state units] tolerances, instead of the
 * FMU's (tolerance and 1e-2 tolerance); all three steppers (Dormand-Prince, ROS34PW2, the
 * exponential band step). */
void prsm_api_set_tolerances(void *handle, double rtol, double atol) {
    prsm_handle *h = (prsm_handle *)handle;
    if (h->au) {
        prsm_auto_set_tolerances(&h->au->a, rtol, atol);
        return;
    }
    h->model.rtol = h->model.band.rtol = rtol;
    h->model.atol = h->model.band.atol = atol;
    /* ROS34PW2's tolerances as prsm_model_init sets them from the FMU's */
    h->model.ros.rtol = h->model.ros.fixed_substeps ? rtol : rtol * PRSM_ROS_TOLERANCE_FACTOR;
    h->model.ros.atol = h->model.ros.fixed_substeps ? atol : atol * PRSM_ROS_TOLERANCE_FACTOR;
}

/* The slaved levels' method where the closed form declines: 1 the exponential band step (the
 * Python stepper closed_form), 0 Dormand-Prince 5(4) (closed_form_explicit, the default of
 * prsm_api_new).  Returns 0, or -1 for another value. */
int prsm_api_set_band(void *handle, int exponential) {
    if (exponential != 0 && exponential != 1) return -1;
    if (((prsm_handle *)handle)->au) return -1;
    ((prsm_handle *)handle)->model.band_exponential = exponential;
    return 0;
}

int prsm_api_n_states(void *handle) { return model_of((prsm_handle *)handle)->nx; }

/* n_steps advances (prsm_advance) of step [s] each from t0 (the i-th from t0 + i step) with the
 * inputs u held throughout: the states after each in x_out (n_steps rows of n_states); stats
 * receives (rhs calls, accepted substeps, rejected substeps) summed.  Returns 0, or -1 with the
 * reason in msg (the rows before the failing step are filled). */
int prsm_api_advance_many(void *handle, double t0, const double *x, const double *u, double step,
                          int n_steps, double *x_out, int *stats, char *msg, int len) {
    prsm_handle *h = (prsm_handle *)handle;
    int nx = model_of(h)->nx;
    double xi[PRSM_NX_MAX] = {0.0}, xo[PRSM_NX_MAX] = {0.0};
    memcpy(xi, x, sizeof(double) * (size_t)nx);
    stats[0] = stats[1] = stats[2] = 0;
    h->before = h->memory;
    if (h->au) h->au->before = h->au->memory;
    for (int i = 0; i < n_steps; i++) {
        prsm_stats st;
        int rc = h->au ? prsm_auto_advance(&h->au->a, &h->au->memory, t0 + i * step, xi, u, step,
                                           xo, &st, msg, len)
                       : prsm_advance(&h->model, &h->memory, t0 + i * step, xi, u, step, xo, &st,
                                      msg, len);
        stats[0] += st.rhs_calls;
        stats[1] += st.substeps;
        stats[2] += st.rejected;
        if (rc) return rc;
        memcpy(x_out + (size_t)i * (size_t)nx, xo, sizeof(double) * (size_t)nx);
        memcpy(xi, xo, sizeof xi);
    }
    return 0;
}

/* The block of prsm_api_step (PRSM_IO_SIZE doubles, laid out as its comment says), its size and
 * where in it the state and the outputs begin. */
double *prsm_api_step_io(void *handle) { return ((prsm_handle *)handle)->io; }
int prsm_api_step_io_size(void) { return PRSM_IO_SIZE; }
int prsm_api_step_io_x(void) { return PRSM_IO_X; }
int prsm_api_step_io_out(void) { return PRSM_IO_OUT; }

/* One communication step of the pythonfmu FMU's doStep, from the block io of
 * prsm_api_step_io: the state io[9..] at time io[0] advanced from the communication point io[1]
 * over io[2] with the inputs io[3..4] held.  Returns 0 after the step (io[0] = io[1] + io[2], the
 * new state in io[9..], the step's counts in io[5..7]); else nothing changed (the stepper's memory
 * included) and it returns
 *   1 when the step is not taken: io[1] is farther from io[0] than io[8] max(1 s, |io[0]|), the
 *     step size is not finite and > 0 or does not advance the time, or an input is out of its
 *     bounds (prsm_bounds.h, which refuses non-finite inputs too);
 *   2 when the integration fails or would end out of the state's bounds.
 * The caller, which owns the messages, then takes its checked step (which refuses naming why). */
int prsm_api_step(double *io) {
    prsm_handle *h = (prsm_handle *)(void *)((char *)io - offsetof(prsm_handle, io));
    double t = io[PRSM_IO_CURRENT], step = io[PRSM_IO_STEP];
    const double *u = io + PRSM_IO_U;
    char msg[600];
    double t_fmu = io[PRSM_IO_T];
    if (!(fabs(t - t_fmu) <= io[PRSM_IO_MATCH] * fmax(1.0, fabs(t_fmu)))
        || !(0.0 < step && step < INFINITY) || !(t + step > t)
        || prsm_input_violation(u, msg, sizeof msg))
        return 1;
    double xo[PRSM_NX_MAX] = {0.0};
    prsm_stats st;
    h->before = h->memory;
    if (prsm_advance(&h->model, &h->memory, t, io + PRSM_IO_X, u, step, xo, &st, msg, sizeof msg))
        return 2;
    if (prsm_model_state_violation(xo, &h->model, msg, sizeof msg)) {
        h->memory = h->before;
        return 2;
    }
    memcpy(io + PRSM_IO_X, xo, sizeof(double) * (size_t)h->model.nx);
    io[PRSM_IO_T] = t + step;
    io[PRSM_IO_STATS] = st.rhs_calls;
    io[PRSM_IO_STATS + 1] = st.substeps;
    io[PRSM_IO_STATS + 2] = st.rejected;
    return 0;
}

/* Put the memory back as it was before the last prsm_api_advance_many: a caller that refuses
 * the step's result (e.g. a state beyond its bounds) takes the whole advance back. */
void prsm_api_undo_advance(void *handle) {
    prsm_handle *h = (prsm_handle *)handle;
    h->memory = h->before;
    if (h->au) h->au->memory = h->au->before;
}

/* The model's right-hand side at x with inputs u (Model.rhs). */
void prsm_api_rhs(void *handle, const double *x, const double *u, double *dx) {
    prsm_handle *h = (prsm_handle *)handle;
    const prsm_model *m = model_of(h);
    double xi[PRSM_NX_MAX] = {0.0}, d[PRSM_NX_MAX];
    memcpy(xi, x, sizeof(double) * (size_t)m->nx);
    prsm_rhs(m, xi, u, d);
    memcpy(dx, d, sizeof(double) * (size_t)m->nx);
}

/* The stepper's memory as bytes (what decides the next advance besides its arguments):
 * prsm_api_memory_size() bytes for a handle of one level, prsm_api_handle_memory_size(handle)
 * for any handle (an auto handle's memory is larger). */
int prsm_api_memory_size(void) { return (int)sizeof(prsm_memory); }
int prsm_api_handle_memory_size(void *handle) {
    return ((prsm_handle *)handle)->au ? (int)sizeof(prsm_auto_memory) : (int)sizeof(prsm_memory);
}
void prsm_api_get_memory(void *handle, unsigned char *out) {
    prsm_handle *h = (prsm_handle *)handle;
    if (h->au)
        memcpy(out, &h->au->memory, sizeof(prsm_auto_memory));
    else
        memcpy(out, &h->memory, sizeof(prsm_memory));
}
void prsm_api_set_memory(void *handle, const unsigned char *in) {
    prsm_handle *h = (prsm_handle *)handle;
    if (h->au)
        memcpy(&h->au->memory, in, sizeof(prsm_auto_memory));
    else
        memcpy(&h->memory, in, sizeof(prsm_memory));
}

/* Forget the memory: the start of a run (for auto its start level, SwitchingStepper.reset). */
void prsm_api_reset(void *handle) {
    prsm_handle *h = (prsm_handle *)handle;
    memset(&h->memory, 0, sizeof h->memory);
    if (h->au) prsm_auto_reset(&h->au->a, &h->au->memory);
}

void prsm_api_free(void *handle) {
    if (handle) free(((prsm_handle *)handle)->au);
    free(handle);
}

/* ---- outputs ---------------------------------------------------------------------------------- */
#include "prsm_quantity.h"

static const char *const API_OUTPUT_NAMES[PRSM_API_N_OUTPUTS] = PRSM_API_OUTPUT_NAMES;
static const int API_OUTPUT_Q[PRSM_API_N_OUTPUTS] = PRSM_API_OUTPUT_Q;
static const int API_OUTPUT_STAGE[PRSM_API_N_OUTPUTS] = PRSM_API_OUTPUT_STAGE;

/* Number of doubles prsm_api_outputs writes. */
int prsm_api_n_outputs(void) { return PRSM_API_N_OUTPUTS; }

/* The FMU output name of prsm_api_outputs' i-th value (0 <= i < prsm_api_n_outputs()), or NULL:
 * the FMU's head outputs (screw_speed, screw_angle, ..., overall_efficiency), then per stage
 * k = 1.. "stage[k].contact_force", normal_force, driven_torque, spline_friction, carrier_speed,
 * carrier_speed_ratio; the order generated from fmu_build.native.api_outputs. */
const char *prsm_api_output_name(int i) {
    return i >= 0 && i < PRSM_API_N_OUTPUTS ? API_OUTPUT_NAMES[i] : NULL;
}

/* The outputs at state x with inputs u (Model.outputs at time t, which they do not depend on) into
 * out[prsm_api_n_outputs()], in the order of prsm_api_output_name; the native FMU's values
 * (prsm_fmi2.c), equal to the Python model's bit for bit (tests/test_engine_outputs.py). */
void prsm_api_outputs(void *handle, double t, const double *x, const double *u, double *out) {
    prsm_handle *h = (prsm_handle *)handle;
    double xi[PRSM_NX_MAX] = {0.0};
    (void)t;
    memcpy(xi, x, sizeof(double) * (size_t)model_of(h)->nx);
    prsm_outputs o;
    const prsm_model *m = &h->model;
    if (h->au) {     /* AdaptiveModel.outputs: the level of the last step */
        double xl[PRSM_NX_MAX];
        m = prsm_auto_outputs_at(&h->au->a, h->au->memory.mode, xi, u, xl, &o);
        memcpy(xi, xl, sizeof xi);
    } else {
        prsm_outputs_at(&h->model, xi, u, &o);
    }
    for (int i = 0; i < PRSM_API_N_OUTPUTS; i++)
        out[i] = prsm_quantity(m, xi, u, &o, API_OUTPUT_Q[i], API_OUTPUT_STAGE[i]);
}

/* ---- contact geometry --------------------------------------------------------------------- */
#include "prsm_geometry.h"

/* Number of doubles prsm_api_contact_geometry writes. */
int prsm_api_n_contact(void) { return PRSM_CONTACT_OUT; }

/* The screw-roller contact of a stage on its "+" flank (prsm_contact_solve: the engine's own
 * solver, equal bit for bit to prsm_fmu.geometry._newton_contact) from the screw radius r_s [m],
 * roller radius r_r [m], screw lead [m], screw starts n_s and flank angle beta [rad], into
 * out[prsm_api_n_contact()]: point (x, y, z) [m], unit normal, (rho, psi, rho_r, psi_r, z_r), the
 * largest scaled residual and the iterations.  Returns 1 if it is a contact near the pitch point
 * (prsm_contact_near), else 0. */
int prsm_api_contact_geometry(double r_s, double r_r, double lead, int n_s, double beta,
                              double *out) {
    double o[PRSM_CONTACT_OUT];
    prsm_contact_solve(r_s, r_r, lead, n_s, beta, o);
    memcpy(out, o, sizeof o);
    return prsm_contact_near(r_s, r_r, beta, o);
}

/* prsm_api_outputs at the state and inputs of prsm_api_step's block io (after a step: the
 * outputs at its end, with the inputs held over it), into the block from io[PRSM_IO_OUT]. */
void prsm_api_step_outputs(double *io) {
    prsm_handle *h = (prsm_handle *)(void *)((char *)io - offsetof(prsm_handle, io));
    prsm_api_outputs(h, io[PRSM_IO_T], io + PRSM_IO_X, io + PRSM_IO_U, io + PRSM_IO_OUT);
}

/* ---- input schedules: a whole run in one call ------------------------------------------------ */
#include <math.h>

/* n_pieces advances (prsm_advance), the i-th from t[i] over h[i] [s] with the inputs
 * (u[2 i], u[2 i + 1]) held, each from the state the one before ended in (the first from x): a run
 * whose inputs are known beforehand (prsm_fmu.simulate's schedule: one piece per output interval,
 * or several where a prescribed acceleration jumps inside one).  After each piece whose record[i]
 * is non-zero, the outputs at the state it ended in with its inputs (prsm_api_outputs, in the order
 * of prsm_api_output_name) fill the next row of y_out (prsm_api_n_outputs() doubles a row).
 * x_out receives the last state reached; stats the work of the pieces done, summed (rhs calls,
 * accepted substeps, rejected substeps).  Returns the number of pieces done: n_pieces, or fewer
 * when a piece fails (its reason in msg) or ends in a non-finite state (said in msg); x_out then
 * holds the state the failing piece started from and the stepper's memory is where it stopped. */
int prsm_api_advance_schedule(void *handle, const double *x, int n_pieces, const double *t,
                              const double *h, const double *u, const int *record, double *y_out,
                              double *x_out, int *stats, char *msg, int len) {
    prsm_handle *hd = (prsm_handle *)handle;
    int nx = model_of(hd)->nx, row = 0;
    double xi[PRSM_NX_MAX] = {0.0}, xo[PRSM_NX_MAX] = {0.0};
    memcpy(xi, x, sizeof(double) * (size_t)nx);
    stats[0] = stats[1] = stats[2] = 0;
    int i;
    for (i = 0; i < n_pieces; i++) {
        prsm_stats st;
        const double *ui = u + 2 * (size_t)i;
        int rc = hd->au ? prsm_auto_advance(&hd->au->a, &hd->au->memory, t[i], xi, ui, h[i], xo,
                                            &st, msg, len)
                        : prsm_advance(&hd->model, &hd->memory, t[i], xi, ui, h[i], xo, &st, msg,
                                       len);
        stats[0] += st.rhs_calls;
        stats[1] += st.substeps;
        stats[2] += st.rejected;
        if (rc) break;
        int finite = 1;
        for (int j = 0; j < nx; j++) finite = finite && isfinite(xo[j]);
        if (!finite) {
            refuse(msg, len, "the stepper returned a non-finite state");
            break;
        }
        memcpy(xi, xo, sizeof xi);
        if (record[i]) {
            prsm_api_outputs(handle, t[i] + h[i], xi, ui, y_out + (size_t)row * PRSM_API_N_OUTPUTS);
            row++;
        }
    }
    memcpy(x_out, xi, sizeof(double) * (size_t)nx);
    return i;
}
