/* A flat C interface to the model and its steppers, for Python's ctypes
 * (fmu_build/native_stepper.py): only doubles, ints and char buffers cross it, so no struct
 * layout has to be mirrored on the other side.  Not part of the FMU.
 */
#include <stdlib.h>
#include <string.h>

#include "prsm_model.h"

typedef struct {
    prsm_model model;
    prsm_memory memory;
    prsm_memory before;        /* the memory before the last prsm_api_advance_many */
} prsm_handle;

/* Number of doubles and ints prsm_api_new reads. */
int prsm_api_n_reals(void) { return 9 * PRSM_N_STAGES + 6; }
int prsm_api_n_ints(void) { return 2 * PRSM_N_STAGES + 4; }

/* Number of doubles and ints prsm_api_new_terms reads besides prsm_api_new's. */
int prsm_api_n_term_reals(void) { return 2; }
int prsm_api_n_term_ints(void) { return PRSM_N_STAGES; }

static int refuse(char *msg, int len, const char *text) {
    strncpy(msg, text, (size_t)len - 1);
    msg[len - 1] = 0;
    return -1;
}

/* A model with its stepper from
 *   reals: per stage screw_mass, nut_mass, roller_mass, carrier_mass [kg], screw_inertia,
 *          roller_inertia, carrier_inertia [kg m2], spline_radius, bearing_radius [m]; then
 *          mu_screw_roller, mu_spline, mu_nut_screw [-], slip_velocity_scale [m/s],
 *          tolerance [-], kinematic_efficiency [-];
 *   ints:  per stage n_rollers, carriers; then the level (0 kinematic, 1 quasi-static,
 *          2 dynamic), the drive (0 torque, 1 speed), substeps (0: adaptive), max_substeps;
 *   term_reals (NULL: zeros): mu_viscous [N.s/m], mu_differential [m];
 *   term_ints (NULL: ones): per stage threads_per_roller.
 * Returns NULL with the reason in msg when a value is out of range. */
void *prsm_api_new_terms(const double *reals, const int *ints, const double *term_reals,
                         const int *term_ints, char *msg, int len) {
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
    }
    const double *r = reals + 9 * PRSM_N_STAGES;
    const int *i = ints + 2 * PRSM_N_STAGES;
    cfg.mu_screw_roller = r[0]; cfg.mu_spline = r[1]; cfg.mu_nut_screw = r[2];
    cfg.slip_velocity_scale = r[3]; cfg.tolerance = r[4]; cfg.kinematic_efficiency = r[5];
    if (term_reals) {
        cfg.mu_viscous = term_reals[0];
        cfg.mu_differential = term_reals[1];
    }
    if (i[0] < 0 || i[0] > 2 || i[1] < 0 || i[1] > 1) {
        refuse(msg, len, "level must be 0, 1 or 2 and drive 0 or 1");
        return NULL;
    }
    cfg.kinematic = i[0] == 0;
    cfg.dynamic = i[0] == 2;
    cfg.speed_drive = i[1];
    cfg.closed_form = 1;
    cfg.substeps = i[2];
    cfg.max_substeps = i[3];
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

/* prsm_api_new_terms with Coulomb friction only (no viscous or differential-sliding term). */
void *prsm_api_new(const double *reals, const int *ints, char *msg, int len) {
    return prsm_api_new_terms(reals, ints, NULL, NULL, msg, len);
}

/* The adaptive steppers' relative [-] and absolute [state units] tolerances, instead of the
 * FMU's (tolerance and 1e-2 tolerance); all three steppers (Dormand-Prince, ROS34PW2, the
 * exponential band step). */
void prsm_api_set_tolerances(void *handle, double rtol, double atol) {
    prsm_handle *h = (prsm_handle *)handle;
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
    ((prsm_handle *)handle)->model.band_exponential = exponential;
    return 0;
}

int prsm_api_n_states(void *handle) { return ((prsm_handle *)handle)->model.nx; }

/* n_steps advances (prsm_advance) of step [s] each from t0 (the i-th from t0 + i step) with the
 * inputs u held throughout: the states after each in x_out (n_steps rows of n_states); stats
 * receives (rhs calls, accepted substeps, rejected substeps) summed.  Returns 0, or -1 with the
 * reason in msg (the rows before the failing step are filled). */
int prsm_api_advance_many(void *handle, double t0, const double *x, const double *u, double step,
                          int n_steps, double *x_out, int *stats, char *msg, int len) {
    prsm_handle *h = (prsm_handle *)handle;
    int nx = h->model.nx;
    double xi[PRSM_NX_MAX] = {0.0}, xo[PRSM_NX_MAX] = {0.0};
    memcpy(xi, x, sizeof(double) * (size_t)nx);
    stats[0] = stats[1] = stats[2] = 0;
    h->before = h->memory;
    for (int i = 0; i < n_steps; i++) {
        prsm_stats st;
        int rc = prsm_advance(&h->model, &h->memory, t0 + i * step, xi, u, step, xo, &st, msg, len);
        stats[0] += st.rhs_calls;
        stats[1] += st.substeps;
        stats[2] += st.rejected;
        if (rc) return rc;
        memcpy(x_out + (size_t)i * (size_t)nx, xo, sizeof(double) * (size_t)nx);
        memcpy(xi, xo, sizeof xi);
    }
    return 0;
}

/* Put the memory back as it was before the last prsm_api_advance_many: a caller that refuses
 * the step's result (e.g. a state beyond its bounds) takes the whole advance back. */
void prsm_api_undo_advance(void *handle) {
    prsm_handle *h = (prsm_handle *)handle;
    h->memory = h->before;
}

/* The model's right-hand side at x with inputs u (Model.rhs). */
void prsm_api_rhs(void *handle, const double *x, const double *u, double *dx) {
    prsm_handle *h = (prsm_handle *)handle;
    double xi[PRSM_NX_MAX] = {0.0}, d[PRSM_NX_MAX];
    memcpy(xi, x, sizeof(double) * (size_t)h->model.nx);
    prsm_rhs(&h->model, xi, u, d);
    memcpy(dx, d, sizeof(double) * (size_t)h->model.nx);
}

/* The stepper's memory as bytes (what decides the next advance besides its arguments). */
int prsm_api_memory_size(void) { return (int)sizeof(prsm_memory); }
void prsm_api_get_memory(void *handle, unsigned char *out) {
    memcpy(out, &((prsm_handle *)handle)->memory, sizeof(prsm_memory));
}
void prsm_api_set_memory(void *handle, const unsigned char *in) {
    memcpy(&((prsm_handle *)handle)->memory, in, sizeof(prsm_memory));
}

void prsm_api_free(void *handle) { free(handle); }

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
    memcpy(xi, x, sizeof(double) * (size_t)h->model.nx);
    prsm_outputs o;
    prsm_outputs_at(&h->model, xi, u, &o);
    for (int i = 0; i < PRSM_API_N_OUTPUTS; i++)
        out[i] = prsm_quantity(&h->model, xi, u, &o, API_OUTPUT_Q[i], API_OUTPUT_STAGE[i]);
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
    int nx = hd->model.nx, row = 0;
    double xi[PRSM_NX_MAX] = {0.0}, xo[PRSM_NX_MAX] = {0.0};
    memcpy(xi, x, sizeof(double) * (size_t)nx);
    stats[0] = stats[1] = stats[2] = 0;
    int i;
    for (i = 0; i < n_pieces; i++) {
        prsm_stats st;
        const double *ui = u + 2 * (size_t)i;
        int rc = prsm_advance(&hd->model, &hd->memory, t[i], xi, ui, h[i], xo, &st, msg, len);
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
